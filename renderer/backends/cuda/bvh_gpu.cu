/* bvh_gpu.cu - the BVH built on the GPU for the CUDA backends.
 *
 *   1. each record's padded box (as the CPU pads it); large triangles split
 *      into pieces, each a reference with its own box (Karras and Aila
 *      2013, bvh_gpu_split.cuh); the references' centroids' bounds;
 *   2. 30-bit Morton codes of the centroids, sorted (CUB's radix sort);
 *   3. H-PLOC (Benthin, Meister, Barczak, Mehalwal, Tsakok and Kensler,
 *      "H-PLOC: Hierarchical Parallel Locally-Ordered Clustering for
 *      Bounding Volume Hierarchy Construction", HPG 2024): one thread per
 *      record climbs the implicit LBVH of the sorted codes (Apetrei, 2014;
 *      equal codes told apart by their index, Karras 2012), and a warp
 *      clusters each range of more than 16 clusters by nearest neighbours
 *      within 8 places (PLOC, Meister and Bittner 2018). Each new node is a
 *      leaf where the SAH says so (traversal and test cost 1, as the CPU
 *      build weighs them), so no separate collapse pass runs;
 *   4. top-down, a level of 4-wide nodes per launch: each opens its largest
 *      inner child until it has four (as accel/wide.c does), writes the
 *      binary nodes it passes in depth-first order and gathers its leaves'
 *      references in leaf order (a split triangle's in each leaf of a
 *      piece); then one thread per reference writes its record there.
 * The result is the RtAccel the CPU builder makes, kept on the device for
 * the render to read in place (rt_accel_host copies it down for --verify
 * and the scene cache). The device code is bvh_gpu_kernels.cuh. */
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <algorithm>

#include <cuda_runtime.h>
#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_reduce.cuh>
#include <cub/device/device_scan.cuh>

extern "C" {
#include "rt.h"
}
#include "bvh_gpu.h"
#include "cuda_check.h"
#include "cuda_session.h"
#include "schedule.h"

#include "bvh_gpu_kernels.cuh"
#include "bvh_gpu_split.cuh"

/* ---------------------------------------------------------------- host */

static unsigned blocks_for(uint32_t n) { return (n + BLOCK - 1) / BLOCK; }
static unsigned bounds_grid(uint32_t n) { return std::min(blocks_for(n), (unsigned)BOUNDS_BLOCKS); }

/* Pieces of one device block at 256-byte aligned offsets: first with base
 * NULL to size it, then again to place them. */
typedef struct Carve {
    unsigned char *base;
    size_t off;
} Carve;

static void *carve(Carve *c, size_t bytes)
{
    void *p = c->base ? c->base + c->off : NULL;
    c->off += (bytes + 255u) & ~(size_t)255u;
    return p;
}

/* What the render keeps (the scene's geometry, records and trees, the
 * outputs at their largest: a leaf per record) and what only the build
 * uses; the task queue reuses the sort's keys, dead by then. */
typedef struct Blocks {
    Carve keep, scratch;
    uint32_t *sortbuf;
    void *sort_temp;
    size_t sort_bytes;
    double *sah; /* SAH_BLOCKS partial sums, then the cost */
    float *psum; /* the split priorities' sum */
} Blocks;

/* n: the references at most; geo: the geometry where the parse copied it
 * (geom_stream.cu), else room for it. */
static void carve_build(Blocks *k, Build *B, const RtScene *sc, uint32_t n, const RtCudaGeom *geo)
{
    const size_t m = 2 * (size_t)n - 1;
    Carve *c = &k->keep;
    if (geo->taken) {
        B->verts = geo->vertices;
        B->tris = geo->triangles;
    } else {
        B->verts = (const RtVec3 *)carve(c, (size_t)sc->nvertices * sizeof(RtVec3));
        B->tris = (const RtTriangle *)carve(c, (size_t)sc->ntriangles * sizeof(RtTriangle));
    }
    B->sph = (const RtSphere *)carve(c, (size_t)sc->nspheres * sizeof(RtSphere));
    B->prims = (RtPrim *)carve(c, (size_t)n * sizeof(RtPrim));
    B->bnodes = (RtBvhNode *)carve(c, m * sizeof(RtBvhNode));
    B->wide = (RtBvh4Node *)carve(c, (size_t)n * sizeof(RtBvh4Node));
    c = &k->scratch;
    B->rbox = (GBox *)carve(c, (size_t)n * sizeof(GBox));
    B->rrec = (uint32_t *)carve(c, (size_t)n * sizeof(uint32_t));
    B->box = (GBox *)carve(c, m * sizeof(GBox));
    B->kids = (uint2 *)carve(c, m * sizeof(uint2));
    B->cost = (float *)carve(c, m * sizeof(float));
    B->meta = (uint32_t *)carve(c, m * sizeof(uint32_t));
    B->nsub = (uint32_t *)carve(c, m * sizeof(uint32_t));
    B->cluster = (uint32_t *)carve(c, (size_t)n * sizeof(uint32_t));
    B->order = B->cluster; /* (dead after H-PLOC) */
    B->parent = (uint32_t *)carve(c, (size_t)n * sizeof(uint32_t));
    k->sortbuf = (uint32_t *)carve(c, 4 * (size_t)n * sizeof(uint32_t)); /* keys, keys, values, values */
    B->queue = (Task *)k->sortbuf;
    k->sort_temp = carve(c, k->sort_bytes);
    B->ctr = (uint32_t *)carve(c, C_COUNT * sizeof(uint32_t));
    k->sah = (double *)carve(c, (SAH_BLOCKS + 1) * sizeof(double));
    k->psum = (float *)carve(c, sizeof(float));
}

