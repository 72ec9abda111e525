#!/bin/sh
# Regenerates the README's configuration reference from the schema: the output of
# `slamd --describe-config --markdown` between the BEGIN/END CONFIG REFERENCE markers.
# Usage: scripts/update-config-reference.sh [path/to/slamd]   (default build/bin/slamd)
set -eu
root=$(cd "$(dirname "$0")/.." && pwd)
slamd=${1:-$root/build/bin/slamd}
readme=$root/README.md
reference=$(mktemp)
trap 'rm -f "$reference" "$reference.readme"' EXIT
"$slamd" --describe-config --markdown > "$reference"
awk -v reference="$reference" '
  /^<!-- BEGIN CONFIG REFERENCE/ { print; print ""; while ((getline line < reference) > 0) print line; print ""; skipping = 1; next }
  /^<!-- END CONFIG REFERENCE/ { skipping = 0 }
  !skipping { print }
' "$readme" > "$reference.readme"
mv "$reference.readme" "$readme"
