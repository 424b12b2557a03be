/* history.c: `harness history add|show|plot|check|publish`: performance
 * across commits, in SQLite.
 *
 * A study's CSV stays the per-study output; the database is the memory
 * across studies. Every CSV row becomes a run (its configuration, commit,
 * machine fingerprint, config hash and time) with its values, one per
 * column and per `extra` key (EAV, so new record keys need no migration):
 * history_db.c holds the schema and `add`; this file reads the series back
 * and checks them, history_plot.c names and plots them, and publish.c
 * draws them as HTML pages.
 * Commits are ordered by their commit time where the repository knows them,
 * else by when they were first measured. A series is one configuration on
 * one machine (fingerprint): numbers from different machines never meet.
 * The step rule of `check` is stated in docs/harness-history.md, "History". */
#include "history.h"

#if HAVE_SQLITE
#include <ctype.h>
#include <getopt.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define HX_HISTORY_DEFAULT_DB "results/history.db"

/* ---- show ----------------------------------------------------------------- */

static int history_show(sqlite3 *db, const char *dbpath)
{
    sqlite3_stmt *st = hx_db_prep(db, dbpath,
        "SELECT s.id, s.added_utc, s.name, COUNT(r.id), COUNT(DISTINCT r.git_commit),"
        " MIN(r.git_commit), MIN(r.host), MIN(r.fingerprint), s.source"
        " FROM studies s LEFT JOIN runs r ON r.study_id = s.id GROUP BY s.id ORDER BY s.id");
    if (!st)
        return 1;
    printf("%-4s %-20s %-12s %5s %-12s %-12s %-16s %s\n", "id", "added", "study", "runs", "commit",
           "host", "fingerprint", "source");
    int n = 0;
    while (sqlite3_step(st) == SQLITE_ROW) {
        const char *commit = (const char *)sqlite3_column_text(st, 5);
        char cbuf[32];
        if (sqlite3_column_int(st, 4) > 1)
            snprintf(cbuf, sizeof cbuf, "%d commits", sqlite3_column_int(st, 4));
        else
            snprintf(cbuf, sizeof cbuf, "%s", commit ? commit : "-");
        hx_put_clean_line(stdout, "%-4d %-20s %-12s %5d %-12s %-12s %-16s %s", sqlite3_column_int(st, 0),
               (const char *)sqlite3_column_text(st, 1), (const char *)sqlite3_column_text(st, 2),
               sqlite3_column_int(st, 3), cbuf, sqlite3_column_text(st, 6) ? (const char *)sqlite3_column_text(st, 6) : "-",
               sqlite3_column_text(st, 7) ? (const char *)sqlite3_column_text(st, 7) : "-",
               (const char *)sqlite3_column_text(st, 8));
        n++;
    }
    sqlite3_finalize(st);
    printf("%d stud%s in %s\n", n, n == 1 ? "y" : "ies", dbpath);
    return 0;
}

/* ---- series: a metric over commits ----------------------------------------- */

static void point_add(HxSeries *s, const char *sha, double v)
{
    if (s->np == 0 || strcmp(s->p[s->np - 1].sha, sha) != 0) {
        s->p = hx_xrealloc(s->p, (s->np + 1) * sizeof *s->p);
        memset(&s->p[s->np], 0, sizeof *s->p);
        s->p[s->np++].sha = hx_strdup(sha);
    }
    HxSeriesPoint *p = &s->p[s->np - 1];
    if (p->n == p->cap) {
        p->cap = p->cap ? 2 * p->cap : 8;
        p->x = hx_xrealloc(p->x, p->cap * sizeof *p->x);
    }
    p->x[p->n++] = v;
}

void hx_series_free(HxSeriesSet *ss)
{
    for (size_t i = 0; i < ss->n; i++) {
        for (size_t k = 0; k < ss->s[i].np; k++) {
            free(ss->s[i].p[k].sha);
            free(ss->s[i].p[k].x);
        }
        free(ss->s[i].p);
        free(ss->s[i].config);
        free(ss->s[i].fingerprint);
    }
    free(ss->s);
}

