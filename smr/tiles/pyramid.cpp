// The quantized-mesh pyramid (pyramid.h): cutting a tile (window refinement, Maheshwari et al.
// 3.2, then clipping and quantizing) and writing the pyramid with its layer.json.
#include "smr/tiles/pyramid.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <map>
#include <memory>
#include <numbers>
#include <tuple>
#include <unordered_map>

#include <unistd.h>

#include <nlohmann/json.hpp>

#include "base/error.h"
#include "smr/extract/extract.h"
#include "smr/io/atomic_file.h"
#include "smr/io/gltf_writer.h"
#include "smr/query/indexed_source.h"
#include "smr/query/region.h"

namespace smr::tiles {

namespace {

namespace fs = std::filesystem;
using nlohmann::json;

constexpr double kMax = 32767.0;

// ---- clipping a triangle to the tile's rectangle ---------------------------------------------

struct Corner {
  Vec3 p;  // x, y in the raster's coordinates, z the height
  Vec3 n;  // the vertex normal, (east, north, up)
};

// The point of segment ab (in canonical order: the same arithmetic in every tile that clips it)
// where axis `a_axis` equals `value`.
Corner cross_at(Corner a, Corner b, int axis, double value) {
  if (std::tie(b.p.x, b.p.y) < std::tie(a.p.x, a.p.y)) std::swap(a, b);
  const double t = (value - a.p[axis]) / (b.p[axis] - a.p[axis]);
  Corner c{a.p + t * (b.p - a.p), a.n + t * (b.n - a.n)};
  c.p[axis] = value;
  return c;
}

double cross2(const Vec3& o, const Vec3& a, const Vec3& b) {
  return (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x);
}

// The convex polygon triangle ∩ rectangle, counter-clockwise: the triangle's corners inside the
// rectangle, its edges' crossings of the rectangle's sides, and the rectangle's corners inside
// the triangle (height and normal interpolated).
std::vector<Corner> clip(const std::array<Corner, 3>& t, const Rect& r) {
  std::vector<Corner> pts;
  const auto inside = [&](const Vec3& p) {
    return p.x >= r.west && p.x <= r.east && p.y >= r.south && p.y <= r.north;
  };
  for (const Corner& c : t) {
    if (inside(c.p)) pts.push_back(c);
  }
  for (int e = 0; e < 3; ++e) {
    const Corner& a = t[std::size_t(e)];
    const Corner& b = t[std::size_t((e + 1) % 3)];
    for (const auto& [axis, value] : {std::pair{0, r.west}, std::pair{0, r.east},
                                      std::pair{1, r.south}, std::pair{1, r.north}}) {
      if ((a.p[axis] - value) * (b.p[axis] - value) >= 0.0) continue;  // no strict crossing
      const Corner c = cross_at(a, b, axis, value);
      if (inside(c.p)) pts.push_back(c);
    }
  }
  const double area = cross2(t[0].p, t[1].p, t[2].p);
  if (area <= 0.0) return {};
  for (const double x : {r.west, r.east}) {
    for (const double y : {r.south, r.north}) {
      const Vec3 q(x, y, 0.0);
      const double w0 = cross2(t[1].p, t[2].p, q), w1 = cross2(t[2].p, t[0].p, q),
                   w2 = cross2(t[0].p, t[1].p, q);
      // Inside, or within rounding of an edge (a corner on a triangle edge must not fall
      // between the two triangles in both of the tiles that share it).
      const double tol = -1e-12 * area;
      if (w0 < tol || w1 < tol || w2 < tol) continue;
      const Vec3 l = Vec3(w0, w1, w2) / area;
      Corner c{l.x * t[0].p + l.y * t[1].p + l.z * t[2].p,
               l.x * t[0].n + l.y * t[1].n + l.z * t[2].n};
      c.p.x = x;
      c.p.y = y;
      pts.push_back(c);
    }
  }
  if (pts.size() < 3) return {};
  Vec3 mid(0.0);
  for (const Corner& c : pts) mid += c.p / double(pts.size());
  std::sort(pts.begin(), pts.end(), [&](const Corner& a, const Corner& b) {
    return std::atan2(a.p.y - mid.y, a.p.x - mid.x) < std::atan2(b.p.y - mid.y, b.p.x - mid.x);
  });
  return pts;
}

// ---- geodesy (WGS 84) -------------------------------------------------------------------------

constexpr double kA = 6378137.0, kF = 1.0 / 298.257223563, kE2 = kF * (2 - kF), kB = kA * (1 - kF);

Vec3 ecef(double lon_deg, double lat_deg, double h) {
  const double lon = lon_deg * std::numbers::pi / 180, lat = lat_deg * std::numbers::pi / 180;
  const double n = kA / std::sqrt(1 - kE2 * std::sin(lat) * std::sin(lat));
  return {(n + h) * std::cos(lat) * std::cos(lon), (n + h) * std::cos(lat) * std::sin(lon),
          (n * (1 - kE2) + h) * std::sin(lat)};
}

// (east, north, up) at (lon, lat) to Earth-centred, Earth-fixed.
Vec3 enu_to_ecef(const Vec3& v, double lon_deg, double lat_deg) {
  const double lon = lon_deg * std::numbers::pi / 180, lat = lat_deg * std::numbers::pi / 180;
  const Vec3 e(-std::sin(lon), std::cos(lon), 0.0);
  const Vec3 n(-std::sin(lat) * std::cos(lon), -std::sin(lat) * std::sin(lon), std::cos(lat));
  const Vec3 u(std::cos(lat) * std::cos(lon), std::cos(lat) * std::sin(lon), std::sin(lat));
  return v.x * e + v.y * n + v.z * u;
}

// The horizon occlusion point (Cesium's "Horizon culling", 2013): along the direction of
// `center` in the ellipsoid-scaled frame, the nearest point that sees no more of the horizon
// than any of `points` would: if it is below the horizon, all of them are.
Vec3 horizon_occlusion_point(const Vec3& center, const std::vector<Vec3>& points) {
  const Vec3 radii(kA, kA, kB);
  const Vec3 d = glm::normalize(center / radii);
  double best = 0.0;
  for (const Vec3& p : points) {
    const Vec3 s = p / radii;
    const double m2 = std::max(1.0, glm::dot(s, s)), m = std::sqrt(m2);
    const Vec3 dir = glm::normalize(s);
    const double cos_a = glm::dot(dir, d), sin_a = glm::length(glm::cross(dir, d));
    const double cos_b = 1.0 / m, sin_b = std::sqrt(m2 - 1.0) * cos_b;
    const double denominator = cos_a * cos_b - sin_a * sin_b;
    if (denominator <= 0.0) return d * 1e6;  // no such point: a far one is never occluded
    best = std::max(best, 1.0 / denominator);
  }
  return d * best;
}

// ---- the tile ------------------------------------------------------------------------------

// The extraction over the rectangle, clipped: corners of the output triangles (3 per triangle).
struct Clipped {
  std::vector<Corner> corners;
  double max_slope = 0.0;  // of the triangles meeting the rectangle, metric
};

Clipped cut_and_clip(const Database& db, const Rect& r, double accuracy, const Vec3& metric) {
  const IndexedSource source(db);
  const auto window =
      std::make_shared<query::WindowRegion>(Vec2(r.west, r.south), Vec2(r.east, r.north));
  const Extraction e = query::refine(source, window, query::Accuracy::within(accuracy));
  const TriangleMesh mesh = to_mesh(db, e.triangles);
  // Area-weighted vertex normals in the metric frame (east, north, up).
  std::vector<Vec3> normal(mesh.positions.size(), Vec3(0.0));
  for (const auto& t : mesh.triangles) {
    const auto& p = mesh.positions;
    const Vec3 f = glm::cross(metric * (p[t[1]] - p[t[0]]), metric * (p[t[2]] - p[t[0]]));
    for (std::uint32_t v : t) normal[v] += f;
  }
  Clipped out;
  for (const auto& t : mesh.triangles) {
    std::array<Corner, 3> c;
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t v = t[std::size_t(k)];
      const double len = glm::length(normal[v]);
      c[std::size_t(k)] = {mesh.positions[v], len > 0 ? normal[v] / len : Vec3(0, 0, 1)};
    }
    const std::vector<Corner> poly = clip(c, r);
    if (poly.empty()) continue;
    const Vec3 f = glm::cross(metric * (c[1].p - c[0].p), metric * (c[2].p - c[0].p));
    if (f.z > 0) out.max_slope = std::max(out.max_slope, std::hypot(f.x, f.y) / f.z);
    for (std::size_t k = 1; k + 1 < poly.size(); ++k) {
      out.corners.push_back(poly[0]);
      out.corners.push_back(poly[k]);
      out.corners.push_back(poly[k + 1]);
    }
  }
  return out;
}

struct Grid {
  Rect r;
  double min_height = 0, step = 1;  // height = min_height + step * code
};

// A clipped corner on the tile's u/v grid.
struct Placed {
  std::uint16_t u = 0, v = 0;
  double z = 0;
  Vec3 n{0.0};
};

// Only the points on a side (or within 1e-7 of the tile's size of it: a crossing computed next
// to a corner) get 0 or 32767: a vertex inside rounds to 1..32766, so that it cannot join the
// edge (the neighbour, which does not have it, would not match).
std::uint16_t to_grid(double x, double lo, double hi) {
  const double f = (x - lo) / (hi - lo);
  if (f <= 1e-7) return 0;
  if (f >= 1 - 1e-7) return 32767;
  return std::uint16_t(std::clamp(std::round(f * kMax), 1.0, kMax - 1));
}

// The corners on the u/v grid, one height per grid point: where several points round to one,
// the nearest to it (then the highest), whatever the order they come in, so that two tiles
// sharing an edge, which have the same points on it, keep the same one.
std::vector<Placed> place(const std::vector<Corner>& corners, const Rect& r) {
  std::vector<Placed> out(corners.size());
  std::unordered_map<std::uint32_t, std::size_t> best;  // u | v << 16 -> corner
  const auto miss = [&](const Placed& p, const Corner& c) {
    const double x = r.west + (r.east - r.west) * p.u / kMax;
    const double y = r.south + (r.north - r.south) * p.v / kMax;
    return std::pair{std::hypot((c.p.x - x) / (r.east - r.west), (c.p.y - y) / (r.north - r.south)),
                     -c.p.z};
  };
  for (std::size_t i = 0; i < corners.size(); ++i) {
    const Corner& c = corners[i];
    out[i] = {to_grid(c.p.x, r.west, r.east), to_grid(c.p.y, r.south, r.north), c.p.z, c.n};
    const auto [it, fresh] = best.try_emplace(out[i].u | std::uint32_t(out[i].v) << 16, i);
    if (!fresh && miss(out[i], c) < miss(out[i], corners[it->second])) it->second = i;
  }
  for (Placed& p : out) {
    const Corner& c = corners[best.at(p.u | std::uint32_t(p.v) << 16)];
    p.z = c.p.z;
    p.n = c.n;
  }
  return out;
}

// The tile's height grid: heights of edge vertices snapped to the global grid `g` (shared by
// every tile), then the finest power-of-two subdivision of g that spans the tile in 15 bits.
Grid height_grid(std::vector<Placed>& corners, const Rect& r, double g) {
  double lo = INFINITY, hi = -INFINITY;
  for (Placed& c : corners) {
    if (c.u == 0 || c.u == 32767 || c.v == 0 || c.v == 32767) c.z = std::round(c.z / g) * g;
    lo = std::min(lo, c.z);
    hi = std::max(hi, c.z);
  }
  Grid grid{r, std::floor(lo / g) * g, g};
  // Finer while it fits and the header's float heights stay exact (< 2^24 steps from 0).
  while ((hi - grid.min_height) / (grid.step / 2) <= kMax &&
         (std::abs(grid.min_height) / (grid.step / 2) + kMax) < 16777216.0 && grid.step > g / 65536)
    grid.step /= 2;
  return grid;
}

void fill_header(QuantizedMeshTile& t, const Grid& grid, const std::vector<Vec3>& pts,
                 bool geographic) {
  const Rect& r = grid.r;
  t.min_height = float(grid.min_height);
  t.max_height = float(grid.min_height + kMax * grid.step);
  const double mid_h = (grid.min_height + t.max_height) / 2;
  const Vec2 c((r.west + r.east) / 2, (r.south + r.north) / 2);
  std::vector<Vec3> world;
  world.reserve(pts.size());
  for (const Vec3& p : pts) world.push_back(geographic ? ecef(p.x, p.y, p.z) : p);
  Box3 box;
  for (const Vec3& w : world) box.add(w);
  t.center = geographic ? ecef(c.x, c.y, mid_h) : Vec3(c.x, c.y, mid_h);
  t.sphere_center = (box.lo + box.hi) * 0.5;
  t.sphere_radius = 0;
  for (const Vec3& w : world)
    t.sphere_radius = std::max(t.sphere_radius, glm::length(w - t.sphere_center));
  t.horizon_occlusion = geographic ? horizon_occlusion_point(t.center, world) : t.sphere_center;
}

// Welds the placed corners into vertices numbered by first use, drops the triangles that
// quantization made degenerate, lists the edge vertices and fills the header.
QuantizedMeshTile assemble(const std::vector<Placed>& corners, const Grid& grid, bool geographic) {
  const Rect& r = grid.r;
  QuantizedMeshTile t;
  std::unordered_map<std::uint32_t, std::uint32_t> index;  // u | v << 16 -> vertex
  std::vector<Vec3> decoded;  // vertex positions as a decoder sees them
  for (std::size_t i = 0; i + 2 < corners.size(); i += 3) {
    const Placed* q = &corners[i];
    const double area = (double(q[1].u) - q[0].u) * (double(q[2].v) - q[0].v) -
                        (double(q[1].v) - q[0].v) * (double(q[2].u) - q[0].u);
    if (area == 0.0) continue;  // collapsed by the quantization
    std::array<std::uint32_t, 3> tri{};
    for (int k = 0; k < 3; ++k) {
      const Placed& c = q[k];
      const auto [it, fresh] =
          index.try_emplace(c.u | std::uint32_t(c.v) << 16, std::uint32_t(t.u.size()));
      if (fresh) {
        const auto code =
            std::uint16_t(std::clamp(std::round((c.z - grid.min_height) / grid.step), 0.0, kMax));
        t.u.push_back(c.u);
        t.v.push_back(c.v);
        t.height.push_back(code);
        const double lon = r.west + (r.east - r.west) * c.u / kMax;
        const double lat = r.south + (r.north - r.south) * c.v / kMax;
        decoded.push_back({lon, lat, grid.min_height + grid.step * code});
        const Vec3 n = glm::normalize(c.n);
        t.normals.push_back(geographic ? enu_to_ecef(n, lon, lat) : n);
      }
      tri[std::size_t(k)] = it->second;
    }
    t.triangles.push_back(tri);
  }
  for (std::uint32_t v = 0; v < t.u.size(); ++v) {
    if (t.u[v] == 0) t.west.push_back(v);
    if (t.v[v] == 0) t.south.push_back(v);
    if (t.u[v] == kMax) t.east.push_back(v);
    if (t.v[v] == kMax) t.north.push_back(v);
  }
  const auto by = [&](const std::vector<std::uint16_t>& coord) {
    return [&coord](std::uint32_t a, std::uint32_t b) { return coord[a] < coord[b]; };
  };
  std::sort(t.west.begin(), t.west.end(), by(t.v));
  std::sort(t.east.begin(), t.east.end(), by(t.v));
  std::sort(t.south.begin(), t.south.end(), by(t.u));
  std::sort(t.north.begin(), t.north.end(), by(t.u));
  fill_header(t, grid, decoded, geographic);
  return t;
}

std::string tile_path(const std::string& dir, const TileId& id) {
  return dir + "/" + std::to_string(id.z) + "/" + std::to_string(id.x) + "/" +
         std::to_string(id.y) + ".terrain";
}

// layer.json's "available" for one zoom: runs of consecutive x per row, rows with equal runs
// merged.
json available_ranges(std::vector<std::pair<std::uint32_t, std::uint32_t>> tiles) {
  std::sort(tiles.begin(), tiles.end(), [](const auto& a, const auto& b) {
    return std::tie(a.second, a.first) < std::tie(b.second, b.first);
  });
  std::vector<std::array<std::uint32_t, 4>> runs;  // startX, endX, startY, endY
  for (std::size_t i = 0; i < tiles.size();) {
    std::size_t j = i;
    while (j + 1 < tiles.size() && tiles[j + 1].second == tiles[i].second &&
           tiles[j + 1].first == tiles[j].first + 1)
      ++j;
    const std::array<std::uint32_t, 4> run{tiles[i].first, tiles[j].first, tiles[i].second,
                                           tiles[i].second};
    bool merged = false;
    for (auto& r : runs) {
      if (r[0] == run[0] && r[1] == run[1] && r[3] + 1 == run[2]) {
        r[3] = run[2];
        merged = true;
        break;
      }
    }
    if (!merged) runs.push_back(run);
    i = j + 1;
  }
  json out = json::array();
  for (const auto& r : runs)
    out.push_back({{"startX", r[0]}, {"endX", r[1]}, {"startY", r[2]}, {"endY", r[3]}});
  return out;
}

json layer_json(const Database& db, const TilingScheme& scheme, const PyramidReport& report,
                const json& available) {
  const Rect& d = scheme.domain();  // in the tiling's longitudes
  json layer = {{"tilejson", "2.1.0"},
                {"name", fs::path(db.path()).filename().string()},
                {"description", "smrdb quantized-mesh pyramid of " + db.path()},
                {"version", "1.0.0"},
                {"format", "quantized-mesh-1.0"},
                {"scheme", "tms"},
                {"tiles", {"{z}/{x}/{y}.terrain"}},
                {"projection", scheme.projection()},
                {"bounds", {d.west, d.south, d.east, d.north}},
                {"minzoom", 0},
                {"maxzoom", report.max_zoom},
                {"extensions", {"octvertexnormals", "metadata"}},
                {"available", available}};
  layer["smrdb"] = {
      {"geometricError", report.level_errors},
      {"heightStep", report.height_step},
      {"gzip", false},
      {"edges",
       "same-zoom neighbours share their edge vertices exactly; tiles of different zooms meet "
       "within their two errors, covered by skirts built from the edge lists"}};
  if (!scheme.geographic())
    layer["smrdb"]["localTiling"] = {
        {"origin", {scheme.origin().x, scheme.origin().y}},
        {"rootSize", scheme.root_size()},
        {"crs_wkt", db.info().georef.crs_wkt},
        {"meaning",
         "tile (z, x, y) covers origin + size * [x, x + 1] x [y, y + 1], size = "
         "rootSize / 2^z; header fields in the raster's coordinates"}};
  return layer;
}

}  // namespace

