/* cuda.cu - the CUDA backend's host flow, one step per function, every CUDA
 * call checked (cuda_check.h):
 *   cuda_open    device and context;
 *   cuda_plan    block, schedule and kernel (the choices are schedule.c's),
 *                checked against the kernel's real limits;
 *   cuda_upload  one device allocation holding the flat scene arrays, the
 *                BVH as the host built it, the images and the counters;
 *   sessions     frames: each a kernel over a share of the image's tile rows
 *                that also quantises its pixels to 8 bits, then the copy of
 *                those bytes to the host, pipelined with the next frame's
 *                kernel (cuda_session.h). The CUDA backend is one session
 *                whose share is the whole image; mpi-cuda runs one per rank.
 * The device code is kernels.cuh. docs/gpu.md describes the design. */
#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cuda_runtime.h>

#include "kernels.cuh"
#include "bvh_gpu.h"
#include "cuda_check.h"
#include "cuda_session.h"
extern "C" {
#include "backends/backends.h" /* RT_OMP_TILE */
}

/* One device allocation for everything: each array at a 256-byte aligned
 * offset, so one size is known (for the out-of-memory message) and one free
 * releases it all. */
typedef struct RtCudaPart {
    const void *host; /* NULL: device-only (image, counters) */
    size_t bytes;
    size_t offset;
} RtCudaPart;

/* A slot of what a frame writes -- the float image (P_IMAGE), its 8-bit
 * form (P_IMAGE8), the ray counters and the work counter (P_COUNTERS, one
 * RT_CUDA_CSLOT each) -- per frame in flight (CudaRun.slots): one frame's
 * kernel runs while another's kernel ends or its bytes are copied down. */
#define PART_INDEX(T, name) P_##name,
enum { P_PRIMS, P_NODES, P_WIDE, RT_SCENE_ARRAYS(PART_INDEX) P_IMAGE, P_IMAGE8, P_COUNTERS, P_ORDER, P_COUNT };
#undef PART_INDEX
enum { RT_CUDA_CSLOT = 64, RT_CUDA_WORK = 48 }; /* a slot's counters: the ray counters, the work counter at 48 */

/* Everything one render acquires (cuda_release frees it) and measures. */
typedef struct CudaRun {
    const RtRenderJob *job;
    int w, h;
    size_t npix;
    cudaDeviceProp prop;
    char gpu[128];
    char gpu_at[160];          /* gpu@PCI bus id */
    RtCudaPlan plan;
    const RtCudaVariant *variant;
    cudaFuncAttributes fa;
    int blocks_per_sm, nblocks;
    double waves;
    RtCudaGrid g;
    RtSceneView dv;            /* the view with device pointers */
    RtCudaPart parts[P_COUNT];
    unsigned char *arena;
    size_t arena_bytes;
    uint32_t *center;          /* host copy of the centre order */
    RtBvh4Node *slot_wide;     /* host copy of the wide tree in slot order */
    int slots;                 /* frames in flight (rt_cuda_frames_in_flight) */
    double init_ms, upload_ms;
    RtCudaTree *tree;          /* the tree the GPU built on this device, read in place; NULL: the host's */
} CudaRun;

static void cuda_gpu_name(const char *in, char *out, size_t size)
{
    size_t k = 0;
    for (; in[k] && k + 1 < size; k++) {
        const char c = in[k];
        const int ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '-' || c == '.';
        out[k] = ok ? c : '_';
    }
    out[k] = '\0';
}

/* The CUDA context takes long to create next to a small scene's render
 * (the record's init_ms: docs/gpu.md); created on a thread of its own while
 * main() parses or maps the scene, it is ready or nearly so when the render
 * starts. */
static pthread_t g_warm;
static int g_warm_started;

/* (device << 1) | wrap */
static void *cuda_warm_main(void *arg)
{
    int device = (int)((intptr_t)arg >> 1), n = 0;
    if (((intptr_t)arg & 1) && cudaGetDeviceCount(&n) == cudaSuccess && n > 0)
        device %= n;
    if (cudaSetDevice(device) == cudaSuccess)
        cudaFree(0); /* (a failure is cuda_open's to report) */
    return NULL;
}

void rt_cuda_prewarm_device(int device, int wrap)
{
    g_warm_started =
        pthread_create(&g_warm, NULL, cuda_warm_main, (void *)(((intptr_t)device << 1) | (wrap ? 1 : 0))) == 0;
}

static void cuda_prewarm(int device) { rt_cuda_prewarm_device(device, 0); }

void rt_cuda_prewarm_join(void)
{
    if (g_warm_started) {
        pthread_join(g_warm, NULL);
        g_warm_started = 0;
    }
}

int rt_cuda_device_bus(int device, char *bus, size_t size, RtError *err)
{
    cudaError_t e = cudaDeviceGetPCIBusId(bus, (int)size, device);
    if (e != cudaSuccess)
        return rt_cuda_fail(err, e, "cudaDeviceGetPCIBusId", __FILE__, __LINE__);
    return 0;
}

