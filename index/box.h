// Axis-aligned boxes in 3-D (Maheshwari et al. section 3.1: the region of influence of an op is
// such a box). Closed on every side; a box with lo > hi on any axis is empty, and so is a
// default-constructed one (lo = +inf, hi = -inf), which makes `add` a plain union.
#pragma once

#include <array>
#include <limits>

namespace smr::index {

struct Box {
  static constexpr double kInf = std::numeric_limits<double>::infinity();

  std::array<double, 3> lo{kInf, kInf, kInf};
  std::array<double, 3> hi{-kInf, -kInf, -kInf};

  // The box holding exactly one point.
  static Box point(double x, double y, double z) { return Box{{x, y, z}, {x, y, z}}; }

  bool empty() const {
    // Written with `!(lo <= hi)` so that a NaN coordinate also counts as empty.
    for (int a = 0; a < 3; ++a) {
      if (!(lo[a] <= hi[a])) return true;
    }
    return false;
  }
  // Grows this box to contain `other` (no-op when `other` is empty).
  void add(const Box& other) {
    if (other.empty()) return;
    for (int a = 0; a < 3; ++a) {
      if (other.lo[a] < lo[a]) lo[a] = other.lo[a];
      if (other.hi[a] > hi[a]) hi[a] = other.hi[a];
    }
  }
  // Closed-box overlap; false when either box is empty.
  bool intersects(const Box& other) const {
    if (empty() || other.empty()) return false;
    for (int a = 0; a < 3; ++a) {
      if (other.hi[a] < lo[a] || hi[a] < other.lo[a]) return false;
    }
    return true;
  }
  // True when `other` lies inside this box; an empty `other` is contained in anything.
  bool contains(const Box& other) const {
    if (other.empty()) return true;
    if (empty()) return false;
    for (int a = 0; a < 3; ++a) {
      if (other.lo[a] < lo[a] || hi[a] < other.hi[a]) return false;
    }
    return true;
  }
  bool operator==(const Box&) const = default;
};

}  // namespace smr::index
