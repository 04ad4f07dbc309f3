// What the two writers (writer.h) share, internal to smr/db: the ops' index records, the shares
// of WriteOptions::sort_bytes, and write_tables, where both end.
//
// write_tables takes the ops' index records through external sorts (storage/external_sort.h)
// under WriteOptions::sort_bytes: the R-tree order (index::EntryOrder) and the locators' id
// order. The stream writer derives ROIs and subtree cones by a backward sweep over its records on
// disk, children sending theirs to their parents through an ExternalQueue (time-forward
// processing, Chiang et al. 1995). What stays in memory is the budget, one summary per data page
// (the R-tree's upper levels) and a window of pages.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "index/rtree.h"
#include "smr/core/clock.h"
#include "smr/core/crmr.h"
#include "smr/db/quantize.h"
#include "smr/db/writer.h"
#include "storage/external_sort.h"
#include "storage/lmdb_env.h"

namespace smr {

// What the index and a data page need of an op; fixed size, so the sorts can spill it.
struct OpEntry {
  std::uint64_t id = 0;
  index::Box roi, box;
  double res = 0.0;
  std::uint32_t weight = 0;      // estimated page bytes
  std::uint32_t spool_size = 0;  // stream writer: the op's bytes in the spool
  std::uint64_t spool_at = 0;    //                and where they start
  NormalCone cone;               // the subtree cone once derived
  index::Entry index_entry() const { return {id, roi, box, res, weight}; }
};

struct SortedEntry {
  index::OrderKey key;
  OpEntry entry;
  bool operator<(const SortedEntry& o) const { return key < o.key; }
};

using EntrySorter = storage::ExternalSorter<SortedEntry>;

index::BuildOptions rtree_options(const CrmrInfo& header, const WriteOptions& options);

// Shares of WriteOptions::sort_bytes: the entry sort holds half, the backward sweep's queue and
// the locator sort (never alive together) a quarter each.
inline std::uint64_t entry_sort_bytes(const WriteOptions& o) {
  return o.sort_bytes / 2;
}
inline std::uint64_t side_sort_bytes(const WriteOptions& o) {
  return o.sort_bytes / 4;
}

// The op's entry with the given ROI and subtree cone.
OpEntry entry_of(const Op& op, ModelKind kind, const Box3& roi, const NormalCone& cone);

// Opens the LMDB writer of a database at `path`, with the tables of tables.h.
storage::DatabaseWriter open_writer(const std::string& path, const WriteOptions& options);

// Writes pages (in R-tree leaf order, with the R-tree's leaves), locators, the R-tree's upper
// levels and the meta record (last), then commits. `sorted` holds every op's entry; `ops_of(run,
// held)` returns the ops of consecutive entries (about a page's worth, in leaf order), in their
// order, as a page must hold them (snapped, ROI, subtree cone, error shifted): ops that outlive
// the call or ones it appends to `held` (a fresh vector a call, with room reserved for the ops, so
// earlier pointers stay valid). It is called from several threads at once.
struct TableCounts {
  std::uint64_t ops = 0, triangles = 0, dag_depth = 0;
};
using OpsOf =
    std::function<std::vector<const Op*>(std::span<const OpEntry>, std::vector<Op>& held)>;
WriteReport write_tables(storage::DatabaseWriter& writer, const CrmrInfo& header,
                         const QuantGrid& grid, double z_shift, EntrySorter& sorted,
                         const TableCounts& counts, const OpsOf& ops_of,
                         const WriteOptions& options, const std::string& tmp_dir);

}  // namespace smr
