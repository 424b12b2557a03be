/* cpu_entries.c - the CPU traversal's entries, one per instruction set,
 * and their table (cpu_trace.h): each a ray query and a tile and a pixel
 * renderer with the traversal of cpu_traverse.h inlined. A unit of its own:
 * beside these large always-inline instantiations, GCC stops inlining
 * rt_trace_ray's primitive tests into rt_cpu_trace (cpu_trace.c, the
 * brute-force path). */
#include "cpu_traverse.h"

/* The pixel loop (core/rt_path_tmpl.h) per instruction set, with the entry's
 * traversal inlined as its query, so a tile renders with no call per ray
 * (what that saves: docs/cpu-backends.md, "Traversal and dispatch"). */
#define RT_PATH_TRACE(s, o, d, tmax, any, hit, cnt, light) trace_wide(s, o, d, tmax, any, hit, cnt, node_c, leaf_c)
#define RT_PATH_NAME(f) f##_c
#define RT_PATH_FN CPU_INLINE
#include "core/rt_path_tmpl.h"
#if RT_SSE
#define RT_PATH_TRACE(s, o, d, tmax, any, hit, cnt, light) \
    trace_wide(s, o, d, tmax, any, hit, cnt, node_sse2, leaf_sse2)
#define RT_PATH_NAME(f) f##_simd
#define RT_PATH_FN CPU_INLINE
#include "core/rt_path_tmpl.h"
#endif

/* An entry: its query, tile and pixel, each with its traversal inlined. */
#define CPU_ENTRY(isa, target, node, leaf, path)                                                                  \
    target static int trace_##isa(const RtSceneView *s, RtVec3 o, RtVec3 d, float tmax, int any, RtHit *hit,      \
                                  RtCounters *cnt)                                                               \
    {                                                                                                            \
        return trace_wide(s, o, d, tmax, any, hit, cnt, node, leaf);                                             \
    }                                                                                                            \
    target static void tile_##isa(const RtSceneView *s, int x0, int y0, int x1, int y1, float *dst,              \
                                  size_t pitch, RtCounters *cnt)                                                 \
    {                                                                                                            \
        rt_render_tile_##path(s, x0, y0, x1, y1, dst, pitch, cnt);                                               \
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

static const RtCpuIsa table[] = {
    {"c", trace_c, always, tile_c, pixel_c},
#if RT_SSE
    {"sse2", trace_sse2, always, tile_sse2, pixel_sse2},
    {"avx2", trace_avx2, have_avx2, tile_avx2, pixel_avx2},
    {"avx512", trace_avx512, have_avx512, tile_avx512, pixel_avx512},
#endif
};

const RtCpuIsa *rt_cpu_isa_table(int *n)
{
    *n = (int)(sizeof table / sizeof table[0]);
    return table;
}
