// 3-D meshes: a CRMR from a progressive mesh built by quadric edge collapse (Brown 7.1.2 and
// 4.4.3.3; Hoppe's progressive meshes; Garland & Heckbert's quadric error metric).
//
// Simplification runs half-edge collapses v' -> v (v' disappears, v keeps its source position),
// cheapest quadric cost first, under the link condition, with no normal flip, boundaries kept
// (a boundary vertex only moves along its boundary, boundary edges carry constraint quadrics) and
// no component shrunk below a tetrahedron (closed) or a triangle (open); at the end all
// components but one are removed whole, so refinement spawns them (Brown 4.4.1, Fig. 4.9d).
// Reversed, every collapse is a vertex split op: F = the triangles around v' before the collapse,
// PreF = the triangles that replaced them; the op introduces one vertex, v'. Because a half-edge
// collapse keeps source positions, the fully refined mesh is the source mesh exactly.
//
// Error: each triangle carries a guaranteed two-sided Hausdorff bound e(T) to the source surface
// (every source point is within e(T) of the triangle it is assigned to, every point of T within
// e(T) of the source). A collapse maps its old star onto the new one; e of the new triangles is
// the old bound plus an upper bound of the distance between the two stars, computed from the
// convexity of the distance to one triangle over subdivided pieces (branch and bound, the
// piece's image under the collapse tried first). An op's error is its own bound (the largest e of
// its PreF triangles, or what a spawned component's absence costs), raised to its children's
// errors, so birth_res never falls from parent to child.
//
// Order (Brown 4.4.3.3 reordering): splits are emitted in a topological order of their
// dependencies (a split needs the splits that created its PreF), largest bound first, so the
// mesh error falls as fast as the dependencies allow; optionally a split is coalesced into the
// op of its parents (bounded fragment size).
#pragma once

#include <cstdint>
#include <functional>
#include <string>

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
  /// Once simplification has run to its end, remove every component but one (the one whose
  /// removal would cost most): refinement then spawns them (Brown Fig. 4.9d), each inside the op
  /// that follows it in the split order, at the error its absence costs.
  bool spawn_components = true;
  /// Progress in [0, 1]; called at most a few hundred times.
  std::function<void(double)> progress;
};

struct QemPmStats {
  std::uint64_t collapses = 0;  // edge collapses (vertex splits)
  std::uint64_t spawned_components = 0;
  std::uint64_t base_vertices = 0, base_triangles = 0;
  std::uint64_t rejected_link = 0, rejected_flip = 0, rejected_boundary = 0;
};

/// Builds the CRMR of `mesh` (a validated manifold, consistently oriented mesh: smr/io's
/// read_mesh output). `name` is recorded as the source. Throws smr::Error on an empty mesh.
Crmr build_qem_pm(const TriangleMesh& mesh, const std::string& name,
                  const QemPmOptions& options = {}, QemPmStats* stats = nullptr);

}  // namespace smr
