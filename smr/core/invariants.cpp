// Executable checks of the CRMR definitions (Brown 4.4.1 complete/minimal, 4.4.2 resolution
// attributes, 4.5.1 Hypermesh, 4.5.2 DAG; Maheshwari 3.1 ROI) and of output tilings.
// Terrain predicates use exact integer arithmetic on grid coordinates.
#include "smr/core/invariants.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <sstream>
#include <unordered_map>
#include <unordered_set>

#include <glm/geometric.hpp>

namespace smr {

void InvariantReport::fail(std::string message) {
  ++failures;
  if (errors.size() < 50) errors.push_back(std::move(message));
}

std::string InvariantReport::summary() const {
  std::ostringstream os;
  os << failures << " failure(s) in " << checked << " checks";
  for (const std::string& e : errors) os << "\n  " << e;
  return os.str();
}

std::int64_t orient(const GridPoint& a, const GridPoint& b, const GridPoint& c) {
  return (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
}

bool interiors_overlap(const GridTriangle& a, const GridTriangle& b) {
  auto separated_by = [](const GridTriangle& s, const GridTriangle& o) {
    for (int k = 0; k < 3; ++k) {
      bool all_out = true;
      for (int j = 0; j < 3 && all_out; ++j) all_out = orient(s[k], s[(k + 1) % 3], o[j]) <= 0;
      if (all_out) return true;
    }
    return false;
  };
  return !separated_by(a, b) && !separated_by(b, a);
}

GridPoint to_grid(const CrmrInfo& info, const Vec3& p) {
  return {std::llround((p.x - info.georef.x0) / info.georef.dx),
          std::llround((p.y - info.georef.y0) / info.georef.dy)};
}

namespace {

__extension__ typedef __int128 i128;

// > 0 when d is strictly inside the circumcircle of counter-clockwise (a, b, c).
i128 incircle(const GridPoint& a, const GridPoint& b, const GridPoint& c, const GridPoint& d) {
  const i128 adx = a.x - d.x, ady = a.y - d.y, bdx = b.x - d.x, bdy = b.y - d.y;
  const i128 cdx = c.x - d.x, cdy = c.y - d.y;
  const i128 ad = adx * adx + ady * ady, bd = bdx * bdx + bdy * bdy, cd = cdx * cdx + cdy * cdy;
  return adx * (bdy * cd - bd * cdy) - ady * (bdx * cd - bd * cdx) + ad * (bdx * cdy - bdy * cdx);
}

struct GridTri {
  std::array<GridPoint, 3> p;
  std::array<VertexId, 3> id;
};

template <class OpT>  // Op or OpView
GridTri grid_tri(const CrmrInfo& info, const OpT& op, const FragmentTriangle& t) {
  GridTri g;
  for (int k = 0; k < 3; ++k) {
    g.p[k] = to_grid(info, op.position(t, k));
    g.id[k] = op.vertex_id(t, k);
  }
  return g;
}

bool interiors_overlap(const GridTri& a, const GridTri& b) {
  return smr::interiors_overlap(a.p, b.p);
}

bool on_domain_boundary(const CrmrInfo& info, const GridPoint& a, const GridPoint& b) {
  const std::int64_t w = info.grid_width - 1, h = info.grid_height - 1;
  return (a.x == 0 && b.x == 0) || (a.x == w && b.x == w) || (a.y == 0 && b.y == 0) ||
         (a.y == h && b.y == h);
}

struct DirectedEdge {
  std::uint64_t a, b;
  friend bool operator==(const DirectedEdge&, const DirectedEdge&) = default;
};
struct EdgeHash {
  std::size_t operator()(const DirectedEdge& e) const {
    return mix64(e.a * 0x9E3779B97F4A7C15ULL ^ e.b);
  }
};

// Boundary of a triangle set as directed edges (those whose reverse is not in the set).
std::vector<DirectedEdge> boundary_of(const std::vector<GridTri>& tris) {
  std::unordered_set<DirectedEdge, EdgeHash> all;
  for (const GridTri& t : tris) {
    for (int k = 0; k < 3; ++k) all.insert({t.id[k].value, t.id[(k + 1) % 3].value});
  }
  std::vector<DirectedEdge> out;
  for (const DirectedEdge& e : all) {
    if (!all.count({e.b, e.a})) out.push_back(e);
  }
  return out;
}

std::string op_name(OpId id) {
  return "op " + std::to_string(id.value);
}

using VertexOwners = std::unordered_map<std::uint64_t, std::pair<OpId, Vec3>>;

// Vertices: new ones introduced by `op`, others introduced earlier with identical positions.
void check_vertices(const Op& op, const std::string& name, InvariantReport& r,
                    VertexOwners& vertex_owner) {
  for (std::size_t i = 0; i < op.vertices.size(); ++i) {
    const Vertex& v = op.vertices[i];
    ++r.checked;
    auto it = vertex_owner.find(v.id.value);
    if (i < op.new_vertex_count) {
      if (it != vertex_owner.end()) {
        r.fail(name + ": new vertex " + std::to_string(v.id.value) + " already introduced by " +
               op_name(it->second.first));
      } else {
        vertex_owner.emplace(v.id.value, std::pair{op.id, v.p});
      }
    } else if (it == vertex_owner.end()) {
      r.fail(name + ": vertex " + std::to_string(v.id.value) + " used before it is introduced");
    } else if (it->second.second != v.p) {
      r.fail(name + ": vertex " + std::to_string(v.id.value) +
             " has a different position than in " + op_name(it->second.first));
    }
  }
}

bool vertex_index_out_of_range(const Op& op, const FragmentTriangle& t, std::size_t i,
                               const std::string& name, InvariantReport& r) {
  for (auto v : t.v) {
    if (v >= op.vertices.size()) {
      r.fail(name + ": triangle " + std::to_string(i) + " has a vertex index out of range");
      return true;
    }
  }
  return false;
}

using Neighbours = std::vector<std::array<std::int32_t, 3>>;  // fragment_neighbours (crmr.h)

// Neighbour links within F are symmetric and share the reversed edge a-b of triangle i's edge k
// (a directed edge used twice breaks the symmetry).
void check_neighbour_link(const Op& op, const Neighbours& nbr, std::size_t i, int k,
                          const std::string& name, InvariantReport& r) {
  const FragmentTriangle& t = op.fragment[i];
  const VertexId a = op.vertex_id(t, k), b = op.vertex_id(t, (k + 1) % 3);
  const auto m = static_cast<std::size_t>(nbr[i][k]);
  const auto& n = op.fragment.at(m);
  bool found = false;
  for (int j = 0; j < 3; ++j) {
    found |= op.vertex_id(n, j) == b && op.vertex_id(n, (j + 1) % 3) == a &&
             nbr[m][j] == static_cast<std::int32_t>(i);
  }
  if (!found) r.fail(name + ": asymmetric neighbour link at triangle " + std::to_string(i));
}

// A coarser link (Hypermesh, Brown 4.5.1) of triangle i's edge k points to a coarser op and
// names the same edge there.
void check_coarser_link(const Crmr& crmr, const Op& op, const FragmentTriangle& t, std::size_t i,
                        int k, const CoarserLink& link, const std::string& name,
                        InvariantReport& r) {
  if (op.id == kBaseOp || link.coarser.tri.op >= op.id) {
    r.fail(name + ": coarser link points to a finer op");
    return;
  }
  const VertexId a = op.vertex_id(t, k), b = op.vertex_id(t, (k + 1) % 3);
  const Op& target = crmr.ops.at(link.coarser.tri.op.value);
  const FragmentTriangle& tt = target.fragment.at(link.coarser.tri.index);
  const int e = link.coarser.edge;
  const VertexId ta = target.vertex_id(tt, e), tb = target.vertex_id(tt, (e + 1) % 3);
  if (!((ta == a && tb == b) || (ta == b && tb == a))) {
    r.fail(name + ": coarser link of triangle " + std::to_string(i) + " names a different edge");
  }
}

// PreF: one triangle of a parent's fragment per entry, and pre_tris holds each as its creator
// does (corners and flags). visit(creator, triangle) sees every PreF triangle.
template <class Visit>
void check_pre(const Crmr& crmr, const Op& op, const std::string& name, InvariantReport& r,
               const char* differs, Visit&& visit) {
  if (op.pre_tris.size() != op.pre.size()) r.fail(name + ": pre_tris does not match PreF");
  for (std::size_t i = 0; i < op.pre.size(); ++i) {
    const TriRef& t = op.pre[i];
    const Op& p = crmr.ops.at(t.op.value);
    const FragmentTriangle& pt = p.fragment.at(t.index);
    visit(p, pt);
    if (i >= op.pre_tris.size()) continue;
    const PreTriangle& mine = op.pre_tris[i];
    bool same = mine.flags == pt.flags;
    for (int k = 0; k < 3 && same; ++k) {
      same = mine.v[k] < op.vertices.size() && op.vertices[mine.v[k]] == p.vertices[pt.v[k]];
    }
    if (!same) r.fail(name + ": PreF triangle " + std::to_string(i) + differs);
  }
}

// Union-find over small index sets (fragment triangles, F and PreF pieces).
struct Components {
  explicit Components(std::size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0); }
  std::size_t find(std::size_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  }
  void join(std::size_t x, std::size_t y) { parent[find(x)] = find(y); }
  std::vector<std::size_t> parent;
};

// F's triangles on the grid, checking indices, orientation, neighbour links and coarser links;
// false if an index is out of range (nothing more can be checked).
bool check_terrain_fragment(const Crmr& crmr, const Op& op, const std::string& name,
                            InvariantReport& r, std::vector<GridTri>& f) {
  const CrmrInfo& info = crmr.header;
  for (std::size_t i = 0; i < op.fragment.size(); ++i) {
    if (vertex_index_out_of_range(op, op.fragment[i], i, name, r)) return false;
  }
  Neighbours nbr;
  fragment_neighbours(op.fragment, nbr);
  for (std::size_t i = 0; i < op.fragment.size(); ++i) {
    const FragmentTriangle& t = op.fragment[i];
    ++r.checked;
    f.push_back(grid_tri(info, op, t));
    if (orient(f.back().p[0], f.back().p[1], f.back().p[2]) <= 0) {
      r.fail(name + ": triangle " + std::to_string(i) + " is not counter-clockwise");
    }
    for (int k = 0; k < 3; ++k) {
      if (nbr[i][k] >= 0) {
        check_neighbour_link(op, nbr, i, k, name, r);
        continue;
      }
      const CoarserLink* link =
          op.coarser_link(static_cast<std::uint32_t>(i), static_cast<std::uint8_t>(k));
      if (on_domain_boundary(info, f.back().p[k], f.back().p[(k + 1) % 3])) {
        if (link != nullptr) r.fail(name + ": model boundary edge has a coarser link");
        continue;
      }
      if (link == nullptr) {
        if (op.id != kBaseOp) {
          r.fail(name + ": fragment boundary edge of triangle " + std::to_string(i) +
                 " has no coarser version");
        }
        continue;
      }
      check_coarser_link(crmr, op, t, i, k, *link, name, r);
    }
  }
  return true;
}

// Complete (Brown 4.4.1): every PreF boundary edge off the model boundary is an F boundary edge;
// and F and PreF cover the same region: equal areas (exact).
void check_terrain_complete(const CrmrInfo& info, const std::vector<GridTri>& f,
                            const std::vector<GridTri>& pre, const std::string& name,
                            InvariantReport& r) {
  ++r.checked;
  const auto bf = boundary_of(f), bp = boundary_of(pre);
  std::unordered_set<DirectedEdge, EdgeHash> bfs(bf.begin(), bf.end());
  std::unordered_map<std::uint64_t, GridPoint> pos;
  for (const GridTri& t : pre) {
    for (int k = 0; k < 3; ++k) pos[t.id[k].value] = t.p[k];
  }
  for (const DirectedEdge& e : bp) {
    if (on_domain_boundary(info, pos[e.a], pos[e.b])) continue;
    if (!bfs.count(e)) {
      r.fail(name + " is incomplete: PreF boundary edge " + std::to_string(e.a) + "-" +
             std::to_string(e.b) + " is not on the boundary of F");
    }
  }
  auto area2 = [](const std::vector<GridTri>& ts) {
    std::int64_t s = 0;
    for (const GridTri& t : ts) s += orient(t.p[0], t.p[1], t.p[2]);
    return s;
  };
  if (area2(f) != area2(pre)) r.fail(name + ": F and PreF cover different areas");
}

// Minimal (Brown 4.4.1): no proper subsets S1 of PreF and S2 of F share a boundary. Such a
// pair covers a region that no other triangle of the op overlaps, so it is a union of connected
// components of the graph joining overlapping PreF and F triangles; the op is minimal iff no
// proper union of components has equal PreF and F boundaries. (An insertion on an edge gives two
// components whose boundaries differ by the split edge: minimal.)
void check_terrain_minimal(const std::vector<GridTri>& f, const std::vector<GridTri>& pre,
                           const std::string& name, InvariantReport& r) {
  ++r.checked;
  const std::size_t n = f.size() + pre.size();
  Components c(n);
  for (std::size_t i = 0; i < f.size(); ++i) {
    for (std::size_t j = 0; j < pre.size(); ++j) {
      if (interiors_overlap(f[i], pre[j])) c.join(i, f.size() + j);
    }
  }
  std::vector<std::size_t> roots;
  for (std::size_t i = 0; i < n; ++i) {
    if (c.find(i) == i) roots.push_back(i);
  }
  const std::size_t k = std::min<std::size_t>(roots.size(), 12);
  for (std::uint32_t mask = 1; k > 1 && mask + 1 < (1u << k); ++mask) {
    std::vector<GridTri> s1, s2;
    for (std::size_t i = 0; i < n; ++i) {
      const auto pos_root = std::find(roots.begin(), roots.begin() + k, c.find(i)) - roots.begin();
      if (pos_root >= static_cast<std::ptrdiff_t>(k) || !(mask & (1u << pos_root))) continue;
      (i < f.size() ? s2 : s1).push_back(i < f.size() ? f[i] : pre[i - f.size()]);
    }
    auto e1 = boundary_of(s1), e2 = boundary_of(s2);
    auto key = [](const DirectedEdge& e) { return std::pair(e.a, e.b); };
    auto less = [&](const DirectedEdge& x, const DirectedEdge& y) { return key(x) < key(y); };
    std::sort(e1.begin(), e1.end(), less);
    std::sort(e2.begin(), e2.end(), less);
    if (!s1.empty() && e1 == e2) {
      r.fail(name +
             " is not minimal: part of PreF is replaced by part of F with the same boundary");
      break;
    }
  }
}

// One 2.5-D op on its own: vertices, fragment, PreF, completeness and minimality.
void check_op_local(const Crmr& crmr, const Op& op, InvariantReport& r,
                    VertexOwners& vertex_owner) {
  const std::string name = op_name(op.id);
  check_vertices(op, name, r, vertex_owner);
  std::vector<GridTri> f, pre;
  if (!check_terrain_fragment(crmr, op, name, r, f)) return;
  check_pre(crmr, op, name, r, " differs from the triangle of its creator (corners or flags)",
            [&](const Op& p, const FragmentTriangle& pt) {
              pre.push_back(grid_tri(crmr.header, p, pt));
            });
  if (op.id == kBaseOp) return;
  check_terrain_complete(crmr.header, f, pre, name, r);
  check_terrain_minimal(f, pre, name, r);
}

// The 3-D counterpart of check_op_local: vertices, in-fragment neighbours, coarser links naming
// the same edge in a coarser op, PreF triangles as their creators hold them, completeness (every
// F boundary edge with a coarser version is a PreF boundary edge; no area or domain in 3-D) and
// minimality: one piece of F is glued to the mesh (a vertex split's star; two glued pieces could
// be two ops), any other piece being a spawned component.
void check_mesh_op_local(const Crmr& crmr, const Op& op, InvariantReport& r,
                         VertexOwners& vertex_owner) {
  const std::string name = op_name(op.id);
  check_vertices(op, name, r, vertex_owner);
  std::unordered_set<DirectedEdge, EdgeHash> f_edges, pre_edges;
  std::vector<DirectedEdge> linked;          // F boundary edges with a coarser version
  std::vector<std::size_t> linked_triangle;  // the F triangle of each
  Components pieces(op.fragment.size());
  for (std::size_t i = 0; i < op.fragment.size(); ++i) {
    if (vertex_index_out_of_range(op, op.fragment[i], i, name, r)) return;
  }
  Neighbours nbr;
  fragment_neighbours(op.fragment, nbr);
  for (std::size_t i = 0; i < op.fragment.size(); ++i) {
    const FragmentTriangle& t = op.fragment[i];
    ++r.checked;
    for (int k = 0; k < 3; ++k) {
      const VertexId a = op.vertex_id(t, k), b = op.vertex_id(t, (k + 1) % 3);
      if (!f_edges.insert({a.value, b.value}).second)
        r.fail(name + ": directed edge used twice in F");
      if (nbr[i][k] >= 0) {
        check_neighbour_link(op, nbr, i, k, name, r);
        pieces.join(i, static_cast<std::size_t>(nbr[i][k]));
        continue;
      }
      const CoarserLink* link =
          op.coarser_link(static_cast<std::uint32_t>(i), static_cast<std::uint8_t>(k));
      if (link == nullptr) continue;  // model boundary (checked through extraction outputs)
      linked.push_back({a.value, b.value});
      linked_triangle.push_back(i);
      check_coarser_link(crmr, op, t, i, k, *link, name, r);
    }
  }
  check_pre(crmr, op, name, r, " differs from its creator's",
            [&](const Op& p, const FragmentTriangle& pt) {
              for (int k = 0; k < 3; ++k) {
                pre_edges.insert({p.vertex_id(pt, k).value, p.vertex_id(pt, (k + 1) % 3).value});
              }
            });
  if (op.id == kBaseOp) return;
  ++r.checked;
  for (const DirectedEdge& e : linked) {
    if (!pre_edges.count(e) || pre_edges.count({e.b, e.a})) {
      r.fail(name + " is incomplete: F boundary edge " + std::to_string(e.a) + "-" +
             std::to_string(e.b) + " is not on the boundary of PreF");
      break;
    }
  }
  // One piece of F is glued to the mesh around PreF; any other piece has no coarser version
  // anywhere: a component the op spawns (Brown Fig. 4.9d).
  std::unordered_set<std::size_t> glued;
  for (std::size_t t : linked_triangle) glued.insert(pieces.find(t));
  if (glued.size() > 1) {
    r.fail(name + " is not minimal: " + std::to_string(glued.size()) +
           " separate pieces of F replace parts of PreF");
  }
}

void check_geometry(const Crmr& crmr, const Op& op, InvariantReport& r) {
  const std::string name = op_name(op.id);
  ++r.checked;
  auto check_tri = [&](const Op& owner, const FragmentTriangle& t) {
    const double tol = 1e-9 * (1.0 + op.sphere.radius + glm::length(op.sphere.center));
    for (int k = 0; k < 3; ++k) {
      const Vec3& p = owner.position(t, k);
      Box3 pb;
      pb.add(p);
      if (!op.box.contains(pb)) r.fail(name + ": box does not contain a vertex");
      if (glm::length(p - op.sphere.center) > op.sphere.radius + tol) {
        r.fail(name + ": bounding sphere does not contain a vertex");
      }
    }
    const Vec3 nrm =
        triangle_normal(owner.position(t, 0), owner.position(t, 1), owner.position(t, 2));
    if (op.cone.half_angle < M_PI &&
        std::acos(std::clamp(glm::dot(nrm, op.cone.axis), -1.0, 1.0)) > op.cone.half_angle + 1e-9) {
      r.fail(name + ": normal cone does not contain a triangle normal");
    }
  };
  for (const FragmentTriangle& t : op.fragment) check_tri(op, t);
  for (const TriRef& t : op.pre)
    check_tri(crmr.ops[t.op.value], crmr.ops[t.op.value].fragment[t.index]);
  if (!op.roi.contains(op.box)) r.fail(name + ": ROI does not contain its own box");
  // The subtree cone holds the op's cone and every child's subtree cone (so every descendant's
  // normals: induction from the leaves).
  if (!cone_contains(op.subtree_cone, op.cone)) r.fail(name + ": subtree cone misses its own cone");
  for (OpId c : op.children) {
    if (!op.roi.contains(crmr.ops[c.value].roi))
      r.fail(name + ": ROI does not contain a child's ROI");
    if (!cone_contains(op.subtree_cone, crmr.ops[c.value].subtree_cone))
      r.fail(name + ": subtree cone misses a child's");
  }
}

}  // namespace

InvariantReport check_crmr(const Crmr& crmr) {
  InvariantReport r;
  if (crmr.ops.empty()) {
    r.fail("CRMR has no base mesh");
    return r;
  }
  if (!crmr.ops[0].pre.empty()) r.fail("R^0 has a pre-operation set");
  std::unordered_map<std::uint64_t, std::pair<OpId, Vec3>> vertex_owner;
  std::vector<std::vector<OpId>> children(crmr.ops.size());
  std::vector<std::vector<OpId>> killers;  // per op, per triangle
  for (const Op& op : crmr.ops) killers.emplace_back(op.fragment.size());
  for (std::size_t i = 0; i < crmr.ops.size(); ++i) {
    const Op& op = crmr.ops[i];
    ++r.checked;
    if (op.id.value != i)
      r.fail("op at position " + std::to_string(i) + " has id " + std::to_string(op.id.value));
    if (!(op.birth_res >= 0.0 && op.birth_res <= 1.0))
      r.fail(op_name(op.id) + ": birth_res outside [0,1]");
    // Terrain: the whole sequence is monotone (each op is the mesh-wide next step). 3-D: along the
    // DAG (an op is never coarser than a parent; each op's error is its own bound or a
    // descendant's), checked below.
    for (OpId p : op.parents) {
      if (p.value < i && op.birth_res < crmr.ops[p.value].birth_res) {
        r.fail(op_name(op.id) + ": coarser than its parent " + op_name(p));
      }
    }
    if (crmr.header.kind == ModelKind::kTerrain && i > 0 &&
        op.birth_res < crmr.ops[i - 1].birth_res) {
      r.fail(op_name(op.id) + ": birth_res decreases (" + std::to_string(op.birth_res) + " after " +
             std::to_string(crmr.ops[i - 1].birth_res) + ")");
    }
    if (i > 0 && std::abs(resolution_of(crmr.header, op.error) - op.birth_res) > 1e-12) {
      r.fail(op_name(op.id) + ": birth_res does not match its error");
    }
    // Above err0 its resolution would be clamped to 0 and the RCF would read a smaller error.
    if (op.error > crmr.header.err0) {
      r.fail(op_name(op.id) + ": error " + std::to_string(op.error) + " above err0 " +
             std::to_string(crmr.header.err0));
    }
    if (op.fragment.empty()) r.fail(op_name(op.id) + ": empty fragment");
    if (i > 0 && op.pre.empty()) r.fail(op_name(op.id) + ": empty pre-operation set");
    std::vector<OpId> parents;
    for (const TriRef& t : op.pre) {
      if (t.op >= op.id || t.index >= crmr.ops[t.op.value].fragment.size()) {
        r.fail(op_name(op.id) + ": PreF names a triangle that does not precede it");
        continue;
      }
      OpId& k = killers[t.op.value][t.index];
      if (k.valid())
        r.fail(op_name(op.id) + ": replaces a triangle already replaced by " + op_name(k));
      k = op.id;
      parents.push_back(t.op);
    }
    std::sort(parents.begin(), parents.end());
    parents.erase(std::unique(parents.begin(), parents.end()), parents.end());
    if (parents != op.parents)
      r.fail(op_name(op.id) + ": parents differ from those implied by PreF");
    for (OpId p : parents) children[p.value].push_back(op.id);
  }
  for (std::size_t i = 0; i < crmr.ops.size(); ++i) {
    const Op& op = crmr.ops[i];
    if (children[i] != op.children)
      r.fail(op_name(op.id) + ": children differ from those implied by PreF");
    for (std::size_t j = 0; j < op.fragment.size(); ++j) {
      const FragmentTriangle& t = op.fragment[j];
      const OpId k = killers[i][j];
      const double expect = k.valid() ? crmr.ops[k.value].birth_res : 1.0;
      if (t.killer != k)
        r.fail(op_name(op.id) + ": triangle " + std::to_string(j) + " names the wrong killer");
      if (t.death_res != expect)
        r.fail(op_name(op.id) + ": triangle " + std::to_string(j) + " has the wrong death_res");
      if (t.death_res < op.birth_res)
        r.fail(op_name(op.id) + ": a triangle dies before it is born");
    }
    if (crmr.header.kind == ModelKind::kTerrain) {
      check_op_local(crmr, op, r, vertex_owner);
    } else {
      check_mesh_op_local(crmr, op, r, vertex_owner);
    }
    if (r.failures > 200) return r;
    check_geometry(crmr, op, r);
  }
  // M^0 and M^m tile the domain (terrain) or are oriented manifold surfaces (3-D).
  std::vector<TriRef> base, finest;
  for (const Op& op : crmr.ops) {
    for (std::uint32_t j = 0; j < op.fragment.size(); ++j) {
      if (op.id == kBaseOp) base.push_back({op.id, j});
      if (!op.fragment[j].killer.valid()) finest.push_back({op.id, j});
    }
  }
  for (const auto& [label, set] : {std::pair{"M^0", &base}, std::pair{"M^m", &finest}}) {
    InvariantReport t = crmr.header.kind == ModelKind::kTerrain ? check_tiling(crmr, *set)
                                                                : check_surface(crmr, *set).report;
    for (const std::string& e : t.errors) r.fail(std::string(label) + ": " + e);
    r.checked += t.checked;
  }
  return r;
}

InvariantReport check_tiling(const OpSource& source, std::span<const TriRef> triangles) {
  InvariantReport r;
  const CrmrInfo& info = source.info();
  std::unordered_map<DirectedEdge, std::size_t, EdgeHash> edges;
  std::unordered_map<std::uint64_t, GridPoint> pos;
  std::unordered_set<TriRef> seen;
  i128 area = 0;
  for (const TriRef& ref : triangles) {
    ++r.checked;
    if (!seen.insert(ref).second) {
      r.fail("triangle " + op_name(ref.op) + "/" + std::to_string(ref.index) + " appears twice");
      continue;
    }
    const OpRef op_ref = source.op(ref.op);
    const OpView& op = *op_ref;
    const GridTri g = grid_tri(info, op, op.triangle(ref.index));
    const std::int64_t a2 = orient(g.p[0], g.p[1], g.p[2]);
    if (a2 <= 0)
      r.fail("triangle " + op_name(ref.op) + "/" + std::to_string(ref.index) +
             " is not counter-clockwise");
    area += a2;
    for (int k = 0; k < 3; ++k) {
      pos[g.id[k].value] = g.p[k];
      const DirectedEdge e{g.id[k].value, g.id[(k + 1) % 3].value};
      if (!edges.emplace(e, 1).second)
        r.fail("directed edge " + std::to_string(e.a) + "-" + std::to_string(e.b) +
               " used twice (overlap)");
    }
  }
  const i128 domain = i128(2) * (info.grid_width - 1) * (info.grid_height - 1);
  if (area != domain) {
    r.fail("triangle areas sum to " + std::to_string(double(area) / 2) +
           " grid cells, the domain has " + std::to_string(double(domain) / 2));
  }
  for (const auto& [e, count] : edges) {
    if (edges.count({e.b, e.a})) continue;
    if (!on_domain_boundary(info, pos[e.a], pos[e.b])) {
      // A T-junction shows here too: the long edge has no reverse (its other side is split).
      r.fail("edge " + std::to_string(e.a) + "-" + std::to_string(e.b) +
             " has one triangle but is not on the domain boundary (gap or T-junction)");
    }
  }
  return r;
}

DelaunayReport check_delaunay(const OpSource& source, std::span<const TriRef> triangles) {
  DelaunayReport rep;
  const CrmrInfo& info = source.info();
  struct Side {
    TriRef tri;
    GridTri g;
    int k;
  };
  std::unordered_map<DirectedEdge, Side, EdgeHash> edges;
  for (const TriRef& ref : triangles) {
    const OpRef op_ref = source.op(ref.op);
    const OpView& op = *op_ref;
    const GridTri g = grid_tri(info, op, op.triangle(ref.index));
    for (int k = 0; k < 3; ++k) edges[{g.id[k].value, g.id[(k + 1) % 3].value}] = {ref, g, k};
  }
  for (const auto& [e, s] : edges) {
    if (e.a > e.b) continue;
    auto it = edges.find({e.b, e.a});
    if (it == edges.end()) continue;
    ++rep.interior_edges;
    const GridPoint opposite = it->second.g.p[(it->second.k + 2) % 3];
    if (incircle(s.g.p[0], s.g.p[1], s.g.p[2], opposite) > 0) {
      ++rep.non_delaunay_edges;
      if (rep.examples.size() < 10) rep.examples.emplace_back(s.tri, it->second.tri);
    }
  }
  return rep;
}

SurfaceReport check_surface(const OpSource& source, std::span<const TriRef> triangles) {
  SurfaceReport out;
  InvariantReport& r = out.report;
  std::unordered_map<DirectedEdge, TriRef, EdgeHash> edges;
  std::unordered_set<TriRef> seen;
  std::unordered_map<std::uint64_t, std::uint64_t> vertex_index;
  std::vector<std::array<std::uint64_t, 3>> tris;
  for (const TriRef& ref : triangles) {
    ++r.checked;
    if (!seen.insert(ref).second) {
      r.fail("triangle " + op_name(ref.op) + "/" + std::to_string(ref.index) + " appears twice");
      continue;
    }
    const OpRef op_ref = source.op(ref.op);
    const OpView& op = *op_ref;
    const FragmentTriangle& t = op.triangle(ref.index);
    std::array<std::uint64_t, 3> ids{};
    for (int k = 0; k < 3; ++k) {
      ids[k] = op.vertex_id(t, k).value;
      vertex_index.emplace(ids[k], vertex_index.size());
    }
    if (ids[0] == ids[1] || ids[1] == ids[2] || ids[0] == ids[2]) {
      r.fail("triangle " + op_name(ref.op) + "/" + std::to_string(ref.index) + " is degenerate");
    }
    for (int k = 0; k < 3; ++k) {
      const DirectedEdge e{ids[k], ids[(k + 1) % 3]};
      if (!edges.emplace(e, ref).second) {
        r.fail("directed edge " + std::to_string(e.a) + "-" + std::to_string(e.b) +
               " used twice (inconsistent orientation, overlap or a non-manifold edge)");
      }
    }
    tris.push_back(ids);
  }
  // Components (edge-connected through shared vertices), boundary edges and loops, Euler.
  const std::size_t nv = vertex_index.size();
  std::vector<std::size_t> parent(nv);
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](std::size_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  for (const auto& t : tris) {
    for (int k = 1; k < 3; ++k) parent[find(vertex_index[t[k]])] = find(vertex_index[t[0]]);
  }
  std::uint64_t undirected = 0;
  std::unordered_map<std::uint64_t, std::uint64_t> next_on_boundary;
  for (const auto& [e, ref] : edges) {
    if (edges.count({e.b, e.a})) {
      if (e.a < e.b) ++undirected;
      continue;
    }
    ++undirected;
    ++out.boundary_edges;
    if (!next_on_boundary.emplace(e.a, e.b).second) {
      r.fail("vertex " + std::to_string(e.a) + " starts two boundary edges (non-manifold vertex)");
    }
  }
  std::unordered_set<std::uint64_t> visited;
  for (const auto& [a, b] : next_on_boundary) {
    if (visited.count(a)) continue;
    ++out.boundary_loops;
    for (std::uint64_t v = a; visited.insert(v).second;) {
      auto it = next_on_boundary.find(v);
      if (it == next_on_boundary.end()) {
        r.fail("boundary chain through vertex " + std::to_string(v) + " does not close");
        break;
      }
      v = it->second;
    }
  }
  for (std::size_t v = 0; v < nv; ++v) out.components += find(v) == v;
  out.vertices = nv;
  out.triangles = tris.size();
  out.euler = std::int64_t(nv) - std::int64_t(undirected) + std::int64_t(tris.size());
  return out;
}

}  // namespace smr
