// smrdb: the command line. Parses options, reports progress on stderr, prints JSON on request.
// Nothing below tools/ prints or exits; errors arrive here as smr::Error (exit 1, or 2 for bugs).
#include <malloc.h>
#include <sys/resource.h>

#include <atomic>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <optional>
#include <span>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "base/error.h"
#include "smr/builders/block_tin.h"
#include "smr/builders/greedy_tin.h"
#include "smr/builders/qem_pm.h"
#include "smr/core/invariants.h"
#include "smr/db/database.h"
#include "smr/db/verify.h"
#include "smr/db/writer.h"
#include "smr/extract/extract.h"
#include "smr/io/dem_reader.h"
#include "smr/io/mesh_reader.h"
#include "smr/io/mesh_writer.h"
#include "smr/io/render.h"
#include "smr/io/synthetic.h"
#include "smr/query/indexed_source.h"
#include "smr/rcf/spec.h"
#include "tools/progress.h"

namespace {

using smr::throw_input;
using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// The process's peak resident set before the last reset_peak_rss() (MiB).
double g_peak_before_reset_mb = 0.0;

// The process's peak resident set so far (getrusage: kilobytes on Linux), in MiB.
double peak_rss_mb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return std::max(g_peak_before_reset_mb, double(u.ru_maxrss) / 1024.0);
}

// Starts measuring a phase's own peak resident set (Linux: clear_refs 5 resets VmHWM); false if
// the kernel does not allow it. peak_rss_mb() still reports the whole run's peak.
bool reset_peak_rss() {
  g_peak_before_reset_mb = peak_rss_mb();
  malloc_trim(0);  // the phase before may have freed much that glibc still holds
  std::FILE* f = std::fopen("/proc/self/clear_refs", "w");
  if (f == nullptr) return false;
  const bool ok = std::fputs("5", f) >= 0;
  return std::fclose(f) == 0 && ok;
}

// The resident set's peak since reset_peak_rss() (VmHWM), in MiB; 0 if unknown.
double phase_peak_rss_mb() {
  std::FILE* f = std::fopen("/proc/self/status", "r");
  if (f == nullptr) return 0.0;
  char line[256];
  double kb = 0.0;
  while (std::fgets(line, sizeof line, f) != nullptr) {
    if (std::strncmp(line, "VmHWM:", 6) == 0) kb = std::strtod(line + 6, nullptr);
  }
  std::fclose(f);
  return kb / 1024.0;
}

