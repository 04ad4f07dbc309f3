#!/usr/bin/env bash
# View-dependent output size against OpenMesh's VDPM (issue 4), on the same meshes, cameras and
# screen-space tolerances:
#   1. installs libopenmesh-dev and libopenmesh-apps (Debian) when missing, builds bench_vdpm;
#   2. per mesh, builds OpenMesh's vertex hierarchy: OpenMesh-mkbalancedpm (balanced QEM
#      progressive mesh, .pm) then OpenMesh-Analyzer (view-dependent parameters, .spm), timed;
#   3. runs bench_vdpm (our build, extraction and VDPM refinement per cut, both measured);
#   4. writes benchmarks/results/vdpm.json with commit, date, machine and load-average stamps, and
#      prints the Markdown tables (benchmarks/vdpm/table.sh).
#
# Environment: BUILD_DIR (default build/bench-vdpm), WORK_DIR (default $BUILD_DIR/vdpm-work),
# SMRDB_DATA_DIR (default data; meshes are read from $SMRDB_DATA_DIR/meshes), MESHES (file names),
# TAUS (1,2,4), DISTANCES (1.5,3), REPEAT (3), MKBALANCEDPM_ARGS (extra mkbalancedpm options, e.g.
# "-N 75"; default none: the tool's defaults), OUT (results file), BENCH_ARGS (extra bench_vdpm
# options, e.g. --no-match).
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
BUILD_DIR="${BUILD_DIR:-$root/build/bench-vdpm}"
WORK_DIR="${WORK_DIR:-$BUILD_DIR/vdpm-work}"
DATA_DIR="${SMRDB_DATA_DIR:-$root/data}/meshes"
MESHES="${MESHES:-bunny00.off armadillo.off ChineseDragon-10kv.off refined_elephant.off}"
TAUS="${TAUS:-1,2,4}"
DISTANCES="${DISTANCES:-1.5,3}"
REPEAT="${REPEAT:-3}"
MKBALANCEDPM_ARGS="${MKBALANCEDPM_ARGS:-}"
BENCH_ARGS="${BENCH_ARGS:-}"
OUT="${OUT:-$root/benchmarks/results/vdpm.json}"
log() { echo "[$(date +%H:%M:%S)] $*" >&2; }

# 1. OpenMesh (library + apps) and the benchmark.
if ! dpkg -s libopenmesh-dev libopenmesh-apps >/dev/null 2>&1; then
  log "installing libopenmesh-dev libopenmesh-apps"
  sudo_cmd=""
  [[ $(id -u) -eq 0 ]] || sudo_cmd="sudo"
  $sudo_cmd apt-get install -y libopenmesh-dev libopenmesh-apps ||
    { $sudo_cmd apt-get update && $sudo_cmd apt-get install -y libopenmesh-dev libopenmesh-apps; }
fi
command -v jq >/dev/null || { echo "jq is required to assemble the results" >&2; exit 1; }
bench="$BUILD_DIR/benchmarks/vdpm/bench_vdpm"
if [[ ! -x "$bench" ]]; then
  log "building bench_vdpm in $BUILD_DIR"
  cmake -S "$root" -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release -DSMRDB_BUILD_TESTS=OFF >/dev/null
fi
cmake --build "$BUILD_DIR" -j2 --target bench_vdpm >/dev/null
mkdir -p "$WORK_DIR" "$(dirname "$OUT")"
# The source the binary was built from: the commit, and a hash of the uncommitted changes to smr/
# (others may commit or edit while this runs; the end state is recorded too).
source_stamp() {
  local commit dirty diff
  commit="$(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo unknown)"
  dirty="$(git -C "$root" status --porcelain -- smr 2>/dev/null | wc -l)"
  diff="$(git -C "$root" diff HEAD -- smr 2>/dev/null | sha256sum | cut -c1-16)"
  jq -n --arg c "$commit" --argjson d "$dirty" --arg h "$diff" \
    '{commit: $c, uncommitted_files_in_smr: $d, smr_diff_sha256_16: (if $d > 0 then $h else null end)}'
}
stamp_built="$(source_stamp)"

loadavg_before="$(cut -d' ' -f1-3 /proc/loadavg)"
elapsed() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.3f", b - a }'; }
results=()
for mesh in $MESHES; do
  src="$DATA_DIR/$mesh"
  [[ -f "$src" ]] || { echo "missing $src (scripts/fetch-data.sh?)" >&2; exit 1; }
  name="${mesh%.*}"
  # 2. OpenMesh's hierarchy (mkbalancedpm decimates as far as it can, the Analyzer adds the
  # bounding spheres, normal cones and mu/sigma of every node).
  log "$name: OpenMesh-mkbalancedpm $MKBALANCEDPM_ARGS"
  t0="$(date +%s.%N)"
  # shellcheck disable=SC2086
  OpenMesh-mkbalancedpm $MKBALANCEDPM_ARGS -o "$WORK_DIR/$name.pm" "$src" >"$WORK_DIR/$name.mkbalancedpm.log" 2>&1
  t1="$(date +%s.%N)"
  log "$name: OpenMesh-Analyzer"
  OpenMesh-Analyzer -o "$WORK_DIR/$name.spm" "$WORK_DIR/$name.pm" >"$WORK_DIR/$name.analyzer.log" 2>&1
  t2="$(date +%s.%N)"
  # 3. Both sides, every cut.
  log "$name: bench_vdpm (taus $TAUS, distances $DISTANCES, repeat $REPEAT)"
  # shellcheck disable=SC2086
  "$bench" --mesh "$src" --spm "$WORK_DIR/$name.spm" --taus "$TAUS" --distances "$DISTANCES" \
    --repeat "$REPEAT" $BENCH_ARGS >"$WORK_DIR/$name.json" 2>"$WORK_DIR/$name.bench.log"
  jq --arg name "$name" --argjson mk "$(elapsed "$t0" "$t1")" --argjson an "$(elapsed "$t1" "$t2")" \
    --arg mkargs "$MKBALANCEDPM_ARGS" \
    '{name: $name} + . | .vdpm_hierarchy += {mkbalancedpm_seconds: $mk, analyzer_seconds: $an,
                                           build_seconds: ($mk + $an), mkbalancedpm_args: $mkargs}
     | del(.machine, .benchmark)' \
    "$WORK_DIR/$name.json" >"$WORK_DIR/$name.result.json"
  results+=("$WORK_DIR/$name.result.json")
  log "$name: $(jq -r '[.cuts[] | select(.target.holds)] | length' "$WORK_DIR/$name.json") of $(jq -r '.cuts | length' "$WORK_DIR/$name.json") cuts meet the target"
