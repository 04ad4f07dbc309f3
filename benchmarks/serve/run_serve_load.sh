#!/usr/bin/env bash
# smrdb serve under load (issue 37): requests/s and p50/p99 latency at 1, 8 and 64 concurrent
# clients asking for random tiles of a quantized-mesh pyramid (zooms 0..MAXZ), from
#   - smrdb serve with its tile cache (a tile is cut from the database on its first request;
#     the warm-up pass requests each once) and without (--tile-cache-mb 0: every tile cut on
#     demand, "smrdb_uncached"), and
#   - the same tiles written by `smrdb tiles` and served as static files by nginx (Debian's
#     nginx-light, when installed: 2 workers, sendfile, keep-alive) and by python3 -m http.server
#     (HTTP/1.1, a thread per connection), in the same run, alternating, REPEAT rounds;
# the server's peak RSS (VmHWM). Both are driven by bench_serve_load (keep-alive connections, no
# compression asked). Writes benchmarks/results/serve_load.json.
#   DB       the database (default: the 1 G-sample fBm of bench-query, else the 8193^2 fBm)
#   MAXZ     deepest zoom (default 6)   DURATION seconds per measurement (default 8)   REPEAT (2)
#   THREADS  smrdb serve --threads (default 8)
set -euo pipefail
cd "$(dirname "$0")/../.."
BUILD="${BUILD:-build/release}"
SMRDB="$BUILD/tools/smrdb"
LOAD="$BUILD/benchmarks/serve/bench_serve_load"
MAIN_BUILD="${MAIN_BUILD:-/work/main/build/release}"
DB="${DB:-}"
if [[ -z "$DB" ]]; then
  for c in "$BUILD/bench-query/fbm32769.smrdb" "$MAIN_BUILD/bench-query/fbm32769.smrdb" \
           "$BUILD/bench-martini/fbm8193_seed1_e1.6.smrdb" \
           "$MAIN_BUILD/bench-martini/fbm8193_seed1_e1.6.smrdb"; do
    [[ -f "$c" ]] && { DB="$c"; break; }
  done
fi
[[ -n "$DB" && -f "$DB" ]] || { echo "run_serve_load: no database (set DB)" >&2; exit 1; }
MAXZ="${MAXZ:-6}"
SECONDS_EACH="${DURATION:-8}"
REPEAT="${REPEAT:-2}"
THREADS="${THREADS:-8}"
WORK="${WORK:-$BUILD/bench-serve}"
mkdir -p "$WORK" benchmarks/results
PYR="$WORK/pyramid_z$MAXZ"
if [[ ! -f "$PYR/layer.json" ]]; then
  "$SMRDB" tiles "$DB" -o "$PYR" --max-zoom "$MAXZ" --force --json > "$WORK/tiles.json"
fi
(cd "$PYR" && find . -name '*.terrain' | sed 's|^\./||' | sort) > "$WORK/paths.txt"
echo "run_serve_load: $(wc -l < "$WORK/paths.txt") tiles of $DB (zooms 0..$MAXZ)" >&2

free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
"$SMRDB" serve big="$DB" --port 0 --threads "$THREADS" --queue 1024 --viewer none \
  > "$WORK/serve.out" 2> "$WORK/serve.err" &
SERVE_PID=$!
UNCACHED_PID=""
"$SMRDB" serve big="$DB" --port 0 --threads "$THREADS" --queue 1024 --viewer none \
  --tile-cache-mb 0 > "$WORK/serve_uncached.out" 2> "$WORK/serve_uncached.err" &
UNCACHED_PID=$!
port_of() {
  for _ in $(seq 100); do
    p=$(grep -o '127.0.0.1:[0-9]*' "$1" | head -1 | cut -d: -f2 || true)
    [[ -n "$p" ]] && { echo "$p"; return; }
    sleep 0.1
  done
}
SPORT=$(port_of "$WORK/serve.out")
UPORT=$(port_of "$WORK/serve_uncached.out")
PPORT=$(free_port)
python3 -m http.server --protocol HTTP/1.1 --bind 127.0.0.1 --directory "$PYR" "$PPORT" \
  > "$WORK/static.out" 2>&1 &
STATIC_PID=$!
SERVERS="smrdb smrdb_uncached static"
NPORT=""
NGINX_PID=""
if command -v nginx > /dev/null; then
  NPORT=$(free_port)
  ABS_WORK=$(cd "$WORK" && pwd)
  ABS_PYR=$(cd "$PYR" && pwd)
  mkdir -p "$ABS_WORK/nginx"
  cat > "$ABS_WORK/nginx/nginx.conf" <<NGX
daemon off;
worker_processes 2;
pid $ABS_WORK/nginx/nginx.pid;
error_log $ABS_WORK/nginx/error.log;
events { worker_connections 1024; }
http {
  access_log off;
  sendfile on;
  tcp_nodelay on;
  types { application/vnd.quantized-mesh terrain; application/json json; }
  client_body_temp_path $ABS_WORK/nginx/body;
  proxy_temp_path $ABS_WORK/nginx/proxy;
  fastcgi_temp_path $ABS_WORK/nginx/fastcgi;
  uwsgi_temp_path $ABS_WORK/nginx/uwsgi;
  scgi_temp_path $ABS_WORK/nginx/scgi;
  server { listen 127.0.0.1:$NPORT; root $ABS_PYR; }
}
NGX
  nginx -p "$ABS_WORK/nginx" -c "$ABS_WORK/nginx/nginx.conf" &
  NGINX_PID=$!
  SERVERS="smrdb smrdb_uncached nginx static"
