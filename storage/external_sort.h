// Sorting and queueing more fixed-size records than the memory budget holds (external memory
// algorithms; Aggarwal & Vitter's multiway merge sort, and the "time-forward processing" queue of
// Chiang et al., 1995): records are gathered in a buffer of at most `memory_bytes`; a full buffer
// is sorted and written as one run to an anonymous scratch file (storage::TempFile, checked for
// room when it is made); reading merges the runs and what is still in memory through a heap of
// their heads, each run read through a buffer of its own.
//
//  - ExternalSorter: add() every record, then next() returns them in `Less` order. Stable: equal
//    records come out in the order they were added, so a sort is a function of the sequence.
//  - ExternalQueue: a priority queue (largest first) whose pushes are never larger than what was
//    last popped, as in a backward sweep that sends messages to earlier items. It may be pushed
//    and popped in any interleaving under that rule; equal records come out in push order.
//
// Records must be trivially copyable (they are written as bytes). With B the buffer's records
// and R the runs, reading holds R run buffers of max(B / R, 4 KiB worth) records: a single merge
// pass, so the scratch data is written once and read once.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "storage/error.h"
#include "storage/temp_file.h"

namespace smr::storage {

namespace detail {

// A record and its arrival number: equal records leave in arrival order.
template <class T>
struct Item {
  T record;
  std::uint64_t seq;
};

// "a leaves before b" for items, from "a leaves before b" for records.
template <class T, class Before>
struct ItemBefore {
  Before before;
  bool operator()(const Item<T>& a, const Item<T>& b) const {
    if (before(a.record, b.record)) return true;
    if (before(b.record, a.record)) return false;
    return a.seq < b.seq;
  }
};

// Runs of items in one scratch file, each sorted in leaving order and read back through a buffer
// of its own; a heap of the runs' heads gives the next item of all runs.
template <class T, class Before>
class Runs {
 public:
  Runs(std::string dir, std::uint64_t memory_bytes, ItemBefore<T, Before> before)
      : dir_(std::move(dir)), memory_bytes_(memory_bytes), before_(std::move(before)) {}

  // Appends `n` items as one run (already in leaving order).
  void write(const Item<T>* data, std::size_t n) {
    if (n == 0) return;
    if (!file_) file_ = std::make_unique<TempFile>(dir_, 0);
    file_->write(end_ * sizeof(Item<T>), data, n * sizeof(Item<T>));
    runs_.push_back({end_, end_ + n, {}, 0});
    end_ += n;
    push_run(runs_.size() - 1);
  }
  std::size_t count() const { return runs_.size(); }
  std::uint64_t bytes() const { return end_ * sizeof(Item<T>); }
  // The first item of all runs (nullptr when they are done); pop() removes it.
  const Item<T>* top() const { return heap_.empty() ? nullptr : head(heap_.front()); }
  void pop() {
    const std::size_t r = heap_.front();
    std::pop_heap(heap_.begin(), heap_.end(), run_after());
    heap_.pop_back();
    ++runs_[r].pos;
    push_run(r);
  }

 private:
  struct Run {
    std::uint64_t next, end;  // items of the file not yet read
    std::vector<Item<T>> buffer;
    std::size_t pos;
  };
  const Item<T>* head(std::size_t r) const { return &runs_[r].buffer[runs_[r].pos]; }
  // Refills run r's buffer when needed and puts the run back in the heap unless it is done.
  void push_run(std::size_t r) {
    Run& run = runs_[r];
    if (run.pos == run.buffer.size()) {
      if (run.next == run.end) {
        std::vector<Item<T>>().swap(run.buffer);
        return;
      }
      if (run.buffer.capacity() == 0) run.buffer.reserve(buffer_items());
      const std::size_t n = static_cast<std::size_t>(
          std::min<std::uint64_t>(run.buffer.capacity(), run.end - run.next));
      run.buffer.resize(n);
      file_->read(run.next * sizeof(Item<T>), run.buffer.data(), n * sizeof(Item<T>));
      run.next += n;
      run.pos = 0;
    }
    heap_.push_back(r);
    std::push_heap(heap_.begin(), heap_.end(), run_after());
  }
  auto run_after() const {
    return [this](std::size_t a, std::size_t b) { return before_(*head(b), *head(a)); };
  }
  std::size_t buffer_items() const {
    const std::size_t floor = std::max<std::size_t>(1, 4096 / sizeof(Item<T>));
    const std::uint64_t share = memory_bytes_ / sizeof(Item<T>) / runs_.size();
    return std::max<std::size_t>(floor, static_cast<std::size_t>(share));
  }