double global_height_step(const Database& db) {
  const Box3& b = db.info().bounds;
  const double range = std::max(b.hi.z - b.lo.z, 0.0);
  double g = db.grid().step.z;
  while (range / g > kMax) g *= 2;
  return g;
}

QuantizedMeshTile cut_tile(const Database& db, const TilingScheme& scheme, const TileId& id,
                           double height_step, double* stated_error) {
  const Rect r = scheme.data_rect(id);  // cut in the raster's coordinates
  const bool geographic = scheme.geographic();
  Vec3 metric(1.0);
  if (geographic) {
    const auto m = metres_per_degree((r.south + r.north) / 2);
    metric = {m[0], m[1], 1.0};
  }
  const double accuracy = scheme.level_error(id.z);
  Clipped c = cut_and_clip(db, r, accuracy, metric);
  if (c.corners.empty()) return {};
  std::vector<Placed> placed = place(c.corners, r);
  const Grid grid = height_grid(placed, r, height_step);
  QuantizedMeshTile t = assemble(placed, grid, geographic);
  // Rounding to the u/v grid moves a vertex by up to half a step, and a grid point keeps the
  // highest of the points rounded to it (at most a step apart): at most a step's length (metres)
  // times the steepest slope in height; edge heights move by up to half the global step.
  const double du = (r.east - r.west) / kMax * metric.x;
  const double dv = (r.north - r.south) / kMax * metric.y;
  const double stated =
      std::max(accuracy, db.info().err_final) + height_step / 2 + std::hypot(du, dv) * c.max_slope;
  if (stated_error != nullptr) *stated_error = stated;
  t.metadata = json{{"geometricError", stated}}.dump();
  return t;
}

