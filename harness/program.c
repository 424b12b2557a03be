/* program.c: command studies, the harness running any program
 * (docs/harness.md, "Your own program").
 *
 * The config's `command:` is an argument vector with {KEY} placeholders,
 * replaced per run word by word and run without a shell, so a value reaches
 * the program as one argument, whatever it holds. Metrics and checks are
 * POSIX extended regular expressions over stdout, stderr or a file the run
 * wrote in its own folder (ReFrame's sanity and performance patterns). */
#include "program.h"
#include "run.h"

#include <errno.h>
#include <stdarg.h>
#include <fcntl.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static int fail(char *why, size_t n, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
static int fail(char *why, size_t n, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(why, n, fmt, ap);
    va_end(ap);
    return -1;
}

/* Keys that take one value, and their slot in key_line. */
static const char *const single_keys[] = {"command", "name", "version", "setup", "workdir", "exit", NULL};
/* Keys followed by a NAME. */
static const char *const named_keys[] = {"param", "env", "input", "template", "metric", NULL};

static int key_index(const char *const *set, const char *k, size_t n)
{
    for (int i = 0; set[i]; i++)
        if (strlen(set[i]) == n && strncmp(set[i], k, n) == 0)
            return i;
    return -1;
}

int hx_program_key(const char *key)
{
    size_t n = strcspn(key, " \t");
    if (key[n] == '\0')
        return key_index(single_keys, key, n) >= 0 || strcmp(key, "check") == 0;
    return key_index(named_keys, key, n) >= 0;
}

static struct HxProgram *prog_of(HxConfig *cfg)
{
    if (!cfg->prog) {
        cfg->prog = calloc(1, sizeof *cfg->prog);
        if (!cfg->prog)
            abort();
    }
    return cfg->prog;
}

int hx_words(const char *s, int commas, HxStrList *out, char *why, size_t n)
{
    HxBuf w = {0};
    int in_word = 0;
    for (const char *p = s;; p++) {
        if (*p == '\0' || *p == ' ' || *p == '\t' || (commas && *p == ',')) {
            if (in_word)
                hx_strlist_push(out, w.s ? w.s : "");
            w.len = 0;
            if (w.s)
                w.s[0] = '\0';
            in_word = 0;
            if (*p == '\0')
                break;
        } else if (*p == '\'' || *p == '"') {
            const char *end = strchr(p + 1, *p);
            if (!end) {
                snprintf(why, n, "unmatched %c", *p);
                hx_buf_free(&w);
                return -1;
            }
            hx_buf_putn(&w, p + 1, (size_t)(end - p - 1));
            hx_buf_put(&w, "");
            in_word = 1;
            p = end;
        } else {
            hx_buf_putn(&w, p, 1);
            in_word = 1;
        }
    }
    hx_buf_free(&w);
    return 0;
}

static void note_template(struct HxProgram *pg, const char *t, int line)
{
    hx_strlist_push(&pg->tmpl, t);
    pg->tmpl_line = hx_xrealloc(pg->tmpl_line, pg->tmpl.n * sizeof *pg->tmpl_line);
    pg->tmpl_line[pg->tmpl.n - 1] = line;
}

/* 'REGEX' [from stdout|stderr|FILE], then the words it did not use from
 * *at on. 0, or -1 with why. */
static int parse_match(const HxStrList *w, size_t *at, HxMatch *m, int line, char *why, size_t n)
{
    m->line = line;
    if (w->n == 0) {
        snprintf(why, n, "expected a regular expression in quotes");
        return -1;
    }
    m->pattern = hx_strdup(w->v[0]);
    int rc = regcomp(&m->re, m->pattern, REG_EXTENDED | REG_NEWLINE);
    if (rc != 0) {
        char msg[160];
        regerror(rc, &m->re, msg, sizeof msg);
        snprintf(why, n, "regular expression '%s' does not compile: %s", m->pattern, msg);
        return -1;
    }
    m->compiled = 1;
    *at = 1;
    if (w->n > 1 && strcmp(w->v[1], "from") == 0) {
        if (w->n < 3) {
            snprintf(why, n, "'from' needs stdout, stderr or a file name");
            return -1;
        }
        const char *f = w->v[2];
        m->from = strcmp(f, "stdout") == 0 ? HX_FROM_STDOUT : strcmp(f, "stderr") == 0 ? HX_FROM_STDERR : HX_FROM_FILE;
        if (m->from == HX_FROM_FILE) {
            /* a name in the run's own folder: nothing outside it */
            if (strchr(f, '/') || strcmp(f, ".") == 0 || strcmp(f, "..") == 0) {
                snprintf(why, n, "from '%s': a file name in the run's folder, without '/'", f);
                return -1;
            }
            m->file = hx_strdup(f);
        }
        *at = 3;
    }
    return 0;
}

