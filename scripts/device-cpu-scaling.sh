#!/bin/bash
# device-cpu-scaling.sh: the CPU scaling study on the GPU machine's 16-core
# CPU (the `run` device tool, docs/cpu-backends.md). Builds the renderer and
# the harness, then runs the OpenMP and MPI scaling configs on the dragon
# (the report's schemes pixels/rows next to the load-balanced defaults
# tiles/dynamic; BVH at the scene's 512x384 and at 1024x768; brute force at
# 128x96), the tile sweep, hybrid ranks x threads and the MPI scene-loading
# comparison. Every CSV, table and log goes to $OUT.
#
# The device gets the git working tree only, so the course scenes travel in
# .devcarry/scenes (git-ignored):
#   mkdir -p .devcarry/scenes && cp ../shared/scenes/course/InterestingScenes/{dragon,arm-reach}.txt .devcarry/scenes/
#   run: bash scripts/device-cpu-scaling.sh     (carry: [".devcarry"], timeout 600)
# Stages run in order of importance and are skipped once BUDGET_S seconds
# have gone, so one 600 s call always brings something back.
set -u
# The device tool brings back at most 8 files from $OUT: everything is written
# to a work folder and packed into $OUT/cpu-device-scaling.tar.gz at the end.
FINAL=${OUT:-/tmp/device-cpu-out}
OUT=$(mktemp -d /tmp/cpu-scaling.XXXXXX)
mkdir -p "$FINAL"
SCENES=${SCENES:-.devcarry/scenes}
BUDGET_S=${BUDGET_S:-480}
mkdir -p "$OUT"
T0=$(date +%s)
trap 'tar -C "$OUT" -czf "$FINAL/cpu-device-scaling.tar.gz" . 2>/dev/null' EXIT
log() { echo "[$(($(date +%s) - T0))s] $*" | tee -a "$OUT/log.txt"; }
time_left() { [ $(($(date +%s) - T0)) -lt "$BUDGET_S" ]; }
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1

{ uname -a; nproc; lscpu; command -v hwloc-ls >/dev/null && hwloc-ls --no-io; mpirun --version; gcc --version | head -1; } \
    > "$OUT/machine.txt" 2>&1

harness=true
# .devcarry/include/xxhash.h stands in for libxxhash-dev (the scene cache the
# harness asks for) where the machine lacks it
xx=()
[ -f /usr/include/xxhash.h ] || xx+=("-Dc_args=-I$PWD/.devcarry/include")
if ! meson setup build-dev -Dcuda=disabled -Dharness=true -Dpng=auto "${xx[@]}" > "$OUT/setup.log" 2>&1; then
    log "setup with the harness failed; without it"
    harness=false
    rm -rf build-dev
    meson setup build-dev -Dcuda=disabled -Dharness=false -Dpng=auto "${xx[@]}" >> "$OUT/setup.log" 2>&1 || { log "setup failed"; exit 1; }
fi
if ! ninja -C build-dev > "$OUT/build.log" 2>&1; then
    log "build failed"; tail -30 "$OUT/build.log"; exit 1
fi
H=build-dev/harness/harness
RT=build-dev/renderer/raytrace
[ -x "$H" ] || harness=false
grep -q 'HAVE_PNG 1' build-dev/config.h && png=1 || png=0
log "built: harness=$harness png=$png"

# A shipped config made to run here: scenes from .devcarry; without libpng the
# harness's image.png cannot be written, so a later -o (getopt: last one
# wins) sends the image to a .ppm.
devconf() { # CONFIG [extra key lines...]
    local src=$1 dst=$OUT/conf/$(basename "$1"); shift
    mkdir -p "$OUT/conf"
    sed -e "s|^scene_dir:.*|scene_dir: $SCENES|" -e '/^extra_args:/d' "$src" > "$dst"
    for kv in "$@"; do
        key=${kv%%:*}
        sed -i "/^$key:/d" "$dst"
        echo "$kv" >> "$dst"
    done
    [ $png = 0 ] && echo "extra_args: -o /tmp/devimg.ppm" >> "$dst"
    echo "$dst"
}
study() { # NAME CONFIG [extra key lines...]
    local name=$1 conf; shift
    time_left || { log "skip $name: out of time"; return; }
    conf=$(devconf "$@")
    log "run $name"
    # never past the device's 600 s limit: the rows written so far are kept
    timeout $((BUDGET_S + 100 - ($(date +%s) - T0))) "$H" run "$conf" -o "$OUT/$name.csv" -q \
        > "$OUT/$name.log" 2>&1 || log "$name: harness exit $?"
    "$H" table "$OUT/$name.csv" > "$OUT/$name-table.md" 2>&1
}

