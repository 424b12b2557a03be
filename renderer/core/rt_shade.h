/* rt_shade.h - the steps of Whitted shading without recursion
 * (RENDERING-RULES "Shading") that trace no ray: a hit's surface, a light's
 * contribution, the pending-ray stack. The loop that traces the rays
 * (rt_trace_path, rt_render_pixel, rt_render_tile) is the template
 * rt_path_tmpl.h, instantiated once per ray query by the unit that uses it.
 *
 * trace(ray, depth) is unrolled into an explicit stack of pending rays, each
 * carrying the product of the ks/kt weights on its path. Popping a ray adds
 * weight * (local colour) to the pixel and pushes its reflected and refracted
 * children. With RT_MAX_DEPTH bounding depth, a pending stack of
 * RT_MAX_DEPTH + 2 entries can never overflow: every pop pushes at most two
 * rays one level deeper, so at most one sibling per level is ever waiting. */
#ifndef RT_SHADE_H
#define RT_SHADE_H

#include "rt_traverse.h"

#define RT_RAY_STACK (RT_MAX_DEPTH + 2)

typedef struct RtPending {
    RtVec3 o, d;  /* ray */
    RtVec3 w;     /* weight of this ray's colour in the pixel */
    int32_t depth;
} RtPending;

/* Surface data at a hit. */
typedef struct RtSurface {
    RtVec3 p;       /* hit point */
    RtVec3 n;       /* unit normal facing against the ray */
    int front;      /* 1 if the geometric side was not flipped */
    uint32_t material;
} RtSurface;

static inline RT_HD RtSurface rt_surface(const RtSceneView *s, RtVec3 o, RtVec3 d, const RtHit *h)
{
    RtSurface sf;
    sf.p = rt_madd(o, d, h->t);
    uint32_t gid = h->id & ~RT_PRIM_SPHERE_BIT;
    RtVec3 n;
    if (h->id & RT_PRIM_SPHERE_BIT) {
        const RtSphere *sp = &s->spheres[gid];
        n = rt_scale(rt_sub(sf.p, rt_v3_load(sp->c)), 1.0f / sp->r);
        sf.material = sp->material;
    } else {
        const RtTriangle *tr = &s->triangles[gid - s->nspheres];
        if (tr->n[0] >= 0) {
            float w0 = 1.0f - h->u - h->v;
            n = rt_scale(s->normals[tr->n[0]], w0);
            n = rt_madd(n, s->normals[tr->n[1]], h->u);
            n = rt_madd(n, s->normals[tr->n[2]], h->v);
        } else {
            RtVec3 v0 = s->vertices[tr->v[0]];
            n = rt_cross(rt_sub(s->vertices[tr->v[1]], v0), rt_sub(s->vertices[tr->v[2]], v0));
        }
        sf.material = tr->material;
    }
    n = rt_normalize(n);
    sf.front = rt_dot(n, d) <= 0.0f;
    sf.n = sf.front ? n : rt_neg(n);
    return sf;
}

/* The unshadowed contribution of light li at the surface, and the shadow ray
 * that decides whether it arrives (from just above the surface towards the
 * light; any surface closer than the light blocks it, transparent or not).
 * Returns 0 when the contribution is exactly zero (behind a spot cone, or
 * N.L <= 0 with no specular lobe): such a light casts no shadow ray, since it
 * could not change the colour. */
