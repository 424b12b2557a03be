/* proc.c: process control for `harness run`: one child run at a time.
 *
 * Each run is a child in its own process group (so a timeout can kill
 * everything it started, mpirun's ranks included), bound to its planned cores
 * before exec, with stdout/stderr read through pipes and a wall-clock deadline.
 * SIGINT and SIGTERM end the run in progress; as the subreaper, the harness
 * kills and reaps whatever a run left behind before the next one starts. */
#include "run.h"

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <dirent.h>
#include <sys/resource.h>
#ifdef __linux__
#include <sys/prctl.h>
#endif
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

/* SIGINT or SIGTERM received (the signal number): the current run is ended,
 * no row is written for it, and the study stops (exit 128 + signal). */
static volatile sig_atomic_t g_stop;

static void on_stop_signal(int sig)
{
    g_stop = sig;
}

int hx_stop_signal(void)
{
    return g_stop;
}

/* No SA_RESTART: poll() and waitpid() return EINTR, and the loop sees g_stop. */
void hx_install_stop_handlers(void)
{
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_stop_signal;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
#ifdef __linux__
    /* Processes a run leaves behind (mpirun's ranks in other process groups,
     * a daemon in its own session) are re-parented to the harness, which
     * reaps them before the next run starts (hx_reap_strays). */
    prctl(PR_SET_CHILD_SUBREAPER, 1);
#endif
}

/* Kills and reaps every process of the last run that is still alive: as the
 * subreaper, they are all children of the harness now. The next run starts
 * on idle cores. */
void hx_reap_strays(void)
{
    for (int round = 0; round < 500; round++) {
        int st;
        pid_t w;
        while ((w = waitpid(-1, &st, WNOHANG)) > 0)
            ;
        if (w < 0 && errno == ECHILD)
            return;
        DIR *d = opendir("/proc");
        struct dirent *e;
        while (d && (e = readdir(d)) != NULL) {
            char path[300], buf[512];
            if (e->d_name[0] < '1' || e->d_name[0] > '9')
                continue;
            snprintf(path, sizeof path, "/proc/%s/stat", e->d_name);
            FILE *f = fopen(path, "r");
            if (!f)
                continue;
            size_t n = fread(buf, 1, sizeof buf - 1, f);
            fclose(f);
            buf[n] = '\0';
            const char *rp = strrchr(buf, ')'); /* the name may hold spaces */
            int ppid = 0;
            if (rp && sscanf(rp + 1, " %*c %d", &ppid) == 1 && ppid == (int)getpid())
                kill((pid_t)atoi(e->d_name), SIGKILL);
        }
        if (d)
            closedir(d);
        usleep(10000);
    }
}

/* Reaps child (wait4, so its resource use comes with it): 1 when it was
 * reaped now. */
static int reap(pid_t child, int *status, int flags, HxChildResult *res)
{
    struct rusage ru;
    if (wait4(child, status, flags, &ru) != child)
        return 0;
    res->have_usage = 1;
    res->user_ms = (double)ru.ru_utime.tv_sec * 1e3 + (double)ru.ru_utime.tv_usec / 1e3;
    res->sys_ms = (double)ru.ru_stime.tv_sec * 1e3 + (double)ru.ru_stime.tv_usec / 1e3;
    res->maxrss_kib = ru.ru_maxrss;
    return 1;
}

const char *hx_signal_name(int sig)
{
    switch (sig) {
    case SIGSEGV: return "SIGSEGV";
    case SIGABRT: return "SIGABRT";
    case SIGBUS: return "SIGBUS";
    case SIGFPE: return "SIGFPE";
    case SIGILL: return "SIGILL";
    case SIGKILL: return "SIGKILL";
    case SIGTERM: return "SIGTERM";
    case SIGINT: return "SIGINT";
    case SIGPIPE: return "SIGPIPE";
    case SIGTRAP: return "SIGTRAP";
    default: return NULL;
    }
}

/* Keep the tail of a large stdout or stderr: the record line is the last
 * line, and a metric is the last match (one only before the tail is not
 * found, never replaced by an earlier one). */
static void keep_tail(HxBuf *b)
{
    const size_t limit = 4u << 20, keep = 64u << 10;
    if (b->len > limit) {
        size_t from = b->len - keep; /* (from a line's start, where the tail has one) */
        const char *nl = memchr(b->s + from, '\n', keep - 1);
        from = nl ? (size_t)(nl + 1 - b->s) : from;
        memmove(b->s, b->s + from, b->len - from);
        b->len -= from;
        b->s[b->len] = '\0';
    }
}

