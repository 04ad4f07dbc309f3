#!/usr/bin/env bash
# The Markdown tables of results/vdpm_table2.json (run_table2.sh): Kim & Lee's Table 2 layout,
# one row per mesh, camera direction and criterion.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
file="${1:-$here/../results/vdpm_table2.json}"
echo "Equal criteria (everything the culling keeps refined; #V / #F / #DC):"
echo
echo "| mesh | dir | criteria | VDPM | minimal | selective | selective F / VDPM F | selective (sphere) F | selective (RCF) F | flipped |"
echo "|---|---|---|---|---|---|---|---|---|---|"
jq -r '.meshes[] | .name as $n | .rows[] | .equal_criteria as $e |
  "| \($n) | \(.direction) | \(.criteria) | \($e.vdpm.V) / \($e.vdpm.F) / \($e.vdpm.DC) | \($e.minimal.V) / \($e.minimal.F) | \($e.selective.V) / \($e.selective.F) / \($e.selective.DC) | \(($e.selective.F / $e.vdpm.F * 100 | round) / 100) | \($e.selective_sphere.F) | \($e.selective_rcf.F) | \($e.selective.flipped_triangles) |"' "$file"
echo
echo "Equal measured error (VDPM at tau = 1 px; ours at the largest tau whose two-sided p99 / max is within VDPM's; F and F / VDPM's F):"
echo
echo "| mesh | dir | criteria | VDPM F | VDPM p99 / max px | minimal at p99 | selective at p99 | minimal at max | selective at max |"
echo "|---|---|---|---|---|---|---|---|---|"
jq -r 'def cell(x): if x.found then "\(x.F) (\((x.F_over_vdpm * 100 | round) / 100))" else "not reached" end;
  def r2(x): (x * 100 | round) / 100;
  .meshes[] | .name as $n | .rows[] | .equal_error as $e |
  "| \($n) | \(.direction) | \(.criteria) | \($e.vdpm.F) | \(r2($e.vdpm.error.p99_px)) / \(r2($e.vdpm.error.max_px)) | \(cell($e.minimal.p99)) | \(cell($e.selective.p99)) | \(cell($e.minimal.max)) | \(cell($e.selective.max)) |"' "$file"
