// The grid samples of a closed triangle with integer corners, row by row, exactly: a sample
// belongs to the triangle iff it lies in the closed triangle. Row spans come from integer edge
// steppers (no division per row). Shared by the terrain builders' error scans.
#pragma once

#include <algorithm>
#include <cstdint>
#include <utility>

namespace smr::build {

inline std::int64_t floor_div(std::int64_t n, std::int64_t d) {  // d > 0
  std::int64_t q = n / d;
  if ((n % d != 0) && (n < 0)) --q;
  return q;
}

/// x(row) = q + r / den (0 <= r < den) along an edge, exactly, stepped one row at a time.
struct EdgeStepper {
  std::int64_t q = 0, r = 0, den = 1, dq = 0, dr = 0;
  // The edge from (xa, ya) to (xb, yb), yb > ya, at row `row`.
  EdgeStepper(std::int64_t xa, std::int64_t ya, std::int64_t xb, std::int64_t yb, std::int64_t row)
      : den(yb - ya) {
    const std::int64_t dx = xb - xa;
    const std::int64_t num = xa * den + (row - ya) * dx;
    q = floor_div(num, den);
    r = num - q * den;
    dq = floor_div(dx, den);
    dr = dx - dq * den;
  }
  EdgeStepper() = default;
  std::int64_t floor() const { return q; }
  std::int64_t ceil() const { return q + (r != 0); }
  void step() {
    q += dq;
    r += dr;
    if (r >= den) {
      r -= den;
      ++q;
    }
  }
};

/// Row spans of the closed triangle (x[k], y[k]): vertices sorted by row (s0 <= s1 <= s2); the
/// long edge s0-s2 bounds every row, the edge s0-s1 the rows above s1 and s1-s2 the rows below.
/// Call next(xl, xr) once per row from ymin() to ymax(); xl > xr means an empty row.
class TriangleRows {
 public:
  /// The triangle must not be degenerate in y (ymin < ymax).
  TriangleRows(const std::int64_t x[3], const std::int64_t y[3]) {
    int s0 = 0, s1 = 1, s2 = 2;
    if (y[s0] > y[s1]) std::swap(s0, s1);
    if (y[s1] > y[s2]) std::swap(s1, s2);
    if (y[s0] > y[s1]) std::swap(s0, s1);
    ymin_ = y[s0];
    ymid_ = y[s1];
    ymax_ = y[s2];
    xmid_ = x[s1];
    lng_ = EdgeStepper(x[s0], ymin_, x[s2], ymax_, ymin_);
    if (ymid_ > ymin_) up_ = EdgeStepper(x[s0], ymin_, x[s1], ymid_, ymin_);
    if (ymax_ > ymid_) down_ = EdgeStepper(x[s1], ymid_, x[s2], ymax_, ymid_);
    row_ = ymin_;
  }
  std::int64_t ymin() const { return ymin_; }
  std::int64_t ymax() const { return ymax_; }
  /// The span of the current row, then moves to the next row.
  void next(std::int64_t& xl, std::int64_t& xr) {
    if (row_ < ymid_) {
      xl = std::min(lng_.ceil(), up_.ceil());
      xr = std::max(lng_.floor(), up_.floor());
      up_.step();
    } else if (row_ > ymid_) {
      xl = std::min(lng_.ceil(), down_.ceil());
      xr = std::max(lng_.floor(), down_.floor());
      down_.step();
    } else {
      xl = std::min(lng_.ceil(), xmid_);
      xr = std::max(lng_.floor(), xmid_);
      if (ymax_ > ymid_) down_.step();
    }
    lng_.step();
    ++row_;
  }

 private:
  std::int64_t ymin_ = 0, ymid_ = 0, ymax_ = 0, xmid_ = 0, row_ = 0;
  EdgeStepper lng_, up_, down_;
};

}  // namespace smr::build
