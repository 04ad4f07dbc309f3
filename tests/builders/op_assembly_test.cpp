// The out-of-core op assembler (smr/builders/op_assembly.h; Brown 4.4.3.3 ordering, 4.4.1 PreF
// and F, 4.5.1 Hypermesh links, 4.5.2 the DAG), tested directly. A decimation of a small terrain
// is made here, vertex by vertex (some removals take two adjacent vertices, some a vertex of the
// domain border, whose fragment then has model-boundary edges), with own error bounds that grow
// as the mesh coarsens, noisy and of a few values (so that independent removals interleave and
// many tie), and handed to the assembler removal by removal. Its
// ops are compared field by field with an in-memory replay of the same removals (the brute-force
// oracle below: the order by falling error, each PreF triangle's owner, the killers and
// death_res, parents and children from PreF and F, the coarser-edge links from the mesh alive
// just before each op), then checked with check_crmr (docs/design.md section 8). Also: spills to
// scratch files (a tiny budget), the thread count and an encoding sink change no op, the scratch
// files go with the assembler, and the malformed input it validates is rejected with smr::Error.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <functional>
#include <map>
#include <mutex>
#include <numeric>
#include <set>
#include <span>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "base/error.h"
#include "smr/builders/op_assembly.h"
#include "smr/core/crmr.h"
#include "smr/core/invariants.h"
#include "tests/support/files.h"

namespace smr {
namespace {

constexpr std::uint32_t kNone = OpAssembler::kNone;
using StarTriangle = OpAssembler::StarTriangle;
using MadeTriangle = OpAssembler::MadeTriangle;

// ---- the input: a decimation of a small terrain, made here ----

// A counter-based generator (splitmix64): the same sequence with every standard library.
class Rng {
 public:
  explicit Rng(std::uint64_t seed) : state_(seed) {}
  std::uint64_t next() { return mix64(state_ += 0x9E3779B97F4A7C15ULL); }
  std::uint32_t below(std::uint32_t n) { return static_cast<std::uint32_t>(next() % n); }
  template <class T>
  void shuffle(std::vector<T>& v) {
    for (std::size_t i = v.size(); i > 1; --i) std::swap(v[i - 1], v[below(std::uint32_t(i))]);
  }

 private:
  std::uint64_t state_;
};

struct Tri {
  std::array<std::uint32_t, 3> v{};  // vertex ids, counter-clockwise
  std::uint32_t id = 0;              // the builder's id (scrambled: not the index)
  std::uint32_t creator = kNone;     // the removal that made it (kNone: a finest triangle)
  std::uint32_t destroyer = kNone;   // the removal whose star holds it (kNone: alive at the end)
  bool is_void = false;
};

struct Removal {
  std::vector<std::uint32_t> vertices;  // removed, in the order the op introduces them
  std::vector<std::uint32_t> star;      // indices into Decimation::tris, in F's order
  std::vector<std::uint32_t> made;      // indices into Decimation::tris, in PreF's order
  double error = 0.0;                   // its own bound
};

struct Recipe {
  const char* name;
  int n;                   // samples per side
  std::uint64_t seed;      // of the vertex ids, diagonals, removal order, errors, void flags
  double removed;          // share of the samples to remove (about)
  bool pairs;              // a quarter of the interior removals take two adjacent vertices
  bool border;             // border vertices (not the corners) are removed too
  double err0, err_final;  // the header handed to finish()
};

struct Decimation {
  Recipe recipe;
  std::vector<Vec3> position;  // by vertex id
  std::vector<Tri> tris;       // every triangle ever made, the finest first
  std::vector<Removal> removals;
  std::vector<std::uint32_t> base;  // the triangles alive at the end, in R^0's order
  CrmrInfo info;                    // as handed to finish()

  StarTriangle star_triangle(std::uint32_t t) const {
    return {tris[t].v, tris[t].id, tris[t].creator, tris[t].is_void};
  }
};

class Decimator {
 public:
  explicit Decimator(const Recipe& r) : r_(r), rng_(r.seed) {}

  Decimation run() {
    d_.recipe = r_;
    make_grid();
    std::vector<std::uint32_t> candidates;
    for (std::uint32_t v = 0; v < grid_.size(); ++v) {
      if (!corner(v) && (r_.border || !border(v))) candidates.push_back(v);
    }
    const auto target = static_cast<std::size_t>(r_.removed * double(grid_.size()));
    std::vector<std::uint8_t> gone(grid_.size(), 0);
    std::size_t removed = 0;
    // Removals whose hole ear clipping cannot fill are tried again in the next round.
    for (int round = 0; round < 3 && removed < target; ++round) {
      rng_.shuffle(candidates);
      for (std::size_t i = 0; i < candidates.size() && removed < target; ++i) {
        const std::uint32_t v = candidates[i];
        if (gone[v]) continue;
        std::vector<std::uint32_t> s{v};
        if (r_.pairs && !border(v) && rng_.below(4) == 0) {
          const std::uint32_t u = interior_neighbour(v);
          if (u != kNone) s = rng_.below(2) == 0 ? std::vector{v, u} : std::vector{u, v};
        }
        // Own bounds grow as the mesh coarsens, with noise: independent removals interleave.
        const double error = 0.25 * double(1 + rng_.below(8) + (8 * removed) / target);
        if (!remove(s, error)) continue;
        for (std::uint32_t x : s) gone[x] = 1;
        removed += s.size();
      }
    }
    for (std::uint32_t t = 0; t < d_.tris.size(); ++t) {
      if (d_.tris[t].destroyer == kNone) d_.base.push_back(t);
    }
    rng_.shuffle(d_.base);
    d_.info.kind = ModelKind::kTerrain;
    d_.info.grid_width = d_.info.grid_height = r_.n;
    d_.info.err0 = r_.err0;
    d_.info.err_final = r_.err_final;
    d_.info.vertex_count = grid_.size();
    for (const Vec3& p : d_.position) d_.info.bounds.add(p);
    d_.info.source = r_.name;
    d_.info.builder = "op_assembly_test";
    return std::move(d_);
  }

