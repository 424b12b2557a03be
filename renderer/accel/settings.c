/* settings.c - the BVH build's settings (RtBvhSettings, rt.h): their
 * defaults, their valid ranges, and what they decide for one build (its
 * threads, its 2 MiB pages, the GPU build's pieces). Each build reads its
 * own settings, so builds running at once never decide for each other. */
#include <stdlib.h>
#include <string.h>

#include "build_internal.h"
#define RT_WIDE_LEAF_VOTE(has_leaf, any) (has_leaf) /* rt_traverse.h asks for it; no ray is traced here */
#include "core/rt_traverse.h" /* RT_BVH_MAX_DEPTH: the traversal stack bounds the build */

RtBvhSettings rt_bvh_settings_default(void)
{
    RtBvhSettings s;
    s.threads = 0;
    /* A second thread that the other cores' work delays costs more at every
     * join than a small build gains (docs/performance.md, "Build threads"). */
    s.prims_per_thread = 16384;
    s.huge_pages = -1;
    /* Page faults contend when many threads fault fresh arrays at once; with
     * few threads the pages cost more than they save (docs/performance.md,
     * "Large scenes"). */
    s.huge_pages_threads = 8;
    s.bins = 32;
    s.sah_depth = 44;
    s.leaf_max = RT_BVH_LEAF_MAX;
    s.wide_merge = 4;
    /* Spatial splits pay where triangles are large against the node, near
     * the top of the tree; trying them in every node costs build time for no
     * better tree (docs/architecture.md, "The BVH"). */
    s.spatial_min = 128;
    s.spatial_share = 2048;
    s.spatial_overlap = 0.1f;
    s.task_min = 4096;
    s.wide_task_min = 65536;
    s.chunk = 16384;
    /* Chosen for each scene (rt_bvh_gpu_split_pct): pieces pay only in
     * scenes of very unequal triangles (docs/performance.md, "The GPU
     * build"). */
    s.gpu_split = -1;
    return s;
}

/* Whether v lies in lo..hi; otherwise the error names the setting. */
static int in_range(const char *name, int v, int lo, int hi, RtError *err)
{
    if (v >= lo && v <= hi)
        return 0;
    return rt_fail(err, "BVH settings: %s is %d, outside %d..%d", name, v, lo, hi);
}

/* The ranges keep the build's arrays and encodings in bounds: the bins'
 * arrays, the leaf count of both trees' nodes, the traversal stack. */
int rt_bvh_settings_check(const RtBvhSettings *s, RtError *err)
{
    if (in_range("prims_per_thread", s->prims_per_thread, 1, INT32_MAX, err) != 0 ||
        in_range("huge_pages", s->huge_pages, -1, 1, err) != 0 ||
        in_range("huge_pages_threads", s->huge_pages_threads, 1, INT32_MAX, err) != 0 ||
        in_range("bins", s->bins, 2, BVH_MAX_BINS, err) != 0 ||
        in_range("sah_depth", s->sah_depth, 0, RT_BVH_MAX_DEPTH, err) != 0 ||
        in_range("leaf_max", s->leaf_max, 1, RT_BVH_LEAF_MAX, err) != 0 ||
        in_range("wide_merge", s->wide_merge, 1, BVH_WIDE_MERGE_MAX, err) != 0 ||
        in_range("spatial_min", s->spatial_min, 0, INT32_MAX, err) != 0 ||
        in_range("spatial_share", s->spatial_share, 1, INT32_MAX, err) != 0 ||
        in_range("task_min", s->task_min, 1, INT32_MAX, err) != 0 ||
        in_range("wide_task_min", s->wide_task_min, 1, INT32_MAX, err) != 0 ||
        in_range("chunk", s->chunk, 64, 1 << 30, err) != 0 || in_range("gpu_split", s->gpu_split, -1, 100, err) != 0)
        return -1;
    if (!(s->spatial_overlap >= 0.0f) || isinf(s->spatial_overlap))
        return rt_fail(err, "BVH settings: spatial_overlap is %g, not a fraction >= 0", (double)s->spatial_overlap);
    return 0;
}

/* The threads a build of nprims primitives runs on: s->threads when set,
 * else one per prims_per_thread primitives, at most the threads OpenMP
 * offers; a build of fewer than two threads' worth starts no thread. */