/* The references (bvh_gpu_split.cuh) into rbox and rrec, B->n their count;
 * the counts and their sums use the sort's buffer, dead until the codes. */
static int make_refs(Build *B, Blocks *k, RtError *err)
{
    const uint32_t nr = B->nrec;
    uint32_t *count = k->sortbuf, *first = k->sortbuf + 2 * (size_t)nr;
    size_t bytes = 0; /* (CUB's in-out size: the sort's stays as it is) */
    if (B->budget == 0) {
        B->n = nr;
        k_split_none<<<blocks_for(nr), BLOCK>>>(*B);
        RT_CUDA_CHECK_LAUNCH("k_split_none");
        return 0;
    }
    k_init<<<1, 128>>>(*B); /* (the records' centroid bounds; build_binary starts again for the references') */
    k_bounds<<<bounds_grid(nr), BLOCK>>>(*B, false);
    k_split_priority<<<blocks_for(nr), BLOCK>>>(*B);
    bytes = k->sort_bytes;
    RT_CUDA_CHECK(cub::DeviceReduce::Sum(k->sort_temp, bytes, B->cost, k->psum, (int)nr));
    k_split_count<<<blocks_for(nr), BLOCK>>>(*B, k->psum, count);
    bytes = k->sort_bytes;
    RT_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(k->sort_temp, bytes, count, first, (int)nr));
    k_split_total<<<1, 1>>>(*B, count, first);
    k_split_emit<<<blocks_for(B->n), BLOCK>>>(*B, count, first); /* (B->n: the most references) */
    RT_CUDA_CHECK_LAUNCH("k_split_emit");
    RT_CUDA_CHECK(cudaMemcpy(&B->n, B->ctr + C_REFS, sizeof B->n, cudaMemcpyDeviceToHost));
    if (B->n < nr || B->n > nr + B->budget)
        return rt_fail(err, "cuda: the GPU build's splits went wrong: %u references for %u records", B->n, nr);
    return 0;
fail:
    return -1;
}

/* References, codes, sort, leaves and H-PLOC. */
static int build_binary(Build *B, Blocks *k, RtError *err)
{
    if (make_refs(B, k, err))
        return -1;
    const uint32_t n = B->n;
    uint32_t *sb = k->sortbuf;
    cub::DoubleBuffer<uint32_t> keys(sb, sb + n), vals(sb + 2 * (size_t)n, sb + 3 * (size_t)n);
    if (B->budget) /* (k_split_none set them otherwise) */
        k_init<<<1, 128>>>(*B);
    k_bounds<<<bounds_grid(n), BLOCK>>>(*B, true);
    k_morton<<<blocks_for(n), BLOCK>>>(*B, keys.Current(), vals.Current());
    RT_CUDA_CHECK_LAUNCH("k_morton");
    RT_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(k->sort_temp, k->sort_bytes, keys, vals, (int)n, 0, 30));
    B->skeys = keys.Current();
    B->svals = vals.Current();
    k_leaves<<<blocks_for(n), BLOCK>>>(*B);
    if (n > 1)
        k_hploc<<<blocks_for(n), BLOCK>>>(*B);
    RT_CUDA_CHECK_LAUNCH("k_hploc");
    return 0;
fail:
    return -1;
}

/* The 4-wide and depth-first trees, a level per launch, and the SAH cost;
 * h gets the counters, sah the cost. 1 when the tree is deeper than the
 * traversal allows. */
