// A table of fixed-size values by number (one per removal or per op of a build) that stays within
// a resident budget whatever its length: the out-of-core builders' per-item tables.
//
// Without a budget it is a std::vector. With one, the values live in an anonymous scratch file
// (storage::TempFile) and the process holds copies of some of its 4 KiB blocks, in slots (block
// number mod slots): a value in no slot is read by reading its block into its slot (pread; a
// block changed by set() is written back first). The kernel keeps the file's pages in its page
// cache, which is not the process's memory, so the table holds at most its slots resident. (It
// once mapped the file and dropped the mapping's pages every so many accesses: that does not
// bound what is resident, as fault-around and large page-cache folios map many pages per fault;
// and mapping windows of the file in place bounds it but costs a remap's TLB shootdown per miss.)
// A table read with locality (the builders' are: removals are numbered along space) misses little.
#pragma once

#include <algorithm>
#include <atomic>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <mutex>
#include <string>
#include <type_traits>
#include <vector>

#include "storage/temp_file.h"

namespace smr::storage {

/// The scratch file under a SpillArray and the blocks of it at hand.
class ScratchBlocks {
 public:
  /// At most `resident_bytes` (at least 64 KiB) of the file's blocks at hand (and 16 bytes of
  /// bookkeeping a 4 KiB block). Tables up to 2^32 - 1 blocks (16 TiB); reserve() refuses more.
  ScratchBlocks(const std::string& dir, std::uint64_t resident_bytes);
  ScratchBlocks(const ScratchBlocks&) = delete;
  ScratchBlocks& operator=(const ScratchBlocks&) = delete;

  /// Makes the first `bytes` addressable (new bytes are zero). Not concurrent with accesses.
  void reserve(std::uint64_t bytes) {
    if (bytes > capacity_) grow(bytes);  // push_back asks on every value
  }

  /// Reads the `n` bytes at `offset` (within one block: n divides the block size and offset is a
  /// multiple of n). Threads may read at once.
  void read(std::uint64_t offset, void* out, std::size_t n) const {
    const std::uint64_t block = offset / kBlock;
    const std::size_t s = slot_of(block);
    const Slot& slot = slots_[s];
    for (;;) {
      const std::uint64_t tag = slot.tag.load(std::memory_order_acquire);
      if (static_cast<std::uint32_t>(tag) != block + 1) {
        fill(block);
        continue;
      }
      std::memcpy(out, at(s, offset), n);
      // Seqlock: the copy counts only if no refill of the slot began meanwhile.
      std::atomic_thread_fence(std::memory_order_acquire);
      if (slot.tag.load(std::memory_order_relaxed) == tag) return;
    }
  }

  /// Writes `n` bytes at `offset` (as read). Not concurrent with other accesses.
  void write(std::uint64_t offset, const void* in, std::size_t n) {
    const std::uint64_t block = offset / kBlock;
    const std::size_t s = slot_of(block);
    if (static_cast<std::uint32_t>(slots_[s].tag.load(std::memory_order_relaxed)) != block + 1) {
      fill(block);
    }
    slots_[s].dirty = true;
    std::memcpy(at(s, offset), in, n);
  }

  /// Times a block was read into a slot.
  std::uint64_t fills() const { return fills_.load(); }

  static constexpr std::uint64_t kBlock = 4096;

 private:
  struct Slot {
    // (generation << 32) | (block + 1); 0 in the low half while no block (or a refill) is there.
    std::atomic<std::uint64_t> tag{0};
    bool dirty = false;
  };
  std::size_t slot_of(std::uint64_t block) const {
    return static_cast<std::size_t>(block & (slots_.size() - 1));
  }
  // Where the byte at `offset` is in slot s (holding its block).
  char* at(std::size_t s, std::uint64_t offset) const {
    return data_.get() + s * kBlock + offset % kBlock;
  }
  void grow(std::uint64_t bytes);
  void fill(std::uint64_t block) const;

  mutable TempFile file_;
  std::uint64_t capacity_ = 0;
  mutable std::vector<Slot> slots_;  // a power of two of them
  std::unique_ptr<char[]> data_;     // a block per slot
  mutable std::mutex fill_;
  mutable std::atomic<std::uint64_t> fills_{0};
};

template <class T>
class SpillArray {
  static_assert(std::is_trivially_copyable_v<T>, "values live in a file's bytes");
  static_assert(std::has_single_bit(sizeof(T)) && sizeof(T) <= ScratchBlocks::kBlock,
                "a value lies within one block");

 public:
  /// In memory when `resident_bytes` is 0, else in a scratch file in `dir` (already resolved by
  /// scratch_dir()) holding at most `resident_bytes` (at least 64 KiB) resident.
  SpillArray(const std::string& dir, std::uint64_t resident_bytes) {
    if (resident_bytes > 0) blocks_ = std::make_unique<ScratchBlocks>(dir, resident_bytes);
  }

  std::size_t size() const { return size_; }

  /// Grows (new values are zero) or shrinks. Not concurrent with accesses.
  void resize(std::size_t n) {
    if (blocks_) {
      blocks_->reserve(std::uint64_t{n} * sizeof(T));
      // Values once held past the size (shrunk, then grown) become zero again; the file's bytes
      // past every size it had are zero already.
      for (std::size_t i = size_; i < std::min(n, high_); ++i) set(i, T{});
      high_ = std::max(high_, n);
    } else {
      mem_.resize(n);
    }
    size_ = n;
  }

  void push_back(const T& v) {
    if (!blocks_) {
      mem_.push_back(v);
      ++size_;
      return;
    }
    resize(size_ + 1);  // the file grows by doubling (ScratchBlocks::reserve)
    set(size_ - 1, v);
  }

  /// Threads may read at once.
  T operator[](std::size_t i) const {
    if (!blocks_) return mem_[i];
    T v{};
    blocks_->read(std::uint64_t{i} * sizeof(T), &v, sizeof(T));
    return v;
  }

  /// Not concurrent with other accesses.
  void set(std::size_t i, const T& v) {
    if (!blocks_) {
      mem_[i] = v;
      return;
    }
    blocks_->write(std::uint64_t{i} * sizeof(T), &v, sizeof(T));
  }

  bool spilled() const { return blocks_ != nullptr; }
  /// Times a block of the scratch file was read (0 in memory).
  std::uint64_t fills() const { return blocks_ ? blocks_->fills() : 0; }

 private:
  std::vector<T> mem_;
  std::unique_ptr<ScratchBlocks> blocks_;
  std::size_t size_ = 0, high_ = 0;  // high_: the largest size it has had (spilled)
};

}  // namespace smr::storage