int rt_cuda_device_count(int *n, RtError *err)
{
    *n = 0;
    cudaError_t e = cudaGetDeviceCount(n);
    if (e != cudaSuccess)
        return rt_fail(err, "cuda: no usable GPU: cudaGetDeviceCount failed: %s (%s)", cudaGetErrorString(e),
                       cudaGetErrorName(e));
    if (*n == 0)
        return rt_fail(err, "cuda: no usable GPU: cudaGetDeviceCount found no CUDA device");
    return 0;
}

/* The device, its context (init_ms: how long the render still waited for
 * it) and its properties. No driver, no GPU: one clear line before
 * anything else. */
int rt_cuda_device_open(int dev, double *wait_ms, RtError *err)
{
    const double t_wait = rt_now_ms();
    rt_cuda_prewarm_join();
    int ndev = 0;
    if (rt_cuda_device_count(&ndev, err))
        return -1;
    if (dev < 0 || dev >= ndev)
        return rt_fail(err, "cuda: --device %d: this machine has %d CUDA device(s), numbered 0 to %d", dev, ndev,
                       ndev - 1);
    RT_CUDA_CHECK(cudaSetDevice(dev));
    RT_CUDA_CHECK(cudaFree(0));
    *wait_ms = rt_now_ms() - t_wait; /* what is left of the context's creation */
    return 0;
fail:
    return -1;
}

static int cuda_open(CudaRun *c, RtError *err)
{
    const int dev = c->job->device;
    if (rt_cuda_device_open(dev, &c->init_ms, err))
        return -1;
    RT_CUDA_CHECK(cudaGetDeviceProperties(&c->prop, dev));
    cuda_gpu_name(c->prop.name, c->gpu, sizeof c->gpu);
    {
        char bus[32] = "unknown";
        RtError ignored;
        if (rt_cuda_device_bus(dev, bus, sizeof bus, &ignored) != 0)
            cudaGetLastError();
        snprintf(c->gpu_at, sizeof c->gpu_at, "%s@%s", c->gpu, bus);
    }
    return 0;
fail:
    return -1;
}

/* The schedule's automatic parts: the large-image defaults and pixel pairs
 * (schedule.c), each weighed with its kernel's occupancy on this GPU. */
static int cuda_plan_auto(CudaRun *c, int has_tree, RtError *err)
{
    RtCudaPlan *p = &c->plan;
    const int nsm = c->prop.multiProcessorCount;
    int pb = 0;
    if (has_tree && c->job->block_x <= 0) {
        RT_CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(
            &pb, rt_cuda_pick_kernel(p->threads, p->minb, 0)->kernel, p->threads, 0));
        rt_cuda_plan_large(p, (double)c->npix, (double)pb * (double)p->threads * (double)nsm);
    }
    if (rt_cuda_pairs_possible(p)) {
        RT_CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(
            &pb, rt_cuda_pick_kernel(p->threads, p->minb, RT_MODE_PAIRS)->kernel, p->threads, 0));
        p->pairs = rt_cuda_pairs_fit(p, c->w, c->h, pb, nsm);
    }
    /* Slot order for the shadow rays where the kernel has the choice: the
     * 4-wide tree, one lane per pixel. */
    p->slot = !p->pairs && (c->job->view.wide != NULL || c->tree != NULL);
    return 0;
fail:
    return -1;
}

/* Block, schedule and kernel; the block checked against the GPU's and the
 * kernel's real limits before any allocation: it renders or fails here. */
