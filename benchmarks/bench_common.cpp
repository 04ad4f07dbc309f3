#include "benchmarks/bench_common.h"

#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <numbers>
#include <sstream>
#include <stdexcept>
#include <thread>

#include "smr/io/dem_reader.h"
#include "smr/io/synthetic.h"

#ifndef SMRDB_BENCH_BUILD_TYPE
#define SMRDB_BENCH_BUILD_TYPE "unknown"
#endif
#ifndef SMRDB_BENCH_CXX_FLAGS
#define SMRDB_BENCH_CXX_FLAGS ""
#endif

namespace smr::bench {

std::uint64_t now_ns() {
  return static_cast<std::uint64_t>(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                        std::chrono::steady_clock::now().time_since_epoch())
                                        .count());
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 == 1 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

double seconds_since(std::uint64_t start_ns) {
  return double(now_ns() - start_ns) * 1e-9;
}

std::vector<std::string> split_list(const std::string& text, char sep) {
  std::vector<std::string> items;
  std::stringstream ss(text);
  for (std::string item; std::getline(ss, item, sep);) items.push_back(item);
  return items;
}

std::vector<double> parse_doubles(const std::string& text) {
  std::vector<double> v;
  for (const std::string& item : split_list(text)) v.push_back(std::stod(item));
  return v;
}

nlohmann::json vec3_json(const Vec3& v) {
  return nlohmann::json::array({v.x, v.y, v.z});
}

std::pair<double, double> z_range(const Heightfield& dem) {
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (std::size_t i = 0; i < dem.z.size(); ++i) {
    if (!dem.valid.empty() && dem.valid[i] == 0) continue;
    lo = std::min(lo, double(dem.z[i]));
    hi = std::max(hi, double(dem.z[i]));
  }
  return {lo, hi};
}

Input load_input(const InputOptions& options) {
  Input in;
  const std::uint64_t t0 = now_ns();
  if (options.fbm_size > 0) {
    in.dem = make_fbm(options.fbm_size, options.fbm_size, options.seed, options.range, 0, 0.5,
                      options.spacing);
    in.description = {{"generator", "fbm"},         {"size", options.fbm_size},
                      {"seed", options.seed},       {"range", options.range},
                      {"spacing", options.spacing}, {"generate_seconds", seconds_since(t0)}};
  } else {
    in.dem = read_dem(options.path);
    in.description = {{"path", options.path}, {"read_seconds", seconds_since(t0)}};
  }
  const auto [lo, hi] = z_range(in.dem);
  in.z_min = lo;
  in.z_max = hi;
  in.description["source"] = in.dem.source;
  in.description["width"] = in.dem.width;
  in.description["height"] = in.dem.height;
  in.description["samples"] = in.dem.sample_count();
  in.description["nodata"] = in.dem.has_nodata();
  in.description["geographic"] = in.dem.georef.geographic;
  in.description["z_min"] = lo;
  in.description["z_max"] = hi;
  in.description["z_range"] = hi - lo;
  return in;
}

Heightfield to_local_metres(const Heightfield& dem) {
  if (!dem.georef.geographic) return dem;
  constexpr double kEarthRadius = 6371008.8;  // mean radius, metres
  const double deg = std::numbers::pi / 180.0;
  const double mid_lat = dem.georef.y0 + 0.5 * (dem.height - 1) * dem.georef.dy;
  Heightfield h = dem;
  h.georef.x0 = 0.0;
  h.georef.y0 = 0.0;
  h.georef.dx = dem.georef.dx * deg * kEarthRadius * std::cos(mid_lat * deg);
  h.georef.dy = dem.georef.dy * deg * kEarthRadius;
  h.georef.geographic = false;
  h.georef.crs_wkt.clear();
  h.source = dem.source + " (local metres)";
  return h;
}

nlohmann::json machine_json() {
  std::string model = "unknown";
  std::ifstream cpuinfo("/proc/cpuinfo");
  for (std::string line; std::getline(cpuinfo, line);) {
    if (line.rfind("model name", 0) == 0) {
      const auto colon = line.find(':');
      if (colon != std::string::npos) {
        model = line.substr(colon + 1);
        model.erase(0, model.find_first_not_of(" \t"));
      }
      break;
    }
  }
  long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
  return {{"nproc", std::thread::hardware_concurrency()},
          {"cpu_model", model},
          {"memory_gib", double(pages) * double(page) / double(1ull << 30)},
          {"compiler", __VERSION__},
          {"build_type", SMRDB_BENCH_BUILD_TYPE},
          {"cxx_flags", SMRDB_BENCH_CXX_FLAGS}};
}

double peak_rss_mb() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return double(ru.ru_maxrss) / 1024.0;  // ru_maxrss is in KiB on Linux
}

