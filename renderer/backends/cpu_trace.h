/* cpu_trace.h - the CPU backends' ray query, chosen at run time for the
 * machine's instruction set (docs/cpu-backends.md, "Traversal and dispatch").
 *
 * Each entry of the table traces one ray on the CPU's copy of the 4-wide
 * tree (rt_cpu_prepare: RtBvh4Node, its leaves' records in RtCpuLeaf4 groups):
 * "c" is the reference, plain C; the others test a node's four boxes and a
 * leaf's triangles four at a time with SIMD. Every entry finds the same hits
 * and counts the same work as "c", bit for bit (tests/unit/test_cpu_trace.c
 * checks each one this machine runs against it), so the choice changes
 * speed only: images and counters stay those of every other CPU run. */
#ifndef RT_CPU_TRACE_H
#define RT_CPU_TRACE_H

#include "rt.h"
/* The CPU's leaf vote (rt_traverse.h): one ray, no warp to wait for, so it
 * tests a leaf at once. */
#define RT_WIDE_LEAF_VOTE(has_leaf, any) (has_leaf)
#include "core/rt_traverse.h"

typedef int (*RtCpuTraceFn)(const RtSceneView *s, RtVec3 o, RtVec3 d, float tmax, int any, RtHit *hit,
                            RtCounters *cnt);

typedef struct RtCpuIsa {
    const char *name;     /* as --isa and the record's isa= say it */
    RtCpuTraceFn trace;
    int (*supported)(void);
    /* rt_render_tile and rt_render_pixel (core/rt_path_tmpl.h, shadow rays
     * RT_ANY_HIT) with this entry's traversal inlined */
    void (*tile)(const RtSceneView *s, int x0, int y0, int x1, int y1, float *dst, size_t pitch, RtCounters *cnt);
    void (*pixel)(const RtSceneView *s, int i, int j, float *rgb, RtCounters *cnt);
} RtCpuIsa;

/* Four records of a leaf, as the SIMD leaf test loads them: p0, e1 and e2
 * component by component, one lane per record, with their ids; a leaf's
 * records fill consecutive groups (rt_cpu_prepare), so one group is three
 * cache lines where the records are four and their arrays nine. */
typedef struct RtCpuLeaf4 {
    float p[9][4];        /* p0 x, y, z, e1 x, y, z, e2 x, y, z */
    uint32_t id[4];
    uint32_t first;       /* lane 0's record in prims[] (the lanes follow it) */
    uint32_t pad[7];
} RtCpuLeaf4;             /* 192 bytes */

/* The table, reference first; n receives its length. */
const RtCpuIsa *rt_cpu_isa_table(int *n);

/* One ray through the selected entry (rt_cpu_isa_select) on scenes with the
 * CPU's copy of the tree (rt_cpu_prepare); brute force, a tree too large for
 * the wide copy, and no memory for the copy, through rt_trace_ray (the same
 * hits). */
int rt_cpu_trace(const RtSceneView *s, RtVec3 o, RtVec3 d, float tmax, int any, RtHit *hit, RtCounters *cnt);

/* What every CPU backend renders with: rt_render_tile and rt_render_pixel
 * of core/rt_path_tmpl.h through the selected entry (its tile and pixel), or,
 * for scenes without the CPU's copy of the tree, through rt_cpu_trace. */
void rt_cpu_render_tile(const RtSceneView *s, int x0, int y0, int x1, int y1, float *dst, size_t pitch,
                        RtCounters *cnt);
void rt_cpu_render_pixel(const RtSceneView *s, int i, int j, float *rgb, RtCounters *cnt);

#endif
