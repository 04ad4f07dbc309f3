#!/usr/bin/env bash
# The whole test suite: install, fetch the real datasets, build the release and the
# AddressSanitizer/UndefinedBehaviorSanitizer presets, run every test in both, check formatting.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
scripts/fetch-data.sh data
export SMRDB_DATA_DIR="$PWD/data"
# Formatting first: it is cheap, and a violation should not wait for the sanitizer run.
files=$(git ls-files '*.h' '*.cpp' | grep -v '^benchmarks/peers/')
clang-format --dry-run -Werror $files
# ctest starts the longest tests first when it knows their durations (from the previous run in
# that build directory); a fresh clone starts from the heavy tests' durations in tests/costs/.
seed_costs() {
  local dir="build/$1/Testing/Temporary"
  [[ -f "$dir/CTestCostData.txt" ]] && return
  mkdir -p "$dir"
  cp "tests/costs/$1.txt" "$dir/CTestCostData.txt"
}
scripts/build.sh release
seed_costs release
ctest --preset release -j"$(nproc)"
scripts/build.sh asan
seed_costs asan
ctest --preset asan -j"$(nproc)"
echo "all tests passed"
