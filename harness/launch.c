/* launch.c: the command line of one run of `harness run`.
 *
 * The MPI launcher in front (mpirun, or srun inside a Slurm allocation),
 * valgrind's cachegrind for instruction counts, the renderer's options from
 * the run's dimensions, and the environment that pins OpenMP threads and
 * orders the GPUs. --dry-run prints the same command lines the runs get. */
#include "program.h"
#include "run.h"

#include <errno.h>
#include <pwd.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <unistd.h>

/* dir as a private folder (0700), made with its parent if missing (an
 * existing one is kept as it is: raytrace refuses one that others can
 * write). 0 when dir is a folder now. */
static int private_dir(const char *parent, const char *dir)
{
    if (mkdir(parent, 0700) != 0 && errno != EEXIST)
        return -1;
    return mkdir(dir, 0700) == 0 || hx_is_dir(dir) ? 0 : -1;
}

/* Resolves cfg->scene_cache once per study (docs/harness.md, "Scene
 * cache"): kept as the config gives it (a directory, or "off"), else the
 * first of $XDG_CACHE_HOME/raybench, $HOME/.cache/raybench and
 * ~/.cache/raybench with ~ the user's home in the password database that
 * can be made; else (no home: a service user) a new private folder
 * raybench-cache-XXXXXX beside the study's CSV. Never a fixed name in /tmp,
 * which another user could create first and fill. hx_build_command only reads
 * the result. */
void hx_resolve_scene_cache(HxConfig *cfg, const char *out_path)
{
    if (cfg->scene_cache)
        return;
    const char *x = getenv("XDG_CACHE_HOME"), *home = getenv("HOME");
    struct passwd *pw = getpwuid(getuid());
    const char *base[3] = {x, home, pw ? pw->pw_dir : NULL};
    HxBuf parent = {0}, dir = {0};
    for (int i = 0; i < 3 && !cfg->scene_cache; i++) {
        if (!base[i] || base[i][0] != '/' || (i > 0 && !hx_is_dir(base[i])))
            continue;
        parent.len = dir.len = 0;
        hx_buf_printf(&parent, i == 0 ? "%s" : "%s/.cache", base[i]);
        hx_buf_printf(&dir, "%s/raybench", parent.s);
        if (private_dir(parent.s, dir.s) == 0)
            cfg->scene_cache = hx_strdup(dir.s);
    }
    if (!cfg->scene_cache) {
        /* the CSV's folder: -o's, else the default's (results/ or here) */
        char *folder = out_path ? hx_dirname(out_path) : hx_strdup(hx_is_dir("results") ? "results" : ".");
        dir.len = 0;
        hx_buf_printf(&dir, "%s/raybench-cache-XXXXXX", folder);
        free(folder);
        char *abs = mkdtemp(dir.s) ? realpath(dir.s, NULL) : NULL; /* runs may start elsewhere */
        if (abs) {
            cfg->scene_cache = abs;
        } else {
            fprintf(stderr, "harness run: no cache folder (no home, and %s: %s): runs without the scene cache\n",
                    dir.s, strerror(errno));
            cfg->scene_cache = hx_strdup("off");
        }
    }
    hx_buf_free(&parent);
    hx_buf_free(&dir);
}

/* The run's rankfile beside its image; argv gets --rankfile FILE. 0, or -1
 * (the caller maps ranks itself). Takes rf. */
static int write_rankfile(const char *image, char *rf, HxCommand *c)
{
    HxBuf path = {0};
    hx_buf_printf(&path, "%s.rankfile", image);
    FILE *f = fopen(path.s, "w");
    int bad = !f || fputs(rf, f) == EOF;
    if (f)
        bad |= fclose(f) != 0;
    free(rf);
    if (!bad) {
        hx_strlist_push(&c->argv, "--rankfile");
        hx_strlist_push(&c->argv, path.s);
    }
    hx_buf_free(&path);
    return bad ? -1 : 0;
}

