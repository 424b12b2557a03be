/* history.c: `harness history add|show|plot|check`: performance across
 * commits, in SQLite.
 *
 * A study's CSV stays the per-study output; the database is the memory
 * across studies. Every CSV row becomes a run (its configuration, commit,
 * machine fingerprint, config hash and time) with its values, one per
 * column and per `extra` key (EAV, so new record keys need no migration).
 * Commits are ordered by their commit time where the repository knows them,
 * else by when they were first measured. A series is one configuration on
 * one machine (fingerprint): numbers from different machines never meet.
 * The step rule of `check` is stated in docs/harness.md, "History". */
#include "hx.h"

#include "config.h"

#if HAVE_SQLITE
#include <ctype.h>
#include <getopt.h>
#include <math.h>
#include <sqlite3.h>
#include <stdlib.h>
#include <string.h>

#define HX_HISTORY_DEFAULT_DB "results/history.db"

static const char *const schema =
    "PRAGMA foreign_keys = ON;"
    "CREATE TABLE IF NOT EXISTS studies(id INTEGER PRIMARY KEY, name TEXT, source TEXT,"
    " added_utc TEXT, content_hash TEXT UNIQUE, nrows INTEGER);"
    "CREATE TABLE IF NOT EXISTS commits(sha TEXT PRIMARY KEY, commit_time INTEGER);"
    "CREATE TABLE IF NOT EXISTS runs(id INTEGER PRIMARY KEY,"
    " study_id INTEGER NOT NULL REFERENCES studies(id), row_no INTEGER, config_id TEXT,"
    " git_commit TEXT, fingerprint TEXT, host TEXT, config_hash TEXT, utc TEXT, status TEXT);"
    "CREATE TABLE IF NOT EXISTS vals(run_id INTEGER NOT NULL REFERENCES runs(id), key TEXT,"
    " num REAL, txt TEXT, PRIMARY KEY(run_id, key)) WITHOUT ROWID;"
    "CREATE INDEX IF NOT EXISTS runs_series ON runs(config_id, fingerprint);";

static int db_open(const char *path, int create, sqlite3 **db)
{
    int flags = SQLITE_OPEN_READWRITE | (create ? SQLITE_OPEN_CREATE : 0);
    if (!create && !hx_file_exists(path)) {
        fprintf(stderr, "harness history: %s: no such database (harness history add creates it)\n", path);
        return -1;
    }
    char *msg = NULL;
    if (sqlite3_open_v2(path, db, flags, NULL) != SQLITE_OK ||
        sqlite3_busy_timeout(*db, 10000) != SQLITE_OK ||
        sqlite3_exec(*db, schema, NULL, NULL, &msg) != SQLITE_OK) {
        fprintf(stderr, "harness history: %s: %s\n", path, msg ? msg : sqlite3_errmsg(*db));
        sqlite3_free(msg);
        sqlite3_close(*db);
        return -1;
    }
    return 0;
}

static int db_exec(sqlite3 *db, const char *path, const char *sql)
{
    char *msg = NULL;
    if (sqlite3_exec(db, sql, NULL, NULL, &msg) == SQLITE_OK)
        return 0;
    fprintf(stderr, "harness history: %s: %s\n", path, msg ? msg : sqlite3_errmsg(db));
    sqlite3_free(msg);
    return -1;
}

static sqlite3_stmt *db_prep(sqlite3 *db, const char *path, const char *sql)
{
    sqlite3_stmt *st = NULL;
    if (sqlite3_prepare_v2(db, sql, -1, &st, NULL) != SQLITE_OK) {
        fprintf(stderr, "harness history: %s: %s\n", path, sqlite3_errmsg(db));
        return NULL;
    }
    return st;
}

/* ---- add ------------------------------------------------------------------ */

/* A commit as the CSV names it: hex digits, nothing else (then it may be
 * given to git; "-dirty" or "unknown" may not). */
static int clean_commit(const char *c)
{
    size_t n = strlen(c);
    if (n < 4 || n > 40)
        return 0;
    for (; *c; c++)
        if (!isxdigit((unsigned char)*c))
            return 0;
    return 1;
}

