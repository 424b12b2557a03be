/* mpi.c - the MPI backend: P ranks (mpirun -np P), each optionally with T
 * OpenMP threads (--threads T: hybrid), all running the shared tile loop of
 * cpu_tiles.h.
 *
 *   --mpi-schedule rows     the report's scheme: rank r renders a contiguous
 *                           block of rows (the first H % P ranks one extra),
 *                           then one MPI_Gatherv of float RGB to rank 0.
 *   --mpi-schedule dynamic  (default) the load-balanced scheme: tiles are
 *                           claimed from a shared counter with MPI-3
 *                           MPI_Fetch_and_op, and each finished tile is
 *                           MPI_Put straight into rank 0's image, so the image
 *                           is complete when the last tile lands: no second
 *                           gather. Rank 0 renders like every other rank; it
 *                           never has to answer requests, because the
 *                           counter and the image live in an MPI window
 *                           (one-sided: on one node Open MPI's osc/sm turns
 *                           both into plain shared-memory atomics and copies).
 *
 * Scene: every rank parses the file (--mpi-scene every, as the report) or
 * rank 0 parses and broadcasts the flat arrays (--mpi-scene bcast); see
 * docs/cpu-backends.md for the measurement behind the default.
 *
 * Errors: every MPI call goes through RT_MPI_CHECK (file, line, MPI's error
 * string, then MPI_Abort, which ends all ranks: never a hang). Failures
 * before rendering are agreed on with MPI_Allreduce (rt_mpi_agree) so that
 * exactly one rank, rank 0, prints exactly one message. */
#include <mpi.h>
#include <stdio.h>
#include <stdlib.h>
#include <unistd.h>
#include <string.h>

#include "config.h"
#include "cpu_tiles.h"
#include "mpi_common.h"
#include "rt.h"

/* rank 0 parses and broadcasts: it wins at 16 ranks and on clusters, where P
 * ranks would otherwise read one file from a shared file system; at 2-4
 * ranks "every" is slightly faster (docs/cpu-backends.md). */
#define RT_MPI_SCENE_DEFAULT "bcast"
#define RT_MPI_TILE 16
enum { RT_TAG_ERROR = 1 };

int rt_mpi_rank, rt_mpi_size = 1;
int rt_mpi_local_rank, rt_mpi_local_size = 1, rt_mpi_node, rt_mpi_nodes = 1;
MPI_Comm rt_mpi_node_comm = MPI_COMM_NULL;
static int g_inited, g_provided;
static double g_load_ms;                      /* this rank's time in mpi_scene_load */
static const char *g_scene_how = "every";     /* how the scene reached the ranks (every when P = 1) */

/* Where one rank's frame went (the record's rank_* keys), from the barrier
 * that starts it. */
enum {
    T_CLAIMS,   /* claims made (dynamic) */
    T_CLAIM_MS, /* in claims */
    T_PUT_MS,   /* in puts (dynamic, across nodes) */
    T_WORK_MS,  /* to the end of its last tile */
    T_END_MS,   /* to the image complete on rank 0: the frame's end (dynamic) or the gather (rows) */
    T_N
};
typedef struct RankTimes {
    double t[T_N];
} RankTimes;

void rt_mpi_die(const char *file, int line, const char *call, int code)
{
    char s[MPI_MAX_ERROR_STRING];
    int n = 0;
    if (MPI_Error_string(code, s, &n) != MPI_SUCCESS)
        snprintf(s, sizeof s, "error %d", code);
    fprintf(stderr, "raytrace: rank %d: %s:%d: %s failed: %s\n", rt_mpi_rank, file, line, call, s);
    fflush(stderr);
    MPI_Abort(MPI_COMM_WORLD, 1);
}