static void kill_group(pid_t pgid, double grace_ms, pid_t child, int *reaped, int *status, HxChildResult *res)
{
    kill(-pgid, SIGTERM);
    double until = hx_now_ms() + grace_ms;
    while (!*reaped && hx_now_ms() < until) {
        if (reap(child, status, WNOHANG, res))
            *reaped = 1;
        else
            usleep(10000);
    }
    /* SIGKILL the group even if the leader is gone: its children may not be */
    kill(-pgid, SIGKILL);
    if (!*reaped && reap(child, status, 0, res))
        *reaped = 1;
}

/* The child's side once its descriptors are set: own process group,
 * default signals, the run's folder, binding, environment, exec. A study's
 * run whose binding fails goes on unpinned (its row says pin_held=no);
 * with strict (harness ceiling, which must measure pinned copies) it ends
 * with 126. Does not return. */
_Noreturn void hx_child_exec(const HxCommand *cmd, const HxTopo *topo, const HxRun *run, int strict)
{
    setpgid(0, 0);
    signal(SIGINT, SIG_DFL);
    signal(SIGTERM, SIG_DFL);
    if (cmd->dir && chdir(cmd->dir) != 0) {
        fprintf(stderr, "cannot enter the run's folder %s: %s\n", cmd->dir, strerror(errno));
        _exit(127);
    }
    if ((cmd->bind || strict) && hx_bind_child(topo, run) != 0) {
        fprintf(stderr, "harness: %s: binding to cores %s failed: %s\n", strict ? "error" : "warning",
                run->cores_planned ? run->cores_planned : "-", strerror(errno));
        if (strict)
            _exit(126);
    }
    for (int i = 0; cmd->env.v && cmd->env.v[i]; i += 2)
        setenv(cmd->env.v[i], cmd->env.v[i + 1], 1);
    execvp(cmd->argv.v[0], cmd->argv.v);
    fprintf(stderr, "cannot execute %s: %s\n", cmd->argv.v[0], strerror(errno));
    _exit(127);
}

/* The child's side of the fork: stdin from /dev/null, the pipes. */
static void exec_child(const HxCommand *cmd, const HxTopo *topo, const HxRun *run, const int po[2],
                       const int pe[2])
{
    int devnull = open("/dev/null", O_RDONLY);
    if (devnull >= 0) {
        dup2(devnull, 0);
        if (devnull > 0)
            close(devnull);
    }
    dup2(po[1], 1);
    dup2(pe[1], 2);
    close(po[0]);
    close(po[1]);
    close(pe[0]);
    close(pe[1]);
    hx_child_exec(cmd, topo, run, 0);
}

/* A started child, as the parent follows it. */
typedef struct {
    pid_t pid;           /* the child, leader of its own process group */
    double t0, deadline; /* hx_now_ms() at the fork; t0 + the timeout */
    int reaped, status;
    HxChildResult *res;
    HxWatch *watch;      /* NULL: not watched */
} Child;

/* Reads the child's stdout (out_fd) and stderr (err_fd) until both close, or
 * the deadline passes or a stop signal comes (the group is killed), or the
 * leader is gone and something it started still holds the pipes. Closes
 * both. */
static void read_output(Child *c, int out_fd, int err_fd)
{
    HxChildResult *res = c->res;
    struct pollfd fds[2] = {{out_fd, POLLIN, 0}, {err_fd, POLLIN, 0}};
    int open_fds = 2;
    double reaped_at = 0;
    char chunk[65536];
    while (open_fds > 0) {
        double now = hx_now_ms();
        if (g_stop) {
            kill_group(c->pid, 500, c->pid, &c->reaped, &c->status, res);
            break;
        }
        if (now >= c->deadline) {
            res->timed_out = 1;
            kill_group(c->pid, 500, c->pid, &c->reaped, &c->status, res);
            break;
        }
        if (!c->reaped && reap(c->pid, &c->status, WNOHANG, res)) {
            c->reaped = 1;
            reaped_at = now;
            res->wall_ms = now - c->t0;
        }
        if (c->reaped && now - reaped_at > 500) {
            /* leader gone but something it started still holds the pipes */
            kill(-c->pid, SIGKILL);
            break;
        }
        double wait = c->deadline - now;
        /* wake up now and then to notice an exited leader (see above), and
         * every 20 ms to see where a watched run's threads are */
        int every = c->watch ? 20 : 100;
        int ms = wait > every ? every : (int)wait + 1;
        if (c->watch && !c->reaped)
            hx_watch_sample(c->watch);
        int pr = poll(fds, 2, ms);
        if (pr < 0) {
            if (errno == EINTR)
                continue;
            break;
        }
        for (int i = 0; i < 2; i++) {
            if (fds[i].fd < 0 || !(fds[i].revents & (POLLIN | POLLHUP | POLLERR)))
                continue;
            ssize_t n = read(fds[i].fd, chunk, sizeof chunk);
            if (n > 0) {
                HxBuf *b = i == 0 ? &res->out : &res->err;
                hx_buf_putn(b, chunk, (size_t)n);
                keep_tail(b);
            } else if (n == 0 || errno != EINTR) {
                close(fds[i].fd);
                fds[i].fd = -1;
                open_fds--;
            }
        }
    }
    for (int i = 0; i < 2; i++)
        if (fds[i].fd >= 0)
            close(fds[i].fd);
}

