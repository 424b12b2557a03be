/* warpmodel.c - a CPU model of how the CUDA kernel's warps spend their time
 * on a scene, for deciding what to try on the GPU before building it
 * (experiments/README.md).
 *
 *   warpmodel [-b BXxBY] [-r WxH] [-w TEST_WEIGHT] [-c SHADE_COST] SCENE
 *
 * Every pixel's rays are traced as rt_trace_path traces them (closest hits
 * on the 4-wide tree, a shadow ray per light that casts one, the reflected
 * and refracted children), and each ray's cost is counted in steps: node
 * visits + TEST_WEIGHT x primitive tests (default 0.5: one pass of the GPU's
 * leaf loop tests two). The pixels are grouped into warps as the grid
 * schedule makes them (blocks of BXxBY threads, default 16x8; a warp is 32
 * consecutive threads of a block). The model then gives each warp's time
 * under several ways of running its lanes:
 *   phased   - as the kernel runs now: every lane's closest hit of bounce k,
 *              then every lane's shadow ray to light 0, to light 1, ...; each
 *              phase lasts as long as its slowest lane, plus SHADE_COST
 *              steps (default 1) of shading;
 *   busiest  - a lane goes on to its pixel's next ray at once, for free: the
 *              warp takes as long as its busiest lane (the floor of refill);
 *   refill T - as busiest, but a pass in which lanes take their next ray
 *              costs SHADE_COST, and lanes wait until T of them are done
 *              (or none is busy);
 *   pairs f  - phased, with a hit's shadow rays traced two at a time in one
 *              lane, the second costing f of its steps;
 *   pool f   - phased, with each bounce's shadow rays of the whole warp
 *              handed to whichever lane is free, a pass with hand-outs
 *              costing f.
 * It prints the slowest warp (what a tail-bound frame waits on) and the sum
 * over warps (the work), each also as a ratio to phased. A model: it knows
 * nothing of registers, divergence inside a step or memory. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* The CPU's leaf vote: the model counts lanes itself (wm_trace). */
#define RT_WIDE_LEAF_VOTE(has_leaf, any) (has_leaf)
#include "core/rt_traverse.h"
#include "rt.h"

#define WM_MAX_RAYS 96 /* per pixel: more are counted in the last one */

typedef struct WmRay {
    int bounce; /* index of the closest-hit ray of the pixel that led to it */
    int light;  /* -1: the closest-hit ray itself; else the light */
    double cost;
} WmRay;

typedef struct WmPixel {
    int n;     /* entries in ray[] */
    long rays; /* rays traced (n, unless more than WM_MAX_RAYS) */
    WmRay ray[WM_MAX_RAYS];
} WmPixel;

static double test_weight = 0.5, shade_cost = 1.0;

static void wm_add(WmPixel *px, int bounce, int light, const RtCounters *before, const RtCounters *after)
{
    const double c = (double)(after->node_visits - before->node_visits) +
                     test_weight * (double)(after->prim_tests - before->prim_tests);
    px->rays++;
    if (px->n == WM_MAX_RAYS) {
        px->ray[px->n - 1].cost += c;
        return;
    }
    px->ray[px->n].bounce = bounce;
    px->ray[px->n].light = light;
    px->ray[px->n].cost = c;
    px->n++;
}

/* rt_trace_path traces every ray through RT_PATH_TRACE: here, the 4-wide
 * traversal as the default kernel runs it, with each ray's cost recorded
 * into the pixel being traced (its closest-hit rays numbered as bounces). */
static WmPixel *wm_pixel;
static int wm_bounce;

static int wm_trace(const RtSceneView *s, RtVec3 o, RtVec3 d, float tmax, int any, RtHit *hit, RtCounters *cnt,
                    int light)
{
    const RtCounters c0 = *cnt;
    const int found = rt_trace_ray_wide(s, o, d, tmax, any, hit, cnt);
    wm_add(wm_pixel, light < 0 ? wm_bounce++ : wm_bounce - 1, light, &c0, cnt);
    return found;
}

#define RT_PATH_TRACE(s, o, d, tmax, any, hit, cnt, light) wm_trace(s, o, d, tmax, any, hit, cnt, light)
#define RT_PATH_NAME(f) f
#define RT_PATH_FN static inline
#include "core/rt_path_tmpl.h"

static void wm_trace_pixel(const RtSceneView *s, RtRay primary, WmPixel *px)
{
    RtCounters cnt;
    memset(&cnt, 0, sizeof cnt);
    px->n = 0;
    px->rays = 0;
    wm_pixel = px;
    wm_bounce = 0;
    rt_trace_path(s, primary, RT_ANY_HIT_SLOT, &cnt); /* shadow rays as the default kernel's */
}

