// AtomicFile (see atomic_file.h).
#include "smr/io/atomic_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <filesystem>

#include "base/error.h"

namespace smr {

namespace {

std::string errno_text(int err) {
  return std::strerror(err);
}

}  // namespace

AtomicFile::AtomicFile(std::string path) : path_(std::move(path)) {
  static std::atomic<std::uint64_t> counter{0};
  const std::filesystem::path target(path_);
  if (target.filename().empty()) {
    throw_io("cannot write '" + path_ + "': the path names a directory, expected a file name");
  }
  std::error_code ec;
  if (std::filesystem::is_directory(target, ec)) {
    throw_io("cannot write '" + path_ + "': it is a directory");
  }
  for (int attempt = 0; attempt < 100; ++attempt) {
    std::string name = ".";
    name += target.filename().string();
    name += ".tmp.";
    name += std::to_string(::getpid());
    name += '.';
    name += std::to_string(counter++);
    const std::filesystem::path temp = target.parent_path() / name;
    temp_path_ = temp.string();
    const int fd = ::open(temp_path_.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
    if (fd < 0) {
      if (errno == EEXIST) continue;
      throw_io("cannot write '" + path_ + "': cannot create a temporary file in its directory (" +
               errno_text(errno) + ")");
    }
    file_ = ::fdopen(fd, "wb");
    if (file_ == nullptr) {
      const int err = errno;
      ::close(fd);
      ::unlink(temp_path_.c_str());
      throw_io("cannot write '" + path_ + "': " + errno_text(err));
    }
    return;
  }
  throw_io("cannot write '" + path_ + "': no free temporary file name in its directory");
}

AtomicFile::~AtomicFile() {
  if (file_ != nullptr) std::fclose(file_);
  if (!committed_) ::unlink(temp_path_.c_str());
}

void AtomicFile::write(const void* data, std::size_t size) {
  if (size == 0) return;
  if (file_ == nullptr) throw_internal("AtomicFile::write after close_stream for '" + path_ + "'");
  if (std::fwrite(data, 1, size, file_) != size) {
    throw_io("cannot write '" + path_ + "': " + errno_text(errno));
  }
}

void AtomicFile::close_stream() {
  if (file_ == nullptr) return;
  std::FILE* f = file_;
  file_ = nullptr;
  const bool failed = std::fflush(f) != 0 || std::ferror(f) != 0;
  const int err = errno;
  if (std::fclose(f) != 0 || failed) {
    throw_io("cannot write '" + path_ + "': " + errno_text(failed ? err : errno));
  }
}

void AtomicFile::commit() {
  if (committed_) return;
  if (file_ != nullptr) {
    if (std::fflush(file_) != 0 || std::ferror(file_) != 0) {
      throw_io("cannot write '" + path_ + "': " + errno_text(errno));
    }
    if (::fsync(::fileno(file_)) != 0 && errno != EINVAL && errno != EROFS) {
      throw_io("cannot write '" + path_ + "': " + errno_text(errno));
    }
    close_stream();
  }
  if (std::rename(temp_path_.c_str(), path_.c_str()) != 0) {
    throw_io("cannot write '" + path_ + "': cannot rename the temporary file over it (" +
             errno_text(errno) + ")");
  }
  committed_ = true;
}

}  // namespace smr
