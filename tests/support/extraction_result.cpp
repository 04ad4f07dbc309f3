#include "tests/support/extraction_result.h"

namespace smr::test {

Result extract_all(const OpSource& source, const RcfSpec& spec) {
  const Rcf rcf = make_rcf(spec, ModelKind::kTerrain, nullptr);
  Result r;
  r.minimal = extract_minimal_surface(source, rcf);
  r.reduced = extract_reduced(source, rcf);
  r.mesh = to_mesh(source, r.minimal.triangles);
  return r;
}

bool same(const Result& a, const Result& b) {
  return a.minimal.x == b.minimal.x && a.minimal.triangles == b.minimal.triangles &&
         a.reduced.x == b.reduced.x && a.reduced.triangles == b.reduced.triangles &&
         a.mesh.positions == b.mesh.positions && a.mesh.triangles == b.mesh.triangles;
}

}  // namespace smr::test
