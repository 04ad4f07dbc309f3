#!/usr/bin/env bash
# Installs what smrdb needs to build and test on Debian 12 (run as root or with sudo available).
set -euo pipefail
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends \
  build-essential cmake g++ git ca-certificates \
  libcgal-dev libgmp-dev libmpfr-dev libboost-dev \
  libgdal-dev gdal-bin libglm-dev libcli11-dev nlohmann-json3-dev libpng-dev zlib1g-dev \
  liblmdb-dev lmdb-utils libdraco-dev libmeshoptimizer-dev libxxhash-dev libzstd-dev \
  libgtest-dev libgmock-dev libbenchmark-dev clang-format pkg-config libcpp-httplib-dev >/dev/null
# node and npm for the JavaScript tools the tests run (tests/js: the Khronos glTF-Validator);
# a node that came with its own npm (NodeSource's) is kept.
if ! command -v npm >/dev/null; then
  $SUDO apt-get install -y -qq --no-install-recommends nodejs npm >/dev/null
fi
(cd "$(dirname "$0")/../tests/js" && npm ci --no-audit --no-fund --silent)
# The browser viewer (tools/viewer: three.js, esbuild; puppeteer-core and pngjs for its test) and
# the headless browser its test drives (tests/viewer).
$SUDO apt-get install -y -qq --no-install-recommends chromium >/dev/null
(cd "$(dirname "$0")/../tools/viewer" && npm ci --no-audit --no-fund --silent)
echo "dependencies installed"