// "256M", "2G", "1.5G", "512K" or a plain number of bytes (binary units: M = 2^20).
std::uint64_t parse_bytes(const std::string& text, const std::string& option) {
  double v = 0.0;
  std::size_t used = 0;
  try {
    v = std::stod(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  const std::string unit = text.substr(used);
  const int shift = unit.empty() || unit == "B"  ? 0
                    : unit == "K" || unit == "k" ? 10
                    : unit == "M" || unit == "m" ? 20
                    : unit == "G" || unit == "g" ? 30
                    : unit == "T" || unit == "t" ? 40
                                                 : -1;
  if (used == 0 || shift < 0 || !std::isfinite(v) || v <= 0.0 || v * std::ldexp(1.0, shift) > 1e18)
    throw_input(option + " expects a size such as 256M or 2G, got '" + text + "'");
  return static_cast<std::uint64_t>(v * std::ldexp(1.0, shift));
}

std::vector<double> parse_numbers(const std::string& text, std::size_t count,
                                  const std::string& option, const std::string& form) {
  std::vector<double> out;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    try {
      std::size_t used = 0;
      const double v = std::stod(item, &used);
      if (used != item.size() || !std::isfinite(v)) throw std::invalid_argument(item);
      out.push_back(v);
    } catch (const std::exception&) {
      throw_input(option + " expects " + form + ", got '" + text + "' ('" + item +
                  "' is not a finite number)");
    }
  }
  if (out.size() != count) throw_input(option + " expects " + form + ", got '" + text + "'");
  return out;
}

smr::Vec3 parse_vec3(const std::string& text, const std::string& option) {
  const auto v = parse_numbers(text, 3, option, "x,y,z");
  return {v[0], v[1], v[2]};
}

smr::AoiSpec parse_aoi(const std::string& text, const std::string& option) {
  const auto v = parse_numbers(text, 4, option, "x,y,radius,level");
  return {v[0], v[1], v[2], v[3]};
}

struct RcfOptions {
  std::string eye, target, up, viewport = "1024x768", screen_aoi, centre_cone;
  double fov = 60.0, near = 0.0, far = 0.0;
  std::optional<double> pixel_error, floor, frustum_level, critical_level;
  double critical_relief = 0.0;
  std::vector<std::string> aois, discs, volumes, balls;
  bool no_cull = false;

  void add_to(CLI::App& app) {
    app.add_option("--eye", eye, "Camera position x,y,z (model coordinates)");
    app.add_option("--target", target, "Point the camera looks at x,y,z");
    app.add_option("--up", up, "Camera up vector x,y,z (default 0,0,1)");
    app.add_option("--fov", fov, "Vertical field of view in degrees")->capture_default_str();
    app.add_option("--viewport", viewport, "Viewport size WxH in pixels")->capture_default_str();
    app.add_option("--near", near, "Near plane distance (0 = at the eye)");
    app.add_option("--far", far, "Far plane distance (0 = none)");
    app.add_flag("--no-cull", no_cull, "Disable view-frustum and back-face culling");
    app.add_option("--pixel-error", pixel_error,
                   "Screen-space tolerance in pixels (needs a camera)");
    app.add_option("--screen-aoi", screen_aoi,
                   "Screen area of interest u,v,radius_px,pixel_error: lower tolerance inside");
    app.add_option("--floor", floor, "Constant object-space resolution level in [0,1]");
    app.add_option("--aoi", aois, "Gaussian area of interest x,y,radius,level (repeatable)");
    app.add_option("--disc", discs, "Thresholded disc x,y,radius,level (repeatable)");
    app.add_option("--volume", volumes,
                   "3-D Gaussian volume of significance x,y,z,radius,level (repeatable)");
    app.add_option("--ball", balls, "3-D thresholded ball x,y,z,radius,level (repeatable)");
    app.add_option("--frustum-level", frustum_level,
                   "Object-space level inside the view frustum's footprint");
    app.add_option("--centre-cone", centre_cone, "Screen-centre cone half_angle_deg,level");
    app.add_option("--critical-lines", critical_level,
                   "Level on Peucker-Douglas ridge/channel samples");
    app.add_option("--critical-relief", critical_relief,
                   "Keep critical samples with 3x3 relief >= this");
  }

  smr::RcfSpec spec() const {
    smr::RcfSpec s;
    if (!eye.empty() || !target.empty()) {
      if (eye.empty() || target.empty()) throw_input("a camera needs both --eye and --target");
      smr::Camera cam;
      cam.eye = parse_vec3(eye, "--eye");
      cam.target = parse_vec3(target, "--target");
      if (!up.empty()) cam.up = parse_vec3(up, "--up");
      cam.fov_y_deg = fov;
      int w = 0, h = 0;
      char x = 0, extra = 0;
      std::stringstream vs(viewport);
      if (!(vs >> w >> x >> h) || x != 'x' || (vs >> extra)) {
        throw_input("--viewport expects WxH (e.g. 1920x1080), got '" + viewport + "'");
      }
      cam.viewport_w = w;
      cam.viewport_h = h;
      cam.near_distance = near;
      cam.far_distance = far;
      s.camera = cam;
    }
    s.cull = !no_cull;
    s.pixel_error = pixel_error;
    if (!screen_aoi.empty()) {
      const auto v = parse_numbers(screen_aoi, 4, "--screen-aoi", "u,v,radius_px,pixel_error");
      s.screen_aoi = smr::ScreenAoi{{v[0], v[1]}, v[2], v[3]};
    }
    s.floor = floor;
    for (const auto& a : aois) s.aois.push_back(parse_aoi(a, "--aoi"));
    for (const auto& a : discs) s.discs.push_back(parse_aoi(a, "--disc"));
    for (const auto& [list, gaussian] : {std::pair{&volumes, true}, std::pair{&balls, false}}) {
      for (const auto& text : *list) {
        const auto v =
            parse_numbers(text, 5, gaussian ? "--volume" : "--ball", "x,y,z,radius,level");
        s.volumes.push_back({v[0], v[1], v[2], v[3], v[4], gaussian});
      }
    }
    s.frustum_level = frustum_level;
    if (!centre_cone.empty()) {
      const auto v = parse_numbers(centre_cone, 2, "--centre-cone", "half_angle_deg,level");
      s.centre_cone = std::pair{v[0], v[1]};
    }
    s.critical_level = critical_level;
    s.critical_relief = critical_relief;
    smr::validate(s);
    return s;
  }
};

nlohmann::json stats_json(const smr::ExtractStats& s) {
  return {{"x", s.x},
          {"x_plus", s.x_plus},
          {"ops_visited", s.ops_visited},
          {"triangles", s.triangles},
          {"void_triangles", s.void_triangles},
          {"fans", s.fans},
          {"triangles_per_fan", s.triangles_per_fan()},
          {"starting_points", s.starting_points},
          {"domain_tests", s.domain_tests},
          {"held_ops_peak", s.held_ops_peak},
          {"held_bytes_peak", s.held_bytes_peak},
          {"extract_seconds", s.extract_seconds},
          {"expand_seconds", s.expand_seconds}};
}

std::string extension_of(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

struct IngestArgs {
  std::string dem;
  double max_error = 0.0;
  std::uint64_t max_vertices = 0, base_vertices = 4;
  std::string codec = "zstd";
  double z_quantum = 0.0;
  std::uint32_t page_kb = 16;
  bool force = false;
  bool repair = false;
  bool allow_self_intersections = false;
  std::uint32_t coalesce = 32;
  double coalesce_ratio = 0.7;
  std::string builder;  // empty: blocks with --memory, else greedy
  int block_cells = 256;
  std::string tmp_dir;
  std::string memory;  // --memory as typed
  unsigned threads = 0;

  bool is_mesh() const { return smr::is_mesh_path(dem); }
  std::string effective_builder() const {
    return !builder.empty() ? builder : !memory.empty() ? "blocks" : "greedy";
  }
  std::uint64_t memory_bytes() const {
    return memory.empty() ? 0 : parse_bytes(memory, "--memory");
  }

  void add_to(CLI::App& app) {
    app.add_option("input", dem,
                   "DEM (GeoTIFF or any GDAL raster with one band, .npy, .npz) or 3-D mesh (.ply, "
                   ".obj, .off, .stl)")
        ->required();
    app.add_option("--coalesce", coalesce,
                   "Meshes: merge vertex splits into ops of at most this many fragment "
                   "triangles (Brown 4.4.3.3; 0 = one op per split)")
        ->capture_default_str();
    app.add_option("--coalesce-ratio", coalesce_ratio,
                   "Meshes: merge a split only when its error is at least this fraction of the "
                   "op's (1 = only equal errors; lower = fewer, larger ops, less selective)")
        ->capture_default_str();
    app.add_flag("--allow-self-intersections", allow_self_intersections,
                 "Meshes: skip the test that keeps simplification from making the surface cross "
                 "itself (faster; coarse levels may then self-intersect)");
    app.add_flag("--repair", repair,
                 "Meshes: weld equal vertices, drop degenerate and duplicate faces, split "
                 "non-manifold edges and vertices, orient faces consistently");
    app.add_option("--max-error", max_error,
                   "Stop refining at this vertical error (data units; 0 = lossless)")
        ->capture_default_str();
    app.add_option("--max-vertices", max_vertices, "Stop at this many vertices (0 = no limit)");
    app.add_option("--base-vertices", base_vertices,
                   "Vertices of the base mesh (terrain: 4 = the corners; meshes: simplify down to "
                   "this many where the collapse rules allow)")
        ->capture_default_str();
    app.add_option("--builder", builder,
                   "DEMs: greedy (Delaunay insertion, the DEM read whole; the default) or blocks "
                   "(hierarchical block decimation, the DEM read one block at a time; the default "
                   "with --memory). Meshes: blocks streams a PLY through octree blocks (the "
                   "default with --memory; otherwise the mesh is read, validated and built in "
                   "memory)");
    app.add_option("--memory", memory,
                   "--builder blocks: memory budget (e.g. 256M, 2G). DEMs: sizes the windows "
                   "held for exact error bounds, the raster and write caches; meshes: the "
                   "external sorts and the writer; peak RSS is reported by --json");
    app.add_option("--block-cells", block_cells,
                   "DEMs, --builder blocks: side of a leaf block in grid cells (a power of two)")
        ->capture_default_str();
    app.add_option("--tmp", tmp_dir,
                   "DEMs, --builder blocks: directory for the scratch copy of the samples "
                   "(default: the system's temporary directory)");
    app.add_option(
           "--threads", threads,
           "--builder blocks (and --memory): threads reading, building and writing blocks; meshes "
           "built in memory: threads computing error bounds ahead (0 = one per core; the database "
           "is the same whatever the number)")
        ->capture_default_str();
    app.add_option("--codec", codec, "Geometry codec of the pages: draco, zstd or raw")
        ->capture_default_str();
    app.add_option("--z-quantum", z_quantum,
                   "Height quantization step (data units; 0 = automatic, range / 2^24)");
    app.add_option("--page-kb", page_kb, "Target size of a data page in KiB")
        ->capture_default_str();
    app.add_flag("--force", force, "Replace an existing database");
  }
  // Checks everything the user typed before any long work.
  void validate() const {
    if (!(max_error >= 0.0) || !std::isfinite(max_error))
      throw_input("--max-error must be >= 0 (data units)");
    if (base_vertices < 4) throw_input("--base-vertices must be at least 4 (the corners)");
    if (!smr::storage::parse_codec(codec))
      throw_input("--codec must be draco, zstd or raw, got '" + codec + "'");
    if (!(z_quantum >= 0.0) || !std::isfinite(z_quantum))
      throw_input("--z-quantum must be >= 0 (0 = automatic)");
    if (page_kb < 1 || page_kb > 4096) throw_input("--page-kb must be in [1, 4096]");
    if (is_mesh() && (max_error != 0.0 || max_vertices != 0)) {
      throw_input(
          "--max-error and --max-vertices apply to DEMs: a mesh database always refines "
          "to the source mesh (use --base-vertices to choose the coarsest level)");
    }
    if (!is_mesh() && repair) throw_input("--repair applies to meshes (.ply, .obj, .off, .stl)");
    if (!is_mesh() && allow_self_intersections)
      throw_input("--allow-self-intersections applies to meshes (.ply, .obj, .off, .stl)");
    if (!(coalesce_ratio >= 0.0 && coalesce_ratio <= 1.0))
      throw_input("--coalesce-ratio must be in [0, 1]");
    if (!builder.empty() && builder != "greedy" && builder != "blocks")
      throw_input("--builder must be greedy or blocks, got '" + builder + "'");
    if (is_mesh() && builder == "greedy")
      throw_input("--builder greedy applies to DEMs; meshes are built by quadric edge collapse");
    if (is_mesh() && effective_builder() == "blocks") {
      if (block_cells != 256)
        throw_input("--block-cells applies to DEMs; mesh blocks are octree cells");
      if (coalesce != 32 || coalesce_ratio != 0.7)
        throw_input("--coalesce and --coalesce-ratio apply to meshes built in memory");
    }
    if (is_mesh() && repair && effective_builder() == "blocks")
      throw_input(
          "--repair needs the mesh in memory: drop --memory / --builder blocks (a streamed mesh "
          "is not repaired)");
    const std::string chosen = effective_builder();
    if (!memory.empty() && chosen != "blocks")
      throw_input("--memory needs --builder blocks: the greedy builder reads the DEM whole");
    if (!memory.empty() && memory_bytes() < (std::uint64_t{32} << 20))
      throw_input("--memory must be at least 32M, got '" + memory + "'");
    if (chosen == "blocks" && (max_vertices != 0 || base_vertices != 4)) {
      throw_input(
          "--max-vertices and --base-vertices apply to --builder greedy; the block "
          "builder refines to --max-error and decimates down to the corners");
    }
    if (!tmp_dir.empty() && chosen != "blocks") throw_input("--tmp applies to --builder blocks");
    if (threads != 0 && chosen != "blocks" && !is_mesh())
      throw_input("--threads applies to --builder blocks and to meshes");
    if (block_cells < 8 || (block_cells & (block_cells - 1)) != 0)
      throw_input("--block-cells must be a power of two, at least 8, got " +
                  std::to_string(block_cells));
  }
  // What the database records of how it was built: the input's file name and every build
  // parameter, in a fixed order. Not the command line: output path, flag order, -q or --json
  // must not change the file (same input and parameters -> byte-identical database).
  std::string describe() const {
    const auto number = [](double v) {  // shortest text that reads back as v
      char buf[32];
      return std::string(buf, std::to_chars(buf, buf + sizeof buf, v).ptr);
    };
    return "input=" + std::filesystem::path(dem).filename().string() +
           " max-error=" + number(max_error) + " max-vertices=" + std::to_string(max_vertices) +
           " base-vertices=" + std::to_string(base_vertices) + " codec=" + codec +
           " z-quantum=" + number(z_quantum) + " page-kb=" + std::to_string(page_kb) +
           (is_mesh() && allow_self_intersections ? " self-intersections=allowed" : "") +
           (is_mesh() && effective_builder() == "blocks"
                ? " builder=blocks" +
                      (memory.empty() ? std::string() : " memory=" + std::to_string(memory_bytes()))
            : is_mesh() ? std::string(" repair=") + (repair ? "yes" : "no") + " coalesce=" +
                              std::to_string(coalesce) + " coalesce-ratio=" + number(coalesce_ratio)
            : effective_builder() == "blocks"
                ? " builder=blocks block-cells=" + std::to_string(block_cells) +
                      (memory.empty() ? std::string() : " memory=" + std::to_string(memory_bytes()))
                : std::string());
  }
};

// What `--json` reports of a CRMR, counted op by op (in memory, or as the ops stream by).
struct CrmrCounts {
  // add() may run on several threads at once (a sink's encode()).
  std::atomic<std::uint64_t> ops = 0, triangles = 0, finest = 0, base = 0;
  std::uint64_t vertices = 0;
  double err0 = 0.0, err_final = 0.0;
  void header(const smr::CrmrInfo& h) {
    vertices = h.vertex_count;
    err0 = h.err0;
    err_final = h.err_final;
  }
  void add(const smr::Op& op) {
    std::uint64_t f = 0;
    for (const auto& t : op.fragment) f += !t.killer.valid() && !t.is_void();
    finest.fetch_add(f, std::memory_order_relaxed);
    if (op.id.value == 0) base = op.fragment.size();
    triangles.fetch_add(op.fragment.size(), std::memory_order_relaxed);
    ops.fetch_add(1, std::memory_order_relaxed);
  }
  nlohmann::json json(double build_seconds) const {
    return {{"ops", ops.load()},
            {"fragment_triangles", triangles.load()},
            {"vertices", vertices},
            {"finest_triangles", finest.load()},
            {"base_triangles", base.load()},
            {"err0", err0},
            {"err_final", err_final},
            {"build_seconds", build_seconds}};
  }
};

smr::WriteOptions write_options(const IngestArgs& a, smr::tools::GdalProgress& progress);
nlohmann::json database_report(const smr::WriteReport& w, const IngestArgs& a,
                               const std::string& db_path, std::uint64_t vertices);
nlohmann::json ingest_blocks(const IngestArgs& a, const std::string& db_path,
                             smr::tools::GdalProgress& progress, bool verify);
nlohmann::json ingest_mesh_blocks(const IngestArgs& a, const std::string& db_path,
                                  smr::tools::GdalProgress& progress, bool verify);

// Reads the DEM, builds the CRMR and writes the database. Returns the report.
nlohmann::json ingest(const IngestArgs& a, const std::string& db_path, bool quiet, bool verify) {
  nlohmann::json report;
  auto t0 = Clock::now();
  smr::tools::GdalProgress progress(quiet ? nullptr : stderr);
  smr::Crmr crmr;
  if (a.is_mesh() && a.effective_builder() == "blocks") {
    return ingest_mesh_blocks(a, db_path, progress, verify);
  } else if (a.is_mesh()) {
    smr::MeshReport mr;
    const smr::TriangleMesh mesh =
        smr::read_mesh(a.dem, a.repair ? smr::MeshRepair::all() : smr::MeshRepair{}, &mr);
    report["input"] = {{"path", a.dem},
                       {"kind", "mesh"},
                       {"vertices", mr.vertices},
                       {"triangles", mr.faces},
                       {"components", mr.components},
                       {"boundary_edges", mr.boundary_edges},
                       {"repairs", mr.repairs()},
                       {"summary", mr.summary()},
                       {"read_seconds", seconds_since(t0)}};
    smr::QemPmOptions opt;
    opt.base_vertices = a.base_vertices;
    opt.max_fragment_triangles = a.coalesce;
    opt.coalesce_error_ratio = a.coalesce_ratio;
    opt.no_self_intersections = !a.allow_self_intersections;
    opt.threads = a.threads;
    opt.progress = [&](double f) { progress.update(0.8 * f); };
    t0 = Clock::now();
    smr::QemPmStats qs;
    crmr = smr::build_qem_pm(mesh, a.dem, opt, &qs);
    report["simplification"] = {{"collapses", qs.collapses},
                                {"spawned_components", qs.spawned_components},
                                {"base_vertices", qs.base_vertices},
                                {"base_triangles", qs.base_triangles},
                                {"bounds_computed", qs.bounds_computed},
                                {"bounds_ahead", qs.bounds_ahead},
                                {"bounds_ahead_used", qs.bounds_ahead_used},
                                {"rejected_link", qs.rejected_link},
                                {"rejected_flip", qs.rejected_flip},
                                {"rejected_boundary", qs.rejected_boundary},
                                {"rejected_intersection", qs.rejected_intersection},
                                {"rejected_mixed_levels", qs.rejected_mixed_levels}};
  } else if (a.effective_builder() == "blocks") {
    return ingest_blocks(a, db_path, progress, verify);
  } else {
    const smr::Heightfield dem = smr::read_dem(a.dem);
    report["input"] = {{"path", a.dem},
                       {"kind", "terrain"},
                       {"width", dem.width},
                       {"height", dem.height},
                       {"samples", dem.sample_count()},
                       {"nodata", dem.has_nodata()},
                       {"geographic", dem.georef.geographic},
                       {"read_seconds", seconds_since(t0)}};
    smr::GreedyTinOptions opt;
    opt.max_error = a.max_error;
    opt.max_vertices = a.max_vertices;
    opt.base_vertices = a.base_vertices;
    opt.progress = [&](double f) { progress.update(0.8 * f); };
    t0 = Clock::now();
    crmr = smr::build_greedy_tin(dem, opt);
  }
  // The database names its source by file name only, like describe(): where the input sits
  // must not change the bytes.
  crmr.header.source = std::filesystem::path(a.dem).filename().string();
  CrmrCounts counts;
  counts.header(crmr.header);
  for (const smr::Op& op : crmr.ops) counts.add(op);
  report["crmr"] = counts.json(seconds_since(t0));
  if (verify) {
    const smr::InvariantReport r = smr::check_crmr(crmr);
    if (!r.ok()) smr::throw_internal("CRMR invariants violated: " + r.summary());
  }
  smr::WriteOptions wo = write_options(a, progress);
  const smr::WriteReport w = smr::write_database(crmr, db_path, wo);
  progress.done();
  report["database"] = database_report(w, a, db_path, crmr.header.vertex_count);
  return report;
}

smr::WriteOptions write_options(const IngestArgs& a, smr::tools::GdalProgress& progress) {
  smr::WriteOptions wo;
  wo.codec = *smr::storage::parse_codec(a.codec);
  wo.force = a.force;
  wo.z_step = a.z_quantum;
  wo.page_bytes = a.page_kb * 1024 - 16;
  wo.parameters = a.describe();
  wo.progress = [&progress](double f) { progress.update(0.8 + 0.2 * f); };
  if (a.memory_bytes() != 0) {
    // A streamed ingest: batches of a 16th; finish() runs once the builder has freed its
    // records, and its sorts take a quarter.
    wo.batch_bytes = a.memory_bytes() / 16;
    wo.memory_bytes = a.memory_bytes() / 4;
  }
  return wo;
}

nlohmann::json database_report(const smr::WriteReport& w, const IngestArgs& a,
                               const std::string& db_path, std::uint64_t vertices) {
  return {
      {"path", db_path},
      {"codec", a.codec},
      {"pages", w.pages},
      {"rtree_nodes", w.rtree_nodes},
      {"page_bytes", w.page_bytes},
      {"locator_bytes", w.locator_bytes},
      {"rtree_bytes", w.rtree_bytes},
      {"file_bytes", w.file_bytes},
      {"bytes_per_vertex", double(w.file_bytes) / double(std::max<std::uint64_t>(1, vertices))},
      {"z_quantum", w.grid.step.z},
      {"z_shift", w.z_shift},
      {"dag_depth", w.dag_depth},
      {"write_seconds", w.seconds},
      {"write_phases_seconds",
       {{"sweep", w.seconds_sweep}, {"tables", w.seconds_tables}, {"commit", w.seconds_commit}}}};
}

// Between the block builder and the database writer: names the source by file name only (as
// ingest() does for the in-memory builders) and counts what the report shows of the ops.
class IngestTap final : public smr::OpSink {
 public:
  IngestTap(smr::OpSink& inner, std::string source) : inner_(inner), source_(std::move(source)) {}
  void begin(const smr::CrmrInfo& header, std::uint64_t op_count) override {
    smr::CrmrInfo h = header;
    h.source = source_;
    counts.header(h);
    inner_.begin(h, op_count);
  }
  void add(smr::Op&& op) override {
    counts.add(op);
    inner_.add(std::move(op));
  }
  bool encodes() const override { return inner_.encodes(); }
  void encode(smr::Op& op, std::vector<std::uint8_t>& out) const override {
    counts.add(op);
    inner_.encode(op, out);
  }
  void add_encoded(std::span<const std::uint8_t> op) override { inner_.add_encoded(op); }
  mutable CrmrCounts counts;

 private:
  smr::OpSink& inner_;
  std::string source_;
};

// The end of a streamed ingest's report: the CRMR counted as it streamed, the database, the
// writer's own peak (its finish(): sorts, sweep, pages; < 0 when not measured) and, with
// --verify, a check of what was written (the CRMR never exists in memory: checksums, DAG, links,
// index).
void report_streamed(nlohmann::json& report, const IngestTap& tap, const smr::WriteReport& w,
                     const IngestArgs& a, const std::string& db_path, double build_seconds,
                     double finish_rss, bool verify) {
  report["crmr"] = tap.counts.json(build_seconds);
  report["database"] = database_report(w, a, db_path, tap.counts.vertices);
  if (finish_rss >= 0.0) report["database"]["finish_peak_rss_mb"] = finish_rss;
  if (verify) {
    const smr::VerifyReport r = smr::verify_database(db_path, nullptr);
    if (!r.ok()) smr::throw_internal("database invariants violated: " + r.faults.front());
  }
}

// --builder blocks: the builder streams its ops into the database writer, which spools them to
// --tmp; neither the raster nor the CRMR is ever whole in memory.
nlohmann::json ingest_blocks(const IngestArgs& a, const std::string& db_path,
                             smr::tools::GdalProgress& progress, bool verify) {
  nlohmann::json report;
  const auto t0 = Clock::now();
  const std::unique_ptr<smr::RasterWindows> dem = smr::open_dem(a.dem);
  smr::BlockTinOptions opt;
  opt.max_error = a.max_error;
  opt.block_cells = a.block_cells;
  opt.tmp_dir = a.tmp_dir;
  opt.memory_bytes = a.memory_bytes();
  opt.threads = a.threads;
  opt.progress = [&](double f) { progress.update(0.8 * f); };
  smr::BlockTinStats st;
  smr::DatabaseStreamWriter writer(db_path, write_options(a, progress), a.tmp_dir);
  IngestTap tap(writer, std::filesystem::path(a.dem).filename().string());
  smr::build_block_tin(*dem, tap, opt, &st);
  const double build_seconds = seconds_since(t0);
  if (opt.memory_bytes != 0 && st.record_bytes > opt.memory_bytes / 2) {
    // The finest mesh's records are not budgeted yet (issue 5): say so rather than overrun
    // --memory silently.
    std::fprintf(stderr,
                 "smrdb: warning: the block builder's records took %.0f MiB (%llu triangles made "
                 "at --max-error %g), more than half of --memory %s: they are not paged out yet; "
                 "a larger --max-error makes fewer\n",
                 double(st.record_bytes) / double(1 << 20),
                 static_cast<unsigned long long>(st.triangles_made), a.max_error, a.memory.c_str());
  }
  const bool phase_rss = reset_peak_rss();
  const smr::WriteReport w = writer.finish();
  const double finish_rss = phase_rss ? phase_peak_rss_mb() : 0.0;
  progress.done();
  report["input"] = {{"path", a.dem},
                     {"kind", "terrain"},
                     {"width", dem->width()},
                     {"height", dem->height()},
                     {"samples", st.samples},
                     {"geographic", dem->georef().geographic},
                     {"largest_window_samples", st.max_block_samples}};
  report["blocks"] = {{"block_cells", a.block_cells},
                      {"leaf_blocks", st.leaf_blocks},
                      {"levels", st.levels},
                      {"rounds", st.rounds},
                      {"dag_height", st.dag_height},
                      {"removals", st.removals},
                      {"finest_vertices", st.finest_vertices},
                      {"base_vertices", st.base_vertices},
                      {"non_delaunay_holes", st.non_delaunay_holes},
                      {"delaunay_flips", st.delaunay_flips},
                      {"delaunay_insertions", st.delaunay_insertions},
                      {"level0_interleaved", st.level0_interleaved},
                      {"level0_restarts", st.level0_restarts},
                      {"exact_levels", st.exact_levels},
                      {"samples_rescanned", st.samples_rescanned},
                      {"samples_scanned", st.samples_scanned},
                      {"plans", st.plans},
                      {"temp_bytes", st.temp_bytes + w.spool_bytes + w.scratch_bytes},
                      {"triangles_made", st.triangles_made},
                      {"record_mb", double(st.record_bytes) / double(1 << 20)},
                      {"seconds",
                       {{"survey", st.seconds_survey},
                        {"read", st.seconds_read},
                        {"greedy", st.seconds_greedy},
                        {"delaunay", st.seconds_delaunay},
                        {"level0", st.seconds_level0},
                        {"leaves", st.seconds_leaves},
                        {"upper", st.seconds_upper},
                        {"assemble", st.seconds_assemble},
                        {"assembly_feed", st.seconds_feed},
                        {"assembly_join", st.seconds_join},
                        {"assembly_emit", st.seconds_emit}}}};
  report_streamed(report, tap, w, a, db_path, build_seconds, phase_rss ? finish_rss : -1.0, verify);
  return report;
}

// Meshes with --memory: the PLY is streamed (two passes), its triangles sorted by octree cell on
// disk, blocks simplified and merged, ops assembled on disk and streamed to the writer.
nlohmann::json ingest_mesh_blocks(const IngestArgs& a, const std::string& db_path,
                                  smr::tools::GdalProgress& progress, bool verify) {
  nlohmann::json report;
  const auto t0 = Clock::now();
  const std::unique_ptr<smr::MeshStream> mesh = smr::open_mesh_stream(a.dem);
  smr::BlockPmOptions opt;
  opt.tmp_dir = a.tmp_dir;
  opt.no_self_intersections = !a.allow_self_intersections;
  // The sorts take a quarter of the budget; the rest holds the vertices (24 + 8 bytes each), the
  // assembler's 16 bytes a collapse, the blocks and the writer.
  opt.memory_bytes = a.memory_bytes() != 0 ? a.memory_bytes() / 4 : 0;
  opt.threads = a.threads;
  opt.progress = [&](double f) { progress.update(0.8 * f); };
  smr::BlockPmStats st;
  smr::DatabaseStreamWriter writer(db_path, write_options(a, progress), a.tmp_dir);
  IngestTap tap(writer, std::filesystem::path(a.dem).filename().string());
  smr::build_block_pm(*mesh, tap, opt, &st);
  const double build_seconds = seconds_since(t0);
  const bool phase_rss = reset_peak_rss();
  const smr::WriteReport w = writer.finish();
  const double finish_rss = phase_rss ? phase_peak_rss_mb() : 0.0;
  progress.done();
  report["input"] = {
      {"path", a.dem}, {"kind", "mesh"}, {"vertices", st.vertices}, {"triangles", st.triangles}};
  report["blocks"] = {
      {"leaf_blocks", st.leaf_blocks},
      {"levels", st.levels},
      {"rounds", st.rounds},
      {"dag_height", st.dag_height},
      {"collapses", st.collapses},
      {"base_vertices", st.base_vertices},
      {"base_triangles", st.base_triangles},
      {"rejected_intersection", st.rejected_intersection},
      {"max_block_triangles", st.max_block_triangles},
      {"max_handed_triangles", st.max_handed_triangles},
      {"triangles_per_second", double(st.triangles) / std::max(1e-9, build_seconds)},
      {"temp_bytes", st.temp_bytes + w.spool_bytes + w.scratch_bytes},
      {"seconds",
       {{"sort", st.seconds_sort},
        {"blocks", st.seconds_blocks},
        {"blocks_tail", st.seconds_tail},
        {"assemble", st.seconds_assemble},
        {"assembly_join", st.seconds_join},
        {"assembly_emit", st.seconds_emit}}}};
  report_streamed(report, tap, w, a, db_path, build_seconds, phase_rss ? finish_rss : -1.0, verify);
  return report;
}

struct ExtractArgs {
  std::string algorithm = "minimal", out, png, dem;
  std::uint64_t cache_mb = 64;

  void add_to(CLI::App& app, bool with_cache) {
    app.add_option("--algorithm", algorithm, "minimal (Brown 5.1) or reduced (Brown 5.2)")
        ->capture_default_str();
    app.add_option("-o,--output", out, "Output mesh (.obj or .ply)")->required();
    app.add_option("--png", png, "Also write a top-down picture of the mesh (.png)");
    if (with_cache) {
      app.add_option("--cache-mb", cache_mb, "Page cache budget in MiB")->capture_default_str();
      app.add_option("--dem", dem, "The source DEM (needed by --critical-lines)");
    }
  }
  void validate() const {
    if (algorithm != "minimal" && algorithm != "reduced")
      throw_input("--algorithm must be 'minimal' or 'reduced', got '" + algorithm + "'");
    const std::string ext = extension_of(out);
    if (ext != ".obj" && ext != ".ply")
      throw_input("-o " + out + ": the output must end in .obj or .ply");
    if (!png.empty() && extension_of(png) != ".png")
      throw_input("--png " + png + ": must end in .png");
    if (cache_mb < 1 || cache_mb > (std::uint64_t{1} << 20))
      throw_input("--cache-mb must be in [1, 1048576]");
  }
};

nlohmann::json extract(const smr::Database& db, const smr::Heightfield* dem,
                       const smr::RcfSpec& spec, const ExtractArgs& a, bool verify) {
  nlohmann::json report;
  if (spec.critical_level && dem == nullptr)
    throw_input("--critical-lines needs the source DEM: pass --dem");
  const smr::Rcf rcf = smr::make_rcf(spec, db.info().kind, dem);
  const smr::IndexedSource source(db);  // RCF questions answered by the R-tree
  const smr::Extraction e = a.algorithm == "reduced" ? smr::extract_reduced(source, rcf)
                                                     : smr::extract_minimal_surface(source, rcf);
  report["rcf"] = rcf.describe();
  report["extraction"] = stats_json(e.stats);
  report["extraction"]["algorithm"] = a.algorithm;
  if (verify && db.info().kind == smr::ModelKind::kTerrain) {
    const smr::InvariantReport r = smr::check_tiling(db, e.triangles);
    if (!r.ok()) smr::throw_internal("output does not tile the domain: " + r.summary());
  } else if (verify) {
    const smr::SurfaceReport r = smr::check_surface(db, e.triangles);
    if (!r.report.ok())
      smr::throw_internal("output is not a manifold surface: " + r.report.summary());
  }
  const smr::TriangleMesh mesh = smr::to_mesh(db, e.triangles);
  const smr::DatabaseStats st = db.stats();
  report["io"] = {{"pages_read", st.pages_read},
                  {"page_bytes_read", st.page_bytes_read},
                  {"rtree_nodes_read", st.rtree_nodes_read},
                  {"lmdb_bytes_read", st.lmdb_bytes_read},
                  {"cache_hits", st.cache.hits},
                  {"cache_misses", st.cache.misses},
                  {"cache_evictions", st.cache.evictions},
                  {"cache_peak_bytes", st.cache.peak_held_bytes},
                  {"bytes_decoded", st.cache.bytes_decoded}};
  smr::write_mesh(a.out, mesh);
  report["output"] = {
      {"path", a.out}, {"vertices", mesh.positions.size()}, {"triangles", mesh.triangles.size()}};
  if (!a.png.empty()) {
    smr::RenderOptions ro;
    ro.geographic = db.info().georef.geographic;
    smr::render_png(a.png, mesh, ro);
    report["output"]["png"] = a.png;
  }
  return report;
}

void print_report(const nlohmann::json& report, bool json) {
  if (json) std::cout << report.dump(2) << "\n";
}

// Checks where a database will be written before the long build (DatabaseWriter checks again).
void check_database_path(const std::string& path, bool force) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) throw_input(path + ": is a directory");
  if (std::filesystem::exists(path, ec) && !force)
    throw_input(path + ": exists; pass --force to replace it");
  const std::filesystem::path parent = std::filesystem::path(path).parent_path();
  if (!parent.empty() && !std::filesystem::is_directory(parent, ec))
    throw_input(path + ": no such directory " + parent.string());
}

