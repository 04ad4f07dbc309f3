#!/usr/bin/env bash
# Issue 34 (size target, and that a smaller format reads no slower): two builds of smrdb write the
# same inputs and read them back side by side.
#   1. sizes: each build ingests the fBm of each size in SIZES (smrdb synth, seed 1, range 1600)
#      at MAX_ERROR (0.1 % of the range: 1.6 m; BIG_SIZE at BIG_ERROR) and each CGAL demo mesh in
#      MESHES; per database the file's bytes, bytes per model vertex, pages and R-tree nodes
#      (`smrdb info --json`) and the LMDB pages of each table (mdb_stat, when installed);
#   2. reads, ROUNDS rounds alternating the builds (each its own bench_extract_speed on its own
#      databases, the file in the OS page cache first): the 1 px oblique view on the BIG_SIZE
#      database (`--cases oblique --algorithms minimal-pages --repeat 30 --cache-mb 64`, the
#      issue's warm <= 10 ms) and full resolution on the first of SIZES (`--cases full
#      --algorithms minimal-pages --repeat 3 --cache-mb 4096`); warm and hot medians, pages and
#      bytes read, the load average;
#   3. OUT (JSON): everything above, per-case medians over the rounds and new / old ratios.
#
# Environment: OLD_BUILD_DIR (required: a build of the commit to compare with, with tools/smrdb
# and benchmarks/bench_extract_speed; the JSON names it), BUILD_DIR (build/release), WORK_DIR
# ($BUILD_DIR/bench-size-ab; inputs are reused, databases while the smrdb that wrote them is the
# same binary), SMRDB_DATA_DIR
# (data), SIZES ("4097"), MAX_ERROR (1.6), BIG_SIZE (16385; empty: no oblique case), BIG_ERROR
# (0.5), MESHES ("armadillo.off bunny00.off ChineseDragon-10kv.off"), ROUNDS (6), OUT
# (benchmarks/results/db_size_ab.json), OLD_INGEST_ARGS and NEW_INGEST_ARGS (more `smrdb ingest`
# options for each side, e.g. NEW_INGEST_ARGS="--page-kb 12" with OLD_BUILD_DIR = BUILD_DIR to
# compare two settings of one build; split on spaces, so no quoted arguments).
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/.." && pwd)"
BUILD_DIR="${BUILD_DIR:-$root/build/release}"
WORK_DIR="${WORK_DIR:-$BUILD_DIR/bench-size-ab}"
DATA_DIR="${SMRDB_DATA_DIR:-$root/data}"
SIZES="${SIZES:-4097}"
MAX_ERROR="${MAX_ERROR:-1.6}"
BIG_SIZE="${BIG_SIZE-16385}"
BIG_ERROR="${BIG_ERROR:-0.5}"
MESHES="${MESHES:-armadillo.off bunny00.off ChineseDragon-10kv.off}"
ROUNDS="${ROUNDS:-6}"
OUT="${OUT:-$here/results/db_size_ab.json}"
: "${OLD_BUILD_DIR:?set OLD_BUILD_DIR to a build of the commit to compare with}"
# shellcheck source=lib.sh
source "$here/lib.sh"
require_executables "$BUILD_DIR" "$BUILD_DIR/tools/smrdb" "$BUILD_DIR/benchmarks/bench_extract_speed"
require_executables "$OLD_BUILD_DIR" "$OLD_BUILD_DIR/tools/smrdb" \
  "$OLD_BUILD_DIR/benchmarks/bench_extract_speed"
require_tools
build_dir() { [[ "$1" == old ]] && echo "$OLD_BUILD_DIR" || echo "$BUILD_DIR"; }
ingest_args() { [[ "$1" == old ]] && echo "${OLD_INGEST_ARGS:-}" || echo "${NEW_INGEST_ARGS:-}"; }
# Each side's databases in a directory named by its smrdb binary and ingest options, so a rebuilt
# one (or other options) makes new ones.
side_key() { { sha1sum <"$(build_dir "$1")/tools/smrdb"; ingest_args "$1"; } | sha1sum | cut -c1-12; }
old_dir="$WORK_DIR/old-$(side_key old)"
new_dir="$WORK_DIR/new-$(side_key new)"
db_dir() { [[ "$1" == old ]] && echo "$old_dir" || echo "$new_dir"; }
mkdir -p "$old_dir" "$new_dir" "$(dirname "$OUT")"
stderr_log="$WORK_DIR/bench.stderr"
: >"$stderr_log"

# Inputs, made once by this build.
smrdb="$BUILD_DIR/tools/smrdb"
inputs=()  # name=source=max_error ("" for meshes: the builder's default)
for n in $SIZES $BIG_SIZE; do
  dem="$WORK_DIR/fbm$n.tif"
  [[ -f "$dem" ]] || { log "synth ${n}^2 fBm -> $dem"; "$smrdb" synth --size "$n" --seed 1 --range 1600 -o "$dem" -q; }
  err="$MAX_ERROR"
  [[ "$n" == "$BIG_SIZE" ]] && err="$BIG_ERROR"
  inputs+=("fbm$n=$dem=$err")
done
for m in $MESHES; do inputs+=("${m%.*}=$DATA_DIR/meshes/$m="); done

