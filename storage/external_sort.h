// Sorting and queueing more fixed-size records than the memory budget holds (external memory
// algorithms; Aggarwal & Vitter's multiway merge sort, and the "time-forward processing" queue of
// Chiang et al., 1995): records are gathered in a buffer of at most `memory_bytes`; a full buffer
// is sorted and written as one run to an anonymous scratch file (storage::TempFile, checked for
// room when it is made); reading merges the runs and what is still in memory through a heap of
// their heads, each run read through a buffer of its own.
//
//  - ExternalSorter: add() every record, then next() returns them in `Less` order. Stable by
//    default: equal records come out in the order they were added, so a sort is a function of
//    the sequence. With Ties::kAny they come out in some order (the same for the same sequence
//    of adds) and no arrival number rides with each record: a third less to write and read for
//    a 16-byte record, for records that Less orders totally or whose ties are interchangeable.
//  - ExternalQueue: a priority queue (largest first) whose pushes are never larger than what was
//    last popped, as in a backward sweep that sends messages to earlier items. It may be pushed
//    and popped in any interleaving under that rule; equal records come out in push order.
//
// Records must be trivially copyable (they are written as bytes). Half the memory budget holds
// records (a run is at most that), the other half the runs' read buffers: the sorter reads R runs
// through buffers of max(budget / 2R, 4 KiB), one merge pass, so its data is written and read
// once, while R is at most max(16, budget / 32 KiB); beyond, passes merge groups of that many
// runs first (each pass writes and reads the data once more), so the buffers stay within the
// budget whatever the input. The queue's buffers are a 64th of that, and every 64 runs it merges
// them into one.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <future>
#include <memory>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "base/error.h"
#include "storage/temp_file.h"

namespace smr::storage {

/// What a sort does with records equal under its order (see above).
enum class Ties { kArrival, kAny };

/// Where an ExternalSorter sorts and writes a full buffer: on the adding thread, or on a thread
/// of its own while the adding goes on into a second buffer (each buffer then a quarter of the
/// budget, not a half: twice the runs, the same bytes written and read, for an adder whose own
/// thread is the one that is short of time).
enum class Spill { kInline, kBackground };

namespace detail {

// A record and its arrival number: equal records leave in arrival order.
template <class T, Ties kTies = Ties::kArrival>
struct Item {
  T record;
  std::uint64_t seq;
};
template <class T>
struct Item<T, Ties::kAny> {
  T record;
};

// "a leaves before b" for items, from "a leaves before b" for records.
template <class T, class Before, Ties kTies = Ties::kArrival>
struct ItemBefore {
  Before before;
  bool operator()(const Item<T, kTies>& a, const Item<T, kTies>& b) const {
    if constexpr (kTies == Ties::kAny) {
      return before(a.record, b.record);
    } else {
      if (before(a.record, b.record)) return true;
      if (before(b.record, a.record)) return false;
      return a.seq < b.seq;
    }
  }
};

// Runs of items in a scratch file, each sorted in leaving order and read back through a buffer
// of its own; a heap of the runs' heads gives the next item of all runs. A run is first read
// when the heads are first asked for, so its buffer is sized by the runs there are then: the
// buffers share `memory_bytes` (each at least 4 KiB). With `max_runs` set (a queue, whose runs
// keep coming while it is read), reaching it merges the runs into one, in a new file.
template <class T, class Before, Ties kTies = Ties::kArrival>
class Runs {
  using Item = detail::Item<T, kTies>;

 public:
  Runs(std::string dir, std::uint64_t memory_bytes, std::size_t max_runs,
       ItemBefore<T, Before, kTies> before)
      : dir_(std::move(dir)),
        memory_bytes_(memory_bytes),
        max_runs_(max_runs),
        before_(std::move(before)) {}

