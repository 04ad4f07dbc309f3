// Storage rounding (smr/db/quantize.h): pages keep resolutions as 32-bit floats, rounded down, and
// derive errors from them; every bound a database states must stay true after the rounding.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "smr/builders/terrain/block_tin.h"
#include "smr/db/database.h"
#include "smr/db/page.h"
#include "smr/db/quantize.h"
#include "smr/db/tables.h"
#include "smr/db/writer.h"
#include "storage/checksum.h"
#include "storage/lmdb_env.h"
#include "tests/support/datasets.h"
#include "tests/support/files.h"

namespace smr {
namespace {

TEST(StoredResolution, RoundsDownToAFloatAndKeepsOrder) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::vector<double> rs(100000);
  for (double& r : rs) r = unit(rng);
  rs.push_back(0.0);
  std::sort(rs.begin(), rs.end());
  double prev = 0.0;
  for (const double r : rs) {
    const double s = stored_resolution(r);
    ASSERT_EQ(double(float(s)), s) << r;          // a float
    ASSERT_LE(s, r) << r;                         // never above
    ASSERT_LT(r - s, std::ldexp(1.0, -23)) << r;  // the float just below at worst
    ASSERT_GE(s, prev) << r;                      // monotone
    prev = s;
  }
  for (double exact : {0.0, 1.0, 0.5, 0.25, double(0.1f), double(std::nextafter(1.0f, 0.0f))})
    EXPECT_EQ(stored_resolution(exact), exact);
  EXPECT_EQ(stored_resolution(double(0.1f) + 1e-12), double(0.1f));
  EXPECT_EQ(stored_resolution(double(0.1f) - 1e-12), double(std::nextafter(0.1f, 0.0f)));
}

// A database written from a real DEM: every op's stored birth_res and every triangle's death_res
// is at most the builder's, by less than a float step, and every stored error at least the
// builder's: a triangle reads at least its true error, so no bound of the source is lost.
TEST(StoredResolution, DatabasesOnlyGrowErrors) {
  for (const char* name : {"topobathy", "elev"}) {
    const test::Dataset& d = test::dataset(name);
    const Crmr exact = d.crmr;
    Crmr m = d.crmr;
    test::TempDir dir("smrdb-quantize-test");
    const std::string path = dir.file("x.smrdb");
    write_database(m, path, {});
    const auto db = Database::open(path, {});
    ASSERT_EQ(db->op_count(), exact.ops.size());
    std::size_t rounded = 0;
    for (const Op& e : exact.ops) {
      const OpRef got = db->op(e.id);
      ASSERT_LE(got->birth_res, e.birth_res) << name << " op " << e.id.value;
      ASSERT_LT(e.birth_res - got->birth_res, std::ldexp(1.0, -23)) << name;
      // Up to the rounding of the error <-> resolution map itself (1e-12 of err0, as the
      // invariants allow): ops at resolution 0 or 1 are floats already and keep their error.
      const double noise = 1e-12 * exact.header.err0;
      ASSERT_GE(got->error, e.error - noise) << name << " op " << e.id.value;
      ASSERT_GE(db->error_at(got->birth_res), e.error - noise) << name << " op " << e.id.value;
      rounded += got->birth_res != e.birth_res;
      ASSERT_EQ(got->fragment.size(), e.fragment.size());
      for (std::size_t i = 0; i < e.fragment.size(); ++i) {
        ASSERT_LE(got->fragment[i].death_res, e.fragment[i].death_res) << name;
        ASSERT_GE(db->error_at(got->fragment[i].death_res),
                  exact.error_at(e.fragment[i].death_res) - noise)
            << name << " op " << e.id.value << " triangle " << i;
      }
    }
    EXPECT_GT(rounded, exact.ops.size() / 2) << name << ": the rounding is exercised";
  }
}

// Terrain vertices are named by their DEM sample (snap_vertices): whichever builder
// made the model (the greedy TIN, the block builder), every vertex of every stored op of a real
// DEM's database is row * width + col of its grid position and lies at that sample's height, and
// the pages derive the ids instead of storing them (each page's vertex id stream is the code and
// the width: a couple of bytes).
// Stored ROIs (quantize.h, stored_roi): each margin outside the op's box a multiple of
// 2^roi_shift grid steps, the ROI holding the true one, stored ROIs nesting (a parent's holds its
// children's) and holding every box below, and looser than the exact ROI by at most about the
// op's error; a written database gives them back exactly.
TEST(StoredRoi, MarginsInUnitsOfTheOpsErrorAndNesting) {
  Crmr m = test::dataset("jacksboro").crmr;
  const Crmr truth = m;  // compute_rois' ROIs, before snapping and rounding
  test::TempDir dir("smrdb-quantize-test");
  const WriteReport w = write_database(m, dir.file("x.smrdb"), {});
  std::size_t rounded = 0;
  double worst = 0.0;
  for (const Op& op : m.ops) {
    EXPECT_TRUE(op.roi.contains(op.box)) << op.id.value;
    for (OpId c : op.children) EXPECT_TRUE(op.roi.contains(m.ops[c.value].roi)) << op.id.value;
    const auto blo = w.grid.quantize(op.box.lo), bhi = w.grid.quantize(op.box.hi);
    const auto rlo = w.grid.quantize(op.roi.lo), rhi = w.grid.quantize(op.roi.hi);
    const Box3& exact = truth.ops[op.id.value].roi;
    for (int k = 0; k < 3; ++k) {
      const std::int64_t unit = std::int64_t{1} << roi_shift(op.error, w.grid.step[k]);
      EXPECT_EQ((std::int64_t(blo[k]) - rlo[k]) % unit, 0) << op.id.value;
      EXPECT_EQ((std::int64_t(rhi[k]) - bhi[k]) % unit, 0) << op.id.value;
      rounded += unit > 1;
      // Looser than the exact ROI by the roundings of this op and its descendants (each less
      // than an eighth of its own error, smaller down the DAG), the snapping aside.
      const double loose = std::max(exact.lo[k] - op.roi.lo[k], op.roi.hi[k] - exact.hi[k]);
      worst = std::max(worst, (loose - 2 * w.z_shift) / op.error);
    }
  }
  EXPECT_GT(rounded, m.ops.size() / 2) << "the z margins of most ops are in units above a step";
  std::printf("stored ROIs: at most %.3f of the op's error looser than the exact ones\n", worst);
  EXPECT_LT(worst, 1.5);  // measured 1.0: roundings add up along chains of like errors
  const auto db = Database::open(dir.file("x.smrdb"), {});
  for (const Op& op : m.ops) EXPECT_EQ(db->op(op.id)->roi, op.roi) << op.id.value;
}

// A DEM built to an error e takes the largest power of two within e / 32 as its z step and is
// built half a step below e (quantize.h): the step is exact, within (e/64, e/32], and the split
// never lets a snapped height pass e.
TEST(ErrorZQuantum, APowerOfTwoWithinAThirtySecondOfTheError) {
  EXPECT_EQ(error_z_quantum(1.6), 0.03125);
  EXPECT_EQ(error_z_quantum(1.0), 0.03125);
  EXPECT_EQ(error_z_quantum(std::nextafter(1.0, 0.0)), 0.015625);
  for (double bad : {0.0, -1.0, std::numeric_limits<double>::infinity(),
                     std::numeric_limits<double>::quiet_NaN()})
    EXPECT_EQ(error_z_quantum(bad), 0.0) << bad;
  EXPECT_EQ(error_z_quantum(std::numeric_limits<double>::denorm_min()), 0.0);  // lossless
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> octave(-20.0, 20.0);
  for (int i = 0; i < 10000; ++i) {
    const double e = std::exp2(octave(rng));
    const double q = error_z_quantum(e);
    int exponent = 0;
    ASSERT_EQ(std::frexp(q, &exponent), 0.5) << e;  // a power of two
    ASSERT_LE(q, e / 32.0) << e;
    ASSERT_GT(q, e / 64.0) << e;
    const TerrainErrorSplit split = split_terrain_error(e, 0.0);
    ASSERT_EQ(split.error_quantum, q);
    ASSERT_LE(split.build_error + q / 2.0, e) << e;  // the largest snap, added back
    ASSERT_GT(split.build_error, 0.98 * e) << e;
  }
  // Heights on the step do not move: the build keeps the whole error, the step is the same.
  const TerrainErrorSplit on_step = split_terrain_error(1.6, 0.0, true);
  EXPECT_EQ(on_step.build_error, 1.6);
  EXPECT_EQ(on_step.error_quantum, 0.03125);
  // A step given on the command line is taken as it is, and the build keeps the whole error.
  const TerrainErrorSplit given = split_terrain_error(1.6, 0.5);
  EXPECT_EQ(given.build_error, 1.6);
  EXPECT_EQ(given.error_quantum, 0.0);
}

TEST(ErrorZQuantum, TheGridTakesItUnlessTheRangeNeedsACoarserStep) {
  CrmrInfo info;
  info.kind = ModelKind::kTerrain;
  info.georef.dx = info.georef.dy = 1.0;
  info.bounds.add(Vec3(0.0, 0.0, -100.0));
  info.bounds.add(Vec3(10.0, 10.0, 1500.0));
  EXPECT_EQ(choose_grid(info, 0.0, 0.0).step.z, std::exp2(-14));  // range / 2^24
  EXPECT_EQ(choose_grid(info, 0.0, 0.03125).step.z, 0.03125);
  EXPECT_EQ(choose_grid(info, 0.0, std::exp2(-16)).step.z, std::exp2(-16));  // finer than 2^24
  // 1600 / 2^30 rounded up to a power of two: at most 2^30 steps over the range.
  EXPECT_EQ(choose_grid(info, 0.0, std::exp2(-40)).step.z, std::exp2(-19));
  EXPECT_EQ(choose_grid(info, 0.25, 0.03125).step.z, 0.25);  // a step given wins
}

TEST(TerrainVertexIds, AreTheDemSampleIndices) {
  for (const char* name : {"jacksboro", "elev"}) {
    const test::Dataset& d = test::dataset(name);
    BlockTinOptions bo;
    bo.block_cells = 32;
    bo.max_error = d.max_error;
    const HeightfieldWindows windows(d.dem);
    for (const auto& [builder, model] :
         {std::pair{"greedy", d.crmr}, {"blocks", build_block_tin(windows, bo)}}) {
      test::TempDir dir("smrdb-quantize-test");
      const std::string path = dir.file("x.smrdb");
      Crmr m = model;
      write_database(m, path, {});
      const auto db = Database::open(path, {});
      const QuantGrid& grid = db->grid();
      const auto width = std::uint64_t(d.dem.width);
      std::size_t checked = 0;
      for (std::uint64_t p = 0; p < db->page_count(); ++p) {
        for (const OpView& op : db->page(p)->ops()) {
          for (std::size_t i = 0; i < op.own_vertex_count(); ++i) {
            const Vertex& v = op.own_vertex(i);
            const auto q = grid.quantize(v.p);
            ASSERT_EQ(v.id.value, std::uint64_t(q[1]) * width + std::uint64_t(q[0]))
                << name << " " << builder << " op " << op.id.value;
            if (!d.dem.has_data(q[0], q[1])) continue;
            const Vec3 sample = d.dem.world(q[0], q[1]);
            ASSERT_EQ(v.p.z, grid.dequantize(grid.quantize(sample))[2]) << name << " " << builder;
            ++checked;
          }
        }
      }
      EXPECT_GT(checked, db->op_count()) << name << " " << builder;
      const storage::Env env = storage::Env::open_read_only(path, kTableNames);
      const storage::ReadTxn txn = env.read();
      txn.for_each(Table::kPages, [&](storage::ByteView, storage::ByteView value) {
        for (const auto& [stream, bytes] :
             page_record_streams(page_payload(value, "pages", "page"), "page")) {
          if (stream == "vertex_ids") {
            EXPECT_LE(bytes.size(), 6u) << name;
          }
        }
      });
    }
  }
}

}  // namespace
}  // namespace smr