# 1. Sizes.
sizes='[]'
for b in old new; do
  for spec in "${inputs[@]}"; do
    IFS='=' read -r name src err <<<"$spec"
    db="$(db_dir "$b")/$name.smrdb"
    if [[ ! -f "$db" ]]; then
      log "$b: ingest $name"
      args=("$src" -o "$db" -q --force)
      [[ -n "$err" ]] && args+=(--max-error "$err")
      read -r -a more <<<"$(ingest_args "$b")"
      args+=(${more[@]+"${more[@]}"})
      "$(build_dir "$b")/tools/smrdb" ingest "${args[@]}"
    fi
    info="$("$(build_dir "$b")/tools/smrdb" info "$db" --json)"
    lmdb='{}'
    if command -v mdb_stat >/dev/null; then
      lmdb="$(mdb_stat -n -a "$db" | awk '/^Status of /{sub(/^Status of /, ""); t=$0}
        /Leaf pages|Branch pages|Overflow pages/{n[t]+=$3}
        END{printf "{"; s=""; for (k in n) {printf "%s\"%s\":%d", s, k, n[k]; s=","} printf "}"}')"
    fi
    sizes="$(jq -c --arg b "$b" --arg name "$name" --argjson info "$info" --argjson lmdb "$lmdb" \
      '. + [{build: $b, name: $name, file_bytes: $info.file_bytes,
             bytes_per_vertex: $info.bytes_per_vertex, format: $info.meta.version,
             counts: $info.meta.counts, table_bytes: $info.meta.bytes, lmdb_pages: $lmdb}]' <<<"$sizes")"
  done
done

# 2. Reads, alternating.
reads='[]'
first="fbm${SIZES%% *}"
for r in $(seq 1 "$ROUNDS"); do
  order="old new"
  ((r % 2 == 0)) && order="new old"  # either build first in every other round
  for b in $order; do
    bench="$(build_dir "$b")/benchmarks/bench_extract_speed"
    cases=("$first full --repeat 3 --cache-mb 4096")
    [[ -n "$BIG_SIZE" ]] && cases+=("fbm$BIG_SIZE oblique --repeat 30 --cache-mb 64")
    for c in "${cases[@]}"; do
      read -r name kind rest <<<"$c"
      db="$(db_dir "$b")/$name.smrdb"
      cat "$db" >/dev/null
      load="$(cut -d' ' -f1 /proc/loadavg)"
      # shellcheck disable=SC2086
      got="$("$bench" "$db" --cases "$kind" --algorithms minimal-pages $rest 2>>"$stderr_log")" ||
        { log "$b $name $kind failed; see $stderr_log"; exit 1; }
      reads="$(jq -c --arg b "$b" --arg r "$r" --arg name "$name" --arg kind "$kind" \
        --arg load "$load" --argjson got "$got" \
        '. + [{round: ($r | tonumber), build: $b, db: $name, case: $kind, load: ($load | tonumber),
               triangles: $got.cases[0].triangles,
               warm_s: $got.cases[0].warm.in_memory_seconds.median,
               warm_min_s: $got.cases[0].warm.in_memory_seconds.min,
               hot_s: $got.cases[0].hot.in_memory_seconds.median,
               pages_read: $got.cases[0].warm.io_first.pages_read,
               value_bytes_read: $got.cases[0].warm.io_first.lmdb_bytes_read}]' <<<"$reads")"
      log "round $r $b $name $kind: warm $(jq -r '.[-1].warm_s' <<<"$reads") s"
    done
  done
done

# 3. The results.
jq -n --argjson sizes "$sizes" --argjson reads "$reads" \
  --arg old "$OLD_BUILD_DIR" --arg old_args "${OLD_INGEST_ARGS:-}" \
  --arg new_args "${NEW_INGEST_ARGS:-}" \
  --arg new "$(git -C "$root" rev-parse --short HEAD)" --arg date "$(date -u +%FT%TZ)" \
  --arg cpu "$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')" \
  --argjson nproc "$(nproc)" '
  def med: sort | if length == 0 then null else .[(length - 1) / 2 | floor] end;
  {benchmark: "benchmarks/run_db_size_ab.sh", old: $old, new: $new, date: $date,
   old_ingest_args: $old_args, new_ingest_args: $new_args,
   machine: {cpu: $cpu, nproc: $nproc},
   sizes: $sizes,
   size_ratios: [$sizes | group_by(.name)[] | {name: .[0].name,
     old_bytes_per_vertex: (map(select(.build == "old"))[0].bytes_per_vertex),
     new_bytes_per_vertex: (map(select(.build == "new"))[0].bytes_per_vertex)}
     | . + {ratio: (.new_bytes_per_vertex / .old_bytes_per_vertex)}],
   reads: $reads,
   read_medians: [$reads | group_by([.db, .case])[] | {db: .[0].db, case: .[0].case,
     old_warm_s: (map(select(.build == "old").warm_s) | med),
     new_warm_s: (map(select(.build == "new").warm_s) | med),
     old_hot_s: (map(select(.build == "old").hot_s) | med),
     new_hot_s: (map(select(.build == "new").hot_s) | med)}
     | . + {warm_ratio: (.new_warm_s / .old_warm_s), hot_ratio: (.new_hot_s / .old_hot_s)}]}' >"$OUT"
log "wrote $OUT"
jq -c '.size_ratios[], .read_medians[]' "$OUT"
