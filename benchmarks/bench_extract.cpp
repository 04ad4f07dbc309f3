// bench_extract: selective mesh refinement results in the style of Brown's Tables 7.1, 7.4 and 7.5
// (Brown ch. 7.1.1, 7.2.1): for each terrain, the CRMR built by greedy Delaunay insertion
// (samples, vertices and triangles of M^m, fragments), then, for a set of RCFs and both
// extraction algorithms (minimal surface, Brown 5.1; reduced extraction, Brown 5.2):
// |X|, |X+|, |F| (output triangles), triangles per fan, extraction, expansion and total time.
// Finally the extraction throughput (output triangles per second, median of >= 5 runs) for a
// view of the 4097^2 synthetic terrain.
//
// RCFs (one camera per terrain, looking across the domain from inside its south-west quarter):
//   object      Brown's Mt St Helens function: floor 0.70, disc 0.95 at the centre, critical
//               lines 0.98, Gaussian AOI 0.99 in the foreground; with and without culling
//   screen Npx  screen-space tolerance N pixels (N = 1, 4), 1024x768, 60 deg; with and without
//               frustum + back-face culling
//   finest      g = 1 everywhere: M^m itself (Brown's "highest resolution mesh")
// Geographic DEMs are converted to local metres first (bench_common.h: to_local_metres), so that
// cameras and screen-space errors do not mix degrees with metres.
#include <algorithm>
#include <cstdio>
#include <iostream>
#include <optional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "benchmarks/bench_common.h"
#include "smr/builders/terrain/greedy_tin.h"
#include "smr/core/invariants.h"
#include "smr/extract/extract.h"
#include "smr/rcf/spec.h"