if $harness; then
    study cpu-openmp-bvh configs/openmp-scaling-bvh.conf
    study cpu-mpi-bvh configs/mpi-scaling-bvh.conf
    study cpu-openmp-bvh-2048 configs/openmp-scaling-bvh.conf "resolution: 2048x1536" "schedule: tiles" \
        "study: openmp-scaling-bvh-2048" "repeats: 3"
fi

# MPI scene loading on the largest course scene: every rank parses vs rank 0
# parses and broadcasts. load_ms_max = the slowest rank's time until it holds
# the scene. Own loop: the harness has no sweep over extra arguments.
if time_left; then
    log "scene loading (arm-reach, 16 ranks)"
    echo "how,ranks,repeat,load_ms_max,parse_ms_rank0" > "$OUT/cpu-mpi-scene-load.csv"
    for np in 4 16; do
        for rep in 1 2 3 4 5; do
            for how in every bcast; do
                rec=$(mpirun --bind-to core --map-by core -np $np "$RT" -q --backend mpi --mpi-scene $how -r 64x48 \
                    -o /tmp/devimg.ppm "$SCENES/arm-reach.txt" 2>>"$OUT/scene-load.err")
                l=$(echo "$rec" | tr ' ' '\n' | sed -n 's/^load_ms_max=//p')
                p=$(echo "$rec" | tr ' ' '\n' | sed -n 's/^parse_ms=//p')
                echo "$how,$np,$rep,$l,$p" >> "$OUT/cpu-mpi-scene-load.csv"
            done
        done
    done
fi

if $harness; then
    study cpu-openmp-bvh-1024 configs/openmp-scaling-bvh.conf "resolution: 1024x768" "study: openmp-scaling-bvh-1024" "repeats: 3"
    study cpu-mpi-bvh-1024 configs/mpi-scaling-bvh.conf "resolution: 1024x768" "study: mpi-scaling-bvh-1024" "repeats: 3"
    study cpu-tile-sweep configs/openmp-tile-sweep.conf "threads: 16" "scenes: dragon" "study: openmp-tile-sweep-16"
    study cpu-hybrid configs/hybrid-dragon.conf "ranks: 1 2 4 8 16" "threads: 1 2 4"
    study cpu-openmp-none-small configs/openmp-scaling-none-small.conf "repeats: 2"
    study cpu-mpi-none-small configs/mpi-scaling-none-small.conf "repeats: 2"
else
    # Without the harness: the same sweeps timed by hand (median-free: every
    # run is one row; pinning by OMP_PLACES/OMP_PROC_BIND and mpirun).
    csv=$OUT/cpu-fallback.csv
    echo "backend,accel,resolution,schedule,workers,repeat,render_ms,render_ms_min,image_fnv1a,cores" > "$csv"
    row() { echo "$1" | tr ' ' '\n' | sed -n "s/^$2=//p"; }
    for res in 512x384; do
        for rep in 1 2 3; do
            time_left || break
            r=$("$RT" -q -r $res -o /tmp/devimg.ppm "$SCENES/dragon.txt")
            echo "serial,bvh,$res,-,1,$rep,$(row "$r" render_ms),-,$(row "$r" image_fnv1a),-" >> "$csv"
            for t in 1 2 4 8 16; do
                for s in pixels tiles; do
                    r=$(OMP_PLACES=cores OMP_PROC_BIND=close "$RT" -q -b openmp --threads $t --schedule $s -r $res \
                        -o /tmp/devimg.ppm "$SCENES/dragon.txt")
                    echo "openmp,bvh,$res,$s,$t,$rep,$(row "$r" render_ms),-,$(row "$r" image_fnv1a),\"$(row "$r" cores)\"" >> "$csv"
                    s2=$([ $s = pixels ] && echo rows || echo dynamic)
                    r=$(mpirun --bind-to core --map-by core -np $t "$RT" -q -b mpi --mpi-schedule $s2 -r $res \
                        -o /tmp/devimg.ppm "$SCENES/dragon.txt")
                    echo "mpi,bvh,$res,$s2,$t,$rep,$(row "$r" render_ms),$(row "$r" render_ms_min),$(row "$r" image_fnv1a),\"$(row "$r" cores)\"" >> "$csv"
                done
            done
        done
    done
fi
log "done"
ls -la "$OUT" >> "$OUT/log.txt"
tar -C "$OUT" -czf "$FINAL/cpu-device-scaling.tar.gz" .
cp "$OUT/log.txt" "$FINAL/log.txt"
