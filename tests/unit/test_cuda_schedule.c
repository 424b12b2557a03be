/* test_cuda_schedule.c - the CUDA backend's scheduling choices
 * (renderer/backends/cuda/schedule.c), which run on the host and need no GPU:
 *   - the centre order: a permutation of the tiles, by squared distance of
 *     the tile centre from the image centre (computed here in doubles),
 *     ties in raster order;
 *   - the slot order: for a scene whose one light is directional, every node
 *     keeps its boxes and children, front to back along the light, laid out
 *     depth first; rays find the same hits in it as in the builder's tree;
 *     other scenes get no copy;
 *   - the rules: pairs need the grid, an even width and whole warps; the
 *     large-image switch at 40 waves; the launch geometry and its limit;
 *   - the shares of several GPUs: P interleaved shares cover every tile of
 *     the image once (the kernel's tile formula), and their copy pieces
 *     cover every byte of the image once, whatever the image's height. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#define RT_WIDE_LEAF_VOTE(has_leaf, any) (has_leaf) /* rt_traverse.h asks for it; no ray is traced here */
#include "core/rt_traverse.h"
#include "backends/cuda/schedule.h"

static void test_center_order(int w, int h, int bx, int by)
{
    RtCudaPlan p;
    RtCudaGrid g;
    RtError err;
    rt_cuda_plan_start(&p, 1, bx, by);
    CHECK(rt_cuda_grid(&p, w, h, &g, &err) == 0, "grid %dx%d", w, h);
    uint32_t *o = rt_cuda_center_order(&g, w, h, &err);
    CHECK(o != NULL, "centre order");
    if (!o)
        return;
    char *seen = calloc(g.ntiles, 1);
    double last = -1.0;
    uint32_t last_tile = 0;
    for (uint32_t k = 0; k < g.ntiles; k++) {
        const uint32_t t = o[k];
        CHECK(t < g.ntiles && !seen[t], "%dx%d: tile %u twice or out of range", w, h, t);
        if (t >= g.ntiles)
            break;
        seen[t] = 1;
        const double cx = ((double)(t % (uint32_t)g.tiles_x) + 0.5) * bx - 0.5 * w;
        const double cy = ((double)(t / (uint32_t)g.tiles_x) + 0.5) * by - 0.5 * h;
        const double d = cx * cx + cy * cy;
        CHECK(d > last || (d == last && t > last_tile), "%dx%d: tile %u (d=%g) after tile %u (d=%g)", w, h, t, d,
              last_tile, last);
        last = d;
        last_tile = t;
    }
    /* 5 x 3 tiles of 8x8 in 40x24: the middle tile, then its four
     * neighbours (all 8 pixels away) in raster order */
    if (w == 40 && h == 24 && bx == 8 && by == 8)
        CHECK(o[0] == 7 && o[1] == 2 && o[2] == 6 && o[3] == 8 && o[4] == 12, "40x24 starts %u %u %u %u %u", o[0],
              o[1], o[2], o[3], o[4]);
    free(seen);
    free(o);
}

/* A scene of n random triangles and the given light line, parsed from memory. */
static int make_scene(RtScene *sc, RtAccel *a, RtCamera *cam, int n, const char *light, unsigned long long seed)
{
    size_t cap = 512 + (size_t)n * 200;
    char *buf = malloc(cap);
    size_t len = (size_t)snprintf(buf, cap, "film_resolution: 64 48\ncamera_pos: 0 0 6\n%s\nmaterial: .1 .1 .1 .6 .6 .6 .2 .2 .2 8 0 0 0 1\n",
                                  light);
    for (int i = 0; i < n; i++) {
        const float cx = check_randf(&seed, -3, 3), cy = check_randf(&seed, -2, 2), cz = check_randf(&seed, -3, 1);
        len += (size_t)snprintf(buf + len, cap - len, "vertex: %g %g %g\nvertex: %g %g %g\nvertex: %g %g %g\n", cx, cy, cz,
                                cx + check_randf(&seed, -.4f, .4f), cy + check_randf(&seed, -.4f, .4f), cz,
                                cx, cy + check_randf(&seed, -.4f, .4f), cz + check_randf(&seed, -.4f, .4f));
    }
    for (int i = 0; i < n; i++)
        len += (size_t)snprintf(buf + len, cap - len, "triangle: %d %d %d\n", 3 * i, 3 * i + 1, 3 * i + 2);
    RtError err;
    memset(sc, 0, sizeof *sc);
    int rc = rt_scene_parse_buffer("mem", buf, len, sc, NULL, NULL, &err) || rt_scene_camera(sc, cam, &err) ||
             rt_accel_build(sc, RT_ACCEL_BVH, a, &err);
    CHECK(rc == 0, "scene: %s", err.msg);
    free(buf);
    return rc;
}