  // Sorts `items` into leaving order and appends them as one run; empties `items`.
  void spill(std::vector<Item>& items) {
    std::sort(items.begin(), items.end(), before_);
    write(items.data(), items.size());
    items.clear();
  }
  // Appends `n` items as one run (already in leaving order).
  void write(const Item* data, std::size_t n) {
    if (n == 0) return;
    if (!file_) file_ = std::make_unique<TempFile>(dir_, 0);
    file_->write(end_ * sizeof(Item), data, n * sizeof(Item));
    runs_.push_back({end_, end_ + n, {}, 0});
    unread_.push_back(runs_.size() - 1);
    end_ += n;
    written_ += n * sizeof(Item);
    ++made_;
    if (max_runs_ != 0 && heap_.size() + unread_.size() >= max_runs_) merge();
  }
  std::size_t count() const { return made_; }       // runs made, merged ones included
  std::uint64_t bytes() const { return written_; }  // written to scratch files in all
  // The first item of all runs (nullptr when they are done); pop() removes it.
  const Item* top() {
    start();
    return heap_.empty() ? nullptr : head(heap_.front());
  }
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
    std::vector<Item> buffer;
    std::size_t pos;
  };
  const Item* head(std::size_t r) const { return &runs_[r].buffer[runs_[r].pos]; }
  void start() {
    // A sorter's runs grow in number with its input: merged at once, their buffers' floor
    // (4 KiB each) would pass the budget. Beyond fan_in() runs, passes merge groups of them first.
    if (max_runs_ == 0 && heap_.empty()) {
      while (unread_.size() > fan_in()) merge_groups();
    }
    for (std::size_t r : unread_) push_run(r);
    unread_.clear();
  }
  // The most runs one merge reads within the budget, through buffers of 16 KiB or more.
  std::size_t fan_in() const {
    return std::max<std::size_t>(16, static_cast<std::size_t>(memory_bytes_ / 16384));
  }
  // Refills run r's buffer when needed and puts the run back in the heap unless it is done.
  void push_run(std::size_t r) {
    Run& run = runs_[r];
    if (run.pos == run.buffer.size()) {
      if (run.next == run.end) {
        std::vector<Item>().swap(run.buffer);
        return;
      }
      if (run.buffer.capacity() == 0) run.buffer.reserve(buffer_items());
      const std::size_t n = static_cast<std::size_t>(
          std::min<std::uint64_t>(run.buffer.capacity(), run.end - run.next));
      run.buffer.resize(n);
      file_->read(run.next * sizeof(Item), run.buffer.data(), n * sizeof(Item));
      run.next += n;
      run.pos = 0;
    }
    heap_.push_back(r);
    std::push_heap(heap_.begin(), heap_.end(), run_after());
  }
  // One pass: each group of fan_in() consecutive unread runs becomes one run of a new file.
  void merge_groups() {
    auto merged = std::make_unique<TempFile>(dir_, 0);
    const std::vector<std::size_t> all = std::move(unread_);
    std::vector<Run> groups;
    std::uint64_t n = 0;
    for (std::size_t g = 0; g < all.size(); g += fan_in()) {
      unread_.assign(all.begin() + static_cast<std::ptrdiff_t>(g),
                     all.begin() + static_cast<std::ptrdiff_t>(std::min(all.size(), g + fan_in())));
      const std::uint64_t first = n;
      n = drain_into(*merged, n);
      groups.push_back({first, n, {}, 0});
    }
    reset(std::move(merged), std::move(groups), n);
  }
  // Every item left, in leaving order, as the one run of a new file.
  void merge() {
    auto merged = std::make_unique<TempFile>(dir_, 0);
    const std::uint64_t n = drain_into(*merged, 0);
    std::vector<Run> one;
    one.push_back({0, n, {}, 0});
    reset(std::move(merged), std::move(one), n);
  }
  // Pops every item of the runs being read (and the unread ones) into `out` from item `at`, in
  // leaving order; returns the item count after them.
  std::uint64_t drain_into(TempFile& out, std::uint64_t at) {
    std::vector<Item> buffer;
    buffer.reserve(buffer_items());
    auto flush = [&] {
      out.write(at * sizeof(Item), buffer.data(), buffer.size() * sizeof(Item));
      at += buffer.size();
      written_ += buffer.size() * sizeof(Item);
      buffer.clear();
    };
    for (const Item* h; (h = top()) != nullptr; pop()) {
      buffer.push_back(*h);
      if (buffer.size() == buffer.capacity()) flush();
    }
    flush();
    return at;
  }
  // The runs are now `runs`, all unread, of `file` (`n` items).
  void reset(std::unique_ptr<TempFile> file, std::vector<Run> runs, std::uint64_t n) {
    file_ = std::move(file);
    runs_ = std::move(runs);
    heap_.clear();
    unread_.resize(runs_.size());
    for (std::size_t r = 0; r < runs_.size(); ++r) unread_[r] = r;
    end_ = n;
  }
  auto run_after() const {
    return [this](std::size_t a, std::size_t b) { return before_(*head(b), *head(a)); };
  }
  std::size_t buffer_items() const {
    const std::size_t floor = std::max<std::size_t>(1, 4096 / sizeof(Item));
    const std::size_t runs =
        std::max<std::size_t>({std::size_t{1}, max_runs_, heap_.size() + unread_.size()});
    const std::uint64_t share = memory_bytes_ / sizeof(Item) / runs;
    return std::max<std::size_t>(floor, static_cast<std::size_t>(share));
  }

  std::string dir_;
  std::uint64_t memory_bytes_;
  std::size_t max_runs_;
  ItemBefore<T, Before, kTies> before_;
  std::unique_ptr<TempFile> file_;
  std::uint64_t end_ = 0, written_ = 0;
  std::size_t made_ = 0;
  std::vector<Run> runs_;
  std::vector<std::size_t> heap_;    // runs with items left, by their heads
  std::vector<std::size_t> unread_;  // runs not read yet
};

// The in-memory records take half of the budget (at least 1024), the run buffers the other half.
template <class Item>
std::size_t buffer_capacity(std::uint64_t memory_bytes) {
  return static_cast<std::size_t>(std::max<std::uint64_t>(1024, memory_bytes / 2 / sizeof(Item)));
}
inline constexpr std::size_t kQueueMaxRuns = 64;

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

template <class T, class Less = std::less<T>, Ties kTies = Ties::kArrival>
class ExternalSorter {
  static_assert(std::is_trivially_copyable_v<T>, "records are written to disk as bytes");
  using Item = detail::Item<T, kTies>;

