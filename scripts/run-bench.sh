#!/usr/bin/env bash
# `make bench`: the benchmark suite. Runs slamd end to end on the shared TUM fr1/xyz sequence (when
# present) and on synthetic worlds, as fast as possible and in real time, then every Google
# Benchmark program (build/bin/bench_*). For each end-to-end case it records frame rate, per-stage
# time p50/p95/p99, capture-to-pose latency, ATE and RPE (1 s) against ground truth, peak RSS and
# CPU time; writes out/bench/results.json and out/bench/results.md; and compares with the
# committed baseline (bench/baseline.json), flagging regressions beyond a tolerance.
#
# Adding a case is one line in CASES below. Environment: SLAMD_DATA_DIR (default ../shared/data),
# SLAMD_BENCH_OUT (out/bench), SLAMD_BENCH_TOLERANCE (0.25 = 25% worse is a regression),
# SLAMD_BENCH_MICRO=0 skips the Google Benchmark programs, SLAMD_BENCH_FLOOD=0 the LCM flood
# benchmark (scripts/bench-lcm-flood.sh), SLAMD_BENCH_CORRIDORS=0 the corridor suite
# (scripts/bench-corridors.sh), SLAMD_BENCH_FAIL_ON_REGRESSION=1 makes a regression fail
# the command.
set -euo pipefail
BUILD_DIR=$(cd "${1:-build}" && pwd)
BIN="$BUILD_DIR/bin"
ROOT=$(cd "$(dirname "$0")/.." && pwd)
DATA=${SLAMD_DATA_DIR:-$ROOT/../shared/data}
OUT=${SLAMD_BENCH_OUT:-$ROOT/out/bench}
TOLERANCE=${SLAMD_BENCH_TOLERANCE:-0.25}
BASELINE="$ROOT/bench/baseline.json"
mkdir -p "$OUT"

# name | config | source | extra --set assignments (space separated) | dataset needed ("" = none)
CASES=(
  "fr1_xyz_fast|tum_fr1.yaml|tum:$DATA/tum_fr1_xyz||tum_fr1_xyz"
  "fr1_xyz_realtime|tum_fr1.yaml|tum:$DATA/tum_fr1_xyz|capture.pacing.mode=realtime|tum_fr1_xyz"
  "fr1_xyz_odometry_realtime|tum_fr1.yaml|tum:$DATA/tum_fr1_xyz|capture.pacing.mode=realtime backend.enabled=false|tum_fr1_xyz"
  "fr1_xyz_fovis_fast|tum_fr1.yaml|tum:$DATA/tum_fr1_xyz|tracking.frontend=fovis backend.enabled=false|tum_fr1_xyz"
  "room_fast|synthetic.yaml|synthetic:room|synthetic.frames=300|"
  "room_lap_slam_fast|synthetic.yaml|synthetic:room|synthetic.trajectory=loop backend.enabled=true|"
  "corridor_lowtexture_fast|synthetic.yaml|synthetic:corridor|synthetic.texture_density=0.2 synthetic.frames=600|"
  "corridor_lowtexture_odometry_only|synthetic.yaml|synthetic:corridor|synthetic.texture_density=0.2 synthetic.frames=600 filter.enabled=false|"
)

json() { grep -o "\"$2\": *[-0-9.eE+]*" "$1" | head -1 | sed 's/.*: *//'; }
stage_json() {  # FILE STAGE KEY: a number inside "stages": {"STAGE": {...}}
  tr -d '\n ' < "$1" | grep -o "\"$2\":{[^}]*}" | grep -o "\"$3\":[-0-9.eE+]*" | sed 's/.*://'
}

SUMMARY="$OUT/summary.txt"  # "case key value" lines, compared with the baseline
: > "$SUMMARY"
echo "[" > "$OUT/results.json.tmp"
first=1
for spec in "${CASES[@]}"; do
  IFS='|' read -r name config source sets dataset <<< "$spec"
  if [ -n "$dataset" ] && [ ! -d "$DATA/$dataset" ]; then
    echo "bench: $name skipped: dataset $dataset not found under $DATA (set SLAMD_DATA_DIR)"
    continue
  fi
  dir="$OUT/$name"
  mkdir -p "$dir"
  args=()
  for assignment in $sets; do args+=(--set "$assignment"); done
  echo "bench: $name ..."
  /usr/bin/time -f "%M %U %S" -o "$dir/time.txt" "$BIN/slamd" --config "$ROOT/config/$config" \
    --source "$source" "${args[@]}" --log-level warn --trajectory-out "$dir/trajectory.txt" \
    --groundtruth-out "$dir/groundtruth.txt" --metrics-out "$dir/metrics.json" 2> "$dir/slamd.log"
  "$BIN/slamd-eval" ate "$dir/groundtruth.txt" "$dir/trajectory.txt" --json > "$dir/ate.json"
  "$BIN/slamd-eval" rpe "$dir/groundtruth.txt" "$dir/trajectory.txt" --delta 1 --delta-unit s \
    --json > "$dir/rpe.json"
  read -r rss_kb user_s system_s < "$dir/time.txt"
  cpu_s=$(awk -v u="$user_s" -v s="$system_s" 'BEGIN { printf "%.2f", u + s }')
  rpe_translation=$(tr -d '\n ' < "$dir/rpe.json" | grep -o '"translation[^}]*' | grep -o '"rmse":[-0-9.eE+]*' | head -1 | sed 's/.*://')
  {
    echo "$name fps $(json "$dir/metrics.json" fps)"
    echo "$name end_to_end_p50_ms $(json "$dir/metrics.json" end_to_end_p50_ms)"
    echo "$name end_to_end_p99_ms $(json "$dir/metrics.json" end_to_end_p99_ms)"
    echo "$name tracking_p50_ms $(stage_json "$dir/metrics.json" tracking p50_ms)"
    echo "$name mapping_p50_ms $(stage_json "$dir/metrics.json" mapping p50_ms)"
    echo "$name ate_rmse_m $(json "$dir/ate.json" rmse)"
    echo "$name rpe_translation_rmse_m ${rpe_translation:-0}"
    echo "$name drops $(json "$dir/metrics.json" drops)"
    echo "$name peak_rss_mb $(awk -v k="$rss_kb" 'BEGIN { printf "%.1f", k / 1024 }')"
    echo "$name cpu_s $cpu_s"
  } >> "$SUMMARY"
  [ $first -eq 1 ] || echo "," >> "$OUT/results.json.tmp"
  first=0
  printf '{"case": "%s", "metrics": %s, "ate": %s, "rpe": %s, "peak_rss_kb": %s, "cpu_s": %s}\n' \
    "$name" "$(cat "$dir/metrics.json")" "$(cat "$dir/ate.json")" "$(cat "$dir/rpe.json")" \
    "$rss_kb" "$cpu_s" >> "$OUT/results.json.tmp"
