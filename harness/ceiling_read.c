/* ceiling_read.c: the machine's ceiling as `table`, `plot` and `report`
 * read it (docs/harness-noise.md, "Ceiling"): a file of `harness ceiling`,
 * or the one `harness run` writes beside its CSV with `ceiling: rounds`,
 * whose rows of one worker count (one per round) are pooled. */
#include "run.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* The median of the finite (or, with nonneg, the non-negative) values of
 * v[0..n-1]; NAN (or -1) where none is. */
static double median_of(const double *v, int n, int nonneg)
{
    double *k = hx_xmalloc((size_t)(n ? n : 1) * sizeof *k);
    size_t m = 0;
    for (int i = 0; i < n; i++)
        if (nonneg ? v[i] >= 0 : isfinite(v[i]))
            k[m++] = v[i];
    const double r = m ? hx_median(k, m) : nonneg ? -1 : NAN;
    free(k);
    return r;
}

/* Whether two rows' scenes are one (NULL: a file without the column). */
static int same_scene(const char *a, const char *b)
{
    return a && b ? strcmp(a, b) == 0 : a == b;
}

/* Whether row p is a ceiling of scene: its own, or one of any scene (a
 * file without the column). */
static int fits_scene(const HxCeilPoint *p, const char *scene)
{
    return !p->scene || (scene && strcmp(p->scene, scene) == 0);
}

/* Several rows of one scene and worker count (`harness run` with `ceiling:
 * rounds` writes one per round) become one: the median of each figure
 * over the rounds, which sampled the same minutes as the study's runs. */
static void pool_rounds(HxStudy *s)
{
    int n = 0;
    double *buf = hx_xmalloc((size_t)(s->nceil ? s->nceil : 1) * sizeof *buf);
    s->ceil_rounds = 1;
    for (int i = 0; i < s->nceil; i++) {
        HxCeilPoint *p = &s->ceil[i];
        int k = 0, seen = 0;
        for (int j = 0; j < n && !seen; j++)
            seen = s->ceil[j].w == p->w && same_scene(s->ceil[j].scene, p->scene);
        if (seen) {
            free(p->scene);
            continue;
        }
        double out[4];
        for (int f = 0; f < 4; f++) {
            k = 0;
            for (int j = i; j < s->nceil; j++)
                if (s->ceil[j].w == p->w && same_scene(s->ceil[j].scene, p->scene))
                    buf[k++] = f == 0 ? s->ceil[j].r : f == 1 ? s->ceil[j].t : f == 2 ? s->ceil[j].s : s->ceil[j].steal;
            out[f] = median_of(buf, k, f == 3);
        }
        s->ceil_rounds = k > s->ceil_rounds ? k : s->ceil_rounds;
        /* n <= i: rows not yet read are past it */
        s->ceil[n++] = (HxCeilPoint){p->scene, p->w, out[0], out[3], out[1], out[2], -1};
    }
    s->nceil = n;
    free(buf);
}

/* c's rows of the study's fingerprint and metric into s (pooled); who and
 * path name them in what is said. */
