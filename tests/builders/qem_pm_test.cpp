// The QEM progressive-mesh builder (smr/builders/mesh/qem_pm.h) on real meshes no one here made
// (CGAL's demo data, all eight: pig.stl read with the repairs): the CRMR invariants, exact
// reproduction of the source when fully refined, coalescing and DAG depth, no collapse turning a
// normal past the limit, and, for a spread of 3-D RCFs (object-space levels, cameras around and
// close to the model with pixel tolerances, with culling), the outputs of minimal-surface
// extraction: an oriented manifold surface with the source's topology (components, boundary loops,
// Euler characteristic), the set formula equal to the advancing front, Theorem 5.1.1, X's
// definition, the screen-space rule pointwise with culling off, culling saving triangles, and the
// stored error bound checked against the source by sampled distances in both directions (source to
// output view-locally: within the bound of the output triangles near each point).
#include <algorithm>
#include <cmath>
#include <map>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <glm/geometric.hpp>

#include "base/error.h"
#include "smr/builders/mesh/qem_pm.h"
#include "smr/core/invariants.h"
#include "smr/extract/extract.h"
#include "smr/io/mesh_reader.h"
#include "smr/rcf/spec.h"
#include "tests/support/datasets.h"
#include "tests/support/mesh_distance.h"
#include "tests/support/meshes.h"
#include "tests/support/oracles.h"
#include "tests/support/sanitized.h"
#include "tests/support/self_intersections.h"

