/* partition.c - a node's references and its children's: their bounds, the
 * children's arrays, the object split's partition (which bounds each side
 * on the way) and the object-median fallback. In a large node the bounds
 * and the object partition run over fixed chunks of references in
 * parallel (RtBvhSettings.chunk): bounds
 * merge by min and max, exact in any order, and the partition keeps the
 * serial order, so the tree is the same on any number of threads. */
#include <stdlib.h>
#include <string.h>

#include "build_internal.h"

/* The bounds of refs[i0..i1): their boxes (bc[0]) and their centroids (bc[1]). */
static void bounds_range(const Ref *refs, uint32_t i0, uint32_t i1, Box *bc)
{
    box_empty(&bc[0]);
    box_empty(&bc[1]);
    for (uint32_t i = i0; i < i1; i++) {
        float c[3] = {ref_cent(&refs[i], 0), ref_cent(&refs[i], 1), ref_cent(&refs[i], 2)};
        box_grow(&bc[0], &refs[i].box);
        box_grow_pt(&bc[1], c);
    }
}

/* One chunk's bounds (bvh_bounds's loop). */
typedef struct BoundsJob {
    const Ref *refs;
    uint32_t count, chunk;
    Box (*part)[2];
} BoundsJob;

static void bounds_chunk(void *ctx, int c)
{
    const BoundsJob *j = ctx;
    uint32_t i0, i1;
    chunk_range(j->count, j->chunk, c, &i0, &i1);
    bounds_range(j->refs, i0, i1, j->part[c]);
}

/* The bounds of refs[0..count): their boxes (bb) and their centroids (cb). */
void bvh_bounds(const Builder *b, const Ref *refs, uint32_t count, Box *bb, Box *cb)
{
    const uint32_t chunk = (uint32_t)b->set->chunk;
    const int nc = nchunks(count, chunk);
    Box (*part)[2] = nc > 1 ? malloc((size_t)nc * sizeof *part) : NULL;
    Box bc[2];
    if (!part) {
        bounds_range(refs, 0, count, bc);
    } else {
        BoundsJob job = {refs, count, chunk, part};
        pool_for(b->pool, nc, bounds_chunk, &job);
        box_empty(&bc[0]);
        box_empty(&bc[1]);
        for (int c = 0; c < nc; c++) {
            box_grow(&bc[0], &part[c][0]);
            box_grow(&bc[1], &part[c][1]);
        }
        free(part);
    }
    *bb = bc[0];
    *cb = bc[1];
}

/* The children's reference arrays of a node of count references, allocated
 * once (a second call keeps them); 0 (and b->oom) when out of memory. */
int bvh_halves(Builder *b, uint32_t count, Ref **left, Ref **right)
{
    if (*left)
        return 1;
    *left = bvh_alloc((size_t)count * sizeof **left, b->huge);
    *right = bvh_alloc((size_t)count * sizeof **right, b->huge);
    if (*left && *right)
        return 1;
    free(*left);
    free(*right);
    *left = *right = NULL;
    b->oom = 1;
    return 0;
}

static int obj_left(const Ref *r, const Box *cb, const Split *obj, float scale)
{
    return bin_of(ref_cent(r, obj->axis), cb->lo[obj->axis], scale, 0, obj->nbins - 1) <= obj->bin;
}

/* A reference into a child's array, its box and centroid into the child's
 * bounds bc (bvh_bounds's values: min and max, exact in any order). */
static inline void put_ref(Ref *to, const Ref *r, Box *bc)
{
    const float c[3] = {ref_cent(r, 0), ref_cent(r, 1), ref_cent(r, 2)};
    *to = *r;
    box_grow(&bc[0], &r->box);
    box_grow_pt(&bc[1], c);
}

/* The object split's partition of refs[i0..i1) from slots l and r on,
 * each side's bounds grown into lb and rb; the left side's end. */
static uint32_t object_partition_range(const Ref *refs, uint32_t i0, uint32_t i1, const Box *cb, const Split *obj,
                                       float scale, Ref *left, uint32_t l, Ref *right, uint32_t r, Box *lb, Box *rb)
{
    for (uint32_t i = i0; i < i1; i++) {
        if (obj_left(&refs[i], cb, obj, scale))
            put_ref(&left[l++], &refs[i], lb);
        else
            put_ref(&right[r++], &refs[i], rb);
    }
    return l;
}

/* The object partition's loops over chunks: each chunk's count on the left
 * (unless the split's bins counted them), then (from their prefix sums) its
 * references moved and each side's bounds. */
typedef struct PartJob {
    const Ref *refs;
    uint32_t count, chunk;
    const Box *cb;
    const Split *obj;
    float scale;
    uint32_t *nleft;
    Ref *left, *right;
    Box (*bounds)[4]; /* per chunk: the left side's box and centroids, the right side's */
} PartJob;

