# Helpers for the daemon scenarios. Each scenario runs inside its own network namespace
# (`unshare -n`, started by the test), so LCM multicast stays on a private loopback.
# Environment from the test: SLAMD_BIN (build/bin), SLAMD_SOURCE_DIR, WORK (empty temp dir).
set -euo pipefail

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
