// bench_vdpm: view-dependent output size against OpenMesh's VDPM (Kim & Lee, "Truly selective
// refinement of progressive meshes", GI 2001, with Hoppe 1997's refinement criteria), issue 4.
//
// For one mesh and the .spm vertex hierarchy that OpenMesh-mkbalancedpm + OpenMesh-Analyzer built
// from the same file, and for every camera x tolerance tau (pixels):
//   ours  smr::read_mesh -> smr::build_qem_pm -> smr::extract_minimal_surface with
//         RcfSpec{camera, pixel_error = tau} (frustum and back-face culling on; also counted off)
//   VDPM  the .spm loaded into OpenMesh's VDPM classes and refined exactly the way OpenMesh's
//         Synthesizer does (openmesh_vdpm.h, which also gives the conventions worked out from
//         OpenMesh's sources), from its base mesh and from the previous cut.
// Both outputs are measured the same way (screen_error.h: output to source and source to output),
// and our triangle count is also searched at VDPM's measured error (--no-match skips it).
//
// The run is linear: read and build ours, load VDPM's hierarchy, then per cut: ours, VDPM, the
// target, the equal-error search. Prints one JSON object on stdout.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include <CLI/CLI.hpp>
#include <glm/geometric.hpp>
#include <nlohmann/json.hpp>

#include "base/error.h"
#include "benchmarks/bench_common.h"
#include "benchmarks/vdpm/openmesh_vdpm.h"
#include "benchmarks/vdpm/screen_error.h"
#include "smr/builders/mesh/qem_pm.h"
#include "smr/extract/extract.h"
#include "smr/io/mesh_reader.h"
#include "smr/rcf/spec.h"

