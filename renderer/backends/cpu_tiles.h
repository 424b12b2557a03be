/* cpu_tiles.h - the multi-threaded tile loop shared by the OpenMP backend and
 * the MPI backend's ranks (hybrid MPI+OpenMP). Internal to renderer/backends.
 *
 * Header-only on purpose: the library is compiled with the OpenMP flags
 * whenever OpenMP was found (renderer/meson.build adds omp_dep to every
 * source), so mpi.c gets the same threaded loop by including this file, and
 * in a build without OpenMP the pragmas vanish and the loops run on one
 * thread. One loop, two callers: neither backend shades or tiles differently.
 *
 * Every loop calls rt_cpu_render_pixel / rt_cpu_render_tile (cpu_trace.h:
 * core/rt_path_tmpl.h's pixel and tile with the CPU traversal inlined); a
 * pixel's colour and counters depend only on (scene, i, j), so any split of
 * the image over threads or ranks gives the serial image bit for bit and the
 * same integer counter sums. */
#ifndef RT_CPU_TILES_H
#define RT_CPU_TILES_H

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "rt.h"
#include "cpu_trace.h"
#ifdef _OPENMP
#include <omp.h>
#endif

#define RT_CPU_MAX_CPUS 1024

/* One worker thread's private state. Threads only ever write their own
 * slot, and each slot starts on its own 128-byte boundary (two cache lines:
 * Intel's adjacent-line prefetcher pairs lines), so no two threads share a
 * line: counters merged at the end, never atomics in the pixel loop. */
typedef struct RtCpuSlot {
    RtCounters cnt;                         /* work counters of this thread (40 bytes) */
    uint64_t backups;                       /* second renders of a strip it started */
    uint64_t backups_won;                   /* ... whose pixels went into the image */
    int64_t start_ns, end_ns;               /* its last tile loop: entered, out of claims */
    uint64_t cpus[RT_CPU_MAX_CPUS / 64];    /* bitmask of CPUs it ran on (128 bytes) */
} RtCpuSlot;

typedef struct RtCpuPool {
    int nthreads;
    int cpus;        /* the CPUs the team may run on (rt_team_cpus) */
    size_t stride;   /* bytes between slots: sizeof(RtCpuSlot) rounded up to 128 */
    unsigned char *mem;
    size_t tile_floats; /* each thread's tile buffer (rt_cpu_render_tiles) */
    float *tiles;
} RtCpuPool;

static inline RtCpuSlot *rt_cpu_slot(const RtCpuPool *p, int t)
{
    return (RtCpuSlot *)(void *)(p->mem + (size_t)t * p->stride);
}

/* Threads to use: --threads (requested > 0), else OMP_NUM_THREADS if set,
 * else `fallback` (<= 0: every CPU this process may run on, which is what
 * omp_get_max_threads() reports when OMP_NUM_THREADS is unset). */
static inline int rt_cpu_threads(int requested, int fallback)
{
    if (requested > 0)
        return requested;
    const char *env = getenv("OMP_NUM_THREADS");
#ifdef _OPENMP
    if (env && *env)
        return omp_get_max_threads();
    return fallback > 0 ? fallback : omp_get_max_threads();
#else
    (void)env;
    (void)fallback;
    return 1;
#endif
}

/* A pool of nthreads, each with a buffer for the strips of one tw x th
 * tile of a w x h image (tw 0: the pool renders no tiles). */
static inline int rt_cpu_pool_init(RtCpuPool *p, int nthreads, int tw, int th, int w, int h, RtError *err)
{
    p->nthreads = nthreads;
    p->stride = (sizeof(RtCpuSlot) + 127) / 128 * 128;
    p->mem = aligned_alloc(128, p->stride * (size_t)nthreads);
    tw = tw < w ? tw : w;
    th = th < h ? th : h;
    /* a strip is rendered into row (its row in the tile) % 16, so 16 rows
     * at most; whole lines per thread: no two threads write one line */
    p->tile_floats = ((size_t)tw * (size_t)(th < 16 ? th : 16) * 3 + 31) / 32 * 32;
    p->tiles = p->tile_floats ? aligned_alloc(128, p->tile_floats * sizeof(float) * (size_t)nthreads) : NULL;
    if (!p->mem || (p->tile_floats && !p->tiles)) {
        free(p->mem);
        free(p->tiles);
        p->mem = NULL;
        p->tiles = NULL;
        return rt_fail(err, "out of memory for %d worker threads with %dx%d tiles", nthreads, tw, th);
    }
    memset(p->mem, 0, p->stride * (size_t)nthreads);
#ifdef _OPENMP
    /* The team size is exactly what was asked for, never trimmed by the
     * runtime under load: a scaling study must run T threads when it says T. */
    omp_set_dynamic(0);
#endif
    /* The team's CPUs, read in a region of its own threads, which also
     * starts the team now, so that thread creation is not timed as pixel
     * work (libgomp keeps the threads for the next parallel region). */
    p->cpus = rt_team_cpus(nthreads);
    return 0;
}

