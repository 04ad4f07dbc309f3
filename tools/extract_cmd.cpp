// smrdb extract: the refinement condition's flags, the extraction and its report.
#include <cstdio>
#include <optional>
#include <span>
#include <tuple>
#include <utility>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "base/error.h"
#include "smr/core/clock.h"
#include "smr/core/invariants.h"
#include "smr/db/database.h"
#include "smr/extract/extract.h"
#include "smr/extract/selective.h"
#include "smr/extract/session.h"
#include "smr/io/dem_reader.h"
#include "smr/io/gltf_writer.h"
#include "smr/io/mesh_writer.h"
#include "smr/io/render.h"
#include "smr/query/indexed_source.h"
#include "smr/query/level_cut.h"
#include "tools/commands.h"
#include "tools/parse.h"
#include "tools/report_json.h"

namespace smr::tools {

namespace {

Vec3 parse_vec3(const std::string& text, const std::string& option) {
  const auto v = parse_numbers(text, 3, option, "x,y,z");
  return {v[0], v[1], v[2]};
}

AoiSpec parse_aoi(const std::string& text, const std::string& option) {
  const auto v = parse_numbers(text, 4, option, "x,y,radius,level");
  return {v[0], v[1], v[2], v[3]};
}

}  // namespace

void RcfOptions::add_to(CLI::App& app) {
  app.add_option("--eye", eye, "Camera position x,y,z (model coordinates)");
  app.add_option("--target", target, "Point the camera looks at x,y,z");
  app.add_option("--up", up, "Camera up vector x,y,z (default 0,0,1)");
  app.add_option("--fov", fov, "Vertical field of view in degrees")->capture_default_str();
  app.add_option("--viewport", viewport, "Viewport size WxH in pixels")->capture_default_str();
  app.add_option("--near", near, "Near plane distance (0 = at the eye)");
  app.add_option("--far", far, "Far plane distance (0 = none)");
  app.add_flag("--no-cull", no_cull, "Disable view-frustum and back-face culling");
  app.add_option("--pixel-error", pixel_error, "Screen-space tolerance in pixels (needs a camera)");
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

RcfSpec RcfOptions::spec() const {
  RcfSpec s;
  if (!eye.empty() || !target.empty()) {
    if (eye.empty() || target.empty()) throw_input("a camera needs both --eye and --target");
    Camera cam;
    cam.eye = parse_vec3(eye, "--eye");
    cam.target = parse_vec3(target, "--target");
    if (!up.empty()) cam.up = parse_vec3(up, "--up");
    cam.fov_y_deg = fov;
    std::tie(cam.viewport_w, cam.viewport_h) = parse_viewport(viewport, "--viewport");
    cam.near_distance = near;
    cam.far_distance = far;
    s.camera = cam;
  }
  s.cull = !no_cull;
  s.pixel_error = pixel_error;
  if (!screen_aoi.empty()) {
    const auto v = parse_numbers(screen_aoi, 4, "--screen-aoi", "u,v,radius_px,pixel_error");
    s.screen_aoi = ScreenAoi{{v[0], v[1]}, v[2], v[3]};
  }
  s.floor = floor;
  for (const auto& a : aois) s.aois.push_back(parse_aoi(a, "--aoi"));
  for (const auto& a : discs) s.discs.push_back(parse_aoi(a, "--disc"));
  for (const auto& [list, gaussian] : {std::pair{&volumes, true}, std::pair{&balls, false}}) {
    for (const auto& text : *list) {
      const auto v = parse_numbers(text, 5, gaussian ? "--volume" : "--ball", "x,y,z,radius,level");
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
  validate(s);
  return s;
}

void ExtractArgs::add_to(CLI::App& app, bool with_budgets) {
  app.add_option("--algorithm", algorithm,
                 "minimal (Brown 5.1), reduced (Brown 5.2) or selective (Kim & Lee 2001: truly "
                 "selective vertex splits; meshes ingested with --coalesce 0)")
      ->capture_default_str();
  app.add_option("--split-scheme", split_scheme,
                 "With --algorithm selective: truly-selective (Kim & Lee: a split needs nothing "
                 "of its neighbourhood; the default) or hoppe97 (Hoppe 1997: a split waits for "
                 "the four faces around its new ones, forcing their splits first)");
  app.add_option("--selective-criterion", selective_criterion,
                 "With --algorithm selective, what selects a vertex: rcf (its split op is not "
                 "completely finer than the RCF; the default), vertex (Hoppe 1997's per-vertex "
                 "tests over its dual piece: its sphere against the frustum, its normal cone "
                 "against the eye over that sphere, its split op's error at the sphere's nearest "
                 "distance against --pixel-error; a camera only) or vdpm (the same with OpenMesh "
                 "VDPM's back-face test: at the vertex, on the cone of the vertex normals below "
                 "it; not conservative)");
  app.add_option("--order", order,
                 "fronts: triangles as the advancing front emits them, in fans (Brown 5.1.2); "
                 "pages: the same triangles from the set formula, page by page (minimal only; "
                 "faster). Default: fronts, but a constant --floor alone takes the level cut "
                 "(the same triangles straight from the pages, page order)");
  app.add_option("-o,--output", out, "Output mesh (.obj, .ply, or glTF .glb/.gltf)")->required();
  app.add_option("--compress", compress,
                 "glTF output only: draco (KHR_draco_mesh_compression) or meshopt "
                 "(EXT_meshopt_compression)");
  app.add_option("--png", png, "Also write a top-down picture of the mesh (.png)");
  if (with_budgets) {
    app.add_option("--cache-mb", cache_mb, "Page cache budget in MiB")->capture_default_str();
    app.add_option("--held-mb", held_mb,
                   "Budget in MiB of the decoded pages held by ops waiting for the "
                   "expansion; beyond it, ops are read through the page cache one by one")
        ->capture_default_str();
    app.add_option("--dem", dem, "The source DEM (needed by --critical-lines)");
    app.add_option("--max-triangles", max_triangles,
                   "Refine lowest resolution first and stop before the mesh exceeds N "
                   "triangles: a valid mesh meeting the RCF capped at the resolution reported");
    app.add_option("--max-ms", max_ms,
                   "The same, stopping when the refinement has run this many milliseconds");
  }
}

void ExtractArgs::validate() const {
  if (algorithm != "minimal" && algorithm != "reduced" && algorithm != "selective")
    throw_input("--algorithm must be 'minimal', 'reduced' or 'selective', got '" + algorithm + "'");
  if (!split_scheme.empty()) SelectiveRefinement::parse_scheme(split_scheme, "--split-scheme");
  if (!split_scheme.empty() && algorithm != "selective")
    throw_input("--split-scheme needs --algorithm selective");
  if (!selective_criterion.empty() && selective_criterion != "rcf" &&
      selective_criterion != "vertex" && selective_criterion != "vdpm")
    throw_input("--selective-criterion must be 'rcf', 'vertex' or 'vdpm', got '" +
                selective_criterion + "'");
  if (!selective_criterion.empty() && algorithm != "selective")
    throw_input("--selective-criterion needs --algorithm selective");
  if (!order.empty() && order != "fronts" && order != "pages")
    throw_input("--order must be 'fronts' or 'pages', got '" + order + "'");
  if (order == "pages" && algorithm != "minimal")
    throw_input(
        "--order pages needs --algorithm minimal (reduced extraction grows X+ as its "
        "front advances)");
  const std::string ext = extension_of(out);
  if (ext != ".obj" && ext != ".ply" && ext != ".glb" && ext != ".gltf")
    throw_input("-o " + out + ": the output must end in .obj, .ply, .glb or .gltf");
  if (!compress.empty()) {
    if (ext != ".glb" && ext != ".gltf")
      throw_input("--compress " + compress + ": only glTF outputs (.glb, .gltf) are compressed, " +
                  "not " + out);
    const auto c = parse_gltf_compression(compress);
    if (!c || *c == GltfCompression::kNone)
      throw_input("--compress must be 'draco' or 'meshopt', got '" + compress + "'");
  }
  if (!png.empty() && extension_of(png) != ".png")
    throw_input("--png " + png + ": must end in .png");
  if (cache_mb < 1 || cache_mb > (std::uint64_t{1} << 20))
    throw_input("--cache-mb must be in [1, 1048576]");
  if (held_mb > (std::uint64_t{1} << 20)) throw_input("--held-mb must be in [0, 1048576]");
  if (!(max_ms >= 0.0) || max_ms > 1e9) throw_input("--max-ms must be in [0, 1e9]");
  if ((max_triangles != 0 || max_ms > 0.0) && algorithm != "minimal")
    throw_input("--max-triangles and --max-ms need --algorithm minimal");
}

GltfOptions gltf_options(const Database& db, const std::string& compress,
                         const nlohmann::json& extras) {
  const CrmrInfo& info = db.info();
  GltfOptions o;
  if (!compress.empty()) o.compression = *parse_gltf_compression(compress);
  o.grid_origin = db.grid().origin;
  o.grid_step = db.grid().step;
  o.terrain = info.kind == ModelKind::kTerrain;
  o.georef = info.georef;
  // Every extraction of one database shares its frame: the centre of its bounds (at height 0 for
  // a terrain, so that glTF y is the height).
  o.reference = (info.bounds.lo + info.bounds.hi) * 0.5;
  if (o.terrain) o.reference.z = 0.0;
  nlohmann::json x = extras;
  x["source"] = db.path();
  x["kind"] = o.terrain ? "terrain" : "mesh";
  o.extras_json = x.dump();
  return o;
}

// The mesh goes out in the format its extension names: OBJ/PLY (mesh_writer.h) or glTF
// (gltf_writer.h, on the database's grid, with its georeference and the report's RCF in
// asset.extras.smrdb).
void write_output(const Database& db, const TriangleMesh& mesh, const ExtractArgs& a,
                  nlohmann::json& report) {
  const std::string ext = extension_of(a.out);
  if (ext == ".glb" || ext == ".gltf") {
    nlohmann::json extras = nlohmann::json::object();
    if (report.contains("rcf")) extras["rcf"] = report["rcf"];
    const GltfOptions options = gltf_options(db, a.compress, extras);
    const GltfReport r = write_gltf(a.out, mesh, options);
    const Vec3& e = r.max_position_error;
    report["output"] = {{"path", a.out},
                        {"vertices", r.vertices},
                        {"triangles", r.triangles},
                        {"bytes", r.bytes},
                        {"compression", gltf_compression_name(options.compression)},
                        {"position_shift", r.shift},
                        {"max_position_error", {e.x, e.y, e.z}},
                        {"normal_bits", r.normal_bits}};
  } else {
    write_mesh(a.out, mesh);
    report["output"] = {
        {"path", a.out}, {"vertices", mesh.positions.size()}, {"triangles", mesh.triangles.size()}};
  }
  if (!a.png.empty()) {
    RenderOptions ro;
    ro.geographic = db.info().georef.geographic;
    render_png(a.png, mesh, ro);
    report["output"]["png"] = a.png;
  }
}

namespace {

// --verify: the output tiles the domain (terrain) or is a manifold surface (meshes).
void verify_output(const Database& db, std::span<const TriRef> triangles) {
  if (db.info().kind == ModelKind::kTerrain) {
    const InvariantReport r = check_tiling(db, triangles);
    if (!r.ok()) throw_internal("output does not tile the domain: " + r.summary());
  } else {
    const SurfaceReport r = check_surface(db, triangles);
    if (!r.report.ok()) throw_internal("output is not a manifold surface: " + r.report.summary());
  }
}

// --verify of a level cut: the minimal surface's set formula gives the same triangles and |X|
// (check_level_cut), and they pass verify_output.
void verify_level_cut(const Database& db, const Rcf& rcf, const TriangleMesh& mesh,
                      const LevelCutStats& cut) {
  Extraction general;
  const std::string differs = check_level_cut(db, rcf, mesh, cut, &general);
  if (!differs.empty()) throw_internal(differs);
  verify_output(db, general.triangles);
}

}  // namespace

nlohmann::json run_extract(const Database& db, const Heightfield* dem, const RcfSpec& spec,
                           const ExtractArgs& a, bool verify) {
  nlohmann::json report;
  if (spec.critical_level && dem == nullptr)
    throw_input("--critical-lines needs the source DEM: pass --dem");
  const Rcf rcf = make_rcf(spec, db.info(), dem);
  if (a.algorithm == "selective") return run_selective(db, spec, rcf, a);
  // A constant level alone (--floor): the level cut, from the pages (smr/query/level_cut.h),
  // unless the fronts' fans were asked for.
  const std::optional<double> level = constant_level(spec);
  if (level && a.algorithm == "minimal" && a.order != "fronts" && a.max_triangles == 0 &&
      a.max_ms <= 0.0) {
    LevelCutStats cut;
    const auto t0 = Clock::now();
    if (std::optional<TriangleMesh> mesh = extract_level_cut(db, *level, {}, &cut)) {
      ExtractStats stats;
      stats.extract_seconds = seconds_since(t0);
      stats.x = stats.x_plus = stats.ops_visited = cut.x;
      stats.triangles = cut.triangles;
      if (verify) verify_level_cut(db, rcf, *mesh, cut);
      report["rcf"] = rcf.describe();
      report["extraction"] = stats;
      report["extraction"]["algorithm"] = a.algorithm;
      report["extraction"]["order"] = "level cut (pages)";
      report["io"] = db.stats();
      write_output(db, *mesh, a, report);
      return report;
    }  // a void triangle: the general path
  }
  ExpansionOptions expansion;
  expansion.max_held_bytes = a.held_mb << 20;
  expansion.fronts = a.order != "pages";
  const IndexedSource source(db);  // the R-tree answers the RCF's queries
  Extraction e;
  if (a.max_triangles != 0 || a.max_ms > 0.0) {
    // Refined lowest resolution first until the budget (smr/extract/session.h); the report says
    // where it stopped and what the mesh then meets.
    const SessionBudget budget{.max_period_ms = a.max_ms, .max_triangles = a.max_triangles};
    FrameStats fs;
    e = extract_budgeted(source, rcf, budget, expansion, &fs);
    report["budget"] = fs;
    report["budget"].update({{"max_triangles", budget.max_triangles},
                             {"max_ms", budget.max_period_ms},
                             {"stop_error", source.error_at(fs.stop_resolution)},
                             {"meaning", fs.complete ? "not stopped: the mesh meets the RCF"
                                                     : "stopped: every triangle meets the RCF "
                                                       "or has error <= stop_error"}});
  } else {
    e = a.algorithm == "reduced" ? extract_reduced(source, rcf, expansion)
                                 : extract_minimal_surface(source, rcf, expansion);
  }
  report["rcf"] = rcf.describe();
  report["extraction"] = e.stats;
  report["extraction"]["algorithm"] = a.algorithm;
  report["extraction"]["order"] = expansion.fronts ? "fronts" : "pages";
  if (verify) verify_output(db, e.triangles);
  const TriangleMesh mesh = to_mesh(db, e.triangles);
  report["io"] = db.stats();
  // Neither the triangle list nor the decoded pages are needed to write the mesh: let them go
  // before the writer's buffers come (the memory bound is cache + output + a margin).
  e = Extraction{};
  db.clear_cache();
  write_output(db, mesh, a, report);
  return report;
}

int cmd_extract(const std::string& db_path, const RcfOptions& rcf, const ExtractArgs& a,
                const CommonFlags& f) {
  a.validate();
  const RcfSpec spec = rcf.spec();
  std::optional<Heightfield> dem;
  if (!a.dem.empty()) dem = read_dem(a.dem);
  const auto db = Database::open(db_path, {std::size_t(a.cache_mb) << 20});
  const nlohmann::json r = run_extract(*db, dem ? &*dem : nullptr, spec, a, f.verify);
  print_report(r, f.json);
  if (!f.json && !f.quiet) {
    std::fprintf(
        stderr, "%s: %llu output triangles (|X| = %llu, %llu pages read) -> %s\n", db_path.c_str(),
        static_cast<unsigned long long>(r["output"]["triangles"].get<std::uint64_t>()),
        static_cast<unsigned long long>(r["extraction"]["x"].get<std::uint64_t>()),
        static_cast<unsigned long long>(r["io"]["pages_read"].get<std::uint64_t>()), a.out.c_str());
    if (r.contains("budget") && !r["budget"]["complete"].get<bool>())
      std::fprintf(stderr,
                   "%s: the budget stopped the refinement: every triangle meets the RCF or has "
                   "error <= %g\n",
                   db_path.c_str(), r["budget"]["stop_error"].get<double>());
  }
  return 0;
}

}  // namespace smr::tools
