#!/usr/bin/env bash
# `make soak` (issue 24): slamd for minutes, not seconds. Plays TUM fr1/xyz forward, then
# backward, LAPS times (default 10 laps: 7980 frames, 4.4 minutes) in real time with mapping and
# the back end on, and records over time, once a second:
#   - slamd's resident memory (VmRSS from /proc);
#   - from SLAMD_STATUS: keyframes, loops, map voxels (occupied, all), capture-to-pose p50/p99 of
#     the last second, and each stage's p99 (mapping, backend).
# Writes OUT/soak.json (the series, per-lap and per-minute summaries, ATE) and OUT/soak.svg (the
# series plotted against time, lap ends marked).
#
# The ping-pong sequence is a TUM folder of lists only: its rgb/ and depth/ are links to the
# frames played (an uncompressed copy of fr1/xyz, below), and every lap keeps the original's
# frame spacing (reversed on backward laps), so laps join without a jump in time or pose. Its
# ground truth is the original's, mapped the same way.
#
# Usage: scripts/bench-soak.sh [BUILD_DIR]. Environment: SLAMD_DATA_DIR (../shared/data),
# SLAMD_SOAK_OUT (out/soak), SLAMD_SOAK_LAPS (10), SLAMD_SOAK_SET (extra --set assignments,
# space separated), SLAMD_SOAK_IMAGES (uncompressed; png plays the benchmark's PNGs). Needs
# python3 for the summary and the plot. Runs LCM inside a private network namespace when run as
# root.
set -euo pipefail
BUILD_DIR=$(cd "${1:-build}" && pwd)
BIN="$BUILD_DIR/bin"
ROOT=$(cd "$(dirname "$0")/.." && pwd)
DATA=${SLAMD_DATA_DIR:-$ROOT/../shared/data}
OUT=${SLAMD_SOAK_OUT:-$ROOT/out/soak}
LAPS=${SLAMD_SOAK_LAPS:-10}
EXTRA_SET=${SLAMD_SOAK_SET:-}
SOURCE_DIR="$DATA/tum_fr1_xyz"

if [ ! -f "$SOURCE_DIR/rgb.txt" ]; then
  echo "soak: skipped: $SOURCE_DIR (TUM fr1/xyz) is not here; set SLAMD_DATA_DIR" >&2
  exit 0
fi
for program in slamd slamd-export slamd-eval slamd-play; do
  [ -x "$BIN/$program" ] || { echo "soak: $BIN/$program is not built" >&2; exit 1; }
done
command -v python3 > /dev/null || { echo "soak: python3 is needed for the summary" >&2; exit 1; }
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)

# --- the frames, decoded once -------------------------------------------------------------------
# A camera delivers decoded images. The benchmark's PNGs cost 6.4 ms of CPU a frame to inflate
# (bench_capture, BM_TumJpegPngDecode), a fifth of a core at 30 Hz that would compete with
# tracking and be charged to slamd. Like `make run`, the soak plays an uncompressed copy (PPM/PGM,
# the same pixels and time stamps, 1.2 GB), made once in OUT and kept. SLAMD_SOAK_IMAGES=png plays
# the PNGs themselves.
IMAGES=${SLAMD_SOAK_IMAGES:-uncompressed}
case "$IMAGES" in
  png) FRAMES_DIR="$SOURCE_DIR" ;;
  uncompressed)
    FRAMES_DIR="$OUT/fr1_xyz_uncompressed"
    if [ "$(cat "$FRAMES_DIR/.made_from" 2> /dev/null)" != "$SOURCE_DIR" ]; then
      echo "soak: decoding $SOURCE_DIR into $FRAMES_DIR (once)"
      rm -rf "$FRAMES_DIR"
      "$BIN/slamd-play" --config "$ROOT/config/tum_fr1.yaml" --source "tum:$SOURCE_DIR" \
        --write-tum "$FRAMES_DIR" --images uncompressed --log-level warn \
        --set capture.preprocess.range_gate=false --set capture.preprocess.flying_pixels=false \
        --set capture.preprocess.bilateral=false 2> "$OUT/decode.log" ||
        { echo "soak: decoding failed (see $OUT/decode.log)" >&2; exit 1; }
      echo "$SOURCE_DIR" > "$FRAMES_DIR/.made_from"
    fi ;;
  *) echo "soak: SLAMD_SOAK_IMAGES is uncompressed or png, not $IMAGES" >&2; exit 1 ;;
