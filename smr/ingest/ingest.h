// Ingest: a DEM or a 3-D mesh in, an on-disk LOD database out, in one call (docs/design.md sections
// 4 and 5). Four builders sit behind it (Brown 7.1; memory_budget.h lists them):
//  - a mesh in memory: read, validated (and repaired), simplified by quadric edge collapse into a
//    progressive mesh (Hoppe 1997; Garland & Heckbert), written whole;
//  - a mesh by blocks: a PLY streamed through octree blocks, its ops assembled on disk and
//    streamed to the writer (Hoppe 1998's block construction in 3-D);
//  - a DEM in memory: greedy Delaunay insertion (Garland & Heckbert's fast TIN), written whole;
//  - a DEM by blocks: hierarchical block decimation of a DEM read one block at a time (Hoppe
//    1998, section 4; De Floriani's independent-set decimation), streamed to the writer.
// The block builders are what a memory budget (IngestOptions::memory) chooses; memory_budget.h
// divides it. Nothing here prints: progress, phases and overruns go through IngestProgress.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <variant>

#include "smr/builders/mesh/qem_pm.h"
#include "smr/builders/terrain/block_tin.h"
#include "smr/db/writer.h"
#include "smr/ingest/memory_budget.h"
#include "smr/io/mesh_reader.h"
#include "storage/codec.h"

namespace smr {

/// Which builder: kAuto = by blocks when there is a memory budget, else in memory.
enum class IngestBuilder { kAuto, kInCore, kBlocks };

struct IngestOptions {
  IngestBuilder builder = IngestBuilder::kAuto;
  // ---- what to build
  /// DEMs: stop refining at this vertical error (data units; 0 = lossless).
  double max_error = 0.0;
  /// DEMs in memory: stop at this many vertices (0 = no limit).
  std::uint64_t max_vertices = 0;
  /// In memory: vertices of the base mesh (DEMs: 4 = the corners; meshes: simplify down to this
  /// many where the collapse rules allow). The block builders decimate down to the corners.
  std::uint64_t base_vertices = 4;
  /// Meshes in memory: weld, drop degenerate and duplicate faces, split non-manifold edges and
  /// vertices, orient faces consistently (MeshRepair::all).
  bool repair = false;
  /// Meshes: skip the test that keeps simplification from making the surface cross itself
  /// (QemPmOptions::allow_self_intersections).
  bool allow_self_intersections = false;
  /// Meshes in memory: QemPmOptions::max_fragment_triangles and coalesce_error_ratio.
  std::uint32_t coalesce = 32;
  double coalesce_ratio = 0.7;
  /// DEMs by blocks: side of a leaf block in grid cells (a power of two, at least 8).
  int block_cells = 256;
  // ---- resources
  /// The block builders' budget (0 = none); see memory_budget.h for its shares.
  MemoryBudget memory;
  /// Scratch files' directory (empty = the system's temporary directory).
  std::string tmp_dir;
  /// Threads of the block builders and of the in-memory mesh builder's bounds (0 = one per
  /// core); the database does not depend on it.
  unsigned threads = 0;
  // ---- the database
  storage::CodecId codec = storage::CodecId::kZstd;
  /// Height quantization step (data units; 0 = automatic): WriteOptions::z_quantum.
  double z_quantum = 0.0;
  /// Target size of a data page in KiB (its payload is 16 bytes less).
  std::uint32_t page_kb = 12;
  /// Replace an existing database at the path.
  bool force = false;
  /// Check the CRMR's invariants before writing it (in memory), or the written database
  /// (verify_database; the block builders never hold the CRMR). A violation is an internal error.
  bool verify = false;
};

/// What a CRMR holds, counted op by op (in memory, or as the ops stream by).
struct CrmrSummary {
  std::uint64_t ops = 0, fragment_triangles = 0, vertices = 0;
  std::uint64_t finest_triangles = 0, base_triangles = 0;  // non-void leaves; R^0's fragment
  double err0 = 0.0, err_final = 0.0;
};

/// What each path read and how its builder went.
struct QemPmReport {
  MeshReport input;           // the mesh as read (and repaired)
  double read_seconds = 0.0;  // reading and validating it
  QemPmStats stats;
};
struct BlockPmReport {
  BlockPmStats stats;  // its vertex and triangle counts are the input's
};
struct GreedyTinReport {
  int width = 0, height = 0;
  std::uint64_t samples = 0;
  bool nodata = false, geographic = false;
  double read_seconds = 0.0;
};
struct BlockTinReport {
  int width = 0, height = 0;
  bool geographic = false;
  BlockTinStats stats;  // its samples are the input's
};

struct IngestReport {
  std::variant<QemPmReport, BlockPmReport, GreedyTinReport, BlockTinReport> build;
  CrmrSummary crmr;
  /// In memory: the build (after reading the input); by blocks: opening the input and the build,
  /// the ops spooled to the writer as they came.
  double build_seconds = 0.0;
  WriteReport database;
  /// Scratch bytes written: the builder's and the writer's.
  std::uint64_t temp_bytes = 0;
  /// The block TIN builder's records exceeded their share of the budget
  /// (MemoryShares::record_bytes): they are not paged out yet.
  bool records_over_budget = false;
  IngestPath path() const { return IngestPath(build.index()); }
};

enum class IngestPhase {
  kBuilt,    // the CRMR is built (by blocks: every op spooled, the builder's memory freed); the
             // database is written next
  kWritten,  // the database is complete (IngestOptions::verify checks it next, by blocks)
};

struct IngestProgress {
  /// Fraction done, in [0, 1]: the build takes 0 to 0.8, writing the database 0.8 to 1.
  std::function<void(double)> fraction;
  /// Called as each phase is reached, with the report so far (kBuilt: the build's section,
  /// crmr, build_seconds and records_over_budget; kWritten: all but verification).
  std::function<void(IngestPhase, const IngestReport&)> phase;
};

/// The path ingest() takes for `input` (a mesh by its extension, smr/io is_mesh_path).
IngestPath choose_path(const std::string& input, const IngestOptions& options);

/// What the database records of how it was built (WriteOptions::parameters): the input's file
/// name and every build parameter, in a fixed order. Not where the input sits nor the output path:
/// the same input and parameters give a byte-identical database.
std::string describe(const std::string& input, const IngestOptions& options);

/// Reads `input` (a DEM: GeoTIFF or another one-band GDAL raster, .npy, .npz; or a mesh: .ply,
/// .obj, .off, .stl), builds its CRMR and writes it to a new database at `db_path`. The database
/// names its source by file name only. Throws smr::Error: kInvalidInput for an unreadable input,
/// an existing `db_path` without options.force, a budget with an in-memory builder or unusable
/// options (the builders' own checks); internal when options.verify finds a violation.
IngestReport ingest(const std::string& input, const std::string& db_path,
                    const IngestOptions& options, const IngestProgress& progress = {});

}  // namespace smr
