/* test_pool.c - the parse's and the BVH build's thread pool
 * (renderer/pool.c): pool_for runs every index once on any number of
 * threads; spawned tasks and loops nest and are all waited for, also when
 * threads that are not the pool's spawn and wait in it, when pools start
 * inside pools and when another thread stops one; and no thread spins:
 * while a task sleeps, the thread waiting for it and the idle worker use
 * next to no CPU time (an OpenMP runtime's spinning waits use most of it),
 * nor does an idle pool. Also compiled under ThreadSanitizer
 * (tests/meson.build). */
#include <pthread.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

#include "pool.h"
#include "check.h"

/* The share of a wait's wall time a waiting thread may use: wake-ups, and
 * this VM's accounting, which charges a sleeping thread 0.1-0.5% of its
 * sleep. libgomp's waits spin first (up to GOMP_SPINCOUNT, 300,000 rounds of
 * `pause`): 2 threads on 2 cores, 20 waits of 5 ms, the waiting one used
 * 16-60% of the wall time. Under ThreadSanitizer every lock and wake is
 * instrumented: only the paths run. */
#define WAIT_SHARE 0.10
#ifdef __SANITIZE_THREAD__
#define TIMED 0
#else
#define TIMED 1
#endif

typedef struct Hits {
    atomic_int *hit;
} Hits;

static void hit_one(void *ctx, int i)
{
    Hits *h = ctx;
    atomic_fetch_add(&h->hit[i], 1);
}

static void check_for(int threads, int n)
{
    RtPool *p = pool_start(threads);
    atomic_int *hit = calloc((size_t)(n ? n : 1), sizeof *hit);
    Hits h = {hit};
    pool_for(p, n, hit_one, &h);
    int bad = 0;
    for (int i = 0; i < n; i++)
        bad += atomic_load(&hit[i]) != 1;
    CHECK(bad == 0, "pool_for on %d threads over %d: %d indices not run exactly once", threads, n, bad);
    free(hit);
    pool_stop(p);
}

/* A tree of tasks of the given depth, each leaf adding 1 to sum. */
typedef struct Tree {
    RtPool *p;
    int depth;
    atomic_long *sum;
} Tree;

/* Each inner node's left half a task and the right half run here (the
 * build's shape), but every third level a parallel loop of 5 whose odd
 * indices are subtrees: tasks and loops nested in each other. */
static long mixed_leaves(int depth)
{
    if (depth <= 0)
        return 1;
    if (depth % 3 == 0)
        return 2 * mixed_leaves(depth - 1) + 3;
    return 2 * mixed_leaves(depth - 1);
}

static void mixed(void *arg);

static void mixed_item(void *ctx, int i)
{
    const Tree *t = ctx;
    Tree sub = {t->p, t->depth - 1, t->sum};
    if (i % 2)
        mixed(&sub);
    else
        atomic_fetch_add(t->sum, 1);
}

static void mixed(void *arg)
{
    Tree *t = arg;
    if (t->depth <= 0) {
        atomic_fetch_add(t->sum, 1);
        return;
    }
    if (t->depth % 3 == 0) {
        pool_for(t->p, 5, mixed_item, t);
        return;
    }
    Tree left = {t->p, t->depth - 1, t->sum}, right = left;
    PoolTask task;
    PoolGroup g = {0, NULL};
    pool_spawn(t->p, &g, &task, mixed, &left);
    mixed(&right);
    pool_wait(t->p, &g);
}

/* One mixed tree of the given depth on p; whether its leaves all ran. */
static int mixed_ok(RtPool *p, int depth)
{
    atomic_long sum;
    atomic_init(&sum, 0);
    Tree t = {p, depth, &sum};
    mixed(&t);
    return atomic_load(&sum) == mixed_leaves(depth);
}

typedef struct Outside {
    RtPool *p;
    int bad;
} Outside;

static void *outside_main(void *arg)
{
    Outside *o = arg;
    for (int r = 0; r < 20; r++)
        o->bad += !mixed_ok(o->p, 9);
    return NULL;
}

/* Threads that are not the pool's spawn into it and wait in it, beside the
 * thread that started it: each waits on a sleeper of its own. */
static void check_outside(void)
{
    for (int round = 0; round < 5; round++) {
        RtPool *p = pool_start(4);
        pthread_t th[4];
        Outside o[4];
        int started = 0, bad = 0;
        for (int k = 0; k < 4; k++) {
            o[k] = (Outside){p, 0};
            started += pthread_create(&th[k], NULL, outside_main, &o[k]) == 0;
        }
        for (int r = 0; r < 20; r++)
            bad += !mixed_ok(p, 9);
        for (int k = 0; k < started; k++) {
            pthread_join(th[k], NULL);
            bad += o[k].bad;
        }
        CHECK(started == 4 && bad == 0, "a pool shared by 5 threads: %d of 100 trees lost tasks", bad);
        pool_stop(p);
    }
}

