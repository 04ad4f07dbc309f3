#!/usr/bin/env bash
# Issue 38 item 2: does `smrdb ingest X.ply --memory M` stay within M + 64 MiB whatever the size
# of X? bunny00.off (CGAL demo data, 75 408 triangles) after LEVELS levels of midpoint 1-to-4
# subdivision (default "2 3 4": 1.21 M, 4.83 M and 19.3 M triangles, binary PLYs of 30, 121 and
# 483 MB: 0.9x, 3.6x and 14.4x a 32 MiB budget; made by `bench_mesh_build --subdivide`, the
# surface unchanged), each ingested with `--memory $MEMORY` (default 32M, the least the CLI takes).
# Per input: peak RSS (the larger of /usr/bin/time's %M and the report's peak_rss_mb: see
# lib.sh), that of reading and building (build_peak_rss_mb) and the database writer's own
# (database.finish_peak_rss_mb), the bound M + 64 MiB and whether each held, triangles/s (wall and per CPU second), temp bytes. With PEER=1 (default) CGAL
# Lindstrom-Turk simplifies the PEER_LEVEL mesh (default 3) to 10 % and 1 % of its triangles in
# memory (`bench_mesh_build --only cgal-lt`, the peer of benchmarks/mesh/run_mesh_build.sh), and
# the ingest of that mesh is timed right after it: the ratio is of the same run. Writes
# benchmarks/results/mesh_memory.json.
#
# Environment: BUILD_DIR (build/release), WORK_DIR ($BUILD_DIR/bench-mesh-memory), SMRDB_DATA_DIR
# (data), MESH (bunny00.off), LEVELS ("2 3 4"), MEMORY (32M), THREADS (0), PEER (1),
# PEER_LEVEL (3), OUT. REUSE=1 takes each level's sub$k.json and sub$k.time already in WORK_DIR
# (the ingest command below run by hand, e.g. the sizes side by side) instead of ingesting.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
BUILD_DIR="${BUILD_DIR:-$root/build/release}"
WORK_DIR="${WORK_DIR:-$BUILD_DIR/bench-mesh-memory}"
DATA_DIR="${SMRDB_DATA_DIR:-$root/data}"
MESH="${MESH:-bunny00.off}"
LEVELS="${LEVELS:-2 3 4}"
MEMORY="${MEMORY:-32M}"
THREADS="${THREADS:-0}"
PEER="${PEER:-1}"
PEER_LEVEL="${PEER_LEVEL:-3}"
REUSE="${REUSE:-0}"
OUT="${OUT:-$root/benchmarks/results/mesh_memory.json}"

smrdb="$BUILD_DIR/tools/smrdb"
bench_mesh="$BUILD_DIR/benchmarks/mesh/bench_mesh_build"
# shellcheck source=../lib.sh
source "$root/benchmarks/lib.sh"
if [[ "$REUSE" == 1 && "$PEER" != 1 ]]; then
  require_executables "$BUILD_DIR" "$smrdb"
else
  require_executables "$BUILD_DIR" "$smrdb" "$bench_mesh"
fi
require_tools
mkdir -p "$WORK_DIR" "$(dirname "$OUT")"

stem="${MESH%.*}"
ply_of() { echo "$WORK_DIR/${stem}_sub$1.ply"; }
for k in $LEVELS; do
  ply="$(ply_of "$k")"
  if [[ ! -f "$ply" && "$REUSE" != 1 ]]; then
    log "generating $ply"
    "$bench_mesh" "$DATA_DIR/meshes/$MESH" --subdivide "$k" -o "$ply" >/dev/null
  fi
done

# ingest K: one ingest of level K's PLY; its JSON line (file bytes, time, report) to stdout.
ingest() {
  local k="$1" ply db t
  ply="$(ply_of "$k")"
  db="$WORK_DIR/${stem}_sub$k.smrdb"
  t="$WORK_DIR/sub$k.time"
  if [[ "$REUSE" == 1 ]]; then
    log "reusing $WORK_DIR/sub$k.json and $t"
  else
    log "ingest $(basename "$ply") --memory $MEMORY"
    /usr/bin/time -f "%M %e %U %S" -o "$t" "$smrdb" ingest "$ply" --memory "$MEMORY" \
      --threads "$THREADS" --tmp "$WORK_DIR" -o "$db" --force -q --json >"$WORK_DIR/sub$k.json"
  fi
  log "  $(cat "$t") (KiB, s wall, s user, s sys)"
  rm -f "$db"
  jq -c -n --slurpfile r "$WORK_DIR/sub$k.json" --arg t "$(cat "$t")" --argjson level "$k" \
    --argjson bytes "$(stat -L -c %s "$ply")" '{level: $level, ply_bytes: $bytes, time: $t, report: $r[0]}'
}

