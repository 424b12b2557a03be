/* rt_traverse.h - ray/primitive tests and the two accelerators' traversals
 * (brute force "none" and the flat BVH), shared by every backend.
 *
 * Determinism: the closest hit is the smallest t > RT_T_MIN, ties going to the
 * lower global primitive index. Brute force and BVH call the same
 * rt_prim_intersect on the same records, so they find bit-identical hits.
 *
 * A unit defines, before including this,
 *   RT_WIDE_LEAF_VOTE(has_leaf, any)  whether a ray of the 4-wide traversal
 *                    with a leaf aside (has_leaf) stops going through inner
 *                    nodes and tests it (rt_trace_ray_wide): on the CPU at
 *                    once (backends/cpu_trace.h), on the GPU when every
 *                    active lane of the warp has one (backends/cuda/kernels.cuh).
 *                    `any` lets a backend treat shadow rays apart (none does:
 *                    docs/gpu.md). Units that run no wide traversal define
 *                    the CPU's.
 * No default: which vote a unit's traversal takes never depends on what it
 * included first. */
#ifndef RT_WIDE_LEAF_VOTE
#error "define RT_WIDE_LEAF_VOTE(has_leaf, any) before including rt_traverse.h (see above)"
#endif
#ifndef RT_TRAVERSE_H
#define RT_TRAVERSE_H

#include <string.h>

#include "rt_camera.h"

/* On x86 hosts the slab test runs on SSE lanes: the same IEEE operations
 * (subtract, multiply, min, max) as the scalar path, so it culls exactly the
 * same boxes, in about a third of the instructions. */
#if !defined(__CUDACC__) && (defined(__SSE2__) || defined(_M_X64)) && !defined(RT_NO_SIMD)
#include <emmintrin.h>
#define RT_SSE 1
#else
#define RT_SSE 0
#endif

/* Traversal stack depth: above RT_BVH_MAX_DEPTH (core/rt_scene.h), which
 * every builder keeps to, so the stack can never overflow. */
#define RT_BVH_STACK 64

typedef struct RtHit {
    float t;     /* distance along the ray */
    float u, v;  /* barycentrics of vertices 1 and 2 (triangles) */
    uint32_t id; /* RtPrim.id of the hit primitive; UINT32_MAX: none */
} RtHit;

/* Returns t of the nearest valid intersection in (RT_T_MIN, inf), or RT_INF;
 * *u_out, *v_out are written on every call (meaningful on a hit).
 * Triangles: Moller & Trumbore 1997, written without early exits: the
 * acceptance conditions (NaN included) are those of the early-exit form, and
 * with no branch inside, two calls overlap on the GPU (rt_leaf_hits) and brute
 * force runs faster on the CPU. Spheres: the quadratic solved as in Haines et
 * al., "Precision improvements for ray/sphere intersection", Ray Tracing Gems
 * ch. 7 (distance to the chord, then the stable root pair), which keeps
 * float32 accurate for small spheres seen from far away. */
static inline RT_HD float rt_prim_intersect(const RtPrim *p, RtVec3 o, RtVec3 d, float *u_out, float *v_out)
{
    if (p->id & RT_PRIM_SPHERE_BIT) {
        *u_out = 0.0f;
        *v_out = 0.0f;
        RtVec3 c = rt_v3_load(p->p0);
        float r = p->e1[0];
        RtVec3 f = rt_sub(o, c);
        float b = -rt_dot(f, d);
        RtVec3 l = rt_madd(f, d, b);
        float disc = r * r - rt_dot(l, l);
        if (disc < 0.0f)
            return RT_INF;
        float cc = rt_dot(f, f) - r * r;
        float q = b + (b >= 0.0f ? sqrtf(disc) : -sqrtf(disc));
        float t0 = q != 0.0f ? cc / q : 0.0f;
        float t1 = q;
        float lo = rt_minf(t0, t1), hi = rt_maxf(t0, t1);
        if (lo > RT_T_MIN)
            return lo;
        if (hi > RT_T_MIN)
            return hi;
        return RT_INF;
    }
    RtVec3 e1 = rt_v3_load(p->e1), e2 = rt_v3_load(p->e2);
    RtVec3 pv = rt_cross(d, e2);
    float det = rt_dot(e1, pv);
    float inv = 1.0f / det;
    RtVec3 tv = rt_sub(o, rt_v3_load(p->p0));
    float u = rt_dot(tv, pv) * inv;
    RtVec3 qv = rt_cross(tv, e1);
    float v = rt_dot(d, qv) * inv;
    float t = rt_dot(e2, qv) * inv;
    int ok = (det != 0.0f) & !(u < 0.0f) & !(u > 1.0f) & !(v < 0.0f) & !(u + v > 1.0f) & (t > RT_T_MIN);
    *u_out = u;
    *v_out = v;
    return ok ? t : RT_INF;
}

