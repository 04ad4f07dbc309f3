// Database (database.h): the meta record and the R-tree's header at open, then op locators, data
// pages and R-tree nodes on demand through one page cache.
#include "smr/db/database.h"

#include <algorithm>
#include <array>
#include <condition_variable>
#include <exception>
#include <optional>
#include <stop_token>
#include <string>
#include <string_view>
#include <thread>

#include <malloc.h>

#include <nlohmann/json.hpp>

#include "base/error.h"
#include "smr/db/meta.h"
#include "smr/db/page.h"
#include "storage/checksum.h"

namespace smr {

using nlohmann::json;
using storage::ByteReader;
using storage::Bytes;
using storage::ByteView;

namespace {

std::atomic<std::uint64_t> next_instance{1};  // Database::instance_ values, never reused

// A cached value's own cost beyond its payload: the shared_ptr's block holding the variant and the
// cache's list and map nodes.
constexpr std::size_t kCacheItemOverhead = 160;
// Every this many bytes read from LMDB, the mapped file pages read so far are dropped from the
// process (they count in its RSS) and glibc returns the free heap pages in the middle of its arena
// (malloc_trim): decoded pages are many small blocks, and the cache's evictions free them in an
// order that leaves most heap pages partly used. On a whole-database output (1.2 M triangles,
// 64 MiB cache) peak RSS is 196 MiB at 16 MiB intervals, 180 at 4, 172 at 1.
constexpr std::uint64_t kReleaseEveryBytes = std::uint64_t{1} << 20;

std::string key_text(std::uint64_t key) {
  return std::to_string(key);
}

// Runs `f`; an smr::Error it throws that does not name the database file yet (checksum and R-tree
// errors name only the table and key) is rethrown with the path in front.
template <class F>
auto naming_file(const std::string& path, F&& f) -> decltype(f()) {
  try {
    return f();
  } catch (const Error& e) {
    const std::string what = e.what();
    if (what.rfind(path, 0) == 0) throw;
    throw Error(e.kind(), path + ": " + what);
  }
}

// Refuses a database of another format, naming it and the command that rebuilds it.
[[noreturn]] void refuse_format(const std::string& path, int version, const json& meta) {
  std::string source = "SOURCE";
  if (meta.contains("model") && meta["model"].contains("source") &&
      meta["model"]["source"].is_string() && !meta["model"]["source"].get<std::string>().empty())
    source = meta["model"]["source"].get<std::string>();
  throw_input(path + ": database format " + std::to_string(version) +
              " is not supported (this smrdb reads format " + std::to_string(kDatabaseFormat) +
              "); rebuild it from its source: smrdb ingest " + source + " -o " + path + " --force");
}

// The meta record, parsed: a file that is not a complete smrdb database, or one of another
// format (refuse_format), throws naming the path.
json read_meta(const storage::Env& env, const std::string& path) {
  const storage::ReadTxn txn = env.read();
  const auto meta = txn.get(Table::kMeta, "meta");
  if (!meta) {
    throw_input(path +
                ": not a complete smrdb database (no meta record; an ingest was "
                "interrupted or this is another LMDB file)");
  }
  const ByteView text =
      naming_file(path, [&] { return storage::unseal(*meta, table_name(Table::kMeta), "meta"); });
  try {
    json j = json::parse(text.begin(), text.end());
    if (j.at("format").get<std::string>() != "smrdb") throw_input(path + ": not an smrdb database");
    if (j.at("version").get<int>() != kDatabaseFormat)
      refuse_format(path, j.at("version").get<int>(), j);
    return j;
  } catch (const json::exception& e) {
    throw Error(ErrorKind::kCorrupt, path + ": meta record is malformed: " + e.what());
  }
}

// Opens the file's tables. A format-2 database (its op locators' table was "nodes") is refused
// by read_meta; any other failure is the first open's.
std::unique_ptr<storage::Env> open_env(const std::string& path) {
  try {
    return std::make_unique<storage::Env>(storage::Env::open_read_only(path, kTableNames));
  } catch (const Error& first) {
    if (first.kind() != ErrorKind::kCorrupt) throw;
    constexpr std::array<std::string_view, 5> kFormat2Tables = {"meta", "nodes", "pages", "rtree",
                                                                "aux"};
    std::optional<storage::Env> old;
    try {
      old.emplace(storage::Env::open_read_only(path, kFormat2Tables));
    } catch (const Error&) {
      throw first;
    }
    (void)read_meta(*old, path);  // throws for every file but a format-3 one
    throw first;                  // format 3 under format 2's table names: damaged
  }
}

}  // namespace

// Each thread's last pages and locator blocks (8 of each, direct-mapped): extraction reads ops
// page by page, and most op() and locality() calls then find their page and locator here without
// the cache's lock and hash lookup. A memo keeps its items alive: up to 8 pages and 8 blocks per
// thread beyond the cache's budget.
struct Database::Memo {
  static constexpr std::size_t kSlots = 8;  // direct-mapped by key: a sweep alternates few pages
  struct Slot {
    std::uint64_t instance = 0, key = 0;
    std::shared_ptr<const CacheItem> item;
  };
  std::array<Slot, kSlots> slots;
  Slot& slot(std::uint64_t key) { return slots[key % kSlots]; }
  void forget(std::uint64_t instance) {
    for (Slot& s : slots) {
      if (s.instance == instance) s = Slot{};
    }
  }
};

Database::Memo& Database::memo(std::uint64_t kind) {
  // Kind 1 or 4: pages (without or with links: the key tells them apart), 2: locator blocks.
  thread_local std::array<Memo, 2> memos;
  return memos[kind == 2 ? 1 : 0];
}

// Decodes hinted pages into the cache on a thread of its own, the latest hint first come first
// served; a page already cached is skipped. Errors are left for the reader to meet.
class Database::Prefetcher {
 public:
  explicit Prefetcher(const Database& db)
      : db_(db), thread_([this](const std::stop_token& stop) { run(stop); }) {}
  ~Prefetcher() {
    thread_.request_stop();
    wake_.notify_all();
  }
  void want(std::vector<std::uint64_t> pages) {  // in this order
    {
      std::lock_guard lock(mutex_);
      queue_ = std::move(pages);
      next_ = 0;
    }
    wake_.notify_one();
  }
  // A reader is about to read `page` through the cache: returns once the page is not being
  // decoded here (the reader then finds it cached), and keeps this thread off it until done().
  void reading(std::uint64_t page) {
    std::unique_lock lock(mutex_);
    done_.wait(lock, [&] { return !busy_ || current_ != page; });
    readers_.push_back(page);
  }
  void done(std::uint64_t page) {
    std::lock_guard lock(mutex_);
    readers_.erase(std::find(readers_.begin(), readers_.end(), page));
  }
  // reading() .. done() around a reader's own read of a page; nothing without a prefetcher.
  class Reading {
   public:
    Reading(Prefetcher* p, std::uint64_t page) : p_(p), page_(page) {
      if (p_ != nullptr) p_->reading(page_);
    }
    Reading(const Reading&) = delete;
    Reading& operator=(const Reading&) = delete;
    ~Reading() {
      if (p_ != nullptr) p_->done(page_);
    }

