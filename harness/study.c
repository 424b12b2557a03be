/* study.c: the study model every analysis reads (table, plot, compare).
 *
 * A study CSV becomes groups, one per configuration of one scene, with the
 * ok samples of the chosen metric, their statistics, the series a scaling
 * study draws and the speedup baselines.
 *
 * The correctness gate is re-applied here from the CSV alone (two passes, so
 * the reference is the first ok serial run of each image even if it was
 * written after a parallel run): a fast wrong image never enters a table. */
#include "hx.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* The row's configuration; with skip >= 0, that dimension replaced by "*"
 * (the series the row belongs to); skip == -2: both worker dimensions. */
static char *row_config_id(const HxCsv *csv, size_t r, int skip)
{
    const char *v[HX_NDIM];
    for (int d = 0; d < HX_NDIM; d++) {
        v[d] = hx_csv_get(csv, r, hx_dim_col[d]);
        if (d == skip || (skip == -2 && (d == HX_DIM_THREADS || d == HX_DIM_RANKS)))
            v[d] = "*";
    }
    /* a command study: its program and params are part of it */
    const char *params = hx_csv_get(csv, r, "params");
    char *id = hx_make_config_id(v, params);
    if (strcmp(v[HX_DIM_BACKEND], "-") != 0)
        return id;
    HxBuf b = {0};
    hx_buf_printf(&b, "program=%s %s", hx_csv_get(csv, r, "program"), id);
    free(id);
    return b.s;
}

/* The swept worker dimension of a row: threads for OpenMP, ranks for MPI;
 * a command study's ranks if it has them, else its threads; -2: none. */
static int swept_dim(const HxCsv *csv, size_t r, const char *backend)
{
    if (strcmp(backend, "-") == 0)
        return strcmp(hx_csv_get(csv, r, "ranks"), "-") != 0     ? HX_DIM_RANKS
               : strcmp(hx_csv_get(csv, r, "threads"), "-") != 0 ? HX_DIM_THREADS
                                                                 : -2;
    return strcmp(backend, "openmp") == 0 ? HX_DIM_THREADS : hx_backend_mpi(backend) ? HX_DIM_RANKS : -2;
}

static int dim_int(const HxCsv *csv, size_t r, int d)
{
    long v;
    return hx_parse_int(hx_csv_get(csv, r, hx_dim_col[d]), 1, 1 << 20, &v) == 0 ? (int)v : 1;
}

/* A series is one fixed value of every dimension but the one swept: threads
 * for OpenMP, ranks for MPI (at fixed threads per rank); in a hybrid study
 * (threads and ranks both swept) also threads at fixed ranks (series2). */
static void group_series(HxGroup *g, const HxCsv *csv, size_t r, const int *varies)
{
    int swept = swept_dim(csv, r, g->backend);
    g->swept = swept;
    g->series_id = row_config_id(csv, r, swept);
    g->axis = swept >= 0 ? dim_int(csv, r, swept) : 1;
    if (swept == HX_DIM_RANKS && varies[HX_DIM_THREADS] && varies[HX_DIM_RANKS]) {
        g->series2_id = row_config_id(csv, r, HX_DIM_THREADS);
        g->axis2 = dim_int(csv, r, HX_DIM_THREADS);
    }
}

/* Oversubscribed runs and runs whose pinning did not hold measure the
 * machine's contention, not the code's scaling. */
static void note_suspect(HxGroup *g, const HxCsv *csv, size_t r)
{
    const char *noise = hx_csv_get(csv, r, "noise");
    g->nbusy += strstr(noise, "busy") != NULL;
    if (strstr(noise, "stolen")) { /* (flagged rows only: a short run's few ticks read high) */
        g->nstolen++;
        double steal;
        if (hx_parse_double(hx_csv_get(csv, r, "steal_pct"), &steal) == 0 && steal > g->steal_max)
            g->steal_max = steal;
    }
    g->npartial += strcmp(hx_csv_get(csv, r, "status"), "ok") == 0 && strcmp(hx_csv_get(csv, r, "pin_held"), "partial") == 0;
    if (strcmp(hx_csv_get(csv, r, "oversubscribed"), "1") == 0) {
        g->suspect = 1;
        g->suspect_why = "oversubscribed";
    } else if (strcmp(hx_csv_get(csv, r, "status"), "ok") == 0 && strcmp(hx_csv_get(csv, r, "pin_held"), "no") == 0) {
        g->suspect = 1;
        g->suspect_why = "pinning did not hold";
    }
}

