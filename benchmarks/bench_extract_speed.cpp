// bench_extract_speed: how fast an on-disk database gives back a mesh (issue 34's targets), the
// figure run_extract_vs_martini.sh sets beside @mapbox/martini's getMesh. Prints one JSON object.
//
// Cases, each with minimal surface (Brown 5.1; "minimal-pages": its triangles from the set formula,
// ExpansionOptions::fronts false), reduced extraction (Brown 5.2; terrain only) and, for the
// constant-level case, "level-cut" (smr/query/level_cut.h: what `smrdb extract --floor` runs; its
// mesh comes straight from the pages, no to_mesh; --verify compares it with minimal-pages'):
//   full     an RCF of constant object-space level 1 (`smrdb extract --floor 1`): the whole
//            finest mesh M^m, every data page read;
//   oblique  a 1 px screen-space view (bench_db's named `oblique` camera relative to the bounds,
//            or --eye/--target), culling on.
// Every run is IndexedSource + extract_* + to_mesh (an indexed TriangleMesh in memory, what a
// library user gets), then write_mesh to a binary PLY, timed apart. Each of --repeat rounds opens
// the database afresh (decoded-page cache empty; the file was read once before, so it is in the
// OS page cache: "warm") and runs twice on it: the first run is warm, the second "hot" (decoded
// pages still cached when the --cache-mb budget holds them; `hot_pages_read` says whether it did).
// Reported per run kind: seconds (median, min, all) in memory and with the PLY, triangles/s, the
// phases, and the database's I/O counters (tools/report_json.h: pages and bytes read, cache bytes
// charged; a decode time appears there when DatabaseStats has one).
//
// Why a program of its own: bench_extract runs on a CRMR built in memory, bench_db measures read
// amplification and cold I/O of views; this one times the whole path from a database to an output
// mesh, at full resolution too, and keeps the in-memory and the written output apart.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "base/error.h"
#include "benchmarks/bench_common.h"
#include "benchmarks/bench_db_common.h"
#include "smr/core/invariants.h"
#include "smr/db/database.h"
#include "smr/extract/extract.h"
#include "smr/io/mesh_writer.h"
#include "smr/query/indexed_source.h"
#include "smr/query/level_cut.h"
#include "smr/rcf/spec.h"
#include "tools/report_json.h"

