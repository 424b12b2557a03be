/* cpu_tiles.h - the multi-threaded tile loop shared by the OpenMP backend and
 * the MPI backend's ranks (hybrid MPI+OpenMP). Internal to renderer/backends.
 *
 * Header-only on purpose: the library is compiled with the OpenMP flags
 * whenever OpenMP was found (renderer/meson.build adds omp_dep to every
 * source), so mpi.c gets the same threaded loop by including this file, and
 * in a build without OpenMP the pragmas vanish and the loops run on one
 * thread. One loop, two callers: neither backend shades or tiles differently.
 *
 * Every loop calls rt_cpu_render_pixel / rt_cpu_render_tile (cpu_trace.h:
 * core/rt_path_tmpl.h's pixel and tile with the CPU traversal inlined); a
 * pixel's colour and counters depend only on (scene, i, j), so any split of
 * the image over threads or ranks gives the serial image bit for bit and the
 * same integer counter sums. */
#ifndef RT_CPU_TILES_H
#define RT_CPU_TILES_H

#include <stdlib.h>
#include <string.h>

#include "rt.h"
#include "cpu_trace.h"
#ifdef _OPENMP
#include <omp.h>
#endif

#define RT_CPU_MAX_CPUS 1024

/* One worker thread's private state. Threads only ever write their own
 * slot, and each slot starts on its own 128-byte boundary (two cache lines:
 * Intel's adjacent-line prefetcher pairs lines), so no two threads share a
 * line: counters merged at the end, never atomics in the pixel loop. */
typedef struct RtCpuSlot {
    RtCounters cnt;                         /* work counters of this thread (40 bytes) */
    uint64_t cpus[RT_CPU_MAX_CPUS / 64];    /* bitmask of CPUs it ran on (128 bytes) */
} RtCpuSlot;

typedef struct RtCpuPool {
    int nthreads;
    size_t stride;   /* bytes between slots: sizeof(RtCpuSlot) rounded up to 128 */
    unsigned char *mem;
} RtCpuPool;

static inline RtCpuSlot *rt_cpu_slot(const RtCpuPool *p, int t)
{
    return (RtCpuSlot *)(void *)(p->mem + (size_t)t * p->stride);
}

/* Threads to use: --threads (requested > 0), else OMP_NUM_THREADS if set,
 * else `fallback` (<= 0: every CPU this process may run on, which is what
 * omp_get_max_threads() reports when OMP_NUM_THREADS is unset). */
static inline int rt_cpu_threads(int requested, int fallback)
{
    if (requested > 0)
        return requested;
    const char *env = getenv("OMP_NUM_THREADS");
#ifdef _OPENMP
    if (env && *env)
        return omp_get_max_threads();
    return fallback > 0 ? fallback : omp_get_max_threads();
#else
    (void)env;
    (void)fallback;
    return 1;
#endif
}

static inline int rt_cpu_pool_init(RtCpuPool *p, int nthreads, RtError *err)
{
    p->nthreads = nthreads;
    p->stride = (sizeof(RtCpuSlot) + 127) / 128 * 128;
    p->mem = aligned_alloc(128, p->stride * (size_t)nthreads);
    if (!p->mem)
        return rt_fail(err, "out of memory for %d worker threads", nthreads);
    memset(p->mem, 0, p->stride * (size_t)nthreads);
#ifdef _OPENMP
    /* The team size is exactly what was asked for, never trimmed by the
     * runtime under load: a scaling study must run T threads when it says T. */
    omp_set_dynamic(0);
    /* Start the team now so that thread creation is not timed as pixel work
     * (libgomp keeps the threads for the next parallel region). */
#pragma omp parallel num_threads(nthreads)
    {
        rt_cpu_slot(p, omp_get_thread_num())->cnt.primary_rays = 0;
    }
#endif
    return 0;
}

static inline void rt_cpu_pool_free(RtCpuPool *p)
{
    free(p->mem);
    p->mem = NULL;
}

static inline int rt_cpu_thread_id(void)
{
#ifdef _OPENMP
    return omp_get_thread_num();
#else
    return 0;
#endif
}

