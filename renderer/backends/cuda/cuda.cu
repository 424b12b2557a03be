/* cuda.cu - the CUDA backend: one thread per pixel, each running the shared
 * iterative Whitted code (rt_render_pixel -> rt_trace_path -> rt_trace_ray in
 * core/rt_*.h, compiled here by nvcc: one implementation for CPU and GPU).
 *
 * Host side, in order, every step checked (cuda_check.h):
 *   device -> block shape checked against the kernel's real limits -> one
 *   device allocation holding the flat scene arrays, the BVH exactly as the
 *   host built it, the image and the counters -> warm-up launches -> N timed
 *   launches (CUDA events; the median is render_ms) -> image download.
 *
 * Scheduling ("sched" in the record; RAYBENCH_CUDA_SCHED):
 *   persistent (default for --accel none): a grid that just fills the GPU;
 *     each warp takes the next 32 pixels from a global counter until none are
 *     left (Aila & Laine, "Understanding the efficiency of ray traversal on
 *     GPUs", HPG 2009), so finished warps pick up new work instead of idling
 *     until the slowest warp of their block ends.
 *   grid (default for --accel bvh): one block per BXxBY tile, as the report
 *     launched it; with small blocks the hardware's block scheduler balances
 *     as well, and it measured faster with the speculative wide traversal.
 *     Large images (RT_CUDA_LARGE_WAVES) take the persistent schedule in 8x8
 *     blocks instead, when no block or schedule was asked for.
 * In both, the block shape BXxBY is the pixel tile a block covers, so a warp
 * covers a 32-pixel piece of a BXxBY tile (8x4 pixels for 8x8 blocks, a row of
 * 32 for 32xN): that is what makes the shape matter for ray coherence.
 * RAYBENCH_CUDA_* variables override the defaults for measurements (docs/gpu.md). */
#include <errno.h>
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cuda_runtime.h>

/* Traversals (RAYBENCH_CUDA_TRAVERSAL, docs/gpu.md):
 *   wide (default): rt_trace_ray_wide, shared code (rt_traverse.h), on the
 *     4-wide copy of the BVH that rt_accel_build collapses from the binary
 *     tree: 6-20% less kernel time than ldg on the H100, same hits;
 *   ldg: a GPU variant of the shared binary traversal, kept for brute force
 *     and for comparison: the same arithmetic in the same order, the same
 *     visits and tests; only the loads differ (16-byte read-only loads of the
 *     32-byte nodes, 8-byte loads of the 40-byte primitives, one 8-byte stack
 *     entry instead of two arrays);
 *   shared: the shared binary traversal as the CPU runs it.
 * The shared binary traversal is compiled under another name, and rt_shade.h
 * -- included next, unchanged -- then calls the dispatcher below. */
/* The wide traversal's leaf vote (RT_WIDE_LEAF_VOTE, rt_traverse.h): a lane
 * that has put a leaf aside goes on through inner nodes until every active
 * lane of its warp has one. Always on: as a switch read from constant memory
 * (RAYBENCH_CUDA_SPEC=0|1, until the sixth round) the vote's branch cost up
 * to 14% of kernel time (0-2% at the course sizes), and testing each leaf at
 * once had measured slower (docs/gpu.md). Measured with the vote for
 * closest-hit rays only, too: slower than for every ray. */
#if defined(__CUDA_ARCH__)
#define RT_WIDE_LEAF_VOTE(has_leaf, any) __all_sync(__activemask(), (has_leaf))
#endif

#define rt_trace_ray rt_trace_ray_shared
#include "core/rt_traverse.h"
#undef rt_trace_ray

/* Which traversal the kernels run (RAYBENCH_CUDA_TRAVERSAL), set once per
 * render with cudaMemcpyToSymbol. */
enum { RT_TRAV_SHARED = 0, RT_TRAV_LDG = 1, RT_TRAV_WIDE = 2 };
__constant__ int rt_cuda_traversal;

#if defined(__CUDA_ARCH__)
static __device__ __forceinline__ float rt_cuda_box(float4 lo, float4 hi, const RtRayBox &rb, float tmax)
{
    /* The non-SSE rt_box_enter with tmin = 0 on a node already in registers. */
    return rt_slab_enter(lo.x, lo.y, lo.z, hi.x, hi.y, hi.z, &rb, 0.0f, tmax);
}

static __device__ int rt_trace_ray_ldg(const RtSceneView *s, RtVec3 o, RtVec3 d, float tmax, int any, RtHit *hit,
                                       RtCounters *cnt)
{
    hit->t = tmax;
    hit->u = hit->v = 0.0f;
    hit->id = 0xffffffffu;
    int found = 0;
    float u, v, t;
    RtPrim pr;
    if (s->nnodes == 0) {
        uint64_t tests = 0;
        for (uint32_t i = 0; i < s->nprims; i++) {
            tests++;
            rt_prim_fetch(&s->prims[i], &pr);
            t = rt_prim_intersect(&pr, o, d, &u, &v);
            if (t < hit->t) {
                hit->t = t; hit->u = u; hit->v = v; hit->id = pr.id;
                found = 1;
                if (any)
                    break;
            }
        }
        cnt->prim_tests += tests;
        return found;
    }
    const float4 *nodes = (const float4 *)s->nodes; /* node i: lo+index at 2i, hi+meta at 2i+1 */
    RtRayBox rb = rt_raybox(o, d);
    uint2 stack[RT_BVH_STACK]; /* x: node, y: entry distance bits */
    int sp = 0;
    uint32_t ni = 0;
    uint32_t visits = 0, tests = 0;
    float4 lo = __ldg(&nodes[0]), hi = __ldg(&nodes[1]);
    /* As the shared code: only a single-leaf tree has its root box tested here
     * (an inner root's box is covered by the tests of its two children). */
    if ((__float_as_uint(hi.w) & 0xffu) && rt_cuda_box(lo, hi, rb, tmax) == RT_INF) {
        cnt->node_visits += 1;
        return 0;
    }
    for (;;) {
        visits++;
        uint32_t count = __float_as_uint(hi.w) & 0xffu;
        if (count) {
            if (rt_leaf_hits(s, __float_as_uint(lo.w), count, o, d, any, hit, &found, &tests))
                goto done;
        } else {
            uint32_t a = ni + 1, b = __float_as_uint(lo.w);
            float4 alo = __ldg(&nodes[2 * a]), ahi = __ldg(&nodes[2 * a + 1]);
            float4 blo = __ldg(&nodes[2 * b]), bhi = __ldg(&nodes[2 * b + 1]);
            float ta = rt_cuda_box(alo, ahi, rb, hit->t), tb = rt_cuda_box(blo, bhi, rb, hit->t);
            if (ta != RT_INF && tb != RT_INF) {
                if (tb < ta) {
                    stack[sp++] = make_uint2(a, __float_as_uint(ta));
                    ni = b; lo = blo; hi = bhi;
                } else {
                    stack[sp++] = make_uint2(b, __float_as_uint(tb));
                    ni = a; lo = alo; hi = ahi;
                }
                continue;
            }
            if (ta != RT_INF) { ni = a; lo = alo; hi = ahi; continue; }
            if (tb != RT_INF) { ni = b; lo = blo; hi = bhi; continue; }
        }
        for (;;) {
            if (sp == 0)
                goto done;
            sp--;
            if (__uint_as_float(stack[sp].y) <= hit->t * RT_BOX_WIDEN)
                break;
        }
        ni = stack[sp].x;
        lo = __ldg(&nodes[2 * ni]);
        hi = __ldg(&nodes[2 * ni + 1]);
    }
done:
    cnt->node_visits += visits;
    cnt->prim_tests += tests;
    return found;
}
#endif

/* What rt_shade.h calls: on the GPU the 4-wide traversal (the default; shared
 * code, rt_traverse.h) or the binary tree's GPU variant; else the shared
 * binary traversal. Brute force has no wide tree and goes to the latter two. */
static inline RT_HD int rt_trace_ray(const RtSceneView *s, RtVec3 o, RtVec3 d, float tmax, int any, RtHit *hit,
                                     RtCounters *cnt)
{
#if defined(__CUDA_ARCH__)
    if (rt_cuda_traversal == RT_TRAV_WIDE && s->wide)
        return rt_trace_ray_wide(s, o, d, tmax, any, hit, cnt);
    if (rt_cuda_traversal != RT_TRAV_SHARED)
        return rt_trace_ray_ldg(s, o, d, tmax, any, hit, cnt);
#endif
    return rt_trace_ray_shared(s, o, d, tmax, any, hit, cnt);
}

extern "C" {
#include "rt.h"
/* the shading loop, after the dispatcher above: its rt_trace_ray calls bind to it */
#include "core/rt_shade.h"
}

#include "cuda_check.h"

/* Default block shapes, chosen by the block-size sweeps on the H100
 * (the tuning journal, git show 65ca656:the tuning journal, git show 65ca656:git show 65ca656:docs/gpu.md, "Fourth round" and "Seventh round"; results/gpu-blocks-round4.csv,
 * results/gpu-round7-blocks.csv): for the tree, 16x8 with the grid schedule
 * is the fastest on the dragon and has the best geometric mean over the
 * report's scenes with the spatial-split tree (8x8 had been, within 1%, with
 * the earlier tree); brute force keeps 8x8 (persistent schedule). */
#define RT_CUDA_DEFAULT_BX 16
#define RT_CUDA_DEFAULT_BY 8
#define RT_CUDA_DEFAULT_NONE_BX 8
#define RT_CUDA_DEFAULT_NONE_BY 8
/* Large images, tree (the tuning journal, git show 65ca656:git show 65ca656:docs/gpu.md, "Tenth round"; results/gpu-round10-large.csv,
 * results/gpu-round10-threshold.csv): from 2048x1536 up (46 and more waves
 * of the grid default's resident threads on the H100) the persistent
 * schedule in 4x8 blocks at MINB 3 was faster than the grid default on all
 * seven report scenes (3-17%); at 1920x1080 (31 waves) and 1600x1200 (28)
 * arm-reach was 10% and 3% slower with it, so the switch sits between.
 * Those sizes were measured with 4x8 blocks; 8x8 then measured faster. */
