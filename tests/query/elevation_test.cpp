// Elevation queries (smr/query/elevation.h) against brute force on the source rasters: at every
// grid sample of real DEMs the answer lies within its stated bound of the sample (0 for a lossless
// build), between samples it equals the finest TIN, no-data samples answer "no data", and a
// database answers as the CRMR it was written from.
#include <gtest/gtest.h>

#include <random>

#include "base/error.h"
#include "smr/builders/terrain/greedy_tin.h"
#include "smr/query/elevation.h"
#include "smr/query/indexed_source.h"
#include "tests/query/written_database.h"
#include "tests/support/datasets.h"
#include "tests/support/oracles.h"

namespace smr::query {
namespace {

using test::dataset;
using test::dataset_names;

Vec2 grid_point(const Heightfield& dem, int col, int row) {
  return {dem.georef.x0 + col * dem.georef.dx, dem.georef.y0 + row * dem.georef.dy};
}

// Heights are float32 samples; a lossless build reproduces them to float rounding.
double tolerance(const Heightfield& dem, double bound) {
  return bound + 1e-6 * std::max(1.0, std::abs(double(dem.z.empty() ? 0.0f : dem.z[0]))) + 1e-4;
}

// Every grid sample: within the stated bound; no-data samples answer "no data".
// Whether some data triangle of the finest mesh of `m` contains p (brute force).
bool finest_data_triangle_contains(const Crmr& m, const Vec2& p) {
  for (const TriRef& r : test::finest_mesh(m)) {
    const OpRef op = m.op(r.op);
    const FragmentTriangle& t = op->fragment[r.index];
    if (t.is_void()) continue;
    const Vec2 a = xy(op->position(t, 0)), b = xy(op->position(t, 1)), c = xy(op->position(t, 2));
    if (std::min({orient2d(p, b, c), orient2d(a, p, c), orient2d(a, b, p)}) >= 0.0) return true;
  }
  return false;
}

// Every grid sample: within the stated bound; no-data samples answer "no data". A valid sample
// that no data triangle of the finest TIN covers (an isolated sample between no-data cells: the
// TIN has no surface there) answers "no data" too, which `crmr` (when given) confirms.
void expect_samples_within_bound(const OpSource& source, const Heightfield& dem,
                                 const Accuracy& acc, double z_slack, const Crmr* crmr = nullptr) {
  const ElevationQuery q(source);
  std::uint64_t checked = 0, nodata = 0, uncovered = 0;
  for (int row = 0; row < dem.height; ++row) {
    for (int col = 0; col < dem.width; ++col) {
      const ElevationAnswer a = q.at(grid_point(dem, col, row), acc);
      if (!dem.has_data(col, row)) {
        EXPECT_FALSE(a.has_data) << dem.source << " (" << col << "," << row << ") has no data";
        ++nodata;
        continue;
      }
      if (!a.has_data) {
        ASSERT_TRUE(a.final) << dem.source << " (" << col << "," << row << ")";
        if (crmr != nullptr) {
          ASSERT_FALSE(finest_data_triangle_contains(*crmr, grid_point(dem, col, row)))
              << dem.source << " (" << col << "," << row << ") answered no data";
        }
        ++uncovered;
        continue;
      }
      if (acc.max_error) {
        ASSERT_LE(a.error_bound, *acc.max_error);
      }
      const double dev = std::abs(a.z - double(dem.at(col, row)));
      ASSERT_LE(dev, tolerance(dem, a.error_bound) + z_slack)
          << dem.source << " (" << col << "," << row << ") z " << a.z << " sample "
          << dem.at(col, row) << " bound " << a.error_bound;
      ++checked;
    }
  }
  EXPECT_GT(checked, 0u);
  EXPECT_LE(uncovered * 100, checked) << dem.source << ": too many valid samples without a surface";
  if (dem.has_nodata()) {
    EXPECT_GT(nodata, 0u) << dem.source;
  }
}

class ElevationOnDem : public ::testing::TestWithParam<std::string> {};

TEST_P(ElevationOnDem, EverySampleLiesWithinTheStatedBound) {
  const test::Dataset& d = dataset(GetParam());
  expect_samples_within_bound(d.crmr, d.dem, Accuracy::finest(), 0.0, &d.crmr);
  for (double e : {d.max_error * 4, d.max_error * 16}) {
    SCOPED_TRACE("max error " + std::to_string(e));
    expect_samples_within_bound(d.crmr, d.dem, Accuracy::within(e), 0.0);
  }
}

// A lossless build answers every sample exactly (bound 0), so the descent reaches the source.
TEST_P(ElevationOnDem, LosslessBuildAnswersEverySampleExactly) {
  const Heightfield& dem = test::dem(GetParam());
  if (dem.sample_count() > 70'000) GTEST_SKIP() << "large DEM: covered by the lossy build";
  const Crmr m = build_greedy_tin(dem, {});
  ASSERT_EQ(m.info().err_final, 0.0);
  expect_samples_within_bound(m, dem, Accuracy::finest(), 0.0, &m);
  const ElevationAnswer a =
      ElevationQuery(m).at(grid_point(dem, dem.width / 3, dem.height / 2), Accuracy::finest());
  EXPECT_EQ(a.error_bound, 0.0);
  EXPECT_TRUE(a.final);
}

// Between samples the answer is the finest TIN's height, found by brute force over its triangles.
TEST_P(ElevationOnDem, BetweenSamplesItIsTheFinestTin) {
  const test::Dataset& d = dataset(GetParam());
  const std::vector<TriRef> finest = test::finest_mesh(d.crmr);
  const Domain dom = terrain_domain(d.crmr.info());
  const ElevationQuery q(d.crmr);
  std::mt19937_64 rng(36);
  std::uniform_real_distribution<double> ux(dom.lo.x, dom.hi.x), uy(dom.lo.y, dom.hi.y);
  for (int i = 0; i < 300; ++i) {
    const Vec2 p{ux(rng), uy(rng)};
    const ElevationAnswer a = q.at(p, Accuracy::finest());
    ASSERT_TRUE(a.final);
    // Brute force: every finest triangle containing p gives the same height.
    bool found = false;
    for (const TriRef& r : finest) {
      const OpRef op = d.crmr.op(r.op);
      const FragmentTriangle& t = op->fragment[r.index];
      const Triangle3 v = corners(*op, t);
      const Vec2 a2 = xy(v[0]), b2 = xy(v[1]), c2 = xy(v[2]);
      const double area = orient2d(a2, b2, c2);
      const double s =
          std::min({orient2d(p, b2, c2), orient2d(a2, p, c2), orient2d(a2, b2, p)}) / area;
      if (s < -1e-12) continue;
      found = true;
      EXPECT_EQ(a.has_data, !t.is_void());
      if (!t.is_void() && a.has_data) {
        EXPECT_NEAR(a.z, interpolate(v, p), 1e-9 * (1.0 + std::abs(a.z))) << p.x << "," << p.y;
      }
    }
    ASSERT_TRUE(found) << "no finest triangle contains " << p.x << "," << p.y;
  }
}

INSTANTIATE_TEST_SUITE_P(Dems, ElevationOnDem, ::testing::ValuesIn(dataset_names()));

TEST(Elevation, PointsOutsideTheDomainAreRefusedWithTheExtent) {
  const test::Dataset& d = dataset("fbm129");
  const ElevationQuery q(d.crmr);
  const Domain dom = q.domain();
  for (const Vec2& p : {Vec2{dom.lo.x - 1.0, dom.lo.y}, Vec2{dom.hi.x, dom.hi.y + 1e-3},
                        Vec2{std::nan(""), dom.lo.y}}) {
    try {
      q.at(p, Accuracy::finest());
      ADD_FAILURE() << "no error for " << p.x << "," << p.y;
    } catch (const Error& e) {
      EXPECT_EQ(e.kind(), ErrorKind::kInvalidInput);
      EXPECT_NE(std::string(e.what()).find("outside the database's domain"), std::string::npos)
          << e.what();
    }
  }
  // The corners themselves are inside.
  EXPECT_TRUE(q.at(dom.lo, Accuracy::finest()).has_data);
  EXPECT_TRUE(q.at(dom.hi, Accuracy::finest()).has_data);
}

// A coarser accuracy reads fewer ops and keeps its bound.
TEST(Elevation, ACoarserAccuracyStopsEarlier) {
  const test::Dataset& d = dataset("jacksboro");
  const ElevationQuery q(d.crmr);
  const Domain dom = q.domain();
  std::uint64_t fine_ops = 0, coarse_ops = 0;
  for (int i = 0; i < 50; ++i) {
    const Vec2 p = dom.lo + (dom.hi - dom.lo) * Vec2{(i % 7 + 0.5) / 7.0, (i / 7 + 0.5) / 8.0};
    fine_ops += q.at(p, Accuracy::finest()).ops_read;
    const ElevationAnswer c = q.at(p, Accuracy::within(20.0));
    EXPECT_LE(c.error_bound, 20.0);
    coarse_ops += c.ops_read;
  }
  EXPECT_LT(coarse_ops, fine_ops);
}

// Written to disk and read through the page cache and index, the answers do not change (heights
// up to the database's z quantum).
TEST(Elevation, ADatabaseAnswersAsTheCrmr) {
  const test::Dataset& d = dataset("elev");
  const test::WrittenDatabase written(d.crmr);
  const IndexedSource& src = written.source();
  const ElevationQuery disk(src), memory(d.crmr);
  for (int row = 0; row < d.dem.height; row += 3) {
    for (int col = 0; col < d.dem.width; col += 2) {
      const Vec2 p = grid_point(d.dem, col, row);
      const ElevationAnswer a = disk.at(p, Accuracy::finest());
      const ElevationAnswer b = memory.at(p, Accuracy::finest());
      ASSERT_EQ(a.has_data, b.has_data);
      EXPECT_EQ(a.triangle, b.triangle);
      EXPECT_GE(a.error_bound, b.error_bound);  // stored errors only grow
      if (a.has_data) {
        EXPECT_NEAR(a.z, b.z, 1e-3);
      }
    }
  }
  expect_samples_within_bound(src, d.dem, Accuracy::finest(), 1e-3);
}

}  // namespace
}  // namespace smr::query
