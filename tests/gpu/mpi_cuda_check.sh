#!/bin/sh
# mpi_cuda_check.sh RAYTRACE MPIRUN MODE SCENE[@WxH][+none]...
#
# The MPI backend with a GPU per rank against the CUDA backend:
#   full   for each scene, `--backend cuda --verify` is the reference (the
#          floats come down and the host quantises them); `--backend cuda`
#          without --verify (quantised on the GPU) must give the same file.
#          Then `--backend mpi-cuda`, with --verify and without, on 1, 2 and
#          4 ranks (--share-gpu where the ranks outnumber the GPUs) must give
#          the same image file and exactly the same five counters, say
#          ranks=N, and give the ranks shares of the tile rows that add up to
#          1. Then more ranks than GPUs without --share-gpu must fail: one
#          line naming --share-gpu, exit 1, no image, no hang.
#   fault  RAYTRACE is raytrace-testhooks: rank 1's GPU faults for real (a
#          trapping kernel) in the middle of a study of 2 ranks: one line
#          naming rank 1 and the CUDA error, exit 1, no image, no hang.
#   nogpu  2 ranks where there is no GPU: one line, exit 1, no image (the CI
#          machine); skipped where a GPU is present.
# SCENE@WxH renders at that size; +none with brute force (the persistent
# schedule). Exit 77 (skipped) without a GPU in full mode.
set -u
RT=$1; MPIRUN=$2; MODE=$3; shift 3
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_mpi_yield_when_idle=1
[ "$MPIRUN" != none ] || { echo "SKIP: no mpirun"; exit 77; }
ngpu=$(nvidia-smi -L 2>/dev/null | grep -c '^GPU ')
TMP=$(mktemp -d) || exit 1
trap 'rm -rf "$TMP"' EXIT
fail=0

# NAME PATTERN NP ARGS...: one stderr line with PATTERN, exit 1, no image,
# within 30 s
expect_one_error() {
    name=$1 pat=$2 np=$3; shift 3
    rm -f "$TMP/err.ppm"
    timeout 30 "$MPIRUN" --quiet --oversubscribe -np "$np" "$RT" -q "$@" -o "$TMP/err.ppm" >"$TMP/out" 2>"$TMP/err"
    rc=$?
    lines=$(grep -v -c '^\[warn\] Epoll ' "$TMP/err")
    echo "$name: exit $rc:"; sed 's/^/  | /' "$TMP/err"
    [ $rc = 1 ] || { echo "FAIL $name: exit $rc, expected 1"; fail=1; }
    [ "$lines" = 1 ] || { echo "FAIL $name: $lines lines on stderr, expected 1"; fail=1; }
    grep -q -- "$pat" "$TMP/err" || { echo "FAIL $name: the message lacks '$pat'"; fail=1; }
    [ ! -e "$TMP/err.ppm" ] || { echo "FAIL $name: an image was written"; fail=1; }
}

if [ "$MODE" = nogpu ]; then
    [ "$ngpu" = 0 ] || { echo "SKIP: a GPU is present"; exit 77; }
    expect_one_error "no GPU, 2 ranks" 'no usable GPU' 2 --backend mpi-cuda "${1%%[@+]*}"
    exit $fail
fi
[ "$ngpu" -gt 0 ] || { echo "SKIP: no GPU (nvidia-smi finds none)"; exit 77; }
if [ "$MODE" = fault ]; then
    share=""; [ "$ngpu" -lt 2 ] && share=--share-gpu
    # shellcheck disable=SC2086
    export RT_MPI_TEST_GPU_FAULT=1
    expect_one_error "rank 1's GPU faults mid-study" 'rank 1: .*cuda' 2 \
        --backend mpi-cuda $share --runs 20 "${1%%[@+]*}"
    exit $fail
fi

field() { printf '%s\n' "$1" | tr ' ' '\n' | sed -n "s/^$2=//p"; }
COUNTERS="image_fnv1a primary_rays shadow_rays secondary_rays node_visits prim_tests"

for arg in "$@"; do
    sc=${arg%%[@+]*}; size=""; accel=bvh
    case $arg in *@*) size=${arg#*@}; size=${size%%+*} ;; esac
    case $arg in *+none) accel=none ;; esac
    opts="--accel $accel ${size:+-r $size}"
    # shellcheck disable=SC2086
    ref=$("$RT" -q --verify --backend cuda $opts -o "$TMP/cuda.ppm" "$sc") ||
        { echo "FAIL $arg: cuda render"; fail=1; continue; }
    # shellcheck disable=SC2086
    "$RT" -q --backend cuda $opts -o "$TMP/cuda8.ppm" "$sc" > /dev/null &&
        cmp -s "$TMP/cuda.ppm" "$TMP/cuda8.ppm" ||
        { echo "FAIL $arg: cuda's image quantised on the GPU differs from the host's quantisation"; fail=1; }
    for run in "1 --verify" "2 --verify" "4 --verify" "1" "2" "4"; do
        np=${run%% *}; verify=""; [ "$run" = "$np" ] || verify=--verify
        share=""; [ "$np" -gt "$ngpu" ] && share=--share-gpu
        # shellcheck disable=SC2086
        rec=$(timeout 300 "$MPIRUN" --quiet --oversubscribe -np $np "$RT" -q $verify --backend mpi-cuda $share \
            $opts -o "$TMP/m.ppm" "$sc" | grep '^record:')
        [ -n "$rec" ] || { echo "FAIL $arg np=$np $verify: mpi-cuda render"; fail=1; continue; }
        bad=""
        for k in $COUNTERS; do
            [ "$(field "$ref" $k)" = "$(field "$rec" $k)" ] || bad="$bad $k:$(field "$ref" $k)/$(field "$rec" $k)"
        done
        [ "$(field "$rec" ranks)" = $np ] || bad="$bad ranks=$(field "$rec" ranks)"
        shares=$(field "$rec" rank_share)
        awk -v s="$shares" 'BEGIN { n = split(s, a, "/"); t = 0; for (i = 1; i <= n; i++) t += a[i];
                                    exit !(t > 0.997 && t < 1.003) }' || bad="$bad rank_share=$shares"
        cmp -s "$TMP/cuda.ppm" "$TMP/m.ppm" || bad="$bad image-file"
        echo "$arg np=$np $verify: render_ms=$(field "$rec" render_ms) (cuda $(field "$ref" render_ms))" \
             "gpus=$(field "$rec" gpus) share=$shares kernel_ms=$(field "$rec" rank_kernel_ms)" \
             "end_ms=$(field "$rec" rank_end_ms) ${bad:-identical}"
        [ -z "$bad" ] || { echo "FAIL $arg np=$np $verify:$bad"; fail=1; }
    done
done
np=$((ngpu + 1))
expect_one_error "$np ranks on $ngpu GPU(s)" '--share-gpu' $np --backend mpi-cuda "${1%%[@+]*}"
exit $fail
