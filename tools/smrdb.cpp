// smrdb: the command line. Parses options, reports progress on stderr, prints JSON on request.
// Nothing below tools/ prints or exits; errors arrive here as smr::Error (exit 1, or 2 for bugs).
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "smr/build/greedy_tin.h"
#include "smr/core/invariants.h"
#include "smr/extract/extract.h"
#include "smr/io/dem_reader.h"
#include "smr/io/mesh_writer.h"
#include "smr/io/render.h"
#include "smr/io/synthetic.h"
#include "smr/rcf/spec.h"
#include "storage/error.h"
#include "tools/progress.h"

namespace {

using smr::throw_input;
using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
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
  std::vector<std::string> aois, discs;
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
          {"extract_seconds", s.extract_seconds},
          {"expand_seconds", s.expand_seconds}};
}

std::string extension_of(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

int cmd_build(const std::string& dem_path, double max_error, std::uint64_t max_vertices,
              std::uint64_t base_vertices, const RcfOptions& rcf_options,
              const std::string& algorithm, const std::string& out, const std::string& png,
              bool json, bool quiet, bool verify) {
  // Check everything the user typed before any long work.
  if (!(max_error >= 0.0) || !std::isfinite(max_error))
    throw_input("--max-error must be >= 0 (data units)");
  if (base_vertices < 4) throw_input("--base-vertices must be at least 4 (the corners)");
  if (algorithm != "minimal" && algorithm != "reduced") {
    throw_input("--algorithm must be 'minimal' or 'reduced', got '" + algorithm + "'");
  }
  const std::string ext = extension_of(out);
  if (ext != ".obj" && ext != ".ply")
    throw_input("-o " + out + ": the output must end in .obj or .ply");
  if (!png.empty() && extension_of(png) != ".png")
    throw_input("--png " + png + ": must end in .png");
  const smr::RcfSpec spec = rcf_options.spec();

  nlohmann::json report;
  auto t0 = Clock::now();
  const smr::Heightfield dem = smr::read_dem(dem_path);
  report["input"] = {{"path", dem_path},
                     {"width", dem.width},
                     {"height", dem.height},
                     {"samples", dem.sample_count()},
                     {"nodata", dem.has_nodata()},
                     {"geographic", dem.georef.geographic},
                     {"read_seconds", seconds_since(t0)}};

  smr::tools::GdalProgress progress(quiet ? nullptr : stderr);
  smr::GreedyTinOptions opt;
  opt.max_error = max_error;
  opt.max_vertices = max_vertices;
  opt.base_vertices = base_vertices;
  opt.progress = [&](double f) { progress.update(f); };
  t0 = Clock::now();
  const smr::Crmr crmr = smr::build_greedy_tin(dem, opt);
  progress.done();
  std::uint64_t finest = 0;
  for (const smr::Op& op : crmr.ops) {
    for (const auto& t : op.fragment) finest += !t.killer.valid() && !t.is_void();
  }
  report["crmr"] = {{"ops", crmr.ops.size()},
                    {"fragment_triangles", crmr.triangle_count()},
                    {"vertices", crmr.header.vertex_count},
                    {"finest_triangles", finest},
                    {"base_triangles", crmr.ops[0].fragment.size()},
                    {"err0", crmr.header.err0},
                    {"err_final", crmr.header.err_final},
                    {"build_seconds", seconds_since(t0)}};

  if (verify) {
    const smr::InvariantReport r = smr::check_crmr(crmr);
    if (!r.ok()) smr::throw_internal("CRMR invariants violated: " + r.summary());
  }

  const smr::Rcf rcf = smr::make_rcf(spec, smr::ModelKind::kTerrain, &dem);
  const smr::Extraction e = algorithm == "reduced" ? smr::extract_reduced(crmr, rcf)
                                                   : smr::extract_minimal_surface(crmr, rcf);
  report["rcf"] = rcf.describe();
  report["extraction"] = stats_json(e.stats);
  report["extraction"]["algorithm"] = algorithm;
  if (verify) {
    const smr::InvariantReport r = smr::check_tiling(crmr, e.triangles);
    if (!r.ok()) smr::throw_internal("output does not tile the domain: " + r.summary());
  }

  const smr::TriangleMesh mesh = smr::to_mesh(crmr, e.triangles);
  smr::write_mesh(out, mesh);
  report["output"] = {
      {"path", out}, {"vertices", mesh.positions.size()}, {"triangles", mesh.triangles.size()}};
  if (!png.empty()) {
    smr::RenderOptions ro;
    ro.geographic = dem.georef.geographic;
    smr::render_png(png, mesh, ro);
    report["output"]["png"] = png;
  }
  if (json) {
    std::cout << report.dump(2) << "\n";
  } else if (!quiet) {
    std::fprintf(stderr, "%s: %llu ops, %llu output triangles (|X| = %llu) -> %s\n",
                 dem_path.c_str(), static_cast<unsigned long long>(crmr.ops.size()),
                 static_cast<unsigned long long>(mesh.triangles.size()),
                 static_cast<unsigned long long>(e.stats.x), out.c_str());
  }
  return 0;
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
  CLI::App app{"smrdb: selective mesh refinement database for terrains"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "smrdb 0.1.0");

  std::string dem, out, png, algorithm = "minimal";
  double max_error = 0.0;
  std::uint64_t max_vertices = 0, base_vertices = 4;
  bool json = false, quiet = false, verify = false;
  RcfOptions rcf;
  CLI::App* build = app.add_subcommand(
      "build",
      "Build a CRMR from a DEM in memory and extract a selectively refined mesh for an RCF");
  build->add_option("dem", dem, "DEM: GeoTIFF or any GDAL raster (one band), .npy or .npz")
      ->required();
  build
      ->add_option("--max-error", max_error,
                   "Stop refining at this vertical error (data units; 0 = lossless)")
      ->capture_default_str();
  build->add_option("--max-vertices", max_vertices, "Stop at this many vertices (0 = no limit)");
  build->add_option("--base-vertices", base_vertices, "Vertices of the base mesh (4 = the corners)")
      ->capture_default_str();
  build->add_option("--algorithm", algorithm, "minimal (Brown 5.1) or reduced (Brown 5.2)")
      ->capture_default_str();
  build->add_option("-o,--output", out, "Output mesh (.obj or .ply)")->required();
  build->add_option("--png", png, "Also write a top-down picture of the mesh (.png)");
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
    app.exit(e);
    return 1;
  }
  try {
    if (*build) {
      return cmd_build(dem, max_error, max_vertices, base_vertices, rcf, algorithm, out, png, json,
                       quiet, verify);
    }
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
