/* tasks.c - the build's subtree tasks. A node of at least
 * RtBvhSettings.task_min references builds its left child as a task of the
 * build's pool (pool.h), each child writing its nodes and leaf order into
 * arrays of its own (a sub-builder); its parent leaves a hole of the child's size, and once
 * the tree is done every subtree is copied into its hole, in parallel
 * (bvh_place_all), so the nodes land in depth-first order, each moved once.
 * The spatial-split budget is shared between the children in proportion to
 * their references, fixed by the counts alone, so the tree is the same on
 * any number of threads. */
#include <stdlib.h>
#include <string.h>

#include "build_internal.h"

/* A builder for a subtree of count references with `budget` of its own,
 * writing into arrays of its own; 0, or -1 out of memory. */
static int sub_init(Builder *s, const Builder *p, uint32_t count, uint32_t budget)
{
    memset(s, 0, sizeof *s);
    s->set = p->set;
    s->prims = p->prims;
    s->verts = p->verts;
    s->refs_left = budget;
    s->spatial_min = p->spatial_min;
    s->huge = p->huge;
    s->pool = p->pool;
    const size_t recs = (size_t)count + budget;
    s->nodes = bvh_alloc(2 * recs * sizeof *s->nodes, p->huge);
    s->order = bvh_alloc(recs * sizeof *s->order, p->huge);
    if (s->nodes && s->order)
        return 0;
    free(s->nodes);
    free(s->order);
    return -1;
}

/* Frees a subtree's arrays and those of the subtrees in its holes. */
static void sub_free(Builder *s)
{
    for (uint32_t k = 0; k < s->nsegs; k++)
        sub_free(&s->segs[k]);
    free(s->segs);
    free(s->nodes);
    free(s->order);
}

/* Appends subtree s to p: a hole of s's size in p's arrays, s kept for
 * bvh_place_all. (p's arrays reserve their full capacity up front, and a
 * hole is never written until then, so its pages cost nothing meanwhile.) */
static void sub_append(Builder *p, Builder *s)
{
    if (p->nsegs == p->capsegs) {
        const uint32_t cap = p->capsegs ? 2 * p->capsegs : 2;
        Builder *g = realloc(p->segs, cap * sizeof *g);
        if (!g) {
            p->oom = 1;
            sub_free(s);
            return;
        }
        p->segs = g;
        p->capsegs = cap;
    }
    s->at_node = p->nnodes;
    s->at_order = p->norder;
    p->segs[p->nsegs++] = *s;
    p->nnodes += s->nnodes;
    p->norder += s->norder;
    p->refs_left += s->refs_left;
    p->leaves += s->leaves;
    p->max_depth = s->max_depth > p->max_depth ? s->max_depth : p->max_depth;
    p->oom |= s->oom;
}

/* Copies s's own nodes and records in [n0, n1) and [o0, o1) to their final
 * places at node_off and order_off, indices shifted by the same. */
static void place_range(const Builder *s, RtBvhNode *nodes, uint32_t *order, uint32_t node_off,
                        uint32_t order_off, uint32_t n0, uint32_t n1, uint32_t o0, uint32_t o1)
{
    for (uint32_t i = n0; i < n1; i++) {
        RtBvhNode n = s->nodes[i];
        n.index += (n.meta & 0xffu) ? order_off : node_off;
        nodes[node_off + i] = n;
    }
    memcpy(order + order_off + o0, s->order + o0, (size_t)(o1 - o0) * sizeof *order);
}

/* What bvh_place_all's loop places: segment k < nsegs, and at nsegs the
 * builder's own ranges between them (when own). */
typedef struct PlaceJob {
    Builder *s;
    RtBvhNode *nodes;
    uint32_t *order;
    uint32_t node_off, order_off;
    int own;
} PlaceJob;

static void place_one(void *ctx, int k)
{
    const PlaceJob *j = ctx;
    const Builder *s = j->s;
    if ((uint32_t)k < s->nsegs) {
        Builder *c = &s->segs[k];
        bvh_place_all(c, j->nodes, j->order, j->node_off + c->at_node, j->order_off + c->at_order, 1);
        return;
    }
    if (!j->own)
        return;
    uint32_t n0 = 0, o0 = 0;
    for (uint32_t i = 0; i < s->nsegs; i++) {
        const Builder *c = &s->segs[i];
        place_range(s, j->nodes, j->order, j->node_off, j->order_off, n0, c->at_node, o0, c->at_order);
        n0 = c->at_node + c->nnodes;
        o0 = c->at_order + c->norder;
    }
    place_range(s, j->nodes, j->order, j->node_off, j->order_off, n0, s->nnodes, o0, s->norder);
}

/* Places subtree s (and those in its holes, in parallel) into the final
 * arrays at node_off and order_off, and frees it. The root builder's own
 * nodes are in place already (own = 0). */
void bvh_place_all(Builder *s, RtBvhNode *nodes, uint32_t *order, uint32_t node_off, uint32_t order_off, int own)
{
    PlaceJob job = {s, nodes, order, node_off, order_off, own};
    pool_for(s->pool, (int)s->nsegs + 1, place_one, &job);
    free(s->segs); /* (the subtrees in it freed themselves) */
    if (own) {
        free(s->nodes);
        free(s->order);
    }
}

/* The left child of bvh_build_pair, the task. */
typedef struct PairLeft {
    Builder *sb;
    Ref *refs;
    uint32_t count, depth;
    const Box *known;
} PairLeft;

static void build_left(void *arg)
{
    const PairLeft *j = arg;
    bvh_build_node(j->sb, j->refs, j->count, j->known, j->depth);
}

/* The two children of a large node (each one's bounds where known, else
 * NULL), the left one as a task; returns the right child's node. Out of
 * memory for the children's arrays, they are built here one after the
 * other. */
uint32_t bvh_build_pair(Builder *b, Ref *left, uint32_t nl, const Box *lknown, Ref *right, uint32_t nr,
                        const Box *rknown, uint32_t depth)
{
    Builder sb[2];
    const uint32_t bl = (uint32_t)((uint64_t)b->refs_left * nl / ((uint64_t)nl + nr));
    if (sub_init(&sb[0], b, nl, bl) != 0) {
        bvh_build_node(b, left, nl, lknown, depth);
        return bvh_build_node(b, right, nr, rknown, depth);
    }
    if (sub_init(&sb[1], b, nr, b->refs_left - bl) != 0) {
        sub_free(&sb[0]);
        bvh_build_node(b, left, nl, lknown, depth);
        return bvh_build_node(b, right, nr, rknown, depth);
    }
    b->refs_left = 0;
    PairLeft job = {&sb[0], left, nl, depth, lknown};
    PoolTask task;
    PoolGroup g = {0, NULL};
    pool_spawn(b->pool, &g, &task, build_left, &job);
    bvh_build_node(&sb[1], right, nr, rknown, depth);
    pool_wait(b->pool, &g);
    sub_append(b, &sb[0]);
    const uint32_t r = b->nnodes;
    sub_append(b, &sb[1]);
    return r;
}
