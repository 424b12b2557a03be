/* build_internal.h - what the BVH build's files share (renderer/accel/):
 * boxes, references, splits, bins and the builder, and each file's entry
 * points. Not part of the library's API (that is rt.h).
 *
 * The small helpers that the binning and partition loops call per reference
 * (the box operations, bin_of, ref_cent) are static inline here, so every
 * file's loops inline them as one file's did. */
#ifndef RT_ACCEL_BUILD_INTERNAL_H
#define RT_ACCEL_BUILD_INTERNAL_H

#include <math.h>
#include <stddef.h>
#include <stdint.h>

#include "pool.h"
#include "rt.h"

/* The bins' array size: RtBvhSettings.bins is at most this. */
#define BVH_MAX_BINS 32
/* A 4-wide leaf reference counts at most 8 records (3 bits of RT_WIDE_LEAF):
 * RtBvhSettings.wide_merge is at most this. */
#define BVH_WIDE_MERGE_MAX 8

/* ---- Boxes ---------------------------------------------------------------- */

typedef struct Box {
    float lo[3], hi[3];
} Box;

static inline void box_empty(Box *b)
{
    for (int i = 0; i < 3; i++) {
        b->lo[i] = RT_INF;
        b->hi[i] = -RT_INF;
    }
}

static inline void box_grow(Box *b, const Box *o)
{
    for (int i = 0; i < 3; i++) {
        b->lo[i] = b->lo[i] < o->lo[i] ? b->lo[i] : o->lo[i];
        b->hi[i] = b->hi[i] > o->hi[i] ? b->hi[i] : o->hi[i];
    }
}

static inline void box_grow_pt(Box *b, const float *p)
{
    for (int i = 0; i < 3; i++) {
        b->lo[i] = b->lo[i] < p[i] ? b->lo[i] : p[i];
        b->hi[i] = b->hi[i] > p[i] ? b->hi[i] : p[i];
    }
}

static inline float box_area(const Box *b)
{
    float dx = b->hi[0] - b->lo[0], dy = b->hi[1] - b->lo[1], dz = b->hi[2] - b->lo[2];
    if (dx < 0.0f || dy < 0.0f || dz < 0.0f)
        return 0.0f;
    return 2.0f * (dx * dy + dy * dz + dz * dx);
}

static inline int box_valid(const Box *b)
{
    return b->lo[0] <= b->hi[0] && b->lo[1] <= b->hi[1] && b->lo[2] <= b->hi[2];
}

/* A hair of padding so a hit on the box boundary is never lost to the
 * rounding of the slab test. */
static inline void box_pad(Box *b)
{
    for (int i = 0; i < 3; i++) {
        float pad = 1e-6f * (fabsf(b->lo[i]) + fabsf(b->hi[i])) + 1e-30f;
        b->lo[i] -= pad;
        b->hi[i] += pad;
    }
}

static inline void box_clip(Box *b, const Box *o)
{
    for (int i = 0; i < 3; i++) {
        b->lo[i] = b->lo[i] > o->lo[i] ? b->lo[i] : o->lo[i];
        b->hi[i] = b->hi[i] < o->hi[i] ? b->hi[i] : o->hi[i];
    }
}

/* The surface area of a binary node's box. */
static inline float node_area(const RtBvhNode *n)
{
    Box b;
    for (int i = 0; i < 3; i++) {
        b.lo[i] = n->lo[i];
        b.hi[i] = n->hi[i];
    }
    return box_area(&b);
}

/* ---- References, splits, bins ------------------------------------------- */

/* A reference: a primitive and the part of its box a node holds. Without
 * spatial splits every reference is a whole primitive box; a spatial split
 * cuts a reference in two at a plane, each half bounding the triangle's part
 * on its side (Stich, Friedrich & Dietrich 2009, "Spatial splits in bounding
 * volume hierarchies"). A primitive cut this way sits in several leaves. */
typedef struct Ref {
    Box box;
    uint32_t prim; /* index into the primitive records (original order) */
} Ref;

static inline float ref_cent(const Ref *r, int a) { return 0.5f * (r->box.lo[a] + r->box.hi[a]); }

/* The bin first..last of coordinate x for bins of width 1/scale from lo;
 * clamped in float, so a point far outside (or a NaN) never overflows the
 * conversion. */
static inline int bin_of(float x, float lo, float scale, int first, int last)
{
    float f = (x - lo) * scale;
    return f >= (float)last ? last : (f >= (float)first ? (int)f : first);
}

/* The best split of a node found so far. */
typedef struct Split {
    float cost;       /* SAH numerator: area(left) * n(left) + area(right) * n(right) */
    int axis;         /* -1: none */
    int spatial;      /* 0: object split by centroid bin; 1: spatial split at pos */
    int bin, nbins;   /* object split: left holds centroid bins 0..bin of nbins */
    float pos;        /* spatial split: the plane */
    Box left, right;  /* object split: the children's boxes */
} Split;

