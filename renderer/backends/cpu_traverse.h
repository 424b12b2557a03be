/* cpu_traverse.h - the CPU traversal itself: the 4-wide tree walked with
 * its node and leaf tests in several instruction sets, each an always-inline
 * function, so that cpu_entries.c's entries (one per instruction set: a ray
 * query and a tile and a pixel renderer) compile the whole query into their
 * own code. Only cpu_entries.c includes it.
 *
 * The traversal (Wald et al. 2008, "Getting rid of packets", and Dammertz
 * et al. 2008, "Shallow bounding volume hierarchies"): one visit tests a
 * node's four child boxes with the binary traversal's slab test
 * (rt_slab_enter: the same operations in the same order, so each child is
 * entered exactly when the binary traversal would enter it), goes on with
 * the nearest and stacks the others with their entry distances, farthest
 * first (ties in slot order). A leaf's primitives are tested in order and
 * taken as rt_leaf_take takes them, so the closest hit, its ties to the
 * lower index and the shadow rays' answers are those of rt_trace_ray. The
 * SIMD versions compute every lane with the IEEE operations of the scalar
 * code, in its order (no fused multiply-add: -ffp-contract=off), so their
 * numbers, and with them the traversal's path and counters, are the
 * reference's. */
#ifndef RT_CPU_TRAVERSE_H
#define RT_CPU_TRAVERSE_H

#include <math.h>
#include <stddef.h>
#include <string.h>

#include "cpu_trace.h"

#define CPU_STACK (3 * RT_BVH_MAX_DEPTH + 4)
/* The traversal is one function body for every instruction set: inlined
 * into each entry with that entry's node and leaf tests, so no call through
 * a pointer is left inside the loop. */
#define CPU_INLINE static inline __attribute__((always_inline))

/* A ray's constants for the node tests: the slab test's, and for the SIMD
 * test each broadcast to four lanes and, per axis, the byte offset in the
 * node of the bounds the ray meets first (lo for a positive direction, hi
 * for a negative one; the far bounds are at offset ^ 16). As 1/d is finite
 * and nonzero (rt_safe_inv), the near bound's distance is exactly the slab
 * test's min of the two and the far one's its max, so selecting them by
 * sign saves the six min/max without changing a value (Williams et al.
 * 2005, "An efficient and robust ray-box intersection algorithm"). */
typedef struct CpuRay {
    RtRayBox rb;
    uint32_t near[3];
#if RT_SSE
    __m128 o[3], inv[3];
#endif
} CpuRay;

_Static_assert(offsetof(RtBvh4Node, hi_x) == offsetof(RtBvh4Node, lo_x) + 16 &&
                   offsetof(RtBvh4Node, hi_y) == offsetof(RtBvh4Node, lo_y) + 16 &&
                   offsetof(RtBvh4Node, hi_z) == offsetof(RtBvh4Node, lo_z) + 16 && offsetof(RtBvh4Node, lo_x) == 0 &&
                   offsetof(RtBvh4Node, lo_y) == 32 && offsetof(RtBvh4Node, lo_z) == 64,
               "the near/far offsets (CpuRay) assume each axis's lo then hi, 16 bytes apart");

CPU_INLINE void cpu_ray(CpuRay *r, RtVec3 o, RtVec3 d)
{
    r->rb = rt_raybox(o, d);
    /* (rt_safe_inv keeps the sign of d, a -0 made +tiny) */
    r->near[0] = d.x < 0.0f ? offsetof(RtBvh4Node, hi_x) : offsetof(RtBvh4Node, lo_x);
    r->near[1] = d.y < 0.0f ? offsetof(RtBvh4Node, hi_y) : offsetof(RtBvh4Node, lo_y);
    r->near[2] = d.z < 0.0f ? offsetof(RtBvh4Node, hi_z) : offsetof(RtBvh4Node, lo_z);
#if RT_SSE
    /* rt_safe_inv of the three at once, without its branches: one
     * division instead of three, the same IEEE quotients */
    const __m128 dv = _mm_set_ps(1.0f, d.z, d.y, d.x), tiny = _mm_set1_ps(1e-20f);
    const __m128 small = _mm_and_ps(_mm_cmpgt_ps(dv, _mm_sub_ps(_mm_setzero_ps(), tiny)), _mm_cmplt_ps(dv, tiny));
    const __m128 nudged = _mm_or_ps(_mm_and_ps(_mm_cmplt_ps(dv, _mm_setzero_ps()), _mm_set1_ps(-1e-20f)),
                                    _mm_andnot_ps(_mm_cmplt_ps(dv, _mm_setzero_ps()), tiny));
    const __m128 inv = _mm_div_ps(_mm_set1_ps(1.0f), _mm_or_ps(_mm_and_ps(small, nudged), _mm_andnot_ps(small, dv)));
    r->o[0] = _mm_set1_ps(o.x), r->o[1] = _mm_set1_ps(o.y), r->o[2] = _mm_set1_ps(o.z);
    r->inv[0] = _mm_shuffle_ps(inv, inv, _MM_SHUFFLE(0, 0, 0, 0));
    r->inv[1] = _mm_shuffle_ps(inv, inv, _MM_SHUFFLE(1, 1, 1, 1));
    r->inv[2] = _mm_shuffle_ps(inv, inv, _MM_SHUFFLE(2, 2, 2, 2));
#endif
}

