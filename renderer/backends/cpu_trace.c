/* cpu_trace.c - the CPU ray query's entries, one per instruction set,
 * picked at run time (dav1d's checkasm pattern: a C reference and faster
 * versions, each tested against it exactly); the traversal they compile is
 * cpu_traverse.h's. Also the CPU's copy of the tree (rt_cpu_prepare). */
#include <stddef.h>
#include <stdlib.h>
#include <string.h>

#include "cpu_traverse.h"

/* The whole pixel loop per instruction set: rt_shade_path.h instantiated
 * with the entry's traversal inlined as its query, so a tile renders with
 * no call per ray (3-7% of a course mesh's render on the 2-core VM, against
 * calling the entry per ray). The default instantiation (rt_shade.h, through
 * rt_cpu_trace) serves the scenes without the CPU's copy of the tree. */
#include "core/rt_shade.h"
#undef RT_PATH_TRACE
#define RT_PATH_FN CPU_INLINE
#define RT_PATH_TRACE(s, o, d, tmax, any, hit, cnt, light) trace_wide(s, o, d, tmax, any, hit, cnt, node_c, leaf_c)
#define RT_PATH_NAME(f) f##_c
#include "core/rt_shade_path.h"
#undef RT_PATH_TRACE
#undef RT_PATH_NAME
#if RT_SSE
#define RT_PATH_TRACE(s, o, d, tmax, any, hit, cnt, light) \
    trace_wide(s, o, d, tmax, any, hit, cnt, node_sse2, leaf_sse2)
#define RT_PATH_NAME(f) f##_simd
#include "core/rt_shade_path.h"
#undef RT_PATH_TRACE
#undef RT_PATH_NAME
#endif
#undef RT_PATH_FN

/* An entry: its query, tile and pixel, each with its traversal inlined. */
#define CPU_ENTRY(isa, target, node, leaf, path)                                                                  \
    target static int trace_##isa(const RtSceneView *s, RtVec3 o, RtVec3 d, float tmax, int any, RtHit *hit,      \
                                  RtCounters *cnt)                                                               \
    {                                                                                                            \
        return trace_wide(s, o, d, tmax, any, hit, cnt, node, leaf);                                             \
    }                                                                                                            \
    target static void tile_##isa(const RtSceneView *s, int x0, int y0, int x1, int y1, float *rgb,              \
                                  RtCounters *cnt)                                                               \
    {                                                                                                            \
        rt_render_tile_##path(s, x0, y0, x1, y1, rgb, cnt);                                                      \
    }                                                                                                            \
    target static void pixel_##isa(const RtSceneView *s, int i, int j, float *rgb, RtCounters *cnt)              \
    {                                                                                                            \
        rt_render_pixel_##path(s, i, j, RT_ANY_HIT, rgb, cnt);                                                   \
    }

CPU_ENTRY(c, , node_c, leaf_c, c)

static int always(void) { return 1; }

#if RT_SSE
CPU_ENTRY(sse2, , node_sse2, leaf_sse2, simd)

/* The same code with AVX2's encoding (three-operand VEX forms, fewer moves);
 * the same operations, so the same numbers. */
CPU_ENTRY(avx2, __attribute__((target("avx2"))), node_sse2, leaf_sse2, simd)

static int have_avx2(void)
{
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx2");
}

/* Again with AVX-512VL's encoding: still four-lane operations, so the same
 * numbers, but 32 vector registers instead of 16, so the ray, the node's
 * bounds and a leaf's edges stay in registers instead of on the stack. */
CPU_ENTRY(avx512, __attribute__((target("avx2,avx512f,avx512vl"))), node_sse2, leaf_sse2, simd)

static int have_avx512(void)
{
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("avx512f") &&
           __builtin_cpu_supports("avx512vl");
}
#endif

/* ---- the CPU's copy of the tree ---------------------------------------- */

/* The records of each leaf of the tree, in groups of four. */
static size_t leaf_groups(const RtBvh4Node *w, uint32_t n)
{
    size_t groups = 0;
    for (uint32_t i = 0; i < n; i++)
        for (uint32_t k = 0; k < w[i].count; k++)
            if (w[i].child[k] & RT_WIDE_LEAF)
                groups += ((w[i].child[k] & 7u) + 4u) / 4u;
    return groups;
}

/* Leaf ref (first record, count) of node slot *ref: its records into
 * groups from g on, and the ref made (group g, count). Returns the groups used. */
