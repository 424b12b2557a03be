/* watch.c: which CPUs a run's threads use, for any program.
 *
 * raytrace reports the cores its threads ran on; another program does not,
 * so while it runs the harness looks at every thread of the run's processes
 * every 20 ms: field 39 of /proc/PID/task/TID/stat is the CPU the thread
 * last ran on (proc(5)). The union over the run, each CPU mapped to its
 * core, is the run's cores_actual, checked against the plan as for raytrace
 * (hx_pin_held). Launchers (mpirun, srun) are not bound themselves, so only
 * the processes running the program count; a run where none was seen (a
 * wrapper script) counts all of its processes. */
#include "run.h"

#include <dirent.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define MAX_CPUS 8192

struct HxWatch {
    pid_t root;
    int any;             /* not only descendants: srun's tasks are slurmstepd's */
    long long since;     /* the root's start (clock ticks after boot) */
    char exe[256];
    double t0;
    unsigned char matched[MAX_CPUS / 8], all[MAX_CPUS / 8];
    int nmatched;
    pid_t *pid, *ppid;   /* this sample's process table */
    size_t n, cap;
};

HxWatch *hx_watch_new(pid_t pid, const char *exe, int any)
{
    HxWatch *w = calloc(1, sizeof *w);
    if (!w)
        return NULL;
    w->root = pid;
    w->any = any && exe && *exe;
    w->since = -1;
    snprintf(w->exe, sizeof w->exe, "%s", exe ? exe : "");
    w->t0 = hx_now_ms();
    return w;
}

/* The fields after the command name of /proc/.../stat (which may hold
 * spaces and parentheses), or NULL. */
static char *stat_fields(const char *path, char *buf, size_t n)
{
    FILE *f = fopen(path, "r");
    if (!f)
        return NULL;
    size_t got = fread(buf, 1, n - 1, f);
    fclose(f);
    buf[got] = '\0';
    char *close = strrchr(buf, ')');
    return close && close[1] == ' ' ? close + 2 : NULL;
}

/* Field k (1-based, as in proc(5)) given the fields from field 3 on. */
static long stat_field(const char *from3, int k)
{
    const char *p = from3;
    for (int i = 3; i < k && p; i++) {
        p = strchr(p, ' ');
        if (p)
            p++;
    }
    return p ? strtol(p, NULL, 10) : -1;
}

/* Start time (field 22) of a process, -1 when gone. */
static long long start_of(pid_t pid)
{
    char path[64], buf[1024];
    snprintf(path, sizeof path, "/proc/%d/stat", (int)pid);
    const char *f = stat_fields(path, buf, sizeof buf);
    const char *p = f;
    for (int i = 3; i < 22 && p; i++) {
        p = strchr(p, ' ');
        if (p)
            p++;
    }
    return p ? strtoll(p, NULL, 10) : -1;
}

static void table_add(HxWatch *w, pid_t pid, pid_t ppid)
{
    if (w->n == w->cap) {
        w->cap = w->cap ? 2 * w->cap : 256;
        w->pid = hx_xrealloc(w->pid, w->cap * sizeof *w->pid);
        w->ppid = hx_xrealloc(w->ppid, w->cap * sizeof *w->ppid);
    }
    w->pid[w->n] = pid;
    w->ppid[w->n++] = ppid;
}

static int in_list(const pid_t *l, size_t n, pid_t p)
{
    for (size_t i = 0; i < n; i++)
        if (l[i] == p)
            return 1;
    return 0;
}

/* The root and its descendants in this sample's table, into desc (at most
 * max); their number. A run has a handful of processes, the table some
 * hundreds: a few passes over it. */
static size_t descendants(const HxWatch *w, pid_t *desc, size_t max)
{
    size_t nd = 0;
    desc[nd++] = w->root;
    for (int grew = 1; grew && nd < max;) {
        grew = 0;
        for (size_t i = 0; i < w->n && nd < max; i++)
            if (in_list(desc, nd, w->ppid[i]) && !in_list(desc, nd, w->pid[i])) {
                desc[nd++] = w->pid[i];
                grew = 1;
            }
    }
    return nd;
}

