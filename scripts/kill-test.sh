#!/usr/bin/env bash
# Crash safety of `smrdb ingest` (docs/design.md section 3: a killed ingest leaves either the previous
# database or nothing): kills an ingest with SIGKILL N times (default 200) at deterministic moments
# spread from 0 to ~110 % of a full ingest's duration, half of the runs over an existing database
# (ingest --force), half to a fresh path. After each kill the path must be absent (fresh path) or
# byte-identical to the old database, or byte-identical to a complete ingest, and `smrdb verify`
# must pass whenever it exists. Stale "<path>.tmp-<pid>*" files left by the kills are counted,
# must never stop the path from opening, and are removed after each run. Then N/10 more kills at
# the moment the path appears.
#
#   scripts/kill-test.sh [N]      env: SMRDB_BIN (default build/release/tools/smrdb),
#                                      KILL_TEST_SIZE (DEM size, default 257), KILL_TEST_SEED (1)
set -euo pipefail
n="${1:-200}"
cd "$(dirname "$0")/.."
bin="$(realpath "${SMRDB_BIN:-build/release/tools/smrdb}")"
size="${KILL_TEST_SIZE:-257}"
RANDOM="${KILL_TEST_SEED:-1}"  # deterministic delays
[[ -x "$bin" ]] || { echo "kill-test: no smrdb binary at $bin (scripts/build.sh release)" >&2; exit 1; }

work="$(mktemp -d "${TMPDIR:-/tmp}/smrdb-kill-test.XXXXXX")"
trap 'rm -rf "$work"' EXIT
db="$work/x.smrdb"
"$bin" synth --size "$size" --seed 3 -o "$work/dem.npy" -q
"$bin" synth --size 65 --seed 4 -o "$work/old.npy" -q
"$bin" ingest "$work/old.npy" -o "$work/old.smrdb" -q
# The same parameters every time: the database records them, and the output is deterministic.
ingest=("$bin" ingest "$work/dem.npy" --max-error 0 -o "$db" --force -q)

now_ns() { date +%s%N; }
t0=$(now_ns)
"${ingest[@]}"
t1=$(now_ns)
full_ns=$((t1 - t0))
mv "$db" "$work/new.smrdb"
"$bin" verify -q "$work/new.smrdb"
echo "kill-test: a full ingest of a ${size}x${size} DEM takes $((full_ns / 1000000)) ms; $n kills"

absent=0 old=0 new=0 stale=0 failures=0
fail() {
  echo "kill-test: run $1 (kill after $2 ms): $3" >&2
  failures=$((failures + 1))
}
for ((i = 0; i < n; ++i)); do
  over_old=$((i % 2))
  rm -f "$db"
  if ((over_old)); then cp "$work/old.smrdb" "$db"; fi
  # Run i of n dies at ((i + u) / n) * 1.1 of the full duration, u uniform in [0, 1).
  delay_ns=$(((i * 32768 + RANDOM) * (full_ns / 32768) * 11 / (10 * n)))
  delay=$(printf '%d.%09d' $((delay_ns / 1000000000)) $((delay_ns % 1000000000)))
  "${ingest[@]}" &
  pid=$!
  sleep "$delay"
  kill -9 "$pid" 2>/dev/null || true
  wait "$pid" 2>/dev/null || true
  ms=$((delay_ns / 1000000))
  if [[ ! -e "$db" ]]; then
    if ((over_old)); then fail "$i" "$ms" "the previous database vanished"; fi
    absent=$((absent + 1))
  elif ((over_old)) && cmp -s "$db" "$work/old.smrdb"; then
    old=$((old + 1))
  elif cmp -s "$db" "$work/new.smrdb"; then
    new=$((new + 1))
  else
    fail "$i" "$ms" "$db is neither the previous nor the complete database"
  fi
  if [[ -e "$db" ]] && ! "$bin" verify -q "$db"; then fail "$i" "$ms" "verify failed"; fi
  shopt -s nullglob
  temps=("$db".tmp-*)
  shopt -u nullglob
  if ((${#temps[@]})); then
    stale=$((stale + 1))
    if [[ -e "$db" ]] && ! "$bin" info "$db" >/dev/null; then
      fail "$i" "$ms" "stale ${temps[*]} stop $db from opening"
    fi
    rm -f "${temps[@]}"
  fi
done
# Then kills at the moment the path appears (polled with shell builtins): a writer that exposed a
# partly written file at the path, even briefly, is caught here.
watched=$(((n + 9) / 10))
for ((i = 0; i < watched; ++i)); do
  rm -f "$db"
  "${ingest[@]}" &
  pid=$!
  while kill -0 "$pid" 2>/dev/null && [[ ! -e "$db" ]]; do :; done
  kill -9 "$pid" 2>/dev/null || true
  wait "$pid" 2>/dev/null || true
  if [[ -e "$db" ]] && ! cmp -s "$db" "$work/new.smrdb"; then
    fail "watched $i" 0 "$db appeared before it was complete"
  fi
  rm -f "$db".tmp-*
done
echo "kill-test: $n kills, then $watched at the moment $db appeared: $absent left nothing, $old the previous database, $new the complete" \
  "one; $stale left stale temporaries; $failures failures"
((failures == 0))
