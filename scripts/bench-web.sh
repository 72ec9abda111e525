#!/usr/bin/env bash
# The web viewer under load (issue 26's target: 10 Hz updates with a 100k-voxel map). Inside a
# private network namespace: slamd-web, a headless Chromium page on it, and slamd-web-feeder
# publishing poses at 30 Hz and map updates at 10 Hz that grow the map to VOXELS voxels (in about
# 5 s) and then replace 1000 voxels per update. The page reports every second (client_stats):
# frames rendered, voxel messages received and the longest gap between messages. Prints and
# writes OUT/web.json: the page's first paint, its render rate and voxel-message interval while
# the map was full, the longest gap, and slamd-web's CPU time.
#
#   bash scripts/bench-web.sh build          # VOXELS=100000 SECONDS_RUN=40 OUT=out/bench
set -euo pipefail
BUILD_DIR=$(cd "${1:-build}" && pwd)
BIN="$BUILD_DIR/bin"
ROOT=$(cd "$(dirname "$0")/.." && pwd)
OUT=${OUT:-$ROOT/out/bench}
VOXELS=${VOXELS:-100000}
SECONDS_RUN=${SECONDS_RUN:-40}
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)
for program in slamd-web slamd-web-feeder; do
  [ -x "$BIN/$program" ] || { echo "bench-web: $BIN/$program is not built" >&2; exit 1; }
done
command -v chromium-headless-shell > /dev/null ||
  { echo "bench-web: chromium-headless-shell is not installed" >&2; exit 1; }

inside() {
  set -euo pipefail
  ip link set lo up
  ip route add 224.0.0.0/4 dev lo
  export LCM_DEFAULT_URL="udpm://239.255.76.67:7667?ttl=0&recv_buf_size=4194304"
  local work
  work=$(mktemp -d)
  cd "$work"
  export HOME=$work
  rm -f "$OUT/web-client-stats.jsonl"
  "$BIN/slamd-web" --port 8080 --client-stats-out "$OUT/web-client-stats.jsonl" \
    --log-level warn 2> web.log &
  local web=$!
  sleep 1
  # the browser itself: Debian's chromium-headless-shell script would leave it running when stopped
  local chromium=/usr/lib/chromium/chromium-headless-shell
  [ -x "$chromium" ] || chromium=chromium-headless-shell
  "$chromium" --no-sandbox --enable-unsafe-swiftshader --window-size=1280,800 \
    --user-data-dir="$work/chromium" --remote-debugging-port=0 http://127.0.0.1:8080/ \
    > page.log 2>&1 &
  local page=$!
  sleep 3
  "$BIN/slamd-web-feeder" --voxels "$VOXELS" --seconds "$SECONDS_RUN" --log-level warn
  sleep 2
  local web_cpu_ticks
  web_cpu_ticks=$(awk '{ print $14 + $15 }' /proc/$web/stat)
  echo "$web_cpu_ticks" > "$OUT/web-cpu-ticks.txt"
  kill -INT $page $web 2> /dev/null || true
  wait $web 2> /dev/null || true
  wait $page 2> /dev/null || true
  tail -1 web.log
  rm -rf "$work"
}
export -f inside
export BIN OUT VOXELS SECONDS_RUN
unshare -n bash -c inside

python3 - "$OUT" "$VOXELS" "$SECONDS_RUN" <<'EOF'
import json, os, statistics, sys
out, voxels, seconds = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
stats = [json.loads(line) for line in open(os.path.join(out, "web-client-stats.jsonl"))]
full = [s for s in stats if s.get("voxels", 0) >= 0.98 * voxels]
ticks = int(open(os.path.join(out, "web-cpu-ticks.txt")).read())
result = {
    "voxels_target": voxels,
    "reports": len(stats),
    "reports_with_full_map": len(full),
    "first_paint_ms": stats[0].get("first_paint_ms") if stats else None,
    "render_fps_median_full_map": statistics.median(s["render_fps"] for s in full) if full else None,
    "voxel_message_interval_ms_median_full_map":
        statistics.median(s["mean_voxel_message_interval_ms"] for s in full) if full else None,
    "max_message_gap_ms_full_map": max(s["max_message_gap_ms"] for s in full) if full else None,
    "max_render_ms_full_map": max(s.get("max_render_ms", 0) for s in full) if full else None,
    "voxels_shown_at_end": stats[-1].get("voxels") if stats else None,
    "slamd_web_cpu_s": ticks / os.sysconf("SC_CLK_TCK"),
    "slamd_web_cpu_share": ticks / os.sysconf("SC_CLK_TCK") / (seconds + 6),
}
json.dump(result, open(os.path.join(out, "web.json"), "w"), indent=2)
print(json.dumps(result, indent=2))
EOF
