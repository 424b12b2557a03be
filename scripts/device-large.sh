#!/usr/bin/env bash
# device-large.sh [bench|ab]... - the large-scene measurements on the GPU
# machine (docs/performance.md, "Large scenes"); run through the device tool
# from the repository root with carry [".devcarry"]:
#   bench  scripts/bench-large.sh on the CUDA backend at 1920x1080, 10K to
#          4M triangles, every core (CSV and table under $OUT)
#   ab     the 3,567,202-triangle scene (gen-scenes.sh large-4m) loaded and
#          rendered by the older commit in .devcarry/old.tar.gz (`git archive
#          OLD | gzip`) and by this tree, interleaved, 5 rounds: parse, build,
#          render, node visits and image (the same tree gives the same visits)
# .devcarry/include/xxhash.h stands in for libxxhash-dev where the machine
# lacks it (the scene cache needs only the header).
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-/tmp/device-large}
mkdir -p "$OUT"
args=()
[ -f /usr/include/xxhash.h ] || args+=("-Dc_args=-I$PWD/.devcarry/include")
[ -f build-large/build.ninja ] || meson setup build-large -Dgpu_arch=9.0 -Dcourse_dir=none "${args[@]}" > /dev/null
ninja -C build-large > /dev/null
for step in "${@:-bench ab}"; do
    case $step in
    bench)
        scripts/bench-large.sh --build build-large --backend cuda --resolution 1920x1080 --threads "$(nproc)" \
            --repeats 3 --out "$OUT/bench-large-h100" ;;
    ab)
        mkdir -p /tmp/old-src
        tar -xzf .devcarry/old.tar.gz -C /tmp/old-src
        [ -f /tmp/build-old/build.ninja ] ||
            meson setup /tmp/build-old /tmp/old-src -Dgpu_arch=9.0 -Dharness=false -Dcourse_dir=none > /dev/null
        ninja -C /tmp/build-old renderer/raytrace > /dev/null
        SCENEGEN=build-large/renderer/scenegen scripts/gen-scenes.sh large-4m > /dev/null
        s=scenes/generated/large-4m.txt
        echo "round,build,parse_ms,build_ms,render_ms,node_visits,image_fnv1a,sah_cost" > "$OUT/large-4m-ab.csv"
        for r in 1 2 3 4 5; do
            for b in old new; do
                rt=build-large/renderer/raytrace; [ $b = old ] && rt=/tmp/build-old/renderer/raytrace
                rec=$("$rt" -q --backend cuda -r 1920x1080 -o /tmp/ab.ppm "$s")
                k() { printf '%s\n' "$rec" | tr ' ' '\n' | sed -n "s/^$1=//p"; }
                echo "$r,$b,$(k parse_ms),$(k build_ms),$(k render_ms),$(k node_visits),$(k image_fnv1a),$(k sah_cost)" |
                    tee -a "$OUT/large-4m-ab.csv"
            done
        done ;;
    *) echo "device-large: unknown step $step" >&2; exit 2 ;;
    esac
done