static inline void rt_cpu_pool_free(RtCpuPool *p)
{
    free(p->mem);
    free(p->tiles);
    p->mem = NULL;
    p->tiles = NULL;
}

static inline int rt_cpu_thread_id(void)
{
#ifdef _OPENMP
    return omp_get_thread_num();
#else
    return 0;
#endif
}

static inline void rt_cpu_note(RtCpuSlot *s)
{
    int cpu = rt_current_cpu();
    if (cpu >= 0 && cpu < RT_CPU_MAX_CPUS)
        s->cpus[cpu / 64] |= 1ull << (cpu % 64);
}

/* The rectangle of tile `index` when [rx0,rx1) x [ry0,ry1) is cut into
 * tw x th tiles, row-major (rt_tile_rect for a sub-region: MPI row blocks). */
static inline void rt_region_tile(int rx0, int ry0, int rx1, int ry1, int tw, int th, int index, int *x0, int *y0,
                                  int *x1, int *y1)
{
    rt_tile_rect(rx1 - rx0, ry1 - ry0, tw, th, index, x0, y0, x1, y1);
    *x0 += rx0;
    *x1 += rx0;
    *y0 += ry0;
    *y1 += ry0;
}

/* ---- strips, and their second renders ---------------------------------
 *
 * The unit of work is a strip: one row of a tile, tile-major (strip s is
 * row s % th of tile s / th), so a tile's rows stay together on one thread
 * while work is plentiful and the frame's last tiles can still be shared.
 * A thread claims up to a tile of strips at a time, fewer as the claims run
 * out (guided, Polychronopoulos and Kuck 1987).
 *
 * A thread that the operating system (or a hypervisor) takes off its core
 * while it holds work holds the frame: on a 64-core virtual machine such
 * stalls reach milliseconds, as long as a whole 512x384 frame. And the
 * frame's last tiles cost up to several times the average one: at 32 MPI
 * ranks, ranks ran out of work 0.5 ms apart in a 4 ms frame. So once every
 * strip is claimed, a thread with nothing left starts a second render of a
 * strip that is claimed and not yet finished, at most one per strip:
 * MapReduce's backup tasks (Dean and Ghemawat, OSDI 2004). Backups take a
 * tile's strips from its last row up, while the owner renders from its
 * first, skipping those already in the image: the two meet in the middle,
 * and a backup that is itself taken off its core never holds a strip whose
 * owner is running. Both renders go into buffers of their own; whichever
 * is published first copies its pixels into the image, and only its
 * counters count. A strip's pixels depend only on the scene, so image and
 * counters are those of one render, whoever wins.
 *
 * The host holds several virtual CPUs at once, so a backup is at times
 * held with the owner it backs up: at 64 ranks on a 512x384 frame, the
 * frame then ended when the owner woke, 1-3 ms late, with 30-80 backups
 * run. Where every thread has a CPU of its own (RtTileRun.rescue), a
 * thread done with its backups' pass therefore renders, in a second pass,
 * every strip still not in the image, backed up or not, and stops once
 * the image is complete: the frame waits for a strip only while every one
 * of its renderers is held. Where threads share cores that pass would take
 * the owners' own time, so it is not run there.
 *
 * States are bits, 16 strips of a tile to a 32-bit word: bit i says strip
 * i's pixels are in the image, bit 16 + i that its backup has started. An
 * owner publishes a tile's rows with one atomic per word (the frame's last
 * claims, a quarter of a tile or less, row by row), so a tile costs the atomics it
 * did when the tile was the unit, and 16 tiles share a cache line. */
