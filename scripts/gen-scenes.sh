#!/usr/bin/env bash
# gen-scenes.sh [NAME...] - writes generated scenes into scenes/generated/:
# mesh10k (11,018 triangles: the stand-in for the course's dragon that the
# tests and configs/ci.conf use, the same bytes as the tests' mesh10k target)
# and the large ones that stand in for the report's big models
# (docs/performance.md, "Large scenes"): sphere fields of 88K to 3.6M
# triangles (large-*), a terrain island in the sea (island-*: the report's
# island) and many small objects of widely varying sizes (objects-*). No
# NAME: all but the two largest (large-4m, island-4m: 0.35 and 0.25 GB of
# text). They are deterministic (same sizes and seeds, same bytes) and not
# committed.
set -euo pipefail
cd "$(dirname "$0")/.."
gen=${SCENEGEN:-build/renderer/scenegen}
[ -x "$gen" ] || { echo "gen-scenes: $gen not built (ninja -C build)" >&2; exit 1; }
mkdir -p scenes/generated
# name:kind:triangles:seed:resolution
all="mesh10k:spheres:12000:5:160x120 large-100k:spheres:100000:1:800x600 large-300k:spheres:300000:2:800x600
     large-1m:spheres:1000000:3:800x600 large-4m:spheres:4000000:1:1920x1080 island-1m:island:1000000:1:1920x1080
     island-4m:island:4000000:1:1920x1080 objects-1m:objects:1000000:1:1920x1080"
big="large-4m island-4m"
want=${*:-}
names=$(for spec in $all; do echo -n "${spec%%:*} "; done)
for name in $want; do
    [[ " $names " == *" $name "* ]] || { echo "gen-scenes: unknown scene '$name' ($names)" >&2; exit 1; }
done
for spec in $all; do
    IFS=: read -r name kind tris seed res <<< "$spec"
    if [ -n "$want" ] && ! [[ " $want " == *" $name "* ]]; then continue; fi
    if [ -z "$want" ] && [[ " $big " == *" $name "* ]]; then continue; fi
    f=scenes/generated/$name.txt
    [ -s "$f" ] || "$gen" --kind "$kind" --triangles "$tris" --seed "$seed" --resolution "$res" -o "$f"
done
ls -la scenes/generated
