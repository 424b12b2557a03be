/* run.h: the parts of `harness run` that runner.c drives, internal to the
 * harness (hx.h has the public API).
 *
 *   proc.c    process control: the stop signals, one child run in its own
 *             process group with a deadline, reaping what a run leaves
 *   launch.c  the per-run command line: the MPI launcher (mpirun or srun),
 *             the renderer's arguments, the environment, the scene cache */
#ifndef HX_RUN_H
#define HX_RUN_H

#include "hx.h"

#include <sys/types.h>

/* ---- process control (proc.c) ---- */

typedef struct {
    int timed_out;
    int exited;        /* WIFEXITED */
    int code;          /* exit code or signal number */
    double wall_ms;
    /* wait4's rusage of the child and the descendants it waited for: CPU
     * time, and the largest resident set among them (Linux's ru_maxrss, the
     * peak of the biggest process, not a sum) */
    int have_usage;
    double user_ms, sys_ms;
    long maxrss_kib;
    HxBuf out, err;
    char *cores_seen;  /* watched runs: the CPUs its threads ran on ("0,1"), else NULL */
} HxChildResult;

/* SIGINT or SIGTERM received (the signal number), else 0: the current run is
 * ended, no row is written for it, and the study stops (exit 128 + signal). */
int hx_stop_signal(void);
/* Installs the SIGINT/SIGTERM handlers (without SA_RESTART) and makes the
 * harness the subreaper of what its runs leave behind. */
void hx_install_stop_handlers(void);
/* Kills and reaps every process of the last run that is still alive. */
void hx_reap_strays(void);
struct HxCommand;
/* Runs c's argv (PATH search) with its env's name, value pairs set, in its
 * folder (c->dir, NULL: here), in its own process group, bound to run's
 * planned cores when c->bind, stdout and stderr read into res (each whole up
 * to 4 MiB, past that its last 64 KiB from a line's start); killed (the whole
 * group) at timeout_s or on a stop signal. With c->watch_exe, the CPUs of
 * its processes running that program are sampled (res->cores_seen). 0, or
 * -1 when pipe or fork failed. */
int hx_run_child(const struct HxCommand *c, const HxTopo *topo, const HxRun *run, double timeout_s,
                 HxChildResult *res);
void hx_child_result_free(HxChildResult *res);
/* argv (NULL-terminated) in dir (NULL: here) as hx_run_child runs it, unbound,
 * ended at timeout_s: its exit status, 124 when it timed out, 128 + the
 * signal, 127 when it could not start; its stdout into out (NULL: dropped),
 * its stderr to ours where say_err. */
int hx_run_limited(char **argv, const char *dir, double timeout_s, HxBuf *out, int say_err);
/* The child's side of a fork once its descriptors are set: own process
 * group, folder, binding to run's cores (when c->bind, or strict: then a
 * failed binding exits 126, else it warns), environment, exec. */
_Noreturn void hx_child_exec(const struct HxCommand *c, const HxTopo *topo, const HxRun *run, int strict);

/* ---- interleaved A/B (ab.c) ---- */
typedef struct {
    int rounds;
    double factor, alpha, timeout_s;
} HxAbRule;
typedef struct {
    int compared, regressions, improvements, inconclusive;
    int images_differ; /* configurations whose last images of A and B differ */
    double cost[3];    /* the last configuration's B/A cost (a rate inverted): median, 95% interval */
} HxAbTally;
/* harness ab --config: each configuration of config (only its config_id
 * `only` when not NULL) run with raytrace builds rt[0] (A) and rt[1] (B),
 * interleaved, the record key's verdict of B against A printed and
 * counted in *tal; header (or NULL) printed once both builds have run. 0,
 * or -1 (said) when the config is bad, a run failed or no configuration
 * matched. */
int hx_ab_config(const char *config, const HxStrList *set, const char *const rt[2], const char *only, const char *key,
                 int higher, const HxAbRule *rule, HxAbTally *tal, const char *header);