namespace {

using nlohmann::json;
using smr::bench::median;
using smr::bench::now_ns;
using smr::bench::seconds_since;

struct Args {
  std::string db, ply, view = "oblique", eye, target, viewport = "1024x768";
  std::vector<std::string> cases{"full", "oblique"};
  std::vector<std::string> algorithms{"minimal", "minimal-pages", "reduced", "level-cut"};
  double pixel_error = 1.0, fov = 60.0;
  std::uint64_t cache_mb = 1024;
  int repeat = 5;
  bool verify = false;
};

std::string loadavg() {
  std::ifstream in("/proc/loadavg");
  std::string a, b, c;
  in >> a >> b >> c;
  return a + " " + b + " " + c;
}

// after - before for every counter of a DatabaseStats report; "peak" values are kept as they are.
json io_delta(const json& before, const json& after) {
  json d = after;
  for (const auto& [key, value] : after.items()) {
    if (key.find("peak") == std::string::npos && value.is_number_unsigned() && before.contains(key))
      d[key] = value.get<std::uint64_t>() - before[key].get<std::uint64_t>();
  }
  return d;
}

// One extraction on `db`: the counts, times and I/O of the extraction + to_mesh, and the PLY.
struct Run {
  smr::ExtractStats stats;
  std::size_t vertices = 0, triangles = 0;
  double extract = 0, to_mesh = 0, write = 0;
  std::uint64_t ply_bytes = 0;
  json io;
  std::string tiling;  // "ok" or the first failure; empty when not checked
};

// The output's counts, and the PLY written (`ply` non-empty), timed.
void take_mesh(Run& r, const smr::TriangleMesh& mesh, const std::string& ply) {
  r.vertices = mesh.positions.size();
  r.triangles = mesh.triangles.size();
  if (ply.empty()) return;
  const std::uint64_t t0 = now_ns();
  smr::write_mesh(ply, mesh);
  r.write = seconds_since(t0);
  r.ply_bytes = std::filesystem::file_size(ply);
}

// The level cut (smr/query/level_cut.h) of a constant-level case; `verify`: the same triangles as
// the minimal surface's set formula.
Run run_level_cut(const smr::Database& db, const smr::Rcf& rcf, double level,
                  const std::string& ply, bool verify) {
  Run r;
  const json before = db.stats();
  const std::uint64_t t0 = now_ns();
  smr::LevelCutStats cs;
  const std::optional<smr::TriangleMesh> mesh = smr::extract_level_cut(db, level, {}, &cs);
  r.extract = seconds_since(t0);
  if (!mesh) smr::throw_input(db.path() + ": void triangles: the level cut does not apply");
  r.io = io_delta(before, db.stats());
  take_mesh(r, *mesh, ply);
  r.stats.x = r.stats.x_plus = cs.x;
  r.stats.triangles = cs.triangles;
  r.stats.extract_seconds = r.extract;
  if (verify) {
    const std::string differs = smr::check_level_cut(db, rcf, *mesh, cs);
    r.tiling = differs.empty() ? "ok" : differs;
  }
  return r;
}

Run run_once(const smr::Database& db, const smr::Rcf& rcf, const std::string& alg,
             const std::string& ply, bool verify, std::optional<double> level) {
  if (alg == "level-cut") return run_level_cut(db, rcf, *level, ply, verify);
  Run r;
  const json before = db.stats();
  std::uint64_t t0 = now_ns();
  const smr::IndexedSource source(db);
  const smr::Extraction e =
      alg == "reduced" ? smr::extract_reduced(source, rcf)
                       : smr::extract_minimal_surface(source, rcf, {.fronts = alg == "minimal"});
  r.extract = seconds_since(t0);
  t0 = now_ns();
  const smr::TriangleMesh mesh = smr::to_mesh(db, e.triangles);
  r.to_mesh = seconds_since(t0);
  r.io = io_delta(before, db.stats());
  take_mesh(r, mesh, ply);
  r.stats = e.stats;
  if (verify && db.info().kind == smr::ModelKind::kTerrain) {
    const smr::InvariantReport tiling = smr::check_tiling(db, e.triangles);
    r.tiling = tiling.ok() ? "ok" : tiling.summary();
  }
  return r;
}

json seconds_json(const std::vector<double>& all) {
  return {{"median", median(all)},
          {"min", all.empty() ? 0.0 : *std::min_element(all.begin(), all.end())},
          {"all", all}};
}

// The times of one run kind (warm: `open` holds each fresh Database's open; hot: empty).
json runs_json(const std::vector<Run>& runs, const std::vector<double>& open) {
  std::vector<double> in_memory, with_ply, ext, exp, mesh, write;
  for (std::size_t i = 0; i < runs.size(); ++i) {
    const Run& r = runs[i];
    const double o = open.empty() ? 0.0 : open[i];
    in_memory.push_back(o + r.extract + r.to_mesh);
    with_ply.push_back(o + r.extract + r.to_mesh + r.write);
    ext.push_back(r.stats.extract_seconds);
    exp.push_back(r.stats.expand_seconds);
    mesh.push_back(r.to_mesh);
    write.push_back(r.write);
  }
  const double tri = double(runs.front().triangles);
  const auto per_s = [&](const std::vector<double>& s) {
    return median(s) > 0 ? tri / median(s) : 0.0;
  };
  json j = {{"in_memory_seconds", seconds_json(in_memory)},
            {"with_ply_seconds", seconds_json(with_ply)},
            {"triangles_per_second", per_s(in_memory)},
            {"triangles_per_second_best",
             tri / std::max(1e-12, *std::min_element(in_memory.begin(), in_memory.end()))},
            {"triangles_per_second_with_ply", per_s(with_ply)},
            {"phases_median",
             {{"extraction", median(ext)},
              {"expansion", median(exp)},
              {"to_mesh", median(mesh)},
              {"write_ply", median(write)}}},
            {"io_first", runs.front().io}};
  if (!open.empty()) j["phases_median"]["open"] = median(open);
  return j;
}

// Cache charge per data page: every cache load's charged bytes (data pages, and the R-tree
// nodes and op-locator blocks the run also loaded) over the data pages read.
json cache_json(const json& io, std::uint64_t cache_mb) {
  const std::uint64_t pages = io.value("pages_read", std::uint64_t{0});
  const std::uint64_t charged = io.value("bytes_decoded", std::uint64_t{0});
  const double per_page = pages == 0 ? 0.0 : double(charged) / double(pages);
  return {
      {"budget_mb", cache_mb},
      {"charged_bytes", charged},
      {"charged_bytes_per_page", per_page},
      {"pages_per_mib", per_page > 0 ? double(1 << 20) / per_page : 0.0},
      {"page_bytes_per_page",
       pages == 0 ? 0.0 : double(io.value("page_bytes_read", std::uint64_t{0})) / double(pages)},
      {"evictions", io.value("cache_evictions", std::uint64_t{0})}};
}

json run_case(const Args& a, const std::string& name, const smr::Rcf& rcf, const std::string& alg,
              std::optional<double> level) {
  std::vector<Run> warm, hot;
  std::vector<double> open;
  for (int i = 0; i < a.repeat; ++i) {
    const std::uint64_t t0 = now_ns();
    const auto db = smr::Database::open(a.db, {std::size_t(a.cache_mb) << 20});
    open.push_back(seconds_since(t0));
    warm.push_back(run_once(*db, rcf, alg, a.ply, a.verify && i == 0, level));
    hot.push_back(run_once(*db, rcf, alg, a.ply, false, level));
  }
  const Run& first = warm.front();
  const smr::ExtractStats& s = first.stats;
  json c = {{"case", name},
            {"algorithm", alg},
            {"rcf", rcf.describe()},
            {"triangles", first.triangles},
            {"mesh_vertices", first.vertices},
            {"void_triangles", s.void_triangles},
            {"x", s.x},
            {"x_plus", s.x_plus},
            {"ops_visited", s.ops_visited},
            {"fans", s.fans},
            {"ply_bytes", first.ply_bytes},
            {"warm", runs_json(warm, open)},
            {"hot", runs_json(hot, {})},
            {"hot_pages_read", hot.front().io.value("pages_read", std::uint64_t{0})},
            {"cache", cache_json(first.io, a.cache_mb)}};
  if (!first.tiling.empty()) c["tiling"] = first.tiling;
  std::fprintf(stderr,
               "  %-7s %-13s %9zu triangles  warm %.3f s (%.3g tri/s), +PLY %.3f s, hot %.3f s; "
               "%llu pages read\n",
               name.c_str(), alg.c_str(), first.triangles,
               c["warm"]["in_memory_seconds"]["median"].get<double>(),
               c["warm"]["triangles_per_second"].get<double>(),
               c["warm"]["with_ply_seconds"]["median"].get<double>(),
               c["hot"]["in_memory_seconds"]["median"].get<double>(),
               static_cast<unsigned long long>(first.io.value("pages_read", std::uint64_t{0})));
  return c;
}

// The database's size and format (the meta record's fields, whatever the format calls them).
json database_json(const Args& a) {
  const auto db = smr::Database::open(a.db, {std::size_t{16} << 20});
  const json meta = json::parse(db->meta_json());
  const std::uint64_t vertices = db->info().vertex_count;
  return {
      {"path", a.db},
      {"file_bytes", db->file_bytes()},
      {"vertices", vertices},
      {"ops", db->op_count()},
      {"pages", db->page_count()},
      {"bytes_per_vertex", double(db->file_bytes()) / double(std::max<std::uint64_t>(1, vertices))},
      {"format", meta.value("format", json())},
      {"version", meta.value("version", json())},
      {"codec", meta.value("codec", json())},
      {"counts", meta.value("counts", json())},
      {"bytes", meta.value("bytes", json())},
      {"err_final", db->info().err_final},
      {"kind", db->info().kind == smr::ModelKind::kTerrain ? "terrain" : "mesh"}};
}

smr::Camera oblique_camera(const Args& a, const smr::Box3& bounds, json& out) {
  smr::Camera cam;
  if (!a.eye.empty() || !a.target.empty()) {
    cam.eye = smr::bench::parse_vec3(a.eye, "--eye");
    cam.target = smr::bench::parse_vec3(a.target, "--target");
    out["view"] = "explicit";
  } else {
    cam = smr::bench::named_camera(a.view, bounds);
    out["view"] = a.view;
  }
  int w = 0, h = 0;
  char x = 0;
  std::istringstream vs(a.viewport);
  if (!(vs >> w >> x >> h) || x != 'x') smr::throw_input("--viewport expects WxH");
  cam.fov_y_deg = a.fov;
  cam.viewport_w = w;
  cam.viewport_h = h;
  out["camera"] = smr::bench::camera_json(cam);
  return cam;
}

json run(const Args& a) {
  json out = {{"benchmark", "extract_speed"}, {"cache_mb", a.cache_mb}, {"repeat", a.repeat}};
  out["machine"] = smr::bench::machine_json();
  out["loadavg_before"] = loadavg();
  out["db"] = database_json(a);
  const std::uint64_t file_bytes = out["db"]["file_bytes"].get<std::uint64_t>();
  out["os_cache"] = {{"read_before_runs", smr::bench::warm_page_cache(a.db)},
                     {"resident_before_runs", smr::bench::resident_bytes(a.db)},
                     {"file_bytes", file_bytes}};
  std::fprintf(stderr, "bench_extract_speed %s (%.1f MB)\n", a.db.c_str(),
               double(file_bytes) / 1e6);
  const smr::CrmrInfo info = smr::Database::open(a.db, {std::size_t{16} << 20})->info();
  json cases = json::array();
  for (const std::string& name : a.cases) {
    smr::RcfSpec spec;
    if (name == "full") {
      spec.floor = 1.0;
    } else if (name == "oblique") {
      spec.camera = oblique_camera(a, info.bounds, out);
      spec.pixel_error = a.pixel_error;
    } else {
      smr::throw_input("--cases: unknown case '" + name + "' (full, oblique)");
    }
    smr::validate(spec);
    const smr::Rcf rcf = smr::make_rcf(spec, info.kind, nullptr);
    for (const std::string& alg : a.algorithms) {
      if (alg != "minimal" && alg != "minimal-pages" && alg != "reduced" && alg != "level-cut")
        smr::throw_input("--algorithms: unknown algorithm '" + alg + "'");
      if (alg == "reduced" && info.kind != smr::ModelKind::kTerrain) continue;
      const std::optional<double> level = smr::constant_level(spec);
      if (alg == "level-cut" && !level) continue;  // a constant level only
      cases.push_back(run_case(a, name, rcf, alg, level));
    }
  }
  out["cases"] = cases;
  out["os_cache"]["resident_after_runs"] = smr::bench::resident_bytes(a.db);
  out["loadavg_after"] = loadavg();
  out["peak_rss_mb"] = smr::bench::peak_rss_mb();
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"bench_extract_speed: a database to a mesh, full resolution and a 1 px view (JSON)"};
  Args a;
  app.add_option("db", a.db, "Database file")->required();
  app.add_option("--cases", a.cases, "full,oblique")->delimiter(',')->capture_default_str();
  app.add_option("--algorithms", a.algorithms,
                 "minimal,minimal-pages,reduced,level-cut (the last: constant-level cases only)")
      ->delimiter(',')
      ->capture_default_str();
  app.add_option("--cache-mb", a.cache_mb, "Decoded-page cache budget, MiB")->capture_default_str();
  app.add_option("--repeat", a.repeat, "Fresh databases per case (medians)")->capture_default_str();
  app.add_option("--ply", a.ply, "Binary PLY written by every run (empty: none)");
  app.add_option("--view", a.view, "oblique case: named camera (oblique, overview)")
      ->capture_default_str();
  app.add_option("--eye", a.eye, "oblique case: explicit camera position x,y,z (with --target)");
  app.add_option("--target", a.target, "oblique case: explicit camera target x,y,z");
  app.add_option("--viewport", a.viewport, "oblique case: viewport WxH")->capture_default_str();
  app.add_option("--fov", a.fov, "oblique case: vertical field of view, degrees")
      ->capture_default_str();
  app.add_option("--pixel-error", a.pixel_error, "oblique case: screen-space tolerance, pixels")
      ->capture_default_str();
  app.add_flag("--verify", a.verify, "Check that the first output of each case tiles the domain");
  CLI11_PARSE(app, argc, argv);
  a.repeat = std::max(1, a.repeat);
  try {
    std::cout << run(a).dump(2) << "\n";
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_extract_speed: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
