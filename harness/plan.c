/* plan.c: the run matrix: a config's swept keys and params expanded into
 * runs, value lists with ranges, and `when` scopes.
 *
 * Nesting order, outermost first: scene, backend, the params in the order
 * declared, then the other dimensions (hx.h's HX_DIM_* order), repeats
 * innermost; with `order: rounds`, repeats outermost within a scene. A scope may only name a key outside the one it scopes, so
 * whether a key applies is known when its turn comes. */
#include "hx.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define MAX_PARAMS 64

/* The values raytrace's dimensions take. */
static const char *const backends[] = {"serial", "openmp", "mpi", "cuda", "mpi-cuda", NULL};
static const char *const accels[] = {"none", "bvh", NULL};
static const char *const schedules[] = {"tiles", "pixels", NULL};
static const char *const mpi_schedules[] = {"dynamic", "rows", NULL};
static const char *const pins[] = {"none", "close", "spread", NULL};

static int in_set(const char *v, const char *const *set)
{
    for (; *set; set++)
        if (strcmp(v, *set) == 0)
            return 1;
    return 0;
}

static void set_join(char *out, size_t n, const char *const *set)
{
    out[0] = '\0';
    for (const char *const *s = set; *s; s++) {
        if (s != set)
            strncat(out, "|", n - strlen(out) - 1);
        strncat(out, *s, n - strlen(out) - 1);
    }
}

int hx_dim_value_check(int dim, const char *v, char *why, size_t n)
{
    const char *const *set = NULL;
    long a, b;
    /* block: "-" is the renderer's default, which depends on the image
     * (docs/gpu.md, large images), swept beside explicit shapes */
    if (dim == HX_DIM_BLOCK && strcmp(v, "-") == 0)
        return 0;
    switch (dim) {
    case HX_DIM_BACKEND: set = backends; break;
    case HX_DIM_ACCEL: set = accels; break;
    case HX_DIM_SCHEDULE: set = schedules; break;
    case HX_DIM_MPI_SCHEDULE: set = mpi_schedules; break;
    case HX_DIM_PIN: set = pins; break;
    case HX_DIM_THREADS:
    case HX_DIM_RANKS:
        if (hx_parse_int(v, 1, 4096, &a)) {
            snprintf(why, n, "expected an integer 1..4096, got '%s'", v);
            return -1;
        }
        return 0;
    case HX_DIM_MAX_DEPTH:
        if (hx_parse_int(v, 0, 32, &a)) { /* raytrace's RT_MAX_DEPTH */
            snprintf(why, n, "expected an integer 0..32, got '%s'", v);
            return -1;
        }
        return 0;
    case HX_DIM_TILE:
    case HX_DIM_BLOCK:
    case HX_DIM_RESOLUTION:
        if (hx_parse_wxh(v, &a, &b)) {
            snprintf(why, n, "expected WxH (e.g. 16x16), got '%s'", v);
            return -1;
        }
        /* the renderer's own limits, so a study fails here, not run by run */
        if (dim == HX_DIM_RESOLUTION && (a > 32768 || b > 32768 || a * b > (1L << 28))) {
            snprintf(why, n, "resolution %s exceeds raytrace's limit (32768 per side, 2^28 pixels)", v);
            return -1;
        }
        if (dim == HX_DIM_TILE && (a > 4096 || b > 4096)) {
            snprintf(why, n, "tile %s exceeds raytrace's limit (4096 per side)", v);
            return -1;
        }
        if (dim == HX_DIM_BLOCK && a * b > 1024) {
            snprintf(why, n, "block %s has more than 1024 threads", v);
            return -1;
        }
        return 0;
    default:
        return 0;
    }
    if (!in_set(v, set)) {
        char opts[128];
        set_join(opts, sizeof opts, set);
        snprintf(why, n, "expected one of %s, got '%s'", opts, v);
        return -1;
    }
    return 0;
}


