/* compare.c: `harness compare NEW.csv BASE.csv`: the regression check.
 *
 * Two kinds of evidence, kept apart on purpose:
 *  - work counters and the image hash are deterministic, so any difference
 *    is a regression (or a renderer change that needs a new baseline);
 *  - times are noisy, so a configuration regresses only when its median got
 *    slower by more than --factor (default 1.8) AND the samples differ
 *    significantly: two-sided Mann-Whitney U p < --alpha (default 0.05) when
 *    both sides have >= 4 samples (with 3 against 3 the smallest possible p is
 *    0.1, the test could never fire); in both cases the minimum must also be
 *    slower by more than the factor (the minimum is the least noisy estimate
 *    of the undisturbed time: on a busy 2-core machine, medians of a quiet
 *    and a loaded run of the same code differed by 1.5x with p = 0.095),
 *    or, with the test, the median ratio's whole 95% interval;
 *  - runs that timed out or failed count against NEW: a larger share of them
 *    than in BASE is a regression.
 * A 2x slowdown passes both rules; scheduler noise on a quiet machine (a few
 * percent, occasionally one slow repeat) passes neither. "no change" needs
 * the interval inside the factor both ways and, from 10 samples a side, the
 * slowest tenth too. */
#include "compare.h"
#include "hx.h"

#include <getopt.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

static const char *const counters[] = {"width", "height", "rays", "primary_rays",
                                       "shadow_rays", "secondary_rays", "node_visits",
                                       "prim_tests", "image_fnv1a", NULL};

static void usage_compare(FILE *f)
{
    fputs("usage: harness compare NEW.csv BASE.csv [--factor F] [--alpha A] [--metric COL]\n"
          "                       [--min-ms MS] [--format text|json|md] [--report URL]\n"
          "Flags regressions of NEW against BASE per configuration and exits 1 if any\n"
          "(an option left unset matches the default the renderer reports):\n"
          "  - any change of a work counter (rays, node_visits, prim_tests, ...) or of the\n"
          "    image hash, a configuration missing from NEW, or no ok run in NEW;\n"
          "  - a larger share of runs that timed out or failed in NEW than in BASE;\n"
          "  - a time regression: median ratio NEW/BASE > F, and the minimum ratio > F or,\n"
          "    with >= 4 samples a side, the median ratio's 95% interval above F; with\n"
          "    >= 4 samples a side also Mann-Whitney U two-sided p < A.\n"
          "The same rule the other way round reports an IMPROVEMENT (never a failure).\n"
          "Rows from different machines (fingerprint column) are reported as such.\n"
          "  --factor F    slowdown factor that counts (default 1.8)\n"
          "  --alpha A     significance level (default 0.05)\n"
          "  --metric COL  time column, or COL/calib (default: render_ms/calib where both\n"
          "                studies ran with --calibrate, else render_ms)\n"
          "  --min-ms MS   base medians below MS are too short to judge (default 0.5)\n"
          "  --format F    text (default), json (schema: docs/harness-table.md) or md (a summary\n"
          "                for a pull-request comment, one screen long)\n"
          "  --report URL  with md: a link to the full report\n"
          "  -h, --help    this text\n", f);
}

/* Distinct values of a column over the ok (non-wrong) rows of a group. */
static void group_values(const HxStudy *s, const HxGroup *g, const char *col, HxStrList *out)
{
    for (size_t r = 0; r < s->csv.nrows; r++) {
        if (s->row_status_wrong[r] || strcmp(hx_csv_get(&s->csv, r, "status"), "ok") != 0)
            continue;
        /* row belongs to g when its config id matches: compare swept values */
        int same = 1;
        for (int d = 0; d < HX_NDIM && same; d++) {
            const char *a = hx_csv_get(&s->csv, r, hx_dim_col[d]);
            const char *b = hx_csv_get(&s->csv, g->first_row, hx_dim_col[d]);
            same = strcmp(a, b) == 0;
        }
        if (!same)
            continue;
        const char *v = hx_csv_get(&s->csv, r, col);
        if (hx_strlist_find(out, v) < 0)
            hx_strlist_push(out, v);
    }
}

static void join(const HxStrList *l, char *buf, size_t n)
{
    buf[0] = '\0';
    for (size_t i = 0; i < l->n; i++) {
        if (i)
            strncat(buf, "/", n - strlen(buf) - 1);
        strncat(buf, l->v[i], n - strlen(buf) - 1);
    }
}