/* Bins of the three axes (object splits: centroid bins; spatial splits:
 * slabs, with the references entering and leaving each). */
typedef struct Bins {
    Box box[3][BVH_MAX_BINS];
    uint32_t in[3][BVH_MAX_BINS], out[3][BVH_MAX_BINS];
} Bins;

/* ---- The builder ----------------------------------------------------------- */

typedef struct Builder {
    const RtBvhSettings *set;
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
    int huge;             /* large arrays in 2 MiB pages (bvh_alloc) */
    RtPool *pool;         /* the build's threads; NULL: serial */
    /* Subtrees built by tasks, not yet copied: each holds a hole of its size
     * in this builder's arrays at (at_node, at_order), filled once at the
     * end (bvh_place_all), so every node is copied once, not once per level. */
    struct Builder *segs;
    uint32_t nsegs, capsegs;
    uint32_t at_node, at_order;
} Builder;

/* Chunks of `chunk` covering all of count, however few (a loop over every
 * primitive or record: no serial case to keep). */
static inline int chunks_covering(uint32_t count, uint32_t chunk)
{
    return (int)(((uint64_t)count + chunk - 1) / chunk);
}

/* Fixed chunks of `chunk` references, so parallel sums and partitions come
 * out the same on any number of threads: 1 below two chunks (then serial). */
static inline int nchunks(uint32_t count, uint32_t chunk)
{
    return (uint64_t)count >= 2u * (uint64_t)chunk ? chunks_covering(count, chunk) : 1;
}

static inline void chunk_range(uint32_t count, uint32_t chunk, int c, uint32_t *i0, uint32_t *i1)
{
    const uint64_t a = (uint64_t)c * chunk, e = a + chunk < count ? a + chunk : count;
    *i0 = (uint32_t)a;
    *i1 = (uint32_t)e;
}

/* ---- Each file's entry points ---------------------------------------------- */

/* settings.c */
int bvh_build_threads(const RtBvhSettings *s, uint64_t nprims);
int bvh_huge_pages_on(const RtBvhSettings *s, int threads);

/* huge_pages.c */
void *bvh_huge_hint(void *p, size_t n, int on);
void *bvh_alloc(size_t n, int on);

/* sah.c: binning, the SAH sweep, object splits, the tree's SAH cost */
typedef void (*BinFn)(const Builder *b, const Ref *refs, uint32_t i0, uint32_t i1, const Box *box,
                      const float *scale, int nb, Bins *o);
void bvh_bins_empty(Bins *b, int nb);
void bvh_bins_all(BinFn fn, const Builder *b, const Ref *refs, uint32_t count, const Box *box, const float *scale,
                  int nb, Bins *o, Bins **keep);
void bvh_bin_scales(const Box *b, int nb, float *scale);
void bvh_sweep(const Box *bins, const uint32_t *lcnt, const uint32_t *rcnt, int nb, int axis, Split *best,
               int spatial);
void bvh_object_split(const Builder *b, const Ref *refs, uint32_t count, const Box *cb, int nb, Split *best,
                      Bins **parts);
double bvh_sah_cost(const RtBvhNode *nodes, uint32_t nnodes, RtPool *pool);

/* spatial.c */
void bvh_spatial_split(const Builder *b, const Ref *refs, uint32_t count, const Box *bb, int nb, Split *best);
int bvh_spatial_partition(Builder *b, const Ref *refs, uint32_t count, const Split *s, Ref *left, uint32_t *nl_out,
                          Ref *right, uint32_t *nr_out);

/* partition.c */
void bvh_bounds(const Builder *b, const Ref *refs, uint32_t count, Box *bb, Box *cb);
int bvh_halves(Builder *b, uint32_t count, Ref **left, Ref **right);
void bvh_object_partition(const Builder *b, const Ref *refs, uint32_t count, const Box *cb, const Split *obj,
                          const Bins *parts, Ref *left, uint32_t *nl_out, Ref *right, uint32_t *nr_out, Box *lb,
                          Box *rb);
void bvh_median_partition(Ref *refs, uint32_t count, int axis, float extent, Ref *left, uint32_t *nl_out, Ref *right,
                          uint32_t *nr_out);

/* build.c */
uint32_t bvh_build_node(Builder *b, Ref *refs, uint32_t count, const Box *known, uint32_t depth);
int bvh_build_binary(const RtScene *s, const RtBvhSettings *set, RtPrim *prims, uint32_t n, RtPool *pool, RtAccel *a,
                     RtError *err);

/* tasks.c */
uint32_t bvh_build_pair(Builder *b, Ref *left, uint32_t nl, const Box *lknown, Ref *right, uint32_t nr,
                        const Box *rknown, uint32_t depth);
void bvh_place_all(Builder *s, RtBvhNode *nodes, uint32_t *order, uint32_t node_off, uint32_t order_off, int own);

/* wide.c */
int bvh_widen(RtAccel *a, const RtBvhSettings *set, RtPool *pool);

#endif
