#!/usr/bin/env bash
# Kim & Lee's Table 2 (papers/002) side by side (issue 38 item 4): per mesh, OpenMesh's VDPM
# hierarchy (OpenMesh-mkbalancedpm, OpenMesh-Analyzer), then bench_table2: #V, #F and #DC of VDPM,
# our minimal surface and our truly selective refinement, at equal criteria and at equal measured
# error. The 2.5-D row is a DEM triangulated as a mesh (bench_table2 --write-terrain, a PLY: jacksboro,
# every STEP-th sample, x and y in metres). Writes benchmarks/results/vdpm_table2.json and prints
# the table (table2.sh).
#
# Environment: BUILD_DIR (default build/bench-vdpm), WORK_DIR, SMRDB_DATA_DIR (default data),
# MESHES (file names in $SMRDB_DATA_DIR/meshes), DEM (default jacksboro_fault_dem.npz; empty: no
# terrain row), STEP (2), TAU (VDPM's tolerance for the equal-error rows, 1), OUT.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
BUILD_DIR="${BUILD_DIR:-$root/build/bench-vdpm}"
WORK_DIR="${WORK_DIR:-$BUILD_DIR/table2-work}"
DATA_DIR="${SMRDB_DATA_DIR:-$root/data}"
MESHES="${MESHES:-ChineseDragon-10kv.off armadillo.off bunny00.off}"
DEM="${DEM-jacksboro_fault_dem.npz}"
STEP="${STEP:-2}"
TAU="${TAU:-1}"
OUT="${OUT:-$root/benchmarks/results/vdpm_table2.json}"
log() { echo "[$(date +%H:%M:%S)] $*" >&2; }

command -v OpenMesh-mkbalancedpm >/dev/null || { echo "needs libopenmesh-apps (run_vdpm.sh installs it)" >&2; exit 1; }
command -v jq >/dev/null || { echo "jq is required to assemble the results" >&2; exit 1; }
bench="$BUILD_DIR/benchmarks/vdpm/bench_table2"
if [[ ! -x "$bench" ]]; then
  cmake -S "$root" -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release -DSMRDB_BUILD_TESTS=OFF >/dev/null
fi
cmake --build "$BUILD_DIR" -j2 --target bench_table2 >/dev/null
mkdir -p "$WORK_DIR" "$(dirname "$OUT")"

inputs=()
if [[ -n "$DEM" ]]; then
  terrain="$WORK_DIR/terrain-${DEM%%.*}-step$STEP.ply"
  "$bench" --write-terrain "$terrain" --dem "$DATA_DIR/$DEM" --step "$STEP"
  inputs+=("$terrain|terrain-${DEM%%.*}|--terrain --fov 45")
fi
for m in $MESHES; do inputs+=("$DATA_DIR/meshes/$m|${m%.*}|"); done
results=()
loadavg_before="$(cut -d' ' -f1-3 /proc/loadavg)"
for entry in "${inputs[@]}"; do
  IFS='|' read -r src name extra <<<"$entry"
  log "$name: OpenMesh-mkbalancedpm, OpenMesh-Analyzer"
  OpenMesh-mkbalancedpm -o "$WORK_DIR/$name.pm" "$src" >"$WORK_DIR/$name.mkbalancedpm.log" 2>&1
  OpenMesh-Analyzer -o "$WORK_DIR/$name.spm" "$WORK_DIR/$name.pm" >"$WORK_DIR/$name.analyzer.log" 2>&1
  log "$name: bench_table2"
  # shellcheck disable=SC2086
  "$bench" --mesh "$src" --spm "$WORK_DIR/$name.spm" --name "$name" --tau "$TAU" $extra \
    >"$WORK_DIR/$name.table2.json" 2>"$WORK_DIR/$name.table2.log"
  results+=("$WORK_DIR/$name.table2.json")
done
jq -s --arg date "$(date -u +%Y-%m-%dT%H:%M:%SZ)" \
  --arg commit "$(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo unknown)" \
  --arg la0 "$loadavg_before" --arg la1 "$(cut -d' ' -f1-3 /proc/loadavg)" --arg tau "$TAU" \
  '{benchmark: "vdpm_table2", date: $date, commit: $commit,
    machine: (.[0].machine + {loadavg_before: $la0, loadavg_after: $la1}),
    setup: {vdpm_tau_px_equal_error: ($tau | tonumber), all_visible_tau_px: 0.001,
            cameras: "3-D: the three directions of bench_vdpm at 1.5 radii, 30 deg fov; terrain: above three corners at 20 deg elevation looking at the centre, 45 deg fov; 1024x768",
            ours: "build_qem_pm one split per op; minimal = extract_minimal_surface(RCF); selective = extract_selective(NodeCriterion); selective_vdpm_criteria = the same with vertex_normal_cones; hoppe97_vdpm_criteria = the same with SplitScheme::kHoppe97; selective_rcf = extract_selective(RCF)"},
    meshes: [.[] | del(.machine)]}' "${results[@]}" >"$OUT"
log "wrote $OUT"
"$here/table2.sh" "$OUT"
