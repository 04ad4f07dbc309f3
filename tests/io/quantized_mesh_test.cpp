// Tests of the quantized-mesh-1.0 encoder (smr/io/quantized_mesh.h) and of the tile pyramid
// (smr/tiles/pyramid.h). Tiles are read back by the small decoder below, written from the format's
// specification (CesiumGS/quantized-mesh README), not from the encoder. On real DEMs: layer.json
// lists exactly the files written; every tile is within its stated geometric error of the source
// DEM at every sample it covers and covers every sample of its rectangle; neighbouring tiles of
// one zoom share their edge vertices exactly, and tiles of adjacent zooms meet within their two
// errors (the gap the skirts of a client cover).
#include "smr/io/quantized_mesh.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <map>
#include <optional>
#include <set>

#include <nlohmann/json.hpp>

#include "base/error.h"
#include "smr/tiles/pyramid.h"
#include "tests/query/written_database.h"
#include "tests/support/datasets.h"
#include "tests/support/files.h"

namespace smr {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// ---- an independent decoder, from the specification -------------------------------------------

struct Decoded {
  double center[3], sphere[4], horizon[3];
  float min_h = 0, max_h = 0;
  std::vector<std::uint32_t> u, v, h;
  std::vector<std::uint32_t> indices;
  std::vector<std::uint32_t> edges[4];  // west, south, east, north
  std::vector<std::array<std::uint8_t, 2>> oct;
  std::string metadata;
};

class Reader {
 public:
  explicit Reader(const std::vector<std::uint8_t>& b) : b_(b) {}
  template <typename T>
  T get() {
    if (at_ + sizeof(T) > b_.size()) throw std::runtime_error("tile truncated");
    T v;
    std::memcpy(&v, b_.data() + at_, sizeof(T));  // the test host is little-endian
    at_ += sizeof(T);
    return v;
  }
  void align(std::size_t n) { at_ = (at_ + n - 1) / n * n; }
  bool done() const { return at_ == b_.size(); }
  std::size_t at() const { return at_; }

