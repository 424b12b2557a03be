/* config.c: the study config format and its expansion into runs.
 *
 * Format (in the spirit of the scene files): one `key: values` per line,
 * `#` starts a comment, values are separated by spaces or commas. A list on
 * a swept key (scenes, backend, accel, threads, ...) sweeps that dimension;
 * the runs are the cartesian product. Every error names FILE:LINE so a typo
 * in a 40-line sweep is found at once, before hours of runs start. */
#include "hx.h"
#include "program.h"

#include <dirent.h>
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>

const char *const hx_dim_key[HX_NDIM] = {
    "scenes", "backend", "accel", "resolution", "max_depth", "tile",
    "schedule", "threads", "ranks", "mpi_schedule", "block", "pin"};
const char *const hx_dim_col[HX_NDIM] = {
    "scene", "backend", "accel", "resolution", "max_depth", "tile",
    "schedule", "threads", "ranks", "mpi_schedule", "block", "pin"};

/* Which option each backend understands. A dimension that does not apply
 * collapses to "-" for that backend, so `threads: 1 2` next to a serial
 * backend does not produce two identical serial runs that would later look
 * like a (fake) scaling series. */
int hx_backend_mpi(const char *backend)
{
    return strcmp(backend, "mpi") == 0 || strcmp(backend, "mpi-cuda") == 0;
}

int hx_backend_gpu(const char *backend)
{
    return strcmp(backend, "cuda") == 0 || strcmp(backend, "mpi-cuda") == 0;
}

int hx_config_has(const HxConfig *cfg, int (*pred)(const char *))
{
    for (size_t i = 0; i < cfg->dim[HX_DIM_BACKEND].n; i++)
        if (pred(cfg->dim[HX_DIM_BACKEND].v[i]))
            return 1;
    return 0;
}

int hx_run_is_mpi(const char *const v[HX_NDIM])
{
    return hx_backend_mpi(v[HX_DIM_BACKEND]) || (strcmp(v[HX_DIM_BACKEND], "-") == 0 && strcmp(v[HX_DIM_RANKS], "-") != 0);
}

int hx_dim_applies(int dim, const char *backend)
{
    if (strcmp(backend, "-") == 0) /* a command study: its cores and ranks */
        return dim == HX_DIM_THREADS || dim == HX_DIM_RANKS || dim == HX_DIM_PIN;
    switch (dim) {
    case HX_DIM_TILE:
        return !hx_backend_gpu(backend);
    case HX_DIM_SCHEDULE:
        return strcmp(backend, "openmp") == 0;
    case HX_DIM_THREADS: /* openmp; with mpi: threads per rank (hybrid) */
        return strcmp(backend, "openmp") == 0 || strcmp(backend, "mpi") == 0;
    case HX_DIM_RANKS: /* mpi-cuda: one rank per GPU */
        return hx_backend_mpi(backend);
    case HX_DIM_MPI_SCHEDULE:
        return strcmp(backend, "mpi") == 0;
    case HX_DIM_BLOCK:
        return hx_backend_gpu(backend);
    default:
        return 1;
    }
}

/* "FILE:LINE: message"; a line below 0 is override -line-1 (harness run
 * --set), named as the option instead. */
static int set_err(char *err, size_t errlen, const HxConfig *cfg, int line,
                   const char *fmt, ...) __attribute__((format(printf, 5, 6)));
static int set_err(char *err, size_t errlen, const HxConfig *cfg, int line,
                   const char *fmt, ...)
{
    char msg[512];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    if (line < 0)
        snprintf(err, errlen, "harness: option --set '%s': %s", cfg->set.v[-line - 1], msg);
    else
        snprintf(err, errlen, "%s:%d: %s", cfg->path, line, msg);
    return -1;
}

/* Finds a scene: DIR/NAME, DIR/NAME.txt, or one level down
 * (DIR/SUB/NAME[.txt]) so that `scenes: dragon` works with the course folder,
 * which keeps its scenes in sub-folders. Returns a malloc'd path, NULL when
 * missing; *ambiguous set when more than one sub-folder has it. */