int bvh_build_threads(const RtBvhSettings *s, uint64_t nprims)
{
    const uint64_t per = (uint64_t)s->prims_per_thread;
    int nt = rt_thread_count(s->threads);
    if (s->threads <= 0 && (uint64_t)nt > nprims / per)
        nt = nprims < 2 * per ? 1 : (int)(nprims / per);
    return nt;
}

/* Whether a build on `threads` threads asks for 2 MiB pages. */
int bvh_huge_pages_on(const RtBvhSettings *s, int threads)
{
    return s->huge_pages == 1 || (s->huge_pages < 0 && threads >= s->huge_pages_threads);
}

/* ---- the GPU build's pieces, chosen for a scene ---------------------------- */

#define SPLIT_AUTO_MIN 65536  /* triangles: fewer, no pieces (the GPU build's own default
                               * starts at as many primitives) */
#define SPLIT_SAMPLE 16384    /* triangles looked at, evenly spaced */
#define SPLIT_OUTSIZED 16.0f  /* a box this many times the median box's area is outsized */
#define SPLIT_AUTO_SHARE 0.5  /* the outsized boxes' share of the excess that calls for pieces */

/* The k-th smallest of a[0..n) (Hoare's selection; a is reordered; no NaN). */
static float select_kth(float *a, int n, int k)
{
    int lo = 0, hi = n - 1;
    while (lo < hi) {
        const float pivot = a[lo + (hi - lo) / 2];
        int i = lo, j = hi;
        while (i <= j) {
            while (a[i] < pivot)
                i++;
            while (a[j] > pivot)
                j--;
            if (i <= j) {
                const float t = a[i];
                a[i++] = a[j];
                a[j--] = t;
            }
        }
        if (k <= j)
            hi = j;
        else if (k >= i)
            lo = i;
        else
            return a[k];
    }
    return a[k];
}

/* One sampled triangle's box area and its excess over twice Karras and
 * Aila's A_ideal (as bvh_gpu_split.cuh counts it); 0 where not finite. */
static void split_sample(const RtScene *s, const RtTriangle *t, float *area, float *excess)
{
    const RtVec3 a = s->vertices[t->v[0]], b = s->vertices[t->v[1]], c = s->vertices[t->v[2]];
    Box box;
    box_empty(&box);
    box_grow_pt(&box, (const float[3]){a.x, a.y, a.z});
    box_grow_pt(&box, (const float[3]){b.x, b.y, b.z});
    box_grow_pt(&box, (const float[3]){c.x, c.y, c.z});
    const float ar = box_area(&box), x = ar - 2.0f * rt_tri_ideal_area(a, b, c);
    *area = isfinite(ar) ? ar : 0.0f;
    *excess = isfinite(x) && x > 0.0f ? x : 0.0f;
}

double rt_bvh_split_outsized(const RtScene *s)
{
    const uint32_t n = s->ntriangles, m = n < SPLIT_SAMPLE ? n : SPLIT_SAMPLE;
    float *area = m ? malloc(3 * (size_t)m * sizeof *area) : NULL;
    if (!area)
        return 0.0;
    float *excess = area + m, *order = area + 2 * (size_t)m;
    for (uint32_t k = 0; k < m; k++)
        split_sample(s, &s->triangles[(uint64_t)k * n / m], &area[k], &excess[k]);
    uint32_t npos = 0; /* (the median of the boxes with an area: slivers along an axis have none) */
    for (uint32_t k = 0; k < m; k++)
        if (area[k] > 0.0f)
            order[npos++] = area[k];
    if (npos == 0) {
        free(area);
        return 0.0;
    }
    const float limit = SPLIT_OUTSIZED * select_kth(order, (int)npos, (int)(npos / 2));
    double total = 0.0, outsized = 0.0;
    for (uint32_t k = 0; k < m; k++) {
        total += excess[k];
        outsized += area[k] > limit ? excess[k] : 0.0;
    }
    free(area);
    return total > 0.0 ? outsized / total : 0.0;
}

int rt_bvh_gpu_split_pct(const RtBvhSettings *set, const RtScene *s, double *outsized)
{
    if (outsized)
        *outsized = -1.0;
    if (set->gpu_split >= 0)
        return set->gpu_split;
    if (s->ntriangles < SPLIT_AUTO_MIN)
        return 0;
    const double share = rt_bvh_split_outsized(s);
    if (outsized)
        *outsized = share;
    return share >= SPLIT_AUTO_SHARE ? 100 : 0;
}
