/* fingerprint.c: what machine and code produced a row.
 * Timings are only comparable on the same machine, so every row carries the
 * CPU model, core count, SMT, governor, compiler and GPU, plus a short hash of
 * them that `compare` checks before it trusts a time ratio. */
#include "hx.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <sys/utsname.h>
#include <unistd.h>

static void copy_trim(char *dst, size_t n, const char *src)
{
    /* bounded copy (memmove: src may be dst); longer values are cut */
    size_t len = strlen(src);
    if (len >= n)
        len = n - 1;
    memmove(dst, src, len);
    dst[len] = '\0';
    char *t = hx_trim(dst);
    memmove(dst, t, strlen(t) + 1);
    /* keep CSV cells tidy: no commas or quotes inside fingerprint cells */
    for (char *p = dst; *p; p++)
        if (*p == ',' || *p == '"' || *p == '\n')
            *p = ' ';
}

/* First line of a program's stdout, or "" (stderr discarded). No shell:
 * the arguments (a folder from --raytrace, say) reach it as they are. */
static void first_line_of(char *const argv[], char *out, size_t n)
{
    char line[512];
    if (hx_run_argv(argv, NULL, line, sizeof line, 1) != 0)
        line[0] = '\0';
    line[strcspn(line, "\n")] = '\0';
    copy_trim(out, n, line);
}

/* The line of text that starts with key, without the key; "" if none. */
static void line_after(const char *text, const char *key, char *out, size_t n)
{
    out[0] = '\0';
    for (const char *l = text; l && *l; l = strchr(l, '\n') ? strchr(l, '\n') + 1 : NULL)
        if (strncmp(l, key, strlen(key)) == 0) {
            l += strlen(key);
            char line[512];
            size_t len = strcspn(l, "\n");
            if (len >= sizeof line)
                len = sizeof line - 1;
            memcpy(line, l, len);
            line[len] = '\0';
            copy_trim(out, n, line);
            return;
        }
}

/* The commit of the renderer's checkout, "-dirty" when a tracked file other
 * than exclude (the study's own CSV, which the study itself changes) differs:
 * only for a renderer that does not name its commit (`raytrace -V` before
 * "commit:"), as it finds no checkout around an out-of-tree build. */
static void git_commit_of(const char *repo_dir, const char *exclude, char *out, size_t n)
{
    char *dir = (char *)(repo_dir ? repo_dir : ".");
    char *rev[] = {"git", "-C", dir, "rev-parse", "--short", "HEAD", NULL};
    first_line_of(rev, out, n - 8);
    if (out[0] == '\0') {
        snprintf(out, n, "unknown");
        return;
    }
    /* a pathspec outside the work tree is an error to git: exclude the CSV
     * only when it lies inside */
    char top[4096];
    char *tl[] = {"git", "-C", dir, "rev-parse", "--show-toplevel", NULL};
    first_line_of(tl, top, sizeof top);
    char *abs = exclude ? realpath(exclude, NULL) : NULL;
    size_t tn = strlen(top);
    int inside = abs && tn && strncmp(abs, top, tn) == 0 && abs[tn] == '/';
    HxBuf spec = {0};
    char *st[] = {"git", "-C", dir, "status", "--porcelain", "--untracked-files=no", NULL, NULL, NULL};
    if (inside) { /* else no pathspec: every tracked file */
        hx_buf_printf(&spec, ":(exclude)%s", abs);
        st[6] = "--";
        st[7] = spec.s;
    }
    char dirty[256];
    first_line_of(st, dirty, sizeof dirty);
    if (dirty[0])
        strcat(out, "-dirty");
    hx_buf_free(&spec);
    free(abs);
}

void hx_utc_now(char *buf, size_t n)
{
    time_t now = time(NULL);
    struct tm tm;
    gmtime_r(&now, &tm);
    strftime(buf, n, "%Y-%m-%dT%H:%M:%SZ", &tm);
}

void hx_fingerprint_hash(HxFingerprint *fp)
{
    /* host and git commit are left out: two hosts of one cluster model are
     * the same machine for timing purposes, and a commit is what we compare */
    HxBuf b = {0};
    hx_buf_printf(&b, "%s|%d|%d|%d|%s|%s|%s", fp->cpu_model, fp->phys_cores,
                  fp->logical_cpus, fp->smt, fp->governor, fp->compiler, fp->gpu_name);
    hx_fnv1a_hex(b.s, fp->fingerprint);
    hx_buf_free(&b);
}