/* Filters: every "key=value" given must be a word of the configuration. */
static int config_matches(const char *config, const HxStrList *want)
{
    for (size_t i = 0; i < want->n; i++) {
        const char *p = config;
        size_t n = strlen(want->v[i]);
        int found = 0;
        while ((p = strstr(p, want->v[i])) != NULL && !found) {
            found = (p == config || p[-1] == ' ') && (p[n] == ' ' || p[n] == '\0');
            p += n;
        }
        if (!found)
            return 0;
    }
    return 1;
}

/* The metric's two keys: "COL" (den NULL) or "COL/calib" (den calib_ms). */
static int metric_keys(const char *metric, char *num, size_t n, const char **den)
{
    const char *slash = strchr(metric, '/');
    *den = NULL;
    if (!slash) {
        snprintf(num, n, "%s", metric);
        return 0;
    }
    if (strcmp(slash, "/calib") != 0 || (size_t)(slash - metric) >= n)
        return -1;
    snprintf(num, n, "%.*s", (int)(slash - metric), metric);
    *den = "calib_ms";
    return 0;
}

/* Commits in commit-time order, then first measured. */
int hx_series_load(sqlite3 *db, const char *dbpath, const char *metric, const HxStrList *want, HxSeriesSet *ss)
{
    char num[64];
    const char *den;
    if (hx_has_ctrl(metric)) { /* (it would break the message, and the plot's title) */
        fprintf(stderr, "harness history: the metric holds a control character (a newline?)\n");
        return -1;
    }
    if (metric_keys(metric, num, sizeof num, &den) != 0) {
        fprintf(stderr, "harness history: metric '%s': a column, a record key, or COLUMN/calib\n", metric);
        return -1;
    }
    sqlite3_stmt *st = hx_db_prep(db, dbpath,
        /* a series: one configuration on one machine under one set of
         * settings (config_hash: extra_args, a command study's command,
         * ...), so that different work never shares a line */
        "SELECT r.config_id, r.fingerprint || ' ' || COALESCE(r.config_hash, ''), r.git_commit, a.num, b.num"
        " FROM runs r"
        " JOIN vals a ON a.run_id = r.id AND a.key = ?1"
        " LEFT JOIN vals b ON b.run_id = r.id AND b.key = ?2"
        " LEFT JOIN commits c ON c.sha = r.git_commit"
        " JOIN (SELECT git_commit AS g, MIN(utc) AS first, MIN(id) AS first_id FROM runs GROUP BY git_commit) f"
        " ON f.g = r.git_commit"
        " WHERE r.status = 'ok' AND a.num IS NOT NULL"
        /* a commit git does not know goes where it was first measured,
         * among the others' commit times, not before them all */
        " ORDER BY r.config_id, r.fingerprint, r.config_hash,"
        " COALESCE(c.commit_time, CAST(strftime('%s', f.first) AS INTEGER), 0), f.first, f.first_id,"
        " r.git_commit, r.id");
    if (!st)
        return -1;
    sqlite3_bind_text(st, 1, num, -1, SQLITE_TRANSIENT);
    sqlite3_bind_text(st, 2, den ? den : "", -1, SQLITE_TRANSIENT);
    memset(ss, 0, sizeof *ss);
    while (sqlite3_step(st) == SQLITE_ROW) {
        const char *cfg = (const char *)sqlite3_column_text(st, 0);
        const char *fp = (const char *)sqlite3_column_text(st, 1);
        double v = sqlite3_column_double(st, 3);
        if (!cfg || !fp || !config_matches(cfg, want))
            continue;
        if (den) {
            double c = sqlite3_column_double(st, 4);
            if (sqlite3_column_type(st, 4) == SQLITE_NULL || !(c > 0.0))
                continue;
            v /= c;
        }
        HxSeries *s = ss->n ? &ss->s[ss->n - 1] : NULL;
        if (!s || strcmp(s->config, cfg) != 0 || strcmp(s->fingerprint, fp) != 0) {
            ss->s = hx_xrealloc(ss->s, (ss->n + 1) * sizeof *ss->s);
            s = &ss->s[ss->n++];
            memset(s, 0, sizeof *s);
            s->config = hx_strdup(cfg);
            s->fingerprint = hx_strdup(fp);
        }
        point_add(s, (const char *)sqlite3_column_text(st, 2), v);
    }
    sqlite3_finalize(st);
    return 0;
}

