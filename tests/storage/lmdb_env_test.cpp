#include "storage/lmdb_env.h"

#include <algorithm>
#include <atomic>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "storage/checksum.h"
#include "storage_test_helpers.h"

namespace smr::storage {
namespace {

using test::expect_error;
using test::TempDir;

// The tables of these tests, by their index in kNames (storage knows no table of its own).
enum class T : std::uint8_t { kMeta, kNodes, kPages, kRtree, kAux };
constexpr std::string_view kNames[] = {"meta", "nodes", "pages", "rtree", "aux"};
constexpr T kAllT[] = {T::kMeta, T::kNodes, T::kPages, T::kRtree, T::kAux};

Env open_env(const std::string& path) {
  return Env::open_read_only(path, kNames);
}

// Deterministic value of (table, key): sizes 0 .. ~12 KiB, so many values exceed a 4 KiB page.
Bytes value_for(T table, std::uint64_t key) {
  std::mt19937_64 rng(key * 31 + static_cast<std::uint64_t>(table));
  const std::size_t size = key % 97 == 0 ? 0 : (key % 5 == 0 ? 4000 + rng() % 8000 : rng() % 600);
  return test::random_bytes(rng, size);
}

constexpr std::uint64_t kKeys[] = {0, 0, 3000, 200, 300};  // keys per table, indexed by T

std::uint64_t key_of(std::uint64_t i) {
  return i * 3 + 5;
}

// Writes the standard content: u64 keys in nodes/pages/rtree/aux, string keys in aux and meta
// (meta last, as the contract asks).
void write_standard(DatabaseWriter& w) {
  for (T t : {T::kNodes, T::kPages, T::kRtree, T::kAux}) {
    for (std::uint64_t i = 0; i < kKeys[static_cast<int>(t)]; ++i) {
      const std::uint64_t k = key_of(i);
      w.append(t, k, value_for(t, k));
    }
  }
  w.put(T::kAux, "zz-string-key", as_bytes("aux value"));
  w.put(T::kMeta, "version", as_bytes("1"));
  w.put(T::kMeta, "bounds", Bytes(5000, 0xab));
  w.put(T::kMeta, "version", as_bytes("2"));  // replaces
}

std::uint64_t standard_value_bytes() {
  std::uint64_t total = 9 + 1 + 5000 + 1;
  for (T t : {T::kNodes, T::kPages, T::kRtree, T::kAux}) {
    for (std::uint64_t i = 0; i < kKeys[static_cast<int>(t)]; ++i) {
      total += value_for(t, key_of(i)).size();
    }
  }
  return total;
}

// Tables are the caller's: named at creation and at opening, addressed by index.
TEST(LmdbEnv, TableNames) {
  TempDir dir;
  const std::string path = dir.file("db.smrdb");
  DatabaseWriter w(path, kNames, false);
  EXPECT_EQ(w.table_name(T::kMeta), "meta");
  EXPECT_EQ(w.table_name(T::kNodes), "nodes");
  EXPECT_EQ(w.table_name(T::kPages), "pages");
  EXPECT_EQ(w.table_name(T::kRtree), "rtree");
  EXPECT_EQ(w.table_name(T::kAux), "aux");
  w.finish();
  const Env env = open_env(path);
  for (T t : kAllT) EXPECT_EQ(env.table_name(t), w.table_name(t));
  // A table beyond the list, more tables than LMDB is set up for, or a name given twice are
  // the caller's bugs.
  expect_error([&] { (void)env.table_name(Table(5)); }, ErrorKind::kInternal, "table 5 of 5");
  const std::vector<std::string_view> nine(9, "t");
  expect_error([&] { DatabaseWriter x(dir.file("nine"), nine, false); }, ErrorKind::kInternal,
               "9 tables");
  const std::string_view twice[] = {"meta", "meta"};
  expect_error([&] { DatabaseWriter x(dir.file("twice"), twice, false); }, ErrorKind::kInternal,
               "table 'meta' named twice");
  // Opened with fewer tables than the file has, it reads those; with one it lacks, it fails.
  const std::string_view some[] = {"pages"};
  EXPECT_EQ(Env::open_read_only(path, some).read().count(Table(0)), 0u);
  const std::string_view more[] = {"meta", "extra"};
  expect_error([&] { Env::open_read_only(path, more); }, ErrorKind::kCorrupt,
               "missing table 'extra'");
}

TEST(LmdbEnv, WriterReaderRoundTripWithMapGrowthAndManyBatches) {
  TempDir dir;
  const std::string path = dir.file("db.smrdb");
  std::uint64_t commits = 0, map_bytes = 0, written = 0;
  {
    DatabaseWriter w(path, kNames, false, /*batch_bytes=*/256 << 10,
                     /*initial_map_bytes=*/64 << 10);
    write_standard(w);
    w.finish();
    commits = w.commits();
    map_bytes = w.map_bytes();
    written = w.bytes_written();
  }
  EXPECT_GT(commits, 10u);                                         // many batches
  EXPECT_GT(map_bytes, 64u << 10);                                 // the map grew on MDB_MAP_FULL
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"db.smrdb"});  // no temporaries left

