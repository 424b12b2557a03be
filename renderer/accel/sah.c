/* sah.c - binned SAH (Wald 2007, "On fast construction of SAH-based
 * bounding volume hierarchies"): the bins of a node's references, the sweep
 * that finds the cheapest plane between bins, the object split over
 * centroid bins, and the SAH cost of a finished tree.
 *
 * In large nodes the bins are filled over fixed chunks of references in
 * parallel and merged by min, max and integer sums, which are exact in any
 * order, so the split is the same on any number of threads (Wald 2007,
 * section 4, does the same horizontally). */
#include <stdlib.h>
#include <string.h>

#include "build_internal.h"
#define RT_WIDE_LEAF_VOTE(has_leaf, any) (has_leaf) /* rt_traverse.h asks for it; no ray is traced here */
#include "core/rt_traverse.h" /* RT_SSE */

/* The tree's SAH cost sums fixed chunks of nodes in order: fixed here, not
 * RtBvhSettings.chunk, so that the reported cost does not move in its last
 * bits with a setting that leaves the tree alone. */
#define SAH_COST_CHUNK 16384

/* Sweeps nb bins (boxes, and counts entering from the left and right) for
 * the cheapest plane between two bins; updates *best when cheaper. */
void bvh_sweep(const Box *bins, const uint32_t *lcnt, const uint32_t *rcnt, int nb, int axis, Split *best,
               int spatial)
{
    Box rbox[BVH_MAX_BINS], acc;
    uint32_t rsum[BVH_MAX_BINS], c = 0;
    box_empty(&acc);
    for (int k = nb - 1; k > 0; k--) {
        box_grow(&acc, &bins[k]);
        c += rcnt[k];
        rbox[k] = acc;
        rsum[k] = c;
    }
    box_empty(&acc);
    c = 0;
    for (int k = 0; k < nb - 1; k++) {
        box_grow(&acc, &bins[k]);
        c += lcnt[k];
        if (c == 0 || rsum[k + 1] == 0)
            continue;
        float cost = box_area(&acc) * (float)c + box_area(&rbox[k + 1]) * (float)rsum[k + 1];
        if (cost < best->cost) {
            best->cost = cost;
            best->axis = axis;
            best->spatial = spatial;
            best->bin = k;
            best->nbins = nb;
            best->left = acc;
            best->right = rbox[k + 1];
        }
    }
}

void bvh_bins_empty(Bins *b, int nb)
{
    for (int a = 0; a < 3; a++)
        for (int k = 0; k < nb; k++) {
            box_empty(&b->box[a][k]);
            b->in[a][k] = b->out[a][k] = 0;
        }
}

static void bins_merge(Bins *to, const Bins *from, int nb)
{
    for (int a = 0; a < 3; a++)
        for (int k = 0; k < nb; k++) {
            box_grow(&to->box[a][k], &from->box[a][k]);
            to->in[a][k] += from->in[a][k];
            to->out[a][k] += from->out[a][k];
        }
}

/* Centroid bins of refs[i0..i1) on the axes with scale[a] > 0. With SSE a
 * bin's box grows by one min and one max over four lanes (the fourth is
 * ignored): the same values as box_grow, which the same comparisons define. */
#if RT_SSE
static void object_bins(const Builder *b, const Ref *refs, uint32_t i0, uint32_t i1, const Box *cb,
                        const float *scale, int nb, Bins *o)
{
    __m128 lo[3][BVH_MAX_BINS], hi[3][BVH_MAX_BINS];
    (void)b;
    bvh_bins_empty(o, nb);
    for (int a = 0; a < 3; a++)
        for (int k = 0; k < nb; k++) {
            lo[a][k] = _mm_set1_ps(RT_INF);
            hi[a][k] = _mm_set1_ps(-RT_INF);
        }
    const __m128 half = _mm_set1_ps(0.5f);
    for (uint32_t i = i0; i < i1; i++) {
        /* (the loads read lo[0..2] and hi[0], then hi[0..2] and the prim
         * index: both inside the Ref) */
        const __m128 l = _mm_loadu_ps(refs[i].box.lo), h = _mm_loadu_ps(refs[i].box.hi);
        float c[4];
        _mm_storeu_ps(c, _mm_mul_ps(half, _mm_add_ps(l, h)));
        for (int a = 0; a < 3; a++) {
            if (!(scale[a] > 0.0f))
                continue;
            const int k = bin_of(c[a], cb->lo[a], scale[a], 0, nb - 1);
            o->in[a][k]++;
            lo[a][k] = _mm_min_ps(lo[a][k], l);
            hi[a][k] = _mm_max_ps(hi[a][k], h);
        }
    }
    for (int a = 0; a < 3; a++)
        for (int k = 0; k < nb; k++) {
            float l4[4], h4[4];
            _mm_storeu_ps(l4, lo[a][k]);
            _mm_storeu_ps(h4, hi[a][k]);
            memcpy(o->box[a][k].lo, l4, sizeof o->box[a][k].lo);
            memcpy(o->box[a][k].hi, h4, sizeof o->box[a][k].hi);
        }
}
#else
static void object_bins(const Builder *b, const Ref *refs, uint32_t i0, uint32_t i1, const Box *cb,
                        const float *scale, int nb, Bins *o)
{
    (void)b;
    bvh_bins_empty(o, nb);
    for (uint32_t i = i0; i < i1; i++)
        for (int a = 0; a < 3; a++) {
            if (!(scale[a] > 0.0f))
                continue;
            const int k = bin_of(ref_cent(&refs[i], a), cb->lo[a], scale[a], 0, nb - 1);
            o->in[a][k]++;
            box_grow(&o->box[a][k], &refs[i].box);
        }
}
#endif

