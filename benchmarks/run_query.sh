#!/usr/bin/env bash
# The GIS queries of issue 36 (smr/query; bench_query), written to results/query.json with the
# plots results/query_fig10.png and results/query_fig11.png:
#   fig       Maheshwari Figs. 10-11 on fBm databases from 33^2 to 32769^2 samples (SIZES): windows
#             of 1/25 and 1/4 of the area at LOCATIONS random places (seed SEED), |X| / vertices of
#             the result in the window; point queries at as many places, ops of the descent
#             (ElevationAnswer::ops_read) and |X| of refine() on the point. The 32769^2 database
#             comes from the block builder, the others from the greedy one; BLOCK_SIZES are built
#             with the block builder too (BLOCK_LOCATIONS places) to tell size from builder.
#   latency   on the 32769^2 database (1.07 G samples): point elevation warm / cold (clear_cache) /
#             OS-cold (posix_fadvise, and DROP_ALL points after echo 3 > /proc/sys/vm/drop_caches,
#             root only), batch at_many over BATCH points, and the same points through
#             `smrdb query DB elevation --input pts.csv -o out.csv`.
#   sight     line of sight (PAIRS random pairs) and 10-leg profiles on the same database.
#   contours  the whole DEM at INTERVAL metres, ours (contours() + write_geojson to a file, decoded
#             page caches of 64 MiB and CACHE_MB) against gdal_contour on the source GeoTIFF, on
#             the 4097^2 and 32769^2 fBm, with peak RSS (/usr/bin/time). gdal_contour on 32769^2
#             runs in the background while the fig step runs on the other core.
#
# The DEMs: `smrdb synth --size N --seed 1 --range 1600` (spacing 1; octave frequencies are relative
# to the grid side, so a larger N is a larger, more detailed terrain), ingested with
# `smrdb ingest --max-error 1.6` (0.1 % of the range; greedy builder; with --memory 2G, the block
# builder, for 32769^2 and BLOCK_SIZES). The 32769^2 database (BIG_DB) and the greedy 8193^2 one
# (DB_8193) are reused when they exist. Every file both sides read is read once first (OS page
# cache warm). Each step writes its part to WORK_DIR/parts; the parts are then assembled.
#
# Environment: BUILD_DIR (build/release), WORK_DIR ($BUILD_DIR/bench-query), SIZES, LOCATIONS
# (2500), SEED (1), CACHE_MB (1024: holds every decoded page of the largest database), INTERVAL
# (50), BATCH (1000000), PAIRS (1000), DROP_ALL (10), BLOCK_SIZES ("2049 8193"), BLOCK_LOCATIONS
# (500), BIG_DB, BIG_TIF, DB_8193, STEPS ("latency sight contours fig"); REUSE=1 keeps the fig
# parts already in WORK_DIR/parts; PLOT_ONLY=1 redraws the PNGs from results/query.json.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/.." && pwd)"
# shellcheck source=lib.sh
source "$here/lib.sh"
BUILD_DIR="${BUILD_DIR:-$root/build/release}"
WORK_DIR="${WORK_DIR:-$BUILD_DIR/bench-query}"
SIZES="${SIZES:-33 129 513 2049 8193 32769}"
LOCATIONS="${LOCATIONS:-2500}"
SEED="${SEED:-1}"
CACHE_MB="${CACHE_MB:-1024}"
INTERVAL="${INTERVAL:-50}"
BATCH="${BATCH:-1000000}"
PAIRS="${PAIRS:-1000}"
DROP_ALL="${DROP_ALL:-10}"
BIG_DB="${BIG_DB:-/work/main/build/release/bench-query/fbm32769.smrdb}"
BIG_TIF="${BIG_TIF:-/work/main/build/release/bench-query/fbm32769_seed1.tif}"
DB_8193="${DB_8193:-/work/main/build/release/bench-martini/fbm8193_seed1_e1.6.smrdb}"
BLOCK_SIZES="${BLOCK_SIZES-2049 8193}"
BLOCK_LOCATIONS="${BLOCK_LOCATIONS:-500}"
STEPS="${STEPS:-latency sight contours fig}"
RES="$here/results"
OUT="$RES/query.json"

