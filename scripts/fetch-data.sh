#!/usr/bin/env bash
# Fetch the real datasets used by the tests and benchmarks from Debian packages.
#
#   scripts/fetch-data.sh [DIR]     (default: <repo>/data)
#
# DEMs (into DIR):
#   jacksboro_fault_dem.npz, topobathy.npz  from python-matplotlib-data
#   elev.tif                                from r-cran-terra
# Meshes (into DIR/meshes, from libcgal-demo's data.tar.gz):
#   bunny00.off armadillo.off refined_elephant.off ChineseDragon-10kv.off blobby_3cc.off
#   elephant-with-holes.off mech-holes-shark.off pig.stl fandisk.off
#   (missing ones are skipped with a warning)
#
# Idempotent: files already present are not fetched again. Data is never committed (.gitignore).
set -euo pipefail

repo_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
dest="${1:-${repo_root}/data}"
mkdir -p "${dest}/meshes"
dest="$(cd "${dest}" && pwd)"

dems=(jacksboro_fault_dem.npz topobathy.npz elev.tif)
meshes=(bunny00.off armadillo.off refined_elephant.off ChineseDragon-10kv.off blobby_3cc.off
        elephant-with-holes.off mech-holes-shark.off pig.stl fandisk.off)

need_matplotlib=0
need_terra=0
need_cgal=0
[[ -f "${dest}/jacksboro_fault_dem.npz" && -f "${dest}/topobathy.npz" ]] || need_matplotlib=1
[[ -f "${dest}/elev.tif" ]] || need_terra=1
for m in "${meshes[@]}"; do
  [[ -f "${dest}/meshes/${m}" ]] || need_cgal=1
done

if (( need_matplotlib + need_terra + need_cgal == 0 )); then
  echo "fetch-data: all datasets already present in ${dest}"
  exit 0
fi

work="$(mktemp -d)"
trap 'rm -rf "${work}"' EXIT

packages=()
(( need_matplotlib )) && packages+=(python-matplotlib-data)
(( need_terra )) && packages+=(r-cran-terra)
(( need_cgal )) && packages+=(libcgal-demo)

download() {
  (cd "${work}" && apt-get download "$@")
}

echo "fetch-data: downloading ${packages[*]}"
if ! download "${packages[@]}"; then
  if [[ "$(id -u)" == 0 ]]; then
    echo "fetch-data: apt-get download failed; running apt-get update and retrying" >&2
    apt-get update
    download "${packages[@]}"
  else
    echo "fetch-data: apt-get download failed (package lists missing? run 'apt-get update' as root)" >&2
    exit 1
  fi
fi

unpack() {  # unpack <package> -> prints the extraction directory
  local deb
  deb="$(find "${work}" -maxdepth 1 -name "$1_*.deb" -print -quit)"
  [[ -n "${deb}" ]] || { echo "fetch-data: error: no .deb downloaded for $1" >&2; exit 1; }
  mkdir -p "${work}/x-$1"
  dpkg -x "${deb}" "${work}/x-$1"
  echo "${work}/x-$1"
}

copy_new() {  # copy_new <src> <dst>
  if [[ -f "$2" ]]; then
    echo "fetch-data: have    $2"
  else
    cp "$1" "$2.partial"  # never leave a truncated file that a later run would take as present
    mv "$2.partial" "$2"
    echo "fetch-data: fetched $2"
  fi
}

if (( need_matplotlib )); then
  root="$(unpack python-matplotlib-data)"
  sample="${root}/usr/share/matplotlib/mpl-data/sample_data"
  copy_new "${sample}/jacksboro_fault_dem.npz" "${dest}/jacksboro_fault_dem.npz"
  copy_new "${sample}/topobathy.npz" "${dest}/topobathy.npz"
fi

if (( need_terra )); then
  root="$(unpack r-cran-terra)"
  copy_new "${root}/usr/lib/R/site-library/terra/ex/elev.tif" "${dest}/elev.tif"
fi

if (( need_cgal )); then
  root="$(unpack libcgal-demo)"
  tarball="$(find "${root}" -name data.tar.gz -print -quit)"
  if [[ -z "${tarball}" ]]; then
    echo "fetch-data: warning: data.tar.gz not found in libcgal-demo; no meshes fetched" >&2
  else
    listing="${work}/data-listing.txt"
    tar -tzf "${tarball}" > "${listing}"
    mkdir -p "${work}/cgal-data"
    for m in "${meshes[@]}"; do
      if [[ -f "${dest}/meshes/${m}" ]]; then
        echo "fetch-data: have    ${dest}/meshes/${m}"
        continue
      fi
      # Prefer the shortest path (the canonical copy) when a name occurs several times.
      member="$(grep -E "(^|/)${m//./\\.}\$" "${listing}" | awk '{ print length, $0 }' | sort -n |
                head -n 1 | cut -d' ' -f2- || true)"
      if [[ -z "${member}" ]]; then
        echo "fetch-data: warning: ${m} not found in ${tarball#"${root}"}; skipped" >&2
        continue
      fi
      tar -xzf "${tarball}" -C "${work}/cgal-data" "${member}"
      copy_new "${work}/cgal-data/${member}" "${dest}/meshes/${m}"
    done
  fi
fi

for d in "${dems[@]}"; do
  [[ -f "${dest}/${d}" ]] || { echo "fetch-data: error: ${dest}/${d} is missing" >&2; exit 1; }
done
echo "fetch-data: done (${dest})"
