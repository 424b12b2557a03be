/* publish.c: `harness history publish --db DB -o DIR`: the history database
 * as static pages (the niche of `asv publish`). DIR/index.html lists the
 * metrics, machines and studies; DIR/METRIC.html draws every series of the
 * metric over commits, one plot per machine (numbers of two machines never
 * meet), medians with min-max bars, the steps `history check` finds marked
 * and tabled. The plots are SVG written here, so every string from the
 * database goes through hx_html_put; pages are self-contained like
 * report's (html.c): no script, nothing fetched. Verdicts are the stored
 * runs' only: re-measuring is `history check --confirm`'s. */
#include "history.h"
#include "program.h"

#if HAVE_SQLITE
#include <ctype.h>
#include <dirent.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define WHO "harness history publish"

/* The metrics a dashboard draws where the database has them (name, unit,
 * what it is); a command study's own metrics (metric_info) follow. */
static const char *const known[][3] = {
    {"render_ms", "ms", "render time: the pixel work only"},
    {"render_ms/calib", "", "render time over the calibration's (--calibrate): the machine's speed taken out"},
    {"mrays_per_s", "Mrays/s", "rays per second"},
    {"total_ms", "ms", "raytrace's whole command"},
    {"parse_ms", "ms", "reading and parsing the scene"},
    {"build_ms", "ms", "building the BVH"},
    {"write_ms", "ms", "writing the image"},
    {"upload_ms", "ms", "cuda: the scene to the GPU"},
    {"download_ms", "ms", "cuda, mpi-cuda: a frame's image back from the GPU"},
    {"wall_ms", "ms", "the run's wall time, as the harness measured it"},
    {"user_ms", "ms", "CPU time in user mode (wait4)"},
    {"sys_ms", "ms", "CPU time in the kernel (wait4)"},
    {"maxrss_kib", "KiB", "peak resident memory (wait4)"},
    {"instructions", "", "instructions executed (cachegrind): exact, no noise"},
};

typedef struct {
    char *name, *unit, *what, *file;
    HxSeriesSet ss;
    int higher;                             /* a rate: higher is better */
    size_t ncommits, nslow, nfast;          /* from its page, for the index */
} Metric;

typedef struct {
    char *fp, *name, *detail; /* fingerprint; the machine in words; host, compiler... */
} Machine;

typedef struct {
    sqlite3 *db;
    const char *dbpath, *dir;
    const HxStrList *want;
    const HxStepRule *rule;
    Metric *m;
    size_t nm;
    Machine *mach;
    size_t nmach;
} Pub;

/* One plot: the series of one machine. */
typedef struct {
    const HxSeries **s;
    size_t n;
    char **legend;         /* the settings that differ between the series */
    HxStep **st;           /* each series' steps */
    size_t *nst;
    size_t step0;          /* steps numbered from step0 + 1 on the page */
    HxStrList order;       /* the commits, in history order: x */
    int logy, higher;
    double lo, hi, spread; /* y range (log10 with logy); max/min of the series' medians */
} Plot;

enum { W = 960, LEFT = 80, RIGHT = 24, TOP = 34, PH = 330, BOTTOM = 96, LEGH = 18 };
static const char *const colour[] = {"#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd",
                                     "#8c564b", "#e377c2", "#17becf", "#7f7f7f", "#bcbd22"};
static const char *const dash[] = {"none", "6 3", "2 2", "8 3 2 3"};

/* pre and post as they are (markup), text escaped (data). */
static void put(FILE *o, const char *pre, const char *text, const char *post)
{
    fputs(pre, o);
    hx_html_put(o, text);
    fputs(post, o);
}

/* ---- the database ---------------------------------------------------------- */

/* Opened read-only (publishing writes nothing outside DIR) and checked to
 * be a history database; *empty when it holds no table at all. 0 or -1. */
static int open_db(const char *path, sqlite3 **db, int *empty)
{
    if (!hx_file_exists(path)) {
        fprintf(stderr, WHO ": %s: no such database (harness history add creates it)\n", path);
        return -1;
    }
    sqlite3_stmt *st = NULL;
    int ntab = -1, ours = 0;
    if (sqlite3_open_v2(path, db, SQLITE_OPEN_READONLY, NULL) == SQLITE_OK &&
        sqlite3_prepare_v2(*db, "SELECT COUNT(*), COALESCE(SUM(name IN ('studies', 'commits', 'runs', 'vals')), 0)"
                                " FROM sqlite_master WHERE type = 'table'", -1, &st, NULL) == SQLITE_OK &&
        sqlite3_step(st) == SQLITE_ROW) {
        ntab = sqlite3_column_int(st, 0);
        ours = sqlite3_column_int(st, 1);
    }
    if (ntab < 0)
        fprintf(stderr, WHO ": %s: %s\n", path, sqlite3_errmsg(*db));
    else if (ntab > 0 && ours != 4)
        fprintf(stderr, WHO ": %s: not a raybench history database (no studies, commits, runs and vals tables)\n",
                path);
    sqlite3_finalize(st);
    *empty = ntab == 0;
    if (ntab < 0 || (ntab > 0 && ours != 4)) {
        sqlite3_close(*db);
        return -1;
    }
    return 0;
}