static int parse_metric(struct HxProgram *pg, const char *name, const HxStrList *w, int line, char *why, size_t n)
{
    for (int i = 0; i < pg->nmetrics; i++)
        if (strcmp(pg->metrics[i].name, name) == 0) {
            snprintf(why, n, "metric '%s' already declared on line %d", name, pg->metrics[i].m.line);
            return -1;
        }
    pg->metrics = hx_xrealloc(pg->metrics, (size_t)(pg->nmetrics + 1) * sizeof *pg->metrics);
    HxMetric *mt = &pg->metrics[pg->nmetrics++];
    memset(mt, 0, sizeof *mt);
    mt->name = hx_strdup(name);
    size_t at = 0;
    if (parse_match(w, &at, &mt->m, line, why, n))
        return -1;
    mt->higher = -1;
    for (; at < w->n; at += 2) {
        const char *k = w->v[at], *v = at + 1 < w->n ? w->v[at + 1] : NULL;
        if (!v || (strcmp(k, "unit") != 0 && strcmp(k, "better") != 0)) {
            snprintf(why, n, "metric %s: expected 'unit UNIT' or 'better lower|higher', got '%s'", name, k);
            return -1;
        }
        if (strcmp(k, "unit") == 0) {
            if (hx_unit_direction(v) == -2) {
                snprintf(why, n, "metric %s: unknown unit '%s' (docs/harness.md, \"Units\")", name, v);
                return -1;
            }
            free(mt->unit);
            mt->unit = hx_strdup(v);
        } else if (strcmp(v, "lower") == 0 || strcmp(v, "higher") == 0) {
            mt->higher = strcmp(v, "higher") == 0;
        } else {
            snprintf(why, n, "metric %s: better: expected lower|higher, got '%s'", name, v);
            return -1;
        }
    }
    if (!mt->unit)
        mt->unit = hx_strdup("1");
    if (mt->higher < 0)
        mt->higher = hx_unit_direction(mt->unit);
    if (mt->higher < 0) {
        snprintf(why, n, "metric %s: unit '%s' has no direction: add 'better lower' or 'better higher'", name,
                 mt->unit);
        return -1;
    }
    return 0;
}

/* `param NAME: VALUES [when KEY=V,...]`: one more alternative of NAME. */
static int parse_param(HxConfig *cfg, const char *name, const char *raw, int line, char *why, size_t n)
{
    HxStrList words = {0}, vals = {0};
    HxScope sc = {0};
    int rc = hx_words(raw, 1, &words, why, n);
    if (rc == 0)
        rc = hx_split_when(&words, &sc, why, n);
    if (rc == 0)
        rc = hx_values_expand(&words, &vals, why, n);
    const char *twice = rc == 0 ? hx_strlist_twice(&vals) : NULL;
    if (twice) {
        snprintf(why, n, "param %s: value '%s' listed twice", name, twice);
        rc = -1;
    }
    hx_strlist_free(&words);
    if (rc) {
        hx_strlist_free(&vals);
        hx_scope_free(&sc);
        return -1;
    }
    int p = 0;
    while (p < cfg->nparams && strcmp(cfg->params[p].name, name) != 0)
        p++;
    if (p == cfg->nparams) {
        cfg->params = hx_xrealloc(cfg->params, (size_t)(cfg->nparams + 1) * sizeof *cfg->params);
        memset(&cfg->params[p], 0, sizeof cfg->params[p]);
        cfg->params[p].name = hx_strdup(name);
        cfg->nparams++;
    }
    HxParam *pr = &cfg->params[p];
    if (pr->nalt && (!sc.name || !pr->alt[pr->nalt - 1].when.name)) {
        snprintf(why, n, "param %s already set on line %d (several lines need a 'when' each)", name,
                 pr->alt[pr->nalt - 1].line);
        hx_strlist_free(&vals);
        hx_scope_free(&sc);
        return -1;
    }
    pr->alt = hx_xrealloc(pr->alt, (size_t)(pr->nalt + 1) * sizeof *pr->alt);
    pr->alt[pr->nalt++] = (HxParamAlt){vals, sc, line};
    return 0;
}

