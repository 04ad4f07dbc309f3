// One vertex removal of the block TIN builder; block_tin_removal.h describes it.
#include "smr/builders/terrain/block_tin_removal.h"

#include <algorithm>
#include <cmath>

namespace smr::block_tin {
namespace {

/// The star and hole polygon of `v`; false if it cannot be removed (degree too high).
bool gather(const Mesh& mesh, const Grid& grid, std::uint32_t max_degree, std::uint32_t v,
            Plan& p) {
  p.star.clear();
  p.poly.clear();
  std::uint32_t t = mesh.verts[v].tri, start = t;
  if (t == kNone) return false;  // its triangles are in another block's copy
  // Clockwise to the first triangle of an open fan (or all the way round).
  std::uint32_t steps = 0;
  for (;;) {
    const int i = index_of(mesh.tris[t], v);
    const std::uint32_t prev = mesh.tris[t].nbr[i];  // across (v, a): the triangle before
    if (prev == kNone) {
      // A fan is open only at the domain's boundary: elsewhere its star goes on in another
      // block's copy, and v is not this block's to remove.
      if (!grid.boundary_edge(mesh.verts[v], mesh.verts[mesh.tris[t].v[(i + 1) % 3]])) return false;
      start = t;
      p.open = true;
      break;
    }
    t = prev;
    if (t == start) {
      p.open = false;
      break;
    }
    if (++steps > max_degree + 1) return false;
  }
  t = start;
  for (;;) {
    const MTri& m = mesh.tris[t];
    const int i = index_of(m, v);
    p.star.push_back(t);
    p.poly.push_back(m.v[(i + 1) % 3]);
    if (p.star.size() > max_degree) return false;
    const std::uint32_t next = m.nbr[(i + 2) % 3];  // across (b, v)
    if (next == kNone) {
      if (!grid.boundary_edge(mesh.verts[m.v[(i + 2) % 3]], mesh.verts[v])) return false;
      p.poly.push_back(m.v[(i + 2) % 3]);
      break;
    }
    if (next == start) break;
    t = next;
  }
  return p.poly.size() <= max_degree && p.poly.size() >= 3;
}

/// Delaunay ears over the hole polygon; false if no triangulation was found.
bool triangulate(std::span<const MVert> verts, Plan& p) {
  p.tris.clear();
  p.delaunay = true;
  std::vector<std::uint32_t> poly = p.poly;
  while (poly.size() > 3) {
    const std::size_t n = poly.size();
    std::size_t ear = n, plain = n;
    for (std::size_t i = 0; i < n && ear == n; ++i) {
      const MVert &a = verts[poly[(i + n - 1) % n]], &b = verts[poly[i]],
                  &c = verts[poly[(i + 1) % n]];
      if (orient(a, b, c) <= 0) continue;
      bool empty = true, circle = true;
      for (std::size_t j = 0; j < n && empty; ++j) {
        if (j == i || j == (i + 1) % n || j == (i + n - 1) % n) continue;
        const MVert& d = verts[poly[j]];
        if (orient(a, b, d) >= 0 && orient(b, c, d) >= 0 && orient(c, a, d) >= 0) empty = false;
        if (circle && in_circle(a, b, c, d)) circle = false;
      }
      if (!empty) continue;
      if (circle) ear = i;
      if (plain == n) plain = i;
    }
    if (ear == n) {
      if (plain == n) return false;
      ear = plain;
      p.delaunay = false;
    }
    p.tris.push_back({poly[(ear + n - 1) % n], poly[ear], poly[(ear + 1) % n]});
    poly.erase(poly.begin() + static_cast<std::ptrdiff_t>(ear));
  }
  if (orient(verts[poly[0]], verts[poly[1]], verts[poly[2]]) <= 0) return false;
  p.tris.push_back({poly[0], poly[1], poly[2]});
  return true;
}

}  // namespace

void plan_removal(const Setup& setup, Mesh& mesh, ClipScratch& scratch, std::uint32_t v, Plan& p,
                  const BlockWindow& window, bool estimate, double limit) {
  const Heightfield* w = window.w;
  const int c0 = window.c0, r0 = window.r0;
  p.err = kInfeasible;
  p.lower_bound = false;
  ++mesh.plans;
  if (!gather(mesh, setup.grid, setup.opt.max_degree, v, p)) return;
  for (std::uint32_t t : p.star) {
    if (mesh.tris[t].is_void) return;
  }
  if (w != nullptr) {  // the hole must lie in the block's window (a Delaunay edge may cross)
    for (std::uint32_t u : p.poly) {
      const MVert& m = mesh.verts[u];
      if (m.col < c0 || m.row < r0 || m.col >= c0 + w->width || m.row >= r0 + w->height) return;
    }
  }
  if (p.open && !setup.grid.on_domain_boundary(mesh.verts[v])) return;
  if (!triangulate(mesh.verts, p)) return;
  p.bounds.clear();
  double err = 0.0;
  if (w != nullptr && estimate) {
    const MVert& m = mesh.verts[v];
    double lb = 0.0;
    for (const auto& nt : p.tris) {
      const MVert &a = mesh.verts[nt[0]], &b = mesh.verts[nt[1]], &c = mesh.verts[nt[2]];
      if (orient(a, b, m) < 0 || orient(b, c, m) < 0 || orient(c, a, m) < 0) continue;
      lb = std::max(lb, std::abs(double(m.z) - Plane(a, b, c).at(m.col, m.row)));
    }
    p.err = lb;
    p.lower_bound = true;
    return;
  }
  for (const auto& nt : p.tris) {
    p.bounds.push_back(w != nullptr ? exact_bound(mesh, nt, *w, c0, r0, true, limit)
                                    : overlay_bound(mesh, nt, p.star, scratch));
    err = std::max(err, p.bounds.back().err());
    if (err > limit) {
      p.err = err;
      p.lower_bound = true;
      return;
    }
  }
  p.err = err;
}

void apply_removal(const Grid& grid, Mesh& mesh, RemovalScratch& scratch, std::uint32_t v,
                   const Plan& p, BlockTinStats& stats) {
  const auto rid = static_cast<std::uint32_t>(mesh.removals.size());
  Removal r;
  r.vertex = v;
  r.star_begin = static_cast<std::uint32_t>(mesh.star_ids.size());
  for (std::uint32_t t : p.star) mesh.star_ids.push_back(t);
  r.star_end = static_cast<std::uint32_t>(mesh.star_ids.size());
  r.new_begin = static_cast<std::uint32_t>(mesh.tris.size());
  r.err = p.err;
  // The outer neighbour of each hole edge (poly[j], poly[j+1]): across star triangle j's edge
  // opposite v; the closing edge of an open fan has none.
  std::vector<std::pair<std::uint64_t, std::uint32_t>>& outer = scratch.outer;
  outer.clear();
  for (std::uint32_t t : p.star) {
    const MTri& m = mesh.tris[t];
    const int i = index_of(m, v);
    const std::uint32_t a = m.v[(i + 1) % 3], b = m.v[(i + 2) % 3];
    outer.push_back({edge_key(a, b), m.nbr[(i + 1) % 3]});
    if (m.nbr[(i + 1) % 3] == kNone) {
      mesh.open_edges.erase(edge_key(a, b));  // a block border edge waiting for its neighbour
    }
  }
  for (std::uint32_t t : p.star) mesh.tris[t].destroyer = rid;
  for (std::size_t j = 0; j < p.tris.size(); ++j) {
    MTri m;
    m.v = p.tris[j];
    m.bound = p.bounds[j];
    m.creator = rid;
    mesh.tris.push_back(m);
  }
  r.new_end = static_cast<std::uint32_t>(mesh.tris.size());
  for (std::uint32_t t = r.new_begin; t < r.new_end; ++t) {
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t a = mesh.tris[t].v[k], b = mesh.tris[t].v[(k + 1) % 3];
      mesh.verts[a].tri = t;
      const std::uint64_t key = edge_key(a, b);
      auto it =
          std::find_if(outer.begin(), outer.end(), [&](const auto& e) { return e.first == key; });
      if (it != outer.end()) {  // a hole edge: glue to the outside
        const std::uint32_t o = it->second;
        mesh.tris[t].nbr[k] = o;
        if (o != kNone) {
          relink(mesh, o, b, a, t);
        } else if (!grid.boundary_edge(mesh.verts[a], mesh.verts[b])) {
          mesh.open_edges[edge_key(a, b)] = (t << 2) | std::uint32_t(k);
        }
        continue;
      }
      for (std::uint32_t u = r.new_begin; u < r.new_end; ++u) {  // an inner edge
        if (u == t) continue;
        const int j = index_of(mesh.tris[u], b);
        if (j >= 0 && mesh.tris[u].v[(j + 1) % 3] == a) mesh.tris[t].nbr[k] = u;
      }
    }
  }
  mesh.verts[v].tri = kNone;
  mesh.removals.push_back(r);
  if (!p.delaunay) ++stats.non_delaunay_holes;
}

}  // namespace smr::block_tin