/* Fingerprint summary of a study: distinct (fingerprint, cpu, compiler). */
static void fingerprints(const HxStudy *s, HxStrList *out)
{
    for (size_t r = 0; r < s->csv.nrows; r++) {
        HxBuf b = {0};
        hx_buf_printf(&b, "%s [%s, %s cores, SMT %s, governor %s, %s, GPU %s]",
                      hx_csv_get(&s->csv, r, "fingerprint"), hx_csv_get(&s->csv, r, "cpu_model"),
                      hx_csv_get(&s->csv, r, "phys_cores"), hx_csv_get(&s->csv, r, "smt"),
                      hx_csv_get(&s->csv, r, "governor"), hx_csv_get(&s->csv, r, "compiler"),
                      hx_csv_get(&s->csv, r, "gpu_name"));
        if (hx_strlist_find(out, b.s) < 0)
            hx_strlist_push(out, b.s);
        hx_buf_free(&b);
    }
}

/* The configuration as the renderer ran it: a dimension left unset ("-")
 * takes the value the record reports (its default), so `accel: bvh` in one
 * study and no accel line in the other are the same configuration. */
static char *effective_id(const HxStudy *s, const HxGroup *g)
{
    static const char *const rec[][2] = {{"accel", "rec_accel"},     {"tile", "rec_tile"},
                                         {"schedule", "rec_schedule"}, {"mpi_schedule", "rec_mpi_schedule"},
                                         {"block", "rec_block"},       {"threads", "rec_threads"},
                                         {"ranks", "rec_ranks"},       {NULL, NULL}};
    const size_t row = g->ok_row; /* a row with a record, where there is one */
    const char *backend = hx_csv_get(&s->csv, row, "backend");
    if (strcmp(backend, "-") == 0) /* a command study: program, params, workers */
        return hx_strdup(g->config_id);
    const char *v[HX_NDIM];
    char res[64];
    for (int d = 0; d < HX_NDIM; d++) {
        v[d] = hx_csv_get(&s->csv, row, hx_dim_col[d]);
        if (strcmp(v[d], "-") != 0 || !hx_dim_applies(d, backend))
            continue;
        for (int k = 0; rec[k][0]; k++)
            if (strcmp(rec[k][0], hx_dim_col[d]) == 0 && *hx_csv_get(&s->csv, row, rec[k][1]))
                v[d] = hx_csv_get(&s->csv, row, rec[k][1]);
        if (d == HX_DIM_RESOLUTION && *hx_csv_get(&s->csv, row, "width")) {
            snprintf(res, sizeof res, "%sx%s", hx_csv_get(&s->csv, row, "width"), hx_csv_get(&s->csv, row, "height"));
            v[d] = res;
        }
    }
    return hx_make_config_id(v, NULL);
}

/* The group of s that is g's configuration, NULL if none. */
static const HxGroup *match(const HxStudy *s, const HxStudy *gs, const HxGroup *g)
{
    char *want = effective_id(gs, g);
    const HxGroup *found = NULL;
    for (size_t k = 0; k < s->ng && !found; k++) {
        char *id = effective_id(s, &s->g[k]);
        if (strcmp(id, want) == 0)
            found = &s->g[k];
        free(id);
    }
    free(want);
    return found;
}

/* note: the whole reason (CMP_NOTE); NULL for the time rule, whose
 * caller fills in the numbers and the kind. */
static CmpVerdict *push_verdict(CmpVerdicts *vs, const HxGroup *g, const char *verdict, const char *note,
                                const HxGroup *other)
{
    if (vs->n == vs->cap) {
        vs->cap = vs->cap ? 2 * vs->cap : 16;
        vs->v = hx_xrealloc(vs->v, vs->cap * sizeof *vs->v);
    }
    CmpVerdict *v = &vs->v[vs->n++];
    memset(v, 0, sizeof *v);
    v->verdict = verdict;
    v->scene = g->scene;
    v->label = g->label;
    v->kind = CMP_NOTE;
    v->note = note ? hx_strdup(note) : NULL;
    v->base_median = v->new_median = v->ratio = v->p = v->min_ratio = v->ci_lo = v->ci_hi = v->mde = NAN;
    v->tail_ratio = NAN;
    v->raw_base = v->raw_new = NAN;
    /* g is BASE's group, other NEW's; a "new" verdict has only NEW's */
    v->n_base = strcmp(verdict, "new") == 0 ? 0 : g->nt;
    v->n_new = strcmp(verdict, "new") == 0 ? g->nt : other ? other->nt : 0;
    vs->regressions += strcmp(verdict, "REGRESSION") == 0;
    vs->improvements += strcmp(verdict, "IMPROVEMENT") == 0;
    vs->inconclusive += strcmp(verdict, "INCONCLUSIVE") == 0;
    return v;
}

static void verdicts_free(CmpVerdicts *vs)
{
    for (size_t i = 0; i < vs->n; i++)
        free(vs->v[i].note);
    free(vs->v);
}