/* The single-valued keys: command, name, version, setup, workdir, exit. */
static int parse_single(struct HxProgram *pg, int k, const char *raw, const HxStrList *w, int line, char *why,
                        size_t n)
{
    if (pg->key_line[k]) {
        snprintf(why, n, "key '%s' already set on line %d", single_keys[k], pg->key_line[k]);
        return -1;
    }
    pg->key_line[k] = line;
    long v;
    switch (k) {
    case 0: case 2: case 3: {
        HxStrList *dst = k == 0 ? &pg->command : k == 2 ? &pg->version : &pg->setup;
        for (size_t i = 0; i < w->n; i++) {
            hx_strlist_push(dst, w->v[i]);
            note_template(pg, w->v[i], line);
        }
        return 0;
    }
    case 1:
        free(pg->name);
        pg->name = hx_strdup(raw);
        return 0;
    case 4:
        if (strcmp(raw, "keep") != 0 && strcmp(raw, "clean") != 0) {
            snprintf(why, n, "workdir: expected clean|keep, got '%s'", raw);
            return -1;
        }
        pg->keep = strcmp(raw, "keep") == 0;
        return 0;
    default:
        if (hx_parse_int(raw, 0, 255, &v)) {
            snprintf(why, n, "exit: expected an exit status 0..255, got '%s'", raw);
            return -1;
        }
        pg->exit_code = (int)v;
        return 0;
    }
}

/* A NAME after param, env, input, template or metric: a word that is safe
 * in a placeholder, a file name and a CSV key. */
int hx_program_good_name(const char *s, int file)
{
    if (!*s || strcmp(s, ".") == 0 || strcmp(s, "..") == 0)
        return 0;
    for (; *s; s++)
        if (!((*s >= 'a' && *s <= 'z') || (*s >= 'A' && *s <= 'Z') || (*s >= '0' && *s <= '9') || *s == '_' ||
              (file && (*s == '.' || *s == '-'))))
            return 0;
    return 1;
}

int hx_program_line(HxConfig *cfg, int lineno, const char *key, const char *raw, char *why, size_t n)
{
    struct HxProgram *pg = prog_of(cfg);
    size_t kn = strcspn(key, " \t");
    const char *name = key + kn;
    while (*name == ' ' || *name == '\t')
        name++;
    if (*raw == '\0') {
        snprintf(why, n, "key '%s' has no value", key);
        return -1;
    }
    HxStrList w = {0};
    if (hx_words(raw, 0, &w, why, n) != 0)
        return -1;
    int rc = 0, k = key_index(single_keys, key, kn), named = key_index(named_keys, key, kn);
    if (named >= 0 && !hx_program_good_name(name, named == 2 || named == 3))
        rc = fail(why, n, "%.*s: '%s' is not a name (letters, digits, _%s)", (int)kn, key, name,
                      named == 2 || named == 3 ? ", . and -" : "");
    else if (k >= 0)
        rc = parse_single(pg, k, raw, &w, lineno, why, n);
    else if (strcmp(key, "check") == 0) {
        pg->checks = hx_xrealloc(pg->checks, (size_t)(pg->nchecks + 1) * sizeof *pg->checks);
        HxMatch *m = &pg->checks[pg->nchecks++];
        memset(m, 0, sizeof *m);
        size_t at = 0;
        rc = parse_match(&w, &at, m, lineno, why, n);
        if (rc == 0 && at < w.n)
            rc = fail(why, n, "check: unexpected '%s' after the pattern", w.v[at]);
    } else if (named == 0) {
        rc = parse_param(cfg, name, raw, lineno, why, n);
    } else if (named == 4) {
        rc = parse_metric(pg, name, &w, lineno, why, n);
    } else {
        HxStrList *dst = named == 1 ? &pg->env : named == 2 ? &pg->inputs : &pg->templates;
        for (size_t i = 0; i < dst->n; i += 2)
            if (strcmp(dst->v[i], name) == 0)
                rc = fail(why, n, "%.*s %s given twice", (int)kn, key, name);
        if (rc == 0 && w.n != 1)
            rc = fail(why, n, "%.*s %s: one value (quote one with spaces)", (int)kn, key, name);
        if (rc == 0) {
            hx_strlist_push(dst, name);
            hx_strlist_push(dst, w.v[0]);
            note_template(pg, w.v[0], lineno);
        }
    }
    hx_strlist_free(&w);
    return rc;
}