static void note_threads(HxWatch *w, pid_t pid, int matched)
{
    char path[64], buf[1024];
    snprintf(path, sizeof path, "/proc/%d/task", (int)pid);
    DIR *d = opendir(path);
    if (!d)
        return;
    struct dirent *e;
    while ((e = readdir(d)) != NULL) {
        if (e->d_name[0] < '0' || e->d_name[0] > '9')
            continue;
        snprintf(path, sizeof path, "/proc/%d/task/%.16s/stat", (int)pid, e->d_name);
        const char *f = stat_fields(path, buf, sizeof buf);
        long cpu = f ? stat_field(f, 39) : -1;
        if (cpu < 0 || cpu >= MAX_CPUS)
            continue;
        w->all[cpu / 8] |= (unsigned char)(1u << (cpu % 8));
        if (matched)
            w->matched[cpu / 8] |= (unsigned char)(1u << (cpu % 8));
    }
    closedir(d);
}

/* Whether the process runs the watched program. */
static int runs_exe(const HxWatch *w, pid_t pid)
{
    char path[64], target[4096];
    snprintf(path, sizeof path, "/proc/%d/exe", (int)pid);
    ssize_t n = readlink(path, target, sizeof target - 1);
    if (n <= 0)
        return 0;
    target[n] = '\0';
    const char *base = strrchr(target, '/');
    return strcmp(base ? base + 1 : target, w->exe) == 0;
}

void hx_watch_sample(HxWatch *w)
{
    if (!w)
        return;
    DIR *d = opendir("/proc");
    if (!d)
        return;
    w->n = 0;
    char path[64], buf[1024];
    struct dirent *e;
    while ((e = readdir(d)) != NULL) {
        if (e->d_name[0] < '1' || e->d_name[0] > '9')
            continue;
        pid_t pid = (pid_t)atol(e->d_name);
        snprintf(path, sizeof path, "/proc/%d/stat", (int)pid);
        const char *f = stat_fields(path, buf, sizeof buf);
        if (f)
            table_add(w, pid, (pid_t)stat_field(f, 4));
    }
    closedir(d);
    /* the first moments are the harness's own fork, not yet bound */
    int settled = hx_now_ms() - w->t0 > 5.0;
    pid_t desc[1024];
    size_t nd = descendants(w, desc, sizeof desc / sizeof desc[0]);
    if (w->any) {
        /* the program's processes started since the run began, wherever
         * they hang in the tree */
        if (w->since < 0)
            w->since = start_of(w->root);
        for (size_t i = 0; i < w->n && nd < sizeof desc / sizeof desc[0]; i++)
            if (!in_list(desc, nd, w->pid[i]) && runs_exe(w, w->pid[i]) && w->since >= 0 &&
                start_of(w->pid[i]) >= w->since)
                desc[nd++] = w->pid[i];
    }
    for (size_t i = 0; i < nd; i++) {
        int m = w->exe[0] && runs_exe(w, desc[i]);
        if (m || settled)
            note_threads(w, desc[i], m);
        w->nmatched += m;
    }
}

char *hx_watch_end(HxWatch *w, const HxTopo *topo)
{
    if (!w)
        return NULL;
    const unsigned char *set = w->nmatched ? w->matched : w->all;
    /* each CPU as its core's first CPU, as the plan names cores */
    int *core_of = calloc(MAX_CPUS, sizeof *core_of);
    for (int c = 0; core_of && topo && c < topo->ncores; c++)
        for (const char *p = topo->core_pus ? topo->core_pus[c] : NULL; p && *p;) {
            long cpu = strtol(p, NULL, 10);
            if (cpu >= 0 && cpu < MAX_CPUS)
                core_of[cpu] = topo->core_os[c] + 1;
            p = strchr(p, ',');
            p = p ? p + 1 : NULL;
        }
    unsigned char seen[MAX_CPUS / 8] = {0};
    for (int cpu = 0; cpu < MAX_CPUS; cpu++)
        if (set[cpu / 8] & (1u << (cpu % 8))) {
            int c = core_of && core_of[cpu] ? core_of[cpu] - 1 : cpu;
            seen[c / 8] |= (unsigned char)(1u << (c % 8));
        }
    HxBuf b = {0};
    for (int c = 0; c < MAX_CPUS; c++)
        if (seen[c / 8] & (1u << (c % 8)))
            hx_buf_printf(&b, "%s%d", b.len ? "," : "", c);
    free(core_of);
    free(w->pid);
    free(w->ppid);
    free(w);
    return b.s;
}
