/* slurm.c: `harness slurm CONFIG`: an sbatch script that runs the study, and
 * with --submit its submission, following and collection.
 *
 * The allocation is sized from the config's own run plan, so it fits the
 * largest hybrid run (ranks x threads per rank) and nothing has to be kept
 * in step by hand when a sweep grows. Inside the job the harness launches
 * MPI runs with srun (`--launcher srun`), which places and binds the ranks
 * inside the allocation. Without --submit Slurm is never called: the script
 * is text, and `bash -n` is enough to check it where Slurm is not installed.
 * With --submit, sbatch, squeue, sacct and scontrol run as argv lists
 * (hx_run_argv), never through a shell. */
#include "hx.h"

#include "config.h"

#include <ctype.h>
#include <errno.h>
#include <getopt.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static void usage_slurm(FILE *f)
{
    fputs("usage: harness slurm CONFIG [-o FILE] [--submit] [--nodes N] [--time HH:MM:SS]\n"
          "                    [--partition P] [--account A] [--job-name NAME]\n"
          "                    [--ntasks N] [--cpus-per-task N] [--mpi TYPE]\n"
          "                    [--max-wait HH:MM:SS]\n"
          "Writes an sbatch script that runs the study of CONFIG in one Slurm job, MPI\n"
          "runs launched with srun, then prints its table. Submit it from the repository\n"
          "root (sbatch FILE); the CSV is results/STUDY-slurm.csv, and a job that did not\n"
          "finish (time limit, preemption, scancel) is continued by submitting it again.\n"
          "  -o, --output FILE     write the script to FILE (default: stdout; with\n"
          "                        --submit results/STUDY-slurm.sbatch)\n"
          "  -s, --submit          submit it with sbatch, follow the job (progress on\n"
          "                        stderr), then print the CSV's path and its table;\n"
          "                        exit 1 if the job did not complete\n"
          "  -N, --nodes N         nodes to allocate (default 1)\n"
          "  -t, --time HH:MM:SS   wall-clock limit of the job (default 01:00:00)\n"
          "  -p, --partition P     partition (default: the site's)\n"
          "  -A, --account A       account to charge (default: the user's)\n"
          "  -J, --job-name NAME   job name (default: the study name)\n"
          "  -n, --ntasks N        tasks to allocate (default: the plan's largest rank count)\n"
          "  -c, --cpus-per-task N cores per task (default: the plan's largest thread count)\n"
          "      --mpi TYPE        srun's MPI plugin for the ranks (default pmix, what Open\n"
          "                        MPI needs; 'site': the site's MpiDefault)\n"
          "      --max-wait HH:MM:SS  stop following after this long (default: --time\n"
          "                        plus one hour); the job itself goes on\n"
          "  -h, --help            this text\n"
          "--ntasks is the largest rank count in the plan and --cpus-per-task the\n"
          "largest thread count, so every run fits in the allocation; on nodes smaller\n"
          "than that, give smaller sizes: the runs that do not fit the granted cores\n"
          "are then refused (or oversubscribed, with 'oversubscribe: allow').\n", f);
}
/* Characters that need no quoting in a shell word. */
static int sh_safe(const char *s)
{
    if (!*s)
        return 0;
    for (; *s; s++)
        if (!isalnum((unsigned char)*s) && !strchr("._/-+=:,@%", *s))
            return 0;
    return 1;
}

/* Appends s as one shell word: as it is when safe, else single-quoted. */
static void sh_word(HxBuf *b, const char *s)
{
    if (sh_safe(s)) {
        hx_buf_put(b, s);
        return;
    }
    hx_buf_put(b, "'");
    for (; *s; s++) {
        if (*s == '\'')
            hx_buf_put(b, "'\\''");
        else
            hx_buf_putn(b, s, 1);
    }
    hx_buf_put(b, "'");
}

/* Values that end up on an #SBATCH line: sbatch splits those lines itself,
 * so blanks or quotes would silently change the request. */