/* One warp's lanes (pixels) under the ways of running them above. */
typedef struct WmWarp {
    WmPixel *lane[32];
    int n;
} WmWarp;

static double wm_pixel_sum(const WmPixel *p)
{
    double s = 0.0;
    for (int r = 0; r < p->n; r++)
        s += p->ray[r].cost;
    return s;
}

static int wm_max_bounce(const WmWarp *w)
{
    int mb = -1;
    for (int l = 0; l < w->n; l++)
        for (int r = 0; r < w->lane[l]->n; r++)
            if (w->lane[l]->ray[r].bounce > mb)
                mb = w->lane[l]->ray[r].bounce;
    return mb;
}

/* Phase (bounce, light)'s slowest lane; *any: some lane has such a ray. */
static double wm_phase_max(const WmWarp *w, int bounce, int light, int *any)
{
    double mx = 0.0;
    *any = 0;
    for (int l = 0; l < w->n; l++)
        for (int r = 0; r < w->lane[l]->n; r++) {
            const WmRay *y = &w->lane[l]->ray[r];
            if (y->bounce == bounce && y->light == light) {
                *any = 1;
                if (y->cost > mx)
                    mx = y->cost;
            }
        }
    return mx;
}

static double wm_phased(const WmWarp *w, int nlights)
{
    const int mb = wm_max_bounce(w);
    double t = 0.0;
    for (int b = 0; b <= mb; b++)
        for (int li = -1; li < nlights; li++) {
            int any;
            const double mx = wm_phase_max(w, b, li, &any);
            if (any)
                t += mx + shade_cost;
        }
    return t;
}

static double wm_busiest(const WmWarp *w)
{
    double mx = 0.0;
    for (int l = 0; l < w->n; l++) {
        const double s = wm_pixel_sum(w->lane[l]);
        if (s > mx)
            mx = s;
    }
    return mx;
}

/* Passes of one step over n queues of costs (lane l: q[l][0..len[l])):
 * a lane whose ray is done takes its next one in a pass that costs
 * take_cost, held back until `threshold` lanes are done or none is busy. */
static double wm_run_queues(double *const *q, const int *len, int n, int threshold, double take_cost)
{
    int idx[32];
    double rem[32];
    for (int l = 0; l < n; l++) {
        idx[l] = 0;
        rem[l] = len[l] ? q[l][0] : 0.0;
    }
    double t = 0.0;
    for (;;) {
        int busy = 0, done = 0;
        for (int l = 0; l < n; l++) {
            if (idx[l] >= len[l])
                continue;
            if (rem[l] > 0.0)
                busy++;
            else
                done++;
        }
        if (!busy && !done)
            return t;
        if (done && (done >= threshold || !busy)) {
            t += take_cost;
            for (int l = 0; l < n; l++)
                if (idx[l] < len[l] && rem[l] <= 0.0 && ++idx[l] < len[l])
                    rem[l] = q[l][idx[l]];
            continue;
        }
        double step = 1.0;
        for (int l = 0; l < n; l++)
            if (idx[l] < len[l] && rem[l] > 0.0 && rem[l] < step)
                step = rem[l];
        t += step;
        for (int l = 0; l < n; l++)
            if (idx[l] < len[l] && rem[l] > 0.0)
                rem[l] -= step;
    }
}

static double wm_refill(const WmWarp *w, int threshold)
{
    double costs[32][WM_MAX_RAYS];
    double *q[32];
    int len[32];
    for (int l = 0; l < w->n; l++) {
        q[l] = costs[l];
        len[l] = w->lane[l]->n;
        for (int r = 0; r < len[l]; r++)
            costs[l][r] = w->lane[l]->ray[r].cost;
    }
    return wm_run_queues(q, len, w->n, threshold, shade_cost);
}

/* A bounce's shadow rays traced two at a time per lane: its slowest lane. */
static double wm_shadow_pairs(const WmWarp *w, int bounce, double f)
{
    double mx = 0.0;
    for (int l = 0; l < w->n; l++) {
        double sh[WM_MAX_RAYS], t = 0.0;
        int ns = 0;
        for (int r = 0; r < w->lane[l]->n; r++)
            if (w->lane[l]->ray[r].bounce == bounce && w->lane[l]->ray[r].light >= 0)
                sh[ns++] = w->lane[l]->ray[r].cost;
        for (int k = 0; k < ns; k += 2) {
            if (k + 1 == ns) {
                t += sh[k];
                break;
            }
            const double a = sh[k] > sh[k + 1] ? sh[k] : sh[k + 1], b = sh[k] + sh[k + 1] - a;
            t += a + f * b;
        }
        if (t > mx)
            mx = t;
    }
    return mx;
}

