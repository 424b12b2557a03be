#!/bin/sh
# make-cache-seeds.sh [BUILD] - remakes tests/fuzz/corpus/cache: the scene
# cache's entries for three small scenes, written by BUILD's raytrace
# (default build/). Run after a change of the entry format.
set -eu
cd "$(dirname "$0")/.."
RT=$(pwd)/${1:-build}/renderer/raytrace
OUT=$(pwd)/tests/fuzz/corpus/cache
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
cd "$T"
printf 'film_resolution: 8 6\nmaterial: .1 .1 .1 .7 .2 .2 .5 .5 .5 20 .3 .3 .3 1.5\nsphere: 0 0 -5 1\nsphere: 1 1 -6 .5\nmaterial: .1 .1 .1 .2 .7 .2 0 0 0 1 0 0 0 1\nvertex: -2 -1 -4\nvertex: 2 -1 -4\nvertex: 0 -1 -8\nvertex: 0 2 -7\nnormal: 0 1 0\nnormal: 0 0 1\nnormal: 1 0 0\ntriangle: 0 1 2\nnormal_triangle: 0 1 3 0 1 2\nambient_light: .1 .1 .1\npoint_light: 1 1 1 0 5 0\ndirectional_light: .5 .5 .5 0 -1 -1\nspot_light: 1 1 1 0 3 -5 0 -1 0 20 30\nmax_depth: 4\n' > mix.txt
printf 'film_resolution: 8 6\nsphere: 0 0 -5 1\n' > one.txt
"$RT" -q --cache c -o o.ppm mix.txt > /dev/null
"$RT" -q --accel none --cache c -o o.ppm mix.txt > /dev/null
"$RT" -q --cache c -o o.ppm one.txt > /dev/null
rm -f "$OUT"/*.rbc
for f in c/*.rbc; do cp "$f" "$OUT/$(basename "$f" | cut -c1-8).rbc"; done
ls "$OUT"