/* Keeps the candidate if it is closer, or as close with a lower index. */
static inline RT_HD void rt_hit_update(RtHit *h, const RtPrim *p, float t, float u, float v)
{
    uint32_t gid = p->id & ~RT_PRIM_SPHERE_BIT, hid = h->id & ~RT_PRIM_SPHERE_BIT;
    if (t < h->t || (t == h->t && t < RT_INF && gid < hid)) {
        h->t = t;
        h->u = u;
        h->v = v;
        h->id = p->id;
    }
}

/* Per-ray constants for the slab test. Zero direction components are nudged
 * to a tiny value so 1/d stays finite and 0*inf never makes a NaN. */
typedef struct RtRayBox {
    RtVec3 o, inv;
#if RT_SSE
    __m128 o4, inv4; /* lanes x, y, z, 0 */
#endif
} RtRayBox;

static inline RT_HD float rt_safe_inv(float x)
{
    const float tiny = 1e-20f;
    if (x > -tiny && x < tiny)
        x = x < 0.0f ? -tiny : tiny;
    return 1.0f / x;
}

static inline RT_HD RtRayBox rt_raybox(RtVec3 o, RtVec3 d)
{
    RtRayBox rb;
    rb.o = o;
    rb.inv = rt_v3(rt_safe_inv(d.x), rt_safe_inv(d.y), rt_safe_inv(d.z));
#if RT_SSE
    rb.o4 = _mm_set_ps(0.0f, o.z, o.y, o.x);
    rb.inv4 = _mm_set_ps(0.0f, rb.inv.z, rb.inv.y, rb.inv.x);
#endif
    return rb;
}

/* Min and max inside the slab test. No operand is ever NaN there (box bounds
 * are finite or +-RT_INF and 1/d is finite), so fminf/fmaxf give the same
 * values as rt_minf/rt_maxf (up to the sign of a zero, which no comparison
 * sees) in one GPU instruction (FMNMX) instead of a compare and a select. */
#if defined(__CUDA_ARCH__)
#define RT_BOX_MIN fminf
#define RT_BOX_MAX fmaxf
#else
#define RT_BOX_MIN rt_minf
#define RT_BOX_MAX rt_maxf
#endif

/* Float rounding makes a slab test's distances differ from the exact ones
 * by a few ulps, and from the triangle test's t. Every box test widens the
 * exit by this factor (pbrt-v4's 1 + 2*gamma(3)), and every pop compares
 * the stored entry with the closest hit widened the same way: a box entered
 * at a rounded-up distance must not be culled by a hit at a rounded-down one
 * (coplanar faces, e.g. a prism standing on a floor), or BVH and brute force
 * would disagree on a pixel. */
#define RT_BOX_WIDEN 1.0000004f

/* The scalar slab test: entry distance of the ray into the box lo..hi within
 * [tmin, tmax], or RT_INF. Every scalar box test calls it (rt_box_enter without
 * SSE, and the wide traversal). */
static inline RT_HD float rt_slab_enter(float lx, float ly, float lz, float hx, float hy, float hz,
                                        const RtRayBox *rb, float tmin, float tmax)
{
    float tx0 = (lx - rb->o.x) * rb->inv.x, tx1 = (hx - rb->o.x) * rb->inv.x;
    float ty0 = (ly - rb->o.y) * rb->inv.y, ty1 = (hy - rb->o.y) * rb->inv.y;
    float tz0 = (lz - rb->o.z) * rb->inv.z, tz1 = (hz - rb->o.z) * rb->inv.z;
    float t0 = RT_BOX_MAX(RT_BOX_MAX(RT_BOX_MIN(tx0, tx1), RT_BOX_MIN(ty0, ty1)), RT_BOX_MAX(RT_BOX_MIN(tz0, tz1), tmin));
    float t1 = RT_BOX_MIN(RT_BOX_MIN(RT_BOX_MAX(tx0, tx1), RT_BOX_MAX(ty0, ty1)), RT_BOX_MIN(RT_BOX_MAX(tz0, tz1), tmax));
    return t0 <= t1 * RT_BOX_WIDEN ? t0 : RT_INF;
}