static int sbatch_value_ok(const char *s, const char *extra)
{
    if (!*s)
        return 0;
    for (; *s; s++)
        if (!isalnum((unsigned char)*s) && !strchr(extra, *s))
            return 0;
    return 1;
}

/* HH:MM:SS with any number of hours (48:00:00 is a valid Slurm limit);
 * the length in seconds goes to *secs. */
static int parse_hms(const char *s, long *secs)
{
    const char *p = s;
    long h = 0;
    int nh = 0;
    while (isdigit((unsigned char)*p)) {
        h = h * 10 + (*p++ - '0');
        if (++nh > 6) /* a million hours: a typo, and no overflow below */
            return -1;
    }
    if (nh == 0 || *p != ':')
        return -1;
    long ms[2];
    for (int f = 0; f < 2; f++) {
        if (!isdigit((unsigned char)p[1]) || !isdigit((unsigned char)p[2]) || p[1] > '5')
            return -1;
        ms[f] = (p[1] - '0') * 10 + (p[2] - '0');
        p += 3;
        if (*p != (f == 0 ? ':' : '\0'))
            return -1;
    }
    *secs = h * 3600 + ms[0] * 60 + ms[1];
    return 0;
}

/* What the command line asked for. */
typedef struct {
    const char *config, *out_path, *time_limit, *partition, *account, *job_name, *mpi;
    long nodes, ntasks, cpus;   /* ntasks, cpus 0: from the plan */
    long time_s, max_wait_s;    /* max_wait_s 0: time_s plus an hour */
    int submit;
} SlurmOpts;

/* What the script requests and what a complete study writes. */
typedef struct {
    long ntasks, cpus;
    size_t nmpi;     /* MPI runs (launched with srun) */
    size_t ngpu;     /* mpi-cuda runs: a GPU per task */
    size_t nrows;    /* CSV rows of the whole study: every run but warm-ups */
} Sizing;

/* The script's commands, after the #SBATCH lines: cfg's study into the CSV
 * at csv_path (relative to the submit folder), then its table. */
static void script_body(HxBuf *b, const HxConfig *cfg, const SlurmOpts *o, const char *csv_path)
{
    HxBuf cfgw = {0}, csv = {0};
    sh_word(&cfgw, cfg->path);
    sh_word(&csv, csv_path);
    hx_buf_printf(b,
        "\n"
        "# Stop at the first failing command or unset variable: no table of a\n"
        "# study that did not run.\n"
        "set -euo pipefail\n"
        "# The paths below are relative to the repository root, where sbatch ran.\n"
        "cd \"$SLURM_SUBMIT_DIR\"\n"
        "# A clear message instead of 'command not found' when submitted elsewhere.\n"
        "if [ ! -x build/harness/harness ]; then\n"
        "    echo \"no build/harness/harness in $PWD: submit from the repository root\" >&2\n"
        "    exit 1\n"
        "fi\n"
        "# -o does not create folders.\n"
        "mkdir -p results\n"
        "# Which nodes ran the study, for the log.\n"
        "echo \"job $SLURM_JOB_ID: $SLURM_JOB_NUM_NODES node(s): $SLURM_JOB_NODELIST\"\n");
    if (strcmp(o->mpi, "site") != 0)
        hx_buf_printf(b,
            "# srun's MPI plugin: Open MPI's ranks find each other through PMIx (Debian's\n"
            "# Open MPI has no PMI-1/2), and a site's MpiDefault is often none.\n"
            "export SLURM_MPI_TYPE=%s\n", o->mpi);
    hx_buf_printf(b,
        "# The study: one CSV row per run, MPI runs through srun inside this\n"
        "# allocation (the harness gives each run its --ntasks, --cpus-per-task and\n"
        "# OMP_* settings). One CSV per study, not per job: a job ended by its time\n"
        "# limit, preemption or scancel leaves whole rows, and this script submitted\n"
        "# again continues them (--resume skips the runs already there and refuses\n"
        "# the CSV of a config that has changed since).\n"
        "build/harness/harness run %s --launcher srun -o %s --resume\n"
        "# Statistics, speedups and the Amdahl fit per series, into the job log.\n"
        "build/harness/harness table %s\n",
        cfgw.s, csv.s, csv.s);
    hx_buf_free(&cfgw);
    hx_buf_free(&csv);
}

