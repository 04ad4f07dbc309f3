// Extraction sessions: geomorphing between selectively refined meshes (Brown ch. 6).
//
// A session keeps X (the refinement operations of the current mesh), for each op of X how many of
// its children are in X (an op with none is in C, Brown 6.3's completely expanded set: its whole
// fragment is in the mesh and removing it keeps X ancestor-closed), and the current mesh as a set
// of triangles (the set formula of X, Lemma 5.1.1, kept up to date op by op: adding R takes PreF(R)
// out and puts F(R) in; removing R does the reverse).
//
// update(rcf, budget) runs Brown 6.3:
//   1. Coarsening: ops of C completely finer than the new RCF are removed, in order of decreasing
//      resolution; removing one may put its parents in C. Afterwards X is the minimal-surface X of
//      the common-denominator RCF of the old and new RCFs (Theorem 6.4.1).
//   2. Refining: every op of X that is not finer than the new RCF offers its children that are
//      not completely finer (AddToList, with their missing ancestors, Brown 5.1.1); they are added
//      lowest birth_res first (the set Y). Afterwards X is the minimal-surface X of the new RCF.
//   An update without a budget skips step 1: the refining reaches the same X on its own (the ops
//   it does not reach are removed after it, finest first), and the frame is the same. After the
//   first update it runs over what the session kept of the ops it met (op_memo.h): their DAG
//   links, and their verdicts for as long as the camera stays within each verdict's motion
//   margin, so an update reads and judges only ops whose verdicts lapsed or that are new to it.
//   Most such updates do not even walk X: they start from the verdicts that lapsed and change X
//   only where one of them changed (refine_incremental in session.cpp: delete and rederive over
//   witness levels, then growth); a traversal runs when that would cost as much, and at times.
// The update returns a Frame: what changed (ops and triangles, net) and the morph of the changed
// region from the old mesh (t = 0) to the new one (t = 1), smr/extract/morph.h.
//
// Budgets. A maximum geomorphing period (Brown 6.3): coarsenings run while the period lasts and
// refinings only if time is left after them. A triangle budget: refinings stop before the mesh
// would exceed it. Either way the update stops between ops, so the mesh is always the valid mesh
// of an ancestor-closed X; what was left is reported (pending), and the next update continues.
// Refinings stop at a resolution r (Frame::stats.stop_resolution): every triangle of the mesh
// then meets the RCF as extraction judges it (its op is finer, or its killer is completely finer)
// or stands at a resolution of at least r (error at most error_at(r)): the mesh meets the RCF
// with its requirement capped at r, a coarser RCF. (The refining is a traversal in order of
// resolution; a needed op it has not added waits at a resolution >= r.) This holds for every
// triangle of a first update (a budgeted one-shot extraction) and, in later updates, for every
// triangle whose op the new RCF reaches; an op kept from the old X that the new RCF no longer
// reaches is only removed once a refining completes (session.cpp, Refiner).
#pragma once

#include <cstdint>
#include <future>
#include <memory>
#include <span>
#include <vector>

#include "smr/core/id_map.h"
#include "smr/core/mesh.h"
#include "smr/core/op_source.h"
#include "smr/extract/extract.h"
#include "smr/extract/morph.h"
#include "smr/extract/op_memo.h"
#include "smr/rcf/rcf.h"

namespace smr {

struct SessionBudget {
  /// Brown 6.3's maximum geomorphing period, in milliseconds (0 = none).
  double max_period_ms = 0.0;
  /// Refinings stop before the mesh would hold more triangles (void ones included; 0 = none).
  /// Coarsenings always run (they only shrink the mesh).
  std::uint64_t max_triangles = 0;
  /// Only Brown 6.3's first step: X becomes the common denominator's (Theorem 6.4.1).
  bool coarsen_only = false;
};

struct SessionOptions {
  /// Build the frame's morph (off: a client that only wants the mesh and what changed).
  bool morph = true;
};

struct FrameStats {
  std::uint64_t coarsenings = 0;  // ops removed from X by this update (net)
  std::uint64_t refinings = 0;    // ops added to X (net)
  /// Work left for a later update because a budget stopped this one: ops of C not yet tested for
  /// coarsening (the period ended during coarsening), and ops waiting to be refined (candidates
  /// not yet tested, so an upper bound on the refinings still needed; 0 when the period ended
  /// before the refining began, stop_resolution 0: then what is pending is not known).
  std::uint64_t pending_coarsenings = 0;
  std::uint64_t pending_refinings = 0;
  /// Ops of X the refining did not reach, removed after it (session.cpp): those Brown's
  /// coarsening kept that the new X lacks or, in an unbudgeted update (which skips the
  /// coarsening: the same X), every op removed.
  std::uint64_t unreached_coarsenings = 0;
  bool complete = true;          // X is the minimal-surface X of the RCF (no budget stopped it)
  double stop_resolution = 1.0;  // see the header comment; 1 when complete
  std::uint64_t x = 0;           // |X| after the update
  std::uint64_t triangles = 0;   // the mesh's triangles after the update, void ones included
  std::uint64_t triangles_in = 0, triangles_out = 0;
  std::uint64_t ops_tested = 0;  // ops read and judged by the RCF in this update
  /// Verdicts of earlier updates reused (op_memo.h: the camera stayed within their margins): in a
  /// traversal those it asked for; in an update without one (traversed false) every verdict held
  /// and not judged again, since X rests on them all.
  std::uint64_t verdicts_kept = 0;
  /// The refining walked all of X (false: it started from the verdicts that lapsed, only).
  bool traversed = true;
  std::uint64_t morph_triangles = 0, morph_vertices = 0, morph_groups = 0;
  double coarsen_seconds = 0.0, refine_seconds = 0.0, morph_seconds = 0.0, seconds = 0.0;
};

struct Frame {
  std::vector<OpId> ops_added, ops_removed;         // net, ascending
  std::vector<TriRef> triangles_in, triangles_out;  // net, ascending
  MorphMesh morph;  // from the surface of triangles_out (t = 0) to that of triangles_in (t = 1)
  FrameStats stats;
};

class Session {
 public:
  /// A session on `source` (which must outlive it), starting from the base mesh (X = {R^0}).
  explicit Session(const OpSource& source, SessionOptions options = {});

