/* gpu_hog.cu - holds all but KEEP MiB of device 0's free memory until
 * killed, so that a test can render a scene that does not fit
 * (gpu_oom.sh). Prints "ready FREE_MIB" once it holds the memory. */
#include <cuda_runtime.h>
#include <stdio.h>
#include <stdlib.h>
#include <unistd.h>

int main(int argc, char **argv)
{
    const size_t keep = (size_t)(argc > 1 ? atoi(argv[1]) : 256) << 20;
    size_t free_b = 0, total_b = 0;
    if (cudaSetDevice(0) != cudaSuccess || cudaMemGetInfo(&free_b, &total_b) != cudaSuccess || free_b <= keep) {
        fprintf(stderr, "gpu_hog: no device memory to hold\n");
        return 1;
    }
    void *p = NULL;
    size_t want = free_b - keep;
    while (cudaMalloc(&p, want) != cudaSuccess && want > keep) /* (the free figure is approximate) */
        want -= 64u << 20;
    cudaMemGetInfo(&free_b, &total_b);
    printf("ready %zu\n", free_b >> 20);
    fflush(stdout);
    for (;;)
        pause();
}
