#!/usr/bin/env bash
# ci-perf-eval.sh [N] [M] - does the CI performance check catch a 10%
# slowdown, and does it stay quiet on unchanged code? (docs/harness-verdicts.md, "CI
# and the baseline"). Builds HEAD twice, once as it is and once with a
# planted slowdown (-Dexperiments=true -Dplant_every=10: every tenth pixel
# traced a second time, counters and image unchanged). Then runs scripts/ci-perf-check.sh N times with HEAD against HEAD
# (default 20) and M times with the planted build against HEAD (default 5),
# and prints how often each part of the check fired.
set -euo pipefail
cd "$(dirname "$0")/.."
n=${1:-20} m=${2:-5}
out=${OUT:-/tmp/ci-perf-eval}
mkdir -p "$out"
head=$(scripts/build-commit.sh HEAD /tmp/ci-eval-head)
rm -rf /tmp/ci-eval-plant
mkdir -p /tmp/ci-eval-plant/src
git archive HEAD | tar -x -C /tmp/ci-eval-plant/src
# the plant (-Dplant_every=10): a second trace of every tenth pixel, counted
# into a scratch copy, so image and counters stay the same
meson setup /tmp/ci-eval-plant /tmp/ci-eval-plant/src -Dharness=false -Dcuda=disabled -Dcourse_dir=none \
    -Dexperiments=true -Dplant_every=10 > /dev/null
ninja -C /tmp/ci-eval-plant renderer/raytrace | grep -E 'error|warning' >&2 || true
[ -x /tmp/ci-eval-plant/renderer/raytrace ] || { echo "ci-perf-eval: the planted build failed" >&2; exit 1; }
plant=/tmp/ci-eval-plant/renderer/raytrace
tally() { # LABEL NEW RUNS
    local ir=0 tm=0 both=0
    for i in $(seq 1 "$3"); do
        log=$out/$1-$i.log
        scripts/ci-perf-check.sh --base "$head" --new "$2" --out "$out/$1-$i" > "$log" 2>&1 || true
        # the first compare's lines come before the timed rounds' compare
        irl=$(awk '/^compare:/{print NR; exit}' "$log")
        a=$(head -n "$irl" "$log" | grep -c '^REGRESSION' || true)
        b=$(tail -n +"$((irl + 1))" "$log" | grep -c '^REGRESSION' || true)
        [ "$a" -gt 0 ] && ir=$((ir + 1))
        [ "$b" -gt 0 ] && tm=$((tm + 1))
        echo "ci-perf-eval: $1 run $i: exact part $a flagged, timed part $b flagged" >&2
        grep -E '^(ok|REGRESSION|IMPROVEMENT) ' "$log" | sed "s/^/$1 $i: /" >> "$out/$1-lines.txt"
    done
    echo "| $1 | $3 | $ir | $tm |"
}
echo "| build against HEAD | checks | instructions or counters flagged | times flagged |"
echo "|---|---|---|---|"
tally unchanged "$head" "$n"
tally planted "$plant" "$m"
