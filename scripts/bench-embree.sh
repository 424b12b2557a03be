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
. scripts/bench-common.sh
rounds=3 cpu=1 build=${BUILD:-build}
bench_opts "$@"
scenes=(${args[@]+"${args[@]}"})
[ ${#scenes[@]} -gt 0 ] || scenes=(dragon arm-reach bottle bottle-nolabel ShadowTest spheres2 bear test_reasonable)
rt=${RAYTRACE:-$build/renderer/raytrace} er=$build/benchmarks/embree-render
[ -x "$er" ] || { echo "bench-embree: $er not built (install libembree-dev, reconfigure)" >&2; exit 1; }
ours() { taskset -c "$cpu" "$rt" -q --backend serial -o /tmp/bench-embree.ppm "$1" | tr ' ' '\n' | sed -n 's/^render_ms=//p'; }
theirs() { taskset -c "$cpu" "$er" "$1" | sed -n 's/.*render_ms=//p'; }
ab_table bench-embree "raybench ms" "Embree ms" a/b ours theirs "${scenes[@]}"