static float slot_key(const RtBvh4Node *n, int k, const float *way)
{
    float key = 0.0f;
    key += 0.5f * (n->lo_x[k] + n->hi_x[k]) * way[0];
    key += 0.5f * (n->lo_y[k] + n->hi_y[k]) * way[1];
    key += 0.5f * (n->lo_z[k] + n->hi_z[k]) * way[2];
    return key;
}

/* Node `o` of the copy against node `b` of the builder's tree, recursively:
 * the same children (as a set), front to back, depth first. */
static void same_node(const RtBvh4Node *copy, const RtBvh4Node *build, uint32_t o, uint32_t b, const float *way,
                      uint32_t *next)
{
    const RtBvh4Node *no = &copy[o], *nb = &build[b];
    CHECK(no->count == nb->count, "node %u: %u children, builder's %u", o, no->count, nb->count);
    for (uint32_t k = 0; k < no->count && k < 4; k++) {
        if (k > 0)
            CHECK(slot_key(no, (int)k - 1, way) <= slot_key(no, (int)k, way), "node %u: slot %u before %u", o, k - 1, k);
        int match = -1;
        for (uint32_t j = 0; j < nb->count; j++)
            if (no->lo_x[k] == nb->lo_x[j] && no->hi_x[k] == nb->hi_x[j] && no->lo_y[k] == nb->lo_y[j] &&
                no->hi_y[k] == nb->hi_y[j] && no->lo_z[k] == nb->lo_z[j] && no->hi_z[k] == nb->hi_z[j] &&
                ((no->child[k] & RT_WIDE_LEAF) != 0) == ((nb->child[j] & RT_WIDE_LEAF) != 0) &&
                (!(no->child[k] & RT_WIDE_LEAF) || no->child[k] == nb->child[j]))
                match = (int)j;
        CHECK(match >= 0, "node %u slot %u: no such child in builder's node %u", o, k, b);
        if (match >= 0 && !(no->child[k] & RT_WIDE_LEAF)) {
            CHECK(no->child[k] == (*next)++, "node %u slot %u: child %u not in depth-first order", o, k, no->child[k]);
            same_node(copy, build, no->child[k], nb->child[match], way, next);
        }
    }
}