  const Env env = open_env(path);
  EXPECT_EQ(env.path(), path);
  EXPECT_EQ(env.file_bytes(), std::filesystem::file_size(path));
  EXPECT_EQ(env.bytes_read(), 0u);
  std::uint64_t expected_read = 0;
  {
    const ReadTxn txn = env.read();
    for (T t : {T::kNodes, T::kPages, T::kRtree}) {
      ASSERT_EQ(txn.count(t), kKeys[static_cast<int>(t)]) << env.table_name(t);
      for (std::uint64_t i = 0; i < kKeys[static_cast<int>(t)]; ++i) {
        const std::uint64_t k = key_of(i);
        const auto v = txn.get(t, k);
        ASSERT_TRUE(v.has_value()) << env.table_name(t) << " " << k;
        const Bytes expected = value_for(t, k);
        ASSERT_EQ(Bytes(v->begin(), v->end()), expected) << env.table_name(t) << " " << k;
        expected_read += expected.size();
      }
      EXPECT_FALSE(txn.get(t, key_of(kKeys[static_cast<int>(t)]) + 1).has_value());
      EXPECT_FALSE(txn.get(t, std::uint64_t{1}).has_value());
    }
    EXPECT_EQ(txn.count(T::kAux), kKeys[static_cast<int>(T::kAux)] + 1);
    EXPECT_EQ(txn.count(T::kMeta), 2u);
    const auto version = txn.get(T::kMeta, std::string_view("version"));
    ASSERT_TRUE(version.has_value());
    EXPECT_EQ(std::string(version->begin(), version->end()), "2");
    EXPECT_EQ(txn.get(T::kMeta, std::string_view("bounds"))->size(), 5000u);
    EXPECT_FALSE(txn.get(T::kMeta, std::string_view("nope")).has_value());
    expected_read += 1 + 5000;
    EXPECT_EQ(env.bytes_read(), expected_read);

    // for_each visits in key order.
    std::vector<std::uint64_t> seen;
    txn.for_each(T::kRtree, [&](ByteView key, ByteView value) {
      const std::uint64_t k = parse_key_u64(key, "rtree");
      seen.push_back(k);
      const Bytes expected = value_for(T::kRtree, k);
      EXPECT_EQ(Bytes(value.begin(), value.end()), expected);
    });
    ASSERT_EQ(seen.size(), kKeys[static_cast<int>(T::kRtree)]);
    EXPECT_TRUE(std::is_sorted(seen.begin(), seen.end()));
    std::vector<std::string> meta_keys;
    txn.for_each(T::kMeta,
                 [&](ByteView key, ByteView) { meta_keys.emplace_back(key.begin(), key.end()); });
    EXPECT_EQ(meta_keys, (std::vector<std::string>{"bounds", "version"}));
  }
  EXPECT_EQ(written, standard_value_bytes());
  // After dropping the mapping, reads still work.
  env.release_mapped_pages();
  const ReadTxn txn = env.read();
  const auto v = txn.get(T::kPages, key_of(1234));
  ASSERT_TRUE(v.has_value());
  EXPECT_EQ(Bytes(v->begin(), v->end()), value_for(T::kPages, key_of(1234)));
}

// kB of RssFile (file pages mapped and resident) in /proc/self/status; -1 when unknown.
long resident_file_kib() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("RssFile:", 0) == 0) return std::stol(line.substr(8));
  }
  return -1;
}