int rt_mpi_init(int *argc, char ***argv, RtError *err)
{
    /* FUNNELED: OpenMP threads render, only the main thread calls MPI. */
    if (MPI_Init_thread(argc, argv, MPI_THREAD_FUNNELED, &g_provided) != MPI_SUCCESS)
        return rt_fail(err, "MPI_Init_thread failed");
    g_inited = 1;
    MPI_Comm_set_errhandler(MPI_COMM_WORLD, MPI_ERRORS_RETURN);
    RT_MPI_CHECK(MPI_Comm_rank(MPI_COMM_WORLD, &rt_mpi_rank));
    RT_MPI_CHECK(MPI_Comm_size(MPI_COMM_WORLD, &rt_mpi_size));
    /* The ranks of this node (what the launcher calls a node: MPI_COMM_TYPE_SHARED)
     * and the node's number: the order of the nodes' lowest ranks. */
    RT_MPI_CHECK(MPI_Comm_split_type(MPI_COMM_WORLD, MPI_COMM_TYPE_SHARED, 0, MPI_INFO_NULL, &rt_mpi_node_comm));
    RT_MPI_CHECK(MPI_Comm_rank(rt_mpi_node_comm, &rt_mpi_local_rank));
    RT_MPI_CHECK(MPI_Comm_size(rt_mpi_node_comm, &rt_mpi_local_size));
    int leader = rt_mpi_local_rank == 0, before = 0;
    RT_MPI_CHECK(MPI_Allreduce(&leader, &rt_mpi_nodes, 1, MPI_INT, MPI_SUM, MPI_COMM_WORLD));
    RT_MPI_CHECK(MPI_Exscan(&leader, &before, 1, MPI_INT, MPI_SUM, MPI_COMM_WORLD));
    rt_mpi_node = rt_mpi_rank == 0 ? 0 : before; /* (Exscan leaves rank 0's undefined) */
    RT_MPI_CHECK(MPI_Bcast(&rt_mpi_node, 1, MPI_INT, 0, rt_mpi_node_comm));
    return 0;
}

void rt_mpi_finalize(void)
{
    if (!g_inited)
        return;
    g_inited = 0;
    if (rt_mpi_node_comm != MPI_COMM_NULL)
        MPI_Comm_free(&rt_mpi_node_comm);
    /* After an agreed failure every rank is alive and knows it, and rank 0
     * has printed the one message (main.c): all ranks finalize together and
     * exit 1. MPI_Abort would return from mpirun faster, but Open MPI 4.1's
     * PMIx thread sometimes crashes during the abort (exit 139 and a
     * backtrace instead of one line). */
    fflush(stdout);
    fflush(stderr);
    MPI_Finalize();
}

static int mpi_is_root(void) { return rt_mpi_rank == 0; }

int rt_mpi_agree(int failed, RtError *err)
{
    int mine = failed ? rt_mpi_rank : rt_mpi_size, first;
    RT_MPI_CHECK(MPI_Allreduce(&mine, &first, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD));
    if (first == rt_mpi_size)
        return 0;
    if (first != 0) { /* the lowest failing rank tells rank 0 what went wrong */
        if (rt_mpi_rank == first) {
            err->msg[sizeof err->msg - 1] = '\0';
            RT_MPI_CHECK(MPI_Send(err->msg, (int)sizeof err->msg, MPI_CHAR, 0, RT_TAG_ERROR, MPI_COMM_WORLD));
        } else if (rt_mpi_rank == 0) {
            char msg[sizeof err->msg];
            RT_MPI_CHECK(MPI_Recv(msg, (int)sizeof msg, MPI_CHAR, first, RT_TAG_ERROR, MPI_COMM_WORLD,
                                  MPI_STATUS_IGNORE));
            msg[sizeof msg - 1] = '\0';
            rt_fail(err, "rank %d: %.1000s", first, msg);
        }
    }
    return 1;
}

int rt_mpi_test_rank(const char *var)
{
#if RT_TEST_HOOKS
    const char *v = getenv(var);
    return v && *v && atoi(v) == rt_mpi_rank;
#else
    (void)var;
    return 0;
#endif
}

/* Test hook: the window of separate memory (MPI_Fetch_and_op claims and
 * MPI_Put tiles, as across nodes) on one node: tests/cpu/mpi_fail.sh. */
static int test_separate(void)
{
#if RT_TEST_HOOKS
    const char *v = getenv("RT_MPI_TEST_SEPARATE");
    return v && *v == '1';
#else
    return 0;
#endif
}

