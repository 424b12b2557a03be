#!/usr/bin/env bash
# device-report.sh CONFIG... - the report's studies on the GPU machine
# (docs/report.md): each config run by the harness with scene_dir pointed at
# the carried course scenes (.devcarry/scenes/course; configs on
# scenes/generated get the generated stand-ins instead), its CSV and table
# written under $OUT. Carry [".devcarry"]; .devcarry/include/xxhash.h stands
# in for libxxhash-dev where the machine lacks it.
#
# A study longer than one device call (the 64-worker Tables 1 and 2: brute
# force on the dragon is about a minute per one-worker run) runs in slices:
# each call stops its studies BUDGET_S seconds after it started (default
# 540, under the tool's 600 s limit; the rows written so far stay), and a
# study whose CSV from an earlier call lies in RESUME_DIR (default
# .devcarry/resume, carried) continues it with `harness run --resume`. Copy
# $OUT/NAME.csv to .devcarry/resume/ after each call and call again until
# the log says nothing was left to run.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-/tmp/device-report}
RESUME_DIR=${RESUME_DIR:-.devcarry/resume}
BUDGET_S=${BUDGET_S:-540}
T0=$(date +%s)
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
    left=$((BUDGET_S - ($(date +%s) - T0)))
    [ "$left" -gt 10 ] || { echo "== $name: no time left in this call"; continue; }
    resume=()
    if [ -f "$RESUME_DIR/$name.csv" ]; then
        cp "$RESUME_DIR/$name.csv" "$OUT/$name.csv"
        resume=(--resume)
    fi
    timeout "$left" build-report/harness/harness run "/tmp/$name.conf" --raytrace build-report/renderer/raytrace \
        -o "$OUT/$name.csv" "${resume[@]}" -q 2> "$OUT/$name.log" || { tail -5 "$OUT/$name.log"; continue; }
    build-report/harness/harness table "$OUT/$name.csv" > "$OUT/$name-table.md" || true
    echo "== $name"; tail -3 "$OUT/$name.log"; head -30 "$OUT/$name-table.md"
done