/* ---- check: where did a series step? ---------------------------------------- */

/* The values of points [a, b) pooled; their count. */
static size_t pool(const HxSeries *s, size_t a, size_t b, double **out)
{
    size_t n = 0;
    for (size_t k = a; k < b; k++)
        n += s->p[k].n;
    double *x = hx_xmalloc((n ? n : 1) * sizeof *x);
    n = 0;
    for (size_t k = a; k < b; k++)
        for (size_t i = 0; i < s->p[k].n; i++)
            x[n++] = s->p[k].x[i];
    *out = x;
    return n;
}

static int flat(const double *x, size_t n)
{
    for (size_t i = 1; i < n; i++)
        if (x[i] != x[0])
            return 0;
    return 1;
}

/* The evidence for a step at point k: p (0 when both windows are exact,
 * e.g. instruction counts) and the ratio of medians after/before. */
static void step_at(const HxSeries *s, size_t k, const HxStepRule *rule, double *p, double *ratio)
{
    size_t a = k > (size_t)rule->window ? k - (size_t)rule->window : 0;
    size_t b = k + (size_t)rule->window < s->np ? k + (size_t)rule->window : s->np;
    double *x, *y;
    size_t nx = pool(s, a, k, &x), ny = pool(s, k, b, &y);
    double mx = hx_median(x, nx), my = hx_median(y, ny);
    *ratio = mx > 0.0 ? my / mx : NAN;
    /* exact (an instruction count) only where each side shows it, two
     * equal values at least: one timing alone is not exact */
    *p = nx >= 2 && ny >= 2 && flat(x, nx) && flat(y, ny) ? 0.0 : hx_mann_whitney_p(x, nx, y, ny);
    free(x);
    free(y);
}

static int step_counts(double p, double ratio, const HxStepRule *rule)
{
    return isfinite(ratio) && p < rule->alpha && fabs(ratio - 1.0) > rule->threshold;
}

/* A series without a step: "no change" when its last window of commits
 * against the one before rules out a step of the threshold (the 95%
 * bootstrap interval of the ratio of medians inside 1 +- threshold), else
 * inconclusive. */
int hx_series_no_step(const HxSeries *s, const HxStepRule *rule, HxNoStep *v)
{
    size_t w = (size_t)rule->window, k = s->np > w ? s->np - w : s->np / 2;
    double *x, *y;
    size_t nx = pool(s, k > w ? k - w : 0, k, &x), ny = pool(s, k, s->np, &y);
    v->lo = v->hi = NAN;
    v->nlast = s->np - k;
    v->nbefore = k - (k > w ? k - w : 0);
    if (nx >= 3 && ny >= 3)
        hx_bootstrap_ci(x, nx, y, ny, &v->lo, &v->hi);
    free(x);
    free(y);
    v->no_change = v->lo > 1.0 - rule->threshold && v->hi < 1.0 + rule->threshold;
    return !v->no_change;
}

/* check's line for a series without a step: "no change", else
 * INCONCLUSIVE with the step the noise would let through. 1 when
 * inconclusive. */
