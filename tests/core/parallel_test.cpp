// smr/core/parallel.h: results combined in order whatever the thread count, and failures in any
// stage reach the caller (no deadlock, nothing merged after the failing item).
#include "smr/core/parallel.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <memory>
#include <mutex>
#include <numeric>
#include <set>
#include <stdexcept>
#include <thread>
#include <vector>

namespace smr {
namespace {

struct Item {
  std::size_t k = 0;
  std::uint64_t value = 0;
};

std::uint64_t slow_hash(std::size_t k) {
  std::uint64_t h = k + 1;
  for (int i = 0; i < 2000 + int(k % 7) * 500; ++i)
    h = h * 6364136223846793005ull + 1442695040888963407ull;
  return h;
}

TEST(OrderedPipeline, MergesInOrderWhateverTheThreads) {
  const std::size_t n = 200;
  std::vector<std::uint64_t> reference;
  for (std::size_t k = 0; k < n; ++k) reference.push_back(slow_hash(k));
  for (unsigned threads : {1u, 2u, 3u, 8u}) {
    SCOPED_TRACE("threads " + std::to_string(threads));
    std::vector<std::size_t> made, merged;
    std::vector<std::uint64_t> values;
    std::atomic<int> in_flight{0}, most{0};
    ordered_pipeline(
        n, threads, 4,
        [&](std::size_t k) {
          made.push_back(k);
          const int now = ++in_flight;
          most = std::max(most.load(), now);
          auto item = std::make_unique<Item>();
          item->k = k;
          return item;
        },
        [&](Item& item) { item.value = slow_hash(item.k); },
        [&](Item& item, std::size_t k) {
          --in_flight;
          EXPECT_EQ(item.k, k);
          merged.push_back(k);
          values.push_back(item.value);
        });
    std::vector<std::size_t> order(n);
    std::iota(order.begin(), order.end(), 0);
    EXPECT_EQ(made, order);
    EXPECT_EQ(merged, order);
    EXPECT_EQ(values, reference);
    EXPECT_LE(most.load(), 4) << "more items in flight than allowed";
  }
}

TEST(OrderedPipeline, AFailureInAnyStageReachesTheCaller) {
  for (unsigned threads : {1u, 2u, 4u}) {
    for (int stage = 0; stage < 3; ++stage) {
      SCOPED_TRACE("threads " + std::to_string(threads) + ", stage " + std::to_string(stage));
      std::size_t last_merged = 0;
      bool any = false;
      try {
        ordered_pipeline(
            100, threads, 6,
            [&](std::size_t k) {
              if (stage == 0 && k == 37) throw std::runtime_error("make 37");
              auto item = std::make_unique<Item>();
              item->k = k;
              return item;
            },
            [&](Item& item) {
              if (stage == 1 && item.k == 37) throw std::runtime_error("work 37");
              item.value = slow_hash(item.k);
            },
            [&](Item& item, std::size_t) {
              if (stage == 2 && item.k == 37) throw std::runtime_error("merge 37");
              last_merged = item.k;
              any = true;
            });
        FAIL() << "the failure was swallowed";
      } catch (const std::runtime_error& e) {
        EXPECT_NE(std::string(e.what()).find("37"), std::string::npos) << e.what();
      }
      EXPECT_TRUE(any);
      EXPECT_LT(last_merged, 37u) << "an item after the failing one was merged";
    }
  }
}

TEST(ParallelFor, EveryIndexOnceAndTheFirstFailureRethrown) {
  std::vector<std::atomic<int>> hits(1000);
  parallel_for(hits.size(), 3, [&](std::size_t i) { ++hits[i]; });
  for (const auto& h : hits) EXPECT_EQ(h.load(), 1);
  EXPECT_THROW(parallel_for(1000, 3,
                            [](std::size_t i) {
                              if (i == 500) throw std::runtime_error("500");
                            }),
               std::runtime_error);
  std::size_t calls = 0;
  parallel_for(0, 4, [&](std::size_t) { ++calls; });
  EXPECT_EQ(calls, 0u);
}

TEST(WorkerPool, ManyBatchesOnTheSameThreadsEachIndexOnce) {
  WorkerPool pool(3);
  std::mutex mu;
  std::set<std::thread::id> seen;
  for (std::size_t batch = 0; batch < 200; ++batch) {
    // Small batches, one after another: a helper that wakes late for one must not run the next
    // one's items twice or touch a finished batch's function.
    std::vector<std::atomic<int>> hits(batch % 7 + 1);
    pool.for_each(hits.size(), [&](std::size_t i) {
      std::this_thread::sleep_for(std::chrono::microseconds(50));  // so the helpers get items
      ++hits[i];
      std::lock_guard lock(mu);
      seen.insert(std::this_thread::get_id());
    });
    for (const auto& h : hits) ASSERT_EQ(h.load(), 1) << "batch " << batch;
  }
  EXPECT_LE(seen.size(), 3u) << "the batches started threads of their own";
  // A failure is rethrown once, and the pool still works after it.
  EXPECT_THROW(pool.for_each(100,
                             [](std::size_t i) {
                               if (i == 50) throw std::runtime_error("50");
                             }),
               std::runtime_error);
  std::atomic<std::size_t> sum{0};
  pool.for_each(100, [&](std::size_t i) { sum += i; });
  EXPECT_EQ(sum.load(), 4950u);
}

// The calling thread's own work runs while the helpers take the batch's items (the stream
// writer appends one window of pages while the next is encoded), then it joins them; a failure
// of its own work is rethrown only after the helpers have left the batch.
TEST(WorkerPool, CallersOwnWorkOverlapsTheBatch) {
  WorkerPool pool(2);
  const std::thread::id caller = std::this_thread::get_id();
  std::vector<std::atomic<int>> hits(64);
  std::atomic<int> done{0};
  int firsts = 0;
  bool overlapped = false;
  pool.for_each(
      hits.size(),
      [&](std::size_t i) {
        std::this_thread::sleep_for(std::chrono::microseconds(200));
        ++hits[i];
        ++done;
      },
      [&] {
        EXPECT_EQ(std::this_thread::get_id(), caller);
        ++firsts;
        // The helper finishes items while the caller is still here (however slowly it is
        // scheduled: up to 10 s).
        const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(10);
        while (done.load() == 0 && std::chrono::steady_clock::now() < until) {
          std::this_thread::sleep_for(std::chrono::microseconds(100));
        }
        overlapped = done.load() > 0;
      });
  EXPECT_EQ(firsts, 1);
  for (const auto& h : hits) ASSERT_EQ(h.load(), 1);
  EXPECT_TRUE(overlapped) << "the helper waited for the caller's own work";

  std::atomic<int> started{0};
  EXPECT_THROW(pool.for_each(
                   1000,
                   [&](std::size_t) {
                     ++started;
                     std::this_thread::sleep_for(std::chrono::microseconds(100));
                   },
                   [] { throw std::runtime_error("first"); }),
               std::runtime_error);
  EXPECT_LT(started.load(), 1000) << "items went on after the caller's work failed";
  std::atomic<std::size_t> sum{0};
  pool.for_each(100, [&](std::size_t i) { sum += i; });
  EXPECT_EQ(sum.load(), 4950u) << "the pool works after a failure";
}

// Turns taken from many threads, started last turn first, run one at a time, 0, 1, 2, ...; a turn
// that throws still lets the next one go; reset() starts again from 0.
TEST(Turnstile, TurnsRunInOrderOneAtATimeAndAThrowPassesTheTurnOn) {
  constexpr std::size_t kTurns = 64;
  Turnstile turns;
  for (int round = 0; round < 2; ++round) {
    turns.reset();
    std::vector<std::size_t> order;
    std::atomic<int> inside{0};
    bool overlapped = false;
    std::vector<std::thread> threads;
    for (std::size_t t = 8; t-- > 0;) {  // the threads with the later turns start first
      threads.emplace_back([&, t] {
        for (std::size_t k = t; k < kTurns; k += 8) {  // each its own turns, in order
          try {
            turns.run(k, [&] {
              if (inside.fetch_add(1) != 0) overlapped = true;
              std::this_thread::sleep_for(std::chrono::microseconds(50));
              order.push_back(k);
              inside.fetch_sub(1);
              if (k % 10 == 3) throw std::runtime_error("turn failed");
            });
          } catch (const std::runtime_error&) {
          }
        }
      });
    }
    for (std::thread& t : threads) t.join();
    EXPECT_FALSE(overlapped) << "two turns ran at once";
    std::vector<std::size_t> want(kTurns);
    std::iota(want.begin(), want.end(), std::size_t{0});
    EXPECT_EQ(order, want);
  }
}

}  // namespace
}  // namespace smr
