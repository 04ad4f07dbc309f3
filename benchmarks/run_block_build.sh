#!/usr/bin/env bash
# The block builder (smrdb ingest --builder blocks, issue 5) against delatin and our in-core
# greedy builder, on the same DEM in one run:
#   1. a deterministic SIZE^2 fBm (default 8193^2 = 67 M samples, seed 1, range 1600 m), written
#      as .npy (delatin's input) and, with INPUT=tif, also as a tiled GeoTIFF (DEFLATE); the block
#      builder reads INPUT (default npy: the same file as delatin) by windows;
#   2. `smrdb ingest --memory $MEMORY` (the block builder; peak RSS from /usr/bin/time) and,
#      unless GREEDY=0,
#      `smrdb ingest` (greedy, the DEM in memory), at max error = 0.1 % of the range;
#   3. delatin (benchmarks/peers/run_peer.mjs) at the same max error;
#   4. bench_check: every sample of the DEM against the block database's finest mesh and
#      delatin's mesh;
#   5. benchmarks/results/block_build.json: times (median of REPEAT rounds, interleaved), peak
#      RSS, the block builder's phases, DAG height, rounds, ops, and the ratios.
#
# Environment: BUILD_DIR (build/release), WORK_DIR ($BUILD_DIR/bench-blocks), SIZE (8193),
# SEED (1), RANGE (1600), MAX_ERROR_FRACTION (0.001), REPEAT (1), BLOCK_CELLS (256), INPUT (npy),
# MEMORY (256M), THREADS (0 = one per core), GREEDY (1), DELATIN (1), CHECK_BLOCKS (1), OUT
# (results file).
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/.." && pwd)"
BUILD_DIR="${BUILD_DIR:-$root/build/release}"
WORK_DIR="${WORK_DIR:-$BUILD_DIR/bench-blocks}"
SIZE="${SIZE:-8193}"
SEED="${SEED:-1}"
RANGE="${RANGE:-1600}"
MAX_ERROR_FRACTION="${MAX_ERROR_FRACTION:-0.001}"
REPEAT="${REPEAT:-1}"
BLOCK_CELLS="${BLOCK_CELLS:-256}"
GREEDY="${GREEDY:-1}"
MEMORY="${MEMORY:-256M}"
THREADS="${THREADS:-0}"
DELATIN="${DELATIN:-1}"
CHECK_BLOCKS="${CHECK_BLOCKS:-1}"
INPUT="${INPUT:-npy}"
OUT="${OUT:-$here/results/block_build.json}"

smrdb="$BUILD_DIR/tools/smrdb"
bench_check="$BUILD_DIR/benchmarks/bench_check"
for exe in "$smrdb" "$bench_check"; do
  [[ -x "$exe" ]] || { echo "missing $exe: build first (cmake --build $BUILD_DIR)" >&2; exit 1; }
done
command -v node >/dev/null || { echo "node is required for delatin" >&2; exit 1; }
command -v jq >/dev/null || { echo "jq is required to assemble the results" >&2; exit 1; }
[[ -x /usr/bin/time ]] || { echo "/usr/bin/time (Debian package time) is required" >&2; exit 1; }
if [[ ! -d "$here/peers/node_modules/delatin" ]]; then
  (cd "$here/peers" && npm ci --no-audit --no-fund)
fi
mkdir -p "$WORK_DIR" "$(dirname "$OUT")"
# shellcheck source=lib.sh
source "$here/lib.sh"

max_error="$(awk -v r="$RANGE" -v f="$MAX_ERROR_FRACTION" 'BEGIN { printf "%.12g", r * f }')"
tif="$WORK_DIR/fbm${SIZE}_seed${SEED}.tif"
npy="$WORK_DIR/fbm${SIZE}_seed${SEED}.npy"
case "$INPUT" in
  npy) input="$npy"; input_text=".npy (float32), the same file as delatin's" ;;
  tif) input="$tif"; input_text="tiled GeoTIFF (256 x 256, DEFLATE) for smrdb, .npy for delatin" ;;
  *) echo "INPUT must be npy or tif, got $INPUT" >&2; exit 1 ;;
