/* syncstep.c: the machine's floor for one synchronised step of W workers.
 *
 * A parallel frame of W workers ends when its last worker does. The copies
 * of `harness ceiling` run for a whole one-worker render each, so a
 * millisecond that the machine takes from one core costs them a fraction
 * of it; a frame that W workers split into steps of 2 ms loses the whole
 * millisecond, and the more workers, the likelier one of them was held.
 * This is the fixed-work-quantum probe (Sottile and Minnich, "Analysis of
 * microbenchmarks for performance tuning of clusters", Cluster 2004) run
 * as the bulk-synchronous step whose noise amplification Petrini et al.
 * ("The case of the missing supercomputer performance", SC 2003) and
 * Hoefler et al. ("Characterizing the influence of system noise on
 * large-scale applications by simulation", SC 2010) describe: W threads,
 * one pinned per core, spin on a shared word; released, each does the same
 * fixed work and records its start and end. A step lasts from the first
 * start to the last end (as a frame's render_ms runs from its first
 * worker's start), and its share is the fastest worker's own time (the work
 * undisturbed, at the clock that W busy cores keep) over that span: 1 on a
 * quiet machine, less where any worker was held. The workers
 * wait spinning, so a core's wake-up from idle is not in it: sleeping is a
 * program's choice, the machine's cost is what a spinning worker still
 * loses. */
#include "config.h"
#include "run.h"

#include <pthread.h>
#include <sched.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#if HAVE_HWLOC
#include <hwloc.h>
#endif

static int64_t now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

/* Fixed work: n rounds of a xorshift, no memory but its own registers, so
 * the probe measures the cores' time and not the memory system (which the
 * copies of the ceiling already share). */
static uint64_t work(uint64_t n, uint64_t x)
{
    for (uint64_t i = 0; i < n; i++) {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
    }
    return x;
}

static inline void relax(void)
{
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_pause();
#endif
}

typedef struct {
    const HxTopo *t;
    int core;
    int id;
    struct Probe *p;
    pthread_t th;
} Worker;

typedef struct Probe {
    _Atomic int go;      /* the step released: its number (-1: none yet) */
    _Atomic int done;    /* workers finished, over all steps */
    _Atomic int ready;   /* workers that tried to bind to their cores */
    _Atomic int unbound; /* ... of whom the binding failed */
    _Atomic int stop;    /* the probe given up: workers leave before their next step */
    uint64_t rounds;   /* of work per step */
    int nsteps, nworkers;
    int64_t *start, *end; /* per step, per worker (step-major) */
    _Atomic uint64_t sink;
} Probe;

static int bind_self(const HxTopo *t, int core)
{
#if HAVE_HWLOC
    if (!t->have_hwloc)
        return -1;
    hwloc_topology_t topo = (hwloc_topology_t)t->topo;
    hwloc_obj_type_t ct = hwloc_get_nbobjs_by_type(topo, HWLOC_OBJ_CORE) > 0 ? HWLOC_OBJ_CORE : HWLOC_OBJ_PU;
    hwloc_obj_t c = hwloc_get_obj_by_type(topo, ct, (unsigned)core);
    return c ? hwloc_set_cpubind(topo, c->cpuset, HWLOC_CPUBIND_THREAD) : -1;
#else
    (void)t;
    (void)core;
    return -1;
#endif
}

/* One worker's steps: spin until step s is released, work, record. */
static void steps_of(Worker *w)
{
    Probe *p = w->p;
    const int nsteps = p->nsteps, nworkers = p->nworkers;
    uint64_t x = 88172645463325252ull + (uint64_t)w->id;
    for (int s = 0; s < nsteps; s++) {
        while (atomic_load_explicit(&p->go, memory_order_acquire) < s && !atomic_load_explicit(&p->stop, memory_order_relaxed))
            relax();
        if (atomic_load_explicit(&p->stop, memory_order_acquire))
            break;
        const int64_t a = now_ns();
        x = work(p->rounds, x);
        const int64_t b = now_ns();
        p->start[(size_t)s * (size_t)nworkers + (size_t)w->id] = a;
        p->end[(size_t)s * (size_t)nworkers + (size_t)w->id] = b;
        atomic_fetch_add_explicit(&p->done, 1, memory_order_acq_rel);
    }
    atomic_fetch_xor_explicit(&p->sink, x, memory_order_relaxed);
}

static void *worker_main(void *arg)
{
    Worker *w = arg;
    if (bind_self(w->t, w->core) != 0) /* a step with two workers on one core measures nothing */
        atomic_fetch_add_explicit(&w->p->unbound, 1, memory_order_relaxed);
    atomic_fetch_add_explicit(&w->p->ready, 1, memory_order_release);
    steps_of(w);
    return NULL;
}

/* Rounds of work() per ms on this core: the fastest of three timings of a
 * count that takes 5 ms or more. */
static double rounds_per_ms(void)
{
    uint64_t n = 1 << 14, x = 1;
    double best = 0;
    for (int tries = 0; tries < 3;) {
        const int64_t a = now_ns();
        x = work(n, x);
        const double ms = (double)(now_ns() - a) * 1e-6;
        if (ms < 5) {
            n *= 2;
            continue;
        }
        best = (double)n / ms > best ? (double)n / ms : best;
        tries++;
    }
    return best + (double)(x & 1) * 1e-12; /* x used: the loop is not dropped */
}

static int probe(const HxTopo *t, const int *cores, int w, double quantum_ms, int nsteps, HxSyncStep *out);