int cmd_ingest(const IngestArgs& a, const std::string& db_path, bool json, bool quiet,
               bool verify) {
  a.validate();
  check_database_path(db_path, a.force);
  nlohmann::json r = ingest(a, db_path, quiet, verify);
  r["peak_rss_mb"] = peak_rss_mb();
  if (a.memory_bytes() != 0) r["memory_budget_mb"] = double(a.memory_bytes()) / double(1 << 20);
  print_report(r, json);
  if (!json && !quiet) {
    std::fprintf(stderr, "%s: %llu ops in %llu pages, %.1f MB (%.1f bytes/vertex) -> %s\n",
                 a.dem.c_str(),
                 static_cast<unsigned long long>(r["crmr"]["ops"].get<std::uint64_t>()),
                 static_cast<unsigned long long>(r["database"]["pages"].get<std::uint64_t>()),
                 double(r["database"]["file_bytes"].get<std::uint64_t>()) / 1e6,
                 r["database"]["bytes_per_vertex"].get<double>(), db_path.c_str());
  }
  return 0;
}

int cmd_extract(const std::string& db_path, const RcfOptions& rcf_options, const ExtractArgs& a,
                bool json, bool quiet, bool verify) {
  a.validate();
  const smr::RcfSpec spec = rcf_options.spec();
  std::optional<smr::Heightfield> dem;
  if (!a.dem.empty()) dem = smr::read_dem(a.dem);
  const auto db = smr::Database::open(db_path, {std::size_t(a.cache_mb) << 20});
  const nlohmann::json r = extract(*db, dem ? &*dem : nullptr, spec, a, verify);
  print_report(r, json);
  if (!json && !quiet) {
    std::fprintf(
        stderr, "%s: %llu output triangles (|X| = %llu, %llu pages read) -> %s\n", db_path.c_str(),
        static_cast<unsigned long long>(r["output"]["triangles"].get<std::uint64_t>()),
        static_cast<unsigned long long>(r["extraction"]["x"].get<std::uint64_t>()),
        static_cast<unsigned long long>(r["io"]["pages_read"].get<std::uint64_t>()), a.out.c_str());
  }
  return 0;
}

