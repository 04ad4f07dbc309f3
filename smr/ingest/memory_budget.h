// One memory budget (`smrdb ingest --memory`), divided in one place into the shares each builder
// and the database writer are given, each an option field of one meaning (a byte count, or for
// the exact windows a sample count derived from bytes). Out-of-core construction holds a few
// blocks and the sorts' buffers, never the whole input (docs/design.md section 4; Hoppe 1998's
// block construction; external sorts in the manner of Aggarwal & Vitter's I/O model).
#pragma once

#include <cstdint>

namespace smr {

/// The four ways ingest() builds a CRMR (smr/ingest/ingest.h).
enum class IngestPath {
  kQemPm,      // a mesh read, validated and simplified in memory (qem_pm.h, build_qem_pm)
  kBlockPm,    // a PLY streamed through octree blocks (qem_pm.h, build_block_pm)
  kGreedyTin,  // a DEM read whole, greedy Delaunay insertion (greedy_tin.h)
  kBlockTin,   // a DEM read one block at a time, hierarchical decimation (block_tin.h)
};

/// What an ingest may hold besides the builder's own records (0 = no budget: each share is the
/// default of the option field it sets). Only the streamed paths (kBlockPm, kBlockTin) take one.
struct MemoryBudget {
  std::uint64_t total_bytes = 0;
};

/// The named shares of a MemoryBudget: each is the value of the option field named beside it.
struct MemoryShares {
  std::uint64_t writer_batch_bytes = 0;    // WriteOptions::batch_bytes
  std::uint64_t writer_sort_bytes = 0;     // WriteOptions::sort_bytes
  std::uint64_t assembly_sort_bytes = 0;   // BlockTinOptions / BlockPmOptions::assembly_sort_bytes
  std::uint64_t assembly_table_bytes = 0;  // ... ::assembly_table_bytes
  std::uint64_t face_sort_bytes = 0;       // BlockPmOptions::face_sort_bytes
  std::uint64_t leaf_triangles = 0;        // BlockPmOptions::leaf_triangles
  std::uint64_t exact_window_samples = 0;  // BlockTinOptions::exact_window_samples
  std::uint64_t raster_cache_bytes = 0;    // BlockTinOptions::raster_cache_bytes
  /// The block TIN builder's records (BlockTinStats::record_bytes) are expected to stay within
  /// this; they are not paged out yet, so beyond it ingest() reports an overrun (0 = no check).
  std::uint64_t record_bytes = 0;
};

/// Bytes an exact window costs a sample: 4 (height) + 1 (validity), and as much for its copy.
inline constexpr std::uint64_t kExactWindowBytesPerSample = 10;

/// Divides `budget` among the parts `path` runs. With a budget M (the shares of one path; they are
/// not all alive at once, and M is at least 32 MiB for the CLI):
///
///   the database writer (both streamed paths)
///     writer_batch_bytes   M/16  values buffered before each LMDB commit, while the builder runs
///     writer_sort_bytes    M/4   the writer's finish(), which runs once the builder has freed
///                                its records: half to the R-tree entry sort, a quarter each to
///                                the ROI queue and the locator sort (smr/db/writer.h,
///                                WriteOptions)
///   kBlockTin (a DEM by blocks)
///     raster_cache_bytes   M/8   the reader's decoded source blocks, during the leaf pass only
///     exact_window_samples (M/4) / kExactWindowBytesPerSample, capped by the option's default:
///                                the largest window decimated with exact bounds
///     assembly_sort_bytes  M/2, at least 16 MiB: the final assembly's sorts (op_assembly.h:
///                                two at a time, a quarter of it each; record chunks an eighth)
///     record_bytes         M/2   what the build records (~64 bytes a triangle made) may take
///     assembly_table_bytes M/16  the assembly's tables of 16 bytes a removal, resident (the rest
///                                stays in scratch files: storage::SpillArray)
///   kBlockPm (a PLY by octree blocks; the rest of M holds the blocks being simplified and the
///   writer's batch; no table of vertices)
///     face_sort_bytes      M/8   the input's regrouping by leaf cell (block_input.h): its
///                                sorts and its cache of vertex pages, two of them at a time, a
///                                half of it each
///     assembly_sort_bytes  M/8   the assembly's sorts, as above
///     assembly_table_bytes M/8   the assembly's tables, as above
///     leaf_triangles       M/8192 rounded down to a power of 2, in [4096, 65536]: a block
///                                being simplified takes ~300 bytes a triangle, and the threads'
///                                leaves and a parent of 8 leaves' worth are alive at once
///
/// Without a budget every share is its option's default (for kBlockTin the raster cache is left
/// as the reader has it, 0, and there is no record check). The in-core paths take only the
/// writer's defaults (they hold the whole input, so a budget would not bound them).
MemoryShares divide(const MemoryBudget& budget, IngestPath path);

}  // namespace smr
