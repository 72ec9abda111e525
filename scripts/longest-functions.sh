#!/usr/bin/env bash
# The longest C++ function definitions under src/, longest first: lines from a definition's first
# line to its closing brace, as Universal Ctags reports them (lambdas count within the function
# that holds them). For keeping functions short enough to read in one sitting.
# Usage: scripts/longest-functions.sh [TREE] [COUNT]   (defaults: this checkout, 5)
set -euo pipefail
TREE=${1:-$(cd "$(dirname "$0")/.." && pwd)}
COUNT=${2:-5}
cd "$TREE"
ctags -R --languages=C++ --kinds-C++=f --fields=+ne -x \
    --_xformat='%{end} %{line} %{scope} %{name} %{input}' src |
  awk '{ scope = ($3 == "-" ? "" : $3 "::"); sub(/^[a-z]*:/, "", scope); gsub(/^:+/, "", scope);
         print $1 - $2 + 1, scope $4, $5 ":" $2 }' |
  sort -rn | awk -v n="$COUNT" 'NR <= n'
