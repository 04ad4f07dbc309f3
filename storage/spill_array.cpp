#include "storage/spill_array.h"

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cstring>
#include <limits>

#include <unistd.h>

#include "base/error.h"

namespace smr::storage {

namespace {
constexpr std::uint64_t kMinResident = std::uint64_t{64} << 10;
}  // namespace

ScratchBlocks::ScratchBlocks(const std::string& dir, std::uint64_t resident_bytes)
    : file_(dir, 0),
      slots_(std::bit_floor(std::max(resident_bytes, kMinResident) / kBlock)),
      data_(new char[slots_.size() * kBlock]) {}

void ScratchBlocks::grow(std::uint64_t bytes) {
  // Whole blocks, so that a block read never reaches past the file's end.
  const std::uint64_t grown = std::max({bytes, capacity_ * 2, std::uint64_t{1} << 20});
  const std::uint64_t capacity = (grown + kBlock - 1) / kBlock * kBlock;
  if (capacity / kBlock >= std::numeric_limits<std::uint32_t>::max()) {  // a slot's tag: 32 bits
    throw_internal("a scratch table of " + std::to_string(capacity) +
                   " bytes: more than 2^32 - 1 blocks of 4 KiB");
  }
  if (::ftruncate(file_.fd(), static_cast<off_t>(capacity)) != 0) {
    throw_io("cannot grow a scratch table to " + std::to_string(capacity) +
             " bytes: " + std::strerror(errno));
  }
  capacity_ = capacity;
}

void ScratchBlocks::fill(std::uint64_t block) const {
  const std::lock_guard<std::mutex> lock(fill_);
  const std::size_t s = slot_of(block);
  Slot& slot = slots_[s];
  const std::uint64_t tag = slot.tag.load(std::memory_order_relaxed);
  if (static_cast<std::uint32_t>(tag) == block + 1) return;  // another thread read it
  char* data = at(s, 0);
  if (slot.dirty) {  // only set() makes a block dirty, and it is never concurrent with reads
    file_.write(std::uint64_t{static_cast<std::uint32_t>(tag) - 1u} * kBlock, data, kBlock);
    slot.dirty = false;
  }
  // Readers of the slot's old block see the tag change and read again (ScratchBlocks::read).
  const std::uint64_t generation = (tag >> 32) + 1;
  slot.tag.store(generation << 32, std::memory_order_relaxed);
  std::atomic_thread_fence(std::memory_order_release);
  file_.read(block * kBlock, data, kBlock);
  slot.tag.store((generation << 32) | (block + 1), std::memory_order_release);
  fills_.fetch_add(1, std::memory_order_relaxed);
}

}  // namespace smr::storage