runs="[]"
peer="null"
for k in $LEVELS; do
  if [[ "$PEER" == 1 && "$k" == "$PEER_LEVEL" ]]; then
    log "CGAL Lindstrom-Turk on $(basename "$(ply_of "$k")")"
    peer="$("$bench_mesh" "$(ply_of "$k")" --only cgal-lt --skip-db --repeat 1)"
  fi
  runs="$(jq --argjson r "$(ingest "$k")" '. + [$r]' <<<"$runs")"
done

jq -n --argjson runs "$runs" --argjson peer "$peer" --arg memory "$MEMORY" --arg mesh "$MESH" \
  --argjson peer_level "$PEER_LEVEL" --arg date "$(date -u +%Y-%m-%dT%H:%M:%SZ)" \
  --arg commit "$(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo unknown)" \
  --arg nproc "$(nproc)" --arg load "$(cut -d' ' -f1-3 /proc/loadavg)" "$PEAK_RSS_JQ"'
  def mib: if test("G$") then (.[:-1] | tonumber) * 1024 elif test("M$") then (.[:-1] | tonumber)
           else error("MEMORY must end in M or G") end;
  ($memory | mib) as $m |
  {
    benchmark: "mesh_memory", date: $date, commit: $commit, nproc: ($nproc | tonumber),
    load_average: $load, mesh: ($mesh + " (CGAL demo data), midpoint-subdivided"),
    memory: $memory, bound_mib: ($m + 64),
    runs: [$runs[] | (.time | split(" ") | map(tonumber)) as $t | .report as $r | {
      subdivision_levels: .level, triangles: $r.input.triangles, vertices: $r.input.vertices,
      ply_mib: (.ply_bytes / 1048576), input_over_budget: (.ply_bytes / 1048576 / $m),
      peak_rss_mib: peak_rss_mb($t[0]; $r),
      build_peak_rss_mib: $r.build_peak_rss_mb,
      writer_finish_peak_rss_mib: $r.database.finish_peak_rss_mb,
      build_within_bound: ($r.build_peak_rss_mb <= $m + 64),
      within_bound: (peak_rss_mb($t[0]; $r) <= $m + 64),
      wall_seconds: $t[1], cpu_seconds: ($t[2] + $t[3]),
      triangles_per_second: ($r.input.triangles / $t[1]),
      triangles_per_cpu_second: ($r.input.triangles / ($t[2] + $t[3])),
      leaf_blocks: $r.blocks.leaf_blocks, levels: $r.blocks.levels,
      phases_seconds: $r.blocks.seconds, temp_gb: ($r.blocks.temp_bytes / 1e9),
      ops: $r.crmr.ops, database_mb: ($r.database.file_bytes / 1e6)}],
    peer: (if $peer == null then null else {
      level: $peer_level, triangles: $peer.input.triangles,
      cgal_lt_10pct_seconds: $peer.results["cgal-lt"]["10pct"].seconds,
      cgal_lt_1pct_seconds: $peer.results["cgal-lt"]["1pct"].seconds,
      cgal_lt_1pct_cpu_seconds: $peer.results["cgal-lt"]["1pct"].cpu_seconds,
      cgal_lt_1pct_triangles_per_second:
        ($peer.input.triangles / $peer.results["cgal-lt"]["1pct"].seconds)} end)
  } | .peer_ratio = (if .peer == null then null else
      ([.runs[] | select(.subdivision_levels == $peer_level)][0].wall_seconds
       / .peer.cgal_lt_1pct_seconds) end)
  | .peer_cpu_ratio = (if .peer == null then null else
      ([.runs[] | select(.subdivision_levels == $peer_level)][0].cpu_seconds
       / .peer.cgal_lt_1pct_cpu_seconds) end)' >"$OUT"
log "wrote $OUT"
jq -c '.runs[] | {subdivision_levels, triangles, input_over_budget, peak_rss_mib, build_peak_rss_mib,
                  writer_finish_peak_rss_mib, within_bound, triangles_per_second}' "$OUT"
jq -c '{bound_mib, peer, peer_ratio, peer_cpu_ratio}' "$OUT"