namespace {

using nlohmann::json;
using smr::Triangle3;
using smr::Vec3;
using smr::bench::median;
using smr::bench::now_ns;
using smr::bench::seconds_since;
using smr::bench::vec3_json;
using namespace smr::bench::vdpm;

// ---- ours ---------------------------------------------------------------------------------------

struct OurCut {
  std::vector<Triangle3> triangles;
  std::vector<double> assigned_error;  // per triangle: the error its death_res stands for
  std::uint64_t x = 0;
  double extract_seconds = 0.0, expand_seconds = 0.0, total_seconds = 0.0;
};

OurCut extract_ours(const smr::Crmr& crmr, const smr::Camera& cam, double tau, bool cull) {
  smr::RcfSpec spec;
  spec.camera = cam;
  spec.cull = cull;
  spec.pixel_error = tau;
  const smr::Rcf rcf = smr::make_rcf(spec, smr::ModelKind::kMesh3d, nullptr);
  const std::uint64_t t0 = now_ns();
  const smr::Extraction e = smr::extract_minimal_surface(crmr, rcf);
  OurCut c;
  c.total_seconds = seconds_since(t0);
  c.extract_seconds = e.stats.extract_seconds;
  c.expand_seconds = e.stats.expand_seconds;
  c.x = e.stats.x;
  const smr::TriangleMesh m = smr::to_mesh(crmr, e.triangles);
  c.triangles = triangles_of(m);
  for (const float res : m.triangle_values) c.assigned_error.push_back(crmr.error_at(res));
  return c;
}

// How tight our per-triangle errors are: for each visible output triangle with a non-zero
// assigned error (error_at(death_res): the op error the screen-space criterion projects), the
// largest distance of its samples to the source surface divided by that error.
json tightness(const OurCut& cut, const SoupDistance& source, const smr::Camera& cam) {
  const auto planes = cam.planes();
  std::vector<double> ratio;
  for (std::size_t i = 0; i < cut.triangles.size(); ++i) {
    const Triangle3& t = cut.triangles[i];
    if (i >= cut.assigned_error.size() || !(cut.assigned_error[i] > 0.0)) continue;
    if (!visible_triangle(cam, planes, t)) continue;
    double d = 0.0;
    for (const Vec3& p : samples(t)) d = std::max(d, source.distance(p));
    ratio.push_back(d / cut.assigned_error[i]);
  }
  if (ratio.empty()) return {{"triangles", 0}};
  return {{"triangles", ratio.size()},
          {"median", quantile(ratio, 0.5)},
          {"p90", quantile(ratio, 0.9)},
          {"max", *std::max_element(ratio.begin(), ratio.end())}};
}

// Diagnostic for the builder: the same CRMR with each op's error replaced by a local one, the
// largest measured distance to the source of the samples of the triangles it replaces (PreF),
// made monotone over the DAG (an op's error is at least its children's: children have larger
// ids). Sampled, so a lower estimate rather than a guaranteed bound: its cuts show how much of
// our cut size comes from op.error being the largest bound over the whole mesh at the op's time.
smr::Crmr local_error_crmr(const smr::Crmr& crmr, const SoupDistance& source, json& stats) {
  smr::Crmr c = crmr;
  std::vector<double> local(c.ops.size(), 0.0), sat(c.ops.size(), 0.0);
  for (std::size_t i = c.ops.size(); i-- > 1;) {
    const smr::Op& op = c.ops[i];
    for (const smr::PreTriangle& t : op.pre_tris) {
      if (t.is_void()) continue;
      const Triangle3 v = smr::corners(op, t);
      for (const Vec3& p : samples(v)) local[i] = std::max(local[i], source.distance(p));
    }
    sat[i] = local[i];
    for (const smr::OpId ch : op.children) sat[i] = std::max(sat[i], sat[ch.value]);
  }
  std::vector<double> ratio_local, ratio_sat;
  for (std::size_t i = 1; i < c.ops.size(); ++i) {
    smr::Op& op = c.ops[i];
    if (op.error > 0.0) {
      ratio_local.push_back(local[i] / op.error);
      ratio_sat.push_back(sat[i] / op.error);
    }
    op.error = sat[i];
    op.birth_res = smr::resolution_of(c.header, sat[i]);
  }
  for (smr::Op& op : c.ops)
    for (smr::FragmentTriangle& t : op.fragment)
      if (t.killer.valid()) t.death_res = c.ops[t.killer.value].birth_res;
  stats = {{"ops", ratio_sat.size()},
           {"local_over_op_error_median", quantile(ratio_local, 0.5)},
           {"local_over_op_error_p90", quantile(ratio_local, 0.9)},
           {"monotone_local_over_op_error_median", quantile(ratio_sat, 0.5)},
           {"monotone_local_over_op_error_p10", quantile(ratio_sat, 0.1)},
           {"monotone_local_over_op_error_p90", quantile(ratio_sat, 0.9)}};
  return c;
}

std::string read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) smr::throw_input("cannot open " + path);
  std::ostringstream os;
  os << in.rdbuf();
  return os.str();
}

// ---- the command line ---------------------------------------------------------------------------

struct Config {
  std::string mesh_path, spm_path, taus_arg = "1,2,4", distances_arg = "1.5,3";
  int repeat = 3, max_passes = 200, viewport_w = 1024, viewport_h = 768;
  double fov = 60.0;
  double match_max_factor = 16.0;
  bool match = true;
  smr::QemPmOptions build_options;
};

void add_options(CLI::App& app, Config& cfg) {
  app.add_option("--mesh", cfg.mesh_path, "source mesh (.off/.ply/.obj/.stl)")->required();
  app.add_option("--spm", cfg.spm_path, "OpenMesh-Analyzer output for the same mesh")->required();
  app.add_option("--taus", cfg.taus_arg, "screen-space tolerances in pixels, comma-separated");
  app.add_option("--distances", cfg.distances_arg, "eye distances in model radii, comma-separated");
  app.add_option("--repeat", cfg.repeat, "timed runs per cut (median)")->check(CLI::PositiveNumber);
  app.add_option("--max-passes", cfg.max_passes, "VDPM refinement passes before giving up");
  app.add_option("--fov", cfg.fov, "vertical field of view, degrees");
  app.add_option("--viewport-w", cfg.viewport_w);
  app.add_option("--viewport-h", cfg.viewport_h);
  app.add_option("--match-max-factor", cfg.match_max_factor,
                 "equal-error search: largest tau multiple tried for ours");
  app.add_flag("!--no-match", cfg.match, "skip the equal-error search");
  app.add_option("--max-fragment-triangles", cfg.build_options.max_fragment_triangles,
                 "our builder's coalescing bound (QemPmOptions; 0 = one op per split)");
}

