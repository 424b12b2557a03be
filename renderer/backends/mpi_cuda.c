/* mpi_cuda.c - the MPI backend with a GPU on each rank (--backend mpi-cuda).
 *
 * One rank per GPU: a rank's device is --device plus its rank on its node
 * (MPI_COMM_TYPE_SHARED, which is what the launcher's local rank numbers),
 * modulo the devices CUDA_VISIBLE_DEVICES leaves it. Two ranks of a node on
 * one physical GPU (the same PCI bus id) is an error unless --share-gpu lets
 * them take turns.
 *
 * Each rank opens a CUDA session (cuda_session.h: the device, the plan for
 * the whole image, the scene uploaded once). The frame is handed out as in
 * the CPU MPI backend's dynamic scheme (mpi_common.h): ranks claim bands of
 * tile rows from the counter in rank 0's window (guided, never less than the
 * rows that fill the GPU once) and render each with the CUDA kernel; a
 * band's rows are copied down while the next band renders. A band is
 * contiguous in the image: on one node every rank copies it straight into
 * rank 0's image (a shared-memory window); across nodes it is one MPI_Put.
 * docs/gpu.md, "Several GPUs". */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "config.h"
#include "cuda/cuda_session.h"
#include "mpi_common.h"
#include "rt.h"

static int g_local_rank, g_local_size = 1;
static MPI_Comm g_node = MPI_COMM_NULL; /* the ranks on this rank's node */

static int mpi_cuda_init(int *argc, char ***argv, RtError *err)
{
    if (rt_mpi_init(argc, argv, err) != 0)
        return -1;
    RT_MPI_CHECK(MPI_Comm_split_type(MPI_COMM_WORLD, MPI_COMM_TYPE_SHARED, 0, MPI_INFO_NULL, &g_node));
    RT_MPI_CHECK(MPI_Comm_rank(g_node, &g_local_rank));
    RT_MPI_CHECK(MPI_Comm_size(g_node, &g_local_size));
    return 0;
}

static void mpi_cuda_finalize(void)
{
    if (g_node != MPI_COMM_NULL)
        MPI_Comm_free(&g_node);
    rt_mpi_finalize();
}

/* (the device as pick_device will choose it) */
static void mpi_cuda_prewarm(int device) { rt_cuda_prewarm_device(device + g_local_rank, 1); }

/* This rank's device: --device + local rank, modulo the GPUs it sees (under
 * Slurm's --gpus-per-task each rank sees only its own: device 0). */
static int pick_device(const RtRenderJob *job, int *dev, char *bus, size_t size, RtError *err)
{
    int n = 0;
    if (rt_cuda_device_count(&n, err) != 0)
        return -1;
    if (job->device >= n)
        return rt_fail(err, "mpi-cuda: --device %d: this node has %d CUDA device(s), numbered 0 to %d", job->device,
                       n, n - 1);
    *dev = (job->device + g_local_rank) % n;
    return rt_cuda_device_bus(*dev, bus, size, err);
}

/* One rank per GPU: collective over the node; fails on a rank whose GPU a
 * lower local rank has too, unless --share-gpu. */
static int check_one_per_gpu(const RtRenderJob *job, const char *bus, RtError *err)
{
    enum { BUS = 32 };
    char *all = malloc((size_t)BUS * (size_t)g_local_size);
    if (!all)
        rt_mpi_die(__FILE__, __LINE__, "malloc", MPI_ERR_NO_MEM);
    char mine[BUS];
    snprintf(mine, sizeof mine, "%s", bus);
    RT_MPI_CHECK(MPI_Allgather(mine, BUS, MPI_CHAR, all, BUS, MPI_CHAR, g_node));
    int rc = 0;
    for (int q = 0; q < g_local_rank && !job->share_gpu && !rc && *mine; q++)
        if (strcmp(all + (size_t)q * BUS, mine) == 0)
            rc = rt_fail(err,
                         "mpi-cuda: local ranks %d and %d would both drive GPU %s (%d ranks on this node): one "
                         "rank per GPU, or --share-gpu to let ranks share them",
                         q, g_local_rank, mine, g_local_size);
    free(all);
    return rc;
}

/* What one rank did in a frame. */
typedef struct Share {
    double done_ms; /* from the frame's start to its last pixels in rank 0's image */
    double claim_ms, wait_ms, put_ms; /* in claims, waiting for the GPU, in puts */
    int rows;       /* tile rows rendered */
    int claims;
    int cpu;        /* the CPU the rank ran on */
} Share;

