// bench_query: the GIS queries of issue 36 (smr/query: Maheshwari et al. 3.2, 4.1-4.3) on terrain
// databases. Prints one JSON object. Every query goes through an IndexedSource. Modes:
//
//   fig DB        Maheshwari Figs. 10-11: windows of 1/F of the domain's area (--fractions) at
//                 --locations random places (--seed), refined at the finest accuracy: |X| (ops
//                 fetched), the distinct vertices of the result inside the window, their ratio,
//                 and the vertices the ops of X introduce (what a vertex split each would be).
//                 Point queries at as many random places: ElevationAnswer::ops_read (the descent,
//                 one op per DAG level) and |X| of refine() on the degenerate window [p, p] (the
//                 paper's selective refinement of a point region, ancestors included).
//   latency DB    Point elevation at random points, each from a fresh ElevationQuery: warm (after
//                 a warm-up on other points), cold (Database::clear_cache() before each point) and
//                 OS-cold (the file dropped from the OS page cache with posix_fadvise and the
//                 database reopened before each point). Batch: ElevationQuery::at_many over
//                 --batch random points, twice (the second pass warm). --write-points writes the
//                 batch's points as CSV for `smrdb query DB elevation --input`.
//   sight DB      line_of_sight between random pairs (q within --reach of the extent of p, both
//                 ends at the surface plus U(0, --lift)), and profile() along random polylines of
//                 --legs legs; warm and cold (clear_cache() before each query).
//   contours DB   contours() of the whole DEM at --interval, then write_geojson to -o: seconds of
//                 each phase, lines, rings, points.
//
// Latencies are per query (steady_clock), summarised as mean, p50, p99 and max; pages are
// DatabaseStats::pages_read per query.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include <unistd.h>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "base/error.h"
#include "benchmarks/bench_common.h"
#include "benchmarks/bench_db_common.h"
#include "smr/db/database.h"
#include "smr/query/contours.h"
#include "smr/query/elevation.h"
#include "smr/query/indexed_source.h"
#include "smr/query/region.h"
#include "smr/query/sight.h"

