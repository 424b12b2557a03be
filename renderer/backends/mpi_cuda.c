/* mpi_cuda.c - the MPI backend with a GPU on each rank (--backend mpi-cuda).
 *
 * One rank per GPU: a rank's device is --device plus its rank on its node
 * (MPI_COMM_TYPE_SHARED, which is what the launcher's local rank numbers),
 * modulo the devices CUDA_VISIBLE_DEVICES leaves it. Two ranks of a node on
 * one physical GPU (the same PCI bus id) is an error unless --share-gpu lets
 * them take turns.
 *
 * Each rank opens a CUDA session (cuda_session.h: the device, the plan for
 * the whole image, the scene uploaded once) and renders, every frame, its
 * share of the image's tile rows: rank r of P takes rows r, r + P, r + 2P...
 * Interleaved row by row, the expensive rows (the subject) are split evenly,
 * so GPUs of one kind finish a frame together with no claims and no step on
 * rank 0 that grows with P. The GPU quantises the pixels to the 8 bits that
 * are written; on one node each rank's copy engine puts its rows straight
 * into rank 0's image (a shared-memory window, page-locked: no staging);
 * across nodes they come down into the rank's own buffer and go on in one
 * MPI_Put (a vector of rows). Frames are pipelined: frame k + 1's kernel
 * runs while frame k's rows are copied down. docs/gpu.md, "Several GPUs". */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "backends.h" /* RT_OMP_TILE */
#include "config.h"
#include "cuda/bvh_gpu.h"
#include "cuda/cuda_session.h"
#include "mpi_common.h"
#include "rt.h"

/* (the device as pick_device will choose it) */
static void mpi_cuda_prewarm(int device) { rt_cuda_prewarm_device(device + rt_mpi_local_rank, 1); }

/* This rank's device: --device + local rank, modulo the GPUs it sees (under
 * Slurm's --gpus-per-task each rank sees only its own: device 0). */
static int rank_device(int device, int *dev, RtError *err)
{
    int n = 0;
    if (rt_cuda_device_count(&n, err) != 0)
        return -1;
    if (device >= n)
        return rt_fail(err, "mpi-cuda: --device %d: this node has %d CUDA device(s), numbered 0 to %d", device, n,
                       n - 1);
    *dev = (device + rt_mpi_local_rank) % n;
    return 0;
}

/* rank_device, and its PCI bus id. */
static int pick_device(const RtRenderJob *job, int *dev, char *bus, size_t size, RtError *err)
{
    return rank_device(job->device, dev, err) || rt_cuda_device_bus(*dev, bus, size, err) ? -1 : 0;
}

/* One rank per GPU: collective over the node; fails on a rank whose GPU a
 * lower local rank has too, unless --share-gpu. */
static int check_one_per_gpu(const RtRenderJob *job, const char *bus, RtError *err)
{
    enum { BUS = 32 };
    char *all = malloc((size_t)BUS * (size_t)rt_mpi_local_size);
    if (!all)
        rt_mpi_die(__FILE__, __LINE__, "malloc", MPI_ERR_NO_MEM);
    char mine[BUS];
    snprintf(mine, sizeof mine, "%s", bus);
    RT_MPI_CHECK(MPI_Allgather(mine, BUS, MPI_CHAR, all, BUS, MPI_CHAR, rt_mpi_node_comm));
    int rc = 0;
    for (int q = 0; q < rt_mpi_local_rank && !job->share_gpu && !rc && *mine; q++)
        if (strcmp(all + (size_t)q * BUS, mine) == 0)
            rc = rt_fail(err,
                         "mpi-cuda: local ranks %d and %d would both drive GPU %s (%d ranks on this node): one "
                         "rank per GPU, or --share-gpu to let ranks share them",
                         q, rt_mpi_local_rank, mine, rt_mpi_local_size);
    free(all);
    return rc;
}

/* What one rank did in a frame. */
typedef struct Share {
    double end_ms;    /* from the previous frame's end to its rows in rank 0's image */
    double kernel_ms, copy_ms, put_ms;
    double rows;      /* its share of the tile rows */
    int cpu;          /* the CPU the rank ran on */
} Share;

static void die_on(int rc, const RtError *err)
{
    if (rc == 0)
        return;
    /* mid-frame the other ranks wait in the frame's reduction: end them all */
    fprintf(stderr, "raytrace: rank %d: %s\n", rt_mpi_rank, err->msg);
    fflush(stderr);
    MPI_Abort(MPI_COMM_WORLD, 1);
}

/* Where a rank's frames come down: rank 0's image itself (direct), or a
 * buffer of its own per frame in flight, taken in turn, so that frame k + 1
 * comes down while frame k is still being put. */
typedef struct Dest {
    RtMpiImage *m;
    void *stage;      /* slots x bytes, or NULL when direct */
    size_t bytes;
    int slots;
    int floats;       /* the image is floats (--verify), not 8-bit */
} Dest;

static void *dest(const Dest *d, unsigned long long frame)
{
    return d->stage ? (char *)d->stage + (frame % (unsigned long long)d->slots) * d->bytes : d->m->img0;
}