/* Writes the script for cfg into b; csv is the study's CSV path. */
static void make_script(HxBuf *b, const HxConfig *cfg, const HxPlan *plan, const SlurmOpts *o,
                        const Sizing *sz, const char *csv_path)
{
    hx_buf_printf(b,
        "#!/bin/bash\n"
        "# Generated by `harness slurm %s` (raybench harness %s): study %s,\n"
        "# %zu runs, %zu of them MPI (launched with srun). Submit it from the\n"
        "# repository root: sbatch FILE. Generate it again when the config changes:\n"
        "# the #SBATCH sizes below come from the config's run plan.\n"
        "#\n"
        "# Name in squeue and sacct.\n"
        "#SBATCH --job-name=%s\n"
        "# Nodes; srun spreads the ranks of one run over them (block distribution).\n"
        "#SBATCH --nodes=%ld\n"
        "%s"
        "#SBATCH --ntasks=%ld\n"
        "%s"
        "#SBATCH --cpus-per-task=%ld\n"
        "# Whole nodes: another job's load on the same cores would be in the timings.\n"
        "#SBATCH --exclusive\n"
        "# One thread per physical core: SMT siblings share a core's execution units,\n"
        "# as the harness's own pinning assumes.\n"
        "#SBATCH --hint=nomultithread\n"
        "# Wall-clock limit for the whole study (warm-ups and repeats included).\n"
        "#SBATCH --time=%s\n"
        "# Job log (progress lines and the table): slurm-JOBID.out in the submit folder.\n"
        "#SBATCH --output=slurm-%%j.out\n",
        cfg->path, RT_VERSION, cfg->study, plan->n, sz->nmpi, o->job_name, o->nodes,
        o->ntasks ? "# From --ntasks, not the plan: runs needing more cores than the job\n"
                    "# was granted are refused by the harness.\n"
                  : "# The largest rank count in the plan, so every run's srun step fits.\n",
        sz->ntasks,
        o->cpus ? "# From --cpus-per-task: a rank's OpenMP threads get that many cores,\n"
                  "# and runs needing more than the job was granted are refused.\n"
                : "# The largest thread count in the plan (threads per rank with MPI): each\n"
                  "# rank gets that many cores for its OpenMP threads.\n",
        sz->cpus, o->time_limit);
    if (sz->ngpu)
        hx_buf_printf(b, "# mpi-cuda runs: one GPU per task (rank), the GPU nearest the task's cores;\n"
                         "# each rank then sees only its own GPU (docs/gpu.md, \"Several GPUs\").\n"
                         "#SBATCH --gpus-per-task=1\n#SBATCH --gpu-bind=closest\n");
    if (o->partition)
        hx_buf_printf(b, "# Partition (queue) to run in.\n#SBATCH --partition=%s\n", o->partition);
    if (o->account)
        hx_buf_printf(b, "# Account charged for the core hours.\n#SBATCH --account=%s\n",
                      o->account);
    script_body(b, cfg, o, csv_path);
}

/* ---- --submit: sbatch, then squeue/sacct until the job ends ---- */

/* Rows in a CSV so far: its lines after the header (0 when unreadable). */
static long csv_rows(const char *path)
{
    FILE *f = fopen(path, "r");
    if (!f)
        return 0;
    char chunk[65536];
    size_t n;
    long lines = 0;
    while ((n = fread(chunk, 1, sizeof chunk, f)) > 0)
        for (size_t i = 0; i < n; i++)
            lines += chunk[i] == '\n';
    fclose(f);
    return lines > 0 ? lines - 1 : 0;
}