 private:
  const std::vector<std::uint8_t>& b_;
  std::size_t at_ = 0;
};

Decoded decode(const std::vector<std::uint8_t>& bytes) {
  static_assert(std::endian::native == std::endian::little);
  Reader r(bytes);
  Decoded d;
  for (double& c : d.center) c = r.get<double>();
  d.min_h = r.get<float>();
  d.max_h = r.get<float>();
  for (double& c : d.sphere) c = r.get<double>();
  for (double& c : d.horizon) c = r.get<double>();
  const std::uint32_t n = r.get<std::uint32_t>();
  for (auto* arr : {&d.u, &d.v, &d.h}) {
    std::int32_t value = 0;
    for (std::uint32_t i = 0; i < n; ++i) {
      const std::uint16_t z = r.get<std::uint16_t>();
      value += (z >> 1) ^ -(z & 1);  // zig-zag
      arr->push_back(std::uint32_t(value));
    }
  }
  const bool wide = n > 65536;
  r.align(wide ? 4 : 2);
  const auto index = [&] { return wide ? r.get<std::uint32_t>() : r.get<std::uint16_t>(); };
  const std::uint32_t triangles = r.get<std::uint32_t>();
  std::uint32_t highest = 0;
  for (std::uint32_t i = 0; i < triangles * 3; ++i) {
    const std::uint32_t code = index();
    d.indices.push_back(highest - code);
    if (code == 0) ++highest;
  }
  for (auto& e : d.edges) {
    const std::uint32_t count = r.get<std::uint32_t>();
    for (std::uint32_t i = 0; i < count; ++i) e.push_back(index());
  }
  while (!r.done()) {
    const std::uint8_t id = r.get<std::uint8_t>();
    const std::uint32_t length = r.get<std::uint32_t>();
    const std::size_t end = r.at() + length;
    if (id == 1) {
      for (std::uint32_t i = 0; i < n; ++i)
        d.oct.push_back({r.get<std::uint8_t>(), r.get<std::uint8_t>()});
    } else if (id == 4) {
      const std::uint32_t len = r.get<std::uint32_t>();
      for (std::uint32_t i = 0; i < len; ++i) d.metadata += char(r.get<std::uint8_t>());
    }
    EXPECT_EQ(r.at(), end) << "extension " << int(id);
  }
  return d;
}

Vec3 oct_decode(const std::array<std::uint8_t, 2>& e) {
  double x = e[0] / 255.0 * 2 - 1, y = e[1] / 255.0 * 2 - 1;
  const double z = 1 - std::abs(x) - std::abs(y);
  if (z < 0) {
    const double ox = x;
    x = (1 - std::abs(y)) * (ox >= 0 ? 1 : -1);
    y = (1 - std::abs(ox)) * (y >= 0 ? 1 : -1);
  }
  return glm::normalize(Vec3(x, y, z));
}

// ---- the format --------------------------------------------------------------------------------

QuantizedMeshTile grid_tile(std::uint32_t side) {
  // A side x side grid of vertices numbered row by row, two triangles per cell, so that the first
  // use of every vertex comes in order.
  QuantizedMeshTile t;
  t.center = {1, 2, 3};
  t.min_height = -12.5f;
  t.max_height = 1234.25f;
  t.sphere_center = {4, 5, 6};
  t.sphere_radius = 7;
  t.horizon_occlusion = {0.1, 0.2, 0.3};
  const auto at = [&](std::uint32_t i, std::uint32_t j) { return j * side + i; };
  for (std::uint32_t j = 0; j < side; ++j) {
    for (std::uint32_t i = 0; i < side; ++i) {
      t.u.push_back(std::uint16_t(i * 32767 / (side - 1)));
      t.v.push_back(std::uint16_t(j * 32767 / (side - 1)));
      t.height.push_back(std::uint16_t((i * 7919 + j * 104729) % 32768));
      const double a = 0.37 * i + 1.3 * j;
      t.normals.push_back(glm::normalize(Vec3(std::cos(a), std::sin(a), 0.5 - (i % 3) * 0.5)));
      if (i == 0) t.west.push_back(at(i, j));
      if (j == 0) t.south.push_back(at(i, j));
      if (i == side - 1) t.east.push_back(at(i, j));
      if (j == side - 1) t.north.push_back(at(i, j));
    }
  }
  std::vector<std::array<std::uint32_t, 3>> tris;
  for (std::uint32_t j = 0; j + 1 < side; ++j) {
    for (std::uint32_t i = 0; i + 1 < side; ++i) {
      tris.push_back({at(i, j), at(i + 1, j), at(i + 1, j + 1)});
      tris.push_back({at(i, j), at(i + 1, j + 1), at(i, j + 1)});
    }
  }
  // Renumber by first use (what the encoder requires).
  std::vector<std::uint32_t> order(t.u.size(), ~0u);
  std::uint32_t next = 0;
  for (auto& tri : tris) {
    for (auto& v : tri) {
      if (order[v] == ~0u) order[v] = next++;
      v = order[v];
    }
  }
  QuantizedMeshTile r = t;
  for (std::uint32_t v = 0; v < t.u.size(); ++v) {
    r.u[order[v]] = t.u[v];
    r.v[order[v]] = t.v[v];
    r.height[order[v]] = t.height[v];
    r.normals[order[v]] = t.normals[v];
  }
  for (auto* e : {&r.west, &r.south, &r.east, &r.north}) {
    for (auto& v : *e) v = order[v];
  }
  r.triangles = tris;
  r.metadata = R"({"geometricError":1.5})";
  return r;
}

void expect_round_trip(const QuantizedMeshTile& t) {
  const std::vector<std::uint8_t> bytes = encode_quantized_mesh(t);
  const Decoded d = decode(bytes);
  EXPECT_EQ(d.center[0], t.center.x);
  EXPECT_EQ(d.center[2], t.center.z);
  EXPECT_EQ(d.min_h, t.min_height);
  EXPECT_EQ(d.max_h, t.max_height);
  EXPECT_EQ(d.sphere[3], t.sphere_radius);
  EXPECT_EQ(d.horizon[1], t.horizon_occlusion.y);
  ASSERT_EQ(d.u.size(), t.u.size());
  for (std::size_t i = 0; i < t.u.size(); ++i) {
    ASSERT_EQ(d.u[i], t.u[i]) << i;
    ASSERT_EQ(d.v[i], t.v[i]) << i;
    ASSERT_EQ(d.h[i], t.height[i]) << i;
    const Vec3 n = oct_decode(d.oct[i]);
    ASSERT_LT(glm::length(n - t.normals[i]), 0.02) << i;  // 8 bits per component
  }
  ASSERT_EQ(d.indices.size(), t.triangles.size() * 3);
  for (std::size_t i = 0; i < d.indices.size(); ++i)
    ASSERT_EQ(d.indices[i], t.triangles[i / 3][i % 3]);
  EXPECT_EQ(d.edges[0], t.west);
  EXPECT_EQ(d.edges[1], t.south);
  EXPECT_EQ(d.edges[2], t.east);
  EXPECT_EQ(d.edges[3], t.north);
  EXPECT_EQ(d.metadata, t.metadata);
}

TEST(QuantizedMesh, RoundTrip16And32BitIndices) {
  expect_round_trip(grid_tile(40));   // 1 600 vertices: 16-bit indices
  expect_round_trip(grid_tile(257));  // 66 049 vertices: 32-bit indices, 4-byte aligned
}

TEST(QuantizedMesh, RejectsIndicesOutOfFirstUseOrder) {
  QuantizedMeshTile t = grid_tile(4);
  std::swap(t.triangles[0][0], t.triangles.back()[2]);
  EXPECT_THROW(encode_quantized_mesh(t), Error);
}

// ---- the pyramid on real DEMs ----------------------------------------------------------------

struct Tile {
  tiles::TileId id;
  tiles::Rect r;
  Decoded d;
  double error = 0;
  Vec3 position(std::uint32_t i) const {
    return {r.west + (r.east - r.west) * d.u[i] / 32767.0,
            r.south + (r.north - r.south) * d.v[i] / 32767.0,
            double(d.min_h) + (double(d.max_h) - double(d.min_h)) * d.h[i] / 32767.0};
  }
};

using Pyramid = std::map<std::tuple<int, std::uint32_t, std::uint32_t>, Tile>;

Pyramid read_pyramid(const std::string& dir, const tiles::TilingScheme& scheme, int max_zoom) {
  const json layer = json::parse(test::read_file(dir + "/layer.json"));
  EXPECT_EQ(layer["format"], "quantized-mesh-1.0");
  EXPECT_EQ(layer["scheme"], "tms");
  EXPECT_EQ(layer["projection"], scheme.projection());
  EXPECT_EQ(layer["maxzoom"], max_zoom);
  EXPECT_EQ(layer["available"].size(), std::size_t(max_zoom + 1));
  Pyramid p;
  std::set<std::string> listed;
  for (int z = 0; z <= max_zoom; ++z) {
    for (const json& range : layer["available"][std::size_t(z)]) {
      for (std::uint32_t y = range["startY"]; y <= range["endY"].get<std::uint32_t>(); ++y) {
        for (std::uint32_t x = range["startX"]; x <= range["endX"].get<std::uint32_t>(); ++x) {
          const std::string rel =
              std::to_string(z) + "/" + std::to_string(x) + "/" + std::to_string(y) + ".terrain";
          listed.insert(rel);
          const std::string s = test::read_file(dir + "/" + rel);
          Tile t;
          t.id = {z, x, y};
          t.r = scheme.data_rect(t.id);  // positions in the DEM's coordinates
          t.d = decode(std::vector<std::uint8_t>(s.begin(), s.end()));
          t.error = json::parse(t.d.metadata)["geometricError"];
          p[{z, x, y}] = std::move(t);
        }
      }
    }
  }
  std::set<std::string> files;
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    if (e.is_regular_file() && e.path().extension() == ".terrain")
      files.insert(fs::relative(e.path(), dir).string());
  }
  EXPECT_EQ(files, listed) << "layer.json's available ranges and the files differ";
  return p;
}

