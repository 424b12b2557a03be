#!/usr/bin/env bash
# device-gpubvh.sh [test|ab|quality|split|first|context|stream|cache|oom]... - the GPU BVH build on the GPU
# machine (docs/performance.md, "The GPU build"); run through the device tool
# from the repository root with carry [".devcarry"] (the course scenes in
# .devcarry/scenes/course, .devcarry/include/xxhash.h where the machine lacks
# libxxhash-dev). Steps (default: all):
#   test     test_gpu_bvh on degenerate input, the project's and the course's
#            scenes and the two large sphere fields; gpu_check.sh's default
#            (CPU tree) and gpubuild (GPU tree) renders on four course scenes
#   ab       the first image of large-1m and large-4m at 1920x1080: the
#            commit in .devcarry/base.tar.gz (`git archive --prefix=base/ OLD
#            | gzip`; its CPU build), this tree with --builder cpu and with
#            --builder gpu, interleaved, ROUNDS rounds (default 5)
#   quality  each builder's tree rendered (--runs 5, 1920x1080) on the large
#            stand-ins and every course scene, 3 rounds: SAH cost, visits,
#            kernel time, image
#   split    the GPU build with and without its triangle pieces: this tree's
#            --builder gpu, the same with --gpu-split 30, and --builder cpu,
#            against the GPU build of the commit in .devcarry/prev.tar.gz
#            (`git archive --prefix=prev/ OLD | gzip`), --runs 5 at 1920x1080
#            on the large stand-ins and the dragon, interleaved, ROUNDS rounds
#            (default 3): build and kernel times, SAH cost, visits, image
#   first    text file to first image (--runs 1 --warmup 0, 1920x1080) of
#            large-4m and large-1m with --builder gpu and --builder cpu, and
#            of large-4m from a warm cache (an entry each version stored
#            first): the commit in .devcarry/prev.tar.gz against this tree,
#            interleaved, ROUNDS rounds (default 7): parse, context wait,
#            build, upload, write, total
#   context  the CUDA context's time: the demo scene's first image (its
#            init_ms is nearly all of the context), and large-4m and large-1m
#            with 16, 15, 14, 12 and 8 parse threads (--build-threads),
#            interleaved, ROUNDS rounds (default 5)
#   stream   the geometry copied up while the file is parsed (geom_up=parse)
#            against the commit in .devcarry/prev.tar.gz (the build copies
#            it after the parse): the first image (--runs 1 --warmup 0,
#            1920x1080, --builder gpu) of large-4m on 4, 8 and 16 parse
#            threads and of a 9.7M-triangle sphere field (0.86 GB of text,
#            made here) on 16, interleaved, ROUNDS rounds (default 7)
#   cache    the first image (--runs 1 --warmup 0) from a warm cache of
#            large-4m (an entry stored by the GPU build, then five loads,
#            every key of the record), each load beside three by the
#            OpenMP backend on every core, 16 and 4 (a 64x36 image: the load's
#            time alone), then benchmarks/cache-check on the entry
#   oom      tests/gpu/gpu_oom.sh: a render and a GPU build that do not fit
#            beside gpu_hog
# Output under $OUT (default /tmp/device-gpubvh).
set -uo pipefail
cd "$(dirname "$0")/.."
R=$PWD
OUT=${OUT:-/tmp/device-gpubvh}
mkdir -p "$OUT"
steps=${*:-test ab quality split cache}
course=$R/.devcarry/scenes/course
xx=()
[ -f /usr/include/xxhash.h ] || xx+=("-Dc_args=-I$R/.devcarry/include")
B=/tmp/b-head
[ -f $B/build.ninja ] || meson setup $B -Dgpu_arch=9.0 "-Dcourse_dir=$course" "${xx[@]}" > "$OUT/setup.log" 2>&1
ninja -C $B renderer/raytrace renderer/scenegen renderer/imgdiff tests/test_gpu_bvh benchmarks/cache-check > "$OUT/build.log" 2>&1 ||
    { tail -20 "$OUT/build.log"; exit 1; }
