#!/usr/bin/env bash
# `make run`: slamd on a built-in synthetic world (no camera, no download), played like a camera
# at 30 Hz in real time with tracking, filter and mapping on, while its clients record the pose
# stream and rebuild the map from LCM. Prints what was captured, tracked and dropped (and why), the
# latency and the ATE against the world's exact ground truth, and writes the trajectory, the map
# (.bt) and a trajectory plot into out/run/.
#
# The world is rendered ahead, once, into a TUM RGB-D folder under the build tree (keyed by the
# renderer binary, config/synthetic.yaml, the scene and the frame count), then replayed in real
# time like a recording. Rendering costs several times a frame period on a loaded 2-core
# machine; a camera costs nothing, so the real-time run measures slamd, not the renderer. For the
# same reason the folder holds uncompressed PPM/PGM images (about 0.9 GB for 600 frames), not PNG:
# inflating a rendered frame's two PNGs costs about 27 ms of CPU on such a machine, more than
# tracking it, where reading PPM/PGM costs about 1.4 ms.
#
# Verdict: PASS when at least 95% of the frames have a measured pose and the ATE is under 1 cm
# (exit 0). DEGRADED (exit 0, with the reasons) when the machine was too slow to keep up but slamd
# still did its job: at least 50% of the frames measured and the ATE under 5 cm. FAIL (exit 1)
# otherwise, or when slamd itself failed. SLAMD_RUN_STRICT=1 makes DEGRADED fail too (CI).
#
# LCM runs inside a private network namespace when possible (root + unshare), so nothing leaves
# this machine; otherwise on the default multicast group with ttl=0 (this host only).
# Environment: SLAMD_RUN_FRAMES (default 600 = 20 s), SLAMD_RUN_SCENE (room|corridor|corridor_loop),
# SLAMD_RUN_OUT (default out/run), SLAMD_RUN_STRICT (0|1), SLAMD_RUN_WEB (1: also start the web
# viewer slamd-web and print its URL; LCM then runs on this host's loopback, not in a private
# namespace, so that a browser here can reach the viewer), SLAMD_RUN_WEB_PORT (default 8080).
set -euo pipefail
BUILD_DIR=$(cd "${1:-build}" && pwd)
BIN="$BUILD_DIR/bin"
ROOT=$(cd "$(dirname "$0")/.." && pwd)
OUT=${SLAMD_RUN_OUT:-$ROOT/out/run}
FRAMES=${SLAMD_RUN_FRAMES:-600}
SCENE=${SLAMD_RUN_SCENE:-room}
STRICT=${SLAMD_RUN_STRICT:-0}
WEB=${SLAMD_RUN_WEB:-0}
WEB_PORT=${SLAMD_RUN_WEB_PORT:-8080}
CONFIG="$ROOT/config/synthetic.yaml"
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)
programs=(slamd slamd-synth slamd-pose-log slamd-map-save slamd-eval)
[ "$WEB" = 1 ] && programs+=(slamd-web)
for program in "${programs[@]}"; do
  [ -x "$BIN/$program" ] || { echo "make run: $BIN/$program is not built" >&2; exit 1; }
done

# --- the world, rendered ahead once ---------------------------------------------------------
CACHE="$BUILD_DIR/run-cache/$SCENE-$FRAMES"
KEY="$(sha1sum "$BIN/slamd-synth" "$CONFIG" | cut -c1-40 | tr '\n' ' ')$SCENE $FRAMES uncompressed"
if [ ! -f "$CACHE/cache.key" ] || [ "$(cat "$CACHE/cache.key")" != "$KEY" ]; then
  echo "make run: rendering $FRAMES frames of synthetic:$SCENE ahead into $CACHE (once)"
  rm -rf "$CACHE" "$CACHE.partial"
  mkdir -p "$(dirname "$CACHE")"
  render_start=$(date +%s)
  if ! "$BIN/slamd-synth" --config "$CONFIG" --scene "$SCENE" --frames "$FRAMES" \
      --images uncompressed --out "$CACHE.partial" --log-level error; then
    echo "make run: FAIL: rendering the world failed" >&2
    exit 1
  fi
  echo "$KEY" > "$CACHE.partial/cache.key"
  mv "$CACHE.partial" "$CACHE"
  echo "make run: rendered in $(( $(date +%s) - render_start )) s"
fi

