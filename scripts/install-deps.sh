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
  liblmdb-dev lmdb-utils libdraco-dev libxxhash-dev libzstd-dev \
  libgtest-dev libgmock-dev libbenchmark-dev clang-format >/dev/null
echo "dependencies installed"