#define RT_CUDA_LARGE_WAVES 40.0
#define RT_CUDA_LARGE_BX 8 /* 8x8: 1.4% faster than 4x8 (geometric mean, faster on 13 of 14; */
#define RT_CUDA_LARGE_BY 8 /* results/gpu-round10-large-blocks.csv), MINB 4 11-13% slower */
#define RT_CUDA_LARGE_MINB 3
#define RT_CUDA_DEFAULT_RUNS 21
/* Host milliseconds of warm-up launches before the timed ones. */
#define RT_CUDA_DEFAULT_WARMUP_MS 50
/* Register cap of the default kernel: 65536 / (256 * MINB) registers per thread. */
#define RT_CUDA_DEFAULT_MINB 1
/* Work order (RAYBENCH_CUDA_ORDER): row-major tiles; scattered tiles
 * (persistent schedule); tiles by leaf coverage (grid schedule,
 * rt_cover_order_kernel); tiles from the image's centre outwards (grid
 * schedule, rt_cuda_center_order: its default, by measurement, git show 65ca656:docs/gpu.md
 * "Ninth round"); or the oracle order (either schedule, a measurement only:
 * rt_cuda_oracle_order). */
enum { RT_ORDER_TILES = 0, RT_ORDER_SCATTER = 1, RT_ORDER_ORACLE = 2, RT_ORDER_COVER = 3, RT_ORDER_CENTER = 4 };
#define RT_CUDA_DEFAULT_GRID_ORDER RT_ORDER_CENTER
#define RT_CUDA_DEFAULT_PERSISTENT_ORDER RT_ORDER_TILES
/* The default traversal: the 4-wide tree (docs/gpu.md). */
#define RT_CUDA_DEFAULT_TRAVERSAL RT_TRAV_WIDE
/* Timed launches stop once they have used this much kernel time in total, so a
 * brute-force render of a large image does not run 21 times. */
#define RT_CUDA_TIME_BUDGET_MS 4000.0

/* Launch geometry the kernel reads (passed by value, lives in constant bank). */
typedef struct RtCudaGrid {
    int32_t bx, by;        /* block shape = pixel tile shape, pixels */
    int32_t tiles_x;       /* tiles per image row */
    uint32_t tile_items;   /* bx * by: work items per tile */
    uint32_t total_items;  /* tiles_x * tiles_y * tile_items (edge tiles overhang the image) */
    int32_t persistent;    /* 1: warps fetch work from *next_item; 0: block b renders tile b */
    int32_t pairs;         /* 1: two lanes per pixel (rt_cuda_pair_item; grid only): tiles of bx/2 x by pixels */
    uint32_t ntiles;       /* tiles in the image */
    uint32_t tile_mask;    /* scatter order: 2^k - 1 >= ntiles - 1; 0: tiles in row-major order */
    /* Oracle order (RAYBENCH_CUDA_ORDER=oracle, a measurement): the n-th
     * 32-item chunk handed out is chunk_order[n]. NULL: off. */
    const uint32_t *chunk_order;
    /* Grid schedule, with an order (cover, center, oracle): block b renders tile
     * units[b] if b < *nunits (else it returns at once). NULL: block b renders
     * tile b. */
    const uint32_t *units;
    const uint32_t *nunits;
    /* A launch with chunks set records every 32-item chunk there (RtCudaChunk:
     * the oracle's first launch, RAYBENCH_CUDA_TIMELINE's last). NULL: off. */
    struct RtCudaChunk *chunks;
} RtCudaGrid;

/* Kernel modes (rt_render_kernel's MODE; rt_cuda_variants). RT_MODE_SLOT:
 * shadow rays are RT_ANY_HIT_SLOT queries (a node's entered children stacked
 * in slot order, rt_traverse.h) instead of RT_ANY_HIT (sorted); on its own
 * only, not with the other two. */
enum { RT_MODE_PAIRS = 1, RT_MODE_EXTRAS = 2, RT_MODE_SLOT = 4 };

/* One 32-item chunk (a warp's pixels) of a recorded launch: when it started
 * and ended (%globaltimer, ns), on which multiprocessor, and the traversal
 * steps (node visits + primitive tests) of its slowest lane and of all 32. */
typedef struct RtCudaChunk {
    unsigned long long t0, t1;
    uint32_t sm, steps_max;
    unsigned long long steps_sum;
    int32_t x, y; /* the pixel of the warp's first lane */
    uint32_t pairs, pad;
} RtCudaChunk;

enum { RT_NCOUNTERS = 5 }; /* fields of RtCounters, all uint64_t, in order */

/* Work item -> pixel: items are numbered tile by tile, row-major inside a
 * tile. Returns 0 for the overhang of an edge tile (outside the image). */
static __device__ __forceinline__ int rt_cuda_item_pixel(const RtSceneView &view, const RtCudaGrid &g,
                                                         uint32_t item, int *px, int *py)
{
    uint32_t tile = item / g.tile_items;
    uint32_t local = item - tile * g.tile_items;
    if (g.tile_mask) {
        /* Scatter order: the n-th tile handed out is a pseudo-random tile (an
         * affine bijection mod 2^k, cycle-walked into [0, ntiles)), so the
         * last tiles of a frame -- its tail -- are a sample of the whole image,
         * not its bottom rows. */
        do
            tile = (tile * 0x2545F491u + 0x9E3779B9u) & g.tile_mask;
        while (tile >= g.ntiles);
    }
    *px = (int)(tile % (uint32_t)g.tiles_x) * g.bx + (int)(local % (uint32_t)g.bx);
    *py = (int)(tile / (uint32_t)g.tiles_x) * g.by + (int)(local / (uint32_t)g.bx);
    return *px < view.cam.width && *py < view.cam.height;
}

/* Grid schedule: the pixel of thread tid in a block rendering tile `tile`
 * (of g.bx x g.by pixels): a lane per pixel, or with pairs the even and odd
 * lanes of a pixel. Returns 0 outside the image. */
static __device__ __forceinline__ int rt_cuda_unit_pixel(const RtSceneView &view, const RtCudaGrid &g, uint32_t tile,
                                                         bool pairs, unsigned tid, int *px, int *py)
{
    const uint32_t l = pairs ? tid >> 1 : tid;
    *px = (int)(tile % (uint32_t)g.tiles_x) * g.bx + (int)(l % (uint32_t)g.bx);
    *py = (int)(tile / (uint32_t)g.tiles_x) * g.by + (int)(l / (uint32_t)g.bx);
    return *px < view.cam.width && *py < view.cam.height;
}

/* Pixel pairs (RAYBENCH_CUDA_PAIRS=1, grid schedule): two lanes per pixel,
 * so that a pixel's shadow rays leave its chain of closest-hit rays. The
 * even lane runs the pending-ray stack of rt_trace_path (closest hits, the
 * ambient term, the children); at each hit it hands the surface to the odd
 * lane, which traces that hit's shadow rays (rt_light_sample, one light per
 * iteration) while the even lane already traces the next closest hit. Both
 * lanes go through one rt_trace_ray call per iteration (any = the lane's
 * role). The even lane waits only while the odd one still has lights of the
 * previous hit. The pixel is the sum of the two lanes' colours: the same
 * terms as rt_trace_path, added in another order. Whole warps only. */
typedef struct RtCudaJob {
    RtVec3 p, n, view, w; /* hit point, normal, -ray direction, ray weight */
    uint32_t material;
} RtCudaJob;

/* The partner lane's (lane ^ 1) vector; every lane of the warp calls it. */
static __device__ __forceinline__ RtVec3 rt_cuda_shfl_pair(RtVec3 v)
{
    return rt_v3(__shfl_xor_sync(0xffffffffu, v.x, 1), __shfl_xor_sync(0xffffffffu, v.y, 1),
                 __shfl_xor_sync(0xffffffffu, v.z, 1));
}

static __device__ __forceinline__ void rt_cuda_job_xchg(RtCudaJob *j, bool take)
{
    RtCudaJob o;
    o.p = rt_cuda_shfl_pair(j->p);
    o.n = rt_cuda_shfl_pair(j->n);
    o.view = rt_cuda_shfl_pair(j->view);
    o.w = rt_cuda_shfl_pair(j->w);
    o.material = __shfl_xor_sync(0xffffffffu, j->material, 1);
    if (take)
        *j = o;
}

