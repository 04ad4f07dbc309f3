// A growing array in fixed chunks: push_back never moves what is stored, and memory follows the
// size (one partly used chunk at most) instead of a vector's doubling, whose growth briefly holds
// the old and the new buffer (3x the data at the worst moment). For builders' records that grow
// to hundreds of megabytes under a memory budget.
#pragma once

#include <algorithm>
#include <cstddef>
#include <memory>
#include <vector>

namespace smr {

template <class T, std::size_t kChunkBits = 16>
class Chunked {
 public:
  static constexpr std::size_t kChunk = std::size_t{1} << kChunkBits;

  std::size_t size() const { return size_; }
  bool empty() const { return size_ == 0; }
  T& operator[](std::size_t i) { return chunks_[i >> kChunkBits][i & (kChunk - 1)]; }
  const T& operator[](std::size_t i) const { return chunks_[i >> kChunkBits][i & (kChunk - 1)]; }
  void push_back(const T& v) {
    if ((size_ & (kChunk - 1)) == 0) chunks_.push_back(std::make_unique<T[]>(kChunk));
    chunks_.back()[size_ & (kChunk - 1)] = v;
    ++size_;
  }
  /// Calls f(i, element) for every element in order, freeing each chunk once it is visited:
  /// converting the records into another form never holds both whole. Ends empty.
  template <class F>
  void drain(F&& f) {
    for (std::size_t c = 0; c < chunks_.size(); ++c) {
      const std::size_t n = std::min(kChunk, size_ - c * kChunk);
      for (std::size_t i = 0; i < n; ++i) f(c * kChunk + i, chunks_[c][i]);
      chunks_[c].reset();
    }
    release();
  }
  /// Frees everything.
  void release() {
    std::vector<std::unique_ptr<T[]>>().swap(chunks_);
    size_ = 0;
  }
  /// Heap bytes held.
  std::size_t bytes() const { return chunks_.size() * kChunk * sizeof(T); }

 private:
  std::vector<std::unique_ptr<T[]>> chunks_;
  std::size_t size_ = 0;
};

}  // namespace smr
