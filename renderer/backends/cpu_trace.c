/* cpu_trace.c - the choice of the CPU traversal's entry (cpu_entries.c), at
 * run time (dav1d's checkasm pattern: a C reference and faster versions,
 * each tested against it exactly); the query and the tile and pixel
 * renderers every CPU backend calls, through it or, for scenes without the
 * CPU's copy of the tree, through rt_trace_ray; and that copy
 * (rt_cpu_prepare). */
#include <stddef.h>
#include <stdlib.h>
#include <string.h>

#include "cpu_trace.h"

/* The loop for scenes without the CPU's copy of the tree (rt_cpu_render_tile
 * and rt_cpu_render_pixel below): every ray through rt_cpu_trace. */
#define RT_PATH_TRACE(s, o, d, tmax, any, hit, cnt, light) rt_cpu_trace(s, o, d, tmax, any, hit, cnt)
#define RT_PATH_NAME(f) f##_fallback
#define RT_PATH_FN static inline
#include "core/rt_path_tmpl.h"

/* ---- the CPU's copy of the tree ---------------------------------------- */

/* The groups of four records that node n's leaves take. */
static uint32_t node_groups(const RtBvh4Node *n)
{
    uint32_t groups = 0;
    for (uint32_t k = 0; k < n->count; k++)
        if (n->child[k] & RT_WIDE_LEAF)
            groups += ((n->child[k] & 7u) + 4u) / 4u;
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

/* Node i's leaves into the groups from first[i] on: counted, summed, then
 * packed, each node on its own, in parallel (a large scene's copy is
 * hundreds of MB); the same bytes on any number of threads. Returns the
 * groups in all, or RT_WIDE_MAX_FIRST when there are too many. */
static size_t group_offsets(const RtBvh4Node *w, uint32_t n, uint32_t *first)
{
#pragma omp parallel for schedule(static) num_threads(rt_stream_threads())
    for (uint32_t i = 0; i < n; i++)
        first[i + 1] = node_groups(&w[i]);
    size_t sum = 0;
    first[0] = 0;
    for (uint32_t i = 0; i < n; i++) {
        sum += first[i + 1];
        if (sum >= RT_WIDE_MAX_FIRST)
            return RT_WIDE_MAX_FIRST;
        first[i + 1] = (uint32_t)sum;
    }
    return sum;
}

void *rt_cpu_prepare(RtSceneView *v)
{
    v->cpu_wide = NULL;
    v->cpu_leaves = NULL;
    v->ncpu_leaves = 0;
    if (!v->wide || v->nnodes == 0)
        return NULL;
    const uint32_t nw = v->nwide;
    uint32_t *first = malloc(((size_t)nw + 1) * sizeof *first);
    const size_t groups = first ? group_offsets(v->wide, nw, first) : RT_WIDE_MAX_FIRST;
    const size_t nodes = ((size_t)nw * sizeof(RtBvh4Node) + 63) & ~(size_t)63;
    char *block = groups < RT_WIDE_MAX_FIRST ? aligned_alloc(64, nodes + groups * sizeof(RtCpuLeaf4)) : NULL;
    if (!block) {
        free(first);
        return NULL;
    }
    RtBvh4Node *w = (RtBvh4Node *)(void *)block;
    RtCpuLeaf4 *leaves = (RtCpuLeaf4 *)(void *)(block + nodes);
#pragma omp parallel for schedule(static) num_threads(rt_stream_threads())
    for (uint32_t i = 0; i < nw; i++) {
        w[i] = v->wide[i];
        /* (lanes past a leaf: zero triangles, which miss) */
        memset(&leaves[first[i]], 0, (size_t)(first[i + 1] - first[i]) * sizeof *leaves);
        uint32_t g = first[i];
        for (uint32_t k = 0; k < w[i].count; k++)
            if (w[i].child[k] & RT_WIDE_LEAF)
                g += pack_leaf(v, &w[i].child[k], leaves, g);
    }
    free(first);
    v->cpu_wide = w;
    v->cpu_leaves = leaves;
    v->ncpu_leaves = (uint32_t)groups;
    return block;
}

/* ---- the choice -------------------------------------------------------- */

/* The entry in use: found in a local and published with one atomic store,
 * so a thread that reads it (rt_cpu_current) sees NULL or a whole entry. */
static const RtCpuIsa *selected;

int rt_cpu_isa_select(const char *name, RtError *err)
{
    int n;
    const RtCpuIsa *table = rt_cpu_isa_table(&n), *pick = NULL;
    for (int i = n - 1; i >= 0 && !pick; i--) /* the last supported: the fastest */
        if (name ? strcmp(name, table[i].name) == 0 : table[i].supported())
            pick = &table[i];
    if (!pick && name)
        return rt_fail(err, "--isa: unknown instruction set '%s' (c, sse2, avx2, avx512 on x86-64)", name);
    if (!pick->supported())
        return rt_fail(err, "--isa: this CPU cannot run %s", name);
    __atomic_store_n(&selected, pick, __ATOMIC_RELEASE);
    return 0;
}

/* The selected entry, the best this CPU runs when none was chosen. */
static const RtCpuIsa *rt_cpu_current(void)
{
    const RtCpuIsa *e = __atomic_load_n(&selected, __ATOMIC_ACQUIRE);
    if (!e) {
        rt_cpu_isa_select(NULL, NULL); /* (entry 0, "c", is always supported) */
        e = __atomic_load_n(&selected, __ATOMIC_ACQUIRE);
    }
    return e;
}

const char *rt_cpu_isa_name(void) { return rt_cpu_current()->name; }

int rt_cpu_trace(const RtSceneView *s, RtVec3 o, RtVec3 d, float tmax, int any, RtHit *hit, RtCounters *cnt)
{
    if (!s->cpu_wide)
        return rt_trace_ray(s, o, d, tmax, any, hit, cnt);
    return rt_cpu_current()->trace(s, o, d, tmax, any, hit, cnt);
}

void rt_cpu_render_tile(const RtSceneView *s, int x0, int y0, int x1, int y1, float *dst, size_t pitch,
                        RtCounters *cnt)
{
    if (!s->cpu_wide) {
        rt_render_tile_fallback(s, x0, y0, x1, y1, dst, pitch, cnt);
        return;
    }
    rt_cpu_current()->tile(s, x0, y0, x1, y1, dst, pitch, cnt);
}

void rt_cpu_render_pixel(const RtSceneView *s, int i, int j, float *rgb, RtCounters *cnt)
{
    if (!s->cpu_wide) {
        rt_render_pixel_fallback(s, i, j, RT_ANY_HIT, rgb, cnt);
        return;
    }
    rt_cpu_current()->pixel(s, i, j, rgb, cnt);
}
