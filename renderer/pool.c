/* pool.c - the parse's and the BVH build's fork-join pool (pool.h). One
 * mutex guards a LIFO of queued tasks and a list of parked threads, each
 * parked on a condition variable of its own: a spawn wakes as many parked
 * threads as it queued tasks, idle workers before threads waiting for a
 * group (whose own work goes on only once the task they take is done), and
 * a group's last task wakes only its waiter, so no wake-up reaches a thread
 * with nothing to do and nothing waits by spinning. (Blocking POSIX
 * mutexes and condition variables: glibc's default mutex does not spin
 * either.)
 *
 * A wake-up is a system call and the woken thread takes tens of
 * microseconds to run, so the pool keeps them off the critical path: the
 * signals to its own threads go out after the mutex is released (each parks
 * on a sleeper that lives as long as the pool, so a late signal never
 * reaches a freed one), and a parallel loop asks only for the threads free
 * to take part: busy ones take no part in it and cost it nothing. */
#include "pool.h"

#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <time.h>

typedef struct PoolSleeper {
    pthread_cond_t cv;
    struct PoolSleeper *prev, *next;
    RtPool *pool;       /* the pool whose thread this is; NULL: a caller's, on its stack */
    int woken;
} PoolSleeper;

struct RtPool {
    pthread_mutex_t mu;
    PoolTask *head;          /* queued tasks, newest first */
    PoolSleeper *parked, *parked_last; /* idle workers first, then waiters */
    int nparked;
    /* Threads free to take a task: workers between tasks (parked or not
     * yet) and threads parked in pool_wait. A worker that just finished a
     * task counts before it parks, so a loop that follows asks for it. */
    int navail;
    int nstarting;           /* workers not yet in their loop */
    int nclaimed;            /* tasks left to those (no thread woken for them) */
    pthread_t starter;       /* the thread that started the pool: it parks on sl[0] */
    int stop;
    int nthreads;            /* the caller and the workers */
    pthread_t *workers;
    PoolSleeper *sl;         /* sl[0] the thread that started the pool, sl[k + 1] worker k */
};

/* The calling thread's sleeper, where it is one of a pool's workers. */
static _Thread_local PoolSleeper *tls_me;

/* ---- parking (p->mu held) -------------------------------------------------- */

/* Parks s until woken: an idle worker (idle) at the front of the list,
 * a thread waiting for a group at its end. */
static void park(RtPool *p, PoolSleeper *s, int idle)
{
    s->woken = 0;
    if (idle || !p->parked) {
        s->prev = NULL;
        s->next = p->parked;
        if (p->parked)
            p->parked->prev = s;
        else
            p->parked_last = s;
        p->parked = s;
    } else {
        s->next = NULL;
        s->prev = p->parked_last;
        p->parked_last->next = s;
        p->parked_last = s;
    }
    p->nparked++;
    while (!s->woken)
        pthread_cond_wait(&s->cv, &p->mu);
}

/* Takes s off the parked list and marks it woken. A sleeper of a caller's
 * own (on its stack, gone once it sees itself woken) is signalled here;
 * 1 for one of the pool's, which the caller signals after releasing the
 * mutex (its choice made now: s may not be read then). */
static int unpark(RtPool *p, PoolSleeper *s)
{
    if (s->prev)
        s->prev->next = s->next;
    else
        p->parked = s->next;
    if (s->next)
        s->next->prev = s->prev;
    else
        p->parked_last = s->prev;
    p->nparked--;
    s->woken = 1;
    if (s->pool)
        return 1;
    pthread_cond_signal(&s->cv);
    return 0;
}

#define WAKE_BATCH 64

/* Unparks up to n parked threads, then releases the mutex and signals
 * them (in batches of WAKE_BATCH, the mutex taken again between). */