// ---- step 1: the source mesh and our CRMR -------------------------------------------------------

// The source mesh, our CRMRs and the source's distance field, shared by every cut.
struct Subject {
  smr::TriangleMesh source;
  smr::Crmr crmr;        // smr::build_qem_pm
  smr::Crmr local_crmr;  // local_error_crmr(crmr)
  std::vector<Triangle3> source_tris;
  SoupDistance source_distance{{}};
  Vec3 centre{};
  double radius = 0.0;
};

// Reads the mesh and builds ours (out["mesh"], out["ours_build"]).
void build_ours(const Config& cfg, Subject& s, json& out) {
  std::uint64_t t0 = now_ns();
  smr::MeshReport report;
  s.source = smr::read_mesh(cfg.mesh_path, {}, &report);
  const double read_seconds = seconds_since(t0);
  t0 = now_ns();
  smr::QemPmStats qstats;
  s.crmr = smr::build_qem_pm(s.source, cfg.mesh_path, cfg.build_options, &qstats);
  const double build_seconds = seconds_since(t0);
  s.source_tris = triangles_of(s.source);
  s.source_distance = SoupDistance(s.source_tris);
  json local_stats;
  t0 = now_ns();
  s.local_crmr = local_error_crmr(s.crmr, s.source_distance, local_stats);
  local_stats["seconds"] = seconds_since(t0);
  const smr::Box3 bounds = s.crmr.info().bounds;
  s.centre = bounds.center();
  s.radius = 0.5 * glm::length(bounds.hi - bounds.lo);
  out["mesh"] = {{"path", cfg.mesh_path},
                 {"vertices", s.source.positions.size()},
                 {"triangles", s.source.triangles.size()},
                 {"summary", report.summary()},
                 {"read_seconds", read_seconds},
                 {"centre", vec3_json(s.centre)},
                 {"radius", s.radius}};
  out["ours_build"] = {{"builder", "smr::build_qem_pm (default options)"},
                       {"builder_header", s.crmr.info().builder},
                       {"seconds", build_seconds},
                       {"ops", s.crmr.op_count()},
                       {"collapses", qstats.collapses},
                       {"base_vertices", qstats.base_vertices},
                       {"base_triangles", qstats.base_triangles},
                       {"err0", s.crmr.info().err0},
                       {"err_final", s.crmr.info().err_final},
                       {"what_if_local_op_errors", local_stats}};
}

// ---- step 2: VDPM's hierarchy -------------------------------------------------------------------

// Loads the .spm once (out["vdpm_hierarchy"]): the instance that refines from cut to cut.
std::unique_ptr<Vdpm> load_vdpm(const Config& cfg, const std::string& spm, const Subject& s,
                                json& out) {
  const std::uint64_t t0 = now_ns();
  auto vdpm = std::make_unique<Vdpm>(spm);
  const double load_seconds = seconds_since(t0);
  out["vdpm_hierarchy"] = {{"path", cfg.spm_path},
                           {"bytes", spm.size()},
                           {"base_vertices", vdpm->base_vertices()},
                           {"base_faces", vdpm->base_faces()},
                           {"details", vdpm->details()},
                           {"load_seconds", load_seconds}};
  if (vdpm->base_vertices() + vdpm->details() != s.source.positions.size())
    std::cerr << "warning: the .spm has " << vdpm->base_vertices() + vdpm->details()
              << " vertices, the mesh " << s.source.positions.size() << "\n";
  return vdpm;
}

