// Parallel helpers for work whose results are combined in order, so that output never depends
// on the thread count: parallel_for (independent items, results by index) and ordered_pipeline
// (items made and merged in order on the calling thread, worked on by a pool).
#pragma once

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <deque>
#include <exception>
#include <memory>
#include <mutex>
#include <thread>
#include <type_traits>
#include <vector>

namespace smr {

inline unsigned thread_count(unsigned requested) {
  return requested != 0 ? requested : std::max(1u, std::thread::hardware_concurrency());
}

/// f(i) for i in [0, n) on up to `threads` threads (0 = one per core) pulling indices from a
/// shared counter. The first exception thrown by any f is rethrown once every thread has stopped.
template <class F>
void parallel_for(std::size_t n, unsigned threads, F&& f) {
  threads = static_cast<unsigned>(std::min<std::size_t>(thread_count(threads), n));
  if (threads <= 1) {
    for (std::size_t i = 0; i < n; ++i) f(i);
    return;
  }
  std::atomic<std::size_t> next{0};
  std::atomic<bool> failed{false};
  std::exception_ptr error;
  std::mutex mu;
  auto run = [&] {
    for (std::size_t i; !failed.load() && (i = next.fetch_add(1)) < n;) {
      try {
        f(i);
      } catch (...) {
        std::lock_guard lock(mu);
        if (!error) error = std::current_exception();
        failed = true;
      }
    }
  };
  std::vector<std::thread> pool;
  for (unsigned t = 1; t < threads; ++t) pool.emplace_back(run);
  run();
  for (std::thread& t : pool) t.join();
  if (error) std::rethrow_exception(error);
}

/// An ordered pipeline for work whose results must be combined in order: for k = 0 .. n-1,
/// make(k) -> std::unique_ptr<T> runs on the calling thread in order, work(T&) on `threads`
/// workers, and merge(T&, k) on the calling thread in order, with at most `in_flight` items
/// made and not yet merged. So make and merge may touch shared state freely, and the result
/// does not depend on the number of threads. With one thread everything runs inline. The first
/// exception (from any stage) stops the pipeline and is rethrown on the calling thread.
template <class Make, class Work, class Merge>
void ordered_pipeline(std::size_t n, unsigned threads, std::size_t in_flight, Make&& make,
                      Work&& work, Merge&& merge) {
  using Item = typename std::invoke_result_t<Make&, std::size_t>::element_type;
  threads = static_cast<unsigned>(std::min<std::size_t>(thread_count(threads), n));
  if (threads <= 1) {
    for (std::size_t k = 0; k < n; ++k) {
      auto item = make(k);
      work(*item);
      merge(*item, k);
    }
    return;
  }
  struct Slot {
    std::unique_ptr<Item> item;
    std::exception_ptr error;
    bool done = false;
  };
  std::mutex mu;
  std::condition_variable work_cv, done_cv;
  std::deque<Slot*> queue;
  std::vector<Slot> slots(n);
  bool stop = false;
  auto worker = [&] {
    for (;;) {
      Slot* slot = nullptr;
      {
        std::unique_lock lock(mu);
        work_cv.wait(lock, [&] { return stop || !queue.empty(); });
        if (queue.empty()) return;
        slot = queue.front();
        queue.pop_front();
      }
      try {
        work(*slot->item);
      } catch (...) {
        slot->error = std::current_exception();
      }
      {
        std::lock_guard lock(mu);
        slot->done = true;
      }
      done_cv.notify_all();
    }
  };
  std::vector<std::thread> pool;
  auto join = [&] {
    {
      std::lock_guard lock(mu);
      stop = true;
      queue.clear();
    }
    work_cv.notify_all();
    for (std::thread& t : pool) t.join();
    pool.clear();
  };
  try {
    for (unsigned i = 0; i < threads; ++i) pool.emplace_back(worker);
    in_flight = std::max<std::size_t>(1, in_flight);
    std::size_t made = 0;
    for (std::size_t k = 0; k < n; ++k) {
      while (made < n && made < k + in_flight) {
        slots[made].item = make(made);
        {
          std::lock_guard lock(mu);
          queue.push_back(&slots[made]);
        }
        work_cv.notify_one();
        ++made;
      }
      Slot& slot = slots[k];
      {
        std::unique_lock lock(mu);
        done_cv.wait(lock, [&] { return slot.done; });
      }
      if (slot.error) std::rethrow_exception(slot.error);
      merge(*slot.item, k);
      slot.item.reset();
    }
  } catch (...) {
    join();
    throw;
  }
  join();
}

}  // namespace smr
