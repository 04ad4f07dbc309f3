// The block TIN builder's leaf pass (block_tin.h, step 1): the finest mesh M^m, one leaf block at
// a time. Each block border line is simplified on its own (1-D, Douglas & Peucker 1973, with
// vertical error), so the two blocks that share it agree on its vertices; each leaf block is then
// triangulated by greedy Delaunay insertion (Garland & Heckbert 1995, "Fast polygonal
// approximation of terrains and height fields"; Brown 7.1.1) from those border vertices to
// max_error, and the leaves are merged into one mesh, their shared border vertices and edges
// glued. Out of core as terrain blocks are in Hoppe 1998 ("Smooth view-dependent level-of-detail
// control and its application to terrain rendering", section 4): the DEM is read one leaf block
// at a time (RasterWindows), never whole.
//
// Leaf blocks are read in order, built by workers into records of their own and merged in order,
// so the records do not depend on the thread count. Interleaved (options.interleave_level0),
// each merge also makes the new borders Delaunay (block_tin_lawson.h) and hands out the level-0
// blocks whose leaves are all merged (block_tin_levels.h), overlapping the reading.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <vector>

#include "smr/builders/terrain/block_tin_lawson.h"
#include "smr/builders/terrain/block_tin_levels.h"
#include "smr/builders/terrain/block_tin_mesh.h"
#include "smr/builders/terrain/sample_spill.h"
#include "smr/core/heightfield.h"
#include "smr/core/id_map.h"
#include "smr/core/parallel.h"

namespace smr::block_tin {

/// The leaf pass over the whole mesh `whole` (empty before), copying the samples to `spill` and
/// leaving the leaves' windows in `tiles` for the Delaunay repair.
class LeafPass {
 public:
  LeafPass(const Setup& setup, Mesh& whole, SampleSpill& spill, SampleSpill::Cache& tiles,
           BlockTinStats& stats)
      : setup_(setup), whole_(whole), spill_(spill), tiles_(tiles), stats_(stats) {}

  /// Every leaf block: read in order on this thread, built on `threads` workers, merged in
  /// order, so the records (and the database) do not depend on the number of threads. Sets
  /// whole.tol to the tolerance of every sample read. True if level 0 was decimated meanwhile
  /// (interleaved); `merged` is called after each level-0 block's merge.
  ///
  /// Interleaved (options.interleave_level0), each merge also repairs the Delaunay property
  /// across the borders the new leaf shares with earlier ones, and a leaf's level-0 block is
  /// copied out as soon as its last neighbour (the one below and to the right) is merged and
  /// repaired; it is decimated by the workers alongside later leaves and merged back kLevel0Lag
  /// items later. A later repair that would touch a triangle handed out so throws LeafConflict,
  /// and the build starts again in the plain order (every leaf, the whole repair, level 0). Every
  /// step is on the merge sequence, so the output does not depend on the thread count.
  bool run(const std::function<void()>& merged);

  /// Valid samples read.
  std::uint64_t valid_samples() const { return valid_samples_; }

  /// A leaf block's samples and the tolerance it is built with, read in block order.
  struct LeafInput {
    int bx = 0, by = 0;
    Heightfield halo, w;  // the block's window with one sample around it, and the window
    double tol = 0.0;     // the tolerance so far: the largest |z| of this and earlier blocks
  };

 private:
  LeafInput read_leaf(std::size_t k);
  LeafInput read_leaf_now(std::size_t k);
  Heightfield spare_window();
  void give_back(Heightfield&& w);
  void merge_leaf(Mesh& leaf, const BlockTinStats& leaf_stats, std::vector<EdgeTask>* glued,
                  std::size_t leaf_index);
  std::unique_ptr<UpperBlock> level0_block(std::size_t j);

  const Setup& setup_;
  Mesh& whole_;
  SampleSpill& spill_;
  SampleSpill::Cache& tiles_;  // the Delaunay repair's tiles (it works along borders)
  BlockTinStats& stats_;
  IdMap<std::uint32_t> shared_;                            // grid index -> border vertex + 1
  std::vector<std::vector<std::uint32_t>> leaf_vertices_;  // interleaved pass: per leaf block
  std::vector<double> leaf_tol_;        // the running tolerance after each leaf's read
  Turnstile read_turns_;                // the leaf pass's reads: one at a time, in block order
  double read_tol_ = 0.0;               // the running tolerance of the reads (whole.tol once done)
  std::uint64_t read_max_samples_ = 0;  // the reads' largest window (with its halo)
  std::uint64_t valid_samples_ = 0;     // of the reads
  std::mutex spare_mu_;                 // guards spare_windows_
  std::vector<Heightfield> spare_windows_;  // windows whose buffers are free (spare_window)
};

}  // namespace smr::block_tin
