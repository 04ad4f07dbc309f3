// Brown 5.1 and 5.2: the two SMR algorithms, the set formula of Lemma 5.1.1, and mesh output.
#include "smr/extract/extract.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <unordered_map>
#include <unordered_set>
#include <utility>
#include <vector>

#include "base/error.h"
#include "smr/core/clock.h"
#include "smr/core/id_map.h"
#include "smr/extract/expansion.h"

namespace smr {

Extraction expand(const OpSource& source, std::span<const OpId> x,
                  const ExpansionOptions& options) {
  return run_expansion(source, x, false, options);
}

Extraction extract_minimal_surface(const OpSource& source, const RcfOracle& rcf,
                                   const ExpansionOptions& options) {
  const auto t0 = Clock::now();
  const std::vector<OpId> x = add_to_list(source, rcf);
  return expand_minimal(source, x, options, seconds_since(t0));
}

Extraction expand_minimal(const OpSource& source, std::span<const OpId> x,
                          const ExpansionOptions& options, double extract_seconds) {
  const auto t0 = Clock::now();
  Extraction e = options.fronts || options.max_triangles != 0
                     ? run_expansion(source, x, false, options)
                     : extract_set_formula(source, x);
  e.stats.expand_seconds = seconds_since(t0);
  e.stats.extract_seconds = extract_seconds;
  return e;
}

Extraction extract_set_formula(const OpSource& source, std::span<const OpId> x) {
  const std::uint64_t n = source.op_count();
  std::vector<std::uint64_t> in_x((n + 63) / 64, 0);              // a bit per op
  std::vector<std::pair<std::uint64_t, std::uint64_t>> by_place;  // (locality, id)
  by_place.reserve(x.size());
  for (OpId id : x) {
    if (id.value >= n) throw_input("op " + std::to_string(id.value) + " does not exist");
    std::uint64_t& word = in_x[id.value / 64];
    const std::uint64_t bit = std::uint64_t{1} << (id.value % 64);
    if (word & bit) continue;
    word |= bit;
    by_place.push_back({source.locality(id), id.value});
  }
  std::sort(by_place.begin(), by_place.end());
  const auto member = [&](OpId id) {
    return id.valid() && id.value < n && (in_x[id.value / 64] >> (id.value % 64) & 1) != 0;
  };
  Extraction e;
  for (const auto& [place, id] : by_place) {
    const OpRef op = source.op(OpId{id});
    const auto count = static_cast<std::uint32_t>(op->fragment.size());
    for (std::uint32_t i = 0; i < count; ++i) {
      const FragmentTriangle& t = op->fragment[i];
      if (member(t.killer)) continue;
      e.triangles.push_back({op->id, i});
      e.stats.void_triangles += t.is_void() ? 1 : 0;
    }
  }
  e.x.reserve(by_place.size());
  for (const auto& entry : by_place) e.x.push_back(OpId{entry.second});
  std::sort(e.x.begin(), e.x.end(), std::greater<>());
  e.stats.x = e.stats.x_plus = e.stats.ops_visited = e.x.size();
  e.stats.triangles = e.triangles.size();
  return e;
}

Extraction extract_reduced(const OpSource& source, const RcfOracle& rcf,
                           const ExpansionOptions& options) {
  if (source.info().kind != ModelKind::kTerrain) {
    // Its starting-point test compares xy-domains (Brown 5.2: 2.5-D models).
    throw_input(
        "reduced extraction is defined for 2.5-D terrains (Brown 5.2); use the minimal "
        "surface algorithm for 3-D meshes");
  }
  auto t0 = Clock::now();
  const std::vector<OpId> x = add_to_list_reduced(source, rcf);
  const double t_extract = seconds_since(t0);
  t0 = Clock::now();
  Extraction e = run_expansion(source, x, true, options);
  e.stats.expand_seconds = seconds_since(t0);
  e.stats.extract_seconds = t_extract;
  e.stats.x = x.size();
  return e;
}

std::vector<TriRef> set_formula(const OpSource& source, std::span<const OpId> x) {
  std::unordered_set<TriRef> replaced;
  for (OpId id : x) {
    const OpRef op = source.op(id);  // holds the op while its PreF is read
    for (const TriRef& t : op->pre) replaced.insert(t);
  }
  std::vector<TriRef> out;
  for (OpId id : x) {
    const OpRef op_ref = source.op(id);
    const OpView& op = *op_ref;
    for (std::uint32_t i = 0; i < op.fragment.size(); ++i) {
      if (!replaced.count({id, i})) out.push_back({id, i});
    }
  }
  std::sort(out.begin(), out.end());
  return out;
}

TriangleMesh to_mesh(const OpSource& source, std::span<const TriRef> triangles, bool keep_void) {
  // Triangles are read page by page (OpSource::locality): in expansion order, finest op first,
  // they cross the pages of a resolution band in no spatial order and an LRU page cache smaller
  // than the band decodes each page again for nearly every triangle (see HeldOps in
  // expansion.cpp). The vertices are numbered in the given order afterwards, so the mesh does not
  // depend on where its ops are stored.
  const std::size_t n = triangles.size();
  std::vector<std::pair<std::uint64_t, std::uint32_t>> order;  // (locality, triangle)
  order.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint64_t place = i > 0 && triangles[i].op == triangles[i - 1].op
                                    ? order.back().first
                                    : source.locality(triangles[i].op);
    order.push_back({place, static_cast<std::uint32_t>(i)});
  }
  const auto by_place = [](const auto& a, const auto& b) { return a.first < b.first; };
  if (!std::is_sorted(order.begin(), order.end(), by_place))
    std::stable_sort(order.begin(), order.end(), by_place);
  // First pass, page by page: every distinct vertex gets a slot (its id and position, in order of
  // first use here), and each corner its slot. Corners index their op's vertex pool (a page's
  // vertex table, or an in-memory op's own list), so a vertex id is looked up once per pool, not
  // once per corner. The pool stays alive while op_ref holds its op, so a pool met again at the
  // same address is the same pool.
  constexpr std::uint32_t kDropped = ~std::uint32_t{0};
  std::vector<std::array<std::uint32_t, 3>> corners(n);  // slots; kDropped: a void triangle
  std::vector<float> values(n);
  std::vector<Vec3> positions;       // by slot
  IdMap<std::uint32_t> slot_of(75);  // vertex id -> 1 + slot (75 %: half the table of 50 %)
  // A triangulated surface has about half as many vertices as triangles (Euler), plus its
  // boundary: sized once, since growing by doubling would hold up to twice the output a moment.
  const std::size_t vertices = n / 2 + 4 * static_cast<std::size_t>(std::sqrt(double(n))) + 16;
  slot_of.reserve(vertices);
  positions.reserve(vertices);
  const Vertex* pool = nullptr;
  std::vector<std::uint32_t> pool_slot;  // pool index -> 1 + slot, 0 if not met yet
  OpRef op_ref;
  for (const auto& [place, i] : order) {
    if (op_ref == nullptr || op_ref->id != triangles[i].op) op_ref = source.op(triangles[i].op);
    const OpView& op = *op_ref;
    if (op.vertices.data() != pool) {
      pool = op.vertices.data();
      pool_slot.assign(op.vertices.size(), 0);
    }
    const FragmentTriangle& t = op.triangle(triangles[i].index);
    if (t.is_void() && !keep_void) {
      corners[i][0] = kDropped;
      continue;
    }
    for (int k = 0; k < 3; ++k) {
      std::uint32_t& known = pool_slot[t.v[k]];
      if (known == 0) {
        const Vertex& v = op.vertices[t.v[k]];
        std::uint32_t& slot = slot_of[v.id.value];
        if (slot == 0) {
          positions.push_back(v.p);  // the same position wherever a vertex appears
          slot = static_cast<std::uint32_t>(positions.size());
        }
        known = slot;
      }
      corners[i][k] = known - 1;
    }
    values[i] = static_cast<float>(t.death_res);
  }
  op_ref.reset();
  std::vector<std::pair<std::uint64_t, std::uint32_t>>().swap(order);
  slot_of = IdMap<std::uint32_t>();  // freed before the mesh grows
  // Second pass, in the given order: slots -> mesh indices by first use.
  TriangleMesh mesh;
  mesh.triangles.reserve(n);
  mesh.triangle_values.reserve(n);
  mesh.positions.reserve(positions.size());
  std::vector<std::uint32_t> index(positions.size(), 0);  // slot -> 1 + index in the mesh
  for (std::size_t i = 0; i < n; ++i) {
    if (corners[i][0] == kDropped) continue;
    std::array<std::uint32_t, 3> tri{};
    for (int k = 0; k < 3; ++k) {
      std::uint32_t& at = index[corners[i][k]];
      if (at == 0) {
        mesh.positions.push_back(positions[corners[i][k]]);
        at = static_cast<std::uint32_t>(mesh.positions.size());
      }
      tri[k] = at - 1;
    }
    mesh.triangles.push_back(tri);
    mesh.triangle_values.push_back(values[i]);
  }
  return mesh;
}

}  // namespace smr