void hx_fingerprint_get(HxFingerprint *fp, const HxTopo *t, int want_gpu, const char *raytrace,
                        const char *mpirun, const char *exclude)
{
    memset(fp, 0, sizeof *fp);
    if (gethostname(fp->host, sizeof fp->host - 1) != 0)
        strcpy(fp->host, "unknown");
    strcpy(fp->cpu_model, "unknown");
    FILE *f = fopen("/proc/cpuinfo", "r");
    if (f) {
        char line[512];
        while (fgets(line, sizeof line, f)) {
            /* x86: "model name"; arm64: no model name, use "CPU part" */
            if (strncmp(line, "model name", 10) == 0 || strncmp(line, "Processor", 9) == 0) {
                char *c = strchr(line, ':');
                if (c) {
                    copy_trim(fp->cpu_model, sizeof fp->cpu_model, c + 1);
                    break;
                }
            }
        }
        fclose(f);
    }
    fp->phys_cores = t->ncores;
    fp->logical_cpus = t->npus;
    fp->smt = t->npus > t->ncores;
    strcpy(fp->governor, "n/a");
    f = fopen("/sys/devices/system/cpu/cpu0/cpufreq/scaling_governor", "r");
    if (f) {
        char g[64];
        if (fgets(g, sizeof g, f))
            copy_trim(fp->governor, sizeof fp->governor, g);
        fclose(f);
    }
    /* The harness is built by the same meson project and compiler as the
     * renderer, so its own compiler string names the renderer's compiler. */
#if defined(__clang__)
    snprintf(fp->compiler, sizeof fp->compiler, "clang %s", __clang_version__);
#elif defined(__GNUC__)
    snprintf(fp->compiler, sizeof fp->compiler, "gcc %s", __VERSION__);
#else
    strcpy(fp->compiler, "unknown");
#endif
    copy_trim(fp->compiler, sizeof fp->compiler, fp->compiler);
    strcpy(fp->gpu_name, "-");
    strcpy(fp->gpu_driver, "-");
    if (want_gpu) {
        char line[512];
        char *smi[] = {"nvidia-smi", "--query-gpu=name,driver_version", "--format=csv,noheader", NULL};
        first_line_of(smi, line, sizeof line);
        /* copy_trim turned the comma into a space; split on the last space */
        char *sp = strrchr(line, ' ');
        if (sp) {
            *sp = '\0';
            copy_trim(fp->gpu_name, sizeof fp->gpu_name, line);
            copy_trim(fp->gpu_driver, sizeof fp->gpu_driver, sp + 1);
        }
    }
    /* the renderer's build flags and commit, as it was built (-V) */
    char version[2048] = "";
    char *rv[] = {(char *)raytrace, "--version", NULL};
    if (raytrace && hx_run_argv(rv, NULL, version, sizeof version, 1) != 0)
        version[0] = '\0';
    line_after(version, "build:", fp->build_flags, sizeof fp->build_flags);
    if (!fp->build_flags[0])
        strcpy(fp->build_flags, raytrace ? "unknown" : "-");
    line_after(version, "commit:", fp->git_commit, sizeof fp->git_commit);
    if (strchr(fp->git_commit, ' ')) /* a commit is one word */
        fp->git_commit[0] = '\0';
    if (!fp->git_commit[0]) { /* an older renderer: its folder's checkout */
        /* a command study: the checkout the harness runs in */
        char *repo_dir = raytrace ? hx_dirname(raytrace) : hx_strdup(".");
        git_commit_of(repo_dir, exclude, fp->git_commit, sizeof fp->git_commit);
        free(repo_dir);
    }
    struct utsname u;
    if (uname(&u) == 0)
        snprintf(fp->kernel, sizeof fp->kernel, "%s %s", u.sysname, u.release);
    else
        strcpy(fp->kernel, "unknown");
    strcpy(fp->mpi_version, "-");
    if (mpirun) {
        char *mv[] = {(char *)mpirun, "--version", NULL};
        first_line_of(mv, fp->mpi_version, sizeof fp->mpi_version);
        if (!fp->mpi_version[0])
            strcpy(fp->mpi_version, "unknown");
    }
    hx_fingerprint_hash(fp);
}
