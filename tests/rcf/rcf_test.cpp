// RCF components (Brown 4.6): every term's maximum over a triangle or rectangle bounds its point
// values; the region (index-entry) tests are conservative against the op tests; camera geometry;
// the Peucker-Douglas detector.
#include <gtest/gtest.h>

#include <random>

#include <glm/geometric.hpp>

#include <unordered_set>

#include "base/error.h"
#include "smr/io/synthetic.h"
#include "smr/rcf/spec.h"
#include "tests/support/datasets.h"
#include "tests/support/meshes.h"
#include "tests/support/rcf_spread.h"
#include "tests/support/sanitized.h"

namespace smr {
namespace {

Camera test_camera() {
  Camera c;
  c.eye = {-50, -80, 400};
  c.target = {300, 250, 0};
  c.fov_y_deg = 45;
  c.viewport_w = 640;
  c.viewport_h = 480;
  return c;
}

TEST(ObjectSpace, TermMaximaBoundPointValues) {
  const Heightfield dem = make_fbm(65, 65, 5, 500.0, 0, 0.5, 10.0);
  auto lines = std::make_shared<CriticalLines>(CriticalLines::detect(dem));
  ASSERT_GT(lines->count(), 10u);
  const Camera cam = test_camera();
  std::vector<std::shared_ptr<const ObjectSpaceTerm>> terms{
      std::make_shared<ConstantTerm>(0.4),
      std::make_shared<GaussianTerm>(Vec2{320, 320}, 80, 0.9),
      std::make_shared<DiscTerm>(Vec2{100, 500}, 60, 0.8),
      std::make_shared<WedgeTerm>(WedgeTerm::frustum_footprint(cam, 0.6)),
      std::make_shared<WedgeTerm>(WedgeTerm::centre_cone(cam, 10, 0.95)),
      std::make_shared<CriticalLineTerm>(lines, 0.7)};
  std::mt19937_64 rng(123);
  std::uniform_real_distribution<double> u(-50, 700);
  int hits = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    Vec2 a{u(rng), u(rng)}, b{u(rng), u(rng)}, c{u(rng), u(rng)};
    if (trial % 3 == 0) {  // grid-aligned triangles, as in a CRMR
      a = glm::round(a / 10.0) * 10.0, b = glm::round(b / 10.0) * 10.0,
      c = glm::round(c / 10.0) * 10.0;
    }
    const Vec2 lo = glm::min(a, glm::min(b, c)), hi = glm::max(a, glm::max(b, c));
    for (const auto& t : terms) {
      const double tri_max = t->max_over_triangle(a, b, c);
      const double rect_max = t->max_over_rect(lo, hi);
      EXPECT_LE(tri_max, rect_max + 1e-12) << t->describe();
      for (int s = 0; s < 60; ++s) {
        double wa = std::uniform_real_distribution<double>(0, 1)(rng);
        double wb = std::uniform_real_distribution<double>(0, 1)(rng);
        if (wa + wb > 1) wa = 1 - wa, wb = 1 - wb;
        const Vec2 p = a + wa * (b - a) + wb * (c - a);
        const double v = t->value(p);
        hits += v > 0;
        ASSERT_LE(v, tri_max + 1e-12) << t->describe() << " trial " << trial;
      }
      // Vertices (critical samples sit exactly on grid points).
      for (const Vec2& p : {a, b, c}) ASSERT_LE(t->value(p), tri_max + 1e-12) << t->describe();
    }
  }
  EXPECT_GT(hits, 1000);
}

TEST(ObjectSpace, WedgeFootprintCoversTheFrustum) {
  const Camera cam = test_camera();
  const WedgeTerm w = WedgeTerm::frustum_footprint(cam, 1.0);
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> u(-1, 1), t(1, 2000);
  for (int i = 0; i < 2000; ++i) {
    // A point inside the 3-D frustum projects into the footprint.
    const Vec3 dir = cam.forward() + u(rng) * cam.tan_half_x() * cam.right() +
                     u(rng) * cam.tan_half_y() * cam.true_up();
    const Vec3 p = cam.eye + t(rng) * dir;
    EXPECT_EQ(w.value(xy(p)), 1.0);
  }
  Camera down = cam;
  down.target = {cam.eye.x, cam.eye.y + 1e-6, 0};
  EXPECT_EQ(WedgeTerm::frustum_footprint(down, 1.0).value({1e6, -1e6}), 1.0);  // whole plane
}

TEST(Camera, ProjectionAndCulling) {
  const Camera cam = test_camera();
  const auto centre = cam.project(cam.target);
  ASSERT_TRUE(centre.has_value());
  EXPECT_NEAR(centre->x, 320, 1e-9);
  EXPECT_NEAR(centre->y, 240, 1e-9);
  EXPECT_FALSE(cam.project(cam.eye - cam.forward()).has_value());
  Box3 behind;
  behind.add(cam.eye - 10.0 * cam.forward() + Vec3{1, 1, 1});
  behind.add(cam.eye - 20.0 * cam.forward());
  EXPECT_TRUE(box_outside(cam, behind));
  Box3 ahead;
  ahead.add(cam.target - Vec3{5});
  ahead.add(cam.target + Vec3{5});
  EXPECT_FALSE(box_outside(cam, ahead));
  EXPECT_FALSE(sphere_outside(cam, Sphere{cam.target, 1}));
  // A patch facing away from the eye is back-facing; facing it is not.
  const Vec3 away = glm::normalize(cam.target - cam.eye);
  EXPECT_TRUE(backfacing(cam, Sphere{cam.target, 1}, NormalCone{away, 0.1}));
  EXPECT_FALSE(backfacing(cam, Sphere{cam.target, 1}, NormalCone{-away, 0.1}));
  EXPECT_FALSE(backfacing(cam, Sphere{cam.target, 1}, NormalCone{away, M_PI}));
}

TEST(Camera, ValidationNamesTheParameter) {
  Camera c = test_camera();
  c.fov_y_deg = 0;
  try {
    c.validate();
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("--fov"), std::string::npos);
  }
  c = test_camera();
  c.target = c.eye;
  EXPECT_THROW(c.validate(), Error);
  RcfSpec s;
  s.pixel_error = 1.0;  // without a camera
  EXPECT_THROW(validate(s), Error);
  s = RcfSpec{};
  s.floor = 1.5;
  EXPECT_THROW(validate(s), Error);
  s = RcfSpec{};
  s.aois.push_back({0, 0, -1, 0.5});
  EXPECT_THROW(validate(s), Error);
}