static char *find_scene(const char *dir, const char *name, int *ambiguous)
{
    *ambiguous = 0;
    char *p = hx_path_join(dir, name);
    if (hx_file_exists(p))
        return p;
    free(p);
    HxBuf b = {0};
    hx_buf_printf(&b, "%s.txt", name);
    p = hx_path_join(dir, b.s);
    if (hx_file_exists(p)) {
        hx_buf_free(&b);
        return p;
    }
    free(p);
    char *found = NULL;
    DIR *d = opendir(dir);
    if (d) {
        struct dirent *e;
        while ((e = readdir(d)) != NULL) {
            if (e->d_name[0] == '.')
                continue;
            char *sub = hx_path_join(dir, e->d_name);
            if (hx_is_dir(sub)) {
                for (int k = 0; k < 2; k++) {
                    char *c = hx_path_join(sub, k ? b.s : name);
                    if (hx_file_exists(c)) {
                        if (found) {
                            *ambiguous = 1;
                            free(c);
                        } else {
                            found = c;
                        }
                        break;
                    }
                    free(c);
                }
            }
            free(sub);
        }
        closedir(d);
    }
    hx_buf_free(&b);
    if (*ambiguous) {
        free(found);
        return NULL;
    }
    return found;
}

/* Relative paths in a config are tried against the current directory first
 * (users run `harness run configs/x.conf` from the repository root) and then
 * against the config file's own folder; one from `harness run --set`
 * (cwd_only) against the current directory only, as the shell would. */
static char *resolve_dir(const char *cfg_path, const char *dir, int cwd_only)
{
    if (dir[0] == '/' || hx_is_dir(dir))
        return hx_strdup(dir);
    if (cwd_only)
        return NULL;
    char *cd = hx_dirname(cfg_path);
    char *p = hx_path_join(cd, dir);
    free(cd);
    if (hx_is_dir(p))
        return p;
    free(p);
    return NULL;
}

static void config_defaults(HxConfig *cfg, const char *path)
{
    memset(cfg, 0, sizeof *cfg);
    cfg->path = hx_strdup(path);
    cfg->repeats = 3;
    cfg->warmup = 0;
    cfg->timeout_s = 600;
    cfg->oversubscribe_allow = 0;
    cfg->launcher = HX_LAUNCHER_MPIRUN;
}

static void fill_default_dims(HxConfig *cfg)
{
    for (int i = 0; i < HX_NDIM; i++) {
        if (cfg->dim[i].n)
            continue;
        /* Pinning defaults to close: unpinned numbers on a shared machine
         * are the report's main source of unexplained spread. */
        if (i == HX_DIM_BACKEND)
            hx_strlist_push(&cfg->dim[i], "serial");
        else if (i == HX_DIM_PIN)
            hx_strlist_push(&cfg->dim[i], "close");
        else
            hx_strlist_push(&cfg->dim[i], "-");
    }
}

/* Splits a value list on spaces and commas. */
static void split_values(char *s, HxStrList *out)
{
    char *save = NULL;
    for (char *t = strtok_r(s, " \t,", &save); t; t = strtok_r(NULL, " \t,", &save))
        hx_strlist_push(out, t);
}

static int dim_of_key(const char *key)
{
    for (int i = 0; i < HX_NDIM; i++)
        if (strcmp(key, hx_dim_key[i]) == 0)
            return i;
    /* The singular is accepted too: `scene: dragon` reads naturally. */
    if (strcmp(key, "scene") == 0)
        return HX_DIM_SCENE;
    return -1;
}

static const char *const scalar_keys[] = {
    "study", "scene_dir", "repeats", "warmup", "timeout", "oversubscribe",
    "baseline", "raytrace", "mpirun", "launcher", "scene_cache", "instructions", "order", "ceiling", NULL};

int hx_launcher_parse(const char *name, HxLauncher *out)
{
    if (strcmp(name, "mpirun") == 0)
        *out = HX_LAUNCHER_MPIRUN;
    else if (strcmp(name, "srun") == 0)
        *out = HX_LAUNCHER_SRUN;
    else
        return -1;
    return 0;
}

const char *hx_launcher_name(HxLauncher l)
{
    return l == HX_LAUNCHER_SRUN ? "srun" : "mpirun";
}

/* Timeout: seconds, with an optional s/m/h suffix. */
static int parse_timeout(const char *v, double *out)
{
    char buf[64];
    size_t n = strlen(v);
    if (n == 0 || n >= sizeof buf)
        return -1;
    memcpy(buf, v, n + 1);
    double mul = 1;
    char last = buf[n - 1];
    if (last == 's' || last == 'm' || last == 'h') {
        mul = last == 's' ? 1 : last == 'm' ? 60 : 3600;
        buf[n - 1] = '\0';
    }
    double d;
    if (hx_parse_double(buf, &d) || d <= 0)
        return -1;
    *out = d * mul;
    return 0;
}

