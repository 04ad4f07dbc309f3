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

f="$res/extract_vs_martini.json"
if [[ -f "$f" ]]; then
  jq -r '
    def f1: (. * 10 | round) / 10;
    def f3: (. * 1000 | round) / 1000;
    def m: (. / 1e4 | round) / 100;
    "### extract_vs_martini.json — \(.date), commit \(.commit), \(.machine.nproc) × \(.machine.cpu_model), load \(.machine.loadavg_before) → \(.machine.loadavg_after)\n",
    "\(.parameters.rounds) rounds × \(.parameters.runs_per_round) runs; max error \(.parameters.max_error) m (\(.parameters.max_error_fraction * 100) % of the range). Ours: warm = fresh Database, file in the OS page cache; hot = same Database again (cache \(.parameters.cache_mb) MiB); in memory = open + extract + to_mesh; + PLY = with write_mesh. Ratio = ours triangles/s over martini getMesh (warm) triangles/s.\n",
    (.sizes[] | . as $s |
      "#### \(.size)² fBm: database \(.database.file_bytes / 1e6 | f1) MB, \(.database.vertices) vertices, \(.database.bytes_per_vertex | f1) B/vertex (format \(.database.format_version), \(.database.codec))\n",
      "| contender | triangles | median s | min s | M triangles/s | ratio |",
      "|---|---|---|---|---|---|",
      "| martini \(.martini.version) getMesh (createTile \(.martini.create_tile_seconds.median | f3) s) | \(.martini.triangles) | \(.martini.get_mesh_warm_seconds.median | f3) | \(.martini.get_mesh_warm_seconds.min | f3) | \(.martini.triangles_per_second | m) | 1 |",
      (.ours.cases[] | . as $c |
        (["warm", "in_memory_seconds", "triangles_per_second", "in memory"], ["warm", "with_ply_seconds", "triangles_per_second_with_ply", "+ PLY"], ["hot", "in_memory_seconds", "triangles_per_second", "in memory"]) as [$k, $t, $r, $what] |
        "| ours \($c.case) \($c.algorithm), \($k), \($what) | \($c.triangles) | \($c[$k][$t].median | f3) | \($c[$k][$t].min | f3) | \($c[$k][$r] | m) | \(if $c.case == "full" then ($c[$k][$r] / $s.martini.triangles_per_second | . * 1000 | round / 1000) else "" end) |"),
      "",
      "Memory: `\(.memory.command)`: peak RSS \(.memory.peak_rss_mb | round) MiB, budget \(.memory.budget_mb | round) MiB (\(if .memory.target_met then "met" else "**not met**" end)); the cache holds \(.memory.cache_pages_per_mib | f1) pages per MiB.\n")
  ' "$f"
fi

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

f="$res/db_amplification.json"
if [[ -f "$f" ]]; then
  jq -r '
    def f2: (. * 100 | round) / 100;
    def f3: (. * 1000 | round) / 1000;
    "### db_amplification.json — \(.date), commit \(.commit)\n",
    "Read amplification = bytes fetched from LMDB (pages + R-tree nodes + op locators) / bytes of the pages holding an op of an output triangle (target ≤ 1.5). Touched = distinct pages fetched; read = fetches with the \(.parameters.cache_mb) MiB cache (re-reads after eviction included). Times: cold = file dropped from the OS page cache (posix_fadvise DONTNEED), fresh Database; warm = fresh Database, file in the OS cache (median); hot = same Database again (median). raw = reading the touched pages from LMDB without decoding.\n",
    (.views[] |
      "#### \(.db.grid[0])² fBm (\(.db.vertices) vertices, \(.db.pages) pages, \(.db.file_bytes / 1e6 | round) MB), view \(.view)\n",
      "| px | algorithm | output triangles | pages needed | touched | read | **LMDB bytes / needed** | touched / needed pages | cold s | warm s | hot s | raw cold s | cold / raw cold | warm / raw warm |",
      "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
      (.cases[] | "| \(.pixel_error) | \(.algorithm) | \(.output.triangles) | \(.pages.needed) | \(.pages.touched) | \(.pages.read) | **\(.amplification.lmdb_bytes_over_needed | f2)** | \(.amplification.touched_over_needed_pages | f2) | \(.seconds.cold_extract | f3) | \(.seconds.warm_extract | f3) | \(.seconds.hot_extract | f3) | \(.raw_read.cold_seconds | f3) | \(.raw_read.cold_extract_over_raw | round) | \(.raw_read.warm_extract_over_raw | round) |"),
      "")
  ' "$f"