// The sample and its 8 neighbours hold data (so the database's finest mesh covers it: cells
// with a corner without data are void).
bool data_around(const Heightfield& dem, int col, int row) {
  for (int r = std::max(0, row - 1); r <= std::min(dem.height - 1, row + 1); ++r) {
    for (int c = std::max(0, col - 1); c <= std::min(dem.width - 1, col + 1); ++c) {
      if (!dem.has_data(c, r)) return false;
    }
  }
  return true;
}

// Every DEM sample inside a tile's rectangle lies in one of its triangles, within its stated
// error of the tile's surface there; samples within a u/v step of the raster's edge may fall
// outside (the edge vertices move by up to half a step), and so may samples next to cells
// without data (void in the database).
void expect_within_error(const Tile& t, const Heightfield& dem, std::uint64_t& checked) {
  const Georef& g = dem.georef;
  const double su = (t.r.east - t.r.west) / 32767.0, sv = (t.r.north - t.r.south) / 32767.0;
  std::vector<std::uint8_t> covered(dem.sample_count(), 0);
  double worst = 0, flipped = 0, total = 0;
  for (std::size_t k = 0; k + 2 < t.d.indices.size(); k += 3) {
    const Vec3 a = t.position(t.d.indices[k]), b = t.position(t.d.indices[k + 1]),
               c = t.position(t.d.indices[k + 2]);
    const double area = (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
    (area < 0 ? flipped : total) += std::abs(area);
    EXPECT_NE(area, 0.0) << "triangle " << k / 3 << " of tile " << t.id.z << "/" << t.id.x << "/"
                         << t.id.y;
    const int c0 = std::max(0, int(std::floor((std::min({a.x, b.x, c.x}) - g.x0) / g.dx)));
    const int c1 =
        std::min(dem.width - 1, int(std::ceil((std::max({a.x, b.x, c.x}) - g.x0) / g.dx)));
    const int r0 = std::max(0, int(std::floor((std::min({a.y, b.y, c.y}) - g.y0) / g.dy)));
    const int r1 =
        std::min(dem.height - 1, int(std::ceil((std::max({a.y, b.y, c.y}) - g.y0) / g.dy)));
    for (int row = r0; row <= r1; ++row) {
      for (int col = c0; col <= c1; ++col) {
        const Vec3 p = dem.world(col, row);
        const double w0 = ((b.x - p.x) * (c.y - p.y) - (b.y - p.y) * (c.x - p.x)) / area;
        const double w1 = ((c.x - p.x) * (a.y - p.y) - (c.y - p.y) * (a.x - p.x)) / area;
        const double w2 = 1 - w0 - w1;
        if (w0 < -1e-9 || w1 < -1e-9 || w2 < -1e-9 || !dem.has_data(col, row)) continue;
        const double h = w0 * a.z + w1 * b.z + w2 * c.z;
        worst = std::max(worst, std::abs(h - p.z));
        covered[dem.index(col, row)] = 1;
        ++checked;
      }
    }
  }
  // Rounding to the u/v grid may flip a sliver or two (a clipped piece a step wide).
  EXPECT_LE(flipped, 1e-6 * total) << "tile " << t.id.z << "/" << t.id.x << "/" << t.id.y;
  EXPECT_LE(worst, t.error * (1 + 1e-9) + 1e-6)
      << "tile " << t.id.z << "/" << t.id.x << "/" << t.id.y << " states " << t.error;
  std::uint64_t missed = 0;
  for (int row = 0; row < dem.height; ++row) {
    for (int col = 0; col < dem.width; ++col) {
      const Vec3 p = dem.world(col, row);
      const double lo_x = std::max(t.r.west, g.x0 + su),
                   hi_x = std::min(t.r.east, g.x0 + (dem.width - 1) * g.dx - su);
      const double lo_y = std::max(t.r.south, g.y0 + sv),
                   hi_y = std::min(t.r.north, g.y0 + (dem.height - 1) * g.dy - sv);
      if (p.x < lo_x || p.x > hi_x || p.y < lo_y || p.y > hi_y || !data_around(dem, col, row))
        continue;
      missed += covered[dem.index(col, row)] == 0;
    }
  }
  EXPECT_EQ(missed, 0u) << "samples of tile " << t.id.z << "/" << t.id.x << "/" << t.id.y
                        << " no triangle covers";
}

// The polyline of a tile's edge `side` (0 west, 1 south, 2 east, 3 north): (position along the
// edge, height), sorted.
std::vector<std::pair<double, double>> edge_polyline(const Tile& t, int side) {
  std::vector<std::pair<double, double>> out;
  for (std::uint32_t i : t.d.edges[side]) {
    const Vec3 p = t.position(i);
    out.push_back({side % 2 == 0 ? p.y : p.x, p.z});
  }
  std::sort(out.begin(), out.end());
  return out;
}

std::optional<double> height_at(const std::vector<std::pair<double, double>>& line, double s) {
  if (line.empty() || s < line.front().first || s > line.back().first) return std::nullopt;
  const auto it =
      std::lower_bound(line.begin(), line.end(), std::pair<double, double>{s, -INFINITY});
  if (it == line.begin()) return it->second;
  const auto& [s1, h1] = *it;
  const auto& [s0, h0] = *(it - 1);
  return s1 == s0 ? h1 : h0 + (h1 - h0) * (s - s0) / (s1 - s0);
}

// Tile `a` and its east (or north) neighbour `b`: the same vertices on the common edge when they
// are of one zoom, within the two errors along the common part otherwise.
void expect_edges_meet(const Tile& a, const Tile& b, bool east, std::uint64_t& same,
                       std::uint64_t& mixed) {
  const auto la = edge_polyline(a, east ? 2 : 3), lb = edge_polyline(b, east ? 0 : 1);
  if (la.empty() || lb.empty()) return;
  const std::string what = std::to_string(a.id.z) + "/" + std::to_string(a.id.x) + "/" +
                           std::to_string(a.id.y) + " and " + std::to_string(b.id.z) + "/" +
                           std::to_string(b.id.x) + "/" + std::to_string(b.id.y);
  if (a.id.z == b.id.z) {
    ASSERT_EQ(la.size(), lb.size()) << what;
    for (std::size_t i = 0; i < la.size(); ++i) {
      EXPECT_NEAR(la[i].first, lb[i].first, 1e-12 * (1 + std::abs(la[i].first))) << what;
      EXPECT_NEAR(la[i].second, lb[i].second, 1e-9) << what;
    }
    ++same;
    return;
  }
  double worst = 0;
  for (const auto* line : {&la, &lb}) {
    for (const auto& [s, h] : *line) {
      const auto ha = height_at(la, s), hb = height_at(lb, s);
      if (ha && hb) worst = std::max(worst, std::abs(*ha - *hb));
    }
  }
  EXPECT_LE(worst, a.error + b.error) << what;
  ++mixed;
}

class TilePyramid : public ::testing::TestWithParam<std::string> {};

TEST_P(TilePyramid, FaithfulConsistentAndCrackFree) {
  const std::string name = GetParam();
  const test::WrittenDatabase wdb(test::dataset(name).crmr);
  const Database& db = wdb.database();
  const tiles::TilingScheme scheme = tiles::TilingScheme::for_terrain(db.info());
  // The small DEMs one zoom deeper than the default, for more edges between tiles.
  const int max_zoom = scheme.default_max_zoom(db.info().err_final) + (name == "jacksboro" ? 0 : 1);
  test::TempDir dir("smrdb-tiles");
  const std::string out = dir.file("pyramid");
  tiles::PyramidOptions options;
  options.max_zoom = max_zoom;
  const tiles::PyramidReport report = tiles::write_pyramid(db, out, options);
  EXPECT_EQ(report.max_zoom, max_zoom);
  const Pyramid p = read_pyramid(out, scheme, max_zoom);
  EXPECT_EQ(p.size(), report.tiles);
  ASSERT_GT(p.size(), 10u) << "too few tiles to test edges";

  const Heightfield& dem = test::dem(name);
  std::uint64_t checked = 0, same = 0, mixed = 0;
  for (const auto& [key, t] : p) {
    expect_within_error(t, dem, checked);
    EXPECT_GE(t.error, scheme.level_error(t.id.z));
    for (const bool east : {true, false}) {
      // The neighbour of the same zoom, and those of the next zoom along the same edge.
      const std::uint32_t nx = t.id.x + (east ? 1 : 0), ny = t.id.y + (east ? 0 : 1);
      if (const auto it = p.find({t.id.z, nx, ny}); it != p.end())
        expect_edges_meet(t, it->second, east, same, mixed);
      for (std::uint32_t k = 0; k < 2; ++k) {
        const std::uint32_t fx = east ? 2 * t.id.x + 2 : 2 * t.id.x + k;
        const std::uint32_t fy = east ? 2 * t.id.y + k : 2 * t.id.y + 2;
        if (const auto it = p.find({t.id.z + 1, fx, fy}); it != p.end())
          expect_edges_meet(t, it->second, east, same, mixed);
      }
    }
    // Edge lists are exactly the vertices on each side.
    for (int side = 0; side < 4; ++side) {
      std::set<std::uint32_t> expected;
      for (std::uint32_t i = 0; i < t.d.u.size(); ++i) {
        const std::uint32_t c = side % 2 == 0 ? t.d.u[i] : t.d.v[i];
        if (c == (side < 2 ? 0u : 32767u)) expected.insert(i);
      }
      EXPECT_EQ(std::set<std::uint32_t>(t.d.edges[side].begin(), t.d.edges[side].end()), expected);
    }
  }
  EXPECT_GT(checked, dem.sample_count());  // every zoom covers the DEM once
  EXPECT_GT(same, 4u);
  EXPECT_GT(mixed, 4u);
  std::printf(
      "%s: %zu tiles (zoom 0..%d, %s), %llu samples checked, %llu same-zoom and %llu "
      "mixed-zoom edges\n",
      name.c_str(), p.size(), max_zoom, scheme.projection().c_str(),
      static_cast<unsigned long long>(checked), static_cast<unsigned long long>(same),
      static_cast<unsigned long long>(mixed));
}

// Three real geographic DEMs (EPSG:4326 tiling; topobathy's longitudes are 234..238) and a
// synthetic one without a CRS (the local tiling).
INSTANTIATE_TEST_SUITE_P(Real, TilePyramid,
                         ::testing::Values("jacksboro", "elev", "topobathy", "fbm129"));

TEST(TilePyramid, RejectsAMeshDatabaseABadZoomAndAnExistingDirectory) {
  const test::WrittenDatabase wdb(test::dataset("jacksboro").crmr);
  test::TempDir dir("smrdb-tiles");
  tiles::PyramidOptions options;
  options.max_zoom = tiles::kMaxZoom + 1;
  EXPECT_THROW(tiles::write_pyramid(wdb.database(), dir.file("a"), options), Error);
  EXPECT_FALSE(fs::exists(dir.file("a")));
  options.max_zoom = 2;
  EXPECT_THROW(tiles::write_pyramid(wdb.database(), dir.path().string(), options), Error);
  options.force = true;
  tiles::write_pyramid(wdb.database(), dir.file("b"), options);
  EXPECT_TRUE(fs::exists(dir.file("b") + "/layer.json"));
  EXPECT_EQ(std::distance(fs::directory_iterator(dir.path()), fs::directory_iterator()), 1)
      << "a temporary directory was left behind";
}

}  // namespace
}  // namespace smr