static void read_rows(HxStudy *s, const HxCsv *c, const char *who, const char *path, const char *fp)
{
    /* a ceiling of another metric is no ceiling of this one; files
     * without the column are of the copies' wall time, used with a line
     * that says so (docs/harness-noise.md, "Ceiling") */
    const int has_metric = hx_csv_col(c, "metric") >= 0, has_steal = hx_csv_col(c, "steal_pct") >= 0,
              has_together = hx_csv_col(c, "together") >= 0, has_step = hx_csv_col(c, "step") >= 0,
              has_scene = hx_csv_col(c, "scene") >= 0, has_round = hx_csv_col(c, "round") >= 0;
    size_t other = 0;
    if (!has_metric && strcmp(s->metric, "wall_ms") != 0)
        fprintf(stderr, "%s: --ceiling: %s has no metric column: a ceiling of the copies' wall time, read against "
                        "%s\n", who, path, s->metric);
    for (size_t r = 0; r < c->nrows; r++) {
        long w, round;
        double v, st, tg, sh;
        if (strcmp(hx_csv_get(c, r, "fingerprint"), fp) != 0 ||
            hx_parse_int(hx_csv_get(c, r, "workers"), 2, 1 << 20, &w) ||
            hx_parse_double(hx_csv_get(c, r, "ratio_median"), &v) || !(v > 0))
            continue;
        if (has_metric && strcmp(hx_csv_get(c, r, "metric"), s->metric) != 0) {
            if (!other++)
                fprintf(stderr, "%s: --ceiling: %s measures %s, this table reads %s: not used\n", who, path,
                        hx_csv_get(c, r, "metric"), s->metric);
            continue;
        }
        const char *scene = has_scene ? hx_csv_get(c, r, "scene") : "";
        if (*scene && hx_strlist_find(&s->scenes, scene) < 0) /* another study's scene */
            continue;
        s->ceil = hx_xrealloc(s->ceil, (size_t)(s->nceil + 1) * sizeof *s->ceil);
        HxCeilPoint *p = &s->ceil[s->nceil++];
        p->scene = *scene ? hx_strdup(scene) : NULL;
        p->w = (int)w;
        p->r = v;
        p->s = has_step && hx_parse_double(hx_csv_get(c, r, "step"), &sh) == 0 && sh > 0 && sh <= 1.5 ? sh : NAN;
        p->t = has_together && hx_parse_double(hx_csv_get(c, r, "together"), &tg) == 0 && tg > 0 ? tg : NAN;
        p->steal = has_steal && hx_parse_double(hx_csv_get(c, r, "steal_pct"), &st) == 0 && st >= 0 ? st : -1;
        p->round = has_round && hx_parse_int(hx_csv_get(c, r, "round"), 0, 1 << 30, &round) == 0 ? (int)round : -1;
    }
    /* the rounds as measured, for each run's pace against its own round */
    for (int i = 0; i < s->nceil; i++)
        if (s->ceil[i].round >= 0) {
            s->ceil_round = hx_xrealloc(s->ceil_round, (size_t)(s->nceil_round + 1) * sizeof *s->ceil_round);
            s->ceil_round[s->nceil_round] = s->ceil[i];
            s->ceil_round[s->nceil_round++].scene = s->ceil[i].scene ? hx_strdup(s->ceil[i].scene) : NULL;
        }
    pool_rounds(s);
}

/* Whether the ceiling has rows for scene (or rows of any scene). */
static int has_scene_rows(const HxStudy *s, const char *scene)
{
    for (int i = 0; i < s->nceil; i++)
        if (fits_scene(&s->ceil[i], scene))
            return 1;
    return 0;
}

int hx_ceiling_load(HxStudy *s, const char *who, const char *file, const char *csv_path)
{
    const char *fp = s->csv.nrows ? hx_csv_get(&s->csv, 0, "fingerprint") : "";
    HxBuf name = {0};
    hx_buf_printf(&name, "ceiling-%s.csv", fp);
    char *dir = hx_dirname(csv_path), *own = hx_ceiling_rounds_path(csv_path);
    const char *cand[4] = {file, NULL, NULL, NULL};
    char *beside = hx_path_join(dir, name.s), *inres = hx_path_join("results", name.s);
    if (!file) { /* the study's own rounds (ceiling: rounds) first */
        cand[1] = own;
        cand[2] = beside;
        cand[3] = inres;
    }
    HxCsv c;
    char err[512];
    int rc = 0;
    /* the first file with rows of this study's machine and metric: one
     * found but of another, or empty, leaves the next its turn */
    for (int i = 0; i < 4 && !s->nceil && rc == 0; i++) {
        if (!cand[i] || (!file && !hx_file_exists(cand[i])))
            continue;
        if (hx_csv_read(cand[i], &c, err, sizeof err) != 0) {
            fprintf(stderr, "%s: --ceiling: %s\n", who, err);
            rc = -1;
            break;
        }
        if (hx_csv_col(&c, "ratio_median") < 0) {
            fprintf(stderr, "%s: --ceiling: %s: not a ceiling file (no ratio_median column)\n", who, cand[i]);
            rc = -1;
        } else {
            read_rows(s, &c, who, cand[i], fp);
            if (s->nceil) /* nothing of it applies: no ceiling named in the table */
                s->ceil_path = hx_strdup(cand[i]);
            if (file && !s->nceil)
                fprintf(stderr, "%s: --ceiling: %s has no row of this study's machine, metric and scenes: not used\n",
                        who, file);
            for (size_t k = 0; k < s->scenes.n && s->nceil; k++)
                if (!has_scene_rows(s, s->scenes.v[k]))
                    fprintf(stderr, "%s: --ceiling: %s has no row of scene %s: its efficiency is not read against "
                                    "a ceiling\n", who, cand[i], s->scenes.v[k]);
        }
        hx_csv_free(&c);
    }
    free(dir);
    free(own);
    free(beside);
    free(inres);
    hx_buf_free(&name);
    return rc;
}

