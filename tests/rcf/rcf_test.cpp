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

}  // namespace
}  // namespace smr
