#!/usr/bin/env bash
# The main job on a real DEM: install, build, fetch jacksboro_fault_dem.npz (Debian's
# python-matplotlib-data), ingest it into an on-disk LOD database (out/jacksboro.smrdb), describe
# it, then extract from the database, inside a 16 MiB page cache, a selectively refined mesh for an
# RCF (an oblique camera with a 1.5-pixel tolerance, plus a Gaussian area of interest), and write
# out/jacksboro.obj and the picture out/jacksboro.png.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
scripts/build.sh release
scripts/fetch-data.sh data
mkdir -p out
# jacksboro is geographic: x, y in degrees (lon/lat), z in metres.
build/release/tools/smrdb ingest data/jacksboro_fault_dem.npz --max-error 1 \
  -o out/jacksboro.smrdb --force
build/release/tools/smrdb info out/jacksboro.smrdb
build/release/tools/smrdb extract out/jacksboro.smrdb --cache-mb 16 \
  --eye=-84.45,36.40,1400 --target=-84.26,36.60,300 --fov 45 --viewport 1280x800 --pixel-error 1.5 \
  --aoi=-84.20,36.50,0.03,0.98 --floor 0.2 \
  -o out/jacksboro.obj --png out/jacksboro.png --json
echo "wrote out/jacksboro.smrdb, out/jacksboro.obj and out/jacksboro.png"