/* srun in front of the renderer (MPI runs inside a Slurm allocation). */
static void srun_launcher(const HxRun *r, int pinned, HxCommand *c)
{
    /* Inside a Slurm allocation srun places and binds the ranks: each
     * task gets T consecutive cores (--cpus-per-task, block:block keeps
     * a rank's cores and consecutive ranks together, like mpirun's
     * slot:PE=T), and OpenMP pins its threads one per core inside them.
     * Slurm >= 22.05 no longer hands the job's --cpus-per-task to srun,
     * so it is given on the command line and in SRUN_CPUS_PER_TASK
     * (which a nested srun would read). */
    const char *t = strcmp(r->v[HX_DIM_THREADS], "-") != 0 ? r->v[HX_DIM_THREADS] : "1";
    HxBuf a = {0};
    hx_strlist_push(&c->argv, "srun");
    hx_buf_printf(&a, "--ntasks=%s", r->v[HX_DIM_RANKS][0] == '-' ? "1" : r->v[HX_DIM_RANKS]);
    hx_strlist_push(&c->argv, a.s);
    a.len = 0;
    hx_buf_printf(&a, "--cpus-per-task=%s", t);
    hx_strlist_push(&c->argv, a.s);
    hx_buf_free(&a);
    hx_strlist_push(&c->argv, pinned ? "--cpu-bind=cores" : "--cpu-bind=none");
    hx_strlist_push(&c->argv, "--distribution=block:block");
    if (hx_backend_gpu(r->v[HX_DIM_BACKEND])) { /* a GPU per rank, the one nearest its cores */
        hx_strlist_push(&c->argv, "--gpus-per-task=1");
        hx_strlist_push(&c->argv, "--gpu-bind=closest");
    }
    /* without it srun refuses (or waits for) more CPUs than allocated */
    if (r->oversubscribed)
        hx_strlist_push(&c->argv, "--overcommit");
    hx_strlist_push(&c->env, "OMP_NUM_THREADS");
    hx_strlist_push(&c->env, t);
    if (pinned) {
        /* pin none leaves placement to the OS, for threads as well */
        hx_strlist_push(&c->env, "OMP_PLACES");
        hx_strlist_push(&c->env, "cores");
        hx_strlist_push(&c->env, "OMP_PROC_BIND");
        hx_strlist_push(&c->env, "close");
    }
    hx_strlist_push(&c->env, "SRUN_CPUS_PER_TASK");
    hx_strlist_push(&c->env, t);
}

/* mpirun in front of the renderer (MPI runs otherwise). */
static void mpirun_launcher(const HxConfig *cfg, const HxTopo *topo, const HxRun *r, const char *image,
                            int pinned, HxCommand *c)
{
    /* mpirun binds its ranks itself; binding mpirun would only shrink
     * the set it maps into. close = --map-by core, spread = --map-by
     * socket: the orders topo.c plans with. */
    hx_strlist_push(&c->argv, cfg->mpirun);
    if (r->oversubscribed)
        hx_strlist_push(&c->argv, "--oversubscribe");
    hx_strlist_push(&c->argv, "--bind-to");
    hx_strlist_push(&c->argv, !pinned ? "none"
                                      : r->oversubscribed ? "core:overload-allowed" : "core");
    /* GPU runs: each rank on the core planned next to its GPU (topo.c) */
    char *rf = pinned && hx_backend_gpu(r->v[HX_DIM_BACKEND]) && topo->ngpus > 0 ? hx_rankfile(topo, r) : NULL;
    const int ranked = rf && write_rankfile(image, rf, c) == 0;
    if (pinned && !ranked) {
        /* hybrid runs: PE=T gives each rank T consecutive cores */
        HxBuf m = {0};
        int spread = strcmp(r->v[HX_DIM_PIN], "spread") == 0;
        if (strcmp(r->v[HX_DIM_THREADS], "-") != 0 && strcmp(r->v[HX_DIM_THREADS], "1") != 0)
            hx_buf_printf(&m, "%s:PE=%s", spread ? "socket" : "slot", r->v[HX_DIM_THREADS]);
        else
            hx_buf_put(&m, spread ? "socket" : "core");
        hx_strlist_push(&c->argv, "--map-by");
        hx_strlist_push(&c->argv, m.s);
        hx_buf_free(&m);
    }
    hx_strlist_push(&c->argv, "-np");
    hx_strlist_push(&c->argv, r->v[HX_DIM_RANKS][0] == '-' ? "1" : r->v[HX_DIM_RANKS]);
    if (geteuid() == 0) {
        hx_strlist_push(&c->env, "OMPI_ALLOW_RUN_AS_ROOT");
        hx_strlist_push(&c->env, "1");
        hx_strlist_push(&c->env, "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM");
        hx_strlist_push(&c->env, "1");
    }
}

