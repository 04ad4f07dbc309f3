# Sourced by the benchmark scripts: a timestamped log line on stderr, and the checks a run makes
# before starting (built executables; jq and /usr/bin/time).
log() { echo "[$(date +%H:%M:%S)] $*" >&2; }

# require_executables BUILD_DIR EXE...: every EXE is built.
require_executables() {
  local build_dir="$1" exe
  shift
  for exe in "$@"; do
    [[ -x "$exe" ]] || { echo "missing $exe: build first (cmake --build $build_dir)" >&2; exit 1; }
  done
}

# require_tools: jq (results) and /usr/bin/time (peak RSS).
require_tools() {
  command -v jq >/dev/null || { echo "jq is required to assemble the results" >&2; exit 1; }
  [[ -x /usr/bin/time ]] || { echo "/usr/bin/time (Debian package time) is required" >&2; exit 1; }
}

# A jq definition to put before a program: peak_rss_mb(time_kb; report) is a run's peak RSS in MiB
# from /usr/bin/time's %M (KiB) and smrdb's --json report. %M alone is not the peak: smrdb resets
# the kernel's high-water mark before writing the database (clear_refs 5, to report that phase's
# own peak), and the exit rusage reads the mark as reset; the report keeps the earlier peak.
PEAK_RSS_JQ='def peak_rss_mb(time_kb; report): [time_kb / 1024, (report.peak_rss_mb // 0)] | max;'

# A jq definition: output_memory_mb, on an `smrdb extract --json` report, is the output's size in
# memory: the Extraction (TriRef 16 B + fan start 4 B per triangle, 8 B per op of X) and the
# TriangleMesh (24 B per vertex, 12 + 4 B per triangle) plus to_mesh's id map (~40 B per vertex).
OUTPUT_MEMORY_JQ='def output_memory_mb:
  (.output.triangles * 36 + .extraction.x_plus * 8 + .output.vertices * 64) / 1048576;'
