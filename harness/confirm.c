/* confirm.c: `history check --confirm CONFIG`: a step found in stored
 * history is re-measured before it counts. Stored runs of two commits were
 * made at different times, perhaps one of them on a busy machine, so a
 * step between them may be the machine's. Both commits are built (the
 * builder, scripts/build-commit.sh) and the step's configuration is run
 * with both builds interleaved (hx_ab_config, as `harness ab --config`).
 * The step is confirmed when that finds the same change; otherwise, or
 * when a commit cannot be built, it stays unconfirmed. */
#include "history.h"
#include "run.h"

#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* The raytrace built from commit sha, NULL with why. Each commit is built
 * once per check (c->built holds sha, path pairs; c->failed the commits
 * that did not build). */
static char *build(HxConfirm *c, const char *sha, char *why, size_t n)
{
    for (size_t i = 0; i + 1 < c->built.n; i += 2)
        if (strcmp(c->built.v[i], sha) == 0)
            return hx_strdup(c->built.v[i + 1]);
    for (size_t i = 0; i < c->failed.n; i++)
        if (strcmp(c->failed.v[i], sha) == 0) {
            snprintf(why, n, "commit %s could not be built (above)", sha);
            return NULL;
        }
    HxCommand cmd;
    memset(&cmd, 0, sizeof cmd);
    HxBuf dir = {0};
    hx_buf_printf(&dir, "%s/%s", c->dir, sha);
    hx_strlist_push(&cmd.argv, c->builder);
    hx_strlist_push(&cmd.argv, sha);
    hx_strlist_push(&cmd.argv, dir.s);
    hx_command_terminate(&cmd);
    hx_put_clean_line(stderr, "harness history check: building %s (%s %s %s)", sha, c->builder, sha, dir.s);
    HxChildResult res;
    int rc = hx_run_child(&cmd, NULL, NULL, 3600, &res);
    char *path = NULL;
    if (rc == 0 && res.exited && res.code == 0 && res.out.s) {
        char *out = res.out.s;
        size_t len = strlen(out);
        while (len && (out[len - 1] == '\n' || out[len - 1] == ' '))
            out[--len] = '\0';
        char *last = strrchr(out, '\n');
        path = hx_strdup(last ? last + 1 : out);
    }
    if (!path || access(path, X_OK) != 0) {
        const char *e = res.err.s && *res.err.s ? res.err.s : "no raytrace path on its output";
        snprintf(why, n, "commit %s could not be built: %.*s", sha, (int)strcspn(e, "\n"), rc ? "builder not started" : e);
        hx_strlist_push(&c->failed, sha);
        free(path);
        path = NULL;
    } else {
        hx_strlist_push(&c->built, sha);
        hx_strlist_push(&c->built, path);
    }
    hx_child_result_free(&res);
    hx_command_free(&cmd);
    hx_buf_free(&dir);
    return path;
}

int hx_confirm_step(HxConfirm *c, const char *config_id, const char *settings, const char *before, const char *at,
                    const char *key, int higher, int slower)
{
    char why[1024] = "";
    char *rt[2] = {NULL, NULL};
    HxConfig cfg;
    char hash[20] = "";
    if (hx_config_open(c->config, &cfg) == 0) {
        hx_settings_hash(&cfg, hash);
        hx_config_free(&cfg);
    }
    if (!*hash)
        snprintf(why, sizeof why, "%s could not be read (above)", c->config);
    else if (settings && *settings && strcmp(settings, hash) != 0)
        snprintf(why, sizeof why, "%s's settings (config_hash %s) are not the series' (%s): not the work measured",
                 c->config, hash, settings);
    else if ((rt[0] = build(c, before, why, sizeof why)) != NULL)
        rt[1] = build(c, at, why, sizeof why);
    int confirmed = 0;
    if (rt[0] && rt[1]) {
        HxAbTally t;
        fflush(stdout);
        if (hx_ab_config(c->config, NULL, (const char *const *)rt, config_id, key, higher, &c->rule, &t, NULL) != 0)
            snprintf(why, sizeof why, "the re-measurement failed (above)");
        else if (slower ? t.regressions : t.improvements)
            confirmed = 1;
        else
            snprintf(why, sizeof why, "the interleaved re-measurement of %s against %s does not show it (%s)", at,
                     before, t.inconclusive ? "inconclusive" : t.regressions + t.improvements ? "the opposite change"
                                                                                           : "no change");
    }
    if (confirmed)
        hx_put_clean_line(stdout, "  CONFIRMED: %s against %s, %d interleaved rounds on this machine", at, before,
                          c->rule.rounds);
    else
        hx_put_clean_line(stdout, "  unconfirmed: %s", why);
    free(rt[0]);
    free(rt[1]);
    return confirmed;
}

void hx_confirm_free(HxConfirm *c)
{
    hx_strlist_free(&c->built);
    hx_strlist_free(&c->failed);
}
