#!/usr/bin/env bash
# device-gpus.sh [STEP...] - the mpi-cuda backend on the GPU machine
# (docs/gpu.md, "Several GPUs"). Steps (default: all):
#   test    build, then the GPU test suite (mpi-cuda against cuda included)
#   shared  configs/mpi-cuda-shared.conf with one GPU visible: 1, 2 and 4
#           ranks taking turns on it
#   gpus    configs/gpus-dragon.conf and configs/gpus-island.conf, the rank
#           lists cut to the GPUs the machine has
#   ab      the same two studies through `harness ab --config` against an
#           older commit built beside this one (.devcarry/base.tar.gz, made
#           here by `git archive --prefix=base/ OLD | gzip`), interleaved,
#           ROUNDS rounds (default 5); then one run of each GPU case for its
#           record keys (keys.txt). STUDIES="dragon" or "island" runs one
#           (the island's 4M-triangle scene is parsed and built on every
#           run: give it a call of its own)
# NINJA_TARGETS limits the build (default: everything). CSVs, tables and
# logs go to $OUT (default /tmp/device-gpus). Carry [".devcarry"]: the
# course scenes in .devcarry/scenes/course, and .devcarry/include/xxhash.h
# where the machine lacks libxxhash-dev.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-/tmp/device-gpus}
mkdir -p "$OUT"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
B=build-gpus
steps=${*:-test shared gpus}
course=$PWD/.devcarry/scenes/course
args=(-Dgpu_arch=9.0 "-Dcourse_dir=$course")
[ -f /usr/include/xxhash.h ] || args+=("-Dc_args=-I$PWD/.devcarry/include")
[ -f $B/build.ninja ] || meson setup $B "${args[@]}" > "$OUT/setup.log"
ninja -C $B ${NINJA_TARGETS:-} > "$OUT/build.log"
ngpu=$(nvidia-smi -L | grep -c '^GPU ')
nvidia-smi -L > "$OUT/gpus.txt"
nvidia-smi topo -m >> "$OUT/gpus.txt" 2>&1 || true
$B/harness/harness topo > "$OUT/topo.txt"

# CONFIG [SED...]: the config with scene_dir set for this machine, run, tabled
study() {
    local conf=$1 name
    name=$(basename "$conf" .conf)
    shift
    sed -e "s|^scene_dir: \.\./shared/scenes/course|scene_dir: $course|" "$@" "$conf" > "/tmp/$name.conf"
    $B/harness/harness run "/tmp/$name.conf" --raytrace $B/renderer/raytrace -o "$OUT/$name.csv" -q \
        2> "$OUT/$name.log" || { tail -5 "$OUT/$name.log"; return 0; }
    $B/harness/harness table "$OUT/$name.csv" > "$OUT/$name-table.md" || true
    echo "== $name"; cat "$OUT/$name-table.md"
}

# NAME RANKS: one run of each GPU case of gpus-NAME.conf, its timing keys
keys() {
    local conf=/tmp/gpus-$1.conf scene res dir
    dir=$(sed -n 's/^scene_dir: //p' "$conf")
    scene=$(find "$dir" -name "$(sed -n 's/^scenes: //p' "$conf").txt" | head -1)
    for res in $(sed -n 's/^resolution: //p' "$conf"); do
        for np in cuda $2; do
            if [ "$np" = cuda ]; then run=($B/renderer/raytrace --backend cuda)
            else run=(mpirun --bind-to none -np "$np" $B/renderer/raytrace --backend mpi-cuda); fi
            echo "== $1 $res ${run[*]:0:4}"
            "${run[@]}" -q -r "$res" "$scene" -o /tmp/keys.png | tr ' ' '\n' | grep -E \
                '^(render_ms|render_ms_min|kernel_ms|download_ms|waves|in_flight|frames|first_ms|rank_[a-z_]+)=' |
                tr '\n' ' '
            echo
        done
    done | tee -a "$OUT/keys.txt"
}

for step in $steps; do
    case $step in
    test)
        meson test -C $B --suite gpu --num-processes 1 > "$OUT/gpu-tests.txt" 2>&1 || true
        grep -E '^ *[0-9]+/[0-9]+ |^(Ok|Fail|Skipped):' "$OUT/gpu-tests.txt"
        grep -E ' np=[0-9]| GPU\(s\)|^  \| |^FAIL' $B/meson-logs/testlog.txt > "$OUT/mpi-cuda-check.txt" || true ;;
    shared)
        CUDA_VISIBLE_DEVICES=0 study configs/mpi-cuda-shared.conf ;;
    gpus)
        keep=""
        for n in 1 2 4 8; do [ "$n" -le "$ngpu" ] && keep="$keep $n"; done
        SCENEGEN=$B/renderer/scenegen scripts/gen-scenes.sh island-4m > /dev/null
        for c in configs/gpus-dragon.conf configs/gpus-island.conf; do
            study "$c" -e "s|^ranks:.*|ranks:$keep|"
        done ;;
    ab)
        tar xzf .devcarry/base.tar.gz -C /tmp
        (cd /tmp/base && { [ -f /tmp/build-base/build.ninja ] || meson setup /tmp/build-base "${args[@]}"; } &&
            ninja -C /tmp/build-base renderer/raytrace) > "$OUT/base-build.log" 2>&1 ||
            { tail -5 "$OUT/base-build.log"; exit 1; }
        keep=""
        for n in 1 2 4 8; do [ "$n" -le "$ngpu" ] && keep="$keep $n"; done
        SCENEGEN=$B/renderer/scenegen scripts/gen-scenes.sh island-4m > /dev/null
        for c in ${STUDIES:-dragon island}; do
            sed -e "s|^scene_dir: \.\./shared/scenes/course|scene_dir: $course|" -e "s|^ranks:.*|ranks:$keep|" \
                "configs/gpus-$c.conf" > "/tmp/gpus-$c.conf"
            $B/harness/harness ab --config "/tmp/gpus-$c.conf" /tmp/build-base/renderer/raytrace \
                $B/renderer/raytrace --rounds "${ROUNDS:-5}" > "$OUT/ab-$c.txt" 2> "$OUT/ab-$c.err" || true
            grep -E '^(IMPROVEMENT|REGRESSION|INCONCLUSIVE|no change)' "$OUT/ab-$c.txt"
            keys "$c" "$keep"
        done ;;
    *) echo "device-gpus: unknown step '$step' (test, shared, gpus, ab)" >&2; exit 1 ;;
    esac
done
