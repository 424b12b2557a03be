/* resume.c: what `harness run --resume` accepts of an existing CSV.
 *
 * A study may grow (more repeats, new values of a swept key) or be
 * continued after a stop: every row already in the CSV must still be a run
 * of the plan, made under the same settings. Those settings are the study
 * name, the scene files (scene_dir), the baseline, warm-ups, timeout,
 * instructions and extra_args: the first three are columns of each row and
 * compared as such, the rest go into the row's config_hash. The plan
 * (repeats, swept values) is not in the hash: a row is matched to the plan
 * by its run_id (docs/harness.md, "Growing a study"). */
#include "program.h"
#include "run.h"

#include <stdlib.h>
#include <string.h>

void hx_settings_hash(const HxConfig *cfg, char out[20])
{
    HxBuf b = {0};
    hx_buf_printf(&b, "settings|%s|%d|%.17g", cfg->study, cfg->warmup, cfg->timeout_s);
    if (cfg->instructions)
        hx_buf_put(&b, "|instructions");
    for (size_t i = 0; i < cfg->extra_args.n; i++)
        hx_buf_printf(&b, "|%s", cfg->extra_args.v[i]);
    if (cfg->prog) { /* what a command study's run is, but its swept params */
        const struct HxProgram *pg = cfg->prog;
        const HxStrList *lists[] = {&pg->command, &pg->env, &pg->inputs, &pg->templates};
        for (size_t l = 0; l < sizeof lists / sizeof lists[0]; l++)
            for (size_t i = 0; i < lists[l]->n; i++)
                hx_buf_printf(&b, "|%zu:%s", l, lists[l]->v[i]);
        for (int i = 0; i < pg->nmetrics; i++)
            hx_buf_printf(&b, "|m:%s:%s:%s", pg->metrics[i].name, pg->metrics[i].m.pattern, pg->metrics[i].unit);
        for (int i = 0; i < pg->nchecks; i++)
            hx_buf_printf(&b, "|c:%s", pg->checks[i].pattern);
        hx_buf_printf(&b, "|exit:%d", pg->exit_code);
    }
    hx_fnv1a_hex(b.s, out);
    hx_buf_free(&b);
}

/* The config_hash harness versions before growing studies wrote: the same
 * settings plus repeats and every planned run id. Rows that carry it are
 * accepted when this config makes the same plan. */
static void legacy_hash(const HxConfig *cfg, const HxPlan *plan, char out[20])
{
    HxBuf b = {0};
    hx_buf_printf(&b, "%s|%d|%d|%.17g", cfg->study, cfg->repeats, cfg->warmup, cfg->timeout_s);
    if (cfg->instructions)
        hx_buf_put(&b, "|instructions");
    for (size_t i = 0; i < cfg->extra_args.n; i++)
        hx_buf_printf(&b, "|%s", cfg->extra_args.v[i]);
    for (size_t i = 0; i < plan->n; i++)
        hx_buf_printf(&b, "|%s", plan->runs[i].run_id);
    hx_fnv1a_hex(b.s, out);
    hx_buf_free(&b);
}

static int cmp_run_id(const void *a, const void *b)
{
    return strcmp((*(const HxRun *const *)a)->run_id, (*(const HxRun *const *)b)->run_id);
}

/* Why row i, whose run_id the plan lacks, is not planned: a swept value the
 * config no longer lists, or a repeat beyond its repeats. */
