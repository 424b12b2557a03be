/* hx.h: shared types and entry points of the raybench harness.
 *
 * Data flows one way: config file -> run matrix (config.c) -> pinned child
 * runs (runner.c, launch.c, proc.c, topo.c) -> CSV rows (csv.c) ->
 * statistics (stats.c) -> the study model (study.c) -> tables (table.c),
 * plots (plot.c) and the regression check (compare.c).
 * The harness never links the renderer: it runs `raytrace` as a child and
 * parses its `record:` line, so it keeps working across renderer changes. */
#ifndef HX_H
#define HX_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

/* ---- small containers (util.c) ---- */
typedef struct {
    char **v;      /* owned strings */
    size_t n, cap;
} HxStrList;

typedef struct {
    char *s;       /* always NUL-terminated once anything was appended */
    size_t len, cap;
} HxBuf;

void hx_strlist_push(HxStrList *l, const char *s);
/* A value listed twice in l (one of them), else NULL. */
const char *hx_strlist_twice(const HxStrList *l);
void hx_strlist_free(HxStrList *l);
int hx_strlist_find(const HxStrList *l, const char *s); /* index or -1 */
void hx_buf_put(HxBuf *b, const char *s);
void hx_buf_putn(HxBuf *b, const char *s, size_t n);
void hx_buf_printf(HxBuf *b, const char *fmt, ...)
    __attribute__((format(printf, 2, 3)));
void hx_buf_free(HxBuf *b);
char *hx_strdup(const char *s);
/* LABEL without its " KEY=VALUE" word (a series' sweep, a plot's axis:
 * what is left names the line), malloc'd. */
char *hx_label_drop(const char *label, const char *key);
char *hx_strndup(const char *s, size_t n);
void *hx_xmalloc(size_t n);
void *hx_xrealloc(void *p, size_t n);
char *hx_trim(char *s);                 /* in place, returns s moved */
int hx_parse_int(const char *s, long lo, long hi, long *out);
int hx_parse_double(const char *s, double *out);
int hx_parse_wxh(const char *s, long *w, long *h);
double hx_now_ms(void);                 /* CLOCK_MONOTONIC */
int hx_file_exists(const char *path);
/* Reads a whole file (or pipe) into b (NUL-terminated); -1 with errno set on
 * failure: EISDIR, EINVAL for a device, EFBIG past HX_READ_MAX bytes. */
#define HX_READ_MAX ((size_t)1 << 30)
int hx_read_file(const char *path, HxBuf *b);
/* hx_read_file's errno in words ("not a regular file" for a device). */
const char *hx_read_error(int e);
int hx_is_dir(const char *path);
/* Whether a command may write path over: missing, empty, or a regular file
 * that starts with own (what that command writes there). 0, or -1 with one
 * line said, who first: -o must not take a results CSV for its own. */
int hx_may_replace(const char *who, const char *path, const char *own);
/* The program name runs: a path (with a '/') if executable, else the first
 * executable NAME on PATH; resolved (realpath), malloc'd, or NULL. */
char *hx_which(const char *name);
char *hx_dirname(const char *path);     /* malloc'd */
char *hx_path_join(const char *a, const char *b);
/* A new private folder $TMPDIR/harness-NAME-XXXXXX ($TMPDIR, else /tmp),
 * malloc'd; NULL with why in err. */
char *hx_temp_dir(const char *name, char *err, size_t n);
int hx_cmp_double(const void *a, const void *b);
/* Runs argv[0] (found on PATH) with argv, never through a shell, in folder
 * dir (NULL: here). Its stdout goes to out, cut at n - 1 bytes (out may be
 * NULL: stdout discarded); quiet discards its stderr. Returns its exit status, 127
 * when it could not be started, 128+N when killed by signal N. */
int hx_run_argv(char *const argv[], const char *dir, char *out, size_t n, int quiet);
/* The value of key in "k1=v1;k2=v2" (sep '=') copied into out, which is
 * returned; NULL when the key is not there. */
const char *hx_kv_get(const char *list, const char *key, char *out, size_t n);
/* A config_id without its unset values ("key=-"), for people. */
void hx_config_label(char *dst, size_t n, const char *config);
const char *hx_kv_get_sep(const char *list, const char *key, char sep, char *out, size_t n);
/* Appends s to b as a gnuplot single-quoted string: gnuplot does no
 * substitution there (no backquote command, no @macro), ' is doubled, and
 * control characters (a newline would end the command) become '?'. */
