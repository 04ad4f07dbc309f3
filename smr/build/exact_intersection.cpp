#include "smr/build/exact_intersection.h"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/intersections.h>
#include <glm/geometric.hpp>

namespace smr {

namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = K::Point_3;

Point point(const Vec3& v) {
  return {v.x, v.y, v.z};
}

// The side of plane (o, o + u, o + w) that p - o lies on: +1 or -1 when certain in double
// arithmetic (the error of the determinant is far below 1e-12 of the product of the lengths,
// the differences of exact inputs being correctly rounded), 0 when it may be on the plane.
int side(const Vec3& u, const Vec3& w, const Vec3& d) {
  const double det = glm::dot(glm::cross(u, w), d);
  const double room2 = 1e-24 * glm::dot(u, u) * glm::dot(w, w) * glm::dot(d, d);
  if (det * det <= room2) return 0;
  return det > 0.0 ? 1 : -1;
}

// Whether all of `corners` (minus o) lie strictly on one side of the plane through o spanned
// by u and w, as far as double arithmetic can tell: then they cannot meet the plane.
template <class... D>
bool strictly_one_side(const Vec3& u, const Vec3& w, const D&... d) {
  const std::array<int, sizeof...(D)> s{side(u, w, d)...};
  for (int x : s) {
    if (x == 0 || x != s[0]) return false;
  }
  return true;
}

}  // namespace

bool triangles_cross(const MeshTriangle& a, const MeshTriangle& b) {
  // A quick separation in double before the exact predicates: most pairs the builder tests are
  // neighbours whose other corners lie clearly off each other's plane.
  {
    std::array<int, 3> ka{-1, -1, -1};
    int shared = 0;
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) {
        if (a.id[std::size_t(i)] == b.id[std::size_t(j)]) ka[std::size_t(shared++)] = i;
      }
    }
    const Vec3 &a0 = a.p[0], &b0 = b.p[0];
    const Vec3 au = a.p[1] - a0, aw = a.p[2] - a0, bu = b.p[1] - b0, bw = b.p[2] - b0;
    if (shared == 0) {
      if (strictly_one_side(bu, bw, a.p[0] - b0, a.p[1] - b0, a.p[2] - b0) ||
          strictly_one_side(au, aw, b.p[0] - a0, b.p[1] - a0, b.p[2] - a0)) {
        return false;
      }
    } else if (shared == 1) {
      // Both other corners of one triangle strictly on one side of the other's plane: it meets
      // that plane only in the shared corner.
      const Vec3& v = a.p[std::size_t(ka[0])];
      const Vec3& a1 = a.p[std::size_t((ka[0] + 1) % 3)];
      const Vec3& a2 = a.p[std::size_t((ka[0] + 2) % 3)];
      std::array<Vec3, 2> bo{};
      int n = 0;
      for (int j = 0; j < 3; ++j) {
        if (b.id[std::size_t(j)] != a.id[std::size_t(ka[0])])
          bo[std::size_t(n++)] = b.p[std::size_t(j)];
      }
      if (strictly_one_side(bu, bw, a1 - v, a2 - v) ||
          strictly_one_side(au, aw, bo[0] - v, bo[1] - v)) {
        return false;
      }
    } else if (shared == 2) {
      // Not coplanar: a shared edge is all they can share.
      const Vec3& r = a.p[std::size_t(3 - ka[0] - ka[1])];
      for (int j = 0; j < 3; ++j) {
        const std::uint32_t id = b.id[std::size_t(j)];
        if (id != a.id[std::size_t(ka[0])] && id != a.id[std::size_t(ka[1])]) {
          if (side(bu, bw, r - b0) != 0) return false;
        }
      }
    }
  }
  const std::array<Point, 3> pa{point(a.p[0]), point(a.p[1]), point(a.p[2])};
  const std::array<Point, 3> pb{point(b.p[0]), point(b.p[1]), point(b.p[2])};
  if (CGAL::collinear(pa[0], pa[1], pa[2]) || CGAL::collinear(pb[0], pb[1], pb[2])) return false;
  // Shared corners: ka[i] in a matches kb[i] in b.
  std::array<int, 3> ka{}, kb{};
  int shared = 0;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      if (a.id[i] == b.id[j]) {
        ka[shared] = i;
        kb[shared] = j;
        ++shared;
      }
    }
  }
  const K::Triangle_3 ta(pa[0], pa[1], pa[2]), tb(pb[0], pb[1], pb[2]);
  switch (shared) {
    case 0:
      return CGAL::do_intersect(ta, tb);
    case 1: {
      // The planes meet in a line through the shared corner; if the triangles share more than
      // that corner, their common segment starts there and leaves one of them through its edge
      // opposite the corner, which then meets the other triangle.
      const K::Segment_3 ea(pa[(ka[0] + 1) % 3], pa[(ka[0] + 2) % 3]);
      const K::Segment_3 eb(pb[(kb[0] + 1) % 3], pb[(kb[0] + 2) % 3]);
      return CGAL::do_intersect(ea, tb) || CGAL::do_intersect(eb, ta);
    }
    case 2: {
      // A shared edge u-w: the triangles overlap only when they are coplanar and their third
      // corners lie on the same side of it (folded onto each other).
      const Point& u = pa[ka[0]];
      const Point& w = pa[ka[1]];
      const Point& r = pa[3 - ka[0] - ka[1]];
      const Point& s = pb[3 - kb[0] - kb[1]];
      return CGAL::coplanar(u, w, r, s) && CGAL::coplanar_orientation(u, w, r, s) == CGAL::POSITIVE;
    }
    default:
      return true;  // the same triangle twice
  }
}

}  // namespace smr
