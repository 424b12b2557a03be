/* accel.c - primitive records, brute force ("none") and the BVH.
 *
 * One build: binned SAH (Wald 2007, "On fast construction of SAH-based
 * bounding volume hierarchies"), 32 bins on the centroid bounds of every axis,
 * with spatial splits (Stich, Friedrich & Dietrich 2009): in large nodes
 * whose best object split leaves overlapping children (RT_BVH_SPATIAL_*),
 * 32 slabs of the node's box are tried as well, triangles cut at the slab
 * planes, and the cheaper split wins; a cut triangle sits in several leaves
 * (at most one extra record per primitive).
 * Leaves of at most RT_BVH_LEAF_MAX records, nodes written depth-first so the
 * first child of node i is node i+1 (pbrt-v4 LinearBVHNode). Spheres and
 * triangles live in one tree. The primitive records are copied into leaf
 * order so a leaf's records are contiguous in memory.
 *
 * The build runs on all the threads it is given and makes the same tree on
 * any number of them, so every backend's images and counters stay
 * bit-identical. Large subtrees are OpenMP tasks, each writing its nodes and
 * leaf order into arrays of its own; its parent leaves a hole of its size,
 * and once the tree is done every subtree is copied into its hole, in
 * parallel, so the nodes land in depth-first order, each moved once. The
 * spatial-split budget is shared between a task's
 * children in proportion to their references, fixed by the counts alone. In
 * large nodes the binning, the bounds and the object partition run over
 * fixed chunks of references in parallel: bins and bounds merge by min, max
 * and integer sums, which are exact in any order, and the partition keeps
 * the serial order (Wald 2007, section 4, does the same horizontally). */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#ifdef _OPENMP
#include <omp.h>
#endif

#include "rt.h"
#include "core/rt_traverse.h" /* RT_BVH_MAX_DEPTH: the traversal stack bounds the build */

#define RT_BVH_BINS 32
/* Below this many levels the SAH split is used; deeper, the object median,
 * which halves the count each level and so bounds the depth. */
#define RT_BVH_SAH_DEPTH 44
/* A subtree of at most this many records becomes one leaf of the 4-wide
 * tree (its reference holds up to 8). */
#ifndef RT_WIDE_MERGE
#define RT_WIDE_MERGE 4
#endif
/* Spatial splits (Stich et al. 2009, "SBVH") are tried in nodes whose best
 * object split leaves children overlapping by more than this fraction of the
 * node's surface area, and of at least RT_BVH_SPATIAL_MIN references and
 * 1/RT_BVH_SPATIAL_SHARE of the scene's: a split pays where triangles are
 * large against the node, near the top of the tree; trying them everywhere
 * gives a tree of the same quality at three times the build time
 * (docs/performance.md, "Large scenes"). */
#ifndef RT_BVH_SPATIAL_MIN
#define RT_BVH_SPATIAL_MIN 128
#endif
#ifndef RT_BVH_SPATIAL_SHARE
#define RT_BVH_SPATIAL_SHARE 2048
#endif
#ifndef RT_BVH_SPATIAL_OVERLAP
#define RT_BVH_SPATIAL_OVERLAP 0.1f
#endif
/* Subtrees of at least this many references are tasks of their own; nodes of
 * at least two chunks of references bin and partition them in parallel. */
#define RT_BVH_TASK_MIN 4096
#define RT_BVH_CHUNK 16384
/* The default build threads: one per RT_BVH_PRIMS_PER_THREAD primitives, at
 * most the threads OpenMP offers. On the 2-core VM (docs/performance.md,
 * "Build threads") 2 threads lost below 16,000 primitives -- 100 of them
 * took 10-400 ms instead of 0.3 ms, waiting on a second thread the other
 * core's work delayed -- and gained from 64,000. A smaller build starts no
 * thread. */
#define RT_BVH_PRIMS_PER_THREAD 16384

/* A large array p of n bytes, just allocated, in 2 MiB pages where the
 * kernel grants them (transparent huge pages on request: madvise mode): a
 * fresh array then costs one page fault per 2 MiB instead of one per 4 KiB,
 * and the top nodes' reference arrays are fresh at every level. Measured
 * (docs/performance.md, "Large scenes"): the 3,567,202-triangle build on the
 * H100 host's 16 threads took 0.83 of the time; on the 2-core VM, 2 threads
 * took 1.13 of it (the 891,802-triangle scene, pages granted without
 * compaction). Hence the default: on from RT_HUGE_PAGES_THREADS threads,
 * where concurrent faults contend. A hint only: the tree is the same. */
#define RT_HUGE_PAGE ((uintptr_t)2 << 20)
static int huge_mode = -1; /* rt_accel_huge_pages: a setting, read by each build */

void rt_accel_huge_pages(int mode) { huge_mode = mode; }

/* (on: this build's choice, kept by the build itself, so builds running at
 * once do not decide for each other) */
static void *huge(void *p, size_t n, int on)
{
#ifdef MADV_HUGEPAGE
    if (p && on && n >= 2 * RT_HUGE_PAGE) {
        const uintptr_t a = ((uintptr_t)p + RT_HUGE_PAGE - 1) & ~(RT_HUGE_PAGE - 1);
        const uintptr_t e = ((uintptr_t)p + n) & ~(RT_HUGE_PAGE - 1);
        if (e > a)
            (void)madvise((void *)a, e - a, MADV_HUGEPAGE);
    }
#endif
    return p;
}

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

static int box_valid(const Box *b) { return b->lo[0] <= b->hi[0] && b->lo[1] <= b->hi[1] && b->lo[2] <= b->hi[2]; }