/* Copies field k of a '|'-separated line (up to the newline) into out. */
static void pipe_field(const char *line, int k, char *out, size_t n)
{
    const char *p = line;
    for (; k > 0 && p; k--) {
        p = strchr(p, '|');
        if (p)
            p++;
    }
    size_t len = p ? strcspn(p, "|\n") : 0;
    if (len >= n)
        len = n - 1;
    memcpy(out, p ? p : "", len);
    out[len] = '\0';
}

typedef struct {
    char state[64], reason[128], elapsed[32], nodes[128], exit_code[32];
} JobInfo;

/* The job's state from squeue (which lists a finished job for MinJobAge
 * seconds), else from sacct (which knows it only with accounting).
 * Returns 0, or -1 when neither does. */
static int job_query(const char *id, JobInfo *j)
{
    char out[1024];
    memset(j, 0, sizeof *j);
    char *sq[] = {"squeue", "-h", "-t", "all", "-j", (char *)id, "-o", "%T|%r|%M|%N", NULL};
    if (hx_run_argv(sq, NULL, out, sizeof out, 1) == 0 && out[0] && out[0] != '\n') {
        pipe_field(out, 0, j->state, sizeof j->state);
        pipe_field(out, 1, j->reason, sizeof j->reason);
        pipe_field(out, 2, j->elapsed, sizeof j->elapsed);
        pipe_field(out, 3, j->nodes, sizeof j->nodes);
        return 0;
    }
    /* -X: the job itself, not its steps */
    char *sa[] = {"sacct", "-n", "-X", "-P", "-j", (char *)id, "-o", "State,ExitCode", NULL};
    if (hx_run_argv(sa, NULL, out, sizeof out, 1) == 0 && out[0] && out[0] != '\n') {
        pipe_field(out, 0, j->state, sizeof j->state);
        j->state[strcspn(j->state, " ")] = '\0'; /* "CANCELLED by 0" */
        pipe_field(out, 1, j->exit_code, sizeof j->exit_code);
        return 0;
    }
    return -1;
}

/* States a job does not leave by itself (a requeued job is PENDING again). */
static int state_final(const char *s)
{
    static const char *const fin[] = {"COMPLETED", "FAILED", "CANCELLED", "TIMEOUT", "PREEMPTED",
                                      "NODE_FAIL", "OUT_OF_MEMORY", "BOOT_FAIL", "DEADLINE", NULL};
    for (int i = 0; fin[i]; i++)
        if (strcmp(s, fin[i]) == 0)
            return 1;
    return 0;
}

/* Pending reasons that do not pass by themselves: the job asks for more than
 * the partition has, or for something it may not use. */
static int reason_never(const char *r)
{
    static const char *const never[] = {"PartitionConfig", "PartitionNodeLimit", "PartitionTimeLimit",
                                        "BadConstraints", "InvalidAccount", "InvalidQOS",
                                        "AccountNotAllowed", "QOSNotAllowed", NULL};
    for (int i = 0; never[i]; i++)
        if (strcmp(r, never[i]) == 0)
            return 1;
    return 0;
}

/* Submits script with sbatch; the job id goes to id. Returns 0 or -1 with
 * one line said (sbatch's own message, if any, above it). */
static int submit_script(const char *script, char *id, size_t n)
{
    /* a file named like an option would be read as one */
    HxBuf path = {0};
    hx_buf_printf(&path, "%s%s", script[0] == '-' ? "./" : "", script);
    char out[256];
    char *argv[] = {"sbatch", "--parsable", path.s, NULL};
    int rc = hx_run_argv(argv, NULL, out, sizeof out, 0);
    hx_buf_free(&path);
    if (rc == 127) {
        fprintf(stderr, "harness slurm: --submit: cannot run sbatch (is Slurm's client installed "
                        "and on PATH?)\n");
        return -1;
    }
    if (rc != 0) {
        fprintf(stderr, "harness slurm: --submit: sbatch %s failed (exit %d)\n", script, rc);
        return -1;
    }
    /* --parsable: "JOBID" or "JOBID;CLUSTER" */
    size_t len = strspn(out, "0123456789");
    if (len == 0 || len >= n || (out[len] != ';' && out[len] != '\n' && out[len] != '\0')) {
        fprintf(stderr, "harness slurm: --submit: sbatch printed no job id (got '%.40s')\n", out);
        return -1;
    }
    memcpy(id, out, len);
    id[len] = '\0';
    return 0;
}

