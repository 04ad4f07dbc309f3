#!/usr/bin/env bash
# Prints the results in benchmarks/results/*.json as Markdown tables (for benchmarks/README.md).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
res="$here/results"

for f in "$res"/build_vs_peers*.json; do
  [[ -f "$f" ]] || continue
  jq -r '
    def f2: (. * 100 | round) / 100;
    def f3: (. * 1000 | round) / 1000;
    "### \(input_filename | split("/") | last): \(.dem.size)² fBm (seed \(.dem.seed), range \(.dem.range) m), max error \(.max_error) m — \(.date), \(.repeats) rounds, \(.machine.nproc) × \(.machine.cpu_model)\n",
    "| builder | seconds (median) | all rounds | vertices | triangles | peak RSS MiB | error bound on every sample | max deviation m | samples over bound |",
    "|---|---|---|---|---|---|---|---|---|",
    "| smrdb greedy Delaunay CRMR | \(.ours.seconds | f2) | \(.ours.seconds_all | map(f2) | join(", ")) | \(.ours.vertices) | \(.ours.triangles) | \(.ours.rss_mb | round) | \(if .ours.error_check.ok then "holds" else "FAILS" end) | \(.ours.error_check.max_deviation | f3) | \(.ours.error_check.over_bound_strict) |",
    (.peers | to_entries[] |
      "| \(.key) \(.value.version) | \(.value.seconds | f2) | \(.value.seconds_all | map(f2) | join(", ")) | \(.value.vertices) | \(.value.triangles) | \(.value.rss_mb | round) | \(if .value.error_check.ok then "holds" else "FAILS" end) | \(.value.error_check.max_deviation | f3) | \(.value.error_check.over_bound_strict) |"),
    "",
    "ours/delatin = **\(.ratios.ours_over_delatin | f2)** (target ≤ \(.targets.ours_over_delatin_max): \(if .targets.met then "met" else "not met" end)), ours/martini = **\(.ratios.ours_over_martini | f2)**.\n"
  ' "$f"
done

f="$res/extract.json"
if [[ -f "$f" ]]; then
  jq -r '
    def f3: (. * 1000 | round) / 1000;
    "### extract.json — \(.date)\n",
    "Table 7.1 style (CRMR built by greedy Delaunay insertion):\n",
    "| terrain | samples | max error | M^m vertices | M^m triangles | fragments | build s |",
    "|---|---|---|---|---|---|---|",
    (.datasets[] | "| \(.name) | \(.samples) | \(.max_error * 1000 | round / 1000) (\(.max_error_fraction_of_range * 100) % of range) | \(.vertices) | \(.finest_triangles) | \(.fragments) | \(.build_seconds * 100 | round / 100) |"),
    "",
    "Tables 7.4/7.5 style (median of \(.datasets[0].rows[0].repeats) runs; |F| = output triangles, void excluded):\n",
    (.datasets[] |
      "#### \(.name)\n",
      "| RCF | algorithm | \\|X\\| | \\|X+\\| | \\|F\\| | triangles/fan | extraction s | expansion s | total s |",
      "|---|---|---|---|---|---|---|---|---|",
      (.rows[] | "| \(.rcf) | \(.algorithm) | \(.x) | \(.x_plus) | \(.triangles) | \(.triangles_per_fan * 100 | round / 100) | \(.extract_seconds | f3) | \(.expand_seconds | f3) | \(.total_seconds | f3) |"),
      ""),
    (if .throughput then
      "Extraction throughput, \(.throughput.dataset), RCF \(.throughput.rcf), median of \(.throughput.repeats) runs:\n",
      "| algorithm | output triangles | median s | triangles/s |",
      "|---|---|---|---|",
      (.throughput | ["minimal", "reduced"][] as $a | .[$a] | "| \($a) | \(.triangles) | \(.total_seconds | f3) | \(.triangles_per_second | round) |"),
      "" else empty end)
  ' "$f"
fi
