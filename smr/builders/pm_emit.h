// Emit: a simplification's collapse log, reversed, as a CRMR (Brown 4.4.3.3, fragment
// reordering): the splits (reversed collapses) in a topological order of their dependencies,
// largest error first, so the mesh error falls as fast as the dependencies allow and birth_res
// is monotone; optionally coalesced into the op of their parents (Brown Fig. 4.12b, bounded
// fragment size); then replayed from the base mesh to give each op its fragment F, its PreF and
// each fragment boundary edge's closest coarser version (Brown 4.5.1). A build stage any builder
// whose steps are local replacements of triangles can hand its log to (docs/design.md section 4).
#pragma once

#include <cstdint>
#include <functional>
#include <span>

#include "smr/builders/mesh/pm_mesh.h"
#include "smr/core/crmr.h"

namespace smr::qem {

// What emit reads: every triangle ever made (its creator and destroyer among the collapses;
// kNone for a source triangle, or one in the base mesh), the collapses in the order they were
// made (a "collapse" replaces the triangles old_tris[old_begin, old_end) by
// new_tris[new_begin, new_end); one with kept == kNone removes a component, spawned by its
// split, Brown 4.4.1 Fig. 4.9d) and the vertices' positions.
struct PmHistory {
  std::span<const Vec3> pos;
  std::span<const std::uint32_t> source_id;  // vertex -> the id ops name (empty: the same)
  std::span<const Tri> tris;
  std::span<const Collapse> collapses;
  std::span<const std::uint32_t> old_tris, new_tris;
};

struct EmitOptions {
  /// Coalescing (QemPmOptions::max_fragment_triangles, coalesce_error_ratio): 0 = one op per
  /// split.
  std::uint32_t max_fragment_triangles = 0;
  double coalesce_error_ratio = 0.0;
  /// Threads making the ops' fragments (0 = one per core); the result does not depend on it.
  unsigned threads = 0;
  /// Called with progress_begin + progress_share * (the fraction of ops linked).
  std::function<void(double)> progress;
  double progress_begin = 0.0, progress_share = 1.0;
};

/// The CRMR of `history`: `header` as given (kind, source, builder, bounds, vertex count,
/// err_final), with err0 set here (the base mesh's bounds, and no less than any op's error). An
/// op's error is its splits' largest, raised to its children's.
Crmr emit_pm(const PmHistory& history, const CrmrInfo& header, const EmitOptions& options);

}  // namespace smr::qem