fi

f="$res/db_memory.json"
if [[ -f "$f" ]]; then
  jq -r '
    def f1: (. * 10 | round) / 10;
    "### db_memory.json — \(.date), commit \(.commit)\n",
    "Peak RSS of `smrdb extract --cache-mb \(.parameters.cache_mb)` (/usr/bin/time -v). Budget = cache + 32 MiB + output in memory (Extraction + TriangleMesh + to_mesh id map, estimated from the counts).\n",
    "| samples | algorithm | RCF | output triangles | output MiB (memory) | output file MiB | pages read | peak RSS MiB | budget MiB | met |",
    "|---|---|---|---|---|---|---|---|---|---|",
    (.runs[] | "| \(.size)² | \(.algorithm) | \(if .rcf == "finest" then "finest (g = 1)" else "\(.rcf) 1 px" end) | \(.output.triangles) | \(.output_memory_mb | f1) | \(.output_file_bytes / 1048576 | f1) | \(.io.pages_read) | **\(.peak_rss_mb | round)** | \(.budget_mb | round) | \(if .target_met then "yes" else "**no**" end) |"),
    ""
  ' "$f"
fi

f="$res/db_scaling.json"
if [[ -f "$f" ]]; then
  jq -r '
    def f3: (. * 1000 | round) / 1000;
    def f2: (. * 100 | round) / 100;
    "### db_scaling.json — \(.date), commit \(.commit)\n",
    "The same camera (world coordinates) and pixel tolerance on the same terrain sampled at \(.databases | map("\(.size)²") | join(", ")) (spacing \(.databases | map(.spacing | f2 | tostring) | join(", ")) m), all ingested at \(.parameters.max_error) m. Ratio = warm time / warm time on the smallest database (target ≤ 1.5).\n",
    "| view | px | algorithm | samples | database MB | output triangles | pages read | LMDB MB read | warm s | cold s | ratio |",
    "|---|---|---|---|---|---|---|---|---|---|---|",
    ([.runs[] | . as $r | .cases[] | {view: $r.view, size: $r.size, mb: ($r.db.file_bytes / 1e6), px: .pixel_error, alg: .algorithm,
        tri: .output.triangles, pages: .io.pages_read, lmdb: (.io.lmdb_bytes_read / 1e6), warm: .seconds.warm_extract, cold: .seconds.cold_extract}]
     | group_by([.view, .px, .alg]) | .[] | sort_by(.size) | .[0].warm as $w0 | .[] |
     "| \(.view) | \(.px) | \(.alg) | \(.size)² | \(.mb | round) | \(.tri) | \(.pages) | \(.lmdb | f2) | \(.warm | f3) | \(.cold | f3) | \(.warm / $w0 | f2) |"),
    ""
  ' "$f"
fi

f="$res/db_codecs.json"
if [[ -f "$f" ]]; then
  jq -r '
    def f1: (. * 10 | round) / 10;
    def f2: (. * 100 | round) / 100;
    "### db_codecs.json — \(.date), commit \(.commit)\n",
    "Per database: file bytes per model vertex (Hoppe PM: \(.datasets[0].references.hoppe_pm_bytes_per_vertex) B/vertex; Brown CRMR: 2–4× PM), geometry blob bytes per page vertex and per fragment triangle, decode_geometry and whole-page decode_page throughput over every page.\n",
    "| dataset | vertices | codec | pages | file B/vertex | pages B/vertex | of which records B/vertex | geometry B/page-vertex | geometry B/triangle | geometry decode MB/s (in) | geometry M tri/s | µs/page | page decode M tri/s | page µs |",
    "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    (.datasets[] | . as $d | .codecs | to_entries[] |
      "| \($d.name) | \($d.crmr.vertices) | \(.key) | \(.value.pages) | \(.value.file_bytes_per_model_vertex | f1) | \(.value.page_bytes_per_model_vertex | f1) | \(.value.record_bytes_per_model_vertex | f1) | \(.value.geometry_bytes_per_page_vertex | f2) | \(.value.geometry_bytes_per_triangle | f2) | \(.value.geometry_decode.input_mb_per_s | round) | \(.value.geometry_decode.triangles_per_s / 1e6 | f2) | \(.value.geometry_decode.us_per_page | round) | \(.value.page_decode.triangles_per_s / 1e6 | f2) | \(.value.page_decode.us_per_page | round) |"),
    ""
  ' "$f"
fi
