/* ceiling_copies.c: the copies of `harness ceiling` (ceiling.c): W
 * one-worker copies of the study's workload at once, pinned one per core,
 * against one alone, and the step after them (syncstep.c). */
#include "ceiling.h"
#include "program.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

HxCeilMetric hx_ceil_metric(const HxConfig *cfg)
{
    if (!cfg->prog)
        return (HxCeilMetric){"render_ms", 0, 1};
    const HxMetric *m = cfg->prog->nmetrics > 0 ? &cfg->prog->metrics[0] : NULL;
    if (m && !hx_metric_is_size(m->name, m->unit))
        return (HxCeilMetric){m->name, m->higher, m->higher ? 0 : hx_unit_ms(m->unit)};
    return (HxCeilMetric){"wall_ms", 0, 1};
}

/* One copy started in its own process group, bound to core, its stdout and
 * stderr into out and err (a command study's metric may be in either). */
static pid_t spawn(const HxCommand *c, const HxTopo *t, int core, const char *out, const char *err)
{
    pid_t pid = fork();
    if (pid != 0)
        return pid;
    int fds[3] = {open("/dev/null", O_RDONLY), open(out, O_WRONLY | O_CREAT | O_TRUNC, 0600),
                  open(err, O_WRONLY | O_CREAT | O_TRUNC, 0600)};
    for (int fd = 0; fd < 3; fd++)
        if (fds[fd] >= 0)
            dup2(fds[fd], fd);
    for (int fd = 0; fd < 3; fd++)
        if (fds[fd] > 2)
            close(fds[fd]);
    HxRun one;
    memset(&one, 0, sizeof one);
    one.ncores = 1;
    one.cores = &core;
    hx_child_exec(c, t, &one, 1);
}

/* When raytrace's copy i rendered, in ms from the copies' start, from its
 * record: its last render ends total_ms - write_ms after its start, and its
 * timed ones (runs) take render_ms each. span[0] < 0: not known. */
static void render_span(const char *rec, double started, double render, double *span)
{
    char num[64];
    double total, write, runs = 1;
    span[0] = span[1] = -1;
    if (!hx_record_get(rec, "total_ms", num, sizeof num) || hx_parse_double(num, &total) != 0 ||
        !hx_record_get(rec, "write_ms", num, sizeof num) || hx_parse_double(num, &write) != 0)
        return;
    if (hx_record_get(rec, "runs", num, sizeof num) && (hx_parse_double(num, &runs) != 0 || runs < 1))
        runs = 1;
    span[1] = started + total - write;
    span[0] = span[1] - render * runs;
}

/* Copy i's value of the metric from its outputs (wall the copy's wall ms),
 * and for raytrace when it rendered (render_span). 0, or -1 with why. */
static int copy_value(const HxCopies *cp, int i, double started, double wall, double *v, double *span, char *why,
                      size_t n)
{
    span[0] = span[1] = -1;
    if (strcmp(cp->m.name, "wall_ms") == 0) {
        *v = wall;
        return 0;
    }
    HxBuf path = {0}, out = {0}, err = {0}, extra = {0};
    hx_buf_printf(&path, "%s/copy-%d.out", cp->tmp, i);
    int rc = hx_read_file(path.s, &out) != 0 ? -1 : 0;
    if (cp->dir) { /* a command study's metric may be in stderr too */
        path.len = 0;
        hx_buf_printf(&path, "%s/copy-%d.err", cp->tmp, i);
        rc = rc || hx_read_file(path.s, &err) != 0 ? -1 : 0;
    }
    char num[64];
    if (rc != 0) {
        snprintf(why, n, "copy %d: its output cannot be read", i);
    } else if (!cp->dir) { /* raytrace: the record's render_ms */
        char *rec = out.s ? hx_record_find(out.s) : NULL;
        if (!rec || !hx_record_get(rec, cp->m.name, num, sizeof num) || hx_parse_double(num, v) != 0)
            rc = -1, snprintf(why, n, "copy %d: no %s in its record", i, cp->m.name);
        else
            render_span(rec, started, *v, span);
    } else if (hx_program_collect(cp->cfg, cp->dir[i], &out, &err, &extra, why, n) != 0) {
        rc = -1;
    } else { /* "name=value;...", the study's metrics in order: the first */
        const char *eq = extra.s ? strchr(extra.s, '=') : NULL;
        snprintf(num, sizeof num, "%.*s", eq ? (int)strcspn(eq + 1, ";") : 0, eq ? eq + 1 : "");
        if (hx_parse_double(num, v) != 0)
            rc = -1, snprintf(why, n, "copy %d: no %s", i, cp->m.name);
    }
    if (rc == 0 && !(*v > 0))
        rc = -1, snprintf(why, n, "copy %d: %s = %g, not a positive value", i, cp->m.name, *v);
    hx_buf_free(&path);
    hx_buf_free(&out);
    hx_buf_free(&err);
    hx_buf_free(&extra);
    return rc;
}

