/* rt_math.h - float32 vector math shared by host and device. */
#ifndef RT_MATH_H
#define RT_MATH_H

#include <math.h>
#include "rt_defs.h"

typedef struct RtVec3 {
    float x, y, z;
} RtVec3;

static inline RT_HD RtVec3 rt_v3(float x, float y, float z)
{
    RtVec3 r;
    r.x = x; r.y = y; r.z = z;
    return r;
}
static inline RT_HD RtVec3 rt_v3_load(const float *p) { return rt_v3(p[0], p[1], p[2]); }
static inline RT_HD RtVec3 rt_add(RtVec3 a, RtVec3 b) { return rt_v3(a.x + b.x, a.y + b.y, a.z + b.z); }
static inline RT_HD RtVec3 rt_sub(RtVec3 a, RtVec3 b) { return rt_v3(a.x - b.x, a.y - b.y, a.z - b.z); }
static inline RT_HD RtVec3 rt_mul(RtVec3 a, RtVec3 b) { return rt_v3(a.x * b.x, a.y * b.y, a.z * b.z); }
static inline RT_HD RtVec3 rt_scale(RtVec3 a, float s) { return rt_v3(a.x * s, a.y * s, a.z * s); }
static inline RT_HD RtVec3 rt_neg(RtVec3 a) { return rt_v3(-a.x, -a.y, -a.z); }
static inline RT_HD float rt_dot(RtVec3 a, RtVec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static inline RT_HD RtVec3 rt_cross(RtVec3 a, RtVec3 b)
{
    return rt_v3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}
static inline RT_HD float rt_length(RtVec3 a) { return sqrtf(rt_dot(a, a)); }
/* Karras and Aila's A_ideal (HPG 2013) of triangle (a, b, c): twice the
 * areas of its projections on the three axis planes, what the boxes of
 * ever smaller pieces tend to (the GPU build's pieces, and their choice in
 * accel/settings.c). */
static inline RT_HD float rt_tri_ideal_area(RtVec3 a, RtVec3 b, RtVec3 c)
{
    const RtVec3 n = rt_cross(rt_sub(b, a), rt_sub(c, a));
    return fabsf(n.x) + fabsf(n.y) + fabsf(n.z);
}
/* Normalizes; a zero vector stays zero instead of becoming NaN. */
static inline RT_HD RtVec3 rt_normalize(RtVec3 a)
{
    float l2 = rt_dot(a, a);
    return l2 > 0.0f ? rt_scale(a, 1.0f / sqrtf(l2)) : a;
}
/* a + s*b */
static inline RT_HD RtVec3 rt_madd(RtVec3 a, RtVec3 b, float s) { return rt_add(a, rt_scale(b, s)); }
static inline RT_HD float rt_minf(float a, float b) { return a < b ? a : b; }
static inline RT_HD float rt_maxf(float a, float b) { return a > b ? a : b; }
static inline RT_HD float rt_clamp01(float a) { return a < 0.0f ? 0.0f : (a > 1.0f ? 1.0f : a); }
static inline RT_HD int rt_is_zero(RtVec3 a) { return a.x == 0.0f && a.y == 0.0f && a.z == 0.0f; }
static inline RT_HD float rt_v3_get(RtVec3 a, int axis) { return axis == 0 ? a.x : (axis == 1 ? a.y : a.z); }

#endif
