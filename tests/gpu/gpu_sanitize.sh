#!/bin/sh
# gpu_sanitize.sh RAYTRACE SCENE_DIR - compute-sanitizer memcheck and
# racecheck on two scenes (a glass/mirror sphere scene, deepest ray stacks, and
# the dragon mesh through the BVH and brute force; blocks with and without
# pixel pairs, odd shapes, the default centre order), at a reduced
# resolution: the tools slow kernels down a hundredfold or more. The
# large-image defaults (persistent 8x8 blocks, 3 blocks per multiprocessor)
# on the sphere scene at 2560x1920, with no --block. Any report fails the test.
# Exit 77 without a GPU or without compute-sanitizer.
set -u
. "$(dirname "$0")/../course.sh"
RT=$1; DIR=$(course_path "$2")
command -v nvidia-smi >/dev/null 2>&1 && nvidia-smi -L 2>/dev/null | grep -q '^GPU ' || { echo "SKIP: no GPU"; exit 77; }
CS=$(command -v compute-sanitizer || ls /usr/local/cuda/bin/compute-sanitizer 2>/dev/null) || { echo "SKIP: no compute-sanitizer"; exit 77; }
[ -d "$DIR" ] || { echo "SKIP: no course scenes at $DIR"; exit 77; }
TMP=$(mktemp -d) || exit 1
trap 'rm -rf "$TMP"' EXIT
fail=0
for tool in memcheck racecheck; do
    for run in "SphereExamples/spheres2 bvh 16x16 160x120" "InterestingScenes/dragon bvh 13x7 128x96" \
               "InterestingScenes/dragon bvh 32x8 128x96" "InterestingScenes/dragon none 32x32 64x48" \
               "SphereExamples/spheres2 none 32x8 160x120" "SphereExamples/spheres2 bvh 16x8 160x120" \
               "InterestingScenes/dragon bvh 8x8 128x96" "InterestingScenes/dragon bvh - 128x96" \
               "SphereExamples/spheres2 bvh - 2560x1920 large"; do
        set -- $run
        log="$TMP/log"
        # 3rd field: the block, - for none (the defaults); 5th: large (the
        # record must say large=1)
        blk="--block $3"; [ "$3" = - ] && blk=""
        # shellcheck disable=SC2086
        "$CS" --tool "$tool" --error-exitcode 3 "$RT" -q --backend cuda --accel "$2" --runs 1 --warmup 0 \
            $blk -r "$4" -o "$TMP/out.ppm" "$DIR/$1.txt" >"$log" 2>&1
        rc=$?
        if [ $rc -eq 0 ] && [ "${5:-}" = large ] && ! grep -q " large=1 " "$log"; then
            echo "$tool $1: the record does not say large=1"; rc=1
        fi
        summary=$(grep -E "ERROR SUMMARY|RACECHECK SUMMARY" "$log" | tail -1)
        echo "$tool $1 $2 $3 $4 ${5:-}: exit $rc: $summary (pairs=$(sed -n 's/.* pairs=\([01]\) .*/\1/p' "$log"))"
        if [ $rc -ne 0 ]; then cat "$log"; fail=1; fi
    done
done
exit $fail