  /// Brown 6.3 towards `rcf`, within `budget`.
  Frame update(const RcfOracle& rcf, const SessionBudget& budget = {});

  /// X, descending (as add_to_list returns it).
  std::vector<OpId> x() const;
  bool in_x(OpId id) const { return x_.contains(id.value); }
  /// The current mesh's triangles (the set formula of X), in no particular order.
  std::span<const TriRef> triangles() const { return triangles_; }
  /// The current mesh, void triangles dropped (to_mesh).
  TriangleMesh mesh() const;
  const OpSource& source() const { return source_; }
  /// Bytes the session itself holds (X, the triangle set and their indexes; not the source's).
  std::uint64_t memory_bytes() const;

 private:
  struct TriKeys {
    static constexpr TriRef empty() { return {OpId{~std::uint64_t{0}}, ~std::uint32_t{0}}; }
    static std::size_t hash(const TriRef& t) {
      return std::size_t(mix64(t.op.value * 0x9E3779B97F4A7C15ull + t.index));
    }
  };
  struct Changes;
  class Refiner;

  void add_op(const OpView& op, Changes& changes);
  void remove_op(const OpView& op, Changes& changes);
  void insert_triangle(const TriRef& t, Changes& changes);
  void erase_triangle(const TriRef& t, Changes& changes);
  void coarsen(const RcfOracle& rcf, double deadline_ms, Changes& changes, FrameStats& stats);
  void refine(const RcfOracle& rcf, const SessionBudget& budget, double start_ms, Changes& changes,
              FrameStats& stats);
  void refine_kept(Changes& changes, FrameStats& stats);
  bool refine_incremental(Changes& changes, FrameStats& stats, const IdMap<std::uint8_t>* entering);
  std::uint32_t child_entry(std::uint32_t e, std::uint32_t i);
  enum class Refresh { kSame, kNext, kNew };  // kNext: a set found ahead, with its entering ids
  Refresh refresh_candidates(const RcfOracle& rcf);
  double candidate_margin() const;
  void remove_finest_first(std::vector<std::uint32_t>& entries, Changes& changes);

  const OpSource& source_;
  SessionOptions options_;
  struct XEntry {
    double birth_res = 0.0;
    std::uint32_t children = 0;  // how many of its children are in X (0: the op is in C)
  };
  IdMap<XEntry> x_;
  std::vector<TriRef> triangles_;
  FlatMap<TriRef, std::uint32_t, TriKeys> slot_;  // triangle -> 1 + index in triangles_
  OpMemo memo_;                                   // ops met and their verdicts, kept across updates
  std::uint32_t updates_ = 0;                     // updates so far
  // The index's candidates (RcfIndexedSource::maybe_not_completely_finer) for every camera within
  // `margin` of `pose`: a child the memo lacks is read only if it is one.
  struct CandidateSet {
    RcfPose pose;
    double margin = 0.0;
    std::shared_ptr<const IdMap<std::uint8_t>> ids;
    /// Found on another thread (Refresh::kNext): the ids not in the set it replaces.
    IdMap<std::uint8_t> entering;
    bool covers(const RcfPose& now) const {
      return pose.signature == now.signature && pose.needed_to(now) <= margin;
    }
  };
  struct IndexCandidates : CandidateSet {
    bool valid = false;
    std::uint32_t tag = 0;  // which set: OpMemo::rule_out_child marks
  } candidates_;
  // The next set, found on another thread from the pose where the camera had used half of the
  // current set's margin (refresh_candidates).
  std::future<CandidateSet> next_candidates_;
  const RcfIndexedSource* indexed_ = nullptr;  // source_, if it has an index
  // The memo entries refine_kept reached in update `reached_update_` (then X, exactly).
  std::vector<std::uint32_t> reached_;
  std::uint32_t reached_update_ = 0;
  // The memo's in_x marks and levels describe X (a kept update made it, refine_incremental).
  bool memo_synced_ = false;
  static constexpr std::uint32_t kIdle = 16;  // updates an op may go unmet before it is forgotten
  // A traversal at least this often (the memo's ring of poses: OpMemo::kRing).
  static constexpr std::uint32_t kTraverseEvery = 256;
  std::uint32_t forgotten_at_ = 0;  // the last update that forgot idle memo entries
};

/// One-shot minimal-surface extraction within a budget (smrdb extract --max-triangles,
/// --max-ms): a session's first update from R^0. The X returned is ancestor-closed, so its set
/// formula is a valid mesh; Extraction::stats says nothing of the budget, `frame_stats` (if not
/// null) receives the update's statistics (stop_resolution, pending, complete).
std::vector<OpId> add_to_list_budgeted(const OpSource& source, const RcfOracle& rcf,
                                       const SessionBudget& budget,
                                       FrameStats* frame_stats = nullptr);
/// add_to_list_budgeted, then the minimal surface's expansion of that X (expand_minimal).
Extraction extract_budgeted(const OpSource& source, const RcfOracle& rcf,
                            const SessionBudget& budget, const ExpansionOptions& options,
                            FrameStats* frame_stats = nullptr);

}  // namespace smr
