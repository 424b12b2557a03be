/* history_plot.c: a history's series in words and as a plot: legends of
 * the settings that differ between series, machines named by their CPU and
 * GPU, and `harness history plot` (gnuplot, a log axis where the series
 * are 10x apart). Never a hash: it names nothing to a reader. */
#include "history.h"

#if HAVE_SQLITE
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* ---- legends: the settings that differ ------------------------------------- */

/* The settings of a configuration: its "key=value" words (unset ones
 * dropped), a word without '=' joined to the value before it (a scene name
 * with a space in it). */
static void settings(const char *config, HxStrList *k, HxStrList *v)
{
    char lab[2048];
    hx_config_label(lab, sizeof lab, config);
    for (char *save = NULL, *w = strtok_r(lab, " ", &save); w; w = strtok_r(NULL, " ", &save)) {
        char *eq = strchr(w, '=');
        if ((!eq || eq == w) && v->n) {
            HxBuf b = {0};
            hx_buf_printf(&b, "%s %s", v->v[v->n - 1], w);
            free(v->v[v->n - 1]);
            v->v[v->n - 1] = b.s;
            continue;
        }
        if (eq && eq != w)
            *eq = '\0';
        hx_strlist_push(k, w);
        hx_strlist_push(v, eq && eq != w ? eq + 1 : "");
    }
}

/* A setting for people: "openmp", "T=2", "accel bvh". */
static void put_setting(HxBuf *b, const char *key, const char *val)
{
    hx_buf_put(b, b->len ? ", " : "");
    if (strcmp(key, "backend") == 0)
        hx_buf_put(b, val);
    else if (strcmp(key, "threads") == 0 || strcmp(key, "ranks") == 0)
        hx_buf_printf(b, "%s=%s", key[0] == 't' ? "T" : "P", val);
    else
        hx_buf_printf(b, *val ? "%s %s" : "%s", key, val);
}

char *hx_series_machine(const HxSeries *s)
{
    const char *sp = strchr(s->fingerprint, ' ');
    return hx_strndup(s->fingerprint, sp ? (size_t)(sp - s->fingerprint) : strlen(s->fingerprint));
}

/* Series alike in every setting differ in their settings hash (other
 * extra_args, ...): numbered, never named by the hash. */
void hx_series_legends(const HxSeries *const *s, size_t n, char **legend, HxBuf *common)
{
    HxStrList *k = calloc(n, sizeof *k), *v = calloc(n, sizeof *v), keys = {0}, hashes = {0};
    HxBuf *lb = calloc(n, sizeof *lb);
    for (size_t i = 0; i < n; i++) {
        settings(s[i]->config, &k[i], &v[i]);
        for (size_t j = 0; j < k[i].n; j++)
            if (hx_strlist_find(&keys, k[i].v[j]) < 0)
                hx_strlist_push(&keys, k[i].v[j]);
    }
    for (size_t j = 0; j < keys.n; j++) {
        int same = 1, at0 = hx_strlist_find(&k[0], keys.v[j]);
        for (size_t i = 1; i < n && same; i++) {
            int at = hx_strlist_find(&k[i], keys.v[j]);
            same = at0 < 0 ? at < 0 : at >= 0 && strcmp(v[i].v[at], v[0].v[at0]) == 0;
        }
        for (size_t i = 0; i < n; i++) {
            int at = hx_strlist_find(&k[i], keys.v[j]);
            if (at >= 0 && (!same || n == 1))
                put_setting(&lb[i], keys.v[j], v[i].v[at]);
        }
        if (same && at0 >= 0)
            put_setting(common, keys.v[j], v[0].v[at0]);
    }
    int *twin = calloc(n, sizeof *twin);
    for (size_t i = 0; i < n; i++)
        for (size_t j = 0; j < n; j++)
            twin[i] |= j != i && strcmp(lb[i].s ? lb[i].s : "", lb[j].s ? lb[j].s : "") == 0;
    for (size_t i = 0; i < n; i++) {
        const char *h = strchr(s[i]->fingerprint, ' ');
        if (hx_strlist_find(&hashes, h ? h + 1 : "") < 0)
            hx_strlist_push(&hashes, h ? h + 1 : "");
        if (twin[i])
            hx_buf_printf(&lb[i], "%ssettings %d", lb[i].len ? ", " : "", hx_strlist_find(&hashes, h ? h + 1 : "") + 1);
        legend[i] = lb[i].s ? lb[i].s : hx_strdup("");
        hx_strlist_free(&k[i]);
        hx_strlist_free(&v[i]);
    }
    free(twin);
    free(k);
    free(v);
    free(lb);
    hx_strlist_free(&keys);
    hx_strlist_free(&hashes);
}

static void put_part(HxBuf *b, const char *sep, const char *fmt, const char *v)
{
    if (v && *v && strcmp(v, "-") != 0 && strcmp(v, "n/a") != 0) {
        hx_buf_put(b, b->len ? sep : "");
        hx_buf_printf(b, fmt, v);
    }
}

