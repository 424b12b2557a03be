/* noise.c: what else the machine did while a run ran.
 *
 * /proc/stat's first line (proc(5): CPU time of all CPUs in clock ticks, by
 * kind) read before and after the run gives the CPU time everything used
 * during it; less the run's own (wait4's user and system time) it is the
 * other work, in cores. Its steal column is the time the hypervisor gave
 * this VM's CPUs to someone else, a cloud machine's noise, and iowait the
 * time CPUs idled waiting for I/O. /proc/loadavg gives the 1-minute load at
 * the start. A run is marked busy when the other work competed for its
 * cores, and stolen when steal took a noticeable share. */
#include "run.h"

#include <math.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

void hx_cpu_stat(HxCpuStat *s)
{
    memset(s, 0, sizeof *s);
    FILE *f = fopen("/proc/stat", "r");
    unsigned long long v[8] = {0};
    if (f) {
        s->ok = fscanf(f, "cpu %llu %llu %llu %llu %llu %llu %llu %llu", &v[0], &v[1], &v[2], &v[3], &v[4], &v[5],
                       &v[6], &v[7]) == 8;
        fclose(f);
    }
    /* user nice system idle iowait irq softirq steal */
    s->busy = v[0] + v[1] + v[2] + v[5] + v[6];
    s->idle = v[3];
    s->iowait = v[4];
    s->steal = v[7];
    f = fopen("/proc/loadavg", "r");
    if (!f || fscanf(f, "%lf", &s->load1) != 1)
        s->load1 = -1;
    if (f)
        fclose(f);
}

/* A counter's ticks from a to b. iowait can go down (proc(5)), and an
 * unsigned difference would then wrap to near 2^64. */
static unsigned long long ticks(unsigned long long a, unsigned long long b)
{
    return b > a ? b - a : 0;
}

unsigned long long hx_cpu_ticks(const HxCpuStat *a, const HxCpuStat *b)
{
    return ticks(a->busy, b->busy) + ticks(a->idle, b->idle) + ticks(a->iowait, b->iowait) +
           ticks(a->steal, b->steal);
}

void hx_noise(const HxCpuStat *a, const HxCpuStat *b, double wall_ms, double own_cpu_ms, int cpus, int workers,
              HxNoise *n)
{
    memset(n, 0, sizeof *n);
    n->load1 = a->load1;
    n->others_cores = n->steal_pct = n->iowait_pct = -1;
    unsigned long long busy = ticks(a->busy, b->busy), steal = ticks(a->steal, b->steal),
                       iowait = ticks(a->iowait, b->iowait);
    unsigned long long total = hx_cpu_ticks(a, b);
    if (!a->ok || !b->ok || total == 0 || !(wall_ms > 0))
        return;
    double tick_ms = 1000.0 / (double)sysconf(_SC_CLK_TCK);
    n->others_cores = ((double)busy * tick_ms - own_cpu_ms) / wall_ms;
    if (n->others_cores < 0)
        n->others_cores = 0;
    n->steal_pct = 100.0 * (double)steal / (double)total;
    n->iowait_pct = 100.0 * (double)iowait / (double)total;
    /* A steal of 2% is already what makes cloud runners' numbers wander.
     * Each CPU's count is off by up to a tick, so the share is off by about
     * tick / wall / sqrt(cpus): a steal counts when it is above 2% by more
     * than that, so a 60 ms run of 64 CPUs with a third of its time stolen
     * is flagged, and a short one on 2 CPUs is not judged on a tick or two. */
    const double err_pct = 100.0 * tick_ms / (wall_ms * sqrt(cpus > 0 ? (double)cpus : 1.0));
    n->stolen = n->steal_pct >= 2.0 + err_pct;
    /* below 0.2 s the ticks are too coarse to count other work in cores;
     * above, half a core or more that left the run fewer free CPUs than it
     * has workers is competition */
    if (wall_ms < 200.0)
        return;
    n->busy = n->others_cores >= 0.5 && n->others_cores + workers > 0.9 * cpus;
}
