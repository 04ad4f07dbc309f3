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

// ---- composition ----
bool Rcf::culled(const OpView& op) const {
  for (const auto& c : culling_) {
    if (c->culls(op)) return true;
  }
  return false;
}

bool Rcf::triangle_culled(const Triangle3& v) const {
  for (const auto& c : culling_) {
    if (c->culls_triangle(v)) return true;
  }
  return false;
}

// Both tests first ask each similarity component about the op's box at the op's least
// resolution (conservative: true only if every triangle in the box at that resolution or more
// satisfies it), which settles most ops far from the requirement without a triangle's test.
bool Rcf::region_satisfied(const Box3& box, double min_res, const CrmrInfo& info) const {
  for (const auto& s : similarity_) {
    if (!s->region_satisfies(box, min_res, info)) return false;
  }
  return true;
}

bool Rcf::is_finer(const OpView& op, const OpSource& source) const {
  if (culled(op)) return true;
  double least = 1.0;
  for (const FragmentTriangle& t : op.fragment) {
    if (!is_final_or_void(t)) least = std::min(least, t.death_res);
  }
  if (region_satisfied(op.box, least, source.info())) return true;
  for (const FragmentTriangle& t : op.fragment) {
    if (is_final_or_void(t)) continue;
    const Triangle3 v = corners(op, t);
    for (const auto& s : similarity_) {
      if (!s->triangle_satisfies(v, t.death_res, source.info())) return false;
    }
  }
  return true;
}

bool Rcf::is_completely_finer(const OpView& op, const OpSource& source) const {
  if (op.id == kBaseOp) return false;
  if (culled(op)) return true;
  if (similarity_.empty()) return true;
  if (op.pre_tris.size() != op.pre.size())
    throw_internal("op " + std::to_string(op.id.value) + " has no PreF corners (link_dag not run)");
  if (region_satisfied(op.box, op.birth_res, source.info())) return true;
  for (const PreTriangle& t : op.pre_tris) {
    if (t.is_void()) continue;
    const Triangle3 v = corners(op, t);
    if (triangle_culled(v)) continue;
    for (const auto& s : similarity_) {
      if (!s->triangle_satisfies(v, op.birth_res, source.info())) return false;
    }
  }
  return true;
}

bool Rcf::region_completely_finer(const Box3& box, const Box3& /*roi*/, double min_birth_res,
                                  const CrmrInfo& info) const {
  for (const auto& c : culling_) {
    if (c->culls_region(box)) return true;
  }
  return region_satisfied(box, min_birth_res, info);
}

std::string Rcf::describe() const {
  std::string s;
  for (const auto& c : culling_) s += (s.empty() ? "" : "; ") + c->describe();
  for (const auto& c : similarity_) s += (s.empty() ? "" : "; ") + c->describe();
  return s.empty() ? "coarsest (no criterion)" : s;
}

}  // namespace smr