#define RT_STRIP_DONE(i) (1u << (i))
#define RT_STRIP_BACKUP(i) (1u << (16 + (i)))

static inline int rt_strip_words(int th) { return (th + 15) / 16; }

/* A frame's strips: their state words, and the count of strips in the
 * image. The MPI backend keeps it in rank 0's shared window, so that ranks
 * back up each other's strips too. */
typedef struct RtTileBoard {
    uint32_t *state;      /* rt_board_words of them: RT_STRIP_* */
    int64_t *done;        /* strips in the image */
    int64_t *end_ns;      /* when the last of them arrived (rt_now_ns, rt.h) */
    int64_t total;        /* strips in the frame (rt_strip_total) */
} RtTileBoard;

/* Strip numbers of the tw x th tiling of a rw x rh region: th per tile; a
 * tile cut short by the region's bottom edge leaves its last ones empty. */
static inline int64_t rt_strip_count(int rw, int rh, int tw, int th)
{
    return (int64_t)rt_tile_count(rw, rh, tw, th) * th;
}
/* ... the strips that are not empty: one per tile column and row ... */
static inline int64_t rt_strip_total(int rw, int rh, int tw)
{
    return (int64_t)((rw + tw - 1) / tw) * rh;
}
/* ... and the board's state words. */
static inline int64_t rt_board_words(int rw, int rh, int tw, int th)
{
    return (int64_t)rt_tile_count(rw, rh, tw, th) * rt_strip_words(th);
}

/* What rt_cpu_render_tiles does: claim strips [first, first + count) of the
 * tw x th tiling of region [rx0,rx1) x [ry0,ry1), or, with claim, whatever
 * claim hands each thread until it returns 0; then back up strips
 * [0, scan_count) of the tiling (all claimed by then), each thread starting
 * its pass at its own place: thread t of a caller that is slot `scan_slot`
 * of `scan_slots` callers (MPI ranks). */
typedef struct RtTileRun {
    const RtSceneView *v;
    int rx0, ry0, rx1, ry1, tw, th;
    int64_t first, count;
    /* each thread's next strips [*first, *first + n), n; 0: none left. A
     * counter shared with other ranks (mpi.c) claims per thread, so the
     * frame is one parallel region: no thread waits for the others at the
     * end of a claim, held up by whichever of them the system stalled */
    int64_t (*claim)(void *ctx, int64_t *first);
    void *claim_ctx;
    int64_t scan_count;
    int scan_slot, scan_slots;
    float *rgb;           /* the whole image (stride = width) */
    RtTileBoard *board;
    int rescue;           /* every thread has a CPU of its own: the rescue pass */
    RtProgressFn progress;
    void *progress_ctx;
} RtTileRun;

/* The strips of state word wd that exist: a tile at the region's bottom
 * edge, or the last word of a tile when th is not a multiple of 16, has
 * fewer. */
static inline uint32_t rt_word_strips(const RtTileRun *r, int64_t wd)
{
    const int wpt = rt_strip_words(r->th), cols = (r->rx1 - r->rx0 + r->tw - 1) / r->tw;
    int rows = r->ry1 - r->ry0 - (int)(wd / wpt / cols) * r->th;
    rows = rows < r->th ? rows : r->th;
    const int n = rows - (int)(wd % wpt) * 16;
    return n >= 16 ? 0xffffu : n > 0 ? (1u << n) - 1 : 0;
}

/* Where strip s is: its tile's pixels [x0, x1), the image row of its
 * word's first strip (*yw) and its bit in the word (*i); whether it exists
 * is rt_word_strips's. */
static inline uint32_t *rt_strip_at(const RtTileRun *r, int64_t s, int *x0, int *x1, int *yw, int *i)
{
    int y0, y1;
    const int64_t t = s / r->th;
    const int row = (int)(s % r->th);
    rt_region_tile(r->rx0, r->ry0, r->rx1, r->ry1, r->tw, r->th, (int)t, x0, &y0, x1, &y1);
    *yw = y0 + row / 16 * 16;
    *i = row % 16;
    return &r->board->state[t * rt_strip_words(r->th) + row / 16];
}