static int no_step(const HxSeries *s, const HxStepRule *rule, const char *lab)
{
    HxNoStep v;
    if (!hx_series_no_step(s, rule, &v)) {
        hx_put_clean_line(stdout, "no change %s [%s]: last %zu commits against the %zu before: ratio in [%.3f, %.3f]",
                          lab, s->fingerprint, v.nlast, v.nbefore, v.lo, v.hi);
        return 0;
    }
    if (isnan(v.lo))
        hx_put_clean_line(stdout, "INCONCLUSIVE %s [%s]: %zu commit(s), too few samples to tell", lab, s->fingerprint,
                          s->np);
    else
        hx_put_clean_line(stdout, "INCONCLUSIVE %s [%s]: at this noise only steps beyond %.1f%% are detectable "
                          "(ratio of the last %zu commits to the %zu before in [%.3f, %.3f]); more repeats per commit "
                          "would resolve %.0f%%", lab, s->fingerprint, 100.0 * (sqrt(v.hi / v.lo) - 1.0), v.nlast,
                          v.nbefore, v.lo, v.hi, 100.0 * rule->threshold);
    return 1;
}

/* A step of series s at point k re-measured (cf: NULL, not asked): 1 for
 * a slowdown that counts (confirmed, exact values, or not asked), else 0. */
static int step_confirmed(const HxSeries *s, size_t k, int window, double p, int slower, const char *metric, int higher,
                          HxConfirm *cf, int *unconfirmed, size_t *last)
{
    if (!cf)
        return slower;
    if (p == 0.0) { /* exact values, e.g. instruction counts: no noise to rule out */
        printf("  CONFIRMED: exact values, the same at every run of each side\n");
        return slower;
    }
    char key[64];
    const char *den;
    metric_keys(metric, key, sizeof key, &den); /* render_ms/calib: render_ms, interleaved */
    const char *settings = strchr(s->fingerprint, ' ');
    const char **commits = hx_xmalloc(s->np * sizeof *commits);
    for (size_t i = 0; i < s->np; i++)
        commits[i] = s->p[i].sha;
    size_t w = (size_t)window, lo = k > w ? k - w : 0, hi = k + w - 1 < s->np ? k + w - 1 : s->np - 1;
    size_t at = 0;
    int r = hx_confirm_step(cf, s->config, settings ? settings + 1 : "", commits, lo, k, hi, key, higher, &at);
    free(commits);
    *unconfirmed += r == 0;
    if (r != 0 && at == *last) { /* two stored steps, one change: counted once */
        printf("  (the step confirmed above)\n");
        return 0;
    }
    if (r != 0)
        *last = at;
    return r == 1;
}

size_t hx_series_steps(const HxSeries *s, const HxStepRule *rule, HxStep **steps)
{
    size_t n = 0;
    HxStep best = {0, 2.0, 1.0};
    *steps = NULL;
    for (size_t k = 1; k <= s->np; k++) {
        double p = 2.0, r = NAN;
        if (k < s->np)
            step_at(s, k, rule, &p, &r);
        if (k < s->np && step_counts(p, r, rule)) {
            if (p < best.p || (p == best.p && fabs(log(r)) > fabs(log(best.ratio))))
                best = (HxStep){k, p, r};
            continue;
        }
        if (best.p > 1.0)
            continue;
        *steps = hx_xrealloc(*steps, (n + 1) * sizeof **steps);
        (*steps)[n++] = best;
        best.p = 2.0;
    }
    return n;
}

/* Reports the steps of one series; the count of slowdowns. */
static int check_series(const HxSeries *s, const HxStepRule *rule, const char *metric, int higher, int *unsure,
                        HxConfirm *cf, int *unconfirmed)
{
    int slow = 0;
    size_t last = (size_t)-1;
    char lab[512];
    hx_config_label(lab, sizeof lab, s->config);
    HxStep *st;
    size_t n = hx_series_steps(s, rule, &st);
    for (size_t i = 0; i < n; i++) {
        size_t k = st[i].k;
        hx_put_clean_line(stdout, "STEP %s [%s]: %s at commit %s (after %s): %+.1f%%, p=%.2g", lab, s->fingerprint,
                          metric, s->p[k].sha, s->p[k - 1].sha, 100.0 * (st[i].ratio - 1.0), st[i].p);
        int slower = higher ? st[i].ratio < 1.0 : st[i].ratio > 1.0; /* a rate's slowdown is a drop */
        slow += step_confirmed(s, k, rule->window, st[i].p, slower, metric, higher, cf, unconfirmed, &last);
    }
    if (!n)
        *unsure += no_step(s, rule, lab);
    free(st);
    return slow;
}

