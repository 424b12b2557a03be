/* ab.c: `harness ab`: two commands, or two raytrace builds over a config's
 * configurations, timed interleaved, and compare's verdict on B against A.
 *
 * A command line is split into words as a config's `command:` is (no
 * shell: hyperfine's -N). A first, untimed round runs both and stops at a
 * failure, before any timing. Then N rounds run A and B back to back, the
 * first of each pair alternating, so that a slow phase of a shared machine
 * falls on both sides alike (the interleaving of Kalibera and Jones,
 * "Rigorous benchmarking in reasonable time", 2013). `history check
 * --confirm` re-measures a step through hx_ab_config. */
#include "program.h"
#include "run.h"

#include <getopt.h>
#include <unistd.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

typedef struct {
    HxAbRule rule;
    const char *metric; /* commands: a regular expression over stdout; NULL: wall time */
    int higher;
    regex_t re;
    const char *config; /* --config: two raytrace builds over its configurations */
    const char *key;    /* --config: the record key (default render_ms) */
    HxStrList set;
} AbOpts;

/* What one side's runs are read for: a record key, a regex, or wall ms. */
typedef struct {
    const char *key;
    const regex_t *re;
    const char *what;
    const HxTopo *topo;
    const HxRun *run;
    double timeout_s;
    char (*image)[2][32]; /* --config: each side's last image_fnv1a */
} AbRead;

static void usage_ab(FILE *f)
{
    fputs("usage: harness ab 'COMMAND A' 'COMMAND B' [--rounds N] [--metric 'REGEX' [--higher]]\n"
          "       harness ab --config CONFIG RAYTRACE_A RAYTRACE_B [--metric KEY [--higher]]\n"
          "                  [--set KEY=VALUE]...\n"
          "       common: [--rounds N] [--factor F] [--alpha A] [--timeout S]\n"
          "Runs A and B alternately (A B, B A, ...) and judges B against A as compare does:\n"
          "REGRESSION, IMPROVEMENT, no change or INCONCLUSIVE. Exit 1 on a regression.\n"
          "  COMMAND              a program and its arguments, split at blanks ('...' and\n"
          "                       \"...\" keep blanks), run without a shell\n"
          "  --config CONFIG      every configuration of a raytrace config, run (pinned as\n"
          "                       `harness run` pins it) by two raytrace builds; one\n"
          "                       verdict per configuration\n"
          "  --rounds N           timed rounds (default 10; 4 or more for the rank test)\n"
          "  --metric 'REGEX'     the number in REGEX's first group, last match on stdout\n"
          "                       (default: the wall time in ms); with --config a record\n"
          "                       key (default render_ms)\n"
          "  --higher             the metric is a rate: higher is better\n"
          "  --factor F           the change that counts (default 1.05)\n"
          "  --alpha A            the rank test's significance (default 0.01)\n"
          "  --timeout S          per run, in seconds (default 600)\n", f);
}