/* Exact counters: any change, or two values in NEW, is a regression. */
static int counters_changed(const HxStudy *nw, const HxStudy *base, const HxGroup *n, const HxGroup *b,
                            CmpVerdicts *vs)
{
    int bad = 0;
    /* GPU images match within a tolerance, not bit for bit (the gate's rule) */
    int cuda = hx_backend_gpu(b->backend);
    for (int ci = 0; counters[ci]; ci++) {
        if (cuda && strcmp(counters[ci], "image_fnv1a") == 0)
            continue;
        HxStrList vb = {0}, vn = {0};
        group_values(base, b, counters[ci], &vb);
        group_values(nw, n, counters[ci], &vn);
        int same = vb.n == vn.n;
        for (size_t k = 0; k < vn.n && same; k++)
            same = hx_strlist_find(&vb, vn.v[k]) >= 0;
        if (!same || vn.n > 1) {
            char sb[256], sn[256];
            join(&vb, sb, sizeof sb);
            join(&vn, sn, sizeof sn);
            HxBuf r = {0};
            hx_buf_printf(&r, "counter %s changed: base %s, new %s%s", counters[ci], sb, sn,
                          vn.n > 1 ? " (not deterministic)" : "");
            push_verdict(vs, b, "REGRESSION", r.s, n);
            hx_buf_free(&r);
            bad = 1;
        }
        hx_strlist_free(&vb);
        hx_strlist_free(&vn);
    }
    return bad;
}

/* The noise-aware time rule for one configuration (docs/harness-verdicts.md). */
/* The best sample: the fastest time, or the highest rate. */
static double best_sample(const HxGroup *g, int higher)
{
    double v = g->min;
    for (size_t i = 0; higher && i < g->nt; i++)
        v = i == 0 || g->t[i] > v ? g->t[i] : v;
    return v;
}

/* What the samples can resolve: the 95% bootstrap interval of the cost
 * ratio (new/base for times, base/new for rates), the smallest change it
 * could tell from none (the interval's half-width as a factor, e^w), and
 * the repeats a side that would resolve the asked factor (the width shrinks
 * as 1/sqrt(n)). */
typedef struct {
    double lo, hi, mde;
    long need;
} Resolution;

static Resolution resolution(const HxGroup *n, const HxGroup *b, const CmpRule *rule)
{
    Resolution r = {NAN, NAN, NAN, 0};
    hx_bootstrap_ci(b->t, b->nt, n->t, n->nt, &r.lo, &r.hi);
    if (rule->higher && isfinite(r.lo)) {
        double lo = 1.0 / r.hi;
        r.hi = 1.0 / r.lo;
        r.lo = lo;
    }
    if (!(r.lo > 0.0) || !isfinite(r.hi))
        return r;
    double w = (log(r.hi) - log(r.lo)) / 2.0, target = log(rule->factor) / 2.0;
    size_t nmin = n->nt < b->nt ? n->nt : b->nt;
    r.mde = exp(w);
    r.need = w > target ? (long)ceil((double)nmin * (w / target) * (w / target)) : (long)nmin;
    return r;
}

/* The slowest tenth's cost ratio, NEW against BASE (the 0.9 quantile of
 * times, the 0.1 of rates), from 10 samples a side; NAN with fewer, where
 * that quantile is one run. */
static double tail_ratio(const HxGroup *n, const HxGroup *b, int higher)
{
    if (n->nt < 10 || b->nt < 10)
        return NAN;
    const double q = higher ? 0.1 : 0.9;
    double r = hx_quantile(n->t, n->nt, q) / hx_quantile(b->t, b->nt, q);
    return higher ? 1.0 / r : r;
}

static void judge_time(const HxGroup *n, const HxGroup *b, const CmpRule *rule, CmpVerdicts *vs)
{
    /* ratio and rmin as costs, above 1 worse, whatever the direction */
    double ratio = n->median / b->median, rmin = best_sample(n, rule->higher) / best_sample(b, rule->higher);
    if (rule->higher) {
        ratio = 1.0 / ratio;
        rmin = 1.0 / rmin;
    }
    if (b->raw_median < rule->min_ms) { /* render_ms, whatever the metric */
        CmpVerdict *v = push_verdict(vs, b, "INCONCLUSIVE", NULL, n);
        v->kind = CMP_SHORT;
        v->raw_base = b->raw_median;
        v->raw_new = n->raw_median;
        return;
    }
    Resolution res = resolution(n, b, rule);
    double p = NAN, f = rule->factor;
    int slow, fast;
    if (b->nt >= 4 && n->nt >= 4) {
        p = hx_mann_whitney_p(n->t, n->nt, b->t, b->nt);
        /* the minimum must move too: noise on a busy machine only ever adds
         * time, so it inflates medians but rarely the fastest run. Unless
         * the interval itself lies beyond the factor: then one run as fast
         * as BASE's among many slow ones does not hold the verdict back. */
        slow = ratio > f && p < rule->alpha && (rmin > f || res.lo > f);
        fast = ratio < 1.0 / f && p < rule->alpha && (rmin < 1.0 / f || res.hi < 1.0 / f);
    } else {
        slow = ratio > f && rmin > f;
        fast = ratio < 1.0 / f && rmin < 1.0 / f;
    }
    /* "no change" only where the interval rules out the asked factor both
     * ways, and the slowest tenth moved less than it too (a tenth of the
     * runs far slower leaves the median where it was); anything else that
     * is not a verdict is inconclusive */
    const double tail = tail_ratio(n, b, rule->higher);
    int none = res.lo > 1.0 / f && res.hi < f && !(tail > f);
    const char *verdict = slow ? "REGRESSION" : fast ? "IMPROVEMENT" : none ? "no change" : "INCONCLUSIVE";
    CmpVerdict *v = push_verdict(vs, b, verdict, NULL, n);
    v->kind = CMP_TIME;
    v->base_median = b->median;
    v->new_median = n->median;
    v->ratio = ratio;
    v->p = p;
    v->min_ratio = rmin;
    v->ci_lo = res.lo;
    v->ci_hi = res.hi;
    v->mde = res.mde;
    v->need = res.need;
    v->tail_ratio = tail;
    v->busy[0] = n->nbusy, v->busy[1] = b->nbusy;
    v->stolen[0] = n->nstolen, v->stolen[1] = b->nstolen;
    v->rows[0] = n->nrows, v->rows[1] = b->nrows;
}