/* The commit's time from the repository the harness runs in, or 0. */
static long long commit_time(const char *sha)
{
    char spec[64], out[64];
    snprintf(spec, sizeof spec, "%s^{commit}", sha);
    char *argv[] = {"git", "show", "-s", "--format=%ct", spec, NULL};
    if (hx_run_argv(argv, NULL, out, sizeof out, 1) != 0)
        return 0;
    return atoll(out);
}

/* Stores one value: numeric where it parses as a number. */
static int put_val(sqlite3_stmt *st, sqlite3_int64 run, const char *key, const char *v)
{
    double d;
    sqlite3_reset(st);
    sqlite3_bind_int64(st, 1, run);
    sqlite3_bind_text(st, 2, key, -1, SQLITE_TRANSIENT);
    if (hx_parse_double(v, &d) == 0 && isfinite(d))
        sqlite3_bind_double(st, 3, d);
    else
        sqlite3_bind_null(st, 3);
    sqlite3_bind_text(st, 4, v, -1, SQLITE_TRANSIENT);
    return sqlite3_step(st) == SQLITE_DONE ? 0 : -1;
}

/* The row's columns, then each KEY=VALUE of its `extra` (k1=v1;k2=v2). */
static int put_row_vals(sqlite3_stmt *st, sqlite3_int64 run, const HxCsv *csv, size_t r)
{
    for (int c = 0; c < csv->ncol; c++) {
        const char *v = hx_csv_cell(csv, r, c);
        if (*v && strcmp(csv->cols[c], "extra") != 0 && put_val(st, run, csv->cols[c], v) != 0)
            return -1;
    }
    char *extra = hx_strdup(hx_csv_get(csv, r, "extra"));
    int rc = 0;
    for (char *save = NULL, *kv = strtok_r(extra, ";", &save); kv && rc == 0; kv = strtok_r(NULL, ";", &save)) {
        char *eq = strchr(kv, '=');
        if (eq && eq != kv) {
            *eq = '\0';
            if (hx_csv_col(csv, kv) < 0)
                rc = put_val(st, run, kv, eq + 1);
        }
    }
    free(extra);
    return rc;
}

/* The configuration of a row: its run_id without " #rN". */
static char *row_config(const HxCsv *csv, size_t r)
{
    const char *id = hx_csv_get(csv, r, "run_id");
    const char *h = strstr(id, " #r");
    return hx_strndup(id, h ? (size_t)(h - id) : strlen(id));
}

static int put_run(sqlite3 *db, sqlite3_stmt *run_st, sqlite3_stmt *val_st, sqlite3_int64 study,
                   const HxCsv *csv, size_t r)
{
    static const char *const cols[] = {"git_commit", "fingerprint", "host", "config_hash", "utc", "status"};
    char *config = row_config(csv, r);
    sqlite3_reset(run_st);
    sqlite3_bind_int64(run_st, 1, study);
    sqlite3_bind_int64(run_st, 2, (sqlite3_int64)r + 2); /* the CSV line */
    sqlite3_bind_text(run_st, 3, config, -1, SQLITE_TRANSIENT);
    for (int k = 0; k < 6; k++)
        sqlite3_bind_text(run_st, 4 + k, hx_csv_get(csv, r, cols[k]), -1, SQLITE_TRANSIENT);
    free(config);
    if (sqlite3_step(run_st) != SQLITE_DONE)
        return -1;
    return put_row_vals(val_st, sqlite3_last_insert_rowid(db), csv, r);
}

/* Every row's commit must be a clean one (unless allow_dirty); 0 or -1. */
static int check_commits(const char *path, const HxCsv *csv, int allow_dirty)
{
    static const char *const need[] = {"study", "run_id", "git_commit", "fingerprint", "utc", "status"};
    for (size_t k = 0; k < sizeof need / sizeof need[0]; k++)
        if (hx_csv_col(csv, need[k]) < 0) {
            fprintf(stderr, "harness history add: %s: no column '%s' (not a harness study CSV)\n", path, need[k]);
            return -1;
        }
    for (size_t r = 0; r < csv->nrows && !allow_dirty; r++) {
        const char *c = hx_csv_get(csv, r, "git_commit");
        if (!clean_commit(c)) {
            fprintf(stderr,
                    "harness history add: %s:%zu: commit '%s': the history keeps committed code only "
                    "(measure a clean tree, or --allow-dirty)\n", path, r + 2, c);
            return -1;
        }
    }
    return 0;
}

