// Geomorphing's local morphs (smr/extract/morph.h; Brown ch. 6) between two extractions of one
// CRMR under different RCFs: the triangles of the first not in the second (out) and the reverse
// (in). 2.5-D, on the real DEMs: at t = 0 the morph is out's surface, at t = 1 in's, and at every
// t it tiles the domain with the unchanged triangles (shared vertices, no T-junction, no flip).
// 3-D, on the CGAL meshes: at t = 0 the morph's non-degenerate triangles are the first mesh's
// changed triangles, at t = 1 the second's, every collapse map found.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <set>
#include <unordered_map>

#include "base/error.h"
#include "smr/db/database.h"
#include "smr/extract/extract.h"
#include "smr/extract/morph.h"
#include "tests/support/datasets.h"
#include "tests/support/meshes.h"
#include "tests/support/rcf_spread.h"
#include "tests/support/sanitized.h"

namespace smr {
namespace {

struct Change {
  std::vector<TriRef> out, in, same;  // A \ B, B \ A, A and B
};

Change change(const Extraction& a, const Extraction& b) {
  std::vector<TriRef> x = a.triangles, y = b.triangles;
  std::sort(x.begin(), x.end());
  std::sort(y.begin(), y.end());
  Change c;
  std::set_difference(x.begin(), x.end(), y.begin(), y.end(), std::back_inserter(c.out));
  std::set_difference(y.begin(), y.end(), x.begin(), x.end(), std::back_inserter(c.in));
  std::set_intersection(x.begin(), x.end(), y.begin(), y.end(), std::back_inserter(c.same));
  return c;
}

const RcfSpec& spec_named(const std::vector<test::NamedSpec>& spread, const std::string& name) {
  for (const test::NamedSpec& ns : spread) {
    if (ns.name == name) return ns.spec;
  }
  ADD_FAILURE() << "no RCF named " << name;
  return spread.front().spec;
}

Triangle3 corners(const OpSource& source, TriRef t) {
  const OpRef op = source.op(t.op);
  const FragmentTriangle& f = op->triangle(t.index);
  return {op->position(f, 0), op->position(f, 1), op->position(f, 2)};
}

// ---------------------------------------------------------------------------------------------
// 2.5-D

// Point location among triangles in the plane: a bucket grid over their boxes.
class Locator {
 public:
  explicit Locator(std::vector<Triangle3> tris) : tris_(std::move(tris)) {
    for (const Triangle3& t : tris_) {
      for (const Vec3& p : t) box_.add(p);
    }
    cells_ = std::max<int>(1, int(std::sqrt(double(tris_.size()))));
    buckets_.resize(std::size_t(cells_) * std::size_t(cells_));
    for (std::uint32_t i = 0; i < tris_.size(); ++i) {
      Box3 b;
      for (const Vec3& p : tris_[i]) b.add(p);
      const auto [x0, y0] = cell(b.lo);
      const auto [x1, y1] = cell(b.hi);
      for (int y = y0; y <= y1; ++y) {
        for (int x = x0; x <= x1; ++x) buckets_[std::size_t(y * cells_ + x)].push_back(i);
      }
    }
  }
  /// The triangle whose closure holds p (the one where p's least barycentric weight is largest).
  std::int64_t find(const Vec2& p) const {
    const auto [x, y] = cell({p.x, p.y, 0.0});
    std::int64_t best = -1;
    double best_w = -std::numeric_limits<double>::infinity();
    for (std::uint32_t i : buckets_[std::size_t(y * cells_ + x)]) {
      const double w = least_weight(i, p);
      if (w > best_w) best_w = w, best = i;
    }
    return best_w > -1e-9 ? best : -1;
  }
  double height(std::size_t i, const Vec2& p) const {
    const auto w = weights(i, p);
    return w[0] * tris_[i][0].z + w[1] * tris_[i][1].z + w[2] * tris_[i][2].z;
  }

