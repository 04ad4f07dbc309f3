#!/usr/bin/env bash
# Issue 5's "extraction cost flat in dataset size" for meshes (not in CI): armadillo.off (CGAL
# demo data, 52 000 triangles) after 0..4 levels of midpoint 1-to-4 subdivision (the surface is
# the same, only the triangle count grows: 52 k, 208 k, 832 k, 3.3 M, 13.3 M triangles), each
# ingested out of core (`smrdb ingest --memory $MEMORY`: the block builder), then the same
# cameras and pixel tolerances on every database (bench_db extract, minimal surface, through a
# $CACHE_MB MiB cache): output triangles, pages needed / touched / read, warm time and peak RSS.
# Writes benchmarks/results/mesh_extract_scaling.json.
#
# Environment: BUILD_DIR (build/release), WORK_DIR ($BUILD_DIR/bench-mesh-scaling), SMRDB_DATA_DIR
# (data), LEVELS ("0 1 2 3 4"), MEMORY (2G), CACHE_MB (64), PIXEL_ERRORS ("1,4,16"), OUT.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
BUILD_DIR="${BUILD_DIR:-$root/build/release}"
WORK_DIR="${WORK_DIR:-$BUILD_DIR/bench-mesh-scaling}"
DATA_DIR="${SMRDB_DATA_DIR:-$root/data}"
LEVELS="${LEVELS:-0 1 2 3 4}"
MEMORY="${MEMORY:-2G}"
CACHE_MB="${CACHE_MB:-64}"
PIXEL_ERRORS="${PIXEL_ERRORS:-1,4,16}"
OUT="${OUT:-$root/benchmarks/results/mesh_extract_scaling.json}"

smrdb="$BUILD_DIR/tools/smrdb"
bench_mesh="$BUILD_DIR/benchmarks/mesh/bench_mesh_build"
bench_db="$BUILD_DIR/benchmarks/bench_db"
# shellcheck source=../lib.sh
source "$root/benchmarks/lib.sh"
require_executables "$BUILD_DIR" "$smrdb" "$bench_mesh" "$bench_db"
require_tools
mkdir -p "$WORK_DIR" "$(dirname "$OUT")"

rows="[]"
for level in $LEVELS; do
  ply="$WORK_DIR/armadillo_sub${level}.ply"
  db="$WORK_DIR/armadillo_sub${level}.smrdb"
  if [[ ! -f "$ply" ]]; then
    log "generating $ply"
    "$bench_mesh" "$DATA_DIR/meshes/armadillo.off" --subdivide "$level" -o "$ply" >/dev/null
  fi
  if [[ ! -f "$db" ]]; then
    log "ingest level $level --memory $MEMORY"
    /usr/bin/time -f "%M %e" -o "$WORK_DIR/ingest$level.time" "$smrdb" ingest "$ply" \
      --memory "$MEMORY" --tmp "$WORK_DIR" -o "$db" --force -q --json >"$WORK_DIR/ingest$level.json"
  fi
  for view in oblique overview; do
    log "level $level: $view at $PIXEL_ERRORS px"
    r="$("$bench_db" extract "$db" --view "$view" --pixel-error "$PIXEL_ERRORS" \
      --cache-mb "$CACHE_MB" --repeat 3 --algorithms minimal)"
    rows="$(jq --argjson r "$r" --argjson level "$level" \
      --slurpfile ingest "$WORK_DIR/ingest$level.json" '. + [{
        subdivision_levels: $level,
        source_triangles: $ingest[0].input.triangles,
        db_pages: $r.db.pages, db_ops: $r.db.ops,
        view: $r.view, peak_rss_mb: $r.peak_rss_mb,
        cases: [$r.cases[] | {
          pixel_error, output_triangles: .output.triangles, x: .output.x,
          held_ops_peak: .output.held_ops_peak, held_bytes_peak: .output.held_bytes_peak,
          pages_needed: .pages.needed, pages_touched: .pages.touched, pages_read: .pages.read,
          read_over_touched: (.pages.read / (.pages.touched | if . == 0 then 1 else . end)),
          warm_seconds: .seconds.warm_extract, to_mesh_seconds: .seconds.to_mesh,
          cold_seconds: .seconds.cold_extract,
          microseconds_per_output_triangle:
            (1e6 * (.seconds.warm_extract + .seconds.to_mesh) / .output.triangles)}]}]' \
      <<<"$rows")"
  done
done

jq -n --argjson rows "$rows" --arg memory "$MEMORY" --argjson cache "$CACHE_MB" \
  --arg date "$(date -u +%Y-%m-%dT%H:%M:%SZ)" \
  --arg commit "$(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo unknown)" \
  --arg nproc "$(nproc)" '{
    benchmark: "mesh_extract_scaling", date: $date, commit: $commit, nproc: ($nproc | tonumber),
    source: "armadillo.off (CGAL demo data), midpoint-subdivided", ingest_memory: $memory,
    cache_mb: $cache, runs: $rows}' >"$OUT"
log "wrote $OUT"
jq -r '.runs[] | .subdivision_levels as $l | .view as $v | .cases[] |
  "level \($l) \($v) \(.pixel_error)px: \(.output_triangles) tris, pages touched \(.pages_touched) read \(.pages_read), \(.warm_seconds) s"' "$OUT"
