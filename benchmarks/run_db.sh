#!/usr/bin/env bash
# I/O benchmarks of the on-disk database (bench_db and `smrdb extract`). Writes
#   results/db_amplification.json  read amplification (LMDB bytes / bytes of the needed pages),
#                                  pages touched vs needed, cold / warm / hot times and the raw
#                                  LMDB read of the same pages, on the largest database, for an
#                                  oblique low view and a high overview at PIXEL_ERRORS
#   results/db_memory.json         peak RSS (/usr/bin/time -v) of `smrdb extract --cache-mb 64`
#                                  on every database, with the output's size
#   results/db_scaling.json        the same camera and pixel tolerance on every database
#   results/db_codecs.json         raw / zstd / draco on real pages (bench_db codecs)
#
# The databases: a deterministic fBm (smrdb synth, seed SEED, range RANGE) over ONE world window
# of WORLD metres (octave frequencies are relative to the grid side, so every size is the same
# terrain), sampled SIZE^2 times at spacing WORLD / SIZE, ingested at MAX_ERROR metres. A larger
# SIZE is the same terrain at a finer spacing, so a camera fixed in world coordinates sees the
# same footprint on every database.
#
# Environment: BUILD_DIR (default build/release), WORK_DIR (scratch, default $BUILD_DIR/bench-db),
# SIZES ("1025 4097"; the full run is SIZES="1025 4097 16385": ~2 min ingest, ~5 GB RAM),
# MAX_ERROR (0.5), WORLD (16385), SEED (1), RANGE (1600), PIXEL_ERRORS ("1,2,4"), REPEAT (5),
# CACHE_MB (64), STEPS ("amplification memory scaling codecs"), FINEST_MAX_SIZE (1025: the
# memory step also extracts the whole finest mesh on databases up to this size).
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/.." && pwd)"
# shellcheck source=lib.sh
source "$here/lib.sh"
BUILD_DIR="${BUILD_DIR:-$root/build/release}"
WORK_DIR="${WORK_DIR:-$BUILD_DIR/bench-db}"
SIZES="${SIZES:-1025 4097}"
MAX_ERROR="${MAX_ERROR:-0.5}"
WORLD="${WORLD:-16385}"
SEED="${SEED:-1}"
RANGE="${RANGE:-1600}"
PIXEL_ERRORS="${PIXEL_ERRORS:-1,2,4}"
REPEAT="${REPEAT:-5}"
CACHE_MB="${CACHE_MB:-64}"
STEPS="${STEPS:-amplification memory scaling codecs}"
FINEST_MAX_SIZE="${FINEST_MAX_SIZE:-1025}"
RES="$here/results"

smrdb="$BUILD_DIR/tools/smrdb"
bench_db="$BUILD_DIR/benchmarks/bench_db"
for exe in "$smrdb" "$bench_db"; do
  [[ -x "$exe" ]] || { echo "missing $exe: build first (cmake --build $BUILD_DIR)" >&2; exit 1; }
done
command -v jq >/dev/null || { echo "jq is required" >&2; exit 1; }
[[ -x /usr/bin/time ]] || { echo "/usr/bin/time (GNU time) is required for peak RSS" >&2; exit 1; }
mkdir -p "$WORK_DIR" "$RES"

stamp() {  # adds date, commit, load average and the run parameters to a JSON document
  jq --arg date "$(date -u +%Y-%m-%dT%H:%M:%SZ)" \
     --arg commit "$(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo unknown)" \
     --arg loadavg "$(cut -d' ' -f1-3 /proc/loadavg)" \
     --arg sizes "$SIZES" --argjson max_error "$MAX_ERROR" --argjson world "$WORLD" \
     --argjson seed "$SEED" --argjson range "$RANGE" --argjson cache_mb "$CACHE_MB" \
     '. + {date: $date, commit: $commit, loadavg_after: $loadavg,
           parameters: {sizes: ($sizes | split(" ") | map(tonumber)), max_error: $max_error,
                        world: $world, seed: $seed, range: $range, cache_mb: $cache_mb}}'
}

