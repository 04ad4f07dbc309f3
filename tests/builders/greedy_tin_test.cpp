// The greedy Delaunay-insertion terrain builder (Brown 4.4, 7.1.1;
// smr/builders/terrain/greedy_tin.h): the invariant checker on every build, lossless reproduction,
// the error bound on the finest mesh, determinism, budgets and no-data holes.
#include <gtest/gtest.h>

#include <algorithm>

#include "base/error.h"
#include "smr/builders/terrain/greedy_tin.h"
#include "smr/core/invariants.h"
#include "smr/extract/extract.h"
#include "smr/io/synthetic.h"
#include "tests/support/datasets.h"
#include "tests/support/oracles.h"
#include "tests/support/sanitized.h"

namespace smr {
namespace {

class PerDataset : public ::testing::TestWithParam<std::string> {};

TEST_P(PerDataset, InvariantsHoldAfterBuild) {
  const test::Dataset& d = test::dataset(GetParam());
  const InvariantReport r = check_crmr(d.crmr);
  EXPECT_TRUE(r.ok()) << r.summary();
  EXPECT_GT(d.crmr.ops.size(), 100u);
  EXPECT_GT(r.checked, d.crmr.ops.size());
  EXPECT_LE(d.crmr.header.err_final, d.max_error);
}

TEST_P(PerDataset, FinestMeshMeetsTheStoredErrorBound) {
  const test::Dataset& d = test::dataset(GetParam());
  const auto tris = test::finest_mesh(d.crmr);
  const test::OracleResult r = test::check_error_bound(d.crmr, tris, d.dem);
  EXPECT_TRUE(r.ok()) << r.failures << " samples over the bound; first: " << r.first_failure;
  EXPECT_GT(r.checked, d.dem.sample_count() / 2);
}

TEST_P(PerDataset, EveryExtractedTriangleMeetsItsDeathResolutionsError) {
  // The bound that error_at(death_res) stands for holds for triangles of every resolution, not
  // only the finest: check the whole of M^0..M^m by testing every fragment triangle.
  const test::Dataset& d = test::dataset(GetParam());
  std::vector<TriRef> all;
  for (const Op& op : d.crmr.ops) {
    for (std::uint32_t i = 0; i < op.fragment.size(); i += 3) all.push_back({op.id, i});
  }
  const test::OracleResult r = test::check_error_bound(d.crmr, all, d.dem);
  EXPECT_TRUE(r.ok()) << r.failures << " samples over the bound; first: " << r.first_failure;
}

TEST_P(PerDataset, LosslessBuildReproducesEverySample) {
  const Heightfield& h = test::dem(GetParam());
  GreedyTinOptions opt;
  opt.max_error = 0.0;
  const Crmr m = build_greedy_tin(h, opt);
  EXPECT_EQ(m.header.err_final, 0.0);
  const auto tris = test::finest_mesh(m);
  const test::OracleResult r = test::check_error_bound(m, tris, h);  // bound = error_at(1) = 0
  EXPECT_TRUE(r.ok()) << r.first_failure;
  const InvariantReport inv = check_crmr(m);
  EXPECT_TRUE(inv.ok()) << inv.summary();
  // Every valid sample is covered by a non-void triangle... except no-data islands' neighbours:
  // count coverage and require all samples covered when the DEM has no holes.
  if (!h.has_nodata()) {
    EXPECT_GE(r.checked, h.sample_count());
  }
}

TEST_P(PerDataset, BuildIsDeterministic) {
  const test::Dataset& d = test::dataset(GetParam());
  GreedyTinOptions opt;
  opt.max_error = d.max_error;
  const Crmr again = build_greedy_tin(d.dem, opt);
  ASSERT_EQ(again.ops.size(), d.crmr.ops.size());
  EXPECT_TRUE(again.header == d.crmr.header);
  for (std::size_t i = 0; i < again.ops.size(); ++i) {
    ASSERT_TRUE(again.ops[i] == d.crmr.ops[i]) << "op " << i << " differs";
  }
}

// The mesh-only build (what block_tin's leaves use) is the CRMR's finest mesh, triangle for
// triangle in the ops' order, with the same corners in the same rotation, the same heights and
// the same void flags.
TEST_P(PerDataset, GreedyMeshIsTheFinestMeshOfTheCrmr) {
  const test::Dataset& d = test::dataset(GetParam());
  GreedyTinOptions opt;
  opt.max_error = d.max_error;
  const GreedyMesh mesh = build_greedy_mesh(d.dem, opt);
  std::size_t i = 0;
  for (const Op& op : d.crmr.ops) {
    for (const FragmentTriangle& t : op.fragment) {
      if (t.killer.valid()) continue;
      ASSERT_LT(i, mesh.triangles.size());
      const GreedyMesh::Triangle& m = mesh.triangles[i++];
      EXPECT_EQ(m.is_void, t.is_void()) << "triangle " << i - 1;
      for (int k = 0; k < 3; ++k) {
        const Vertex& want = op.vertices[t.v[k]];
        ASSERT_LT(m.v[k], mesh.vertices.size());
        const GreedyMesh::Vertex& got = mesh.vertices[m.v[k]];
        EXPECT_EQ(m.v[k], want.id.value) << "triangle " << i - 1 << " corner " << k;
        EXPECT_EQ(d.dem.georef.x0 + got.col * d.dem.georef.dx, want.p.x);
        EXPECT_EQ(d.dem.georef.y0 + got.row * d.dem.georef.dy, want.p.y);
        EXPECT_EQ(double(got.z), want.p.z);
      }
    }
  }
  EXPECT_EQ(i, mesh.triangles.size());
  EXPECT_EQ(mesh.vertices.size(), d.crmr.header.vertex_count);
}

INSTANTIATE_TEST_SUITE_P(Dems, PerDataset, ::testing::ValuesIn(test::dataset_names()),
                         [](const auto& p) { return p.param; });

TEST(GreedyTin, BirthResolutionIsMonotoneAndOpsAreSmall) {
  const test::Dataset& d = test::dataset("fbm257");
  std::size_t points = 0;
  for (std::size_t i = 1; i < d.crmr.ops.size(); ++i) {
    EXPECT_LE(d.crmr.ops[i - 1].birth_res, d.crmr.ops[i].birth_res);
    points += d.crmr.ops[i].new_vertex_count;
  }
  // Brown 7.1.1 inserted about two points per op; coalescing must stay local.
  const double per_op = double(points) / double(d.crmr.ops.size() - 1);
  EXPECT_GE(per_op, 1.0);
  EXPECT_LE(per_op, 4.0);
}

TEST(GreedyTin, VertexBudgetStopsTheBuild) {
  const Heightfield& h = test::dem("fbm257");
  GreedyTinOptions opt;
  opt.max_vertices = 500;
  const Crmr m = build_greedy_tin(h, opt);
  EXPECT_GE(m.header.vertex_count, 500u);
  EXPECT_LE(m.header.vertex_count, 520u);
  EXPECT_GT(m.header.err_final, 0.0);
  EXPECT_TRUE(check_crmr(m).ok());
  const test::OracleResult r = test::check_error_bound(m, test::finest_mesh(m), h);
  EXPECT_TRUE(r.ok()) << r.first_failure;
}

TEST(GreedyTin, CoarseBaseMeshOption) {
  const Heightfield& h = test::dem("fbm129");
  GreedyTinOptions opt;
  opt.max_error = 5.0;
  opt.base_vertices = 40;
  const Crmr m = build_greedy_tin(h, opt);
  EXPECT_GE(m.ops[0].vertices.size(), 40u);
  EXPECT_GT(m.ops[0].fragment.size(), 60u);
  EXPECT_TRUE(check_crmr(m).ok());
}

TEST(GreedyTin, NoDataHolesAreTriangulatedExactly) {
  // elev.tif (r-cran-terra) is Luxembourg: the corners and a rim are no data.
  const test::Dataset& d = test::dataset("elev");
  ASSERT_TRUE(d.dem.has_nodata());
  std::uint64_t void_tris = 0, valid_tris = 0;
  for (const TriRef& t : test::finest_mesh(d.crmr)) {
    if (d.crmr.triangle(t).is_void()) {
      ++void_tris;
    } else {
      ++valid_tris;
    }
  }
  EXPECT_GT(void_tris, 0u);
  EXPECT_GT(valid_tris, 1000u);
  // check_error_bound fails on any non-void triangle covering a no-data sample; and at every
  // resolution, not just the finest (no valid triangle ever spans a hole).
  std::vector<TriRef> all;
  for (const Op& op : d.crmr.ops) {
    for (std::uint32_t i = 0; i < op.fragment.size(); ++i) all.push_back({op.id, i});
  }
  const test::OracleResult r = test::check_error_bound(d.crmr, all, d.dem);
  EXPECT_TRUE(r.ok()) << r.first_failure;
}

TEST(GreedyTin, RejectsUnusableInput) {
  Heightfield tiny;
  tiny.width = 1;
  tiny.height = 5;
  tiny.z.assign(5, 1.0f);
  tiny.source = "tiny.npy";
  try {
    build_greedy_tin(tiny);
    FAIL() << "a 1x5 DEM was accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kInvalidInput);
    EXPECT_NE(std::string(e.what()).find("tiny.npy"), std::string::npos);
  }
  Heightfield empty = make_fbm(8, 8, 1);
  empty.valid.assign(empty.z.size(), 0);
  EXPECT_THROW(build_greedy_tin(empty), Error);
}

TEST(GreedyTin, FlatTerrainIsItsBaseMesh) {
  Heightfield flat = make_fbm(33, 17, 3);
  std::fill(flat.z.begin(), flat.z.end(), 12.5f);
  const Crmr m = build_greedy_tin(flat);
  EXPECT_EQ(m.ops.size(), 1u);
  EXPECT_EQ(m.ops[0].fragment.size(), 2u);
  EXPECT_TRUE(check_crmr(m).ok());
}

}  // namespace
}  // namespace smr
