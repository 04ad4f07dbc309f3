// Independent-set rounds of collapses for the block builder (block_pm.h; De Floriani et al.'s
// independent-set decimation, "Level of Detail models, part two": no two simplifications of a
// round touch, so the DAG's height is at most the number of rounds), cheapest quadric cost first
// (Garland & Heckbert 1997, section 4) under a bound tolerance.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "smr/builders/mesh/qem_simplify.h"

namespace smr::qem {

// Per vertex: its target, the cheapest by cost (tested when it comes up), and that collapse's
// bound once computed.
struct Best {
  double cost = 0.0, error = 0.0;
  double lower = 0.0;         // a lower bound of the error once one exceeded the tolerance
  std::vector<double> new_e;  // the bounds of the new triangles (BoundScratch::new_e)
  std::uint32_t to = kNone;
  std::array<std::uint32_t, 2> versions{};  // star_version of v and `to` when chosen
  bool have_error = false;
  bool validated = false;  // collapse_allowed() passed for `to` (at `versions`)
};

// A vertex of the ring around `kept` after the collapse removed -> kept.
struct Moved {
  std::uint32_t w, removed, kept;
};

// What the rounds keep between calls (one block's).
struct Rounds {
  std::vector<Best> best;            // per vertex
  std::vector<std::uint32_t> dirty;  // vertices whose target is to be found again
  std::vector<Moved> moved;          // vertices beside a collapse (cheapest_after)
  std::vector<std::uint32_t> taken;  // per vertex: taken_stamp when taken
  std::uint32_t taken_stamp = 0;
  double last_tolerance = 0.0;  // the last call's
};

/// Rounds of collapses whose bound is at most `tolerance`, cheapest quadric cost first; in a
/// round no two collapses touch (each takes its two vertices and their neighbours), so none
/// depends on another of its round and the DAG height is at most the number of rounds. Each
/// vertex keeps its cheapest target and that collapse's bound between calls; both are
/// recomputed only when its neighbourhood changes. The target is the cheapest by cost alone
/// until the vertex comes up in a round: only then is the collapse tested (collapse_allowed()),
/// and when it fails the vertex takes its cheapest valid target from the next round on. A star
/// changes about ten times before its vertex comes up (4.3 M refreshes for 416 k collapses on
/// the 832 k armadillo), and testing each time cost 6 M tests: 10 % of the CPU, saved; the cuts'
/// triangle counts move by under 1.2 % either way. Returns the rounds that made a collapse.
std::uint64_t simplify_rounds(Simplification& s, Rounds& r, double tolerance);

}  // namespace smr::qem