// ---- step 3: per cut ----------------------------------------------------------------------------

// Cameras as in tests/support/meshes.cpp: three directions around the bounds' centre.
const std::array<Vec3, 3> kDirections{Vec3{1, 0.3, 0.2}, Vec3{-0.4, 1, -0.5}, Vec3{0.2, -0.6, 1}};

smr::Camera camera_at(const Config& cfg, const Subject& s, const Vec3& dir, double dist) {
  smr::Camera cam;
  cam.eye = s.centre + glm::normalize(dir) * (dist * s.radius);
  cam.target = s.centre;
  cam.up = std::abs(glm::normalize(dir).z) > 0.9 ? Vec3{0, 1, 0} : Vec3{0, 0, 1};
  cam.fov_y_deg = cfg.fov;
  cam.viewport_w = cfg.viewport_w;
  cam.viewport_h = cfg.viewport_h;
  cam.validate();
  return cam;
}

json camera_json(const Config& cfg, const smr::Camera& cam) {
  return {{"eye", vec3_json(cam.eye)},
          {"target", vec3_json(cam.target)},
          {"up", vec3_json(cam.up)},
          {"fov_y_deg", cfg.fov},
          {"viewport", {cfg.viewport_w, cfg.viewport_h}},
          {"focal_px", cam.focal_px()}};
}

// One side of a cut: its JSON, culled triangle count and measured error.
struct Side {
  json j;
  std::size_t triangles = 0;
  TwoSided err;
};

// Ours: timed (median of --repeat), without culling, and on the local-error CRMR.
Side measure_ours(const Config& cfg, const Subject& s, const smr::Camera& cam, double tau) {
  std::vector<double> times, totals;
  OurCut ours;
  for (int r = 0; r < cfg.repeat; ++r) {
    ours = extract_ours(s.crmr, cam, tau, true);
    times.push_back(ours.extract_seconds + ours.expand_seconds);
    totals.push_back(ours.total_seconds);
  }
  const OurCut nocull = extract_ours(s.crmr, cam, tau, false);
  const TwoSided err = measure_both(ours.triangles, s.source_tris, s.source_distance, cam);
  const TwoSided nocull_err = measure_both(nocull.triangles, s.source_tris, s.source_distance, cam);
  const OurCut local = extract_ours(s.local_crmr, cam, tau, true);
  const TwoSided local_err = measure_both(local.triangles, s.source_tris, s.source_distance, cam);
  json j = {{"triangles", ours.triangles.size()},
            {"triangles_no_culling", nocull.triangles.size()},
            {"error_no_culling", nocull_err.to_json()},
            {"measured_over_assigned_error", tightness(ours, s.source_distance, cam)},
            {"what_if_local_op_errors",
             {{"triangles", local.triangles.size()},
              {"extract_seconds", local.extract_seconds + local.expand_seconds},
              {"error", local_err.to_json()}}},
            {"x", ours.x},
            {"extract_seconds", median(times)},
            {"extract_seconds_all", times},
            {"wall_seconds_incl_setup", median(totals)},
            {"error", err.to_json()}};
  return {std::move(j), ours.triangles.size(), err};
}