void hx_gp_quote(HxBuf *b, const char *s);
/* JSON output: a string with its escapes; `, "key": number` (null for
 * NaN or infinity), `, "key": [a, b]`, `, "key": "string"`. */
void hx_json_str(FILE *o, const char *v);
void hx_json_num(FILE *o, const char *key, double v);
void hx_json_pair(FILE *o, const char *key, double a, double b);
void hx_json_kstr(FILE *o, const char *key, const char *v);
/* FNV-1a (64 bits) of s as 16 hex digits: the machine fingerprint, the
 * config hash. */
void hx_fnv1a_hex(const char *s, char out[20]);
/* A control character: below 0x20, or 0x7f. */
static inline int hx_is_ctrl(unsigned char c)
{
    return c < 0x20 || c == 0x7f;
}
/* Text from a CSV or a database on a terminal: each control character (a
 * terminal escape, a newline that would fake a line) as '?', and with md
 * a '|' as "\|", so that a Markdown table cell does not end early. */
void hx_fput_clean(FILE *o, const char *s, int md);
/* The first line of s that is not blank (a child's stderr: what went
 * wrong), its length in *n (0: none). */
const char *hx_first_line(const char *s, int *n);
/* Text from a CSV into an HTML page: & < > " ' as entities, control
 * characters as blanks: never markup. */
