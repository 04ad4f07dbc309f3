// An anonymous scratch file for data that does not fit the memory budget: created in a chosen
// directory after checking that it has room, unlinked at once, so that it disappears with the
// process however it ends (kill -9 included) and never appears beside the user's files.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace smr::storage {

/// `dir`, or the system's temporary directory when `dir` is empty.
std::string scratch_dir(const std::string& dir);

class TempFile {
 public:
  /// Creates the file in `dir`. Throws smr::Error (kInvalidInput) naming `dir` when it does not
  /// exist or has less than `expected_bytes` (plus 64 MiB) free, kIo when the file cannot be made.
  TempFile(const std::string& dir, std::uint64_t expected_bytes);
  ~TempFile();
  TempFile(const TempFile&) = delete;
  TempFile& operator=(const TempFile&) = delete;

  /// Writes / reads exactly `n` bytes at `offset`; throws kIo (naming the directory) on failure.
  void write(std::uint64_t offset, const void* data, std::size_t n);
  void read(std::uint64_t offset, void* data, std::size_t n) const;
  std::uint64_t bytes_written() const { return written_; }
  /// The file's descriptor (to size it: storage::ScratchBlocks).
  int fd() const { return fd_; }

 private:
  std::string dir_;
  int fd_ = -1;
  std::uint64_t written_ = 0;
};

}  // namespace smr::storage
