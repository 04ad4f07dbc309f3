#!/usr/bin/env bash
# Prints benchmarks/results/vdpm.json (or the file given) as Markdown tables.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
file="${1:-$here/../results/vdpm.json}"
jq -r '
  def r(n): if . == null then "-" else (. * pow(10; n) | round) / pow(10; n) | tostring end;
  def ms: if . == null then "-" else (. * 1000 * 10 | round) / 10 | tostring end;
  "Measured \(.date), commit \(.commit)\(if .uncommitted_files_in_smr > 0 then " + uncommitted smr changes (diff \(.smr_diff_sha256_16))" else "" end), load \(.machine.loadavg_before) -> \(.machine.loadavg_after), OpenMesh \(.peer.debian_version).",
  "",
  "| mesh | V | T | our build s | our base T | VDPM hierarchy s (mkbalancedpm + Analyzer) | VDPM base T |",
  "|---|---|---|---|---|---|---|",
  (.meshes[] | "| \(.name) | \(.mesh.vertices) | \(.mesh.triangles) | \(.ours_build.seconds | r(2)) | \(.ours_build.base_triangles) | \(.vdpm_hierarchy.build_seconds | r(2)) | \(.vdpm_hierarchy.base_faces) |"),
  "",
  "Per cut: dir = direction index, dist = eye distance in radii, tau in px. Triangles: ours (culling off), VDPM (culling off). Error = measured two-sided screen-space error max / p99 px. Times ms: our extraction (median); VDPM from its base (median) / from the previous cut. Target = ours <= VDPM triangles and ours max <= VDPM max. Next: our triangles at the largest tau whose measured p99 (max) is still <= VDPM'"'"'s. Last: what-if, our triangles (two-sided max / p99 px) when op errors are local (measured, DAG-monotone) instead of the mesh-wide bound.",
  "",
  "| mesh | dir | dist | tau | ours T | VDPM T | ours err max / p99 | VDPM err max / p99 | ours ms | VDPM ms base / prev | target | ours T at VDPM p99 (max) | what-if local op errors |",
  "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
  (.meshes[] | .name as $n | .cuts[] |
    "| \($n) | \(.direction) | \(.distance_radii) | \(.tau_px) | \(.ours.triangles) (\(.ours.triangles_no_culling)) | \(.vdpm.triangles) (\(.vdpm.triangles_no_culling)) | \(.ours.error.max_px | r(2)) / \(.ours.error.p99_px | r(2)) | \(.vdpm.error.max_px | r(2)) / \(.vdpm.error.p99_px | r(2)) | \(.ours.extract_seconds | ms) | \(.vdpm.from_base_seconds | ms) / \(.vdpm.from_previous.seconds | ms) | \(if .target.holds then "holds" else "fails" end) | \(.ours_at_vdpm_error.p99.triangles // "-") (\(.ours_at_vdpm_error.max.triangles // "-")) | \(.ours.what_if_local_op_errors.triangles) (\(.ours.what_if_local_op_errors.error.max_px | r(2)) / \(.ours.what_if_local_op_errors.error.p99_px | r(2))) |"),
  "",
  "| mesh | cuts | target holds | median T ours / VDPM | at VDPM'"'"'s p99 | at VDPM'"'"'s max |",
  "|---|---|---|---|---|---|",
  (.summary.per_mesh[] | "| \(.name) | \(.cuts) | \(.target_holds) | \(.median_triangle_ratio | r(2)) | \(.median_ratio_at_vdpm_p99 | r(2)) | \(.median_ratio_at_vdpm_max | r(2)) |"),
  "",
  "Summary: target holds in \(.summary.target_holds) of \(.summary.cuts) cuts; ours <= VDPM triangles in \(.summary.ours_le_vdpm_triangles), ours max <= VDPM max in \(.summary.ours_le_vdpm_max_px), ours p99 <= VDPM p99 in \(.summary.ours_le_vdpm_p99_px). Median triangles ours/VDPM \(.summary.median_triangle_ratio_ours_over_vdpm | r(2)); at VDPM'"'"'s measured p99 \(.summary.median_triangle_ratio_at_vdpm_p99_error | r(2)), at its max \(.summary.median_triangle_ratio_at_vdpm_max_error | r(2))."
' "$file"