/* Does a dimension take more than one value in the study? Only those go into
 * labels, so a label reads "openmp/bvh T=2", not twelve key=value pairs. */
static int dim_varies(const HxCsv *csv, const char *col)
{
    const char *first = NULL;
    for (size_t r = 0; r < csv->nrows; r++) {
        const char *v = hx_csv_get(csv, r, col);
        if (strcmp(v, "-") == 0)
            continue;
        if (!first)
            first = v;
        else if (strcmp(first, v) != 0)
            return 1;
    }
    return 0;
}

/* Whether param key takes more than one value in the study's rows. */
static int param_varies(const HxCsv *csv, const char *key)
{
    char first[128] = "", v[128];
    for (size_t r = 0; r < csv->nrows; r++) {
        if (!hx_kv_get(hx_csv_get(csv, r, "params"), key, v, sizeof v))
            continue;
        if (!first[0])
            snprintf(first, sizeof first, "%s", v);
        else if (strcmp(first, v) != 0)
            return 1;
    }
    return 0;
}

/* A command study's params that vary, as " NAME=VALUE". */
static void label_params(HxBuf *b, const HxCsv *csv, size_t r)
{
    const char *p = hx_csv_get(csv, r, "params");
    while (*p) {
        size_t n = strcspn(p, ";"), k = strcspn(p, "=");
        char key[128];
        snprintf(key, sizeof key, "%.*s", (int)(k < n ? k : n), p);
        if (param_varies(csv, key))
            hx_buf_printf(b, " %.*s", (int)n, p);
        p += n + (p[n] == ';');
    }
}

static char *row_label(const HxCsv *csv, size_t r, int with_workers, const int *varies)
{
    HxBuf b = {0};
    const char *be = hx_csv_get(csv, r, "backend");
    hx_buf_put(&b, strcmp(be, "-") == 0 && *hx_csv_get(csv, r, "program") ? hx_csv_get(csv, r, "program") : be);
    const char *acc = hx_csv_get(csv, r, "accel");
    if (strcmp(acc, "-") != 0)
        hx_buf_printf(&b, "/%s", acc);
    static const struct { int dim; const char *pfx; } shown[] = {
        {HX_DIM_THREADS, "T="}, {HX_DIM_RANKS, "P="}, {HX_DIM_BLOCK, "B="}};
    for (size_t i = 0; i < 3; i++) {
        if (!with_workers && i < 2)
            continue;
        const char *v = hx_csv_get(csv, r, hx_dim_col[shown[i].dim]);
        if (strcmp(v, "-") != 0 && *v)
            hx_buf_printf(&b, " %s%s", shown[i].pfx, v);
    }
    for (int d = HX_DIM_RESOLUTION; d < HX_NDIM; d++) {
        if (d == HX_DIM_THREADS || d == HX_DIM_RANKS || d == HX_DIM_BLOCK || !varies[d])
            continue;
        const char *v = hx_csv_get(csv, r, hx_dim_col[d]);
        if (strcmp(v, "-") != 0 && *v)
            hx_buf_printf(&b, " %s=%s", hx_dim_col[d], v);
    }
    label_params(&b, csv, r);
    return b.s;
}

/* The value of KEY in the row's `extra` (k1=v1;k2=v2), or NULL; the
 * number is copied into num. */
static const char *extra_value(const HxCsv *csv, size_t r, const char *key, char *num, size_t n)
{
    return hx_kv_get(hx_csv_get(csv, r, "extra"), key, num, n);
}

/* The metric of row r: a numeric column, a record key kept in `extra`, or
 * "COLUMN/calib": the column divided by the row's calib_ms (raytrace
 * --calibrate), a time in units of the machine's speed at that moment. */
