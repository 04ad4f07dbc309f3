#!/usr/bin/env bash
# Brown Fig. 7.21 (issue 35, Benchmarks): a forward flight over a real DEM through a geomorphing
# session (smrdb flythrough), without a maximum geomorphing period and with one of 100 ms (Brown's
# 0.1 s) and a tight one of 8 ms; each frame also extracted from scratch (--compare-fresh) for the
# headline ratio. DEMs: jacksboro at full resolution (its degrees turned into metres by
# metric_npz.py, so the camera flies in one unit) and the 4097^2 fBm database of
# run_extract_vs_martini.sh (FBM_DB). On the fBm also a flight at the default walking speed (1 % of
# the model's extent per second at 60 fps), and the frame-rate target's setting: the same walk at
# 1920x1080 over the 32769^2 (1.07 G-sample) database of run_block_build_big.sh (BIG_DB).
#
# Writes benchmarks/results/flythrough_<dem>_<period>.json (smrdb flythrough --json, plus date,
# commit and load) and a PNG per run beside it: (a) per frame, refinings (+) and coarsenings (-)
# done (bars) and pending (lines), (b) triangles, (c) update and fresh-extraction time.
# A summary table goes to stderr and benchmarks/results/flythrough.json.
#
# Environment: BUILD_DIR (default build/release), FBM_DB, FRAMES (jacksboro, default 300),
# FBM_FRAMES (default 240), WALK_FRAMES (default 120), BIG_WALK_FRAMES (default 600), BIG_DB,
# RUNS (default "jacksboro fbm fbm_walk big_walk"; big_walk is skipped when BIG_DB does not exist);
# PLOT_ONLY=1 only redraws the PNGs of the JSON already in results/.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/.." && pwd)"
source "$here/lib.sh"
BUILD_DIR="${BUILD_DIR:-$root/build/release}"
FBM_DB="${FBM_DB:-/work/main/build/release/bench-martini/fbm4097_seed1_e1.6.smrdb}"
FRAMES="${FRAMES:-300}"
FBM_FRAMES="${FBM_FRAMES:-240}"
WALK_FRAMES="${WALK_FRAMES:-120}"
BIG_WALK_FRAMES="${BIG_WALK_FRAMES:-600}"
BIG_DB="${BIG_DB:-$root/build/release/bench-query/fbm32769.smrdb}"
RUNS="${RUNS:-jacksboro fbm fbm_walk big_walk}"
RES="$here/results"
smrdb="$BUILD_DIR/tools/smrdb"
require_executables "$BUILD_DIR" "$smrdb"
command -v jq >/dev/null || { echo "jq is required" >&2; exit 1; }
command -v gnuplot >/dev/null || { echo "gnuplot is required (apt-get install gnuplot-nox)" >&2; exit 1; }
mkdir -p "$RES"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