void rt_mpi_rank_nodes(char *buf, size_t size)
{
    int *all = rt_mpi_rank == 0 ? malloc(sizeof *all * (size_t)rt_mpi_size) : NULL;
    if (rt_mpi_rank == 0 && !all)
        rt_mpi_die(__FILE__, __LINE__, "malloc", MPI_ERR_NO_MEM);
    RT_MPI_CHECK(MPI_Gather(&rt_mpi_node, 1, MPI_INT, all, 1, MPI_INT, 0, MPI_COMM_WORLD));
    if (rt_mpi_rank != 0)
        return;
    size_t len = 0;
    buf[0] = '\0';
    for (int r = 0; r < rt_mpi_size && len < size; r++)
        len += (size_t)snprintf(buf + len, size - len, "%s%d", r ? "/" : "", all[r]);
    free(all);
}

/* Broadcasts n bytes in pieces below INT_MAX (MPI counts are int). */
static void bcast_bytes(void *p, size_t n)
{
    const size_t piece = (size_t)1 << 30;
    for (size_t off = 0; off < n; off += piece) {
        size_t k = n - off < piece ? n - off : piece;
        RT_MPI_CHECK(MPI_Bcast((char *)p + off, (int)k, MPI_BYTE, 0, MPI_COMM_WORLD));
    }
}

static int mpi_same(const uint8_t digest[16], RtError *err)
{
    uint8_t root[16];
    memcpy(root, digest, 16);
    RT_MPI_CHECK(MPI_Bcast(root, 16, MPI_BYTE, 0, MPI_COMM_WORLD));
    const int differs = memcmp(root, digest, 16) != 0;
    if (differs)
        rt_fail(err, "the scene this rank read differs from rank 0's (its files changed between the ranks' reads, "
                     "or the ranks see different files)");
    return rt_mpi_agree(differs, err);
}

/* The dependency list from rank 0 (the receivers' pointers were rank 0's). */
static int bcast_deps(RtScene *scene, RtError *err)
{
    char *blob = NULL;
    size_t len = 0;
    int bad = rt_mpi_rank == 0 && rt_scene_deps_pack(scene, &blob, &len) != 0;
    unsigned long long n = len;
    RT_MPI_CHECK(MPI_Bcast(&n, 1, MPI_UNSIGNED_LONG_LONG, 0, MPI_COMM_WORLD));
    if (rt_mpi_rank != 0) {
        scene->deps = NULL, scene->ndeps = 0;
        bad = !(blob = malloc(n ? (size_t)n : 1));
    }
    int any = 0;
    RT_MPI_CHECK(MPI_Allreduce(&bad, &any, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD));
    if (!any) {
        bcast_bytes(blob, (size_t)n);
        if (rt_mpi_rank != 0)
            any = rt_scene_deps_unpack(scene, blob, (size_t)n, err) != 0;
    }
    free(blob);
    return any ? rt_fail(err, "out of memory for the scene's file list") : 0;
}

static int scene_load_bcast(const char *path, RtScene *scene, RtWarnFn warn, void *warn_ctx, RtError *err)
{
    int st = 0;
    if (rt_mpi_rank == 0)
        st = rt_scene_load(path, scene, warn, warn_ctx, err);
    RT_MPI_CHECK(MPI_Bcast(&st, 1, MPI_INT, 0, MPI_COMM_WORLD));
    if (st != 0) /* rank 0 has the parser's message and will print it */
        return rt_mpi_rank == 0 ? -1 : rt_fail(err, "%s: rank 0 could not load the scene", path);
    /* The struct first (counts, camera, names), then the six flat arrays;
     * receivers replace rank 0's pointers by their own copies. */
    bcast_bytes(scene, sizeof *scene);
    if (rt_mpi_rank != 0)
        scene->deps = NULL, scene->ndeps = 0; /* (rank 0's pointers: bcast_deps sends the list) */
    struct { void **p; uint32_t n, *cap; size_t size; } a[] = {
        {(void **)&scene->vertices, scene->nvertices, &scene->cap_vertices, sizeof *scene->vertices},
        {(void **)&scene->normals, scene->nnormals, &scene->cap_normals, sizeof *scene->normals},
        {(void **)&scene->spheres, scene->nspheres, &scene->cap_spheres, sizeof *scene->spheres},
        {(void **)&scene->triangles, scene->ntriangles, &scene->cap_triangles, sizeof *scene->triangles},
        {(void **)&scene->materials, scene->nmaterials, &scene->cap_materials, sizeof *scene->materials},
        {(void **)&scene->lights, scene->nlights, &scene->cap_lights, sizeof *scene->lights},
    };
    const int na = (int)(sizeof a / sizeof a[0]);
    int nomem = 0;
    if (rt_mpi_rank != 0)
        for (int i = 0; i < na; i++) {
            *a[i].p = malloc(a[i].n ? (size_t)a[i].n * a[i].size : 1);
            *a[i].cap = a[i].n;
            nomem |= *a[i].p == NULL;
        }
    int any = 0;
    RT_MPI_CHECK(MPI_Allreduce(&nomem, &any, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD));
    if (any)
        return rt_fail(err, "%s: out of memory for the broadcast scene", path);
    for (int i = 0; i < na; i++)
        bcast_bytes(*a[i].p, (size_t)a[i].n * a[i].size);
    return bcast_deps(scene, err);
}