static void test_slot_order(void)
{
    RtScene sc;
    RtAccel a;
    RtCamera cam;
    RtError err;
    int failed = 0;
    if (make_scene(&sc, &a, &cam, 400, "directional_light: 1 1 1 -0.3 -1 -0.5", 7))
        return;
    RtSceneView v = rt_scene_view(&sc, &a, &cam);
    RtBvh4Node *copy = rt_cuda_slot_order(&v, &err, &failed);
    CHECK(copy != NULL && !failed, "one directional light: a copy");
    if (copy) {
        const float way[3] = {0.3f, 1.0f, 0.5f};
        uint32_t next = 1;
        same_node(copy, a.wide, 0, 0, way, &next);
        CHECK(next == a.nwide, "the copy reaches %u of %u nodes", next, a.nwide);
        /* the same hits, closest and any, on random rays through the scene */
        RtSceneView vc = v;
        vc.wide = copy;
        unsigned long long seed = 11;
        for (int i = 0; i < 2000; i++) {
            const RtVec3 o = rt_v3(check_randf(&seed, -4, 4), check_randf(&seed, -3, 3), 5.0f);
            const RtVec3 d = rt_normalize(rt_sub(rt_v3(check_randf(&seed, -3, 3), check_randf(&seed, -2, 2), -2.0f), o));
            for (int any = 0; any <= RT_ANY_HIT_SLOT; any++) {
                RtHit h1, h2;
                RtCounters c;
                memset(&c, 0, sizeof c);
                const float tmax = any ? 7.0f : RT_INF;
                const int f1 = rt_trace_ray_wide(&v, o, d, tmax, any, &h1, &c);
                const int f2 = rt_trace_ray_wide(&vc, o, d, tmax, any, &h2, &c);
                CHECK(f1 == f2 && (any || !f1 || (h1.t == h2.t && h1.id == h2.id)), "ray %d any=%d: %d/%u/%g vs %d/%u/%g",
                      i, any, f1, h1.id, h1.t, f2, h2.id, h2.t);
            }
        }
    }
    free(copy);
    rt_accel_free(&a);
    rt_scene_free(&sc);
    /* a point light, or two lights: shadow rays go every way, no copy */
    const char *others[] = {"point_light: 1 1 1 0 4 4",
                            "directional_light: 1 1 1 0 -1 0\ndirectional_light: 1 1 1 1 0 0"};
    for (int k = 0; k < 2; k++) {
        if (make_scene(&sc, &a, &cam, 50, others[k], 3))
            return;
        v = rt_scene_view(&sc, &a, &cam);
        copy = rt_cuda_slot_order(&v, &err, &failed);
        CHECK(copy == NULL && !failed, "%s: no copy", others[k]);
        free(copy);
        rt_accel_free(&a);
        rt_scene_free(&sc);
    }
}

static void test_rules(void)
{
    RtCudaPlan p;
    RtCudaGrid g;
    RtError err;
    rt_cuda_plan_start(&p, 1, 0, 0);
    CHECK(p.bx == 16 && p.by == 8 && !p.persistent && p.center && p.minb == 1, "tree defaults %dx%d", p.bx, p.by);
    CHECK(rt_cuda_pairs_possible(&p), "16x8 grid: pairs possible");
    /* 64x48 in pairs of 8x8-pixel tiles: 8 x 6 = 48 blocks */
    CHECK(rt_cuda_pairs_fit(&p, 64, 48, 1, 48) && !rt_cuda_pairs_fit(&p, 64, 48, 1, 47), "pairs fit at 48 blocks");
    CHECK(!rt_cuda_plan_large(&p, 39.9 * 1000.0, 1000.0) && !p.large, "39.9 waves: not large");
    CHECK(rt_cuda_plan_large(&p, 40.0 * 1000.0, 1000.0) && p.large && p.persistent && !p.center && p.bx == 8 &&
              p.by == 8 && p.minb == 3, "40 waves: large");
    CHECK(!rt_cuda_pairs_possible(&p), "persistent: no pairs");
    rt_cuda_plan_start(&p, 0, 0, 0);
    CHECK(p.bx == 8 && p.by == 8 && p.persistent && !p.center, "brute-force defaults");
    rt_cuda_plan_start(&p, 1, 13, 7);
    CHECK(!rt_cuda_pairs_possible(&p), "13x7: no pairs");
    rt_cuda_plan_start(&p, 1, 32, 4);
    p.pairs = 1;
    CHECK(rt_cuda_grid(&p, 100, 10, &g, &err) == 0 && g.bx == 16 && g.by == 4 && g.tiles_x == 7 && g.ntiles == 21 &&
              g.total_items == 21u * 64u, "pairs grid: %dx%d tiles_x %d ntiles %u", g.bx, g.by, g.tiles_x, g.ntiles);
    rt_cuda_plan_start(&p, 1, 1, 1);
    CHECK(rt_cuda_grid(&p, 32768, 32768, &g, &err) == 0, "2^30 items fit");
    rt_cuda_plan_start(&p, 1, 1, 1024);
    CHECK(rt_cuda_grid(&p, 32768, 32768 * 5, &g, &err) != 0 && strstr(err.msg, "2^32"), "past 2^32 items: %s",
          err.msg);
}

