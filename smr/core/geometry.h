// Small geometric types shared by the model, the RCF and (later) the index: boxes, spheres,
// cones of normals, and exact-enough 2-D predicates on the xy-domain of 2.5-D data.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <span>

#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

namespace smr {

using Vec2 = glm::dvec2;
using Vec3 = glm::dvec3;
using Triangle3 = std::array<Vec3, 3>;  // corners, counter-clockwise seen from above / outside

/// Axis-aligned box. Empty when lo > hi on any axis.
struct Box3 {
  Vec3 lo{std::numeric_limits<double>::infinity()};
  Vec3 hi{-std::numeric_limits<double>::infinity()};

  bool empty() const { return lo.x > hi.x || lo.y > hi.y || lo.z > hi.z; }
  void add(const Vec3& p) {
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
  }
  void add(const Box3& b) {
    if (b.empty()) return;
    lo = glm::min(lo, b.lo);
    hi = glm::max(hi, b.hi);
  }
  bool contains(const Box3& b) const {
    return b.empty() || (lo.x <= b.lo.x && lo.y <= b.lo.y && lo.z <= b.lo.z && hi.x >= b.hi.x &&
                         hi.y >= b.hi.y && hi.z >= b.hi.z);
  }
  /// Closed boxes that share a point (false when either is empty).
  bool intersects(const Box3& b) const {
    return lo.x <= b.hi.x && lo.y <= b.hi.y && lo.z <= b.hi.z && b.lo.x <= hi.x && b.lo.y <= hi.y &&
           b.lo.z <= hi.z;
  }
  Vec3 center() const { return (lo + hi) * 0.5; }
  friend bool operator==(const Box3&, const Box3&) = default;
};

struct Sphere {
  Vec3 center{0.0};
  double radius = 0.0;
  friend bool operator==(const Sphere&, const Sphere&) = default;
};

/// Cone of normals (Hoppe 97 / Brown 4.6.1): every normal n of the region satisfies
/// angle(n, axis) <= half_angle. half_angle >= pi means "any direction".
struct NormalCone {
  Vec3 axis{0.0, 0.0, 1.0};
  double half_angle = 0.0;
  friend bool operator==(const NormalCone&, const NormalCone&) = default;
};

/// Twice the signed area of the xy-projection of (a, b, c); > 0 when counter-clockwise.
inline double orient2d(const Vec2& a, const Vec2& b, const Vec2& c) {
  return (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
}
inline Vec2 xy(const Vec3& p) {
  return {p.x, p.y};
}

/// Distance from p to the closed triangle (a, b, c) in the plane (0 when inside).
double point_triangle_distance2d(const Vec2& p, const Vec2& a, const Vec2& b, const Vec2& c);
/// Distance from p to the closed triangle (a, b, c) in space.
double point_triangle_distance3d(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c);

/// One triangle prepared for many distance queries (the same Voronoi-region method as
/// point_triangle_distance3d, with the triangle's own dot products computed once).
class TriangleDistance {
 public:
  TriangleDistance() = default;
  TriangleDistance(const Vec3& a, const Vec3& b, const Vec3& c);
  /// Squared distance from p (inline: the mesh builder's error bound calls it in its inner loop).
  double squared(const Vec3& p) const {
    // The closest point by the Voronoi region of p (Ericson, Real-Time Collision Detection
    // 5.1.5). With ap = p - a: bp = ap - ab and cp = ap - ac, so the six dot products follow
    // from two. Degenerate triangles: the nearest edge.
    const auto sq = [](const Vec3& v) { return glm::dot(v, v); };
    if (degenerate_) return degenerate_squared(p);
    const Vec3 ap = p - a_;
    const double d1 = glm::dot(ab_, ap), d2 = glm::dot(ac_, ap);
    if (d1 <= 0.0 && d2 <= 0.0) return sq(ap);
    const double d3 = d1 - abab_, d4 = d2 - abac_;
    if (d3 >= 0.0 && d4 <= d3) return sq(p - b_);
    const double vc = d1 * d4 - d3 * d2;
    if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return sq(ap - (d1 / (d1 - d3)) * ab_);
    const double d5 = d1 - abac_, d6 = d2 - acac_;
    if (d6 >= 0.0 && d5 <= d6) return sq(p - c_);
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return sq(ap - (d2 / (d2 - d6)) * ac_);
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0) {
      return sq((p - b_) - ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c_ - b_));
    }
    const double inv = 1.0 / (va + vb + vc);
    return sq(ap - ab_ * (vb * inv) - ac_ * (vc * inv));
  }

 private:
  double degenerate_squared(const Vec3& p) const;

  Vec3 a_{0.0}, b_{0.0}, c_{0.0}, ab_{0.0}, ac_{0.0};
  double abab_ = 0.0, abac_ = 0.0, acac_ = 0.0;
  bool degenerate_ = true;
};
/// Distance from p to segment ab in the plane.
double point_segment_distance2d(const Vec2& p, const Vec2& a, const Vec2& b);
/// Distance from p to the closed axis-aligned rectangle [lo, hi] in the plane.
inline double point_rect_distance2d(const Vec2& p, const Vec2& lo, const Vec2& hi) {
  const double dx = std::max({lo.x - p.x, 0.0, p.x - hi.x});
  const double dy = std::max({lo.y - p.y, 0.0, p.y - hi.y});
  return std::sqrt(dx * dx + dy * dy);  // coordinates: far from overflow, no need of hypot
}

/// Bounding sphere of points: centred at the centre of their bounding box (so it is contained
/// in the ball around any box that contains the points' box centre... see Op::sphere docs).
Sphere bounding_sphere(std::span<const Vec3> points);
/// Smallest cone (approximately: axis = normalised mean) containing the given unit normals.
NormalCone normal_cone(std::span<const Vec3> unit_normals);
/// normal_cone(unit_normals) given their sum, added in order.
NormalCone normal_cone_of(std::span<const Vec3> unit_normals, const Vec3& sum);
/// The smallest cone around an axis on the great circle through a's and b's axes that holds
/// both cones (half angle pi: every direction).
NormalCone cone_union(const NormalCone& a, const NormalCone& b);

/// Every direction of `inner` lies in `outer` (to ~1e-9 rad).
bool cone_contains(const NormalCone& outer, const NormalCone& inner);

/// A normal cone as a page stores it: the axis scaled so that its largest component is +-127,
/// the half angle in steps of (pi/2)/255 (a byte each: the axis moves by < 0.5 degree and the
/// angle widens by that and < 0.36 degree more; 16-bit codes cost 4.7 bytes a terrain vertex,
/// database format 4). A cone of pi/2 or more (which never culls) is stored as the full cone.
struct ConeCode {
  bool full = true;
  std::array<std::int8_t, 3> axis{};
  std::uint8_t half = 0;
};
inline constexpr int kConeAxisMax = 127;
inline constexpr int kConeHalfSteps = 255;  // the half angle code is below it
inline constexpr double kConeStep = (M_PI / 2) / kConeHalfSteps;
NormalCone decode_cone(const ConeCode& code);
/// The codes of a cone already in canonical form (decode_cone(cone_code(c)) == c).
ConeCode cone_code(const NormalCone& canonical);
/// The smallest canonical cone that holds `c` (axis rounded, angle widened by the rounding).
NormalCone canonical_cone(const NormalCone& c);
/// Unit normal of triangle (a, b, c), counter-clockwise front; zero vector when degenerate.
Vec3 triangle_normal(const Vec3& a, const Vec3& b, const Vec3& c);

}  // namespace smr