void hx_cmp_reason(HxBuf *r, const CmpVerdict *v, const CmpRule *rule)
{
    if (v->kind == CMP_NOTE) {
        hx_buf_put(r, v->note ? v->note : "");
        return;
    }
    if (v->kind == CMP_SHORT) {
        hx_buf_printf(r, "time %.3f -> %.3f ms too short to judge (< %.3g ms)", v->raw_base, v->raw_new,
                      rule->min_ms);
        return;
    }
    int judged = strcmp(v->verdict, "REGRESSION") == 0 || strcmp(v->verdict, "IMPROVEMENT") == 0;
    char how[160];
    if (isfinite(v->p)) /* the test ran: 4 samples a side or more */
        snprintf(how, sizeof how, "Mann-Whitney p=%.4f, min ratio %.2f, n=%zu/%zu", v->p, v->min_ratio, v->n_new,
                 v->n_base);
    else
        snprintf(how, sizeof how, "min ratio %.2f, n=%zu/%zu (too few for a test)", v->min_ratio, v->n_new,
                 v->n_base);
    hx_buf_printf(r, "median %.3f -> %.3f%s%s, %s %.3f [%.3f, %.3f] (%s)%s", v->base_median, v->new_median,
                  *rule->unit ? " " : "", rule->unit, rule->higher ? "cost ratio (base/new)" : "ratio", v->ratio,
                  v->ci_lo, v->ci_hi, how, judged && rule->fp_differs ? " [different machines]" : "");
    if (v->busy[0] || v->busy[1] || v->stolen[0] || v->stolen[1]) /* the noise the rows recorded */
        hx_buf_printf(r, "; noisy rows: busy %zu/%zu new, %zu/%zu base; CPU steal %zu/%zu new, %zu/%zu base",
                      v->busy[0], v->rows[0], v->busy[1], v->rows[1], v->stolen[0], v->rows[0], v->stolen[1],
                      v->rows[1]);
    int none = strcmp(v->verdict, "no change") == 0;
    if (none && (v->ci_lo > 1.0 || v->ci_hi < 1.0))
        hx_buf_printf(r, "; a change of x%.2f, within the factor %.2f", v->ratio, rule->factor);
    const double f = rule->factor;
    const int beyond = v->ci_lo > f || v->ci_hi < 1.0 / f, tail = v->tail_ratio > f;
    if (!judged && !none && tail && v->ci_lo > 1.0 / f && v->ci_hi < f)
        hx_buf_printf(r, "; the medians agree, but the slowest tenth of NEW is x%.2f BASE's", v->tail_ratio);
    else if (!judged && !none && beyond && isfinite(v->p)) /* the interval is past the factor: the test held it back */
        hx_buf_printf(r, "; the interval lies %s x%.2f, but the rank test's p is not below %.3g",
                      v->ci_lo > f ? "above" : "below", v->ci_lo > f ? f : 1.0 / f, rule->alpha);
    else if (!judged && !none && beyond) /* too few for the test: the minimum decides */
        hx_buf_printf(r, "; the interval lies %s x%.2f, but the minimum ratio x%.2f does not",
                      v->ci_lo > f ? "above" : "below", v->ci_lo > f ? f : 1.0 / f, v->min_ratio);
    else if (!judged && !none && isfinite(v->mde))
        hx_buf_printf(r, "; at this noise only changes beyond x%.2f are detectable, about %ld repeats a side "
                         "would resolve x%.2f", v->mde, v->need, f);
    else if (!judged && !none)
        hx_buf_put(r, "; too few samples for an interval (3 a side at least)");
}

