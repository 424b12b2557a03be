/* schedule.c - the CUDA backend's scheduling choices, each in one place, with
 * the measurement behind it (docs/gpu.md, "Design and defaults"):
 *   - block shapes: 16x8 for the tree, 8x8 for brute force;
 *   - schedule: one block per tile (grid) for the tree, persistent warps
 *     taking 32 pixels at a time for brute force (Aila and Laine, HPG 2009)
 *     and for large images with the tree;
 *   - the grid's tiles from the image's centre outwards;
 *   - pixel pairs when their blocks all fit on the GPU at once;
 *   - shadow rays in slot order, with the slots front to back along a single
 *     directional light. */
#include <stdlib.h>
#include <string.h>

#include "schedule.h"

#define RT_CUDA_TREE_BX 16
#define RT_CUDA_TREE_BY 8
#define RT_CUDA_NONE_BX 8
#define RT_CUDA_NONE_BY 8
/* Large images: from about 40 waves of the grid default's resident threads
 * on the H100, persistent 8x8 blocks at 3 blocks per multiprocessor beat the
 * grid on every report scene; at 31 waves (1920x1080) not on all. */
#define RT_CUDA_LARGE_WAVES 40.0
#define RT_CUDA_LARGE_BX 8
#define RT_CUDA_LARGE_BY 8
#define RT_CUDA_LARGE_MINB 3

/* Below about 4 waves a frame's time is its slowest pixels' (latency), not
 * the GPU's throughput: on the H200 the dragon at 512x384 (2.9 waves) gave
 * frames faster with 4 frames in flight than with 2; at 3840x2160 (82
 * waves) 2 are as fast as any more (docs/gpu.md, "Measured"). */
#define RT_CUDA_DEEP_WAVES 4.0

int rt_cuda_frames_in_flight(double waves) { return waves < RT_CUDA_DEEP_WAVES ? RT_CUDA_MAX_SLOTS : 2; }

void rt_cuda_default_block(int has_tree, int *bx, int *by)
{
    *bx = has_tree ? RT_CUDA_TREE_BX : RT_CUDA_NONE_BX;
    *by = has_tree ? RT_CUDA_TREE_BY : RT_CUDA_NONE_BY;
}

void rt_cuda_plan_start(RtCudaPlan *p, int has_tree, int block_x, int block_y)
{
    memset(p, 0, sizeof *p);
    if (block_x > 0) {
        p->bx = block_x;
        p->by = block_y;
    } else {
        rt_cuda_default_block(has_tree, &p->bx, &p->by);
    }
    p->threads = p->bx * p->by;
    p->persistent = !has_tree;
    p->minb = 1;
    p->center = has_tree;
}

int rt_cuda_plan_large(RtCudaPlan *p, double npix, double resident)
{
    if (!(resident > 0.0) || npix < RT_CUDA_LARGE_WAVES * resident)
        return 0;
    p->large = 1;
    p->persistent = 1;
    p->center = 0;
    p->bx = RT_CUDA_LARGE_BX;
    p->by = RT_CUDA_LARGE_BY;
    p->threads = p->bx * p->by;
    p->minb = RT_CUDA_LARGE_MINB;
    return 1;
}

/* Pairs split a block's lanes two to a pixel: the grid schedule, an even
 * block width and whole warps. */
int rt_cuda_pairs_possible(const RtCudaPlan *p)
{
    return !p->persistent && p->bx % 2 == 0 && p->threads % 32 == 0;
}

/* The second lane per pixel costs no wave when every block of pairs is
 * resident at once; then it shortens the chains of rays the frame waits on. */
int rt_cuda_pairs_fit(const RtCudaPlan *p, int w, int h, int pair_blocks_per_sm, int nsm)
{
    const int pw = p->bx / 2;
    const unsigned long long tiles =
        (unsigned long long)((w + pw - 1) / pw) * (unsigned long long)((h + p->by - 1) / p->by);
    return tiles <= (unsigned long long)pair_blocks_per_sm * (unsigned long long)nsm;
}

int rt_cuda_grid(const RtCudaPlan *p, int w, int h, RtCudaGrid *g, RtError *err)
{
    memset(g, 0, sizeof *g);
    g->pairs = p->pairs;
    g->persistent = p->persistent;
    g->bx = p->pairs ? p->bx / 2 : p->bx;
    g->by = p->by;
    g->tiles_x = (w + g->bx - 1) / g->bx;
    g->tile_items = (uint32_t)(g->bx * g->by);
    const unsigned long long tiles = (unsigned long long)g->tiles_x * (unsigned long long)((h + g->by - 1) / g->by);
    if (tiles * (unsigned long long)p->threads > 0xffffffffull - 1024ull)
        return rt_fail(err, "cuda: a %dx%d image in %dx%d blocks has more than 2^32 work items", w, h, p->bx, p->by);
    g->ntiles = (uint32_t)tiles;
    g->total_items = (uint32_t)(tiles * g->tile_items);
    g->run = g->period = 1;
    return 0;
}

/* The share's tile rows below `rows`: whole periods, then what the last,
 * partial period holds of the run. */
