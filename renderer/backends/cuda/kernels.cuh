/* kernels.cuh - the CUDA backend's device code, included once by cuda.cu:
 * one thread per pixel (or two, with pixel pairs), each running the shared
 * iterative Whitted code (rt_render_pixel -> rt_trace_path -> rt_cuda_trace:
 * core/rt_path_tmpl.h instantiated here, compiled by nvcc: one
 * implementation for CPU and GPU).
 *
 * In both schedules (schedule.h) the block shape BXxBY is the pixel tile a
 * block covers, so a warp covers a 32-pixel piece of a tile (8x4 pixels for
 * 8x8 blocks, a row of 32 for 32xN): that is what makes the shape matter for
 * ray coherence. */

/* The wide traversal's leaf vote (RT_WIDE_LEAF_VOTE, rt_traverse.h): a lane
 * that has put a leaf aside goes on through inner nodes until every active
 * lane of its warp has one, so the warp tests its leaves together
 * (Aila and Laine, HPG 2009, "speculative traversal"). nvcc's host pass has
 * no warp: the CPU's vote, a leaf at once. */
#if defined(__CUDA_ARCH__)
#define RT_WIDE_LEAF_VOTE(has_leaf, any) __all_sync(__activemask(), (has_leaf))
#else
#define RT_WIDE_LEAF_VOTE(has_leaf, any) (has_leaf)
#endif

#include "core/rt_traverse.h"

/* The GPU's ray query: the 4-wide tree that rt_accel_build collapses from
 * the binary one, when there is one; else the binary traversal (brute force,
 * and trees past the wide tree's 2^28 primitives). */
static inline RT_HD int rt_cuda_trace(const RtSceneView *s, RtVec3 o, RtVec3 d, float tmax, int any, RtHit *hit,
                                      RtCounters *cnt)
{
    if (s->wide)
        return rt_trace_ray_wide(s, o, d, tmax, any, hit, cnt);
    return rt_trace_ray(s, o, d, tmax, any, hit, cnt);
}

extern "C" {
#include "rt.h"
#include "core/rt_quantize.h"
#include "core/rt_shade.h"
#include "schedule.h"

/* The shading loop the kernels run (rt_render_pixel), through rt_cuda_trace */
#define RT_PATH_TRACE(s, o, d, tmax, any, hit, cnt, light) rt_cuda_trace(s, o, d, tmax, any, hit, cnt)
#define RT_PATH_NAME(f) f
#define RT_PATH_FN static inline RT_HD
#include "core/rt_path_tmpl.h"
}

enum { RT_NCOUNTERS = 5 }; /* fields of RtCounters, all uint64_t, in order */

/* Persistent schedule: work item -> pixel. Items are numbered tile by tile
 * through the launch's share of tile rows, row-major inside a tile. Returns
 * 0 for the overhang of an edge tile. */
