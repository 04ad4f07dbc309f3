// Packed R-tree: ordering, packing, serialisation and queries (Maheshwari et al. 3.2 and 4.4;
// the order is explained at the top of rtree.h).
#include "index/rtree.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>
#include <tuple>
#include <unordered_map>
#include <utility>

#include "base/error.h"
#include "index/hilbert.h"
#include "index/node_codec.h"
#include "storage/checksum.h"
#include "storage/record_file.h"

namespace smr::index {
namespace {

constexpr std::uint32_t kHeaderMagic = 0x54524D53;  // "SMRT", little-endian
constexpr std::uint64_t kFormatVersion = 1;
constexpr int kMaxBandsPerOctave = 8;
constexpr int kMaxClass = 64 * kMaxBandsPerOctave;
constexpr std::size_t kMaxHeight = 64;

std::string node_key(std::uint64_t node_id) {
  return std::to_string(node_id);
}

void check_options(const BuildOptions& o) {
  if (o.max_leaf_entries < 1) throw_input("R-tree: max_leaf_entries must be at least 1");
  if (o.fanout < 2) throw_input("R-tree: fanout must be at least 2");
  if (o.bands_per_octave < 1 || o.bands_per_octave > kMaxBandsPerOctave) {
    throw_input("R-tree: bands_per_octave must be within 1..8");
  }
  if (o.order_dims != 2 && o.order_dims != 3) throw_input("R-tree: order_dims must be 2 or 3");
  if (o.order != BuildOptions::Order::kResolutionBands &&
      o.order != BuildOptions::Order::kSizeClasses && o.order != BuildOptions::Order::kSpatial) {
    throw_input("R-tree: unknown order");
  }
}

bool finite_box(const Box& b) {
  for (int a = 0; a < 3; ++a) {
    if (!std::isfinite(b.lo[a]) || !std::isfinite(b.hi[a])) return false;
  }
  return !b.empty();
}

void check_entry(const Entry& e) {
  const std::string what = "R-tree: entry " + std::to_string(e.id);
  if (!finite_box(e.box) || !finite_box(e.roi))
    throw_input(what + " has an empty or non-finite box");
  if (!e.roi.contains(e.box)) throw_input(what + ": its roi does not contain its box");
  if (std::isnan(e.res)) throw_input(what + " has a NaN res");
}

std::vector<std::uint64_t> level_sizes_for(std::uint64_t leaves, std::uint32_t fanout) {
  std::vector<std::uint64_t> sizes;
  if (leaves == 0) return sizes;
  sizes.push_back(leaves);
  while (sizes.back() > 1) sizes.push_back((sizes.back() + fanout - 1) / fanout);
  return sizes;
}

// floor(bands * log2(1 / (1 - res))): the band of the error relative to the base mesh, `bands`
// bands per octave. Computed from frexp and fixed thresholds (no log2 of the data).
int resolution_band(double res, const std::array<double, kMaxBandsPerOctave + 1>& thresholds,
                    int bands) {
  const double err = 1.0 - res;
  if (!(err > 0)) return kMaxClass;
  if (err >= 1) return 0;
  int e = 0;
  const double f = 2 * std::frexp(err, &e);  // err = f * 2^(e-1), f in [1, 2)
  // log2(1/err) = -e + (1 - log2 f), the second term in (0, 1]; count the sub-bands it passes:
  // (1 - log2 f) >= j / bands  <=>  f <= 2^(1 - j/bands) = thresholds[j].
  int sub = 0;
  for (int j = 1; j <= bands; ++j) sub += f <= thresholds[static_cast<std::size_t>(j)] ? 1 : 0;
  const long band = static_cast<long>(-e) * bands + sub;
  return static_cast<int>(std::clamp<long>(band, 0, kMaxClass));
}

// floor(log2(world extent / box extent)) over the ordering axes: a quadtree level.
int size_class(const Box& box, double world_extent, int dims) {
  double extent = 0;
  for (int a = 0; a < dims; ++a) extent = std::max(extent, box.hi[a] - box.lo[a]);
  if (!(extent > 0)) return kMaxClass;
  const double ratio = world_extent / extent;
  if (!std::isfinite(ratio)) return kMaxClass;
  if (ratio <= 1) return 0;
  int e = 0;
  std::frexp(ratio, &e);  // ratio = m * 2^e, m in [0.5, 1): floor(log2(ratio)) = e - 1
  return std::clamp(e - 1, 0, kMaxClass);
}

Summary summarize(const detail::Node& stored) {
  Summary s;
  for (const detail::NodeItem& item : stored.items) {
    s.roi.add(item.roi);
    s.box.add(item.box);
    s.min_res = std::min(s.min_res, item.res);
    s.count += stored.level == 0 ? 1 : item.value;
  }
  return s;
}

detail::NodeItem as_item(const Summary& s) {
  return {s.roi, s.box, s.min_res, s.count};
}

}  // namespace

std::uint64_t Plan::node_count() const {
  std::uint64_t n = 0;
  for (std::uint64_t s : level_sizes) n += s;
  return n;
}

EntryOrder::EntryOrder(const BuildOptions& options)
    : options_(options), present_(kMaxClass + 1, false), reversed_(kMaxClass + 1, false) {
  check_options(options);
  const int bands = static_cast<int>(options.bands_per_octave);
  static_assert(std::tuple_size_v<decltype(thresholds_)> == kMaxBandsPerOctave + 1);
  for (int j = 0; j <= bands; ++j) {
    thresholds_[static_cast<std::size_t>(j)] = std::exp2(1.0 - static_cast<double>(j) / bands);
  }
}

void EntryOrder::observe(const Entry& e) {
  check_entry(e);
  if (side_ >= 0) throw_internal("R-tree order: observe() after key()");
  world_.add(e.roi);
  // A size class needs the cube's side: presence is taken at the first key() for those.
  if (options_.order == BuildOptions::Order::kResolutionBands) {
    present_[static_cast<std::size_t>(class_of(e))] = true;
  }
}

int EntryOrder::class_of(const Entry& e) const {
  switch (options_.order) {
    case BuildOptions::Order::kResolutionBands:
      return resolution_band(e.res, thresholds_, static_cast<int>(options_.bands_per_octave));
    case BuildOptions::Order::kSizeClasses:
      return size_class(e.box, side_, options_.order_dims);
    case BuildOptions::Order::kSpatial:
      break;
  }
  return 0;
}

OrderKey EntryOrder::key(const Entry& e) const {
  const int dims = options_.order_dims;
  if (side_ < 0) {
    side_ = 0;
    for (int a = 0; a < dims; ++a) side_ = std::max(side_, world_.hi[a] - world_.lo[a]);
    // Serpentine: the rank of a class among the classes present decides its direction.
    std::vector<bool> present = present_;
    if (options_.order == BuildOptions::Order::kSizeClasses) {
      // Every class from 0 to the finest is taken as present: the order of a class must not
      // depend on the entries of other classes, which a single pass cannot see.
      std::fill(present.begin(), present.end(), true);
    } else if (options_.order == BuildOptions::Order::kSpatial) {
      present[0] = true;
    }
    for (int c = 0, rank = 0; c <= kMaxClass; ++c) {
      if (present[static_cast<std::size_t>(c)]) reversed_[static_cast<std::size_t>(c)] = rank++ % 2;
    }
  }
  const int cls = class_of(e);
  const int bits = hilbert_bits(dims);
  const double cells = std::ldexp(1.0, bits);
  const auto max_cell = static_cast<std::uint32_t>((std::uint64_t{1} << bits) - 1);
  std::array<std::uint32_t, 3> cell{};
  for (int a = 0; a < dims; ++a) {
    if (!(side_ > 0)) break;
    const double centre = e.box.lo[a] / 2 + e.box.hi[a] / 2;
    const double t = std::floor((centre - world_.lo[a]) / side_ * cells);
    cell[a] = t <= 0 ? 0 : (t >= max_cell ? max_cell : static_cast<std::uint32_t>(t));
  }
  std::uint64_t curve = hilbert_index(cell, dims);
  if (reversed_[static_cast<std::size_t>(cls)]) curve = ~curve;
  return {cls, curve, e.id};
}

bool LeafPacker::starts_leaf(std::uint32_t weight) {
  const bool start = !any_ || (entries_ > 0 && (weight_ + weight > options_.leaf_weight ||
                                                entries_ >= options_.max_leaf_entries));
  if (start) {
    weight_ = 0;
    entries_ = 0;
  }
  any_ = true;
  weight_ += weight;
  ++entries_;
  return start;
}

Plan plan(std::vector<Entry> entries, const BuildOptions& options) {
  EntryOrder order(options);
  for (const Entry& e : entries) order.observe(e);
  {
    std::vector<std::uint64_t> ids(entries.size());
    for (std::size_t i = 0; i < entries.size(); ++i) ids[i] = entries[i].id;
    std::sort(ids.begin(), ids.end());
    const auto dup = std::adjacent_find(ids.begin(), ids.end());
    if (dup != ids.end()) throw_input("R-tree: duplicate entry id " + std::to_string(*dup));
  }
  std::vector<std::pair<OrderKey, std::size_t>> keys(entries.size());
  for (std::size_t i = 0; i < entries.size(); ++i) keys[i] = {order.key(entries[i]), i};
  std::sort(keys.begin(), keys.end());
  Plan p;
  LeafPacker packer(options);
  for (const auto& [key, index] : keys) {
    const Entry& e = entries[index];
    const std::uint64_t before = packer.weight();
    if (packer.starts_leaf(e.weight)) {
      if (!p.leaves.empty()) p.leaf_weights.push_back(before);
      p.leaves.emplace_back();
    }
    p.leaves.back().push_back(e.id);
  }
  if (!p.leaves.empty()) p.leaf_weights.push_back(packer.weight());
  if (p.leaves.size() > std::numeric_limits<std::uint32_t>::max()) {
    throw_input("R-tree: more than 2^32 leaves");
  }
  p.level_sizes = level_sizes_for(p.leaves.size(), options.fanout);
  return p;
}

TreeWriter::TreeWriter(const BuildOptions& options,
                       std::function<void(std::uint64_t node_id, ByteView node)> put,
                       const std::string& scratch_dir)
    : options_(options), put_(std::move(put)) {
  check_options(options);
  if (!scratch_dir.empty()) spilled_ = std::make_unique<storage::RecordFile<Summary>>(scratch_dir);
}

TreeWriter::~TreeWriter() = default;

Summary TreeWriter::emit(const detail::Node& node) {
  payload_.clear();
  const detail::Node stored = detail::encode_node(node, payload_);
  sealed_.clear();
  storage::seal_into(payload_, sealed_);
  put_(node_id_++, sealed_);
  return summarize(stored);
}

namespace {
// The leaf node of `leaf`'s entries (checked).
detail::Node leaf_node(std::span<const Entry> leaf) {
  if (leaf.empty()) throw_internal("R-tree write: an empty leaf");
  detail::Node node;
  node.items.reserve(leaf.size());
  for (const Entry& e : leaf) {
    check_entry(e);
    node.items.push_back({e.roi, e.box, e.res, e.id});
  }
  return node;
}
}  // namespace

Bytes encode_leaf(std::span<const Entry> leaf) {
  Bytes payload;
  (void)detail::encode_node(leaf_node(leaf), payload);
  return storage::seal(payload);
}

void TreeWriter::add_leaf(std::span<const Entry> leaf) {
  if (node_id_ >= std::numeric_limits<std::uint32_t>::max()) {  // leaves so far
    throw_input("R-tree: more than 2^32 leaves");
  }
  const detail::Node node = leaf_node(leaf);
  entries_ += leaf.size();
  const Summary s = emit(node);
  if (spilled_) {
    spilled_->push(s);
  } else {
    leaves_.push_back(s);
  }
}

Bytes TreeWriter::finish() {
  const std::uint64_t leaves = node_id_;  // only leaves are emitted before finish()
  const std::vector<std::uint64_t> level_sizes = level_sizes_for(leaves, options_.fanout);
  std::vector<Summary> level;  // the level below, but spilled leaves
  if (spilled_) {
    spilled_->flush();
    if (level_sizes.size() == 1) {  // one leaf or none: the root is read back
      level.resize(static_cast<std::size_t>(leaves));
      spilled_->read(0, level);
    }
  } else {
    level = std::move(leaves_);
  }
  std::vector<Summary> children;  // a node's spilled leaves
  for (std::uint64_t lvl = 1; lvl < level_sizes.size(); ++lvl) {
    const bool from_file = spilled_ && lvl == 1;
    const std::uint64_t below = from_file ? leaves : level.size();
    const std::uint64_t first_of_level_below = node_id_ - below;
    std::vector<Summary> above;
    for (std::uint64_t g = 0; g < below; g += options_.fanout) {
      detail::Node node;
      node.level = lvl;
      node.first_child = first_of_level_below + g;
      const std::uint64_t end = std::min<std::uint64_t>(below, g + options_.fanout);
      std::span<const Summary> kids;
      if (from_file) {
        children.resize(static_cast<std::size_t>(end - g));
        spilled_->read(g, children);
        kids = children;
      } else {
        kids = std::span<const Summary>(level).subspan(g, end - g);
      }
      for (const Summary& c : kids) node.items.push_back(as_item(c));
      above.push_back(emit(node));
    }
    level = std::move(above);
  }

  Bytes header;
  storage::ByteWriter w(header);
  w.u32(kHeaderMagic);
  w.varint(kFormatVersion);
  w.varint(entries_);
  w.varint(level_sizes.size());
  for (std::uint64_t s : level_sizes) w.varint(s);
  if (!level.empty()) {
    const Summary& root = level.front();
    for (int a = 0; a < 3; ++a) w.f64(root.roi.lo[a]);
    for (int a = 0; a < 3; ++a) w.f64(root.roi.hi[a]);
    for (int a = 0; a < 3; ++a) w.f64(root.box.lo[a]);
    for (int a = 0; a < 3; ++a) w.f64(root.box.hi[a]);
    w.f64(root.min_res);
  }
  return storage::seal(header);
}

Bytes write(const Plan& plan, std::span<const Entry> entries, const BuildOptions& options,
            const std::function<void(std::uint64_t node_id, ByteView node)>& put) {
  check_options(options);
  std::unordered_map<std::uint64_t, std::size_t> where;
  where.reserve(entries.size());
  for (std::size_t i = 0; i < entries.size(); ++i) {
    check_entry(entries[i]);
    if (!where.emplace(entries[i].id, i).second) {
      throw_input("R-tree: duplicate entry id " + std::to_string(entries[i].id));
    }
  }
  if (plan.level_sizes != level_sizes_for(plan.leaves.size(), options.fanout)) {
    throw_internal("R-tree write: the plan's levels do not match its leaves and fanout");
  }
  std::vector<bool> placed(entries.size(), false);
  std::uint64_t total = 0;
  for (const auto& leaf : plan.leaves) {
    if (leaf.empty()) throw_internal("R-tree write: the plan has an empty leaf");
    for (std::uint64_t id : leaf) {
      const auto it = where.find(id);
      if (it == where.end() || placed[it->second]) {
        throw_internal("R-tree write: entry " + std::to_string(id) +
                       " is missing from the entries or placed twice");
      }
      placed[it->second] = true;
    }
    total += leaf.size();
  }
  if (total != entries.size()) throw_internal("R-tree write: the plan does not hold every entry");

  TreeWriter writer(options, put);
  std::vector<Entry> leaf_entries;
  for (const auto& leaf : plan.leaves) {
    leaf_entries.clear();
    for (std::uint64_t id : leaf) leaf_entries.push_back(entries[where.at(id)]);
    writer.add_leaf(leaf_entries);
  }
  return writer.finish();
}

struct RTree::Node : detail::Node {};

RTree::RTree(ByteView header, std::function<Bytes(std::uint64_t node_id)> fetch, std::string table,
             std::string leaf_table)
    : fetch_(std::move(fetch)), table_(std::move(table)), leaf_table_(std::move(leaf_table)) {
  const ByteView payload = storage::unseal(header, table_, "header");
  storage::ByteReader r(payload, table_ + "/header");
  if (r.u32() != kHeaderMagic) r.fail("not an R-tree header (bad magic)");
  const std::uint64_t version = r.varint();
  if (version != kFormatVersion) r.fail("unsupported format version " + std::to_string(version));
  root_.count = r.varint();
  const std::uint64_t height = r.varint();
  if (height > kMaxHeight) r.fail("height " + std::to_string(height) + " out of range");
  for (std::uint64_t k = 0; k < height; ++k) {
    const std::uint64_t size = r.varint();
    if (size == 0) r.fail("level " + std::to_string(k) + " is empty");
    if (k > 0 && size >= level_sizes_.back()) r.fail("level sizes do not decrease");
    level_starts_.push_back(node_count_);
    level_sizes_.push_back(size);
    node_count_ += size;  // strictly decreasing sizes: no overflow before the checks below
    if (node_count_ < size) r.fail("node count overflows");
  }
  if (height > 0 && level_sizes_.back() != 1) r.fail("the top level has more than one node");
  if ((height == 0) != (root_.count == 0)) r.fail("entry count and height disagree");
  if (leaf_count() > root_.count) r.fail("more leaves than entries");
  if (leaf_count() > std::numeric_limits<std::uint32_t>::max()) r.fail("more than 2^32 leaves");
  if (height > 0) {
    for (int a = 0; a < 3; ++a) root_.roi.lo[a] = r.f64();
    for (int a = 0; a < 3; ++a) root_.roi.hi[a] = r.f64();
    for (int a = 0; a < 3; ++a) root_.box.lo[a] = r.f64();
    for (int a = 0; a < 3; ++a) root_.box.hi[a] = r.f64();
    root_.min_res = r.f64();
    if (!finite_box(root_.roi) || !finite_box(root_.box) || !root_.roi.contains(root_.box) ||
        std::isnan(root_.min_res)) {
      r.fail("bad root summary");
    }
  }
  r.expect_end();
}

std::string RTree::node_context(std::uint64_t node_id) const {
  return table_of(node_id) + "/" + node_key(node_id);
}

const std::string& RTree::table_of(std::uint64_t node_id) const {
  return node_id < leaf_count() && !leaf_table_.empty() ? leaf_table_ : table_;
}

RTree::Node RTree::read_node(std::uint64_t node_id, std::uint64_t level) const {
  const Bytes sealed = fetch_(node_id);
  const std::string key = node_key(node_id);
  const ByteView payload = storage::unseal(sealed, table_of(node_id), key);
  const std::string context = node_context(node_id);
  Node node{detail::decode_node(payload, context)};
  if (node.level != level) {
    throw_corrupt(context + ": node is at level " + std::to_string(node.level) + ", expected " +
                  std::to_string(level));
  }
  if (level > 0) {
    const std::uint64_t start = level_starts_[level - 1];
    const std::uint64_t size = level_sizes_[level - 1];
    const std::uint64_t n = node.items.size();
    if (node.first_child < start || node.first_child - start > size ||
        n > size - (node.first_child - start)) {
      throw_corrupt(context + ": child ids " + std::to_string(node.first_child) + ".." +
                    std::to_string(node.first_child + n - 1) + " are not nodes of level " +
                    std::to_string(level - 1));
    }
  }
  return node;
}

void RTree::visit(std::uint64_t node_id, std::uint64_t level, std::uint64_t expected_count,
                  Visitor& visitor, std::vector<Hit>& hits, QueryStats& stats) const {
  const Node node = read_node(node_id, level);
  ++stats.nodes_read;
  std::uint64_t count = 0;
  if (level == 0) {
    ++stats.leaves_read;
    count = node.items.size();
  } else {
    for (const detail::NodeItem& item : node.items) {
      count += item.value;
      if (count < item.value) break;  // overflow: reported below
    }
  }
  if (count != expected_count) {
    throw_corrupt(node_context(node_id) + ": holds " + std::to_string(count) +
                  " entries, its parent says " + std::to_string(expected_count));
  }
  if (level == 0) {
    const std::size_t before = hits.size();
    for (const detail::NodeItem& item : node.items) {
      ++stats.entries_tested;
      const Entry e{item.value, item.roi, item.box, item.res, 0};
      if (visitor.accept(e)) {
        hits.push_back({static_cast<std::uint32_t>(node_id), item.value});
        ++stats.hits;
      }
    }
    visitor.leaf_done(static_cast<std::uint32_t>(node_id), hits.size() - before);
    return;
  }
  std::vector<std::uint64_t> entered;
  for (std::size_t c = 0; c < node.items.size(); ++c) {
    const detail::NodeItem& item = node.items[c];
    if (visitor.enter(Summary{item.roi, item.box, item.res, item.value}))
      entered.push_back(node.first_child + c);
  }
  if (advise_ && !entered.empty()) advise_(entered);
  for (std::uint64_t child : entered) {
    visit(child, level - 1, node.items[child - node.first_child].value, visitor, hits, stats);
  }
}

std::vector<Hit> RTree::query(Visitor& visitor, QueryStats* stats) const {
  std::vector<Hit> hits;
  QueryStats local;
  if (height() > 0 && visitor.enter(root_)) {
    visit(node_count_ - 1, level_sizes_.size() - 1, root_.count, visitor, hits, local);
  }
  if (stats != nullptr) {
    stats->nodes_read += local.nodes_read;
    stats->leaves_read += local.leaves_read;
    stats->entries_tested += local.entries_tested;
    stats->hits += local.hits;
  }
  return hits;
}

std::vector<Entry> RTree::leaf_entries(std::uint32_t leaf) const {
  if (leaf >= leaf_count()) {
    throw_input("R-tree: leaf " + std::to_string(leaf) + " out of range (" +
                std::to_string(leaf_count()) + " leaves)");
  }
  const Node node = read_node(leaf, 0);
  std::vector<Entry> out;
  out.reserve(node.items.size());
  for (const detail::NodeItem& item : node.items) {
    out.push_back({item.value, item.roi, item.box, item.res, 0});
  }
  return out;
}

}  // namespace smr::index