static int scope_holds(const HxScope *sc, const char *const v[HX_NDIM], const char *const *pv)
{
    if (sc->key < 0)
        return 1;
    const char *val = sc->key == HX_SCOPE_BACKEND ? v[HX_DIM_BACKEND] : pv[sc->key];
    return hx_strlist_find(&sc->vals, val) >= 0;
}

/* The values param p takes under the outer values (NULL: out of scope). */
static const HxStrList *param_values(const HxParam *p, const char *const v[HX_NDIM], const char *const *pv)
{
    for (int a = 0; a < p->nalt; a++)
        if (scope_holds(&p->alt[a].when, v, pv))
            return &p->alt[a].vals;
    return NULL;
}

/* Whether dimension d (not scene or backend) is swept under these values. */
static int dim_on(const HxConfig *cfg, int d, const char *const v[HX_NDIM], const char *const *pv)
{
    return hx_dim_applies(d, v[HX_DIM_BACKEND]) && scope_holds(&cfg->dim_when[d], v, pv);
}

/* Counting twin of expand_rec: slot 1 is the backend, 2.. the params. */
static double count_rec(const HxConfig *cfg, const char *v[HX_NDIM], const char **pv, int slot)
{
    if (slot == 1) {
        double n = 0;
        for (size_t b = 0; b < cfg->dim[HX_DIM_BACKEND].n; b++) {
            v[HX_DIM_BACKEND] = cfg->dim[HX_DIM_BACKEND].v[b];
            n += count_rec(cfg, v, pv, 2);
        }
        return n;
    }
    int p = slot - 2;
    if (p < cfg->nparams) {
        const HxStrList *vals = param_values(&cfg->params[p], v, pv);
        if (!vals) {
            pv[p] = "-";
            return count_rec(cfg, v, pv, slot + 1);
        }
        double n = 0;
        size_t i = 0;
        for (; i < vals->n && n <= HX_MAX_RUNS; i++) {
            pv[p] = vals->v[i];
            n += count_rec(cfg, v, pv, slot + 1);
        }
        return i < vals->n ? INFINITY : n; /* (over the limit, counted no further) */
    }
    double n = (double)cfg->dim[HX_DIM_SCENE].n * (double)(cfg->repeats + cfg->warmup);
    for (int d = HX_DIM_BACKEND + 1; d < HX_NDIM; d++)
        if (cfg->dim[d].n && dim_on(cfg, d, v, pv))
            n *= (double)cfg->dim[d].n;
    return n;
}

double hx_plan_size(const HxConfig *cfg)
{
    const char *v[HX_NDIM], *pv[MAX_PARAMS];
    for (int d = 0; d < HX_NDIM; d++)
        v[d] = "-";
    return cfg->nparams > MAX_PARAMS ? INFINITY : count_rec(cfg, v, pv, 1);
}

char *hx_make_config_id(const char *const v[HX_NDIM], const char *params)
{
    /* A readable, stable key: the same run gets the same id in every study,
     * which is what --resume and `compare` match on. */
    HxBuf b = {0};
    int command = strcmp(v[HX_DIM_BACKEND], "-") == 0;
    for (int d = 0; d < HX_NDIM; d++) {
        if (command && d != HX_DIM_THREADS && d != HX_DIM_RANKS && d != HX_DIM_PIN)
            continue;
        hx_buf_printf(&b, "%s%s=%s", b.len ? " " : "", hx_dim_col[d], v[d]);
    }
    for (const char *p = params; p && *p;) {
        size_t n = strcspn(p, ";");
        hx_buf_put(&b, " ");
        hx_buf_putn(&b, p, n);
        p += n + (p[n] == ';');
    }
    return b.s;
}

char *hx_run_params(const HxConfig *cfg, const HxRun *r)
{
    HxBuf b = {0};
    hx_buf_put(&b, "");
    for (int p = 0; p < cfg->nparams; p++)
        hx_buf_printf(&b, "%s%s=%s", p ? ";" : "", cfg->params[p].name, r->pv[p]);
    return b.s;
}

