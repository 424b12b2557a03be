/* accel.c - primitive records, brute force ("none") and the binned-SAH BVH.
 *
 * One build: binned SAH (Wald 2007, "On fast construction of SAH-based
 * bounding volume hierarchies"), 32 bins on the centroid bounds of every axis,
 * leaves of at most RT_BVH_LEAF_MAX primitives, nodes written depth-first so
 * the first child of node i is node i+1 (pbrt-v4 LinearBVHNode). Spheres and
 * triangles live in one tree. The primitive records are reordered into leaf
 * order so a leaf's primitives are contiguous in memory. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "rt.h"

#define RT_BVH_LEAF_MAX 4
#define RT_BVH_BINS 32
/* Below this many levels the SAH split is used; deeper, the object median,
 * which halves the count each level and so bounds the depth. */
#define RT_BVH_SAH_DEPTH 44

typedef struct Box {
    float lo[3], hi[3];
} Box;

static void box_empty(Box *b)
{
    for (int i = 0; i < 3; i++) {
        b->lo[i] = RT_INF;
        b->hi[i] = -RT_INF;
    }
}
static void box_grow(Box *b, const Box *o)
{
    for (int i = 0; i < 3; i++) {
        b->lo[i] = b->lo[i] < o->lo[i] ? b->lo[i] : o->lo[i];
        b->hi[i] = b->hi[i] > o->hi[i] ? b->hi[i] : o->hi[i];
    }
}
static void box_grow_pt(Box *b, const float *p)
{
    for (int i = 0; i < 3; i++) {
        b->lo[i] = b->lo[i] < p[i] ? b->lo[i] : p[i];
        b->hi[i] = b->hi[i] > p[i] ? b->hi[i] : p[i];
    }
}
static float box_area(const Box *b)
{
    float dx = b->hi[0] - b->lo[0], dy = b->hi[1] - b->lo[1], dz = b->hi[2] - b->lo[2];
    if (dx < 0.0f || dy < 0.0f || dz < 0.0f)
        return 0.0f;
    return 2.0f * (dx * dy + dy * dz + dz * dx);
}

const char *rt_accel_name(RtAccelKind k) { return k == RT_ACCEL_BVH ? "bvh" : "none"; }

int rt_accel_parse(const char *s, RtAccelKind *k)
{
    if (strcmp(s, "none") == 0) { *k = RT_ACCEL_NONE; return 0; }
    if (strcmp(s, "bvh") == 0) { *k = RT_ACCEL_BVH; return 0; }
    return -1;
}

static RtPrim *make_prims(const RtScene *s, uint32_t *n_out, RtError *err)
{
    uint64_t n = (uint64_t)s->nspheres + s->ntriangles;
    if (n >= RT_PRIM_SPHERE_BIT) {
        rt_fail(err, "%s: %llu primitives exceed the limit of %u", s->path, (unsigned long long)n,
                RT_PRIM_SPHERE_BIT - 1);
        return NULL;
    }
    RtPrim *p = calloc(n ? n : 1, sizeof *p);
    if (!p) {
        rt_fail(err, "out of memory for %llu primitive records", (unsigned long long)n);
        return NULL;
    }
    for (uint32_t i = 0; i < s->nspheres; i++) {
        memcpy(p[i].p0, s->spheres[i].c, sizeof p[i].p0);
        p[i].e1[0] = s->spheres[i].r;
        p[i].id = i | RT_PRIM_SPHERE_BIT;
    }
    for (uint32_t i = 0; i < s->ntriangles; i++) {
        RtPrim *q = &p[s->nspheres + i];
        const RtTriangle *t = &s->triangles[i];
        RtVec3 a = s->vertices[t->v[0]], b = s->vertices[t->v[1]], c = s->vertices[t->v[2]];
        RtVec3 e1 = rt_sub(b, a), e2 = rt_sub(c, a);
        q->p0[0] = a.x; q->p0[1] = a.y; q->p0[2] = a.z;
        q->e1[0] = e1.x; q->e1[1] = e1.y; q->e1[2] = e1.z;
        q->e2[0] = e2.x; q->e2[1] = e2.y; q->e2[2] = e2.z;
        q->id = s->nspheres + i;
    }
    *n_out = (uint32_t)n;
    return p;
}

