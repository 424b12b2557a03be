/* options.h - raytrace's command line (cli/options.c): the options main.c
 * runs with, their defaults, --help and --version. */
#ifndef RT_CLI_OPTIONS_H
#define RT_CLI_OPTIONS_H

#include "rt.h"

typedef struct Options {
    const char *scene;
    const char *output;
    const char *backend;
    RtAccelKind accel;
    int width, height;  /* 0: from the scene */
    int max_depth;      /* -1: from the scene */
    int threads;
    int build_threads;  /* 0: every allowed CPU */
    int huge_pages;     /* 1 on, 0 off, -1 auto (RtBvhSettings.huge_pages) */
    RtBuilder builder;  /* --builder: auto (default), cpu or gpu */
    int gpu_split;      /* --gpu-split: the GPU build's pieces, percent of the triangles; -1 (default): auto */
    int tile_w, tile_h; /* 0: the backend's (RtBackend.tile) */
    RtSchedule schedule;
    RtMpiSchedule mpi_schedule;
    int block_x, block_y;
    int device;
    int share_gpu;      /* mpi-cuda: ranks may share a GPU */
    int runs;           /* 0: the backend's default */
    int warmup_runs;    /* -1: unset */
    double warmup_ms;   /* -1: unset */
    double start_at_ms; /* --start-at: CLOCK_MONOTONIC ms the render waits for; 0: none */
    int quiet;
    int verify;
    int calibrate;
    const char *mpi_scene; /* NULL: the mpi backend's default */
    const char *cache;     /* scene cache directory; NULL: none */
    const char *isa;       /* CPU traversal's instruction set; NULL: the best this CPU runs */
} Options;

/* The program's name, which its messages start with. */
extern const char cli_prog[];

/* Parses argv into *o on every process; --help and --version print and exit.
 * Under mpirun only rank 0 (other_rank 0) may say what is wrong with the
 * options or print --help and --version: the others' stdout and stderr are
 * silenced meanwhile. 0, or -1 after saying why. */
int cli_parse(int argc, char **argv, Options *o, int other_rank);

#endif