int cmd_build(IngestArgs a, std::string db_path, const RcfOptions& rcf_options,
              const ExtractArgs& e, bool json, bool quiet, bool verify) {
  a.validate();
  e.validate();
  const smr::RcfSpec spec = rcf_options.spec();
  std::optional<std::filesystem::path> scratch;
  if (db_path.empty()) {
    // No --db: a scratch database next to the output, removed afterwards.
    scratch = std::filesystem::path(e.out).concat(".smrdb-scratch");
    db_path = scratch->string();
    a.force = true;
  }
  check_database_path(db_path, a.force);
  struct Remove {
    std::optional<std::filesystem::path>& p;
    ~Remove() {
      std::error_code ec;
      if (p) std::filesystem::remove(*p, ec);
    }
  } remove{scratch};
  nlohmann::json r = ingest(a, db_path, quiet, verify);
  std::optional<smr::Heightfield> dem;
  if (!a.is_mesh()) dem = smr::read_dem(a.dem);
  const auto db = smr::Database::open(db_path, {std::size_t(e.cache_mb) << 20});
  r.update(extract(*db, dem ? &*dem : nullptr, spec, e, verify));
  print_report(r, json);
  if (!json && !quiet) {
    std::fprintf(stderr, "%s: %llu ops, %llu output triangles (|X| = %llu) -> %s\n", a.dem.c_str(),
                 static_cast<unsigned long long>(r["crmr"]["ops"].get<std::uint64_t>()),
                 static_cast<unsigned long long>(r["output"]["triangles"].get<std::uint64_t>()),
                 static_cast<unsigned long long>(r["extraction"]["x"].get<std::uint64_t>()),
                 e.out.c_str());
  }
  return 0;
}