int hx_unit_direction(const char *u)
{
    static const char *const lower[] = {"ns", "us", "ms", "s", "min", "B", "KiB", "MiB", "GiB", "kB", "MB", "GB", NULL};
    static const char *const higher[] = {"B/s", "kB/s", "MB/s", "GB/s", "KiB/s", "MiB/s", "GiB/s", "flop/s",
                                         "Mflop/s", "Gflop/s", "Tflop/s", "GUP/s", "ops/s", "items/s", NULL};
    if (key_index(lower, u, strlen(u)) >= 0)
        return 0;
    if (key_index(higher, u, strlen(u)) >= 0)
        return 1;
    return strcmp(u, "1") == 0 || strcmp(u, "%") == 0 ? -1 : -2;
}

double hx_unit_ms(const char *u)
{
    static const char *const times[] = {"ns", "us", "ms", "s", "min", NULL};
    static const double ms[] = {1e-6, 1e-3, 1, 1e3, 6e4};
    const int i = u ? key_index(times, u, strlen(u)) : -1;
    return i >= 0 ? ms[i] : 0;
}

int hx_subst(const char *t, const HxVars *vars, HxBuf *out, char *bad, size_t n)
{
    hx_buf_put(out, "");
    for (const char *p = t; *p; p++) {
        if ((p[0] == '{' && p[1] == '{') || (p[0] == '}' && p[1] == '}')) {
            hx_buf_putn(out, p++, 1);
            continue;
        }
        /* {NAME} with NAME a word is a placeholder; other braces (awk's,
         * JSON's) are text */
        size_t kl = p[0] == '{' && !(p[1] >= '0' && p[1] <= '9') ? strspn(p + 1, "abcdefghijklmnopqrstuvwxyz"
                                                                            "ABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_") : 0;
        const char *end = kl && p[kl + 1] == '}' ? p + kl + 1 : NULL;
        if (!end) {
            hx_buf_putn(out, p, 1);
            continue;
        }
        int k = -1;
        for (size_t i = 0; end && i < vars->k.n && k < 0; i++)
            if (strlen(vars->k.v[i]) == kl && strncmp(vars->k.v[i], p + 1, kl) == 0)
                k = (int)i;
        if (k < 0) {
            snprintf(bad, n, "%.*s", end ? (int)kl : 40, p + 1);
            return -1;
        }
        hx_buf_put(out, vars->v.v[k]);
        p = end;
    }
    return 0;
}

static void var(HxVars *vars, const char *k, const char *v)
{
    hx_strlist_push(&vars->k, k);
    hx_strlist_push(&vars->v, v);
}

void hx_vars_of_run(const HxConfig *cfg, const HxRun *r, const char *rundir, const char *workdir, HxVars *vars)
{
    memset(vars, 0, sizeof *vars);
    const char *t = r && strcmp(r->v[HX_DIM_THREADS], "-") != 0 ? r->v[HX_DIM_THREADS] : "1";
    const char *p = r && strcmp(r->v[HX_DIM_RANKS], "-") != 0 ? r->v[HX_DIM_RANKS] : "1";
    char w[32];
    snprintf(w, sizeof w, "%d", r ? r->workers : 1);
    var(vars, "threads", t);
    var(vars, "ranks", p);
    var(vars, "workers", w);
    for (int i = 0; i < cfg->nparams; i++)
        var(vars, cfg->params[i].name, r && r->pv ? r->pv[i] : cfg->params[i].alt[0].vals.v[0]);
    var(vars, "rundir", rundir);
    var(vars, "workdir", workdir);
    var(vars, "confdir", cfg->prog && cfg->prog->confdir ? cfg->prog->confdir : ".");
}

void hx_vars_free(HxVars *vars)
{
    hx_strlist_free(&vars->k);
    hx_strlist_free(&vars->v);
}

/* argv[0] of a command that starts elsewhere (the run's folder): a relative
 * path made absolute now; a bare name must be on PATH. */
