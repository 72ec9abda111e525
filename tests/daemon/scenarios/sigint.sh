#!/usr/bin/env bash
# SIGINT mid-run: slamd drains, saves the map and the trajectory, exits 0; both load back.
source "$(dirname "$0")/lib.sh"
private_network
cd "$WORK"
start_pose_log poses.txt
"$SLAMD_BIN/slamd" --config "$SLAMD_SOURCE_DIR/config/synthetic.yaml" --log-level warn \
  "${SMALL_CAMERA[@]}" --source synthetic:room --set synthetic.frames=900 \
  --trajectory-out trajectory.txt --map-out map.bt &
SLAMD_PID=$!
wait_for 60 "30 poses" has_poses poses.txt 30
kill -INT $SLAMD_PID
set +e
wait $SLAMD_PID
rc=$?
set -e
[ $rc -eq 0 ] || fail "slamd exited with $rc after SIGINT"
check "slamd exited 0 after SIGINT"
stop_process $POSE_LOG_PID
n=$(count_poses trajectory.txt)
[ "$n" -ge 30 ] && [ "$n" -lt 900 ] || fail "trajectory has $n poses, expected a partial run"
check "trajectory.txt saved with $n poses"
"$SLAMD_BIN/slamd-eval" ate poses.txt trajectory.txt --align none --json > saved_vs_published.json
less_equal "$(json_number saved_vs_published.json rmse)" 0.000001 || fail "saved trajectory differs from the published poses"
check "saved trajectory equals the published poses"
[ -s map.bt ] || fail "map.bt missing"
convert_octree map.bt map_check.ot > /dev/null || fail "map.bt does not load"
check "map.bt loads back"
