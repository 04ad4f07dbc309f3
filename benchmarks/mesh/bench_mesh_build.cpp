// bench_mesh_build: build time of our QEM progressive-mesh CRMR builder (smr::build_qem_pm, the
// whole hierarchy down to a tiny base mesh) against simplifiers that build no hierarchy, on the
// same mesh in one process:
//   - meshoptimizer's meshopt_simplify (0.18, Debian libmeshoptimizer-dev) to 10 % and 1 % of the
//     index count with no error limit (target_error 1.0 = the whole extent), with and without
//     meshopt_SimplifyLockBorder;
//   - CGAL's Surface_mesh_simplification::edge_collapse on a Surface_mesh<Simple_cartesian<double>>
//     with Count_ratio_stop_predicate 0.1 and 0.01 (ratio of edges), default Lindstrom-Turk cost
//     and placement, and Garland-Heckbert plane policies (CGAL 5.5, needs Eigen).
// And our out-of-core builder (smr::build_block_pm: octree blocks with locked borders, leaf
// blocks simplified on every core, `smrdb ingest --memory`), from the mesh in memory, as
// "ours-blocks"; its CPU time is every thread's.
// Rounds are interleaved (each round runs every contender once, starting with a different one),
// and medians are reported. Only the simplification is timed: the float copy meshoptimizer needs
// and the Surface_mesh construction CGAL needs are reported separately.
//
// After the rounds the last CRMR is written to a database (write_database, zstd) for bytes per
// vertex (against Hoppe's 24.9 B/vertex), pages and DAG depth, and Brown Table 7.7-style rows
// are measured for a few RCFs: |X|, output |F|, triangles per fan, extraction and expansion time,
// both on the in-memory (quantized) CRMR and on the database.
//
//   bench_mesh_build MESH [--repeat 3]
//                         [--only ours,ours-blocks,meshopt,meshopt-lockborder,cgal-lt,cgal-gh]
//                         [--skip-db] [--db PATH] [--repair]
//   bench_mesh_build MESH --subdivide K -o OUT.ply      midpoint (1-to-4) subdivision, K levels
//                                                      (K = 0 or no --subdivide: the mesh as read)
//
// `--only` lets a script measure one contender's peak RSS per process (/usr/bin/time -v). Prints
// one JSON object on stdout. The run (run()) is linear: read, choose the contenders, the
// interleaved rounds, results and ratios, then the database and Table 7.7.
#include <malloc.h>

#include <unistd.h>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <ctime>
#include <filesystem>
#include <iostream>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <vector>

// Eigen (inside CGAL's Garland-Heckbert policies) trips GCC 12's -Wmaybe-uninitialized after
// inlining, which system-header suppression does not catch.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <CGAL/Simple_cartesian.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/Count_ratio_stop_predicate.h>
#include <CGAL/Surface_mesh_simplification/edge_collapse.h>
#if SMRDB_HAVE_EIGEN
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/GarlandHeckbert_plane_policies.h>
#endif
#pragma GCC diagnostic pop
#if SMRDB_HAVE_MESHOPTIMIZER
#include <meshoptimizer.h>
#endif

#include <CLI/CLI.hpp>
#include <glm/geometric.hpp>
#include <nlohmann/json.hpp>

#include "benchmarks/bench_common.h"
#include "smr/builders/mesh/qem_pm.h"
#include "smr/core/mesh.h"
#include "smr/core/parallel.h"
#include "smr/db/database.h"
#include "smr/db/writer.h"
#include "smr/extract/extract.h"
#include "smr/io/mesh_reader.h"
#include "smr/io/mesh_writer.h"
#include "smr/query/indexed_source.h"
#include "smr/rcf/spec.h"
#include "tools/report_json.h"