static int locate(HxStrList *argv, char *why, size_t n)
{
    const char *a0 = argv->v[0];
    if (strchr(a0, '{'))
        return 0;
    char *abs = hx_which(a0);
    if (!abs)
        return fail(why, n, "program '%s' %s", a0, strchr(a0, '/') ? "not found or not executable" : "not found on PATH");
    if (strchr(a0, '/')) {
        free(argv->v[0]);
        argv->v[0] = abs;
    } else {
        free(abs); /* a name stays a name: the run's PATH finds it */
    }
    return 0;
}

/* Template name's file at path, read into text: 0, or -1 with why (it
 * cannot be read, or holds a NUL byte, which hx_subst's C strings would
 * cut it at). */
static int template_text(const char *name, const char *path, HxBuf *text, char *why, size_t n)
{
    if (hx_read_file(path, text) != 0)
        return fail(why, n, "template %s: %s: %s", name, path, hx_read_error(errno));
    if (text->len && memchr(text->s, '\0', text->len))
        return fail(why, n, "template %s: %s holds a NUL byte: not a text file", name, path);
    return 0;
}

/* Each template's placeholders known, each template file's text too. */
static int check_placeholders(const HxConfig *cfg, int *line, char *why, size_t n)
{
    const struct HxProgram *pg = cfg->prog;
    HxVars vars;
    hx_vars_of_run(cfg, NULL, "/RUNDIR", "/WORKDIR", &vars);
    HxBuf out = {0};
    char bad[64];
    int rc = 0;
    for (size_t i = 0; rc == 0 && i < pg->tmpl.n; i++) {
        out.len = 0;
        if (hx_subst(pg->tmpl.v[i], &vars, &out, bad, sizeof bad) != 0) {
            *line = pg->tmpl_line[i];
            rc = fail(why, n, "unknown placeholder {%s} (known: threads, ranks, workers, rundir, workdir, confdir "
                      "and the params)", bad);
        }
    }
    for (size_t i = 0; rc == 0 && i < pg->templates.n; i += 2) {
        const char *p = pg->templates.v[i + 1];
        HxBuf text = {0}, path = {0};
        /* a path with no placeholder but {confdir} can be checked now */
        if (!strchr(strstr(p, "{confdir}") == p ? p + 9 : p, '{')) {
            hx_subst(p, &vars, &path, bad, sizeof bad);
            if (template_text(pg->templates.v[i], path.s, &text, why, n) != 0)
                rc = -1;
            else if (hx_subst(text.s ? text.s : "", &vars, &out, bad, sizeof bad) != 0)
                rc = fail(why, n, "template %s: %s has an unknown placeholder {%s}", pg->templates.v[i], path.s, bad);
        }
        for (size_t k = 0; rc && k < pg->tmpl.n; k++)
            if (pg->tmpl.v[k] == p || strcmp(pg->tmpl.v[k], p) == 0)
                *line = pg->tmpl_line[k];
        hx_buf_free(&text);
        hx_buf_free(&path);
    }
    hx_buf_free(&out);
    hx_vars_free(&vars);
    return rc;
}

int hx_program_finish(HxConfig *cfg, int *line, char *why, size_t n)
{
    struct HxProgram *pg = cfg->prog;
    *line = 0;
    if (!pg->command.n) {
        *line = pg->tmpl.n ? pg->tmpl_line[0] : cfg->nparams ? cfg->params[0].alt[0].line : 1;
        return fail(why, n, "a command study needs 'command:' (the program and its arguments)");
    }
    char *cd = hx_dirname(cfg->path);
    pg->confdir = realpath(cd, NULL);
    free(cd);
    if (!pg->confdir)
        pg->confdir = hx_strdup(".");
    if (!pg->name) {
        const char *b = strrchr(pg->command.v[0], '/');
        pg->name = hx_strdup(b ? b + 1 : pg->command.v[0]);
    }
    for (int p = 0; p < cfg->nparams; p++)
        for (int a = 0; a < cfg->params[p].nalt; a++)
            if (hx_scope_resolve(cfg, &cfg->params[p].alt[a].when, p, why, n) != 0) {
                char msg[512];
                snprintf(msg, sizeof msg, "param %s: %s", cfg->params[p].name, why);
                snprintf(why, n, "%s", msg);
                *line = cfg->params[p].alt[a].line;
                return -1;
            }
    HxStrList *cmds[3] = {&pg->command, &pg->version, &pg->setup};
    for (int i = 0; i < 3; i++)
        if (cmds[i]->n && locate(cmds[i], why, n) != 0) {
            *line = pg->key_line[i == 0 ? 0 : i == 1 ? 2 : 3];
            return -1;
        }
    return check_placeholders(cfg, line, why, n);
}

