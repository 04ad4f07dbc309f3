// smrdb's subcommands: each one's flags (a struct that adds them to its CLI11 subcommand and
// checks what was typed) and its entry point. main.cpp parses and dispatches; the commands call
// the library (smr/ingest, smr/extract, smr/db), print progress and summaries on stderr and, with
// --json, their report on stdout (report_json.h). Errors arrive at main() as smr::Error.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "smr/db/database.h"
#include "smr/ingest/ingest.h"
#include "smr/io/gltf_writer.h"
#include "smr/rcf/spec.h"

namespace CLI {
class App;
}

namespace smr::tools {

/// The flags every command shares.
struct CommonFlags {
  bool json = false;    // the report as JSON on stdout
  bool quiet = false;   // no progress or summary on stderr
  bool verify = false;  // check invariants (slow)
};

/// `ingest` and `build`: what to read and how to build and store it (smr::IngestOptions).
struct IngestArgs {
  std::string input;  // a DEM or a mesh
  double max_error = 0.0;
  std::uint64_t max_vertices = 0, base_vertices = 4;
  std::string codec = "zstd";
  double z_quantum = 0.0;
  std::uint32_t page_kb = 12;
  bool force = false;
  bool repair = false;
  bool allow_self_intersections = false;
  std::uint32_t coalesce = 32;
  double coalesce_ratio = 0.7;
  std::string builder;  // as typed; empty: blocks with --memory, else greedy
  int block_cells = 256;
  std::string tmp_dir;
  std::string memory;  // --memory as typed
  unsigned threads = 0;

  bool is_mesh() const;
  std::string effective_builder() const;
  std::uint64_t memory_bytes() const;  // --memory parsed (0 = none)
  void add_to(CLI::App& app);
  /// Checks everything the user typed before any long work.
  void validate() const;
  IngestOptions options(bool verify) const;
};

/// `extract` and `build`: the output and how to extract it.
struct ExtractArgs {
  std::string algorithm = "minimal", out, png, dem;
  // "fronts" or "pages" (ExpansionOptions::fronts); empty: fronts, or the level cut for a constant
  // level alone (smr/query/level_cut.h)
  std::string order;
  std::string compress;  // glTF outputs: "draco" or "meshopt" (empty: none)
  // --algorithm selective: "truly-selective" or "hoppe97" (SplitScheme; empty: truly-selective)
  std::string split_scheme;
  // --algorithm selective: what selects a vertex: "rcf" (empty), "vertex" or "vdpm"
  std::string selective_criterion;
  std::uint64_t cache_mb = 64;
  std::uint64_t held_mb = 512;      // ExpansionOptions::max_held_bytes, in MiB
  std::uint64_t max_triangles = 0;  // SessionBudget (smr/extract/session.h); 0 = none
  double max_ms = 0.0;

  void add_to(CLI::App& app, bool with_budgets);
  void validate() const;
};

/// The refinement condition (an RcfSpec, smr/rcf/spec.h) as flags.
struct RcfOptions {
  std::string eye, target, up, viewport = "1024x768", screen_aoi, centre_cone;
  double fov = 60.0, near = 0.0, far = 0.0;
  std::optional<double> pixel_error, floor, frustum_level, critical_level;
  double critical_relief = 0.0;
  std::vector<std::string> aois, discs, volumes, balls;
  bool no_cull = false;

  void add_to(CLI::App& app);
  RcfSpec spec() const;
};

/// `flythrough`: a camera path replayed through a geomorphing session (flythrough_cmd.cpp).
struct FlythroughArgs {
  std::string path, line, viewport = "1024x768", png_dir;
  bool orbit = false, keyframes = false, settle = false, no_cull = false, no_morph = false;
  bool compare_fresh = false;
  std::uint64_t frames = 0;  // 0: as many as the path lasts at the speed
  double fps = 60.0;
  std::optional<double> speed;  // model units per second
  double pitch = 20.0;          // --line: degrees below the horizon
  double max_period_ms = 0.0, pixel_error = 1.0, fov = 60.0;
  std::uint64_t cache_mb = 64, png_every = 1;

