#!/usr/bin/env bash
# Issue 25's fast start: from process start to the first pose localised in a loaded fr1-sized
# session, loading and the vocabulary included (target: at most 2 s).
#
# Maps all of TUM fr1/xyz once with the back end on (--session-out), then starts slamd RUNS times
# with --session-in and backend.mode=localize on the same sequence from frame FIRST, played in
# real time as a camera would deliver it, and measures the wall time from launching the process to
# its log line "keyframe N: relocalised against keyframe M" (the back end's first correction into
# the map; the published poses carry it from the next frame on). Prints each run and the median,
# and the session's load time (the daemon's "session ... loaded" line).
#
# Usage: scripts/bench-session-start.sh [BUILD_DIR]. Environment: SLAMD_DATA_DIR (../shared/data),
# SLAMD_BENCH_OUT (out/session-start), RUNS (5), FIRST (400).
set -euo pipefail
BUILD_DIR=$(cd "${1:-build}" && pwd)
BIN="$BUILD_DIR/bin"
ROOT=$(cd "$(dirname "$0")/.." && pwd)
DATA=${SLAMD_DATA_DIR:-$ROOT/../shared/data}
OUT=${SLAMD_BENCH_OUT:-$ROOT/out/session-start}
RUNS=${RUNS:-5}
FIRST=${FIRST:-400}
SEQUENCE="$DATA/tum_fr1_xyz"
if [ ! -f "$SEQUENCE/rgb.txt" ]; then
  echo "bench-session-start: $SEQUENCE not found (set SLAMD_DATA_DIR); nothing measured" >&2
  exit 0
fi
mkdir -p "$OUT"
COMMON=(--config "$ROOT/config/tum_fr1.yaml" --lcm-url memq:// --set backend.enabled=true)

"$BIN/slamd" "${COMMON[@]}" --source "tum:$SEQUENCE" --session-out "$OUT/session" \
  --log-level warn > "$OUT/map.log" 2>&1
"$BIN/slamd-session-info" "$OUT/session" | sed 's/^/  /'

# Milliseconds since the epoch of a log line's HH:MM:SS.mmm (today, UTC as the daemon logs it).
line_ms() {
  local clock
  clock=$(awk '{ print $1; exit }' <<< "$1")
  date -u -d "$(date -u +%F) $clock" +%s%3N
}

results=()
for run in $(seq 1 "$RUNS"); do
  log="$OUT/localize-$run.log"
  start_ms=$(date -u +%s%3N)
  "$BIN/slamd" "${COMMON[@]}" --source "tum:$SEQUENCE" --session-in "$OUT/session" \
    --set backend.mode=localize --set capture.tum.first_frame="$FIRST" \
    --set capture.tum.frame_count=90 --set capture.pacing.mode=realtime \
    --log-level info > "$log" 2>&1
  localised=$(grep -m1 "relocalised against keyframe" "$log" || true)
  loaded=$(grep -m1 "slamd: session .* loaded" "$log" || true)
  if [ -z "$localised" ]; then
    echo "run $run: never localised (see $log)"
    continue
  fi
  delay_ms=$(($(line_ms "$localised") - start_ms))
  load_ms=$(($(line_ms "$loaded") - start_ms))
  echo "run $run: session loaded ${load_ms} ms, first localised pose ${delay_ms} ms after start"
  results+=("$delay_ms")
done
[ ${#results[@]} -gt 0 ] || exit 1
median=$(printf '%s\n' "${results[@]}" | sort -n | awk '{ a[NR] = $1 } END { print a[int((NR + 1) / 2)] }')
echo "start to first localised pose: median ${median} ms over ${#results[@]} runs (target 2000 ms)"
