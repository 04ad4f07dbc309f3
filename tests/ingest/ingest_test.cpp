// smr/ingest: a MemoryBudget divides into the shares each builder and the writer read, and
// ingest() runs the four builders behind one call, reporting progress and phases in order.
#include "smr/ingest/ingest.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <vector>

#include "base/error.h"
#include "smr/db/database.h"
#include "smr/io/synthetic.h"
#include "tests/support/files.h"

namespace smr {
namespace {

constexpr std::uint64_t MiB = std::uint64_t{1} << 20;

// Without a budget each share is the default of the option field it sets.
TEST(MemoryBudget, NoBudgetGivesTheOptionsDefaults) {
  for (IngestPath path :
       {IngestPath::kQemPm, IngestPath::kBlockPm, IngestPath::kGreedyTin, IngestPath::kBlockTin}) {
    const MemoryShares s = divide({}, path);
    EXPECT_EQ(s.writer_batch_bytes, WriteOptions{}.batch_bytes);
    EXPECT_EQ(s.writer_sort_bytes, WriteOptions{}.sort_bytes);
    EXPECT_EQ(s.record_bytes, 0u) << "no budget, no overrun check";
  }
  const MemoryShares tin = divide({}, IngestPath::kBlockTin);
  EXPECT_EQ(tin.assembly_sort_bytes, BlockTinOptions{}.assembly_sort_bytes);
  EXPECT_EQ(tin.exact_window_samples, BlockTinOptions{}.exact_window_samples);
  EXPECT_EQ(tin.raster_cache_bytes, 0u) << "the reader keeps its own cache";
  const MemoryShares pm = divide({}, IngestPath::kBlockPm);
  EXPECT_EQ(pm.assembly_sort_bytes, BlockPmOptions{}.assembly_sort_bytes);
  EXPECT_EQ(pm.face_sort_bytes, BlockPmOptions{}.face_sort_bytes);
}

// The shares of --memory 64M, as the databases of 9c425f2 were built with them.
TEST(MemoryBudget, SharesOfABudget) {
  const MemoryBudget m{64 * MiB};
  const MemoryShares tin = divide(m, IngestPath::kBlockTin);
  EXPECT_EQ(tin.writer_batch_bytes, 4 * MiB);
  EXPECT_EQ(tin.writer_sort_bytes, 16 * MiB);
  EXPECT_EQ(tin.raster_cache_bytes, 8 * MiB);
  EXPECT_EQ(tin.exact_window_samples, 64 * MiB / 40);
  EXPECT_EQ(tin.assembly_sort_bytes, 32 * MiB);
  EXPECT_EQ(tin.record_bytes, 32 * MiB);
  const MemoryShares pm = divide(m, IngestPath::kBlockPm);
  EXPECT_EQ(pm.writer_batch_bytes, 4 * MiB);
  EXPECT_EQ(pm.writer_sort_bytes, 16 * MiB);
  EXPECT_EQ(pm.face_sort_bytes, 8 * MiB);
  EXPECT_EQ(pm.assembly_sort_bytes, 8 * MiB);
  // A large budget does not widen the exact windows past the option's default.
  EXPECT_EQ(divide({64 << 30}, IngestPath::kBlockTin).exact_window_samples,
            BlockTinOptions{}.exact_window_samples);
  // The in-memory builders hold the whole input: a budget changes none of their shares.
  const MemoryShares greedy = divide(m, IngestPath::kGreedyTin);
  EXPECT_EQ(greedy.writer_batch_bytes, WriteOptions{}.batch_bytes);
  EXPECT_EQ(greedy.writer_sort_bytes, WriteOptions{}.sort_bytes);
}

// What is alive at once while a block builder runs stays within the budget (the writer's sorts
// run after the builder has freed its records).
TEST(MemoryBudget, TheSharesAliveDuringTheBuildFitTheBudget) {
  for (std::uint64_t total : {32 * MiB, 64 * MiB, 1000 * MiB + 7, std::uint64_t{3} << 30}) {
    SCOPED_TRACE(total);
    const MemoryShares tin = divide({total}, IngestPath::kBlockTin);
    EXPECT_LE(tin.writer_batch_bytes + tin.raster_cache_bytes +
                  tin.exact_window_samples * kExactWindowBytesPerSample + tin.assembly_sort_bytes,
              total);
    const MemoryShares pm = divide({total}, IngestPath::kBlockPm);
    EXPECT_LE(pm.writer_batch_bytes + pm.face_sort_bytes + pm.assembly_sort_bytes, total);
    EXPECT_LE(pm.writer_sort_bytes, total);
  }
}

TEST(Ingest, TheBudgetChoosesTheBlockBuilders) {
  IngestOptions o;
  EXPECT_EQ(choose_path("a.tif", o), IngestPath::kGreedyTin);
  EXPECT_EQ(choose_path("a.PLY", o), IngestPath::kQemPm);
  o.memory.total_bytes = 64 * MiB;
  EXPECT_EQ(choose_path("a.tif", o), IngestPath::kBlockTin);
  EXPECT_EQ(choose_path("a.ply", o), IngestPath::kBlockPm);
  o.memory.total_bytes = 0;
  o.builder = IngestBuilder::kBlocks;
  EXPECT_EQ(choose_path("a.npy", o), IngestPath::kBlockTin);
}

// Each path writes a database holding the ops it counted, names its source by file name only,
// reports progress rising to 1 and its two phases in order.
TEST(Ingest, EveryPathWritesTheDatabaseItReports) {
  test::TempDir dir("ingest-test");
  const std::string dem = dir.file("fbm.npy");
  write_npy(dem, make_fbm(65, 65, 3, 100.0));
  // An octahedron, as OFF (read whole) and as PLY (streamed by the block builder).
  const std::string vertices = "1 0 0\n-1 0 0\n0 1 0\n0 -1 0\n0 0 1\n0 0 -1\n";
  const std::string faces =
      "3 0 2 4\n3 2 1 4\n3 1 3 4\n3 3 0 4\n3 2 0 5\n3 1 2 5\n3 3 1 5\n3 0 3 5\n";
  const std::string mesh = dir.file("octahedron.off"), ply = dir.file("octahedron.ply");
  test::write_file(mesh, "OFF\n6 8 0\n" + vertices + faces);
  test::write_file(ply,
                   "ply\nformat ascii 1.0\nelement vertex 6\nproperty float x\nproperty float y\n"
                   "property float z\nelement face 8\nproperty list uchar int vertex_indices\n"
                   "end_header\n" +
                       vertices + faces);
  struct Case {
    std::string input;
    IngestBuilder builder;
    IngestPath path;
  };
  const std::vector<Case> cases = {{dem, IngestBuilder::kInCore, IngestPath::kGreedyTin},
                                   {dem, IngestBuilder::kBlocks, IngestPath::kBlockTin},
                                   {mesh, IngestBuilder::kInCore, IngestPath::kQemPm},
                                   {ply, IngestBuilder::kBlocks, IngestPath::kBlockPm}};
  for (const Case& c : cases) {
    SCOPED_TRACE(int(c.path));
    IngestOptions o;
    o.builder = c.builder;
    const bool is_mesh = c.path == IngestPath::kQemPm || c.path == IngestPath::kBlockPm;
    o.max_error = is_mesh ? 0.0 : 0.5;
    o.block_cells = 16;
    o.verify = true;
    std::vector<double> fractions;
    std::vector<IngestPhase> phases;
    IngestProgress progress;
    progress.fraction = [&](double f) { fractions.push_back(f); };
    progress.phase = [&](IngestPhase p, const IngestReport& r) {
      phases.push_back(p);
      EXPECT_EQ(r.path(), c.path);
      EXPECT_GT(r.crmr.ops, 0u) << "the build is counted before the database is written";
    };
    const std::string db_path = dir.file("out" + std::to_string(int(c.path)) + ".smrdb");
    const IngestReport r = ingest(c.input, db_path, o, progress);
    EXPECT_EQ(r.path(), c.path);
    EXPECT_EQ(phases, (std::vector<IngestPhase>{IngestPhase::kBuilt, IngestPhase::kWritten}));
    ASSERT_FALSE(fractions.empty());
    EXPECT_TRUE(std::is_sorted(fractions.begin(), fractions.end()));
    EXPECT_LE(fractions.back(), 1.0);
    const auto db = Database::open(db_path, {});
    EXPECT_EQ(db->op_count(), r.crmr.ops);
    EXPECT_EQ(db->info().vertex_count, r.crmr.vertices);
    EXPECT_EQ(db->file_bytes(), r.database.file_bytes);
    EXPECT_EQ(db->info().source, std::filesystem::path(c.input).filename().string());
    EXPECT_NE(db->meta_json().find(describe(c.input, o)), std::string::npos)
        << "meta records the build parameters";
    if (!is_mesh) {  // heights at a 32nd of the error, and the error kept (quantize.h)
      EXPECT_EQ(db->grid().step.z, error_z_quantum(o.max_error));
      EXPECT_LE(db->info().err_final, o.max_error);
    }
  }
}

TEST(Ingest, ABudgetNeedsABlockBuilder) {
  test::TempDir dir("ingest-test");
  const std::string dem = dir.file("fbm.npy");
  write_npy(dem, make_fbm(17, 17, 3, 100.0));
  IngestOptions o;
  o.builder = IngestBuilder::kInCore;
  o.memory.total_bytes = 64 * MiB;
  try {
    ingest(dem, dir.file("x.smrdb"), o);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kInvalidInput);
    EXPECT_NE(std::string(e.what()).find("block builder"), std::string::npos) << e.what();
  }
}

TEST(Ingest, DescribeNamesEveryParameterOfThePath) {
  IngestOptions o;
  o.max_error = 0.5;
  o.memory.total_bytes = 64 * MiB;
  o.block_cells = 64;
  EXPECT_EQ(describe("/some/where/fbm513.npy", o),
            "input=fbm513.npy max-error=0.5 max-vertices=0 base-vertices=4 codec=zstd "
            "z-quantum=0 page-kb=12 builder=blocks block-cells=64 memory=67108864");
  IngestOptions m;
  m.allow_self_intersections = true;
  EXPECT_EQ(describe("bunny.off", m),
            "input=bunny.off max-error=0 max-vertices=0 base-vertices=4 codec=zstd z-quantum=0 "
            "page-kb=12 self-intersections=allowed repair=no coalesce=32 coalesce-ratio=0.7");
}

}  // namespace
}  // namespace smr