static int build_wide(const Build *B, const Blocks *k, int nsm, cudaEvent_t end, uint32_t *h, double *sah,
                      RtError *err)
{
    const unsigned grid = (unsigned)nsm * 8u;
    /* Levels launched before the first look at the queue: about a 4-wide
     * tree's depth (log4 n, plus 6 for the leaves' sizes and the tree's
     * imbalance), so a large build waits on the host once; 8 at a time
     * after that. (Every look drains the GPU: 10-20 us.) */
    int level = 0, batch = 6;
    for (uint32_t m = B->n; m > 1; m = (m + 3) / 4)
        batch++;
    batch = std::max(batch, 8);
    k_root<<<1, 1>>>(*B);
    for (;;) {
        for (int j = 0; j < batch && level < MAX_LEVELS; j++, level++)
            k_widen<<<grid, BLOCK>>>(*B, level);
        batch = 8;
        RT_CUDA_CHECK_LAUNCH("k_widen");
        RT_CUDA_CHECK(cudaMemcpy(h, B->ctr, C_COUNT * sizeof(uint32_t), cudaMemcpyDeviceToHost));
        if (h[C_MARK + level + 1] == h[C_MARK + level])
            break;
        if (level >= MAX_LEVELS)
            return 1;
    }
    k_prims<<<blocks_for(B->n), BLOCK>>>(*B);
    k_sah<<<SAH_BLOCKS, BLOCK>>>(*B, k->sah);
    RT_CUDA_CHECK_LAUNCH("k_sah");
    RT_CUDA_CHECK(cudaEventRecord(end));
    RT_CUDA_CHECK(cudaMemcpy(sah, k->sah + SAH_BLOCKS, sizeof *sah, cudaMemcpyDeviceToHost));
    return 0;
fail:
    return -1;
}

/* The scene's records, vertices and spheres to the device (the spheres
 * alone where the parse copied the rest). */
static int upload(const Build *B, const RtScene *sc, const RtCudaGeom *geo, RtError *err)
{
    if (!geo->taken) {
        RT_CUDA_CHECK(rt_cuda_copy_up((void *)B->verts, sc->vertices, (size_t)sc->nvertices * sizeof(RtVec3)));
        RT_CUDA_CHECK(rt_cuda_copy_up((void *)B->tris, sc->triangles, (size_t)sc->ntriangles * sizeof(RtTriangle)));
    }
    RT_CUDA_CHECK(rt_cuda_copy_up((void *)B->sph, sc->spheres, (size_t)sc->nspheres * sizeof(RtSphere)));
    return 0;
fail:
    return -1;
}

/* The device's two blocks for n records, or 1 with why they do not fit. */
static int reserve(Build *B, Blocks *k, const RtScene *sc, const RtCudaGeom *geo, int device, unsigned char **keep,
                   unsigned char **scratch, RtError *err)
{
    size_t free_b = 0, total_b = 0;
    cub::DoubleBuffer<uint32_t> dk(NULL, NULL), dv(NULL, NULL);
    cudaError_t e = cudaSuccess;
    double need = 0.0;
    size_t reduce_b = 0, scan_b = 0;
    RT_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(NULL, k->sort_bytes, dk, dv, (int)B->n, 0, 30));
    RT_CUDA_CHECK(cub::DeviceReduce::Sum(NULL, reduce_b, (float *)NULL, (float *)NULL, (int)B->nrec));
    RT_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(NULL, scan_b, (uint32_t *)NULL, (uint32_t *)NULL, (int)B->nrec));
    k->sort_bytes = std::max(k->sort_bytes, std::max(reduce_b, scan_b));
    k->keep.base = k->scratch.base = NULL;
    k->keep.off = k->scratch.off = 0;
    carve_build(k, B, sc, B->n, geo);
    need = (double)(k->keep.off + k->scratch.off) / 1048576.0;
    RT_CUDA_CHECK(cudaMemGetInfo(&free_b, &total_b));
    if (k->keep.off + k->scratch.off > free_b)
        return rt_fail(err, "the GPU build of %u records needs %.1f MiB, device %d has %.1f MiB free", B->n, need,
                       device, (double)free_b / 1048576.0), 1;
    e = cudaMalloc((void **)keep, k->keep.off);
    if (e == cudaSuccess)
        e = cudaMalloc((void **)scratch, k->scratch.off);
    if (e == cudaErrorMemoryAllocation) {
        cudaGetLastError();
        return rt_fail(err, "the GPU build of %u records needs %.1f MiB, more than device %d could give", B->n,
                       need, device), 1;
    }
    RT_CUDA_CHECK(e);
    k->keep.base = *keep;
    k->scratch.base = *scratch;
    k->keep.off = k->scratch.off = 0;
    carve_build(k, B, sc, B->n, geo);
    return 0;
