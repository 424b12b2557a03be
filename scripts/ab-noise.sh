#!/usr/bin/env bash
# ab-noise.sh [TRIALS] [BUILD] - how `harness ab` judges on this machine,
# quiet and with stress-ng busy on every CPU (docs/harness.md, "A/B"): TRIALS
# (default 10) runs of `harness ab` each, 10 rounds, of raytrace's serial
# render of scenes/glass.txt against itself (unchanged: a "REGRESSION" is a
# false alarm), and against the same render with 2.5x the pixels (a planted
# 2.5x slowdown: anything but "REGRESSION" is a miss). Prints one table row
# per case with the count of each verdict.
set -euo pipefail
cd "$(dirname "$0")/.."
trials=${1:-10}
build=${2:-build}
h=$build/harness/harness rt=$build/renderer/raytrace
command -v stress-ng > /dev/null || { echo "ab-noise: stress-ng missing (scripts/install-deps.sh)" >&2; exit 1; }
tmp=$(mktemp -d)
spid=""
trap '[ -z "$spid" ] || kill "$spid" 2> /dev/null; rm -rf "$tmp"' EXIT
a="$rt -q --backend serial -r 320x240 -o $tmp/a.ppm scenes/glass.txt"
slow="$rt -q --backend serial -r 506x380 -o $tmp/b.ppm scenes/glass.txt" # 2.50x the pixels
echo "| case | neighbour | trials | REGRESSION | IMPROVEMENT | no change | INCONCLUSIVE |"
echo "|---|---|---|---|---|---|---|"
for neighbour in none stress-ng; do
    if [ "$neighbour" = stress-ng ]; then
        stress-ng --cpu "$(nproc)" --timeout 3600s --quiet &
        spid=$!
        sleep 1
    fi
    for case in unchanged 2.5x; do
        b=$a
        [ "$case" = unchanged ] || b=$slow
        declare -A n=([REGRESSION]=0 [IMPROVEMENT]=0 ["no change"]=0 [INCONCLUSIVE]=0)
        for t in $(seq 1 "$trials"); do
            v=$("$h" ab "$a" "$b" --rounds 10 | sed -n 's/ B against A:.*//p' || true)
            n[$v]=$((${n[$v]:-0} + 1))
        done
        echo "| $case | $neighbour | $trials | ${n[REGRESSION]} | ${n[IMPROVEMENT]} | ${n[no change]} | ${n[INCONCLUSIVE]} |"
        unset n
    done
    if [ -n "$spid" ]; then kill "$spid"; wait "$spid" 2> /dev/null || true; spid=""; fi
done
