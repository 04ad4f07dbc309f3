#!/usr/bin/env bash
# Issue 5's large terrain run (not in CI): a deterministic SIZE^2 fBm DEM (default 32769^2 =
# 1.07 G samples, 4 GiB as float32) as a tiled GeoTIFF, ingested out of core with
# `smrdb ingest --memory $MEMORY` (default 2G), then
#   - peak RSS (/usr/bin/time) against the budget, samples/s, temp bytes, DAG height, ops, pages;
#   - every sample of the DEM checked against the database's finest mesh (bench_check --db: the
#     DEM and the finest mesh in memory, a checker's privilege);
#   - extraction on it, and on SMALL_DB if given (the 8193^2 database of run_block_build.sh):
#     bench_db's oblique and overview views at 1 px, pages read and time.
# Writes benchmarks/results/block_build_big.json.
#
# Environment: BUILD_DIR (build/release), WORK_DIR ($BUILD_DIR/bench-blocks), SIZE (32769),
# SEED (1), RANGE (1600), MAX_ERROR (1.6), MEMORY (2G), THREADS (0), CHECK (1), SMALL_DB, OUT.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/.." && pwd)"
BUILD_DIR="${BUILD_DIR:-$root/build/release}"
WORK_DIR="${WORK_DIR:-$BUILD_DIR/bench-blocks}"
SIZE="${SIZE:-32769}"
SEED="${SEED:-1}"
RANGE="${RANGE:-1600}"
MAX_ERROR="${MAX_ERROR:-1.6}"
MEMORY="${MEMORY:-2G}"
THREADS="${THREADS:-0}"
CHECK="${CHECK:-1}"
SMALL_DB="${SMALL_DB:-}"
OUT="${OUT:-$here/results/block_build_big.json}"

smrdb="$BUILD_DIR/tools/smrdb"
bench_check="$BUILD_DIR/benchmarks/bench_check"
bench_db="$BUILD_DIR/benchmarks/bench_db"
for exe in "$smrdb" "$bench_check" "$bench_db"; do
  [[ -x "$exe" ]] || { echo "missing $exe: build first (cmake --build $BUILD_DIR)" >&2; exit 1; }
done
command -v jq >/dev/null || { echo "jq is required to assemble the results" >&2; exit 1; }
[[ -x /usr/bin/time ]] || { echo "/usr/bin/time (Debian package time) is required" >&2; exit 1; }
mkdir -p "$WORK_DIR" "$(dirname "$OUT")"
# shellcheck source=lib.sh
source "$here/lib.sh"

tif="$WORK_DIR/fbm${SIZE}_seed${SEED}.tif"
db="$WORK_DIR/fbm${SIZE}.smrdb"
[[ -f "$tif" ]] || { log "generating $tif"; "$smrdb" synth --size "$SIZE" --seed "$SEED" --range "$RANGE" -o "$tif" -q; }

log "ingest --memory $MEMORY"
/usr/bin/time -f "%M %e" -o "$WORK_DIR/big.time" "$smrdb" ingest "$tif" --memory "$MEMORY" \
  --threads "$THREADS" --max-error "$MAX_ERROR" --tmp "$WORK_DIR" -o "$db" --force -q --json \
  >"$WORK_DIR/big_ingest.json"
log "  $(cat "$WORK_DIR/big.time") (KiB, s)"

echo '{}' >"$WORK_DIR/big_check.json"
if [[ "$CHECK" == 1 ]]; then
  log "checking every sample against the finest mesh"
  set +e
  "$bench_check" "$tif" --db "$db" --max-error "$MAX_ERROR" >"$WORK_DIR/big_check.json"
  set -e
fi

extract_views() {  # database -> JSON array of bench_db runs
  local d="$1" out="[]"
  for view in oblique overview; do
    local r
    r="$("$bench_db" extract "$d" --view "$view" --pixel-error 1 --cache-mb 64 --repeat 3)"
    out="$(jq --argjson r "$r" '. + [$r]' <<<"$out")"
  done
  echo "$out"
}
log "extraction on the large database"
extract_views "$db" >"$WORK_DIR/big_extract.json"
if [[ -n "$SMALL_DB" ]]; then
  log "extraction on $SMALL_DB"
  extract_views "$SMALL_DB" >"$WORK_DIR/small_extract.json"
else
  echo null >"$WORK_DIR/small_extract.json"
fi

jq -n --slurpfile ingest "$WORK_DIR/big_ingest.json" --slurpfile check "$WORK_DIR/big_check.json" \
  --slurpfile big "$WORK_DIR/big_extract.json" --slurpfile small "$WORK_DIR/small_extract.json" \
  --arg time "$(cat "$WORK_DIR/big.time")" --arg memory "$MEMORY" --argjson size "$SIZE" \
  --arg date "$(date -u +%Y-%m-%dT%H:%M:%SZ)" \
  --arg commit "$(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo unknown)" \
  --arg nproc "$(nproc)" "$PEAK_RSS_JQ"'
  ($time | split(" ")) as $t | ($ingest[0]) as $i |
  {
    benchmark: "block_build_big", date: $date, commit: $commit, nproc: ($nproc | tonumber),
    dem: {generator: "smrdb synth --size \($size) --seed 1 --range 1600", samples: ($size * $size),
          file: "tiled GeoTIFF (256 x 256, DEFLATE)"},
    memory: $memory,
    peak_rss_mb: peak_rss_mb($t[0] | tonumber; $i), wall_seconds: ($t[1] | tonumber),
    samples_per_second: (($size * $size) / ($t[1] | tonumber)),
    ingest: $i,
    error_check: $check[0].error_check,
    extraction: {large: $big[0], small: $small[0]}
  }' >"$OUT"
log "wrote $OUT"
jq '{peak_rss_mb, wall_seconds, samples_per_second, bound_ok: .error_check.ok,
     dag: .ingest.blocks.dag_height, ops: .ingest.crmr.ops, pages: .ingest.database.pages}' "$OUT"