/* Column 0 of each row of sql (text, not empty) into out. */
static void query_texts(sqlite3 *db, const char *dbpath, const char *sql, HxStrList *out)
{
    sqlite3_stmt *st = hx_db_prep(db, dbpath, sql);
    while (st && sqlite3_step(st) == SQLITE_ROW)
        if (sqlite3_column_text(st, 0) && *sqlite3_column_text(st, 0))
            hx_strlist_push(out, (const char *)sqlite3_column_text(st, 0));
    sqlite3_finalize(st);
}

/* A page's file name: the metric's letters, digits, '_' and '-' ('/' as
 * '-', anything else '_'), never index.html, never another metric's. */
static void add_metric(Pub *p, const char *name, const char *unit, const char *what, HxStrList *files)
{
    HxBuf b = {0};
    for (const char *c = name; *c; c++) {
        char ch = *c == '/' ? '-' : *c;
        hx_buf_putn(&b, isalnum((unsigned char)ch) || ch == '_' || ch == '-' ? &ch : "_", 1);
    }
    if (!b.len || strcmp(b.s, "index") == 0)
        hx_buf_put(&b, "_m");
    HxBuf f = {0};
    hx_buf_printf(&f, "%s.html", b.s);
    for (int k = 2; hx_strlist_find(files, f.s) >= 0; k++) {
        f.len = 0;
        hx_buf_printf(&f, "%s-%d.html", b.s, k);
    }
    hx_strlist_push(files, f.s);
    p->m = hx_xrealloc(p->m, (p->nm + 1) * sizeof *p->m);
    p->m[p->nm++] = (Metric){hx_strdup(name), hx_strdup(unit), hx_strdup(what), f.s, {NULL, 0}, 0, 0, 0, 0};
    hx_buf_free(&b);
}

/* The metrics the database has values of: the known ones, then each
 * command study's (metric_info "name:unit:lower|higher;..."). */
static void list_metrics(Pub *p)
{
    HxStrList have = {0}, infos = {0}, files = {0};
    query_texts(p->db, p->dbpath, "SELECT DISTINCT key FROM vals WHERE num IS NOT NULL", &have);
    query_texts(p->db, p->dbpath, "SELECT DISTINCT txt FROM vals WHERE key = 'metric_info'", &infos);
    for (size_t i = 0; i < sizeof known / sizeof known[0]; i++) {
        const char *slash = strchr(known[i][0], '/');
        int has = slash ? hx_strlist_find(&have, "render_ms") >= 0 && hx_strlist_find(&have, "calib_ms") >= 0
                        : hx_strlist_find(&have, known[i][0]) >= 0;
        if (has)
            add_metric(p, known[i][0], known[i][1], known[i][2], &files);
    }
    for (size_t i = 0; i < infos.n; i++) {
        char *save = NULL;
        for (char *d = strtok_r(infos.v[i], ";", &save); d; d = strtok_r(NULL, ";", &save)) {
            char *unit = strchr(d, ':'), *end;
            if (unit)
                *unit++ = '\0';
            if (unit && (end = strchr(unit, ':')) != NULL)
                *end = '\0';
            int seen = 0;
            for (size_t k = 0; k < p->nm && !seen; k++)
                seen = strcmp(p->m[k].name, d) == 0;
            /* (a name a config can give: a CSV made by hand with '../x' there
             * must not stop the pages of every other metric) */
            if (!seen && hx_program_good_name(d, 0) && hx_strlist_find(&have, d) >= 0)
                add_metric(p, d, unit ? unit : "", "the command study's metric", &files);
        }
    }
    hx_strlist_free(&have);
    hx_strlist_free(&infos);
    hx_strlist_free(&files);
}

/* Each machine (fingerprint) in words (hx_machine_words). */
static void load_machines(Pub *p)
{
    HxStrList fps = {0};
    query_texts(p->db, p->dbpath, "SELECT DISTINCT fingerprint FROM runs ORDER BY fingerprint", &fps);
    for (size_t i = 0; i < fps.n; i++) {
        HxBuf name = {0}, detail = {0};
        hx_machine_words(p->db, p->dbpath, fps.v[i], &name, &detail);
        p->mach = hx_xrealloc(p->mach, (p->nmach + 1) * sizeof *p->mach);
        p->mach[p->nmach++] = (Machine){hx_strdup(fps.v[i]), name.s, detail.s ? detail.s : hx_strdup("")};
    }
    hx_strlist_free(&fps);
}

