/* ceiling.c: `harness ceiling CONFIG`: the machine's own scaling ceiling.
 *
 * W workers of a parallel run share more than cores: memory bandwidth,
 * caches, turbo budget, a VM's host. W independent one-worker copies of the
 * study's workload, run at once and pinned one per core where the study
 * pins a W-worker run, have no communication and no serial part, so the
 * speed each keeps against a copy alone is the best efficiency any parallel
 * code can reach there (the "throughput ceiling"; Hoefler and Belli,
 * "Scientific benchmarking of parallel computing systems", SC 2015, ask
 * for such a machine baseline). `table` reports efficiency against it.
 * Each scene of the plan has its own: a scene's copies are its own work.
 * The copies themselves: ceiling_copies.c. */
#include "ceiling.h"
#include "program.h"

#include <errno.h>
#include <fcntl.h>
#include <getopt.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

/* The study's one-worker workload: its first run with one worker, no MPI,
 * serial for raytrace. */
static void one_worker(const HxConfig *cfg, const HxRun *first, HxRun *one)
{
    *one = *first;
    one->v[HX_DIM_RANKS] = "-";
    if (!cfg->prog) {
        one->v[HX_DIM_BACKEND] = "serial";
        one->v[HX_DIM_THREADS] = one->v[HX_DIM_BLOCK] = one->v[HX_DIM_SCHEDULE] = one->v[HX_DIM_MPI_SCHEDULE] = "-";
    } else if (strcmp(first->v[HX_DIM_THREADS], "-") != 0) {
        one->v[HX_DIM_THREADS] = "1";
    }
    one->v[HX_DIM_PIN] = "none"; /* spawn binds */
    one->workers = 1;
}

typedef struct {
    const char *out, *rt_opt;
    int repeats;
    HxStrList set;
} CeilOpts;

static int ceiling_opts(int argc, char **argv, CeilOpts *o)
{
    static const struct option lo[] = {{"output", required_argument, NULL, 'o'}, {"repeats", required_argument, NULL, 'r'},
                                       {"set", required_argument, NULL, 's'}, {"raytrace", required_argument, NULL, 't'},
                                       {"help", no_argument, NULL, 'h'}, {NULL, 0, NULL, 0}};
    memset(o, 0, sizeof *o);
    o->repeats = 3;
    long v;
    int c;
    while ((c = getopt_long(argc, argv, "o:h", lo, NULL)) != -1) {
        switch (c) {
        case 'o': o->out = optarg; break;
        case 'r':
            if (hx_parse_int(optarg, 1, 1000, &v)) {
                fprintf(stderr, "harness ceiling: --repeats: expected an integer >= 1, got '%s'\n", optarg);
                return 1;
            }
            o->repeats = (int)v;
            break;
        case 's': hx_strlist_push(&o->set, optarg); break;
        case 't': o->rt_opt = optarg; break;
        case 'h':
            fputs("usage: harness ceiling CONFIG [--repeats N] [-o FILE] [--set KEY=VALUE]... [--raytrace PATH]\n"
                  "For each scene and worker count W of CONFIG's plan, runs W one-worker copies of the\n"
                  "study's workload at once, pinned one per core where the study pins W workers, against one\n"
                  "copy alone: the speed each copy keeps is the machine's ceiling for W-worker\n"
                  "efficiency. Writes FILE (default results/ceiling-FINGERPRINT.csv), which `table`\n"
                  "reads (docs/harness-noise.md, \"Ceiling\").\n"
                  "  --repeats N      rounds of copies at each W (default 3); the median is kept\n"
                  "  -o FILE          where to write (a new file or a ceiling file, never another)\n"
                  "  --set KEY=VALUE  override a config key, as `run --set` does (repeatable)\n"
                  "  --raytrace PATH  the renderer, as `run --raytrace`\n"
                  "  -h, --help       this text\n", stdout);
            return 0;
        default: return 1;
        }
    }
    if (argc - optind != 1) {
        fprintf(stderr, "harness ceiling: expected one CONFIG (see --help)\n");
        return 1;
    }
    return -1;
}

/* One scene of the plan: its first run (the copies' workload) and its
 * pinned worker counts above 1, ws[i] workers on cores[i]. */
#define CEIL_MAX_W 64 /* worker counts a scene's ceiling measures */
typedef struct {
    const char *name;
    const HxRun *first;
    int ws[CEIL_MAX_W], *cores[CEIL_MAX_W], nw, wmax;
} CeilScene;

