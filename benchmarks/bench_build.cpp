// bench_build: time the in-core greedy Delaunay CRMR builder (Brown 7.1.1; Garland & Heckbert
// 1995) on one DEM and check the finest mesh's error bound on every sample.
//
//   bench_build DEM [--max-error M]                 a DEM file (GeoTIFF, .npy, .npz ...)
//   bench_build --fbm 4097 --seed 1 [--max-error M]  a generated fBm (range 1600, spacing 1)
//
// Prints one JSON object on stdout: input, build time, counts (vertices, finest-mesh triangles,
// ops, fragment triangles), the error-bound check of M^m and peak RSS.
#include <cstdio>
#include <iostream>
#include <string>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "benchmarks/bench_common.h"
#include "smr/build/greedy_tin.h"
#include "smr/extract/extract.h"
#include "smr/io/mesh_writer.h"
#include "smr/io/npy.h"

int main(int argc, char** argv) {
  CLI::App app{"bench_build: time the greedy Delaunay CRMR build and check its error bound"};
  smr::bench::InputOptions in_opt;
  double max_error = -1.0, max_error_fraction = 0.001;
  std::string write_mesh, write_npy;
  bool skip_check = false, skip_build = false;
  app.add_option("dem", in_opt.path, "DEM file (any format smr::read_dem reads)");
  app.add_option("--fbm", in_opt.fbm_size, "Generate an N x N fBm instead of reading a DEM");
  app.add_option("--seed", in_opt.seed, "fBm seed")->capture_default_str();
  app.add_option("--range", in_opt.range, "fBm height range")->capture_default_str();
  app.add_option("--spacing", in_opt.spacing, "fBm sample spacing")->capture_default_str();
  app.add_option("--max-error", max_error,
                 "Max vertical error (data units); default: a fraction of the height range");
  app.add_option("--max-error-fraction", max_error_fraction,
                 "Default max error as a fraction of the height range")
      ->capture_default_str();
  app.add_option(
      "--write-mesh", write_mesh,
      "Write the finest mesh: .obj/.ply (smr::write_mesh), else a SMRGRID1 dump (bench_common.h)");
  app.add_option("--write-npy", write_npy, "Write the input DEM as float32 .npy (for the peers)");
  app.add_flag("--skip-check", skip_check, "Do not check the error bound");
  app.add_flag("--skip-build", skip_build, "Only load/generate (and --write-npy) the DEM");
  CLI11_PARSE(app, argc, argv);
  if (in_opt.path.empty() == (in_opt.fbm_size <= 0)) {
    std::cerr << "bench_build: give either a DEM path or --fbm N\n";
    return 1;
  }

  try {
    nlohmann::json report;
    report["benchmark"] = "build";
    report["machine"] = smr::bench::machine_json();
    const smr::bench::Input input = smr::bench::load_input(in_opt);
    const smr::Heightfield& dem = input.dem;
    report["input"] = input.description;
    report["rss_after_input_mb"] = smr::bench::peak_rss_mb();
    if (!write_npy.empty()) {
      smr::write_npy(write_npy, dem);
      report["input"]["npy"] = write_npy;
    }
    if (skip_build) {
      std::cout << report.dump(2) << "\n";
      return 0;
    }
    if (max_error < 0.0) max_error = max_error_fraction * (input.z_max - input.z_min);
    report["max_error"] = max_error;

    smr::GreedyTinOptions opt;
    opt.max_error = max_error;
    const std::uint64_t t0 = smr::bench::now_ns();
    const smr::Crmr crmr = smr::build_greedy_tin(dem, opt);
    const double build_seconds = smr::bench::seconds_since(t0);
    const double peak_after_build = smr::bench::peak_rss_mb();

    std::uint64_t finest = 0, finest_void = 0;
    for (const smr::Op& op : crmr.ops) {
      for (const auto& t : op.fragment) {
        if (t.killer.valid()) continue;
        (t.is_void() ? finest_void : finest) += 1;
      }
    }
    const smr::bench::GridMesh mesh = smr::bench::finest_mesh(crmr, dem);
    report["build"] = {
        {"seconds", build_seconds},
        {"vertices", crmr.header.vertex_count},
        {"finest_vertices", mesh.vertices.size()},
        {"finest_triangles", finest},
        {"finest_void_triangles", finest_void},
        {"ops", crmr.ops.size()},
        {"fragment_triangles", crmr.triangle_count()},
        {"base_triangles", crmr.ops[0].fragment.size()},
        {"err0", crmr.header.err0},
        {"err_final", crmr.header.err_final},
        {"vertices_per_second", double(crmr.header.vertex_count) / build_seconds},
        {"sample_fraction", double(crmr.header.vertex_count) / double(dem.sample_count())}};
    report["rss_peak_after_build_mb"] = peak_after_build;

    if (!write_mesh.empty()) {
      const std::string ext = write_mesh.size() > 4 ? write_mesh.substr(write_mesh.size() - 4) : "";
      if (ext == ".obj" || ext == ".ply") {
        std::vector<smr::TriRef> refs;
        for (const smr::Op& op : crmr.ops) {
          for (std::uint32_t i = 0; i < op.fragment.size(); ++i) {
            if (!op.fragment[i].killer.valid()) refs.push_back({op.id, i});
          }
        }
        smr::write_mesh(write_mesh, smr::to_mesh(crmr, refs));
      } else {
        smr::bench::write_grid_mesh(write_mesh, mesh);
      }
      report["mesh_dump"] = write_mesh;
    }
    bool ok = true;
    if (!skip_check) {
      const smr::bench::ErrorBoundReport check =
          smr::bench::check_error_bound(mesh, dem, max_error);
      report["error_check"] = check.to_json();
      ok = check.ok();
    }
    report["rss_peak_mb"] = smr::bench::peak_rss_mb();
    std::cout << report.dump(2) << "\n";
    return ok ? 0 : 3;
  } catch (const std::exception& e) {
    std::cerr << "bench_build: error: " << e.what() << "\n";
    return 1;
  }
}
