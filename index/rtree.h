// Packed R-tree over regions of influence (Maheshwari et al. section 4.4: "build a packed R-tree
// on the list of vertex splits, where the box associated with a vertex split v is roi(v)";
// docs/design.md section 5). Bulk-loaded once from a static set of entries, stored as sealed byte
// nodes that the caller keeps wherever it likes (a table of its own, named in RTree's error
// messages); this module never touches LMDB. A query retrieves every entry a Visitor accepts,
// pruning subtrees whose summary it rejects (Maheshwari 3.2: GET-SPLITS over roi boxes, here over
// tree nodes).
//
// Leaf order (the design point). One leaf is one data page (docs/design.md section 3), so the order
// of entries decides what an extraction reads. Entries are refinement ops: coarse ops have big
// boxes and low resolution, fine ops small boxes and high resolution. A view-dependent query
// (Brown 5.2, reduced extraction) needs, at each place, the ops coarser than a threshold that
// varies smoothly with distance; a distant view needs few coarse ops spread over the whole
// domain. A purely spatial order (Hilbert of the centre) would put those few coarse ops in
// every leaf, so the query would read every page for a handful of ops. Hence the order is
// class-major:
//   1. class = resolution band (default, Order::kResolutionBands):
//      floor(bands_per_octave * log2(1 / (1 - res))), i.e. the band of the op's error relative
//      to the base mesh (res = 1 - err/err0, Brown 4.4.2) — the quantity a screen-space RCF
//      thresholds (projected error <= tau), so a view needs, at each place, a prefix of the
//      bands. Two bands per octave measured best on a synthetic hierarchy (tests/index/
//      locality_test.cpp: 1.85x read amplification vs 2.2x with one band per octave and 2.1x
//      with eight; coarser bands mix needed and unneeded errors in a leaf, finer bands spread a
//      leaf over more ground). Order::kSizeClasses uses instead floor(log2(world extent / box
//      extent)) over the ordering axes (a quadtree level), and Order::kSpatial a single class
//      (the classic Hilbert-packed R-tree, a baseline for benchmarks).
//   2. within a class, Hilbert order of the entry's own box centre (Kamel & Faloutsos 1993),
//      in a cube around the union of all ROIs (2-D on x-y, or 3-D), traversed forward in even
//      classes and backward in odd ones (serpentine), so a leaf that straddles two classes
//      holds the end of one and the start of the next at the same place;
//   3. ties broken by id, so the plan is a function of the set of entries.
// Leaves are then filled greedily in that order up to `leaf_weight` bytes (the page payload) and
// `max_leaf_entries`; a small class shares a leaf with the next one (the whole coarse top of the
// hierarchy lands in the first few leaves). plan() and LeafPacker weigh entries by their `weight`;
// the database writer cuts the same order by each page's encoded size (smr/db/writer.cpp,
// PagePacker) and hands its leaves to TreeWriter. Internal levels group `fanout` consecutive nodes
// of the level below, so a subtree is a run of consecutive leaves.
//
// Node format (all nodes sealed with storage::seal; errors name "<table>/<node id>", the table
// the caller gives RTree):
//   varint level (0 = leaf), varint count, frame (3 x f64 origin, 3 x f64 step);
//   internal: varint first_child (children are first_child .. first_child + count - 1);
//   per item: roi and box as 12 x u8 on the node's frame (coordinate = origin + q * step),
//     u16 res (bfloat16 of 1 - res, node_codec.h), then
//     leaf: svarint id - previous id   |   internal: varint entry count.
// Quantisation is conservative: stored lo <= true lo, stored hi >= true hi, stored res <= true
// res (1 - res rounded up, by < 2^-7 of itself). A leaf entry costs ~17 bytes (a 500-entry leaf
// ~8.5 KiB): every query reads the nodes it enters, so small nodes are low read amplification,
// and 8 bits (1/255 of the node's extent) lose little pruning.
// Readers see the stored values: Visitor::accept gets the conservative boxes and res (and
// weight 0). Every summary is computed from the stored values below it, so a stored summary
// contains the stored boxes of its subtree exactly (no float slack between levels): a visitor
// whose `enter` is monotone (a bigger box or a lower res can only say "yes" more often) finds
// exactly the entries a brute-force scan of the stored entries would accept.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "index/box.h"
#include "storage/bytes.h"

namespace smr::storage {
template <class T>
class RecordFile;
}

