// Fixed-size records appended to an anonymous scratch file (storage::TempFile) through a buffer
// of 4 MiB, and read back by position: the spools of the out-of-core builders and writers.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <string>
#include <type_traits>
#include <vector>

#include "storage/temp_file.h"

namespace smr::storage {

template <class T>
class RecordFile {
  static_assert(std::is_trivially_copyable_v<T>, "records are written to disk as bytes");

 public:
  /// A scratch file in `dir` (already resolved by scratch_dir()).
  explicit RecordFile(const std::string& dir) : file_(dir, 0) {}
  void push(const T& r) { append(&r, 1); }
  void append(const T* r, std::size_t n) {
    buffer_.insert(buffer_.end(), r, r + n);
    if (buffer_.size() * sizeof(T) >= kFlushBytes) flush();
  }
  /// Writes the buffer out: records are readable once flushed.
  void flush() {
    if (buffer_.empty()) return;
    file_.write(count_ * sizeof(T), buffer_.data(), buffer_.size() * sizeof(T));
    count_ += buffer_.size();
    buffer_.clear();
  }
  std::uint64_t count() const { return count_ + buffer_.size(); }
  /// Records [first, first + out.size()) (after flush()).
  void read(std::uint64_t first, std::vector<T>& out) const { read(first, out.data(), out.size()); }
  void read(std::uint64_t first, T* out, std::size_t n) const {
    file_.read(first * sizeof(T), out, n * sizeof(T));
  }
  std::uint64_t bytes() const { return count() * sizeof(T); }

  /// Calls f(record) for every record in order, reading `chunk` records at a time (after flush()).
  template <class F>
  void for_each(F&& f, std::size_t chunk = (std::size_t{1} << 20) / sizeof(T) + 1) const {
    std::vector<T> buf;
    for (std::uint64_t at = 0; at < count_; at += buf.size()) {
      buf.resize(static_cast<std::size_t>(std::min<std::uint64_t>(chunk, count_ - at)));
      read(at, buf);
      for (const T& r : buf) f(r);
    }
  }

 private:
  static constexpr std::size_t kFlushBytes = std::size_t{4} << 20;
  TempFile file_;
  std::vector<T> buffer_;
  std::uint64_t count_ = 0;
};

}  // namespace smr::storage
