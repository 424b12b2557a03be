/* rt.h - the raybench renderer library: scene loading, acceleration
 * structures, images and the backend table. Library functions report errors
 * as return values with a message in RtError; they never exit(). */
#ifndef RT_H
#define RT_H

#include <stddef.h>
#include <stdint.h>
/* the data types only: the shading and traversal code (core/rt_shade.h,
 * core/rt_traverse.h) is included by the backends and tools that run it */
#include "core/rt_scene.h"

typedef struct RtError {
    char msg[1024];
} RtError;

/* Formats msg into err (printf-style); returns -1 so callers can `return rt_fail(...)`. */
int rt_fail(RtError *err, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

/* ---------------------------------------------------------------- scene */

/* Image size limits, checked before any allocation. */
#define RT_MAX_SIDE 32768
#define RT_MAX_PIXELS (1ull << 28)

/* The render settings as read (camera vectors unnormalized): with the
 * arrays, all a scene cache entry stores and the MPI broadcast sends. */
typedef struct RtSceneSettings {
    RtVec3 camera_pos, camera_fwd, camera_up;
    float fov_ha; /* degrees, half the horizontal... as the format names it */
    int32_t width, height;
    int32_t max_depth;
    RtVec3 background, ambient;
    char output[4096]; /* output_image */
} RtSceneSettings;

/* Where a scene came from: the file, the lines that set values (for
 * messages), the files read for it and its own memory. file_hash is the
 * hash of the scene file's bytes as parsed (rt_content_hash); deps every
 * other file read for it (models and the files they reference), each with
 * the hash of the bytes read: the scene cache keys the first and checks the
 * others, MPI ranks agree on all. Never stored or sent as bytes: whoever
 * loads a scene fills it; a cache entry and the MPI broadcast carry, each
 * by name, only what the key, the ranks' agreement and the messages need. */
typedef struct RtSceneSource {
    char name[256];  /* scene name: file name without directory and extension */
    char path[4096]; /* file it came from */
    int line_fwd, line_up, line_fov, line_res, line_depth, line_output; /* 0: default */
    int models;      /* mesh: lines read */
    uint8_t file_hash[16];
    struct RtDep *deps; uint32_t ndeps;
    void *cache_map; /* the cache entry the arrays live in (rt_cache_load); NULL: malloc'd */
    size_t cache_len;
} RtSceneSource;

/* The arrays (core/rt_scene.h's RT_SCENE_ARRAYS), then the settings
 * (scene->settings.width) and the source (scene->source.name). */
#define RT_SCENE_ARRAY_(T, name) T *name; uint32_t n##name, cap_##name;
typedef struct RtScene {
    RT_SCENE_ARRAYS(RT_SCENE_ARRAY_)
    RtSceneSettings settings;
    RtSceneSource source;
} RtScene;
#undef RT_SCENE_ARRAY_

typedef void (*RtWarnFn)(void *ctx, const char *msg);

/* A file a scene read besides itself, as opened, and the hash of its bytes. */
typedef struct RtDep {
    char *path;
    uint8_t hash[16];
} RtDep;
/* Records that scene read len bytes from path (the bytes' hash is kept). */
int rt_scene_add_dep(RtScene *scene, const char *path, const void *bytes, size_t len, RtError *err);
/* A 128-bit hash of len bytes: XXH3-128 where the build has xxhash, else
 * two FNV-1a 64 (the same value on any number of threads). */
void rt_content_hash(const void *bytes, size_t len, uint8_t out[16]);
/* One digest of the scene's file_hash and every dependency's path and
 * hash: what MPI ranks compare. */
void rt_scene_digest(const RtScene *scene, uint8_t out[16]);
/* The dependency list as bytes (malloc'd; the cache's entries and MPI's
 * broadcast carry it) and back; unpack checks every length. */
int rt_scene_deps_pack(const RtScene *scene, char **blob, size_t *len);
int rt_scene_deps_unpack(RtScene *scene, const char *blob, size_t len, RtError *err);
struct RtAccel;
/* Checks every index a renderer follows (vertices, normals, materials,
 * light types, primitive ids) and the settings it relies on, as for a scene
 * that did not come from the parser (a cache entry). */
int rt_scene_check(const RtScene *scene, const struct RtAccel *accel, RtError *err);

/* Parses path into scene (which the caller zeroes or frees). Unknown commands
 * go to warn (may be NULL). Returns 0, or -1 with "path:line: message". */
int rt_scene_load(const char *path, RtScene *scene, RtWarnFn warn, void *warn_ctx, RtError *err);
/* As rt_scene_load on `threads` threads (0: as many as OpenMP gives): files
 * of 8 MB and more are parsed in parallel, with the same result. */
int rt_scene_load_threads(const char *path, int threads, RtScene *scene, RtWarnFn warn, void *warn_ctx,
                          RtError *err);
/* Parses a scene held in memory (len bytes, no terminator needed); name is
 * used in messages. */
int rt_scene_parse_buffer(const char *name, const char *buf, size_t len, RtScene *scene, RtWarnFn warn,
                          void *warn_ctx, RtError *err);
int rt_scene_parse_buffer_threads(const char *name, const char *buf, size_t len, int threads, RtScene *scene,
                                  RtWarnFn warn, void *warn_ctx, RtError *err);
/* Where a parse hands on the scene's geometry as it becomes final, so that
 * a backend copies it to its device while the rest is parsed (the CUDA
 * backend's GPU build: backends/cuda/geom_stream.cu). Only the parse on
 * several threads calls it, from its threads at once: `sized` once, when the
 * pools are allocated at their final sizes (the scene's caps), then `ready`
 * for disjoint ranges of elements written for good. A parse that never
 * calls `sized` (one thread, a small file, mesh: lines) leaves the copy to
 * the build. */
enum { RT_GEOM_VERTICES = 0, RT_GEOM_TRIANGLES = 1 };
typedef struct RtGeomSink {
    void *ctx;
    void (*sized)(void *ctx, const RtScene *scene);
    void (*ready)(void *ctx, int pool, uint32_t first, uint32_t count);
    /* after the load: keep 1 lets the copies finish for the build to take,
     * keep 0 stops them and frees what they hold (idempotent; also after
     * the build took them) */
    void (*end)(void *ctx, int keep);
} RtGeomSink;
/* rt_scene_load_threads and rt_scene_parse_buffer_threads with a sink
 * (NULL: none). The caller calls sink->end. */
int rt_scene_load_sink(const char *path, int threads, const RtGeomSink *sink, RtScene *scene, RtWarnFn warn,
                       void *warn_ctx, RtError *err);
int rt_scene_parse_buffer_sink(const char *name, const char *buf, size_t len, int threads, const RtGeomSink *sink,
                               RtScene *scene, RtWarnFn warn, void *warn_ctx, RtError *err);
void rt_scene_free(RtScene *scene);
/* Frees the dependency list alone (and empties it). */
void rt_scene_free_deps(RtScene *scene);
/* Sets the scene's name (the file name without directory and extension) and path. */
void rt_scene_name(RtScene *scene, const char *path);
/* Checks the camera and resolution (after CLI overrides) and builds the camera. */
int rt_scene_camera(const RtScene *scene, RtCamera *cam, RtError *err);

/* ---------------------------------------------------------------- accel */

typedef enum RtAccelKind { RT_ACCEL_NONE = 0, RT_ACCEL_BVH = 1 } RtAccelKind;

typedef struct RtAccel {
    RtAccelKind kind;
    RtPrim *prims;       /* nprims records; BVH order for bvh, index order for none */
    uint32_t nprims;
    uint32_t nsplit;     /* records a spatial split added (a primitive in several
                          * leaves): nprims - nsplit is the scene's count */
    RtBvhNode *nodes;    /* nnodes (0 for none) */
    uint32_t nnodes;
    RtBvh4Node *wide;    /* the 4-wide copy of nodes (NULL for none) */
    uint32_t nwide;
    uint32_t depth;      /* deepest leaf */
    uint32_t leaves;
    int build_threads;   /* threads the build ran on */
    int huge_pages;      /* the build asked for 2 MiB pages (RtBvhSettings.huge_pages) */
    double sah_cost;     /* the tree's SAH cost (0 for none): its quality */
    int mapped;          /* the arrays are in the scene's cache mapping: not freed here */
    /* A tree a backend built on its device (RtBackend.accel_build) stays
     * there: prims, nodes and wide are NULL until rt_accel_host copies them
     * down; rt_accel_free calls device_free. */
    void *device;
    void (*device_free)(void *device);
    int (*device_host)(struct RtAccel *accel, RtError *err);
} RtAccel;

/* The BVH build's settings, one struct a build (as Embree's
 * RTCBuildSettings): rt_bvh_settings_default() fills in the defaults, a
 * caller changes the fields it needs. threads and huge_pages change only
 * the build's speed; the others shape the tree. A value outside its range
 * (settings.c) fails the build. */
typedef struct RtBvhSettings {
    int threads;            /* build threads; <= 0 (default 0): one per prims_per_thread
                             * primitives, at most the threads OpenMP offers */
    int prims_per_thread;   /* 16384 (docs/performance.md, "Build threads") */
    int huge_pages;         /* the large arrays in 2 MiB pages (madvise(MADV_HUGEPAGE)):
                             * 1 on, 0 off, -1 (default) from huge_pages_threads build
                             * threads (raytrace --huge-pages); the same tree either way */
    int huge_pages_threads; /* 8 (docs/performance.md, "Large scenes") */
    int bins;               /* SAH bins per axis: 32 (2..32) */
    int sah_depth;          /* the SAH split above this depth, the object median
                             * below (it halves the count, bounding the depth): 44 */
    int leaf_max;           /* records per leaf: RT_BVH_LEAF_MAX (1..RT_BVH_LEAF_MAX) */
    int wide_merge;         /* a subtree of at most this many records left over in the
                             * 4-wide copy is one leaf there: 4 (1..8) */
    int spatial_min;        /* spatial splits only in nodes of at least this many
                             * references: 128, */
    int spatial_share;      /* and of at least 1/spatial_share of the scene's: 2048, */
    float spatial_overlap;  /* whose best object split's children overlap by more than
                             * this fraction of the node's area: 0.1 */
    int task_min;           /* subtrees of at least this many references are tasks: 4096 */
    int wide_task_min;      /* the same in the 4-wide copy, in records: 65536 */
    int chunk;              /* references per chunk of a large node's parallel binning
                             * and partition: 16384 (64..2^30) */
    int gpu_split;          /* the GPU build: pieces of large triangles it may add, in
                             * percent of the triangles (0..100; bvh_gpu_split.cuh), or
                             * -1 (default): chosen for the scene, rt_bvh_gpu_split_pct */
} RtBvhSettings;
RtBvhSettings rt_bvh_settings_default(void);
/* The GPU build's pieces for a scene, in percent of its triangles:
 * settings->gpu_split, or for -1 100 where the triangles are very unequal
 * (rt_bvh_split_outsized at least 0.5, from 65,536 triangles) and 0
 * otherwise; *outsized (NULL: not wanted) gets the share it was chosen by,
 * or -1 where no share was taken. */
int rt_bvh_gpu_split_pct(const RtBvhSettings *settings, const RtScene *scene, double *outsized);
/* Of the excess box area over Karras and Aila's A_ideal (doubled), the
 * share held by triangles whose boxes exceed 16 times the median box (of
 * those with an area),
 * from 16,384 triangles evenly spaced: near 1 where a few large triangles
 * spoil a tree built from sorted codes, 0 for triangles all alike. */
double rt_bvh_split_outsized(const RtScene *scene);
/* 0 when every setting lies in its range (accel/settings.c), else -1 and
 * err names the first that does not; both builders check theirs. */
int rt_bvh_settings_check(const RtBvhSettings *settings, RtError *err);
/* Builds the accelerator with `settings` (NULL: the defaults); the same tree
 * on any number of threads. 0, or -1 with err. */
int rt_accel_build_with(const RtScene *scene, RtAccelKind kind, const RtBvhSettings *settings, RtAccel *accel,
                        RtError *err);
/* The same with the default settings, and with those but `threads`. */
int rt_accel_build(const RtScene *scene, RtAccelKind kind, RtAccel *accel, RtError *err);
int rt_accel_build_threads(const RtScene *scene, RtAccelKind kind, int threads, RtAccel *accel, RtError *err);
void rt_accel_free(RtAccel *accel);
/* Makes a device-built tree's arrays (RtAccel.device) readable in host
 * memory too; nothing for any other. 0, or -1 with err. */
int rt_accel_host(RtAccel *accel, RtError *err);
/* Leaves of the binary tree hold at most this many records (the bound
 * rt_bvh_check holds every tree to; RtBvhSettings.leaf_max may be lower). */
#define RT_BVH_LEAF_MAX 4
/* Checks the BVH invariants (accel/check.c), in parallel over subtrees:
 * every record slot in exactly one leaf, every primitive in at least one
 * slot, leaves of 1..4 records, children inside parents, depth-first
 * layout, depth within the traversal stacks; the same of the 4-wide copy. */
int rt_bvh_check(const RtAccel *accel, RtError *err);
const char *rt_accel_name(RtAccelKind kind);

/* Who builds the BVH (raytrace --builder): the CPU, the GPU (a backend
 * with RtBackend.accel_build), or the one that gives the earlier image. */
typedef enum RtBuilder { RT_BUILDER_AUTO = 0, RT_BUILDER_CPU = 1, RT_BUILDER_GPU = 2 } RtBuilder;
/* What a backend's own build measured (RtBackend.accel_build). */
typedef struct RtBuildInfo {
    double kernel_ms;   /* its kernels, first to last (CUDA events) */
    double upload_ms;   /* the scene's vertices, triangles and spheres to the device (what the
                         * build still waited for, where the parse copied them) */
    int geom_streamed;  /* 1: the parse copied the vertices and triangles up (RtGeomSink) */
    double init_ms;     /* what it still waited for the device's context */
    int split_pct;      /* the pieces' budget it used (rt_bvh_gpu_split_pct) */
    double outsized;    /* the share that chose it, -1 when not chosen by one */
} RtBuildInfo;
int rt_accel_parse(const char *s, RtAccelKind *kind);

/* The view the shading code reads; pointers into scene and accel. */
RtSceneView rt_scene_view(const RtScene *scene, const RtAccel *accel, const RtCamera *cam);

/* ---------------------------------------------------------------- models */

/* Appends every triangle of a model file (OBJ, PLY, STL, glTF, ...: Assimp)
 * to the scene with the given material, positions through the 3x4 row-major
 * affine map xf (normals through its inverse transpose). Smooth triangles
 * where the file has usable normals, flat ones otherwise. 0, or -1 with
 * "FILE: message". */
int rt_model_append(const char *file, const float xf[12], uint32_t material, RtScene *scene, RtError *err);
/* Whether path names a model file this build reads (not a .txt scene). */
int rt_model_supported(const char *path);
/* A scene around one model: a camera that frames it, a light, a material
 * (io/scene_load.c, which makes `raytrace MODEL` a scene). */
int rt_model_scene(const char *path, RtScene *scene, RtError *err);
/* The most triangles one model may expand to (instanced nodes counted
 * before any expansion; default 50,000,000; --max-model-triangles): 0, or
 * -1 for 0. */
int rt_model_set_max_triangles(uint64_t n);
/* NULL when this build reads models; else why not. */
const char *rt_model_unavailable(void);

/* ---------------------------------------------------------------- scene cache */

/* The parsed scene and its accelerator for scene_path from the cache
 * folder dir (docs/scene-format.md, "Scene cache"): 1, loaded (the arrays
 * in the scene's own mapping; key gets the entry's 32 hex digits); 0, a
 * miss (parse and build; err->msg says why when an entry was refused, else
 * it is empty); -1 when the folder is refused (another user's, writable by
 * others, a link). */
int rt_cache_load(const char *dir, const char *scene_path, RtAccelKind kind, RtScene *scene, RtAccel *accel,
                  char *key, RtError *err);
/* Stores a scene as parsed and its accelerator, keyed by the bytes it was
 * parsed from (scene->source.file_hash) and listing the other files it read
 * (written whole or not at all); key gets the entry's name. */
int rt_cache_store(const char *dir, const RtScene *scene, const RtAccel *accel, char *key, RtError *err);
/* An entry's bytes (len of them, at a 64-byte aligned address, kept while
 * the scene is used) as a scene and accelerator, after checking its header,
 * its hash and everything the renderer follows: 0, or -1 with why. The
 * fuzz test calls it directly, after rt_cache_entry_seal (which sets the
 * payload hash, as anyone who can write the folder could). */
int rt_cache_entry_parse(void *bytes, size_t len, RtAccelKind kind, RtScene *scene, RtAccel *accel, RtError *err);
void rt_cache_entry_seal(void *bytes, size_t len);
/* NULL when this build has the cache; else why not. */
const char *rt_cache_unavailable(void);

/* ---------------------------------------------------------------- images */

typedef enum RtImageFormat { RT_IMG_UNKNOWN = 0, RT_IMG_PNG, RT_IMG_BMP, RT_IMG_PPM } RtImageFormat;

RtImageFormat rt_image_format_for(const char *path);
/* Writes 8-bit RGB, row-major from the top; the file appears whole or not at
 * all (written under a temporary name, then renamed). */
int rt_image_write(const char *path, const uint8_t *rgb, int width, int height, RtError *err);
/* Reads PNG (8/16-bit, any colour type), BMP (24-bit) or PPM (P6) into 8-bit RGB (malloc'd). */
int rt_image_read(const char *path, uint8_t **rgb, int *width, int *height, RtError *err);
void rt_image_quantize(const float *rgbf, uint8_t *rgb, size_t npixels);
/* One channel by the same rule (rt_quantize). */
uint8_t rt_quantize_value(float c);
uint64_t rt_fnv1a64(const uint8_t *data, size_t len);

/* ---------------------------------------------------------------- CPU traversal */

/* Chooses the CPU backends' traversal by instruction set (backends/cpu_trace.c):
 * name NULL, the best this CPU runs. 0, or -1 with "--isa: ..." in err. */
int rt_cpu_isa_select(const char *name, RtError *err);
/* The chosen one's name ("c", "sse2", "avx2"). */
const char *rt_cpu_isa_name(void);
/* The CPU traversal's copy of view v's 4-wide tree (v->cpu_wide), its
 * leaves' records packed four to a group for the SIMD leaf test
 * (v->cpu_leaves). Returns the one block to free(); NULL, with both NULL,
 * for brute force or out of memory (the CPU backends then trace with
 * rt_trace_ray: the same hits). */
void *rt_cpu_prepare(RtSceneView *v);

/* ---------------------------------------------------------------- backends */

typedef enum RtSchedule { RT_SCHED_TILES = 0, RT_SCHED_PIXELS = 1 } RtSchedule;
typedef enum RtMpiSchedule { RT_MPI_DYNAMIC = 0, RT_MPI_ROWS = 1 } RtMpiSchedule;

typedef void (*RtProgressFn)(void *ctx, uint64_t done, uint64_t total);

typedef struct RtRenderJob {
    const RtScene *scene;
    const RtAccel *accel;
    RtSceneView view;
    int threads;          /* 0: backend default */
    int tile_w, tile_h;   /* tile size in pixels */
    RtSchedule schedule;
    RtMpiSchedule mpi_schedule;
    int block_x, block_y; /* CUDA block shape; 0: default */
    int device;           /* CUDA device (mpi-cuda: the first of the node's ranks) */
    int share_gpu;        /* mpi-cuda: a node's ranks may share its GPUs */
    /* Timing (--runs, --warmup; the backend's default where unset): runs
     * timed renders, render_ms their median, after warm-up renders that are
     * not timed: warmup_runs of them, or as many as take warmup_ms (at least
     * one). Backends without RtBackend.times_runs render once per call and
     * main.c repeats the call. */
    int runs;             /* 0: the backend's default */
    int warmup_runs;      /* -1: unset */
    double warmup_ms;     /* -1: unset */
    RtProgressFn progress; /* may be NULL */
    void *progress_ctx;
    int want_float;       /* GPU backends: fill RtRenderOut.rgb too (--verify), not only rgb8 */
} RtRenderJob;

typedef struct RtRenderOut {
    float *rgb;           /* width*height*3 floats, filled by the backend (root rank); GPU backends
                           * fill it only with want_float */
    uint8_t *rgb8;        /* width*height*3 bytes: the image as written (rt_quantize of rgb) */
    int quantized;        /* 1: the backend filled rgb8 itself (GPU backends, quantised on the GPU) */
    RtCounters counters;  /* summed over all workers */
    double render_ms;     /* pixel work only (max over ranks for MPI; GPU: to the image in host memory) */
    double render_ms_min; /* min over ranks; = render_ms elsewhere */
    double render_ms_best; /* the fastest of the timed runs */
    int runs, warmups;    /* timed and warm-up renders */
    int threads_used;
    int ranks_used;
    int is_root;          /* 0 on MPI ranks other than 0: they print and write nothing */
    char cores[512];      /* CPUs the workers ran on, "0,1" */
    char extra[8192];     /* extra record keys, " key=value ...": per-rank keys of 64+ ranks */
} RtRenderOut;

typedef struct RtBackend {
    const char *name;
    /* NULL when built in; else the reason it cannot run in this build */
    const char *unavailable;
    /* optional: called before the scene is loaded (MPI_Init_thread) */
    int (*init)(int *argc, char ***argv, RtError *err);
    int (*render)(const RtRenderJob *job, RtRenderOut *out, RtError *err);
    /* optional: called before exit, also after errors */
    void (*finalize)(void);
    /* optional: hooks of backends that run as several processes (MPI) */
    const struct RtCollective *collective;
    /* 1: render() does the job's warm-up and timed runs itself (CUDA: the
     * scene stays on the device); 0: one render per call */
    int times_runs;
    /* optional: starts set-up that takes long and needs no scene (the CUDA
     * context on --device) in the background, before the scene is loaded;
     * render() waits for it */
    void (*prewarm)(int device);
    int gpu;              /* 1: renders on GPUs (no CPU traversal, no isa key) */
    /* the side of the square tiles it renders without --tile, as the
     * record's tile= shows it: the CPU backends' own (backends/backends.h);
     * the GPU backends tile by --block and record the threaded loop's; 0 for
     * a backend this build lacks */
    int tile;
    /* optional: builds the BVH on the backend's device (device: --device)
     * into accel, in host memory as rt_accel_build_with leaves it. 0 built;
     * 1 not built, for a reason err holds, where the CPU may build instead
     * (too little device memory); -1 failed */
    int (*accel_build)(const RtScene *scene, const RtBvhSettings *settings, int device, RtAccel *accel,
                       RtBuildInfo *info, RtError *err);
    /* optional, with accel_build: a sink (RtGeomSink) that copies the
     * geometry of a scene of at least min_records (0: any) to device
     * `device` while it is parsed, where accel_build finds it */
    const RtGeomSink *(*geom_sink)(int device, uint64_t min_records);
} RtBackend;

/* What main.c needs from a backend that runs as several processes, so that
 * one rank speaks for all of them and no rank is left waiting in a
 * collective call after another has failed. */
typedef struct RtCollective {
    /* 1 on the process that prints messages and the record (rank 0) */
    int (*is_root)(void);
    /* Collective: every process calls it once before rendering with its own
     * status (err holds its message when failed != 0). Returns nonzero on
     * every process if any failed; the root's err then holds the message of
     * the lowest failing rank. */
    int (*agree)(int failed, RtError *err);
    /* optional: loads the scene on every process (replaces rt_scene_load);
     * how is NULL (the backend's default) or a backend-specific mode. */
    int (*scene_load)(const char *path, const char *how, RtScene *scene, RtWarnFn warn, void *warn_ctx,
                      RtError *err);
    /* Collective: nonzero on every process unless every one holds the same
     * 16 bytes as the root (the scene's digest: ranks that read different
     * bytes must not render one image together); err then names a rank. */
    int (*same)(const uint8_t digest[16], RtError *err);
    /* optional, CPU backends: points the view's arrays at one copy for all
     * the processes of a node, so that their caches hold one scene rather
     * than one per process. Returns what unshare releases (NULL: nothing
     * shared, the view unchanged). Both collective. */
    void *(*share)(RtSceneView *v);
    void (*unshare)(void *shared);
} RtCollective;

const RtBackend *rt_backend_find(const char *name);
/* NULL-terminated list of every backend this program knows. */
const RtBackend *const *rt_backend_list(void);

/* ---------------------------------------------------------------- helpers */

/* CLOCK_MONOTONIC: one clock for every process of a node (MPI ranks
 * compare their times on it). */
int64_t rt_now_ns(void);
double rt_now_ms(void);
/* Milliseconds a fixed CPU workload takes on the calling thread now: a
 * measure of the machine's current speed (record key calib_ms). */
double rt_calibrate_ms(void);
/* Tiles of tw x th covering the image, row-major. */
static inline int rt_tile_count(int w, int h, int tw, int th)
{
    return ((w + tw - 1) / tw) * ((h + th - 1) / th);
}
static inline void rt_tile_rect(int w, int h, int tw, int th, int index, int *x0, int *y0, int *x1, int *y1)
{
    int cols = (w + tw - 1) / tw;
    *x0 = (index % cols) * tw;
    *y0 = (index / cols) * th;
    *x1 = *x0 + tw < w ? *x0 + tw : w;
    *y1 = *y0 + th < h ? *y0 + th : h;
}
/* The command-line numbers of raytrace and the tools: a whole decimal
 * integer in lo..hi, and WxH with 1 <= W,H <= maxside. 0, or -1 (out untouched). */
int rt_parse_int(const char *s, long lo, long hi, int *out);
int rt_parse_wxh(const char *s, int maxside, int *w, int *h);
/* Opens a file for reading if it is a regular file; a FIFO or a directory is
 * refused at once instead of blocking. The descriptor (st filled), or -1
 * with "path: cannot open: ..." or "path: not a regular file". */
struct stat;
int rt_open_regular(const char *path, struct stat *st, RtError *err);
/* A file written whole or not at all (io/atomic.c): unnamed until it is
 * complete (O_TMPFILE, then linkat, and renameat where the name is taken),
 * so no signal, SIGKILL included, leaves a partial file; where the file system lacks O_TMPFILE a
 * named temporary file that rt_atomic_abandon() removes from a signal
 * handler. rt_atomic_open creates name in dirfd (AT_FDCWD for a path; a
 * name with '/' is opened in its own folder), with mode 0666 less the
 * umask; write to f->fd, then rt_atomic_commit (which closes it) or
 * rt_atomic_abort. */
typedef struct RtAtomicFile {
    int fd, dirfd, own_dir;
    char base[256];  /* the final name in dirfd */
    char tmp[300];   /* the temporary name, once there is one */
} RtAtomicFile;
int rt_atomic_open(RtAtomicFile *f, int dirfd, const char *name, RtError *err);
int rt_atomic_commit(RtAtomicFile *f, RtError *err);
void rt_atomic_abort(RtAtomicFile *f);
void rt_atomic_abandon(void);
/* Where a run may write (io/output.c): an image path whose format is known
 * and whose folder is writable (checked before rendering, so a long render
 * never ends in a write error); a scene's own output_image, which must stay
 * inside the working folder (relative, no "..", no link out of it). */
int rt_output_check(const char *path, RtError *err);
int rt_scene_output_check(const char *out, RtError *err);
/* Writes msg and a newline to stderr with every byte a terminal could act
 * on (control characters, bytes that are not UTF-8) escaped as \xNN. */
void rt_say(const char *msg);
/* Input files (scenes, models, cache entries) larger than this are refused
 * before a byte is read. */
#define RT_MAX_FILE (1ull << 30)
/* Reads a whole regular file of at most max bytes into memory (malloc'd,
 * NUL-terminated, *len bytes), once: read, never mapped, so a file
 * truncated underneath is an error rather than a SIGBUS, and the file's
 * size, mtime and ctime are compared before and after, so a file written
 * meanwhile is refused ("changed while it was read") instead of mixed.
 * 0, or -1 with "path: ..." in err. */
int rt_read_file(const char *path, size_t max, char **data, size_t *len, RtError *err);
/* Reads bytes 0..n of fd into buf, in pieces on every core (pread): 0 when
 * all n came. rt_read_file and the scene cache's entries read through it. */
int rt_read_fd(int fd, char *buf, size_t n);
/* As rt_read_file, with the file's state the bytes were read in. */
int rt_read_file_stat(const char *path, size_t max, char **data, size_t *len, struct stat *st, RtError *err);
/* The median of v[0..n), n >= 1 (v is sorted in place: v[0] is the least). */
double rt_median(double *v, int n);
/* Whether another untimed warm-up render is due after `done` of them, the
 * first begun elapsed_ms ago: warmup_runs >= 0 counts them; else
 * warmup_ms >= 0 is a time, with at least one render; else none (--warmup). */
int rt_warmup_due(int warmup_runs, double warmup_ms, int done, double elapsed_ms);
/* Marks the whole 2 MiB pages inside p (n bytes, just allocated, to be
 * filled) for transparent huge pages (accel/huge_pages.c): one fault per
 * 2 MiB instead of per 4 KiB; a hint the kernel may decline. Returns p. */
void *rt_huge_hint(void *p, size_t n);
/* malloc(n) in 2 MiB pages where the kernel grants them (rt_huge_hint). */
void *rt_huge_alloc(size_t n);
/* The threads a loading step runs on when `asked` for (0: as many as
 * OpenMP gives, one per allowed CPU; 1 in a build without OpenMP). */
int rt_thread_count(int asked);
/* The threads of a pass that only streams memory -- reading, hashing and
 * checking a scene cache entry, the CPU backends' copy of the tree: at most
 * RT_STREAM_THREADS. Past that they only contend: on a 64-vCPU host, 16
 * threads hash and check a 516 MB entry in 43 ms, 64 threads in 174 ms
 * (docs/performance.md, "Scene cache"). */
#define RT_STREAM_THREADS 16
int rt_stream_threads(void);
/* Appends the CPU the calling thread runs on to a sorted, unique list. */
void rt_cores_note(char *list, size_t size, int cpu);
int rt_current_cpu(void);
/* The calling thread's CPUs (its affinity mask): a cpu_set_t of *size bytes
 * (CPU_ALLOC_SIZE) for every CPU the system may have, *ncpu of them, empty
 * and *known 0 where the kernel does not say; NULL without memory. Free
 * with free(). */
void *rt_thread_cpu_mask(size_t *size, int *ncpu, int *known);
/* The CPUs that a team of nthreads OpenMP threads may run on: the union of
 * its threads' masks; 0 where any is unknown. */
int rt_team_cpus(int nthreads);

#endif
