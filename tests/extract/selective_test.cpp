// Truly selective refinement (Kim & Lee 2001; smr/extract/selective.h) on the CGAL demo meshes,
// built one vertex split per op: every output is an oriented manifold with the source's topology,
// is exactly the source relabelled by its active vertices (the dual-piece partition), leaves no
// selected vertex unsplit, splits nothing the criterion did not ask for but the counted degenerate
// cases, and is the same read from disk as in memory.
#include <algorithm>
#include <functional>
#include <map>
#include <mutex>
#include <numeric>
#include <set>

#include <gtest/gtest.h>
#include <glm/geometric.hpp>

#include "base/error.h"
#include "smr/builders/mesh/qem_pm.h"
#include "smr/db/database.h"
#include "smr/db/writer.h"
#include "smr/extract/extract.h"
#include "smr/extract/selective.h"
#include "smr/io/mesh_reader.h"
#include "smr/rcf/spec.h"
#include "tests/support/files.h"
#include "tests/support/meshes.h"
#include "tests/support/test_data.h"

namespace smr {
namespace {

using Tri = std::array<std::uint32_t, 3>;

struct Built {
  TriangleMesh source;
  Crmr crmr;
  std::shared_ptr<const SelectiveIndex> index;
};

// One split per op (--coalesce 0); cached per process.
const Built& built(const std::string& name) {
  static std::mutex mutex;
  static std::map<std::string, Built> cache;
  std::lock_guard lock(mutex);
  auto it = cache.find(name);
  if (it != cache.end()) return it->second;
  Built b;
  b.source = read_mesh(test::data_path("meshes/" + name), {});
  QemPmOptions o;
  o.max_fragment_triangles = 0;
  b.crmr = build_qem_pm(b.source, name, o);
  b.index = SelectiveIndex::build(b.crmr, {.vertex_cones = true});
  return cache.emplace(name, std::move(b)).first->second;
}

// Topology of an indexed mesh, checked to be an oriented 2-manifold.
struct Topology {
  std::uint64_t components = 0, boundary_loops = 0;
  std::int64_t euler = 0;
  friend bool operator==(const Topology&, const Topology&) = default;
};

std::uint32_t find_root(std::vector<std::uint32_t>& p, std::uint32_t x) {
  while (p[x] != x) x = p[x] = p[p[x]];
  return x;
}

Topology oriented_manifold_topology(const TriangleMesh& m) {
  std::map<std::pair<std::uint32_t, std::uint32_t>, std::uint32_t> directed;
  std::vector<std::uint32_t> parent(m.positions.size());
  std::iota(parent.begin(), parent.end(), 0u);
  std::vector<std::uint8_t> used(m.positions.size(), 0);
  for (std::uint32_t t = 0; t < m.triangles.size(); ++t) {
    const Tri& c = m.triangles[t];
    EXPECT_TRUE(c[0] != c[1] && c[1] != c[2] && c[2] != c[0]) << "degenerate triangle " << t;
    for (int k = 0; k < 3; ++k) {
      const auto e = std::pair{c[k], c[(k + 1) % 3]};
      EXPECT_TRUE(directed.emplace(e, t).second)
          << "edge " << e.first << "-" << e.second << " twice in one direction (not oriented)";
      used[c[k]] = 1;
      parent[find_root(parent, c[k])] = find_root(parent, c[(k + 1) % 3]);
    }
  }
  // Each vertex's triangles form one fan: per triangle (v, a, b) a link edge a -> b; the link is
  // one path (at most one a that is no b) or one cycle, and walking it meets every triangle.
  std::vector<std::map<std::uint32_t, std::uint32_t>> link(m.positions.size());
  for (const Tri& c : m.triangles) {
    for (int k = 0; k < 3; ++k) link[c[k]][c[(k + 1) % 3]] = c[(k + 2) % 3];
  }
  std::uint64_t edges = 0;
  std::map<std::uint32_t, std::uint32_t> boundary_next;  // boundary edge a->b (no b->a)
  for (const auto& [e, t] : directed) {
    const bool boundary = !directed.contains({e.second, e.first});
    if (boundary) {
      EXPECT_TRUE(boundary_next.emplace(e.first, e.second).second)
          << "vertex " << e.first << " has two boundary edges out (not a manifold)";
    }
    if (boundary || e.first < e.second) ++edges;
  }
  for (std::uint32_t v = 0; v < link.size(); ++v) {
    if (link[v].empty()) continue;
    std::set<std::uint32_t> targets;
    for (const auto& [a, b] : link[v]) targets.insert(b);
    std::uint32_t start = link[v].begin()->first;
    int starts = 0;
    for (const auto& [a, b] : link[v]) {
      if (!targets.contains(a)) {
        start = a;
        ++starts;
      }
    }
    EXPECT_LE(starts, 1) << "vertex " << v << " has more than one fan (not a manifold)";
    std::size_t walked = 0;
    for (auto it = link[v].find(start); it != link[v].end() && walked <= link[v].size();
         it = link[v].find(it->second)) {
      ++walked;
      if (it->second == start) break;
    }
    EXPECT_EQ(walked, link[v].size()) << "vertex " << v << " is not a manifold vertex";
  }
  Topology topo;
  std::set<std::uint32_t> roots;
  std::uint64_t vertices = 0;
  for (std::uint32_t v = 0; v < used.size(); ++v) {
    if (!used[v]) continue;
    ++vertices;
    roots.insert(find_root(parent, v));
  }
  topo.components = roots.size();
  std::set<std::uint32_t> visited;
  for (const auto& [a, b] : boundary_next) {
    if (visited.contains(a)) continue;
    ++topo.boundary_loops;
    for (std::uint32_t x = a; visited.insert(x).second;) {
      const auto it = boundary_next.find(x);
      if (it == boundary_next.end()) break;
      x = it->second;
    }
  }
  topo.euler = std::int64_t(vertices) - std::int64_t(edges) + std::int64_t(m.triangles.size());
  return topo;
}

// Triangles by vertex ids, each rotated to start at its smallest corner, sorted.
std::vector<Tri> id_triangles(const TriangleMesh& m, const std::vector<std::uint32_t>& ids) {
  std::vector<Tri> out;
  for (const Tri& t : m.triangles) {
    Tri c{ids[t[0]], ids[t[1]], ids[t[2]]};
    std::rotate(c.begin(), std::min_element(c.begin(), c.end()), c.end());
    out.push_back(c);
  }
  std::sort(out.begin(), out.end());
  return out;
}

std::vector<std::uint32_t> identity(std::size_t n) {
  std::vector<std::uint32_t> v(n);
  std::iota(v.begin(), v.end(), 0u);
  return v;
}

// The dual-piece mesh of r's active vertices, computed independently of the splits: every source
// triangle whose corners have three different active ancestors, relabelled.
std::vector<Tri> relabelled_source(const TriangleMesh& source, const SelectiveRefinement& r) {
  const SelectiveIndex& ix = r.index();
  std::vector<std::uint32_t> anc(source.positions.size());
  for (std::uint32_t x = 0; x < anc.size(); ++x) {
    std::uint32_t n = ix.leaf(x);
    while (r.node_of(ix.nodes()[n].vertex) != n) n = ix.nodes()[n].parent;
    anc[x] = ix.nodes()[n].vertex;
  }
  TriangleMesh m;
  m.positions.resize(source.positions.size());
  for (const Tri& t : source.triangles) {
    const Tri c{anc[t[0]], anc[t[1]], anc[t[2]]};
    if (c[0] != c[1] && c[1] != c[2] && c[2] != c[0]) m.triangles.push_back(c);
  }
  return id_triangles(m, identity(m.positions.size()));
}

RcfSpec camera_spec(const CrmrInfo& info, const Vec3& dir, double distance, double px) {
  const Vec3 c = 0.5 * (info.bounds.lo + info.bounds.hi);
  const double radius = 0.5 * glm::length(info.bounds.hi - info.bounds.lo);
  RcfSpec s;
  Camera cam;
  cam.eye = c + glm::normalize(dir) * (distance * radius);
  cam.target = c;
  cam.up = std::abs(glm::normalize(dir).z) > 0.9 ? Vec3{0, 1, 0} : Vec3{0, 0, 1};
  s.camera = cam;
  s.pixel_error = px;
  return s;
}

class SelectiveMeshTest : public ::testing::TestWithParam<std::string> {};

TEST_P(SelectiveMeshTest, FullRefinementIsTheSourceAndTheHierarchyIsConsistent) {
  const Built& b = built(GetParam());
  const SelectiveIndex& ix = *b.index;
  EXPECT_EQ(ix.stats().splits + 1, b.crmr.op_count());
  // The fundamental cut vertices are source vertices; IsAncestor agrees with the parents.
  for (const auto& s : ix.splits()) {
    EXPECT_TRUE(s.cut_l != SelectiveIndex::kNone || s.cut_r != SelectiveIndex::kNone);
    EXPECT_TRUE(ix.is_ancestor(s.node, ix.leaf(s.vs)));
    EXPECT_TRUE(ix.is_ancestor(s.node, ix.leaf(s.vu)));
    EXPECT_FALSE(ix.is_ancestor(s.child_t, ix.leaf(s.vu)));
    EXPECT_FALSE(ix.is_ancestor(s.child_u, ix.leaf(s.vs)));
    if (s.cut_l != SelectiveIndex::kNone) {
      EXPECT_FALSE(ix.is_ancestor(s.node, ix.leaf(s.cut_l)));
    }
  }
  RcfSpec full;
  full.floor = 1.0;
  const Rcf rcf = make_rcf(full, ModelKind::kMesh3d, nullptr);
  const SelectiveExtraction e = extract_selective(b.crmr, b.index, rcf);
  EXPECT_EQ(id_triangles(e.mesh, e.vertex_ids),
            id_triangles(b.source, identity(b.source.positions.size())));
  EXPECT_EQ(e.stats.splits, ix.stats().splits);
  EXPECT_EQ(e.stats.degenerate_cases, 0u);
  EXPECT_EQ(e.stats.flipped_triangles, 0u);
  EXPECT_EQ(e.stats.displacement_bound, 0.0);
  for (std::uint32_t v = 0; v < e.mesh.positions.size(); ++v) {
    EXPECT_EQ(e.mesh.positions[v], b.source.positions[e.vertex_ids[v]]);
  }
}

// The properties every truly selective cut has: an oriented manifold with the source's topology,
// the dual-piece mesh of its vertices, no active vertex still selected, and every split either
// selected (split_selected(s), when given, confirms it) or forced by a counted degenerate case.
SelectiveStats check_cut(const Built& b, const SelectiveRefinement& r,
                         const std::function<bool(std::uint32_t v)>& still_selected,
                         const std::function<bool(std::uint32_t s)>& split_selected) {
  std::vector<std::uint32_t> ids;
  const TriangleMesh m = r.to_mesh(&ids);
  EXPECT_EQ(oriented_manifold_topology(m), oriented_manifold_topology(b.source));
  EXPECT_EQ(id_triangles(m, ids), relabelled_source(b.source, r));
  for (std::uint32_t v : ids) EXPECT_FALSE(still_selected(v)) << "vertex " << v;
  const SelectiveStats st = r.stats();
  std::uint64_t selected = 0, forced_made = 0;
  for (std::uint32_t s = 0; s < r.split_made().size(); ++s) {
    if (r.split_made()[s] == 1) {
      ++selected;
      if (split_selected) {
        EXPECT_TRUE(split_selected(s)) << "split " << s;
      }
    }
    if (r.split_made()[s] == 2) ++forced_made;
  }
  EXPECT_EQ(selected, st.selected);
  EXPECT_EQ(forced_made, st.forced_splits);
  EXPECT_EQ(st.splits, st.selected + st.forced_splits);
  EXPECT_GE(st.forced_splits, st.degenerate_cases);
  EXPECT_EQ(st.triangles, m.triangles.size());
  return st;
}

TEST_P(SelectiveMeshTest, ViewDependentCutsAreManifoldDualPieceMeshesThatMeetTheCriterion) {
  const Built& b = built(GetParam());
  std::uint64_t degenerate = 0, forced = 0;
  for (const Vec3 dir : {Vec3{1, 0.3, 0.2}, Vec3{-0.4, 1, -0.5}, Vec3{0.2, -0.6, 1}}) {
    for (double px : {0.5, 4.0}) {
      for (bool cull : {true, false}) {
        SCOPED_TRACE("px " + std::to_string(px) + (cull ? " cull" : " no cull"));
        RcfSpec spec = camera_spec(b.crmr.info(), dir, 1.5, px);
        spec.cull = cull;
        const Rcf rcf = make_rcf(spec, ModelKind::kMesh3d, nullptr);
        SelectiveRefinement r(b.crmr, b.index);
        r.refine(rcf);
        const SelectiveStats st = check_cut(
            b, r, [&](std::uint32_t v) { return r.selected(v, rcf); },
            [&](std::uint32_t s) {
              return !rcf.is_completely_finer(*b.crmr.op(b.index->splits()[s].op), b.crmr);
            });
        // Hoppe's per-vertex criterion over the dual pieces, culling as the RCF's.
        const NodeCriterion node{*spec.camera, cull, cull, px};
        SelectiveRefinement rn(b.crmr, b.index);
        rn.refine(node);
        const SelectiveStats sn =
            check_cut(b, rn, [&](std::uint32_t v) { return rn.selected(v, node); }, {});
        EXPECT_GT(sn.splits, 0u);
        degenerate += st.degenerate_cases + sn.degenerate_cases;
        forced += st.forced_splits + sn.forced_splits;
      }
    }
  }
  RecordProperty("degenerate_cases", std::to_string(degenerate));
  RecordProperty("forced_splits", std::to_string(forced));
}

// The splits made without their Hoppe 1997 neighbourhood (the makers of their fn0..fn3).
std::uint64_t splits_without_their_neighbourhood(const SelectiveRefinement& r) {
  std::uint64_t n = 0;
  for (std::uint32_t s = 0; s < r.split_made().size(); ++s) {
    if (r.split_made()[s] != 0 && !r.neighbourhood_made(s)) ++n;
  }
  return n;
}

// Kim & Lee's Table 2 on one hierarchy and criterion: Hoppe 1997's scheme (a split waits for
// its fn0..fn3, forcing their splits) gives a valid cut that splits everything the truly
// selective one selects through selected ancestors, and more: the truly selective scheme splits
// vertices without that neighbourhood, and gives fewer triangles.
TEST_P(SelectiveMeshTest, Hoppe97SchemeForcesNeighbourhoodsTheTrulySelectiveSchemeDoesWithout) {
  const Built& b = built(GetParam());
  const SelectiveIndex& ix = *b.index;
  std::uint64_t hoppe_triangles = 0, selective_triangles = 0, hoppe_forced = 0,
                selective_forced = 0, without = 0;
  for (const Vec3 dir : {Vec3{1, 0.3, 0.2}, Vec3{-0.4, 1, -0.5}}) {
    for (double px : {0.5, 4.0}) {
      for (bool vertex_cones : {false, true}) {
        SCOPED_TRACE("px " + std::to_string(px) + (vertex_cones ? " vertex cones" : ""));
        NodeCriterion node{*camera_spec(b.crmr.info(), dir, 1.5, px).camera, true, true, px};
        node.vertex_normal_cones = vertex_cones;
        SelectiveRefinement h(b.crmr, b.index, SplitScheme::kHoppe97);
        h.refine(node);
        const SelectiveStats sh =
            check_cut(b, h, [&](std::uint32_t v) { return h.selected(v, node); }, {});
        EXPECT_EQ(sh.degenerate_cases, 0u);
        EXPECT_EQ(splits_without_their_neighbourhood(h), 0u);
        SelectiveRefinement k(b.crmr, b.index);
        k.refine(node);
        const SelectiveStats sk =
            check_cut(b, k, [&](std::uint32_t v) { return k.selected(v, node); }, {});
        // A split selected through selected ancestors only is one either scheme must make.
        for (std::uint32_t s = 0; s < k.split_made().size(); ++s) {
          bool chain = true;
          for (std::uint32_t n = ix.splits()[s].node; chain && n != SelectiveIndex::kNone;
               n = ix.nodes()[n].parent) {
            chain = k.split_made()[ix.nodes()[n].split] == 1;
          }
          if (chain) {
            EXPECT_NE(h.split_made()[s], 0) << "split " << s;
          }
        }
        hoppe_triangles += sh.triangles;
        selective_triangles += sk.triangles;
        hoppe_forced += sh.forced_splits;
        selective_forced += sk.forced_splits;
        without += splits_without_their_neighbourhood(k);
      }
    }
  }
  EXPECT_GT(without, 0u);
  EXPECT_GT(hoppe_forced, selective_forced);
  EXPECT_GT(hoppe_triangles, selective_triangles);
  RecordProperty("hoppe97_over_selective_triangles",
                 std::to_string(double(hoppe_triangles) / double(selective_triangles)));
  RecordProperty("hoppe97_forced_splits", std::to_string(hoppe_forced));
}

// Hoppe 1997's scheme on its own terms, checked on the mesh rather than through `around`: right
// after force_vsplit(v), v's new faces (v, u, l) and (u, v, r) meet the faces fn0..fn3 across
// (u, l), (l, v), (v, r) and (r, u): the neighbourhood the split was made with in the PM.
TEST_P(SelectiveMeshTest, Hoppe97SplitsMeetTheirFnFacesAcrossTheirEdges) {
  const Built& b = built(GetParam());
  const SelectiveIndex& ix = *b.index;
  SelectiveRefinement h(b.crmr, b.index, SplitScheme::kHoppe97);
  std::uint64_t state = 7, checked = 0;
  const auto shares = [](const std::array<std::uint32_t, 3>& t, std::uint32_t a, std::uint32_t c) {
    return std::count(t.begin(), t.end(), a) == 1 && std::count(t.begin(), t.end(), c) == 1;
  };
  for (int step = 0; step < 400; ++step) {
    std::vector<std::uint32_t> splittable;  // active vertices with a split left
    for (std::uint32_t v : h.active_vertices()) {
      if (ix.nodes()[h.node_of(v)].split != SelectiveIndex::kNone) splittable.push_back(v);
    }
    if (splittable.empty()) break;
    state = mix64(state + 0x9E3779B97F4A7C15ULL);
    const std::uint32_t v = splittable[state % splittable.size()];
    const std::uint32_t s = ix.nodes()[h.node_of(v)].split;
    h.split_with_dependencies(v);
    ASSERT_NE(h.split_made()[s], 0);
    std::map<std::uint32_t, std::array<std::uint32_t, 3>> by_face;  // face id -> corners now
    for (std::uint32_t t = 0; t < h.mesh().capacity(); ++t) {
      if (h.mesh().alive(t)) by_face[h.mesh().face(t)] = h.mesh().triangle(t);
    }
    const auto& sp = ix.splits()[s];
    for (int side = 0; side < 2; ++side) {
      const auto own = by_face.find(ix.split_face(s, side));
      if (own == by_face.end()) continue;  // no such side (the model boundary)
      // The wing: the corner that is neither v nor u.
      std::uint32_t w = SelectiveIndex::kNone;
      for (std::uint32_t c : own->second) {
        if (c != sp.vs && c != sp.vu) w = c;
      }
      const std::array<std::pair<std::uint32_t, std::uint32_t>, 2> edges =
          side == 0 ? std::array{std::pair{sp.vu, w}, std::pair{w, sp.vs}}
                    : std::array{std::pair{sp.vs, w}, std::pair{w, sp.vu}};
      for (int k = 0; k < 2; ++k) {
        const std::uint32_t f = sp.around[std::size_t(2 * side + k)];
        if (f == SelectiveIndex::kNone) continue;
        const auto it = by_face.find(f);
        ASSERT_NE(it, by_face.end())
            << "split " << s << ": fn" << 2 * side + k << " not in the mesh";
        EXPECT_TRUE(shares(it->second, edges[std::size_t(k)].first, edges[std::size_t(k)].second))
            << "split " << s << ": fn" << 2 * side + k << " is not across its edge";
        ++checked;
      }
    }
  }
  EXPECT_GT(checked, 100u);
  EXPECT_EQ(h.stats().degenerate_cases, 0u);
}

TEST_P(SelectiveMeshTest, NormalConesHoldEverySourceNormalBelowThemAndBeatTheUnion) {
  // Hoppe 1997 section 4.2: a node's cone bounds the normals of the source triangles at the
  // source vertices below it (what the back-face test may cull on), checked for every triangle,
  // corner and ancestor; and it is never wider than the union of its children's cones.
  const Built& b = built(GetParam());
  const SelectiveIndex& ix = *b.index;
  const std::vector<Vec3>& pos = ix.source_positions();
  ASSERT_EQ(pos.size(), b.source.positions.size());
  std::uint64_t checked = 0;
  for (const Tri& t : b.source.triangles) {
    const Vec3 n = triangle_normal(pos[t[0]], pos[t[1]], pos[t[2]]);
    if (!(glm::length(n) > 0.5)) continue;  // degenerate: no normal to bound
    for (std::uint32_t x : t) {
      for (std::uint32_t node = ix.leaf(x); node != SelectiveIndex::kNone;
           node = ix.nodes()[node].parent) {
        const NormalCone& c = ix.nodes()[node].cone;
        if (c.half_angle >= M_PI) continue;
        ASSERT_LE(std::acos(std::clamp(glm::dot(n, c.axis), -1.0, 1.0)),
                  c.half_angle + 1e-7)  // acos near 1: ~1e-8
            << "node " << node << " above vertex " << x;
        ++checked;
      }
    }
  }
  EXPECT_GT(checked, 3 * b.source.triangles.size());
  // The vertex cones (OpenMesh's Analyzer's kind) hold every source vertex normal below them.
  std::vector<Vec3> vertex_normal(pos.size(), Vec3{0.0});
  for (const Tri& t : b.source.triangles) {
    const Vec3 n = triangle_normal(pos[t[0]], pos[t[1]], pos[t[2]]);
    if (glm::length(n) > 0.5) {
      for (std::uint32_t x : t) vertex_normal[x] += n;
    }
  }
  std::uint64_t vertex_checked = 0, vertex_narrower = 0, internal = 0;
  for (std::uint32_t x = 0; x < pos.size(); ++x) {
    if (!(glm::length(vertex_normal[x]) > 1e-9)) continue;
    const Vec3 n = glm::normalize(vertex_normal[x]);
    for (std::uint32_t node = ix.leaf(x); node != SelectiveIndex::kNone;
         node = ix.nodes()[node].parent) {
      const NormalCone& c = ix.vertex_cone(node);
      ASSERT_LE(std::acos(std::clamp(glm::dot(n, c.axis), -1.0, 1.0)), c.half_angle + 1e-6)
          << "vertex cone of node " << node << " above vertex " << x;
      ++vertex_checked;
    }
  }
  EXPECT_GT(vertex_checked, pos.size());
  for (std::uint32_t n = 0; n < ix.nodes().size(); ++n) {  // a leaf's vertex cone: one normal
    if (ix.nodes()[n].split == SelectiveIndex::kNone) continue;
    ++internal;
    vertex_narrower += ix.vertex_cone(n).half_angle < ix.nodes()[n].cone.half_angle - 1e-6;
  }
  EXPECT_GT(vertex_narrower, internal / 2);
  std::uint64_t narrower = 0;
  for (const SelectiveIndex::Split& s : ix.splits()) {
    const NormalCone joined = cone_union(ix.nodes()[s.child_t].cone, ix.nodes()[s.child_u].cone);
    EXPECT_LE(ix.nodes()[s.node].cone.half_angle, joined.half_angle);
    narrower += ix.nodes()[s.node].cone.half_angle < joined.half_angle - 1e-6;
  }
  EXPECT_GT(narrower, 0u);
}

TEST_P(SelectiveMeshTest, CollapsingEverySplitReturnsToTheBaseMesh) {
  const Built& b = built(GetParam());
  RcfSpec spec = camera_spec(b.crmr.info(), Vec3{1, 0.3, 0.2}, 1.5, 1.0);
  const Rcf rcf = make_rcf(spec, ModelKind::kMesh3d, nullptr);
  SelectiveRefinement r(b.crmr, b.index);
  std::vector<std::uint32_t> ids;
  const std::vector<Tri> base = [&] {
    const TriangleMesh m = r.to_mesh(&ids);
    return id_triangles(m, ids);
  }();
  r.refine(rcf);
  ASSERT_GT(r.stats().splits, 0u);
  // ecol_new on any collapsible edge, finest first, pass after pass: postponed collapses wait
  // for their pinching neighbours to go.
  for (bool progress = true; progress;) {
    progress = false;
    for (std::uint32_t s = static_cast<std::uint32_t>(r.split_made().size()); s-- > 0;) {
      const auto& sp = b.index->splits()[s];
      if (r.split_made()[s] == 0 || r.node_of(sp.vs) != sp.child_t ||
          r.node_of(sp.vu) != sp.child_u) {
        continue;
      }
      if (r.collapse(s)) {
        progress = true;
        // Still a dual-piece mesh after each collapse.
        if (s % 97 == 0) {
          const TriangleMesh m = r.to_mesh(&ids);
          ASSERT_EQ(id_triangles(m, ids), relabelled_source(b.source, r));
        }
      }
    }
  }
  const TriangleMesh m = r.to_mesh(&ids);
  EXPECT_EQ(id_triangles(m, ids), base);
}

// Any vertex, any edge, in any order (the paper's claim): random splits of active vertices and
// collapses of active edges, the mesh checked along the way. Degenerate cases (both cut vertices
// one vertex) arise here, where a split vertex's neighbours are much coarser than it.
TEST_P(SelectiveMeshTest, RandomSplitsAndCollapsesKeepADualPieceManifold) {
  const Built& b = built(GetParam());
  const Topology source = oriented_manifold_topology(b.source);
  std::uint64_t degenerate = 0, postponed = 0;
  for (std::uint32_t seed = 1; seed <= 3; ++seed) {
    SelectiveRefinement r(b.crmr, b.index);
    std::uint64_t state = seed;
    const auto random = [&](std::uint64_t n) {
      state = mix64(state + 0x9E3779B97F4A7C15ULL);
      return state % n;
    };
    const std::uint32_t vertices = b.index->vertex_count();
    for (int step = 0; step < 3000; ++step) {
      if (random(4) != 0) {  // a split of a random active vertex with a split left
        const auto v = static_cast<std::uint32_t>(random(vertices));
        const std::uint32_t n = r.node_of(v);
        if (n == SelectiveIndex::kNone || b.index->nodes()[n].split == SelectiveIndex::kNone)
          continue;
        r.split(v);
      } else {  // a collapse of a random collapsible split
        const auto s = static_cast<std::uint32_t>(random(b.index->splits().size()));
        const auto& sp = b.index->splits()[s];
        if (r.node_of(sp.vs) == sp.child_t && r.node_of(sp.vu) == sp.child_u) r.collapse(s);
      }
    }
    std::vector<std::uint32_t> ids;
    const TriangleMesh m = r.to_mesh(&ids);
    EXPECT_EQ(oriented_manifold_topology(m), source);
    EXPECT_EQ(id_triangles(m, ids), relabelled_source(b.source, r));
    degenerate += r.stats().degenerate_cases;
    postponed += r.postponed_collapses();
  }
  RecordProperty("degenerate_cases", std::to_string(degenerate));
  RecordProperty("postponed_collapses", std::to_string(postponed));
}

INSTANTIATE_TEST_SUITE_P(Cgal, SelectiveMeshTest,
                         ::testing::Values("ChineseDragon-10kv.off", "blobby_3cc.off",
                                           "elephant-with-holes.off", "fandisk.off",
                                           "mech-holes-shark.off"),
                         [](const auto& p) {
                           std::string n = p.param.substr(0, p.param.find('.'));
                           std::replace(n.begin(), n.end(), '-', '_');
                           return n;
                         });

TEST(Selective, SameOutputsFromDiskAsInMemory) {
  Built b = built("elephant-with-holes.off");  // a copy: writing snaps it to the grid
  test::TempDir tmp("selective");
  const std::string path = tmp.file("e.smrdb");
  write_database(b.crmr, path, {});
  const auto db = Database::open(path, {std::size_t{1} << 20});  // a small cache: pages evicted
  const auto disk = SelectiveIndex::build(*db);
  const auto memory = SelectiveIndex::build(b.crmr);
  ASSERT_EQ(disk->splits().size(), memory->splits().size());
  for (const Vec3 dir : {Vec3{1, 0.3, 0.2}, Vec3{0.2, -0.6, 1}}) {
    const Rcf rcf =
        make_rcf(camera_spec(b.crmr.info(), dir, 1.5, 1.0), ModelKind::kMesh3d, nullptr);
    const SelectiveExtraction a = extract_selective(*db, disk, rcf);
    const SelectiveExtraction c = extract_selective(b.crmr, memory, rcf);
    EXPECT_EQ(a.mesh.positions, c.mesh.positions);
    EXPECT_EQ(a.mesh.triangles, c.mesh.triangles);
    EXPECT_EQ(a.vertex_ids, c.vertex_ids);
    EXPECT_EQ(a.stats.degenerate_cases, c.stats.degenerate_cases);
    EXPECT_GT(a.stats.splits, 0u);
  }
}

// Vertex cones cost a third more memory a node and are built only when asked; without them the
// index is otherwise the same, and a criterion that reads them is refused.
TEST(Selective, VertexConesOnlyWhenAsked) {
  const Built& b = built("fandisk.off");
  const auto plain = SelectiveIndex::build(b.crmr);
  EXPECT_FALSE(plain->has_vertex_cones());
  EXPECT_TRUE(b.index->has_vertex_cones());
  ASSERT_EQ(plain->nodes().size(), b.index->nodes().size());
  for (std::uint32_t n = 0; n < plain->nodes().size(); ++n) {
    EXPECT_EQ(plain->nodes()[n].cone, b.index->nodes()[n].cone) << "node " << n;
  }
  NodeCriterion node{*camera_spec(b.crmr.info(), Vec3{1, 0.3, 0.2}, 1.5, 1.0).camera, true, true,
                     1.0};
  EXPECT_GT(extract_selective(b.crmr, plain, node).stats.splits, 0u);
  node.vertex_normal_cones = true;
  try {
    extract_selective(b.crmr, plain, node);
    FAIL() << "vertex cones were read from an index without them";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kInvalidInput);
    EXPECT_NE(std::string(e.what()).find("vertex cones"), std::string::npos) << e.what();
  }
}

TEST(Selective, CoalescedDatabaseIsRefusedNamingTheOp) {
  const test::BuiltMesh& b = test::built_mesh("elephant-with-holes.off");  // coalesced (32)
  try {
    SelectiveIndex::build(b.crmr);
    FAIL() << "a coalesced CRMR was accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kInvalidInput);
    EXPECT_NE(std::string(e.what()).find("op "), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("--coalesce 0"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace smr