PyramidReport write_pyramid(const Database& db, const std::string& dir,
                            const PyramidOptions& options) {
  const auto t0 = std::chrono::steady_clock::now();
  const TilingScheme scheme = TilingScheme::for_terrain(db.info());
  PyramidReport report;
  report.max_zoom =
      options.max_zoom < 0 ? scheme.default_max_zoom(db.info().err_final) : options.max_zoom;
  if (report.max_zoom > kMaxZoom)
    throw_input("--max-zoom must be in [0, " + std::to_string(kMaxZoom) + "], got " +
                std::to_string(report.max_zoom));
  if (fs::exists(dir) && !options.force)
    throw_input("tiles: '" + dir + "' exists (pass --force to replace it)");
  report.projection = scheme.projection();
  report.height_step = global_height_step(db);
  std::uint64_t total = 0;
  for (int z = 0; z <= report.max_zoom; ++z) total += scheme.covering(z).count();

  const std::string tmp = dir + ".tmp-" + std::to_string(::getpid());
  std::error_code ec;
  fs::remove_all(tmp, ec);
  fs::create_directories(tmp, ec);
  if (ec) throw_io("tiles: cannot create '" + tmp + "': " + ec.message());
  struct Cleanup {
    std::string path;
    bool keep = false;
    ~Cleanup() {
      std::error_code e;
      if (!keep) fs::remove_all(path, e);
    }
  } cleanup{tmp};
  json available = json::array();
  const std::uint64_t pages_before = db.stats().pages_read;
  std::uint64_t done = 0;
  for (int z = 0; z <= report.max_zoom; ++z) {
    const TileRange range = scheme.covering(z);
    std::vector<std::pair<std::uint32_t, std::uint32_t>> written;
    for (std::int64_t y = range.y0; y <= range.y1; ++y) {
      for (std::int64_t x = range.x0; x <= range.x1; ++x) {
        const TileId id{z, std::uint32_t(x), std::uint32_t(y)};
        const QuantizedMeshTile t = cut_tile(db, scheme, id, report.height_step, nullptr);
        if (options.progress) options.progress(++done, total);
        if (t.triangles.empty()) continue;
        const std::vector<std::uint8_t> bytes = encode_quantized_mesh(t);
        const std::string path = tile_path(tmp, id);
        fs::create_directories(fs::path(path).parent_path(), ec);
        if (ec)
          throw_io("tiles: cannot create '" + fs::path(path).parent_path().string() +
                   "': " + ec.message());
        AtomicFile file(path);
        file.write(bytes.data(), bytes.size());
        file.commit();
        written.push_back({id.x, id.y});
        report.vertices += t.u.size();
        report.triangles += t.triangles.size();
        report.bytes += bytes.size();
      }
    }
    report.tiles += written.size();
    report.level_tiles.push_back(written.size());
    report.level_errors.push_back(scheme.level_error(z));
    available.push_back(available_ranges(std::move(written)));
  }
  {
    AtomicFile file(tmp + "/layer.json");
    file.write(layer_json(db, scheme, report, available).dump(2) + "\n");
    file.commit();
  }
  if (fs::exists(dir)) fs::remove_all(dir, ec);
  fs::rename(tmp, dir, ec);
  if (ec) throw_io("tiles: cannot rename '" + tmp + "' to '" + dir + "': " + ec.message());
  cleanup.keep = true;
  report.pages_read = db.stats().pages_read - pages_before;
  report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return report;
}

std::string covering_layer_json(const Database& db, int max_zoom) {
  const TilingScheme scheme = TilingScheme::for_terrain(db.info());
  PyramidReport report;
  report.max_zoom = max_zoom < 0 ? scheme.default_max_zoom(db.info().err_final) : max_zoom;
  if (report.max_zoom > kMaxZoom)
    throw_input("--max-zoom must be in [0, " + std::to_string(kMaxZoom) + "], got " +
                std::to_string(report.max_zoom));
  report.height_step = global_height_step(db);
  json available = json::array();
  for (int z = 0; z <= report.max_zoom; ++z) {
    report.level_errors.push_back(scheme.level_error(z));
    const TileRange r = scheme.covering(z);
    json ranges = json::array();
    if (!r.empty())
      ranges.push_back({{"startX", r.x0}, {"endX", r.x1}, {"startY", r.y0}, {"endY", r.y1}});
    available.push_back(ranges);
  }
  return layer_json(db, scheme, report, available).dump(2) + "\n";
}

}  // namespace smr::tiles