// The index (next issue) prunes an entry when region_completely_finer(ROI, min birth_res): this
// must imply IsCompletelyFiner for every op below it. Check it on every op's ROI and subtree.
TEST(Rcf, RegionTestIsConservative) {
  // fbm129 under the sanitizers, whose datasets do not include fbm257.
  const test::Dataset& d = test::dataset(test::kSanitized ? "fbm129" : "fbm257");
  const Crmr& m = d.crmr;
  const Box3& b = m.header.bounds;
  const Vec3 c = b.center();
  std::vector<RcfSpec> specs(4);
  specs[0].floor = 0.4;
  specs[0].aois.push_back({c.x, c.y, 300, 0.97});
  specs[1].camera = test_camera();
  specs[1].camera->eye = {b.lo.x - 100, b.lo.y - 100, b.hi.z + 300};
  specs[1].camera->target = c;
  specs[1].pixel_error = 2;
  specs[2] = specs[1];
  specs[2].screen_aoi = ScreenAoi{{320, 240}, 100, 0.5};
  specs[3].critical_level = 0.9;
  specs[3].discs.push_back({c.x, c.y, 200, 0.8});
  for (const RcfSpec& s : specs) {
    const Rcf rcf = make_rcf(s, ModelKind::kTerrain, &d.dem);
    std::uint64_t pruned = 0;
    for (const Op& op : m.ops) {
      if (op.id == kBaseOp) continue;
      if (!rcf.region_completely_finer(op.roi, op.roi, op.birth_res, m.header)) continue;
      ++pruned;
      // Every op in the subtree has its box in the ROI and a birth_res >= op.birth_res.
      std::vector<OpId> stack{op.id};
      std::unordered_set<std::uint64_t> seen;
      while (!stack.empty()) {
        const OpRef q_ref = m.op(stack.back());
        const OpView& q = *q_ref;
        stack.pop_back();
        if (!seen.insert(q.id.value).second) continue;
        ASSERT_TRUE(rcf.is_completely_finer(q, m)) << rcf.describe() << ": op " << q.id.value;
        for (OpId ch : q.children) stack.push_back(ch);
      }
    }
    EXPECT_GT(pruned, 0u) << rcf.describe();
  }
}