/* The scene's pinned worker counts (CeilScene). */
static void worker_counts(const HxPlan *plan, CeilScene *sc)
{
    sc->nw = 0, sc->wmax = 1;
    for (size_t i = 0; i < plan->n && sc->nw < CEIL_MAX_W; i++) {
        const HxRun *r = &plan->runs[i];
        int seen = strcmp(r->scene_name, sc->name) != 0;
        for (int k = 0; k < sc->nw; k++)
            seen |= sc->ws[k] == r->workers;
        if (seen || r->workers < 2 || r->ncores != r->workers || r->oversubscribed)
            continue;
        sc->ws[sc->nw] = r->workers;
        sc->cores[sc->nw++] = r->cores;
        sc->wmax = r->workers > sc->wmax ? r->workers : sc->wmax;
    }
}

/* The copies of a plan's scenes, ready to run. */
struct HxCeilRounds {
    const HxConfig *cfg;
    const HxTopo *t;
    const HxFingerprint *fp;
    const char *rt;
    CeilScene *sc;
    int nsc, nw;  /* scenes; worker counts of them all */
    HxCopies cp;  /* of scene built */
    int built;    /* -1 none */
    char *tmp;    /* the copies' folder */
    char *path;   /* ceiling: rounds: the file its rows go to */
    int fd;       /* open on it (hx_ceiling_rounds_start) */
    int keep;     /* --resume: its rows kept */
    HxStrList kept; /* "ROUND\tSCENE\tW" of its rows from before (--resume) */
};

/* The plan's scenes and their worker counts into c (nothing made yet). */
static void ceil_plan(HxCeilRounds *c, const HxConfig *cfg, const HxPlan *plan, const HxTopo *t, const char *rt)
{
    memset(c, 0, sizeof *c);
    c->cfg = cfg, c->t = t, c->rt = rt, c->built = -1, c->fd = -1;
    for (size_t i = 0; i < plan->n; i++) {
        int seen = 0;
        for (int k = 0; k < c->nsc && !seen; k++)
            seen = strcmp(c->sc[k].name, plan->runs[i].scene_name) == 0;
        if (seen)
            continue;
        c->sc = hx_xrealloc(c->sc, (size_t)(c->nsc + 1) * sizeof *c->sc);
        CeilScene *sc = &c->sc[c->nsc++];
        sc->name = plan->runs[i].scene_name;
        sc->first = &plan->runs[i];
        worker_counts(plan, sc);
        c->nw += sc->nw;
    }
}

/* What refuses a ceiling before anything is made or run: one line on
 * stderr and -1, else 0. */
static int ceil_check(const HxCeilRounds *c, const char *who)
{
    if (c->t->ncores < 2 || !c->t->have_hwloc) {
        fprintf(stderr, "%s: %s: one copy per core needs two cores or more and hwloc to pin them\n", who,
                c->t->ncores < 2 ? "only one core is allowed here" : "built without hwloc");
        return -1;
    }
    if (c->nw == 0) {
        fprintf(stderr, "%s: %s plans no pinned run of 2 to %d workers: no ceiling to measure\n", who, c->cfg->path,
                c->t->ncores);
        return -1;
    }
    return 0;
}

/* The copies' folder (after ceil_check). 0, or -1 (said). */
static int ceil_open(HxCeilRounds *c, const char *who)
{
    char err[512];
    c->tmp = hx_temp_dir("ceiling", err, sizeof err);
    if (!c->tmp)
        fprintf(stderr, "%s: %s\n", who, err);
    return c->tmp ? 0 : -1;
}

/* Scene k's copies built (the scene cache resolved before). 0, or -1. */
static int ceil_build(HxCeilRounds *c, int k)
{
    if (c->built == k)
        return 0;
    hx_copies_free(&c->cp);
    c->built = -1;
    HxRun one;
    one_worker(c->cfg, c->sc[k].first, &one);
    HxBuf work = {0};
    hx_buf_printf(&work, "%s/work-%d", c->tmp, k);
    const int rc = hx_copies_build(&c->cp, c->cfg, c->t, &one, c->rt, c->tmp, work.s, c->sc[k].wmax);
    hx_buf_free(&work);
    c->built = rc ? -1 : k;
    return rc;
}

/* Scene k's worker counts (but those where skip[i]), repeats each: a line
 * each on say, a row each into b. 0, or -1 (a copy failed or a stop
 * signal came). */
