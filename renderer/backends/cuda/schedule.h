/* schedule.h - how the CUDA backend maps pixels to threads: the launch
 * geometry the kernel reads, and the host-side choices that fill it in
 * (schedule.c). Plain C, shared by nvcc and the C compiler, so the choices
 * are tested without a GPU (tests/unit/test_cuda_schedule.c). */
#ifndef RT_CUDA_SCHEDULE_H
#define RT_CUDA_SCHEDULE_H

#include <stdint.h>

#include "rt.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Launch geometry the kernel reads (passed by value: the constant bank). */
typedef struct RtCudaGrid {
    int32_t bx, by;         /* pixel tile of a block (bx is half the block's width with pairs) */
    int32_t tiles_x;        /* tiles per image row */
    uint32_t tile_items;    /* bx * by: pixels per tile */
    uint32_t total_items;   /* tiles_x * tiles_y * tile_items (edge tiles overhang the image) */
    uint32_t ntiles;        /* tiles in the image */
    int32_t persistent;     /* 1: warps fetch 32 pixels at a time from a counter; 0: one block per tile */
    int32_t pairs;          /* 1: two lanes per pixel (grid schedule only) */
    const uint32_t *units;  /* grid schedule: block b renders tile units[b] (the centre order); NULL: the
                             * launch's tile b in its share (rt_cuda_share_tile) */
    uint32_t first_row;     /* the share of tile rows the launch renders (RtCudaShare): rows first_row + */
    uint32_t run, period;   /* k * period + j for j < run; 0, 1, 1 for the whole image */
} RtCudaGrid;

/* A GPU's share of each frame's tile rows (the MPI backend's ranks): rows
 * first + k * period + j, for k = 0, 1, ... and j < run, inside the image.
 * Ranks that interleave their shares row by row (run 1, period P) get the
 * image's expensive rows in equal parts, so GPUs of one kind finish
 * together. The whole image is {0, 1, 1}. */
typedef struct RtCudaShare {
    int first, run, period;
} RtCudaShare;

/* The launch's tile n in raster order of the whole image: its row of tiles
 * through the share, its column as it is (host and device, one formula). */
#ifdef __CUDACC__
__host__ __device__
#endif
static inline uint32_t rt_cuda_share_tile(const RtCudaGrid *g, uint32_t n)
{
    const uint32_t r = n / (uint32_t)g->tiles_x, x = n - r * (uint32_t)g->tiles_x;
    return (g->first_row + (r / g->run) * g->period + r % g->run) * (uint32_t)g->tiles_x + x;
}

/* How a share's pixels lie in an image of `rows` tile rows of row_h pixel
 * rows each (the last may be cut by the image's height h), each pixel row
 * row_bytes long: `count` equal pieces `width` bytes long, `pitch` apart,
 * from byte `off` (a 2D copy or an MPI vector), then one more piece of
 * tail_bytes at tail_off (0: none). tile_rows is the share's rows. */
typedef struct RtShareRuns {
    size_t off, width, pitch, count;
    size_t tail_off, tail_bytes;
    uint32_t tile_rows;
} RtShareRuns;
void rt_cuda_share_runs(const RtCudaShare *sh, int rows, int row_h, int h, size_t row_bytes, RtShareRuns *out);
/* The grid g restricted to share sh (units dropped unless sh is the whole
 * image); 0 when the share has no rows in the image. */
uint32_t rt_cuda_grid_share(RtCudaGrid *g, const RtCudaShare *sh, int rows);

/* What the host decided for one render (the record prints it). */
typedef struct RtCudaPlan {
    int bx, by, threads;    /* the CUDA block */
    int persistent;         /* schedule: persistent (1) or grid (0) */
    int large;              /* the large-image defaults were taken */
    int pairs;              /* two lanes per pixel */
    int slot;               /* shadow rays take a node's children in slot order (RT_ANY_HIT_SLOT) */
    int minb;               /* blocks per multiprocessor the kernel's register budget allows */
    int center;             /* grid schedule: tiles from the image's centre outwards */
} RtCudaPlan;

