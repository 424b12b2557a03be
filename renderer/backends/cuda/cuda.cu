/* cuda.cu - the CUDA backend's host flow, one step per function, every CUDA
 * call checked (cuda_check.h):
 *   cuda_open    device and context;
 *   cuda_plan    block, schedule and kernel (the choices are schedule.c's),
 *                checked against the kernel's real limits;
 *   cuda_upload  one device allocation holding the flat scene arrays, the
 *                BVH as the host built it, the image and the counters;
 *   cuda_launch  warm-up launches, then the timed ones (CUDA events; the
 *                median is render_ms);
 *   cuda_finish  image and counters down, the record's keys.
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
#include "cuda_check.h"
#include "cuda_session.h"

/* One device allocation for everything: each array at a 256-byte aligned
 * offset, so one size is known (for the out-of-memory message) and one free
 * releases it all. */
typedef struct RtCudaPart {
    const void *host; /* NULL: device-only (image, counters) */
    size_t bytes;
    size_t offset;
} RtCudaPart;

enum { P_PRIMS, P_NODES, P_WIDE, P_VERTS, P_NORMALS, P_SPHERES, P_TRIS, P_MATS, P_LIGHTS, P_IMAGE, P_COUNTERS, P_WORK,
       P_ORDER, P_COUNT };

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
    cudaEvent_t ev0, ev1;
    double *times;             /* timed launches, ms */
    int runs, warmups;
    double init_ms, upload_ms, download_ms, first_ms;
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

/* The CUDA context takes 100 ms and more to create (H100 machine: 114-127
 * ms); created on a thread of its own while main() parses or maps the
 * scene, it is ready or nearly so when the render starts. */
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
static int cuda_open(CudaRun *c, RtError *err)
{
    const double t_wait = rt_now_ms();
    if (g_warm_started) {
        pthread_join(g_warm, NULL);
        g_warm_started = 0;
    }
    int ndev = 0;
    const int dev = c->job->device;
    if (rt_cuda_device_count(&ndev, err))
        return -1;
    if (dev < 0 || dev >= ndev)
        return rt_fail(err, "cuda: --device %d: this machine has %d CUDA device(s), numbered 0 to %d", dev, ndev,
                       ndev - 1);
    RT_CUDA_CHECK(cudaSetDevice(dev));
    RT_CUDA_CHECK(cudaFree(0));
    c->init_ms = rt_now_ms() - t_wait; /* what is left of the context's creation */
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
    p->slot = !p->pairs && c->job->view.wide != NULL;
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
    const RtScene *sc = c->job->scene;
    RtCudaPart *pt = c->parts;
    int failed = 0;
    if (c->plan.slot && (c->slot_wide = rt_cuda_slot_order(hv, err, &failed)) == NULL && failed)
        return -1;
    if (c->plan.center && (c->center = rt_cuda_center_order(&c->g, c->w, c->h, err)) == NULL)
        return -1;
    memset(pt, 0, sizeof c->parts);
    pt[P_PRIMS].host = hv->prims;      pt[P_PRIMS].bytes = (size_t)hv->nprims * sizeof(RtPrim);
    /* the binary nodes only where the kernel traverses them: no 4-wide tree (kernels.cuh) */
    pt[P_NODES].host = hv->nodes;      pt[P_NODES].bytes = hv->wide ? 0 : (size_t)hv->nnodes * sizeof(RtBvhNode);
    pt[P_WIDE].host = c->slot_wide ? c->slot_wide : hv->wide;
    pt[P_WIDE].bytes = hv->wide ? (size_t)hv->nwide * sizeof(RtBvh4Node) : 0;
    pt[P_VERTS].host = hv->vertices;   pt[P_VERTS].bytes = (size_t)sc->nvertices * sizeof(RtVec3);
    pt[P_NORMALS].host = hv->normals;  pt[P_NORMALS].bytes = (size_t)sc->nnormals * sizeof(RtVec3);
    pt[P_SPHERES].host = hv->spheres;  pt[P_SPHERES].bytes = (size_t)hv->nspheres * sizeof(RtSphere);
    pt[P_TRIS].host = hv->triangles;   pt[P_TRIS].bytes = (size_t)hv->ntriangles * sizeof(RtTriangle);
    pt[P_MATS].host = hv->materials;   pt[P_MATS].bytes = (size_t)hv->nmaterials * sizeof(RtMaterial);
    pt[P_LIGHTS].host = hv->lights;    pt[P_LIGHTS].bytes = (size_t)hv->nlights * sizeof(RtLight);
    pt[P_IMAGE].bytes = c->npix * 3 * sizeof(float);
    pt[P_COUNTERS].bytes = RT_NCOUNTERS * sizeof(unsigned long long);
    pt[P_WORK].bytes = sizeof(unsigned int);
    pt[P_ORDER].host = c->center;
    pt[P_ORDER].bytes = c->center ? (size_t)c->g.ntiles * sizeof(uint32_t) : 0;
    c->arena_bytes = 0;
    for (int i = 0; i < P_COUNT; i++) {
        pt[i].offset = c->arena_bytes;
        c->arena_bytes += (pt[i].bytes + 255u) & ~(size_t)255u;
    }
    return 0;
}

