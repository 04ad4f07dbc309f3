#!/usr/bin/env bash
# Extraction throughput against @mapbox/martini's getMesh on the same DEM (issue 34's targets):
#   1. for each SIZE in SIZES, a deterministic SIZE^2 fBm (smrdb synth, seed SEED, range RANGE,
#      spacing 1) as .npy, ingested with `smrdb ingest --max-error` at MAX_ERROR_FRACTION of the
#      range (0.1 %: 1.6 m); the database's size and bytes per vertex (`smrdb info --json`);
#   2. REPEAT rounds, interleaved: martini (peers/run_peer.mjs --repeat INNER: createTile once,
#      getMesh INNER times in one process; the calls after the first are the warm ones) and
#      bench_extract_speed (--repeat INNER: full resolution `--floor 1` and a 1 px oblique view,
#      minimal, minimal-pages, reduced and, for --floor 1, the level cut that `smrdb extract
#      --floor` takes (smr/query/level_cut.h), each on a freshly opened database with the file in the OS page cache
#      (warm) and again on the same database (hot), in memory and with a binary PLY written);
#   3. memory: peak RSS (/usr/bin/time) of `smrdb extract --floor 1 --cache-mb MEMORY_CACHE_MB -o
#      x.ply` against the budget N + output + 32 MiB, and the pages the cache holds per MiB;
#   4. benchmarks/results/extract_vs_martini.json: per size, ours and martini's triangles/s (medians
#      over every warm run of every round) and their ratios, with nproc, CPU model, load average,
#      commit and date.
# Martini's getMesh reads a precomputed error map (createTile, once per tile: our ingest) and gives
# 2-D uint16 vertices without heights and no error guarantee; ours gives x, y, z doubles and every
# triangle within the bound. The comparison is output triangles per second, as issue 34 sets it.
#
# Environment: BUILD_DIR (default build/release), WORK_DIR (default $BUILD_DIR/bench-martini),
# SIZES ("4097 8193"), SEED (1), RANGE (1600), MAX_ERROR_FRACTION (0.001), REPEAT (3 rounds),
# INNER (3 runs per program per round), CACHE_MB (4096: bench_extract_speed's decoded-page cache,
# large enough for the hot runs to find every page), MEMORY_CACHE_MB (64), CASES ("full,oblique"),
# OUT (results file). Databases and DEMs in WORK_DIR are reused when present.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/.." && pwd)"
# shellcheck source=lib.sh
source "$here/lib.sh"
BUILD_DIR="${BUILD_DIR:-$root/build/release}"
WORK_DIR="${WORK_DIR:-$BUILD_DIR/bench-martini}"
SIZES="${SIZES:-4097 8193}"
SEED="${SEED:-1}"
RANGE="${RANGE:-1600}"
MAX_ERROR_FRACTION="${MAX_ERROR_FRACTION:-0.001}"
REPEAT="${REPEAT:-3}"
INNER="${INNER:-3}"
CACHE_MB="${CACHE_MB:-4096}"
MEMORY_CACHE_MB="${MEMORY_CACHE_MB:-64}"
CASES="${CASES:-full,oblique}"
OUT="${OUT:-$here/results/extract_vs_martini.json}"

smrdb="$BUILD_DIR/tools/smrdb"
bench="$BUILD_DIR/benchmarks/bench_extract_speed"
require_executables "$BUILD_DIR" "$smrdb" "$bench"
require_tools
command -v node >/dev/null || { echo "node is required for martini" >&2; exit 1; }
if [[ ! -d "$here/peers/node_modules/@mapbox/martini" ]]; then
  (cd "$here/peers" && npm ci --no-audit --no-fund)
fi
mkdir -p "$WORK_DIR" "$(dirname "$OUT")"

# The fBm is normalised to min 0, max RANGE exactly, so 0.1 % of the range is RANGE * 0.001.
max_error="$(awk -v r="$RANGE" -v f="$MAX_ERROR_FRACTION" 'BEGIN { printf "%.12g", r * f }')"
loadavg_before="$(cut -d' ' -f1-3 /proc/loadavg)"

