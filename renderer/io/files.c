/* files.c - input files read once and whole, and the record of every file
 * a scene was made of (the scene cache keys them, MPI ranks agree on them). */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "rt.h"

/* Pieces a large file is read in, side by side: the page cache copies at a
 * few GB/s per core, so a file of hundreds of MB takes one core's time
 * divided by the cores. */
#define RT_READ_PIECE (8u << 20)

/* Whether a file's bytes may have changed between two states: any write
 * or truncation moves its size or mtime. (Not its ctime: that also moves
 * when the file is renamed away or replaced under its name, as an editor
 * saves, while the bytes being read stay the same.) */
static int same_file_state(const struct stat *a, const struct stat *b)
{
    return a->st_dev == b->st_dev && a->st_ino == b->st_ino && a->st_size == b->st_size &&
           a->st_mtim.tv_sec == b->st_mtim.tv_sec && a->st_mtim.tv_nsec == b->st_mtim.tv_nsec;
}

/* Reads [off, off+n) of fd into buf; 0 when all n bytes came. */
static int read_at(int fd, char *buf, size_t n, off_t off)
{
    while (n > 0) {
        const ssize_t r = pread(fd, buf, n, off);
        if (r < 0 && errno == EINTR)
            continue;
        if (r <= 0)
            return -1;
        buf += r, n -= (size_t)r, off += r;
    }
    return 0;
}

int rt_read_fd(int fd, char *buf, size_t n)
{
    const long pieces = (long)((n + RT_READ_PIECE - 1) / RT_READ_PIECE);
    int bad = 0;
#pragma omp parallel for schedule(dynamic, 1) reduction(| : bad) if (pieces > 2) num_threads(rt_stream_threads())
    for (long i = 0; i < pieces; i++) {
        const size_t a = (size_t)i * RT_READ_PIECE, b = a + RT_READ_PIECE < n ? a + RT_READ_PIECE : n;
        bad |= read_at(fd, buf + a, b - a, (off_t)a) != 0;
    }
    return bad ? -1 : 0;
}

int rt_read_file(const char *path, size_t max, char **data, size_t *len, RtError *err)
{
    struct stat st;
    return rt_read_file_stat(path, max, data, len, &st, err);
}

int rt_read_file_stat(const char *path, size_t max, char **data, size_t *len, struct stat *stp, RtError *err)
{
    struct stat st, after;
    const int fd = rt_open_regular(path, &st, err);
    if (fd < 0)
        return -1;
    if (st.st_size < 0 || (unsigned long long)st.st_size > max) {
        close(fd);
        return rt_fail(err, "%s: file of %lld bytes is larger than the %llu-byte limit", path, (long long)st.st_size,
                       (unsigned long long)max);
    }
    const size_t n = (size_t)st.st_size;
    char *buf = malloc(n + 1);
    if (!buf) {
        close(fd);
        return rt_fail(err, "%s: out of memory for %zu bytes", path, n);
    }
    if (n >= (size_t)16 << 20) /* (a 350 MB scene: 170 faults instead of 86,000, as the cache's entries) */
        rt_huge_hint(buf, n);
    const int bad = rt_read_fd(fd, buf, n) != 0;
    /* one byte more must not exist: a file that grew is a file that changed */
    char extra;
    const int grew = !bad && pread(fd, &extra, 1, (off_t)n) > 0;
    const int changed = bad || grew || fstat(fd, &after) != 0 || !same_file_state(&st, &after);
    close(fd);
    if (changed) {
        free(buf);
        return rt_fail(err, "%s: changed while it was read (written or truncated meanwhile); run again", path);
    }
    buf[n] = '\0';
    *data = buf;
    *len = n;
    *stp = st;
    return 0;
}