static const Machine *machine_of(const Pub *p, const char *fp)
{
    for (size_t i = 0; i < p->nmach; i++)
        if (strcmp(p->mach[i].fp, fp) == 0)
            return &p->mach[i];
    return NULL;
}

/* ---- the plot (SVG) ---------------------------------------------------------- */

static double point_median(const HxSeriesPoint *q)
{
    return hx_median(q->x, q->n);
}

static double nice_step(double range)
{
    double e = pow(10.0, floor(log10(range / 5.0))), f = range / 5.0 / e;
    return e * (f < 1.5 ? 1.0 : f < 3.5 ? 2.0 : f < 7.5 ? 5.0 : 10.0);
}

/* The y range, and a log axis where the series' medians differ 10x. */
static void plot_range(Plot *p)
{
    double mn = INFINITY, mx = -INFINITY, smin = INFINITY, smax = -INFINITY;
    for (size_t i = 0; i < p->n; i++) {
        const HxSeries *s = p->s[i];
        double *med = hx_xmalloc(s->np * sizeof *med);
        for (size_t k = 0; k < s->np; k++) {
            med[k] = point_median(&s->p[k]);
            mn = fmin(mn, hx_min(s->p[k].x, s->p[k].n));
            for (size_t j = 0; j < s->p[k].n; j++)
                mx = fmax(mx, s->p[k].x[j]);
        }
        double m = hx_median(med, s->np);
        smin = fmin(smin, m);
        smax = fmax(smax, m);
        free(med);
    }
    p->spread = smin > 0.0 ? smax / smin : NAN;
    p->logy = mn > 0.0 && p->spread >= 10.0;
    if (p->logy) { /* (at least a decade: the medians differ 10x) */
        double a = log10(mn), b = log10(mx);
        p->lo = a - 0.04 * (b - a);
        p->hi = b + 0.04 * (b - a);
        return;
    }
    if (!(mx > mn)) { /* one value: a band around it */
        double d = mn != 0.0 ? fabs(mn) * 0.05 : 1.0;
        mn -= d;
        mx += d;
    }
    double step = nice_step(mx - mn);
    p->lo = floor(mn / step) * step;
    p->hi = ceil(mx / step) * step;
}

static double px(const Plot *p, size_t i)
{
    return LEFT + ((double)i + 0.5) * (W - LEFT - RIGHT) / (double)p->order.n;
}

static double py(const Plot *p, double v)
{
    double t = ((p->logy ? log10(v) : v) - p->lo) / (p->hi - p->lo);
    return TOP + PH * (1.0 - t);
}

/* A number for people: 4 digits, whole where it is large (an instruction
 * count reads better as 1040000 than as 1.04e+06). */
static const char *num(char buf[32], double v)
{
    snprintf(buf, 32, fabs(v) >= 1e4 && fabs(v) < 1e9 ? "%.0f" : "%.4g", v);
    return buf;
}

static void y_tick(FILE *o, const Plot *p, double v)
{
    double y = py(p, v);
    char b[32];
    fprintf(o, "<line x1=\"%d\" x2=\"%d\" y1=\"%.1f\" y2=\"%.1f\" stroke=\"#ddd\"/>"
               "<text x=\"%d\" y=\"%.1f\" text-anchor=\"end\">%s</text>\n", LEFT, W - RIGHT, y, y, LEFT - 6, y + 4,
            num(b, v));
}

/* Grid, ticks (decades, with 2 and 5 where few), commits and axis labels. */
static void svg_axes(FILE *o, const Plot *p, const char *ylabel)
{
    if (p->logy) {
        for (int e = (int)floor(p->lo); e <= (int)ceil(p->hi); e++)
            for (int m = 1; m <= 5; m += m == 1 ? 1 : 3)
                if ((m == 1 || p->hi - p->lo <= 3.0) && log10(m) + e >= p->lo && log10(m) + e <= p->hi)
                    y_tick(o, p, m * pow(10.0, e));
    } else {
        double step = nice_step(p->hi - p->lo);
        for (int i = 0; p->lo + i * step <= p->hi + step * 1e-6; i++) {
            double v = p->lo + i * step;
            y_tick(o, p, fabs(v) < step * 1e-9 ? 0.0 : v);
        }
    }
    size_t every = (p->order.n + 29) / 30; /* at most 30 commit labels */
    for (size_t i = 0; i < p->order.n; i += every) {
        double x = px(p, i);
        fprintf(o, "<line x1=\"%.1f\" x2=\"%.1f\" y1=\"%d\" y2=\"%d\" stroke=\"#444\"/>"
                   "<text transform=\"translate(%.1f,%d) rotate(-45)\" text-anchor=\"end\">",
                x, x, TOP + PH, TOP + PH + 4, x + 3, TOP + PH + 14);
        char sha[16];
        snprintf(sha, sizeof sha, "%.9s", p->order.v[i]);
        put(o, "", sha, "</text>\n");
    }
    fprintf(o, "<rect x=\"%d\" y=\"%d\" width=\"%d\" height=\"%d\" fill=\"none\" stroke=\"#444\"/>\n", LEFT, TOP,
            W - LEFT - RIGHT, PH);
    fprintf(o, "<text transform=\"translate(16,%d) rotate(-90)\" text-anchor=\"middle\">", TOP + PH / 2);
    put(o, "", ylabel, "</text>\n");
    fprintf(o, "<text x=\"%d\" y=\"%d\" text-anchor=\"middle\">commit (history order)</text>\n",
            (W + LEFT - RIGHT) / 2, TOP + PH + BOTTOM - 12);
}

