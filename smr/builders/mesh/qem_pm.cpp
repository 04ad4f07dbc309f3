// Quadric edge collapse into a CRMR (qem_pm.h; Garland & Heckbert 1997's quadrics, Hoppe 1996's
// progressive mesh reversed into vertex-split ops, Brown 7.1.2). The driver of two passes:
//  1. simplify (qem_simplify.h): half-edge collapses from a lazy priority queue (one best
//     candidate per vertex, re-validated when popped, collapse_rules.h; refused when its new
//     triangles would cross the mesh, collapse_crossings.h) in bands of their guaranteed bound
//     (collapse_bound.h), recording for each collapse the triangles it removed and made
//     (pm_mesh.h); then every component but one removed (spawn_components.h);
//  2. emit (pm_emit.h): order the reversed collapses (vertex splits) topologically, largest
//     error first (Brown 4.4.3.3), and replay them from the base mesh to assign triangles to
//     ops and find each fragment boundary edge's closest coarser version (Brown 4.5.1).
// The out-of-core builder, build_block_pm, is block_pm.h.
#include "smr/builders/mesh/qem_pm.h"

#include <cmath>
#include <string>
#include <vector>

#include "base/error.h"
#include "smr/builders/mesh/qem_simplify.h"
#include "smr/builders/mesh/spawn_components.h"
#include "smr/builders/pm_emit.h"

namespace smr {
namespace {

void check_options(const TriangleMesh& mesh, const std::string& name, const QemPmOptions& options) {
  if (mesh.triangles.empty()) throw_input("mesh '" + name + "' has no triangles");
  if (!(options.max_normal_turn_degrees > 0.0 && options.max_normal_turn_degrees <= 180.0)) {
    throw_input("QEM PM: max normal turn must be in (0, 180] degrees");
  }
  if (!(options.coalesce_error_ratio >= 0.0 && options.coalesce_error_ratio <= 1.0)) {
    throw_input("QEM PM: the coalescing error ratio must be in [0, 1]");
  }
  if (!(options.bound_band == 0.0 ||
        (options.bound_band >= 1.0 && std::isfinite(options.bound_band)))) {
    throw_input("QEM PM: the bound band must be 0 (none) or a finite factor of at least 1");
  }
}

// The CRMR's header but err0 (emit's): the model's vertices, the builder's parameters.
CrmrInfo header_of(const qem::PmMesh& m, const std::string& name, const QemPmOptions& o) {
  CrmrInfo h;
  h.kind = ModelKind::kMesh3d;
  h.source = name;
  h.err_final = 0.0;
  for (std::uint32_t v = 0; v < m.pos.size(); ++v) {
    if (m.comp[v] != qem::kNone) {
      h.bounds.add(m.pos[v]);
      ++h.vertex_count;
    }
  }
  h.builder = "qem-pm max-normal-turn=" + std::to_string(o.max_normal_turn_degrees) +
              " coalesce=" + std::to_string(o.max_fragment_triangles) +
              " coalesce-ratio=" + std::to_string(o.coalesce_error_ratio) +
              " boundary-weight=" + std::to_string(o.boundary_weight) +
              " base-vertices=" + std::to_string(o.base_vertices) +
              " max-base-error=" + std::to_string(o.max_base_error) +
              " bound-band=" + std::to_string(o.bound_band) +
              " no-self-intersections=" + (o.allow_self_intersections ? "no" : "yes");
  return h;
}

}  // namespace

Crmr build_qem_pm(const TriangleMesh& mesh, const std::string& name, const QemPmOptions& options,
                  QemPmStats* stats) {
  check_options(mesh, name, options);
  qem::Simplification s;
  const std::vector<std::uint32_t> source_id =
      qem::load_source(s.mesh, mesh, options.boundary_weight);
  qem::init_simplification(s, options);
  const bool exhausted = qem::simplify_bands(s, options);
  if (options.spawn_components && exhausted) qem::remove_components(s.mesh, s.log, s.stats);
  const qem::PmHistory history{s.mesh.pos,      source_id,      s.mesh.tris,
                               s.log.collapses, s.log.old_tris, s.log.new_tris};
  qem::EmitOptions eo;
  eo.max_fragment_triangles = options.max_fragment_triangles;
  eo.coalesce_error_ratio = options.coalesce_error_ratio;
  eo.threads = options.threads;
  eo.progress = options.progress;
  eo.progress_begin = 0.8;
  eo.progress_share = 0.15;
  Crmr crmr = qem::emit_pm(history, header_of(s.mesh, name, options), eo);
  if (options.progress) options.progress(1.0);
  if (stats != nullptr) {
    s.stats.collapses = s.log.collapses.size() - s.stats.spawned_components;
    s.stats.bounds_computed = s.scratch.computed;
    s.stats.base_triangles = crmr.ops[0].fragment.size();
    s.stats.base_vertices = crmr.ops[0].vertices.size();
    *stats = s.stats;
  }
  return crmr;
}

}  // namespace smr