/* A machine (its fingerprint) in words, from the fingerprint columns of one
 * of its runs (they agree on them): "CPU (N cores, M CPUs, SMT s), GPU g"
 * into name; host, compiler, governor and GPU driver into detail (may be
 * NULL). A hash names nothing to a reader. */
void hx_machine_words(sqlite3 *db, const char *dbpath, const char *fp, HxBuf *name, HxBuf *detail)
{
    enum { CPU, CORES, CPUS, SMT, GPU, DRIVER, HOST, COMPILER, GOV, NK };
    static const char *const key[NK] = {"cpu_model", "phys_cores", "logical_cpus", "smt", "gpu_name",
                                        "gpu_driver", "host", "compiler", "governor"};
    HxBuf sql = {0};
    hx_buf_put(&sql, "SELECT 1");
    for (int k = 0; k < NK; k++)
        hx_buf_printf(&sql, ", (SELECT txt FROM vals WHERE run_id = f.id AND key = '%s')", key[k]);
    hx_buf_put(&sql, " FROM (SELECT MIN(id) AS id FROM runs WHERE fingerprint = ?1) f");
    sqlite3_stmt *st = hx_db_prep(db, dbpath, sql.s);
    const char *v[NK];
    for (int k = 0; k < NK; k++)
        v[k] = "";
    if (st && sqlite3_bind_text(st, 1, fp, -1, SQLITE_TRANSIENT) == SQLITE_OK && sqlite3_step(st) == SQLITE_ROW)
        for (int k = 0; k < NK; k++)
            v[k] = sqlite3_column_text(st, k + 1) ? (const char *)sqlite3_column_text(st, k + 1) : "";
    HxBuf cores = {0};
    hx_buf_put(name, *v[CPU] ? v[CPU] : "unknown CPU");
    put_part(&cores, ", ", "%s cores", v[CORES]);
    put_part(&cores, ", ", "%s CPUs", v[CPUS]);
    put_part(&cores, ", ", "SMT %s", v[SMT]);
    if (cores.len)
        hx_buf_printf(name, " (%s)", cores.s);
    int gpu = *v[GPU] && strcmp(v[GPU], "-") != 0;
    hx_buf_printf(name, ", %s%s", gpu ? "GPU " : "no GPU", gpu ? v[GPU] : "");
    if (detail) {
        put_part(detail, "; ", "host %s", v[HOST]);
        put_part(detail, "; ", "compiler %s", v[COMPILER]);
        put_part(detail, "; ", "governor %s", v[GOV]);
        put_part(detail, "; ", "GPU driver %s", v[DRIVER]);
    }
    sqlite3_finalize(st);
    hx_buf_free(&cores);
    hx_buf_free(&sql);
}

/* ---- plot --------------------------------------------------------------- */

static double max_of(const double *x, size_t n)
{
    double m = x[0];
    for (size_t i = 1; i < n; i++)
        m = x[i] > m ? x[i] : m;
    return m;
}

/* The commits of the series, in the order the series hold them (each
 * series is in commit order; a commit missing from one series keeps its
 * place from the others). */
void hx_series_commit_order(const HxSeriesSet *ss, HxStrList *order)
{
    for (size_t i = 0; i < ss->n; i++) {
        int at = -1;
        for (size_t k = 0; k < ss->s[i].np; k++) {
            int j = hx_strlist_find(order, ss->s[i].p[k].sha);
            if (j < 0) {
                /* insert after the previous commit of this series */
                hx_strlist_push(order, ss->s[i].p[k].sha);
                j = (int)order->n - 1;
                for (int m = j; m > at + 1; m--) {
                    char *t = order->v[m];
                    order->v[m] = order->v[m - 1];
                    order->v[m - 1] = t;
                }
                j = at + 1;
            }
            at = j;
        }
    }
}

/* One block per series, headed by its legend; how far apart the series
 * are (the largest of their medians over the smallest) into *spread, the
 * range of the points' medians into lo, hi. */
static void write_history_dat(FILE *dat, const HxSeriesSet *ss, const HxStrList *order, char **legend,
                              double *spread, double *lo, double *hi)
{
    double slo = INFINITY, shi = 0;
    *lo = INFINITY, *hi = 0;
    fprintf(dat, "# x median min max commit (one block per series)\n");
    for (size_t i = 0; i < ss->n; i++) {
        char lab[512];
        hx_plot_clean_label(lab, sizeof lab, legend[i]);
        fprintf(dat, "\"%s\"\n", lab);
        double *med = calloc(ss->s[i].np + 1, sizeof *med);
        for (size_t k = 0; k < ss->s[i].np; k++) {
            const HxSeriesPoint *p = &ss->s[i].p[k];
            double m = med[k] = hx_median(p->x, p->n);
            *lo = m > 0 && m < *lo ? m : *lo;
            *hi = m > *hi ? m : *hi;
            fprintf(dat, "%d %.6g %.6g %.6g %s\n", hx_strlist_find(order, p->sha), m, hx_min(p->x, p->n),
                    max_of(p->x, p->n), p->sha);
        }
        double sm = ss->s[i].np ? hx_median(med, ss->s[i].np) : 0;
        slo = sm > 0 && sm < slo ? sm : slo;
        shi = sm > shi ? sm : shi;
        free(med);
        fprintf(dat, "\n\n");
    }
    *spread = shi > 0 && isfinite(slo) ? shi / slo : 1;
}

