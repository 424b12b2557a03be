/* history_db.c: the history database (docs/harness-history.md, "History"): its
 * schema, opening it, and `harness history add`, which stores study CSVs.
 *
 * Every CSV row becomes a run (its configuration, commit, machine
 * fingerprint, config hash and time) with its values, one per column and per
 * `extra` key (EAV, so new record keys need no migration). Only a clean
 * tree's rows go in, unless asked. history.c reads the database back. */
#include "history.h"

#if HAVE_SQLITE
#include <ctype.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

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

int hx_db_open(const char *path, int create, sqlite3 **db)
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

int hx_db_exec(sqlite3 *db, const char *path, const char *sql)
{
    char *msg = NULL;
    if (sqlite3_exec(db, sql, NULL, NULL, &msg) == SQLITE_OK)
        return 0;
    fprintf(stderr, "harness history: %s: %s\n", path, msg ? msg : sqlite3_errmsg(db));
    sqlite3_free(msg);
    return -1;
}

sqlite3_stmt *hx_db_prep(sqlite3 *db, const char *path, const char *sql)
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
    const char *h = strstr(id, " #r"), *prog = hx_csv_get(csv, r, "program");
    HxBuf b = {0};
    /* a command study's runs are its program's: another program's with
     * the same params is another series */
    if (*prog && strcmp(prog, "raytrace") != 0)
        hx_buf_printf(&b, "program=%s ", prog);
    hx_buf_putn(&b, id, h ? (size_t)(h - id) : strlen(id));
    const char *ver = hx_csv_get(csv, r, "program_version");
    if (*ver && strcmp(ver, "-") != 0) /* another version of the program is other work */
        hx_buf_printf(&b, " version=%s", ver);
    return b.s;
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
    sqlite3_stmt *st = hx_db_prep(db, dbpath, "INSERT INTO commits(sha, commit_time) VALUES(?1, ?2) ON CONFLICT(sha) DO UPDATE"
        /* (a commit unknown when first added gets its time once git has it) */
        " SET commit_time = COALESCE(commit_time, excluded.commit_time)");
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
    sqlite3_stmt *st = hx_db_prep(db, dbpath, "SELECT id FROM studies WHERE content_hash = ?1");
    if (!st)
        return -1;
    sqlite3_bind_text(st, 1, hash, -1, SQLITE_TRANSIENT);
    if (sqlite3_step(st) == SQLITE_ROW) {
        *id = sqlite3_column_int64(st, 0);
        sqlite3_finalize(st);
        return 1;
    }
    sqlite3_finalize(st);
    st = hx_db_prep(db, dbpath, "INSERT INTO studies(name, source, added_utc, content_hash, nrows) "
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
        rc = hx_db_exec(db, dbpath, "BEGIN IMMEDIATE");
    if (rc == 0 && (rc = put_study(db, dbpath, path, &csv, hash, &study)) == 1) {
        printf("%s: already stored as study %lld\n", path, (long long)study);
        hx_csv_free(&csv);
        return hx_db_exec(db, dbpath, "ROLLBACK");
    }
    sqlite3_stmt *run_st = rc ? NULL : hx_db_prep(db, dbpath,
        "INSERT INTO runs(study_id, row_no, config_id, git_commit, fingerprint, host, config_hash, utc, status)"
        " VALUES(?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9)");
    sqlite3_stmt *val_st = run_st ? hx_db_prep(db, dbpath, "INSERT OR REPLACE INTO vals VALUES(?1, ?2, ?3, ?4)") : NULL;
    rc = val_st ? 0 : -1;
    for (size_t r = 0; r < csv.nrows && rc == 0; r++)
        rc = put_run(db, run_st, val_st, study, &csv, r);
    if (rc == 0)
        rc = record_commits(db, dbpath, &csv);
    sqlite3_finalize(run_st);
    sqlite3_finalize(val_st);
    if (rc == 0 && hx_db_exec(db, dbpath, "COMMIT") == 0) {
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
    if (hx_db_open(dbpath, 1, &db) != 0)
        return 1;
    int failed = 0;
    for (int i = 0; i < n; i++)
        failed |= add_one(db, dbpath, csvs[i], allow_dirty) != 0;
    sqlite3_close(db);
    return failed;
}

#else /* no SQLite in this build */

int hx_history_add(const char *db, char **csvs, int n, int allow_dirty)
{
    (void)db; (void)csvs; (void)n; (void)allow_dirty;
    fprintf(stderr, "harness history: this build has no SQLite (install libsqlite3-dev and reconfigure)\n");
    return 1;
}
#endif