static int ceil_scene(HxCeilRounds *c, int k, const int *skip, int repeats, int round, FILE *say, HxBuf *b)
{
    const CeilScene *sc = &c->sc[k];
    HxCeilKey key = {c->fp, c->cfg->path, sc->name, round, c->nsc > 1};
    int rc = ceil_build(c, k);
    for (int w = 0; w < sc->nw && rc == 0 && !hx_stop_signal(); w++)
        if (!skip || !skip[w])
            rc = hx_copies_measure(&c->cp, c->t, sc->ws[w], sc->cores[w], repeats, &key, say, b);
    hx_reap_strays(); /* no copy of a failed round left on a core */
    return rc || hx_stop_signal() ? -1 : 0;
}

static void ceil_close(HxCeilRounds *c)
{
    hx_copies_free(&c->cp);
    if (c->tmp)
        hx_rmtree(c->tmp);
    if (c->fd >= 0)
        close(c->fd);
    free(c->tmp);
    free(c->path);
    free(c->sc);
    hx_strlist_free(&c->kept);
}

/* Only wakes sigsuspend in run_copies: the default would discard it. */
static void on_child(int sig) { (void)sig; }

char *hx_ceiling_rounds_path(const char *csv_path)
{
    const size_t n = strlen(csv_path), cut = n >= 4 && strcmp(csv_path + n - 4, ".csv") == 0 ? n - 4 : n;
    HxBuf b = {0};
    hx_buf_printf(&b, "%.*s-ceiling.csv", (int)cut, csv_path);
    return b.s;
}

#define ROUNDS_WHO "harness run: ceiling: rounds"

int hx_ceiling_rounds_check(const HxConfig *cfg, const HxPlan *plan, const HxTopo *t)
{
    HxCeilRounds c;
    ceil_plan(&c, cfg, plan, t, NULL);
    const int rc = ceil_check(&c, ROUNDS_WHO);
    ceil_close(&c);
    return rc;
}

/* Whether text starts with this harness's header; a line where not. */
static int own_header(const HxCeilRounds *c, const HxBuf *text)
{
    const size_t hlen = strlen(HX_CEIL_HEADER);
    if (text->len >= hlen && memcmp(text->s, HX_CEIL_HEADER, hlen) == 0)
        return 1;
    fprintf(stderr, "%s: %s: its header is not this harness's; move it away, or start the study again\n", ROUNDS_WHO,
            c->path);
    return 0;
}

/* The rounds' file before the study's CSV is opened, nothing written: a
 * regular file one can write, or one its folder can take; with keep
 * (--resume), this harness's header. 0, or -1 (said). */
static int rounds_check(HxCeilRounds *c)
{
    struct stat st;
    const int missing = stat(c->path, &st) != 0;
    if (missing && errno != ENOENT) {
        fprintf(stderr, "%s: %s: %s\n", ROUNDS_WHO, c->path, strerror(errno));
        return -1;
    }
    if (missing) { /* its folder must take it */
        char *dir = hx_dirname(c->path);
        const int rc = access(dir, W_OK | X_OK) == 0 ? 0 : -1;
        if (rc)
            fprintf(stderr, "%s: %s: cannot create %s there: %s\n", ROUNDS_WHO, dir, c->path, strerror(errno));
        free(dir);
        return rc;
    }
    if (!S_ISREG(st.st_mode) || access(c->path, W_OK) != 0) {
        fprintf(stderr, "%s: %s: %s\n", ROUNDS_WHO, c->path,
                S_ISREG(st.st_mode) ? strerror(errno) : "not a regular file");
        return -1;
    }
    HxBuf text = {0};
    int rc = 0;
    if (c->keep && st.st_size > 0 && hx_read_file(c->path, &text) != 0)
        rc = -1, fprintf(stderr, "%s: %s: %s\n", ROUNDS_WHO, c->path, strerror(errno));
    else if (c->keep && st.st_size > 0 && !own_header(c, &text))
        rc = -1;
    hx_buf_free(&text);
    return rc;
}

/* --resume, the study's CSV locked: the rows in the file (text, its
 * header this harness's) into c->kept, a row cut short (a power loss)
 * dropped. 0, or -1 (said). */