 private:
  bool border(std::uint32_t v) const {
    const GridPoint g = grid_[v];
    return g.x == 0 || g.y == 0 || g.x == r_.n - 1 || g.y == r_.n - 1;
  }
  bool corner(std::uint32_t v) const {
    const GridPoint g = grid_[v];
    return (g.x == 0 || g.x == r_.n - 1) && (g.y == 0 || g.y == r_.n - 1);
  }
  std::int64_t orient3(std::uint32_t a, std::uint32_t b, std::uint32_t c) const {
    return orient(grid_[a], grid_[b], grid_[c]);
  }

  // Samples with scrambled vertex ids (an op's vertices after the introduced ones are sorted by
  // id, which is then not the grid order) and two triangles per cell, diagonals drawn at random.
  void make_grid() {
    const auto n = static_cast<std::uint32_t>(r_.n);
    std::vector<std::uint32_t> id(n * n);
    std::iota(id.begin(), id.end(), 0u);
    rng_.shuffle(id);
    grid_.resize(n * n);
    d_.position.resize(n * n);
    incident_.resize(n * n);
    for (std::uint32_t y = 0; y < n; ++y) {
      for (std::uint32_t x = 0; x < n; ++x) {
        const std::uint32_t v = id[y * n + x];
        grid_[v] = {std::int64_t{x}, std::int64_t{y}};
        const double z = 40.0 * std::sin(0.31 * x) * std::cos(0.23 * y) + 0.01 * rng_.below(100);
        d_.position[v] = Vec3(double(x), double(y), z);
      }
    }
    for (std::uint32_t y = 0; y + 1 < n; ++y) {
      for (std::uint32_t x = 0; x + 1 < n; ++x) {
        const std::uint32_t a = id[y * n + x], b = id[y * n + x + 1];
        const std::uint32_t c = id[(y + 1) * n + x + 1], e = id[(y + 1) * n + x];
        if (rng_.below(2) == 0) {
          add_triangle({a, b, c}, kNone);
          add_triangle({a, c, e}, kNone);
        } else {
          add_triangle({a, b, e}, kNone);
          add_triangle({b, c, e}, kNone);
        }
      }
    }
  }

  std::uint32_t add_triangle(const std::array<std::uint32_t, 3>& v, std::uint32_t creator) {
    const auto t = static_cast<std::uint32_t>(d_.tris.size());
    // Unique (t * odd is a bijection mod 2^32) and far from the index.
    d_.tris.push_back({v, t * 0x9E3779B1u + 12345u, creator, kNone, rng_.below(8) == 0});
    for (std::uint32_t x : v) incident_[x].push_back(t);
    return t;
  }

  std::uint32_t interior_neighbour(std::uint32_t v) {
    std::vector<std::uint32_t> near;
    for (std::uint32_t t : incident_[v]) {
      for (std::uint32_t x : d_.tris[t].v) {
        if (x != v && !border(x)) near.push_back(x);
      }
    }
    return near.empty() ? kNone : near[rng_.below(std::uint32_t(near.size()))];
  }

  // The hole that removing `s` leaves, as a counter-clockwise polygon: the boundary of its star,
  // a cycle for interior vertices; for a border vertex the chain of its link, closed by the
  // border segment through it. False if the boundary is not one simple cycle or chain through
  // every vertex of the star but `s` (two stars can enclose a third vertex).
  bool hole(const std::vector<std::uint32_t>& s, const std::vector<std::uint32_t>& star,
            std::vector<std::uint32_t>& poly) const {
    std::set<std::pair<std::uint32_t, std::uint32_t>> edges;
    for (std::uint32_t t : star) {
      const auto& v = d_.tris[t].v;
      for (int k = 0; k < 3; ++k) edges.insert({v[k], v[(k + 1) % 3]});
    }
    auto removed = [&](std::uint32_t x) { return std::find(s.begin(), s.end(), x) != s.end(); };
    std::map<std::uint32_t, std::uint32_t> next;
    std::set<std::uint32_t> has_incoming;
    int touching = 0;
    for (const auto& [a, b] : edges) {
      if (edges.count({b, a})) continue;
      if (removed(a) || removed(b)) {
        ++touching;
      } else if (!next.emplace(a, b).second || !has_incoming.insert(b).second) {
        return false;
      }
    }
    const bool chain = touching == 2 && s.size() == 1 && border(s[0]);
    if (next.empty() || (touching != 0 && !chain)) return false;
    std::uint32_t start = next.begin()->first;
    if (chain) {
      for (const auto& [a, b] : next) {
        if (!has_incoming.count(a)) start = a;
      }
    }
    poly.clear();
    std::uint32_t a = start;
    do {
      poly.push_back(a);
      const auto it = next.find(a);
      if (it == next.end()) break;
      a = it->second;
    } while (a != start && poly.size() <= next.size());
    std::set<std::uint32_t> kept;
    for (std::uint32_t t : star) {
      for (std::uint32_t x : d_.tris[t].v) {
        if (!removed(x)) kept.insert(x);
      }
    }
    const std::set<std::uint32_t> distinct(poly.begin(), poly.end());
    return distinct.size() == poly.size() && distinct == kept &&
           poly.size() == next.size() + (chain ? 1 : 0) && poly.size() >= 3;
  }

