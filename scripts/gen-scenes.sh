#!/usr/bin/env bash
# gen-scenes.sh [NAME...] - writes generated scenes into scenes/generated/:
# mesh10k (11,018 triangles: the stand-in for the course's dragon that the
# tests and configs/ci.conf use, the same bytes as the tests' mesh10k target)
# and the large ones that stand in for the report's big models (cat,
# character, island, ...). No NAME: all of them. They are deterministic
# (same sizes and seeds, same bytes) and not committed.
set -euo pipefail
cd "$(dirname "$0")/.."
gen=${SCENEGEN:-build/renderer/scenegen}
[ -x "$gen" ] || { echo "gen-scenes: $gen not built (ninja -C build)" >&2; exit 1; }
mkdir -p scenes/generated
all="mesh10k:12000:5:160x120 large-100k:100000:1:800x600 large-300k:300000:2:800x600 large-1m:1000000:3:800x600"
want=${*:-}
for spec in $all; do
    IFS=: read -r name tris seed res <<< "$spec"
    if [ -n "$want" ] && ! [[ " $want " == *" $name "* ]]; then continue; fi
    f=scenes/generated/$name.txt
    [ -s "$f" ] || "$gen" --triangles "$tris" --seed "$seed" --resolution "$res" -o "$f"
done
for name in $want; do
    [[ " $all " == *" $name:"* ]] || { echo "gen-scenes: unknown scene '$name' (mesh10k large-100k large-300k large-1m)" >&2; exit 1; }
done
ls -la scenes/generated
