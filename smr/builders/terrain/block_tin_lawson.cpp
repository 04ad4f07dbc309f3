// The block TIN builder's Delaunay repair; block_tin_lawson.h describes it.
#include "smr/builders/terrain/block_tin_lawson.h"

#include <algorithm>
#include <utility>

#include "base/error.h"
#include "smr/builders/terrain/block_tin_bounds.h"

namespace smr::block_tin {
namespace {

struct SampleWindow {
  int c0, r0;
  Heightfield w;
};
/// The samples of a triangle's bounding box, from the scratch copy through a tile cache.
SampleWindow window_of(std::span<const MVert> verts, const SampleSpill& spill,
                       const RasterWindows& dem, const std::array<std::uint32_t, 3>& v,
                       SampleSpill::Cache& tiles) {
  const MVert &a = verts[v[0]], &b = verts[v[1]], &c = verts[v[2]];
  const int c0 = std::min({a.col, b.col, c.col}), r0 = std::min({a.row, b.row, c.row});
  const int c1 = std::max({a.col, b.col, c.col}), r1 = std::max({a.row, b.row, c.row});
  return {c0, r0, spill.read(c0, r0, c1 - c0 + 1, r1 - r0 + 1, dem, &tiles)};
}

}  // namespace

void LawsonRepair::make_borders_delaunay() {
  const int B = setup_.grid.B, W = setup_.grid.W, H = setup_.grid.H;
  std::vector<EdgeTask> stack;
  for (std::uint32_t t = 0; t < mesh_.tris.size(); ++t) {
    const MTri& m = mesh_.tris[t];
    for (int k = 0; k < 3; ++k) {
      const MVert &a = mesh_.verts[m.v[k]], &b = mesh_.verts[m.v[(k + 1) % 3]];
      const bool on_line = (a.col == b.col && a.col % B == 0 && a.col > 0 && a.col < W - 1) ||
                           (a.row == b.row && a.row % B == 0 && a.row > 0 && a.row < H - 1);
      if (on_line && m.nbr[k] != kNone && m.nbr[k] > t)
        stack.push_back({t, m.v[k], m.v[(k + 1) % 3]});
    }
  }
  std::reverse(stack.begin(), stack.end());  // popped in triangle order
  repair(stack);
}

void LawsonRepair::repair(std::vector<EdgeTask>& stack) {
  const int B = setup_.grid.B;
  std::vector<std::uint32_t> stale, wave;
  legalise(stack, stale);
  while (!stale.empty()) {
    wave.swap(stale);
    stale.clear();
    std::vector<std::pair<std::uint64_t, std::uint32_t>> order;
    for (std::uint32_t t : wave) {
      const MTri& m = mesh_.tris[t];
      const int col =
          std::min({mesh_.verts[m.v[0]].col, mesh_.verts[m.v[1]].col, mesh_.verts[m.v[2]].col});
      const int row =
          std::min({mesh_.verts[m.v[0]].row, mesh_.verts[m.v[1]].row, mesh_.verts[m.v[2]].row});
      order.push_back(
          {(std::uint64_t(row / B) * std::uint64_t(setup_.grid.bw) + std::uint64_t(col / B)) << 32 |
               t,
           t});
    }
    std::sort(order.begin(), order.end());
    order.erase(std::unique(order.begin(), order.end()), order.end());
    for (const auto& [key, t] : order) {
      const auto [c0, r0, w] = window_of(mesh_.verts, spill_, setup_.dem, mesh_.tris[t].v, tiles_);
      TriBound& b = mesh_.tris[t].bound;
      b = exact_bound(mesh_, mesh_.tris[t].v, w, c0, r0, false);
      if (b.err() <= setup_.stop_error) {
        mesh_.err_final = std::max(mesh_.err_final, b.err());
        continue;
      }
      const auto [col, row] = worst_sample(mesh_.verts, mesh_.tris[t].v, w, c0, r0);
      insert_sample(t, col, row, w.at(col - c0, row - r0), stack, stale);
      legalise(stack, stale);
    }
  }
}

/// Lawson's flips until every edge of the stack is locally Delaunay; flipped triangles go to
/// `stale`.
void LawsonRepair::legalise(std::vector<EdgeTask>& stack, std::vector<std::uint32_t>& stale) {
  Chunked<MTri>& tris = mesh_.tris;
  std::vector<MVert>& verts = mesh_.verts;
  while (!stack.empty()) {
    const EdgeTask e = stack.back();
    stack.pop_back();
    const std::uint32_t t1 = e.t;
    int k = -1;
    for (int i = 0; i < 3; ++i) {
      const std::uint32_t x = tris[t1].v[i], y = tris[t1].v[(i + 1) % 3];
      if ((x == e.a && y == e.b) || (x == e.b && y == e.a)) k = i;
    }
    if (k < 0) continue;  // flipped away since
    const std::uint32_t t2 = tris[t1].nbr[k];
    if (t2 == kNone || tris[t1].is_void || tris[t2].is_void) continue;
    if (handed_out(tris[t1]) || handed_out(tris[t2])) throw LeafConflict{};
    const std::uint32_t a = tris[t1].v[k], b = tris[t1].v[(k + 1) % 3], c = tris[t1].v[(k + 2) % 3];
    const int j = index_of(tris[t2], b);
    const std::uint32_t d = tris[t2].v[(j + 2) % 3];
    if (!in_circle(verts[a], verts[b], verts[c], verts[d])) continue;
    // (a, b, c) and (b, a, d) become (c, a, d) and (d, b, c): the quad a, d, b, c is convex.
    const std::uint32_t n_bc = tris[t1].nbr[(k + 1) % 3], n_ca = tris[t1].nbr[(k + 2) % 3];
    const std::uint32_t n_ad = tris[t2].nbr[(j + 1) % 3], n_db = tris[t2].nbr[(j + 2) % 3];
    set_triangle(t1, {c, a, d}, {n_ca, n_ad, t2});
    set_triangle(t2, {d, b, c}, {n_db, n_bc, t1});
    relink(mesh_, n_ad, d, a, t1);
    relink(mesh_, n_bc, c, b, t2);
    ++stats_.delaunay_flips;
    stale.push_back(t1);
    stale.push_back(t2);
    stack.push_back({t1, c, a});
    stack.push_back({t1, a, d});
    stack.push_back({t2, d, b});
    stack.push_back({t2, b, c});
  }
}

/// Inserts grid sample (col, row) of height z, which lies in triangle t (inside, or on an edge
/// shared with another data triangle), splitting t (and that neighbour); the new triangles go to
/// `stale` and their outer edges to `stack`.
void LawsonRepair::insert_sample(std::uint32_t t, int col, int row, float z,
                                 std::vector<EdgeTask>& stack, std::vector<std::uint32_t>& stale) {
  Chunked<MTri>& tris = mesh_.tris;
  std::vector<MVert>& verts = mesh_.verts;
  MVert pv;
  pv.col = col;
  pv.row = row;
  pv.z = z;
  const auto p = static_cast<std::uint32_t>(verts.size());
  verts.push_back(pv);
  if (leaf_vertices_ != nullptr) {  // the interleaved leaf pass: a candidate of its leaf's block
    const Grid& g = setup_.grid;
    (*leaf_vertices_)[std::size_t(std::min(row / g.B, g.bh - 1)) * std::size_t(g.bw) +
                      std::size_t(std::min(col / g.B, g.bw - 1))]
        .push_back(p);
  }
  ++stats_.delaunay_insertions;
  int k = -1;
  for (int i = 0; i < 3; ++i) {
    if (orient(verts[tris[t].v[i]], verts[tris[t].v[(i + 1) % 3]], pv) == 0) k = i;
  }
  const std::uint32_t a = tris[t].v[k < 0 ? 0 : k], b = tris[t].v[k < 0 ? 1 : (k + 1) % 3],
                      c = tris[t].v[k < 0 ? 2 : (k + 2) % 3];
  const std::uint32_t n_ab = tris[t].nbr[k < 0 ? 0 : k],
                      n_bc = tris[t].nbr[k < 0 ? 1 : (k + 1) % 3],
                      n_ca = tris[t].nbr[k < 0 ? 2 : (k + 2) % 3];
  const auto n1 = static_cast<std::uint32_t>(tris.size());
  tris.push_back(MTri{});
  if (k < 0) {  // inside: (a, b, p), (b, c, p), (c, a, p)
    const std::uint32_t n2 = n1 + 1;
    tris.push_back(MTri{});
    set_triangle(t, {a, b, p}, {n_ab, n1, n2});
    set_triangle(n1, {b, c, p}, {n_bc, n2, t});
    set_triangle(n2, {c, a, p}, {n_ca, t, n1});
    relink(mesh_, n_bc, c, b, n1);
    relink(mesh_, n_ca, a, c, n2);
    stale.insert(stale.end(), {t, n1, n2});
    stack.insert(stack.end(), {{t, a, b}, {n1, b, c}, {n2, c, a}});
    mesh_.finest_triangles += 2;
    return;
  }
  // On edge (a, b), shared with u = (b, a, d): (a, p, c), (p, b, c), (b, p, d), (p, a, d).
  const std::uint32_t u = n_ab;
  if (u == kNone || tris[u].is_void)
    throw_internal("block TIN: a sample over the error lies on an old edge");
  const int j = index_of(tris[u], b);
  const std::uint32_t d = tris[u].v[(j + 2) % 3];
  const std::uint32_t n_ad = tris[u].nbr[(j + 1) % 3], n_db = tris[u].nbr[(j + 2) % 3];
  const std::uint32_t n2 = n1 + 1;
  tris.push_back(MTri{});
  set_triangle(t, {a, p, c}, {n2, n1, n_ca});
  set_triangle(n1, {p, b, c}, {u, n_bc, t});
  set_triangle(u, {b, p, d}, {n1, n2, n_db});
  set_triangle(n2, {p, a, d}, {t, n_ad, u});
  relink(mesh_, n_bc, c, b, n1);
  relink(mesh_, n_ad, d, a, n2);
  stale.insert(stale.end(), {t, n1, u, n2});
  stack.insert(stack.end(), {{t, c, a}, {n1, b, c}, {u, d, b}, {n2, a, d}});
  mesh_.finest_triangles += 2;
}

/// Triangle t of M^m becomes (v, nbr), counter-clockwise; its vertices point at it.
void LawsonRepair::set_triangle(std::uint32_t t, const std::array<std::uint32_t, 3>& v,
                                const std::array<std::uint32_t, 3>& nbr) {
  Chunked<MTri>& tris = mesh_.tris;
  std::vector<MVert>& verts = mesh_.verts;
  MTri& m = tris[t];
  m.v = v;
  m.nbr = nbr;
  if (orient(verts[v[0]], verts[v[1]], verts[v[2]]) <= 0)
    throw_internal("block TIN: a Delaunay repair made a degenerate triangle");
  for (int k = 0; k < 3; ++k) {
    verts[v[k]].tri = t;
    // An edge waiting for a later leaf (the interleaved pass) may have moved to this slot.
    if (nbr[k] == kNone && !setup_.grid.boundary_edge(verts[v[k]], verts[v[(k + 1) % 3]]))
      mesh_.open_edges[edge_key(v[k], v[(k + 1) % 3])] = (t << 2) | std::uint32_t(k);
  }
}

}  // namespace smr::block_tin
