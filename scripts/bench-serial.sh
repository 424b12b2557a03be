#!/usr/bin/env bash
# bench-serial.sh [REPEATS] [SCENE_DIR] - the serial BVH benchmark behind
# docs/performance.md: every course scene rendered REPEATS times (default 7)
# by the serial backend; prints, per scene, the best and median render time,
# Mrays/s at the best time, the parse/build/render/write split of the median
# run, and the BVH build speed in Mtris/s. Runs are interleaved across scenes
# so a noisy neighbour spreads over all of them rather than one.
set -euo pipefail
cd "$(dirname "$0")/.."
reps=${1:-7}
dir=${2:-../shared/scenes/course}
rt=${RAYTRACE:-build/renderer/raytrace}
[ -x "$rt" ] || { echo "bench-serial: $rt not built (run: meson setup build && ninja -C build)" >&2; exit 1; }
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
mapfile -t scenes < <(find "$dir" -name '*.txt' | sort)
[ ${#scenes[@]} -gt 0 ] || { echo "bench-serial: no scenes under $dir" >&2; exit 1; }
for r in $(seq "$reps"); do
    for s in "${scenes[@]}"; do
        n=$(basename "$s" .txt)
        "$rt" --quiet -o "$tmp/$n.ppm" "$s" >> "$tmp/$n.rec"
    done
done
echo "machine: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'), $(nproc) cores; $reps runs per scene; $(date -u +%Y-%m-%dT%H:%MZ)"
printf '| %-16s | %8s | %8s | %8s | %7s | %7s | %7s | %7s | %8s | %9s |\n' scene rays best_ms median_ms Mrays/s parse build write prims build_Mt/s
printf '|%s|\n' "------------------|----------|----------|-----------|---------|---------|---------|---------|----------|-----------"
get() { sed -n "s/.* $1=\([^ ]*\).*/\1/p"; }
for s in "${scenes[@]}"; do
    n=$(basename "$s" .txt)
    f="$tmp/$n.rec"
    rays=$(head -n1 "$f" | get rays)
    sorted=$(get render_ms < "$f" | sort -g)
    best=$(echo "$sorted" | head -n1)
    med=$(echo "$sorted" | sed -n "$(( (reps + 1) / 2 ))p")
    parse=$(get parse_ms < "$f" | sort -g | sed -n "$(( (reps + 1) / 2 ))p")
    build=$(get build_ms < "$f" | sort -g | sed -n "$(( (reps + 1) / 2 ))p")
    write=$(get write_ms < "$f" | sort -g | sed -n "$(( (reps + 1) / 2 ))p")
    prims=$(head -n1 "$f" | get prims)
    awk -v n="$n" -v rays="$rays" -v best="$best" -v med="$med" -v p="$parse" -v b="$build" -v w="$write" -v prims="$prims" \
        'BEGIN { printf "| %-16s | %8d | %8.1f | %9.1f | %7.2f | %7.2f | %7.2f | %7.2f | %8d | %9.2f |\n",
                 n, rays, best, med, rays / (best * 1000), p, b, w, prims, (b > 0 ? prims / (b * 1000) : 0) }'
done
