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
  // The closest point by the Voronoi region of p (Ericson, Real-Time Collision Detection 5.1.5):
  // dot products only, no square root but the last. Degenerate triangles: nearest edge.
  const Vec3 ab = b - a, ac = c - a;
  const Vec3 n = glm::cross(ab, ac);
  if (!(glm::dot(n, n) > 0.0)) {
    return std::min({point_segment_distance3d(p, a, b), point_segment_distance3d(p, b, c),
                     point_segment_distance3d(p, c, a)});
  }
  const Vec3 ap = p - a;
  const double d1 = glm::dot(ab, ap), d2 = glm::dot(ac, ap);
  if (d1 <= 0.0 && d2 <= 0.0) return glm::length(ap);
  const Vec3 bp = p - b;
  const double d3 = glm::dot(ab, bp), d4 = glm::dot(ac, bp);
  if (d3 >= 0.0 && d4 <= d3) return glm::length(bp);
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return glm::length(ap - (d1 / (d1 - d3)) * ab);
  const Vec3 cp = p - c;
  const double d5 = glm::dot(ab, cp), d6 = glm::dot(ac, cp);
  if (d6 >= 0.0 && d5 <= d6) return glm::length(cp);
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return glm::length(ap - (d2 / (d2 - d6)) * ac);
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0) {
    return glm::length(bp - ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c - b));
  }
  const double inv = 1.0 / (va + vb + vc);
  return glm::length(ap - ab * (vb * inv) - ac * (vc * inv));
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