double hx_ceiling_at(const HxStudy *s, const char *scene, int workers, double *together, double *step)
{
    /* the scene's own before one of any scene */
    const HxCeilPoint *p = NULL;
    for (int i = 0; i < s->nceil; i++)
        if (s->ceil[i].w == workers && fits_scene(&s->ceil[i], scene))
            p = !p || !p->scene ? &s->ceil[i] : p;
    if (together)
        *together = p ? p->t : NAN;
    if (step)
        *step = p ? p->s : NAN;
    return p ? p->r : NAN;
}

double hx_ceiling_paired_pace(const HxStudy *s, const HxGroup *g)
{
    if (!g->nt || g->workers < 2)
        return NAN;
    double *pace = hx_xmalloc(g->nt * sizeof *pace);
    size_t n = 0;
    for (size_t k = 0; k < g->nt; k++) {
        const HxCeilPoint *p = NULL;
        for (int i = 0; i < s->nceil_round && !p; i++) {
            const HxCeilPoint *q = &s->ceil_round[i];
            if (q->w == g->workers && q->round == g->rep[k] && fits_scene(q, g->scene))
                p = q;
        }
        if (!p || !isfinite(p->t) || !(g->t[k] > 0))
            break;
        pace[n++] = (s->higher ? g->t[k] / p->t : p->t / g->t[k]) / g->workers;
    }
    const double r = n == g->nt ? hx_median(pace, n) : NAN;
    free(pace);
    return r;
}

void hx_ceiling_para(const HxStudy *s, HxBuf *b)
{
    hx_buf_printf(b, "Efficiency (a) also against this machine's ceiling from %s: \"0.750 (1.07 of 0.70)\" is "
                  "1.07 of the 0.70 that independent copies keep at that many workers.", s->ceil_path);
    if (s->ceil_rounds > 1) /* ceiling: rounds */
        hx_buf_printf(b, " Each figure of it is the median of %d rounds measured between the study's own%s",
                      s->ceil_rounds, s->nceil_round ? "; a pace is the median of each run's against the copies "
                                                       "of its own round (where every run's round has them)."
                                                     : ".");
    /* a study's runs with more steal than the copies had lose more than
     * the ceiling says: the user compares the two */
    int steals = 0, paced = 0, stepped = 0, scenes = 0;
    for (int i = 0; i < s->nceil; i++)
        scenes |= s->ceil[i].scene && !same_scene(s->ceil[i].scene, s->ceil[0].scene);
    for (int i = 0; i < s->nceil; i++)
        if (s->ceil[i].steal >= 0) {
            hx_buf_printf(b, "%s%.1f%% at %d", steals++ ? ", " : " Its copies ran with CPU steal of ", s->ceil[i].steal,
                          s->ceil[i].w);
            if (scenes && s->ceil[i].scene) /* each scene's copies are its own work */
                hx_buf_printf(b, " (%s)", s->ceil[i].scene);
        }
    if (steals)
        hx_buf_put(b, " workers (the runs' own: the column steal_pct).");
    for (int i = 0; i < s->nceil; i++) {
        paced |= isfinite(s->ceil[i].t);
        stepped |= isfinite(s->ceil[i].s);
    }
    if (paced)
        hx_buf_put(b, " \"pace 1.04\": the run is 1.04 times as fast as W workers that split the work perfectly at "
                      "the speed each of W copies at once kept: the same share without the one-worker time, which was "
                      "measured alone and at another moment.");
    if (stepped)
        hx_buf_put(b, " \"pace 0.74 of 0.83\": W workers that each did their share of that work at once, released "
                      "together, kept 0.83 of it from the first's start to the last's end on this machine: the pace "
                      "that its noise leaves a run whose workers must all end.");
}
