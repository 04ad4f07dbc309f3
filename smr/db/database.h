// Reading a database (tables.h) back: the meta record and the R-tree's header when it opens,
// then ops on demand. Op locators say where an op is; its data page, decoded once into a page
// cache with a byte budget (storage/page_cache.h), holds it with the other ops of its R-tree leaf.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <utility>
#include <variant>
#include <vector>

#include "index/rtree.h"
#include "smr/core/op_source.h"
#include "smr/db/page.h"
#include "smr/db/quantize.h"
#include "smr/db/tables.h"
#include "storage/bytes.h"
#include "storage/lmdb_env.h"
#include "storage/page_cache.h"

namespace smr {

struct DatabaseStats {
  storage::CacheStats cache;
  std::uint64_t pages_read = 0;        // data pages fetched from LMDB
  std::uint64_t pages_prefetched = 0;  // of which decoded ahead on the prefetch thread
  std::uint64_t page_bytes_read = 0;   // their bytes (a pages value's page part)
  std::uint64_t rtree_nodes_read = 0;
  std::uint64_t rtree_bytes_read = 0;    // bytes of R-tree nodes fetched (a leaf: its part of
                                         // its page's value, page.h PageValue)
  std::uint64_t locator_bytes_read = 0;  // bytes of op-locator blocks fetched
  std::uint64_t lmdb_bytes_read = 0;     // the three above: what was read of LMDB's values
};

/// A database opened for reading. An OpSource: ops are read lazily, a data page at a time,
/// through a page cache with a byte budget, so extraction (smr/extract) runs on it unchanged.
/// Safe to read from several threads. What answers RCF questions from the R-tree (Brown Lemma
/// 5.2.1 via Maheshwari 4.4) is an adapter over it, smr/query/indexed_source.h.
class Database final : public OpSource {
 public:
  struct Options {
    std::size_t cache_bytes = std::size_t{64} << 20;
    /// Decode hinted pages (prefetch) on a second thread, when the machine has more than one.
    bool prefetch = true;
  };
  /// Opens a database read-only. A missing file, a file that is not a complete smrdb database (no
  /// meta record: an interrupted ingest), or an unknown format throws smr::Error naming the path.
  static std::unique_ptr<Database> open(const std::string& path, const Options& options);
  ~Database() override;

  const CrmrInfo& info() const override { return info_; }
  std::uint64_t op_count() const override { return op_count_; }
  OpRef op(OpId id) const override;
  std::uint64_t locality(OpId id) const override { return locate(id).page; }
  std::uint64_t locality_bytes(std::uint64_t page) const override;
  OpPlace place_of(OpId id) const override {
    const Locator l = locate(id);
    return {l.page, l.slot};
  }
  OpBatch batch(std::uint64_t page) const override;
  std::size_t prefetch(std::span<const std::uint64_t> pages) const override;
  /// Pages are decoded without their Hypermesh links until a reader asks for them (the advancing
  /// front does): from then on, for every reader of this database, with them. The pages decoded
  /// without are dropped from the cache then (readers holding one keep it).
  void need_links() const override;
  /// Asks the OS to read the data pages not in the cache ahead (storage::ReadTxn::will_need): a
  /// cold start then waits on many reads at once instead of one after another.
  void will_need(std::span<const std::uint64_t> pages) const;
  /// The same for the op locators of `ids` (any order): reads the locator tree's branch pages and
  /// asks for the leaves that hold them, without waiting for those.
  void will_need_locators(std::span<const OpId> ids) const;
  /// The entries of the R-tree that `visitor` accepts, grouped by leaf (= data page); reads the
  /// nodes the query enters (through the cache) and no page. Errors name the file.
  std::vector<index::Hit> rtree_query(index::Visitor& visitor) const;
  const index::RTree& rtree() const { return *rtree_; }
  const QuantGrid& grid() const { return grid_; }
  std::uint64_t page_count() const { return page_count_; }
  const std::string& meta_json() const { return meta_json_; }
  const std::string& path() const;
  std::uint64_t file_bytes() const;
  DatabaseStats stats() const;
  /// Decoded ops of data page `page` (through the cache).
  std::shared_ptr<const DecodedPage> page(std::uint64_t page) const;
  /// Calls f with the stored bytes of data page `page`, unsealed (checksum checked), read past the
  /// cache and valid only during the call (LMDB's own mapped memory, not copied): for readers that
  /// take only part of a page (cut_page). Counted in stats() as a page read.
  void with_page_bytes(std::uint64_t page, const std::function<void(storage::ByteView)>& f) const;
  /// Where the op locators say op `id` is: its data page and slot. Reads no page.
  std::pair<std::uint64_t, std::uint32_t> locator(OpId id) const {
    const Locator l = locate(id);
    return {l.page, l.slot};
  }
  /// Forgets every cached page (for cold measurements).
  void clear_cache() const;

