/* test_cpu_trace.c SCENE... - the CPU traversal's instruction sets against
 * their C reference, checkasm style: every entry of the table that this CPU
 * runs traces the scene's rays (each primary ray of the camera, from each hit
 * the shadow ray to every light and the mirror ray, and seeded random rays
 * from inside the scene's bounds) and must return exactly what "c" returns:
 * found, t, u, v, primitive, and the node and primitive counters. "c" itself
 * must find the binary traversal's hits (rt_trace_ray), bit for bit. Then the
 * choice: unknown names fail with a message, NULL picks a supported entry.
 * Each entry's tile and pixel renderers (the shading with its traversal
 * inlined) must give the binary traversal's image bit for bit, into a
 * poisoned buffer, and the counters of c's.
 * The hit records start poisoned (NaN, a wrong id) for every call. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "backends/cpu_trace.h"
#include "check.h"
#include "core/rt_shade.h"
#include "scene_fixture.h"

/* rt_render_tile_binary: the image of the binary traversal, the reference */
#define RT_PATH_TRACE(s, o, d, tmax, any, hit, cnt, light) rt_trace_ray(s, o, d, tmax, any, hit, cnt)
#define RT_PATH_NAME(f) f##_binary
#define RT_PATH_FN static inline
#include "core/rt_path_tmpl.h"

static void poison(RtHit *h)
{
    h->t = h->u = h->v = NAN;
    h->id = 0x5a5a5a5au;
}

typedef struct {
    const RtSceneView *v;
    const RtCpuIsa *isa;
    int nisa;
    long rays, bad_ref, bad_isa[8];
    RtCounters cnt[8];
} Ctx;

/* One query through every entry and the binary reference. */
static void query(Ctx *c, RtVec3 o, RtVec3 d, float tmax, int any, RtHit *ref_hit, int *ref_found)
{
    RtHit hb, h0, h;
    RtCounters cb;
    memset(&cb, 0, sizeof cb);
    poison(&hb);
    poison(&h0);
    const int fb = rt_trace_ray(c->v, o, d, tmax, any, &hb, &cb);
    const RtCounters c0 = c->cnt[0];
    const int f0 = c->isa[0].trace(c->v, o, d, tmax, any, &h0, &c->cnt[0]);
    const uint64_t v0 = c->cnt[0].node_visits - c0.node_visits, t0 = c->cnt[0].prim_tests - c0.prim_tests;
    c->rays++;
    /* (an any-hit query may stop at another blocker than the binary one's) */
    c->bad_ref += any ? fb != f0 : !fixture_same(fb, &hb, f0, &h0);
    for (int i = 1; i < c->nisa; i++) {
        const RtCounters before = c->cnt[i];
        poison(&h);
        const int f = c->isa[i].trace(c->v, o, d, tmax, any, &h, &c->cnt[i]);
        c->bad_isa[i] += !fixture_same(f0, &h0, f, &h) || c->cnt[i].node_visits - before.node_visits != v0 ||
                         c->cnt[i].prim_tests - before.prim_tests != t0;
    }
    *ref_hit = hb;
    *ref_found = fb;
}

static void camera_rays(Ctx *c, const RtCamera *cam)
{
    for (int j = 0; j < cam->height; j++)
        for (int i = 0; i < cam->width; i++) {
            RtRay r = rt_camera_ray(cam, i, j);
            RtHit h;
            int f;
            query(c, r.o, r.d, RT_INF, 0, &h, &f);
            if (!f)
                continue;
            RtSurface sf = rt_surface(c->v, r.o, r.d, &h);
            const RtMaterial *m = &c->v->materials[sf.material];
            RtVec3 so = rt_shadow_origin(&sf);
            for (uint32_t li = 0; li < c->v->nlights; li++) {
                RtVec3 col, L;
                float dist;
                RtHit sh;
                int sf_found;
                if (rt_light_sample(c->v, &sf, m, rt_neg(r.d), li, &col, &L, &dist))
                    query(c, so, L, dist, RT_ANY_HIT, &sh, &sf_found);
            }
            RtVec3 R = rt_normalize(rt_sub(r.d, rt_scale(sf.n, 2.0f * rt_dot(r.d, sf.n))));
            query(c, rt_madd(sf.p, R, RT_SECONDARY_OFFSET), R, RT_INF, 0, &h, &f);
        }
}

