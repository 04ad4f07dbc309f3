#include "tests/support/extraction_result.h"

#include <algorithm>

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

std::vector<TriRef> sorted(std::span<const TriRef> triangles) {
  std::vector<TriRef> v(triangles.begin(), triangles.end());
  std::sort(v.begin(), v.end());
  return v;
}

}  // namespace smr::test