namespace {

using nlohmann::json;
using smr::Vec2;
using smr::Vec3;
using smr::bench::now_ns;
using smr::bench::seconds_since;
namespace q = smr::query;

struct Common {
  std::string db;
  std::uint64_t cache_mb = 1024;
  std::uint64_t seed = 1;
};

// ---- statistics -----------------------------------------------------------------------------

// n, mean, min, p50, p99 (nearest rank), max.
json summary(std::vector<double> v) {
  if (v.empty()) return {{"n", 0}};
  std::sort(v.begin(), v.end());
  double sum = 0.0;
  for (double x : v) sum += x;
  const auto rank = [&](double p) {
    const auto k = static_cast<std::size_t>(std::ceil(p * double(v.size())));
    return v[std::min(v.size() - 1, k == 0 ? 0 : k - 1)];
  };
  return {{"n", v.size()},     {"mean", sum / double(v.size())},
          {"min", v.front()},  {"p50", rank(0.5)},
          {"p99", rank(0.99)}, {"max", v.back()}};
}

// Per-query samples of one measured series.
struct Series {
  std::vector<double> ms, ops, pages;
  void add(double seconds, double op_count, double pages_read) {
    ms.push_back(seconds * 1e3);
    ops.push_back(op_count);
    pages.push_back(pages_read);
  }
  json to_json() const {
    return {{"ms", summary(ms)}, {"ops", summary(ops)}, {"pages_read", summary(pages)}};
  }
};

// ---- the database ---------------------------------------------------------------------------

std::unique_ptr<smr::Database> open_db(const Common& c) {
  return smr::Database::open(c.db, {std::size_t(c.cache_mb) << 20});
}

json database_json(const smr::Database& db) {
  const smr::CrmrInfo& info = db.info();
  const json meta = json::parse(db.meta_json());
  return {{"path", db.path()},
          {"file_bytes", db.file_bytes()},
          {"samples", std::uint64_t(info.grid_width) * std::uint64_t(info.grid_height)},
          {"grid", {info.grid_width, info.grid_height}},
          {"vertices", info.vertex_count},
          {"ops", db.op_count()},
          {"pages", db.page_count()},
          {"dag_depth", meta["counts"]["dag_depth"]},
          {"builder", info.builder},
          {"err0", info.err0},
          {"err_final", info.err_final}};
}

// Decodes every data page into the cache (warm: a query then reads no page if the cache holds
// them all). Returns the pages the cache read.
std::uint64_t warm_all_pages(const smr::Database& db) {
  const std::uint64_t before = db.stats().pages_read;
  for (std::uint64_t p = 0; p < db.page_count(); ++p) db.page(p);
  return db.stats().pages_read - before;
}

// Empties the kernel's page cache, dentries and inodes (root only). "" when done, else why not.
std::string drop_all_os_caches() {
  ::sync();
  std::ofstream f("/proc/sys/vm/drop_caches");
  if (!f) return "cannot open /proc/sys/vm/drop_caches for writing (not root?)";
  f << "3\n";
  f.flush();
  return f ? "" : "writing /proc/sys/vm/drop_caches failed";
}

// Uniform random points and windows inside a terrain's domain.
class Sampler {
 public:
  Sampler(const q::Domain& d, std::uint64_t seed) : d_(d), rng_(seed) {}
  const q::Domain& domain() const { return d_; }
  Vec2 extent() const { return d_.hi - d_.lo; }
  double uniform(double lo, double hi) {
    return std::uniform_real_distribution<double>(lo, hi)(rng_);
  }
  Vec2 point() { return {uniform(d_.lo.x, d_.hi.x), uniform(d_.lo.y, d_.hi.y)}; }
  // A point within `reach` (a fraction of the extent, per axis) of p, inside the domain.
  Vec2 near(const Vec2& p, double reach) {
    const Vec2 r = extent() * reach;
    for (;;) {
      const Vec2 c{p.x + uniform(-r.x, r.x), p.y + uniform(-r.y, r.y)};
      if (d_.contains(c) && c != p) return c;
    }
  }
  // The lower corner of a window of size `side` that lies inside the domain.
  Vec2 window_lo(const Vec2& side) {
    return {uniform(d_.lo.x, d_.hi.x - side.x), uniform(d_.lo.y, d_.hi.y - side.y)};
  }
  std::vector<Vec2> points(std::size_t n) {
    std::vector<Vec2> out(n);
    for (Vec2& p : out) p = point();
    return out;
  }

 private:
  q::Domain d_;
  std::mt19937_64 rng_;
};

// ---- mode: fig (Maheshwari Figs. 10-11) -----------------------------------------------------

struct FigArgs {
  Common c;
  int locations = 2500;
  std::vector<int> fractions{25, 4};
  bool point_refine = true;
};

// Counts the distinct vertices of the result's triangles with data lying in a closed window. Ids
// below a bound are stamped in a table (one pass), larger ones sorted.
class VertexCounter {
 public:
  explicit VertexCounter(std::uint64_t vertices)
      : stamp_(std::min<std::uint64_t>(vertices * 4, 1u << 26), 0) {}
  std::uint64_t count(const smr::OpSource& src, const smr::Extraction& e, Vec2 lo, Vec2 hi) {
    ++now_;
    std::uint64_t n = 0;
    std::vector<std::uint64_t> big;
    smr::OpRef op;
    for (const smr::TriRef& t : e.triangles) {
      if (!op || op->id != t.op) op = src.op(t.op);  // the set formula's triangles come op by op
      const smr::FragmentTriangle& f = op->fragment[t.index];
      if (f.is_void()) continue;
      for (int k = 0; k < 3; ++k) {
        const Vec3& p = op->position(f, k);
        if (!(p.x >= lo.x && p.x <= hi.x && p.y >= lo.y && p.y <= hi.y)) continue;
        const std::uint64_t id = op->vertex_id(f, k).value;
        if (id >= stamp_.size()) {
          big.push_back(id);
        } else if (stamp_[id] != now_) {
          stamp_[id] = now_;
          ++n;
        }
      }
    }
    std::sort(big.begin(), big.end());
    return n + std::uint64_t(std::unique(big.begin(), big.end()) - big.begin());
  }