// VDPM: from its base mesh (a fresh load each run; the load is not timed), without culling, and
// from the previous cut of this run (`previous`, in the order of the cuts in the output).
Side measure_vdpm(const Config& cfg, const Subject& s, const std::string& spm, Vdpm& previous,
                  const smr::Camera& cam, double tau) {
  std::vector<double> vtimes;
  AdaptStats vstats;
  double plane_dev = 0.0;
  std::unique_ptr<Vdpm> fresh;
  for (int r = 0; r < cfg.repeat; ++r) {
    fresh = std::make_unique<Vdpm>(spm);
    plane_dev = fresh->set_view(cam, tau, true);
    vstats = fresh->adapt(cfg.max_passes);
    vtimes.push_back(vstats.seconds);
  }
  const std::vector<Triangle3> tris = fresh->triangles();
  const TwoSided err = measure_both(tris, s.source_tris, s.source_distance, cam);
  Vdpm nocull(spm);
  nocull.set_view(cam, tau, false);
  const AdaptStats nocull_stats = nocull.adapt(cfg.max_passes);
  const TwoSided nocull_err =
      measure_both(nocull.triangles(), s.source_tris, s.source_distance, cam);
  previous.set_view(cam, tau, true);
  const AdaptStats prev_stats = previous.adapt(cfg.max_passes);
  json j = {{"triangles", tris.size()},
            {"triangles_no_culling", nocull.face_count()},
            {"from_base", vstats.to_json()},
            {"from_base_seconds", median(vtimes)},
            {"from_base_seconds_all", vtimes},
            {"from_previous", prev_stats.to_json()},
            {"from_previous_triangles", previous.face_count()},
            {"no_culling", nocull_stats.to_json()},
            {"error_no_culling", nocull_err.to_json()},
            {"frustum_plane_check", plane_dev},
            {"error", err.to_json()}};
  return {std::move(j), tris.size(), err};
}

double triangle_ratio(std::size_t ours, std::size_t vdpm) {
  return double(ours) / double(std::max<std::size_t>(1, vdpm));
}

json target_json(const Side& ours, const Side& vdpm) {
  const bool fewer = ours.triangles <= vdpm.triangles;
  const bool lower_max = ours.err.max_px() <= vdpm.err.max_px();
  const bool lower_p99 = ours.err.p99_px() <= vdpm.err.p99_px();
  return {{"ours_le_vdpm_triangles", fewer},
          {"ours_le_vdpm_max_px", lower_max},
          {"ours_le_vdpm_p99_px", lower_p99},
          {"holds", fewer && lower_max},
          {"triangle_ratio", triangle_ratio(ours.triangles, vdpm.triangles)}};
}

// Our cuts at tau' = tau * 2^(k/4), extracted and measured once per k.
class Ladder {
 public:
  Ladder(const Subject& s, const smr::Camera& cam, double tau, const Side& ours)
      : s_(s), cam_(cam), tau_(tau) {
    steps_[0] = {ours.triangles, ours.err};
  }

  double tau_at(int k) const { return tau_ * std::pow(2.0, k / 4.0); }

  /// (triangles, measured error) at k.
  const std::pair<std::size_t, TwoSided>& at(int k) {
    auto it = steps_.find(k);
    if (it == steps_.end()) {
      const OurCut c = extract_ours(s_.crmr, cam_, tau_at(k), true);
      it = steps_
               .emplace(k,
                        std::make_pair(c.triangles.size(), measure_both(c.triangles, s_.source_tris,
                                                                        s_.source_distance, cam_)))
               .first;
    }
    return it->second;
  }

  /// Every step taken, in order of k.
  json steps_json() const {
    json steps = json::array();
    for (const auto& [k, v] : steps_)
      steps.push_back({{"tau_px", tau_at(k)},
                       {"triangles", v.first},
                       {"max_px", v.second.max_px()},
                       {"p99_px", v.second.p99_px()}});
    return steps;
  }

 private:
  const Subject& s_;
  const smr::Camera& cam_;
  double tau_;
  std::map<int, std::pair<std::size_t, TwoSided>> steps_;  // k -> (triangles, error)
};

