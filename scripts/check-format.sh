#!/usr/bin/env bash
# Fails when a tracked C++ file differs from what clang-format makes of it (.clang-format at the
# root: Google style, 100 columns, include blocks C / C++ / third-party / slamd). Run by the test
# suite (ctest format_check). Exits 77 (skip) where clang-format or the git checkout is missing.
# Fix with: scripts/check-format.sh --fix
set -euo pipefail
cd "$(dirname "$0")/.."
if ! command -v clang-format > /dev/null; then
  echo "check-format: clang-format is not installed (scripts/install-deps.sh installs it); skipped"
  exit 77
fi
if ! git rev-parse --is-inside-work-tree > /dev/null 2>&1; then
  echo "check-format: not a git checkout; skipped"
  exit 77
fi
mapfile -t files < <(git ls-files '*.cpp' '*.hpp' '*.h' '*.cc')
if [ "${1:-}" = "--fix" ]; then
  clang-format -i "${files[@]}"
  echo "check-format: formatted ${#files[@]} files"
  exit 0
fi
# One clang-format process for every file: it names each unformatted file in its warnings.
report=$(clang-format --dry-run "${files[@]}" 2>&1 || true)
mapfile -t unformatted < <(printf '%s\n' "$report" |
  sed -n 's/^\(.*\):[0-9]*:[0-9]*: \(warning\|error\): code should be clang-formatted.*/\1/p' |
  sort -u)
if [ ${#unformatted[@]} -gt 0 ]; then
  echo "check-format: ${#unformatted[@]} of ${#files[@]} files are not formatted (scripts/check-format.sh --fix):"
  printf '  %s\n' "${unformatted[@]}"
  exit 1
fi
if printf '%s\n' "$report" | grep -q "error:"; then
  echo "check-format: clang-format failed:"
  printf '%s\n' "$report" | grep "error:" | head -20
  exit 1
fi
echo "check-format: ${#files[@]} files formatted"