static int row_metric(const HxCsv *csv, size_t r, const char *metric, double *out)
{
    const char *slash = strchr(metric, '/');
    char num[32];
    if (!slash && hx_csv_col(csv, metric) < 0) /* a record key kept in `extra` */
        return extra_value(csv, r, metric, num, sizeof num) ? hx_parse_double(num, out) : -1;
    if (!slash)
        return hx_parse_double(hx_csv_get(csv, r, metric), out);
    char col[64];
    size_t n = (size_t)(slash - metric);
    if (n >= sizeof col)
        return -1;
    memcpy(col, metric, n);
    col[n] = '\0';
    double v, c;
    if (hx_parse_double(hx_csv_get(csv, r, col), &v) != 0 || !extra_value(csv, r, "calib_ms", num, sizeof num))
        return -1;
    if (hx_parse_double(num, &c) != 0 || !(c > 0.0))
        return -1;
    *out = v / c;
    return 0;
}

int hx_study_open(const char *who, const char *path, const char *metric, HxStudy *s)
{
    char err[512];
    if (hx_study_load(path, metric, s, err, sizeof err) == 0)
        return 0;
    fprintf(stderr, "%s: %s\n", who, err);
    return -1;
}

static void mark_wrong_rows(HxStudy *s);
static void group_rows(HxStudy *s, const char *metric);
static void group_stats(HxStudy *s);

int hx_study_load(const char *path, const char *metric, HxStudy *s, char *err, size_t errlen)
{
    memset(s, 0, sizeof *s);
    if (hx_csv_read(path, &s->csv, err, errlen))
        return -1;
    return hx_study_build(path, metric, s, err, errlen);
}

/* The metric a study is read by when none is named: render_ms for
 * raytrace's rows, else a command study's first metric, else wall_ms. */
static void default_metric(const HxCsv *csv, char *buf, size_t n)
{
    if (hx_csv_has_values(csv, "render_ms")) {
        snprintf(buf, n, "render_ms");
        return;
    }
    for (size_t r = 0; r < csv->nrows; r++) {
        const char *mi = hx_csv_get(csv, r, "metric_info");
        if (*mi) {
            snprintf(buf, n, "%.*s", (int)strcspn(mi, ":;"), mi);
            return;
        }
    }
    snprintf(buf, n, "wall_ms");
}

int hx_metric_is_size(const char *metric, const char *unit)
{
    static const char *const sizes[] = {"B", "KiB", "MiB", "GiB", "kB", "MB", "GB", NULL};
    for (int i = 0; sizes[i]; i++)
        if (strcmp(unit, sizes[i]) == 0)
            return 1;
    return strcmp(metric, "maxrss_kib") == 0;
}

static void metric_unit(HxStudy *s, const char *metric);

/* The metric's unit, direction and kind (size or not). */
static void metric_sense(HxStudy *s, const char *metric)
{
    metric_unit(s, metric);
    s->size = hx_metric_is_size(metric, s->unit);
}

/* The metric's unit and direction: a command study's declaration
 * (metric_info "name:unit:higher;..."), else by its name. */
static void metric_unit(HxStudy *s, const char *metric)
{
    const HxCsv *csv = &s->csv;
    char decl[160];
    snprintf(s->unit, sizeof s->unit, "%s", strstr(metric, "/calib") ? "x calib" : "");
    s->higher = 0;
    for (size_t r = 0; r < csv->nrows; r++) {
        const char *mi = hx_csv_get(csv, r, "metric_info");
        if (!*mi)
            continue;
        if (hx_kv_get_sep(mi, metric, ':', decl, sizeof decl)) {
            char *colon = strchr(decl, ':');
            s->higher = colon && strcmp(colon + 1, "higher") == 0;
            if (colon)
                *colon = '\0';
            snprintf(s->unit, sizeof s->unit, "%.23s", decl);
            return;
        }
        break;
    }
    size_t ml = strlen(metric);
    if (!s->unit[0] && ml > 3 && strcmp(metric + ml - 3, "_ms") == 0)
        snprintf(s->unit, sizeof s->unit, "ms");
    else if (strcmp(metric, "maxrss_kib") == 0)
        snprintf(s->unit, sizeof s->unit, "KiB");
    else if (strcmp(metric, "mrays_per_s") == 0) {
        snprintf(s->unit, sizeof s->unit, "Mrays/s");
        s->higher = 1;
    }
}

