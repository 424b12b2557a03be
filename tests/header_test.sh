#!/bin/sh
# header_test.sh CC NVCC HEADER... - every shared RT_HD header compiles ALONE,
# as strict C11 and through nvcc (pbrt-v4's CPU/GPU rule): no VLAs, compound
# literals, designated initializers, bare restrict or implicit void* casts,
# and no missing includes, each with the parameter rt_traverse.h asks for (the
# CPU's leaf vote). The shading loop's template (rt_path_tmpl.h) and
# rt_traverse.h must refuse to compile without their parameters; one extra
# unit instantiates the template with both traversals and the GPU's vote, as
# kernels.cuh does, and launches a kernel that calls it, so the device code
# of every function really gets compiled.
# NVCC may be "none": then only the C half runs.
set -u
cc=$1 nvcc=$2
shift 2
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fails=0
vote='#define RT_WIDE_LEAF_VOTE(has_leaf, any) (has_leaf)'
for h in "$@"; do
    dir=$(dirname "$h") base=$(basename "$h")
    printf '%s\n#include "%s"\n#include "%s"\n' "$vote" "$base" "$base" > "$tmp/t.c"
    if ! "$cc" -std=c11 -pedantic-errors -Wall -Wextra -Werror -I"$dir" -c "$tmp/t.c" -o "$tmp/t.o"; then
        echo "FAIL: $base does not compile alone as C11"; fails=$((fails + 1))
    fi
    if [ "$nvcc" != none ]; then
        printf '%s\n#include "%s"\n' "$vote" "$base" > "$tmp/t.cu"
        if ! "$nvcc" -std=c++17 -arch=sm_90 -Werror all-warnings -I"$dir" -c "$tmp/t.cu" -o "$tmp/t.o"; then
            echo "FAIL: $base does not compile alone through nvcc"; fails=$((fails + 1))
        fi
    fi
done
dir=$(dirname "$1")
printf '%s\n#include "rt_path_tmpl.h"\n' "$vote" > "$tmp/p.c"
if "$cc" -std=c11 -I"$dir" -c "$tmp/p.c" -o "$tmp/p.o" 2> "$tmp/p.err" || ! grep -q 'define RT_PATH_TRACE' "$tmp/p.err"; then
    echo "FAIL: rt_path_tmpl.h without its parameters does not stop at its #error"; fails=$((fails + 1))
fi
printf '#include "rt_traverse.h"\n' > "$tmp/v.c"
if "$cc" -std=c11 -I"$dir" -c "$tmp/v.c" -o "$tmp/v.o" 2> "$tmp/v.err" || ! grep -q 'define RT_WIDE_LEAF_VOTE' "$tmp/v.err"; then
    echo "FAIL: rt_traverse.h without RT_WIDE_LEAF_VOTE does not stop at its #error"; fails=$((fails + 1))
fi
if [ "$nvcc" != none ]; then
    cat > "$tmp/k.cu" <<'CU'
#if defined(__CUDA_ARCH__)
#define RT_WIDE_LEAF_VOTE(has_leaf, any) __all_sync(__activemask(), (has_leaf))
#else
#define RT_WIDE_LEAF_VOTE(has_leaf, any) (has_leaf)
#endif
#define RT_PATH_TRACE(s, o, d, tmax, any, hit, cnt, light) \
    ((s)->wide ? rt_trace_ray_wide(s, o, d, tmax, any, hit, cnt) : rt_trace_ray(s, o, d, tmax, any, hit, cnt))
#define RT_PATH_NAME(f) f
#define RT_PATH_FN static inline RT_HD
#include "rt_path_tmpl.h"
__global__ void k(RtSceneView s, float *rgb, RtCounters *c)
{
    RtCounters mine = {0, 0, 0, 0, 0};
    rt_render_pixel(&s, (int)threadIdx.x, (int)blockIdx.x, RT_ANY_HIT_SLOT, rgb, &mine);
    atomicAdd((unsigned long long *)&c->primary_rays, (unsigned long long)mine.primary_rays);
}
CU
    if ! "$nvcc" -std=c++17 -arch=sm_90 -Werror all-warnings -I"$dir" -c "$tmp/k.cu" -o "$tmp/k.o"; then
        echo "FAIL: the shading loop does not compile as device code"; fails=$((fails + 1))
    fi
else
    echo "nvcc not found: C11 half only"
fi
echo "header_test: $fails failures"
[ $fails -eq 0 ]
