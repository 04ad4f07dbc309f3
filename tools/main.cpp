// smrdb: the command line. Parses the flags, dispatches to a subcommand (commands.h) and turns
// errors into exit codes. Nothing below tools/ prints or exits; errors arrive here as smr::Error
// (exit 1, or 2 for bugs).
#include <malloc.h>

#include <cstdio>
#include <exception>
#include <new>
#include <string>

#include <CLI/CLI.hpp>

#include "base/error.h"
#include "tools/commands.h"

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

  smr::tools::CommonFlags flags;
  smr::tools::RcfOptions rcf;
  smr::tools::IngestArgs ingest_args;
  smr::tools::ExtractArgs extract_args;
  smr::tools::SynthArgs synth_args;
  smr::tools::FlythroughArgs fly_args;
  smr::tools::QueryArgs query_args;
  smr::tools::TilesArgs tiles_args;
  smr::tools::ServeArgs serve_args;
  std::string db_path;

  CLI::App* ingest = app.add_subcommand(
      "ingest", "Build a CRMR from a DEM or a 3-D mesh and store it as an on-disk LOD database");
  ingest_args.add_to(*ingest);
  ingest->add_option("-o,--output", db_path, "Database file to create")->required();
  ingest->add_flag("--json", flags.json, "Print statistics as JSON on stdout");
  ingest->add_flag("-q,--quiet", flags.quiet, "No progress or summary on stderr");
  ingest->add_flag("--verify", flags.verify,
                   "Check the CRMR invariants before writing (slow); --builder blocks, which "
                   "never holds the CRMR, checks the written database instead");

  CLI::App* extract = app.add_subcommand(
      "extract", "Extract a selectively refined mesh for an RCF from a database");
  extract->add_option("db", db_path, "Database file")->required();
  extract_args.add_to(*extract, true);
  extract->add_flag("--json", flags.json, "Print statistics as JSON on stdout");
  extract->add_flag("-q,--quiet", flags.quiet, "No summary on stderr");
  extract->add_flag("--verify", flags.verify, "Check that the output tiles the domain (slow)");
  rcf.add_to(*extract);

  CLI::App* info = app.add_subcommand("info", "Describe a database");
  info->add_option("db", db_path, "Database file")->required();
  info->add_flag("--json", flags.json, "Print as JSON");

  CLI::App* verify = app.add_subcommand(
      "verify", "Check every checksum, the DAG and the index of a database (exit 1 on a fault)");
  verify->add_option("db", db_path, "Database file")->required();
  verify->add_flag("--json", flags.json, "Print the result as JSON");
  verify->add_flag("-q,--quiet", flags.quiet, "No progress or summary on stderr");

  CLI::App* build = app.add_subcommand("build",
                                       "Ingest a DEM or a 3-D mesh and extract a mesh from the "
                                       "database in one go (ingest + extract)");
  ingest_args.add_to(*build);
  extract_args.add_to(*build, false);
  build->add_option("--db", db_path, "Keep the database at this path (default: a scratch file)");
  build->add_flag("--json", flags.json, "Print statistics as JSON on stdout");
  build->add_flag("-q,--quiet", flags.quiet, "No progress or summary on stderr");
  build->add_flag("--verify", flags.verify,
                  "Check the CRMR invariants and the output tiling (slow)");
  rcf.add_to(*build);

  CLI::App* synth =
      app.add_subcommand("synth", "Write a deterministic fractional Brownian motion DEM");
  synth_args.add_to(*synth);
  synth->add_flag("-q,--quiet", flags.quiet, "No summary on stderr");

  CLI::App* fly = app.add_subcommand(
      "flythrough",
      "Replay a camera path through a geomorphing session (Brown ch. 6): per-frame statistics");
  fly->add_option("db", db_path, "Database file")->required();
  fly_args.add_to(*fly);
  fly->add_flag("--json", flags.json, "Print the per-frame report as JSON on stdout");
  fly->add_flag("-q,--quiet", flags.quiet, "No progress or summary on stderr");
  fly->add_flag("--verify", flags.verify,
                "With --compare-fresh: compare the triangle sets, not only their counts");

  CLI::App* query = app.add_subcommand(
      "query",
      "Ask a terrain database for elevations, a window, profiles, line of sight or "
      "contours, each answer with its error bound (Maheshwari et al. 3-4)");
  query->add_option("db", db_path, "Database file")->required();
  query_args.add_to(*query);

  CLI::App* tiles = app.add_subcommand(
      "tiles", "Write a static quantized-mesh-1.0 terrain tile pyramid and its layer.json");
  tiles->add_option("db", db_path, "Database file (a terrain)")->required();
  tiles_args.add_to(*tiles);
  tiles->add_flag("--json", flags.json, "Print statistics as JSON on stdout");
  tiles->add_flag("-q,--quiet", flags.quiet, "No progress or summary on stderr");

  CLI::App* serve = app.add_subcommand(
      "serve", "Serve databases over HTTP: extraction, tiles, queries, progressive sessions");
  serve_args.add_to(*serve);

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
                   "synth, flythrough, query, tiles, serve; --help lists them)\n",
                   argv[1]);
      return 1;
    }
    app.exit(e);
    return 1;
  }
  try {
    using namespace smr::tools;
    if (*ingest) return cmd_ingest(ingest_args, db_path, flags);
    if (*extract) return cmd_extract(db_path, rcf, extract_args, flags);
    if (*info) return cmd_info(db_path, flags.json);
    if (*verify) return cmd_verify(db_path, flags);
    if (*build) return cmd_build(ingest_args, db_path, rcf, extract_args, flags);
    if (*synth) return cmd_synth(synth_args, flags.quiet);
    if (*fly) return cmd_flythrough(db_path, fly_args, flags);
    if (*query) return cmd_query(db_path, query->get_subcommands().at(0)->get_name(), query_args);
    if (*tiles) return cmd_tiles(db_path, tiles_args, flags);
    if (*serve) return cmd_serve(serve_args);
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
