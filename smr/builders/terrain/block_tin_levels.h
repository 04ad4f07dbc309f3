// The block TIN builder's level decimation (block_tin.h, step 2): at level l the blocks are 2^l
// leaf blocks wide (2x2 merges of the level below, Hoppe 1998, "Smooth view-dependent
// level-of-detail control and its application to terrain rendering", section 4) and the
// vertices on their border lines are locked. Each level runs stages of growing error tolerance;
// each stage runs rounds, and a round removes an independent set of vertices (no two adjacent),
// cheapest first (De Floriani et al., LOD part two, "construction through simplification":
// independent-set decimation), so the DAG height is at most the number of rounds.
//
// Levels whose blocks' windows are small enough are decimated block by block with exact bounds:
// each block is copied out of the whole mesh, decimated by a worker from its window and merged
// back in block order (the records a single pass makes). Larger levels run on the whole mesh
// with overlay bounds (block_tin_bounds.h).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

#include "smr/builders/terrain/block_tin_mesh.h"
#include "smr/builders/terrain/block_tin_removal.h"
#include "smr/builders/terrain/sample_spill.h"
#include "smr/core/heightfield.h"
#include "smr/core/id_map.h"

namespace smr::block_tin {

/// The decimation's per-vertex marks and buffers, kept from level to level on the whole mesh (a
/// block's copy has its own).
struct DecimationScratch {
  std::vector<double> cost;
  // 1 = the star changed; 2 = cost is only a lower bound (an estimate: with exact bounds a
  // removal's samples are scanned only when it is about to be chosen).
  std::vector<std::uint8_t> dirty;
  std::vector<std::uint32_t> stamp;  // = round_stamp: in this round's independent set or its ring
  std::uint32_t round_stamp = 0;
  std::vector<std::uint32_t> cand_mark, seen;  // candidates of this level; in the next round
  std::uint32_t cand_stamp = 0, seen_stamp = 0;
  RemovalScratch removal;
};

/// One level's decimation of `mesh` (the whole mesh, or a block's copy). With a window (level 0,
/// or an exact upper level) errors are exact from its samples and the candidates are `only`, the
/// block's vertices; without, overlay bounds and every vertex not locked.
void decimate_level(const Setup& setup, Mesh& mesh, DecimationScratch& scratch,
                    BlockTinStats& stats, int level, const BlockWindow& window,
                    const std::vector<std::uint32_t>* only);

/// A block of an exact level copied out of the whole mesh for a worker: its live triangles and
/// their vertices, numbered in increasing whole-mesh id (so candidates and ties order as in the
/// whole mesh), and what merge_block needs to put the result back.
struct UpperBlock {
  int level = 0, c0 = 0, r0 = 0, w = 0, h = 0;
  BlockTinStats stats;
  Mesh mesh;                                 // the copy, decimated by a worker
  std::vector<std::uint32_t> gverts, gtris;  // local id -> whole-mesh id, both increasing
  std::vector<std::uint32_t> first_tri;      // each local vertex's `tri` as copied
  std::vector<std::uint32_t> cand;           // local ids of the removal candidates
  IdMap<std::uint32_t> border_owner;  // edge on the block's border -> its whole-mesh triangle
  Heightfield samples;  // the block's window when it was at hand as the block was copied
};

/// The block of `level` whose window starts at grid (c0, r0), copied out of `whole`: `tris` and
/// the candidates `cand` (whole-mesh ids). Counts its window into `stats`.
std::unique_ptr<UpperBlock> setup_block(const Setup& setup, const Mesh& whole, BlockTinStats& stats,
                                        int level, int c0, int r0, int span,
                                        std::vector<std::uint32_t>&& tris,
                                        const std::vector<std::uint32_t>& cand);

/// A copied block's decimation (a worker thread), exact bounds from its window: block.samples
/// if it has them (left there), else read from the samples' copy.
void decimate_block(const Setup& setup, const SampleSpill& spill, UpperBlock& block);

/// Puts a decimated block back into `whole`: its removals, stars and new triangles after the
/// whole mesh's (the ids a single pass gives), the copied triangles' deaths and new neighbours,
/// the new triangles on the block's border glued to the current triangles outside, and the
/// vertices' `tri` where the block changed it.
void merge_block(Mesh& whole, UpperBlock& block, BlockTinStats& stats);

/// Decimates `level` of the whole mesh: block by block with exact bounds from each block's
/// window at level 0 (the leaf blocks) and above it while a window fits
/// setup.exact_window_samples, else over the whole mesh with overlay bounds (with `scratch`).
/// `merged` is called after each block's merge.
void decimate_blocks(const Setup& setup, Mesh& whole, DecimationScratch& scratch,
                     const SampleSpill& spill, BlockTinStats& stats, int level,
                     const std::function<void()>& merged);

/// This thread's last block window, whose buffers the next one reuses. A worker's goes with its
/// thread; the calling thread's (it works inline with one thread) is freed after each pass.
Heightfield& window_buffer();

}  // namespace smr::block_tin