double current_rss_mb() {
  std::ifstream statm("/proc/self/statm");
  long size = 0, resident = 0;
  if (!(statm >> size >> resident)) return 0.0;
  return double(resident) * double(sysconf(_SC_PAGE_SIZE)) / double(1 << 20);
}

// ---- grid meshes ----------------------------------------------------------------------------

GridMesh finest_mesh(const Crmr& crmr, const Heightfield& dem) {
  GridMesh m;
  std::vector<std::uint32_t> index_of(crmr.header.vertex_count,
                                      std::numeric_limits<std::uint32_t>::max());
  const Georef& g = dem.georef;
  auto to_grid = [&](double w, double origin, double step, int n, const char* axis) {
    const double f = (w - origin) / step;
    const long long i = std::llround(f);
    const double back = origin + double(i) * step;
    if (i < 0 || i >= n || std::abs(back - w) > 1e-9 * std::max(1.0, std::abs(w))) {
      std::ostringstream os;
      os << "finest mesh: vertex " << axis << " = " << w << " is not on the grid";
      throw std::runtime_error(os.str());
    }
    return static_cast<std::uint32_t>(i);
  };
  for (const Op& op : crmr.ops) {
    for (const FragmentTriangle& t : op.fragment) {
      if (t.killer.valid() || t.is_void()) continue;
      std::array<std::uint32_t, 3> tri{};
      for (int k = 0; k < 3; ++k) {
        const VertexId id = op.vertex_id(t, k);
        if (id.value >= index_of.size())
          index_of.resize(id.value + 1, std::numeric_limits<std::uint32_t>::max());
        std::uint32_t& slot = index_of[id.value];
        if (slot == std::numeric_limits<std::uint32_t>::max()) {
          const Vec3& p = op.position(t, k);
          slot = static_cast<std::uint32_t>(m.vertices.size());
          m.vertices.push_back({to_grid(p.x, g.x0, g.dx, dem.width, "x"),
                                to_grid(p.y, g.y0, g.dy, dem.height, "y")});
          m.z.push_back(p.z);
        }
        tri[k] = slot;
      }
      m.triangles.push_back(tri);
    }
  }
  return m;
}

namespace {
constexpr char kMagic[8] = {'S', 'M', 'R', 'G', 'R', 'I', 'D', '1'};
}

void write_grid_mesh(const std::string& path, const GridMesh& mesh) {
  std::ofstream out(path, std::ios::binary);
  if (!out) throw std::runtime_error("cannot write " + path);
  const auto nv = static_cast<std::uint32_t>(mesh.vertices.size());
  const auto nt = static_cast<std::uint32_t>(mesh.triangles.size());
  out.write(kMagic, 8);
  out.write(reinterpret_cast<const char*>(&nv), 4);
  out.write(reinterpret_cast<const char*>(&nt), 4);
  out.write(reinterpret_cast<const char*>(mesh.vertices.data()), std::streamsize(nv) * 8);
  out.write(reinterpret_cast<const char*>(mesh.triangles.data()), std::streamsize(nt) * 12);
  if (!out.flush()) throw std::runtime_error("failed writing " + path);
}