static void judge(const HxStudy *nw, const HxStudy *base, const HxGroup *b, const CmpRule *rule, CmpVerdicts *vs)
{
    const HxGroup *n = match(nw, base, b);
    if (!n) {
        push_verdict(vs, b, "REGRESSION", "missing from NEW", NULL);
        return;
    }
    vs->compared++;
    if (b->nt && !n->nt) {
        HxBuf r = {0};
        hx_buf_printf(&r, "no ok run in NEW (timeout %zu, wrong-image %zu, %s %zu)", n->ntimeout, n->nwrong,
                      n->first_status ? n->first_status : "other", n->nerror);
        push_verdict(vs, b, "REGRESSION", r.s, n);
        hx_buf_free(&r);
        return;
    }
    if (n->nwrong) {
        HxBuf r = {0};
        hx_buf_printf(&r, "%zu wrong-image run(s) in NEW", n->nwrong);
        push_verdict(vs, b, "REGRESSION", r.s, n);
        hx_buf_free(&r);
    }
    /* a run that timed out or failed is a slow or broken run, not a
     * missing sample: a larger share of them in NEW than in BASE is a
     * regression, whatever NEW's ok runs took */
    const size_t nf = n->ntimeout + n->nerror, bf = b->ntimeout + b->nerror;
    if (n->nt && nf * b->nrows > bf * n->nrows) {
        HxBuf r = {0};
        hx_buf_printf(&r, "%zu of %zu runs in NEW did not end ok (", nf, n->nrows);
        if (n->ntimeout)
            hx_buf_printf(&r, "timeout %zu%s", n->ntimeout, n->nerror ? ", " : "");
        if (n->nerror)
            hx_buf_printf(&r, "%s %zu", n->first_status ? n->first_status : "other", n->nerror);
        hx_buf_printf(&r, "), %zu of %zu in BASE", bf, b->nrows);
        push_verdict(vs, b, "REGRESSION", r.s, n);
        hx_buf_free(&r);
    }
    if (!b->nt)
        return;
    int changed = counters_changed(nw, base, n, b, vs);
    judge_time(n, b, rule, vs);
    (void)changed;
}

/* A group of bare samples, as judge_time reads one. */
static void sample_group(HxGroup *g, const char *label, double *x, size_t n)
{
    memset(g, 0, sizeof *g);
    g->scene = (char *)"-";
    g->label = (char *)label;
    g->t = x;
    g->nt = g->nrows = g->nok = n;
    g->median = n ? hx_median(x, n) : NAN;
    g->min = n ? hx_min(x, n) : NAN;
    g->raw_median = INFINITY; /* no --min-ms: the caller chose what to time */
}

int hx_judge_samples(const char *label, double *nw, size_t nn, double *base, size_t nb, double factor, double alpha,
                     int higher, const char *unit, const char **verdict)
{
    HxGroup gn, gb;
    sample_group(&gn, label, nw, nn);
    sample_group(&gb, label, base, nb);
    CmpRule rule = {factor, alpha, 0.0, unit, 0, higher};
    CmpVerdicts vs = {0};
    judge_time(&gn, &gb, &rule, &vs);
    *verdict = vs.v[0].verdict;
    HxBuf why = {0};
    hx_cmp_reason(&why, &vs.v[0], &rule);
    hx_put_clean_line(stdout, "%s %s: %s", vs.v[0].verdict, label, why.s);
    hx_buf_free(&why);
    int bad = vs.regressions > 0;
    verdicts_free(&vs);
    return bad;
}

/* --format json (schema: docs/harness-table.md, "JSON output") */
static void print_json(const CmpVerdicts *vs, const CmpRule *rule, const char *new_csv, const char *base_csv,
                       const char *metric)
{
    FILE *o = stdout;
    fputs("{\"schema\": \"raybench-compare/1\"", o);
    hx_json_kstr(o, "new", new_csv);
    hx_json_kstr(o, "base", base_csv);
    hx_json_kstr(o, "metric", metric);
    hx_json_num(o, "factor", rule->factor);
    hx_json_num(o, "alpha", rule->alpha);
    printf(", \"machines_differ\": %s, \"compared\": %d, \"regressions\": %d, \"improvements\": %d,"
           " \"inconclusive\": %d,\n \"verdicts\": [",
           rule->fp_differs ? "true" : "false", vs->compared, vs->regressions, vs->improvements, vs->inconclusive);
    for (size_t i = 0; i < vs->n; i++) {
        const CmpVerdict *v = &vs->v[i];
        fputs(i ? ",\n  {\"verdict\": " : "\n  {\"verdict\": ", o);
        hx_json_str(o, v->verdict);
        hx_json_kstr(o, "scene", v->scene);
        hx_json_kstr(o, "configuration", v->label);
        hx_json_num(o, "base_median", v->base_median);
        hx_json_num(o, "new_median", v->new_median);
        hx_json_num(o, "ratio", v->ratio);
        hx_json_num(o, "p", v->p);
        hx_json_num(o, "min_ratio", v->min_ratio);
        hx_json_pair(o, "ratio_ci95", v->ci_lo, v->ci_hi);
        hx_json_num(o, "detectable_ratio", v->mde);
        hx_json_num(o, "repeats_needed", v->need > 0 ? (double)v->need : NAN);
        hx_json_num(o, "tail_ratio", v->tail_ratio);
        hx_json_num(o, "n_base", (double)v->n_base);
        hx_json_num(o, "n_new", (double)v->n_new);
        HxBuf why = {0};
        hx_cmp_reason(&why, v, rule);
        hx_json_kstr(o, "reason", why.s);
        hx_buf_free(&why);
        fputc('}', o);
    }
    printf("]}\n");
}

