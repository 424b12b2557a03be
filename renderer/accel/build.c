/* build.c - the binary BVH: each node's split (the cheaper of the binned
 * object split, sah.c, and the spatial split, spatial.c; the object median
 * where neither pays and the node must split), its leaves, and the build's
 * top level: the references, the run on the build's threads, and the
 * primitive records copied into leaf order so a leaf's records are
 * contiguous. Nodes are written depth-first: the first child of node i is
 * node i + 1 (pbrt-v4 LinearBVHNode). */
#include <stdlib.h>
#include <string.h>

#include "build_internal.h"
#define RT_WIDE_LEAF_VOTE(has_leaf, any) (has_leaf) /* rt_traverse.h asks for it; no ray is traced here */
#include "core/rt_traverse.h" /* RT_BVH_MAX_DEPTH: the traversal stack bounds the build */

/* A node's children: their reference arrays and counts, and where the
 * partition found them (bounded), each one's box and centroid bounds. */
typedef struct Kids {
    Ref *left, *right;
    uint32_t nl, nr;
    int bounded;
    Box lb[2], rb[2];
} Kids;

static int split_children(Builder *b, const Ref *refs, uint32_t count, const Box *bb, const Box *cb, float parea,
                          int nb, const Split *objp, const Bins *parts, Kids *k);

/* The SAH split of a node (bb: its box, of area parea; cb: its centroids'
 * bounds), partitioned into k: its axis; -1 when a leaf is cheaper or the
 * split separates nothing, -2 out of memory. */
static int sah_split(Builder *b, const Ref *refs, uint32_t count, const Box *bb, const Box *cb, float parea, Kids *k)
{
    const RtBvhSettings *set = b->set;
    /* Small nodes get one bin per reference (at least 4): sweeping all the
     * bins for a few references costs more than it can gain. */
    const int nb = count < (uint32_t)set->bins ? (count < 4 ? 4 : (int)count) : set->bins;
    Split obj = {.cost = RT_INF, .axis = -1};
    Bins *parts = NULL; /* (each chunk's bins: the partition's counts) */
    bvh_object_split(b, refs, count, cb, nb, &obj, &parts);
    const int axis = split_children(b, refs, count, bb, cb, parea, nb, &obj, parts, k);
    free(parts);
    return axis;
}

/* sah_split's choice between obj and a spatial split (of nb bins), and its
 * partition. */
static int split_children(Builder *b, const Ref *refs, uint32_t count, const Box *bb, const Box *cb, float parea,
                          int nb, const Split *objp, const Bins *parts, Kids *k)
{
    const RtBvhSettings *set = b->set;
    const Split obj = *objp;
    /* Spatial splits only where the object split's children overlap by
     * more than spatial_overlap of the node's area, and not in small nodes:
     * there binning the cut triangles costs the most build time for the
     * least gain. */
    Split s = obj;
    Box overlap = obj.left;
    box_clip(&overlap, &obj.right);
    if (count >= b->spatial_min && b->refs_left > 0 &&
        (obj.axis < 0 || box_area(&overlap) > set->spatial_overlap * parea))
        bvh_spatial_split(b, refs, count, bb, nb, &s);
    /* SAH: traversal cost 1, intersection cost 1 per primitive. */
    const float split_cost = 1.0f + s.cost / parea;
    if (!(s.axis >= 0 && (count > (uint32_t)set->leaf_max || split_cost < (float)count)))
        return -1;
    if (!bvh_halves(b, count, &k->left, &k->right))
        return -2;
    if (s.spatial && bvh_spatial_partition(b, refs, count, &s, k->left, &k->nl, k->right, &k->nr))
        return s.axis;
    if (obj.axis >= 0) {
        /* the object split, also when the spatial one separated nothing or
         * ran out of its reference budget */
        bvh_object_partition(b, refs, count, cb, &obj, parts, k->left, &k->nl, k->right, &k->nr, k->lb, k->rb);
        k->bounded = 1;
        if (k->nl > 0 && k->nr > 0)
            return obj.axis;
    }
    return -1;
}

/* No useful split (equal centroids, or too deep) in a node that must split:
 * the object median on the widest centroid axis, which halves the count.
 * Its axis, or -2 out of memory. */
