#!/usr/bin/env bash
# lcm-spy decodes every slamd type: slamd-lcmtypes.jar holds a class for each type in lcmtypes/;
# slamd-spy (lcm-spy with that jar) starts under Xvfb and finds them all; while slamd runs with
# every output on, each channel's messages decode with lcm-spy's own type database and the
# classes' constructors (SpyDecodeCheck.java, what lcm-spy does for its table); and a screenshot
# of lcm-spy's window is kept in build/test-output/lcm-spy.png.
source "$(dirname "$0")/lib.sh"
private_network
cd "$WORK"
JAR=$SLAMD_BIN/../share/java/slamd-lcmtypes.jar
CLASSES=/usr/share/java/lcm.jar:/usr/share/java/jchart2d.jar:$JAR

# A class for every type.
jar tf "$JAR" > jar.txt
types=0
for file in "$SLAMD_SOURCE_DIR"/lcmtypes/*.lcm; do
  package=$(awk '$1 == "package" { sub(";", "", $2); print $2 }' "$file")
  for struct in $(awk '$1 == "struct" { print $2 }' "$file"); do
    grep -qx "$package/$struct.class" jar.txt || fail "slamd-lcmtypes.jar has no $package/$struct.class"
    types=$((types + 1))
  done
done
check "slamd-lcmtypes.jar holds a class for each of the $types types in lcmtypes/"

# The project's exit codes: 0 after --help (lcm-spy's own help exits 1), 2 on a bad option.
"$SLAMD_BIN/slamd-spy" --help > help.txt 2>&1 || fail "slamd-spy --help exited with $?"
grep -q -- "--lcm-url" help.txt || fail "slamd-spy --help does not list lcm-spy's options"
rc=0
"$SLAMD_BIN/slamd-spy" --no-such-option > /dev/null 2>&1 || rc=$?
[ "$rc" -eq 2 ] || fail "slamd-spy --no-such-option exited with $rc, not 2"
check "slamd-spy --help exits 0 and lists lcm-spy's options; a bad option exits 2"

# An X server of our own; lcm-spy with slamd's types on it.
Xvfb -displayfd 3 -screen 0 1280x900x24 -nolisten tcp 3> display.txt 2> xvfb.err &
wait_for 20 "Xvfb to start" test -s display.txt
export DISPLAY=:$(head -1 display.txt)
"$SLAMD_BIN/slamd-spy" > spy.out 2> spy.err &
SPY_PID=$!
wait_for 60 "lcm-spy to load slamd's types" grep -q "Found $types LCM types" spy.out
check "slamd-spy: lcm-spy found all $types types"

javac -nowarn -cp "$CLASSES" -d . "$SLAMD_SOURCE_DIR/tests/daemon/SpyDecodeCheck.java"
java -Djava.net.preferIPv4Stack=true -cp "$CLASSES:." SpyDecodeCheck stop 300 > decoded.txt &
CHECK_PID=$!
wait_for 60 "the decoding check to subscribe" grep -q listening decoded.txt

# slamd with the back end (SLAMD_KEYFRAMES) and its input published (SLAMD_FRAMES); a command
# (SLAMD_COMMAND) asks for a full map (SLAMD_MAP, and the planes on SLAMD_PLANE_MAP) while it
# runs.
"$SLAMD_BIN/slamd" --config "$SLAMD_SOURCE_DIR/config/synthetic.yaml" --log-level warn \
  "${SMALL_CAMERA[@]}" --source synthetic:room --set synthetic.frames=150 \
  --set backend.enabled=true --set daemon.publish_frames=true 2> slamd.log &
SLAMD_PID=$!
wait_for 30 "slamd to publish status" "$SLAMD_BIN/slamd-status" --once --timeout 1 --log-level error
"$SLAMD_BIN/slamd-cmd" --log-level error publish-map
wait $SLAMD_PID || { tail -20 slamd.log; fail "slamd exited with $?"; }
touch stop
wait $CHECK_PID || fail "the decoding check did not finish"
cat decoded.txt

for expected in SLAMD_POSE:slamd.pose_t POSE:bot_core.pose_t SLAMD_ODOMETRY:slamd.odometry_t \
    SLAMD_STATUS:slamd.status_t SLAMD_MAP_UPDATE:slamd.voxel_map_update_t \
    SLAMD_MAP:slamd.voxel_map_t SLAMD_PLANE_MAP:slamd.plane_map_t \
    SLAMD_KEYFRAMES:slamd.keyframe_trajectory_t \
    SLAMD_COMMAND:slamd.command_t SLAMD_FRAMES:slamd.rgbd_frame_t; do
  channel=${expected%%:*} type=${expected#*:}
  line=$(grep "^$channel " decoded.txt) || fail "no message on $channel"
  [ "$(echo "$line" | awk '{ print $2 }')" = "$type" ] || fail "$channel: $line (expected $type)"
  [ "$(echo "$line" | awk '{ print $3 }')" = decoded ] && [ "$(echo "$line" | awk '{ print $4 }')" -ge 1 ] \
    || fail "$channel: $line"
done
# slamd's channels (LCM_SELF_TEST is LCM's own start-up probe, not a typed message).
grep -E '^(SLAMD_[A-Z_]+|POSE) ' decoded.txt > slamd_channels.txt
awk '$6 != 0 { exit 1 }' slamd_channels.txt ||
  fail "undecodable messages: $(awk '$6 != 0' slamd_channels.txt)"
check "every message on slamd's $(wc -l < slamd_channels.txt) channels decoded as its type"

# lcm-spy's window, with its channel table, as the test's picture.
kill -0 $SPY_PID || fail "lcm-spy exited: $(tail -5 spy.err)"
xwd -root -silent | xwdtopnm 2> /dev/null | pnmtopng > lcm-spy.png
[ "$(stat -c %s lcm-spy.png)" -gt 10000 ] || fail "the screenshot is empty ($(stat -c %s lcm-spy.png) bytes)"
mkdir -p "$SLAMD_BIN/../test-output"
cp lcm-spy.png "$SLAMD_BIN/../test-output/lcm-spy.png"
check "screenshot of lcm-spy: build/test-output/lcm-spy.png ($(stat -c %s lcm-spy.png) bytes)"