/* One series: medians joined, a bar from min to max at each commit, and
 * the numbers in each point's tooltip (an SVG title: no script). */
static void svg_series(FILE *o, const Plot *p, size_t i, const char *unit)
{
    const HxSeries *s = p->s[i];
    fprintf(o, "<g stroke=\"%s\" fill=\"%s\">\n<polyline fill=\"none\" stroke-width=\"1.6\" stroke-dasharray=\"%s\" "
               "points=\"", colour[i % 10], colour[i % 10], dash[(i / 10) % 4]);
    for (size_t k = 0; k < s->np; k++)
        fprintf(o, "%s%.1f,%.1f", k ? " " : "", px(p, (size_t)hx_strlist_find(&p->order, s->p[k].sha)),
                py(p, point_median(&s->p[k])));
    fputs("\"/>\n", o);
    for (size_t k = 0; k < s->np; k++) {
        const HxSeriesPoint *q = &s->p[k];
        double x = px(p, (size_t)hx_strlist_find(&p->order, q->sha)), lo = hx_min(q->x, q->n), hi = lo;
        for (size_t j = 0; j < q->n; j++)
            hi = fmax(hi, q->x[j]);
        fprintf(o, "<path d=\"M%.1f %.1fV%.1fM%.1f %.1fh6M%.1f %.1fh6\" fill=\"none\"/>", x, py(p, lo), py(p, hi),
                x - 3, py(p, lo), x - 3, py(p, hi));
        fprintf(o, "<circle cx=\"%.1f\" cy=\"%.1f\" r=\"3\"><title>", x, py(p, point_median(q)));
        put(o, "", p->legend[i], " at ");
        hx_html_put(o, q->sha);
        char b[3][32];
        put(o, ": median ", num(b[0], point_median(q)), " ");
        put(o, "", unit, "");
        fprintf(o, " (min %s, max %s; %zu runs)</title></circle>\n", num(b[1], lo), num(b[2], hi), q->n);
    }
    fputs("</g>\n", o);
}

/* Each step: a dashed line at its commit, its number (S1, ...) above,
 * red for a slowdown, green for an improvement. */
static void svg_steps(FILE *o, const Plot *p)
{
    size_t no = p->step0, *xs = NULL, nx = 0;
    for (size_t i = 0; i < p->n; i++)
        for (size_t j = 0; j < p->nst[i]; j++) {
            const HxStep *st = &p->st[i][j];
            const HxSeriesPoint *q = &p->s[i]->p[st->k];
            size_t xi = (size_t)hx_strlist_find(&p->order, q->sha), stack = 0;
            for (size_t m = 0; m < nx; m++)
                stack += xs[m] == xi;
            xs = hx_xrealloc(xs, (nx + 1) * sizeof *xs);
            xs[nx++] = xi;
            int slower = p->higher ? st->ratio < 1.0 : st->ratio > 1.0;
            const char *c = slower ? "#c00000" : "#008000";
            double x = px(p, xi);
            no++;
            fprintf(o, "<g stroke=\"%s\" fill=\"%s\"><line x1=\"%.1f\" x2=\"%.1f\" y1=\"%d\" y2=\"%d\" "
                       "stroke-dasharray=\"4 3\"/><circle cx=\"%.1f\" cy=\"%.1f\" r=\"7\" fill=\"none\" "
                       "stroke-width=\"2\"/><text x=\"%.1f\" y=\"%.1f\" stroke=\"none\" font-weight=\"bold\">S%zu"
                       "</text><title>S%zu: %+.1f%% at ", c, c, x, x, TOP, TOP + PH, x,
                    py(p, point_median(q)), x + 3, TOP - 6 - 12.0 * (double)(stack < 2 ? stack : 1), no, no,
                    100.0 * (st->ratio - 1.0));
            put(o, "", q->sha, "</title></g>\n");
        }
    free(xs);
}