  // Ear clipping with exact orientations: an ear is a strictly convex corner whose closed
  // triangle holds no other polygon vertex. The search starts at a random corner.
  bool ear_clip(std::vector<std::uint32_t> poly, std::vector<std::array<std::uint32_t, 3>>& out) {
    out.clear();
    while (poly.size() > 3) {
      const std::size_t n = poly.size(), start = rng_.below(std::uint32_t(n));
      bool clipped = false;
      for (std::size_t j = 0; j < n && !clipped; ++j) {
        const std::size_t i = (start + j) % n;
        const std::uint32_t p = poly[(i + n - 1) % n], c = poly[i], q = poly[(i + 1) % n];
        if (orient3(p, c, q) <= 0) continue;
        bool blocked = false;
        for (std::uint32_t x : poly) {
          if (x == p || x == c || x == q) continue;
          blocked |= orient3(p, c, x) >= 0 && orient3(c, q, x) >= 0 && orient3(q, p, x) >= 0;
        }
        if (blocked) continue;
        out.push_back({p, c, q});
        poly.erase(poly.begin() + static_cast<std::ptrdiff_t>(i));
        clipped = true;
      }
      if (!clipped) return false;
    }
    if (orient3(poly[0], poly[1], poly[2]) <= 0) return false;
    out.push_back({poly[0], poly[1], poly[2]});
    return true;
  }

  // One removal: its star (in a random order) out, the hole's triangulation in.
  bool remove(const std::vector<std::uint32_t>& s, double error) {
    std::vector<std::uint32_t> star;
    for (std::uint32_t x : s) star.insert(star.end(), incident_[x].begin(), incident_[x].end());
    std::sort(star.begin(), star.end());
    star.erase(std::unique(star.begin(), star.end()), star.end());
    std::vector<std::uint32_t> poly;
    std::vector<std::array<std::uint32_t, 3>> fill;
    if (!hole(s, star, poly) || !ear_clip(poly, fill)) return false;
    rng_.shuffle(star);
    const auto k = static_cast<std::uint32_t>(d_.removals.size());
    for (std::uint32_t t : star) {
      d_.tris[t].destroyer = k;
      for (std::uint32_t x : d_.tris[t].v) std::erase(incident_[x], t);
    }
    Removal r{s, star, {}, error};
    for (const auto& v : fill) r.made.push_back(add_triangle(v, k));
    d_.removals.push_back(std::move(r));
    return true;
  }