static int cuda_plan(CudaRun *c, RtError *err)
{
    RtCudaPlan *p = &c->plan;
    const int has_tree = c->job->view.nnodes != 0;
    const cudaDeviceProp *prop = &c->prop;
    rt_cuda_plan_start(p, has_tree, c->job->block_x, c->job->block_y);
    if (p->threads > prop->maxThreadsPerBlock || p->bx > prop->maxThreadsDim[0] || p->by > prop->maxThreadsDim[1])
        return rt_fail(err, "cuda: block %dx%d (%d threads): %s allows at most %d threads per block, %d x %d", p->bx,
                       p->by, p->threads, c->gpu, prop->maxThreadsPerBlock, prop->maxThreadsDim[0],
                       prop->maxThreadsDim[1]);
    if (cuda_plan_auto(c, has_tree, err))
        return -1;
    c->variant = rt_cuda_pick_kernel(p->threads, p->minb, (p->pairs ? RT_MODE_PAIRS : 0) | (p->slot ? RT_MODE_SLOT : 0));
    RT_CUDA_CHECK(cudaFuncGetAttributes(&c->fa, c->variant->kernel));
    if (p->threads > c->fa.maxThreadsPerBlock)
        return rt_fail(err,
                       "cuda: block %dx%d (%d threads): the kernel uses %d registers per thread, so at most %d "
                       "threads fit in a block on %s (%d registers per block)",
                       p->bx, p->by, p->threads, c->fa.numRegs, c->fa.maxThreadsPerBlock, c->gpu, prop->regsPerBlock);
    RT_CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&c->blocks_per_sm, c->variant->kernel, p->threads, 0));
    if (c->blocks_per_sm < 1)
        return rt_fail(err, "cuda: block %dx%d (%d threads): no such block fits on a multiprocessor of %s (%d "
                            "registers, %zu bytes of local memory per thread)",
                       p->bx, p->by, p->threads, c->gpu, c->fa.numRegs, (size_t)c->fa.localSizeBytes);
    /* the image's pixels over the pixels in flight (a block of pairs covers half its threads' pixels) */
    c->waves = (double)c->npix / ((double)c->blocks_per_sm * (double)(p->pairs ? p->threads / 2 : p->threads) *
                                  (double)prop->multiProcessorCount);
    c->slots = rt_cuda_frames_in_flight(c->waves);
    if (rt_cuda_grid(p, c->w, c->h, &c->g, err))
        return -1;
    /* Persistent: exactly the blocks resident at once, never more than there are tiles. */
    c->nblocks = (int)c->g.ntiles;
    if (p->persistent && c->blocks_per_sm * prop->multiProcessorCount < c->nblocks)
        c->nblocks = c->blocks_per_sm * prop->multiProcessorCount;
    return 0;
fail:
    return -1;
}

/* The host arrays of the allocation, with the tables only this backend uses:
 * the wide tree in slot order and the centre order. */
static int cuda_parts(CudaRun *c, RtError *err)
{
    const RtSceneView *hv = &c->job->view;
    RtCudaPart *pt = c->parts;
    int failed = 0;
    float way[3];
    if (c->plan.slot && c->tree && rt_cuda_slot_way(hv, way) && rt_cuda_tree_slot_order(c->tree, hv->nwide, way, err))
        return -1;
    if (c->plan.slot && !c->tree && (c->slot_wide = rt_cuda_slot_order(hv, err, &failed)) == NULL && failed)
        return -1;
    if (c->plan.center && (c->center = rt_cuda_center_order(&c->g, c->w, c->h, err)) == NULL)
        return -1;
    memset(pt, 0, sizeof c->parts);
    pt[P_PRIMS].host = hv->prims;      pt[P_PRIMS].bytes = (size_t)hv->nprims * sizeof(RtPrim);
    /* the binary nodes only where the kernel traverses them: no 4-wide tree (kernels.cuh) */
    pt[P_NODES].host = hv->nodes;      pt[P_NODES].bytes = hv->wide ? 0 : (size_t)hv->nnodes * sizeof(RtBvhNode);
    pt[P_WIDE].host = c->slot_wide ? c->slot_wide : hv->wide;
    pt[P_WIDE].bytes = hv->wide ? (size_t)hv->nwide * sizeof(RtBvh4Node) : 0;
#define PART_HOST(T, name) pt[P_##name].host = hv->name, pt[P_##name].bytes = (size_t)hv->n##name * sizeof(T);
    RT_SCENE_ARRAYS(PART_HOST) /* every scene array goes up whole */
#undef PART_HOST
    if (c->tree) /* (on the device already: the build's) */
        pt[P_PRIMS].bytes = pt[P_NODES].bytes = pt[P_WIDE].bytes = pt[P_vertices].bytes = pt[P_triangles].bytes =
            pt[P_spheres].bytes = 0;
    pt[P_IMAGE].bytes = (size_t)c->slots * c->npix * 3 * sizeof(float);
    pt[P_IMAGE8].bytes = (size_t)c->slots * c->npix * 3;
    pt[P_COUNTERS].bytes = (size_t)c->slots * RT_CUDA_CSLOT;
    pt[P_ORDER].host = c->center;
    pt[P_ORDER].bytes = c->center ? (size_t)c->g.ntiles * sizeof(uint32_t) : 0;
    c->arena_bytes = 0;
    for (int i = 0; i < P_COUNT; i++) {
        pt[i].offset = c->arena_bytes;
        c->arena_bytes += (pt[i].bytes + 255u) & ~(size_t)255u;
    }
    return 0;
}

/* Out of device memory, in one plain line: what the arena and the kernel's
 * stacks need, and what the device has free. */
static int cuda_out_of_memory(const CudaRun *c, size_t stacks, RtError *err)
{
    size_t free_b = 0, total_b = 0;
    cudaGetLastError(); /* clear it: an allocation failure is not sticky */
    cudaMemGetInfo(&free_b, &total_b);
    return rt_fail(err, "cuda: out of device memory: the scene, BVH and %dx%d image need %zu bytes (%.1f MiB) "
                        "and the kernel's stacks %.1f MiB on device %d (%s), which has %.1f MiB free of %.1f MiB",
                   c->w, c->h, c->arena_bytes, (double)c->arena_bytes / 1048576.0, (double)stacks / 1048576.0,
                   c->job->device, c->gpu, (double)free_b / 1048576.0, (double)total_b / 1048576.0);
}