static void svg_plot(FILE *o, const Plot *p, const char *metric, const char *unit)
{
    int h = TOP + PH + BOTTOM + (int)p->n * LEGH + 8;
    HxBuf yl = {0};
    hx_buf_printf(&yl, *unit ? "%s (%s)%s" : "%s%s%s", metric, *unit ? unit : "", p->logy ? ", log scale" : "");
    fprintf(o, "<svg xmlns=\"http://www.w3.org/2000/svg\" viewBox=\"0 0 %d %d\" width=\"%d\" height=\"%d\" "
               "font-family=\"sans-serif\" font-size=\"12\" role=\"img\" aria-label=\"", W, h, W, h);
    hx_html_put(o, yl.s);
    fprintf(o, " over commits\">\n<rect width=\"%d\" height=\"%d\" fill=\"#fff\"/>\n", W, h);
    svg_axes(o, p, yl.s);
    for (size_t i = 0; i < p->n; i++)
        svg_series(o, p, i, unit);
    svg_steps(o, p);
    for (size_t i = 0; i < p->n; i++) { /* the legend, below the plot */
        int y = TOP + PH + BOTTOM + (int)i * LEGH;
        fprintf(o, "<line x1=\"%d\" x2=\"%d\" y1=\"%d\" y2=\"%d\" stroke=\"%s\" stroke-width=\"2\" "
                   "stroke-dasharray=\"%s\"/><circle cx=\"%d\" cy=\"%d\" r=\"3\" fill=\"%s\"/>"
                   "<text class=\"legend\" x=\"%d\" y=\"%d\">", LEFT, LEFT + 26, y, y, colour[i % 10],
                dash[(i / 10) % 4], LEFT + 13, y, colour[i % 10], LEFT + 34, y + 4);
        put(o, "", p->legend[i], "</text>\n");
    }
    fputs("</svg>", o);
    hx_buf_free(&yl);
}

/* ---- the tables ------------------------------------------------------------ */

static void put_series_cell(FILE *o, const Plot *p, size_t i)
{
    fprintf(o, "<td><span style=\"color:%s\">&#9632;</span> ", colour[i % 10]);
    put(o, "", p->legend[i], "</td>");
}

static void step_table(FILE *o, const Plot *p, const HxStepRule *rule)
{
    size_t no = p->step0, n = 0;
    for (size_t i = 0; i < p->n; i++)
        n += p->nst[i];
    if (!n) {
        fprintf(o, "<p>No step: no commit where the median moved by more than %g%% with p &lt; %g (windows of %d "
                   "commits).</p>\n", 100.0 * rule->threshold, rule->alpha, rule->window);
        return;
    }
    fprintf(o, "<h3>Steps</h3>\n<p class=\"note\">As <code>history check</code> finds them in the stored runs "
               "(windows of %d commits, change over %g%%, Mann-Whitney p &lt; %g): <b>not confirmed</b>; "
               "<code>history check --confirm CONFIG</code> re-measures them.</p>\n<table><thead><tr><th>step</th>"
               "<th>series</th><th>at commit</th><th>after</th><th>change</th><th>p</th><th>verdict</th></tr></thead>"
               "<tbody>\n", rule->window, 100.0 * rule->threshold, rule->alpha);
    for (size_t i = 0; i < p->n; i++)
        for (size_t j = 0; j < p->nst[i]; j++) {
            const HxStep *st = &p->st[i][j];
            int slower = p->higher ? st->ratio < 1.0 : st->ratio > 1.0;
            fprintf(o, "<tr><td>S%zu</td>", ++no);
            put_series_cell(o, p, i);
            put(o, "<td><code>", p->s[i]->p[st->k].sha, "</code></td>");
            put(o, "<td><code>", p->s[i]->p[st->k - 1].sha, "</code></td>");
            fprintf(o, "<td>%+.1f%%</td><td>%s%.2g</td><td><span class=\"%s\">%s</span>, not confirmed"
                       "</td></tr>\n", 100.0 * (st->ratio - 1.0), st->p == 0.0 ? "exact values, " : "", st->p,
                    slower ? "warn" : "ok", slower ? "slower" : "faster");
        }
    fputs("</tbody></table>\n", o);
}