TEST(CriticalLines, PeuckerDouglasFindsRidgesAndChannels) {
  Heightfield h;
  h.width = 41;
  h.height = 21;
  h.source = "ridge";
  h.z.resize(std::size_t(h.width) * h.height);
  for (int r = 0; r < h.height; ++r) {
    for (int col = 0; col < h.width; ++col) {
      // A ridge along col 10 and a channel along col 30, with a gentle slope along rows.
      const double ridge = -std::abs(col - 10.0), channel = std::abs(col - 30.0);
      h.z[h.index(col, r)] = float((col < 20 ? ridge : channel - 20.0) + 0.01 * r);
    }
  }
  const CriticalLines cl = CriticalLines::detect(h);
  for (int r = 1; r + 1 < h.height; ++r) {
    EXPECT_TRUE(cl.flagged(10, r)) << "ridge row " << r;
    EXPECT_TRUE(cl.flagged(30, r)) << "channel row " << r;
    for (int col : {5, 15, 25, 35}) EXPECT_FALSE(cl.flagged(col, r)) << col << "," << r;
  }
  EXPECT_EQ(cl.count_in_rect(0, 0, 40, 20), cl.count());
  EXPECT_EQ(cl.count_in_rect(11, 1, 29, 19), 0u);
  // A relief threshold above the local relief removes everything.
  EXPECT_EQ(CriticalLines::detect(h, {5.0}).count(), 0u);
}

// ---- verdicts over a motion (rcf.h Motion; sessions keep verdicts across updates with them) ----

Vec3 unframe(const MetricFrame& f, const Vec3& p) {
  return {p.x / f.kx + f.origin.x, p.y / f.ky + f.origin.y, p.z};
}

Vec3 random_unit(std::mt19937_64& rng) {
  std::normal_distribution<double> n;
  Vec3 v{n(rng), n(rng), n(rng)};
  return glm::normalize(v);
}

// `v` turned by `angle` about the unit `axis` (Rodrigues).
Vec3 turned(const Vec3& v, const Vec3& axis, double angle) {
  return v * std::cos(angle) + glm::cross(axis, v) * std::sin(angle) +
         axis * glm::dot(axis, v) * (1.0 - std::cos(angle));
}

// Every definite answer of finer_within / completely_finer_within over motions of a few sizes
// equals the exact verdict under cameras moved at random within the motion (the eye shifted, the
// view turned about a random axis, in the model's metric frame). Returns the answers checked.
std::uint64_t check_motion_verdicts(const Crmr& crmr, const Heightfield* dem, RcfSpec spec,
                                    std::mt19937_64& rng) {
  const CrmrInfo& info = crmr.header;
  const MetricFrame frame = MetricFrame::of(info.georef, info.bounds);
  const Rcf rcf = make_rcf(spec, info, dem);
  const std::optional<RcfPose> pose = rcf.pose();
  EXPECT_TRUE(pose.has_value());
  if (!pose) return 0;
  const Camera cam = frame.apply(*spec.camera);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::uniform_int_distribution<std::uint64_t> pick(0, crmr.op_count() - 1);
  std::uint64_t checked = 0;
  std::array<std::uint64_t, 2> values{0, 0};
  const bool failed_before = ::testing::Test::HasFailure();
  for (const double fraction : {1e-3, 1e-2, 5e-2}) {
    const double m = fraction * pose->scale;
    const Motion motion{m, m / pose->scale};
    std::vector<Rcf> moved;
    while (moved.size() < 6) {
      // Alternately the whole shift or the whole turn (the cases at the bounds), then mixes.
      const std::size_t k = moved.size();
      Camera c = cam;
      c.eye += random_unit(rng) * (k % 3 == 1 ? 0.0 : (k % 3 == 0 ? 0.999 : u(rng)) * m);
      const Vec3 axis = random_unit(rng);
      const double angle = (k % 3 == 0 ? 0.0 : (k % 3 == 1 ? 1.0 : u(rng))) * motion.theta / 1.5;
      c.target = c.eye + turned(cam.target - cam.eye, axis, angle);
      c.up = turned(cam.up, axis, angle);
      RcfSpec s = spec;
      s.camera = c;
      s.camera->eye = unframe(frame, c.eye);
      s.camera->target = unframe(frame, c.target);
      Rcf r = make_rcf(s, info, dem);
      const Motion actual = RcfPose::between(*pose, *r.pose());
      if (actual.delta <= motion.delta && actual.theta <= motion.theta) moved.push_back(r);
    }
    for (int i = 0; i < (test::kSanitized ? 500 : 2000); ++i) {
      const OpRef op = crmr.op(OpId{pick(rng)});
      const Tri finer = rcf.finer_within(*op, crmr, motion);
      const Tri complete = rcf.completely_finer_within(*op, crmr, motion);
      for (const Rcf& r : moved) {
        if (finer != Tri::kUnknown) {
          EXPECT_EQ(r.is_finer(*op, crmr), finer == Tri::kTrue) << "op " << op->id.value;
          ++checked;
          ++values[finer == Tri::kTrue];
        }
        if (complete != Tri::kUnknown) {
          EXPECT_EQ(r.is_completely_finer(*op, crmr), complete == Tri::kTrue)
              << "op " << op->id.value;
          ++checked;
          ++values[complete == Tri::kTrue];
        }
      }
      // The index test over the motion, on the op's box, binds every moved camera too.
      if (rcf.region_completely_finer_within(op->box, op->roi, op->birth_res, info, motion)) {
        for (const Rcf& r : moved)
          EXPECT_TRUE(r.region_completely_finer(op->box, op->roi, op->birth_res, info));
      }
      if (::testing::Test::HasFailure() && !failed_before) return checked;
    }
  }
  EXPECT_GT(values[0], 10u) << "too few definite false verdicts to test";
  EXPECT_GT(values[1], 10u) << "too few definite true verdicts to test";
  return checked;
}

