// Terrain CRMR by hierarchical block decimation (docs/design.md section 4; Hoppe 1998, "Smooth
// view-dependent level-of-detail control and its application to terrain rendering", section 4;
// De Floriani et al., LOD part two, "construction through simplification": independent-set
// decimation).
//
// The DEM is read one leaf block at a time (RasterWindows), never whole:
//  1. Each block border line is simplified on its own (1-D, within max_error), so the two blocks
//     that share it agree on its vertices; each leaf block is then triangulated by greedy
//     Delaunay insertion (build_greedy_mesh) from those border vertices to max_error. The union of
//     the blocks is made Delaunay across the border lines by Lawson flips, with a greedy
//     insertion wherever a flipped triangle would exceed max_error: the finest mesh M^m, a
//     Delaunay triangulation with exact per-triangle errors.
//  2. Decimation, finest to coarsest, in levels: at level l the blocks are 2^l leaf blocks wide
//     and the vertices on their border lines are locked, as are those whose star or hole leaves
//     their block (a flipped edge may cross a line). Error bounds are guaranteed either way:
//     - exact: the samples under each new triangle are scanned, from the block's window re-read
//       from a scratch copy of the samples (level 0 always; above while a block's window holds
//       at most exact_window_samples);
//     - overlay (levels whose blocks are larger): one-sided bounds source - plane <= up and
//       plane - source <= down, carried from the old triangles a new one overlaps plus the
//       largest difference of the two planes over each overlap (both are linear on each piece
//       of the overlay, so its corners suffice), capped by the source's range under it.
//     Each level runs stages of growing error tolerance (x sqrt 2, x4 per level); each stage
//     runs rounds, and a round removes an independent set (no two removed vertices adjacent) of
//     vertices of degree at most max_degree, cheapest first, re-triangulating each hole by
//     Delaunay ears. So the DAG height is at most the number of rounds, and removal from a
//     Delaunay triangulation with Delaunay holes keeps every mesh of the hierarchy Delaunay:
//     every fragment meets the Delaunay criterion, so every extracted mesh does (Brown Theorem
//     5.1.4).
//  3. Each removal, reversed, is an op: PreF = the hole's triangles, F = the removed vertex's
//     star. An op's error is its own bound or a child's, whichever is larger, so ordering the ops
//     by falling error is a topological order and birth_res never decreases (Brown 4.4.3.3).
//
// No-data samples: a leaf block's greedy TIN marks void triangles exactly as build_greedy_tin
// does; a vertex of a void triangle is never removed, so holes stay exact at every resolution.
//
// Memory and threads. Leaf blocks are read in order on the calling thread (the running tolerance
// and the reader are sequential), built by `threads` workers into records of their own and
// merged in order; the Delaunay repair runs on the calling thread; blocks of the exact levels
// are copied out, decimated by workers and merged back in order. Ids are the ones a single pass
// gives, so the CRMR does not depend on the thread count. Each removal goes to the out-of-core
// assembler (op_assembly.h) as it is merged; at the end the assembler orders and links the ops and
// hands each to an OpSink as it is made (DatabaseStreamWriter spools it to disk). What stays in
// memory is the build records of the triangles ever made (an MTri of 64 bytes; the assembler
// has its own copy on disk, so they could be paged out -- not done yet) and the vertices.
#pragma once

#include <cstdint>
#include <functional>
#include <string>

#include "smr/core/crmr.h"
#include "smr/core/heightfield.h"