smrdb="$BUILD_DIR/tools/smrdb"
bench="$BUILD_DIR/benchmarks/bench_query"
has_step() { [[ " $STEPS " == *" $1 "* ]]; }

# ---- plots ----------------------------------------------------------------------------------
plot() {  # query.json -> query_fig10.png, query_fig11.png
  local builder
  mkdir -p "$WORK_DIR"
  for builder in greedy blocks; do
    jq -r --arg b "$builder" '.fig[] | select(.builder == $b) | [.db.vertices,
             (.windows[] | .ratio.mean, .ratio.p50, .ratio.p99, .introduced_ratio.mean),
             .points.descent_ops.mean, .points.descent_ops.p50, .points.descent_ops.p99,
             .points.descent_ops.max, .points.refine_ops.mean, .points.refine_ops.max,
             .db.samples] | @tsv' "$1" | sort -n >"$WORK_DIR/fig_$builder.tsv"
  done
  local g="$WORK_DIR/fig_greedy.tsv" b="$WORK_DIR/fig_blocks.tsv"
  gnuplot <<EOF
set terminal pngcairo size 1000,650 font ",10" noenhanced
set datafile separator "\t"
set logscale x
set grid
set key top right
set xrange [700:1e6]
set xlabel "vertices of the database (fBm 33^2 .. 32769^2 samples at 1.6 m; filled: greedy builder, open: block builder)"
set output "${RES}/query_fig10.png"
set title "Maheshwari Fig. 10: ops fetched (|X|) / vertices of the result in the window, finest accuracy, random windows"
set ylabel "ratio"
set yrange [0:7]
plot "$g" u 1:2 w linespoints lw 2 pt 7 lc rgb "#2c7fb8" t "1/25 of the area: mean", \
     "" u 1:4 w lines dt 2 lc rgb "#2c7fb8" t "1/25: p99", \
     "" u 1:5 w linespoints pt 1 dt 3 lc rgb "#2c7fb8" t "1/25: vertices the ops of X introduce / vertices", \
     "" u 1:6 w linespoints lw 2 pt 5 lc rgb "#d95f0e" t "1/4 of the area: mean", \
     "" u 1:8 w lines dt 2 lc rgb "#d95f0e" t "1/4: p99", \
     "" u 1:9 w linespoints pt 1 dt 3 lc rgb "#d95f0e" t "1/4: vertices the ops of X introduce / vertices", \
     "$b" u 1:2 w linespoints pt 6 lc rgb "#2c7fb8" t "1/25, block builder: mean", \
     "" u 1:6 w linespoints pt 4 lc rgb "#d95f0e" t "1/4, block builder: mean", \
     3 w lines lc rgb "black" dt 4 t "paper: < 3"
set output "${RES}/query_fig11.png"
set title "Maheshwari Fig. 11: ops fetched by a point query, random points"
set ylabel "ops"
set logscale y
set yrange [5:5000]
set key top left
plot "$g" u 1:10 w linespoints lw 2 pt 7 lc rgb "#2c7fb8" t "elevation descent: mean", \
     "" u 1:12 w lines dt 2 lc rgb "#2c7fb8" t "descent: p99", \
     "" u 1:13 w points pt 2 lc rgb "#2c7fb8" t "descent: max", \
     "" u 1:14 w linespoints pt 5 lc rgb "#d95f0e" t "refine() of the point as a window: mean", \
     "" u 1:15 w points pt 2 lc rgb "#d95f0e" t "refine(): max", \
     "$b" u 1:10 w linespoints pt 6 lc rgb "#2c7fb8" t "descent, block builder: mean", \
     "" u 1:13 w points pt 1 lc rgb "#2c7fb8" t "descent, block builder: max", \
     "" u 1:14 w linespoints pt 4 lc rgb "#d95f0e" t "refine(), block builder: mean", \
     70 w lines lc rgb "black" dt 4 t "paper: <= 70 (up to 50 k vertices)"