  std::string dir_;
  std::uint64_t memory_bytes_;
  ItemBefore<T, Before> before_;
  std::unique_ptr<TempFile> file_;
  std::uint64_t end_ = 0;
  std::vector<Run> runs_;
  std::vector<std::size_t> heap_;  // runs with items left, by their heads
};

template <class T>
std::size_t buffer_capacity(std::uint64_t memory_bytes) {
  return static_cast<std::size_t>(std::max<std::uint64_t>(1024, memory_bytes / sizeof(Item<T>)));
}

// b < a under `less`: the queue's leaving order (largest first).
template <class Less>
struct Greater {
  Less less;
  template <class T>
  bool operator()(const T& a, const T& b) const {
    return less(b, a);
  }
};

}  // namespace detail

template <class T, class Less = std::less<T>>
class ExternalSorter {
  static_assert(std::is_trivially_copyable_v<T>, "records are written to disk as bytes");

 public:
  /// `tmp_dir`: where runs go (empty = the system's temporary directory); `memory_bytes`: the
  /// buffer's size (at least 1024 records).
  ExternalSorter(const std::string& tmp_dir, std::uint64_t memory_bytes, Less less = {})
      : before_{less},
        runs_(scratch_dir(tmp_dir), memory_bytes, before_),
        capacity_(detail::buffer_capacity<T>(memory_bytes)) {}

  void add(const T& record) {
    if (reading_) throw_internal("ExternalSorter: add() after next()");
    if (buffer_.size() == capacity_) spill();
    buffer_.push_back({record, size_++});
  }
  /// The next record in order; false once all are out. The first call ends the adding.
  bool next(T& out) {
    if (!reading_) {
      reading_ = true;
      std::sort(buffer_.begin(), buffer_.end(), before_);
    }
    const detail::Item<T>* run = runs_.top();
    if (pos_ < buffer_.size() && (run == nullptr || before_(buffer_[pos_], *run))) {
      out = buffer_[pos_++].record;
      return true;
    }
    if (run == nullptr) return false;
    out = run->record;
    runs_.pop();
    return true;
  }
  std::uint64_t size() const { return size_; }
  std::size_t runs() const { return runs_.count(); }
  std::uint64_t spilled_bytes() const { return runs_.bytes(); }

 private:
  void spill() {
    std::sort(buffer_.begin(), buffer_.end(), before_);
    runs_.write(buffer_.data(), buffer_.size());
    buffer_.clear();
  }

  detail::ItemBefore<T, Less> before_;
  detail::Runs<T, Less> runs_;
  std::size_t capacity_;
  std::vector<detail::Item<T>> buffer_;
  std::size_t pos_ = 0;
  std::uint64_t size_ = 0;
  bool reading_ = false;
};

template <class T, class Less = std::less<T>>
class ExternalQueue {
  static_assert(std::is_trivially_copyable_v<T>, "records are written to disk as bytes");
  using Before = detail::Greater<Less>;

 public:
  ExternalQueue(const std::string& tmp_dir, std::uint64_t memory_bytes, Less less = {})
      : before_{Before{less}},
        runs_(scratch_dir(tmp_dir), memory_bytes, before_),
        capacity_(detail::buffer_capacity<T>(memory_bytes)) {}

  /// Adds a record; it must not be larger than the last one popped.
  void push(const T& record) {
    if (heap_.size() == capacity_) spill();
    heap_.push_back({record, seq_++});
    std::push_heap(heap_.begin(), heap_.end(), after());
    ++size_;
  }
  bool empty() const { return size_ == 0; }
  std::uint64_t size() const { return size_; }
  /// The largest record (the earliest pushed of equal ones); the queue must not be empty.
  const T& top() const {
    const detail::Item<T>* run = runs_.top();
    if (!heap_.empty() && (run == nullptr || before_(heap_.front(), *run)))
      return heap_.front().record;
    return run->record;
  }
  void pop() {
    const detail::Item<T>* run = runs_.top();
    if (!heap_.empty() && (run == nullptr || before_(heap_.front(), *run))) {
      std::pop_heap(heap_.begin(), heap_.end(), after());
      heap_.pop_back();
    } else {
      runs_.pop();
    }
    --size_;
  }
  std::size_t runs() const { return runs_.count(); }
  std::uint64_t spilled_bytes() const { return runs_.bytes(); }

 private:
  auto after() const {
    return [this](const detail::Item<T>& a, const detail::Item<T>& b) { return before_(b, a); };
  }
  void spill() {
    std::sort(heap_.begin(), heap_.end(), before_);
    runs_.write(heap_.data(), heap_.size());
    heap_.clear();
  }

  detail::ItemBefore<T, Before> before_;
  detail::Runs<T, Before> runs_;
  std::size_t capacity_;
  std::vector<detail::Item<T>> heap_;
  std::uint64_t seq_ = 0, size_ = 0;
};

}  // namespace smr::storage