fail:
    return -1;
}

/* ---------------------------------------------------------------- the kept tree */

static void tree_free(void *p)
{
    RtCudaTree *t = (RtCudaTree *)p;
    if (!t)
        return;
    int cur = -1;
    if (cudaGetDevice(&cur) == cudaSuccess && cur != t->device)
        cudaSetDevice(t->device);
    cudaFree(t->mem);
    cudaFree(t->geom);
    if (cur >= 0 && cur != t->device)
        cudaSetDevice(cur);
    free(t);
}

/* The tree's arrays in host memory, for --verify, the scene cache and the
 * record (a GPU tree stays on the device otherwise). */
static int tree_host(RtAccel *a, RtError *err)
{
    const RtCudaTree *t = (const RtCudaTree *)a->device;
    if (a->prims || !t)
        return 0;
    a->prims = (RtPrim *)malloc((size_t)a->nprims * sizeof(RtPrim));
    a->nodes = (RtBvhNode *)malloc((size_t)a->nnodes * sizeof(RtBvhNode));
    a->wide = (RtBvh4Node *)malloc((size_t)a->nwide * sizeof(RtBvh4Node));
    if (!a->prims || !a->nodes || !a->wide)
        return rt_fail(err, "out of memory for the BVH of %u records", a->nprims);
    RT_CUDA_CHECK(cudaSetDevice(t->device));
    RT_CUDA_CHECK(cudaMemcpy(a->prims, t->prims, (size_t)a->nprims * sizeof(RtPrim), cudaMemcpyDeviceToHost));
    RT_CUDA_CHECK(cudaMemcpy(a->nodes, t->nodes, (size_t)a->nnodes * sizeof(RtBvhNode), cudaMemcpyDeviceToHost));
    RT_CUDA_CHECK(cudaMemcpy(a->wide, t->wide, (size_t)a->nwide * sizeof(RtBvh4Node), cudaMemcpyDeviceToHost));
    return 0;
fail:
    return -1;
}

extern "C" int rt_cuda_tree_slot_order(RtCudaTree *t, uint32_t nwide, const float way[3], RtError *err)
{
    k_slot_sort<<<(nwide + BLOCK - 1) / BLOCK, BLOCK>>>(t->wide, nwide, way[0], way[1], way[2]);
    RT_CUDA_CHECK_LAUNCH("k_slot_sort");
    return 0;
fail:
    return -1;
}

/* The build's results into accel: the tree stays on the device. */
static int adopt(const Build *B, const uint32_t *h, double sah, int device, unsigned char *keep, unsigned char *geom,
                 RtAccel *a, RtError *err)
{
    RtCudaTree *t = (RtCudaTree *)calloc(1, sizeof *t);
    if (!t)
        return rt_fail(err, "out of memory");
    t->device = device;
    t->mem = keep;
    t->geom = geom;
    t->prims = B->prims;
    t->nodes = B->bnodes;
    t->wide = B->wide;
    t->vertices = B->verts;
    t->triangles = B->tris;
    t->spheres = B->sph;
    a->kind = RT_ACCEL_BVH;
    a->nprims = B->n;
    a->nsplit = B->n - B->nrec;
    a->nnodes = h[C_NSUB];
    a->nwide = h[C_QTAIL];
    a->depth = h[C_DEPTH];
    a->leaves = h[C_LEAVES];
    a->sah_cost = sah;
    a->device = t;
    a->device_free = tree_free;
    a->device_host = tree_host;
    return 0;
}

/* The build without pieces: where the auto budget's pieces would pass the
 * records' limit, or their room does not fit the device. */
static void pieces_give_way(Build *B, RtBuildInfo *info)
{
    B->budget = 0;
    B->n = B->nrec;
    info->split_pct = 0;
}