static uint32_t pack_leaf(const RtSceneView *v, uint32_t *ref, RtCpuLeaf4 *leaves, uint32_t g)
{
    const uint32_t first = (*ref & ~RT_WIDE_LEAF) >> 3, count = (*ref & 7u) + 1u;
    for (uint32_t j = 0; j < count; j++) {
        RtCpuLeaf4 *l = &leaves[g + j / 4];
        const RtPrim *p = &v->prims[first + j];
        const uint32_t lane = j % 4;
        for (int a = 0; a < 3; a++) {
            l->p[a][lane] = p->p0[a];
            l->p[3 + a][lane] = p->e1[a];
            l->p[6 + a][lane] = p->e2[a];
        }
        l->id[lane] = p->id;
        if (lane == 0)
            l->first = first + j;
    }
    *ref = RT_WIDE_LEAF | g << 3 | (count - 1u);
    return (count + 3u) / 4u;
}

void *rt_cpu_prepare(RtSceneView *v)
{
    v->cpu_wide = NULL;
    v->cpu_leaves = NULL;
    if (!v->wide || v->nnodes == 0)
        return NULL;
    const size_t groups = leaf_groups(v->wide, v->nwide);
    const size_t nodes = ((size_t)v->nwide * sizeof(RtBvh4Node) + 63) & ~(size_t)63;
    if (groups >= RT_WIDE_MAX_FIRST)
        return NULL;
    char *block = aligned_alloc(64, nodes + groups * sizeof(RtCpuLeaf4));
    if (!block)
        return NULL;
    RtBvh4Node *w = (RtBvh4Node *)(void *)block;
    RtCpuLeaf4 *leaves = (RtCpuLeaf4 *)(void *)(block + nodes);
    memcpy(w, v->wide, (size_t)v->nwide * sizeof *w);
    memset(leaves, 0, groups * sizeof *leaves); /* (lanes past a leaf: zero triangles, which miss) */
    uint32_t g = 0;
    for (uint32_t i = 0; i < v->nwide; i++)
        for (uint32_t k = 0; k < w[i].count; k++)
            if (w[i].child[k] & RT_WIDE_LEAF)
                g += pack_leaf(v, &w[i].child[k], leaves, g);
    v->cpu_wide = w;
    v->cpu_leaves = leaves;
    return block;
}

/* ---- the table and the choice ----------------------------------------- */

static const RtCpuIsa table[] = {
    {"c", trace_c, always, tile_c, pixel_c},
#if RT_SSE
    {"sse2", trace_sse2, always, tile_sse2, pixel_sse2},
    {"avx2", trace_avx2, have_avx2, tile_avx2, pixel_avx2},
    {"avx512", trace_avx512, have_avx512, tile_avx512, pixel_avx512},
#endif
};

static const RtCpuIsa *selected;

const RtCpuIsa *rt_cpu_isa_table(int *n)
{
    *n = (int)(sizeof table / sizeof table[0]);
    return table;
}

int rt_cpu_isa_select(const char *name, RtError *err)
{
    const int n = (int)(sizeof table / sizeof table[0]);
    selected = NULL;
    for (int i = n - 1; i >= 0 && !selected; i--) /* the last supported: the fastest */
        if (name ? strcmp(name, table[i].name) == 0 : table[i].supported())
            selected = &table[i];
    if (!selected && name)
        return rt_fail(err, "--isa: unknown instruction set '%s' (c, sse2, avx2, avx512 on x86-64)", name);
    if (!selected->supported()) {
        rt_fail(err, "--isa: this CPU cannot run %s", name);
        selected = NULL;
        return -1;
    }
    return 0;
}

const char *rt_cpu_isa_name(void)
{
    if (!selected)
        rt_cpu_isa_select(NULL, NULL);
    return selected->name;
}

int rt_cpu_trace(const RtSceneView *s, RtVec3 o, RtVec3 d, float tmax, int any, RtHit *hit, RtCounters *cnt)
{
    if (!s->cpu_wide)
        return rt_trace_ray(s, o, d, tmax, any, hit, cnt);
    if (!selected)
        rt_cpu_isa_select(NULL, NULL);
    return selected->trace(s, o, d, tmax, any, hit, cnt);
}

void rt_cpu_render_tile(const RtSceneView *s, int x0, int y0, int x1, int y1, float *rgb, RtCounters *cnt)
{
    if (!s->cpu_wide) {
        rt_render_tile(s, x0, y0, x1, y1, rgb, cnt);
        return;
    }
    if (!selected)
        rt_cpu_isa_select(NULL, NULL);
    selected->tile(s, x0, y0, x1, y1, rgb, cnt);
}

void rt_cpu_render_pixel(const RtSceneView *s, int i, int j, float *rgb, RtCounters *cnt)
{
    if (!s->cpu_wide) {
        rt_render_pixel(s, i, j, RT_ANY_HIT, rgb, cnt);
        return;
    }
    if (!selected)
        rt_cpu_isa_select(NULL, NULL);
    selected->pixel(s, i, j, rgb, cnt);
}
