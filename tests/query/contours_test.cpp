// Contour queries (smr/query/contours.h) against brute force and against GDAL: at the finest
// accuracy the lines are exactly the finest mesh's contours (every triangle that matters was
// found); within an error they are exactly the refined mesh's, each line's bound covers the
// triangles it crosses and every source sample under them lies within it; lines are rings or end
// on the domain boundary or a no-data hole; gdal_contour's lines on the same raster lie within a
// cell of ours (Hausdorff, both ways); the GeoJSON records the CRS as GDAL does.
#include "smr/query/contours.h"

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <cmath>
#include <map>
#include <random>
#include <set>
#include <sstream>
#include <unordered_map>

#include "base/error.h"
#include "smr/builders/mesh/qem_pm.h"
#include "smr/builders/terrain/greedy_tin.h"
#include "smr/io/gdal_raster.h"
#include "smr/query/geojson.h"
#include "smr/query/indexed_source.h"
#include "tests/query/written_database.h"
#include "tests/support/datasets.h"
#include "tests/support/files.h"
#include "tests/support/oracles.h"
#include "tests/support/process.h"
#include "tests/support/test_data.h"

namespace smr::query {
namespace {

using test::dataset;
using test::dataset_names;
using Seg = std::array<double, 5>;                               // level, from x, y, to x, y
using Lines = std::map<double, std::vector<std::vector<Vec2>>>;  // by level

Seg seg(double h, const Vec2& a, const Vec2& b) {
  return {h, a.x, a.y, b.x, b.y};
}

std::pair<double, double> data_range(const Heightfield& dem) {
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (int row = 0; row < dem.height; ++row) {
    for (int col = 0; col < dem.width; ++col) {
      if (!dem.has_data(col, row)) continue;
      lo = std::min(lo, double(dem.at(col, row)));
      hi = std::max(hi, double(dem.at(col, row)));
    }
  }
  return {lo, hi};
}

// Levels that catch the edge cases: a sample's own height, an integer (jacksboro is integer data,
// so many samples lie exactly on it), an arbitrary height, the highest and the lowest sample.
std::vector<double> test_levels(const Heightfield& dem) {
  const auto [lo, hi] = data_range(dem);
  int col = dem.width / 2, row = dem.height / 2;
  while (!dem.has_data(col, row)) col = (col + 1) % dem.width;
  return {double(dem.at(col, row)), std::round(lo + 0.3 * (hi - lo)), lo + 0.55 * (hi - lo), hi,
          lo};
}

// The levels of every(interval, base) between lo and hi, listed.
std::vector<double> interval_levels(double interval, double base, double lo, double hi) {
  std::vector<double> out;
  for (auto k = static_cast<std::int64_t>(std::floor((lo - base) / interval)) - 1;
       base + double(k) * interval <= hi; ++k) {
    if (base + double(k) * interval >= lo) out.push_back(base + double(k) * interval);
  }
  return out;
}

// The segments of positive length of the lines.
std::vector<Seg> segments_of(const ContourResult& r) {
  std::vector<Seg> out;
  for (const ContourLine& l : r.lines) {
    for (std::size_t i = 0; i + 1 < l.points.size(); ++i)
      if (l.points[i] != l.points[i + 1]) out.push_back(seg(l.level, l.points[i], l.points[i + 1]));
  }
  std::sort(out.begin(), out.end());
  return out;
}

// A segment of the brute force and the error of the triangle it cuts.
struct Cut {
  Seg s;
  double error = 0.0;
  TriRef triangle;
  friend bool operator<(const Cut& x, const Cut& y) { return x.s < y.s; }
};

// Brute force: every data triangle of the list cut by each level (a corner at h counts as above),
// the crossing on each edge interpolated from its corner below, the segment turned so that the
// triangle's gradient points to its left. Sorted.
std::vector<Cut> mesh_contours(const OpSource& src, std::span<const TriRef> triangles,
                               std::span<const double> levels) {
  std::vector<Cut> out;
  for (const TriRef& r : triangles) {
    const OpRef op = src.op(r.op);
    const FragmentTriangle& t = op->triangle(r.index);
    if (t.is_void()) continue;
    const Triangle3 v = corners(*op, t);
    const Vec3 n = glm::cross(v[1] - v[0], v[2] - v[0]);
    const Vec2 gradient{-n.x / n.z, -n.y / n.z};
    for (const double h : levels) {
      std::vector<Vec2> cut;
      for (int i = 0; i < 3; ++i) {
        Vec3 u = v[std::size_t(i)], w = v[std::size_t((i + 1) % 3)];
        if ((u.z >= h) == (w.z >= h)) continue;
        if (u.z >= h) std::swap(u, w);
        cut.push_back(xy(u) + (h - u.z) / (w.z - u.z) * (xy(w) - xy(u)));
      }
      if (cut.size() != 2) continue;
      const Vec2 d = cut[1] - cut[0];
      if (glm::dot(gradient, Vec2{-d.y, d.x}) < 0.0) std::swap(cut[0], cut[1]);
      out.push_back({seg(h, cut[0], cut[1]), triangle_error(src, t), r});
    }
  }
  std::sort(out.begin(), out.end());
  return out;
}

// The segments of positive length (the query writes a repeated point once, except in a line
// that is a single point).
std::vector<Seg> segments_only(std::span<const Cut> cuts) {
  std::vector<Seg> out;
  for (const Cut& c : cuts)
    if (c.s[1] != c.s[3] || c.s[2] != c.s[4]) out.push_back(c.s);
  return out;
}

void expect_same_segments(const std::vector<Seg>& got, const std::vector<Seg>& want) {
  EXPECT_EQ(got.size(), want.size());
  const auto [g, w] = std::mismatch(got.begin(), got.end(), want.begin(), want.end());
  if (g != got.end() || w != want.end()) {
    const Seg& s = g != got.end() ? *g : *w;
    ADD_FAILURE() << "first difference at level " << s[0] << " near (" << s[1] << ", " << s[2]
                  << ") in the " << (g != got.end() ? "query's" : "brute force's") << " segments";
  }
}

bool near(double a, double b) {
  return std::abs(a - b) <= 1e-9 * std::max(1.0, std::abs(b));
}

double distance_to_segment(const Vec2& p, const Vec2& a, const Vec2& b) {
  const Vec2 d = b - a;
  const double len2 = glm::dot(d, d);
  const double t = len2 == 0.0 ? 0.0 : std::clamp(glm::dot(p - a, d) / len2, 0.0, 1.0);
  return glm::length(p - (a + t * d));
}

// The edges of the void triangles of the mesh the query refines to.
std::vector<std::array<Vec2, 2>> void_edges(const OpSource& src, const ContourOptions& o) {
  const Extraction e =
      refine(src, std::make_shared<const LevelsRegion>(levels_region(o)), o.accuracy);
  std::vector<std::array<Vec2, 2>> out;
  for (const TriRef& r : e.triangles) {
    const OpRef op = src.op(r.op);
    const FragmentTriangle& t = op->triangle(r.index);
    if (!t.is_void()) continue;
    for (int k = 0; k < 3; ++k)
      out.push_back({xy(op->position(t, k)), xy(op->position(t, (k + 1) % 3))});
  }
  return out;
}

bool ends_legally(const Vec2& p, const Domain& dom, std::span<const std::array<Vec2, 2>> voids) {
  if (near(p.x, dom.lo.x) || near(p.x, dom.hi.x) || near(p.y, dom.lo.y) || near(p.y, dom.hi.y))
    return true;
  const double tol = 1e-9 * std::max({1.0, std::abs(p.x), std::abs(p.y)});
  return std::any_of(voids.begin(), voids.end(), [&](const std::array<Vec2, 2>& e) {
    return distance_to_segment(p, e[0], e[1]) <= tol;
  });
}

// Rings close bit for bit, open lines end on the domain boundary or a void triangle, no segment is
// used twice in the same direction (a ridge at exactly h is run along both ways), no point
// repeats the one before, lines come by level and the stats count what is there.
void expect_well_formed(const OpSource& src, const ContourResult& r, const ContourOptions& o) {
  const auto voids = void_edges(src, o);
  const Domain dom = terrain_domain(src.info());
  std::set<Seg> seen;
  std::uint64_t rings = 0, points = 0;
  for (const ContourLine& l : r.lines) {
    ASSERT_GE(l.points.size(), 2u);
    if (l.closed) {
      EXPECT_EQ(l.points.front(), l.points.back()) << "level " << l.level;
    }
    rings += l.closed ? 1 : 0;
    points += l.points.size();
    for (std::size_t i = 0; i + 1 < l.points.size(); ++i) {
      const Vec2 &a = l.points[i], &b = l.points[i + 1];
      EXPECT_TRUE(a != b || l.points.size() == 2) << "a point repeated at level " << l.level;
      EXPECT_TRUE(seen.insert(seg(l.level, a, b)).second) << "segment used twice";
    }
    if (l.closed) continue;
    for (const Vec2& p : {l.points.front(), l.points.back()}) {
      EXPECT_TRUE(ends_legally(p, dom, voids))
          << "level " << l.level << " ends inside the mesh at (" << p.x << ", " << p.y << ")";
    }
  }
  EXPECT_TRUE(std::is_sorted(r.lines.begin(), r.lines.end(),
                             [](const auto& a, const auto& b) { return a.level < b.level; }));
  EXPECT_EQ(r.stats.polylines, r.lines.size());
  EXPECT_EQ(r.stats.rings, rings);
  EXPECT_EQ(r.stats.points, points);
  EXPECT_GE(r.stats.segments, points - r.lines.size());
}

// The lines are exactly the contours of the mesh the query refines to (brute force over its
// triangles), each line's bound is the largest error of the triangles it cuts, and every source
// sample under those triangles lies within their errors: each line is the exact contour of a
// surface within its bound of the source. (Not: within its bound of the finest TIN between
// samples. The finest triangles under a coarse one do not nest in it, since an op retriangulates
// its whole PreF, so the TIN there interpolates samples the coarse triangle's bound says nothing
// about; a lossless topobathy build shows 48 m against a bound of 34 m.)
void expect_contours_of_refined_mesh(const OpSource& src, const Heightfield& dem,
                                     const ContourOptions& o, const ContourResult& r,
                                     std::span<const double> levels) {
  const Extraction e =
      refine(src, std::make_shared<const LevelsRegion>(levels_region(o)), o.accuracy);
  const std::vector<Cut> cuts = mesh_contours(src, e.triangles, levels);
  expect_same_segments(segments_of(r), segments_only(cuts));
  for (const ContourLine& l : r.lines) {
    double most = 0.0;
    for (std::size_t i = 0; i + 1 < l.points.size(); ++i) {
      const Cut key{seg(l.level, l.points[i], l.points[i + 1]), 0.0, {}};
      const auto c = std::lower_bound(cuts.begin(), cuts.end(), key);
      if (c != cuts.end() && c->s == key.s) most = std::max(most, c->error);
    }
    EXPECT_GE(l.error, most) << "level " << l.level;
  }
  std::vector<TriRef> cut;
  for (const Cut& c : cuts) cut.push_back(c.triangle);
  const test::OracleResult bound = test::check_error_bound(src, cut, dem);
  EXPECT_TRUE(bound.ok()) << bound.first_failure;
  EXPECT_GT(bound.checked, 0u);
}

class ContoursOnDem : public ::testing::TestWithParam<std::string> {};

// The refinement found every finest triangle a level crosses: the query's segments are the finest
// mesh's, for explicit levels (sample heights included) and for an interval.
TEST_P(ContoursOnDem, AtTheFinestAccuracyTheyAreTheFinestMeshsContours) {
  const test::Dataset& d = dataset(GetParam());
  ContourOptions o;
  o.levels = test_levels(d.dem);
  const ContourResult r = contours(d.crmr, o);
  const std::vector<TriRef> finest = test::finest_mesh(d.crmr);
  expect_same_segments(segments_of(r), segments_only(mesh_contours(d.crmr, finest, o.levels)));
  EXPECT_GT(r.stats.segments, 0u);
  const Box3& b = d.crmr.info().bounds;
  const std::set<double> in_range(o.levels.begin(), o.levels.end());
  EXPECT_EQ(r.stats.levels, std::count_if(in_range.begin(), in_range.end(),
                                          [&](double h) { return h >= b.lo.z && h <= b.hi.z; }));
  for (const ContourLine& l : r.lines) EXPECT_EQ(l.error, d.crmr.info().err_final);
  expect_well_formed(d.crmr, r, o);
  // One level needs only the ops whose triangles' error bands reach it.
  ContourOptions one;
  one.levels = {o.levels[0]};
  const ContourResult r1 = contours(d.crmr, one);
  expect_same_segments(segments_of(r1), segments_only(mesh_contours(d.crmr, finest, one.levels)));
  EXPECT_LT(r1.stats.ops, d.crmr.op_count());

  const auto [lo, hi] = data_range(d.dem);
  ContourOptions every;
  every.interval = (hi - lo) / 7.3;
  every.base = lo + 0.1;
  const ContourResult ri = contours(d.crmr, every);
  const auto levels = interval_levels(*every.interval, every.base, lo, hi);
  expect_same_segments(segments_of(ri), segments_only(mesh_contours(d.crmr, finest, levels)));
  expect_well_formed(d.crmr, ri, every);
}

// Within an error, the lines are the contours of a surface within their bounds of the source, the
// bounds are within the error asked, and the answer is coarser than the finest one.
TEST_P(ContoursOnDem, WithinAnErrorTheBoundHoldsAgainstTheSource) {
  const test::Dataset& d = dataset(GetParam());
  const auto [lo, hi] = data_range(d.dem);
  ContourOptions o;
  o.interval = (hi - lo) / 9.0;
  const auto levels = interval_levels(*o.interval, 0.0, lo, hi);
  const ContourResult finest = contours(d.crmr, o);
  for (const double e : {d.max_error * 4, d.max_error * 16}) {
    SCOPED_TRACE("max error " + std::to_string(e));
    o.accuracy = Accuracy::within(e);
    const ContourResult r = contours(d.crmr, o);
    expect_well_formed(d.crmr, r, o);
    expect_contours_of_refined_mesh(d.crmr, d.dem, o, r, levels);
    for (const ContourLine& l : r.lines) EXPECT_LE(l.error, std::max(e, d.crmr.info().err_final));
    EXPECT_LT(r.stats.points, finest.stats.points);
    EXPECT_LT(r.stats.ops, finest.stats.ops);
  }
}

// On a lossless build the finest lines carry bound 0, and coarser ones hold theirs.
TEST_P(ContoursOnDem, OnALosslessBuildTheFinestBoundIsZero) {
  const Heightfield& dem = test::dem(GetParam());
  if (dem.sample_count() > 70'000) GTEST_SKIP() << "large DEM: covered by the lossy build";
  const Crmr m = build_greedy_tin(dem, {});
  const auto [lo, hi] = data_range(dem);
  ContourOptions o;
  o.interval = (hi - lo) / 6.0;
  const auto levels = interval_levels(*o.interval, 0.0, lo, hi);
  const ContourResult finest = contours(m, o);
  ASSERT_FALSE(finest.lines.empty());
  for (const ContourLine& l : finest.lines) EXPECT_EQ(l.error, 0.0);
  expect_contours_of_refined_mesh(m, dem, o, finest, levels);
  o.accuracy = Accuracy::within((hi - lo) / 100.0);
  const ContourResult r = contours(m, o);
  expect_well_formed(m, r, o);
  expect_contours_of_refined_mesh(m, dem, o, r, levels);
  EXPECT_LT(r.stats.points, finest.stats.points);
}

INSTANTIATE_TEST_SUITE_P(Dems, ContoursOnDem, ::testing::ValuesIn(dataset_names()));

// --- Against GDAL ----------------------------------------------------------------------------

bool have_gdal_contour() {
  return test::run_command("command -v gdal_contour").code == 0;
}

Lines read_lines(const nlohmann::json& fc, const char* level_key) {
  Lines out;
  for (const auto& f : fc.at("features")) {
    std::vector<Vec2>& line = out[f.at("properties").at(level_key).get<double>()].emplace_back();
    for (const auto& c : f.at("geometry").at("coordinates"))
      line.push_back({c.at(0).get<double>(), c.at(1).get<double>()});
  }
  return out;
}

Lines lines_by_level(const ContourResult& r) {
  Lines out;
  for (const ContourLine& l : r.lines) out[l.level].push_back(l.points);
  return out;
}

nlohmann::json run_gdal_contour(const std::string& tif, double interval, const test::TempDir& dir) {
  const std::string out = dir.file("gdal.geojson");
  std::filesystem::remove(out);
  std::ostringstream cmd;
  cmd.precision(17);
  cmd << "gdal_contour -q -a elev -i " << interval << " -f GeoJSON '" << tif << "' '" << out << "'";
  const test::CommandResult res = test::run_command(cmd.str());
  if (res.code != 0) throw std::runtime_error(cmd.str() + " failed: " + res.out);
  return nlohmann::json::parse(test::read_file(out));
}

// Segments of `lines` bucketed by cells of side `cell`, for "is one within `cell` of p".
class SegmentGrid {
 public:
  SegmentGrid(const std::vector<std::vector<Vec2>>& lines, double cell) : cell_(cell) {
    for (const auto& l : lines) {
      for (std::size_t i = 0; i + 1 < l.size(); ++i) {
        const Vec2 lo = glm::min(l[i], l[i + 1]), hi = glm::max(l[i], l[i + 1]);
        for (auto x = key(lo.x); x <= key(hi.x); ++x)
          for (auto y = key(lo.y); y <= key(hi.y); ++y)
            cells_[pack(x, y)].push_back({l[i], l[i + 1]});
      }
    }
  }
  // The distance from p to the nearest segment, if one lies within `cell`; else infinity.
  double nearest(const Vec2& p) const {
    double best = std::numeric_limits<double>::infinity();
    for (auto x = key(p.x) - 1; x <= key(p.x) + 1; ++x) {
      for (auto y = key(p.y) - 1; y <= key(p.y) + 1; ++y) {
        const auto it = cells_.find(pack(x, y));
        if (it == cells_.end()) continue;
        for (const auto& s : it->second) best = std::min(best, distance_to_segment(p, s[0], s[1]));
      }
    }
    return best;
  }

 private:
  std::int64_t key(double v) const { return static_cast<std::int64_t>(std::floor(v / cell_)); }
  static std::int64_t pack(std::int64_t x, std::int64_t y) { return x * 1'000'003 + y; }
  double cell_;
  std::unordered_map<std::int64_t, std::vector<std::array<Vec2, 2>>> cells_;
};

// Whether p lies in (or on the border of) a grid cell with a no-data corner. GDAL cuts such cells
// at their centre (marching squares' sub-squares) while a data triangle of the TIN, which covers
// no no-data sample, may still cross the cell and bridge the hole: the lines are not comparable.
bool beside_no_data(const Heightfield& dem, const Vec2& p) {
  if (!dem.has_nodata()) return false;
  const Vec2 g = dem.to_grid(p);
  const int c0 = std::max(0, int(std::floor(g.x - 1e-9))),
            c1 = std::min(dem.width - 1, int(std::ceil(g.x + 1e-9)));
  const int r0 = std::max(0, int(std::floor(g.y - 1e-9))),
            r1 = std::min(dem.height - 1, int(std::ceil(g.y + 1e-9)));
  for (int row = r0; row <= r1; ++row)
    for (int col = c0; col <= c1; ++col)
      if (!dem.has_data(col, row)) return true;
  return false;
}

// The largest distance from a vertex or segment midpoint of `from` (not beside no data) to the
// lines `to` (infinity when one lies farther than `cell` from all of them), and the point that
// has it.
std::pair<double, Vec2> directed_hausdorff(const std::vector<std::vector<Vec2>>& from,
                                           const std::vector<std::vector<Vec2>>& to, double cell,
                                           const Heightfield& dem) {
  const SegmentGrid grid(to, cell);
  std::pair<double, Vec2> worst{0.0, Vec2{0.0}};
  const auto visit = [&](const Vec2& p) {
    if (beside_no_data(dem, p)) return;
    const double d = grid.nearest(p);
    if (d > worst.first) worst = {d, p};
  };
  for (const auto& l : from) {
    for (std::size_t i = 0; i < l.size(); ++i) {
      visit(l[i]);
      if (i + 1 < l.size()) visit(0.5 * (l[i] + l[i + 1]));
    }
  }
  return worst;
}

// gdal_contour -i D on the source GeoTIFF and our lossless contours at the same interval: the
// same levels, and each set of lines within one cell diagonal of the other (Hausdorff both
// ways). GDAL samples pixel centres, which are smrdb's sample positions (dem_reader.h: x0 is the
// centre of pixel 0; write_geotiff puts pixel centres on the samples), so no offset is applied.
// The lines differ inside a cell only: GDAL splits the square of four samples at its centre
// (marching squares), the TIN along its own diagonals. Cells beside no data are left out.
void expect_like_gdal(const std::string& tif, const Heightfield& dem, double interval) {
  test::TempDir dir("contours-gdal");
  const Lines theirs = read_lines(run_gdal_contour(tif, interval, dir), "elev");
  ContourOptions o;
  o.interval = interval;
  const Lines ours = lines_by_level(contours(build_greedy_tin(dem, {}), o));
  std::vector<double> our_levels, their_levels;
  for (const auto& [h, l] : ours) our_levels.push_back(h);
  for (const auto& [h, l] : theirs) their_levels.push_back(h);
  EXPECT_EQ(our_levels, their_levels);
  const double diagonal = std::hypot(dem.georef.dx, dem.georef.dy);
  double worst = 0.0;
  for (const auto& [h, lines] : ours) {
    if (!theirs.contains(h)) continue;
    const auto [there, p] = directed_hausdorff(lines, theirs.at(h), diagonal, dem);
    const auto [back, q] = directed_hausdorff(theirs.at(h), lines, diagonal, dem);
    EXPECT_LE(there, diagonal * (1 + 1e-9)) << "level " << h << ": ours at " << p.x << ", " << p.y;
    EXPECT_LE(back, diagonal * (1 + 1e-9)) << "level " << h << ": GDAL's at " << q.x << ", " << q.y;
    worst = std::max({worst, there, back});
  }
  std::printf("%s: %zu levels, Hausdorff distance to gdal_contour %.3f cell diagonals\n",
              dem.source.c_str(), ours.size(), worst / diagonal);
}

TEST(ContoursAgainstGdal, ElevTifAtFiftyMetres) {
  if (!have_gdal_contour()) GTEST_SKIP() << "gdal_contour is not installed (Debian: gdal-bin)";
  expect_like_gdal(test::data_path("elev.tif"), test::dem("elev"), 50.0);
}

TEST(ContoursAgainstGdal, DemsWrittenAsGeoTiff) {
  if (!have_gdal_contour()) GTEST_SKIP() << "gdal_contour is not installed (Debian: gdal-bin)";
  for (const std::string name : {"topobathy", "fbm129", "jacksboro"}) {
    SCOPED_TRACE(name);
    const Heightfield& dem = test::dem(name);
    if (dem.sample_count() > 150'000) continue;
    test::TempDir dir("contours-tif");
    const std::string tif = dir.file(name + ".tif");
    write_geotiff(tif, dem);
    const auto [lo, hi] = data_range(dem);
    expect_like_gdal(tif, dem, std::round((hi - lo) / 8.0));
  }
}

// --- GeoJSON ----------------------------------------------------------------------------------

constexpr const char* kUtm15Wkt1 =
    R"(PROJCS["WGS 84 / UTM zone 15N",GEOGCS["WGS 84",DATUM["WGS_1984",SPHEROID["WGS 84",6378137,)"
    R"(298.257223563,AUTHORITY["EPSG","7030"]],AUTHORITY["EPSG","6326"]],PRIMEM["Greenwich",0,)"
    R"(AUTHORITY["EPSG","8901"]],UNIT["degree",0.0174532925199433,AUTHORITY["EPSG","9122"]],)"
    R"(AUTHORITY["EPSG","4326"]],PROJECTION["Transverse_Mercator"],PARAMETER["latitude_of_origin",)"
    R"(0],PARAMETER["central_meridian",-93],PARAMETER["scale_factor",0.9996],PARAMETER[)"
    R"("false_easting",500000],PARAMETER["false_northing",0],UNIT["metre",1,AUTHORITY["EPSG",)"
    R"("9001"]],AXIS["Easting",EAST],AXIS["Northing",NORTH],AUTHORITY["EPSG","32615"]])";

TEST(ContoursGeoJson, RoundTripsEveryLineWithItsLevelAndBound) {
  const test::Dataset& d = dataset("elev");
  ContourOptions o;
  o.interval = 50.0;
  o.accuracy = Accuracy::within(8.0);
  const ContourResult r = contours(d.crmr, o);
  std::ostringstream os;
  write_geojson(os, r, d.crmr.info().georef);
  const nlohmann::json j = nlohmann::json::parse(os.str());
  EXPECT_EQ(j.at("type"), "FeatureCollection");
  EXPECT_EQ(j.at("crs").at("properties").at("name"), "urn:ogc:def:crs:OGC:1.3:CRS84");
  EXPECT_EQ(j.at("crs_wkt"), d.crmr.info().georef.crs_wkt);
  ASSERT_EQ(j.at("features").size(), r.lines.size());
  for (std::size_t i = 0; i < r.lines.size(); ++i) {
    const auto& f = j.at("features")[i];
    EXPECT_EQ(f.at("properties").at("elev").get<double>(), r.lines[i].level);
    EXPECT_EQ(f.at("properties").at("error").get<double>(), r.lines[i].error);
    EXPECT_EQ(f.at("geometry").at("type"), "LineString");
    const auto& c = f.at("geometry").at("coordinates");
    ASSERT_EQ(c.size(), r.lines[i].points.size());
    for (std::size_t k = 0; k < c.size(); ++k) {
      EXPECT_EQ(c[k][0].get<double>(), r.lines[i].points[k].x);
      EXPECT_EQ(c[k][1].get<double>(), r.lines[i].points[k].y);
    }
  }
}

TEST(ContoursGeoJson, TheCrsMemberIsGdals) {
  EXPECT_EQ(geojson_crs_name(kUtm15Wkt1), "urn:ogc:def:crs:EPSG::32615");
  EXPECT_EQ(geojson_crs_name(R"(PROJCRS["x",BASEGEOGCRS["y",ID["EPSG",4326]],ID["EPSG",32615]])"),
            "urn:ogc:def:crs:EPSG::32615");
  EXPECT_EQ(geojson_crs_name(R"(GEOGCS["y",AUTHORITY["EPSG","4326"]])"),
            "urn:ogc:def:crs:OGC:1.3:CRS84");
  EXPECT_EQ(geojson_crs_name(R"(PROJCS["local",GEOGCS["y",AUTHORITY["EPSG","4326"]]])"), "");
  EXPECT_EQ(geojson_crs_name(R"(PROJCS["a \"]\" b",AUTHORITY["ESRI","102003"]])"), "");
  EXPECT_EQ(geojson_crs_name(""), "");
  if (!have_gdal_contour()) GTEST_SKIP() << "gdal_contour is not installed (Debian: gdal-bin)";
  // GDAL's own GeoJSON for the same rasters: a projected CRS and elev.tif's WGS 84.
  test::TempDir dir("contours-crs");
  Heightfield h = test::dem("fbm129");
  h.georef.crs_wkt = kUtm15Wkt1;
  const std::string tif = dir.file("utm.tif");
  write_geotiff(tif, h);
  for (const auto& [path, georef] :
       {std::pair{tif, h.georef},
        std::pair{test::data_path("elev.tif"), test::dem("elev").georef}}) {
    const nlohmann::json gdal = run_gdal_contour(path, 100.0, dir);
    std::ostringstream os;
    write_geojson(os, ContourResult{}, georef);
    EXPECT_EQ(nlohmann::json::parse(os.str()).at("crs"), gdal.at("crs")) << path;
  }
}

// --- Databases, bad input ---------------------------------------------------------------------

// Through the page cache and the R-tree the lines are the CRMR's (heights up to the z quantum)
// and still join: vertices shared by id across pages decode to the same position.
TEST(Contours, ADatabaseAnswersAsTheCrmr) {
  const test::Dataset& d = dataset("elev");
  const test::WrittenDatabase written(d.crmr);
  const IndexedSource& src = written.source();
  ContourOptions o;
  o.interval = 25.0;
  o.base = 0.5;  // no sample (integer data) on a level: the quantum cannot move one across
  const ContourResult disk = contours(src, o), memory = contours(d.crmr, o);
  expect_well_formed(src, disk, o);
  EXPECT_EQ(disk.stats.segments, memory.stats.segments);
  EXPECT_EQ(disk.stats.rings, memory.stats.rings);
  EXPECT_EQ(disk.lines.size(), memory.lines.size());
  // Stored errors only grow, so a coarse answer may refine a little more than the CRMR's.
  o.accuracy = Accuracy::within(10.0);
  const ContourResult coarse = contours(src, o);
  expect_well_formed(src, coarse, o);
  const auto [lo, hi] = data_range(d.dem);
  expect_contours_of_refined_mesh(src, d.dem, o, coarse, interval_levels(25.0, 0.5, lo, hi));
  EXPECT_LT(coarse.stats.ops, disk.stats.ops);
}

void expect_invalid_input(const OpSource& src, const ContourOptions& o, const std::string& says) {
  try {
    contours(src, o);
    ADD_FAILURE() << "no error; expected one saying '" << says << "'";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kInvalidInput);
    EXPECT_NE(std::string(e.what()).find(says), std::string::npos) << e.what();
  }
}

TEST(Contours, BadOptionsAreRefusedWithAMessage) {
  const Crmr& m = dataset("fbm129").crmr;
  expect_invalid_input(m, {}, "no levels given");
  for (const double bad : {0.0, -5.0, std::nan("")}) {
    ContourOptions o;
    o.interval = bad;
    expect_invalid_input(m, o, "expected a number > 0");
  }
  ContourOptions both;
  both.levels = {10.0};
  both.interval = 5.0;
  expect_invalid_input(m, both, "not both");
  ContourOptions inf;
  inf.levels = {1.0, std::numeric_limits<double>::infinity()};
  expect_invalid_input(m, inf, "not a finite number");
  ContourOptions ok;
  ok.levels = {100.0};
  TriangleMesh octahedron;
  octahedron.positions = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
  octahedron.triangles = {{0, 2, 4}, {2, 1, 4}, {1, 3, 4}, {3, 0, 4},
                          {2, 0, 5}, {1, 2, 5}, {3, 1, 5}, {0, 3, 5}};
  expect_invalid_input(build_qem_pm(octahedron, "octahedron"), ok, "needs a terrain database");
}

// Levels outside the data's range are no error: no lines, and stats.levels says none was in it.
TEST(Contours, LevelsOutsideTheDataGiveNoLines) {
  const Crmr& m = dataset("fbm129").crmr;
  ContourOptions o;
  o.levels = {m.info().bounds.lo.z - 1.0, m.info().bounds.hi.z + 1.0, 1e9};
  const ContourResult r = contours(m, o);
  EXPECT_TRUE(r.lines.empty());
  EXPECT_EQ(r.stats.levels, 0u);
  EXPECT_EQ(r.stats.segments, 0u);
  o.levels.push_back(0.5 * (m.info().bounds.lo.z + m.info().bounds.hi.z));
  EXPECT_EQ(contours(m, o).stats.levels, 1u);
}

// --- The region ---------------------------------------------------------------------------------

// Lookups agree with a scan of the levels, explicit or by interval (negative base, levels on the
// queried heights), and meeting is monotone in the error.
TEST(LevelsRegion, LookupsAgreeWithAScan) {
  const LevelsRegion every = LevelsRegion::every(0.1, -0.35);
  const LevelsRegion at = LevelsRegion::at({3.0, -1.0, 2.5, 3.0, 0.25});
  const std::vector<double> at_levels{-1.0, 0.25, 2.5, 3.0};
  std::mt19937_64 rng(36);
  std::uniform_real_distribution<double> uz(-2.0, 4.0);
  for (int i = 0; i < 2000; ++i) {
    // Every tenth query sits exactly on a level.
    const double z = i % 10 == 0 ? every.level(i / 10 - 60) : uz(rng);
    const std::int64_t k = every.first_at_or_above(z), j = every.first_above(z);
    ASSERT_GE(every.level(k), z);
    ASSERT_LT(every.level(k - 1), z);
    ASSERT_GT(every.level(j), z);
    ASSERT_LE(every.level(j - 1), z);
    const auto count = [&](auto pred) {
      return std::int64_t(std::count_if(at_levels.begin(), at_levels.end(), pred));
    };
    const double za = i % 10 == 0 ? at_levels[std::size_t(i / 10) % 4] : z;
    EXPECT_EQ(at.first_at_or_above(za), count([&](double h) { return h < za; }));
    EXPECT_EQ(at.first_above(za), count([&](double h) { return h <= za; }));
  }
  const Triangle3 t{Vec3{0, 0, 0.31}, Vec3{1, 0, 0.33}, Vec3{0, 1, 0.34}};
  EXPECT_FALSE(every.triangle_meets(t, 0.0));  // levels at 0.25 and 0.35
  EXPECT_TRUE(every.triangle_meets(t, 0.02));
  EXPECT_TRUE(every.triangle_meets(t, 0.5));
  EXPECT_EQ(every.count_in(-0.36, 0.66), 11u);
  Box3 box;
  box.add(Vec3{0, 0, 0.5});
  box.add(Vec3{1, 1, 2.0});
  EXPECT_FALSE(at.box_meets(box, 0.2));
  EXPECT_TRUE(at.box_meets(box, 0.25));
  EXPECT_FALSE(at.box_meets(Box3{}, 100.0));
}

}  // namespace
}  // namespace smr::query
