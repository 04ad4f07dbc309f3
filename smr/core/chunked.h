// A growing array in fixed chunks: push_back never moves what is stored, and memory follows the
// size (one partly used chunk at most) instead of a vector's doubling, whose growth briefly holds
// the old and the new buffer (3x the data at the worst moment). For builders' records that grow
// to hundreds of megabytes under a memory budget. Chunks are raw storage, constructed element by
// element as they fill, so an array that stays small costs only the pages it touches.
//
// Freed chunks are kept for the next array of the same type, up to kPoolBytes of them in all:
// builders make and drop many short-lived arrays (a block's copy, a leaf's records), and a fresh
// chunk is mapped, faulted in page by page and unmapped again every time.
#pragma once

#include <algorithm>
#include <cstddef>
#include <mutex>
#include <new>
#include <type_traits>
#include <utility>
#include <vector>

namespace smr {

namespace detail {

// The chunks freed by every Chunked<T, kChunkBits> of the process, for the next ones.
template <class T, std::size_t kChunkBytes>
class ChunkPool {
 public:
  static constexpr std::size_t kPoolBytes = std::size_t{16} << 20;
  static constexpr std::size_t kMaxChunks = std::max<std::size_t>(1, kPoolBytes / kChunkBytes);

  static ChunkPool& instance() {
    static ChunkPool pool;
    return pool;
  }
  T* take() {
    {
      std::lock_guard lock(mu_);
      if (!free_.empty()) {
        T* c = free_.back();
        free_.pop_back();
        return c;
      }
    }
    return static_cast<T*>(::operator new(kChunkBytes, std::align_val_t(alignof(T))));
  }
  void give(T* c) {
    {
      std::lock_guard lock(mu_);
      if (free_.size() < kMaxChunks) {
        free_.push_back(c);
        return;
      }
    }
    ::operator delete(c, std::align_val_t(alignof(T)));
  }
  ~ChunkPool() {
    for (T* c : free_) ::operator delete(c, std::align_val_t(alignof(T)));
  }
  /// Chunks kept for reuse.
  std::size_t pooled() {
    std::lock_guard lock(mu_);
    return free_.size();
  }

 private:
  ChunkPool() { free_.reserve(kMaxChunks); }
  std::mutex mu_;
  std::vector<T*> free_;
};

}  // namespace detail

template <class T, std::size_t kChunkBits = 16>
class Chunked {
  static_assert(std::is_trivially_destructible_v<T>, "chunks are freed without destructors");

 public:
  static constexpr std::size_t kChunk = std::size_t{1} << kChunkBits;
  /// Where freed chunks wait for the next array of this type.
  using Pool = detail::ChunkPool<T, kChunk * sizeof(T)>;

  Chunked() = default;
  Chunked(const Chunked&) = delete;
  Chunked& operator=(const Chunked&) = delete;
  ~Chunked() { release(); }

  std::size_t size() const { return size_; }
  bool empty() const { return size_ == 0; }
  T& operator[](std::size_t i) { return chunks_[i >> kChunkBits][i & (kChunk - 1)]; }
  const T& operator[](std::size_t i) const { return chunks_[i >> kChunkBits][i & (kChunk - 1)]; }
  void push_back(const T& v) {
    if ((size_ & (kChunk - 1)) == 0) chunks_.push_back(Pool::instance().take());
    ::new (chunks_.back() + (size_ & (kChunk - 1))) T(v);
    ++size_;
  }
  /// Calls f(i, element) for every element in order, freeing each chunk once it is visited:
  /// converting the records into another form never holds both whole. Ends empty.
  template <class F>
  void drain(F&& f) {
    for (std::size_t c = 0; c < chunks_.size(); ++c) {
      const std::size_t n = std::min(kChunk, size_ - c * kChunk);
      for (std::size_t i = 0; i < n; ++i) f(c * kChunk + i, chunks_[c][i]);
      free_chunk(chunks_[c]);
    }
    release();
  }
  /// Frees everything.
  void release() {
    for (T*& c : chunks_) free_chunk(c);
    std::vector<T*>().swap(chunks_);
    size_ = 0;
  }

 private:
  static void free_chunk(T*& c) {
    if (c != nullptr) Pool::instance().give(c);
    c = nullptr;
  }
  std::vector<T*> chunks_;
  std::size_t size_ = 0;
};

}  // namespace smr