EOF
  echo "wrote $RES/query_fig10.png $RES/query_fig11.png" >&2
}

if [[ "${PLOT_ONLY:-0}" == 1 ]]; then
  plot "$OUT"
  exit 0
fi

require_executables "$BUILD_DIR" "$smrdb" "$bench"
require_tools
command -v gnuplot >/dev/null || { echo "gnuplot is required (apt-get install gnuplot-nox)" >&2; exit 1; }
command -v gdal_contour >/dev/null || { echo "gdal_contour is required (gdal-bin)" >&2; exit 1; }
mkdir -p "$WORK_DIR" "$RES"
parts="$WORK_DIR/parts"
mkdir -p "$parts"

# ---- databases ------------------------------------------------------------------------------
# dem_of N / db_of N / block_db_of N: the fBm GeoTIFF and its databases (made here unless reused).
dem_of() { if [[ "$1" == 32769 ]]; then echo "$BIG_TIF"; else echo "$WORK_DIR/fbm$1_seed1.tif"; fi; }
db_of() {
  if [[ "$1" == 32769 ]]; then echo "$BIG_DB"
  elif [[ "$1" == 8193 && -f "$DB_8193" ]]; then echo "$DB_8193"
  else echo "$WORK_DIR/fbm$1_e1.6.smrdb"; fi
}
block_db_of() { echo "$WORK_DIR/fbm$1_blocks_e1.6.smrdb"; }
prepare_dem() {  # N
  local dem
  dem="$(dem_of "$1")"
  [[ -f "$dem" ]] && return
  log "synth $1^2 -> $dem"
  nice "$smrdb" synth --size "$1" --seed 1 --range 1600 -o "$dem" -q
}
prepare_db() {  # N DB [INGEST OPTIONS...]
  local n="$1" db="$2"
  shift 2
  [[ -f "$db" ]] && return
  prepare_dem "$n"
  log "ingest $(dem_of "$n") $* -> $db"
  nice "$smrdb" ingest "$(dem_of "$n")" --max-error 1.6 "$@" -o "$db" -q
}
big_step=0
if has_step latency || has_step sight || has_step contours; then big_step=1; fi
if has_step fig || (( big_step )); then prepare_db 32769 "$BIG_DB" --memory 2G; fi
if has_step fig; then
  for n in $SIZES; do
    if [[ "$n" == 32769 ]]; then continue; fi
    prepare_db "$n" "$(db_of "$n")"
  done
  for n in $BLOCK_SIZES; do prepare_db "$n" "$(block_db_of "$n")" --memory 2G; done
fi
if has_step contours; then
  prepare_db 4097 "$(db_of 4097)"
  prepare_dem 32769
fi

stamp() {  # date, commit, load average
  jq --arg date "$(date -u +%Y-%m-%dT%H:%M:%SZ)" \
     --arg commit "$(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo unknown)" \
     --arg loadavg "$(cut -d' ' -f1-3 /proc/loadavg)" \
     '. + {date: $date, commit: $commit, loadavg_after: $loadavg}'
}
warm() { cat "$@" >/dev/null; }  # into the OS page cache