GridMesh read_grid_mesh(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("cannot open " + path);
  char magic[8];
  std::uint32_t nv = 0, nt = 0;
  in.read(magic, 8);
  in.read(reinterpret_cast<char*>(&nv), 4);
  in.read(reinterpret_cast<char*>(&nt), 4);
  if (!in || std::memcmp(magic, kMagic, 8) != 0)
    throw std::runtime_error(path + ": not a SMRGRID1 mesh dump");
  GridMesh m;
  m.vertices.resize(nv);
  m.triangles.resize(nt);
  in.read(reinterpret_cast<char*>(m.vertices.data()), std::streamsize(nv) * 8);
  in.read(reinterpret_cast<char*>(m.triangles.data()), std::streamsize(nt) * 12);
  if (!in) throw std::runtime_error(path + ": truncated mesh dump");
  for (const auto& t : m.triangles) {
    for (std::uint32_t v : t) {
      if (v >= nv) throw std::runtime_error(path + ": triangle index out of range");
    }
  }
  return m;
}

// ---- the exact error-bound check ------------------------------------------------------------

nlohmann::json ErrorBoundReport::to_json() const {
  return {{"ok", ok()},
          {"bound", bound},
          {"tolerance", tolerance},
          {"triangles", triangles},
          {"degenerate_triangles", degenerate_triangles},
          {"bad_vertices", bad_vertices},
          {"nodata_vertex_triangles", nodata_vertex_triangles},
          {"samples", samples},
          {"samples_covered", samples_covered},
          {"all_samples_covered", all_samples_covered()},
          {"dem_has_nodata", dem_has_nodata},
          {"sample_visits", sample_visits},
          {"nodata_samples_covered", nodata_samples_covered},
          {"violations", violations},
          {"over_bound_strict", over_bound_strict},
          {"max_deviation", max_deviation},
          {"rms_deviation", rms_deviation},
          {"first_violation", first_violation},
          {"seconds", seconds}};
}

namespace {
std::int64_t floor_div(std::int64_t n, std::int64_t d) {  // d > 0
  return n >= 0 ? n / d : -((-n + d - 1) / d);
}
std::int64_t ceil_div(std::int64_t n, std::int64_t d) {  // d > 0
  return n >= 0 ? (n + d - 1) / d : -((-n) / d);
}
}  // namespace