/* The device arrays: allocated (out of memory is one plain message), copied,
 * the image poisoned, and the device view pointed at them. The launch
 * reserves the kernel's local memory for every thread the device can hold,
 * so that is counted before the arena: an arena that fits without it would
 * fail at the launch instead, with no sizes. */
static int cuda_upload(CudaRun *c, RtError *err)
{
    if (cuda_parts(c, err))
        return -1;
    const size_t stacks = (size_t)c->fa.localSizeBytes * (size_t)c->prop.maxThreadsPerMultiProcessor *
                          (size_t)c->prop.multiProcessorCount;
    size_t free_b = 0, total_b = 0;
    if (cudaMemGetInfo(&free_b, &total_b) == cudaSuccess && c->arena_bytes + stacks > free_b)
        return cuda_out_of_memory(c, stacks, err);
    cudaError_t e = cudaMalloc((void **)&c->arena, c->arena_bytes);
    if (e == cudaErrorMemoryAllocation) {
        c->arena = NULL;
        return cuda_out_of_memory(c, stacks, err);
    }
    if (e != cudaSuccess) {
        c->arena = NULL;
        return rt_cuda_fail(err, e, "cudaMalloc(arena)", __FILE__, __LINE__);
    }
    const double t0 = rt_now_ms();
    for (int i = 0; i < P_COUNT; i++)
        if (c->parts[i].host && c->parts[i].bytes)
            RT_CUDA_CHECK(rt_cuda_copy_up(c->arena + c->parts[i].offset, c->parts[i].host, c->parts[i].bytes));
    c->upload_ms = rt_now_ms() - t0;
    /* NaN in every channel: a pixel the kernel never writes cannot pass as black. */
    RT_CUDA_CHECK(cudaMemset(c->arena + c->parts[P_IMAGE].offset, 0xff, c->parts[P_IMAGE].bytes));
    {
        const RtSceneView *hv = &c->job->view;
        RtSceneView *dv = &c->dv;
        unsigned char *a = c->arena;
        *dv = *hv;
        dv->prims = (const RtPrim *)(a + c->parts[P_PRIMS].offset);
        dv->nodes = c->parts[P_NODES].bytes ? (const RtBvhNode *)(a + c->parts[P_NODES].offset) : NULL;
        dv->wide = hv->wide ? (const RtBvh4Node *)(a + c->parts[P_WIDE].offset) : NULL;
#define PART_DEVICE(T, name) dv->name = (const T *)(a + c->parts[P_##name].offset);
        RT_SCENE_ARRAYS(PART_DEVICE)
#undef PART_DEVICE
        if (c->tree) {
            dv->prims = c->tree->prims;
            dv->wide = c->tree->wide;
            dv->vertices = c->tree->vertices;
            dv->triangles = c->tree->triangles;
            dv->spheres = c->tree->spheres;
        }
        c->g.units = c->center ? (const uint32_t *)(a + c->parts[P_ORDER].offset) : NULL;
    }
    return 0;
fail:
    return -1;
}

/* The kernel over grid g in nblocks blocks, its 8-bit pixels into image
 * slot `slot` (the stream's order keeps it after the work counter's reset). */
static int cuda_kernel(CudaRun *c, const RtCudaGrid *g, int nblocks, int slot, cudaStream_t stream, RtError *err)
{
    unsigned char *a = c->arena;
    c->variant->kernel<<<nblocks, dim3((unsigned)c->plan.bx, (unsigned)c->plan.by), 0, stream>>>(
        c->dv, (float *)(a + c->parts[P_IMAGE].offset) + (size_t)slot * c->npix * 3,
        a + c->parts[P_IMAGE8].offset + (size_t)slot * c->npix * 3,
        (unsigned long long *)(a + c->parts[P_COUNTERS].offset + (size_t)slot * RT_CUDA_CSLOT),
        (unsigned int *)(a + c->parts[P_COUNTERS].offset + (size_t)slot * RT_CUDA_CSLOT + RT_CUDA_WORK), *g);
    RT_CUDA_CHECK_LAUNCH("rt_render_kernel");
    return 0;
fail:
    return -1;
}

/* Slot `slot`'s ray counters down from the device. */
static int cuda_counters(CudaRun *c, int slot, RtCounters *cnt, RtError *err)
{
    unsigned long long h[RT_NCOUNTERS];
    RT_CUDA_CHECK(cudaMemcpy(h, c->arena + c->parts[P_COUNTERS].offset + (size_t)slot * RT_CUDA_CSLOT, sizeof h,
                             cudaMemcpyDeviceToHost));
    cnt->primary_rays = h[0];
    cnt->shadow_rays = h[1];
    cnt->secondary_rays = h[2];
    cnt->node_visits = h[3];
    cnt->prim_tests = h[4];
    return 0;
fail:
    return -1;
}

