// 3-D meshes through the database: a QEM progressive-mesh CRMR written to disk reads back op for
// op, extraction from disk (through a cache a third of the decoded size) equals extraction in
// memory triangle for triangle for the 3-D RCF spread, outputs stay manifold with the source's
// topology across page boundaries (shared vertices decode bit-identically), and the same mesh
// gives byte-identical files.
#include <algorithm>
#include <cstdio>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "base/error.h"
#include "smr/core/invariants.h"
#include "smr/db/database.h"
#include "smr/db/writer.h"
#include "smr/extract/extract.h"
#include "smr/query/indexed_source.h"
#include "tests/support/files.h"
#include "tests/support/meshes.h"
#include "tests/support/sanitized.h"

namespace smr {
namespace {

class MeshDb : public ::testing::TestWithParam<std::string> {};

TEST_P(MeshDb, ExtractionFromDiskEqualsExtractionInMemory) {
  Crmr m = test::built_mesh(GetParam()).crmr;
  test::TempDir dir("smrdb-mesh-db-test");
  const std::string path = dir.file("mesh.smrdb");
  const WriteReport w = write_database(m, path, {});
  EXPECT_GT(w.pages, 1u);
  EXPECT_LE(w.z_shift, 0.87 * w.grid.step.x);  // at most half a step on each axis
  // Pages are filled greedily in leaf order up to their target payload (WriteOptions::
  // page_bytes, by their encoded size): on average at least half of it, though the last page of
  // each packing run is partial (tests/db/page_fill_test.cpp asks much more).
  const double mean_page = double(w.page_bytes) / double(w.pages);
  std::printf("%s: %llu pages, mean payload %.0f bytes (target %u)\n", GetParam().c_str(),
              static_cast<unsigned long long>(w.pages), mean_page, WriteOptions{}.page_bytes);
  EXPECT_GE(mean_page, 0.5 * WriteOptions{}.page_bytes);
  const InvariantReport inv = check_crmr(m);
  ASSERT_TRUE(inv.ok()) << inv.summary();

  std::size_t decoded = 0;
  {
    const auto whole = Database::open(path, {std::size_t{1} << 30});
    ASSERT_EQ(whole->op_count(), m.ops.size());
    EXPECT_EQ(whole->info(), m.header);
    whole->need_links();  // to_op reads them
    for (const Op& op : m.ops) ASSERT_EQ(to_op(*whole->op(op.id)), op) << "op " << op.id.value;
    decoded = whole->stats().cache.bytes_decoded;
  }
  const auto db = Database::open(path, {decoded / 3});
  const IndexedSource source(*db);
  const SurfaceReport fine = [&] {
    std::vector<TriRef> finest;
    for (const Op& op : m.ops) {
      for (std::uint32_t j = 0; j < op.fragment.size(); ++j) {
        if (!op.fragment[j].killer.valid()) finest.push_back({op.id, j});
      }
    }
    return check_surface(m, finest);
  }();
  for (const test::NamedSpec& ns : test::mesh_rcf_spread(m.header)) {
    SCOPED_TRACE(ns.name);
    const Rcf rcf = make_rcf(ns.spec, ModelKind::kMesh3d, nullptr);
    const Extraction mem = extract_minimal_surface(m, rcf);
    const Extraction disk = extract_minimal_surface(source, rcf);
    EXPECT_EQ(disk.x, mem.x);
    EXPECT_EQ(disk.triangles, mem.triangles);
    const SurfaceReport s = check_surface(*db, disk.triangles);
    EXPECT_TRUE(s.report.ok()) << s.report.summary();
    test::expect_same_topology_or_unspawned(s, fine);
    // No cracks: the output mesh welds by vertex id, and every id has one position.
    const TriangleMesh out = to_mesh(*db, disk.triangles);
    const TriangleMesh ref = to_mesh(m, mem.triangles);
    EXPECT_EQ(out.positions, ref.positions);
    EXPECT_EQ(out.triangles, ref.triangles);
    // The set formula from disk, page by page (extract --order pages): the same triangles.
    const Extraction pages = extract_minimal_surface(source, rcf, {.fronts = false});
    EXPECT_EQ(pages.x, mem.x);
    std::vector<TriRef> a = mem.triangles, b = pages.triangles;
    std::sort(a.begin(), a.end());
    std::sort(b.begin(), b.end());
    EXPECT_EQ(a, b);
  }
  EXPECT_THROW((void)extract_reduced(source, make_rcf({}, ModelKind::kMesh3d, nullptr)), Error);
}

TEST(MeshDb, SameMeshGivesByteIdenticalFiles) {
  test::TempDir dir("smrdb-mesh-db-test");
  Crmr a = test::built_mesh("blobby_3cc.off").crmr;
  Crmr b = test::built_mesh("blobby_3cc.off").crmr;
  write_database(a, dir.file("a.smrdb"), {});
  write_database(b, dir.file("b.smrdb"), {});
  EXPECT_TRUE(test::read_file(dir.file("a.smrdb")) == test::read_file(dir.file("b.smrdb")));
}

// Surface expansion visits X finest first, which crosses each resolution band's pages in no
// spatial order; through a cache smaller than a band every op fetched could decode its page again.
// Held ops (expansion.cpp) and to_mesh's page order read each page of the output about once,
// through a cache a 32nd of the decoded pages.
TEST(MeshDb, AWholeModelCutReadsEachPageAboutOnceThroughASmallCache) {
  // The dragon under the sanitizers: the unheld expansion decodes pages thousands of times.
  const char* name = test::kSanitized ? "ChineseDragon-10kv.off" : "armadillo.off";
  Crmr m = test::built_mesh(name).crmr;
  test::TempDir dir("smrdb-mesh-db-test");
  const std::string path = dir.file("mesh.smrdb");
  WriteOptions wo;
  // The dragon's default pages are ~80, fewer than the unheld expansion needs to show its rereads.
  if (test::kSanitized) wo.page_bytes = 4096 - 16;
  const WriteReport w = write_database(m, path, wo);
  std::size_t decoded = 0;
  {
    const auto whole = Database::open(path, {std::size_t{1} << 30});
    whole->need_links();  // as the expansion below reads them
    for (std::uint64_t p = 0; p < whole->page_count(); ++p) (void)whole->page(p);
    decoded = whole->stats().cache.bytes_decoded;
  }
  RcfSpec all;
  all.floor = 1.0;  // every op: X is the whole DAG, the output the source mesh
  const Rcf rcf = make_rcf(all, ModelKind::kMesh3d, nullptr);
  const std::vector<OpId> x = add_to_list(m, rcf);
  ASSERT_EQ(x.size(), m.ops.size());
  const auto reads = [&](std::uint64_t max_held_bytes) {
    const auto db = Database::open(path, {decoded / 32});
    ExpansionOptions o;
    o.max_held_bytes = max_held_bytes;
    const Extraction e = expand(*db, x, o);
    const std::uint64_t expansion = db->stats().pages_read;
    const TriangleMesh mesh = to_mesh(*db, e.triangles);
    EXPECT_EQ(mesh.triangles.size(), test::built_mesh(name).source.triangles.size());
    return std::pair{expansion, db->stats().pages_read - expansion};
  };
  const auto [expansion, meshing] = reads(ExpansionOptions{}.max_held_bytes);
  EXPECT_LE(expansion, w.pages + w.pages / 10);
  EXPECT_LE(meshing, w.pages + w.pages / 10);
  // Without held ops (none may be copied) the same expansion reads pages again and again.
  const auto [unheld, unused] = reads(0);
  EXPECT_GT(unheld, 2 * w.pages);
  std::printf("pages %llu: expansion reads %llu (%llu unheld), to_mesh %llu\n",
              static_cast<unsigned long long>(w.pages), static_cast<unsigned long long>(expansion),
              static_cast<unsigned long long>(unheld), static_cast<unsigned long long>(meshing));
}

// blobby_3cc: three components, two spawned; elephant-with-holes: boundaries; pig.stl (read
// with the repairs): 17 components, 16 spawned, in 4x the elephant's triangles.
INSTANTIATE_TEST_SUITE_P(CgalMeshes, MeshDb,
                         ::testing::Values("blobby_3cc.off", "elephant-with-holes.off", "pig.stl"),
                         [](const auto& p) {
                           std::string n = p.param;
                           n = n.substr(0, n.find('.'));
                           std::replace(n.begin(), n.end(), '-', '_');
                           return n;
                         });

}  // namespace
}  // namespace smr
