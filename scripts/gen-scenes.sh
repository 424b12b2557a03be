#!/usr/bin/env bash
# gen-scenes.sh - writes the large generated scenes that stand in for the
# report's big models (cat, character, island, ...) into scenes/generated/.
# They are deterministic (same sizes and seeds, same bytes) and not committed.
set -euo pipefail
cd "$(dirname "$0")/.."
gen=${SCENEGEN:-build/renderer/scenegen}
[ -x "$gen" ] || { echo "gen-scenes: $gen not built (ninja -C build)" >&2; exit 1; }
mkdir -p scenes/generated
for spec in large-100k:100000:1 large-300k:300000:2 large-1m:1000000:3; do
    IFS=: read -r name tris seed <<< "$spec"
    f=scenes/generated/$name.txt
    [ -s "$f" ] || "$gen" --triangles "$tris" --seed "$seed" -o "$f"
done
ls -la scenes/generated