int cmd_info(const std::string& db_path, bool json) {
  const auto db = smr::Database::open(db_path, {std::size_t{16} << 20});
  nlohmann::json meta = nlohmann::json::parse(db->meta_json());
  const std::uint64_t max_depth = meta["counts"]["dag_depth"].get<std::uint64_t>();
  const std::uint64_t vertices = meta["model"]["vertex_count"].get<std::uint64_t>();
  nlohmann::json out = {
      {"path", db_path},
      {"file_bytes", db->file_bytes()},
      {"bytes_per_vertex", double(db->file_bytes()) / double(std::max<std::uint64_t>(1, vertices))},
      {"dag_depth", max_depth},
      {"rtree_height", db->rtree().height()},
      {"meta", meta}};
  if (json) {
    std::cout << out.dump(2) << "\n";
    return 0;
  }
  const auto& m = meta["model"];
  std::printf("database        %s (format %d, %s pages, checksum %s)\n", db_path.c_str(),
              meta["version"].get<int>(), meta["codec"].get<std::string>().c_str(),
              meta["checksum"].get<std::string>().c_str());
  if (m["kind"].get<std::string>() == "terrain") {
    std::printf("source          %s (%dx%d samples)\n", m["source"].get<std::string>().c_str(),
                m["grid_width"].get<int>(), m["grid_height"].get<int>());
  } else {
    std::printf("source          %s (3-D mesh)\n", m["source"].get<std::string>().c_str());
  }
  std::printf("builder         %s\n", m["builder"].get<std::string>().c_str());
  std::printf("ops             %llu (DAG depth %llu), %llu triangles, %llu vertices\n",
              static_cast<unsigned long long>(meta["counts"]["ops"].get<std::uint64_t>()),
              static_cast<unsigned long long>(max_depth),
              static_cast<unsigned long long>(meta["counts"]["triangles"].get<std::uint64_t>()),
              static_cast<unsigned long long>(vertices));
  std::printf("pages           %llu data pages, R-tree of %llu nodes (height %d)\n",
              static_cast<unsigned long long>(meta["counts"]["pages"].get<std::uint64_t>()),
              static_cast<unsigned long long>(meta["counts"]["rtree_nodes"].get<std::uint64_t>()),
              db->rtree().height());
  std::printf(
      "size            %.3f MB, %.2f bytes/vertex (pages %.3f MB, locators %.3f MB, R-tree %.3f "
      "MB)\n",
      double(db->file_bytes()) / 1e6, out["bytes_per_vertex"].get<double>(),
      double(meta["bytes"]["pages"].get<std::uint64_t>()) / 1e6,
      double(meta["bytes"]["nodes"].get<std::uint64_t>()) / 1e6,
      double(meta["bytes"]["rtree"].get<std::uint64_t>()) / 1e6);
  std::printf("error           err0 %g, err_final %g (includes the z quantization shift %g)\n",
              m["err0"].get<double>(), m["err_final"].get<double>(), meta["z_shift"].get<double>());
  std::printf("quantization    origin %s, step %s\n", meta["grid"]["origin"].dump().c_str(),
              meta["grid"]["step"].dump().c_str());
  std::printf("parameters      %s\n", meta["parameters"].get<std::string>().c_str());
  return 0;
}