static void wake_release(RtPool *p, int n)
{
    PoolSleeper *w[WAKE_BATCH];
    for (;;) {
        int k = 0, late = 0;
        while (k < n && k < WAKE_BATCH && p->parked) {
            PoolSleeper *s = p->parked;
            k++;
            if (unpark(p, s))
                w[late++] = s;
        }
        pthread_mutex_unlock(&p->mu);
        for (int i = 0; i < late; i++)
            pthread_cond_signal(&w[i]->cv);
        n -= k;
        if (k < WAKE_BATCH || n <= 0)
            return;
        pthread_mutex_lock(&p->mu);
    }
}

/* ---- running tasks ----------------------------------------------------------- */

/* Runs the newest queued task (p->mu held on entry and on return). */
static void run_one(RtPool *p)
{
    PoolTask *t = p->head;
    p->head = t->next;
    PoolGroup *g = t->group;
    pthread_mutex_unlock(&p->mu);
    t->fn(t->arg);
    pthread_mutex_lock(&p->mu);
    /* (t and g belong to g's waiter, who may return once pending is 0) */
    if (--g->pending == 0 && g->waiter && !g->waiter->woken) {
        PoolSleeper *w = g->waiter;
        if (unpark(p, w)) {
            pthread_mutex_unlock(&p->mu);
            pthread_cond_signal(&w->cv);
            pthread_mutex_lock(&p->mu);
        }
    }
}

/* arg: the worker's sleeper, which names its pool. */
static void *worker_main(void *arg)
{
    PoolSleeper *s = arg;
    RtPool *p = s->pool;
    tls_me = s;
    pthread_mutex_lock(&p->mu);
    p->nstarting--;
    if (p->nclaimed > p->nstarting) /* (this worker takes one of the tasks left to it) */
        p->nclaimed = p->nstarting > 0 ? p->nstarting : 0;
    for (;;) {
        if (p->head) {
            p->navail--;
            run_one(p);
            p->navail++;
        } else if (p->stop)
            break;
        else
            park(p, s, 1);
    }
    pthread_mutex_unlock(&p->mu);
    tls_me = NULL;
    return NULL;
}

/* ---- the API ----------------------------------------------------------------- */

RtPool *pool_start(int threads)
{
    if (threads <= 1)
        return NULL;
    RtPool *p = calloc(1, sizeof *p);
    pthread_t *w = malloc((size_t)(threads - 1) * sizeof *w);
    PoolSleeper *sl = calloc((size_t)threads, sizeof *sl);
    if (!p || !w || !sl) {
        free(p);
        free(w);
        free(sl);
        return NULL;
    }
    pthread_mutex_init(&p->mu, NULL);
    for (int k = 0; k < threads; k++) {
        pthread_cond_init(&sl[k].cv, NULL);
        sl[k].pool = p;
    }
    p->workers = w;
    p->sl = sl;
    p->nthreads = 1;
    p->starter = pthread_self();
    pthread_attr_t attr;
    const int have_attr = pthread_attr_init(&attr) == 0;
    /* The recursion nests tasks a waiting thread picks up: 16 MiB of stack
     * (address space; pages only as used), as deep as the main thread's. */
    if (have_attr)
        pthread_attr_setstacksize(&attr, (size_t)16 << 20);
    const pthread_attr_t *ap = have_attr ? &attr : NULL;
    for (int k = 0; k < threads - 1 && pthread_create(&w[k], ap, worker_main, &sl[k + 1]) == 0; k++)
        p->nthreads++;
    if (have_attr)
        pthread_attr_destroy(&attr);
    if (p->nthreads == 1) {
        pool_stop(p);
        return NULL;
    }
    pthread_mutex_lock(&p->mu);
    /* (workers take queued tasks before they first park) */
    p->navail = p->nthreads - 1;
    p->nstarting += p->nthreads - 1;
    pthread_mutex_unlock(&p->mu);
    return p;
}

void pool_stop(RtPool *p)
{
    if (!p)
        return;
    pthread_mutex_lock(&p->mu);
    p->stop = 1;
    wake_release(p, p->nthreads);
    for (int k = 0; k < p->nthreads - 1; k++)
        pthread_join(p->workers[k], NULL);
    for (int k = 0; k < p->nthreads; k++)
        pthread_cond_destroy(&p->sl[k].cv);
    pthread_mutex_destroy(&p->mu);
    free(p->workers);
    free(p->sl);
    free(p);
}