/* valgrind in front of the renderer, for the instruction count. */
static void cachegrind_prefix(const char *image, HxCommand *c)
{
    /* cachegrind without its cache model: the exact instruction count
     * (docs/harness-verdicts.md, "CI and the baseline") */
    HxBuf f = {0};
    hx_buf_printf(&f, "--cachegrind-out-file=%s.cg", image);
    hx_strlist_push(&c->argv, "valgrind");
    hx_strlist_push(&c->argv, "--tool=cachegrind");
    hx_strlist_push(&c->argv, "--cache-sim=no");
    hx_strlist_push(&c->argv, f.s);
    hx_buf_free(&f);
}

/* The renderer and its arguments: the run's dimensions as options, the
 * image, the config's extra_args, the scene cache and the scene. */
static void raytrace_args(const HxConfig *cfg, const HxRun *r, const char *raytrace, const char *image,
                          HxCommand *c)
{
    const char *cache_dir = strcmp(cfg->scene_cache, "off") == 0 ? NULL : cfg->scene_cache;
    hx_strlist_push(&c->argv, raytrace);
    hx_strlist_push(&c->argv, "--backend");
    hx_strlist_push(&c->argv, r->v[HX_DIM_BACKEND]);
    static const struct { int dim; const char *opt; } opts[] = {
        {HX_DIM_ACCEL, "--accel"}, {HX_DIM_RESOLUTION, "--resolution"},
        {HX_DIM_MAX_DEPTH, "--max-depth"}, {HX_DIM_TILE, "--tile"},
        {HX_DIM_SCHEDULE, "--schedule"}, {HX_DIM_THREADS, "--threads"},
        {HX_DIM_MPI_SCHEDULE, "--mpi-schedule"}, {HX_DIM_BLOCK, "--block"},
    };
    for (size_t i = 0; i < sizeof opts / sizeof opts[0]; i++) {
        const char *v = r->v[opts[i].dim];
        if (strcmp(v, "-") == 0)
            continue;
        hx_strlist_push(&c->argv, opts[i].opt);
        hx_strlist_push(&c->argv, v);
    }
    hx_strlist_push(&c->argv, "-o");
    hx_strlist_push(&c->argv, image);
    for (size_t i = 0; i < cfg->extra_args.n; i++)
        hx_strlist_push(&c->argv, cfg->extra_args.v[i]);
    if (cache_dir) {
        hx_strlist_push(&c->argv, "--cache");
        hx_strlist_push(&c->argv, cache_dir);
    }
    hx_strlist_push(&c->argv, r->scene_path);
}

/* OpenMP runs: the thread count, and with pinning the threads' places. */
static void openmp_env(const HxTopo *topo, const HxRun *r, int pinned, HxCommand *c)
{
    char n[16];
    snprintf(n, sizeof n, "%d", r->workers);
    /* OMP_PLACES lists exactly the planned cores inside the bound set */
    hx_strlist_push(&c->env, "OMP_NUM_THREADS");
    hx_strlist_push(&c->env, n);
    if (pinned && r->ncores > 0) {
        char *places = hx_omp_places(topo, r);
        hx_strlist_push(&c->env, "OMP_PLACES");
        hx_strlist_push(&c->env, places);
        free(places);
        hx_strlist_push(&c->env, "OMP_PROC_BIND");
        hx_strlist_push(&c->env, strcmp(r->v[HX_DIM_PIN], "spread") == 0 ? "spread" : "close");
    }
}

