// The distance bounds of a collapse's star (the mesh builders' guaranteed error bound,
// collapse_bound.h): a branch and bound over pieces of triangles, cut by the star's spoke planes.
// Internal to smr/builders; a header so that tests can check it against brute force.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <limits>
#include <span>
#include <utility>
#include <vector>

#include <glm/geometric.hpp>

#include "smr/core/geometry.h"

namespace smr {

// The depth of the builder's branch and bound: pieces down to 1/8 of a triangle's side.
inline constexpr int kStarBoundDepth = 3;

// Upper bound of max over q in triangle (a, b, c) of min over targets k of
// (dist(q, target k) + offset k): the distance to one triangle is convex, so over a convex piece
// it is at most its largest value at the piece's corners, and the piece's bound is the least of
// these over the targets. A piece that straddles targets is also cut by the star's spoke planes
// (below); pieces are then split in four while their bound could raise `floor` and depth
// remains (branch and bound).
//
// Spoke planes. The targets are a star: triangles around one hub vertex (the new star around the
// collapse's target vertex, or the old star around the removed one). Through each spoke (an edge
// from the hub) goes a plane containing the spoke and the mean normal of the triangles on it. A
// piece cut by every spoke plane falls into convex cells; each cell gets the bound above, and
// the piece's bound is the largest cell's. This is valid for any planes (the cells cover the
// piece); these make it tight: where the two stars cover the same flat region, each cell lies in
// one target and its bound is 0, where one-target bounds over midpoint-split pieces never reach
// 0 on a seam between targets (they stop at about the piece's size over 2^depth, and the seams'
// slack added up over successive collapses: a 1 px cut of a midpoint-subdivided mesh grew 3x per
// subdivision level).
class StarDistance {
 public:
  struct Target {
    Vec3 a, b, c;
    double offset;
    TriangleDistance distance;
    Target(const Vec3& pa, const Vec3& pb, const Vec3& pc, double off)
        : a(pa), b(pb), c(pc), offset(off), distance(pa, pb, pc) {}
  };
  // Bounds to `targets` (kept by reference) around `hub`. The builder keeps one StarDistance per
  // direction and resets it for every collapse, so its buffers are allocated once.
  void reset(const std::vector<Target>& targets, const Vec3& hub) {
    targets_ = &targets;
    hub_ = hub;
    planes_.clear();
    // Spokes: the corners other than the hub, each with the normals of the targets on it.
    spokes_.clear();
    for (const Target& t : targets) {
      const std::array<const Vec3*, 3> corners{&t.a, &t.b, &t.c};
      int at = -1;
      for (int k = 0; k < 3; ++k) {
        if (*corners[k] == hub) at = k;
      }
      if (at < 0) continue;
      Vec3 n = glm::cross(t.b - t.a, t.c - t.a);
      const double len = glm::length(n);
      if (!(len > 0.0)) continue;
      n /= len;
      for (int k = 0; k < 3; ++k) {
        if (k == at) continue;
        auto it = std::find_if(spokes_.begin(), spokes_.end(),
                               [&](const auto& sp) { return sp.first == *corners[k]; });
        if (it == spokes_.end()) {
          spokes_.push_back({*corners[k], n});
        } else {
          it->second += n;
        }
      }
    }
    for (const auto& [end, normals] : spokes_) {
      const Vec3 m = glm::cross(end - hub, normals);
      const double len = glm::length(m);
      if (len > 0.0) planes_.push_back(m / len);
    }
  }

  // `first`: the target likeliest to be nearest (the piece's image under the collapse), tried
  // before the others so that most pieces stop at their first target.
  double bound(const Vec3& a, const Vec3& b, const Vec3& c, double floor, int depth,
               std::size_t first) const {
    // The corners' squared distances to the targets, computed once each: a corner of the
    // subdivision is shared by up to six pieces. Three arrays per level of the recursion, NaN
    // until computed (each level clears its own when it splits).
    const std::size_t n = targets_->size();
    cache_.resize(3 * n * std::size_t(depth + 1));
    std::fill_n(cache_.begin(), 3 * n, std::numeric_limits<double>::quiet_NaN());
    return bound({a, b, c}, {cache_.data(), cache_.data() + n, cache_.data() + 2 * n},
                 cache_.data() + 3 * n, floor, depth, first);
  }

