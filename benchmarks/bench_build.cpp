// bench_build: time the in-core greedy Delaunay CRMR builder (Brown 7.1.1; Garland & Heckbert
// 1995) on one DEM and check the finest mesh's error bound on every sample.
//
//   bench_build DEM [--max-error M]                 a DEM file (GeoTIFF, .npy, .npz ...)
//   bench_build --fbm 4097 --seed 1 [--max-error M]  a generated fBm (range 1600, spacing 1)
//
// Prints one JSON object on stdout: input, build time, counts (vertices, finest-mesh triangles,
// ops, fragment triangles), the error-bound check of M^m and peak RSS.
#include <cstdio>
#include <cstring>
#include <iostream>
#include <string>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "benchmarks/bench_common.h"
#include "smr/builders/terrain/greedy_tin.h"
#include "smr/extract/extract.h"
#include "smr/io/mesh_writer.h"
#include "smr/io/npy.h"

namespace {

// A hash of everything the builder and link_dag put in the CRMR (header and every field of every
// op, doubles by their bits), so that builder changes can be checked to give bit-identical output.
class Fingerprint {
 public:
  void add(std::uint64_t v) { h_ = smr::mix64(h_ ^ v) + 0x9e3779b97f4a7c15ULL; }
  void add(double d) {
    std::uint64_t b;
    std::memcpy(&b, &d, sizeof b);
    add(b);
  }
  void add(const smr::Vec3& p) {
    add(p.x);
    add(p.y);
    add(p.z);
  }
  void add(const smr::Box3& b) {
    add(b.lo);
    add(b.hi);
  }
  void add(const smr::Crmr& crmr) {
    const smr::CrmrInfo& h = crmr.header;
    add(std::uint64_t(h.grid_width));
    add(std::uint64_t(h.grid_height));
    add(h.err0);
    add(h.err_final);
    add(h.bounds);
    add(h.vertex_count);
    add(std::uint64_t(crmr.ops.size()));
    for (const smr::Op& op : crmr.ops) {
      add(op.id.value);
      add(op.birth_res);
      add(op.error);
      add(std::uint64_t(op.new_vertex_count));
      add(std::uint64_t(op.vertices.size()));
      for (const smr::Vertex& v : op.vertices) {
        add(v.id.value);
        add(v.p);
      }
      add(std::uint64_t(op.fragment.size()));
      for (const smr::FragmentTriangle& t : op.fragment) {
        for (int k = 0; k < 3; ++k) add(std::uint64_t(t.v[k]));
        add(t.death_res);
        add(t.killer.value);
        add(std::uint64_t(t.flags));
      }
      add(std::uint64_t(op.pre.size()));
      for (const smr::TriRef& r : op.pre) add(r.op.value ^ (std::uint64_t(r.index) << 40));
      for (const smr::PreTriangle& t : op.pre_tris) {
        for (int k = 0; k < 3; ++k) add(std::uint64_t(t.v[k]));
        add(std::uint64_t(t.flags));
      }
      add(std::uint64_t(op.coarser.size()));
      for (const smr::CoarserLink& l : op.coarser) {
        add((std::uint64_t(l.tri) << 8) | l.edge);
        add(l.coarser.tri.op.value ^ (std::uint64_t(l.coarser.tri.index) << 40));
        add(std::uint64_t(l.coarser.edge));
      }
      add(std::uint64_t(op.parents.size()));
      for (smr::OpId p : op.parents) add(p.value);
      add(std::uint64_t(op.children.size()));
      for (smr::OpId c : op.children) add(c.value);
      add(op.box);
      add(op.sphere.center);
      add(op.sphere.radius);
      add(op.cone.axis);
      add(op.cone.half_angle);
      add(op.roi);
    }
  }
  std::string hex() const {
    char buf[17];
    std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(h_));
    return buf;
  }

 private:
  std::uint64_t h_ = 0;
};

// What the CRMR's vectors hold (by capacity), in MiB, and how many heap blocks they use: where the
// build's memory goes.
nlohmann::json crmr_memory(const smr::Crmr& crmr) {
  std::uint64_t blocks = 0;
  auto bytes = [&blocks](const auto& v) {
    if (v.capacity() != 0) ++blocks;
    return double(v.capacity() * sizeof(v[0]));
  };
  double vertices = 0, fragment = 0, pre = 0, pre_tris = 0, coarser = 0, dag = 0;
  for (const smr::Op& op : crmr.ops) {
    vertices += bytes(op.vertices);
    fragment += bytes(op.fragment);
    pre += bytes(op.pre);
    pre_tris += bytes(op.pre_tris);
    coarser += bytes(op.coarser);
    dag += bytes(op.parents) + bytes(op.children);
  }
  const double mib = 1024.0 * 1024.0;
  const double ops = double(crmr.ops.capacity() * sizeof(smr::Op));
  return {{"ops_mb", ops / mib},
          {"vertices_mb", vertices / mib},
          {"fragment_mb", fragment / mib},
          {"pre_mb", pre / mib},
          {"pre_tris_mb", pre_tris / mib},
          {"coarser_mb", coarser / mib},
          {"parents_children_mb", dag / mib},
          {"total_mb", (ops + vertices + fragment + pre + pre_tris + coarser + dag) / mib},
          {"heap_blocks", blocks}};
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"bench_build: time the greedy Delaunay CRMR build and check its error bound"};
  smr::bench::InputOptions in_opt;
  double max_error = -1.0, max_error_fraction = 0.001;
  std::string write_mesh, write_npy;
  bool skip_check = false, skip_build = false, fingerprint = false;
  std::uint64_t base_vertices = 4;
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
  app.add_option("--base-vertices", base_vertices, "Vertices of the base mesh R^0")
      ->capture_default_str();
  app.add_flag("--skip-check", skip_check, "Do not check the error bound");
  app.add_flag("--skip-build", skip_build, "Only load/generate (and --write-npy) the DEM");
  app.add_flag("--fingerprint", fingerprint,
               "Report a hash of the whole CRMR (every op field), to compare builder versions");
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
    opt.base_vertices = base_vertices;
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
    report["rss_after_build_mb"] = smr::bench::current_rss_mb();
    report["build"]["crmr_memory"] = crmr_memory(crmr);
    if (fingerprint) {
      Fingerprint fp;
      fp.add(crmr);
      report["build"]["fingerprint"] = fp.hex();
    }

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