/* How much of each copy's render the others spent rendering too (0..1),
 * into ov; -1 where a span is not known. Copies that load for different
 * times can render partly alone, and then read faster than together. */
static void overlaps(const double *span, int n, double *ov)
{
    for (int i = 0; i < n; i++) {
        const double *a = span + 2 * i;
        ov[i] = -1;
        if (a[0] < 0 || !(a[1] > a[0]))
            continue;
        double sum = 0;
        int known = 1;
        for (int j = 0; j < n && known; j++) {
            const double *b = span + 2 * j;
            known = b[0] >= 0;
            if (j != i) {
                const double lo = a[0] > b[0] ? a[0] : b[0], hi = a[1] < b[1] ? a[1] : b[1];
                sum += hi > lo ? hi - lo : 0;
            }
        }
        if (known)
            ov[i] = sum / ((double)(n - 1) * (a[1] - a[0]));
    }
}

/* Runs n copies at once on cores[0..n-1]; each one's value of the metric
 * into v and, when n > 1 and ov is not NULL, its overlap (overlaps). 0, or
 * -1 when one failed (a line on stderr). */
static int run_copies(HxCopies *cp, const HxTopo *t, const int *cores, int n, double *v, double *ov)
{
    pid_t *pid = hx_xmalloc((size_t)n * sizeof *pid);
    double t0 = hx_now_ms(), *wall = hx_xmalloc((size_t)n * sizeof *wall);
    double *started = hx_xmalloc((size_t)n * sizeof *started), *span = hx_xmalloc(2 * (size_t)n * sizeof *span);
    int bad = 0;
    /* raytrace's copies render together: from a start time past what the
     * copy alone took to load, four times over (loads contend), 0.1 s at
     * least; a copy that loads slower still starts late, and its overlap
     * shows it */
    char gate[64] = "0";
    if (!cp->dir && cp->pre > 0 && n > 1)
        snprintf(gate, sizeof gate, "%.3f", t0 + (4 * cp->pre > cp->pre + 100 ? 4 * cp->pre : cp->pre + 100));
    for (int i = 0; i < n && !cp->dir; i++) { /* the value after --start-at (build_copies) */
        HxStrList *a = &cp->c[i].argv;
        free(a->v[a->n - 1]);
        a->v[a->n - 1] = hx_strdup(gate);
    }
    for (int i = 0; i < n; i++) {
        started[i] = hx_now_ms() - t0;
        HxBuf o = {0}, e = {0};
        hx_buf_printf(&o, "%s/copy-%d.out", cp->tmp, i);
        hx_buf_printf(&e, "%s/copy-%d.err", cp->tmp, i);
        pid[i] = spawn(&cp->c[i], t, cores[i], o.s, e.s);
        if (pid[i] > 0)
            setpgid(pid[i], pid[i]); /* both sides: no race with an early kill */
        else
            bad = 1; /* no fork: nothing of this copy to read */
        hx_buf_free(&o);
        hx_buf_free(&e);
    }
    /* The stop signals and SIGCHLD held but in sigsuspend, so a stop that
     * comes between the check and the wait still wakes it. */
    sigset_t hold, old;
    sigemptyset(&hold);
    sigaddset(&hold, SIGINT);
    sigaddset(&hold, SIGTERM);
    sigaddset(&hold, SIGCHLD);
    sigprocmask(SIG_BLOCK, &hold, &old);
    for (int done = 0; done < n && !hx_stop_signal();) {
        int st, reaped = 0;
        pid_t p;
        while ((p = waitpid(-1, &st, WNOHANG)) > 0)
            for (int i = 0; i < n; i++)
                if (pid[i] == p) {
                    wall[i] = hx_now_ms() - t0;
                    bad |= !WIFEXITED(st) || WEXITSTATUS(st) != 0;
                    pid[i] = 0;
                    done++;
                    reaped++;
                }
        if (p < 0 && errno == ECHILD)
            break;
        if (!reaped && done < n)
            sigsuspend(&old);
    }
    sigprocmask(SIG_SETMASK, &old, NULL);
    if (hx_stop_signal()) { /* SIGINT or SIGTERM: no copy outlives the harness */
        for (int i = 0; i < n; i++)
            if (pid[i] > 0)
                kill(-pid[i], SIGKILL);
        hx_reap_strays();
        bad = -1;
    }
    char why[512] = "a copy of the workload failed (run the study once to see why)";
    for (int i = 0; i < n && !bad; i++)
        bad = copy_value(cp, i, started[i], wall[i], &v[i], span + 2 * i, why, sizeof why) != 0;
    if (bad > 0)
        fprintf(stderr, "harness ceiling: %s\n", why);
    if (!bad && ov && n > 1)
        overlaps(span, n, ov);
    if (!bad && n == 1)
        cp->pre = span[0] > started[0] ? span[0] - started[0] : 0;
    free(pid);
    free(wall);
    free(started);
    free(span);
    return bad ? -1 : 0;
}

