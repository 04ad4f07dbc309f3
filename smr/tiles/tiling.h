// The tiling of a terrain database into a quadtree pyramid of quantized-mesh tiles (pyramid.h).
//
// Geographic rasters (x, y in degrees; longitudes given in [180, 540) or [-540, -180), like
// topobathy's 234..238, are shifted by 360 degrees into the tiling, and back for the cuts; a
// raster across the antimeridian or beyond the poles is kInvalidInput): Cesium's EPSG:4326 tiling
// in the TMS layout, 2 x 1 tiles at zoom 0 covering the globe, 2^(z+1) x 2^z at zoom z, y counted
// from the south. Tile z has the geometric error e(z) = 77 067 m / 2^z: the estimate CesiumJS
// itself makes for the level (WGS 84 equatorial circumference x 0.25 / (65 samples x 2 root tiles);
// CesiumTerrainProvider), so that its screen-space error test refines these tiles as it would its
// own.
//
// Other rasters (projected, or no CRS): a local tiling over the raster's extent: one root tile,
// the square whose south-west corner is the raster's first sample and whose side is the larger of
// its two extents, split in 2^z x 2^z tiles at zoom z (TMS layout, y from the south); e(z) is the
// same rule CesiumJS applies, a tile's width x 0.25 / 65 (in the raster's units, taken to be
// those of its heights). Cesium cannot load it unchanged (its layer.json projections are
// EPSG:4326 and EPSG:3857); layer.json says "projection": "local" and gives the square.
#pragma once

#include <cstdint>
#include <string>

#include "smr/core/geometry.h"
#include "smr/core/op_source.h"

namespace smr::tiles {

struct TileId {
  int z = 0;
  std::uint32_t x = 0, y = 0;
  friend bool operator==(const TileId&, const TileId&) = default;
};

/// A rectangle in the raster's coordinates (degrees for a geographic raster).
struct Rect {
  double west = 0, south = 0, east = 0, north = 0;
};

/// Tiles [x0, x1] x [y0, y1] of one zoom (empty when x1 < x0).
struct TileRange {
  std::int64_t x0 = 0, y0 = 0, x1 = -1, y1 = -1;
  bool empty() const { return x1 < x0 || y1 < y0; }
  std::uint64_t count() const { return empty() ? 0 : std::uint64_t((x1 - x0 + 1) * (y1 - y0 + 1)); }
};

constexpr int kMaxZoom = 24;

class TilingScheme {
 public:
  /// The scheme for a terrain database (kInvalidInput for a 3-D mesh).
  static TilingScheme for_terrain(const CrmrInfo& info);

  bool geographic() const { return geographic_; }
  /// "EPSG:4326" or "local".
  std::string projection() const { return geographic_ ? "EPSG:4326" : "local"; }
  /// The tile's rectangle in the tiling (longitudes in [-180, 180]).
  Rect rect(const TileId& id) const;
  /// The same rectangle in the raster's coordinates (rect() shifted by data_offset()).
  Rect data_rect(const TileId& id) const;
  /// Raster x = tiling x + data_offset() (0, or a multiple of 360 degrees).
  double data_offset() const { return data_offset_; }
  /// The tiles of zoom z whose interior meets the raster's domain (in the tiling's coordinates).
  TileRange covering(int z) const;
  /// e(z): the geometric error the tiles of zoom z are cut to.
  double level_error(int z) const;
  /// The first zoom whose tiles are at most 64 raster samples across (CesiumJS's e(z) assumes 65)
  /// or whose error e(z) is at most `finest_error` (the database's: deeper adds nothing); at
  /// most kMaxZoom.
  int default_max_zoom(double finest_error) const;
  const Rect& domain() const { return domain_; }
  Vec2 origin() const { return origin_; }
  double root_size() const { return root_size_; }

 private:
  bool geographic_ = false;
  Rect domain_;
  Vec2 origin_{0.0};      // south-west corner of tile (0, 0) at every zoom
  double root_size_ = 0;  // side of a zoom-0 tile
  int root_tiles_x_ = 1;  // tiles across at zoom 0 (2 for EPSG:4326)
  double level0_error_ = 0;
  double sample_spacing_ = 1;  // the raster's x spacing
  double data_offset_ = 0;
};

}  // namespace smr::tiles
