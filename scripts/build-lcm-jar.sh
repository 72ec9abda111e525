#!/usr/bin/env bash
# Builds the Java classes of LCM types into one jar, for lcm-spy and other Java LCM tools:
#   scripts/build-lcm-jar.sh OUT.jar LCM_JAR LCM_GEN FILE.lcm...
# lcm-gen -j writes one .java per type (package folders), javac compiles them against LCM's own
# lcm.jar, and jar packs the classes. The jar appears only when every step succeeded.
set -euo pipefail
out=$1 lcm_jar=$2 lcm_gen=$3
shift 3
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$lcm_gen" --java --jpath "$work/src" "$@"
find "$work/src" -name '*.java' | sort > "$work/sources.txt"
[ -s "$work/sources.txt" ] || { echo "build-lcm-jar: lcm-gen wrote no Java source" >&2; exit 1; }
javac -nowarn -encoding UTF-8 -cp "$lcm_jar" -d "$work/classes" @"$work/sources.txt"
mkdir -p "$(dirname "$out")"
jar cf "$out.tmp" -C "$work/classes" .
mv "$out.tmp" "$out"