static int dim_values(int lineno, int dim, const char *key, const HxStrList *vals, HxConfig *cfg, char *err,
                      size_t errlen);

/* A swept key's values (dimension dim) from line lineno. 0, or -1 with err
 * set. */
static int parse_dim(int lineno, int dim, const char *key, const HxStrList *vals,
                     HxConfig *cfg, char *err, size_t errlen)
{
    if (cfg->dim_line[dim])
        return set_err(err, errlen, cfg, lineno, "key '%s' already set on line %d",
                       key, cfg->dim_line[dim]);
    cfg->dim_line[dim] = lineno;
    char why[256];
    HxStrList words = {0}, list = {0};
    for (size_t i = 0; i < vals->n; i++)
        hx_strlist_push(&words, vals->v[i]);
    int rc = dim == HX_DIM_SCENE || dim == HX_DIM_BACKEND ? 0 : hx_split_when(&words, &cfg->dim_when[dim], why, sizeof why);
    if (rc == 0 && (dim == HX_DIM_SCENE || dim == HX_DIM_BACKEND)) /* names, never ranges */
        for (size_t i = 0; i < words.n; i++)
            hx_strlist_push(&list, words.v[i]);
    else if (rc == 0)
        rc = hx_values_expand(&words, &list, why, sizeof why);
    hx_strlist_free(&words);
    if (rc == 0)
        rc = dim_values(lineno, dim, key, &list, cfg, err, errlen);
    else
        set_err(err, errlen, cfg, lineno, "%s: %s", key, why);
    hx_strlist_free(&list);
    return rc;
}

/* The values of a swept key, after ranges and scope. */
static int dim_values(int lineno, int dim, const char *key, const HxStrList *vals, HxConfig *cfg, char *err,
                      size_t errlen)
{
    for (size_t i = 0; i < vals->n; i++) {
        char why[256];
        if (hx_dim_value_check(dim, vals->v[i], why, sizeof why))
            return set_err(err, errlen, cfg, lineno, "%s: %s", key, why);
        hx_strlist_push(&cfg->dim[dim], vals->v[i]);
    }
    const char *twice = hx_strlist_twice(&cfg->dim[dim]);
    return twice ? set_err(err, errlen, cfg, lineno, "%s: value '%s' listed twice", key, twice) : 0;
}

