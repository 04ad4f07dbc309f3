// SpillArray: the same values as a std::vector whatever the access pattern and the budget, and a
// resident set that stays within the budget while the in-memory table grows with its length.
#include "storage/spill_array.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include <fcntl.h>
#include <unistd.h>

namespace smr::storage {
namespace {

std::string tmp() {
  return std::filesystem::temp_directory_path().string();
}

// The process's resident set, in bytes (statm's second field, in pages). Read without allocating:
// under AddressSanitizer each allocation is fresh memory held in quarantine, which the measure
// would count.
std::uint64_t rss_bytes() {
  char buf[128] = {};
  const int fd = ::open("/proc/self/statm", O_RDONLY);
  if (fd < 0) return 0;
  const ssize_t n = ::read(fd, buf, sizeof buf - 1);
  ::close(fd);
  if (n <= 0) return 0;
  unsigned long long size = 0, resident = 0;
  if (std::sscanf(buf, "%llu %llu", &size, &resident) != 2) return 0;
  return resident * static_cast<std::uint64_t>(::sysconf(_SC_PAGESIZE));
}

TEST(SpillArray, HoldsTheValuesOfAVectorUnderAnyBudget) {
  for (const std::uint64_t budget : {std::uint64_t{0}, std::uint64_t{64} << 10}) {
    SpillArray<std::uint64_t> a(tmp(), budget);
    std::vector<std::uint64_t> ref;
    std::mt19937_64 rng(11);
    for (std::uint64_t i = 0; i < 200'000; ++i) {  // grows through several reserves
      const std::uint64_t v = rng();
      a.push_back(v);
      ref.push_back(v);
      if (i % 3 == 0) {  // and changes earlier values, far back
        const std::size_t j = rng() % ref.size();
        ref[j] = rng();
        a.set(j, ref[j]);
      }
    }
    a.resize(400'000);
    ref.resize(400'000);
    ASSERT_EQ(a.size(), ref.size());
    for (std::size_t k = 0; k < 50'000; ++k) {
      const std::size_t j = rng() % ref.size();
      ASSERT_EQ(a[j], ref[j]) << "value " << j << ", budget " << budget;
    }
    for (std::size_t j = 0; j < ref.size(); ++j) ASSERT_EQ(a[j], ref[j]) << "value " << j;
    EXPECT_EQ(a.spilled(), budget > 0);
    if (budget > 0) {
      EXPECT_GT(a.fills(), 0u);
    }
  }
}

TEST(SpillArray, StaysWithinItsBudgetWhereAVectorGrows) {
  constexpr std::size_t n = std::size_t{16} << 20;  // 128 MiB of values
  constexpr std::uint64_t budget = std::uint64_t{4} << 20;
  // Filled in order, then read and written at random (values changed, so that a lost write-back
  // shows). Random reads are what made the table's first design, a mapping of the file whose
  // pages were dropped every so many accesses, hold 25 times its budget: the kernel maps up to
  // 16 cached neighbours on a read fault.
  std::vector<bool> flipped(n);
  const auto growth = [&](std::uint64_t b) {
    std::fill(flipped.begin(), flipped.end(), false);
    const std::uint64_t before = rss_bytes();
    SpillArray<std::uint64_t> a(tmp(), b);
    a.resize(n);
    std::uint64_t peak = before;
    for (std::size_t i = 0; i < n; ++i) {
      a.set(i, i * 3);
      if (i % 65536 == 0) peak = std::max(peak, rss_bytes());
    }
    std::mt19937_64 rng(5);
    std::uint64_t wrong = 0;
    for (std::size_t k = 0; k < 200'000; ++k) {
      const std::size_t i = rng() % n;
      if (k % 4 == 0) {
        flipped[i] = !flipped[i];
        a.set(i, i * 3 + flipped[i]);
      } else if (a[i] != i * 3 + flipped[i]) {
        ++wrong;
      }
      if (k % 4096 == 0) peak = std::max(peak, rss_bytes());
    }
    EXPECT_EQ(wrong, 0u);
    return std::max(peak, rss_bytes()) - before;
  };
  const std::uint64_t spilled = growth(budget), in_memory = growth(0);
  EXPECT_GT(in_memory, std::uint64_t{100} << 20) << "the measure cannot see the table";
  // The margin: code and the allocator's first pages (and the sanitizer's shadow of the slots).
  EXPECT_LT(spilled, budget + (std::uint64_t{2} << 20));
}

TEST(SpillArray, ResizeAndPushBackAgreeWithAVector) {
  for (const std::uint64_t budget : {std::uint64_t{0}, std::uint64_t{64} << 10}) {
    SpillArray<std::uint32_t> a(tmp(), budget);
    std::vector<std::uint32_t> ref;
    const auto check = [&] {
      ASSERT_EQ(a.size(), ref.size());
      for (std::size_t i = 0; i < ref.size(); ++i) ASSERT_EQ(a[i], ref[i]) << i << ", " << budget;
    };
    a.resize(300'000);  // then pushed onto: past what resize reserved
    ref.resize(300'000);
    for (std::uint32_t i = 0; i < 300'000; ++i) {
      a.set(i, i + 1);
      ref[i] = i + 1;
    }
    for (std::uint32_t i = 0; i < 2'000'000; ++i) {
      a.push_back(~i);
      ref.push_back(~i);
    }
    check();
    a.resize(1000);  // shrunk, then grown: the values past 1000 are zero again
    ref.resize(1000);
    a.resize(500'000);
    ref.resize(500'000);
    check();
  }
}

TEST(SpillArray, ThreadsReadWhileSlotsAreRefilled) {
  // 32 blocks over 16 slots: reads of blocks at hand race with refills all the time.
  SpillArray<std::uint32_t> a(tmp(), 64 << 10);
  constexpr std::uint32_t n = 32 * 1024;
  a.resize(n);
  for (std::uint32_t i = 0; i < n; ++i) a.set(i, i ^ 0x5bd1e995u);
  std::vector<std::uint64_t> wrong(4, 0);
  std::vector<std::thread> threads;
  for (std::size_t t = 0; t < wrong.size(); ++t) {
    threads.emplace_back([&, t] {
      std::mt19937 rng(static_cast<unsigned>(t));
      for (int k = 0; k < 50'000; ++k) {
        const auto i = static_cast<std::uint32_t>(rng() % n);
        if (a[i] != (i ^ 0x5bd1e995u)) ++wrong[t];
      }
    });
  }
  for (auto& th : threads) th.join();
  for (std::uint64_t w : wrong) EXPECT_EQ(w, 0u);
  EXPECT_GT(a.fills(), 100u);
}

}  // namespace
}  // namespace smr::storage