static void push_run(HxPlan *plan, size_t *cap, const HxConfig *cfg, const char *const v[HX_NDIM],
                     const char *const *pv, size_t scene_idx, int repeat, int warmup)
{
    if (plan->n == *cap) {
        *cap = *cap ? 2 * *cap : 64;
        plan->runs = hx_xrealloc(plan->runs, *cap * sizeof *plan->runs);
    }
    HxRun *r = &plan->runs[plan->n++];
    memset(r, 0, sizeof *r);
    for (int d = 0; d < HX_NDIM; d++)
        r->v[d] = v[d];
    if (cfg->nparams) {
        r->pv = hx_xmalloc((size_t)cfg->nparams * sizeof *r->pv);
        memcpy(r->pv, pv, (size_t)cfg->nparams * sizeof *r->pv);
    }
    r->scene_path = cfg->scene_path.v[scene_idx];
    r->scene_name = v[HX_DIM_SCENE];
    r->repeat = repeat;
    r->warmup = warmup;
    long w = 1, t = 1;
    if (strcmp(v[HX_DIM_THREADS], "-") != 0)
        hx_parse_int(v[HX_DIM_THREADS], 1, 4096, &w);
    if (hx_run_is_mpi(v) && strcmp(v[HX_DIM_RANKS], "-") != 0)
        hx_parse_int(v[HX_DIM_RANKS], 1, 4096, &t);
    r->workers = (int)(w * t);
    char *params = cfg->nparams ? hx_run_params(cfg, r) : NULL;
    r->config_id = hx_make_config_id(v, params);
    free(params);
    HxBuf b = {0};
    hx_buf_printf(&b, "%s #r%d", r->config_id, repeat);
    r->run_id = b.s;
}

typedef struct {
    const HxConfig *cfg;
    HxPlan *plan;
    size_t cap;
    const char *v[HX_NDIM];
    const char *pv[MAX_PARAMS];
    size_t scene_idx;
} Expand;

/* The dimensions after the params (d from HX_DIM_BACKEND + 1), then the
 * repeats. */
static void expand_dims(Expand *e, int d)
{
    const HxConfig *cfg = e->cfg;
    if (d == HX_NDIM) {
        for (int w = 0; w < cfg->warmup; w++)
            push_run(e->plan, &e->cap, cfg, e->v, e->pv, e->scene_idx, w - cfg->warmup, 1);
        for (int r = 0; r < cfg->repeats; r++)
            push_run(e->plan, &e->cap, cfg, e->v, e->pv, e->scene_idx, r, 0);
        return;
    }
    if (!dim_on(cfg, d, e->v, e->pv)) {
        e->v[d] = "-";
        expand_dims(e, d + 1);
        return;
    }
    for (size_t i = 0; i < cfg->dim[d].n; i++) {
        e->v[d] = cfg->dim[d].v[i];
        expand_dims(e, d + 1);
    }
}

static void expand_params(Expand *e, int p)
{
    if (p == e->cfg->nparams) {
        expand_dims(e, HX_DIM_BACKEND + 1);
        return;
    }
    const HxStrList *vals = param_values(&e->cfg->params[p], e->v, e->pv);
    if (!vals) {
        e->pv[p] = "-";
        expand_params(e, p + 1);
        return;
    }
    for (size_t i = 0; i < vals->n; i++) {
        e->pv[p] = vals->v[i];
        expand_params(e, p + 1);
    }
}

/* `order: rounds`: within a scene, round k (warm-ups first) runs every
 * configuration once, in the nested order, so that a drift of the machine
 * over the study reaches every worker count alike instead of whichever ran
 * during it: a one-worker baseline measured in a quiet minute skews every
 * efficiency in the table. Keys: scene block, repeat, position. */
typedef struct {
    size_t block, pos;
    int repeat;
} RoundKey;

