#!/usr/bin/env bash
# slamd-map-save joins a running slamd late, with no periodic full maps: its first update comes
# with a sequence number after others it never saw (as after a message lost on UDP). It asks
# slamd for a full map (PUBLISH_MAP) instead of waiting for one, and ends with a synchronised
# copy of the map. (How many updates follow the full map depends on the machine's speed: under
# the sanitizers slamd may finish first, so they are not counted.) The run lasts 20 s: the status
# counts voxels every 5 s at most, so map-save joins 5-10 s in and must still see updates after,
# however loaded the machine is; the mapping thread, which serves the full map, is not niced (on a
# loaded machine a niced one may not get to it before the run ends).
source "$(dirname "$0")/lib.sh"
private_network
cd "$WORK"

"$SLAMD_BIN/slamd" --config "$SLAMD_SOURCE_DIR/config/synthetic.yaml" --log-level warn \
  "${SMALL_CAMERA[@]}" --source synthetic:room --set synthetic.frames=600 \
  --set capture.pacing.mode=realtime --set mapping.full_map_period_s=0 --set daemon.mapping_nice=0 \
  --map-out map.bt 2> slamd.log &
SLAMD_PID=$!
# Late: the map already holds voxels, so updates have been published before map-save listens.
map_has_voxels() {
  "$SLAMD_BIN/slamd-status" --once --timeout 1 --log-level error > status.txt &&
    grep -Eq "map: [1-9][0-9]* occupied" status.txt
}
wait_for 30 "slamd to map voxels" map_has_voxels
"$SLAMD_BIN/slamd-map-save" --out copy.bt --timeout 3 2> map-save.txt &
SAVE_PID=$!
wait $SLAMD_PID || { tail -20 slamd.log; fail "slamd exited with $?"; }
wait $SAVE_PID || { cat map-save.txt; fail "slamd-map-save exited with $?"; }
cat map-save.txt
grep -q "map copy has a gap: asked slamd for a full map" map-save.txt ||
  fail "slamd-map-save did not ask for a full map after joining late"
grep -Eq "[1-9][0-9]* full maps \([1-9][0-9]* asked for\)" map-save.txt ||
  fail "no full map arrived after slamd-map-save asked for one"
if grep -q "NOT synchronised" map-save.txt; then fail "the copy ended unsynchronised"; fi
check "a late slamd-map-save asked for a full map and got it: its copy ends synchronised"