# plot JSON PNG TITLE: Brown Fig. 7.21's three graphs of one run.
plot() {
  jq -r '.frames[] | [.frame, .refinings, -.coarsenings, .pending_refinings,
         -.pending_coarsenings, .triangles, .update_ms, (.fresh_ms // 0)] | @tsv' "$1" >"$work/f.tsv"
  local period
  period="$(jq '.flight.max_period_ms' "$1")"
  gnuplot <<EOF
set terminal pngcairo size 1000,1100 font ",10" noenhanced
set output "$2"
set multiplot layout 3,1 title "$3"
set xlabel "frame"
set grid
set style fill solid 0.6 noborder
set ylabel "ops (refinings +, coarsenings -)"
set title "(a) refinings and coarsenings done (bars) and pending after the update (lines)"
plot "$work/f.tsv" u 1:2 w boxes lc rgb "#2c7fb8" t "refinings", \
     "" u 1:3 w boxes lc rgb "#d95f0e" t "coarsenings", \
     "" u 1:4 w steps lc rgb "#08306b" lw 1.5 t "pending refinings", \
     "" u 1:5 w steps lc rgb "#7f2704" lw 1.5 t "pending coarsenings"
set ylabel "triangles"
set title "(b) triangles in the mesh"
plot "$work/f.tsv" u 1:6 w lines lw 1.5 lc rgb "#31a354" notitle
set ylabel "ms"
set logscale y
set title "(c) time per frame: session update and a fresh extraction of the same RCF"
plot "$work/f.tsv" u 1:7 w lines lw 1.2 lc rgb "#2c7fb8" t "update", \
     "" u 1:(\$8 > 0 ? \$8 : 1/0) w lines lw 1.2 lc rgb "#999999" t "fresh extraction", \
     ($period > 0 ? $period : 1/0) w lines dt 2 lc rgb "black" t "max period"
unset multiplot
EOF
}

# fly NAME DB ARGS...: one run -> results/flythrough_NAME.json and .png.
fly() {
  local name="$1" db="$2"
  shift 2
  local out="$RES/flythrough_$name.json"
  log "flythrough $name: $*"
  "$smrdb" flythrough "$db" --json --compare-fresh "$@" >"$work/run.json"
  jq --arg date "$(date -u +%Y-%m-%dT%H:%M:%SZ)" \
     --arg commit "$(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo unknown)" \
     --arg loadavg "$(cut -d' ' -f1-3 /proc/loadavg)" \
     --arg args "$*" \
     '{date: $date, commit: $commit, loadavg_after: $loadavg, args: $args} + .' \
     "$work/run.json" >"$out"
  plot "$out" "$RES/flythrough_$name.png" "smrdb flythrough $name ($(basename "$db"))"
}

# The table of every results/flythrough_*.json: results/flythrough.json and stderr.
summarize() {
  jq -n '{date: (now | todate), runs: [inputs |
      {name: (input_filename | split("/") | last | ltrimstr("flythrough_") | rtrimstr(".json"))} +
      (.summary | {frames, incomplete_frames, update_p50: .update_ms.p50,
        update_p99: .update_ms.p99, update_max: .update_ms.max, first_frame_ms,
        fresh_p50: .fresh_ms.p50, fresh_p99: .fresh_ms.p99, ratio_p50: .fresh_over_update_p50,
        ratio_mean: .fresh_over_update_mean, morphs_pct_p50: .local_morphs_pct.p50,
        morphs_pct_max: .local_morphs_pct.max, fresh_mismatches, peak_rss_mib, cache_mib})]}' \
    "$@" >"$RES/flythrough.json"
  jq -r '.runs[] | [.name, .frames, .incomplete_frames, (.update_p50 | .*1000|round/1000),
         (.update_p99 | .*1000|round/1000), (.first_frame_ms | round), (.fresh_p50 | .*1000|round/1000),
         (.ratio_p50 | .*100|round/100), (.morphs_pct_p50 | .*1000|round/1000),
         (.morphs_pct_max | .*100|round/100), .fresh_mismatches, (.peak_rss_mib | round)] | @tsv' \
    "$RES/flythrough.json" |
    (echo -e "run\tframes\tincomplete\tupd_p50\tupd_p99\tfirst_ms\tfresh_p50\tfresh/upd\tmorph%p50\tmorph%max\tmismatch\trss_mib"; cat) |
    column -t >&2
  echo "wrote $RES/flythrough.json" >&2
}

if [[ "${PLOT_ONLY:-0}" == 1 ]]; then  # redraw the PNGs and the table of the results written
  for f in "$RES"/flythrough_{3d,fbm,jacksboro}*.json; do
    plot "$f" "${f%.json}.png" "smrdb flythrough $(basename "${f%.json}" | sed 's/^flythrough_//') ($(jq -r .database "$f" | xargs basename))"
  done
  summarize "$RES"/flythrough_{3d,fbm,jacksboro}*.json
  exit 0
fi

has_run() { [[ " $RUNS " == *" $1 "* ]]; }

# Forward flights (Brown: "the viewpoint stepped forwards along the view direction"): from near
# the south-west corner towards the north-east, descending, looking ahead and 20 degrees down.
forward_line() {  # DB -> X1,Y1,Z1:X2,Y2,Z2 from the bounds
  "$smrdb" info "$1" --json | jq -r '.meta.model.bounds as $b | ($b.hi[0] - $b.lo[0]) as $w |
    ($b.hi[1] - $b.lo[1]) as $h | ($b.hi[2] - $b.lo[2]) as $r |
    "\($b.lo[0] + 0.05 * $w),\($b.lo[1] + 0.05 * $h),\($b.hi[2] + 0.1 * ([$w, $h] | max)):" +
    "\($b.lo[0] + 0.6 * $w),\($b.lo[1] + 0.6 * $h),\($b.hi[2] + 0.02 * ([$w, $h] | max))"'
}