static void match_free(HxMatch *m)
{
    free(m->pattern);
    free(m->file);
    if (m->compiled)
        regfree(&m->re);
}

void hx_program_free(HxConfig *cfg)
{
    for (int p = 0; p < cfg->nparams; p++) {
        for (int a = 0; a < cfg->params[p].nalt; a++) {
            hx_strlist_free(&cfg->params[p].alt[a].vals);
            hx_scope_free(&cfg->params[p].alt[a].when);
        }
        free(cfg->params[p].alt);
        free(cfg->params[p].name);
    }
    free(cfg->params);
    cfg->params = NULL;
    cfg->nparams = 0;
    struct HxProgram *pg = cfg->prog;
    if (!pg)
        return;
    HxStrList *lists[] = {&pg->command, &pg->version, &pg->setup, &pg->env, &pg->inputs, &pg->templates, &pg->tmpl};
    for (size_t i = 0; i < sizeof lists / sizeof lists[0]; i++)
        hx_strlist_free(lists[i]);
    for (int i = 0; i < pg->nmetrics; i++) {
        free(pg->metrics[i].name);
        free(pg->metrics[i].unit);
        match_free(&pg->metrics[i].m);
    }
    for (int i = 0; i < pg->nchecks; i++)
        match_free(&pg->checks[i]);
    free(pg->metrics);
    free(pg->checks);
    free(pg->tmpl_line);
    free(pg->name);
    free(pg->confdir);
    free(pg);
    cfg->prog = NULL;
}

void hx_program_command(const HxConfig *cfg, const HxVars *vars, HxCommand *c)
{
    const struct HxProgram *pg = cfg->prog;
    HxBuf b = {0};
    char bad[64];
    for (size_t i = 0; i < pg->command.n; i++) {
        b.len = 0;
        hx_subst(pg->command.v[i], vars, &b, bad, sizeof bad); /* checked when the config was read */
        hx_strlist_push(&c->argv, b.s);
    }
    for (size_t i = 0; i < pg->env.n; i += 2) {
        b.len = 0;
        hx_subst(pg->env.v[i + 1], vars, &b, bad, sizeof bad);
        hx_strlist_push(&c->env, pg->env.v[i]);
        hx_strlist_push(&c->env, b.s);
    }
    hx_buf_free(&b);
}

/* The file NAME in dir, written whole with text. 0 or -1 (errno). */
static int write_new(const char *dir, const char *name, const char *text, size_t len)
{
    char *p = hx_path_join(dir, name);
    int fd = open(p, O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0644);
    free(p);
    if (fd < 0)
        return -1;
    int rc = write(fd, text, len) == (ssize_t)len ? 0 : -1;
    return close(fd) != 0 ? -1 : rc;
}

int hx_program_prepare(const HxConfig *cfg, const HxVars *vars, const char *rundir, char *why, size_t n)
{
    const struct HxProgram *pg = cfg->prog;
    if (mkdir(rundir, 0700) != 0)
        return fail(why, n, "cannot make the run's folder %s: %s", rundir, strerror(errno));
    HxBuf path = {0}, text = {0}, out = {0};
    char bad[64];
    int rc = 0;
    for (size_t i = 0; rc == 0 && i < pg->inputs.n; i += 2) {
        path.len = 0;
        hx_subst(pg->inputs.v[i + 1], vars, &path, bad, sizeof bad);
        char *abs = realpath(path.s, NULL), *dst = hx_path_join(rundir, pg->inputs.v[i]);
        if (!abs || symlink(abs, dst) != 0)
            rc = fail(why, n, "input %s: %s: %s", pg->inputs.v[i], path.s, strerror(errno));
        free(abs);
        free(dst);
    }
    for (size_t i = 0; rc == 0 && i < pg->templates.n; i += 2) {
        path.len = out.len = 0;
        hx_subst(pg->templates.v[i + 1], vars, &path, bad, sizeof bad);
        if (template_text(pg->templates.v[i], path.s, &text, why, n) != 0)
            rc = -1;
        else if (hx_subst(text.s ? text.s : "", vars, &out, bad, sizeof bad) != 0)
            rc = fail(why, n, "template %s: unknown placeholder {%s} in %s", pg->templates.v[i], bad, path.s);
        else if (write_new(rundir, pg->templates.v[i], out.s, out.len) != 0)
            rc = fail(why, n, "template %s: cannot write it: %s", pg->templates.v[i], strerror(errno));
        hx_buf_free(&text);
    }
    hx_buf_free(&path);
    hx_buf_free(&out);
    return rc;
}