/* A task of one pool that starts, uses and stops another. */
static void nested_task(void *arg)
{
    RtPool *q = pool_start(3);
    if (mixed_ok(q, 8))
        atomic_fetch_add((atomic_long *)arg, 1);
    pool_stop(q);
}

static void *stop_main(void *arg)
{
    pool_stop(arg);
    return NULL;
}

/* Pools inside pools: the starter starts and stops a second pool, then
 * uses its first; tasks of the first start pools of their own; and the
 * first is stopped by another thread than the one that started it. */
static void check_nested(void)
{
    RtPool *a = pool_start(3), *b = pool_start(2);
    CHECK(mixed_ok(b, 8), "a second pool of the same thread lost tasks");
    pool_stop(b);
    CHECK(mixed_ok(a, 8), "a pool lost tasks after its thread started and stopped another");
    atomic_long ok;
    atomic_init(&ok, 0);
    PoolTask ts[4];
    PoolGroup g = {0, NULL};
    for (int k = 0; k < 4; k++)
        pool_spawn(a, &g, &ts[k], nested_task, &ok);
    pool_wait(a, &g);
    CHECK(atomic_load(&ok) == 4, "%ld of 4 pools started by tasks ran every task", (long)atomic_load(&ok));
    CHECK(mixed_ok(a, 8), "a pool lost tasks after its tasks' own pools");
    pthread_t th;
    CHECK(pthread_create(&th, NULL, stop_main, a) == 0 && pthread_join(th, NULL) == 0,
          "a pool stopped by another thread");
}

static long long thread_cpu_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return (long long)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

static long long wall_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (long long)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

static void sleep_ms(void *arg)
{
    const long ms = (long)(intptr_t)arg;
    struct timespec ts = {ms / 1000, (ms % 1000) * 1000000L};
    while (nanosleep(&ts, &ts) != 0)
        ;
}

/* A task that says it started, then sleeps 5 ms. */
static void started_sleep(void *arg)
{
    atomic_store((atomic_int *)arg, 1);
    sleep_ms((void *)(intptr_t)5);
}

static long long workers_cpu_ns(const RtPool *p)
{
    long long sum = 0;
    for (int k = 0; k < pool_threads(p) - 1; k++) {
        const long long c = pool_worker_cpu_ns(p, k);
        CHECK(c >= 0, "worker %d's CPU clock unreadable", k);
        sum += c;
    }
    return sum;
}

/* Three threads; 20 times one task sleeps 5 ms on a worker while the caller
 * waits for it and the other worker has nothing to do: neither may spin
 * meanwhile. Then the
 * idle pool for 100 ms. */
static void check_no_spin(void)
{
    RtPool *p = pool_start(3);
    CHECK(pool_threads(p) == 3, "pool_start(3) runs %d threads", pool_threads(p));
    if (pool_threads(p) != 3) {
        pool_stop(p);
        return;
    }
    const long long w0 = workers_cpu_ns(p), me0 = thread_cpu_ns(), t0 = wall_ns();
    for (int r = 0; r < 20; r++) {
        PoolTask task;
        PoolGroup g = {0, NULL};
        atomic_int started;
        atomic_init(&started, 0);
        pool_spawn(p, &g, &task, started_sleep, &started);
        /* (so that a worker runs it and the caller has nothing to help with) */
        while (!atomic_load(&started))
            nanosleep(&(struct timespec){0, 20000}, NULL);
        pool_wait(p, &g);
    }
    const double wall = (double)(wall_ns() - t0);
    const double waited = (double)(thread_cpu_ns() - me0), workers = (double)(workers_cpu_ns(p) - w0);
    CHECK(!TIMED || waited < WAIT_SHARE * wall, "waiting %.1f ms for tasks, the caller used %.3f ms of CPU",
          wall / 1e6, waited / 1e6);
    CHECK(!TIMED || workers < 2 * WAIT_SHARE * wall, "over %.1f ms of sleeping tasks the 2 workers used %.3f ms of CPU",
          wall / 1e6, workers / 1e6);
    const long long w1 = workers_cpu_ns(p), t1 = wall_ns();
    sleep_ms((void *)(intptr_t)100);
    const double idle = (double)(workers_cpu_ns(p) - w1), idle_wall = (double)(wall_ns() - t1);
    CHECK(!TIMED || idle < WAIT_SHARE * idle_wall, "an idle pool's workers used %.3f ms of CPU in %.1f ms",
          idle / 1e6, idle_wall / 1e6);
    pool_stop(p);
}

int main(void)
{
    CHECK(pool_start(1) == NULL && pool_threads(NULL) == 1, "one thread is no pool");
    static const int threads[] = {1, 2, 3, 8};
    static const int sizes[] = {0, 1, 2, 7, 1000};
    for (int t = 0; t < 4; t++) {
        for (int s = 0; s < 5; s++)
            check_for(threads[t], sizes[s]);
        RtPool *p = pool_start(threads[t]);
        CHECK(mixed_ok(p, 12), "tasks and loops nested on %d threads: leaves lost", threads[t]);
        pool_stop(p);
    }
    check_outside();
    check_nested();
    check_no_spin();
    return check_report("test_pool");
}