/* A scalar key's one value v. 0, or -1 with err set. */
static int parse_scalar(int lineno, const char *key, const char *v, HxConfig *cfg,
                        char *err, size_t errlen)
{
    int rc = 0;
    long iv;
    if (strcmp(key, "study") == 0) {
        /* (it names results/STUDY.csv and the Slurm files: a '/' would put them elsewhere) */
        if (strchr(v, '/'))
            rc = set_err(err, errlen, cfg, lineno, "study: a name, not a path: no '/', got '%s'", v);
        else
            cfg->study = hx_strdup(v);
    } else if (strcmp(key, "scene_dir") == 0) {
        cfg->scene_dir = hx_strdup(v);
    } else if (strcmp(key, "repeats") == 0) {
        if (hx_parse_int(v, 1, 100000, &iv))
            rc = set_err(err, errlen, cfg, lineno, "repeats: expected an integer >= 1, got '%s'", v);
        else
            cfg->repeats = (int)iv;
    } else if (strcmp(key, "warmup") == 0) {
        if (hx_parse_int(v, 0, 1000, &iv))
            rc = set_err(err, errlen, cfg, lineno, "warmup: expected an integer >= 0, got '%s'", v);
        else
            cfg->warmup = (int)iv;
    } else if (strcmp(key, "timeout") == 0) {
        if (parse_timeout(v, &cfg->timeout_s))
            rc = set_err(err, errlen, cfg, lineno,
                         "timeout: expected seconds > 0 (e.g. 30, 30s, 5m, 2h), got '%s'", v);
    } else if (strcmp(key, "oversubscribe") == 0) {
        if (strcmp(v, "allow") == 0)
            cfg->oversubscribe_allow = 1;
        else if (strcmp(v, "refuse") == 0)
            cfg->oversubscribe_allow = 0;
        else
            rc = set_err(err, errlen, cfg, lineno,
                         "oversubscribe: expected refuse|allow, got '%s'", v);
    } else if (strcmp(key, "baseline") == 0) {
        const char *eq = strchr(v, '=');
        if (!eq || eq == v || eq[1] == '\0')
            rc = set_err(err, errlen, cfg, lineno,
                         "baseline: expected KEY=VALUE (e.g. backend=serial), got '%s'", v);
        else
            cfg->baseline = hx_strdup(v);
    } else if (strcmp(key, "raytrace") == 0) {
        cfg->raytrace = hx_strdup(v);
    } else if (strcmp(key, "mpirun") == 0) {
        cfg->mpirun = hx_strdup(v);
    } else if (strcmp(key, "scene_cache") == 0) {
        cfg->scene_cache = hx_strdup(v);
    } else if (strcmp(key, "order") == 0) {
        if (strcmp(v, "rounds") == 0 || strcmp(v, "nested") == 0)
            cfg->order_rounds = strcmp(v, "rounds") == 0;
        else
            rc = set_err(err, errlen, cfg, lineno, "order: expected nested|rounds, got '%s'", v);
    } else if (strcmp(key, "ceiling") == 0) {
        if (strcmp(v, "rounds") == 0 || strcmp(v, "off") == 0)
            cfg->ceiling_rounds = strcmp(v, "rounds") == 0;
        else
            rc = set_err(err, errlen, cfg, lineno, "ceiling: expected off|rounds, got '%s'", v);
        cfg->ceiling_line = lineno;
    } else if (strcmp(key, "instructions") == 0) {
        if (strcmp(v, "on") == 0 || strcmp(v, "off") == 0)
            cfg->instructions = strcmp(v, "on") == 0;
        else
            rc = set_err(err, errlen, cfg, lineno, "instructions: expected on|off, got '%s'", v);
        cfg->instructions_line = lineno;
    } else if (strcmp(key, "launcher") == 0) {
        if (hx_launcher_parse(v, &cfg->launcher))
            rc = set_err(err, errlen, cfg, lineno,
                         "launcher: expected mpirun|srun, got '%s'", v);
    }
    return rc;
}

/* One `key: values` pair; seen_scalar[k]: the line scalar_keys[k] was set
 * on. 0, or -1 with err set. */
static int parse_key(int lineno, const char *key, const HxStrList *vals,
                     HxConfig *cfg, int *seen_scalar, char *err, size_t errlen)
{
    if (vals->n == 0)
        return set_err(err, errlen, cfg, lineno, "key '%s' has no value", key);
    int dim = dim_of_key(key);
    if (dim >= 0)
        return parse_dim(lineno, dim, key, vals, cfg, err, errlen);
    if (strcmp(key, "extra_args") == 0) {
        for (size_t i = 0; i < vals->n; i++)
            hx_strlist_push(&cfg->extra_args, vals->v[i]);
        return 0;
    }
    int sk = -1;
    for (int i = 0; scalar_keys[i]; i++)
        if (strcmp(key, scalar_keys[i]) == 0)
            sk = i;
    if (sk < 0)
        return set_err(err, errlen, cfg, lineno, "unknown key '%s'", key);
    if (seen_scalar[sk])
        return set_err(err, errlen, cfg, lineno, "key '%s' already set on line %d",
                       key, seen_scalar[sk]);
    seen_scalar[sk] = lineno;
    if (vals->n != 1)
        return set_err(err, errlen, cfg, lineno, "key '%s' takes one value, got %zu",
                       key, vals->n);
    return parse_scalar(lineno, key, vals->v[0], cfg, err, errlen);
}

/* "param  n" as "param n": one blank between a key's words, in place. */
static char *squeeze(char *k)
{
    char *o = k;
    for (const char *i = k; *i; i++)
        if (*i != ' ' && *i != '\t')
            *o++ = *i;
        else if (o > k && o[-1] != ' ')
            *o++ = ' ';
    *o = '\0';
    return k;
}

/* Cuts the line at its comment: '#' starts one, except inside quotes in
 * the value of a command study's key (a command's argument, a pattern). */
