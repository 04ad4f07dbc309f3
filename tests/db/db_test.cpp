// The on-disk database (docs/design.md sections 3, 5, 6; invariant 6): ops read back equal the ops
// built, extraction from disk equals extraction in memory triangle for triangle and meets every
// invariant, no cracks across pages, byte-identical files, atomic creation, the cache budget.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <set>
#include <thread>
#include <tuple>
#include <unordered_map>

#include "base/error.h"
#include "smr/builders/terrain/block_tin.h"
#include "smr/core/invariants.h"
#include "smr/core/parallel.h"
#include "smr/db/database.h"
#include "smr/db/page.h"
#include "smr/db/tables.h"
#include "smr/db/verify.h"
#include "smr/db/writer.h"
#include "smr/extract/extract.h"
#include "smr/query/indexed_source.h"
#include "storage/checksum.h"
#include "storage/lmdb_env.h"
#include "tests/support/datasets.h"
#include "tests/support/files.h"
#include "tests/support/meshes.h"
#include "tests/support/oracles.h"
#include "tests/support/rcf_spread.h"
#include "tests/support/sanitized.h"

namespace smr {
namespace {

namespace fs = std::filesystem;
using test::read_file;

// A scratch directory for this suite.
struct TempDir : test::TempDir {
  TempDir() : test::TempDir("smrdb-db-test") {}
};

// Ops read from disk equal the (quantized) ops in memory, field for field.
void expect_same_ops(const Crmr& m, const Database& db) {
  ASSERT_EQ(db.op_count(), m.ops.size());
  EXPECT_EQ(db.info(), m.header);
  db.need_links();  // to_op reads them
  for (const Op& op : m.ops) {
    const OpRef got = db.op(op.id);
    ASSERT_EQ(to_op(*got), op) << "op " << op.id.value << " differs after the round trip";
  }
}

class PerDataset : public ::testing::TestWithParam<std::string> {};

TEST_P(PerDataset, ExtractionFromDiskEqualsExtractionInMemory) {
  const test::Dataset& d = test::dataset(GetParam());
  Crmr m = d.crmr;
  TempDir dir;
  const std::string path = dir.file("model.smrdb");
  const WriteReport w = write_database(m, path, {});
  EXPECT_GT(w.pages, 1u);
  EXPECT_LE(w.z_shift, w.grid.step.z / 2);
  // Quantization keeps the model valid and its stored errors true bounds.
  const InvariantReport inv = check_crmr(m);
  ASSERT_TRUE(inv.ok()) << inv.summary();

  // Every op read back equals the op built; this also measures the decoded size of all pages.
  std::size_t decoded = 0;
  {
    const auto whole = Database::open(path, {std::size_t{1} << 30});
    expect_same_ops(m, *whole);
    decoded = whole->stats().cache.bytes_decoded;
    EXPECT_EQ(whole->stats().pages_read, w.pages);
  }
  // Then extract through a cache a third of that size, so pages are evicted and read again.
  const std::size_t budget = decoded / 3;
  const auto db = Database::open(path, {budget});
  const IndexedSource source(*db);  // extraction's view: RCF questions go to the R-tree

  const std::vector<test::NamedSpec> spread = test::rcf_spread(m.header);
  for (std::size_t i = 0; i < spread.size(); ++i) {
    const test::NamedSpec& ns = spread[i];
    SCOPED_TRACE(GetParam() + "/" + ns.name);
    // Every spec compares disk with memory; the oracles (which extraction_test already runs on
    // the same triangles in memory) run on every third, through the disk's OpSource.
    const bool oracles = i % 3 == 0;
    const Rcf rcf = make_rcf(ns.spec, ModelKind::kTerrain, &d.dem);
    const Extraction mem = extract_minimal_surface(m, rcf);
    const Extraction disk = extract_minimal_surface(source, rcf);
    EXPECT_EQ(disk.x, mem.x);
    EXPECT_EQ(disk.triangles, mem.triangles);
    EXPECT_EQ(disk.fan_starts, mem.fan_starts);

    // Reduced extraction: X from the R-tree == X from a scan of every op.
    const Extraction rmem = extract_reduced(m, rcf);
    const Extraction rdisk = extract_reduced(source, rcf);
    EXPECT_EQ(rdisk.x, rmem.x);
    EXPECT_EQ(rdisk.triangles, rmem.triangles);

    for (const Extraction* e : {&disk, &rdisk}) {
      if (!oracles) break;
      const InvariantReport tiling = check_tiling(*db, e->triangles);
      EXPECT_TRUE(tiling.ok()) << tiling.summary();
      const test::OracleResult rcf_ok = test::check_rcf_opwise(*db, e->triangles, rcf);
      EXPECT_TRUE(rcf_ok.ok()) << rcf_ok.first_failure;
      const test::OracleResult bound = test::check_error_bound(*db, e->triangles, d.dem);
      EXPECT_TRUE(bound.ok()) << bound.first_failure;
    }
    // No cracks: every vertex decodes to one position, whichever op (page) it comes from.
    std::unordered_map<std::uint64_t, Vec3> at;
    for (const TriRef& ref : disk.triangles) {
      const OpRef op = db->op(ref.op);
      const FragmentTriangle& t = op->fragment[ref.index];
      for (int k = 0; k < 3; ++k) {
        const Vertex& v = op->vertices[t.v[k]];
        auto [it, fresh] = at.emplace(v.id.value, v.p);
        ASSERT_TRUE(fresh || it->second == v.p) << "vertex " << v.id.value << " cracks";
      }
    }
  }
  const DatabaseStats st = db->stats();
  EXPECT_LE(st.cache.peak_held_bytes, budget);
  EXPECT_GT(st.cache.evictions, 0u);
  EXPECT_GT(st.pages_read, w.pages);  // pages were evicted and faulted in again
}

TEST(Database, PrefetchingChangesNothingAndDecodesEachPageOnce) {
  // Prefetching (a second thread decoding the pages a traversal says come next) may only make
  // reads earlier: the same X, triangles and mesh, each page decoded once when the cache holds
  // them all, and no more page reads than without it when the cache is small.
  const test::Dataset& d = test::dataset(test::dataset_names().front());
  TempDir dir;
  const std::string path = dir.file("model.smrdb");
  Crmr m = d.crmr;  // write_database quantizes it
  const WriteReport w = write_database(m, path, {});
  RcfSpec whole;
  whole.floor = 1.0;
  const Rcf rcf = make_rcf(whole, ModelKind::kTerrain, &d.dem);
  struct Run {
    Extraction e;
    TriangleMesh mesh;
    DatabaseStats stats;
  };
  const auto run = [&](bool prefetch, std::size_t cache_bytes, bool fronts) {
    const auto db = Database::open(path, {cache_bytes, prefetch});
    const IndexedSource source(*db);
    ExpansionOptions o;
    o.fronts = fronts;
    Run r{extract_minimal_surface(source, rcf, o), {}, {}};
    r.mesh = to_mesh(source, r.e.triangles);
    r.stats = db->stats();
    return r;
  };
  const std::size_t all = std::size_t{1} << 30;
  for (const bool fronts : {false, true}) {
    SCOPED_TRACE(fronts ? "advancing front" : "set formula");
    const Run off = run(false, all, fronts), on = run(true, all, fronts);
    EXPECT_EQ(on.e.x, off.e.x);
    EXPECT_EQ(on.e.triangles, off.e.triangles);
    EXPECT_EQ(on.mesh.positions, off.mesh.positions);
    EXPECT_EQ(on.mesh.triangles, off.mesh.triangles);
    EXPECT_EQ(off.stats.pages_prefetched, 0u);
    EXPECT_EQ(off.stats.pages_read, w.pages);
    EXPECT_EQ(on.stats.pages_read, w.pages);  // nothing decoded twice
    if (std::thread::hardware_concurrency() > 1) {
      EXPECT_GT(on.stats.pages_prefetched, 0u);
    }
    // A cache of an eighth of the pages: the lookahead stays within it.
    const std::size_t small = off.stats.cache.bytes_decoded / 8;
    const Run small_off = run(false, small, fronts), small_on = run(true, small, fronts);
    EXPECT_EQ(small_on.e.triangles, off.e.triangles);
    // Timing decides which prefetched page a reader evicts, so allow a tenth more reads than
    // without prefetching (a lookahead past the cache would thrash: twice as many or more).
    EXPECT_LE(small_on.stats.pages_read * 10, small_off.stats.pages_read * 11);
  }
}

TEST(Database, PagesAreDecodedWithoutTheirLinksUntilAReaderNeedsThem) {
  // Only the advancing front reads the Hypermesh links, so pages are decoded without them (and
  // take less memory) until a reader calls need_links, as run_expansion does: the set formula
  // reads no link, a view without links refuses to give any, and after the front ran every op
  // read has its links, equal to the op built.
  const test::Dataset& d = test::dataset(test::dataset_names().front());
  TempDir dir;
  const std::string path = dir.file("model.smrdb");
  Crmr m = d.crmr;  // write_database quantizes it
  write_database(m, path, {});
  const auto linked =
      std::find_if(m.ops.begin(), m.ops.end(), [](const Op& op) { return !op.coarser.empty(); });
  ASSERT_NE(linked, m.ops.end());
  const RcfSpec spec = test::rcf_spread(m.header).back().spec;
  const Rcf rcf = make_rcf(spec, ModelKind::kTerrain, &d.dem);
  // Without the prefetch thread: no page decoded behind the test's back between its checks.
  const auto db = Database::open(path, {std::size_t{1} << 30, false});
  const IndexedSource source(*db);
  const std::uint64_t page = db->locality(linked->id);

  const OpRef lean = db->op(linked->id);
  EXPECT_FALSE(lean->links);
  EXPECT_TRUE(lean->coarser.empty());
  const auto internal = [](const auto& f) {
    try {
      f();
    } catch (const Error& e) {
      return e.kind() == ErrorKind::kInternal;
    }
    return false;
  };
  EXPECT_TRUE(internal([&] { to_op(*lean); }));
  EXPECT_TRUE(internal([&] { lean->coarser_link(0, 0); }));
  const std::size_t lean_bytes = db->page(page)->memory_bytes();

  ExpansionOptions pages;
  pages.fronts = false;
  const auto sorted = [](std::vector<TriRef> t) {
    std::sort(t.begin(), t.end());
    return t;
  };
  const Extraction set = extract_minimal_surface(source, rcf, pages);
  const Extraction mem = extract_minimal_surface(m, rcf);
  EXPECT_EQ(set.x, mem.x);
  EXPECT_EQ(sorted(set.triangles), sorted(mem.triangles));  // page order: not the front's
  EXPECT_FALSE(db->op(linked->id)->links);                  // the set formula asked for none

  // The first to ask drops the pages held without links (they would only take cache space).
  const std::uint64_t held = db->stats().cache.held_bytes;
  db->need_links();
  EXPECT_LE(db->stats().cache.held_bytes + lean_bytes, held);
  const Extraction front = extract_minimal_surface(source, rcf);
  EXPECT_EQ(front.triangles, mem.triangles);
  EXPECT_EQ(front.fan_starts, mem.fan_starts);
  const OpRef full = db->op(linked->id);
  EXPECT_TRUE(full->links);
  EXPECT_EQ(to_op(*full), *linked);
  // Every link of the page took memory the lean page does not (at least a CoarserLink each).
  std::size_t links = 0;
  for (const OpView& op : db->page(page)->ops()) links += op.coarser.size();
  EXPECT_GE(db->page(page)->memory_bytes(), lean_bytes + links * sizeof(CoarserLink));
}

TEST(Database, ViewsReadAheadOnlyTheIndexsCandidatePages) {
  // A view's AddToList hands the R-tree's candidate pages to the prefetcher, during the query and
  // after it, top down (add_to_list.cpp, hint_places): the same X, triangles and mesh as without
  // prefetching, and no more page decodes than the candidate pages (and R^0's). Small pages,
  // so that a view leaves most of them out.
  const test::Dataset& d = test::dataset(test::dataset_names().front());
  TempDir dir;
  const std::string path = dir.file("model.smrdb");
  Crmr m = d.crmr;
  WriteOptions wo;
  wo.page_bytes = 4096 - 16;
  const WriteReport w = write_database(m, path, wo);
  int views = 0;
  std::uint64_t read_ahead = 0;
  for (const test::NamedSpec& named : test::rcf_spread(m.header)) {
    if (!named.spec.camera) continue;
    SCOPED_TRACE(named.name);
    const Rcf rcf = make_rcf(named.spec, ModelKind::kTerrain, &d.dem);
    const auto run = [&](bool prefetch) {
      const auto db = Database::open(path, {std::size_t{1} << 30, prefetch});
      const IndexedSource source(*db);
      const CandidateOps c = source.maybe_not_completely_finer(rcf, false);
      std::set<std::uint64_t> places;
      for (OpId id : c.ids) places.insert(source.locality(id));
      EXPECT_EQ(std::set<std::uint64_t>(c.places.begin(), c.places.end()), places);
      EXPECT_EQ(places.size(), c.places.size());  // each once
      ExpansionOptions o;
      o.fronts = false;
      Extraction e = extract_minimal_surface(source, rcf, o);
      TriangleMesh mesh = to_mesh(source, e.triangles);
      return std::tuple{std::move(e), std::move(mesh), db->stats(), places.size() + 1};
    };
    const auto [off, off_mesh, off_stats, off_places] = run(false);
    const auto [on, on_mesh, on_stats, on_places] = run(true);
    EXPECT_EQ(on.x, off.x);
    EXPECT_EQ(on.triangles, off.triangles);
    EXPECT_EQ(on_mesh.triangles, off_mesh.triangles);
    EXPECT_EQ(on_mesh.positions, off_mesh.positions);
    EXPECT_GE(on_stats.pages_read, off_stats.pages_read);
    EXPECT_LE(on_stats.pages_read, on_places);  // candidate pages, and R^0's
    if (off_stats.pages_read * 2 < w.pages) ++views;
    read_ahead += on_stats.pages_prefetched;
  }
  EXPECT_GT(views, 0);  // some view left most pages out
  if (std::thread::hardware_concurrency() > 1) {
    EXPECT_GT(read_ahead, 0u);
  }
}

INSTANTIATE_TEST_SUITE_P(Dems, PerDataset, ::testing::ValuesIn(test::dataset_names()),
                         [](const auto& p) { return p.param; });

TEST(Database, EveryCodecRoundTripsAndFilesAreByteIdentical) {
  // The smallest real DEM under the sanitizers (Draco's encoder is slow there).
  const test::Dataset& d = test::dataset(test::kSanitized ? "elev" : "jacksboro");
  TempDir dir;
  std::uint64_t sizes[3] = {};
  for (storage::CodecId codec :
       {storage::CodecId::kRaw, storage::CodecId::kZstd, storage::CodecId::kDraco}) {
    SCOPED_TRACE(std::string(storage::codec_name(codec)));
    WriteOptions o;
    o.codec = codec;
    Crmr a = d.crmr, b = d.crmr;
    const std::string pa = dir.file("a.smrdb"), pb = dir.file("b.smrdb");
    o.force = true;
    write_database(a, pa, o);
    write_database(b, pb, o);
    const std::string bytes = read_file(pa);
    EXPECT_TRUE(bytes == read_file(pb)) << "same input, different bytes";
    sizes[static_cast<int>(codec)] = bytes.size();
    expect_same_ops(a, *Database::open(pa, {}));
    const VerifyReport v = verify_database(pa, nullptr);
    EXPECT_TRUE(v.ok()) << v.faults.front();
    EXPECT_EQ(v.ops, a.ops.size());
    std::uint64_t links = 0;  // every Hypermesh link is read and checked
    for (const Op& op : a.ops) links += op.coarser.size();
    EXPECT_EQ(v.links, links);
  }
  EXPECT_LT(sizes[2], sizes[0]);  // Draco beats raw
  EXPECT_LT(sizes[1], sizes[0]);  // and so does zstd
}

TEST(Database, ExistingPathNeedsForceAndStaysUntouched) {
  const test::Dataset& d = test::dataset("fbm129");
  TempDir dir;
  const std::string path = dir.file("x.smrdb");
  Crmr m = d.crmr;
  write_database(m, path, {});
  const std::string before = read_file(path);
  Crmr again = d.crmr;
  WriteOptions o;
  o.codec = storage::CodecId::kRaw;  // a different file than the default codec's
  try {
    write_database(again, path, o);
    FAIL() << "overwrote an existing database without force";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kInvalidInput);
    EXPECT_NE(std::string(e.what()).find("--force"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(read_file(path) == before) << "the existing database changed";
  o.force = true;
  write_database(again, path, o);
  EXPECT_TRUE(read_file(path) != before) << "--force did not replace the database";
  // Nothing but the database is left in the directory.
  int files = 0;
  for (const auto& entry : fs::directory_iterator(fs::path(path).parent_path())) {
    ++files;
    EXPECT_EQ(entry.path().string(), path);
  }
  EXPECT_EQ(files, 1);
}

TEST(Database, OpeningSomethingElseFailsClearly) {
  TempDir dir;
  EXPECT_THROW(Database::open(dir.file("missing.smrdb"), {}), Error);
  { std::ofstream(dir.file("text.smrdb")) << "not a database\n"; }
  EXPECT_THROW(Database::open(dir.file("text.smrdb"), {}), Error);
  { std::ofstream(dir.file("empty.smrdb")); }
  EXPECT_THROW(Database::open(dir.file("empty.smrdb"), {}), Error);
  const VerifyReport v = verify_database(dir.file("text.smrdb"), nullptr);
  EXPECT_FALSE(v.ok());
}

// A database of another format (here format 2, whose op locators' table was "nodes", or a
// format-3 file whose meta says another version) is refused with a message naming the format and
// the command that rebuilds it from its source; nothing is read beyond the meta record.
TEST(Database, OtherFormatsAreRefusedNamingTheRebuildCommand) {
  TempDir dir;
  const auto write = [&](const std::string& path, std::span<const std::string_view> tables,
                         int version) {
    storage::DatabaseWriter w(path, tables, false);
    const std::string meta =
        nlohmann::json{
            {"format", "smrdb"}, {"version", version}, {"model", {{"source", "dem.npy"}}}}
            .dump();
    w.put(Table::kMeta, "meta", storage::seal(storage::as_bytes(meta)));
    w.finish();
  };
  constexpr std::array<std::string_view, 5> kFormat2 = {"meta", "nodes", "pages", "rtree", "aux"};
  const std::string old = dir.file("old.smrdb"), future = dir.file("future.smrdb");
  write(old, kFormat2, 2);
  write(future, kTableNames, kDatabaseFormat + 1);
  for (const auto& [path, version] : {std::pair{old, 2}, {future, kDatabaseFormat + 1}}) {
    try {
      Database::open(path, {});
      ADD_FAILURE() << path << " opened";
    } catch (const Error& e) {
      EXPECT_EQ(e.kind(), ErrorKind::kInvalidInput);
      const std::string what = e.what();
      EXPECT_NE(what.find(path + ": database format " + std::to_string(version) +
                          " is not supported (this smrdb reads format " +
                          std::to_string(kDatabaseFormat) + ")"),
                std::string::npos)
          << what;
      EXPECT_NE(what.find("smrdb ingest dem.npy -o " + path + " --force"), std::string::npos)
          << what;
    }
  }
}

TEST(Database, OpsOutOfRangeAreAnErrorNotACrash) {
  const test::Dataset& d = test::dataset("fbm129");
  TempDir dir;
  Crmr m = d.crmr;
  write_database(m, dir.file("x.smrdb"), {});
  const auto db = Database::open(dir.file("x.smrdb"), {});
  EXPECT_THROW(db->op(OpId{m.ops.size()}), Error);
  EXPECT_THROW(db->page(db->page_count()), Error);
}

// Format 5 (page.h, PageValue): each pages value holds its R-tree leaf, whose entries are the
// page's ops slot for slot, and the rtree table holds only the nodes above the leaves and the
// header. A leaf damaged inside its value is an error naming the pages table and key, for the
// index's readers, while the page itself still decodes (the two are sealed apart).
TEST(Database, EachPageValueHoldsItsRtreeLeaf) {
  const test::Dataset& d = test::dataset("fbm129");
  TempDir dir;
  Crmr m = d.crmr;
  WriteOptions o;
  o.page_bytes = 2 * 4096 - 16;  // several pages and internal nodes
  o.rtree_fanout = 4;
  const WriteReport w = write_database(m, dir.file("x.smrdb"), o);
  const auto db = Database::open(dir.file("x.smrdb"), {});
  ASSERT_GE(db->page_count(), 8u);
  const index::RTree& tree = db->rtree();
  ASSERT_EQ(tree.leaf_count(), db->page_count());
  ASSERT_EQ(w.rtree_nodes, tree.node_count());
  std::size_t entries = 0;
  for (std::uint32_t p = 0; p < db->page_count(); ++p) {
    const std::vector<index::Entry> leaf = tree.leaf_entries(p);
    const auto page = db->page(p);
    ASSERT_EQ(leaf.size(), page->size()) << "page " << p;
    for (std::size_t s = 0; s < leaf.size(); ++s) {
      EXPECT_EQ(leaf[s].id, (*page)[s].id.value) << "page " << p << " slot " << s;
      entries += 1;
    }
  }
  EXPECT_EQ(entries, m.ops.size());
  const std::string bytes = read_file(dir.file("x.smrdb"));
  std::uint64_t rtree_values = 0, leaf_offset = 0, leaf_size = 0;
  {
    const storage::Env env = storage::Env::open_read_only(dir.file("x.smrdb"), kTableNames);
    const storage::ReadTxn txn = env.read();
    txn.for_each(Table::kRtree, [&](storage::ByteView, storage::ByteView) { ++rtree_values; });
    const auto value = txn.get(Table::kPages, 3);
    ASSERT_TRUE(value.has_value());
    const PageValue parts = split_page_value(*value, "pages", "3");
    EXPECT_EQ(storage::unseal(parts.leaf, "pages", "3").size() + 8, parts.leaf.size());
    const std::string_view leaf(reinterpret_cast<const char*>(parts.leaf.data()),
                                parts.leaf.size());
    leaf_offset = bytes.find(leaf);
    leaf_size = leaf.size();
    ASSERT_NE(leaf_offset, std::string::npos);
  }
  EXPECT_EQ(rtree_values, tree.node_count() - tree.leaf_count() + 1);  // + the header

  // A bit of page 3's leaf flipped: the index's reader names pages/3; the page still decodes.
  std::string bad = bytes;
  bad[leaf_offset + leaf_size / 2] = static_cast<char>(bad[leaf_offset + leaf_size / 2] ^ 4);
  test::write_file(dir.file("bad.smrdb"), bad);
  const auto damaged = Database::open(dir.file("bad.smrdb"), {});
  EXPECT_EQ(damaged->page(3)->size(), db->page(3)->size());
  try {
    damaged->rtree().leaf_entries(3);
    ADD_FAILURE() << "a damaged leaf was read";
  } catch (const Error& e) {
    EXPECT_EQ(e.exit_code(), 1) << e.what();
    EXPECT_NE(std::string(e.what()).find("table 'pages', key 3"), std::string::npos) << e.what();
  }
}

// The LMDB sub-database names and their order are part of the file format (tables.h): format 3
// names the op locators' table "locators" (format 2: "nodes").
TEST(Database, TableNamesAreTheFormats) {
  EXPECT_EQ(table_name(Table::kMeta), "meta");
  EXPECT_EQ(table_name(Table::kOpLocators), "locators");
  EXPECT_EQ(table_name(Table::kPages), "pages");
  EXPECT_EQ(table_name(Table::kRtree), "rtree");
  EXPECT_EQ(table_name(Table::kAux), "aux");
  EXPECT_EQ(kTableNames.size(), kAllTables.size());
  for (std::size_t i = 0; i < kAllTables.size(); ++i) {
    EXPECT_EQ(static_cast<std::size_t>(kAllTables[i]), i);
  }
}

// The streaming writer (ops handed over one at a time, spooled to a scratch file) writes the same
// bytes as write_database on the whole CRMR, for each builder's kind of CRMR: greedy terrain,
// block-decimation terrain with no-data holes, a 3-D mesh with spawned components; and after it
// the writer's header equals the quantized CRMR's.
void expect_streamed_equals_whole(const Crmr& crmr, const WriteOptions& o, const TempDir& dir) {
  Crmr whole = crmr;
  write_database(whole, dir.file("whole.smrdb"), o);
  const std::string scratch = dir.file("scratch");
  fs::create_directories(scratch);
  DatabaseStreamWriter w(dir.file("streamed.smrdb"), o, scratch);
  w.begin(crmr.header, crmr.ops.size());
  for (const Op& op : crmr.ops) w.add(Op(op));
  const WriteReport r = w.finish();
  EXPECT_TRUE(read_file(dir.file("whole.smrdb")) == read_file(dir.file("streamed.smrdb")))
      << "the streamed database differs from the whole CRMR's";
  EXPECT_EQ(w.header(), whole.header);
  EXPECT_EQ(r.ops, crmr.ops.size());
  EXPECT_GT(r.spool_bytes, 0u);
  EXPECT_TRUE(fs::is_empty(scratch)) << "the scratch file is visible";

  // The split path (OpSink::encodes): ops encoded on several threads, last first, their bounds
  // cleared (encode computes them), then handed over in id order: the same bytes again.
  DatabaseStreamWriter e(dir.file("encoded.smrdb"), o, scratch);
  ASSERT_TRUE(e.encodes());
  e.begin(crmr.header, crmr.ops.size());
  const std::size_t n = crmr.ops.size();
  std::vector<std::vector<std::uint8_t>> encoded(n);
  parallel_for(n, 3, [&](std::size_t i) {
    Op op = crmr.ops[n - 1 - i];
    op.box = Box3{};
    op.sphere = Sphere{};
    op.cone = NormalCone{};
    e.encode(op, encoded[n - 1 - i]);
  });
  for (const std::vector<std::uint8_t>& bytes : encoded) e.add_encoded(bytes);
  e.finish();
  EXPECT_TRUE(read_file(dir.file("whole.smrdb")) == read_file(dir.file("encoded.smrdb")))
      << "the database from encoded ops differs from the whole CRMR's";
  EXPECT_EQ(e.header(), whole.header);
  EXPECT_TRUE(fs::is_empty(scratch)) << "the scratch file is visible";
}

TEST(DatabaseStreamWriter, WritesTheBytesOfTheWholeCrmr) {
  TempDir dir;
  WriteOptions o;
  o.force = true;
  {
    const char* dem = test::kSanitized ? "elev" : "jacksboro";  // a smaller one when sanitized
    SCOPED_TRACE(std::string("greedy ") + dem + ", zstd");
    expect_streamed_equals_whole(test::dataset(dem).crmr, o, dir);
  }
  {
    SCOPED_TRACE("blocks over topobathy (no data), draco");
    BlockTinOptions bo;
    bo.block_cells = 32;
    bo.max_error = test::dataset("topobathy").max_error;
    const HeightfieldWindows windows(test::dataset("topobathy").dem);
    WriteOptions draco = o;
    draco.codec = storage::CodecId::kDraco;
    expect_streamed_equals_whole(build_block_tin(windows, bo), draco, dir);
  }
  {
    SCOPED_TRACE("blobby_3cc (spawned components), raw");
    WriteOptions raw = o;
    raw.codec = storage::CodecId::kRaw;
    expect_streamed_equals_whole(test::built_mesh("blobby_3cc.off").crmr, raw, dir);
  }
}

// Under the smallest memory budget the writer's sorts and its ROI queue spill into many runs
// (1024 records each) and must give the same bytes as with everything in memory.
TEST(DatabaseStreamWriter, SpillingSortsGiveTheSameBytes) {
  // Under the sanitizers fbm129, which has enough ops to spill as well: jacksboro is not among
  // their datasets, and building it for this test alone took most of its time.
  const Crmr& crmr = test::dataset(test::kSanitized ? "fbm129" : "jacksboro").crmr;
  ASSERT_GT(crmr.ops.size(), 8 * 1024u) << "too few ops to spill";
  TempDir dir;
  std::uint64_t scratch[2] = {0, 0};
  for (int tight = 0; tight < 2; ++tight) {
    WriteOptions o;
    o.sort_bytes = tight ? 0 : std::uint64_t{1} << 30;
    const std::string path = dir.file(tight ? "tight.smrdb" : "roomy.smrdb");
    DatabaseStreamWriter w(path, o, dir.path().string());
    w.begin(crmr.header, crmr.ops.size());
    for (const Op& op : crmr.ops) w.add(Op(op));
    scratch[tight] = w.finish().scratch_bytes;
  }
  EXPECT_TRUE(read_file(dir.file("tight.smrdb")) == read_file(dir.file("roomy.smrdb")));
  EXPECT_GT(scratch[1], scratch[0]) << "the tight budget should have spilled sort runs";
  Crmr whole = crmr;
  write_database(whole, dir.file("whole.smrdb"), {});
  EXPECT_TRUE(read_file(dir.file("whole.smrdb")) == read_file(dir.file("tight.smrdb")));
}

// The block builder streams straight into the writer (the way `smrdb ingest --builder blocks`
// runs): the same file as collecting its CRMR and writing it whole, and the DAG depth both report.
TEST(DatabaseStreamWriter, TheBlockBuilderStreamsIntoIt) {
  const test::Dataset& d = test::dataset(test::kSanitized ? "fbm129" : "fbm257");
  TempDir dir;
  BlockTinOptions bo;
  bo.block_cells = 32;
  bo.max_error = d.max_error;
  const HeightfieldWindows windows(d.dem);
  BlockTinStats collected_stats, streamed_stats;
  Crmr whole = build_block_tin(windows, bo, &collected_stats);
  write_database(whole, dir.file("whole.smrdb"), {});
  DatabaseStreamWriter w(dir.file("streamed.smrdb"), {}, dir.path().string());
  build_block_tin(windows, w, bo, &streamed_stats);
  const WriteReport r = w.finish();
  EXPECT_TRUE(read_file(dir.file("whole.smrdb")) == read_file(dir.file("streamed.smrdb")));
  EXPECT_EQ(streamed_stats.dag_height, collected_stats.dag_height);
  EXPECT_EQ(r.dag_depth, streamed_stats.dag_height);
  EXPECT_GE(r.dag_depth, 3u);
  EXPECT_EQ(r.ops, whole.ops.size());
}

// Misuse and interruption: an existing database without force is refused before any op; ops out
// of id order are a bug reported as such; a writer dropped before finish() leaves no database.
TEST(DatabaseStreamWriter, RefusesMisuseAndLeavesNothingWhenDropped) {
  const test::Dataset& d = test::dataset("fbm129");
  TempDir dir;
  const std::string path = dir.file("x.smrdb");
  {
    DatabaseStreamWriter w(path, {}, dir.path().string());
    w.begin(d.crmr.header, 0);
    w.add(Op(d.crmr.ops[0]));
    EXPECT_THROW(w.add(Op(d.crmr.ops[2])), Error);
    std::vector<std::uint8_t> bytes;
    Op op = d.crmr.ops[1];
    w.encode(op, bytes);
    EXPECT_THROW(w.add_encoded(bytes), Error) << "add() and add_encoded() mixed";
  }
  {
    DatabaseStreamWriter w(path, {}, dir.path().string());
    w.begin(d.crmr.header, 0);
    std::vector<std::uint8_t> bytes;
    Op op = d.crmr.ops[1];
    w.encode(op, bytes);
    EXPECT_THROW(w.add_encoded(bytes), Error) << "op 1 before op 0";
  }
  EXPECT_TRUE(fs::is_empty(dir.path())) << "a dropped writer left files behind";
  {
    Crmr m = d.crmr;
    write_database(m, path, {});
  }
  const std::string before = read_file(path);
  try {
    DatabaseStreamWriter w(path, {}, dir.path().string());
    FAIL() << "opened an existing database without force";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kInvalidInput);
    EXPECT_NE(std::string(e.what()).find("--force"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(read_file(path) == before);
  EXPECT_THROW(DatabaseStreamWriter(dir.file("y.smrdb"), {}, dir.file("no-such-dir")), Error);
  EXPECT_FALSE(fs::exists(dir.file("y.smrdb")));
}

}  // namespace
}  // namespace smr