static double wm_shadow_pool(const WmWarp *w, int bounce, int nlights, double f)
{
    /* the warp's shadow rays queued light by light, lane by lane, and
     * handed out to whichever of the 32 lanes is free */
    static double pool[32 * WM_MAX_RAYS];
    int n = 0;
    for (int li = 0; li < nlights; li++)
        for (int l = 0; l < w->n; l++)
            for (int r = 0; r < w->lane[l]->n; r++) {
                const WmRay *y = &w->lane[l]->ray[r];
                if (y->bounce == bounce && y->light == li)
                    pool[n++] = y->cost;
            }
    double rem[32];
    int next = 0;
    for (int l = 0; l < 32; l++)
        rem[l] = 0.0;
    double t = 0.0;
    for (;;) {
        int took = 0, busy = 0;
        for (int l = 0; l < 32 && next < n; l++)
            if (rem[l] <= 0.0) {
                rem[l] = pool[next++];
                took = 1;
            }
        if (took)
            t += f;
        double step = 1.0;
        for (int l = 0; l < 32; l++)
            if (rem[l] > 0.0) {
                busy++;
                if (rem[l] < step)
                    step = rem[l];
            }
        if (!busy)
            return t;
        t += step;
        for (int l = 0; l < 32; l++)
            if (rem[l] > 0.0)
                rem[l] -= step;
    }
}

/* Phased, with each bounce's shadow rays as pairs (pool = 0) or a pool. */
static double wm_phased_shadows(const WmWarp *w, int nlights, int pool, double f)
{
    const int mb = wm_max_bounce(w);
    double t = 0.0;
    for (int b = 0; b <= mb; b++) {
        int any, anys = 0;
        const double mc = wm_phase_max(w, b, -1, &any);
        if (any)
            t += mc + shade_cost;
        for (int li = 0; li < nlights && !anys; li++)
            wm_phase_max(w, b, li, &anys);
        if (anys)
            t += (pool ? wm_shadow_pool(w, b, nlights, f) : wm_shadow_pairs(w, b, f)) + shade_cost;
    }
    return t;
}

enum { WM_PHASED, WM_BUSIEST, WM_REFILL1, WM_REFILL4, WM_REFILL8, WM_REFILL16, WM_PAIRS0, WM_PAIRS25, WM_PAIRS50,
       WM_POOL0, WM_POOL25, WM_POOL50, WM_NMODELS };
static const char *const wm_names[WM_NMODELS] = {
    "phased (now)", "busiest lane", "refill T=1", "refill T=4", "refill T=8", "refill T=16", "pairs f=0",
    "pairs f=0.25", "pairs f=0.5", "pool f=0", "pool f=0.25", "pool f=0.5"};

static int usage(const char *why)
{
    fprintf(stderr, "warpmodel: %s\nusage: warpmodel [-b BXxBY] [-r WxH] [-w TEST_WEIGHT] [-c SHADE_COST] SCENE\n",
            why);
    return 2;
}

static int parse_weight(const char *s, double *out)
{
    char *e;
    const double v = strtod(s, &e);
    if (e == s || *e || !(v >= 0.0 && v <= 100.0))
        return 0;
    *out = v;
    return 1;
}