static void prim_box(const RtScene *s, const RtPrim *p, Box *b)
{
    if (p->id & RT_PRIM_SPHERE_BIT) {
        float r = p->e1[0];
        for (int i = 0; i < 3; i++) {
            b->lo[i] = p->p0[i] - r;
            b->hi[i] = p->p0[i] + r;
        }
    } else {
        const RtTriangle *t = &s->triangles[p->id - s->nspheres];
        box_empty(b);
        for (int k = 0; k < 3; k++) {
            const RtVec3 *v = &s->vertices[t->v[k]];
            float q[3] = {v->x, v->y, v->z};
            box_grow_pt(b, q);
        }
    }
    /* A hair of padding so a hit on the box boundary is never lost to the
     * rounding of the slab test. */
    for (int i = 0; i < 3; i++) {
        float pad = 1e-6f * (fabsf(b->lo[i]) + fabsf(b->hi[i])) + 1e-30f;
        b->lo[i] -= pad;
        b->hi[i] += pad;
    }
}

typedef struct Builder {
    const Box *boxes;   /* per original primitive */
    const float *cent;  /* 3 per original primitive */
    uint32_t *idx;      /* permutation being partitioned */
    RtBvhNode *nodes;
    uint32_t nnodes, cap;
    uint32_t max_depth, leaves;
} Builder;

/* qsort context for the median fallback (the build is single-threaded). */
static const float *sort_cent;
static int sort_axis;
static int cmp_cent(const void *x, const void *y)
{
    float a = sort_cent[3 * *(const uint32_t *)x + sort_axis], c = sort_cent[3 * *(const uint32_t *)y + sort_axis];
    return a < c ? -1 : (a > c ? 1 : 0);
}

static uint32_t build(Builder *b, uint32_t begin, uint32_t end, uint32_t depth)
{
    uint32_t ni = b->nnodes++;
    Box bb, cb;
    box_empty(&bb);
    box_empty(&cb);
    for (uint32_t i = begin; i < end; i++) {
        box_grow(&bb, &b->boxes[b->idx[i]]);
        box_grow_pt(&cb, &b->cent[3 * b->idx[i]]);
    }
    RtBvhNode *n = &b->nodes[ni];
    memcpy(n->lo, bb.lo, sizeof n->lo);
    memcpy(n->hi, bb.hi, sizeof n->hi);
    uint32_t count = end - begin;
    if (depth > b->max_depth)
        b->max_depth = depth;

    /* Choose the split. */
    int axis = -1;
    uint32_t mid = begin;
    float leaf_cost = (float)count;
    int ext_axis = 0;
    float ext = -1.0f;
    for (int a = 0; a < 3; a++)
        if (cb.hi[a] - cb.lo[a] > ext) {
            ext = cb.hi[a] - cb.lo[a];
            ext_axis = a;
        }
    if (count > 1 && ext > 0.0f && depth < RT_BVH_SAH_DEPTH) {
        float best = RT_INF;
        int best_axis = -1, best_bin = 0, best_nb = RT_BVH_BINS;
        /* Small nodes get one bin per primitive (at least 4): sweeping 32
         * bins for 6 primitives costs more than it can gain. */
        int nb = count < RT_BVH_BINS ? (count < 4 ? 4 : (int)count) : RT_BVH_BINS;
        for (int a = 0; a < 3; a++) {
            float w = cb.hi[a] - cb.lo[a];
            if (!(w > 0.0f))
                continue;
            float scale = (float)nb / w;
            Box bins[RT_BVH_BINS];
            uint32_t cnt[RT_BVH_BINS];
            for (int k = 0; k < nb; k++) {
                box_empty(&bins[k]);
                cnt[k] = 0;
            }
            for (uint32_t i = begin; i < end; i++) {
                uint32_t p = b->idx[i];
                int k = (int)((b->cent[3 * p + a] - cb.lo[a]) * scale);
                k = k < 0 ? 0 : (k >= nb ? nb - 1 : k);
                cnt[k]++;
                box_grow(&bins[k], &b->boxes[p]);
            }
            /* Sweep: right-side areas, then left-to-right. */
            float rarea[RT_BVH_BINS];
            uint32_t rcnt[RT_BVH_BINS];
            Box acc;
            box_empty(&acc);
            uint32_t c = 0;
            for (int k = nb - 1; k > 0; k--) {
                box_grow(&acc, &bins[k]);
                c += cnt[k];
                rarea[k] = box_area(&acc);
                rcnt[k] = c;
            }
            box_empty(&acc);
            c = 0;
            for (int k = 0; k < nb - 1; k++) {
                box_grow(&acc, &bins[k]);
                c += cnt[k];
                if (c == 0 || rcnt[k + 1] == 0)
                    continue;
                float cost = box_area(&acc) * (float)c + rarea[k + 1] * (float)rcnt[k + 1];
                if (cost < best) {
                    best = cost;
                    best_axis = a;
                    best_bin = k;
                    best_nb = nb;
                }
            }
        }
        float parea = box_area(&bb);
        /* SAH: traversal cost 1, intersection cost 1 per primitive. */
        float split_cost = parea > 0.0f ? 1.0f + best / parea : RT_INF;
        if (best_axis >= 0 && (count > RT_BVH_LEAF_MAX || split_cost < leaf_cost)) {
            float w = cb.hi[best_axis] - cb.lo[best_axis];
            float scale = (float)best_nb / w;
            uint32_t i = begin, j = end;
            while (i < j) {
                uint32_t p = b->idx[i];
                int k = (int)((b->cent[3 * p + best_axis] - cb.lo[best_axis]) * scale);
                k = k < 0 ? 0 : (k >= best_nb ? best_nb - 1 : k);
                if (k <= best_bin) {
                    i++;
                } else {
                    j--;
                    b->idx[i] = b->idx[j];
                    b->idx[j] = p;
                }
            }
            if (i > begin && i < end) {
                axis = best_axis;
                mid = i;
            }
        }
    }
    if (axis < 0 && count > RT_BVH_LEAF_MAX) {
        /* No useful SAH split (equal centroids, or too deep): the object
         * median on the widest centroid axis, which halves the count. */
        axis = ext_axis;
        mid = begin + count / 2;
        if (ext > 0.0f) {
            sort_cent = b->cent;
            sort_axis = axis;
            qsort(b->idx + begin, count, sizeof *b->idx, cmp_cent);
        }
    }
    if (axis < 0) {
        n->index = begin;
        n->meta = count;
        b->leaves++;
        return ni;
    }
    build(b, begin, mid, depth + 1);
    uint32_t right = build(b, mid, end, depth + 1);
    n = &b->nodes[ni]; /* (nodes never move: capacity reserved up front) */
    n->index = right;
    n->meta = (uint32_t)axis << 8;
    return ni;
}

