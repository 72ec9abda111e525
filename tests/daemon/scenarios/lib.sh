# Helpers for the daemon scenarios. Each scenario runs inside its own network namespace
# (`unshare -n`, started by the test), so LCM multicast stays on a private loopback.
# Environment from the test: SLAMD_BIN (build/bin), SLAMD_SOURCE_DIR, WORK (empty temp dir).
set -euo pipefail

# Every client and daemon a scenario starts in the background is stopped when the scenario ends,
# passed or failed: SIGTERM, then SIGKILL after 5 s. Without this a scenario that ends without
# stopping one (or fails first) leaves it running, orphaned, for as long as the machine runs.
stop_background_jobs() {
  local pids
  pids=$(jobs -pr)
  [ -n "$pids" ] || return 0
  kill -TERM $pids 2> /dev/null || true
  local deadline=$((SECONDS + 5))
  while [ $SECONDS -lt $deadline ] && kill -0 $pids 2> /dev/null; do sleep 0.05; done
  kill -KILL $pids 2> /dev/null || true
  wait $pids 2> /dev/null || true
}
trap stop_background_jobs EXIT

private_network() {
  ip link set lo up
  ip route add 224.0.0.0/4 dev lo
  # A 4 MB socket receive buffer (capped by net.core.rmem_max): frame messages of ~100 kB come in
  # bursts, and on a busy machine a subscriber descheduled for a few frames would otherwise
  # overflow the ~200 kB default and lose one (seen once with lcm-logger while 2 builds ran).
  export LCM_DEFAULT_URL="udpm://239.255.76.67:7667?ttl=0&recv_buf_size=4194304"
}

# A 320x240 camera for the synthetic worlds: 4x less rendering and ~100 kB frame messages, so the
# scenarios stay quick on a loaded 2-core machine and loopback multicast never drops fragments.
SMALL_CAMERA=(--set camera.width=320 --set camera.height=240 --set camera.fx=262.5
              --set camera.fy=262.5 --set camera.cx=159.5 --set camera.cy=119.5)

fail() { echo "FAIL: $*" >&2; exit 1; }
check() { echo "ok: $*"; }

# wait_for SECONDS DESCRIPTION COMMAND...: polls COMMAND every 50 ms until it succeeds; fails the
# scenario at the deadline. Synchronises on observable conditions, never on fixed sleeps.
wait_for() {
  local seconds=$1 description=$2
  shift 2
  local deadline=$((SECONDS + seconds))
  until "$@" > /dev/null 2>&1; do
    [ $SECONDS -lt $deadline ] || fail "timed out after ${seconds}s waiting for: $description"
    sleep 0.05
  done
}

# Starts lcm-logger on FILE and waits until it demonstrably records (a ping shows up in the file).
start_logger() {
  local file=$1
  lcm-logger -q -f --flush-interval=50 "$file" &
  LOGGER_PID=$!
  logger_has_ping() {
    "$SLAMD_BIN/slamd-cmd" --log-level error --set channels.command=SLAMD_TEST_PING pause \
      > /dev/null
    [ -s "$file" ] && "$SLAMD_BIN/slamd-log-info" --json "$file" | grep -q SLAMD_TEST_PING
  }
  wait_for 10 "lcm-logger to record" logger_has_ping
}

stop_process() {  # PID: SIGINT and wait (ignoring its exit status)
  kill -INT "$1" 2> /dev/null || true
  wait "$1" 2> /dev/null || true
}

# Starts slamd-pose-log writing FILE and waits until it is subscribed.
start_pose_log() {
  local file=$1
  shift
  "$SLAMD_BIN/slamd-pose-log" --out "$file" "$@" 2> "$file.stderr" &
  POSE_LOG_PID=$!
  wait_for 10 "slamd-pose-log to subscribe" grep -q recording "$file.stderr"
}

# Number of poses in a TUM file (non-comment lines).
count_poses() { grep -vc '^#' "$1" 2> /dev/null || true; }
# has_poses FILE N: FILE holds at least N poses (for wait_for, which re-runs it on every poll).
has_poses() { [ "$(count_poses "$1")" -ge "$2" ]; }

# JSON field of a flat object printed by slamd-eval / slamd-log-info: json_number FILE KEY
json_number() { grep -o "\"$2\": *[-0-9.eE+]*" "$1" | head -1 | sed 's/.*: *//'; }

# Messages on CHANNEL in an LCM log (via slamd-log-info --json).
log_count() {
  "$SLAMD_BIN/slamd-log-info" --json "$1" |
    grep -o "\"$2\": {\"messages\": [0-9]*" | sed 's/.*: //' || echo 0
}

# a <= b for decimals
less_equal() { awk -v a="$1" -v b="$2" 'BEGIN { exit !(a <= b) }'; }

# flood_run DIR FACTOR FRAMES SECONDS [SLAMD ARGS...]: slamd on lcm:SLAMD_FRAMES while
# slamd-test-flood publishes the TUM folder FRAMES for SECONDS at FACTOR messages per frame
# period (1 = the camera alone). Leaves DIR/metrics.json, DIR/rss_kb.txt (slamd's resident memory
# every 0.25 s), DIR/flood.txt and DIR/slamd.log; fails when slamd does not exit cleanly.
# CONFIG names the configuration file.
flood_run() {
  local dir=$1 factor=$2 frames=$3 seconds=$4
  shift 4
  mkdir -p "$dir"
  "$SLAMD_BIN/slamd" --config "$CONFIG" --log-level warn "$@" --source lcm:SLAMD_FRAMES \
    --metrics-out "$dir/metrics.json" 2> "$dir/slamd.log" &
  local pid=$!
  wait_for 20 "slamd to publish status" "$SLAMD_BIN/slamd-status" --once --timeout 1 --log-level error
  # Memory is sampled from the moment the publisher starts (after it has encoded its frames).
  rm -f "$dir/publishing"
  (while kill -0 $pid 2> /dev/null; do
     [ -e "$dir/publishing" ] && { awk '/VmRSS/ { print $2 }' /proc/$pid/status 2> /dev/null || true; }
     sleep 0.25
   done) > "$dir/rss_kb.txt" &
  local sampler=$!
  "$SLAMD_BIN/slamd-test-flood" --config "$CONFIG" --log-level warn "$@" --source "tum:$frames" \
    --seconds "$seconds" --factor "$factor" --started-file "$dir/publishing" > "$dir/flood.txt"
  kill -INT $pid
  local status=0
  wait $pid || status=$?
  kill $sampler 2> /dev/null || true
  wait $sampler 2> /dev/null || true
  [ $status -eq 0 ] || { tail -20 "$dir/slamd.log"; fail "slamd exited with $status (factor $factor)"; }
}

# rss_quarters FILE: mean resident memory (kB) over the second quarter and over the last quarter
# of the samples in FILE, as "EARLY LATE".
rss_quarters() {
  awk '{ v[NR] = $1 } END { n = NR; for (i = 1; i <= n; i++) {
    if (i > n / 4 && i <= n / 2) { e += v[i]; ne++ } if (i > 3 * n / 4) { l += v[i]; nl++ } }
    printf "%d %d\n", e / ne, l / nl }' "$1"
}