static void why_unplanned(const HxCsv *old, size_t i, const HxConfig *cfg, char *why, size_t n)
{
    for (int d = 0; d < HX_NDIM; d++) {
        const char *v = hx_csv_get(old, i, hx_dim_col[d]);
        if (strcmp(v, "-") != 0 && hx_strlist_find(&cfg->dim[d], v) < 0) {
            snprintf(why, n, "the config's %s no longer has '%s'", hx_dim_key[d], v);
            return;
        }
    }
    for (int k = 0; k < cfg->nparams; k++) { /* a param's value the config no longer lists in any line */
        char v[256];
        if (!hx_kv_get(hx_csv_get(old, i, "params"), cfg->params[k].name, v, sizeof v) || strcmp(v, "-") == 0)
            continue;
        int listed = 0;
        for (int a = 0; a < cfg->params[k].nalt && !listed; a++)
            listed = hx_strlist_find(&cfg->params[k].alt[a].vals, v) >= 0;
        if (!listed) {
            snprintf(why, n, "the config's param %s no longer has '%.100s'", cfg->params[k].name, v);
            return;
        }
    }
    long rep = -1;
    if (hx_parse_int(hx_csv_get(old, i, "repeat"), 0, 1000000, &rep) == 0 && rep >= cfg->repeats) {
        snprintf(why, n, "repeat %ld is beyond 'repeats: %d' (a resume does not drop rows)", rep,
                 cfg->repeats);
        return;
    }
    snprintf(why, n, "another study wrote them");
}

/* Row i against the config and its planned run r (NULL: none): the columns
 * that fix what a run means. 0, or -1 with err saying what changed. */
static int row_matches(const HxCsv *old, size_t i, const HxConfig *cfg, const HxRun *r, char *err,
                       size_t errlen)
{
    const char *study = hx_csv_get(old, i, "study"), *scene = hx_csv_get(old, i, "scene_path");
    const char *base = hx_csv_get(old, i, "baseline");
    if (strcmp(study, cfg->study) != 0)
        snprintf(err, errlen, "its runs were made for study '%s', the config now says '%s'", study, cfg->study);
    else if (r && strcmp(scene, r->scene_path) != 0)
        snprintf(err, errlen, "its runs were made with scene %s, the config now gives %s (scene_dir %s)", scene,
                 r->scene_path, cfg->scene_dir ? cfg->scene_dir : ".");
    else if (strcmp(base, cfg->baseline) != 0) /* table reads the first row's */
        snprintf(err, errlen, "its runs were made with baseline %s, the config now says %s", base, cfg->baseline);
    else
        return 0;
    return -1;
}

int hx_resume_check(const HxCsv *old, const HxConfig *cfg, const HxPlan *plan, const char *hash, char *err,
                    size_t errlen)
{
    char legacy[20];
    legacy_hash(cfg, plan, legacy);
    const HxRun **sorted = hx_xmalloc((plan->n ? plan->n : 1) * sizeof *sorted);
    for (size_t k = 0; k < plan->n; k++)
        sorted[k] = &plan->runs[k];
    qsort(sorted, plan->n, sizeof *sorted, cmp_run_id);
    size_t foreign = 0, other_hash = 0, example = 0;
    const char *old_hash = NULL;
    int rc = 0;
    for (size_t i = 0; i < old->nrows && rc == 0; i++) {
        HxRun key = {.run_id = (char *)hx_csv_get(old, i, "run_id")};
        const HxRun *kp = &key, **hit = bsearch(&kp, sorted, plan->n, sizeof *sorted, cmp_run_id);
        if (!hit && !foreign++)
            example = i;
        rc = row_matches(old, i, cfg, hit ? *hit : NULL, err, errlen);
        const char *h = hx_csv_get(old, i, "config_hash");
        if (strcmp(h, hash) != 0 && strcmp(h, legacy) != 0) {
            other_hash++;
            old_hash = h;
        }
    }
    free(sorted);
    if (rc == 0 && foreign) {
        char why[256];
        why_unplanned(old, example, cfg, why, sizeof why);
        snprintf(err, errlen, "%zu row(s) are runs this config does not plan (e.g. '%s'): %s", foreign,
                 hx_csv_get(old, example, "run_id"), why);
        rc = -1;
    } else if (rc == 0 && other_hash) {
        snprintf(err, errlen, "%zu row(s) come from a configuration with other settings (warm-ups, timeout, "
                 "instructions or extra_args; config_hash %s, this config %s)", other_hash, old_hash, hash);
        rc = -1;
    }
    return rc;
}