static int median_split(Builder *b, Ref *refs, uint32_t count, const Box *cb, Kids *k)
{
    int axis = 0;
    float ext = -1.0f;
    for (int a = 0; a < 3; a++)
        if (cb->hi[a] - cb->lo[a] > ext) {
            ext = cb->hi[a] - cb->lo[a];
            axis = a;
        }
    if (!bvh_halves(b, count, &k->left, &k->right))
        return -2;
    k->bounded = 0;
    bvh_median_partition(refs, count, axis, ext, k->left, &k->nl, k->right, &k->nr);
    return axis;
}

/* Node ni becomes a leaf of refs[0..count), appended to the leaf order. */
static void make_leaf(Builder *b, uint32_t ni, const Ref *refs, uint32_t count)
{
    RtBvhNode *n = &b->nodes[ni];
    n->index = b->norder;
    n->meta = count;
    for (uint32_t i = 0; i < count; i++)
        b->order[b->norder++] = refs[i].prim;
    b->leaves++;
}

/* Builds the subtree over refs[0..count) (which it frees) and returns its
 * node; the nodes are written depth-first. known: its box and centroid
 * bounds where its parent's partition found them, else NULL. */
uint32_t bvh_build_node(Builder *b, Ref *refs, uint32_t count, const Box *known, uint32_t depth)
{
    const uint32_t ni = b->nnodes++;
    Box bb, cb;
    if (known) {
        bb = known[0];
        cb = known[1];
    } else {
        bvh_bounds(b, refs, count, &bb, &cb);
    }
    RtBvhNode *n = &b->nodes[ni];
    memcpy(n->lo, bb.lo, sizeof n->lo);
    memcpy(n->hi, bb.hi, sizeof n->hi);
    if (depth > b->max_depth)
        b->max_depth = depth;

    Kids k = {.left = NULL};
    int axis = -1;
    const float parea = box_area(&bb);
    if (count > 1 && depth < (uint32_t)b->set->sah_depth && parea > 0.0f)
        axis = sah_split(b, refs, count, &bb, &cb, parea, &k);
    if (axis == -1 && count > (uint32_t)b->set->leaf_max)
        axis = median_split(b, refs, count, &cb, &k);
    if (axis == -2) { /* out of memory: b->oom fails the build */
        free(refs);
        return ni;
    }
    if (axis < 0) {
        make_leaf(b, ni, refs, count);
        free(k.left);
        free(k.right);
        free(refs);
        return ni;
    }
    free(refs);
    uint32_t r;
    const Box *lk = k.bounded ? k.lb : NULL, *rk = k.bounded ? k.rb : NULL;
    if (count >= (uint32_t)b->set->task_min) {
        r = bvh_build_pair(b, k.left, k.nl, lk, k.right, k.nr, rk, depth + 1);
    } else {
        bvh_build_node(b, k.left, k.nl, lk, depth + 1);
        r = bvh_build_node(b, k.right, k.nr, rk, depth + 1);
    }
    n = &b->nodes[ni]; /* (nodes never move: capacity reserved up front) */
    n->index = r;
    n->meta = (uint32_t)axis << 8;
    return ni;
}

/* The padded box of primitive record p (v: its vertices, for a triangle). */
static void prim_box(const RtPrim *p, const float v[3][3], Box *b)
{
    if (p->id & RT_PRIM_SPHERE_BIT) {
        float r = p->e1[0];
        for (int i = 0; i < 3; i++) {
            b->lo[i] = p->p0[i] - r;
            b->hi[i] = p->p0[i] + r;
        }
    } else {
        box_empty(b);
        for (int k = 0; k < 3; k++)
            box_grow_pt(b, v[k]);
    }
    box_pad(b);
}

/* The build's loops over all its primitives or records, in chunks of
 * RtBvhSettings.chunk on the pool. */
typedef struct AllJob {
    const RtScene *s;
    const RtPrim *prims;
    uint32_t n, chunk;
    Ref *refs;
    float (*verts)[3][3];
    const uint32_t *order;
    RtPrim *ordered;
} AllJob;

/* A reference per primitive (its whole box) and each triangle's vertices,
 * from the scene's vertex pool (the spatial splits cut the triangles). */
static void refs_chunk(void *ctx, int c)
{
    const AllJob *j = ctx;
    const RtScene *s = j->s;
    uint32_t i0, i1;
    chunk_range(j->n, j->chunk, c, &i0, &i1);
    for (uint32_t i = i0; i < i1; i++) {
        if (!(j->prims[i].id & RT_PRIM_SPHERE_BIT)) {
            const RtTriangle *t = &s->triangles[j->prims[i].id - s->nspheres];
            for (int k = 0; k < 3; k++) {
                const RtVec3 *q = &s->vertices[t->v[k]];
                j->verts[i][k][0] = q->x; j->verts[i][k][1] = q->y; j->verts[i][k][2] = q->z;
            }
        }
        prim_box(&j->prims[i], (const float(*)[3])j->verts[i], &j->refs[i].box);
        j->refs[i].prim = i;
    }
}