static void cut_comment(char *line)
{
    char *colon = strchr(line, ':'), *hash = strchr(line, '#');
    if (!hash)
        return;
    if (!colon || hash < colon) {
        *hash = '\0';
        return;
    }
    char key[128];
    snprintf(key, sizeof key, "%.*s", (int)(colon - line), line);
    if (!hx_program_key(squeeze(hx_trim(key)))) {
        *hash = '\0';
        return;
    }
    for (char *c = colon, q = 0; *c; c++) {
        if (*c == '#' && !q) {
            *c = '\0';
            return;
        }
        if (*c == '\'' || *c == '"')
            q = q == *c ? 0 : q ? q : *c;
    }
}

/* The key as the parser knows it: "scene" is "scenes". */
static const char *canonical_key(const char *key)
{
    int dim = dim_of_key(key);
    return dim >= 0 ? hx_dim_key[dim] : key;
}

/* The key of an override "KEY=VALUE" (harness run --set), canonical. */
static const char *override_key(const char *kv, char *buf, size_t n)
{
    snprintf(buf, n, "%.*s", (int)strcspn(kv, "="), kv);
    return canonical_key(hx_trim(buf));
}

/* Whether an override (cfg->set) gives key ("param n" is given by n=...). */
static int overridden(const HxConfig *cfg, const char *key)
{
    char buf[128];
    const char *param = strncmp(key, "param ", 6) == 0 ? key + 6 : NULL;
    for (size_t i = 0; i < cfg->set.n; i++) {
        const char *k = override_key(cfg->set.v[i], buf, sizeof buf);
        if (strcmp(k, canonical_key(key)) == 0 || (param && strcmp(k, param) == 0))
            return 1;
    }
    return 0;
}

/* One line of the config (line is modified). 0, or -1 with err set. */
static int parse_line(int lineno, char *line, HxConfig *cfg, int *seen_scalar,
                      char *err, size_t errlen)
{
    for (const unsigned char *c = (const unsigned char *)line; *c; c++)
        if (hx_is_ctrl(*c) && *c != '\t')
            /* names from here reach CSV cells, tables and Slurm scripts */
            return set_err(err, errlen, cfg, lineno, "control character 0x%02x in the line", *c);
    cut_comment(line);
    char *s = hx_trim(line);
    if (*s == '\0')
        return 0;
    char *colon = strchr(s, ':');
    if (!colon)
        return set_err(err, errlen, cfg, lineno, "expected 'key: values', got '%s'", s);
    *colon = '\0';
    char *key = squeeze(hx_trim(s));
    char *val = hx_trim(colon + 1);
    if (lineno > 0 && overridden(cfg, key)) {
        hx_strlist_push(&cfg->set_seen, key);
        return 0; /* harness run --set KEY=...: that line is replaced */
    }
    if (hx_program_key(key)) {
        char why[512];
        return hx_program_line(cfg, lineno, key, val, why, sizeof why) ? set_err(err, errlen, cfg, lineno, "%s", why)
                                                                       : 0;
    }
    HxStrList vals = {0};
    split_values(val, &vals);
    int rc = parse_key(lineno, key, &vals, cfg, seen_scalar, err, errlen);
    hx_strlist_free(&vals);
    return rc;
}

/* After the last line (lineno): the default study name, the checks across
 * keys, the defaults, and the scenes resolved to files. 0, or -1 with err
 * set. */
/* The scopes (`when`) of the swept keys, and the worker keys a backend
 * takes: `threads: 1 2` beside serial alone would plan serial runs only. */
static int finish_dims(HxConfig *cfg, char *err, size_t errlen)
{
    char why[256];
    for (int d = 0; d < HX_NDIM; d++)
        if (hx_scope_resolve(cfg, &cfg->dim_when[d], cfg->nparams, why, sizeof why) != 0)
            return set_err(err, errlen, cfg, cfg->dim_line[d], "%s: %s", hx_dim_key[d], why);
    static const int worker[2] = {HX_DIM_THREADS, HX_DIM_RANKS};
    for (int i = 0; i < 2 && !cfg->prog; i++) {
        int d = worker[i], used = 0;
        for (size_t b = 0; b < cfg->dim[HX_DIM_BACKEND].n; b++)
            used |= hx_dim_applies(d, cfg->dim[HX_DIM_BACKEND].v[b]);
        if (cfg->dim_line[d] && !used) { /* a warning: older configs did this */
            char w[512];
            set_err(w, sizeof w, cfg, cfg->dim_line[d], "warning: %s: no backend of the study takes it (backend: %s), "
                    "so no run sweeps it; add %s to backend", hx_dim_key[d], cfg->dim[HX_DIM_BACKEND].v[0],
                    d == HX_DIM_THREADS ? "openmp or mpi" : "mpi or mpi-cuda");
            hx_strlist_push(&cfg->warnings, w);
        }
    }
    return 0;
}