static int mpi_scene_load(const char *path, const char *how, RtScene *scene, RtWarnFn warn, void *warn_ctx,
                          RtError *err)
{
    double t0 = rt_now_ms();
    int bcast = strcmp(how ? how : RT_MPI_SCENE_DEFAULT, "bcast") == 0 && rt_mpi_size > 1;
    g_scene_how = bcast ? "bcast" : "every";
    int rc = bcast ? scene_load_bcast(path, scene, warn, warn_ctx, err) : rt_scene_load(path, scene, warn, warn_ctx, err);
    g_load_ms = rt_now_ms() - t0;
    return rc;
}

/* ---------------------------------------------------------------- rows */

static void render_rows(const RtRenderJob *job, RtCpuPool *pool, int tw, int th, float *rgb, RankTimes *rt)
{
    const RtSceneView *v = &job->view;
    int w = v->cam.width, h = v->cam.height, P = rt_mpi_size;
    int base = h / P, rem = h % P;
    int *counts = malloc(2 * sizeof(int) * (size_t)P);
    if (!counts)
        rt_mpi_die(__FILE__, __LINE__, "malloc", MPI_ERR_NO_MEM);
    int *displs = counts + P;
    for (int r = 0; r < P; r++) {
        int y0 = r * base + (r < rem ? r : rem), rows = base + (r < rem);
        counts[r] = rows * w * 3; /* <= 3 * 2^28 floats: fits an int */
        displs[r] = y0 * w * 3;
    }
    int y0 = displs[rt_mpi_rank] / (w * 3), y1 = y0 + counts[rt_mpi_rank] / (w * 3);
    RT_MPI_CHECK(MPI_Barrier(MPI_COMM_WORLD));
    const double t0 = rt_now_ms();
    if (y1 > y0) {
        if (job->schedule == RT_SCHED_PIXELS)
            rt_cpu_render_pixels(pool, v, 0, y0, w, y1, rgb);
        else
            rt_cpu_render_tiles(pool, v, 0, y0, w, y1, tw, th, 0, rt_tile_count(w, y1 - y0, tw, th), rgb, NULL, NULL);
    }
    rt->t[T_WORK_MS] = rt_now_ms() - t0;
    if (rt_mpi_rank == 0)
        RT_MPI_CHECK(MPI_Gatherv(MPI_IN_PLACE, 0, MPI_FLOAT, rgb, counts, displs, MPI_FLOAT, 0, MPI_COMM_WORLD));
    else
        RT_MPI_CHECK(MPI_Gatherv(rgb + displs[rt_mpi_rank], counts[rt_mpi_rank], MPI_FLOAT, NULL, NULL, NULL, MPI_FLOAT, 0,
                                 MPI_COMM_WORLD));
    rt->t[T_END_MS] = rt_now_ms() - t0;
    free(counts);
}

/* ---------------------------------------------------------------- dynamic */

/* Window layout on rank 0 (disp_unit 1): the claim counter, then the image,
 * a 128-byte line pair later (the adjacent-line prefetcher's pair), so that
 * claims never contend with the pixels written beside them. */
#define RT_WIN_IMAGE 128 /* byte offset of the image */