static __device__ __forceinline__ void rt_cuda_pair_item(const RtSceneView &view, int px, int py, bool valid,
                                                         unsigned odd, float *rgb, RtCounters *cnt)
{
    const RtSceneView *s = &view;
    RtPending stack[RT_RAY_STACK];
    int sp = 0;
    RtVec3 color = rt_v3(0.0f, 0.0f, 0.0f);
    RtCudaJob job;                   /* even lane: the hit handed over; odd lane: the hit it shades */
    job.p = job.n = job.view = job.w = color;
    job.material = 0;
    bool full = false;               /* even lane: job holds a hit not yet taken */
    uint32_t next_light = s->nlights; /* odd lane: the next light of its hit to try */
    if (valid && !odd && s->max_depth > 0) {
        const RtRay r = rt_camera_ray(&s->cam, px, py);
        stack[0].o = r.o;
        stack[0].d = r.d;
        stack[0].w = rt_v3(1.0f, 1.0f, 1.0f);
        stack[0].depth = s->max_depth;
        sp = 1;
    }
    for (;;) {
        /* The odd lane takes the even lane's hit once it has tried every light of its last one. */
        const bool free_odd = odd && next_light >= s->nlights;
        const bool take = __shfl_xor_sync(0xffffffffu, odd ? free_odd : full, 1) && (odd ? free_odd : full);
        rt_cuda_job_xchg(&job, take && odd);
        if (take) {
            if (odd)
                next_light = 0;
            else
                full = false;
        }
        /* This iteration's ray: the even lane's next pending ray (unless its
         * hit still waits), the odd lane's next light with a contribution. */
        RtPending r;
        RtVec3 c, L;
        float dist = RT_INF;
        bool has = false;
        if (!odd) {
            if (!full && sp > 0) {
                r = stack[--sp];
                has = true;
                if (r.depth == s->max_depth)
                    cnt->primary_rays++;
                else
                    cnt->secondary_rays++;
            }
        } else {
            RtSurface sf;
            sf.p = job.p;
            sf.n = job.n;
            sf.front = 1;
            sf.material = job.material;
            const RtMaterial *m = &s->materials[job.material];
            while (!has && next_light < s->nlights)
                if (rt_light_sample(s, &sf, m, job.view, next_light++, &c, &L, &dist)) {
                    r.o = rt_shadow_origin(&sf);
                    r.d = L;
                    has = true;
                    cnt->shadow_rays++;
                }
        }
        if (!__any_sync(0xffffffffu, has || full || sp > 0 || (odd && next_light < s->nlights)))
            break;
        if (!has)
            continue;
        RtHit h;
        const int hit = rt_trace_ray(s, r.o, r.d, dist, (int)odd, &h, cnt);
        if (odd) {
            if (!hit)
                color = rt_add(color, rt_mul(job.w, c));
        } else if (!hit) {
            color = rt_add(color, rt_mul(r.w, s->background));
        } else {
            const RtSurface sf = rt_surface(s, r.o, r.d, &h);
            const RtMaterial *m = &s->materials[sf.material];
            color = rt_add(color, rt_mul(r.w, rt_ambient_term(s, m)));
            if (r.depth > 1)
                rt_push_children(stack, &sp, &r, &sf, m);
            job.p = sf.p;
            job.n = sf.n;
            job.view = rt_neg(r.d);
            job.w = r.w;
            job.material = sf.material;
            full = s->nlights > 0;
        }
    }
    const RtVec3 other = rt_cuda_shfl_pair(color);
    if (valid && !odd) {
        float *pp = rgb + 3 * ((size_t)py * (size_t)s->cam.width + (size_t)px);
        pp[0] = color.x + other.x;
        pp[1] = color.y + other.y;
        pp[2] = color.z + other.z;
    }
}

/* Exact counters: sum over the warp (shuffles), then the block (shared
 * atomics), then one 64-bit global atomic per counter and block. Called by
 * every thread of the block at the end of a kernel. */
static __device__ __forceinline__ void rt_cuda_flush_counters(const RtCounters &cnt, unsigned long long *block_cnt,
                                                              unsigned long long *counters, unsigned mask,
                                                              unsigned lane, unsigned tid)
{
    unsigned long long v[RT_NCOUNTERS] = {cnt.primary_rays, cnt.shadow_rays, cnt.secondary_rays, cnt.node_visits,
                                          cnt.prim_tests};
    if (mask == 0xffffffffu) {
#pragma unroll
        for (int k = 0; k < RT_NCOUNTERS; k++)
            for (int off = 16; off > 0; off >>= 1)
                v[k] += __shfl_down_sync(0xffffffffu, v[k], off);
        if (lane == 0)
            for (int k = 0; k < RT_NCOUNTERS; k++)
                atomicAdd(&block_cnt[k], v[k]);
    } else {
        /* Partial warp: shuffling from an absent lane is undefined; add each lane. */
        for (int k = 0; k < RT_NCOUNTERS; k++)
            atomicAdd(&block_cnt[k], v[k]);
    }
    __syncthreads();
    if (tid < RT_NCOUNTERS)
        atomicAdd(&counters[tid], block_cnt[tid]);
}

static __device__ __forceinline__ unsigned long long rt_cuda_globaltimer()
{
    unsigned long long t;
    asm volatile("mov.u64 %0, %%globaltimer;" : "=l"(t));
    return t;
}

/* Chunk records (RtCudaGrid.chunks; whole warps only: the host records only
 * for blocks of a multiple of 32 threads). */
static __device__ __forceinline__ void rt_cuda_chunk_begin(unsigned long long *t0, uint32_t *id, unsigned tid,
                                                           bool leader, uint32_t chunk)
{
    if (leader) {
        id[tid >> 5] = chunk;
        t0[tid >> 5] = rt_cuda_globaltimer();
    }
}

static __device__ __forceinline__ void rt_cuda_chunk_end(RtCudaChunk *chunks, const unsigned long long *t0,
                                                         const uint32_t *id, unsigned tid, bool leader,
                                                         unsigned mask, uint32_t steps, int px, int py, bool pairs)
{
    uint32_t mx = steps;
    unsigned long long sum = steps;
    for (int off = 16; off > 0; off >>= 1) {
        mx = max(mx, __shfl_down_sync(mask, mx, off));
        sum += __shfl_down_sync(mask, sum, off);
    }
    if (leader) {
        unsigned sm;
        asm volatile("mov.u32 %0, %%smid;" : "=r"(sm));
        RtCudaChunk *c = &chunks[id[tid >> 5]];
        c->t1 = rt_cuda_globaltimer();
        c->t0 = t0[tid >> 5];
        c->sm = sm;
        c->steps_max = mx;
        c->steps_sum = sum;
        c->x = px;
        c->y = py;
        c->pairs = pairs;
    }
}

/* MAXT is the largest block the instantiation is compiled for and MINB the
 * blocks per multiprocessor it must allow: together they cap the registers per
 * thread at 65536 / (MAXT * MINB) (rounded down to the allocation granule), so
 * that a 1024-thread block cannot be refused at launch for lack of registers --
 * the failure the report's 32x32 blocks hit without noticing -- and so that the
 * register/occupancy trade can be measured (RAYBENCH_CUDA_MINB).
 * __grid_constant__ lets the shared code take &view without a local copy. */
template <int MAXT, int MINB, int MODE>
__global__ void __launch_bounds__(MAXT, MINB) rt_render_kernel(const __grid_constant__ RtSceneView view, float *rgb,
                                                               unsigned long long *counters, unsigned int *next_item,
                                                               const RtCudaGrid g)
{
    /* MODE: RT_MODE_PAIRS (pixel pairs), RT_MODE_EXTRAS (chunk records and
     * the grid's work units: orders and timelines), RT_MODE_SLOT (shadow rays
     * in slot order). Each is an instantiation of its own: compiled into
     * the default kernel, the extras' code cost it 16% on the dragon even
     * when unused (the tuning journal, git show 65ca656:git show 65ca656:docs/gpu.md, "Fifth round"). */
    constexpr bool PAIRS = (MODE & RT_MODE_PAIRS) != 0, EXTRAS = (MODE & RT_MODE_EXTRAS) != 0;
    /* The shadow rays' query, a constant of the instantiation: a runtime
     * choice between the two measured slower than either (git show 65ca656:docs/gpu.md,
     * "Ninth round"). */
    constexpr int SHADOW = (MODE & RT_MODE_SLOT) ? RT_ANY_HIT_SLOT : RT_ANY_HIT;
    __shared__ unsigned long long block_cnt[RT_NCOUNTERS];
    __shared__ unsigned long long chunk_t0[32]; /* per warp: start of its chunk (RtCudaGrid.chunks) */
    __shared__ uint32_t chunk_id[32];
    /* Per lane: its steps before the chunk (persistent schedule, recording
     * only: dynamic shared memory, none otherwise). */
    extern __shared__ uint32_t lane_steps0[];
    const unsigned tid = threadIdx.y * blockDim.x + threadIdx.x;
    const unsigned lane = tid & 31u;
    /* Every thread of the block is alive here; a block of, say, 5x5 threads
     * has a last warp with fewer than 32 lanes, so the mask is not all ones. */
    const unsigned mask = __activemask();
    const unsigned leader = __ffs(mask) - 1;
    /* Grid schedule with an order: blocks past the units have nothing to do
     * (the whole block leaves, before any barrier). */
    if (EXTRAS && !g.persistent && g.units && blockIdx.x >= *g.nunits)
        return;
    if (tid < RT_NCOUNTERS)
        block_cnt[tid] = 0;
    __syncthreads();

    RtCounters cnt;
    cnt.primary_rays = cnt.shadow_rays = cnt.secondary_rays = cnt.node_visits = cnt.prim_tests = 0;
    if (g.persistent) {
        const unsigned nact = __popc(mask);
        const unsigned rank = __popc(mask & ((1u << lane) - 1u));
        for (;;) {
            unsigned base = 0;
            if (lane == leader)
                base = atomicAdd(next_item, nact);
            base = __shfl_sync(mask, base, leader);
            if (base >= g.total_items)
                break;
            uint32_t item = base + rank;
            if (EXTRAS && g.chunk_order)
                item = g.chunk_order[base >> 5] * 32u + rank;
            /* Chunk records: start time and chunk in shared memory, not in
             * registers across the render (one more register costs warps). */
            if (EXTRAS && g.chunks) {
                rt_cuda_chunk_begin(chunk_t0, chunk_id, tid, lane == leader, item >> 5);
                lane_steps0[tid] = (uint32_t)(cnt.node_visits + cnt.prim_tests);
            }
            {
                int px, py;
                if (item < g.total_items && rt_cuda_item_pixel(view, g, item, &px, &py))
                    rt_render_pixel(&view, px, py, SHADOW, rgb, &cnt);
            }
            if (EXTRAS && g.chunks) {
                /* the leader's pixel: the chunk's first (found again, not kept live) */
                int px, py;
                rt_cuda_item_pixel(view, g, chunk_id[tid >> 5] * 32u, &px, &py);
                rt_cuda_chunk_end(g.chunks, chunk_t0, chunk_id, tid, lane == leader, mask,
                                  (uint32_t)(cnt.node_visits + cnt.prim_tests) - lane_steps0[tid], px, py, false);
            }
        }
    } else {
        {
            /* The block's tile: from the order's table (the centre order,
             * the default; cover; the oracle), or the block index. */
            const uint32_t tile = g.units ? g.units[blockIdx.x] : blockIdx.x;
            int px, py;
            const bool valid = rt_cuda_unit_pixel(view, g, tile, PAIRS, tid, &px, &py);
            /* Chunk records by warp of the launch. */
            if (EXTRAS && g.chunks)
                rt_cuda_chunk_begin(chunk_t0, chunk_id, tid, lane == leader,
                                    (blockIdx.x * blockDim.x * blockDim.y + tid) >> 5);
            if (PAIRS)
                rt_cuda_pair_item(view, px, py, valid, tid & 1u, rgb, &cnt);
            else if (valid)
                rt_render_pixel(&view, px, py, SHADOW, rgb, &cnt);
        }
        if (EXTRAS && g.chunks) {
            /* one item per lane: its counters are its chunk's; the leader's
             * pixel found again, not kept live across the render */
            int px, py;
            rt_cuda_unit_pixel(view, g, g.units ? g.units[blockIdx.x] : blockIdx.x, PAIRS, tid, &px, &py);
            rt_cuda_chunk_end(g.chunks, chunk_t0, chunk_id, tid, lane == leader, mask,
                              (uint32_t)(cnt.node_visits + cnt.prim_tests), px, py, PAIRS);
        }
    }

    rt_cuda_flush_counters(cnt, block_cnt, counters, mask, lane, tid);
}

