#include "smr/builders/mesh/exact_intersection.h"

#include <algorithm>
#include <array>

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/intersections.h>
#include <glm/common.hpp>
#include <glm/geometric.hpp>

namespace smr {

namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = K::Point_3;

Point point(const Vec3& v) {
  return {v.x, v.y, v.z};
}

// The plane through a point o spanned by u and w (its normal computed once); points are given
// as their offsets d from o.
struct Plane {
  Plane(const Vec3& u, const Vec3& w) : n(glm::cross(u, w)), uw2(glm::dot(u, u) * glm::dot(w, w)) {}
  // +1 or -1 when d's side is certain in double arithmetic (the determinant's error is far
  // below 1e-12 of the product of the lengths, the differences of exact inputs being correctly
  // rounded), 0 when d may lie on the plane.
  int side(const Vec3& d) const {
    const double det = glm::dot(n, d);
    if (det * det <= 1e-24 * uw2 * glm::dot(d, d)) return 0;
    return det > 0.0 ? 1 : -1;
  }
  // Whether every d lies strictly on one side, as far as double arithmetic can tell: then none
  // meets the plane.
  template <class... D>
  bool strictly_one_side(const D&... d) const {
    const std::array<int, sizeof...(D)> s{side(d)...};
    for (int x : s) {
      if (x == 0 || x != s[0]) return false;
    }
    return true;
  }
  Vec3 n;
  double uw2;
};

// Whether the projections of a and b on the coordinate plane most nearly parallel to a (whose
// normal is n_a) are certainly apart, as far as double arithmetic can tell: a line through an
// edge of either has the other's corners strictly on its far side, the corners at `shared` (the
// corner both have, or none) excepted, which must lie on that line. Then a and b share at most
// that corner in space too: a point of both projects into both projections, where only the
// shared corner lies, and the projection is one-to-one on a. Decides the coplanar pairs of flat
// regions, whose exact predicates otherwise fall back to multiprecision arithmetic.
bool projections_apart(const MeshTriangle& a, const MeshTriangle& b, const Vec3& n_a,
                       const Vec3* shared) {
  const Vec3 m = glm::abs(n_a);
  if (!(std::max({m.x, m.y, m.z}) > 0.0)) return false;
  const int drop = m.x >= m.y && m.x >= m.z ? 0 : (m.y >= m.z ? 1 : 2);
  // Both triangles' corners projected once: [0][k] a's, [1][k] b's; is_shared likewise.
  std::array<std::array<Vec2, 3>, 2> flat{};
  std::array<std::array<bool, 3>, 2> is_shared{};
  const std::array<const MeshTriangle*, 2> t{&a, &b};
  for (std::size_t s = 0; s < 2; ++s) {
    for (std::size_t k = 0; k < 3; ++k) {
      const Vec3& v = t[s]->p[k];
      flat[s][k] = drop == 0 ? Vec2(v.y, v.z) : drop == 1 ? Vec2(v.z, v.x) : Vec2(v.x, v.y);
      is_shared[s][k] = shared != nullptr && v == *shared;
    }
  }
  // The side of x from the line p -> q: +1 or -1 when certain, 0 when x may lie on it.
  const auto side = [](const Vec2& p, const Vec2& q, const Vec2& x) {
    const double det = orient2d(p, q, x);
    if (det * det <= 1e-24 * glm::dot(q - p, q - p) * glm::dot(x - p, x - p)) return 0;
    return det > 0.0 ? 1 : -1;
  };
  for (std::size_t s = 0; s < 2; ++s) {
    const std::array<Vec2, 3>& own = flat[s];
    for (std::size_t k = 0; k < 3; ++k) {
      const std::size_t j = (k + 1) % 3;
      // With a shared corner, only a line through it can separate.
      if (shared != nullptr && !is_shared[s][k] && !is_shared[s][j]) continue;
      const int inner = side(own[k], own[j], own[(k + 2) % 3]);
      if (inner == 0) continue;
      bool apart = true;
      for (std::size_t x = 0; x < 3 && apart; ++x) {
        apart = is_shared[1 - s][x] || side(own[k], own[j], flat[1 - s][x]) == -inner;
      }
      if (apart) return true;
    }
  }
  return false;
}

}  // namespace

