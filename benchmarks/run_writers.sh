#!/usr/bin/env bash
# The mesh writers (bench_writers: binary PLY, ASCII PLY, OBJ of bunny00 subdivided 3 times,
# 4.83 M triangles) on a disk file system (DISK_DIR, default the temp directory) and on tmpfs
# (TMPFS_DIR, default /dev/shm), ROUNDS times each (default 3), alternating with an earlier build's
# bench_writers when BEFORE names one (e.g. main's writer built the same way: see README.md), so
# that both see the same load. Writes benchmarks/results/writers.json: every run, and per file
# system and build the median of each format's per-run medians.
#
# Environment: BUILD_DIR (default build/release), BEFORE, ROUNDS, REPEAT (rounds inside a run,
# default 5), DISK_DIR, TMPFS_DIR, OUT.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/.." && pwd)"
source "$here/lib.sh"
BUILD_DIR="${BUILD_DIR:-$root/build/release}"
OUT="${OUT:-$here/results/writers.json}"
ROUNDS="${ROUNDS:-3}"
REPEAT="${REPEAT:-5}"
DISK_DIR="${DISK_DIR:-${TMPDIR:-/tmp}}"
TMPFS_DIR="${TMPFS_DIR:-/dev/shm}"
after="$BUILD_DIR/benchmarks/bench_writers"
require_executables "$BUILD_DIR" "$after" ${BEFORE:+"$BEFORE"}
command -v jq >/dev/null || { echo "jq is required to assemble the results" >&2; exit 1; }
mesh="$root/data/meshes/bunny00.off"
[[ -f "$mesh" ]] || { echo "missing $mesh: run scripts/fetch-data.sh" >&2; exit 1; }
mkdir -p "$(dirname "$OUT")"

work="$(mktemp -d "${TMPDIR:-/tmp}/smrdb-run-writers.XXXXXX")"
trap 'rm -rf "$work"' EXIT
load_before="$(cut -d' ' -f1-3 /proc/loadavg)"
for round in $(seq 1 "$ROUNDS"); do
  for fs in disk tmpfs; do
    dir="$DISK_DIR"
    [[ $fs == tmpfs ]] && dir="$TMPFS_DIR"
    for build in ${BEFORE:+before} after; do
      exe="$after"
      [[ $build == before ]] && exe="$BEFORE"
      log "round $round: $build on $fs ($dir)"
      "$exe" "$mesh" --repeat "$REPEAT" --dir "$dir" >"$work/$build.$fs.$round.json"
    done
  done
done

jq -s --arg date "$(date -u +%Y-%m-%dT%H:%M:%SZ)" \
   --arg commit "$(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo unknown)" \
   --arg loadavg_before "$load_before" --arg loadavg_after "$(cut -d' ' -f1-3 /proc/loadavg)" \
   --arg before "${BEFORE:-}" '
  def median: sort | if length % 2 == 1 then .[length / 2 | floor]
                     else (.[length / 2 - 1] + .[length / 2]) / 2 end;
  (map(.results | keys) | add | unique) as $formats
  | {benchmark: "mesh_writers", date: $date, commit: $commit, before_executable: $before,
     loadavg_before: $loadavg_before, loadavg_after: $loadavg_after,
     machine: .[0].machine, input: .[0].input,
     summary: (group_by([.build, .fs]) | map({
       build: .[0].build, fs: .[0].fs, tmpfs: .[0].file_system.tmpfs, runs: length,
       formats: ([$formats[] as $f | [.[].results[$f] | select(. != null)] as $r
                  | select($r | length > 0)
                  | {key: $f, value: {seconds: ($r | map(.seconds) | median),
                                      mb_per_s: ($r | map(.mb_per_s) | median),
                                      triangles_per_s: ($r | map(.triangles_per_s) | if any(. == null) then null else median end),
                                      bytes: $r[0].bytes, fnv1a64: $r[0].fnv1a64}}]
                 | from_entries)})),
     runs: .}' \
   $(for f in "$work"/*.json; do
       b="$(basename "$f" .json)"
       jq --arg build "${b%%.*}" --arg fs "$(echo "$b" | cut -d. -f2)" '. + {build: $build, fs: $fs}' "$f" >"$f.tagged"
       echo "$f.tagged"
     done) >"$OUT"
log "wrote $OUT"
jq -r '.summary[] | "\(.build) \(.fs): " + ([.formats | to_entries[] |
  "\(.key) \(.value.mb_per_s | round) MB/s" + (if .value.triangles_per_s then " \((.value.triangles_per_s / 1e5 | round) / 10) Mtri/s" else "" end)] | join("; "))' "$OUT"
