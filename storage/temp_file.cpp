#include "storage/temp_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <vector>

#include "base/error.h"

namespace smr::storage {

std::string scratch_dir(const std::string& dir) {
  return dir.empty() ? std::filesystem::temp_directory_path().string() : dir;
}

TempFile::TempFile(const std::string& dir, std::uint64_t expected_bytes) : dir_(dir) {
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec)) {
    throw_input("temporary directory '" + dir + "' does not exist (--tmp)");
  }
  const std::filesystem::space_info space = std::filesystem::space(dir, ec);
  const std::uint64_t margin = std::uint64_t{64} << 20;
  if (!ec && space.available < expected_bytes + margin) {
    throw_input("temporary directory '" + dir + "' has " + std::to_string(space.available >> 20) +
                " MiB free; this ingest needs " + std::to_string((expected_bytes + margin) >> 20) +
                " MiB there (choose another with --tmp)");
  }
  std::string name = (std::filesystem::path(dir) / "smrdb-scratch-XXXXXX").string();
  std::vector<char> buf(name.begin(), name.end());
  buf.push_back('\0');
  fd_ = ::mkstemp(buf.data());
  if (fd_ < 0) throw_io("cannot create a temporary file in '" + dir + "': " + std::strerror(errno));
  ::unlink(buf.data());
}

TempFile::~TempFile() {
  if (fd_ >= 0) ::close(fd_);
}

void TempFile::write(std::uint64_t offset, const void* data, std::size_t n) {
  const char* p = static_cast<const char*>(data);
  while (n > 0) {
    const ssize_t k = ::pwrite(fd_, p, n, static_cast<off_t>(offset));
    if (k < 0 && errno == EINTR) continue;
    if (k <= 0) {
      throw_io("cannot write the temporary file in '" + dir_ + "': " + std::strerror(errno));
    }
    p += k;
    n -= static_cast<std::size_t>(k);
    offset += static_cast<std::uint64_t>(k);
    written_ += static_cast<std::uint64_t>(k);
  }
}

void TempFile::read(std::uint64_t offset, void* data, std::size_t n) const {
  char* p = static_cast<char*>(data);
  while (n > 0) {
    const ssize_t k = ::pread(fd_, p, n, static_cast<off_t>(offset));
    if (k < 0 && errno == EINTR) continue;
    if (k <= 0) {
      throw_io("cannot read the temporary file in '" + dir_ +
               "': " + (k == 0 ? std::string("short file") : std::string(std::strerror(errno))));
    }
    p += k;
    n -= static_cast<std::size_t>(k);
    offset += static_cast<std::uint64_t>(k);
  }
}

}  // namespace smr::storage
