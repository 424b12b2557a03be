/* mpi.c - the MPI backend: P ranks (mpirun -np P), each optionally with T
 * OpenMP threads (--threads T: hybrid), all running the shared tile loop of
 * cpu_tiles.h.
 *
 *   --mpi-schedule rows     the report's scheme: rank r renders a contiguous
 *                           block of rows (the first H % P ranks one extra),
 *                           then one MPI_Gatherv of float RGB to rank 0.
 *   --mpi-schedule dynamic  (default) the load-balanced scheme: strips (rows
 *                           of tiles, cpu_tiles.h) are claimed from a shared
 *                           counter with MPI-3 MPI_Fetch_and_op, and each
 *                           claim's pixels are MPI_Put straight into rank 0's
 *                           image, so the image is complete when the last
 *                           strip lands: no second gather. Rank 0 renders
 *                           like every other rank; it never has to answer
 *                           requests, because the counter and the image live
 *                           in an MPI window (one-sided: on one node a shared
 *                           window, where both are plain shared-memory
 *                           atomics and stores). On one node the window also
 *                           holds the strips' board, so ranks back up each
 *                           other's strips once the counter is spent.
 *
 * Start and end, the scene on every rank, agreeing on failures and the
 * shared image's window and claims are mpi_common.c's, shared with
 * mpi_cuda.c. */
#include <mpi.h>
#include <stdio.h>
#include <sys/resource.h>
#include <stdlib.h>
#include <unistd.h>
#include <string.h>

#include "config.h"
#include "cpu_tiles.h"
#include "mpi_common.h"
#include "rt.h"

#define RT_MPI_TILE 16

/* Where one rank's frame went (the record's rank_* keys), from the barrier
 * that starts it. */
enum {
    T_CLAIMS,   /* claims made (dynamic) */
    T_CLAIM_MS, /* in claims */
    T_PUT_MS,   /* in puts (dynamic, across nodes) */
    T_WORK_MS,  /* to the end of its last tile */
    T_END_MS,   /* to the image complete on rank 0: the frame's end (dynamic) or the gather (rows) */
    T_START_MS, /* started after the first rank did */
    T_FAULTS,   /* page faults (minor) from the start to the end of the frame */
    T_FORK_MS,  /* from the barrier to its team's first thread in the tile loop (dynamic, one node) */
    T_N
};
typedef struct RankTimes {
    double t[T_N];
    int64_t t0_ns;      /* when this rank started: left the starting barrier, or (dynamic, one node) its
                         * team's first thread entered the tile loop */
    int64_t end_ns;     /* when the last tile reached rank 0's image (shared board), else 0 */
    uint64_t backups[2]; /* second renders started, won */
} RankTimes;

/* This process's minor page faults so far. */
static double minor_faults(void)
{
    struct rusage u;
    return getrusage(RUSAGE_SELF, &u) == 0 ? (double)u.ru_minflt : 0;
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

/* Whether each of this rank's threads has a CPU of its own: no other rank
 * of the node may run on its CPUs, and its team has a CPU per thread (the
 * tile loop's rescue pass, cpu_tiles.h). */
static int own_cores(const RtCpuPool *pool) { return !rt_mpi_shares_core && pool->nthreads <= pool->cpus; }

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
    /* the rank's strips, backed up among its own threads */
    const int64_t nstrips = y1 > y0 ? rt_strip_count(w, y1 - y0, tw, th) : 0;
    /* + 1: never calloc(0), which may be NULL */
    uint32_t *state = calloc((size_t)(y1 > y0 ? rt_board_words(w, y1 - y0, tw, th) : 0) + 1, sizeof *state);
    if (!state)
        rt_mpi_die(__FILE__, __LINE__, "malloc", MPI_ERR_NO_MEM);
    int64_t done = 0, end_ns = 0;
    RtTileBoard board = {state, &done, &end_ns, y1 > y0 ? rt_strip_total(w, y1 - y0, tw) : 0};
    RtTileRun run = {.v = v, .ry0 = y0, .rx1 = w, .ry1 = y1, .tw = tw, .th = th, .count = nstrips,
                     .scan_count = nstrips, .scan_slots = 1, .rgb = rgb, .board = &board,
                     .rescue = own_cores(pool)};
    RT_MPI_CHECK(MPI_Barrier(MPI_COMM_WORLD));
    rt->t0_ns = rt_now_ns();
    const double t0 = rt_now_ms(), f0 = minor_faults();
    if (y1 > y0) {
        if (job->schedule == RT_SCHED_PIXELS)
            rt_cpu_render_pixels(pool, v, 0, y0, w, y1, rgb);
        else
            rt_cpu_render_tiles(pool, &run);
    }
    free(state);
    rt->t[T_WORK_MS] = rt_now_ms() - t0;
    if (rt_mpi_rank == 0)
        RT_MPI_CHECK(MPI_Gatherv(MPI_IN_PLACE, 0, MPI_FLOAT, rgb, counts, displs, MPI_FLOAT, 0, MPI_COMM_WORLD));
    else
        RT_MPI_CHECK(MPI_Gatherv(rgb + displs[rt_mpi_rank], counts[rt_mpi_rank], MPI_FLOAT, NULL, NULL, NULL, MPI_FLOAT, 0,
                                 MPI_COMM_WORLD));
    rt->t[T_END_MS] = rt_now_ms() - t0;
    rt->t[T_FAULTS] = minor_faults() - f0;
    free(counts);
}

