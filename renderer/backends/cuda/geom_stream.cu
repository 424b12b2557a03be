/* geom_stream.cu - the scene's vertices and triangles copied up to the GPU
 * while the file is still parsed (rt.h's RtGeomSink), for the GPU build to
 * take instead of copying them itself (bvh_gpu.cu).
 *
 * The parse on several threads (io/scene_chunks.c) sizes its pools after
 * its first pass, then places each chunk's vertices and writes the runs of
 * triangles on its threads; each range is handed here once final. A thread
 * of its own waits for the context (made on the prewarm thread), takes room
 * on the device, page-locks the two pools and copies the ranges as they
 * come, adjacent ones as one copy. The build finds the geometry on the
 * device when every vertex and triangle came so; otherwise (a serial parse,
 * a failed copy) it copies as before. One load per process: the state is
 * static. */
#include <pthread.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <algorithm>

#include <cuda_runtime.h>

extern "C" {
#include "rt.h"
}
#include "bvh_gpu.h"
#include "cuda_check.h"

typedef struct Range {
    uint32_t pool, first, count;
} Range;

static pthread_mutex_t g_mu = PTHREAD_MUTEX_INITIALIZER;
static pthread_cond_t g_cv = PTHREAD_COND_INITIALIZER;

static struct {
    pthread_t thread;
    int started, ended, stop, failed;
    int device;
    uint64_t min_records;
    const RtScene *scene;  /* as `sized` saw it: the pools' places and sizes */
    const void *host[2];
    size_t elem[2];
    uint32_t cap[2];
    uint64_t copied[2];
    Range *q;
    size_t nq, capq;
    unsigned char *mem;    /* vertices, then triangles at tri_off */
    size_t tri_off;
} g;

static size_t align256(size_t b) { return (b + 255u) & ~(size_t)255u; }

static bool range_less(const Range &a, const Range &b)
{
    return a.pool != b.pool ? a.pool < b.pool : a.first < b.first;
}

/* The ranges taken off the queue, sorted, adjacent ones joined, copied. */
static int copy_ranges(Range *r, size_t n)
{
    std::sort(r, r + n, range_less);
    for (size_t i = 0; i < n;) {
        size_t j = i + 1;
        uint32_t count = r[i].count;
        while (j < n && r[j].pool == r[i].pool && r[j].first == r[i].first + count)
            count += r[j++].count;
        const int pl = (int)r[i].pool;
        const size_t off = (size_t)r[i].first * g.elem[pl], bytes = (size_t)count * g.elem[pl];
        unsigned char *dst = g.mem + (pl == RT_GEOM_TRIANGLES ? g.tri_off : 0) + off;
        if (cudaMemcpy(dst, (const unsigned char *)g.host[pl] + off, bytes, cudaMemcpyHostToDevice) != cudaSuccess)
            return -1;
        g.copied[pl] += count;
        i = j;
    }
    return 0;
}

/* The copying thread: the context, the room, the locks, then the queue
 * until the load ends (or is stopped). */
static void *stream_main(void *)
{
    int locked[2] = {0, 0};
    Range *batch = NULL;
    size_t cap = 0;
    int ok = cudaSetDevice(g.device) == cudaSuccess && cudaFree(0) == cudaSuccess &&
             cudaMalloc((void **)&g.mem, g.tri_off + align256((size_t)g.cap[1] * g.elem[1])) == cudaSuccess;
    for (int pl = 0; ok && pl < 2; pl++) /* (a range that cannot be locked is copied as it is) */
        locked[pl] = rt_cuda_lock((void *)g.host[pl], (size_t)g.cap[pl] * g.elem[pl]);
    pthread_mutex_lock(&g_mu);
    for (;;) {
        while (ok && g.nq == 0 && !g.ended && !g.stop)
            pthread_cond_wait(&g_cv, &g_mu);
        if (!ok || g.stop || (g.nq == 0 && g.ended))
            break;
        if (g.nq > cap) {
            Range *nb = (Range *)realloc(batch, g.nq * sizeof *nb);
            ok = nb != NULL;
            if (!ok)
                break;
            batch = nb;
            cap = g.nq;
        }
        const size_t n = g.nq;
        memcpy(batch, g.q, n * sizeof *batch);
        g.nq = 0;
        pthread_mutex_unlock(&g_mu);
        ok = copy_ranges(batch, n) == 0;
        pthread_mutex_lock(&g_mu);
    }
    g.failed = !ok;
    pthread_mutex_unlock(&g_mu);
    for (int pl = 0; pl < 2; pl++)
        if (locked[pl])
            cudaHostUnregister((void *)g.host[pl]);
    if (!ok)
        cudaGetLastError(); /* (the build copies instead, and reports any lasting fault) */
    free(batch);
    return NULL;
}