  Recipe r_;
  Rng rng_;
  Decimation d_;
  std::vector<GridPoint> grid_;                       // by vertex id
  std::vector<std::vector<std::uint32_t>> incident_;  // by vertex id: its alive triangles
};

const Recipe kRecipes[] = {
    // Pairs and border removals; err0 below the removals' errors (finish() raises it).
    {"mixed", 33, 11, 0.85, true, true, 0.5, 0.1},
    // One interior vertex per removal (as block decimation makes them); err0 above them all.
    {"single", 24, 5, 0.80, false, false, 9.0, 0.0},
};

const Decimation& decimation(const std::string& name) {
  static std::map<std::string, Decimation> cache;
  auto it = cache.find(name);
  if (it != cache.end()) return it->second;
  for (const Recipe& r : kRecipes) {
    if (r.name == name) return cache.emplace(name, Decimator(r).run()).first->second;
  }
  throw std::logic_error("no recipe " + name);
}

// ---- the oracle: an in-memory replay of the removals ----

struct Expected {
  CrmrInfo info;
  std::vector<double> err;             // per removal: own bound raised to its children's
  std::vector<std::uint32_t> removal;  // per op from 1: its removal
  std::vector<Op> ops;                 // every field but sphere, cone, roi and subtree_cone
  // Per op, parallel to its coarser links (sorted by triangle and edge): the other acceptable
  // target where PreF's triangle and the one across lie in the same fragment (either names the
  // edge there), else the link's own.
  std::vector<std::vector<EdgeRef>> alternative;
  std::uint64_t dag_height = 0, links = 0, destroyed = 0, made = 0;
};

std::uint32_t index_in(const std::vector<Vertex>& vs, std::uint32_t id) {
  for (std::uint32_t i = 0; i < vs.size(); ++i) {
    if (vs[i].id.value == id) return i;
  }
  throw std::logic_error("oracle: a corner is not among the op's vertices");
}

// An op's vertices (`first`, then the rest of its fragment's by id; R^0 introduces all) and its
// fragment: killers and death_res from the removals that destroy its triangles.
void fill_fragment(Op& op, const Decimation& d, std::span<const std::uint32_t> first,
                   std::span<const std::uint32_t> frag, const std::vector<std::uint32_t>& op_of,
                   const Expected& x) {
  std::set<std::uint32_t> rest;
  for (std::uint32_t t : frag) rest.insert(d.tris[t].v.begin(), d.tris[t].v.end());
  for (std::uint32_t v : first) {
    op.vertices.push_back({VertexId(v), d.position[v]});
    rest.erase(v);
  }
  for (std::uint32_t v : rest) op.vertices.push_back({VertexId(v), d.position[v]});
  op.new_vertex_count = op.id == kBaseOp ? std::uint32_t(op.vertices.size())
                                         : static_cast<std::uint32_t>(first.size());
  for (const Vertex& v : op.vertices) op.box.add(v.p);
  std::set<OpId> children;
  for (std::uint32_t t : frag) {
    const Tri& tri = d.tris[t];
    FragmentTriangle ft;
    for (int k = 0; k < 3; ++k) ft.v[k] = index_in(op.vertices, tri.v[k]);
    if (tri.is_void) ft.flags = FragmentTriangle::kVoid;
    // Its killer is the op of the removal that made it (that removal destroyed it, reversed).
    if (tri.creator != kNone) {
      ft.killer = OpId(op_of[tri.creator]);
      ft.death_res = resolution_of(x.info, x.err[tri.creator]);
      children.insert(ft.killer);
    }
    op.fragment.push_back(ft);
  }
  op.children.assign(children.begin(), children.end());
}

// The neighbours in F by brute force over vertex ids: across edge k of triangle i, the triangle
// with the reversed edge (the oracle of fragment_neighbours).
std::vector<std::array<std::int32_t, 3>> brute_neighbours(const Op& op) {
  std::vector<std::array<std::int32_t, 3>> nbr(
      op.fragment.size(), {FragmentTriangle::kNoNeighbour, FragmentTriangle::kNoNeighbour,
                           FragmentTriangle::kNoNeighbour});
  for (std::size_t i = 0; i < op.fragment.size(); ++i) {
    for (std::size_t j = 0; j < op.fragment.size(); ++j) {
      for (int k = 0; k < 3; ++k) {
        for (int l = 0; l < 3; ++l) {
          const FragmentTriangle &a = op.fragment[i], &b = op.fragment[j];
          if (nbr[i][k] < 0 && op.vertex_id(a, k) == op.vertex_id(b, (l + 1) % 3) &&
              op.vertex_id(a, (k + 1) % 3) == op.vertex_id(b, l))
            nbr[i][k] = int(j);  // the first, as fragment_neighbours' scan
        }
      }
    }
  }
  return nbr;
}

using DirectedEdge = std::pair<std::uint32_t, std::uint32_t>;
struct Alive {
  TriRef ref;
  int edge;  // the edge's index in that triangle
};

// The coarser-edge links of op `i` (removal `k`): for each boundary edge a->b of F, the newer of
// PreF's triangle with a->b and the triangle with b->a alive just before the op (none on the
// model boundary). `alive` is the mesh M^{i-1} by directed edge.
void link_op(Op& op, std::vector<EdgeRef>& alternative, const Decimation& d, const Removal& r,
             const std::map<DirectedEdge, Alive>& alive) {
  std::set<DirectedEdge> in_f;
  for (std::uint32_t t : r.star) {
    const auto& v = d.tris[t].v;
    for (int k = 0; k < 3; ++k) in_f.insert({v[k], v[(k + 1) % 3]});
  }
  for (std::uint32_t j = 0; j < r.star.size(); ++j) {
    const auto& v = d.tris[r.star[j]].v;
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t a = v[k], b = v[(k + 1) % 3];
      if (in_f.count({b, a})) continue;
      const auto across = alive.find({b, a});
      if (across == alive.end()) continue;
      const Alive& inside = alive.at({a, b});  // PreF's: F and PreF have one boundary
      const EdgeRef in{inside.ref, std::uint8_t(inside.edge)};
      const EdgeRef out{across->second.ref, std::uint8_t(across->second.edge)};
      const bool same = in.tri.op == out.tri.op;
      op.coarser.push_back({j, std::uint8_t(k), in.tri.op > out.tri.op || same ? in : out});
      alternative.push_back(same ? out : op.coarser.back().coarser);
    }
  }
}

Expected replay(const Decimation& d) {
  Expected x;
  const std::size_t m = d.removals.size();
  x.err.resize(m);
  for (std::size_t k = 0; k < m; ++k) {
    double e = d.removals[k].error;
    for (std::uint32_t t : d.removals[k].star) {
      if (d.tris[t].creator != kNone) e = std::max(e, x.err[d.tris[t].creator]);
    }
    x.err[k] = e;
    x.destroyed += d.removals[k].star.size();
    x.made += d.removals[k].made.size();
  }
  // Falling error, the later removal first among equals: op i + 1 is order[i].
  std::vector<std::uint32_t>& order = x.removal;
  std::vector<std::uint32_t> op_of(m);
  order.resize(m);
  std::iota(order.begin(), order.end(), 0u);
  std::sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) {
    return x.err[a] > x.err[b] || (x.err[a] == x.err[b] && a > b);
  });
  for (std::uint32_t i = 0; i < m; ++i) op_of[order[i]] = i + 1;
  x.info = d.info;
  for (double e : x.err) x.info.err0 = std::max(x.info.err0, e);
  x.info.err_final = std::min(x.info.err_final, x.info.err0);
  // Where each triangle is held: the fragment of the op of the removal that destroyed it (R^0's
  // if none), at its place there.
  std::vector<TriRef> home(d.tris.size());
  for (std::uint32_t j = 0; j < d.base.size(); ++j) home[d.base[j]] = {kBaseOp, j};
  for (std::uint32_t k = 0; k < m; ++k) {
    const auto& star = d.removals[k].star;
    for (std::uint32_t j = 0; j < star.size(); ++j) home[star[j]] = {OpId(op_of[k]), j};
  }
  std::map<DirectedEdge, Alive> alive;  // the mesh M^{i-1}, replayed from R^0
  auto live = [&](const Op& op, std::span<const std::uint32_t> frag) {
    for (std::uint32_t j = 0; j < frag.size(); ++j) {
      const auto& v = d.tris[frag[j]].v;
      for (int k = 0; k < 3; ++k) {
        if (!alive.insert({{v[k], v[(k + 1) % 3]}, {TriRef{op.id, j}, k}}).second)
          throw std::logic_error("oracle: a directed edge alive twice");
      }
    }
  };
  x.ops.resize(m + 1);
  x.alternative.resize(m + 1);
  x.ops[0].id = kBaseOp;
  x.ops[0].error = x.info.err0;
  fill_fragment(x.ops[0], d, {}, d.base, op_of, x);
  live(x.ops[0], d.base);
  std::vector<std::uint64_t> depth(m + 1, 0);
  for (std::uint32_t i = 1; i <= m; ++i) {
    const Removal& r = d.removals[order[i - 1]];
    Op& op = x.ops[i];
    op.id = OpId(i);
    op.error = x.err[order[i - 1]];
    op.birth_res = resolution_of(x.info, op.error);
    fill_fragment(op, d, r.vertices, r.star, op_of, x);
    std::set<OpId> parents;
    for (std::uint32_t t : r.made) {
      op.pre.push_back(home[t]);
      parents.insert(home[t].op);
      PreTriangle pt;
      for (int k = 0; k < 3; ++k) pt.v[k] = index_in(op.vertices, d.tris[t].v[k]);
      if (d.tris[t].is_void) pt.flags = FragmentTriangle::kVoid;
      op.pre_tris.push_back(pt);
    }
    op.parents.assign(parents.begin(), parents.end());
    for (OpId p : op.parents) depth[i] = std::max(depth[i], depth[p.value] + 1);
    x.dag_height = std::max(x.dag_height, depth[i]);
    link_op(op, x.alternative[i], d, r, alive);
    x.links += op.coarser.size();
    for (std::uint32_t t : r.made) {
      const auto& v = d.tris[t].v;
      for (int k = 0; k < 3; ++k) alive.erase({v[k], v[(k + 1) % 3]});
    }
    live(op, r.star);
  }
  return x;
}

