// ExternalSorter and ExternalQueue against std::stable_sort and std::priority_queue semantics,
// with budgets small enough that the data spills into many runs.
#include "storage/external_sort.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <random>
#include <tuple>
#include <vector>

namespace smr::storage {
namespace {

struct Rec {
  std::uint32_t key;
  std::uint32_t tag;  // arrival order: checks stability
  double payload;
};
struct ByKey {
  bool operator()(const Rec& a, const Rec& b) const { return a.key < b.key; }
};

std::vector<Rec> random_records(std::size_t n, std::uint32_t keys, unsigned seed) {
  std::mt19937 rng(seed);
  std::vector<Rec> v(n);
  for (std::size_t i = 0; i < n; ++i)
    v[i] = {static_cast<std::uint32_t>(rng() % keys), static_cast<std::uint32_t>(i),
            static_cast<double>(rng()) * 0.5};
  return v;
}

// Both spill modes: with Spill::kBackground, full buffers are sorted and written on another
// thread while the adds go on; the output must not change.
TEST(ExternalSorter, MatchesStableSortAcrossManyRuns) {
  for (const Spill spill : {Spill::kInline, Spill::kBackground}) {
    for (const std::uint64_t memory :
         {std::uint64_t{0}, std::uint64_t{100} << 10, std::uint64_t{64} << 20}) {
      SCOPED_TRACE(spill == Spill::kInline ? "inline spills" : "background spills");
      const std::vector<Rec> in = random_records(200000, 5000, 7);
      ExternalSorter<Rec, ByKey> sorter("", memory, ByKey{}, spill);
      for (const Rec& r : in) sorter.add(r);
      std::vector<Rec> want = in;
      std::stable_sort(want.begin(), want.end(), ByKey{});
      std::vector<Rec> got;
      Rec r{};
      while (sorter.next(r)) got.push_back(r);
      ASSERT_EQ(got.size(), want.size()) << memory;
      for (std::size_t i = 0; i < got.size(); ++i) {
        ASSERT_EQ(std::tie(got[i].key, got[i].tag), std::tie(want[i].key, want[i].tag))
            << "record " << i << " with a budget of " << memory;
      }
      EXPECT_EQ(sorter.size(), in.size());
      if (memory < (std::uint64_t{1} << 20)) {
        EXPECT_GT(sorter.runs(), 8u) << "the budget should have forced runs";
        EXPECT_GT(sorter.spilled_bytes(), 0u);
        // More runs than one merge may read within the budget (16 at these sizes): groups of
        // them were merged first, so the data was written more than once.
        if (sorter.runs() > 16) {
          EXPECT_GT(sorter.spilled_bytes(), in.size() * sizeof(Rec)) << memory;
        }
      } else {
        EXPECT_EQ(sorter.runs(), 0u);
      }
    }
  }
}

// Ties::kAny: the same records in key order (ties in some order), and the same order for the
// same sequence of adds; each record takes 16 bytes of scratch, not 24.
TEST(ExternalSorter, AnyTiesKeepsEveryRecordInKeyOrderWithoutArrivalNumbers) {
  for (const std::uint64_t memory : {std::uint64_t{0}, std::uint64_t{100} << 10}) {
    const std::vector<Rec> in = random_records(200000, 5000, 11);
    auto sorted = [&] {
      ExternalSorter<Rec, ByKey, Ties::kAny> sorter("", memory);
      for (const Rec& r : in) sorter.add(r);
      sorter.seal();
      std::vector<Rec> got;
      Rec r{};
      while (sorter.next(r)) got.push_back(r);
      EXPECT_EQ(sorter.spilled_bytes() % sizeof(Rec), 0u);
      // Written at most twice (the runs, then one pass merging groups of them: more runs than
      // one merge reads within these budgets), 16 bytes a record: with arrival numbers each
      // write would take 24.
      EXPECT_LE(sorter.spilled_bytes(), 2 * in.size() * sizeof(Rec));
      EXPECT_GT(sorter.runs(), 8u) << "the budget should have forced runs";
      return got;
    };
    const std::vector<Rec> got = sorted();
    ASSERT_EQ(got.size(), in.size());
    for (std::size_t i = 1; i < got.size(); ++i) {
      ASSERT_LE(got[i - 1].key, got[i].key) << "record " << i << " with a budget of " << memory;
    }
    std::vector<std::uint32_t> tags;
    for (const Rec& r : got) tags.push_back(r.tag);
    std::sort(tags.begin(), tags.end());
    for (std::uint32_t i = 0; i < tags.size(); ++i) ASSERT_EQ(tags[i], i) << "a record was lost";
    const std::vector<Rec> again = sorted();
    for (std::size_t i = 0; i < got.size(); ++i) ASSERT_EQ(again[i].tag, got[i].tag) << i;
  }
}

TEST(ExternalSorter, EmptyAndAddAfterReadingIsAnError) {
  ExternalSorter<Rec, ByKey> sorter("", 0);
  Rec r{};
  EXPECT_FALSE(sorter.next(r));
  EXPECT_THROW(sorter.add(r), Error);
}

// A background spill's error reaches the adder too: at the next full buffer, or at seal().
TEST(ExternalSorter, MissingDirectoryNamesIt) {
  for (const Spill spill : {Spill::kInline, Spill::kBackground}) {
    ExternalSorter<Rec, ByKey> sorter("/nonexistent/smrdb-tmp", 0, ByKey{}, spill);
    try {
      for (std::uint32_t i = 0; i < 5000; ++i) sorter.add({i, i, 0.0});
      sorter.seal();
      FAIL() << "spilling into a missing directory should throw";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("/nonexistent/smrdb-tmp"), std::string::npos)
          << e.what();
    }
  }
}

// A backward sweep (time-forward processing): item i sends messages to random earlier items; at
// each item the queue must give exactly the messages sent to it, in the order they were sent.
TEST(ExternalQueue, BackwardSweepDeliversEveryMessageInPushOrder) {
  constexpr std::uint32_t kItems = 60000;
  for (const std::uint64_t memory : {std::uint64_t{0}, std::uint64_t{64} << 20}) {
    std::mt19937 rng(11);
    ExternalQueue<Rec, ByKey> queue("", memory);
    std::vector<std::vector<std::uint32_t>> sent(kItems);
    std::uint32_t tag = 0;
    std::uint64_t delivered = 0;
    for (std::uint32_t i = kItems; i-- > 0;) {
      std::vector<std::uint32_t> got;
      while (!queue.empty() && queue.top().key >= i) {
        ASSERT_EQ(queue.top().key, i) << "a message for a later item is still queued";
        got.push_back(queue.top().tag);
        queue.pop();
      }
      ASSERT_EQ(got, sent[i]) << "item " << i << ", budget " << memory;
      delivered += got.size();
      if (i == 0) break;
      const int n = static_cast<int>(rng() % 5);
      for (int k = 0; k < n; ++k) {
        const std::uint32_t to = static_cast<std::uint32_t>(rng() % i);
        queue.push({to, tag, 0.0});
        sent[to].push_back(tag++);
      }
    }
    EXPECT_TRUE(queue.empty());
    EXPECT_EQ(delivered, tag);
    if (memory == 0) {
      EXPECT_GT(queue.runs(), detail::kQueueMaxRuns) << "the runs should have been merged";
    } else {
      EXPECT_EQ(queue.runs(), 0u);
    }
  }
}

}  // namespace
}  // namespace smr::storage
