// The out-of-core mesh builder behind build_block_pm (qem_pm.h: BlockPmOptions says what it
// does): Hoppe 1998's block construction ("Smooth view-dependent level-of-detail control and
// its application to terrain rendering") in 3-D, with De Floriani et al.'s
// independent-set rounds (qem_rounds.h) inside each block. The triangles and their vertices are
// sorted by octree leaf cell on disk (block_input.h); each leaf block is simplified with its
// border locked; 2x2x2 blocks merge, their shared borders unlock and simplification goes on, up
// to the root; every collapse goes to the out-of-core op assembler (op_assembly.h) as it is made,
// with its star's positions. No table the size of the input is held: a block carries its
// vertices' positions, lock spans and quadrics. Internal to smr/builders.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

#include "smr/builders/mesh/block_input.h"
#include "smr/builders/mesh/pm_mesh.h"
#include "smr/builders/mesh/qem_pm.h"
#include "smr/builders/mesh/qem_simplify.h"
#include "smr/builders/op_assembly.h"

namespace smr::qem {

// What a block hands to its parent: its triangles (global vertex and triangle ids, bounds, the
// collapse that made each) and their vertices (position, lock span, quadric), by id.
struct BlockTriangle {
  std::array<std::uint32_t, 3> v{};
  double e = 0.0;
  std::uint32_t creator = kNone;  // global removal
  std::uint32_t id = 0;
};
struct BlockVertex {
  std::uint32_t id = 0;
  std::uint32_t lo = 0, hi = 0;  // first and last leaf cell of its triangles (LeafVertex)
  Vec3 pos;
  Quadric quad;
};
struct BlockState {
  std::vector<BlockTriangle> tris;
  std::vector<BlockVertex> verts;  // by id
};

// A block simplified, not yet handed over (BlockPmBuilder::compute).
struct SimplifiedBlock {
  std::unique_ptr<Simplification> s;
  std::vector<std::uint32_t> gid;  // local vertex -> global
  std::vector<std::uint32_t> src;  // local vertex -> its index in the block's BlockState::verts
  std::uint64_t rounds = 0;
};

class BlockPmBuilder {
 public:
  /// Throws smr::Error on unusable options.
  BlockPmBuilder(const MeshStream& mesh, const BlockPmOptions& options, BlockPmStats& stats);
  void run(OpSink& sink);

 private:
  void report(double f) const;
  void reject_duplicate_faces(const std::vector<std::array<std::uint32_t, 3>>& faces) const;
  void simplify_leaves(BlockInput& input);
  bool locked_at(const BlockVertex& v, int level) const;
  BlockState leaf_state(const LeafInput& leaf) const;
  void push(int level, std::uint64_t code, BlockState b);
  void flush(int level);
  BlockState merge(int level);
  BlockState simplify(int level, BlockState in);
  SimplifiedBlock compute(int level, const BlockState& in) const;
  SimplifiedBlock load(int level, const BlockState& in) const;
  std::uint64_t simplify_block(int level, Simplification& s) const;
  BlockState commit(BlockState in, SimplifiedBlock done);
  void add_removals(const Simplification& s, const std::vector<std::uint32_t>& gid,
                    std::vector<std::uint32_t>& id_of, std::vector<std::uint32_t>& creator_of);
  void finish(const BlockState& root, OpSink& sink);

  const MeshStream& mesh_;
  const BlockPmOptions& opt_;
  BlockPmStats& stats_;
  QemPmOptions qem_;  // the options of each block's simplification
  Box3 box_;
  double side_ = 1.0;
  int levels_ = 0;
  Box3 referenced_box_;  // of the vertices some triangle uses
  std::uint64_t referenced_ = 0;
  std::vector<std::vector<BlockState>> pending_;  // per level: blocks waiting for siblings
  std::vector<std::uint64_t> pending_code_;
  std::uint32_t next_tri_ = 0;
  std::uint64_t leaf_done_ = 0;
  std::unique_ptr<OpAssembler> assembler_;
};

}  // namespace smr::qem
