/* cuda_check.h - every CUDA runtime call and launch goes through RT_CUDA_CHECK.
 *
 * Errors are values (GUIDE habit 5): a failed call formats "file:line: call:
 * CUDA's message" into the RtError in scope (named `err`) and jumps to the
 * function's `fail:` label, which releases what was allocated. Release builds
 * check too: the report's 32x32 blocks failed silently because nothing was
 * checked after its launches. */
#ifndef RT_CUDA_CHECK_H
#define RT_CUDA_CHECK_H

#include <cuda_runtime.h>

/* Formats the message; returns -1 (see rt_fail). */
static inline int rt_cuda_fail(RtError *err, cudaError_t e, const char *call, const char *file, int line)
{
    return rt_fail(err, "cuda: %s:%d: %s failed: %s (%s)", file, line, call, cudaGetErrorString(e),
                   cudaGetErrorName(e));
}

/* Checks one runtime call; needs `RtError *err` and a `fail:` label in scope. */
#define RT_CUDA_CHECK(call)                                                  \
    do {                                                                     \
        cudaError_t rt_e_ = (call);                                          \
        if (rt_e_ != cudaSuccess) {                                          \
            rt_cuda_fail(err, rt_e_, #call, __FILE__, __LINE__);             \
            goto fail;                                                       \
        }                                                                    \
    } while (0)

/* After a <<<...>>> launch: a bad configuration (too many threads or
 * registers for the block, no kernel image for this GPU) is reported by
 * cudaGetLastError at once; faults inside the kernel surface at the next
 * synchronizing call, which is itself checked. */
#define RT_CUDA_CHECK_LAUNCH(kernel_name)                                    \
    do {                                                                     \
        cudaError_t rt_e_ = cudaGetLastError();                              \
        if (rt_e_ != cudaSuccess) {                                          \
            rt_cuda_fail(err, rt_e_, "launch of " kernel_name, __FILE__, __LINE__); \
            goto fail;                                                       \
        }                                                                    \
    } while (0)

/* Page-locks host memory for the device's copies: 1, or 0 where it cannot
 * be locked and stays pageable (the failure is not sticky: cleared). */
static inline int rt_cuda_lock(void *host, size_t bytes)
{
    if (cudaHostRegister(host, bytes, cudaHostRegisterDefault) == cudaSuccess)
        return 1;
    cudaGetLastError();
    return 0;
}

/* cudaMemcpy from host memory up to the device. A large range is
 * page-locked for the copy and released after it: 121 MB in 2 MiB pages
 * took 7.5-12.6 ms so, lock and release included, against 15-21 ms from
 * pageable memory (one H200: benchmarks/cuda_setup.c, docs/performance.md,
 * "The GPU build"). A range that cannot be locked is copied as it is. */
static inline cudaError_t rt_cuda_copy_up(void *dst, const void *src, size_t bytes)
{
    void *lock = bytes >= ((size_t)8 << 20) && rt_cuda_lock((void *)src, bytes) ? (void *)src : NULL;
    cudaError_t e = cudaMemcpy(dst, src, bytes, cudaMemcpyHostToDevice);
    if (lock) {
        const cudaError_t u = cudaHostUnregister(lock);
        e = e != cudaSuccess ? e : u;
    }
    return e;
}

#endif
