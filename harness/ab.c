/* ab.c: `harness ab 'COMMAND A' 'COMMAND B'`: two commands timed
 * interleaved, and compare's verdict on B against A.
 *
 * Each command line is split into words as a config's `command:` is (no
 * shell: hyperfine's -N). A first, untimed round runs both and stops at a
 * failure, before any timing. Then N rounds run A and B back to back, the
 * first of each pair alternating, so that a slow phase of a shared machine
 * falls on both sides alike (the interleaving of Kalibera and Jones,
 * "Rigorous benchmarking in reasonable time", 2013). */
#include "program.h"
#include "run.h"

#include <getopt.h>
#include <unistd.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

typedef struct {
    int rounds;
    double factor, alpha, timeout_s;
    const char *metric; /* a regular expression over stdout; NULL: wall time */
    int higher;
    regex_t re;
} AbOpts;

static void usage_ab(FILE *f)
{
    fputs("usage: harness ab 'COMMAND A' 'COMMAND B' [--rounds N] [--metric 'REGEX' [--higher]]\n"
          "                  [--factor F] [--alpha A] [--timeout S]\n"
          "Runs A and B alternately (A B, B A, ...) and judges B against A as compare does:\n"
          "REGRESSION, IMPROVEMENT, no change or INCONCLUSIVE. Exit 1 on a regression.\n"
          "  COMMAND              a program and its arguments, split at blanks ('...' and\n"
          "                       \"...\" keep blanks), run without a shell\n"
          "  --rounds N           timed rounds (default 10; 4 or more for the rank test)\n"
          "  --metric 'REGEX'     the number in REGEX's first group, last match on stdout\n"
          "                       (default: the wall time in ms)\n"
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
        {"help", no_argument, NULL, 'h'},         {NULL, 0, NULL, 0}};
    *o = (AbOpts){10, 1.05, 0.01, 600, NULL, 0, {0}};
    long n;
    int c;
    while ((c = getopt_long(argc, argv, "h", lo, NULL)) != -1) {
        const char *bad = NULL;
        switch (c) {
        case 'r': bad = hx_parse_int(optarg, 1, 100000, &n) ? "expected an integer >= 1" : NULL; o->rounds = (int)n; break;
        case 'm': o->metric = optarg; break;
        case 'H': o->higher = 1; break;
        case 'f': bad = hx_parse_double(optarg, &o->factor) || o->factor <= 1 ? "expected a number > 1" : NULL; break;
        case 'a':
            bad = hx_parse_double(optarg, &o->alpha) || o->alpha <= 0 || o->alpha >= 1 ? "expected 0 < A < 1" : NULL;
            break;
        case 't': bad = hx_parse_double(optarg, &o->timeout_s) || o->timeout_s <= 0 ? "expected seconds > 0" : NULL; break;
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
        fprintf(stderr, "harness ab: expected two commands, 'COMMAND A' 'COMMAND B' (see --help)\n");
        return 1;
    }
    if (o->metric && regcomp(&o->re, o->metric, REG_EXTENDED | REG_NEWLINE) != 0) {
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

/* One run: its value (wall ms or the metric) in *v; 0, or -1 with why. */
static int ab_run(const HxCommand *c, const AbOpts *o, double *v, int *busy, char *why, size_t n)
{
    HxChildResult res;
    HxCpuStat a, b;
    hx_cpu_stat(&a);
    int rc = hx_run_child(c, NULL, NULL, o->timeout_s, &res);
    hx_cpu_stat(&b);
    hx_reap_strays();
    if (rc != 0 || res.timed_out || !res.exited || res.code != 0) {
        const char *e = res.err.s ? res.err.s : "";
        snprintf(why, n, "%s%s%.*s", rc ? "could not start" : res.timed_out ? "timed out" : !res.exited ? "killed by a signal"
                 : "failed", *e ? ": " : "", (int)strcspn(e, "\n"), e);
        if (rc == 0 && res.exited && res.code != 0 && !*e)
            snprintf(why, n, "exited with status %d", res.code);
        hx_child_result_free(&res);
        return -1;
    }
    HxNoise noise;
    hx_noise(&a, &b, res.wall_ms, res.user_ms + res.sys_ms, (int)sysconf(_SC_NPROCESSORS_ONLN), 1, &noise);
    *busy = noise.busy || noise.stolen;
    *v = res.wall_ms;
    char num[64];
    if (o->metric && hx_match_number(&o->re, res.out.s ? res.out.s : "", v, num, sizeof num) != 0) {
        snprintf(why, n, "--metric '%s': no number on its stdout", o->metric);
        hx_child_result_free(&res);
        return -1;
    }
    hx_child_result_free(&res);
    return 0;
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

int hx_cmd_ab(int argc, char **argv)
{
    AbOpts o;
    int orc = ab_opts(argc, argv, &o);
    if (orc >= 0)
        return orc;
    const char *line[2] = {argv[optind], argv[optind + 1]}, *name[2] = {"A", "B"};
    HxCommand c[2];
    int made[2] = {ab_command(line[0], "A", &c[0]) == 0, 0};
    made[1] = made[0] && ab_command(line[1], "B", &c[1]) == 0;
    int rc = made[0] && made[1] ? 0 : 1;
    hx_install_stop_handlers();
    double *x[2] = {hx_xmalloc((size_t)o.rounds * sizeof(double)), hx_xmalloc((size_t)o.rounds * sizeof(double))};
    size_t busy[2] = {0, 0};
    char why[512];
    double v;
    int b;
    /* round 0: both must work before anything is timed */
    for (int k = 0; k < 2 && rc == 0; k++)
        if (ab_run(&c[k], &o, &v, &b, why, sizeof why) != 0) {
            hx_put_clean_line(stderr, "harness ab: command %s failed in the first, untimed round: %s", name[k], why);
            rc = 1;
        }
    for (int r = 0; r < o.rounds && rc == 0 && !hx_stop_signal(); r++)
        for (int j = 0; j < 2 && rc == 0; j++) {
            int k = (r % 2) ^ j; /* A B, then B A, ... */
            if (ab_run(&c[k], &o, &x[k][r], &b, why, sizeof why) != 0) {
                hx_put_clean_line(stderr, "harness ab: command %s failed in round %d: %s", name[k], r + 1, why);
                rc = 1;
            }
            busy[k] += b;
        }
    if (rc == 0 && hx_stop_signal())
        rc = 128 + hx_stop_signal();
    if (rc == 0) {
        const char *what = o.metric ? "metric" : "wall ms", *verdict;
        printf("harness ab: %d rounds, A and B alternating first (factor %.3g, alpha %.3g)\n", o.rounds, o.factor,
               o.alpha);
        ab_side("A", line[0], x[0], (size_t)o.rounds, busy[0], what);
        ab_side("B", line[1], x[1], (size_t)o.rounds, busy[1], what);
        rc = hx_judge_samples("B against A", x[1], (size_t)o.rounds, x[0], (size_t)o.rounds, o.factor, o.alpha,
                              o.higher, o.metric ? "" : "ms", &verdict);
    }
    for (int k = 0; k < 2; k++) {
        if (made[k])
            hx_command_free(&c[k]);
        free(x[k]);
    }
    if (o.metric)
        regfree(&o.re);
    return rc;
}
