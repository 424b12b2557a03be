/* test_build_threads.c - the BVH build makes the same tree on any number of
 * threads (renderer/accel/): the binary nodes, the primitive records
 * in leaf order and the 4-wide copy are compared byte for byte between 1, 2,
 * 3 and 7 threads, on a scene large enough for every parallel path (tasks,
 * chunked binning and partition, the 4-wide copy's subtree tasks from 65536
 * records) and with triangles long enough that spatial
 * splits cut some of them (checked: the build adds records). Scenes named on
 * the command line are compared too. And the default thread count: one
 * thread per 16,384 primitives at most (the OpenMP threads permitting), so a
 * small build starts no thread. And the other choice the settings make for
 * one scene, the GPU build's pieces (rt_bvh_gpu_split_pct): 100 for a scene
 * whose long triangles hold the excess box area, 0 for triangles all alike
 * and for small scenes, a set percentage as set. And no build leaves a
 * thread behind. */
#include <dirent.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "check.h"
#include "rt.h"

enum { LONG_ONES, ALIKE, AXIS_SLIVERS };

/* n triangles: most small, every 16th long and thin across the scene
 * (LONG_ONES); all small (ALIKE); or 3 in 5 collinear along x, boxes
 * without area, the rest small (AXIS_SLIVERS). */
static char *random_scene(int n, int kind, size_t *len)
{
    unsigned long long seed = 42;
    size_t cap = 256 + (size_t)n * 160;
    char *buf = malloc(cap);
    size_t k = (size_t)snprintf(buf, cap, "film_resolution: 32 24\ncamera_pos: 0 0 30\npoint_light: 1 1 1 0 20 20\n");
    for (int i = 0; i < n; i++) {
        const float x = check_randf(&seed, -20, 20), y = check_randf(&seed, -15, 15), z = check_randf(&seed, -20, 5);
        const float r = i % 16 == 0 && kind == LONG_ONES ? 12.0f : 0.3f;
        if (kind == AXIS_SLIVERS && i % 5 < 3) {
            k += (size_t)snprintf(buf + k, cap - k, "vertex: %g %g %g\nvertex: %g %g %g\nvertex: %g %g %g\n", x, y, z,
                                  x + 0.2f, y, z, x + 0.5f, y, z);
            continue;
        }
        k += (size_t)snprintf(buf + k, cap - k, "vertex: %g %g %g\nvertex: %g %g %g\nvertex: %g %g %g\n", x, y, z,
                              x + check_randf(&seed, -r, r), y + check_randf(&seed, -0.3f, 0.3f), z,
                              x + check_randf(&seed, -0.3f, 0.3f), y + check_randf(&seed, -r, r),
                              z + check_randf(&seed, -0.3f, 0.3f));
    }
    for (int i = 0; i < n; i++)
        k += (size_t)snprintf(buf + k, cap - k, "triangle: %d %d %d\n", 3 * i, 3 * i + 1, 3 * i + 2);
    *len = k;
    return buf;
}

static int same(const RtAccel *a, const RtAccel *b)
{
    return a->nnodes == b->nnodes && a->nprims == b->nprims && a->nwide == b->nwide && a->nsplit == b->nsplit &&
           memcmp(a->nodes, b->nodes, (size_t)a->nnodes * sizeof *a->nodes) == 0 &&
           memcmp(a->prims, b->prims, (size_t)a->nprims * sizeof *a->prims) == 0 &&
           memcmp(a->wide, b->wide, (size_t)a->nwide * sizeof *a->wide) == 0 && a->sah_cost == b->sah_cost;
}

/* The threads of this process (/proc/self/task): a build's threads end
 * with it, so none waits, sleeping or spinning, once it returned. */
static int process_threads(void)
{
    DIR *d = opendir("/proc/self/task");
    int n = 0;
    for (struct dirent *e; d && (e = readdir(d));)
        n += e->d_name[0] != '.';
    if (d)
        closedir(d);
    return n;
}

/* The threads once no more than `most` are left, or after 2 s: a joined
 * thread may stay listed a moment while the kernel reaps it. most < 0:
 * once the count held still for 10 ms. */
static int settled_threads(int most)
{
    int n = process_threads(), still = 0;
    for (int i = 0; i < 400; i++) {
        if (most >= 0 ? n <= most : still >= 2)
            break;
        nanosleep(&(struct timespec){0, 5000000}, NULL);
        const int m = process_threads();
        still = m == n ? still + 1 : 0;
        n = m;
    }
    return n;
}