  // The forward bound per target. Source points lie within `offset` of the piece (a, b, c); the
  // piece is cut by the spoke planes and each cell is handed to its nearest target by the corner
  // bound: that target's charge rises to offset + the bound, and its points are now assigned to
  // that target. A cell already within its nearest target's charge costs nothing; otherwise the
  // piece is split in four while depth remains. Each new triangle gets its own charge, so a
  // collapse no longer spreads the worst old bound over its whole new star.
  void charge(const Vec3& a, const Vec3& b, const Vec3& c, double offset, int depth,
              std::size_t first, std::vector<double>& charges, double& ceiling) const {
    // The cells that would raise a charge, and whether one would raise the ceiling (the
    // largest charge so far): only then is the piece split, as in bound().
    raised_.clear();
    if (!crossed(a, b, c)) {  // one cell
      const std::array<Vec3, 3> corners{a, b, c};
      const auto [v, k] = nearest(corners, offset, first, charges, ceiling);
      if (k != kFree) raised_.push_back({v, k});
    } else {
      cut(a, b, c);
      for (std::size_t i = 0; i < cells_.size(); ++i) {
        const auto [v, k] = nearest(cell(i), offset, first, charges, ceiling);
        if (k != kFree) raised_.push_back({v, k});
      }
    }
    bool above = false;
    for (const auto& [v, k] : raised_) above = above || offset + v > ceiling;
    if (!above || depth == 0) {
      for (const auto& [v, k] : raised_) {
        charges[k] = std::max(charges[k], offset + v);
        ceiling = std::max(ceiling, charges[k]);
      }
      return;
    }
    const Vec3 ab = 0.5 * (a + b), bc = 0.5 * (b + c), ca = 0.5 * (c + a);
    charge(a, ab, ca, offset, depth - 1, first, charges, ceiling);
    charge(ab, b, bc, offset, depth - 1, first, charges, ceiling);
    charge(ca, bc, c, offset, depth - 1, first, charges, ceiling);
    charge(ab, bc, ca, offset, depth - 1, first, charges, ceiling);
  }

 private:
  static constexpr std::size_t kFree = std::numeric_limits<std::size_t>::max();

  // bound() over the piece p with its corners' cached distances d2; `free` is where cache_'s
  // unused arrays begin (three per remaining depth).
  double bound(const std::array<Vec3, 3>& p, const std::array<double*, 3>& d2, double* free,
               double floor, int depth, std::size_t first) const {
    // The corners' distances: cached, NaN until computed.
    double ub = convex_bound(
        std::numeric_limits<double>::infinity(), floor, first, [&](std::size_t k, double room) {
          return corner_distance2(3, room, [&](std::size_t j) { return cached(p, d2, j, k); });
        });
    if (ub <= floor) return ub;
    ub = std::min(ub, cells_bound(p[0], p[1], p[2], ub, first));
    if (ub <= floor || depth == 0 || attained(p, d2, ub, first)) return ub;
    const std::array<Vec3, 3> mid{0.5 * (p[0] + p[1]), 0.5 * (p[1] + p[2]), 0.5 * (p[2] + p[0])};
    const std::size_t n = targets_->size();
    const std::array<double*, 3> dm{free, free + n, free + 2 * n};
    std::fill(free, free + 3 * n, std::numeric_limits<double>::quiet_NaN());
    double* rest = free + 3 * n;
    double m = floor;
    m = std::max(m,
                 bound({p[0], mid[0], mid[2]}, {d2[0], dm[0], dm[2]}, rest, m, depth - 1, first));
    m = std::max(m,
                 bound({mid[0], p[1], mid[1]}, {dm[0], d2[1], dm[1]}, rest, m, depth - 1, first));
    m = std::max(m,
                 bound({mid[2], mid[1], p[2]}, {dm[2], dm[1], d2[2]}, rest, m, depth - 1, first));
    m = std::max(m, bound({mid[0], mid[1], mid[2]}, dm, rest, m, depth - 1, first));
    return std::min(m, ub);
  }

