/* openmp.c - the OpenMP backend: the shared tile loop (cpu_tiles.h) on T
 * threads of one process.
 *
 *   --schedule tiles  (default) tiles of --tile WxH (default RT_OMP_TILE,
 *                     backends.h) handed out dynamically: the load-balanced
 *                     scheme.
 *   --schedule pixels the report's scheme: `collapse(2)` static over pixels.
 *
 * Threads: --threads N, else OMP_NUM_THREADS, else every CPU of the process's
 * affinity mask. */
#include <stdio.h>
#include <string.h>

#include "backends.h" /* RT_OMP_TILE */
#include "cpu_tiles.h"
#include "rt.h"

static int render_openmp(const RtRenderJob *job, RtRenderOut *out, RtError *err)
{
    const RtSceneView *v = &job->view;
    int w = v->cam.width, h = v->cam.height;
    int tw = job->tile_w > 0 ? job->tile_w : RT_OMP_TILE, th = job->tile_h > 0 ? job->tile_h : RT_OMP_TILE;
    RtCpuPool pool;
    if (rt_cpu_pool_init(&pool, rt_cpu_threads(job->threads, 0), err) != 0)
        return -1;

    double t0 = rt_now_ms();
    if (job->schedule == RT_SCHED_PIXELS)
        rt_cpu_render_pixels(&pool, v, 0, 0, w, h, out->rgb);
    else
        rt_cpu_render_tiles(&pool, v, 0, 0, w, h, tw, th, 0, rt_tile_count(w, h, tw, th), out->rgb, job->progress,
                            job->progress_ctx);
    out->render_ms = rt_now_ms() - t0;
    if (job->progress && job->schedule == RT_SCHED_PIXELS)
        job->progress(job->progress_ctx, 1, 1); /* the report's static loop has no natural progress points */

    out->render_ms_min = out->render_ms;
    rt_cpu_pool_merge(&pool, &out->counters, out->cores, sizeof out->cores);
    out->threads_used = pool.nthreads;
    out->ranks_used = 1;
    out->is_root = 1;
    snprintf(out->extra, sizeof out->extra, " schedule=%s",
             job->schedule == RT_SCHED_PIXELS ? "pixels" : "tiles");
    rt_cpu_pool_free(&pool);
    return 0;
}

const RtBackend rt_backend_openmp = {"openmp", NULL, NULL, render_openmp, NULL, NULL, 0, NULL, 0, RT_OMP_TILE, NULL};