/* One progress line when the job's state or the CSV's row count changed. */
static void progress(const char *id, const JobInfo *j, const char *csv, long rows, size_t nrows)
{
    if (strcmp(j->state, "PENDING") == 0)
        fprintf(stderr, "harness slurm: job %s PENDING%s%s%s\n", id,
                strcmp(j->reason, "None") != 0 && j->reason[0] ? " (" : "",
                strcmp(j->reason, "None") != 0 ? j->reason : "",
                strcmp(j->reason, "None") != 0 && j->reason[0] ? ")" : "");
    else
        fprintf(stderr, "harness slurm: job %s %s %s%s%s: %ld/%zu rows in %s\n", id, j->state,
                j->elapsed, j->nodes[0] ? " on " : "", j->nodes, rows, nrows, csv);
}

/* Follows job id until it ends: 0 with its last state in j (state "" when
 * it left the queue unseen and there is no accounting), or -1 after
 * max_wait_s (the job goes on) with one line said. */
static int follow_job(const char *id, const char *csv, size_t nrows, long max_wait_s, JobInfo *j)
{
    double t0 = hx_now_ms();
    unsigned delay = 1;
    long last_rows = -1;
    char last[64] = "";
    int said_down = 0;
    for (;;) {
        if (job_query(id, j) == 0) {
            if (state_final(j->state))
                return 0;
            if (strcmp(j->state, "PENDING") == 0 && reason_never(j->reason)) {
                fprintf(stderr, "harness slurm: job %s cannot start as submitted (PENDING: %s): it "
                                "asks for more than the partition has or may use; scancel %s, then "
                                "ask for less (--nodes, --ntasks, --cpus-per-task, --time)\n",
                        id, j->reason, id);
                return -1;
            }
            long rows = csv_rows(csv);
            if (strcmp(j->state, last) != 0 || rows != last_rows)
                progress(id, j, csv, rows, nrows);
            snprintf(last, sizeof last, "%s", j->state);
            last_rows = rows;
            said_down = 0;
        } else {
            /* the controller answers but no longer knows the job: it ended
             * more than MinJobAge ago, and there is no accounting */
            char *ping[] = {"scontrol", "ping", NULL};
            if (hx_run_argv(ping, NULL, NULL, 0, 1) == 0) {
                memset(j, 0, sizeof *j);
                return 0;
            }
            if (!said_down++)
                fprintf(stderr, "harness slurm: job %s: squeue cannot reach the controller; "
                                "trying again\n", id);
        }
        double left = (double)max_wait_s - (hx_now_ms() - t0) / 1e3;
        if (left <= 0) {
            fprintf(stderr, "harness slurm: stopped following job %s after %ld s (--max-wait); it "
                            "goes on: squeue -j %s, then harness table %s\n", id, max_wait_s, id, csv);
            return -1;
        }
        sleep(delay < left ? delay : (unsigned)left + 1);
        /* polite to the controller on long studies: every 30 s at most */
        delay = delay >= 20 ? 30 : delay + delay / 2 + 1;
    }
}

/* The last line of the job's log, cleaned for one line of ours. */
static void log_tail(const char *log, char *out, size_t n)
{
    HxBuf b = {0};
    out[0] = '\0';
    if (hx_read_file(log, &b) == 0 && b.s) {
        size_t end = b.len;
        while (end > 0 && isspace((unsigned char)b.s[end - 1]))
            end--;
        size_t start = end;
        while (start > 0 && b.s[start - 1] != '\n')
            start--;
        size_t len = end - start < n - 1 ? end - start : n - 1;
        for (size_t i = 0; i < len; i++)
            out[i] = hx_is_ctrl((unsigned char)b.s[start + i]) ? '?' : b.s[start + i];
        out[len] = '\0';
    }
    hx_buf_free(&b);
}