int hx_sync_step(const HxTopo *t, const int *cores, int w, double quantum_ms, int nsteps, HxSyncStep *out)
{
    memset(out, 0, sizeof *out);
    if (w < 1 || nsteps < 1 || !(quantum_ms > 0))
        return -1;
#if HAVE_HWLOC /* the main thread's binding, restored after (the probe binds it to cores[0]) */
    hwloc_bitmap_t was = t->have_hwloc ? hwloc_bitmap_alloc() : NULL;
    if (!was || hwloc_get_cpubind((hwloc_topology_t)t->topo, was, HWLOC_CPUBIND_THREAD) != 0) {
        hwloc_bitmap_free(was);
        return -1;
    }
    const int rc = probe(t, cores, w, quantum_ms, nsteps, out);
    hwloc_set_cpubind((hwloc_topology_t)t->topo, was, HWLOC_CPUBIND_THREAD);
    hwloc_bitmap_free(was);
    return rc;
#else
    (void)cores;
    (void)probe;
    return -1; /* no binding: no step */
#endif
}

double hx_sync_wait_ms(double quantum_ms)
{
    return 10000 + 20 * quantum_ms;
}

/* Waits until *v reaches n: spinning (the step's waits, timed) or yielding
 * (the start, not timed), for at most limit_ms, while no stop signal came.
 * 0, or -1 when it gave up. */
static int wait_for(_Atomic int *v, int n, double limit_ms, int yield)
{
    const int64_t until = now_ns() + (int64_t)(limit_ms * 1e6);
    for (unsigned i = 0; atomic_load_explicit(v, memory_order_acquire) < n; i++) {
        if (yield)
            sched_yield();
        else
            relax();
        if ((i & 1023) == 0 && (now_ns() > until || hx_stop_signal()))
            return -1;
    }
    return 0;
}

/* hx_sync_step's probe; it binds the main thread to cores[0] once the
 * workers are bound. */
static int probe(const HxTopo *t, const int *cores, int w, double quantum_ms, int nsteps, HxSyncStep *out)
{
    Probe p;
    memset(&p, 0, sizeof p);
    atomic_init(&p.go, -1);
    atomic_init(&p.done, 0);
    atomic_init(&p.ready, 0);
    atomic_init(&p.unbound, 0);
    atomic_init(&p.stop, 0);
    atomic_init(&p.sink, 0);
    p.rounds = (uint64_t)(quantum_ms * rounds_per_ms()) + 1;
    p.start = hx_xmalloc((size_t)nsteps * (size_t)w * sizeof *p.start);
    p.end = hx_xmalloc((size_t)nsteps * (size_t)w * sizeof *p.end);
    p.nsteps = nsteps;
    p.nworkers = w;
    Worker *args = hx_xmalloc((size_t)w * sizeof *args);
    int started = 1, rc = 0;
    for (int i = 0; i < w; i++)
        args[i] = (Worker){t, cores[i], i, &p, 0};
    /* The workers start where the main thread may run, bind themselves, and
     * only then is the main thread bound to cores[0]: a worker that began
     * on the core where the main thread spins would wait for it forever
     * under a real-time policy. */
    for (int i = 1; i < w && rc == 0; i++, started++)
        rc = pthread_create(&args[i].th, NULL, worker_main, &args[i]) != 0 ? -1 : 0;
    if (rc != 0)
        started--;
    if (rc == 0 && (wait_for(&p.ready, w - 1, hx_sync_wait_ms(0), 1) != 0 || atomic_load(&p.unbound) > 0 || bind_self(t, cores[0]) != 0))
        rc = -1;
    /* the main thread is worker 0: it releases the first step once every
     * worker is on its core, each next one once every worker ended the
     * last, and works it too */
    uint64_t x = 1;
    for (int s = 0; s < nsteps && rc == 0; s++) {
        if (wait_for(&p.done, s * w, hx_sync_wait_ms(quantum_ms), 0) != 0) {
            rc = -1;
            break;
        }
        atomic_store_explicit(&p.go, s, memory_order_release);
        const int64_t a = now_ns();
        x = work(p.rounds, x);
        const int64_t b = now_ns();
        p.start[(size_t)s * (size_t)w] = a;
        p.end[(size_t)s * (size_t)w] = b;
        atomic_fetch_add_explicit(&p.done, 1, memory_order_acq_rel);
    }
    if (rc != 0) /* the threads that started leave before their next step */
        atomic_store_explicit(&p.stop, 1, memory_order_release);
    for (int i = 1; i < started; i++)
        pthread_join(args[i].th, NULL);
    if (rc == 0)
        hx_sync_summarise(p.start, p.end, nsteps, w, out);
    out->sink = x ^ atomic_load(&p.sink);
    free(p.start);
    free(p.end);
    free(args);
    return rc;
}

/* Each step's share (the fastest worker's own time over the span from the
 * first start to the last end); their median into out. */
void hx_sync_summarise(const int64_t *start, const int64_t *end, int nsteps, int w, HxSyncStep *out)
{
    double *share = hx_xmalloc((size_t)nsteps * sizeof *share);
    for (int s = 0; s < nsteps; s++) {
        const int64_t *a = start + (size_t)s * (size_t)w, *b = end + (size_t)s * (size_t)w;
        int64_t first = a[0], last = b[0], own = b[0] - a[0];
        for (int i = 0; i < w; i++) {
            first = a[i] < first ? a[i] : first;
            last = b[i] > last ? b[i] : last;
            own = b[i] - a[i] < own ? b[i] - a[i] : own;
        }
        share[s] = last > first ? (double)own / (double)(last - first) : 1;
    }
    out->share = hx_median(share, (size_t)nsteps);
    out->steps = nsteps;
    free(share);
}