/* Whether metric is a rate (higher is better), as a command study's
 * metric_info declares it; times and counts are not. */
int hx_metric_higher(sqlite3 *db, const char *metric)
{
    sqlite3_stmt *st = NULL;
    int higher = 0;
    if (sqlite3_prepare_v2(db, "SELECT txt FROM vals WHERE key = 'metric_info' AND txt <> '' LIMIT 1", -1, &st,
                           NULL) == SQLITE_OK &&
        sqlite3_step(st) == SQLITE_ROW && sqlite3_column_text(st, 0)) {
        char decl[160];
        if (hx_kv_get_sep((const char *)sqlite3_column_text(st, 0), metric, ':', decl, sizeof decl))
            higher = strstr(decl, ":higher") != NULL;
    }
    sqlite3_finalize(st);
    return higher || strcmp(metric, "mrays_per_s") == 0;
}

/* ---- the command ------------------------------------------------------------ */

static void usage_history(FILE *f)
{
    fputs("usage: harness history add STUDY.csv... [--db DB] [--allow-dirty]\n"
          "       harness history show [--db DB]\n"
          "       harness history plot METRIC -o PREFIX [FILTERS] [--db DB]\n"
          "       harness history check [--metric METRIC] [FILTERS] [--window N] [--alpha A]\n"
          "                             [--threshold T] [--db DB]\n"
          "                             [--confirm CONFIG [--rounds N] [--builder B] [--build-dir D]]\n"
          "       harness history publish -o DIR [FILTERS] [--window N] [--alpha A] [--threshold T]\n"
          "                               [--db DB]\n"
          "Performance across commits, in SQLite (docs/harness-history.md, \"History\").\n"
          "  add      stores every row of each study CSV with its commit, machine fingerprint\n"
          "           and config hash; a CSV stored before is skipped; rows of a dirty tree\n"
          "           are refused unless --allow-dirty\n"
          "  show     the stored studies\n"
          "  plot     METRIC (a column, a record key such as instructions, or COLUMN/calib)\n"
          "           over commits, one line per\n"
          "           configuration and machine: PREFIX-history.png/.svg (gnuplot)\n"
          "  check    the commit where a series stepped: medians of the N commits before and\n"
          "           from it differ by more than T and Mann-Whitney p < A (exact values:\n"
          "           any change over T); exit 1 when a series got slower\n"
          "  publish  a static HTML dashboard in DIR (new, empty, or written before): index.html\n"
          "           and a page per metric, each series over commits with check's steps\n"
          "           (from the stored runs: not confirmed), self-contained, no script\n"
          "  --confirm CONFIG   re-measure each step: build both commits (B COMMIT DIR/COMMIT,\n"
          "                     default B scripts/build-commit.sh, D build-confirm) and run\n"
          "                     the step's configuration of CONFIG with both, interleaved over\n"
          "                     N rounds (default 10); exit 1 only for a confirmed slowdown\n"
          "  --db DB            the database (default " HX_HISTORY_DEFAULT_DB ")\n"
          "  --metric M         check's metric (default render_ms)\n"
          "  FILTERS            --scene S --backend B --accel A --resolution WxH --threads N\n"
          "                     --ranks N --block BXxBY: series whose configuration has them\n"
          "  --window N         commits on either side of a step (default 5)\n"
          "  --alpha A          significance (default 0.01)\n"
          "  --threshold T      relative change that counts (default 0.05)\n"
          "  -o, --output PATH  plot's path prefix; publish's folder\n", f);
}

typedef struct {
    const char *db, *metric, *prefix;
    int allow_dirty;
    HxStrList want;
    HxStepRule rule;
    HxConfirm confirm; /* confirm.config NULL: steps are not re-measured */
} HistOpts;