/* The device arrays: allocated (out of memory is one plain message), copied,
 * the image poisoned, and the device view pointed at them. */
static int cuda_upload(CudaRun *c, RtError *err)
{
    if (cuda_parts(c, err))
        return -1;
    cudaError_t e = cudaMalloc((void **)&c->arena, c->arena_bytes);
    if (e == cudaErrorMemoryAllocation) {
        size_t free_b = 0, total_b = 0;
        cudaGetLastError(); /* clear it: an allocation failure is not sticky */
        cudaMemGetInfo(&free_b, &total_b);
        c->arena = NULL;
        return rt_fail(err, "cuda: out of device memory: the scene, BVH and %dx%d image need %zu bytes (%.1f MiB) "
                            "on device %d (%s), which has %.1f MiB free of %.1f MiB",
                       c->w, c->h, c->arena_bytes, (double)c->arena_bytes / 1048576.0, c->job->device, c->gpu,
                       (double)free_b / 1048576.0, (double)total_b / 1048576.0);
    }
    if (e != cudaSuccess) {
        c->arena = NULL;
        return rt_cuda_fail(err, e, "cudaMalloc(arena)", __FILE__, __LINE__);
    }
    const double t0 = rt_now_ms();
    for (int i = 0; i < P_COUNT; i++)
        if (c->parts[i].host && c->parts[i].bytes)
            RT_CUDA_CHECK(cudaMemcpy(c->arena + c->parts[i].offset, c->parts[i].host, c->parts[i].bytes,
                                     cudaMemcpyHostToDevice));
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
        dv->vertices = (const RtVec3 *)(a + c->parts[P_VERTS].offset);
        dv->normals = (const RtVec3 *)(a + c->parts[P_NORMALS].offset);
        dv->spheres = (const RtSphere *)(a + c->parts[P_SPHERES].offset);
        dv->triangles = (const RtTriangle *)(a + c->parts[P_TRIS].offset);
        dv->materials = (const RtMaterial *)(a + c->parts[P_MATS].offset);
        dv->lights = (const RtLight *)(a + c->parts[P_LIGHTS].offset);
        c->g.units = c->center ? (const uint32_t *)(a + c->parts[P_ORDER].offset) : NULL;
    }
    return 0;
fail:
    return -1;
}

/* The kernel over grid g in nblocks blocks (the stream's order keeps it
 * after the work counter's reset). */
static int cuda_kernel(CudaRun *c, const RtCudaGrid *g, int nblocks, cudaStream_t stream, RtError *err)
{
    unsigned char *a = c->arena;
    c->variant->kernel<<<nblocks, dim3((unsigned)c->plan.bx, (unsigned)c->plan.by), 0, stream>>>(
        c->dv, (float *)(a + c->parts[P_IMAGE].offset), (unsigned long long *)(a + c->parts[P_COUNTERS].offset),
        (unsigned int *)(a + c->parts[P_WORK].offset), *g);
    RT_CUDA_CHECK_LAUNCH("rt_render_kernel");
    return 0;
fail:
    return -1;
}

/* The ray counters down from the device. */
static int cuda_counters(CudaRun *c, RtCounters *cnt, RtError *err)
{
    unsigned long long h[RT_NCOUNTERS];
    RT_CUDA_CHECK(cudaMemcpy(h, c->arena + c->parts[P_COUNTERS].offset, sizeof h, cudaMemcpyDeviceToHost));
    cnt->primary_rays = h[0];
    cnt->shadow_rays = h[1];
    cnt->secondary_rays = h[2];
    cnt->node_visits = h[3];
    cnt->prim_tests = h[4];
    return 0;
fail:
    return -1;
}

