#include "storage/mapped_file.h"

#include <cerrno>
#include <chrono>
#include <cstring>

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include "base/error.h"

namespace smr::storage {

MappedFile::MappedFile(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw_io("cannot open '" + path + "': " + std::strerror(errno));
  struct stat st {};
  if (::fstat(fd, &st) != 0) {
    const int err = errno;
    ::close(fd);
    throw_io("cannot read '" + path + "': " + std::strerror(err));
  }
  if (S_ISDIR(st.st_mode)) {
    ::close(fd);
    throw_input("cannot read '" + path + "': it is a directory, expected a file");
  }
  size_ = static_cast<std::uint64_t>(st.st_size);
  if (size_ > 0) {
    data_ = ::mmap(nullptr, static_cast<std::size_t>(size_), PROT_READ, MAP_PRIVATE, fd, 0);
    if (data_ == MAP_FAILED) {
      const int err = errno;
      ::close(fd);
      data_ = nullptr;
      throw_io("cannot map '" + path + "': " + std::strerror(err));
    }
    (void)::madvise(data_, static_cast<std::size_t>(size_), MADV_SEQUENTIAL);
  }
  ::close(fd);
}

MappedFile::~MappedFile() {
  if (data_ != nullptr) ::munmap(data_, static_cast<std::size_t>(size_));
}

PageTrimmer::PageTrimmer(const void* data, std::size_t bytes) {
  if (data == nullptr || bytes == 0) return;
  thread_ = std::thread([this, data, bytes] {
    while (running_.load()) {
      (void)::madvise(const_cast<void*>(data), bytes, MADV_DONTNEED);
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
  });
}

PageTrimmer::~PageTrimmer() {
  running_.store(false);
  if (thread_.joinable()) thread_.join();
}

}  // namespace smr::storage
