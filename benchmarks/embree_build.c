/* embree_build.c - Intel Embree's BVH build of a raybench scene's triangles,
 * timed, for the build comparison in scripts/bench-large.sh
 * (docs/performance.md, "Large scenes").
 *
 *   embree-build [--threads N] [--repeats R] SCENE
 *
 * The scene is read by raybench's own parser; Embree 3 builds its
 * high-quality tree (RTC_BUILD_QUALITY_HIGH: binned SAH with spatial splits)
 * over the triangles on N threads (default: all). Prints one line per repeat:
 * "embree-build: threads=N ms=T". Spheres are left out (Embree would build
 * them as user geometry); the benchmark scenes have none. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "embree_scene.h"

static int fail(const char *msg)
{
    fprintf(stderr, "embree-build: %s\n", msg);
    return 1;
}

/* One build of the scene's triangles; its time in ms, or < 0. */
static double build_once(RTCDevice dev, const RtScene *sc)
{
    RTCScene scene = rtcNewScene(dev);
    rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_HIGH);
    RTCGeometry g = embree_triangles(dev, sc);
    if (!g) {
        rtcReleaseScene(scene);
        return -1.0;
    }
    rtcAttachGeometry(scene, g);
    rtcReleaseGeometry(g);
    const double t0 = rt_now_ms();
    rtcCommitScene(scene);
    const double ms = rt_now_ms() - t0;
    const int ok = rtcGetDeviceError(dev) == RTC_ERROR_NONE;
    rtcReleaseScene(scene);
    return ok ? ms : -1.0;
}

int main(int argc, char **argv)
{
    int threads = 0, repeats = 1;
    const char *path = NULL;
    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--threads") == 0 && i + 1 < argc) {
            if (rt_parse_int(argv[++i], 1, 4096, &threads) != 0)
                return fail("--threads: expected an integer from 1 to 4096");
        } else if (strcmp(argv[i], "--repeats") == 0 && i + 1 < argc) {
            if (rt_parse_int(argv[++i], 1, 1000, &repeats) != 0)
                return fail("--repeats: expected an integer from 1 to 1000");
        } else if (!path && argv[i][0] != '-') {
            path = argv[i];
        } else {
            return fail("usage: embree-build [--threads N] [--repeats R] SCENE");
        }
    }
    if (!path)
        return fail("usage: embree-build [--threads N] [--repeats R] SCENE");
    RtScene sc;
    RtError err;
    memset(&sc, 0, sizeof sc);
    if (rt_scene_load(path, &sc, NULL, NULL, &err) != 0)
        return fail(err.msg);
    char cfg[64] = "";
    if (threads > 0)
        snprintf(cfg, sizeof cfg, "threads=%d", threads);
    RTCDevice dev = rtcNewDevice(cfg);
    if (!dev) {
        rt_scene_free(&sc);
        return fail("rtcNewDevice failed");
    }
    int rc = 0;
    for (int r = 0; r < repeats && rc == 0; r++) {
        const double ms = build_once(dev, &sc);
        if (ms < 0.0)
            rc = fail("the build failed (out of memory?)");
        else
            printf("embree-build: scene=%s triangles=%u threads=%d ms=%.1f\n", sc.source.name, sc.ntriangles, threads,
                   ms);
    }
    rtcReleaseDevice(dev);
    rt_scene_free(&sc);
    return rc;
}