# jq: median, min and all of an array of numbers.
STATS_JQ='def med: sort | if length == 0 then null elif length % 2 == 1 then .[length / 2 | floor]
                        else (.[length / 2 - 1] + .[length / 2]) / 2 end;
          def stats: {median: med, min: min, all: .};'

# ---- 1. the DEM and its database --------------------------------------------------------------
prepare() {  # SIZE -> $WORK_DIR/fbm$n.{npy,smrdb,ingest.json,info.json}
  local n="$1" dem="$WORK_DIR/fbm$1_seed$SEED.npy" db="$WORK_DIR/fbm$1_seed${SEED}_e$max_error.smrdb"
  if [[ ! -f "$dem" ]]; then
    log "synth ${n}x$n fBm (seed $SEED, range $RANGE) -> $dem"
    "$smrdb" synth --size "$n" --seed "$SEED" --range "$RANGE" -o "$dem" -q
  fi
  if [[ ! -f "$db" || ! -f "$db.ingest.json" ]]; then
    log "ingest $dem at max error $max_error -> $db"
    /usr/bin/time -f '%e %M' -o "$db.ingest.time" \
      "$smrdb" ingest "$dem" -o "$db" --max-error "$max_error" --force --json -q >"$db.ingest.raw.json"
    read -r secs kb <"$db.ingest.time"
    jq --argjson s "$secs" --argjson kb "$kb" "$PEAK_RSS_JQ"'
       . + {ingest_seconds: $s, ingest_peak_rss_mb: peak_rss_mb($kb; .)}' \
      "$db.ingest.raw.json" >"$db.ingest.json"
  fi
  "$smrdb" info "$db" --json >"$db.info.json"
}

# ---- 2. the interleaved rounds -----------------------------------------------------------------
rounds() {  # SIZE
  local n="$1" i dem="$WORK_DIR/fbm$1_seed$SEED.npy" db="$WORK_DIR/fbm$1_seed${SEED}_e$max_error.smrdb"
  local verify
  for ((i = 1; i <= REPEAT; i++)); do
    log "$n^2 round $i/$REPEAT: martini getMesh x $INNER"
    node --max-old-space-size=12288 "$here/peers/run_peer.mjs" --peer martini --npy "$dem" \
      --max-error "$max_error" --repeat "$INNER" >"$WORK_DIR/martini_${n}_$i.json"
    log "  martini: $(jq -r '"\(.triangles) triangles, getMesh warm \(.get_mesh_warm_median) s (\(.get_mesh_triangles_per_second / 1e6 | . * 100 | round / 100) M/s)"' \
      "$WORK_DIR/martini_${n}_$i.json")"
    log "$n^2 round $i/$REPEAT: bench_extract_speed x $INNER"
    verify=()
    [[ $i -eq 1 ]] && verify=(--verify)
    "$bench" "$db" --repeat "$INNER" --cache-mb "$CACHE_MB" --cases "$CASES" \
      --ply "$WORK_DIR/ours_$n.ply" "${verify[@]}" >"$WORK_DIR/ours_${n}_$i.json"
  done
  rm -f "$WORK_DIR/ours_$n.ply"
}