static void series_table(FILE *o, const Plot *p, const HxStepRule *rule, const char *unit)
{
    size_t no = p->step0;
    fputs("<h3>Series</h3>\n<table><thead><tr><th>series</th><th>commits</th><th>runs</th><th>first median</th>"
          "<th>last median</th><th>verdict (stored runs)</th></tr></thead><tbody>\n", o);
    for (size_t i = 0; i < p->n; i++) {
        const HxSeries *s = p->s[i];
        size_t runs = 0;
        for (size_t k = 0; k < s->np; k++)
            runs += s->p[k].n;
        fputs("<tr>", o);
        put_series_cell(o, p, i);
        char b[32];
        fprintf(o, "<td>%zu</td><td>%zu</td><td>%s ", s->np, runs, num(b, point_median(&s->p[0])));
        put(o, "", unit, "</td>");
        fprintf(o, "<td>%s ", num(b, point_median(&s->p[s->np - 1])));
        put(o, "", unit, "</td><td>");
        HxNoStep v;
        if (p->nst[i]) {
            for (size_t j = 0; j < p->nst[i]; j++)
                fprintf(o, "%sS%zu", j ? ", " : "step ", ++no);
        } else if (!hx_series_no_step(s, rule, &v)) {
            fprintf(o, "no change (last %zu commits against the %zu before: ratio in [%.3f, %.3f])", v.nlast,
                    v.nbefore, v.lo, v.hi);
        } else if (isnan(v.lo)) {
            fputs("inconclusive: too few samples to tell", o);
        } else {
            fprintf(o, "inconclusive: at this noise only steps beyond %.1f%% are detectable",
                    100.0 * (sqrt(v.hi / v.lo) - 1.0));
        }
        fputs("</td></tr>\n", o);
    }
    fputs("</tbody></table>\n", o);
}

/* ---- the pages -------------------------------------------------------------- */

/* One machine's section of a metric's page: plot, steps, series. */
static void machine_section(FILE *o, const Pub *pub, Metric *m, Plot *p)
{
    HxBuf common = {0};
    HxSeriesSet view = {hx_xmalloc(p->n * sizeof *view.s), p->n};
    for (size_t i = 0; i < p->n; i++)
        view.s[i] = *p->s[i]; /* shallow: the order of these series' commits */
    hx_series_commit_order(&view, &p->order);
    free(view.s);
    p->legend = calloc(p->n, sizeof *p->legend);
    hx_series_legends(p->s, p->n, p->legend, &common);
    plot_range(p);
    p->st = calloc(p->n, sizeof *p->st);
    p->nst = calloc(p->n, sizeof *p->nst);
    size_t nsteps = m->nslow + m->nfast; /* the page's before this plot */
    for (size_t i = 0; i < p->n; i++) {
        p->nst[i] = hx_series_steps(p->s[i], pub->rule, &p->st[i]);
        for (size_t j = 0; j < p->nst[i]; j++) {
            int slower = p->higher ? p->st[i][j].ratio < 1.0 : p->st[i][j].ratio > 1.0;
            m->nslow += slower;
            m->nfast += !slower;
        }
    }
    char *mfp = hx_series_machine(p->s[0]);
    const Machine *mc = machine_of(pub, mfp);
    put(o, "<section><h2>", mc ? mc->name : "a machine not described in the database", "</h2>\n");
    put(o, "<p class=\"note\">", mc ? mc->detail : "", "");
    fprintf(o, "%s%zu series over %zu commits", mc && *mc->detail ? ". " : "", p->n, p->order.n);
    if (common.len)
        put(o, "; all of them: ", common.s, "");
    fputs(".</p>\n<figure>", o);
    svg_plot(o, p, m->name, m->unit);
    fputs("<figcaption>Median of each commit's runs, the bar from their minimum to their maximum", o);
    if (p->logy)
        fprintf(o, "; y axis on a log scale: the series' medians differ %.0fx", p->spread);
    fputs(m->nslow + m->nfast > nsteps ? "; steps marked S1, ... (red slower, green faster)" : "", o);
    fputs(".</figcaption></figure>\n", o);
    step_table(o, p, pub->rule);
    series_table(o, p, pub->rule, m->unit);
    fputs("</section>\n", o);
    free(mfp);
    hx_buf_free(&common);
}

static void free_plot(Plot *p)
{
    for (size_t i = 0; i < p->n; i++) {
        free(p->legend ? p->legend[i] : NULL);
        free(p->st ? p->st[i] : NULL);
    }
    free(p->legend);
    free(p->st);
    free(p->nst);
    free(p->s);
    hx_strlist_free(&p->order);
}

static void put_nav(FILE *o, const Pub *p)
{
    fputs("<p><a href=\"index.html\">index</a> | metrics:", o);
    for (size_t i = 0; i < p->nm; i++) {
        put(o, " <a href=\"", p->m[i].file, "\">");
        put(o, "", p->m[i].name, "</a>");
    }
    fputs("</p>\n", o);
}