# ---- latency --------------------------------------------------------------------------------
if has_step latency; then
  log "latency: point and batch elevation on $(basename "$BIG_DB")"
  nice "$bench" latency "$BIG_DB" --cache-mb "$CACHE_MB" --seed "$SEED" --batch "$BATCH" \
    --drop-all "$DROP_ALL" --write-points "$WORK_DIR/pts.csv" | stamp >"$parts/latency.json"
  # The same points through the CLI (its default 64 MiB cache, then CACHE_MB), CSV in and out.
  cli='[]'
  for cache in 64 "$CACHE_MB"; do
    warm "$BIG_DB" "$WORK_DIR/pts.csv"
    log "smrdb query elevation --input pts.csv ($BATCH points, --cache-mb $cache)"
    /usr/bin/time -f '%e %M' -o "$WORK_DIR/cli.time" nice "$smrdb" query "$BIG_DB" elevation \
      --input "$WORK_DIR/pts.csv" -o "$WORK_DIR/elev.csv" --cache-mb "$cache" -q
    read -r secs kb <"$WORK_DIR/cli.time"
    lines=$(($(wc -l <"$WORK_DIR/elev.csv") - 1))
    cli="$(jq --argjson c "$cache" --argjson s "$secs" --argjson kb "$kb" --argjson n "$lines" \
      '. + [{cache_mb: $c, seconds: $s, answers: $n, points_per_second: ($n / $s),
             peak_rss_mb: ($kb / 1024)}]' <<<"$cli")"
  done
  jq --argjson cli "$cli" '. + {cli: $cli}' "$parts/latency.json" >"$parts/latency.tmp"
  mv "$parts/latency.tmp" "$parts/latency.json"
  rm -f "$WORK_DIR/elev.csv"
fi

# ---- sight ----------------------------------------------------------------------------------
if has_step sight; then
  log "sight: line of sight and profiles on $(basename "$BIG_DB")"
  nice "$bench" sight "$BIG_DB" --cache-mb "$CACHE_MB" --seed "$SEED" --pairs "$PAIRS" |
    stamp >"$parts/sight.json"
fi

# ---- contours -------------------------------------------------------------------------------
# count_geojson FILE: lines, closed rings and points of a GeoJSON of LineStrings (one per line,
# as gdal_contour writes them).
count_geojson() {
  python3 - "$1" <<'EOF'
import json, sys
lines = rings = points = 0
with open(sys.argv[1]) as f:
    for row in f:
        row = row.strip().rstrip(",")
        if not row.startswith('{ "type": "Feature"') and not row.startswith('{"type": "Feature"'):
            continue
        c = json.loads(row)["geometry"]["coordinates"]
        lines += 1
        points += len(c)
        rings += c[0] == c[-1]
print(json.dumps({"lines": lines, "rings": rings, "points": points}))
EOF
}
# gdal_contour_run N: gdal_contour on the N^2 GeoTIFF -> $parts/gdal_N.json
gdal_contour_run() {
  local n="$1" out="$WORK_DIR/gdal_$1.geojson"
  rm -f "$out"
  /usr/bin/time -f '%e %M %U %S' -o "$WORK_DIR/gdal_$n.time" \
    nice gdal_contour -q -a elev -i "$INTERVAL" -f GeoJSON "$(dem_of "$n")" "$out"
  read -r secs kb user sys <"$WORK_DIR/gdal_$n.time"
  count_geojson "$out" | jq --argjson s "$secs" --argjson kb "$kb" --argjson u "$user" \
    --argjson sy "$sys" --arg v "$(gdalinfo --version)" --argjson bytes "$(stat -c %s "$out")" \
    '. + {seconds: $s, cpu_seconds: ($u + $sy), peak_rss_mb: ($kb / 1024), output_bytes: $bytes,
          version: $v}' \
    >"$parts/gdal_$n.json"
  rm -f "$out"
}
# ours_contour_run N CACHE: bench_query contours (a fresh process) -> $parts/ours_N_CACHE.json
ours_contour_run() {
  local n="$1" cache="$2" out="$WORK_DIR/ours_$1.geojson"
  /usr/bin/time -f '%e %M %U %S' -o "$WORK_DIR/ours.time" nice "$bench" contours \
    "$(db_of "$n")" --interval "$INTERVAL" --cache-mb "$cache" -o "$out" >"$WORK_DIR/ours.json"
  read -r secs kb user sys <"$WORK_DIR/ours.time"
  jq --argjson s "$secs" --argjson kb "$kb" --argjson u "$user" --argjson sy "$sys" \
    '. + {process_seconds: $s, process_cpu_seconds: ($u + $sy),
          process_peak_rss_mb: ($kb / 1024)}' "$WORK_DIR/ours.json" \
    >"$parts/ours_${n}_$cache.json"
  rm -f "$out"
}
gdal_big_pid=""
if has_step contours; then
  for n in 4097 32769; do
    warm "$(db_of "$n")" "$(dem_of "$n")"
    for cache in 64 "$CACHE_MB"; do
      log "contours: ours on $n^2 every $INTERVAL m (cache $cache MiB)"
      ours_contour_run "$n" "$cache"
    done
  done
  log "contours: gdal_contour on 4097^2"
  gdal_contour_run 4097
  log "contours: gdal_contour on 32769^2 in the background"
  warm "$BIG_TIF"
  gdal_contour_run 32769 &
  gdal_big_pid=$!
