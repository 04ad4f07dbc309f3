#!/usr/bin/env bash
# Build time of our QEM progressive-mesh CRMR builders (in core, and the block builder on every core
# as "ours-blocks") against meshopt_simplify (meshoptimizer 0.18,
# Debian libmeshoptimizer-dev) and CGAL 5.5's Surface_mesh_simplification edge collapse
# (Lindstrom-Turk; Garland-Heckbert plane policies), all on the same mesh in one process
# (bench_mesh_build, interleaved rounds, medians), on:
#   1. the CGAL demo meshes in $SMRDB_DATA_DIR/meshes (scripts/fetch-data.sh);
#   2. armadillo.off after SUBDIVIDE levels of midpoint 1-to-4 subdivision (3 levels: 3.33 M
#      triangles; the surface is unchanged, only the triangle count grows).
# Each contender's peak RSS is measured in a process of its own (--only C, /usr/bin/time -v).
# Writes benchmarks/results/mesh_build.json.
#
# Environment: BUILD_DIR (default build/bench-mesh; configured and built here unless
# SKIP_BUILD=1), WORK_DIR (default $BUILD_DIR/bench-work), SMRDB_DATA_DIR (default data),
# MESHES (file names in $SMRDB_DATA_DIR/meshes), REPAIR_MESHES (read with --repair: pig.stl),
# REPEAT (3 rounds), SUBDIVIDE (3; 0 = no large mesh), REPEAT_BIG (rounds on the large mesh, 2),
# RSS (1: measure peak RSS per contender), OUT (results file), RESUME (1: reuse the outputs an
# interrupted run left in WORK_DIR, per mesh and per RSS measurement; the binary must be the same).
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
BUILD_DIR="${BUILD_DIR:-$root/build/bench-mesh}"
WORK_DIR="${WORK_DIR:-$BUILD_DIR/bench-work}"
DATA_DIR="${SMRDB_DATA_DIR:-$root/data}"
MESHES="${MESHES:-bunny00.off armadillo.off refined_elephant.off ChineseDragon-10kv.off blobby_3cc.off elephant-with-holes.off mech-holes-shark.off pig.stl}"
REPAIR_MESHES="${REPAIR_MESHES:-pig.stl}"
REPEAT="${REPEAT:-3}"
SUBDIVIDE="${SUBDIVIDE:-3}"
REPEAT_BIG="${REPEAT_BIG:-2}"
RSS="${RSS:-1}"
OUT="${OUT:-$root/benchmarks/results/mesh_build.json}"
log() { echo "[$(date +%H:%M:%S)] $*" >&2; }