namespace {

using nlohmann::json;
using smr::bench::median;

struct DatasetSpec {
  std::string name;
  smr::bench::InputOptions input;
  double max_error_fraction = 0.001;
};

struct RcfCase {
  std::string label;
  smr::RcfSpec spec;
};

// The camera and RCFs for one terrain (world coordinates of the local-metre DEM).
std::vector<RcfCase> rcf_cases(const smr::Heightfield& dem, double z_min, double z_max) {
  const double lx = (dem.width - 1) * dem.georef.dx, ly = (dem.height - 1) * dem.georef.dy;
  const double x0 = dem.georef.x0, y0 = dem.georef.y0;
  const double l = std::max(lx, ly), zr = z_max - z_min;
  smr::Camera cam;
  cam.eye = {x0 + 0.25 * lx, y0 + 0.15 * ly, z_max + 0.1 * l};
  cam.target = {x0 + 0.6 * lx, y0 + 0.75 * ly, z_min + 0.3 * zr};
  cam.fov_y_deg = 60.0;
  cam.viewport_w = 1024;
  cam.viewport_h = 768;

  smr::RcfSpec object;
  object.camera = cam;
  object.floor = 0.70;
  object.discs.push_back({x0 + 0.5 * lx, y0 + 0.5 * ly, 0.15 * l, 0.95});
  object.critical_level = 0.98;
  object.critical_relief = 0.01 * zr;
  const smr::Vec2 fore = smr::Vec2(cam.eye) + 0.25 * (smr::Vec2(cam.target) - smr::Vec2(cam.eye));
  object.aois.push_back({fore.x, fore.y, 0.08 * l, 0.99});

  std::vector<RcfCase> cases;
  cases.push_back({"object, culling", object});
  object.cull = false;
  cases.push_back({"object, no culling", object});
  for (bool cull : {true, false}) {
    for (double px : {1.0, 4.0}) {
      smr::RcfSpec s;
      s.camera = cam;
      s.cull = cull;
      s.pixel_error = px;
      char label[64];
      std::snprintf(label, sizeof label, "screen %gpx, %s", px, cull ? "culling" : "no culling");
      cases.push_back({label, s});
    }
  }
  cases.push_back({"finest (g = 1)", smr::RcfSpec{}});
  return cases;
}

json camera_json(const smr::Camera& c) {
  return {{"eye", {c.eye.x, c.eye.y, c.eye.z}},
          {"target", {c.target.x, c.target.y, c.target.z}},
          {"fov_y_deg", c.fov_y_deg},
          {"viewport", {c.viewport_w, c.viewport_h}}};
}

struct Run {
  smr::Extraction e;
  double total = 0.0;
};

Run run_once(const smr::Crmr& crmr, const smr::Rcf& rcf, bool reduced) {
  const std::uint64_t t0 = smr::bench::now_ns();
  Run r;
  r.e = reduced ? smr::extract_reduced(crmr, rcf) : smr::extract_minimal_surface(crmr, rcf);
  r.total = smr::bench::seconds_since(t0);
  return r;
}

// Runs one (RCF, algorithm) `repeat` times; reports the counts and median times.
json measure(const smr::Crmr& crmr, const smr::Rcf& rcf, bool reduced, int repeat, bool verify,
             std::vector<double>* totals_out = nullptr) {
  std::vector<double> ext, exp, tot;
  std::optional<Run> first;
  for (int i = 0; i < repeat; ++i) {
    Run r = run_once(crmr, rcf, reduced);
    ext.push_back(r.e.stats.extract_seconds);
    exp.push_back(r.e.stats.expand_seconds);
    tot.push_back(r.total);
    if (!first) first = std::move(r);
  }
  const smr::ExtractStats& s = first->e.stats;
  const std::uint64_t out = s.triangles - s.void_triangles;
  const double t = median(tot);
  json row = {{"algorithm", reduced ? "reduced" : "minimal"},
              {"x", s.x},
              {"x_plus", s.x_plus},
              {"ops_visited", s.ops_visited},
              {"triangles", out},
              {"void_triangles", s.void_triangles},
              {"fans", s.fans},
              {"triangles_per_fan", s.triangles_per_fan()},
              {"starting_points", s.starting_points},
              {"domain_tests", s.domain_tests},
              {"extract_seconds", median(ext)},
              {"expand_seconds", median(exp)},
              {"total_seconds", t},
              {"triangles_per_second", t > 0 ? double(out) / t : 0.0},
              {"repeats", repeat}};
  if (verify) {
    const smr::InvariantReport tiling = smr::check_tiling(crmr, first->e.triangles);
    row["tiling_ok"] = tiling.ok();
    if (!tiling.ok()) row["tiling_errors"] = tiling.summary();
  }
  if (totals_out) *totals_out = tot;
  return row;
}

void print_row(const std::string& label, const json& r) {
  std::fprintf(stderr,
               "  %-24s %-7s |X| %8llu |X+| %8llu |F| %9llu  tri/fan %.2f  ext %.3fs exp %.3fs "
               "total %.3fs\n",
               label.c_str(), r["algorithm"].get<std::string>().c_str(),
               static_cast<unsigned long long>(r["x"].get<std::uint64_t>()),
               static_cast<unsigned long long>(r["x_plus"].get<std::uint64_t>()),
               static_cast<unsigned long long>(r["triangles"].get<std::uint64_t>()),
               r["triangles_per_fan"].get<double>(), r["extract_seconds"].get<double>(),
               r["expand_seconds"].get<double>(), r["total_seconds"].get<double>());
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"bench_extract: Brown Table 7.1/7.4/7.5-style selective refinement results"};
  std::string data_dir = SMRDB_BENCH_DATA_DIR;
  int fbm_size = 4097, repeat = 3, throughput_repeat = 7;
  std::uint64_t seed = 1;
  double real_fraction = 0.005, fbm_fraction = 0.001;
  bool skip_fbm = false, skip_real = false, verify = false;
  app.add_option("--data-dir", data_dir, "Directory with the fetched DEMs (scripts/fetch-data.sh)")
      ->capture_default_str();
  app.add_option("--fbm-size", fbm_size, "Size of the synthetic terrain")->capture_default_str();
  app.add_option("--seed", seed, "fBm seed")->capture_default_str();
  app.add_option("--real-max-error-fraction", real_fraction,
                 "Build tolerance of the real DEMs, as a fraction of their height range")
      ->capture_default_str();
  app.add_option("--fbm-max-error-fraction", fbm_fraction,
                 "Build tolerance of the fBm (fraction of range)")
      ->capture_default_str();
  app.add_option("--repeat", repeat, "Runs per table row (median reported)")->capture_default_str();
  app.add_option("--throughput-repeat", throughput_repeat, "Runs for the throughput figure (>= 5)")
      ->capture_default_str();
  app.add_flag("--skip-fbm", skip_fbm, "Only the real DEMs");
  app.add_flag("--skip-real", skip_real, "Only the synthetic terrain");
  app.add_flag("--verify", verify,
               "Check that every output tiles the domain (slow on large outputs)");
  CLI11_PARSE(app, argc, argv);
  repeat = std::max(repeat, 1);
  throughput_repeat = std::max(throughput_repeat, 5);

  std::vector<DatasetSpec> specs;
  if (!skip_real) {
    for (const char* f : {"jacksboro_fault_dem.npz", "topobathy.npz", "elev.tif"}) {
      DatasetSpec d;
      d.name = std::string(f).substr(0, std::string(f).find('.'));
      d.input.path = data_dir + "/" + f;
      d.max_error_fraction = real_fraction;
      specs.push_back(d);
    }
  }
  if (!skip_fbm) {
    DatasetSpec d;
    d.name = "fbm" + std::to_string(fbm_size);
    d.input.fbm_size = fbm_size;
    d.input.seed = seed;
    d.max_error_fraction = fbm_fraction;
    specs.push_back(d);
  }

