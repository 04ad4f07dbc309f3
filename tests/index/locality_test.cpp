// Leaf order: on a synthetic quadtree hierarchy (level L: 4^L cells over the unit square, coarse
// = big boxes and low res), coarse queries and view-dependent queries must touch few leaves and
// read little they do not use — the reason for the class-major order (index/rtree.h). The plain
// Hilbert order is measured too, to show what it would cost.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <random>
#include <set>

#include "index/rtree.h"
#include "index/visitors.h"
#include "tests/index/index_test_util.h"

namespace smr::index {
namespace {

constexpr std::uint32_t kWeight = 128;  // bytes per op in its page

// Levels 0..depth; an op's box is its cell shrunk by 10%, its roi the cell (which holds every
// descendant's box); its error 2^-L * u with u in (0.5, 1], so res = 1 - error.
std::vector<Entry> quadtree(int depth, std::uint32_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> jitter(0.5000001, 1.0);
  std::vector<Entry> out;
  std::uint64_t id = 0;
  for (int level = 0; level <= depth; ++level) {
    const std::uint32_t n = 1u << level;
    const double side = 1.0 / n;
    for (std::uint32_t i = 0; i < n; ++i) {
      for (std::uint32_t j = 0; j < n; ++j) {
        Entry e;
        e.id = id++;
        e.roi = Box{{i * side, j * side, 0.0}, {(i + 1) * side, (j + 1) * side, side}};
        e.box = Box{{(i + 0.05) * side, (j + 0.05) * side, 0.0},
                    {(i + 0.95) * side, (j + 0.95) * side, 0.9 * side}};
        e.res = 1.0 - side * jitter(rng);
        e.weight = kWeight;
        out.push_back(e);
      }
    }
  }
  return out;
}

double distance(const Point3& p, const Box& b) {
  double d2 = 0;
  for (int a = 0; a < 3; ++a) {
    const double d = std::max({b.lo[a] - p[a], 0.0, p[a] - b.hi[a]});
    d2 += d * d;
  }
  return std::sqrt(d2);
}

// The shape of a screen-space RCF: an op is needed while its error exceeds tau * distance.
class View : public Visitor {
 public:
  View(const Point3& eye, double tau) : eye_(eye), tau_(tau) {}
  bool enter(const Summary& s) override { return needed(s.min_res, s.roi); }
  bool accept(const Entry& e) override { return needed(e.res, e.roi); }
  bool needed(double res, const Box& roi) const { return 1.0 - res > tau_ * distance(eye_, roi); }

 private:
  Point3 eye_;
  double tau_;
};

class CoarserThan : public Visitor {
 public:
  explicit CoarserThan(double threshold) : t_(threshold) {}
  bool enter(const Summary& s) override { return s.min_res < t_; }
  bool accept(const Entry& e) override { return e.res < t_; }

 private:
  double t_;
};

struct Cost {
  std::uint64_t leaves = 0;
  std::uint64_t min_leaves = 0;
  double amplification = 0;  // bytes of leaves read / bytes of the ops the query needs
};

Cost measure(const test::Built& built, Visitor& v, std::uint32_t leaf_weight) {
  std::set<std::uint64_t> leaves_fetched;
  const RTree tree(
      built.store.header,
      [&](std::uint64_t id) {
        if (id < built.plan.leaves.size()) leaves_fetched.insert(id);
        return built.store.nodes.at(id);
      },
      "rtree");
  QueryStats stats;
  const auto hits = tree.query(v, &stats);
  EXPECT_EQ(stats.leaves_read, leaves_fetched.size());
  std::uint64_t read = 0;
  for (std::uint64_t leaf : leaves_fetched) read += built.plan.leaf_weights[leaf];
  Cost c;
  c.leaves = stats.leaves_read;
  const std::uint64_t needed = hits.size() * kWeight;
  c.min_leaves = (needed + leaf_weight - 1) / leaf_weight;
  c.amplification = static_cast<double>(read) / static_cast<double>(needed);
  return c;
}

TEST(RTreeLocality, CoarseLevelsOverTheWholeSquareSitInTheFirstLeaves) {
  const auto entries = quadtree(8, 1);   // 87381 ops
  const double level3 = 1.0 - 1.0 / 16;  // res below this: levels 0..3 (85 ops)
  for (auto order : {BuildOptions::Order::kResolutionBands, BuildOptions::Order::kSizeClasses,
                     BuildOptions::Order::kSpatial}) {
    BuildOptions options;
    options.order = order;
    options.order_dims = 2;
    const auto built = test::build(entries, options);
    CoarserThan v(level3);
    const Cost c = measure(built, v, options.leaf_weight);
    std::cout << "order " << static_cast<int>(order) << ": " << built.plan.leaves.size()
              << " leaves, coarse query reads " << c.leaves << " (min " << c.min_leaves << ")\n";
    if (order == BuildOptions::Order::kSpatial) {
      EXPECT_GT(c.leaves, 20 * c.min_leaves);  // why the order is class-major
    } else {
      EXPECT_EQ(c.min_leaves, 1u);
      EXPECT_LE(c.leaves, 2 * c.min_leaves);
      EXPECT_LE(c.amplification, 1.0 * static_cast<double>(options.leaf_weight) / (85 * kWeight));
    }
  }
}

TEST(RTreeLocality, ViewQueriesReadFewUnusedBytesAndStayFlatAsTheHierarchyDeepens) {
  // An eye above the square; the tolerance needs levels up to 7 (error > tau * 0.3 > 2^-8), so
  // deeper hierarchies add ops the view must not pay for.
  const Point3 eye{0.1, 0.1, 0.3};
  const double tau = 0.02;
  for (int dims : {2, 3}) {
    for (auto order : {BuildOptions::Order::kResolutionBands, BuildOptions::Order::kSizeClasses}) {
      BuildOptions options;
      options.order = order;
      options.order_dims = dims;
      options.leaf_weight = 16 * 1024 - 16;  // ~127 ops a leaf: several leaves per level
      std::vector<Cost> costs;
      for (int depth : {8, 9}) {
        const auto built = test::build(quadtree(depth, 2), options);
        View v(eye, tau);
        costs.push_back(measure(built, v, options.leaf_weight));
        std::cout << "dims " << dims << " order " << static_cast<int>(order) << " depth " << depth
                  << ": leaves read " << costs.back().leaves << " (min " << costs.back().min_leaves
                  << "), amplification " << costs.back().amplification << "\n";
      }
      EXPECT_EQ(costs[0].min_leaves, costs[1].min_leaves);
      EXPECT_LE(static_cast<double>(costs[1].leaves), 1.5 * static_cast<double>(costs[0].leaves));
      for (const Cost& c : costs) {
        EXPECT_LE(c.leaves, 2 * c.min_leaves + 6);
        // Errors within a level are i.i.d. over a factor 2 here, so ops near the edge of the cut
        // are needed at random and no order reaches 1 (measured: 1.85 with resolution bands,
        // 2.2-2.3 with size classes or one band per octave).
        EXPECT_LE(c.amplification, order == BuildOptions::Order::kResolutionBands ? 2.0 : 2.4);
      }
    }
  }
}

}  // namespace
}  // namespace smr::index
