// Data pages fill the LMDB pages they take (issue 34): a value of S bytes takes ceil((S + 16) /
// 4096) 4-KiB overflow pages, so the writer cuts R-tree leaves by encoding their ops and their
// leaf (the value holds both: page.h, PageValue), not by an estimate. Every page's value is at most
// WriteOptions::page_bytes (k * 4096 - 16) unless it holds a single op, and the cut is tight: the
// page with the next op in leaf order added would pass the cap, except at the end of a packing run
// (WriteReport::page_runs) or of max_leaf_entries. The same model gives the same bytes with one
// thread or several.
#include <cstdint>
#include <vector>

#include <gtest/gtest.h>

#include "index/rtree.h"
#include "smr/db/database.h"
#include "smr/db/page.h"
#include "smr/db/tables.h"
#include "smr/db/writer.h"
#include "storage/checksum.h"
#include "storage/lmdb_env.h"
#include "tests/support/datasets.h"
#include "tests/support/files.h"
#include "tests/support/meshes.h"

namespace smr {
namespace {

struct Fill {
  std::uint64_t pages = 0;
  std::uint64_t over = 0;        // values past the cap holding more than one op
  std::uint64_t alone = 0;       // values past the cap holding one op
  std::uint64_t loose = 0;       // pages the next op would still have fitted in
  std::uint64_t lmdb_pages = 0;  // overflow pages the values take
  double mean_value = 0;
};

// `m` as write_database left it (snapped: what the pages hold).
Fill check_fill(const Crmr& m, const std::string& path, const WriteReport& w,
                const WriteOptions& o) {
  std::vector<std::uint64_t> sizes;
  {
    const storage::Env env = storage::Env::open_read_only(path, kTableNames);
    const storage::ReadTxn txn = env.read();
    txn.for_each(Table::kPages, [&](storage::ByteView, storage::ByteView value) {
      sizes.push_back(value.size());
    });
  }
  std::vector<std::vector<const Op*>> pages(sizes.size());
  std::vector<std::vector<index::Entry>> leaves(sizes.size());  // as stored
  {
    const auto db = Database::open(path, {std::size_t{64} << 20});
    for (const Op& op : m.ops) {
      const auto [page, slot] = db->locator(op.id);
      std::vector<const Op*>& p = pages.at(page);
      if (p.size() <= slot) p.resize(slot + 1);
      p[slot] = &op;
    }
    for (std::uint32_t p = 0; p < leaves.size(); ++p) leaves[p] = db->rtree().leaf_entries(p);
  }
  const std::uint64_t seal = storage::seal({}).size();
  const std::uint32_t max_entries = index::BuildOptions{}.max_leaf_entries;
  Fill f;
  f.pages = sizes.size();
  std::uint64_t total = 0;
  for (std::size_t p = 0; p < pages.size(); ++p) {
    total += sizes[p];
    f.lmdb_pages += (sizes[p] + 16 + 4095) / 4096;
    if (sizes[p] > o.page_bytes) ++(pages[p].size() > 1 ? f.over : f.alone);
    if (p + 1 == pages.size() || pages[p].size() >= max_entries) continue;
    std::vector<const Op*> more = pages[p];
    more.push_back(pages[p + 1].front());
    // The value holds the leaf too (PageValue): its size depends on the count and ids alone.
    std::vector<index::Entry> leaf = leaves[p];
    leaf.push_back(leaves[p + 1].front());
    if (encode_page(more, w.grid, o.codec).size() + seal +
            page_value_overhead(index::encode_leaf(leaf).size()) <=
        o.page_bytes)
      ++f.loose;
  }
  f.mean_value = double(total) / double(sizes.size());
  return f;
}

void expect_tight(const Crmr& built, const std::string& name, std::uint32_t page_bytes) {
  Crmr m = built;
  test::TempDir dir("smrdb-page-fill-test");
  WriteOptions o;
  o.page_bytes = page_bytes;
  o.threads = 1;
  const WriteReport w = write_database(m, dir.file("one.smrdb"), o);
  const Fill f = check_fill(m, dir.file("one.smrdb"), w, o);
  std::printf(
      "%s: %llu pages in %llu runs, %llu loose, mean value %.0f bytes (cap %u), %.3f LMDB "
      "pages each, %.2f encodes a page\n",
      name.c_str(), static_cast<unsigned long long>(f.pages),
      static_cast<unsigned long long>(w.page_runs), static_cast<unsigned long long>(f.loose),
      f.mean_value, page_bytes, double(f.lmdb_pages) / double(f.pages),
      double(w.page_encodes) / double(f.pages));
  EXPECT_EQ(f.pages, w.pages);
  EXPECT_EQ(f.over, 0u);
  // Only each run's last page may be loose, and runs are long (64 estimated pages).
  EXPECT_LE(f.loose, w.page_runs - 1);
  EXPECT_LE(w.page_runs, f.pages / 16 + 1);
  EXPECT_GE(f.pages, 20u) << "too few pages to tell";
  // Values fill their k overflow pages: on average within 4 % of k * 4096.
  const std::uint64_t k = (page_bytes + 16 + 4095) / 4096;
  EXPECT_LT(double(f.lmdb_pages) / double(f.pages), double(k) + 0.05);
  EXPECT_GT(f.mean_value, 0.96 * page_bytes);

  // Pages do not depend on the thread count.
  o.threads = 3;
  Crmr again = built;  // write_database snaps the CRMR (and raises its errors) in place
  write_database(again, dir.file("three.smrdb"), o);
  EXPECT_TRUE(test::read_file(dir.file("one.smrdb")) == test::read_file(dir.file("three.smrdb")));
}

TEST(PageFill, TerrainPagesAreCutTightByTheirEncodedSize) {
  expect_tight(test::dataset("jacksboro").crmr, "jacksboro", 16 * 1024 - 16);
}

TEST(PageFill, MeshPagesAreCutTightByTheirEncodedSize) {
  expect_tight(test::built_mesh("ChineseDragon-10kv.off").crmr, "dragon", 16 * 1024 - 16);
}

TEST(PageFill, OneLmdbPagePages) {
  expect_tight(test::dataset("fbm257").crmr, "fbm257", 4096 - 16);
}

// Pages of 400 bytes: the ops that alone pass them get a page each; the others still share pages
// cut tight.
TEST(PageFill, AnOpBiggerThanAPageGetsAPageOfItsOwn) {
  Crmr m = test::dataset("fbm129").crmr;
  test::TempDir dir("smrdb-page-fill-test");
  WriteOptions o;
  o.page_bytes = 400;
  const WriteReport w = write_database(m, dir.file("small.smrdb"), o);
  const Fill f = check_fill(m, dir.file("small.smrdb"), w, o);
  std::printf("fbm129 at %u bytes: %llu pages, %llu of one op past the cap, %llu loose\n",
              o.page_bytes, static_cast<unsigned long long>(f.pages),
              static_cast<unsigned long long>(f.alone), static_cast<unsigned long long>(f.loose));
  EXPECT_EQ(f.over, 0u);
  EXPECT_GT(f.alone, 0u);
  EXPECT_LT(f.alone, f.pages / 2);
  EXPECT_LE(f.loose, w.page_runs - 1);
}

}  // namespace
}  // namespace smr