int main(int argc, char **argv)
{
    int bx = 16, by = 8, rw = 0, rh = 0, opt;
    while ((opt = getopt(argc, argv, "b:r:w:c:")) != -1) {
        char why[160];
        switch (opt) {
        case 'b':
            if (rt_parse_wxh(optarg, 1024, &bx, &by) != 0 || bx * by > 1024 || (bx * by) % 32 != 0) {
                snprintf(why, sizeof why, "-b %s: expected BXxBY, a multiple of 32 threads up to 1024", optarg);
                return usage(why);
            }
            break;
        case 'r':
            if (rt_parse_wxh(optarg, 32768, &rw, &rh) != 0) {
                snprintf(why, sizeof why, "-r %s: expected WxH with 1 <= W,H <= 32768", optarg);
                return usage(why);
            }
            break;
        case 'w':
        case 'c':
            if (!parse_weight(optarg, opt == 'w' ? &test_weight : &shade_cost)) {
                snprintf(why, sizeof why, "-%c %s: expected a number from 0 to 100", opt, optarg);
                return usage(why);
            }
            break;
        default:
            return usage("unknown option");
        }
    }
    if (optind != argc - 1)
        return usage("expected one scene file");
    const char *path = argv[optind];

    RtScene sc;
    RtAccel acc;
    RtCamera cam;
    RtError err;
    if (rt_scene_load(path, &sc, NULL, NULL, &err) != 0) {
        fprintf(stderr, "warpmodel: %s\n", err.msg);
        return 1;
    }
    if (rw) {
        sc.settings.width = rw;
        sc.settings.height = rh;
    }
    if (rt_scene_camera(&sc, &cam, &err) != 0 || rt_accel_build(&sc, RT_ACCEL_BVH, &acc, &err) != 0) {
        fprintf(stderr, "warpmodel: %s\n", err.msg);
        rt_scene_free(&sc);
        return 1;
    }
    RtSceneView v = rt_scene_view(&sc, &acc, &cam);
    const int W = cam.width, H = cam.height;
    /* one block's pixels at a time (a pixel's record is 1.5 KB) */
    WmPixel *px = malloc((size_t)bx * (size_t)by * sizeof *px);
    if (!px) {
        fprintf(stderr, "warpmodel: out of memory for a block of %dx%d pixels\n", bx, by);
        rt_accel_free(&acc);
        rt_scene_free(&sc);
        return 1;
    }
    double slowest[WM_NMODELS] = {0}, sum[WM_NMODELS] = {0}, lane_steps = 0.0;
    long warps = 0, rays = 0;
    const int nbx = (W + bx - 1) / bx, nby = (H + by - 1) / by;
    for (int blk = 0; blk < nbx * nby; blk++)
        for (int wi = 0; wi < bx * by / 32; wi++) {
            WmWarp w;
            w.n = 0;
            for (int t = 0; t < 32; t++) {
                const int tid = wi * 32 + t, x = (blk % nbx) * bx + tid % bx, y = (blk / nbx) * by + tid / bx;
                if (x >= W || y >= H)
                    continue;
                WmPixel *p = &px[tid];
                wm_trace_pixel(&v, rt_camera_ray(&cam, x, y), p);
                rays += p->rays;
                w.lane[w.n++] = p;
            }
            if (!w.n)
                continue;
            double t[WM_NMODELS];
            t[WM_PHASED] = wm_phased(&w, (int)v.nlights);
            t[WM_BUSIEST] = wm_busiest(&w);
            t[WM_REFILL1] = wm_refill(&w, 1);
            t[WM_REFILL4] = wm_refill(&w, 4);
            t[WM_REFILL8] = wm_refill(&w, 8);
            t[WM_REFILL16] = wm_refill(&w, 16);
            t[WM_PAIRS0] = wm_phased_shadows(&w, (int)v.nlights, 0, 0.0);
            t[WM_PAIRS25] = wm_phased_shadows(&w, (int)v.nlights, 0, 0.25);
            t[WM_PAIRS50] = wm_phased_shadows(&w, (int)v.nlights, 0, 0.5);
            t[WM_POOL0] = wm_phased_shadows(&w, (int)v.nlights, 1, 0.0);
            t[WM_POOL25] = wm_phased_shadows(&w, (int)v.nlights, 1, 0.25);
            t[WM_POOL50] = wm_phased_shadows(&w, (int)v.nlights, 1, 0.5);
            for (int k = 0; k < WM_NMODELS; k++) {
                if (t[k] > slowest[k])
                    slowest[k] = t[k];
                sum[k] += t[k];
            }
            for (int l = 0; l < w.n; l++)
                lane_steps += wm_pixel_sum(w.lane[l]);
            warps++;
        }
    printf("warpmodel: %s, %dx%d, blocks %dx%d, warps=%ld rays=%ld lights=%u; a step: a node visit, or a primitive "
           "test weighing %.2f; shading %.2f steps a phase\n",
           path, W, H, bx, by, warps, rays, v.nlights, test_weight, shade_cost);
    printf("%-14s %14s %8s %14s %8s %10s\n", "model", "slowest warp", "ratio", "sum of warps", "ratio",
           "lane use");
    for (int k = 0; k < WM_NMODELS; k++)
        printf("%-14s %14.1f %8.3f %14.0f %8.3f %10.3f\n", wm_names[k], slowest[k],
               slowest[0] > 0.0 ? slowest[k] / slowest[0] : 1.0, sum[k], sum[0] > 0.0 ? sum[k] / sum[0] : 1.0,
               sum[k] > 0.0 ? lane_steps / (32.0 * sum[k]) : 0.0);
    free(px);
    rt_accel_free(&acc);
    rt_scene_free(&sc);
    return 0;
}