/* The plan's record keys (docs/gpu.md, "Record keys"), for the launch g in
 * nblocks blocks. */
static void cuda_plan_keys(const CudaRun *c, const RtCudaGrid *g, int nblocks, char *buf, size_t size)
{
    const RtCudaPlan *p = &c->plan;
    snprintf(buf, size,
             " block=%dx%d large=%d pairs=%d sched=%s order=%s traversal=%s anyhit=%s waves=%.2f regs=%d "
             "local_bytes=%zu bounds=%dx%d blocks_per_sm=%d grid=%d in_flight=%d",
             p->bx, p->by, p->large, p->pairs, p->persistent ? "persistent" : "grid", g->units ? "center" : "tiles",
             c->job->view.wide ? "wide" : "binary", p->slot ? "slot" : "sorted", c->waves, c->fa.numRegs,
             (size_t)c->fa.localSizeBytes, c->variant->maxt, c->variant->minb, c->blocks_per_sm, nblocks, c->slots);
}

static void cuda_release(CudaRun *c)
{
    if (c->arena)
        cudaFree(c->arena);
    free(c->center);
    free(c->slot_wide);
}

/* ---------------------------------------------------------------- sessions */

/* Event sets: the frames in flight and the one before them (whose kernel's
 * end may start the next frame's kernel time). */
#define RT_CUDA_EV (RT_CUDA_MAX_SLOTS + 1)
#define RT_CUDA_PINS 4

/* A session queues frames: each frame's kernel on a stream of its slot, so
 * that a frame's kernel starts on the multiprocessors the previous
 * frame's last blocks leave idle (the tail of a launch); the copy of its
 * share's rows down on a third stream after it, so that it overlaps the next
 * frame's kernel. Events time each frame's kernel and copy; frames complete
 * in the order they were queued. */
struct RtCudaSession {
    CudaRun c;
    RtCudaGrid g;                 /* the share's launch */
    int nblocks;
    RtShareRuns r8, rf;           /* the share's pixels in the 8-bit and in the float image */
    void *pinned[RT_CUDA_PINS];   /* host buffers page-locked by rt_cuda_session_pin */
    int npinned;
    cudaStream_t ks[RT_CUDA_MAX_SLOTS], cs; /* kernels (frame k on ks[k % slots]), copies */
    cudaEvent_t k0[RT_CUDA_EV], k1[RT_CUDA_EV], c1[RT_CUDA_EV];
    int nev;                      /* event sets created */
    unsigned long long queued, done;
};

static int session_events(RtCudaSession *s, RtError *err)
{
    for (; s->nev < RT_CUDA_EV; s->nev++) {
        cudaEvent_t *e[3] = {&s->k0[s->nev], &s->k1[s->nev], &s->c1[s->nev]};
        for (int i = 0; i < 3; i++)
            if (cudaEventCreate(e[i]) != cudaSuccess) {
                while (i-- > 0)
                    cudaEventDestroy(*e[i]);
                RT_CUDA_CHECK(cudaGetLastError());
            }
    }
    return 0;
fail:
    return -1;
}

int rt_cuda_session_open(const RtRenderJob *job, RtCudaSession **out, RtError *err)
{
    RtCudaSession *s = (RtCudaSession *)calloc(1, sizeof *s);
    *out = NULL;
    if (!s)
        return rt_fail(err, "cuda: out of memory");
    CudaRun *c = &s->c;
    c->job = job;
    c->w = job->view.cam.width;
    c->h = job->view.cam.height;
    c->npix = (size_t)c->w * (size_t)c->h;
    if (job->accel && job->accel->device) { /* built on a GPU: read in place on its device */
        c->tree = (RtCudaTree *)job->accel->device;
        if (c->tree->device != job->device && !job->accel->prims) {
            rt_fail(err, "cuda: the BVH was built on device %d, the render runs on %d", c->tree->device, job->device);
            goto fail;
        }
        if (c->tree->device != job->device)
            c->tree = NULL;
    }
    if (cuda_open(c, err) || cuda_plan(c, err) || cuda_upload(c, err))
        goto fail;
    RT_CUDA_CHECK(cudaDeviceSynchronize()); /* (the streams below do not wait for the legacy stream's poison) */
    for (int i = 0; i < c->slots; i++)
        RT_CUDA_CHECK(cudaStreamCreateWithFlags(&s->ks[i], cudaStreamNonBlocking));
    RT_CUDA_CHECK(cudaStreamCreateWithFlags(&s->cs, cudaStreamNonBlocking));
    if (session_events(s, err))
        goto fail;
    {
        const RtCudaShare whole = {0, 1, 1};
        rt_cuda_session_share(s, &whole);
    }
    *out = s;
    return 0;
fail:
    rt_cuda_session_close(s);
    return -1;
}