/* Entry distance of the ray into the node's box within [tmin, tmax], or RT_INF. */
static inline RT_HD float rt_box_enter(const RtBvhNode *n, const RtRayBox *rb, float tmin, float tmax)
{
#if RT_SSE
    /* Lane 3 holds index/meta bits; overwriting it with lane 2 (one shuffle)
     * makes the 4-lane reductions see x, y, z only. tmin/tmax join as scalars. */
    __m128 a = _mm_mul_ps(_mm_sub_ps(_mm_loadu_ps(n->lo), rb->o4), rb->inv4);
    __m128 b = _mm_mul_ps(_mm_sub_ps(_mm_loadu_ps(n->hi), rb->o4), rb->inv4);
    __m128 tn = _mm_min_ps(a, b), tf = _mm_max_ps(a, b);
    tn = _mm_shuffle_ps(tn, tn, _MM_SHUFFLE(2, 2, 1, 0));
    tf = _mm_shuffle_ps(tf, tf, _MM_SHUFFLE(2, 2, 1, 0));
    tn = _mm_max_ps(tn, _mm_shuffle_ps(tn, tn, _MM_SHUFFLE(1, 0, 3, 2)));
    tf = _mm_min_ps(tf, _mm_shuffle_ps(tf, tf, _MM_SHUFFLE(1, 0, 3, 2)));
    tn = _mm_max_ss(tn, _mm_shuffle_ps(tn, tn, _MM_SHUFFLE(2, 3, 0, 1)));
    tf = _mm_min_ss(tf, _mm_shuffle_ps(tf, tf, _MM_SHUFFLE(2, 3, 0, 1)));
    float t0s = rt_maxf(_mm_cvtss_f32(tn), tmin), t1s = rt_minf(_mm_cvtss_f32(tf), tmax);
    return t0s <= t1s * RT_BOX_WIDEN ? t0s : RT_INF;
#else
    return rt_slab_enter(n->lo[0], n->lo[1], n->lo[2], n->hi[0], n->hi[1], n->hi[2], rb, tmin, tmax);
#endif
}

/* Which of two sibling boxes the ray enters (bit 0: a, bit 1: b) and the entry
 * distances (valid where the bit is set). The SSE path shares the lane
 * reductions between the two boxes; it computes the same values as two calls
 * of rt_box_enter. Returning a mask spares the caller float compares. */
static inline RT_HD int rt_box_enter2(const RtBvhNode *na, const RtBvhNode *nb, const RtRayBox *rb, float tmax,
                                      float *ta, float *tb)
{
#if RT_SSE
    __m128 a0 = _mm_mul_ps(_mm_sub_ps(_mm_loadu_ps(na->lo), rb->o4), rb->inv4);
    __m128 a1 = _mm_mul_ps(_mm_sub_ps(_mm_loadu_ps(na->hi), rb->o4), rb->inv4);
    __m128 b0 = _mm_mul_ps(_mm_sub_ps(_mm_loadu_ps(nb->lo), rb->o4), rb->inv4);
    __m128 b1 = _mm_mul_ps(_mm_sub_ps(_mm_loadu_ps(nb->hi), rb->o4), rb->inv4);
    __m128 an = _mm_min_ps(a0, a1), af = _mm_max_ps(a0, a1);
    __m128 bn = _mm_min_ps(b0, b1), bf = _mm_max_ps(b0, b1);
    /* [ax, ay, bx, by] against [az, az, bz, bz], then across pairs. */
    __m128 n = _mm_max_ps(_mm_movelh_ps(an, bn), _mm_shuffle_ps(an, bn, _MM_SHUFFLE(2, 2, 2, 2)));
    __m128 f = _mm_min_ps(_mm_movelh_ps(af, bf), _mm_shuffle_ps(af, bf, _MM_SHUFFLE(2, 2, 2, 2)));
    n = _mm_max_ps(n, _mm_shuffle_ps(n, n, _MM_SHUFFLE(2, 3, 0, 1)));
    f = _mm_min_ps(f, _mm_shuffle_ps(f, f, _MM_SHUFFLE(2, 3, 0, 1)));
    n = _mm_max_ps(n, _mm_setzero_ps());
    f = _mm_min_ps(f, _mm_set1_ps(tmax));
    int hit = _mm_movemask_ps(_mm_cmple_ps(n, _mm_mul_ps(f, _mm_set1_ps(RT_BOX_WIDEN))));
    *ta = _mm_cvtss_f32(n);
    *tb = _mm_cvtss_f32(_mm_movehl_ps(n, n));
    return (hit & 1) | ((hit >> 1) & 2);
#else
    *ta = rt_box_enter(na, rb, 0.0f, tmax);
    *tb = rt_box_enter(nb, rb, 0.0f, tmax);
    return (*ta != RT_INF ? 1 : 0) | (*tb != RT_INF ? 2 : 0);
#endif
}

