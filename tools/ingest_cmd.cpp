// smrdb ingest and smrdb build: the flags, their checks, and the report of smr::ingest().
#include <malloc.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <optional>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "base/error.h"
#include "smr/db/database.h"
#include "smr/io/dem_reader.h"
#include "smr/io/mesh_reader.h"
#include "tools/commands.h"
#include "tools/parse.h"
#include "tools/progress.h"
#include "tools/report_json.h"
#include "tools/rss.h"

namespace smr::tools {

bool IngestArgs::is_mesh() const {
  return is_mesh_path(input);
}

std::string IngestArgs::effective_builder() const {
  return !builder.empty() ? builder : !memory.empty() ? "blocks" : "greedy";
}

std::uint64_t IngestArgs::memory_bytes() const {
  return memory.empty() ? 0 : parse_bytes(memory, "--memory");
}

void IngestArgs::add_to(CLI::App& app) {
  app.add_option("input", input,
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
                 "--builder blocks: memory budget (e.g. 256M, 2G; at least 32M), divided among "
                 "the writer, the external sorts and, for DEMs, the raster cache and the windows "
                 "held for exact error bounds; peak RSS is reported by --json");
  app.add_option("--block-cells", block_cells,
                 "DEMs, --builder blocks: side of a leaf block in grid cells (a power of two)")
      ->capture_default_str();
  app.add_option("--tmp", tmp_dir,
                 "--builder blocks: directory for scratch files (the samples' copy, sort runs, "
                 "the ops' spool; default: the system's temporary directory)");
  app.add_option(
         "--threads", threads,
         "--builder blocks (and --memory): threads reading, building and writing blocks; meshes "
         "built in memory: threads computing error bounds ahead (0 = one per core; the database "
         "is the same whatever the number)")
      ->capture_default_str();
  app.add_option("--codec", codec, "Geometry codec of the pages: draco, zstd or raw")
      ->capture_default_str();
  app.add_option(
      "--z-quantum", z_quantum,
      "Height quantization step (data units; 0 = automatic: a power of two, the coarser of "
      "range / 2^24 and --max-error / 32, the DEM then built to --max-error less half a "
      "step)");
  app.add_option("--page-kb", page_kb, "Target size of a data page in KiB")->capture_default_str();
  app.add_flag("--force", force, "Replace an existing database");
}
void IngestArgs::validate() const {
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

IngestOptions IngestArgs::options(bool verify) const {
  IngestOptions o;
  o.builder = builder.empty()       ? IngestBuilder::kAuto
              : builder == "blocks" ? IngestBuilder::kBlocks
                                    : IngestBuilder::kInCore;
  o.max_error = max_error;
  o.max_vertices = max_vertices;
  o.base_vertices = base_vertices;
  o.repair = repair;
  o.allow_self_intersections = allow_self_intersections;
  o.coalesce = coalesce;
  o.coalesce_ratio = coalesce_ratio;
  o.block_cells = block_cells;
  o.memory.total_bytes = memory_bytes();
  o.tmp_dir = tmp_dir;
  o.threads = threads;
  o.codec = *storage::parse_codec(codec);
  o.z_quantum = z_quantum;
  o.page_kb = page_kb;
  o.force = force;
  o.verify = verify;
  return o;
}

namespace {

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

bool streamed(IngestPath path) {
  return path == IngestPath::kBlockTin || path == IngestPath::kBlockPm;
}

}  // namespace

nlohmann::json run_ingest(const IngestArgs& a, const std::string& db_path, bool quiet,
                          bool verify) {
  const IngestOptions options = a.options(verify);
  ProgressBar bar(quiet ? nullptr : stderr);
  // The block builders' writer finishes once the builder has freed its records: its own peak
  // resident set is measured apart (< 0: not measured).
  bool phase_rss = false;
  double finish_rss = -1.0, build_rss = -1.0;
  IngestProgress progress;
  progress.fraction = [&](double f) { bar.update(f); };
  progress.phase = [&](IngestPhase phase, const IngestReport& r) {
    if (phase == IngestPhase::kBuilt) {
      if (r.records_over_budget) {
        const BlockTinStats& st = std::get<BlockTinReport>(r.build).stats;
        std::fprintf(stderr,
                     "smrdb: warning: the block builder's records took %.0f MiB (%llu triangles "
                     "made at --max-error %g), more than half of --memory %s: they are not paged "
                     "out yet; a larger --max-error makes fewer\n",
                     double(st.record_bytes) / double(1 << 20),
                     static_cast<unsigned long long>(st.triangles_made), a.max_error,
                     a.memory.c_str());
      }
      if (streamed(r.path())) {
        build_rss = peak_rss_mb();  // reading and building, before the writer's finish()
        phase_rss = reset_peak_rss();
      }
    } else {
      if (phase_rss) finish_rss = phase_peak_rss_mb();
      bar.done();
    }
  };
  const IngestReport r = ingest(a.input, db_path, options, progress);
  nlohmann::json report = ingest_json(r, a.input, db_path, options);
  if (finish_rss >= 0.0) report["database"]["finish_peak_rss_mb"] = finish_rss;
  if (build_rss >= 0.0) report["build_peak_rss_mb"] = build_rss;
  return report;
}

namespace {

// The heap for a build: main() hands blocks of 128 KiB and more to mmap and glibc gives the top
// of the heap back past 128 KiB free, right for an extraction's bound (main.cpp), but a build
// allocates and frees its tables many times over, and each time the kernel zeroed their pages
// again: page faults were 6-7 % of a mesh ingest's cycles. With a budget of 1 GiB or more (or
// none: an in-memory build), glibc keeps a 32nd of it (at most 64 MiB) mapped at the top of each
// arena's heap (pad) and twice that free in it before it trims. Measured: benchmarks/README.md,
// "Stop 53" (the mmap threshold stayed at 128 KiB there: glibc takes at most 32 MiB, and raising
// it is not measured yet). Smaller budgets keep main()'s settings: at --memory 32M even a 1 MiB
// pad added 16 MiB to the peak (one per arena), a third of what the bound leaves.
void tune_heap_for_build(std::uint64_t budget) {
#if defined(__GLIBC__)
  if (budget != 0 && budget < (std::uint64_t{1} << 30)) return;
  const std::uint64_t keep =
      budget == 0 ? std::uint64_t{64} << 20 : std::min(budget / 32, std::uint64_t{64} << 20);
  mallopt(M_TOP_PAD, static_cast<int>(keep));
  mallopt(M_TRIM_THRESHOLD, static_cast<int>(2 * keep));
#else
  (void)budget;
#endif
}

}  // namespace

int cmd_ingest(const IngestArgs& a, const std::string& db_path, const CommonFlags& f) {
  a.validate();
  check_database_path(db_path, a.force);
  tune_heap_for_build(a.memory_bytes());
  nlohmann::json r = run_ingest(a, db_path, f.quiet, f.verify);
  r["peak_rss_mb"] = peak_rss_mb();
  if (a.memory_bytes() != 0) r["memory_budget_mb"] = double(a.memory_bytes()) / double(1 << 20);
  print_report(r, f.json);
  if (!f.json && !f.quiet) {
    std::fprintf(stderr, "%s: %llu ops in %llu pages, %.1f MB (%.1f bytes/vertex) -> %s\n",
                 a.input.c_str(),
                 static_cast<unsigned long long>(r["crmr"]["ops"].get<std::uint64_t>()),
                 static_cast<unsigned long long>(r["database"]["pages"].get<std::uint64_t>()),
                 double(r["database"]["file_bytes"].get<std::uint64_t>()) / 1e6,
                 r["database"]["bytes_per_vertex"].get<double>(), db_path.c_str());
  }
  return 0;
}

int cmd_build(IngestArgs a, std::string db_path, const RcfOptions& rcf, const ExtractArgs& e,
              const CommonFlags& f) {
  a.validate();
  e.validate();
  const RcfSpec spec = rcf.spec();
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
  nlohmann::json r = run_ingest(a, db_path, f.quiet, f.verify);
  std::optional<Heightfield> dem;
  if (!a.is_mesh()) dem = read_dem(a.input);
  const auto db = Database::open(db_path, {std::size_t(e.cache_mb) << 20});
  r.update(run_extract(*db, dem ? &*dem : nullptr, spec, e, f.verify));
  print_report(r, f.json);
  if (!f.json && !f.quiet) {
    std::fprintf(
        stderr, "%s: %llu ops, %llu output triangles (|X| = %llu) -> %s\n", a.input.c_str(),
        static_cast<unsigned long long>(r["crmr"]["ops"].get<std::uint64_t>()),
        static_cast<unsigned long long>(r["output"]["triangles"].get<std::uint64_t>()),
        static_cast<unsigned long long>(r["extraction"]["x"].get<std::uint64_t>()), e.out.c_str());
  }
  return 0;
}

}  // namespace smr::tools