/* ---- The 4-wide copy -------------------------------------------------------
 * Each wide node takes a binary node's two children and keeps opening the
 * inner child of largest surface area until it holds four (or only leaves
 * remain): the collapse of Wald et al. 2008 / pbrt's MBVH. Every box in it is
 * a binary node's box, bit for bit, so the wide traversal culls no primitive
 * the binary one would test and finds the same closest hit. Leaves are not
 * nodes here: a child reference holds the leaf's primitive range. */
typedef struct Widen {
    const RtBvhNode *bin;
    RtBvh4Node *wide;
    uint32_t n;
} Widen;

static float node_area(const RtBvhNode *n)
{
    Box b;
    memcpy(b.lo, n->lo, sizeof b.lo);
    memcpy(b.hi, n->hi, sizeof b.hi);
    return box_area(&b);
}

static uint32_t widen_ref(Widen *w, uint32_t bi);

/* Fills wide node wi with the binary nodes cand[0..nc). */
static void widen_fill(Widen *w, uint32_t wi, const uint32_t *cand, int nc)
{
    uint32_t refs[4];
    for (int k = 0; k < nc; k++)
        refs[k] = widen_ref(w, cand[k]); /* (may append nodes: index, not pointer) */
    RtBvh4Node *o = &w->wide[wi];
    memset(o, 0, sizeof *o);
    for (int k = 0; k < 4; k++) {
        if (k < nc) {
            const RtBvhNode *c = &w->bin[cand[k]];
            o->lo_x[k] = c->lo[0]; o->lo_y[k] = c->lo[1]; o->lo_z[k] = c->lo[2];
            o->hi_x[k] = c->hi[0]; o->hi_y[k] = c->hi[1]; o->hi_z[k] = c->hi[2];
            o->child[k] = refs[k];
        } else {
            /* An empty slot's box is inside out (lo = +inf, hi = -inf): the
             * traversal's slab test misses it without looking at the child. */
            o->lo_x[k] = o->lo_y[k] = o->lo_z[k] = INFINITY;
            o->hi_x[k] = o->hi_y[k] = o->hi_z[k] = -INFINITY;
            o->child[k] = RT_WIDE_EMPTY;
        }
    }
    o->count = (uint32_t)nc;
}

