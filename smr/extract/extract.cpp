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
  // The front reads the links: asked before AddToList reads the pages, which it then reads once.
  if (options.runs_front()) source.need_links();
  const auto t0 = Clock::now();
  const std::vector<OpId> x = add_to_list(source, rcf);
  return expand_minimal(source, x, options, seconds_since(t0));
}

Extraction expand_minimal(const OpSource& source, std::span<const OpId> x,
                          const ExpansionOptions& options, double extract_seconds) {
  const auto t0 = Clock::now();
  Extraction e = options.runs_front() ? run_expansion(source, x, false, options)
                                      : extract_set_formula(source, x);
  e.stats.expand_seconds = seconds_since(t0);
  e.stats.extract_seconds = extract_seconds;
  return e;
}

namespace {

// The places of `items` (each with `at`, grouped by place), each once, in order.
template <class Items>
std::vector<std::uint64_t> distinct_places(const Items& items) {
  std::vector<std::uint64_t> places;
  for (const auto& item : items) {
    if (places.empty() || places.back() != item.at.place) places.push_back(item.at.place);
  }
  return places;
}

}  // namespace

Extraction extract_set_formula(const OpSource& source, std::span<const OpId> x) {
  const std::uint64_t n = source.op_count();
  std::vector<std::uint64_t> in_x((n + 63) / 64, 0);  // a bit per op
  std::vector<PlacedOp> by_place;
  by_place.reserve(x.size());
  for (OpId id : x) {
    if (id.value >= n) throw_input("op " + std::to_string(id.value) + " does not exist");
    std::uint64_t& word = in_x[id.value / 64];
    const std::uint64_t bit = std::uint64_t{1} << (id.value % 64);
    if (word & bit) continue;
    word |= bit;
    by_place.push_back({source.place_of(id), id});
  }
  sort_for_reading(by_place);
  const auto member = [&](OpId id) {
    return id.valid() && id.value < n && (in_x[id.value / 64] >> (id.value % 64) & 1) != 0;
  };
  Extraction e;
  OpReader reader(source);
  PlaceLookahead lookahead(source, distinct_places(by_place));
  std::size_t place_index = 0;
  for (std::size_t k = 0; k < by_place.size(); ++k) {
    const PlacedOp& p = by_place[k];
    if (k > 0 && p.at.place != by_place[k - 1].at.place) lookahead.reached(++place_index);
    const OpView& op = reader.read(p);
    const auto count = static_cast<std::uint32_t>(op.fragment.size());
    for (std::uint32_t i = 0; i < count; ++i) {
      const FragmentTriangle& t = op.fragment[i];
      if (member(t.killer)) continue;
      e.triangles.push_back({op.id, i});
      e.stats.void_triangles += t.is_void() ? 1 : 0;
    }
  }
  if (std::is_sorted(x.begin(), x.end(), std::greater_equal<>())) {  // decreasing, no repeats
    e.x.assign(x.begin(), x.end());
  } else {
    e.x.reserve(by_place.size());
    for (const PlacedOp& p : by_place) e.x.push_back(p.id);
    std::sort(e.x.begin(), e.x.end(), std::greater<>());
  }
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
  source.need_links();  // as extract_minimal_surface: before the pages are read
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
  struct Placed {
    OpPlace at;
    std::uint32_t triangle;
  };
  std::vector<Placed> order;
  order.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    const OpPlace at = i > 0 && triangles[i].op == triangles[i - 1].op
                           ? order.back().at
                           : source.place_of(triangles[i].op);
    order.push_back({at, static_cast<std::uint32_t>(i)});
  }
  const auto by_place = [](const Placed& a, const Placed& b) { return a.at.place < b.at.place; };
  if (!std::is_sorted(order.begin(), order.end(), by_place))
    std::stable_sort(order.begin(), order.end(), by_place);
  // First pass, page by page: every distinct vertex gets a slot (its id and position, in order of
  // first use here), and each corner its slot. Corners index their op's vertex pool (a page's
  // vertex table, or an in-memory op's own list), so a vertex id is looked up once per pool, not
  // once per corner. The pool stays alive while the reader holds its op, so a pool met again at
  // the same address is the same pool.
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
  // A pool's corners first hold pool indices; when the run of triangles on one pool ends, the
  // vertices it met are looked up together, a few ahead prefetched (the map is far larger than
  // the caches: a lookup one after another waits on memory each time), and the corners become
  // slots.
  const Vertex* pool = nullptr;
  std::vector<std::uint32_t> pool_slot;  // pool index -> 1 + slot; 0 not met; kDropped pending
  std::vector<std::uint32_t> fresh;      // pool indices met first in the current run
  std::size_t run_begin = 0;             // the current run is order[run_begin, j)
  const auto end_run = [&](std::size_t run_end) {
    constexpr std::size_t kAhead = 8;
    for (std::size_t f = 0; f < fresh.size(); ++f) {
      if (f + kAhead < fresh.size()) slot_of.prefetch(pool[fresh[f + kAhead]].id.value);
      const Vertex& v = pool[fresh[f]];
      std::uint32_t& slot = slot_of[v.id.value];
      if (slot == 0) {
        positions.push_back(v.p);  // the same position wherever a vertex appears
        slot = static_cast<std::uint32_t>(positions.size());
      }
      pool_slot[fresh[f]] = slot;
    }
    fresh.clear();
    for (std::size_t r = run_begin; r < run_end; ++r) {
      auto& c = corners[order[r].triangle];
      if (c[0] == kDropped) continue;
      for (std::uint32_t& k : c) k = pool_slot[k] - 1;
    }
    run_begin = run_end;
  };
  OpReader reader(source);
  const OpView* current = nullptr;
  PlaceLookahead lookahead(source, distinct_places(order));
  std::size_t place_index = 0;
  for (std::size_t j = 0; j < n; ++j) {
    const auto& [at, i] = order[j];
    if (j > 0 && at.place != order[j - 1].at.place) lookahead.reached(++place_index);
    if (current == nullptr || current->id != triangles[i].op) {
      // Reading another place may let the pool go: its run ends first.
      if (at.index == OpPlace::kNoIndex || (j > 0 && at.place != order[j - 1].at.place)) end_run(j);
      current = &reader.read({at, triangles[i].op});
    }
    const OpView& op = *current;
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
        known = kDropped;
        fresh.push_back(t.v[k]);
      }
      corners[i][k] = t.v[k];
    }
    values[i] = static_cast<float>(t.death_res);
  }
  end_run(n);
  reader = OpReader(source);
  std::vector<Placed>().swap(order);
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
