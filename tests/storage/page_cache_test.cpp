#include "storage/page_cache.h"

#include <atomic>
#include <random>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

namespace smr::storage {
namespace {

using Cache = PageCache<std::string>;

std::string name(std::uint64_t key) {
  std::string s("v");
  s += std::to_string(key);
  return s;
}

// Loads "v<key>" charged `size` bytes, counting calls.
std::function<Cache::Loaded()> loader(std::uint64_t key, std::size_t size, int* calls = nullptr) {
  return [=] {
    if (calls != nullptr) ++*calls;
    return Cache::Loaded{std::make_shared<const std::string>(name(key)), size, size / 2};
  };
}

TEST(PageCache, HitsMissesAndCounters) {
  Cache cache(100);
  EXPECT_EQ(cache.budget(), 100u);
  int calls = 0;
  EXPECT_EQ(*cache.get(1, loader(1, 10, &calls)), "v1");
  EXPECT_EQ(*cache.get(1, loader(1, 10, &calls)), "v1");
  EXPECT_EQ(*cache.get(2, loader(2, 20, &calls)), "v2");
  EXPECT_EQ(calls, 2);
  CacheStats s = cache.stats();
  EXPECT_EQ(s.hits, 1u);
  EXPECT_EQ(s.misses, 2u);
  EXPECT_EQ(s.evictions, 0u);
  EXPECT_EQ(s.bytes_decoded, 30u);
  EXPECT_EQ(s.bytes_read, 15u);
  EXPECT_EQ(s.held_bytes, 30u);
  EXPECT_EQ(s.peak_held_bytes, 30u);
  cache.clear();
  EXPECT_EQ(cache.stats().held_bytes, 0u);
  EXPECT_EQ(cache.size(), 0u);
  EXPECT_EQ(*cache.get(1, loader(1, 10, &calls)), "v1");
  EXPECT_EQ(calls, 3);
}

TEST(PageCache, EvictsLeastRecentlyUsedFirst) {
  Cache cache(30);
  cache.get(1, loader(1, 10));
  cache.get(2, loader(2, 10));
  cache.get(3, loader(3, 10));
  cache.get(1, loader(1, 10));  // 1 is now the most recent; 2 the least
  cache.get(4, loader(4, 10));
  EXPECT_TRUE(cache.contains(1));
  EXPECT_FALSE(cache.contains(2));
  EXPECT_TRUE(cache.contains(3));
  EXPECT_TRUE(cache.contains(4));
  EXPECT_EQ(cache.stats().evictions, 1u);
  cache.get(5, loader(5, 20));  // needs 20: evicts 3 then 1
  EXPECT_FALSE(cache.contains(3));
  EXPECT_FALSE(cache.contains(1));
  EXPECT_TRUE(cache.contains(4));
  EXPECT_TRUE(cache.contains(5));
  EXPECT_EQ(cache.stats().evictions, 3u);
  EXPECT_EQ(cache.stats().held_bytes, 30u);
}

TEST(PageCache, OversizeValuesAreReturnedButNotKept) {
  Cache cache(50);
  cache.get(1, loader(1, 40));
  int calls = 0;
  const auto big = cache.get(2, loader(2, 51, &calls));
  EXPECT_EQ(*big, "v2");
  EXPECT_FALSE(cache.contains(2));
  EXPECT_TRUE(cache.contains(1));  // nothing evicted for a value that is not kept
  EXPECT_EQ(cache.stats().held_bytes, 40u);
  cache.get(2, loader(2, 51, &calls));
  EXPECT_EQ(calls, 2);
  Cache zero(0);
  EXPECT_EQ(*zero.get(1, loader(1, 1)), "v1");
  EXPECT_EQ(zero.size(), 0u);
  EXPECT_EQ(*zero.get(1, loader(1, 0)), "v1");  // a free value fits even a zero budget
}

TEST(PageCache, EvictedValuesStayAliveWhileHeld) {
  Cache cache(10);
  const auto held = cache.get(1, loader(1, 10));
  cache.get(2, loader(2, 10));
  EXPECT_FALSE(cache.contains(1));
  EXPECT_EQ(*held, "v1");
}

TEST(PageCache, FailedLoadCachesNothing) {
  Cache cache(100);
  EXPECT_THROW(cache.get(1, []() -> Cache::Loaded { throw std::runtime_error("disk"); }),
               std::runtime_error);
  EXPECT_FALSE(cache.contains(1));
  EXPECT_EQ(*cache.get(1, loader(1, 5)), "v1");
}

TEST(PageCache, NeverHoldsMoreThanBudgetUnderRandomAccess) {
  std::mt19937_64 rng(21);
  Cache cache(1000);
  std::uint64_t gets = 0;
  for (int i = 0; i < 20000; ++i) {
    const std::uint64_t key = rng() % 200;
    const std::size_t size = 1 + (key * 7919) % 150;  // the same key always costs the same
    ASSERT_EQ(*cache.get(key, loader(key, size)), name(key));
    ++gets;
    const CacheStats s = cache.stats();
    ASSERT_LE(s.held_bytes, 1000u);
  }
  const CacheStats s = cache.stats();
  EXPECT_LE(s.peak_held_bytes, 1000u);
  EXPECT_GT(s.peak_held_bytes, 850u);  // the budget is actually used
  EXPECT_EQ(s.hits + s.misses, gets);
  EXPECT_GT(s.hits, 0u);
  EXPECT_GT(s.evictions, 0u);
}

TEST(PageCache, ConcurrentGetsFromFourThreads) {
  Cache cache(2000);
  std::atomic<int> wrong{0};
  std::atomic<std::uint64_t> gets{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      std::mt19937_64 rng(static_cast<std::uint64_t>(t) + 100);
      for (int i = 0; i < 20000; ++i) {
        const std::uint64_t key = rng() % 300;
        const auto v = cache.get(key, loader(key, 1 + key % 64));
        if (*v != name(key)) ++wrong;
        ++gets;
      }
    });
  }
  for (auto& th : threads) th.join();
  const CacheStats s = cache.stats();
  EXPECT_EQ(wrong.load(), 0);
  EXPECT_EQ(s.hits + s.misses, gets.load());
  EXPECT_LE(s.peak_held_bytes, 2000u);
  EXPECT_LE(s.held_bytes, 2000u);
  EXPECT_GT(s.hits, 0u);
}

}  // namespace
}  // namespace smr::storage
