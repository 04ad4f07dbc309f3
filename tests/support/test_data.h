// Locating the real datasets fetched by scripts/fetch-data.sh.
#pragma once

#include <string>

namespace smr::test {

/// Directory of fetched datasets: $SMRDB_DATA_DIR, else <source>/data.
std::string data_dir();
/// Full path of a fetched dataset; fails the current test (GTEST_SKIP is not used: CI fetches
/// the data first, so a missing file is a failure) when it is absent.
std::string data_path(const std::string& name);

}  // namespace smr::test
