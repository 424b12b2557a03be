/* scene_fixture.h - what the traversal tests share: a scene loaded with its
 * camera, BVH and view, and the comparison of two hits bit for bit.
 * Include after check.h and rt.h (and core/rt_traverse.h). */
#ifndef RT_SCENE_FIXTURE_H
#define RT_SCENE_FIXTURE_H

/* Loads path with its camera and BVH; 0, or -1 after a failed CHECK (the
 * scene freed). */
static inline int fixture_load(const char *path, RtScene *s, RtAccel *a, RtCamera *cam, RtSceneView *v)
{
    RtError e;
    if (rt_scene_load(path, s, NULL, NULL, &e) != 0) {
        CHECK(0, "%s", e.msg);
        return -1;
    }
    if (rt_scene_camera(s, cam, &e) != 0 || rt_accel_build(s, RT_ACCEL_BVH, a, &e) != 0) {
        CHECK(0, "%s", e.msg);
        rt_scene_free(s);
        return -1;
    }
    *v = rt_scene_view(s, a, cam);
    CHECK(v->wide != NULL, "%s: no wide tree", path);
    return 0;
}

/* Frees what fixture_load made. */
static inline void fixture_free(RtScene *s, RtAccel *a)
{
    rt_accel_free(a);
    rt_scene_free(s);
}

/* The same answer: both found nothing, or the same t, u, v and primitive. */
static inline int fixture_same(int fa, const RtHit *a, int fb, const RtHit *b)
{
    return fa == fb && (!fa || (a->t == b->t && a->id == b->id && a->u == b->u && a->v == b->v));
}

#endif
