/* pool.c - the BVH build's fork-join pool (pool.h). One mutex guards a LIFO
 * of queued tasks and a list of parked threads, each parked on a condition
 * variable of its own: a spawn wakes one parked thread, a group's last task
 * wakes only its waiter, so no wake-up reaches a thread with nothing to do
 * and nothing waits by spinning. (Blocking POSIX mutexes and condition
 * variables: glibc's default mutex does not spin either.) */
#include "pool.h"

#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <time.h>

typedef struct PoolSleeper {
    pthread_cond_t cv;
    struct PoolSleeper *prev, *next;
    int woken;
} PoolSleeper;

struct RtPool {
    pthread_mutex_t mu;
    PoolTask *head;          /* queued tasks, newest first */
    PoolSleeper *parked;     /* parked threads, the latest first */
    int stop;
    int nthreads;            /* the caller and the workers */
    pthread_t *workers;
};

/* ---- parking (p->mu held) -------------------------------------------------- */

static void park(RtPool *p, PoolSleeper *s)
{
    s->woken = 0;
    s->prev = NULL;
    s->next = p->parked;
    if (p->parked)
        p->parked->prev = s;
    p->parked = s;
    while (!s->woken)
        pthread_cond_wait(&s->cv, &p->mu);
}

static void unpark(RtPool *p, PoolSleeper *s)
{
    if (s->prev)
        s->prev->next = s->next;
    else
        p->parked = s->next;
    if (s->next)
        s->next->prev = s->prev;
    s->woken = 1;
    pthread_cond_signal(&s->cv);
}

/* Wakes up to n parked threads for queued work. */
static void wake(RtPool *p, int n)
{
    while (n-- > 0 && p->parked)
        unpark(p, p->parked);
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
    if (--g->pending == 0 && g->waiter && !g->waiter->woken)
        unpark(p, g->waiter);
}

static void *worker_main(void *arg)
{
    RtPool *p = arg;
    PoolSleeper s;
    pthread_cond_init(&s.cv, NULL);
    pthread_mutex_lock(&p->mu);
    for (;;) {
        if (p->head)
            run_one(p);
        else if (p->stop)
            break;
        else
            park(p, &s);
    }
    pthread_mutex_unlock(&p->mu);
    pthread_cond_destroy(&s.cv);
    return NULL;
}

/* ---- the API ----------------------------------------------------------------- */

RtPool *pool_start(int threads)
{
    if (threads <= 1)
        return NULL;
    RtPool *p = calloc(1, sizeof *p);
    pthread_t *w = malloc((size_t)(threads - 1) * sizeof *w);
    if (!p || !w) {
        free(p);
        free(w);
        return NULL;
    }
    pthread_mutex_init(&p->mu, NULL);
    p->workers = w;
    p->nthreads = 1;
    pthread_attr_t attr;
    const int have_attr = pthread_attr_init(&attr) == 0;
    /* The recursion nests tasks a waiting thread picks up: 16 MiB of stack
     * (address space; pages only as used), as deep as the main thread's. */
    if (have_attr)
        pthread_attr_setstacksize(&attr, (size_t)16 << 20);
    for (int k = 0; k < threads - 1; k++) {
        if (pthread_create(&w[k], have_attr ? &attr : NULL, worker_main, p) != 0)
            break;
        p->nthreads++;
    }
    if (have_attr)
        pthread_attr_destroy(&attr);
    if (p->nthreads == 1) {
        pool_stop(p);
        return NULL;
    }
    return p;
}

void pool_stop(RtPool *p)
{
    if (!p)
        return;
    pthread_mutex_lock(&p->mu);
    p->stop = 1;
    wake(p, p->nthreads);
    pthread_mutex_unlock(&p->mu);
    for (int k = 0; k < p->nthreads - 1; k++)
        pthread_join(p->workers[k], NULL);
    pthread_mutex_destroy(&p->mu);
    free(p->workers);
    free(p);
}

int pool_threads(const RtPool *p)
{
    return p ? p->nthreads : 1;
}

/* Queues n tasks ts[0..n) of group g running fn on args[k] (p->mu not held). */
static void spawn_n(RtPool *p, PoolGroup *g, PoolTask *ts, int n, void (*fn)(void *), void *const *args)
{
    pthread_mutex_lock(&p->mu);
    for (int k = 0; k < n; k++) {
        ts[k].fn = fn;
        ts[k].arg = args ? args[k] : ts[k].arg;
        ts[k].group = g;
        ts[k].next = p->head;
        p->head = &ts[k];
    }
    g->pending += (unsigned)n;
    wake(p, n);
    pthread_mutex_unlock(&p->mu);
}

void pool_spawn(RtPool *p, PoolGroup *g, PoolTask *t, void (*fn)(void *arg), void *arg)
{
    if (!p) {
        fn(arg);
        return;
    }
    spawn_n(p, g, t, 1, fn, &arg);
}

void pool_wait(RtPool *p, PoolGroup *g)
{
    if (!p)
        return;
    PoolSleeper s;
    pthread_cond_init(&s.cv, NULL);
    pthread_mutex_lock(&p->mu);
    while (g->pending) {
        if (p->head) {
            run_one(p);
            continue;
        }
        g->waiter = &s;
        park(p, &s);
        g->waiter = NULL;
    }
    /* A spawn may have woken this thread for work it no longer takes. */
    if (p->head)
        wake(p, 1);
    pthread_mutex_unlock(&p->mu);
    pthread_cond_destroy(&s.cv);
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
    const int helpers = p && n > 1 ? (n < p->nthreads ? n : p->nthreads) - 1 : 0;
    PoolTask few[8], *ts = helpers <= 8 ? few : malloc((size_t)helpers * sizeof *ts);
    PoolGroup g = {0, NULL};
    if (helpers > 0 && ts) {
        for (int k = 0; k < helpers; k++)
            ts[k].arg = &r;
        spawn_n(p, &g, ts, helpers, for_runner, NULL);
    }
    for_runner(&r);
    if (helpers > 0 && ts)
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
