// Region predicates of the ready-made visitors (Maheshwari et al. 3.2, 4.1-4.3).
#include "index/visitors.h"

#include <algorithm>
#include <utility>

namespace smr::index {

bool window_meets(const Box& window, const Box& box) {
  return window.intersects(box);
}

bool point_meets(double x, double y, const Box& box) {
  return !box.empty() && box.lo[0] <= x && x <= box.hi[0] && box.lo[1] <= y && y <= box.hi[1];
}

bool segment_meets(const Point3& p, const Point3& q, const Box& box) {
  constexpr double kSlack = 1e-12;
  if (box.empty()) return false;
  double t0 = 0;
  double t1 = 1;
  for (int a = 0; a < 3; ++a) {
    const double d = q[a] - p[a];
    if (d == 0) {
      if (p[a] < box.lo[a] || box.hi[a] < p[a]) return false;
      continue;
    }
    double enter = (box.lo[a] - p[a]) / d;
    double leave = (box.hi[a] - p[a]) / d;
    if (enter > leave) std::swap(enter, leave);
    t0 = std::max(t0, enter);
    t1 = std::min(t1, leave);
    if (!(t0 <= t1 + kSlack)) return false;
  }
  return true;
}

bool plane_meets(double h, const Box& box) {
  return !box.empty() && box.lo[2] <= h && h <= box.hi[2];
}

}  // namespace smr::index
