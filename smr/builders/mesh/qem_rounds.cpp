// Independent-set rounds of collapses (qem_rounds.h; De Floriani et al.'s independent-set
// decimation; Garland & Heckbert 1997's cost order within a round).
#include "smr/builders/mesh/qem_rounds.h"

#include <algorithm>
#include <utility>

#include "smr/builders/mesh/collapse_rules.h"

namespace smr::qem {
namespace {

void set_best(const PmMesh& m, Rounds& r, std::uint32_t v, double c, std::uint32_t to,
              bool validated) {
  Best& b = r.best[v];
  b = Best{};
  b.cost = c;
  b.to = to;
  b.validated = validated;
  if (to != kNone) b.versions = {m.star_version[v], m.star_version[to]};
}

// Whether b's collapse of v is known valid without testing it again: collapse_allowed() read
// the stars of v and its target (positions, locks and boundary flags do not change), neither
// has changed since it passed, and v's component still has more vertices than the test's
// limit. A vertex whose star changes gets a new target before the next round (dirty, moved), so
// the test is repeated only where the target's star changed (a collapse beside the target, not
// beside v: that cannot break v's link condition, and on the subdivided dragon the 12 564
// repeats all pass). The rounds' choices are the same as with the test (databases
// byte-identical); 2 % less CPU.
bool still_valid(const PmMesh& m, std::uint32_t v, const Best& b) {
  return b.validated && b.versions[0] == m.star_version[v] &&
         b.versions[1] == m.star_version[b.to] && component_can_shrink(m, v);
}

// New targets for the vertices beside the last round's collapses (moved: their cheapest target
// by cost, not tested yet) and for the dirty ones (after: a dirty vertex may undo a move), then
// the vertices whose collapse is within `tolerance`, cheapest first.
void rank_round(Simplification& s, Rounds& r, double tolerance,
                std::vector<std::pair<double, std::uint32_t>>& cands) {
  for (const Moved& mv : r.moved) {
    const auto [c, to] = cheapest_after(s.mesh, s.cand, mv.w, mv.removed, mv.kept);
    set_best(s.mesh, r, mv.w, c, to, false);
  }
  r.moved.clear();
  for (std::uint32_t v : r.dirty) {
    const auto [c, to] = cheapest_target(s.mesh, s.cand, v);
    set_best(s.mesh, r, v, c, to, false);
  }
  r.dirty.clear();
  cands.clear();
  for (std::uint32_t v = 0; v < s.mesh.pos.size(); ++v) {
    const Best& b = r.best[v];
    if (b.to == kNone || s.mesh.removed[v] || (b.have_error ? b.error : b.lower) > tolerance)
      continue;
    cands.push_back({b.cost, v});
  }
  std::sort(cands.begin(), cands.end());
}

// v's turn in the round (its target's collapse within `tolerance`, if valid): whether it was
// made. `reranked` counts the vertices that took their cheapest valid target instead.
bool take(Simplification& s, Rounds& r, std::uint32_t v, double tolerance,
          std::uint64_t& reranked) {
  PmMesh& m = s.mesh;
  Best& b = r.best[v];
  neighbours(m, s.cand.marks, v, s.cand.ring);
  if (!still_valid(m, v, b) &&
      !collapse_allowed(m, s.cand.marks, s.cand.cos_max_turn, v, b.to, s.cand.ring, s.stats)) {
    if (b.validated) {
      r.dirty.push_back(v);
    } else {  // its cheapest target fails: its cheapest valid one, from the next round
      const auto [cheapest, to] = cheapest_valid(m, s.cand, s.stats, v, b.to);
      set_best(m, r, v, cheapest, to, true);
      ++reranked;
    }
    return false;
  }
  b.validated = true;
  if (!b.have_error) {
    const auto [error, exact] = bound_within(m, s.log, v, b.to, tolerance, true, s.scratch);
    if (!exact) {  // a lower bound is already too large: it waits while its star stays
      b.lower = error;
      return false;
    }
    b.error = error;
    b.new_e = s.scratch.new_e;
    b.have_error = true;
  }
  if (b.error > tolerance) return false;
  if (crosses_after(s.cross, m, s.log, s.stats, v, b.to, b.error)) {
    refuse(s.cand, v, b.to);
    r.dirty.push_back(v);
    return false;
  }
  const std::uint32_t to = b.to;
  apply_collapse(s, v, to, b.error, b.new_e);
  b = Best{};
  r.dirty.push_back(to);
  neighbours(m, s.cand.marks, to, s.cand.ring);
  for (std::uint32_t w : s.cand.ring) r.moved.push_back({w, v, to});
  // A collapse v -> to takes v, to and their rings (the new ring of `to`); a candidate may not
  // touch a taken vertex's star, so it is refused when it or its target is in the new 2-ring
  // of a collapse made in this round. That set is marked once per collapse (stars of taken
  // vertices do not change in the round: no later collapse is beside one).
  r.taken[v] = r.taken[to] = r.taken_stamp;
  for (std::uint32_t w : s.cand.ring) {
    for (std::uint32_t id : m.star[w]) {
      for (std::uint32_t u : m.tris[id].v) r.taken[u] = r.taken_stamp;
    }
  }
  return true;
}

}  // namespace

std::uint64_t simplify_rounds(Simplification& s, Rounds& r, double tolerance) {
  const std::size_t n = s.mesh.pos.size();
  retire_dead(s.cross, s.mesh, s.log, r.last_tolerance);  // the rounds of the last call
  r.last_tolerance = tolerance;
  if (r.best.size() != n) {
    r.best.assign(n, Best{});
    for (std::uint32_t v = 0; v < n; ++v) r.dirty.push_back(v);
    r.taken.assign(n, 0);
  }
  std::uint64_t rounds = 0;
  std::vector<std::pair<double, std::uint32_t>> cands;
  for (;;) {
    rank_round(s, r, tolerance, cands);
    ++r.taken_stamp;
    std::uint64_t made = 0, reranked = 0;
    const auto near_taken = [&](std::uint32_t x) { return r.taken[x] == r.taken_stamp; };
    for (const auto& [c, v] : cands) {
      if (s.mesh.removed[v] || near_taken(v) || near_taken(r.best[v].to)) continue;
      if (take(s, r, v, tolerance, reranked)) ++made;
    }
    std::sort(r.dirty.begin(), r.dirty.end());
    r.dirty.erase(std::unique(r.dirty.begin(), r.dirty.end()), r.dirty.end());
    if (made == 0 && r.dirty.empty() && reranked == 0) return rounds;
    if (made != 0) ++rounds;
  }
}

}  // namespace smr::qem