/* One chunk's bins (bvh_bins_all's loop). */
typedef struct BinsJob {
    BinFn fn;
    const Builder *b;
    const Ref *refs;
    uint32_t count;
    const Box *box;
    const float *scale;
    int nb;
    Bins *part;
} BinsJob;

static void bins_chunk(void *ctx, int c)
{
    const BinsJob *j = ctx;
    uint32_t i0, i1;
    chunk_range(j->count, (uint32_t)j->b->set->chunk, c, &i0, &i1);
    j->fn(j->b, j->refs, i0, i1, j->box, j->scale, j->nb, &j->part[c]);
}

/* The bins of refs[0..count) by fn, over chunks in parallel in a large node;
 * with keep, each chunk's own bins go there (the caller frees them; NULL
 * when there was one chunk). */
void bvh_bins_all(BinFn fn, const Builder *b, const Ref *refs, uint32_t count, const Box *box, const float *scale,
                  int nb, Bins *o, Bins **keep)
{
    if (keep)
        *keep = NULL;
    const int nc = nchunks(count, (uint32_t)b->set->chunk);
    Bins *part = nc > 1 ? malloc((size_t)nc * sizeof *part) : NULL;
    if (!part) {
        fn(b, refs, 0, count, box, scale, nb, o);
        return;
    }
    BinsJob job = {fn, b, refs, count, box, scale, nb, part};
    pool_for(b->pool, nc, bins_chunk, &job);
    bvh_bins_empty(o, nb);
    for (int c = 0; c < nc; c++)
        bins_merge(o, &part[c], nb);
    if (keep)
        *keep = part;
    else
        free(part);
}

/* nb bins per unit of each axis of box b; 0 on an axis of no extent. */
void bvh_bin_scales(const Box *b, int nb, float *scale)
{
    for (int a = 0; a < 3; a++) {
        const float w = b->hi[a] - b->lo[a];
        scale[a] = w > 0.0f ? (float)nb / w : 0.0f;
    }
}

/* Binned SAH over the references' centroids (cb: their bounds); each
 * chunk's bins into *parts (bvh_bins_all's keep). */
void bvh_object_split(const Builder *b, const Ref *refs, uint32_t count, const Box *cb, int nb, Split *best,
                      Bins **parts)
{
    float scale[3];
    bvh_bin_scales(cb, nb, scale);
    Bins bins;
    bvh_bins_all(object_bins, b, refs, count, cb, scale, nb, &bins, parts);
    for (int a = 0; a < 3; a++)
        if (scale[a] > 0.0f)
            bvh_sweep(bins.box[a], bins.in[a], bins.in[a], nb, a, best, 0);
}

/* One chunk's share of the SAH cost (bvh_sah_cost's loop). */
typedef struct CostJob {
    const RtBvhNode *nodes;
    uint32_t nnodes;
    double *part;
} CostJob;

static void cost_chunk(void *ctx, int k)
{
    const CostJob *j = ctx;
    uint32_t i0, i1;
    chunk_range(j->nnodes, SAH_COST_CHUNK, k, &i0, &i1);
    double sum = 0.0;
    for (uint32_t i = i0; i < i1; i++) {
        const uint32_t count = j->nodes[i].meta & 0xffu;
        sum += node_area(&j->nodes[i]) * (count ? (double)count : 1.0);
    }
    j->part[k] = sum;
}

/* The tree's SAH cost (traversal and intersection cost 1, as the build
 * weighs them): the expected work of a ray that meets the root's box. */
double bvh_sah_cost(const RtBvhNode *nodes, uint32_t nnodes, RtPool *pool)
{
    const double root = node_area(&nodes[0]);
    if (!(root > 0.0))
        return 0.0;
    /* (fixed chunks summed in order: the same value on any thread count) */
    const int nc = chunks_covering(nnodes, SAH_COST_CHUNK);
    double *part = malloc((size_t)nc * sizeof *part), c = 0.0;
    if (!part)
        return 0.0;
    CostJob job = {nodes, nnodes, part};
    pool_for(pool, nc, cost_chunk, &job);
    for (int k = 0; k < nc; k++)
        c += part[k];
    free(part);
    return c / root;
}
