/* test_parse_threads.c - a large scene parsed in parallel chunks gives the
 * serial parser's result byte for byte (renderer/io/scene_parse.c): the
 * pools, materials, lights and settings, every warning in order, and for a
 * broken file the same first error. The scene (about 12 MB, three chunks
 * and more) mixes vertices, normals, both kinds of triangle, spheres,
 * materials that change between them, lights, unknown commands and
 * comments. Each fault is planted at a few places: an error in a later
 * chunk must not hide an earlier one, of either pass. The parse hands its
 * vertices and triangles to a sink (rt.h's RtGeomSink) once each, final. */
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "rt.h"

typedef struct Log {
    char text[1 << 16];
    size_t len;
} Log;

static void on_warn(void *ctx, const char *msg)
{
    Log *l = ctx;
    l->len += (size_t)snprintf(l->text + l->len, sizeof l->text - l->len, "%s\n", msg);
}

/* A scene of `blocks` blocks; fault f planted in block `at` (0: none), and
 * fault f2 in block at2. */
static char *make_scene(int blocks, int f, int at, int f2, int at2, size_t *len)
{
    size_t cap = (size_t)blocks * 1200 + 4096, k = 0;
    char *b = malloc(cap);
    k += (size_t)snprintf(b + k, cap - k, "film_resolution: 64 48\ncamera_pos: 0 0 9\n# a comment\n");
    for (int i = 0; i < blocks; i++) {
        const int v = 4 * i, n = 2 * i;
        if (i % 500 == 0)
            k += (size_t)snprintf(b + k, cap - k, "material: .1 .1 .1 .%d .5 .5 0 0 0 %d 0 0 0 1\n", i % 9, i % 7 + 1);
        if (i % 1500 == 7)
            k += (size_t)snprintf(b + k, cap - k, "shininess: %d\n", i); /* unknown: warned */
        if (i % 2500 == 11)
            k += (size_t)snprintf(b + k, cap - k, "point_light: 1 1 1 %d 5 5\n", i % 10);
        k += (size_t)snprintf(b + k, cap - k,
                              "vertex: %d.25 1.5 -%d\nvertex: %d.5 2.5 -3\nvertex: 1 %d.75 -2  # tail\nvertex: 0 0 -%d\n"
                              "normal: 0 0 1\nnormal: 0 1 0\ntriangle: %d %d %d\nnormal_triangle: %d %d %d %d %d %d\n"
                              "sphere: %d 1 -20 0.5\n\n",
                              i % 97, i % 13 + 1, i % 31, i % 17, i % 5 + 1, v, v + 1, v + 2, v + 1, v + 2, v + 3, n, n,
                              n + 1, i % 50);
        if ((i == at && f == 1) || (i == at2 && f2 == 1))
            k += (size_t)snprintf(b + k, cap - k, "vertex: 1 2 x3\n"); /* pass 1: a bad number */
        if ((i == at && f == 2) || (i == at2 && f2 == 2))
            k += (size_t)snprintf(b + k, cap - k, "triangle: %d 0 1\n", v + 4); /* pass 2: a forward index */
        if ((i == at && f == 3) || (i == at2 && f2 == 3))
            k += (size_t)snprintf(b + k, cap - k, "material: 1 1 1 1 1 1 1 1 1 1 1 1 1 0\n"); /* a deferred line */
        if ((i == at && f == 4) || (i == at2 && f2 == 4))
            k += (size_t)snprintf(b + k, cap - k, "normal_triangle: 0 1 2 0 0 %d\n", n + 2);
        if ((i == at && f == 5) || (i == at2 && f2 == 5))
            k += (size_t)snprintf(b + k, cap - k, "bad line without a colon\n");
    }
    *len = k;
    return b;
}

static int same_scene(const RtScene *a, const RtScene *b)
{
#define SAME_POOL(f, n) (a->n == b->n && memcmp(a->f, b->f, (size_t)a->n * sizeof *a->f) == 0)
    return SAME_POOL(vertices, nvertices) && SAME_POOL(normals, nnormals) && SAME_POOL(triangles, ntriangles) &&
           SAME_POOL(spheres, nspheres) && SAME_POOL(materials, nmaterials) && SAME_POOL(lights, nlights) &&
           memcmp(&a->settings, &b->settings, (const char *)(a + 1) - (const char *)&a->settings) == 0;
#undef SAME_POOL
}

/* Serial against 2 and 5 threads; returns the serial parse's status. */
static int compare(const char *what, const char *buf, size_t len)
{
    static const int threads[] = {2, 5};
    RtScene s1, s2;
    RtError e1, e2;
    static Log w1, w2;
    w1.len = 0;
    const int rc1 = rt_scene_parse_buffer_threads("big.txt", buf, len, 1, &s1, on_warn, &w1, &e1);
    for (size_t i = 0; i < sizeof threads / sizeof threads[0]; i++) {
        w2.len = 0;
        const int rc2 = rt_scene_parse_buffer_threads("big.txt", buf, len, threads[i], &s2, on_warn, &w2, &e2);
        CHECK(rc1 == rc2, "%s, %d threads: status %d, serial %d (%s)", what, threads[i], rc2, rc1,
              rc2 ? e2.msg : e1.msg);
        if (rc1 == 0 && rc2 == 0)
            CHECK(same_scene(&s1, &s2), "%s, %d threads: the scene differs", what, threads[i]);
        if (rc1 != 0 && rc2 != 0)
            CHECK(strcmp(e1.msg, e2.msg) == 0, "%s, %d threads: '%s', serial '%s'", what, threads[i], e2.msg, e1.msg);
        CHECK(w1.len == w2.len && memcmp(w1.text, w2.text, w1.len) == 0, "%s, %d threads: other warnings", what,
              threads[i]);
        rt_scene_free(&s2);
    }
    rt_scene_free(&s1);
    return rc1;
}