/* The entered children of node n (bit k: child k) and their entry
 * distances t[k], against the closest hit so far tmax. */
typedef int (*NodeFn)(const RtBvh4Node *n, const CpuRay *r, float tmax, float t[4]);
/* A leaf: its `count` records, from its first group of four in
 * s->cpu_leaves; rt_leaf_hits' contract. */
typedef int (*LeafFn)(const RtSceneView *s, uint32_t group, uint32_t count, RtVec3 o, RtVec3 d, int any,
                      RtHit *hit, int *found, uint32_t *tests);

/* ---- the C reference -------------------------------------------------- */

CPU_INLINE int node_c(const RtBvh4Node *n, const CpuRay *r, float tmax, float t[4])
{
    const RtRayBox *rb = &r->rb;
    int mask = 0;
    for (uint32_t k = 0; k < n->count; k++) {
        t[k] = rt_slab_enter(n->lo_x[k], n->lo_y[k], n->lo_z[k], n->hi_x[k], n->hi_y[k], n->hi_z[k], rb, 0.0f,
                             tmax);
        mask |= (t[k] != RT_INF) << k;
    }
    return mask;
}

/* rt_leaf_hits' contract, one record at a time and always inlined into
 * the traversal (the reference's leaf test, and the SIMD one's without its
 * copy of the records): rt_leaf_hits is only static inline, and the
 * compiler may leave it a call in every leaf the SIMD traversal visits. */
CPU_INLINE int leaf_c(const RtSceneView *s, uint32_t group, uint32_t count, RtVec3 o, RtVec3 d, int any, RtHit *hit,
                  int *found, uint32_t *tests)
{
    const uint32_t first = s->cpu_leaves[group].first;
    for (uint32_t k = 0; k < count; k++) {
        const RtPrim *p = &s->prims[first + k];
        float u, v;
        const float t = rt_prim_intersect(p, o, d, &u, &v);
        if (rt_leaf_take(p, t, u, v, any, hit, found, tests))
            return 1;
    }
    return 0;
}

/* ---- the traversal, shared ------------------------------------------- */

/* Stacks the entered children of n (mask) but the nearest, farthest first,
 * and returns the nearest; ties keep slot order. */
CPU_INLINE uint32_t order_children(const RtBvh4Node *n, int mask, const float t[4], uint32_t *sn, float *st,
                                   int *sp)
{
    int ks[4], m = 0;
    for (int k = 0; k < 4; k++)
        if (mask >> k & 1) {
            int i = m++;
            for (; i > 0 && t[ks[i - 1]] > t[k]; i--)
                ks[i] = ks[i - 1];
            ks[i] = k;
        }
    for (int i = m - 1; i > 0; i--) {
        sn[*sp] = n->child[ks[i]];
        st[*sp] = t[ks[i]];
        (*sp)++;
    }
    return n->child[ks[0]];
}