fi
trap 'kill $SERVE_PID $UNCACHED_PID $STATIC_PID $NGINX_PID 2>/dev/null || true' EXIT
sleep 1
# The served tiles are the static ones (a sample).
for p in $(shuf -n 20 --random-source=<(yes) "$WORK/paths.txt"); do
  curl -sf "http://127.0.0.1:$SPORT/v1/big/tiles/$p" | cmp -s - "$PYR/$p" ||
    { echo "run_serve_load: served $p differs from the static file" >&2; exit 1; }
done
# Warm every server (database pages, the tile cache, the OS page cache): each tile requested once.
"$LOAD" --port "$SPORT" --prefix /v1/big/tiles/ --paths "$WORK/paths.txt" --clients 2 \
  --seconds 600 --once 1 > "$WORK/warmup.json"
"$LOAD" --port "$UPORT" --prefix /v1/big/tiles/ --paths "$WORK/paths.txt" --clients 2 --seconds 3 > /dev/null
"$LOAD" --port "$PPORT" --prefix / --paths "$WORK/paths.txt" --clients 2 --seconds 3 > /dev/null
[[ -n "$NPORT" ]] && "$LOAD" --port "$NPORT" --prefix / --paths "$WORK/paths.txt" --clients 2 --seconds 3 > /dev/null

RUNS="$WORK/runs.jsonl"
: > "$RUNS"
for round in $(seq "$REPEAT"); do
  for clients in 1 8 64; do
    for server in $SERVERS; do
      case $server in
        smrdb) port=$SPORT prefix=/v1/big/tiles/ ;;
        smrdb_uncached) port=$UPORT prefix=/v1/big/tiles/ ;;
        nginx) port=$NPORT prefix=/ ;;
        static) port=$PPORT prefix=/ ;;
      esac
      load=$(cut -d' ' -f1 /proc/loadavg)
      r=$("$LOAD" --port "$port" --prefix "$prefix" --paths "$WORK/paths.txt" \
            --clients "$clients" --seconds "$SECONDS_EACH" --seed "$round")
      echo "{\"round\": $round, \"server\": \"$server\", \"loadavg\": $load, \"run\": $r}" >> "$RUNS"
      echo "run_serve_load: round $round $server x$clients: $r" >&2
    done
  done
done
RSS_KIB=$(awk '/VmHWM/ {print $2}' "/proc/$SERVE_PID/status")
URSS_KIB=$(awk '/VmHWM/ {print $2}' "/proc/$UNCACHED_PID/status")
python3 - "$RUNS" "$RSS_KIB,$URSS_KIB" "$DB" "$MAXZ" "$THREADS" "$SECONDS_EACH" "$(wc -l < "$WORK/paths.txt")" \
  > benchmarks/results/serve_load.json <<'PY'
import json, statistics, subprocess, sys, os, platform
runs = [json.loads(l) for l in open(sys.argv[1])]
out = {"what": "random quantized-mesh tiles: smrdb serve (tile cache warm: 'smrdb'; every tile cut on demand: 'smrdb_uncached') vs the same tiles as "
               "static files (nginx: 'nginx'; python3 -m http.server --protocol HTTP/1.1: "
               "'static'), closed loop, keep-alive, same client (bench_serve_load)",
       "database": sys.argv[3], "max_zoom": int(sys.argv[4]), "tiles": int(sys.argv[7]),
       "serve_threads": int(sys.argv[5]), "seconds_per_run": float(sys.argv[6]),
       "serve_peak_rss_mib": round(int(sys.argv[2].split(",")[0]) / 1024, 1),
       "serve_uncached_peak_rss_mib": round(int(sys.argv[2].split(",")[1]) / 1024, 1),
       "nproc": os.cpu_count(), "cpu": platform.processor() or "",
       "commit": subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                                text=True).stdout.strip(),
       "by_clients": {}, "runs": runs}
for c in sorted({r["run"]["clients"] for r in runs}):
    row = {}
    servers = [s for s in ("smrdb", "smrdb_uncached", "nginx", "static")
               if any(r["server"] == s for r in runs)]
    for s in servers:
        rs = [r["run"] for r in runs if r["server"] == s and r["run"]["clients"] == c]
        row[s] = {"rps": statistics.median(r["rps"] for r in rs),
                  "p50_ms": statistics.median(r["p50_ms"] for r in rs),
                  "p99_ms": statistics.median(r["p99_ms"] for r in rs),
                  "errors": sum(r["errors"] for r in rs),
                  "non_200": sum(n for r in rs for k, n in r["status"].items() if k != "200")}
    for ours in ("smrdb", "smrdb_uncached"):
        for s in servers[2:]:
            row["rps_ratio_%s_over_%s" % (ours, s)] = round(row[ours]["rps"] / row[s]["rps"], 4)
            row["p99_ratio_%s_over_%s" % (ours, s)] = round(row[ours]["p99_ms"] / row[s]["p99_ms"], 3)
    row["loadavg"] = [r["loadavg"] for r in runs if r["run"]["clients"] == c]
    out["by_clients"][str(c)] = row
json.dump(out, sys.stdout, indent=2)
print()
PY
echo "run_serve_load: wrote benchmarks/results/serve_load.json" >&2