/* ---- what else the machine did during a run (noise.c) ---- */
typedef struct {
    unsigned long long busy, idle, iowait, steal; /* clock ticks, all CPUs */
    double load1;                                 /* 1-minute load, -1 unknown */
    int ok;
} HxCpuStat;
typedef struct {
    double load1, others_cores, steal_pct, iowait_pct; /* -1: unknown */
    int busy, stolen;
} HxNoise;
void hx_cpu_stat(HxCpuStat *s);
/* The clock ticks from a to b over every CPU: busy, idle, iowait and stolen. */
unsigned long long hx_cpu_ticks(const HxCpuStat *a, const HxCpuStat *b);
/* The noise between samples a and b of a run of wall_ms that used
 * own_cpu_ms of CPU itself, with workers workers on a machine of cpus. */
void hx_noise(const HxCpuStat *a, const HxCpuStat *b, double wall_ms, double own_cpu_ms, int cpus, int workers,
              HxNoise *n);

/* ---- the machine's floor for one synchronised step (syncstep.c) ---- */
typedef struct {
    double share;      /* median over steps: the fastest worker's own time over the step */
    int steps;
    uint64_t sink;     /* the work's result, kept so that it is done */
} HxSyncStep;
/* nsteps steps of w threads pinned one per core of cores (the calling
 * thread on cores[0], its binding restored after), each doing quantum_ms of
 * fixed work per step. 0, or -1 when a thread or a binding failed, a wait
 * passed hx_sync_wait_ms or a stop signal came. */
int hx_sync_step(const HxTopo *t, const int *cores, int w, double quantum_ms, int nsteps, HxSyncStep *out);
/* How long hx_sync_step waits for its workers to start, or for a step of
 * quantum_ms to end, before it gives up. */
double hx_sync_wait_ms(double quantum_ms);
/* The shares of nsteps steps of w workers from their start and end times
 * (ns, step-major). */
void hx_sync_summarise(const int64_t *start, const int64_t *end, int nsteps, int w, HxSyncStep *out);

/* ---- which CPUs a run's threads use (watch.c) ---- */
typedef struct HxWatch HxWatch;
/* Follows the descendants of pid (itself included) whose executable's
 * name is exe (all of them when none is); with any, also every process of
 * exe started since pid was (srun's tasks, which slurmd starts). */
HxWatch *hx_watch_new(pid_t pid, const char *exe, int any);
/* One look at every thread's current CPU. */
void hx_watch_sample(HxWatch *w);
/* The CPUs seen, each as the first CPU of its core ("0,1"; NULL when none),
 * and frees w. */
char *hx_watch_end(HxWatch *w, const HxTopo *topo);
/* "SIGSEGV" and the like, NULL for a signal without a name here. */
const char *hx_signal_name(int sig);

/* ---- per-run command line (launch.c) ---- */

typedef struct HxCommand {
    HxStrList argv;  /* NULL-terminated (the NULL not counted in n) */
    HxStrList env;   /* name, value pairs, NULL-terminated likewise */
    int bind;        /* bind the child with hwloc before exec */
    char *dir;       /* the folder it starts in; NULL: the harness's */
    char *watch_exe; /* the program whose CPUs are watched; NULL: none */
    int watch_any;   /* not only its descendants (srun) */
} HxCommand;

/* Sets cfg->scene_cache once per study (kept when the config gives it). */
void hx_resolve_scene_cache(HxConfig *cfg, const char *out_path);
/* The command line and environment of run r, writing its image to image
 * (raytrace), or starting in rundir with the study's folder workdir (a
 * command study). */
void hx_build_command(const HxConfig *cfg, const HxTopo *topo, const HxRun *r, const char *raytrace,
                      const char *image, const char *rundir, const char *workdir, HxCommand *c);
/* After run r of a Slurm job (launcher srun, inside an allocation) ended
 * with status error, crash or timeout: whether the job can no longer run on
 * its nodes (a node failed, or the job is being cancelled or ended) rather
 * than the run failing. Starts `srun true` on every node under the run's
 * timeout. 1 when it fails or times out (srun's first error line in *why,
 * malloc'd), or when a stop signal came meanwhile (*why NULL); 0 when every
 * node answered, or for any other run. */
