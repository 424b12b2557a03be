/* fuzz_cache.c - scene cache entries as someone who can write the cache
 * folder might make them: the input is an entry's bytes, sealed with a
 * correct payload hash (anyone can compute it), then parsed for both
 * accelerators; whatever rt_cache_entry_parse accepts is rendered at 8x6
 * through the shared shading code, so an index or a tree the checks let
 * through shows up as a sanitizer error here. The seed corpus is entries
 * raytrace wrote, remade by scripts/make-cache-seeds.sh whenever the
 * entry format changes (then no seed parses and the test fails). */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "rt.h"

/* render_small's loop, every ray through rt_trace_ray (rt_traverse.h's leaf
 * vote, the CPU's, goes unused) */
#define RT_WIDE_LEAF_VOTE(has_leaf, any) (has_leaf)
#define RT_PATH_TRACE(s, o, d, tmax, any, hit, cnt, light) rt_trace_ray(s, o, d, tmax, any, hit, cnt)
#define RT_PATH_NAME(f) f
#define RT_PATH_FN static inline
#include "core/rt_path_tmpl.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static unsigned long accepted; /* inputs that parsed as an entry */

/* A corpus of which no entry parses any more (the format changed) fuzzes
 * nothing but the header check: that fails the test. */
static void report(void)
{
    fprintf(stderr, "fuzz_cache: %lu inputs accepted as entries\n", accepted);
    if (accepted == 0) {
        fprintf(stderr, "fuzz_cache: no input parsed: remake the seed corpus (scripts/make-cache-seeds.sh)\n");
        _exit(1);
    }
}

static void render_small(RtScene *s, const RtAccel *a)
{
    s->settings.width = 8, s->settings.height = 6;
    if (s->settings.max_depth > 3) /* (2^depth rays a pixel where glass both reflects and refracts) */
        s->settings.max_depth = 3;
    RtCamera cam;
    RtError err;
    if (rt_scene_camera(s, &cam, &err) != 0)
        return;
    const RtSceneView v = rt_scene_view(s, a, &cam);
    RtCounters cnt;
    memset(&cnt, 0, sizeof cnt);
    float rgb[8 * 6 * 3];
    for (int j = 0; j < 6; j++)
        for (int i = 0; i < 8; i++)
            rt_render_pixel(&v, i, j, RT_ANY_HIT, rgb, &cnt);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static int once;
    if (!once++)
        atexit(report);
    const size_t cap = (size + 63) / 64 * 64 + 64;
    for (int kind = RT_ACCEL_NONE; kind <= RT_ACCEL_BVH; kind++) {
        void *buf = aligned_alloc(64, cap); /* (a parse may leave pointers into it: fresh per kind) */
        if (!buf)
            return 0;
        memcpy(buf, data, size);
        rt_cache_entry_seal(buf, size);
        RtScene s;
        RtAccel a;
        RtError err;
        if (rt_cache_entry_parse(buf, size, (RtAccelKind)kind, &s, &a, &err) == 0) {
            accepted++;
            render_small(&s, &a);
            rt_scene_free_deps(&s);
        }
        free(buf);
    }
    return 0;
}
