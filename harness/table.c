/* table.c: `harness table`: per-configuration statistics, scaling against two
 * baselines, Amdahl fits and the report's scenes x configurations table.
 *
 * The groups, their statistics and the correctness gate re-applied from the
 * CSV alone come from the study model (study.c): a fast wrong image never
 * enters a table. The default Markdown, laid out to fit 100 columns, is
 * table_md.c's; HTML, CSV, --wide and JSON are here. */
#include "table_md.h"

#include <getopt.h>
#include <math.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>

/* ---- output: Markdown or CSV tables ---- */

typedef struct {
    FILE *out;
    int csv;
    int ncol;
    int html, open; /* harness report: HTML tables; one is open */
    int compact;    /* the default Markdown: fits HX_MD_WIDTH (table_md.c) */
} Emit;

static void emit_end(Emit *e)
{
    if (e->html && e->open)
        fputs("</tbody></table>\n", e->out);
    e->open = 0;
}

static void emit_row(Emit *e, const char *const *cells, int n)
{
    if (e->html) {
        fputs("<tr>", e->out);
        for (int i = 0; i < n; i++) {
            fputs("<td>", e->out);
            hx_html_put(e->out, cells[i]);
            fputs("</td>", e->out);
        }
        fputs("</tr>\n", e->out);
        return;
    }
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
        hx_fput_clean(e->out, cells[i], 1);
        fputs(" |", e->out);
    }
    fputc('\n', e->out);
}

