/* check.c - the BVH's invariants (rt_bvh_check): after every build in the
 * tests, with --verify, and on every scene cache entry before it is used
 * (a tree read from a file is followed by the traversal only once checked).
 *
 * Both trees are walked from the root: the top levels breadth-first on one
 * thread until a few hundred subtrees are pending, then each subtree
 * depth-first on its own thread. Nodes and primitive slots are marked with
 * atomic increments, so a node or slot reached twice (a cycle, a shared
 * subtree, overlapping leaves) is found whichever thread reaches it second;
 * the first failure in subtree order is reported. */
#include <limits.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "rt.h"
#define RT_WIDE_LEAF_VOTE(has_leaf, any) (has_leaf) /* rt_traverse.h asks for it; no ray is traced here */
#include "core/rt_traverse.h" /* RT_BVH_MAX_DEPTH: the traversal stacks' bound */

#define FRONTIER 512 /* subtrees handed to the threads */

/* A pending node: its index, depth, and (wide tree) the box its parent gave it. */
typedef struct Item {
    uint32_t node, depth;
    float lo[3], hi[3];
} Item;

/* (an exchange, not an increment: a record in 256 leaves must not wrap to "first") */
static int first_visit(uint8_t *seen, uint32_t i)
{
    return __atomic_exchange_n(&seen[i], 1, __ATOMIC_RELAXED) == 0;
}

static int inside(const RtBvhNode *c, const RtBvhNode *p)
{
    for (int i = 0; i < 3; i++)
        if (c->lo[i] < p->lo[i] || c->hi[i] > p->hi[i])
            return 0;
    return 1;
}

typedef struct Walk {
    const RtAccel *a;
    uint8_t *seen_node, *seen_prim;
    int wide;
} Walk;

/* Checks binary node it (reached from its parent) and pushes its children. */
static int visit_binary(const Walk *w, const Item *it, Item *st, int *sp, RtError *err)
{
    const RtAccel *a = w->a;
    const uint32_t ni = it->node;
    const RtBvhNode *n = &a->nodes[ni];
    if (!first_visit(w->seen_node, ni))
        return rt_fail(err, "BVH check: node %u reached twice", ni);
    const uint32_t count = n->meta & 0xffu;
    if (count) {
        if (count > RT_BVH_LEAF_MAX || (uint64_t)n->index + count > a->nprims)
            return rt_fail(err, "BVH check: leaf %u holds [%u, +%u) of %u primitives", ni, n->index, count, a->nprims);
        for (uint32_t k = n->index; k < n->index + count; k++)
            if (!first_visit(w->seen_prim, k))
                return rt_fail(err, "BVH check: primitive slot %u referenced twice", k);
        return 0;
    }
    const uint32_t l = ni + 1, r = n->index;
    if (r <= l || r >= a->nnodes || l >= a->nnodes)
        return rt_fail(err, "BVH check: node %u has children %u, %u (not depth-first)", ni, l, r);
    if (!inside(&a->nodes[l], n) || !inside(&a->nodes[r], n))
        return rt_fail(err, "BVH check: a child of node %u lies outside its bounds", ni);
    if (it->depth + 1 > RT_BVH_MAX_DEPTH)
        return rt_fail(err, "BVH check: deeper than %d", RT_BVH_MAX_DEPTH);
    st[*sp].node = r, st[*sp].depth = it->depth + 1, (*sp)++;
    st[*sp].node = l, st[*sp].depth = it->depth + 1, (*sp)++;
    return 0;
}