CPU_INLINE int trace_wide(const RtSceneView *s, RtVec3 o, RtVec3 d, float tmax, int any, RtHit *hit,
                             RtCounters *cnt, NodeFn node, LeafFn leaf)
{
    hit->t = tmax;
    hit->u = hit->v = 0.0f;
    hit->id = 0xffffffffu;
    CpuRay ray;
    cpu_ray(&ray, o, d);
    uint32_t sn[CPU_STACK], ref = 0, visits = 0, tests = 0;
    float st[CPU_STACK];
    int sp = 0, found = 0;
    for (;;) {
        visits++;
        if (ref & RT_WIDE_LEAF) {
            if (leaf(s, (ref & ~RT_WIDE_LEAF) >> 3, (ref & 7u) + 1u, o, d, any, hit, &found, &tests))
                break;
        } else {
            const RtBvh4Node *n = &s->cpu_wide[ref];
            float t[4];
            const int mask = node(n, &ray, hit->t, t);
            if (mask) {
                ref = order_children(n, mask, t, sn, st, &sp);
                continue;
            }
        }
        /* Pop, skipping what is entered beyond the closest hit (widened, as
         * the binary traversal: ties are still visited). */
        while (sp > 0 && !(st[sp - 1] <= hit->t * RT_BOX_WIDEN))
            sp--;
        if (sp == 0)
            break;
        ref = sn[--sp];
    }
    cnt->node_visits += visits;
    cnt->prim_tests += tests;
    return found;
}

/* ---- SSE2 (every x86-64) --------------------------------------------- */
#if RT_SSE
CPU_INLINE int node_sse2(const RtBvh4Node *n, const CpuRay *r, float tmax, float t[4])
{
    const char *b = (const char *)n;
#define SLAB(a, off) _mm_mul_ps(_mm_sub_ps(_mm_loadu_ps((const float *)(const void *)(b + (off))), r->o[a]), r->inv[a])
    const __m128 x0 = SLAB(0, r->near[0]), x1 = SLAB(0, r->near[0] ^ 16u);
    const __m128 y0 = SLAB(1, r->near[1]), y1 = SLAB(1, r->near[1] ^ 16u);
    const __m128 z0 = SLAB(2, r->near[2]), z1 = SLAB(2, r->near[2] ^ 16u);
#undef SLAB
    /* rt_slab_enter's expressions with its inner min/max already taken
     * (CpuRay); _mm_max_ps(a, b) is a > b ? a : b, as rt_maxf */
    const __m128 t0 = _mm_max_ps(_mm_max_ps(x0, y0), _mm_max_ps(z0, _mm_setzero_ps()));
    const __m128 t1 = _mm_min_ps(_mm_min_ps(x1, y1), _mm_min_ps(z1, _mm_set1_ps(tmax)));
    _mm_storeu_ps(t, t0);
    const int in = _mm_movemask_ps(_mm_cmple_ps(t0, _mm_mul_ps(t1, _mm_set1_ps(RT_BOX_WIDEN))));
    return in & ((1 << n->count) - 1); /* (an empty slot's inside-out box is no child) */
}