static int round_cmp(const void *a, const void *b)
{
    const RoundKey *x = a, *y = b;
    if (x->block != y->block)
        return x->block < y->block ? -1 : 1;
    if (x->repeat != y->repeat)
        return x->repeat < y->repeat ? -1 : 1;
    return x->pos < y->pos ? -1 : x->pos > y->pos;
}

static void order_rounds(HxPlan *plan)
{
    RoundKey *k = hx_xmalloc((plan->n ? plan->n : 1) * sizeof *k);
    for (size_t i = 0, block = 0; i < plan->n; i++) {
        if (i && plan->runs[i].scene_path != plan->runs[i - 1].scene_path)
            block++;
        k[i] = (RoundKey){block, i, plan->runs[i].repeat};
    }
    qsort(k, plan->n, sizeof *k, round_cmp);
    HxRun *runs = hx_xmalloc((plan->n ? plan->n : 1) * sizeof *runs);
    for (size_t i = 0; i < plan->n; i++)
        runs[i] = plan->runs[k[i].pos];
    free(plan->runs);
    plan->runs = runs;
    free(k);
}

int hx_expand(const HxConfig *cfg, HxPlan *plan)
{
    memset(plan, 0, sizeof *plan);
    if (cfg->nparams > MAX_PARAMS)
        return -1;
    Expand e = {.cfg = cfg, .plan = plan};
    for (int d = 0; d < HX_NDIM; d++)
        e.v[d] = "-";
    const HxStrList *sc = &cfg->dim[HX_DIM_SCENE], *be = &cfg->dim[HX_DIM_BACKEND];
    for (size_t s = 0; s < sc->n; s++) {
        e.v[HX_DIM_SCENE] = sc->v[s];
        e.scene_idx = s;
        /* serial first (the image reference), then the config's order */
        for (int pass = 0; pass < 2; pass++)
            for (size_t i = 0; i < be->n; i++) {
                if ((strcmp(be->v[i], "serial") == 0) != (pass == 0))
                    continue;
                e.v[HX_DIM_BACKEND] = be->v[i];
                expand_params(&e, 0);
            }
    }
    if (cfg->order_rounds)
        order_rounds(plan);
    return 0;
}

void hx_plan_free(HxPlan *plan)
{
    for (size_t i = 0; i < plan->n; i++) {
        free(plan->runs[i].config_id);
        free(plan->runs[i].run_id);
        free(plan->runs[i].cores);
        free(plan->runs[i].cores_planned);
        free(plan->runs[i].pv);
    }
    free(plan->runs);
    memset(plan, 0, sizeof *plan);
}

/* "A..B" with an optional next token "+S" or "*F" into out. 1 when tok was a
 * range (*used: tokens taken), 0 when not, -1 on error. */
static int expand_range(const char *tok, const char *next, HxStrList *out, int *used, char *why, size_t n)
{
    const char *dots = strstr(tok, "..");
    if (!dots)
        return 0;
    char a_s[32], op = '+';
    long a, b, step = 1;
    snprintf(a_s, sizeof a_s, "%.*s", (int)(dots - tok), tok);
    if (hx_parse_int(a_s, -1000000000L, 1000000000L, &a) || hx_parse_int(dots + 2, -1000000000L, 1000000000L, &b)) {
        snprintf(why, n, "range '%s': expected integers A..B", tok);
        return -1;
    }
    *used = 1;
    if (next && (next[0] == '+' || next[0] == '*')) {
        op = next[0];
        *used = 2;
        if (hx_parse_int(next + 1, 1, 1000000000L, &step) || (op == '*' && step < 2)) {
            snprintf(why, n, "range '%s %s': the step is +S (S >= 1) or *F (F >= 2)", tok, next);
            return -1;
        }
    }
    if (b < a || (op == '*' && a < 1)) {
        snprintf(why, n, "range '%s': %s", tok, b < a ? "the end is below the start" : "a factor needs a start >= 1");
        return -1;
    }
    char num[32];
    size_t count = 0;
    for (long x = a; x <= b; x = op == '*' ? x * step : x + step) {
        if (++count > 100000) {
            snprintf(why, n, "range '%s' has more than 100000 values", tok);
            return -1;
        }
        snprintf(num, sizeof num, "%ld", x);
        hx_strlist_push(out, num);
    }
    return 1;
}