  // Whether some point of the piece p is at least ub from every target (its distance plus the
  // target's offset): ub, an upper bound over the piece, is then its exact maximum, and
  // splitting the piece cannot lower it (it would give ub again, up to rounding). The points
  // tried are p's corners (their distances cached in d2, which the pieces of a split would need
  // anyway) and the corners of the largest cell of the last cells_bound(): those of its corners
  // that are not p's (cut points, the hub) are where a seam's maximum usually lies. Pruning
  // here took the pieces bounded per collapse from 30 to 15 on the subdivided armadillo.
  bool attained(const std::array<Vec3, 3>& p, const std::array<double*, 3>& d2, double ub,
                std::size_t first) const {
    for (std::size_t j = 0; j < 3; ++j) {
      if (reaches(ub, first, [&](std::size_t k) { return cached(p, d2, j, k); })) return true;
    }
    if (worst_cell_ == kFree) return false;
    for (const Vec3& q : cell(worst_cell_)) {
      if (reaches(ub, first, [&](std::size_t k) { return (*targets_)[k].distance.squared(q); }))
        return true;
    }
    return false;
  }
  // Corner j of piece p: its squared distance to target k, computed once (NaN until then).
  double cached(const std::array<Vec3, 3>& p, const std::array<double*, 3>& d2, std::size_t j,
                std::size_t k) const {
    double& v = d2[j][k];
    if (std::isnan(v)) v = (*targets_)[k].distance.squared(p[j]);
    return v;
  }
  // The i-th target tried: `first`, then the others in order.
  static std::size_t nth(std::size_t i, std::size_t first) {
    return i == 0 ? first : (i == first ? 0 : i);
  }
  // Whether a point, d2(k) being its squared distance to target k, is at least ub from every
  // target (offset included).
  template <class Distance2>
  bool reaches(double ub, std::size_t first, Distance2&& d2) const {
    for (std::size_t i = 0; i < targets_->size(); ++i) {
      const std::size_t k = nth(i, first);
      const double offset = (*targets_)[k].offset;
      if (offset < ub && offset + std::sqrt(d2(k)) < ub) return false;
    }
    return true;
  }

  // The target nearest the convex polygon by the corner bound (target offset + its largest
  // corner distance), or kFree as soon as a target holds it within its charge.
  template <class Corners>
  std::pair<double, std::size_t> nearest(const Corners& corners, double offset, std::size_t first,
                                         const std::vector<double>& charges, double ceiling) const {
    double best = std::numeric_limits<double>::infinity();
    std::size_t at = kFree;
    for (std::size_t i = 0; i < targets_->size(); ++i) {
      const std::size_t k = nth(i, first);
      const Target& t = (*targets_)[k];
      const double free_room = charges[k] - offset - t.offset;   // within it: free
      const double room = std::max(free_room, best - t.offset);  // beyond it: no use
      if (!(room >= 0.0)) continue;
      const double d2 = corner_distance2(t, corners, room);
      if (d2 == std::numeric_limits<double>::infinity()) continue;
      if (free_room >= 0.0 && d2 <= free_room * free_room) return {0.0, kFree};
      const double v = t.offset + std::sqrt(d2);
      if (v < best) {
        best = v;
        at = k;
        if (offset + v <= ceiling) break;  // good enough: it raises no bound past the ceiling
      }
    }
    return {best, at};
  }

  // The largest of d2(j) over the corners j < corners, or infinity once it exceeds room^2 (the
  // corners' distances are not all needed then).
  template <class Distance2>
  static double corner_distance2(std::size_t corners, double room, Distance2&& d2) {
    const double room2 = square_room(room);
    double worst = 0.0;
    for (std::size_t j = 0; j < corners; ++j) {
      worst = std::max(worst, d2(j));
      if (worst > room2) return std::numeric_limits<double>::infinity();
    }
    return worst;
  }
  // The same for the corners of a polygon and target t.
  template <class Corners>
  static double corner_distance2(const Target& t, const Corners& corners, double room) {
    return corner_distance2(corners.size(), room,
                            [&](std::size_t j) { return t.distance.squared(corners[j]); });
  }
  static double square_room(double room) {
    return room < std::numeric_limits<double>::infinity() ? room * room
                                                          : std::numeric_limits<double>::infinity();
  }

  // min over targets k of (offset + the largest distance from a corner of a convex polygon),
  // d2(k, room) being the corners' largest squared distance to target k (corner_distance2): at
  // most `ub`; stops once at most `floor`.
  template <class Distance2>
  double convex_bound(double ub, double floor, std::size_t first, Distance2&& d2) const {
    for (std::size_t i = 0; i < targets_->size(); ++i) {
      const std::size_t k = nth(i, first);
      const Target& t = (*targets_)[k];
      // Squared distances to the corners; stop once no better than a target already seen.
      const double room = ub - t.offset;
      if (room <= 0.0) continue;
      const double d = d2(k, room);
      if (!(d < room * room)) continue;
      ub = std::min(ub, t.offset + std::sqrt(d));
      if (ub <= floor) return ub;
    }
    return ub;
  }

