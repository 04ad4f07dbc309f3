#!/usr/bin/env bash
# Build-speed comparison with peer terrain triangulators, all on the same DEM in one run:
#   1. a deterministic SIZE^2 fBm (default 4097^2, seed 1, height range 1600 m) written as .npy;
#   2. bench_build (our greedy Delaunay CRMR builder) at max error = 0.1 % of the range (1.6 m);
#   3. delatin and @mapbox/martini (benchmarks/peers/run_peer.mjs) at the same max error;
#   4. bench_check: the same exact checker verifies every peer mesh on every sample
#      (bench_build checks ours in-process);
#   5. benchmarks/results/build_vs_peers.json with ours/delatin and ours/martini time ratios.
#
# Environment: BUILD_DIR (default build/release), WORK_DIR (default $BUILD_DIR/bench-work),
# SIZE (4097), SEED (1), RANGE (1600), MAX_ERROR_FRACTION (0.001), OUT (results file),
# PEERS ("delatin martini"), REPEAT (3: rounds; times are the median over rounds).
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/.." && pwd)"
BUILD_DIR="${BUILD_DIR:-$root/build/release}"
WORK_DIR="${WORK_DIR:-$BUILD_DIR/bench-work}"
SIZE="${SIZE:-4097}"
SEED="${SEED:-1}"
RANGE="${RANGE:-1600}"
MAX_ERROR_FRACTION="${MAX_ERROR_FRACTION:-0.001}"
OUT="${OUT:-$here/results/build_vs_peers.json}"
PEERS="${PEERS:-delatin martini}"
REPEAT="${REPEAT:-3}"

bench_build="$BUILD_DIR/benchmarks/bench_build"
bench_check="$BUILD_DIR/benchmarks/bench_check"
smrdb="$BUILD_DIR/tools/smrdb"
for exe in "$bench_build" "$bench_check"; do
  [[ -x "$exe" ]] || { echo "missing $exe: build first (cmake --build $BUILD_DIR)" >&2; exit 1; }
done
command -v node >/dev/null || { echo "node is required for the peers" >&2; exit 1; }
command -v jq >/dev/null || { echo "jq is required to assemble the results" >&2; exit 1; }
if [[ ! -d "$here/peers/node_modules/delatin" || ! -d "$here/peers/node_modules/@mapbox/martini" ]]; then
  (cd "$here/peers" && npm ci --no-audit --no-fund)
fi
mkdir -p "$WORK_DIR" "$(dirname "$OUT")"

# The fBm is normalised to min 0, max RANGE exactly, so 0.1 % of the range is RANGE * 0.001.
max_error="$(awk -v r="$RANGE" -v f="$MAX_ERROR_FRACTION" 'BEGIN { printf "%.12g", r * f }')"
dem="$WORK_DIR/fbm${SIZE}_seed${SEED}.npy"
log() { echo "[$(date +%H:%M:%S)] $*" >&2; }

log "generating ${SIZE}x${SIZE} fBm (seed $SEED, range $RANGE) -> $dem"
if [[ -x "$smrdb" ]] && "$smrdb" synth --size "$SIZE" --seed "$SEED" --range "$RANGE" -o "$dem" -q; then
  generator="smrdb synth --size $SIZE --seed $SEED --range $RANGE"
else
  "$bench_build" --fbm "$SIZE" --seed "$SEED" --range "$RANGE" --write-npy "$dem" --skip-build >/dev/null
  generator="bench_build --fbm $SIZE --seed $SEED --range $RANGE --write-npy"
fi

loadavg_before="$(cut -d' ' -f1-3 /proc/loadavg)"

# Interleave the contenders REPEAT times, each run a fresh process (a cold start, as a user would
# run it), so that load from other processes hits all of them alike; medians are compared. The
# first run of each writes its mesh, which is checked on every sample.
for ((i = 1; i <= REPEAT; i++)); do
  log "round $i/$REPEAT: bench_build (ours) at max error $max_error"
  if [[ $i -eq 1 ]]; then
    set +e
    "$bench_build" "$dem" --max-error "$max_error" --write-mesh "$WORK_DIR/ours.bin" >"$WORK_DIR/ours.json"
    rc=$?
    set -e
    [[ $rc -eq 0 || $rc -eq 3 ]] || { echo "bench_build failed ($rc)" >&2; exit 1; }
    log "  ours: $(jq -r '"\(.build.seconds) s, \(.build.finest_triangles) triangles, bound ok: \(.error_check.ok)"' "$WORK_DIR/ours.json")"
  else
    "$bench_build" "$dem" --max-error "$max_error" --skip-check >"$WORK_DIR/ours_$i.json"
    log "  ours: $(jq -r .build.seconds "$WORK_DIR/ours_$i.json") s"
  fi
  for peer in $PEERS; do
    log "round $i/$REPEAT: $peer at max error $max_error"
    if [[ $i -eq 1 ]]; then
      node --max-old-space-size=12288 "$here/peers/run_peer.mjs" --peer "$peer" --npy "$dem" \
        --max-error "$max_error" --out-mesh "$WORK_DIR/$peer.bin" >"$WORK_DIR/$peer.json"
      set +e
      "$bench_check" "$dem" --mesh "$WORK_DIR/$peer.bin" --max-error "$max_error" >"$WORK_DIR/${peer}_check.json"
      rc=$?
      set -e
      [[ $rc -eq 0 || $rc -eq 3 ]] || { echo "bench_check failed on $peer ($rc)" >&2; exit 1; }
      log "  $peer: $(jq -r '"\(.seconds) s, \(.triangles) triangles"' "$WORK_DIR/$peer.json"), bound ok: $(jq -r .error_check.ok "$WORK_DIR/${peer}_check.json")"
    else
      node --max-old-space-size=12288 "$here/peers/run_peer.mjs" --peer "$peer" --npy "$dem" \
        --max-error "$max_error" >"$WORK_DIR/${peer}_$i.json"
      log "  $peer: $(jq -r .seconds "$WORK_DIR/${peer}_$i.json") s"
    fi
  done