ErrorBoundReport check_error_bound(const GridMesh& mesh, const Heightfield& dem, double bound) {
  const std::uint64_t t0 = now_ns();
  ErrorBoundReport r;
  r.bound = bound;
  double zabs = 0.0;
  for (float z : dem.z) zabs = std::max(zabs, double(std::abs(z)));
  r.tolerance = 1e-9 * std::max(1.0, zabs);
  r.triangles = mesh.triangles.size();
  r.dem_has_nodata = dem.has_nodata();

  const std::int64_t W = dem.width, H = dem.height;
  for (std::size_t i = 0; i < dem.z.size(); ++i)
    r.samples += dem.valid.empty() || dem.valid[i] != 0;

  std::vector<std::uint8_t> bad(mesh.vertices.size(), 0);
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i) {
    const auto [c, w] = mesh.vertices[i];
    if (c >= W || w >= H) {
      bad[i] = 1;
    } else if (!mesh.z.empty() && dem.has_data(int(c), int(w)) &&
               mesh.z[i] != double(dem.at(int(c), int(w)))) {
      bad[i] = 1;
    }
    r.bad_vertices += bad[i];
  }

  std::vector<std::uint8_t> covered(dem.z.size(), 0);
  double sumsq = 0.0;
  for (std::size_t ti = 0; ti < mesh.triangles.size(); ++ti) {
    auto tri = mesh.triangles[ti];
    if (bad[tri[0]] || bad[tri[1]] || bad[tri[2]]) continue;
    std::int64_t x[3], y[3];
    double z[3];
    bool nodata_vertex = false;
    for (int k = 0; k < 3; ++k) {
      x[k] = mesh.vertices[tri[k]][0];
      y[k] = mesh.vertices[tri[k]][1];
      nodata_vertex |= !dem.has_data(int(x[k]), int(y[k]));
      z[k] = mesh.z.empty() ? double(dem.at(int(x[k]), int(y[k]))) : mesh.z[tri[k]];
    }
    if (nodata_vertex) {
      ++r.nodata_vertex_triangles;
      continue;
    }
    std::int64_t area = (x[1] - x[0]) * (y[2] - y[0]) - (y[1] - y[0]) * (x[2] - x[0]);
    if (area == 0) {
      ++r.degenerate_triangles;
      continue;
    }
    if (area < 0) {  // make it counter-clockwise
      std::swap(x[1], x[2]);
      std::swap(y[1], y[2]);
      std::swap(z[1], z[2]);
      area = -area;
    }
    const std::int64_t xmin = std::min({x[0], x[1], x[2]}), xmax = std::max({x[0], x[1], x[2]});
    const std::int64_t ymin = std::min({y[0], y[1], y[2]}), ymax = std::max({y[0], y[1], y[2]});
    const double inv_area = 1.0 / double(area);
    for (std::int64_t row = ymin; row <= ymax; ++row) {
      // Sample (col, row) is inside iff orient(a, b, p) >= 0 for the three CCW edges a -> b:
      // (bx - ax)(row - ay) - (by - ay)(col - ax) >= 0, i.e. dy * col <= k with
      // dy = by - ay, k = (bx - ax)(row - ay) + dy * ax. Each edge bounds col on one side.
      std::int64_t lo = xmin, hi = xmax;
      for (int e = 0; e < 3; ++e) {
        const int f = (e + 1) % 3;
        const std::int64_t dy = y[f] - y[e];
        const std::int64_t k = (x[f] - x[e]) * (row - y[e]) + dy * x[e];
        if (dy > 0) {
          hi = std::min(hi, floor_div(k, dy));
        } else if (dy < 0) {
          lo = std::max(lo, ceil_div(-k, -dy));
        } else if (k < 0) {
          lo = 1;
          hi = 0;  // horizontal edge with the row on its outer side
        }
      }
      for (std::int64_t col = lo; col <= hi; ++col) {
        const std::int64_t w0 = (x[2] - x[1]) * (row - y[1]) - (y[2] - y[1]) * (col - x[1]);
        const std::int64_t w1 = (x[0] - x[2]) * (row - y[2]) - (y[0] - y[2]) * (col - x[2]);
        const std::int64_t w2 = area - w0 - w1;
        if (w0 < 0 || w1 < 0 || w2 < 0) {
          throw std::logic_error("error-bound checker: rasteriser produced an outside sample");
        }
        const double zi = (double(w0) * z[0] + double(w1) * z[1] + double(w2) * z[2]) * inv_area;
        const std::size_t idx = std::size_t(row) * std::size_t(W) + std::size_t(col);
        if (!dem.valid.empty() && dem.valid[idx] == 0) {
          ++r.nodata_samples_covered;
          continue;
        }
        ++r.sample_visits;
        const double dev = std::abs(zi - double(dem.z[idx]));
        if (!covered[idx]) {
          covered[idx] = 1;
          ++r.samples_covered;
          sumsq += dev * dev;
        }
        r.max_deviation = std::max(r.max_deviation, dev);
        if (dev > bound) ++r.over_bound_strict;
        if (dev > bound + r.tolerance) {
          if (r.violations++ == 0) {
            std::ostringstream os;
            os.precision(17);
            os << "triangle " << ti << ": sample (" << col << "," << row << ") deviates " << dev
               << " > " << bound;
            r.first_violation = os.str();
          }
        }
      }
    }
  }
  r.rms_deviation = r.samples_covered == 0 ? 0.0 : std::sqrt(sumsq / double(r.samples_covered));
  r.seconds = seconds_since(t0);
  return r;
}

}  // namespace smr::bench
