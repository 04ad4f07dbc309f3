// The self-intersection test's grid of triangle boxes (smr/builders/mesh/triangle_grid.h) against
// brute force. Random boxes of sizes spread over six octaves (so that they fall on several of the
// grid's levels), in two sets, are inserted, moved between sets and cells, erased and re-keyed in
// random order; after every batch of changes, random query boxes must visit:
//  - every triangle of the queried set whose box meets the query's, once, and no other;
//  - with the box it was given, rounded outwards to floats (it contains the double box);
//  - with a `least`, every one whose key exceeds it, and none whose key is at most `least`
//    rounded down (a key is kept rounded up to a float).
// Cells emptied and refilled reuse their slabs: a query after many erasures must still see the
// right triangles (a slab given back twice, or read after it was handed to another cell, fails).
#include "smr/builders/mesh/triangle_grid.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <random>
#include <vector>

namespace smr::qem {
namespace {

struct Placed {
  Box3 box;
  int set = 0;
  double key = std::numeric_limits<double>::infinity();
};

Box3 random_box(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const double size = 0.01 * std::exp2(6.0 * u(rng));  // 0.01 .. 0.64
  Box3 b;
  const Vec3 c(u(rng), u(rng), 0.2 * u(rng));
  b.add(c);
  b.add(c + Vec3(size * u(rng), size * u(rng), size * u(rng)));
  return b;
}

bool contains(const Box3& outer, const Box3& inner) {
  for (int k = 0; k < 3; ++k) {
    if (outer.lo[k] > inner.lo[k] || outer.hi[k] < inner.hi[k]) return false;
  }
  return true;
}

// Every query of `rounds` random boxes against brute force over `placed`.
void check_queries(const TriangleGrid& grid, const std::map<std::uint32_t, Placed>& placed,
                   std::mt19937_64& rng, int rounds) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int q = 0; q < rounds; ++q) {
    const Box3 query = random_box(rng);
    const int set = q % TriangleGrid::kSets;
    const double least = q % 3 == 0 ? -std::numeric_limits<double>::infinity() : u(rng);
    std::map<std::uint32_t, int> seen;
    grid.visit(
        query,
        [&](std::uint32_t id, const Box3& box) {
          ++seen[id];
          const auto it = placed.find(id);
          ASSERT_NE(it, placed.end()) << "visited a triangle not in the grid: " << id;
          EXPECT_TRUE(contains(box, it->second.box)) << "triangle " << id;
          EXPECT_TRUE(box.intersects(query)) << "triangle " << id;
          EXPECT_GT(
              double(std::nextafter(float(it->second.key), std::numeric_limits<float>::max())),
              least)
              << "triangle " << id << " has a key at most the query's least";
        },
        set, least);
    for (const auto& [id, p] : placed) {
      const bool meets = p.box.intersects(query);
      const bool expected = p.set == set && meets && p.key > least;
      const auto it = seen.find(id);
      if (expected) {
        ASSERT_NE(it, seen.end()) << "query " << q << " missed triangle " << id;
      }
      if (it != seen.end()) {
        EXPECT_EQ(it->second, 1) << "triangle " << id << " visited more than once";
        EXPECT_EQ(p.set, set) << "triangle " << id << " visited in the wrong set";
      }
    }
  }
}

TEST(TriangleGrid, VisitsWhatBruteForceFindsThroughInsertsMovesErasuresAndKeys) {
  std::mt19937_64 rng(20261207);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  TriangleGrid grid;
  grid.reset(Vec3(0.0), 0.02);
  std::map<std::uint32_t, Placed> placed;
  std::uint32_t next_id = 0;
  for (int batch = 0; batch < 40; ++batch) {
    for (int k = 0; k < 200; ++k) {
      const double r = u(rng);
      if (r < 0.5 || placed.empty()) {  // a new triangle, ids not in order of insertion
        const std::uint32_t id = next_id++ * 7 % 100003;
        Placed p{random_box(rng), int(u(rng) * TriangleGrid::kSets)};
        grid.insert(id, p.box, p.set);
        placed[id] = p;
        continue;
      }
      auto it = placed.begin();
      std::advance(it, std::size_t(u(rng) * double(placed.size())));
      const std::uint32_t id = it->first;
      if (r < 0.65) {
        grid.erase(id);
        placed.erase(it);
      } else if (r < 0.8) {  // moved: a new box, set and key
        Placed p{random_box(rng), int(u(rng) * TriangleGrid::kSets), u(rng)};
        grid.insert(id, p.box, p.set, p.key);
        it->second = p;
      } else {
        it->second.key = u(rng);
        grid.set_key(id, it->second.key);
      }
    }
    grid.erase(next_id + 100003);  // absent: nothing happens
    grid.set_key(next_id + 100003, 0.5);
    check_queries(grid, placed, rng, 20);
    if (batch == 20) {  // empty every cell, then fill them again from reused slabs
      for (const auto& [id, p] : placed) grid.erase(id);
      placed.clear();
      check_queries(grid, placed, rng, 5);
    }
  }
  EXPECT_GT(placed.size(), 1000u);
}

// Keys are rounded up: a key just above `least` whose float rounds to nearest below it is still
// visited, and one equal to a float is passed over at that float.
TEST(TriangleGrid, KeysRoundUpSoNoTriangleAboveLeastIsPassedOver) {
  TriangleGrid grid;
  grid.reset(Vec3(0.0), 1.0);
  Box3 b;
  b.add(Vec3(0.0));
  b.add(Vec3(0.5));
  const double key = 0.7;  // not a float: float(0.7) < 0.7
  ASSERT_LT(double(float(key)), key);
  grid.insert(7, b, 0, key);
  const auto count = [&](double least) {
    int n = 0;
    grid.visit(
        b, [&](std::uint32_t, const Box3&) { ++n; }, 0, least);
    return n;
  };
  EXPECT_EQ(count(std::nextafter(key, 0.0)), 1);
  EXPECT_EQ(count(double(float(key))), 1);
  grid.set_key(7, 0.25);  // a float
  EXPECT_EQ(count(0.25), 0);
  EXPECT_EQ(count(std::nextafter(0.25, 0.0)), 1);
  // Beyond floats' range: an infinite key (a live triangle) is above the largest double, and a
  // key above the largest float is kept as +inf, not passed over below it.
  grid.set_key(7, std::numeric_limits<double>::infinity());
  EXPECT_EQ(count(std::numeric_limits<double>::max()), 1);
  grid.set_key(7, 1e300);
  EXPECT_EQ(count(1e299), 1);
  grid.erase(7);
  EXPECT_EQ(count(-1.0), 0);
  grid.set_key(7, 0.5);  // erased: nothing happens
  EXPECT_EQ(count(-1.0), 0);
}

}  // namespace
}  // namespace smr::qem