static void box_pad(Box *b)
{
    /* A hair of padding so a hit on the box boundary is never lost to the
     * rounding of the slab test. */
    for (int i = 0; i < 3; i++) {
        float pad = 1e-6f * (fabsf(b->lo[i]) + fabsf(b->hi[i])) + 1e-30f;
        b->lo[i] -= pad;
        b->hi[i] += pad;
    }
}

static void box_clip(Box *b, const Box *o)
{
    for (int i = 0; i < 3; i++) {
        b->lo[i] = b->lo[i] > o->lo[i] ? b->lo[i] : o->lo[i];
        b->hi[i] = b->hi[i] < o->hi[i] ? b->hi[i] : o->hi[i];
    }
}

const char *rt_accel_name(RtAccelKind k) { return k == RT_ACCEL_BVH ? "bvh" : "none"; }

int rt_accel_parse(const char *s, RtAccelKind *k)
{
    if (strcmp(s, "none") == 0) { *k = RT_ACCEL_NONE; return 0; }
    if (strcmp(s, "bvh") == 0) { *k = RT_ACCEL_BVH; return 0; }
    return -1;
}

static RtPrim *make_prims(const RtScene *s, int nt, int on, uint32_t *n_out, RtError *err)
{
    uint64_t n = (uint64_t)s->nspheres + s->ntriangles;
    if (n >= RT_PRIM_SPHERE_BIT) {
        rt_fail(err, "%s: %llu primitives exceed the limit of %u", s->path, (unsigned long long)n,
                RT_PRIM_SPHERE_BIT - 1);
        return NULL;
    }
    RtPrim *p = huge(calloc(n ? n : 1, sizeof *p), (size_t)n * sizeof *p, on);
    if (!p) {
        rt_fail(err, "out of memory for %llu primitive records", (unsigned long long)n);
        return NULL;
    }
    for (uint32_t i = 0; i < s->nspheres; i++) {
        memcpy(p[i].p0, s->spheres[i].c, sizeof p[i].p0);
        p[i].e1[0] = s->spheres[i].r;
        p[i].id = i | RT_PRIM_SPHERE_BIT;
    }
    (void)nt;
#pragma omp parallel for num_threads(nt) schedule(static)
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

/* The vertices of triangle record p, from the scene's vertex pool. */
static void prim_verts(const RtScene *s, const RtPrim *p, float v[3][3])
{
    const RtTriangle *t = &s->triangles[p->id - s->nspheres];
    for (int k = 0; k < 3; k++) {
        const RtVec3 *q = &s->vertices[t->v[k]];
        v[k][0] = q->x; v[k][1] = q->y; v[k][2] = q->z;
    }
}

/* The padded box of record p (v: its vertices, for a triangle). */
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

/* A reference: a primitive and the part of its box a node holds. Without
 * spatial splits every reference is a whole primitive box; a spatial split
 * cuts a reference in two at a plane, each half bounding the triangle's part
 * on its side (Stich, Friedrich & Dietrich 2009, "Spatial splits in bounding
 * volume hierarchies"). A primitive cut this way sits in several leaves. */
typedef struct Ref {
    Box box;
    uint32_t prim; /* index into the primitive records (original order) */
} Ref;

typedef struct Builder {
    const RtPrim *prims;  /* original order */
    const float (*verts)[3][3]; /* per primitive: a triangle's vertices */
    RtBvhNode *nodes;
    uint32_t nnodes;
    uint32_t *order;      /* leaf order: the primitive of each record slot */
    uint32_t norder;
    uint32_t refs_left;   /* references spatial splits may still add */
    uint32_t spatial_min; /* the smallest node that tries spatial splits */
    uint32_t max_depth, leaves;
    int oom;
    int huge;             /* large arrays in 2 MiB pages (huge) */
    /* Subtrees built by tasks, not yet copied: each holds a hole of its size
     * in this builder's arrays at (at_node, at_order), filled once at the
     * end (place_all), so every node is copied once, not once per level. */
    struct Builder *segs;
    uint32_t nsegs, capsegs;
    uint32_t at_node, at_order;
} Builder;

/* Chunks of RT_BVH_CHUNK references: 1 below two chunks (then serial). */
static int nchunks(uint32_t count)
{
    return count >= 2u * RT_BVH_CHUNK ? (int)((count + RT_BVH_CHUNK - 1) / RT_BVH_CHUNK) : 1;
}

static void chunk_range(uint32_t count, int c, uint32_t *i0, uint32_t *i1)
{
    *i0 = (uint32_t)c * RT_BVH_CHUNK;
    *i1 = *i0 + RT_BVH_CHUNK < count ? *i0 + RT_BVH_CHUNK : count;
}

static float ref_cent(const Ref *r, int a) { return 0.5f * (r->box.lo[a] + r->box.hi[a]); }

/* The best split of a node found so far. */
typedef struct Split {
    float cost;       /* SAH numerator: area(left) * n(left) + area(right) * n(right) */
    int axis;         /* -1: none */
    int spatial;      /* 0: object split by centroid bin; 1: spatial split at pos */
    int bin, nbins;   /* object split: left holds centroid bins 0..bin of nbins */
    float pos;        /* spatial split: the plane */
    Box left, right;  /* object split: the children's boxes */
} Split;

/* Cuts reference r at the plane x[axis] = pos: the boxes of the triangle's
 * parts on either side (its vertices there and its edges' crossings of the
 * plane), padded and clipped to r's box. A sphere keeps its box, cut at the
 * plane. A side the primitive does not reach comes back invalid. */
static void ref_split(const Builder *b, const Ref *r, int axis, float pos, Box *L, Box *R)
{
    const RtPrim *p = &b->prims[r->prim];
    if (p->id & RT_PRIM_SPHERE_BIT) {
        *L = r->box;
        *R = r->box;
    } else {
        const float(*v)[3] = b->verts[r->prim];
        box_empty(L);
        box_empty(R);
        for (int k = 0; k < 3; k++) {
            const float *a = v[k], *c = v[(k + 1) % 3];
            if (a[axis] <= pos)
                box_grow_pt(L, a);
            if (a[axis] >= pos)
                box_grow_pt(R, a);
            if ((a[axis] < pos && c[axis] > pos) || (a[axis] > pos && c[axis] < pos)) {
                float s = (pos - a[axis]) / (c[axis] - a[axis]), q[3];
                for (int i = 0; i < 3; i++)
                    q[i] = a[i] + s * (c[i] - a[i]);
                q[axis] = pos;
                box_grow_pt(L, q);
                box_grow_pt(R, q);
            }
        }
        if (box_valid(L))
            box_pad(L);
        if (box_valid(R))
            box_pad(R);
    }
    float pad = 1e-6f * fabsf(pos) + 1e-30f;
    if (L->hi[axis] > pos + pad)
        L->hi[axis] = pos + pad;
    if (R->lo[axis] < pos - pad)
        R->lo[axis] = pos - pad;
    box_clip(L, &r->box);
    box_clip(R, &r->box);
}

/* The bin first..last of coordinate x for bins of width 1/scale from lo;
 * clamped in float, so a point far outside (or a NaN) never overflows the
 * conversion. */
static int bin_of(float x, float lo, float scale, int first, int last)
{
    float f = (x - lo) * scale;
    return f >= (float)last ? last : (f >= (float)first ? (int)f : first);
}

/* Sweeps nb bins (boxes, and counts entering from the left and right) for
 * the cheapest plane between two bins; updates *best when cheaper. */
static void sweep(const Box *bins, const uint32_t *lcnt, const uint32_t *rcnt, int nb, int axis, Split *best,
                  int spatial)
{
    Box rbox[RT_BVH_BINS], acc;
    uint32_t rsum[RT_BVH_BINS], c = 0;
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

/* Bins of the three axes (object splits: centroid bins; spatial splits:
 * slabs, with the references entering and leaving each). */
typedef struct Bins {
    Box box[3][RT_BVH_BINS];
    uint32_t in[3][RT_BVH_BINS], out[3][RT_BVH_BINS];
} Bins;

static void bins_empty(Bins *b, int nb)
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
static void object_bins(const Ref *refs, uint32_t i0, uint32_t i1, const Box *cb, const float *scale, int nb,
                        Bins *o)
{
    __m128 lo[3][RT_BVH_BINS], hi[3][RT_BVH_BINS];
    bins_empty(o, nb);
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
static void object_bins(const Ref *refs, uint32_t i0, uint32_t i1, const Box *cb, const float *scale, int nb,
                        Bins *o)
{
    bins_empty(o, nb);
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

typedef void (*BinFn)(const void *ctx, const Ref *refs, uint32_t i0, uint32_t i1, const Box *b, const float *scale,
                      int nb, Bins *o);

/* The bins of refs[0..count), over chunks in parallel in a large node. */
static void bins_all(BinFn fn, const void *ctx, const Ref *refs, uint32_t count, const Box *b, const float *scale,
                     int nb, Bins *o)
{
    const int nc = nchunks(count);
    Bins *part = nc > 1 ? malloc((size_t)nc * sizeof *part) : NULL;
    if (!part) {
        fn(ctx, refs, 0, count, b, scale, nb, o);
        return;
    }
#pragma omp taskloop grainsize(1)
    for (int c = 0; c < nc; c++) {
        uint32_t i0, i1;
        chunk_range(count, c, &i0, &i1);
        fn(ctx, refs, i0, i1, b, scale, nb, &part[c]);
    }
    bins_empty(o, nb);
    for (int c = 0; c < nc; c++)
        bins_merge(o, &part[c], nb);
    free(part);
}

static void object_bin_fn(const void *ctx, const Ref *refs, uint32_t i0, uint32_t i1, const Box *b,
                          const float *scale, int nb, Bins *o)
{
    (void)ctx;
    object_bins(refs, i0, i1, b, scale, nb, o);
}

/* nb bins per unit of each axis of box b; 0 on an axis of no extent. */
static void bin_scales(const Box *b, int nb, float *scale)
{
    for (int a = 0; a < 3; a++) {
        const float w = b->hi[a] - b->lo[a];
        scale[a] = w > 0.0f ? (float)nb / w : 0.0f;
    }
}

/* Binned SAH over the references' centroids (cb: their bounds). */
static void object_split(const Ref *refs, uint32_t count, const Box *cb, int nb, Split *best)
{
    float scale[3];
    bin_scales(cb, nb, scale);
    Bins bins;
    bins_all(object_bin_fn, NULL, refs, count, cb, scale, nb, &bins);
    for (int a = 0; a < 3; a++)
        if (scale[a] > 0.0f)
            sweep(bins.box[a], bins.in[a], bins.in[a], nb, a, best, 0);
}

/* Grows bins k0..k1 (slab k between the planes lo + k/scale and
 * lo + (k+1)/scale on axis a) by the parts of triangle v in each slab,
 * clipped to the reference's box r: the vertices in the slab and the edges'
 * crossings of its planes. (Estimates for the SAH sweep; the partition cuts
 * with ref_split.) */
static void chop(const float (*v)[3], const Box *r, int a, float lo, float scale, int k0, int k1, Box *bins)
{
    Box part[RT_BVH_BINS];
    for (int k = k0; k <= k1; k++)
        box_empty(&part[k]);
    int kv[3];
    for (int j = 0; j < 3; j++) {
        kv[j] = bin_of(v[j][a], lo, scale, k0, k1);
        box_grow_pt(&part[kv[j]], v[j]);
    }
    for (int j = 0; j < 3; j++) {
        int j2 = (j + 1) % 3;
        const float *p = v[j], *q = v[j2];
        int kp = kv[j], kq = kv[j2];
        if (kp > kq) {
            const float *t = p; p = q; q = t;
            int tk = kp; kp = kq; kq = tk;
        }
        float dpa = q[a] - p[a];
        for (int k = kp; k < kq; k++) {
            float plane = lo + (float)(k + 1) / scale, x[3];
            float t = dpa > 0.0f ? (plane - p[a]) / dpa : 0.0f;
            t = t < 0.0f ? 0.0f : (t > 1.0f ? 1.0f : t);
            for (int i = 0; i < 3; i++)
                x[i] = p[i] + t * (q[i] - p[i]);
            x[a] = plane;
            box_grow_pt(&part[k], x);
            box_grow_pt(&part[k + 1], x);
        }
    }
    for (int k = k0; k <= k1; k++) {
        box_clip(&part[k], r);
        if (box_valid(&part[k]))
            box_grow(&bins[k], &part[k]);
    }
}

/* Binned spatial split: nb equal slabs of the node's box bb per axis; a
 * reference is cut into every slab it spans and counted entering its first
 * and leaving its last. */
static void spatial_bins(const void *ctx, const Ref *refs, uint32_t i0, uint32_t i1, const Box *bb,
                         const float *scale, int nb, Bins *o)
{
    const Builder *b = ctx;
    bins_empty(o, nb);
    for (int a = 0; a < 3; a++) {
        if (!(scale[a] > 0.0f))
            continue;
        for (uint32_t i = i0; i < i1; i++) {
            const int k0 = bin_of(refs[i].box.lo[a], bb->lo[a], scale[a], 0, nb - 1);
            const int k1 = bin_of(refs[i].box.hi[a], bb->lo[a], scale[a], k0, nb - 1);
            o->in[a][k0]++;
            o->out[a][k1]++;
            if (k0 == k1 || (b->prims[refs[i].prim].id & RT_PRIM_SPHERE_BIT))
                for (int k = k0; k <= k1; k++) {
                    Box part = refs[i].box;
                    part.lo[a] = k > k0 ? bb->lo[a] + (float)k / scale[a] : part.lo[a];
                    part.hi[a] = k < k1 ? bb->lo[a] + (float)(k + 1) / scale[a] : part.hi[a];
                    box_grow(&o->box[a][k], &part);
                }
            else
                chop(b->verts[refs[i].prim], &refs[i].box, a, bb->lo[a], scale[a], k0, k1, o->box[a]);
        }
    }
}

static void spatial_split(const Builder *b, const Ref *refs, uint32_t count, const Box *bb, int nb, Split *best)
{
    float scale[3];
    bin_scales(bb, nb, scale);
    Bins bins;
    bins_all(spatial_bins, b, refs, count, bb, scale, nb, &bins);
    for (int a = 0; a < 3; a++) {
        if (!(scale[a] > 0.0f))
            continue;
        Split s = *best;
        sweep(bins.box[a], bins.in[a], bins.out[a], nb, a, &s, 1);
        if (s.cost < best->cost) {
            *best = s;
            best->pos = bb->lo[a] + (float)(best->bin + 1) / scale[a];
        }
    }
}

/* Partitions refs by the spatial split s into left and right; a reference
 * that straddles the plane is cut in two, or goes whole to one side when
 * that is cheaper ("reference unsplitting"). Returns 0 when the split
 * separates nothing, cuts every reference, or would exceed the reference
 * budget. */
static int spatial_partition(Builder *b, const Ref *refs, uint32_t count, const Split *s, Ref *left,
                             uint32_t *nl_out, Ref *right, uint32_t *nr_out)
{
    int a = s->axis;
    Box lb, rb;
    box_empty(&lb);
    box_empty(&rb);
    uint32_t sure_l = 0, sure_r = 0;
    for (uint32_t i = 0; i < count; i++) {
        if (refs[i].box.hi[a] <= s->pos) {
            box_grow(&lb, &refs[i].box);
            sure_l++;
        } else if (refs[i].box.lo[a] >= s->pos) {
            box_grow(&rb, &refs[i].box);
            sure_r++;
        }
    }
    float nl_all = (float)(count - sure_r), nr_all = (float)(count - sure_l);
    uint32_t nl = 0, nr = 0;
    for (uint32_t i = 0; i < count; i++) {
        const Ref *r = &refs[i];
        if (r->box.hi[a] <= s->pos) {
            left[nl++] = *r;
            continue;
        }
        if (r->box.lo[a] >= s->pos) {
            right[nr++] = *r;
            continue;
        }
        Box L, R;
        ref_split(b, r, a, s->pos, &L, &R);
        int side = 0; /* 0: cut, 1: whole to the left, 2: whole to the right */
        if (!box_valid(&L)) {
            side = 2;
        } else if (!box_valid(&R)) {
            side = 1;
        } else {
            Box lu = lb, ru = rb, lc = lb, rc = rb;
            box_grow(&lu, &r->box);
            box_grow(&ru, &r->box);
            box_grow(&lc, &L);
            box_grow(&rc, &R);
            float cut = box_area(&lc) * nl_all + box_area(&rc) * nr_all;
            float to_l = box_area(&lu) * nl_all + box_area(&rb) * (nr_all - 1.0f);
            float to_r = box_area(&lb) * (nl_all - 1.0f) + box_area(&ru) * nr_all;
            if (to_l < cut && to_l <= to_r)
                side = 1;
            else if (to_r < cut)
                side = 2;
        }
        if (side == 1) {
            left[nl++] = *r;
            box_grow(&lb, &r->box);
            nr_all -= 1.0f;
        } else if (side == 2) {
            right[nr++] = *r;
            box_grow(&rb, &r->box);
            nl_all -= 1.0f;
        } else {
            left[nl] = *r;
            left[nl++].box = L;
            right[nr] = *r;
            right[nr++].box = R;
            box_grow(&lb, &L);
            box_grow(&rb, &R);
        }
    }
    /* (a split that cuts every reference only doubles them) */
    if (nl == 0 || nr == 0 || (nl == count && nr == count) || nl + nr - count > b->refs_left)
        return 0;
    b->refs_left -= nl + nr - count;
    *nl_out = nl;
    *nr_out = nr;
    return 1;
}

/* Comparators for the median fallback, one per axis (tasks sort at once). */
static int cmp_ref_axis(const void *x, const void *y, int axis)
{
    float a = ref_cent(x, axis), c = ref_cent(y, axis);
    return a < c ? -1 : (a > c ? 1 : 0);
}
static int cmp_ref0(const void *x, const void *y) { return cmp_ref_axis(x, y, 0); }
static int cmp_ref1(const void *x, const void *y) { return cmp_ref_axis(x, y, 1); }
static int cmp_ref2(const void *x, const void *y) { return cmp_ref_axis(x, y, 2); }

/* The children's reference arrays of a node of count references, allocated
 * once; 0 (and b->oom) when out of memory. */
static int halves(Builder *b, uint32_t count, Ref **left, Ref **right)
{
    if (*left)
        return 1;
    *left = huge(malloc((size_t)count * sizeof **left), (size_t)count * sizeof **left, b->huge);
    *right = huge(malloc((size_t)count * sizeof **right), (size_t)count * sizeof **right, b->huge);
    if (*left && *right)
        return 1;
    free(*left);
    free(*right);
    *left = *right = NULL;
    b->oom = 1;
    return 0;
}

/* The bounds of refs[i0..i1): their boxes (bb) and their centroids (cb). */
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

static void bounds_all(const Ref *refs, uint32_t count, Box *bb, Box *cb)
{
    const int nc = nchunks(count);
    Box (*part)[2] = nc > 1 ? malloc((size_t)nc * sizeof *part) : NULL;
    Box bc[2];
    if (!part) {
        bounds_range(refs, 0, count, bc);
    } else {
#pragma omp taskloop grainsize(1)
        for (int c = 0; c < nc; c++) {
            uint32_t i0, i1;
            chunk_range(count, c, &i0, &i1);
            bounds_range(refs, i0, i1, part[c]);
        }
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

/* The object split's partition, in the references' order: over chunks in
 * parallel in a large node (each chunk's share of either side first
 * counted, so every chunk knows where its references go). */
static int obj_left(const Ref *r, const Box *cb, const Split *obj, float scale)
{
    return bin_of(ref_cent(r, obj->axis), cb->lo[obj->axis], scale, 0, obj->nbins - 1) <= obj->bin;
}

static void object_partition(const Ref *refs, uint32_t count, const Box *cb, const Split *obj, Ref *left,
                             uint32_t *nl_out, Ref *right, uint32_t *nr_out)
{
    const float scale = (float)obj->nbins / (cb->hi[obj->axis] - cb->lo[obj->axis]);
    const int nc = nchunks(count);
    uint32_t *nleft = nc > 1 ? malloc((size_t)nc * sizeof *nleft) : NULL;
    uint32_t nl = 0, nr = 0;
    if (!nleft) {
        for (uint32_t i = 0; i < count; i++) {
            if (obj_left(&refs[i], cb, obj, scale))
                left[nl++] = refs[i];
            else
                right[nr++] = refs[i];
        }
        *nl_out = nl;
        *nr_out = nr;
        return;
    }
#pragma omp taskloop grainsize(1)
    for (int c = 0; c < nc; c++) {
        uint32_t i0, i1, k = 0;
        chunk_range(count, c, &i0, &i1);
        for (uint32_t i = i0; i < i1; i++)
            k += (uint32_t)obj_left(&refs[i], cb, obj, scale);
        nleft[c] = k;
    }
    for (int c = 0; c < nc; c++) { /* exclusive prefix sums: each chunk's first slot on the left */
        const uint32_t k = nleft[c];
        nleft[c] = nl;
        nl += k;
    }
#pragma omp taskloop grainsize(1)
    for (int c = 0; c < nc; c++) {
        uint32_t i0, i1;
        chunk_range(count, c, &i0, &i1);
        uint32_t l = nleft[c], r = i0 - nleft[c];
        for (uint32_t i = i0; i < i1; i++) {
            if (obj_left(&refs[i], cb, obj, scale))
                left[l++] = refs[i];
            else
                right[r++] = refs[i];
        }
    }
    free(nleft);
    *nl_out = nl;
    *nr_out = count - nl;
}

static uint32_t build(Builder *b, Ref *refs, uint32_t count, uint32_t depth);

/* A builder for a subtree of count references with `budget` of its own,
 * writing into arrays of its own; 0, or -1 out of memory. */
static int sub_init(Builder *s, const Builder *p, uint32_t count, uint32_t budget)
{
    memset(s, 0, sizeof *s);
    s->prims = p->prims;
    s->verts = p->verts;
    s->refs_left = budget;
    s->spatial_min = p->spatial_min;
    s->huge = p->huge;
    const size_t recs = (size_t)count + budget;
    s->nodes = huge(malloc(2 * recs * sizeof *s->nodes), 2 * recs * sizeof *s->nodes, p->huge);
    s->order = huge(malloc(recs * sizeof *s->order), recs * sizeof *s->order, p->huge);
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
 * place_all. (p's arrays reserve their full capacity up front, and a hole
 * is never written until then, so its pages cost nothing meanwhile.) */
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

/* Places subtree s (and those in its holes, as tasks) into the final arrays
 * at node_off and order_off, and frees it. The root builder's own nodes are
 * in place already (own = 0). */
static void place_all(Builder *s, RtBvhNode *nodes, uint32_t *order, uint32_t node_off, uint32_t order_off,
                      int own)
{
    uint32_t n0 = 0, o0 = 0;
    for (uint32_t k = 0; k < s->nsegs; k++) {
        Builder *c = &s->segs[k];
        if (own)
            place_range(s, nodes, order, node_off, order_off, n0, c->at_node, o0, c->at_order);
#pragma omp task firstprivate(c)
        place_all(c, nodes, order, node_off + c->at_node, order_off + c->at_order, 1);
        n0 = c->at_node + c->nnodes;
        o0 = c->at_order + c->norder;
    }
    if (own)
        place_range(s, nodes, order, node_off, order_off, n0, s->nnodes, o0, s->norder);
#pragma omp taskwait
    free(s->segs); /* (the subtrees in it freed themselves) */
    if (own) {
        free(s->nodes);
        free(s->order);
    }
}

/* The two children of a large node, the left one as a task (see the file's
 * header); returns the right child's node. Out of memory for the children's
 * arrays, they are built here one after the other. */
static uint32_t build_pair(Builder *b, Ref *left, uint32_t nl, Ref *right, uint32_t nr, uint32_t depth)
{
    Builder sb[2];
    const uint32_t bl = (uint32_t)((uint64_t)b->refs_left * nl / ((uint64_t)nl + nr));
    if (sub_init(&sb[0], b, nl, bl) != 0) {
        build(b, left, nl, depth);
        return build(b, right, nr, depth);
    }
    if (sub_init(&sb[1], b, nr, b->refs_left - bl) != 0) {
        sub_free(&sb[0]);
        build(b, left, nl, depth);
        return build(b, right, nr, depth);
    }
    b->refs_left = 0;
#pragma omp task default(shared)
    build(&sb[0], left, nl, depth);
    build(&sb[1], right, nr, depth);
#pragma omp taskwait
    sub_append(b, &sb[0]);
    const uint32_t r = b->nnodes;
    sub_append(b, &sb[1]);
    return r;
}

/* Builds the subtree over refs[0..count) (which it frees) and returns its
 * node; the nodes are written depth-first. */
static uint32_t build(Builder *b, Ref *refs, uint32_t count, uint32_t depth)
{
    uint32_t ni = b->nnodes++;
    Box bb, cb;
    bounds_all(refs, count, &bb, &cb);
    RtBvhNode *n = &b->nodes[ni];
    memcpy(n->lo, bb.lo, sizeof n->lo);
    memcpy(n->hi, bb.hi, sizeof n->hi);
    if (depth > b->max_depth)
        b->max_depth = depth;

    /* Choose the split: the cheaper of the object and the spatial split. */
    Ref *left = NULL, *right = NULL;
    uint32_t nl = 0, nr = 0;
    int axis = -1, ext_axis = 0;
    float ext = -1.0f;
    for (int a = 0; a < 3; a++)
        if (cb.hi[a] - cb.lo[a] > ext) {
            ext = cb.hi[a] - cb.lo[a];
            ext_axis = a;
        }
    float parea = box_area(&bb);
    if (count > 1 && depth < RT_BVH_SAH_DEPTH && parea > 0.0f) {
        /* Small nodes get one bin per reference (at least 4): sweeping 32
         * bins for 6 references costs more than it can gain. */
        int nb = count < RT_BVH_BINS ? (count < 4 ? 4 : (int)count) : RT_BVH_BINS;
        Split obj = {.cost = RT_INF, .axis = -1};
        object_split(refs, count, &cb, nb, &obj);
        /* Spatial splits only where the object split's children overlap by
         * more than RT_BVH_SPATIAL_OVERLAP of the node's area, and not in
         * small nodes: there binning the cut triangles costs the most build
         * time for the least gain. */
        Split s = obj;
        Box overlap = obj.left;
        box_clip(&overlap, &obj.right);
        if (count >= b->spatial_min && b->refs_left > 0 &&
            (obj.axis < 0 || box_area(&overlap) > RT_BVH_SPATIAL_OVERLAP * parea))
            spatial_split(b, refs, count, &bb, nb, &s);
        /* SAH: traversal cost 1, intersection cost 1 per primitive. */
        float split_cost = 1.0f + s.cost / parea;
        if (s.axis >= 0 && (count > RT_BVH_LEAF_MAX || split_cost < (float)count)) {
            if (!halves(b, count, &left, &right)) {
                free(refs);
                return ni;
            }
            if (s.spatial && spatial_partition(b, refs, count, &s, left, &nl, right, &nr))
                axis = s.axis;
            else if (obj.axis >= 0) {
                /* the object split, also when the spatial one separated
                 * nothing or ran out of its reference budget */
                object_partition(refs, count, &cb, &obj, left, &nl, right, &nr);
                if (nl > 0 && nr > 0)
                    axis = obj.axis;
            }
        }
    }
    if (axis < 0 && count > RT_BVH_LEAF_MAX) {
        /* No useful split (equal centroids, or too deep): the object median
         * on the widest centroid axis, which halves the count. */
        if (!halves(b, count, &left, &right)) {
            free(refs);
            return ni;
        }
        axis = ext_axis;
        if (ext > 0.0f)
            qsort(refs, count, sizeof *refs, axis == 0 ? cmp_ref0 : (axis == 1 ? cmp_ref1 : cmp_ref2));
        nl = count / 2;
        nr = count - nl;
        memcpy(left, refs, nl * sizeof *refs);
        memcpy(right, refs + nl, nr * sizeof *refs);
    }
    if (axis < 0) {
        n->index = b->norder;
        n->meta = count;
        for (uint32_t i = 0; i < count; i++)
            b->order[b->norder++] = refs[i].prim;
        b->leaves++;
        free(left);
        free(right);
        free(refs);
        return ni;
    }
    free(refs);
    uint32_t r;
    if (count >= RT_BVH_TASK_MIN) {
        r = build_pair(b, left, nl, right, nr, depth + 1);
    } else {
        build(b, left, nl, depth + 1);
        r = build(b, right, nr, depth + 1);
    }
    n = &b->nodes[ni]; /* (nodes never move: capacity reserved up front) */
    n->index = r;
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

/* The children of a large wide node, each subtree a task writing its own
 * array, appended in order with their inner references shifted (the same
 * nodes in the same order as one after the other). 0, or -1 out of memory. */
static int widen_children_tasks(Widen *w, const uint32_t *cand, int nc, uint32_t *refs)
{
    Widen sw[4];
    uint32_t r[4];
    int k;
    for (k = 0; k < nc; k++) {
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
#pragma omp task default(shared) firstprivate(k)
        r[k] = widen_ref(&sw[k], cand[k]);
    }
#pragma omp taskwait
    for (k = 0; k < nc; k++) {
        const uint32_t off = w->n, nn = sw[k].n;
        const int nch = nchunks(nn);
#pragma omp taskloop grainsize(1) if (nch > 1)
        for (int ch = 0; ch < nch; ch++) {
            uint32_t i0 = 0, i1 = nn;
            if (nch > 1)
                chunk_range(nn, ch, &i0, &i1);
            for (uint32_t i = i0; i < i1; i++) {
                RtBvh4Node o = sw[k].wide[i];
                for (int c = 0; c < 4; c++)
                    o.child[c] += (o.child[c] & RT_WIDE_LEAF) ? 0u : off;
                w->wide[off + i] = o;
            }
        }
        refs[k] = (r[k] & RT_WIDE_LEAF) ? r[k] : r[k] + off;
        w->n += nn;
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
        big = !(w->bin[cand[k]].meta & 0xffu) && records_under(w->bin, cand[k]) >= RT_BVH_TASK_MIN * 16u;
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

/* The records under binary node bi when they are at most RT_WIDE_MERGE (a
 * subtree's leaves are contiguous: the nodes are written depth-first), or 0. */
static uint32_t small_subtree(const RtBvhNode *bin, uint32_t bi, uint32_t *first)
{
    uint32_t stack[RT_WIDE_MERGE], lo = 0xffffffffu, total = 0;
    int sp = 0;
    stack[sp++] = bi;
    while (sp > 0) {
        const RtBvhNode *n = &bin[stack[--sp]];
        uint32_t count = n->meta & 0xffu;
        if (count) {
            lo = n->index < lo ? n->index : lo;
            total += count;
        } else if (sp + 2 > RT_WIDE_MERGE) {
            return 0; /* (more leaves than records allowed) */
        } else {
            stack[sp++] = (uint32_t)(n - bin) + 1;
            stack[sp++] = n->index;
        }
        if (total > RT_WIDE_MERGE)
            return 0;
    }
    *first = lo;
    return total;
}

/* The reference to binary node bi in the wide tree: a leaf range, or a new
 * wide node collapsed from bi's subtree. A subtree of at most RT_WIDE_MERGE
 * records left over when its parent's four slots are full becomes one leaf
 * range: a ray tests it as one leaf instead of visiting a node of leaves. */
static uint32_t widen_ref(Widen *w, uint32_t bi)
{
    const RtBvhNode *b = &w->bin[bi];
    uint32_t count = b->meta & 0xffu, first = b->index;
    if (count || (count = small_subtree(w->bin, bi, &first)) != 0)
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
static int widen(RtAccel *a, int nt)
{
    if (a->nnodes == 0 || a->nprims >= RT_WIDE_MAX_FIRST)
        return -1;
    Widen w;
    w.bin = a->nodes;
    w.n = 0;
    /* At most one wide node per binary inner node, plus the root. */
    w.wide = huge(malloc(((size_t)a->nnodes + 1) * sizeof *w.wide), ((size_t)a->nnodes + 1) * sizeof *w.wide,
                  a->huge_pages);
    if (!w.wide)
        return -1;
    uint32_t first;
    if ((a->nodes[0].meta & 0xffu) || small_subtree(a->nodes, 0, &first)) {
        /* the whole tree is one leaf range: a root with one child */
        uint32_t root = 0;
        w.n = 1;
        widen_fill(&w, 0, &root, 1);
    } else {
        (void)nt;
#pragma omp parallel num_threads(nt)
#pragma omp single
        widen_ref(&w, 0);
    }
    RtBvh4Node *shrunk = realloc(w.wide, (size_t)w.n * sizeof *w.wide);
    a->wide = shrunk ? shrunk : w.wide;
    a->nwide = w.n;
    return 0;
}

/* The tree's SAH cost (traversal and intersection cost 1, as the build
 * weighs them): the expected work of a ray that meets the root's box. */
static double sah_cost(const RtBvhNode *nodes, uint32_t nnodes, int nt)
{
    const double root = node_area(&nodes[0]);
    if (!(root > 0.0))
        return 0.0;
    /* (fixed chunks summed in order: the same value on any thread count) */
    const int nc = (int)((nnodes + RT_BVH_CHUNK - 1) / RT_BVH_CHUNK);
    double *part = malloc((size_t)nc * sizeof *part), c = 0.0;
    if (!part)
        return 0.0;
    (void)nt;
#pragma omp parallel for num_threads(nt) schedule(static)
    for (int k = 0; k < nc; k++) {
        uint32_t i0, i1;
        chunk_range(nnodes, k, &i0, &i1);
        double sum = 0.0;
        for (uint32_t i = i0; i < i1; i++) {
            const uint32_t count = nodes[i].meta & 0xffu;
            sum += node_area(&nodes[i]) * (count ? (double)count : 1.0);
        }
        part[k] = sum;
    }
    for (int k = 0; k < nc; k++)
        c += part[k];
    free(part);
    return c / root;
}

int rt_accel_build(const RtScene *s, RtAccelKind kind, RtAccel *a, RtError *err)
{
    return rt_accel_build_threads(s, kind, 0, a, err);
}

int rt_accel_build_threads(const RtScene *s, RtAccelKind kind, int threads, RtAccel *a, RtError *err)
{
    memset(a, 0, sizeof *a);
    a->kind = kind;
    a->build_threads = 1;
    const uint64_t nprims = (uint64_t)s->nspheres + s->ntriangles;
    int nt = rt_thread_count(threads);
    if (threads <= 0 && (uint64_t)nt > nprims / RT_BVH_PRIMS_PER_THREAD)
        nt = nprims < 2 * (uint64_t)RT_BVH_PRIMS_PER_THREAD ? 1 : (int)(nprims / RT_BVH_PRIMS_PER_THREAD);
    uint32_t n = 0;
    const int on = huge_mode == 1 || (huge_mode < 0 && nt >= RT_HUGE_PAGES_THREADS);
    a->huge_pages = on;
    RtPrim *prims = make_prims(s, nt, on, &n, err);
    if (!prims)
        return -1;
    a->nprims = n;
    if (kind == RT_ACCEL_NONE || n == 0) {
        a->prims = prims;
        return 0;
    }
    /* Spatial splits may add up to one reference per primitive (none in a
     * scene so large that twice its count would pass the wide tree's limit
     * on a leaf's first record). */
    uint32_t budget = n < RT_WIDE_MAX_FIRST / 4 ? n : 0;
    uint32_t total = n + budget;
    Ref *refs = huge(malloc((size_t)n * sizeof *refs), (size_t)n * sizeof *refs, on);
    float (*verts)[3][3] = huge(malloc((size_t)n * sizeof *verts), (size_t)n * sizeof *verts, on);
    /* A binary tree with leaves of >= 1 reference has at most 2 refs - 1 nodes. */
    RtBvhNode *nodes = huge(malloc((size_t)2 * total * sizeof *nodes), (size_t)2 * total * sizeof *nodes, on);
    uint32_t *order = huge(malloc((size_t)total * sizeof *order), (size_t)total * sizeof *order, on);
    if (!refs || !verts || !nodes || !order) {
        free(refs); free(verts); free(nodes); free(order); free(prims);
        return rt_fail(err, "out of memory building a BVH over %u primitives", n);
    }
#pragma omp parallel for num_threads(nt) schedule(static)
    for (uint32_t i = 0; i < n; i++) {
        if (!(prims[i].id & RT_PRIM_SPHERE_BIT))
            prim_verts(s, &prims[i], verts[i]);
        prim_box(&prims[i], (const float(*)[3])verts[i], &refs[i].box);
        refs[i].prim = i;
    }
    Builder b;
    memset(&b, 0, sizeof b);
    b.prims = prims;
    b.verts = (const float(*)[3][3])verts;
    b.nodes = nodes;
    b.order = order;
    b.refs_left = budget;
    b.huge = on;
    b.spatial_min = n / RT_BVH_SPATIAL_SHARE > RT_BVH_SPATIAL_MIN ? n / RT_BVH_SPATIAL_SHARE : RT_BVH_SPATIAL_MIN;
#ifdef _OPENMP
#pragma omp parallel num_threads(nt)
#pragma omp single
    {
        a->build_threads = omp_get_num_threads();
        build(&b, refs, n, 0);
        place_all(&b, nodes, order, 0, 0, 0);
    }
#else
    build(&b, refs, n, 0);
    place_all(&b, nodes, order, 0, 0, 0);
#endif
    free(verts);
    const size_t obytes = (size_t)b.norder * sizeof(RtPrim);
    RtPrim *ordered = b.oom ? NULL : huge(malloc(obytes), obytes, on);
    if (!ordered) {
        free(nodes); free(order); free(prims);
        return rt_fail(err, "out of memory building a BVH over %u primitives", n);
    }
#pragma omp parallel for num_threads(nt) schedule(static)
    for (uint32_t i = 0; i < b.norder; i++)
        ordered[i] = prims[order[i]];
    free(order); free(prims);
    if (b.max_depth >= RT_BVH_MAX_DEPTH) {
        free(nodes); free(ordered);
        return rt_fail(err, "BVH depth %u exceeds the traversal stack (%d)", b.max_depth, RT_BVH_MAX_DEPTH);
    }
    RtBvhNode *shrunk = realloc(nodes, (size_t)b.nnodes * sizeof *nodes);
    a->nodes = shrunk ? shrunk : nodes;
    a->nnodes = b.nnodes;
    a->prims = ordered;
    a->nprims = b.norder;
    a->nsplit = b.norder - n;
    a->depth = b.max_depth;
    a->leaves = b.leaves;
    a->sah_cost = sah_cost(a->nodes, a->nnodes, nt);
    widen(a, nt); /* optional: without it the GPU traverses the binary tree */
    return 0;
}

void rt_accel_free(RtAccel *a)
{
    if (!a->mapped) {
        free(a->prims);
        free(a->nodes);
        free(a->wide);
    }
    memset(a, 0, sizeof *a);
}