/* Frames in flight: 2, so that one frame's copy (and its kernel's last
 * blocks) run under the next frame's kernel; RT_CUDA_MAX_SLOTS where the
 * frame fills the GPU's resident threads fewer than RT_CUDA_DEEP_WAVES times
 * (waves), so that frames too small to fill it share it. */
#define RT_CUDA_MAX_SLOTS 4
int rt_cuda_frames_in_flight(double waves);

/* The block when --block is not given: tree or brute force. */
void rt_cuda_default_block(int has_tree, int *bx, int *by);
/* The schedule and register cap before --block and the image are weighed in. */
void rt_cuda_plan_start(RtCudaPlan *p, int has_tree, int block_x, int block_y);
/* Large images with the tree and no --block: npix at least RT_CUDA_LARGE_WAVES
 * times the pixels the default kernel keeps resident switch to the persistent
 * schedule in its own block and register cap. Returns 1 when it switched. */
int rt_cuda_plan_large(RtCudaPlan *p, double npix, double resident);
/* Pixel pairs when the grid's blocks of pairs all fit on the GPU at once:
 * pair_blocks_per_sm is the pairs kernel's occupancy. */
int rt_cuda_pairs_possible(const RtCudaPlan *p);
int rt_cuda_pairs_fit(const RtCudaPlan *p, int w, int h, int pair_blocks_per_sm, int nsm);
/* Fills the launch geometry for a w x h image; -1 (err) past 2^32 work items. */
int rt_cuda_grid(const RtCudaPlan *p, int w, int h, RtCudaGrid *g, RtError *err);
/* The centre order of the grid's tiles (malloc'd, g->ntiles entries). */
uint32_t *rt_cuda_center_order(const RtCudaGrid *g, int w, int h, RtError *err);
/* The slot order of the 4-wide tree for shadow rays (a malloc'd copy of the
 * nodes, or NULL when the scene has no single direction of shadow rays and
 * the build's order stays): see schedule.c. */
RtBvh4Node *rt_cuda_slot_order(const RtSceneView *v, RtError *err, int *failed);
/* Whether the slot order applies (the scene's one light is directional),
 * and its way (towards the light). */
int rt_cuda_slot_way(const RtSceneView *v, float way[3]);
/* One node's slots front to back along `way` (by their boxes' centres),
 * ties in their order: rt_cuda_slot_order's sort, and the GPU build's
 * (bvh_gpu.cu), which sorts its tree in place. */
static inline RT_HD void rt_cuda_slot_sort(const float way[3], RtBvh4Node *o)
{
    float key[4];
    for (uint32_t k = 0; k < o->count; k++) {
        key[k] = 0.0f;
        key[k] += 0.5f * (o->lo_x[k] + o->hi_x[k]) * way[0];
        key[k] += 0.5f * (o->lo_y[k] + o->hi_y[k]) * way[1];
        key[k] += 0.5f * (o->lo_z[k] + o->hi_z[k]) * way[2];
    }
    for (uint32_t i = 1; i < o->count; i++) /* insertion sort: ties keep their order */
        for (uint32_t j = i; j > 0 && key[j] < key[j - 1]; j--) {
#define RT_SWAP(T, a) do { T t_ = (a)[j]; (a)[j] = (a)[j - 1]; (a)[j - 1] = t_; } while (0)
            RT_SWAP(float, key);
            RT_SWAP(float, o->lo_x); RT_SWAP(float, o->lo_y); RT_SWAP(float, o->lo_z);
            RT_SWAP(float, o->hi_x); RT_SWAP(float, o->hi_y); RT_SWAP(float, o->hi_z);
            RT_SWAP(uint32_t, o->child);
#undef RT_SWAP
        }
}

#ifdef __cplusplus
}
#endif

#endif
