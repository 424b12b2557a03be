/* Unit tests of the harness internals: `test_harness GROUP` runs one group
 * (config, expand, stats, csv, compare, pin) and exits non-zero on any failure. */
#include "hx.h"
#include "run.h"

#include <getopt.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static int failures;

#define CHECK(cond)                                                              \
    do {                                                                         \
        if (!(cond)) {                                                           \
            fprintf(stderr, "%s:%d: CHECK failed: %s\n", __FILE__, __LINE__, #cond); \
            failures++;                                                          \
        }                                                                        \
    } while (0)
#define CHECK_NEAR(a, b, tol) CHECK(fabs((double)(a) - (double)(b)) <= (tol))
#define CHECK_STR(a, b) CHECK(strcmp((a), (b)) == 0)

static char tmpdir[] = "/tmp/hx-unit-XXXXXX";

static void write_file(const char *path, const char *text)
{
    FILE *f = fopen(path, "w");
    if (!f) {
        perror(path);
        exit(2);
    }
    fputs(text, f);
    fclose(f);
}

static char *tpath(const char *name)
{
    return hx_path_join(tmpdir, name);
}

/* parse a config text; scene_dir points at our temp dir with two dummy
 * files (the parser only checks that scenes exist) */
static int parse(const char *text, HxConfig *cfg, char *err, size_t n)
{
    HxBuf b = {0};
    hx_buf_printf(&b, "scene_dir: %s\n%s", tmpdir, text);
    int rc = hx_config_parse_string("t.conf", b.s, cfg, err, n);
    hx_buf_free(&b);
    return rc;
}

static void expect_error(const char *text, const char *want)
{
    HxConfig cfg;
    char err[512] = "";
    int rc = parse(text, &cfg, err, sizeof err);
    if (rc == 0 || !strstr(err, want)) {
        fprintf(stderr, "config error test: wanted '%s', got rc=%d '%s'\n", want, rc, err);
        failures++;
    }
    hx_config_free(&cfg);
}

static void test_config(void)
{
    HxConfig cfg;
    char err[512];
    int rc = parse("# a comment\n"
                   "study: s1\n"
                   "scenes: a b   # trailing comment\n"
                   "backend: serial, openmp\n"
                   "threads: 1 2 4\n"
                   "accel: bvh none\n"
                   "block: 8x8 16x16\n"
                   "repeats: 5\nwarmup: 2\ntimeout: 2m\noversubscribe: allow\n"
                   "pin: spread\nbaseline: accel=none\n",
                   &cfg, err, sizeof err);
    if (rc)
        fprintf(stderr, "%s\n", err);
    CHECK(rc == 0);
    CHECK_STR(cfg.study, "s1");
    CHECK(cfg.dim[HX_DIM_SCENE].n == 2);
    CHECK(cfg.dim[HX_DIM_BACKEND].n == 2);
    CHECK_STR(cfg.dim[HX_DIM_BACKEND].v[1], "openmp");
    CHECK(cfg.dim[HX_DIM_THREADS].n == 3);
    CHECK(cfg.repeats == 5 && cfg.warmup == 2);
    CHECK_NEAR(cfg.timeout_s, 120, 1e-9);
    CHECK(cfg.oversubscribe_allow == 1);
    CHECK_STR(cfg.baseline, "accel=none");
    CHECK_STR(cfg.dim[HX_DIM_PIN].v[0], "spread");
    CHECK(strstr(cfg.scene_path.v[1], "b.txt") != NULL);
    hx_config_free(&cfg);

    /* defaults: study from the file name, serial, pin close, 3 repeats */
    rc = parse("scenes: a\n", &cfg, err, sizeof err);
    CHECK(rc == 0);
    CHECK_STR(cfg.study, "t");
    CHECK_STR(cfg.dim[HX_DIM_BACKEND].v[0], "serial");
    CHECK_STR(cfg.dim[HX_DIM_PIN].v[0], "close");
    CHECK(cfg.repeats == 3);
    CHECK(cfg.launcher == HX_LAUNCHER_MPIRUN);
    hx_config_free(&cfg);

    /* launcher: mpirun (default) or srun; one parser for key and option */
    rc = parse("scenes: a\nlauncher: srun\n", &cfg, err, sizeof err);
    CHECK(rc == 0);
    CHECK(cfg.launcher == HX_LAUNCHER_SRUN);
    CHECK_STR(hx_launcher_name(cfg.launcher), "srun");
    hx_config_free(&cfg);
    rc = parse("scenes: a\nlauncher: mpirun\n", &cfg, err, sizeof err);
    CHECK(rc == 0);
    CHECK(cfg.launcher == HX_LAUNCHER_MPIRUN);
    hx_config_free(&cfg);
    HxLauncher l;
    CHECK(hx_launcher_parse("srun", &l) == 0 && l == HX_LAUNCHER_SRUN);
    CHECK(hx_launcher_parse("SRUN", &l) != 0);

    /* errors name the file and the line (scene_dir is line 1) */
    expect_error("scenes: a\nfoo: 1\n", "t.conf:3: unknown key 'foo'");
    expect_error("scenes: a\nthreads: 1 x\n", "t.conf:3: threads: expected an integer");
    expect_error("scenes: a\nbackend: serial gpu\n", "t.conf:3: backend: expected one of serial|openmp|mpi|cuda");
    expect_error("scenes: a\nscenes: b\n", "t.conf:3: key 'scenes' already set on line 2");
    expect_error("scenes: a\njust words\n", "t.conf:3: expected 'key: values'");
    expect_error("scenes: a\nrepeats: 1 2\n", "t.conf:3: key 'repeats' takes one value");
    expect_error("scenes: a\nrepeats: 0\n", "t.conf:3: repeats");
    expect_error("scenes: a\nblock: 8by8\n", "t.conf:3: block: expected WxH");
    /* block "-": the renderer's default, as a value beside explicit shapes */
    rc = parse("scenes: a\nbackend: cuda\nblock: - 16x8\n", &cfg, err, sizeof err);
    CHECK(rc == 0);
    CHECK(cfg.dim[HX_DIM_BLOCK].n == 2);
    CHECK_STR(cfg.dim[HX_DIM_BLOCK].v[0], "-");
    hx_config_free(&cfg);
    expect_error("scenes: a\nblock: - -\n", "value '-' listed twice");
    expect_error("scenes: a\ntile: -\n", "t.conf:3: tile: expected WxH");
    expect_error("scenes: a\ntimeout: soon\n", "t.conf:3: timeout");
    expect_error("scenes: a\naccel:\n", "t.conf:3: key 'accel' has no value");
    expect_error("scenes: nosuch\n", "t.conf:2: scene 'nosuch' not found");
    expect_error("accel: bvh\n", "missing required key 'scenes'");
    expect_error("scenes: a\nthreads: 2 2\n", "value '2' listed twice");
    expect_error("scenes: a\nbaseline: serial\n", "t.conf:3: baseline: expected KEY=VALUE");
    expect_error("scenes: a\nlauncher: slurm\n",
                 "t.conf:3: launcher: expected mpirun|srun, got 'slurm'");
    expect_error("scenes: a\nlauncher: srun mpirun\n", "t.conf:3: key 'launcher' takes one value");
    expect_error("scenes: a\nlauncher: srun\nlauncher: srun\n",
                 "t.conf:4: key 'launcher' already set on line 3");

    /* a missing file is a one-line error, not a crash */
    rc = hx_config_load("/nonexistent/x.conf", &cfg, err, sizeof err);
    CHECK(rc != 0 && strstr(err, "/nonexistent/x.conf") != NULL);
    hx_config_free(&cfg);
}

/* GPU backends: mpi-cuda sweeps ranks and blocks, not threads or tiles; each
 * rank goes to a free core next to its GPU (rank w: GPU w mod 2), and the
 * rankfile names those cores as package:core. Fake machine: 2 packages of 2
 * cores, GPU 0 on package 1, GPU 1 on package 0. */
static void test_expand_gpus(void)
{
    HxConfig cfg;
    HxPlan plan;
    char err[512];
    int rc = parse("scenes: a\nbackend: mpi-cuda cuda\nranks: 1 3\nthreads: 2\ntile: 8x8\nblock: 8x8\n"
                   "repeats: 1\n", &cfg, err, sizeof err);
    CHECK(rc == 0);
    hx_expand(&cfg, &plan);
    CHECK(plan.n == 3);
    HxTopo t;
    memset(&t, 0, sizeof t);
    t.ncores = t.npus = 4;
    t.npackages = 2;
    int os[4] = {0, 1, 2, 3}, order[4] = {0, 2, 1, 3}, pkg[4] = {0, 0, 1, 1}, inpkg[4] = {0, 1, 0, 1};
    int near0[2] = {2, 3}, near1[2] = {0, 1}, *near[2] = {near0, near1}, nnear[2] = {2, 2};
    char *pus[4] = {"0", "1", "2", "3"}, *bus[2] = {"0000:19:00.0", "0000:3b:00.0"};
    t.core_os = os;
    t.spread_order = order;
    t.core_pus = pus;
    t.core_pkg = pkg;
    t.core_in_pkg = inpkg;
    t.ngpus = 2;
    t.gpu_bus = bus;
    t.gpu_cores = near;
    t.gpu_ncores = nnear;
    hx_plan_cores(&t, &cfg, &plan);
    int seen = 0;
    for (size_t i = 0; i < plan.n; i++) {
        const HxRun *r = &plan.runs[i];
        CHECK_STR(r->v[HX_DIM_THREADS], "-");
        CHECK_STR(r->v[HX_DIM_TILE], "-");
        CHECK_STR(r->v[HX_DIM_BLOCK], "8x8");
        if (strcmp(r->v[HX_DIM_BACKEND], "cuda") == 0) {
            CHECK_STR(r->v[HX_DIM_RANKS], "-");
            CHECK_STR(r->cores_planned, "2");
            seen |= 1;
        } else if (strcmp(r->v[HX_DIM_RANKS], "3") == 0) {
            CHECK(r->workers == 3);
            CHECK_STR(r->cores_planned, "2,0,3");
            char *rf = hx_rankfile(&t, r);
            CHECK(rf && strcmp(rf, "rank 0=localhost slot=1:0\nrank 1=localhost slot=0:0\n"
                                   "rank 2=localhost slot=1:1\n") == 0);
            free(rf);
            seen |= 2;
        }
    }
    CHECK(seen == 3);
    CHECK(hx_backend_mpi("mpi-cuda") && hx_backend_gpu("mpi-cuda") && !hx_backend_gpu("mpi"));
    hx_plan_free(&plan);
    hx_config_free(&cfg);
}

/* The run of plan with these backend, threads and ranks values. */
static const HxRun *find_run(const HxPlan *plan, const char *be, const char *threads, const char *ranks)
{
    for (size_t i = 0; i < plan->n; i++) {
        const HxRun *r = &plan->runs[i];
        if (!strcmp(r->v[HX_DIM_BACKEND], be) && !strcmp(r->v[HX_DIM_THREADS], threads) &&
            !strcmp(r->v[HX_DIM_RANKS], ranks))
            return r;
    }
    fprintf(stderr, "no run %s threads=%s ranks=%s\n", be, threads, ranks);
    exit(1);
}

/* srun in a 2-node job of fake 2-core nodes: an MPI run's ranks are dealt
 * out over the nodes (the first one more when odd), and each node's cores
 * are planned as on one node, nodes separated by '|'. A node's cores bound
 * the run: one rank never spans nodes. OpenMP runs stay on the harness's. */
static void test_expand_nodes(const HxTopo *t)
{
    HxConfig cfg;
    HxPlan plan;
    char err[512];
    int rc = parse("scenes: a\nbackend: openmp mpi\nthreads: 1 2 4\nranks: 1 2 3\nrepeats: 1\n"
                   "launcher: srun\n", &cfg, err, sizeof err);
    CHECK(rc == 0);
    hx_expand(&cfg, &plan);
    setenv("SLURM_JOB_NUM_NODES", "2", 1);
    hx_plan_cores(t, &cfg, &plan);
    CHECK(find_run(&plan, "openmp", "4", "-")->refused);
    CHECK(find_run(&plan, "mpi", "4", "1")->refused);
    CHECK_STR(find_run(&plan, "mpi", "2", "1")->cores_planned, "0,1");
    CHECK_STR(find_run(&plan, "mpi", "1", "2")->cores_planned, "0|0");
    CHECK_STR(find_run(&plan, "mpi", "2", "2")->cores_planned, "0,1|0,1");
    CHECK(find_run(&plan, "mpi", "2", "2")->ncores == 0); /* srun binds, not the harness */
    CHECK_STR(find_run(&plan, "mpi", "1", "3")->cores_planned, "0,1|0");
    CHECK(find_run(&plan, "mpi", "2", "3")->refused && find_run(&plan, "mpi", "4", "2")->refused);
    cfg.oversubscribe_allow = 1;
    hx_plan_cores(t, &cfg, &plan);
    CHECK(find_run(&plan, "mpi", "2", "3")->oversubscribed);
    CHECK_STR(find_run(&plan, "mpi", "2", "3")->cores_planned, "0,1,0,1|0,1");
    /* with mpirun the job's node count is not used */
    cfg.oversubscribe_allow = 0;
    cfg.launcher = HX_LAUNCHER_MPIRUN;
    hx_plan_cores(t, &cfg, &plan);
    CHECK(find_run(&plan, "mpi", "2", "2")->refused);
    unsetenv("SLURM_JOB_NUM_NODES");
    hx_plan_free(&plan);
    hx_config_free(&cfg);
}

static void test_expand(void)
{
    HxConfig cfg;
    char err[512];
    /* openmp listed first: serial must still come first (image reference) */
    int rc = parse("scenes: a b\nbackend: openmp serial\nthreads: 1 2\naccel: bvh none\n"
                   "repeats: 3\nwarmup: 1\n", &cfg, err, sizeof err);
    CHECK(rc == 0);
    HxPlan plan;
    hx_expand(&cfg, &plan);
    /* per scene: serial x 2 accels (threads collapse) + openmp x 2 accels x 2
     * threads = 6 configurations, each 1 warm-up + 3 repeats; 2 scenes */
    CHECK(plan.n == 2 * 6 * 4);
    CHECK_STR(plan.runs[0].v[HX_DIM_BACKEND], "serial");
    CHECK(plan.runs[0].warmup == 1 && plan.runs[0].repeat == -1);
    CHECK(plan.runs[1].warmup == 0 && plan.runs[1].repeat == 0);
    CHECK(plan.runs[3].repeat == 2);
    CHECK_STR(plan.runs[0].v[HX_DIM_THREADS], "-");
    CHECK_STR(plan.runs[0].v[HX_DIM_ACCEL], "bvh");
    CHECK_STR(plan.runs[4].v[HX_DIM_ACCEL], "none");
    CHECK_STR(plan.runs[8].v[HX_DIM_BACKEND], "openmp");
    CHECK_STR(plan.runs[8].v[HX_DIM_THREADS], "1");
    CHECK_STR(plan.runs[12].v[HX_DIM_THREADS], "2");
    CHECK(plan.runs[12].workers == 2);
    CHECK_STR(plan.runs[24].v[HX_DIM_SCENE], "b");
    /* run ids are unique among recorded runs */
    for (size_t i = 0; i < plan.n; i++)
        for (size_t k = i + 1; k < plan.n; k++)
            if (!plan.runs[i].warmup && !plan.runs[k].warmup)
                CHECK(strcmp(plan.runs[i].run_id, plan.runs[k].run_id) != 0);

    /* pinning plan on a fake 2-core topology: close, spread, oversubscribe */
    HxTopo t;
    memset(&t, 0, sizeof t);
    t.ncores = t.npus = 2;
    t.npackages = 1;
    int os[2] = {0, 1}, order[2] = {0, 1};
    char *pus[2] = {"0", "1"};
    t.core_os = os;
    t.spread_order = order;
    t.core_pus = pus;
    hx_plan_cores(&t, &cfg, &plan);
    CHECK_STR(plan.runs[1].cores_planned, "0");
    CHECK_STR(plan.runs[12].cores_planned, "0,1");
    char *places = hx_omp_places(&t, &plan.runs[12]);
    CHECK_STR(places, "{0},{1}");
    free(places);
    hx_plan_free(&plan);
    hx_config_free(&cfg);

    rc = parse("scenes: a\nbackend: openmp\nthreads: 4\nrepeats: 1\n", &cfg, err, sizeof err);
    CHECK(rc == 0);
    hx_expand(&cfg, &plan);
    hx_plan_cores(&t, &cfg, &plan);
    CHECK(plan.n == 1 && plan.runs[0].oversubscribed && plan.runs[0].refused);
    cfg.oversubscribe_allow = 1;
    hx_plan_cores(&t, &cfg, &plan);
    CHECK(!plan.runs[0].refused);
    CHECK_STR(plan.runs[0].cores_planned, "0,1,0,1");
    hx_plan_free(&plan);
    hx_config_free(&cfg);

    test_expand_nodes(&t);
    test_expand_gpus();
}

/* The pinning check: one node as planned, and runs over several nodes
 * checked node by node from the record's rank_node and rank_cores. */
static void test_pin(void)
{
    CHECK_STR(hx_pin_held("0,1", "1,0"), "yes");
    CHECK_STR(hx_pin_held("0,1", "0"), "partial");
    CHECK_STR(hx_pin_held("0,1", "0,2"), "no");
    CHECK_STR(hx_pin_held("-", "0"), "n/a");
    CHECK_STR(hx_pin_held("0", ""), "unknown");
    /* core 0 of node 0 is not core 0 of node 1 */
    CHECK_STR(hx_pin_held("0,1|0,1", "0,1|0,1"), "yes");
    CHECK_STR(hx_pin_held("0,1|0,1", "0,1|1"), "partial"); /* node 1's two ranks on one core */
    CHECK_STR(hx_pin_held("0|0", "0|1"), "no");
    CHECK_STR(hx_pin_held("0,1|0,1", "0,1"), "no");        /* every rank on one node */
    CHECK_STR(hx_pin_held("0|0", "0|0|0"), "no");
    CHECK_STR(hx_pin_held("0|0", "0|"), "unknown");        /* node 1 reported nothing */
    const struct { const char *node, *cores, *want; } by[] = {
        {"0/0/1/1", "0/1/1/0", "0,1|0,1"}, {"0/1", "0,1/2,3", "0,1|2,3"}, {"0/0/1", "1/1/0", "1|0"},
        {"0/1", "0/", "0|"}, {"0", "3", "3"},
        {"0/1", "0/1/2", NULL}, {"0/1/1", "0/1", NULL}, {"0/x", "0/1", NULL}, {"", "0", NULL},
    };
    for (size_t i = 0; i < sizeof by / sizeof by[0]; i++) {
        char *s = hx_cores_by_node(by[i].node, by[i].cores);
        if (by[i].want ? !s || strcmp(s, by[i].want) != 0 : s != NULL) {
            fprintf(stderr, "hx_cores_by_node(%s, %s) = %s, expected %s\n", by[i].node, by[i].cores,
                    s ? s : "NULL", by[i].want ? by[i].want : "NULL");
            failures++;
        }
        free(s);
    }
    /* a row: raytrace's cores= (the union over the nodes) gives way to the
     * cores per node */
    char **vals = calloc((size_t)hx_ncolumns, sizeof *vals);
    int ka = hx_column_index("cores_actual");
    hx_row_set(vals, "cores_actual", "0,1");
    hx_row_set(vals, "extra", "mpi_schedule=dynamic;rank_cores=0/1/0/1;nodes=2;rank_node=0/0/1/1");
    CHECK_STR(hx_pin_held_row("0,1|0,1", vals), "yes");
    CHECK_STR(vals[ka], "0,1|0,1");
    hx_row_set(vals, "extra", "rank_cores=0/0/0/1;nodes=2;rank_node=0/0/1/1");
    CHECK_STR(hx_pin_held_row("0,1|0,1", vals), "partial");
    hx_row_set(vals, "extra", "rank_cores=0/1"); /* no rank_node: the nodes cannot be told apart */
    CHECK_STR(hx_pin_held_row("0|0", vals), "unknown");
    hx_row_set(vals, "cores_actual", "0");
    CHECK_STR(hx_pin_held_row("0,1", vals), "partial"); /* one node: cores_actual as reported */
    CHECK_STR(vals[ka], "0");
    for (int k = 0; k < hx_ncolumns; k++)
        free(vals[k]);
    free(vals);
}

/* hx_noise on made-up /proc/stat samples (100 clock ticks a second). */
static void test_noise(void)
{
    HxCpuStat a = {1000, 5000, 10, 0, 0.5, 1}, b = a;
    HxNoise n;
    /* 1 s of 2 CPUs: 150 ticks busy, of which the run's own 1000 ms: half a
     * core of other work, and a CPU left free for the run's one worker */
    b.busy += 150;
    b.idle += 50;
    hx_noise(&a, &b, 1000.0, 1000.0, 2, 1, &n);
    CHECK_NEAR(n.others_cores, 0.5, 1e-9);
    CHECK(n.busy == 0 && n.stolen == 0);
    /* every tick busy: a whole core of other work beside the run */
    b = a;
    b.busy += 200;
    hx_noise(&a, &b, 1000.0, 1000.0, 2, 1, &n);
    CHECK_NEAR(n.others_cores, 1.0, 1e-9);
    CHECK(n.busy == 1 && n.stolen == 0);
    CHECK_NEAR(n.load1, 0.5, 0);
    /* the same with 10 of the 200 ticks stolen */
    b = a;
    b.busy += 100;
    b.idle += 90;
    b.steal += 10;
    hx_noise(&a, &b, 1000.0, 1000.0, 2, 1, &n);
    CHECK_NEAR(n.others_cores, 0.0, 1e-9);
    CHECK_NEAR(n.steal_pct, 5.0, 1e-9);
    CHECK(n.busy == 0 && n.stolen == 1);
    /* too short to judge */
    hx_noise(&a, &b, 100.0, 100.0, 2, 1, &n);
    CHECK(n.busy == 0 && n.stolen == 0);
    /* 60 ms of 64 CPUs (384 ticks): a third stolen is flagged, 3% (within
     * the ticks' 2.1 points of error above the 2%) is not */
    b = a;
    b.busy += 200;
    b.idle += 54;
    b.steal += 130;
    hx_noise(&a, &b, 60.0, 60.0 * 64, 64, 64, &n);
    CHECK(n.stolen == 1 && n.busy == 0);
    b = a;
    b.busy += 360;
    b.idle += 12;
    b.steal += 12;
    hx_noise(&a, &b, 60.0, 60.0 * 64, 64, 64, &n);
    CHECK_NEAR(n.steal_pct, 3.125, 1e-9);
    CHECK(n.stolen == 0);
}

/* The step's summary (syncstep.c): per step, the fastest worker's own time
 * over the span from the first start to the last end; medians over steps. */
static void test_sync_step(void)
{
    /* 3 steps of 2 workers (ns): equal and aligned; the second worker
     * started 1 ms late; the second took twice as long */
    const int64_t start[] = {0, 0, 10000000, 11000000, 20000000, 20000000};
    const int64_t end[] = {2000000, 2000000, 12000000, 13000000, 22000000, 24000000};
    HxSyncStep st;
    hx_sync_summarise(start, end, 3, 2, &st);
    CHECK(st.steps == 3);
    CHECK_NEAR(st.share, 2.0 / 3.0, 1e-9); /* the median of 1, 2/3 and 1/2 */
    /* The probe itself: one worker keeps all of its step; a worker that
     * cannot be bound to its core (no such core) fails the probe rather
     * than share another's core and report that as the machine's noise. */
    HxTopo t;
    hx_topo_load(&t);
    int one[] = {0}, bad[] = {0, 1 << 20}, two[] = {0, 1};
    const int want = t.have_hwloc ? 0 : -1; /* (without hwloc nothing is bound: no step) */
    CHECK(hx_sync_step(&t, one, 1, 0.5, 5, &st) == want);
    CHECK(!t.have_hwloc || (st.steps == 5 && st.share == 1));
    CHECK(hx_sync_step(&t, bad, 2, 0.5, 5, &st) == -1);
    if (t.ncores >= 2) {
        CHECK(hx_sync_step(&t, two, 2, 0.5, 20, &st) == want);
        CHECK(!t.have_hwloc || (st.steps == 20 && st.share > 0 && st.share <= 1));
    }
    hx_topo_free(&t);
}

static void test_stats(void)
{
    test_noise();
    double a[] = {5, 1, 3};
    CHECK_NEAR(hx_median(a, 3), 3, 0);
    double b[] = {4, 1, 3, 2};
    CHECK_NEAR(hx_median(b, 4), 2.5, 0);
    double s[] = {1, 2, 3, 4, 5};
    CHECK_NEAR(hx_quantile_sorted(s, 5, 0.25), 2, 1e-12);
    CHECK_NEAR(hx_quantile_sorted(s, 5, 0.75), 4, 1e-12);
    double s4[] = {1, 2, 3, 4};
    CHECK_NEAR(hx_quantile_sorted(s4, 4, 0.25), 1.75, 1e-12); /* type 7, as R */
    CHECK_NEAR(hx_mad(s, 5), 1, 0);
    double o[] = {10, 10.1, 9.9, 10.05, 9.95, 30};
    int flag[6];
    CHECK(hx_outliers(o, 6, 10, flag) == 1 && flag[5] == 1 && flag[0] == 0);
    double same[] = {7, 7, 7, 8};
    CHECK(hx_outliers(same, 4, 10, NULL) == 0); /* MAD 0: nothing flagged */
    CHECK_NEAR(hx_min(o, 6), 9.9, 0);

    /* speedup/efficiency/Karp-Flatt on the report's Table 1 numbers */
    double t1 = 2063492, t64 = 69803;
    double sp = t1 / t64;
    CHECK_NEAR(sp, 29.56, 0.01);
    CHECK_NEAR(sp / 64, 0.462, 0.001);
    CHECK_NEAR(hx_karp_flatt(2.0, 2), 0.0, 1e-12);   /* perfect: e = 0 */
    CHECK_NEAR(hx_karp_flatt(1.6, 2), 0.25, 1e-12);
    CHECK_NEAR(hx_karp_flatt(1.0, 4), 1.0, 1e-12);   /* no speedup: e = 1 */
    CHECK(isnan(hx_karp_flatt(1.0, 1)));

    /* Amdahl fit recovers a, b from exact data T(p) = 10 + 90/p */
    double p[] = {1, 2, 4, 8, 16, 1, 2, 4};
    double t[8];
    for (int i = 0; i < 8; i++)
        t[i] = 10 + 90 / p[i];
    HxAmdahl f = hx_amdahl_fit(p, t, 8);
    CHECK(f.ok && f.has_se);
    CHECK_NEAR(f.a, 10, 1e-9);
    CHECK_NEAR(f.b, 90, 1e-9);
    CHECK_NEAR(f.serial_fraction, 0.1, 1e-12);
    CHECK_NEAR(f.se_serial_fraction, 0, 1e-9);
    /* with noise the standard error becomes positive */
    t[0] += 1;
    t[3] -= 0.5;
    f = hx_amdahl_fit(p, t, 8);
    CHECK(f.has_se && f.se_serial_fraction > 0 && fabs(f.serial_fraction - 0.1) < 0.02);
    double p1[] = {2, 2, 2}, t1s[] = {5, 6, 7};
    CHECK(!hx_amdahl_fit(p1, t1s, 3).ok); /* one worker count: no fit */

    /* Mann-Whitney: 5 vs 5 fully separated: exact two-sided p = 2/252 */
    double x[] = {1, 2, 3, 4, 5}, y[] = {6, 7, 8, 9, 10};
    CHECK_NEAR(hx_mann_whitney_p(x, 5, y, 5), 2.0 / 252.0, 1e-12);
    CHECK_NEAR(hx_mann_whitney_p(y, 5, x, 5), 2.0 / 252.0, 1e-12);
    /* 3 vs 3 cannot go below 0.1: why compare needs 4 a side */
    CHECK_NEAR(hx_mann_whitney_p(x, 3, y, 3), 0.1, 1e-12);
    CHECK_NEAR(hx_mann_whitney_p(x, 5, x, 5), 1.0, 1e-12);
    double z[] = {5.5, 9.5, 6.5, 8.5, 7.5}; /* interleaved with y */
    CHECK(hx_mann_whitney_p(z, 5, y, 5) > 0.05);
    /* ties, exact: of the 70 ways to pick 4 of {0,0,0,2,2,4,4,4}, 2 have a
     * rank sum as low as {0,0,0,2}'s, so p = 2 x 2/70 (the normal
     * approximation gave 0.033) */
    double tx[] = {0, 0, 2, 0}, ty[] = {4, 4, 2, 4};
    CHECK_NEAR(hx_mann_whitney_p(tx, 4, ty, 4), 4.0 / 70.0, 1e-12);
    /* all of one value against all of another: 1 way of 126 to pick 5 of 9 */
    double ax[] = {1, 1, 1, 1, 1}, ay[] = {2, 2, 2, 2};
    CHECK_NEAR(hx_mann_whitney_p(ax, 5, ay, 4), 2.0 / 126.0, 1e-12);
    CHECK_NEAR(hx_mann_whitney_p(ax, 5, ax, 4), 1.0, 1e-12);
}

static void test_csv(void)
{
    char *path = tpath("rows.csv");
    char err[512];
    int fd = hx_csv_open_append(path, 1, err, sizeof err);
    CHECK(fd >= 0);
    char **vals = calloc((size_t)hx_ncolumns, sizeof *vals);
    vals[hx_column_index("study")] = hx_strdup("st");
    vals[hx_column_index("run_id")] = hx_strdup("id #r0");
    vals[hx_column_index("status")] = hx_strdup("error");
    vals[hx_column_index("status_detail")] = hx_strdup("bad, \"quoted\" thing");
    int n = hx_record_to_row("record: scene=x width=3 height=2 render_ms=1.5 cores=0,1 "
                             "image_fnv1a=abc newkey=7 other=q", vals);
    CHECK(n == 8);
    CHECK_STR(vals[hx_column_index("rec_scene")], "x");
    CHECK_STR(vals[hx_column_index("cores_actual")], "0,1");
    CHECK_STR(vals[hx_column_index("extra")], "newkey=7;other=q");
    CHECK(hx_csv_append_row(fd, (const char *const *)vals) == 0);
    free(vals[hx_column_index("run_id")]);
    vals[hx_column_index("run_id")] = hx_strdup("id #r1");
    CHECK(hx_csv_append_row(fd, (const char *const *)vals) == 0);
    close(fd);
    HxCsv csv;
    CHECK(hx_csv_read(path, &csv, err, sizeof err) == 0);
    CHECK(csv.nrows == 2 && csv.ncol == hx_ncolumns);
    CHECK_STR(hx_csv_get(&csv, 0, "status_detail"), "bad, \"quoted\" thing");
    CHECK_STR(hx_csv_get(&csv, 1, "run_id"), "id #r1");
    CHECK_STR(hx_csv_get(&csv, 1, "cores_actual"), "0,1");
    hx_csv_free(&csv);

    /* a torn last row (power cut mid-write) is dropped on reopen */
    FILE *f = fopen(path, "a");
    fputs("st,id #r2,0,half a ro", f);
    fclose(f);
    fd = hx_csv_open_append(path, 0, err, sizeof err);
    CHECK(fd >= 0);
    close(fd);
    CHECK(hx_csv_read(path, &csv, err, sizeof err) == 0);
    CHECK(csv.nrows == 2);
    hx_csv_free(&csv);

    /* a foreign header is refused, not mixed */
    char *other = tpath("other.csv");
    write_file(other, "a,b\n1,2\n");
    fd = hx_csv_open_append(other, 0, err, sizeof err);
    CHECK(fd < 0 && strstr(err, "header differs") != NULL);
    /* malformed CSV: one-line error */
    write_file(other, "a,b\n1,2,3\n");
    CHECK(hx_csv_read(other, &csv, err, sizeof err) != 0 && strstr(err, "line 2") != NULL);
    for (int i = 0; i < hx_ncolumns; i++)
        free(vals[i]);
    free(vals);
    free(path);
    free(other);
}

/* The reader parses the text in place: quotes, doubled quotes, newlines
 * inside quotes, CRLF and lone CR line ends, blank lines, a last row
 * without a newline, and the line numbers of its errors. */
static void test_csv_parse(void)
{
    HxCsv csv;
    char err[512];
    const char *text = "a,b,c\r\n"
                       "\"x,\"\"y\"\"\",,\"two\nlines\"\n"
                       "\n"
                       "1,\"\",3\r"
                       "p\"q\"r,\"s\"t,";
    CHECK(hx_csv_parse(text, &csv, err, sizeof err) == 0);
    CHECK(csv.ncol == 3 && csv.nrows == 3);
    CHECK_STR(csv.cols[0], "a");
    CHECK_STR(csv.cols[2], "c");
    CHECK_STR(hx_csv_cell(&csv, 0, 0), "x,\"y\"");
    CHECK_STR(hx_csv_cell(&csv, 0, 1), "");
    CHECK_STR(hx_csv_get(&csv, 0, "c"), "two\nlines");
    CHECK_STR(hx_csv_get(&csv, 1, "a"), "1");
    CHECK_STR(hx_csv_get(&csv, 1, "b"), "");
    CHECK_STR(hx_csv_get(&csv, 1, "c"), "3");
    CHECK_STR(hx_csv_get(&csv, 2, "a"), "p\"q\"r"); /* a quote inside a plain field is kept */
    CHECK_STR(hx_csv_get(&csv, 2, "b"), "st");       /* a quoted part, then plain text */
    CHECK_STR(hx_csv_get(&csv, 2, "c"), "");
    CHECK_STR(hx_csv_get(&csv, 2, "nosuch"), "");
    hx_csv_free(&csv);
    /* line numbers count the newlines inside quoted fields */
    CHECK(hx_csv_parse("a,b\n\"1\n2\",3\n4\n", &csv, err, sizeof err) != 0);
    CHECK(strstr(err, "line 4: 1 fields, header has 2") != NULL);
    CHECK(hx_csv_parse("a,b\n1,\"open\n", &csv, err, sizeof err) != 0);
    CHECK(strstr(err, "line 2: unterminated quoted field") != NULL);
    CHECK(hx_csv_parse("a,b\n1,2\n3", &csv, err, sizeof err) != 0);
    CHECK(strstr(err, "line 3: 1 fields") != NULL && strstr(err, "torn") != NULL);
    CHECK(hx_csv_parse("", &csv, err, sizeof err) != 0 && strstr(err, "empty file") != NULL);
    /* a header alone: no rows */
    CHECK(hx_csv_parse("a,b", &csv, err, sizeof err) == 0 && csv.ncol == 2 && csv.nrows == 0);
    hx_csv_free(&csv);
    /* read from a file, sized once: the same rows */
    char *path = tpath("parse.csv");
    write_file(path, text);
    CHECK(hx_csv_read(path, &csv, err, sizeof err) == 0 && csv.nrows == 3);
    CHECK_STR(hx_csv_get(&csv, 0, "c"), "two\nlines");
    hx_csv_free(&csv);
    free(path);
}

/* ---- compare on synthetic studies ---- */

/* Writes a study CSV: per scene two configurations, `reps` samples of
 * base_ms * scale (+ deterministic jitter), counters fixed unless bumped. */
static char *make_study(const char *name, int reps, double scale, long ray_bump, unsigned seed)
{
    char *path = tpath(name);
    char err[256];
    int fd = hx_csv_open_append(path, 1, err, sizeof err);
    if (fd < 0) {
        fprintf(stderr, "%s\n", err);
        exit(2);
    }
    static const char *const scenes[] = {"dragon", "bear"};
    static const char *const accels[] = {"bvh", "none"};
    srand(seed);
    for (int s = 0; s < 2; s++)
        for (int a = 0; a < 2; a++)
            for (int r = 0; r < reps; r++) {
                char **v = calloc((size_t)hx_ncolumns, sizeof *v);
                const char *vv[HX_NDIM];
                for (int d = 0; d < HX_NDIM; d++)
                    vv[d] = "-";
                vv[HX_DIM_SCENE] = scenes[s];
                vv[HX_DIM_BACKEND] = "serial";
                vv[HX_DIM_ACCEL] = accels[a];
                vv[HX_DIM_PIN] = "close";
                for (int d = 0; d < HX_NDIM; d++)
                    v[hx_column_index(hx_dim_col[d])] = hx_strdup(vv[d]);
                char *cid = hx_make_config_id(vv, NULL);
                HxBuf id = {0};
                hx_buf_printf(&id, "%s #r%d", cid, r);
                free(cid);
                v[hx_column_index("run_id")] = id.s;
                v[hx_column_index("study")] = hx_strdup("syn");
                v[hx_column_index("scene_path")] = hx_strdup(scenes[s]);
                v[hx_column_index("workers")] = hx_strdup("1");
                v[hx_column_index("status")] = hx_strdup("ok");
                v[hx_column_index("fingerprint")] = hx_strdup("fp1");
                double base = (s + 1) * (a + 1) * 50.0;
                /* +-3% noise, like this machine on a quiet day */
                double jitter = 1.0 + 0.06 * ((double)rand() / RAND_MAX - 0.5);
                char num[64];
                snprintf(num, sizeof num, "%.3f", base * scale * jitter);
                v[hx_column_index("render_ms")] = hx_strdup(num);
                snprintf(num, sizeof num, "%ld", 1000000L + s * 10 + a + ray_bump);
                v[hx_column_index("rays")] = hx_strdup(num);
                v[hx_column_index("image_fnv1a")] = hx_strdup(s ? "00000000deadbeef" : "0000000012345678");
                hx_csv_append_row(fd, (const char *const *)v);
                for (int i = 0; i < hx_ncolumns; i++)
                    free(v[i]);
                free(v);
            }
    close(fd);
    return path;
}

static int run_compare(const char *nw, const char *base, const char *extra)
{
    char *argv[6];
    int argc = 0;
    argv[argc++] = "compare";
    if (extra)
        argv[argc++] = (char *)extra;
    argv[argc++] = (char *)nw;
    argv[argc++] = (char *)base;
    argv[argc] = NULL;
    optind = 0; /* glibc: full getopt re-initialisation between calls */
    fprintf(stderr, "--- compare %s %s\n", nw, base);
    fflush(stdout);
    return hx_cmd_compare(argc, argv);
}

static void test_compare(void)
{
    char *base = make_study("base.csv", 10, 1.0, 0, 1);
    char *same = make_study("same.csv", 10, 1.0, 0, 2);   /* new noise, same code */
    char *slow = make_study("slow.csv", 10, 2.0, 0, 3);   /* planted 2x slowdown */
    char *bit = make_study("bit.csv", 10, 1.1, 0, 4);     /* 10%: below the factor */
    char *ctr = make_study("ctr.csv", 10, 1.0, 1, 5);     /* one more ray */
    char *few_b = make_study("few_b.csv", 3, 1.0, 0, 6);
    char *few_s = make_study("few_s.csv", 3, 2.0, 0, 7);
    CHECK(run_compare(base, base, NULL) == 0);
    CHECK(run_compare(same, base, NULL) == 0);
    CHECK(run_compare(slow, base, NULL) == 1);
    CHECK(run_compare(bit, base, NULL) == 0);
    CHECK(run_compare(ctr, base, NULL) == 1);
    CHECK(run_compare(few_s, few_b, NULL) == 1); /* 3 samples: min rule */
    CHECK(run_compare(few_b, few_b, NULL) == 0);
    CHECK(run_compare(slow, base, "--factor=2.5") == 0); /* 2x < 2.5 */
    CHECK(run_compare(slow, "/nonexistent.csv", NULL) == 1);
    free(base);
    free(same);
    free(slow);
    free(bit);
    free(ctr);
    free(few_b);
    free(few_s);
}

int main(int argc, char **argv)
{
    if (argc != 2) {
        fprintf(stderr, "usage: test_harness config|expand|stats|csv|compare|pin\n");
        return 2;
    }
    if (!mkdtemp(tmpdir)) {
        perror("mkdtemp");
        return 2;
    }
    char *a = tpath("a.txt"), *b = tpath("b.txt");
    write_file(a, "# dummy: the config parser only checks that scenes exist\n");
    write_file(b, "# dummy\n");
    free(a);
    free(b);
    if (strcmp(argv[1], "config") == 0)
        test_config();
    else if (strcmp(argv[1], "expand") == 0)
        test_expand();
    else if (strcmp(argv[1], "stats") == 0) {
        test_stats();
        test_sync_step();
    }
    else if (strcmp(argv[1], "csv") == 0) {
        test_csv();
        test_csv_parse();
    }
    else if (strcmp(argv[1], "compare") == 0)
        test_compare();
    else if (strcmp(argv[1], "pin") == 0)
        test_pin();
    else {
        fprintf(stderr, "unknown group %s\n", argv[1]);
        return 2;
    }
    char cmd[128];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", tmpdir);
    if (system(cmd) != 0)
        fprintf(stderr, "warning: could not remove %s\n", tmpdir);
    if (failures)
        fprintf(stderr, "%d check(s) failed\n", failures);
    else
        printf("all checks passed (%s)\n", argv[1]);
    return failures ? 1 : 0;
}
