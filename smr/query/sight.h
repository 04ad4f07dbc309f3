// Line of sight and elevation profiles (Maheshwari et al. 4.3: visibility is the selective
// refinement of a 3-D segment, stopped at the first blocking triangle; a profile is that of the
// vertical walls over a polyline's legs).
//
// Line of sight between p and q descends the DAG along the segment (sight.cpp): its x-y path is
// cut into spans, one per triangle, taken in order from p. A final triangle decides its span:
// clear where the segment runs more than err_final above it, blocked more than err_final below,
// undecided in between (never for a lossless database: err_final = 0). A coarse triangle is
// refined into its killer's fragment unless the segment clears the killer's ROI, which holds
// every triangle refining it (Maheshwari 3.1); with Accuracy::within(E) a coarse triangle of error
// <= E whose band the segment enters (without going under it) leaves its span undecided instead.
// The walk stops at the first certain block and refines nothing beyond it.
//
// Why not refine(SightRegion) and walk the result: a coarse triangle's error bounds its distance
// to the grid samples under it, not to the finest mesh between them (a finer triangulation crosses
// its edges; on the test DEMs the finest mesh strays from a coarse triangle up to 7-85 times its
// error), so the band cannot prove a stretch clear or blocked. Refining by SightRegion
// and deciding on the bands answered 0.1-1.3 % of random pairs wrongly at the finest accuracy
// (2-7 % within 4x the build error) against brute force on the finest mesh; the ROI is sound. The
// descent also reads about 4 times fewer ops than that refinement (fbm 4097^2 database).
//
// Profile along a polyline: refine the walls over its legs (PathRegion per leg, UnionRegion; the
// result is one conforming mesh, so the profile is continuous), then cut each leg at every
// triangle edge it crosses: between those breakpoints the surface is linear. At the finest
// accuracy the profile is the finest mesh's; within E, every piece's triangle has error <= E (as
// region.h defines it: against the grid samples under it).
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include "smr/core/op_source.h"
#include "smr/query/region.h"

namespace smr::query {

/// The 3-D segment pq as a query region (Maheshwari 4.3). A triangle with error e meets it when,
/// over the triangle's x-y footprint, the segment's height minus the triangle's plane (linear
/// along the segment) is neither everywhere > e nor everywhere < -e: the segment may come within
/// e of it. A box meets it when the segment meets the box grown by e in z. Both with a small
/// relative slack, conservative and monotone. refine() with it gives the mesh around a sight line
/// under region.h's meaning of an error (the grid samples); line_of_sight uses its box test on
/// ROIs, where it is sound for the finest mesh too.
class SightRegion final : public Region {
 public:
  SightRegion(const Vec3& p, const Vec3& q) : p_(p), q_(q) {}
  std::string describe() const override;
  bool triangle_meets(const Triangle3& v, double error) const override;
  bool box_meets(const Box3& box, double error) const override;
  bool depends_on_height() const override { return true; }

 private:
  Vec3 p_, q_;
};

enum class Sight : std::uint8_t {
  kVisible,    // the segment runs above every triangle's error band over the whole way
  kBlocked,    // the segment certainly passes below the surface (at blocked_at)
  kUndecided,  // no certain block, but the segment passes within the error band (undecided_at)
};
const char* to_string(Sight s);

struct SightAnswer {
  Sight sight = Sight::kVisible;
  Vec3 p{0.0}, q{0.0};
  /// kBlocked: the first point of pq below the surface by more than the surface's error there
  /// (exactly where pq goes under the surface when that error is 0).
  Vec3 blocked_at{0.0};
  /// The first point of pq within the error band of the surface, before blocked_at (or anywhere
  /// for kUndecided): from here on the segment may touch or pass under the true surface. Absent
  /// when the band is never entered (always for exact answers: error 0).
  std::optional<Vec3> undecided_at;
  /// The first point of pq over no data (a void triangle of the finest mesh) before the walk
  /// stopped. No data never blocks: the answer speaks for the parts with data. Spans proven
  /// clear by a ROI are not searched for no data, so a sliver of no data between grid samples
  /// under a coarse triangle with data may go unreported.
  std::optional<Vec3> no_data_at;
  /// The largest error of a triangle whose band the segment entered before the walk stopped (the
  /// stretches the answer leaves undecided, or decides within that error): <= max(accuracy,
  /// err_final); err_final (or 0) at Accuracy::finest(), 0 for an exact answer.
  double error_bound = 0.0;
  std::uint64_t ops = 0;               // distinct ops read
  std::uint64_t triangles_tested = 0;  // spans settled (triangles over the path)
  double seconds = 0.0;
};

/// Whether q is visible from p: both are 3-D points in the source's coordinates (x-y as the
/// terrain's georef, z in data units). Throws smr::Error (kInvalidInput) for an end outside the
/// domain (naming it and the domain) or a 3-D mesh source.
SightAnswer line_of_sight(const OpSource& source, const Vec3& p, const Vec3& q,
                          const Accuracy& accuracy);

/// A breakpoint of a profile: a polyline vertex or a crossing of a leg with a triangle edge.
struct ProfilePoint {
  double distance = 0.0;  // along the polyline from its first point, in x-y (georef units)
  Vec3 p{0.0};            // z: the surface height (NaN where no data lies on either side)
  std::uint32_t leg = 0;  // the leg the piece from this point on belongs to
  /// The piece from this point to the next one (the last point: the piece ending here): the error
  /// bound of its triangle and whether it lies over data. The surface is linear along a piece.
  double error_bound = 0.0;
  bool has_data = true;
};

struct ProfileResult {
  std::vector<ProfilePoint> points;  // ordered by distance
  double error_bound = 0.0;          // the largest over pieces with data
  std::uint64_t ops = 0;             // |X| of the refinement
  std::uint64_t triangles = 0;       // pieces before merging duplicates along shared edges
  double seconds = 0.0;
};

/// The exact piecewise-linear profile of the surface (the finest mesh, or within
/// accuracy.max_error) along the polyline. Throws smr::Error (kInvalidInput) for fewer than two
/// points, a point outside the domain, or a 3-D mesh source.
ProfileResult profile(const OpSource& source, std::span<const Vec2> polyline,
                      const Accuracy& accuracy);

}  // namespace smr::query
