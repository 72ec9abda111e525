#!/usr/bin/env bash
# A full disk under the map: a tmpfs in a private mount namespace holds the snapshot and the map.
# The disk fills up while slamd runs: each failed snapshot is logged with the system's reason, the
# previous snapshot stays intact, the map stays in memory, and the snapshot is retried (1, 2,
# 4 s ...). Once space is freed the next retry writes it, and the final map is saved at exit.
if [ -z "${SLAMD_IN_MOUNT_NS:-}" ]; then
  export SLAMD_IN_MOUNT_NS=1
  # In a chroot (a fresh-machine test) the root is not a mount point, so unshare cannot make all
  # mounts private; the namespace then keeps their propagation, and the tmpfs is unmounted on
  # exit below so that nothing is left behind either way.
  if unshare -m true 2> /dev/null; then
    exec unshare -m bash "$0" "$@"
  fi
  exec unshare -m --propagation unchanged bash "$0" "$@"
fi
source "$(dirname "$0")/lib.sh"
private_network
cd "$WORK"
mkdir -p disk
mount -t tmpfs -o size=4m slamd-full-disk disk || fail "cannot mount a tmpfs"
trap 'stop_background_jobs; umount -l "$WORK/disk" 2> /dev/null || true' EXIT
# The mapping thread writes the snapshots: not niced, so that a machine loaded by other tests (and
# the sanitizers) does not starve it before the run ends.
"$SLAMD_BIN/slamd" --config "$SLAMD_SOURCE_DIR/config/synthetic.yaml" --log-level info \
  "${SMALL_CAMERA[@]}" --source synthetic:room --set synthetic.frames=450 \
  --set capture.pacing.mode=realtime --set mapping.snapshot_path="$WORK/disk/snapshot.bt" \
  --set mapping.snapshot_period_s=1 --set daemon.mapping_nice=0 \
  --map-out "$WORK/disk/final.bt" 2> slamd.log &
SLAMD_PID=$!
wait_for 30 "the first snapshot" test -s disk/snapshot.bt
sleep 0.2  # let the rename finish before hashing
before=$(sha1sum < disk/snapshot.bt)
dd if=/dev/zero of=disk/filler bs=64k 2> /dev/null || true  # fills the disk
wait_for 20 "a failed snapshot" grep -q "map snapshot failed.*No space left on device" slamd.log
check "a full disk is reported: $(grep -m1 -o 'map snapshot failed.*' slamd.log)"
[ "$(sha1sum < disk/snapshot.bt)" = "$before" ] || fail "the previous snapshot changed"
convert_octree disk/snapshot.bt snapshot_check.ot > /dev/null || fail "the previous snapshot does not load"
ls disk/*.tmp 2> /dev/null && fail "a temporary file was left on the full disk"
check "the previous snapshot is intact and loads; no temporary file left"
rm disk/filler
wait_for 20 "the snapshot retried" grep -q "map snapshot written again" slamd.log
check "after space was freed the snapshot was retried and written"
status=0
wait $SLAMD_PID || status=$?
[ $status -eq 0 ] || { tail -20 slamd.log; fail "slamd exited with $status"; }
convert_octree disk/final.bt final_check.ot > /dev/null || fail "the final map does not load"
# The final map holds at least what the last snapshot held; its file can still be somewhat smaller,
# since voxels that became certain are pruned into their parents (half is far beyond that).
[ "$(stat -c %s disk/final.bt)" -ge $(($(stat -c %s disk/snapshot.bt) / 2)) ] ||
  fail "the final map is less than half the size of the last snapshot"
check "the final map was saved at exit and loads ($(stat -c %s disk/final.bt) bytes)"
