/* rt_path_tmpl.h - the pixel and tile loop (rt_trace_path, rt_render_pixel,
 * rt_render_tile), written once for every ray query. A template, as dav1d's
 * *_tmpl.c: each unit that shades instantiates it by defining
 *   RT_PATH_TRACE(s, o, d, tmax, any, hit, cnt, light)  the ray query, with
 *                    rt_trace_ray's contract; light is -1 for a closest-hit
 *                    ray, else the light of the shadow ray (for tools that
 *                    study the rays);
 *   RT_PATH_NAME(f)  the name function f gets in this instantiation;
 *   RT_PATH_FN       how the functions are declared;
 * and then including this file, which takes the three away again, so one
 * unit may instantiate it twice. The instantiations: backends/cpu_entries.c
 * (one per instruction set, the traversal inlined so that a tile renders
 * without a call per ray), backends/cpu_trace.c (scenes without the CPU's
 * copy of the tree), backends/cuda/kernels.cuh (the GPU), and tests and
 * tools with queries of their own. No include guard: each inclusion is one
 * instantiation. */
#if !defined(RT_PATH_TRACE) || !defined(RT_PATH_NAME) || !defined(RT_PATH_FN)
#error "rt_path_tmpl.h: define RT_PATH_TRACE, RT_PATH_NAME and RT_PATH_FN, then include it"
#endif

#include "rt_shade.h"

/* The colour of one primary ray, unclamped: trace() of RENDERING-RULES with
 * the recursion unrolled into the pending-ray stack. Each popped ray is traced
 * for its closest hit; the hit's shadow rays are traced in the inner loop over
 * the lights, as shadow_any queries (RT_ANY_HIT or RT_ANY_HIT_SLOT). The
 * colour is summed exactly as trace(): ambient, then each light in order,
 * then weight * local into the pixel.
 *
 * The closest-hit and any-hit queries are two call sites, not one loop
 * serving every ray kind: on the GPU each keeps its own, smaller, traversal
 * code (docs/gpu.md, "Design and defaults"). */
RT_PATH_FN RtVec3 RT_PATH_NAME(rt_trace_path)(const RtSceneView *s, RtRay primary, int shadow_any, RtCounters *cnt)
{
    RtPending stack[RT_RAY_STACK];
    RtVec3 color = rt_v3(0.0f, 0.0f, 0.0f);
    int sp = rt_path_begin(s, primary, stack);
    while (sp > 0) {
        RtPending r = rt_path_pop(s, stack, &sp, cnt);
        RtHit h;
        if (!RT_PATH_TRACE(s, r.o, r.d, RT_INF, 0, &h, cnt, -1)) {
            color = rt_add(color, rt_mul(r.w, s->background));
            continue;
        }
        RtSurface sf = rt_surface(s, r.o, r.d, &h);
        const RtMaterial *m = &s->materials[sf.material];
        RtVec3 view = rt_neg(r.d);
        RtVec3 so = rt_shadow_origin(&sf);
        RtVec3 local = rt_ambient_term(s, m);
        for (uint32_t li = 0; li < s->nlights; li++) {
            RtVec3 c, L;
            float dist;
            if (!rt_light_sample(s, &sf, m, view, li, &c, &L, &dist))
                continue;
            RtHit sh;
            cnt->shadow_rays++;
            if (!RT_PATH_TRACE(s, so, L, dist, shadow_any, &sh, cnt, (int)li))
                local = rt_add(local, c);
        }
        color = rt_add(color, rt_mul(r.w, local));
        if (r.depth > 1)
            rt_push_children(stack, &sp, &r, &sf, m);
    }
    return color;
}

/* The colour of pixel (i, j); shadow_any is the shadow rays' query,
 * RT_ANY_HIT or RT_ANY_HIT_SLOT (rt_traverse.h): the same image either way. */
RT_PATH_FN RtVec3 RT_PATH_NAME(rt_shade_pixel)(const RtSceneView *s, int i, int j, int shadow_any, RtCounters *cnt)
{
    RtVec3 c = RT_PATH_NAME(rt_trace_path)(s, rt_camera_ray(&s->cam, i, j), shadow_any, cnt);
#ifdef RT_PLANT_EVERY
    /* -Dexperiments=true -Dplant_every=N -Dplant_times=K: every Nth pixel
     * traced K more times, a known slowdown for measuring the harness's
     * verdicts; the extra traces count into a scratch copy, so image and
     * counters stay the same */
    if (((size_t)j * (size_t)s->cam.width + (size_t)i) % RT_PLANT_EVERY == 0)
        for (int k = 0; k < RT_PLANT_TIMES; k++) {
            RtCounters scratch = *cnt;
            volatile float sink = RT_PATH_NAME(rt_trace_path)(s, rt_camera_ray(&s->cam, i, j), shadow_any, &scratch).x;
            (void)sink;
        }
#endif
    return c;
}

/* Renders pixel (i, j) into rgb (float RGB, row-major, stride = image
 * width). */
RT_PATH_FN void RT_PATH_NAME(rt_render_pixel)(const RtSceneView *s, int i, int j, int shadow_any, float *rgb,
                                         RtCounters *cnt)
{
    RtVec3 c = RT_PATH_NAME(rt_shade_pixel)(s, i, j, shadow_any, cnt);
    float *px = rgb + 3 * ((size_t)j * (size_t)s->cam.width + (size_t)i);
    px[0] = c.x;
    px[1] = c.y;
    px[2] = c.z;
}

/* Renders pixels [x0,x1) x [y0,y1) into dst, pixel (x0, y0) first and rows
 * `pitch` floats apart: into the image itself (pitch 3 * width, dst at the
 * tile's corner) or into a tile of its own (pitch 3 * (x1 - x0)). The one
 * loop every CPU backend calls. */
RT_PATH_FN void RT_PATH_NAME(rt_render_tile)(const RtSceneView *s, int x0, int y0, int x1, int y1, float *dst,
                                        size_t pitch, RtCounters *cnt)
{
    for (int j = y0; j < y1; j++) {
        float *row = dst + (size_t)(j - y0) * pitch;
        for (int i = x0; i < x1; i++) {
            RtVec3 c = RT_PATH_NAME(rt_shade_pixel)(s, i, j, RT_ANY_HIT, cnt);
            row[3 * (i - x0)] = c.x;
            row[3 * (i - x0) + 1] = c.y;
            row[3 * (i - x0) + 2] = c.z;
        }
    }
}

#undef RT_PATH_TRACE
#undef RT_PATH_NAME
#undef RT_PATH_FN