static int rounds_keep(HxCeilRounds *c, HxBuf *text)
{
    size_t whole = text->len;
    while (whole > 0 && text->s[whole - 1] != '\n')
        whole--;
    if (whole < text->len) {
        fprintf(stderr, "%s: %s: dropping a torn last row\n", ROUNDS_WHO, c->path);
        if (ftruncate(c->fd, (off_t)whole) != 0) {
            fprintf(stderr, "%s: %s: %s\n", ROUNDS_WHO, c->path, strerror(errno));
            return -1;
        }
    }
    text->s[whole] = '\0';
    HxCsv csv;
    char err[512];
    if (hx_csv_parse(text->s, &csv, err, sizeof err) != 0) {
        fprintf(stderr, "%s: %s: %s\n", ROUNDS_WHO, c->path, err);
        return -1;
    }
    for (size_t r = 0; r < csv.nrows; r++) {
        HxBuf k = {0};
        hx_buf_printf(&k, "%s\t%s\t%s", hx_csv_get(&csv, r, "round"), hx_csv_get(&csv, r, "scene"),
                      hx_csv_get(&csv, r, "workers"));
        hx_strlist_push(&c->kept, k.s);
        hx_buf_free(&k);
    }
    hx_csv_free(&csv);
    return 0;
}

HxCeilRounds *hx_ceiling_rounds_open(const HxConfig *cfg, const HxPlan *plan, const HxTopo *t, const char *raytrace,
                                     const char *path, int keep)
{
    HxCeilRounds *c = hx_xmalloc(sizeof *c);
    ceil_plan(c, cfg, plan, t, raytrace);
    c->path = hx_strdup(path);
    c->keep = keep;
    if (ceil_check(c, ROUNDS_WHO) != 0 || rounds_check(c) != 0 || ceil_open(c, ROUNDS_WHO) != 0) {
        hx_ceiling_rounds_close(c);
        return NULL;
    }
    return c;
}

int hx_ceiling_rounds_start(HxCeilRounds *c, const HxFingerprint *fp, int quiet)
{
    c->fp = fp;
    /* the file belongs to the study's CSV, read now that its lock is
     * held: a new study starts it again */
    c->fd = open(c->path, O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    HxBuf text = {0};
    int rc = c->fd < 0 ? -1 : 0;
    if (rc == 0 && c->keep && hx_read_file(c->path, &text) != 0)
        rc = -1;
    else if (rc == 0 && !c->keep)
        rc = ftruncate(c->fd, 0);
    if (rc != 0) {
        fprintf(stderr, "%s: %s: %s\n", ROUNDS_WHO, c->path, strerror(errno));
    } else if (text.len > 0 && !own_header(c, &text)) {
        rc = -1;
    } else if (text.len > 0) {
        rc = rounds_keep(c, &text);
    } else {
        const size_t hlen = strlen(HX_CEIL_HEADER);
        if (write(c->fd, HX_CEIL_HEADER, hlen) != (ssize_t)hlen || fsync(c->fd) != 0) {
            fprintf(stderr, "%s: %s: %s\n", ROUNDS_WHO, c->path, strerror(errno));
            if (ftruncate(c->fd, 0) != 0) /* a torn header reads as another file's */
                fprintf(stderr, "%s: %s: a torn header left: %s\n", ROUNDS_WHO, c->path, strerror(errno));
            rc = -1;
        }
    }
    hx_buf_free(&text);
    if (rc == 0 && !quiet)
        fprintf(stderr, "%s: the copies before each round, into %s\n", ROUNDS_WHO, c->path);
    return rc;
}

int hx_ceiling_rounds_measure(HxCeilRounds *c, const char *scene, int round, int quiet)
{
    int k = 0;
    while (k < c->nsc && strcmp(c->sc[k].name, scene) != 0)
        k++;
    if (k == c->nsc || c->sc[k].nw == 0) /* no pinned worker count: no ceiling */
        return 0;
    /* the worker counts of this round measured before --resume keep their
     * rows; those the study grew by are measured */
    int skip[CEIL_MAX_W], todo = 0;
    for (int w = 0; w < c->sc[k].nw; w++) {
        HxBuf key = {0};
        hx_buf_printf(&key, "%d\t%s\t%d", round, scene, c->sc[k].ws[w]);
        skip[w] = hx_strlist_find(&c->kept, key.s) >= 0;
        todo += !skip[w];
        hx_buf_free(&key);
    }
    if (!todo)
        return 0;
    struct sigaction sa, old;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_child;
    sa.sa_flags = SA_RESTART;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGCHLD, &sa, &old);
    HxBuf b = {0};
    int rc = ceil_scene(c, k, skip, 1, round, quiet ? NULL : stderr, &b);
    sigaction(SIGCHLD, &old, NULL);
    /* whole rows only, appended after the round's copies all ended; a
     * write cut short (a full disk) is cut back off */
    const off_t end = rc ? 0 : lseek(c->fd, 0, SEEK_END);
    if (!rc && (end < 0 || write(c->fd, b.s, b.len) != (ssize_t)b.len || fsync(c->fd) != 0)) {
        fprintf(stderr, "%s: %s: %s\n", ROUNDS_WHO, c->path, strerror(errno));
        if (end >= 0 && ftruncate(c->fd, end) != 0)
            fprintf(stderr, "%s: %s: a torn row left: %s\n", ROUNDS_WHO, c->path, strerror(errno));
        rc = -1;
    }
    hx_buf_free(&b);
    return rc;
}