int rt_cuda_session_tile_rows(const RtCudaSession *s, int *row_h, int *wave_rows)
{
    const CudaRun *c = &s->c;
    const int rows = (int)((c->g.ntiles + (uint32_t)c->g.tiles_x - 1) / (uint32_t)c->g.tiles_x);
    /* the pixels resident at once over a tile row's pixels, rounded up */
    const double resident = (double)c->blocks_per_sm * (double)c->prop.multiProcessorCount *
                            (double)(c->plan.pairs ? c->plan.threads / 2 : c->plan.threads);
    const double per_row = (double)c->g.tiles_x * (double)c->g.tile_items;
    const double wr = resident / per_row;
    *row_h = c->g.by;
    *wave_rows = wr >= rows ? rows : wr < 1.0 ? 1 : (int)wr + (wr > (int)wr);
    return rows;
}

int rt_cuda_session_share(RtCudaSession *s, const RtCudaShare *sh)
{
    CudaRun *c = &s->c;
    int row_h, wave_rows;
    const int rows = rt_cuda_session_tile_rows(s, &row_h, &wave_rows);
    s->g = c->g;
    const uint32_t n = rt_cuda_grid_share(&s->g, sh, rows);
    /* persistent: the blocks resident at once, never more than there are tiles */
    s->nblocks = (int)s->g.ntiles;
    if (c->plan.persistent && c->nblocks < s->nblocks)
        s->nblocks = c->nblocks;
    rt_cuda_share_runs(sh, rows, row_h, c->h, (size_t)c->w * 3, &s->r8);
    rt_cuda_share_runs(sh, rows, row_h, c->h, (size_t)c->w * 3 * sizeof(float), &s->rf);
    return (int)n;
}

const RtShareRuns *rt_cuda_session_runs(const RtCudaSession *s, int floats) { return floats ? &s->rf : &s->r8; }

void rt_cuda_session_pin(RtCudaSession *s, void *host, size_t bytes)
{
    if (s->npinned == RT_CUDA_PINS)
        return;
    if (rt_cuda_lock(host, bytes)) /* (else the copies go on from pageable memory) */
        s->pinned[s->npinned++] = host;
}

void rt_cuda_session_unpin(RtCudaSession *s)
{
    while (s->npinned > 0)
        cudaHostUnregister(s->pinned[--s->npinned]);
}

/* The share's pieces of one image (runs r, from src to dst at the same
 * offsets) queued on stream st. */
static int copy_runs(const RtShareRuns *r, void *dst, const void *src, cudaStream_t st, RtError *err)
{
    if (r->count)
        RT_CUDA_CHECK(cudaMemcpy2DAsync((char *)dst + r->off, r->pitch, (const char *)src + r->off, r->pitch,
                                        r->width, r->count, cudaMemcpyDeviceToHost, st));
    if (r->tail_bytes)
        RT_CUDA_CHECK(cudaMemcpyAsync((char *)dst + r->tail_off, (const char *)src + r->tail_off, r->tail_bytes,
                                      cudaMemcpyDeviceToHost, st));
    return 0;
fail:
    return -1;
}

int rt_cuda_session_queue(RtCudaSession *s, uint8_t *rgb8, float *rgbf, RtError *err)
{
    CudaRun *c = &s->c;
    unsigned char *a = c->arena;
    const unsigned long long q = s->queued;
    const unsigned long long n = (unsigned long long)c->slots;
    const int e = (int)(q % RT_CUDA_EV), slot = (int)(q % n);
    cudaStream_t ks = s->ks[slot];
    if (q - s->done >= n)
        return rt_fail(err, "cuda: more than %d frames in flight", c->slots);
    /* the slot's last frame is copied down before this one writes it */
    if (q >= n)
        RT_CUDA_CHECK(cudaStreamWaitEvent(ks, s->c1[(q - n) % RT_CUDA_EV], 0));
    RT_CUDA_CHECK(cudaMemsetAsync(a + c->parts[P_COUNTERS].offset + (size_t)slot * RT_CUDA_CSLOT, 0, RT_CUDA_CSLOT,
                                  ks));
    RT_CUDA_CHECK(cudaEventRecord(s->k0[e], ks));
    if (s->nblocks > 0 && cuda_kernel(c, &s->g, s->nblocks, slot, ks, err))
        return -1;
    RT_CUDA_CHECK(cudaEventRecord(s->k1[e], ks));
    RT_CUDA_CHECK(cudaStreamWaitEvent(s->cs, s->k1[e], 0));
    if (rgb8 && copy_runs(&s->r8, rgb8, a + c->parts[P_IMAGE8].offset + (size_t)slot * c->npix * 3, s->cs, err))
        return -1;
    if (rgbf && copy_runs(&s->rf, rgbf, (float *)(a + c->parts[P_IMAGE].offset) + (size_t)slot * c->npix * 3, s->cs,
                          err))
        return -1;
    RT_CUDA_CHECK(cudaEventRecord(s->c1[e], s->cs));
    s->queued++;
    return 0;
fail:
    return -1;
}