/* A sink as a device copy would use it: each range copied into shadow
 * pools at once, each element counted. */
typedef struct Shadow {
    pthread_mutex_t mu; /* (ready comes from the parse's threads at once) */
    const RtScene *sc;
    int sized, overlap, outside;
    RtVec3 *v;
    RtTriangle *t;
    unsigned char *seen[2];
    uint32_t cap[2];
} Shadow;

static void sh_sized(void *ctx, const RtScene *sc)
{
    Shadow *s = ctx;
    s->sized++;
    s->sc = sc;
    s->cap[0] = sc->cap_vertices;
    s->cap[1] = sc->cap_triangles;
    s->v = malloc((size_t)s->cap[0] * sizeof *s->v);
    s->t = malloc((size_t)s->cap[1] * sizeof *s->t);
    s->seen[0] = calloc(s->cap[0], 1);
    s->seen[1] = calloc(s->cap[1], 1);
}

static void sh_ready(void *ctx, int pool, uint32_t first, uint32_t count)
{
    Shadow *s = ctx;
    pthread_mutex_lock(&s->mu);
    {
        if ((uint64_t)first + count > s->cap[pool]) {
            s->outside++;
        } else {
            if (pool == RT_GEOM_VERTICES)
                memcpy(s->v + first, s->sc->vertices + first, (size_t)count * sizeof *s->v);
            else
                memcpy(s->t + first, s->sc->triangles + first, (size_t)count * sizeof *s->t);
            for (uint32_t k = first; k < first + count; k++)
                s->overlap += s->seen[pool][k]++ != 0;
        }
    }
    pthread_mutex_unlock(&s->mu);
}

static void sh_end(void *ctx, int keep) { (void)ctx, (void)keep; }

/* The sink's ranges on `threads` threads: sized once at the final sizes,
 * every vertex and triangle handed on once, final when handed on. */
static void check_sink(const char *buf, size_t len, int threads)
{
    Shadow sh;
    memset(&sh, 0, sizeof sh);
    pthread_mutex_init(&sh.mu, NULL);
    const RtGeomSink sink = {&sh, sh_sized, sh_ready, sh_end};
    RtScene sc;
    RtError e;
    const int rc = rt_scene_parse_buffer_sink("big.txt", buf, len, threads, &sink, &sc, NULL, NULL, &e);
    CHECK(rc == 0, "sink, %d threads: %s", threads, e.msg);
    if (threads == 1) {
        CHECK(sh.sized == 0, "sink, 1 thread: sized %d times (the serial parse hands nothing on)", sh.sized);
        rt_scene_free(&sc);
        return;
    }
    CHECK(sh.sized == 1, "sink, %d threads: sized %d times", threads, sh.sized);
    if (rc == 0 && sh.sized == 1) {
        CHECK(sh.cap[0] == sc.nvertices && sh.cap[1] == sc.ntriangles, "sink: sized %u and %u, the scene has %u and %u",
              sh.cap[0], sh.cap[1], sc.nvertices, sc.ntriangles);
        CHECK(sh.overlap == 0 && sh.outside == 0, "sink: %d elements handed on twice, %d ranges outside", sh.overlap,
              sh.outside);
        uint32_t missed = 0;
        for (int pl = 0; pl < 2; pl++)
            for (uint32_t k = 0; k < sh.cap[pl]; k++)
                missed += !sh.seen[pl][k];
        CHECK(missed == 0, "sink, %d threads: %u elements never handed on", threads, missed);
        CHECK(memcmp(sh.v, sc.vertices, (size_t)sc.nvertices * sizeof *sh.v) == 0 &&
                  memcmp(sh.t, sc.triangles, (size_t)sc.ntriangles * sizeof *sh.t) == 0,
              "sink, %d threads: a range changed after it was handed on", threads);
    }
    free(sh.v), free(sh.t), free(sh.seen[0]), free(sh.seen[1]);
    pthread_mutex_destroy(&sh.mu);
    rt_scene_free(&sc);
}

int main(void)
{
    const int blocks = 60000; /* about 12 MB */
    size_t len;
    char *buf = make_scene(blocks, 0, 0, 0, 0, &len);
    CHECK(len > 3 * (4u << 20), "the scene is %zu bytes, too small to be split", len);
    CHECK(compare("clean", buf, len) == 0, "the clean scene failed");
    check_sink(buf, len, 1);
    check_sink(buf, len, 2);
    check_sink(buf, len, 5);
    free(buf);
    const int where[] = {1, 30000, 59990};
    for (int f = 1; f <= 5; f++)
        for (int w = 0; w < 3; w++) {
            char what[64];
            snprintf(what, sizeof what, "fault %d at block %d", f, where[w]);
            buf = make_scene(blocks, f, where[w], 0, 0, &len);
            CHECK(compare(what, buf, len) != 0, "%s: accepted", what);
            free(buf);
        }
    /* two faults in different chunks: the earlier wins, whichever pass finds it */
    const int pairs[][2] = {{2, 1}, {1, 2}, {3, 1}, {4, 5}, {2, 3}, {3, 4}};
    for (size_t i = 0; i < sizeof pairs / sizeof pairs[0]; i++) {
        char what[64];
        snprintf(what, sizeof what, "faults %d then %d", pairs[i][0], pairs[i][1]);
        buf = make_scene(blocks, pairs[i][0], 3000, pairs[i][1], 45000, &len);
        CHECK(compare(what, buf, len) != 0, "%s: accepted", what);
        free(buf);
    }
    return check_report("parse-threads");
}
