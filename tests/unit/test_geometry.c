/* test_geometry.c - ray/sphere and ray/triangle hits and misses, camera rays
 * for known pixels, and the BVH against brute force on seeded random scenes. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
/* the CPU's leaf vote (rt_traverse.h): a leaf at once */
#define RT_WIDE_LEAF_VOTE(has_leaf, any) (has_leaf)
#include "core/rt_traverse.h" /* the traversals and intersections under test */
#include "rt.h"

static RtPrim sphere_prim(float x, float y, float z, float r)
{
    RtPrim p;
    memset(&p, 0, sizeof p);
    p.p0[0] = x; p.p0[1] = y; p.p0[2] = z;
    p.e1[0] = r;
    p.id = RT_PRIM_SPHERE_BIT;
    return p;
}

static RtPrim tri_prim(RtVec3 a, RtVec3 b, RtVec3 c)
{
    RtPrim p;
    memset(&p, 0, sizeof p);
    p.p0[0] = a.x; p.p0[1] = a.y; p.p0[2] = a.z;
    p.e1[0] = b.x - a.x; p.e1[1] = b.y - a.y; p.e1[2] = b.z - a.z;
    p.e2[0] = c.x - a.x; p.e2[1] = c.y - a.y; p.e2[2] = c.z - a.z;
    return p;
}

static void test_sphere(void)
{
    RtPrim s = sphere_prim(0, 0, -5, 1);
    float u, v;
    float t = rt_prim_intersect(&s, rt_v3(0, 0, 0), rt_v3(0, 0, -1), &u, &v);
    CHECK(fabsf(t - 4.0f) < 1e-5f, "front hit t=%g", (double)t);
    t = rt_prim_intersect(&s, rt_v3(0, 0, -5), rt_v3(0, 0, -1), &u, &v);
    CHECK(fabsf(t - 1.0f) < 1e-5f, "from inside t=%g", (double)t);
    t = rt_prim_intersect(&s, rt_v3(0, 0, 0), rt_v3(0, 0, 1), &u, &v);
    CHECK(t == RT_INF, "behind the ray t=%g", (double)t);
    t = rt_prim_intersect(&s, rt_v3(0, 1.01f, 0), rt_v3(0, 0, -1), &u, &v);
    CHECK(t == RT_INF, "just above t=%g", (double)t);
    t = rt_prim_intersect(&s, rt_v3(0, 0.99f, 0), rt_v3(0, 0, -1), &u, &v);
    CHECK(t < RT_INF && fabsf(t - (5.0f - sqrtf(1.0f - 0.99f * 0.99f))) < 1e-4f, "grazing t=%g", (double)t);
    /* A small sphere far away: float32 must still find it (precision form). */
    RtPrim far = sphere_prim(0, 0, -1e4f, 0.01f);
    t = rt_prim_intersect(&far, rt_v3(0, 0, 0), rt_v3(0, 0, -1), &u, &v);
    CHECK(fabsf(t - (1e4f - 0.01f)) < 1e-2f, "far small sphere t=%g", (double)t);
    /* Hits closer than RT_T_MIN are ignored: leaving the surface finds the far side. */
    t = rt_prim_intersect(&s, rt_v3(0, 0, -4), rt_v3(0, 0, -1), &u, &v);
    CHECK(fabsf(t - 2.0f) < 1e-4f, "self hit ignored t=%g", (double)t);
}

