/* settings.c - the BVH build's settings (RtBvhSettings, rt.h): their
 * defaults, their valid ranges, and what they decide for one build (its
 * threads, its 2 MiB pages). Each build reads its own settings, so builds
 * running at once never decide for each other. */
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
    /* Off: on the large stand-ins only objects-1m renders faster with
     * pieces, and every build takes longer (docs/performance.md, "The GPU
     * build"). */
    s.gpu_split = 0;
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
        in_range("chunk", s->chunk, 64, 1 << 30, err) != 0 || in_range("gpu_split", s->gpu_split, 0, 100, err) != 0)
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