static int record_commits(sqlite3 *db, const char *dbpath, const HxCsv *csv)
{
    sqlite3_stmt *st = db_prep(db, dbpath, "INSERT OR IGNORE INTO commits(sha, commit_time) VALUES(?1, ?2)");
    if (!st)
        return -1;
    HxStrList seen = {0};
    int rc = 0;
    for (size_t r = 0; r < csv->nrows && rc == 0; r++) {
        const char *c = hx_csv_get(csv, r, "git_commit");
        if (hx_strlist_find(&seen, c) >= 0)
            continue;
        hx_strlist_push(&seen, c);
        long long t = clean_commit(c) ? commit_time(c) : 0;
        sqlite3_reset(st);
        sqlite3_bind_text(st, 1, c, -1, SQLITE_TRANSIENT);
        if (t > 0)
            sqlite3_bind_int64(st, 2, t);
        else
            sqlite3_bind_null(st, 2);
        rc = sqlite3_step(st) == SQLITE_DONE ? 0 : -1;
    }
    hx_strlist_free(&seen);
    sqlite3_finalize(st);
    return rc;
}

/* The study row; 1 when this very CSV is stored already (*id its study). */
static int put_study(sqlite3 *db, const char *dbpath, const char *path, const HxCsv *csv,
                     const char *hash, sqlite3_int64 *id)
{
    sqlite3_stmt *st = db_prep(db, dbpath, "SELECT id FROM studies WHERE content_hash = ?1");
    if (!st)
        return -1;
    sqlite3_bind_text(st, 1, hash, -1, SQLITE_TRANSIENT);
    if (sqlite3_step(st) == SQLITE_ROW) {
        *id = sqlite3_column_int64(st, 0);
        sqlite3_finalize(st);
        return 1;
    }
    sqlite3_finalize(st);
    st = db_prep(db, dbpath, "INSERT INTO studies(name, source, added_utc, content_hash, nrows) "
                             "VALUES(?1, ?2, ?3, ?4, ?5)");
    if (!st)
        return -1;
    char now[32];
    hx_utc_now(now, sizeof now);
    sqlite3_bind_text(st, 1, csv->nrows ? hx_csv_get(csv, 0, "study") : "", -1, SQLITE_TRANSIENT);
    sqlite3_bind_text(st, 2, path, -1, SQLITE_TRANSIENT);
    sqlite3_bind_text(st, 3, now, -1, SQLITE_TRANSIENT);
    sqlite3_bind_text(st, 4, hash, -1, SQLITE_TRANSIENT);
    sqlite3_bind_int64(st, 5, (sqlite3_int64)csv->nrows);
    int rc = sqlite3_step(st) == SQLITE_DONE ? 0 : -1;
    sqlite3_finalize(st);
    *id = sqlite3_last_insert_rowid(db);
    return rc;
}