static int ab_opts(int argc, char **argv, AbOpts *o)
{
    static const struct option lo[] = {
        {"rounds", required_argument, NULL, 'r'}, {"metric", required_argument, NULL, 'm'},
        {"higher", no_argument, NULL, 'H'},       {"factor", required_argument, NULL, 'f'},
        {"alpha", required_argument, NULL, 'a'},  {"timeout", required_argument, NULL, 't'},
        {"config", required_argument, NULL, 'c'}, {"set", required_argument, NULL, 's'},
        {"help", no_argument, NULL, 'h'},         {NULL, 0, NULL, 0}};
    memset(o, 0, sizeof *o);
    o->rule = (HxAbRule){10, 1.05, 0.01, 600};
    long n;
    int c;
    while ((c = getopt_long(argc, argv, "h", lo, NULL)) != -1) {
        const char *bad = NULL;
        switch (c) {
        case 'r': bad = hx_parse_int(optarg, 1, 100000, &n) ? "expected an integer >= 1" : NULL; o->rule.rounds = (int)n; break;
        case 'm': o->metric = optarg; break;
        case 'H': o->higher = 1; break;
        case 'c': o->config = optarg; break;
        case 's': hx_strlist_push(&o->set, optarg); break;
        case 'f': bad = hx_parse_double(optarg, &o->rule.factor) || o->rule.factor <= 1 ? "expected a number > 1" : NULL; break;
        case 'a':
            bad = hx_parse_double(optarg, &o->rule.alpha) || o->rule.alpha <= 0 || o->rule.alpha >= 1 ? "expected 0 < A < 1" : NULL;
            break;
        case 't': bad = hx_parse_double(optarg, &o->rule.timeout_s) || o->rule.timeout_s <= 0 ? "expected seconds > 0" : NULL; break;
        case 'h': usage_ab(stdout); return 0;
        default: usage_ab(stderr); return 1;
        }
        if (bad) {
            const char *name = c == 'r' ? "rounds" : c == 'f' ? "factor" : c == 'a' ? "alpha" : "timeout";
            fprintf(stderr, "harness ab: --%s: %s, got '%s'\n", name, bad, optarg);
            return 1;
        }
    }
    if (argc - optind != 2) {
        fprintf(stderr, o->config ? "harness ab: expected two raytrace builds, RAYTRACE_A RAYTRACE_B (see --help)\n"
                                  : "harness ab: expected two commands, 'COMMAND A' 'COMMAND B' (see --help)\n");
        return 1;
    }
    if (o->set.n && !o->config) {
        fprintf(stderr, "harness ab: --set applies to --config only\n");
        return 1;
    }
    if (o->config) {
        o->key = o->metric ? o->metric : "render_ms";
        o->metric = NULL;
        if (!*o->key || strchr(o->key, '/') || strchr(o->key, '=') || hx_has_ctrl(o->key)) {
            hx_put_clean_line(stderr, "harness ab: --metric: '%s' is not a record key (e.g. render_ms)", o->key);
            return 1;
        }
    } else if (o->metric && regcomp(&o->re, o->metric, REG_EXTENDED | REG_NEWLINE) != 0) {
        fprintf(stderr, "harness ab: --metric: '%s' is not a regular expression\n", o->metric);
        return 1;
    }
    return -1;
}

/* The command line as a NULL-terminated argv in c. 0, or -1 (said). */
static int ab_command(const char *line, const char *side, HxCommand *c)
{
    char why[128] = "empty";
    memset(c, 0, sizeof *c);
    char *abs = NULL;
    if (hx_words(line, 0, &c->argv, why, sizeof why) != 0 || c->argv.n == 0)
        fprintf(stderr, "harness ab: command %s: %s\n", side, why);
    else if (!(abs = hx_which(c->argv.v[0])))
        hx_put_clean_line(stderr, "harness ab: command %s: program '%s' not found%s", side, c->argv.v[0],
                          strchr(c->argv.v[0], '/') ? " or not executable" : " on PATH");
    if (!abs) {
        hx_strlist_free(&c->argv);
        return -1;
    }
    free(abs);
    hx_command_terminate(c);
    return 0;
}

/* The value read from a finished run; 0, or -1 with why. */
static int ab_value(const HxChildResult *res, const AbRead *rd, int side, double *v, char *why, size_t n)
{
    char num[64];
    *v = res->wall_ms;
    if (rd->re && hx_match_number(rd->re, res->out.s ? res->out.s : "", v, num, sizeof num) != 0) {
        snprintf(why, n, "--metric: no number on its stdout");
        return -1;
    }
    if (!rd->key)
        return 0;
    const char *rec = res->out.s ? hx_record_find(res->out.s) : NULL;
    if (rec && rd->image)
        hx_record_get(rec, "image_fnv1a", (*rd->image)[side], sizeof (*rd->image)[side]);
    if (!rec || !hx_record_get(rec, rd->key, num, sizeof num) || hx_parse_double(num, v) != 0) {
        snprintf(why, n, "no %s in its record line", rd->key);
        return -1;
    }
    return 0;
}