/* One slot of a wide node: empty, a leaf range, or an inner child to push. */
static int wide_slot(const Walk *w, const Item *it, uint32_t k, Item *st, int *sp, RtError *err)
{
    const RtAccel *a = w->a;
    const RtBvh4Node *n = &a->wide[it->node];
    const uint32_t c = n->child[k];
    if (k >= n->count) {
        if (c != RT_WIDE_EMPTY)
            return rt_fail(err, "BVH check: wide node %u: child slot %u past its count is used", it->node, k);
        if (!(n->lo_x[k] == INFINITY && n->lo_y[k] == INFINITY && n->lo_z[k] == INFINITY &&
              n->hi_x[k] == -INFINITY && n->hi_y[k] == -INFINITY && n->hi_z[k] == -INFINITY))
            return rt_fail(err, "BVH check: wide node %u: empty slot %u has a box", it->node, k);
        return 0;
    }
    const float lo[3] = {n->lo_x[k], n->lo_y[k], n->lo_z[k]}, hi[3] = {n->hi_x[k], n->hi_y[k], n->hi_z[k]};
    for (int x = 0; x < 3; x++)
        if (lo[x] < it->lo[x] || hi[x] > it->hi[x])
            return rt_fail(err, "BVH check: wide node %u: child %u lies outside its parent", it->node, k);
    if (c & RT_WIDE_LEAF) {
        const uint32_t first = (c & ~RT_WIDE_LEAF) >> 3, count = (c & 7u) + 1u;
        if ((uint64_t)first + count > a->nprims)
            return rt_fail(err, "BVH check: wide leaf [%u, +%u) past %u primitives", first, count, a->nprims);
        for (uint32_t p = first; p < first + count; p++)
            if (!first_visit(w->seen_prim, p))
                return rt_fail(err, "BVH check: primitive slot %u in two wide leaves", p);
        return 0;
    }
    if (c >= a->nwide || c == 0)
        return rt_fail(err, "BVH check: wide node %u: child %u -> node %u of %u", it->node, k, c, a->nwide);
    if (it->depth + 1 > RT_BVH_MAX_DEPTH) /* (the traversals' stacks are sized for this depth) */
        return rt_fail(err, "BVH check: the wide tree is deeper than %d", RT_BVH_MAX_DEPTH);
    Item *e = &st[(*sp)++];
    e->node = c, e->depth = it->depth + 1;
    memcpy(e->lo, lo, sizeof lo);
    memcpy(e->hi, hi, sizeof hi);
    return 0;
}

static int visit_wide(const Walk *w, const Item *it, Item *st, int *sp, RtError *err)
{
    const RtBvh4Node *n = &w->a->wide[it->node];
    if (!first_visit(w->seen_node, it->node))
        return rt_fail(err, "BVH check: wide node %u reached twice", it->node);
    if (n->count < 1 || n->count > 4)
        return rt_fail(err, "BVH check: wide node %u has %u children", it->node, n->count);
    for (uint32_t k = 0; k < 4; k++)
        if (wide_slot(w, it, k, st, sp, err) != 0)
            return -1;
    return 0;
}

static int visit(const Walk *w, const Item *it, Item *st, int *sp, RtError *err)
{
    return w->wide ? visit_wide(w, it, st, sp, err) : visit_binary(w, it, st, sp, err);
}

/* The subtree under it, depth-first: a node pushes at most 4 and pops 1,
 * and the depth is bounded, so the stack is too. */
static int walk_subtree(const Walk *w, const Item *it, RtError *err)
{
    Item st[3 * RT_BVH_MAX_DEPTH + 8];
    int sp = 0;
    st[sp++] = *it;
    while (sp > 0) {
        const Item cur = st[--sp];
        if (visit(w, &cur, st, &sp, err) != 0)
            return -1;
    }
    return 0;
}

/* Walks the tree from the root item: the top breadth-first here, then the
 * pending subtrees in parallel. */
static int walk(const Walk *w, const Item *root, RtError *err)
{
    Item *q = malloc((FRONTIER + 8) * sizeof *q);
    if (!q)
        return rt_fail(err, "BVH check: out of memory");
    long head = 0, tail = 0;
    q[tail++] = *root;
    int rc = 0;
    while (rc == 0 && head < tail && tail - head < FRONTIER) {
        if (tail + 4 > FRONTIER + 8) { /* slide the pending items to the front */
            memmove(q, q + head, (size_t)(tail - head) * sizeof *q);
            tail -= head, head = 0;
        }
        int sp = 0; /* (a node's children land at q + tail: at most 4) */
        const Item cur = q[head++];
        rc = visit(w, &cur, q + tail, &sp, err);
        tail += sp;
    }
    long failed = LONG_MAX;
#pragma omp parallel for schedule(dynamic, 1) if (rc == 0 && tail - head > 1) num_threads(rt_stream_threads())
    for (long i = head; i < tail; i++) {
        RtError e;
        if (rc == 0 && walk_subtree(w, &q[i], &e) != 0) {
#pragma omp critical(rt_bvh_check_error)
            if (i < failed) {
                failed = i;
                *err = e;
            }
        }
    }
    free(q);
    return rc != 0 || failed != LONG_MAX ? -1 : 0;
}