SCENEGEN=$B/renderer/scenegen scripts/gen-scenes.sh large-1m large-4m island-1m island-4m objects-1m > /dev/null 2>&1
export RAYBENCH_COURSE_DIR=$course
keys='^(scene|backend|builder|cache|bvh_pieces|parse_ms|build_ms|gpu_build_ms|build_init_ms|init_ms|upload_ms|geom_up|geom_up_ms|render_ms|kernel_ms|write_ms|total_ms|sah_cost|node_visits|image_fnv1a|bvh_nodes|prims)='
rec() { "$@" | tr ' ' '\n' | grep -E "$keys" | tr '\n' ' '; echo; }
C=course:InterestingScenes
build_prev() {
    [ -x /tmp/b-prev/renderer/raytrace ] && return 0
    rm -rf /tmp/prev && tar xzf .devcarry/prev.tar.gz -C /tmp
    (cd /tmp/prev && meson setup /tmp/b-prev -Dgpu_arch=9.0 -Dcourse_dir=none "${xx[@]}" > "$OUT/setup-prev.log" 2>&1 &&
        ninja -C /tmp/b-prev renderer/raytrace > "$OUT/build-prev.log" 2>&1) || { echo "prev build failed"; return 1; }
}
for step in $steps; do case $step in
test)
    timeout 300 $B/tests/test_gpu_bvh scenes/demo.txt scenes/glass.txt tests/scenes/odd.txt $C/dragon.txt \
        $C/arm-reach.txt $C/bottle.txt course:SphereExamples/spheres2.txt $C/ShadowTest.txt \
        scenes/generated/large-1m.txt scenes/generated/large-4m.txt > "$OUT/test.txt" 2>&1
    echo "test_gpu_bvh rc=$?"
    GPU_CHECK_BLOCKS="bvh:-:default bvh:-:gpubuild" sh tests/gpu/gpu_check.sh $B/renderer/raytrace \
        $B/renderer/imgdiff "$course" full InterestingScenes/dragon TriangleExamples/outdoor \
        SphereExamples/spheres2 InterestingScenes/ShadowTest > "$OUT/gpu-check.txt" 2>&1
    echo "gpu_check rc=$?" ;;
ab)
    tar xzf .devcarry/base.tar.gz -C /tmp
    (cd /tmp/base && meson setup /tmp/b-base -Dgpu_arch=9.0 "${xx[@]}" > "$OUT/setup-base.log" 2>&1 &&
        ninja -C /tmp/b-base renderer/raytrace > "$OUT/build-base.log" 2>&1) || { echo "base build failed"; exit 1; }
    for round in $(seq "${ROUNDS:-5}"); do
        for sc in large-1m large-4m; do
            echo -n "round=$round version=base "
            rec /tmp/b-base/renderer/raytrace --backend cuda -q -r 1920x1080 scenes/generated/$sc.txt -o /tmp/k.png
            for b in cpu gpu; do
                echo -n "round=$round version=head "
                rec $B/renderer/raytrace --backend cuda --builder $b -q -r 1920x1080 scenes/generated/$sc.txt -o /tmp/k.png
            done
        done
    done > "$OUT/first-image.txt" ;;