/* The text a match reads: stdout, stderr, or a file of the run's folder (at
 * most 64 MiB, never through a link the run left). 0, or -1 with why. */
static int match_text(const HxMatch *m, const char *rundir, const HxBuf *out, const HxBuf *err, HxBuf *own,
                      const char **text, char *why, size_t n)
{
    if (m->from != HX_FROM_FILE) {
        const HxBuf *b = m->from == HX_FROM_STDOUT ? out : err;
        *text = b->s ? b->s : "";
        return 0;
    }
    char *p = hx_path_join(rundir, m->file);
    /* O_NONBLOCK: a FIFO there would block the open, and the harness with it */
    int fd = open(p, O_RDONLY | O_NOFOLLOW | O_CLOEXEC | O_NONBLOCK);
    free(p);
    if (fd < 0)
        return fail(why, n, "%s: the run wrote no such file (%s)", m->file, strerror(errno));
    struct stat st;
    if (fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
        close(fd);
        return fail(why, n, "%s: not a regular file", m->file);
    }
    char chunk[65536];
    ssize_t r;
    while ((r = read(fd, chunk, sizeof chunk)) > 0 && own->len < (64u << 20))
        hx_buf_putn(own, chunk, (size_t)r);
    close(fd);
    hx_buf_put(own, "");
    *text = own->s;
    return 0;
}

static const char *from_name(const HxMatch *m)
{
    return m->from == HX_FROM_STDOUT ? "stdout" : m->from == HX_FROM_STDERR ? "stderr" : m->file;
}

/* The value of the metric's last match (its first group, else all of it). */
int hx_match_number(const regex_t *re, const char *text, double *v, char *num, size_t n)
{
    regmatch_t g[2];
    const char *at = NULL;
    size_t len = 0;
    for (const char *p = text; *p && regexec(re, p, 2, g, p == text ? 0 : REG_NOTBOL) == 0;
         p += g[0].rm_eo > 0 ? g[0].rm_eo : 1) {
        int k = g[1].rm_so >= 0 ? 1 : 0; /* the first group, else the match */
        at = p + g[k].rm_so;
        len = (size_t)(g[k].rm_eo - g[k].rm_so);
    }
    snprintf(num, n, "%.*s", (int)len, at ? at : "");
    if (!at)
        return -1;
    /* a decimal number, whole: not cut to fit num, not hex (strtod reads
     * 0x10 as 16), not inf or nan */
    const char *t = hx_trim(num);
    if (len >= n || strpbrk(t, "xXpP") || hx_parse_double(t, v) != 0 || !isfinite(*v))
        return -2;
    return 0;
}

static int metric_value(const HxMetric *mt, const char *text, double *v, char *why, size_t n)
{
    char num[64];
    int rc = hx_match_number(&mt->m.re, text, v, num, sizeof num);
    if (rc == -1)
        return fail(why, n, "metric %s: '%s' not found in %s", mt->name, mt->m.pattern, from_name(&mt->m));
    if (rc == -2)
        return fail(why, n, "metric %s: '%.40s' from %s is not a decimal number", mt->name, num, from_name(&mt->m));
    /* a time, a size or a rate below zero is a misread, not a measurement */
    if (*v < 0 && mt->unit && strcmp(mt->unit, "1") != 0 && strcmp(mt->unit, "%") != 0)
        return fail(why, n, "metric %s: %s %s from %s is negative", mt->name, num, mt->unit, from_name(&mt->m));
    return 0;
}