  // The piece cut by the spoke planes: the largest of its cells' convex bounds, or `ub` as soon
  // as one cell cannot do better.
  double cells_bound(const Vec3& a, const Vec3& b, const Vec3& c, double ub,
                     std::size_t first) const {
    worst_cell_ = kFree;
    if (!crossed(a, b, c)) return ub;  // one cell: the one-target bound already computed
    cut(a, b, c);
    double worst = 0.0;
    worst_cell_ = 0;
    for (std::size_t i = 0; i < cells_.size(); ++i) {
      const std::span<const Vec3> poly = cell(i);
      const double v = convex_bound(ub, worst, first, [&](std::size_t k, double room) {
        return corner_distance2((*targets_)[k], poly, room);
      });
      if (v > worst) {
        worst = v;
        worst_cell_ = i;
      }
      if (worst >= ub) return ub;
    }
    return worst;
  }

  // Cell i of the last cut: a convex polygon.
  std::span<const Vec3> cell(std::size_t i) const {
    return {corners_.data() + cells_[i].first, cells_[i].second};
  }

  // cells_ = the triangle (a, b, c) cut by every spoke plane that crosses it (crossed(a, b, c)
  // found them). A plane that does not cross the triangle crosses none of its cells.
  void cut(const Vec3& a, const Vec3& b, const Vec3& c) const {
    corners_.assign({a, b, c});
    cells_.assign(1, {0, 3});
    for (const std::size_t k : crossing_) {
      const std::size_t n = cells_.size();
      for (std::size_t i = 0; i < n; ++i) split(i, planes_[k]);
    }
  }

  // Whether some spoke plane has corners of the piece strictly on both sides (checked before
  // any cell is made: most pieces of the branch and bound lie within one wedge); crossing_ =
  // those planes, for cut().
  bool crossed(const Vec3& a, const Vec3& b, const Vec3& c) const {
    crossing_.clear();
    for (std::size_t k = 0; k < planes_.size(); ++k) {
      if (crosses(a, b, c, planes_[k])) crossing_.push_back(k);
    }
    return !crossing_.empty();
  }
  bool crosses(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& m) const {
    const double sa = glm::dot(a - hub_, m), sb = glm::dot(b - hub_, m), sc = glm::dot(c - hub_, m);
    return std::min({sa, sb, sc}) < 0.0 && std::max({sa, sb, sc}) > 0.0;
  }

  // Splits cell i by the plane through the hub with normal m: the part below replaces it, the
  // part above is appended (when the plane crosses the cell). Both go to the end of corners_.
  void split(std::size_t i, const Vec3& m) const {
    const auto [first, count] = cells_[i];
    side_.resize(count);
    bool below = false, above = false;
    for (std::size_t k = 0; k < count; ++k) {
      side_[k] = glm::dot(corners_[first + k] - hub_, m);
      below |= side_[k] < 0.0;
      above |= side_[k] > 0.0;
    }
    if (!below || !above) return;
    // A convex polygon crosses a plane twice: each part has at most count + 2 corners. With
    // that room reserved, the cell's corners stay in place while the part below is appended.
    const std::size_t lo = corners_.size();
    corners_.reserve(lo + 2 * count + 4);
    high_.clear();
    for (std::size_t k = 0; k < count; ++k) {
      const std::size_t j = k + 1 == count ? 0 : k + 1;
      const Vec3& p = corners_[first + k];
      if (side_[k] <= 0.0) corners_.push_back(p);
      if (side_[k] >= 0.0) high_.push_back(p);
      if ((side_[k] < 0.0 && side_[j] > 0.0) || (side_[k] > 0.0 && side_[j] < 0.0)) {
        const double t = side_[k] / (side_[k] - side_[j]);
        const Vec3 x = p + t * (corners_[first + j] - p);
        corners_.push_back(x);
        high_.push_back(x);
      }
    }
    cells_[i] = {lo, corners_.size() - lo};
    cells_.push_back({corners_.size(), high_.size()});
    corners_.insert(corners_.end(), high_.begin(), high_.end());
  }

  const std::vector<Target>* targets_ = nullptr;
  Vec3 hub_{0.0};
  std::vector<std::pair<Vec3, Vec3>> spokes_;  // (far end, sum of unit normals of its targets)
  std::vector<Vec3> planes_;  // unit normals of the spoke planes (all through the hub)
  // The cells of the last cut: (first, count) in corners_ (one pool: no allocation per cell).
  mutable std::vector<std::pair<std::size_t, std::size_t>> cells_;
  mutable std::vector<Vec3> corners_, high_;
  mutable std::vector<double> side_;
  mutable std::vector<std::size_t> crossing_;  // the planes crossing the last piece (crossed())
  mutable std::vector<std::pair<double, std::size_t>> raised_;
  mutable std::vector<double> cache_;       // bound()'s corner distances
  mutable std::size_t worst_cell_ = kFree;  // cells_bound()'s largest cell (kFree: none)
};

}  // namespace smr
