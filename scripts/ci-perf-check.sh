#!/usr/bin/env bash
# ci-perf-check.sh [--base RAYTRACE] [--new RAYTRACE] [--rounds N] [--out DIR]
# The CI performance check (docs/harness-verdicts.md, "CI and the baseline"): the
# baseline commit named in results/ci-baseline.txt, built here (a worktree in
# build-base/, scripts/build-commit.sh), against this
# build, on the same machine in the same run:
#   1. exact: every work counter and image hash of configs/ci-instructions.conf
#      and ci-instructions-none.conf equal, and the instructions executed
#      (cachegrind) at most 3% more;
#   2. times: each configuration of configs/ci.conf run N (default 10) times
#      by each build, interleaved with the first of each pair alternating
#      (`harness ab --config`), render_ms judged at factor 1.05.
# Prints which baseline it used and when that was refreshed; exit 1 on a
# regression. --base/--new take prebuilt binaries (scripts/ci-perf-eval.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
h=build/harness/harness
base="" new=build/renderer/raytrace rounds=10 out=""
while [ $# -gt 0 ]; do
    case $1 in
    --base) base=$2; shift 2 ;;
    --new) new=$2; shift 2 ;;
    --rounds) rounds=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    *) echo "ci-perf-check: unknown argument $1 (see the script's header)" >&2; exit 2 ;;
    esac
done
[ -x "$h" ] && [ -x "$new" ] || { echo "ci-perf-check: build first ($h, $new)" >&2; exit 2; }
# below 4 samples a side harness compare has no rank test and the ratios
# alone decide: one slow phase of the machine would fail the check
[[ "$rounds" =~ ^[0-9]+$ ]] && [ "$rounds" -ge 5 ] ||
    { echo "ci-perf-check: --rounds: expected an integer of at least 5, got '$rounds'" >&2; exit 2; }
if [ -z "$out" ]; then out=$(mktemp -d); trap 'rm -rf "$out"' EXIT; fi
mkdir -p "$out"

if [ -z "$base" ]; then
    commit=$(sed -n 's/^commit: *//p' results/ci-baseline.txt)
    echo "ci-perf-check: baseline $commit, refreshed $(sed -n 's/^refreshed: *//p' results/ci-baseline.txt)" \
         "($(git rev-list --count "$commit"..HEAD 2>/dev/null || echo '?') commits ago; scripts/ci-refresh-baseline.sh)"
    base=$(scripts/build-commit.sh "$commit" build-base)
fi
SCENEGEN=build/renderer/scenegen scripts/gen-scenes.sh mesh10k > /dev/null

fail=0
# 1. exact: counters, image hashes and instructions
for side in base new; do
    bin=$base; [ $side = new ] && bin=$new
    "$h" run configs/ci-instructions.conf --raytrace "$bin" -o "$out/$side-instructions.csv" --overwrite -q
    "$h" run configs/ci-instructions-none.conf --raytrace "$bin" -o "$out/$side-none.csv" --overwrite -q
    tail -n +2 "$out/$side-none.csv" >> "$out/$side-instructions.csv"
done
"$h" compare --metric instructions --factor 1.03 "$out/new-instructions.csv" "$out/base-instructions.csv" || fail=1

# 2. times: harness ab runs each configuration with both builds, the first
# of each pair alternating, so that a slow phase of the machine hits both
# (factor 1.05, ab's default: 0 false regressions in 200 verdicts on unchanged
# code, quiet and under stress-ng, docs/harness-verdicts.md "Verdicts measured")
"$h" ab --config configs/ci.conf "$base" "$new" --rounds "$rounds" | tee "$out/ab.txt" || fail=1
if [ $fail -eq 0 ]; then echo "ci-perf-check: ok"; else echo "ci-perf-check: REGRESSION"; fi
exit $fail