done
echo "]" >> "$OUT/results.json.tmp"
mv "$OUT/results.json.tmp" "$OUT/results.json"

# Markdown table.
{
  echo "| case | fps | capture-to-pose p50 / p99 ms | tracking p50 ms | mapping p50 ms | ATE RMSE m | RPE 1 s m | drops | peak RSS MB | CPU s |"
  echo "|---|---|---|---|---|---|---|---|---|---|"
  for name in $(awk '{ print $1 }' "$SUMMARY" | uniq); do
    v() { awk -v n="$name" -v k="$1" '$1 == n && $2 == k { print $3 }' "$SUMMARY"; }
    printf '| %s | %.1f | %.1f / %.1f | %.1f | %.1f | %.4f | %.4f | %s | %s | %s |\n' "$name" \
      "$(v fps)" "$(v end_to_end_p50_ms)" "$(v end_to_end_p99_ms)" "$(v tracking_p50_ms)" \
      "$(v mapping_p50_ms)" "$(v ate_rmse_m)" "$(v rpe_translation_rmse_m)" "$(v drops)" \
      "$(v peak_rss_mb)" "$(v cpu_s)"
  done
} > "$OUT/results.md"
cat "$OUT/results.md"

# Google Benchmark programs.
if [ "${SLAMD_BENCH_MICRO:-1}" != 0 ]; then
  for bench in "$BIN"/bench_*; do
    [ -x "$bench" ] || continue
    echo "bench: $(basename "$bench") ..."
    "$bench" --benchmark_format=console --benchmark_out="$OUT/$(basename "$bench").json" \
      --benchmark_out_format=json > "$OUT/$(basename "$bench").txt" 2>&1 ||
      echo "bench: $(basename "$bench") failed (see $OUT/$(basename "$bench").txt)"
  done
fi

# LCM flood: latency and memory of an lcm: source at 10x the camera's message rate.
if [ "${SLAMD_BENCH_FLOOD:-1}" != 0 ]; then
  OUT="$OUT/lcm_flood" bash "$ROOT/scripts/bench-lcm-flood.sh" "$BUILD_DIR" ||
    echo "bench: the LCM flood benchmark failed (see $OUT/lcm_flood)"
fi

# The corridor suite (issue 22): full SLAM on the evaluation seeds' varied corridors.
if [ "${SLAMD_BENCH_CORRIDORS:-1}" != 0 ]; then
  SLAMD_BENCH_OUT="$OUT" bash "$ROOT/scripts/bench-corridors.sh" "$BUILD_DIR" ||
    echo "bench: the corridor suite failed (see $OUT/corridors)"
fi

# Regressions against the committed baseline (same "case key value" lines inside a JSON string
# list). Higher is better for fps; lower is better for everything else.
regressions=0
if [ -f "$BASELINE" ]; then
  grep -o '"[a-z0-9_]* [a-z0-9_]* [-0-9.eE+]*"' "$BASELINE" | tr -d '"' > "$OUT/baseline.txt"
  while read -r name key base; do
    now=$(awk -v n="$name" -v k="$key" '$1 == n && $2 == k { print $3 }' "$SUMMARY")
    [ -n "$now" ] || continue
    case "$key" in drops | cpu_s | peak_rss_mb) continue ;; esac  # reported, not judged
    if awk -v now="$now" -v base="$base" -v key="$key" -v tol="$TOLERANCE" 'BEGIN {
         if (key == "fps") exit !(now < base * (1 - tol));
         exit !(now > base * (1 + tol) && now - base > 1e-3) }'; then
      echo "REGRESSION: $name $key = $now (baseline $base, tolerance $TOLERANCE)"
      regressions=$((regressions + 1))
    fi
  done < "$OUT/baseline.txt"
  echo "bench: $regressions regressions against bench/baseline.json"
else
  echo "bench: no bench/baseline.json to compare with"
fi
echo "bench: results in $OUT (results.json, results.md, per-case folders)"
if [ "${SLAMD_BENCH_FAIL_ON_REGRESSION:-0}" = 1 ] && [ $regressions -gt 0 ]; then exit 1; fi
exit 0
