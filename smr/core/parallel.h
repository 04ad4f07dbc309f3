// Parallel helpers for work whose results are combined in order, so that output never depends
// on the thread count: parallel_for (independent items, results by index; WorkerPool runs many
// such batches on the same threads), ordered_pipeline (items made and merged in order on the
// calling thread, worked on by a pool) and Turnstile (a step of the workers' that runs in item
// order).
#pragma once

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <exception>
#include <functional>
#include <memory>
#include <mutex>
#include <thread>
#include <type_traits>
#include <utility>
#include <vector>

namespace smr {

inline unsigned thread_count(unsigned requested) {
  return requested != 0 ? requested : std::max(1u, std::thread::hardware_concurrency());
}

/// Turns taken in order by several threads: run(k, f) runs f() once turns 0..k-1 have run, one
/// turn at a time, and lets turn k + 1 go however f() ends (a throw included). For a step of
/// ordered_pipeline's workers that must follow the items' order (a reader that is not shared, a
/// running total), so that the calling thread is left only the merges. Every turn from 0 must
/// come, or later ones wait for ever: ordered_pipeline's workers take the items in order, so
/// an item's earlier ones are always taken.
class Turnstile {
 public:
  template <class F>
  decltype(auto) run(std::size_t k, F&& f) {
    std::unique_lock lock(mu_);
    cv_.wait(lock, [&] { return next_ == k; });
    struct Next {
      Turnstile& t;
      ~Next() {
        ++t.next_;
        t.cv_.notify_all();
      }
    } next{*this};
    return f();
  }
  /// Starts again from turn 0 (no turn may be waiting).
  void reset() {
    std::lock_guard lock(mu_);
    next_ = 0;
  }

 private:
  std::mutex mu_;
  std::condition_variable cv_;
  std::size_t next_ = 0;
};

/// A fixed set of threads that runs batches of independent items one batch after another: a
/// caller with many small batches starts its threads (and whatever they keep thread_local, such
/// as codec contexts) once, not once a batch. The calling thread works on each batch too.
class WorkerPool {
 public:
  /// `threads` in all, the caller's included (0 = one per core).
  explicit WorkerPool(unsigned threads) {
    const unsigned n = thread_count(threads);
    for (unsigned t = 1; t < n; ++t) helpers_.emplace_back([this] { serve(); });
  }
  ~WorkerPool() {
    {
      std::lock_guard lock(mu_);
      quit_ = true;
    }
    start_cv_.notify_all();
    for (std::thread& t : helpers_) t.join();
  }
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  /// f(i) for i in [0, n), the items pulled from a shared counter. The first exception thrown by
  /// any f is rethrown once every thread has left the batch.
  template <class F>
  void for_each(std::size_t n, F&& f) {
    for_each(n, std::forward<F>(f), [] {});
  }
  /// The same, but the calling thread first runs `first()` while the helpers start on the items
  /// (work of its own that the batch does not need: the previous batch's results, in order),
  /// then joins them. If first() throws, the items not started are skipped and, once every
  /// helper has left the batch, its exception is rethrown.
  template <class F, class G>
  void for_each(std::size_t n, F&& f, G&& first) {
    if (helpers_.empty() || n <= 1) {
      first();
      for (std::size_t i = 0; i < n; ++i) f(i);
      return;
    }
    {
      std::unique_lock lock(mu_);
      // A helper that woke late for the last batch may still be looking at it.
      idle_cv_.wait(lock, [&] { return busy_ == 0; });
      job_ = [&f](std::size_t i) { f(i); };
      n_ = n;
      next_ = 0;
      failed_ = false;
      error_ = nullptr;
      ++generation_;
    }
    start_cv_.notify_all();
    try {
      first();
    } catch (...) {
      std::lock_guard lock(mu_);
      if (!error_) error_ = std::current_exception();
      failed_ = true;
    }
    drain();
    std::unique_lock lock(mu_);
    idle_cv_.wait(lock, [&] { return busy_ == 0; });
    job_ = nullptr;
    if (error_) std::rethrow_exception(std::exchange(error_, nullptr));
  }

 private:
  void serve() {
    std::uint64_t seen = 0;
    for (;;) {
      {
        std::unique_lock lock(mu_);
        start_cv_.wait(lock, [&] { return quit_ || generation_ != seen; });
        if (quit_) return;
        seen = generation_;
        ++busy_;
      }
      drain();
      {
        std::lock_guard lock(mu_);
        --busy_;
      }
      idle_cv_.notify_all();
    }
  }
  // job_ and n_ change only while no helper is busy, so reading them here needs no lock.
  void drain() {
    for (std::size_t i; !failed_.load() && (i = next_.fetch_add(1)) < n_;) {
      try {
        job_(i);
      } catch (...) {
        std::lock_guard lock(mu_);
        if (!error_) error_ = std::current_exception();
        failed_ = true;
      }
    }
  }

  std::vector<std::thread> helpers_;
  std::mutex mu_;
  std::condition_variable start_cv_, idle_cv_;
  bool quit_ = false;
  std::uint64_t generation_ = 0;  // batches started
  unsigned busy_ = 0;             // helpers inside a batch
  std::function<void(std::size_t)> job_;
  std::size_t n_ = 0;
  std::atomic<std::size_t> next_{0};
  std::atomic<bool> failed_{false};
  std::exception_ptr error_;
};

/// f(i) for i in [0, n) on up to `threads` threads (0 = one per core) pulling indices from a
/// shared counter. The first exception thrown by any f is rethrown once every thread has stopped.
template <class F>
void parallel_for(std::size_t n, unsigned threads, F&& f) {
  if (n == 0) return;
  WorkerPool pool(static_cast<unsigned>(std::min<std::size_t>(thread_count(threads), n)));
  pool.for_each(n, f);
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