std::string str(TriRef t) {
  return "op " + std::to_string(t.op.value) + " triangle " + std::to_string(t.index);
}
std::string str(const std::vector<OpId>& ids) {
  std::string s = "{";
  for (OpId id : ids) {
    s += ' ';
    s += std::to_string(id.value);
  }
  return s + " }";
}

// The differences between an op the assembler made and the replay's, as messages.
void compare_op(const Op& got, const Expected& x, std::size_t i, std::vector<std::string>& out) {
  const Op& want = x.ops[i];
  const std::string name = "op " + std::to_string(i) + ": ";
  auto expect = [&](bool ok, const std::string& what) {
    if (!ok) out.push_back(name + what);
  };
  expect(got.id == want.id, "id " + std::to_string(got.id.value));
  expect(got.error == want.error, "error " + std::to_string(got.error) + ", the replay's " +
                                      std::to_string(want.error) + " (the order differs)");
  expect(got.birth_res == want.birth_res, "birth_res differs");
  expect(got.vertices == want.vertices, "vertices (ids, order or positions) differ");
  expect(got.new_vertex_count == want.new_vertex_count, "new_vertex_count differs");
  expect(got.box == want.box, "box differs from its vertices' bounds");
  expect(got.fragment.size() == want.fragment.size(), "fragment size differs");
  for (std::size_t j = 0; j < std::min(got.fragment.size(), want.fragment.size()); ++j) {
    const FragmentTriangle &g = got.fragment[j], &w = want.fragment[j];
    const std::string t = "triangle " + std::to_string(j) + " ";
    expect(g.v == w.v && g.flags == w.flags, t + "corners or flags differ");
    expect(g.killer == w.killer, t + "killer " + std::to_string(g.killer.value) +
                                     ", the replay's " + std::to_string(w.killer.value));
    expect(g.death_res == w.death_res, t + "death_res differs");
  }
  {
    std::vector<std::array<std::int32_t, 3>> derived;
    fragment_neighbours(got.fragment, derived);
    expect(derived == brute_neighbours(want), "neighbours in F differ");
  }
  expect(got.pre.size() == want.pre.size(), "PreF size differs");
  for (std::size_t j = 0; j < std::min(got.pre.size(), want.pre.size()); ++j) {
    expect(got.pre[j] == want.pre[j], "PreF " + std::to_string(j) + " is " + str(got.pre[j]) +
                                          ", the replay's owner " + str(want.pre[j]));
  }
  expect(got.pre_tris == want.pre_tris, "pre_tris (corners or flags) differ");
  expect(got.parents == want.parents,
         "parents " + str(got.parents) + ", the replay's " + str(want.parents));
  expect(got.children == want.children,
         "children " + str(got.children) + ", the replay's " + str(want.children));
  std::vector<CoarserLink> links = got.coarser;
  std::sort(links.begin(), links.end(), [](const CoarserLink& a, const CoarserLink& b) {
    return std::pair(a.tri, a.edge) < std::pair(b.tri, b.edge);
  });
  std::vector<std::size_t> by(want.coarser.size());  // the replay's, sorted alike
  std::iota(by.begin(), by.end(), std::size_t{0});
  std::sort(by.begin(), by.end(), [&](std::size_t a, std::size_t b) {
    return std::pair(want.coarser[a].tri, want.coarser[a].edge) <
           std::pair(want.coarser[b].tri, want.coarser[b].edge);
  });
  expect(links.size() == by.size(), "coarser links: " + std::to_string(links.size()) +
                                        ", the replay's " + std::to_string(by.size()));
  for (std::size_t j = 0; j < std::min(links.size(), by.size()); ++j) {
    const CoarserLink& w = want.coarser[by[j]];
    const CoarserLink& g = links[j];
    const bool ok = g.tri == w.tri && g.edge == w.edge &&
                    (g.coarser == w.coarser || g.coarser == x.alternative[i][by[j]]);
    expect(ok, "coarser link of triangle " + std::to_string(g.tri) + " edge " +
                   std::to_string(g.edge) + " names " + str(g.coarser.tri) + ", the replay's " +
                   str(w.coarser.tri));
  }
}

