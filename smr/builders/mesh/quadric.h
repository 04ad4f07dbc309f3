// Garland & Heckbert's quadric error metric (Garland & Heckbert 1997, "Surface simplification
// using quadric error metrics", sections 5 and 6.1): the squared distance to a set of planes,
// summed as one symmetric 4x4 matrix, that ranks the QEM builder's collapses (cheapest first).
#pragma once

#include <array>

#include "smr/core/geometry.h"

namespace smr::qem {

// The fundamental error quadric: the sum of w (n.p + d)^2 over planes.
struct Quadric {
  std::array<double, 10> q{};  // aa ab ac ad bb bc bd cc cd dd
  void add_plane(const Vec3& n, double d, double w) {
    const double a = n.x, b = n.y, c = n.z;
    const std::array<double, 10> t{a * a, a * b, a * c, a * d, b * b,
                                   b * c, b * d, c * c, c * d, d * d};
    for (int i = 0; i < 10; ++i) q[i] += w * t[i];
  }
  Quadric& operator+=(const Quadric& o) {
    for (int i = 0; i < 10; ++i) q[i] += o.q[i];
    return *this;
  }
  double eval(const Vec3& p) const {
    const double x = p.x, y = p.y, z = p.z;
    return q[0] * x * x + 2 * q[1] * x * y + 2 * q[2] * x * z + 2 * q[3] * x + q[4] * y * y +
           2 * q[5] * y * z + 2 * q[6] * y + q[7] * z * z + 2 * q[8] * z + q[9];
  }
};

/// The plane of triangle (a, b, c) weighted by its area (section 5); empty for a degenerate
/// triangle.
Quadric face_quadric(const Vec3& a, const Vec3& b, const Vec3& c);

/// The constraint plane of a boundary edge a -> b of a face with (unnormalized) normal `normal`
/// (section 6.1): through the edge, perpendicular to the face, weighted by `weight` times the
/// edge's squared length. False (q untouched) for a degenerate face or edge.
bool boundary_quadric(const Vec3& a, const Vec3& b, const Vec3& normal, double weight, Quadric& q);

}  // namespace smr::qem