/* rt_prim_intersect of a group's four records: t (RT_INF on a miss), u, v. */
CPU_INLINE void tri4_sse2(const RtCpuLeaf4 *g, RtVec3 o, RtVec3 d, float *t, float *u, float *v)
{
    __m128 f[9];
    for (int k = 0; k < 9; k++)
        f[k] = _mm_load_ps(g->p[k]);
    const __m128 *p0 = f, *e1 = f + 3, *e2 = f + 6;
    const __m128 dx = _mm_set1_ps(d.x), dy = _mm_set1_ps(d.y), dz = _mm_set1_ps(d.z);
    const __m128 pvx = _mm_sub_ps(_mm_mul_ps(dy, e2[2]), _mm_mul_ps(dz, e2[1]));
    const __m128 pvy = _mm_sub_ps(_mm_mul_ps(dz, e2[0]), _mm_mul_ps(dx, e2[2]));
    const __m128 pvz = _mm_sub_ps(_mm_mul_ps(dx, e2[1]), _mm_mul_ps(dy, e2[0]));
#define DOT(ax, ay, az, bx, by, bz) _mm_add_ps(_mm_add_ps(_mm_mul_ps(ax, bx), _mm_mul_ps(ay, by)), _mm_mul_ps(az, bz))
    const __m128 det = DOT(e1[0], e1[1], e1[2], pvx, pvy, pvz);
    const __m128 inv = _mm_div_ps(_mm_set1_ps(1.0f), det);
    const __m128 tx = _mm_sub_ps(_mm_set1_ps(o.x), p0[0]);
    const __m128 ty = _mm_sub_ps(_mm_set1_ps(o.y), p0[1]);
    const __m128 tz = _mm_sub_ps(_mm_set1_ps(o.z), p0[2]);
    const __m128 uu = _mm_mul_ps(DOT(tx, ty, tz, pvx, pvy, pvz), inv);
    const __m128 qx = _mm_sub_ps(_mm_mul_ps(ty, e1[2]), _mm_mul_ps(tz, e1[1]));
    const __m128 qy = _mm_sub_ps(_mm_mul_ps(tz, e1[0]), _mm_mul_ps(tx, e1[2]));
    const __m128 qz = _mm_sub_ps(_mm_mul_ps(tx, e1[1]), _mm_mul_ps(ty, e1[0]));
    const __m128 vv = _mm_mul_ps(DOT(dx, dy, dz, qx, qy, qz), inv);
    const __m128 tt = _mm_mul_ps(DOT(e2[0], e2[1], e2[2], qx, qy, qz), inv);
#undef DOT
    const __m128 zero = _mm_setzero_ps(), one = _mm_set1_ps(1.0f);
    __m128 ok = _mm_and_ps(_mm_cmpneq_ps(det, zero), _mm_cmpnlt_ps(uu, zero));
    ok = _mm_and_ps(ok, _mm_and_ps(_mm_cmpngt_ps(uu, one), _mm_cmpnlt_ps(vv, zero)));
    ok = _mm_and_ps(ok, _mm_and_ps(_mm_cmpngt_ps(_mm_add_ps(uu, vv), one), _mm_cmpgt_ps(tt, _mm_set1_ps(RT_T_MIN))));
    _mm_storeu_ps(t, _mm_or_ps(_mm_and_ps(ok, tt), _mm_andnot_ps(ok, _mm_set1_ps(RT_INF))));
    _mm_storeu_ps(u, uu);
    _mm_storeu_ps(v, vv);
}

/* A leaf four records at a time from its groups (a group with a sphere
 * one at a time); the results taken in order, as leaf_c takes them. A lane
 * that missed (t = RT_INF) only counts a test in rt_leaf_take, so only the
 * lanes that hit are taken: the records themselves are read only for hits.
 * (A short group's lanes past the leaf are zero triangles, ignored.) */
CPU_INLINE int leaf_sse2(const RtSceneView *s, uint32_t group, uint32_t count, RtVec3 o, RtVec3 d, int any,
                         RtHit *hit, int *found, uint32_t *tests)
{
    const __m128i sphere_bit = _mm_set1_epi32((int)RT_PRIM_SPHERE_BIT);
    for (uint32_t k = 0; k < count; k += 4) {
        const RtCpuLeaf4 *g = &s->cpu_leaves[group + k / 4];
        const uint32_t m = count - k < 4 ? count - k : 4, lanes = (1u << m) - 1u;
        const RtPrim *p = &s->prims[g->first];
        const __m128i ids = _mm_load_si128((const __m128i *)(const void *)g->id);
        const __m128i sph = _mm_cmpeq_epi32(_mm_and_si128(ids, sphere_bit), sphere_bit);
        float t[4], u[4], v[4];
        if ((uint32_t)_mm_movemask_ps(_mm_castsi128_ps(sph)) & lanes) {
            for (uint32_t i = 0; i < m; i++) {
                const float ti = rt_prim_intersect(&p[i], o, d, &u[i], &v[i]);
                if (rt_leaf_take(&p[i], ti, u[i], v[i], any, hit, found, tests))
                    return 1;
            }
            continue;
        }
        tri4_sse2(g, o, d, t, u, v);
        uint32_t hits = (uint32_t)_mm_movemask_ps(_mm_cmplt_ps(_mm_loadu_ps(t), _mm_set1_ps(RT_INF))) & lanes;
        for (uint32_t scratch = 0; hits; hits &= hits - 1) {
            const uint32_t i = (uint32_t)__builtin_ctz(hits);
            if (rt_leaf_take(&p[i], t[i], u[i], v[i], any, hit, found, &scratch)) {
                *tests += i + 1; /* (the lanes before it, as leaf_c counts them) */
                return 1;
            }
        }
        *tests += m;
    }
    return 0;
}
#endif /* RT_SSE */

#endif
