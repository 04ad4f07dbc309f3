// A static pyramid of quantized-mesh-1.0 terrain tiles cut from a terrain database
// (smr/io/quantized_mesh.h; the tiling in tiling.h), with its layer.json.
//
// Each tile is a cut of the CRMR over the tile's rectangle: the exact window refinement of
// Maheshwari et al. 3.2 (smr/query/region.h: refine() with a WindowRegion) at the level's error
// e(z), halving per zoom, so that every triangle meeting the rectangle is within e(z) of the
// source DEM (or final); the mesh is then clipped to the rectangle, its vertices quantized to the
// tile's u/v/height grid and welded.
//
// Crack-free edges. Neighbouring tiles of one zoom share their edge vertices exactly: the window
// refinement leaves the same triangles along a common edge in both cuts (any op refining one of
// them would have to be needed by a triangle of error above e(z), and birth resolutions never
// decrease down the DAG), both clip those triangles at the same line with the same arithmetic
// (each original edge in one canonical direction), their u/v grids agree along the edge, and
// every vertex on a tile edge has its height on the pyramid's global height grid (a power of two,
// the finest that spans the database's heights in 15 bits), which every tile's own height grid
// subdivides. Tiles of different zooms meet along polylines of different detail: those gaps (at
// most the two tiles' errors) are covered by the skirts a client hangs from the edge vertex lists
// (CesiumJS does, 5 x its level error deep). Tests check both (tests/io/quantized_mesh_test.cpp).
//
// Headers: for the geographic tiling, the centre, bounding sphere and horizon occlusion point in
// Earth-centred, Earth-fixed WGS 84 metres (heights taken as ellipsoidal), the normals in the
// same frame; for the local tiling, the same fields in the raster's own coordinates (x, y,
// height; the horizon occlusion point is the sphere's centre) and normals in (east, north, up).
// Files are not gzipped (a static server can send them as they are). Each tile carries the
// octvertexnormals extension and the metadata extension {"geometricError": e}: e(z) (or the
// database's finest error when larger) plus what quantizing u, v and the height can add.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "smr/db/database.h"
#include "smr/io/quantized_mesh.h"
#include "smr/tiles/tiling.h"

namespace smr::tiles {

struct PyramidOptions {
  int max_zoom = -1;   // -1: TilingScheme::default_max_zoom(the database's err_final)
  bool force = false;  // replace an existing output directory
  /// Called after each tile with the tiles done and the total.
  std::function<void(std::uint64_t, std::uint64_t)> progress;
};

struct PyramidReport {
  int max_zoom = 0;
  std::string projection;
  std::uint64_t tiles = 0, vertices = 0, triangles = 0, bytes = 0, pages_read = 0;
  std::vector<double> level_errors;        // e(z) for z = 0..max_zoom
  std::vector<std::uint64_t> level_tiles;  // tiles written per zoom
  double height_step = 0;                  // the global height grid
  double seconds = 0;
};

/// The global height grid of a database's pyramid: the smallest power of two g (at least the
/// database's z step) with (highest - lowest) / g <= 32767.
double global_height_step(const Database& db);

/// A tile: the cut of `db` over `id`'s rectangle at error `accuracy`, quantized. `height_step`:
/// global_height_step(db). `stated_error` receives the tile's geometric error. Empty (no
/// triangles) when the rectangle's interior misses the raster.
QuantizedMeshTile cut_tile(const Database& db, const TilingScheme& scheme, const TileId& id,
                           double height_step, double* stated_error);

/// Writes the pyramid of zooms 0..max_zoom under `dir` ({z}/{x}/{y}.terrain and layer.json):
/// into a temporary directory beside it, renamed to `dir` when complete, so that a failure
/// leaves no partial pyramid. kInvalidInput for a 3-D mesh database, a zoom outside
/// [0, kMaxZoom], or an existing `dir` without options.force.
PyramidReport write_pyramid(const Database& db, const std::string& dir,
                            const PyramidOptions& options);

/// The layer.json of a pyramid of zooms 0..max_zoom (-1: the default) served on demand (smrdb
/// serve): what write_pyramid writes, except that "available" lists every tile of the scheme's
/// covering(z) (write_pyramid lists the tiles it wrote: the same unless a covered tile holds no
/// triangle). kInvalidInput like write_pyramid.
std::string covering_layer_json(const Database& db, int max_zoom);

}  // namespace smr::tiles