/* A command study: raytrace's keys refused, its program checked. */
static int finish_command(const int *seen_scalar, HxConfig *cfg, char *err, size_t errlen)
{
    for (int d = 0; d < HX_NDIM; d++)
        if (cfg->dim_line[d] && !hx_dim_applies(d, "-"))
            return set_err(err, errlen, cfg, cfg->dim_line[d], "key '%s' is raytrace's: a command study sweeps its "
                           "own parameters ('param NAME: VALUES')", hx_dim_key[d]);
    static const int raytrace_only[] = {1, 7, 10, 11}; /* scene_dir, raytrace, scene_cache, instructions */
    for (int i = 0; i < 4; i++)
        if (seen_scalar[raytrace_only[i]])
            return set_err(err, errlen, cfg, seen_scalar[raytrace_only[i]], "key '%s' is raytrace's, not for a "
                           "command study", scalar_keys[raytrace_only[i]]);
    if (cfg->extra_args.n)
        return set_err(err, errlen, cfg, cfg->prog->key_line[0] ? cfg->prog->key_line[0] : 1,
                       "extra_args is raytrace's: put the arguments in 'command:'");
    hx_strlist_push(&cfg->dim[HX_DIM_SCENE], "-");
    hx_strlist_push(&cfg->scene_path, "-");
    hx_strlist_push(&cfg->dim[HX_DIM_BACKEND], "-");
    if (!cfg->baseline)
        cfg->baseline = hx_strdup("workers=1");
    int line;
    char why[512];
    if (hx_program_finish(cfg, &line, why, sizeof why) != 0)
        return set_err(err, errlen, cfg, line, "%s", why);
    return 0;
}

/* After the last line (lineno): the default study name, the checks across
 * keys, the defaults, and the scenes resolved to files. 0, or -1 with err
 * set. */
static int config_finish(const char *path, int lineno, const int *seen_scalar, HxConfig *cfg,
                         char *err, size_t errlen)
{
    int rc = 0;
    if (!cfg->study) {
        /* Default study name: the config's file name without .conf. */
        const char *base = strrchr(path, '/');
        base = base ? base + 1 : path;
        size_t n = strlen(base);
        if (n > 5 && strcmp(base + n - 5, ".conf") == 0)
            n -= 5;
        cfg->study = hx_strndup(base, n);
    }
    if (!cfg->mpirun)
        cfg->mpirun = hx_strdup("mpirun");
    if (cfg->ceiling_rounds && !cfg->order_rounds) /* its rounds are the study's */
        return set_err(err, errlen, cfg, cfg->ceiling_line,
                       "ceiling: rounds measures the ceiling before each round of the study: it needs order: rounds");
    if (cfg->prog) {
        rc = finish_command(seen_scalar, cfg, err, errlen);
        fill_default_dims(cfg);
        return rc ? rc : finish_dims(cfg, err, errlen);
    }
    if (!cfg->dim_line[HX_DIM_SCENE])
        return set_err(err, errlen, cfg, lineno > 0 ? lineno : 1,
                       "missing required key 'scenes' (or 'command:' for a command study)");
    /* threads waiting in a barrier spin: only one thread counts exactly */
    for (size_t i = 0; cfg->instructions && i < cfg->dim[HX_DIM_BACKEND].n; i++)
        if (strcmp(cfg->dim[HX_DIM_BACKEND].v[i], "serial") != 0)
            return set_err(err, errlen, cfg, cfg->instructions_line,
                           "instructions: on counts serial runs only, but backends has '%s'",
                           cfg->dim[HX_DIM_BACKEND].v[i]);
    if (!cfg->baseline)
        cfg->baseline = hx_strdup("backend=serial");
    fill_default_dims(cfg);
    if (finish_dims(cfg, err, errlen) != 0)
        return -1;

    /* Resolve scenes now, so a missing file fails before any run starts. */
    int sline = cfg->dim_line[HX_DIM_SCENE];
    char *dir = resolve_dir(path, cfg->scene_dir ? cfg->scene_dir : ".", seen_scalar[1] < 0);
    if (!dir)
        return set_err(err, errlen, cfg, seen_scalar[1] ? seen_scalar[1] : sline,
                       "scene_dir '%s' is not a directory", cfg->scene_dir);
    for (size_t i = 0; i < cfg->dim[HX_DIM_SCENE].n; i++) {
        int amb;
        char *sp = find_scene(dir, cfg->dim[HX_DIM_SCENE].v[i], &amb);
        if (!sp) {
            rc = set_err(err, errlen, cfg, sline, "scene '%s' %s in '%s'",
                         cfg->dim[HX_DIM_SCENE].v[i],
                         amb ? "is ambiguous (several sub-folders have it)" : "not found",
                         dir);
            break;
        }
        hx_strlist_push(&cfg->scene_path, sp);
        free(sp);
    }
    free(dir);
    return rc;
}