/* Frame `frame`'s rows, down in this rank's buffer, put into rank 0's image. */
static void put_frame(const Dest *d, const RtShareRuns *r, unsigned long long frame)
{
    const void *src = dest(d, frame);
    rt_mpi_put_runs(d->m, src, r->off, r->width, r->pitch, r->count);
    rt_mpi_put_runs(d->m, src, r->tail_off, r->tail_bytes, r->tail_bytes, r->tail_bytes ? 1 : 0);
    RT_MPI_CHECK(MPI_Win_flush(0, d->m->win));
}

static int queue(RtCudaSession *s, const Dest *d, unsigned long long frame, RtError *err)
{
    void *p = dest(d, frame);
    return rt_cuda_session_queue(s, d->floats ? NULL : (uint8_t *)p, d->floats ? (float *)p : NULL, err);
}

/* Only in raytrace-testhooks (tests/gpu/mpi_cuda_check.sh): a real fault of
 * the GPU of the rank RT_MPI_TEST_GPU_FAULT names, after its frame 2. */
static int test_fault(RtCudaSession *s, unsigned long long k, RtError *err)
{
    return k == 2 && rt_mpi_test_rank("RT_MPI_TEST_GPU_FAULT") ? rt_cuda_session_fault(s, err) : 0;
}

/* The frames, as many in flight as the session has slots. A frame ends,
 * on rank 0, when every rank's rows are in its image: one reduction of the
 * ranks' times per frame (O(log P)), which also carries rank 0's wish for
 * no more frames (from the frame before: frames queued past the last wanted
 * one are rendered and not counted) and any rank's failure. A rank whose GPU
 * fails stops using it; every rank leaves after that frame and the failure
 * is agreed (one message). Every rank changes course at the same frame, so
 * all make the same calls. Returns nonzero on every rank when one failed. */
static int frames(RtCudaSession *s, const Dest *d, const RtShareRuns *runs, RtCudaFrames *fr, Share *sh,
                  RtError *err)
{
    const unsigned long long n = (unsigned long long)d->slots;
    RT_MPI_CHECK(MPI_Barrier(MPI_COMM_WORLD));
    double prev = rt_now_ms();
    int more = 1, want = 1, failed = 0;
    for (unsigned long long k = 0;; k++) {
        while (!failed && more && rt_cuda_session_queued(s) < k + n)
            failed = queue(s, d, rt_cuda_session_queued(s), err) != 0;
        RtCudaFrame f;
        memset(&f, 0, sizeof f);
        if (!failed && k < rt_cuda_session_queued(s))
            failed = rt_cuda_session_wait(s, &f, err) != 0 || test_fault(s, k, err) != 0;
        const double t = rt_now_ms();
        if (!failed && d->stage)
            put_frame(d, runs, k);
        sh->put_ms = rt_now_ms() - t;
        sh->end_ms = rt_now_ms() - prev;
        sh->kernel_ms = f.kernel_ms;
        sh->copy_ms = f.copy_ms;
        /* max of end, kernel and copy; min of end (as the max of its negation); any failure; stop */
        double mine[6] = {sh->end_ms, f.kernel_ms, f.copy_ms, -sh->end_ms, failed, rt_mpi_rank == 0 && !want};
        double top[6];
        RT_MPI_CHECK(MPI_Allreduce(mine, top, 6, MPI_DOUBLE, MPI_MAX, MPI_COMM_WORLD));
        const double now = rt_now_ms();
        if (top[4] > 0.0)
            break;
        if (rt_mpi_rank == 0 && want)
            want = rt_cuda_frames_add(fr, now - prev, top[1], top[2], -top[3]);
        prev = now;
        if (top[5] > 0.0)
            more = 0;
        if (!more && k + 1 == rt_cuda_session_queued(s))
            break;
    }
    sh->cpu = rt_current_cpu();
    return rt_mpi_agree(failed, err);
}

/* The record's per-rank keys: its GPU, share of the tile rows and times in
 * the last frame, ranks separated by '/'; and the union of the ranks' CPUs
 * (the harness's pinning check). */
static void rank_keys(RtCudaSession *s, const Share *sh, RtRenderOut *out)
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
    char nodes[400];
    rt_mpi_rank_nodes(nodes, sizeof nodes);
    if (rt_mpi_rank != 0)
        return;
    enum { K = 5 };
    char k_gpu[300] = "", k[K][160];
    size_t a = 0, len[K] = {0};
    int distinct = 0;
    for (int i = 0; i < K; i++)
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
        const double v[K] = {all[r].rows, all[r].kernel_ms, all[r].copy_ms, all[r].end_ms, all[r].put_ms};
        for (int i = 0; i < K; i++)
            if (len[i] < sizeof k[i])
                len[i] += (size_t)snprintf(k[i] + len[i], sizeof k[i] - len[i], "%s%.3f", sep, v[i]);
    }
    size_t n = strlen(out->extra);
    snprintf(out->extra + n, sizeof out->extra - n,
             " gpus=%d rank_gpu=%s rank_share=%s rank_kernel_ms=%s rank_copy_ms=%s rank_end_ms=%s rank_put_ms=%s"
             " nodes=%d rank_node=%s",
             distinct, k_gpu, k[0], k[1], k[2], k[3], k[4], rt_mpi_nodes, nodes);
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