int rt_cuda_session_wait(RtCudaSession *s, RtCudaFrame *f, RtError *err)
{
    const int e = (int)(s->done % RT_CUDA_EV);
    float k = 0.0f, d = 0.0f;
    if (s->done == s->queued)
        return rt_fail(err, "cuda: no frame queued");
    RT_CUDA_CHECK(cudaEventSynchronize(s->c1[e]));
    f->end = rt_now_ms();
    RT_CUDA_CHECK(cudaEventElapsedTime(&k, s->k0[e], s->k1[e]));
    RT_CUDA_CHECK(cudaEventElapsedTime(&d, s->k1[e], s->c1[e]));
    if (s->done > 0) { /* from the previous kernel's end where this one started under it */
        float since = 0.0f;
        RT_CUDA_CHECK(cudaEventElapsedTime(&since, s->k1[(s->done - 1) % RT_CUDA_EV], s->k1[e]));
        if (since > 0.0f && since < k)
            k = since;
    }
    f->kernel_ms = k;
    f->copy_ms = d;
    s->done++;
    return 0;
fail:
    return -1;
}

static __global__ void rt_trap_kernel(void) { __trap(); }

int rt_cuda_session_fault(RtCudaSession *s, RtError *err)
{
    rt_trap_kernel<<<1, 1, 0, s->ks[0]>>>();
    RT_CUDA_CHECK(cudaStreamSynchronize(s->ks[0]));
    return rt_fail(err, "cuda: the trap kernel did not fault");
fail:
    return -1;
}

int rt_cuda_session_slots(const RtCudaSession *s) { return s->c.slots; }

unsigned long long rt_cuda_session_queued(const RtCudaSession *s) { return s->queued; }

int rt_cuda_session_counters(RtCudaSession *s, RtCounters *cnt, RtError *err)
{
    for (int i = 0; i < s->c.slots; i++)
        RT_CUDA_CHECK(cudaStreamSynchronize(s->ks[i]));
    return cuda_counters(&s->c, (int)((s->queued - 1) % (unsigned long long)s->c.slots), cnt, err);
fail:
    return -1;
}

const char *rt_cuda_session_gpu(const RtCudaSession *s) { return s->c.gpu_at; }

void rt_cuda_session_keys(const RtCudaSession *s, char *buf, size_t size)
{
    cuda_plan_keys(&s->c, &s->g, s->nblocks, buf, size);
}

void rt_cuda_session_close(RtCudaSession *s)
{
    if (!s)
        return;
    for (int i = 0; i < RT_CUDA_MAX_SLOTS; i++)
        if (s->ks[i])
            cudaStreamSynchronize(s->ks[i]);
    if (s->cs)
        cudaStreamSynchronize(s->cs);
    rt_cuda_session_unpin(s);
    for (int i = 0; i < s->nev; i++) {
        cudaEventDestroy(s->k0[i]);
        cudaEventDestroy(s->k1[i]);
        cudaEventDestroy(s->c1[i]);
    }
    for (int i = 0; i < RT_CUDA_MAX_SLOTS; i++)
        if (s->ks[i])
            cudaStreamDestroy(s->ks[i]);
    if (s->cs)
        cudaStreamDestroy(s->cs);
    cuda_release(&s->c);
    free(s);
}

/* ---------------------------------------------------------------- frames */

int rt_cuda_frames_init(RtCudaFrames *f, const RtRenderJob *job, RtError *err)
{
    memset(f, 0, sizeof *f);
    f->job = job;
    f->max_runs = job->runs > 0 ? job->runs : RT_CUDA_RUNS;
    f->warm_ms = job->warmup_runs < 0 && job->warmup_ms < 0.0 ? RT_CUDA_WARMUP_MS : job->warmup_ms;
    f->v = (double *)malloc(4 * sizeof *f->v * (size_t)f->max_runs);
    if (!f->v)
        return rt_fail(err, "cuda: out of memory for %d timings", f->max_runs);
    f->t0 = rt_now_ms();
    return 0;
}

int rt_cuda_frames_add(RtCudaFrames *f, double period_ms, double kernel_ms, double copy_ms, double first_end_ms)
{
    const RtRenderJob *job = f->job;
    if (f->n == 0)
        f->first_kernel_ms = kernel_ms;
    const int warm = f->runs == 0 && rt_warmup_due(job->warmup_runs, f->warm_ms, f->n, rt_now_ms() - f->t0);
    f->n++;
    if (warm) {
        f->warmups++;
    } else {
        const int m = f->max_runs, r = f->runs++;
        f->v[r] = period_ms;
        f->v[m + r] = kernel_ms;
        f->v[2 * m + r] = copy_ms;
        f->v[3 * m + r] = first_end_ms;
    }
    if (job->progress)
        job->progress(job->progress_ctx, (uint64_t)f->n, (uint64_t)f->max_runs + 1);
    const int budget = job->runs <= 0 && period_ms * (f->runs + 1) > RT_CUDA_TIME_BUDGET_MS;
    return f->runs < f->max_runs && !budget;
}