/* One CSV into the database, in one transaction: all of it or nothing. */
static int add_one(sqlite3 *db, const char *dbpath, const char *path, int allow_dirty)
{
    HxBuf text = {0};
    HxCsv csv;
    char err[512] = "cannot read", hash[20];
    /* the hash of the text as read: the parse below takes it over */
    int bad = hx_csv_read_text(path, &text) != 0;
    hx_fnv1a_hex(text.s, hash);
    if (bad || hx_csv_parse_buf(&text, &csv, err, sizeof err) != 0) {
        fprintf(stderr, "harness history add: %s: %s\n", path, err);
        hx_buf_free(&text);
        return -1;
    }
    sqlite3_int64 study = 0;
    int rc = check_commits(path, &csv, allow_dirty);
    if (rc == 0)
        rc = db_exec(db, dbpath, "BEGIN IMMEDIATE");
    if (rc == 0 && (rc = put_study(db, dbpath, path, &csv, hash, &study)) == 1) {
        printf("%s: already stored as study %lld\n", path, (long long)study);
        hx_csv_free(&csv);
        return db_exec(db, dbpath, "ROLLBACK");
    }
    sqlite3_stmt *run_st = rc ? NULL : db_prep(db, dbpath,
        "INSERT INTO runs(study_id, row_no, config_id, git_commit, fingerprint, host, config_hash, utc, status)"
        " VALUES(?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9)");
    sqlite3_stmt *val_st = run_st ? db_prep(db, dbpath, "INSERT OR REPLACE INTO vals VALUES(?1, ?2, ?3, ?4)") : NULL;
    rc = val_st ? 0 : -1;
    for (size_t r = 0; r < csv.nrows && rc == 0; r++)
        rc = put_run(db, run_st, val_st, study, &csv, r);
    if (rc == 0)
        rc = record_commits(db, dbpath, &csv);
    sqlite3_finalize(run_st);
    sqlite3_finalize(val_st);
    if (rc == 0 && db_exec(db, dbpath, "COMMIT") == 0) {
        printf("%s: stored as study %lld (%zu runs)\n", path, (long long)study, csv.nrows);
    } else {
        if (rc != 0 && sqlite3_errcode(db) != SQLITE_OK && sqlite3_errcode(db) != SQLITE_DONE)
            fprintf(stderr, "harness history add: %s: %s\n", dbpath, sqlite3_errmsg(db));
        sqlite3_exec(db, "ROLLBACK", NULL, NULL, NULL);
        rc = -1;
    }
    hx_csv_free(&csv);
    return rc;
}

int hx_history_add(const char *dbpath, char **csvs, int n, int allow_dirty)
{
    sqlite3 *db;
    if (db_open(dbpath, 1, &db) != 0)
        return 1;
    int failed = 0;
    for (int i = 0; i < n; i++)
        failed |= add_one(db, dbpath, csvs[i], allow_dirty) != 0;
    sqlite3_close(db);
    return failed;
}

/* ---- show ----------------------------------------------------------------- */

