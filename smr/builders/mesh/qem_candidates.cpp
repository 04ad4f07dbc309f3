// Candidate collapses, cheapest quadric cost first (Garland & Heckbert 1997, section 4;
// qem_candidates.h).
#include "smr/builders/mesh/qem_candidates.h"

#include <algorithm>
#include <string>

#include "base/error.h"
#include "smr/builders/mesh/collapse_rules.h"

namespace smr::qem {
namespace {

// c.ranked = (cost, target) for the neighbours of `from` (c.cand) that the self-intersection
// test has not refused since its neighbourhood last changed; false when `from` cannot collapse.
bool rank_targets(const PmMesh& m, Candidates& c, std::uint32_t from) {
  if (m.removed[from] || is_locked(m, from)) return false;
  neighbours(m, c.marks, from, c.cand);
  c.ranked.clear();
  const std::vector<std::uint32_t>& blocked = c.blocked[from];
  for (std::uint32_t to : c.cand) {
    if (std::find(blocked.begin(), blocked.end(), to) == blocked.end())
      c.ranked.push_back({cost(m, from, to), to});
  }
  return true;
}

}  // namespace

void init_candidates(Candidates& c, std::size_t n, double max_normal_turn_degrees) {
  c.stamp.assign(n, 0);
  c.marks.of.assign(n, 0);
  c.blocked.assign(n, {});
  c.cheapest.assign(n, kUnknown);
  c.cos_max_turn = max_turn_cosine(max_normal_turn_degrees);
}

bool valid(const PmMesh& m, Candidates& c, QemPmStats& stats, std::uint32_t from,
           std::uint32_t to) {
  neighbours(m, c.marks, from, c.nf);
  return collapse_allowed(m, c.marks, c.cos_max_turn, from, to, c.nf, stats);
}

Target cheapest_valid(const PmMesh& m, Candidates& c, QemPmStats& stats, std::uint32_t from,
                      std::uint32_t failed) {
  if (!rank_targets(m, c, from)) return {0.0, kNone};
  std::sort(c.ranked.begin(), c.ranked.end());
  for (const auto& [cst, to] : c.ranked) {
    if (to != failed && collapse_allowed(m, c.marks, c.cos_max_turn, from, to, c.cand, stats))
      return {cst, to};
  }
  return {0.0, kNone};
}

Target cheapest_target(const PmMesh& m, Candidates& c, std::uint32_t from) {
  Target first = kUnknown;
  if (rank_targets(m, c, from)) {
    for (const auto& r : c.ranked) {
      if (!is_locked(m, r.second) && (first.second == kNone || r < first)) first = r;
    }
  }
  return c.cheapest[from] = first;
}

Target cheapest_after(const PmMesh& m, Candidates& c, std::uint32_t w, std::uint32_t removed,
                      std::uint32_t kept) {
  Target& last = c.cheapest[w];
  const std::vector<std::uint32_t>& refused = c.blocked[w];
  if (last.second == kNone || last.second == removed || last.second == kept ||
      std::find(refused.begin(), refused.end(), kept) != refused.end()) {
    return cheapest_target(m, c, w);
  }
  last = std::min(last, {cost(m, w, kept), kept});
  if (kSelfChecks) {
    const Target found = last;
    if (cheapest_target(m, c, w) != found)
      throw_internal("QEM PM: vertex " + std::to_string(w) +
                     "'s cheapest target after a collapse beside it is not the one in full");
  }
  return last;
}

void push_best(const PmMesh& m, Candidates& c, QemPmStats& stats, std::uint32_t from,
               std::uint32_t failed) {
  ++c.stamp[from];
  const auto [cst, to] = cheapest_valid(m, c, stats, from, failed);
  if (to != kNone) c.heap.push({cst, from, to, c.stamp[from]});
}

void push_cheapest(Candidates& c, std::uint32_t from, Target target) {
  ++c.stamp[from];
  if (target.second != kNone) c.heap.push({target.first, from, target.second, c.stamp[from]});
}

void refuse(Candidates& c, std::uint32_t from, std::uint32_t to) {
  c.blocked[from].push_back(to);
  c.cheapest[from] = kUnknown;
}

void forget_refusals(const PmMesh& m, Candidates& c, const CollapseLog& log) {
  const Collapse& col = log.collapses.back();
  for (std::uint32_t k = col.old_begin; k < col.old_end; ++k) {
    for (std::uint32_t w : m.tris[log.old_tris[k]].v) {  // their neighbourhoods change
      if (!c.blocked[w].empty()) {
        c.blocked[w].clear();
        c.cheapest[w] = kUnknown;  // the targets given back were not among those ranked
      }
    }
  }
}

}  // namespace smr::qem