/* The bands this rank has queued and not yet put, oldest first. */
typedef struct Bands {
    int r0[RT_CUDA_BANDS], r1[RT_CUDA_BANDS];
    unsigned long long queued, put;
    int row_h, w;
} Bands;

static void die_on(int rc, const RtError *err)
{
    if (rc == 0)
        return;
    /* mid-frame the other ranks are in the claim loop: end them all */
    fprintf(stderr, "raytrace: rank %d: %s\n", rt_mpi_rank, err->msg);
    fflush(stderr);
    MPI_Abort(MPI_COMM_WORLD, 1);
}

/* The bands whose rows are down (wait: all of them) into rank 0's image:
 * already there when this rank writes it directly, else one MPI_Put each. */
static void put_ready(RtCudaSession *s, RtMpiImage *m, float *rgb, Bands *b, int wait, Share *sh, RtError *err)
{
    double t = rt_now_ms();
    const int n = rt_cuda_session_ready(s, wait, err);
    die_on(n < 0, err);
    sh->wait_ms += rt_now_ms() - t;
    t = rt_now_ms();
    for (int i = 0; i < n; i++, b->put++) {
        const unsigned k = (unsigned)(b->put % RT_CUDA_BANDS);
        if (m->direct)
            continue;
        const size_t h = m->npix / (size_t)b->w, y0 = (size_t)b->r0[k] * (size_t)b->row_h;
        const size_t y1 = (size_t)b->r1[k] * (size_t)b->row_h < h ? (size_t)b->r1[k] * (size_t)b->row_h : h;
        rt_mpi_put(m, rgb, y0 * (size_t)b->w * 3, (y1 - y0) * (size_t)b->w * 3);
    }
    sh->put_ms += rt_now_ms() - t;
}

/* One frame: claims of tile rows until none is left, each queued on the GPU
 * as soon as the previous band's kernel runs (so the GPU never waits for a
 * claim, and a rank never holds more than two unfinished bands: the claims
 * stay balanced), its rows put as they come down. Returns rank 0's time to
 * the whole image (other ranks: their own end). */
static double frame(RtCudaSession *s, RtMpiImage *m, float *rgb, int rows, int wave_rows, Bands *b, Share *sh,
                    RtError *err)
{
    float *dst = m->direct ? m->img0 : rgb;
    int64_t seen = 0, first, count;
    memset(sh, 0, sizeof *sh);
    b->queued = b->put = 0;
    die_on(rt_cuda_session_frame(s, err), err);
    rt_mpi_frame_start(m);
    const double t0 = rt_now_ms();
    for (;;) {
        double t = rt_now_ms();
        die_on(rt_cuda_session_kernels(s, 1, err), err);
        sh->wait_ms += rt_now_ms() - t;
        t = rt_now_ms();
        count = rt_mpi_claim(m, rows, wave_rows, &seen, &first);
        sh->claim_ms += rt_now_ms() - t;
        if (count == 0)
            break;
        if (b->queued - b->put == RT_CUDA_BANDS)
            put_ready(s, m, rgb, b, 1, sh, err);
        const unsigned k = (unsigned)(b->queued++ % RT_CUDA_BANDS);
        b->r0[k] = (int)first;
        b->r1[k] = (int)(first + count);
        die_on(rt_cuda_session_band(s, b->r0[k], b->r1[k], dst, err), err);
        put_ready(s, m, rgb, b, 0, sh, err);
        sh->rows += (int)count;
        sh->claims++;
    }
    put_ready(s, m, rgb, b, 1, sh, err);
    const double tf = rt_now_ms();
    RT_MPI_CHECK(MPI_Win_flush(0, m->win));
    sh->put_ms += rt_now_ms() - tf;
    sh->done_ms = rt_now_ms() - t0;
    sh->cpu = rt_current_cpu();
    rt_mpi_frame_end(m);
    return rt_now_ms() - t0;
}

/* Warm-up and timed frames as the CUDA backend times launches (rank 0
 * decides, so every rank renders the same frames). times[] gets rank 0's
 * frame times, mins[] the earliest rank's end of each. */