/* One launch from zeroed counters, timed between CUDA events. */
static int cuda_launch_once(CudaRun *c, float *ms, RtError *err)
{
    unsigned char *a = c->arena;
    /* the counters and the work counter that follows them, in one memset */
    RT_CUDA_CHECK(cudaMemsetAsync(a + c->parts[P_COUNTERS].offset, 0,
                                  c->parts[P_WORK].offset + c->parts[P_WORK].bytes - c->parts[P_COUNTERS].offset));
    RT_CUDA_CHECK(cudaEventRecord(c->ev0));
    if (cuda_kernel(c, &c->g, c->nblocks, 0, err))
        return -1;
    RT_CUDA_CHECK(cudaEventRecord(c->ev1));
    RT_CUDA_CHECK(cudaEventSynchronize(c->ev1));
    RT_CUDA_CHECK(cudaEventElapsedTime(ms, c->ev0, c->ev1));
    return 0;
fail:
    return -1;
}

/* Warm-up launches (--warmup: a count, or a time with at least one launch;
 * first_ms is the first, cold, launch either way), then the timed ones
 * (--runs). The image and counters of the last launch are kept. */
static int cuda_launch(CudaRun *c, RtError *err)
{
    const RtRenderJob *job = c->job;
    const int max_runs = job->runs > 0 ? job->runs : RT_CUDA_RUNS;
    const int budget = job->runs <= 0;
    const double warm_ms = job->warmup_runs < 0 && job->warmup_ms < 0.0 ? RT_CUDA_WARMUP_MS : job->warmup_ms;
    c->times = (double *)malloc((size_t)max_runs * sizeof *c->times);
    if (!c->times)
        return rt_fail(err, "cuda: out of memory for %d timings", max_runs);
    double t0;
    RT_CUDA_CHECK(cudaEventCreate(&c->ev0));
    RT_CUDA_CHECK(cudaEventCreate(&c->ev1));
    t0 = rt_now_ms();
    for (int launch = 0;; launch++) {
        float ms = 0.0f;
        if (cuda_launch_once(c, &ms, err))
            return -1;
        if (launch == 0) {
            c->first_ms = ms;
            if (job->progress)
                job->progress(job->progress_ctx, 1, (uint64_t)max_runs + 1);
        }
        const int warm = c->runs == 0 && rt_warmup_due(job->warmup_runs, warm_ms, launch, rt_now_ms() - t0);
        if (warm) {
            c->warmups++;
            continue;
        }
        c->times[c->runs++] = ms;
        if (c->runs >= max_runs || (budget && (double)ms * (double)(c->runs + 1) > RT_CUDA_TIME_BUDGET_MS))
            break;
    }
    if (job->progress)
        job->progress(job->progress_ctx, (uint64_t)max_runs + 1, (uint64_t)max_runs + 1);
    return 0;
fail:
    return -1;
}

/* The image and counters down; render_ms the median of the timed launches. */
static int cuda_finish(CudaRun *c, RtRenderOut *out, RtError *err)
{
    double t0 = rt_now_ms();
    RT_CUDA_CHECK(cudaMemcpy(out->rgb, c->arena + c->parts[P_IMAGE].offset, c->parts[P_IMAGE].bytes,
                             cudaMemcpyDeviceToHost));
    c->download_ms = rt_now_ms() - t0;
    if (cuda_counters(c, &out->counters, err))
        return -1;
    out->render_ms = rt_median(c->times, c->runs); /* (sorts: times[0] is the fastest) */
    out->render_ms_min = out->render_ms;
    out->render_ms_best = c->times[0];
    out->runs = c->runs;
    out->warmups = c->warmups;
    out->threads_used = c->nblocks * c->plan.threads;
    out->ranks_used = 1;
    out->is_root = 1;
    rt_cores_note(out->cores, sizeof out->cores, rt_current_cpu());
    return 0;
fail:
    return -1;
}

/* The plan's record keys (docs/gpu.md, "Record keys"). */
static void cuda_plan_keys(const CudaRun *c, char *buf, size_t size)
{
    const RtCudaPlan *p = &c->plan;
    snprintf(buf, size,
             " block=%dx%d large=%d pairs=%d sched=%s order=%s traversal=%s anyhit=%s waves=%.2f regs=%d "
             "local_bytes=%zu bounds=%dx%d blocks_per_sm=%d grid=%d",
             p->bx, p->by, p->large, p->pairs, p->persistent ? "persistent" : "grid", p->center ? "center" : "tiles",
             c->job->view.wide ? "wide" : "binary", p->slot ? "slot" : "sorted", c->waves, c->fa.numRegs,
             (size_t)c->fa.localSizeBytes, c->variant->maxt, c->variant->minb, c->blocks_per_sm, c->nblocks);
}

