// 3-D meshes: a CRMR from a progressive mesh built by quadric edge collapse (Brown 7.1.2 and
// 4.4.3.3; Hoppe's progressive meshes; Garland & Heckbert's quadric error metric).
//
// Simplification runs half-edge collapses v' -> v (v' disappears, v keeps its source position),
// cheapest quadric cost first within bands of the error bound (a collapse whose bound exceeds
// the band waits for the next one, twice the least bound that waited), under the link condition,
// with no normal flip, boundaries kept (a boundary vertex only moves along its boundary, boundary
// edges carry constraint quadrics) and no component shrunk below a tetrahedron (closed) or a
// triangle (open); at the end all components but one are removed whole, so refinement spawns them
// (Brown 4.4.1, Fig. 4.9d). Reversed, every collapse is a vertex split op: F = the triangles around
// v' before the collapse, PreF = the triangles that replaced them; the op introduces one vertex,
// v'. Because a half-edge collapse keeps source positions, the fully refined mesh is the source
// mesh exactly.
//
// Error: each triangle carries a guaranteed two-sided Hausdorff bound e(T) to the source surface
// (every source point is within e(T) of the triangle it is assigned to, every point of T within
// e(T) of the source). A collapse maps its old star onto the new one, and each new triangle gets
// its own e: backward, its points' distance to the old star plus the old bounds there; forward,
// the source points of each old triangle are handed, cell by cell, to their nearest new triangle,
// whose e rises to the old bound plus that cell's distance. Distances come from the convexity of
// the distance to one triangle over pieces cut by the stars' spoke planes and subdivided (branch
// and bound, the piece's image under the collapse tried first). A collapse's error is the largest
// e of its new triangles and at least the errors of the collapses it depends on. An op's error is
// its members' (or what a spawned component's absence costs), raised to its children's errors,
// so birth_res never falls from parent to child.
//
// Order (Brown 4.4.3.3 reordering): splits are emitted in a topological order of their
// dependencies (a split needs the splits that created its PreF), largest bound first, so the
// mesh error falls as fast as the dependencies allow; optionally a split is coalesced into the
// op of its parents (bounded fragment size).
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <utility>

#include "smr/core/crmr.h"
#include "smr/core/mesh.h"