static void frames(const RtRenderJob *job, RtCudaSession *s, RtMpiImage *m, float *rgb, int rows, int row_h,
                   int wave_rows, double *times, double *mins, int max_runs, int *runs, int *warmups, Share *sh,
                   RtError *err)
{
    Bands *b = malloc(sizeof *b);
    if (!b)
        rt_mpi_die(__FILE__, __LINE__, "malloc", MPI_ERR_NO_MEM);
    b->row_h = row_h;
    b->w = job->view.cam.width;
    const double warm_ms = job->warmup_runs < 0 && job->warmup_ms < 0.0 ? RT_CUDA_WARMUP_MS : job->warmup_ms;
    const double t0 = rt_now_ms();
    *runs = *warmups = 0;
    for (int n = 0;; n++) {
        double ms = frame(s, m, rgb, rows, wave_rows, b, sh, err), first_end;
        RT_MPI_CHECK(MPI_Reduce(&sh->done_ms, &first_end, 1, MPI_DOUBLE, MPI_MIN, 0, MPI_COMM_WORLD));
        int next = 0; /* rank 0's answer: another frame (1) or the last (0) */
        if (rt_mpi_rank == 0) {
            const int warm = *runs == 0 && rt_warmup_due(job->warmup_runs, warm_ms, n, rt_now_ms() - t0);
            if (warm) {
                ++*warmups;
            } else {
                times[*runs] = ms;
                mins[(*runs)++] = first_end;
            }
            const int budget = job->runs <= 0 && ms * (*runs + 1) > RT_CUDA_TIME_BUDGET_MS;
            next = *runs < max_runs && !budget ? 1 : 0;
        }
        RT_MPI_CHECK(MPI_Bcast(&next, 1, MPI_INT, 0, MPI_COMM_WORLD));
        if (job->progress && rt_mpi_rank == 0)
            job->progress(job->progress_ctx, (uint64_t)(n + 1), (uint64_t)max_runs + 1);
        if (!next) {
            free(b);
            return;
        }
    }
}

/* The record's per-rank keys: its GPU, share of the tile rows, claims and
 * time to its last band in the last frame, ranks separated by '/'; and the
 * union of the ranks' CPUs (the harness's pinning check). */
static void rank_keys(RtCudaSession *s, const Share *sh, int rows, RtRenderOut *out)
{
    char gpu[64];
    snprintf(gpu, sizeof gpu, "%s", strchr(rt_cuda_session_gpu(s), '@') + 1);
    const int P = rt_mpi_size;
    char *gpus = rt_mpi_rank == 0 ? malloc(sizeof gpu * (size_t)P) : NULL;
    Share *all = rt_mpi_rank == 0 ? malloc(sizeof *all * (size_t)P) : NULL;
    if (rt_mpi_rank == 0 && (!gpus || !all))
        rt_mpi_die(__FILE__, __LINE__, "malloc", MPI_ERR_NO_MEM);
    RT_MPI_CHECK(MPI_Gather(gpu, (int)sizeof gpu, MPI_CHAR, gpus, (int)sizeof gpu, MPI_CHAR, 0, MPI_COMM_WORLD));
    RT_MPI_CHECK(MPI_Gather(sh, (int)sizeof *sh, MPI_BYTE, all, (int)sizeof *sh, MPI_BYTE, 0, MPI_COMM_WORLD));
    if (rt_mpi_rank != 0)
        return;
    char k_gpu[300] = "", k[6][160];
    size_t a = 0, len[6] = {0};
    int distinct = 0;
    for (int i = 0; i < 6; i++)
        k[i][0] = '\0';
    for (int r = 0; r < P; r++) {
        const char *g = gpus + (size_t)r * sizeof gpu;
        rt_cores_note(out->cores, sizeof out->cores, all[r].cpu);
        int seen = 0;
        for (int q = 0; q < r; q++)
            seen |= strcmp(g, gpus + (size_t)q * sizeof gpu) == 0;
        distinct += !seen;
        const char *sep = r ? "/" : "";
        if (a < sizeof k_gpu)
            a += (size_t)snprintf(k_gpu + a, sizeof k_gpu - a, "%s%s", sep, g);
        const double v[6] = {(double)all[r].rows / rows, all[r].claims, all[r].done_ms, all[r].claim_ms,
                             all[r].wait_ms, all[r].put_ms};
        for (int i = 0; i < 6; i++)
            if (len[i] < sizeof k[i])
                len[i] += (size_t)snprintf(k[i] + len[i], sizeof k[i] - len[i], i == 1 ? "%s%.0f" : "%s%.3f", sep,
                                           v[i]);
    }
    size_t n = strlen(out->extra);
    snprintf(out->extra + n, sizeof out->extra - n,
             " gpus=%d rank_gpu=%s rank_share=%s rank_claims=%s rank_end_ms=%s rank_claim_ms=%s rank_wait_ms=%s"
             " rank_put_ms=%s",
             distinct, k_gpu, k[0], k[1], k[2], k[3], k[4], k[5]);
    free(gpus);
    free(all);
}