double hx_study_speedup(const HxStudy *s, double base, double v)
{
    return s->higher ? v / base : base / v;
}

int hx_study_better(const HxStudy *s, double a, double b)
{
    return s->higher ? a > b : a < b;
}

int hx_study_build(const char *path, const char *metric_opt, HxStudy *s, char *err, size_t errlen)
{
    const HxCsv *csv = &s->csv;
    default_metric(csv, s->metric, sizeof s->metric);
    if (metric_opt)
        snprintf(s->metric, sizeof s->metric, "%s", metric_opt);
    const char *metric = s->metric;
    metric_sense(s, metric);
    static const char *const need[] = {"status", "scene", "backend", "run_id", NULL};
    for (int i = 0; need[i]; i++)
        if (hx_csv_col(csv, need[i]) < 0) {
            snprintf(err, errlen, "%s: no '%s' column (not a harness CSV?)", path, need[i]);
            hx_csv_free(&s->csv);
            return -1;
        }
    const char *slash = strchr(metric, '/');
    int found = slash ? strcmp(slash, "/calib") == 0 && hx_csv_col(csv, "extra") >= 0 : hx_csv_col(csv, metric) >= 0;
    char num[32];
    for (size_t r = 0; !found && !slash && hx_csv_col(csv, "extra") >= 0 && r < csv->nrows; r++)
        found = extra_value(csv, r, metric, num, sizeof num) != NULL;
    if (!found) {
        snprintf(err, errlen, "%s: no column or record key '%s' for --metric (a column, a key of extra, or COLUMN/calib)",
                 path, metric);
        hx_csv_free(&s->csv);
        return -1;
    }
    /* an ok row's value that is there but no number: a column that is no
     * metric (--metric status), or a CSV changed by hand */
    for (size_t r = 0; !slash && hx_csv_col(csv, metric) >= 0 && r < csv->nrows; r++) {
        const char *v = hx_csv_get(csv, r, metric);
        double x;
        if (strcmp(hx_csv_get(csv, r, "status"), "ok") == 0 && *v && strcmp(v, "-") != 0 &&
            hx_parse_double(v, &x) != 0) {
            snprintf(err, errlen, "%s: row %zu: %s '%.40s' is not a number (--metric names a numeric column)", path,
                     r + 1, metric, v);
            hx_csv_free(&s->csv);
            return -1;
        }
    }
    mark_wrong_rows(s);
    group_rows(s, metric);
    group_stats(s);
    return 0;
}

/* The correctness gate again, from the CSV alone: pass 1 finds the reference
 * hash per image (scene, resolution, depth), pass 2 marks the rows that
 * differ. */
static void mark_wrong_rows(HxStudy *s)
{
    const HxCsv *csv = &s->csv;
    size_t n = csv->nrows;
    s->row_status_wrong = calloc(n ? n : 1, sizeof(int));
    char **refkey = calloc(n ? n : 1, sizeof(char *));
    const char **refhash = calloc(n ? n : 1, sizeof(char *));
    int *refserial = calloc(n ? n : 1, sizeof(int));
    size_t nref = 0;
    for (size_t r = 0; r < n; r++) {
        if (strcmp(hx_csv_get(csv, r, "status"), "ok") != 0)
            continue;
        const char *be = hx_csv_get(csv, r, "backend");
        const char *hash = hx_csv_get(csv, r, "image_fnv1a");
        if (!*hash || hx_backend_gpu(be))
            continue;
        HxBuf k = {0};
        hx_buf_printf(&k, "%s|%s|%s", hx_csv_get(csv, r, "scene_path"),
                      hx_csv_get(csv, r, "resolution"), hx_csv_get(csv, r, "max_depth"));
        size_t i;
        for (i = 0; i < nref; i++)
            if (strcmp(refkey[i], k.s) == 0)
                break;
        int serial = strcmp(be, "serial") == 0;
        if (i == nref) {
            refkey[nref] = k.s;
            refhash[nref] = hash;
            refserial[nref++] = serial;
            continue;
        }
        if (!refserial[i] && serial) {
            refhash[i] = hash;
            refserial[i] = 1;
        }
        hx_buf_free(&k);
    }
    /* pass 2: mark rows */
    for (size_t r = 0; r < n; r++) {
        const char *st = hx_csv_get(csv, r, "status");
        if (strcmp(st, "wrong-image") == 0) {
            s->row_status_wrong[r] = 1;
        } else if (strcmp(st, "ok") == 0 && !hx_backend_gpu(hx_csv_get(csv, r, "backend"))) {
            HxBuf k = {0};
            hx_buf_printf(&k, "%s|%s|%s", hx_csv_get(csv, r, "scene_path"),
                          hx_csv_get(csv, r, "resolution"), hx_csv_get(csv, r, "max_depth"));
            for (size_t i = 0; i < nref; i++)
                if (strcmp(refkey[i], k.s) == 0 &&
                    strcmp(refhash[i], hx_csv_get(csv, r, "image_fnv1a")) != 0)
                    s->row_status_wrong[r] = 1;
            hx_buf_free(&k);
        }
        s->nwrong_rows += (size_t)s->row_status_wrong[r];
    }
    for (size_t i = 0; i < nref; i++)
        free(refkey[i]);
    free(refkey);
    free(refhash);
    free(refserial);
}

