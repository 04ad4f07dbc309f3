// Elevation at a point (Maheshwari et al. 4.1: point location is the query of a vertical line).
// A vertical line needs no mesh around it, only the triangle above the point at each level of
// the hierarchy, so the query is a descent through the DAG: the triangle of F(R^0) containing the
// point, then, while it is not fine enough, the triangle of F(killer) containing it (F(K) covers
// PreF(K)'s domain, 2.5-D ops being complete, Brown 4.5), one op read per level. The answer is a
// height of a triangle of a valid mesh of the CRMR, with the error that triangle carries: the
// finest mesh (err_final, 0 for a lossless database) or the first triangle within max_error.
#pragma once

#include <cstdint>
#include <functional>
#include <span>
#include <vector>

#include "smr/core/op_source.h"
#include "smr/query/region.h"

namespace smr::query {

struct ElevationAnswer {
  Vec2 p{0.0};
  bool has_data = false;     // false: the point lies on "no data" (a void triangle)
  double z = 0.0;            // the surface height at p (meaningless without data)
  double error_bound = 0.0;  // |z - source| <= error_bound at p's grid samples (see header)
  bool final = false;        // the triangle belongs to the finest mesh
  TriRef triangle;           // the triangle answering
  std::uint32_t ops_read = 0;
};

/// Answers elevation queries on a terrain source (a database, or an in-memory CRMR). Keeps the
/// ops of the last descent (at most the DAG's depth of them, and the pages they sit in), so the
/// next point reuses the levels it shares without asking the source: answers are the same as
/// from a fresh descent. Thread-compatible (one per thread).
class ElevationQuery {
 public:
  /// Throws smr::Error (kInvalidInput) for a 3-D mesh source.
  explicit ElevationQuery(const OpSource& source);
  /// The elevation at p in the source's coordinates. A point outside the grid's extent throws
  /// smr::Error (kInvalidInput) naming it and the extent.
  ElevationAnswer at(const Vec2& p, const Accuracy& accuracy) const;
  /// A batch: one answer per point, in the points' order, answered in Hilbert order of the
  /// points so that neighbours share their descents and pages (the page cache then holds the
  /// working set of a sweep instead of thrashing on random points). Throws like at() for the
  /// first point (in input order) outside the domain, before answering any.
  std::vector<ElevationAnswer> at_many(std::span<const Vec2> points,
                                       const Accuracy& accuracy) const;
  /// The same, handing each answer with its index in `points` to `take` (in Hilbert order), so
  /// a caller keeps only what it needs of each.
  void at_many(std::span<const Vec2> points, const Accuracy& accuracy,
               const std::function<void(std::size_t, const ElevationAnswer&)>& take) const;
  const Domain& domain() const { return domain_; }
  /// Throws at()'s error if p is outside the domain.
  void check_inside(const Vec2& p) const;

 private:
  OpRef fetch(std::size_t level, OpId id) const;
  ElevationAnswer descend(const Vec2& p, const Accuracy& accuracy) const;  // p inside

  const OpSource& source_;
  Domain domain_;
  mutable std::vector<OpRef> path_;  // path_[k]: the op read at level k of the last descent
};

/// The triangle of F(op) whose x-y footprint contains p (closed, with a relative tolerance of
/// 1e-9 of its size), preferring one with data; else the nearest one if p lies within 1e-6 of
/// its size outside it (rounding on the domain's boundary); -1 if none.
int locate_in_fragment(const OpView& op, const Vec2& p);

/// The height at p of the plane through the triangle with corners v.
double interpolate(const Triangle3& v, const Vec2& p);

}  // namespace smr::query
