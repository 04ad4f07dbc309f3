// bench_check: the exact error-bound check of bench_build, applied to a triangulation dumped by
// another program (benchmarks/peers/run_peer.mjs writes delatin's and martini's meshes in the
// SMRGRID1 format of bench_common.h). Every sample of the DEM is checked.
//
//   bench_check DEM --mesh peer.bin --max-error M
//   bench_check DEM --db ours.smrdb --max-error M     (the database's finest mesh M^m, with
//                                                      the DEM's heights at its vertices)
//
// Prints a JSON object {mesh, dem, error_check: {...}}; exit status 0 when the bound holds on every
// sample and every sample is covered, 3 when it does not, 1 on bad input.
#include <iostream>
#include <string>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "benchmarks/bench_common.h"
#include "smr/db/database.h"
#include "smr/io/dem_reader.h"

int main(int argc, char** argv) {
  CLI::App app{"bench_check: check a grid triangulation's max vertical error on every DEM sample"};
  std::string dem_path, mesh_path;
  double max_error = 0.0;
  app.add_option("dem", dem_path, "The DEM the mesh approximates")->required();
  std::string db_path;
  auto* mesh_opt = app.add_option("--mesh", mesh_path, "SMRGRID1 mesh dump");
  auto* db_opt = app.add_option("--db", db_path, "smrdb database: check its finest mesh M^m");
  mesh_opt->excludes(db_opt);

  app.add_option("--max-error", max_error, "The bound to check (data units)")->required();
  CLI11_PARSE(app, argc, argv);
  if (mesh_path.empty() == db_path.empty()) {
    std::cerr << "bench_check: give exactly one of --mesh and --db\n";
    return 1;
  }
  try {
    const smr::Heightfield dem = smr::read_dem(dem_path);
    smr::bench::GridMesh mesh;
    if (!db_path.empty()) {
      const auto db = smr::Database::open(db_path, {});
      smr::Crmr crmr;
      crmr.header = db->info();
      db->need_links();  // to_op reads them
      for (std::uint64_t i = 0; i < db->op_count(); ++i)
        crmr.ops.push_back(smr::to_op(*db->op(smr::OpId(i))));
      mesh = smr::bench::finest_mesh(crmr, dem);
      // The database's heights are quantized (by at most the z_shift in its meta): check the
      // finest mesh's triangles with the DEM's heights at their corners, the TIN that was built.
      mesh.z.clear();
      mesh_path = db_path;
    } else {
      mesh = smr::bench::read_grid_mesh(mesh_path);
    }
    const smr::bench::ErrorBoundReport r = smr::bench::check_error_bound(mesh, dem, max_error);
    nlohmann::json out = {{"dem", dem_path},
                          {"mesh", mesh_path},
                          {"vertices", mesh.vertices.size()},
                          {"triangles", mesh.triangles.size()},
                          {"error_check", r.to_json()}};
    std::cout << out.dump(2) << "\n";
    return r.ok() ? 0 : 3;
  } catch (const std::exception& e) {
    std::cerr << "bench_check: error: " << e.what() << "\n";
    return 1;
  }
}
