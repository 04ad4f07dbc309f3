// Fixed-size records appended to an anonymous scratch file (storage::TempFile) through a buffer
// of 1 MiB, and read back by position (many scattered pieces in runs of nearby ones): the spools
// of the out-of-core builders and writers.
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

  /// Records [first, first + count) of the file, to go to out[to, to + count).
  struct Piece {
    std::uint64_t first = 0;
    std::size_t count = 0;
    std::size_t to = 0;
  };
  /// Reads many pieces (after flush()), in place order, a run of nearby ones in one read: a
  /// piece starting at most kGapBytes past the run's end joins it (the gap is read through, which
  /// costs less than a system call), up to kRunBytes a run. Reorders `pieces`.
  void read_pieces(std::vector<Piece>& pieces, T* out) const {
    std::sort(pieces.begin(), pieces.end(),
              [](const Piece& a, const Piece& b) { return a.first < b.first; });
    constexpr std::uint64_t gap = kGapBytes / sizeof(T) + 1, run_max = kRunBytes / sizeof(T) + 1;
    std::vector<T> run;
    for (std::size_t i = 0; i < pieces.size();) {
      const std::uint64_t begin = pieces[i].first;
      std::uint64_t end = begin + pieces[i].count;
      std::size_t k = i + 1;
      for (; k < pieces.size(); ++k) {
        const Piece& p = pieces[k];
        if (p.first > end + gap || p.first + p.count - begin > run_max) break;
        end = std::max<std::uint64_t>(end, p.first + p.count);
      }
      if (k == i + 1) {  // alone: straight to its place
        read(begin, out + pieces[i].to, pieces[i].count);
        i = k;
        continue;
      }
      run.resize(static_cast<std::size_t>(end - begin));
      read(begin, run);
      for (; i < k; ++i) {
        std::copy_n(run.begin() + static_cast<std::ptrdiff_t>(pieces[i].first - begin),
                    pieces[i].count, out + pieces[i].to);
      }
    }
  }

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
  // A build holds several spools at once (the op assembler's two, the stream writer's three):
  // 4 MiB each was a third of a 32 MiB budget, for writes no faster than 1 MiB ones.
  static constexpr std::size_t kFlushBytes = std::size_t{1} << 20;
  static constexpr std::uint64_t kGapBytes = 16384, kRunBytes = std::uint64_t{1} << 20;
  TempFile file_;
  std::vector<T> buffer_;
  std::uint64_t count_ = 0;
};

}  // namespace smr::storage
