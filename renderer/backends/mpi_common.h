/* mpi_common.h - what the two MPI backends share (mpi.c: ranks on the CPU;
 * mpi_cuda.c: a GPU on each rank), defined in mpi_common.c: start and end,
 * agreeing on failures, the scene on every rank, and the dynamic scheme's
 * shared image -- the claim counter and the image in one MPI window on rank
 * 0 (docs/cpu-backends.md, "MPI"). */
#ifndef RT_MPI_COMMON_H
#define RT_MPI_COMMON_H

#include <mpi.h>
#include <stdint.h>

#include "rt.h"

extern int rt_mpi_rank, rt_mpi_size;
/* This rank's node (MPI_COMM_TYPE_SHARED: the ranks that share memory with
 * it), its rank and size there, the node's number (0 holds rank 0) and the
 * number of nodes; set by rt_mpi_init. */
extern int rt_mpi_local_rank, rt_mpi_local_size, rt_mpi_node, rt_mpi_nodes;
extern MPI_Comm rt_mpi_node_comm;
/* The thread support MPI_Init_thread provided (MPI_THREAD_*). */
extern int rt_mpi_thread_level;
/* This rank's time in the collective's scene_load, and how the scene
 * reached the ranks ("bcast" or "every"; "every" when P = 1): the record's
 * load_ms_max and mpi_scene. */
extern double rt_mpi_load_ms;
extern const char *rt_mpi_scene_how;
/* The copies of the scene the ranks render from: one per NUMA node where
 * RtCollective.share made one (the record's scene_copies), else one each. */
extern int rt_mpi_scene_copies;
/* 1 where another rank of this node may run on one of this rank's CPUs
 * (their affinity masks overlap: unbound or oversubscribed), and the number
 * of such ranks (the record's core_sharing_ranks); set by rt_mpi_init. */
extern int rt_mpi_shares_core, rt_mpi_core_sharing_ranks;

/* Names the failed call with MPI's error string, then MPI_Abort (never a hang). */
void rt_mpi_die(const char *file, int line, const char *call, int code);

/* MPI_ERRORS_RETURN is set on the communicator and the window, so errors come
 * back here and are named, instead of Open MPI's generic abort text. */
#define RT_MPI_CHECK(call)                                                                                            \
    do {                                                                                                              \
        int rc_ = (call);                                                                                             \
        if (rc_ != MPI_SUCCESS)                                                                                       \
            rt_mpi_die(__FILE__, __LINE__, #call, rc_);                                                               \
    } while (0)

int rt_mpi_init(int *argc, char ***argv, RtError *err);
void rt_mpi_finalize(void);
/* Collective: nonzero on every rank if any failed; rank 0's err then holds
 * the lowest failing rank's message (RtCollective.agree). */
int rt_mpi_agree(int failed, RtError *err);
/* Test hooks: 1 when environment variable var names this rank, in
 * raytrace-testhooks only (mpi_common.c built with RT_TEST_HOOKS); else 0. */
int rt_mpi_test_rank(const char *var);
/* Collective: rank 0's buf gets each rank's node number, ranks separated by
 * '/' (the record's rank_node: "0/0/1/1"). */
void rt_mpi_rank_nodes(char *buf, size_t size);
extern const RtCollective rt_mpi_collective;

/* The shared image of the dynamic scheme. The window on rank 0 (disp_unit
 * 1) holds the claim counter, the starting barrier's (shared memory only),
 * then `extra` bytes of the caller's (the tile
 * board, shared memory only), then the image at byte img_off, each part
 * 128-byte line pairs apart (the adjacent-line prefetcher's pair), so that
 * claims never contend with the pixels written beside them. */
#define RT_WIN_EXTRA 256
typedef struct RtMpiImage {
    MPI_Win win;
    void *base;     /* rank 0's window (the counter at its start) */
    void *extra;    /* rank 0's extra bytes, where this rank may reach them directly */
    void *img0;     /* rank 0's image, where this rank may write it directly */
    int direct;     /* 1: write img0 directly; 0: MPI_Put into it */
    int atomic;     /* 1: claim with a CPU atomic on the counter (shared memory) */
    size_t bytes;   /* the image's size */
    size_t extra_bytes;
    size_t img_off; /* the image's byte in the window */
} RtMpiImage;

/* Collective: the window on rank 0 (counter, `extra` bytes zeroed at every
 * frame start, and an image of `bytes`, the image starting as rank 0's
 * init, e.g. main's NaN poison, or zeros where init is NULL), locked for the
 * passive target epochs of frames. Rank 0 writes its own pixels directly
 * where the memory model allows. shared (the same on every rank) says every
 * rank runs on one node: the window is then shared memory
 * (MPI_Win_allocate_shared), every rank writes its pixels straight into
 * rank 0's image (no puts) and claims with one CPU atomic on the counter (no
 * MPI call, no lock). */
void rt_mpi_image_open(RtMpiImage *m, size_t bytes, const void *init, int shared, size_t extra);
/* Collective: the counter back to 0; returns when every rank may claim. */
void rt_mpi_frame_start(RtMpiImage *m);
/* Guided self-scheduling (Polychronopoulos & Kuck 1987) of `total` units
 * among the P ranks' `claimers` each: claims 1/(4 P claimers) of what
 * remains (a look at the counter just before the claim is added to it),
 * never less than min_claim. Early claims are large, so the counter on rank
 * 0 is hit a few dozen times per claimer rather than once per unit; the
 * last are small, so the claimers finish together. The claim's first unit
 * in *first and its length returned; 0 when nothing is left. Thread-safe
 * where m->atomic (one node). */
int64_t rt_mpi_claim(RtMpiImage *m, int64_t total, int64_t min_claim, int claimers, int64_t *first);
/* Puts `count` pieces of `width` bytes, `pitch` apart from byte `off` of
 * this rank's whole-image buffer src, into the same places of rank 0's
 * image (one MPI vector). */
void rt_mpi_put_runs(RtMpiImage *m, const void *src, size_t off, size_t width, size_t pitch, size_t count);
/* Collective: every rank's puts are in rank 0's image. */
void rt_mpi_frame_end(RtMpiImage *m);
/* Collective: rank 0 copies the image into out; the window is freed. */
void rt_mpi_image_close(RtMpiImage *m, void *out);

#endif