namespace smr {

struct QemPmOptions {
  /// Stop simplifying when this many vertices remain (0 = as far as the rules allow).
  std::uint64_t base_vertices = 0;
  /// Stop simplifying before a collapse whose bound would exceed this (data units; 0 = none).
  double max_base_error = 0.0;
  /// A collapse may turn no triangle's normal by more than this (degrees).
  double max_normal_turn_degrees = 75.0;
  /// Weight of the boundary constraint planes relative to the face planes.
  double boundary_weight = 100.0;
  /// Coalescing (Brown 4.4.3.3): a split joins the op of its parents when they are one op, the
  /// merged fragment has at most this many triangles and the split's error is at least
  /// coalesce_error_ratio of that op's first split. 0 = one op per vertex split.
  std::uint32_t max_fragment_triangles = 32;
  double coalesce_error_ratio = 0.7;
  /// Collapses go in bands of their bound: the next band's tolerance is this many times the
  /// least bound that waited (at least 1). 0 = no bands, cheapest quadric cost first only: 1.3x
  /// fewer instructions, and 5-12 % more triangles in a 1 px view of the dragon and the
  /// armadillo (bench_mesh_build --bound-band 0; benchmarks/README.md).
  double bound_band = 2.0;
  /// Once simplification has run to its end, remove every component but one (the one whose
  /// removal would cost most): refinement then spawns them (Brown Fig. 4.9d), each inside the op
  /// that follows it in the split order, at the error its absence costs.
  bool spawn_components = true;
  /// false (the default): refuse a collapse that would make a new triangle cross another
  /// triangle (exactly, anywhere but in shared corners and edges), so that simplification
  /// introduces no self-intersection: neither in any state of it nor in any cut at one error,
  /// which mixes states (the triangles a collapse is checked against include recently dead ones;
  /// collapse_crossings.cpp). true: skip that test (faster; coarse levels may then cross
  /// themselves).
  bool allow_self_intersections = false;
  /// Threads computing the bounds of the candidates that come next (0 = one per core). The
  /// result does not depend on it.
  unsigned threads = 0;
  /// Progress in [0, 1]; called at most a few hundred times.
  std::function<void(double)> progress;
};

struct QemPmStats {
  std::uint64_t collapses = 0;  // edge collapses (vertex splits)
  std::uint64_t spawned_components = 0;
  std::uint64_t base_vertices = 0, base_triangles = 0;
  std::uint64_t rejected_link = 0, rejected_flip = 0, rejected_boundary = 0;
  std::uint64_t rejected_intersection = 0;  // collapses refused: a new triangle would cross another
  // Of those, refused because a new triangle would cross a triangle of another level that a cut
  // at one error can show with it (mixed levels; see collapse_crossings.cpp, crosses_dead).
  std::uint64_t rejected_mixed_levels = 0;
  std::uint64_t bounds_computed = 0;  // guaranteed bounds of candidate collapses it needed
  // QemPmOptions::threads > 1: bound computations handed over ahead of time, and those whose
  // result was used (computed by a helper, or by the calling thread when the candidate came up
  // before a helper had started it; the rest: their candidates changed first).
  std::uint64_t bounds_ahead = 0, bounds_ahead_used = 0;
};

// Out of core (docs/design.md section 4; Hoppe 1998's block construction, in 3-D): the triangles
// are sorted by the octree leaf cell of their centroid (an external sort), so each leaf block is
// read on its own. A block is simplified by the collapses above with its locked vertices -- those
// with triangles in another block of its level -- kept, up to a bound of tolerance_fraction of the
// block's side (doubling per level as blocks do; within a block it rises in steps of 2 from an 8th
// of it, and the root's on to the model's size; past it while the block still has more than
// leaf_triangles triangles, so that a block above the leaves holds at most 8 times that), cheapest
// quadric cost first, in independent-set rounds (no two collapses of a round touch, so the DAG
// height is at most the number of rounds). Then 2x2x2 blocks merge, the borders between them unlock
// and simplification goes on, up to the root, which simplifies as far as the rules allow. Every
// collapse goes to the out-of-core assembler (op_assembly.h) as it is made, so ops are ordered and
// linked on disk. Components are not spawned (R^0 keeps each at its smallest) and splits are not
// coalesced.
// Quadrics: each block adds its triangles' planes to their corners and sums what its children
// carried; boundary constraint planes are added when an edge's boundary status is first known (one
// end unlocked), from the triangle then on it.
// Memory: 24 bytes a vertex (positions) and 8 (their octree span), 16 a collapse (the assembler),
// the largest block being simplified and the blocks waiting for their siblings.
struct BlockPmOptions {
  /// Leaf octree cells are made small enough to hold about this many triangles on average.
  std::uint64_t leaf_triangles = 1 << 16;
  /// A level's largest tolerance, as a fraction of its blocks' side. Small, so that a block
  /// stops simplifying near the errors of the collapses its locked border will make one level
  /// up: a border collapse comes after the ones beside it, so in refinement it must be split
  /// before them, and a coarse block interior would keep its border at full resolution in
  /// every cut finer than the interior (a 1 px cut of the armadillo subdivided 3 times had 2x
  /// the triangles of the in-core build at 1/64; at 1/1024 it has fewer, benchmarks/README.md).
  double tolerance_fraction = 1.0 / 1024.0;
  double max_normal_turn_degrees = 75.0;
  double boundary_weight = 100.0;
  /// QemPmOptions::allow_self_intersections, within each block (blocks meet at locked borders).
  bool allow_self_intersections = false;
  /// Memory of the external sort of the triangles by octree leaf cell (beyond it, sorted runs
  /// spill to scratch files). smr/ingest/memory_budget.h gives it its share of a budget.
  std::uint64_t face_sort_bytes = std::uint64_t{128} << 20;
  /// Memory of the assembly's external sorts (AssemblyOptions::sort_bytes).
  std::uint64_t assembly_sort_bytes = std::uint64_t{128} << 20;
  /// Resident memory of the assembly's per-collapse tables (AssemblyOptions::table_bytes; 0 =
  /// in memory).
  std::uint64_t assembly_table_bytes = 0;
  /// Scratch files' directory (empty = the system's temporary directory).
  std::string tmp_dir;
  /// Threads simplifying leaf blocks (0 = one per core); the database does not depend on it.
  /// Each holds one leaf block being simplified (and one more waits per thread).
  unsigned threads = 0;
  std::function<void(double)> progress;
};

struct BlockPmStats {
  int levels = 0;  // octree levels above the leaves (the root is the last)
  std::uint64_t leaf_blocks = 0, vertices = 0, triangles = 0;
  std::uint64_t collapses = 0, rounds = 0, dag_height = 0;
  std::uint64_t base_vertices = 0, base_triangles = 0;
  std::uint64_t rejected_intersection = 0;  // collapses refused: a new triangle would cross
  std::uint64_t max_block_triangles = 0;    // largest block simplified
  std::uint64_t max_handed_triangles = 0;   // most triangles a block handed its parent
  std::uint64_t temp_bytes = 0;
  double seconds_sort = 0, seconds_blocks = 0, seconds_assemble = 0;
  // Of seconds_blocks: the blocks simplified after the last leaf (serial, on one thread).
  double seconds_tail = 0;
  double seconds_join = 0, seconds_emit = 0;  // the assembly's parts (AssemblyStats)
};

/// Builds the CRMR of `mesh` block by block into `sink` (ops in id order). Throws smr::Error on
/// an empty mesh, an index out of range or unusable options.
void build_block_pm(const MeshStream& mesh, OpSink& sink, const BlockPmOptions& options = {},
                    BlockPmStats* stats = nullptr);
Crmr build_block_pm(const MeshStream& mesh, const BlockPmOptions& options = {},
                    BlockPmStats* stats = nullptr);

/// Builds the CRMR of `mesh` (a validated manifold, consistently oriented mesh: smr/io's
/// read_mesh output). `name` is recorded as the source. Throws smr::Error on an empty mesh.
Crmr build_qem_pm(const TriangleMesh& mesh, const std::string& name,
                  const QemPmOptions& options = {}, QemPmStats* stats = nullptr);

}  // namespace smr
