/* wide.c - the 4-wide copy of the binary tree (RtBvh4Node). Each wide node
 * takes a binary node's two children and keeps opening the inner child of
 * largest surface area until it holds four (or only leaves remain): the
 * collapse of Wald et al. 2008 / pbrt's MBVH. Every box in it is a binary
 * node's box, bit for bit, so the wide traversal culls no primitive the
 * binary one would test and finds the same closest hit. Leaves are not
 * nodes here: a child reference holds the leaf's primitive range. Large
 * subtrees are tasks, appended in order, so the copy is the same on any
 * number of threads. */
#include <stdlib.h>
#include <string.h>

#include "build_internal.h"

typedef struct Widen {
    const RtBvhSettings *set;
    RtPool *pool;
    const RtBvhNode *bin;
    RtBvh4Node *wide;
    uint32_t n;
} Widen;

static uint32_t widen_ref(Widen *w, uint32_t bi);

/* The records under binary node bi (a subtree's leaves are contiguous). */
static uint32_t records_under(const RtBvhNode *bin, uint32_t bi)
{
    uint32_t lo = bi, hi = bi;
    while (!(bin[lo].meta & 0xffu))
        lo = lo + 1;
    while (!(bin[hi].meta & 0xffu))
        hi = bin[hi].index;
    return bin[hi].index + (bin[hi].meta & 0xffu) - bin[lo].index;
}

/* append_copy's loop: one chunk of the sub-copy. */
typedef struct AppendJob {
    Widen *w;
    const Widen *s;
    uint32_t off, chunk;
    int nch;
} AppendJob;

static void append_chunk(void *ctx, int ch)
{
    const AppendJob *j = ctx;
    uint32_t i0 = 0, i1 = j->s->n;
    if (j->nch > 1)
        chunk_range(j->s->n, j->chunk, ch, &i0, &i1);
    for (uint32_t i = i0; i < i1; i++) {
        RtBvh4Node o = j->s->wide[i];
        for (int c = 0; c < 4; c++)
            o.child[c] += (o.child[c] & RT_WIDE_LEAF) ? 0u : j->off;
        j->w->wide[j->off + i] = o;
    }
}

/* Appends sub-copy s (its own array) to w's, its inner references shifted
 * by where it lands: over chunks in parallel when large. */
static void append_copy(Widen *w, const Widen *s)
{
    const uint32_t chunk = (uint32_t)w->set->chunk;
    AppendJob job = {w, s, w->n, chunk, nchunks(s->n, chunk)};
    pool_for(w->pool, job.nch, append_chunk, &job);
    w->n += s->n;
}

/* widen_children_tasks's task: one child's subtree into its own copy. */
typedef struct ChildJob {
    Widen *sw;
    uint32_t bi, ref;
} ChildJob;

static void widen_child(void *arg)
{
    ChildJob *j = arg;
    j->ref = widen_ref(j->sw, j->bi);
}

/* The children of a large wide node, each subtree a task writing its own
 * array, appended in order with their inner references shifted (the same
 * nodes in the same order as one after the other). 0, or -1 out of memory. */
static int widen_children_tasks(Widen *w, const uint32_t *cand, int nc, uint32_t *refs)
{
    Widen sw[4];
    ChildJob job[4];
    PoolTask task[4];
    PoolGroup g = {0, NULL};
    int k;
    for (k = 0; k < nc; k++) {
        sw[k].set = w->set;
        sw[k].pool = w->pool;
        sw[k].bin = w->bin;
        sw[k].n = 0;
        sw[k].wide = malloc(((size_t)2 * records_under(w->bin, cand[k]) + 1) * sizeof *sw[k].wide);
        if (!sw[k].wide)
            break;
    }
    if (k < nc) {
        while (k-- > 0)
            free(sw[k].wide);
        return -1;
    }
    for (k = 0; k < nc; k++) {
        job[k] = (ChildJob){&sw[k], cand[k], 0};
        if (k + 1 < nc)
            pool_spawn(w->pool, &g, &task[k], widen_child, &job[k]);
    }
    widen_child(&job[nc - 1]);
    pool_wait(w->pool, &g);
    for (k = 0; k < nc; k++) {
        const uint32_t off = w->n, r = job[k].ref;
        append_copy(w, &sw[k]);
        refs[k] = (r & RT_WIDE_LEAF) ? r : r + off;
        free(sw[k].wide);
    }
    return 0;
}

/* Fills wide node wi with the binary nodes cand[0..nc), in that order (the
 * children of a large node as tasks). (The CUDA backend reorders the slots
 * for its shadow rays: its schedule.c.) */
static void widen_fill(Widen *w, uint32_t wi, const uint32_t *cand, int nc)
{
    uint32_t refs[4];
    int big = 0;
    for (int k = 0; k < nc && !big; k++)
        big = !(w->bin[cand[k]].meta & 0xffu) &&
              records_under(w->bin, cand[k]) >= (uint32_t)w->set->wide_task_min;
    if (!big || widen_children_tasks(w, cand, nc, refs) != 0)
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

/* The records under binary node bi when they are at most `merge` (a
 * subtree's leaves are contiguous: the nodes are written depth-first), or 0. */
static uint32_t small_subtree(const RtBvhNode *bin, uint32_t bi, int merge, uint32_t *first)
{
    uint32_t stack[BVH_WIDE_MERGE_MAX], lo = 0xffffffffu, total = 0;
    int sp = 0;
    stack[sp++] = bi;
    while (sp > 0) {
        const RtBvhNode *n = &bin[stack[--sp]];
        uint32_t count = n->meta & 0xffu;
        if (count) {
            lo = n->index < lo ? n->index : lo;
            total += count;
        } else if (sp + 2 > merge) {
            return 0; /* (more leaves than records allowed) */
        } else {
            stack[sp++] = (uint32_t)(n - bin) + 1;
            stack[sp++] = n->index;
        }
        if (total > (uint32_t)merge)
            return 0;
    }
    *first = lo;
    return total;
}

/* The reference to binary node bi in the wide tree: a leaf range, or a new
 * wide node collapsed from bi's subtree. A subtree of at most wide_merge
 * records left over when its parent's four slots are full becomes one leaf
 * range: a ray tests it as one leaf instead of visiting a node of leaves. */
static uint32_t widen_ref(Widen *w, uint32_t bi)
{
    const RtBvhNode *b = &w->bin[bi];
    uint32_t count = b->meta & 0xffu, first = b->index;
    if (count || (count = small_subtree(w->bin, bi, w->set->wide_merge, &first)) != 0)
        return RT_WIDE_LEAF | (first << 3) | (count - 1);
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
int bvh_widen(RtAccel *a, const RtBvhSettings *set, RtPool *pool)
{
    if (a->nnodes == 0 || a->nprims >= RT_WIDE_MAX_FIRST)
        return -1;
    Widen w;
    w.set = set;
    w.pool = pool;
    w.bin = a->nodes;
    w.n = 0;
    /* At most one wide node per binary inner node, plus the root. */
    w.wide = bvh_alloc(((size_t)a->nnodes + 1) * sizeof *w.wide, a->huge_pages);
    if (!w.wide)
        return -1;
    uint32_t first;
    if ((a->nodes[0].meta & 0xffu) || small_subtree(a->nodes, 0, set->wide_merge, &first)) {
        /* the whole tree is one leaf range: a root with one child */
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
