// The out-of-core mesh builder behind build_block_pm (qem_pm.h: BlockPmOptions says what it
// does): Hoppe 1998's block construction ("Smooth view-dependent level-of-detail control and
// its application to terrain rendering") in 3-D, with De Floriani et al.'s
// independent-set rounds (qem_rounds.h) inside each block. The triangles are sorted by octree
// leaf cell (an external sort); each leaf block is simplified with its border locked; 2x2x2
// blocks merge, their shared borders unlock and simplification goes on, up to the root; every
// collapse goes to the out-of-core op assembler (op_assembly.h) as it is made. Internal to
// smr/builders.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <unordered_set>
#include <utility>
#include <vector>

#include "smr/builders/mesh/pm_mesh.h"
#include "smr/builders/mesh/qem_pm.h"
#include "smr/builders/mesh/qem_simplify.h"
#include "smr/builders/op_assembly.h"
#include "storage/external_sort.h"

namespace smr::qem {

struct FaceRecord {  // a source triangle and its leaf cell (Morton code)
  std::uint32_t cell = 0;
  std::array<std::uint32_t, 3> v{};
  bool operator<(const FaceRecord& o) const { return cell < o.cell; }
};

// What a block hands to its parent: its triangles (global vertex and triangle ids, bounds, the
// collapse that made each) and the quadrics of their vertices.
struct BlockTriangle {
  std::array<std::uint32_t, 3> v{};
  double e = 0.0;
  std::uint32_t creator = kNone;  // global removal
  std::uint32_t id = 0;
};
struct BlockState {
  std::vector<BlockTriangle> tris;
  std::vector<std::pair<std::uint32_t, Quadric>> quads;  // by vertex id
};

// A block simplified, not yet handed over (BlockPmBuilder::compute).
struct SimplifiedBlock {
  std::unique_ptr<Simplification> s;
  std::vector<std::uint32_t> gid;  // local vertex -> global
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
  void read_vertices();
  void sort_faces(storage::ExternalSorter<FaceRecord>& faces);
  void simplify_leaves(storage::ExternalSorter<FaceRecord>& faces);
  bool locked_at(std::uint32_t v, int level) const;
  BlockState leaf_state(const std::vector<std::array<std::uint32_t, 3>>& leaf) const;
  void push(int level, std::uint64_t code, BlockState b);
  void flush(int level);
  BlockState simplify(int level, BlockState in);
  SimplifiedBlock compute(int level, const BlockState& in) const;
  std::uint64_t simplify_block(int level, Simplification& s) const;
  BlockState commit(BlockState in, SimplifiedBlock done);
  void finish(const BlockState& root, OpSink& sink);

  const MeshStream& mesh_;
  const BlockPmOptions& opt_;
  BlockPmStats& stats_;
  QemPmOptions qem_;  // the options of each block's simplification
  std::vector<Vec3> pos_;
  Box3 box_;
  double side_ = 1.0;
  int levels_ = 0;
  std::vector<std::uint32_t> vmin_, vmax_;  // leaf cells of each vertex's triangles (Morton)
  Box3 referenced_box_;                     // of the vertices some triangle uses
  std::uint64_t referenced_ = 0;
  std::vector<std::vector<BlockState>> pending_;  // per level: blocks waiting for siblings
  std::vector<std::uint64_t> pending_code_;
  std::uint32_t next_tri_ = 0;
  std::uint64_t leaf_done_ = 0;
  std::unordered_set<std::uint32_t> leaf_cells_;  // non-empty leaf cells (sort_faces)
  std::unique_ptr<OpAssembler> assembler_;
};

}  // namespace smr::qem