/* Ends l with a NULL slot, not counted in l->n (execvp's argv). */
static void null_terminate(HxStrList *l)
{
    hx_strlist_push(l, ""); /* placeholder for the NULL terminator */
    free(l->v[l->n - 1]);
    l->v[l->n - 1] = NULL;
    l->n--;
}

/* The name of the executable argv0 runs (a link resolved: /usr/bin/python3
 * runs python3.11), for the CPU watcher; malloc'd, NULL when not found. */
static char *exe_name(const char *argv0)
{
    char *abs = hx_which(argv0);
    const char *b = abs ? strrchr(abs, '/') : NULL;
    char *name = b ? hx_strdup(b + 1) : NULL;
    free(abs);
    return name;
}

/* A command study's run: the launcher for ranks, else bound to its cores;
 * the program's argv and env; its folder; its CPUs watched. */
static void program_command(const HxConfig *cfg, const HxTopo *topo, const HxRun *r, const char *rundir,
                            const char *workdir, int pinned, HxCommand *c)
{
    if (hx_run_is_mpi(r->v) && cfg->launcher == HX_LAUNCHER_SRUN)
        srun_launcher(r, pinned, c);
    else if (hx_run_is_mpi(r->v))
        mpirun_launcher(cfg, topo, r, rundir, pinned, c);
    else
        c->bind = pinned;
    size_t first = c->argv.n;
    HxVars vars;
    hx_vars_of_run(cfg, r, rundir, workdir, &vars);
    hx_program_command(cfg, &vars, c);
    hx_vars_free(&vars);
    c->dir = hx_strdup(rundir);
    c->watch_exe = exe_name(c->argv.v[first]);
    c->watch_any = hx_run_is_mpi(r->v) && cfg->launcher == HX_LAUNCHER_SRUN;
}

void hx_build_command(const HxConfig *cfg, const HxTopo *topo, const HxRun *r, const char *raytrace,
                      const char *image, const char *rundir, const char *workdir, HxCommand *c)
{
    memset(c, 0, sizeof *c);
    const char *be = r->v[HX_DIM_BACKEND];
    int is_mpi = hx_backend_mpi(be);
    int pinned = strcmp(r->v[HX_DIM_PIN], "none") != 0;
    if (cfg->prog) {
        program_command(cfg, topo, r, rundir, workdir, pinned, c);
        hx_command_terminate(c);
        return;
    }
    if (is_mpi && cfg->launcher == HX_LAUNCHER_SRUN)
        srun_launcher(r, pinned, c);
    else if (is_mpi)
        mpirun_launcher(cfg, topo, r, image, pinned, c);
    else
        c->bind = pinned;
    if (hx_backend_gpu(be)) {
        /* CUDA numbers the GPUs as hwloc walks the bus (topo.c's plan) */
        hx_strlist_push(&c->env, "CUDA_DEVICE_ORDER");
        hx_strlist_push(&c->env, "PCI_BUS_ID");
    }
    if (cfg->instructions)
        cachegrind_prefix(image, c);
    raytrace_args(cfg, r, raytrace, image, c);
    if (strcmp(be, "openmp") == 0)
        openmp_env(topo, r, pinned, c);
    hx_command_terminate(c);
}

void hx_command_terminate(HxCommand *c)
{
    null_terminate(&c->argv);
    null_terminate(&c->env);
}

void hx_command_free(HxCommand *c)
{
    c->argv.n++; /* include the NULL slot, free() of NULL is fine */
    c->env.n++;
    hx_strlist_free(&c->argv);
    hx_strlist_free(&c->env);
    free(c->dir);
    free(c->watch_exe);
    c->dir = c->watch_exe = NULL;
}

void hx_print_command(FILE *out, const HxCommand *c)
{
    if (c->dir)
        fprintf(out, "(in %s) ", c->dir);
    for (size_t i = 0; i + 1 < c->env.n + 1 && c->env.v[i]; i += 2)
        fprintf(out, "%s=%s ", c->env.v[i], c->env.v[i + 1]);
    for (size_t i = 0; i < c->argv.n; i++) {
        /* quoted as a shell would need it, so the line shows one argument
         * per word (the run itself gets the argv, no shell) */
        const char *a = c->argv.v[i];
        int plain = *a && strspn(a, "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-+=/.,:@%") == strlen(a);
        fputs(i ? " " : "", out);
        if (plain) {
            fputs(a, out);
            continue;
        }
        fputc('\'', out);
        for (; *a; a++)
            fputs(*a == '\'' ? "'\\''" : (char[2]){*a, 0}, out);
        fputc('\'', out);
    }
    fputc('\n', out);
}

