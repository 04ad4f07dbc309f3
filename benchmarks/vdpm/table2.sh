#!/usr/bin/env bash
# The Markdown tables of results/vdpm_table2.json (run_table2.sh): Kim & Lee's Table 2 layout,
# one row per mesh, camera direction and criterion.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
file="${1:-$here/../results/vdpm_table2.json}"
echo "Equal criteria (everything the culling keeps refined). On our hierarchy with VDPM's criteria (the"
echo "back-face test at the vertex, on the cone of the vertex normals below it): Hoppe 1997's scheme and"
echo "Kim & Lee's truly selective one; beside them OpenMesh's VDPM on its own hierarchy. #V / #F /"
echo "forced splits (Hoppe 97) or degenerate cases (#DC):"
echo
echo "| mesh | dir | criteria | VDPM | minimal | Hoppe 97 | selective | selective F / Hoppe 97 F | selective F / VDPM F | selective, face cones F | (sphere) F | (RCF) F | flipped |"
echo "|---|---|---|---|---|---|---|---|---|---|---|---|---|"
jq -r 'def r2(x): (x * 100 | round) / 100;
  .meshes[] | .name as $n | .rows[] | .equal_criteria as $e | $e.selective_vdpm_criteria as $k | $e.hoppe97_vdpm_criteria as $h |
  "| \($n) | \(.direction) | \(.criteria) | \($e.vdpm.V) / \($e.vdpm.F) / \($e.vdpm.DC) | \($e.minimal.V) / \($e.minimal.F) | \($h.V) / \($h.F) / \($h.forced_splits) | \($k.V) / \($k.F) / \($k.DC) | \(r2($k.F / $h.F)) | \(r2($k.F / $e.vdpm.F)) | \($e.selective.F) | \($e.selective_sphere.F) | \($e.selective_rcf.F) | \($k.flipped_triangles) |"' "$file"
echo
echo "Equal measured error (VDPM at tau = 1 px; ours at the largest tau whose two-sided p99 / max is within VDPM's, the ladder bisected; F and F / VDPM's F; selective: the back-face test over the sphere on the face-normal cones):"
echo
echo "| mesh | dir | criteria | VDPM F | VDPM p99 / max px | minimal at p99 | selective at p99 | selective, VDPM's criteria, at p99 | minimal at max | selective at max | selective, VDPM's criteria, at max |"
echo "|---|---|---|---|---|---|---|---|---|---|---|"
jq -r 'def cell(x): if x.found then "\(x.F) (\((x.F_over_vdpm * 100 | round) / 100))" else "not reached" end;
  def r2(x): (x * 100 | round) / 100;
  .meshes[] | .name as $n | .rows[] | .equal_error as $e |
  "| \($n) | \(.direction) | \(.criteria) | \($e.vdpm.F) | \(r2($e.vdpm.error.p99_px)) / \(r2($e.vdpm.error.max_px)) | \(cell($e.minimal.p99)) | \(cell($e.selective.p99)) | \(cell($e.selective_vdpm_criteria.p99)) | \(cell($e.minimal.max)) | \(cell($e.selective.max)) | \(cell($e.selective_vdpm_criteria.max)) |"' "$file"
