// Packed R-tree: plan/write/read round trip, packing rules, determinism, queries against brute
// force (Maheshwari et al. 3.2, 4.1-4.4).
#include "index/rtree.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <ostream>
#include <random>
#include <set>

#include "index/visitors.h"
#include "storage/temp_file.h"
#include "tests/index/index_test_util.h"

namespace smr::index {
namespace {

using test::brute_force;
using test::build;
using test::random_entries;
using test::stored_entries;

std::map<std::uint64_t, Entry> by_id(const std::vector<Entry>& entries) {
  std::map<std::uint64_t, Entry> m;
  for (const Entry& e : entries) m[e.id] = e;
  return m;
}

TEST(RTree, RoundTripIsConservativeAndTight) {
  const auto entries = random_entries(5000, 1);
  const BuildOptions options;
  const auto built = build(entries, options);
  const RTree tree = built.store.tree();
  ASSERT_EQ(tree.entry_count(), entries.size());
  ASSERT_EQ(tree.leaf_count(), built.plan.leaves.size());
  ASSERT_EQ(tree.node_count(), built.plan.node_count());
  EXPECT_EQ(tree.height(), static_cast<int>(built.plan.level_sizes.size()));

  const auto truth = by_id(entries);
  Box world;
  for (const Entry& e : entries) world.add(e.roi);
  Summary root_check;
  for (std::uint32_t leaf = 0; leaf < tree.leaf_count(); ++leaf) {
    const auto stored = tree.leaf_entries(leaf);
    ASSERT_EQ(stored.size(), built.plan.leaves[leaf].size());
    for (std::size_t i = 0; i < stored.size(); ++i) {
      const Entry& s = stored[i];
      ASSERT_EQ(s.id, built.plan.leaves[leaf][i]) << "leaf " << leaf;
      const Entry& t = truth.at(s.id);
      EXPECT_TRUE(s.roi.contains(t.roi)) << s.id;
      EXPECT_TRUE(s.box.contains(t.box)) << s.id;
      EXPECT_TRUE(s.roi.contains(s.box)) << s.id;
      EXPECT_LE(s.res, t.res);
      // 1 - res is rounded up to bfloat16: by less than 2^-7 of itself.
      EXPECT_LE(1.0 - s.res, (1.0 - t.res) * (1.0 + 1.0 / 128) + 1e-12);
      EXPECT_EQ(s.weight, 0u);
      for (int a = 0; a < 3; ++a) {
        // 8-bit quantisation on a frame no larger than the world: within 1/255 of its extent.
        const double slack = (world.hi[a] - world.lo[a]) / 255.0;
        EXPECT_LE(t.roi.lo[a] - s.roi.lo[a], slack);
        EXPECT_LE(s.box.hi[a] - t.box.hi[a], slack);
      }
      root_check.roi.add(s.roi);
      root_check.box.add(s.box);
      root_check.min_res = std::min(root_check.min_res, s.res);
    }
  }
  // The header's root summary contains every stored entry.
  EXPECT_TRUE(tree.root().roi.contains(root_check.roi));
  EXPECT_TRUE(tree.root().box.contains(root_check.box));
  EXPECT_LE(tree.root().min_res, root_check.min_res);
  EXPECT_EQ(tree.root().count, entries.size());
}

TEST(RTree, NodesArePutLeavesFirstRootLastAndStayCompact) {
  const auto entries = random_entries(20000, 2);
  BuildOptions options;
  options.fanout = 8;
  const auto built = build(entries, options);
  ASSERT_EQ(built.store.put_order.size(), built.plan.node_count());
  for (std::size_t i = 0; i < built.store.put_order.size(); ++i) {
    EXPECT_EQ(built.store.put_order[i], i);
  }
  EXPECT_GE(built.plan.level_sizes.size(), 3u);
  // ~30 bytes per stored entry: a full leaf of 512 entries stays well under 20 KiB.
  std::size_t biggest = 0;
  for (std::uint64_t leaf = 0; leaf < built.plan.leaves.size(); ++leaf) {
    const double per_entry = static_cast<double>(built.store.nodes.at(leaf).size()) /
                             static_cast<double>(built.plan.leaves[leaf].size());
    if (built.plan.leaves[leaf].size() > 100) {
      EXPECT_LT(per_entry, 36.0);
    }
    biggest = std::max(biggest, built.store.nodes.at(leaf).size());
  }
  EXPECT_LT(biggest, 20u * 1024);
}

// TreeWriter with a scratch dir keeps the leaves' summaries in a file (the database writer's
// memory does not grow with its pages): the same nodes and header as write()'s, whose summaries
// stay in memory, for trees of 0, 1 and several levels.
TEST(RTree, SpilledLeafSummariesWriteTheSameTree) {
  for (const std::size_t n : {std::size_t{0}, std::size_t{1}, std::size_t{20000}}) {
    const auto entries = random_entries(n, 9);
    BuildOptions options;
    options.fanout = 8;
    const auto built = build(entries, options);
    test::MemoryStore spilled;
    TreeWriter writer(options, spilled.putter(), storage::scratch_dir(""));
    std::vector<Entry> leaf;
    const auto truth = by_id(entries);
    for (const auto& ids : built.plan.leaves) {
      leaf.clear();
      for (std::uint64_t id : ids) leaf.push_back(truth.at(id));
      writer.add_leaf(leaf);
    }
    spilled.header = writer.finish();
    EXPECT_EQ(spilled.header, built.store.header) << n;
    EXPECT_EQ(spilled.nodes, built.store.nodes) << n;
    if (n > 1) {
      EXPECT_GE(built.plan.level_sizes.size(), 3u);
    }
  }
}

TEST(RTree, EveryEntryInExactlyOneLeafAndLeavesRespectWeights) {
  auto entries = random_entries(8000, 3);
  entries[17].weight = 100000;  // heavier than any leaf
  entries[4000].weight = 70000;
  BuildOptions options;
  options.leaf_weight = 16 * 1024 - 16;
  options.max_leaf_entries = 100;
  const Plan p = plan(entries, options);
  ASSERT_EQ(p.leaves.size(), p.leaf_weights.size());
  const auto truth = by_id(entries);
  std::set<std::uint64_t> seen;
  std::size_t total = 0;
  for (std::size_t leaf = 0; leaf < p.leaves.size(); ++leaf) {
    const auto& ids = p.leaves[leaf];
    ASSERT_FALSE(ids.empty());
    EXPECT_LE(ids.size(), options.max_leaf_entries);
    std::uint64_t weight = 0;
    for (std::uint64_t id : ids) {
      EXPECT_TRUE(seen.insert(id).second) << "id " << id << " in two leaves";
      weight += truth.at(id).weight;
    }
    total += ids.size();
    EXPECT_EQ(weight, p.leaf_weights[leaf]);
    if (ids.size() > 1) {
      EXPECT_LE(weight, options.leaf_weight) << "leaf " << leaf;
    }
    if (weight > options.leaf_weight) {
      EXPECT_EQ(ids.size(), 1u);
    }
  }
  EXPECT_EQ(total, entries.size());
  EXPECT_EQ(seen.size(), entries.size());
  // Greedy packing: two consecutive leaves could not have been merged.
  for (std::size_t leaf = 0; leaf + 1 < p.leaves.size(); ++leaf) {
    const bool full_count = p.leaves[leaf].size() == options.max_leaf_entries;
    const std::uint64_t next = truth.at(p.leaves[leaf + 1].front()).weight;
    EXPECT_TRUE(full_count || p.leaf_weights[leaf] + next > options.leaf_weight) << leaf;
  }
}

TEST(RTree, DeterministicUnderShuffledInput) {
  for (auto order : {BuildOptions::Order::kResolutionBands, BuildOptions::Order::kSizeClasses,
                     BuildOptions::Order::kSpatial}) {
    auto entries = random_entries(3000, 4);
    BuildOptions options;
    options.order = order;
    options.leaf_weight = 8 * 1024;
    const auto a = build(entries, options);
    std::mt19937 rng(99);
    std::shuffle(entries.begin(), entries.end(), rng);
    const auto b = build(entries, options);
    EXPECT_EQ(a.plan.leaves, b.plan.leaves);
    EXPECT_EQ(a.store.nodes, b.store.nodes);
    EXPECT_EQ(a.store.header, b.store.header);
  }
}

// Conservative: a stored box can only be bigger, so the tree never misses a true hit.
template <typename Pred>
void expect_superset_of_truth(const std::vector<Hit>& hits, const std::vector<Entry>& truth,
                              Pred pred) {
  std::set<std::uint64_t> got;
  for (const Hit& h : hits) got.insert(h.id);
  for (const Entry& e : truth) {
    if (pred(e.roi)) {
      EXPECT_TRUE(got.count(e.id)) << "missed entry " << e.id;
    }
  }
}

struct QueryCase {
  std::uint32_t fanout;
  std::uint32_t max_leaf_entries;
  BuildOptions::Order order;
  int dims;
};

void PrintTo(const QueryCase& c, std::ostream* os) {
  *os << "fanout " << c.fanout << ", max_leaf_entries " << c.max_leaf_entries << ", order "
      << static_cast<int>(c.order) << ", dims " << c.dims;
}

class RTreeQuery : public ::testing::TestWithParam<QueryCase> {};

TEST_P(RTreeQuery, EqualsBruteForceOnStoredEntries) {
  const QueryCase c = GetParam();
  const auto entries = random_entries(4000, 5 + c.fanout);
  BuildOptions options;
  options.fanout = c.fanout;
  options.max_leaf_entries = c.max_leaf_entries;
  options.order = c.order;
  options.order_dims = c.dims;
  const auto built = build(entries, options);
  const RTree tree = built.store.tree();
  const auto stored = stored_entries(tree);
  ASSERT_EQ(stored.size(), entries.size());

  std::mt19937_64 rng(c.fanout * 31 + c.max_leaf_entries);
  std::uniform_real_distribution<double> u(-50.0, 1050.0);
  std::uniform_real_distribution<double> uz(-10.0, 110.0);
  std::uniform_real_distribution<double> size(0.0, 1.0);
  std::uint64_t total_hits = 0;
  std::uint64_t pruned_leaves = 0;
  for (int q = 0; q < 40; ++q) {
    // Windows: 3-D, 2-D (z infinite) and degenerate (a point).
    Box w;
    const double s = 1000.0 * std::pow(size(rng), 3.0);
    w.lo = {u(rng), u(rng), uz(rng)};
    w.hi = {w.lo[0] + s, w.lo[1] + s * size(rng), w.lo[2] + 100.0 * size(rng)};
    if (q % 3 == 1) {
      w.lo[2] = -Box::kInf;
      w.hi[2] = Box::kInf;
    }
    if (q % 5 == 4) w.hi = w.lo;
    {
      WindowVisitor v(w);
      QueryStats stats;
      const auto hits = tree.query(v, &stats);
      const auto expect =
          brute_force(stored, [&](const Entry& e) { return window_meets(w, e.roi); });
      EXPECT_EQ(hits, expect) << "window query " << q;
      EXPECT_EQ(stats.hits, hits.size());
      expect_superset_of_truth(hits, entries, [&](const Box& b) { return window_meets(w, b); });
      total_hits += hits.size();
      pruned_leaves += tree.leaf_count() - stats.leaves_read;
    }
    const double x = u(rng);
    const double y = u(rng);
    {
      PointVisitor v(x, y);
      const auto hits = tree.query(v);
      EXPECT_EQ(hits, brute_force(stored, [&](const Entry& e) { return point_meets(x, y, e.roi); }))
          << "point query " << q;
      expect_superset_of_truth(hits, entries, [&](const Box& b) { return point_meets(x, y, b); });
      total_hits += hits.size();
    }
    {
      const Point3 p{u(rng), u(rng), uz(rng)};
      Point3 r{u(rng), u(rng), uz(rng)};
      if (q % 4 == 0) r = {p[0], p[1], uz(rng)};  // vertical: an axis with d == 0
      if (q % 4 == 1) r = {p[0] + 3.0 * size(rng), p[1] - 3.0 * size(rng), p[2]};  // short
      SegmentVisitor v(p, r);
      const auto hits = tree.query(v);
      EXPECT_EQ(hits,
                brute_force(stored, [&](const Entry& e) { return segment_meets(p, r, e.roi); }))
          << "segment query " << q;
      expect_superset_of_truth(hits, entries, [&](const Box& b) { return segment_meets(p, r, b); });
      total_hits += hits.size();
    }
    {
      const double h = uz(rng);
      PlaneVisitor v(h);
      const auto hits = tree.query(v);
      EXPECT_EQ(hits, brute_force(stored, [&](const Entry& e) { return plane_meets(h, e.roi); }))
          << "plane query " << q;
      expect_superset_of_truth(hits, entries, [&](const Box& b) { return plane_meets(h, b); });
      total_hits += hits.size();
    }
  }
  EXPECT_GT(total_hits, 1000u);  // the queries are not trivially empty...
  EXPECT_GT(pruned_leaves, 0u);  // ...and the tree does prune
}

INSTANTIATE_TEST_SUITE_P(
    Shapes, RTreeQuery,
    ::testing::Values(QueryCase{64, 512, BuildOptions::Order::kResolutionBands, 3},
                      QueryCase{2, 7, BuildOptions::Order::kResolutionBands, 3},
                      QueryCase{3, 1, BuildOptions::Order::kSizeClasses, 2},
                      QueryCase{16, 50, BuildOptions::Order::kSpatial, 2},
                      QueryCase{5, 64, BuildOptions::Order::kSizeClasses, 3}));

// A custom visitor: a window and a resolution threshold (the shape of an RCF query).
class CoarserThan : public Visitor {
 public:
  CoarserThan(const Box& w, double threshold) : w_(w), t_(threshold) {}
  bool enter(const Summary& s) override {
    ++entered;
    return s.min_res < t_ && window_meets(w_, s.roi);
  }
  bool accept(const Entry& e) override { return e.res < t_ && window_meets(w_, e.roi); }
  int entered = 0;