# ---- 3. memory of `smrdb extract --floor 1` -----------------------------------------------------
memory() {  # SIZE -> $WORK_DIR/memory_$n.json
  local n="$1" db="$WORK_DIR/fbm$1_seed${SEED}_e$max_error.smrdb" out="$WORK_DIR/mem_$1.ply" kb
  log "$n^2 memory: smrdb extract --floor 1 --cache-mb $MEMORY_CACHE_MB"
  /usr/bin/time -v -o "$WORK_DIR/mem.time" "$smrdb" extract "$db" --floor 1 \
    --cache-mb "$MEMORY_CACHE_MB" -o "$out" --json -q >"$WORK_DIR/mem_run.json"
  kb="$(awk -F': ' '/Maximum resident set size/ { print $2 }' "$WORK_DIR/mem.time")"
  jq --argjson kb "$kb" --argjson cache "$MEMORY_CACHE_MB" --argjson bytes "$(stat -c %s "$out")" \
     --arg wall "$(awk -F': ' '/Elapsed \(wall clock\)/ { print $2 }' "$WORK_DIR/mem.time")" \
     "$OUTPUT_MEMORY_JQ"'
    {command: "smrdb extract --floor 1 --cache-mb \($cache) -o x.ply", cache_mb: $cache,
     peak_rss_mb: ($kb / 1024), wall: $wall, ply_bytes: $bytes, output: .output, io: .io,
     output_memory_mb: output_memory_mb,
     cache_pages_per_mib: (if .io.bytes_decoded > 0 then .io.pages_read * 1048576 / .io.bytes_decoded else null end)}
    | . + {budget_mb: ($cache + 32 + .output_memory_mb)} | . + {target_met: (.peak_rss_mb <= .budget_mb)}' \
    "$WORK_DIR/mem_run.json" >"$WORK_DIR/memory_$n.json"
  rm -f "$out"
  log "  peak RSS $(jq -r '"\(.peak_rss_mb | round) MiB, budget \(.budget_mb | round) MiB"' "$WORK_DIR/memory_$n.json")"
}