char *hx_find_raytrace(const HxConfig *cfg, const char *opt)
{
    if (opt)
        return hx_strdup(opt);
    if (cfg->raytrace)
        return hx_strdup(cfg->raytrace);
    const char *env = getenv("RAYTRACE");
    if (env && *env)
        return hx_strdup(env);
    /* default: the build tree layout, build/harness/harness next to
     * build/renderer/raytrace */
    char self[4096];
    ssize_t n = readlink("/proc/self/exe", self, sizeof self - 1);
    if (n > 0) {
        self[n] = '\0';
        char *d = hx_dirname(self);
        char *p = hx_path_join(d, "../renderer/raytrace");
        free(d);
        return p;
    }
    return hx_strdup("raytrace");
}

int hx_srun_job_gone(const HxConfig *cfg, const HxTopo *topo, const HxRun *r, const char *status, char **why)
{
    *why = NULL;
    int nodes = hx_slurm_nodes();
    /* Any run of a job, one node too: a job cancelled while a run is in
     * progress has its steps' tasks killed, and the run can end before the
     * harness's own SIGTERM arrives. The probe then cannot start a step, and
     * the run is not taken for a failure of its own. */
    const char *job = getenv("SLURM_JOB_ID");
    if (cfg->launcher != HX_LAUNCHER_SRUN || !job || !*job || !status ||
        (strcmp(status, "error") != 0 && strcmp(status, "crash") != 0 && strcmp(status, "timeout") != 0))
        return 0;
    /* One task on each node; --overlap: the CPUs of a step still being
     * cleaned up do not make it wait, so a live node answers at once and a
     * dead one fails the launch (or holds it until the controller ends the
     * job, which stops the harness). */
    HxCommand c;
    memset(&c, 0, sizeof c);
    char n[64];
    hx_strlist_push(&c.argv, "srun");
    snprintf(n, sizeof n, "--nodes=%d", nodes);
    hx_strlist_push(&c.argv, n);
    snprintf(n, sizeof n, "--ntasks=%d", nodes);
    hx_strlist_push(&c.argv, n);
    const char *fixed[] = {"--ntasks-per-node=1", "--cpus-per-task=1", "--overlap", "--cpu-bind=none",
                           "--mpi=none", "true"};
    for (size_t i = 0; i < sizeof fixed / sizeof fixed[0]; i++)
        hx_strlist_push(&c.argv, fixed[i]);
    hx_command_terminate(&c);
    HxChildResult res;
    /* at least 30 s: a slow controller is not a lost job (a false one would
     * stop the study at this run every time it is resumed) */
    const double limit = cfg->timeout_s > 30 ? cfg->timeout_s : 30;
    int spawned = hx_run_child(&c, topo, r, limit, &res);
    hx_reap_strays();
    hx_command_free(&c);
    int lost = 1;
    HxBuf b = {0};
    if (hx_stop_signal() || spawned != 0) {
        lost = hx_stop_signal() != 0; /* no fork: nothing known about the nodes */
    } else if (res.timed_out) {
        hx_buf_printf(&b, "srun on each of the job's %d nodes did not finish in %g s", nodes, limit);
    } else if (!res.exited || res.code != 0) {
        int len;
        const char *e = hx_first_line(res.err.s, &len);
        if (len)
            hx_buf_printf(&b, "srun on each of the job's %d nodes failed: %.*s", nodes, len, e);
        else
            hx_buf_printf(&b, "srun on each of the job's %d nodes failed (exit %d)", nodes, res.code);
    } else {
        lost = 0; /* every node answers: the failure was the run's own */
    }
    hx_child_result_free(&res);
    *why = b.s;
    return lost;
}
