#!/usr/bin/env bash
# Data pages cut by their encoded size against pages cut by the estimate (issue 34, size target):
# OLD_SMRDB (a build of the estimate-cut writer) and this build's smrdb ingest the same inputs,
# interleaved, REPEAT rounds:
#   1. each input: the 4097² fBm (smrdb synth, seed 1, range 1600, max error 1.6 m = 0.1 % of the
#      range) and CGAL meshes (MESHES, default bunny00 and armadillo) from data/meshes;
#   2. per database: ingest wall and CPU time (/usr/bin/time, medians over the rounds), file bytes
#      and bytes per model vertex (`smrdb info --json`), the pages table's values (count, mean
#      bytes) and the 4-KiB LMDB pages they take (`mdb_stat -a`, lmdb-utils: overflow + leaf +
#      branch pages);
#   3. extraction: this build's bench_extract_speed (full resolution, minimal-pages, REPEAT_EXTRACT
#      fresh databases, CACHE_MB cache) on both databases in turn, REPEAT rounds; warm and hot
#      medians over every run;
#   4. benchmarks/results/page_fill.json: the figures, new/old ratios, nproc, load, commit, date.
# Environment: OLD_SMRDB (required), BUILD_DIR (build/release), WORK_DIR ($BUILD_DIR/bench-page-fill),
# REPEAT (3), REPEAT_EXTRACT (3), CACHE_MB (4096), MESHES ("bunny00.off armadillo.off"), OUT.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/.." && pwd)"
# shellcheck source=lib.sh
source "$here/lib.sh"
BUILD_DIR="${BUILD_DIR:-$root/build/release}"
WORK_DIR="${WORK_DIR:-$BUILD_DIR/bench-page-fill}"
REPEAT="${REPEAT:-3}"
REPEAT_EXTRACT="${REPEAT_EXTRACT:-3}"
CACHE_MB="${CACHE_MB:-4096}"
MESHES="${MESHES:-bunny00.off armadillo.off}"
OUT="${OUT:-$here/results/page_fill.json}"
: "${OLD_SMRDB:?set OLD_SMRDB to an smrdb built from the estimate-cut writer}"
smrdb="$BUILD_DIR/tools/smrdb"
bench="$BUILD_DIR/benchmarks/bench_extract_speed"
require_executables "$BUILD_DIR" "$smrdb" "$bench" "$OLD_SMRDB"
require_tools
command -v mdb_stat >/dev/null || { echo "mdb_stat (lmdb-utils) is required" >&2; exit 1; }
mkdir -p "$WORK_DIR"
loadavg_before="$(cut -d' ' -f1-3 /proc/loadavg)"

dem="$WORK_DIR/fbm4097_seed1.npy"
if [[ ! -f "$dem" ]]; then
  log "synth 4097x4097 fBm -> $dem"
  "$smrdb" synth --size 4097 --seed 1 --range 1600 -o "$dem" -q
fi
inputs=("fbm4097:$dem:--max-error 1.6")
for m in $MESHES; do inputs+=("${m%.*}:$root/data/meshes/$m:"); done

# lmdb_pages DB: {values, lmdb_pages} of the pages table.
lmdb_pages() {
  mdb_stat -a -n "$1" | awk '
    /^Status of / { t = $3 }
    t == "pages" && /Entries:/ { e = $2 }
    t == "pages" && /(Branch|Leaf|Overflow) pages:/ { p += $3 }
    END { printf "{\"values\": %d, \"lmdb_pages\": %d}\n", e, p }'
}

