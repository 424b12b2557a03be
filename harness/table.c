/* table.c: `harness table`: per-configuration statistics, scaling against two
 * baselines, Amdahl fits and the report's scenes x configurations table.
 *
 * The correctness gate is re-applied here from the CSV alone (two passes, so
 * the reference is the first ok serial run of each image even if it was
 * written after a parallel run): a fast wrong image never enters a table. */
#include "hx.h"

#include <getopt.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

static const char *const worker_dims[] = {"threads", "ranks"};

static char *row_config_id(const HxCsv *csv, size_t r, int skip_workers)
{
    const char *v[HX_NDIM];
    for (int d = 0; d < HX_NDIM; d++) {
        v[d] = hx_csv_get(csv, r, hx_dim_col[d]);
        if (skip_workers && (d == HX_DIM_THREADS || d == HX_DIM_RANKS))
            v[d] = "*";
    }
    return hx_make_config_id(v);
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

static char *row_label(const HxCsv *csv, size_t r, int with_workers, const int *varies)
{
    HxBuf b = {0};
    hx_buf_put(&b, hx_csv_get(csv, r, "backend"));
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
    return b.s;
}

/* The metric of row r: a numeric column, or "COLUMN/calib": the column
 * divided by the row's calib_ms (raytrace --calibrate, kept in `extra`), a
 * time in units of the machine's speed at that moment. */
static int row_metric(const HxCsv *csv, size_t r, const char *metric, double *out)
{
    const char *slash = strchr(metric, '/');
    if (!slash)
        return hx_parse_double(hx_csv_get(csv, r, metric), out);
    char col[64];
    size_t n = (size_t)(slash - metric);
    if (n >= sizeof col)
        return -1;
    memcpy(col, metric, n);
    col[n] = '\0';
    double v, c;
    const char *extra = hx_csv_get(csv, r, "extra");
    const char *k = strstr(extra, "calib_ms=");
    if (hx_parse_double(hx_csv_get(csv, r, col), &v) != 0 || !k)
        return -1;
    char num[32];
    size_t m = 0;
    for (k += 9; *k && *k != ';' && m + 1 < sizeof num; k++)
        num[m++] = *k;
    num[m] = '\0';
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

int hx_study_load(const char *path, const char *metric, HxStudy *s, char *err, size_t errlen)
{
    memset(s, 0, sizeof *s);
    if (hx_csv_read(path, &s->csv, err, errlen))
        return -1;
    const HxCsv *csv = &s->csv;
    static const char *const need[] = {"status", "scene", "backend", "run_id", NULL};
    for (int i = 0; need[i]; i++)
        if (hx_csv_col(csv, need[i]) < 0) {
            snprintf(err, errlen, "%s: no '%s' column (not a harness CSV?)", path, need[i]);
            return -1;
        }
    const char *slash = strchr(metric, '/');
    if (slash ? (strcmp(slash, "/calib") != 0 || hx_csv_col(csv, "extra") < 0) : hx_csv_col(csv, metric) < 0) {
        snprintf(err, errlen, "%s: no column '%s' for --metric (a column, or COLUMN/calib)", path, metric);
        return -1;
    }
    /* gate, pass 1: reference hash per image (scene, resolution, depth) */
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
        if (!*hash || strcmp(be, "cuda") == 0)
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
        } else if (strcmp(st, "ok") == 0 && strcmp(hx_csv_get(csv, r, "backend"), "cuda") != 0) {
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

    int varies[HX_NDIM];
    for (int d = 0; d < HX_NDIM; d++)
        varies[d] = dim_varies(csv, hx_dim_col[d]);
    size_t gcap = 0;
    for (size_t r = 0; r < n; r++) {
        char *id = row_config_id(csv, r, 0);
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
            g->series_id = row_config_id(csv, r, 1);
            g->scene = hx_strdup(hx_csv_get(csv, r, "scene"));
            g->label = row_label(csv, r, 1, varies);
            g->backend = hx_strdup(hx_csv_get(csv, r, "backend"));
            g->block = hx_strdup(hx_csv_get(csv, r, "block"));
            long w = 1;
            if (hx_parse_int(hx_csv_get(csv, r, "workers"), 1, 1 << 20, &w))
                w = 1;
            g->workers = (int)w;
            g->first_row = r;
            g->t = hx_xmalloc(n * sizeof(double));
            if (hx_strlist_find(&s->scenes, g->scene) < 0)
                hx_strlist_push(&s->scenes, g->scene);
            if (hx_strlist_find(&s->labels, g->label) < 0)
                hx_strlist_push(&s->labels, g->label);
        }
        free(id);
        HxGroup *g = &s->g[gi];
        g->nrows++;
        const char *st = hx_csv_get(csv, r, "status");
        double t;
        if (s->row_status_wrong[r]) {
            g->nwrong++;
        } else if (strcmp(st, "ok") == 0 && row_metric(csv, r, metric, &t) == 0) {
            g->t[g->nt++] = t;
            g->nok++;
        } else if (strcmp(st, "timeout") == 0) {
            g->ntimeout++;
        } else {
            g->nerror++;
            if (!g->first_status)
                g->first_status = strcmp(st, "ok") == 0 ? "no-time" : st;
        }
    }
    for (size_t gi = 0; gi < s->ng; gi++) {
        HxGroup *g = &s->g[gi];
        if (!g->nt) {
            g->median = g->min = g->q1 = g->q3 = NAN;
            continue;
        }
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
    (void)worker_dims;
    return 0;
}

void hx_study_free(HxStudy *s)
{
    for (size_t i = 0; i < s->ng; i++) {
        free(s->g[i].scene);
        free(s->g[i].config_id);
        free(s->g[i].series_id);
        free(s->g[i].label);
        free(s->g[i].backend);
        free(s->g[i].block);
        free(s->g[i].t);
    }
    free(s->g);
    free(s->row_status_wrong);
    hx_strlist_free(&s->scenes);
    hx_strlist_free(&s->labels);
    hx_csv_free(&s->csv);
    memset(s, 0, sizeof *s);
}

const HxGroup *hx_baseline_one_worker(const HxStudy *s, const HxGroup *g)
{
    for (size_t i = 0; i < s->ng; i++) {
        const HxGroup *b = &s->g[i];
        if (b->nt && b->workers == 1 && strcmp(b->series_id, g->series_id) == 0)
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
        if (!best || b->median < best->median)
            best = b;
    }
    return best;
}

/* ---- output: Markdown or CSV tables ---- */

typedef struct {
    FILE *out;
    int csv;
    int ncol;
} Emit;

static void emit_row(Emit *e, const char *const *cells, int n)
{
    if (e->csv) {
        HxBuf b = {0};
        for (int i = 0; i < n; i++) {
            if (i)
                hx_buf_put(&b, ",");
            hx_csv_field(&b, cells[i]);
        }
        fprintf(e->out, "%s\n", b.s ? b.s : "");
        hx_buf_free(&b);
        return;
    }
    fputs("|", e->out);
    for (int i = 0; i < n; i++) {
        /* a cell from someone's CSV: no control character, and a '|' that
         * does not end the cell */
        fputc(' ', e->out);
        for (const unsigned char *p = (const unsigned char *)cells[i]; *p; p++) {
            if (*p < 0x20 || *p == 0x7f)
                fputc('?', e->out);
            else if (*p == '|')
                fputs("\\|", e->out);
            else
                fputc(*p, e->out);
        }
        fputs(" |", e->out);
    }
    fputc('\n', e->out);
}

static void emit_header(Emit *e, const char *title, const char *const *cells, int n)
{
    e->ncol = n;
    if (e->csv)
        fprintf(e->out, "# %s\n", title);
    else
        fprintf(e->out, "\n### %s\n\n", title);
    emit_row(e, cells, n);
    if (!e->csv) {
        fputs("|", e->out);
        for (int i = 0; i < n; i++)
            fputs("---|", e->out);
        fputc('\n', e->out);
    }
}

static void fmt_ms(char *b, size_t n, double v)
{
    if (isnan(v))
        snprintf(b, n, "-");
    else if (v >= 1000)
        snprintf(b, n, "%.0f", v);
    else if (v >= 100)
        snprintf(b, n, "%.1f", v);
    else if (v >= 1)
        snprintf(b, n, "%.2f", v);
    else
        snprintf(b, n, "%.3f", v);
}

static void fmt_num(char *b, size_t n, const char *f, double v)
{
    if (isnan(v) || isinf(v))
        snprintf(b, n, "-");
    else
        snprintf(b, n, f, v);
}

static void usage_table(FILE *f)
{
    fputs("usage: harness table CSV [--baseline KEY=VALUE] [--format md|csv] [--metric COLUMN]\n"
          "Per configuration: median, min, IQR, outliers (>10 MAD, flagged not dropped),\n"
          "speedup/efficiency against (a) the same configuration at one worker and (b) the\n"
          "fastest configuration of the scene matching KEY=VALUE (default: the CSV's\n"
          "baseline column, else backend=serial), Karp-Flatt per point, Amdahl fit\n"
          "T(p) = a + b/p per series, and the scenes x configurations cross table.\n"
          "  --baseline KEY=VALUE  column=value selecting baseline (b)\n"
          "  --format md|csv       output format (default md)\n"
          "  --metric COLUMN       time column (default render_ms)\n"
          "  -h, --help            this text\n", f);
}

int hx_cmd_table(int argc, char **argv)
{
    static const struct option lo[] = {
        {"baseline", required_argument, NULL, 'b'}, {"format", required_argument, NULL, 'f'},
        {"metric", required_argument, NULL, 'm'}, {"help", no_argument, NULL, 'h'},
        {NULL, 0, NULL, 0}};
    const char *baseline = NULL, *format = "md", *metric = "render_ms";
    int c;
    while ((c = getopt_long(argc, argv, "h", lo, NULL)) != -1) {
        switch (c) {
        case 'b': baseline = optarg; break;
        case 'f': format = optarg; break;
        case 'm': metric = optarg; break;
        case 'h': usage_table(stdout); return 0;
        default: usage_table(stderr); return 1;
        }
    }
    if (optind != argc - 1) {
        fprintf(stderr, "harness table: expected one CSV argument (see --help)\n");
        return 1;
    }
    if (strcmp(format, "md") != 0 && strcmp(format, "csv") != 0) {
        fprintf(stderr, "harness table: --format: expected md or csv, got '%s'\n", format);
        return 1;
    }
    if (baseline && (!strchr(baseline, '=') || baseline[0] == '=')) {
        fprintf(stderr, "harness table: --baseline: expected KEY=VALUE, got '%s'\n", baseline);
        return 1;
    }
    HxStudy s;
    if (hx_study_open("harness table", argv[optind], metric, &s))
        return 1;
    if (!baseline) {
        baseline = "backend=serial";
        if (s.csv.nrows && *hx_csv_get(&s.csv, 0, "baseline"))
            baseline = hx_csv_get(&s.csv, 0, "baseline");
    }
    if (s.nwrong_rows)
        fprintf(stderr, "harness table: warning: %zu wrong-image row(s) left out (image hash "
                        "differs from the study's reference)\n", s.nwrong_rows);
    Emit e = {stdout, strcmp(format, "csv") == 0, 0};
    const char *study = s.csv.nrows ? hx_csv_get(&s.csv, 0, "study") : "";
    if (!e.csv)
        printf("## Study %s (%s, metric %s, baseline (b): fastest %s)\n", study, argv[optind],
               metric, baseline);

    static const char *const h1[] = {
        "scene", "configuration", "workers", "n", "median ms", "min ms", "IQR ms",
        "outliers", "T(1) ms", "speedup", "efficiency", "Karp-Flatt", "base (b) ms",
        "base (b)", "speedup (b)", "efficiency (b)", "status"};
    emit_header(&e, "Per configuration", h1, 17);
    for (size_t i = 0; i < s.ng; i++) {
        const HxGroup *g = &s.g[i];
        char w[16], n[32], med[32], mn[32], iqr[32], out[16], t1[32], sp[32], ef[32], kf[32],
            bt[32], sb[32], eb[32], st[96];
        snprintf(w, sizeof w, "%d", g->workers);
        snprintf(n, sizeof n, "%zu/%zu", g->nok, g->nrows);
        fmt_ms(med, sizeof med, g->median);
        fmt_ms(mn, sizeof mn, g->min);
        fmt_ms(iqr, sizeof iqr, g->q3 - g->q1);
        snprintf(out, sizeof out, "%d", g->noutliers);
        const HxGroup *a = hx_baseline_one_worker(&s, g);
        const HxGroup *b = hx_baseline_fastest(&s, g, baseline);
        double spa = a && g->nt ? a->median / g->median : NAN;
        double spb = b && g->nt ? b->median / g->median : NAN;
        fmt_ms(t1, sizeof t1, a ? a->median : NAN);
        fmt_num(sp, sizeof sp, "%.2f", spa);
        fmt_num(ef, sizeof ef, "%.3f", spa / g->workers);
        fmt_num(kf, sizeof kf, "%.3f", g->workers > 1 ? hx_karp_flatt(spa, g->workers) : NAN);
        fmt_ms(bt, sizeof bt, b ? b->median : NAN);
        fmt_num(sb, sizeof sb, "%.2f", spb);
        fmt_num(eb, sizeof eb, "%.3f", spb / g->workers);
        HxBuf sts = {0};
        if (g->nok)
            hx_buf_printf(&sts, "ok %zu", g->nok);
        if (g->ntimeout)
            hx_buf_printf(&sts, "%sTLE %zu", sts.len ? ", " : "", g->ntimeout);
        if (g->nwrong)
            hx_buf_printf(&sts, "%swrong-image %zu", sts.len ? ", " : "", g->nwrong);
        if (g->nerror)
            hx_buf_printf(&sts, "%s%s %zu", sts.len ? ", " : "", g->first_status, g->nerror);
        snprintf(st, sizeof st, "%s", sts.s ? sts.s : "-");
        hx_buf_free(&sts);
        const char *cells[17] = {g->scene, g->label, w, n, med, mn, iqr, out, t1, sp, ef, kf,
                                 bt, b ? b->label : "-", sb, eb, st};
        emit_row(&e, cells, 17);
    }

    /* Amdahl fits, one per (scene, series) with two or more worker counts */
    static const char *const h2[] = {"scene", "series", "points", "a (serial) ms",
                                     "b (parallel) ms", "serial fraction", "std. error"};
    int any = 0;
    char *done = calloc(s.ng ? s.ng : 1, 1);
    for (size_t i = 0; i < s.ng; i++) {
        if (done[i] || !s.g[i].nt)
            continue;
        size_t np = 0, cap = 0, distinct = 0;
        double *p = NULL, *t = NULL;
        int lastw = -1;
        for (size_t k = i; k < s.ng; k++) {
            const HxGroup *g = &s.g[k];
            if (strcmp(g->series_id, s.g[i].series_id) != 0 || !g->nt)
                continue;
            done[k] = 1;
            if (g->workers != lastw)
                distinct++;
            lastw = g->workers;
            for (size_t j = 0; j < g->nt; j++) {
                if (np == cap) {
                    cap = cap ? 2 * cap : 32;
                    p = hx_xrealloc(p, cap * sizeof *p);
                    t = hx_xrealloc(t, cap * sizeof *t);
                }
                p[np] = g->workers;
                t[np++] = g->t[j];
            }
        }
        if (distinct >= 2) {
            HxAmdahl f = hx_amdahl_fit(p, t, np);
            if (f.ok) {
                if (!any)
                    emit_header(&e, "Amdahl fit T(p) = a + b/p (least squares over all samples)", h2, 7);
                any = 1;
                char pts[16], as[32], bs[32], fs[32], se[32];
                snprintf(pts, sizeof pts, "%zu", np);
                fmt_ms(as, sizeof as, f.a);
                fmt_ms(bs, sizeof bs, f.b);
                fmt_num(fs, sizeof fs, "%.4f", f.serial_fraction);
                fmt_num(se, sizeof se, "%.4f", f.has_se ? f.se_serial_fraction : NAN);
                /* series label: the label without the worker count */
                char *lab = hx_strdup(s.g[i].label);
                hx_label_drop_workers(lab);
                const char *cells[7] = {s.g[i].scene, lab, pts, as, bs, fs, se};
                emit_row(&e, cells, 7);
                free(lab);
            }
        }
        free(p);
        free(t);
    }
    free(done);

    /* cross table: scenes x configurations, median ms, TLE for timeouts */
    size_t nl = s.labels.n;
    const char **hdr = hx_xmalloc((nl + 1) * sizeof *hdr);
    hdr[0] = "scene";
    for (size_t l = 0; l < nl; l++)
        hdr[l + 1] = s.labels.v[l];
    emit_header(&e, "Scenes x configurations (median ms; TLE = timed out)", hdr, (int)nl + 1);
    char **cells = hx_xmalloc((nl + 1) * sizeof *cells);
    for (size_t sc = 0; sc < s.scenes.n; sc++) {
        cells[0] = s.scenes.v[sc];
        for (size_t l = 0; l < nl; l++) {
            cells[l + 1] = hx_xmalloc(32);
            snprintf(cells[l + 1], 32, "-");
            for (size_t i = 0; i < s.ng; i++) {
                const HxGroup *g = &s.g[i];
                if (strcmp(g->scene, s.scenes.v[sc]) || strcmp(g->label, s.labels.v[l]))
                    continue;
                if (g->nt)
                    fmt_ms(cells[l + 1], 32, g->median);
                else if (g->ntimeout)
                    snprintf(cells[l + 1], 32, "TLE");
                else if (g->nwrong)
                    snprintf(cells[l + 1], 32, "wrong-image");
                else if (g->first_status)
                    snprintf(cells[l + 1], 32, "%s", g->first_status);
            }
        }
        emit_row(&e, (const char *const *)cells, (int)nl + 1);
        for (size_t l = 0; l < nl; l++)
            free(cells[l + 1]);
    }
    free(cells);
    free(hdr);
    hx_study_free(&s);
    return 0;
}
