/* openmp.c - the OpenMP backend: the shared tile loop (cpu_tiles.h) on T
 * threads of one process.
 *
 *   --schedule tiles  (default) tiles of --tile WxH (default RT_OMP_TILE,
 *                     backends.h) handed out dynamically, then backed up
 *                     (cpu_tiles.h): the load-balanced scheme.
 *   --schedule pixels the report's scheme: `collapse(2)` static over pixels.
 *
 * Threads: --threads N, else OMP_NUM_THREADS, else every CPU of the process's
 * affinity mask. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "backends.h" /* RT_OMP_TILE */
#include "cpu_tiles.h"
#include "rt.h"

static int render_openmp(const RtRenderJob *job, RtRenderOut *out, RtError *err)
{
    const RtSceneView *v = &job->view;
    int w = v->cam.width, h = v->cam.height;
    int tw = job->tile_w > 0 ? job->tile_w : RT_OMP_TILE, th = job->tile_h > 0 ? job->tile_h : RT_OMP_TILE;
    const int pixels = job->schedule == RT_SCHED_PIXELS;
    const int64_t nstrips = rt_strip_count(w, h, tw, th);
    RtCpuPool pool;
    if (rt_cpu_pool_init(&pool, rt_cpu_threads(job->threads, 0), pixels ? 0 : tw, th, w, h, err) != 0)
        return -1;
    uint32_t *state = pixels ? NULL : calloc((size_t)rt_board_words(w, h, tw, th), sizeof *state);
    if (!pixels && !state) {
        rt_cpu_pool_free(&pool);
        return rt_fail(err, "out of memory for %lld tile rows", (long long)nstrips);
    }
    int64_t done = 0, end_ns = 0;
    RtTileBoard board = {state, &done, &end_ns, rt_strip_total(w, h, tw)};
    RtTileRun run = {.v = v, .rx1 = w, .ry1 = h, .tw = tw, .th = th, .count = nstrips, .scan_count = nstrips,
                     .scan_slots = 1, .rgb = out->rgb, .board = &board, .progress = job->progress,
                     .progress_ctx = job->progress_ctx, .rescue = pool.nthreads <= pool.cpus};

    const int64_t t0 = rt_now_ns();
    if (pixels)
        rt_cpu_render_pixels(&pool, v, 0, 0, w, h, out->rgb);
    else
        rt_cpu_render_tiles(&pool, &run);
    const int64_t t1 = rt_now_ns();
    /* render_ms: from the team's start of work to the image complete, when
     * the last tile's pixels are in it, as an MPI frame runs from the
     * starting barrier. libgomp releases a team only once every thread of
     * the last one is back in its dock, so one thread held off its core
     * holds the region's start (fork_ms, measured here at 1-6 ms on a
     * 64-core virtual machine). join_ms: from the call to the region's end,
     * which also waits for threads still busy with a tile already finished. */
    const int64_t start = pixels ? t0 : rt_cpu_pool_start(&pool);
    out->render_ms = ((pixels ? t1 : end_ns) - start) * 1e-6;
    if (job->progress && pixels)
        job->progress(job->progress_ctx, 1, 1); /* the report's static loop has no natural progress points */

    out->render_ms_min = out->render_ms;
    rt_cpu_pool_merge(&pool, &out->counters, out->cores, sizeof out->cores);
    out->threads_used = pool.nthreads;
    out->ranks_used = 1;
    out->is_root = 1;
    uint64_t runs, won;
    rt_cpu_pool_backups(&pool, &runs, &won);
    if (pixels)
        snprintf(out->extra, sizeof out->extra, " schedule=pixels");
    else {
        snprintf(out->extra, sizeof out->extra,
                 " schedule=tiles fork_ms=%.3f join_ms=%.3f backups=%llu backups_won=%llu", (start - t0) * 1e-6,
                 (t1 - t0) * 1e-6, (unsigned long long)runs, (unsigned long long)won);
        /* where each thread's frame went: a late start is a thread the
         * system woke late; an early end, one that found no tile left */
        rt_cpu_pool_times(&pool, 0, t0, "thread_start_ms", out->extra, sizeof out->extra);
        rt_cpu_pool_times(&pool, 1, t0, "thread_work_ms", out->extra, sizeof out->extra);
    }
    rt_cpu_pool_free(&pool);
    free(state);
    return 0;
}

const RtBackend rt_backend_openmp = {"openmp", NULL, NULL, render_openmp, NULL, NULL, 0, NULL, 0, RT_OMP_TILE, NULL, NULL};
