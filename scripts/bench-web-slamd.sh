#!/usr/bin/env bash
# Does a connected web viewer slow slamd down? (issue 26's target: capture-to-pose p99 at most
# 33 ms while the viewer runs.) Plays make run's rendered room (600 frames, real time) through
# slamd RUNS times alone and RUNS times with slamd-web and a headless Chromium page on it, each
# in a private network namespace, and prints slamd's capture-to-pose p50/p99 (metrics.json) and
# the page's first paint, voxels shown and render rate. SLAMD_EXTRA adds slamd options (the
# default, a 3 cm map, gives the page about 125k voxels). Needs make run's cache (run make run
# once) and chromium-headless-shell. PAGE_NICE (default 0) runs the browser at that niceness: on a
# robot the page is on another machine, and a browser beside slamd on the same 2 cores, drawing
# 100k points in software WebGL, competes with tracking for the CPU.
#
#   bash scripts/bench-web-slamd.sh build        # RUNS=2 OUT=out/bench/web-slamd
set -euo pipefail
BUILD_DIR=$(cd "${1:-build}" && pwd)
ROOT=$(cd "$(dirname "$0")/.." && pwd)
RUNS=${RUNS:-2}
OUT=${OUT:-$ROOT/out/bench/web-slamd}
export SLAMD_EXTRA=${SLAMD_EXTRA:---set mapping.resolution_m=0.03}
export BIN="$BUILD_DIR/bin" CACHE="$BUILD_DIR/run-cache/room-600" CONFIG="$ROOT/config/synthetic.yaml"
export CHROMIUM=/usr/lib/chromium/chromium-headless-shell PAGE_NICE=${PAGE_NICE:-0}
[ -f "$CACHE/rgb.txt" ] || { echo "bench-web-slamd: $CACHE is missing; run make run once" >&2; exit 1; }
[ -x "$CHROMIUM" ] || { echo "bench-web-slamd: chromium-headless-shell is not installed" >&2; exit 1; }
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)

one_run() {  # MODE (alone|viewer) FOLDER, inside its own network namespace
  local mode=$1 folder=$2
  ip link set lo up
  ip route add 224.0.0.0/4 dev lo
  export LCM_DEFAULT_URL="udpm://239.255.76.67:7667?ttl=0&recv_buf_size=4194304"
  rm -rf "$folder"
  mkdir -p "$folder"
  cd "$folder"
  export HOME=$folder
  local web="" page=""
  if [ "$mode" = viewer ]; then
    "$BIN/slamd-web" --port 8080 --client-stats-out client.jsonl --log-level warn 2> web.log &
    web=$!
    sleep 1
    # the browser binary itself: Debian's wrapper script would leave it running when stopped
    nice -n "$PAGE_NICE" "$CHROMIUM" --no-sandbox --enable-unsafe-swiftshader --window-size=1280,800 \
      --user-data-dir="$folder/chromium" --remote-debugging-port=0 http://127.0.0.1:8080/ \
      > page.log 2>&1 &
    page=$!
    sleep 3
  fi
  # shellcheck disable=SC2086  # SLAMD_EXTRA is a list of options
  "$BIN/slamd" --config "$CONFIG" --source "tum:$CACHE" --set capture.pacing.mode=realtime \
    --metrics-out metrics.json $SLAMD_EXTRA 2> slamd.log
  if [ -n "$web" ]; then
    sleep 2  # the page's last reports
    kill -INT "$page" "$web" 2> /dev/null || true
    wait "$web" 2> /dev/null || true
    wait "$page" 2> /dev/null || true
    rm -rf "$folder/chromium"
  fi
}
export -f one_run

for ((run = 1; run <= RUNS; ++run)); do
  for mode in alone viewer; do
    unshare -n bash -c "one_run $mode '$OUT/$mode-$run'"
  done
done

python3 - "$OUT" "$RUNS" <<'PY'
import json, os, statistics, sys
out, runs = sys.argv[1], int(sys.argv[2])
print("| run | slamd alone p50 / p99 | with slamd-web + page p50 / p99 | page: first paint, voxels shown, render fps (median) |")
print("|---|---|---|---|")
for run in range(1, runs + 1):
    alone = json.load(open(os.path.join(out, f"alone-{run}", "metrics.json")))
    viewer = json.load(open(os.path.join(out, f"viewer-{run}", "metrics.json")))
    stats = [json.loads(line) for line in open(os.path.join(out, f"viewer-{run}", "client.jsonl"))]
    page = "no page report"
    if stats:
        page = "%.0f ms, %d, %.1f" % (stats[0].get("first_paint_ms") or -1, stats[-1].get("voxels", 0),
                                      statistics.median(s.get("render_fps", 0) for s in stats))
    print("| %d | %.1f / %.1f ms | %.1f / %.1f ms | %s |" % (
        run, alone["end_to_end_p50_ms"], alone["end_to_end_p99_ms"],
        viewer["end_to_end_p50_ms"], viewer["end_to_end_p99_ms"], page))
PY