// The largest k in [-8, k_max] whose error (by `metric`) is still <= VDPM's: from k = 0 up while
// it is, or down until it is.
json search_ladder(Ladder& ladder, int k_max, double (*metric)(const TwoSided&), const Side& vdpm) {
  const double limit = metric(vdpm.err);
  auto ok = [&](int k) { return metric(ladder.at(k).second) <= limit; };
  int best = std::numeric_limits<int>::min();
  if (ok(0)) {
    best = 0;
    while (best < k_max && ok(best + 1)) ++best;
  } else {
    for (int k = -1; k >= -8; --k) {
      if (ok(k)) {
        best = k;
        break;
      }
    }
  }
  if (best == std::numeric_limits<int>::min()) return json{{"found", false}};
  const auto& [tris, err] = ladder.at(best);
  return json{{"found", true},
              {"tau_px", ladder.tau_at(best)},
              {"at_ladder_limit", best == k_max},
              {"triangles", tris},
              {"max_px", err.max_px()},
              {"p99_px", err.p99_px()},
              {"triangle_ratio_vs_vdpm", triangle_ratio(tris, vdpm.triangles)}};
}

// Equal measured error: our triangle count at the largest tolerance tau' = tau * 2^(k/4)
// (-8 <= k <= 4 log2(match_max_factor)) whose measured two-sided error is still <= VDPM's at tau,
// once for the max and once for the p99.
json match_vdpm_error(const Config& cfg, const Subject& s, const smr::Camera& cam, double tau,
                      const Side& ours, const Side& vdpm) {
  Ladder ladder(s, cam, tau, ours);
  const int k_max = int(std::floor(4.0 * std::log2(cfg.match_max_factor) + 1e-9));
  json matched = {{"max", search_ladder(
                              ladder, k_max, [](const TwoSided& e) { return e.max_px(); }, vdpm)},
                  {"p99", search_ladder(
                              ladder, k_max, [](const TwoSided& e) { return e.p99_px(); }, vdpm)}};
  matched["ladder"] = ladder.steps_json();
  return matched;
}

json measure_cut(const Config& cfg, const Subject& s, const std::string& spm, Vdpm& previous,
                 std::size_t d, double dist, double tau) {
  const smr::Camera cam = camera_at(cfg, s, kDirections[d], dist);
  json cut = {{"direction", d},
              {"distance_radii", dist},
              {"tau_px", tau},
              {"camera", camera_json(cfg, cam)}};
  std::cerr << cfg.mesh_path << ": dir " << d << ", " << dist << " radii, tau " << tau << " px\n";
  const Side ours = measure_ours(cfg, s, cam, tau);
  const Side vdpm = measure_vdpm(cfg, s, spm, previous, cam, tau);
  cut["ours"] = ours.j;
  cut["vdpm"] = vdpm.j;
  cut["target"] = target_json(ours, vdpm);
  if (cfg.match) cut["ours_at_vdpm_error"] = match_vdpm_error(cfg, s, cam, tau, ours, vdpm);
  return cut;
}

// ---- the run ------------------------------------------------------------------------------------

json run(const Config& cfg) {
  const std::vector<double> taus = smr::bench::parse_doubles(cfg.taus_arg),
                            distances = smr::bench::parse_doubles(cfg.distances_arg);
  json out;
  out["benchmark"] = "vdpm";
  out["machine"] = smr::bench::machine_json();
  Subject s;
  build_ours(cfg, s, out);
  const std::string spm = read_bytes(cfg.spm_path);
  const std::unique_ptr<Vdpm> previous = load_vdpm(cfg, spm, s, out);
  json cuts = json::array();
  for (std::size_t d = 0; d < kDirections.size(); ++d)
    for (const double dist : distances)
      for (const double tau : taus)
        cuts.push_back(measure_cut(cfg, s, spm, *previous, d, dist, tau));
  out["cuts"] = cuts;
  out["peak_rss_mb"] = smr::bench::peak_rss_mb();
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  Config cfg;
  CLI::App app{"View-dependent output size and measured screen-space error: ours vs OpenMesh VDPM"};
  add_options(app, cfg);
  CLI11_PARSE(app, argc, argv);
  try {
    std::cout << run(cfg).dump(2) << "\n";
  } catch (const std::exception& e) {
    std::cerr << "bench_vdpm: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