int hx_copies_build(HxCopies *cp, const HxConfig *cfg, const HxTopo *t, const HxRun *one, const char *rt,
                    const char *tmp, const char *workdir, int n)
{
    char why[512];
    *cp = (HxCopies){cfg, hx_xmalloc((size_t)n * sizeof *cp->c), n, NULL, tmp, hx_ceil_metric(cfg), 0};
    memset(cp->c, 0, (size_t)n * sizeof *cp->c);
    int rc = 0;
    if (cfg->prog && mkdir(workdir, 0700) != 0)
        rc = -1, snprintf(why, sizeof why, "%s: %s", workdir, strerror(errno));
    else if (cfg->prog)
        rc = hx_program_setup(cfg, workdir, why, sizeof why);
    cp->dir = cfg->prog ? hx_xmalloc((size_t)n * sizeof *cp->dir) : NULL;
    for (int i = 0; i < n; i++) {
        HxBuf img = {0}, dir = {0};
        hx_buf_printf(&img, "%s/copy-%d.ppm", tmp, i);
        hx_buf_printf(&dir, "%s/copy-%d", cfg->prog ? workdir : tmp, i);
        if (rc == 0 && cfg->prog) {
            HxVars vars;
            hx_vars_of_run(cfg, one, dir.s, workdir, &vars);
            rc = hx_program_prepare(cfg, &vars, dir.s, why, sizeof why);
            hx_vars_free(&vars);
        }
        hx_build_command(cfg, t, one, rt, img.s, dir.s, workdir, &cp->c[i]);
        if (!cfg->prog) { /* its value set by run_copies */
            HxStrList *a = &cp->c[i].argv;
            hx_strlist_push(a, "--start-at");
            hx_strlist_push(a, "0");
            hx_command_terminate(&cp->c[i]);
        }
        hx_buf_free(&img);
        if (cp->dir)
            cp->dir[i] = dir.s;
        else
            hx_buf_free(&dir);
    }
    if (rc)
        fprintf(stderr, "harness ceiling: %s\n", why);
    return rc;
}

void hx_copies_free(HxCopies *cp)
{
    for (int i = 0; cp->c && i < cp->n; i++) {
        hx_command_free(&cp->c[i]);
        if (cp->dir)
            free(cp->dir[i]);
    }
    free(cp->c);
    free(cp->dir);
    memset(cp, 0, sizeof *cp);
}

/* The step probe (syncstep.c) after W copies ran together: each worker's work
 * per step is what W workers sharing one copy's work would each do, the
 * copies' value together / W where the metric is a time, else their wall
 * time / W; as many steps as fill the copies' time held to 0.3 to 2 s,
 * but 5 at least (longer where each step is) and 500 at most. Its share
 * into share[*n] and its work per step into quantum[*n], the CPU steal
 * over it into *stolen and *ticks. */
static void step_after(const HxCopies *cp, const HxTopo *t, const int *cores, int w, const double *v, double wall,
                       double *share, int *n, double *quantum, unsigned long long *stolen, unsigned long long *ticks)
{
    const double q = (cp->m.ms > 0 ? hx_median(v, (size_t)w) * cp->m.ms : wall) / w;
    const double fill = wall < 300 ? 300 : wall > 2000 ? 2000 : wall;
    const int steps = fill / q < 5 ? 5 : fill / q > 500 ? 500 : (int)(fill / q);
    HxCpuStat s0, s1;
    HxSyncStep st;
    hx_cpu_stat(&s0);
    if (hx_sync_step(t, cores, w, q, steps, &st) != 0) {
        if (!hx_stop_signal()) /* a stop is said by who stops */
            fprintf(stderr, "harness ceiling: W=%d: no step this repeat (a worker could not be bound to its core, "
                            "a step did not end within %.0f s, or a signal came)\n", w, hx_sync_wait_ms(q) / 1000);
        return;
    }
    hx_cpu_stat(&s1);
    quantum[*n] = q;
    share[(*n)++] = st.share;
    if (s0.ok && s1.ok) {
        *stolen += s1.steal - s0.steal;
        *ticks += hx_cpu_ticks(&s0, &s1);
    }
}