 private:
  std::pair<int, int> cell(const Vec3& p) const {
    const auto at = [&](double v, double lo, double hi) {
      const double f = hi > lo ? (v - lo) / (hi - lo) : 0.0;
      return std::clamp(int(f * cells_), 0, cells_ - 1);
    };
    return {at(p.x, box_.lo.x, box_.hi.x), at(p.y, box_.lo.y, box_.hi.y)};
  }
  std::array<double, 3> weights(std::size_t i, const Vec2& p) const {
    const Triangle3& t = tris_[i];
    const double a = orient2d(xy(t[0]), xy(t[1]), xy(t[2]));
    return {orient2d(p, xy(t[1]), xy(t[2])) / a, orient2d(xy(t[0]), p, xy(t[2])) / a,
            orient2d(xy(t[0]), xy(t[1]), p) / a};
  }
  double least_weight(std::size_t i, const Vec2& p) const {
    const auto w = weights(i, p);
    return std::min({w[0], w[1], w[2]});
  }

  std::vector<Triangle3> tris_;
  Box3 box_;
  int cells_ = 1;
  std::vector<std::vector<std::uint32_t>> buckets_;
};

// At t = 0 (side 0) the morph is the surface of `tris` (out), at t = 1 that of in: at every vertex
// and at every triangle's centroid, which lies in one triangle of tris (the void flag agrees).
void expect_surface(const OpSource& m, const MorphMesh& morph, std::span<const TriRef> tris,
                    int side) {
  std::vector<Triangle3> world;
  for (TriRef t : tris) world.push_back(corners(m, t));
  const Locator locate(world);
  const double tol = 1e-9 * std::max(1.0, m.info().bounds.hi.z - m.info().bounds.lo.z);
  const double t = side;
  const std::uint8_t void_flag = side == 0 ? MorphMesh::kVoidStart : MorphMesh::kVoidEnd;
  std::uint64_t bad = 0, bad_void = 0;
  for (std::size_t i = 0; i < morph.triangles.size(); ++i) {
    Vec3 c{0.0};
    for (std::uint32_t v : morph.triangles[i]) c += morph.at(v, t) / 3.0;
    const std::int64_t at = locate.find(xy(c));
    ASSERT_GE(at, 0) << "a morph triangle outside the triangles at t = " << side;
    bad += std::abs(locate.height(std::size_t(at), xy(c)) - c.z) > tol;
    const bool is_void = m.triangle(tris[std::size_t(at)]).is_void();
    bad_void += is_void != ((morph.flags[i] & void_flag) != 0);
  }
  for (std::size_t v = 0; v < morph.start.size(); ++v) {
    const Vec3 p = morph.at(v, t);
    const std::int64_t at = locate.find(xy(p));
    ASSERT_GE(at, 0);
    bad += std::abs(locate.height(std::size_t(at), xy(p)) - p.z) > tol;
  }
  EXPECT_EQ(bad, 0u) << "heights off the surface at t = " << side;
  EXPECT_EQ(bad_void, 0u) << "void flags at t = " << side;
}

// The morph at t with the unchanged triangles tiles the domain in xy: every triangle
// counter-clockwise with positive area, no two vertices at one xy (they are shared), every
// directed edge once, every edge without its reverse on the domain boundary (so no T-junction),
// and twice the areas summing to the domain's. Returns the first problem, empty if none.
std::string tiling_problem(const OpSource& m, const MorphMesh& morph, double t,
                           std::span<const TriRef> same) {
  std::map<std::pair<double, double>, std::uint32_t> index;
  std::vector<Vec3> xyz;
  for (std::size_t v = 0; v < morph.start.size(); ++v) {
    const Vec3 p = morph.at(v, t);
    if (!index.emplace(std::pair{p.x, p.y}, std::uint32_t(v)).second)
      return "two morph vertices at one xy";
    xyz.push_back(p);
  }
  std::vector<std::array<std::uint32_t, 3>> tris = morph.triangles;
  for (TriRef r : same) {
    const Triangle3 c = corners(m, r);
    std::array<std::uint32_t, 3> tri{};
    for (int k = 0; k < 3; ++k) {
      const auto [it, added] = index.emplace(std::pair{c[k].x, c[k].y}, std::uint32_t(xyz.size()));
      if (added) xyz.push_back(c[k]);
      tri[k] = it->second;
    }
    tris.push_back(tri);
  }
  Box3 box;
  for (const Vec3& p : xyz) box.add(p);
  double area = 0.0;
  std::unordered_map<std::uint64_t, std::uint32_t> edges;
  const auto key = [](std::uint32_t a, std::uint32_t b) { return std::uint64_t{a} << 32 | b; };
  for (const auto& tri : tris) {
    const double a = orient2d(xy(xyz[tri[0]]), xy(xyz[tri[1]]), xy(xyz[tri[2]]));
    if (!(a > 0)) return "a triangle of area " + std::to_string(a);
    area += a;
    for (int k = 0; k < 3; ++k) {
      if (++edges[key(tri[k], tri[(k + 1) % 3])] > 1) return "a directed edge twice";
    }
  }
  for (const auto& [e, count] : edges) {
    const auto a = std::uint32_t(e >> 32), b = std::uint32_t(e);
    if (edges.count(key(b, a))) continue;
    const Vec3 &p = xyz[a], &q = xyz[b];
    const bool boundary =
        (p.x == box.lo.x && q.x == box.lo.x) || (p.x == box.hi.x && q.x == box.hi.x) ||
        (p.y == box.lo.y && q.y == box.lo.y) || (p.y == box.hi.y && q.y == box.hi.y);
    if (!boundary) return "an unmatched edge inside the domain (a gap or a T-junction)";
  }
  const double domain = 2 * (box.hi.x - box.lo.x) * (box.hi.y - box.lo.y);
  if (std::abs(area - domain) > 1e-9 * domain) return "areas sum to " + std::to_string(area);
  return "";
}

// Checks the morph between the cuts of two RCFs; false if they are the same cut.
bool expect_terrain_morph(const test::Dataset& d, const RcfSpec& from, const RcfSpec& to) {
  const Crmr& m = d.crmr;
  const Extraction a = extract_minimal_surface(m, make_rcf(from, ModelKind::kTerrain, &d.dem));
  const Extraction b = extract_minimal_surface(m, make_rcf(to, ModelKind::kTerrain, &d.dem));
  const Change c = change(a, b);
  EXPECT_EQ(c.out.empty(), c.in.empty());
  if (c.out.empty()) return false;
  const MorphMesh morph = terrain_morph(m, c.out, c.in);
  EXPECT_EQ(morph.end.size(), morph.start.size());
  EXPECT_EQ(morph.group.size(), morph.start.size());
  EXPECT_EQ(morph.flags.size(), morph.triangles.size());
  if (morph.end.size() != morph.start.size() || morph.group.size() != morph.start.size() ||
      morph.flags.size() != morph.triangles.size())
    return true;
  // xy never moves; the morph starts and ends exactly where MorphMesh::at says.
  std::uint64_t moved = 0, ends = 0;
  for (std::size_t v = 0; v < morph.start.size(); ++v) {
    moved += xy(morph.start[v]) != xy(morph.end[v]);
    ends += morph.at(v, 0.0) != morph.start[v] || morph.at(v, 1.0) != morph.end[v];
  }
  EXPECT_EQ(moved, 0u);
  EXPECT_EQ(ends, 0u);
  // Vertices are shared: one per xy (pieces that each made their own would repeat xy).
  std::set<std::pair<double, double>> distinct;
  for (const Vec3& p : morph.start) distinct.insert({p.x, p.y});
  EXPECT_EQ(distinct.size(), morph.start.size());
  // The common refinement has at least as many triangles as either side.
  EXPECT_GE(morph.triangles.size(), std::max(c.out.size(), c.in.size()));
  expect_surface(m, morph, c.out, 0);
  expect_surface(m, morph, c.in, 1);
  for (double t : {0.0, 0.25, 0.5, 0.75, 1.0}) {
    EXPECT_EQ(tiling_problem(m, morph, t, c.same), "") << "t = " << t;
  }
  // Groups: connected, each triangle inside one.
  for (const auto& tri : morph.triangles) {
    EXPECT_EQ(morph.group[tri[0]], morph.group[tri[1]]);
    EXPECT_EQ(morph.group[tri[0]], morph.group[tri[2]]);
  }
  EXPECT_GE(morph.groups, 1u);
  std::printf("    %zu out, %zu in -> %zu morph triangles, %zu vertices, %u groups\n", c.out.size(),
              c.in.size(), morph.triangles.size(), morph.start.size(), morph.groups);
  return true;
}

// A terrain "CRMR" whose R^0 holds the triangles of two triangulations (terrain_morph reads
// triangles only): out = fragment[0, n_out), in = the rest. Heights z = x + 2y on out's corners
// and z = 10 - y on in's, so each side is one plane.
struct TwoSides {
  Crmr crmr;
  std::vector<TriRef> out, in;
};
TwoSides two_sides(const std::vector<std::array<GridPoint, 3>>& out,
                   const std::vector<std::array<GridPoint, 3>>& in) {
  TwoSides t;
  t.crmr.header.kind = ModelKind::kTerrain;
  t.crmr.header.grid_width = t.crmr.header.grid_height = 9;
  Op& op = t.crmr.ops.emplace_back();
  op.id = kBaseOp;
  for (int side = 0; side < 2; ++side) {
    for (const auto& tri : side == 0 ? out : in) {
      FragmentTriangle f;
      for (int k = 0; k < 3; ++k) {
        const double x = double(tri[k].x), y = double(tri[k].y);
        f.v[k] = static_cast<std::uint32_t>(op.vertices.size());
        op.vertices.push_back(
            {VertexId{op.vertices.size()}, {x, y, side == 0 ? x + 2 * y : 10 - y}});
      }
      (side == 0 ? t.out : t.in).push_back({kBaseOp, std::uint32_t(op.fragment.size())});
      op.fragment.push_back(f);
    }
  }
  return t;
}

TEST(TerrainMorphCases, CrossingDiagonalsMeetAtARationalVertex) {
  // The unit square split by one diagonal, then by the other: four pieces around (1/2, 1/2).
  const TwoSides s = two_sides({{{{0, 0}, {1, 0}, {1, 1}}}, {{{0, 0}, {1, 1}, {0, 1}}}},
                               {{{{0, 0}, {1, 0}, {0, 1}}}, {{{1, 0}, {1, 1}, {0, 1}}}});
  const MorphMesh m = terrain_morph(s.crmr, s.out, s.in);
  ASSERT_EQ(m.start.size(), 5u);
  EXPECT_EQ(m.triangles.size(), 4u);
  EXPECT_EQ(m.groups, 1u);
  const auto centre = std::find(m.start.begin(), m.start.end(), Vec3{0.5, 0.5, 1.5});
  ASSERT_NE(centre, m.start.end());
  EXPECT_EQ(m.end[std::size_t(centre - m.start.begin())], (Vec3{0.5, 0.5, 9.5}));
  EXPECT_EQ(tiling_problem(s.crmr, m, 0.5, {}), "");
}

TEST(TerrainMorphCases, KeepsVerticesOnEdgesAndSeparatesGroups) {
  // One triangle refined at its edge midpoints (the new corners lie on its edges: no piece may
  // drop them), and apart from it a square whose diagonal flips.
  const TwoSides s = two_sides(
      {{{{0, 0}, {4, 0}, {0, 4}}}, {{{6, 0}, {8, 0}, {8, 2}}}, {{{6, 0}, {8, 2}, {6, 2}}}},
      {{{{0, 0}, {2, 0}, {0, 2}}},
       {{{2, 0}, {4, 0}, {2, 2}}},
       {{{0, 2}, {2, 2}, {0, 4}}},
       {{{2, 0}, {2, 2}, {0, 2}}},
       {{{6, 0}, {8, 0}, {6, 2}}},
       {{{8, 0}, {8, 2}, {6, 2}}}});
  const MorphMesh m = terrain_morph(s.crmr, s.out, s.in);
  EXPECT_EQ(m.start.size(), 6u + 5u);
  EXPECT_EQ(m.triangles.size(), 4u + 4u);
  EXPECT_EQ(m.groups, 2u);
  for (std::size_t v = 0; v < m.start.size(); ++v) {
    EXPECT_EQ(m.start[v].z, m.start[v].x + 2 * m.start[v].y);  // exact on this grid
    EXPECT_EQ(m.end[v].z, 10 - m.end[v].y);
  }
  for (const auto& tri : m.triangles) {
    EXPECT_GT(orient2d(xy(m.start[tri[0]]), xy(m.start[tri[1]]), xy(m.start[tri[2]])), 0.0);
    EXPECT_EQ(m.group[tri[0]], m.group[tri[1]]);
  }
}

TEST(TerrainMorphCases, RefusesAnAddedTriangleOutsideTheRemovedOnes) {
  const TwoSides s = two_sides({{{{0, 0}, {1, 0}, {0, 1}}}},
                               {{{{0, 0}, {1, 0}, {0, 1}}}, {{{3, 3}, {4, 3}, {3, 4}}}});
  EXPECT_THROW(terrain_morph(s.crmr, s.out, s.in), Error);
}

class TerrainMorph : public ::testing::TestWithParam<std::string> {};

TEST_P(TerrainMorph, IsTheOldSurfaceAtZeroTheNewAtOneAndTilesInBetween) {
  const test::Dataset& d = test::dataset(GetParam());
  const auto spread = test::rcf_spread(d.crmr.header);
  // Areas of interest moved, cameras moved (object-space frustum terms, screen-space tolerances;
  // on the real DEMs some screen-space cuts are the base mesh, so some pairs may not differ), a
  // camera jump, uniform error changes (the last from the finest mesh: a large change).
  const std::vector<std::pair<std::string, std::string>> pairs = {
      {"aois", "disc"},
      {"frustum_cone", "frustum_critical_nocull"},
      {"oblique_px5", "aside_screen_aoi"},
      {"down", "oblique_px10"},
      {"floor50", "floor75"},
      {"critical", "frustum_cone"},
      {"floor100", "critical"}};
  int changes = 0;
  for (const auto& [from, to] : pairs) {
    SCOPED_TRACE(GetParam() + ": " + from + " -> " + to);
    std::printf("  %s -> %s\n", from.c_str(), to.c_str());
    changes += expect_terrain_morph(d, spec_named(spread, from), spec_named(spread, to));
  }
  EXPECT_GE(changes, 5);
}

INSTANTIATE_TEST_SUITE_P(Dems, TerrainMorph, ::testing::ValuesIn(test::dataset_names()),
                         [](const auto& p) { return p.param; });

// ---------------------------------------------------------------------------------------------
// 3-D

bool less_point(const Vec3& a, const Vec3& b) {
  return a.x != b.x ? a.x < b.x : a.y != b.y ? a.y < b.y : a.z < b.z;
}
bool less_triangle(const Triangle3& a, const Triangle3& b) {
  for (int k = 0; k < 3; ++k) {
    if (a[k] != b[k]) return less_point(a[k], b[k]);
  }
  return false;
}
// The same triangle, same orientation, rotated so its least corner comes first.
Triangle3 rotated(const Triangle3& t) {
  int m = 0;
  for (int k = 1; k < 3; ++k) m = less_point(t[k], t[m]) ? k : m;
  return {t[m], t[(m + 1) % 3], t[(m + 2) % 3]};
}

std::vector<Triangle3> sorted_triangles(std::vector<Triangle3> tris) {
  for (Triangle3& t : tris) t = rotated(t);
  std::sort(tris.begin(), tris.end(), less_triangle);
  return tris;
}

struct FlipCount {
  std::uint64_t triangles = 0, flips = 0;
  std::uint64_t one_moving = 0;  // flips of triangles with one moving corner
};

void expect_mesh_morph(const Crmr& m, const RcfSpec& from, const RcfSpec& to, FlipCount& flips) {
  const Extraction a = extract_minimal_surface(m, make_rcf(from, ModelKind::kMesh3d, nullptr));
  const Extraction b = extract_minimal_surface(m, make_rcf(to, ModelKind::kMesh3d, nullptr));
  std::set<OpId> xa(a.x.begin(), a.x.end()), xb(b.x.begin(), b.x.end());
  std::vector<OpId> added, removed;
  for (OpId id : b.x) {
    if (!xa.count(id)) added.push_back(id);
  }
  for (OpId id : a.x) {
    if (!xb.count(id)) removed.push_back(id);
  }
  const auto in_union = [&](OpId id) { return xa.count(id) != 0 || xb.count(id) != 0; };
  const MorphMesh morph = mesh_morph(m, in_union, added, removed);
  EXPECT_EQ(morph.inexact_vertices, 0u);
  const Change c = change(a, b);
  for (int side = 0; side < 2; ++side) {
    std::vector<Triangle3> expected, images;
    for (TriRef t : side == 0 ? c.out : c.in) expected.push_back(corners(m, t));
    for (const auto& tri : morph.triangles) {
      const Triangle3 p{morph.at(tri[0], side), morph.at(tri[1], side), morph.at(tri[2], side)};
      if (p[0] != p[1] && p[1] != p[2] && p[2] != p[0]) images.push_back(p);
    }
    const auto e = sorted_triangles(expected), g = sorted_triangles(images);
    EXPECT_EQ(e.size(), g.size()) << "at t = " << side;
    EXPECT_TRUE(e == g) << "the morph at t = " << side << " is not the "
                        << (side == 0 ? "first" : "second") << " mesh's changed part";
  }
  // Vertices are shared: one per vertex id of the triangles of the union's mesh in the changed
  // ops (which may put two ids at one position: the repaired pig, the elephant's holes), and every
  // directed edge once (oriented incidence, as the cut of the union has it).
  std::set<std::uint64_t> ids;
  std::uint64_t union_triangles = 0;
  for (const auto* list : {&added, &removed}) {
    for (OpId id : *list) {
      const OpRef op = m.op(id);
      for (const FragmentTriangle& t : op->fragment) {
        if (t.killer.valid() && in_union(t.killer)) continue;
        ++union_triangles;
        for (int k = 0; k < 3; ++k) ids.insert(op->vertex_id(t, k).value);
      }
    }
  }
  EXPECT_EQ(morph.start.size(), ids.size());
  EXPECT_EQ(morph.triangles.size(), union_triangles);
  std::set<std::pair<std::uint32_t, std::uint32_t>> edges;
  for (const auto& tri : morph.triangles) {
    for (int k = 0; k < 3; ++k) EXPECT_TRUE(edges.insert({tri[k], tri[(k + 1) % 3]}).second);
  }
  // Orientation between t = 0.5 and t = 1, measured: linear geomorphs of several collapses at
  // once (Hoppe 1997) can fold a triangle whose corners move towards different originators.
  for (const auto& tri : morph.triangles) {
    const auto normal = [&](double t) {
      const Vec3 p = morph.at(tri[0], t), q = morph.at(tri[1], t), r = morph.at(tri[2], t);
      return glm::cross(q - p, r - p);
    };
    const Vec3 half = normal(0.5), one = normal(1.0);
    if (glm::length(one) == 0.0 || glm::length(half) == 0.0) continue;
    int moving = 0;
    for (std::uint32_t v : tri) moving += morph.start[v] != morph.end[v];
    ++flips.triangles;
    if (glm::dot(half, one) > 0.0) continue;
    ++flips.flips;
    flips.one_moving += moving == 1;
  }
}

class MeshMorph : public ::testing::TestWithParam<std::string> {};

TEST_P(MeshMorph, CollapsesToTheOldMeshAtZeroAndTheNewAtOne) {
  const Crmr& m = test::built_mesh(GetParam()).crmr;
  const auto spread = test::mesh_rcf_spread(m.header);
  const std::vector<std::pair<std::string, std::string>> pairs = {
      {"floor 0.300000", "floor 0.600000"},
      {"floor 0.900000", "floor 0.000000"},
      {"gaussian volume", "ball"},
      {"camera 0 at 3.000000 radii, 2.000000 px", "camera 1 at 3.000000 radii, 2.000000 px"},
      {"camera 2 at 1.200000 radii, 0.500000 px", "gaussian volume over floor 0.4"}};
  FlipCount flips;
  for (const auto& [from, to] : pairs) {
    SCOPED_TRACE(GetParam() + ": " + from + " -> " + to);
    expect_mesh_morph(m, spec_named(spread, from), spec_named(spread, to), flips);
  }
  std::printf(
      "  %s: %llu of %llu triangles turn their normal over between t = 0.5 and 1 (%llu with one "
      "moving corner)\n",
      GetParam().c_str(), static_cast<unsigned long long>(flips.flips),
      static_cast<unsigned long long>(flips.triangles),
      static_cast<unsigned long long>(flips.one_moving));
}

std::vector<std::string> meshes() {
  std::vector<std::string> m = {"blobby_3cc.off", "elephant-with-holes.off", "mech-holes-shark.off",
                                "pig.stl"};
  if (!test::kSanitized) m.push_back("ChineseDragon-10kv.off");
  return m;
}

INSTANTIATE_TEST_SUITE_P(CgalMeshes, MeshMorph, ::testing::ValuesIn(meshes()),
                         [](const ::testing::TestParamInfo<std::string>& p) {
                           std::string n = p.param.substr(0, p.param.find('.'));
                           std::replace(n.begin(), n.end(), '-', '_');
                           return n;
                         });

}  // namespace
}  // namespace smr

