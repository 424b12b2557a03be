/* history.h: the history database's helpers shared by history_db.c (schema,
 * open, `add`) and history.c (show, plot, check), internal to the harness. */
#ifndef HX_HISTORY_H
#define HX_HISTORY_H

#include "hx.h"

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

#endif