// ---- running the assembler ----

// Collects the ops; as an encoding sink (OpSink::encodes) it keeps each op made by encode() (on
// the workers) under its id and takes it back in add_encoded(), which must come in id order.
class Collector final : public OpSink {
 public:
  explicit Collector(bool encoding) : encoding_(encoding) {}
  std::function<void()> on_begin;

  void begin(const CrmrInfo& header, std::uint64_t op_count) override {
    crmr_.header = header;
    announced_ = op_count;
    if (on_begin) on_begin();
  }
  void add(Op&& op) override {
    if (encoding_) ADD_FAILURE() << "add() called on a sink that encodes";
    push(std::move(op));
  }
  bool encodes() const override { return encoding_; }
  void encode(Op& op, std::vector<std::uint8_t>& out) const override {
    Op copy = op;
    compute_op_bounds(copy);  // the sink's share (crmr.h)
    const std::uint64_t id = op.id.value;
    {
      std::lock_guard lock(mutex_);
      if (!pending_.emplace(id, std::move(copy)).second) ADD_FAILURE() << "op encoded twice";
    }
    const auto* b = reinterpret_cast<const std::uint8_t*>(&id);
    out.insert(out.end(), b, b + sizeof id);
  }
  void add_encoded(std::span<const std::uint8_t> bytes) override {
    ASSERT_EQ(bytes.size(), sizeof(std::uint64_t)) << "one op's bytes, exactly";
    std::uint64_t id = 0;
    std::memcpy(&id, bytes.data(), sizeof id);
    std::lock_guard lock(mutex_);
    const auto it = pending_.find(id);
    ASSERT_NE(it, pending_.end()) << "op " << id << " handed over but never encoded";
    push(std::move(it->second));
    pending_.erase(it);
  }
  Crmr take() {
    EXPECT_EQ(crmr_.ops.size(), announced_) << "begin() announced another op count";
    EXPECT_TRUE(pending_.empty()) << "ops encoded but never handed over";
    compute_rois(crmr_);
    return std::move(crmr_);
  }

 private:
  void push(Op&& op) {
    EXPECT_EQ(op.id.value, crmr_.ops.size()) << "ops must arrive in id order";
    crmr_.ops.push_back(std::move(op));
  }
  bool encoding_;
  Crmr crmr_;
  std::uint64_t announced_ = 0;
  mutable std::mutex mutex_;
  mutable std::map<std::uint64_t, Op> pending_;
};

struct Assembled {
  Crmr crmr;
  AssemblyStats stats;
  std::vector<double> err;       // error(k) after the last removal
  std::vector<double> progress;  // as reported
};

std::vector<StarTriangle> star_of(const Decimation& d, std::span<const std::uint32_t> ts) {
  std::vector<StarTriangle> out;
  for (std::uint32_t t : ts) out.push_back(d.star_triangle(t));
  return out;
}

void feed(const Decimation& d, OpAssembler& a) {
  for (std::uint32_t k = 0; k < d.removals.size(); ++k) {
    const Removal& r = d.removals[k];
    std::vector<MadeTriangle> made;
    for (std::uint32_t t : r.made) made.push_back({d.tris[t].v, d.tris[t].id, d.tris[t].is_void});
    ASSERT_EQ(a.add_removal(r.vertices, star_of(d, r.star), made, r.error), k);
  }
}

Assembled assemble(const Decimation& d, AssemblyOptions opt, bool encoding = false,
                   const std::function<void()>& on_begin = {}) {
  Assembled run;
  std::mutex mutex;
  opt.progress = [&](double f) {
    std::lock_guard lock(mutex);
    run.progress.push_back(f);
  };
  OpAssembler a(opt);
  feed(d, a);
  EXPECT_EQ(a.removals(), d.removals.size());
  for (std::uint32_t k = 0; k < a.removals(); ++k) run.err.push_back(a.error(k));
  Collector sink(encoding);
  sink.on_begin = on_begin;
  a.finish(
      d.info, star_of(d, d.base), [&](std::uint32_t v) { return d.position.at(v); }, sink);
  run.stats = a.stats();
  run.crmr = sink.take();
  return run;
}

// Files open in `dir` (scratch files are unlinked at once, so only their descriptors show them).
int open_files_in(const std::filesystem::path& dir) {
  const std::string prefix = std::filesystem::canonical(dir).string() + "/";
  int n = 0;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator("/proc/self/fd", ec)) {
    std::error_code link_ec;
    const std::string target = std::filesystem::read_symlink(e.path(), link_ec).string();
    if (!link_ec && target.rfind(prefix, 0) == 0) ++n;
  }
  return n;
}

