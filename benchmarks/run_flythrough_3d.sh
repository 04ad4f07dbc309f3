#!/usr/bin/env bash
# Issue 35's 3-D setting: a geomorphing session orbiting a CGAL demo mesh (one turn, a camera per
# degree, 1 px at 1024x768, 64 MiB cache), each frame also extracted from scratch
# (--compare-fresh) for the headline ratio, with the local morphs per frame.
#   smrdb ingest MESH -o DB   (the in-core QEM builder)
#   smrdb flythrough DB --orbit --frames 360 --compare-fresh --pixel-error 1 --json
# Writes benchmarks/results/flythrough_3d_<mesh>.json (the flythrough report plus date, commit,
# load and the commands).
#
# Environment: BUILD_DIR (default build/release), SMRDB_DATA_DIR (default data), MESHES (default
# "bunny00 armadillo": .off files under data/meshes), FRAMES (default 360).
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/.." && pwd)"
source "$here/lib.sh"
BUILD_DIR="${BUILD_DIR:-$root/build/release}"
DATA_DIR="${SMRDB_DATA_DIR:-$root/data}"
MESHES="${MESHES:-bunny00 armadillo}"
FRAMES="${FRAMES:-360}"
smrdb="$BUILD_DIR/tools/smrdb"
require_executables "$BUILD_DIR" "$smrdb"
command -v jq >/dev/null || { echo "jq is required" >&2; exit 1; }
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

for mesh in $MESHES; do
  src="$DATA_DIR/meshes/$mesh.off"
  [[ -f "$src" ]] || { echo "missing $src: run scripts/fetch-data.sh" >&2; exit 1; }
  log "ingest $mesh"
  "$smrdb" ingest "$src" -q -o "$work/$mesh.smrdb"
  args=(--orbit --frames "$FRAMES" --compare-fresh --pixel-error 1 --viewport 1024x768 --json)
  log "flythrough $mesh: ${args[*]}"
  "$smrdb" flythrough "$work/$mesh.smrdb" "${args[@]}" >"$work/run.json"
  jq --arg date "$(date -u +%Y-%m-%dT%H:%M:%SZ)" \
     --arg commit "$(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo unknown)" \
     --arg loadavg "$(cut -d' ' -f1-3 /proc/loadavg)" \
     --arg command "smrdb ingest $mesh.off; smrdb flythrough DB ${args[*]}" \
     '{date: $date, commit: $commit, loadavg_after: $loadavg, command: $command} + .' \
     "$work/run.json" >"$here/results/flythrough_3d_$mesh.json"
  jq -r --arg m "$mesh" '.summary | "\($m): update p50 \(.update_ms.p50) ms p99 \(.update_ms.p99), fresh p50 \(.fresh_ms.p50) ms (ratio \(.fresh_over_update_p50)), morphs \(.local_morphs_pct.mean) % mean \(.local_morphs_pct.max) % max, mismatches \(.fresh_mismatches), peak RSS \(.peak_rss_mib) MiB"' \
    "$here/results/flythrough_3d_$mesh.json" >&2
done
