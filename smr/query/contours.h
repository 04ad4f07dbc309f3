// Contour lines (isolines) from a terrain database: Maheshwari et al. 4.2, the selective refinement
// whose query region is the plane z = h (here a set of planes), then the triangles of the result
// that meet a plane, walked into polylines.
//
// Refinement (region.h, HeightRegionRcf): an op whose ROI spans a level must be applied unless its
// error is within Accuracy::max_error; elsewhere the mesh stays coarse. A triangle left coarse has
// a killer whose ROI (holding every triangle that refines it) spans no level, so nothing finer
// crosses a level over it: at Accuracy::finest() the lines are exactly the finest mesh's contours.
// (A triangle's own error band would not do: the finest triangles under a coarse one cross its
// edges and can leave its band between the samples under it.)
//
// Marching: for each level h and each triangle with data, a corner with z >= h counts as above h
// and one with z < h as below (symbolic perturbation: a corner exactly at h is above). A triangle
// with corners on both sides gives one segment, between the points where h crosses its two edges
// that join a corner below to one above (interpolated from the corner below, so both triangles of
// an edge compute the same point bit for bit). Vertices are shared by id across fragments
// (smr::VertexId), so segments join exactly by edge key (level, below id, above id).
//
// Where a level passes through a vertex at exactly h, consecutive points repeat: each is written
// once, except in a line that is a single point (a peak, or a boundary vertex, at exactly h: the
// perturbed surface's vanishing ring, where gdal_contour writes a tiny one), written as two equal
// points. A ridge at exactly h between lower ground gives a line that runs along it and back (the
// perturbed surface's thin sliver above h).
//
// Lines: each runs with higher ground on its LEFT (the surface >= h lies to the left, below h to
// the right): rings around hills run counter-clockwise, rings around pits clockwise. A line is a
// closed ring (first point == last point, bit for bit) or open, ending on the domain boundary or at
// a no-data hole (a void triangle). Each carries the error bound it holds: the largest
// triangle_error (region.h) of the triangles it crosses. The line is the exact contour at h of the
// refined mesh, whose triangles there lie within that bound (vertically) of every source sample
// under them; 0 on a lossless database at Accuracy::finest(). (Between samples the finest mesh
// may stray further from a coarse triangle: the finest triangles under it do not nest in it.)
#pragma once

#include <cstdint>
#include <optional>
#include <ostream>
#include <string>
#include <vector>

#include "smr/core/op_source.h"
#include "smr/query/region.h"

namespace smr::query {

/// The levels of a contour query as a query region (Maheshwari 4.2): an increasing sequence
/// level(k) over integers k, given explicitly or as every base + k * interval. Lookups are binary
/// searches (explicit) or arithmetic (interval), never a loop over the levels.
class LevelsRegion final : public Region {
 public:
  /// Explicit levels, in any order (duplicates merged). kInvalidInput when empty or not finite.
  static LevelsRegion at(std::vector<double> levels);
  /// Every base + k * interval, k any integer (gdal_contour -i interval -off base).
  /// kInvalidInput unless interval > 0 and both are finite.
  static LevelsRegion every(double interval, double base = 0.0);

  std::string describe() const override;
  /// Some level lies in [min z - error, max z + error] of the triangle.
  bool triangle_meets(const Triangle3& v, double error) const override;
  /// Some level lies in [box.lo.z - error, box.hi.z + error].
  bool box_meets(const Box3& box, double error) const override;
  bool depends_on_height() const override { return true; }

  /// Level k (explicit levels: 0 <= k < their count).
  double level(std::int64_t k) const;
  /// The smallest k with level(k) >= z (explicit levels: their count when there is none).
  std::int64_t first_at_or_above(double z) const;
  /// The smallest k with level(k) > z (explicit levels: their count when there is none).
  std::int64_t first_above(double z) const;
  /// The number of levels in [lo, hi].
  std::uint64_t count_in(double lo, double hi) const;

 private:
  LevelsRegion() = default;
  bool meets(double lo, double hi) const { return first_at_or_above(lo) < first_above(hi); }
  std::int64_t first_where(double z, bool strictly_above) const;  // an interval's lookups
  std::vector<double> levels_;  // explicit, sorted, unique; empty: an interval
  double interval_ = 0.0, base_ = 0.0;
};

struct ContourOptions {
  std::vector<double> levels;      // explicit levels (gdal_contour -fl), or
  std::optional<double> interval;  // every base + k * interval (gdal_contour -i, -off)
  double base = 0.0;
  /// finest(): the finest mesh's contours (the source's, for a lossless database). within(E):
  /// triangles crossed are within E (fewer ops read, fewer and shorter lines).
  Accuracy accuracy;
};

/// The region `o` asks for; kInvalidInput for no levels, both levels and an interval, or a bad
/// interval or level (LevelsRegion::at, ::every).
LevelsRegion levels_region(const ContourOptions& o);

struct ContourLine {
  double level = 0.0;
  double error = 0.0;   // the largest triangle_error of the triangles it crosses
  bool closed = false;  // a ring: points.front() == points.back()
  std::vector<Vec2> points;
};

struct ContourStats {
  std::uint64_t levels = 0;             // levels within the data's height range (info().bounds)
  std::uint64_t ops = 0;                // |X| of the refinement
  std::uint64_t triangles = 0;          // in the refined mesh, void ones included
  std::uint64_t triangles_marched = 0;  // with data: tested against the levels
  std::uint64_t segments = 0;           // one per triangle and level it straddles
  std::uint64_t polylines = 0;          // open lines and rings
  std::uint64_t rings = 0;
  std::uint64_t points = 0;  // of the lines (<= segments + polylines: repeats are written once)
  double refine_seconds = 0.0, march_seconds = 0.0, join_seconds = 0.0, seconds = 0.0;
};

struct ContourResult {
  std::vector<ContourLine> lines;  // by increasing level; within a level, in no promised order
  ContourStats stats;
};

/// The contour lines of a terrain source (pass an IndexedSource for a database, so the R-tree
/// prunes) at the levels and accuracy of `o`. No level within the data's range is not an error:
/// no lines, and stats.levels == 0 says why. kInvalidInput for bad options (levels_region) or a
/// 3-D mesh source; kInternal if the refined mesh is not a surface (an edge crossed twice).
ContourResult contours(const OpSource& src, const ContourOptions& o);

/// The lines as a GeoJSON FeatureCollection named "contours" (geojson.h: the georef's CRS), one
/// LineString feature per line with properties {"elev": level, "error": bound}. kIo when the
/// stream fails.
void write_geojson(std::ostream& out, const ContourResult& r, const Georef& georef);

}  // namespace smr::query
