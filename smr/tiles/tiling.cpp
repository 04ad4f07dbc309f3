// Tiling schemes of the quantized-mesh pyramid (tiling.h).
#include "smr/tiles/tiling.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "base/error.h"

namespace smr::tiles {

namespace {

// CesiumJS's geometric error estimate for a tile of a heightmap tiling: its width x 0.25 (its
// heightmap terrain quality) / 65 samples; at zoom 0 of the WGS 84 ellipsoid's EPSG:4326 tiling
// (maximum radius x 2 pi / 2 root tiles wide), 77 067 m.
constexpr double kCesiumErrorPerWidth = 0.25 / 65.0;
constexpr double kCesiumLevel0Error =
    6378137.0 * 2.0 * std::numbers::pi / 2.0 * kCesiumErrorPerWidth;

}  // namespace

TilingScheme TilingScheme::for_terrain(const CrmrInfo& info) {
  if (info.kind != ModelKind::kTerrain)
    throw_input("tiles need a terrain database; this one holds a 3-D mesh");
  const Georef& g = info.georef;
  TilingScheme s;
  s.geographic_ = g.geographic;
  s.domain_ = {g.x0, g.y0, g.x0 + (info.grid_width - 1) * g.dx,
               g.y0 + (info.grid_height - 1) * g.dy};
  s.sample_spacing_ = g.dx;
  if (s.geographic_) {
    s.data_offset_ = 360.0 * std::floor((s.domain_.west + 180.0) / 360.0);
    s.domain_.west -= s.data_offset_;
    s.domain_.east -= s.data_offset_;
    if (s.domain_.east > 180.0 || s.domain_.south < -90.0 || s.domain_.north > 90.0)
      throw_input("tiles: the geographic raster spans longitudes " +
                  std::to_string(s.domain_.west + s.data_offset_) + " to " +
                  std::to_string(s.domain_.east + s.data_offset_) + " and latitudes " +
                  std::to_string(s.domain_.south) + " to " + std::to_string(s.domain_.north) +
                  ": one that crosses the antimeridian or a pole cannot be tiled");
    s.origin_ = {-180.0, -90.0};
    s.root_size_ = 180.0;
    s.root_tiles_x_ = 2;
    s.level0_error_ = kCesiumLevel0Error;
  } else {
    s.origin_ = {s.domain_.west, s.domain_.south};
    s.root_size_ = std::max(s.domain_.east - s.domain_.west, s.domain_.north - s.domain_.south);
    s.root_tiles_x_ = 1;
    s.level0_error_ = s.root_size_ * kCesiumErrorPerWidth;
  }
  if (!(s.root_size_ > 0.0)) throw_input("tiles need a raster of at least 2 x 2 samples");
  return s;
}

Rect TilingScheme::rect(const TileId& id) const {
  const double size = std::ldexp(root_size_, -id.z);
  return {origin_.x + id.x * size, origin_.y + id.y * size, origin_.x + (id.x + 1.0) * size,
          origin_.y + (id.y + 1.0) * size};
}

TileRange TilingScheme::covering(int z) const {
  const double size = std::ldexp(root_size_, -z);
  const std::int64_t nx = std::int64_t(root_tiles_x_) << z, ny = std::int64_t{1} << z;
  // Tile x's interior (x * size, (x + 1) * size) meets (west, east) when x < east / size and
  // x + 1 > west / size.
  const auto first = [&](double lo, std::int64_t n) {
    return std::clamp<std::int64_t>(std::int64_t(std::floor(lo / size)), 0, n - 1);
  };
  const auto last = [&](double hi, std::int64_t n) {
    return std::clamp<std::int64_t>(std::int64_t(std::ceil(hi / size)) - 1, 0, n - 1);
  };
  TileRange r;
  r.x0 = first(domain_.west - origin_.x, nx);
  r.x1 = last(domain_.east - origin_.x, nx);
  r.y0 = first(domain_.south - origin_.y, ny);
  r.y1 = last(domain_.north - origin_.y, ny);
  return r;
}

Rect TilingScheme::data_rect(const TileId& id) const {
  Rect r = rect(id);
  r.west += data_offset_;
  r.east += data_offset_;
  return r;
}

double TilingScheme::level_error(int z) const {
  return std::ldexp(level0_error_, -z);
}

int TilingScheme::default_max_zoom(double finest_error) const {
  int z = 0;
  while (z < kMaxZoom && std::ldexp(root_size_, -z) > 64.0 * sample_spacing_ &&
         level_error(z) > finest_error)
    ++z;
  return z;
}

}  // namespace smr::tiles