/* The backend's record keys: the plan's, then the timings'. */
static void cuda_record(const CudaRun *c, RtRenderOut *out, double wall_ms)
{
    char plan[512];
    cuda_plan_keys(c, plan, sizeof plan);
    snprintf(out->extra, sizeof out->extra,
             "%s kernel_runs=%d kernel_min_ms=%.4f warmup_launches=%d first_ms=%.4f init_ms=%.3f upload_ms=%.3f "
             "download_ms=%.3f wall_ms=%.3f gpu=%s",
             plan, c->runs, c->times[0], c->warmups, c->first_ms, c->init_ms, c->upload_ms, c->download_ms, wall_ms,
             c->gpu);
}

static void cuda_release(CudaRun *c)
{
    if (c->ev0)
        cudaEventDestroy(c->ev0);
    if (c->ev1)
        cudaEventDestroy(c->ev1);
    if (c->arena)
        cudaFree(c->arena);
    free(c->center);
    free(c->slot_wide);
    free(c->times);
}

static int render_cuda(const RtRenderJob *job, RtRenderOut *out, RtError *err)
{
    const double t_wall0 = rt_now_ms();
    CudaRun c;
    memset(&c, 0, sizeof c);
    c.job = job;
    c.w = job->view.cam.width;
    c.h = job->view.cam.height;
    c.npix = (size_t)c.w * (size_t)c.h;
    int rc = -1;
    if (cuda_open(&c, err) == 0 && cuda_plan(&c, err) == 0 && cuda_upload(&c, err) == 0 && cuda_launch(&c, err) == 0 &&
        cuda_finish(&c, out, err) == 0) {
        cuda_record(&c, out, rt_now_ms() - t_wall0);
        rc = 0;
    }
    cuda_release(&c);
    return rc;
}

/* ---------------------------------------------------------------- sessions */

/* A session queues bands: each band's kernel on one stream, the copy of its
 * rows down on another after it, so that a band's copy overlaps the next
 * band's kernel. Events mark each band's kernel and copy; bands complete in
 * the order they were queued. */
struct RtCudaSession {
    CudaRun c;
    void *pinned;                 /* the host buffer page-locked by rt_cuda_session_pin */
    cudaStream_t ks, cs;          /* kernels, copies */
    cudaEvent_t kev[RT_CUDA_BANDS], cev[RT_CUDA_BANDS];
    int nev;                      /* event pairs created */
    unsigned long long queued, kernels_done, copies_done;
};

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
    int rc = cuda_open(c, err) || cuda_plan(c, err);
    c->plan.center = 0; /* bands are raster runs of tiles: no centre order */
    if (rc || cuda_upload(c, err))
        goto fail;
    RT_CUDA_CHECK(cudaDeviceSynchronize()); /* (the streams below do not wait for the legacy stream's poison) */
    RT_CUDA_CHECK(cudaStreamCreateWithFlags(&s->ks, cudaStreamNonBlocking));
    RT_CUDA_CHECK(cudaStreamCreateWithFlags(&s->cs, cudaStreamNonBlocking));
    for (; s->nev < RT_CUDA_BANDS; s->nev++) {
        RT_CUDA_CHECK(cudaEventCreateWithFlags(&s->kev[s->nev], cudaEventDisableTiming));
        if (cudaEventCreateWithFlags(&s->cev[s->nev], cudaEventDisableTiming) != cudaSuccess) {
            cudaEventDestroy(s->kev[s->nev]);
            RT_CUDA_CHECK(cudaGetLastError());
        }
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
    const int rows = (int)(c->g.ntiles / (uint32_t)c->g.tiles_x);
    /* the pixels resident at once over a tile row's pixels, rounded up */
    const double resident = (double)c->blocks_per_sm * (double)c->prop.multiProcessorCount *
                            (double)(c->plan.pairs ? c->plan.threads / 2 : c->plan.threads);
    const double per_row = (double)c->g.tiles_x * (double)c->g.tile_items;
    const double wr = resident / per_row;
    *row_h = c->g.by;
    *wave_rows = wr >= rows ? rows : wr < 1.0 ? 1 : (int)wr + (wr > (int)wr);
    return rows;
}

void rt_cuda_session_pin(RtCudaSession *s, void *host, size_t bytes)
{
    rt_cuda_session_unpin(s);
    if (cudaHostRegister(host, bytes, cudaHostRegisterDefault) == cudaSuccess)
        s->pinned = host;
    else
        cudaGetLastError(); /* (not sticky: the copies go on from pageable memory) */
}

void rt_cuda_session_unpin(RtCudaSession *s)
{
    if (s->pinned)
        cudaHostUnregister(s->pinned);
    s->pinned = NULL;
}