static inline RT_HD int rt_light_sample(const RtSceneView *s, const RtSurface *sf, const RtMaterial *m, RtVec3 view,
                                        uint32_t li, RtVec3 *contrib, RtVec3 *dir, float *dist)
{
    const RtLight *lt = &s->lights[li];
    RtVec3 I = rt_v3_load(lt->color);
    RtVec3 L;
    float dl;
    if (lt->type == RT_LIGHT_DIRECTIONAL) {
        L = rt_neg(rt_v3_load(lt->dir));
        dl = RT_INF;
    } else {
        RtVec3 tl = rt_sub(rt_v3_load(lt->pos), sf->p);
        dl = rt_length(tl);
        if (!(dl > 0.0f))
            return 0;
        L = rt_scale(tl, 1.0f / dl);
        I = rt_scale(I, 1.0f / (dl * dl));
        if (lt->type == RT_LIGHT_SPOT) {
            float c = rt_dot(rt_v3_load(lt->dir), rt_neg(L));
            c = c > 1.0f ? 1.0f : (c < -1.0f ? -1.0f : c);
            float a = acosf(c) * (180.0f / 3.14159265358979f);
            if (a > lt->angle2)
                return 0;
            if (a > lt->angle1)
                I = rt_scale(I, 1.0f - (a - lt->angle1) / (lt->angle2 - lt->angle1));
        }
    }
    float ndl = rt_maxf(0.0f, rt_dot(sf->n, L));
    RtVec3 H = rt_normalize(rt_add(L, view));
    float ndh = rt_maxf(0.0f, rt_dot(sf->n, H));
    float spec = powf(ndh, m->ns);
    RtVec3 c = rt_add(rt_scale(rt_v3_load(m->kd), ndl), rt_scale(rt_v3_load(m->ks), spec));
    c = rt_mul(c, I);
    if (rt_is_zero(c))
        return 0;
    *contrib = c;
    *dir = L;
    *dist = dl;
    return 1;
}

/* The start of a hit's local colour (ka * ambient_light) and where its
 * shadow rays leave from (just above the surface, along the normal), for
 * rt_trace_path and for tests that trace a hit's rays one by one. */
static inline RT_HD RtVec3 rt_ambient_term(const RtSceneView *s, const RtMaterial *m)
{
    return rt_mul(rt_v3_load(m->ka), s->ambient);
}

static inline RT_HD RtVec3 rt_shadow_origin(const RtSurface *sf)
{
    return rt_madd(sf->p, sf->n, RT_SHADOW_OFFSET);
}

/* Pushes the mirror and refracted children of a shaded hit (refraction
 * first, so the mirror ray is traced first). */
static inline RT_HD void rt_push_children(RtPending *stack, int *sp, const RtPending *r, const RtSurface *sf,
                                          const RtMaterial *m)
{
    float dn = rt_dot(r->d, sf->n);
    RtVec3 R = rt_normalize(rt_sub(r->d, rt_scale(sf->n, 2.0f * dn)));
    RtVec3 wt = rt_mul(r->w, rt_v3_load(m->kt));
    if (!rt_is_zero(wt)) {
        float eta = sf->front ? 1.0f / m->ior : m->ior;
        float cos_i = -dn;
        float k = 1.0f - eta * eta * (1.0f - cos_i * cos_i);
        RtVec3 T = R; /* total internal reflection */
        if (k >= 0.0f)
            T = rt_normalize(rt_add(rt_scale(r->d, eta), rt_scale(sf->n, eta * cos_i - sqrtf(k))));
        stack[*sp].o = rt_madd(sf->p, T, RT_SECONDARY_OFFSET);
        stack[*sp].d = T;
        stack[*sp].w = wt;
        stack[*sp].depth = r->depth - 1;
        (*sp)++;
    }
    RtVec3 wr = rt_mul(r->w, rt_v3_load(m->ks));
    if (!rt_is_zero(wr)) {
        stack[*sp].o = rt_madd(sf->p, R, RT_SECONDARY_OFFSET);
        stack[*sp].d = R;
        stack[*sp].w = wr;
        stack[*sp].depth = r->depth - 1;
        (*sp)++;
    }
}

/* The pending stack of a pixel: its primary ray (none when max_depth is 0).
 * Returns the stack's size. */
static inline RT_HD int rt_path_begin(const RtSceneView *s, RtRay primary, RtPending *stack)
{
    if (s->max_depth <= 0)
        return 0;
    stack[0].o = primary.o;
    stack[0].d = primary.d;
    stack[0].w = rt_v3(1.0f, 1.0f, 1.0f);
    stack[0].depth = s->max_depth;
    return 1;
}

/* The next pending ray, counted as primary or secondary. */
static inline RT_HD RtPending rt_path_pop(const RtSceneView *s, RtPending *stack, int *sp, RtCounters *cnt)
{
    const RtPending r = stack[--*sp];
    if (r.depth == s->max_depth)
        cnt->primary_rays++;
    else
        cnt->secondary_rays++;
    return r;
}

#endif