/* The reference to binary node bi in the wide tree: a leaf range, or a new
 * wide node collapsed from bi's subtree. */
static uint32_t widen_ref(Widen *w, uint32_t bi)
{
    const RtBvhNode *b = &w->bin[bi];
    uint32_t count = b->meta & 0xffu;
    if (count)
        return RT_WIDE_LEAF | (b->index << 3) | (count - 1);
    uint32_t cand[4] = {bi + 1, b->index, 0, 0};
    int nc = 2;
    while (nc < 4) {
        int best = -1;
        float best_area = -1.0f;
        for (int k = 0; k < nc; k++) {
            const RtBvhNode *c = &w->bin[cand[k]];
            float area = (c->meta & 0xffu) == 0 ? node_area(c) : -1.0f;
            if (area > best_area) {
                best = k;
                best_area = area;
            }
        }
        if (best < 0)
            break;
        uint32_t c = cand[best];
        cand[best] = c + 1;
        cand[nc++] = w->bin[c].index;
    }
    uint32_t wi = w->n++;
    widen_fill(w, wi, cand, nc);
    return wi;
}

/* Builds a->wide from a->nodes. A tree that is one leaf gets a root with one
 * child. Fails only for lack of memory or more than 2^28 primitives (the
 * reference encoding); then the view simply has no wide tree. */
static int widen(RtAccel *a)
{
    if (a->nnodes == 0 || a->nprims >= RT_WIDE_MAX_FIRST)
        return -1;
    Widen w;
    w.bin = a->nodes;
    w.n = 0;
    /* At most one wide node per binary inner node, plus the root. */
    w.wide = malloc(((size_t)a->nnodes + 1) * sizeof *w.wide);
    if (!w.wide)
        return -1;
    if (a->nodes[0].meta & 0xffu) {
        uint32_t root = 0;
        w.n = 1;
        widen_fill(&w, 0, &root, 1);
    } else {
        widen_ref(&w, 0);
    }
    RtBvh4Node *shrunk = realloc(w.wide, (size_t)w.n * sizeof *w.wide);
    a->wide = shrunk ? shrunk : w.wide;
    a->nwide = w.n;
    return 0;
}

int rt_accel_build(const RtScene *s, RtAccelKind kind, RtAccel *a, RtError *err)
{
    memset(a, 0, sizeof *a);
    a->kind = kind;
    uint32_t n = 0;
    RtPrim *prims = make_prims(s, &n, err);
    if (!prims)
        return -1;
    a->nprims = n;
    if (kind == RT_ACCEL_NONE || n == 0) {
        a->prims = prims;
        return 0;
    }
    Box *boxes = malloc((size_t)n * sizeof *boxes);
    float *cent = malloc((size_t)n * 3 * sizeof *cent);
    uint32_t *idx = malloc((size_t)n * sizeof *idx);
    /* A binary tree with leaves of >= 1 primitive has at most 2n-1 nodes. */
    RtBvhNode *nodes = malloc(((size_t)2 * n) * sizeof *nodes);
    RtPrim *ordered = malloc((size_t)n * sizeof *ordered);
    if (!boxes || !cent || !idx || !nodes || !ordered) {
        free(boxes); free(cent); free(idx); free(nodes); free(ordered); free(prims);
        return rt_fail(err, "out of memory building a BVH over %u primitives", n);
    }
    for (uint32_t i = 0; i < n; i++) {
        prim_box(s, &prims[i], &boxes[i]);
        for (int k = 0; k < 3; k++)
            cent[3 * i + k] = 0.5f * (boxes[i].lo[k] + boxes[i].hi[k]);
        idx[i] = i;
    }
    Builder b;
    memset(&b, 0, sizeof b);
    b.boxes = boxes;
    b.cent = cent;
    b.idx = idx;
    b.nodes = nodes;
    b.cap = 2 * n;
    build(&b, 0, n, 0);
    for (uint32_t i = 0; i < n; i++)
        ordered[i] = prims[idx[i]];
    free(boxes); free(cent); free(idx); free(prims);
    if (b.max_depth >= RT_BVH_MAX_DEPTH) {
        free(nodes); free(ordered);
        return rt_fail(err, "BVH depth %u exceeds the traversal stack (%d)", b.max_depth, RT_BVH_MAX_DEPTH);
    }
    RtBvhNode *shrunk = realloc(nodes, (size_t)b.nnodes * sizeof *nodes);
    a->nodes = shrunk ? shrunk : nodes;
    a->nnodes = b.nnodes;
    a->prims = ordered;
    a->depth = b.max_depth;
    a->leaves = b.leaves;
    widen(a); /* optional: without it the GPU traverses the binary tree */
    return 0;
}

