#!/usr/bin/env bash
# An lcm: source with idle periods: the capture thread sends heartbeats while no frame arrives,
# and the exit summary must count only the real frames (hostile-input issue, row 12: 196
# "published" for 143 received). 12 frames at 2 Hz, about 30 heartbeats in the gaps.
source "$(dirname "$0")/lib.sh"
private_network
cd "$WORK"
"$SLAMD_BIN/slamd" --config "$SLAMD_SOURCE_DIR/config/synthetic.yaml" --log-level warn \
  "${SMALL_CAMERA[@]}" --source lcm:SLAMD_FRAMES --set capture.lcm.idle_end_s=3 \
  --set daemon.heartbeat_period_s=0.1 --metrics-out metrics.json --trajectory-out trajectory.txt &
SLAMD_PID=$!
wait_for 20 "slamd to publish status" "$SLAMD_BIN/slamd-status" --once --timeout 1 --log-level error
"$SLAMD_BIN/slamd-play" --config "$SLAMD_SOURCE_DIR/config/synthetic.yaml" --log-level warn \
  "${SMALL_CAMERA[@]}" --source synthetic:room --set synthetic.frames=12 \
  --set capture.pacing.mode=fixed --set capture.pacing.rate_hz=2 --publish > play.log 2>&1
set +e
wait $SLAMD_PID
rc=$?
set -e
[ $rc -eq 0 ] || fail "slamd exited with $rc"
captured=$(json_number metrics.json frames_captured)
published=$(json_number metrics.json poses_published)
heartbeats=$(grep -o '"heartbeats": *[0-9]*' metrics.json | head -1 | sed 's/.*: *//')
[ "$captured" -eq 12 ] || fail "frames captured: $captured, expected 12"
[ "$published" -eq 12 ] || fail "poses published: $published, expected 12"
[ "${heartbeats:-0}" -ge 10 ] || fail "only ${heartbeats:-0} heartbeats: the idle gaps were not exercised"
check "12 frames with idle gaps: 12 captured, 12 published, $heartbeats heartbeats counted apart"
