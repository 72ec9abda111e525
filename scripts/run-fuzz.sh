#!/usr/bin/env bash
# `make fuzz [FUZZ_SECONDS=N] [FUZZ_RUNS=N] [FUZZ_TARGETS="a b"]`: builds the fuzz targets (tests/fuzz) with
# clang, libFuzzer, AddressSanitizer and UndefinedBehaviorSanitizer in build-fuzz/, writes the
# seed corpora from real data (fuzz_seeds), and runs every target for FUZZ_SECONDS (default 60)
# seconds, or until FUZZ_RUNS executions if that comes first, one per core at a time. Limits per target: no single allocation over 1 GB
# (-malloc_limit_mb), 2 GB resident, 10 s per input. Prints per target the executions, their rate,
# the corpus size and the findings, and exits 1 when any target crashed, hung, leaked or
# over-allocated. Findings are kept in build-fuzz/fuzz/findings/<target>/: add each to
# tests/fuzz/regressions/<target>/ with its fix, so the test suite replays it from then on.
# The corpus (build-fuzz/fuzz/corpus/) grows across runs.
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
BUILD_DIR=${1:-$ROOT/build-fuzz}
SECONDS_PER_TARGET=${FUZZ_SECONDS:-60}
RUNS_PER_TARGET=${FUZZ_RUNS:--1}  # -1: no limit on executions (FUZZ_SECONDS ends the run)
JOBS=${FUZZ_JOBS:-$(nproc)}
TARGETS=${FUZZ_TARGETS:-"lcm_messages frame_codec map_codec command config vocabulary tum_lists"}

CC=clang CXX=clang++ cmake -S "$ROOT" -B "$BUILD_DIR" -DSLAMD_SANITIZE=fuzzer \
  -DSLAMD_BUILD_BENCH=OFF -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
cmake --build "$BUILD_DIR" -j"${BUILD_JOBS:-$JOBS}" --target fuzzers

WORK="$BUILD_DIR/fuzz"
rm -rf "$WORK/seeds" "$WORK/logs"
mkdir -p "$WORK/seeds" "$WORK/logs" "$WORK/corpus" "$WORK/findings"
touch "$WORK/logs/started"  # findings of this run are the files newer than this
"$BUILD_DIR/bin/fuzz_seeds" "$WORK/seeds" >/dev/null

run_target() {
  local target=$1
  mkdir -p "$WORK/corpus/$target" "$WORK/findings/$target"
  # libFuzzer reads the seeds and the corpus, and adds what it finds to the first folder.
  ASAN_OPTIONS="detect_leaks=1:allocator_may_return_null=0" \
  UBSAN_OPTIONS="print_stacktrace=1" \
    "$BUILD_DIR/bin/${target}_fuzzer" "$WORK/corpus/$target" "$WORK/seeds/$target" \
      -max_total_time="$SECONDS_PER_TARGET" -runs="$RUNS_PER_TARGET" -malloc_limit_mb=1024 -rss_limit_mb=2048 \
      -timeout=10 -print_final_stats=1 -artifact_prefix="$WORK/findings/$target/" \
      >"$WORK/logs/$target.log" 2>&1 || true
}
export -f run_target
export WORK BUILD_DIR SECONDS_PER_TARGET RUNS_PER_TARGET
echo "fuzzing ${TARGETS// /, } for ${SECONDS_PER_TARGET} s each, $JOBS at a time"
printf '%s\n' $TARGETS | xargs -P "$JOBS" -I{} bash -c 'run_target {}'

stat() {  # stat <log> <name>: a libFuzzer final statistic
  sed -n "s/^stat::$2: *//p" "$1" | tail -1
}
total=0
failed=0
printf '\n%-14s %12s %10s %8s %9s %s\n' target executions "exec/s" corpus "peak MB" findings
for target in $TARGETS; do
  log="$WORK/logs/$target.log"
  runs=$(stat "$log" number_of_executed_units)
  rate=$(stat "$log" average_exec_per_sec)
  rss=$(stat "$log" peak_rss_mb)
  corpus=$(find "$WORK/corpus/$target" -type f | wc -l)
  findings=$(find "$WORK/findings/$target" -type f -newer "$WORK/logs/started" | wc -l)
  if [[ -z "$runs" ]]; then
    findings="$findings (no final statistics: see $log)"
    failed=1
    runs=0
  elif [[ $findings -gt 0 ]]; then
    failed=1
  fi
  total=$((total + runs))
  printf '%-14s %12s %10s %8s %9s %s\n' "$target" "$runs" "$rate" "$corpus" "$rss" "$findings"
done
printf '%-14s %12s\n' total "$total"
if [[ $failed -ne 0 ]]; then
  echo "FINDINGS: see $WORK/findings/ and $WORK/logs/" >&2
  exit 1
fi
