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
scripts/build.sh release
ctest --preset release -j"$(nproc)"
scripts/build.sh asan
ctest --preset asan -j"$(nproc)"
echo "all tests passed"
