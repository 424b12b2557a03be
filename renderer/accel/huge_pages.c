/* huge_pages.c - the build's large arrays and the parser's pools in 2 MiB
 * pages where the kernel grants them (transparent huge pages on request:
 * madvise mode). A fresh array then costs one page fault per 2 MiB instead
 * of one per 4 KiB, and the top nodes' reference arrays are fresh at every
 * level; with many build threads those faults contend (docs/performance.md,
 * "Large scenes"). The GPU build locks the pools for its copy up in a few
 * pages. A hint only: the tree is the same with or without it. */
#include <stdlib.h>
#include <sys/mman.h>

#include "build_internal.h"

#define HUGE_PAGE ((uintptr_t)2 << 20)

void *rt_huge_hint(void *p, size_t n)
{
#ifdef MADV_HUGEPAGE
    if (p && n >= 2 * HUGE_PAGE) {
        const uintptr_t a = ((uintptr_t)p + HUGE_PAGE - 1) & ~(HUGE_PAGE - 1);
        const uintptr_t e = ((uintptr_t)p + n) & ~(HUGE_PAGE - 1);
        if (e > a)
            (void)madvise((void *)a, e - a, MADV_HUGEPAGE);
    }
#else
    (void)n;
#endif
    return p;
}

/* rt_huge_hint when `on` (the build's choice: bvh_huge_pages_on). */
void *bvh_huge_hint(void *p, size_t n, int on) { return on ? rt_huge_hint(p, n) : p; }

void *rt_huge_alloc(size_t n) { return rt_huge_hint(malloc(n), n); }

/* malloc(n), in 2 MiB pages when `on`. */
void *bvh_alloc(size_t n, int on) { return on ? rt_huge_alloc(n) : malloc(n); }
