/* test_wide.c SCENE... - the 4-wide BVH traversal against the binary one on
 * real scenes: every primary ray of the scene's camera, and from each hit the
 * shadow ray towards every light (any hit, both queries: RT_ANY_HIT, children
 * sorted, and RT_ANY_HIT_SLOT, children in slot order) and the mirror ray
 * (closest hit), must give bit-identical hits (t, u, v, primitive). A scene
 * named course:PATH is read from the course scenes' folder (tests/course.sh:
 * RAYBENCH_COURSE_DIR, else RAYBENCH_COURSE_DEFAULT); exit 77 when one of
 * those is missing. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
/* the CPU's leaf vote (rt_traverse.h): a leaf at once */
#define RT_WIDE_LEAF_VOTE(has_leaf, any) (has_leaf)
#include "core/rt_shade.h"
#include "rt.h"
#include "scene_fixture.h"

static void check_scene(const char *path)
{
    RtScene s;
    RtAccel a;
    RtCamera cam;
    RtSceneView v;
    if (fixture_load(path, &s, &a, &cam, &v) != 0)
        return;
    RtCounters cb, cw, cs; /* binary, wide, wide shadow rays in slot order */
    memset(&cb, 0, sizeof cb);
    memset(&cw, 0, sizeof cw);
    memset(&cs, 0, sizeof cs);
    long rays = 0, bad = 0, shadows = 0, bad_slot = 0;
    for (int j = 0; v.wide && j < cam.height; j++)
        for (int i = 0; i < cam.width; i++) {
            RtRay r = rt_camera_ray(&cam, i, j);
            RtHit hb, hw;
            int fb = rt_trace_ray(&v, r.o, r.d, RT_INF, 0, &hb, &cb);
            int fw = rt_trace_ray_wide(&v, r.o, r.d, RT_INF, 0, &hw, &cw);
            rays++;
            bad += !fixture_same(fb, &hb, fw, &hw);
            if (!fb)
                continue;
            RtSurface sf = rt_surface(&v, r.o, r.d, &hb);
            const RtMaterial *m = &v.materials[sf.material];
            RtVec3 so = rt_shadow_origin(&sf);
            for (uint32_t li = 0; li < v.nlights; li++) {
                RtVec3 c, L;
                float dist;
                if (!rt_light_sample(&v, &sf, m, rt_neg(r.d), li, &c, &L, &dist))
                    continue;
                fb = rt_trace_ray(&v, so, L, dist, 1, &hb, &cb);
                fw = rt_trace_ray_wide(&v, so, L, dist, RT_ANY_HIT, &hw, &cw);
                const int fs = rt_trace_ray_wide(&v, so, L, dist, RT_ANY_HIT_SLOT, &hw, &cs);
                rays++;
                shadows++;
                bad += fb != fw;
                bad_slot += fb != fs;
            }
            RtVec3 R = rt_normalize(rt_sub(r.d, rt_scale(sf.n, 2.0f * rt_dot(r.d, sf.n))));
            RtVec3 ro = rt_madd(sf.p, R, RT_SECONDARY_OFFSET);
            fb = rt_trace_ray(&v, ro, R, RT_INF, 0, &hb, &cb);
            fw = rt_trace_ray_wide(&v, ro, R, RT_INF, 0, &hw, &cw);
            rays++;
            bad += !fixture_same(fb, &hb, fw, &hw);
        }
    CHECK(bad == 0, "%s: %ld of %ld rays differ between the wide and the binary tree", path, bad, rays);
    CHECK(bad_slot == 0, "%s: %ld of %ld shadow rays in slot order differ between the wide and the binary tree", path,
          bad_slot, shadows);
    printf("%s: %ld rays, %u binary / %u wide nodes, visits %.2f / %.2f per ray, tests %.2f / %.2f\n", path, rays,
           a.nnodes, a.nwide, (double)cb.node_visits / (double)rays, (double)cw.node_visits / (double)rays,
           (double)cb.prim_tests / (double)rays, (double)cw.prim_tests / (double)rays);
    printf("%s: %ld shadow rays in slot order, visits %.2f per ray\n", path, shadows,
           shadows ? (double)cs.node_visits / (double)shadows : 0.0);
    fixture_free(&s, &a);
}

int main(int argc, char **argv)
{
    char buf[4096];
    if (check_scenes_present(argc, argv) != 0)
        return 77;
    for (int k = 1; k < argc; k++)
        check_scene(check_scene_path(argv[k], buf, sizeof buf));
    return check_report("test_wide");
}