/* A primitive record into registers. On the GPU: five 8-byte read-only loads
 * (the records are 40 bytes, 8-byte aligned) instead of ten 4-byte ones. */
static inline RT_HD void rt_prim_fetch(const RtPrim *p, RtPrim *out)
{
#if defined(__CUDA_ARCH__)
    const float2 *q = (const float2 *)p;
    float2 a = __ldg(q), b = __ldg(q + 1), c = __ldg(q + 2), d = __ldg(q + 3), e = __ldg(q + 4);
    out->p0[0] = a.x; out->p0[1] = a.y; out->p0[2] = b.x;
    out->e1[0] = b.y; out->e1[1] = c.x; out->e1[2] = c.y;
    out->e2[0] = d.x; out->e2[1] = d.y; out->e2[2] = e.x;
    out->id = __float_as_uint(e.y);
#else
    *out = *p;
#endif
}

/* One tested primitive into the hit record (rt_leaf_hits): returns 1 when an
 * any-hit query is answered. */
static inline RT_HD int rt_leaf_take(const RtPrim *p, float t, float u, float v, int any, RtHit *hit, int *found,
                                     uint32_t *tests)
{
    (*tests)++;
    if (any) {
        if (t < hit->t) {
            hit->t = t; hit->u = u; hit->v = v; hit->id = p->id;
            *found = 1;
            return 1;
        }
    } else if (t <= hit->t && t < RT_INF) {
        rt_hit_update(hit, p, t, u, v);
        *found = 1;
    }
    return 0;
}

/* A leaf's primitives [first, first + count) against the ray, as the binary
 * traversal below tests them: closest hit (ties to the lower index), or for
 * any != 0 the first hit strictly closer than hit->t. Returns 1 when an
 * any-hit query is answered. The wide traversal uses it too. */
static inline RT_HD int rt_leaf_hits(const RtSceneView *s, uint32_t first, uint32_t count, RtVec3 o, RtVec3 d,
                                     int any, RtHit *hit, int *found, uint32_t *tests)
{
    /* Two primitives per step, both tested before either result is used:
     * two independent chains of loads and arithmetic instead of one (the
     * results are then taken in order, exactly as one at a time would). An
     * odd count tests its last primitive twice and ignores the copy. */
    for (uint32_t k = 0; k < count; k += 2) {
        const uint32_t two = k + 1 < count;
        RtPrim pa, pb;
        rt_prim_fetch(&s->prims[first + k], &pa);
        rt_prim_fetch(&s->prims[first + k + two], &pb);
        float ua, va, ub, vb;
        const float ta = rt_prim_intersect(&pa, o, d, &ua, &va);
        const float tb = rt_prim_intersect(&pb, o, d, &ub, &vb);
        if (rt_leaf_take(&pa, ta, ua, va, any, hit, found, tests))
            return 1;
        if (two && rt_leaf_take(&pb, tb, ub, vb, any, hit, found, tests))
            return 1;
    }
    return 0;
}

/* The `any` argument of the traversals: 0, the closest hit; RT_ANY_HIT,
 * any hit closer than tmax (a shadow ray); RT_ANY_HIT_SLOT, the same query,
 * for which the 4-wide traversal stacks a node's entered children in slot
 * order instead of sorting them (rt_wide_visit; the other traversals treat
 * it as RT_ANY_HIT). Same answers either way; which is faster depends on
 * the frame (docs/gpu.md), so the caller chooses. */
#define RT_ANY_HIT 1
#define RT_ANY_HIT_SLOT 2

