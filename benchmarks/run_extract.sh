#!/usr/bin/env bash
# Selective-refinement results in the style of Brown's Tables 7.1, 7.4 and 7.5 for the three real
# DEMs (scripts/fetch-data.sh) and a 4097^2 fBm, plus extraction throughput on a view of the fBm.
# Writes benchmarks/results/extract.json (the per-row table also goes to stderr).
#
# Environment: BUILD_DIR (default build/release), OUT (results file), and any extra bench_extract
# options as arguments, e.g. ./run_extract.sh --skip-fbm --verify
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/.." && pwd)"
BUILD_DIR="${BUILD_DIR:-$root/build/release}"
OUT="${OUT:-$here/results/extract.json}"
bench_extract="$BUILD_DIR/benchmarks/bench_extract"
[[ -x "$bench_extract" ]] || { echo "missing $bench_extract: build first (cmake --build $BUILD_DIR)" >&2; exit 1; }
for f in jacksboro_fault_dem.npz topobathy.npz elev.tif; do
  [[ -f "$root/data/$f" ]] || { echo "missing data/$f: run scripts/fetch-data.sh" >&2; exit 1; }
done
mkdir -p "$(dirname "$OUT")"

tmp="$(mktemp "${OUT}.XXXXXX")"
trap 'rm -f "$tmp"' EXIT
"$bench_extract" --data-dir "$root/data" "$@" >"$tmp"
jq --arg date "$(date -u +%Y-%m-%dT%H:%M:%SZ)" \
   --arg commit "$(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo unknown)" \
   --arg loadavg "$(cut -d' ' -f1-3 /proc/loadavg)" \
   '. + {date: $date, commit: $commit, loadavg_after: $loadavg}' "$tmp" >"$OUT"
echo "wrote $OUT" >&2
jq '.throughput | {rcf, minimal: {triangles: .minimal.triangles, median_seconds: .minimal.total_seconds, triangles_per_second: .minimal.triangles_per_second},
                       reduced: {triangles: .reduced.triangles, median_seconds: .reduced.total_seconds, triangles_per_second: .reduced.triangles_per_second}}' "$OUT"