namespace smr::index {

namespace detail {
struct Node;
}

using storage::Bytes;
using storage::ByteView;

struct Entry {
  std::uint64_t id = 0;      // payload (an op id); unique within a tree
  Box roi;                   // region of influence: contains `box` and every descendant's box
  Box box;                   // the item's own box
  double res = 0;            // the item's resolution (birth_res), normally in [0, 1]
  std::uint32_t weight = 0;  // bytes the item takes in its data page (for leaf packing)
};

// Of a subtree: unions of roi and box, minimum res, number of entries.
struct Summary {
  Box roi;
  Box box;
  double min_res = Box::kInf;
  std::uint64_t count = 0;
};

struct BuildOptions {
  enum class Order : std::uint8_t {
    kResolutionBands,  // class = octave of (1 - res); the default (see the header comment)
    kSizeClasses,      // class = floor(log2(world extent / box extent))
    kSpatial,          // one class: plain Hilbert packing (a baseline for benchmarks)
  };
  // Max total weight of a leaf (= its data page payload; LMDB values of k*4096-16 bytes fill
  // k pages, docs/design.md section 3). A single heavier entry gets a leaf of its own.
  std::uint32_t leaf_weight = 64 * 1024 - 16;
  std::uint32_t max_leaf_entries = 512;  // >= 1
  std::uint32_t fanout = 64;             // children per internal node, >= 2
  Order order = Order::kResolutionBands;
  // Resolution bands per octave of error (kResolutionBands only), 1..8.
  std::uint32_t bands_per_octave = 2;
  // Axes used by the Hilbert order and by size classes: 2 = x-y (2.5-D terrain), 3 = x-y-z.
  // 3 also works for terrain (the cube is flat, so nearby columns stay nearby on the curve).
  int order_dims = 3;
};

// The packed R-tree, before serialisation.
struct Plan {
  std::vector<std::vector<std::uint64_t>> leaves;  // leaf i (== data page i): entry ids, in order
  std::vector<std::uint64_t> leaf_weights;         // total weight of each leaf
  std::vector<std::uint64_t> level_sizes;  // nodes per level, leaves first; empty when no entries
  std::uint64_t node_count() const;
};

// The order of the header comment, one entry at a time, for entries that do not fit in memory:
// observe() every entry first (the ordering cube is around all ROIs; serpentine needs the classes
// present), then key() gives each entry's place; entries sorted by key are in leaf order.
struct OrderKey {
  int cls = 0;
  std::uint64_t curve = 0;
  std::uint64_t id = 0;
  friend auto operator<=>(const OrderKey&, const OrderKey&) = default;
};
class EntryOrder {
 public:
  // Throws kInvalidInput on options out of range.
  explicit EntryOrder(const BuildOptions& options);
  // Throws kInvalidInput on an empty or non-finite box, a roi not containing its box, a NaN res.
  void observe(const Entry& e);
  OrderKey key(const Entry& e) const;  // after every observe()

 private:
  int class_of(const Entry& e) const;
  BuildOptions options_;
  Box world_;
  mutable double side_ = -1;            // fixed by the first key()
  std::array<double, 9> thresholds_{};  // resolution bands: 1 + the most bands per octave
  std::vector<bool> present_;
  mutable std::vector<bool> reversed_;
};

// Cuts entries, in leaf order, into leaves of at most leaf_weight bytes and max_leaf_entries.
class LeafPacker {
 public:
  explicit LeafPacker(const BuildOptions& options) : options_(options) {}
  // True when an entry of `weight` starts a new leaf (the first entry always does); counts it.
  bool starts_leaf(std::uint32_t weight);
  std::uint64_t weight() const { return weight_; }  // of the current leaf, with the entry

 private:
  BuildOptions options_;
  std::uint64_t weight_ = 0, entries_ = 0;
  bool any_ = false;
};

// Serialises a tree leaf by leaf, in order, then its internal levels from the leaves' summaries
// (a hundred bytes a leaf: held in memory, or with `scratch_dir` in a scratch file there, read
// back a node's children at a time, so that the writer's memory does not grow with the leaves;
// the levels above, a fanout-th of them each, stay in memory). Nodes go to `put` as in write().
class TreeWriter {
 public:
  // `scratch_dir`: already resolved by storage::scratch_dir(); empty keeps the summaries in memory.
  TreeWriter(const BuildOptions& options,
             std::function<void(std::uint64_t node_id, ByteView node)> put,
             const std::string& scratch_dir = {});
  ~TreeWriter();
  TreeWriter(const TreeWriter&) = delete;
  TreeWriter& operator=(const TreeWriter&) = delete;
  // Throws kInvalidInput on an entry check_entry rejects, kInternal on an empty leaf. The leaf's
  // node goes to `put` at once (encode_leaf's bytes), with the next leaf id.
  void add_leaf(std::span<const Entry> leaf);
  // Writes the internal levels; returns the sealed header (as write()).
  Bytes finish();

