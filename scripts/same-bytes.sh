#!/usr/bin/env bash
# Do two smrdb binaries write the same bytes? For refactors that must not change what the program
# computes (docs/design.md section 8.6: same input + parameters -> byte-identical database).
# Ingests terrains (greedy; blocks; blocks out of core with --memory; Draco) and meshes (in core;
# streamed by blocks) with each binary, extracts two meshes, and compares every file with cmp.
#
#   scripts/same-bytes.sh OLD_SMRDB NEW_SMRDB     (data from scripts/fetch-data.sh; env SMRDB_DATA_DIR)
#
# A binary of an earlier commit: git worktree add /tmp/old REV && (cd /tmp/old &&
# scripts/build.sh release), then /tmp/old/build/release/tools/smrdb. Exit 0 iff all are identical.
set -euo pipefail
cd "$(dirname "$0")/.."
[[ $# == 2 ]] || { echo "usage: $0 OLD_SMRDB NEW_SMRDB" >&2; exit 2; }
data="${SMRDB_DATA_DIR:-$PWD/data}"
work="$(mktemp -d "${TMPDIR:-/tmp}/smrdb-same-bytes.XXXXXX")"
trap 'rm -rf "$work"' EXIT

make_files() {  # make_files BIN DIR
  local bin="$1" out="$2"
  mkdir -p "$out"
  "$bin" synth --size 513 --seed 7 -o "$out/fbm513.npy" -q
  "$bin" ingest "$data/jacksboro_fault_dem.npz" --max-error 1 -o "$out/jack_greedy.smrdb" -q
  "$bin" ingest "$data/jacksboro_fault_dem.npz" --max-error 1 --builder blocks \
    -o "$out/jack_blocks.smrdb" -q
  "$bin" ingest "$out/fbm513.npy" --max-error 0.5 --memory 64M --block-cells 64 \
    -o "$out/fbm_blocks_memory.smrdb" -q 2>/dev/null
  "$bin" ingest "$data/elev.tif" --codec draco -o "$out/elev_draco.smrdb" -q
  "$bin" ingest "$data/meshes/bunny00.off" -o "$out/bunny_core.smrdb" -q
  "$bin" ingest "$data/meshes/elephant-with-holes.off" -o "$out/elephant_core.smrdb" -q
  "$bin" extract "$out/bunny_core.smrdb" --floor 1 -o "$out/bunny_full.ply" -q
  "$bin" ingest "$out/bunny_full.ply" --memory 64M -o "$out/bunny_streamed.smrdb" -q
  "$bin" extract "$out/jack_greedy.smrdb" --floor 0.5 -o "$out/jack_greedy.obj" -q
}

make_files "$(realpath "$1")" "$work/old"
make_files "$(realpath "$2")" "$work/new"
differ=0
for f in "$work"/old/*; do
  name="$(basename "$f")"
  if cmp -s "$f" "$work/new/$name"; then
    echo "same      $name"
  else
    echo "DIFFERENT $name"
    differ=1
  fi
done
exit "$differ"
