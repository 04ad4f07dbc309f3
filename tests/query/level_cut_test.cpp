// The constant-level cut (smr/query/level_cut.h) against the general path it replaces for a
// constant --floor: AddToList (Brown 5.1.1) and the set formula (Lemma 5.1.1) through the R-tree,
// then to_mesh. Oracle: the same triangles (positions exact, each with its death_res), the same
// |X|, on real DEMs and real meshes, at levels spread over [0, 1] and at the ops' own birth_res
// (ties, where meets_level's >= decides) and just beside them. A database with void triangles
// (elev.tif's no-data) is refused by the cut (nullopt): the closed form of X does not hold there.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <optional>
#include <string>
#include <tuple>
#include <vector>

#include "smr/db/database.h"
#include "smr/extract/extract.h"
#include "smr/query/level_cut.h"
#include "smr/rcf/spec.h"
#include "tests/query/written_database.h"
#include "tests/support/datasets.h"
#include "tests/support/meshes.h"
#include "tests/support/sanitized.h"

namespace smr {
namespace {

using Corner = std::array<double, 3>;
using Tri = std::tuple<Corner, Corner, Corner, float>;

// A mesh's triangles as position triples (each rotated to start at its least corner) with their
// value, sorted: equal for meshes with the same triangles in any order and numbering.
std::vector<Tri> canonical(const TriangleMesh& m) {
  EXPECT_EQ(m.triangle_values.size(), m.triangles.size());
  std::vector<Tri> out;
  for (std::size_t i = 0; i < m.triangles.size(); ++i) {
    std::array<Corner, 3> c;
    for (int k = 0; k < 3; ++k) {
      const Vec3& p = m.positions[m.triangles[i][k]];
      c[k] = {p.x, p.y, p.z};
    }
    std::rotate(c.begin(), std::min_element(c.begin(), c.end()), c.end());
    out.emplace_back(c[0], c[1], c[2], m.triangle_values[i]);
  }
  std::sort(out.begin(), out.end());
  return out;
}

bool has_void_triangle(const Crmr& crmr) {
  for (const Op& op : crmr.ops) {
    for (const FragmentTriangle& t : op.fragment)
      if (t.is_void()) return true;
  }
  return false;
}

// Levels over [0, 1], and the birth_res of a spread of ops with the floats on either side.
std::vector<double> levels_of(const Database& db) {
  std::vector<double> levels{0.0, 0.05, 0.25, 0.5, 0.75, 0.9, 0.99, 0.999, 1.0};
  const std::uint64_t n = db.op_count();
  for (std::uint64_t i = 1; i < 6; ++i) {
    const double r = db.op(OpId{i * (n - 1) / 6})->birth_res;
    for (double l :
         {r, double(std::nextafter(float(r), 0.0f)), double(std::nextafter(float(r), 2.0f))})
      if (l >= 0.0 && l <= 1.0) levels.push_back(l);
  }
  return levels;
}

// The general path's mesh for `level`: what smrdb extract gave before the cut.
std::pair<TriangleMesh, std::uint64_t> general(const test::WrittenDatabase& w, double level) {
  RcfSpec spec;
  spec.floor = level;
  const Rcf rcf = make_rcf(spec, w.database().info(), nullptr);
  const Extraction e = extract_minimal_surface(w.source(), rcf, {.fronts = false});
  return {to_mesh(w.source(), e.triangles), e.x.size()};
}

void expect_cut_is_the_minimal_surface(const Crmr& crmr, const std::string& name) {
  SCOPED_TRACE(name);
  const test::WrittenDatabase w(crmr);
  const Database& db = w.database();
  const bool voids = has_void_triangle(crmr);
  for (double level : levels_of(db)) {
    SCOPED_TRACE("level " + std::to_string(level));
    LevelCutStats stats;
    const std::optional<TriangleMesh> cut = extract_level_cut(db, level, {.threads = 2}, &stats);
    if (voids) {
      // A cut that reads only void-free pages may still answer; it must then be right.
      if (!cut) continue;
    } else {
      ASSERT_TRUE(cut.has_value());
    }
    const auto [mesh, x] = general(w, level);
    EXPECT_EQ(stats.x, x);
    EXPECT_EQ(stats.triangles, cut->triangles.size());
    EXPECT_EQ(canonical(*cut), canonical(mesh));
    EXPECT_EQ(cut->positions.size(), mesh.positions.size());
    EXPECT_LE(stats.pages, db.page_count());
  }
}

TEST(LevelCut, IsTheMinimalSurfaceOnEveryDem) {
  for (const std::string& name : test::dataset_names())
    expect_cut_is_the_minimal_surface(test::dataset(name).crmr, name);
}

TEST(LevelCut, IsTheMinimalSurfaceOnRealMeshes) {
  const std::vector<std::string> meshes =
      test::kSanitized
          ? std::vector<std::string>{"fandisk.off"}
          : std::vector<std::string>{"bunny00.off", "fandisk.off", "elephant-with-holes.off"};
  for (const std::string& name : meshes)
    expect_cut_is_the_minimal_surface(test::built_mesh(name).crmr, name);
}

TEST(LevelCut, FullResolutionIsTheSourceMesh) {
  const test::BuiltMesh& m = test::built_mesh("fandisk.off");
  const test::WrittenDatabase w(m.crmr);
  const std::optional<TriangleMesh> cut = extract_level_cut(w.database(), 1.0);
  ASSERT_TRUE(cut.has_value());
  ASSERT_EQ(cut->triangles.size(), m.source.triangles.size());
  TriangleMesh source = m.source;
  source.triangle_values.assign(source.triangles.size(), 1.0f);  // never replaced
  // The database's positions are the source's on its quantization grid.
  const QuantGrid& g = w.database().grid();
  for (Vec3& p : source.positions) p = g.dequantize(g.quantize(p));
  EXPECT_EQ(canonical(*cut), canonical(source));
}

TEST(LevelCut, ReadsOnlyThePagesOfX) {
  const test::WrittenDatabase w(test::dataset("fbm129").crmr);
  const Database& db = w.database();
  LevelCutStats coarse, full;
  ASSERT_TRUE(extract_level_cut(db, 0.5, {}, &coarse));
  ASSERT_TRUE(extract_level_cut(db, 1.0, {}, &full));
  EXPECT_EQ(full.pages, db.page_count());
  EXPECT_EQ(full.x, db.op_count());
  EXPECT_LT(coarse.pages, full.pages / 2);
  EXPECT_LT(coarse.x, full.x);
}

TEST(LevelCut, TheThreadCountChangesNothing) {
  const test::WrittenDatabase w(test::dataset("jacksboro").crmr);
  for (double level : {0.99, 1.0}) {
    LevelCutStats stats;
    const std::optional<TriangleMesh> one =
        extract_level_cut(w.database(), level, {.threads = 1}, &stats);
    ASSERT_TRUE(one.has_value());
    EXPECT_GT(stats.pages, 16u) << "more pages than two threads' first items";
    for (unsigned threads : {2u, 3u}) {
      const std::optional<TriangleMesh> more =
          extract_level_cut(w.database(), level, {.threads = threads});
      ASSERT_TRUE(more.has_value());
      EXPECT_EQ(more->positions, one->positions);
      EXPECT_EQ(more->triangles, one->triangles);
      EXPECT_EQ(more->triangle_values, one->triangle_values);
    }
  }
}

TEST(LevelCut, NoDataDemsTakeTheGeneralPath) {
  const Crmr& crmr = test::dataset("elev").crmr;
  ASSERT_TRUE(has_void_triangle(crmr)) << "elev.tif is expected to have no-data";
  const test::WrittenDatabase w(crmr);
  LevelCutStats stats;
  EXPECT_FALSE(extract_level_cut(w.database(), 1.0, {}, &stats).has_value());
  EXPECT_TRUE(stats.voids);
  EXPECT_FALSE(stats.over_budget);
}

TEST(LevelCut, StopsPastMaxTriangles) {
  const test::WrittenDatabase w(test::dataset("fbm129").crmr);
  LevelCutStats all, capped;
  const std::optional<TriangleMesh> mesh = extract_level_cut(w.database(), 1.0, {}, &all);
  ASSERT_TRUE(mesh.has_value());
  const std::uint64_t n = mesh->triangles.size();
  EXPECT_TRUE(extract_level_cut(w.database(), 1.0, {.max_triangles = n}).has_value());
  EXPECT_FALSE(extract_level_cut(w.database(), 1.0, {.max_triangles = n / 3}, &capped));
  EXPECT_TRUE(capped.over_budget);
  EXPECT_FALSE(capped.voids);
  EXPECT_GT(capped.triangles, n / 3);
  EXPECT_LT(capped.pages, all.pages);  // it stopped early
}

TEST(LevelCut, OnlyAConstantLevelAloneIsOne) {
  RcfSpec spec;
  EXPECT_FALSE(constant_level(spec));
  spec.floor = 0.4;
  EXPECT_EQ(constant_level(spec), 0.4);
  spec.aois.push_back({});
  EXPECT_FALSE(constant_level(spec));
  spec.aois.clear();
  // Every other term of a spec makes it not a constant level.
  const std::vector<void (*)(RcfSpec&)> terms = {
      [](RcfSpec& s) { s.camera = Camera{}; },
      [](RcfSpec& s) { s.pixel_error = 1.0; },
      [](RcfSpec& s) { s.screen_aoi = ScreenAoi{}; },
      [](RcfSpec& s) { s.discs.push_back({}); },
      [](RcfSpec& s) { s.volumes.push_back({}); },
      [](RcfSpec& s) { s.frustum_level = 0.5; },
      [](RcfSpec& s) {
        s.centre_cone = std::pair{10.0, 0.5};
      },
      [](RcfSpec& s) { s.critical_level = 0.5; },
  };
  for (const auto& add : terms) {
    RcfSpec with = spec;
    add(with);
    EXPECT_FALSE(constant_level(with));
  }
  EXPECT_EQ(constant_level(spec), 0.4);
}

}  // namespace
}  // namespace smr
