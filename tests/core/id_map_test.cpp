// smr/core/id_map.h against std::unordered_map: same contents after random inserts and updates
// and erases (with growth from empty), lookups of absent ids, iteration visiting each entry once.
#include "smr/core/id_map.h"

#include <gtest/gtest.h>

#include <random>
#include <unordered_map>

namespace smr {
namespace {

TEST(IdMap, AgreesWithUnorderedMap) {
  std::mt19937_64 rng(5);
  for (std::uint64_t range : {8ull, 1000ull, 1ull << 40}) {
    IdMap<std::uint32_t> m;
    std::unordered_map<std::uint64_t, std::uint32_t> truth;
    EXPECT_TRUE(m.empty());
    EXPECT_EQ(m.find(3), nullptr);
    for (int i = 0; i < 200000; ++i) {
      const std::uint64_t id = rng() % range;
      const std::uint64_t op = rng() % 3;
      if (op == 2) {
        ASSERT_EQ(m.erase(id), truth.erase(id) == 1) << id;
      } else if (op == 1) {
        EXPECT_EQ(m.insert(id), truth.emplace(id, 0).second);
      } else {
        const auto v = static_cast<std::uint32_t>(rng());
        m[id] = v;
        truth[id] = v;
      }
      const std::uint64_t probe = rng() % (2 * range);
      const auto it = truth.find(probe);
      const std::uint32_t* got = m.find(probe);
      ASSERT_EQ(got != nullptr, it != truth.end()) << probe;
      if (got != nullptr) {
        ASSERT_EQ(*got, it->second);
      }
    }
    ASSERT_EQ(m.size(), truth.size());
    std::size_t visited = 0;
    m.for_each([&](std::uint64_t id, std::uint32_t v) {
      ++visited;
      ASSERT_EQ(truth.at(id), v);
    });
    EXPECT_EQ(visited, truth.size());
  }
}

TEST(IdTable, ArrayAndMapAgreeWithAReferenceMap) {
  // Small n: an array; huge n: a hashed map. Both read 0 until set and keep what is set.
  std::mt19937_64 rng(7);
  for (const std::uint64_t n : {std::uint64_t{5000}, std::uint64_t{1} << 40}) {
    IdTable<std::uint8_t> t(n);
    EXPECT_EQ(t.dense(), n == 5000);
    std::unordered_map<std::uint64_t, std::uint8_t> truth;
    for (int step = 0; step < 20000; ++step) {
      const std::uint64_t id = rng() % std::min<std::uint64_t>(n, 9000);
      const auto v = static_cast<std::uint8_t>(rng());
      t[id] |= v;
      truth[id] |= v;
      const std::uint64_t probe = rng() % std::min<std::uint64_t>(n, 9000);
      const auto it = truth.find(probe);
      ASSERT_EQ(t.get(probe), it == truth.end() ? 0 : it->second) << probe;
    }
    EXPECT_EQ(t.get(n + 1), 0);  // beyond the ids: unset, not a crash
  }
  IdTable<std::uint8_t> small(10);
  EXPECT_THROW(small[10], Error);  // setting beyond the array is a bug, caught
}

}  // namespace
}  // namespace smr