done
loadavg_after="$(cut -d' ' -f1-3 /proc/loadavg)"

# 4. The results file.
first_json="$WORK_DIR/$(echo "$MESHES" | awk '{ print $1 }' | sed 's/\.[^.]*$//').json"
cpu_model="$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//')"
jq -s \
  --slurpfile first "$first_json" \
  --arg date "$(date -u +%Y-%m-%dT%H:%M:%SZ)" \
  --argjson built "$stamp_built" --argjson ended "$(source_stamp)" \
  --arg nproc "$(nproc)" --arg cpu "$cpu_model" --arg kernel "$(uname -sr)" \
  --arg la0 "$loadavg_before" --arg la1 "$loadavg_after" \
  --arg openmesh "$(dpkg-query -W -f='${Version}' libopenmesh-dev 2>/dev/null || echo unknown)" \
  --arg taus "$TAUS" --arg distances "$DISTANCES" --argjson repeat "$REPEAT" '
  def med: sort | if length == 0 then null elif length % 2 == 1 then .[length / 2 | floor]
                  else (.[length / 2 - 1] + .[length / 2]) / 2 end;
  . as $meshes | [$meshes[].cuts[]] as $cuts |
  {
    benchmark: "vdpm",
    date: $date,
    commit: $built.commit,
    uncommitted_files_in_smr: $built.uncommitted_files_in_smr,
    smr_diff_sha256_16: $built.smr_diff_sha256_16,
    source_at_end: (if $ended == $built then "unchanged" else $ended end),
    machine: ($first[0].machine + {nproc: ($nproc | tonumber), cpu_model: $cpu, kernel: $kernel,
                                  loadavg_before: $la0, loadavg_after: $la1}),
    peer: {name: "OpenMesh VDPM (Kim & Lee 2001; Hoppe 1997 criteria)", debian_version: $openmesh,
           hierarchy: "OpenMesh-mkbalancedpm then OpenMesh-Analyzer",
           refinement: "the Synthesizer'"'"'s adaptive_refinement, repeated until a pass changes nothing"},
    setup: {taus_px: $taus, distances_radii: $distances, viewport: [1024, 768], fov_y_deg: 60,
            directions: "tests/support/meshes.cpp: (1,0.3,0.2), (-0.4,1,-0.5), (0.2,-0.6,1), eye at distance x half the bounds diagonal from the bounds centre",
            repeats: $repeat,
            measured_error: "samples (vertices, edge midpoints, centroid, 3 interior points) of every front-facing output triangle not outside the frustum, those inside the frustum: distance to the source surface (exact, bucket grid) x focal_px / depth along the view direction; and the same from the source triangles to the output. max_px/p99_px = the larger of the two directions.",
            target: "ours.triangles <= vdpm.triangles and ours two-sided max_px <= vdpm two-sided max_px"},
    summary: {
      cuts: ($cuts | length),
      target_holds: ([$cuts[] | select(.target.holds)] | length),
      ours_le_vdpm_triangles: ([$cuts[] | select(.target.ours_le_vdpm_triangles)] | length),
      ours_le_vdpm_max_px: ([$cuts[] | select(.target.ours_le_vdpm_max_px)] | length),
      ours_le_vdpm_p99_px: ([$cuts[] | select(.target.ours_le_vdpm_p99_px)] | length),
      median_triangle_ratio_ours_over_vdpm: ([$cuts[].target.triangle_ratio] | med),
      median_triangle_ratio_at_vdpm_max_error: ([$cuts[] | .ours_at_vdpm_error.max | select(.found) | .triangle_ratio_vs_vdpm] | med),
      median_triangle_ratio_at_vdpm_p99_error: ([$cuts[] | .ours_at_vdpm_error.p99 | select(.found) | .triangle_ratio_vs_vdpm] | med),
      per_mesh: [$meshes[] | {name, cuts: (.cuts | length),
                 target_holds: ([.cuts[] | select(.target.holds)] | length),
                 median_triangle_ratio: ([.cuts[].target.triangle_ratio] | med),
                 median_ratio_at_vdpm_p99: ([.cuts[] | .ours_at_vdpm_error.p99 | select(.found) | .triangle_ratio_vs_vdpm] | med),
                 median_ratio_at_vdpm_max: ([.cuts[] | .ours_at_vdpm_error.max | select(.found) | .triangle_ratio_vs_vdpm] | med)}]
    },
    meshes: $meshes
  }' "${results[@]}" >"$OUT"
log "wrote $OUT"
"$here/table.sh" "$OUT"
