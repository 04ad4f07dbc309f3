// Chunked: elements stay where they were put, and chunks freed by one array are reused by the
// next (the pool that spares the block builders a fresh, faulted-in chunk per block), up to the
// pool's limit, without one array ever seeing another's elements.
#include "smr/core/chunked.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <memory>
#include <vector>

namespace smr {
namespace {

struct Rec {
  std::uint64_t a = 0;
  std::uint32_t b = 0;
};
using Small = Chunked<Rec, 4>;  // 16 elements a chunk, 256 bytes

TEST(Chunked, FreedChunksAreReusedUpToThePoolsLimitAndHoldOnlyTheirOwnElements) {
  Small::Pool& pool = Small::Pool::instance();
  const std::size_t before = pool.pooled();
  {
    Small first;
    for (std::uint32_t i = 0; i < 5 * Small::kChunk; ++i) first.push_back({i, i + 1});
    ASSERT_EQ(first.size(), 5 * Small::kChunk);
  }
  EXPECT_EQ(pool.pooled(), before + 5) << "the five chunks of a dropped array are kept";

  // Arrays made while the pool holds chunks take them, and see only what they put there.
  std::vector<std::unique_ptr<Small>> arrays;
  for (int k = 0; k < 3; ++k) {
    arrays.push_back(std::make_unique<Small>());
    for (std::uint32_t i = 0; i < Small::kChunk + 3; ++i) {
      arrays.back()->push_back({std::uint64_t(k) << 32 | i, i});
    }
  }
  EXPECT_EQ(pool.pooled(), before + 5 - 5) << "six chunks wanted, five were pooled";
  for (int k = 0; k < 3; ++k) {
    const Small& x = *arrays[std::size_t(k)];
    ASSERT_EQ(x.size(), Small::kChunk + 3);
    for (std::uint32_t i = 0; i < x.size(); ++i) {
      ASSERT_EQ(x[i].a, std::uint64_t(k) << 32 | i) << "array " << k << " element " << i;
      ASSERT_EQ(x[i].b, i);
    }
  }
  // drain() hands each chunk back as it is visited, in order.
  std::uint64_t visited = 0;
  arrays[0]->drain([&](std::size_t i, const Rec& r) {
    EXPECT_EQ(r.b, i);
    ++visited;
  });
  EXPECT_EQ(visited, Small::kChunk + 3);
  EXPECT_TRUE(arrays[0]->empty());
  EXPECT_EQ(pool.pooled(), before + 2);
  arrays.clear();
  EXPECT_EQ(pool.pooled(), before + 6);

  // Never more than the limit: the rest go back to the allocator.
  {
    std::vector<std::unique_ptr<Small>> many;
    const std::size_t n = Small::Pool::kMaxChunks + 10;
    for (std::size_t k = 0; k < n; ++k) {
      many.push_back(std::make_unique<Small>());
      many.back()->push_back({k, 0});
    }
  }
  EXPECT_EQ(pool.pooled(), Small::Pool::kMaxChunks);
}

}  // namespace
}  // namespace smr
