#!/usr/bin/env bash
# Decoded pages (issue 34: "the cache holds more pages for the same N", and the warm 1 px oblique
# view that decoding dominates), this build against OLD_BUILD_DIR's (optional), interleaved,
# REPEAT rounds on the 16385² fBm database at 0.5 m (made as benchmarks/README.md says if DB is
# missing):
#   1. `bench_db decode DB --stride STRIDE --keep`: decode_page alone over every STRIDE-th real page,
#      each page of a pass in fresh memory (as a first view has): µs per page, decoded bytes per
#      page, pages per MiB; this build also with `--links` (a database decodes the Hypermesh links
#      only once a reader asks for them: OpSource::need_links);
#   2. `bench_extract_speed DB --cases oblique --algorithms minimal-pages --repeat INNER
#      --cache-mb 64`: the 1 px oblique view, warm (a fresh Database::open, the OS page cache
#      warm) and hot medians, and the cache's pages per MiB;
#   3. results/decoded_pages.json: every run, medians per build, new/old ratios, nproc, CPU model,
#      load average per round, commit, date.
# Environment: BUILD_DIR (build/release), OLD_BUILD_DIR (none), DB, REPEAT (4), INNER (15),
# STRIDE (10), OUT.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/.." && pwd)"
# shellcheck source=lib.sh
source "$here/lib.sh"
BUILD_DIR="${BUILD_DIR:-$root/build/release}"
DB="${DB:-$BUILD_DIR/bench-db/fbm16385_e0.5.smrdb}"
REPEAT="${REPEAT:-4}"
INNER="${INNER:-15}"
STRIDE="${STRIDE:-10}"
OUT="${OUT:-$here/results/decoded_pages.json}"
builds=(new)
dirs=("$BUILD_DIR")
if [[ -n "${OLD_BUILD_DIR:-}" ]]; then
  builds=(old new)
  dirs=("$OLD_BUILD_DIR" "$BUILD_DIR")
fi
for d in "${dirs[@]}"; do
  require_executables "$d" "$d/benchmarks/bench_db" "$d/benchmarks/bench_extract_speed"
done
require_tools
if [[ ! -f "$DB" ]]; then
  smrdb="$BUILD_DIR/tools/smrdb"
  mkdir -p "$(dirname "$DB")"
  tif="$(dirname "$DB")/fbm16385.tif"
  log "synth 16385x16385 fBm -> $tif, ingest at 0.5 m -> $DB"
  [[ -f "$tif" ]] || "$smrdb" synth --size 16385 --seed 1 --range 1600 --spacing 1 -o "$tif" -q
  "$smrdb" ingest "$tif" --max-error 0.5 -o "$DB" -q
fi
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

rounds=()
for round in $(seq 1 "$REPEAT"); do
  for i in "${!builds[@]}"; do
    b="${builds[$i]}"
    d="${dirs[$i]}"
    log "round $round: $b"
    "$d/benchmarks/bench_db" decode "$DB" --stride "$STRIDE" --keep >"$work/$b.decode.$round.json"
    if [[ "$b" == new ]]; then
      "$d/benchmarks/bench_db" decode "$DB" --stride "$STRIDE" --keep --links \
        >"$work/$b.decode_links.$round.json"
    fi
    "$d/benchmarks/bench_extract_speed" "$DB" --cases oblique --algorithms minimal-pages \
      --repeat "$INNER" --cache-mb 64 >"$work/$b.oblique.$round.json"
  done
  rounds+=("$(cut -d' ' -f1-3 /proc/loadavg)")
done

# summary BUILD: medians over every round of the decode and the oblique view.
summary() {
  local b="$1" links=null
  if [[ -f "$work/$b.decode_links.1.json" ]]; then
    links="$(jq -s '{us_per_page: ([.[].us_per_page] | sort | .[length / 2 | floor]),
      decoded_bytes_per_page: .[0].decoded_bytes_per_page, pages_per_mib: .[0].pages_per_mib}' \
      "$work/$b".decode_links.*.json)"
  fi
  jq -n --argjson links "$links" \
    --slurpfile dec <(jq -s '.' "$work/$b".decode.[0-9]*.json) \
    --slurpfile obl <(jq -s '.' "$work/$b".oblique.*.json) '
    def median: sort | .[length / 2 | floor];
    {decode: {us_per_page: ([$dec[0][].us_per_page] | median),
              us_per_page_all: [$dec[0][].us_per_page],
              decoded_bytes_per_page: $dec[0][0].decoded_bytes_per_page,
              pages_per_mib: (1048576 / $dec[0][0].decoded_bytes_per_page)},
     decode_with_links: $links,
     oblique: {warm_seconds: ([$obl[0][].cases[0].warm.in_memory_seconds.all[]] | median),
               hot_seconds: ([$obl[0][].cases[0].hot.in_memory_seconds.all[]] | median),
               warm_round_medians: [$obl[0][].cases[0].warm.in_memory_seconds.median],
               triangles: $obl[0][0].cases[0].triangles,
               pages_read: $obl[0][0].cases[0].warm.io_first.pages_read,
               cache_pages_per_mib: $obl[0][0].cases[0].cache.pages_per_mib}}'
}

new="$(summary new)"
old=null
[[ "${builds[0]}" == old ]] && old="$(summary old)"
printf '%s\n' "${rounds[@]}" | jq -R . | jq -s --argjson new "$new" --argjson old "$old" \
  --arg db "$DB" --arg nproc "$(nproc)" --arg cpu "$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2-)" \
  --arg commit "$(git -C "$root" rev-parse --short HEAD)" --arg date "$(date -u +%FT%TZ)" '
  {benchmark: "decoded pages: bench_db decode --keep, bench_extract_speed --cases oblique",
   db: $db, new: $new, old: $old,
   ratios: (if $old == null then null else
     {decode_us_per_page: ($new.decode.us_per_page / $old.decode.us_per_page),
      decoded_bytes_per_page: ($new.decode.decoded_bytes_per_page / $old.decode.decoded_bytes_per_page),
      oblique_warm: ($new.oblique.warm_seconds / $old.oblique.warm_seconds),
      oblique_hot: ($new.oblique.hot_seconds / $old.oblique.hot_seconds)} end),
   nproc: ($nproc | tonumber), cpu_model: $cpu, loadavg_per_round: ., commit: $commit, date: $date}' \
  >"$OUT"
jq -r '"decode: \(.new.decode.us_per_page | floor) us/page, \(.new.decode.pages_per_mib * 100 | floor / 100) pages/MiB (with links \(.new.decode_with_links.pages_per_mib * 100 | floor / 100)); oblique warm \(.new.oblique.warm_seconds * 1e4 | floor / 10) ms, hot \(.new.oblique.hot_seconds * 1e4 | floor / 10) ms" + (if .ratios then "; new/old: decode x\(.ratios.decode_us_per_page * 100 | floor / 100), bytes x\(.ratios.decoded_bytes_per_page * 100 | floor / 100), warm x\(.ratios.oblique_warm * 100 | floor / 100), hot x\(.ratios.oblique_hot * 100 | floor / 100)" else "" end)' "$OUT"
