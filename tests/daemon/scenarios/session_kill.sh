#!/usr/bin/env bash
# SAVE_SESSION while slamd runs writes a session that loads. kill -9 while a later SAVE_SESSION
# into the same folder is under way leaves a session that still loads (the previous one, or the
# new one if it was complete), and the next save removes what the killed one left behind.
source "$(dirname "$0")/lib.sh"
private_network
cd "$WORK"
mkdir -p maps

start_slamd() {  # LOG: a paced synthetic room with the back end, saving into maps/
  "$SLAMD_BIN/slamd" --config "$SLAMD_SOURCE_DIR/config/synthetic.yaml" --log-level info \
    "${SMALL_CAMERA[@]}" --source synthetic:room --set synthetic.frames=100000 \
    --set capture.pacing.mode=fixed --set capture.pacing.rate_hz=15 \
    --set backend.enabled=true --set daemon.save_dir="$WORK/maps" > "$1" 2>&1 &
  SLAMD_PID=$!
}
session_loads() { "$SLAMD_BIN/slamd-session-info" --verify maps/room > "$1" 2>&1; }
current_generation() { cat maps/room/CURRENT 2> /dev/null || echo none; }

start_pose_log poses.txt
start_slamd slamd-0.log
wait_for 60 "40 poses" has_poses poses.txt 40
"$SLAMD_BIN/slamd-cmd" --log-level error save-session room
wait_for 30 "the first session to be written" grep -q "SAVE_SESSION: session written" slamd-0.log
session_loads info-0.txt || fail "the session saved while running does not load: $(cat info-0.txt)"
grep -q "keyframes" info-0.txt || fail "slamd-session-info printed no keyframes: $(cat info-0.txt)"
check "SAVE_SESSION wrote maps/room ($(current_generation)) while running; it loads"
# A name with a path in it is refused (the folder comes from any peer on the network).
"$SLAMD_BIN/slamd-cmd" --log-level error save-session ../escape
wait_for 10 "the refusal to be logged" grep -q "SAVE_SESSION '../escape' refused" slamd-0.log
[ ! -e escape ] || fail "SAVE_SESSION ../escape wrote outside daemon.save_dir"
check "SAVE_SESSION ../escape refused"
stop_process $SLAMD_PID

# Each round: a new daemon, a save into the same folder, and kill -9 a few milliseconds after
# slamd logs the command (a save takes 30-70 ms here: the back end's and the mapping thread's
# next frame, then the files), so that most kills land inside the save.
interrupted=0
rounds=0
for delay in 0 0.01 0.02 0.035 0.05; do
  before=$(current_generation)
  start_slamd "slamd-$delay.log"
  wait_for 60 "slamd to track" grep -q "running; LCM" "slamd-$delay.log"
  sleep 2  # some keyframes, so that there is something to save
  "$SLAMD_BIN/slamd-cmd" --log-level error save-session room
  # Polled every 2 ms (wait_for's 50 ms would miss most saves), for at most 20 s.
  deadline=$((SECONDS + 20))
  until grep -q "command SAVE_SESSION" "slamd-$delay.log"; do
    [ $SECONDS -lt $deadline ] || fail "slamd never logged the SAVE_SESSION command"
    sleep 0.002
  done
  sleep "$delay"
  kill -KILL $SLAMD_PID
  wait $SLAMD_PID 2> /dev/null || true
  after=$(current_generation)
  rounds=$((rounds + 1))
  session_loads "info-$delay.txt" ||
    fail "after kill -9 ${delay}s into SAVE_SESSION the session does not load: $(cat "info-$delay.txt")"
  leftovers=$(find maps/room -mindepth 1 -maxdepth 1 -name 'generation-*' | wc -l)
  [ "$after" = "$before" ] && interrupted=$((interrupted + 1))
  check "kill -9 ${delay}s after SAVE_SESSION began: CURRENT $before -> $after, $leftovers generation folders; the session loads"
done
# Otherwise the rounds above proved nothing about a kill inside a save.
[ "$interrupted" -ge 1 ] || fail "no kill landed inside a save (all $rounds completed first)"
check "$interrupted of $rounds saves were killed before they completed; the previous session loaded every time"

# A last save completes, and removes every other generation folder.
start_slamd slamd-last.log
wait_for 60 "slamd to track" grep -q "running; LCM" slamd-last.log
sleep 1
"$SLAMD_BIN/slamd-cmd" --log-level error save-session room
wait_for 30 "the last session to be written" grep -q "SAVE_SESSION: session written" slamd-last.log
stop_process $SLAMD_PID
session_loads info-last.txt || fail "the last session does not load: $(cat info-last.txt)"
generations=$(find maps/room -mindepth 1 -maxdepth 1 -name 'generation-*' | wc -l)
[ "$generations" -eq 1 ] || fail "$generations generation folders after a complete save"
check "a complete save leaves one generation ($(current_generation)); it loads"
