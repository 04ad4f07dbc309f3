// The in-core QEM simplification (qem_pm.h): half-edge collapses cheapest quadric cost first
// (Garland & Heckbert 1997, section 4; Hoppe 1996's progressive mesh construction)
// within bands of their guaranteed error bound, under the collapse rules; and the state one
// simplification holds, by concern, shared with the block builder (block_pm.cpp).
#pragma once

#include <cstdint>
#include <vector>

#include "smr/builders/mesh/collapse_bound.h"
#include "smr/builders/mesh/collapse_crossings.h"
#include "smr/builders/mesh/pm_mesh.h"
#include "smr/builders/mesh/qem_candidates.h"
#include "smr/builders/mesh/qem_pm.h"

namespace smr::qem {

// One simplification's state: the mesh and its collapse log, the candidates, the
// self-intersection test's grids and the calling thread's bound buffers. Each kernel takes the
// parts it reads and writes.
struct Simplification {
  PmMesh mesh;
  CollapseLog log;
  Candidates cand;
  Crossings cross;
  BoundScratch scratch;
  QemPmStats stats;
};

/// The candidates' and the crossing test's state for s.mesh (loaded) under `options`.
void init_simplification(Simplification& s, const QemPmOptions& options);

/// Collapses from -> to (bound `error`, new triangles' bounds `new_e`): the mesh, the crossing
/// test's grid and the candidates' refusals follow.
void apply_collapse(Simplification& s, std::uint32_t from, std::uint32_t to, double error,
                    const std::vector<double>& new_e);

/// Cheapest quadric cost first, in bands of the bound: a collapse whose bound exceeds the
/// band's tolerance waits for the next band (QemPmOptions::bound_band times the least bound
/// that waited). A collapse's bound is at least those of the collapses it depends on, so one
/// early large bound would raise every later one in its region; in bands, small bounds go first
/// (the block builder's rising tolerances do the same). Stops at options.base_vertices or
/// max_base_error; returns whether it went as far as the rules allow.
bool simplify_bands(Simplification& s, const QemPmOptions& options);

}  // namespace smr::qem