TEST(Rcf, VerdictsOverAMotionHoldForEveryCameraInIt) {
  std::mt19937_64 rng(20261206);
  for (const std::string name : {"jacksboro", "elev", "fbm129"}) {
    SCOPED_TRACE(name);
    const test::Dataset& d = test::dataset(name);
    const Box3& b = d.crmr.header.bounds;
    const Vec3 size = b.hi - b.lo;
    RcfSpec spec;
    // Oblique, from beyond a corner, above the highest point (model units: degrees for elev).
    spec.camera = test::test_camera(
        {b.lo.x - 0.1 * size.x, b.lo.y - 0.2 * size.y, b.hi.z + 0.3 * std::max(size.z, 100.0)},
        b.center());
    for (const double px : {1.0, 0.1}) {  // finer tolerances leave more to the culling
      spec.pixel_error = px;
      EXPECT_GT(check_motion_verdicts(d.crmr, &d.dem, spec, rng),
                test::kSanitized ? 2000u : 10000u);
    }
  }
  for (const std::string name : {"bunny00.off"}) {
    SCOPED_TRACE(name);
    const test::BuiltMesh& m = test::built_mesh(name);
    const Box3& b = m.crmr.header.bounds;
    const double r = glm::length(b.hi - b.lo);
    RcfSpec spec;
    spec.camera = test::test_camera(b.center() + Vec3{0.3, -0.9, 0.4} * r, b.center());
    spec.pixel_error = 0.5;
    EXPECT_GT(check_motion_verdicts(m.crmr, nullptr, spec, rng), test::kSanitized ? 2000u : 10000u);
  }
}

// Turning the view moves a far triangle across a side plane by its distance times the angle: a
// triangle 1 unit outside the left plane, 1000 units away, is culled for every camera within a
// 0.5 shift, but not for every camera within that shift and a turn of 0.002 rad, and one turned
// by 0.0015 rad sees it.
TEST(Rcf, FrustumVerdictsOverAMotionAllowForTurning) {
  Camera cam;
  cam.eye = {0, 0, 0};
  cam.target = {0, 1, 0};
  cam.up = {0, 0, 1};
  cam.fov_y_deg = 60;
  cam.viewport_w = cam.viewport_h = 100;
  const FrustumCulling frustum(cam);
  const Plane left = cam.planes()[0];
  const Vec3 far = Vec3{0, 1000, 0} - left.n * (left.signed_distance({0, 1000, 0}) + 1.0);
  const Triangle3 t{far, far + Vec3{0, 0, 1}, far + Vec3{0, 1, 0}};
  ASSERT_NEAR(left.signed_distance(far), -1.0, 1e-9);
  EXPECT_TRUE(frustum.culls_triangle(t));
  EXPECT_EQ(frustum.culls_triangle_within(t, {0.5, 0.0}), Tri::kTrue);
  EXPECT_EQ(frustum.culls_triangle_within(t, {0.5, 0.002}), Tri::kUnknown);
  Camera turned = cam;  // towards the triangle, about the up axis
  turned.target = {-std::sin(0.0015), std::cos(0.0015), 0};
  EXPECT_FALSE(FrustumCulling(turned).culls_triangle(t));
}

}  // namespace
}  // namespace smr
