/* rt_quantize.h - the 8-bit output rule, one function for host and device:
 * the CPU backends' images (scene.c) and the GPU's (kernels.cuh) are
 * rounded by the same operations, so they compare byte for byte. */
#ifndef RT_QUANTIZE_H
#define RT_QUANTIZE_H

#include "rt_math.h"

/* Clamp to [0,1], times 255, round to nearest. */
static inline RT_HD uint8_t rt_quantize(float c)
{
    if (!(c > 0.0f)) /* also maps a NaN (an unwritten, poisoned pixel) to 0 */
        return 0;
#if defined(__CUDA_ARCH__)
    /* a multiply and an add, each rounded, as the C build does them
     * (-ffp-contract=off): nvcc would fuse them into one FMA */
    return (uint8_t)__fadd_rn(__fmul_rn(rt_clamp01(c), 255.0f), 0.5f);
#else
    return (uint8_t)(rt_clamp01(c) * 255.0f + 0.5f);
#endif
}

#endif
