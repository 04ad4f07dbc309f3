// Brute-force-exact distances to a triangle soup, for the 3-D error-bound oracle: the distance
// from a point to the nearest triangle, found through a uniform grid of buckets (every triangle
// is in each bucket its box meets; rings of buckets are searched outwards until no farther
// bucket can hold a nearer triangle), so the answer equals the minimum over all triangles.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstdlib>
#include <vector>

#include <glm/geometric.hpp>

#include "smr/core/geometry.h"

namespace smr::test {

/// Textbook distances, written independently of smr/core's (oracles for it and for code using it).
/// From p to the closed segment ab (a point when a == b).
inline double textbook_segment_distance(const Vec3& p, const Vec3& a, const Vec3& b) {
  const Vec3 ab = b - a;
  const double l2 = glm::dot(ab, ab);
  const double t = l2 > 0.0 ? std::clamp(glm::dot(p - a, ab) / l2, 0.0, 1.0) : 0.0;
  return glm::length(p - (a + t * ab));
}
/// From p to the closed triangle abc: to its plane when p projects inside it, else to its
/// nearest edge (a zero-area triangle is its edges).
inline double textbook_triangle_distance(const Vec3& p, const Vec3& a, const Vec3& b,
                                         const Vec3& c) {
  const Vec3 n = glm::cross(b - a, c - a);
  const double n2 = glm::dot(n, n);
  if (n2 > 0.0) {
    const Vec3 q = p - (glm::dot(p - a, n) / n2) * n;  // p projected on the plane
    if (glm::dot(glm::cross(b - a, q - a), n) >= 0.0 &&
        glm::dot(glm::cross(c - b, q - b), n) >= 0.0 &&
        glm::dot(glm::cross(a - c, q - c), n) >= 0.0) {
      return glm::length(p - q);
    }
  }
  return std::min({textbook_segment_distance(p, a, b), textbook_segment_distance(p, b, c),
                   textbook_segment_distance(p, c, a)});
}

class TriangleSoupDistance {
 public:
  /// `radii`, when given, holds one radius per triangle, for within_own_radius.
  explicit TriangleSoupDistance(std::vector<std::array<Vec3, 3>> triangles,
                                std::vector<double> radii = {});
  /// min over triangles of the distance from p to the closed triangle.
  double distance(const Vec3& p) const { return search(p, -1.0); }
  /// distance(p) <= radius, searching only the buckets within `radius` of p.
  bool within(const Vec3& p, double radius) const { return search(p, radius) <= radius; }
  /// Whether some triangle i is within scale * radii[i] of p (searching the buckets within the
  /// largest such radius of p): the brute-force answer of "any i: distance(p, triangle i) <=
  /// scale * radii[i]".
  bool within_own_radius(const Vec3& p, double scale = 1.0) const;

 private:
  std::array<std::int64_t, 3> cell_of(const Vec3& p) const;
  // Calls f(triangle index) for the items of every bucket at Chebyshev distance r from bucket c.
  template <class F>
  void for_ring(const std::array<std::int64_t, 3>& c, std::int64_t r, F&& f) const {
    for (std::int64_t z = c[2] - r; z <= c[2] + r; ++z) {
      if (z < 0 || z >= dims_[2]) continue;
      for (std::int64_t y = c[1] - r; y <= c[1] + r; ++y) {
        if (y < 0 || y >= dims_[1]) continue;
        for (std::int64_t x = c[0] - r; x <= c[0] + r; ++x) {
          if (x < 0 || x >= dims_[0]) continue;
          if (std::max({std::abs(x - c[0]), std::abs(y - c[1]), std::abs(z - c[2])}) != r) {
            continue;
          }
          const std::size_t b = std::size_t((z * dims_[1] + y) * dims_[0] + x);
          for (std::uint32_t k = start_[b]; k < start_[b + 1]; ++k) f(items_[k]);
        }
      }
    }
  }
  // The distance, or (radius >= 0) any value <= radius once one is found, or > radius when none.
  double search(const Vec3& p, double radius) const;
  std::vector<std::array<Vec3, 3>> tris_;
  std::vector<double> radii_;
  double max_radius_ = 0.0;
  Box3 box_;
  double cell_ = 1.0;
  std::array<std::int64_t, 3> dims_{1, 1, 1};
  std::vector<std::uint32_t> start_, items_;  // bucket b holds items_[start_[b] .. start_[b+1])
};

}  // namespace smr::test