int rt_cuda_session_frame(RtCudaSession *s, RtError *err)
{
    CudaRun *c = &s->c;
    RT_CUDA_CHECK(cudaMemsetAsync(c->arena + c->parts[P_COUNTERS].offset, 0, c->parts[P_COUNTERS].bytes, s->ks));
    return 0;
fail:
    return -1;
}

int rt_cuda_session_band(RtCudaSession *s, int r0, int r1, float *rgb, RtError *err)
{
    CudaRun *c = &s->c;
    unsigned char *a = c->arena;
    RtCudaGrid g = c->g;
    const unsigned slot = (unsigned)(s->queued % RT_CUDA_BANDS);
    const uint32_t tiles = (uint32_t)(r1 - r0) * (uint32_t)g.tiles_x;
    g.units = NULL;
    g.first_tile = (uint32_t)r0 * (uint32_t)g.tiles_x;
    g.ntiles = tiles;
    g.total_items = tiles * g.tile_items;
    const int nblocks = (int)(g.persistent && (uint32_t)c->nblocks < tiles ? (uint32_t)c->nblocks : tiles);
    const int y0 = r0 * g.by, y1 = r1 * g.by < c->h ? r1 * g.by : c->h;
    const size_t off = (size_t)y0 * (size_t)c->w * 3, n = (size_t)(y1 - y0) * (size_t)c->w * 3;
    if (s->queued - s->copies_done >= RT_CUDA_BANDS)
        return rt_fail(err, "cuda: more than %d bands in flight", RT_CUDA_BANDS);
    RT_CUDA_CHECK(cudaMemsetAsync(a + c->parts[P_WORK].offset, 0, c->parts[P_WORK].bytes, s->ks));
    if (cuda_kernel(c, &g, nblocks, s->ks, err))
        return -1;
    RT_CUDA_CHECK(cudaEventRecord(s->kev[slot], s->ks));
    RT_CUDA_CHECK(cudaStreamWaitEvent(s->cs, s->kev[slot], 0));
    RT_CUDA_CHECK(cudaMemcpyAsync(rgb + off, (float *)(a + c->parts[P_IMAGE].offset) + off, n * sizeof(float),
                                  cudaMemcpyDeviceToHost, s->cs));
    RT_CUDA_CHECK(cudaEventRecord(s->cev[slot], s->cs));
    s->queued++;
    return 0;
fail:
    return -1;
}

int rt_cuda_session_kernels(RtCudaSession *s, int keep, RtError *err)
{
    if (s->queued - s->kernels_done > (unsigned long long)keep) {
        const unsigned long long last = s->queued - (unsigned long long)keep - 1;
        RT_CUDA_CHECK(cudaEventSynchronize(s->kev[last % RT_CUDA_BANDS]));
        s->kernels_done = last + 1;
    }
    return 0;
fail:
    return -1;
}

int rt_cuda_session_ready(RtCudaSession *s, int wait, RtError *err)
{
    int n = 0;
    for (; s->copies_done < s->queued; s->copies_done++, n++) {
        cudaEvent_t e = s->cev[s->copies_done % RT_CUDA_BANDS];
        if (wait) {
            RT_CUDA_CHECK(cudaEventSynchronize(e));
        } else {
            cudaError_t q = cudaEventQuery(e);
            if (q == cudaErrorNotReady)
                break;
            RT_CUDA_CHECK(q);
        }
    }
    if (s->kernels_done < s->copies_done)
        s->kernels_done = s->copies_done;
    return n;
fail:
    return -1;
}

int rt_cuda_session_counters(RtCudaSession *s, RtCounters *cnt, RtError *err)
{
    RT_CUDA_CHECK(cudaStreamSynchronize(s->ks));
    return cuda_counters(&s->c, cnt, err);
fail:
    return -1;
}

const char *rt_cuda_session_gpu(const RtCudaSession *s) { return s->c.gpu_at; }

void rt_cuda_session_keys(const RtCudaSession *s, char *buf, size_t size) { cuda_plan_keys(&s->c, buf, size); }

void rt_cuda_session_close(RtCudaSession *s)
{
    if (!s)
        return;
    rt_cuda_session_unpin(s);
    for (int i = 0; i < s->nev; i++) {
        cudaEventDestroy(s->kev[i]);
        cudaEventDestroy(s->cev[i]);
    }
    if (s->ks)
        cudaStreamDestroy(s->ks);
    if (s->cs)
        cudaStreamDestroy(s->cs);
    cuda_release(&s->c);
    free(s);
}

extern "C" {
extern const RtBackend rt_backend_cuda;
/* times its own runs: the scene stays on the device between launches */
const RtBackend rt_backend_cuda = {"cuda", NULL, NULL, render_cuda, NULL, NULL, 1, cuda_prewarm, 1};
}