bool triangles_cross(const MeshTriangle& a, const MeshTriangle& b) {
  // Shared corners: a.p[ka[i]] is b.p[kb[i]] (the same vertex id, or the same position).
  std::array<int, 3> ka{}, kb{};
  int shared = 0;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      const auto si = std::size_t(i), sj = std::size_t(j);
      if (a.id[si] == b.id[sj] || a.p[si] == b.p[sj]) {
        ka[std::size_t(shared)] = i;
        kb[std::size_t(shared)] = j;
        ++shared;
        break;
      }
    }
  }
  const auto pa_ = [&](int k) -> const Vec3& { return a.p[std::size_t(k % 3)]; };
  const auto pb_ = [&](int k) -> const Vec3& { return b.p[std::size_t(k % 3)]; };
  // A quick separation in double before the exact predicates: most pairs the builder tests are
  // neighbours whose other corners lie clearly off each other's plane.
  const Plane plane_a(pa_(1) - pa_(0), pa_(2) - pa_(0)), plane_b(pb_(1) - pb_(0), pb_(2) - pb_(0));
  if (shared == 0) {
    if (plane_b.strictly_one_side(pa_(0) - pb_(0), pa_(1) - pb_(0), pa_(2) - pb_(0)) ||
        plane_a.strictly_one_side(pb_(0) - pa_(0), pb_(1) - pa_(0), pb_(2) - pa_(0)) ||
        projections_apart(a, b, plane_a.n, nullptr)) {
      return false;
    }
  } else if (shared == 1) {
    // Both other corners of one triangle strictly on one side of the other's plane: it meets
    // that plane only in the shared corner.
    const Vec3& v = pa_(ka[0]);
    if (plane_b.strictly_one_side(pa_(ka[0] + 1) - v, pa_(ka[0] + 2) - v) ||
        plane_a.strictly_one_side(pb_(kb[0] + 1) - v, pb_(kb[0] + 2) - v) ||
        projections_apart(a, b, plane_a.n, &v)) {
      return false;
    }
  } else if (shared == 2) {
    // Not coplanar, or third corners clearly on opposite sides of the shared edge (across the
    // plane of a, whatever the dihedral angle): a shared edge is all they can share.
    const Vec3& u = pa_(ka[0]);
    const Vec3 e = pa_(ka[1]) - u, r = pa_(3 - ka[0] - ka[1]) - u, t = pb_(3 - kb[0] - kb[1]) - u;
    if (plane_b.side(pa_(3 - ka[0] - ka[1]) - pb_(0)) != 0) return false;
    // The sides of the plane through the edge perpendicular to a: dot(e x (e x x), x') =
    // (e.r)(e.t) - (e.e)(r.t) for t, which is -|e|^2 |r|^2 sin^2 < 0 for r.
    const double ee = glm::dot(e, e), er = glm::dot(e, r), et = glm::dot(e, t);
    const double rr = glm::dot(r, r), tt = glm::dot(t, t), rt = glm::dot(r, t);
    const double dr = er * er - ee * rr, dt = er * et - ee * rt;
    if (dr * dr > 1e-24 * ee * ee * rr * rr && dr < 0.0 && dt * dt > 1e-24 * ee * ee * rr * tt &&
        dt > 0.0) {
      return false;
    }
  }

  const std::array<Point, 3> pa{point(pa_(0)), point(pa_(1)), point(pa_(2))};
  const std::array<Point, 3> pb{point(pb_(0)), point(pb_(1)), point(pb_(2))};
  if (CGAL::collinear(pa[0], pa[1], pa[2]) || CGAL::collinear(pb[0], pb[1], pb[2])) return false;
  const K::Triangle_3 ta(pa[0], pa[1], pa[2]), tb(pb[0], pb[1], pb[2]);
  switch (shared) {
    case 0:
      return CGAL::do_intersect(ta, tb);
    case 1: {
      // The planes meet in a line through the shared corner; if the triangles share more than
      // that corner, their common segment starts there and leaves one of them through its edge
      // opposite the corner, which then meets the other triangle.
      const K::Segment_3 ea(pa[std::size_t((ka[0] + 1) % 3)], pa[std::size_t((ka[0] + 2) % 3)]);
      const K::Segment_3 eb(pb[std::size_t((kb[0] + 1) % 3)], pb[std::size_t((kb[0] + 2) % 3)]);
      return CGAL::do_intersect(ea, tb) || CGAL::do_intersect(eb, ta);
    }
    case 2: {
      // A shared edge u-w: the triangles overlap only when they are coplanar and their third
      // corners lie on the same side of it (folded onto each other).
      const Point& u = pa[std::size_t(ka[0])];
      const Point& w = pa[std::size_t(ka[1])];
      const Point& r = pa[std::size_t(3 - ka[0] - ka[1])];
      const Point& t = pb[std::size_t(3 - kb[0] - kb[1])];
      return CGAL::coplanar(u, w, r, t) && CGAL::coplanar_orientation(u, w, r, t) == CGAL::POSITIVE;
    }
    default:
      return true;  // the same triangle twice
  }
}

}  // namespace smr
