/* embree_render.c - a raybench scene rendered with Intel Embree's traversal,
 * for the CPU comparison of scripts/bench-embree.sh (docs/performance.md,
 * "Against Embree").
 *
 *   embree-render [-r WxH] [-o IMAGE] [--runs N] SCENE
 *
 * Everything but the ray queries is raybench's: its parser, camera, and the
 * Whitted loop of core/rt_path_tmpl.h with RENDERING-RULES' shading, over the
 * same 32x32 tiles as the serial backend on one thread. Each closest-hit and
 * shadow query goes to Embree 3 (rtcIntersect1 / rtcOccluded1, one ray at a
 * time, as raybench's CPU path traces them) on its high-quality tree with
 * spatial splits: triangles as triangle geometry, spheres as sphere points.
 * Prints "embree-render: scene=S width=W height=H render_ms=T" per run (T the
 * pixel loop, as raytrace's render_ms); the image is for a look (its hits
 * differ from raybench's in the last bits of some t). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "embree_scene.h"
#define RT_WIDE_LEAF_VOTE(has_leaf, any) (has_leaf) /* rt_traverse.h asks for it; Embree traces here */
#include "core/rt_traverse.h" /* RtHit, RT_T_MIN */

static RTCScene g_scene; /* the query target of embree_trace (one thread) */
static struct RTCIntersectContext g_ctx;

/* RT_PATH_TRACE for Embree: the same contract as rt_trace_ray (1 on a hit;
 * for a closest-hit query *hit filled as raybench fills it). */
static int embree_trace(const RtSceneView *s, RtVec3 o, RtVec3 d, float tmax, int any, RtHit *hit)
{
    struct RTCRayHit rh;
    rh.ray.org_x = o.x; rh.ray.org_y = o.y; rh.ray.org_z = o.z;
    rh.ray.dir_x = d.x; rh.ray.dir_y = d.y; rh.ray.dir_z = d.z;
    rh.ray.tnear = RT_T_MIN;
    rh.ray.tfar = tmax < RT_INF ? tmax : INFINITY;
    rh.ray.time = 0.0f;
    rh.ray.mask = 0xffffffffu;
    rh.ray.id = 0;
    rh.ray.flags = 0;
    if (any) {
        rtcOccluded1(g_scene, &g_ctx, &rh.ray);
        return rh.ray.tfar < 0.0f; /* Embree's mark of an occluded ray */
    }
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(g_scene, &g_ctx, &rh);
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID)
        return 0;
    hit->t = rh.ray.tfar;
    hit->u = rh.hit.u;
    hit->v = rh.hit.v;
    /* geometry 0: the triangles, 1: the spheres (raybench's global ids) */
    hit->id = rh.hit.geomID == 0 ? s->nspheres + rh.hit.primID : rh.hit.primID | RT_PRIM_SPHERE_BIT;
    return 1;
}

#define RT_PATH_TRACE(s, o, d, tmax, any, hit, cnt, light) embree_trace(s, o, d, tmax, any, hit)
#define RT_PATH_NAME(f) f
#define RT_PATH_FN static inline
#include "core/rt_path_tmpl.h"

static int fail(const char *msg)
{
    fprintf(stderr, "embree-render: %s\n", msg);
    return 1;
}

static void add_spheres(RTCDevice dev, RTCScene scene, const RtScene *sc)
{
    RTCGeometry g = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_SPHERE_POINT);
    float *v = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT4, 4 * sizeof(float),
                                       sc->nspheres);
    for (uint32_t i = 0; v && i < sc->nspheres; i++) {
        memcpy(&v[4 * i], sc->spheres[i].c, 3 * sizeof(float));
        v[4 * i + 3] = sc->spheres[i].r;
    }
    rtcCommitGeometry(g);
    rtcAttachGeometryByID(scene, g, 1);
    rtcReleaseGeometry(g);
}