/* Rays from random points of the root box in random directions. */
static void random_rays(Ctx *c, const RtBvh4Node *root, int n)
{
    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint32_t k = 0; k < root->count; k++) {
        lo[0] = fminf(lo[0], root->lo_x[k]); hi[0] = fmaxf(hi[0], root->hi_x[k]);
        lo[1] = fminf(lo[1], root->lo_y[k]); hi[1] = fmaxf(hi[1], root->hi_y[k]);
        lo[2] = fminf(lo[2], root->lo_z[k]); hi[2] = fmaxf(hi[2], root->hi_z[k]);
    }
    unsigned long long seed = 0x9e3779b97f4a7c15ull;
    for (int i = 0; i < n; i++) {
        RtVec3 o = rt_v3(check_randf(&seed, lo[0], hi[0]), check_randf(&seed, lo[1], hi[1]),
                         check_randf(&seed, lo[2], hi[2]));
        RtVec3 d = rt_normalize(rt_v3(check_randf(&seed, -1, 1), check_randf(&seed, -1, 1), check_randf(&seed, -1, 1)));
        RtHit h;
        int f;
        query(c, o, d, RT_INF, 0, &h, &f);
        query(c, o, d, check_randf(&seed, 0.0f, hi[0] - lo[0]), RT_ANY_HIT, &h, &f);
    }
}

/* The image of every entry's tile (the whole image as one tile, from its
 * rows' middle on so the tile starts off the origin) and pixel renderers
 * against the binary traversal's, bit for bit, and their counters against c's. */
static void check_renders(const char *path, const RtSceneView *v, const RtCpuIsa *isa, int nisa)
{
    const int w = v->cam.width, h = v->cam.height;
    const size_t n = (size_t)w * (size_t)h * 3;
    float *ref = malloc(n * sizeof *ref), *img = malloc(n * sizeof *img);
    RtCounters cr, c0, c;
    memset(&cr, 0, sizeof cr);
    memset(&c0, 0, sizeof c0);
    for (size_t i = 0; i < n; i++)
        ref[i] = NAN;
    rt_render_tile_binary(v, 0, 0, w, h, ref, 3 * (size_t)w, &cr);
    for (int e = 0; e < nisa; e++)
        for (int way = 0; way < 2; way++) {
            for (size_t i = 0; i < n; i++)
                img[i] = NAN;
            memset(&c, 0, sizeof c);
            if (way == 0) {
                isa[e].tile(v, 0, 0, w, h / 2, img, 3 * (size_t)w, &c);
                isa[e].tile(v, 0, h / 2, w, h, img + 3 * (size_t)w * (size_t)(h / 2), 3 * (size_t)w, &c);
            } else {
                for (int j = 0; j < h; j++)
                    for (int i = 0; i < w; i++)
                        isa[e].pixel(v, i, j, img, &c);
            }
            CHECK(memcmp(img, ref, n * sizeof *img) == 0, "%s: %s's %s image differs from the binary traversal's",
                  path, isa[e].name, way ? "pixel" : "tile");
            CHECK(c.primary_rays == cr.primary_rays && c.shadow_rays == cr.shadow_rays &&
                      c.secondary_rays == cr.secondary_rays,
                  "%s: %s's %s renderer traced other rays", path, isa[e].name, way ? "pixel" : "tile");
            if (e == 0 && way == 0)
                c0 = c;
            CHECK(c.node_visits == c0.node_visits && c.prim_tests == c0.prim_tests,
                  "%s: %s's %s renderer counted %llu visits, %llu tests; c's tile %llu, %llu", path, isa[e].name,
                  way ? "pixel" : "tile", (unsigned long long)c.node_visits, (unsigned long long)c.prim_tests,
                  (unsigned long long)c0.node_visits, (unsigned long long)c0.prim_tests);
        }
    free(ref);
    free(img);
}

