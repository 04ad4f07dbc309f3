#include "smr/core/geometry.h"

#include <glm/geometric.hpp>

namespace smr {

double point_segment_distance2d(const Vec2& p, const Vec2& a, const Vec2& b) {
  const Vec2 ab = b - a;
  const double len2 = glm::dot(ab, ab);
  double t = len2 > 0.0 ? glm::dot(p - a, ab) / len2 : 0.0;
  t = std::clamp(t, 0.0, 1.0);
  return glm::length(p - (a + t * ab));
}

double point_triangle_distance2d(const Vec2& p, const Vec2& a, const Vec2& b, const Vec2& c) {
  const double o = orient2d(a, b, c);
  const double d0 = orient2d(a, b, p), d1 = orient2d(b, c, p), d2 = orient2d(c, a, p);
  if (o > 0.0 ? (d0 >= 0.0 && d1 >= 0.0 && d2 >= 0.0) : (d0 <= 0.0 && d1 <= 0.0 && d2 <= 0.0)) {
    return 0.0;
  }
  return std::min({point_segment_distance2d(p, a, b), point_segment_distance2d(p, b, c),
                   point_segment_distance2d(p, c, a)});
}

namespace {
double point_segment_distance3d(const Vec3& p, const Vec3& a, const Vec3& b) {
  const Vec3 ab = b - a;
  const double len2 = glm::dot(ab, ab);
  double t = len2 > 0.0 ? glm::dot(p - a, ab) / len2 : 0.0;
  t = std::clamp(t, 0.0, 1.0);
  return glm::length(p - (a + t * ab));
}
}  // namespace

double point_triangle_distance3d(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  return std::sqrt(TriangleDistance(a, b, c).squared(p));
}

TriangleDistance::TriangleDistance(const Vec3& a, const Vec3& b, const Vec3& c)
    : a_(a), b_(b), c_(c), ab_(b - a), ac_(c - a) {
  const Vec3 n = glm::cross(ab_, ac_);
  degenerate_ = !(glm::dot(n, n) > 0.0);
  abab_ = glm::dot(ab_, ab_);
  abac_ = glm::dot(ab_, ac_);
  acac_ = glm::dot(ac_, ac_);
}

double TriangleDistance::degenerate_squared(const Vec3& p) const {
  const double d =
      std::min({point_segment_distance3d(p, a_, b_), point_segment_distance3d(p, b_, c_),
                point_segment_distance3d(p, c_, a_)});
  return d * d;
}

Sphere bounding_sphere(std::span<const Vec3> points) {
  Box3 box;
  for (const Vec3& p : points) box.add(p);
  Sphere s;
  if (box.empty()) return s;
  s.center = box.center();
  double r2 = 0.0;
  for (const Vec3& p : points) r2 = std::max(r2, glm::dot(p - s.center, p - s.center));
  s.radius = std::sqrt(r2);
  return s;
}

NormalCone normal_cone(std::span<const Vec3> unit_normals) {
  Vec3 sum{0.0};
  for (const Vec3& n : unit_normals) sum += n;
  return normal_cone_of(unit_normals, sum);
}

NormalCone normal_cone_of(std::span<const Vec3> unit_normals, const Vec3& sum) {
  NormalCone cone;
  const double len = glm::length(sum);
  if (unit_normals.empty() || len < 1e-12) {
    cone.half_angle = M_PI;  // no usable axis: the cone admits every direction
    return cone;
  }
  cone.axis = sum / len;
  double min_cos = 1.0;
  for (const Vec3& n : unit_normals) min_cos = std::min(min_cos, glm::dot(n, cone.axis));
  // Round outward so the cone certainly contains every normal.
  cone.half_angle = std::min(M_PI, std::acos(std::clamp(min_cos, -1.0, 1.0)) + 1e-9);
  return cone;
}

NormalCone cone_union(const NormalCone& a, const NormalCone& b) {
  if (a.half_angle >= M_PI || b.half_angle >= M_PI) return NormalCone{a.axis, M_PI};
  const double between = std::acos(std::clamp(glm::dot(a.axis, b.axis), -1.0, 1.0));
  if (between + b.half_angle <= a.half_angle) return a;
  if (between + a.half_angle <= b.half_angle) return b;
  const double half = 0.5 * (between + a.half_angle + b.half_angle);
  if (half >= M_PI) return NormalCone{a.axis, M_PI};
  // Rotate a's axis towards b's by (half - a.half_angle) in their common plane.
  const Vec3 ortho = b.axis - glm::dot(a.axis, b.axis) * a.axis;
  const double len = glm::length(ortho);
  if (!(len > 1e-12)) return NormalCone{a.axis, M_PI};  // opposite axes
  const double t = half - a.half_angle;
  const Vec3 axis = glm::normalize(std::cos(t) * a.axis + std::sin(t) * (ortho / len));
  return NormalCone{axis, std::min(M_PI, half + 1e-9)};
}

bool cone_contains(const NormalCone& outer, const NormalCone& inner) {
  if (outer.half_angle >= M_PI) return true;
  if (inner.half_angle >= M_PI) return false;
  // between + inner <= outer, compared by cosines (acos loses ~1e-8 rad near 0).
  const double spare = outer.half_angle - inner.half_angle + 1e-9;
  if (spare < 0.0) return false;
  return spare >= M_PI || glm::dot(outer.axis, inner.axis) >= std::cos(spare) - 1e-12;
}

namespace {
std::array<std::int8_t, 3> axis_codes(const Vec3& axis) {
  const double m = std::max({std::abs(axis.x), std::abs(axis.y), std::abs(axis.z)});
  std::array<std::int8_t, 3> code{};
  for (int k = 0; k < 3; ++k)
    code[k] = static_cast<std::int8_t>(std::lround(axis[k] / m * double(kConeAxisMax)));
  return code;
}
}  // namespace

NormalCone decode_cone(const ConeCode& code) {
  if (code.full) return NormalCone{Vec3{0.0, 0.0, 1.0}, M_PI};
  const Vec3 a{double(code.axis[0]), double(code.axis[1]), double(code.axis[2])};
  return NormalCone{a / glm::length(a), code.half * kConeStep};
}

ConeCode cone_code(const NormalCone& c) {
  ConeCode code;
  if (c.half_angle >= M_PI / 2) return code;
  code.full = false;
  code.axis = axis_codes(c.axis);
  code.half = static_cast<std::uint8_t>(std::lround(c.half_angle / kConeStep));
  return code;
}

NormalCone canonical_cone(const NormalCone& c) {
  ConeCode code;
  if (c.half_angle < M_PI / 2) {
    code.axis = axis_codes(c.axis);
    code.full = code.axis == std::array<std::int8_t, 3>{};
    const NormalCone rounded = decode_cone(code);
    // The angle between the axes from their chord (acos loses ~1e-8 rad near 0): exactly 0 for
    // an axis that is already a code's, so a canonical cone is its own canonical form. Without
    // that, re-canonicalising at every level of the DAG (compute_rois) widened cones by a step a
    // level. A moved axis adds a margin for the rounding of `shift`.
    const double chord = glm::length(rounded.axis - c.axis);
    const double shift = 2.0 * std::asin(std::min(1.0, chord / 2.0));
    const double need = c.half_angle + shift + (shift > 0.0 ? 1e-12 : 0.0);
    double steps = std::max(0.0, std::ceil(need / kConeStep - 1e-6));
    while (steps * kConeStep < need) steps += 1.0;  // decode_cone's product
    if (steps < double(kConeHalfSteps)) {
      code.half = static_cast<std::uint8_t>(steps);
    } else {
      code.full = true;
    }
  }
  return decode_cone(code);
}

Vec3 triangle_normal(const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 n = glm::cross(b - a, c - a);
  const double len = glm::length(n);
  return len > 0.0 ? n / len : Vec3{0.0};
}

}  // namespace smr