rows=()
for spec in "${inputs[@]}"; do
  IFS=: read -r name input args <<<"$spec"
  : >"$WORK_DIR/$name.old.walls"
  : >"$WORK_DIR/$name.new.walls"
  : >"$WORK_DIR/$name.old.cpus"
  : >"$WORK_DIR/$name.new.cpus"
  rm -f "$WORK_DIR/$name".*.extract.*.json
  for round in $(seq "$REPEAT"); do
    for side in old new; do
      exe="$smrdb"
      [[ $side == old ]] && exe="$OLD_SMRDB"
      db="$WORK_DIR/$name.$side.smrdb"
      log "round $round: $side ingest $name"
      # shellcheck disable=SC2086
      /usr/bin/time -f '%e %U %S' -o "$WORK_DIR/time.txt" \
        "$exe" ingest "$input" $args -o "$db" --force -q --json >"$WORK_DIR/$name.$side.ingest.json"
      read -r wall user sys <"$WORK_DIR/time.txt"
      echo "$wall" >>"$WORK_DIR/$name.$side.walls"
      echo "$user + $sys" | bc >>"$WORK_DIR/$name.$side.cpus"
    done
  done
  # Extraction, interleaved: REPEAT rounds of bench_extract_speed on each database in turn.
  for round in $(seq "$REPEAT"); do
    for side in old new; do
      log "round $round: extract $name ($side database)"
      "$bench" "$WORK_DIR/$name.$side.smrdb" --cases full --algorithms minimal-pages \
        --repeat "$REPEAT_EXTRACT" --cache-mb "$CACHE_MB" >"$WORK_DIR/$name.$side.extract.$round.json"
    done
  done
  for side in old new; do
    db="$WORK_DIR/$name.$side.smrdb"
    "$smrdb" info "$db" --json >"$WORK_DIR/$name.$side.info.json"
    lmdb_pages "$db" >"$WORK_DIR/$name.$side.lmdb.json"
    jq -s '{warm: [.[].cases[0].warm.in_memory_seconds.all[]],
            hot: [.[].cases[0].hot.in_memory_seconds.all[]], triangles: .[0].cases[0].triangles}' \
      "$WORK_DIR/$name.$side".extract.*.json >"$WORK_DIR/$name.$side.extract.json"
    jq -n --arg side "$side" \
      --slurpfile walls <(jq -s '.' "$WORK_DIR/$name.$side.walls") \
      --slurpfile cpus <(jq -s '.' "$WORK_DIR/$name.$side.cpus") \
      --slurpfile ingest "$WORK_DIR/$name.$side.ingest.json" \
      --slurpfile info "$WORK_DIR/$name.$side.info.json" \
      --slurpfile lmdb "$WORK_DIR/$name.$side.lmdb.json" \
      --slurpfile ex "$WORK_DIR/$name.$side.extract.json" '
      def median: sort | if length == 0 then null else .[(length - 1) / 2 | floor] end;
      ($ingest[0].database) as $d |
      {side: $side, ingest_wall_seconds: ($walls[0] | median), ingest_walls: $walls[0],
       ingest_cpu_seconds: ($cpus[0] | median), ingest_cpus: $cpus[0],
       write_tables_seconds: $d.write_phases_seconds.tables,
       file_bytes: $info[0].file_bytes, bytes_per_vertex: $info[0].bytes_per_vertex,
       pages: $d.pages, page_bytes: $d.page_bytes, mean_value_bytes: ($d.page_bytes / $d.pages),
       pages_table_lmdb_pages: $lmdb[0].lmdb_pages,
       lmdb_pages_per_value: ($lmdb[0].lmdb_pages / $lmdb[0].values),
       extract_warm_seconds: ($ex[0].warm | median), extract_warm_all: $ex[0].warm,
       extract_hot_seconds: ($ex[0].hot | median), extract_hot_all: $ex[0].hot,
       triangles: $ex[0].triangles}' \
      >"$WORK_DIR/$name.$side.row.json"
  done
  rows+=("$(jq -n --arg name "$name" --arg input "$input" --arg args "$args" \
    --slurpfile old "$WORK_DIR/$name.old.row.json" --slurpfile new "$WORK_DIR/$name.new.row.json" '
    {name: $name, input: $input, ingest_args: $args, old: $old[0], new: $new[0],
     ratios: {ingest_wall: ($new[0].ingest_wall_seconds / $old[0].ingest_wall_seconds),
              ingest_cpu: ($new[0].ingest_cpu_seconds / $old[0].ingest_cpu_seconds),
              file_bytes: ($new[0].file_bytes / $old[0].file_bytes),
              pages_table_lmdb_pages: ($new[0].pages_table_lmdb_pages / $old[0].pages_table_lmdb_pages),
              extract_warm: ($new[0].extract_warm_seconds / $old[0].extract_warm_seconds),
              extract_hot: ($new[0].extract_hot_seconds / $old[0].extract_hot_seconds)}}')")
done

loadavg_after="$(cut -d' ' -f1-3 /proc/loadavg)"
printf '%s\n' "${rows[@]}" | jq -s --arg nproc "$(nproc)" --arg la0 "$loadavg_before" \
  --arg la1 "$loadavg_after" --arg commit "$(git -C "$root" rev-parse --short HEAD)" \
  --arg date "$(date -u +%Y-%m-%dT%H:%M:%SZ)" --arg repeat "$REPEAT" '
  {benchmark: "page_fill", commit: $commit, date: $date, rounds: ($repeat | tonumber),
   machine: {nproc: ($nproc | tonumber), loadavg_before: $la0, loadavg_after: $la1},
   inputs: .}' >"$OUT"
log "wrote $OUT"
jq -r '.inputs[] | "\(.name): B/vertex \(.old.bytes_per_vertex | floor) -> \(.new.bytes_per_vertex | floor), LMDB pages x\(.ratios.pages_table_lmdb_pages), ingest wall x\(.ratios.ingest_wall) cpu x\(.ratios.ingest_cpu), extract warm x\(.ratios.extract_warm) hot x\(.ratios.extract_hot)"' "$OUT"