/* One group per configuration, with its ok samples of the metric. */
static void group_rows(HxStudy *s, const char *metric)
{
    const HxCsv *csv = &s->csv;
    size_t n = csv->nrows;
    int varies[HX_NDIM];
    for (int d = 0; d < HX_NDIM; d++)
        varies[d] = dim_varies(csv, hx_dim_col[d]);
    size_t gcap = 0;
    for (size_t r = 0; r < n; r++) {
        char *id = row_config_id(csv, r, -1);
        size_t gi;
        for (gi = 0; gi < s->ng; gi++)
            if (strcmp(s->g[gi].config_id, id) == 0)
                break;
        if (gi == s->ng) {
            if (s->ng == gcap) {
                gcap = gcap ? 2 * gcap : 32;
                s->g = hx_xrealloc(s->g, gcap * sizeof *s->g);
            }
            HxGroup *g = &s->g[s->ng++];
            memset(g, 0, sizeof *g);
            g->config_id = id;
            id = NULL;
            g->scene = hx_strdup(hx_csv_get(csv, r, "scene"));
            g->label = row_label(csv, r, 1, varies);
            g->backend = hx_strdup(hx_csv_get(csv, r, "backend"));
            group_series(g, csv, r, varies);
            g->block = hx_strdup(hx_csv_get(csv, r, "block"));
            long w = 1;
            if (hx_parse_int(hx_csv_get(csv, r, "workers"), 1, 1 << 20, &w))
                w = 1;
            g->workers = (int)w;
            g->first_row = r;
            g->ok_row = (size_t)-1;
            g->steal_max = -1;
            g->t = hx_xmalloc(n * sizeof(double));
            g->rep = hx_xmalloc(n * sizeof(int));
            g->raw = hx_xmalloc(n * sizeof(double));
            if (hx_strlist_find(&s->scenes, g->scene) < 0)
                hx_strlist_push(&s->scenes, g->scene);
            if (hx_strlist_find(&s->labels, g->label) < 0)
                hx_strlist_push(&s->labels, g->label);
        }
        free(id);
        HxGroup *g = &s->g[gi];
        g->nrows++;
        note_suspect(g, csv, r);
        const char *st = hx_csv_get(csv, r, "status");
        double t;
        /* compare's --min-ms: render_ms, or a command's wall time */
        if (strcmp(st, "ok") == 0 && (hx_parse_double(hx_csv_get(csv, r, "render_ms"), &t) == 0 ||
                                      hx_parse_double(hx_csv_get(csv, r, "wall_ms"), &t) == 0))
            g->raw[g->nraw++] = t;
        if (s->row_status_wrong[r]) {
            g->nwrong++;
        } else if (strcmp(st, "ok") == 0 && row_metric(csv, r, metric, &t) == 0) {
            long rep;
            g->rep[g->nt] = hx_parse_int(hx_csv_get(csv, r, "repeat"), 0, 1 << 30, &rep) ? -1 : (int)rep;
            g->t[g->nt++] = t;
            g->nok++;
            if (g->ok_row == (size_t)-1)
                g->ok_row = r;
        } else if (strcmp(st, "timeout") == 0) {
            g->ntimeout++;
        } else {
            g->nerror++;
            if (!g->first_status)
                g->first_status = strcmp(st, "ok") == 0 ? "no-time" : st;
        }
    }
}

