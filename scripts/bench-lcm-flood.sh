#!/usr/bin/env bash
# The LCM flood benchmark (part of `make bench`; needs root for a private network namespace):
# slamd on an lcm: source with a 640x480 camera at 30 Hz, alone (--factor 1) and inside a flood of
# ten times the camera's message rate (--factor 10: valid and malformed frames and commands, see
# tests/daemon/lcm_flood.cpp), RUNS times each for SECONDS. Reports per case the median over runs
# of capture-to-pose latency p50/p99 (from the moment a frame reached slamd), poses published,
# frames dropped, and slamd's resident memory early (25-50% of the run) and late (last 25%).
#   scripts/bench-lcm-flood.sh [BUILD_DIR]    environment: RUNS (3), SECONDS_PER_RUN (20), OUT,
#   SLAMD_ARGS (more slamd arguments, e.g. "--set daemon.mapping_nice=19")
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
BIN=$(cd "${1:-$ROOT/build}" && pwd)/bin
RUNS=${RUNS:-3}
SECONDS_PER_RUN=${SECONDS_PER_RUN:-20}
OUT=${OUT:-$ROOT/out/bench/lcm_flood}
if [ "$(id -u)" -ne 0 ]; then
  echo "bench-lcm-flood: needs root (a private network namespace for LCM multicast); skipped" >&2
  exit 0
fi
if [ -z "${SLAMD_IN_NET_NS:-}" ]; then
  SLAMD_IN_NET_NS=1 exec unshare -n bash "$0" "$@"
fi
SLAMD_BIN=$BIN
source "$ROOT/tests/daemon/scenarios/lib.sh"
private_network
mkdir -p "$OUT"
cd "$OUT"
CONFIG="$ROOT/config/synthetic.yaml"
frames=$((SECONDS_PER_RUN * 30))
if [ ! -f "frames-$frames/rgb.txt" ]; then
  "$BIN/slamd-synth" --config "$CONFIG" --log-level warn --scene room --frames "$frames" \
    --out "frames-$frames" > /dev/null
fi

one_run() {  # one_run FACTOR RUN: prints "p50 p99 published drops rss_early_mb rss_late_mb"
  local dir="factor$1-run$2"
  rm -rf "$dir"
  flood_run "$dir" "$1" "frames-$frames" "$SECONDS_PER_RUN" --set daemon.save_dir="$dir/maps" ${SLAMD_ARGS:-}
  local m="$dir/metrics.json"
  echo "$(json_number "$m" end_to_end_p50_ms) $(json_number "$m" end_to_end_p99_ms)" \
       "$(json_number "$m" poses_published) $(json_number "$m" drops)" \
       "$(rss_quarters "$dir/rss_kb.txt" | awk '{ printf "%d %d", $1 / 1024, $2 / 1024 }')"
}

median() { sort -g | awk '{ v[NR] = $1 } END { print v[int((NR + 1) / 2)] }'; }

{
  echo "| case | runs | capture-to-pose p50 ms | p99 ms | poses published | frames dropped | RSS early MB | RSS late MB |"
  echo "|---|---|---|---|---|---|---|---|"
  for factor in 1 10; do
    : > "results-$factor.txt"
    for run in $(seq 1 "$RUNS"); do one_run "$factor" "$run" >> "results-$factor.txt"; done
    row="| $([ "$factor" = 1 ] && echo "camera alone (30 msg/s)" || echo "flood x$factor ($((factor * 30)) msg/s)") | $RUNS"
    for column in 1 2 3 4 5 6; do
      row="$row | $(awk -v c=$column '{ print $c }' "results-$factor.txt" | median)"
    done
    echo "$row |"
  done
} | tee results.md
