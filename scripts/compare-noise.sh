#!/usr/bin/env bash
# compare-noise.sh CONFIG N [BUILD] - how often `harness compare` cries wolf
# on unchanged code: runs the study CONFIG N+1 times with the same build,
# then compares each of the last N runs with the first under several
# settings and counts the runs flagged as regressions (false alarms) and as
# improvements. Prints one table row per setting (docs/harness-verdicts.md,
# "compare"). The study should have 5 or more repeats (Mann-Whitney) and
# `extra_args: --calibrate` for the calibrated metric.
set -euo pipefail
cd "$(dirname "$0")/.."
conf=${1:?usage: compare-noise.sh CONFIG N [BUILD]}
n=${2:?usage: compare-noise.sh CONFIG N [BUILD]}
build=${3:-build}
h=$build/harness/harness
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
for i in $(seq 0 "$n"); do
    "$h" run "$conf" -o "$out/run$i.csv" -q --raytrace "$build/renderer/raytrace" 2> /dev/null ||
        echo "compare-noise: run $i had failed runs" >&2
    echo "compare-noise: run $i of $n done" >&2
done
echo "| setting | reruns flagged as regressions | as improvements | with an inconclusive configuration | metric refused | configurations x reruns |"
echo "|---|---|---|---|---|---|"
for setting in "--metric render_ms --factor 1.5" "--metric render_ms --factor 1.8" \
               "--metric render_ms/calib --factor 1.5" "--metric render_ms/calib --factor 1.8"; do
    bad=0 better=0 unsure=0 refused=0 cfgs=0
    for i in $(seq 1 "$n"); do
        # shellcheck disable=SC2086
        r=$("$h" compare $setting "$out/run$i.csv" "$out/run0.csv" 2> "$out/err" || true)
        grep -q 'refused' "$out/err" && refused=$((refused + 1))
        echo "$r" | grep -q '^REGRESSION' && bad=$((bad + 1))
        echo "$r" | grep -q '^IMPROVEMENT' && better=$((better + 1))
        echo "$r" | grep -q '^INCONCLUSIVE' && unsure=$((unsure + 1))
        cfgs=$((cfgs + $(echo "$r" | grep -c -E '^(no change|INCONCLUSIVE|REGRESSION|IMPROVEMENT) ')))
    done
    echo "| \`$setting\` | $bad of $n | $better of $n | $unsure of $n | $refused of $n | $cfgs |"
done