# Peers and tools: Debian packages, installed when missing.
need=()
dpkg -s libmeshoptimizer-dev >/dev/null 2>&1 || need+=(libmeshoptimizer-dev)
dpkg -s libeigen3-dev >/dev/null 2>&1 || need+=(libeigen3-dev)
dpkg -s libcgal-dev >/dev/null 2>&1 || need+=(libcgal-dev)
command -v jq >/dev/null || need+=(jq)
[[ -x /usr/bin/time ]] || need+=(time)
if ((${#need[@]})); then
  log "installing ${need[*]}"
  sudo_cmd=()
  [[ $(id -u) -eq 0 ]] || sudo_cmd=(sudo)
  if ! "${sudo_cmd[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y "${need[@]}"; then
    "${sudo_cmd[@]}" apt-get update
    "${sudo_cmd[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y "${need[@]}"
  fi
fi

if [[ "${SKIP_BUILD:-0}" != 1 ]]; then
  log "building bench_mesh_build in $BUILD_DIR"
  cmake -S "$root" -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release -DSMRDB_BUILD_TESTS=OFF >/dev/null
  cmake --build "$BUILD_DIR" -j2 --target bench_mesh_build >/dev/null
fi
bench="$BUILD_DIR/benchmarks/mesh/bench_mesh_build"
[[ -x "$bench" ]] || { echo "missing $bench" >&2; exit 1; }
# The source state the binary was built from (others may edit smr/ while this runs).
commit="$(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo unknown)"
dirty="$(git -C "$root" status --porcelain -- smr 2>/dev/null | wc -l)"
diff_sha="$(git -C "$root" diff HEAD -- smr 2>/dev/null | sha1sum | cut -c1-12)"
# With SKIP_BUILD=1 the binary may predate the sources: then the stamp above is not its source.
stale="$(find "$root/smr" "$root/storage" "$root/index" "$root/benchmarks" -name '*.[ch]*' \
  -newer "$bench" -type f 2>/dev/null | wc -l)"
((stale == 0)) || log "warning: $stale source files are newer than $bench"
mkdir -p "$WORK_DIR" "$(dirname "$OUT")"

# The large mesh: deterministic, regenerated only when missing.
inputs=()
for m in $MESHES; do inputs+=("$DATA_DIR/meshes/$m"); done
if ((SUBDIVIDE > 0)); then
  big="$WORK_DIR/armadillo_sub${SUBDIVIDE}.ply"
  if [[ ! -s "$big" ]]; then
    log "subdividing armadillo.off $SUBDIVIDE times -> $big"
    "$bench" "$DATA_DIR/meshes/armadillo.off" --subdivide "$SUBDIVIDE" -o "$big" >"$WORK_DIR/subdivide.json"
  fi
  inputs+=("$big")
fi

contenders="$("$bench" --list-contenders)"
# Reuse an output of an earlier, interrupted run (RESUME=1) when it is complete JSON.
reuse() { [[ "${RESUME:-0}" == 1 && -s "$1" ]] && jq -e . "$1" >/dev/null 2>&1; }
if [[ "${RESUME:-0}" == 1 && -s "$WORK_DIR/loadavg_before" ]]; then
  loadavg_before="$(cat "$WORK_DIR/loadavg_before")"
else
  loadavg_before="$(cut -d' ' -f1-3 /proc/loadavg)"
  echo "$loadavg_before" >"$WORK_DIR/loadavg_before"
fi
results=()
for input in "${inputs[@]}"; do
  name="$(basename "$input")"
  stem="$WORK_DIR/${name%.*}"
  args=()
  [[ " $REPAIR_MESHES " == *" $name "* ]] && args+=(--repair)
  rounds="$REPEAT"
  [[ "$input" == "${big:-}" ]] && rounds="$REPEAT_BIG"
  if reuse "$stem.json"; then
    log "$name: reusing $stem.json"
  else
    log "$name: $rounds interleaved rounds of: $contenders"
    "$bench" "$input" "${args[@]}" --repeat "$rounds" >"$stem.json.tmp"
    mv "$stem.json.tmp" "$stem.json"
  fi
  log "  ours $(jq -r '.results.ours.seconds' "$stem.json") s; ratios $(jq -c '.ratios' "$stem.json")"
  rss="{}"
  if [[ "$RSS" == 1 ]]; then
    for c in $contenders; do
      if ! reuse "$stem.rss.$c.json" || ! grep -q "Maximum resident" "$stem.rss.$c.time"; then
        /usr/bin/time -v "$bench" "$input" "${args[@]}" --repeat 1 --only "$c" --skip-db \
          >"$stem.rss.$c.json.tmp" 2>"$stem.rss.$c.time"
        mv "$stem.rss.$c.json.tmp" "$stem.rss.$c.json"
      fi
      kb="$(awk -F: '/Maximum resident set size/ { gsub(/ /, "", $2); print $2 }' "$stem.rss.$c.time")"
      rss="$(jq -n --argjson acc "$rss" --arg c "$c" --argjson kb "$kb" \
        --slurpfile run "$stem.rss.$c.json" \
        '$acc + {($c): {peak_rss_mb: ($kb / 1024), rss_after_input_mb: $run[0].rss_after_input_mb}}')"
      log "  peak RSS $c: $((kb / 1024)) MiB"
    done
  fi
  jq --argjson rss "$rss" '. + {peak_rss_per_contender: $rss}' "$stem.json" >"$stem.full.json"
  results+=("$stem.full.json")
done
loadavg_after="$(cut -d' ' -f1-3 /proc/loadavg)"

cpu_model="$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//')"
jq -s \
  --arg nproc "$(nproc)" --arg cpu "$cpu_model" --arg kernel "$(uname -sr)" \
  --arg date "$(date -u +%Y-%m-%dT%H:%M:%SZ)" \
  --arg la0 "$loadavg_before" --arg la1 "$loadavg_after" \
  --arg commit "$commit" --arg dirty "$dirty" --arg diff_sha "$diff_sha" --arg resumed "${RESUME:-0}" \
  --arg stale "$stale" \
  --argjson repeat "$REPEAT" --argjson repeat_big "$REPEAT_BIG" --argjson subdivide "$SUBDIVIDE" '
  def r(x): if x == null then null else (x * 1000 | round) / 1000 end;
  {
    benchmark: "mesh_build",
    date: $date,
    commit: $commit,
    uncommitted_files_in_smr: ($dirty | tonumber),
    resumed: ($resumed == "1"),
    sources_newer_than_binary: ($stale | tonumber),
    smr_diff_sha1: $diff_sha,
    machine: (.[0].machine + {nproc: ($nproc | tonumber), cpu_model: $cpu, kernel: $kernel,
                              loadavg_before: $la0, loadavg_after: $la1}),
    repeats: $repeat, repeats_large_mesh: $repeat_big, subdivision_levels: $subdivide,
    targets: {ours_over_meshopt_max: 2.0, ours_over_cgal_max: 1.0,
              note: "Issue 4: our full build (every level down to the base mesh) <= 2x meshopt_simplify to 10 % and to 1 % of the triangles (which builds no hierarchy), and faster than CGAL edge collapse to the same targets. Hoppe: 24.9 B/vertex."},
    summary: [ .[] | {
      mesh: .input.name, vertices: .input.vertices, triangles: .input.triangles,
      ours_s: r(.results.ours.seconds), ours_cpu_s: r(.results.ours.cpu_seconds),
      meshopt_10_s: r(.results.meshopt["10pct"].seconds), meshopt_1_s: r(.results.meshopt["1pct"].seconds),
      cgal_lt_10_s: r(.results["cgal-lt"]["10pct"].seconds), cgal_lt_1_s: r(.results["cgal-lt"]["1pct"].seconds),
      cgal_gh_10_s: r(.results["cgal-gh"]["10pct"].seconds), cgal_gh_1_s: r(.results["cgal-gh"]["1pct"].seconds),
      ours_over_meshopt_10: r(.ratios["ours_over_meshopt_10pct"]), ours_over_meshopt_1: r(.ratios["ours_over_meshopt_1pct"]),
      ours_over_cgal_lt_10: r(.ratios["ours_over_cgal-lt_10pct"]), ours_over_cgal_lt_1: r(.ratios["ours_over_cgal-lt_1pct"]),
      ours_over_cgal_gh_10: r(.ratios["ours_over_cgal-gh_10pct"]), ours_over_cgal_gh_1: r(.ratios["ours_over_cgal-gh_1pct"]),
      cpu_ours_over_meshopt_10: r(.ratios["cpu_ours_over_meshopt_10pct"]), cpu_ours_over_cgal_lt_10: r(.ratios["cpu_ours_over_cgal-lt_10pct"]),
      ours_blocks_s: r(.results["ours-blocks"].seconds), ours_blocks_cpu_s: r(.results["ours-blocks"].cpu_seconds),
      ours_blocks_threads: .results["ours-blocks"].threads,
      ours_blocks_over_cgal_lt_10: r(.ratios["ours-blocks_over_cgal-lt_10pct"]), ours_blocks_over_cgal_lt_1: r(.ratios["ours-blocks_over_cgal-lt_1pct"]),
      ours_blocks_over_meshopt_10: r(.ratios["ours-blocks_over_meshopt_10pct"]),
      cpu_ours_blocks_over_cgal_lt_10: r(.ratios["cpu_ours-blocks_over_cgal-lt_10pct"]),
      peak_rss_mb: (.peak_rss_per_contender | with_entries(.value = r(.value.peak_rss_mb))),
      bytes_per_vertex: r(.database.bytes_per_vertex), over_hoppe: r(.database.bytes_per_vertex_over_hoppe),
      ops: .results.ours.ops, pages: .database.pages, dag_depth: .results.ours.dag_depth,
      meets_2x_meshopt: ((.ratios["ours_over_meshopt_10pct"] // 1e9) <= 2 and (.ratios["ours_over_meshopt_1pct"] // 1e9) <= 2),
      faster_than_cgal: ((.ratios["ours_over_cgal-lt_10pct"] // 1e9) < 1 and (.ratios["ours_over_cgal-lt_1pct"] // 1e9) < 1),
      blocks_faster_than_cgal: ((.ratios["ours-blocks_over_cgal-lt_10pct"] // 1e9) < 1 and (.ratios["ours-blocks_over_cgal-lt_1pct"] // 1e9) < 1)
    } ],
    meshes: .
  }' "${results[@]}" >"$OUT"
log "wrote $OUT"
jq -r '.summary[] | [.mesh, .triangles, .ours_s, .ours_blocks_s, .meshopt_10_s, .meshopt_1_s, .cgal_lt_10_s, .cgal_lt_1_s,
                     .ours_over_meshopt_10, .ours_over_cgal_lt_10, .bytes_per_vertex, .dag_depth] | @tsv' "$OUT"