fi

# ---- fig (Maheshwari Figs. 10-11) ------------------------------------------------------------
fig_run() {  # NAME DB LOCATIONS -> $parts/fig_NAME.json
  local part="$parts/fig_$1.json"
  if [[ "${REUSE:-0}" == 1 ]] && jq -e .windows "$part" >/dev/null 2>&1; then
    log "fig: $1 (reused $part)"
    return
  fi
  log "fig: $1 ($3 locations)"
  nice "$bench" fig "$2" --locations "$3" --seed "$SEED" --cache-mb "$CACHE_MB" |
    stamp >"$part"
}
fig_jobs() {  # NAME DB LOCATIONS per line
  local n
  for n in $SIZES; do echo "$n $(db_of "$n") $LOCATIONS"; done
  for n in $BLOCK_SIZES; do echo "${n}_blocks $(block_db_of "$n") $BLOCK_LOCATIONS"; done
}
if has_step fig; then
  # One core runs gdal_contour while it lasts: every other job (the largest first) goes there,
  # the rest after it ends.
  jobs_sorted="$(fig_jobs | sort -t' ' -k1,1nr)"
  (i=0; while read -r name db locs; do
     if (( i++ % 2 == 0 )); then fig_run "$name" "$db" "$locs"; fi
   done <<<"$jobs_sorted") &
  fig_pid=$!
  if [[ -n "$gdal_big_pid" ]]; then wait "$gdal_big_pid"; gdal_big_pid=""; fi
  i=0
  while read -r name db locs; do
    if (( i++ % 2 == 1 )); then fig_run "$name" "$db" "$locs"; fi
  done <<<"$jobs_sorted"
  wait "$fig_pid"
fi
if [[ -n "$gdal_big_pid" ]]; then wait "$gdal_big_pid"; fi

# ---- results --------------------------------------------------------------------------------
log "assembling $OUT"
part() { if [[ -f "$parts/$1.json" ]]; then cat "$parts/$1.json"; else echo null; fi; }
figs='[]'
while read -r name _; do
  if [[ -f "$parts/fig_$name.json" ]]; then
    figs="$(jq --slurpfile f "$parts/fig_$name.json" '. + $f' <<<"$figs")"
  fi
done < <(fig_jobs)
figs="$(jq 'map(. + {builder: (if .db.builder | startswith("greedy") then "greedy" else "blocks" end)})
  | sort_by(.builder != "greedy", .db.vertices)' <<<"$figs")"
contours='[]'
for n in 4097 32769; do
  [[ -f "$parts/gdal_$n.json" ]] || continue
  contours="$(jq --argjson n "$n" --slurpfile g "$parts/gdal_$n.json" \
    --slurpfile o64 "$parts/ours_${n}_64.json" --slurpfile ob "$parts/ours_${n}_$CACHE_MB.json" \
    '. + [{size: $n, gdal: $g[0], ours: [$o64[0], $ob[0]] | map(del(.machine)),
           gdal_over_ours: [$o64[0], $ob[0]] | map({cache_mb, ratio: ($g[0].seconds / .seconds),
             ratio_process: ($g[0].seconds / .process_seconds),
             ratio_cpu: ($g[0].cpu_seconds / .process_cpu_seconds)})}]' <<<"$contours")"