/* One run: its value in *v, *busy whether the machine was busy or stolen;
 * 0, or -1 with why. */
static int ab_run(const HxCommand *c, const AbRead *rd, int side, double *v, int *busy, char *why, size_t n)
{
    HxChildResult res;
    HxCpuStat a, b;
    hx_cpu_stat(&a);
    int rc = hx_run_child(c, rd->topo, rd->run, rd->timeout_s, &res);
    hx_cpu_stat(&b);
    hx_reap_strays();
    if (rc != 0 || res.timed_out || !res.exited || res.code != 0) {
        int el;
        const char *e = hx_first_line(res.err.s, &el);
        char sig[32] = "";
        if (rc == 0 && !res.timed_out && !res.exited) {
            const char *sn = hx_signal_name(res.code);
            if (sn)
                snprintf(sig, sizeof sig, "killed by %s", sn);
            else
                snprintf(sig, sizeof sig, "killed by signal %d", res.code);
        }
        snprintf(why, n, "%s%s%.*s", rc ? "could not start" : res.timed_out ? "timed out" : *sig ? sig : "failed",
                 el ? ": " : "", el, e);
        if (rc == 0 && res.exited && res.code != 0 && !el)
            snprintf(why, n, "exited with status %d", res.code);
        hx_child_result_free(&res);
        return -1;
    }
    HxNoise noise;
    int workers = rd->run ? rd->run->workers : 1;
    hx_noise(&a, &b, res.wall_ms, res.user_ms + res.sys_ms, (int)sysconf(_SC_NPROCESSORS_ONLN), workers, &noise);
    *busy = noise.busy || noise.stolen;
    rc = ab_value(&res, rd, side, v, why, n);
    hx_child_result_free(&res);
    return rc;
}

/* The summary of one side's samples. */
static void ab_side(const char *name, const char *line, double *x, size_t n, size_t busy, const char *what)
{
    double lo, hi, max = x[0];
    for (size_t i = 1; i < n; i++)
        max = x[i] > max ? x[i] : max;
    hx_bootstrap_ci(x, n, NULL, 0, &lo, &hi);
    hx_put_clean_line(stdout, "%s: %s: median %.3f [%.3f, %.3f], min %.3f, max %.3f (n=%zu, %zu busy or stolen)",
                      name, what, hx_median(x, n), lo, hi, hx_min(x, n), max, n, busy);
    hx_put_clean_line(stdout, "   %s", line);
}

/* Both sides measured and judged: an untimed first round, then the rounds
 * alternating. 0 or 1 (a regression), or -1 (a run failed, said). */
static int ab_pair(const HxCommand c[2], const AbRead *rd, const HxAbRule *rule, int higher, const char *label,
                   const char *const line[2], const char **verdict, const char **header, double cost[3])
{
    static const char *const name[2] = {"A", "B"};
    size_t nr = (size_t)rule->rounds, busy[2] = {0, 0};
    double *x[2] = {hx_xmalloc(nr * sizeof(double)), hx_xmalloc(nr * sizeof(double))}, v;
    char why[512];
    int rc = 0, b;
    for (int k = 0; k < 2 && rc == 0; k++)
        if (ab_run(&c[k], rd, k, &v, &b, why, sizeof why) != 0) {
            hx_put_clean_line(stderr, "harness ab: %s%scommand %s failed in the first, untimed round: %s", label,
                              *label ? ": " : "", name[k], why);
            rc = -1;
        }
    if (rc == 0 && header && *header) { /* once, and only when both commands work */
        fputs(*header, stdout);
        fflush(stdout);
        *header = NULL;
    }
    for (size_t r = 0; r < nr && rc == 0 && !hx_stop_signal(); r++)
        for (int j = 0; j < 2 && rc == 0; j++) {
            int k = (int)(r % 2) ^ j; /* A B, then B A, ... */
            if (ab_run(&c[k], rd, k, &x[k][r], &b, why, sizeof why) != 0) {
                hx_put_clean_line(stderr, "harness ab: %s%scommand %s failed in round %zu: %s", label,
                                  *label ? ": " : "", name[k], r + 1, why);
                rc = -1;
            }
            busy[k] += (size_t)b;
        }
    if (rc == 0 && !hx_stop_signal()) {
        ab_side("A", line[0], x[0], nr, busy[0], rd->what);
        ab_side("B", line[1], x[1], nr, busy[1], rd->what);
        rc = hx_judge_samples(*label ? label : "B against A", x[1], nr, x[0], nr, rule->factor, rule->alpha, higher,
                              rd->key ? (strstr(rd->key, "_ms") ? "ms" : "") : rd->re ? "" : "ms", verdict);
        /* B's cost against A's (a rate's inverse ratio): median and 95% interval */
        double m0 = hx_median(x[0], nr), m1 = hx_median(x[1], nr), lo, hi;
        hx_bootstrap_ci(x[0], nr, x[1], nr, &lo, &hi);
        cost[0] = higher ? m0 / m1 : m1 / m0;
        cost[1] = higher ? 1.0 / hi : lo;
        cost[2] = higher ? 1.0 / lo : hi;
    }
    free(x[0]);
    free(x[1]);
    return rc;
}