/* Closest hit (any = 0) or any hit closer than tmax (any != 0). Returns 1 on a hit. */
static inline RT_HD int rt_trace_ray(const RtSceneView *s, RtVec3 o, RtVec3 d, float tmax, int any,
                                     RtHit *hit, RtCounters *cnt)
{
    hit->t = tmax;
    hit->u = hit->v = 0.0f;
    hit->id = 0xffffffffu;
    int found = 0;
    float u = 0.0f, v = 0.0f, t;
    if (s->nnodes == 0) {
        /* Brute force: the report's baseline, every ray against every primitive.
         * Records are in index order, so a strict < keeps the lower index on ties. */
        uint64_t tests = 0;
        RtPrim pr;
        for (uint32_t i = 0; i < s->nprims; i++) {
            tests++;
            rt_prim_fetch(&s->prims[i], &pr); /* read-only loads on the GPU */
            t = rt_prim_intersect(&pr, o, d, &u, &v);
            if (t < hit->t) {
                hit->t = t; hit->u = u; hit->v = v; hit->id = pr.id;
                found = 1;
                if (any)
                    break;
            }
        }
        cnt->prim_tests += tests;
        return found;
    }
    RtRayBox rb = rt_raybox(o, d);
    uint32_t stack_node[RT_BVH_STACK];
    float stack_t[RT_BVH_STACK];
    int sp = 0;
    uint32_t ni = 0;
    uint64_t visits = 0, tests = 0;
    /* A single-leaf tree has no parent to test the root's box: test it here. */
    if ((s->nodes[0].meta & 0xffu) && rt_box_enter(&s->nodes[0], &rb, 0.0f, tmax) == RT_INF) {
        cnt->node_visits += 1;
        return 0;
    }
    for (;;) {
        const RtBvhNode *n = &s->nodes[ni];
        visits++;
        uint32_t count = n->meta & 0xffu;
        if (count) {
            const RtPrim *p = &s->prims[n->index];
            for (uint32_t k = 0; k < count; k++) {
                tests++;
                t = rt_prim_intersect(&p[k], o, d, &u, &v);
                if (any) {
                    if (t < hit->t) { /* strictly closer than the light, as brute force */
                        hit->t = t; hit->u = u; hit->v = v; hit->id = p[k].id;
                        found = 1;
                        goto done;
                    }
                } else if (t <= hit->t && t < RT_INF) {
                    rt_hit_update(hit, &p[k], t, u, v);
                    found = 1;
                }
            }
        } else {
            uint32_t a = ni + 1, b = n->index;
            float ta, tb;
            int mask = rt_box_enter2(&s->nodes[a], &s->nodes[b], &rb, hit->t, &ta, &tb);
            if (mask == 3) {
                /* Near child first; the far one waits with its entry distance.
                 * (Shadow rays too: the nearer box is likelier to block.) */
                /* Selects rather than swaps (conditional moves: the order
                 * is a coin toss the branch predictor cannot learn). */
                int bfirst = tb < ta;
                stack_node[sp] = bfirst ? a : b;
                stack_t[sp] = bfirst ? ta : tb;
                sp++;
                ni = bfirst ? b : a;
                continue;
            }
            if (mask == 1) { ni = a; continue; }
            if (mask == 2) { ni = b; continue; }
        }
        /* Pop, skipping nodes entered beyond the closest hit so far
         * (widened: RT_BOX_WIDEN). Ties are still visited: an equal-t hit
         * with a lower index may live there. */
        for (;;) {
            if (sp == 0)
                goto done;
            sp--;
            if (stack_t[sp] <= hit->t * RT_BOX_WIDEN)
                break;
        }
        ni = stack_node[sp];
    }
done:
    cnt->node_visits += visits;
    cnt->prim_tests += tests;
    return found;
}

/* The same query on the 4-wide tree (RtBvh4Node): one visit tests the four
 * child boxes (the binary tree's boxes, with the conservative FMA slab test
 * rt_wide_key, tmin = 0), sorts the entered ones by entry distance (for
 * RT_ANY_HIT_SLOT: takes them in slot order), goes on with the nearest (the
 * first) and stacks the others with their distances; leaf children
 * are primitive ranges, put aside until RT_WIDE_LEAF_VOTE (above) says to
 * test them.
 * Same hits as rt_trace_ray: the closest t, ties to the lower index, any hit
 * strictly closer than tmax. node_visits counts wide nodes and leaves (fewer
 * than the binary tree's). The GPU's default traversal (docs/gpu.md); its
 * four box tests are independent work, which hides latency. */
#define RT_WIDE_STACK (3 * RT_BVH_MAX_DEPTH + 4)
#define RT_WIDE_MISS_KEY 0xffffffffu
#define RT_WIDE_DONE 0xffffffffu /* no node left (has the leaf bit; never a reference) */