/* The W= line's figures of one worker count, and its CSV row. */
static void ceil_report(const HxCopies *cp, int w, int repeats, const HxCeilKey *key, const double *ratio,
                        const double *tog, int n, double solos, double steal, double overlap, double step,
                        double quantum, double ssteal, FILE *say, HxBuf *b)
{
    const double together = hx_median(tog, (size_t)n); /* table's pace compares a run with it directly */
    double med = hx_median(ratio, (size_t)n), lo = hx_min(ratio, (size_t)n), hi = lo;
    for (int i = 0; i < n; i++)
        hi = ratio[i] > hi ? ratio[i] : hi;
    if (say) {
        fprintf(say, "%sW=%d%s%s: each copy's %s at %.3f of a copy alone (median of %d, %.3f to %.3f; alone %.4g, "
                "together %.4g", key->round >= 0 ? "ceiling: " : "", w, key->name_scene ? " of " : "",
                key->name_scene ? key->scene : "", cp->m.name, med, n, lo, hi, solos / repeats, together);
        if (steal >= 0)
            fprintf(say, "; CPU steal %.1f%%", steal);
        if (overlap >= 0) /* below 1, the copies rendered partly alone and the ceiling reads high */
            fprintf(say, "; renders overlapping %.2f", overlap);
        if (isfinite(step)) /* the step: what a W-way split of that work keeps when all W must end */
            fprintf(say, "; a step of %.4g ms on %d cores at once keeps %.3f (CPU steal %.1f%%)", quantum, w, step,
                    ssteal);
        fprintf(say, ")\n");
        fflush(say);
    }
    hx_buf_printf(b, "%s,%s,%d,%d,%.4f,%.4f,%.4f,%.6g,", key->fp->fingerprint, key->fp->host, w, repeats, med, lo,
                  hi, solos / repeats);
    hx_csv_field(b, key->config);
    hx_buf_put(b, ",");
    hx_csv_field(b, cp->m.name);
    hx_buf_printf(b, ",%.2f,%.3f,%.6g,%.4f,%.6g,", steal, overlap, together, step, quantum);
    if (key->round >= 0)
        hx_buf_printf(b, "%d", key->round);
    hx_buf_put(b, ",");
    hx_csv_field(b, key->scene);
    hx_buf_put(b, "\n");
}

int hx_copies_measure(HxCopies *cp, const HxTopo *t, int w, const int *cores, int repeats, const HxCeilKey *key,
                      FILE *say, HxBuf *b)
{
    int n = 0, nstep = 0, bad = 0;
    double *ratio = hx_xmalloc((size_t)(w * repeats) * sizeof *ratio), *v = hx_xmalloc((size_t)w * sizeof *v);
    double *ov = hx_xmalloc((size_t)w * sizeof *ov), *ovs = hx_xmalloc((size_t)(w * repeats) * sizeof *ovs);
    double *tog = hx_xmalloc((size_t)(w * repeats) * sizeof *tog);
    double solo = 0, solos = 0, *sshare = hx_xmalloc((size_t)repeats * sizeof *sshare),
           *squant = hx_xmalloc((size_t)repeats * sizeof *squant);
    size_t nov = 0;
    /* the CPU time the hypervisor took while the copies ran together: a
     * study's runs with more steal than this lose more than the ceiling */
    unsigned long long stolen = 0, ticks = 0, sstolen = 0, sticks = 0;
    for (int r = 0; r < repeats && !bad; r++) {
        /* alone, then all at once: a slow phase of the machine hits both */
        HxCpuStat s0, s1;
        bad = run_copies(cp, t, cores, 1, &solo, NULL) != 0;
        hx_cpu_stat(&s0);
        const double t0 = hx_now_ms();
        bad = bad || run_copies(cp, t, cores, w, v, ov) != 0;
        const double wall = hx_now_ms() - t0;
        hx_cpu_stat(&s1);
        if (bad)
            break;
        step_after(cp, t, cores, w, v, wall, sshare, &nstep, squant, &sstolen, &sticks);
        if (hx_stop_signal()) { /* the step cut short: no row of it */
            bad = 1;
            break;
        }
        for (int i = 0; i < w; i++)
            if (ov[i] >= 0)
                ovs[nov++] = ov[i];
        if (s0.ok && s1.ok) {
            stolen += s1.steal - s0.steal;
            ticks += hx_cpu_ticks(&s0, &s1);
        }
        solos += solo;
        for (int i = 0; i < w; i++) {
            tog[n] = v[i];
            ratio[n++] = cp->m.higher ? v[i] / solo : solo / v[i];
        }
    }
    if (!bad)
        ceil_report(cp, w, repeats, key, ratio, tog, n, solos, ticks ? 100.0 * (double)stolen / (double)ticks : -1,
                    nov ? hx_median(ovs, nov) : -1, nstep ? hx_median(sshare, (size_t)nstep) : NAN,
                    nstep ? hx_median(squant, (size_t)nstep) : NAN,
                    sticks ? 100.0 * (double)sstolen / (double)sticks : 0.0, say, b);
    free(sshare);
    free(squant);
    free(ratio);
    free(tog);
    free(v);
    free(ov);
    free(ovs);
    return bad ? -1 : 0;
}
