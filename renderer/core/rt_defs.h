/* rt_defs.h - the host/device macro and fixed-size types every shared header uses.
 *
 * Shared code is `static inline RT_HD` on typedef'd plain structs, so that the
 * C compiler and nvcc compile the very same source (pbrt-v4's PBRT_CPU_GPU).
 * Rules for shared headers: no VLAs, no compound literals, no designated
 * initializers, no bare `restrict`, no implicit void* casts. tests/header_test
 * compiles each header alone as C11 and through nvcc. */
#ifndef RT_DEFS_H
#define RT_DEFS_H

#include <stdint.h>

#if defined(__CUDACC__)
#define RT_HD __host__ __device__
#define RT_RESTRICT __restrict__
#else
#define RT_HD
#define RT_RESTRICT __restrict
#endif

/* Deepest recursion a scene may ask for; bounds the explicit ray stack. */
#define RT_MAX_DEPTH 32
/* Hits closer than this along a ray are ignored (RENDERING-RULES: t > 1e-4). */
#define RT_T_MIN 1e-4f
/* Secondary rays leave the surface by this much along their direction. */
#define RT_SECONDARY_OFFSET 1e-3f
/* Shadow rays leave the surface by this much along the normal. */
#define RT_SHADOW_OFFSET 1e-4f
#define RT_INF 3.402823466e+38f

#endif