 private:
  Database() = default;
  struct Locator {
    std::uint64_t page;
    std::uint32_t slot;
  };
  using CacheItem =
      std::variant<std::shared_ptr<const DecodedPage>, std::vector<Locator>, storage::Bytes>;
  std::shared_ptr<const CacheItem> cached(std::uint64_t kind, Table table, std::uint64_t id) const;
  std::shared_ptr<const CacheItem> fetch(std::uint64_t kind, Table table, std::uint64_t id) const;
  std::vector<std::uint64_t> uncached(std::uint64_t kind, std::span<const std::uint64_t> ids,
                                      std::uint64_t count) const;
  // The same item, held by this thread's memo until its next lookup of that kind (no reference
  // count touched): for reads that finish before the next lookup.
  const CacheItem& memoized(std::uint64_t kind, Table table, std::uint64_t id) const;
  struct Memo;
  static Memo& memo(std::uint64_t kind);
  // f(a value as stored, sealed) while its read transaction lasts; throws kCorrupt naming it
  // when it is missing.
  // `head`: the bytes of it the reader needs (storage::ReadTxn::get).
  void with_value(Table table, std::uint64_t id, const std::function<void(storage::ByteView)>& f,
                  std::size_t head = storage::ReadTxn::kWhole) const;
  // Reads and decodes one item of `kind` (the cache's loader) from its table.
  storage::PageCache<CacheItem>::Loaded load(std::uint64_t kind, Table table,
                                             std::uint64_t id) const;
  // Where R-tree node `node` is: a leaf in its page's value (page.h, PageValue), or the rtree
  // table.
  Table node_table(std::uint64_t node) const {
    return node < page_count_ ? Table::kPages : Table::kRtree;
  }
  // Cache keys are (kind << 60) | id. Kinds: 1 data pages decoded without their links, 2 locator
  // blocks, 3 R-tree nodes, 4 data pages with their links.
  static constexpr std::uint64_t kRtreeNodes = 3;
  static constexpr std::uint64_t kLinkedPages = 4;
  std::uint64_t page_kind() const {
    return links_.load(std::memory_order_relaxed) ? kLinkedPages : 1;
  }
  Locator locate(OpId id) const;
  void maybe_release(bool trim = true) const;  // trim: malloc_trim the heap too
  std::uint64_t value_bytes_read() const;      // DatabaseStats::lmdb_bytes_read

  class Prefetcher;
  void decode_ahead(std::uint64_t page) const;  // the prefetcher's work: into the cache

  std::unique_ptr<storage::Env> env_;
  std::unique_ptr<storage::PageCache<CacheItem>> cache_;
  std::unique_ptr<index::RTree> rtree_;
  CrmrInfo info_;
  QuantGrid grid_;
  std::uint64_t op_count_ = 0, page_count_ = 0;
  std::string meta_json_;
  mutable std::atomic<std::uint64_t> pages_read_{0}, page_bytes_read_{0}, nodes_read_{0};
  mutable std::atomic<std::uint64_t> rtree_bytes_read_{0}, locator_bytes_read_{0};
  mutable std::atomic<std::uint64_t> pages_prefetched_{0};
  mutable std::atomic<bool> links_{false};  // need_links() was called
  mutable std::atomic<std::uint64_t> released_at_{0};
  // Names this database (and its cache's contents) in each thread's memo of the last page and
  // locator block it read (cached()): a new number after clear_cache().
  mutable std::atomic<std::uint64_t> instance_{0};
  std::unique_ptr<Prefetcher> prefetcher_;  // last: stopped before anything it reads
};

}  // namespace smr