// Each batch reads the path to every table's last page through LMDB's map, and the kernel maps
// the cached pages around each page faulted in (64 KiB): a batch's last pages lie among its data
// pages, so without the writer dropping them after every commit they piled up with the file (the
// writer of a 1.7 GB database held ~90 MiB of them, issue 38). Data pages and small nodes
// interleaved as the database writer makes them, ~125 MiB in 1 MiB batches (no finish(): the
// temporaries go with the writer).
TEST(LmdbEnv, WriterDropsTheMapsPagesAsItGoes) {
  if (resident_file_kib() < 0) GTEST_SKIP() << "no RssFile in /proc/self/status";
  TempDir dir;
  DatabaseWriter w(dir.file("db.smrdb"), kNames, false, /*batch_bytes=*/1 << 20,
                   /*initial_map_bytes=*/std::uint64_t{256} << 20);
  std::mt19937_64 rng(38);
  const Bytes page = test::random_bytes(rng, 9000), node = test::random_bytes(rng, 1400);
  const long before = resident_file_kib();
  for (std::uint64_t k = 0; k < 12000; ++k) {
    w.append(T::kPages, k, page);
    w.append(T::kRtree, k, node);
  }
  const long grown_kib = resident_file_kib() - before;
  EXPECT_GT(w.commits(), 100u);
  EXPECT_LT(grown_kib, 4 * 1024) << "file pages resident after " << w.commits() << " commits";
}

TEST(LmdbEnv, EmptyDatabaseHasAllTables) {
  TempDir dir;
  const std::string path = dir.file("empty.smrdb");
  {
    DatabaseWriter w(path, kNames, false);
    w.finish();
  }
  const Env env = open_env(path);
  const ReadTxn txn = env.read();
  for (T t : kAllT) EXPECT_EQ(txn.count(t), 0u);
}

TEST(LmdbEnv, AppendOutOfOrderIsAnInternalError) {
  TempDir dir;
  DatabaseWriter w(dir.file("db"), kNames, false);
  w.append(T::kNodes, 10, as_bytes("a"));
  w.append(T::kPages, 5, as_bytes("b"));  // other tables are independent
  expect_error([&] { w.append(T::kNodes, 10, as_bytes("c")); }, ErrorKind::kInternal,
               "table 'nodes': key 10 appended after key 10");
  expect_error([&] { w.append(T::kNodes, 9, as_bytes("c")); }, ErrorKind::kInternal,
               "strictly increasing");
}

TEST(LmdbEnv, ExistingPathWithoutForceIsRejectedAndUntouched) {
  TempDir dir;
  const std::string path = dir.file("db.smrdb");
  const Bytes original = {'o', 'l', 'd'};
  test::write_file(path, original);
  expect_error([&] { DatabaseWriter w(path, kNames, false); }, ErrorKind::kInvalidInput,
               path + ": exists; pass --force to replace it");
  EXPECT_EQ(test::read_file(path), original);
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"db.smrdb"});

  {
    DatabaseWriter w(path, kNames, true);
    w.put(T::kMeta, "version", as_bytes("1"));
    // Until finish(), the old file is still there.
    EXPECT_EQ(test::read_file(path), original);
    w.finish();
  }
  const Env env = open_env(path);
  EXPECT_EQ(env.read().count(T::kMeta), 1u);
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"db.smrdb"});
}

TEST(LmdbEnv, WriterWithoutFinishLeavesNothingBehind) {
  TempDir dir;
  const std::string fresh = dir.file("fresh.smrdb");
  const std::string existing = dir.file("existing.smrdb");
  const Bytes original = {'k', 'e', 'e', 'p'};
  test::write_file(existing, original);
  {
    DatabaseWriter a(fresh, kNames, false, 1 << 10);
    DatabaseWriter b(existing, kNames, true, 1 << 10);
    for (std::uint64_t k = 0; k < 200; ++k) {
      a.append(T::kPages, k, value_for(T::kPages, k));
      b.append(T::kPages, k, value_for(T::kPages, k));
    }
    EXPECT_GT(a.commits(), 0u);
    EXPECT_GT(dir.entries().size(), 1u);  // temporaries exist while writing
  }
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"existing.smrdb"});
  EXPECT_EQ(test::read_file(existing), original);

  // Same when an exception unwinds through the writer.
  try {
    DatabaseWriter w(fresh, kNames, false);
    w.append(T::kNodes, 2, as_bytes("x"));
    w.append(T::kNodes, 1, as_bytes("y"));  // throws
    FAIL() << "out-of-order append did not throw";
  } catch (const Error&) {
  }
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"existing.smrdb"});
}

