// Error bounds of the block TIN builder's triangles (block_tin.h): exact ones from the samples
// under a triangle, and the conservative overlay bound of a new triangle from the old ones it
// overlaps.
//
// The exact bound scans every grid sample of the closed triangle against its plane, the vertical
// error of greedy insertion (Garland & Heckbert 1995, "Fast polygonal approximation of terrains
// and height fields"; Brown 7.1.1), kept one-sided (up, down) so that bounds compose. The overlay
// bound (the levels whose windows are too large to re-read) carries the old triangles' one-sided
// bounds across the overlay of the old and the new triangles: on each piece of it both planes are
// linear, so their largest difference is at the piece's corners.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <utility>
#include <vector>

#include "smr/builders/terrain/block_tin_mesh.h"
#include "smr/core/heightfield.h"

namespace smr::block_tin {

/// The bound of the samples in the closed triangle `v` (window coordinates: w's sample (0, 0) is
/// grid (c0, r0)) against its plane; up = kInfeasible when it covers a no-data sample. With
/// `outward`, rounded up by mesh.tol (a bound on new triangles). The scan stops after the first
/// row that takes up or down past `limit`: the bound is then only a lower bound of the
/// triangle's, above `limit`. Counts the samples visited into mesh.scanned.
TriBound exact_bound(Mesh& mesh, const std::array<std::uint32_t, 3>& v, const Heightfield& w,
                     int c0, int r0, bool outward, double limit = kInfeasible);

/// The sample of the closed triangle `v` farthest from its plane (the first in row order), in
/// grid coordinates.
std::pair<int, int> worst_sample(std::span<const MVert> verts,
                                 const std::array<std::uint32_t, 3>& v, const Heightfield& w,
                                 int c0, int r0);

/// overlay_bound's buffers, kept from call to call.
struct ClipScratch {
  std::vector<std::array<double, 2>> a, b;
};

/// Conservative bound of new triangle `nt` over the old triangles `star` it replaces: for every
/// old triangle o it overlaps, source - new = (source - o) + (o - new), so up <= o.up + the
/// largest o - new over the overlap (at its corners: both planes are linear there), and likewise
/// down; and never more than the source's range allows: the plane lies between its corners'
/// heights and the source between the overlapped triangles' zlo and zhi. Rounded up by mesh.tol.
TriBound overlay_bound(const Mesh& mesh, const std::array<std::uint32_t, 3>& nt,
                       std::span<const std::uint32_t> star, ClipScratch& scratch);

}  // namespace smr::block_tin