  void add_to(CLI::App& app);
  void validate() const;
};

/// `query`: a GIS query (smr/query) of one kind (query_cmd.cpp).
struct QueryArgs {
  std::vector<std::string> args;  // the kind's positional arguments (points, a window...)
  std::string input, out;
  std::optional<double> max_error;
  std::string levels;  // contours: --levels as typed
  std::optional<double> interval;
  double base = 0.0;
  std::uint64_t cache_mb = 64;
  bool json = false, quiet = false, clip = false;

  /// Adds a subcommand per kind to `query`.
  void add_to(CLI::App& query);
  void add_common(CLI::App& app);
};

/// `tiles`: a static quantized-mesh pyramid (tiles_cmd.cpp, smr/tiles/pyramid.h).
struct TilesArgs {
  std::string out;
  std::optional<int> max_zoom;  // absent: the scheme's default
  std::uint64_t cache_mb = 64;
  bool force = false;

  void add_to(CLI::App& app);
};

/// `serve`: databases over HTTP (serve_cmd.cpp, tools/serve/, docs/serve.md).
struct ServeArgs {
  std::vector<std::string> databases;  // NAME=PATH or PATH
  int port = 8080;
  std::string bind = "127.0.0.1";
  unsigned threads = 8;
  std::size_t queue = 64;
  std::size_t max_connections = 1024;
  std::uint64_t cache_mb = 256;
  std::size_t max_sessions = 64;
  int session_idle_s = 60;
  std::uint64_t max_triangles = 2'000'000;
  std::uint64_t tile_cache_mb = 64;
  int timeout_ms = 10'000;
  std::string viewer;  // empty: the source tree's built viewer, if any
  bool log = false;

  void add_to(CLI::App& app);
};

struct SynthArgs {
  int width = 1025, height = 0;  // height 0: = width
  std::uint64_t seed = 1;
  double range = 1600.0, spacing = 1.0;
  std::string out;

  void add_to(CLI::App& app);
};

/// Ingests a.input into db_path, drawing the progress bar unless quiet; returns the report.
nlohmann::json run_ingest(const IngestArgs& a, const std::string& db_path, bool quiet, bool verify);
/// The glTF writer's options for meshes of `db`: its grid, georeference and frame (the centre of
/// its bounds), `compress` ("" or a name parse_gltf_compression knows), `extras` added to
/// asset.extras.smrdb with the database's path and kind.
GltfOptions gltf_options(const Database& db, const std::string& compress,
                         const nlohmann::json& extras);
/// Extracts the mesh `spec` asks of `db` into a.out (and a.png); returns the report. `dem`: the
/// source DEM, for --critical-lines (nullptr: none).
nlohmann::json run_extract(const Database& db, const Heightfield* dem, const RcfSpec& spec,
                           const ExtractArgs& a, bool verify);

/// --algorithm selective (extract_selective.cpp): Kim & Lee's truly selective refinement of
/// `db` for `rcf` into a.out (and a.png); returns the report.
nlohmann::json run_selective(const Database& db, const RcfSpec& spec, const Rcf& rcf,
                             const ExtractArgs& a);
/// Writes `mesh` to a.out (and its picture to a.png) and adds "output" to the report.
void write_output(const Database& db, const TriangleMesh& mesh, const ExtractArgs& a,
                  nlohmann::json& report);

int cmd_ingest(const IngestArgs& a, const std::string& db_path, const CommonFlags& f);
int cmd_extract(const std::string& db_path, const RcfOptions& rcf, const ExtractArgs& a,
                const CommonFlags& f);
/// Ingest, then extract; without a db_path the database is a scratch file removed afterwards.
int cmd_build(IngestArgs a, std::string db_path, const RcfOptions& rcf, const ExtractArgs& e,
              const CommonFlags& f);
int cmd_info(const std::string& db_path, bool json);
int cmd_verify(const std::string& db_path, const CommonFlags& f);
int cmd_synth(const SynthArgs& a, bool quiet);
/// `kind`: the name of the query subcommand that was given.
int cmd_query(const std::string& db_path, const std::string& kind, const QueryArgs& a);
int cmd_flythrough(const std::string& db_path, const FlythroughArgs& a, const CommonFlags& f);
int cmd_tiles(const std::string& db_path, const TilesArgs& a, const CommonFlags& f);
int cmd_serve(const ServeArgs& a);

}  // namespace smr::tools