static void test_triangle(void)
{
    RtPrim tr = tri_prim(rt_v3(-1, -1, -3), rt_v3(1, -1, -3), rt_v3(0, 1, -3));
    float u, v;
    float t = rt_prim_intersect(&tr, rt_v3(0, 0, 0), rt_v3(0, 0, -1), &u, &v);
    CHECK(fabsf(t - 3.0f) < 1e-5f, "centre hit t=%g", (double)t);
    CHECK(fabsf(u - 0.25f) < 1e-5f && fabsf(v - 0.5f) < 1e-5f, "barycentrics %g %g", (double)u, (double)v);
    t = rt_prim_intersect(&tr, rt_v3(0, 0, -6), rt_v3(0, 0, 1), &u, &v);
    CHECK(fabsf(t - 3.0f) < 1e-5f, "back face hit t=%g", (double)t);
    t = rt_prim_intersect(&tr, rt_v3(2, 0, 0), rt_v3(0, 0, -1), &u, &v);
    CHECK(t == RT_INF, "outside edge");
    t = rt_prim_intersect(&tr, rt_v3(0, 0, 0), rt_v3(1, 0, 0), &u, &v);
    CHECK(t == RT_INF, "parallel ray");
    t = rt_prim_intersect(&tr, rt_v3(0, 0, -4), rt_v3(0, 0, -1), &u, &v);
    CHECK(t == RT_INF, "behind");
    RtPrim degenerate = tri_prim(rt_v3(0, 0, -3), rt_v3(1, 1, -3), rt_v3(2, 2, -3));
    t = rt_prim_intersect(&degenerate, rt_v3(1, 1, 0), rt_v3(0, 0, -1), &u, &v);
    CHECK(t == RT_INF, "degenerate triangle never hits");
}

static void test_camera(void)
{
    RtScene s;
    RtError e;
    const char *text = "camera_pos: 1 2 3\ncamera_fwd: 0 0 1\ncamera_up: 0 1 0\ncamera_fov_ha: 45\n"
                       "film_resolution: 4 2\n";
    CHECK(rt_scene_parse_buffer("c.txt", text, strlen(text), &s, NULL, NULL, &e) == 0, "%s", e.msg);
    RtCamera cam;
    CHECK(rt_scene_camera(&s, &cam, &e) == 0, "%s", e.msg);
    /* d = (H/2)/tan(45deg) = 1; looks along -fwd = -z; right = up x fwd = +x */
    CHECK(fabsf(cam.d - 1.0f) < 1e-6f, "d=%g", (double)cam.d);
    CHECK(cam.right.x == 1.0f && cam.up.y == 1.0f, "basis");
    RtRay r = rt_camera_ray(&cam, 0, 0);
    /* through pos - d*fwd + (W/2 - 0.5)*right + (H/2 - 0.5)*up = (1.5, 0.5, -1) relative */
    RtVec3 want = rt_normalize(rt_v3(1.5f, 0.5f, -1.0f));
    CHECK(fabsf(r.d.x - want.x) < 1e-6f && fabsf(r.d.y - want.y) < 1e-6f && fabsf(r.d.z - want.z) < 1e-6f,
          "pixel (0,0) dir %g %g %g", (double)r.d.x, (double)r.d.y, (double)r.d.z);
    CHECK(r.o.x == 1.0f && r.o.y == 2.0f && r.o.z == 3.0f, "origin");
    r = rt_camera_ray(&cam, 3, 1);
    want = rt_normalize(rt_v3(-1.5f, -0.5f, -1.0f));
    CHECK(fabsf(r.d.x - want.x) < 1e-6f && fabsf(r.d.y - want.y) < 1e-6f, "pixel (3,1)");
    rt_scene_free(&s);
}

/* Random scene: triangles and spheres in a box. */
static void random_scene(RtScene *s, unsigned long long *seed, int ntri, int nsph)
{
    size_t cap = (size_t)(ntri * 3 + nsph) * 64 + 256;
    char *buf = malloc(cap);
    size_t off = 0;
    for (int i = 0; i < ntri; i++) {
        float cx = check_randf(seed, -10, 10), cy = check_randf(seed, -10, 10), cz = check_randf(seed, -10, 10);
        float sz = check_randf(seed, 0.05f, 2.0f);
        for (int k = 0; k < 3; k++)
            off += (size_t)snprintf(buf + off, cap - off, "vertex: %.6f %.6f %.6f\n",
                                    (double)(cx + check_randf(seed, -sz, sz)), (double)(cy + check_randf(seed, -sz, sz)),
                                    (double)(cz + check_randf(seed, -sz, sz)));
        off += (size_t)snprintf(buf + off, cap - off, "triangle: %d %d %d\n", 3 * i, 3 * i + 1, 3 * i + 2);
    }
    for (int i = 0; i < nsph; i++)
        off += (size_t)snprintf(buf + off, cap - off, "sphere: %.6f %.6f %.6f %.6f\n",
                                (double)check_randf(seed, -10, 10), (double)check_randf(seed, -10, 10),
                                (double)check_randf(seed, -10, 10), (double)check_randf(seed, 0.05f, 1.5f));
    RtError e;
    CHECK(rt_scene_parse_buffer("r.txt", buf, off, s, NULL, NULL, &e) == 0, "%s", e.msg);
    free(buf);
}