/* n more strips are in the image; the last one stamps the frame's end. */
static inline void rt_strips_done(RtTileBoard *b, int64_t n)
{
    if (n && __atomic_add_fetch(b->done, n, __ATOMIC_ACQ_REL) == b->total)
        __atomic_store_n(b->end_ns, rt_now_ns(), __ATOMIC_RELEASE);
}

/* Publishes the rendered strips `mine` of one word: row i of buf (counters
 * rc[i]) is bit i's, image row yw + i. Copies those no other render
 * published first, adds their counters; how many it copied. */
static inline int rt_strips_publish(const RtTileRun *r, uint32_t *word, uint32_t mine, int x0, int x1, int yw,
                                    const float *buf, const RtCounters *rc, RtCounters *cnt)
{
    const uint32_t won = mine & ~__atomic_fetch_or(word, mine, __ATOMIC_ACQ_REL);
    const size_t cw = (size_t)(x1 - x0) * 3, w = (size_t)r->v->cam.width;
    for (uint32_t b = won; b; b &= b - 1) {
        const int i = __builtin_ctz(b);
        memcpy(r->rgb + 3 * ((size_t)(yw + i) * w + (size_t)x0), buf + (size_t)i * cw, cw * sizeof(float));
        rt_counters_add(cnt, &rc[i]);
    }
    return __builtin_popcount(won);
}

/* Strip s rendered into buf (a tile buffer) and published: 1 if this
 * render put it in the image. The board's count is the caller's
 * (rt_strips_done). */
static inline int rt_strip_render(const RtTileRun *r, int64_t s, float *buf, RtCounters *cnt)
{
    int x0, x1, yw, i;
    uint32_t *word = rt_strip_at(r, s, &x0, &x1, &yw, &i);
    if (!(rt_word_strips(r, word - r->board->state) & RT_STRIP_DONE(i)))
        return 0;
    const size_t cw = (size_t)(x1 - x0) * 3;
    RtCounters rc[16];
    memset(&rc[i], 0, sizeof rc[i]);
    rt_cpu_render_tile(r->v, x0, yw + i, x1, yw + i + 1, buf + (size_t)i * cw, cw, &rc[i]);
    return rt_strips_publish(r, word, RT_STRIP_DONE(i), x0, x1, yw, buf, rc, cnt);
}

/* The owner's render of claimed strips [s0, s0 + k): those not yet in the
 * image, published a word at a time, or row by row when the claim is a
 * quarter of a tile or less (the frame's end, when backups run). Each
 * publication is counted on the board at once: counted at the claim's end,
 * a word published before the owner was held would hold the frame's end
 * stamp until it woke, whoever rendered the rest. */
static inline void rt_strips_render(const RtTileRun *r, int64_t s0, int64_t k, float *buf, RtCounters *cnt)
{
    const int per_row = 4 * k <= r->th;
    for (int64_t s = s0; s < s0 + k;) {
        int x0, x1, yw, i;
        uint32_t *word = rt_strip_at(r, s, &x0, &x1, &yw, &i);
        const uint32_t exist = rt_word_strips(r, word - r->board->state);
        /* the claim's strips in this word: to the word's or the tile's end */
        int64_t e = s - i + 16, tile_end = (s / r->th + 1) * r->th;
        e = e < tile_end ? e : tile_end;
        e = e < s0 + k ? e : s0 + k;
        const size_t cw = (size_t)(x1 - x0) * 3;
        RtCounters rc[16];
        uint32_t mine = 0;
        for (; s < e; s++, i++) {
            if (!(exist & RT_STRIP_DONE(i)) || __atomic_load_n(word, __ATOMIC_RELAXED) & RT_STRIP_DONE(i))
                continue;
            memset(&rc[i], 0, sizeof rc[i]);
            rt_cpu_render_tile(r->v, x0, yw + i, x1, yw + i + 1, buf + (size_t)i * cw, cw, &rc[i]);
            if (per_row)
                rt_strips_done(r->board, rt_strips_publish(r, word, RT_STRIP_DONE(i), x0, x1, yw, buf, rc, cnt));
            else
                mine |= RT_STRIP_DONE(i);
        }
        if (mine)
            rt_strips_done(r->board, rt_strips_publish(r, word, mine, x0, x1, yw, buf, rc, cnt));
    }
}

