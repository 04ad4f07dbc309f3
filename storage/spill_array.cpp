#include "storage/spill_array.h"

#include <algorithm>
#include <cerrno>
#include <cstring>

#include <sys/mman.h>
#include <unistd.h>

#include "base/error.h"

namespace smr::storage {

namespace {
constexpr std::uint64_t kPage = 4096;
}

ScratchMapping::ScratchMapping(const std::string& dir, std::uint64_t resident_bytes)
    : file_(dir, 0), trim_every_(std::max<std::uint64_t>(resident_bytes / kPage, 16)) {}

ScratchMapping::~ScratchMapping() {
  if (data_ != nullptr) ::munmap(data_, capacity_);
}

void ScratchMapping::reserve(std::uint64_t bytes) {
  if (bytes <= capacity_) return;
  const std::uint64_t grown = std::max({bytes, capacity_ * 2, std::uint64_t{1} << 20});
  const std::uint64_t capacity = (grown + kPage - 1) / kPage * kPage;
  if (::ftruncate(file_.fd(), static_cast<off_t>(capacity)) != 0) {
    throw_io("cannot grow a scratch table to " + std::to_string(capacity) +
             " bytes: " + std::strerror(errno));
  }
  void* data = ::mmap(nullptr, capacity, PROT_READ | PROT_WRITE, MAP_SHARED, file_.fd(), 0);
  if (data == MAP_FAILED) {
    throw_io("cannot map a scratch table of " + std::to_string(capacity) +
             " bytes: " + std::strerror(errno));
  }
  if (data_ != nullptr) ::munmap(data_, capacity_);
  data_ = data;
  capacity_ = capacity;
}

void ScratchMapping::trim() const {
  // Advisory: a failure only leaves the pages resident.
  if (data_ != nullptr) (void)::madvise(data_, capacity_, MADV_DONTNEED);
  trims_.fetch_add(1, std::memory_order_relaxed);
}

}  // namespace smr::storage
