// Writing a database (tables.h): a whole CRMR at once (write_database) or ops streamed from a
// builder (DatabaseStreamWriter). Data pages hold ops in R-tree leaf order (one leaf <-> one page,
// Maheshwari 4.4's packed R-tree over ROI boxes), then come the op locators, the R-tree's upper
// levels and the meta record, last: a file without meta is an interrupted ingest. The same ops
// give the same bytes, whichever writer and however many threads.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "smr/core/crmr.h"
#include "smr/db/quantize.h"
#include "storage/codec.h"

namespace smr {

struct WriteOptions {
  // zstd: on real pages it is ~2x smaller than order-preserving Draco and decodes faster
  // (benchmarks/results/db_codecs.json); Draco stays available for glTF-minded users.
  storage::CodecId codec = storage::CodecId::kZstd;
  bool force = false;      // replace an existing database at the path
  double z_quantum = 0.0;  // quantization step of heights (grid.step.z); 0 = automatic (quantize.h)
  // A terrain's automatic z step is at least this: error_z_quantum of the error it was built to
  // (ingest sets it and builds to that error less half of it; choose_grid).
  double error_quantum = 0.0;
  // Most bytes of a data page's value, sealed (a page of one op may pass it). LMDB keeps a value
  // of S bytes in ceil((S + 16) / 4096) 4-KiB overflow pages, so k * 4096 - 16 fills k of them:
  // pages are filled to it by encoding their ops, not by an estimate (write_pages in writer.cpp).
  std::uint32_t page_bytes = 12 * 1024 - 16;
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
  // Runs of entries packed into pages on their own (only each run's last page may have room for
  // the next op), cut where the estimated bytes reach 64 pages.
  std::uint64_t page_runs = 0;
  std::uint64_t page_encodes = 0;  // encode_page calls that cut the pages (2.5-3.1 a page)
  // Value bytes per table (tables.h).
  std::uint64_t page_bytes = 0, locator_bytes = 0, rtree_bytes = 0;
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

}  // namespace smr