void rt_mpi_image_open(RtMpiImage *m, size_t bytes, const void *init, int shared)
{
    memset(m, 0, sizeof *m);
    m->bytes = bytes;
    shared = shared && rt_mpi_size > 1;
    MPI_Aint size = rt_mpi_rank == 0 ? (MPI_Aint)(RT_WIN_IMAGE + bytes) : 0;
    if (shared)
        RT_MPI_CHECK(MPI_Win_allocate_shared(size, 1, MPI_INFO_NULL, MPI_COMM_WORLD, &m->base, &m->win));
    else
        RT_MPI_CHECK(MPI_Win_allocate(size, 1, MPI_INFO_NULL, MPI_COMM_WORLD, &m->base, &m->win));
    MPI_Win_set_errhandler(m->win, MPI_ERRORS_RETURN);
    int *model = NULL, flag = 0;
    RT_MPI_CHECK(MPI_Win_get_attr(m->win, MPI_WIN_MODEL, &model, &flag));
    /* In the unified memory model (osc/sm, osc/rdma) rank 0 can render into
     * the window directly; in the separate model it MPI_Puts to itself. */
    m->direct = rt_mpi_rank == 0 && flag && *model == MPI_WIN_UNIFIED;
    if (shared) { /* rank 0's segment, mapped here */
        MPI_Aint seg;
        int disp;
        RT_MPI_CHECK(MPI_Win_shared_query(m->win, 0, &seg, &disp, &m->base));
        m->direct = 1;
        m->atomic = 1;
    }
    m->img0 = (char *)m->base + RT_WIN_IMAGE;
    if (rt_mpi_rank == 0) {
        if (init)
            memcpy(m->img0, init, bytes); /* e.g. main's NaN poison, for --verify */
        else
            memset(m->img0, 0, bytes);
    }
    RT_MPI_CHECK(MPI_Win_lock_all(MPI_MODE_NOCHECK, m->win));
}

void rt_mpi_frame_start(RtMpiImage *m)
{
    if (rt_mpi_rank == 0)
        *(int64_t *)m->base = 0;
    RT_MPI_CHECK(MPI_Win_sync(m->win));
    RT_MPI_CHECK(MPI_Barrier(MPI_COMM_WORLD));
}

/* The counter now, and the counter before adding n to it. Nothing is
 * published through the counter: relaxed atomics. (A look and an add rather
 * than a compare-and-swap: Open MPI 4.1's osc/rdma crashes in
 * MPI_Compare_and_swap on one node.) */
static int64_t counter_add(RtMpiImage *m, int64_t n)
{
    int64_t was;
    if (m->atomic)
        return n ? __atomic_fetch_add((int64_t *)m->base, n, __ATOMIC_RELAXED)
                 : __atomic_load_n((int64_t *)m->base, __ATOMIC_RELAXED);
    RT_MPI_CHECK(MPI_Fetch_and_op(&n, &was, MPI_INT64_T, 0, 0, n ? MPI_SUM : MPI_NO_OP, m->win));
    RT_MPI_CHECK(MPI_Win_flush(0, m->win));
    return was;
}

int64_t rt_mpi_claim(RtMpiImage *m, int64_t total, int64_t min_claim, int64_t *first)
{
    /* The claim is sized from a look at the counter just before it is
     * added, never from this rank's last claim: a rank that last looked
     * early would otherwise take a large claim at the end of the frame and
     * finish last. */
    int64_t now = counter_add(m, 0), claim = (total - now) / (4 * (int64_t)rt_mpi_size);
    claim = claim < min_claim ? min_claim : claim;
    *first = now >= total ? now : counter_add(m, claim);
    if (*first >= total)
        return 0;
    return total - *first < claim ? total - *first : claim;
}

void rt_mpi_put_runs(RtMpiImage *m, const void *src, size_t off, size_t width, size_t pitch, size_t count)
{
    if (count == 0 || width == 0)
        return;
    MPI_Datatype t;
    RT_MPI_CHECK(MPI_Type_vector((int)count, (int)width, (int)pitch, MPI_BYTE, &t));
    RT_MPI_CHECK(MPI_Type_commit(&t));
    RT_MPI_CHECK(MPI_Put((const char *)src + off, 1, t, 0, (MPI_Aint)(RT_WIN_IMAGE + off), 1, t, m->win));
    MPI_Type_free(&t);
}

