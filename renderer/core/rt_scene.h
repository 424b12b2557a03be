/* rt_scene.h - the scene as flat, pointer-free arrays.
 *
 * Every array here goes unchanged to the GPU (one cudaMemcpy each) and over MPI
 * (one MPI_Bcast each): no pointers inside elements, fixed-size fields only.
 * RtSceneView bundles pointers to those arrays (host or device) plus the
 * per-frame constants, and is what the shading code reads. */
#ifndef RT_SCENE_H
#define RT_SCENE_H

#include "rt_math.h"

typedef struct RtMaterial {
    float ka[3];  /* ambient reflectance, multiplies ambient_light */
    float kd[3];  /* diffuse reflectance */
    float ks[3];  /* specular reflectance and mirror weight */
    float ns;     /* Phong exponent */
    float kt[3];  /* transmission weight */
    float ior;    /* index of refraction of the inside */
} RtMaterial;     /* 56 bytes */

typedef struct RtSphere {
    float c[3];        /* centre, world units */
    float r;           /* radius, world units (> 0) */
    uint32_t material; /* index into materials */
} RtSphere;            /* 20 bytes */

typedef struct RtTriangle {
    uint32_t v[3];     /* vertex pool indices */
    int32_t n[3];      /* normal pool indices; n[0] < 0: flat triangle */
    uint32_t material; /* index into materials */
} RtTriangle;          /* 28 bytes */

enum { RT_LIGHT_POINT = 0, RT_LIGHT_DIRECTIONAL = 1, RT_LIGHT_SPOT = 2 };

typedef struct RtLight {
    int32_t type;     /* RT_LIGHT_* */
    float color[3];   /* intensity per channel */
    float pos[3];     /* point/spot position, world units */
    float dir[3];     /* directional/spot: direction the light travels, normalized */
    float angle1;     /* spot: full-intensity cone half angle, degrees */
    float angle2;     /* spot: cut-off half angle, degrees */
} RtLight;            /* 48 bytes */

/* One intersectable primitive in the layout the traversal reads: 40 bytes.
 * Triangles keep vertex 0 and the two edges (Moller-Trumbore needs exactly
 * these); spheres keep centre and radius. Both accelerators intersect the same
 * records with the same arithmetic, which is what makes their images equal. */
#define RT_PRIM_SPHERE_BIT 0x80000000u
typedef struct RtPrim {
    float p0[3];  /* triangle: vertex 0; sphere: centre */
    float e1[3];  /* triangle: v1 - v0; sphere: e1[0] = radius */
    float e2[3];  /* triangle: v2 - v0; sphere: unused (0) */
    uint32_t id;  /* global primitive index | RT_PRIM_SPHERE_BIT for spheres */
} RtPrim;

/* Global primitive index: spheres first (0 .. nspheres-1) in file order, then
 * triangles in file order. Equal hit distances go to the lower index. */

typedef struct RtCamera {
    RtVec3 pos;     /* camera position */
    RtVec3 fwd;     /* normalized camera_fwd: the camera looks along -fwd */
    RtVec3 right;   /* normalize(cross(up_hint, fwd)) */
    RtVec3 up;      /* normalize(cross(fwd, right)) */
    float d;        /* distance to the film plane, pixels: (H/2)/tan(fov_ha) */
    int32_t width;  /* pixels */
    int32_t height; /* pixels */
} RtCamera;

/* A node of the flat BVH: 32 bytes, depth-first order, the first child of an
 * interior node is the next node (pbrt-v4 LinearBVHNode). */
/* The deepest leaf a tree may have (the root at depth 0): a binned-SAH BVH
 * over 2^32 primitives with leaves of at most 4 is far shallower; the
 * builders refuse deeper trees, so the traversal's stacks
 * (core/rt_traverse.h) never overflow. */
