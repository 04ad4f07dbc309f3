// Executable forms of the CRMR definitions (Brown 4.4.1, 4.5) and of the output properties of
// selective refinement (Brown 5.1.4, 5.2.2; docs/design.md section 8). Used by tests and `verify`.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "smr/core/crmr.h"

namespace smr {

struct InvariantReport {
  std::vector<std::string> errors;  // empty = every invariant holds
  std::uint64_t checked = 0;        // number of items examined
  bool ok() const { return errors.empty(); }
  void fail(std::string message);  // keeps the first 50 messages, counts the rest
  std::uint64_t failures = 0;
  std::string summary() const;
};

/// Validates a whole CRMR. Terrain: ids and ordering, non-decreasing birth_res, every op complete
/// and minimal, PreF references and killers, death_res, parents/children derived from PreF (so the
/// DAG is acyclic: parents precede children), Hypermesh neighbour and coarser-edge links, geometry
/// (box, sphere, cone contain F and PreF) and ROI containment, M^0 and M^m tiling the domain.
/// 3-D meshes: the same DAG, resolution and geometry checks; per op, vertices, neighbour and
/// coarser links, PreF, completeness (F and PreF have the same directed boundary) and one
/// connected F; M^0 and M^m oriented manifold surfaces (check_surface).
InvariantReport check_crmr(const Crmr& crmr);

/// A 3-D output surface: no triangle twice, none degenerate, every directed edge at most once
/// (so every edge has 1 or 2 triangles, oriented consistently), boundary edges forming closed
/// loops with one boundary edge leaving each boundary vertex (no non-manifold vertex on them);
/// and its topology for comparison with the source: components, boundary loops, Euler
/// characteristic (V - E + F).
struct SurfaceReport {
  InvariantReport report;
  std::uint64_t vertices = 0, triangles = 0, components = 0;
  std::uint64_t boundary_edges = 0, boundary_loops = 0;
  std::int64_t euler = 0;
};
SurfaceReport check_surface(const OpSource& source, std::span<const TriRef> triangles);

/// Grid coordinates of a terrain vertex (exact integers by construction).
struct GridPoint {
  std::int64_t x, y;
  friend bool operator==(const GridPoint&, const GridPoint&) = default;
};
GridPoint to_grid(const CrmrInfo& info, const Vec3& p);
using GridTriangle = std::array<GridPoint, 3>;
/// Twice the signed area of (a, b, c), exactly.
std::int64_t orient(const GridPoint& a, const GridPoint& b, const GridPoint& c);
/// True when the open interiors of two counter-clockwise triangles intersect (separating axes).
bool interiors_overlap(const GridTriangle& a, const GridTriangle& b);

/// Checks that `triangles` tile the terrain's rectangular domain (Brown Theorem 5.2.1): every
/// triangle counter-clockwise, twice-areas sum exactly to the domain's, every interior edge shared
/// by exactly two triangles with opposite orientation, every other edge on the domain boundary,
/// and no vertex inside another triangle's edge (no T-junction). Void triangles count as tiles.
InvariantReport check_tiling(const OpSource& source, std::span<const TriRef> triangles);

struct DelaunayReport {
  std::uint64_t interior_edges = 0;
  std::uint64_t non_delaunay_edges = 0;  // opposite vertex strictly inside the circumcircle
  std::vector<std::pair<TriRef, TriRef>> examples;  // up to 10 offending triangle pairs
  double share() const {
    return interior_edges == 0 ? 0.0 : double(non_delaunay_edges) / double(interior_edges);
  }
};
/// Local Delaunay test on every interior edge (exact integer arithmetic on grid coordinates).
DelaunayReport check_delaunay(const OpSource& source, std::span<const TriRef> triangles);

}  // namespace smr
