/* cuda_setup.c - what a first image pays the GPU before any kernel
 * (docs/performance.md, "The GPU build"):
 *   cuda-setup context SPINNERS   the CUDA context (cudaGetDeviceCount, then
 *                                 cudaFree(0) on device 0) made beside
 *                                 SPINNERS threads busy on the CPU; run it in
 *                                 a fresh process each time
 *   cuda-setup copy MB ROUNDS     the copy of MB megabytes up from pageable
 *                                 memory in 4 KiB and in 2 MiB pages, and
 *                                 through rt_cuda_copy_up (locked for the
 *                                 copy), each from freshly written memory
 * One line of key=value per measurement. */
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "rt.h"
#include "backends/cuda/cuda_check.h"

static volatile int stop;

static void *spin(void *arg)
{
    (void)arg;
    while (!stop) {
    }
    return NULL;
}

static int context(int spinners)
{
    pthread_t th[256];
    int n = 0, ndev = 0;
    while (n < spinners && n < 256 && pthread_create(&th[n], NULL, spin, NULL) == 0)
        n++;
    const double t0 = rt_now_ms();
    const cudaError_t e1 = cudaGetDeviceCount(&ndev);
    const double t1 = rt_now_ms();
    const cudaError_t e2 = e1 == cudaSuccess && ndev > 0 ? cudaFree(0) : e1;
    const double t2 = rt_now_ms();
    stop = 1;
    for (int i = 0; i < n; i++)
        pthread_join(th[i], NULL);
    if (e2 != cudaSuccess || ndev == 0) {
        fprintf(stderr, "cuda-setup: no usable GPU: %s\n", cudaGetErrorString(e2));
        return 1;
    }
    printf("spinners=%d device_count_ms=%.1f context_ms=%.1f\n", n, t1 - t0, t2 - t1);
    return 0;
}

/* n fresh bytes, in 2 MiB pages when huge (rt_huge_alloc) */
static char *fresh(size_t n, int huge)
{
    char *p = huge ? rt_huge_alloc(n) : malloc(n);
    if (p)
        memset(p, 1, n);
    return p;
}

static int copy(size_t mb, int rounds)
{
    const size_t n = mb << 20;
    void *d = NULL;
    if (cudaMalloc(&d, n) != cudaSuccess) {
        fprintf(stderr, "cuda-setup: cudaMalloc(%zu MB) failed\n", mb);
        return 1;
    }
    for (int r = 0; r < rounds; r++)
        for (int way = 0; way < 3; way++) { /* 4 KiB pageable, 2 MiB pageable, 2 MiB locked */
            char *p = fresh(n, way > 0);
            if (!p)
                return fprintf(stderr, "cuda-setup: out of memory for %zu MB\n", mb), cudaFree(d), 1;
            const double t0 = rt_now_ms();
            const cudaError_t e = way == 2 ? rt_cuda_copy_up(d, p, n) : cudaMemcpy(d, p, n, cudaMemcpyHostToDevice);
            const double t1 = rt_now_ms();
            free(p);
            if (e != cudaSuccess)
                return fprintf(stderr, "cuda-setup: copy failed: %s\n", cudaGetErrorString(e)), 1;
            printf("round=%d mb=%zu pages=%s copy=%s ms=%.2f\n", r, mb, way ? "2M" : "4K",
                   way == 2 ? "locked" : "pageable", t1 - t0);
        }
    cudaFree(d);
    return 0;
}

/* A whole number in [lo, hi] from s, else -1. */
static long number(const char *s, long lo, long hi)
{
    char *end;
    const long v = strtol(s, &end, 10);
    return end != s && !*end && v >= lo && v <= hi ? v : -1;
}

int main(int argc, char **argv)
{
    const long a = argc >= 3 ? number(argv[2], 0, 1 << 20) : -1, b = argc == 4 ? number(argv[3], 1, 1000) : -1;
    if (argc == 3 && !strcmp(argv[1], "context") && a >= 0 && a <= 256)
        return context((int)a);
    if (argc == 4 && !strcmp(argv[1], "copy") && a >= 1 && b >= 1)
        return copy((size_t)a, (int)b);
    fprintf(stderr, "usage: cuda-setup context SPINNERS (0-256) | cuda-setup copy MB ROUNDS (1-1048576, 1-1000)\n");
    return 2;
}