/* --format text: a line per verdict (the names cleaned: a newline in a
 * scene would fake a line), then the counts. */
static void print_text(const CmpVerdicts *vs, const CmpRule *rule)
{
    for (size_t k = 0; k < vs->n; k++) {
        HxBuf why = {0};
        hx_cmp_reason(&why, &vs->v[k], rule);
        hx_put_clean_line(stdout, "%s %s %s: %s", vs->v[k].verdict, vs->v[k].scene, vs->v[k].label, why.s);
        hx_buf_free(&why);
    }
    printf("compare: %d configuration(s) compared, %d regression(s), %d improvement(s), %d inconclusive "
           "(factor %.2f, alpha %.3g)\n", vs->compared, vs->regressions, vs->improvements, vs->inconclusive,
           rule->factor, rule->alpha);
}

/* 1 when every ok row of the CSV carries calib_ms (raytrace --calibrate). */
static int has_calib(const HxCsv *csv)
{
    int ok = csv->nrows > 0;
    for (size_t r = 0; r < csv->nrows && ok; r++)
        if (strcmp(hx_csv_get(csv, r, "status"), "ok") == 0)
            ok = strstr(hx_csv_get(csv, r, "extra"), "calib_ms=") != NULL;
    return ok;
}

/* The widest spread of calib_ms (max/min) within one configuration of
 * csv; its configuration and range in where. */
static double calib_spread(const HxCsv *csv, char *where, size_t n)
{
    double worst = 1.0;
    for (size_t r = 0; r < csv->nrows; r++) {
        const char *id = hx_csv_get(csv, r, "run_id");
        size_t idn = strcspn(id, "#");
        double lo = INFINITY, hi = 0, c;
        char num[32];
        int first = 1; /* each configuration once, from its first row */
        for (size_t k = 0; k < r && first; k++)
            first = strncmp(hx_csv_get(csv, k, "run_id"), id, idn + 1) != 0;
        for (size_t k = r; k < csv->nrows && first; k++) {
            const char *other = hx_csv_get(csv, k, "run_id");
            if (strncmp(other, id, idn + 1) != 0 || strcmp(hx_csv_get(csv, k, "status"), "ok") != 0 ||
                !hx_kv_get(hx_csv_get(csv, k, "extra"), "calib_ms", num, sizeof num) || hx_parse_double(num, &c) ||
                !(c > 0))
                continue;
            lo = c < lo ? c : lo;
            hi = c > hi ? c : hi;
        }
        if (hi > 0 && hi / lo > worst) {
            worst = hi / lo;
            snprintf(where, n, "'%.*s' (%.1f-%.1f ms)", (int)(idn > 0 && id[idn - 1] == ' ' ? idn - 1 : idn), id,
                     lo, hi);
        }
    }
    return worst;
}

enum { FMT_TEXT, FMT_JSON, FMT_MD };

/* A note beside the verdicts: text prints it at once, md keeps it for the
 * end of its summary (its first line must be the verdict), JSON has none. */
static void say_note(int fmt, HxStrList *notes, const char *s)
{
    if (fmt == FMT_TEXT)
        hx_put_clean_line(stdout, "NOTE %s", s);
    else if (fmt == FMT_MD)
        hx_strlist_push(notes, s);
}

/* A time divided by the calibration only helps while the calibration
 * varies less than the change it should reveal. Refused (-1, one line)
 * when asked for; else replaced by the plain time with a note. */
static int calib_refused(HxStudy *nw, HxStudy *base, char **paths, double factor, int asked, int fmt,
                         HxStrList *notes, const char **metric)
{
    char where[2][512] = {"", ""};
    double spread[2] = {calib_spread(&nw->csv, where[0], sizeof where[0]),
                        calib_spread(&base->csv, where[1], sizeof where[1])};
    int k = spread[1] > spread[0];
    if (spread[k] <= factor)
        return 0;
    if (asked) {
        hx_put_clean_line(stderr, "harness compare: --metric %s refused: the calibration varies x%.1f within %s of "
                          "%s, more than the factor %.2f it should reveal; compare the plain time", *metric,
                          spread[k], where[k], paths[k], factor);
        return -1;
    }
    HxBuf b = {0};
    hx_buf_printf(&b, "render_ms/calib not used: the calibration varies x%.1f within %s of %s, more than the "
                  "factor %.2f; comparing render_ms", spread[k], where[k], paths[k], factor);
    say_note(fmt, notes, b.s);
    hx_buf_free(&b);
    *metric = "render_ms";
    return 0;
}