static int filter_opt(HistOpts *o, const char *key, const char *v)
{
    if (!*v || strchr(v, ' ') || hx_has_ctrl(v)) {
        fprintf(stderr, "harness history: --%s: expected one word, got '%s'\n", key, v);
        return -1;
    }
    char why[256];
    for (int d = 0; d < HX_NDIM; d++) /* a value a config could give (--threads 4, not x) */
        if (d != HX_DIM_SCENE && strcmp(hx_dim_col[d], key) == 0 && hx_dim_value_check(d, v, why, sizeof why)) {
            fprintf(stderr, "harness history: --%s: %s\n", key, why);
            return -1;
        }
    HxBuf b = {0};
    hx_buf_printf(&b, "%s=%s", key, v);
    hx_strlist_push(&o->want, b.s);
    hx_buf_free(&b);
    return 0;
}

static int history_number(const char *opt, const char *v, double lo, double hi, double *out)
{
    if (hx_parse_double(v, out) == 0 && *out >= lo && *out <= hi)
        return 0;
    fprintf(stderr, "harness history: --%s: expected a number in [%g, %g], got '%s'\n", opt, lo, hi, v);
    return -1;
}

static int parse_history_opts(int argc, char **argv, HistOpts *o)
{
    static const struct option lo[] = {
        {"db", required_argument, NULL, 'd'}, {"metric", required_argument, NULL, 'm'},
        {"output", required_argument, NULL, 'o'}, {"allow-dirty", no_argument, NULL, 'D'},
        {"window", required_argument, NULL, 'w'}, {"alpha", required_argument, NULL, 'a'},
        {"threshold", required_argument, NULL, 't'}, {"scene", required_argument, NULL, 1},
        {"backend", required_argument, NULL, 2}, {"accel", required_argument, NULL, 3},
        {"resolution", required_argument, NULL, 4}, {"threads", required_argument, NULL, 5},
        {"ranks", required_argument, NULL, 6}, {"block", required_argument, NULL, 7},
        {"confirm", required_argument, NULL, 'c'}, {"builder", required_argument, NULL, 'b'},
        {"build-dir", required_argument, NULL, 'B'}, {"rounds", required_argument, NULL, 'r'},
        {"help", no_argument, NULL, 'h'}, {NULL, 0, NULL, 0}};
    static const char *const fkey[] = {"", "scene", "backend", "accel", "resolution", "threads", "ranks", "block"};
    double w;
    int c;
    optind = 1;
    while ((c = getopt_long(argc, argv, "o:h", lo, NULL)) != -1) {
        int bad = 0;
        switch (c) {
        case 'd': o->db = optarg; break;
        case 'm': o->metric = optarg; break;
        case 'o': o->prefix = optarg; break;
        case 'D': o->allow_dirty = 1; break;
        case 'w': bad = history_number("window", optarg, 1, 1000, &w); o->rule.window = (int)w; break;
        case 'a': bad = history_number("alpha", optarg, 1e-12, 1, &o->rule.alpha); break;
        case 't': bad = history_number("threshold", optarg, 0, 100, &o->rule.threshold); break;
        case 'c': o->confirm.config = optarg; break;
        case 'b': o->confirm.builder = optarg; break;
        case 'B': o->confirm.dir = optarg; break;
        case 'r': bad = history_number("rounds", optarg, 4, 10000, &w); o->confirm.rule.rounds = (int)w; break;
        case 'h': usage_history(stdout); return 1;
        default:
            if (c >= 1 && c <= 7)
                bad = filter_opt(o, fkey[c], optarg);
            else {
                usage_history(stderr);
                return -1;
            }
        }
        if (bad)
            return -1;
    }
    return 0;
}

