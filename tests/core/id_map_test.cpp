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

}  // namespace
}  // namespace smr