/* The image: rank 0's window (8-bit, or floats with --verify), and where
 * this rank's frames come down to. */
static void open_image(const RtRenderJob *job, RtCudaSession *s, RtRenderOut *out, RtMpiImage *m, Dest *d)
{
    const size_t npix = (size_t)job->view.cam.width * (size_t)job->view.cam.height;
    memset(d, 0, sizeof *d);
    d->m = m;
    d->floats = job->want_float;
    d->bytes = npix * 3 * (d->floats ? sizeof(float) : 1);
    d->slots = rt_cuda_session_slots(s);
    /* the same on every rank, or their frames' calls would differ (GPUs of other kinds) */
    RT_MPI_CHECK(MPI_Allreduce(MPI_IN_PLACE, &d->slots, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD));
    rt_mpi_image_open(m, d->bytes, d->floats ? (const void *)out->rgb : NULL, rt_mpi_local_size == rt_mpi_size, 0);
    if (!m->direct && (d->stage = malloc((size_t)d->slots * d->bytes)) == NULL)
        rt_mpi_die(__FILE__, __LINE__, "malloc", MPI_ERR_NO_MEM);
    rt_cuda_session_pin(s, d->stage ? d->stage : m->img0, d->stage ? (size_t)d->slots * d->bytes : d->bytes);
}

static int render_mpi_cuda(const RtRenderJob *job, RtRenderOut *out, RtError *err)
{
    RtCudaSession *s = NULL;
    if (open_all(job, &s, err) != 0)
        return -1;
    RtCudaFrames fr;
    die_on(rt_cuda_frames_init(&fr, job, err), err);
    int row_h, wave_rows;
    const int rows = rt_cuda_session_tile_rows(s, &row_h, &wave_rows);
    const RtCudaShare mine = {rt_mpi_rank, 1, rt_mpi_size};
    Share sh;
    memset(&sh, 0, sizeof sh);
    sh.rows = (double)rt_cuda_session_share(s, &mine) / rows;
    RtMpiImage m;
    Dest d;
    open_image(job, s, out, &m, &d);
    const int failed = frames(s, &d, rt_cuda_session_runs(s, d.floats), &fr, &sh, err);
    rt_mpi_frame_end(&m);
    rt_cuda_session_unpin(s); /* (before the window's memory goes) */
    rt_mpi_image_close(&m, d.floats ? (void *)out->rgb : (void *)out->rgb8);
    free(d.stage);
    if (failed) {
        rt_cuda_frames_free(&fr);
        rt_cuda_session_close(s);
        return -1;
    }

    RtCounters cnt, sum;
    die_on(rt_cuda_session_counters(s, &cnt, err), err);
    _Static_assert(sizeof(RtCounters) == 5 * sizeof(uint64_t), "RtCounters is reduced as 5 uint64");
    RT_MPI_CHECK(MPI_Reduce(&cnt, &sum, 5, MPI_UINT64_T, MPI_SUM, 0, MPI_COMM_WORLD));
    if (rt_mpi_rank == 0) {
        rt_cuda_frames_out(&fr, out);
        rt_cuda_session_keys(s, out->extra, sizeof out->extra);
        size_t len = strlen(out->extra);
        snprintf(out->extra + len, sizeof out->extra - len,
                 " kernel_ms=%.4f kernel_min_ms=%.4f download_ms=%.3f row_h=%d wave_rows=%d frames=%d"
                 " warmup_frames=%d",
                 fr.kernel_ms, fr.kernel_min_ms, fr.copy_ms, row_h, wave_rows, fr.runs, fr.warmups);
    }
    rank_keys(s, &sh, out);
    out->threads_used = 1;
    out->ranks_used = rt_mpi_size;
    out->is_root = rt_mpi_rank == 0;
    if (out->is_root) {
        size_t len = strlen(out->extra);
        snprintf(out->extra + len, sizeof out->extra - len, " gpu=%.60s", rt_cuda_session_gpu(s));
        out->counters = sum;
    }
    if (job->progress && out->is_root)
        job->progress(job->progress_ctx, (uint64_t)fr.max_runs + 1, (uint64_t)fr.max_runs + 1);
    rt_cuda_frames_free(&fr);
    rt_cuda_session_close(s);
    return 0;
}

/* Each rank builds its own tree on the device it renders on. */
static int mpi_cuda_accel_build(const RtScene *scene, const RtBvhSettings *settings, int device, RtAccel *accel,
                                RtBuildInfo *info, RtError *err)
{
    int dev = 0;
    return rank_device(device, &dev, err) ? -1 : rt_cuda_accel_build(scene, settings, dev, accel, info, err);
}

/* times its own runs: the scene stays on each rank's device between frames */
const RtBackend rt_backend_mpi_cuda = {"mpi-cuda",         NULL, rt_mpi_init, render_mpi_cuda, rt_mpi_finalize,
                                       &rt_mpi_collective, 1,    mpi_cuda_prewarm, 1, RT_OMP_TILE,
                                       mpi_cuda_accel_build, NULL};