/* The strips of state word st that a pass may render: not in the image,
 * and (a backups' pass) not backed up yet. */
static inline uint32_t rt_strips_open(uint32_t st, int rescue)
{
    return ~(st | (rescue ? 0 : st >> 16)) & 0xffffu;
}

/* One pass of a thread over the board's words [0, n), from word k0 on:
 * strips that are neither in the image nor (backups) already backed up, or
 * (rescue) every strip not in the image while the image is incomplete.
 * Each word from its last strip up: the owner works up from its first. */
static inline void rt_strips_pass(const RtTileRun *r, int rescue, int64_t n, int64_t k0, RtCpuSlot *slot,
                                  float *buf, RtCounters *cnt)
{
    const int wpt = rt_strip_words(r->th);
    if (rescue && __atomic_load_n(r->board->done, __ATOMIC_RELAXED) >= r->board->total)
        return;
    for (int64_t k = 0; k < n; k++) {
        const int64_t wd = (k0 + k) % n;
        uint32_t *word = &r->board->state[wd];
        uint32_t st = __atomic_load_n(word, __ATOMIC_RELAXED), open = rt_strips_open(st, rescue);
        if (open)
            open &= rt_word_strips(r, wd);
        while (open) {
            if (rescue && __atomic_load_n(r->board->done, __ATOMIC_RELAXED) >= r->board->total)
                return;
            const int i = 31 - __builtin_clz(open);
            if (rescue || !(__atomic_fetch_or(word, RT_STRIP_BACKUP(i), __ATOMIC_RELAXED) &
                            (RT_STRIP_DONE(i) | RT_STRIP_BACKUP(i)))) {
                const int won = rt_strip_render(r, wd / wpt * r->th + wd % wpt * 16 + i, buf, cnt);
                slot->backups++;
                slot->backups_won += (uint64_t)won;
                rt_strips_done(r->board, won);
            }
            st = __atomic_load_n(word, __ATOMIC_RELAXED);
            open &= rt_strips_open(st, rescue) & ~RT_STRIP_DONE(i);
        }
    }
}

/* Renders r's strips on the pool's threads: ray cost varies by orders of
 * magnitude across an image (sky vs. a glass dragon), so work is handed
 * out to whichever thread is free (dynamic), then backed up. */
static inline void rt_cpu_render_tiles(RtCpuPool *p, const RtTileRun *r)
{
    int64_t next = r->first, done = 0; /* done: for progress only */
    const int64_t end = r->first + r->count, guide = 4 * (int64_t)p->nthreads;
#pragma omp parallel num_threads(p->nthreads)
    {
        int tid = rt_cpu_thread_id();
        RtCpuSlot *slot = rt_cpu_slot(p, tid);
        float *buf = p->tiles + (size_t)tid * p->tile_floats;
        RtCounters cnt; /* on this thread's stack: the hot loop writes nothing shared */
        memset(&cnt, 0, sizeof cnt);
        slot->start_ns = rt_now_ns();
        rt_cpu_note(slot);
        for (int64_t at = 0; r->claim || (at = __atomic_load_n(&next, __ATOMIC_RELAXED)) < end;) {
            int64_t s0, k;
            if (r->claim) {
                if ((k = r->claim(r->claim_ctx, &s0)) <= 0)
                    break;
            } else {
                k = (end - at) / guide;
                k = k < 1 ? 1 : k > r->th ? r->th : k;
                s0 = __atomic_fetch_add(&next, k, __ATOMIC_RELAXED);
                k = s0 >= end ? 0 : end - s0 < k ? end - s0 : k;
            }
            rt_strips_render(r, s0, k, buf, &cnt);
            rt_cpu_note(slot);
            if (r->progress && k) {
                /* only thread 0 prints: no thread ever waits for the terminal */
                int64_t d = __atomic_add_fetch(&done, k, __ATOMIC_RELAXED);
                if (tid == 0)
                    r->progress(r->progress_ctx, (uint64_t)d, (uint64_t)r->count);
            }
        }
        slot->end_ns = rt_now_ns();
        /* the backups' pass, a state word at a time (a word of finished
         * strips costs one load), then the rescue pass */
        const int64_t n = r->scan_count / r->th * rt_strip_words(r->th),
                      k0 = n * (int64_t)(r->scan_slot * p->nthreads + tid) / ((int64_t)r->scan_slots * p->nthreads);
        rt_strips_pass(r, 0, n, k0, slot, buf, &cnt);
        if (r->rescue)
            rt_strips_pass(r, 1, n, k0, slot, buf, &cnt);
        rt_counters_add(&slot->cnt, &cnt);
    }
    if (r->progress)
        r->progress(r->progress_ctx, (uint64_t)r->count, (uint64_t)r->count);
}

