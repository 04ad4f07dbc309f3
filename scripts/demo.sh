#!/usr/bin/env bash
# The main job on a real DEM: install, build, fetch jacksboro_fault_dem.npz (Debian's
# python-matplotlib-data), build its CRMR, extract a selectively refined mesh for an RCF
# (an oblique camera with a 1.5-pixel tolerance, plus a Gaussian area of interest), and write
# out/jacksboro.obj and the picture out/jacksboro.png.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
scripts/build.sh release
scripts/fetch-data.sh data
mkdir -p out
# jacksboro is geographic: x, y in degrees (lon/lat), z in metres.
build/release/tools/smrdb build data/jacksboro_fault_dem.npz --max-error 1 \
  --eye=-84.45,36.40,1400 --target=-84.26,36.60,300 --fov 45 --viewport 1280x800 --pixel-error 1.5 \
  --aoi=-84.20,36.50,0.03,0.98 --floor 0.2 \
  -o out/jacksboro.obj --png out/jacksboro.png --json
echo "wrote out/jacksboro.obj and out/jacksboro.png"
