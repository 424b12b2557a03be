/* cuda_session.h - the GPU backends' frames: a session opens the device,
 * plans the launch for the whole image and uploads the scene once; then it
 * renders frames of its share of the image's tile rows (the whole image for
 * the CUDA backend, one share per rank for mpi-cuda), each frame's 8-bit
 * pixels copied down while the next frame renders. Plain C: mpi_cuda.c is
 * compiled by the C compiler. */
#ifndef RT_CUDA_SESSION_H
#define RT_CUDA_SESSION_H

#include <stddef.h>

#include "rt.h"
#include "schedule.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Default timing of the GPU backends (--runs and --warmup replace it):
 * RT_CUDA_RUNS timed frames (fewer when they would take more than
 * RT_CUDA_TIME_BUDGET_MS), after RT_CUDA_WARMUP_MS of warm-up frames (module
 * load, caches, and the clocks: an idle H100 needs some milliseconds of work
 * to boost). */
#define RT_CUDA_RUNS 21
#define RT_CUDA_WARMUP_MS 50.0
#define RT_CUDA_TIME_BUDGET_MS 4000.0

typedef struct RtCudaSession RtCudaSession;

/* CUDA devices this process sees (CUDA_VISIBLE_DEVICES applies). 0, or -1
 * with "cuda: no usable GPU: ..." when there is no driver or no device. */
int rt_cuda_device_count(int *n, RtError *err);
/* The PCI bus id of a device ("0000:19:00.0"): which physical GPU it is,
 * whatever CUDA_VISIBLE_DEVICES numbers it. 0 or -1. */
int rt_cuda_device_bus(int device, char *bus, size_t size, RtError *err);
/* Creates device `device`'s context on a thread of its own, so that it is
 * ready when the session opens; device modulo the device count when wrap. */
void rt_cuda_prewarm_device(int device, int wrap);
/* Waits for the context rt_cuda_prewarm_device started, if it did. */
void rt_cuda_prewarm_join(void);
/* Makes device `dev` the calling thread's, its context created (wait_ms:
 * how long that still took). 0, or -1 with "cuda: no usable GPU: ..." or
 * "cuda: --device N: ...". */
int rt_cuda_device_open(int dev, double *wait_ms, RtError *err);
/* Opens job->device, plans the launch for job's whole image and uploads the
 * scene; the share is the whole image. 0, or -1 with the message (out of
 * memory names the bytes needed). */
int rt_cuda_session_open(const RtRenderJob *job, RtCudaSession **s, RtError *err);
/* Tile rows in the image; *row_h receives the rows of pixels in each, and
 * *wave_rows the tile rows that fill the GPU once (its resident threads). */
int rt_cuda_session_tile_rows(const RtCudaSession *s, int *row_h, int *wave_rows);
/* The tile rows this session renders of each frame from now on (schedule.h);
 * returns how many there are. */
int rt_cuda_session_share(RtCudaSession *s, const RtCudaShare *sh);
/* Where the share's pixels lie in the 8-bit image (floats: in the float
 * image): the pieces the session copies down, and a caller puts on. */
const RtShareRuns *rt_cuda_session_runs(const RtCudaSession *s, int floats);
/* Page-locks a host buffer the frames are copied into (the copies then run
 * at the link's speed, several times faster than into pageable memory)
 * until rt_cuda_session_unpin; a buffer that cannot be locked is left as it
 * is. Up to four buffers. */
void rt_cuda_session_pin(RtCudaSession *s, void *host, size_t bytes);
void rt_cuda_session_unpin(RtCudaSession *s);
/* Queues a frame: the ray counters zeroed, the kernel over the share (its
 * pixels quantised to 8 bits on the GPU, rt_quantize), then on a second
 * stream the copy of the share's 8-bit pixels into rgb8 and, unless NULL,
 * of their floats into rgbf (whole-image host buffers, the pixels at their
 * own offsets; rgb8 may be NULL too). Returns at once. The frame's kernel
 * runs while the frame before it is copied down; at most
 * rt_cuda_session_slots frames are queued and not yet waited for. */
int rt_cuda_session_queue(RtCudaSession *s, uint8_t *rgb8, float *rgbf, RtError *err);
/* The oldest queued frame, waited for until its copies are in host memory:
 * end is that moment (rt_now_ms); kernel_ms the GPU's time in its kernel
 * (from its start, or from the previous frame's kernel end where it started
 * under that one); copy_ms from its kernel's end to its copies' end. */
typedef struct RtCudaFrame {
    double end, kernel_ms, copy_ms;
} RtCudaFrame;
int rt_cuda_session_wait(RtCudaSession *s, RtCudaFrame *f, RtError *err);
/* Frames the session keeps in flight (rt_cuda_frames_in_flight). */
int rt_cuda_session_slots(const RtCudaSession *s);
/* Frames queued so far. */
unsigned long long rt_cuda_session_queued(const RtCudaSession *s);
/* A real fault of the session's GPU (a kernel that traps), for the tests
 * of a GPU failing mid-study: -1 with CUDA's message; the device is
 * unusable afterwards. */
int rt_cuda_session_fault(RtCudaSession *s, RtError *err);
/* The counters of the last frame (waits for its kernel). */
int rt_cuda_session_counters(RtCudaSession *s, RtCounters *c, RtError *err);
/* "NAME@PCI-BUS-ID" of the session's GPU (characters safe in a record). */
const char *rt_cuda_session_gpu(const RtCudaSession *s);
/* The plan's record keys (" block=8x8 sched=grid ..."; docs/gpu.md). */
void rt_cuda_session_keys(const RtCudaSession *s, char *buf, size_t size);
void rt_cuda_session_close(RtCudaSession *s);

/* The GPU backends' frame timing: warm-up frames (--warmup, else
 * RT_CUDA_WARMUP_MS of them), then --runs timed frames (else RT_CUDA_RUNS,
 * fewer past RT_CUDA_TIME_BUDGET_MS). A frame's time is its period: from
 * the previous frame's image in host memory to its own (the first frame:
 * from the first queue). */
typedef struct RtCudaFrames {
    const RtRenderJob *job;
    double *v;               /* per timed frame: period, kernel, copy, earliest end (4 x max_runs) */
    int max_runs, runs, warmups, n;
    double t0, warm_ms, first_kernel_ms;
    double kernel_ms, kernel_min_ms, copy_ms; /* rt_cuda_frames_out's medians */
} RtCudaFrames;
int rt_cuda_frames_init(RtCudaFrames *f, const RtRenderJob *job, RtError *err);
/* Frame n done: counted as warm-up or timed; 1 while another is wanted. */
int rt_cuda_frames_add(RtCudaFrames *f, double period_ms, double kernel_ms, double copy_ms, double first_end_ms);
/* render_ms (the periods' median), render_ms_best, render_ms_min (the
 * earliest ends'), runs, warmups and quantized into out; the kernel's and
 * copies' medians into f. */
void rt_cuda_frames_out(RtCudaFrames *f, RtRenderOut *out);
void rt_cuda_frames_free(RtCudaFrames *f);

#ifdef __cplusplus
}
#endif

#endif