void rt_mpi_frame_end(RtMpiImage *m)
{
    RT_MPI_CHECK(MPI_Win_flush(0, m->win));    /* this rank's puts are in rank 0's memory, */
    RT_MPI_CHECK(MPI_Win_sync(m->win));        /* and its direct stores visible */
    RT_MPI_CHECK(MPI_Barrier(MPI_COMM_WORLD)); /* ... and everyone's */
    if (rt_mpi_rank == 0)
        RT_MPI_CHECK(MPI_Win_sync(m->win));
}

void rt_mpi_image_close(RtMpiImage *m, void *out)
{
    if (rt_mpi_rank == 0)
        memcpy(out, m->img0, m->bytes);
    RT_MPI_CHECK(MPI_Win_unlock_all(m->win));
    RT_MPI_CHECK(MPI_Win_free(&m->win));
}

typedef struct TileTypes {
    int n;
    int cw[4], ch[4];      /* a full-image tiling has at most 4 tile shapes */
    MPI_Datatype t[4];
} TileTypes;

/* A tile is ch rows of cw RGB pixels, one image row apart. */
static MPI_Datatype tile_type(TileTypes *tt, int cw, int ch, int w)
{
    for (int i = 0; i < tt->n; i++)
        if (tt->cw[i] == cw && tt->ch[i] == ch)
            return tt->t[i];
    int i = tt->n++;
    tt->cw[i] = cw;
    tt->ch[i] = ch;
    RT_MPI_CHECK(MPI_Type_vector(ch, cw * 3, w * 3, MPI_FLOAT, &tt->t[i]));
    RT_MPI_CHECK(MPI_Type_commit(&tt->t[i]));
    return tt->t[i];
}

/* The smallest claim: one tile for a single-threaded rank (finest balance at
 * the end of the frame). With T threads per rank, 4*T tiles, so the rank's
 * threads share out a batch dynamically and the batch's last tile does not
 * leave them idle for long. Earlier claims are larger (rt_mpi_claim). */
static int64_t tiles_per_claim(int threads) { return threads > 1 ? 4 * (int64_t)threads : 1; }

/* One rank's frame: claim, render, put, until no tile is left. On one node
 * (every rank in rank 0's shared memory) a claim is one CPU atomic and the
 * pixels go straight into rank 0's image; across nodes a claim is an
 * MPI_Fetch_and_op and each tile an MPI_Put. The frame ends when every
 * rank's pixels are in rank 0's image; the copy into main's buffer after it
 * is not part of the frame. */
static void render_dynamic(const RtRenderJob *job, RtCpuPool *pool, int tw, int th, float *rgb, RankTimes *rt)
{
    const RtSceneView *v = &job->view;
    int w = v->cam.width, h = v->cam.height;
    int64_t ntiles = rt_tile_count(w, h, tw, th);
    RtMpiImage m;
    rt_mpi_image_open(&m, (size_t)w * (size_t)h * 3 * sizeof(float), rgb, rt_mpi_local_size == rt_mpi_size && !test_separate());
    rt_mpi_frame_start(&m);
    const double t0 = rt_now_ms();

    float *dst = m.direct ? (float *)m.img0 : rgb;
    const int64_t min_claim = tiles_per_claim(pool->nthreads);
    int64_t first, count;
    TileTypes tt;
    tt.n = 0;
    /* Which rank renders a tile never changes the image. */
    for (;;) {
        double t = rt_now_ms();
        count = rt_mpi_claim(&m, ntiles, min_claim, &first);
        rt->t[T_CLAIM_MS] += rt_now_ms() - t;
        if (count <= 0)
            break;
        rt->t[T_CLAIMS]++;
        rt_cpu_render_tiles(pool, v, 0, 0, w, h, tw, th, (int)first, (int)count, dst, NULL, NULL);
        if (m.direct)
            continue;
        t = rt_now_ms();
        for (int k = (int)first; k < first + count; k++) {
            int x0, y0, x1, y1;
            rt_tile_rect(w, h, tw, th, k, &x0, &y0, &x1, &y1);
            MPI_Datatype ty = tile_type(&tt, x1 - x0, y1 - y0, w);
            size_t off = ((size_t)y0 * (size_t)w + (size_t)x0) * 3;
            RT_MPI_CHECK(MPI_Put(rgb + off, 1, ty, 0, (MPI_Aint)(RT_WIN_IMAGE + off * sizeof(float)), 1, ty, m.win));
        }
        rt->t[T_PUT_MS] += rt_now_ms() - t;
    }
    rt->t[T_WORK_MS] = rt_now_ms() - t0;
    rt_mpi_frame_end(&m);
    rt->t[T_END_MS] = rt_now_ms() - t0;
    rt_mpi_image_close(&m, rgb);
    for (int i = 0; i < tt.n; i++)
        MPI_Type_free(&tt.t[i]);
}

