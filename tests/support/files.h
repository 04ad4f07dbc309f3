// Scratch directories and whole-file reads and writes for the tests.
#pragma once

#include <filesystem>
#include <string>

namespace smr::test {

/// A fresh directory under the system's temporary directory, removed with everything in it when
/// the object goes out of scope. `prefix` names the test suite in the directory's name.
class TempDir {
 public:
  explicit TempDir(const std::string& prefix = "smrdb-test");
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const std::filesystem::path& path() const { return path_; }
  std::string file(const std::string& name) const { return (path_ / name).string(); }

 private:
  std::filesystem::path path_;
};

std::string read_file(const std::string& path);
void write_file(const std::string& path, const std::string& bytes);

}  // namespace smr::test