// ---- the tests ----

class PerRecipe : public ::testing::TestWithParam<std::string> {};

TEST_P(PerRecipe, OpsMatchAnInMemoryReplayOfTheRemovals) {
  const Decimation& d = decimation(GetParam());
  const Expected x = replay(d);
  // The input is what the test means it to be: most ops away from the reverse of the removals'
  // order, many ties, many errors raised to a child's, several batches of ops and chunks of
  // records.
  const std::size_t m = d.removals.size();
  ASSERT_GT(m, 300u);
  std::size_t moved = 0, ties = 0, raised = 0;
  for (std::uint32_t i = 2; i <= m; ++i) ties += x.ops[i].error == x.ops[i - 1].error;
  for (std::size_t i = 0; i < m; ++i) moved += x.removal[i] != m - 1 - i;
  for (std::size_t k = 0; k < m; ++k) raised += x.err[k] > d.removals[k].error;
  EXPECT_GT(moved, m / 2);
  EXPECT_GT(ties, m / 4);
  EXPECT_GT(raised, m / 10);
  EXPECT_GT(x.links, m);
  std::size_t pairs = 0, border = 0;  // where the recipe has them
  const double last = d.recipe.n - 1;
  for (const Removal& r : d.removals) {
    pairs += r.vertices.size() == 2;
    for (std::uint32_t v : r.vertices) {
      const Vec3& p = d.position[v];
      border += p.x == 0 || p.y == 0 || p.x == last || p.y == last;
    }
  }
  EXPECT_EQ(pairs > m / 10, d.recipe.pairs);
  EXPECT_EQ(border > m / 20, d.recipe.border);

  const Assembled run = assemble(d, AssemblyOptions{});
  EXPECT_EQ(run.err, x.err) << "error(k): own bound raised to its children's";
  EXPECT_EQ(run.crmr.header, x.info) << "err0 raised to the largest error, err_final capped";
  ASSERT_EQ(run.crmr.ops.size(), x.ops.size());
  std::vector<std::string> diffs;
  for (std::size_t i = 0; i < x.ops.size(); ++i) compare_op(run.crmr.ops[i], x, i, diffs);
  std::string first;
  for (std::size_t j = 0; j < std::min<std::size_t>(diffs.size(), 10); ++j)
    first += "\n  " + diffs[j];
  EXPECT_TRUE(diffs.empty()) << diffs.size() << " differences from the replay:" << first;

  const InvariantReport r = check_crmr(run.crmr);
  EXPECT_TRUE(r.ok()) << r.summary();
  EXPECT_GT(r.checked, x.ops.size());

  const AssemblyStats& s = run.stats;
  EXPECT_EQ(s.removals, d.removals.size());
  EXPECT_EQ(s.triangles_destroyed, x.destroyed);
  EXPECT_EQ(s.triangles_made, x.made);
  EXPECT_EQ(s.dag_height, x.dag_height);
  EXPECT_EQ(s.links, x.links);
  EXPECT_GT(s.scratch_bytes, 0u);
  ASSERT_FALSE(run.progress.empty());
  EXPECT_TRUE(std::is_sorted(run.progress.begin(), run.progress.end()));
  EXPECT_GE(run.progress.front(), 0.0);
  EXPECT_EQ(run.progress.back(), 1.0);
}

INSTANTIATE_TEST_SUITE_P(OpAssembly, PerRecipe, ::testing::Values("mixed", "single"),
                         [](const auto& p) { return p.param; });

TEST(OpAssembly, SpillsToScratchFilesChangeNoOpAndGoWithTheAssembler) {
  const Decimation& d = decimation("mixed");
  const test::TempDir tmp("op-assembly");
  AssemblyOptions large, tiny;
  large.tmp_dir = tiny.tmp_dir = tmp.path().string();
  tiny.sort_bytes = 4 << 10;    // the sorts spill every few hundred records
  tiny.table_bytes = 48 << 10;  // the per-removal tables live in scratch files
  int open_large = 0, open_tiny = 0;
  const Assembled a = assemble(d, large, false, [&] { open_large = open_files_in(tmp.path()); });
  EXPECT_EQ(open_files_in(tmp.path()), 0) << "scratch files outlive the assembler";
  const Assembled b = assemble(d, tiny, false, [&] { open_tiny = open_files_in(tmp.path()); });
  EXPECT_EQ(open_files_in(tmp.path()), 0) << "scratch files outlive the assembler";
  EXPECT_GT(open_large, 0) << "the scratch files are not in tmp_dir";
  EXPECT_GT(open_tiny, 0) << "the scratch files are not in tmp_dir";
  EXPECT_TRUE(std::filesystem::is_empty(tmp.path())) << "scratch files left beside the user's";
  EXPECT_GT(b.stats.scratch_bytes, a.stats.scratch_bytes) << "the tiny budget spilled nothing";
  EXPECT_TRUE(a.crmr.header == b.crmr.header);
  ASSERT_EQ(a.crmr.ops.size(), b.crmr.ops.size());
  for (std::size_t i = 0; i < a.crmr.ops.size(); ++i) {
    ASSERT_TRUE(a.crmr.ops[i] == b.crmr.ops[i]) << "op " << i << " differs with a tiny budget";
  }
  EXPECT_EQ(a.stats.links, b.stats.links);
  EXPECT_EQ(a.stats.dag_height, b.stats.dag_height);
}

