// The in-core simplification loop (qem_simplify.h): Garland & Heckbert 1997's greedy order
// (section 4) in bands of the guaranteed bound, with bounds computed ahead on helper threads
// (bound_ahead.h).
#include "smr/builders/mesh/qem_simplify.h"

#include <algorithm>
#include <limits>

#include "smr/builders/mesh/bound_ahead.h"
#include "smr/core/parallel.h"

namespace smr::qem {
namespace {

struct Waiting {
  Candidate c;
  double error;
};

// The bands: the current tolerance, the candidates waiting for a later band and, per vertex, the
// bound its candidate last waited with.
struct Bands {
  double tolerance = 0.0;
  std::vector<Waiting> waiting;
  std::vector<Waited> waited;
};

bool current(const PmMesh& m, const Candidates& c, const Candidate& top) {
  return !m.removed[top.from] && top.stamp == c.stamp[top.from];
}

// The heap ran out: the next band's tolerance is `bound_band` times the least bound that
// waited; the waiting candidates within it go back into the heap. False when none is current:
// nothing is left to collapse.
bool next_band(Simplification& s, Bands& b, double bound_band) {
  double least = std::numeric_limits<double>::infinity();
  for (const Waiting& w : b.waiting) {
    if (current(s.mesh, s.cand, w.c)) least = std::min(least, w.error);
  }
  if (least == std::numeric_limits<double>::infinity()) {
    b.waiting.clear();  // only stale entries
    return false;
  }
  retire_dead(s.cross, s.mesh, s.log, b.tolerance);  // the band that ended
  b.tolerance = bound_band * least;
  // Those still above it would only come up to wait again.
  std::size_t kept = 0;
  for (const Waiting& w : b.waiting) {
    if (!current(s.mesh, s.cand, w.c)) continue;
    if (w.error > b.tolerance) {
      b.waiting[kept++] = w;
    } else {
      Candidate c = w.c;
      c.looked = false;  // a new band
      s.cand.heap.push(c);
    }
  }
  b.waiting.resize(kept);
  return true;
}

// The current candidate `top` (its target not removed) comes up: collapsed if its bound is
// within the band and it passes the rules, else it waits, is given up or replaced by from's
// next target. Returns whether it was collapsed.
bool take(Simplification& s, Bands& b, AheadState& ahead, const QemPmOptions& o,
          const Candidate& top) {
  PmMesh& m = s.mesh;
  Candidates& c = s.cand;
  // The bound, or a lower bound of it when that already exceeds the band (bound_within).
  Waited& w = b.waited[top.from];
  double error = w.error;
  bool known = w.to == top.to && w.stamp == top.stamp;
  if (error <= b.tolerance) {
    known = true;
    error = ahead.threads
                ? bound_ahead(ahead, m, s.log, c, s.scratch, s.stats, top, b.tolerance, b.waited)
                : bound_within(m, s.log, top.from, top.to, b.tolerance, false, s.scratch).first;
  }
  // Validity is tested only once the collapse is to be made or `from` given up: 80 % of the
  // candidates that come up wait here for a later band instead (the bunny: 163 k of 206 k),
  // and their stars change meanwhile. An infinite bound (no new star) is never valid.
  const bool never = error == std::numeric_limits<double>::infinity();
  if (never || (known && o.max_base_error > 0.0 && error > o.max_base_error)) {
    if (never || !valid(m, c, s.stats, top.from, top.to)) {
      push_best(m, c, s.stats, top.from, top.to);
    } else {
      ++c.stamp[top.from];  // given up; retried only when its neighbourhood changes
    }
    return false;
  }
  if (error > b.tolerance) {
    if (known) w = {top.stamp, top.to, error};
    b.waiting.push_back({top, error});
    return false;
  }
  if (!valid(m, c, s.stats, top.from, top.to)) {
    push_best(m, c, s.stats, top.from, top.to);
    return false;
  }
  if (crosses_after(s.cross, m, s.log, s.stats, top.from, top.to, error)) {
    refuse(c, top.from, top.to);
    push_best(m, c, s.stats, top.from);
    return false;
  }
  apply_collapse(s, top.from, top.to, error, s.scratch.new_e);
  neighbours(m, c.marks, top.to, c.ring);
  const std::vector<std::uint32_t> ring = c.ring;
  push_cheapest(m, c, top.to);
  for (std::uint32_t r : ring) push_cheapest(c, r, cheapest_after(m, c, r, top.from, top.to));
  return true;
}

}  // namespace

void init_simplification(Simplification& s, const QemPmOptions& options) {
  init_candidates(s.cand, s.mesh.pos.size(), options.max_normal_turn_degrees);
  s.cross.enabled = !options.allow_self_intersections;
  s.cross.ratio = options.coalesce_error_ratio;
}

void apply_collapse(Simplification& s, std::uint32_t from, std::uint32_t to, double error,
                    const std::vector<double>& new_e) {
  collapse_mesh(s.mesh, s.log, from, to, error, new_e);
  record_collapse(s.cross, s.mesh, s.log);
  forget_refusals(s.mesh, s.cand, s.log);
}

bool simplify_bands(Simplification& s, const QemPmOptions& o) {
  PmMesh& m = s.mesh;
  Candidates& c = s.cand;
  const std::size_t n = m.pos.size();
  for (std::uint32_t v = 0; v < n; ++v) push_cheapest(m, c, v);
  const std::uint64_t start = alive_vertices(m);
  std::uint64_t alive = start;
  std::uint64_t next_report = 0;
  Bands b;
  b.tolerance = o.bound_band > 0.0 ? 0.0 : std::numeric_limits<double>::infinity();
  b.waited.resize(n);
  AheadState ahead;  // bounds computed ahead (none: one thread)
  if (thread_count(o.threads) > 1 && n > kAhead) {
    start_ahead(ahead, thread_count(o.threads) - 1, n);
  }
  while (alive > o.base_vertices) {
    if (c.heap.empty()) {
      if (!next_band(s, b, o.bound_band)) break;
      continue;
    }
    const Candidate top = c.heap.top();
    c.heap.pop();
    if (!current(m, c, top)) continue;
    if (m.removed[top.to]) {
      push_best(m, c, s.stats, top.from, top.to);
      continue;
    }
    if (!take(s, b, ahead, o, top)) continue;
    --alive;
    if (o.progress && start - alive >= next_report) {
      o.progress(0.8 * double(start - alive) / double(start));
      next_report += std::max<std::uint64_t>(1, start / 200);
    }
  }
  return c.heap.empty() && b.waiting.empty() && o.max_base_error == 0.0;
}

}  // namespace smr::qem