 private:
  std::vector<std::uint32_t> stamp_;
  std::uint32_t now_ = 0;
};

// The vertices each op introduces (V(R), what a vertex split each would be in a PM), by op id.
std::vector<std::uint32_t> introduced_vertices(const smr::OpSource& src) {
  std::vector<std::uint32_t> out(src.op_count());
  for (std::uint64_t i = 0; i < out.size(); ++i) out[i] = src.op(smr::OpId(i))->new_vertex_count;
  return out;
}

struct FigContext {
  const smr::Database& db;
  const smr::IndexedSource& src;
  std::vector<std::uint32_t> introduced;
  VertexCounter counter;
};

json fig_windows(FigContext& c, Sampler& s, int fraction, int locations) {
  const Vec2 side = s.extent() / std::sqrt(double(fraction));
  std::vector<double> ratio, split_ratio, x, verts, ms, pages;
  double sum_x = 0, sum_v = 0, sum_new = 0;
  for (int i = 0; i < locations; ++i) {
    const Vec2 lo = s.window_lo(side), hi = lo + side;
    const std::uint64_t pages0 = c.db.stats().pages_read, t0 = now_ns();
    const smr::Extraction e =
        q::refine(c.src, std::make_shared<q::WindowRegion>(lo, hi), q::Accuracy::finest());
    ms.push_back(seconds_since(t0) * 1e3);
    pages.push_back(double(c.db.stats().pages_read - pages0));
    const auto v = double(c.counter.count(c.src, e, lo, hi));
    double introduced = 0;
    for (const smr::OpId id : e.x) introduced += c.introduced[id.value];
    x.push_back(double(e.stats.x));
    verts.push_back(v);
    if (v > 0) {
      ratio.push_back(double(e.stats.x) / v);
      split_ratio.push_back(introduced / v);
    }
    sum_x += double(e.stats.x);
    sum_v += v;
    sum_new += introduced;
  }
  return {{"fraction", 1.0 / fraction},
          {"window", {side.x, side.y}},
          {"locations", locations},
          {"ops_fetched", summary(x)},
          {"vertices_in_window", summary(verts)},
          {"ratio", summary(ratio)},
          {"ratio_of_sums", sum_v > 0 ? sum_x / sum_v : 0.0},
          {"introduced_ratio", summary(split_ratio)},
          {"introduced_ratio_of_sums", sum_v > 0 ? sum_new / sum_v : 0.0},
          {"ms", summary(ms)},
          {"pages_read", summary(pages)}};
}

json fig_points(const smr::IndexedSource& src, Sampler& s, const FigArgs& a) {
  std::vector<double> ops, ms, refine_x, refine_ms;
  for (int i = 0; i < a.locations; ++i) {
    const Vec2 p = s.point();
    std::uint64_t t0 = now_ns();
    const q::ElevationQuery query(src);
    const q::ElevationAnswer ans = query.at(p, q::Accuracy::finest());
    ms.push_back(seconds_since(t0) * 1e3);
    ops.push_back(ans.ops_read);
    if (a.point_refine) {
      t0 = now_ns();
      const smr::Extraction e =
          q::refine(src, std::make_shared<q::WindowRegion>(p, p), q::Accuracy::finest());
      refine_ms.push_back(seconds_since(t0) * 1e3);
      refine_x.push_back(double(e.stats.x));
    }
  }
  json out = {
      {"locations", a.locations}, {"descent_ops", summary(ops)}, {"descent_ms", summary(ms)}};
  if (a.point_refine) {
    out["refine_ops"] = summary(refine_x);
    out["refine_ms"] = summary(refine_ms);
  }
  return out;
}

json mode_fig(const FigArgs& a) {
  const auto db = open_db(a.c);
  const smr::IndexedSource src(*db);
  json out = {{"mode", "fig"}, {"db", database_json(*db)}, {"cache_mb", a.c.cache_mb}};
  Sampler s(q::terrain_domain(db->info()), a.c.seed);
  FigContext c{*db, src, introduced_vertices(src), VertexCounter(db->info().vertex_count)};
  const std::uint64_t t0 = now_ns();
  out["windows"] = json::array();
  for (int f : a.fractions) out["windows"].push_back(fig_windows(c, s, f, a.locations));
  out["points"] = fig_points(src, s, a);
  out["seconds"] = seconds_since(t0);
  return out;
}

// ---- mode: latency (point and batch elevation) ----------------------------------------------

struct LatencyArgs {
  Common c;
  int warm = 10000, warmup = 1000, cold = 200, os_cold = 200, drop_all = 10;
  std::uint64_t batch = 1000000;
  std::string write_points;
};

// One point from a fresh ElevationQuery, timed, into `s`.
void time_point(const smr::Database& db, const smr::IndexedSource& src, const Vec2& p, Series& s) {
  const std::uint64_t pages0 = db.stats().pages_read, t0 = now_ns();
  const q::ElevationQuery query(src);
  const q::ElevationAnswer ans = query.at(p, q::Accuracy::finest());
  s.add(seconds_since(t0), ans.ops_read, double(db.stats().pages_read - pages0));
}

// `n` points, each on a fresh Database after the OS page cache lost the file: dropped with
// posix_fadvise (the file alone, checked with mincore), or with `drop_all`, the whole kernel page
// cache through /proc/sys/vm/drop_caches.
json os_cold_points(const LatencyArgs& a, Sampler& s, int n, bool drop_all) {
  Series series;
  std::vector<double> open_ms;
  std::uint64_t resident_after_drop = 0;
  for (int i = 0; i < n; ++i) {
    if (drop_all) {
      const std::string why = drop_all_os_caches();
      if (!why.empty()) return {{"error", why}};
    }
    resident_after_drop = std::max(resident_after_drop, smr::bench::drop_from_page_cache(a.c.db));
    const std::uint64_t t0 = now_ns();
    const auto db = open_db(a.c);
    open_ms.push_back(seconds_since(t0) * 1e3);
    const smr::IndexedSource src(*db);
    time_point(*db, src, s.point(), series);
  }
  json out = series.to_json();
  out["open_ms"] = summary(open_ms);
  out["max_resident_bytes_after_drop"] = resident_after_drop;
  return out;
}

// at_many over `pts`, with the cache as it is or emptied first.
json batch_elevation(const smr::Database& db, const smr::IndexedSource& src,
                     const std::vector<Vec2>& pts, bool clear_first) {
  if (clear_first) db.clear_cache();
  const std::uint64_t pages0 = db.stats().pages_read, t0 = now_ns();
  const q::ElevationQuery query(src);
  const std::vector<q::ElevationAnswer> ans = query.at_many(pts, q::Accuracy::finest());
  const double sec = seconds_since(t0);
  double ops = 0;
  std::uint64_t nodata = 0;
  for (const q::ElevationAnswer& x : ans) {
    ops += x.ops_read;
    nodata += x.has_data ? 0 : 1;
  }
  return {{"points", pts.size()},
          {"seconds", sec},
          {"points_per_second", double(pts.size()) / sec},
          {"mean_ops", ops / double(pts.size())},
          {"no_data", nodata},
          {"pages_read", db.stats().pages_read - pages0}};
}

void write_points_csv(const std::string& path, const std::vector<Vec2>& pts) {
  std::ofstream f(path);
  f.precision(17);
  f << "x,y\n";
  for (const Vec2& p : pts) f << p.x << ',' << p.y << '\n';
  if (!f) smr::throw_io(path + ": cannot write the points");
}

json mode_latency(const LatencyArgs& a) {
  json out = {{"mode", "latency"}, {"cache_mb", a.c.cache_mb}};
  Sampler s(q::terrain_domain(smr::Database::open(a.c.db, {})->info()), a.c.seed);
  {
    smr::bench::warm_page_cache(a.c.db);
    const auto db = open_db(a.c);
    const smr::IndexedSource src(*db);
    out["db"] = database_json(*db);
    out["warm_pages_decoded"] = warm_all_pages(*db);
    Series warmup, warm, cold;
    for (int i = 0; i < a.warmup; ++i) time_point(*db, src, s.point(), warmup);
    for (int i = 0; i < a.warm; ++i) time_point(*db, src, s.point(), warm);
    out["point_warm"] = warm.to_json();
    const std::vector<Vec2> pts = s.points(a.batch);
    if (!a.write_points.empty()) write_points_csv(a.write_points, pts);
    out["batch_warm"] = batch_elevation(*db, src, pts, false);
    out["batch_cache_cleared"] = batch_elevation(*db, src, pts, true);
    for (int i = 0; i < a.cold; ++i) {
      db->clear_cache();
      time_point(*db, src, s.point(), cold);
    }
    out["point_cold"] = cold.to_json();
  }
  if (a.os_cold > 0) out["point_os_cold"] = os_cold_points(a, s, a.os_cold, false);
  if (a.drop_all > 0) out["point_drop_caches"] = os_cold_points(a, s, a.drop_all, true);
  smr::bench::warm_page_cache(a.c.db);  // leave the file as the next step expects it
  return out;
}

// ---- mode: sight (line of sight and profiles) -----------------------------------------------

struct SightArgs {
  Common c;
  int pairs = 1000, cold_pairs = 200, profiles = 100, cold_profiles = 50, legs = 10;
  double reach = 0.1, lift = 30.0;
};

struct Pair {
  Vec3 p, q;
};

std::vector<Pair> make_pairs(const smr::IndexedSource& src, Sampler& s, const SightArgs& a, int n) {
  const q::ElevationQuery height(src);
  const auto at_surface = [&](const Vec2& xy) {
    return Vec3{xy.x, xy.y, height.at(xy, q::Accuracy::finest()).z + s.uniform(0.0, a.lift)};
  };
  std::vector<Pair> out;
  for (int i = 0; i < n; ++i) {
    const Vec2 p = s.point();
    out.push_back({at_surface(p), at_surface(s.near(p, a.reach))});
  }
  return out;
}

std::vector<std::vector<Vec2>> make_polylines(Sampler& s, const SightArgs& a, int n) {
  std::vector<std::vector<Vec2>> out(static_cast<std::size_t>(n));
  for (auto& line : out) {
    line.push_back(s.point());
    for (int k = 0; k < a.legs; ++k) line.push_back(s.near(line.back(), a.reach));
  }
  return out;
}

json sight_series(const smr::Database& db, const smr::IndexedSource& src,
                  const std::vector<Pair>& pairs, std::size_t n, bool cold) {
  Series series;
  std::vector<double> tested;
  std::uint64_t counts[3] = {0, 0, 0};
  for (std::size_t i = 0; i < n && i < pairs.size(); ++i) {
    if (cold) db.clear_cache();
    const std::uint64_t pages0 = db.stats().pages_read, t0 = now_ns();
    const q::SightAnswer ans = q::line_of_sight(src, pairs[i].p, pairs[i].q, q::Accuracy::finest());
    series.add(seconds_since(t0), double(ans.ops), double(db.stats().pages_read - pages0));
    tested.push_back(double(ans.triangles_tested));
    ++counts[static_cast<int>(ans.sight)];
  }
  json out = series.to_json();
  out["triangles_tested"] = summary(tested);
  out["visible"] = counts[0];
  out["blocked"] = counts[1];
  out["undecided"] = counts[2];
  return out;
}

json profile_series(const smr::Database& db, const smr::IndexedSource& src,
                    const std::vector<std::vector<Vec2>>& lines, std::size_t n, bool cold) {
  Series series;
  std::vector<double> points;
  for (std::size_t i = 0; i < n && i < lines.size(); ++i) {
    if (cold) db.clear_cache();
    const std::uint64_t pages0 = db.stats().pages_read, t0 = now_ns();
    const q::ProfileResult r = q::profile(src, lines[i], q::Accuracy::finest());
    series.add(seconds_since(t0), double(r.ops), double(db.stats().pages_read - pages0));
    points.push_back(double(r.points.size()));
  }
  json out = series.to_json();
  out["profile_points"] = summary(points);
  return out;
}

json mode_sight(const SightArgs& a) {
  const auto db = open_db(a.c);
  const smr::IndexedSource src(*db);
  json out = {{"mode", "sight"},  {"db", database_json(*db)}, {"cache_mb", a.c.cache_mb},
              {"reach", a.reach}, {"lift", a.lift},           {"legs", a.legs}};
  Sampler s(q::terrain_domain(db->info()), a.c.seed);
  smr::bench::warm_page_cache(a.c.db);
  out["warm_pages_decoded"] = warm_all_pages(*db);
  const std::vector<Pair> warmup = make_pairs(src, s, a, a.pairs);
  const std::vector<Pair> pairs = make_pairs(src, s, a, a.pairs);
  const auto warmup_lines = make_polylines(s, a, a.profiles);
  const auto lines = make_polylines(s, a, a.profiles);
  sight_series(*db, src, warmup, warmup.size(), false);
  out["sight_warm"] = sight_series(*db, src, pairs, pairs.size(), false);
  out["sight_cold"] = sight_series(*db, src, pairs, std::size_t(a.cold_pairs), true);
  warm_all_pages(*db);
  profile_series(*db, src, warmup_lines, warmup_lines.size(), false);
  out["profile_warm"] = profile_series(*db, src, lines, lines.size(), false);
  out["profile_cold"] = profile_series(*db, src, lines, std::size_t(a.cold_profiles), true);
  return out;
}

// ---- mode: contours -------------------------------------------------------------------------

struct ContourArgs {
  Common c;
  double interval = 50.0, base = 0.0;
  std::string output;
};

json mode_contours(const ContourArgs& a) {
  const std::uint64_t t_open = now_ns();
  const auto db = open_db(a.c);
  const smr::IndexedSource src(*db);
  const double open_seconds = seconds_since(t_open);
  q::ContourOptions o;
  o.interval = a.interval;
  o.base = a.base;
  o.accuracy = q::Accuracy::finest();
  std::uint64_t t0 = now_ns();
  const q::ContourResult r = q::contours(src, o);
  const double contour_seconds = seconds_since(t0);
  t0 = now_ns();
  {
    std::ofstream f(a.output, std::ios::binary);
    if (!f) smr::throw_io(a.output + ": cannot open");
    q::write_geojson(f, r, db->info().georef);
  }
  const double write_seconds = seconds_since(t0);
  double max_error = 0;
  for (const q::ContourLine& l : r.lines) max_error = std::max(max_error, l.error);
  const q::ContourStats& st = r.stats;
  return {{"mode", "contours"},
          {"db", database_json(*db)},
          {"cache_mb", a.c.cache_mb},
          {"interval", a.interval},
          {"base", a.base},
          {"output", a.output},
          {"output_bytes", std::filesystem::file_size(a.output)},
          {"open_seconds", open_seconds},
          {"contour_seconds", contour_seconds},
          {"write_seconds", write_seconds},
          {"seconds", contour_seconds + write_seconds},
          {"phases",
           {{"refine", st.refine_seconds}, {"march", st.march_seconds}, {"join", st.join_seconds}}},
          {"levels", st.levels},
          {"ops", st.ops},
          {"triangles", st.triangles},
          {"segments", st.segments},
          {"lines", st.polylines},
          {"rings", st.rings},
          {"points", st.points},
          {"max_line_error", max_error},
          {"pages_read", db->stats().pages_read}};
}

void add_common(CLI::App* app, Common& c) {
  app->add_option("db", c.db, "Database file")->required();
  app->add_option("--cache-mb", c.cache_mb, "Decoded-page cache, MiB")->capture_default_str();
  app->add_option("--seed", c.seed, "Random seed of the locations")->capture_default_str();
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"bench_query: GIS queries on terrain databases (JSON on stdout)"};
  app.require_subcommand(1);
  FigArgs fa;
  CLI::App* fig = app.add_subcommand("fig", "Maheshwari Figs. 10-11: windows and points");
  add_common(fig, fa.c);
  fig->add_option("--locations", fa.locations, "Random locations per test")->capture_default_str();
  fig->add_option("--fractions", fa.fractions, "Window = 1/F of the area (list)")
      ->delimiter(',')
      ->capture_default_str();
  bool no_point_refine = false;
  fig->add_flag("--no-point-refine", no_point_refine, "Skip refine() of the point windows");