int hx_values_expand(const HxStrList *in, HxStrList *out, char *why, size_t n)
{
    for (size_t i = 0; i < in->n; i++) {
        const char *t = in->v[i];
        int used = 0;
        int rc = expand_range(t, i + 1 < in->n ? in->v[i + 1] : NULL, out, &used, why, n);
        if (rc < 0)
            return -1;
        if (rc == 0 && (t[0] == '+' || t[0] == '*') && t[1] >= '0' && t[1] <= '9') {
            snprintf(why, n, "'%s' follows no range (write A..B %s)", t, t);
            return -1;
        }
        if (rc == 0)
            hx_strlist_push(out, t);
        else
            i += (size_t)used - 1;
    }
    return 0;
}

int hx_split_when(HxStrList *vals, HxScope *sc, char *why, size_t n)
{
    sc->key = -1;
    sc->name = NULL;
    int at = hx_strlist_find(vals, "when");
    if (at < 0)
        return 0;
    /* "when mode=omp,mpi" arrives split at the comma: KEY=V then Vs */
    const char *kv = (size_t)at + 1 < vals->n ? vals->v[at + 1] : "";
    const char *eq = strchr(kv, '=');
    if (!eq || eq == kv || eq[1] == '\0') {
        snprintf(why, n, "expected 'when KEY=VALUE[,VALUE...]' at the end, got 'when %s'", kv);
        return -1;
    }
    sc->name = hx_strndup(kv, (size_t)(eq - kv));
    hx_strlist_push(&sc->vals, eq + 1);
    for (size_t i = (size_t)at + 2; i < vals->n; i++)
        hx_strlist_push(&sc->vals, vals->v[i]);
    while (vals->n > (size_t)at)
        free(vals->v[--vals->n]);
    if (at == 0) {
        snprintf(why, n, "no values before 'when'");
        return -1;
    }
    return 0;
}

int hx_scope_resolve(const HxConfig *cfg, HxScope *sc, int upto, char *why, size_t n)
{
    const HxStrList *known = NULL;
    HxStrList all = {0};
    const char *key = sc->name;
    sc->key = -1;
    if (!key)
        return 0;
    if (strcmp(key, "backend") == 0 && !cfg->prog) {
        sc->key = HX_SCOPE_BACKEND;
        known = &cfg->dim[HX_DIM_BACKEND];
    }
    for (int p = 0; p < upto && sc->key < 0; p++)
        if (strcmp(cfg->params[p].name, key) == 0) {
            sc->key = p;
            for (int a = 0; a < cfg->params[p].nalt; a++)
                for (size_t i = 0; i < cfg->params[p].alt[a].vals.n; i++)
                    hx_strlist_push(&all, cfg->params[p].alt[a].vals.v[i]);
            known = &all;
        }
    int rc = 0;
    if (sc->key < 0) {
        snprintf(why, n, "when %s=...: '%s' is not %s declared before this line", key, key,
                 cfg->prog ? "a param" : "backend or a param");
        rc = -1;
    }
    for (size_t i = 0; rc == 0 && i < sc->vals.n; i++)
        if (hx_strlist_find(known, sc->vals.v[i]) < 0) {
            snprintf(why, n, "when %s=%s: %s has no value '%s'", key, sc->vals.v[i], key, sc->vals.v[i]);
            rc = -1;
        }
    hx_strlist_free(&all);
    return rc;
}

void hx_scope_free(HxScope *sc)
{
    hx_strlist_free(&sc->vals);
    free(sc->name);
    memset(sc, 0, sizeof *sc);
}