static void test_bvh_random(void)
{
    unsigned long long seed = 12345;
    uint32_t copies = 0;
    for (int round = 0; round < 12; round++) {
        RtScene s;
        int ntri = (int)(check_rand(&seed) % 3000), nsph = (int)(check_rand(&seed) % 300);
        if (round == 0) { ntri = 1; nsph = 0; }
        if (round == 1) { ntri = 0; nsph = 1; }
        random_scene(&s, &seed, ntri, nsph);
        RtAccel bvh, none;
        RtError e;
        CHECK(rt_accel_build(&s, RT_ACCEL_BVH, &bvh, &e) == 0, "%s", e.msg);
        CHECK(rt_accel_build(&s, RT_ACCEL_NONE, &none, &e) == 0, "%s", e.msg);
        CHECK(rt_bvh_check(&bvh, &e) == 0, "round %d: %s", round, e.msg);
        CHECK(bvh.nprims - bvh.nsplit == (uint32_t)(ntri + nsph), "prim count: %u records, %u copies", bvh.nprims,
              bvh.nsplit);
        copies += bvh.nsplit;
        RtCamera cam;
        memset(&cam, 0, sizeof cam);
        RtSceneView vb = rt_scene_view(&s, &bvh, &cam), vn = rt_scene_view(&s, &none, &cam);
        int mismatches = 0, wide_mismatches = 0, hits = 0;
        for (int k = 0; k < 2000; k++) {
            RtVec3 o = rt_v3(check_randf(&seed, -15, 15), check_randf(&seed, -15, 15), check_randf(&seed, -15, 15));
            RtVec3 d = rt_normalize(rt_v3(check_randf(&seed, -1, 1), check_randf(&seed, -1, 1), check_randf(&seed, -1, 1)));
            if (k % 7 == 0)
                d = rt_v3(0, 0, k % 2 ? 1.0f : -1.0f); /* axis-aligned: zero direction components */
            RtHit hb, hn;
            memset(&hb, 0, sizeof hb);
            memset(&hn, 0, sizeof hn);
            RtCounters c;
            memset(&c, 0, sizeof c);
            int fb = rt_trace_ray(&vb, o, d, RT_INF, 0, &hb, &c);
            int fn = rt_trace_ray(&vn, o, d, RT_INF, 0, &hn, &c);
            hits += fn;
            if (fb != fn || (fn && (hb.t != hn.t || hb.id != hn.id || hb.u != hn.u || hb.v != hn.v)))
                mismatches++;
            /* the 4-wide tree finds the very same hit */
            RtHit hw;
            int fw = rt_trace_ray_wide(&vb, o, d, RT_INF, 0, &hw, &c);
            if (fw != fn || (fn && (hw.t != hn.t || hw.id != hn.id || hw.u != hn.u || hw.v != hn.v)))
                wide_mismatches++;
            /* any-hit with a finite tmax agrees with the closest hit */
            float tmax = check_randf(&seed, 0.1f, 30.0f);
            int ab = rt_trace_ray(&vb, o, d, tmax, 1, &hb, &c);
            int an = rt_trace_ray(&vn, o, d, tmax, 1, &hn, &c);
            RtHit hc;
            rt_trace_ray(&vn, o, d, RT_INF, 0, &hc, &c);
            int want = fn && hc.t < tmax;
            if (ab != want || an != want)
                mismatches++;
            if (rt_trace_ray_wide(&vb, o, d, tmax, 1, &hw, &c) != want)
                wide_mismatches++;
        }
        CHECK(mismatches == 0, "round %d: %d rays disagree between bvh and brute force", round, mismatches);
        CHECK(vb.wide && vb.nwide >= 1 && vb.nwide <= bvh.nnodes, "round %d: wide tree of %u nodes for %u binary nodes",
              round, vb.nwide, bvh.nnodes);
        CHECK(wide_mismatches == 0, "round %d: %d rays disagree between the wide tree and brute force", round,
              wide_mismatches);
        CHECK(ntri + nsph < 50 || hits > 0, "round %d: no ray hit anything", round);
        rt_accel_free(&bvh);
        rt_accel_free(&none);
        rt_scene_free(&s);
    }
    /* the random triangles overlap: spatial splits put some of them in
     * several leaves, and the hits above still matched brute force */
    CHECK(copies > 0, "no spatial split in 12 random scenes");
}

