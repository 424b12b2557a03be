/* program.h: command studies, the harness running any program
 * (docs/harness.md, "Your own program"). Internal to the harness. */
#ifndef HX_PROGRAM_H
#define HX_PROGRAM_H

#include "run.h"

#include <regex.h>

typedef enum { HX_FROM_STDOUT, HX_FROM_STDERR, HX_FROM_FILE } HxFrom;

/* A regular expression over one of the run's outputs. */
typedef struct {
    char *pattern;
    regex_t re;
    int compiled;
    HxFrom from;
    char *file;          /* HX_FROM_FILE: a name in the run's folder */
    int line;
} HxMatch;

typedef struct {
    char *name;
    HxMatch m;
    char *unit;
    int higher;          /* 1: higher is better (rates), 0: lower (times, sizes) */
} HxMetric;

struct HxProgram {
    char *name;                  /* the `program` column */
    HxStrList command;           /* argv template */
    HxStrList version, setup;    /* argv, run once per study */
    HxStrList env;               /* NAME, template pairs */
    HxStrList inputs, templates; /* NAME, path template pairs */
    HxStrList tmpl;              /* every template, for the placeholder check */
    int *tmpl_line;              /* ... and its line */
    int keep;                    /* workdir: keep */
    HxMetric *metrics;
    int nmetrics;
    HxMatch *checks;
    int nchecks;
    int exit_code;
    char *confdir;               /* the config's folder, absolute */
    int key_line[8];             /* the line of each single-valued key */
};

/* Whether KEY ("command", "param n", "metric x", ...) belongs to command
 * studies. */
int hx_program_key(const char *key);
/* A NAME after param, env, input, template or metric: a word that is safe
 * in a placeholder, a file name and a CSV key (file: '.' and '-' too, as
 * input and template names take). */
int hx_program_good_name(const char *s, int file);
/* One `KEY: RAW` line of a command study (RAW unsplit). 0, or -1 with why. */
int hx_program_line(HxConfig *cfg, int lineno, const char *key, const char *raw, char *why, size_t n);
/* After the last line: placeholders, the program found, scopes resolved.
 * 0, or -1 with why and *line the line at fault. */
int hx_program_finish(HxConfig *cfg, int *line, char *why, size_t n);
void hx_program_free(HxConfig *cfg);

/* Words of s: split at blanks (and commas), '...' and "..." keep them.
 * 0 or -1. */
int hx_words(const char *s, int commas, HxStrList *out, char *why, size_t n);

/* The placeholders of one run. */
typedef struct {
    HxStrList k, v;
} HxVars;
/* rundir and workdir as given (the dry run's stand-ins, or real paths). */
void hx_vars_of_run(const HxConfig *cfg, const HxRun *r, const char *rundir, const char *workdir, HxVars *vars);
void hx_vars_free(HxVars *vars);
/* t with each {KEY} replaced; 0, or -1 with the unknown KEY in bad. */
int hx_subst(const char *t, const HxVars *vars, HxBuf *out, char *bad, size_t n);

/* The run's program and its environment appended to c. */
void hx_program_command(const HxConfig *cfg, const HxVars *vars, HxCommand *c);
/* Makes the run's folder with its inputs and templates. 0, or -1 with why. */
int hx_program_prepare(const HxConfig *cfg, const HxVars *vars, const char *rundir, char *why, size_t n);
/* Checks and metrics of a finished run: metric values appended to extra
 * ("name=value;..."). 0, or -1 with why (a check that failed, a metric not
 * found). */
int hx_program_collect(const HxConfig *cfg, const char *rundir, const HxBuf *out, const HxBuf *err, HxBuf *extra,
                       char *why, size_t n);
/* The number of re's last match in text (its first group, else all of
 * it), the text of it in num: 0, -1 no match, -2 not a number. */
int hx_match_number(const regex_t *re, const char *text, double *v, char *num, size_t n);
/* "name:unit:higher;..." of the metrics (the CSV's metric_info). */
char *hx_program_metric_info(const HxConfig *cfg);
/* The first line the version command prints, or "-". malloc'd. */
char *hx_program_version(const HxConfig *cfg);
/* Runs setup in workdir. 0, or -1 with why. */
int hx_program_setup(const HxConfig *cfg, const char *workdir, char *why, size_t n);
/* The direction of a unit: 1 higher is better, 0 lower, -1 none (must be
 * given), -2 not a unit. */
int hx_unit_direction(const char *unit);
/* Milliseconds in one of a time unit (ns us ms s min), 0 for any other. */
double hx_unit_ms(const char *unit);

/* ---- folders and verdicts (workdir.c) ---- */
/* rm -rf path, never following a link. */
void hx_rmtree(const char *path);
/* The study's folder: STUDY.runs beside the CSV (workdir: keep) or tmpdir's
 * work/. *workdir absolute, malloc'd. 0, or -1 with err. */
int hx_workdir_open(const HxConfig *cfg, const char *out_path, const char *tmpdir, char **workdir, char *err,
                    size_t n);
/* The folder of plan run index (not made; a leftover removed). */
char *hx_rundir(const char *workdir, size_t index);
/* The status of a finished (exited) run of a command study: exit status,
 * record line, cores seen, checks, metrics into vals; detail on failure. */
const char *hx_program_status(const HxConfig *cfg, const char *rundir, HxChildResult *res, char **vals,
                              char **detail);

#endif
