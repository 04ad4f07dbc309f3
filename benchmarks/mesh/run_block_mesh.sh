#!/usr/bin/env bash
# Issue 5's large mesh run (not in CI): armadillo.off (CGAL demo data, 52 000 triangles) after
# SUBDIVIDE levels of midpoint 1-to-4 subdivision (5 levels: 53.2 M triangles, 26.6 M vertices,
# a 1.3 GB binary PLY; the surface is unchanged, only the triangle count grows), ingested out of
# core with `smrdb ingest --memory $MEMORY` (default 2G): the PLY is streamed, its triangles
# sorted by octree cell on disk, blocks simplified with locked borders and merged up to the root,
# ops assembled on disk. Reports peak RSS (/usr/bin/time; also that of reading and building, and
# that of writing the database, from the report) against the budget, triangles/s, temp
# bytes, DAG height, ops and pages, then extraction on the database (bench_db's views at 1 px,
# minimal surface -- reduced extraction is 2.5-D only -- pages read and time). Writes
# benchmarks/results/block_mesh.json.
#
# Environment: BUILD_DIR (build/release), WORK_DIR ($BUILD_DIR/bench-mesh-blocks), SMRDB_DATA_DIR
# (data), SUBDIVIDE (5), MEMORY (2G), OUT.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
BUILD_DIR="${BUILD_DIR:-$root/build/release}"
WORK_DIR="${WORK_DIR:-$BUILD_DIR/bench-mesh-blocks}"
DATA_DIR="${SMRDB_DATA_DIR:-$root/data}"
SUBDIVIDE="${SUBDIVIDE:-5}"
MEMORY="${MEMORY:-2G}"
OUT="${OUT:-$root/benchmarks/results/block_mesh.json}"

smrdb="$BUILD_DIR/tools/smrdb"
bench_mesh="$BUILD_DIR/benchmarks/mesh/bench_mesh_build"
bench_db="$BUILD_DIR/benchmarks/bench_db"
# shellcheck source=../lib.sh
source "$root/benchmarks/lib.sh"
require_executables "$BUILD_DIR" "$smrdb" "$bench_mesh" "$bench_db"
require_tools
mkdir -p "$WORK_DIR" "$(dirname "$OUT")"

ply="$WORK_DIR/armadillo_sub${SUBDIVIDE}.ply"
db="$WORK_DIR/armadillo_sub${SUBDIVIDE}.smrdb"
if [[ ! -f "$ply" ]]; then
  log "generating $ply"
  "$bench_mesh" "$DATA_DIR/meshes/armadillo.off" --subdivide "$SUBDIVIDE" -o "$ply" >/dev/null
fi

log "ingest --memory $MEMORY"
/usr/bin/time -f "%M %e" -o "$WORK_DIR/ingest.time" "$smrdb" ingest "$ply" --memory "$MEMORY" \
  --tmp "$WORK_DIR" -o "$db" --force -q --json >"$WORK_DIR/ingest.json"
log "  $(cat "$WORK_DIR/ingest.time") (KiB, s)"

log "extraction"
views="[]"
for view in oblique overview; do
  r="$("$bench_db" extract "$db" --view "$view" --pixel-error 1 --cache-mb 64 --repeat 3 \
    --algorithms minimal)"
  views="$(jq --argjson r "$r" '. + [$r]' <<<"$views")"
done

jq -n --slurpfile ingest "$WORK_DIR/ingest.json" --argjson views "$views" \
  --arg time "$(cat "$WORK_DIR/ingest.time")" --arg memory "$MEMORY" \
  --argjson levels "$SUBDIVIDE" --arg date "$(date -u +%Y-%m-%dT%H:%M:%SZ)" \
  --arg commit "$(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo unknown)" \
  --arg nproc "$(nproc)" "$PEAK_RSS_JQ"'
  ($time | split(" ")) as $t | ($ingest[0]) as $i |
  {
    benchmark: "block_mesh", date: $date, commit: $commit, nproc: ($nproc | tonumber),
    mesh: {source: "armadillo.off (CGAL demo data)", subdivision_levels: $levels,
           vertices: $i.input.vertices, triangles: $i.input.triangles},
    memory: $memory,
    peak_rss_mb: peak_rss_mb($t[0] | tonumber; $i), build_peak_rss_mb: $i.build_peak_rss_mb,
    writer_finish_peak_rss_mb: $i.database.finish_peak_rss_mb, wall_seconds: ($t[1] | tonumber),
    triangles_per_second: ($i.input.triangles / ($t[1] | tonumber)),
    ingest: $i,
    extraction: $views
  }' >"$OUT"
log "wrote $OUT"
jq '{peak_rss_mb, build_peak_rss_mb, writer_finish_peak_rss_mb, wall_seconds, triangles_per_second, dag: .ingest.blocks.dag_height,
     ops: .ingest.crmr.ops, pages: .ingest.database.pages}' "$OUT"