int pool_threads(const RtPool *p)
{
    return p ? p->nthreads : 1;
}

/* Queues ts[0..n) (fn and arg set) in group g; with `idle`, no more than
 * the threads free to take them (a busy thread would take its task only
 * after its own work, which the caller by then has done). Wakes as many
 * parked threads; returns n. */
static int spawn_n(RtPool *p, PoolGroup *g, PoolTask *ts, int n, int idle)
{
    pthread_mutex_lock(&p->mu);
    if (idle && n > p->navail)
        n = p->navail > 0 ? p->navail : 0;
    for (int k = 0; k < n; k++) {
        ts[k].group = g;
        ts[k].next = p->head;
        p->head = &ts[k];
    }
    g->pending += (unsigned)n;
    /* Workers still starting take tasks before they first park: as many
     * tasks as they have not been left already wake no one. */
    int left = p->nstarting - p->nclaimed;
    left = left < 0 ? 0 : (left < n ? left : n);
    p->nclaimed += left;
    wake_release(p, n - left);
    return n;
}

void pool_spawn(RtPool *p, PoolGroup *g, PoolTask *t, void (*fn)(void *arg), void *arg)
{
    if (!p) {
        fn(arg);
        return;
    }
    t->fn = fn;
    t->arg = arg;
    spawn_n(p, g, t, 1, 0);
}

void pool_wait(RtPool *p, PoolGroup *g)
{
    if (!p)
        return;
    /* A worker of p, or p's starter, parks on its sleeper in p; any other
     * thread on one of its own. */
    PoolSleeper own, *s = tls_me && tls_me->pool == p                  ? tls_me
                          : pthread_equal(pthread_self(), p->starter) ? &p->sl[0]
                                                                      : &own;
    if (s == &own) {
        pthread_cond_init(&own.cv, NULL);
        own.pool = NULL;
    }
    pthread_mutex_lock(&p->mu);
    while (g->pending) {
        if (p->head) {
            run_one(p);
            continue;
        }
        g->waiter = s;
        p->navail++;
        park(p, s, 0);
        p->navail--;
        g->waiter = NULL;
    }
    /* A spawn may have woken this thread for work it no longer takes. */
    wake_release(p, p->head ? 1 : 0);
    if (s == &own)
        pthread_cond_destroy(&own.cv);
}

/* pool_for's shared loop: each runner claims the next index until none is
 * left. */
typedef struct ForRun {
    void (*fn)(void *ctx, int i);
    void *ctx;
    int n;
    atomic_int next;
} ForRun;

static void for_runner(void *arg)
{
    ForRun *r = arg;
    for (int i; (i = atomic_fetch_add_explicit(&r->next, 1, memory_order_relaxed)) < r->n;)
        r->fn(r->ctx, i);
}

void pool_for(RtPool *p, int n, void (*fn)(void *ctx, int i), void *ctx)
{
    ForRun r = {.fn = fn, .ctx = ctx, .n = n};
    atomic_init(&r.next, 0);
    const int most = p && n > 1 ? (n < p->nthreads ? n : p->nthreads) - 1 : 0;
    PoolTask few[8], *ts = most <= 8 ? few : malloc((size_t)most * sizeof *ts);
    PoolGroup g = {0, NULL};
    int helpers = 0;
    if (most > 0 && ts) {
        for (int k = 0; k < most; k++) {
            ts[k].fn = for_runner;
            ts[k].arg = &r;
        }
        helpers = spawn_n(p, &g, ts, most, 1);
    }
    for_runner(&r);
    if (helpers > 0)
        pool_wait(p, &g);
    if (ts != few)
        free(ts);
}

long long pool_worker_cpu_ns(const RtPool *p, int k)
{
    clockid_t c;
    struct timespec ts;
    if (!p || k < 0 || k >= p->nthreads - 1 || pthread_getcpuclockid(p->workers[k], &c) != 0 ||
        clock_gettime(c, &ts) != 0)
        return -1;
    return (long long)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}