void hx_ceiling_rounds_close(HxCeilRounds *c)
{
    if (!c)
        return;
    ceil_close(c);
    free(c);
}

/* Every scene's ceiling, repeats each, into b (its header first). 0, or
 * the exit status. */
static int ceil_all(HxCeilRounds *c, int repeats, HxBuf *b)
{
    fprintf(stderr, "harness ceiling: %s on %s: %d worker count(s)%s, %d repeat(s) each, copies measured by %s\n",
            c->cfg->path, c->fp->host, c->nw, c->nsc > 1 ? " of its scenes" : "", repeats, hx_ceil_metric(c->cfg).name);
    hx_buf_put(b, HX_CEIL_HEADER);
    int rc = 0;
    for (int k = 0; k < c->nsc && rc == 0; k++)
        if (c->sc[k].nw > 0)
            rc = ceil_scene(c, k, NULL, repeats, -1, stdout, b) != 0;
    if (hx_stop_signal()) {
        fprintf(stderr, "harness ceiling: stopped by %s: its copies ended, no ceiling written\n",
                hx_signal_name(hx_stop_signal()));
        rc = 128 + hx_stop_signal();
    }
    return rc;
}

/* What a ceiling file starts with, in every version of its header. */
#define CEIL_OWN "fingerprint,host,workers,repeats,ratio_median,"

/* b into -o FILE, else results/ceiling-FINGERPRINT.csv. 0 or 1. */
static int ceil_write(const char *out, const HxFingerprint *fp, const HxBuf *b)
{
    HxBuf path = {0};
    if (out)
        hx_buf_put(&path, out);
    else
        hx_buf_printf(&path, "%sceiling-%s.csv", hx_is_dir("results") ? "results/" : "", fp->fingerprint);
    if (hx_may_replace("harness ceiling", path.s, CEIL_OWN) != 0) {
        hx_buf_free(&path);
        return 1;
    }
    FILE *f = fopen(path.s, "w");
    int rc = 0;
    if (!f || fputs(b->s, f) == EOF || fclose(f) != 0) {
        fprintf(stderr, "harness ceiling: %s: %s\n", path.s, strerror(errno));
        rc = 1;
    } else {
        fprintf(stderr, "harness ceiling: wrote %s\n", path.s);
    }
    hx_buf_free(&path);
    return rc;
}

int hx_cmd_ceiling(int argc, char **argv)
{
    CeilOpts o;
    hx_install_stop_handlers();
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_child;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGCHLD, &sa, NULL);
    int rc = ceiling_opts(argc, argv, &o);
    HxConfig cfg;
    if (rc < 0 && hx_config_open_set(argv[optind], &o.set, &cfg) != 0)
        rc = 1;
    hx_strlist_free(&o.set);
    if (rc >= 0)
        return rc;
    HxPlan plan;
    HxTopo t;
    hx_expand(&cfg, &plan);
    hx_topo_load(&t);
    hx_plan_cores(&t, &cfg, &plan);
    HxFingerprint fp;
    HxBuf b = {0};
    char *rt = hx_find_raytrace(&cfg, o.rt_opt);
    HxCeilRounds c;
    ceil_plan(&c, &cfg, &plan, &t, rt);
    rc = ceil_check(&c, "harness ceiling") != 0;
    /* (-o checked before the copies run, and again when written) */
    rc = rc || (o.out && hx_may_replace("harness ceiling", o.out, CEIL_OWN) != 0);
    if (rc == 0 && !cfg.prog) /* the scene cache only for a ceiling that will run */
        hx_resolve_scene_cache(&cfg, NULL);
    rc = rc || ceil_open(&c, "harness ceiling") != 0;
    if (rc == 0) {
        hx_fingerprint_get(&fp, &t, 0, cfg.prog ? NULL : rt, NULL, NULL);
        c.fp = &fp;
        rc = ceil_all(&c, o.repeats, &b);
    }
    ceil_close(&c);
    if (rc == 0)
        rc = ceil_write(o.out, &fp, &b);
    free(rt);
    hx_buf_free(&b);
    hx_topo_free(&t);
    hx_plan_free(&plan);
    hx_config_free(&cfg);
    return rc;
}
