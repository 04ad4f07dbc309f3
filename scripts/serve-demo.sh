#!/usr/bin/env bash
# Serve the demo database over HTTP (smrdb serve, docs/serve.md) and print the viewer's URL.
# Builds and ingests first when needed (scripts/demo.sh does both: install, build, fetch,
# ingest). PORT (default 8080) and BIND (default 127.0.0.1) choose where it listens; Ctrl-C stops.
set -euo pipefail
cd "$(dirname "$0")/.."
PORT="${PORT:-8080}"
BIND="${BIND:-127.0.0.1}"
if [[ ! -x build/release/tools/smrdb || ! -f out/jacksboro.smrdb ]]; then
  scripts/demo.sh
fi
VIEWER=tools/viewer/dist
ARGS=(jacksboro=out/jacksboro.smrdb --port "$PORT" --bind "$BIND")
if [[ -f "$VIEWER/index.html" ]]; then
  ARGS+=(--viewer "$VIEWER")
else
  echo "serve-demo: no built viewer in $VIEWER: serving the HTTP API only" >&2
  ARGS+=(--viewer none)
fi
echo "serve-demo: open http://$BIND:$PORT/ (API: http://$BIND:$PORT/v1/databases); Ctrl-C stops"
exec build/release/tools/smrdb serve "${ARGS[@]}"
