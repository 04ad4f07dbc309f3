// The QEM builders' candidate collapses (Garland & Heckbert 1997, section 4: each vertex's
// cheapest quadric cost, in a heap; here half-edge collapses, whose rules, collapse_rules.h, are
// tested lazily, when a candidate comes up): per vertex its cheapest target, the targets
// the self-intersection test refused, and the heap of the in-core simplification.
#pragma once

#include <cstdint>
#include <queue>
#include <utility>
#include <vector>

#include "smr/builders/mesh/pm_mesh.h"
#include "smr/builders/mesh/qem_pm.h"

namespace smr::qem {

// Incremental bookkeeping recomputed in full and compared (CMake SMRDB_SELF_CHECKS: the
// sanitizer preset's tests).
#ifdef SMRDB_SELF_CHECKS
inline constexpr bool kSelfChecks = true;
#else
inline constexpr bool kSelfChecks = false;
#endif

struct Candidate {
  double cost;
  std::uint32_t from, to, stamp;
  // The in-core builder's post_ahead() is done with it for its band: handed over, or never
  // current again (not part of the order).
  bool looked = false;
  // std::priority_queue is a max-heap: the "largest" is the cheapest, ties by vertex ids.
  bool operator<(const Candidate& o) const {
    if (cost != o.cost) return cost > o.cost;
    if (from != o.from) return from > o.from;
    return to > o.to;
  }
};

// The queue; its items in heap order (those in front come up soon) for post_ahead().
struct CandidateHeap : std::priority_queue<Candidate> {
  std::vector<Candidate>& items() { return c; }  // Candidate::looked may change, not the order
};

// A (cost, target) pair; kUnknown: none known.
using Target = std::pair<double, std::uint32_t>;
inline constexpr Target kUnknown{0.0, kNone};

struct Candidates {
  double cos_max_turn = 0.0;  // collapse_allowed()'s normal-turn threshold
  CandidateHeap heap;
  std::vector<std::uint32_t> stamp;  // per vertex: its current candidate's stamp in the heap
  // Per vertex: the targets the self-intersection test refused since its neighbourhood last
  // changed, and its cheapest target by cost (cheapest_target()), or kUnknown.
  std::vector<std::vector<std::uint32_t>> blocked;
  std::vector<Target> cheapest;
  Marks marks;                                // per vertex (neighbours, the link condition)
  std::vector<std::uint32_t> nf, cand, ring;  // neighbour lists
  std::vector<Target> ranked;                 // rank_targets()
};

/// The per-vertex arrays for n vertices and the normal-turn threshold.
void init_candidates(Candidates& c, std::size_t n, double max_normal_turn_degrees);

/// The quadric cost of collapsing from -> to (Garland & Heckbert 1997, section 4).
inline double cost(const PmMesh& m, std::uint32_t from, std::uint32_t to) {
  Quadric q = m.quad[from];
  q += m.quad[to];
  return std::max(0.0, q.eval(m.pos[to]));
}

/// collapse_allowed() for from -> to, with its neighbours found here.
bool valid(const PmMesh& m, Candidates& c, QemPmStats& stats, std::uint32_t from, std::uint32_t to);

/// The cheapest valid target of `from` and its cost (ties: the smaller id; kNone if none):
/// validity, the costly test, is checked in order of cost until one passes. `failed`: a target
/// just found not valid, not tested again.
Target cheapest_valid(const PmMesh& m, Candidates& c, QemPmStats& stats, std::uint32_t from,
                      std::uint32_t failed = kNone);
/// The cheapest target of `from` by cost (ties: the smaller id; kNone if none), kept in
/// c.cheapest (locked targets never pass collapse_allowed(): skipped).
Target cheapest_target(const PmMesh& m, Candidates& c, std::uint32_t from);
/// The same for w, a vertex of the ring around `kept` after the collapse removed -> kept. Its
/// targets are those it had less `removed`, with `kept`, and only the cost to `kept` changed
/// (its quadric grew): a cheapest target that was neither stays cheapest unless `kept` is now
/// cheaper (same ties). 70 % of these are found so on the 832 k armadillo (blocks), 78 % on the
/// bunny (in core).
Target cheapest_after(const PmMesh& m, Candidates& c, std::uint32_t w, std::uint32_t removed,
                      std::uint32_t kept);

/// Pushes from's cheapest valid target (a new stamp).
void push_best(const PmMesh& m, Candidates& c, QemPmStats& stats, std::uint32_t from,
               std::uint32_t failed = kNone);
/// Pushes `target` for `from` (a new stamp): the cheapest target by cost alone, whose validity,
/// the costly test, waits until the candidate comes up (the simplification checks it then and,
/// if it fails, pushes the cheapest valid target instead). Most candidates are replaced before
/// they come up.
void push_cheapest(Candidates& c, std::uint32_t from, Target target);
inline void push_cheapest(const PmMesh& m, Candidates& c, std::uint32_t from) {
  push_cheapest(c, from, cheapest_target(m, c, from));
}

/// A target the self-intersection test refused `from`, until its neighbourhood changes.
void refuse(Candidates& c, std::uint32_t from, std::uint32_t to);
/// Follows log.collapses.back(): the corners of its old star have new neighbourhoods, so the
/// targets refused them are given back.
void forget_refusals(const PmMesh& m, Candidates& c, const CollapseLog& log);

}  // namespace smr::qem
