/* history.h: the history database's helpers shared by history_db.c (schema,
 * open, `add`) and history.c (show, plot, check), internal to the harness. */
#ifndef HX_HISTORY_H
#define HX_HISTORY_H

#include "hx.h"
#include "run.h"

#include "config.h"

#if HAVE_SQLITE
#include <sqlite3.h>

/* Opens the database at path (create: make it if missing) and applies the
 * schema; 0, or -1 with the reason on stderr. */
int hx_db_open(const char *path, int create, sqlite3 **db);
/* Runs sql; 0, or -1 with the reason on stderr. */
int hx_db_exec(sqlite3 *db, const char *path, const char *sql);
/* A prepared statement, or NULL with the reason on stderr. */
sqlite3_stmt *hx_db_prep(sqlite3 *db, const char *path, const char *sql);
#endif

/* ---- series: a metric over commits (history.c), for plot, check and publish ---- */
typedef struct {
    char *sha;
    double *x; /* the values of this commit's ok runs */
    size_t n, cap;
} HxSeriesPoint;

/* One configuration on one machine under one set of settings. */
typedef struct {
    char *config;      /* config_id */
    char *fingerprint; /* "MACHINE-FINGERPRINT CONFIG-HASH" */
    HxSeriesPoint *p;  /* in commit order */
    size_t np;
} HxSeries;

typedef struct {
    HxSeries *s;
    size_t n;
} HxSeriesSet;

/* check's step rule (docs/harness-history.md, "History"). */
typedef struct {
    int window;       /* commits on either side */
    double alpha;     /* Mann-Whitney two-sided */
    double threshold; /* relative change of the median that counts */
} HxStepRule;

/* A step at point k of a series: p (0: both windows exact) and the ratio
 * of the medians after/before. */
typedef struct {
    size_t k;
    double p, ratio;
} HxStep;

/* A series without a step: its last window against the one before. */
typedef struct {
    int no_change;        /* 1: a step of the threshold is ruled out */
    double lo, hi;        /* 95% interval of the ratio (NaN: too few samples) */
    size_t nlast, nbefore; /* commits in the two windows */
} HxNoStep;

void hx_series_free(HxSeriesSet *ss);
/* The commits of the series in history order (a commit missing from one
 * series keeps its place from the others). */
void hx_series_commit_order(const HxSeriesSet *ss, HxStrList *order);
/* The steps of a series by the rule: of each run of consecutive flagged
 * commits, the one with the smallest p, then the largest change. Their
 * count; *steps malloc'd (NULL when none). */
size_t hx_series_steps(const HxSeries *s, const HxStepRule *rule, HxStep **steps);
/* The verdict on a series without a step, in *v; 1 when inconclusive. */
int hx_series_no_step(const HxSeries *s, const HxStepRule *rule, HxNoStep *v);
/* The machine part of a series' fingerprint ("MACHINE SETTINGS"), malloc'd. */
char *hx_series_machine(const HxSeries *s);
/* Each series' legend (malloc'd into legend[i]): the settings in which the
 * series differ ("openmp, T=2"); the settings they all share go to common. */
void hx_series_legends(const HxSeries *const *s, size_t n, char **legend, HxBuf *common);

#if HAVE_SQLITE
/* A machine (its fingerprint) in words: CPU, cores, GPU into name; host,
 * compiler, governor, GPU driver into detail (NULL: not wanted). */
void hx_machine_words(sqlite3 *db, const char *dbpath, const char *fp, HxBuf *name, HxBuf *detail);
/* `history plot`: PREFIX-history.png/.svg of the series; 0, or 1 (said). */
int hx_history_plot(sqlite3 *db, const char *dbpath, const HxSeriesSet *ss, const char *metric,
                    const char *prefix);
/* Every ok run's metric (a column, a record key or COLUMN/calib) by series
 * and commit, commits in history order; want: "key=value" words each
 * configuration must have. 0, or -1 with one line on stderr. */
int hx_series_load(sqlite3 *db, const char *dbpath, const char *metric, const HxStrList *want, HxSeriesSet *ss);
/* Whether metric is a rate (higher is better). */
int hx_metric_higher(sqlite3 *db, const char *metric);
/* `history publish`: the static dashboard of the database in dir
 * (publish.c). 0, or 1 with one line on stderr. */
int hx_history_publish(const char *dbpath, const char *dir, const HxStrList *want, const HxStepRule *rule);
#endif

/* ---- a step re-measured before it counts (confirm.c) ---- */
typedef struct HxConfirm {
    const char *config;  /* the study config whose configurations the series are */
    const char *builder; /* BUILDER COMMIT DIR prints the raytrace built of COMMIT */
    const char *dir;     /* builds go to DIR/COMMIT */
    HxAbRule rule;
    HxStrList built, failed;
    char hash[20]; /* config's settings hash, read at the first step ("": not yet) */
} HxConfirm;
/* A step of configuration config_id (settings: the series' config_hash)
 * found at commits[k], its windows commits[lo..hi], in record key key,
 * re-measured: the ends of the windows built and run interleaved, and a
 * change there bisected to its commit. Lines "  re-measuring ...", then
 * "  CONFIRMED: ..." or "  unconfirmed: WHY" on stdout. 1 for a confirmed
 * slowdown (worse by the metric's direction), 2 for a confirmed
 * improvement (*at: the index of its commit, or of the last commit of the
 * range where bisection stopped), 0 unconfirmed. */
int hx_confirm_step(HxConfirm *c, const char *config_id, const char *settings, const char *const *commits, size_t lo,
                    size_t k, size_t hi, const char *key, int higher, size_t *at);
void hx_confirm_free(HxConfirm *c);

#endif