# --- slamd in real time, with its clients --------------------------------------------------
run_inside() {
  set -euo pipefail
  if [ "${SLAMD_PRIVATE_NET:-0}" = 1 ]; then
    ip link set lo up
    ip route add 224.0.0.0/4 dev lo
  fi
  export LCM_DEFAULT_URL="udpm://239.255.76.67:7667?ttl=0"
  cd "$OUT"
  rm -f poses.txt map_from_stream.bt metrics.json
  "$BIN/slamd-pose-log" --log-level warn --out poses.txt 2> pose-log.txt &
  local pose_log=$!
  "$BIN/slamd-map-save" --log-level warn --out map_from_stream.bt 2> map-save.txt &
  local map_save=$!
  local web=""
  if [ "$WEB" = 1 ]; then
    "$BIN/slamd-web" --log-level warn --port "$WEB_PORT" 2> web.log &
    web=$!
    local waited=0
    until (exec 3<> "/dev/tcp/127.0.0.1/$WEB_PORT") 2> /dev/null; do
      if ! kill -0 $web 2> /dev/null || [ $waited -ge 100 ]; then
        cat web.log >&2
        echo "make run: slamd-web did not start listening on port $WEB_PORT" >&2
        exit 1
      fi
      sleep 0.1
      waited=$((waited + 1))
    done
    echo "slamd-web: open http://127.0.0.1:$WEB_PORT/ in a browser on this machine"
  fi
  echo "slamd: $FRAMES frames of synthetic:$SCENE at 30 Hz, real time; logs in $OUT/slamd.log"
  local rc=0
  "$BIN/slamd" --config "$CONFIG" --source "tum:$CACHE" --set capture.pacing.mode=realtime \
    --trajectory-out trajectory.txt --groundtruth-out groundtruth.txt --map-out map.bt \
    --metrics-out metrics.json 2> slamd.log || rc=$?
  kill -INT $pose_log $map_save 2> /dev/null || true
  wait $pose_log $map_save 2> /dev/null || true
  if [ -n "$web" ]; then
    if [ -t 0 ]; then
      read -r -p "slamd-web still shows the run at http://127.0.0.1:$WEB_PORT/; press Enter to stop it " _ || true
    fi
    kill -INT $web 2> /dev/null || true
    wait $web 2> /dev/null || true
  fi
  return $rc
}
export -f run_inside
export BIN ROOT OUT FRAMES SCENE CONFIG CACHE WEB WEB_PORT

slamd_rc=0
if [ "$WEB" != 1 ] && [ "$(id -u)" = 0 ] && unshare -n true 2> /dev/null; then
  SLAMD_PRIVATE_NET=1 unshare -n bash -c run_inside || slamd_rc=$?
else
  bash -c run_inside || slamd_rc=$?
fi

cd "$OUT"
echo
grep -E "slamd: (source|stages|frames|tracking|drops|vanishing points|trajectory|map):" slamd.log |
  sed 's/^[0-9:.]* \[[a-z]*\] //'
echo
if [ "$slamd_rc" -ne 0 ]; then
  echo "make run: FAIL: slamd exited with $slamd_rc; the end of $OUT/slamd.log:" >&2
  tail -20 slamd.log >&2
  exit 1
fi

json() { grep -o "\"$2\": *[-0-9.eE+a-z]*" "$1" | head -1 | sed 's/.*: *//'; }
tracked=$(json metrics.json poses_tracked)
ate_m=nan
if [ "${tracked:-0}" -gt 0 ] &&
    "$BIN/slamd-eval" ate groundtruth.txt trajectory.txt --plot trajectory.png --json > ate.json &&
    "$BIN/slamd-eval" rpe groundtruth.txt trajectory.txt --delta 1 --delta-unit s --json > rpe.json; then
  ate_m=$(json ate.json rmse)
  printf 'ATE RMSE against ground truth: %.4f m over %s poses (max %.4f m)\n' \
    "$ate_m" "$(json ate.json pairs)" "$(json ate.json max)"
else
  echo "ATE: not computed (no measured pose)"
fi
echo "clients: $(tail -1 pose-log.txt | sed 's/^slamd-pose-log: //')"
echo "         $(grep -h 'voxels' map-save.txt | tail -1 | sed 's/^slamd-map-save: //')"
echo
echo "written to $OUT:"
echo "  trajectory.txt (TUM), groundtruth.txt, poses.txt (as received over LCM),"
echo "  map.bt (slamd's map), map_from_stream.bt (rebuilt from the LCM stream), trajectory.png,"
echo "  metrics.json, slamd.log"
echo

# --- verdict --------------------------------------------------------------------------------
verdict=$(awk -v tracked="${tracked:-0}" -v frames="$FRAMES" -v ate="$ate_m" \
  -v behind="$(json metrics.json frames_behind_schedule)" \
  -v before_tracking="$(json metrics.json frames_dropped_before_tracking)" '
  BEGIN {
    share = tracked / frames
    ate_known = (ate != "nan")
    line = sprintf("%d of %d frames (%.1f%%) have a measured pose", tracked, frames, 100 * share)
    line = line (ate_known ? sprintf(", ATE %.2f cm", 100 * ate) : ", no ATE")
    if (share >= 0.95 && ate_known && ate < 0.01) { print "PASS: " line; exit }
    why = ""
    if (behind > 0) why = why sprintf("; %d frames passed over because capture ran behind real time", behind)
    if (before_tracking > 0) why = why sprintf("; %d frames dropped because tracking was slower than 30 Hz", before_tracking)
    if (why == "") why = "; see the tracking line above"
    if (share >= 0.5 && ate_known && ate < 0.05) print "DEGRADED: " line why " (this machine did not keep up)"
    else print "FAIL: " line why
  }')
echo "make run: $verdict"
case "$verdict" in
  PASS*) exit 0 ;;
  DEGRADED*) [ "$STRICT" = 1 ] && exit 1; exit 0 ;;
  *) exit 1 ;;
esac