/* RAYBENCH_CUDA_ORDER=cover (grid schedule): the tiles in order of how many
 * BVH leaves' screen rectangles cover them, most first, so that the
 * expensive tiles -- whose warps are the frame's longest chains -- start in
 * the first wave instead of wherever the raster order puts them. One block,
 * one launch before the render, inside the timed region: each leaf's box is
 * projected through the camera (RENDERING-RULES "Camera", inverted) and
 * counted into a 2D difference array over cells of cw x ch tiles (at most
 * RT_COVER_CELLS of them, in shared memory; four atomics a leaf), which two
 * prefix passes turn into counts; a counting sort of the tiles by their
 * cell's count makes the order (RtCudaGrid.units). Boxes that reach behind
 * the film plane are left out (they would cover everything). The order
 * inside a count bucket is the atomics'. */
#define RT_COVER_BUCKETS 64
#define RT_COVER_CELLS 4096 /* difference array entries, (cells_x + 1) * (cells_y + 1) */

static __device__ __forceinline__ uint32_t rt_cover_bucket(uint32_t c)
{
    /* exact below 8, then 8 buckets per octave */
    if (c < 8)
        return c;
    const int oct = 31 - __clz(c);
    const uint32_t b = (uint32_t)(oct - 2) * 8u + ((c >> (oct - 3)) & 7u);
    return b < RT_COVER_BUCKETS ? b : RT_COVER_BUCKETS - 1;
}

__global__ void __launch_bounds__(1024) rt_cover_order_kernel(const __grid_constant__ RtSceneView view,
                                                               const RtCudaGrid g, uint32_t *units, uint32_t *nunits)
{
    __shared__ int diff[RT_COVER_CELLS];
    __shared__ uint32_t hist[RT_COVER_BUCKETS];
    const int tx = g.tiles_x, ty = (int)(g.ntiles / (uint32_t)g.tiles_x);
    /* cells of cw x ch tiles (powers of two), few enough for the array */
    int cw = 1, ch = 1;
    while (((tx + cw - 1) / cw + 1) * ((ty + ch - 1) / ch + 1) > RT_COVER_CELLS) {
        if (cw <= ch)
            cw *= 2;
        else
            ch *= 2;
    }
    const int cx = (tx + cw - 1) / cw, cy = (ty + ch - 1) / ch, dx = cx + 1;
    const int pw = g.bx * cw, ph = g.by * ch; /* cell size in pixels */
    const RtCamera &cam = view.cam;
    for (int i = threadIdx.x; i < dx * (cy + 1); i += blockDim.x)
        diff[i] = 0;
    for (int b = threadIdx.x; b < RT_COVER_BUCKETS; b += blockDim.x)
        hist[b] = 0;
    __syncthreads();
    for (uint32_t ni = threadIdx.x; ni < view.nnodes; ni += blockDim.x) {
        const RtBvhNode n = view.nodes[ni];
        if (!(n.meta & 0xffu))
            continue;
        float i0 = 1e30f, i1 = -1e30f, j0 = 1e30f, j1 = -1e30f;
        bool behind = false;
#pragma unroll
        for (int c = 0; c < 8; c++) {
            const RtVec3 q = rt_sub(rt_v3(c & 1 ? n.hi[0] : n.lo[0], c & 2 ? n.hi[1] : n.lo[1], c & 4 ? n.hi[2] : n.lo[2]),
                                    cam.pos);
            const float z = -rt_dot(q, cam.fwd); /* distance in front of the camera */
            behind |= !(z > 1e-6f);
            const float iz = cam.d / z;
            const float i = 0.5f * (float)cam.width - rt_dot(q, cam.right) * iz - 0.5f;
            const float j = 0.5f * (float)cam.height - rt_dot(q, cam.up) * iz - 0.5f;
            i0 = fminf(i0, i); i1 = fmaxf(i1, i);
            j0 = fminf(j0, j); j1 = fmaxf(j1, j);
        }
        if (behind || i1 < 0.0f || j1 < 0.0f || i0 > (float)(cam.width - 1) || j0 > (float)(cam.height - 1))
            continue;
        const int a0 = (int)fmaxf(i0, 0.0f) / pw, a1 = (int)fminf(i1, (float)(cam.width - 1)) / pw;
        const int b0 = (int)fmaxf(j0, 0.0f) / ph, b1 = (int)fminf(j1, (float)(cam.height - 1)) / ph;
        atomicAdd(&diff[b0 * dx + a0], 1);
        atomicAdd(&diff[b0 * dx + a1 + 1], -1);
        atomicAdd(&diff[(b1 + 1) * dx + a0], -1);
        atomicAdd(&diff[(b1 + 1) * dx + a1 + 1], 1);
    }
    __syncthreads();
    for (int y = threadIdx.x; y < cy; y += blockDim.x) /* rows */
        for (int x = 1; x < cx; x++)
            diff[y * dx + x] += diff[y * dx + x - 1];
    __syncthreads();
    for (int x = threadIdx.x; x < cx; x += blockDim.x) /* columns: now counts */
        for (int y = 1; y < cy; y++)
            diff[y * dx + x] += diff[(y - 1) * dx + x];
    __syncthreads();
#define RT_COVER_KEY(t) rt_cover_bucket((uint32_t)diff[((int)((t) / (uint32_t)tx) / ch) * dx + (int)((t) % (uint32_t)tx) / cw])
    for (uint32_t t = threadIdx.x; t < g.ntiles; t += blockDim.x)
        atomicAdd(&hist[RT_COVER_KEY(t)], 1u);
    __syncthreads();
    if (threadIdx.x == 0) { /* exclusive offsets, most covered first */
        uint32_t sum = 0;
        for (int b = RT_COVER_BUCKETS - 1; b >= 0; b--) {
            const uint32_t c = hist[b];
            hist[b] = sum;
            sum += c;
        }
        *nunits = sum;
    }
    __syncthreads();
    for (uint32_t t = threadIdx.x; t < g.ntiles; t += blockDim.x)
        units[atomicAdd(&hist[RT_COVER_KEY(t)], 1u)] = t;
#undef RT_COVER_KEY
}

typedef void (*RtCudaKernel)(const RtSceneView, float *, unsigned long long *, unsigned int *, const RtCudaGrid);

typedef struct RtCudaVariant {
    int maxt, minb, mode;
    RtCudaKernel kernel;
} RtCudaVariant;

/* The default kernels at every register cap, with shadow rays sorted and in
 * slot order; pixel pairs and the extras (RT_MODE_*) at MINB 1 only. */
#define RT_CUDA_VARIANT(T, B, M) {T, B, M, rt_render_kernel<T, B, M>}
#define RT_CUDA_MODES(T)                                                       \
    RT_CUDA_VARIANT(T, 1, RT_MODE_PAIRS), RT_CUDA_VARIANT(T, 1, RT_MODE_EXTRAS), \
        RT_CUDA_VARIANT(T, 1, RT_MODE_PAIRS | RT_MODE_EXTRAS)
static const RtCudaVariant rt_cuda_variants[] = {
    RT_CUDA_VARIANT(256, 1, 0), RT_CUDA_VARIANT(256, 2, 0), RT_CUDA_VARIANT(256, 3, 0), RT_CUDA_VARIANT(256, 4, 0),
    RT_CUDA_VARIANT(512, 1, 0), RT_CUDA_VARIANT(512, 2, 0), RT_CUDA_VARIANT(1024, 1, 0),
    RT_CUDA_MODES(256), RT_CUDA_MODES(512), RT_CUDA_MODES(1024),
    RT_CUDA_VARIANT(256, 1, RT_MODE_SLOT), RT_CUDA_VARIANT(256, 2, RT_MODE_SLOT), RT_CUDA_VARIANT(256, 3, RT_MODE_SLOT),
    RT_CUDA_VARIANT(256, 4, RT_MODE_SLOT), RT_CUDA_VARIANT(512, 1, RT_MODE_SLOT), RT_CUDA_VARIANT(512, 2, RT_MODE_SLOT),
    RT_CUDA_VARIANT(1024, 1, RT_MODE_SLOT),
};
#undef RT_CUDA_MODES
#undef RT_CUDA_VARIANT

/* The instantiation for a block of `threads` in mode `mode`: the smallest
 * MAXT that holds it (so small blocks keep every register they want) with
 * MINB = minb, or the first MINB there is. */
static const RtCudaVariant *rt_cuda_pick_kernel(int threads, int minb, int mode)
{
    const RtCudaVariant *best = NULL;
    for (size_t i = 0; i < sizeof rt_cuda_variants / sizeof rt_cuda_variants[0]; i++) {
        const RtCudaVariant *v = &rt_cuda_variants[i];
        if (v->maxt < threads || v->mode != mode)
            continue;
        if (!best || v->maxt < best->maxt || (v->maxt == best->maxt && v->minb == minb && best->minb != minb))
            best = v;
    }
    return best;
}

/* One device allocation for everything: each array at a 256-byte aligned
 * offset, so one size is known (for the out-of-memory message) and one free
 * releases it all. */
typedef struct RtCudaPart {
    const void *host;  /* NULL: device-only (image, counters) */
    size_t bytes;
    size_t offset;
} RtCudaPart;