extern "C" int rt_cuda_accel_build(const RtScene *sc, const RtBvhSettings *set, int device, RtAccel *a,
                                   RtBuildInfo *info, RtError *err)
{
    const RtBvhSettings def = rt_bvh_settings_default();
    const uint64_t n64 = (uint64_t)sc->nspheres + sc->ntriangles;
    memset(a, 0, sizeof *a);
    memset(info, 0, sizeof *info);
    if (!set)
        set = &def;
    if (n64 == 0) /* nothing to build: the CPU's empty accelerator */
        return rt_accel_build_with(sc, RT_ACCEL_BVH, set, a, err) ? -1 : 0;
    if (rt_bvh_settings_check(set, err) != 0)
        return -1;
    /* (chosen on the host while the context may still be in the making) */
    info->split_pct = rt_bvh_gpu_split_pct(set, sc, &info->outsized);
    const uint64_t budget = sc->ntriangles * (uint64_t)info->split_pct / 100u;
    const int chosen = set->gpu_split < 0; /* (pieces chosen for the scene give way where they do not fit) */
    if (n64 + (chosen ? 0 : budget) >= RT_WIDE_MAX_FIRST)
        return rt_fail(err, "the GPU build takes fewer than %u records and pieces, the scene has %llu and %llu",
                       RT_WIDE_MAX_FIRST, (unsigned long long)n64, (unsigned long long)budget), 1;
    Build B;
    Blocks k;
    memset(&B, 0, sizeof B);
    memset(&k, 0, sizeof k);
    B.nrec = (uint32_t)n64;
    B.budget = (uint32_t)budget;
    B.n = (uint32_t)(n64 + budget); /* (the blocks hold the most references) */
    if (n64 + budget >= RT_WIDE_MAX_FIRST)
        pieces_give_way(&B, info);
    B.nspheres = sc->nspheres;
    B.leaf_max = set->leaf_max;
    unsigned char *keep = NULL, *scratch = NULL;
    uint32_t h[C_COUNT];
    cudaEvent_t ev[2] = {NULL, NULL};
    int nsm = 0, rc = -1;
    float ms = 0.0f;
    double sah = 0.0, t0 = 0.0;
    RtCudaGeom geo;
    if (rt_cuda_device_open(device, &info->init_ms, err))
        return -1;
    info->geom_streamed = rt_cuda_geom_take(sc, device, &geo);
    RT_CUDA_CHECK(cudaDeviceGetAttribute(&nsm, cudaDevAttrMultiProcessorCount, device));
    rc = reserve(&B, &k, sc, &geo, device, &keep, &scratch, err);
    if (rc == 1 && chosen && B.budget) { /* without the pieces' room it may fit */
        cudaFree(keep);
        cudaFree(scratch);
        keep = scratch = NULL;
        memset(&k, 0, sizeof k);
        pieces_give_way(&B, info);
        rc = reserve(&B, &k, sc, &geo, device, &keep, &scratch, err);
    }
    if (rc != 0)
        goto done;
    rc = -1;
    t0 = rt_now_ms();
    if (upload(&B, sc, &geo, err))
        goto done;
    info->upload_ms = rt_now_ms() - t0 + geo.wait_ms;
    RT_CUDA_CHECK(cudaEventCreate(&ev[0]));
    RT_CUDA_CHECK(cudaEventCreate(&ev[1]));
    RT_CUDA_CHECK(cudaEventRecord(ev[0]));
    if (build_binary(&B, &k, err) || (rc = build_wide(&B, &k, nsm, ev[1], h, &sah, err)) < 0)
        goto done;
    if (rc == 1 || h[C_DEPTH] > RT_BVH_MAX_DEPTH) {
        rt_fail(err, "the GPU's tree is %s%u levels deep, past the traversal's %d", rc == 1 ? "over " : "",
                rc == 1 ? (unsigned)MAX_LEVELS : h[C_DEPTH], RT_BVH_MAX_DEPTH);
        rc = 1;
        goto done;
    }
    rc = -1;
    RT_CUDA_CHECK(cudaEventElapsedTime(&ms, ev[0], ev[1]));
    info->kernel_ms = ms;
    if (h[C_PRIMS] != B.n || h[C_QTAIL] > B.n || h[C_NSUB] > 2 * B.n - 1 || h[C_NODES] != 2 * B.n - 1) {
        rt_fail(err, "cuda: the GPU build went wrong: %u of %u records in leaves, %u nodes", h[C_PRIMS], B.n,
                h[C_NODES]);
        goto done;
    }
    if (adopt(&B, h, sah, device, keep, geo.mem, a, err))
        goto done;
    keep = NULL;
    geo.mem = NULL;
    rc = 0;
    goto done;
fail:
    rc = -1;
done:
    for (int j = 0; j < 2; j++)
        if (ev[j])
            cudaEventDestroy(ev[j]);
    cudaFree(scratch);
    cudaFree(keep);
    cudaFree(geo.mem);
    if (rc != 0)
        rt_accel_free(a);
    return rc;
}
