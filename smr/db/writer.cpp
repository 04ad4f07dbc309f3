// The whole-CRMR writer and what both writers end in (write_tables.h): data pages in R-tree leaf
// order (Maheshwari 4.4's packed R-tree over ROI boxes; one leaf <-> one page), the op locators,
// the R-tree's upper levels and the meta record, last.
#include <algorithm>
#include <chrono>
#include <span>

#include <nlohmann/json.hpp>

#include "base/error.h"
#include "smr/core/parallel.h"
#include "smr/db/index_box.h"
#include "smr/db/meta.h"
#include "smr/db/page.h"
#include "smr/db/tables.h"
#include "smr/db/write_tables.h"
#include "smr/db/writer.h"
#include "storage/checksum.h"
#include "storage/temp_file.h"

namespace smr {

using nlohmann::json;
using storage::Bytes;
using storage::ByteView;
using storage::ByteWriter;

namespace {

// Rough encoded size of an op, for packing leaves into pages of about WriteOptions::page_bytes.
// A vertex costs most in 3-D: three coordinates on a grid of 2^-28 of the extent, which differ
// in their low bits from one vertex to the next, where a terrain vertex has two on the DEM's
// lattice. Measured on 16 KiB pages: 2 bytes a vertex fill terrain pages to 0.87 of the target
// (Jacksboro, median; none over); in 3-D they overfilled every page 1.27-1.47x (past 4 LMDB
// pages), 13 bytes fill them to 0.88-0.94 (median) with the largest at 0.95-1.01 (the seven
// CGAL meshes but the pig).
std::uint32_t estimated_bytes(const Op& op, ModelKind kind) {
  const std::size_t per_vertex = kind == ModelKind::kMesh3d ? 13 : 2;
  return static_cast<std::uint32_t>(24 + 4 * op.fragment.size() + per_vertex * op.vertices.size() +
                                    5 * op.pre.size() + 5 * op.coarser.size() +
                                    10 * op.children.size());
}

// Where an op is stored: its data page and slot (table op locators, tables.h).
struct Locator {
  std::uint64_t id = 0, page = 0;
  std::uint32_t slot = 0;
  bool operator<(const Locator& o) const { return id < o.id; }
};
// Ids are unique: the locators' sort keeps no arrival numbers.
using LocatorSorter = storage::ExternalSorter<Locator, std::less<Locator>, storage::Ties::kAny>;

Bytes encode_locators(std::span<const std::pair<std::uint64_t, std::uint32_t>> locs) {
  Bytes b;
  ByteWriter w(b);
  w.varint(locs.size());
  std::uint64_t prev = 0;
  for (const auto& [page, slot] : locs) {
    w.svarint(std::int64_t(page - prev));
    prev = page;
    w.varint(slot);
  }
  return b;
}

void progress_to(const WriteOptions& options, double f) {
  if (options.progress) options.progress(f);
}

// The data pages, leaves cut from the sorted entries a window at a time: their pages are encoded
// on every core, and while the helpers start on a window the calling thread appends the previous
// one's pages, in order, with their locators (to `locators`) and R-tree leaves (to `tree`).
// Returns the number of ops placed.
std::uint64_t write_pages(storage::DatabaseWriter& writer, EntrySorter& sorted, const OpsOf& ops_of,
                          const QuantGrid& grid, const index::BuildOptions& bo,
                          const WriteOptions& options, std::uint64_t op_count,
                          index::TreeWriter& tree, LocatorSorter& locators, WriteReport& report) {
  const unsigned threads = thread_count(options.threads);
  const std::size_t window = 8 * std::size_t(threads);
  struct Window {
    std::vector<std::vector<OpEntry>> leaves;
    std::vector<Bytes> pages;
  };
  Window filling, encoded;
  std::vector<index::Entry> leaf_entries;
  std::uint64_t placed = 0;
  WorkerPool pool(threads);  // its threads keep their codec contexts from window to window
  auto append_encoded = [&] {
    for (std::size_t j = 0; j < encoded.leaves.size(); ++j) {
      const std::vector<OpEntry>& leaf = encoded.leaves[j];
      const std::uint64_t page = report.pages++;
      report.page_bytes += encoded.pages[j].size();
      writer.append(Table::kPages, page, encoded.pages[j]);
      leaf_entries.clear();
      for (std::uint32_t slot = 0; slot < leaf.size(); ++slot) {
        locators.add({leaf[slot].id, page, slot});
        leaf_entries.push_back(leaf[slot].index_entry());
      }
      tree.add_leaf(leaf_entries);
      placed += leaf.size();
    }
    encoded.leaves.clear();
    progress_to(options, 0.9 * double(placed) / double(std::max<std::uint64_t>(1, op_count)));
  };
  auto write_window = [&] {
    filling.pages.resize(filling.leaves.size());
    pool.for_each(
        filling.leaves.size(),
        [&](std::size_t j) {
          std::vector<Op> held;
          held.reserve(filling.leaves[j].size());
          filling.pages[j] =
              storage::seal(encode_page(ops_of(filling.leaves[j], held), grid, options.codec));
        },
        append_encoded);
    std::swap(filling, encoded);
  };
  index::LeafPacker packer(bo);
  SortedEntry s;
  while (sorted.next(s)) {
    if (packer.starts_leaf(s.entry.weight)) {
      if (filling.leaves.size() == window) write_window();
      filling.leaves.emplace_back();
    }
    filling.leaves.back().push_back(s.entry);
  }
  write_window();
  append_encoded();
  return placed;
}

// The op locators, in id order: every id from 0 exactly once, kOpsPerLocatorBlock to a value.
void write_locators(storage::DatabaseWriter& writer, LocatorSorter& locators, WriteReport& report) {
  std::vector<std::pair<std::uint64_t, std::uint32_t>> block;
  std::uint64_t expected = 0;
  auto write_block = [&] {
    const Bytes sealed = storage::seal(encode_locators(block));
    report.locator_bytes += sealed.size();
    writer.append(Table::kOpLocators, (expected - 1) / kOpsPerLocatorBlock, sealed);
    block.clear();
  };
  Locator loc;
  while (locators.next(loc)) {
    if (loc.id != expected)
      throw_internal("database writer: op " + std::to_string(expected) +
                     (loc.id < expected ? " is placed twice" : " is missing"));
    block.push_back({loc.page, loc.slot});
    ++expected;
    if (block.size() == kOpsPerLocatorBlock) write_block();
  }
  if (!block.empty()) write_block();
}

// The meta record's text (tables.h).
std::string meta_text(const CrmrInfo& header, const QuantGrid& grid, double z_shift,
                      const TableCounts& counts, const WriteReport& report,
                      const WriteOptions& options) {
  const json meta = {{"format", "smrdb"},
                     {"version", kDatabaseFormat},
                     {"checksum", "xxh3-64"},
                     {"codec", std::string(storage::codec_name(options.codec))},
                     {"model", info_json(header)},
                     {"grid", {{"origin", vec_json(grid.origin)}, {"step", vec_json(grid.step)}}},
                     {"z_shift", z_shift},
                     {"counts",
                      {{"ops", report.ops},
                       {"triangles", counts.triangles},
                       {"pages", report.pages},
                       {"rtree_nodes", report.rtree_nodes},
                       {"dag_depth", counts.dag_depth}}},
                     {"bytes",
                      {{"pages", report.page_bytes},
                       {"locators", report.locator_bytes},
                       {"rtree", report.rtree_bytes}}},
                     {"page_bytes_target", options.page_bytes},
                     {"parameters", options.parameters}};
  return meta.dump();
}

}  // namespace

index::BuildOptions rtree_options(const CrmrInfo& header, const WriteOptions& options) {
  index::BuildOptions bo;
  bo.leaf_weight = options.page_bytes;
  bo.fanout = options.rtree_fanout;
  bo.order_dims = header.kind == ModelKind::kTerrain ? 2 : 3;
  return bo;
}

OpEntry entry_of(const Op& op, ModelKind kind, const Box3& roi, const NormalCone& cone) {
  OpEntry e;
  e.id = op.id.value;
  e.roi = to_index(roi);
  e.box = to_index(op.box);
  e.res = op.birth_res;
  e.weight = estimated_bytes(op, kind);
  e.cone = cone;
  return e;
}

storage::DatabaseWriter open_writer(const std::string& path, const WriteOptions& options) {
  return storage::DatabaseWriter(path, kTableNames, options.force, options.batch_bytes);
}

WriteReport write_tables(storage::DatabaseWriter& writer, const CrmrInfo& header,
                         const QuantGrid& grid, double z_shift, EntrySorter& sorted,
                         const TableCounts& counts, const OpsOf& ops_of,
                         const WriteOptions& options, const std::string& tmp_dir) {
  const auto started = Clock::now();
  WriteReport report;
  report.grid = grid;
  report.z_shift = z_shift;
  report.ops = counts.ops;
  const index::BuildOptions bo = rtree_options(header, options);
  // The leaves' summaries (one per page) wait in a scratch file for the upper levels.
  index::TreeWriter tree(
      bo,
      [&](std::uint64_t id, ByteView node) {
        report.rtree_bytes += node.size();
        ++report.rtree_nodes;
        writer.append(Table::kRtree, id, node);
      },
      tmp_dir);
  LocatorSorter locators(tmp_dir, side_sort_bytes(options));
  const std::uint64_t placed =
      write_pages(writer, sorted, ops_of, grid, bo, options, counts.ops, tree, locators, report);
  if (placed != counts.ops)
    throw_internal("database writer: " + std::to_string(placed) + " ops reached the pages, not " +
                   std::to_string(counts.ops));
  write_locators(writer, locators, report);
  // The R-tree's upper levels, then its header.
  writer.append(Table::kRtree, kRtreeHeaderKey, tree.finish());
  progress_to(options, 0.95);

  const std::string text = meta_text(header, grid, z_shift, counts, report, options);
  writer.put(Table::kMeta, "meta", storage::seal(storage::as_bytes(text)));  // last
  const auto committing = Clock::now();
  report.seconds_tables = seconds_since(started);
  writer.finish();
  report.seconds_commit = seconds_since(committing);
  report.file_bytes = storage::Env::open_read_only(writer.path(), kTableNames).file_bytes();
  report.dag_depth = counts.dag_depth;
  report.triangles = counts.triangles;
  report.scratch_bytes += sorted.spilled_bytes() + locators.spilled_bytes();
  progress_to(options, 1.0);
  return report;
}

WriteReport write_database(Crmr& crmr, const std::string& path, const WriteOptions& options) {
  const auto t0 = Clock::now();
  // Opening the writer first checks the path (exists without --force) before any work.
  storage::DatabaseWriter writer = open_writer(path, options);
  const QuantGrid grid = choose_grid(crmr.header, options.z_quantum);
  const double shift = quantize(crmr, grid);  // ROIs and subtree cones derived too
  const std::string tmp_dir = storage::scratch_dir("");
  TableCounts counts;
  counts.ops = crmr.ops.size();
  index::EntryOrder order(rtree_options(crmr.header, options));
  std::vector<std::uint32_t> depth(crmr.ops.size(), 0);  // longest parent chain from R^0
  for (const Op& op : crmr.ops) {
    if (op.id.value >= crmr.ops.size() || &op != &crmr.ops[op.id.value])
      throw_internal("database writer: op " + std::to_string(op.id.value) + " is out of place");
    order.observe(entry_of(op, crmr.header.kind, op.roi, op.subtree_cone).index_entry());
    std::uint32_t& d = depth[op.id.value];
    for (OpId p : op.parents) {
      if (p.value < op.id.value) d = std::max(d, depth[p.value] + 1);  // always, in a valid CRMR
    }
    counts.dag_depth = std::max<std::uint64_t>(counts.dag_depth, d);
    counts.triangles += op.fragment.size();
  }
  EntrySorter sorted(tmp_dir, entry_sort_bytes(options));
  for (const Op& op : crmr.ops) {
    const OpEntry e = entry_of(op, crmr.header.kind, op.roi, op.subtree_cone);
    sorted.add({order.key(e.index_entry()), e});
  }
  WriteReport report = write_tables(
      writer, crmr.header, grid, shift, sorted, counts,
      [&](std::span<const OpEntry> page, std::vector<Op>&) {
        std::vector<const Op*> ops;
        for (const OpEntry& e : page) ops.push_back(&crmr.ops.at(e.id));
        return ops;
      },
      options, tmp_dir);
  report.seconds = seconds_since(t0);
  return report;
}

}  // namespace smr
