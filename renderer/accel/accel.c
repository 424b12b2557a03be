/* accel.c - the accelerators' public entry (rt.h): brute force ("none": the
 * primitive records alone) and the BVH, built by the files beside this one.
 *
 * One build: binned SAH (sah.c) with spatial splits (spatial.c) in large
 * nodes whose best object split leaves overlapping children; leaves of at
 * most RtBvhSettings.leaf_max records; nodes written depth-first (build.c);
 * spheres and triangles in one tree; then its 4-wide copy (wide.c). Its
 * settings are an RtBvhSettings (settings.c), each build reading its own.
 *
 * The build runs on all the threads it is given and makes the same tree on
 * any number of them, so every backend's images and counters stay
 * bit-identical: large subtrees are tasks writing arrays of their own
 * (tasks.c), and large nodes bin and partition fixed chunks of references in
 * parallel, merged exactly (sah.c, partition.c). Its threads are a pool of
 * its own (pool.c) that sleep rather than spin while they wait. Its large
 * arrays may ask for 2 MiB pages (huge_pages.c). The invariants are checked
 * by check.c. */
#include <stdlib.h>
#include <string.h>

#include "build_internal.h"

const char *rt_accel_name(RtAccelKind k) { return k == RT_ACCEL_BVH ? "bvh" : "none"; }

int rt_accel_parse(const char *s, RtAccelKind *k)
{
    if (strcmp(s, "none") == 0) { *k = RT_ACCEL_NONE; return 0; }
    if (strcmp(s, "bvh") == 0) { *k = RT_ACCEL_BVH; return 0; }
    return -1;
}

/* make_prims's loop: one chunk of triangles' records. */
typedef struct PrimsJob {
    const RtScene *s;
    RtPrim *p;
    uint32_t chunk;
} PrimsJob;

static void prims_chunk(void *ctx, int c)
{
    const PrimsJob *j = ctx;
    const RtScene *s = j->s;
    uint32_t i0, i1;
    chunk_range(s->ntriangles, j->chunk, c, &i0, &i1);
    for (uint32_t i = i0; i < i1; i++) {
        RtPrim *q = &j->p[s->nspheres + i];
        const RtTriangle *t = &s->triangles[i];
        RtVec3 a = s->vertices[t->v[0]], b = s->vertices[t->v[1]], c3 = s->vertices[t->v[2]];
        RtVec3 e1 = rt_sub(b, a), e2 = rt_sub(c3, a);
        q->p0[0] = a.x; q->p0[1] = a.y; q->p0[2] = a.z;
        q->e1[0] = e1.x; q->e1[1] = e1.y; q->e1[2] = e1.z;
        q->e2[0] = e2.x; q->e2[1] = e2.y; q->e2[2] = e2.z;
        q->id = s->nspheres + i;
    }
}

/* The primitive records in the scene's order: its spheres, then its
 * triangles (a vertex and two edges each). */
static RtPrim *make_prims(const RtScene *s, const RtBvhSettings *set, RtPool *pool, int on, uint32_t *n_out,
                          RtError *err)
{
    uint64_t n = (uint64_t)s->nspheres + s->ntriangles;
    if (n >= RT_PRIM_SPHERE_BIT) {
        rt_fail(err, "%s: %llu primitives exceed the limit of %u", s->source.path, (unsigned long long)n,
                RT_PRIM_SPHERE_BIT - 1);
        return NULL;
    }
    RtPrim *p = bvh_huge_hint(calloc(n ? n : 1, sizeof *p), (size_t)n * sizeof *p, on);
    if (!p) {
        rt_fail(err, "out of memory for %llu primitive records", (unsigned long long)n);
        return NULL;
    }
    for (uint32_t i = 0; i < s->nspheres; i++) {
        memcpy(p[i].p0, s->spheres[i].c, sizeof p[i].p0);
        p[i].e1[0] = s->spheres[i].r;
        p[i].id = i | RT_PRIM_SPHERE_BIT;
    }
    const uint32_t chunk = (uint32_t)set->chunk;
    PrimsJob job = {s, p, chunk};
    pool_for(pool, chunks_covering(s->ntriangles, chunk), prims_chunk, &job);
    *n_out = (uint32_t)n;
    return p;
}

/* The records and, for a BVH, the tree and its 4-wide copy, on the pool. */
static int build_on(const RtScene *s, RtAccelKind kind, const RtBvhSettings *set, RtPool *pool, RtAccel *a,
                    RtError *err)
{
    uint32_t n = 0;
    RtPrim *prims = make_prims(s, set, pool, a->huge_pages, &n, err);
    if (!prims)
        return -1;
    a->nprims = n;
    if (kind == RT_ACCEL_NONE || n == 0) {
        a->prims = prims;
        return 0;
    }
    if (bvh_build_binary(s, set, prims, n, pool, a, err) != 0)
        return -1;
    a->sah_cost = bvh_sah_cost(a->nodes, a->nnodes, pool);
    bvh_widen(a, set, pool); /* optional: without it the GPU traverses the binary tree */
    return 0;
}

int rt_accel_build_with(const RtScene *s, RtAccelKind kind, const RtBvhSettings *set, RtAccel *a, RtError *err)
{
    const RtBvhSettings def = rt_bvh_settings_default();
    if (!set)
        set = &def;
    memset(a, 0, sizeof *a);
    a->kind = kind;
    a->build_threads = 1;
    if (rt_bvh_settings_check(set, err) != 0)
        return -1;
    const int nt = bvh_build_threads(set, (uint64_t)s->nspheres + s->ntriangles);
    a->huge_pages = bvh_huge_pages_on(set, nt);
    RtPool *pool = pool_start(nt);
    a->build_threads = pool_threads(pool);
    const int rc = build_on(s, kind, set, pool, a, err);
    pool_stop(pool);
    return rc;
}

int rt_accel_build_threads(const RtScene *s, RtAccelKind kind, int threads, RtAccel *a, RtError *err)
{
    RtBvhSettings set = rt_bvh_settings_default();
    set.threads = threads;
    return rt_accel_build_with(s, kind, &set, a, err);
}

int rt_accel_build(const RtScene *s, RtAccelKind kind, RtAccel *a, RtError *err)
{
    return rt_accel_build_with(s, kind, NULL, a, err);
}

int rt_accel_host(RtAccel *a, RtError *err)
{
    return a->device && a->device_host ? a->device_host(a, err) : 0;
}

void rt_accel_free(RtAccel *a)
{
    if (a->device && a->device_free)
        a->device_free(a->device);
    if (!a->mapped) {
        free(a->prims);
        free(a->nodes);
        free(a->wide);
    }
    memset(a, 0, sizeof *a);
}
