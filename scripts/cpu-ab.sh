#!/usr/bin/env bash
# cpu-ab.sh [--rounds N] [--cpu C] OLD NEW SCENE... - two raytrace builds on
# the serial backend, interleaved on CPU C (default 1) for N rounds (default
# 5), each run the best of 3 renders in one process; prints the best
# render_ms of each build per scene and NEW / OLD. The A/B behind the CPU
# steps in docs/performance.md ("Against Embree"); OLD is usually an older
# commit's build (scripts/build-commit.sh). SCENE: a path, or a course scene's
# name (found under ../shared/scenes/course).
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/bench-common.sh
rounds=5 cpu=1
bench_opts "$@"
set -- ${args[@]+"${args[@]}"}
[ $# -ge 3 ] || { echo "usage: cpu-ab.sh [--rounds N] [--cpu C] OLD NEW SCENE..." >&2; exit 2; }
old=$1 new=$2
shift 2
for b in "$old" "$new"; do [ -x "$b" ] || { echo "cpu-ab: $b is not an executable" >&2; exit 1; }; done
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
best() { taskset -c "$cpu" "$1" -q --backend serial --runs 3 -o "$tmp/x.ppm" "$2" | tr ' ' '\n' | sed -n 's/^render_ms_best=//p'; }
run_old() { best "$old" "$1"; }
run_new() { best "$new" "$1"; }
ab_table cpu-ab "old ms" "new ms" b/a run_old run_new "$@"
