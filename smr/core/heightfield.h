// A regular grid of elevation samples (a DEM) with its georeferencing.
//
// Conventions (all readers normalise to these):
//  - sample (col, row) is at world x = x0 + col * dx, y = y0 + row * dy, with dx > 0, dy > 0:
//    row 0 is the SOUTHERNMOST row (readers flip north-up rasters), so that counter-clockwise
//    in grid space is counter-clockwise in world space;
//  - (x0, y0) is the world position of sample (0, 0): the pixel centre for pixel-is-area data;
//  - z is in the data's vertical units (metres for the bundled DEMs);
//  - `valid` is empty when every sample holds data, else one byte per sample (0 = no data).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "smr/core/geometry.h"

namespace smr {

struct Georef {
  double x0 = 0.0, y0 = 0.0;  // world position of sample (0, 0)
  double dx = 1.0, dy = 1.0;  // sample spacing, both > 0
  std::string crs_wkt;        // empty when unknown
  bool geographic = false;    // true when x/y are degrees of longitude/latitude
  friend bool operator==(const Georef&, const Georef&) = default;
};

struct Heightfield {
  int width = 0;
  int height = 0;
  std::vector<float> z;             // width * height, row-major, row 0 = south
  std::vector<std::uint8_t> valid;  // empty = all valid; else 0 marks no data
  Georef georef;
  std::string source;  // file name or generator description, for messages

  std::size_t index(int col, int row) const {
    return static_cast<std::size_t>(row) * static_cast<std::size_t>(width) +
           static_cast<std::size_t>(col);
  }
  float at(int col, int row) const { return z[index(col, row)]; }
  bool has_data(int col, int row) const { return valid.empty() || valid[index(col, row)] != 0; }
  bool has_nodata() const { return !valid.empty(); }
  std::size_t sample_count() const { return z.size(); }

  Vec3 world(int col, int row) const {
    return {georef.x0 + col * georef.dx, georef.y0 + row * georef.dy, double(at(col, row))};
  }
  Vec2 to_grid(const Vec2& w) const {
    return {(w.x - georef.x0) / georef.dx, (w.y - georef.y0) / georef.dy};
  }
  Vec2 to_world(const Vec2& g) const {
    return {georef.x0 + g.x * georef.dx, georef.y0 + g.y * georef.dy};
  }
};

}  // namespace smr