/* P shares {r, run, P * run} of a w x h image in bx x by tiles. */
static void test_shares(int w, int h, int bx, int by, int P, int run)
{
    RtCudaPlan p;
    RtCudaGrid whole;
    RtError err;
    rt_cuda_plan_start(&p, 1, bx, by);
    CHECK(rt_cuda_grid(&p, w, h, &whole, &err) == 0, "grid %dx%d", w, h);
    const int rows = (int)(whole.ntiles / (uint32_t)whole.tiles_x);
    const size_t row_bytes = (size_t)w * 3, bytes = row_bytes * (size_t)h;
    unsigned char *tiles = calloc(whole.ntiles, 1), *img = calloc(bytes, 1);
    uint32_t tile_rows = 0;
    for (int r = 0; r < P; r++) {
        const RtCudaShare sh = {r * run, run, P * run};
        RtCudaGrid g = whole;
        const uint32_t n = rt_cuda_grid_share(&g, &sh, rows);
        CHECK(g.ntiles == n * (uint32_t)g.tiles_x, "%dx%d P=%d: share %d's tiles", w, h, P, r);
        for (uint32_t t = 0; t < g.ntiles; t++) {
            const uint32_t tile = rt_cuda_share_tile(&g, t);
            CHECK(tile < whole.ntiles && tiles[tile] == 0, "%dx%d P=%d: tile %u twice or outside", w, h, P, tile);
            if (tile < whole.ntiles)
                tiles[tile] = 1;
        }
        RtShareRuns sr;
        rt_cuda_share_runs(&sh, rows, by, h, row_bytes, &sr);
        CHECK(sr.tile_rows == n, "%dx%d P=%d: share %d: %u rows against %u", w, h, P, r, sr.tile_rows, n);
        tile_rows += n;
        for (size_t k = 0; k < sr.count; k++)
            for (size_t b = 0; b < sr.width; b++) {
                const size_t at = sr.off + k * sr.pitch + b;
                CHECK(at < bytes && img[at] == 0, "%dx%d P=%d: byte %zu twice or outside", w, h, P, at);
                if (at < bytes)
                    img[at] = 1;
            }
        for (size_t b = 0; b < sr.tail_bytes; b++) {
            const size_t at = sr.tail_off + b;
            CHECK(at < bytes && img[at] == 0, "%dx%d P=%d: tail byte %zu twice or outside", w, h, P, at);
            if (at < bytes)
                img[at] = 1;
        }
    }
    CHECK(tile_rows == (uint32_t)rows, "%dx%d P=%d: %u tile rows shared of %d", w, h, P, tile_rows, rows);
    size_t missed = 0;
    for (uint32_t t = 0; t < whole.ntiles; t++)
        missed += !tiles[t];
    for (size_t b = 0; b < bytes; b++)
        missed += !img[b];
    CHECK(missed == 0, "%dx%d P=%d run %d: %zu tiles or bytes in no share", w, h, P, run, missed);
    free(tiles);
    free(img);
}

int main(void)
{
    test_shares(64, 48, 16, 8, 1, 1);
    test_shares(64, 45, 16, 8, 2, 1);
    test_shares(100, 61, 8, 8, 3, 1);
    test_shares(100, 61, 8, 8, 4, 2);
    test_shares(40, 20, 8, 8, 5, 1); /* more ranks than tile rows */
    test_shares(512, 384, 16, 8, 4, 1);
    test_center_order(40, 24, 8, 8);
    test_center_order(512, 384, 16, 8);
    test_center_order(37, 23, 13, 7);
    test_slot_order();
    test_rules();
    return check_report("cuda-schedule");
}