  LatencyArgs la;
  CLI::App* lat = app.add_subcommand("latency", "Point and batch elevation latency");
  add_common(lat, la.c);
  lat->add_option("--warm", la.warm, "Warm points")->capture_default_str();
  lat->add_option("--warmup", la.warmup, "Warm-up points (not reported)")->capture_default_str();
  lat->add_option("--cold", la.cold, "Points after clear_cache()")->capture_default_str();
  lat->add_option("--os-cold", la.os_cold, "Points with the file dropped from the OS cache")
      ->capture_default_str();
  lat->add_option("--drop-all", la.drop_all,
                  "Points after echo 3 > /proc/sys/vm/drop_caches (root; 0: none)")
      ->capture_default_str();
  lat->add_option("--batch", la.batch, "Points of the at_many batch")->capture_default_str();
  lat->add_option("--write-points", la.write_points, "Write the batch's points (CSV)");

  SightArgs sa;
  CLI::App* sight = app.add_subcommand("sight", "Line of sight and profile latency");
  add_common(sight, sa.c);
  sight->add_option("--pairs", sa.pairs, "Warm pairs")->capture_default_str();
  sight->add_option("--cold-pairs", sa.cold_pairs, "Cold pairs")->capture_default_str();
  sight->add_option("--profiles", sa.profiles, "Warm profiles")->capture_default_str();
  sight->add_option("--cold-profiles", sa.cold_profiles, "Cold profiles")->capture_default_str();
  sight->add_option("--legs", sa.legs, "Legs per profile")->capture_default_str();
  sight->add_option("--reach", sa.reach, "Max offset of q from p, fraction of the extent per axis")
      ->capture_default_str();
  sight->add_option("--lift", sa.lift, "Ends at the surface + U(0, lift)")->capture_default_str();

  ContourArgs ca;
  CLI::App* con = app.add_subcommand("contours", "Whole-DEM contours written as GeoJSON");
  add_common(con, ca.c);
  con->add_option("--interval", ca.interval, "Contour interval")->capture_default_str();
  con->add_option("--base", ca.base, "Contour base")->capture_default_str();
  con->add_option("-o,--output", ca.output, "GeoJSON output")->required();
  CLI11_PARSE(app, argc, argv);
  try {
    json out;
    if (*fig) {
      fa.point_refine = !no_point_refine;
      out = mode_fig(fa);
    } else if (*lat) {
      out = mode_latency(la);
    } else if (*sight) {
      out = mode_sight(sa);
    } else {
      out = mode_contours(ca);
    }
    out["machine"] = smr::bench::machine_json();
    out["peak_rss_mb"] = smr::bench::peak_rss_mb();
    std::cout << out.dump(2) << "\n";
  } catch (const smr::Error& e) {
    std::fprintf(stderr, "bench_query: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
