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

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <numbers>
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

/// WGS 84 metres per degree of longitude (x) and of latitude (y) at `latitude_deg`.
inline std::array<double, 2> metres_per_degree(double latitude_deg) {
  constexpr double a = 6378137.0, f = 1.0 / 298.257223563, e2 = f * (2 - f);
  const double phi = latitude_deg * std::numbers::pi / 180.0;
  const double w = 1.0 - e2 * std::sin(phi) * std::sin(phi);
  const double rad = std::numbers::pi / 180.0;
  return {rad * a * std::cos(phi) / std::sqrt(w), rad * a * (1.0 - e2) / (w * std::sqrt(w))};
}

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

/// Sets `out`'s header to window [col0, col0 + w) x [row0, row0 + h) of a raster with `georef`
/// (its sample (0, 0) is the raster's (col0, row0)). Its sample buffers are kept as they are,
/// for a reader filling window after window into them (their pages stay faulted in).
inline void set_window_header(Heightfield& out, const Georef& georef, const std::string& source,
                              int col0, int row0, int w, int h) {
  out.width = w;
  out.height = h;
  out.source = source;
  out.georef = georef;
  out.georef.x0 += col0 * georef.dx;
  out.georef.y0 += row0 * georef.dy;
}

/// The header of that window alone; no samples yet.
inline Heightfield window_header(const Georef& georef, const std::string& source, int col0,
                                 int row0, int w, int h) {
  Heightfield out;
  set_window_header(out, georef, source, col0, row0, w, h);
  return out;
}

/// Read access to a DEM one window at a time, so that a builder never needs the whole grid in
/// memory (smr/builders/terrain/block_tin.h). Windows follow the Heightfield conventions: row 0 is
/// the south.
class RasterWindows {
 public:
  virtual ~RasterWindows() = default;
  virtual int width() const = 0;
  virtual int height() const = 0;
  virtual const Georef& georef() const = 0;
  virtual const std::string& source() const = 0;
  /// Samples [col0, col0 + w) x [row0, row0 + h) as a Heightfield whose georef is the window's
  /// (x0, y0 at sample (col0, row0)) and whose `valid` is empty when every sample has data.
  /// Throws smr::Error naming the source when they cannot be read.
  virtual Heightfield read(int col0, int row0, int w, int h) const = 0;
  /// Caps the reader's cache of decoded source blocks at `bytes`; 0 empties it (a builder that
  /// has read what it needs hands the memory back). Returns the previous cap; readers without
  /// such a cache ignore it and return 0.
  virtual std::uint64_t set_cache_bytes(std::uint64_t /*bytes*/) const { return 0; }
  /// True when `read` may be called from several threads at once and costs about the bytes it
  /// returns (memory, or a file read in place): a builder may then read samples again from the
  /// source instead of keeping a copy of its own (smr/builders/terrain/block_tin.cpp).
  virtual bool random_access() const { return false; }
  /// `read` into `out`, reusing its buffers where the reader can.
  virtual void read_into(Heightfield& out, int col0, int row0, int w, int h) const {
    out = read(col0, row0, w, h);
  }
};

/// Windows of a Heightfield already in memory (tests, small inputs).
class HeightfieldWindows final : public RasterWindows {
 public:
  explicit HeightfieldWindows(const Heightfield& h) : h_(h) {}
  bool random_access() const override { return true; }
  int width() const override { return h_.width; }
  int height() const override { return h_.height; }
  const Georef& georef() const override { return h_.georef; }
  const std::string& source() const override { return h_.source; }
  Heightfield read(int col0, int row0, int w, int h) const override {
    Heightfield out;
    read_into(out, col0, row0, w, h);
    return out;
  }
  void read_into(Heightfield& out, int col0, int row0, int w, int h) const override {
    set_window_header(out, h_.georef, h_.source, col0, row0, w, h);
    out.z.resize(static_cast<std::size_t>(w) * static_cast<std::size_t>(h));
    out.valid.resize(h_.has_nodata() ? out.z.size() : 0);
    bool any_invalid = false;
    for (int r = 0; r < h; ++r) {
      const std::size_t i = out.index(0, r), j = h_.index(col0, row0 + r);
      std::copy_n(h_.z.begin() + std::ptrdiff_t(j), w, out.z.begin() + std::ptrdiff_t(i));
      if (!h_.has_nodata()) continue;
      for (int c = 0; c < w; ++c) {
        out.valid[i + std::size_t(c)] = h_.valid[j + std::size_t(c)];
        any_invalid |= h_.valid[j + std::size_t(c)] == 0;
      }
    }
    if (!any_invalid) out.valid.clear();
  }

 private:
  const Heightfield& h_;
};

}  // namespace smr
