#!/usr/bin/env bash
# Malformed messages on SLAMD_COMMAND and on the frame channel: slamd keeps running and counts
# them. SLAMD_COMMAND SAVE_MAP writes a loadable map while slamd runs.
source "$(dirname "$0")/lib.sh"
private_network
cd "$WORK"
start_pose_log poses.txt
mkdir -p maps
"$SLAMD_BIN/slamd" --config "$SLAMD_SOURCE_DIR/config/synthetic.yaml" --log-level warn \
  "${SMALL_CAMERA[@]}" --source lcm:SLAMD_FRAMES --trajectory-out trajectory.txt \
  --set daemon.save_dir="$WORK/maps" &
SLAMD_PID=$!
wait_for 20 "slamd to publish status" "$SLAMD_BIN/slamd-status" --once --timeout 1 --log-level error
# A frame feeder: slamd-play republishes a synthetic sequence at 15 Hz on SLAMD_FRAMES.
"$SLAMD_BIN/slamd-play" --config "$SLAMD_SOURCE_DIR/config/synthetic.yaml" --log-level warn \
  "${SMALL_CAMERA[@]}" --source synthetic:room --set synthetic.frames=900 \
  --set capture.pacing.mode=fixed --set capture.pacing.rate_hz=15 --publish > play.log 2>&1 &
PLAY_PID=$!
wait_for 60 "10 poses" has_poses poses.txt 10

"$SLAMD_BIN/slamd-status" --log-level warn > status-watch.txt 2>&1 &
STATUS_PID=$!
"$SLAMD_BIN/slamd-test-inject" SLAMD_COMMAND 30 1
"$SLAMD_BIN/slamd-test-inject" SLAMD_FRAMES 30 2
# Every fourth message is a string length of INT32_MIN: once a SIGSEGV in slamd (on
# SLAMD_COMMAND), slamd-pose-log (SLAMD_POSE) and slamd-status (SLAMD_STATUS).
"$SLAMD_BIN/slamd-test-inject" SLAMD_POSE 8 3
"$SLAMD_BIN/slamd-test-inject" SLAMD_STATUS 8 4
before=$(count_poses poses.txt)
wait_for 30 "poses after the garbage" has_poses poses.txt $((before + 20))
kill -0 $SLAMD_PID || fail "slamd died after malformed messages"
kill -0 $POSE_LOG_PID || fail "slamd-pose-log died after malformed messages"
kill -0 $STATUS_PID || fail "slamd-status died after malformed messages"
stop_process $STATUS_PID
check "slamd kept tracking after 60 malformed messages; slamd-pose-log and slamd-status survived 8 each"
# Every malformed frame is counted: rejected by the decoder (capture errors) or, when a burst
# overflows the source's receive queue before decoding, dropped (capture drops). Status is 1 Hz.
capture_counted() {
  "$SLAMD_BIN/slamd-status" --once --timeout 3 --log-level error > status.txt
  local errors drops
  errors=$(awk '$1 == "capture" { print $8 }' status.txt)
  drops=$(awk '$1 == "capture" { print $7 }' status.txt)
  [ "${errors:-0}" -ge 1 ] && [ $((${errors:-0} + ${drops:-0})) -ge 30 ] &&
    grep -q "30 malformed" status.txt
}
wait_for 20 "status to count the 30 malformed commands and 30 malformed frames" capture_counted
check "status counts them: $(grep -o '[0-9]* malformed[a-z ]*' status.txt | head -1); capture errors $(awk '$1 == "capture" { print $8 }' status.txt), drops $(awk '$1 == "capture" { print $7 }' status.txt)"

"$SLAMD_BIN/slamd-cmd" --log-level error save-map "$WORK/maps/live.bt"
"$SLAMD_BIN/slamd-cmd" --log-level error save-map named.bt
wait_for 20 "maps/live.bt and maps/named.bt to be written" \
  bash -c "test -s '$WORK/maps/live.bt' && test -s '$WORK/maps/named.bt'"
kill -0 $SLAMD_PID || fail "slamd stopped after SAVE_MAP"
convert_octree maps/live.bt live_check.ot > /dev/null || fail "live.bt does not load"
check "SAVE_MAP wrote loadable maps into daemon.save_dir while slamd keeps running"

# Paths outside daemon.save_dir are refused, counted and logged; nothing is written.
for path in "$WORK/escape.bt" ../escape2.bt /etc/slamd-escape.bt; do
  "$SLAMD_BIN/slamd-cmd" --log-level error save-map "$path"
done
refused() {
  "$SLAMD_BIN/slamd-status" --once --timeout 3 --log-level error > status.txt
  grep -q "3 commands refused" status.txt
}
wait_for 20 "status to count 3 refused commands" refused
[ ! -e "$WORK/escape.bt" ] && [ ! -e "$WORK/../escape2.bt" ] && [ ! -e /etc/slamd-escape.bt ] ||
  fail "a refused SAVE_MAP wrote a file"
check "SAVE_MAP outside daemon.save_dir: 3 refused, counted on SLAMD_STATUS, nothing written"

stop_process $PLAY_PID
kill -INT $SLAMD_PID
wait $SLAMD_PID || fail "slamd exited with $? at SIGINT"
check "slamd exited 0"
stop_process $POSE_LOG_PID