/* Legends of the settings that differ (hx_series_legends), the machine in
 * words before each when the series come from several; what all share
 * into title. */
static void history_legends(sqlite3 *db, const char *dbpath, const HxSeriesSet *ss, char **legend, HxBuf *title)
{
    const HxSeries **ptr = calloc(ss->n, sizeof *ptr);
    int *machine = calloc(ss->n, sizeof *machine); /* series i's index in fps */
    HxStrList fps = {0};
    for (size_t i = 0; i < ss->n; i++) {
        ptr[i] = &ss->s[i];
        char *fp = hx_series_machine(&ss->s[i]);
        if ((machine[i] = hx_strlist_find(&fps, fp)) < 0) {
            machine[i] = (int)fps.n;
            hx_strlist_push(&fps, fp);
        }
        free(fp);
    }
    HxBuf common = {0};
    hx_series_legends(ptr, ss->n, legend, &common);
    if (common.len)
        hx_buf_printf(title, "\nall series: %s", common.s);
    for (size_t m = 0; m < fps.n; m++) {
        HxBuf name = {0};
        hx_machine_words(db, dbpath, fps.v[m], &name, NULL);
        if (fps.n > 1)
            hx_buf_printf(title, "\nmachine %zu: %s", m + 1, name.s);
        else
            hx_buf_printf(title, "\non %s", name.s);
        hx_buf_free(&name);
    }
    for (size_t i = 0; fps.n > 1 && i < ss->n; i++) {
        HxBuf l = {0};
        hx_buf_printf(&l, "machine %d%s%s", machine[i] + 1, *legend[i] ? ", " : "", legend[i]);
        free(legend[i]);
        legend[i] = l.s;
    }
    hx_buf_free(&common);
    hx_strlist_free(&fps);
    free(machine);
    free(ptr);
}

/* The commits as x tic labels, rotated: short hashes. */
static void gp_xtics(FILE *gp, const HxStrList *order)
{
    fprintf(gp, "set xtics rotate by -45 (");
    for (size_t k = 0; k < order->n; k++) {
        char sha[16];
        snprintf(sha, sizeof sha, "%.9s", order->v[k]);
        HxBuf q = {0};
        hx_gp_quote(&q, sha);
        fprintf(gp, "%s%s %zu", k ? ", " : "", q.s, k);
        hx_buf_free(&q);
    }
    fprintf(gp, ")\nset xlabel 'commit'\n");
}

int hx_history_plot(sqlite3 *db, const char *dbpath, const HxSeriesSet *ss, const char *metric,
                    const char *prefix)
{
    HxPlot c;
    if (hx_plot_init(&c, "harness history plot", prefix) != 0)
        return 1;
    FILE *dat, *gp = hx_plot_open(&c, "history", &dat);
    if (!gp) {
        hx_plot_done(&c);
        return 1;
    }
    HxStrList order = {0};
    hx_series_commit_order(ss, &order);
    char **legend = calloc(ss->n, sizeof *legend);
    HxBuf t = {0};
    hx_buf_printf(&t, "%s over commits (median, bars: min to max)", metric);
    history_legends(db, dbpath, ss, legend, &t);
    double spread, lo, hi;
    write_history_dat(dat, ss, &order, legend, &spread, &lo, &hi);
    hx_plot_head(gp, &c, "history", t.s);
    hx_buf_free(&t);
    gp_xtics(gp, &order);
    /* series 10x apart on a linear axis flatten the small ones to a line */
    HxBuf yl = {0};
    hx_buf_printf(&yl, "%s%s", metric, spread >= 10 ? " (log scale)" : "");
    hx_plot_put(gp, spread >= 10 ? "set logscale y\nset ylabel %s\n" : "set ylabel %s\n", yl.s);
    if (spread >= 10)
        hx_plot_log_tics(gp, "y", lo, hi);
    hx_buf_free(&yl);
    fprintf(gp, "set key below\nset offsets 0.3, 0.3, 0, 0\n");
    fprintf(gp, "plot for [i=0:%zu] ", ss->n - 1);
    hx_plot_file(gp, "%s index i using 1:2:3:4 with yerrorlines title columnheader(1)\n", c.base, "history", "dat");
    hx_plot_tail(gp, &c, "history");
    hx_plot_finish(&c, "history", gp, dat);
    hx_strlist_free(&order);
    for (size_t i = 0; i < ss->n; i++)
        free(legend[i]);
    free(legend);
    int rc = c.failures ? 1 : 0;
    hx_plot_done(&c);
    return rc;
}

#endif