enum { P_PRIMS, P_NODES, P_WIDE, P_VERTS, P_NORMALS, P_SPHERES, P_TRIS, P_MATS, P_LIGHTS, P_IMAGE, P_COUNTERS, P_WORK,
       P_ORDER, P_CHUNKS, P_NUNITS, P_COUNT };

static size_t rt_cuda_layout(RtCudaPart *parts)
{
    size_t off = 0;
    for (int i = 0; i < P_COUNT; i++) {
        parts[i].offset = off;
        off += (parts[i].bytes + 255u) & ~(size_t)255u;
    }
    return off;
}

static void rt_cuda_gpu_name(const char *in, char *out, size_t size)
{
    size_t k = 0;
    for (; in[k] && k + 1 < size; k++) {
        char c = in[k];
        int ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '-' || c == '.';
        out[k] = ok ? c : '_';
    }
    out[k] = '\0';
}

static int rt_cuda_cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : (x > y ? 1 : 0);
}

/* s as a whole decimal integer in lo..hi (into *out when not NULL). */
static int rt_cuda_parse_int(const char *s, int lo, int hi, int *out)
{
    char *end;
    errno = 0;
    const long x = strtol(s, &end, 10);
    if (errno || end == s || *end != '\0' || x < lo || x > hi)
        return 0;
    if (out)
        *out = (int)x;
    return 1;
}

/* The measurement variables (docs/gpu.md, "Environment"), every one checked
 * before the GPU is touched: a value the backend would not use is a one-line
 * error naming the variable, not a silent default (and CI, without a GPU,
 * can test it). Combinations that depend on the block or the device are
 * checked where they are known. */
typedef struct RtCudaEnvVar {
    const char *name;
    const char *words; /* the accepted values, space-separated; NULL: an integer in lo..hi */
    int lo, hi;
    const char *why;   /* appended to the message, or NULL */
} RtCudaEnvVar;

static const RtCudaEnvVar rt_cuda_env_vars[] = {
    {"RAYBENCH_CUDA_SCHED", "grid persistent", 0, 0, NULL},
    {"RAYBENCH_CUDA_TRAVERSAL", "wide ldg shared", 0, 0, NULL},
    {"RAYBENCH_CUDA_ORDER", "tiles scatter oracle cover center", 0, 0, NULL},
    {"RAYBENCH_CUDA_PAIRS", "0 1 auto", 0, 0, NULL},
    {"RAYBENCH_CUDA_ANYHIT", "sorted slot auto", 0, 0, NULL},
    {"RAYBENCH_CUDA_SPEC", "1", 0, 0,
     "only 1 is left: the wide traversal always postpones leaves (git show 65ca656:docs/gpu.md, \"Sixth round\")"},
    {"RAYBENCH_CUDA_RUNS", NULL, 1, 64, NULL},
    {"RAYBENCH_CUDA_WARMUP_MS", NULL, 0, 10000, NULL},
    {"RAYBENCH_CUDA_MINB", NULL, 1, 4, NULL},
    {"RAYBENCH_CUDA_CARVEOUT", NULL, -1, 100, NULL},
};

static int rt_cuda_check_env(RtError *err)
{
    for (size_t i = 0; i < sizeof rt_cuda_env_vars / sizeof rt_cuda_env_vars[0]; i++) {
        const RtCudaEnvVar *v = &rt_cuda_env_vars[i];
        const char *s = getenv(v->name);
        if (!s || !*s)
            continue;
        if (v->words) {
            const size_t n = strlen(s);
            const char *p = v->words;
            int ok = 0;
            while (*p && !ok) {
                const size_t k = strcspn(p, " ");
                ok = k == n && strncmp(p, s, n) == 0;
                p += k + (p[k] == ' ');
            }
            if (!ok)
                return rt_fail(err, "%s=%s: expected one of: %s%s%s", v->name, s, v->words, v->why ? "; " : "",
                               v->why ? v->why : "");
        } else if (!rt_cuda_parse_int(s, v->lo, v->hi, NULL))
            return rt_fail(err, "%s=%s: expected an integer from %d to %d", v->name, s, v->lo, v->hi);
    }
    return 0;
}

/* An integer measurement variable (its range in rt_cuda_env_vars), or def
 * when unset or empty; rt_cuda_check_env has refused anything else. */
static int rt_cuda_env_int(const char *name, int def)
{
    const char *s = getenv(name);
    if (!s || !*s)
        return def;
    for (size_t i = 0; i < sizeof rt_cuda_env_vars / sizeof rt_cuda_env_vars[0]; i++)
        if (strcmp(rt_cuda_env_vars[i].name, name) == 0 && !rt_cuda_env_vars[i].words) {
            rt_cuda_parse_int(s, rt_cuda_env_vars[i].lo, rt_cuda_env_vars[i].hi, &def);
            break;
        }
    return def;
}

/* The n chunk records of a recorded launch, downloaded into a malloc'd
 * array (the caller frees it); NULL after an error message. */
static RtCudaChunk *rt_cuda_download_chunks(const unsigned char *dchunks, uint32_t n, const char *what, RtError *err)
{
    RtCudaChunk *rec = (RtCudaChunk *)malloc((size_t)n * sizeof *rec);
    if (!rec) {
        rt_fail(err, "cuda: out of memory for the %s of %u chunks", what, n);
        return NULL;
    }
    if (cudaMemcpy(rec, dchunks, (size_t)n * sizeof *rec, cudaMemcpyDeviceToHost) != cudaSuccess) {
        free(rec);
        rt_fail(err, "cuda: download of the chunk records for the %s failed", what);
        return NULL;
    }
    return rec;
}

static const unsigned long long *rt_cuda_sort_cost;
static int rt_cuda_cmp_cost(const void *a, const void *b)
{
    const uint32_t i = *(const uint32_t *)a, j = *(const uint32_t *)b;
    const unsigned long long x = rt_cuda_sort_cost[i], y = rt_cuda_sort_cost[j];
    return x > y ? -1 : (x < y ? 1 : (i < j ? -1 : (i > j ? 1 : 0)));
}

/* RAYBENCH_CUDA_ORDER=oracle: the device's chunk times of one launch ->
 * the chunk order of the next ones, longest first (what a perfect cost
 * prediction would give the persistent schedule; a measurement, not a mode). */
static int rt_cuda_oracle_order(const unsigned char *dchunks, unsigned char *dorder, uint32_t n, uint32_t per_unit,
                                RtError *err)
{
    /* Units: chunks (persistent schedule, per_unit 1) or tiles (grid: the
     * warps of block b, which rendered tile b), each costing its slowest
     * chunk. */
    int ok = 0;
    const uint32_t units = n / per_unit;
    RtCudaChunk *rec = rt_cuda_download_chunks(dchunks, n, "oracle order", err);
    unsigned long long *cost = (unsigned long long *)calloc((size_t)units, sizeof *cost);
    uint32_t *order = (uint32_t *)malloc((size_t)units * sizeof *order);
    if (!rec || !cost || !order) {
        if (rec) /* (without rec, the download has said why) */
            rt_fail(err, "cuda: out of memory for the oracle order of %u chunks", n);
    } else {
        for (uint32_t i = 0; i < units; i++)
            order[i] = i;
        for (uint32_t i = 0; i < n; i++) {
            const unsigned long long c = rec[i].t1 - rec[i].t0;
            if (c > cost[i / per_unit])
                cost[i / per_unit] = c;
        }
        rt_cuda_sort_cost = cost;
        qsort(order, units, sizeof *order, rt_cuda_cmp_cost);
        ok = cudaMemcpy(dorder, order, (size_t)units * sizeof *order, cudaMemcpyHostToDevice) == cudaSuccess;
        if (!ok)
            rt_fail(err, "cuda: upload of the oracle order failed");
    }
    free(rec);
    free(cost);
    free(order);
    return ok;
}

/* RAYBENCH_CUDA_TIMELINE=FILE: the chunk records of one more launch after
 * the timed ones, as CSV (docs/gpu.md): which pixels, which multiprocessor,
 * start and end in ns from the launch's first chunk, traversal steps. */
static int rt_cuda_write_timeline(const char *path, const unsigned char *dchunks, uint32_t n, RtError *err)
{
    RtCudaChunk *rec = rt_cuda_download_chunks(dchunks, n, "timeline", err);
    if (!rec)
        return -1;
    unsigned long long start = ~0ull;
    for (uint32_t i = 0; i < n; i++)
        if (rec[i].t1 && rec[i].t0 < start)
            start = rec[i].t0;
    FILE *f = fopen(path, "w");
    if (!f) {
        free(rec);
        return rt_fail(err, "RAYBENCH_CUDA_TIMELINE: cannot write %s: %s", path, strerror(errno));
    }
    fprintf(f, "chunk,x,y,sm,start_ns,end_ns,steps_max,steps_sum,pairs\n");
    for (uint32_t i = 0; i < n; i++) {
        if (!rec[i].t1) /* not recorded: a grid block past the work units */
            continue;
        fprintf(f, "%u,%d,%d,%u,%llu,%llu,%u,%llu,%u\n", i, rec[i].x, rec[i].y, rec[i].sm, rec[i].t0 - start,
                rec[i].t1 - start, rec[i].steps_max, rec[i].steps_sum, rec[i].pairs);
    }
    const int bad = ferror(f) != 0;
    free(rec);
    if (fclose(f) != 0 || bad)
        return rt_fail(err, "RAYBENCH_CUDA_TIMELINE: write error on %s", path);
    return 0;
}

/* RAYBENCH_CUDA_ORDER=center: the grid's tiles by the distance of their
 * centres from the image's centre, nearest first (ties: raster order). A
 * frame's heavy work is mostly on its subject, and a subject is mostly near
 * the middle of the frame, so its tiles start in the first wave instead of
 * wherever the rows put them (arm-reach's slowest warps lie 70% down the
 * image). Depends on the image and tile sizes only, not on the scene. */
typedef struct RtCudaTileKey {
    unsigned long long d2;
    uint32_t tile;
} RtCudaTileKey;