TEST(OpAssembly, ThreadCountAndAnEncodingSinkChangeNoOp) {
  const Decimation& d = decimation("mixed");
  const Assembled ref = assemble(d, AssemblyOptions{});
  struct Variant {
    unsigned threads;
    bool encoding;
    std::uint64_t memory;
  };
  for (const Variant v :
       {Variant{2, false, 64 << 20}, Variant{3, false, 4 << 10}, Variant{0, false, 64 << 20},
        Variant{1, true, 64 << 20}, Variant{3, true, 4 << 10}}) {
    AssemblyOptions opt;
    opt.threads = v.threads;
    opt.sort_bytes = v.memory;
    if (v.memory < (1 << 20)) opt.table_bytes = 48 << 10;  // workers read spilled tables
    const Assembled run = assemble(d, opt, v.encoding);
    const std::string what = std::to_string(v.threads) + " threads" +
                             (v.encoding ? ", encoding sink" : "") + ", budget " +
                             std::to_string(v.memory);
    EXPECT_TRUE(run.crmr.header == ref.crmr.header) << what;
    ASSERT_EQ(run.crmr.ops.size(), ref.crmr.ops.size()) << what;
    for (std::size_t i = 0; i < ref.crmr.ops.size(); ++i) {
      ASSERT_TRUE(run.crmr.ops[i] == ref.crmr.ops[i]) << "op " << i << " differs with " << what;
    }
    EXPECT_EQ(run.stats.dag_height, ref.stats.dag_height) << what;
    EXPECT_EQ(run.stats.links, ref.stats.links) << what;
  }
}

// Runs f, which must throw smr::Error of the internal kind (a builder's broken promise) with a
// message that names the assembler and contains `words`.
template <class F>
void expect_rejected(F&& f, const std::string& words) {
  try {
    f();
    ADD_FAILURE() << "accepted; expected an error about '" << words << "'";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kInternal) << e.what();
    EXPECT_NE(std::string(e.what()).find("op assembly"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
  }
}

TEST(OpAssembly, RejectsRemovalsThatBreakItsContract) {
  const std::uint32_t v[] = {7};
  const MadeTriangle made[] = {{{1, 2, 3}, 100, false}};
  {  // Every creator must be an earlier removal (op_assembly.h): itself and later ones are not.
    OpAssembler a;
    const StarTriangle self[] = {{{1, 2, 7}, 5, 0, false}};
    expect_rejected([&] { a.add_removal(v, self, made, 1.0); }, "later removal");
    const StarTriangle later[] = {{{1, 2, 7}, 5, 3, false}};
    expect_rejected([&] { a.add_removal(v, later, made, 1.0); }, "later removal");
  }
  {  // A removal removes a vertex and makes triangles (an op without PreF has no parent).
    OpAssembler a;
    const StarTriangle star[] = {{{1, 2, 7}, 5, kNone, false}};
    expect_rejected([&] { a.add_removal({}, star, made, 1.0); }, "must remove a vertex");
    expect_rejected([&] { a.add_removal(v, star, {}, 1.0); }, "make triangles");
  }
  {  // finish() is called once, after the last removal.
    const Decimation& d = decimation("single");
    OpAssembler a;
    feed(d, a);
    const auto pos = [&](std::uint32_t x) { return d.position.at(x); };
    Collector sink(false);
    a.finish(d.info, star_of(d, d.base), pos, sink);
    const Removal& r = d.removals[0];
    std::vector<MadeTriangle> m0;
    for (std::uint32_t t : r.made) m0.push_back({d.tris[t].v, d.tris[t].id, false});
    expect_rejected([&] { a.add_removal(r.vertices, star_of(d, r.star), m0, 1.0); },
                    "after finish");
    Collector again(false);
    expect_rejected([&] { a.finish(d.info, star_of(d, d.base), pos, again); }, "twice");
  }
}

// finish() with a base that does not match the removals (run on several threads, so the error
// crosses the workers): each is rejected, and the assembler is destroyed cleanly after.
TEST(OpAssembly, RejectsABaseThatDoesNotMatchTheRemovals) {
  const Decimation& d = decimation("single");
  auto finish_with = [&](const std::vector<StarTriangle>& base) {
    AssemblyOptions opt;
    opt.threads = 2;
    OpAssembler a(opt);
    feed(d, a);
    Collector sink(false);
    a.finish(
        d.info, base, [&](std::uint32_t v) { return d.position.at(v); }, sink);
  };
  const std::vector<StarTriangle> base = star_of(d, d.base);
  const auto made = std::find_if(base.begin(), base.end(),
                                 [](const StarTriangle& t) { return t.creator != kNone; });
  ASSERT_NE(made, base.end());
  {  // A triangle a removal made is in no later star and not in R^0.
    std::vector<StarTriangle> missing = base;
    missing.erase(missing.begin() + (made - base.begin()));
    expect_rejected([&] { finish_with(missing); }, "in no later star nor in R^0");
  }
  {  // A base triangle names as its creator a removal that did not make it.
    std::vector<StarTriangle> renamed = base;
    renamed[std::size_t(made - base.begin())].id ^= 0x40000000u;
    expect_rejected([&] { finish_with(renamed); }, "did not make it");
  }
  {  // A base triangle names a creator that is no removal.
    std::vector<StarTriangle> beyond = base;
    beyond[std::size_t(made - base.begin())].creator = std::uint32_t(d.removals.size());
    expect_rejected([&] { finish_with(beyond); }, "made by no removal");
  }
}

}  // namespace
}  // namespace smr