# ---- 4. one size's results ----------------------------------------------------------------------
collect() {  # SIZE -> $WORK_DIR/size_$n.json
  local n="$1" db="$WORK_DIR/fbm$1_seed${SEED}_e$max_error.smrdb" i martini=() ours=()
  for ((i = 1; i <= REPEAT; i++)); do
    martini+=("$WORK_DIR/martini_${n}_$i.json")
    ours+=("$WORK_DIR/ours_${n}_$i.json")
  done
  jq -s "$STATS_JQ"'
    .[0] as $f |
    {version: $f.version, node: $f.node, triangles: $f.triangles, vertices: $f.vertices,
     get_mesh_repeat_per_round: $f.get_mesh_repeat,
     get_mesh_warm_seconds: ([.[] | .get_mesh_seconds_all | if length > 1 then .[1:] else . end | .[]] | stats),
     get_mesh_first_call_seconds: ([.[].get_mesh_seconds] | stats),
     create_tile_seconds: ([.[].create_tile_seconds] | stats),
     setup_seconds: ([.[].setup_seconds] | stats),
     rss_mb: ([.[].rss_mb] | max)}
    | . + {triangles_per_second: (.triangles / .get_mesh_warm_seconds.median),
           triangles_per_second_best: (.triangles / .get_mesh_warm_seconds.min)}' \
    "${martini[@]}" >"$WORK_DIR/martini_$n.json"
  jq -s "$STATS_JQ"'
    def runs($kind; $c): {
      in_memory_seconds: ([$c[] | .[$kind].in_memory_seconds.all[]] | stats),
      with_ply_seconds: ([$c[] | .[$kind].with_ply_seconds.all[]] | stats),
      phases_median: ($c[0][$kind].phases_median | keys_unsorted
                      | map(. as $p | {($p): ([$c[] | .[$kind].phases_median[$p]] | med)}) | add),
      io_first: $c[0][$kind].io_first};
    . as $rounds |
    [$rounds[0].cases[] | {case, algorithm}] | map(. as $k |
      [$rounds[] | .cases[] | select(.case == $k.case and .algorithm == $k.algorithm)] as $c |
      $c[0] as $f |
      {case: $k.case, algorithm: $k.algorithm, rcf: $f.rcf, triangles: $f.triangles,
       mesh_vertices: $f.mesh_vertices, x: $f.x, x_plus: $f.x_plus, ply_bytes: $f.ply_bytes,
       tiling: ($f.tiling // "not checked"), warm: runs("warm"; $c), hot: runs("hot"; $c),
       hot_pages_read: $f.hot_pages_read, cache: $f.cache}
      | .warm += {triangles_per_second: (.triangles / .warm.in_memory_seconds.median),
                  triangles_per_second_best: (.triangles / .warm.in_memory_seconds.min),
                  triangles_per_second_with_ply: (.triangles / .warm.with_ply_seconds.median)}
      | .hot += {triangles_per_second: (.triangles / .hot.in_memory_seconds.median),
                 triangles_per_second_with_ply: (.triangles / .hot.with_ply_seconds.median)})
    | {cases: ., machine: $rounds[0].machine, camera: $rounds[0].camera, cache_mb: $rounds[0].cache_mb,
       repeat_per_round: $rounds[0].repeat, peak_rss_mb: ([$rounds[].peak_rss_mb] | max),
       os_cache: $rounds[0].os_cache,
       loadavg_per_round: [$rounds[] | {before: .loadavg_before, after: .loadavg_after}]}' \
    "${ours[@]}" >"$WORK_DIR/ours_$n.json"
  jq -n --argjson n "$n" --argjson seed "$SEED" --argjson range "$RANGE" --argjson max_error "$max_error" \
     --slurpfile m "$WORK_DIR/martini_$n.json" --slurpfile o "$WORK_DIR/ours_$n.json" \
     --slurpfile info "$db.info.json" --slurpfile ingest "$db.ingest.json" \
     --slurpfile mem "$WORK_DIR/memory_$n.json" '
    $m[0] as $m | $o[0] as $o | $info[0] as $i |
    def ours($c; $a): $o.cases[] | select(.case == $c and .algorithm == $a);
    def ratio($c; $a; $kind; $key): (ours($c; $a)[$kind][$key] // null) as $v
                                    | if $v == null then null else $v / $m.triangles_per_second end;
    {size: $n,
     dem: {generator: "smrdb synth --size \($n) --seed \($seed) --range \($range)", samples: ($n * $n)},
     max_error: $max_error,
     database: {file_bytes: $i.file_bytes, vertices: $i.meta.model.vertex_count,
                bytes_per_vertex: ($i.file_bytes / $i.meta.model.vertex_count),
                page_bytes: $i.meta.bytes.pages, pages: $i.meta.counts.pages, ops: $i.meta.counts.ops,
                format_version: $i.meta.version, codec: $i.meta.codec,
                ingest_seconds: $ingest[0].ingest_seconds, ingest_peak_rss_mb: $ingest[0].ingest_peak_rss_mb},
     martini: $m,
     ours: $o,
     memory: $mem[0],
     ratios: {
       note: "full_*: ours triangles/s over martini getMesh warm triangles/s; seconds_*: ours seconds over martini getMesh warm seconds (medians over every run of every round)",
       full_minimal_warm: ratio("full"; "minimal"; "warm"; "triangles_per_second"),
       full_minimal_warm_with_ply: ratio("full"; "minimal"; "warm"; "triangles_per_second_with_ply"),
       full_minimal_hot: ratio("full"; "minimal"; "hot"; "triangles_per_second"),
       full_minimal_pages_warm: ratio("full"; "minimal-pages"; "warm"; "triangles_per_second"),
       full_minimal_pages_warm_with_ply:
         ratio("full"; "minimal-pages"; "warm"; "triangles_per_second_with_ply"),
       full_minimal_pages_hot: ratio("full"; "minimal-pages"; "hot"; "triangles_per_second"),
       full_level_cut_warm: ratio("full"; "level-cut"; "warm"; "triangles_per_second"),
       full_level_cut_warm_with_ply: ratio("full"; "level-cut"; "warm"; "triangles_per_second_with_ply"),
       full_level_cut_hot: ratio("full"; "level-cut"; "hot"; "triangles_per_second"),
       full_reduced_warm: ratio("full"; "reduced"; "warm"; "triangles_per_second"),
       full_reduced_warm_with_ply: ratio("full"; "reduced"; "warm"; "triangles_per_second_with_ply"),
       full_reduced_hot: ratio("full"; "reduced"; "hot"; "triangles_per_second"),
       seconds_full_minimal_warm_over_martini:
         ((ours("full"; "minimal").warm.in_memory_seconds.median // null) as $v
          | if $v == null then null else $v / $m.get_mesh_warm_seconds.median end),
       full_minimal_warm_best_over_martini_best:
         ((ours("full"; "minimal").warm.triangles_per_second_best // null) as $v
          | if $v == null then null else $v / $m.triangles_per_second_best end),
       triangles_ours_over_martini: ((ours("full"; "minimal").triangles // null) as $t
                                     | if $t == null then null else $t / $m.triangles end)},
     targets: {
       full_note: "smrdb extract --floor 1 takes the level cut (smr/query/level_cut.h): the targets are its",
       full_warm_over_martini_min: 1,
       full_warm_met: ((ours("full"; "level-cut").warm.triangles_per_second // 0) >= $m.triangles_per_second),
       stretch_triangles_per_second: 20e6,
       stretch_met: ((ours("full"; "level-cut").warm.triangles_per_second // 0) >= 20e6),
       oblique_warm_seconds_max: 0.010,
       oblique_warm_seconds: ([ours("oblique"; "minimal"), ours("oblique"; "reduced")]
                              | map({(.algorithm): .warm.in_memory_seconds.median}) | add),
       oblique_note: "issue 34 sets the 10 ms on the 16385^2 database at 0.5 m (run_db.sh, bench_db); this is the same named camera on this fBm database",
       memory_met: $mem[0].target_met}}' >"$WORK_DIR/size_$n.json"
}

for n in $SIZES; do
  prepare "$n"
  rounds "$n"
  memory "$n"
  collect "$n"
  jq -r '"\(.size)^2: ours full/level-cut \(.ours.cases[] | select(.case == "full" and .algorithm == "level-cut") | .warm.triangles_per_second | round) tri/s, martini \(.martini.triangles_per_second | round) tri/s: ratio \(.ratios.full_level_cut_warm)"' \
    "$WORK_DIR/size_$n.json" >&2
done
loadavg_after="$(cut -d' ' -f1-3 /proc/loadavg)"

sizes_files=()
for n in $SIZES; do sizes_files+=("$WORK_DIR/size_$n.json"); done
cpu_model="$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//')"
jq -s \
  --arg nproc "$(nproc)" --arg cpu "$cpu_model" --arg kernel "$(uname -sr)" \
  --arg date "$(date -u +%Y-%m-%dT%H:%M:%SZ)" --arg la0 "$loadavg_before" --arg la1 "$loadavg_after" \
  --arg commit "$(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo unknown)" \
  --arg dirty "$(git -C "$root" status --porcelain -- smr storage tools 2>/dev/null | wc -l)" \
  --arg sizes "$SIZES" --argjson seed "$SEED" --argjson range "$RANGE" \
  --argjson fraction "$MAX_ERROR_FRACTION" --argjson max_error "$max_error" \
  --argjson repeat "$REPEAT" --argjson inner "$INNER" --argjson cache "$CACHE_MB" \
  --argjson mem_cache "$MEMORY_CACHE_MB" --arg cases "$CASES" '
  {benchmark: "extract_vs_martini",
   date: $date, commit: $commit, uncommitted_files_in_smr_storage_tools: ($dirty | tonumber),
   machine: (.[0].ours.machine + {nproc: ($nproc | tonumber), cpu_model: $cpu, kernel: $kernel,
                                 loadavg_before: $la0, loadavg_after: $la1}),
   parameters: {sizes: ($sizes | split(" ") | map(select(length > 0) | tonumber)), seed: $seed,
                range: $range, max_error_fraction: $fraction, max_error: $max_error,
                rounds: $repeat, runs_per_round: $inner, cache_mb: $cache,
                memory_cache_mb: $mem_cache, cases: $cases},
   method: ("Per size, REPEAT rounds alternate martini (one node process: createTile, then getMesh runs_per_round times; "
            + "the calls after the first are warm) and bench_extract_speed (runs_per_round fresh Database::open, "
            + "each run twice: warm = decoded-page cache empty, file in the OS page cache; hot = the same Database "
            + "again). Ours in memory = open + extract_* + to_mesh (an indexed TriangleMesh with x, y, z doubles; "
            + "level-cut: open + extract_level_cut, which makes that mesh itself); "
            + "with PLY = that + write_mesh (binary PLY). Medians over every run of every round."),
   sizes: .}' "${sizes_files[@]}" >"$OUT"
log "wrote $OUT"
jq '.sizes[] | {size, martini_tri_per_s: .martini.triangles_per_second, ratios, database: {bytes_per_vertex: .database.bytes_per_vertex}}' "$OUT"
