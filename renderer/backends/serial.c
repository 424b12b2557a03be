/* serial.c - the reference backend: one thread walks the tiles in order.
 * Every other backend must reproduce its image and counters (CPU backends
 * bit-identically). */
#include <string.h>

#include "backends.h"
#include "rt.h"
#include "cpu_trace.h"

static int render_serial(const RtRenderJob *job, RtRenderOut *out, RtError *err)
{
    (void)err;
    const RtSceneView *v = &job->view;
    int w = v->cam.width, h = v->cam.height;
    int tw = job->tile_w > 0 ? job->tile_w : RT_SERIAL_TILE, th = job->tile_h > 0 ? job->tile_h : RT_SERIAL_TILE;
    int ntiles = rt_tile_count(w, h, tw, th);
    RtCounters cnt;
    memset(&cnt, 0, sizeof cnt);
    double t0 = rt_now_ms();
    for (int t = 0; t < ntiles; t++) {
        int x0, y0, x1, y1;
        rt_tile_rect(w, h, tw, th, t, &x0, &y0, &x1, &y1);
        rt_cpu_render_tile(v, x0, y0, x1, y1, out->rgb + 3 * ((size_t)y0 * (size_t)w + (size_t)x0), 3 * (size_t)w,
                           &cnt);
        if (job->progress)
            job->progress(job->progress_ctx, (uint64_t)t + 1, (uint64_t)ntiles);
    }
    out->render_ms = rt_now_ms() - t0;
    out->render_ms_min = out->render_ms;
    out->counters = cnt;
    out->threads_used = 1;
    out->ranks_used = 1;
    out->is_root = 1;
    rt_cores_note(out->cores, sizeof out->cores, rt_current_cpu());
    return 0;
}

const RtBackend rt_backend_serial = {"serial", NULL, NULL, render_serial, NULL, NULL, 0, NULL, 0, RT_SERIAL_TILE, NULL, NULL};