void rt_accel_free(RtAccel *a)
{
    free(a->prims);
    free(a->nodes);
    free(a->wide);
    memset(a, 0, sizeof *a);
}

static int inside(const RtBvhNode *c, const RtBvhNode *p)
{
    for (int i = 0; i < 3; i++)
        if (c->lo[i] < p->lo[i] || c->hi[i] > p->hi[i])
            return 0;
    return 1;
}

/* The wide tree: every node reached once from the root, 1..4 children in
 * use and the rest empty, every primitive slot in exactly one leaf range, and
 * every child box inside the box its parent gave it (the tree nests). */
static int wide_check(const RtAccel *a, RtError *err)
{
    uint8_t *seen_node = calloc(a->nwide, 1), *seen_prim = calloc(a->nprims, 1);
    /* each entry: node index, and its box as the parent saw it */
    typedef struct { uint32_t node; float lo[3], hi[3]; } Entry;
    Entry *stack = malloc(((size_t)a->nwide + 1) * sizeof *stack);
    int rc = 0, sp = 0;
    if (!seen_node || !seen_prim || !stack) {
        rc = rt_fail(err, "BVH check: out of memory");
        goto out;
    }
    stack[sp].node = 0;
    for (int k = 0; k < 3; k++) {
        stack[sp].lo[k] = a->nodes[0].lo[k];
        stack[sp].hi[k] = a->nodes[0].hi[k];
    }
    sp++;
    while (sp > 0 && rc == 0) {
        Entry e = stack[--sp];
        const RtBvh4Node *n = &a->wide[e.node];
        if (seen_node[e.node]++) {
            rc = rt_fail(err, "BVH check: wide node %u reached twice", e.node);
            break;
        }
        if (n->count < 1 || n->count > 4) {
            rc = rt_fail(err, "BVH check: wide node %u has %u children", e.node, n->count);
            break;
        }
        for (uint32_t k = 0; k < 4 && rc == 0; k++) {
            uint32_t c = n->child[k];
            if (k >= n->count) {
                if (c != RT_WIDE_EMPTY)
                    rc = rt_fail(err, "BVH check: wide node %u: child slot %u past its count is used", e.node, k);
                else if (!(n->lo_x[k] == INFINITY && n->lo_y[k] == INFINITY && n->lo_z[k] == INFINITY &&
                           n->hi_x[k] == -INFINITY && n->hi_y[k] == -INFINITY && n->hi_z[k] == -INFINITY))
                    rc = rt_fail(err, "BVH check: wide node %u: empty slot %u has a box", e.node, k);
                continue;
            }
            const float lo[3] = {n->lo_x[k], n->lo_y[k], n->lo_z[k]}, hi[3] = {n->hi_x[k], n->hi_y[k], n->hi_z[k]};
            for (int x = 0; x < 3; x++)
                if (lo[x] < e.lo[x] || hi[x] > e.hi[x])
                    rc = rt_fail(err, "BVH check: wide node %u: child %u lies outside its parent", e.node, k);
            if (rc)
                break;
            if (c & RT_WIDE_LEAF) {
                uint32_t first = (c & ~RT_WIDE_LEAF) >> 3, count = (c & 7u) + 1u;
                if ((uint64_t)first + count > a->nprims) {
                    rc = rt_fail(err, "BVH check: wide leaf [%u, +%u) past %u primitives", first, count, a->nprims);
                    break;
                }
                for (uint32_t p = first; p < first + count && rc == 0; p++)
                    if (seen_prim[p]++)
                        rc = rt_fail(err, "BVH check: primitive slot %u in two wide leaves", p);
            } else if (c >= a->nwide || c == 0) {
                rc = rt_fail(err, "BVH check: wide node %u: child %u -> node %u of %u", e.node, k, c, a->nwide);
            } else if (sp >= (int)a->nwide) {
                rc = rt_fail(err, "BVH check: the wide tree has a cycle");
            } else {
                stack[sp].node = c;
                memcpy(stack[sp].lo, lo, sizeof lo);
                memcpy(stack[sp].hi, hi, sizeof hi);
                sp++;
            }
        }
    }
    for (uint32_t k = 0; rc == 0 && k < a->nprims; k++)
        if (!seen_prim[k])
            rc = rt_fail(err, "BVH check: primitive slot %u is in no wide leaf", k);
    for (uint32_t k = 0; rc == 0 && k < a->nwide; k++)
        if (!seen_node[k])
            rc = rt_fail(err, "BVH check: wide node %u is unreachable", k);
out:
    free(seen_node); free(seen_prim); free(stack);
    return rc;
}