static inline RT_HD uint32_t rt_float_bits(float f)
{
#if defined(__CUDA_ARCH__)
    return __float_as_uint(f);
#else
    uint32_t u;
    memcpy(&u, &f, sizeof u);
    return u;
#endif
}

/* The wide traversal's slab test, one fused multiply-add per plane: the
 * plane at coordinate x is entered at x * inv + c with c = -o * inv, as GPU
 * tracers write it (Aila & Laine 2009), which is 12 instructions fewer per
 * node than (x - o) * inv. The rounding of o * inv is an absolute error of at
 * most |o * inv| * 2^-24 in every distance; each plane's constant moves that
 * plane's distance outwards by |o * inv| * 2^-21 (down for the near side of
 * the slab, up for the far side), and the exit is widened by the same
 * relative margin as rt_slab_enter's. So the test stays conservative: it may
 * enter a box the exact test would miss by a hair (one more visit) but never
 * misses one it would enter, and the hits stay those of rt_trace_ray
 * (test_wide, test_geometry).
 *
 * Which plane of a slab is the near one depends only on the sign of inv (lo
 * where inv > 0, hi where inv < 0; 1/d is never 0), so the traversal reads
 * each axis's near and far planes by the ray's signs (sx, sy, sz) instead of
 * ordering the two distances of every child with a min and a max: 24
 * instructions fewer per node. With the constants above the near distance is
 * never above the far one (rounding is monotonic), so the distances are the
 * ones min and max would pick. */
typedef struct RtWideRay {
    float ix, iy, iz;          /* 1/d, as rt_raybox */
    float nx, ny, nz;          /* constant of the near plane, per axis */
    float fx, fy, fz;          /* constant of the far plane, per axis */
    uint32_t sx, sy, sz;       /* 1 where 1/d < 0: the hi plane is the near one */
} RtWideRay;

static inline RT_HD void rt_wide_consts(float o, float inv, float *cnear, float *cfar, uint32_t *sign)
{
    const float ood = o * inv;
    const float e = fabsf(ood) * 4.76837158203125e-7f; /* 2^-21 */
    *cnear = -ood - e;
    *cfar = -ood + e;
    *sign = inv < 0.0f;
}

static inline RT_HD RtWideRay rt_wide_ray(RtVec3 o, RtVec3 d)
{
    RtWideRay w;
    w.ix = rt_safe_inv(d.x);
    w.iy = rt_safe_inv(d.y);
    w.iz = rt_safe_inv(d.z);
    rt_wide_consts(o.x, w.ix, &w.nx, &w.fx, &w.sx);
    rt_wide_consts(o.y, w.iy, &w.ny, &w.fy, &w.sy);
    rt_wide_consts(o.z, w.iz, &w.nz, &w.fz, &w.sz);
    return w;
}

/* Sort key of a child from its near planes (nx, ny, nz) and far planes:
 * the bits of its entry distance (t >= 0, so they order as the floats do)
 * with the low two replaced by k, or all ones for a miss. An empty slot's
 * inside-out box (rt_accel_build) always misses: its near distances are
 * +inf and its far ones -inf. Keys sort with integer min/max and carry their
 * child along; the key's distance part is at most t widened (RT_BOX_WIDEN),
 * the pop's limit, so the pop culls no box that the test itself would keep. */
static inline RT_HD uint32_t rt_wide_key(const RtWideRay *w, float nx, float ny, float nz, float fx, float fy,
                                         float fz, float tmax, uint32_t k)
{
    const float ax = fmaf(nx, w->ix, w->nx), bx = fmaf(fx, w->ix, w->fx);
    const float ay = fmaf(ny, w->iy, w->ny), by = fmaf(fy, w->iy, w->fy);
    const float az = fmaf(nz, w->iz, w->nz), bz = fmaf(fz, w->iz, w->fz);
    const float t0 = RT_BOX_MAX(RT_BOX_MAX(ax, ay), RT_BOX_MAX(az, 0.0f));
    const float t1 = RT_BOX_MIN(RT_BOX_MIN(bx, by), RT_BOX_MIN(bz, tmax));
    return t0 <= t1 * RT_BOX_WIDEN ? (rt_float_bits(t0) & 0x7ffffffcu) | k : RT_WIDE_MISS_KEY;
}

