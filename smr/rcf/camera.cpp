#include "smr/rcf/camera.h"

#include <algorithm>
#include <cmath>
#include <string>

#include <glm/geometric.hpp>

#include "base/error.h"

namespace smr {

namespace {
bool finite(const Vec3& v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}
}  // namespace

void Camera::validate() const {
  if (!finite(eye)) throw_input("--eye: coordinates must be finite numbers");
  if (!finite(target)) throw_input("--target: coordinates must be finite numbers");
  if (glm::length(target - eye) <= 0.0) throw_input("--target must differ from --eye");
  if (!(fov_y_deg > 0.0 && fov_y_deg < 179.0)) {
    throw_input("--fov must be in (0, 179) degrees, got " + std::to_string(fov_y_deg));
  }
  if (viewport_w <= 0 || viewport_h <= 0 || viewport_w > 1 << 16 || viewport_h > 1 << 16) {
    throw_input("--viewport must be WxH with 1..65536 pixels each, got " +
                std::to_string(viewport_w) + "x" + std::to_string(viewport_h));
  }
  if (!(near_distance >= 0.0) || !std::isfinite(near_distance)) throw_input("--near must be >= 0");
  if (!(far_distance >= 0.0) || !std::isfinite(far_distance) ||
      (far_distance > 0.0 && far_distance <= near_distance)) {
    throw_input("--far must be 0 (none) or greater than --near");
  }
}

Vec3 Camera::forward() const {
  return glm::normalize(target - eye);
}
Vec3 Camera::right() const {
  const Vec3 f = forward();
  Vec3 r = glm::cross(f, up);
  if (glm::length(r) < 1e-9) r = glm::cross(f, Vec3{0.0, 1.0, 0.0});
  if (glm::length(r) < 1e-9) r = glm::cross(f, Vec3{1.0, 0.0, 0.0});
  return glm::normalize(r);
}
Vec3 Camera::true_up() const {
  return glm::cross(right(), forward());
}
double Camera::tan_half_y() const {
  return std::tan(fov_y_deg * M_PI / 360.0);
}
double Camera::tan_half_x() const {
  return tan_half_y() * double(viewport_w) / double(viewport_h);
}
double Camera::focal_px() const {
  return 0.5 * double(viewport_h) / tan_half_y();
}

std::optional<Vec2> Camera::project(const Vec3& p) const {
  const Vec3 d = p - eye;
  const double depth = glm::dot(d, forward());
  if (depth <= 0.0) return std::nullopt;
  const double f = focal_px();
  return Vec2{0.5 * viewport_w + f * glm::dot(d, right()) / depth,
              0.5 * viewport_h - f * glm::dot(d, true_up()) / depth};
}

std::array<Plane, 6> Camera::planes() const {
  const Vec3 f = forward(), r = right(), u = true_up();
  auto through_eye = [&](const Vec3& n) {
    const Vec3 un = glm::normalize(n);
    return Plane{un, -glm::dot(un, eye)};
  };
  std::array<Plane, 6> p;
  p[0] = through_eye(f * tan_half_x() + r);  // left
  p[1] = through_eye(f * tan_half_x() - r);  // right
  p[2] = through_eye(f * tan_half_y() + u);  // bottom
  p[3] = through_eye(f * tan_half_y() - u);  // top
  p[4] = Plane{f, -glm::dot(f, eye) - near_distance};
  p[5] = Plane{-f, glm::dot(f, eye) + far_distance};
  return p;
}

bool sphere_outside(const Frustum& f, const Sphere& s) {
  for (int i = 0; i < f.count; ++i) {
    if (f.planes[i].signed_distance(s.center) < -s.radius) return true;
  }
  return false;
}
bool sphere_outside(const Camera& cam, const Sphere& s) {
  return sphere_outside(Frustum(cam), s);
}

bool box_outside(const Frustum& f, const Box3& b) {
  if (b.empty()) return true;
  for (int i = 0; i < f.count; ++i) {
    const Plane& pl = f.planes[i];
    // The corner farthest along the plane normal.
    const Vec3 far{pl.n.x >= 0 ? b.hi.x : b.lo.x, pl.n.y >= 0 ? b.hi.y : b.lo.y,
                   pl.n.z >= 0 ? b.hi.z : b.lo.z};
    if (pl.signed_distance(far) < 0.0) return true;
  }
  return false;
}
bool box_outside(const Camera& cam, const Box3& b) {
  return box_outside(Frustum(cam), b);
}

bool backfacing(const Camera& cam, const Sphere& s, const NormalCone& cone) {
  if (cone.half_angle >= M_PI / 2) return false;
  const Vec3 d = s.center - cam.eye;
  const double dist = glm::length(d);
  if (dist <= s.radius) return false;
  const double view_spread = std::asin(std::min(1.0, s.radius / dist));
  const double axis_angle = std::acos(std::clamp(glm::dot(cone.axis, d / dist), -1.0, 1.0));
  return axis_angle + cone.half_angle + view_spread < M_PI / 2 - 1e-12;
}

double distance_to_box(const Vec3& eye, const Box3& b) {
  const Vec3 q = glm::clamp(eye, b.lo, b.hi);
  return glm::length(eye - q);
}

double max_sin_vertical(const Vec3& eye, const Box3& b) {
  const double dz = std::max({b.lo.z - eye.z, 0.0, eye.z - b.hi.z});
  if (dz <= 0.0) return 1.0;
  const double hx = std::max(std::abs(b.lo.x - eye.x), std::abs(b.hi.x - eye.x));
  const double hy = std::max(std::abs(b.lo.y - eye.y), std::abs(b.hi.y - eye.y));
  const double h2 = hx * hx + hy * hy;  // coordinates: far from overflow, no need of hypot
  return std::sqrt(h2 / (h2 + dz * dz));
}

// ---- the metric frame ----
MetricFrame MetricFrame::of(const Georef& georef, const Box3& bounds) {
  MetricFrame f;
  if (!georef.geographic || bounds.empty()) return f;
  const Vec3 c = bounds.center();
  const std::array<double, 2> m = metres_per_degree(c.y);
  f.origin = {c.x, c.y};
  f.kx = m[0];
  f.ky = m[1];
  return f;
}

Sphere MetricFrame::apply(const Sphere& s) const {
  return {apply(s.center), s.radius * std::max({kx, ky, 1.0})};
}

Camera MetricFrame::apply(const Camera& c) const {
  Camera m = c;
  m.eye = apply(c.eye);
  m.target = apply(c.target);
  return m;
}

}  // namespace smr