/* Every rank's device and session, agreed on before any frame. */
static int open_all(const RtRenderJob *job, RtCudaSession **s, RtError *err)
{
    RtRenderJob mine = *job;
    char bus[32] = "";
    int failed = pick_device(job, &mine.device, bus, sizeof bus, err) != 0;
    if (failed)
        bus[0] = '\0';
    failed |= check_one_per_gpu(job, bus, err) != 0;
    if (!failed)
        failed = rt_cuda_session_open(&mine, s, err) != 0;
    if (rt_mpi_agree(failed, err) != 0) {
        rt_cuda_session_close(*s);
        *s = NULL;
        return -1;
    }
    return 0;
}

static int render_mpi_cuda(const RtRenderJob *job, RtRenderOut *out, RtError *err)
{
    RtCudaSession *s = NULL;
    if (open_all(job, &s, err) != 0)
        return -1;
    const int max_runs = job->runs > 0 ? job->runs : RT_CUDA_RUNS;
    double *times = malloc(2 * sizeof *times * (size_t)max_runs);
    if (!times)
        rt_mpi_die(__FILE__, __LINE__, "malloc", MPI_ERR_NO_MEM);
    RtMpiImage m;
    Share sh;
    int runs, warmups, row_h, wave_rows;
    const int rows = rt_cuda_session_tile_rows(s, &row_h, &wave_rows);
    const size_t npix = (size_t)job->view.cam.width * (size_t)job->view.cam.height;
    rt_mpi_image_open(&m, npix, out->rgb, g_local_size == rt_mpi_size);
    rt_cuda_session_pin(s, m.direct ? (void *)m.img0 : (void *)out->rgb, npix * 3 * sizeof(float));
    frames(job, s, &m, out->rgb, rows, row_h, wave_rows, times, times + max_runs, max_runs, &runs, &warmups, &sh,
           err);
    rt_cuda_session_unpin(s); /* (before the window's memory goes) */
    rt_mpi_image_close(&m, out->rgb);

    RtCounters mine, sum;
    die_on(rt_cuda_session_counters(s, &mine, err), err);
    _Static_assert(sizeof(RtCounters) == 5 * sizeof(uint64_t), "RtCounters is reduced as 5 uint64");
    RT_MPI_CHECK(MPI_Reduce(&mine, &sum, 5, MPI_UINT64_T, MPI_SUM, 0, MPI_COMM_WORLD));
    if (rt_mpi_rank == 0) {
        rt_cuda_session_keys(s, out->extra, sizeof out->extra);
        size_t len = strlen(out->extra);
        snprintf(out->extra + len, sizeof out->extra - len, " row_h=%d wave_rows=%d frames=%d warmup_frames=%d",
                 row_h, wave_rows, runs, warmups);
    }
    rank_keys(s, &sh, rows, out);
    out->threads_used = 1;
    out->ranks_used = rt_mpi_size;
    out->is_root = rt_mpi_rank == 0;
    if (out->is_root) {
        size_t len = strlen(out->extra);
        snprintf(out->extra + len, sizeof out->extra - len, " gpu=%.60s", rt_cuda_session_gpu(s));
        out->counters = sum;
        out->render_ms_min = rt_median(times + max_runs, runs);
        out->render_ms = rt_median(times, runs); /* (sorts: times[0] is the fastest) */
        out->render_ms_best = times[0];
        out->runs = runs;
        out->warmups = warmups;
    }
    free(times);
    rt_cuda_session_close(s);
    return 0;
}

/* times its own runs: the scene stays on each rank's device between frames */
const RtBackend rt_backend_mpi_cuda = {"mpi-cuda",         NULL, mpi_cuda_init, render_mpi_cuda, mpi_cuda_finalize,
                                       &rt_mpi_collective, 1,    mpi_cuda_prewarm, 1};
