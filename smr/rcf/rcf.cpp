// Brown 4.6: RCF composition and the frustum, back-face, object- and screen-space components.
#include "smr/rcf/rcf.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include <glm/geometric.hpp>

#include "base/error.h"

namespace smr {

Triangle3 corners(const OpView& op, const FragmentTriangle& t) {
  return {op.position(t, 0), op.position(t, 1), op.position(t, 2)};
}
Triangle3 corners(const OpView& op, const PreTriangle& t) {
  return {op.position(t, 0), op.position(t, 1), op.position(t, 2)};
}
Box3 triangle_box(const Triangle3& v) {
  Box3 b;
  for (const Vec3& p : v) b.add(p);
  return b;
}

// ---- culling ----
bool FrustumCulling::culls(const OpView& op) const {
  return sphere_outside(frustum_, frame_.apply(op.sphere)) ||
         box_outside(frustum_, frame_.apply(op.box));
}

bool FrustumCulling::culls_triangle(const Triangle3& model) const {
  // Every corner strictly outside one plane. A sphere or box outside that plane holds no point
  // inside it, so culls(op) implies this for each triangle of the op.
  const auto& planes = frustum_.planes;
  const Triangle3 v = frame_.apply(model);
  for (int i = 0; i < frustum_.count; ++i) {
    if (planes[i].signed_distance(v[0]) < 0 && planes[i].signed_distance(v[1]) < 0 &&
        planes[i].signed_distance(v[2]) < 0)
      return true;
  }
  return false;
}

// ---- verdicts under motion (rcf.h: Motion, Tri) ----
namespace {

Tri tri_or(Tri a, Tri b) {
  if (a == Tri::kTrue || b == Tri::kTrue) return Tri::kTrue;
  return a == Tri::kFalse && b == Tri::kFalse ? Tri::kFalse : Tri::kUnknown;
}

// A point's signed distance to a frustum plane, n.(p - eye) + c with n a fixed combination of the
// camera's basis, moves by at most delta + theta (|p - eye| + delta) when the eye moves by delta
// and every basis vector by at most theta (the plane's normal, a unit vector in their span, then
// moves by at most theta as well).
double plane_shift(const Motion& m, double reach) {
  return m.delta + m.theta * (reach + m.delta);
}

// The box's corner farthest along the plane's normal (box_outside's test point).
double far_corner_distance(const Plane& pl, const Box3& b) {
  return pl.signed_distance({pl.n.x >= 0 ? b.hi.x : b.lo.x, pl.n.y >= 0 ? b.hi.y : b.lo.y,
                             pl.n.z >= 0 ? b.hi.z : b.lo.z});
}

// The farthest distance from `eye` to a point of the box.
double farthest(const Vec3& eye, const Box3& b) {
  const Vec3 d = glm::max(glm::abs(b.lo - eye), glm::abs(b.hi - eye));
  return glm::length(d);
}

// The verdict of "some plane has every point of the set outside" given, per plane, the largest
// signed distance of the set (`worst`, filled by the caller) and how far motion shifts them.
template <class Worst>
Tri outside_within(const Frustum& f, double shift, Worst worst) {
  bool may = false;
  for (int i = 0; i < f.count; ++i) {
    const double d = worst(f.planes[i]);  // culled by this plane when d < 0
    if (d < -shift) return Tri::kTrue;
    if (d < shift) may = true;
  }
  return may ? Tri::kUnknown : Tri::kFalse;
}

}  // namespace

Tri FrustumCulling::culls_within(const OpView& op, const Motion& m) const {
  if (m.zero()) return to_tri(culls(op));
  const Sphere s = frame_.apply(op.sphere);
  const Box3 b = frame_.apply(op.box);
  if (b.empty()) return Tri::kTrue;
  const double reach = std::max(glm::length(s.center - cam_.eye) + s.radius, farthest(cam_.eye, b));
  // culls() is "the sphere or the box outside one plane": the smaller of the two distances.
  return outside_within(frustum_, plane_shift(m, reach), [&](const Plane& pl) {
    return std::min(pl.signed_distance(s.center) + s.radius, far_corner_distance(pl, b));
  });
}

bool FrustumCulling::culls_region_within(const Box3& box, const Motion& m) const {
  if (m.zero()) return culls_region(box);
  const Box3 b = frame_.apply(box);
  if (b.empty()) return true;
  return outside_within(frustum_, plane_shift(m, farthest(cam_.eye, b)),
                        [&](const Plane& pl) { return far_corner_distance(pl, b); }) == Tri::kTrue;
}

Tri FrustumCulling::culls_triangle_within(const Triangle3& model, const Motion& m) const {
  if (m.zero()) return to_tri(culls_triangle(model));
  const Triangle3 v = frame_.apply(model);
  double reach = 0.0;
  for (const Vec3& p : v) reach = std::max(reach, glm::length(p - cam_.eye));
  return outside_within(frustum_, plane_shift(m, reach), [&](const Plane& pl) {
    return std::max({pl.signed_distance(v[0]), pl.signed_distance(v[1]), pl.signed_distance(v[2])});
  });
}

Tri BackfaceCulling::culls_within(const OpView& op, const Motion& m) const {
  if (m.zero()) return to_tri(culls(op));
  if (op.subtree_cone.half_angle >= M_PI / 2) return Tri::kFalse;
  const Vec3 centre = op.roi.center();
  const double r = glm::length(op.roi.hi - centre);
  // The eye moved by delta sees the sphere where the unmoved eye sees it moved by -delta, inside
  // the sphere grown by delta: back-facing from every point of that one, it is from them all.
  if (backfacing(cam_, Sphere{centre, r + m.delta}, op.subtree_cone)) return Tri::kTrue;
  // Not back-facing from any of those eyes when even the least angle sum reaches pi/2: the
  // direction to the centre turns by at most asin(delta / dist), the spread is at least
  // asin(r / (dist + delta)).
  const Vec3 d = centre - cam_.eye;
  const double dist = glm::length(d);
  if (dist <= r + m.delta) return Tri::kUnknown;
  const double axis_angle =
      std::acos(std::clamp(glm::dot(op.subtree_cone.axis, d / dist), -1.0, 1.0));
  const double least = axis_angle - std::asin(std::min(1.0, m.delta / dist)) +
                       op.subtree_cone.half_angle + std::asin(std::min(1.0, r / (dist + m.delta)));
  return least >= M_PI / 2 ? Tri::kFalse : Tri::kUnknown;
}

bool BackfaceCulling::culls(const OpView& op) const {
  const Vec3 centre = op.roi.center();
  return backfacing(cam_, Sphere{centre, glm::length(op.roi.hi - centre)}, op.subtree_cone);
}

// ---- object space ----
std::string ObjectSpaceCriterion::describe() const {
  std::string s = "object-space g = max(";
  for (std::size_t i = 0; i < g_.terms().size(); ++i)
    s += (i ? ", " : "") + g_.terms()[i]->describe();
  return s + ")";
}

bool ObjectSpaceCriterion::triangle_satisfies(const Triangle3& v, double res,
                                              const CrmrInfo&) const {
  return meets_level(res, g_.max_over_triangle(xy(v[0]), xy(v[1]), xy(v[2])));
}

bool ObjectSpaceCriterion::region_satisfies(const Box3& box, double min_res,
                                            const CrmrInfo&) const {
  return meets_level(min_res, g_.max_over_rect(xy(box.lo), xy(box.hi)));
}

// ---- volumes of significance ----
double Volume::at_distance(double d) const {
  if (gaussian) return level * std::exp(-(d * d) / (2.0 * radius * radius));
  return d <= radius ? level : 0.0;
}

std::string VolumeCriterion::describe() const {
  std::ostringstream os;
  os << "volumes of significance (";
  for (std::size_t i = 0; i < volumes_.size(); ++i) {
    const Volume& v = volumes_[i];
    os << (i ? ", " : "") << (v.gaussian ? "gaussian " : "ball ") << v.level << " r=" << v.radius
       << " at " << v.center.x << "," << v.center.y << "," << v.center.z;
  }
  return os.str() + ")";
}

double VolumeCriterion::value(const Vec3& p) const {
  double g = 0.0;
  for (const Volume& v : volumes_) g = std::max(g, v.at_distance(glm::length(p - v.center)));
  return std::min(g, 1.0);
}

bool VolumeCriterion::triangle_satisfies(const Triangle3& t, double res, const CrmrInfo&) const {
  for (const Volume& v : volumes_) {
    if (!meets_level(res, v.at_distance(point_triangle_distance3d(v.center, t[0], t[1], t[2]))))
      return false;
  }
  return true;
}

bool VolumeCriterion::region_satisfies(const Box3& box, double min_res, const CrmrInfo&) const {
  for (const Volume& v : volumes_) {
    const Vec3 outside = glm::max(glm::max(box.lo - v.center, v.center - box.hi), Vec3(0.0));
    if (!meets_level(min_res, v.at_distance(glm::length(outside)))) return false;
  }
  return true;
}

// ---- screen space ----
std::string ScreenSpaceCriterion::describe() const {
  std::ostringstream os;
  os << "screen-space tau=" << tau_ << "px";
  if (aoi_)
    os << " (" << aoi_->pixel_error << "px within " << aoi_->radius_px << "px of "
       << aoi_->center_px.x << "," << aoi_->center_px.y << ")";
  return os.str();
}

double ScreenSpaceCriterion::pixel_error_bound(double error, const Box3& region) const {
  if (error <= 0.0) return 0.0;
  const double dist = distance_to_box(cam_.eye, region);
  if (dist <= 0.0) return std::numeric_limits<double>::infinity();
  const double s = vertical_ ? max_sin_vertical(cam_.eye, region) : 1.0;
  return error * s * focal_px_ / dist;
}

double ScreenSpaceCriterion::tolerance_at(const Vec2& pixel) const {
  if (aoi_ && glm::length(pixel - aoi_->center_px) <= aoi_->radius_px)
    return std::min(tau_, aoi_->pixel_error);
  return tau_;
}

double ScreenSpaceCriterion::tolerance(const Box3& region) const {
  if (!aoi_ || aoi_->pixel_error >= tau_) return tau_;
  const double tau_min = std::min(tau_, aoi_->pixel_error);
  Vec2 lo{std::numeric_limits<double>::infinity()}, hi{-std::numeric_limits<double>::infinity()};
  for (int i = 0; i < 8; ++i) {
    const Vec3 corner{(i & 1) ? region.hi.x : region.lo.x, (i & 2) ? region.hi.y : region.lo.y,
                      (i & 4) ? region.hi.z : region.lo.z};
    const auto p = cam_.project(corner);
    if (!p) return tau_min;  // part of the region is beside or behind the eye
    lo = glm::min(lo, *p);
    hi = glm::max(hi, *p);
  }
  // The projected region lies in the projection of the box's corners' convex hull, which lies in
  // [lo, hi] since projection maps the in-front part of a convex set to a convex set.
  return point_rect_distance2d(aoi_->center_px, lo, hi) <= aoi_->radius_px ? tau_min : tau_;
}

bool ScreenSpaceCriterion::triangle_satisfies(const Triangle3& v, double res,
                                              const CrmrInfo& info) const {
  const Box3 b = triangle_box(frame_.apply(v));
  return pixel_error_bound(error_at(info, res), b) <= tolerance(b);
}

bool ScreenSpaceCriterion::region_satisfies(const Box3& box, double min_res,
                                            const CrmrInfo& info) const {
  const Box3 b = frame_.apply(box);
  return pixel_error_bound(error_at(info, min_res), b) <= tolerance(b);
}

Tri ScreenSpaceCriterion::satisfies_within(const Box3& b, double error, const Motion& m) const {
  if (m.zero()) return to_tri(pixel_error_bound(error, b) <= tolerance(b));
  if (aoi_ && aoi_->pixel_error < tau_) return Tri::kUnknown;  // the tolerance moves on screen
  if (error <= 0.0) return Tri::kTrue;
  // The view direction does not matter; an eye moved by delta sees the box where the unmoved eye
  // sees it moved by -delta, inside the box grown by delta, and pixel_error_bound is monotone in
  // the box: its value there bounds every moved eye's.
  const Vec3 grow(m.delta);
  if (pixel_error_bound(error, Box3{b.lo - grow, b.hi + grow}) <= tau_) return Tri::kTrue;
  // The least projected error: distance at most dist + delta, the sine at least that of the
  // nearest horizontal reach and the farthest vertical gap.
  double s = 1.0;
  if (vertical_) {
    const Vec3& e = cam_.eye;
    const double dz = std::max({b.lo.z - e.z, 0.0, e.z - b.hi.z}) + m.delta;
    const double hx =
        std::max(std::max(std::abs(b.lo.x - e.x), std::abs(b.hi.x - e.x)) - m.delta, 0.0);
    const double hy =
        std::max(std::max(std::abs(b.lo.y - e.y), std::abs(b.hi.y - e.y)) - m.delta, 0.0);
    const double h = std::sqrt(hx * hx + hy * hy);
    s = h / std::sqrt(h * h + dz * dz);
  }
  const double dist = distance_to_box(cam_.eye, b) + m.delta;
  return error * s * focal_px_ / dist > tau_ ? Tri::kFalse : Tri::kUnknown;
}

Tri ScreenSpaceCriterion::triangle_satisfies_within(const Triangle3& v, double res,
                                                    const CrmrInfo& info, const Motion& m) const {
  return satisfies_within(triangle_box(frame_.apply(v)), error_at(info, res), m);
}

Tri ScreenSpaceCriterion::region_satisfies_within(const Box3& box, double min_res,
                                                  const CrmrInfo& info, const Motion& m) const {
  return satisfies_within(frame_.apply(box), error_at(info, min_res), m);
}

// ---- composition ----
// The exact tests are the tests over the motion of none: one composition for both.
bool Rcf::is_finer(const OpView& op, const OpSource& source) const {
  return finer_within(op, source, Motion{}) == Tri::kTrue;
}

bool Rcf::is_completely_finer(const OpView& op, const OpSource& source) const {
  return completely_finer_within(op, source, Motion{}) == Tri::kTrue;
}

bool Rcf::region_completely_finer(const Box3& box, const Box3& roi, double min_birth_res,
                                  const CrmrInfo& info) const {
  return region_completely_finer_within(box, roi, min_birth_res, info, Motion{});
}

Tri Rcf::culled_within(const OpView& op, const Motion& m) const {
  Tri t = Tri::kFalse;
  for (const auto& c : culling_) t = tri_or(t, c->culls_within(op, m));
  return t;
}

// Every similarity component accepts the triangle at `res`, or (culling) a culling one drops it.
Tri Rcf::triangle_within(const Triangle3& v, double res, const CrmrInfo& info,
                         const Motion& m) const {
  Tri all = Tri::kTrue;
  for (const auto& s : similarity_) {
    const Tri t = s->triangle_satisfies_within(v, res, info, m);
    if (t == Tri::kFalse) return Tri::kFalse;
    if (t == Tri::kUnknown) all = Tri::kUnknown;
  }
  return all;
}

// IsFiner and IsCompletelyFiner (rcf.h) with each test replaced by its value over the motion
// (Kleene's logic); with no motion every value is definite and these are the exact tests. The
// shortcuts (culling, the region test) only ever settle a verdict they imply. Both tests first ask
// each similarity component about the op's box at the op's least resolution (conservative: true
// only if every triangle in the box at that resolution or more satisfies it), which settles most
// ops far from the requirement without a triangle's test.
Tri Rcf::finer_within(const OpView& op, const OpSource& source, const Motion& m) const {
  const Tri culled = culled_within(op, m);
  if (culled == Tri::kTrue) return Tri::kTrue;
  double least = 1.0;
  for (const FragmentTriangle& t : op.fragment) {
    if (!is_final_or_void(t)) least = std::min(least, t.death_res);
  }
  Tri region = Tri::kTrue;
  for (const auto& s : similarity_) {
    if (s->region_satisfies_within(op.box, least, source.info(), m) != Tri::kTrue) {
      region = Tri::kUnknown;
      break;
    }
  }
  if (region == Tri::kTrue) return Tri::kTrue;
  Tri all = Tri::kTrue;
  for (const FragmentTriangle& t : op.fragment) {
    if (is_final_or_void(t)) continue;
    const Tri s = triangle_within(corners(op, t), t.death_res, source.info(), m);
    if (s == Tri::kFalse) return tri_or(culled, Tri::kFalse);
    if (s == Tri::kUnknown) all = Tri::kUnknown;
  }
  return tri_or(culled, all);
}

Tri Rcf::completely_finer_within(const OpView& op, const OpSource& source, const Motion& m) const {
  if (op.id == kBaseOp) return Tri::kFalse;
  const Tri culled = culled_within(op, m);
  if (culled == Tri::kTrue || similarity_.empty()) return Tri::kTrue;
  if (op.pre_tris.size() != op.pre.size())
    throw_internal("op " + std::to_string(op.id.value) + " has no PreF corners (link_dag not run)");
  bool region = true;
  for (const auto& s : similarity_) {
    region =
        region && s->region_satisfies_within(op.box, op.birth_res, source.info(), m) == Tri::kTrue;
  }
  if (region) return Tri::kTrue;
  Tri all = Tri::kTrue;
  for (const PreTriangle& t : op.pre_tris) {
    if (t.is_void()) continue;
    const Triangle3 v = corners(op, t);
    Tri dropped = Tri::kFalse;
    for (const auto& c : culling_) dropped = tri_or(dropped, c->culls_triangle_within(v, m));
    const Tri s = tri_or(dropped, triangle_within(v, op.birth_res, source.info(), m));
    if (s == Tri::kFalse) return tri_or(culled, Tri::kFalse);
    if (s == Tri::kUnknown) all = Tri::kUnknown;
  }
  return tri_or(culled, all);
}

bool Rcf::region_completely_finer_within(const Box3& box, const Box3& /*roi*/, double min_birth_res,
                                         const CrmrInfo& info, const Motion& m) const {
  for (const auto& c : culling_) {
    if (c->culls_region_within(box, m)) return true;
  }
  for (const auto& s : similarity_) {
    if (s->region_satisfies_within(box, min_birth_res, info, m) != Tri::kTrue) return false;
  }
  return true;
}

namespace {
bool same_camera(const Camera& a, const Camera& b) {
  return a.eye == b.eye && a.target == b.target && a.up == b.up && a.fov_y_deg == b.fov_y_deg &&
         a.viewport_w == b.viewport_w && a.viewport_h == b.viewport_h &&
         a.near_distance == b.near_distance && a.far_distance == b.far_distance;
}
}  // namespace

std::optional<RcfPose> Rcf::pose() const {
  const Camera* cam = nullptr;
  const auto take = [&](const Camera* c) {
    if (c == nullptr) return true;
    if (cam == nullptr) cam = c;
    return same_camera(*cam, *c);
  };
  for (const auto& c : culling_) {
    if (!take(c->camera())) return std::nullopt;
  }
  for (const auto& s : similarity_) {
    if (!take(s->camera())) return std::nullopt;
  }
  RcfPose p;
  p.signature = describe();
  if (cam != nullptr) {
    std::ostringstream os;
    os.precision(17);
    os << " | fov " << cam->fov_y_deg << " viewport " << cam->viewport_w << "x" << cam->viewport_h
       << " near " << cam->near_distance << " far " << cam->far_distance;
    p.signature += os.str();
    p.eye = cam->eye;
    p.basis = {cam->right(), cam->true_up(), cam->forward()};
    p.scale = glm::length(cam->target - cam->eye);
  }
  return p;
}

Motion RcfPose::between(const RcfPose& a, const RcfPose& b) {
  // A unit vector n = sum n_i a_i moves to sum n_i b_i, by at most sqrt(sum |b_i - a_i|^2)
  // (Cauchy-Schwarz): a bound on the rotation's effect that needs no angle.
  double turn2 = 0.0;
  for (int i = 0; i < 3; ++i) {
    const Vec3 d = b.basis[i] - a.basis[i];
    turn2 += glm::dot(d, d);
  }
  // Rounded up by more than the arithmetic's error.
  const double delta = glm::length(b.eye - a.eye);
  return {delta + 1e-12 * (1.0 + glm::length(a.eye) + glm::length(b.eye)),
          std::sqrt(turn2) + 1e-12};
}

double RcfPose::needed_to(const RcfPose& to) const {
  const Motion m = between(*this, to);
  return std::max(m.delta, m.theta * scale);
}

std::string Rcf::describe() const {
  std::string s;
  for (const auto& c : culling_) s += (s.empty() ? "" : "; ") + c->describe();
  for (const auto& c : similarity_) s += (s.empty() ? "" : "; ") + c->describe();
  return s.empty() ? "coarsest (no criterion)" : s;
}

}  // namespace smr
