#!/usr/bin/env bash
# verdict-campaign.sh [TRIALS] [CI_TRIALS] - how the harness's verdicts hold
# on this machine, quiet and with stress-ng busy on every CPU
# (docs/harness-verdicts.md, "Verdicts measured"). Builds HEAD three times in
# worktrees: unchanged, with a planted 10% slowdown (-Dplant_every=10) and
# with a planted 2.5x one (-Dplant_every=2 -Dplant_times=3). Then, per case
# (build x neighbour):
#   ab       `harness ab --config configs/ci.conf HEAD BUILD` (factor 1.05), TRIALS times
#   ci-ab    the CI check's timed half: the same at --factor 1.25, TRIALS times
#   compare  two studies of configs/ci.conf (5 repeats), HEAD then BUILD,
#            `harness compare --metric render_ms --factor 1.05`, TRIALS times
#   ci       scripts/ci-perf-check.sh --base HEAD --new BUILD, CI_TRIALS times
# and, quiet only, the instruction metric: configs/ci-instructions.conf under
# cachegrind with each build, `compare --metric instructions --factor 1.03`,
# TRIALS times. Verdicts are counted per configuration (2 per trial; the CI
# check's per run). NEIGHBOURS (default "none stress-ng"), BUILDS (default
# "unchanged 10% 2.5x") and PATHS (default "ab ci-ab compare ci") pick a
# part. Prints the Markdown table;
# logs in $OUT.
set -euo pipefail
cd "$(dirname "$0")/.."
trials=${1:-50} ci_trials=${2:-10}
h=build/harness/harness
out=${OUT:-/tmp/verdict-campaign}
mkdir -p "$out"
command -v stress-ng > /dev/null || { echo "verdict-campaign: stress-ng missing (scripts/install-deps.sh)" >&2; exit 1; }
[ -x "$h" ] || { echo "verdict-campaign: build first ($h)" >&2; exit 1; }
plant() { # DIR MESON_OPTION... : HEAD built with them
    rm -rf "$1"
    mkdir -p "$1/src"
    git archive HEAD | tar -x -C "$1/src"
    shift_dir=$1
    shift
    meson setup "$shift_dir" "$shift_dir/src" -Dharness=false -Dcuda=disabled -Dcourse_dir=none "$@" > /dev/null
    ninja -C "$shift_dir" renderer/raytrace > /dev/null
    echo "$shift_dir/renderer/raytrace"
}
head=$(plant /tmp/vc-head)
p10=$(plant /tmp/vc-p10 -Dexperiments=true -Dplant_every=10)
p25=$(plant /tmp/vc-p25 -Dexperiments=true -Dplant_every=2 -Dplant_times=3)
SCENEGEN=build/renderer/scenegen scripts/gen-scenes.sh mesh10k > /dev/null
spid=""
trap '[ -z "$spid" ] || kill "$spid" 2> /dev/null || true' EXIT
count() { # FILE: "REGRESSION IMPROVEMENT no-change INCONCLUSIVE" of its verdict lines
    local f=$1
    echo "$(grep -c '^REGRESSION' "$f" || true) $(grep -c '^IMPROVEMENT' "$f" || true)" \
         "$(grep -c '^no change' "$f" || true) $(grep -c '^INCONCLUSIVE' "$f" || true)"
}
row() { # PATH BUILD NEIGHBOUR TRIALS FILE
    read -r r i n u <<< "$(count "$5")"
    echo "| $1 | $2 | $3 | $4 | $r | $i | $n | $u |" | tee -a "$out/table.md"
}
echo "| path | build | neighbour | trials | REGRESSION | IMPROVEMENT | no change | INCONCLUSIVE |" | tee "$out/table.md"
echo "|---|---|---|---|---|---|---|---|" | tee -a "$out/table.md"
paths=" ${PATHS:-ab ci-ab compare ci} "
has() { [[ "$paths" == *" $1 "* ]]; }
for neighbour in ${NEIGHBOURS:-none stress-ng}; do
    if [ "$neighbour" = stress-ng ]; then
        stress-ng --cpu "$(nproc)" --timeout 7200s --quiet &
        spid=$!
        sleep 1
    fi
    for b in ${BUILDS:-unchanged 10% 2.5x}; do
        bin=$head; [ "$b" = 10% ] && bin=$p10; [ "$b" = 2.5x ] && bin=$p25
        tag="$neighbour-${b%\%}"
        : > "$out/ab-$tag.log"; : > "$out/ci-ab-$tag.log"; : > "$out/compare-$tag.log"
        for t in $(seq 1 "$trials"); do
            ! has ab || "$h" ab --config configs/ci.conf "$head" "$bin" --rounds 10 >> "$out/ab-$tag.log" 2>&1 || true
            ! has ci-ab || "$h" ab --config configs/ci.conf "$head" "$bin" --rounds 10 --factor 1.25 \
                >> "$out/ci-ab-$tag.log" 2>&1 || true
            if has compare; then
                "$h" run configs/ci.conf --raytrace "$head" -o "$out/base.csv" --overwrite -q --set repeats=5 2> /dev/null || true
                "$h" run configs/ci.conf --raytrace "$bin" -o "$out/new.csv" --overwrite -q --set repeats=5 2> /dev/null || true
                "$h" compare --metric render_ms --factor 1.05 "$out/new.csv" "$out/base.csv" >> "$out/compare-$tag.log" 2>&1 || true
            fi
            echo "verdict-campaign: $tag trial $t of $trials" >&2
        done
        ! has ab || row "harness ab" "$b" "$neighbour" "$trials" "$out/ab-$tag.log"
        ! has ci-ab || row "CI check, times (ab, factor 1.25)" "$b" "$neighbour" "$trials" "$out/ci-ab-$tag.log"
        ! has compare || row "compare, two studies" "$b" "$neighbour" "$trials" "$out/compare-$tag.log"
        if [ "$b" != 10% ] && has ci; then
            : > "$out/ci-$tag.log"
            for t in $(seq 1 "$ci_trials"); do
                if scripts/ci-perf-check.sh --base "$head" --new "$bin" --rounds 10 > "$out/ci-one.log" 2>&1; then
                    echo "no change CI check: ok" >> "$out/ci-$tag.log"
                else
                    echo "REGRESSION CI check: $(grep -c '^REGRESSION' "$out/ci-one.log") verdict(s)" >> "$out/ci-$tag.log"
                fi
                cat "$out/ci-one.log" >> "$out/ci-$tag.full.log"
            done
            row "CI check (whole run)" "$b" "$neighbour" "$ci_trials" "$out/ci-$tag.log"
        fi
    done
    if [ "$neighbour" = none ] && has ab; then
        : > "$out/ir.log"
        for t in $(seq 1 "$trials"); do
            "$h" run configs/ci-instructions.conf --raytrace "$head" -o "$out/ir-base.csv" --overwrite -q 2> /dev/null || true
            "$h" run configs/ci-instructions.conf --raytrace "$p10" -o "$out/ir-new.csv" --overwrite -q 2> /dev/null || true
            "$h" compare --metric instructions --factor 1.03 "$out/ir-new.csv" "$out/ir-base.csv" >> "$out/ir.log" 2>&1 || true
        done
        row "compare, instructions (cachegrind)" "10%" none "$trials" "$out/ir.log"
    fi
    if [ -n "$spid" ]; then kill "$spid"; wait "$spid" 2> /dev/null || true; spid=""; fi
done