# ---- the databases --------------------------------------------------------------------------
db_of() { echo "$WORK_DIR/fbm$1_e$MAX_ERROR.smrdb"; }
dbs_json="$WORK_DIR/dbs.json"
echo '[]' >"$dbs_json"
for n in $SIZES; do
  dem="$WORK_DIR/fbm$n.tif"
  db="$(db_of "$n")"
  spacing="$(awk -v w="$WORLD" -v n="$n" 'BEGIN { printf "%.17g", w / n }')"
  if [[ ! -f "$dem" ]]; then
    "$smrdb" synth --size "$n" --seed "$SEED" --range "$RANGE" --spacing "$spacing" -o "$dem" -q
  fi
  if [[ ! -f "$db" || ! -f "$db.ingest.json" ]]; then
    echo "ingest $n^2 (spacing $spacing, max error $MAX_ERROR)" >&2
    /usr/bin/time -f '%e %M' -o "$db.ingest.time" \
      "$smrdb" ingest "$dem" -o "$db" --max-error "$MAX_ERROR" --force --json -q >"$db.ingest.json"
    read -r secs kb <"$db.ingest.time"
    jq --argjson s "$secs" --argjson kb "$kb" '. + {ingest_seconds: $s, ingest_peak_rss_mb: ($kb / 1024)}' \
      "$db.ingest.json" >"$db.ingest.json.tmp" && mv "$db.ingest.json.tmp" "$db.ingest.json"
  fi
  jq --argjson n "$n" --argjson sp "$spacing" \
    '{size: $n, spacing: $sp, crmr, database, ingest_seconds, ingest_peak_rss_mb}' \
    "$db.ingest.json" >"$WORK_DIR/db_row.json"
  jq --slurpfile r "$WORK_DIR/db_row.json" '. + $r' "$dbs_json" >"$dbs_json.tmp" && mv "$dbs_json.tmp" "$dbs_json"
done
largest="$(echo "$SIZES" | tr ' ' '\n' | sort -n | tail -1)"
big_db="$(db_of "$largest")"

# One camera for every database: the named views of bench_db on the largest one (the bounds of
# the smaller ones differ by < 0.1 %), passed explicitly so that they are identical.
camera_of() {  # view -> "--eye x,y,z --target x,y,z"
  "$bench_db" extract "$big_db" --view "$1" --pixel-error 4 --algorithms reduced --repeat 1 \
    --no-cold --no-raw 2>/dev/null |
    jq -r '"--eye \(.camera.eye | map(tostring) | join(",")) --target \(.camera.target | map(tostring) | join(","))"'
}

has_step() { [[ " $STEPS " == *" $1 "* ]]; }

# ---- 1 + 4: read amplification, cold / warm / hot, raw LMDB read ----------------------------
if has_step amplification; then
  views="$WORK_DIR/amplification_views.json"
  echo '[]' >"$views"
  for view in oblique overview; do
    "$bench_db" extract "$big_db" --view "$view" --pixel-error "$PIXEL_ERRORS" \
      --cache-mb "$CACHE_MB" --repeat "$REPEAT" >"$WORK_DIR/amp_$view.json"
    jq --slurpfile v "$WORK_DIR/amp_$view.json" '. + $v' "$views" >"$views.tmp" && mv "$views.tmp" "$views"
  done
  jq '{views: .}' "$views" | stamp >"$RES/db_amplification.json"
  echo "wrote $RES/db_amplification.json" >&2
fi

