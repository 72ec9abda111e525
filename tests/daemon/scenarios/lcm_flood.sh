#!/usr/bin/env bash
# An LCM flood: a camera at 30 Hz on SLAMD_FRAMES plus, in every frame period, nine more
# messages (three more valid frames, three malformed frames, a refused SAVE_MAP, a malformed and
# a valid command): ten times the normal message rate, for 10 s (slamd-test-flood). slamd keeps
# publishing poses, counts what it rejects and drops, and its memory grows no more than with the
# camera alone. The latency it keeps under the flood is a measurement
# (scripts/bench-lcm-flood.sh, part of make bench), not asserted here.
source "$(dirname "$0")/lib.sh"
private_network
cd "$WORK"
CONFIG="$SLAMD_SOURCE_DIR/config/synthetic.yaml"
"$SLAMD_BIN/slamd-synth" --config "$CONFIG" --log-level warn "${SMALL_CAMERA[@]}" --scene room \
  --frames 300 --out frames > /dev/null
mkdir -p maps
run_case() { flood_run "$1" "$1" frames 10 "${SMALL_CAMERA[@]}" --set daemon.save_dir="$WORK/maps"; }
growth_kb() { rss_quarters "$1" | awk '{ print $2 - $1 }'; }

run_case 1
run_case 10
cat 10/flood.txt
check "slamd survived 10 s of 300 messages/s and exited cleanly"
cd 10
published=$(json_number metrics.json poses_published)
tracked=$(json_number metrics.json poses_tracked)
malformed=$(json_number metrics.json malformed_commands)
refused=$(json_number metrics.json commands_refused)
errors=$(json_number metrics.json errors)
drops=$(json_number metrics.json drops)
p50=$(json_number metrics.json end_to_end_p50_ms)
p99=$(json_number metrics.json end_to_end_p99_ms)
cd ..
# The camera sent 300 frames and the flood 900 more valid ones; loopback multicast may lose a few.
[ "$published" -ge 250 ] || fail "only $published poses published"
[ "$tracked" -ge 200 ] || fail "only $tracked poses measured"
[ "$malformed" -ge 250 ] || fail "only $malformed of 300 malformed commands counted"
[ "$refused" -ge 250 ] || fail "only $refused of 300 SAVE_MAP outside the save folder refused"
[ "$errors" -ge 100 ] || fail "only $errors malformed frames counted as errors"
[ -z "$(ls maps)" ] || fail "a refused SAVE_MAP wrote into maps/: $(ls maps)"
check "poses published $published (measured $tracked); counted: $malformed malformed commands, $refused refused, $errors bad frames, $drops frames dropped; capture-to-pose p50 $p50 ms, p99 $p99 ms"

# Memory is flat: under the flood it grows no more than with the camera alone (the map grows as
# the camera explores the room) plus 15 MB; a leak of even 10 kB per flood message would be 27 MB.
alone=$(growth_kb 1/rss_kb.txt)
flood=$(growth_kb 10/rss_kb.txt)
[ "$(wc -l < 10/rss_kb.txt)" -ge 20 ] || fail "too few memory samples"
[ $((flood - alone)) -le 15360 ] ||
  fail "memory grew $flood kB under the flood, $alone kB with the camera alone"
check "memory under the flood grew $flood kB over the run, with the camera alone $alone kB"