esac

# --- the ping-pong sequence ---------------------------------------------------------------------
SEQUENCE="$OUT/fr1_xyz_pingpong_$LAPS"
rm -rf "$SEQUENCE"
mkdir -p "$SEQUENCE"
ln -s "$FRAMES_DIR/rgb" "$SEQUENCE/rgb"
ln -s "$FRAMES_DIR/depth" "$SEQUENCE/depth"
# Lap k (0-based) maps an original time t to start + k * (span + gap) + (t - first) forward, or
# + (last - t) backward, where first and last bound the rgb and depth stamps.
bounds=$(grep -hv '^#' "$FRAMES_DIR/rgb.txt" "$FRAMES_DIR/depth.txt" |
  awk 'NR == 1 { lo = $1; hi = $1 } { if ($1 < lo) lo = $1; if ($1 > hi) hi = $1 }
       END { printf "%.6f %.6f\n", lo, hi }')
read -r FIRST LAST <<< "$bounds"
remap() {  # FILE: the lists' lines for all laps, sorted by the new time
  grep -v '^#' "$1" | awk -v laps="$LAPS" -v first="$FIRST" -v last="$LAST" '
    { line[NR] = $0; stamp[NR] = $1 }
    END {
      gap = 1.0 / 30.0; span = last - first
      for (k = 0; k < laps; ++k) {
        base = first + k * (span + gap)
        for (i = 1; i <= NR; ++i) {
          t = (k % 2 == 0) ? base + (stamp[i] - first) : base + (last - stamp[i])
          if (t < base - 1e-9 || t > base + span + 1e-9) continue
          rest = line[i]; sub(/^[^ ]+ /, "", rest)
          printf "%.6f %s\n", t, rest
        }
      }
    }' | sort -n -k1,1
}
{ echo "# fr1/xyz played forward then backward, $LAPS laps"; remap "$FRAMES_DIR/rgb.txt"; } > "$SEQUENCE/rgb.txt"
{ echo "# fr1/xyz played forward then backward, $LAPS laps"; remap "$FRAMES_DIR/depth.txt"; } > "$SEQUENCE/depth.txt"
{ echo "# fr1/xyz ground truth, mapped like the frames"; remap "$FRAMES_DIR/groundtruth.txt"; } > "$SEQUENCE/groundtruth.txt"
FRAMES=$(grep -vc '^#' "$SEQUENCE/rgb.txt")
LAP_SECONDS=$(awk -v a="$FIRST" -v b="$LAST" 'BEGIN { printf "%.3f", b - a + 1.0 / 30.0 }')
echo "soak: $FRAMES frames ($LAPS laps of fr1/xyz, ${LAP_SECONDS} s each) in real time; output in $OUT"

# --- the run --------------------------------------------------------------------------------------
soak_run() {
  cd "$OUT"
  rm -f soak.lcmlog rss.tsv threads.tsv threads.prev trajectory.txt metrics.json
  lcm-logger --quiet --channel='SLAMD_STATUS' soak.lcmlog > logger.txt 2>&1 &
  local logger=$!
  local sets=(--set capture.pacing.mode=realtime --set backend.enabled=true)
  for assignment in $EXTRA_SET; do sets+=(--set "$assignment"); done
  "$BIN/slamd" --config "$ROOT/config/tum_fr1.yaml" --source "tum:$SEQUENCE" "${sets[@]}" \
    --log-level warn --trajectory-out trajectory.txt --metrics-out metrics.json 2> slamd.log &
  local slamd=$!
  local start_ns
  start_ns=$(date +%s%N)
  # Besides RSS, the CPU time of the whole machine and of slamd over each interval, in cores: a
  # second where slamd's stages take far longer than their CPU time while neither is busy points
  # at the host, not at slamd.
  echo -e "t_s\trss_kb\tmachine_busy_cores\tslamd_cores" > rss.tsv
  local ticks cores prev_busy=0 prev_total=0 prev_slamd=0 prev_ns=$start_ns
  ticks=$(getconf CLK_TCK)
  cores=$(nproc)
  # And each of slamd's threads (the pipeline names them slamd:STAGE): which ones ran together
  # in a slow second.
  echo -e "t_s\ttid\tthread\tcores" > threads.tsv
  : > threads.prev
  while kill -0 $slamd 2> /dev/null; do
    local rss_kb now_ns busy total slamd_ticks
    rss_kb=$(awk '/^VmRSS:/ { print $2 }' "/proc/$slamd/status" 2> /dev/null || true)
    now_ns=$(date +%s%N)
    read -r busy total < <(awk '/^cpu / { t = 0; for (i = 2; i <= 9; ++i) t += $i;
                                           print t - $5 - $6, t }' /proc/stat)
    slamd_ticks=$(awk '{ sub(/^.*\) /, ""); print $12 + $13 }' "/proc/$slamd/stat" 2> /dev/null || echo 0)
    if [ -n "$rss_kb" ]; then
      awk -v t="$(( (now_ns - start_ns) / 1000000 ))" -v rss="$rss_kb" -v b="$busy" -v pb="$prev_busy" \
          -v tot="$total" -v pt="$prev_total" -v c="$cores" -v s="$slamd_ticks" -v ps="$prev_slamd" \
          -v dt="$(( now_ns - prev_ns ))" -v hz="$ticks" 'BEGIN {
            machine = (tot > pt && pt > 0) ? c * (b - pb) / (tot - pt) : 0
            own = (dt > 0 && ps > 0) ? (s - ps) / hz / (dt * 1e-9) : 0
            printf "%se-3\t%s\t%.3f\t%.3f\n", t, rss, machine, own }' >> rss.tsv
    fi
    awk -v t="$(( (now_ns - start_ns) / 1000000 ))" -v hz="$ticks" \
        -v dt="$(awk -v a="$now_ns" -v b="$prev_ns" 'BEGIN { print (a - b) * 1e-9 }')" '
      FNR == NR { previous[$1] = $2; next }
      {
        name = $0; sub(/^[^(]*\(/, "", name); sub(/\)[^)]*$/, "", name); gsub(/[ \t]/, "_", name)
        rest = $0; sub(/^.*\) /, "", rest); split(rest, field, " ")
        used = field[12] + field[13]
        print $1, used > "threads.prev.new"
        if (($1 in previous) && dt > 0)
          printf "%se-3\t%s\t%s\t%.3f\n", t, $1, name, (used - previous[$1]) / hz / dt >> "threads.tsv"
      }' threads.prev /proc/$slamd/task/*/stat 2> /dev/null || true
    [ -f threads.prev.new ] && mv threads.prev.new threads.prev
    prev_busy=$busy prev_total=$total prev_slamd=$slamd_ticks prev_ns=$now_ns
    sleep 1
  done
  local rc=0
  wait $slamd || rc=$?
  sleep 0.5
  kill -INT $logger 2> /dev/null || true
  wait $logger 2> /dev/null || true
  return $rc
}
export -f soak_run
export BIN ROOT OUT SEQUENCE EXTRA_SET
if [ "$(id -u)" = 0 ] && unshare -n true 2> /dev/null; then
  unshare -n bash -c 'ip link set lo up && ip route add 224.0.0.0/4 dev lo && soak_run'
else
  soak_run
fi

cd "$OUT"
"$BIN/slamd-export" --log-level warn --status-csv status.csv soak.lcmlog
"$BIN/slamd-eval" --json ate "$SEQUENCE/groundtruth.txt" trajectory.txt > ate.json
python3 "$ROOT/scripts/soak-report.py" --out "$OUT" --laps "$LAPS" --lap-seconds "$LAP_SECONDS" \
  --frames "$FRAMES" --images "$IMAGES"