/* Every slot of 0..n is marked: the first that is not, or -1. */
static long first_unmarked(const uint8_t *seen, uint32_t n)
{
    long bad = LONG_MAX;
#pragma omp parallel for reduction(min : bad) schedule(static) num_threads(rt_stream_threads())
    for (long k = 0; k < (long)n; k++)
        if (!seen[k] && k < bad)
            bad = k;
    return bad == LONG_MAX ? -1 : bad;
}

/* The wide tree: every node reached once from the root, 1..4 children in
 * use and the rest empty, every primitive slot in exactly one leaf range, and
 * every child box inside the box its parent gave it (the tree nests). */
static int wide_check(const RtAccel *a, RtError *err)
{
    Walk w = {a, calloc(a->nwide, 1), calloc(a->nprims, 1), 1};
    int rc = 0;
    if (!w.seen_node || !w.seen_prim) {
        rc = rt_fail(err, "BVH check: out of memory");
    } else {
        Item root = {0, 0, {0}, {0}};
        memcpy(root.lo, a->nodes[0].lo, sizeof root.lo);
        memcpy(root.hi, a->nodes[0].hi, sizeof root.hi);
        rc = walk(&w, &root, err);
    }
    long k;
    if (rc == 0 && (k = first_unmarked(w.seen_prim, a->nprims)) >= 0)
        rc = rt_fail(err, "BVH check: primitive slot %ld is in no wide leaf", k);
    if (rc == 0 && (k = first_unmarked(w.seen_node, a->nwide)) >= 0)
        rc = rt_fail(err, "BVH check: wide node %ld is unreachable", k);
    free(w.seen_node);
    free(w.seen_prim);
    return rc;
}

/* Every slot's primitive in range; the slots beyond the first of each
 * primitive are the build's spatial-split copies, exactly nsplit. */
static int check_ids(const RtAccel *a, RtError *err)
{
    const uint32_t nscene = a->nprims - a->nsplit;
    uint8_t *seen_id = calloc(nscene ? nscene : 1, 1);
    if (!seen_id)
        return rt_fail(err, "BVH check: out of memory");
    long bad = LONG_MAX, copies = 0;
#pragma omp parallel for reduction(min : bad) reduction(+ : copies) schedule(static) \
    num_threads(rt_stream_threads())
    for (long k = 0; k < (long)a->nprims; k++) {
        const uint32_t id = a->prims[k].id & ~RT_PRIM_SPHERE_BIT;
        if (id >= nscene)
            bad = k < bad ? k : bad;
        else if (!first_visit(seen_id, id))
            copies++;
    }
    free(seen_id);
    if (bad != LONG_MAX)
        return rt_fail(err, "BVH check: primitive %u is out of range (%u)", a->prims[bad].id & ~RT_PRIM_SPHERE_BIT,
                       nscene);
    if ((uint64_t)copies != a->nsplit)
        return rt_fail(err, "BVH check: %ld primitive copies, the build made %u", copies, a->nsplit);
    return 0;
}

int rt_bvh_check(const RtAccel *a, RtError *err)
{
    if (a->kind != RT_ACCEL_BVH || a->nprims == 0)
        return 0;
    if (a->nnodes == 0 || a->nnodes > 2 * a->nprims)
        return rt_fail(err, "BVH check: %u nodes for %u primitives", a->nnodes, a->nprims);
    if (a->nsplit >= a->nprims)
        return rt_fail(err, "BVH check: %u of %u records are spatial-split copies", a->nsplit, a->nprims);
    Walk w = {a, calloc(a->nnodes, 1), calloc(a->nprims, 1), 0};
    int rc = 0;
    long k;
    if (!w.seen_node || !w.seen_prim) {
        rc = rt_fail(err, "BVH check: out of memory");
    } else {
        const Item root = {0, 0, {0}, {0}};
        rc = walk(&w, &root, err);
    }
    if (rc == 0 && (k = first_unmarked(w.seen_prim, a->nprims)) >= 0)
        rc = rt_fail(err, "BVH check: primitive slot %ld is in no leaf", k);
    if (rc == 0)
        rc = check_ids(a, err);
    if (rc == 0 && (k = first_unmarked(w.seen_node, a->nnodes)) >= 0)
        rc = rt_fail(err, "BVH check: node %ld is unreachable", k);
    free(w.seen_node);
    free(w.seen_prim);
    if (rc == 0 && a->wide)
        rc = a->nwide ? wide_check(a, err) : rt_fail(err, "BVH check: an empty wide tree");
    return rc;
}
