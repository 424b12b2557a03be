/* workdir.c: a command study's folders and the verdict on each of its runs.
 *
 * The study's folder ({workdir}) holds what `setup:` made and one folder per
 * run ({rundir}), where the run starts with its inputs linked and its
 * templates filled in. With `workdir: clean` (the default) the study's
 * folder is private and temporary and each run's folder goes when the run
 * has been read; with `workdir: keep` both stay beside the CSV. */
#define _XOPEN_SOURCE 700 /* nftw */
#include "program.h"
#include "run.h"

#include <errno.h>
#include <ftw.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static int rm_one(const char *path, const struct stat *sb, int flag, struct FTW *ftw)
{
    (void)sb;
    (void)flag;
    (void)ftw;
    remove(path);
    return 0;
}

void hx_rmtree(const char *path)
{
    /* FTW_PHYS: a link a run left is removed, never followed */
    nftw(path, rm_one, 16, FTW_DEPTH | FTW_PHYS);
}

int hx_workdir_open(const HxConfig *cfg, const char *out_path, const char *tmpdir, char **workdir, char *err,
                    size_t n)
{
    HxBuf b = {0};
    if (cfg->prog->keep) {
        size_t len = strlen(out_path);
        if (len > 4 && strcmp(out_path + len - 4, ".csv") == 0)
            len -= 4;
        hx_buf_printf(&b, "%.*s.runs", (int)len, out_path);
    } else {
        hx_buf_printf(&b, "%s/work", tmpdir);
    }
    if (mkdir(b.s, 0700) != 0 && !(errno == EEXIST && cfg->prog->keep && hx_is_dir(b.s))) {
        snprintf(err, n, "cannot make the study's folder %s: %s", b.s, strerror(errno));
        hx_buf_free(&b);
        return -1;
    }
    /* placeholders hand it to programs that start elsewhere */
    *workdir = realpath(b.s, NULL);
    hx_buf_free(&b);
    return *workdir ? 0 : -1;
}

char *hx_rundir(const char *workdir, size_t index)
{
    HxBuf b = {0};
    hx_buf_printf(&b, "%s/run-%04zu", workdir, index + 1);
    hx_rmtree(b.s); /* what a run cut short left (--resume) */
    return b.s;
}

/* The first line of stderr, else the exit status against the one
 * expected. */
static char *failure_line(const HxChildResult *res, int expected)
{
    int n;
    const char *e = hx_first_line(res->err.s, &n);
    HxBuf b = {0};
    if (n)
        hx_buf_printf(&b, "exit %d (expected %d): %.*s", res->code, expected, n, e);
    else
        hx_buf_printf(&b, "exit %d (expected %d), nothing on stderr", res->code, expected);
    return b.s;
}

const char *hx_program_status(const HxConfig *cfg, const char *rundir, HxChildResult *res, char **vals,
                              char **detail)
{
    char num[16];
    snprintf(num, sizeof num, "%d", res->code);
    hx_row_set(vals, "exit_code", num);
    /* a record line, if the program prints one, as raytrace's (stdout
     * stays whole: metrics read it) */
    char *rec = res->out.s ? hx_record_find(res->out.s) : NULL;
    if (rec)
        hx_record_to_row(rec, vals);
    int k = hx_column_index("cores_actual");
    if ((!vals[k] || !*vals[k]) && res->cores_seen)
        hx_row_set(vals, "cores_actual", res->cores_seen);
    if (res->code != cfg->prog->exit_code) {
        *detail = failure_line(res, cfg->prog->exit_code);
        return "error";
    }
    HxBuf extra = {0};
    int e = hx_column_index("extra");
    hx_buf_put(&extra, vals[e] ? vals[e] : "");
    char why[512];
    if (hx_program_collect(cfg, rundir, &res->out, &res->err, &extra, why, sizeof why) != 0) {
        *detail = hx_strdup(why);
        hx_buf_free(&extra);
        return "error";
    }
    free(vals[e]);
    vals[e] = extra.s;
    return "ok";
}