esac
if [[ "$INPUT" == tif && ! -f "$tif" ]]; then
  log "generating $tif"
  "$smrdb" synth --size "$SIZE" --seed "$SEED" --range "$RANGE" -o "$tif" -q
fi
[[ -f "$npy" ]] || { log "generating $npy"; "$smrdb" synth --size "$SIZE" --seed "$SEED" --range "$RANGE" -o "$npy" -q; }

# Runs smrdb with /usr/bin/time; writes $2.json (smrdb's --json) and $2.time ("rss_kb seconds").
timed_ingest() {  # $1 = extra args, $2 = output prefix, $3 = database
  /usr/bin/time -f "%M %e" -o "$2.time" "$smrdb" ingest "$input" $1 --max-error "$max_error" \
    -o "$3" --force -q --json >"$2.json"
}

loadavg_before="$(cut -d' ' -f1-3 /proc/loadavg)"
for ((i = 1; i <= REPEAT; i++)); do
  log "round $i/$REPEAT: blocks"
  timed_ingest "--builder blocks --block-cells $BLOCK_CELLS --memory $MEMORY --threads $THREADS --tmp $WORK_DIR" "$WORK_DIR/blocks_$i" "$WORK_DIR/blocks.smrdb"
  log "  blocks: $(cat "$WORK_DIR/blocks_$i.time") (KiB, s)"
  if [[ "$GREEDY" == 1 ]]; then
    log "round $i/$REPEAT: greedy"
    timed_ingest "" "$WORK_DIR/greedy_$i" "$WORK_DIR/greedy.smrdb"
    log "  greedy: $(cat "$WORK_DIR/greedy_$i.time") (KiB, s)"
  fi
  log "round $i/$REPEAT: delatin"
  if [[ $i -eq 1 ]]; then
    node --max-old-space-size=16384 "$here/peers/run_peer.mjs" --peer delatin --npy "$npy" \
      --max-error "$max_error" --out-mesh "$WORK_DIR/delatin.bin" >"$WORK_DIR/delatin_$i.json"
  else
    node --max-old-space-size=16384 "$here/peers/run_peer.mjs" --peer delatin --npy "$npy" \
      --max-error "$max_error" >"$WORK_DIR/delatin_$i.json"
  fi
  log "  delatin: $(jq -r '"\(.seconds) s, \(.rss_mb) MiB"' "$WORK_DIR/delatin_$i.json")"
done
loadavg_after="$(cut -d' ' -f1-3 /proc/loadavg)"

log "checking every sample: block database, delatin"
set +e
"$bench_check" "$npy" --db "$WORK_DIR/blocks.smrdb" --max-error "$max_error" >"$WORK_DIR/blocks_check.json"
"$bench_check" "$npy" --mesh "$WORK_DIR/delatin.bin" --max-error "$max_error" >"$WORK_DIR/delatin_check.json"
set -e

for ((i = 1; i <= REPEAT; i++)); do
  jq --slurpfile j "$WORK_DIR/blocks_$i.json" -R "$PEAK_RSS_JQ"' split(" ") | {rss_mb: peak_rss_mb(.[0] | tonumber; $j[0]), wall_seconds: (.[1] | tonumber), report: $j[0]}' \
    "$WORK_DIR/blocks_$i.time" >"$WORK_DIR/blocks_run_$i.json"
  if [[ "$GREEDY" == 1 ]]; then
    jq --slurpfile j "$WORK_DIR/greedy_$i.json" -R "$PEAK_RSS_JQ"' split(" ") | {rss_mb: peak_rss_mb(.[0] | tonumber; $j[0]), wall_seconds: (.[1] | tonumber), report: $j[0]}' \
      "$WORK_DIR/greedy_$i.time" >"$WORK_DIR/greedy_run_$i.json"
  else
    echo null >"$WORK_DIR/greedy_run_$i.json"
  fi
done

