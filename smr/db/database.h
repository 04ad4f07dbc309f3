// The on-disk LOD database (DESIGN.md sections 3, 5, 6): a CRMR written into one LMDB file —
// data pages of ops in R-tree leaf order (one leaf <-> one page), op locators, the packed R-tree
// over ROI boxes, and a `meta` record committed last — and read back lazily through a page cache
// with a byte budget. Database is an OpSource, so both extraction algorithms run on it unchanged;
// reduced extraction takes its X from the R-tree (Brown Lemma 5.2.1 via Maheshwari 4.4).
//
// Tables: meta  "meta" -> JSON (format, model info, grid, counts, build parameters), sealed
//         pages u64 leaf -> page (smr/db/page.h), sealed
//         nodes u64 block -> locators of ops 256*block .. 256*block+255: varint page, varint slot
//         rtree u64 node -> R-tree node (index/rtree.h); key 2^64-1 -> the tree's header
//         aux   unused so far
// Every value carries an xxhash checksum; a mismatch names the table and key.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <variant>
#include <vector>

#include "index/rtree.h"
#include "smr/core/crmr.h"
#include "smr/db/quantize.h"
#include "smr/extract/extract.h"
#include "storage/codec.h"
#include "storage/lmdb_env.h"
#include "storage/page_cache.h"

namespace smr {

inline constexpr int kDatabaseFormat = 2;  // 2: 8-bit R-tree boxes, bfloat16 res
inline constexpr std::uint64_t kOpsPerLocatorBlock = 256;

struct WriteOptions {
  // zstd: on real pages it is ~2x smaller than order-preserving Draco and decodes faster
  // (benchmarks/results/db_codecs.json); Draco stays available for glTF-minded users.
  storage::CodecId codec = storage::CodecId::kZstd;
  bool force = false;      // replace an existing database at the path
  double z_quantum = 0.0;  // quantization step of heights (grid.step.z); 0 = automatic (quantize.h)
  std::uint32_t page_bytes = 16 * 1024 - 16;  // target payload of a data page
  // Children per internal R-tree node. A view enters internal nodes that each contribute one or
  // two leaves, so small nodes read fewer unused bytes: 16 read 8 % fewer index bytes than 64 on
  // a 4097^2 fBm view (benchmarks/README.md), with little more than 8 gives.
  std::uint32_t rtree_fanout = 16;
  // Threads encoding pages (0 = one per core); the file does not depend on it.
  unsigned threads = 0;
  // Bytes of values buffered before each LMDB commit (memory held while writing).
  std::uint64_t batch_bytes = std::uint64_t{64} << 20;
  // Memory for the writer's external sorts (the R-tree order, the locators) and, in
  // DatabaseStreamWriter, the queue deriving ROIs: beyond it they spill to scratch files. The
  // entry sort holds half of it, the queue and the locator sort (never alive together) a quarter.
  std::uint64_t sort_bytes = std::uint64_t{128} << 20;
  std::string parameters;                // free text recorded in meta (the command line, say)
  std::function<void(double)> progress;  // fraction done, from 0 to 1
};

struct WriteReport {
  QuantGrid grid;
  double z_shift = 0.0;  // largest vertex move made by the quantization (added to every error)
  std::uint64_t ops = 0, pages = 0, rtree_nodes = 0;
  std::uint64_t page_bytes = 0, node_bytes = 0, rtree_bytes = 0;  // value bytes per table
  std::uint64_t file_bytes = 0;
  std::uint64_t dag_depth = 0;      // longest parent-to-child path from R^0
  std::uint64_t triangles = 0;      // over all fragments
  std::uint64_t spool_bytes = 0;    // DatabaseStreamWriter: ops held in its scratch file
  std::uint64_t scratch_bytes = 0;  // other scratch data: index records, sort runs
  double seconds = 0.0;  // DatabaseStreamWriter: finish() alone (spooling ran during the build)
  // Of `seconds`: the spooler's last ops and the backward sweep (DatabaseStreamWriter); the pages,
  // locators and R-tree; LMDB's commit, the compacting copy, its fsync and the rename.
  double seconds_sweep = 0.0, seconds_tables = 0.0, seconds_commit = 0.0;
};

/// Writes `crmr` to a new database file at `path`, atomically: the meta record is written last
/// and the file appears only when complete. Snaps `crmr` to the quantization grid in place first,
/// so afterwards it equals what the database holds. Throws smr::Error (kInvalidInput if `path`
/// exists without options.force).
WriteReport write_database(Crmr& crmr, const std::string& path, const WriteOptions& options);

/// Writes a database from ops streamed in id order (an OpSink: a builder hands each op over as it
/// makes it and never holds the whole CRMR). Each op is snapped to the grid (choose_grid on the
/// header given to begin()) and spooled, its fields copied as they are, to an anonymous scratch
/// file in `tmp_dir` (storage::TempFile: gone with the process however it ends), with a fixed-size
/// index record and its parents' ids in two more. Memory holds no per-op data: finish() derives
/// ROIs and subtree cones by a backward sweep over the records (children send theirs to their
/// parents through an external queue), orders the R-tree entries by an external sort, writes the
/// pages in leaf order (re-reading their ops from the spool) with the R-tree's leaves, then the
/// locators (another external sort), the R-tree's upper levels and the meta record, last; the
/// sorts and the queue stay within options.sort_bytes and spill beyond. The same ops give the
/// same bytes as write_database on the Crmr they make up. Ops are spooled on a thread of the
/// writer's own, handed over in batches of 256 (up to 8 waiting), so the builder goes on making
/// the next ones meanwhile.
class DatabaseStreamWriter final : public OpSink {
 public:
  /// Opens the output at once: an existing `path` without options.force throws before any work.
  DatabaseStreamWriter(const std::string& path, const WriteOptions& options,
                       const std::string& tmp_dir);
  ~DatabaseStreamWriter() override;  // without finish(): nothing is left at `path`
  void begin(const CrmrInfo& header, std::uint64_t op_count) override;
  void add(Op&& op) override;
  /// Snaps the op, computes its bounds and encodes it for the spool: the work add() does on
  /// its own thread, done by the caller's. A writer takes either add() or add_encoded(), not both.
  bool encodes() const override { return true; }
  void encode(Op& op, std::vector<std::uint8_t>& out) const override;
  void add_encoded(std::span<const std::uint8_t> op) override;
  WriteReport finish();
  /// The header as stored: bounds of the snapped vertices, errors raised by the largest move.
  const CrmrInfo& header() const;