# ---- 2: memory ------------------------------------------------------------------------------
if has_step memory; then
  mem="$WORK_DIR/memory.json"
  echo '[]' >"$mem"
  oblique="$(camera_of oblique)"
  overview="$(camera_of overview)"
  for n in $SIZES; do
    db="$(db_of "$n")"
    # 1 px views (minimal and reduced); on databases of at most FINEST_MAX_SIZE^2 samples also the
    # whole finest mesh (g = 1 everywhere: an output as large as the database).
    runs=("minimal oblique" "reduced oblique" "minimal overview" "reduced overview")
    if ((n <= FINEST_MAX_SIZE)); then runs+=("minimal finest"); fi
    for run in "${runs[@]}"; do
      read -r alg what <<<"$run"
      case "$what" in
        oblique) rcf=($oblique --pixel-error 1) ;;
        overview) rcf=($overview --pixel-error 1) ;;
        *) rcf=(--floor 1) ;;
      esac
      out="$WORK_DIR/mem_${n}_${alg}_$what.ply"
      /usr/bin/time -v -o "$WORK_DIR/mem.time" "$smrdb" extract "$db" "${rcf[@]}" \
        --algorithm "$alg" --cache-mb "$CACHE_MB" -o "$out" --json -q >"$WORK_DIR/mem_run.json"
      kb="$(awk -F': ' '/Maximum resident set size/ { print $2 }' "$WORK_DIR/mem.time")"
      secs="$(awk -F': ' '/Elapsed \(wall clock\)/ { print $2 }' "$WORK_DIR/mem.time")"
      bytes="$(stat -c %s "$out")"
      jq --argjson n "$n" --arg alg "$alg" --arg what "$what" --argjson kb "$kb" --arg wall "$secs" \
         --argjson bytes "$bytes" --argjson cache "$CACHE_MB" "$OUTPUT_MEMORY_JQ"'
         {size: $n, algorithm: $alg, rcf: $what, peak_rss_mb: ($kb / 1024), wall: $wall,
          output_file_bytes: $bytes, output: .output, extraction: .extraction, io: .io,
          output_memory_mb: output_memory_mb}
         | . + {budget_mb: ($cache + 32 + .output_memory_mb)}
         | . + {target_met: (.peak_rss_mb <= .budget_mb)}' "$WORK_DIR/mem_run.json" >"$WORK_DIR/mem_row.json"
      jq --slurpfile r "$WORK_DIR/mem_row.json" '. + $r' "$mem" >"$mem.tmp" && mv "$mem.tmp" "$mem"
      rm -f "$out"
      jq -r '"  \(.size)^2 \(.algorithm) \(.rcf): peak RSS \(.peak_rss_mb | round) MiB, output \(.output.triangles) triangles (\(.output_memory_mb * 10 | round / 10) MiB in memory), budget \(.budget_mb | round) MiB"' \
        "$WORK_DIR/mem_row.json" >&2
    done
  done
  jq --slurpfile d "$dbs_json" '{databases: $d[0], runs: .}' "$mem" | stamp >"$RES/db_memory.json"
  echo "wrote $RES/db_memory.json" >&2
fi

# ---- 3: cost vs size ------------------------------------------------------------------------
if has_step scaling; then
  sc="$WORK_DIR/scaling.json"
  echo '[]' >"$sc"
  for view in oblique overview; do
    cam="$(camera_of "$view")"
    for n in $SIZES; do
      # shellcheck disable=SC2086
      "$bench_db" extract "$(db_of "$n")" $cam --pixel-error "$PIXEL_ERRORS" --cache-mb "$CACHE_MB" \
        --repeat "$REPEAT" --no-raw >"$WORK_DIR/scale_${view}_$n.json"
      jq --arg view "$view" --argjson n "$n" '. + {view: $view, size: $n}' \
        "$WORK_DIR/scale_${view}_$n.json" >"$WORK_DIR/scale_row.json"
      jq --slurpfile r "$WORK_DIR/scale_row.json" '. + $r' "$sc" >"$sc.tmp" && mv "$sc.tmp" "$sc"
    done
  done
  jq --slurpfile d "$dbs_json" '{databases: $d[0], runs: .}' "$sc" | stamp >"$RES/db_scaling.json"
  echo "wrote $RES/db_scaling.json" >&2
fi

# ---- 5: codecs on real pages ----------------------------------------------------------------
if has_step codecs; then
  cod="$WORK_DIR/codecs.json"
  echo '[]' >"$cod"
  "$bench_db" codecs "$root/data/jacksboro_fault_dem.npz" --max-error-fraction 0.005 \
    --name jacksboro --work-dir "$WORK_DIR" >"$WORK_DIR/codecs_jacksboro.json"
  "$bench_db" codecs --fbm 4097 --max-error 1.6 --name fbm4097 --work-dir "$WORK_DIR" \
    >"$WORK_DIR/codecs_fbm4097.json"
  jq -s '{datasets: .}' "$WORK_DIR/codecs_jacksboro.json" "$WORK_DIR/codecs_fbm4097.json" |
    stamp >"$RES/db_codecs.json"
  echo "wrote $RES/db_codecs.json" >&2
fi