static void part_count(void *ctx, int c)
{
    const PartJob *j = ctx;
    uint32_t i0, i1, k = 0;
    chunk_range(j->count, j->chunk, c, &i0, &i1);
    for (uint32_t i = i0; i < i1; i++)
        k += (uint32_t)obj_left(&j->refs[i], j->cb, j->obj, j->scale);
    j->nleft[c] = k;
}

static void part_move(void *ctx, int c)
{
    const PartJob *j = ctx;
    uint32_t i0, i1;
    chunk_range(j->count, j->chunk, c, &i0, &i1);
    Box *bc = j->bounds[c];
    for (int k = 0; k < 4; k++)
        box_empty(&bc[k]);
    object_partition_range(j->refs, i0, i1, j->cb, j->obj, j->scale, j->left, j->nleft[c], j->right,
                           i0 - j->nleft[c], &bc[0], &bc[2]);
}

/* The object split's partition, in the references' order, with each
 * side's bounds (lb, rb: box and centroids, as bvh_bounds gives them, so
 * the children need no pass of their own). In a large node over chunks in
 * parallel: every chunk's share of the left side is known first, from the
 * split's own bins of each chunk (parts, their counts on the split's axis
 * up to its bin: the same test as obj_left) or else counted, so every chunk
 * knows where its references go. */
void bvh_object_partition(const Builder *b, const Ref *refs, uint32_t count, const Box *cb, const Split *obj,
                          const Bins *parts, Ref *left, uint32_t *nl_out, Ref *right, uint32_t *nr_out, Box *lb,
                          Box *rb)
{
    const float scale = (float)obj->nbins / (cb->hi[obj->axis] - cb->lo[obj->axis]);
    const uint32_t chunk = (uint32_t)b->set->chunk;
    const int nc = nchunks(count, chunk);
    uint32_t *nleft = nc > 1 ? malloc((size_t)nc * (sizeof *nleft + 4 * sizeof(Box))) : NULL;
    uint32_t nl = 0;
    for (int k = 0; k < 2; k++) {
        box_empty(&lb[k]);
        box_empty(&rb[k]);
    }
    if (!nleft) {
        nl = object_partition_range(refs, 0, count, cb, obj, scale, left, 0, right, 0, lb, rb);
        *nl_out = nl;
        *nr_out = count - nl;
        return;
    }
    PartJob job = {refs, count, chunk, cb, obj, scale, nleft, left, right, (Box(*)[4])(nleft + nc)};
    if (parts)
        for (int c = 0; c < nc; c++) {
            uint32_t k = 0;
            for (int i = 0; i <= obj->bin; i++)
                k += parts[c].in[obj->axis][i];
            nleft[c] = k;
        }
    else
        pool_for(b->pool, nc, part_count, &job);
    for (int c = 0; c < nc; c++) { /* exclusive prefix sums: each chunk's first slot on the left */
        const uint32_t k = nleft[c];
        nleft[c] = nl;
        nl += k;
    }
    pool_for(b->pool, nc, part_move, &job);
    for (int c = 0; c < nc; c++) {
        box_grow(&lb[0], &job.bounds[c][0]);
        box_grow(&lb[1], &job.bounds[c][1]);
        box_grow(&rb[0], &job.bounds[c][2]);
        box_grow(&rb[1], &job.bounds[c][3]);
    }
    free(nleft);
    *nl_out = nl;
    *nr_out = count - nl;
}

/* Comparators for the median fallback, one per axis (tasks sort at once,
 * so the axis cannot be a global). */
static int cmp_ref_axis(const void *x, const void *y, int axis)
{
    float a = ref_cent(x, axis), c = ref_cent(y, axis);
    return a < c ? -1 : (a > c ? 1 : 0);
}
static int cmp_ref0(const void *x, const void *y) { return cmp_ref_axis(x, y, 0); }
static int cmp_ref1(const void *x, const void *y) { return cmp_ref_axis(x, y, 1); }
static int cmp_ref2(const void *x, const void *y) { return cmp_ref_axis(x, y, 2); }

/* The object median on `axis` (extent: the centroids' extent there; none,
 * and the references stay in their order): the first half of the sorted
 * references to the left, which halves the count and so bounds the depth. */
void bvh_median_partition(Ref *refs, uint32_t count, int axis, float extent, Ref *left, uint32_t *nl_out, Ref *right,
                          uint32_t *nr_out)
{
    if (extent > 0.0f)
        qsort(refs, count, sizeof *refs, axis == 0 ? cmp_ref0 : (axis == 1 ? cmp_ref1 : cmp_ref2));
    const uint32_t nl = count / 2, nr = count - nl;
    memcpy(left, refs, nl * sizeof *refs);
    memcpy(right, refs + nl, nr * sizeof *refs);
    *nl_out = nl;
    *nr_out = nr;
}