/* DIR/METRIC.html: a section per machine, in the series' order. 0 or -1. */
static int metric_page(Pub *pub, Metric *m)
{
    const HxSeriesSet *ss = &m->ss;
    HxStrList fps = {0}, all = {0};
    hx_series_commit_order(ss, &all);
    m->ncommits = all.n;
    for (size_t i = 0; i < ss->n; i++) {
        char *fp = hx_series_machine(&ss->s[i]);
        if (hx_strlist_find(&fps, fp) < 0)
            hx_strlist_push(&fps, fp);
        free(fp);
    }
    HxBuf path = {0}, title = {0};
    hx_buf_printf(&path, "%s/%s", pub->dir, m->file);
    hx_buf_printf(&title, "%s over commits: raybench history", m->name);
    HxHtmlPage pg;
    FILE *o = hx_html_open(&pg, path.s, title.s);
    if (o) {
        put(o, "<h1>", m->name, " over commits</h1>\n");
        put_nav(o, pub);
        put(o, "<p>", m->what, "");
        fprintf(o, "; %s is better. Commits in history order (commit time where the repository knew it, else "
                   "when first measured); one plot per machine.</p>\n", m->higher ? "higher" : "lower");
        size_t step0 = 0;
        for (size_t f = 0; f < fps.n; f++) {
            Plot p = {.s = hx_xmalloc(ss->n * sizeof *p.s), .higher = m->higher, .step0 = step0};
            for (size_t i = 0; i < ss->n; i++) {
                char *fp = hx_series_machine(&ss->s[i]);
                if (strcmp(fp, fps.v[f]) == 0)
                    p.s[p.n++] = &ss->s[i];
                free(fp);
            }
            machine_section(o, pub, m, &p);
            for (size_t i = 0; i < p.n; i++)
                step0 += p.nst[i];
            free_plot(&p);
        }
    }
    int rc = hx_html_close(&pg, WHO, o != NULL);
    hx_buf_free(&path);
    hx_buf_free(&title);
    hx_strlist_free(&fps);
    hx_strlist_free(&all);
    return rc;
}

/* The stored studies, newest first (at most 50). */
static void studies_table(FILE *o, const Pub *p)
{
    sqlite3_stmt *st = hx_db_prep(p->db, p->dbpath,
        "SELECT s.id, s.name, s.added_utc, COUNT(r.id), COUNT(DISTINCT r.git_commit), MIN(r.git_commit),"
        " (SELECT COUNT(*) FROM studies) FROM studies s LEFT JOIN runs r ON r.study_id = s.id"
        " GROUP BY s.id ORDER BY s.id DESC LIMIT 50");
    int n = 0;
    while (st && sqlite3_step(st) == SQLITE_ROW) {
        if (n++ == 0)
            fprintf(o, "<h2>Studies</h2>\n<p>%d stored%s.</p>\n<table><thead><tr><th>id</th><th>study</th>"
                       "<th>added</th><th>runs</th><th>commit</th></tr></thead><tbody>\n", sqlite3_column_int(st, 6),
                    sqlite3_column_int(st, 6) > 50 ? ", the newest 50 here" : "");
        fprintf(o, "<tr><td>%d</td>", sqlite3_column_int(st, 0));
        put(o, "<td>", (const char *)sqlite3_column_text(st, 1), "</td>");
        put(o, "<td>", (const char *)sqlite3_column_text(st, 2), "</td>");
        fprintf(o, "<td>%d</td><td><code>", sqlite3_column_int(st, 3));
        if (sqlite3_column_int(st, 4) > 1)
            fprintf(o, "%d commits", sqlite3_column_int(st, 4));
        else
            hx_html_put(o, sqlite3_column_text(st, 5) ? (const char *)sqlite3_column_text(st, 5) : "-");
        fputs("</code></td></tr>\n", o);
    }
    if (n)
        fputs("</tbody></table>\n", o);
    sqlite3_finalize(st);
}

static void metrics_table(FILE *o, const Pub *p)
{
    fputs("<h2>Metrics</h2>\n<table><thead><tr><th>metric</th><th>what</th><th>series</th><th>commits</th>"
          "<th>steps (not confirmed)</th></tr></thead><tbody>\n", o);
    for (size_t i = 0; i < p->nm; i++) {
        const Metric *m = &p->m[i];
        put(o, "<tr><td><a href=\"", m->file, "\">");
        put(o, "", m->name, "</a></td>");
        put(o, "<td>", m->what, *m->unit ? " (" : "");
        put(o, "", m->unit, *m->unit ? ")" : "");
        fprintf(o, "</td><td>%zu</td><td>%zu</td><td>", m->ss.n, m->ncommits);
        if (m->nslow)
            fprintf(o, "<span class=\"warn\">%zu slower</span>%s", m->nslow, m->nfast ? ", " : "");
        if (m->nfast)
            fprintf(o, "<span class=\"ok\">%zu faster</span>", m->nfast);
        fputs(m->nslow || m->nfast ? "</td></tr>\n" : "none</td></tr>\n", o);
    }
    fputs("</tbody></table>\n", o);
}