namespace {

using json = nlohmann::json;
using smr::bench::now_ns;
using smr::bench::seconds_since;

constexpr double kHoppeBytesPerVertex = 24.9;
const std::vector<double> kRatios{0.1, 0.01};
const char* const kContenders[] = {"ours",    "ours-blocks", "meshopt", "meshopt-lockborder",
                                   "cgal-lt", "cgal-gh"};

// Process CPU time: every contender but ours-blocks is single-threaded, so on a shared VM (other
// engineers' builds on the same two cores) CPU seconds are the steadier measure; wall seconds are
// the headline.
double cpu_seconds() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

// A wall + CPU stopwatch.
struct Stopwatch {
  std::uint64_t wall0 = now_ns();
  double cpu0 = cpu_seconds();
};

struct Times {
  std::vector<double> all, cpu_all;
  void add(const Stopwatch& w) {
    all.push_back(seconds_since(w.wall0));
    cpu_all.push_back(cpu_seconds() - w.cpu0);
  }
  double median() const { return smr::bench::median(all); }
  double cpu_median() const { return smr::bench::median(cpu_all); }
  double min() const { return all.empty() ? 0.0 : *std::min_element(all.begin(), all.end()); }
  json to_json() const {
    return {{"seconds", median()},
            {"seconds_min", min()},
            {"seconds_all", all},
            {"cpu_seconds", cpu_median()},
            {"cpu_seconds_all", cpu_all}};
  }
};

std::string ratio_key(double ratio) {
  return ratio == 0.1 ? "10pct" : ratio == 0.01 ? "1pct" : std::to_string(ratio);
}

// ---- ours -----------------------------------------------------------------------------------

// Longest chain of parents from any op down to R^0 (parents have smaller ids than their
// children), in ops; R^0 has depth 0.
std::pair<std::uint64_t, double> dag_depth(const smr::Crmr& crmr) {
  std::vector<std::uint32_t> depth(crmr.ops.size(), 0);
  std::uint64_t max_depth = 0;
  double sum = 0.0;
  for (std::size_t i = 1; i < crmr.ops.size(); ++i) {
    std::uint32_t d = 0;
    for (const smr::OpId p : crmr.ops[i].parents) d = std::max(d, depth[p.value]);
    depth[i] = d + 1;
    max_depth = std::max<std::uint64_t>(max_depth, depth[i]);
    sum += depth[i];
  }
  return {max_depth, crmr.ops.size() > 1 ? sum / double(crmr.ops.size() - 1) : 0.0};
}

json ours_json(const smr::Crmr& crmr, const smr::QemPmStats& stats) {
  std::uint64_t finest = 0, max_fragment = 0;
  for (const smr::Op& op : crmr.ops) {
    max_fragment = std::max<std::uint64_t>(max_fragment, op.fragment.size());
    for (const auto& t : op.fragment) finest += !t.killer.valid() && !t.is_void();
  }
  const auto [depth, mean_depth] = dag_depth(crmr);
  json j = stats;  // the builder's counters, as `smrdb ingest --json` reports them
  j.update({{"threads", smr::thread_count(0)},  // QemPmOptions::threads = 0: one per core
            {"vertices", crmr.header.vertex_count},
            {"ops", crmr.ops.size()},
            {"fragment_triangles", crmr.triangle_count()},
            {"max_fragment_triangles", max_fragment},
            {"finest_triangles", finest},
            {"err0", crmr.header.err0},
            {"err_final", crmr.header.err_final},
            {"dag_depth", depth},
            {"dag_mean_depth", mean_depth}});
  return j;
}

// ---- CGAL -----------------------------------------------------------------------------------

using Kernel = CGAL::Simple_cartesian<double>;
using SurfaceMesh = CGAL::Surface_mesh<Kernel::Point_3>;
namespace SMS = CGAL::Surface_mesh_simplification;

SurfaceMesh to_surface_mesh(const smr::TriangleMesh& mesh) {
  SurfaceMesh sm;
  sm.reserve(SurfaceMesh::size_type(mesh.positions.size()),
             SurfaceMesh::size_type(mesh.positions.size() + mesh.triangles.size()),
             SurfaceMesh::size_type(mesh.triangles.size()));
  std::vector<SurfaceMesh::Vertex_index> v;
  v.reserve(mesh.positions.size());
  for (const smr::Vec3& p : mesh.positions) v.push_back(sm.add_vertex({p.x, p.y, p.z}));
  for (std::size_t i = 0; i < mesh.triangles.size(); ++i) {
    const auto& t = mesh.triangles[i];
    if (sm.add_face(v[t[0]], v[t[1]], v[t[2]]) == SurfaceMesh::null_face()) {
      throw std::runtime_error("CGAL Surface_mesh rejected face " + std::to_string(i));
    }
  }
  return sm;
}

struct CgalRun {
  std::size_t removed_edges = 0, vertices = 0, faces = 0;
};

enum class CgalPolicy { kLindstromTurk, kGarlandHeckbert };

CgalRun run_cgal(SurfaceMesh& sm, double ratio, CgalPolicy policy) {
  CgalRun r;
  SMS::Count_ratio_stop_predicate<SurfaceMesh> stop(ratio);
  if (policy == CgalPolicy::kLindstromTurk) {
    r.removed_edges = std::size_t(SMS::edge_collapse(sm, stop));
  } else {
#if SMRDB_HAVE_EIGEN
    SMS::GarlandHeckbert_plane_policies<SurfaceMesh, Kernel> gh(sm);
    r.removed_edges = std::size_t(SMS::edge_collapse(
        sm, stop, CGAL::parameters::get_cost(gh.get_cost()).get_placement(gh.get_placement())));
#endif
  }
  r.vertices = sm.number_of_vertices();
  r.faces = sm.number_of_faces();
  return r;
}

// ---- extraction (Brown Table 7.7) -----------------------------------------------------------

struct NamedRcf {
  std::string name;
  smr::RcfSpec spec;
};

std::vector<NamedRcf> table_rcfs(const smr::CrmrInfo& info) {
  std::vector<NamedRcf> out;
  for (double g : {0.5, 0.9, 1.0}) {
    smr::RcfSpec s;
    s.floor = g;
    std::ostringstream name;
    name << "object floor " << g;
    out.push_back({name.str(), s});
  }
  // As tests/support/meshes.cpp's spread: direction (1, 0.3, 0.2), 3 model radii, 1 px, 60 deg,
  // 1024x768, frustum and back-face culling on.
  const smr::Vec3 c = 0.5 * (info.bounds.lo + info.bounds.hi);
  const double radius = 0.5 * glm::length(info.bounds.hi - info.bounds.lo);
  const smr::Vec3 dir{1, 0.3, 0.2};
  smr::RcfSpec s;
  smr::Camera cam;
  cam.eye = c + glm::normalize(dir) * (3.0 * radius);
  cam.target = c;
  cam.up = smr::Vec3{0, 0, 1};
  s.camera = cam;
  s.pixel_error = 1.0;
  out.push_back({"camera at 3 radii, 1 px", s});
  return out;
}

json table_rows(const smr::OpSource& source, const std::vector<NamedRcf>& rcfs, int repeat) {
  json rows = json::array();
  for (const NamedRcf& r : rcfs) {
    const smr::Rcf rcf = smr::make_rcf(r.spec, smr::ModelKind::kMesh3d, nullptr);
    std::vector<double> extract, expand;
    Times total;
    smr::ExtractStats s;
    for (int i = 0; i < std::max(1, repeat); ++i) {
      const Stopwatch w;
      const smr::Extraction e = smr::extract_minimal_surface(source, rcf);
      total.add(w);
      extract.push_back(e.stats.extract_seconds);
      expand.push_back(e.stats.expand_seconds);
      s = e.stats;
    }
    rows.push_back({{"rcf", r.name},
                    {"x", s.x},
                    {"triangles", s.triangles - s.void_triangles},
                    {"fans", s.fans},
                    {"triangles_per_fan", s.triangles_per_fan()},
                    {"ops_visited", s.ops_visited},
                    {"extract_seconds", smr::bench::median(extract)},
                    {"expand_seconds", smr::bench::median(expand)},
                    {"total_seconds", total.median()},
                    {"total_seconds_all", total.all}});
  }
  return rows;
}

void trim() {
  malloc_trim(0);
}

// ---- the command line -----------------------------------------------------------------------

struct Config {
  std::string path, output, db_path, only_list;
  int repeat = 3, subdivide_levels = 0, extract_repeat = 5;
  double bound_band = smr::QemPmOptions{}.bound_band;
  bool skip_db = false, repair = false, keep_db = false, list_contenders = false;
  std::string name() const { return std::filesystem::path(path).filename().string(); }
};

void add_options(CLI::App& app, Config& cfg) {
  app.add_option("mesh", cfg.path, "Mesh file (.ply .obj .off .stl)");
  app.add_option("--repeat", cfg.repeat, "Interleaved rounds (median reported)")
      ->capture_default_str();
  app.add_option("--only", cfg.only_list,
                 "Comma-separated contenders: ours, ours-blocks, meshopt, meshopt-lockborder, "
                 "cgal-lt, cgal-gh "
                 "(default: all available)");
  app.add_flag("--skip-db", cfg.skip_db, "Do not write the database or extract (Table 7.7)");
  app.add_option("--db", cfg.db_path, "Database path (default: a temporary file, removed)");
  app.add_flag("--keep-db", cfg.keep_db, "Keep the database file");
  app.add_option("--extract-repeat", cfg.extract_repeat, "Runs per RCF (median)")
      ->capture_default_str();
  app.add_option("--bound-band", cfg.bound_band,
                 "Our builder's bands of the bound (QemPmOptions::bound_band; 0 = none)")
      ->capture_default_str();
  app.add_flag("--repair", cfg.repair, "Read with every repair (smrdb ingest --repair)");
  app.add_flag("--list-contenders", cfg.list_contenders,
               "Print the contenders this build has (space-separated) and exit");
  app.add_option("--subdivide", cfg.subdivide_levels,
                 "Write MESH after K levels of midpoint 1-to-4 subdivision to -o and exit");
  app.add_option("-o,--output", cfg.output,
                 "Output mesh of --subdivide, or the mesh as read without it (.ply: binary)");
}

// The contenders this build has.
std::set<std::string> available_contenders() {
  std::set<std::string> available{"ours", "ours-blocks", "cgal-lt"};
#if SMRDB_HAVE_MESHOPTIMIZER
  available.insert("meshopt");
  available.insert("meshopt-lockborder");
#endif
#if SMRDB_HAVE_EIGEN
  available.insert("cgal-gh");
#endif
  return available;
}

// The chosen contenders in kContenders' order; nullopt (after a message) when --only names one
// this build does not have.
std::optional<std::vector<std::string>> chosen_contenders(const Config& cfg,
                                                          const std::set<std::string>& available) {
  std::set<std::string> chosen = available;
  if (!cfg.only_list.empty()) {
    chosen.clear();
    for (const std::string& item : smr::bench::split_list(cfg.only_list)) {
      if (!available.count(item)) {
        std::cerr << "bench_mesh_build: contender '" << item
                  << "' unknown or not built (meshoptimizer/Eigen missing?)\n";
        return std::nullopt;
      }
      chosen.insert(item);
    }
  }
  std::vector<std::string> order;
  for (const char* c : kContenders)
    if (chosen.count(c)) order.emplace_back(c);
  return order;
}

// ---- input ----------------------------------------------------------------------------------

json read_input(const Config& cfg, smr::TriangleMesh& mesh) {
  smr::MeshReport mr;
  const std::uint64_t t0 = now_ns();
  mesh = smr::read_mesh(cfg.path, cfg.repair ? smr::MeshRepair::all() : smr::MeshRepair{}, &mr);
  json input = mr;  // tools/report_json.h
  input["read_seconds"] = seconds_since(t0);
  input["path"] = cfg.path;
  input["name"] = cfg.name();
  input["closed"] = mr.closed;
  return input;
}

// --subdivide K -o OUT (or -o alone: the mesh as read, 0 levels).
json subdivide(const Config& cfg, smr::TriangleMesh& mesh) {
  if (cfg.output.empty()) throw std::runtime_error("--subdivide needs -o OUT");
  const std::uint64_t t0 = now_ns();
  for (int i = 0; i < cfg.subdivide_levels; ++i) mesh = smr::midpoint_subdivided(mesh);
  const double sub_seconds = seconds_since(t0);
  smr::write_mesh(cfg.output, mesh);
  return {{"levels", cfg.subdivide_levels},
          {"scheme", "midpoint 1-to-4 (flat: the surface is unchanged)"},
          {"output", cfg.output},
          {"vertices", mesh.positions.size()},
          {"triangles", mesh.triangles.size()},
          {"seconds", sub_seconds}};
}

// ---- the contenders -------------------------------------------------------------------------

struct PeerResult {
  Times times;
  json last;
};

// Everything the rounds measure, per contender (peers: per target ratio too).
struct Measurements {
  Times ours_times;
  std::optional<smr::Crmr> crmr;  // our last build
  smr::QemPmStats ours_stats;
  Times blocks_times;
  json blocks_last;
  std::map<std::string, std::map<double, PeerResult>> peers;
  Times cgal_construct;  // Surface_mesh construction (cgal-lt, first ratio)
  json meshopt_prep;     // the float copy meshoptimizer needs, and its error scale
};

// The mesh and the inputs of the peers, prepared once, outside the timings.
struct Subject {
  smr::TriangleMesh mesh;
  std::string name;
  std::vector<float> positions_f;
  std::vector<unsigned> indices, destination;
  float meshopt_scale = 0.0f;
};

void prepare_meshopt(Subject& s, Measurements& m) {
#if SMRDB_HAVE_MESHOPTIMIZER
  const std::uint64_t t0 = now_ns();
  s.positions_f.reserve(s.mesh.positions.size() * 3);
  for (const smr::Vec3& p : s.mesh.positions) {
    s.positions_f.push_back(float(p.x));
    s.positions_f.push_back(float(p.y));
    s.positions_f.push_back(float(p.z));
  }
  s.indices.reserve(s.mesh.triangles.size() * 3);
  for (const auto& t : s.mesh.triangles) s.indices.insert(s.indices.end(), t.begin(), t.end());
  s.destination.resize(s.indices.size());
  m.meshopt_prep["prepare_seconds"] = seconds_since(t0);
  s.meshopt_scale =
      meshopt_simplifyScale(s.positions_f.data(), s.mesh.positions.size(), 3 * sizeof(float));
  m.meshopt_prep["error_scale"] = s.meshopt_scale;
#else
  (void)s;
  (void)m;
#endif
}

void run_ours(const Subject& s, double bound_band, Measurements& m) {
  m.crmr.reset();
  trim();
  smr::QemPmStats stats;
  smr::QemPmOptions options;
  options.bound_band = bound_band;
  const Stopwatch w;
  smr::Crmr built = smr::build_qem_pm(s.mesh, s.name, options, &stats);
  m.ours_times.add(w);
  m.crmr.emplace(std::move(built));
  m.ours_stats = stats;
}

void run_ours_blocks(const Subject& s, Measurements& m) {
  trim();
  const smr::MemoryMeshStream stream(s.mesh, s.name);
  smr::BlockPmStats st;
  const Stopwatch w;
  const smr::Crmr built = smr::build_block_pm(stream, smr::BlockPmOptions{}, &st);
  m.blocks_times.add(w);
  m.blocks_last = {{"threads", smr::thread_count(0)},
                   {"levels", st.levels},
                   {"leaf_blocks", st.leaf_blocks},
                   {"collapses", st.collapses},
                   {"ops", built.ops.size()},
                   {"base_triangles", st.base_triangles},
                   {"dag_height", st.dag_height},
                   {"max_block_triangles", st.max_block_triangles},
                   {"seconds_sort", st.seconds_sort},
                   {"seconds_blocks", st.seconds_blocks},
                   {"seconds_blocks_tail", st.seconds_tail},
                   {"seconds_assemble", st.seconds_assemble},
                   {"seconds_join", st.seconds_join},
                   {"seconds_emit", st.seconds_emit},
                   {"builder", built.header.builder}};
}

#if SMRDB_HAVE_MESHOPTIMIZER
void run_meshopt(const std::string& c, Subject& s, Measurements& m) {
  const unsigned options = c == "meshopt" ? 0u : unsigned(meshopt_SimplifyLockBorder);
  const std::size_t tri_count = s.mesh.triangles.size();
  for (double ratio : kRatios) {
    const std::size_t target = std::size_t(std::llround(ratio * double(tri_count))) * 3;
    float result_error = 0.0f;
    const Stopwatch w;
    const std::size_t n = meshopt_simplify(s.destination.data(), s.indices.data(), s.indices.size(),
                                           s.positions_f.data(), s.mesh.positions.size(),
                                           3 * sizeof(float), target, 1.0f, options, &result_error);
    PeerResult& r = m.peers[c][ratio];
    r.times.add(w);
    r.last = {{"target_triangles", target / 3},
              {"triangles", n / 3},
              {"result_error_relative", result_error},
              {"result_error", double(result_error) * double(s.meshopt_scale)}};
  }
}
#endif

void run_cgal_contender(const std::string& c, const Subject& s, Measurements& m) {
  const CgalPolicy policy =
      c == "cgal-lt" ? CgalPolicy::kLindstromTurk : CgalPolicy::kGarlandHeckbert;
  for (double ratio : kRatios) {
    trim();
    const Stopwatch construct;
    SurfaceMesh sm = to_surface_mesh(s.mesh);
    if (c == "cgal-lt" && ratio == kRatios.front()) m.cgal_construct.add(construct);
    const Stopwatch w;
    const CgalRun run = run_cgal(sm, ratio, policy);
    PeerResult& r = m.peers[c][ratio];
    r.times.add(w);
    r.last = {{"target_edge_ratio", ratio},
              {"target_triangles", std::llround(ratio * double(s.mesh.triangles.size()))},
              {"triangles", run.faces},
              {"vertices", run.vertices},
              {"removed_edges", run.removed_edges}};
  }
}

void run_contender(const std::string& c, const Config& cfg, Subject& s, Measurements& m) {
  if (c == "ours") return run_ours(s, cfg.bound_band, m);
  if (c == "ours-blocks") return run_ours_blocks(s, m);
#if SMRDB_HAVE_MESHOPTIMIZER
  if (c == "meshopt" || c == "meshopt-lockborder") return run_meshopt(c, s, m);
#endif
  if (c == "cgal-lt" || c == "cgal-gh") return run_cgal_contender(c, s, m);
}

// Interleaved rounds; round i starts with contender i mod n.
void run_rounds(const Config& cfg, const std::vector<std::string>& order, Subject& s,
                Measurements& m) {
  for (int round = 0; round < cfg.repeat; ++round) {
    for (std::size_t k = 0; k < order.size(); ++k) {
      const std::string& c = order[(std::size_t(round) + k) % order.size()];
      std::cerr << "[bench_mesh_build] " << s.name << " round " << round + 1 << "/" << cfg.repeat
                << ": " << c << "\n";
      run_contender(c, cfg, s, m);
    }
  }
}

// ---- the report -----------------------------------------------------------------------------

json peer_json(const std::string& c, const std::map<double, PeerResult>& by_ratio,
               const Measurements& m) {
  json pj;
  for (const auto& [ratio, r] : by_ratio) {
    json row = r.times.to_json();
    row.update(r.last);
    pj[ratio_key(ratio)] = row;
  }
  if (c.rfind("meshopt", 0) == 0) {
    pj["version"] = "0.18 (Debian libmeshoptimizer-dev)";
    pj["target_error"] = 1.0;
    pj["options"] = c == "meshopt" ? "0" : "meshopt_SimplifyLockBorder";
    pj.update(m.meshopt_prep);
  } else {
    pj["version"] = std::string("CGAL ") + CGAL_VERSION_STR;
    pj["policy"] = c == "cgal-lt" ? "Lindstrom-Turk cost and placement (default)"
                                  : "GarlandHeckbert_plane_policies";
    pj["stop"] = "Count_ratio_stop_predicate (ratio of edges)";
    if (c == "cgal-lt") pj["surface_mesh_construction"] = m.cgal_construct.to_json();
  }
  return pj;
}

bool has(const std::vector<std::string>& order, const std::string& c) {
  return std::find(order.begin(), order.end(), c) != order.end();
}

json results_json(const std::vector<std::string>& order, std::size_t tri_count,
                  const Measurements& m) {
  json results;
  if (has(order, "ours")) {
    results["ours"] = m.ours_times.to_json();
    results["ours"].update(ours_json(*m.crmr, m.ours_stats));
    results["ours"]["triangles_per_second"] = double(tri_count) / m.ours_times.median();
    results["ours"]["builder"] = m.crmr->header.builder;
  }
  if (has(order, "ours-blocks")) {
    results["ours-blocks"] = m.blocks_times.to_json();
    results["ours-blocks"].update(m.blocks_last);
    results["ours-blocks"]["triangles_per_second"] = double(tri_count) / m.blocks_times.median();
  }
  for (const auto& [c, by_ratio] : m.peers) results[c] = peer_json(c, by_ratio, m);
  return results;
}

// Each of our full builds against each peer's time to each target.
json ratios_json(const std::vector<std::string>& order, const Measurements& m) {
  json ratios;
  for (const auto& [name, times] :
       {std::pair{"ours", &m.ours_times}, {"ours-blocks", &m.blocks_times}}) {
    if (!has(order, name)) continue;
    for (const auto& [c, by_ratio] : m.peers) {
      for (const auto& [ratio, r] : by_ratio) {
        const std::string key = std::string(name) + "_over_" + c + "_" + ratio_key(ratio);
        ratios[key] = times->median() / r.times.median();
        ratios["cpu_" + key] = times->cpu_median() / r.times.cpu_median();
      }
    }
  }
  return ratios;
}

// ---- database and Table 7.7 -----------------------------------------------------------------

json database_json(const smr::WriteReport& w, const smr::Crmr& crmr) {
  const double bpv =
      double(w.file_bytes) / double(std::max<std::uint64_t>(1, crmr.header.vertex_count));
  return {{"codec", "zstd"},
          {"ops", w.ops},
          {"pages", w.pages},
          {"rtree_nodes", w.rtree_nodes},
          {"page_bytes", w.page_bytes},
          {"locator_bytes", w.locator_bytes},
          {"rtree_bytes", w.rtree_bytes},
          {"file_bytes", w.file_bytes},
          {"bytes_per_vertex", bpv},
          {"page_bytes_per_vertex", double(w.page_bytes) / double(crmr.header.vertex_count)},
          {"hoppe_bytes_per_vertex", kHoppeBytesPerVertex},
          {"bytes_per_vertex_over_hoppe", bpv / kHoppeBytesPerVertex},
          {"z_shift", w.z_shift},
          {"write_seconds", w.seconds}};
}

// Writes our last CRMR (report["database"]; write_database snaps it to the quantization grid in
// place) and measures Table 7.7 on it in memory and on the database, warm (report["table_7_7"]).
void database_and_table(const Config& cfg, smr::Crmr& crmr, json& report) {
  const bool temp_db = cfg.db_path.empty();
  const std::string db_path = temp_db
                                  ? (std::filesystem::temp_directory_path() /
                                     ("bench_mesh_build_" + std::to_string(::getpid()) + ".smrdb"))
                                        .string()
                                  : cfg.db_path;
  smr::WriteOptions wo;
  wo.force = true;
  wo.parameters = "bench_mesh_build";
  report["database"] = database_json(smr::write_database(crmr, db_path, wo), crmr);
  const std::vector<NamedRcf> rcfs = table_rcfs(crmr.header);
  json table;
  table["memory"] = table_rows(crmr, rcfs, cfg.extract_repeat);
  {
    const auto db = smr::Database::open(db_path, {});
    const smr::IndexedSource source(*db);
    // One warm-up pass fills the page cache; the rows are then warm-cache figures.
    (void)table_rows(source, rcfs, 1);
    table["database_warm"] = table_rows(source, rcfs, cfg.extract_repeat);
  }
  report["table_7_7"] = table;
  if (temp_db && !cfg.keep_db)
    std::filesystem::remove(db_path);
  else
    report["database"]["path"] = db_path;
}

// ---- the run --------------------------------------------------------------------------------

// Read, build with every chosen contender in interleaved rounds, report; then the database.
int run(const Config& cfg, const std::set<std::string>& available) {
  json report;
  report["benchmark"] = "mesh_build";
  report["machine"] = smr::bench::machine_json();
  Subject s;
  s.name = cfg.name();
  report["input"] = read_input(cfg, s.mesh);
  if (cfg.subdivide_levels > 0 || !cfg.output.empty()) {
    report["benchmark"] = "mesh_subdivide";
    report["subdivision"] = subdivide(cfg, s.mesh);
    std::cout << report.dump(2) << "\n";
    return 0;
  }
  report["rss_after_input_mb"] = smr::bench::peak_rss_mb();

  const std::optional<std::vector<std::string>> order = chosen_contenders(cfg, available);
  if (!order) return 1;
  report["contenders"] = *order;
  report["repeats"] = cfg.repeat;

  Measurements m;
  if (has(*order, "meshopt") || has(*order, "meshopt-lockborder")) prepare_meshopt(s, m);
  run_rounds(cfg, *order, s, m);
  report["results"] = results_json(*order, s.mesh.triangles.size(), m);
  const json ratios = ratios_json(*order, m);
  if (!ratios.empty()) report["ratios"] = ratios;
  report["rss_peak_after_builds_mb"] = smr::bench::peak_rss_mb();

  if (has(*order, "ours") && !cfg.skip_db) database_and_table(cfg, *m.crmr, report);
  report["rss_peak_mb"] = smr::bench::peak_rss_mb();
  std::cout << report.dump(2) << "\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"bench_mesh_build: QEM PM CRMR build vs meshopt_simplify and CGAL edge collapse"};
  Config cfg;
  add_options(app, cfg);
  CLI11_PARSE(app, argc, argv);
  if (cfg.repeat < 1) {
    std::cerr << "bench_mesh_build: --repeat must be at least 1\n";
    return 1;
  }
  const std::set<std::string> available = available_contenders();
  if (cfg.list_contenders) {
    std::string line;
    for (const char* c : kContenders) {
      if (available.count(c)) line += (line.empty() ? "" : " ") + std::string(c);
    }
    std::cout << line << "\n";
    return 0;
  }
  if (cfg.path.empty()) {
    std::cerr << "bench_mesh_build: a mesh file is required\n";
    return 1;
  }
  try {
    return run(cfg, available);
  } catch (const std::exception& e) {
    std::cerr << "bench_mesh_build: error: " << e.what() << "\n";
    return 1;
  }
}
