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
