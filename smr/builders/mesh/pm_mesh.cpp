// The mesh under half-edge collapse (Hoppe 1996, section 3; pm_mesh.h), with Garland &
// Heckbert 1997's quadrics (sections 5 and 6.1) set up on it.
#include "smr/builders/mesh/pm_mesh.h"

#include <numeric>
#include <unordered_map>
#include <utility>

#include "base/error.h"
#include "smr/builders/mesh/morton_order.h"

namespace smr::qem {

void init_arrays(PmMesh& m, std::size_t triangles) {
  const std::size_t n = m.pos.size();
  m.star.resize(n);
  m.star_version.assign(n, 0);
  m.removed.assign(n, 0);
  m.boundary.assign(n, 0);
  m.tris.reserve(triangles * 2);
}

std::uint32_t add_triangle(PmMesh& m, const Tri& t) {
  const auto id = static_cast<std::uint32_t>(m.tris.size());
  m.tris.push_back(t);
  for (std::uint32_t v : t.v) {
    m.star[v].push_back(id);
    ++m.star_version[v];
  }
  return id;
}

void unlink_triangle(PmMesh& m, std::uint32_t id, std::uint32_t except) {
  for (std::uint32_t v : m.tris[id].v) {
    if (v == except) continue;
    auto& s = m.star[v];
    s.erase(std::find(s.begin(), s.end(), id));
    ++m.star_version[v];
  }
}

std::size_t fans(const PmMesh& m, std::uint32_t v) {
  const std::vector<std::uint32_t>& star = m.star[v];
  std::vector<std::pair<std::uint32_t, std::uint32_t>> rim;  // (other corner, star index)
  rim.reserve(2 * star.size());
  for (std::uint32_t i = 0; i < star.size(); ++i) {
    for (std::uint32_t w : m.tris[star[i]].v) {
      if (w != v) rim.push_back({w, i});
    }
  }
  std::sort(rim.begin(), rim.end());
  std::vector<std::uint32_t> parent(star.size());
  std::iota(parent.begin(), parent.end(), 0u);
  const auto root = [&](std::uint32_t i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  };
  std::size_t pieces = star.size();
  for (std::size_t j = 1; j < rim.size(); ++j) {
    if (rim[j].first != rim[j - 1].first) continue;
    const std::uint32_t a = root(rim[j].second), b = root(rim[j - 1].second);
    if (a == b) continue;
    parent[a] = b;
    --pieces;
  }
  return pieces;
}

IdMap<std::uint8_t> directed_edges(const PmMesh& m, std::uint64_t* twice) {
  IdMap<std::uint8_t> directed;
  directed.reserve(m.tris.size() * 3);
  for (const Tri& t : m.tris) {
    for (int k = 0; k < 3; ++k) {
      const std::uint64_t key = edge_key(t.v[k], t.v[(k + 1) % 3]);
      if (!directed.insert(key) && twice != nullptr && *twice == kNoEdge) *twice = key;
    }
  }
  return directed;
}

void add_constraint(PmMesh& m, const Tri& t, int k, double boundary_weight) {
  const std::uint32_t a = t.v[k], b = t.v[(k + 1) % 3];
  Quadric bq;
  if (!boundary_quadric(m.pos[a], m.pos[b], normal(m, t.v), boundary_weight, bq)) return;
  m.quad[a] += bq;
  m.quad[b] += bq;
}

void init_quadrics_and_boundary(PmMesh& m, double boundary_weight) {
  // Face planes weighted by area; each boundary edge adds a constraint plane through it,
  // perpendicular to its face (Garland & Heckbert 1997, section 6.1).
  const auto directed = directed_edges(m, nullptr);
  for (const Tri& t : m.tris) {
    if (!(glm::length(normal(m, t.v)) > 0.0)) continue;
    const Quadric q = face_quadric(m.pos[t.v[0]], m.pos[t.v[1]], m.pos[t.v[2]]);
    for (std::uint32_t v : t.v) m.quad[v] += q;
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t a = t.v[k], b = t.v[(k + 1) % 3];
      if (directed.contains(edge_key(b, a))) continue;
      m.boundary[a] = m.boundary[b] = 1;
      add_constraint(m, t, k, boundary_weight);
    }
  }
}