static __device__ __forceinline__ int rt_cuda_item_pixel(const RtSceneView &view, const RtCudaGrid &g,
                                                         uint32_t item, int *px, int *py)
{
    const uint32_t nth = item / g.tile_items;
    const uint32_t local = item - nth * g.tile_items;
    const uint32_t tile = rt_cuda_share_tile(&g, nth);
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

/* Pixel pairs (grid schedule, schedule.c): two lanes per pixel,
 * so that a pixel's shadow rays leave its chain of closest-hit rays. The
 * even lane runs the pending-ray stack of rt_trace_path (closest hits, the
 * ambient term, the children); at each hit it hands the surface to the odd
 * lane, which traces that hit's shadow rays (rt_light_sample, one light per
 * iteration) while the even lane already traces the next closest hit. Both
 * lanes go through one rt_cuda_trace call per iteration (any = the lane's
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
    if (valid && !odd)
        sp = rt_path_begin(s, rt_camera_ray(&s->cam, px, py), stack);
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
                r = rt_path_pop(s, stack, &sp, cnt);
                has = true;
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
        const int hit = rt_cuda_trace(s, r.o, r.d, dist, (int)odd, &h, cnt);
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

/* The pixel's 8-bit value, from the floats this thread has just written,
 * by the rule the CPU backends' images get (rt_quantize): the image leaves
 * the GPU a quarter of the float image's size. */
static __device__ __forceinline__ void rt_cuda_store8(const RtSceneView &view, const float *rgb, uint8_t *rgb8, int px,
                                                      int py)
{
    const size_t i = 3 * ((size_t)py * (size_t)view.cam.width + (size_t)px);
    rgb8[i] = rt_quantize(rgb[i]);
    rgb8[i + 1] = rt_quantize(rgb[i + 1]);
    rgb8[i + 2] = rt_quantize(rgb[i + 2]);
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

/* Kernel modes (rt_render_kernel's MODE), each an instantiation of its own:
 * RT_MODE_PAIRS, two lanes per pixel; RT_MODE_SLOT, shadow rays as
 * RT_ANY_HIT_SLOT queries (rt_traverse.h) instead of RT_ANY_HIT. A runtime
 * switch between the two queries is slower than either (docs/gpu.md). */
enum { RT_MODE_PAIRS = 1, RT_MODE_SLOT = 2 };

/* MAXT is the largest block the instantiation is compiled for and MINB the
 * blocks per multiprocessor it must allow: together they cap the registers per
 * thread at 65536 / (MAXT * MINB), so that a 1024-thread block cannot be
 * refused at launch for lack of registers -- the failure the report's 32x32
 * blocks hit without noticing. __grid_constant__ lets the shared code take
 * &view without a local copy. */
template <int MAXT, int MINB, int MODE>
__global__ void __launch_bounds__(MAXT, MINB) rt_render_kernel(const __grid_constant__ RtSceneView view, float *rgb,
                                                               uint8_t *rgb8, unsigned long long *counters,
                                                               unsigned int *next_item, const RtCudaGrid g)
{
    constexpr bool PAIRS = (MODE & RT_MODE_PAIRS) != 0;
    constexpr int SHADOW = (MODE & RT_MODE_SLOT) ? RT_ANY_HIT_SLOT : RT_ANY_HIT;
    __shared__ unsigned long long block_cnt[RT_NCOUNTERS];
    const unsigned tid = threadIdx.y * blockDim.x + threadIdx.x;
    const unsigned lane = tid & 31u;
    /* Every thread of the block is alive here; a block of, say, 5x5 threads
     * has a last warp with fewer than 32 lanes, so the mask is not all ones. */
    const unsigned mask = __activemask();
    const unsigned leader = __ffs(mask) - 1;
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
            const uint32_t item = base + rank;
            int px, py;
            if (item < g.total_items && rt_cuda_item_pixel(view, g, item, &px, &py)) {
                rt_render_pixel(&view, px, py, SHADOW, rgb, &cnt);
                rt_cuda_store8(view, rgb, rgb8, px, py);
            }
        }
    } else {
        const uint32_t tile = g.units ? g.units[blockIdx.x] : rt_cuda_share_tile(&g, blockIdx.x);
        int px, py;
        const bool valid = rt_cuda_unit_pixel(view, g, tile, PAIRS, tid, &px, &py);
        if (PAIRS)
            rt_cuda_pair_item(view, px, py, valid, tid & 1u, rgb, &cnt);
        else if (valid)
            rt_render_pixel(&view, px, py, SHADOW, rgb, &cnt);
        if (valid && !(PAIRS && (tid & 1u)))
            rt_cuda_store8(view, rgb, rgb8, px, py);
    }
    rt_cuda_flush_counters(cnt, block_cnt, counters, mask, lane, tid);
}

typedef void (*RtCudaKernel)(const RtSceneView, float *, uint8_t *, unsigned long long *, unsigned int *,
                             const RtCudaGrid);

typedef struct RtCudaVariant {
    int maxt, minb, mode;
    RtCudaKernel kernel;
} RtCudaVariant;

/* Every block size (up to 256, 512 and 1024 threads) in each mode at one
 * block per multiprocessor; and the large-image schedule's register cap
 * (schedule.c). */
#define RT_CUDA_VARIANT(T, B, M) {T, B, M, rt_render_kernel<T, B, M>}
#define RT_CUDA_MODES(T) RT_CUDA_VARIANT(T, 1, 0), RT_CUDA_VARIANT(T, 1, RT_MODE_SLOT), RT_CUDA_VARIANT(T, 1, RT_MODE_PAIRS)
static const RtCudaVariant rt_cuda_variants[] = {
    RT_CUDA_MODES(256), RT_CUDA_MODES(512), RT_CUDA_MODES(1024),
    RT_CUDA_VARIANT(256, 3, 0), RT_CUDA_VARIANT(256, 3, RT_MODE_SLOT),
};
#undef RT_CUDA_MODES
#undef RT_CUDA_VARIANT

/* The instantiation for a block of `threads` in mode `mode`: the smallest
 * MAXT that holds it (so small blocks keep every register they want), at
 * MINB = minb where there is one, else at 1. */
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
