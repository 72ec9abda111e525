#!/usr/bin/env bash
# `make run`: runs the most complete end-to-end program slamd has on its built-in default input.
set -euo pipefail
BUILD_DIR=${1:-build}
echo "slamd: no end-to-end program is built yet (the foundation issue only provides libraries and tests)." >&2
echo "slamd: run 'make test' to exercise what exists." >&2
exit 1