namespace smr {
namespace {

using Built = test::BuiltMesh;

const Built& built(const std::string& name) {
  return test::built_mesh(name);
}

std::vector<TriRef> level(const Crmr& crmr, bool finest) {
  std::vector<TriRef> out;
  for (const Op& op : crmr.ops) {
    for (std::uint32_t j = 0; j < op.fragment.size(); ++j) {
      if (finest ? !op.fragment[j].killer.valid() : op.id == kBaseOp) out.push_back({op.id, j});
    }
  }
  return out;
}

// The corners of `refs`' triangles, void ones left out.
std::vector<std::array<Vec3, 3>> corners_of(const Crmr& crmr, const std::vector<TriRef>& refs) {
  std::vector<std::array<Vec3, 3>> out;
  for (const TriRef& ref : refs) {
    const Op& op = crmr.ops[ref.op.value];
    const FragmentTriangle& t = op.fragment[ref.index];
    if (!t.is_void()) out.push_back({op.position(t, 0), op.position(t, 1), op.position(t, 2)});
  }
  return out;
}

// A collapse whose new triangles would cross a triangle of the mesh that no triangle of the old
// star crossed is refused (QemPmOptions::allow_self_intersections off). So a source that does not
// cross itself gives a base mesh R^0, the last state of the simplification, that does not
// either (CGAL's self_intersections counts crossing pairs, independently of the builder's own
// test); a source that does is only reported. The in-core builder also checks each collapse
// against the dead triangles a cut at one error can show beside its new ones (crosses_dead in
// qem_pm.cpp): with `uniform_cuts_hold`, no cut of the spread at one error (a floor alone)
// crosses more than the source. Cuts whose error varies (cameras, volumes) are reported.
std::size_t expect_simplification_adds_no_crossing(const Crmr& crmr, const std::string& name,
                                                   bool uniform_cuts_hold) {
  const std::size_t source = test::crossing_pairs(corners_of(crmr, level(crmr, true)));
  const std::size_t base = test::crossing_pairs(corners_of(crmr, level(crmr, false)));
  if (source == 0) {
    EXPECT_EQ(base, 0u) << "simplification made the mesh cross itself";
  }
  std::size_t cuts = 0, crossing_cuts = 0, worst = 0;
  for (const test::NamedSpec& c : test::mesh_rcf_spread(crmr.header)) {
    const Extraction e =
        extract_minimal_surface(crmr, make_rcf(c.spec, ModelKind::kMesh3d, nullptr));
    const std::size_t n = test::crossing_pairs(corners_of(crmr, e.triangles));
    ++cuts;
    if (n > source) ++crossing_cuts;
    const bool uniform = c.spec.floor && !c.spec.camera && c.spec.volumes.empty() &&
                         c.spec.aois.empty() && c.spec.discs.empty();
    if (uniform_cuts_hold && uniform) {
      EXPECT_LE(n, source) << c.name << ": a cut at one error crosses where the source does not";
    }
    worst = std::max(worst, n);
  }
  std::printf(
      "%s: crossing pairs: source %zu, base %zu; %zu of %zu cuts cross more than the "
      "source (most pairs in a cut: %zu)\n",
      name.c_str(), source, base, crossing_cuts, cuts, worst);
  return base;
}

// A triangle as its vertex ids, rotated so the smallest comes first (orientation kept).
std::array<std::uint64_t, 3> canonical(std::array<std::uint64_t, 3> t) {
  std::rotate(t.begin(), std::min_element(t.begin(), t.end()), t.end());
  return t;
}

// The fully refined mesh M^m is the source: same triangles (orientation kept), no vertex moved.
void expect_finest_mesh_is_the_source(const Crmr& crmr, const TriangleMesh& source) {
  std::vector<std::array<std::uint64_t, 3>> want, got;
  for (const auto& t : source.triangles) want.push_back(canonical({t[0], t[1], t[2]}));
  for (const TriRef& ref : level(crmr, true)) {
    const Op& op = crmr.ops[ref.op.value];
    const FragmentTriangle& t = op.fragment[ref.index];
    std::array<std::uint64_t, 3> ids{};
    for (int k = 0; k < 3; ++k) {
      ids[k] = op.vertex_id(t, k).value;
      EXPECT_EQ(op.position(t, k), source.positions[ids[k]]) << "vertex " << ids[k] << " moved";
    }
    got.push_back(canonical(ids));
  }
  std::sort(want.begin(), want.end());
  std::sort(got.begin(), got.end());
  EXPECT_EQ(got, want) << "M^m differs from the source mesh";
  // And a full refinement (level 1 everywhere) reaches M^m, zero-error collapses included.
  RcfSpec all;
  all.floor = 1.0;
  const Extraction e = extract_minimal_surface(crmr, make_rcf(all, ModelKind::kMesh3d, nullptr));
  std::vector<TriRef> full = e.triangles, finest = level(crmr, true);
  std::sort(full.begin(), full.end());
  std::sort(finest.begin(), finest.end());
  EXPECT_EQ(e.stats.x, crmr.ops.size()) << "a full refinement left ops out";
  EXPECT_EQ(full, finest) << "a full refinement is not the source mesh";
}

// A cube whose faces are n x n grids: flat regions everywhere, so most collapses have zero error
// (their ops' birth_res is 1, like the finest mesh's).
TriangleMesh subdivided_cube(int n) {
  TriangleMesh m;
  std::map<std::array<int, 3>, std::uint32_t> ids;
  const auto vertex = [&](std::array<int, 3> c) {
    const auto [it, added] = ids.emplace(c, static_cast<std::uint32_t>(m.positions.size()));
    if (added) m.positions.push_back(Vec3{double(c[0]), double(c[1]), double(c[2])} / double(n));
    return it->second;
  };
  for (int axis = 0; axis < 3; ++axis) {
    for (int side = 0; side < 2; ++side) {
      const int u = (axis + 1) % 3, v = (axis + 2) % 3;
      const auto at = [&](int i, int j) {
        std::array<int, 3> c{};
        c[axis] = side * n;
        c[u] = i;
        c[v] = j;
        return vertex(c);
      };
      for (int i = 0; i < n; ++i) {
        for (int j = 0; j < n; ++j) {
          const std::uint32_t a = at(i, j), b = at(i + 1, j), c = at(i + 1, j + 1),
                              d = at(i, j + 1);
          // Outward: counter-clockwise seen from outside (u x v = +axis on the far side).
          if (side == 1) {
            m.triangles.push_back({a, b, c});
            m.triangles.push_back({a, c, d});
          } else {
            m.triangles.push_back({a, c, b});
            m.triangles.push_back({a, d, c});
          }
        }
      }
    }
  }
  return m;
}

TEST(PlanarMesh, FullRefinementIsTheSourceWithZeroErrorCollapses) {
  const TriangleMesh cube = subdivided_cube(12);
  const Crmr in_core = build_qem_pm(cube, "cube12");
  EXPECT_TRUE(check_crmr(in_core).ok()) << check_crmr(in_core).summary();
  std::uint64_t zero = 0;
  for (const Op& op : in_core.ops) zero += (op.id != kBaseOp && op.birth_res >= 1.0) ? 1 : 0;
  EXPECT_GT(zero, 10u) << "the cube should have collapses of zero error";
  expect_finest_mesh_is_the_source(in_core, cube);
  BlockPmOptions o;
  o.leaf_triangles = 300;
  expect_finest_mesh_is_the_source(build_block_pm(MemoryMeshStream(cube, "cube12"), o), cube);
}

// Union-find over vertices; a triangle joins its three corners.
struct Corners {
  std::vector<std::uint32_t> parent;
  explicit Corners(std::size_t n) : parent(n) {
    for (std::uint32_t i = 0; i < n; ++i) parent[i] = i;
  }
  std::uint32_t root(std::uint32_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  }
  void join(const std::array<std::uint32_t, 3>& t) {
    parent[root(t[1])] = root(t[0]);
    parent[root(t[2])] = root(t[0]);
  }
};

// The connected component of each vertex of `mesh`, through its triangles: a vertex of it.
std::vector<std::uint32_t> components_of(const TriangleMesh& mesh) {
  Corners c(mesh.positions.size());
  for (const auto& t : mesh.triangles) c.join(t);
  std::vector<std::uint32_t> out(mesh.positions.size());
  for (std::uint32_t i = 0; i < out.size(); ++i) out[i] = c.root(i);
  return out;
}

// The part of an op's fragment made by its vertex splits: the triangles of the pieces of F
// (joined at shared corners) that touch a corner of PreF, and the new vertices they use. The rest
// is a spawned component.
struct SplitPart {
  std::size_t triangles = 0, new_vertices = 0;
};

SplitPart split_part(const Op& op) {
  Corners c(op.vertices.size());
  for (const FragmentTriangle& t : op.fragment) c.join(t.v);
  std::vector<std::uint8_t> split(op.vertices.size(), 0);
  for (const PreTriangle& t : op.pre_tris) {
    for (std::uint32_t v : t.v) split[c.root(v)] = 1;
  }
  SplitPart r;
  for (const FragmentTriangle& t : op.fragment) r.triangles += split[c.root(t.v[0])];
  for (std::uint32_t v = 0; v < op.new_vertex_count; ++v) r.new_vertices += split[c.root(v)];
  return r;
}

class QemPm : public ::testing::TestWithParam<std::string> {};

// Brute force over the DAG: whether some triangle of op `id` or of any descendant (F or PreF)
// has a corner from which the eye is not strictly behind its plane. Memoized in `front`
// (0 unknown, 1 no, 2 yes).
bool any_front_facing(const Crmr& crmr, std::uint64_t id, const Vec3& eye,
                      std::vector<std::uint8_t>& front) {
  if (front[id] != 0) return front[id] == 2;
  const Op& op = crmr.ops[id];
  bool any = false;
  const auto faces = [&](const Vec3& a, const Vec3& b, const Vec3& c) {
    const Vec3 n = glm::cross(b - a, c - a);
    return glm::dot(n, a - eye) <= 0 || glm::dot(n, b - eye) <= 0 || glm::dot(n, c - eye) <= 0;
  };
  for (const FragmentTriangle& t : op.fragment)
    any = any || faces(op.position(t, 0), op.position(t, 1), op.position(t, 2));
  for (const PreTriangle& t : op.pre_tris)
    any = any || faces(op.position(t, 0), op.position(t, 1), op.position(t, 2));
  for (OpId c : op.children) any = any || any_front_facing(crmr, c.value, eye, front);
  front[id] = any ? 2 : 1;
  return any;
}

TEST_P(QemPm, CrmrInvariantsHoldAndTheFinestMeshIsTheSource) {
  const Built& b = built(GetParam());
  const InvariantReport r = check_crmr(b.crmr);
  EXPECT_TRUE(r.ok()) << r.summary();
  EXPECT_EQ(b.crmr.header.kind, ModelKind::kMesh3d);
  EXPECT_GT(b.stats.collapses, b.source.positions.size() / 2) << "simplified too little";
  // Coalescing (default: fragments of at most 32 triangles) merged splits, each op at least one.
  // A spawned component rides in the op that follows it in the split order (qem_pm.h), whole:
  // its triangles are the fragment's pieces that touch no corner of PreF, and are not counted
  // in the coalesced fragment's size.
  std::uint64_t new_vertices = 0, spawning_ops = 0;
  for (const Op& op : b.crmr.ops) {
    if (op.id == kBaseOp) continue;
    new_vertices += op.new_vertex_count;
    EXPECT_GE(op.new_vertex_count, 1u);
    const SplitPart split = split_part(op);
    spawning_ops += split.triangles < op.fragment.size() ? 1 : 0;
    if (split.new_vertices > 1) {
      EXPECT_LE(split.triangles, QemPmOptions{}.max_fragment_triangles) << "op " << op.id.value;
    }
  }
  // Each vertex is introduced once: by R^0, by a split, or with a spawned component.
  EXPECT_EQ(new_vertices + b.crmr.ops[0].vertices.size(), b.source.positions.size());
  EXPECT_LE(spawning_ops, b.stats.spawned_components);
  EXPECT_GE(new_vertices, b.stats.collapses);
  // DAG depth: the longest parent-to-child path from R^0 (parents have smaller ids).
  std::vector<std::uint64_t> depth(b.crmr.ops.size(), 0);
  std::uint64_t dag_depth = 0;
  for (const Op& op : b.crmr.ops) {
    for (OpId p : op.parents) depth[op.id.value] = std::max(depth[op.id.value], depth[p.value] + 1);
    dag_depth = std::max(dag_depth, depth[op.id.value]);
  }
  std::printf("%s: %zu ops for %llu collapses (%.3f), DAG depth %llu (log2 ops %.1f)\n",
              GetParam().c_str(), b.crmr.ops.size(), (unsigned long long)b.stats.collapses,
              double(b.crmr.ops.size()) / double(b.stats.collapses), (unsigned long long)dag_depth,
              std::log2(double(b.crmr.ops.size())));
  // Coalescing merges about a third of the splits (0.62-0.73 ops per collapse on the CGAL
  // meshes), and the DAG stays shallow: its depth is logarithmic in the ops (19-49, at most
  // 3.4 log2(ops)).
  EXPECT_LE(double(b.crmr.ops.size()), 0.8 * double(b.stats.collapses)) << "too little coalesced";
  EXPECT_LE(double(dag_depth), 4.0 * std::log2(double(b.crmr.ops.size()))) << "the DAG is deep";

  expect_finest_mesh_is_the_source(b.crmr, b.source);

  const SurfaceReport fine = check_surface(b.crmr, level(b.crmr, true));
  const SurfaceReport base = check_surface(b.crmr, level(b.crmr, false));
  EXPECT_TRUE(base.report.ok()) << base.report.summary();
  // Every component but one is spawned by refinement (Brown Fig. 4.9d).
  EXPECT_EQ(base.components, 1u);
  EXPECT_EQ(base.components + b.stats.spawned_components, fine.components);
  test::expect_same_topology_or_unspawned(base, fine);
  EXPECT_DOUBLE_EQ(b.crmr.header.err_final, 0.0);
  EXPECT_GT(b.crmr.header.err0, 0.0);
  std::printf(
      "%s: %zu vertices, %zu triangles -> base %llu vertices %llu triangles, %zu ops, "
      "err0 %.4g (bbox diagonal %.4g)\n",
      GetParam().c_str(), b.source.positions.size(), b.source.triangles.size(),
      (unsigned long long)b.stats.base_vertices, (unsigned long long)b.stats.base_triangles,
      b.crmr.ops.size(), b.crmr.header.err0,
      glm::length(b.crmr.header.bounds.hi - b.crmr.header.bounds.lo));
}

// Extractions from `crmr` for many cameras, tolerances and volumes: set formula == advancing
// front, manifold with the source's incidence, the RCF met op-wise and pointwise, back-face
// culling hiding no detail, and the error bound both ways against `source`.
void expect_extractions_hold(const Crmr& crmr, const TriangleMesh& source) {
  const SurfaceReport fine = check_surface(crmr, level(crmr, true));
  std::vector<std::array<Vec3, 3>> source_tris;
  for (const auto& t : source.triangles) {
    source_tris.push_back({source.positions[t[0]], source.positions[t[1]], source.positions[t[2]]});
  }
  const test::TriangleSoupDistance to_source(source_tris);
  const double scale = glm::length(crmr.header.bounds.hi - crmr.header.bounds.lo);
  const double tol = 1e-9 * scale;
  // The component of each source vertex (the output's vertex ids are the source's).
  const std::vector<std::uint32_t> source_component = components_of(source);
  std::size_t sizes_seen = 0, last_size = 0;
  std::uint64_t all_half_failures = 0;
  for (const test::NamedSpec& c : test::mesh_rcf_spread(crmr.header)) {
    SCOPED_TRACE(c.name);
    const Rcf rcf = make_rcf(c.spec, ModelKind::kMesh3d, nullptr);
    const Extraction e = extract_minimal_surface(crmr, rcf);
    if (e.triangles.size() != last_size) ++sizes_seen, last_size = e.triangles.size();

    std::vector<TriRef> front = e.triangles, formula = set_formula(crmr, e.x);
    std::sort(front.begin(), front.end());
    EXPECT_EQ(front, formula) << "set formula != advancing front";

    const SurfaceReport s = check_surface(crmr, e.triangles);
    EXPECT_TRUE(s.report.ok()) << s.report.summary();
    test::expect_same_topology_or_unspawned(s, fine);

    const test::OracleResult opwise = test::check_rcf_opwise(crmr, e.triangles, rcf);
    EXPECT_TRUE(opwise.ok()) << opwise.first_failure;
    const test::OracleResult xdef = test::check_x_definition(crmr, e.x, rcf, true);
    EXPECT_TRUE(xdef.ok()) << xdef.first_failure;

    // Volumes of significance, pointwise from their definition: at the corners, edge midpoints
    // and centroid of every output triangle that some op could refine, the level asked for is
    // at most the triangle's death_res.
    std::uint64_t volume_failures = 0;
    for (const VolumeSpec& v : c.spec.volumes) {
      for (const TriRef& ref : e.triangles) {
        const Op& op = crmr.ops[ref.op.value];
        const FragmentTriangle& t = op.fragment[ref.index];
        if (!t.killer.valid()) continue;  // final: the finest the model has
        const Vec3 a = op.position(t, 0), b2 = op.position(t, 1), c2 = op.position(t, 2);
        for (const Vec3& q :
             {a, b2, c2, 0.5 * (a + b2), 0.5 * (b2 + c2), 0.5 * (c2 + a), (a + b2 + c2) / 3.0}) {
          const double d = glm::length(q - Vec3{v.x, v.y, v.z});
          const double g = v.gaussian ? v.level * std::exp(-d * d / (2 * v.radius * v.radius))
                                      : (d <= v.radius ? v.level : 0.0);
          if (g > t.death_res + 1e-12) ++volume_failures;
        }
      }
    }
    EXPECT_EQ(volume_failures, 0u);

    // Back-face culling never hides detail: an output triangle that is coarser than the
    // similarity criteria ask is outside the frustum (itself or its killer), or its killer's
    // whole subtree faces away from the eye (brute force over the descendants, not the cones).
    if (c.spec.camera && c.spec.cull && !rcf.similarity().empty()) {
      std::vector<std::uint8_t> facing(crmr.ops.size(), 0);
      const FrustumCulling frustum(*c.spec.camera);
      std::uint64_t hidden = 0;
      for (const TriRef& ref : e.triangles) {
        const Op& op = crmr.ops[ref.op.value];
        const FragmentTriangle& t = op.fragment[ref.index];
        if (!t.killer.valid()) continue;
        const Triangle3 v = corners(op, t);
        bool similar = true;
        for (const auto& criterion : rcf.similarity())
          similar = similar && criterion->triangle_satisfies(v, t.death_res, crmr.header);
        if (similar) continue;
        const Op& killer = crmr.ops[t.killer.value];
        if (frustum.culls(killer) || frustum.culls_triangle(v)) continue;
        if (any_front_facing(crmr, killer.id.value, c.spec.camera->eye, facing)) ++hidden;
      }
      EXPECT_EQ(hidden, 0u) << "coarse output triangles whose refinements face the eye";
    }

    // Error bound, output -> source: points of each (sampled) output triangle lie within the
    // triangle's stored error of the source surface.
    std::vector<std::array<Vec3, 3>> out_tris;
    std::vector<double> out_bounds;
    double max_bound = 0.0;
    std::uint64_t failures = 0;
    double worst = 0.0;
    std::vector<std::uint8_t> present(source_component.size(), 0);
    const std::size_t stride = std::max<std::size_t>(1, e.triangles.size() / 1500);
    for (std::size_t i = 0; i < e.triangles.size(); ++i) {
      const TriRef ref = e.triangles[i];
      const Op& op = crmr.ops[ref.op.value];
      const FragmentTriangle& t = op.fragment[ref.index];
      const std::array<Vec3, 3> p{op.position(t, 0), op.position(t, 1), op.position(t, 2)};
      out_tris.push_back(p);
      const double bound = error_at(crmr.header, t.death_res);
      out_bounds.push_back(bound + tol);
      max_bound = std::max(max_bound, bound);
      present[source_component[op.vertex_id(t, 0).value]] = 1;
      if (i % stride != 0) continue;
      for (const auto& w :
           {Vec3{1, 1, 1} / 3.0, Vec3{0.5, 0.5, 0}, Vec3{0, 0.5, 0.5}, Vec3{0.5, 0, 0.5},
            Vec3{4, 1, 1} / 6.0, Vec3{1, 4, 1} / 6.0, Vec3{1, 1, 4} / 6.0}) {
        const Vec3 q = w.x * p[0] + w.y * p[1] + w.z * p[2];
        if (!to_source.within(q, bound + tol)) {
          ++failures;
          worst = std::max(worst, to_source.distance(q) - bound);
        }
      }
    }
    EXPECT_EQ(failures, 0u) << "output points farther from the source than their bound (worst "
                            << worst << " over)";
    // Source -> output, view-locally. The builder assigns every source point to one triangle of
    // each state of the simplification, within that triangle's own bound e(T) (qem_pm.h), and a
    // collapse hands the points of the triangles it removes (F of the split) to the ones it makes
    // (PreF). Followed from R^0 through the killers that are in X, a point's triangle ends at an
    // output triangle (its killer is not in X): so each source point lies within the bound of SOME
    // output triangle (error_at(death_res) is its killer's error, at least e(T)). Checking
    // against the largest bound of the cut instead lets any point pass in a camera view (it is
    // about err0 there); here a point near the eye, where the output is fine, must be near fine
    // triangles. A component not spawned yet in the cut has no output triangle to be assigned to:
    // its points are only bounded by the error of the op that spawns it, at most the largest.
    const test::TriangleSoupDistance to_output(out_tris, out_bounds);
    const std::size_t sstride = std::max<std::size_t>(1, source_tris.size() / 1500);
    failures = 0;
    std::uint64_t half_failures = 0;
    for (std::size_t i = 0; i < source_tris.size(); i += sstride) {
      const auto& t = source_tris[i];
      const bool spawned = present[source_component[source.triangles[i][0]]] != 0;
      for (const Vec3& q : {t[0], (t[0] + t[1] + t[2]) / 3.0, 0.5 * (t[1] + t[2])}) {
        if (!spawned) {
          if (!to_output.within(q, max_bound + tol)) ++failures;
          continue;
        }
        if (!to_output.within_own_radius(q)) ++failures;
        if (!to_output.within_own_radius(q, 0.5)) ++half_failures;
      }
    }
    EXPECT_EQ(failures, 0u) << "source points farther from the output than the bounds of the "
                               "output triangles near them";
    all_half_failures += half_failures;
  }
  EXPECT_GE(sizes_seen, 5u) << "the RCFs should give many different outputs";
  // Teeth: the bounds are tight enough that halving them fails some source points.
  EXPECT_GT(all_half_failures, 0u) << "the source -> output check would pass bounds half as large";
}

TEST_P(QemPm, ExtractionsAreManifoldSatisfyTheRcfAndHoldTheErrorBound) {
  const Built& b = built(GetParam());
  expect_extractions_hold(b.crmr, b.source);
}

TEST_P(QemPm, SimplificationMakesNoSelfIntersection) {
  expect_simplification_adds_no_crossing(built(GetParam()).crmr, GetParam(), true);
}

// The 3-D screen-space rule pointwise, from its definition (Brown 4.6.3) with the camera's own
// numbers, not the RCF's functions. With culling off nothing may escape the rule, and Theorem
// 5.1.1 gives every output triangle t that an op replaces the screen-space component at its
// death_res: in F(creator), finer, or in PreF(killer), completely finer at birth_res(killer) =
// death_res(t). The component promises error_at(death_res) * focal_px / dist(eye, box(t)) <= tau
// (ScreenSpaceCriterion, s(B) = 1 in 3-D, no screen AOI in this spread). The box holds t, so the
// eye is at least as far from t's nearest point, and
//     error * focal_px / |eye - nearest point of t| <= tau
// follows for every output triangle, which is checked here (a superset of those inside the
// frustum), with error = (1 - death_res) * (err0 - err_final) + err_final, the focal length
// (viewport_h / 2) / tan(fov_y / 2) in pixels and the distance computed above. Teeth: some
// triangle of the views comes within a factor 2 of tau (a library with half the focal length,
// or this test with half of tau, fails). The same views with culling on must be smaller.
TEST_P(QemPm, ScreenSpaceRuleHoldsPointwiseAndCullingSavesTriangles) {
  const Crmr& crmr = built(GetParam()).crmr;
  const CrmrInfo& info = crmr.header;
  std::size_t views = 0, smaller = 0;
  std::uint64_t with_culling = 0, without = 0, checked = 0;
  double closest = 0.0;  // the largest projected error over tau
  for (const test::NamedSpec& c : test::mesh_rcf_spread(info)) {
    if (!c.spec.camera || !c.spec.pixel_error) continue;
    SCOPED_TRACE(c.name);
    RcfSpec off = c.spec;
    off.cull = false;
    const Extraction e = extract_minimal_surface(crmr, make_rcf(off, ModelKind::kMesh3d, nullptr));
    const Camera& cam = *off.camera;
    const double focal = 0.5 * cam.viewport_h / std::tan(cam.fov_y_deg * M_PI / 360.0);
    const double tau = *off.pixel_error;
    std::uint64_t failures = 0;
    std::string first;
    for (const TriRef& ref : e.triangles) {
      const Op& op = crmr.ops[ref.op.value];
      const FragmentTriangle& t = op.fragment[ref.index];
      if (!t.killer.valid()) continue;  // final: the finest the model has
      ++checked;
      const double error = (1.0 - t.death_res) * (info.err0 - info.err_final) + info.err_final;
      const double px = error * focal /
                        test::textbook_triangle_distance(cam.eye, op.position(t, 0),
                                                         op.position(t, 1), op.position(t, 2));
      closest = std::max(closest, px / tau);
      if (px > tau * (1.0 + 1e-9) && failures++ == 0) {
        first = "op " + std::to_string(ref.op.value) + " triangle " + std::to_string(ref.index) +
                ": " + std::to_string(px) + " px";
      }
    }
    EXPECT_EQ(failures, 0u) << "output triangles whose projected error exceeds " << tau
                            << " px, first " << first;
    // Culling only makes ops finer or completely finer, so X shrinks: X(on) is in X(off), and
    // every split adds triangles, so the output cannot grow.
    const Extraction on =
        extract_minimal_surface(crmr, make_rcf(c.spec, ModelKind::kMesh3d, nullptr));
    std::vector<OpId> x_on = on.x, x_off = e.x;
    std::sort(x_on.begin(), x_on.end());
    std::sort(x_off.begin(), x_off.end());
    EXPECT_TRUE(std::includes(x_off.begin(), x_off.end(), x_on.begin(), x_on.end()))
        << "culling added an op to X";
    EXPECT_LE(on.triangles.size(), e.triangles.size());
    ++views;
    smaller += on.triangles.size() < e.triangles.size() ? 1 : 0;
    with_culling += on.triangles.size();
    without += e.triangles.size();
  }
  std::printf(
      "%s: %zu views, %llu triangles checked, largest projected error %.3f tau; culling "
      "gives fewer triangles in %zu views (%llu against %llu)\n",
      GetParam().c_str(), views, (unsigned long long)checked, closest, smaller,
      (unsigned long long)with_culling, (unsigned long long)without);
  EXPECT_GT(checked, 0u);
  EXPECT_GT(closest, 0.9) << "no triangle comes near the tolerance: the check has no teeth";
  // Every mesh has views where culling removes triangles (11 to 18 of the 18 views here).
  EXPECT_GE(smaller, views / 2) << "culling rarely removed a triangle";
}

// Most ops' normal cones (F and PreF) are narrower than a half space, so back-face culling can
// decide on them: on these smooth scans at least 90 % of the ops have a half angle below pi/2.
TEST_P(QemPm, MostNormalConesAreNarrow) {
  const Crmr& crmr = built(GetParam()).crmr;
  std::size_t narrow = 0, subtree_narrow = 0;
  for (const Op& op : crmr.ops) {
    if (op.id == kBaseOp) continue;
    narrow += op.cone.half_angle < M_PI / 2 ? 1 : 0;
    subtree_narrow += op.subtree_cone.half_angle < M_PI / 2 ? 1 : 0;
  }
  const double n = double(crmr.ops.size() - 1);
  std::printf("%s: %.1f %% of the ops' cones, %.1f %% of their subtree cones below pi/2\n",
              GetParam().c_str(), 100.0 * double(narrow) / n, 100.0 * double(subtree_narrow) / n);
  EXPECT_GE(double(narrow), 0.9 * n);
}

// Normal turns, per collapse, exactly as the builder guarantees them (valid() in
// smr/builders/mesh/qem_pm.cpp): a half-edge collapse v' -> u turns each triangle of the star of v'
// that does not hold u into the same triangle with u in place of v'; that triangle must not be
// degenerate, and when the old one was not, the angle between their normals is at most
// max_normal_turn_degrees. Coalescing hides the triangles between the splits of one op, so this
// runs on a CRMR built without it (the same collapses: coalescing only groups the splits), where
// every op but R^0 is one split: F = the star of its new vertex v' (plus any component it
// spawns), PreF = the star's triangles without u, with u for v'. The split is recovered from the
// op alone: the (v', u) for which the star of v' maps onto PreF exactly (a vertex of degree 3
// has several; one of them must then keep every turn within the limit).
struct NormalTurns {
  std::uint64_t pairs = 0, unexplained = 0, too_far = 0, degenerate = 0;
  double worst = 0.0;  // degrees, over the explaining collapses
};

NormalTurns normal_turns(const Crmr& crmr, double limit_degrees) {
  NormalTurns r;
  using Ids = std::array<std::uint64_t, 3>;
  for (const Op& op : crmr.ops) {
    if (op.id == kBaseOp || op.pre_tris.empty()) continue;
    std::map<std::uint64_t, Vec3> at;
    for (const Vertex& v : op.vertices) at[v.id.value] = v.p;
    std::vector<Ids> pre;
    for (const PreTriangle& t : op.pre_tris) {
      pre.push_back(canonical({op.vertices[t.v[0]].id.value, op.vertices[t.v[1]].id.value,
                               op.vertices[t.v[2]].id.value}));
    }
    std::sort(pre.begin(), pre.end());
    std::vector<Ids> fragment;
    for (const FragmentTriangle& t : op.fragment) {
      fragment.push_back(
          {op.vertex_id(t, 0).value, op.vertex_id(t, 1).value, op.vertex_id(t, 2).value});
    }
    const auto normal = [&](const Ids& t) {
      return glm::cross(at[t[1]] - at[t[0]], at[t[2]] - at[t[0]]);
    };
    const auto has = [](const Ids& t, std::uint64_t v) {
      return t[0] == v || t[1] == v || t[2] == v;
    };
    bool explained = false;
    double best = 1e300;  // the explaining collapse's largest turn, least over the candidates
    bool best_degenerate = false;
    for (std::uint32_t k = 0; k < op.new_vertex_count; ++k) {
      const std::uint64_t split = op.vertices[k].id.value;
      for (const std::uint64_t u : pre.front()) {
        std::vector<Ids> mapped;
        std::vector<std::pair<Ids, Ids>> pairs;  // (before, after)
        int shared = 0;
        for (const Ids& t : fragment) {
          if (!has(t, split)) continue;
          if (has(t, u)) {
            ++shared;
            continue;
          }
          Ids after = t;
          for (auto& w : after) w = w == split ? u : w;
          pairs.push_back({t, after});
          mapped.push_back(canonical(after));
        }
        std::sort(mapped.begin(), mapped.end());
        if (shared < 1 || shared > 2 || mapped != pre) continue;
        explained = true;
        double turn = 0.0;
        bool degenerate = false;
        for (const auto& [before, after] : pairs) {
          const Vec3 nb = normal(before), na = normal(after);
          if (!(glm::length(na) > 0.0)) degenerate = true;
          if (glm::length(nb) > 0.0 && glm::length(na) > 0.0) {
            turn = std::max(
                turn, std::atan2(glm::length(glm::cross(nb, na)), glm::dot(nb, na)) * 180.0 / M_PI);
          }
        }
        if (!degenerate && turn < best) best = turn;
        best_degenerate = best_degenerate || degenerate;
      }
    }
    r.pairs += op.pre_tris.size();
    if (!explained) {
      ++r.unexplained;
    } else if (best == 1e300) {
      r.degenerate += best_degenerate ? 1 : 0;
    } else {
      r.worst = std::max(r.worst, best);
      if (best > limit_degrees + 1e-6) ++r.too_far;
    }
  }
  return r;
}

TEST_P(QemPm, NoCollapseTurnsANormalFurtherThanTheLimit) {
  const Built& b = built(GetParam());
  QemPmOptions o;
  o.max_fragment_triangles = 0;  // one op per split
  QemPmStats stats;
  const Crmr crmr = build_qem_pm(b.source, GetParam(), o, &stats);
  ASSERT_EQ(stats.collapses, b.stats.collapses) << "coalescing changed the collapses";
  ASSERT_EQ(crmr.ops.size(), stats.collapses + 1);
  const NormalTurns r = normal_turns(crmr, o.max_normal_turn_degrees);
  std::printf(
      "%s: %llu turned triangles, largest turn %.2f degrees (limit %.0f), %llu flips "
      "refused\n",
      GetParam().c_str(), (unsigned long long)r.pairs, r.worst, o.max_normal_turn_degrees,
      (unsigned long long)stats.rejected_flip);
  EXPECT_EQ(r.unexplained, 0u) << "ops that are not one half-edge collapse reversed";
  EXPECT_EQ(r.degenerate, 0u) << "collapses that made a degenerate triangle";
  EXPECT_EQ(r.too_far, 0u) << "collapses that turned a normal more than the limit";
  EXPECT_GT(r.pairs, b.stats.collapses);
  EXPECT_GT(r.worst, 60.0) << "no normal turned far: the check has nothing to catch";
}

// The oracle follows the option: with a 20 degree limit no turn exceeds 20 degrees, where the
// default (75) lets some do.
TEST(QemPmOptions, ATighterNormalTurnLimitIsKept) {
  const char* name = "elephant-with-holes.off";
  QemPmOptions o;
  o.max_fragment_triangles = 0;
  const NormalTurns loose = normal_turns(build_qem_pm(built(name).source, name, o), 75.0);
  o.max_normal_turn_degrees = 20.0;
  const NormalTurns tight = normal_turns(build_qem_pm(built(name).source, name, o), 20.0);
  EXPECT_GT(loose.worst, 20.0);
  EXPECT_EQ(tight.unexplained, 0u);
  EXPECT_EQ(tight.degenerate, 0u);
  EXPECT_EQ(tight.too_far, 0u);
  EXPECT_LE(tight.worst, 20.0 + 1e-6);
}

// Without the test, simplification of the elephant with holes crosses itself, so the oracle above
// has something to catch.
TEST(QemPmOptions, WithoutTheIntersectionTestTheBaseMeshCrossesItself) {
  const char* name = "elephant-with-holes.off";
  QemPmOptions o;
  o.allow_self_intersections = true;
  QemPmStats stats;
  const Crmr plain = build_qem_pm(built(name).source, name, o, &stats);
  EXPECT_EQ(stats.rejected_intersection, 0u);
  EXPECT_GT(built(name).stats.rejected_intersection, 0u);
  EXPECT_EQ(test::crossing_pairs(corners_of(plain, level(plain, true))), 0u);
  EXPECT_GT(test::crossing_pairs(corners_of(plain, level(plain, false))), 0u);
}

// Without coalescing every vertex split is its own op, and the CRMR is as valid.
TEST(QemPmOptions, OneOpPerSplitWithoutCoalescing) {
  const TriangleMesh mesh = test::built_mesh("elephant-with-holes.off").source;
  QemPmOptions o;
  o.max_fragment_triangles = 0;
  QemPmStats stats;
  const Crmr crmr = build_qem_pm(mesh, "elephant-with-holes.off", o, &stats);
  EXPECT_EQ(crmr.ops.size(), stats.collapses + 1);
  for (const Op& op : crmr.ops) {
    if (op.id != kBaseOp) {
      EXPECT_EQ(op.new_vertex_count, 1u);
    }
  }
  const InvariantReport r = check_crmr(crmr);
  EXPECT_TRUE(r.ok()) << r.summary();
  o.coalesce_error_ratio = 1.5;
  EXPECT_THROW((void)build_qem_pm(mesh, "x", o), Error);
}

// Bounds computed ahead on helper threads (QemPmOptions::threads) are used only for the
// candidate and band they were computed for, so the CRMR is the same op for op whatever the
// number of threads (4: more than this machine's 2 cores), and so are the count of bounds the
// simplification needed and the rejections; with helpers, bounds handed over are used.
TEST(QemPmOptions, TheSameCrmrWhateverTheThreads) {
  const char* name = test::kSanitized ? "mech-holes-shark.off" : "ChineseDragon-10kv.off";
  const TriangleMesh& mesh = built(name).source;
  QemPmOptions one;
  one.threads = 1;
  QemPmStats one_stats;
  const Crmr a = build_qem_pm(mesh, name, one, &one_stats);
  EXPECT_EQ(one_stats.bounds_ahead, 0u);
  for (unsigned threads : {2u, 4u}) {
    QemPmOptions o;
    o.threads = threads;
    QemPmStats stats;
    const Crmr b = build_qem_pm(mesh, name, o, &stats);
    EXPECT_TRUE(a.header == b.header);
    ASSERT_EQ(a.ops.size(), b.ops.size());
    std::size_t differ = 0;
    for (std::size_t i = 0; i < a.ops.size(); ++i) differ += a.ops[i] == b.ops[i] ? 0 : 1;
    EXPECT_EQ(differ, 0u) << threads << " threads";
    EXPECT_EQ(stats.bounds_computed, one_stats.bounds_computed);
    EXPECT_EQ(stats.rejected_flip, one_stats.rejected_flip);
    EXPECT_EQ(stats.rejected_link, one_stats.rejected_link);
    EXPECT_GT(stats.bounds_ahead_used, 0u) << threads << " threads";
    EXPECT_LE(stats.bounds_ahead_used, stats.bounds_ahead);
  }
}

// Bands of the bound (the default) against none: both CRMRs are valid and hold their bounds in
// every extraction, and the bands' cuts at the same uniform resolutions use fewer triangles (an
// early large bound no longer raises every later collapse in its region). Factors below 1 could
// never reach the least bound that waited: an input error. (The shark under the sanitizers:
// 10 445 against 12 519 triangles.)
TEST(QemPmOptions, BandsOfTheBoundGiveSmallerUniformCuts) {
  const char* name = test::kSanitized ? "mech-holes-shark.off" : "ChineseDragon-10kv.off";
  const Built& banded = built(name);
  QemPmOptions o;
  o.bound_band = 0.0;
  const Crmr plain = build_qem_pm(banded.source, name, o);
  const InvariantReport r = check_crmr(plain);
  ASSERT_TRUE(r.ok()) << r.summary();
  expect_extractions_hold(plain, banded.source);
  std::uint64_t with = 0, without = 0;
  const auto cut = [](const Crmr& c, double error) {
    RcfSpec spec;
    spec.floor = resolution_of(c.info(), error);
    return extract_minimal_surface(c, make_rcf(spec, ModelKind::kMesh3d, nullptr)).triangles.size();
  };
  // Uniform errors from 1/1000 to 1/30 of the model's coarsest bound.
  for (const double f : {0.001, 0.003, 0.01, 0.03}) {
    with += cut(banded.crmr, f * banded.crmr.info().err0);
    without += cut(plain, f * banded.crmr.info().err0);
  }
  std::printf("uniform cuts at 4 errors: %llu triangles with bands, %llu without\n",
              static_cast<unsigned long long>(with), static_cast<unsigned long long>(without));
  EXPECT_LT(double(with), 0.95 * double(without));
  for (const double bad : {0.5, -1.0, std::nan("")}) {
    o.bound_band = bad;
    EXPECT_THROW((void)build_qem_pm(banded.source, "x", o), Error) << bad;
  }
}

// The repaired pig's parts touch at its pinch points, now vertices repeated at one position:
// triangles meeting there share the position, and a crossing the old star already had may be
// reshaped, so the test does not stall simplification where the source touches itself. Either
// rule alone is enough here; with neither, 258 base triangles were left (without the test, 1).
TEST(QemPmOptions, TheIntersectionTestDoesNotStallWhereTheSourceTouchesItself) {
  const TriangleMesh pig = read_mesh(test::mesh_path("pig.stl"), MeshRepair::all());
  QemPmOptions o;
  QemPmStats with, without;
  (void)build_qem_pm(pig, "pig.stl", o, &with);
  o.allow_self_intersections = true;
  (void)build_qem_pm(pig, "pig.stl", o, &without);
  EXPECT_GT(with.rejected_intersection, 0u);
  EXPECT_LE(with.base_triangles, 2 * without.base_triangles + 8);
  EXPECT_GE(double(with.collapses), 0.99 * double(without.collapses));
}

// ---- the out-of-core builder with tiny leaf blocks, so the octree has several levels ----------

struct BlockBuilt {
  Crmr crmr;
  BlockPmStats stats;
};

BlockPmOptions tiny_blocks() {
  BlockPmOptions o;
  o.leaf_triangles = 300;
  o.face_sort_bytes = o.assembly_sort_bytes = 128 << 10;  // the sorts spill
  return o;
}

const BlockBuilt& block_built(const std::string& name) {
  static std::map<std::string, BlockBuilt> cache;
  auto it = cache.find(name);
  if (it != cache.end()) return it->second;
  BlockBuilt b;
  const TriangleMesh& mesh = built(name).source;
  b.crmr = build_block_pm(MemoryMeshStream(mesh, name), tiny_blocks(), &b.stats);
  return cache.emplace(name, std::move(b)).first->second;
}

class BlockPm : public ::testing::TestWithParam<std::string> {};

TEST_P(BlockPm, CrmrInvariantsHoldAndTheFinestMeshIsTheSource) {
  const BlockBuilt& b = block_built(GetParam());
  const TriangleMesh& source = built(GetParam()).source;
  const InvariantReport r = check_crmr(b.crmr);
  EXPECT_TRUE(r.ok()) << r.summary();
  EXPECT_GE(b.stats.levels, 2);
  EXPECT_GT(b.stats.collapses, source.positions.size() / 2) << "simplified too little";
  EXPECT_EQ(b.crmr.ops.size(), b.stats.collapses + 1);
  EXPECT_LE(b.stats.dag_height, b.stats.rounds);
  EXPECT_LE(b.stats.max_block_triangles, source.triangles.size());
  expect_finest_mesh_is_the_source(b.crmr, source);
  test::expect_links_of_a_replay(b.crmr);
  // No component is spawned: R^0 keeps every one, with the source's topology.
  const SurfaceReport fine = check_surface(b.crmr, level(b.crmr, true));
  const SurfaceReport base = check_surface(b.crmr, level(b.crmr, false));
  EXPECT_TRUE(base.report.ok()) << base.report.summary();
  EXPECT_EQ(base.components, fine.components);
  test::expect_same_topology_or_unspawned(base, fine);
  std::printf(
      "%s: %zu triangles, %d levels, %llu leaf blocks, %llu collapses in %llu rounds, DAG height "
      "%llu, base %llu vertices %llu triangles (in core: %llu), err0 %.4g\n",
      GetParam().c_str(), source.triangles.size(), b.stats.levels,
      (unsigned long long)b.stats.leaf_blocks, (unsigned long long)b.stats.collapses,
      (unsigned long long)b.stats.rounds, (unsigned long long)b.stats.dag_height,
      (unsigned long long)b.stats.base_vertices, (unsigned long long)b.stats.base_triangles,
      (unsigned long long)built(GetParam()).stats.base_triangles, b.crmr.header.err0);
}

TEST_P(BlockPm, ExtractionsAcrossBlockBordersAreManifoldAndHoldTheRcfAndTheBound) {
  expect_extractions_hold(block_built(GetParam()).crmr, built(GetParam()).source);
}

TEST_P(BlockPm, SimplificationMakesNoSelfIntersection) {
  expect_simplification_adds_no_crossing(block_built(GetParam()).crmr, GetParam(), false);
}

TEST(BlockPmBuild, DeterministicWhateverTheBudgetAndTheThreads) {
  const TriangleMesh& mesh = built("elephant-with-holes.off").source;
  BlockPmOptions one = tiny_blocks();
  one.threads = 1;
  const Crmr a = build_block_pm(MemoryMeshStream(mesh, "e"), one);
  BlockPmOptions roomy = tiny_blocks();
  roomy.face_sort_bytes = roomy.assembly_sort_bytes = 256 << 20;
  roomy.threads = 3;  // more workers than cores: leaves finish out of order
  BlockPmOptions two = tiny_blocks();
  two.threads = 2;
  for (const BlockPmOptions& o : {roomy, two}) {
    const Crmr b = build_block_pm(MemoryMeshStream(mesh, "e"), o);
    EXPECT_TRUE(a.header == b.header);
    ASSERT_EQ(a.ops.size(), b.ops.size());
    std::size_t differ = 0;
    for (std::size_t i = 0; i < a.ops.size(); ++i) differ += a.ops[i] == b.ops[i] ? 0 : 1;
    EXPECT_EQ(differ, 0u) << o.threads << " threads";
  }
}

// A block interior simplified far past what its locked border will reach one level up makes
// the border's later collapses parents of the interior's, so every cut finer than the interior
// would hold the border at full resolution. Blocks stop at a small fraction of their side
// (BlockPmOptions::tolerance_fraction), so uniform cuts across many blocks are no larger than
// the in-core builder's. The mesh is midpoint-subdivided once: its flat new vertices collapse
// at no cost, the case where an interior runs furthest ahead of its border (the shark: 1.04x
// the in-core cuts; 1.62x at 1/64 of the side, the fraction before). And no block hands its
// parent more than leaf_triangles triangles.
TEST(BlockPmBuild, CutsAcrossBlockBordersAreNoLargerThanInCore) {
  const char* name = "mech-holes-shark.off";
  // Under the sanitizers, for the suite's time, the shark as it is (10 k triangles).
  const TriangleMesh mesh =
      test::kSanitized ? built(name).source : midpoint_subdivided(built(name).source);
  const Crmr in_core = build_qem_pm(mesh, name);
  BlockPmOptions o;
  o.leaf_triangles = mesh.triangles.size() / 32;
  BlockPmStats stats;
  const Crmr blocks = build_block_pm(MemoryMeshStream(mesh, name), o, &stats);
  EXPECT_GE(stats.leaf_blocks, 8u);
  EXPECT_GE(stats.levels, 2);
  EXPECT_LE(stats.max_handed_triangles, o.leaf_triangles);
  const auto cut = [](const Crmr& c, double error) {
    RcfSpec spec;
    spec.floor = resolution_of(c.info(), error);
    return extract_minimal_surface(c, make_rcf(spec, ModelKind::kMesh3d, nullptr)).triangles.size();
  };
  std::uint64_t ours = 0, reference = 0;
  for (const double f : {0.0005, 0.001, 0.002, 0.004}) {
    const double error = f * in_core.info().err0;
    ours += cut(blocks, error);
    reference += cut(in_core, error);
  }
  std::printf("uniform cuts at 4 errors: %llu triangles from %llu leaf blocks, %llu in core\n",
              static_cast<unsigned long long>(ours),
              static_cast<unsigned long long>(stats.leaf_blocks),
              static_cast<unsigned long long>(reference));
  // 1.15: the unsubdivided shark under the sanitizers gave 19 558 against 17 684 (1.106) once
  // the in-core builder's bound bands (QemPmOptions::bound_band) changed when it waits (the blocks'
  // cuts did not change).
  EXPECT_LE(double(ours), 1.15 * double(reference));
}

TEST(BlockPmBuild, RejectsBadInput) {
  TriangleMesh mesh;
  EXPECT_THROW((void)build_block_pm(MemoryMeshStream(mesh, "empty")), Error);
  mesh.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  mesh.triangles = {{0, 1, 3}};
  try {
    (void)build_block_pm(MemoryMeshStream(mesh, "bad.ply"));
    ADD_FAILURE() << "an index out of range was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("bad.ply"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("vertex 3"), std::string::npos) << e.what();
  }
  mesh.triangles = {{0, 1, 2}};
  mesh.positions[1].x = std::nan("");
  EXPECT_THROW((void)build_block_pm(MemoryMeshStream(mesh, "nan")), Error);
  BlockPmOptions o;
  o.tolerance_fraction = 0.0;
  mesh.positions[1].x = 1.0;
  EXPECT_THROW((void)build_block_pm(MemoryMeshStream(mesh, "x"), o), Error);
}

// blobby_3cc: three components; elephant-with-holes: boundaries; the shark: holes; pig.stl, read
// with the repairs: 17 components, 16 of them spawned by refinement; the dragon (not under the
// sanitizers, for the suite's time: the other four cover components, boundaries and holes there).
std::vector<std::string> cgal_meshes() {
  std::vector<std::string> m = {"blobby_3cc.off", "elephant-with-holes.off", "mech-holes-shark.off",
                                "pig.stl"};
  if (!test::kSanitized) m.push_back("ChineseDragon-10kv.off");
  return m;
}
// The larger scans, through the in-core builder only (6-9 s each in a release build; the block
// builder's cuts are checked on the five above): the bunny (closed, smooth), the refined
// elephant (genus 3) and the armadillo. Not under the sanitizers.
std::vector<std::string> larger_meshes() {
  if (test::kSanitized) return {};
  return {"bunny00.off", "refined_elephant.off", "armadillo.off"};
}
const auto kCgalMeshes = ::testing::ValuesIn(cgal_meshes());
std::string mesh_test_name(const ::testing::TestParamInfo<std::string>& p) {
  std::string n = p.param.substr(0, p.param.find('.'));
  std::replace(n.begin(), n.end(), '-', '_');
  return n;
}

INSTANTIATE_TEST_SUITE_P(CgalMeshes, BlockPm, kCgalMeshes, mesh_test_name);
INSTANTIATE_TEST_SUITE_P(CgalMeshes, QemPm, kCgalMeshes, mesh_test_name);
INSTANTIATE_TEST_SUITE_P(LargerMeshes, QemPm, ::testing::ValuesIn(larger_meshes()), mesh_test_name);

}  // namespace
}  // namespace smr