/* Scenes of 1..12 primitives: the wide tree of a tree that fits in one
 * merged leaf still has a root node, passes the checks and finds the hits
 * brute force finds. */
static void test_bvh_tiny(void)
{
    unsigned long long seed = 99;
    for (int n = 1; n <= 12; n++) {
        RtScene s;
        random_scene(&s, &seed, n, n % 3 == 0 ? 1 : 0);
        RtAccel bvh, none;
        RtError e;
        CHECK(rt_accel_build(&s, RT_ACCEL_BVH, &bvh, &e) == 0, "%s", e.msg);
        CHECK(rt_accel_build(&s, RT_ACCEL_NONE, &none, &e) == 0, "%s", e.msg);
        CHECK(rt_bvh_check(&bvh, &e) == 0, "%d primitives: %s", n, e.msg);
        CHECK(bvh.wide && bvh.nwide >= 1 && bvh.wide[0].count >= 1, "%d primitives: wide root", n);
        RtCamera cam;
        memset(&cam, 0, sizeof cam);
        RtSceneView vb = rt_scene_view(&s, &bvh, &cam), vn = rt_scene_view(&s, &none, &cam);
        int mismatches = 0;
        for (int k = 0; k < 500; k++) {
            RtVec3 o = rt_v3(check_randf(&seed, -15, 15), check_randf(&seed, -15, 15), check_randf(&seed, -15, 15));
            RtVec3 d = rt_normalize(rt_v3(-o.x + check_randf(&seed, -3, 3), -o.y + check_randf(&seed, -3, 3),
                                          -o.z + check_randf(&seed, -3, 3)));
            RtHit hw, hn;
            RtCounters c;
            memset(&c, 0, sizeof c);
            int fw = rt_trace_ray_wide(&vb, o, d, RT_INF, 0, &hw, &c);
            int fn = rt_trace_ray(&vn, o, d, RT_INF, 0, &hn, &c);
            if (fw != fn || (fn && (hw.t != hn.t || hw.id != hn.id)))
                mismatches++;
        }
        CHECK(mismatches == 0, "%d primitives: %d rays disagree between the wide tree and brute force", n, mismatches);
        rt_accel_free(&bvh);
        rt_accel_free(&none);
        rt_scene_free(&s);
    }
}

/* Equal distances go to the lower primitive index, in both accelerators. */
static void test_tie_break(void)
{
    const char *text = "vertex: -1 -1 -2\nvertex: 1 -1 -2\nvertex: 0 1 -2\n"
                       "triangle: 0 1 2\ntriangle: 2 1 0\ntriangle: 0 1 2\n";
    RtScene s;
    RtError e;
    CHECK(rt_scene_parse_buffer("tie.txt", text, strlen(text), &s, NULL, NULL, &e) == 0, "%s", e.msg);
    RtAccel a[2];
    RtCamera cam;
    memset(&cam, 0, sizeof cam);
    for (int k = 0; k < 2; k++) {
        CHECK(rt_accel_build(&s, k ? RT_ACCEL_BVH : RT_ACCEL_NONE, &a[k], &e) == 0, "%s", e.msg);
        RtSceneView v = rt_scene_view(&s, &a[k], &cam);
        RtHit h;
        RtCounters c;
        memset(&c, 0, sizeof c);
        CHECK(rt_trace_ray(&v, rt_v3(0, 0, 0), rt_v3(0, 0, -1), RT_INF, 0, &h, &c), "hit");
        CHECK(h.id == 0, "accel %d: tie went to primitive %u, not 0", k, h.id);
        rt_accel_free(&a[k]);
    }
    rt_scene_free(&s);
}