done
loadavg_after="$(cut -d' ' -f1-3 /proc/loadavg)"

# Collect the times of every round: {all: [...], median, min}.
times() {  # $1 = first-run json, $2 = jq path of the seconds, $3 = glob prefix of later runs
  local files=("$1") i
  for ((i = 2; i <= REPEAT; i++)); do files+=("$3_$i.json"); done
  jq -s "[.[] | $2] | {all: ., min: min, median: (sort | if length % 2 == 1 then .[length / 2 | floor] else (.[length / 2 - 1] + .[length / 2]) / 2 end)}" "${files[@]}"
}
ours_times="$(times "$WORK_DIR/ours.json" .build.seconds "$WORK_DIR/ours")"
peer_json="{}"
for peer in $PEERS; do
  peer_times="$(times "$WORK_DIR/$peer.json" .seconds "$WORK_DIR/$peer")"
  peer_json="$(jq -n --argjson acc "$peer_json" --arg p "$peer" --argjson t "$peer_times" \
    --slurpfile run "$WORK_DIR/$peer.json" --slurpfile chk "$WORK_DIR/${peer}_check.json" \
    '$acc + {($p): ($run[0] + {seconds_first: $run[0].seconds, seconds: $t.median, seconds_min: $t.min,
                                seconds_all: $t.all, error_check: $chk[0].error_check})}')"
done

cpu_model="$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//')"
jq -n \
  --slurpfile ours "$WORK_DIR/ours.json" --argjson ot "$ours_times" --argjson repeat "$REPEAT" \
  --argjson peers "$peer_json" \
  --arg nproc "$(nproc)" --arg cpu "$cpu_model" --arg kernel "$(uname -sr)" \
  --arg date "$(date -u +%Y-%m-%dT%H:%M:%SZ)" --arg generator "$generator" \
  --arg la0 "$loadavg_before" --arg la1 "$loadavg_after" \
  --arg commit "$(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo unknown)" \
  --arg dirty "$(git -C "$root" status --porcelain -- smr 2>/dev/null | wc -l)" \
  --argjson size "$SIZE" --argjson seed "$SEED" --argjson range "$RANGE" --argjson max_error "$max_error" '
  ($ours[0]) as $o |
  {
    benchmark: "build_vs_peers",
    date: $date,
    commit: $commit,
    uncommitted_files_in_smr: ($dirty | tonumber),
    machine: ($o.machine + {nproc: ($nproc | tonumber), cpu_model: $cpu, kernel: $kernel,
                            loadavg_before: $la0, loadavg_after: $la1}),
    dem: {generator: $generator, size: $size, seed: $seed, range: $range,
          samples: $o.input.samples, z_min: $o.input.z_min, z_max: $o.input.z_max},
    max_error: $max_error,
    repeats: $repeat,
    ours: {seconds: $ot.median, seconds_min: $ot.min, seconds_all: $ot.all, vertices: $o.build.vertices, triangles: $o.build.finest_triangles,
           ops: $o.build.ops, fragment_triangles: $o.build.fragment_triangles,
           read_seconds: $o.input.read_seconds,
           rss_mb: $o.rss_peak_after_build_mb, error_check: $o.error_check},
    peers: $peers,
    ratios: ( {}
      + (if $peers.delatin then {ours_over_delatin: ($ot.median / $peers.delatin.seconds),
                                 ours_over_delatin_best_of_rounds: ($ot.min / $peers.delatin.seconds_min),
                                 triangles_ours_over_delatin: ($o.build.finest_triangles / $peers.delatin.triangles)} else {} end)
      + (if $peers.martini then {ours_over_martini: ($ot.median / $peers.martini.seconds),
                                 ours_over_martini_best_of_rounds: ($ot.min / $peers.martini.seconds_min),
                                 triangles_ours_over_martini: ($o.build.finest_triangles / $peers.martini.triangles)} else {} end) ),
    targets: {
      ours_over_delatin_max: 0.63,
      met: (if $peers.delatin then ($ot.median / $peers.delatin.seconds) <= 0.63 else null end),
      note: ("DESIGN targets: build <= 0.63x delatin, and within 1.5x of fogleman/hmm. On the DESIGN reference "
             + "DEM delatin took 35.5 s and hmm 15 s for 3.46 M triangles, so 1.5x hmm = 0.63x delatin: one "
             + "target, checked here against delatin run on the same DEM (hmm is not runnable here). Absolute "
             + "times are not comparable with the reference: this DEM and triangle count differ.")
    }
  }' >"$OUT"
log "wrote $OUT"
jq '{ours: .ours.seconds, delatin: .peers.delatin.seconds, martini: .peers.martini.seconds, ratios,
     bounds_ok: {ours: .ours.error_check.ok, delatin: .peers.delatin.error_check.ok, martini: .peers.martini.error_check.ok}}' "$OUT"
