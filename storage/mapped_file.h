// A file mapped read-only into memory, for parsers that read it front to back, and a scoped
// thread that keeps a mapping's pages out of the resident set.
//
// Mapped file pages count in a process's resident set while they stay mapped in, so reading a
// 2 GB file through a map would show 2 GB of RSS. A PageTrimmer drops the whole range's pages
// (madvise MADV_DONTNEED) every 20 ms while it lives: they are clean file pages, so a later read
// faults them back in from the page cache and nothing is lost.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <thread>

namespace smr::storage {

class MappedFile {
 public:
  /// Maps `path`; throws smr::Error naming it when it cannot be opened or mapped.
  explicit MappedFile(const std::string& path);
  ~MappedFile();
  MappedFile(const MappedFile&) = delete;
  MappedFile& operator=(const MappedFile&) = delete;

  std::string_view bytes() const {
    return {static_cast<const char*>(data_), static_cast<std::size_t>(size_)};
  }

 private:
  void* data_ = nullptr;
  std::uint64_t size_ = 0;
};

class PageTrimmer {
 public:
  PageTrimmer(const void* data, std::size_t bytes);
  ~PageTrimmer();  // stops and joins the thread
  PageTrimmer(const PageTrimmer&) = delete;
  PageTrimmer& operator=(const PageTrimmer&) = delete;

 private:
  std::atomic<bool> running_{true};
  std::thread thread_;
};

}  // namespace smr::storage