static int rt_cuda_cmp_tile_key(const void *a, const void *b)
{
    const RtCudaTileKey *x = (const RtCudaTileKey *)a, *y = (const RtCudaTileKey *)b;
    if (x->d2 != y->d2)
        return x->d2 < y->d2 ? -1 : 1;
    return x->tile < y->tile ? -1 : (x->tile > y->tile ? 1 : 0);
}

static uint32_t *rt_cuda_center_order(const RtCudaGrid *g, int w, int h, RtError *err)
{
    RtCudaTileKey *k = (RtCudaTileKey *)malloc((size_t)g->ntiles * sizeof *k);
    uint32_t *order = (uint32_t *)malloc((size_t)g->ntiles * sizeof *order);
    if (!k || !order) {
        free(k);
        free(order);
        rt_fail(err, "cuda: out of memory for the centre order of %u tiles", g->ntiles);
        return NULL;
    }
    for (uint32_t t = 0; t < g->ntiles; t++) {
        /* doubled pixel coordinates: tile centre against image centre, exact */
        const long long cx = 2LL * (t % (uint32_t)g->tiles_x) * g->bx + g->bx - w;
        const long long cy = 2LL * (t / (uint32_t)g->tiles_x) * g->by + g->by - h;
        k[t].d2 = (unsigned long long)(cx * cx + cy * cy);
        k[t].tile = t;
    }
    qsort(k, g->ntiles, sizeof *k, rt_cuda_cmp_tile_key);
    for (uint32_t t = 0; t < g->ntiles; t++)
        order[t] = k[t].tile;
    free(k);
    return order;
}

/* Indexed by RT_ORDER_* and RT_TRAV_*: the names RAYBENCH_CUDA_ORDER and
 * RAYBENCH_CUDA_TRAVERSAL take and the record says. */
static const char *const rt_cuda_order_names[] = {"tiles", "scatter", "oracle", "cover", "center"};
static const char *const rt_cuda_trav_names[] = {"shared", "ldg", "wide"};
/* RAYBENCH_CUDA_ANYHIT's and RAYBENCH_CUDA_PAIRS's words but auto (the
 * record's anyhit= and pairs=). */
static const char *const rt_cuda_anyhit_names[] = {"sorted", "slot"};
static const char *const rt_cuda_pairs_names[] = {"0", "1"};

/* The index of variable name's value in names[0..n), or def when unset or
 * empty (rt_cuda_check_env has refused any other word). */
static int rt_cuda_env_word(const char *name, const char *const *names, int n, int def)
{
    const char *s = getenv(name);
    for (int i = 0; s && *s && i < n; i++)
        if (strcmp(s, names[i]) == 0)
            return i;
    return def;
}