/* ---------------------------------------------------------------- dynamic */

/* The smallest claim: one strip (a tile's row, cpu_tiles.h) for a
 * single-threaded rank, the finest balance at the end of the frame. With T
 * threads per rank, 4*T strips, so the rank's threads share out a batch
 * dynamically. Earlier claims are larger (rt_mpi_claim). */
static int64_t strips_per_claim(int threads) { return threads > 1 ? 4 * (int64_t)threads : 1; }

/* Puts strips [first, first + count) from rgb into rank 0's image: one
 * MPI_Put per tile they belong to (its rows, one image row apart). */
static void put_strips(RtMpiImage *m, const float *rgb, int w, int h, int tw, int th, int64_t first, int64_t count)
{
    for (int64_t s = first, e; s < first + count; s = e) {
        for (e = s + 1; e < first + count && e / th == s / th;)
            e++;
        int x0, y0, x1, y1;
        rt_tile_rect(w, h, tw, th, (int)(s / th), &x0, &y0, &x1, &y1);
        const int ya = y0 + (int)(s % th);
        int yb = y0 + (int)((e - 1) % th) + 1; /* past the last, or the tile's edge */
        yb = yb < y1 ? yb : y1;
        const size_t px = 3 * sizeof(float);
        if (ya < yb)
            rt_mpi_put_runs(m, rgb, ((size_t)ya * (size_t)w + (size_t)x0) * px, (size_t)(x1 - x0) * px,
                            (size_t)w * px, (size_t)(yb - ya));
    }
}

/* A claim of one of the rank's threads from the counter in rank 0's
 * memory (m->atomic: a CPU atomic), counted with the time it took. */
typedef struct {
    RtMpiImage *m;
    int64_t total, claims, claim_ns; /* claims, claim_ns: over the rank's threads */
    int claimers;
} ThreadClaims;

static int64_t thread_claim(void *ctx, int64_t *first)
{
    ThreadClaims *c = ctx;
    const int64_t t = rt_now_ns(), n = rt_mpi_claim(c->m, c->total, 1, c->claimers, first);
    __atomic_add_fetch(&c->claim_ns, rt_now_ns() - t, __ATOMIC_RELAXED);
    if (n > 0)
        __atomic_add_fetch(&c->claims, 1, __ATOMIC_RELAXED);
    return n;
}

/* The claims across nodes: the rank's first thread claims (MPI_Fetch_and_op),
 * the rank's threads render the claim, and its tiles go to rank 0 (one
 * MPI_Put each), until no strip is left. */
static void claims_with_puts(RtMpiImage *m, RtCpuPool *pool, RtTileRun *run, const float *rgb, int64_t nstrips,
                             RankTimes *rt)
{
    const int w = run->v->cam.width, h = run->v->cam.height;
    for (;;) {
        double t = rt_now_ms();
        run->count = rt_mpi_claim(m, nstrips, strips_per_claim(pool->nthreads), 1, &run->first);
        rt->t[T_CLAIM_MS] += rt_now_ms() - t;
        if (run->count <= 0)
            break;
        rt->t[T_CLAIMS]++;
        rt_cpu_render_tiles(pool, run);
        if (m->direct)
            continue;
        t = rt_now_ms();
        put_strips(m, rgb, w, h, run->tw, run->th, run->first, run->count);
        rt->t[T_PUT_MS] += rt_now_ms() - t;
    }
}

