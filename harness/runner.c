/* runner.c: `harness run`: execute the run matrix, one CSV row per run.
 *
 * Each run is a child in its own process group with a wall-clock deadline
 * (proc.c), started by the command line launch.c builds. A row is formatted
 * whole, written with one write() and fsync()ed before the next run starts:
 * a study killed half-way leaves only whole rows, and --resume continues it.
 * The correctness gate (gate.c) compares each run's image hash with the
 * first ok serial run of the same image. */
#include "program.h"
#include "run.h"

#include "config.h"

#include <errno.h>
#include <getopt.h>
#include <stdarg.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <dirent.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <unistd.h>

/* ---- the command ---- */

static void setf(char **vals, const char *col, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
static void setf(char **vals, const char *col, const char *fmt, ...)
{
    char buf[256];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    hx_row_set(vals, col, buf);
}

static void usage_run(FILE *f)
{
    fputs("usage: harness run CONFIG [-o FILE.csv] [--resume | --overwrite] [--dry-run]\n"
          "                  [--set KEY=VALUE]... [--raytrace PATH] [--launcher mpirun|srun]\n"
          "                  [--history DB] [--quiet]\n"
          "Expands CONFIG into runs and executes them, appending one CSV row per run.\n"
          "  -o, --output FILE   CSV to append to (default: results/STUDY.csv if results/\n"
          "                      exists, else STUDY.csv)\n"
          "      --resume        skip runs whose run_id is already in FILE; the study may\n"
          "                      grow (repeats, new swept values), not change its runs\n"
          "      --overwrite     start FILE afresh (without it, a non-empty FILE is refused)\n"
          "      --dry-run       list the runs, their command lines and planned cores\n"
          "      --set KEY=VALUE as if CONFIG's line for KEY said VALUE (repeatable):\n"
          "                      --set threads='1 2 4', --set scene_dir=DIR (relative\n"
          "                      to the current folder), --set repeats=5\n"
          "      --raytrace PATH renderer binary (else config 'raytrace:', $RAYTRACE,\n"
          "                      or ../renderer/raytrace next to the harness)\n"
          "      --launcher NAME how MPI runs start: mpirun, or srun inside a Slurm\n"
          "                      allocation (overrides the config's 'launcher:')\n"
          "      --history DB    then store the CSV in the history database DB\n"
          "                      (harness history add: a clean tree's rows only)\n"
          "  -q, --quiet         no progress lines\n"
          "  -h, --help          this text\n", f);
}

/* "scene=demo backend=openmp threads=2 ...": every dimension that has a
 * value, so that no two configurations read alike */
static void dims_text(HxBuf *b, const HxRun *r, const HxConfig *cfg)
{
    for (int d = 0; d < HX_NDIM; d++)
        if (strcmp(r->v[d], "-") != 0)
            hx_buf_printf(b, "%s%s=%s", b->len ? " " : "", hx_dim_col[d], r->v[d]);
    for (int p = 0; p < cfg->nparams; p++)
        hx_buf_printf(b, "%s%s=%s", b->len ? " " : "", cfg->params[p].name, r->pv[p]);
}

/* One progress line per run: its place in the plan, every dimension, the
 * outcome, and the time left at the mean pace so far (runs skipped by
 * --resume are left out of the pace). */
static void progress_line(const HxConfig *cfg, const HxPlan *plan, size_t i, const HxRun *r, const char *status,
                          const char *shown, const char *detail, double elapsed_ms, size_t attempted)
{
    HxBuf b = {0};
    dims_text(&b, r, cfg);
    double left_s = elapsed_ms / 1e3 / (double)attempted * (double)(plan->n - i - 1);
    char eta[32];
    if (left_s >= 3600)
        snprintf(eta, sizeof eta, "%dh%02dm", (int)(left_s / 3600), (int)(left_s / 60) % 60);
    else
        snprintf(eta, sizeof eta, "%dm%02ds", (int)(left_s / 60), (int)left_s % 60);
    fprintf(stderr, "[%zu/%zu] %s%s r%d: %s%s%s%s%s (left ~%s)\n", i + 1, plan->n, r->warmup ? "warm-up " : "",
            b.s, r->repeat, status, shown && *shown ? " " : "", shown ? shown : "",
            detail ? ": " : "", detail ? detail : "", eta);
    hx_buf_free(&b);
}

/* Notes a failed run's configuration (once) for the end-of-study summary. */
static void note_failure(HxStrList *failures, const HxConfig *cfg, const HxRun *r, const char *status,
                         const char *detail)
{
    if (strcmp(status, "ok") == 0 || strcmp(status, "refused") == 0)
        return;
    HxBuf b = {0};
    dims_text(&b, r, cfg);
    hx_buf_put(&b, ":");
    for (size_t k = 0; k < failures->n; k++)
        if (strncmp(failures->v[k], b.s, b.len) == 0) {
            hx_buf_free(&b);
            return;
        }
    hx_buf_printf(&b, " %s%s%s", status, detail && *detail ? ": " : "", detail ? detail : "");
    hx_strlist_push(failures, b.s);
    hx_buf_free(&b);
}

static int csv_has_rows(const char *path)
{
    struct stat st;
    if (stat(path, &st) != 0 || !S_ISREG(st.st_mode))
        return 0; /* hx_csv_open_append says what is wrong with it */
    FILE *f = fopen(path, "r");
    if (!f)
        return 0;
    int lines = 0, c;
    while ((c = fgetc(f)) != EOF && lines < 2)
        lines += c == '\n';
    fclose(f);
    return lines >= 2;
}

/* Everything one `harness run` holds while it runs the plan. */
typedef struct {
    HxConfig cfg;
    HxPlan plan;
    HxTopo topo;
    char *raytrace, *image, *tmpdir;
    const char *out_path;
    int fd, quiet, want_mpi;
    HxFingerprint fp;
    char chash[20];
    /* done_ids: run ids already in the CSV (--resume); timed_out: configurations
     * whose run hit the timeout; deterministic: those that ended with exit 1
     * (the renderer's answer to bad input or an option this build lacks: a
     * repeat would fail the same way); failures: one line per failing
     * configuration for the summary */
    HxStrList done_ids, timed_out, deterministic, failures;
    HxRefTable refs;
    char *workdir, *version, *metric_info; /* command studies */
    char *lost;                            /* why a node of the Slurm job is deemed lost */
    size_t nbusy, nstolen, npartial;       /* rows on a busy or stolen machine, with pinning not held */
    double max_others, max_steal;
    double t0, child_ms;
    size_t executed, skipped, attempted, nstat[6];
    HxCeilRounds *ceil; /* ceiling: rounds */
    int ceil_round;     /* the round whose ceiling was measured last, -1 none */
    const char *ceil_scene; /* of this scene */
    double ceil_ms;     /* spent measuring it, not the harness's overhead */
} Study;

static const char *const stat_names[6] = {"ok", "wrong-image", "timeout", "crash", "error", "refused"};

/* The row's cells that come before the run: provenance and the plan. */
static char **row_head(const Study *st, const HxRun *r)
{
    const HxFingerprint *fp = &st->fp;
    int cuda = hx_backend_gpu(r->v[HX_DIM_BACKEND]);
    char **vals = calloc((size_t)hx_ncolumns, sizeof *vals);
    char utc[32];
    hx_utc_now(utc, sizeof utc);
    hx_row_set(vals, "study", st->cfg.study);
    hx_row_set(vals, "run_id", r->run_id);
    setf(vals, "repeat", "%d", r->repeat);
    hx_row_set(vals, "utc", utc);
    hx_row_set(vals, "git_commit", fp->git_commit);
    hx_row_set(vals, "host", fp->host);
    hx_row_set(vals, "cpu_model", fp->cpu_model);
    setf(vals, "phys_cores", "%d", fp->phys_cores);
    setf(vals, "logical_cpus", "%d", fp->logical_cpus);
    hx_row_set(vals, "smt", fp->smt ? "on" : "off");
    hx_row_set(vals, "governor", fp->governor);
    hx_row_set(vals, "compiler", fp->compiler);
    hx_row_set(vals, "gpu_name", cuda ? fp->gpu_name : "-");
    hx_row_set(vals, "gpu_driver", cuda ? fp->gpu_driver : "-");
    hx_row_set(vals, "fingerprint", fp->fingerprint);
    hx_row_set(vals, "kernel", fp->kernel);
    hx_row_set(vals, "mpi_version", st->want_mpi ? fp->mpi_version : "-");
    hx_row_set(vals, "build_flags", fp->build_flags);
    hx_row_set(vals, "config_hash", st->chash);
    for (int d = 0; d < HX_NDIM; d++)
        hx_row_set(vals, hx_dim_col[d], r->v[d]);
    hx_row_set(vals, "scene_path", r->scene_path);
    setf(vals, "workers", "%d", r->workers);
    hx_row_set(vals, "oversubscribed", r->oversubscribed ? "1" : "0");
    hx_row_set(vals, "baseline", st->cfg.baseline);
    hx_row_set(vals, "cores_planned", r->cores_planned);
    char *params = hx_run_params(&st->cfg, r);
    hx_row_set(vals, "program", st->cfg.prog ? st->cfg.prog->name : "raytrace");
    hx_row_set(vals, "params", params);
    hx_row_set(vals, "program_version", st->version ? st->version : "-");
    hx_row_set(vals, "metric_info", st->metric_info ? st->metric_info : "");
    free(params);
    return vals;
}

static void row_free(char **vals)
{
    for (int k = 0; k < hx_ncolumns; k++)
        free(vals[k]);
    free(vals);
}

/* The first line of the child's stderr, or what stands in for it. */
static char *error_detail(const HxChildResult *res)
{
    int n;
    const char *e = hx_first_line(res->err.s, &n);
    HxBuf b = {0};
    if (n)
        hx_buf_putn(&b, e, (size_t)n);
    else if (res->code != 0)
        hx_buf_printf(&b, "exit %d, nothing on stderr", res->code);
    else
        hx_buf_put(&b, "exit 0 but no record line on stdout");
    return b.s;
}

/* The record with the instruction count of cachegrind's IMAGE.cg (its
 * "summary:" line) added as key `instructions`, into vals; 0 or -1. */
static int add_instructions(const char *image, const char *rec, char **vals)
{
    HxBuf path = {0}, text = {0};
    hx_buf_printf(&path, "%s.cg", image);
    int rc = hx_read_file(path.s, &text);
    unlink(path.s);
    hx_buf_free(&path);
    const char *sum = rc == 0 && text.s ? strstr(text.s, "\nsummary: ") : NULL;
    long long ir = sum ? atoll(sum + 10) : 0;
    hx_buf_free(&text);
    if (ir <= 0)
        return -1;
    HxBuf r = {0};
    hx_buf_printf(&r, "%s instructions=%lld", rec, ir);
    hx_record_to_row(r.s, vals);
    hx_buf_free(&r);
    return 0;
}

/* The status of a run whose child has ended (vals gets the record). */
static const char *outcome(Study *st, const HxRun *r, const char *rundir, HxChildResult *res, char **vals,
                           char **detail)
{
    HxBuf b = {0};
    if (res->timed_out) {
        hx_strlist_push(&st->timed_out, r->config_id);
        hx_buf_printf(&b, "killed after %g s (process group)", st->cfg.timeout_s);
        *detail = b.s;
        return "timeout";
    }
    if (!res->exited) {
        const char *sn = hx_signal_name(res->code);
        if (sn)
            hx_buf_put(&b, sn);
        else
            hx_buf_printf(&b, "signal %d", res->code);
        *detail = b.s;
        setf(vals, "exit_code", "%d", 128 + res->code);
        return "crash";
    }
    if (st->cfg.prog)
        return hx_program_status(&st->cfg, rundir, res, vals, detail);
    setf(vals, "exit_code", "%d", res->code);
    char *rec = res->out.s ? hx_record_find(res->out.s) : NULL;
    if (rec) /* one line: cachegrind's count goes after it */
        rec[strcspn(rec, "\n")] = '\0';
    if (res->code != 0 || !rec) {
        *detail = error_detail(res);
        if (res->code == 1)
            hx_strlist_push(&st->deterministic, r->config_id);
        return "error";
    }
    if (!st->cfg.instructions) {
        hx_record_to_row(rec, vals);
    } else if (add_instructions(st->image, rec, vals) != 0) {
        *detail = hx_strdup("no instruction count from cachegrind (is valgrind installed?)");
        return "error";
    }
    char *key = hx_image_key(r->scene_path, r->v[HX_DIM_RESOLUTION], r->v[HX_DIM_MAX_DEPTH]);
    const char *status = hx_gate(&st->refs, key, r->v[HX_DIM_BACKEND], vals[hx_column_index("image_fnv1a")],
                              r->run_id, detail);
    free(key);
    return status;
}

/* The run's noise columns, and the study's count of noisy rows. */
static void note_noise(Study *st, const HxRun *r, const HxCpuStat *before, const HxCpuStat *after,
                       const HxChildResult *res, char **vals)
{
    HxNoise n;
    hx_noise(before, after, res->wall_ms, res->have_usage ? res->user_ms + res->sys_ms : 0, st->fp.logical_cpus,
             r->workers, &n);
    if (n.load1 >= 0)
        setf(vals, "load1", "%.2f", n.load1);
    if (n.others_cores >= 0) {
        setf(vals, "others_cores", "%.2f", n.others_cores);
        setf(vals, "steal_pct", "%.2f", n.steal_pct);
        setf(vals, "iowait_pct", "%.2f", n.iowait_pct);
    }
    hx_row_set(vals, "noise", n.busy && n.stolen ? "busy,stolen" : n.busy ? "busy" : n.stolen ? "stolen" : "");
    if (!r->warmup) {
        st->nbusy += n.busy;
        st->nstolen += n.stolen;
        if (n.others_cores > st->max_others)
            st->max_others = n.others_cores;
        if (n.steal_pct > st->max_steal)
            st->max_steal = n.steal_pct;
    }
}

/* Runs r (or records why it is not run). Returns the status, NULL when a
 * SIGINT or SIGTERM cut it short (no row then). */
static const char *run_one(Study *st, const HxRun *r, char **vals, char **detail)
{
    if (!r->warmup && hx_strlist_find(&st->timed_out, r->config_id) >= 0) {
        /* a configuration that timed out once will again: record the TLE
         * for the remaining repeats instead of burning hours */
        *detail = hx_strdup("not run: an earlier repeat of this configuration timed out");
        return "timeout";
    }
    if (!r->warmup && hx_strlist_find(&st->deterministic, r->config_id) >= 0) {
        *detail = hx_strdup("not run: an earlier repeat of this configuration exited with status 1 "
                            "(bad input or option), as this one would");
        return "error";
    }
    if (r->refused) {
        HxBuf b = {0};
        int nodes = st->cfg.launcher == HX_LAUNCHER_SRUN && hx_run_is_mpi(r->v) ? hx_slurm_nodes() : 1;
        if (nodes > 1) /* srun deals the ranks out over the nodes */
            hx_buf_printf(&b, "%d workers on %d nodes: more than a node's %d physical cores (oversubscribe: refuse)",
                          r->workers, nodes, st->topo.ncores);
        else
            hx_buf_printf(&b, "%d workers > %d physical cores (oversubscribe: refuse)", r->workers, st->topo.ncores);
        *detail = b.s;
        return "refused";
    }
    char *rundir = st->cfg.prog ? hx_rundir(st->workdir, (size_t)(r - st->plan.runs)) : NULL;
    char why[512];
    if (rundir) {
        HxVars vars;
        hx_vars_of_run(&st->cfg, r, rundir, st->workdir, &vars);
        int bad = hx_program_prepare(&st->cfg, &vars, rundir, why, sizeof why);
        hx_vars_free(&vars);
        if (bad) {
            hx_rmtree(rundir);
            free(rundir);
            *detail = hx_strdup(why);
            return "error";
        }
    }
    HxCommand cmd;
    hx_build_command(&st->cfg, &st->topo, r, st->raytrace, st->image, rundir, st->workdir, &cmd);
    HxChildResult res;
    HxCpuStat before, after;
    hx_cpu_stat(&before);
    int spawned = hx_run_child(&cmd, &st->topo, r, st->cfg.timeout_s, &res);
    hx_cpu_stat(&after);
    hx_reap_strays();
    hx_command_free(&cmd);
    const char *status = NULL;
    if (hx_stop_signal()) {
        status = NULL;
    } else if (spawned != 0) {
        *detail = hx_strdup("fork/pipe failed");
        status = "error";
    } else {
        st->executed++;
        st->child_ms += res.wall_ms;
        setf(vals, "wall_ms", "%.3f", res.wall_ms);
        if (res.have_usage) {
            setf(vals, "user_ms", "%.3f", res.user_ms);
            setf(vals, "sys_ms", "%.3f", res.sys_ms);
            setf(vals, "maxrss_kib", "%ld", res.maxrss_kib);
        }
        note_noise(st, r, &before, &after, &res, vals);
        status = outcome(st, r, rundir, &res, vals, detail);
        /* a node of the job lost or the job ending, not the run failing: no
         * row, the study stops, and a resumption runs it again */
        if (hx_srun_job_gone(&st->cfg, &st->topo, r, status, &st->lost))
            status = NULL;
    }
    hx_child_result_free(&res);
    if (rundir && !st->cfg.prog->keep)
        hx_rmtree(rundir);
    free(rundir);
    return status;
}

/* A warm-up only helps when a repeat of its configuration will run. */
static int warmup_needed(const Study *st, size_t i)
{
    const HxRun *r = &st->plan.runs[i];
    if (r->refused)
        return 0;
    for (size_t k = i + 1; k < st->plan.n; k++)
        if (!st->plan.runs[k].warmup && strcmp(st->plan.runs[k].config_id, r->config_id) == 0 &&
            hx_strlist_find(&st->done_ids, st->plan.runs[k].run_id) < 0)
            return 1;
    return 0;
}

/* Runs the plan: one row per recorded run. Returns 0, or 1 when a row could
 * not be written (the study stops there). */
static int run_plan(Study *st)
{
    for (size_t i = 0; i < st->plan.n && !hx_stop_signal(); i++) {
        const HxRun *r = &st->plan.runs[i];
        if (hx_strlist_find(&st->done_ids, r->run_id) >= 0) {
            st->skipped++;
            continue;
        }
        if (r->warmup && !warmup_needed(st, i))
            continue;
        if (st->ceil && !r->warmup && (r->repeat != st->ceil_round || strcmp(r->scene_name, st->ceil_scene) != 0)) {
            /* the copies between the rounds: a drift of the machine reaches
             * the ceiling as it reaches the runs (docs/harness-noise.md) */
            st->ceil_round = r->repeat;
            st->ceil_scene = r->scene_name;
            const double c0 = hx_now_ms();
            const int bad = hx_ceiling_rounds_measure(st->ceil, r->scene_name, r->repeat, st->quiet) != 0;
            st->ceil_ms += hx_now_ms() - c0;
            if (bad && !hx_stop_signal()) {
                fprintf(stderr, "harness run: ceiling: rounds: no ceiling from round %d on; the study goes on\n",
                        r->repeat);
                hx_ceiling_rounds_close(st->ceil);
                st->ceil = NULL;
            }
            if (hx_stop_signal())
                return 0;
        }
        char **vals = row_head(st, r);
        char *detail = NULL;
        const char *status = run_one(st, r, vals, &detail);
        if (!status) { /* interrupted: no row for a run cut short */
            free(detail);
            row_free(vals);
            return st->lost ? 1 : 0;
        }
        const char *held = hx_pin_held_row(r->cores_planned, vals);
        hx_row_set(vals, "pin_held", held);
        st->npartial += !r->warmup && strcmp(status, "ok") == 0 && (!strcmp(held, "partial") || !strcmp(held, "no"));
        hx_row_set(vals, "status", status);
        hx_row_set(vals, "status_detail", detail ? detail : "");
        int rc = 0;
        if (!r->warmup && hx_csv_append_row(st->fd, (const char *const *)vals) != 0) {
            /* the study ends here: the rows before this one stay, whole */
            fprintf(stderr, "harness run: %s: write failed: %s; the study stops, the rows written so far are "
                            "intact\n", st->out_path, strerror(errno));
            rc = 1;
        } else if (!r->warmup) {
            for (int k = 0; k < 6; k++) /* the summary counts rows on disk */
                st->nstat[k] += strcmp(status, stat_names[k]) == 0;
            note_failure(&st->failures, &st->cfg, r, status, detail);
        }
        if (!st->quiet) {
            /* raytrace's render time, a command's metrics (or wall time) */
            HxBuf shown = {0};
            const char *rm = vals[hx_column_index("render_ms")], *ex = vals[hx_column_index("extra")];
            if (rm && *rm)
                hx_buf_printf(&shown, "render_ms=%s", rm);
            else if (st->cfg.prog && st->cfg.prog->nmetrics && ex && *ex)
                hx_buf_put(&shown, ex);
            else if (st->cfg.prog && vals[hx_column_index("wall_ms")])
                hx_buf_printf(&shown, "wall_ms=%s", vals[hx_column_index("wall_ms")]);
            progress_line(&st->cfg, &st->plan, i, r, status, shown.s, detail, hx_now_ms() - st->t0, ++st->attempted);
            hx_buf_free(&shown);
        }
        free(detail);
        row_free(vals);
        if (rc)
            return rc;
    }
    return 0;
}

/* --resume: the run ids already done and the image references they set. */
static int load_done(Study *st, char *err, size_t errlen)
{
    HxCsv old;
    if (hx_csv_read(st->out_path, &old, err, errlen) != 0) {
        /* resuming from a file we cannot read would run everything again */
        fprintf(stderr, "harness run: --resume: %s\n", err);
        return -1;
    }
    if (hx_resume_check(&old, &st->cfg, &st->plan, st->chash, err, errlen) != 0) {
        fprintf(stderr, "harness run: --resume: %s: %s; write to another file or use --overwrite\n",
                st->out_path, err);
        hx_csv_free(&old);
        return -1;
    }
    for (size_t i = 0; i < old.nrows; i++) {
        hx_strlist_push(&st->done_ids, hx_csv_get(&old, i, "run_id"));
        if (strcmp(hx_csv_get(&old, i, "status"), "ok") != 0)
            continue;
        char *key = hx_image_key(hx_csv_get(&old, i, "scene_path"), hx_csv_get(&old, i, "resolution"),
                              hx_csv_get(&old, i, "max_depth"));
        char *d = NULL;
        hx_gate(&st->refs, key, hx_csv_get(&old, i, "backend"), hx_csv_get(&old, i, "image_fnv1a"),
             hx_csv_get(&old, i, "run_id"), &d);
        free(d);
        free(key);
    }
    hx_csv_free(&old);
    return 0;
}

/* The summary's first line: whether the rows can be trusted, and why not
 * (docs/harness-noise.md, "Noise"). */
static void trust_line(const Study *st)
{
    size_t rows = 0;
    for (int k = 0; k < 6; k++)
        rows += st->nstat[k];
    if (!rows)
        return;
    if (!st->nbusy && !st->nstolen && !st->npartial) {
        fprintf(stderr, "harness: trusted: no row ran on a busy machine or with CPU steal, and every ok row's "
                        "pinning held\n");
        return;
    }
    HxBuf b = {0};
    if (st->nbusy)
        hx_buf_printf(&b, "%zu of %zu rows ran on a busy machine (other work up to %.1f cores)", st->nbusy, rows,
                      st->max_others);
    if (st->nstolen)
        hx_buf_printf(&b, "%s%zu with CPU steal (up to %.1f%%)", b.len ? ", " : "", st->nstolen, st->max_steal);
    if (st->npartial)
        hx_buf_printf(&b, "%s%zu ok rows whose pinning did not hold, or held in part", b.len ? ", " : "", st->npartial);
    fprintf(stderr, "harness: NOT trusted: %s; `harness table` marks them (docs/harness-noise.md, \"Noise\")\n", b.s);
    hx_buf_free(&b);
}

/* The end of a study: counts, overhead, failures. Returns the exit status. */
static int summary(const Study *st, int rc)
{
    if (hx_stop_signal()) {
        fprintf(stderr, "harness run: stopped by %s: the run in progress was ended and not recorded; continue "
                        "with --resume\n", hx_signal_name(hx_stop_signal()));
        rc = 128 + hx_stop_signal();
    } else if (st->lost) {
        fprintf(stderr, "harness run: the Slurm job cannot run on its nodes any more, a node lost or the job "
                        "ending (%s): the run in progress was not recorded and the study stops; continue with "
                        "--resume\n", st->lost);
    }
    const size_t *n = st->nstat;
    double total = hx_now_ms() - st->t0 - st->ceil_ms;
    trust_line(st);
    fprintf(stderr, "harness: %s: %zu rows (ok %zu, wrong-image %zu, timeout %zu, crash %zu, error %zu, "
                    "refused %zu), %zu skipped (resume)\n", st->out_path,
            n[0] + n[1] + n[2] + n[3] + n[4] + n[5], n[0], n[1], n[2], n[3], n[4], n[5], st->skipped);
    if (st->executed)
        fprintf(stderr, "harness: %zu child runs, %.1f ms in children, %.1f ms total: harness overhead %.3f ms "
                        "per run\n", st->executed, st->child_ms, total,
                (total - st->child_ms) / (double)st->executed);
    if (n[1])
        fprintf(stderr, "harness: warning: %zu wrong-image row(s): left out of tables and plots\n", n[1]);
    if (st->failures.n && rc == 0) {
        /* refused runs are the config's own choice, not failures */
        fprintf(stderr, "harness run: %zu configuration(s) had failed runs:\n", st->failures.n);
        for (size_t k = 0; k < st->failures.n && k < 10; k++)
            fprintf(stderr, "  %s\n", st->failures.v[k]);
        if (st->failures.n > 10)
            fprintf(stderr, "  ... and %zu more (status column of %s)\n", st->failures.n - 10, st->out_path);
        rc = 1;
    }
    return rc;
}

static void print_dry_run(const Study *st)
{
    printf("study %s: %zu runs (%d warm-up + %d repeats per configuration), %d cores\n", st->cfg.study,
           st->plan.n, st->cfg.warmup, st->cfg.repeats, st->topo.ncores);
    if (st->cfg.ceiling_rounds)
        printf("ceiling: rounds: one repeat of `harness ceiling` at each pinned worker count before each round\n");
    for (size_t i = 0; i < st->cfg.set.n; i++) /* the config as run, not as the file says */
        printf("override: --set '%s'\n", st->cfg.set.v[i]);
    for (size_t i = 0; i < st->plan.n; i++) {
        const HxRun *r = &st->plan.runs[i];
        HxCommand cmd;
        char rundir[32];
        snprintf(rundir, sizeof rundir, "RUNDIR-%04zu", i + 1);
        hx_build_command(&st->cfg, &st->topo, r, st->raytrace, "IMAGE.ppm", rundir, "WORKDIR", &cmd);
        printf("[%zu] %s%s  cores=%s%s%s\n    ", i + 1, r->warmup ? "(warm-up) " : "", r->run_id,
               r->cores_planned, r->oversubscribed ? " oversubscribed" : "", r->refused ? " REFUSED" : "");
        hx_print_command(stdout, &cmd);
        hx_command_free(&cmd);
    }
}

static void warn_plan(const Study *st)
{
    for (size_t i = 0; i < st->cfg.warnings.n; i++)
        fprintf(stderr, "%s\n", st->cfg.warnings.v[i]);
    size_t nover = 0;
    for (size_t i = 0; i < st->plan.n; i++)
        nover += st->plan.runs[i].oversubscribed && !st->plan.runs[i].warmup;
    if (nover)
        fprintf(stderr, "harness: %zu run(s) need more workers than the %d physical cores: %s\n", nover,
                st->topo.ncores, st->cfg.oversubscribe_allow
                ? "running them oversubscribed (oversubscribed=1 in the CSV)"
                : "refused (status refused; set 'oversubscribe: allow' to run them)");
    if (!st->topo.have_hwloc)
        fprintf(stderr, "harness: built without hwloc: runs are not pinned\n");
}

/* A command study's folder, version and setup. 0, or -1 (printed). */
static int program_open(Study *st)
{
    char err[1024];
    if (hx_workdir_open(&st->cfg, st->out_path, st->tmpdir, &st->workdir, err, sizeof err) != 0) {
        fprintf(stderr, "harness run: %s\n", err);
        return -1;
    }
    st->version = hx_program_version(&st->cfg);
    st->metric_info = hx_program_metric_info(&st->cfg);
    if (st->skipped + st->done_ids.n < st->plan.n && hx_program_setup(&st->cfg, st->workdir, err, sizeof err) != 0) {
        fprintf(stderr, "harness run: %s\n", err);
        return -1;
    }
    return 0;
}

/* Opens (locks) the CSV, reads what --resume skips, makes the temporary
 * folder and takes the fingerprint. Returns 0 or -1 (message printed). */
static int study_open(Study *st, int resume, int overwrite)
{
    char err[1024];
    if (!resume && !overwrite && csv_has_rows(st->out_path)) {
        fprintf(stderr, "harness run: %s already has rows; use --resume to continue it or --overwrite to start "
                        "again\n", st->out_path);
        return -1;
    }
    /* Open (and drop a torn last row) before reading what is done: a row cut
     * short must be run again, not counted as done and then deleted. */
    /* a command study's setup: runs before --overwrite empties the CSV,
     * so a setup that fails leaves its rows */
    const int later = overwrite && !resume && st->cfg.prog;
    st->fd = hx_csv_open_append(st->out_path, later ? HX_CSV_LOCK_ONLY : overwrite, err, sizeof err);
    if (st->fd < 0) {
        fprintf(stderr, "harness run: %s\n", err);
        return -1;
    }
    hx_settings_hash(&st->cfg, st->chash);
    if (resume && load_done(st, err, sizeof err) != 0)
        return -1;
    st->tmpdir = hx_temp_dir("run", err, sizeof err);
    if (!st->tmpdir) {
        fprintf(stderr, "harness run: %s\n", err);
        return -1;
    }
    st->image = hx_path_join(st->tmpdir, "image.ppm");
    hx_install_stop_handlers();
    int want_gpu = hx_config_has(&st->cfg, hx_backend_gpu);
    st->want_mpi = hx_config_has(&st->cfg, hx_backend_mpi);
    for (size_t i = 0; st->cfg.prog && i < st->plan.n; i++)
        st->want_mpi |= hx_run_is_mpi(st->plan.runs[i].v);
    /* the MPI library is mpirun's, whichever launcher starts the ranks */
    hx_fingerprint_get(&st->fp, &st->topo, want_gpu, st->cfg.prog ? NULL : st->raytrace,
                       st->want_mpi ? st->cfg.mpirun : NULL, st->out_path);
    if (st->cfg.prog && program_open(st) != 0)
        return -1;
    if (later && (st->fd = hx_csv_restart(st->fd, st->out_path, err, sizeof err)) < 0) {
        fprintf(stderr, "harness run: %s\n", err);
        return -1;
    }
    return 0;
}

/* ceiling: rounds: the copies ready, their file beside the CSV checked;
 * before study_open, which --overwrite empties the CSV in. 0 or -1. */
static int ceiling_open(Study *st, int resume)
{
    st->ceil_round = -1;
    st->ceil_scene = "";
    if (!st->cfg.ceiling_rounds)
        return 0;
    char *path = hx_ceiling_rounds_path(st->out_path);
    st->ceil = hx_ceiling_rounds_open(&st->cfg, &st->plan, &st->topo, st->raytrace, path, resume);
    free(path);
    return st->ceil ? 0 : -1;
}

static void study_close(Study *st)
{
    hx_ceiling_rounds_close(st->ceil);
    if (st->fd >= 0)
        close(st->fd);
    /* everything in it: a killed renderer may have left IMAGE.tmp.XXXXXX,
     * a command study its work folder */
    if (st->tmpdir)
        hx_rmtree(st->tmpdir);
    free(st->workdir);
    free(st->version);
    free(st->metric_info);
    free(st->lost);
    free(st->image);
    free(st->tmpdir);
    free(st->raytrace);
    hx_ref_free(&st->refs);
    hx_strlist_free(&st->done_ids);
    hx_strlist_free(&st->timed_out);
    hx_strlist_free(&st->deterministic);
    hx_strlist_free(&st->failures);
    hx_topo_free(&st->topo);
    hx_plan_free(&st->plan);
    hx_config_free(&st->cfg);
}

/* harness run's options. */
typedef struct {
    const char *out_path, *rt_opt, *history;
    HxLauncher launcher;
    int launcher_set, resume, overwrite, dry, quiet;
    HxStrList set; /* --set KEY=VALUE, in order */
} RunOpts;

/* Parses the options into o. -1: go on; else the exit status (--help 0,
 * a bad option 1). */
static int run_opts(int argc, char **argv, RunOpts *o)
{
    static const struct option lo[] = {
        {"output", required_argument, NULL, 'o'}, {"resume", no_argument, NULL, 'r'},
        {"overwrite", no_argument, NULL, 'w'}, {"dry-run", no_argument, NULL, 'n'},
        {"raytrace", required_argument, NULL, 't'}, {"quiet", no_argument, NULL, 'q'},
        {"launcher", required_argument, NULL, 'l'}, {"history", required_argument, NULL, 'H'},
        {"set", required_argument, NULL, 's'}, {"help", no_argument, NULL, 'h'}, {NULL, 0, NULL, 0}};
    int c;
    while ((c = getopt_long(argc, argv, "o:qh", lo, NULL)) != -1) {
        switch (c) {
        case 'o': o->out_path = optarg; break;
        case 'r': o->resume = 1; break;
        case 'w': o->overwrite = 1; break;
        case 'n': o->dry = 1; break;
        case 't': o->rt_opt = optarg; break;
        case 'l':
            if (hx_launcher_parse(optarg, &o->launcher)) {
                fprintf(stderr, "harness run: --launcher: expected mpirun|srun, got '%s'\n", optarg);
                return 1;
            }
            o->launcher_set = 1;
            break;
        case 'q': o->quiet = 1; break;
        case 'H': o->history = optarg; break;
        case 's': hx_strlist_push(&o->set, optarg); break; /* checked with the config */
        case 'h': usage_run(stdout); return 0;
        default: usage_run(stderr); return 1;
        }
    }
    if (optind != argc - 1) {
        fprintf(stderr, "harness run: expected one CONFIG argument (see --help)\n");
        return 1;
    }
    if (o->resume && o->overwrite) {
        fprintf(stderr, "harness run: --resume and --overwrite exclude each other\n");
        return 1;
    }
    return -1;
}

int hx_cmd_run(int argc, char **argv)
{
    RunOpts o;
    memset(&o, 0, sizeof o);
    int orc = run_opts(argc, argv, &o);
    Study st;
    memset(&st, 0, sizeof st);
    st.fd = -1;
    st.quiet = o.quiet;
    if (orc < 0 && hx_config_open_set(argv[optind], &o.set, &st.cfg) != 0)
        orc = 1;
    hx_strlist_free(&o.set);
    if (orc >= 0)
        return orc;
    if (!st.cfg.prog)
        hx_resolve_scene_cache(&st.cfg, o.out_path);
    /* the command line wins: the same config runs on a workstation with
     * mpirun and in a Slurm job (harness slurm) with srun */
    if (o.launcher_set)
        st.cfg.launcher = o.launcher;
    hx_expand(&st.cfg, &st.plan);
    hx_topo_load(&st.topo);
    hx_plan_cores(&st.topo, &st.cfg, &st.plan);
    st.raytrace = hx_find_raytrace(&st.cfg, o.rt_opt);
    /* before the CSV is opened: --overwrite empties it */
    int rc = st.cfg.ceiling_rounds && hx_ceiling_rounds_check(&st.cfg, &st.plan, &st.topo) != 0;
    if (rc == 0)
        warn_plan(&st);
    HxBuf defout = {0};
    if (rc == 0 && o.dry) {
        print_dry_run(&st);
    } else if (rc == 0 && !st.cfg.prog && access(st.raytrace, X_OK) != 0) {
        fprintf(stderr, "harness run: raytrace not executable at '%s' (set --raytrace, 'raytrace:' in the config "
                        "or $RAYTRACE)\n", st.raytrace);
        rc = 1;
    } else if (rc == 0) {
        if (!o.out_path)
            hx_buf_printf(&defout, "%s%s.csv", hx_is_dir("results") ? "results/" : "", st.cfg.study);
        st.out_path = o.out_path ? o.out_path : defout.s;
        if (ceiling_open(&st, o.resume) != 0 || study_open(&st, o.resume, o.overwrite) != 0 ||
            (st.ceil && hx_ceiling_rounds_start(st.ceil, &st.fp, st.quiet) != 0)) {
            rc = 1;
        } else {
            st.t0 = hx_now_ms();
            rc = summary(&st, run_plan(&st));
        }
    }
    study_close(&st);
    /* the finished CSV into the history (docs/harness-history.md, "History") */
    if (o.history && st.t0 > 0.0 && hx_history_add(o.history, (char **)&st.out_path, 1, 0) != 0)
        rc = 1;
    hx_buf_free(&defout);
    return rc;
}