 private:
  Summary emit(const detail::Node& node);
  BuildOptions options_;
  std::function<void(std::uint64_t, ByteView)> put_;
  std::vector<Summary> leaves_;                            // without a scratch dir
  std::unique_ptr<storage::RecordFile<Summary>> spilled_;  // with one
  std::uint64_t node_id_ = 0, entries_ = 0;
  Bytes payload_, sealed_;
};

// The sealed node TreeWriter::add_leaf puts for `leaf` (a caller that keeps each leaf beside its
// data page measures the two together before it cuts the page). Same exceptions as add_leaf.
Bytes encode_leaf(std::span<const Entry> leaf);

// Orders and packs `entries` (see the header comment). Deterministic: the same set of entries in
// any order gives the same plan. Throws kInvalidInput on a duplicate id, an empty or non-finite
// box, a roi that does not contain its box, a NaN res, or options out of range.
Plan plan(std::vector<Entry> entries, const BuildOptions& options);

// Serialises `plan`: calls put(node_id, sealed node bytes) for every node, leaves 0..L-1 first,
// then each internal level in order, the root last (a single leaf is its own root). Returns the
// sealed header, which the caller stores under a separate key. `entries` must be the entries
// given to plan() (any order); `options` the same options. Throws kInternal when they disagree.
Bytes write(const Plan& plan, std::span<const Entry> entries, const BuildOptions& options,
            const std::function<void(std::uint64_t node_id, ByteView node)>& put);

// Decides what a query retrieves. `enter` must be conservative (false only when no entry below
// can be accepted) and should be monotone: true for a summary implies true for any summary with
// a larger roi/box or a smaller min_res.
class Visitor {
 public:
  virtual ~Visitor() = default;
  virtual bool enter(const Summary& subtree) = 0;
  virtual bool accept(const Entry& entry) = 0;  // weight is 0 for entries read back
  // After the entries of leaf `leaf` were tested, `accepted` of them accepted.
  virtual void leaf_done(std::uint32_t /*leaf*/, std::size_t /*accepted*/) {}
};

struct Hit {
  std::uint32_t leaf = 0;
  std::uint64_t id = 0;
  bool operator==(const Hit&) const = default;
};

struct QueryStats {
  std::uint64_t nodes_read = 0;      // nodes fetched (internal and leaves)
  std::uint64_t leaves_read = 0;     // of which leaves (== data pages an extraction will fault)
  std::uint64_t entries_tested = 0;  // Visitor::accept calls
  std::uint64_t hits = 0;
};

// A read-only view of a stored tree. Holds no node cache: `fetch` is called for every node a
// query visits (the caller caches). Safe to query from several threads if `fetch` is.
class RTree {
 public:
  // `header` is write()'s result; `fetch(node_id)` returns the node's bytes as given to put();
  // `table` is where the caller keeps them, for messages ("<table>/<node id>", "<table>/header");
  // `leaf_table`, when not empty, where it keeps the leaves (ids 0 .. leaf_count() - 1).
  // Every node read is verified (checksum, level, counts, child ids within the level below —
  // which also rules out cycles) and a malformation throws smr::Error (kCorrupt) naming the node.
  RTree(ByteView header, std::function<Bytes(std::uint64_t node_id)> fetch, std::string table,
        std::string leaf_table = {});

  // Called, if set, with the children a query is about to enter below a node, before it reads
  // them (a caller reading from disk can ask for them all at once).
  void set_advise(std::function<void(std::span<const std::uint64_t> node_ids)> advise) {
    advise_ = std::move(advise);
  }

  std::uint64_t leaf_count() const { return level_sizes_.empty() ? 0 : level_sizes_.front(); }
  std::uint64_t entry_count() const { return root_.count; }
  std::uint64_t node_count() const { return node_count_; }
  int height() const { return static_cast<int>(level_sizes_.size()); }  // 0 when empty
  Summary root() const { return root_; }

  // Every entry the visitor accepts, in leaf order then in-leaf order (deterministic, grouped
  // by leaf). `stats`, when given, is added to (not reset).
  std::vector<Hit> query(Visitor& visitor, QueryStats* stats = nullptr) const;
  // The stored entries of leaf `leaf` (weight 0). Throws kInvalidInput when out of range.
  std::vector<Entry> leaf_entries(std::uint32_t leaf) const;

 private:
  struct Node;
  Node read_node(std::uint64_t node_id, std::uint64_t level) const;
  std::string node_context(std::uint64_t node_id) const;  // "<table>/<node id>"
  const std::string& table_of(std::uint64_t node_id) const;
  void visit(std::uint64_t node_id, std::uint64_t level, std::uint64_t expected_count,
             Visitor& visitor, std::vector<Hit>& hits, QueryStats& stats) const;

  std::function<Bytes(std::uint64_t)> fetch_;
  std::function<void(std::span<const std::uint64_t>)> advise_;
  std::string table_, leaf_table_;
  std::vector<std::uint64_t> level_sizes_;   // nodes per level, leaves first
  std::vector<std::uint64_t> level_starts_;  // first node id of each level
  std::uint64_t node_count_ = 0;
  Summary root_;
};

}  // namespace smr::index
