/* bvh_gpu.h - the BVH built on the GPU (bvh_gpu.cu), for the CUDA backends'
 * RtBackend.accel_build. It yields the RtAccel the CPU builder yields --
 * records in leaf order, the binary tree depth-first, its 4-wide copy --
 * kept on the device, where the render reads it; rt_accel_host copies it
 * down for --verify and the scene cache. */
#ifndef RT_BVH_GPU_H
#define RT_BVH_GPU_H

#include "rt.h"

#ifdef __cplusplus
extern "C" {
#endif

/* A tree built on the device (RtAccel.device): the build's one allocation
 * that the render reads in place -- the records, the binary and 4-wide
 * trees, and the scene's vertices, triangles and spheres it took up. */
typedef struct RtCudaTree {
    int device;
    unsigned char *mem;
    unsigned char *geom; /* the vertices and triangles the parse copied up (geom_stream.cu), or NULL */
    const RtPrim *prims;
    const RtBvhNode *nodes;
    RtBvh4Node *wide;
    const RtVec3 *vertices;
    const RtTriangle *triangles;
    const RtSphere *spheres;
} RtCudaTree;

/* The scene's vertices and triangles on the device, copied while the scene
 * was parsed (geom_stream.cu). */
typedef struct RtCudaGeom {
    unsigned char *mem;      /* one allocation (cudaFree) */
    const RtVec3 *vertices;
    const RtTriangle *triangles;
    int taken;               /* 1: every vertex and triangle is there */
    double wait_ms;          /* what the build still waited for them */
} RtCudaGeom;

/* The CUDA backend's RtGeomSink for device `device`: it copies a scene of
 * at least min_records triangles and spheres (0: any) while it is parsed. */
const RtGeomSink *rt_cuda_geom_sink(int device, uint64_t min_records);
/* Waits for the sink's copies; 1 with the geometry in out (the caller owns
 * out->mem) when every vertex and triangle of sc was copied to `device`;
 * 0 otherwise (out->wait_ms still set), the copying left to the caller. */
int rt_cuda_geom_take(const RtScene *sc, int device, RtCudaGeom *out);

/* Sorts the tree's nwide 4-wide nodes' slots in place along way
 * (schedule.h's rt_cuda_slot_sort), on the current device's stream 0. */
int rt_cuda_tree_slot_order(RtCudaTree *tree, uint32_t nwide, const float way[3], RtError *err);

/* Builds scene's BVH on CUDA device `device` with settings' leaf_max (the
 * other settings shape the CPU's top-down build only) into accel, its
 * device an RtCudaTree; as RtBackend.accel_build. 1 (err says why): too
 * little device memory, too many records, or a tree deeper than the
 * traversal's stacks. */
int rt_cuda_accel_build(const RtScene *scene, const RtBvhSettings *settings, int device, RtAccel *accel,
                        RtBuildInfo *info, RtError *err);

#ifdef __cplusplus
}
#endif

#endif