/* The report's OpenMP scheme: `collapse(2)` over the pixel loops of the
 * region, default static schedule (equal contiguous pixel ranges). */
static inline void rt_cpu_render_pixels(RtCpuPool *p, const RtSceneView *v, int x0, int y0, int x1, int y1,
                                        float *rgb)
{
#pragma omp parallel num_threads(p->nthreads)
    {
        RtCpuSlot *slot = rt_cpu_slot(p, rt_cpu_thread_id());
        RtCounters cnt;
        memset(&cnt, 0, sizeof cnt);
        rt_cpu_note(slot);
#pragma omp for collapse(2) schedule(static) nowait
        for (int j = y0; j < y1; j++)
            for (int i = x0; i < x1; i++)
                rt_cpu_render_pixel(v, i, j, rgb, &cnt);
        rt_cpu_note(slot);
        rt_counters_add(&slot->cnt, &cnt);
    }
}

/* Sums the threads' counters into *sum and appends their CPUs to `cores`
 * (sorted, unique, "0,1,5"). */
static inline void rt_cpu_pool_merge(const RtCpuPool *p, RtCounters *sum, char *cores, size_t size)
{
    memset(sum, 0, sizeof *sum);
    for (int t = 0; t < p->nthreads; t++) {
        const RtCpuSlot *s = rt_cpu_slot(p, t);
        rt_counters_add(sum, &s->cnt);
        for (int c = 0; c < RT_CPU_MAX_CPUS; c++)
            if (s->cpus[c / 64] >> (c % 64) & 1)
                rt_cores_note(cores, size, c);
    }
}

/* Appends " key=v0/v1/..." to buf: each thread's start or end of its last
 * tile loop (end: 1) in ms after t0_ns. */
static inline void rt_cpu_pool_times(const RtCpuPool *p, int end, int64_t t0_ns, const char *key, char *buf,
                                     size_t size)
{
    size_t len = strlen(buf);
    if (len < size)
        len += (size_t)snprintf(buf + len, size - len, " %s=", key);
    for (int t = 0; t < p->nthreads && len < size; t++) {
        const RtCpuSlot *s = rt_cpu_slot(p, t);
        len += (size_t)snprintf(buf + len, size - len, "%s%.3f", t ? "/" : "",
                                ((end ? s->end_ns : s->start_ns) - t0_ns) * 1e-6);
    }
}

/* When the first thread entered its last tile loop (of those that ran:
 * a runtime may start fewer, e.g. under OMP_THREAD_LIMIT). */
static inline int64_t rt_cpu_pool_start(const RtCpuPool *p)
{
    int64_t start = INT64_MAX;
    for (int t = 0; t < p->nthreads; t++)
        if (rt_cpu_slot(p, t)->start_ns > 0 && rt_cpu_slot(p, t)->start_ns < start)
            start = rt_cpu_slot(p, t)->start_ns;
    return start == INT64_MAX ? 0 : start;
}

/* When the last thread ran out of claims (its tile loop's end). */
static inline int64_t rt_cpu_pool_end(const RtCpuPool *p)
{
    int64_t end = rt_cpu_slot(p, 0)->end_ns;
    for (int t = 1; t < p->nthreads; t++)
        if (rt_cpu_slot(p, t)->end_ns > end)
            end = rt_cpu_slot(p, t)->end_ns;
    return end;
}

/* Second renders started and won, over the pool's threads (the record's
 * backups= key). */
static inline void rt_cpu_pool_backups(const RtCpuPool *p, uint64_t *runs, uint64_t *won)
{
    *runs = *won = 0;
    for (int t = 0; t < p->nthreads; t++) {
        *runs += rt_cpu_slot(p, t)->backups;
        *won += rt_cpu_slot(p, t)->backups_won;
    }
}

#endif
