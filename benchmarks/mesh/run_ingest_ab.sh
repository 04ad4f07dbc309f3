#!/usr/bin/env bash
# Issue 38 item 2 (ingest throughput): two builds of smrdb ingest the same mesh side by side.
# armadillo.off (CGAL demo data, 52 000 triangles) after SUBDIVIDE levels of midpoint 1-to-4
# subdivision (3: 3.33 M triangles, 4: 13.3 M, 5: 53.2 M; made by `bench_mesh_build
# --subdivide`), `smrdb ingest X.ply --memory $MEMORY --threads 0`, the old build ($OLD_SMRDB) and
# this one alternating for ROUNDS rounds, so that the machine's load falls on both alike. Per run:
# wall, user and system seconds and peak RSS (/usr/bin/time and the report), the builder's phases;
# per round, whether the two databases are byte-identical (a change meant to make the build faster
# only must leave them so); medians and new / old ratios. Writes benchmarks/results/ingest_ab.json.
#
# Environment: OLD_SMRDB (required), BUILD_DIR (build/release), WORK_DIR
# ($BUILD_DIR/bench-ingest-ab), SMRDB_DATA_DIR (data), MESH (armadillo.off), SUBDIVIDE (3),
# MEMORY (2G), ROUNDS (2), OUT.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
BUILD_DIR="${BUILD_DIR:-$root/build/release}"
WORK_DIR="${WORK_DIR:-$BUILD_DIR/bench-ingest-ab}"
DATA_DIR="${SMRDB_DATA_DIR:-$root/data}"
MESH="${MESH:-armadillo.off}"
SUBDIVIDE="${SUBDIVIDE:-3}"
MEMORY="${MEMORY:-2G}"
ROUNDS="${ROUNDS:-2}"
OUT="${OUT:-$root/benchmarks/results/ingest_ab.json}"
: "${OLD_SMRDB:?set OLD_SMRDB to the smrdb of the build to compare with}"

smrdb="$BUILD_DIR/tools/smrdb"
bench_mesh="$BUILD_DIR/benchmarks/mesh/bench_mesh_build"
# shellcheck source=../lib.sh
source "$root/benchmarks/lib.sh"
require_executables "$BUILD_DIR" "$smrdb" "$bench_mesh"
require_tools
[[ -x "$OLD_SMRDB" ]] || { log "OLD_SMRDB=$OLD_SMRDB is not an executable"; exit 1; }
mkdir -p "$WORK_DIR" "$(dirname "$OUT")"

ply="$WORK_DIR/${MESH%.*}_sub${SUBDIVIDE}.ply"
if [[ ! -f "$ply" ]]; then
  log "generating $ply"
  "$bench_mesh" "$DATA_DIR/meshes/$MESH" --subdivide "$SUBDIVIDE" -o "$ply" >/dev/null
fi

# run NAME BINARY ROUND: one ingest; its JSON line to stdout, its database left as NAME.smrdb.
run() {
  local name="$1" bin="$2" round="$3" t="$WORK_DIR/$1.time" j="$WORK_DIR/$1.json"
  log "round $round: $name ingest $(basename "$ply") --memory $MEMORY"
  /usr/bin/time -f "%M %e %U %S" -o "$t" "$bin" ingest "$ply" --memory "$MEMORY" --threads 0 \
    --tmp "$WORK_DIR" -o "$WORK_DIR/$name.smrdb" --force -q --json >"$j"
  log "  $(cat "$t") (KiB, s wall, s user, s sys)"
  read -r kib wall user sys <"$t"
  jq -c -n --slurpfile r "$j" --arg name "$name" --argjson round "$round" --argjson kib "$kib" \
    --argjson wall "$wall" --argjson user "$user" --argjson sys "$sys" "$PEAK_RSS_JQ"'
    {build: $name, round: $round, wall_seconds: $wall, user_seconds: $user, sys_seconds: $sys,
     peak_rss_mib: peak_rss_mb($kib; $r[0]), phases_seconds: $r[0].blocks.seconds,
     database_bytes: $r[0].database.file_bytes}'
}

runs="[]"
identical="[]"
for ((round = 1; round <= ROUNDS; ++round)); do
  # The order alternates too: the first run of a round meets a cold page cache for the PLY.
  if ((round % 2)); then order="old new"; else order="new old"; fi
  for name in $order; do
    bin="$smrdb"
    [[ "$name" == old ]] && bin="$OLD_SMRDB"
    runs="$(jq -c --argjson r "$(run "$name" "$bin" "$round")" '. + [$r]' <<<"$runs")"
  done
  same=false
  cmp -s "$WORK_DIR/old.smrdb" "$WORK_DIR/new.smrdb" && same=true
  log "  databases byte-identical: $same"
  identical="$(jq -c --argjson s "$same" '. + [$s]' <<<"$identical")"
done
rm -f "$WORK_DIR/old.smrdb" "$WORK_DIR/new.smrdb"

triangles="$(jq -r '.input.triangles' "$WORK_DIR/new.json")"
jq -n --argjson runs "$runs" --argjson identical "$identical" --argjson tri "$triangles" \
  --arg mesh "$MESH" --argjson sub "$SUBDIVIDE" --arg memory "$MEMORY" --arg old "$OLD_SMRDB" \
  --arg commit "$(git -C "$root" rev-parse --short HEAD)" --arg date "$(date -u +%FT%TZ)" \
  --argjson nproc "$(nproc)" '
  def median: sort | if length % 2 == 1 then .[length / 2 | floor]
                     else (.[length / 2 - 1] + .[length / 2]) / 2 end;
  def of(b; f): [$runs[] | select(.build == b) | f] | median;
  {benchmark: "ingest_ab", date: $date, commit: $commit, nproc: $nproc, old_smrdb: $old,
   mesh: {source: ($mesh + " (CGAL demo data)"), subdivision_levels: $sub, triangles: $tri},
   memory: $memory, databases_identical: $identical, runs: $runs,
   median: ([("old", "new") as $b | {key: $b, value: {
     wall_seconds: of($b; .wall_seconds), cpu_seconds: of($b; .user_seconds + .sys_seconds),
     peak_rss_mib: of($b; .peak_rss_mib), blocks_seconds: of($b; .phases_seconds.blocks),
     triangles_per_second: ($tri / of($b; .wall_seconds)),
     triangles_per_cpu_second: ($tri / of($b; .user_seconds + .sys_seconds))}}] | from_entries),
   new_over_old: {wall: (of("new"; .wall_seconds) / of("old"; .wall_seconds)),
                  cpu: (of("new"; .user_seconds + .sys_seconds) /
                        of("old"; .user_seconds + .sys_seconds))}}' >"$OUT"
log "wrote $OUT"
jq -c '{median, new_over_old, databases_identical}' "$OUT"
