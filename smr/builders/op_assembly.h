// The CRMR of a decimation, assembled out of core (docs/design.md section 4; Brown 4.4.3.3, 4.5).
//
// A decimating builder (vertex removal, edge collapse) hands over each removal as it makes it,
// in the order it makes them: the vertices it removes, the triangles it destroys (its star,
// which reversed is F of an op) and the triangles it makes (PreF). Everything that joins one
// removal to others is found by external sorts (storage::ExternalSorter) in scratch files:
//  - the order: err(k) = max(own bound, err of the removals that made its star), so sorting by
//    falling err (ties: the later removal first) is a topological order of the DAG and birth_res
//    never decreases (Brown 4.4.3.3); op ids are ranks in it (R^0 is op 0);
//  - PreF's references: the op and index of the fragment that holds each triangle a removal made
//    (its destroyer's star, or R^0), joined on (op, triangle);
//  - the Hypermesh links (Brown 4.5.1): the closest coarser version of a fragment boundary edge
//    a->b of op i is the newer (larger owner op) of PreF's triangle with a->b and the triangle
//    with b->a alive just before i. Triangles with one directed edge live one after another, so
//    the alive one is the last, by owner, whose owner is below i, provided its killer is above i:
//    a merge of every triangle's edges with every op's boundary edges, both sorted by edge.
// Memory holds 16 bytes per removal (its err, op id and DAG depth: in scratch files under
// AssemblyOptions::table_bytes) and the budget, never the triangles: a removal's record is spooled
// when it is added and read back when its op is made, a chunk of records at a time (an 8th of the
// budget, read in runs of nearby records), and the ops are made on `threads` workers a batch at a
// time, handed to the sink in id order (to a sink that encodes, OpSink::encodes, encoded by the
// workers and handed over as bytes). The ops are the ones an in-memory replay of the ops in id
// order gives.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <span>
#include <string>

#include "smr/core/crmr.h"

namespace smr {

struct AssemblyOptions {
  /// Scratch files' directory (empty = the system's temporary directory).
  std::string tmp_dir;
  /// Memory of the external sorts, in bytes (tests use a few KiB to force spills). Two sorts are
  /// filled at a time, each holding a quarter of it; the records read back while the ops are made
  /// come in chunks of an eighth of it.
  std::uint64_t sort_bytes = std::uint64_t{64} << 20;
  /// Memory of the per-removal tables (err(k), op ids, DAG depths: 16 bytes a removal): 0 keeps
  /// them in memory; otherwise they live in scratch files with at most this many bytes of them
  /// resident (storage::SpillArray), so the assembler's memory does not grow with the input.
  std::uint64_t table_bytes = 0;
  /// Threads making the ops in finish() (0 = one per core); the ops do not depend on it. The
  /// `position` given to finish() is then called from several threads at once.
  unsigned threads = 1;
  /// Progress of finish() in [0, 1].
  std::function<void(double)> progress;
};

struct AssemblyStats {
  std::uint64_t removals = 0;
  std::uint64_t triangles_destroyed = 0, triangles_made = 0;
  std::uint64_t dag_height = 0;     // longest parent-to-child path from R^0
  std::uint64_t scratch_bytes = 0;  // written to scratch files
  std::uint64_t links = 0;          // fragment boundary edges linked to a coarser version
  // Seconds (wall) of finish(): the order and the joins' sorts and merge; making the ops (the
  // sink's add() included).
  double seconds_join = 0.0, seconds_emit = 0.0;
};

class OpAssembler {
 public:
  static constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();

  /// A triangle a removal destroys (or one of R^0): `id` is the builder's (unique among the
  /// triangles ever made), `creator` the removal that made it (kNone: a finest-mesh triangle).
  struct StarTriangle {
    std::array<std::uint32_t, 3> v{};  // vertex ids, counter-clockwise
    std::uint32_t id = 0;
    std::uint32_t creator = kNone;
    bool is_void = false;
  };
  /// A triangle a removal makes.
  struct MadeTriangle {
    std::array<std::uint32_t, 3> v{};
    std::uint32_t id = 0;
    bool is_void = false;
  };

  explicit OpAssembler(AssemblyOptions options = {});
  ~OpAssembler();
  OpAssembler(const OpAssembler&) = delete;
  OpAssembler& operator=(const OpAssembler&) = delete;

  /// Adds removal k (k = removals added before) and returns k. `vertices`: the vertices it
  /// removes (the op introduces them, in this order); `star`: the triangles it destroys, in the
  /// order F keeps them; `made`: the triangles it makes. `error`: its own bound. Every creator
  /// must be an earlier removal; throws smr::Error (internal) otherwise.
  std::uint32_t add_removal(std::span<const std::uint32_t> vertices,
                            std::span<const StarTriangle> star, std::span<const MadeTriangle> made,
                            double error);
  /// The same, with the coordinates of every vertex of `star`, in increasing order of vertex id
  /// (each once): they ride with the removal's record, and finish() makes its op with them
  /// instead of calling `position` (a builder that keeps no table of positions).
  std::uint32_t add_removal(std::span<const std::uint32_t> vertices,
                            std::span<const StarTriangle> star, std::span<const MadeTriangle> made,
                            double error, std::span<const Vec3> star_positions);
  std::uint64_t removals() const;
  /// err(k) as the order uses it: k's own bound raised to its children's.
  double error(std::uint32_t k) const;

  /// Hands R^0 (the triangles `base`, alive after the last removal, in this order) and then every
  /// op, in id order, to `sink`. info.err0 is raised to the largest err(k) and info.err_final
  /// capped by it. `position` gives a vertex's coordinates (R^0's, and those of the ops added
  /// without positions). Call once.
  void finish(CrmrInfo info, std::span<const StarTriangle> base,
              const std::function<Vec3(std::uint32_t)>& position, OpSink& sink);
  const AssemblyStats& stats() const;

 private:
  struct State;
  std::unique_ptr<State> s_;
};

}  // namespace smr