 private:
  struct State;
  std::unique_ptr<State> s_;
};

struct DatabaseStats {
  storage::CacheStats cache;
  std::uint64_t pages_read = 0;       // data pages fetched from LMDB
  std::uint64_t page_bytes_read = 0;  // their bytes
  std::uint64_t rtree_nodes_read = 0;
  std::uint64_t rtree_bytes_read = 0;    // bytes of R-tree nodes fetched
  std::uint64_t locator_bytes_read = 0;  // bytes of op-locator blocks (table nodes) fetched
  std::uint64_t lmdb_bytes_read = 0;     // every value fetched from LMDB
};

class Database final : public OpSource, public RcfIndexedSource {
 public:
  struct Options {
    std::size_t cache_bytes = std::size_t{64} << 20;
  };
  /// Opens a database read-only. A missing file, a file that is not a complete smrdb database (no
  /// meta record: an interrupted ingest), or an unknown format throws smr::Error naming the path.
  static std::unique_ptr<Database> open(const std::string& path, const Options& options);
  ~Database() override;

  const CrmrInfo& info() const override { return info_; }
  std::uint64_t op_count() const override { return op_count_; }
  OpRef op(OpId id) const override;
  /// Reduced extraction's X from the R-tree: every op not completely finer than `rcf`.
  /// Reduced extraction's X from the R-tree: every op not completely finer than `rcf`. Reads
  /// the R-tree nodes the query enters and the data pages of the entries it accepts.
  std::vector<OpId> not_completely_finer(const Rcf& rcf) const override;
  /// The entries the R-tree query accepts (a superset of not_completely_finer), reading no page.
  std::vector<OpId> maybe_not_completely_finer(const Rcf& rcf) const override;
  std::uint64_t locality(OpId id) const override { return locate(id).page; }
  /// The R-tree query behind both: accepted entries, grouped by leaf (= data page).
  std::vector<index::Hit> rcf_hits(const Rcf& rcf) const;
  const index::RTree& rtree() const { return *rtree_; }
  const QuantGrid& grid() const { return grid_; }
  std::uint64_t page_count() const { return page_count_; }
  const std::string& meta_json() const { return meta_json_; }
  const std::string& path() const;
  std::uint64_t file_bytes() const;
  DatabaseStats stats() const;
  /// Decoded ops of data page `page` (through the cache).
  std::shared_ptr<const std::vector<Op>> page(std::uint64_t page) const;
  /// Where the op locators (table `nodes`) say op `id` is: its data page and slot. Reads no page.
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
  using CacheItem = std::variant<std::vector<Op>, std::vector<Locator>, storage::Bytes>;
  std::shared_ptr<const CacheItem> cached(std::uint64_t key, storage::Table table,
                                          std::uint64_t id) const;
  // Reads and decodes one value (the cache's loader).
  storage::PageCache<CacheItem>::Loaded load(storage::Table table, std::uint64_t id) const;
  Locator locate(OpId id) const;
  void maybe_release() const;

  std::unique_ptr<storage::Env> env_;
  std::unique_ptr<storage::PageCache<CacheItem>> cache_;
  std::unique_ptr<index::RTree> rtree_;
  CrmrInfo info_;
  QuantGrid grid_;
  std::uint64_t op_count_ = 0, page_count_ = 0;
  std::string meta_json_;
  mutable std::atomic<std::uint64_t> pages_read_{0}, page_bytes_read_{0}, nodes_read_{0};
  mutable std::atomic<std::uint64_t> rtree_bytes_read_{0}, locator_bytes_read_{0};
  mutable std::atomic<std::uint64_t> released_at_{0};
};

/// `smrdb verify`: reads every value of the database and checks checksums, decoding, the op
/// locators, the DAG (parents <-> children, PreF <-> killers), Hypermesh links, and that the
/// R-tree holds every op exactly once with a conservative box, in the page of its leaf.
struct VerifyReport {
  std::vector<std::string> faults;  // empty = clean
  std::uint64_t pages = 0, ops = 0, triangles = 0, rtree_nodes = 0;
  bool ok() const { return faults.empty(); }
};
VerifyReport verify_database(const std::string& path, const std::function<void(double)>& progress);

}  // namespace smr
