/* pool.h - the threads of a large file's parse (io/scene_chunks.c) and of
 * the BVH build (accel/): a fork-join pool of POSIX threads whose idle and
 * waiting threads sleep on a condition variable at once, where OpenMP
 * runtimes spin first (libgomp up to GOMP_SPINCOUNT, 300,000 rounds, and no
 * API sets its wait policy). A build that waits for a slow thread thus
 * leaves the core to whatever else runs there. A waiting thread runs queued
 * tasks meanwhile (help-first, as OpenMP's taskwait may), so a task never
 * waits for a thread that is itself waiting.
 *
 * A pool lives for one parse or one build: the threads start with it and
 * end with it, so nothing of it runs, spins or sleeps after. A NULL pool is
 * the serial case: every call runs its work at once on the caller. */
#ifndef RT_POOL_H
#define RT_POOL_H

typedef struct RtPool RtPool;
struct PoolSleeper;

/* Tasks spawned together, waited for together. Zero-initialise. */
typedef struct PoolGroup {
    unsigned pending;
    struct PoolSleeper *waiter;
} PoolGroup;

/* A spawned task; the spawner's storage, valid until its group is waited. */
typedef struct PoolTask {
    void (*fn)(void *arg);
    void *arg;
    PoolGroup *group;
    struct PoolTask *next;
} PoolTask;

/* A pool of `threads` in all, the caller included (threads - 1 started);
 * NULL for one thread, or when not even one more can start. Fewer start
 * when the system refuses some: pool_threads says how many run. */
RtPool *pool_start(int threads);
void pool_stop(RtPool *p);
int pool_threads(const RtPool *p);

/* Queues fn(arg) in group g, in t (which the caller keeps until pool_wait);
 * without a pool it runs now. */
void pool_spawn(RtPool *p, PoolGroup *g, PoolTask *t, void (*fn)(void *arg), void *arg);
/* Returns once every task of g has run, running queued tasks meanwhile.
 * Any thread may wait (and spawn, and stop the pool once every group it
 * started is waited for). */
void pool_wait(RtPool *p, PoolGroup *g);
/* fn(ctx, i) for every i in 0..n, on as many of the pool's threads as are
 * free, the caller one of them; returns when all have run. */
void pool_for(RtPool *p, int n, void (*fn)(void *ctx, int i), void *ctx);

/* CPU time worker k (0 .. pool_threads - 2) has used, in nanoseconds; -1 if
 * unknown. For the tests: a sleeping thread's does not grow. */
long long pool_worker_cpu_ns(const RtPool *p, int k);

#endif