done
jq -n --argjson fig "$figs" --argjson contours "$contours" \
  --argjson latency "$(part latency)" --argjson sight "$(part sight)" \
  --arg date "$(date -u +%Y-%m-%dT%H:%M:%SZ)" \
  --arg commit "$(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo unknown)" \
  --arg loadavg "$(cut -d' ' -f1-3 /proc/loadavg)" \
  --argjson params "$(jq -n --arg sizes "$SIZES" --argjson l "$LOCATIONS" --argjson s "$SEED" \
     --argjson c "$CACHE_MB" --argjson i "$INTERVAL" --argjson b "$BATCH" --argjson p "$PAIRS" \
     --arg bs "$BLOCK_SIZES" --argjson bl "$BLOCK_LOCATIONS" \
     '{sizes: ($sizes | split(" ") | map(tonumber)), locations: $l, seed: $s, cache_mb: $c,
       interval: $i, batch: $b, pairs: $p, max_error: 1.6, range: 1600,
       block_sizes: ($bs | split(" ") | map(select(. != "") | tonumber)),
       block_locations: $bl}')" '
  {date: $date, commit: $commit, loadavg_after: $loadavg, parameters: $params,
   machine: ([$fig[0], $latency, $sight] | map(select(. != null)) | first | .machine),
   fig: ($fig | map(del(.machine))), latency: ($latency | if . then del(.machine) else . end),
   sight: ($sight | if . then del(.machine) else . end), contours: $contours} |
  .targets = {
    fig10_ratio_below_3: ([.fig[] | .db.vertices as $v | .windows[] | {vertices: $v, fraction,
        mean: .ratio.mean}] |
      {paper: "< 3, converging as n grows", worst_mean: (map(.mean) | max),
       worst_mean_from_10k_vertices: (map(select(.vertices >= 10000).mean) | max),
       met: ((map(select(.vertices >= 10000).mean) | max) < 3)}),
    fig11_ops_at_most_70: ([.fig[].points.descent_ops.max] |
      {paper: "<= 70 up to 50 k vertices, logarithmic", worst_max: max, met: (max <= 70)}),
    point_warm_p99_ms_at_most_1: (.latency.point_warm.ms.p99 // null |
      {value: ., met: (. != null and . <= 1)}),
    point_cold_p99_ms_at_most_20: (.latency.point_cold.ms.p99 // null |
      {value: ., os_cold: $latency.point_os_cold.ms.p99, drop_caches: $latency.point_drop_caches.ms.p99,
       met: (. != null and . <= 20)}),
    batch_warm_points_per_second_at_least_200k: (.latency.batch_warm.points_per_second // null |
      {value: ., cli: [$latency.cli[]?.points_per_second], met: (. != null and . >= 200000)}),
    contours_faster_than_gdal: ([.contours[] | {size, ratios: .gdal_over_ours}] |
      {value: ., met: (map(.ratios[].ratio) | length > 0 and min > 1)})
  }' >"$OUT"
plot "$OUT"
jq -r '.fig[] | [.db.grid[0], .builder, .db.samples, .db.vertices,
      (.windows[] | .ratio.mean, .ratio.p99), .points.descent_ops.mean, .points.descent_ops.p99,
      .points.descent_ops.max] | @tsv' "$OUT" |
  (echo -e "size\tbuilder\tsamples\tvertices\tr25_mean\tr25_p99\tr4_mean\tr4_p99\tpt_mean\tpt_p99\tpt_max"; cat) |
  column -t >&2
jq '.targets' "$OUT" >&2
echo "wrote $OUT" >&2
