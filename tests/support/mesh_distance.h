// Brute-force-exact distances to a triangle soup, for the 3-D error-bound oracle: the distance
// from a point to the nearest triangle, found through a uniform grid of buckets (every triangle
// is in each bucket its box meets; rings of buckets are searched outwards until no farther
// bucket can hold a nearer triangle), so the answer equals the minimum over all triangles.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "smr/core/geometry.h"

namespace smr::test {

class TriangleSoupDistance {
 public:
  explicit TriangleSoupDistance(std::vector<std::array<Vec3, 3>> triangles);
  /// min over triangles of the distance from p to the closed triangle.
  double distance(const Vec3& p) const { return search(p, -1.0); }
  /// distance(p) <= radius, searching only the buckets within `radius` of p.
  bool within(const Vec3& p, double radius) const { return search(p, radius) <= radius; }

 private:
  std::array<std::int64_t, 3> cell_of(const Vec3& p) const;
  // The distance, or (radius >= 0) any value <= radius once one is found, or > radius when none.
  double search(const Vec3& p, double radius) const;
  std::vector<std::array<Vec3, 3>> tris_;
  Box3 box_;
  double cell_ = 1.0;
  std::array<std::int64_t, 3> dims_{1, 1, 1};
  std::vector<std::uint32_t> start_, items_;  // bucket b holds items_[start_[b] .. start_[b+1])
};

}  // namespace smr::test