int rt_scene_add_dep(RtScene *s, const char *path, const void *bytes, size_t len, RtError *err)
{
    for (uint32_t i = 0; i < s->source.ndeps; i++) /* a file read twice is one dependency, if its bytes were the same */
        if (strcmp(s->source.deps[i].path, path) == 0) {
            uint8_t h[16];
            rt_content_hash(bytes, len, h);
            if (memcmp(h, s->source.deps[i].hash, 16) != 0)
                return rt_fail(err, "%s: changed while the scene was read; run again", path);
            return 0;
        }
    RtDep *nd = realloc(s->source.deps, (s->source.ndeps + 1) * sizeof *nd);
    if (!nd)
        return rt_fail(err, "%s: out of memory", path);
    s->source.deps = nd;
    RtDep *d = &s->source.deps[s->source.ndeps];
    if (!(d->path = strdup(path)))
        return rt_fail(err, "%s: out of memory", path);
    rt_content_hash(bytes, len, d->hash);
    s->source.ndeps++;
    return 0;
}

void rt_scene_digest(const RtScene *s, uint8_t out[16])
{
    size_t n = 16;
    for (uint32_t i = 0; i < s->source.ndeps; i++)
        n += strlen(s->source.deps[i].path) + 1 + 16;
    uint8_t *buf = malloc(n);
    if (!buf) { /* (the scene file alone: still a digest every rank computes alike) */
        memcpy(out, s->source.file_hash, 16);
        return;
    }
    size_t at = 0;
    memcpy(buf, s->source.file_hash, 16), at += 16;
    for (uint32_t i = 0; i < s->source.ndeps; i++) {
        const size_t l = strlen(s->source.deps[i].path) + 1;
        memcpy(buf + at, s->source.deps[i].path, l), at += l;
        memcpy(buf + at, s->source.deps[i].hash, 16), at += 16;
    }
    rt_content_hash(buf, at, out);
    free(buf);
}

/* The packed list: per dependency its hash (16 bytes), its path's length
 * (4 bytes, little-endian on every host this runs on) and the path. */
int rt_scene_deps_pack(const RtScene *s, char **blob, size_t *len)
{
    size_t n = 0;
    for (uint32_t i = 0; i < s->source.ndeps; i++)
        n += 20 + strlen(s->source.deps[i].path);
    char *b = malloc(n ? n : 1);
    if (!b)
        return -1;
    size_t at = 0;
    for (uint32_t i = 0; i < s->source.ndeps; i++) {
        const uint32_t l = (uint32_t)strlen(s->source.deps[i].path);
        memcpy(b + at, s->source.deps[i].hash, 16);
        memcpy(b + at + 16, &l, 4);
        memcpy(b + at + 20, s->source.deps[i].path, l);
        at += 20 + l;
    }
    *blob = b;
    *len = n;
    return 0;
}

int rt_scene_deps_unpack(RtScene *s, const char *blob, size_t len, RtError *err)
{
    s->source.deps = NULL;
    s->source.ndeps = 0;
    size_t at = 0;
    while (at < len) {
        uint32_t l;
        if (len - at < 20 || (memcpy(&l, blob + at + 16, 4), l == 0) || l >= 4096 || l > len - at - 20 ||
            memchr(blob + at + 20, '\0', l))
            return rt_fail(err, "the list of files the scene read is damaged");
        RtDep *nd = realloc(s->source.deps, (s->source.ndeps + 1) * sizeof *nd);
        char *path = malloc(l + 1);
        if (nd)
            s->source.deps = nd;
        if (!nd || !path) {
            free(path);
            return rt_fail(err, "out of memory");
        }
        memcpy(path, blob + at + 20, l);
        path[l] = '\0';
        s->source.deps[s->source.ndeps].path = path;
        memcpy(s->source.deps[s->source.ndeps].hash, blob + at, 16);
        s->source.ndeps++;
        at += 20 + l;
    }
    return 0;
}

void rt_scene_free_deps(RtScene *s)
{
    for (uint32_t i = 0; i < s->source.ndeps; i++)
        free(s->source.deps[i].path);
    free(s->source.deps);
    s->source.deps = NULL;
    s->source.ndeps = 0;
}