static void emit_header(Emit *e, const char *title, const char *const *cells, int n)
{
    e->ncol = n;
    if (e->html) {
        emit_end(e);
        fputs("<h3>", e->out);
        hx_html_put(e->out, title);
        fputs("</h3>\n<table><thead><tr>", e->out);
        for (int i = 0; i < n; i++) {
            fputs("<th>", e->out);
            hx_html_put(e->out, cells[i]);
            fputs("</th>", e->out);
        }
        fputs("</tr></thead><tbody>\n", e->out);
        e->open = 1;
        return;
    }
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

void tab_fmt_ms(char *b, size_t n, double v)
{
    if (isnan(v))
        snprintf(b, n, "-");
    else if (fabs(v) >= 1e9) /* (whole digits past that would not fit a cell, nor its buffer) */
        snprintf(b, n, "%.4g", v);
    else if (v >= 1000)
        snprintf(b, n, "%.0f", v);
    else if (v >= 100)
        snprintf(b, n, "%.1f", v);
    else if (v >= 1)
        snprintf(b, n, "%.2f", v);
    else
        snprintf(b, n, "%.3f", v);
}

void tab_fmt_num(char *b, size_t n, const char *f, double v)
{
    if (isnan(v) || isinf(v))
        snprintf(b, n, "-");
    else
        snprintf(b, n, f, v);
}

static void usage_table(FILE *f)
{
    fputs("usage: harness table CSV [--baseline KEY=VALUE] [--format md|csv|json] [--wide]\n"
          "                         [--metric COLUMN] [--include-suspect] [--ceiling FILE]\n"
          "Per configuration: median with its 95% bootstrap interval, speedup and\n"
          "efficiency against (a) the same series at one worker and (b) the fastest\n"
          "configuration of the scene matching KEY=VALUE (default: the CSV's baseline\n"
          "column, else backend=serial); an Amdahl fit T(p) = a + b/p per series (a\n"
          "series sweeps one dimension: threads for OpenMP, ranks for MPI, and in hybrid\n"
          "studies also threads at fixed ranks); the scenes x configurations cross table.\n"
          "Oversubscribed runs and runs whose pinning did not hold are marked and left\n"
          "out of the fits. A size (unit B, KiB ... GB, or maxrss_kib) has no speedup:\n"
          "it is shown as its ratio to one worker, with no fit. Schema of --format\n"
          "json: docs/harness-table.md.\n"
          "  --baseline KEY=VALUE  column=value selecting baseline (b)\n"
          "  --format md|csv|json  output format (default md)\n"
          "  --wide                every column (the default table fits 100 columns)\n"
          "  --metric COLUMN       a column or record key (default render_ms; a command\n"
          "                        study's first metric, else wall_ms)\n"
          "  --include-suspect     fit oversubscribed and unpinned points too\n"
          "  --ceiling FILE        the machine's ceiling (harness ceiling; default\n"
          "                        ceiling-FINGERPRINT.csv beside the CSV or in results/)\n"
          "  -h, --help            this text\n", f);
}

/* Speedup and efficiency against both baselines: times and rates only. */
static void scaling_stats(const HxStudy *s, const HxGroup *g, const char *baseline, ConfigStats *c)
{
    c->b = hx_baseline_fastest(s, g, baseline);
    c->spa = c->a && g->nt ? hx_study_speedup(s, c->a->median, g->median) : NAN;
    if (c->a && g->nt && c->a != g) {
        hx_bootstrap_ci(g->t, g->nt, c->a->t, c->a->nt, &c->spa_lo, &c->spa_hi);
        if (s->higher) { /* a rate's speedup is the inverse ratio */
            double lo = 1.0 / c->spa_hi;
            c->spa_hi = 1.0 / c->spa_lo;
            c->spa_lo = lo;
        }
    }
    c->efa = c->spa / g->axis;
    double tog = NAN, step = NAN;
    c->ceil = g->axis > 1 ? hx_ceiling_at(s, g->scene, g->workers, &tog, &step) : NAN;
    /* The same share without the one-worker time: W copies each took tog at
     * once, so W workers sharing the work as well would take tog / W. The
     * one-worker time is measured alone, at another moment: on a VM whose
     * lone core ran 83 or 108 ms by the round, it moves the share by a
     * quarter (docs/harness-noise.md, "Ceiling"). */
    c->pace = isfinite(c->ceil) && isfinite(tog) && g->nt && g->median > 0
                  ? (s->higher ? g->median / tog : tog / g->median) / g->workers
                  : NAN;
    /* with rounds, each run against the copies of its own minutes: the
     * machine's drift between rounds then leaves the pace */
    const double paired = isfinite(c->pace) ? hx_ceiling_paired_pace(s, g) : NAN;
    c->pace = isfinite(paired) ? paired : c->pace;
    c->step = isfinite(c->pace) ? step : NAN;
    /* Karp-Flatt only where it means something: a speedup below 1 gives
     * e > 1, a "serial fraction" that no program has */
    c->kf = g->axis > 1 && c->spa >= 1 ? hx_karp_flatt(c->spa, g->axis) : NAN;
    c->spb = c->b && g->nt ? hx_study_speedup(s, c->b->median, g->median) : NAN;
    c->efb = c->spb / g->workers;
}

/* Appends one code (printf-style) to b and its bit to *used. */
static void __attribute__((format(printf, 4, 5))) add_code(HxBuf *b, unsigned *used, int bit, const char *fmt, ...)
{
    char v[64];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(v, sizeof v, fmt, ap);
    va_end(ap);
    hx_buf_printf(b, "%s%s", b->len ? " " : "", v);
    *used |= 1u << bit;
}

/* The notes again as codes, for the default Markdown (legend: table_md.c):
 * the same conditions in the same order. */
static void note_codes(ConfigStats *c)
{
    const HxGroup *g = c->g;
    HxBuf b = {0};
    if (g->ntimeout)
        add_code(&b, &c->used, NC_TLE, "T%zu", g->ntimeout);
    if (g->nwrong)
        add_code(&b, &c->used, NC_WRONG, "W%zu", g->nwrong);
    if (g->nerror) /* a status from the CSV: cut, --wide has it whole */
        add_code(&b, &c->used, NC_FAIL, "%.12s:%zu", g->first_status, g->nerror);
    if (g->suspect) {
        int over = strcmp(g->suspect_why, "oversubscribed") == 0;
        add_code(&b, &c->used, over ? NC_OVER : NC_UNPIN, "%s", over ? "OS" : "NP");
    }
    if (g->npartial)
        add_code(&b, &c->used, NC_PARTIAL, "P%zu/%zu", g->npartial, g->nrows);
    if (g->nbusy)
        add_code(&b, &c->used, NC_BUSY, "B%zu/%zu", g->nbusy, g->nrows);
    if (g->nstolen && g->steal_max >= 0)
        add_code(&b, &c->used, NC_STEAL, "CS%zu/%zu %.0f%%", g->nstolen, g->nrows, g->steal_max);
    else if (g->nstolen)
        add_code(&b, &c->used, NC_STEAL, "CS%zu/%zu", g->nstolen, g->nrows);
    if (c->efa > 1.0 && g->axis > 1)
        add_code(&b, &c->used, NC_EFF, ">1");
    if (g->noutliers)
        add_code(&b, &c->used, NC_OUT, "O%d", g->noutliers);
    if (c->spa < 1 && g->axis > 1)
        add_code(&b, &c->used, NC_SLOW, "<1");
    snprintf(c->codes, sizeof c->codes, "%s", b.s ? b.s : "");
    hx_buf_free(&b);
}

/* A size (peak memory) has no speedup: it is shown against one worker, and
 * notes about speedup (efficiency above 1, slower than 1 worker) stay out. */
void tab_config_stats(const HxStudy *s, const HxGroup *g, const char *baseline, ConfigStats *c)
{
    memset(c, 0, sizeof *c);
    c->g = g;
    c->a = hx_baseline_one_worker(s, g);
    c->spa = c->spa_lo = c->spa_hi = c->efa = c->kf = c->spb = c->efb = c->ceil = c->pace = c->step = NAN;
    c->ratio = c->a && g->nt ? g->median / c->a->median : NAN;
    if (!s->size)
        scaling_stats(s, g, baseline, c);
    HxBuf n = {0};
    if (g->ntimeout)
        hx_buf_printf(&n, "TLE %zu", g->ntimeout);
    if (g->nwrong)
        hx_buf_printf(&n, "%swrong-image %zu", n.len ? ", " : "", g->nwrong);
    if (g->nerror)
        hx_buf_printf(&n, "%s%s %zu", n.len ? ", " : "", g->first_status, g->nerror);
    if (g->suspect)
        hx_buf_printf(&n, "%s%s", n.len ? ", " : "", g->suspect_why);
    /* what should not be trusted as it stands (docs/harness-noise.md, "Noise") */
    if (g->npartial)
        hx_buf_printf(&n, "%spinning partial %zu/%zu", n.len ? ", " : "", g->npartial, g->nrows);
    if (g->nbusy)
        hx_buf_printf(&n, "%sbusy machine %zu/%zu", n.len ? ", " : "", g->nbusy, g->nrows);
    if (g->nstolen)
        hx_buf_printf(&n, "%sCPU steal %zu/%zu", n.len ? ", " : "", g->nstolen, g->nrows);
    if (g->nstolen && g->steal_max >= 0)
        hx_buf_printf(&n, " (up to %.1f%%)", g->steal_max);
    if (c->efa > 1.0 && g->axis > 1)
        hx_buf_printf(&n, "%sefficiency above 1", n.len ? ", " : "");
    if (g->noutliers)
        hx_buf_printf(&n, "%soutliers %d", n.len ? ", " : "", g->noutliers);
    if (c->spa < 1 && g->axis > 1)
        hx_buf_printf(&n, "%sslower than 1 worker", n.len ? ", " : "");
    snprintf(c->notes, sizeof c->notes, "%s", n.s ? n.s : "");
    hx_buf_free(&n);
    note_codes(c);
}

/* compact: "v [lo,hi]", the default Markdown's */
static void fmt_ci(char *b, size_t n, double v, double lo, double hi, int ms, int compact)
{
    char a[32], l[32], h[32];
    if (ms) {
        tab_fmt_ms(a, sizeof a, v);
        tab_fmt_ms(l, sizeof l, lo);
        tab_fmt_ms(h, sizeof h, hi);
    } else {
        tab_fmt_num(a, sizeof a, "%.2f", v);
        tab_fmt_num(l, sizeof l, "%.2f", lo);
        tab_fmt_num(h, sizeof h, "%.2f", hi);
    }
    if (isnan(lo))
        snprintf(b, n, "%s", a);
    else
        snprintf(b, n, compact ? "%s [%s,%s]" : "%s [%s, %s]", a, l, h);
}

void tab_unit_heads(const HxStudy *s, UnitHeads *h)
{
    const char *u = s->unit[0] && strcmp(s->unit, "1") != 0 ? s->unit : "";
    snprintf(h->med, sizeof h->med, "median %s%s[CI]", u, *u ? " " : "");
    snprintf(h->min, sizeof h->min, "%s %s", s->higher ? "max" : "min", u);
    snprintf(h->iqr, sizeof h->iqr, "IQR %s", u);
    snprintf(h->t1, sizeof h->t1, "%s %s", s->size ? "1 worker" : "T(1)", u);
    snprintf(h->bt, sizeof h->bt, "base (b) %s", u);
}

void tab_common_cells(const HxStudy *s, const ConfigStats *c, Cells *k)
{
    const HxGroup *g = c->g;
    snprintf(k->w, sizeof k->w, "%d", g->workers);
    snprintf(k->n, sizeof k->n, "%zu/%zu", g->nok, g->nrows);
    fmt_ci(k->med, sizeof k->med, g->median, g->ci_lo, g->ci_hi, 1, 0);
    fmt_ci(k->medc, sizeof k->medc, g->median, g->ci_lo, g->ci_hi, 1, 1);
    double top = g->min;
    for (size_t i = 0; s->higher && i < g->nt; i++)
        top = i == 0 || g->t[i] > top ? g->t[i] : top;
    tab_fmt_ms(k->mn, sizeof k->mn, top);
    tab_fmt_ms(k->iqr, sizeof k->iqr, g->q3 - g->q1);
    snprintf(k->out, sizeof k->out, "%d", g->noutliers);
    tab_fmt_ms(k->t1, sizeof k->t1, c->a ? c->a->median : NAN);
}

/* A size's rows: the median and its ratio to the same series at one worker. */
static void table_sizes(Emit *e, const HxStudy *s, int wide)
{
    UnitHeads h;
    tab_unit_heads(s, &h);
    const char *const narrow[] = {"scene", "configuration", "n", h.med, "x 1 worker", "notes"};
    const char *const all[] = {"scene", "configuration", "workers", "n", h.med, h.min,
                               h.iqr, "outliers", h.t1, "x 1 worker", "notes"};
    if (wide)
        emit_header(e, "Per configuration (CI: 95% bootstrap interval)", all, 11);
    else
        emit_header(e, "Per configuration (CI: 95% bootstrap interval; --wide: every column)", narrow, 6);
    for (size_t i = 0; i < s->ng; i++) {
        ConfigStats c;
        tab_config_stats(s, &s->g[i], NULL, &c);
        Cells k;
        tab_common_cells(s, &c, &k);
        char r[32];
        tab_fmt_num(r, sizeof r, "%.2f", c.ratio);
        const char *notes = c.notes[0] ? c.notes : "-";
        if (wide) {
            const char *cells[11] = {c.g->scene, c.g->label, k.w, k.n, k.med, k.mn, k.iqr, k.out, k.t1, r, notes};
            emit_row(e, cells, 11);
        } else {
            const char *cells[6] = {c.g->scene, c.g->label, k.n, k.med, r, notes};
            emit_row(e, cells, 6);
        }
    }
}

void tab_speed_cells(const ConfigStats *c, SpeedCells *p)
{
    fmt_ci(p->sp, sizeof p->sp, c->spa, c->spa_lo, c->spa_hi, 0, 0);
    fmt_ci(p->spc, sizeof p->spc, c->spa, c->spa_lo, c->spa_hi, 0, 1);
    tab_fmt_num(p->sps, sizeof p->sps, "%.2f", c->spa);
    tab_fmt_num(p->efs, sizeof p->efs, "%.3f", c->efa);
    snprintf(p->ef, sizeof p->ef, "%s", p->efs);
    snprintf(p->efb, sizeof p->efb, "%s", p->efs);
    if (isfinite(c->ceil) && isfinite(c->efa)) { /* against what this machine allows */
        char pace[40] = "";
        if (isfinite(c->pace)) /* and the pace the machine's steps allow */
            snprintf(pace, sizeof pace, isfinite(c->step) ? "pace %.2f of %.2f" : "pace %.2f", c->pace, c->step);
        snprintf(p->ef, sizeof p->ef, "%.3f (%.2f of %.2f%s%s)", c->efa, c->efa / c->ceil, c->ceil, *pace ? ", " : "",
                 pace);
        if (*pace) /* the pace needs no one-worker time: the part a narrow table keeps */
            snprintf(p->efb, sizeof p->efb, "%.3f (%s)", c->efa, pace);
    }
    tab_fmt_num(p->kf, sizeof p->kf, "%.3f", c->kf);
    tab_fmt_ms(p->bt, sizeof p->bt, c->b ? c->b->median : NAN);
    tab_fmt_num(p->sb, sizeof p->sb, "%.2f", c->spb);
    tab_fmt_num(p->eb, sizeof p->eb, "%.3f", c->efb);
}

static void table_configs(Emit *e, const HxStudy *s, const char *baseline, int wide)
{
    if (e->compact) {
        hx_md_configs(e->out, s, baseline);
        return;
    }
    if (s->size) {
        table_sizes(e, s, wide);
        return;
    }
    UnitHeads h;
    tab_unit_heads(s, &h);
    const char *const narrow[] = {"scene", "configuration", "n", h.med, "speedup (a) [CI]",
                                  "eff. (a)", "speedup (b)", "notes"};
    const char *const all[] = {
        "scene", "configuration", "workers", "n", h.med, h.min, h.iqr, "outliers",
        h.t1, "speedup (a) [CI]", "efficiency (a)", "Karp-Flatt", h.bt, "base (b)",
        "speedup (b)", "efficiency (b)", "notes"};
    if (wide)
        emit_header(e, "Per configuration (CI: 95% bootstrap interval)", all, 17);
    else
        emit_header(e, "Per configuration (CI: 95% bootstrap interval; --wide: every column)", narrow, 8);
    for (size_t i = 0; i < s->ng; i++) {
        ConfigStats c;
        tab_config_stats(s, &s->g[i], baseline, &c);
        const HxGroup *g = c.g;
        Cells k;
        tab_common_cells(s, &c, &k);
        SpeedCells p;
        tab_speed_cells(&c, &p);
        const char *notes = c.notes[0] ? c.notes : "-";
        if (wide) {
            const char *cells[17] = {g->scene, g->label, k.w, k.n, k.med, k.mn, k.iqr, k.out, k.t1, p.sp, p.ef, p.kf,
                                     p.bt, c.b ? c.b->label : "-", p.sb, p.eb, notes};
            emit_row(e, cells, 17);
        } else {
            const char *cells[8] = {g->scene, g->label, k.n, k.med, p.sp, p.ef, p.sb, notes};
            emit_row(e, cells, 8);
        }
    }
}

/* One Amdahl fit over a series' samples (second: the hybrid series over
 * threads). Suspect points are left out unless asked; the note says so, and
 * marks a fit whose serial fraction is outside [0, 1] or less than its
 * standard error from zero width. */

/* The fit's note, in words and as codes (the default Markdown's). */
static void fit_notes(Fit *out)
{
    const HxAmdahl *f = &out->f;
    HxBuf n = {0}, c = {0};
    if (f->ok && (f->serial_fraction < 0 || f->serial_fraction > 1)) {
        hx_buf_printf(&n, "implausible: serial fraction outside [0, 1]");
        add_code(&c, &out->used, FC_IMPL, "I");
    } else if (f->ok && f->has_se && f->se_serial_fraction > fabs(f->serial_fraction)) {
        hx_buf_printf(&n, "uncertain: std. error above the value");
        add_code(&c, &out->used, FC_UNCERTAIN, "U");
    }
    if (out->left_out) {
        hx_buf_printf(&n, "%s%s%zu suspect sample(s) left out", n.len ? "; " : "",
                      f->ok ? "" : "no fit: too few points once ", out->left_out);
        if (!f->ok)
            add_code(&c, &out->used, FC_NOFIT, "no fit");
        add_code(&c, &out->used, FC_LEFT, "L%zu", out->left_out);
    }
    snprintf(out->note, sizeof out->note, "%s", n.s ? n.s : "-");
    snprintf(out->code, sizeof out->code, "%s", c.s ? c.s : "-");
    hx_buf_free(&n);
    hx_buf_free(&c);
}

static void fit_series(const HxStudy *s, size_t i, int second, int include_suspect, char *done, Fit *out)
{
    const HxGroup *gi = &s->g[i];
    const char *sid = second ? gi->series2_id : gi->series_id;
    size_t cap = 0;
    double *p = NULL, *t = NULL;
    int lastw = -1;
    memset(out, 0, sizeof *out);
    for (size_t k = i; k < s->ng; k++) {
        const HxGroup *g = &s->g[k];
        const char *gid = second ? g->series2_id : g->series_id;
        if (!gid || strcmp(gid, sid) != 0 || !g->nt)
            continue;
        done[k] = 1;
        if (g->suspect && !include_suspect) {
            out->left_out += g->nt;
            continue;
        }
        int axis = second ? g->axis2 : g->axis;
        out->distinct += axis != lastw;
        lastw = axis;
        for (size_t j = 0; j < g->nt; j++) {
            if (out->np == cap) {
                cap = cap ? 2 * cap : 32;
                p = hx_xrealloc(p, cap * sizeof *p);
                t = hx_xrealloc(t, cap * sizeof *t);
            }
            p[out->np] = axis;
            /* a rate r fits as its time per unit of work, 1/r */
            t[out->np++] = s->higher ? 1.0 / g->t[j] : g->t[j];
        }
    }
    if (out->distinct >= 2)
        out->f = hx_amdahl_fit(p, t, out->np);
    if (!out->f.ok)
        out->f.a = out->f.b = out->f.serial_fraction = NAN;
    free(p);
    free(t);
    fit_notes(out);
}

/* Every series' fit, the series over the swept dimension first, then the
 * hybrid series over threads; *n of them, malloc'd (tab_fits_free). */
Fit *tab_collect_fits(const HxStudy *s, int include_suspect, size_t *n)
{
    Fit *fits = NULL;
    size_t cap = 0;
    *n = 0;
    for (int second = 0; second < 2; second++) {
        char *done = calloc(s->ng ? s->ng : 1, 1);
        for (size_t i = 0; i < s->ng; i++) {
            if (done[i] || !s->g[i].nt || (second && !s->g[i].series2_id))
                continue;
            Fit f;
            fit_series(s, i, second, include_suspect, done, &f);
            if (!f.f.ok && !f.left_out)
                continue;
            f.scene = s->g[i].scene;
            f.series = hx_series_label(&s->g[i], second);
            f.sweep = second || s->g[i].swept == HX_DIM_THREADS ? "threads" : "ranks";
            if (*n == cap) {
                cap = cap ? 2 * cap : 8;
                fits = hx_xrealloc(fits, cap * sizeof *fits);
            }
            fits[(*n)++] = f;
        }
        free(done);
    }
    return fits;
}

void tab_fits_free(Fit *fits, size_t n)
{
    for (size_t i = 0; i < n; i++)
        free(fits[i].series);
    free(fits);
}

static void table_fits(Emit *e, const HxStudy *s, int include_suspect)
{
    if (s->size) { /* a[KiB] + b[KiB]/p would be no law of anything */
        emit_end(e);
        if (e->html) {
            fputs("<p>No Amdahl fit: it applies to times and rates only, and ", e->out);
            hx_html_put(e->out, s->metric);
            fputs(" is a size.</p>\n", e->out);
        } else if (!e->csv) {
            HxBuf b = {0};
            hx_buf_printf(&b, "No Amdahl fit: it applies to times and rates only, and %s is a size.", s->metric);
            fputc('\n', e->out);
            hx_md_para(e->out, b.s);
            hx_buf_free(&b);
        }
        return;
    }
    if (e->compact) {
        hx_md_fits(e->out, s, include_suspect);
        return;
    }
    char ah[48], bh[48];
    const char *u = s->unit[0] ? s->unit : "-";
    /* a rate is fitted as 1/rate */
    snprintf(ah, sizeof ah, s->higher ? "a (1/%s)" : "a %s", u);
    snprintf(bh, sizeof bh, s->higher ? "b (1/%s)" : "b %s", u);
    const char *const h[] = {"scene", "series", "sweep", "points", "serial fraction", "std. error", ah, bh, "note"};
    size_t n;
    Fit *fits = tab_collect_fits(s, include_suspect, &n);
    if (n)
        emit_header(e, "Amdahl fit T(p) = a + b/p per series (least squares over all samples)", h, 9);
    for (size_t i = 0; i < n; i++) {
        const Fit *f = &fits[i];
        char pts[16], fs[32], se[32], as[32], bs[32];
        snprintf(pts, sizeof pts, "%zu", f->np);
        tab_fmt_num(fs, sizeof fs, "%.4f", f->f.serial_fraction);
        tab_fmt_num(se, sizeof se, "%.4f", f->f.has_se ? f->f.se_serial_fraction : NAN);
        tab_fmt_ms(as, sizeof as, f->f.a);
        tab_fmt_ms(bs, sizeof bs, f->f.b);
        const char *cells[9] = {f->scene, f->series, f->sweep, pts, fs, se, as, bs, f->note};
        emit_row(e, cells, 9);
    }
    tab_fits_free(fits, n);
}

void tab_cross_cell(const HxGroup *g, char *b, size_t n)
{
    if (g->nt)
        tab_fmt_ms(b, n, g->median);
    else if (g->ntimeout)
        snprintf(b, n, "TLE");
    else if (g->nwrong)
        snprintf(b, n, "wrong-image");
    else if (g->first_status)
        snprintf(b, n, "%s", g->first_status);
}

static void table_cross(Emit *e, const HxStudy *s)
{
    if (e->compact) {
        hx_md_cross_study(e->out, s);
        return;
    }
    size_t nl = s->labels.n;
    const char **hdr = hx_xmalloc((nl + 1) * sizeof *hdr);
    hdr[0] = "scene";
    for (size_t l = 0; l < nl; l++)
        hdr[l + 1] = s->labels.v[l];
    char title[96];
    snprintf(title, sizeof title, "Scenes x configurations (median %s; TLE = timed out)", s->size ? s->unit : "ms");
    emit_header(e, title, hdr, (int)nl + 1);
    char **cells = hx_xmalloc((nl + 1) * sizeof *cells);
    for (size_t sc = 0; sc < s->scenes.n; sc++) {
        cells[0] = s->scenes.v[sc];
        for (size_t l = 0; l < nl; l++) {
            cells[l + 1] = hx_xmalloc(32);
            snprintf(cells[l + 1], 32, "-");
            for (size_t i = 0; i < s->ng; i++) {
                const HxGroup *g = &s->g[i];
                if (strcmp(g->scene, s->scenes.v[sc]) == 0 && strcmp(g->label, s->labels.v[l]) == 0)
                    tab_cross_cell(g, cells[l + 1], 32);
            }
        }
        emit_row(e, (const char *const *)cells, (int)nl + 1);
        for (size_t l = 0; l < nl; l++)
            free(cells[l + 1]);
    }
    free(cells);
    free(hdr);
}

/* ---- --format json (schema: docs/harness-table.md, "JSON output") ---- */

static void json_scaling(FILE *o, const ConfigStats *c)
{
    hx_json_num(o, "speedup_a", c->spa);
    hx_json_pair(o, "speedup_a_ci95", c->spa_lo, c->spa_hi);
    hx_json_num(o, "efficiency_a", c->efa);
    hx_json_num(o, "ceiling", c->ceil);
    hx_json_num(o, "ceiling_pace", c->pace);
    hx_json_num(o, "ceiling_step", c->step);
    hx_json_num(o, "karp_flatt", c->kf);
    if (c->b)
        hx_json_kstr(o, "baseline_b", c->b->label);
    else
        fputs(", \"baseline_b\": null", o);
    hx_json_num(o, "speedup_b", c->spb);
    hx_json_num(o, "efficiency_b", c->efb);
}

static void json_config(FILE *o, const ConfigStats *c, int size)
{
    const HxGroup *g = c->g;
    fputs("{\"scene\": ", o);
    hx_json_str(o, g->scene);
    hx_json_kstr(o, "configuration", g->label);
    hx_json_num(o, "workers", g->workers);
    hx_json_num(o, "axis", g->axis);
    hx_json_num(o, "n_ok", (double)g->nok);
    hx_json_num(o, "n_rows", (double)g->nrows);
    hx_json_num(o, "median_ms", g->median);
    hx_json_pair(o, "median_ci95_ms", g->ci_lo, g->ci_hi);
    hx_json_num(o, "min_ms", g->min);
    hx_json_num(o, "iqr_ms", g->q3 - g->q1);
    hx_json_num(o, "outliers", g->noutliers);
    if (size) /* no speedup, efficiency or baseline (b) for a size */
        hx_json_num(o, "ratio_to_one_worker", c->ratio);
    else
        json_scaling(o, c);
    fprintf(o, ", \"suspect\": %s", g->suspect ? "true" : "false");
    hx_json_num(o, "timeouts", (double)g->ntimeout);
    hx_json_num(o, "wrong_image", (double)g->nwrong);
    hx_json_num(o, "errors", (double)g->nerror);
    hx_json_kstr(o, "notes", c->notes);
    fputs("}", o);
}

static void table_json(FILE *o, const HxStudy *s, const char *path, const char *metric, const char *baseline,
                       int include_suspect)
{
    fputs("{\"schema\": \"raybench-table/1\"", o);
    hx_json_kstr(o, "csv", path);
    hx_json_kstr(o, "study", s->csv.nrows ? hx_csv_get(&s->csv, 0, "study") : "");
    hx_json_kstr(o, "metric", metric);
    if (s->size)
        fputs(", \"size\": true", o);
    hx_json_kstr(o, "baseline", baseline);
    fputs(",\n \"configurations\": [", o);
    for (size_t i = 0; i < s->ng; i++) {
        ConfigStats c;
        tab_config_stats(s, &s->g[i], baseline, &c);
        fputs(i ? ",\n  " : "\n  ", o);
        json_config(o, &c, s->size);
    }
    fputs("],\n \"fits\": [", o);
    size_t n = 0;
    Fit *fits = s->size ? NULL : tab_collect_fits(s, include_suspect, &n);
    for (size_t i = 0; i < n; i++) {
        const Fit *f = &fits[i];
        fputs(i ? ",\n  {\"scene\": " : "\n  {\"scene\": ", o);
        hx_json_str(o, f->scene);
        hx_json_kstr(o, "series", f->series);
        hx_json_kstr(o, "sweep", f->sweep);
        hx_json_num(o, "points", (double)f->np);
        hx_json_num(o, "serial_fraction", f->f.serial_fraction);
        hx_json_num(o, "std_error", f->f.has_se ? f->f.se_serial_fraction : NAN);
        hx_json_num(o, "a_ms", f->f.a);
        hx_json_num(o, "b_ms", f->f.b);
        hx_json_kstr(o, "note", f->note);
        fputs("}", o);
    }
    tab_fits_free(fits, n);
    fputs("]}\n", o);
}

void hx_table_html(FILE *out, const HxStudy *s, const char *baseline)
{
    Emit e = {out, 0, 0, 1, 0, 0};
    table_configs(&e, s, baseline, 0);
    table_fits(&e, s, 0);
    if (s->scenes.n > 1 || (s->scenes.n == 1 && strcmp(s->scenes.v[0], "-") != 0))
        table_cross(&e, s);
    emit_end(&e);
}

/* The study, its CSV, metric and baselines: lines wrapped to fit (the
 * phrase "metric NAME" starts a line, for whoever looks for it). */
static void study_head(const HxStudy *s, const char *path, const char *baseline, int compact)
{
    HxBuf b = {0};
    hx_buf_printf(&b, "## Study %s", s->csv.nrows ? hx_csv_get(&s->csv, 0, "study") : "");
    hx_md_para(stdout, b.s);
    b.len = 0;
    putchar('\n');
    hx_buf_printf(&b, "From %s;", path);
    hx_md_para(stdout, b.s);
    b.len = 0;
    if (s->size)
        hx_buf_printf(&b, "metric %s (%s), a size: shown against 1 worker, no speedup", s->metric, s->unit);
    else
        hx_buf_printf(&b, "metric %s%s, baseline (b): %s %s", s->metric, s->higher ? ", higher is better" : "",
                      s->higher ? "best" : "fastest", baseline);
    hx_md_para(stdout, b.s);
    if (s->ceil_path && !s->size) {
        b.len = 0;
        hx_ceiling_para(s, &b);
        hx_md_para(stdout, b.s);
    }
    unsigned keys = 0;
    for (size_t i = 0; compact && i < s->labels.n; i++)
        free(hx_md_label(s->labels.v[i], &keys));
    hx_md_keys_legend(stdout, keys);
    hx_buf_free(&b);
}

int hx_cmd_table(int argc, char **argv)
{
    static const struct option lo[] = {
        {"baseline", required_argument, NULL, 'b'}, {"format", required_argument, NULL, 'f'},
        {"metric", required_argument, NULL, 'm'}, {"wide", no_argument, NULL, 'w'},
        {"include-suspect", no_argument, NULL, 'i'}, {"help", no_argument, NULL, 'h'},
        {"ceiling", required_argument, NULL, 'c'}, {NULL, 0, NULL, 0}};
    const char *baseline = NULL, *format = "md", *metric = NULL, *ceiling = NULL;
    int c, wide = 0, include_suspect = 0;
    while ((c = getopt_long(argc, argv, "h", lo, NULL)) != -1) {
        switch (c) {
        case 'b': baseline = optarg; break;
        case 'f': format = optarg; break;
        case 'm': metric = optarg; break;
        case 'w': wide = 1; break;
        case 'i': include_suspect = 1; break;
        case 'c': ceiling = optarg; break;
        case 'h': usage_table(stdout); return 0;
        default: usage_table(stderr); return 1;
        }
    }
    if (optind != argc - 1) {
        fprintf(stderr, "harness table: expected one CSV argument (see --help)\n");
        return 1;
    }
    if (strcmp(format, "md") != 0 && strcmp(format, "csv") != 0 && strcmp(format, "json") != 0) {
        fprintf(stderr, "harness table: --format: expected md, csv or json, got '%s'\n", format);
        return 1;
    }
    if (baseline && (!strchr(baseline, '=') || baseline[0] == '=')) {
        fprintf(stderr, "harness table: --baseline: expected KEY=VALUE, got '%s'\n", baseline);
        return 1;
    }
    HxStudy s;
    if (hx_study_open("harness table", argv[optind], metric, &s))
        return 1;
    if (hx_ceiling_load(&s, "harness table", ceiling, argv[optind]) != 0) {
        hx_study_free(&s);
        return 1;
    }
    metric = s.metric;
    if (!baseline) {
        baseline = "backend=serial";
        if (s.csv.nrows && *hx_csv_get(&s.csv, 0, "baseline"))
            baseline = hx_csv_get(&s.csv, 0, "baseline");
    }
    if (s.nwrong_rows)
        fprintf(stderr, "harness table: warning: %zu wrong-image row(s) left out (image hash "
                        "differs from the study's reference)\n", s.nwrong_rows);
    if (strcmp(format, "json") == 0) {
        table_json(stdout, &s, argv[optind], metric, baseline, include_suspect);
        hx_study_free(&s);
        return 0;
    }
    Emit e = {stdout, strcmp(format, "csv") == 0, 0, 0, 0, 0};
    e.compact = !e.csv && !wide;
    if (!e.csv)
        study_head(&s, argv[optind], baseline, e.compact);
    table_configs(&e, &s, baseline, wide);
    table_fits(&e, &s, include_suspect);
    if (s.scenes.n > 1 || (s.scenes.n == 1 && strcmp(s.scenes.v[0], "-") != 0)) /* not a command study's */
        table_cross(&e, &s);
    hx_study_free(&s);
    return 0;
}