static void tally(HxAbTally *t, const char *verdict)
{
    t->compared++;
    if (strcmp(verdict, "REGRESSION") == 0)
        t->regressions++;
    else if (strcmp(verdict, "IMPROVEMENT") == 0)
        t->improvements++;
    else if (strcmp(verdict, "INCONCLUSIVE") == 0)
        t->inconclusive++;
}

/* One configuration of the plan with both builds. 0, or -1 (said). */
static int ab_one(const HxConfig *cfg, const HxTopo *t, const HxRun *r, const char *const rt[2], const char *key,
                  int higher, const HxAbRule *rule, HxAbTally *tal, const char **header)
{
    char err[512], *tmp = hx_temp_dir("ab", err, sizeof err);
    if (!tmp) {
        fprintf(stderr, "harness ab: %s\n", err);
        return -1;
    }
    HxCommand c[2];
    HxBuf img[2] = {{0}, {0}};
    for (int k = 0; k < 2; k++) {
        hx_buf_printf(&img[k], "%s/%c.ppm", tmp, 'a' + k);
        hx_build_command(cfg, t, r, rt[k], img[k].s, tmp, NULL, &c[k]);
    }
    char lab[512];
    hx_config_label(lab, sizeof lab, r->config_id);
    char image[2][32] = {"", ""};
    AbRead rd = {key, NULL, key, t, r, cfg->timeout_s, &image};
    const char *verdict = NULL;
    int rc = ab_pair(c, &rd, rule, higher, lab, rt, &verdict, header, tal->cost);
    if (rc >= 0) {
        tally(tal, verdict);
        /* raytrace's CPU backends render bit for bit alike: a change of
         * image is a change of work, whatever the time says */
        int same = strcmp(image[0], image[1]) == 0;
        tal->images_differ += !same;
        printf("   images: %s (image_fnv1a A %s, B %s)\n", same ? "identical" : "DIFFER", *image[0] ? image[0] : "-",
               *image[1] ? image[1] : "-");
    }
    for (int k = 0; k < 2; k++) {
        unlink(img[k].s);
        hx_buf_printf(&img[k], ".rankfile");
        unlink(img[k].s);
        hx_buf_free(&img[k]);
        hx_command_free(&c[k]);
    }
    rmdir(tmp);
    free(tmp);
    return rc < 0 ? -1 : 0;
}