int hx_program_collect(const HxConfig *cfg, const char *rundir, const HxBuf *out, const HxBuf *err, HxBuf *extra,
                       char *why, size_t n)
{
    const struct HxProgram *pg = cfg->prog;
    HxBuf own = {0};
    const char *text;
    int rc = 0;
    for (int i = 0; rc == 0 && i < pg->nchecks; i++) {
        own.len = 0;
        const HxMatch *m = &pg->checks[i];
        if (match_text(m, rundir, out, err, &own, &text, why, n) != 0)
            rc = -1;
        else if (regexec(&m->re, text, 0, NULL, 0) != 0)
            rc = fail(why, n, "check failed: '%s' not found in %s", m->pattern, from_name(m));
    }
    for (int i = 0; rc == 0 && i < pg->nmetrics; i++) {
        own.len = 0;
        double v;
        if (match_text(&pg->metrics[i].m, rundir, out, err, &own, &text, why, n) != 0 ||
            metric_value(&pg->metrics[i], text, &v, why, n) != 0)
            rc = -1;
        else
            hx_buf_printf(extra, "%s%s=%.12g", extra->len ? ";" : "", pg->metrics[i].name, v);
    }
    hx_buf_free(&own);
    return rc;
}

char *hx_program_metric_info(const HxConfig *cfg)
{
    HxBuf b = {0};
    hx_buf_put(&b, "");
    for (int i = 0; cfg->prog && i < cfg->prog->nmetrics; i++) {
        const HxMetric *m = &cfg->prog->metrics[i];
        hx_buf_printf(&b, "%s%s:%s:%s", i ? ";" : "", m->name, m->unit, m->higher ? "higher" : "lower");
    }
    return b.s;
}

/* The argv of a study-wide command (version, setup), placeholders replaced;
 * NULL-terminated, malloc'd. */
static char **study_argv(const HxConfig *cfg, const HxStrList *t, const char *workdir)
{
    HxVars vars;
    hx_vars_of_run(cfg, NULL, workdir, workdir, &vars);
    char **argv = hx_xmalloc((t->n + 1) * sizeof *argv);
    char bad[64];
    for (size_t i = 0; i < t->n; i++) {
        HxBuf b = {0};
        hx_subst(t->v[i], &vars, &b, bad, sizeof bad);
        argv[i] = b.s;
    }
    argv[t->n] = NULL;
    hx_vars_free(&vars);
    return argv;
}

static void argv_free(char **argv)
{
    for (size_t i = 0; argv[i]; i++)
        free(argv[i]);
    free(argv);
}

char *hx_program_version(const HxConfig *cfg)
{
    if (!cfg->prog || !cfg->prog->version.n)
        return hx_strdup("-");
    char **argv = study_argv(cfg, &cfg->prog->version, ".");
    HxBuf text = {0};
    int rc = hx_run_limited(argv, NULL, cfg->timeout_s, &text, 0);
    argv_free(argv);
    char out[512];
    snprintf(out, sizeof out, "%s", text.s ? text.s : "");
    hx_buf_free(&text);
    char *s = out + strspn(out, " \t\r\n");
    s[strcspn(s, "\r\n")] = '\0';
    for (char *p = s; *p; p++)
        if (hx_is_ctrl((unsigned char)*p))
            *p = '?';
    if (rc != 0 || !*s) /* (the study runs on; its rows say program_version -) */
        fprintf(stderr, "harness: warning: %s:%d: version: %s; program_version is '-'\n", cfg->path,
                cfg->prog->key_line[2],
                rc == 124 ? "still running at the study's timeout, ended" : rc ? "failed" : "printed nothing");
    return hx_strdup(rc == 0 && *s ? s : "-");
}

int hx_program_setup(const HxConfig *cfg, const char *workdir, char *why, size_t n)
{
    if (!cfg->prog || !cfg->prog->setup.n)
        return 0;
    char **argv = study_argv(cfg, &cfg->prog->setup, workdir);
    int rc = hx_run_limited(argv, workdir, cfg->timeout_s, NULL, 1);
    argv_free(argv);
    if (rc == 124)
        return fail(why, n, "%s:%d: setup: still running after the study's timeout (%g s); ended", cfg->path,
                    cfg->prog->key_line[3], cfg->timeout_s);
    return rc == 0 ? 0 : fail(why, n, "%s:%d: setup: exited with status %d", cfg->path, cfg->prog->key_line[3], rc);
}