/* A key of the config format (a param's bare NAME is not). */
static int known_key(const char *k)
{
    int known = dim_of_key(k) >= 0 || strcmp(k, "extra_args") == 0 || hx_program_key(k);
    for (int j = 0; scalar_keys[j]; j++)
        known |= strcmp(k, scalar_keys[j]) == 0;
    return known;
}

/* The overrides of `harness run --set` (cfg->set, "KEY=VALUE"), checked
 * before the file is read: the form, a known key, each key once. */
static int check_overrides(HxConfig *cfg, char *err, size_t errlen)
{
    for (size_t i = 0; i < cfg->set.n; i++) {
        const char *kv = cfg->set.v[i], *eq = strchr(kv, '=');
        int line = -(int)i - 1;
        if (!eq)
            return set_err(err, errlen, cfg, line, "expected KEY=VALUE (e.g. threads='1 2 4')");
        char key[128], other[128];
        const char *k = override_key(kv, key, sizeof key);
        int known = known_key(k);
        if (!*k)
            return set_err(err, errlen, cfg, line, "expected KEY=VALUE, the key is empty");
        /* NAME=VALUES may be a param of the config: known once it is read */
        known |= strspn(k, "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_") == strlen(k);
        if (!known)
            return set_err(err, errlen, cfg, line, "unknown key '%s'", k);
        for (size_t j = 0; j < i; j++)
            if (strcmp(override_key(cfg->set.v[j], other, sizeof other), k) == 0)
                return set_err(err, errlen, cfg, line, "key '%s' is given by --set twice", k);
    }
    return 0;
}

/* Each override as the line "KEY: VALUE", numbered -1, -2, ... */
static int parse_overrides(HxConfig *cfg, int *seen_scalar, char *err, size_t errlen)
{
    int rc = 0;
    for (size_t i = 0; i < cfg->set.n && rc == 0; i++) {
        const char *kv = cfg->set.v[i], *eq = strchr(kv, '=');
        HxBuf line = {0}, pk = {0};
        char key[128];
        const char *k = override_key(kv, key, sizeof key);
        int known = known_key(k);
        hx_buf_printf(&pk, "param %s", k);
        if (!known && hx_strlist_find(&cfg->set_seen, pk.s) < 0)
            rc = set_err(err, errlen, cfg, -(int)i - 1, "unknown key '%s'%s", k,
                         cfg->prog ? " (and no param of that name)" : "");
        else if (strncmp(k, "param ", 6) == 0 && hx_strlist_find(&cfg->set_seen, k) < 0)
            rc = set_err(err, errlen, cfg, -(int)i - 1, "'%s': the config has no param of that name", k);
        else if (!known) /* NAME=VALUES: the config's param NAME */
            hx_buf_put(&line, "param ");
        hx_buf_free(&pk);
        if (rc)
            break;
        hx_buf_putn(&line, kv, (size_t)(eq - kv));
        hx_buf_printf(&line, ": %s", eq + 1);
        rc = parse_line(-(int)i - 1, line.s, cfg, seen_scalar, err, errlen);
        hx_buf_free(&line);
    }
    return rc;
}

int hx_config_parse_string(const char *path, const char *text, HxConfig *cfg,
                           char *err, size_t errlen)
{
    return hx_config_parse_set(path, text, NULL, cfg, err, errlen);
}

