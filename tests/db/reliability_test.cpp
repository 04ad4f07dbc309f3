// Reliability of the on-disk database (docs/design.md section 3): a damaged file — truncated, or a
// single bit flipped inside any value of any table — is a clear error naming the table and key,
// never a crash and never a different mesh; extraction stays within its cache budget; threads
// read one database while another is being written next to it.
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <mutex>
#include <optional>
#include <thread>

#include "base/error.h"
#include "smr/db/database.h"
#include "smr/db/tables.h"
#include "smr/db/verify.h"
#include "smr/db/writer.h"
#include "smr/extract/extract.h"
#include "smr/query/indexed_source.h"
#include "smr/rcf/spec.h"
#include "storage/lmdb_env.h"
#include "tests/support/datasets.h"
#include "tests/support/extraction_result.h"
#include "tests/support/files.h"

namespace smr {
namespace {

namespace fs = std::filesystem;
using test::read_file;
using test::write_file;

struct TempDir : test::TempDir {
  TempDir() : test::TempDir("smrdb-reliability") {}
};

// The small database every test here reads: fbm129 in pages of about 4 KiB, so that each table
// holds several values (pages, locator blocks, R-tree levels).
struct SmallDb {
  TempDir dir;
  std::string path = dir.file("small.smrdb");
  Crmr crmr = test::dataset("fbm129").crmr;
  WriteReport written;
  SmallDb() {
    WriteOptions o;
    o.page_bytes = 4096 - 16;
    written = write_database(crmr, path, o);
  }
};

const SmallDb& small_db() {
  static const SmallDb db;
  return db;
}

// RCFs that need everything, a corner of the model, and almost nothing.
std::vector<std::pair<std::string, RcfSpec>> specs(const CrmrInfo& info) {
  const Box3& b = info.bounds;
  const double w = b.hi.x - b.lo.x;
  RcfSpec full, corner, coarse;
  full.floor = 1.0;
  corner.floor = 0.0;
  corner.aois.push_back({b.lo.x + 0.1 * w, b.lo.y + 0.1 * w, 0.08 * w, 1.0});
  coarse.floor = 0.05;
  return {{"full", full}, {"corner", corner}, {"coarse", coarse}};
}

using test::extract_all;
using test::Result;
using test::same;

std::vector<Result> clean_results() {
  const auto db = Database::open(small_db().path, {std::size_t{1} << 30});
  std::vector<Result> out;
  for (const auto& [name, spec] : specs(db->info()))
    out.push_back(extract_all(IndexedSource(*db), spec));
  return out;
}

// Where a stored value lies in the file: its bytes are contiguous in an LMDB leaf or overflow
// page, so a value that occurs once in the file is found by searching for it.
struct Located {
  std::string key;  // as error messages spell it
  std::size_t offset = 0, size = 0;
};

// The first, a middle and the last value of `table` that occur once in the file.
std::vector<Located> locate_values(const std::string& path, Table table) {
  const std::string file = read_file(path);
  const storage::Env env = storage::Env::open_read_only(path, kTableNames);
  const storage::ReadTxn txn = env.read();
  std::vector<std::pair<std::string, std::string>> all;  // (key, value)
  txn.for_each(table, [&](storage::ByteView key, storage::ByteView value) {
    std::string name;
    if (table == Table::kMeta) {
      name.assign(reinterpret_cast<const char*>(key.data()), key.size());
    } else {
      const std::uint64_t k = storage::parse_key_u64(key, "test");
      name = k == ~std::uint64_t{0} ? "header" : std::to_string(k);
    }
    all.emplace_back(name, std::string(reinterpret_cast<const char*>(value.data()), value.size()));
  });
  auto find_once = [&](const std::string& v) -> std::optional<std::size_t> {
    const std::boyer_moore_horspool_searcher searcher(v.begin(), v.end());
    const auto it = std::search(file.begin(), file.end(), searcher);
    if (it == file.end() || std::search(it + 1, file.end(), searcher) != file.end()) return {};
    return static_cast<std::size_t>(it - file.begin());
  };
  std::vector<Located> out;
  for (const std::size_t start : {std::size_t{0}, all.size() / 2, all.size() - 1}) {
    // From `start` on to the first unique value (backwards for the last one).
    for (std::size_t k = 0; k < all.size() && k < 8; ++k) {
      const std::size_t i = start + 1 == all.size() ? start - k : start + k;
      if (i >= all.size()) break;
      if (const auto at = find_once(all[i].second)) {
        if (out.empty() || out.back().offset != *at)
          out.push_back({all[i].first, *at, all[i].second.size()});
        break;
      }
    }
  }
  return out;
}

TEST(Reliability, TruncatedFileIsACorruptDatabaseNotACrash) {
  const SmallDb& db = small_db();
  const std::string bytes = read_file(db.path);
  ASSERT_GT(bytes.size(), 16u * 4096);
  TempDir dir;
  const std::string bad = dir.file("truncated.smrdb");
  for (std::size_t length :
       {std::size_t{0}, std::size_t{1}, std::size_t{512}, std::size_t{4095}, std::size_t{4096},
        std::size_t{8191}, std::size_t{8192}, std::size_t{3 * 4096}, bytes.size() / 4,
        bytes.size() / 2, bytes.size() - 4096, bytes.size() - 1}) {
    SCOPED_TRACE("truncated to " + std::to_string(length) + " of " + std::to_string(bytes.size()));
    write_file(bad, bytes.substr(0, length));
    try {
      Database::open(bad, {});
      ADD_FAILURE() << "a truncated database opened";
    } catch (const Error& e) {
      EXPECT_EQ(e.exit_code(), 1) << e.what();
      EXPECT_NE(std::string(e.what()).find(bad), std::string::npos) << e.what();
    }
    const VerifyReport v = verify_database(bad, nullptr);
    ASSERT_FALSE(v.ok());
    EXPECT_NE(v.faults.front().find(bad), std::string::npos) << v.faults.front();
  }
}

// One bit flipped inside a value of `table`: verify reports the table and key; extraction either
// fails with a user-facing error or (when it never reads that value) returns the clean result.
void flip_bits_in(Table table) {
  const SmallDb& db = small_db();
  const std::string name(table_name(table));
  const std::string clean = read_file(db.path);
  const std::vector<Result> expected = clean_results();
  const std::vector<Located> values = locate_values(db.path, table);
  ASSERT_FALSE(values.empty()) << name;
  // In each value a bit of the first byte, of the middle and of the checksum (the last byte).
  const std::vector<Located>& picked = values;
  if (table != Table::kMeta) {
    EXPECT_EQ(values.size(), 3u);
  }
  TempDir dir;
  const std::string bad = dir.file("flipped.smrdb");
  int failed = 0, unaffected = 0;
  for (const Located& v : picked) {
    for (const std::size_t at : {std::size_t{0}, v.size / 2, v.size - 1}) {
      const int bit = static_cast<int>((at + v.offset) % 8);
      SCOPED_TRACE(name + "/" + v.key + ": bit " + std::to_string(bit) + " of value byte " +
                   std::to_string(at) + " of " + std::to_string(v.size));
      std::string bytes = clean;
      bytes[v.offset + at] = static_cast<char>(bytes[v.offset + at] ^ (1 << bit));
      write_file(bad, bytes);

      const VerifyReport report = verify_database(bad, nullptr);
      ASSERT_FALSE(report.ok()) << "verify missed the damage";
      const std::string where = "table '" + name + "', key " + v.key;
      bool named = false;
      for (const std::string& f : report.faults) named |= f.find(where) != std::string::npos;
      EXPECT_TRUE(named) << "no fault names " << where << "; first: " << report.faults.front();

      std::unique_ptr<Database> opened;
      try {
        opened = Database::open(bad, {std::size_t{1} << 30});
      } catch (const Error& e) {
        EXPECT_EQ(e.exit_code(), 1) << e.what();
        EXPECT_NE(std::string(e.what()).find(where), std::string::npos) << e.what();
        ++failed;
        continue;
      }
      const auto s = specs(opened->info());
      for (std::size_t i = 0; i < s.size(); ++i) {
        SCOPED_TRACE(s[i].first);
        opened->clear_cache();
        try {
          const Result got = extract_all(IndexedSource(*opened), s[i].second);
          EXPECT_TRUE(same(got, expected[i])) << "a damaged database gave a different mesh";
          ++unaffected;
        } catch (const Error& e) {
          EXPECT_EQ(e.exit_code(), 1) << e.what();
          EXPECT_NE(std::string(e.what()).find(where), std::string::npos) << e.what();
          ++failed;
        }
      }
    }
  }
  EXPECT_GT(failed, 0) << "no extraction noticed the damage in " << name;
}

TEST(Reliability, BitFlipInMetaIsCaught) {
  flip_bits_in(Table::kMeta);
}
TEST(Reliability, BitFlipInLocatorsIsCaught) {
  flip_bits_in(Table::kOpLocators);
}
TEST(Reliability, BitFlipInPagesIsCaught) {
  flip_bits_in(Table::kPages);
}
TEST(Reliability, BitFlipInRtreeIsCaught) {
  flip_bits_in(Table::kRtree);
}

TEST(Reliability, SmallDatabaseHasSeveralValuesPerTable) {
  const SmallDb& db = small_db();
  EXPECT_GE(db.written.pages, 20u);
  // Nodes above the leaves (the rtree table's values; the leaves are in the pages values).
  EXPECT_GE(db.written.rtree_nodes - db.written.pages, 2u);
  EXPECT_GE(db.crmr.ops.size(), 3 * kOpsPerLocatorBlock);
}

// A meta-less LMDB file (what an interrupted ingest would be if meta were not written last)
// does not open as a database.
TEST(Reliability, FileWithoutMetaIsNotADatabase) {
  TempDir dir;
  const std::string path = dir.file("nometa.smrdb");
  {
    storage::DatabaseWriter w(path, kTableNames, false);
    const storage::Bytes value(100, 7);
    w.append(Table::kPages, 0, value);
    w.finish();
  }
  try {
    Database::open(path, {});
    ADD_FAILURE() << "opened a database without meta";
  } catch (const Error& e) {
    EXPECT_EQ(e.exit_code(), 1);
    EXPECT_NE(std::string(e.what()).find("no meta record"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(verify_database(path, nullptr).ok());
}

// An operating-system failure while writing is an I/O error (exit code 1), not an internal one.
TEST(Reliability, WritingIntoAMissingDirectoryIsAnIoError) {
  TempDir dir;
  const std::string path = dir.file("no-such-dir/x.smrdb");
  try {
    storage::DatabaseWriter w(path, kTableNames, false);
    ADD_FAILURE() << "created a database in a missing directory";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kIo) << e.what();
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
  }
}

// docs/design.md section 6, memory bound: a budget a twentieth of the file still gives the same
// mesh. (Not the full-resolution RCF: with a budget far below its working set, the expansion
// re-decodes pages many times over, which is slow, not wrong.)
TEST(Reliability, ExtractionWithinATwentiethOfTheFile) {
  const SmallDb& small = small_db();
  const std::vector<Result> expected = clean_results();
  const std::size_t budget = fs::file_size(small.path) / 20;
  const auto db = Database::open(small.path, {budget});
  const auto s = specs(db->info());
  for (std::size_t i = 1; i < s.size(); ++i) {
    SCOPED_TRACE(s[i].first);
    EXPECT_TRUE(same(extract_all(IndexedSource(*db), s[i].second), expected[i]));
  }
  const DatabaseStats st = db->stats();
  EXPECT_LE(st.cache.peak_held_bytes, budget);
  EXPECT_GT(st.cache.evictions, 0u);
}

// Readers on threads — two sharing one Database (and its cache), two with their own — while a
// second database is written into the same directory: every extraction gives the same result.
TEST(Reliability, ConcurrentReadersWhileAnotherDatabaseIsWritten) {
  const SmallDb& small = small_db();
  const std::vector<Result> expected = clean_results();
  constexpr std::size_t kBudget = std::size_t{6} << 20;
  const auto shared = Database::open(small.path, {kBudget});
  const std::string second = fs::path(small.path).parent_path() / "second.smrdb";
  std::mutex mu;
  std::vector<std::string> errors;
  auto note = [&](const std::string& e) {
    std::lock_guard lock(mu);
    errors.push_back(e);
  };
  std::thread writer([&] {
    try {
      Crmr m = test::dataset("fbm129").crmr;
      WriteOptions o;
      o.codec = storage::CodecId::kRaw;
      o.force = true;
      write_database(m, second, o);
    } catch (const std::exception& e) {
      note(std::string("writer: ") + e.what());
    }
  });
  auto reader = [&](int id) {
    try {
      std::unique_ptr<Database> own;
      if (id >= 2) own = Database::open(small.path, {kBudget});
      const Database& db = own ? *own : *shared;
      const auto s = specs(db.info());
      for (int round = 0; round < (id < 2 ? 2 : 1); ++round) {
        for (std::size_t i = 0; i < s.size(); ++i) {
          if (!same(extract_all(IndexedSource(db), s[i].second), expected[i]))
            note("reader " + std::to_string(id) + ": " + s[i].first + " differs");
        }
      }
    } catch (const std::exception& e) {
      note("reader " + std::to_string(id) + ": " + e.what());
    }
  };
  std::vector<std::thread> readers;
  for (int id = 0; id < 4; ++id) readers.emplace_back(reader, id);
  writer.join();
  for (std::thread& t : readers) t.join();
  for (const std::string& e : errors) ADD_FAILURE() << e;
  EXPECT_TRUE(verify_database(second, nullptr).ok());
  EXPECT_LE(shared->stats().cache.peak_held_bytes, kBudget);
  EXPECT_GT(shared->stats().cache.evictions, 0u);
  fs::remove(second);
}

}  // namespace
}  // namespace smr