static int index_page(const Pub *p)
{
    HxBuf path = {0};
    hx_buf_printf(&path, "%s/index.html", p->dir);
    HxHtmlPage pg;
    FILE *o = hx_html_open(&pg, path.s, "raybench history");
    if (o) {
        put(o, "<h1>raybench history</h1>\n<p>The database <code>", p->dbpath, "</code>: ");
        fputs("each metric over commits, a series per configuration, machine and settings.</p>\n", o);
        if (p->nm == 0) {
            fputs("<p class=\"warn\">No history yet: the database holds no ok run with a metric. "
                  "<code>harness history add STUDY.csv</code> stores a study.</p>\n", o);
        } else {
            metrics_table(o, p);
            fputs("<h2>Machines</h2>\n<table><thead><tr><th>machine</th><th>details</th></tr></thead><tbody>\n", o);
            for (size_t i = 0; i < p->nmach; i++) {
                put(o, "<tr><td>", p->mach[i].name, "</td>");
                put(o, "<td>", p->mach[i].detail, "</td></tr>\n");
            }
            fputs("</tbody></table>\n", o);
        }
        studies_table(o, p);
        fputs("<p>Written by <code>harness history publish</code> (docs/harness-history.md, \"Dashboard\").</p>\n", o);
    }
    int rc = hx_html_close(&pg, WHO, o != NULL);
    hx_buf_free(&path);
    return rc;
}

/* Pages of metrics no longer published: the folder is the dashboard's
 * (it holds the mark), so its stale pages go. */
static void remove_stale(const char *dir, const HxStrList *pages)
{
    DIR *d = opendir(dir);
    struct dirent *e;
    while (d && (e = readdir(d)) != NULL) {
        size_t n = strlen(e->d_name);
        if (n > 5 && e->d_name[0] != '.' && strcmp(e->d_name + n - 5, ".html") == 0 &&
            hx_strlist_find(pages, e->d_name) < 0) {
            char *f = hx_path_join(dir, e->d_name);
            unlink(f);
            free(f);
        }
    }
    if (d)
        closedir(d);
}

static void metric_free(Metric *m)
{
    free(m->name);
    free(m->unit);
    free(m->what);
    free(m->file);
    hx_series_free(&m->ss);
}

/* Each metric's series, read before anything is written; a metric no ok
 * run has (where filters leave none) gets no page. 0 or -1. */
static int load_series(Pub *p)
{
    size_t keep = 0;
    int rc = 0;
    for (size_t i = 0; i < p->nm; i++) {
        if (rc == 0 && hx_series_load(p->db, p->dbpath, p->m[i].name, p->want, &p->m[i].ss) != 0)
            rc = -1;
        p->m[i].higher = hx_metric_higher(p->db, p->m[i].name);
        if (rc == 0 && p->m[i].ss.n)
            p->m[keep++] = p->m[i];
        else
            metric_free(&p->m[i]);
    }
    p->nm = keep;
    return rc;
}

static void pub_free(Pub *p)
{
    for (size_t i = 0; i < p->nm; i++)
        metric_free(&p->m[i]);
    for (size_t i = 0; i < p->nmach; i++) {
        free(p->mach[i].fp);
        free(p->mach[i].name);
        free(p->mach[i].detail);
    }
    free(p->m);
    free(p->mach);
    sqlite3_close(p->db);
}

int hx_history_publish(const char *dbpath, const char *dir, const HxStrList *want, const HxStepRule *rule)
{
    Pub p = {.dbpath = dbpath, .dir = dir, .want = want, .rule = rule};
    int empty;
    if (hx_has_ctrl(dir)) {
        fprintf(stderr, WHO ": -o: the folder's name holds a control character\n");
        return 1;
    }
    if (open_db(dbpath, &p.db, &empty) != 0)
        return 1;
    if (!empty) {
        list_metrics(&p);
        load_machines(&p);
    }
    int rc = load_series(&p);
    if (rc == 0)
        rc = hx_html_dir(WHO, dir, "written by harness history publish");
    HxStrList pages = {0};
    hx_strlist_push(&pages, "index.html");
    for (size_t i = 0; i < p.nm && rc == 0; i++) {
        rc = metric_page(&p, &p.m[i]);
        hx_strlist_push(&pages, p.m[i].file);
    }
    if (rc == 0)
        rc = index_page(&p);
    if (rc == 0) {
        remove_stale(dir, &pages);
        printf(WHO ": wrote %s/index.html and %zu metric page(s)\n", dir, p.nm);
    }
    hx_strlist_free(&pages);
    pub_free(&p);
    return rc ? 1 : 0;
}
#endif