static inline RT_HD uint32_t rt_umin(uint32_t a, uint32_t b) { return a < b ? a : b; }
static inline RT_HD uint32_t rt_umax(uint32_t a, uint32_t b) { return a > b ? a : b; }

/* The wide traversal's stack entry: sort key (rt_wide_key) in the high word,
 * reference in the low. Pops the nearest entry not beyond t (ties are
 * visited), RT_WIDE_DONE when none is left: for keys and t >= 0,
 * (key & ~3) <= bits(t) is key <= bits(t) | 3. */
static inline RT_HD uint32_t rt_wide_pop(const uint64_t *st, int *sp, float t)
{
    const uint32_t lim = rt_float_bits(t * RT_BOX_WIDEN) | 3u; /* widened as the box test */
    while (*sp > 0) {
        const uint64_t e = st[--*sp];
        if ((uint32_t)(e >> 32) <= lim)
            return (uint32_t)e;
    }
    return RT_WIDE_DONE;
}

/* One visit of inner node ref for a ray whose closest hit so far is at t:
 * the four child boxes tested, the entered ones stacked farthest first (any
 * = RT_ANY_HIT_SLOT: in slot order, without the sorting network) and the
 * nearest (the first entered) returned as the next node to visit, or the
 * pop's. */
static inline RT_HD uint32_t rt_wide_visit(const RtSceneView *s, const RtWideRay *wr, uint32_t ref, float t, int any,
                                           uint64_t *st, int *sp)
{
    float nx[4], fx[4], ny[4], fy[4], nz[4], fz[4];
    uint32_t c[4];
#if defined(__CUDA_ARCH__)
    /* The node as float4 rows lo_x, hi_x, lo_y, hi_y, lo_z, hi_z,
     * child: each axis's near row, then its far row. */
    const float4 *q = (const float4 *)s->wide;
    const uint32_t r = ref * 8u;
    float4 a;
    a = __ldg(q + (r + wr->sx)); nx[0] = a.x; nx[1] = a.y; nx[2] = a.z; nx[3] = a.w;
    a = __ldg(q + (r + 1u - wr->sx)); fx[0] = a.x; fx[1] = a.y; fx[2] = a.z; fx[3] = a.w;
    a = __ldg(q + (r + 2u + wr->sy)); ny[0] = a.x; ny[1] = a.y; ny[2] = a.z; ny[3] = a.w;
    a = __ldg(q + (r + 3u - wr->sy)); fy[0] = a.x; fy[1] = a.y; fy[2] = a.z; fy[3] = a.w;
    a = __ldg(q + (r + 4u + wr->sz)); nz[0] = a.x; nz[1] = a.y; nz[2] = a.z; nz[3] = a.w;
    a = __ldg(q + (r + 5u - wr->sz)); fz[0] = a.x; fz[1] = a.y; fz[2] = a.z; fz[3] = a.w;
    const uint4 cc = __ldg((const uint4 *)(q + (r + 6u)));
    c[0] = cc.x; c[1] = cc.y; c[2] = cc.z; c[3] = cc.w;
#else
    const RtBvh4Node *n = &s->wide[ref];
    const float *px = wr->sx ? n->hi_x : n->lo_x, *qx = wr->sx ? n->lo_x : n->hi_x;
    const float *py = wr->sy ? n->hi_y : n->lo_y, *qy = wr->sy ? n->lo_y : n->hi_y;
    const float *pz = wr->sz ? n->hi_z : n->lo_z, *qz = wr->sz ? n->lo_z : n->hi_z;
    for (int k = 0; k < 4; k++) {
        nx[k] = px[k]; fx[k] = qx[k];
        ny[k] = py[k]; fy[k] = qy[k];
        nz[k] = pz[k]; fz[k] = qz[k];
        c[k] = n->child[k];
    }
#endif
    uint32_t key[4];
#if defined(__CUDA_ARCH__)
#pragma unroll
#endif
    for (int k = 0; k < 4; k++) /* all four tested, then selected: no branch per child */
        key[k] = rt_wide_key(wr, nx[k], ny[k], nz[k], fx[k], fy[k], fz[k], t, (uint32_t)k);
    if (any == RT_ANY_HIT_SLOT) {
        /* Slot order; the first entered child next. */
#define RT_WIDE_PUSHK(k)                                                       \
    {                                                                          \
        st[*sp] = ((uint64_t)key[k] << 32) | c[k];                             \
        *sp += key[k] != RT_WIDE_MISS_KEY;                                     \
    }
        RT_WIDE_PUSHK(3) RT_WIDE_PUSHK(2) RT_WIDE_PUSHK(1)
#undef RT_WIDE_PUSHK
        return key[0] != RT_WIDE_MISS_KEY ? c[0] : rt_wide_pop(st, sp, t);
    }
    /* A 5-exchange sorting network, nearest first. */
#define RT_WIDE_CX(i, j)                                                       \
    {                                                                          \
        const uint32_t lo_ = rt_umin(key[i], key[j]);                          \
        key[j] = rt_umax(key[i], key[j]);                                      \
        key[i] = lo_;                                                          \
    }
    RT_WIDE_CX(0, 1) RT_WIDE_CX(2, 3) RT_WIDE_CX(0, 2) RT_WIDE_CX(1, 3) RT_WIDE_CX(1, 2)
#undef RT_WIDE_CX
#define RT_WIDE_CHILD(kk) (((kk) & 2u) ? (((kk) & 1u) ? c[3] : c[2]) : (((kk) & 1u) ? c[1] : c[0]))
    /* Pushes without branches: every entry is written, and the top moves
     * past it only if it is a hit (the stack has a spare slot). */
#define RT_WIDE_PUSH(kk)                                                       \
    {                                                                          \
        st[*sp] = ((uint64_t)(kk) << 32) | RT_WIDE_CHILD(kk);                  \
        *sp += (kk) != RT_WIDE_MISS_KEY;                                       \
    }
    RT_WIDE_PUSH(key[3]) RT_WIDE_PUSH(key[2]) RT_WIDE_PUSH(key[1])
#undef RT_WIDE_PUSH
    return key[0] != RT_WIDE_MISS_KEY ? RT_WIDE_CHILD(key[0]) : rt_wide_pop(st, sp, t);
#undef RT_WIDE_CHILD
}

