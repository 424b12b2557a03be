/* confirm.c: `history check --confirm CONFIG`: a step found in stored
 * history is re-measured before it counts. Stored runs of two commits were
 * made at different times, perhaps one of them on a busy machine, so a
 * step between them may be the machine's, and noise in the windows may put
 * a real step at a neighbour. The commits at the two ends of the step's
 * windows are built (the builder, scripts/build-commit.sh) and the step's
 * configuration is run with both builds interleaved (hx_ab_config, as
 * `harness ab --config`). Only when that shows a change is it confirmed,
 * and then bisected to its commit with the same re-measurement (asv's
 * `find` and git bisect do the same over commits). A commit that cannot be
 * built leaves the step unconfirmed. */
#include "history.h"
#include "run.h"

#include <math.h>
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
        int el;
        const char *e = hx_first_line(res.err.s, &el);
        if (rc || !el) {
            e = rc ? "builder not started" : "no raytrace path on its output";
            el = (int)strlen(e);
        }
        snprintf(why, n, "commit %s could not be built: %.*s", sha, el, e);
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

enum { WORSE = 1, BETTER = -1, SAME = 0, UNSURE = 3, FAILED = -2 };

/* Commit b against commit a in configuration config_id, re-measured
 * interleaved. With mid 0, the verdict at the rule's factor: WORSE, BETTER,
 * SAME (no change) or UNSURE. With mid (the geometric middle of a change
 * already confirmed), which side of it b's cost lies on: WORSE above it,
 * SAME below, UNSURE when the interval straddles it. UNSURE is measured
 * again with twice the rounds; FAILED (why) when a build or run failed. */
static int change(HxConfirm *c, const char *config_id, const char *a, const char *b, const char *key, int higher,
                  double mid, double *cost, char *why, size_t n)
{
    char *rt[2] = {build(c, a, why, n), NULL};
    if (rt[0])
        rt[1] = build(c, b, why, n);
    int r = rt[0] && rt[1] ? UNSURE : FAILED;
    HxAbRule rule = c->rule;
    for (int tries = 0; r == UNSURE && tries < 2; tries++, rule.rounds *= 2) {
        HxAbTally t;
        printf("  re-measuring %s against %s, %d rounds:\n", b, a, rule.rounds);
        fflush(stdout);
        if (hx_ab_config(c->config, NULL, (const char *const *)rt, config_id, key, higher, &rule, &t, NULL) != 0) {
            snprintf(why, n, "the re-measurement failed (above)");
            r = FAILED;
        } else if (mid > 0) {
            int up = mid > 1; /* the change is a slowdown */
            r = (up ? t.cost[1] > mid : t.cost[2] < mid) ? WORSE : (up ? t.cost[2] < mid : t.cost[1] > mid) ? SAME
                                                                                                          : UNSURE;
        } else {
            r = t.regressions ? WORSE : t.improvements ? BETTER : t.inconclusive ? UNSURE : SAME;
        }
        *cost = t.cost[0];
    }
    free(rt[0]);
    free(rt[1]);
    return r;
}

int hx_confirm_step(HxConfirm *c, const char *config_id, const char *settings, const char *const *commits, size_t lo,
                    size_t k, size_t hi, const char *key, int higher, size_t *at)
{
    char why[1024] = "";
    HxConfig cfg;
    if (!*c->hash && hx_config_open(c->config, &cfg) == 0) {
        hx_settings_hash(&cfg, c->hash);
        hx_config_free(&cfg);
    }
    const char *hash = c->hash;
    int dir = FAILED, n = 1;
    double cost = NAN, mcost;
    if (!*hash)
        snprintf(why, sizeof why, "%s could not be read (above)", c->config);
    else if (settings && *settings && strcmp(settings, hash) != 0)
        snprintf(why, sizeof why, "%s's settings (config_hash %s) are not the series' (%s): not the work measured",
                 c->config, hash, settings);
    else /* across the two windows: did anything change at all? */
        dir = change(c, config_id, commits[lo], commits[hi], key, higher, 0, &cost, why, sizeof why);
    if (dir == SAME || dir == UNSURE)
        snprintf(why, sizeof why, "re-measured interleaved, %s against %s (the windows' ends) shows %s", commits[hi],
                 commits[lo], dir == SAME ? "no change" : "nothing conclusive");
    if (dir != WORSE && dir != BETTER) {
        hx_put_clean_line(stdout, "  unconfirmed: %s", why);
        return 0;
    }
    /* it did: bisect for the commit, one step assumed, as git bisect does
     * (the stored runs may have put it at a neighbour); a commit belongs
     * to the after side when its cost against the start is past the
     * change's geometric middle */
    size_t a = lo, b = hi;
    int d = WORSE;
    while (b - a > 1 && (d == WORSE || d == SAME)) {
        size_t m = a + (b - a) / 2;
        d = change(c, config_id, commits[a], commits[m], key, higher, sqrt(cost), &mcost, why, sizeof why);
        n++;
        if (d == WORSE)
            b = m;
        else if (d == SAME)
            a = m;
    }
    const char *what = dir == WORSE ? "a slowdown" : "an improvement";
    if (b - a > 1) /* a re-measurement on the way failed or stayed in between */
        hx_put_clean_line(stdout, "  CONFIRMED: %s of %.3fx between commits %s and %s (bisection stopped: %s), %d "
                          "interleaved re-measurement(s)", what, cost, commits[a], commits[b],
                          d == UNSURE ? "inconclusive" : why, n);
    else
        hx_put_clean_line(stdout, "  CONFIRMED: %s of %.3fx at commit %s (after %s)%s, %d interleaved "
                          "re-measurement(s)", what, cost, commits[b], commits[a],
                          b == k ? "" : ", not where the stored runs put it", n);
    *at = b;
    return dir == WORSE ? 1 : 2;
}

void hx_confirm_free(HxConfirm *c)
{
    hx_strlist_free(&c->built);
    hx_strlist_free(&c->failed);
}