/* The end of --submit: where the CSV and the log are, the table, the exit
 * status (0 only for a job that completed, or one that left the queue
 * unseen with every row written). */
static int report_job(const char *id, const JobInfo *j, const char *csv, size_t nrows)
{
    long rows = csv_rows(csv);
    char log[64], tail[160];
    snprintf(log, sizeof log, "slurm-%s.out", id);
    int ok = strcmp(j->state, "COMPLETED") == 0 || (!j->state[0] && rows >= (long)nrows);
    if (ok)
        fprintf(stderr, "harness slurm: job %s %s: %ld/%zu rows in %s, log %s\n", id,
                j->state[0] ? j->state : "ended (state unknown: no accounting)", rows, nrows, csv, log);
    int trc = 0;
    if (rows > 0) {
        char *av[] = {"table", (char *)csv, NULL};
        fflush(stderr);
        optind = 0; /* getopt starts afresh for table's options */
        trc = hx_cmd_table(2, av);
        fflush(stdout);
    }
    if (ok)
        return trc;
    log_tail(log, tail, sizeof tail);
    /* the scheduler's interruptions need nothing but a resubmission */
    int cut = strcmp(j->state, "CANCELLED") == 0 || strcmp(j->state, "TIMEOUT") == 0 ||
              strcmp(j->state, "PREEMPTED") == 0 || strcmp(j->state, "NODE_FAIL") == 0;
    fprintf(stderr, "harness slurm: job %s ended %s%s%s: %ld/%zu rows in %s; log %s%s%s%s; "
                    "%s--submit again continues the CSV\n", id, j->state[0] ? j->state : "(state unknown)",
            j->exit_code[0] ? " exit " : "", j->exit_code, rows, nrows, csv, log,
            tail[0] ? " ends: '" : "", tail, tail[0] ? "'" : "", cut ? "" : "once fixed, ");
    return 1;
}

/* A positive count option; 0 with one line said on bad input. */
static long count_opt(const char *name, const char *v, long max)
{
    long n;
    if (hx_parse_int(v, 1, max, &n) == 0)
        return n;
    fprintf(stderr, "harness slurm: --%s: expected an integer >= 1, got '%s'\n", name, v);
    return 0;
}

/* A value for an #SBATCH line; NULL with one line said when it has more
 * than letters, digits and the characters in extra. */
static const char *name_opt(const char *name, const char *v, const char *extra)
{
    if (sbatch_value_ok(v, extra))
        return v;
    fprintf(stderr, "harness slurm: --%s: expected a name of letters, digits and %s, got '%s'\n",
            name, extra, v);
    return NULL;
}

/* Fills o from the command line. Returns 0, 1 on bad input (said), or 2
 * after --help. */