static int history_show(sqlite3 *db, const char *dbpath)
{
    sqlite3_stmt *st = db_prep(db, dbpath,
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

typedef struct {
    char *sha;
    double *x;
    size_t n, cap;
} Point;

typedef struct {
    char *config, *fingerprint;
    Point *p; /* in commit order */
    size_t np;
} Series;

typedef struct {
    Series *s;
    size_t n;
} SeriesSet;

static void point_add(Series *s, const char *sha, double v)
{
    if (s->np == 0 || strcmp(s->p[s->np - 1].sha, sha) != 0) {
        s->p = hx_xrealloc(s->p, (s->np + 1) * sizeof *s->p);
        memset(&s->p[s->np], 0, sizeof *s->p);
        s->p[s->np++].sha = hx_strdup(sha);
    }
    Point *p = &s->p[s->np - 1];
    if (p->n == p->cap) {
        p->cap = p->cap ? 2 * p->cap : 8;
        p->x = hx_xrealloc(p->x, p->cap * sizeof *p->x);
    }
    p->x[p->n++] = v;
}

static void series_free(SeriesSet *ss)
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

/* The configuration without its unset values ("key=-"), for people. */
static void config_label(char *dst, size_t n, const char *config)
{
    size_t m = 0;
    const char *w = config;
    while (*w && m + 1 < n) {
        size_t len = strcspn(w, " ");
        int unset = len >= 2 && w[len - 1] == '-' && w[len - 2] == '=';
        if (!unset && len > 0) {
            m += (size_t)snprintf(dst + m, n - m, "%s%.*s", m ? " " : "", (int)len, w);
            m = m < n ? m : n - 1;
        }
        w += len + (w[len] == ' ');
    }
    dst[m] = '\0';
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

/* Every ok run's metric, by series and commit (commits in commit-time
 * order, then first measured). */
static int load_series(sqlite3 *db, const char *dbpath, const char *metric, const HxStrList *want,
                       SeriesSet *ss)
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
    sqlite3_stmt *st = db_prep(db, dbpath,
        "SELECT r.config_id, r.fingerprint, r.git_commit, a.num, b.num FROM runs r"
        " JOIN vals a ON a.run_id = r.id AND a.key = ?1"
        " LEFT JOIN vals b ON b.run_id = r.id AND b.key = ?2"
        " LEFT JOIN commits c ON c.sha = r.git_commit"
        " JOIN (SELECT git_commit AS g, MIN(utc) AS first FROM runs GROUP BY git_commit) f ON f.g = r.git_commit"
        " WHERE r.status = 'ok' AND a.num IS NOT NULL"
        " ORDER BY r.config_id, r.fingerprint, COALESCE(c.commit_time, 0), f.first, r.git_commit, r.id");
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
        Series *s = ss->n ? &ss->s[ss->n - 1] : NULL;
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

typedef struct {
    int window;       /* commits on either side */
    double alpha;     /* Mann-Whitney two-sided */
    double threshold; /* relative change of the median that counts */
} StepRule;

/* The values of points [a, b) pooled; their count. */
static size_t pool(const Series *s, size_t a, size_t b, double **out)
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
static void step_at(const Series *s, size_t k, const StepRule *rule, double *p, double *ratio)
{
    size_t a = k > (size_t)rule->window ? k - (size_t)rule->window : 0;
    size_t b = k + (size_t)rule->window < s->np ? k + (size_t)rule->window : s->np;
    double *x, *y;
    size_t nx = pool(s, a, k, &x), ny = pool(s, k, b, &y);
    double mx = hx_median(x, nx), my = hx_median(y, ny);
    *ratio = mx > 0.0 ? my / mx : NAN;
    *p = flat(x, nx) && flat(y, ny) ? 0.0 : hx_mann_whitney_p(x, nx, y, ny);
    free(x);
    free(y);
}

static int step_counts(double p, double ratio, const StepRule *rule)
{
    return isfinite(ratio) && p < rule->alpha && fabs(ratio - 1.0) > rule->threshold;
}

/* Reports the steps of one series (in each run of flagged commits, the one
 * with the smallest p, then the largest change); the count of slowdowns. */
static int check_series(const Series *s, const StepRule *rule, const char *metric)
{
    int slow = 0;
    size_t best = 0;
    char lab[512];
    config_label(lab, sizeof lab, s->config);
    double best_p = 2.0, best_r = 1.0;
    for (size_t k = 1; k <= s->np; k++) {
        double p = 2.0, r = NAN;
        if (k < s->np)
            step_at(s, k, rule, &p, &r);
        if (k < s->np && step_counts(p, r, rule)) {
            if (p < best_p || (p == best_p && fabs(log(r)) > fabs(log(best_r)))) {
                best = k;
                best_p = p;
                best_r = r;
            }
            continue;
        }
        if (best_p > 1.0)
            continue;
        hx_put_clean_line(stdout, "STEP %s [%s]: %s at commit %s (after %s): %+.1f%%, p=%.2g", lab, s->fingerprint,
               metric, s->p[best].sha, s->p[best - 1].sha, 100.0 * (best_r - 1.0), best_p);
        slow += best_r > 1.0;
        best_p = 2.0;
    }
    return slow;
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
static void commit_order(const SeriesSet *ss, HxStrList *order)
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

static void write_history_dat(FILE *dat, const SeriesSet *ss, const HxStrList *order)
{
    fprintf(dat, "# x median min max commit (one block per series: configuration [machine])\n");
    for (size_t i = 0; i < ss->n; i++) {
        char cfg[400], raw[512], lab[512];
        config_label(cfg, sizeof cfg, ss->s[i].config);
        snprintf(raw, sizeof raw, "%s [%.8s]", cfg, ss->s[i].fingerprint);
        hx_plot_clean_label(lab, sizeof lab, raw);
        fprintf(dat, "\"%s\"\n", lab);
        for (size_t k = 0; k < ss->s[i].np; k++) {
            const Point *p = &ss->s[i].p[k];
            fprintf(dat, "%d %.6g %.6g %.6g %s\n", hx_strlist_find(order, p->sha), hx_median(p->x, p->n),
                    hx_min(p->x, p->n), max_of(p->x, p->n), p->sha);
        }
        fprintf(dat, "\n\n");
    }
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

static int history_plot(const SeriesSet *ss, const char *metric, const char *prefix)
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
    commit_order(ss, &order);
    write_history_dat(dat, ss, &order);
    HxBuf t = {0};
    hx_buf_printf(&t, "%s over commits (median, bars: min to max)", metric);
    hx_plot_head(gp, &c, "history", t.s);
    hx_buf_free(&t);
    gp_xtics(gp, &order);
    hx_plot_put(gp, "set ylabel %s\nset key below\nset offsets 0.3, 0.3, 0, 0\n", metric);
    fprintf(gp, "plot for [i=0:%zu] ", ss->n - 1);
    hx_plot_file(gp, "%s index i using 1:2:3:4 with yerrorlines title columnheader(1)\n", c.base, "history", "dat");
    hx_plot_tail(gp, &c, "history");
    hx_plot_finish(&c, "history", gp, dat);
    hx_strlist_free(&order);
    int rc = c.failures ? 1 : 0;
    hx_plot_done(&c);
    return rc;
}

/* ---- the command ------------------------------------------------------------ */

static void usage_history(FILE *f)
{
    fputs("usage: harness history add STUDY.csv... [--db DB] [--allow-dirty]\n"
          "       harness history show [--db DB]\n"
          "       harness history plot METRIC -o PREFIX [FILTERS] [--db DB]\n"
          "       harness history check [--metric METRIC] [FILTERS] [--window N] [--alpha A]\n"
          "                             [--threshold T] [--db DB]\n"
          "Performance across commits, in SQLite (docs/harness.md, \"History\").\n"
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
          "  --db DB            the database (default " HX_HISTORY_DEFAULT_DB ")\n"
          "  --metric M         check's metric (default render_ms)\n"
          "  FILTERS            --scene S --backend B --accel A --resolution WxH --threads N\n"
          "                     --ranks N --block BXxBY: series whose configuration has them\n"
          "  --window N         commits on either side of a step (default 5)\n"
          "  --alpha A          significance (default 0.01)\n"
          "  --threshold T      relative change that counts (default 0.05)\n"
          "  -o, --output PFX   plot's path prefix\n", f);
}

typedef struct {
    const char *db, *metric, *prefix;
    int allow_dirty;
    HxStrList want;
    StepRule rule;
} HistOpts;

static int filter_opt(HistOpts *o, const char *key, const char *v)
{
    if (!*v || strchr(v, ' ') || hx_has_ctrl(v)) {
        fprintf(stderr, "harness history: --%s: expected one word, got '%s'\n", key, v);
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
    if (db_open(o->db, 0, &db) != 0)
        return 1;
    SeriesSet ss;
    int rc = load_series(db, o->db, metric, &o->want, &ss);
    sqlite3_close(db);
    if (rc != 0)
        return 1;
    if (ss.n == 0) {
        fprintf(stderr, "harness history %s: no ok runs with '%s' match in %s\n", sub, metric, o->db);
        series_free(&ss);
        return 1;
    }
    if (is_plot) {
        rc = history_plot(&ss, metric, o->prefix);
    } else {
        int slow = 0;
        for (size_t i = 0; i < ss.n; i++)
            slow += check_series(&ss.s[i], &o->rule, metric);
        printf("history check: %zu series, %d slowdown step(s) (window %d commits, p < %g, change > %g%%)\n",
               ss.n, slow, o->rule.window, o->rule.alpha, 100.0 * o->rule.threshold);
        rc = slow ? 1 : 0;
    }
    series_free(&ss);
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
                  .rule = {.window = 5, .alpha = 0.01, .threshold = 0.05}};
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
        if (db_open(o.db, 0, &db) == 0) {
            rc = history_show(db, o.db);
            sqlite3_close(db);
        }
    } else if (strcmp(sub, "plot") == 0 || strcmp(sub, "check") == 0)
        rc = history_series_cmd(sub, &o, argc, argv);
    else
        fprintf(stderr, "harness history: unknown command '%s' (add, show, plot, check)\n", sub);
    hx_strlist_free(&o.want);
    return rc;
}

#else /* no SQLite in this build */

int hx_history_add(const char *db, char **csvs, int n, int allow_dirty)
{
    (void)db; (void)csvs; (void)n; (void)allow_dirty;
    fprintf(stderr, "harness history: this build has no SQLite (install libsqlite3-dev and reconfigure)\n");
    return 1;
}

int hx_cmd_history(int argc, char **argv)
{
    return hx_history_add(NULL, argv, argc, 0);
}
#endif
