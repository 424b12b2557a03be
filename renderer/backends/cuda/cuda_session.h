/* cuda_session.h - the CUDA backend's steps for a caller that renders one
 * frame in many pieces: the MPI backend with a GPU on each rank
 * (backends/mpi_cuda.c). A session opens the device, plans the launch for
 * the whole image and uploads the scene once (as cuda.cu's own render does);
 * then the caller queues bands of tile rows, each rendered by the same kernel
 * and its pixel rows copied down while the next band renders. Plain C:
 * mpi_cuda.c is compiled by the C compiler. */
#ifndef RT_CUDA_SESSION_H
#define RT_CUDA_SESSION_H

#include <stddef.h>

#include "rt.h"

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
/* Opens job->device, plans the launch for job's whole image and uploads the
 * scene. 0, or -1 with the message (out of memory names the bytes needed). */
int rt_cuda_session_open(const RtRenderJob *job, RtCudaSession **s, RtError *err);
/* Tile rows in the image; *row_h receives the rows of pixels in each, and
 * *wave_rows the tile rows that fill the GPU once (its resident threads). */
int rt_cuda_session_tile_rows(const RtCudaSession *s, int *row_h, int *wave_rows);
/* Page-locks the host buffer the bands are copied into (the copies then run
 * at the link's speed, several times faster than into pageable memory) until
 * rt_cuda_session_unpin; a buffer that cannot be locked is left as it is. */
void rt_cuda_session_pin(RtCudaSession *s, void *host, size_t bytes);
void rt_cuda_session_unpin(RtCudaSession *s);
/* Zeroes the ray counters: a frame starts. */
int rt_cuda_session_frame(RtCudaSession *s, RtError *err);
/* Queues tile rows [r0, r1): their kernel, then the copy of their pixel rows
 * into rgb (the whole image's host buffer, at the same offsets) on a second
 * stream, so that it overlaps the next band's kernel. Returns at once. At
 * most RT_CUDA_BANDS bands may be queued and not yet reported ready. */
#define RT_CUDA_BANDS 256
int rt_cuda_session_band(RtCudaSession *s, int r0, int r1, float *rgb, RtError *err);
/* Waits until at most `keep` queued kernels are unfinished. */
int rt_cuda_session_kernels(RtCudaSession *s, int keep, RtError *err);
/* How many more of the oldest queued bands are in rgb now, in queue order
 * (wait: all of them, waiting for their copies); -1 on an error. */
int rt_cuda_session_ready(RtCudaSession *s, int wait, RtError *err);
/* The counters of the frame so far. */
int rt_cuda_session_counters(RtCudaSession *s, RtCounters *c, RtError *err);
/* "NAME@PCI-BUS-ID" of the session's GPU (characters safe in a record). */
const char *rt_cuda_session_gpu(const RtCudaSession *s);
/* The plan's record keys (" block=8x8 sched=grid ..."; docs/gpu.md). */
void rt_cuda_session_keys(const RtCudaSession *s, char *buf, size_t size);
void rt_cuda_session_close(RtCudaSession *s);

#ifdef __cplusplus
}
#endif

#endif