void init_components(PmMesh& m) {
  const std::size_t n = m.pos.size();
  std::vector<std::uint32_t> parent(n);
  std::iota(parent.begin(), parent.end(), 0u);
  auto find = [&](std::uint32_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  for (const Tri& t : m.tris) {
    for (int k = 1; k < 3; ++k) parent[find(t.v[k])] = find(t.v[0]);
  }
  m.comp.resize(n);
  std::unordered_map<std::uint32_t, std::uint32_t> ids;
  for (std::uint32_t v = 0; v < n; ++v) {
    if (m.star[v].empty()) {
      m.comp[v] = kNone;
      m.removed[v] = 1;  // unreferenced: never part of the model
      continue;
    }
    auto [it, fresh] = ids.emplace(find(v), std::uint32_t(m.comp_vertices.size()));
    if (fresh) {
      m.comp_vertices.push_back(0);
      m.comp_open.push_back(0);
    }
    m.comp[v] = it->second;
    ++m.comp_vertices[it->second];
    if (m.boundary[v]) m.comp_open[it->second] = 1;
  }
}

std::vector<std::uint32_t> load_source(PmMesh& m, const TriangleMesh& mesh,
                                       double boundary_weight) {
  const std::size_t n = mesh.positions.size();
  for (const auto& t : mesh.triangles) {
    for (std::uint32_t v : t) {
      if (v >= n) throw_input("mesh: a triangle references a vertex out of range");
    }
  }
  Box3 box;
  for (const Vec3& p : mesh.positions) box.add(p);
  std::vector<std::pair<std::uint64_t, std::uint32_t>> codes(n);
  for (std::uint32_t v = 0; v < n; ++v) {
    codes[v] = {morton_code(mesh.positions[v], box.lo, box.hi - box.lo), v};
  }
  std::sort(codes.begin(), codes.end());
  std::vector<std::uint32_t> renumbered(n), source_id(n);
  m.pos.resize(n);
  for (std::uint32_t i = 0; i < n; ++i) {
    source_id[i] = codes[i].second;
    renumbered[codes[i].second] = i;
    m.pos[i] = mesh.positions[codes[i].second];
  }
  std::vector<std::pair<std::uint32_t, std::uint32_t>> first;  // (first corner, triangle)
  first.reserve(mesh.triangles.size());
  for (std::uint32_t i = 0; i < mesh.triangles.size(); ++i) {
    const auto& t = mesh.triangles[i];
    first.push_back({std::min({renumbered[t[0]], renumbered[t[1]], renumbered[t[2]]}), i});
  }
  std::sort(first.begin(), first.end());
  m.quad.resize(n);
  init_arrays(m, first.size());
  for (const auto& [corner, i] : first) {
    const auto& t = mesh.triangles[i];
    add_triangle(m, Tri{{renumbered[t[0]], renumbered[t[1]], renumbered[t[2]]}, 0.0, kNone, kNone});
  }
  init_quadrics_and_boundary(m, boundary_weight);
  init_components(m);
  return source_id;
}

std::uint64_t alive_triangles(const PmMesh& m) {
  return static_cast<std::uint64_t>(std::count_if(
      m.tris.begin(), m.tris.end(), [](const Tri& t) { return t.destroyer == kNone; }));
}

std::uint64_t alive_vertices(const PmMesh& m) {
  return std::accumulate(m.comp_vertices.begin(), m.comp_vertices.end(), std::uint64_t{0});
}

void neighbours(const PmMesh& m, Marks& marks, std::uint32_t v, std::vector<std::uint32_t>& out) {
  out.clear();
  const std::uint32_t seen = marks.next();
  for (std::uint32_t id : m.star[v]) {
    for (std::uint32_t w : m.tris[id].v) {
      if (w == v || marks.of[w] == seen) continue;
      marks.of[w] = seen;
      out.push_back(w);
    }
  }
}

void collapse_mesh(PmMesh& m, CollapseLog& log, std::uint32_t from, std::uint32_t to, double error,
                   const std::vector<double>& new_e) {
  const auto c = static_cast<std::uint32_t>(log.collapses.size());
  Collapse col;
  col.removed = from;
  col.kept = to;
  col.error = error;
  col.old_begin = static_cast<std::uint32_t>(log.old_tris.size());
  for (std::uint32_t id : m.star[from]) {
    log.old_tris.push_back(id);
    m.tris[id].destroyer = c;
    unlink_triangle(m, id, from);
  }
  col.old_end = static_cast<std::uint32_t>(log.old_tris.size());
  m.star[from].clear();
  ++m.star_version[from];
  col.new_begin = static_cast<std::uint32_t>(log.new_tris.size());
  std::size_t made = 0;
  for (std::uint32_t k = col.old_begin; k < col.old_end; ++k) {
    const std::uint32_t id = log.old_tris[k];
    if (has(m.tris[id], to)) continue;
    Tri t;
    t.v = corners_after(m.tris[id], from, to);
    t.e = new_e[made++];
    t.creator = c;
    log.new_tris.push_back(add_triangle(m, t));
  }
  col.new_end = static_cast<std::uint32_t>(log.new_tris.size());
  log.collapses.push_back(col);
  m.removed[from] = 1;
  --m.comp_vertices[m.comp[from]];
  const Quadric qf = m.quad[from];
  m.quad[to] += qf;
}

}  // namespace smr::qem