/* Appends " key=v0/v1/..." of time `f` of every rank. */
static size_t rank_key(char *buf, size_t size, size_t len, const char *key, const RankTimes *all, int f,
                       const char *fmt)
{
    if (len < size)
        len += (size_t)snprintf(buf + len, size - len, " %s=", key);
    for (int r = 0; r < rt_mpi_size && len < size; r++) {
        len += (size_t)snprintf(buf + len, size - len, "%s", r ? "/" : "");
        if (len < size)
            len += (size_t)snprintf(buf + len, size - len, fmt, all[r].t[f]);
    }
    return len;
}

/* The per-rank keys (collective; rank 0 gets them in buf). */
static void rank_keys(const RankTimes *mine, int dynamic, char *e, size_t size)
{
    RankTimes *all = rt_mpi_rank == 0 ? malloc(sizeof *all * (size_t)rt_mpi_size) : NULL;
    if (rt_mpi_rank == 0 && !all)
        rt_mpi_die(__FILE__, __LINE__, "malloc", MPI_ERR_NO_MEM);
    RT_MPI_CHECK(MPI_Gather(mine->t, T_N, MPI_DOUBLE, all, T_N, MPI_DOUBLE, 0, MPI_COMM_WORLD));
    if (rt_mpi_rank != 0)
        return;
    size_t len = 0;
    e[0] = '\0';
    if (dynamic) {
        len = rank_key(e, size, len, "rank_claims", all, T_CLAIMS, "%.0f");
        len = rank_key(e, size, len, "rank_claim_ms", all, T_CLAIM_MS, "%.3f");
        len = rank_key(e, size, len, "rank_put_ms", all, T_PUT_MS, "%.3f");
    }
    len = rank_key(e, size, len, "rank_work_ms", all, T_WORK_MS, "%.3f");
    rank_key(e, size, len, "rank_end_ms", all, T_END_MS, "%.3f");
    free(all);
}

/* ---------------------------------------------------------------- render */