cpu_model="$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//')"
jq -n \
  --slurpfile blocks <(cat "$WORK_DIR"/blocks_run_*.json | jq -s .) \
  --slurpfile greedy <(cat "$WORK_DIR"/greedy_run_*.json | jq -s .) \
  --slurpfile delatin <(cat "$WORK_DIR"/delatin_[0-9]*.json | jq -s .) \
  --slurpfile bcheck "$WORK_DIR/blocks_check.json" --slurpfile dcheck "$WORK_DIR/delatin_check.json" \
  --arg date "$(date -u +%Y-%m-%dT%H:%M:%SZ)" \
  --arg commit "$(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo unknown)" \
  --arg dirty "$(git -C "$root" status --porcelain -- smr tools 2>/dev/null | wc -l)" \
  --arg nproc "$(nproc)" --arg cpu "$cpu_model" --arg la0 "$loadavg_before" --arg la1 "$loadavg_after" \
  --argjson size "$SIZE" --argjson seed "$SEED" --argjson range "$RANGE" \
  --argjson max_error "$max_error" --argjson block_cells "$BLOCK_CELLS" \
  --arg memory "$MEMORY" --arg threads "$THREADS" --arg input_text "$input_text" '
  def median: sort | if length % 2 == 1 then .[length / 2 | floor] else (.[length / 2 - 1] + .[length / 2]) / 2 end;
  ($blocks[0]) as $b | ($greedy[0] | map(select(. != null))) as $g | ($delatin[0]) as $d |
  ($b | map(.report.crmr.build_seconds) | median) as $b_build |
  ($b | map(.wall_seconds) | median) as $b_wall |
  ($d | map(.seconds) | median) as $d_s |
  {
    benchmark: "block_build",
    date: $date, commit: $commit, uncommitted_files: ($dirty | tonumber),
    machine: {nproc: ($nproc | tonumber), cpu_model: $cpu, loadavg_before: $la0, loadavg_after: $la1},
    dem: {generator: "smrdb synth --size \($size) --seed \($seed) --range \($range)",
          samples: ($size * $size), file: $input_text},
    max_error: $max_error, memory: $memory, threads: ($threads | tonumber),
    repeats: ($b | length),
    blocks: {block_cells: $block_cells,
             build_seconds: $b_build, ingest_wall_seconds: $b_wall,
             build_seconds_all: ($b | map(.report.crmr.build_seconds)),
             peak_rss_mb: ($b | map(.rss_mb) | max),
             phases_seconds: $b[0].report.blocks.seconds,
             blocks: ($b[0].report.blocks | del(.seconds)),
             crmr: $b[0].report.crmr, database: $b[0].report.database,
             error_check: $bcheck[0].error_check},
    greedy: (if ($g | length) > 0 then
               {build_seconds: ($g | map(.report.crmr.build_seconds) | median),
                ingest_wall_seconds: ($g | map(.wall_seconds) | median),
                peak_rss_mb: ($g | map(.rss_mb) | max), crmr: $g[0].report.crmr}
             else null end),
    delatin: {seconds: $d_s, seconds_all: ($d | map(.seconds)), rss_mb: ($d | map(.rss_mb) | max),
              read_seconds: ($d | map(.read_seconds) | median),
              triangles: $d[0].triangles, error_check: $dcheck[0].error_check},
    ratios: {
      blocks_build_over_delatin: ($b_build / $d_s),
      blocks_ingest_over_delatin: ($b_wall / $d_s),
      blocks_ingest_over_delatin_with_its_read: ($b_wall / ($d_s + ($d | map(.read_seconds) | median))),
      finest_triangles_blocks_over_delatin: ($b[0].report.crmr.finest_triangles / $d[0].triangles)
    },
    targets: {
      time_over_delatin_max: 0.7, peak_rss_mb_max: 320,
      time_met: (($b_wall / $d_s) <= 0.7),
      rss_met: (($b | map(.rss_mb) | max) <= 320),
      note: "issue 5: 8193^2 fBm at 0.1 % of the range, --memory 256M: ingest wall time <= 0.7x delatin, peak RSS <= 256 + 64 MiB."
    }
  }' >"$OUT"
log "wrote $OUT"
jq '{blocks: {build: .blocks.build_seconds, wall: .blocks.ingest_wall_seconds, rss_mb: .blocks.peak_rss_mb, bound_ok: .blocks.error_check.ok},
     greedy: (.greedy | if . then {build: .build_seconds, rss_mb: .peak_rss_mb} else null end),
     delatin: {s: .delatin.seconds, rss_mb: .delatin.rss_mb, bound_ok: .delatin.error_check.ok}, ratios, targets}' "$OUT"