static int parse_opts(int argc, char **argv, SlurmOpts *o)
{
    static const struct option lo[] = {
        {"output", required_argument, NULL, 'o'}, {"nodes", required_argument, NULL, 'N'},
        {"time", required_argument, NULL, 't'}, {"partition", required_argument, NULL, 'p'},
        {"account", required_argument, NULL, 'A'}, {"job-name", required_argument, NULL, 'J'},
        {"ntasks", required_argument, NULL, 'n'}, {"cpus-per-task", required_argument, NULL, 'c'},
        {"mpi", required_argument, NULL, 'm'}, {"max-wait", required_argument, NULL, 'w'},
        {"submit", no_argument, NULL, 's'}, {"help", no_argument, NULL, 'h'}, {NULL, 0, NULL, 0}};
    memset(o, 0, sizeof *o);
    o->time_limit = "01:00:00";
    o->time_s = 3600;
    o->mpi = "pmix";
    o->nodes = 1;
    int c;
    while ((c = getopt_long(argc, argv, "o:N:t:p:A:J:n:c:sh", lo, NULL)) != -1) {
        switch (c) {
        case 'o': o->out_path = optarg; break;
        case 's': o->submit = 1; break;
        case 'N': if (!(o->nodes = count_opt("nodes", optarg, 100000))) return 1; break;
        case 'n': if (!(o->ntasks = count_opt("ntasks", optarg, 1000000))) return 1; break;
        case 'c': if (!(o->cpus = count_opt("cpus-per-task", optarg, 4096))) return 1; break;
        case 't':
        case 'w': {
            long s;
            if (parse_hms(optarg, &s)) {
                fprintf(stderr, "harness slurm: --%s: expected HH:MM:SS (e.g. 02:30:00), got '%s'\n",
                        c == 't' ? "time" : "max-wait", optarg);
                return 1;
            }
            if (c == 't')
                o->time_limit = optarg, o->time_s = s;
            else
                o->max_wait_s = s;
            break;
        }
        /* a comma-separated partition list lets Slurm pick the first free one */
        case 'p': if (!(o->partition = name_opt("partition", optarg, "._,+-"))) return 1; break;
        case 'A': if (!(o->account = name_opt("account", optarg, "._+-"))) return 1; break;
        case 'J': if (!(o->job_name = name_opt("job-name", optarg, "._+-"))) return 1; break;
        case 'm': if (!(o->mpi = name_opt("mpi", optarg, "_-"))) return 1; break;
        case 'h': usage_slurm(stdout); return 2;
        default: usage_slurm(stderr); return 1;
        }
    }
    if (optind != argc - 1) {
        fprintf(stderr, "harness slurm: expected one CONFIG argument (see --help)\n");
        return 1;
    }
    o->config = argv[optind];
    if (!o->max_wait_s)
        o->max_wait_s = o->time_s + 3600; /* an hour in the queue on top */
    return 0;
}

/* Sizes from the expanded plan, not the raw lists: threads on a serial
 * backend collapse to "-" and must not inflate the request. The options
 * win over the plan. */
static void size_plan(const HxPlan *plan, const SlurmOpts *o, Sizing *sz)
{
    memset(sz, 0, sizeof *sz);
    sz->ntasks = sz->cpus = 1;
    for (size_t i = 0; i < plan->n; i++) {
        const HxRun *r = &plan->runs[i];
        long v;
        sz->nrows += !r->warmup;
        if (hx_run_is_mpi(r->v)) {
            sz->nmpi++;
            sz->ngpu += hx_backend_gpu(r->v[HX_DIM_BACKEND]);
            if (strcmp(r->v[HX_DIM_RANKS], "-") != 0 &&
                hx_parse_int(r->v[HX_DIM_RANKS], 1, 4096, &v) == 0 && v > sz->ntasks)
                sz->ntasks = v;
        }
        if (strcmp(r->v[HX_DIM_THREADS], "-") != 0 &&
            hx_parse_int(r->v[HX_DIM_THREADS], 1, 4096, &v) == 0 && v > sz->cpus)
            sz->cpus = v;
    }
    if (o->ntasks)
        sz->ntasks = o->ntasks;
    if (o->cpus)
        sz->cpus = o->cpus;
}

/* What every script of make_script starts with. */
#define SCRIPT_OWN "#!/bin/bash\n# Generated by `harness slurm "

/* Writes text to path, executable like scripts/slurm-hybrid.sbatch (sbatch
 * does not need it). Returns 0 or -1 with one line said. */
static int write_script(const char *path, const char *text)
{
    if (hx_may_replace("harness slurm", path, SCRIPT_OWN) != 0)
        return -1;
    FILE *f = fopen(path, "w");
    int bad = !f;
    if (f) {
        bad = fputs(text, f) == EOF;
        bad |= fclose(f) != 0;   /* a full disk shows up here */
    }
    if (bad) {
        fprintf(stderr, "harness slurm: %s: cannot write: %s\n", path, strerror(errno));
        return -1;
    }
    chmod(path, 0755);
    return 0;
}