/* The records in leaf order. */
static void order_chunk(void *ctx, int c)
{
    const AllJob *j = ctx;
    uint32_t i0, i1;
    chunk_range(j->n, j->chunk, c, &i0, &i1);
    for (uint32_t i = i0; i < i1; i++)
        j->ordered[i] = j->prims[j->order[i]];
}

/* Copies the primitive records into leaf order and hands b's tree to a;
 * frees prims and, on failure, b's arrays. */
static int finish(Builder *b, RtPrim *prims, uint32_t n, RtAccel *a, RtError *err)
{
    const size_t obytes = (size_t)b->norder * sizeof(RtPrim);
    RtPrim *ordered = b->oom ? NULL : bvh_alloc(obytes, b->huge);
    if (!ordered) {
        free(b->nodes); free(b->order); free(prims);
        return rt_fail(err, "out of memory building a BVH over %u primitives", n);
    }
    const uint32_t chunk = (uint32_t)b->set->chunk;
    AllJob job = {.prims = prims, .n = b->norder, .chunk = chunk, .order = b->order, .ordered = ordered};
    pool_for(b->pool, chunks_covering(b->norder, chunk), order_chunk, &job);
    free(b->order); free(prims);
    if (b->max_depth >= RT_BVH_MAX_DEPTH) {
        free(b->nodes); free(ordered);
        return rt_fail(err, "BVH depth %u exceeds the traversal stack (%d)", b->max_depth, RT_BVH_MAX_DEPTH);
    }
    RtBvhNode *shrunk = realloc(b->nodes, (size_t)b->nnodes * sizeof *b->nodes);
    a->nodes = shrunk ? shrunk : b->nodes;
    a->nnodes = b->nnodes;
    a->prims = ordered;
    a->nprims = b->norder;
    a->nsplit = b->norder - n;
    a->depth = b->max_depth;
    a->leaves = b->leaves;
    return 0;
}

/* The binary tree over the n primitive records prims (which it takes) on
 * the pool's threads, into a; 0, or -1 with err. */
int bvh_build_binary(const RtScene *s, const RtBvhSettings *set, RtPrim *prims, uint32_t n, RtPool *pool, RtAccel *a,
                     RtError *err)
{
    const int on = a->huge_pages;
    /* Spatial splits may add up to one reference per primitive (none in a
     * scene so large that twice its count would pass the wide tree's limit
     * on a leaf's first record). */
    const uint32_t budget = n < RT_WIDE_MAX_FIRST / 4 ? n : 0, total = n + budget;
    Ref *refs = bvh_alloc((size_t)n * sizeof *refs, on);
    float (*verts)[3][3] = bvh_alloc((size_t)n * sizeof *verts, on);
    /* A binary tree with leaves of >= 1 reference has at most 2 refs - 1 nodes. */
    RtBvhNode *nodes = bvh_alloc((size_t)2 * total * sizeof *nodes, on);
    uint32_t *order = bvh_alloc((size_t)total * sizeof *order, on);
    if (!refs || !verts || !nodes || !order) {
        free(refs); free(verts); free(nodes); free(order); free(prims);
        return rt_fail(err, "out of memory building a BVH over %u primitives", n);
    }
    const uint32_t chunk = (uint32_t)set->chunk;
    AllJob job = {.s = s, .prims = prims, .n = n, .chunk = chunk, .refs = refs, .verts = verts};
    pool_for(pool, chunks_covering(n, chunk), refs_chunk, &job);
    Builder b;
    memset(&b, 0, sizeof b);
    b.set = set;
    b.prims = prims;
    b.verts = (const float(*)[3][3])verts;
    b.nodes = nodes;
    b.order = order;
    b.refs_left = budget;
    b.huge = on;
    b.pool = pool;
    const uint32_t share = n / (uint32_t)set->spatial_share, smin = (uint32_t)set->spatial_min;
    b.spatial_min = share > smin ? share : smin;
    bvh_build_node(&b, refs, n, NULL, 0);
    bvh_place_all(&b, b.nodes, b.order, 0, 0, 0);
    free(verts);
    return finish(&b, prims, n, a, err);
}