void rt_cuda_frames_out(RtCudaFrames *f, RtRenderOut *out)
{
    const int m = f->max_runs, n = f->runs;
    out->render_ms = rt_median(f->v, n); /* (sorts: v[0] is the fastest) */
    out->render_ms_best = f->v[0];
    out->render_ms_min = rt_median(f->v + 3 * m, n);
    out->runs = n;
    out->warmups = f->warmups;
    f->kernel_ms = rt_median(f->v + m, n);
    f->kernel_min_ms = f->v[m];
    f->copy_ms = rt_median(f->v + 2 * m, n);
    out->quantized = !f->job->want_float;
}

void rt_cuda_frames_free(RtCudaFrames *f)
{
    free(f->v);
    f->v = NULL;
}

/* ---------------------------------------------------------------- render */

/* Frames of the whole image until the timing is done (rt_cuda_frames_add),
 * as many in flight as the session has slots, so that a frame's copy runs
 * under the next frame's kernel. Frames queued after the last wanted one are
 * waited for and not counted. */
static int cuda_frames(RtCudaSession *s, RtCudaFrames *fr, RtRenderOut *out, RtError *err)
{
    const RtRenderJob *job = fr->job;
    uint8_t *rgb8 = job->want_float ? NULL : out->rgb8;
    float *rgbf = job->want_float ? out->rgb : NULL;
    double prev = rt_now_ms();
    int more = 1;
    if (rt_cuda_session_queue(s, rgb8, rgbf, err))
        return -1;
    while (s->done < s->queued) {
        while (more && s->queued - s->done < (unsigned long long)s->c.slots)
            if (rt_cuda_session_queue(s, rgb8, rgbf, err))
                return -1;
        RtCudaFrame f;
        if (rt_cuda_session_wait(s, &f, err))
            return -1;
        if (more)
            more = rt_cuda_frames_add(fr, f.end - prev, f.kernel_ms, f.copy_ms, f.end - prev);
        prev = f.end;
    }
    if (job->progress)
        job->progress(job->progress_ctx, (uint64_t)fr->max_runs + 1, (uint64_t)fr->max_runs + 1);
    return 0;
}

static int render_cuda(const RtRenderJob *job, RtRenderOut *out, RtError *err)
{
    const double t_wall0 = rt_now_ms();
    RtCudaSession *s = NULL;
    RtCudaFrames fr;
    memset(&fr, 0, sizeof fr);
    if (rt_cuda_session_open(job, &s, err) || rt_cuda_frames_init(&fr, job, err))
        goto fail;
    {
        const size_t npix = s->c.npix;
        if (job->want_float) /* --verify: the floats, quantised and checked on the host */
            rt_cuda_session_pin(s, out->rgb, npix * 3 * sizeof(float));
        else
            rt_cuda_session_pin(s, out->rgb8, npix * 3);
    }
    if (cuda_frames(s, &fr, out, err) || rt_cuda_session_counters(s, &out->counters, err))
        goto fail;
    rt_cuda_frames_out(&fr, out);
    out->threads_used = s->nblocks * s->c.plan.threads;
    out->ranks_used = 1;
    out->is_root = 1;
    rt_cores_note(out->cores, sizeof out->cores, rt_current_cpu());
    {
        char plan[512];
        rt_cuda_session_keys(s, plan, sizeof plan);
        snprintf(out->extra, sizeof out->extra,
                 "%s kernel_ms=%.4f kernel_min_ms=%.4f frames=%d warmup_frames=%d first_ms=%.4f init_ms=%.3f "
                 "upload_ms=%.3f download_ms=%.3f wall_ms=%.3f gpu=%s",
                 plan, fr.kernel_ms, fr.kernel_min_ms, fr.runs, fr.warmups, fr.first_kernel_ms, s->c.init_ms,
                 s->c.upload_ms, fr.copy_ms, rt_now_ms() - t_wall0, s->c.gpu);
    }
    rt_cuda_frames_free(&fr);
    rt_cuda_session_close(s);
    return 0;
fail:
    rt_cuda_frames_free(&fr);
    rt_cuda_session_close(s);
    return -1;
}

extern "C" {
extern const RtBackend rt_backend_cuda;
/* times its own runs: the scene stays on the device between frames */
const RtBackend rt_backend_cuda = {"cuda", NULL, NULL, render_cuda, NULL, NULL, 1, cuda_prewarm, 1, RT_OMP_TILE,
                                   rt_cuda_accel_build, rt_cuda_geom_sink};
}