/* Median, quartiles, interval and outliers of every group. */
static void group_stats(HxStudy *s)
{
    for (size_t gi = 0; gi < s->ng; gi++) {
        HxGroup *g = &s->g[gi];
        g->ci_lo = g->ci_hi = NAN;
        g->raw_median = g->nraw ? hx_median(g->raw, g->nraw) : NAN;
        if (g->ok_row == (size_t)-1)
            g->ok_row = g->first_row;
        if (!g->nt) {
            g->median = g->min = g->q1 = g->q3 = NAN;
            continue;
        }
        hx_bootstrap_ci(g->t, g->nt, NULL, 0, &g->ci_lo, &g->ci_hi);
        double *sorted = hx_xmalloc(g->nt * sizeof *sorted);
        memcpy(sorted, g->t, g->nt * sizeof *sorted);
        qsort(sorted, g->nt, sizeof *sorted, hx_cmp_double);
        g->median = hx_quantile_sorted(sorted, g->nt, 0.5);
        g->q1 = hx_quantile_sorted(sorted, g->nt, 0.25);
        g->q3 = hx_quantile_sorted(sorted, g->nt, 0.75);
        g->min = sorted[0];
        free(sorted);
        g->noutliers = hx_outliers(g->t, g->nt, 10.0, NULL);
    }
}

void hx_study_free(HxStudy *s)
{
    for (size_t i = 0; i < s->ng; i++) {
        free(s->g[i].scene);
        free(s->g[i].config_id);
        free(s->g[i].series_id);
        free(s->g[i].series2_id);
        free(s->g[i].label);
        free(s->g[i].backend);
        free(s->g[i].block);
        free(s->g[i].t);
        free(s->g[i].raw);
        free(s->g[i].rep);
    }
    free(s->g);
    free(s->row_status_wrong);
    hx_strlist_free(&s->scenes);
    hx_strlist_free(&s->labels);
    hx_csv_free(&s->csv);
    for (int i = 0; i < s->nceil; i++)
        free(s->ceil[i].scene);
    free(s->ceil);
    for (int i = 0; i < s->nceil_round; i++)
        free(s->ceil_round[i].scene);
    free(s->ceil_round);
    free(s->ceil_path);
    memset(s, 0, sizeof *s);
}

const HxGroup *hx_baseline_one_worker(const HxStudy *s, const HxGroup *g)
{
    for (size_t i = 0; i < s->ng; i++) {
        const HxGroup *b = &s->g[i];
        if (b->nt && b->axis == 1 && strcmp(b->series_id, g->series_id) == 0)
            return b;
    }
    return NULL;
}

const HxGroup *hx_baseline_one_thread(const HxStudy *s, const HxGroup *g)
{
    for (size_t i = 0; g->series2_id && i < s->ng; i++) {
        const HxGroup *b = &s->g[i];
        if (b->nt && b->axis2 == 1 && b->series2_id && strcmp(b->series2_id, g->series2_id) == 0)
            return b;
    }
    return NULL;
}

const HxGroup *hx_baseline_fastest(const HxStudy *s, const HxGroup *g, const char *kv)
{
    const char *eq = strchr(kv, '=');
    if (!eq)
        return NULL;
    char key[128];
    size_t kn = (size_t)(eq - kv);
    if (kn >= sizeof key)
        return NULL;
    memcpy(key, kv, kn);
    key[kn] = '\0';
    const HxGroup *best = NULL;
    for (size_t i = 0; i < s->ng; i++) {
        const HxGroup *b = &s->g[i];
        if (!b->nt || strcmp(b->scene, g->scene) != 0)
            continue;
        if (strcmp(hx_csv_get(&s->csv, b->first_row, key), eq + 1) != 0)
            continue;
        if (!best || hx_study_better(s, b->median, best->median))
            best = b;
    }
    return best;
}

/* The series' name: the label without the swept dimension's value. */
char *hx_series_label(const HxGroup *g, int second)
{
    return hx_label_drop(g->label, second || g->swept == HX_DIM_THREADS ? "T" : "P");
}
