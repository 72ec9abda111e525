#!/usr/bin/env bash
# Signals other than SIGINT, and a log reader that goes away: slamd still drains, writes its
# trajectory and map, and exits 0 (hostile-input issue, row 9: exit 141, 129 and 138 before).
source "$(dirname "$0")/lib.sh"
private_network
cd "$WORK"
run_slamd() {  # OUT_PREFIX FRAMES [slamd options...]; only in a subshell (pipe or background)
  local prefix=$1 frames=$2
  shift 2
  exec "$SLAMD_BIN/slamd" --config "$SLAMD_SOURCE_DIR/config/synthetic.yaml" "${SMALL_CAMERA[@]}" \
    --source synthetic:room --set synthetic.frames="$frames" \
    --trajectory-out "$prefix-trajectory.txt" --map-out "$prefix-map.bt" "$@"
}

# The log's reader exits after its first line; slamd keeps going without its log.
set +e
run_slamd pipe 60 2>&1 | head -1 > /dev/null
rc=${PIPESTATUS[0]}
set -e
[ "$rc" -eq 0 ] || fail "slamd exited with $rc when its log pipe closed"
[ "$(count_poses pipe-trajectory.txt)" -eq 60 ] || fail "trajectory has $(count_poses pipe-trajectory.txt) poses, expected 60"
[ -s pipe-map.bt ] || fail "map missing"
check "log piped into 'head -1': exit 0, 60 poses and the map written"

for signal in HUP USR1; do
  run_slamd "$signal" 900 --set capture.pacing.mode=realtime --log-level warn &
  pid=$!
  sleep 3
  kill -s "$signal" $pid
  set +e
  wait $pid
  rc=$?
  set -e
  [ $rc -eq 0 ] || fail "slamd exited with $rc after SIG$signal"
  n=$(count_poses "$signal-trajectory.txt")
  [ "$n" -ge 1 ] && [ "$n" -lt 900 ] || fail "SIG$signal: trajectory has $n poses, expected a partial run"
  convert_octree "$signal-map.bt" "$signal-map.ot" > /dev/null || fail "SIG$signal: the map does not load"
  check "SIG$signal mid-run: exit 0, $n poses and a loadable map written"
done
