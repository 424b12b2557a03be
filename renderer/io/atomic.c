/* atomic.c - files that appear whole or not at all: the image and the
 * scene cache's entries and memos.
 *
 * The file is written unnamed (O_TMPFILE) and given a name only once it is
 * complete (linkat to the final name, or, where a file has that name, to a
 * temporary one and renameat over it), so no signal, SIGKILL included,
 * leaves a partial file behind. Where the
 * file system has no O_TMPFILE, a named temporary file is written instead
 * and removed on failure or by rt_atomic_abandon() from a signal handler. */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "rt.h"

/* The named temporary file being written (fallback path), for
 * rt_atomic_abandon() in a signal handler: only a flag and unlinkat there. */
static char pending_name[300];
static int pending_dir = -1;
static volatile sig_atomic_t pending_set;

void rt_atomic_abandon(void)
{
    if (pending_set)
        unlinkat(pending_dir, pending_name, 0);
}

/* f->tmp, a name of the file not yet final, for rt_atomic_abandon(). */
static void set_pending(const RtAtomicFile *f)
{
    snprintf(pending_name, sizeof pending_name, "%s", f->tmp);
    pending_dir = f->dirfd;
    pending_set = 1;
}

/* A temporary name beside the final one: NAME.tmp.PID.RANDOM. */
static void tmp_name(char *out, size_t size, const char *base)
{
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    const unsigned r = (unsigned)(ts.tv_nsec ^ (ts.tv_sec << 20)) ^ (unsigned)rand();
    snprintf(out, size, "%.200s.tmp.%ld.%08x", base, (long)getpid(), r);
}

int rt_atomic_open(RtAtomicFile *f, int dirfd, const char *name, RtError *err)
{
    memset(f, 0, sizeof *f);
    f->fd = -1;
    const char *slash = strrchr(name, '/');
    if (slash) { /* a path: its folder becomes the directory written into */
        char dir[4096];
        snprintf(dir, sizeof dir, "%.*s", slash == name ? 1 : (int)(slash - name), name);
        f->dirfd = openat(dirfd, dir, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
        if (f->dirfd < 0)
            return rt_fail(err, "%s: cannot open the folder: %s", name, strerror(errno));
        f->own_dir = 1;
        name = slash + 1;
    } else {
        f->dirfd = dirfd;
    }
    if (strlen(name) >= sizeof f->base || !*name) {
        rt_atomic_abort(f);
        return rt_fail(err, "%s: file name too long or empty", name);
    }
    snprintf(f->base, sizeof f->base, "%s", name);
    f->fd = openat(f->dirfd, ".", O_TMPFILE | O_WRONLY | O_CLOEXEC, 0666);
    if (f->fd >= 0)
        return 0;
    /* no O_TMPFILE here (EOPNOTSUPP, EISDIR, EINVAL): a named file */
    for (int tries = 0; tries < 16 && f->fd < 0; tries++) {
        tmp_name(f->tmp, sizeof f->tmp, f->base);
        f->fd = openat(f->dirfd, f->tmp, O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0666);
        if (f->fd < 0 && errno != EEXIST)
            break;
    }
    if (f->fd < 0) {
        const int e = errno;
        rt_atomic_abort(f);
        return rt_fail(err, "%s: cannot create: %s", name, strerror(e));
    }
    set_pending(f);
    return 0;
}

/* The unnamed file f->fd given the name `name` in its folder. */
static int link_unnamed(const RtAtomicFile *f, const char *name)
{
    char proc[64];
    snprintf(proc, sizeof proc, "/proc/self/fd/%d", f->fd);
    int rc = linkat(AT_FDCWD, proc, f->dirfd, name, AT_SYMLINK_FOLLOW);
    if (rc != 0 && errno == ENOENT) /* (no /proc: needs CAP_DAC_READ_SEARCH) */
        rc = linkat(f->fd, "", f->dirfd, name, AT_EMPTY_PATH);
    return rc;
}

int rt_atomic_commit(RtAtomicFile *f, RtError *err)
{
    int rc = 0, e = 0, named = 0;
    if (!f->tmp[0]) {
        /* unnamed: where nothing has the name yet, the whole file takes it
         * at once; else a temporary name, then renamed over the old file
         * (a SIGKILL between the two leaves the temporary name; SIGTERM's
         * handler removes it) */
        named = link_unnamed(f, f->base) == 0;
        for (int tries = 0; !named && tries < 16; tries++) {
            tmp_name(f->tmp, sizeof f->tmp, f->base);
            rc = link_unnamed(f, f->tmp);
            if (rc == 0 || errno != EEXIST)
                break;
        }
        if (rc != 0) {
            e = errno;
            f->tmp[0] = '\0';
        } else if (!named) {
            set_pending(f);
        }
    }
    if (close(f->fd) != 0 && rc == 0)
        rc = -1, e = errno;
    f->fd = -1;
    if (rc == 0 && !named && renameat(f->dirfd, f->tmp, f->dirfd, f->base) != 0)
        rc = -1, e = errno;
    if (rc != 0) {
        char base[sizeof f->base];
        memcpy(base, f->base, sizeof base);
        rt_atomic_abort(f);
        return rt_fail(err, "%s: cannot write: %s", base, strerror(e));
    }
    pending_set = 0;
    if (f->own_dir)
        close(f->dirfd);
    f->own_dir = 0;
    f->fd = -1;
    return 0;
}

void rt_atomic_abort(RtAtomicFile *f)
{
    if (f->fd >= 0)
        close(f->fd);
    if (f->tmp[0])
        unlinkat(f->dirfd, f->tmp, 0);
    pending_set = 0;
    if (f->own_dir)
        close(f->dirfd);
    memset(f, 0, sizeof *f);
    f->fd = -1;
}