quality)
    for round in 1 2 3; do
        for f in scenes/generated/{large-1m,large-4m,island-1m,island-4m,objects-1m}.txt "$course"/*/*.txt; do
            for b in cpu gpu; do
                echo -n "round=$round "
                rec $B/renderer/raytrace --backend cuda --builder $b --runs 5 -q -r 1920x1080 "$f" -o /tmp/q.png
            done
        done
    done > "$OUT/quality.txt" ;;
split)
    build_prev || exit 1
    for round in $(seq "${ROUNDS:-3}"); do
        for f in scenes/generated/{large-1m,large-4m,island-1m,island-4m,objects-1m}.txt "$course"/InterestingScenes/dragon.txt; do
            for v in prev:gpu head:gpu head:gpu30 head:cpu; do
                x=$B/renderer/raytrace; [ ${v%:*} = prev ] && x=/tmp/b-prev/renderer/raytrace
                b=${v#*:} a=(); [ $b = gpu30 ] && b=gpu a=(--gpu-split 30)
                echo -n "round=$round version=$v "
                rec $x --backend cuda --builder $b "${a[@]}" --runs 5 -q -r 1920x1080 "$f" -o /tmp/s-$v.png
            done
            $B/renderer/imgdiff /tmp/s-head:gpu30.png /tmp/s-head:cpu.png 2>&1 | head -1
        done
    done > "$OUT/split.txt" 2>&1 ;;
first)
    build_prev || exit 1
    ver() { x=$B/renderer/raytrace; [ "$1" = prev ] && x=/tmp/b-prev/renderer/raytrace; echo $x; }
    for v in prev head; do
        rm -rf /tmp/rb-first-$v && mkdir -m 700 /tmp/rb-first-$v
        $(ver $v) --backend cuda --builder gpu --cache /tmp/rb-first-$v -q -r 1920x1080 --runs 1 --warmup 0 \
            scenes/generated/large-4m.txt -o /tmp/f.png > /dev/null
    done
    for round in $(seq "${ROUNDS:-7}"); do
        for sc in large-4m large-1m; do for b in gpu cpu; do for v in prev head; do
            echo -n "round=$round case=$sc version=$v "
            rec $(ver $v) --backend cuda --builder $b --runs 1 --warmup 0 -q -r 1920x1080 \
                scenes/generated/$sc.txt -o /tmp/f-$v.png
        done; done; done
        for v in prev head; do
            echo -n "round=$round case=large-4m-cache version=$v "
            rec $(ver $v) --backend cuda --builder gpu --cache /tmp/rb-first-$v --runs 1 --warmup 0 -q \
                -r 1920x1080 scenes/generated/large-4m.txt -o /tmp/f-$v.png
        done
    done > "$OUT/first.txt" ;;
context)
    for round in $(seq "${ROUNDS:-5}"); do
        for sc in large-4m large-1m; do for bt in 16 15 14 12 8; do
            echo -n "round=$round case=$sc threads=$bt "
            rec $B/renderer/raytrace --backend cuda --builder gpu --runs 1 --warmup 0 --build-threads $bt -q \
                -r 1920x1080 scenes/generated/$sc.txt -o /tmp/f.png
        done; done
        echo -n "round=$round case=demo "
        rec $B/renderer/raytrace --backend cuda --runs 1 --warmup 0 -q -r 64x36 scenes/demo.txt -o /tmp/f.png
    done > "$OUT/context.txt" ;;
stream)
    build_prev || exit 1
    [ -s /tmp/large-10m.txt ] || $B/renderer/scenegen --kind spheres --triangles 11000000 --seed 1 \
        --resolution 1920x1080 -o /tmp/large-10m.txt > /dev/null 2>&1
    for round in $(seq "${ROUNDS:-7}"); do
        for c in large-4m:4 large-4m:8 large-4m:16 large-10m:16; do for v in prev head; do
            x=$B/renderer/raytrace; [ $v = prev ] && x=/tmp/b-prev/renderer/raytrace
            f=scenes/generated/${c%:*}.txt; [ ${c%:*} = large-10m ] && f=/tmp/large-10m.txt
            echo -n "round=$round case=${c%:*} threads=${c#*:} version=$v "
            rec $x --backend cuda --builder gpu --build-threads ${c#*:} --runs 1 --warmup 0 -q -r 1920x1080 \
                "$f" -o /tmp/st-$v.png
        done; done
    done > "$OUT/stream.txt" ;;
cache)
    rm -rf /tmp/rb-cache && mkdir -m 700 /tmp/rb-cache
    for i in 0 1 2 3 4 5; do
        echo -n "cache run=$i "
        $B/renderer/raytrace --backend cuda --builder gpu --cache /tmp/rb-cache -q -r 1920x1080 --runs 1 \
            --warmup 0 scenes/generated/large-4m.txt -o /tmp/c.png
        [ $i = 0 ] && continue
        for nt in $(nproc) 16 4; do
            echo -n "cache run=$i omp_threads=$nt "
            OMP_NUM_THREADS=$nt rec $B/renderer/raytrace --backend openmp --cache /tmp/rb-cache -q -r 64x36 \
                scenes/generated/large-4m.txt -o /tmp/c.png
        done
    done > "$OUT/cache.txt"
    for nt in $(nproc) 16 4; do
        echo -n "omp_threads=$nt "
        OMP_NUM_THREADS=$nt $B/benchmarks/cache-check /tmp/rb-cache/*.rbc bvh 5
    done >> "$OUT/cache.txt" 2>&1 ;;
oom)
    ninja -C $B tests/gpu/gpu_hog >> "$OUT/build.log" 2>&1 || { echo "gpu_hog build failed"; exit 1; }
    sh tests/gpu/gpu_oom.sh $B/renderer/raytrace $B/tests/gpu/gpu_hog $B/renderer/scenegen > "$OUT/oom.txt" 2>&1
    echo "gpu_oom rc=$?" | tee -a "$OUT/oom.txt" ;;
*) echo "device-gpubvh: unknown step '$step' (test, ab, quality, split, first, context, stream, cache, oom)" >&2; exit 2 ;;
esac; done
