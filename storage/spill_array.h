// A table of fixed-size values by number (one per removal or per op of a build) that stays within
// a resident budget whatever its length: the out-of-core builders' per-item tables.
//
// Without a budget it is a std::vector. With one, the values live in a shared mapping of an
// anonymous scratch file (storage::TempFile): the kernel keeps the file's pages in its page
// cache, which is not the process's memory, and the mapping's pages are dropped from the
// resident set (madvise MADV_DONTNEED; clean or dirty, they stay in the page cache and fault back
// in on the next access) after every budget / 4 KiB accesses, since each access maps at most one
// page in. So the table holds at most its budget however it is accessed, and a table read with
// locality (the builders' are: removals are numbered along space) faults little.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <type_traits>
#include <vector>

#include "storage/temp_file.h"

namespace smr::storage {

/// The mapped scratch file under a SpillArray.
class ScratchMapping {
 public:
  ScratchMapping(const std::string& dir, std::uint64_t resident_bytes);
  ~ScratchMapping();
  ScratchMapping(const ScratchMapping&) = delete;
  ScratchMapping& operator=(const ScratchMapping&) = delete;

  /// Makes the first `bytes` addressable (new bytes are zero). Not concurrent with accesses.
  void reserve(std::uint64_t bytes);
  void* data() const { return data_; }
  /// Counts an access; every resident_bytes / 4 KiB of them drops the mapping's pages. Several
  /// threads may access (and so trim) at once.
  void touch() const {
    if (touches_.fetch_add(1, std::memory_order_relaxed) % trim_every_ == trim_every_ - 1) trim();
  }
  std::uint64_t trims() const { return trims_.load(); }

 private:
  void trim() const;

  TempFile file_;
  void* data_ = nullptr;
  std::uint64_t capacity_ = 0;
  std::uint64_t trim_every_;
  mutable std::atomic<std::uint64_t> touches_{0}, trims_{0};
};

template <class T>
class SpillArray {
  static_assert(std::is_trivially_copyable_v<T>, "values live in a file's bytes");

 public:
  /// In memory when `resident_bytes` is 0, else in a scratch file in `dir` (already resolved by
  /// scratch_dir()) holding at most `resident_bytes` (at least 64 KiB) resident.
  SpillArray(const std::string& dir, std::uint64_t resident_bytes) {
    if (resident_bytes > 0) map_ = std::make_unique<ScratchMapping>(dir, resident_bytes);
  }

  std::size_t size() const { return size_; }
  /// Grows (new values are zero) or shrinks. Not concurrent with accesses.
  void resize(std::size_t n) {
    if (map_) {
      map_->reserve(std::uint64_t{n} * sizeof(T));
    } else {
      mem_.resize(n);
    }
    size_ = n;
  }
  void push_back(const T& v) {
    if (!map_) {
      mem_.push_back(v);
      ++size_;
      return;
    }
    if (size_ == capacity_) {
      capacity_ = capacity_ < 4096 ? 4096 : capacity_ * 2;
      map_->reserve(std::uint64_t{capacity_} * sizeof(T));
    }
    set(size_++, v);
  }
  T operator[](std::size_t i) const {
    if (!map_) return mem_[i];
    map_->touch();
    return static_cast<const T*>(map_->data())[i];
  }
  void set(std::size_t i, const T& v) {
    if (!map_) {
      mem_[i] = v;
      return;
    }
    map_->touch();
    static_cast<T*>(map_->data())[i] = v;
  }
  bool spilled() const { return map_ != nullptr; }
  /// Times the resident pages were dropped (0 in memory).
  std::uint64_t trims() const { return map_ ? map_->trims() : 0; }

 private:
  std::vector<T> mem_;
  std::unique_ptr<ScratchMapping> map_;
  std::size_t size_ = 0, capacity_ = 0;
};

}  // namespace smr::storage
