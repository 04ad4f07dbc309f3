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
  const Vec3 n = glm::cross(b - a, c - a);
  const double n2 = glm::dot(n, n);
  if (n2 > 0.0) {
    // Project onto the plane; inside test by barycentric signs.
    const double dist = glm::dot(p - a, n) / std::sqrt(n2);
    const Vec3 q = p - dist * (n / std::sqrt(n2));
    const double s0 = glm::dot(glm::cross(b - a, q - a), n);
    const double s1 = glm::dot(glm::cross(c - b, q - b), n);
    const double s2 = glm::dot(glm::cross(a - c, q - c), n);
    if (s0 >= 0.0 && s1 >= 0.0 && s2 >= 0.0) return std::abs(dist);
  }
  return std::min({point_segment_distance3d(p, a, b), point_segment_distance3d(p, b, c),
                   point_segment_distance3d(p, c, a)});
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
  NormalCone cone;
  Vec3 sum{0.0};
  for (const Vec3& n : unit_normals) sum += n;
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

Vec3 triangle_normal(const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 n = glm::cross(b - a, c - a);
  const double len = glm::length(n);
  return len > 0.0 ? n / len : Vec3{0.0};
}

}  // namespace smr
