// The whole-CRMR writer and what both writers end in (write_tables.h): data pages in R-tree leaf
// order (Maheshwari 4.4's packed R-tree over ROI boxes; one leaf <-> one page), the op locators,
// the R-tree's upper levels and the meta record, last.
#include <algorithm>
#include <chrono>
#include <deque>
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

// Rough encoded size of an op: it cuts the sorted entries into runs (write_pages) and proposes
// each page's first cut, which real encodes then correct (PagePacker).
// A vertex costs most in 3-D: three coordinates on a grid of 2^-24 of the extent, which differ
// in their low bits from one vertex to the next, where a terrain vertex has two on the DEM's
// lattice. Measured on 16 KiB pages: 2 bytes a vertex fill terrain pages to 0.87 of the target
// (Jacksboro, median; none over); in 3-D they overfilled every page 1.27-1.47x (past 4 LMDB
// pages), 13 bytes fill them to 0.88-0.94 (median) with the largest at 0.95-1.01 (the seven
// CGAL meshes but the pig). Measured with 16 KiB pages and the 2^-28 grid: on today's 12 KiB
// pages and 2^-24 grid it proposes cuts that the encodes then move (it decides no page).
std::uint32_t estimated_bytes(const Op& op, ModelKind kind) {
  const std::size_t per_vertex = kind == ModelKind::kMesh3d ? 13 : 2;
  // 17: the op's R-tree leaf entry, which its page's value holds too (page.h, PageValue).
  return static_cast<std::uint32_t>(41 + 4 * op.fragment.size() + per_vertex * op.vertices.size() +
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

// The R-tree leaf TreeWriter::add_leaf just put, kept for its page's value (write_pages).
struct LeafSlot {
  Bytes bytes;
  std::uint64_t id = ~std::uint64_t{0};
};

// Runs of sorted entries packed on their own (see write_pages): a run ends before the entry that
// would take its estimated bytes past this many pages' worth. Each run's last page may be partly
// filled (half a page in 60 on average); longer runs waste less but leave fewer to share out
// among the threads.
constexpr std::uint64_t kRunPages = 64;

// A run of entries in leaf order, cut into leaves (= data pages) by real encodes.
struct PackedRun {
  std::vector<OpEntry> entries;
  std::vector<std::size_t> ends;  // leaf j holds entries [ends[j - 1], ends[j])
  std::vector<Bytes> pages;       // leaf j's page, sealed
  std::uint64_t encodes = 0;      // encode_page calls it took
};

// Cuts a run into pages greedily in leaf order: each page takes as many entries as fit in
// `cap` bytes (WriteOptions::page_bytes) and max_leaf_entries, measured by encoding them: the
// `pages` value, i.e. the sealed page and its sealed R-tree leaf (join_page_value).
// The estimate proposes the first cut (scaled by the real-to-estimated ratio of the run's
// previous pages), then encodes bracket the cut: [lo fits, hi does not] narrowed by interpolating
// on the sizes (bisecting after a few tries) until hi = lo + 1, so adding the next entry would
// have passed the cap. An entry that alone passes it gets a page of its own.
class PagePacker {
 public:
  PagePacker(const QuantGrid& grid, const WriteOptions& options, std::uint32_t max_entries)
      : grid_(grid),
        codec_(options.codec),
        cap_(options.page_bytes),
        max_entries_(max_entries),
        seal_bytes_(storage::seal({}).size()) {}

  // Packs `run`, reading its ops a page's worth at a time (those of the pages cut are let go).
  void pack(PackedRun& run, const OpsOf& ops_of) const {
    const std::span<const OpEntry> entries = run.entries;
    std::deque<std::vector<Op>> batches;  // held by ops_of, for the entries not yet placed
    std::vector<std::size_t> batch_ends;
    std::vector<const Op*> ops;  // of entries [0, ops.size())
    auto fetch_to = [&](std::size_t end) {
      while (ops.size() < end) {
        std::size_t stop = ops.size();
        for (std::uint64_t w = 0; stop < entries.size() && w < cap_; ++stop) {
          w += entries[stop].weight;
        }
        stop = std::max(stop, end);
        std::vector<Op>& held = batches.emplace_back();
        held.reserve(stop - ops.size());
        const std::vector<const Op*> got =
            ops_of(entries.subspan(ops.size(), stop - ops.size()), held);
        ops.insert(ops.end(), got.begin(), got.end());
        batch_ends.push_back(stop);
      }
    };
    // Sealed bytes per estimated byte, averaged over the run's previous pages (1/4 the last page's,
    // 3/4 those before: it took the fewest encodes on the fBm and the bunny).
    double ratio = 1.0;
    for (std::size_t at = 0, batch = 0; at < entries.size();) {
      Bytes page;
      double bytes = 0;
      const std::size_t taken = cut(
          entries.subspan(at),
          [&](std::size_t n) {
            fetch_to(at + n);
            return std::span<const Op* const>(ops).subspan(at, n);
          },
          ratio, page, bytes, run.encodes);
      std::uint64_t estimated = 0;
      for (std::size_t i = at; i < at + taken; ++i) estimated += entries[i].weight;
      const double r = bytes / double(std::max<std::uint64_t>(1, estimated));
      ratio = at == 0 ? r : 0.25 * r + 0.75 * ratio;
      run.pages.push_back(storage::seal(page));
      at += taken;
      run.ends.push_back(at);
      for (; batch < batch_ends.size() && batch_ends[batch] <= at; ++batch) batches.pop_front();
    }
  }

 private:
  // The entries of the next page (a prefix of `entries`, whose first n ops ops_for(n) returns);
  // their encoding to `page`, unsealed, and the bytes of its value to `value_bytes`.
  template <class OpsFor>
  std::size_t cut(std::span<const OpEntry> entries, const OpsFor& ops_for, double ratio,
                  Bytes& page, double& value_bytes, std::uint64_t& encodes) const {
    const std::size_t limit = std::min<std::size_t>(entries.size(), max_entries_);
    const double cap = cap_;
    // Estimated bytes of each prefix; sizes are predicted as a line in them, which follows an
    // op's size better than a line in the count of ops.
    std::vector<double> weight(limit + 1, 0.0);
    for (std::size_t i = 0; i < limit; ++i) weight[i + 1] = weight[i] + entries[i].weight;
    auto prefix_within = [&](double w) {  // the longest prefix estimated at most w
      return std::size_t(std::upper_bound(weight.begin(), weight.end(), w) - weight.begin()) - 1;
    };
    std::size_t guess = prefix_within(cap / ratio);
    std::size_t lo = 0, hi = limit + 1;  // prefix lo fits (0 trivially); hi does not (or is past)
    double lo_bytes = 0, hi_bytes = 0, probe_bytes = 0;
    Bytes probe;
    std::vector<index::Entry> leaf;
    for (int probes = 1;; ++probes) {
      guess = std::clamp<std::size_t>(guess, lo + 1, std::min(hi - 1, limit));
      probe = encode_page(ops_for(guess), grid_, codec_);
      ++encodes;
      leaf.clear();
      for (std::size_t i = 0; i < guess; ++i) leaf.push_back(entries[i].index_entry());
      const double bytes =
          double(probe.size() + seal_bytes_ + page_value_overhead(index::encode_leaf(leaf).size()));
      probe_bytes = bytes;
      if (bytes <= cap) {
        lo = guess;
        lo_bytes = bytes;
        std::swap(page, probe);
      } else {
        hi = guess;
        hi_bytes = bytes;
      }
      if (lo == limit || hi == lo + 1) break;
      if (probes >= 4) {
        guess = lo + (hi - lo) / 2;
      } else if (hi > limit) {  // a line through 0 and lo
        guess = prefix_within(cap * weight[lo] / lo_bytes);
      } else {  // a line through lo (0 takes 0 bytes) and hi
        guess = prefix_within(weight[lo] +
                              (cap - lo_bytes) / (hi_bytes - lo_bytes) * (weight[hi] - weight[lo]));
      }
    }
    if (lo == 0) {  // one entry past the cap: a page of its own
      std::swap(page, probe);
      value_bytes = probe_bytes;
      return 1;
    }
    value_bytes = lo_bytes;
    return lo;
  }

  const QuantGrid& grid_;
  storage::CodecId codec_;
  std::uint32_t cap_, max_entries_;
  std::size_t seal_bytes_;
};

// The data pages. The sorted entries are cut into runs whose bounds depend on the entries alone
// (estimated bytes, kRunPages), and each run is packed into pages by PagePacker, so the pages do
// not depend on the thread count. Runs are packed on every core a window (a run per thread) at a
// time, and while the helpers start on a window the calling thread appends the previous one's
// pages, in order, with their locators (to `locators`) and R-tree leaves (to `tree`, whose `put`
// hands each leaf back in `leaf`: it is stored in the page's value). Memory holds
// two windows of runs (entries and pages: ~2 MiB a run on the 4097^2 fBm) and the ops of the
// pages being cut. Returns the number of ops placed.
std::uint64_t write_pages(storage::DatabaseWriter& writer, EntrySorter& sorted, const OpsOf& ops_of,
                          const QuantGrid& grid, const index::BuildOptions& bo,
                          const WriteOptions& options, std::uint64_t op_count,
                          index::TreeWriter& tree, const LeafSlot& leaf, LocatorSorter& locators,
                          WriteReport& report) {
  const unsigned threads = thread_count(options.threads);
  const std::size_t window = std::size_t(threads);
  const PagePacker packer(grid, options, bo.max_leaf_entries);
  std::vector<PackedRun> filling, packed;
  std::vector<index::Entry> leaf_entries;
  std::uint64_t placed = 0;
  WorkerPool pool(threads);  // its threads keep their codec contexts from window to window
  auto append_packed = [&] {
    for (const PackedRun& run : packed) {
      for (std::size_t j = 0, begin = 0; j < run.pages.size(); begin = run.ends[j++]) {
        const std::uint64_t page = report.pages++;
        leaf_entries.clear();
        for (std::size_t i = begin; i < run.ends[j]; ++i) {
          locators.add({run.entries[i].id, page, std::uint32_t(i - begin)});
          leaf_entries.push_back(run.entries[i].index_entry());
        }
        tree.add_leaf(leaf_entries);  // -> leaf
        if (leaf.id != page) throw_internal("database writer: leaf and page out of step");
        const Bytes value = join_page_value(leaf.bytes, run.pages[j]);
        report.page_bytes += value.size() - leaf.bytes.size();  // the leaf is the R-tree's
        writer.append(Table::kPages, page, value);
      }
      placed += run.entries.size();
      ++report.page_runs;
      report.page_encodes += run.encodes;
    }
    packed.clear();
    progress_to(options, 0.9 * double(placed) / double(std::max<std::uint64_t>(1, op_count)));
  };
  auto write_window = [&] {
    pool.for_each(
        filling.size(), [&](std::size_t j) { packer.pack(filling[j], ops_of); }, append_packed);
    std::swap(filling, packed);
  };
  const std::uint64_t run_weight = kRunPages * options.page_bytes;
  std::uint64_t weight = 0;
  SortedEntry s;
  while (sorted.next(s)) {
    if (filling.empty() || weight + s.entry.weight > run_weight) {
      if (filling.size() == window) write_window();
      filling.emplace_back();
      weight = 0;
    }
    weight += s.entry.weight;
    filling.back().entries.push_back(s.entry);
  }
  write_window();
  append_packed();
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
  // The leaves' summaries (one per page) wait in a scratch file for the upper levels. A leaf
  // goes into its page's value (page.h, PageValue); the table holds the nodes above.
  LeafSlot leaf;
  bool leaves = true;
  index::TreeWriter tree(
      bo,
      [&](std::uint64_t id, ByteView node) {
        report.rtree_bytes += node.size();
        ++report.rtree_nodes;
        if (leaves) {
          leaf.bytes.assign(node.begin(), node.end());
          leaf.id = id;
        } else {
          writer.append(Table::kRtree, id, node);
        }
      },
      tmp_dir);
  LocatorSorter locators(tmp_dir, side_sort_bytes(options));
  const std::uint64_t placed = write_pages(writer, sorted, ops_of, grid, bo, options, counts.ops,
                                           tree, leaf, locators, report);
  leaves = false;
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
  const QuantGrid grid = choose_grid(crmr.header, options.z_quantum, options.error_quantum);
  const double shift = quantize(crmr, grid);  // ROIs and subtree cones derived too
  const std::string tmp_dir = storage::scratch_dir("");
  TableCounts counts;
  counts.ops = crmr.ops.size();
  index::EntryOrder order(rtree_options(crmr.header, options));
  std::vector<std::uint32_t> depth(crmr.ops.size(), 0);  // longest parent chain from R^0
  for (const Op& op : crmr.ops) {
    if (op.id.value >= crmr.ops.size() || &op != &crmr.ops[op.id.value])
      throw_internal("database writer: op " + std::to_string(op.id.value) + " is out of place");
    // The ordering cube is around the boxes, as the stream writer observes them (before its
    // sweep): the stored ROIs reach past them by their rounding (stored_roi).
    order.observe(entry_of(op, crmr.header.kind, op.box, op.subtree_cone).index_entry());
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
