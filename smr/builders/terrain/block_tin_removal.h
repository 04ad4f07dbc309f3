// One vertex removal of the block TIN builder's decimation (block_tin.h): the vertex's star, the
// hole it leaves re-triangulated by Delaunay ears, the new triangles' error bounds, and the
// records of the removal (reversed, an op: PreF = the hole's triangles, F = the star).
//
// Decimation by vertex removal with the hole re-triangulated (Schroeder, Zarge & Lorensen 1992,
// "Decimation of triangle meshes"); removed from a Delaunay TIN with a Delaunay hole, the mesh
// stays Delaunay (De Floriani et al., LOD part two, "construction through simplification"), so
// every fragment meets the Delaunay criterion (Brown Theorem 5.1.4). An ear is Delaunay when no
// other hole vertex lies in its circumcircle.
#pragma once

#include <array>
#include <cstdint>
#include <utility>
#include <vector>

#include "smr/builders/terrain/block_tin_bounds.h"
#include "smr/builders/terrain/block_tin_mesh.h"

namespace smr::block_tin {

/// A removal planned: what it destroys, what it makes and its error.
struct Plan {
  std::vector<std::uint32_t> star;                 // triangles, counter-clockwise around the vertex
  std::vector<std::uint32_t> poly;                 // the hole's boundary, counter-clockwise
  bool open = false;                               // the vertex is on the domain boundary
  std::vector<std::array<std::uint32_t, 3>> tris;  // the hole's new triangles (vertex ids)
  std::vector<TriBound> bounds;                    // of each new triangle
  double err = kInfeasible;
  bool lower_bound = false;  // err is only a lower bound (plan's gate)
  bool delaunay = true;
};

/// The samples exact bounds are taken from: w's sample (0, 0) is grid (c0, r0). No samples (w
/// null): overlay bounds.
struct BlockWindow {
  const Heightfield* w = nullptr;
  int c0 = 0, r0 = 0;
};

/// Buffers of planning and applying removals, kept from removal to removal.
struct RemovalScratch {
  ClipScratch clip;
  std::vector<std::pair<std::uint64_t, std::uint32_t>> outer;  // apply_removal's hole edges
};

/// Plans the removal of `v`: its hole's triangulation and error (kInfeasible if impossible).
/// With a window and `estimate`, no sample is scanned: the error is the removed vertex's
/// own deviation from the new triangles, a lower bound of the exact one (p.lower_bound).
/// Exact errors are scanned only until they pass `limit` (a removal that would not be made):
/// p.err is then a lower bound above it (p.lower_bound) and p.bounds incomplete.
void plan_removal(const Setup& setup, Mesh& mesh, ClipScratch& scratch, std::uint32_t v, Plan& p,
                  const BlockWindow& window, bool estimate, double limit = kInfeasible);

/// Makes the planned removal of `v`: the star's triangles die, the hole's are made and glued to
/// the outside, the removal is recorded.
void apply_removal(const Grid& grid, Mesh& mesh, RemovalScratch& scratch, std::uint32_t v,
                   const Plan& p, BlockTinStats& stats);

}  // namespace smr::block_tin