int cmd_verify(const std::string& db_path, bool json, bool quiet) {
  if (!std::filesystem::exists(db_path)) throw_input(db_path + ": no such file");
  smr::tools::GdalProgress progress(quiet || json ? nullptr : stderr);
  const smr::VerifyReport r = smr::verify_database(db_path, [&](double f) { progress.update(f); });
  progress.done();
  if (json) {
    std::cout << nlohmann::json{{"path", db_path},  {"ok", r.ok()}, {"faults", r.faults},
                                {"pages", r.pages}, {"ops", r.ops}, {"triangles", r.triangles}}
                     .dump(2)
              << "\n";
  }
  for (const std::string& f : r.faults) std::fprintf(stderr, "smrdb: verify: %s\n", f.c_str());
  if (!json && !quiet)
    std::fprintf(stderr, "%s: %s (%llu pages, %llu ops, %llu triangles)\n", db_path.c_str(),
                 r.ok() ? "ok" : "FAULTY", static_cast<unsigned long long>(r.pages),
                 static_cast<unsigned long long>(r.ops),
                 static_cast<unsigned long long>(r.triangles));
  return r.ok() ? 0 : 1;
}

int cmd_synth(int width, int height, std::uint64_t seed, double range, double spacing,
              const std::string& out, bool quiet) {
  if (width < 2 || height < 2 || width > 65536 || height > 65536) {
    throw_input("--size/--height must be in [2, 65536], got " + std::to_string(width) + "x" +
                std::to_string(height));
  }
  if (!(range > 0.0) || !std::isfinite(range))
    throw_input("--range must be a positive height range");
  if (!(spacing > 0.0) || !std::isfinite(spacing)) throw_input("--spacing must be positive");
  const std::string ext = extension_of(out);
  if (ext != ".tif" && ext != ".tiff" && ext != ".npy")
    throw_input("-o " + out + ": must end in .tif or .npy");
  smr::Heightfield h = smr::make_fbm(width, height, seed, range, 0, 0.5, spacing);
  if (ext == ".npy") {
    smr::write_npy(out, h);
  } else {
    smr::write_geotiff(out, h);
  }
  if (!quiet)
    std::fprintf(stderr, "%s: %dx%d fBm, seed %llu, range %g\n", out.c_str(), width, height,
                 static_cast<unsigned long long>(seed), range);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
#if defined(__GLIBC__)
  // Blocks of 128 KiB and more come straight from mmap and go back to the system when freed.
  // glibc otherwise raises this threshold after the first such free, and the large buffers an
  // extraction grows and frees (output, hash tables) then stay in the heap: a whole-database
  // extraction of 1.2 M triangles peaked at 264 MiB, 232 MiB with the threshold fixed.
  mallopt(M_MMAP_THRESHOLD, 128 * 1024);
#endif
  CLI::App app{"smrdb: selective mesh refinement database for terrains and 3-D meshes"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "smrdb 0.1.0");

  bool json = false, quiet = false, verify = false;
  RcfOptions rcf;
  IngestArgs ingest_args;
  ExtractArgs extract_args;
  std::string db_path;

  CLI::App* ingest_cmd = app.add_subcommand(
      "ingest", "Build a CRMR from a DEM or a 3-D mesh and store it as an on-disk LOD database");
  ingest_args.add_to(*ingest_cmd);
  ingest_cmd->add_option("-o,--output", db_path, "Database file to create")->required();
  ingest_cmd->add_flag("--json", json, "Print statistics as JSON on stdout");
  ingest_cmd->add_flag("-q,--quiet", quiet, "No progress or summary on stderr");
  ingest_cmd->add_flag("--verify", verify,
                       "Check the CRMR invariants before writing (slow); --builder blocks, which "
                       "never holds the CRMR, checks the written database instead");

  CLI::App* extract_cmd = app.add_subcommand(
      "extract", "Extract a selectively refined mesh for an RCF from a database");
  extract_cmd->add_option("db", db_path, "Database file")->required();
  extract_args.add_to(*extract_cmd, true);
  extract_cmd->add_flag("--json", json, "Print statistics as JSON on stdout");
  extract_cmd->add_flag("-q,--quiet", quiet, "No summary on stderr");
  extract_cmd->add_flag("--verify", verify, "Check that the output tiles the domain (slow)");
  rcf.add_to(*extract_cmd);

  CLI::App* info_cmd = app.add_subcommand("info", "Describe a database");
  info_cmd->add_option("db", db_path, "Database file")->required();
  info_cmd->add_flag("--json", json, "Print as JSON");

  CLI::App* verify_cmd = app.add_subcommand(
      "verify", "Check every checksum, the DAG and the index of a database (exit 1 on a fault)");
  verify_cmd->add_option("db", db_path, "Database file")->required();
  verify_cmd->add_flag("--json", json, "Print the result as JSON");
  verify_cmd->add_flag("-q,--quiet", quiet, "No progress or summary on stderr");

  CLI::App* build = app.add_subcommand("build",
                                       "Ingest a DEM or a 3-D mesh and extract a mesh from the "
                                       "database in one go (ingest + extract)");
  ingest_args.add_to(*build);
  extract_args.add_to(*build, false);
  build->add_option("--db", db_path, "Keep the database at this path (default: a scratch file)");
  build->add_flag("--json", json, "Print statistics as JSON on stdout");
  build->add_flag("-q,--quiet", quiet, "No progress or summary on stderr");
  build->add_flag("--verify", verify, "Check the CRMR invariants and the output tiling (slow)");
  rcf.add_to(*build);

  int width = 1025, height = 0;
  std::uint64_t seed = 1;
  double range = 1600.0, spacing = 1.0;
  std::string synth_out;
  CLI::App* synth =
      app.add_subcommand("synth", "Write a deterministic fractional Brownian motion DEM");
  synth->add_option("--size", width, "Width in samples")->capture_default_str();
  synth->add_option("--height", height, "Height in samples (default: = size)");
  synth->add_option("--seed", seed, "Random seed")->capture_default_str();
  synth->add_option("--range", range, "Height range (max - min)")->capture_default_str();
  synth->add_option("--spacing", spacing, "Sample spacing")->capture_default_str();
  synth->add_option("-o,--output", synth_out, "Output DEM (.tif or .npy)")->required();
  synth->add_flag("-q,--quiet", quiet, "No summary on stderr");

  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    if (app.get_subcommands().empty() && argc > 1 && argv[1][0] != '-') {
      std::fprintf(stderr,
                   "smrdb: error: unknown subcommand '%s' (ingest, extract, info, verify, build, "
                   "synth; --help lists them)\n",
                   argv[1]);
      return 1;
    }
    app.exit(e);
    return 1;
  }
  try {
    if (*ingest_cmd) return cmd_ingest(ingest_args, db_path, json, quiet, verify);
    if (*extract_cmd) return cmd_extract(db_path, rcf, extract_args, json, quiet, verify);
    if (*info_cmd) return cmd_info(db_path, json);
    if (*verify_cmd) return cmd_verify(db_path, json, quiet);
    if (*build) return cmd_build(ingest_args, db_path, rcf, extract_args, json, quiet, verify);
    if (*synth)
      return cmd_synth(width, height == 0 ? width : height, seed, range, spacing, synth_out, quiet);
  } catch (const smr::Error& e) {
    std::fprintf(stderr, "smrdb: error: %s\n", e.what());
    return e.exit_code();
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "smrdb: error: out of memory\n");
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "smrdb: internal error: %s\n", e.what());
    return 2;
  }
  return 0;
}