static inline RT_HD int rt_trace_ray_wide(const RtSceneView *s, RtVec3 o, RtVec3 d, float tmax, int any, RtHit *hit,
                                          RtCounters *cnt)
{
    hit->t = tmax;
    hit->u = hit->v = 0.0f;
    hit->id = 0xffffffffu;
    int found = 0;
    const RtWideRay wr = rt_wide_ray(o, d);
    uint64_t st[RT_WIDE_STACK]; /* entries of rt_wide_pop */
    int sp = 0;
    uint32_t ref = 0;  /* the next node to visit; RT_WIDE_DONE: none */
    uint32_t leaf = 0; /* a postponed leaf; 0: none (a leaf reference has its top bit set) */
    uint32_t visits = 0, tests = 0;
    /* Inner nodes and leaves in two phases (Aila & Laine's while-while with
     * speculative traversal): a ray that reaches a leaf puts it aside and
     * goes on through inner nodes until every ray of its warp has a leaf
     * aside (RT_WIDE_LEAF_VOTE; on the CPU, at once), then the warp tests leaves
     * together. A warp of rays then runs each phase's code with most lanes
     * busy instead of alternating both with half of them. A leaf tested late
     * lets fewer stack entries be culled, never a hit be missed. */
    for (;;) {
        while (!(ref & RT_WIDE_LEAF)) {
            visits++;
            ref = rt_wide_visit(s, &wr, ref, hit->t, any, st, &sp);
            if ((ref & RT_WIDE_LEAF) && ref != RT_WIDE_DONE && !leaf) {
                leaf = ref;
                ref = rt_wide_pop(st, &sp, hit->t);
            }
            if (RT_WIDE_LEAF_VOTE(leaf != 0, any))
                break;
        }
        /* Here a leaf is aside or no node is left: the inner loop ends only
         * by the vote (leaf set) or at a leaf or RT_WIDE_DONE in ref, and a
         * leaf reaching ref with none aside was put aside at once. */
        while (leaf) {
            visits++;
            if (rt_leaf_hits(s, (leaf & ~RT_WIDE_LEAF) >> 3, (leaf & 7u) + 1u, o, d, any, hit, &found, &tests))
                goto done;
            leaf = 0;
            if ((ref & RT_WIDE_LEAF) && ref != RT_WIDE_DONE) {
                leaf = ref;
                ref = rt_wide_pop(st, &sp, hit->t);
            }
        }
        if (ref == RT_WIDE_DONE)
            break;
    }
done:
    cnt->node_visits += visits;
    cnt->prim_tests += tests;
    return found;
}

#endif
