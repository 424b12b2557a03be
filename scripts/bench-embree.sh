#!/usr/bin/env bash
# bench-embree.sh [--rounds N] [--cpu C] [SCENE...] - raybench's CPU render
# against Intel Embree's traversal under the same shading (docs/performance.md,
# "Against Embree"): for each course scene, raytrace --backend serial and
# benchmarks/embree-render, both on CPU C (default 1), alternating for N
# rounds (default 3); prints the best render_ms of each and their ratio,
# ours / Embree, as a Markdown table. Needs the build with -Dembree (Debian
# libembree-dev) and the course scenes (../shared/scenes/course). RAYTRACE=PATH
# measures another raytrace (an older commit: scripts/build-commit.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
rounds=3 cpu=1 build=${BUILD:-build}
while [ $# -gt 0 ]; do
    case $1 in
    --rounds) rounds=$2; shift 2 ;;
    --cpu) cpu=$2; shift 2 ;;
    *) break ;;
    esac
done
course=${RAYBENCH_COURSE_DIR:-../shared/scenes/course}
scenes=("$@")
[ ${#scenes[@]} -gt 0 ] || scenes=(dragon arm-reach bottle bottle-nolabel ShadowTest spheres2 bear test_reasonable)
rt=${RAYTRACE:-$build/renderer/raytrace} er=$build/benchmarks/embree-render
[ -x "$er" ] || { echo "bench-embree: $er not built (install libembree-dev, reconfigure)" >&2; exit 1; }
best() { sort -g | head -n 1; }
echo "| scene | raybench ms | Embree ms | ours / Embree |"
echo "|---|---|---|---|"
for s in "${scenes[@]}"; do
    f=$(find "$course" -name "$s.txt" | head -n 1)
    [ -n "$f" ] || { echo "bench-embree: no scene $s under $course" >&2; exit 1; }
    ours=() theirs=()
    for r in $(seq 1 "$rounds"); do
        ours+=("$(taskset -c "$cpu" "$rt" -q --backend serial -o /tmp/bench-embree.ppm "$f" | tr ' ' '\n' | sed -n 's/^render_ms=//p')")
        theirs+=("$(taskset -c "$cpu" "$er" "$f" | sed -n 's/.*render_ms=//p')")
    done
    o=$(printf '%s\n' "${ours[@]}" | best) e=$(printf '%s\n' "${theirs[@]}" | best)
    echo "| $s | $o | $e | $(awk -v a="$o" -v b="$e" 'BEGIN { printf "%.2f", a / b }') |"
done