/* One rank's frame. With the counter in shared memory (every rank on one
 * node, or one rank) each of the rank's threads claims for itself, renders
 * into rank 0's image and then backs up strips still unfinished, all in one
 * parallel region; across nodes, claims_with_puts. The frame ends when
 * every rank's pixels are in rank 0's image; the copy into main's buffer
 * after it is not part of the frame. */
static void render_dynamic(const RtRenderJob *job, RtCpuPool *pool, int tw, int th, float *rgb, RankTimes *rt)
{
    const RtSceneView *v = &job->view;
    int w = v->cam.width, h = v->cam.height;
    const int64_t nstrips = rt_strip_count(w, h, tw, th), words = rt_board_words(w, h, tw, th);
    RtMpiImage m;
    /* Each thread's CPU, claim or no claim: a rank that gets no tile still
     * ran where it was bound (the record's cores, the harness's pinning check). */
#pragma omp parallel num_threads(pool->nthreads)
    rt_cpu_note(rt_cpu_slot(pool, rt_cpu_thread_id()));
    /* On one node the board lives in rank 0's window, after two int64s
     * (strips done, the time of the last) on a line pair of their own, so
     * ranks back up each other's strips (cpu_tiles.h); across nodes each
     * rank keeps one for its own threads. */
    const int shared = rt_mpi_local_size == rt_mpi_size && !test_separate() && rt_mpi_size > 1;
    rt_mpi_image_open(&m, (size_t)w * (size_t)h * 3 * sizeof(float), rgb, shared, shared ? 128 + 4 * (size_t)words : 0);
    uint32_t *local = shared ? NULL : calloc((size_t)words, sizeof *local);
    int64_t local_done = 0, local_end = 0;
    if (!shared && !local)
        rt_mpi_die(__FILE__, __LINE__, "malloc", MPI_ERR_NO_MEM);
    RtTileBoard board = {local, &local_done, &local_end, rt_strip_total(w, h, tw)};
    if (shared) {
        board.done = (int64_t *)m.extra;
        board.end_ns = (int64_t *)m.extra + 1;
        board.state = (uint32_t *)(void *)((char *)m.extra + 128);
    }
    RtTileRun run = {.v = v, .rx1 = w, .ry1 = h, .tw = tw, .th = th, .scan_slot = rt_mpi_rank,
                     .scan_slots = rt_mpi_size, .rgb = m.direct ? (float *)m.img0 : rgb, .board = &board,
                     .rescue = own_cores(pool)};
    ThreadClaims tc = {&m, nstrips, 0, 0, pool->nthreads};
    rt_mpi_frame_start(&m);
    rt->t0_ns = rt_now_ns();
    double t0 = rt_now_ms();
    const double f0 = minor_faults();

    /* Which rank or thread renders a strip never changes the image. */
    if (m.atomic && m.direct) {
        run.claim = thread_claim;
        run.claim_ctx = &tc;
        run.scan_count = nstrips;
        rt_cpu_render_tiles(pool, &run);
        /* The rank starts when its team's first thread does, as an OpenMP
         * frame starts (openmp.c): libgomp starts a team only once every
         * thread of the last one is back in its dock, so one thread the
         * host held delays the whole team by milliseconds (rank_fork_ms). */
        const int64_t start = rt_cpu_pool_start(pool);
        rt->t[T_FORK_MS] = (start - rt->t0_ns) * 1e-6;
        t0 += rt->t[T_FORK_MS];
        rt->t0_ns = start;
        rt->t[T_CLAIMS] = (double)tc.claims;
        rt->t[T_CLAIM_MS] = tc.claim_ns * 1e-6;
        rt->t[T_WORK_MS] = (rt_cpu_pool_end(pool) - start) * 1e-6;
    } else {
        claims_with_puts(&m, pool, &run, rgb, nstrips, rt);
        rt->t[T_WORK_MS] = rt_now_ms() - t0;
    }
    rt_mpi_frame_end(&m);
    rt->t[T_END_MS] = rt_now_ms() - t0;
    rt->t[T_FAULTS] = minor_faults() - f0;
    if (rt_mpi_rank == 0)
        rt->end_ns = shared ? *board.end_ns : rt_mpi_size == 1 ? local_end : 0;
    rt_mpi_image_close(&m, rgb);
    free(local);
}

