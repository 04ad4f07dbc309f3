// Morton (Z-order) codes of points in a box: the order the mesh builders lay vertices and octree
// cells out in, so that neighbours lie close in memory (the octree blocks of the out-of-core
// builder, Hoppe 1998's block construction in 3-D, are runs of this order).
#pragma once

#include <algorithm>
#include <cstdint>

#include "smr/core/geometry.h"

namespace smr::qem {

// Spreads the low 21 bits of x to every third bit (Morton order).
inline std::uint64_t spread3(std::uint64_t x) {
  x &= 0x1fffff;
  x = (x | x << 32) & 0x1f00000000ffffULL;
  x = (x | x << 16) & 0x1f0000ff0000ffULL;
  x = (x | x << 8) & 0x100f00f00f00f00fULL;
  x = (x | x << 4) & 0x10c30c30c30c30c3ULL;
  x = (x | x << 2) & 0x1249249249249249ULL;
  return x;
}

// The Morton code of p in the box lo + [0, extent] (21 bits per axis; a flat axis is 0).
inline std::uint64_t morton_code(const Vec3& p, const Vec3& lo, const Vec3& extent) {
  std::uint64_t code = 0;
  for (int a = 0; a < 3; ++a) {
    const double u = extent[a] > 0.0 ? (p[a] - lo[a]) / extent[a] : 0.0;
    code |= spread3(static_cast<std::uint64_t>(std::clamp(u, 0.0, 1.0) * 2097151.0)) << a;
  }
  return code;
}

}  // namespace smr::qem