int hx_config_parse_set(const char *path, const char *text, const HxStrList *set, HxConfig *cfg,
                        char *err, size_t errlen)
{
    config_defaults(cfg, path);
    for (size_t i = 0; set && i < set->n; i++)
        hx_strlist_push(&cfg->set, set->v[i]);
    int seen_scalar[16] = {0};
    int lineno = 0, rc = check_overrides(cfg, err, errlen);
    const char *p = text;
    if (strncmp(p, "\xEF\xBB\xBF", 3) == 0) /* a UTF-8 byte-order mark, as editors on Windows write */
        p += 3;
    while (*p && rc == 0) {
        const char *nl = strchr(p, '\n');
        size_t n = nl ? (size_t)(nl - p) : strlen(p);
        char *line = hx_strndup(p, n);
        p += n + (nl ? 1 : 0);
        lineno++;
        if (n && line[n - 1] == '\r') /* CRLF line ends */
            line[n - 1] = '\0';
        rc = parse_line(lineno, line, cfg, seen_scalar, err, errlen);
        free(line);
    }
    if (rc == 0)
        rc = parse_overrides(cfg, seen_scalar, err, errlen);
    if (rc)
        return rc;
    return config_finish(path, lineno, seen_scalar, cfg, err, errlen);
}

int hx_config_load(const char *path, HxConfig *cfg, char *err, size_t errlen)
{
    return hx_config_load_set(path, NULL, cfg, err, errlen);
}

int hx_config_load_set(const char *path, const HxStrList *set, HxConfig *cfg, char *err, size_t errlen)
{
    memset(cfg, 0, sizeof *cfg);
    HxBuf b = {0};
    if (hx_read_file(path, &b) != 0) {
        snprintf(err, errlen, "%s: cannot read config: %s", path, hx_read_error(errno));
        hx_buf_free(&b);
        return -1;
    }
    const char *nul = b.len ? memchr(b.s, '\0', b.len) : NULL;
    if (nul) { /* (the parser reads C strings: the rest of the line would vanish) */
        int line = 1;
        for (const char *p = b.s; p < nul; p++)
            line += *p == '\n';
        snprintf(err, errlen, "%s:%d: control character 0x00 in the line", path, line);
        hx_buf_free(&b);
        return -1;
    }
    int rc = hx_config_parse_set(path, b.s ? b.s : "", set, cfg, err, errlen);
    hx_buf_free(&b);
    double runs = rc == 0 ? hx_plan_size(cfg) : 0;
    if (runs > HX_MAX_RUNS && isinf(runs)) {
        snprintf(err, errlen, "%s: the study expands to more runs than the limit of %d (warm-ups included): "
                 "split it into several configs", path, HX_MAX_RUNS);
        rc = -1;
    } else if (runs > HX_MAX_RUNS) {
        snprintf(err, errlen, "%s: the study expands to %.0f runs (warm-ups included), more than the "
                 "limit of %d: split it into several configs", path, runs, HX_MAX_RUNS);
        rc = -1;
    }
    return rc;
}

int hx_config_open(const char *path, HxConfig *cfg)
{
    return hx_config_open_set(path, NULL, cfg);
}

int hx_config_open_set(const char *path, const HxStrList *set, HxConfig *cfg)
{
    char err[1024];
    if (hx_config_load_set(path, set, cfg, err, sizeof err) == 0)
        return 0;
    fprintf(stderr, "%s\n", err);
    hx_config_free(cfg);
    return -1;
}

void hx_config_free(HxConfig *cfg)
{
    free(cfg->path);
    free(cfg->study);
    for (int i = 0; i < HX_NDIM; i++)
        hx_strlist_free(&cfg->dim[i]);
    hx_strlist_free(&cfg->scene_path);
    hx_strlist_free(&cfg->extra_args);
    hx_strlist_free(&cfg->set);
    hx_strlist_free(&cfg->set_seen);
    hx_strlist_free(&cfg->warnings);
    for (int d = 0; d < HX_NDIM; d++)
        hx_scope_free(&cfg->dim_when[d]);
    hx_program_free(cfg);
    free(cfg->scene_dir);
    free(cfg->baseline);
    free(cfg->raytrace);
    free(cfg->mpirun);
    free(cfg->scene_cache);
    memset(cfg, 0, sizeof *cfg);
}

