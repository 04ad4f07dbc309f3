// The self-intersection rule of the QEM builders (unless QemPmOptions::allow_self_intersections): a
// collapse may not make a new triangle cross another triangle, exactly (exact_intersection.h),
// neither in any state of the simplification nor in any cut at one error, which mixes states
// (Brown 4.6.2's object-space criterion at one error selects such a cut; 5.1 extracts it). Live
// and recently dead triangles are found by box (triangle_grid.h).
#pragma once

#include <cstdint>
#include <utility>
#include <vector>

#include "smr/builders/mesh/exact_intersection.h"
#include "smr/builders/mesh/pm_mesh.h"
#include "smr/builders/mesh/qem_pm.h"
#include "smr/builders/mesh/triangle_grid.h"

namespace smr::qem {

// crosses_after()'s buffers.
struct CrossingScratch {
  Marks tri_marks;       // per triangle (the old star)
  Marks collapse_marks;  // per collapse (mark_dependencies)
  std::vector<std::uint32_t> dependency_stack;
  std::vector<MeshTriangle> made;                               // the new star under test
  std::vector<Box3> made_boxes;                                 // its triangles' boxes
  std::vector<std::pair<std::uint32_t, Box3>> near, dead_near;  // live and dead triangles near it
};

// The test's state: the live triangles by box, made at the first test, and the dead ones a
// collapse may still need (crosses_dead in collapse_crossings.cpp): they stay in the grid's set
// kNear while bounds near theirs are still to come (`dead`), then move to its set kArchive
// (retire_dead). A live triangle's grid key is +inf, a dead one's its destroyer's bound, so a
// query with `least` = r * the collapse's bound passes over the dead triangles the test drops.
struct Crossings {
  static constexpr int kNear = 0, kArchive = 1;  // TriangleGrid sets
  bool enabled = false;                          // !QemPmOptions::allow_self_intersections
  double ratio = 0.0;  // QemPmOptions::coalesce_error_ratio (r in crosses_dead)
  TriangleGrid grid;
  bool grid_ready = false;
  std::vector<std::uint32_t> dead;  // the dead triangles still in kNear
  double archive_largest = 0.0;     // the largest bound of the destroyers of kArchive's
  CrossingScratch scratch;
};

/// Whether collapsing from -> to (bound `error`) would make a new triangle cross another
/// triangle of the mesh (one that stays, or another new one) anywhere but in the corners and
/// edges they share (exact_intersection.h), unless a triangle of the old star crossed it
/// already; or cross a dead triangle that a cut at one error can show with it. Such a collapse
/// is refused: a source that does not cross itself gives no level that does, and one that does
/// can still simplify around its crossings (refusing every collapse near them stalled the
/// repaired pig at 258 base triangles). False when the rule is off.
bool crosses_after(Crossings& c, const PmMesh& m, const CollapseLog& log, QemPmStats& stats,
                   std::uint32_t from, std::uint32_t to, double error);

/// Follows log.collapses.back() (just made by collapse_mesh): its old star leaves the live
/// triangles (staying in the grid, dead), its new triangles enter.
void record_collapse(Crossings& c, const PmMesh& m, const CollapseLog& log);

/// Dead triangles stay in the grid while a collapse can still need them (crosses_dead): with
/// bounds b >= `least` to come, one whose destroyer's bound is at most r `least` moves to the
/// archive, which only a collapse of a smaller bound (rare: bounds rise band by band) visits.
/// Nothing before the first test (no grid).
void retire_dead(Crossings& c, const PmMesh& m, const CollapseLog& log, double least);

}  // namespace smr::qem