static int render_mpi(const RtRenderJob *job, RtRenderOut *out, RtError *err)
{
    int tw = job->tile_w > 0 ? job->tile_w : RT_MPI_TILE, th = job->tile_h > 0 ? job->tile_h : RT_MPI_TILE;
    /* threads per rank: --threads, else OMP_NUM_THREADS, else 1 (pure MPI, as the report) */
    int threads = rt_cpu_threads(job->threads, 1);
    int failed = 0;
    RtCpuPool pool;
    pool.mem = NULL;
    if (threads > 1 && g_provided < MPI_THREAD_FUNNELED)
        failed = rt_fail(err, "--threads %d needs MPI_THREAD_FUNNELED, this MPI library provides level %d", threads,
                         g_provided) != 0;
    else if (rt_cpu_pool_init(&pool, threads, err) != 0)
        failed = 1;
    /* only in tests/cpu's raytrace-testhooks (mpi_fail.sh): an error on one
     * rank only */
    if (!failed && rt_mpi_test_rank("RT_MPI_TEST_FAIL_RANK"))
        failed = rt_fail(err, "injected failure (RT_MPI_TEST_FAIL_RANK=%d)", rt_mpi_rank) != 0;
    /* A rank that cannot render must not leave the others in a collective. */
    if (rt_mpi_agree(failed, err) != 0) {
        rt_cpu_pool_free(&pool);
        return -1;
    }

    RankTimes times;
    memset(&times, 0, sizeof times);
    const int dynamic = job->mpi_schedule != RT_MPI_ROWS;
    if (dynamic)
        render_dynamic(job, &pool, tw, th, out->rgb, &times);
    else
        render_rows(job, &pool, tw, th, out->rgb, &times);
    /* render_ms: the slowest rank's time to the image complete on rank 0;
     * render_ms_min: the earliest a rank ran out of work (the imbalance) */
    double ms = times.t[T_END_MS], work = times.t[T_WORK_MS];

    RtCounters mine, sum;
    char cores[sizeof out->cores];
    cores[0] = '\0';
    rt_cpu_pool_merge(&pool, &mine, cores, sizeof cores);
    rt_cpu_pool_free(&pool);
    _Static_assert(sizeof(RtCounters) == 5 * sizeof(uint64_t), "RtCounters is reduced as 5 uint64");
    RT_MPI_CHECK(MPI_Reduce(&mine, &sum, 5, MPI_UINT64_T, MPI_SUM, 0, MPI_COMM_WORLD));
    double ms_max, ms_min, load_max;
    RT_MPI_CHECK(MPI_Reduce(&ms, &ms_max, 1, MPI_DOUBLE, MPI_MAX, 0, MPI_COMM_WORLD));
    RT_MPI_CHECK(MPI_Reduce(&work, &ms_min, 1, MPI_DOUBLE, MPI_MIN, 0, MPI_COMM_WORLD));
    RT_MPI_CHECK(MPI_Reduce(&g_load_ms, &load_max, 1, MPI_DOUBLE, MPI_MAX, 0, MPI_COMM_WORLD));
    char *all = rt_mpi_rank == 0 ? malloc(sizeof cores * (size_t)rt_mpi_size) : NULL;
    if (rt_mpi_rank == 0 && !all)
        rt_mpi_die(__FILE__, __LINE__, "malloc", MPI_ERR_NO_MEM);
    RT_MPI_CHECK(MPI_Gather(cores, (int)sizeof cores, MPI_CHAR, all, (int)sizeof cores, MPI_CHAR, 0, MPI_COMM_WORLD));
    char nodes[1024];
    rt_mpi_rank_nodes(nodes, sizeof nodes);
    char keys[sizeof out->extra / 2];
    rank_keys(&times, dynamic, keys, sizeof keys);

    out->threads_used = threads;
    out->ranks_used = rt_mpi_size;
    out->is_root = rt_mpi_rank == 0;
    if (rt_mpi_rank != 0)
        return 0;
    out->counters = sum;
    out->render_ms = ms_max;
    out->render_ms_min = ms_min;
    /* cores: the union (the harness's pinning check); rank_cores: per rank,
     * ranks separated by '/', e.g. 0/1 or 0,1/2,3 for 2 ranks x 2 threads */
    char per_rank[4096];
    size_t len = 0;
    per_rank[0] = '\0';
    out->cores[0] = '\0';
    for (int r = 0; r < rt_mpi_size; r++) {
        const char *c = all + (size_t)r * sizeof cores;
        for (const char *p = c; *p;) {
            rt_cores_note(out->cores, sizeof out->cores, atoi(p));
            p = strchr(p, ',');
            p = p ? p + 1 : "";
        }
        if (len < sizeof per_rank)
            len += (size_t)snprintf(per_rank + len, sizeof per_rank - len, "%s%s", r ? "/" : "", c);
    }
    free(all);
    snprintf(out->extra, sizeof out->extra,
             " mpi_schedule=%s schedule=%s mpi_scene=%s load_ms_max=%.3f tiles_per_claim=%lld"
             " rank_cores=%s nodes=%d rank_node=%s%s",
             job->mpi_schedule == RT_MPI_ROWS ? "rows" : "dynamic",
             job->schedule == RT_SCHED_PIXELS ? "pixels" : "tiles",
             g_scene_how, load_max,
             (long long)tiles_per_claim(threads), per_rank, rt_mpi_nodes, nodes, keys);
    if (job->progress)
        job->progress(job->progress_ctx, 1, 1);
    return 0;
}

const RtCollective rt_mpi_collective = {mpi_is_root, rt_mpi_agree, mpi_scene_load, mpi_same};

const RtBackend rt_backend_mpi = {"mpi", NULL, rt_mpi_init, render_mpi, rt_mpi_finalize, &rt_mpi_collective, 0, NULL, 0};