/* Appends " key=v0/v1/..." of time `f` of every rank. */
static size_t rank_key(char *buf, size_t size, size_t len, const char *key, const double *all, int f,
                       const char *fmt)
{
    if (len < size)
        len += (size_t)snprintf(buf + len, size - len, " %s=", key);
    for (int r = 0; r < rt_mpi_size && len < size; r++) {
        len += (size_t)snprintf(buf + len, size - len, "%s", r ? "/" : "");
        if (len < size)
            len += (size_t)snprintf(buf + len, size - len, fmt, all[(size_t)r * T_N + (size_t)f]);
    }
    return len;
}

/* The per-rank keys (collective; rank 0 gets them in buf). */
static void rank_keys(const RankTimes *mine, int dynamic, char *e, size_t size)
{
    double *all = rt_mpi_rank == 0 ? malloc(sizeof *all * T_N * (size_t)rt_mpi_size) : NULL;
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
        len = rank_key(e, size, len, "rank_fork_ms", all, T_FORK_MS, "%.3f");
    }
    len = rank_key(e, size, len, "rank_start_ms", all, T_START_MS, "%.3f");
    len = rank_key(e, size, len, "rank_work_ms", all, T_WORK_MS, "%.3f");
    len = rank_key(e, size, len, "rank_end_ms", all, T_END_MS, "%.3f");
    rank_key(e, size, len, "rank_faults", all, T_FAULTS, "%.0f");
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
    if (threads > 1 && rt_mpi_thread_level < MPI_THREAD_FUNNELED)
        failed = rt_fail(err, "--threads %d needs MPI_THREAD_FUNNELED, this MPI library provides level %d", threads,
                         rt_mpi_thread_level) != 0;
    else if (rt_cpu_pool_init(&pool, threads, tw, th, job->view.cam.width, job->view.cam.height, err) != 0)
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
    uint64_t backups[2];
    rt_cpu_pool_backups(&pool, &times.backups[0], &times.backups[1]);
    rt_cpu_pool_free(&pool);
    RT_MPI_CHECK(MPI_Reduce(times.backups, backups, 2, MPI_UINT64_T, MPI_SUM, 0, MPI_COMM_WORLD));
    int64_t t0_min;
    RT_MPI_CHECK(MPI_Allreduce(&times.t0_ns, &t0_min, 1, MPI_INT64_T, MPI_MIN, MPI_COMM_WORLD));
    times.t[T_START_MS] = (double)(times.t0_ns - t0_min) * 1e-6;
    _Static_assert(sizeof(RtCounters) == 5 * sizeof(uint64_t), "RtCounters is reduced as 5 uint64");
    RT_MPI_CHECK(MPI_Reduce(&mine, &sum, 5, MPI_UINT64_T, MPI_SUM, 0, MPI_COMM_WORLD));
    double ms_max, ms_min, load_max;
    RT_MPI_CHECK(MPI_Reduce(&ms, &ms_max, 1, MPI_DOUBLE, MPI_MAX, 0, MPI_COMM_WORLD));
    RT_MPI_CHECK(MPI_Reduce(&work, &ms_min, 1, MPI_DOUBLE, MPI_MIN, 0, MPI_COMM_WORLD));
    RT_MPI_CHECK(MPI_Reduce(&rt_mpi_load_ms, &load_max, 1, MPI_DOUBLE, MPI_MAX, 0, MPI_COMM_WORLD));
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
    /* with the board (dynamic, one node): from the first rank's start to the
     * last tile in the image, one clock on one node; else to the end of the
     * slowest rank */
    out->render_ms = times.end_ns > 0 ? (times.end_ns - t0_min) * 1e-6 : ms_max;
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
             " mpi_schedule=%s schedule=%s mpi_scene=%s scene_copies=%d core_sharing_ranks=%d load_ms_max=%.3f"
             " strips_per_claim=%lld"
             " backups=%llu backups_won=%llu rank_cores=%s nodes=%d rank_node=%s%s",
             job->mpi_schedule == RT_MPI_ROWS ? "rows" : "dynamic",
             job->schedule == RT_SCHED_PIXELS ? "pixels" : "tiles",
             rt_mpi_scene_how, rt_mpi_scene_copies, rt_mpi_core_sharing_ranks, load_max,
             (long long)strips_per_claim(threads), (unsigned long long)backups[0], (unsigned long long)backups[1],
             per_rank, rt_mpi_nodes, nodes, keys);
    if (job->progress)
        job->progress(job->progress_ctx, 1, 1);
    return 0;
}

const RtBackend rt_backend_mpi = {"mpi", NULL, rt_mpi_init, render_mpi, rt_mpi_finalize, &rt_mpi_collective, 0, NULL, 0,
                                  RT_MPI_TILE, NULL, NULL};
