#include "smr/db/database.h"

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <exception>
#include <filesystem>
#include <limits>
#include <map>
#include <mutex>
#include <set>
#include <span>
#include <thread>
#include <type_traits>

#include <malloc.h>

#include <nlohmann/json.hpp>

#include "base/error.h"
#include "smr/core/parallel.h"
#include "smr/db/page.h"
#include "storage/checksum.h"
#include "storage/external_sort.h"
#include "storage/record_file.h"
#include "storage/temp_file.h"

namespace smr {

using nlohmann::json;
using storage::ByteReader;
using storage::Bytes;
using storage::ByteView;
using storage::ByteWriter;
using storage::RecordFile;
using storage::Table;

namespace {

constexpr std::uint64_t kRtreeHeaderKey = std::numeric_limits<std::uint64_t>::max();
// A cached value's own cost beyond its payload: the shared_ptr's block holding the variant and the
// cache's list and map nodes.
constexpr std::size_t kCacheItemOverhead = 160;
// Every this many bytes read from LMDB, the mapped file pages read so far are dropped from the
// process (they count in its RSS) and glibc returns the free heap pages in the middle of its arena
// (malloc_trim): decoded pages are many small blocks, and the cache's evictions free them in an
// order that leaves most heap pages partly used. On a whole-database output (1.2 M triangles,
// 64 MiB cache) peak RSS is 196 MiB at 16 MiB intervals, 180 at 4, 172 at 1.
constexpr std::uint64_t kReleaseEveryBytes = std::uint64_t{1} << 20;

index::Box to_index(const Box3& b) {
  index::Box out;
  for (int k = 0; k < 3; ++k) {
    out.lo[k] = b.lo[k];
    out.hi[k] = b.hi[k];
  }
  return out;
}

Box3 from_index(const index::Box& b) {
  Box3 out;
  for (int k = 0; k < 3; ++k) {
    out.lo[k] = b.lo[k];
    out.hi[k] = b.hi[k];
  }
  return out;
}

json vec_json(const Vec3& v) {
  return json::array({v.x, v.y, v.z});
}
Vec3 json_vec(const json& j) {
  return {j.at(0).get<double>(), j.at(1).get<double>(), j.at(2).get<double>()};
}

json info_json(const CrmrInfo& info) {
  return {{"kind", info.kind == ModelKind::kTerrain ? "terrain" : "mesh"},
          {"georef",
           {{"x0", info.georef.x0},
            {"y0", info.georef.y0},
            {"dx", info.georef.dx},
            {"dy", info.georef.dy},
            {"crs_wkt", info.georef.crs_wkt},
            {"geographic", info.georef.geographic}}},
          {"grid_width", info.grid_width},
          {"grid_height", info.grid_height},
          {"err0", info.err0},
          {"err_final", info.err_final},
          {"bounds", {{"lo", vec_json(info.bounds.lo)}, {"hi", vec_json(info.bounds.hi)}}},
          {"source", info.source},
          {"builder", info.builder},
          {"vertex_count", info.vertex_count}};
}

CrmrInfo json_info(const json& j) {
  CrmrInfo info;
  info.kind =
      j.at("kind").get<std::string>() == "terrain" ? ModelKind::kTerrain : ModelKind::kMesh3d;
  const json& g = j.at("georef");
  info.georef.x0 = g.at("x0").get<double>();
  info.georef.y0 = g.at("y0").get<double>();
  info.georef.dx = g.at("dx").get<double>();
  info.georef.dy = g.at("dy").get<double>();
  info.georef.crs_wkt = g.at("crs_wkt").get<std::string>();
  info.georef.geographic = g.at("geographic").get<bool>();
  info.grid_width = j.at("grid_width").get<int>();
  info.grid_height = j.at("grid_height").get<int>();
  info.err0 = j.at("err0").get<double>();
  info.err_final = j.at("err_final").get<double>();
  info.bounds = Box3{json_vec(j.at("bounds").at("lo")), json_vec(j.at("bounds").at("hi"))};
  info.source = j.at("source").get<std::string>();
  info.builder = j.at("builder").get<std::string>();
  info.vertex_count = j.at("vertex_count").get<std::uint64_t>();
  return info;
}

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

}  // namespace

// ------------------------------------------------------------------------------------ writing
//
// Both writers end in write_tables, which takes the ops' index records through external sorts
// (storage/external_sort.h) under WriteOptions::sort_bytes: the R-tree order (index::EntryOrder)
// and the locators' id order. The stream writer derives ROIs and subtree cones by a backward
// sweep over its records on disk, children sending theirs to their parents through an
// ExternalQueue (time-forward processing, Chiang et al. 1995). What stays in memory is the
// budget, one summary per data page (the R-tree's upper levels) and a window of pages.

namespace {

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

struct Locator {
  std::uint64_t id = 0, page = 0;
  std::uint32_t slot = 0;
  bool operator<(const Locator& o) const { return id < o.id; }
};

using EntrySorter = storage::ExternalSorter<SortedEntry>;

double seconds_since(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

index::BuildOptions rtree_options(const CrmrInfo& header, const WriteOptions& options) {
  index::BuildOptions bo;
  bo.leaf_weight = options.page_bytes;
  bo.fanout = options.rtree_fanout;
  bo.order_dims = header.kind == ModelKind::kTerrain ? 2 : 3;
  return bo;
}

// Shares of WriteOptions::sort_bytes: the entry sort holds half, the backward sweep's queue and
// the locator sort (never alive together) a quarter each.
std::uint64_t entry_sort_bytes(const WriteOptions& o) {
  return o.sort_bytes / 2;
}
std::uint64_t side_sort_bytes(const WriteOptions& o) {
  return o.sort_bytes / 4;
}

// Writes pages (in R-tree leaf order, with the R-tree's leaves), locators, the R-tree's upper
// levels and the meta record (last), then commits. `sorted` holds every op's entry; `ops_of(page,
// held)` returns a page's ops, in the order of its entries, as the page must hold them (snapped,
// ROI, subtree cone, error shifted): ops that outlive the call or ones it appends to `held` (one
// per page, with room reserved for the page's ops, so earlier pointers stay valid). It is called
// from several threads at once.
struct TableCounts {
  std::uint64_t ops = 0, triangles = 0, dag_depth = 0;
};
using OpsOf =
    std::function<std::vector<const Op*>(std::span<const OpEntry>, std::vector<Op>& held)>;
WriteReport write_tables(storage::DatabaseWriter& writer, const CrmrInfo& header,
                         const QuantGrid& grid, double z_shift, EntrySorter& sorted,
                         const TableCounts& counts, const OpsOf& ops_of,
                         const WriteOptions& options, const std::string& tmp_dir) {
  auto progress = [&](double f) {
    if (options.progress) options.progress(f);
  };
  const auto started = std::chrono::steady_clock::now();
  WriteReport report;
  report.grid = grid;
  report.z_shift = z_shift;
  report.ops = counts.ops;
  const index::BuildOptions bo = rtree_options(header, options);
  index::TreeWriter tree(bo, [&](std::uint64_t id, ByteView node) {
    report.rtree_bytes += node.size();
    ++report.rtree_nodes;
    writer.append(Table::kRtree, id, node);
  });
  // Ids are unique: the locators' sort keeps no arrival numbers.
  storage::ExternalSorter<Locator, std::less<Locator>, storage::Ties::kAny> locators(
      tmp_dir, side_sort_bytes(options));

  // Leaves, a window of them at a time: their pages are encoded on every core, and while the
  // helpers start on a window the calling thread appends the previous one's pages, in order,
  // with their locators and R-tree leaves.
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
    progress(0.9 * double(placed) / double(std::max<std::uint64_t>(1, counts.ops)));
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
  if (placed != counts.ops)
    throw_internal("database writer: " + std::to_string(placed) + " ops reached the pages, not " +
                   std::to_string(counts.ops));

  // Locators, in id order: every id from 0 exactly once.
  std::vector<std::pair<std::uint64_t, std::uint32_t>> block;
  std::uint64_t expected = 0;
  auto write_block = [&] {
    const Bytes sealed = storage::seal(encode_locators(block));
    report.node_bytes += sealed.size();
    writer.append(Table::kNodes, (expected - 1) / kOpsPerLocatorBlock, sealed);
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
  // The R-tree's upper levels, then its header.
  writer.append(Table::kRtree, kRtreeHeaderKey, tree.finish());
  progress(0.95);

  json meta = {
      {"format", "smrdb"},
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
       {{"pages", report.page_bytes}, {"nodes", report.node_bytes}, {"rtree", report.rtree_bytes}}},
      {"page_bytes_target", options.page_bytes},
      {"parameters", options.parameters}};
  const std::string text = meta.dump();
  writer.put(Table::kMeta, "meta", storage::seal(storage::as_bytes(text)));  // last
  const auto committing = std::chrono::steady_clock::now();
  report.seconds_tables = seconds_since(started);
  writer.finish();
  report.seconds_commit = seconds_since(committing);
  report.file_bytes = storage::Env::open_read_only(writer.path()).file_bytes();
  report.dag_depth = counts.dag_depth;
  report.triangles = counts.triangles;
  report.scratch_bytes += sorted.spilled_bytes() + locators.spilled_bytes();
  progress(1.0);
  return report;
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

}  // namespace

WriteReport write_database(Crmr& crmr, const std::string& path, const WriteOptions& options) {
  const auto t0 = std::chrono::steady_clock::now();
  // Opening the writer first checks the path (exists without --force) before any work.
  storage::DatabaseWriter writer(path, options.force, options.batch_bytes);
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

namespace {

// An op as add() leaves it for finish(): its own box and cone, and where its parents are.
struct OpRecord {
  OpEntry entry;                 // roi == box and cone == the op's own until the backward sweep
  std::uint64_t parents_at = 0;  // first of its parents' ids in the parents file
  std::uint32_t parent_count = 0;
};

// The spool's copy of an op, for this process only (no version, no byte order): positions as
// their grid coordinates (the op is snapped before it is spooled), ids and indices as varints of
// their differences from the op's id or the previous one, resolutions, errors and bounds as
// doubles; no vertex table shared between ops, no geometry codec, no compression (on the 8193²
// terrain: 108 MB for 372 576 ops, against 377 MB for a raw copy of the fields). roi and
// subtree_cone are not kept: finish() derives them.
void spool_op(const Op& op, const QuantGrid& grid, Bytes& out) {
  ByteWriter w(out);  // appends
  const std::uint64_t id = op.id.value;
  w.varint(id);
  w.f64(op.birth_res);
  w.f64(op.error);
  w.varint(op.new_vertex_count);
  for (const Vec3& p : {op.box.lo, op.box.hi, op.sphere.center, op.cone.axis}) {
    for (int k = 0; k < 3; ++k) w.f64(p[k]);
  }
  w.f64(op.sphere.radius);
  w.f64(op.cone.half_angle);
  w.varint(op.vertices.size());
  std::uint64_t prev_id = id;
  std::array<std::int32_t, 3> prev_q{};
  for (const Vertex& v : op.vertices) {
    w.svarint(std::int64_t(v.id.value - prev_id));
    prev_id = v.id.value;
    const std::array<std::int32_t, 3> q = grid.quantize(v.p);
    if (grid.dequantize(q) != v.p)
      throw_internal("database writer: op " + std::to_string(id) + " has vertex " +
                     std::to_string(v.id.value) + " off the quantization grid");
    for (int k = 0; k < 3; ++k) w.svarint(std::int64_t(q[k]) - prev_q[k]);
    prev_q = q;
  }
  w.varint(op.fragment.size());
  for (const FragmentTriangle& t : op.fragment) {
    for (std::uint32_t v : t.v) w.varint(v);
    for (std::int32_t n : t.nbr) w.varint(std::uint64_t(std::int64_t(n) + 1));
    w.svarint(t.killer.valid() ? std::int64_t(t.killer.value - id) : 0);
    w.f64(t.death_res);
    w.u8(t.flags);
  }
  w.varint(op.pre.size());
  for (const TriRef& r : op.pre) {
    w.svarint(std::int64_t(id - r.op.value));
    w.varint(r.index);
  }
  w.varint(op.pre_tris.size());
  for (const PreTriangle& t : op.pre_tris) {
    for (std::uint32_t v : t.v) w.varint(v);
    w.u8(t.flags);
  }
  w.varint(op.coarser.size());
  for (const CoarserLink& c : op.coarser) write_link(w, c, id);
  w.varint(op.parents.size());
  for (OpId p : op.parents) w.svarint(std::int64_t(id - p.value));
  w.varint(op.children.size());
  for (OpId c : op.children) w.svarint(std::int64_t(c.value - id));
}

Op unspool_op(ByteView in, std::uint64_t id, const QuantGrid& grid) {
  ByteReader r(in, "scratch op " + std::to_string(id));
  Op op;
  op.id = OpId(r.varint());
  if (op.id.value != id)
    throw_internal("database writer: the scratch file lost op " + std::to_string(id));
  op.birth_res = r.f64();
  op.error = r.f64();
  op.new_vertex_count = static_cast<std::uint32_t>(r.varint());
  for (Vec3* p : {&op.box.lo, &op.box.hi, &op.sphere.center, &op.cone.axis}) {
    for (int k = 0; k < 3; ++k) (*p)[k] = r.f64();
  }
  op.sphere.radius = r.f64();
  op.cone.half_angle = r.f64();
  // Counts are checked against the bytes left (each element takes at least one) before sizing.
  auto count = [&](std::size_t least) {
    const std::uint64_t n = r.varint();
    if (n > r.remaining() / least)
      throw_internal("database writer: the scratch copy of op " + std::to_string(id) +
                     " is truncated");
    return static_cast<std::size_t>(n);
  };
  op.vertices.resize(count(4));
  std::uint64_t prev_id = id;
  std::array<std::int32_t, 3> q{};
  for (Vertex& v : op.vertices) {
    prev_id += static_cast<std::uint64_t>(r.svarint());
    v.id = VertexId(prev_id);
    for (int k = 0; k < 3; ++k) q[k] = static_cast<std::int32_t>(q[k] + r.svarint());
    v.p = grid.dequantize(q);
  }
  op.fragment.resize(count(15));
  for (FragmentTriangle& t : op.fragment) {
    for (std::uint32_t& v : t.v) v = static_cast<std::uint32_t>(r.varint());
    for (std::int32_t& n : t.nbr) n = static_cast<std::int32_t>(std::int64_t(r.varint()) - 1);
    const std::int64_t killer = r.svarint();
    if (killer != 0) t.killer = OpId(id + static_cast<std::uint64_t>(killer));
    t.death_res = r.f64();
    t.flags = r.u8();
  }
  op.pre.resize(count(2));
  for (TriRef& t : op.pre) {
    t.op = OpId(id - static_cast<std::uint64_t>(r.svarint()));
    t.index = static_cast<std::uint32_t>(r.varint());
  }
  op.pre_tris.resize(count(4));
  for (PreTriangle& t : op.pre_tris) {
    for (std::uint32_t& v : t.v) v = static_cast<std::uint32_t>(r.varint());
    t.flags = r.u8();
  }
  op.coarser.resize(count(5));
  for (CoarserLink& c : op.coarser) c = read_link(r, id);
  op.parents.resize(count(1));
  for (OpId& p : op.parents) p = OpId(id - static_cast<std::uint64_t>(r.svarint()));
  op.children.resize(count(1));
  for (OpId& c : op.children) c = OpId(id + static_cast<std::uint64_t>(r.svarint()));
  if (r.remaining() != 0)
    throw_internal("database writer: the scratch copy of op " + std::to_string(id) +
                   " has trailing bytes");
  return op;
}

// An op made ready for the spool (DatabaseStreamWriter::encode): this head, its parents' ids,
// then its spool_op bytes. Only this process reads it, right away.
struct EncodedHead {
  OpEntry entry;  // spool_at and spool_size not set yet
  Box3 vertices;  // of its (snapped) vertices
  double moved = 0.0;
  std::uint32_t parent_count = 0;
  std::uint32_t triangles = 0;
};

// Snaps the op and encodes it (quantize()'s snap and bounds). The bounds are recomputed unless
// `bounds_set` says the builder computed them and nothing moved.
void encode_op(Op& op, ModelKind kind, const QuantGrid& grid, bool bounds_set, Bytes& out) {
  EncodedHead h;
  h.moved = snap_vertices(op, grid);
  for (const Vertex& v : op.vertices) h.vertices.add(v.p);
  if (h.moved != 0.0 || !bounds_set) compute_op_bounds(op);
  h.entry = entry_of(op, kind, op.box, op.cone);
  h.parent_count = static_cast<std::uint32_t>(op.parents.size());
  h.triangles = static_cast<std::uint32_t>(op.fragment.size());
  const std::size_t at = out.size();
  out.resize(at + sizeof h + op.parents.size() * sizeof(std::uint64_t));
  std::memcpy(out.data() + at, &h, sizeof h);
  for (std::size_t i = 0; i < op.parents.size(); ++i) {
    const std::uint64_t p = op.parents[i].value;
    std::memcpy(out.data() + at + sizeof h + i * sizeof p, &p, sizeof p);
  }
  spool_op(op, grid, out);  // without ROI and subtree cone: finish() derives them
}

// A child's ROI, subtree cone and height, on its way to a parent (the backward sweep).
struct Message {
  std::uint64_t to = 0, from = 0;
  index::Box roi;
  NormalCone cone;
  std::uint64_t height = 0;
  bool operator<(const Message& o) const { return to < o.to; }
};

}  // namespace

struct DatabaseStreamWriter::State {
  State(const std::string& path, const WriteOptions& o, const std::string& tmp)
      : options(o),
        writer(path, o.force, o.batch_bytes),
        tmp_dir(storage::scratch_dir(tmp)),
        spool(tmp_dir),
        records(tmp_dir),
        parents(tmp_dir) {}
  WriteOptions options;
  storage::DatabaseWriter writer;
  std::string tmp_dir;
  RecordFile<std::uint8_t> spool;     // the ops (spool_op), in id order
  Bytes spooled;                      // the spooler's buffer for one op
  RecordFile<OpRecord> records;       // one per op, in id order
  RecordFile<std::uint64_t> parents;  // every op's parents, in id order
  std::unique_ptr<index::EntryOrder> order;
  CrmrInfo header;
  QuantGrid grid;
  double shift = 0.0;
  std::uint64_t triangles = 0;
  bool begun = false, finished = false;
  std::uint64_t next_id = 0;        // add()'s next op (checked as it comes, on its thread)
  std::uint64_t next_appended = 0;  // append()'s, whichever way the op came
  enum class Input { kNone, kOps, kEncoded } input = Input::kNone;

  // Spooling runs on its own thread, in id order, while the builder makes the next ops. Ops are
  // handed over in batches (one lock and one wake-up per batch, not per op) and the scratch file
  // is written in large pieces.
  static constexpr std::size_t kBatch = 256, kBatches = 8;
  std::mutex mu;
  std::condition_variable cv;
  std::vector<Op> filling;  // the builder's side, not shared
  std::deque<std::vector<Op>> queue;
  bool closing = false;
  std::exception_ptr error;
  std::thread spooler;

  void spool_one(Op& op) {
    spooled.clear();
    encode_op(op, header.kind, grid, true, spooled);
    append(spooled);
  }
  // The ordered half: an encoded op (encode_op) into the spool, its record and its parents.
  void append(ByteView encoded) {
    EncodedHead h;
    if (encoded.size() < sizeof h) throw_internal("database writer: a truncated encoded op");
    std::memcpy(&h, encoded.data(), sizeof h);
    const std::size_t head = sizeof h + std::size_t(h.parent_count) * sizeof(std::uint64_t);
    if (encoded.size() < head) throw_internal("database writer: a truncated encoded op");
    if (h.entry.id != next_appended)
      throw_internal("database writer: op " + std::to_string(h.entry.id) +
                     " arrived out of id order");
    ++next_appended;
    shift = std::max(shift, h.moved);
    header.bounds.add(h.vertices);
    OpRecord r;
    r.entry = h.entry;
    r.entry.spool_at = spool.count();
    r.entry.spool_size = static_cast<std::uint32_t>(encoded.size() - head);
    r.parents_at = parents.count();
    r.parent_count = h.parent_count;
    for (std::uint32_t i = 0; i < h.parent_count; ++i) {
      std::uint64_t p = 0;
      std::memcpy(&p, encoded.data() + sizeof h + i * sizeof p, sizeof p);
      parents.push(p);
    }
    records.push(r);
    order->observe(r.entry.index_entry());
    triangles += h.triangles;
    spool.append(encoded.data() + head, encoded.size() - head);
  }
  void run() {
    for (;;) {
      std::vector<Op> batch;
      {
        std::unique_lock lock(mu);
        cv.wait(lock, [&] { return closing || !queue.empty(); });
        if (queue.empty()) return;
        batch = std::move(queue.front());
        queue.pop_front();
      }
      cv.notify_all();
      try {
        if (!error) {
          for (Op& op : batch) spool_one(op);
        }
      } catch (...) {
        std::lock_guard lock(mu);
        error = std::current_exception();
      }
    }
  }
  // Hands the builder's current batch to the spooler, waiting while kBatches are queued.
  void hand_over() {
    if (filling.empty()) return;
    std::unique_lock lock(mu);
    cv.wait(lock, [&] { return queue.size() < kBatches || error; });
    if (error) {
      lock.unlock();
      drain();
    }
    queue.push_back(std::move(filling));
    lock.unlock();
    cv.notify_all();
    filling = std::vector<Op>();
    filling.reserve(kBatch);
  }
  // Stops the spooler once the queue is empty; rethrows what it threw.
  void drain() {
    if (spooler.joinable()) {
      {
        std::lock_guard lock(mu);
        closing = true;
      }
      cv.notify_all();
      spooler.join();
    }
    if (error) std::rethrow_exception(error);
    spool.flush();
    records.flush();
    parents.flush();
  }
  // The backward sweep: ROI = own box united with the children's ROIs, subtree cone likewise
  // (compute_rois' rule, children folded in id order), height = the longest path down. Children
  // have larger ids, so going from the last op to the first finishes every child before its
  // parents; each op's finished entry goes to `sorted` under its R-tree key. Returns the DAG
  // depth (the longest path from an op without parents: R^0 in a valid CRMR).
  std::uint64_t sweep(EntrySorter& sorted, std::uint64_t* scratch_bytes) {
    storage::ExternalQueue<Message> messages(tmp_dir, side_sort_bytes(options));
    constexpr std::uint64_t kChunk = 4096;
    const std::uint64_t n = records.count();
    std::vector<OpRecord> chunk;
    std::vector<std::uint64_t> parent_ids;
    std::vector<Message> inbox;
    std::uint64_t dag_depth = 0;
    for (std::uint64_t end = n; end > 0;) {
      const std::uint64_t first = end > kChunk ? end - kChunk : 0;
      chunk.resize(end - first);
      records.read(first, chunk);
      const std::uint64_t p0 = chunk.front().parents_at;
      parent_ids.resize(chunk.back().parents_at + chunk.back().parent_count - p0);
      parents.read(p0, parent_ids);
      for (std::size_t k = chunk.size(); k-- > 0;) {
        OpRecord& r = chunk[k];
        const std::uint64_t id = first + k;
        inbox.clear();
        while (!messages.empty() && messages.top().to >= id) {
          if (messages.top().to != id)
            throw_internal("database writer: a message for op " +
                           std::to_string(messages.top().to) + " was left behind");
          inbox.push_back(messages.top());
          messages.pop();
        }
        std::sort(inbox.begin(), inbox.end(),
                  [](const Message& a, const Message& b) { return a.from < b.from; });
        NormalCone cone = r.entry.cone;
        std::uint64_t height = 0;
        for (const Message& m : inbox) {
          r.entry.roi.add(m.roi);
          cone = cone_union(cone, m.cone);
          height = std::max(height, m.height + 1);
        }
        r.entry.cone = canonical_cone(cone);
        if (r.parent_count == 0) dag_depth = std::max(dag_depth, height);
        for (std::uint32_t j = 0; j < r.parent_count; ++j) {
          const std::uint64_t p = parent_ids[r.parents_at - p0 + j];
          if (p >= id)
            throw_internal("database writer: op " + std::to_string(id) + " has parent " +
                           std::to_string(p) + ", not an earlier op");
          messages.push({p, id, r.entry.roi, r.entry.cone, height});
        }
        sorted.add({order->key(r.entry.index_entry()), r.entry});
      }
      end = first;
    }
    *scratch_bytes += messages.spilled_bytes();
    return dag_depth;
  }
  ~State() {
    if (spooler.joinable()) {
      {
        std::lock_guard lock(mu);
        closing = true;
        queue.clear();
      }
      cv.notify_all();
      spooler.join();
    }
  }
};

DatabaseStreamWriter::DatabaseStreamWriter(const std::string& path, const WriteOptions& options,
                                           const std::string& tmp_dir)
    : s_(std::make_unique<State>(path, options, tmp_dir)) {}

DatabaseStreamWriter::~DatabaseStreamWriter() = default;

void DatabaseStreamWriter::begin(const CrmrInfo& header, std::uint64_t /*op_count*/) {
  if (s_->begun) throw_internal("database writer: begin() called twice");
  s_->begun = true;
  s_->header = header;
  s_->grid = choose_grid(header, s_->options.z_quantum);
  s_->header.bounds = Box3{};  // of the snapped vertices, as quantize() does
  s_->order = std::make_unique<index::EntryOrder>(rtree_options(header, s_->options));
  s_->spooler = std::thread([s = s_.get()] { s->run(); });
}

void DatabaseStreamWriter::encode(Op& op, std::vector<std::uint8_t>& out) const {
  const State& s = *s_;
  if (!s.begun || s.finished) throw_internal("database writer: encode() outside begin/finish");
  encode_op(op, s.header.kind, s.grid, false, out);
}

void DatabaseStreamWriter::add_encoded(std::span<const std::uint8_t> op) {
  State& s = *s_;
  if (!s.begun || s.finished) throw_internal("database writer: add_encoded() outside begin/finish");
  if (s.input == State::Input::kOps)
    throw_internal("database writer: add_encoded() after add(): one or the other");
  s.input = State::Input::kEncoded;
  s.append(op);  // on this thread (the op's own work was done by encode()); checks the id order
}

void DatabaseStreamWriter::add(Op&& op) {
  State& s = *s_;
  if (!s.begun || s.finished) throw_internal("database writer: add() outside begin/finish");
  if (s.input == State::Input::kEncoded)
    throw_internal("database writer: add() after add_encoded(): one or the other");
  s.input = State::Input::kOps;
  if (op.id.value != s.next_id)
    throw_internal("database writer: op " + std::to_string(op.id.value) +
                   " arrived out of id order");
  ++s.next_id;
  s.filling.push_back(std::move(op));
  if (s.filling.size() >= State::kBatch) s.hand_over();
}

WriteReport DatabaseStreamWriter::finish() {
  if (!s_->begun || s_->finished) throw_internal("database writer: finish() without begin()");
  s_->finished = true;
  State& s = *s_;
  const auto t0 = std::chrono::steady_clock::now();
  s.hand_over();
  s.drain();
  std::uint64_t scratch = 0;
  // The sweep is one thread's work: full buffers of entries are sorted on another.
  EntrySorter sorted(s.tmp_dir, entry_sort_bytes(s.options), {}, storage::Spill::kBackground);
  TableCounts counts;
  counts.ops = s.records.count();
  counts.triangles = s.triangles;
  counts.dag_depth = s.sweep(sorted, &scratch);
  const double seconds_sweep = seconds_since(t0);
  s.header.err0 += s.shift;
  s.header.err_final += s.shift;
  WriteReport report = write_tables(
      s.writer, s.header, s.grid, s.shift, sorted, counts,
      [&](std::span<const OpEntry> page, std::vector<Op>& held) {
        // A page's ops lie near one another in the spool (pages and the build's blocks both
        // follow space): they are read a run of nearby records at a time, not one by one.
        std::vector<RecordFile<std::uint8_t>::Piece> pieces(page.size());
        std::size_t total = 0;
        for (std::size_t i = 0; i < page.size(); ++i) {
          pieces[i] = {page[i].spool_at, page[i].spool_size, total};
          total += page[i].spool_size;
        }
        // Each thread reads its pages into one buffer it keeps (a page's ops are ~100 KiB: a
        // fresh buffer would be mapped, faulted in and unmapped for every page).
        thread_local Bytes bytes;
        bytes.resize(total);
        s.spool.read_pieces(pieces, bytes.data());
        std::vector<const Op*> ops(page.size());
        for (std::size_t i = 0, at = 0; i < page.size(); at += page[i].spool_size, ++i) {
          const OpEntry& e = page[i];
          Op& op = held.emplace_back(
              unspool_op(ByteView(bytes).subspan(at, e.spool_size), e.id, s.grid));
          op.roi = from_index(e.roi);
          op.subtree_cone = e.cone;
          op.error += s.shift;
          ops[i] = &op;
        }
        return ops;
      },
      s.options, s.tmp_dir);
  report.spool_bytes = s.spool.bytes();
  report.scratch_bytes += scratch + s.records.bytes() + s.parents.bytes();
  report.seconds_sweep = seconds_sweep;
  report.seconds = seconds_since(t0);
  return report;
}

const CrmrInfo& DatabaseStreamWriter::header() const {
  return s_->header;
}

// ------------------------------------------------------------------------------------ reading

std::unique_ptr<Database> Database::open(const std::string& path, const Options& options) {
  std::unique_ptr<Database> db(new Database());
  db->env_ = std::make_unique<storage::Env>(storage::Env::open_read_only(path));
  db->cache_ = std::make_unique<storage::PageCache<CacheItem>>(options.cache_bytes);
  const storage::ReadTxn txn = db->env_->read();
  const auto meta = txn.get(Table::kMeta, "meta");
  if (!meta) {
    throw_input(path +
                ": not a complete smrdb database (no meta record; an ingest was "
                "interrupted or this is another LMDB file)");
  }
  const ByteView text = naming_file(path, [&] { return storage::unseal(*meta, "meta", "meta"); });
  try {
    const json j = json::parse(text.begin(), text.end());
    if (j.at("format").get<std::string>() != "smrdb") throw_input(path + ": not an smrdb database");
    if (j.at("version").get<int>() != kDatabaseFormat)
      throw_input(path + ": database format " + std::to_string(j.at("version").get<int>()) +
                  " is not supported (this smrdb reads format " + std::to_string(kDatabaseFormat) +
                  ")");
    db->info_ = json_info(j.at("model"));
    db->grid_.origin = json_vec(j.at("grid").at("origin"));
    db->grid_.step = json_vec(j.at("grid").at("step"));
    db->op_count_ = j.at("counts").at("ops").get<std::uint64_t>();
    db->page_count_ = j.at("counts").at("pages").get<std::uint64_t>();
    db->meta_json_ = j.dump(2);
  } catch (const json::exception& e) {
    throw Error(ErrorKind::kCorrupt, path + ": meta record is malformed: " + e.what());
  }
  const auto header = txn.get(Table::kRtree, kRtreeHeaderKey);
  if (!header) throw Error(ErrorKind::kCorrupt, path + ": the R-tree header is missing");
  const Database* self = db.get();
  db->rtree_ = naming_file(path, [&] {
    return std::make_unique<index::RTree>(*header, [self](std::uint64_t node) {
      return std::get<Bytes>(*self->cached(3, Table::kRtree, node));
    });
  });
  if (db->rtree_->entry_count() != db->op_count_ || db->rtree_->leaf_count() != db->page_count_)
    throw Error(ErrorKind::kCorrupt, path + ": R-tree and meta disagree on the counts");
  return db;
}

Database::~Database() = default;

const std::string& Database::path() const {
  return env_->path();
}
std::uint64_t Database::file_bytes() const {
  return env_->file_bytes();
}

void Database::maybe_release() const {
  const std::uint64_t read = env_->bytes_read();
  std::uint64_t last = released_at_.load();
  if (read - last >= kReleaseEveryBytes && released_at_.compare_exchange_strong(last, read)) {
    env_->release_mapped_pages();
    malloc_trim(0);
  }
}

std::shared_ptr<const Database::CacheItem> Database::cached(std::uint64_t kind, Table table,
                                                            std::uint64_t id) const {
  const std::uint64_t key = (kind << 60) | id;
  return cache_->get(key, [&]() { return naming_file(path(), [&] { return load(table, id); }); });
}

storage::PageCache<Database::CacheItem>::Loaded Database::load(Table table,
                                                               std::uint64_t id) const {
  storage::PageCache<CacheItem>::Loaded loaded;
  const std::string name = std::string(storage::table_name(table)) + "/" + key_text(id);
  Bytes raw;
  {
    const storage::ReadTxn txn = env_->read();
    const auto value = txn.get(table, id);
    if (!value) throw Error(ErrorKind::kCorrupt, path() + ": " + name + " is missing");
    raw.assign(value->begin(), value->end());
  }
  loaded.bytes_read = raw.size();
  if (table == Table::kRtree) {
    loaded.charged_bytes = kCacheItemOverhead + heap_block_bytes(raw.capacity());
    rtree_bytes_read_.fetch_add(raw.size());
    loaded.value = std::make_shared<const CacheItem>(std::move(raw));
    nodes_read_.fetch_add(1);
  } else if (table == Table::kPages) {
    const ByteView payload = storage::unseal(raw, storage::table_name(table), key_text(id));
    std::vector<Op> ops = decode_page(payload, grid_, path() + ": " + name);
    std::size_t bytes = kCacheItemOverhead + heap_block_bytes(ops.capacity() * sizeof(Op));
    for (const Op& op : ops) bytes += op_memory_bytes(op) - sizeof(Op);
    loaded.charged_bytes = bytes;
    loaded.value = std::make_shared<const CacheItem>(std::move(ops));
    pages_read_.fetch_add(1);
    page_bytes_read_.fetch_add(raw.size());
  } else {
    locator_bytes_read_.fetch_add(raw.size());
    const ByteView payload = storage::unseal(raw, storage::table_name(table), key_text(id));
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
  const auto item = cached(2, Table::kNodes, id.value / kOpsPerLocatorBlock);
  const auto& locs = std::get<std::vector<Locator>>(*item);
  const std::uint64_t i = id.value % kOpsPerLocatorBlock;
  if (i >= locs.size() || locs[i].page >= page_count_)
    throw Error(ErrorKind::kCorrupt, path() + ": nodes/" +
                                         key_text(id.value / kOpsPerLocatorBlock) +
                                         ": no valid locator for op " + key_text(id.value));
  return locs[i];
}

std::shared_ptr<const std::vector<Op>> Database::page(std::uint64_t page) const {
  if (page >= page_count_) throw_input(path() + ": page " + key_text(page) + " does not exist");
  auto item = cached(1, Table::kPages, page);
  return {item, &std::get<std::vector<Op>>(*item)};
}

OpRef Database::op(OpId id) const {
  const Locator loc = locate(id);
  auto ops = page(loc.page);
  if (loc.slot >= ops->size() || (*ops)[loc.slot].id != id)
    throw Error(ErrorKind::kCorrupt, path() + ": pages/" + key_text(loc.page) +
                                         " does not hold op " + key_text(id.value) +
                                         " where nodes/ says");
  return OpRef(ops, &(*ops)[loc.slot]);
}

namespace {

// Brown Lemma 5.2.1 through the R-tree: a subtree is skipped when every op in it is completely
// finer (Rcf::region_completely_finer on the union of the ops' own boxes, at the subtree's least
// birth_res: conservative and monotone); an entry passing its box test is then judged exactly.
class RcfVisitor final : public index::Visitor {
 public:
  RcfVisitor(const Rcf& rcf, const CrmrInfo& info) : rcf_(rcf), info_(info) {}
  bool enter(const index::Summary& s) override {
    return !rcf_.region_completely_finer(from_index(s.box), s.min_res, info_);
  }
  bool accept(const index::Entry& e) override {
    return !rcf_.region_completely_finer(from_index(e.box), e.res, info_);
  }

 private:
  const Rcf& rcf_;
  const CrmrInfo& info_;
};

}  // namespace

std::vector<index::Hit> Database::rcf_hits(const Rcf& rcf) const {
  RcfVisitor visitor(rcf, info_);
  return naming_file(path(), [&] { return rtree_->query(visitor); });
}

std::vector<OpId> Database::maybe_not_completely_finer(const Rcf& rcf) const {
  std::vector<OpId> ids;
  for (const index::Hit& h : rcf_hits(rcf)) ids.push_back(OpId{h.id});
  return ids;
}

std::vector<OpId> Database::not_completely_finer(const Rcf& rcf) const {
  std::vector<OpId> x;
  std::shared_ptr<const std::vector<Op>> ops;
  std::uint64_t current = ~0ull;
  std::size_t slot = 0;  // hits come in slot order within a leaf: one pass over each page
  for (const index::Hit& h : rcf_hits(rcf)) {
    if (h.leaf != current) {
      current = h.leaf;
      ops = page(h.leaf);
      slot = 0;
    }
    while (slot < ops->size() && (*ops)[slot].id.value != h.id) ++slot;
    const Op* found = slot < ops->size() ? &(*ops)[slot] : nullptr;
    if (found == nullptr)
      throw Error(ErrorKind::kCorrupt, path() + ": pages/" + key_text(h.leaf) + " lacks op " +
                                           key_text(h.id) + " of its R-tree leaf");
    if (found->id == kBaseOp || !rcf.is_completely_finer(*found, *this)) x.push_back(found->id);
  }
  return x;
}

DatabaseStats Database::stats() const {
  DatabaseStats s;
  s.cache = cache_->stats();
  s.pages_read = pages_read_.load();
  s.page_bytes_read = page_bytes_read_.load();
  s.rtree_nodes_read = nodes_read_.load();
  s.rtree_bytes_read = rtree_bytes_read_.load();
  s.locator_bytes_read = locator_bytes_read_.load();
  s.lmdb_bytes_read = env_->bytes_read();
  return s;
}

void Database::clear_cache() const {
  cache_->clear();
}

}  // namespace smr