  try {
    json report;
    report["benchmark"] = "extract";
    report["machine"] = smr::bench::machine_json();
    report["datasets"] = json::array();
    for (const DatasetSpec& d : specs) {
      smr::bench::Input input = smr::bench::load_input(d.input);
      const bool was_geographic = input.dem.georef.geographic;
      const smr::Heightfield dem = smr::bench::to_local_metres(input.dem);
      input.dem = {};
      const double max_error = d.max_error_fraction * (input.z_max - input.z_min);
      std::fprintf(stderr, "%s: %dx%d, max error %.4g (%.3g %% of range)\n", d.name.c_str(),
                   dem.width, dem.height, max_error, 100 * d.max_error_fraction);

      smr::GreedyTinOptions opt;
      opt.max_error = max_error;
      std::uint64_t t0 = smr::bench::now_ns();
      const smr::Crmr crmr = smr::build_greedy_tin(dem, opt);
      const double build_seconds = smr::bench::seconds_since(t0);
      std::uint64_t finest = 0;
      for (const smr::Op& op : crmr.ops) {
        for (const auto& t : op.fragment) finest += !t.killer.valid() && !t.is_void();
      }
      json ds = {{"name", d.name},
                 {"input", input.description},
                 {"converted_to_local_metres", was_geographic},
                 {"spacing_m", {dem.georef.dx, dem.georef.dy}},
                 {"max_error", max_error},
                 {"max_error_fraction_of_range", d.max_error_fraction},
                 {"samples", dem.sample_count()},
                 {"vertices", crmr.header.vertex_count},
                 {"finest_triangles", finest},
                 {"fragments", crmr.ops.size() - 1},
                 {"ops_including_base", crmr.ops.size()},
                 {"fragment_triangles", crmr.triangle_count()},
                 {"vertices_per_fragment",
                  double(crmr.header.vertex_count - crmr.ops[0].new_vertex_count) /
                      double(std::max<std::size_t>(crmr.ops.size() - 1, 1))},
                 {"err0", crmr.header.err0},
                 {"err_final", crmr.header.err_final},
                 {"build_seconds", build_seconds}};
      std::fprintf(stderr,
                   "  samples %zu, M^m %llu vertices %llu triangles, %zu fragments, build %.2fs\n",
                   dem.sample_count(), static_cast<unsigned long long>(crmr.header.vertex_count),
                   static_cast<unsigned long long>(finest), crmr.ops.size() - 1, build_seconds);

      const std::vector<RcfCase> cases = rcf_cases(dem, input.z_min, input.z_max);
      if (cases.front().spec.camera) ds["camera"] = camera_json(*cases.front().spec.camera);
      json rows = json::array();
      std::optional<smr::Rcf> view_rcf;
      for (const RcfCase& c : cases) {
        t0 = smr::bench::now_ns();
        smr::Rcf rcf = smr::make_rcf(c.spec, smr::ModelKind::kTerrain, &dem);
        const double rcf_seconds = smr::bench::seconds_since(t0);
        for (bool reduced : {false, true}) {
          json row = measure(crmr, rcf, reduced, repeat, verify);
          row["rcf"] = c.label;
          row["rcf_description"] = rcf.describe();
          row["culling"] = c.spec.camera.has_value() && c.spec.cull;
          row["rcf_build_seconds"] = rcf_seconds;
          print_row(c.label, row);
          rows.push_back(row);
        }
        if (c.label == "screen 1px, culling") view_rcf = rcf;
      }
      ds["rows"] = rows;

      if (d.input.fbm_size > 0 && view_rcf) {
        json tp = {
            {"dataset", d.name}, {"rcf", "screen 1px, culling"}, {"repeats", throughput_repeat}};
        for (bool reduced : {false, true}) {
          std::vector<double> totals;
          json row = measure(crmr, *view_rcf, reduced, throughput_repeat, false, &totals);
          row["total_seconds_all"] = totals;
          tp[reduced ? "reduced" : "minimal"] = row;
          std::fprintf(
              stderr, "  throughput (%s): %llu triangles in %.3f s median = %.3g triangles/s\n",
              reduced ? "reduced" : "minimal",
              static_cast<unsigned long long>(row["triangles"].get<std::uint64_t>()),
              row["total_seconds"].get<double>(), row["triangles_per_second"].get<double>());
        }
        report["throughput"] = tp;
      }
      ds["rss_peak_mb"] = smr::bench::peak_rss_mb();
      report["datasets"].push_back(ds);
    }
    report["rss_peak_mb"] = smr::bench::peak_rss_mb();
    std::cout << report.dump(2) << "\n";
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "bench_extract: error: " << e.what() << "\n";
    return 1;
  }
}