/* --submit: the script to a file, sbatch, follow, report. */
static int submit_and_follow(const SlurmOpts *o, const HxConfig *cfg, const char *text,
                             const char *csv, const Sizing *sz)
{
    HxBuf defpath = {0};
    const char *path = o->out_path;
    if (!path) {
        mkdir("results", 0755); /* (fopen below says it if this failed) */
        hx_buf_printf(&defpath, "results/%s-slurm.sbatch", cfg->study);
        path = defpath.s;
    }
    char id[32];
    JobInfo j;
    int rc = 1;
    if (write_script(path, text) == 0 && submit_script(path, id, sizeof id) == 0) {
        fprintf(stderr, "harness slurm: submitted %s as job %s (%ld node(s), %ld task(s) x %ld "
                        "cpu(s)); log slurm-%s.out, CSV %s\n", path, id, o->nodes, sz->ntasks,
                sz->cpus, id, csv);
        if (follow_job(id, csv, sz->nrows, o->max_wait_s, &j) == 0)
            rc = report_job(id, &j, csv, sz->nrows);
    }
    hx_buf_free(&defpath);
    return rc;
}

int hx_cmd_slurm(int argc, char **argv)
{
    SlurmOpts o;
    int prc = parse_opts(argc, argv, &o);
    if (prc)
        return prc == 2 ? 0 : 1;
    /* the path and the study name go into the script's comments and
     * commands: a newline there would start a command of its own */
    if (hx_has_ctrl(o.config)) {
        fprintf(stderr, "harness slurm: the config path holds a control character (a newline?)\n");
        return 1;
    }
    HxConfig cfg;
    if (hx_config_open(o.config, &cfg))
        return 1;
    if (hx_has_ctrl(cfg.study)) {
        fprintf(stderr, "harness slurm: %s: the study name holds a control character\n", o.config);
        hx_config_free(&cfg);
        return 1;
    }
    HxPlan plan;
    hx_expand(&cfg, &plan);
    Sizing sz;
    size_plan(&plan, &o, &sz);
    int rc = 1;
    HxBuf name = {0}, script = {0}, csv = {0};
    /* Slurm will not start a job with more nodes than tasks; say so here
     * rather than at submission. */
    if (o.nodes > sz.ntasks) {
        fprintf(stderr, "harness slurm: --nodes: %ld nodes but the largest run has %ld "
                        "rank(s); at most %ld node(s) can be used\n", o.nodes, sz.ntasks, sz.ntasks);
        goto done;
    }
    if (!o.job_name) {
        /* the study name, with anything sbatch would split on replaced */
        for (const char *s = cfg.study; *s; s++)
            hx_buf_putn(&name, isalnum((unsigned char)*s) || strchr("._+-", *s) ? s : "_", 1);
        o.job_name = name.s ? name.s : "raybench";
    }
    /* one path for every job of the study, so a resubmission resumes it */
    hx_buf_printf(&csv, "results/%s-slurm.csv", cfg.study);
    make_script(&script, &cfg, &plan, &o, &sz, csv.s);
    if (o.submit) {
        rc = submit_and_follow(&o, &cfg, script.s, csv.s, &sz);
    } else if (!o.out_path) {
        fputs(script.s, stdout);
        rc = 0;
    } else if (write_script(o.out_path, script.s) == 0) {
        fprintf(stderr, "harness slurm: wrote %s (%ld node(s), %ld task(s) x %ld cpu(s)); "
                        "submit with: sbatch %s\n", o.out_path, o.nodes, sz.ntasks, sz.cpus, o.out_path);
        rc = 0;
    }
done:
    hx_buf_free(&script);
    hx_buf_free(&name);
    hx_buf_free(&csv);
    hx_plan_free(&plan);
    hx_config_free(&cfg);
    return rc;
}