   private:
    Prefetcher* p_;
    std::uint64_t page_;
  };

 private:
  void run(const std::stop_token& stop) {
    while (true) {
      {
        std::unique_lock lock(mutex_);
        if (!wake_.wait(lock, stop, [&] { return next_ < queue_.size(); })) return;
        current_ = queue_[next_++];
        if (std::find(readers_.begin(), readers_.end(), current_) != readers_.end()) continue;
        busy_ = true;
      }
      try {
        db_.decode_ahead(current_);
      } catch (...) {  // NOLINT(bugprone-empty-catch): the reader meets the same error
      }
      {
        std::lock_guard lock(mutex_);
        busy_ = false;
      }
      done_.notify_all();
    }
  }
  const Database& db_;
  std::mutex mutex_;
  std::condition_variable_any wake_;
  std::condition_variable done_;
  std::vector<std::uint64_t> queue_;
  std::size_t next_ = 0;
  std::uint64_t current_ = 0;
  bool busy_ = false;
  std::vector<std::uint64_t> readers_;  // pages readers are reading themselves
  std::jthread thread_;                 // last: started once the rest exists, stopped first
};

std::size_t Database::prefetch(std::span<const std::uint64_t> pages) const {
  if (prefetcher_ == nullptr || pages.empty()) return 0;
  // At most a quarter of the cache ahead, or the pages prefetched first would be evicted by the
  // later ones before they are read. Pages are sized by those decoded so far (256 KiB before).
  const std::uint64_t decoded = pages_read_.load(std::memory_order_relaxed);
  const std::uint64_t page_bytes =
      decoded == 0 ? std::uint64_t{256} << 10 : cache_->stats().bytes_decoded / decoded + 1;
  const std::size_t most = std::min<std::uint64_t>(pages.size(), cache_->budget() / 4 / page_bytes);
  // The first page is the reader's next: it reads it itself.
  if (most <= 1) return most;
  std::vector<std::uint64_t> missing =
      uncached(page_kind(), pages.subspan(1, most - 1), page_count_);
  if (!missing.empty()) prefetcher_->want(std::move(missing));
  return most;
}

// The ids (below `count`) of items of `kind` the cache lacks, in their order.
std::vector<std::uint64_t> Database::uncached(std::uint64_t kind,
                                              std::span<const std::uint64_t> ids,
                                              std::uint64_t count) const {
  std::vector<std::uint64_t> keys;
  keys.reserve(ids.size());
  for (std::uint64_t id : ids) {
    if (id < count) keys.push_back((kind << 60) | id);
  }
  std::vector<std::uint64_t> missing = cache_->missing(keys);
  for (std::uint64_t& k : missing) k &= (std::uint64_t{1} << 60) - 1;
  return missing;
}

void Database::will_need(std::span<const std::uint64_t> pages) const {
  const std::vector<std::uint64_t> missing = uncached(page_kind(), pages, page_count_);
  if (!missing.empty())
    naming_file(path(), [&] { env_->read().will_need(Table::kPages, missing); });
}

void Database::need_links() const {
  if (links_.load(std::memory_order_acquire) || links_.exchange(true)) return;
  // The first reader to ask: from now on pages are read whole (page_kind), and the copies without
  // links would only hold cache space until the LRU let them go.
  cache_->erase_if([](std::uint64_t key) { return key >> 60 == 1; });
}

void Database::will_need_locators(std::span<const OpId> ids) const {
  std::vector<std::uint64_t> blocks;
  for (OpId id : ids) {  // grouped by page, so neighbours often share a block
    const std::uint64_t b = id.value / kOpsPerLocatorBlock;
    if (blocks.empty() || blocks.back() != b) blocks.push_back(b);
  }
  std::sort(blocks.begin(), blocks.end());
  blocks.erase(std::unique(blocks.begin(), blocks.end()), blocks.end());
  const std::vector<std::uint64_t> missing =
      uncached(2, blocks, (op_count_ + kOpsPerLocatorBlock - 1) / kOpsPerLocatorBlock);
  if (!missing.empty())
    naming_file(path(), [&] { env_->read().will_need_leaves(Table::kOpLocators, missing); });
}

void Database::decode_ahead(std::uint64_t page) const {
  const std::uint64_t kind = page_kind();
  if (cache_->contains((kind << 60) | page)) return;
  fetch(kind, Table::kPages, page);
  pages_prefetched_.fetch_add(1, std::memory_order_relaxed);
}

std::unique_ptr<Database> Database::open(const std::string& path, const Options& options) {
  std::unique_ptr<Database> db(new Database());
  if (options.prefetch && std::thread::hardware_concurrency() > 1)
    db->prefetcher_ = std::make_unique<Prefetcher>(*db);
  db->env_ = open_env(path);
  db->cache_ = std::make_unique<storage::PageCache<CacheItem>>(options.cache_bytes);
  db->instance_.store(next_instance.fetch_add(1));
  const json j = read_meta(*db->env_, path);
  try {
    db->info_ = json_info(j.at("model"));
    db->grid_.origin = json_vec(j.at("grid").at("origin"));
    db->grid_.step = json_vec(j.at("grid").at("step"));
    db->op_count_ = j.at("counts").at("ops").get<std::uint64_t>();
    db->page_count_ = j.at("counts").at("pages").get<std::uint64_t>();
    db->meta_json_ = j.dump(2);
  } catch (const json::exception& e) {
    throw Error(ErrorKind::kCorrupt, path + ": meta record is malformed: " + e.what());
  }
  const storage::ReadTxn txn = db->env_->read();
  const auto header = txn.get(Table::kRtree, kRtreeHeaderKey);
  if (!header) throw Error(ErrorKind::kCorrupt, path + ": the R-tree header is missing");
  const Database* self = db.get();
  db->rtree_ = naming_file(path, [&] {
    return std::make_unique<index::RTree>(
        *header,
        [self](std::uint64_t node) {
          return std::get<Bytes>(*self->cached(kRtreeNodes, self->node_table(node), node));
        },
        std::string(table_name(Table::kRtree)), std::string(table_name(Table::kPages)));
  });
  db->rtree_->set_advise([self](std::span<const std::uint64_t> nodes) {
    const std::vector<std::uint64_t> missing =
        self->uncached(kRtreeNodes, nodes, self->rtree_->node_count());
    if (missing.empty()) return;
    // The children of one node: all leaves (the heads of pages values) or none.
    const Table table = self->node_table(missing.front());
    self->env_->read().will_need(
        table, missing, table == Table::kPages ? kLeafHeadBytes : storage::ReadTxn::kWhole);
  });
  if (db->rtree_->entry_count() != db->op_count_ || db->rtree_->leaf_count() != db->page_count_)
    throw Error(ErrorKind::kCorrupt, path + ": R-tree and meta disagree on the counts");
  return db;
}

Database::~Database() {
  prefetcher_.reset();  // before the memos are forgotten and the cache goes
  for (std::uint64_t kind : {1, 2})
    memo(kind).forget(instance_.load());  // this thread's (others'
                                          // lapse: never matched)
}

const std::string& Database::path() const {
  return env_->path();
}
std::uint64_t Database::file_bytes() const {
  return env_->file_bytes();
}

std::uint64_t Database::value_bytes_read() const {
  // Not env_->bytes_read(): that counts a whole pages value for a leaf read from its head.
  return page_bytes_read_.load(std::memory_order_relaxed) +
         rtree_bytes_read_.load(std::memory_order_relaxed) +
         locator_bytes_read_.load(std::memory_order_relaxed);
}

void Database::maybe_release(bool trim) const {
  const std::uint64_t read = value_bytes_read();
  std::uint64_t last = released_at_.load();
  if (read - last >= kReleaseEveryBytes && released_at_.compare_exchange_strong(last, read)) {
    env_->release_mapped_pages();
    if (trim) malloc_trim(0);
  }
}

std::shared_ptr<const Database::CacheItem> Database::fetch(std::uint64_t kind, Table table,
                                                           std::uint64_t id) const {
  return cache_->get((kind << 60) | id,
                     [&]() { return naming_file(path(), [&] { return load(kind, table, id); }); });
}

std::shared_ptr<const Database::CacheItem> Database::cached(std::uint64_t kind, Table table,
                                                            std::uint64_t id) const {
  if (kind == kRtreeNodes) return fetch(kind, table, id);
  memoized(kind, table, id);
  return memo(kind).slot(id).item;
}

const Database::CacheItem& Database::memoized(std::uint64_t kind, Table table,
                                              std::uint64_t id) const {
  const std::uint64_t key = (kind << 60) | id;
  Memo::Slot& m = memo(kind).slot(id);
  const std::uint64_t instance = instance_.load(std::memory_order_relaxed);
  if (m.instance != instance || m.key != key) {
    const Prefetcher::Reading reading(kind != 2 ? prefetcher_.get() : nullptr, id);
    m = Memo::Slot{instance, key, fetch(kind, table, id)};
  }
  return *m.item;
}

void Database::with_value(Table table, std::uint64_t id, const std::function<void(ByteView)>& f,
                          std::size_t head) const {
  const storage::ReadTxn txn = env_->read();
  const auto value = txn.get(table, id, head);
  if (!value)
    throw Error(ErrorKind::kCorrupt, path() + ": " + std::string(table_name(table)) + "/" +
                                         key_text(id) + " is missing");
  f(*value);
}

void Database::with_page_bytes(std::uint64_t page, const std::function<void(ByteView)>& f) const {
  naming_file(path(), [&] {
    with_value(Table::kPages, page, [&](ByteView raw) {
      const std::string key = key_text(page);
      const ByteView sealed = split_page_value(raw, table_name(Table::kPages), key).page;
      page_bytes_read_.fetch_add(sealed.size());
      f(storage::unseal(sealed, table_name(Table::kPages), key));
    });
  });
  pages_read_.fetch_add(1);
  // The mapped file's pages, as reads through the cache let them go; not the heap's (a reader
  // past the cache holds no decoded page, and trimming every MiB cost the level cut ~20 %).
  maybe_release(false);
}

storage::PageCache<Database::CacheItem>::Loaded Database::load(std::uint64_t kind, Table table,
                                                               std::uint64_t id) const {
  storage::PageCache<CacheItem>::Loaded loaded;
  const std::string name = std::string(table_name(table)) + "/" + key_text(id);
  Bytes raw;
  const bool leaf = kind == kRtreeNodes && table == Table::kPages;
  with_value(
      table, id,
      [&](ByteView v) {
        // A pages value holds an R-tree leaf, then its data page (page.h, PageValue).
        ByteView part = v;
        if (table == Table::kPages) {
          const PageValue both = split_page_value(v, table_name(table), key_text(id));
          part = leaf ? both.leaf : both.page;
        }
        raw.assign(part.begin(), part.end());
      },
      leaf ? kLeafHeadBytes : storage::ReadTxn::kWhole);
  loaded.bytes_read = raw.size();
  if (kind == kRtreeNodes) {
    loaded.charged_bytes = kCacheItemOverhead + heap_block_bytes(raw.capacity());
    rtree_bytes_read_.fetch_add(raw.size());
    loaded.value = std::make_shared<const CacheItem>(std::move(raw));
    nodes_read_.fetch_add(1);
  } else if (table == Table::kPages) {
    const ByteView payload = storage::unseal(raw, table_name(table), key_text(id));
    std::shared_ptr<const DecodedPage> ops =
        decode_page(payload, grid_, info_, path() + ": " + name, kind == kLinkedPages);
    loaded.charged_bytes = kCacheItemOverhead + ops->memory_bytes();
    loaded.value = std::make_shared<const CacheItem>(std::move(ops));
    pages_read_.fetch_add(1);
    page_bytes_read_.fetch_add(raw.size());
  } else {
    locator_bytes_read_.fetch_add(raw.size());
    const ByteView payload = storage::unseal(raw, table_name(table), key_text(id));
    ByteReader r(payload, path() + ": " + name);
    const std::uint64_t n = r.varint();
    if (n > kOpsPerLocatorBlock) r.fail("too many locators");
    std::vector<Locator> locs(n);
    std::uint64_t prev = 0;
    for (Locator& l : locs) {
      l.page = prev + std::uint64_t(r.svarint());
      prev = l.page;
      l.slot = std::uint32_t(r.varint());
    }
    r.expect_end();
    loaded.charged_bytes = kCacheItemOverhead + heap_block_bytes(locs.capacity() * sizeof(Locator));
    loaded.value = std::make_shared<const CacheItem>(std::move(locs));
  }
  maybe_release();
  return loaded;
}

Database::Locator Database::locate(OpId id) const {
  if (id.value >= op_count_)
    throw_input(path() + ": op " + std::to_string(id.value) + " does not exist (the database has " +
                std::to_string(op_count_) + " ops)");
  const auto& locs = std::get<std::vector<Locator>>(
      memoized(2, Table::kOpLocators, id.value / kOpsPerLocatorBlock));
  const std::uint64_t i = id.value % kOpsPerLocatorBlock;
  if (i >= locs.size() || locs[i].page >= page_count_)
    throw Error(ErrorKind::kCorrupt, path() + ": " + std::string(table_name(Table::kOpLocators)) +
                                         "/" + key_text(id.value / kOpsPerLocatorBlock) +
                                         ": no valid locator for op " + key_text(id.value));
  return locs[i];
}

std::shared_ptr<const DecodedPage> Database::page(std::uint64_t page) const {
  if (page >= page_count_) throw_input(path() + ": page " + key_text(page) + " does not exist");
  return std::get<std::shared_ptr<const DecodedPage>>(*cached(page_kind(), Table::kPages, page));
}

std::uint64_t Database::locality_bytes(std::uint64_t p) const {
  return page(p)->memory_bytes();
}

OpBatch Database::batch(std::uint64_t page_id) const {
  std::shared_ptr<const DecodedPage> p = page(page_id);
  const std::span<const OpView> ops = p->ops();
  return {std::move(p), ops};
}

OpRef Database::op(OpId id) const {
  const Locator loc = locate(id);
  auto ops = page(loc.page);
  if (loc.slot >= ops->size() || (*ops)[loc.slot].id != id)
    throw Error(ErrorKind::kCorrupt, path() + ": pages/" + key_text(loc.page) +
                                         " does not hold op " + key_text(id.value) + " where " +
                                         std::string(table_name(Table::kOpLocators)) + "/ says");
  return OpRef(ops, &(*ops)[loc.slot]);
}

std::vector<index::Hit> Database::rtree_query(index::Visitor& visitor) const {
  return naming_file(path(), [&] { return rtree_->query(visitor); });
}

DatabaseStats Database::stats() const {
  DatabaseStats s;
  s.cache = cache_->stats();
  s.pages_read = pages_read_.load();
  s.pages_prefetched = pages_prefetched_.load();
  s.page_bytes_read = page_bytes_read_.load();
  s.rtree_nodes_read = nodes_read_.load();
  s.rtree_bytes_read = rtree_bytes_read_.load();
  s.locator_bytes_read = locator_bytes_read_.load();
  s.lmdb_bytes_read = value_bytes_read();
  return s;
}

void Database::clear_cache() const {
  // Every thread's memo lapses; this thread's lets go of its items now.
  const std::uint64_t old = instance_.exchange(next_instance.fetch_add(1));
  for (std::uint64_t kind : {1, 2}) memo(kind).forget(old);
  cache_->clear();
}

}  // namespace smr