 public:
  /// `tmp_dir`: where runs go (empty = the system's temporary directory); `memory_bytes`: half
  /// for records in memory (at least 1024), half for the runs' read buffers.
  ExternalSorter(const std::string& tmp_dir, std::uint64_t memory_bytes, Less less = {},
                 Spill spill = Spill::kInline)
      : before_{less},
        runs_(scratch_dir(tmp_dir), memory_bytes / 2, 0, before_),
        capacity_(detail::buffer_capacity<Item>(spill == Spill::kBackground ? memory_bytes / 2
                                                                            : memory_bytes)),
        background_(spill == Spill::kBackground) {}
  ~ExternalSorter() {
    if (pending_.valid()) pending_.wait();  // its exception, if any, goes with it
  }
  ExternalSorter(const ExternalSorter&) = delete;
  ExternalSorter& operator=(const ExternalSorter&) = delete;

  void add(const T& record) {
    if (reading_) throw_internal("ExternalSorter: add() after next()");
    // Room for a whole run at once: growing by doubling would copy it and hold it twice, and
    // pages not filled are never touched.
    if (buffer_.capacity() == 0) buffer_.reserve(capacity_);
    if (buffer_.size() == capacity_) {
      if (background_) {
        finish_spill();  // one run at a time, in the order of the adds
        spilling_.swap(buffer_);
        if (buffer_.capacity() == 0) buffer_.reserve(capacity_);
        pending_ = std::async(std::launch::async, [this] { runs_.spill(spilling_); });
      } else {
        runs_.spill(buffer_);
      }
    }
    if constexpr (kTies == Ties::kAny) {
      buffer_.push_back({record});
    } else {
      buffer_.push_back({record, size_});
    }
    ++size_;
  }
  /// Ends the adding: sorts the records still in memory (the first next() does it otherwise),
  /// so that a thread of its own can do it. Idempotent.
  void seal() {
    if (reading_) return;
    reading_ = true;
    finish_spill();
    std::vector<Item>().swap(spilling_);  // its half of the budget goes to the runs' buffers
    std::sort(buffer_.begin(), buffer_.end(), before_);
  }
  /// The next record in order; false once all are out. The first call ends the adding.
  bool next(T& out) {
    seal();
    const Item* run = runs_.top();
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
  /// Runs made so far and the bytes they took (with Spill::kBackground, ask after seal() or the
  /// first next(): a run may be being written until then).
  std::size_t runs() const { return runs_.count(); }
  std::uint64_t spilled_bytes() const { return runs_.bytes(); }

 private:
  // Waits for the background spill, if one is running; rethrows what it threw.
  void finish_spill() {
    if (pending_.valid()) pending_.get();
  }

  detail::ItemBefore<T, Less, kTies> before_;
  detail::Runs<T, Less, kTies> runs_;
  std::size_t capacity_;
  bool background_;
  std::vector<Item> buffer_;
  std::vector<Item> spilling_;  // the buffer the background spill sorts and writes
  std::size_t pos_ = 0;
  std::uint64_t size_ = 0;
  bool reading_ = false;
  std::future<void> pending_;  // last: it is waited for before the rest goes
};

template <class T, class Less = std::less<T>>
class ExternalQueue {
  static_assert(std::is_trivially_copyable_v<T>, "records are written to disk as bytes");
  using Before = detail::Greater<Less>;

 public:
  ExternalQueue(const std::string& tmp_dir, std::uint64_t memory_bytes, Less less = {})
      : before_{Before{less}},
        runs_(scratch_dir(tmp_dir), memory_bytes / 2, detail::kQueueMaxRuns, before_),
        capacity_(detail::buffer_capacity<detail::Item<T>>(memory_bytes)) {}

  /// Adds a record; it must not be larger than the last one popped.
  void push(const T& record) {
    if (heap_.capacity() == 0) heap_.reserve(capacity_);  // as ExternalSorter::add
    if (heap_.size() == capacity_) runs_.spill(heap_);
    heap_.push_back({record, seq_++});
    std::push_heap(heap_.begin(), heap_.end(), after());
    ++size_;
  }
  bool empty() const { return size_ == 0; }
  std::uint64_t size() const { return size_; }
  /// The largest record (the earliest pushed of equal ones); the queue must not be empty.
  const T& top() { return heap_first() ? heap_.front().record : runs_.top()->record; }
  void pop() {
    if (heap_first()) {
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
  // Whether the largest record is in memory rather than at the head of a run.
  bool heap_first() {
    const detail::Item<T>* run = runs_.top();
    return !heap_.empty() && (run == nullptr || before_(heap_.front(), *run));
  }
  auto after() const {
    return [this](const detail::Item<T>& a, const detail::Item<T>& b) { return before_(b, a); };
  }

  detail::ItemBefore<T, Before> before_;
  detail::Runs<T, Before> runs_;
  std::size_t capacity_;
  std::vector<detail::Item<T>> heap_;
  std::uint64_t seq_ = 0, size_ = 0;
};

}  // namespace smr::storage