/* A hand-built broken tree is rejected by the invariant check. */
static void test_bvh_check_catches(void)
{
    unsigned long long seed = 7;
    RtScene s;
    random_scene(&s, &seed, 100, 10);
    RtAccel a;
    RtError e;
    CHECK(rt_accel_build(&s, RT_ACCEL_BVH, &a, &e) == 0, "%s", e.msg);
    CHECK(a.nnodes > 3, "tree has interior nodes");
    for (uint32_t i = 0; i < a.nnodes; i++)
        if (a.nodes[i].meta & 0xff) {
            uint32_t saved = a.nodes[i].index;
            a.nodes[i].index = (saved + 1) % a.nprims; /* now one slot is referenced twice */
            CHECK(rt_bvh_check(&a, &e) != 0, "duplicated reference not caught");
            a.nodes[i].index = saved;
            uint32_t meta = a.nodes[i].meta;
            a.nodes[i].meta = (meta & ~0xffu) | 5u; /* leaf of 5 */
            CHECK(rt_bvh_check(&a, &e) != 0, "oversized leaf not caught");
            a.nodes[i].meta = meta;
            break;
        }
    /* the wide copy: a leaf range referenced twice, a bad child index, a box
     * outside its parent */
    CHECK(a.wide && a.nwide > 1, "a wide tree with inner nodes");
    uint32_t c0 = a.wide[0].child[0], c1 = a.wide[0].child[1];
    a.wide[0].child[1] = c0;
    CHECK(rt_bvh_check(&a, &e) != 0, "wide child referenced twice not caught");
    a.wide[0].child[1] = a.nwide + 7;
    CHECK(rt_bvh_check(&a, &e) != 0, "wide child out of range not caught");
    a.wide[0].child[1] = c1;
    CHECK(rt_bvh_check(&a, &e) == 0, "restored wide tree refused: %s", e.msg);
    for (uint32_t i = 1; i < a.nwide; i++) {
        float saved = a.wide[i].hi_x[0];
        a.wide[i].hi_x[0] = 1e30f;
        CHECK(rt_bvh_check(&a, &e) != 0, "wide child outside its parent not caught");
        a.wide[i].hi_x[0] = saved;
        break;
    }
    /* an empty slot must hold an inside-out box: the traversal's slab test
     * misses it without looking at the child (a 3-triangle scene is one
     * leaf under a root with three empty slots) */
    RtScene ts;
    RtAccel t;
    random_scene(&ts, &seed, 3, 0);
    CHECK(rt_accel_build(&ts, RT_ACCEL_BVH, &t, &e) == 0, "%s", e.msg);
    int empty_seen = 0;
    for (uint32_t i = 0; i < t.nwide && !empty_seen; i++)
        if (t.wide[i].count < 4) {
            const uint32_t k = t.wide[i].count;
            CHECK(t.wide[i].lo_x[k] == INFINITY && t.wide[i].hi_z[k] == -INFINITY, "empty slot %u of node %u: box", k, i);
            float saved = t.wide[i].lo_y[k];
            t.wide[i].lo_y[k] = 0.0f;
            CHECK(rt_bvh_check(&t, &e) != 0, "empty wide slot with a box not caught");
            t.wide[i].lo_y[k] = saved;
            CHECK(rt_bvh_check(&t, &e) == 0, "restored wide tree refused: %s", e.msg);
            empty_seen = 1;
        }
    CHECK(empty_seen, "the wide tree of a 3-triangle scene has a node with an empty slot");
    rt_accel_free(&t);
    rt_scene_free(&ts);
    a.nodes[0].hi[0] = a.nodes[0].lo[0]; /* children now stick out */
    CHECK(rt_bvh_check(&a, &e) != 0, "child outside parent not caught");
    rt_accel_free(&a);
    rt_scene_free(&s);
}

int main(void)
{
    test_sphere();
    test_triangle();
    test_camera();
    test_tie_break();
    test_bvh_random();
    test_bvh_tiny();
    test_bvh_check_catches();
    return check_report("test_geometry");
}