#define RT_BVH_MAX_DEPTH 60
typedef struct RtBvhNode {
    float lo[3];     /* bounds minimum */
    uint32_t index;  /* leaf: first primitive in prims; interior: second child */
    float hi[3];     /* bounds maximum */
    uint32_t meta;   /* bits 0-7: primitive count (0 = interior); bits 8-9: split axis */
} RtBvhNode;

/* A node of the 4-wide BVH: the binary tree collapsed (rt_accel_build does
 * it, accel/wide.c), each node holding the boxes of up to four children -- the
 * binary tree's own boxes, unchanged -- in SoA order, so a node is one
 * 128-byte cache line and one visit tests four boxes, independently (Wald et
 * al., "Getting rid of packets", 2008; the GPU's traversal, docs/gpu.md). */
#define RT_WIDE_EMPTY 0xffffffffu /* child[k]: no child */
#define RT_WIDE_LEAF 0x80000000u  /* child[k]: RT_WIDE_LEAF | first prim << 3 | (count - 1) */
#define RT_WIDE_MAX_FIRST (1u << 28)
typedef struct RtBvh4Node {
    float lo_x[4], hi_x[4], lo_y[4], hi_y[4], lo_z[4], hi_z[4];
    uint32_t child[4]; /* inner child: node index */
    uint32_t count;    /* children in use (the first `count` entries) */
    uint32_t pad[3];
} RtBvh4Node;         /* 128 bytes */

/* The scene's flat arrays, listed once: X(element type, name) each. The
 * scene (rt.h's RtScene) holds `T *name; uint32_t nname, cap_name;`, the
 * view below `const T *name; uint32_t nname;`, and the scene's free, its
 * cache entry, the MPI broadcast and the CUDA upload iterate the list. */
#define RT_SCENE_ARRAYS(X)   \
    X(RtVec3, vertices)      \
    X(RtVec3, normals)       \
    X(RtSphere, spheres)     \
    X(RtTriangle, triangles) \
    X(RtMaterial, materials) \
    X(RtLight, lights)

#define RT_VIEW_ARRAY_(T, name) const T *name; uint32_t n##name;
typedef struct RtSceneView {
    const RtPrim *prims;          /* nprims records, in BVH order for bvh */
    const RtBvhNode *nodes;       /* nnodes nodes; NULL/0: brute force */
    const RtBvh4Node *wide;       /* nwide nodes of the 4-wide copy (root 0); NULL: none */
    RT_SCENE_ARRAYS(RT_VIEW_ARRAY_) /* the vertex and normal pools, spheres, triangles, materials, lights */
    uint32_t nprims, nnodes, nwide;
    RtCamera cam;
    RtVec3 background;            /* colour of rays that hit nothing */
    RtVec3 ambient;               /* ambient light intensity */
    int32_t max_depth;            /* 1: primary and shadow rays only */
    /* CPU backends: their copy of the 4-wide tree, whose leaves refer to
     * groups of four records in cpu_leaves (backends/cpu_trace.h); NULL: none. */
    const RtBvh4Node *cpu_wide;         /* nwide nodes */
    const struct RtCpuLeaf4 *cpu_leaves; /* ncpu_leaves groups */
    uint32_t ncpu_leaves;
} RtSceneView;
#undef RT_VIEW_ARRAY_

/* Exact, deterministic work counters (machine-independent). */
typedef struct RtCounters {
    uint64_t primary_rays;
    uint64_t shadow_rays;
    uint64_t secondary_rays;
    uint64_t node_visits;
    uint64_t prim_tests;
} RtCounters;

static inline RT_HD void rt_counters_add(RtCounters *a, const RtCounters *b)
{
    a->primary_rays += b->primary_rays;
    a->shadow_rays += b->shadow_rays;
    a->secondary_rays += b->secondary_rays;
    a->node_visits += b->node_visits;
    a->prim_tests += b->prim_tests;
}

static inline RT_HD uint64_t rt_counters_rays(const RtCounters *c)
{
    return c->primary_rays + c->shadow_rays + c->secondary_rays;
}

#endif
