// Brown 5.1 and 5.2: the two SMR algorithms, the set formula of Lemma 5.1.1, and mesh output.
#include "smr/extract/extract.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <unordered_map>
#include <unordered_set>

#include "smr/extract/expansion.h"
#include "storage/error.h"

namespace smr {

namespace {
double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}
}  // namespace

Extraction expand(const OpSource& source, std::span<const OpId> x,
                  const ExpansionOptions& options) {
  return run_expansion(source, x, false, options);
}

Extraction extract_minimal_surface(const OpSource& source, const Rcf& rcf,
                                   const ExpansionOptions& options) {
  auto t0 = std::chrono::steady_clock::now();
  const std::vector<OpId> x = add_to_list(source, rcf);
  const double t_extract = seconds_since(t0);
  t0 = std::chrono::steady_clock::now();
  Extraction e = run_expansion(source, x, false, options);
  e.stats.expand_seconds = seconds_since(t0);
  e.stats.extract_seconds = t_extract;
  return e;
}

Extraction extract_reduced(const OpSource& source, const Rcf& rcf,
                           const ExpansionOptions& options) {
  if (source.info().kind != ModelKind::kTerrain) {
    // Its starting-point test compares xy-domains (Brown 5.2: 2.5-D models).
    throw_input(
        "reduced extraction is defined for 2.5-D terrains (Brown 5.2); use the minimal "
        "surface algorithm for 3-D meshes");
  }
  auto t0 = std::chrono::steady_clock::now();
  const std::vector<OpId> x = add_to_list_reduced(source, rcf);
  const double t_extract = seconds_since(t0);
  t0 = std::chrono::steady_clock::now();
  Extraction e = run_expansion(source, x, true, options);
  e.stats.expand_seconds = seconds_since(t0);
  e.stats.extract_seconds = t_extract;
  e.stats.x = x.size();
  return e;
}

std::vector<TriRef> set_formula(const OpSource& source, std::span<const OpId> x) {
  std::unordered_set<TriRef> replaced;
  for (OpId id : x) {
    for (const TriRef& t : source.op(id)->pre) replaced.insert(t);
  }
  std::vector<TriRef> out;
  for (OpId id : x) {
    const OpRef op_ref = source.op(id);
    const Op& op = *op_ref;
    for (std::uint32_t i = 0; i < op.fragment.size(); ++i) {
      if (!replaced.count({id, i})) out.push_back({id, i});
    }
  }
  std::sort(out.begin(), out.end());
  return out;
}

TriangleMesh to_mesh(const OpSource& source, std::span<const TriRef> triangles, bool keep_void) {
  TriangleMesh mesh;
  // Sized once: a triangulated surface has about half as many vertices as triangles (Euler),
  // plus its boundary; growing by doubling would hold up to twice the output for a moment.
  const std::size_t n = triangles.size();
  const std::size_t vertices = n / 2 + 4 * static_cast<std::size_t>(std::sqrt(double(n))) + 16;
  mesh.triangles.reserve(n);
  mesh.triangle_values.reserve(n);
  mesh.positions.reserve(vertices);
  std::unordered_map<std::uint64_t, std::uint32_t> index;
  index.reserve(vertices);
  for (const TriRef& ref : triangles) {
    const OpRef op_ref = source.op(ref.op);
    const Op& op = *op_ref;
    const FragmentTriangle& t = op.fragment[ref.index];
    if (t.is_void() && !keep_void) continue;
    std::array<std::uint32_t, 3> tri{};
    for (int k = 0; k < 3; ++k) {
      const Vertex& v = op.vertices[t.v[k]];
      auto [it, fresh] =
          index.emplace(v.id.value, static_cast<std::uint32_t>(mesh.positions.size()));
      if (fresh) mesh.positions.push_back(v.p);
      tri[k] = it->second;
    }
    mesh.triangles.push_back(tri);
    mesh.triangle_values.push_back(static_cast<float>(t.death_res));
  }
  return mesh;
}

}  // namespace smr