 private:
  Box w_;
  double t_;
};

TEST(RTree, ResolutionPruningEqualsBruteForce) {
  const auto entries = random_entries(6000, 6);
  BuildOptions options;
  options.max_leaf_entries = 60;
  options.fanout = 4;
  const auto built = build(entries, options);
  const RTree tree = built.store.tree();
  const auto stored = stored_entries(tree);
  for (double t : {0.0, 0.05, 0.3, 0.7, 0.999, 1.5}) {
    const Box w{{100, 200, -Box::kInf}, {700, 450, Box::kInf}};
    CoarserThan v(w, t);
    QueryStats stats;
    const auto hits = tree.query(v, &stats);
    EXPECT_EQ(
        hits,
        brute_force(stored, [&](const Entry& e) { return e.res < t && window_meets(w, e.roi); }))
        << t;
    // Band-major order: entries with res < 0.5 fill the first half of the leaves, the rest
    // are never read for such thresholds.
    if (t == 0.0) {
      EXPECT_EQ(stats.leaves_read, 0u);
    }
    if (t <= 0.3) {
      EXPECT_LE(stats.leaves_read, tree.leaf_count() / 2 + 2) << t;
    }
  }
}

TEST(RTree, HitsAreGroupedByLeafInLeafOrder) {
  const auto entries = random_entries(3000, 7);
  BuildOptions options;
  options.max_leaf_entries = 40;
  const auto built = build(entries, options);
  const RTree tree = built.store.tree();
  PlaneVisitor v(50);
  const auto hits = tree.query(v);
  ASSERT_FALSE(hits.empty());
  std::map<std::uint64_t, std::uint32_t> leaf_of;
  for (std::uint32_t l = 0; l < built.plan.leaves.size(); ++l) {
    for (std::uint64_t id : built.plan.leaves[l]) leaf_of[id] = l;
  }
  for (std::size_t i = 0; i < hits.size(); ++i) {
    EXPECT_EQ(hits[i].leaf, leaf_of.at(hits[i].id));
    if (i > 0) {
      EXPECT_LE(hits[i - 1].leaf, hits[i].leaf);
    }
  }
}

TEST(RTree, EmptyTree) {
  const auto built = build({}, BuildOptions{});
  EXPECT_TRUE(built.plan.leaves.empty());
  EXPECT_TRUE(built.store.nodes.empty());
  const RTree tree = built.store.tree();
  EXPECT_EQ(tree.entry_count(), 0u);
  EXPECT_EQ(tree.leaf_count(), 0u);
  EXPECT_EQ(tree.height(), 0);
  EXPECT_TRUE(tree.root().roi.empty());
  WindowVisitor v(Box{{-1e9, -1e9, -1e9}, {1e9, 1e9, 1e9}});
  QueryStats stats;
  EXPECT_TRUE(tree.query(v, &stats).empty());
  EXPECT_EQ(stats.nodes_read, 0u);
  EXPECT_THROW(tree.leaf_entries(0), Error);
}

TEST(RTree, SingleEntry) {
  Entry e{42, Box{{0, 0, 0}, {2, 2, 2}}, Box{{0.5, 0.5, 0.5}, {1, 1, 1}}, 0.25, 100};
  const auto built = build({e}, BuildOptions{});
  ASSERT_EQ(built.plan.leaves.size(), 1u);
  const RTree tree = built.store.tree();
  EXPECT_EQ(tree.height(), 1);
  EXPECT_EQ(tree.entry_count(), 1u);
  EXPECT_EQ(tree.root().roi, e.roi);  // exact: the bounds are the frame's ends
  PointVisitor inside(1.5, 1.5);
  EXPECT_EQ(tree.query(inside), (std::vector<Hit>{{0, 42}}));
  PointVisitor outside(2.5, 1.5);
  EXPECT_TRUE(tree.query(outside).empty());
  const auto stored = tree.leaf_entries(0);
  ASSERT_EQ(stored.size(), 1u);
  EXPECT_TRUE(stored[0].box.contains(e.box));
  EXPECT_EQ(stored[0].res, 0.25);
}

TEST(RTree, DegenerateAndFarAwayCoordinates) {
  // Identical points (zero-extent frames) and UTM-like coordinates with sub-metre boxes.
  std::vector<Entry> entries;
  for (std::uint64_t i = 0; i < 300; ++i) {
    entries.push_back({i, Box::point(5, 5, 5), Box::point(5, 5, 5), 0.5, 10});
  }
  for (std::uint64_t i = 0; i < 3000; ++i) {
    const double x = 500000.0 + static_cast<double>(i % 60) * 0.7;
    const double y = 4000000.0 + static_cast<double>(i / 60) * 0.7;
    entries.push_back({1000 + i, Box{{x, y, 100}, {x + 0.5, y + 0.5, 101}},
                       Box{{x + 0.1, y + 0.1, 100.5}, {x + 0.4, y + 0.4, 100.6}}, 0.9, 100});
  }
  BuildOptions options;
  options.max_leaf_entries = 100;
  const auto built = build(entries, options);
  const RTree tree = built.store.tree();
  const auto truth = by_id(entries);
  std::map<std::uint32_t, Box> leaf_bounds;  // each leaf's frame spans its true rois
  for (const auto& [leaf, s] : stored_entries(tree)) leaf_bounds[leaf].add(truth.at(s.id).roi);
  for (const auto& [leaf, s] : stored_entries(tree)) {
    const Entry& t = truth.at(s.id);
    ASSERT_TRUE(s.roi.contains(t.roi) && s.box.contains(t.box)) << s.id;
    if (s.id >= 1000 && leaf > 0) {  // leaves of neighbours only: boxes stay tight
      // Within two steps of the leaf's 8-bit frame, far from the origin as they are.
      const Box& f = leaf_bounds[leaf];
      EXPECT_LE(s.roi.hi[0] - t.roi.hi[0], 2 * (f.hi[0] - f.lo[0]) / 255) << s.id;
    }
  }
  PointVisitor v(500000.0 + 0.7 * 10 + 0.25, 4000000.0 + 0.7 * 20 + 0.25);
  const auto hits = tree.query(v);
  ASSERT_EQ(hits.size(), 1u);
  EXPECT_EQ(hits[0].id, 1000u + 20 * 60 + 10);
}

TEST(RTree, RejectsBadInput) {
  auto entries = random_entries(10, 8);
  auto dup = entries;
  dup[3].id = dup[5].id;
  EXPECT_THROW(plan(dup, BuildOptions{}), Error);
  auto outside = entries;
  outside[2].box.hi[0] = outside[2].roi.hi[0] + 1;
  EXPECT_THROW(plan(outside, BuildOptions{}), Error);
  auto nan = entries;
  nan[1].res = std::nan("");
  EXPECT_THROW(plan(nan, BuildOptions{}), Error);
  auto inf = entries;
  inf[0].roi.hi[1] = Box::kInf;
  EXPECT_THROW(plan(inf, BuildOptions{}), Error);
  BuildOptions bad;
  bad.fanout = 1;
  EXPECT_THROW(plan(entries, bad), Error);
  // write() with a plan that does not match its entries.
  const Plan p = plan(entries, BuildOptions{});
  auto fewer = entries;
  fewer.pop_back();
  try {
    write(p, fewer, BuildOptions{}, [](std::uint64_t, ByteView) {});
    ADD_FAILURE() << "expected an error";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kInternal);
  }
}

}  // namespace
}  // namespace smr::index
