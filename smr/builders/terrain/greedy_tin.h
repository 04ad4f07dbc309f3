// Terrain CRMR by greedy Delaunay insertion (Brown 7.1.1; Garland & Heckbert's fast TIN;
// De Floriani's Delaunay selector). Each step inserts the sample of largest vertical error; the
// conflict zone of an insertion is PreF and the new star is F. Insertions are grouped into one op
// while the mesh error exceeds the error the op started at, so birth_res never decreases
// (Brown 4.4.3.3 coalescing).
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <utility>
#include <vector>

#include "smr/core/crmr.h"
#include "smr/core/heightfield.h"

namespace smr {

struct GreedyTinOptions {
  /// Stop when every sample is within this vertical distance of the TIN (data units).
  /// 0 = lossless: every sample is reproduced (to 1e-9 relative, float rounding).
  double max_error = 0.0;
  /// Stop once the TIN has this many vertices (0 = no limit). Checked between ops.
  std::uint64_t max_vertices = 0;
  /// Vertices of the base mesh R^0: 4 = the corner triangulation; more = a coarse greedy TIN.
  std::uint64_t base_vertices = 4;
  /// Grid samples (col, row) put into R^0 besides the corners (smr/builders/terrain/block_tin.cpp:
  /// a block's border vertices, which its neighbour shares).
  std::vector<std::pair<std::uint32_t, std::uint32_t>> initial_vertices;
  /// Never insert a sample of the grid's outer rows and columns (a block whose border vertices
  /// are given in initial_vertices and shared with its neighbours). Applies to DEMs with no-data
  /// samples; without them a border sample is inserted only if its error exceeds max_error.
  bool freeze_border = false;
  /// The error below which a sample counts as exact; negative = exact_tolerance(dem).
  double tolerance = -1.0;
  /// Accept a DEM without a single valid sample (a block of a larger one): its mesh is void.
  bool allow_no_data_only = false;
  /// Progress in [0, 1]; called at most a few hundred times.
  std::function<void(double)> progress;
};

/// Builds the CRMR. With no-data samples (Heightfield::valid), only the valid region is
/// triangulated: triangles touching a no-data vertex are marked void (never output), and the
/// base mesh is refined until no valid triangle covers a no-data sample and no void triangle
/// covers a valid sample other than its vertices, so holes are represented exactly.
/// Throws smr::Error on unusable input (fewer than 2x2 samples, no valid sample).
Crmr build_greedy_tin(const Heightfield& dem, const GreedyTinOptions& options = {});

/// The finest mesh of the same insertions, without the CRMR (no ops are made): for a builder
/// that makes its own hierarchy from it (block_tin.cpp's leaf blocks).
struct GreedyMesh {
  struct Vertex {
    std::uint32_t col = 0, row = 0;
    float z = 0.0f;  // the sample, or the fill value at a no-data sample
  };
  struct Triangle {
    std::array<std::uint32_t, 3> v{};  // vertex indices, counter-clockwise
    bool is_void = false;
  };
  std::vector<Vertex> vertices;  // in insertion order (the corners first)
  /// In the order build_greedy_tin's ops hold them (by op, then fragment index).
  std::vector<Triangle> triangles;
};
GreedyMesh build_greedy_mesh(const Heightfield& dem, const GreedyTinOptions& options = {});

/// The tolerance below which a vertical error counts as zero for `dem` (float rounding).
double exact_tolerance(const Heightfield& dem);

}  // namespace smr