static inline void rt_cpu_note(RtCpuSlot *s)
{
    int cpu = rt_current_cpu();
    if (cpu >= 0 && cpu < RT_CPU_MAX_CPUS)
        s->cpus[cpu / 64] |= 1ull << (cpu % 64);
}

/* The rectangle of tile `index` when [rx0,rx1) x [ry0,ry1) is cut into
 * tw x th tiles, row-major (rt_tile_rect for a sub-region: MPI row blocks). */
static inline void rt_region_tile(int rx0, int ry0, int rx1, int ry1, int tw, int th, int index, int *x0, int *y0,
                                  int *x1, int *y1)
{
    rt_tile_rect(rx1 - rx0, ry1 - ry0, tw, th, index, x0, y0, x1, y1);
    *x0 += rx0;
    *x1 += rx0;
    *y0 += ry0;
    *y1 += ry0;
}

/* Renders tiles [first, first + count) of the tw x th tiling of the region,
 * handed out one at a time to whichever thread is free (dynamic): ray cost
 * varies by orders of magnitude across an image (sky vs. a glass dragon), so
 * a static split leaves threads idle. rgb is the full image (stride = width). */
static inline void rt_cpu_render_tiles(RtCpuPool *p, const RtSceneView *v, int rx0, int ry0, int rx1, int ry1,
                                       int tw, int th, int first, int count, float *rgb, RtProgressFn progress,
                                       void *progress_ctx)
{
    int done = 0; /* tiles finished, for progress only */
#pragma omp parallel num_threads(p->nthreads)
    {
        int tid = rt_cpu_thread_id();
        RtCpuSlot *slot = rt_cpu_slot(p, tid);
        RtCounters cnt; /* on this thread's stack: the hot loop writes nothing shared */
        memset(&cnt, 0, sizeof cnt);
        rt_cpu_note(slot);
#pragma omp for schedule(dynamic, 1) nowait
        for (int t = first; t < first + count; t++) {
            int x0, y0, x1, y1;
            rt_region_tile(rx0, ry0, rx1, ry1, tw, th, t, &x0, &y0, &x1, &y1);
            rt_cpu_render_tile(v, x0, y0, x1, y1, rgb, &cnt);
            rt_cpu_note(slot);
            if (progress) {
                /* One atomic add per tile (hundreds of pixels); only thread 0
                 * prints, so no thread ever waits for the terminal. */
                int d;
#pragma omp atomic capture
                d = ++done;
                if (tid == 0)
                    progress(progress_ctx, (uint64_t)d, (uint64_t)count);
            }
        }
        rt_counters_add(&slot->cnt, &cnt);
    }
    if (progress)
        progress(progress_ctx, (uint64_t)count, (uint64_t)count);
}

/* The report's OpenMP scheme: `collapse(2)` over the pixel loops of the
 * region, default static schedule (equal contiguous pixel ranges). */
static inline void rt_cpu_render_pixels(RtCpuPool *p, const RtSceneView *v, int x0, int y0, int x1, int y1,
                                        float *rgb)
{
#pragma omp parallel num_threads(p->nthreads)
    {
        RtCpuSlot *slot = rt_cpu_slot(p, rt_cpu_thread_id());
        RtCounters cnt;
        memset(&cnt, 0, sizeof cnt);
        rt_cpu_note(slot);
#pragma omp for collapse(2) schedule(static) nowait
        for (int j = y0; j < y1; j++)
            for (int i = x0; i < x1; i++)
                rt_cpu_render_pixel(v, i, j, rgb, &cnt);
        rt_cpu_note(slot);
        rt_counters_add(&slot->cnt, &cnt);
    }
}

/* Sums the threads' counters into *sum and appends their CPUs to `cores`
 * (sorted, unique, "0,1,5"). */
static inline void rt_cpu_pool_merge(const RtCpuPool *p, RtCounters *sum, char *cores, size_t size)
{
    memset(sum, 0, sizeof *sum);
    for (int t = 0; t < p->nthreads; t++) {
        const RtCpuSlot *s = rt_cpu_slot(p, t);
        rt_counters_add(sum, &s->cnt);
        for (int c = 0; c < RT_CPU_MAX_CPUS; c++)
            if (s->cpus[c / 64] >> (c % 64) & 1)
                rt_cores_note(cores, size, c);
    }
}

#endif