static int render_cuda(const RtRenderJob *job, RtRenderOut *out, RtError *err)
{
    /* All locals first: RT_CUDA_CHECK jumps to fail:, and C++ forbids jumping
     * over initializations. */
    const double t_wall0 = rt_now_ms();
    const RtSceneView *hv = &job->view;
    const int w = hv->cam.width, h = hv->cam.height;
    const int dev = job->device;
    int rc = -1, ndev = 0, traversal = 0, order_mode = 0, carveout = -1, warmup_ms = 0, warmups = 0;
    int blocks_per_sm = 0, nblocks = 0, runs = 0, max_runs = 0, pairs = 0, minb = 1, mode = 0, slot = 0;
    double waves = 0.0;
    uint32_t nchunks = 0, *center_order = NULL;
    size_t shmem = 0;
    const char *timeline = NULL;
    int bx = job->block_x > 0 ? job->block_x : (hv->nnodes ? RT_CUDA_DEFAULT_BX : RT_CUDA_DEFAULT_NONE_BX);
    int by = job->block_y > 0 ? job->block_y : (hv->nnodes ? RT_CUDA_DEFAULT_BY : RT_CUDA_DEFAULT_NONE_BY);
    int threads = bx * by;
    const char *sched_env = getenv("RAYBENCH_CUDA_SCHED");
    const int sched_asked = sched_env && *sched_env;
    /* Default schedule by measurement (the tuning journal, git show 65ca656:git show 65ca656:docs/gpu.md, "Fourth round"): grid for
     * the tree, persistent for brute force; large images below. */
    int persistent = sched_asked ? strcmp(sched_env, "grid") != 0 : hv->nnodes == 0;
    int large = 0;
    cudaError_t e = cudaSuccess;
    cudaDeviceProp prop;
    cudaFuncAttributes fa;
    RtCudaKernel kernel = NULL;
    const RtCudaVariant *variant = NULL;
    RtCudaPart parts[P_COUNT];
    RtCudaGrid g;
    RtSceneView dv = *hv;
    unsigned char *arena = NULL;
    size_t arena_bytes = 0, free_b = 0, total_b = 0;
    cudaEvent_t ev0 = NULL, ev1 = NULL;
    double t0 = 0.0, init_ms = 0.0, upload_ms = 0.0, download_ms = 0.0, first_ms = 0.0;
    double times[64];
    float ms = 0.0f;
    unsigned long long hcnt[RT_NCOUNTERS];
    char gpu[128];
    const size_t npix = (size_t)w * (size_t)h;

    memset(&prop, 0, sizeof prop);
    memset(&fa, 0, sizeof fa);
    memset(parts, 0, sizeof parts);
    memset(&g, 0, sizeof g);

    if (rt_cuda_check_env(err))
        return -1;
    traversal = rt_cuda_env_word("RAYBENCH_CUDA_TRAVERSAL", rt_cuda_trav_names,
                                 (int)(sizeof rt_cuda_trav_names / sizeof rt_cuda_trav_names[0]),
                                 RT_CUDA_DEFAULT_TRAVERSAL);
    if (traversal == RT_TRAV_WIDE && !hv->wide)
        traversal = RT_TRAV_LDG; /* brute force, or no wide tree */
    /* No driver, no GPU: one clear line, before anything else is touched. */
    e = cudaGetDeviceCount(&ndev);
    if (e != cudaSuccess)
        return rt_fail(err, "cuda: no usable GPU: cudaGetDeviceCount failed: %s (%s)", cudaGetErrorString(e),
                       cudaGetErrorName(e));
    if (ndev == 0)
        return rt_fail(err, "cuda: no usable GPU: cudaGetDeviceCount found no CUDA device");
    if (dev < 0 || dev >= ndev)
        return rt_fail(err, "cuda: --device %d: this machine has %d CUDA device(s), numbered 0 to %d", dev, ndev,
                       ndev - 1);
    t0 = rt_now_ms();
    RT_CUDA_CHECK(cudaSetDevice(dev));
    RT_CUDA_CHECK(cudaFree(0)); /* creates the context here, so init_ms holds its cost */
    init_ms = rt_now_ms() - t0;
    RT_CUDA_CHECK(cudaGetDeviceProperties(&prop, dev));
    rt_cuda_gpu_name(prop.name, gpu, sizeof gpu);

    /* Large images with the tree, when neither the block nor the schedule
     * was asked for: at least RT_CUDA_LARGE_WAVES times the pixels the grid
     * default keeps resident take the persistent schedule in
     * RT_CUDA_LARGE_BX x RT_CUDA_LARGE_BY blocks at RT_CUDA_LARGE_MINB
     * (record: large=1). */
    if (hv->nnodes && job->block_x <= 0 && !sched_asked) {
        int pb = 0;
        RT_CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(
            &pb, rt_cuda_pick_kernel(threads, RT_CUDA_DEFAULT_MINB, 0)->kernel, threads, 0));
        const double resident = (double)pb * (double)threads * (double)prop.multiProcessorCount;
        if (resident > 0.0 && (double)npix >= RT_CUDA_LARGE_WAVES * resident) {
            large = 1;
            persistent = 1;
            bx = RT_CUDA_LARGE_BX;
            by = RT_CUDA_LARGE_BY;
            threads = bx * by;
        }
    }

    /* The block shape, checked against this kernel's real limits before any
     * allocation or launch: it renders correctly or fails here, loudly. */
    if (bx < 1 || by < 1 || threads > 1024 || threads > prop.maxThreadsPerBlock || bx > prop.maxThreadsDim[0] ||
        by > prop.maxThreadsDim[1]) {
        rt_fail(err, "cuda: block %dx%d (%d threads): %s allows at most %d threads per block, %d x %d", bx, by,
                threads, gpu, prop.maxThreadsPerBlock, prop.maxThreadsDim[0], prop.maxThreadsDim[1]);
        goto fail;
    }
    /* Pixel pairs (rt_cuda_pair_item, a kernel of their own):
     * RAYBENCH_CUDA_PAIRS 0, 1 or auto (the default): on when the grid
     * schedule's blocks of pairs all fit on the GPU at once -- then the second
     * lane per pixel costs no wave, and it shortens the chains the frame waits
     * on (the tuning journal, git show 65ca656:git show 65ca656:docs/gpu.md, "Fifth round"); not when slot order was asked for,
     * which the pairs' kernel does not have. */
    minb = rt_cuda_env_int("RAYBENCH_CUDA_MINB", large ? RT_CUDA_LARGE_MINB : RT_CUDA_DEFAULT_MINB);
    /* RAYBENCH_CUDA_ANYHIT as asked: -1 auto, 0 sorted, 1 slot (the choice
     * is made below, once the kernel's mode is known). */
    slot = rt_cuda_env_word("RAYBENCH_CUDA_ANYHIT", rt_cuda_anyhit_names,
                            (int)(sizeof rt_cuda_anyhit_names / sizeof rt_cuda_anyhit_names[0]), -1);
    /* RAYBENCH_CUDA_SPEC accepts only 1 (rt_cuda_check_env): the leaf vote is
     * compiled in (RT_WIDE_LEAF_VOTE above); the record keeps saying spec=1. */
    {
        const int asked = rt_cuda_env_word("RAYBENCH_CUDA_PAIRS", rt_cuda_pairs_names,
                                           (int)(sizeof rt_cuda_pairs_names / sizeof rt_cuda_pairs_names[0]), -1);
        const int can = !persistent && bx % 2 == 0 && threads % 32 == 0;
        if (asked >= 0) { /* -1: auto, or unset */
            pairs = asked;
            if (pairs && !can) {
                rt_fail(err, "RAYBENCH_CUDA_PAIRS=1: needs the grid schedule and blocks of an even width and a "
                             "multiple of 32 threads (got %dx%d, %s)",
                        bx, by, persistent ? "persistent" : "grid");
                goto fail;
            }
        } else if (can && slot != 1) {
            int pb = 0;
            const unsigned long long pair_tiles =
                (unsigned long long)((w + bx / 2 - 1) / (bx / 2)) * (unsigned long long)((h + by - 1) / by);
            RT_CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&pb, rt_cuda_pick_kernel(threads, minb, RT_MODE_PAIRS)->kernel,
                                                                        threads, 0));
            pairs = pair_tiles <= (unsigned long long)pb * (unsigned long long)prop.multiProcessorCount;
        }
    }
    /* The order; the oracle, cover and timeline need the kernels with the
     * extras, the centre order does not (a table of tiles, like cover's). */
    order_mode = rt_cuda_env_word("RAYBENCH_CUDA_ORDER", rt_cuda_order_names,
                                  (int)(sizeof rt_cuda_order_names / sizeof rt_cuda_order_names[0]),
                                  persistent ? RT_CUDA_DEFAULT_PERSISTENT_ORDER : RT_CUDA_DEFAULT_GRID_ORDER);
    /* scatter: the persistent schedule's; cover: the grid's, with a tree;
     * center: the grid's; the oracle (either schedule) needs whole 32-item
     * chunks. */
    if ((order_mode == RT_ORDER_SCATTER && !persistent) || (order_mode == RT_ORDER_ORACLE && threads % 32 != 0) ||
        (order_mode == RT_ORDER_COVER && (persistent || hv->nnodes == 0)) || (order_mode == RT_ORDER_CENTER && persistent))
        order_mode = RT_ORDER_TILES;
    timeline = getenv("RAYBENCH_CUDA_TIMELINE"); /* empty: off, as unset */
    if (timeline && !*timeline)
        timeline = NULL;
    if (timeline && threads % 32 != 0) {
        rt_fail(err, "RAYBENCH_CUDA_TIMELINE=%s: needs blocks of a multiple of 32 threads (got %dx%d)", timeline, bx, by);
        goto fail;
    }
    mode = (pairs ? RT_MODE_PAIRS : 0) |
           (order_mode == RT_ORDER_ORACLE || order_mode == RT_ORDER_COVER || timeline ? RT_MODE_EXTRAS : 0);
    /* The shadow rays' query (RAYBENCH_CUDA_ANYHIT: sorted, slot, or auto,
     * the default): slot order with the wide traversal -- fewer instructions
     * per node, faster on 65 of the 77 scene and image sizes measured
     * (the tuning journal, git show 65ca656:git show 65ca656:docs/gpu.md, "Eleventh round") -- where the kernel has the choice
     * (not pixel pairs, not the extras: asking for slot there is an error).
     * The binary traversals (ldg, shared; brute force) have one any-hit
     * query: they run the sorted kernel, and the record says so. */
    if (slot < 0)
        slot = mode == 0;
    else if (slot && mode != 0) {
        rt_fail(err, "RAYBENCH_CUDA_ANYHIT=slot: the kernel of %s traces shadow rays sorted only",
                pairs ? "pixel pairs" : (timeline ? "RAYBENCH_CUDA_TIMELINE" : "this RAYBENCH_CUDA_ORDER"));
        goto fail;
    }
    slot = slot && traversal == RT_TRAV_WIDE;
    variant = rt_cuda_pick_kernel(threads, minb, mode | (slot ? RT_MODE_SLOT : 0));
    kernel = variant->kernel;
    RT_CUDA_CHECK(cudaFuncGetAttributes(&fa, kernel));
    if (threads > fa.maxThreadsPerBlock) {
        rt_fail(err,
                "cuda: block %dx%d (%d threads): the kernel uses %d registers per thread, so at most %d threads "
                "fit in a block on %s (%d registers per block)",
                bx, by, threads, fa.numRegs, fa.maxThreadsPerBlock, gpu, prop.regsPerBlock);
        goto fail;
    }
    /* Shared memory / L1 split (percent of the most shared memory; 0 = the
     * largest L1). Unset: the driver's choice. */
    carveout = rt_cuda_env_int("RAYBENCH_CUDA_CARVEOUT", -1);
    if (carveout >= 0)
        RT_CUDA_CHECK(cudaFuncSetAttribute(kernel, cudaFuncAttributePreferredSharedMemoryCarveout, carveout));
    RT_CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&blocks_per_sm, kernel, threads, 0));
    if (blocks_per_sm < 1) {
        rt_fail(err, "cuda: block %dx%d (%d threads): no such block fits on a multiprocessor of %s (%d registers, "
                     "%zu bytes of local memory per thread)",
                bx, by, threads, gpu, fa.numRegs, (size_t)fa.localSizeBytes);
        goto fail;
    }
    /* For the record: the image's pixels over the pixels this kernel keeps
     * in flight (a block covers half its threads' pixels with pairs). */
    waves = (double)npix / ((double)blocks_per_sm * (double)(pairs ? threads / 2 : threads) *
                            (double)prop.multiProcessorCount);

    g.pairs = pairs;
    g.bx = pairs ? bx / 2 : bx; /* the pixel tile of a block (whole unit) */
    g.by = by;
    g.tiles_x = (w + g.bx - 1) / g.bx;
    g.tile_items = (uint32_t)(g.bx * g.by);
    {
        unsigned long long tiles = (unsigned long long)g.tiles_x * (unsigned long long)((h + by - 1) / by);
        if (tiles * (unsigned long long)threads > 0xffffffffull - 1024ull) {
            rt_fail(err, "cuda: a %dx%d image in %dx%d blocks has more than 2^32 work items", w, h, bx, by);
            goto fail;
        }
        g.total_items = (uint32_t)(tiles * (unsigned long long)g.tile_items);
        g.persistent = persistent;
        g.ntiles = (uint32_t)tiles;
        if (order_mode == RT_ORDER_SCATTER)
            while (g.tile_mask < g.ntiles - 1)
                g.tile_mask = (g.tile_mask << 1) | 1u;
        /* Persistent: exactly the blocks that are resident at once, never more
         * than there are tiles. */
        nblocks = persistent ? blocks_per_sm * prop.multiProcessorCount : (int)tiles;
        if (persistent && (unsigned long long)nblocks > tiles)
            nblocks = (int)tiles;
    }

    /* One allocation: the arrays exactly as the host holds them. */
    parts[P_PRIMS].host = hv->prims;         parts[P_PRIMS].bytes = (size_t)hv->nprims * sizeof(RtPrim);
    parts[P_NODES].host = hv->nodes;         parts[P_NODES].bytes = (size_t)hv->nnodes * sizeof(RtBvhNode);
    parts[P_WIDE].host = hv->wide;           parts[P_WIDE].bytes = hv->wide ? (size_t)hv->nwide * sizeof(RtBvh4Node) : 0;
    parts[P_VERTS].host = hv->vertices;      parts[P_VERTS].bytes = (size_t)job->scene->nvertices * sizeof(RtVec3);
    parts[P_NORMALS].host = hv->normals;     parts[P_NORMALS].bytes = (size_t)job->scene->nnormals * sizeof(RtVec3);
    parts[P_SPHERES].host = hv->spheres;     parts[P_SPHERES].bytes = (size_t)hv->nspheres * sizeof(RtSphere);
    parts[P_TRIS].host = hv->triangles;      parts[P_TRIS].bytes = (size_t)hv->ntriangles * sizeof(RtTriangle);
    parts[P_MATS].host = hv->materials;      parts[P_MATS].bytes = (size_t)hv->nmaterials * sizeof(RtMaterial);
    parts[P_LIGHTS].host = hv->lights;       parts[P_LIGHTS].bytes = (size_t)hv->nlights * sizeof(RtLight);
    parts[P_IMAGE].bytes = npix * 3 * sizeof(float);
    parts[P_COUNTERS].bytes = RT_NCOUNTERS * sizeof(unsigned long long);
    parts[P_WORK].bytes = sizeof(unsigned int);
    /* Chunk records: the persistent schedule's 32-item chunks, or the grid's warps. */
    nchunks = persistent ? g.total_items / 32u : (uint32_t)nblocks * (uint32_t)(threads / 32);
    parts[P_ORDER].bytes = order_mode == RT_ORDER_ORACLE || order_mode == RT_ORDER_COVER || order_mode == RT_ORDER_CENTER
                               ? (size_t)(persistent ? nchunks : (uint32_t)nblocks) * sizeof(uint32_t) : 0;
    parts[P_NUNITS].bytes = sizeof(uint32_t);
    if (order_mode == RT_ORDER_CENTER) {
        /* A static order (image and tile sizes only, like the launch grid):
         * made and uploaded with the scene, outside the timed launches. */
        center_order = rt_cuda_center_order(&g, w, h, err);
        if (!center_order)
            goto fail;
        parts[P_ORDER].host = center_order;
        parts[P_NUNITS].host = &g.ntiles;
    }
    parts[P_CHUNKS].bytes = order_mode == RT_ORDER_ORACLE || timeline ? (size_t)nchunks * sizeof(RtCudaChunk) : 0;
    arena_bytes = rt_cuda_layout(parts);
    e = cudaMalloc((void **)&arena, arena_bytes);
    if (e != cudaSuccess) {
        if (e == cudaErrorMemoryAllocation) {
            cudaGetLastError(); /* clear it: an allocation failure is not sticky */
            cudaMemGetInfo(&free_b, &total_b);
            rt_fail(err, "cuda: out of device memory: the scene, BVH and %dx%d image need %zu bytes (%.1f MiB) on "
                         "device %d (%s), which has %.1f MiB free of %.1f MiB",
                    w, h, arena_bytes, (double)arena_bytes / 1048576.0, dev, gpu, (double)free_b / 1048576.0,
                    (double)total_b / 1048576.0);
        } else {
            rt_cuda_fail(err, e, "cudaMalloc(arena)", __FILE__, __LINE__);
        }
        arena = NULL;
        goto fail;
    }
    t0 = rt_now_ms();
    for (int i = 0; i < P_COUNT; i++)
        if (parts[i].host && parts[i].bytes)
            RT_CUDA_CHECK(cudaMemcpy(arena + parts[i].offset, parts[i].host, parts[i].bytes, cudaMemcpyHostToDevice));
    upload_ms = rt_now_ms() - t0;
    /* The device copy of the view: same constants, device pointers. */
    dv.prims = (const RtPrim *)(arena + parts[P_PRIMS].offset);
    dv.nodes = hv->nnodes ? (const RtBvhNode *)(arena + parts[P_NODES].offset) : NULL;
    dv.wide = hv->wide ? (const RtBvh4Node *)(arena + parts[P_WIDE].offset) : NULL;
    dv.vertices = (const RtVec3 *)(arena + parts[P_VERTS].offset);
    dv.normals = (const RtVec3 *)(arena + parts[P_NORMALS].offset);
    dv.spheres = (const RtSphere *)(arena + parts[P_SPHERES].offset);
    dv.triangles = (const RtTriangle *)(arena + parts[P_TRIS].offset);
    dv.materials = (const RtMaterial *)(arena + parts[P_MATS].offset);
    dv.lights = (const RtLight *)(arena + parts[P_LIGHTS].offset);
    /* Poison the device image (all bytes 0xff: NaN), so a pixel the kernel
     * never writes cannot pass as black in --verify or the tests. */
    RT_CUDA_CHECK(cudaMemset(arena + parts[P_IMAGE].offset, 0xff, parts[P_IMAGE].bytes));

    RT_CUDA_CHECK(cudaMemcpyToSymbol(rt_cuda_traversal, &traversal, sizeof traversal));
    RT_CUDA_CHECK(cudaEventCreate(&ev0));
    RT_CUDA_CHECK(cudaEventCreate(&ev1));
    max_runs = rt_cuda_env_int("RAYBENCH_CUDA_RUNS", RT_CUDA_DEFAULT_RUNS);
    warmup_ms = rt_cuda_env_int("RAYBENCH_CUDA_WARMUP_MS", RT_CUDA_DEFAULT_WARMUP_MS);
    /* Warm-up launches (module load, caches, and the GPU's clocks: an idle
     * H100 sits at a low SM clock and needs some milliseconds of work to boost)
     * are timed but kept out of render_ms: first_ms is the cold first launch.
     * They repeat until warmup_ms of host time has passed (at least one).
     * Then up to max_runs timed launches, each from zeroed counters; the
     * image and counters of the last one are kept. */
    if (parts[P_CHUNKS].bytes)
        RT_CUDA_CHECK(cudaMemset(arena + parts[P_CHUNKS].offset, 0, parts[P_CHUNKS].bytes));
    if (order_mode == RT_ORDER_ORACLE)
        g.chunks = (RtCudaChunk *)(arena + parts[P_CHUNKS].offset);
    if (order_mode == RT_ORDER_COVER || order_mode == RT_ORDER_CENTER) {
        g.units = (const uint32_t *)(arena + parts[P_ORDER].offset);
        g.nunits = (const uint32_t *)(arena + parts[P_NUNITS].offset);
    }

    /* The per-lane step snapshots of a recorded persistent launch. */
    shmem = persistent && parts[P_CHUNKS].bytes ? (size_t)threads * sizeof(uint32_t) : 0;
    t0 = rt_now_ms();
    for (int run = 0;; run++) {
        const int warm = runs == 0 && (run == 0 || rt_now_ms() - t0 < (double)warmup_ms);
        /* Counters and the work counter that follows them, in one memset. */
        RT_CUDA_CHECK(cudaMemsetAsync(arena + parts[P_COUNTERS].offset, 0,
                                      parts[P_WORK].offset + parts[P_WORK].bytes - parts[P_COUNTERS].offset));
        RT_CUDA_CHECK(cudaEventRecord(ev0));
        if (order_mode == RT_ORDER_COVER) {
            /* Inside the timed region: the order is part of the frame's cost. */
            rt_cover_order_kernel<<<1, 1024>>>(dv, g, (uint32_t *)(arena + parts[P_ORDER].offset),
                                               (uint32_t *)(arena + parts[P_NUNITS].offset));
            RT_CUDA_CHECK_LAUNCH("rt_cover_order_kernel");
        }
        kernel<<<nblocks, dim3((unsigned)bx, (unsigned)by), shmem>>>(
            dv, (float *)(arena + parts[P_IMAGE].offset), (unsigned long long *)(arena + parts[P_COUNTERS].offset),
            (unsigned int *)(arena + parts[P_WORK].offset), g);
        RT_CUDA_CHECK_LAUNCH("rt_render_kernel");
        RT_CUDA_CHECK(cudaEventRecord(ev1));
        RT_CUDA_CHECK(cudaEventSynchronize(ev1));
        RT_CUDA_CHECK(cudaEventElapsedTime(&ms, ev0, ev1));
        if (run == 0 && order_mode == RT_ORDER_ORACLE) {
            /* Oracle order: chunks by the first launch's times, longest first. */
            if (!rt_cuda_oracle_order(arena + parts[P_CHUNKS].offset, arena + parts[P_ORDER].offset, nchunks,
                                      persistent ? 1u : (uint32_t)threads / 32u, err))
                goto fail;
            if (persistent) {
                g.chunk_order = (const uint32_t *)(arena + parts[P_ORDER].offset);
            } else {
                const uint32_t n = (uint32_t)nblocks;
                RT_CUDA_CHECK(cudaMemcpy(arena + parts[P_NUNITS].offset, &n, sizeof n, cudaMemcpyHostToDevice));
                g.units = (const uint32_t *)(arena + parts[P_ORDER].offset);
                g.nunits = (const uint32_t *)(arena + parts[P_NUNITS].offset);
            }
            g.chunks = NULL;
        }
        if (run == 0) {
            first_ms = ms;
            if (job->progress)
                job->progress(job->progress_ctx, 1, (uint64_t)max_runs + 1);
        }
        if (warm) {
            warmups++;
            continue;
        }
        times[runs++] = ms;
        if (runs >= max_runs || (double)ms * (double)(runs + 1) > RT_CUDA_TIME_BUDGET_MS)
            break;
    }
    if (timeline) {
        /* One more launch, recorded (not timed into render_ms); its image is
         * the same as the timed ones'. */
        RT_CUDA_CHECK(cudaMemsetAsync(arena + parts[P_COUNTERS].offset, 0,
                                      parts[P_WORK].offset + parts[P_WORK].bytes - parts[P_COUNTERS].offset));
        RT_CUDA_CHECK(cudaMemset(arena + parts[P_CHUNKS].offset, 0, parts[P_CHUNKS].bytes));
        g.chunks = (RtCudaChunk *)(arena + parts[P_CHUNKS].offset);
        kernel<<<nblocks, dim3((unsigned)bx, (unsigned)by), shmem>>>(
            dv, (float *)(arena + parts[P_IMAGE].offset), (unsigned long long *)(arena + parts[P_COUNTERS].offset),
            (unsigned int *)(arena + parts[P_WORK].offset), g);
        RT_CUDA_CHECK_LAUNCH("rt_render_kernel");
        RT_CUDA_CHECK(cudaDeviceSynchronize());
        if (rt_cuda_write_timeline(timeline, arena + parts[P_CHUNKS].offset, nchunks, err))
            goto fail;
    }
    if (job->progress)
        job->progress(job->progress_ctx, (uint64_t)max_runs + 1, (uint64_t)max_runs + 1);

    t0 = rt_now_ms();
    RT_CUDA_CHECK(cudaMemcpy(out->rgb, arena + parts[P_IMAGE].offset, parts[P_IMAGE].bytes, cudaMemcpyDeviceToHost));
    download_ms = rt_now_ms() - t0;
    RT_CUDA_CHECK(cudaMemcpy(hcnt, arena + parts[P_COUNTERS].offset, sizeof hcnt, cudaMemcpyDeviceToHost));

    qsort(times, (size_t)runs, sizeof times[0], rt_cuda_cmp_double);
    out->render_ms = runs % 2 ? times[runs / 2] : 0.5 * (times[runs / 2 - 1] + times[runs / 2]);
    out->render_ms_min = out->render_ms;
    out->counters.primary_rays = hcnt[0];
    out->counters.shadow_rays = hcnt[1];
    out->counters.secondary_rays = hcnt[2];
    out->counters.node_visits = hcnt[3];
    out->counters.prim_tests = hcnt[4];
    out->threads_used = nblocks * threads;
    out->ranks_used = 1;
    out->is_root = 1;
    rt_cores_note(out->cores, sizeof out->cores, rt_current_cpu());
    rc = 0;
