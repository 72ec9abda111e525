#!/usr/bin/env bash
# `make run`: slamd on a built-in synthetic world (no camera, no download), in real time at
# 30 Hz with mapping on, while its clients record the pose stream and rebuild the map from LCM.
# Prints a summary (frames, rate, latency, drops, ATE against the world's exact ground truth) and
# writes the trajectory, the map (.bt) and a trajectory plot into out/run/.
#
# LCM runs inside a private network namespace when possible (root + unshare), so nothing leaves
# this machine; otherwise on the default multicast group with ttl=0 (this host only).
# Environment: SLAMD_RUN_FRAMES (default 600 = 20 s), SLAMD_RUN_SCENE (room|corridor|corridor_loop),
# SLAMD_RUN_OUT (default out/run).
set -euo pipefail
BUILD_DIR=$(cd "${1:-build}" && pwd)
BIN="$BUILD_DIR/bin"
ROOT=$(cd "$(dirname "$0")/.." && pwd)
OUT=${SLAMD_RUN_OUT:-$ROOT/out/run}
FRAMES=${SLAMD_RUN_FRAMES:-600}
SCENE=${SLAMD_RUN_SCENE:-room}
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)
for program in slamd slamd-pose-log slamd-map-save slamd-eval; do
  [ -x "$BIN/$program" ] || { echo "make run: $BIN/$program is not built" >&2; exit 1; }
done

run_inside() {
  set -euo pipefail
  if [ "${SLAMD_PRIVATE_NET:-0}" = 1 ]; then
    ip link set lo up
    ip route add 224.0.0.0/4 dev lo
  fi
  export LCM_DEFAULT_URL="udpm://239.255.76.67:7667?ttl=0"
  cd "$OUT"
  rm -f poses.txt map_from_stream.bt
  "$BIN/slamd-pose-log" --log-level warn --out poses.txt 2> pose-log.txt &
  local pose_log=$!
  "$BIN/slamd-map-save" --log-level warn --out map_from_stream.bt 2> map-save.txt &
  local map_save=$!
  echo "slamd: $FRAMES frames of synthetic:$SCENE at 30 Hz, real time; logs in $OUT/slamd.log"
  local rc=0
  "$BIN/slamd" --config "$ROOT/config/synthetic.yaml" --source "synthetic:$SCENE" \
    --set synthetic.frames="$FRAMES" --set capture.pacing.mode=realtime \
    --trajectory-out trajectory.txt --groundtruth-out groundtruth.txt --map-out map.bt \
    2> slamd.log || rc=$?
  kill -INT $pose_log $map_save 2> /dev/null || true
  wait $pose_log $map_save 2> /dev/null || true
  return $rc
}
export -f run_inside
export BIN ROOT OUT FRAMES SCENE

if [ "$(id -u)" = 0 ] && unshare -n true 2> /dev/null; then
  SLAMD_PRIVATE_NET=1 unshare -n bash -c run_inside
else
  bash -c run_inside
fi

cd "$OUT"
echo
grep -E "slamd: (source|stages|frames|trajectory|map):" slamd.log | sed 's/^[0-9:.]* \[info\] //'
echo
"$BIN/slamd-eval" ate groundtruth.txt trajectory.txt --plot trajectory.png --json > ate.json
"$BIN/slamd-eval" rpe groundtruth.txt trajectory.txt --delta 1 --delta-unit s --json > rpe.json
json() { grep -o "\"$2\": *[-0-9.eE+]*" "$1" | head -1 | sed 's/.*: *//'; }
printf 'ATE RMSE against ground truth: %.4f m over %s poses (max %.4f m)\n' \
  "$(json ate.json rmse)" "$(json ate.json pairs)" "$(json ate.json max)"
echo "clients: $(tail -1 pose-log.txt | sed 's/^slamd-pose-log: //')"
echo "         $(grep -h 'voxels' map-save.txt | tail -1 | sed 's/^slamd-map-save: //')"
echo
echo "written to $OUT:"
echo "  trajectory.txt (TUM), groundtruth.txt, poses.txt (as received over LCM),"
echo "  map.bt (slamd's map), map_from_stream.bt (rebuilt from the LCM stream), trajectory.png,"
echo "  slamd.log"