/* After the pipes closed: unless reaped or timed out already, the leader
 * should be exiting: wait for it up to the deadline. */
static void wait_leader(Child *c)
{
    HxChildResult *res = c->res;
    if (c->reaped || res->timed_out)
        return;
    while (!c->reaped) {
        if (g_stop) {
            kill_group(c->pid, 500, c->pid, &c->reaped, &c->status, res);
            break;
        }
        if (reap(c->pid, &c->status, WNOHANG, res)) {
            c->reaped = 1;
            res->wall_ms = hx_now_ms() - c->t0;
            break;
        }
        if (hx_now_ms() >= c->deadline) {
            res->timed_out = 1;
            kill_group(c->pid, 500, c->pid, &c->reaped, &c->status, res);
            break;
        }
        usleep(200);
    }
}

void hx_child_result_free(HxChildResult *res)
{
    hx_buf_free(&res->out);
    hx_buf_free(&res->err);
    free(res->cores_seen);
    res->cores_seen = NULL;
}

int hx_run_child(const HxCommand *cmd, const HxTopo *topo, const HxRun *run, double timeout_s,
                 HxChildResult *res)
{
    memset(res, 0, sizeof *res);
    int po[2], pe[2] = {-1, -1};
    if (pipe(po) != 0)
        return -1;
    if (pipe(pe) != 0) {
        close(po[0]);
        close(po[1]);
        return -1;
    }
    double t0 = hx_now_ms();
    pid_t pid = fork();
    if (pid < 0) {
        close(po[0]);
        close(po[1]);
        close(pe[0]);
        close(pe[1]);
        return -1;
    }
    if (pid == 0)
        exec_child(cmd, topo, run, po, pe);
    setpgid(pid, pid); /* both sides: no race with an early kill */
    close(po[1]);
    close(pe[1]);
    Child c = {pid, t0, t0 + timeout_s * 1e3, 0, 0, res, cmd->watch_exe ? hx_watch_new(pid, cmd->watch_exe, cmd->watch_any) : NULL};
    read_output(&c, po[0], pe[0]);
    wait_leader(&c);
    if (c.watch)
        res->cores_seen = hx_watch_end(c.watch, topo);
    if (res->timed_out)
        res->wall_ms = hx_now_ms() - t0;
    if (WIFEXITED(c.status)) {
        res->exited = 1;
        res->code = WEXITSTATUS(c.status);
    } else if (WIFSIGNALED(c.status)) {
        res->exited = 0;
        res->code = WTERMSIG(c.status);
    }
    return 0;
}

/* argv in dir as a run is started (hx_run_child: its own process group,
 * killed whole at timeout_s or on a stop signal): a command study's setup
 * and version, which must not hang the study. */
int hx_run_limited(char **argv, const char *dir, double timeout_s, HxBuf *out, int say_err)
{
    HxCommand cmd;
    memset(&cmd, 0, sizeof cmd);
    for (char **a = argv; *a; a++)
        hx_strlist_push(&cmd.argv, *a);
    hx_command_terminate(&cmd);
    cmd.dir = (char *)dir;
    HxChildResult res;
    int rc = 127;
    if (hx_run_child(&cmd, NULL, NULL, timeout_s, &res) == 0) {
        rc = res.timed_out ? 124 : res.exited ? res.code : 128 + res.code;
        if (out && res.out.s)
            hx_buf_put(out, res.out.s);
        if (say_err && res.err.s)
            fputs(res.err.s, stderr);
        hx_child_result_free(&res);
    }
    hx_strlist_free(&cmd.argv);
    hx_strlist_free(&cmd.env);
    return rc;
}