static void check_scene(const char *path, const RtCpuIsa *isa, int nisa)
{
    RtScene s;
    RtAccel a;
    RtCamera cam;
    RtSceneView v;
    if (fixture_load(path, &s, &a, &cam, &v) != 0)
        return;
    void *soa = rt_cpu_prepare(&v);
    CHECK(soa != NULL && v.cpu_wide != NULL && v.cpu_leaves != NULL, "%s: no CPU copy of the tree", path);
    Ctx c;
    memset(&c, 0, sizeof c);
    c.v = &v;
    c.isa = isa;
    c.nisa = nisa;
    if (v.wide) {
        camera_rays(&c, &cam);
        random_rays(&c, &v.wide[0], 20000);
    }
    CHECK(c.bad_ref == 0, "%s: %ld of %ld rays: c differs from the binary traversal", path, c.bad_ref, c.rays);
    check_renders(path, &v, isa, nisa);
    for (int i = 1; i < nisa; i++) {
        CHECK(c.bad_isa[i] == 0, "%s: %ld of %ld rays: %s differs from c", path, c.bad_isa[i], c.rays, isa[i].name);
        CHECK(c.cnt[i].node_visits == c.cnt[0].node_visits && c.cnt[i].prim_tests == c.cnt[0].prim_tests,
              "%s: %s counted %llu visits, %llu tests; c %llu, %llu", path, isa[i].name,
              (unsigned long long)c.cnt[i].node_visits, (unsigned long long)c.cnt[i].prim_tests,
              (unsigned long long)c.cnt[0].node_visits, (unsigned long long)c.cnt[0].prim_tests);
    }
    printf("%s: %ld rays through %d instruction sets\n", path, c.rays, nisa);
    free(soa);
    fixture_free(&s, &a);
}

int main(int argc, char **argv)
{
    char buf[4096];
    if (check_scenes_present(argc, argv) != 0)
        return 77;
    int n, nrun = 0;
    const RtCpuIsa *table = rt_cpu_isa_table(&n), *run[8];
    CHECK(n >= 1 && strcmp(table[0].name, "c") == 0, "the table starts with the C reference");
    for (int i = 0; i < n && nrun < 8; i++)
        if (table[i].supported()) /* (this CPU's: the others are not run, as checkasm) */
            run[nrun++] = &table[i];
    const RtCpuIsa flat[8] = {0};
    RtCpuIsa list[8];
    memcpy(list, flat, sizeof list);
    for (int i = 0; i < nrun; i++)
        list[i] = *run[i];
    printf("instruction sets run here:");
    for (int i = 0; i < nrun; i++)
        printf(" %s", list[i].name);
    printf("\n");
    for (int k = 1; k < argc; k++)
        check_scene(check_scene_path(argv[k], buf, sizeof buf), list, nrun);
    RtError e;
    CHECK(rt_cpu_isa_select("mmx", &e) != 0 && strstr(e.msg, "unknown instruction set 'mmx'"), "an unknown name");
    CHECK(rt_cpu_isa_select(NULL, &e) == 0, "the default choice");
    CHECK(strcmp(rt_cpu_isa_name(), list[nrun - 1].name) == 0, "the default is the last supported entry (%s), got %s",
          list[nrun - 1].name, rt_cpu_isa_name());
    CHECK(rt_cpu_isa_select("c", &e) == 0 && strcmp(rt_cpu_isa_name(), "c") == 0, "c by name");
    return check_report("test_cpu_trace");
}
