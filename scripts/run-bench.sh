#!/usr/bin/env bash
# `make bench`: runs every benchmark program built in build/bin.
set -euo pipefail
BUILD_DIR=${1:-build}
found=0
for bench in "$BUILD_DIR"/bin/bench_*; do
  [ -x "$bench" ] || continue
  found=1
  echo "== $bench"
  "$bench"
done
[ $found -eq 1 ] || echo "no benchmark programs built yet"
