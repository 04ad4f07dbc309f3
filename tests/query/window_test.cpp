// Window queries (exact selective refinement of a region, Maheshwari et al. 3.2, through
// smr/query/region.h): checked against brute force over the finest mesh with exact integer
// arithmetic on the grid. Every finest triangle meeting the window is in the answer (Maheshwari
// Lemma 1), every answer triangle meeting the window is final (the Fig. 9 caveat: none is left
// coarse) or within the asked error, the answer tiles the domain, it is coarse elsewhere, and a
// database gives the same triangles.
#include <gtest/gtest.h>

#include <random>
#include <set>

#include "smr/core/invariants.h"
#include "smr/query/indexed_source.h"
#include "smr/query/region.h"
#include "tests/query/written_database.h"
#include "tests/support/datasets.h"
#include "tests/support/oracles.h"

namespace smr::query {
namespace {

using test::dataset;

struct GridWindow {
  std::int64_t x0, y0, x1, y1;  // closed, in grid units
};

bool inside(const GridWindow& w, const GridPoint& p) {
  return p.x >= w.x0 && p.x <= w.x1 && p.y >= w.y0 && p.y <= w.y1;
}

// Closed segments ab and cd share a point (exact on integers).
bool segments_meet(const GridPoint& a, const GridPoint& b, const GridPoint& c, const GridPoint& d) {
  const auto sgn = [](std::int64_t v) { return (v > 0) - (v < 0); };
  const int o1 = sgn(orient(a, b, c)), o2 = sgn(orient(a, b, d));
  const int o3 = sgn(orient(c, d, a)), o4 = sgn(orient(c, d, b));
  const auto on = [](const GridPoint& p, const GridPoint& q, const GridPoint& r) {
    return std::min(p.x, q.x) <= r.x && r.x <= std::max(p.x, q.x) && std::min(p.y, q.y) <= r.y &&
           r.y <= std::max(p.y, q.y);
  };
  if (o1 != o2 && o3 != o4) return true;
  return (o1 == 0 && on(a, b, c)) || (o2 == 0 && on(a, b, d)) || (o3 == 0 && on(c, d, a)) ||
         (o4 == 0 && on(c, d, b));
}

// The brute-force oracle: a closed counter-clockwise triangle meets the closed window.
bool meets(const GridTriangle& t, const GridWindow& w) {
  for (const GridPoint& p : t)
    if (inside(w, p)) return true;
  const GridPoint c[4] = {{w.x0, w.y0}, {w.x1, w.y0}, {w.x1, w.y1}, {w.x0, w.y1}};
  for (const GridPoint& p : c) {
    if (orient(t[0], t[1], p) >= 0 && orient(t[1], t[2], p) >= 0 && orient(t[2], t[0], p) >= 0)
      return true;
  }
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 4; ++k)
      if (segments_meet(t[i], t[(i + 1) % 3], c[k], c[(k + 1) % 4])) return true;
  return false;
}

GridTriangle grid_triangle(const OpSource& s, TriRef r) {
  const OpRef op = s.op(r.op);
  const FragmentTriangle& t = op->fragment[r.index];
  return {to_grid(s.info(), op->position(t, 0)), to_grid(s.info(), op->position(t, 1)),
          to_grid(s.info(), op->position(t, 2))};
}

std::shared_ptr<const Region> window_region(const CrmrInfo& info, const GridWindow& w) {
  const Georef& g = info.georef;
  const auto at = [&](std::int64_t x, std::int64_t y) {
    return Vec2{g.x0 + double(x) * g.dx, g.y0 + double(y) * g.dy};
  };
  return std::make_shared<WindowRegion>(at(w.x0, w.y0), at(w.x1, w.y1));
}

std::vector<GridWindow> windows_of(const Heightfield& dem, int count, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<GridWindow> out;
  for (int i = 0; i < count; ++i) {
    const int w = 1 + int(rng() % std::uint64_t(dem.width / 4));
    const int h = int(rng() % std::uint64_t(dem.height / 4));  // 0: a horizontal segment
    const int x = int(rng() % std::uint64_t(dem.width - w)),
              y = int(rng() % std::uint64_t(dem.height - h));
    out.push_back({x, y, x + w, y + h});
  }
  return out;
}

class WindowOnDem : public ::testing::TestWithParam<std::string> {};

TEST_P(WindowOnDem, HoldsEveryFinestTriangleMeetingTheWindowAndNothingCoarseThere) {
  const test::Dataset& d = dataset(GetParam());
  const std::vector<TriRef> finest = test::finest_mesh(d.crmr);
  for (const GridWindow& w : windows_of(d.dem, 12, 3)) {
    SCOPED_TRACE("window " + std::to_string(w.x0) + "," + std::to_string(w.y0) + " .. " +
                 std::to_string(w.x1) + "," + std::to_string(w.y1));
    const Extraction e = refine(d.crmr, window_region(d.crmr.info(), w), Accuracy::finest());
    const InvariantReport tiling = check_tiling(d.crmr, e.triangles);
    EXPECT_TRUE(tiling.ok()) << tiling.summary();
    const std::set<TriRef> got(e.triangles.begin(), e.triangles.end());
    std::uint64_t meeting = 0;
    for (const TriRef& r : finest) {
      if (!meets(grid_triangle(d.crmr, r), w)) continue;
      ++meeting;
      EXPECT_TRUE(got.count(r)) << "finest triangle " << r.op.value << "/" << r.index << " missing";
    }
    EXPECT_GT(meeting, 0u);
    for (const TriRef& r : e.triangles) {
      if (meets(grid_triangle(d.crmr, r), w)) {
        EXPECT_FALSE(d.crmr.triangle(r).killer.valid()) << "coarse triangle meets the window";
      }
    }
    EXPECT_LT(e.triangles.size(), finest.size());  // coarse elsewhere
  }
}

TEST_P(WindowOnDem, WithinAnErrorEveryTriangleMeetingTheWindowHoldsIt) {
  const test::Dataset& d = dataset(GetParam());
  const double E = d.max_error * 5;
  for (const GridWindow& w : windows_of(d.dem, 6, 4)) {
    const Extraction e = refine(d.crmr, window_region(d.crmr.info(), w), Accuracy::within(E));
    const Extraction f = refine(d.crmr, window_region(d.crmr.info(), w), Accuracy::finest());
    EXPECT_TRUE(check_tiling(d.crmr, e.triangles).ok());
    EXPECT_LE(e.triangles.size(), f.triangles.size());
    for (const TriRef& r : e.triangles) {
      if (meets(grid_triangle(d.crmr, r), w)) {
        EXPECT_LE(triangle_error(d.crmr, d.crmr.triangle(r)), E);
      }
    }
    const test::OracleResult bound = test::check_error_bound(d.crmr, e.triangles, d.dem);
    EXPECT_EQ(bound.failures, 0u) << bound.first_failure;
  }
}

INSTANTIATE_TEST_SUITE_P(Dems, WindowOnDem, ::testing::ValuesIn(test::dataset_names()));

// Through the R-tree and the page cache the same triangles come out, reading fewer ops than the
// database holds.
TEST(Window, ADatabaseAnswersAsTheCrmr) {
  const test::Dataset& d = dataset("jacksboro");
  const test::WrittenDatabase written(d.crmr, std::size_t{4} << 20);
  const IndexedSource& src = written.source();
  for (const GridWindow& w : windows_of(d.dem, 5, 5)) {
    const auto region = window_region(d.crmr.info(), w);
    Extraction a = refine(src, region, Accuracy::finest());
    Extraction b = refine(d.crmr, region, Accuracy::finest());
    std::sort(a.triangles.begin(), a.triangles.end());
    std::sort(b.triangles.begin(), b.triangles.end());
    EXPECT_EQ(a.triangles, b.triangles);
    EXPECT_LT(a.stats.x, written.database().op_count());
  }
}

}  // namespace
}  // namespace smr::query
