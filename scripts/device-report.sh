#!/usr/bin/env bash
# device-report.sh CONFIG... - the report's studies on the GPU machine
# (docs/report.md): each config run by the harness with scene_dir pointed at
# the carried course scenes (.devcarry/scenes/course; configs on
# scenes/generated get the generated stand-ins instead), its CSV and table
# written under $OUT. Carry [".devcarry"]; .devcarry/include/xxhash.h stands
# in for libxxhash-dev where the machine lacks it.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-/tmp/device-report}
mkdir -p "$OUT"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
args=()
[ -f /usr/include/xxhash.h ] || args+=("-Dc_args=-I$PWD/.devcarry/include")
[ -f build-report/build.ninja ] ||
    meson setup build-report -Dgpu_arch=9.0 -Dcourse_dir=none "${args[@]}" > /dev/null
ninja -C build-report > /dev/null
for conf in "$@"; do
    name=$(basename "$conf" .conf)
    if grep -q '^scene_dir: scenes/generated' "$conf"; then
        # the generated stand-ins (scripts/gen-scenes.sh), made here
        SCENEGEN=build-report/renderer/scenegen scripts/gen-scenes.sh island-1m objects-1m large-1m > /dev/null
        cp "$conf" "/tmp/$name.conf"
    else
        sed "s|^scene_dir:.*|scene_dir: $PWD/.devcarry/scenes/course|" "$conf" > "/tmp/$name.conf"
    fi
    build-report/harness/harness run "/tmp/$name.conf" --raytrace build-report/renderer/raytrace \
        -o "$OUT/$name.csv" -q 2> "$OUT/$name.log" || { tail -5 "$OUT/$name.log"; continue; }
    build-report/harness/harness table "$OUT/$name.csv" > "$OUT/$name-table.md" || true
    echo "== $name"; tail -3 "$OUT/$name.log"; head -30 "$OUT/$name-table.md"
done