/* compare's options. */
typedef struct {
    double factor, alpha, min_ms;
    int fmt;
    const char *metric, *report;
} CompareOpts;

/* --format's value into o->fmt; 0, or -1 with one line said (the wording
 * of `table --format`). */
static int parse_format(const char *v, CompareOpts *o)
{
    static const char *const names[] = {"text", "json", "md"}; /* FMT_ order */
    for (int k = 0; k < 3; k++)
        if (strcmp(v, names[k]) == 0) {
            o->fmt = k;
            return 0;
        }
    hx_put_clean_line(stderr, "harness compare: --format: expected text, json or md, got '%s'", v);
    return -1;
}

/* Parses the options into o. -1: go on; else the exit status (--help 0,
 * a bad option 1). */
static int compare_opts(int argc, char **argv, CompareOpts *o)
{
    static const struct option lo[] = {
        {"factor", required_argument, NULL, 'f'}, {"alpha", required_argument, NULL, 'a'},
        {"metric", required_argument, NULL, 'm'}, {"min-ms", required_argument, NULL, 'n'},
        {"format", required_argument, NULL, 'F'}, {"report", required_argument, NULL, 'r'},
        {"help", no_argument, NULL, 'h'}, {NULL, 0, NULL, 0}};
    /* defaults from 20 reruns of unchanged code on the noisy 2-core machine
     * (docs/harness-verdicts.md, "False alarms"): calibrated times and 1.8 raised
     * none; plain render_ms at 1.5 raised 2 */
    *o = (CompareOpts){1.8, 0.05, 0.5, FMT_TEXT, NULL, NULL};
    int c;
    while ((c = getopt_long(argc, argv, "h", lo, NULL)) != -1) {
        switch (c) {
        case 'f':
            if (hx_parse_double(optarg, &o->factor) || o->factor <= 1.0) {
                fprintf(stderr, "harness compare: --factor: expected a number > 1, got '%s'\n", optarg);
                return 1;
            }
            break;
        case 'a':
            if (hx_parse_double(optarg, &o->alpha) || o->alpha <= 0 || o->alpha >= 1) {
                fprintf(stderr, "harness compare: --alpha: expected 0 < A < 1, got '%s'\n", optarg);
                return 1;
            }
            break;
        case 'n':
            if (hx_parse_double(optarg, &o->min_ms) || o->min_ms < 0) {
                fprintf(stderr, "harness compare: --min-ms: expected a number >= 0, got '%s'\n", optarg);
                return 1;
            }
            break;
        case 'm': o->metric = optarg; break;
        case 'F':
            if (parse_format(optarg, o) != 0)
                return 1;
            break;
        case 'r': o->report = optarg; break;
        case 'h': usage_compare(stdout); return 0;
        default: usage_compare(stderr); return 1;
        }
    }
    if (o->report && (o->fmt != FMT_MD || !*o->report)) {
        fprintf(stderr, "harness compare: --report: %s\n",
                *o->report ? "only with --format md (the link is in its summary)" : "expected a URL, got ''");
        return 1;
    }
    return -1;
}

/* Reads both CSVs (paths: NEW, BASE) and builds their studies on one
 * metric, whose default depends on what both hold. 0, or 1 with one line
 * said and nothing left to free. */
