// AtomicFile: write a file under a temporary name, then rename it over its path, so a reader never
// sees a half-written output (the "loses nothing" rule for every file smrdb writes).
#pragma once

#include <cstdio>
#include <string>

namespace smr {

/// A file that appears at `path` only when commit() succeeds: bytes go to a uniquely named
/// temporary file in the same directory, which commit() flushes, closes and renames over `path`.
/// Destroying an uncommitted AtomicFile removes the temporary file. Errors throw kIo naming `path`.
class AtomicFile {
 public:
  explicit AtomicFile(std::string path);
  ~AtomicFile();
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  void write(const void* data, std::size_t size);
  void write(const std::string& text) { write(text.data(), text.size()); }
  /// The open stream on the temporary file, for libraries that write a FILE* (libpng).
  /// Errors on it are detected by commit().
  std::FILE* stream() { return file_; }
  /// Closes the stream; for writers (GDAL) that then write temp_path() themselves.
  void close_stream();
  const std::string& temp_path() const { return temp_path_; }
  const std::string& path() const { return path_; }
  void commit();

 private:
  std::string path_;
  std::string temp_path_;
  std::FILE* file_ = nullptr;
  bool committed_ = false;
};

}  // namespace smr
