#!/usr/bin/env bash
# Configures and builds one preset: release (default) or asan.
set -euo pipefail
cd "$(dirname "$0")/.."
preset="${1:-release}"
cmake --preset "$preset" >/dev/null
cmake --build --preset "$preset" -j"$(nproc)"
# The browser viewer's bundle (tools/viewer/dist, served by `smrdb serve --viewer`).
(cd tools/viewer && npm run build --silent)