# Walking speed: 1 % of the model's horizontal extent per second (--frames alone would instead
# spread the frames over the whole line).
walking_speed() {  # DB -> model units per second
  "$smrdb" info "$1" --json | jq '.meta.model.bounds | [.hi[0] - .lo[0], .hi[1] - .lo[1]] | max * 0.01'
}

if has_run jacksboro; then
  [[ -f "$root/data/jacksboro_fault_dem.npz" ]] || { echo "missing data/jacksboro_fault_dem.npz: run scripts/fetch-data.sh" >&2; exit 1; }
  python3 "$here/metric_npz.py" "$root/data/jacksboro_fault_dem.npz" "$work/jacksboro_m.npz"
  "$smrdb" ingest "$work/jacksboro_m.npz" -q -o "$work/jacksboro_m.smrdb"
  line="$(forward_line "$work/jacksboro_m.smrdb")"
  for period in 0 100 8; do
    fly "jacksboro_p$period" "$work/jacksboro_m.smrdb" --line "$line" --frames "$FRAMES" \
      --max-period "$period" --settle
  done
fi
if has_run fbm || has_run fbm_walk; then
  [[ -f "$FBM_DB" ]] || { echo "missing $FBM_DB: run benchmarks/run_extract_vs_martini.sh" >&2; exit 1; }
  line="$(forward_line "$FBM_DB")"
  if has_run fbm; then
    for period in 0 100 8; do
      fly "fbm4097_p$period" "$FBM_DB" --line "$line" --frames "$FBM_FRAMES" --max-period "$period" \
        --settle
    done
  fi
  if has_run fbm_walk; then
    fly "fbm4097_walk" "$FBM_DB" --line "$line" --frames "$WALK_FRAMES" --fps 60 \
      --speed "$(walking_speed "$FBM_DB")"
  fi
fi

if has_run big_walk && [[ -f "$BIG_DB" ]]; then
  # Warm: the database file is read once first, so the flight starts with it in the OS cache.
  cat "$BIG_DB" >/dev/null
  fly "fbm32769_walk" "$BIG_DB" --line "$(forward_line "$BIG_DB")" --frames "$BIG_WALK_FRAMES" \
    --fps 60 --speed "$(walking_speed "$BIG_DB")" --viewport 1920x1080
  # Cold: the OS's page cache dropped before each of COLD_RUNS starts (needs root; skipped
  # otherwise): open to first frame, into results/flythrough_cold.json (not a flythrough_ run).
  if [[ -w /proc/sys/vm/drop_caches ]]; then
    cold=()
    for ((i = 0; i < ${COLD_RUNS:-5}; i++)); do
      sync
      echo 3 >/proc/sys/vm/drop_caches
      sleep 1
      "$smrdb" flythrough "$BIG_DB" --json --line "$(forward_line "$BIG_DB")" --frames 30 --fps 60 \
        --speed "$(walking_speed "$BIG_DB")" --viewport 1920x1080 -q >"$work/cold.json"
      cold+=("$(jq '{open_to_first_frame_ms: .summary.open_to_first_frame_ms,
                     first_frame_ms: .summary.first_frame_ms, pages_read: .io.pages_read,
                     lmdb_bytes_read: .io.lmdb_bytes_read}' "$work/cold.json")")
      log "  cold start $((i + 1)): $(jq .summary.open_to_first_frame_ms "$work/cold.json") ms to the first frame"
    done
    printf '%s\n' "${cold[@]}" | jq -s --arg date "$(date -u +%Y-%m-%dT%H:%M:%SZ)" \
      --arg commit "$(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo unknown)" \
      '{date: $date, commit: $commit, database: "fbm32769", viewport: "1920x1080",
        note: "OS page cache dropped before each run (echo 3 > /proc/sys/vm/drop_caches)",
        runs: ., open_to_first_frame_ms: ([.[].open_to_first_frame_ms] | sort |
        {min: .[0], median: .[length / 2 | floor], max: .[-1]})}' >"$RES/flythrough_cold.json"
  fi
fi

summarize "$RES"/flythrough_{3d,fbm,jacksboro}*.json