namespace smr {
namespace {

// Speed, not asserted (run with --gtest_also_run_disabled_tests and SMRDB_MORPH_BENCH_DB set to a
// terrain database, e.g. benchmarks' fbm4097_seed1_e1.6.smrdb): the morph between the 1 px cuts of
// two cameras, the second moved a quarter of the domain (a jump). Prints one JSON line.
TEST(MorphSpeed, DISABLED_TerrainCameraJump) {
  const char* path = std::getenv("SMRDB_MORPH_BENCH_DB");
  ASSERT_NE(path, nullptr) << "set SMRDB_MORPH_BENCH_DB to a terrain database";
  const auto db = Database::open(path, {.cache_bytes = std::size_t{512} << 20});
  const Box3& b = db->info().bounds;
  const double w = b.hi.x - b.lo.x, h = b.hi.y - b.lo.y, zr = std::max(1.0, b.hi.z - b.lo.z);
  const auto cut = [&](double shift) {
    RcfSpec s;
    Camera cam;
    cam.eye = {b.lo.x + (0.2 + shift) * w, b.lo.y + 0.2 * h, b.hi.z + 0.3 * zr};
    cam.target = {cam.eye.x + 0.3 * w, cam.eye.y + 0.5 * h, b.lo.z};
    cam.viewport_w = 1920;
    cam.viewport_h = 1080;
    s.camera = cam;
    s.pixel_error = 1.0;
    return extract_minimal_surface(*db, make_rcf(s, ModelKind::kTerrain, nullptr));
  };
  const Change c = change(cut(0.0), cut(0.25));
  double best = std::numeric_limits<double>::infinity();
  MorphMesh morph;
  for (int run = 0; run < 3; ++run) {
    const auto t0 = std::chrono::steady_clock::now();
    morph = terrain_morph(*db, c.out, c.in);
    best = std::min(best,
                    std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  }
  std::printf(
      "{\"out\": %zu, \"in\": %zu, \"pieces\": %zu, \"vertices\": %zu, \"groups\": %u, "
      "\"seconds\": %.4f, \"pieces_per_second\": %.0f, \"changed_triangles_per_second\": %.0f}\n",
      c.out.size(), c.in.size(), morph.triangles.size(), morph.start.size(), morph.groups, best,
      double(morph.triangles.size()) / best, double(c.out.size() + c.in.size()) / best);
}

}  // namespace
}  // namespace smr
