#!/usr/bin/env bash
# device-large.sh [bench|ab|warm]... - the large-scene measurements on the GPU
# machine (docs/performance.md, "Large scenes"); run through the device tool
# from the repository root with carry [".devcarry"]:
#   bench  scripts/bench-large.sh on the CUDA backend at 1920x1080, 10K to
#          4M triangles, every core (CSV and table under $OUT)
#   ab     the 3,567,202-triangle scene (gen-scenes.sh large-4m) loaded and
#          rendered by the older commit in .devcarry/old.tar.gz (`git archive
#          OLD | gzip`) and by this tree, interleaved, ROUNDS (default 5)
#          rounds: parse, build, render, node visits and image (the same
#          tree gives the same visits)
#   warm   the first image from a warm cache: the whole command
#          `raytrace -q --backend cuda --cache DIR -r 1920x1080 -o x.png`
#          on that scene, timed from outside, for the older commit and this
#          tree, interleaved, ROUNDS rounds; and the floor every CUDA run pays
#          (process start and CUDA context): an empty scene at 1x1, and a
#          one-sphere scene at 1920x1080 with its PNG
#   warmcpu the same first image on the CPU (--backend openmp on every core,
#          at 640x360 and 1920x1080), the older commit and this tree
#          interleaved, ROUNDS rounds
#   check  what checking the scene's cache entry costs (benchmarks/cache_check.c:
#          the whole parse of this tree's entry, and the index and tree
#          checks alone, ROUNDS rounds each; after warmcpu)
# .devcarry/include/xxhash.h stands in for libxxhash-dev where the machine
# lacks it (the scene cache needs only the header).
set -euo pipefail
cd "$(dirname "$0")/.."
ROUNDS=${ROUNDS:-5} # rounds of ab and warm
old_build() {
    mkdir -p /tmp/old-src
    tar -xzf .devcarry/old.tar.gz -C /tmp/old-src
    [ -f /tmp/build-old/build.ninja ] ||
        meson setup /tmp/build-old /tmp/old-src -Dgpu_arch=9.0 -Dharness=false -Dcourse_dir=none "${args[@]}" > /dev/null
    ninja -C /tmp/build-old renderer/raytrace > /dev/null
}
cmd_ms() { # cmd_ms CMD...: the command's record on stdout, then cmd_ms=... (its time from outside)
    local t0 t1 rec
    t0=$(date +%s%N)
    rec=$("$@")
    t1=$(date +%s%N)
    echo "$rec cmd_ms=$(( (t1 - t0) / 1000000 ))"
}
OUT=${OUT:-/tmp/device-large}
mkdir -p "$OUT"
args=()
[ -f /usr/include/xxhash.h ] || args+=("-Dc_args=-I$PWD/.devcarry/include")
[ -f build-large/build.ninja ] || meson setup build-large -Dgpu_arch=9.0 -Dcourse_dir=none "${args[@]}" > /dev/null
ninja -C build-large > /dev/null
rt_of() { [ "$1" = old ] && echo /tmp/build-old/renderer/raytrace || echo build-large/renderer/raytrace; }
k() { printf '%s\n' "$rec" | tr ' ' '\n' | sed -n "s/^$1=//p"; } # a key of the record in $rec
emit() { # emit FILE PREFIX KEY...: one CSV row, PREFIX then the keys of $rec
    local f=$1 line=$2
    shift 2
    for key in "$@"; do line="$line,$(k "$key")"; done
    echo "$line" | tee -a "$f"
}
scene_4m() { # the older build, the scene in $s, settled for its hash memo
    old_build
    SCENEGEN=build-large/renderer/scenegen scripts/gen-scenes.sh large-4m > /dev/null
    s=scenes/generated/large-4m.txt
    sleep 3 # (files changed within 2 s get no hash memo: docs/scene-format.md)
}
prime() { # prime BACKEND CACHE: each build's cache entry built, then loaded once
    for b in old new old new; do
        "$(rt_of $b)" -q --backend "$1" --cache "$2-$b" -r 64x36 -o /tmp/w.png "$s" > /dev/null
    done
}
for step in "${@:-bench ab}"; do
    case $step in
    bench)
        scripts/bench-large.sh --build build-large --backend cuda --resolution 1920x1080 --threads "$(nproc)" \
            --repeats 3 --out "$OUT/bench-large-h100" ;;
    ab)
        scene_4m
        f="$OUT/large-4m-ab.csv"
        echo "round,build,parse_ms,build_ms,render_ms,node_visits,image_fnv1a,sah_cost" > "$f"
        for r in $(seq "$ROUNDS"); do
            for b in old new; do
                rec=$("$(rt_of $b)" -q --backend cuda -r 1920x1080 -o /tmp/ab.ppm "$s")
                emit "$f" "$r,$b" parse_ms build_ms render_ms node_visits image_fnv1a sah_cost
            done
        done ;;
    warm)
        scene_4m
        : > /tmp/empty.txt
        printf 'film_resolution: 1920 1080\nsphere: 0 0 -5 1\n' > /tmp/one.txt
        prime cuda /tmp/warm
        f="$OUT/warm-cache-4m-ab.csv"
        echo "round,build,scene,cmd_ms,total_ms,parse_ms,init_ms,upload_ms,render_ms,write_ms,cache,image_fnv1a" > "$f"
        for r in $(seq "$ROUNDS"); do
            for b in old new floor-empty floor-one; do
                rt=$(rt_of $b)
                case $b in
                floor-empty) rec=$(cmd_ms "$rt" -q --backend cuda -r 1x1 -o /tmp/w.ppm /tmp/empty.txt) ;;
                floor-one) rec=$(cmd_ms "$rt" -q --backend cuda -o /tmp/w.png /tmp/one.txt) ;;
                *) rec=$(cmd_ms "$rt" -q --backend cuda --cache /tmp/warm-$b -r 1920x1080 -o /tmp/w.png "$s") ;;
                esac
                emit "$f" "$r,$b" scene cmd_ms total_ms parse_ms init_ms upload_ms render_ms write_ms cache image_fnv1a
            done
        done ;;
    warmcpu)
        scene_4m
        prime openmp /tmp/warm-cpu
        f="$OUT/warm-cache-4m-cpu.csv"
        echo "round,build,resolution,cmd_ms,total_ms,parse_ms,render_ms,write_ms,threads,cache,image_fnv1a" > "$f"
        for r in $(seq "$ROUNDS"); do
            for res in 640x360 1920x1080; do
                for b in old new; do
                    rec=$(cmd_ms "$(rt_of $b)" -q --backend openmp --cache /tmp/warm-cpu-$b -r "$res" -o /tmp/w.png "$s")
                    emit "$f" "$r,$b,$res" cmd_ms total_ms parse_ms render_ms write_ms threads cache image_fnv1a
                done
            done
        done ;;
    check)
        for e in /tmp/warm-cpu-new/*.rbc; do
            build-large/benchmarks/cache-check "$e" bvh "$ROUNDS" | tee -a "$OUT/cache-check-4m.txt"
        done ;;
    *) echo "device-large: unknown step $step" >&2; exit 2 ;;
    esac
done