static uint32_t share_rows(const RtCudaShare *sh, int rows)
{
    const int full = rows / sh->period, rem = rows % sh->period - sh->first;
    return (uint32_t)(full * sh->run + (rem <= 0 ? 0 : rem < sh->run ? rem : sh->run));
}

void rt_cuda_share_runs(const RtCudaShare *sh, int rows, int row_h, int h, size_t row_bytes, RtShareRuns *out)
{
    memset(out, 0, sizeof *out);
    out->tile_rows = share_rows(sh, rows);
    const int whole = h / row_h; /* tile rows not cut by the image's height */
    const size_t tile_row = (size_t)row_h * row_bytes;
    out->off = (size_t)sh->first * tile_row;
    out->width = (size_t)sh->run * tile_row;
    out->pitch = (size_t)sh->period * tile_row;
    /* runs wholly inside the uncut rows: first + k * period + run <= whole */
    out->count = whole >= sh->first + sh->run ? (size_t)((whole - sh->first - sh->run) / sh->period + 1) : 0;
    /* at most one more run reaches past them: it starts after the last
     * whole run ends, so the next one starts past the image */
    const int start = sh->first + (int)out->count * sh->period;
    if (start < rows) {
        const int end_row = start + sh->run < rows ? start + sh->run : rows;
        const int y1 = end_row * row_h < h ? end_row * row_h : h;
        out->tail_off = (size_t)start * tile_row;
        out->tail_bytes = (size_t)(y1 - start * row_h) * row_bytes;
    }
}

uint32_t rt_cuda_grid_share(RtCudaGrid *g, const RtCudaShare *sh, int rows)
{
    const uint32_t n = share_rows(sh, rows);
    g->first_row = (uint32_t)sh->first;
    g->run = (uint32_t)sh->run;
    g->period = (uint32_t)sh->period;
    if (sh->period != 1)
        g->units = NULL;
    g->ntiles = n * (uint32_t)g->tiles_x;
    g->total_items = g->ntiles * g->tile_items;
    return n;
}

/* ---- The centre order ------------------------------------------------------
 * A frame's heavy work is mostly on its subject, and a subject is mostly near
 * the middle of the frame: its tiles go into the first wave instead of
 * wherever the rows put them, so the frame does not end waiting on them.
 * Depends on the image and tile sizes only, not on the scene. */
typedef struct TileKey {
    unsigned long long d2;
    uint32_t tile;
} TileKey;

static int cmp_tile_key(const void *a, const void *b)
{
    const TileKey *x = (const TileKey *)a, *y = (const TileKey *)b;
    if (x->d2 != y->d2)
        return x->d2 < y->d2 ? -1 : 1;
    return x->tile < y->tile ? -1 : (x->tile > y->tile ? 1 : 0);
}

uint32_t *rt_cuda_center_order(const RtCudaGrid *g, int w, int h, RtError *err)
{
    TileKey *k = malloc((size_t)g->ntiles * sizeof *k);
    uint32_t *order = malloc((size_t)g->ntiles * sizeof *order);
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
    qsort(k, g->ntiles, sizeof *k, cmp_tile_key); /* ties: raster order */
    for (uint32_t t = 0; t < g->ntiles; t++)
        order[t] = k[t].tile;
    free(k);
    return order;
}

/* ---- The slot order ---------------------------------------------------------
 * The kernel's shadow rays take a node's entered children in slot order,
 * without sorting them (RT_ANY_HIT_SLOT, rt_traverse.h): fewer instructions
 * per node. When every shadow ray of the scene goes the same way -- its one
 * light is directional -- the slots are put front to back along that way (by
 * their boxes' centres), so that a blocked shadow ray meets its blocker
 * sooner. The copy is laid out depth first in the new slot order, as the
 * build lays out its own. Boxes and hits are unchanged. */
typedef struct SlotOrder {
    const RtBvh4Node *in;
    RtBvh4Node *out;
    uint32_t n;
    float way[3];
} SlotOrder;

static void slot_copy(SlotOrder *so, uint32_t from, uint32_t to)
{
    RtBvh4Node o = so->in[from];
    rt_cuda_slot_sort(so->way, &o);
    for (uint32_t k = 0; k < o.count; k++)
        if (!(o.child[k] & RT_WIDE_LEAF)) {
            const uint32_t c = o.child[k];
            o.child[k] = so->n++;
            slot_copy(so, c, o.child[k]);
        }
    so->out[to] = o;
}

int rt_cuda_slot_way(const RtSceneView *v, float way[3])
{
    if (v->nlights != 1 || v->lights[0].type != RT_LIGHT_DIRECTIONAL)
        return 0;
    for (int i = 0; i < 3; i++)
        way[i] = -v->lights[0].dir[i]; /* towards the light */
    return 1;
}

RtBvh4Node *rt_cuda_slot_order(const RtSceneView *v, RtError *err, int *failed)
{
    *failed = 0;
    SlotOrder so;
    if (!v->wide || !rt_cuda_slot_way(v, so.way))
        return NULL;
    so.in = v->wide;
    so.out = malloc((size_t)v->nwide * sizeof *so.out);
    if (!so.out) {
        *failed = 1;
        rt_fail(err, "cuda: out of memory for the slot order of %u nodes", v->nwide);
        return NULL;
    }
    so.n = 1;
    slot_copy(&so, 0, 0);
    return so.out;
}