void hx_html_put(FILE *o, const char *s);
/* printf of one line cleaned so, then a newline. */
void hx_put_clean_line(FILE *o, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* 1 when s holds a control character. */
int hx_has_ctrl(const char *s);

/* ---- config and run matrix (config.c) ---- */
/* Swept dimensions, in the nesting order of the expansion (outermost first).
 * Repeats are innermost, so all repeats of one configuration run back to
 * back; the backend dimension puts `serial` first so that the reference image
 * of every scene exists before any parallel run is checked against it. */
enum {
    HX_DIM_SCENE,
    HX_DIM_BACKEND,
    HX_DIM_ACCEL,
    HX_DIM_RESOLUTION,
    HX_DIM_MAX_DEPTH,
    HX_DIM_TILE,
    HX_DIM_SCHEDULE,
    HX_DIM_THREADS,
    HX_DIM_RANKS,
    HX_DIM_MPI_SCHEDULE,
    HX_DIM_BLOCK,
    HX_DIM_PIN,
    HX_NDIM
};
/* The most runs one config may expand to (checked before expanding): a
 * million is weeks of runs, while a typo in a list can make billions. */
#define HX_MAX_RUNS 1000000
extern const char *const hx_dim_key[HX_NDIM];  /* config key ("scenes", ...) */
extern const char *const hx_dim_col[HX_NDIM];  /* CSV column ("scene", ...) */

/* How MPI runs are started: mpirun (Open MPI, the default, maps and binds
 * ranks itself) or srun (inside a Slurm allocation, where mpirun would not
 * see the allocation's nodes or would fight Slurm's own binding). */
typedef enum { HX_LAUNCHER_MPIRUN, HX_LAUNCHER_SRUN } HxLauncher;

/* A `when KEY=V1,V2` on a swept key (docs/harness.md, "Your own
 * program"): the key applies only where KEY has one of the values. key:
 * -1 none, HX_SCOPE_BACKEND, else the index of an earlier param. */
#define HX_SCOPE_BACKEND 1000
typedef struct {
    int key;
    HxStrList vals;
    char *name;                 /* KEY as written; resolved after the last line */
} HxScope;

/* One line of a user parameter: its values where its scope holds. */
typedef struct {
    HxStrList vals;
    HxScope when;
    int line;
} HxParamAlt;

typedef struct {
    char *name;
    HxParamAlt *alt;            /* the first alternative whose scope holds */
    int nalt;
} HxParam;

struct HxProgram;               /* a command study's program (program.c) */

typedef struct {
    char *path;                 /* config file as given */
    char *study;
    HxStrList dim[HX_NDIM];     /* values; an unset dimension holds "-" */
    int dim_line[HX_NDIM];
    HxStrList scene_path;       /* resolved path of each dim[HX_DIM_SCENE] */
    char *scene_dir;
    int repeats, warmup;
    int order_rounds;           /* order: rounds: each round runs every configuration once */
    int ceiling_rounds;         /* ceiling: rounds: harness ceiling's copies before each round */
    int ceiling_line;
    double timeout_s;
    int oversubscribe_allow;
    char *baseline;             /* KEY=VALUE for `table`'s baseline (b) */
    char *raytrace;             /* NULL: $RAYTRACE or next to the harness */
    char *mpirun;
    HxLauncher launcher;
    HxStrList extra_args;       /* passed verbatim to raytrace */
    char *scene_cache;          /* raytrace --cache DIR; "off": none; NULL: the user's cache directory */
    int instructions;           /* each run under cachegrind: record key instructions */
    int instructions_line;
    HxStrList set;              /* harness run --set KEY=VALUE, as given */
    HxStrList set_seen;         /* the config's keys an override replaced */
    HxStrList warnings;         /* "FILE:LINE: warning: ...", printed by run */
    HxScope dim_when[HX_NDIM];  /* threads, ranks, ... only where it holds */
    HxParam *params;            /* `param NAME:` in declaration order */
    int nparams;
    struct HxProgram *prog;     /* `command:` given: a command study; NULL: raytrace */
} HxConfig;

typedef struct {
    const char *v[HX_NDIM];     /* "-" where not set or not applicable */
    const char *scene_path;
    const char *scene_name;     /* basename without .txt */
    const char **pv;            /* each param's value ("-": not in scope) */
    int repeat;                 /* 0-based; warm-ups count -warmup..-1 */
    int warmup;
    int workers;                /* threads (openmp), ranks (mpi), else 1 */
    char *config_id;            /* every swept value except repeat */
    char *run_id;               /* config_id + "#r" repeat */
    /* filled by the planner (topo.c) */
    int ncores;                 /* entries in cores[] */
    int *cores;                 /* topology core index per worker */
    char *cores_planned;        /* OS CPU ids, "-" when not pinned */
    int oversubscribed, refused;
} HxRun;

typedef struct {
    HxRun *runs;
    size_t n;
} HxPlan;

/* Returns 0, or -1 with "FILE:LINE: message" in err. */
int hx_config_load(const char *path, HxConfig *cfg, char *err, size_t errlen);
int hx_config_parse_string(const char *path, const char *text, HxConfig *cfg,
                           char *err, size_t errlen);
/* The same with overrides (harness run --set): each "KEY=VALUE" of set
 * replaces the config's line for KEY (or adds one); its errors name the
 * option instead of FILE:LINE, and a relative scene_dir it gives is taken
 * from the current folder only. set may be NULL. */
int hx_config_parse_set(const char *path, const char *text, const HxStrList *set, HxConfig *cfg,
                        char *err, size_t errlen);
int hx_config_load_set(const char *path, const HxStrList *set, HxConfig *cfg, char *err, size_t errlen);
int hx_config_open_set(const char *path, const HxStrList *set, HxConfig *cfg);
void hx_config_free(HxConfig *cfg);
/* hx_config_load for a subcommand: the error goes to stderr as one line and
 * the config is freed. Returns 0 or -1. */
int hx_config_open(const char *path, HxConfig *cfg);
/* "mpirun" or "srun" -> 0 and *out; anything else -1. One parser for the
 * config key and `run --launcher`, so both accept exactly the same names. */
int hx_launcher_parse(const char *name, HxLauncher *out);
const char *hx_launcher_name(HxLauncher l);
int hx_dim_applies(int dim, const char *backend);
/* Backends started as MPI ranks (mpi, mpi-cuda); backends on GPUs (cuda,
 * mpi-cuda: images checked against a tolerance, not bit for bit). */
int hx_backend_mpi(const char *backend);
int hx_backend_gpu(const char *backend);
/* Whether any backend of the config is one of those. */
int hx_config_has(const HxConfig *cfg, int (*pred)(const char *));
/* Whether the run is started as MPI ranks: an MPI backend, or a command
 * study's run with ranks. */
int hx_run_is_mpi(const char *const v[HX_NDIM]);

/* ---- the run matrix (plan.c) ---- */
/* Checks one value of raytrace's swept dimension dim. 0, or -1 with why. */
int hx_dim_value_check(int dim, const char *v, char *why, size_t n);
/* The runs the config expands to, counted without building the plan. */
double hx_plan_size(const HxConfig *cfg);
int hx_expand(const HxConfig *cfg, HxPlan *plan);
void hx_plan_free(HxPlan *plan);
/* "scene=... pin=close" and each param as " NAME=VALUE"; a command study
 * (backend "-") names only threads, ranks, pin and its params. params is
 * "NAME=VALUE;..." or NULL. malloc'd. */
char *hx_make_config_id(const char *const v[HX_NDIM], const char *params);
/* The run's params as "NAME=VALUE;NAME=VALUE" (the CSV's `params`), "" when
 * the study has none. malloc'd. */
char *hx_run_params(const HxConfig *cfg, const HxRun *r);
/* A value list with ranges: "A..B" (step 1), "A..B +S", "A..B *F" become
 * their values. 0, or -1 with why. */
int hx_values_expand(const HxStrList *in, HxStrList *out, char *why, size_t n);
/* Splits a trailing "when KEY=V1,V2" off vals into sc (name, vals); 0
 * when there is none (sc->name NULL) or it is well formed, -1 with why. */
int hx_split_when(HxStrList *vals, HxScope *sc, char *why, size_t n);
/* Resolves sc->name (backend, or one of the first upto params) into
 * sc->key and checks that KEY has each value. 0, or -1 with why. */
int hx_scope_resolve(const HxConfig *cfg, HxScope *sc, int upto, char *why, size_t n);
void hx_scope_free(HxScope *sc);

/* ---- topology and pinning (topo.c) ---- */
typedef struct {
    int ncores;         /* physical cores (hwloc), else online CPUs */
    int npus;
    int npackages;
    int numa_nodes;
    int have_hwloc;
    int restricted;     /* the process may use fewer CPUs than the machine has */
    int *core_os;       /* OS id of the first PU of each core, close order */
    char **core_pus;    /* "0" or "0,36": every PU of the core */
    int *spread_order;  /* core indices round-robin across packages */
    int *core_pkg;      /* package of each core, and its index within it */
    int *core_in_pkg;   /* (Open MPI's rankfile names a core as pkg:core) */
    int ngpus;          /* NVIDIA GPUs on PCI (hwloc), in bus order: CUDA's */
    char **gpu_bus;     /* order under CUDA_DEVICE_ORDER=PCI_BUS_ID */
    int **gpu_cores;    /* the cores nearest each GPU (its NUMA node's) */
    int *gpu_ncores;
    void *topo;         /* hwloc_topology_t */
} HxTopo;

int hx_topo_load(HxTopo *t);
void hx_topo_free(HxTopo *t);
/* Plans cores for every run; prints a warning per run over the machine. */
void hx_plan_cores(const HxTopo *t, const HxConfig *cfg, HxPlan *plan);
/* Open MPI rankfile text placing rank w on the run's core w ("rank 0=localhost
 * slot=0:3" ...; malloc'd), or NULL when the run has no planned cores. */
char *hx_rankfile(const HxTopo *t, const HxRun *r);
/* In the forked child, before exec: bind to the run's cores. */
int hx_bind_child(const HxTopo *t, const HxRun *r);
void hx_topo_print(const HxTopo *t, FILE *out);
/* OMP_PLACES value for the run's cores, malloc'd ("{0},{1}"). */
char *hx_omp_places(const HxTopo *t, const HxRun *r);
/* Whether a run's pinning held: its planned cores against the cores its
 * threads reported (cores_actual): "yes", "partial", "no", "unknown" or
 * "n/a" (nothing planned). Lists of several nodes ("0,1|0,1", a run spread
 * over a Slurm job's nodes) are compared node by node. */
const char *hx_pin_held(const char *planned, const char *actual);
/* hx_pin_held for a row: a plan over several nodes is checked against the
 * cores per node of the record's rank_node and rank_cores (extra), which
 * then become the row's cores_actual. */
const char *hx_pin_held_row(const char *planned, char **vals);
/* Nodes of the Slurm job the harness runs in (SLURM_JOB_NUM_NODES), 1
 * outside one. */
int hx_slurm_nodes(void);
/* The cores each node's ranks ran on, from the record's rank_node
 * ("0/0/1/1") and rank_cores ("0/1/0/1"): "0,1|0,1", nodes in order, each
 * sorted; malloc'd, NULL when the two do not fit together. */
char *hx_cores_by_node(const char *rank_node, const char *rank_cores);

/* ---- machine fingerprint (fingerprint.c) ---- */
typedef struct {
    char host[256];
    char cpu_model[256];
    int phys_cores, logical_cpus, smt;
    char governor[64];
    char compiler[128];
    char gpu_name[256];
    char gpu_driver[64];
    char git_commit[64];
    char fingerprint[20];   /* FNV-1a of the fields that affect timings */
    char kernel[160];       /* uname: system and release */
    char mpi_version[128];  /* first line of `mpirun --version`, or "-" */
    char build_flags[256];  /* the renderer's compiler and flags (raytrace -V) */
} HxFingerprint;

/* What produced the rows: the machine, the renderer's commit (dirty when a
 * tracked file other than exclude, the study's own CSV, differs), its build
 * flags, the kernel and, given mpirun, the MPI library. */
void hx_fingerprint_get(HxFingerprint *fp, const HxTopo *t, int want_gpu, const char *raytrace,
                        const char *mpirun, const char *exclude);
void hx_fingerprint_hash(HxFingerprint *fp);
void hx_utc_now(char *buf, size_t n);

/* ---- CSV schema, writing and reading (csv.c) ---- */
extern const char *const hx_columns[];
extern const int hx_ncolumns;
int hx_column_index(const char *name);     /* schema index or -1 */
/* Maps a record key to its fixed column, or NULL (goes to `extra`). */
const char *hx_record_column(const char *key);

/* The file's text parsed in place (every field NUL-terminated where it
 * stands) and 4 bytes per field: hx_csv_cell and hx_csv_get read it. */
typedef struct {
    int ncol;
    char **cols;         /* header names, into text */
    size_t nrows;
    char *text;
    size_t *row_at;      /* row r starts at text + row_at[r] */
    uint32_t *field_at;  /* field c of row r at that + field_at[r * ncol + c] */
    int torn_line;       /* a harness CSV's last row without a line end, left out (0: none) */
} HxCsv;

int hx_csv_read(const char *path, HxCsv *csv, char *err, size_t errlen);
int hx_csv_parse(const char *text, HxCsv *csv, char *err, size_t errlen);
/* Reads a whole file into b in one allocation of its size; -1 with errno. */
int hx_csv_read_text(const char *path, HxBuf *b);
/* hx_csv_parse of text->s, parsed in place: csv takes its memory (text is
 * left empty, also on failure). */
int hx_csv_parse_buf(HxBuf *text, HxCsv *csv, char *err, size_t errlen);
void hx_csv_free(HxCsv *csv);
int hx_csv_col(const HxCsv *csv, const char *name);
const char *hx_csv_cell(const HxCsv *csv, size_t row, int col);
const char *hx_csv_get(const HxCsv *csv, size_t row, const char *name);
void hx_csv_field(HxBuf *b, const char *s);   /* RFC 4180 quoting */
/* Formats one row of hx_ncolumns values (NULL -> empty) with a newline. */
void hx_csv_format_row(HxBuf *b, const char *const *vals);
/* Opens for appending, the file locked: creates the header, checks an
 * existing header, cuts a torn last line; truncate 1: starts it again;
 * HX_CSV_LOCK_ONLY: only opens and locks it, for hx_csv_restart later.
 * Returns fd or -1 with err. */
#define HX_CSV_LOCK_ONLY 2
int hx_csv_open_append(const char *path, int truncate, char *err, size_t errlen);
/* Empties the open CSV fd and writes the header: fd, or -1 with err (fd
 * closed). */
int hx_csv_restart(int fd, const char *path, char *err, size_t errlen);
/* Writes a whole row with one write() and fsync()s it. */
int hx_csv_append_row(int fd, const char *const *vals);
/* Parses "record: k=v ..." (up to the line's end) into the row values
 * (malloc'd strings). */
int hx_record_to_row(const char *line, char **vals);
/* The value of key in the record line ("record: k=v ..."), into out; NULL
 * when the line has no such key. */
const char *hx_record_get(const char *line, const char *key, char *out, size_t n);
/* The last line of out that starts with "record: ", or NULL. */
char *hx_record_find(char *out);
/* vals[col] = a copy of v (NULL: empty); an unknown column is ignored. */
void hx_row_set(char **vals, const char *col, const char *v);
/* Whether any row of csv has col non-empty. */
int hx_csv_has_values(const HxCsv *csv, const char *col);

/* ---- statistics (stats.c) ---- */
double hx_median(const double *x, size_t n);
double hx_quantile(const double *x, size_t n, double q); /* of unsorted x, type 7; NAN when n is 0 */
double hx_quantile_sorted(const double *sorted, size_t n, double q);
double hx_mad(const double *x, size_t n);
double hx_min(const double *x, size_t n);
int hx_outliers(const double *x, size_t n, double k, int *flag);
double hx_karp_flatt(double speedup, double p);
/* 95% percentile-bootstrap interval of median(a) (b NULL), or of the
 * speedup median(b) / median(a) (b the baseline's samples). */
void hx_bootstrap_ci(const double *a, size_t na, const double *b, size_t nb, double *lo, double *hi);
typedef struct {
    int ok;          /* enough points for a, b */
    int has_se;      /* enough for standard errors */
    double a, b, se_a, se_b, cov_ab;
    double serial_fraction, se_serial_fraction;
} HxAmdahl;
HxAmdahl hx_amdahl_fit(const double *p, const double *t, size_t n);
double hx_mann_whitney_p(const double *x, size_t nx, const double *y, size_t ny);

/* ---- gnuplot files (plot.c) ---- */
/* A plot is PREFIX-KIND.png and .svg, drawn by PREFIX-KIND.gp from
 * PREFIX-KIND.dat, both kept beside the images. */
typedef struct {
    const char *who;      /* the command, for messages */
    char *dir;            /* folder of PREFIX (owned) */
    const char *base;     /* file name part of PREFIX */
    const char *term_png; /* pngcairo or png */
    int failures, made;
} HxPlot;
/* Checks PREFIX (its folder exists, no control character); 0 or -1 with
 * one line on stderr. hx_plot_done frees it. */
int hx_plot_init(HxPlot *c, const char *who, const char *prefix);
void hx_plot_done(HxPlot *c);
FILE *hx_plot_open(const HxPlot *c, const char *kind, FILE **dat);
void hx_plot_head(FILE *gp, const HxPlot *c, const char *kind, const char *title);
void hx_plot_tail(FILE *gp, const HxPlot *c, const char *kind);
/* Closes both files and runs gnuplot; counts made and failures. */
void hx_plot_finish(HxPlot *c, const char *kind, FILE *gp, FILE *dat);
/* The same head for a multiplot, whose BODY is written once per terminal. */
void hx_plot_multi(FILE *gp, const HxPlot *c, const char *kind, const char *title, int rows, int cols,
                   const char *body, int w, int h);
/* fprintf of fmt with one %s: s (or "BASE-KIND.EXT") quoted for gnuplot */
void hx_plot_put(FILE *gp, const char *fmt, const char *s);
void hx_plot_file(FILE *gp, const char *fmt, const char *base, const char *kind, const char *ext);
/* A label for a .dat column header: quotes and control characters blanked. */
void hx_plot_clean_label(char *dst, size_t n, const char *src);
/* The verdict of compare's time rule on bare samples, new against base
 * (harness ab): printed as one line "VERDICT label: reason"; *verdict the
 * word. 1 for a regression, else 0. */
int hx_judge_samples(const char *label, double *nw, size_t nn, double *base, size_t nb, double factor, double alpha,
                     int higher, const char *unit, const char **verdict);
/* ---- HTML pages (html.c), shared by report and history publish ---- */
/* The mark of a folder the harness writes pages into: one holding it may be
 * written again, any other folder that is not empty is refused. */
#define HX_HTML_MARK ".raybench-report"
/* The pages' inline stylesheet. */
extern const char *const hx_html_css;
/* DIR made ready: created, or empty, or marked before; the mark written
 * (mark_text its line). 0, or -1 with one line "WHO: ..." on stderr. */
int hx_html_dir(const char *who, const char *dir, const char *mark_text);
/* The SVG file inlined as a figure (its XML declaration dropped) with the
 * caption; 1 when there was one. */
int hx_html_svg_file(FILE *o, const char *path, const char *caption);
/* A page written whole or not at all: into a hidden PATH.part beside it,
 * renamed onto PATH when complete. */
typedef struct {
    FILE *f;
    char *path, *part;
} HxHtmlPage;
/* Opens the part file and writes the head (title escaped, the stylesheet)
 * up to <body>; NULL when it cannot be created. */
FILE *hx_html_open(HxHtmlPage *pg, const char *path, const char *title);
/* Ends the body and renames the part onto the page, when ok and every
 * write went through; else removes it and says "WHO: PATH not written".
 * 0 or -1. */
int hx_html_close(HxHtmlPage *pg, const char *who, int ok);

/* ---- commands ---- */
int hx_cmd_run(int argc, char **argv);
int hx_cmd_table(int argc, char **argv);
int hx_cmd_report(int argc, char **argv);
int hx_cmd_plot(int argc, char **argv);
int hx_cmd_compare(int argc, char **argv);
int hx_cmd_topo(int argc, char **argv);
int hx_cmd_slurm(int argc, char **argv);
int hx_cmd_history(int argc, char **argv);
int hx_cmd_ab(int argc, char **argv);
int hx_cmd_ceiling(int argc, char **argv);
/* Stores study CSVs in the history database (history_db.c); 0, or 1 on failure. */
int hx_history_add(const char *db, char **csvs, int n, int allow_dirty);

/* ---- the study model (study.c), shared by table, plot and compare ---- */
/* One configuration of one scene, with its ok samples. */
typedef struct {
    char *scene;
    char *config_id;     /* unique key: scene + every swept value */
    char *series_id;     /* config_id without the swept worker dimension:
                          * threads for OpenMP, ranks for MPI */
    int axis;            /* that dimension's value: the series' x */
    char *series2_id;    /* hybrid MPI studies (threads and ranks both
                          * swept): the series over threads at fixed ranks;
                          * NULL otherwise */
    int axis2;           /* threads, for series2 */
    int swept;           /* HX_DIM_THREADS, HX_DIM_RANKS or -2 (none) */
    int suspect;         /* a run was oversubscribed or its pinning did not
                          * hold: left out of fits unless asked */
    const char *suspect_why;
    size_t npartial;     /* ok rows whose pinning held only in part */
    size_t nbusy, nstolen; /* rows on a busy machine, with CPU steal (noise) */
    double steal_max;    /* the largest CPU steal of its stolen rows, % (-1: none recorded) */
    double ci_lo, ci_hi; /* 95% bootstrap interval of the median */
    char *label;         /* short, readable, for tables and plots */
    char *backend;
    char *block;
    int workers;
    size_t nrows, nok, ntimeout, nwrong, nerror;
    double *t;           /* ok samples of the metric */
    int *rep;            /* each one's repeat (its round with order: rounds), -1 unknown */
    size_t nt;
    double median, min, q1, q3;
    int noutliers;
    const char *first_status; /* status of a failed run for the cross table */
    size_t first_row;
    size_t ok_row;       /* first ok row (the record's values), else first_row */
    double *raw;         /* render_ms of the ok rows, whatever the metric */
    size_t nraw;
    double raw_median;   /* their median (compare's --min-ms) */
} HxGroup;

/* The machine's ceiling at one worker count (ceiling.c, ceiling_read.c). */
typedef struct {
    char *scene;  /* of this scene; NULL: of any (a file without the column) */
    int w;        /* at w workers, each copy keeps */
    double r;     /* this share of a lone copy's speed, */
    double steal; /* with this CPU steal (%) while they ran, -1 unknown; */
    double t;     /* each copy's own metric while they ran, NAN unknown; */
    double s;     /* the share a step of w workers kept (syncstep.c), NAN unknown */
    int round;    /* ceiling: rounds: the round it was measured before, -1 pooled or none */
} HxCeilPoint;

typedef struct {
    HxCsv csv;
    HxGroup *g;
    size_t ng;
    HxStrList scenes;
    HxStrList labels;    /* cross-table columns, first-seen order */
    int *row_status_wrong; /* per row: 1 when the gate marks it wrong */
    size_t nwrong_rows;
    char metric[96];     /* the metric read: as asked, else the study's default */
    char unit[24];       /* its unit ("ms", "GB/s", ...; "" unknown) */
    int higher;          /* 1: higher is better (a rate), 0: lower (a time) */
    int size;            /* 1: a size (unit B, KiB, ..., GB, or maxrss_kib):
                          * shown against 1 worker, no speedup or fit */
    int nceil;           /* the machine's ceiling (harness ceiling), by scene and workers */
    HxCeilPoint *ceil;
    int nceil_round;     /* ceiling: rounds: its rows as measured, before pooling */
    HxCeilPoint *ceil_round;
    char *ceil_path;
    int ceil_rounds;     /* the most rows pooled for one worker count (ceiling: rounds), else 1 */
} HxStudy;

/* ---- plots of a study (plot.c, plot_sweep.c) ---- */
/* "STUDY: WHAT", a new line, "on CPU, N cores, GPU" into t; given the
 * legend's titles (else NULL), the words every one shares are taken out of
 * each and named once in a last line, "all series: ...". */
void hx_plot_title(HxBuf *t, const HxStudy *s, const char *what, HxStrList *titles);
/* Plot terms for DAT's block k of one-configuration series: labelled
 * markers, one legend entry; last: the plot command ends there. */
void hx_plot_markers(FILE *gp, const HxPlot *c, const char *kind, int k, int last);
/* Tics at 1, 2 and 5 of each decade of [lo, hi] (finer within a decade) on a log axis ("x", "y"). */
void hx_plot_log_tics(FILE *gp, const char *axis, double lo, double hi);
/* PREFIX-blocks (a heatmap per scene) and PREFIX-sweep (the metric over
 * a swept size); each says on stdout when the study has nothing for it. */
void hx_plot_blocks(HxPlot *c, const HxStudy *s);
void hx_plot_sweep(HxPlot *c, const HxStudy *s);

/* The analysis of s->csv, already read (everything else in s zero); on
 * failure s->csv is freed. hx_study_load is hx_csv_read and this. metric
 * NULL: the study's default (render_ms for raytrace, a command study's
 * first metric, else wall_ms), in s->metric with its unit, direction and
 * whether it is a size. */
int hx_study_build(const char *path, const char *metric, HxStudy *s, char *err, size_t errlen);
/* Whether the metric is a size (peak memory, a file's size): neither a
 * time nor a rate, so it has no speedup (docs/harness.md, "Units"). */
int hx_metric_is_size(const char *metric, const char *unit);
int hx_study_load(const char *path, const char *metric, HxStudy *s,
                  char *err, size_t errlen);
void hx_study_free(HxStudy *s);
/* hx_study_load for a subcommand: the error goes to stderr as "WHO: message".
 * Returns 0 or -1. */
int hx_study_open(const char *who, const char *path, const char *metric, HxStudy *s);
/* The speedup of v over base: base / v for times, v / base for rates. */
double hx_study_speedup(const HxStudy *s, double base, double v);
/* Whether a is better than b by the metric's direction. */
int hx_study_better(const HxStudy *s, double a, double b);
/* The ceiling of the study's machine (ceiling.c): FILE, else
 * ceiling-FINGERPRINT.csv beside the CSV or in results/. 0 when one was
 * read (or none is there and none was asked for), -1 with a line said. */
int hx_ceiling_load(HxStudy *s, const char *who, const char *file, const char *csv_path);
/* Its ratio for scene at workers, NAN when not measured; *together and *step (may be
 * NULL): each copy's own metric with that many running, and the share a
 * step of that many workers kept, NAN unknown. */
double hx_ceiling_at(const HxStudy *s, const char *scene, int workers, double *together, double *step);
/* ceiling: rounds: the median over g's samples of each one's pace against
 * the copies of its own round (together / (W x the sample), a rate's
 * inverse); NAN unless every sample's round has a row. */
double hx_ceiling_paired_pace(const HxStudy *s, const HxGroup *g);
/* table's paragraph on the study's ceiling, appended to b. */
void hx_ceiling_para(const HxStudy *s, HxBuf *b);
/* table's per-configuration, fit and cross tables as HTML (harness report). */
void hx_table_html(FILE *out, const HxStudy *s, const char *baseline);
/* Speedup baselines of a group: (a) same series at one worker, (b) the
 * fastest group of the same scene matching KEY=VALUE. NULL if none. */
const HxGroup *hx_baseline_one_worker(const HxStudy *s, const HxGroup *g);
/* The series' name: g's label without the swept dimension's value (second:
 * the hybrid series over threads). malloc'd. */
char *hx_series_label(const HxGroup *g, int second);
/* The same for a hybrid group's series2 (one thread, same ranks). */
const HxGroup *hx_baseline_one_thread(const HxStudy *s, const HxGroup *g);
const HxGroup *hx_baseline_fastest(const HxStudy *s, const HxGroup *g,
                                   const char *kv);

#endif