/* One render of the whole image over 32x32 tiles; its time in ms. */
static double render_once(const RtSceneView *v, float *rgb)
{
    RtCounters cnt;
    memset(&cnt, 0, sizeof cnt);
    const int w = v->cam.width, h = v->cam.height, n = rt_tile_count(w, h, 32, 32);
    const double t0 = rt_now_ms();
    for (int t = 0; t < n; t++) {
        int x0, y0, x1, y1;
        rt_tile_rect(w, h, 32, 32, t, &x0, &y0, &x1, &y1);
        rt_render_tile(v, x0, y0, x1, y1, rgb + 3 * ((size_t)y0 * (size_t)w + (size_t)x0), 3 * (size_t)w, &cnt);
    }
    return rt_now_ms() - t0;
}

typedef struct {
    const char *scene, *image;
    int w, h, runs;
} Args;

static int parse_args(int argc, char **argv, Args *a)
{
    memset(a, 0, sizeof *a);
    a->runs = 1;
    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "-r") == 0 && i + 1 < argc) {
            if (rt_parse_wxh(argv[++i], 16384, &a->w, &a->h) != 0)
                return fail("-r: expected WxH, e.g. 640x480");
        } else if (strcmp(argv[i], "-o") == 0 && i + 1 < argc) {
            a->image = argv[++i];
        } else if (strcmp(argv[i], "--runs") == 0 && i + 1 < argc) {
            if (rt_parse_int(argv[++i], 1, 1000, &a->runs) != 0)
                return fail("--runs: expected an integer from 1 to 1000");
        } else if (!a->scene && argv[i][0] != '-') {
            a->scene = argv[i];
        } else {
            return fail("usage: embree-render [-r WxH] [-o IMAGE] [--runs N] SCENE");
        }
    }
    return a->scene ? 0 : fail("usage: embree-render [-r WxH] [-o IMAGE] [--runs N] SCENE");
}

static int render_all(const Args *a, RtScene *sc, RtError *err)
{
    RtCamera cam;
    RtAccel accel; /* brute force: only the primitive records the shading reads */
    if (a->w) {
        sc->settings.width = a->w;
        sc->settings.height = a->h;
    }
    if (rt_scene_camera(sc, &cam, err) != 0 || rt_accel_build(sc, RT_ACCEL_NONE, &accel, err) != 0)
        return fail(err->msg);
    RTCDevice dev = rtcNewDevice("threads=1");
    g_scene = rtcNewScene(dev);
    rtcSetSceneBuildQuality(g_scene, RTC_BUILD_QUALITY_HIGH);
    RTCGeometry tris = sc->ntriangles ? embree_triangles(dev, sc) : NULL;
    if (tris) {
        rtcAttachGeometryByID(g_scene, tris, 0);
        rtcReleaseGeometry(tris);
    }
    if (sc->nspheres)
        add_spheres(dev, g_scene, sc);
    rtcCommitScene(g_scene);
    rtcInitIntersectContext(&g_ctx);
    int rc = rtcGetDeviceError(dev) == RTC_ERROR_NONE ? 0 : fail("Embree could not build the scene");
    const RtSceneView v = rt_scene_view(sc, &accel, &cam);
    const size_t npix = (size_t)cam.width * (size_t)cam.height;
    float *rgb = malloc(npix * 3 * sizeof *rgb);
    uint8_t *img = malloc(npix * 3);
    for (int r = 0; rc == 0 && rgb && img && r < a->runs; r++)
        printf("embree-render: scene=%s width=%d height=%d render_ms=%.3f\n", sc->source.name, cam.width, cam.height,
               render_once(&v, rgb));
    if (rc == 0 && (!rgb || !img))
        rc = fail("out of memory for the image");
    if (rc == 0 && a->image) {
        rt_image_quantize(rgb, img, npix);
        if (rt_image_write(a->image, img, cam.width, cam.height, err) != 0)
            rc = fail(err->msg);
    }
    free(rgb);
    free(img);
    rtcReleaseScene(g_scene);
    rtcReleaseDevice(dev);
    rt_accel_free(&accel);
    return rc;
}

int main(int argc, char **argv)
{
    Args a;
    if (parse_args(argc, argv, &a) != 0)
        return 1;
    RtScene sc;
    RtError err;
    memset(&sc, 0, sizeof sc);
    if (rt_scene_load(a.scene, &sc, NULL, NULL, &err) != 0)
        return fail(err.msg);
    int rc = render_all(&a, &sc, &err);
    rt_scene_free(&sc);
    return rc;
}