static void on_sized(void *, const RtScene *sc)
{
    if ((uint64_t)sc->cap_triangles + sc->cap_spheres < g.min_records)
        return; /* (a scene the build would not take to the GPU) */
    pthread_mutex_lock(&g_mu);
    g.scene = sc;
    g.host[RT_GEOM_VERTICES] = sc->vertices;
    g.host[RT_GEOM_TRIANGLES] = sc->triangles;
    g.elem[RT_GEOM_VERTICES] = sizeof(RtVec3);
    g.elem[RT_GEOM_TRIANGLES] = sizeof(RtTriangle);
    g.cap[RT_GEOM_VERTICES] = sc->cap_vertices;
    g.cap[RT_GEOM_TRIANGLES] = sc->cap_triangles;
    g.tri_off = align256((size_t)sc->cap_vertices * sizeof(RtVec3));
    g.started = pthread_create(&g.thread, NULL, stream_main, NULL) == 0;
    pthread_mutex_unlock(&g_mu);
}

static void on_ready(void *, int pool, uint32_t first, uint32_t count)
{
    pthread_mutex_lock(&g_mu);
    if (g.started && !g.stop) {
        if (g.nq == g.capq) {
            const size_t nc = g.capq ? 2 * g.capq : 256;
            Range *nq = (Range *)realloc(g.q, nc * sizeof *nq);
            if (nq) {
                g.q = nq;
                g.capq = nc;
            } else {
                g.stop = 1; /* (the build copies all of it) */
            }
        }
        if (g.nq < g.capq)
            g.q[g.nq++] = Range{(uint32_t)pool, first, count};
        pthread_cond_signal(&g_cv);
    }
    pthread_mutex_unlock(&g_mu);
}

/* Waits for the copying thread (stopping it first unless keep). */
static void stream_join(int keep)
{
    pthread_mutex_lock(&g_mu);
    g.ended = 1;
    g.stop |= !keep;
    pthread_cond_signal(&g_cv);
    const int started = g.started;
    g.started = 0;
    pthread_mutex_unlock(&g_mu);
    if (started)
        pthread_join(g.thread, NULL);
}

static void on_end(void *, int keep)
{
    if (keep) { /* the copies go on; the build joins them */
        pthread_mutex_lock(&g_mu);
        g.ended = 1;
        pthread_cond_signal(&g_cv);
        pthread_mutex_unlock(&g_mu);
        return;
    }
    stream_join(0);
    if (g.mem) /* (NULL once the build took it; no call that would make a context) */
        cudaFree(g.mem);
    g.mem = NULL;
    free(g.q);
    g.q = NULL;
    g.nq = g.capq = 0;
}

static const RtGeomSink g_sink = {NULL, on_sized, on_ready, on_end};

extern "C" const RtGeomSink *rt_cuda_geom_sink(int device, uint64_t min_records)
{
    g.device = device;
    g.min_records = min_records;
    return &g_sink;
}

extern "C" int rt_cuda_geom_take(const RtScene *sc, int device, RtCudaGeom *out)
{
    memset(out, 0, sizeof *out);
    const double t0 = rt_now_ms();
    stream_join(1);
    out->wait_ms = rt_now_ms() - t0;
    if (!g.mem || g.failed || g.scene != sc || g.device != device || g.host[0] != sc->vertices ||
        g.host[1] != sc->triangles || g.copied[0] != sc->nvertices || g.copied[1] != sc->ntriangles)
        return 0;
    out->mem = g.mem;
    out->vertices = (const RtVec3 *)g.mem;
    out->triangles = (const RtTriangle *)(g.mem + g.tri_off);
    out->taken = 1;
    g.mem = NULL;
    return 1;
}