int hx_ab_config(const char *config, const HxStrList *set, const char *const rt[2], const char *only, const char *key,
                 int higher, const HxAbRule *rule, HxAbTally *tal, const char *header)
{
    HxConfig cfg;
    memset(tal, 0, sizeof *tal);
    if (hx_config_open_set(config, set, &cfg) != 0)
        return -1;
    if (cfg.prog) {
        fprintf(stderr, "harness ab: %s: a command study; --config compares two raytrace builds (give two commands "
                        "instead)\n", config);
        hx_config_free(&cfg);
        return -1;
    }
    free(cfg.scene_cache); /* each build parses: caches of two builds need not agree */
    cfg.scene_cache = hx_strdup("off");
    HxPlan plan;
    HxTopo t;
    hx_expand(&cfg, &plan);
    hx_topo_load(&t);
    hx_plan_cores(&t, &cfg, &plan);
    int rc = 0, seen = 0;
    for (size_t i = 0; i < plan.n && rc == 0 && !hx_stop_signal(); i++) {
        const HxRun *r = &plan.runs[i];
        if (r->repeat != 0 || r->refused || (only && strcmp(r->config_id, only) != 0))
            continue;
        seen = 1;
        rc = ab_one(&cfg, &t, r, rt, key, higher, rule, tal, &header);
    }
    if (rc == 0 && !seen) {
        hx_put_clean_line(stderr, "harness ab: %s: %s", config,
                          only ? "no configuration of it is the one asked for" : "plans no run");
        rc = -1;
    }
    hx_plan_free(&plan);
    hx_topo_free(&t);
    hx_config_free(&cfg);
    return rc;
}

static int ab_commands(const AbOpts *o, const char *const line[2])
{
    HxCommand c[2];
    int made[2] = {ab_command(line[0], "A", &c[0]) == 0, 0};
    made[1] = made[0] && ab_command(line[1], "B", &c[1]) == 0;
    int rc = made[0] && made[1] ? 0 : 1;
    if (rc == 0) {
        char head[256];
        const char *header = head;
        snprintf(head, sizeof head, "harness ab: %d rounds, A and B alternating first (factor %.3g, alpha %.3g)\n",
                 o->rule.rounds, o->rule.factor, o->rule.alpha);
        AbRead rd = {NULL, o->metric ? &o->re : NULL, o->metric ? "metric" : "wall ms", NULL, NULL, o->rule.timeout_s,
                     NULL};
        const char *verdict;
        double cost[3];
        rc = ab_pair(c, &rd, &o->rule, o->higher, "", line, &verdict, &header, cost);
        rc = rc < 0 ? 1 : rc;
    }
    for (int k = 0; k < 2; k++)
        if (made[k])
            hx_command_free(&c[k]);
    return rc;
}

int hx_cmd_ab(int argc, char **argv)
{
    AbOpts o;
    int rc = ab_opts(argc, argv, &o);
    if (rc >= 0) {
        hx_strlist_free(&o.set);
        return rc;
    }
    const char *const line[2] = {argv[optind], argv[optind + 1]};
    hx_install_stop_handlers();
    if (!o.config) {
        rc = ab_commands(&o, line);
    } else {
        HxAbTally t;
        char *rt[2] = {hx_which(line[0]), hx_which(line[1])};
        for (int k = 0; k < 2; k++)
            if (!rt[k])
                hx_put_clean_line(stderr, "harness ab: raytrace %c: '%s' not found or not executable", 'A' + k,
                                  line[k]);
        HxBuf head = {0};
        hx_buf_printf(&head, "harness ab: %s, %d rounds per configuration, A and B alternating first (metric %s, "
                      "factor %.3g, alpha %.3g)\n", o.config, o.rule.rounds, o.key, o.rule.factor, o.rule.alpha);
        rc = rt[0] && rt[1] ? hx_ab_config(o.config, &o.set, (const char *const *)rt, NULL, o.key, o.higher, &o.rule, &t,
                                           head.s)
                            : -1;
        hx_buf_free(&head);
        if (rc == 0)
            printf("harness ab: %d configuration(s): %d regression(s), %d improvement(s), %d inconclusive; images "
                   "differ in %d\n", t.compared, t.regressions, t.improvements, t.inconclusive, t.images_differ);
        rc = rc != 0 ? 1 : t.regressions > 0;
        free(rt[0]);
        free(rt[1]);
    }
    if (hx_stop_signal())
        rc = 128 + hx_stop_signal();
    if (o.metric)
        regfree(&o.re);
    hx_strlist_free(&o.set);
    return rc;
}
