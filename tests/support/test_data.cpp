#include "tests/support/test_data.h"

#include <cstdlib>
#include <filesystem>

#include <gtest/gtest.h>

namespace smr::test {

std::string data_dir() {
  if (const char* env = std::getenv("SMRDB_DATA_DIR"); env != nullptr && *env != '\0') return env;
  return "data";
}

std::string data_path(const std::string& name) {
  const std::string path = data_dir() + "/" + name;
  if (!std::filesystem::exists(path)) {
    ADD_FAILURE() << "dataset " << path << " is missing: run scripts/fetch-data.sh";
  }
  return path;
}

}  // namespace smr::test