static void compare_threads(const char *name, const RtScene *sc, int want_splits)
{
    static const int threads[] = {1, 2, 3, 7};
    RtAccel ref, a;
    RtError err;
    if (rt_accel_build_threads(sc, RT_ACCEL_BVH, 1, &ref, &err) != 0) {
        CHECK(0, "%s: build: %s", name, err.msg);
        return;
    }
    CHECK(rt_bvh_check(&ref, &err) == 0, "%s: %s", name, err.msg);
    if (want_splits)
        CHECK(ref.nsplit > 0, "%s: no spatial split: the test does not reach that path", name);
    for (size_t i = 1; i < sizeof threads / sizeof threads[0]; i++) {
        const int before = settled_threads(-1);
        const int rc = rt_accel_build_threads(sc, RT_ACCEL_BVH, threads[i], &a, &err);
        const int after = settled_threads(before);
        CHECK(after <= before, "%s: %d threads before a build on %d, %d after it", name, before, threads[i], after);
        if (rc != 0) {
            CHECK(0, "%s: build on %d threads: %s", name, threads[i], err.msg);
            continue;
        }
        CHECK(same(&ref, &a), "%s: the tree on %d threads differs from the tree on 1 (nodes %u/%u, records %u/%u)",
              name, threads[i], a.nnodes, ref.nnodes, a.nprims, ref.nprims);
        rt_accel_free(&a);
    }
    /* with the 2 MiB page hint forced on (auto leaves it off below
     * RtBvhSettings.huge_pages_threads; it marks the arrays of 4 MiB and
     * more: the node arrays here), on 3 threads: the same tree */
    CHECK(!ref.huge_pages, "%s: one build thread asked for huge pages by default", name);
    RtBvhSettings set = rt_bvh_settings_default();
    set.threads = 3;
    set.huge_pages = 1;
    if (rt_accel_build_with(sc, RT_ACCEL_BVH, &set, &a, &err) == 0) {
        CHECK(a.huge_pages && same(&ref, &a), "%s: the tree with huge pages differs", name);
        rt_accel_free(&a);
    } else {
        CHECK(0, "%s: build with huge pages: %s", name, err.msg);
    }
    rt_accel_free(&ref);
}

/* The GPU build's pieces as the settings choose them for a scene of n
 * triangles of a kind (random_scene), against want. */
static void split_choice(int n, int kind, int set_pct, int want)
{
    static const char *kinds[] = {"with long ones", "alike", "mostly slivers along an axis"};
    size_t len;
    char *buf = random_scene(n, kind, &len);
    RtScene sc;
    RtError err;
    if (rt_scene_parse_buffer("split", buf, len, &sc, NULL, NULL, &err) != 0) {
        CHECK(0, "split scene: %s", err.msg);
        free(buf);
        return;
    }
    free(buf);
    RtBvhSettings set = rt_bvh_settings_default();
    set.gpu_split = set_pct;
    double share = -2.0;
    const int got = rt_bvh_gpu_split_pct(&set, &sc, &share);
    CHECK(got == want, "%d triangles %s, gpu_split %d: %d%% pieces (outsized share %.3f), expected %d%%", n,
          kinds[kind], set_pct, got, share, want);
    CHECK(set_pct >= 0 || n < 65536 ? share == -1.0 : share >= 0.0 && share <= 1.0,
          "%d triangles, gpu_split %d: share %.3f", n, set_pct, share);
    rt_scene_free(&sc);
}

int main(int argc, char **argv)
{
    split_choice(80000, LONG_ONES, -1, 100);
    split_choice(80000, ALIKE, -1, 0);
    split_choice(80000, AXIS_SLIVERS, -1, 0); /* (the median box has no area: the median of those with one) */
    split_choice(20000, LONG_ONES, -1, 0);    /* (below 65,536 triangles) */
    split_choice(80000, LONG_ONES, 30, 30);
    split_choice(80000, ALIKE, 0, 0);
    RtScene sc;
    RtError err;
    size_t len;
    char *buf = random_scene(80000, LONG_ONES, &len);
    CHECK(rt_scene_parse_buffer("random", buf, len, &sc, NULL, NULL, &err) == 0, "random scene: %s", err.msg);
    free(buf);
    compare_threads("random", &sc, 1);
    {
        RtAccel a;
        const int omp = rt_thread_count(0), want = omp < 4 ? omp : 4; /* 80,000 primitives: 4 */
        CHECK(rt_accel_build_threads(&sc, RT_ACCEL_BVH, 0, &a, &err) == 0 && a.build_threads == want,
              "random: the default build ran %d threads, expected %d", a.build_threads, want);
        rt_accel_free(&a);
    }
    rt_scene_free(&sc);
    buf = random_scene(100, LONG_ONES, &len);
    CHECK(rt_scene_parse_buffer("small", buf, len, &sc, NULL, NULL, &err) == 0, "small scene: %s", err.msg);
    free(buf);
    {
        RtAccel a;
        CHECK(rt_accel_build_threads(&sc, RT_ACCEL_BVH, 0, &a, &err) == 0 && a.build_threads == 1,
              "small: 100 primitives built on %d threads by default, expected 1", a.build_threads);
        rt_accel_free(&a);
    }
    rt_scene_free(&sc);
    for (int i = 1; i < argc; i++) {
        if (rt_scene_load(argv[i], &sc, NULL, NULL, &err) != 0) {
            CHECK(0, "%s", err.msg);
            continue;
        }
        compare_threads(argv[i], &sc, 0);
        rt_scene_free(&sc);
    }
    return check_report("build-threads");
}