TEST(LmdbEnv, SameWritesGiveByteIdenticalFiles) {
  TempDir dir;
  for (const char* name : {"a.smrdb", "b.smrdb"}) {
    DatabaseWriter w(dir.file(name), kNames, false, 100 << 10, 64 << 10);
    write_standard(w);
    w.finish();
  }
  const Bytes a = test::read_file(dir.file("a.smrdb"));
  const Bytes b = test::read_file(dir.file("b.smrdb"));
  ASSERT_GT(a.size(), 1000000u);
  EXPECT_TRUE(a == b) << "files differ";
  // And a different write gives a different file (the comparison can fail).
  {
    DatabaseWriter w(dir.file("c.smrdb"), kNames, false, 100 << 10, 64 << 10);
    write_standard(w);
    w.put(T::kMeta, "extra", as_bytes("!"));
    w.finish();
  }
  EXPECT_FALSE(a == test::read_file(dir.file("c.smrdb")));
}

TEST(LmdbEnv, OpenRejectsMissingEmptyGarbageAndTruncatedFiles) {
  TempDir dir;
  const std::string missing = dir.file("missing.smrdb");
  expect_error([&] { open_env(missing); }, ErrorKind::kIo, missing);

  const std::string empty = dir.file("empty.smrdb");
  test::write_file(empty, {});
  expect_error([&] { open_env(empty); }, ErrorKind::kCorrupt, empty + ": empty file");

  std::mt19937_64 rng(9);
  const std::string garbage = dir.file("garbage.smrdb");
  for (std::size_t size : {1u, 100u, 4096u, 65536u}) {
    test::write_file(garbage, test::random_bytes(rng, size));
    expect_error([&] { open_env(garbage); }, ErrorKind::kCorrupt, garbage);
  }
  expect_error([&] { open_env(dir.file("")); }, ErrorKind::kInvalidInput, "not a regular file");

  const std::string real = dir.file("real.smrdb");
  {
    DatabaseWriter w(real, kNames, false);
    write_standard(w);
    w.finish();
  }
  const Bytes bytes = test::read_file(real);
  ASSERT_NO_THROW(open_env(real));
  const std::string cut = dir.file("cut.smrdb");
  std::vector<std::size_t> lengths = {1,
                                      16,
                                      100,
                                      4095,
                                      4096,
                                      4097,
                                      8191,
                                      8192,
                                      8193,
                                      bytes.size() / 2,
                                      bytes.size() - 4096,
                                      bytes.size() - 1};
  for (std::size_t n = 12288; n < bytes.size(); n += 4096 * 37) lengths.push_back(n);
  for (std::size_t n : lengths) {
    test::write_file(cut, Bytes(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(n)));
    try {
      open_env(cut);
      ADD_FAILURE() << "truncated to " << n << " of " << bytes.size() << " bytes opened";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(cut), std::string::npos) << e.what();
      EXPECT_NE(e.kind(), ErrorKind::kInternal) << e.what();
    }
  }
}

TEST(LmdbEnv, ConcurrentReadersFromFourThreads) {
  TempDir dir;
  const std::string path = dir.file("db.smrdb");
  {
    DatabaseWriter w(path, kNames, false);
    write_standard(w);
    w.finish();
  }
  const Env env = open_env(path);
  std::atomic<int> mismatches{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      std::mt19937_64 rng(static_cast<std::uint64_t>(t));
      for (int round = 0; round < 5; ++round) {
        const ReadTxn txn = env.read();
        for (int i = 0; i < 400; ++i) {
          const std::uint64_t k = key_of(rng() % kKeys[static_cast<int>(T::kPages)]);
          const auto v = txn.get(T::kPages, k);
          if (!v || Bytes(v->begin(), v->end()) != value_for(T::kPages, k)) ++mismatches;
        }
      }
    });
  }
  for (auto& th : threads) th.join();
  EXPECT_EQ(mismatches.load(), 0);
  EXPECT_GT(env.bytes_read(), 0u);
}

TEST(LmdbEnv, MovedEnvAndTxnStayUsable) {
  TempDir dir;
  const std::string path = dir.file("db.smrdb");
  {
    DatabaseWriter w(path, kNames, false);
    w.append(T::kNodes, 1, seal(as_bytes("payload")));
    w.finish();
  }
  Env env = open_env(path);
  ReadTxn txn = env.read();
  Env moved = std::move(env);
  ReadTxn txn2 = std::move(txn);
  const auto v = txn2.get(T::kNodes, std::uint64_t{1});
  ASSERT_TRUE(v.has_value());
  const ByteView payload = unseal(*v, "nodes", "1");
  EXPECT_EQ(std::string(payload.begin(), payload.end()), "payload");
  EXPECT_EQ(moved.bytes_read(), v->size());
}

}  // namespace
}  // namespace smr::storage