fail:
    if (ev0)
        cudaEventDestroy(ev0);
    if (ev1)
        cudaEventDestroy(ev1);
    if (arena)
        cudaFree(arena);
    free(center_order);
    if (rc == 0) {
        snprintf(out->extra, sizeof out->extra,
                 " block=%dx%d large=%d pairs=%d sched=%s order=%s carveout=%d traversal=%s spec=1 anyhit=%s "
                 "waves=%.2f kernel_runs=%d kernel_min_ms=%.4f warmup_launches=%d first_ms=%.4f init_ms=%.3f upload_ms=%.3f "
                 "download_ms=%.3f wall_ms=%.3f regs=%d local_bytes=%zu bounds=%dx%d blocks_per_sm=%d grid=%d gpu=%s",
                 bx, by, large, pairs, persistent ? "persistent" : "grid", rt_cuda_order_names[order_mode], carveout,
                 rt_cuda_trav_names[traversal], rt_cuda_anyhit_names[slot], waves, runs, times[0], warmups, first_ms, init_ms, upload_ms,
                 download_ms, rt_now_ms() - t_wall0, fa.numRegs, (size_t)fa.localSizeBytes, variant->maxt, variant->minb,
                 blocks_per_sm, nblocks,
                 gpu);
    }
    return rc;
}

extern "C" {
extern const RtBackend rt_backend_cuda;
const RtBackend rt_backend_cuda = {"cuda", NULL, NULL, render_cuda, NULL, NULL};
}