static int compare_load(char **paths, const CompareOpts *o, HxStudy *nw, HxStudy *base, HxStrList *notes)
{
    memset(nw, 0, sizeof *nw);
    memset(base, 0, sizeof *base);
    const char *metric = o->metric;
    char err[512];
    if (hx_csv_read(paths[0], &nw->csv, err, sizeof err) != 0) {
        fprintf(stderr, "harness compare: %s\n", err);
        return 1;
    }
    if (hx_csv_read(paths[1], &base->csv, err, sizeof err) != 0) {
        fprintf(stderr, "harness compare: %s\n", err);
        hx_csv_free(&nw->csv);
        return 1;
    }
    /* raytrace's rows (a command study's have no render_ms) */
    const int tn = hx_csv_has_values(&nw->csv, "render_ms"), tb = hx_csv_has_values(&base->csv, "render_ms");
    if (!metric && tn != tb)
        metric = "render_ms"; /* (one side without a time: every run of it failed, which judge says) */
    if (!metric && tn && tb) {
        /* calibrated times where both studies have them (--calibrate) */
        int calibrated = has_calib(&nw->csv) && has_calib(&base->csv);
        metric = calibrated ? "render_ms/calib" : "render_ms";
        if (!calibrated)
            say_note(o->fmt, notes, "times are not calibrated (run the studies with extra_args: --calibrate): on a "
                     "noisy machine expect a false alarm now and then (docs/harness-verdicts.md, \"False alarms\")");
    }
    if (metric && strstr(metric, "/calib") &&
        calib_refused(nw, base, paths, o->factor, o->metric != NULL, o->fmt, notes, &metric) != 0) {
        hx_csv_free(&nw->csv);
        hx_csv_free(&base->csv);
        return 1;
    }
    if (hx_study_build(paths[0], metric, nw, err, sizeof err) != 0) {
        fprintf(stderr, "harness compare: %s\n", err);
        hx_csv_free(&base->csv);
        return 1;
    }
    if (hx_study_build(paths[1], metric, base, err, sizeof err) != 0) {
        fprintf(stderr, "harness compare: %s\n", err);
        hx_study_free(nw);
        return 1;
    }
    /* one metric in one unit on both sides: 300 ms against 0.3 s is no slowdown */
    if (strcmp(nw->metric, base->metric) != 0 || strcmp(nw->unit, base->unit) != 0 || nw->higher != base->higher) {
        fprintf(stderr, "harness compare: NEW's metric %s [%s, %s is better] and BASE's %s [%s, %s] differ; "
                        "compare studies of one metric in one unit (--metric)\n", nw->metric, nw->unit,
                nw->higher ? "higher" : "lower", base->metric, base->unit, base->higher ? "higher" : "lower");
        hx_study_free(nw);
        hx_study_free(base);
        return 1;
    }
    return 0;
}

/* Whether the two studies ran on different machines (fingerprints); text
 * lists both sides' fingerprints, md keeps a note. */
static int machines_differ(const HxStudy *nw, const HxStudy *base, int fmt, HxStrList *notes)
{
    HxStrList fpn = {0}, fpb = {0};
    fingerprints(nw, &fpn);
    fingerprints(base, &fpb);
    int differ = fpn.n != fpb.n;
    for (size_t i = 0; i < fpn.n && !differ; i++)
        differ = hx_strlist_find(&fpb, fpn.v[i]) < 0;
    if (differ && fmt == FMT_TEXT) {
        printf("NOTE machine fingerprints differ: times below compare different machines\n");
        for (size_t i = 0; i < fpb.n; i++)
            hx_put_clean_line(stdout, "  base: %s", fpb.v[i]);
        for (size_t i = 0; i < fpn.n; i++)
            hx_put_clean_line(stdout, "  new:  %s", fpn.v[i]);
    } else if (differ && fmt == FMT_MD) {
        hx_strlist_push(notes, "machine fingerprints differ (CPU, cores, SMT, governor, compiler or GPU): the "
                        "times compare different machines");
    }
    hx_strlist_free(&fpn);
    hx_strlist_free(&fpb);
    return differ;
}

int hx_cmd_compare(int argc, char **argv)
{
    CompareOpts o;
    int orc = compare_opts(argc, argv, &o);
    if (orc >= 0)
        return orc;
    if (argc - optind != 2) {
        fprintf(stderr, "harness compare: expected NEW.csv BASE.csv (see --help)\n");
        return 1;
    }
    /* each CSV read once: the metric depends on what both hold */
    HxStudy nw, base;
    HxStrList notes = {0};
    if (compare_load(argv + optind, &o, &nw, &base, &notes) != 0) {
        hx_strlist_free(&notes);
        return 1;
    }
    int fp_differs = machines_differ(&nw, &base, o.fmt, &notes);
    /* nw.metric: a command study's default, its unit and direction */
    CmpRule rule = {o.factor, o.alpha, o.min_ms, nw.unit, fp_differs, nw.higher};
    CmpVerdicts v = {0};
    for (size_t i = 0; i < base.ng; i++)
        judge(&nw, &base, &base.g[i], &rule, &v);
    for (size_t k = 0; k < nw.ng; k++)
        if (!match(&base, &nw, &nw.g[k]))
            push_verdict(&v, &nw.g[k], "new", "not in the baseline (not compared)", NULL);
    if (o.fmt == FMT_JSON) {
        print_json(&v, &rule, argv[optind], argv[optind + 1], nw.metric);
    } else if (o.fmt == FMT_MD) {
        CmpMdInfo info = {&nw, &base, nw.metric, &notes, o.report};
        hx_cmp_print_md(stdout, &v, &rule, &info);
    } else {
        print_text(&v, &rule);
    }
    int regressions = v.regressions;
    verdicts_free(&v);
    hx_strlist_free(&notes);
    hx_study_free(&nw);
    hx_study_free(&base);
    return regressions ? 1 : 0;
}