namespace smr {

struct BlockTinOptions {
  /// Error of the finest mesh M^m (data units); 0 = lossless.
  double max_error = 0.0;
  /// Side of a leaf block in grid cells (a power of two, at least 8).
  int block_cells = 256;
  /// Only vertices with at most this many neighbours are removed (bounds the fragment size).
  std::uint32_t max_degree = 12;
  /// Levels above the leaves whose blocks hold at most this many samples are decimated block by
  /// block with exact error bounds, re-reading each block's window; larger blocks use the
  /// conservative overlay bound. Sizes the largest window held in memory (4 + 1 bytes a sample,
  /// and as much again for its copy). smr/ingest/memory_budget.h caps it by a share of a budget,
  /// as it does the two byte counts below.
  std::uint64_t exact_window_samples = std::uint64_t{16} << 20;
  /// The reader's cache of decoded source blocks during the leaf pass (RasterWindows::
  /// set_cache_bytes), emptied once the leaf blocks are read; 0 = the reader's own.
  std::uint64_t raster_cache_bytes = 0;
  /// Memory of the final assembly's external sorts (AssemblyOptions::sort_bytes).
  std::uint64_t assembly_sort_bytes = std::uint64_t{256} << 20;
  /// Resident memory of the assembly's per-removal tables (AssemblyOptions::table_bytes; 0 =
  /// in memory).
  std::uint64_t assembly_table_bytes = 0;
  /// Directory of the scratch file holding the samples for the later passes' re-reads (the
  /// Delaunay repair, level 0, the exact upper levels; empty = the system's temporary directory).
  /// Checked for room before any work.
  std::string tmp_dir;
  /// Threads building and decimating blocks (0 = one per core). The output does not depend on
  /// it: blocks are read and merged in order, only their greedy TINs and decimation run in
  /// parallel.
  unsigned threads = 0;
  /// Decimate each leaf block's level 0 during the leaf pass, as soon as the leaves around it are
  /// merged and their borders made Delaunay (overlapping the reading), rather than after every
  /// leaf. In the rare case that a later border's repair reaches such a block, the build starts
  /// again without. The output does not depend on the thread count either way.
  bool interleave_level0 = true;
  /// Progress in [0, 1].
  std::function<void(double)> progress;
};

// More than 20 members: one flat record of a build's figures, each a field of its own (what the
// CLI prints and the tests and benchmarks read by name), not state any code works on.
struct BlockTinStats {
  int levels = 0;                 // block levels above the leaves (the root is the last)
  std::uint64_t leaf_blocks = 0;  // blocks read
  std::uint64_t samples = 0;      // samples read
  std::uint64_t finest_vertices = 0, finest_triangles = 0;  // M^m
  std::uint64_t base_vertices = 0, base_triangles = 0;      // R^0
  std::uint64_t removals = 0;                               // ops other than R^0
  std::uint64_t rounds = 0;               // independent-set rounds (bounds the DAG height)
  std::uint64_t dag_height = 0;           // longest parent-to-child path from R^0
  std::uint64_t non_delaunay_holes = 0;   // holes with no Delaunay ear (none when M^m is Delaunay)
  std::uint64_t delaunay_flips = 0;       // Lawson flips making M^m Delaunay across block borders
  std::uint64_t delaunay_insertions = 0;  // samples inserted where a flip exceeded max_error
  bool level0_interleaved = false;        // level 0 ran during the leaf pass
  int level0_restarts = 0;                // builds started again without interleaving
  std::uint64_t max_block_samples = 0;    // largest window held in memory
  int exact_levels = 0;                   // upper levels decimated with exact bounds
  std::uint64_t samples_rescanned = 0;    // samples re-read for them
  std::uint64_t samples_scanned = 0;      // sample visits of exact bounds
  std::uint64_t plans = 0;                // removals planned (evaluated)
  std::uint64_t temp_bytes = 0;           // written to the scratch file
  // Triangles ever made, and the bytes of the build records (triangles, vertices, removals)
  // before the assembly: they stay in memory, outside every share BlockTinOptions sizes, and grow
  // with the finest mesh (~64 bytes a triangle made, ~3 triangles made per finest-mesh triangle).
  std::uint64_t triangles_made = 0, record_bytes = 0;
  // Seconds: survey pass, leaf windows read, leaf greedy TINs, the Delaunay repair, level 0,
  // upper levels (with their reads), assembling the CRMR.
  // Leaf reads are wall time on the reading thread; greedy is summed over the workers (thread
  // time); seconds_leaves is the wall time of the whole leaf pass, which includes the repair and
  // level 0 when level0_interleaved (their own figures are then 0); the others are wall time.
  double seconds_survey = 0, seconds_read = 0, seconds_greedy = 0, seconds_delaunay = 0,
         seconds_level0 = 0, seconds_leaves = 0, seconds_upper = 0, seconds_assemble = 0;
  // Of the assembly (op_assembly.h): handing removals over as they are merged (inside the levels'
  // times), then, inside seconds_assemble, its joins and making the ops (the sink's add included).
  double seconds_feed = 0, seconds_join = 0, seconds_emit = 0;
};

/// Builds the CRMR into `sink`, op by op in id order as the assembly makes them (the ops never
/// exist all at once; smr::DatabaseStreamWriter writes them to a database). Throws smr::Error on
/// unusable input (fewer than 2x2 samples, no valid sample) or options (block_cells not a power of
/// two >= 8, max_degree < 3).
void build_block_tin(const RasterWindows& dem, OpSink& sink, const BlockTinOptions& options = {},
                     BlockTinStats* stats = nullptr);
/// The same, collected in memory (ROIs computed).
Crmr build_block_tin(const RasterWindows& dem, const BlockTinOptions& options = {},
                     BlockTinStats* stats = nullptr);

}  // namespace smr