int hx_srun_job_gone(const HxConfig *cfg, const HxTopo *topo, const HxRun *r, const char *status, char **why);
/* Ends argv and env with the NULL execvp and hx_run_child want. */
void hx_command_terminate(HxCommand *c);
void hx_command_free(HxCommand *c);
/* "NAME=value ... argv..." on one line (--dry-run). */
void hx_print_command(FILE *out, const HxCommand *c);
/* The renderer: --raytrace (opt), the config's, $RAYTRACE, or the build
 * tree's ../renderer/raytrace next to the harness. malloc'd. */
char *hx_find_raytrace(const HxConfig *cfg, const char *opt);

/* ---- the correctness gate (gate.c) ---- */

typedef struct {
    char *key;         /* scene_path|resolution|max_depth: what fixes the image */
    char *hash;
    char *run_id;
    int serial;
} HxImageRef;

typedef struct {
    HxImageRef *v;
    size_t n;
} HxRefTable;

HxImageRef *hx_ref_find(HxRefTable *t, const char *key);
/* Applies the gate to an ok row; returns the new status (static string) and
 * may set *detail. Reference: the first ok serial run of the image, else the
 * first ok run. CUDA rows are never failed on the hash: the GPU image may
 * differ by rounding and is checked against a tolerance by the image test. */
const char *hx_gate(HxRefTable *t, const char *key, const char *backend, const char *hash, const char *run_id,
                    char **detail);
void hx_ref_free(HxRefTable *t);
/* "scene_path|resolution|max_depth", malloc'd. */
char *hx_image_key(const char *scene_path, const char *res, const char *depth);

/* ---- the ceiling between a study's rounds (ceiling.c, `ceiling: rounds`) ---- */

typedef struct HxCeilRounds HxCeilRounds;
/* Where `harness run` writes the ceiling of its rounds: the CSV's path
 * with "-ceiling.csv" for its ".csv" (malloc'd). */
char *hx_ceiling_rounds_path(const char *csv_path);
/* What refuses `ceiling: rounds` on this machine or plan (one allowed core,
 * no hwloc, no pinned worker count above 1): a line on stderr and -1,
 * before anything is opened. Else 0. */
int hx_ceiling_rounds_check(const HxConfig *cfg, const HxPlan *plan, const HxTopo *t);
/* The copies of each scene's pinned worker counts, their rows to go to
 * path: checked before the study's CSV is opened, nothing written (with
 * keep, as --resume does, the rounds in it read). NULL with a line on
 * stderr when this machine, plan or file cannot have them. */
HxCeilRounds *hx_ceiling_rounds_open(const HxConfig *cfg, const HxPlan *plan, const HxTopo *t, const char *raytrace,
                                     const char *path, int keep);
/* Once the study's CSV is open (locked): the file started again (or,
 * kept, its rounds read and a torn last row dropped), its header written
 * when it is new, a line saying so unless quiet; rows of machine fp. 0,
 * or -1 (said). */
int hx_ceiling_rounds_start(HxCeilRounds *c, const HxFingerprint *fp, int quiet);
/* One repeat of scene's ceiling at each of its worker counts, as round
 * `round`: one row each, a line each on stderr unless quiet; none of a
 * worker count whose row of that round the file has already. 0, or -1 (a copy failed,
 * a stop signal, or the file could not be written). */
int hx_ceiling_rounds_measure(HxCeilRounds *c, const char *scene, int round, int quiet);
void hx_ceiling_rounds_close(HxCeilRounds *c);

/* ---- what --resume accepts (resume.c) ---- */

/* The config_hash of a study's rows: what a run means beyond its run_id,
 * scene_path, study and baseline columns (warm-ups, timeout, instructions,
 * extra_args). Not the plan: a study may grow. */
void hx_settings_hash(const HxConfig *cfg, char out[20]);
/* 0 when every row of old is a run of plan made under cfg's settings (hash:
 * hx_settings_hash); else -1 with err saying what changed. */
int hx_resume_check(const HxCsv *old, const HxConfig *cfg, const HxPlan *plan, const char *hash, char *err,
                    size_t errlen);

#endif