static int history_series_cmd(const char *sub, HistOpts *o, int argc, char **argv)
{
    int is_plot = strcmp(sub, "plot") == 0;
    if (is_plot && (optind != argc - 1 || !o->prefix)) {
        fprintf(stderr, "harness history plot: expected METRIC and -o PREFIX (see --help)\n");
        return 1;
    }
    if (!is_plot && optind != argc) {
        fprintf(stderr, "harness history check: unexpected argument '%s' (see --help)\n", argv[optind]);
        return 1;
    }
    const char *metric = is_plot ? argv[optind] : o->metric;
    sqlite3 *db;
    if (hx_db_open(o->db, 0, &db) != 0)
        return 1;
    HxSeriesSet ss;
    int rc = hx_series_load(db, o->db, metric, &o->want, &ss), higher = hx_metric_higher(db, metric);
    if (rc != 0) {
        sqlite3_close(db);
        return 1;
    }
    if (ss.n == 0) {
        fprintf(stderr, "harness history %s: no ok runs with '%s' match in %s\n", sub, metric, o->db);
        rc = 1;
    } else if (is_plot) {
        rc = hx_history_plot(db, o->db, &ss, metric, o->prefix); /* the machines named from db */
    }
    sqlite3_close(db);
    if (rc == 0 && !is_plot) {
        int slow = 0, unsure = 0, unconfirmed = 0;
        HxConfirm *cf = o->confirm.config ? &o->confirm : NULL;
        if (cf)
            cf->rule.factor = 1.0 + o->rule.threshold;
        for (size_t i = 0; i < ss.n; i++)
            slow += check_series(&ss.s[i], &o->rule, metric, higher, &unsure, cf, &unconfirmed);
        printf("history check: %zu series, %d %sslowdown step(s), %d inconclusive (window %d commits, p < %g, "
               "change > %g%%)\n", ss.n, slow, cf ? "confirmed " : "", unsure, o->rule.window, o->rule.alpha,
               100.0 * o->rule.threshold);
        if (cf)
            printf("history check: %d step(s) unconfirmed (not failing the check)\n", unconfirmed);
        rc = slow ? 1 : 0;
    }
    hx_series_free(&ss);
    return rc;
}

int hx_cmd_history(int argc, char **argv)
{
    if (argc < 2 || strcmp(argv[1], "-h") == 0 || strcmp(argv[1], "--help") == 0) {
        usage_history(argc < 2 ? stderr : stdout);
        return argc < 2 ? 1 : 0;
    }
    const char *sub = argv[1];
    HistOpts o = {.db = HX_HISTORY_DEFAULT_DB, .metric = "render_ms",
                  .rule = {.window = 5, .alpha = 0.01, .threshold = 0.05},
                  .confirm = {.builder = "scripts/build-commit.sh", .dir = "build-confirm",
                              .rule = {.rounds = 10, .factor = 1.05, .alpha = 0.01, .timeout_s = 600}}};
    int prc = parse_history_opts(argc - 1, argv + 1, &o);
    int rc = 1;
    argc--;
    argv++;
    if (prc > 0)
        rc = 0;
    else if (prc < 0)
        rc = 1;
    else if (strcmp(sub, "add") == 0 && optind < argc)
        rc = hx_history_add(o.db, argv + optind, argc - optind, o.allow_dirty);
    else if (strcmp(sub, "add") == 0)
        fprintf(stderr, "harness history add: expected STUDY.csv... (see --help)\n");
    else if (strcmp(sub, "show") == 0) {
        sqlite3 *db;
        if (hx_db_open(o.db, 0, &db) == 0) {
            rc = history_show(db, o.db);
            sqlite3_close(db);
        }
    } else if (strcmp(sub, "plot") == 0 || strcmp(sub, "check") == 0)
        rc = history_series_cmd(sub, &o, argc, argv);
    else if (strcmp(sub, "publish") == 0 && optind == argc && o.prefix)
        rc = hx_history_publish(o.db, o.prefix, &o.want, &o.rule);
    else if (strcmp(sub, "publish") == 0)
        fprintf(stderr, "harness history publish: expected -o DIR and no other argument (see --help)\n");
    else
        fprintf(stderr, "harness history: unknown command '%s' (add, show, plot, check, publish)\n", sub);
    hx_strlist_free(&o.want);
    hx_confirm_free(&o.confirm);
    return rc;
}

#else /* no SQLite in this build */

int hx_cmd_history(int argc, char **argv)
{
    return hx_history_add(NULL, argv, argc, 0); /* says there is no SQLite */
}
#endif