int rt_bvh_check(const RtAccel *a, RtError *err)
{
    if (a->kind != RT_ACCEL_BVH || a->nprims == 0)
        return 0;
    if (a->nnodes == 0 || a->nnodes > 2 * a->nprims)
        return rt_fail(err, "BVH check: %u nodes for %u primitives", a->nnodes, a->nprims);
    uint8_t *seen_prim = calloc(a->nprims, 1);
    uint8_t *seen_node = calloc(a->nnodes, 1);
    uint8_t *seen_id = calloc(a->nprims, 1);
    uint32_t *stack = malloc(((size_t)RT_BVH_MAX_DEPTH + 2) * sizeof *stack);
    uint32_t *sdepth = malloc(((size_t)RT_BVH_MAX_DEPTH + 2) * sizeof *sdepth);
    int rc = 0;
    if (!seen_prim || !seen_node || !seen_id || !stack || !sdepth) {
        rc = rt_fail(err, "BVH check: out of memory");
        goto out;
    }
    int sp = 0;
    stack[sp] = 0;
    sdepth[sp++] = 0;
    while (sp > 0 && rc == 0) {
        sp--;
        uint32_t ni = stack[sp], d = sdepth[sp];
        const RtBvhNode *n = &a->nodes[ni];
        if (seen_node[ni]++) {
            rc = rt_fail(err, "BVH check: node %u reached twice", ni);
            break;
        }
        uint32_t count = n->meta & 0xffu;
        if (count) {
            if (count > RT_BVH_LEAF_MAX || (uint64_t)n->index + count > a->nprims) {
                rc = rt_fail(err, "BVH check: leaf %u holds [%u, +%u) of %u primitives", ni, n->index, count,
                             a->nprims);
                break;
            }
            for (uint32_t k = n->index; k < n->index + count; k++) {
                if (seen_prim[k]++) {
                    rc = rt_fail(err, "BVH check: primitive slot %u referenced twice", k);
                    break;
                }
            }
        } else {
            uint32_t l = ni + 1, r = n->index;
            if (r <= l || r >= a->nnodes || l >= a->nnodes) {
                rc = rt_fail(err, "BVH check: node %u has children %u, %u (not depth-first)", ni, l, r);
                break;
            }
            if (!inside(&a->nodes[l], n) || !inside(&a->nodes[r], n)) {
                rc = rt_fail(err, "BVH check: a child of node %u lies outside its bounds", ni);
                break;
            }
            if (d + 1 > RT_BVH_MAX_DEPTH) {
                rc = rt_fail(err, "BVH check: deeper than %d", RT_BVH_MAX_DEPTH);
                break;
            }
            stack[sp] = r; sdepth[sp++] = d + 1;
            stack[sp] = l; sdepth[sp++] = d + 1;
        }
    }
    for (uint32_t k = 0; rc == 0 && k < a->nprims; k++) {
        uint32_t id = a->prims[k].id & ~RT_PRIM_SPHERE_BIT;
        if (!seen_prim[k])
            rc = rt_fail(err, "BVH check: primitive slot %u is in no leaf", k);
        else if (id >= a->nprims || seen_id[id]++)
            rc = rt_fail(err, "BVH check: primitive %u appears twice or is out of range", id);
    }
    for (uint32_t k = 0; rc == 0 && k < a->nnodes; k++)
        if (!seen_node[k])
            rc = rt_fail(err, "BVH check: node %u is unreachable", k);
    if (rc == 0 && a->wide)
        rc = wide_check(a, err);
out:
    free(seen_prim); free(seen_node); free(seen_id); free(stack); free(sdepth);
    return rc;
}
