/* scene_cache.c - the parsed scene and its acceleration structure in one
 * binary file, read by a later run instead of parsing and building again
 * (docs/scene-format.md, "Scene cache").
 *
 * An entry is DIR/KEY.rbc. KEY is a 128-bit XXH3 hash of the scene file's
 * bytes as parsed, the accelerator kind, the format version, the model
 * loader's version and the running program's own bytes. Every other file
 * the scene read (models and what they reference) is listed in the entry
 * with the hash of the bytes read, and a load misses unless each still
 * hashes the same (ccache's manifest idea). The file is a header (counts,
 * array offsets, the hash of the payload, the scene file's hash and the
 * settings' line numbers), the render settings (RtSceneSettings) and the
 * arrays, each at a 64-byte offset; none of the scene's source (RtSceneSource:
 * names, pointers) is stored as bytes, the loader fills it. The payload hash finds damage, not tampering:
 * every index the renderer follows and the trees' shape are checked as for
 * --verify before an entry is used, and one that fails is removed and built
 * again. The folder must be the user's own and closed to others (as ssh
 * treats ~/.ssh); names in it are never followed out of it. Entries and
 * memos appear whole or not at all (io/atomic.c). */
#define _GNU_SOURCE
#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "config.h"
#include "rt.h"

#if HAVE_XXHASH
#define XXH_INLINE_ALL /* the header alone: no library to link */
#include <xxhash.h>
#if HAVE_ASSIMP
#include <assimp/version.h>
#endif

#define RT_CACHE_MAGIC "RBCACHE1"
#define RT_CACHE_FORMAT 4u /* (3: the dependency list; 4: the settings alone, not the scene struct) */
#define RT_CACHE_ALIGN 64u
/* Pieces of 4 MB: a few hundred MB of arrays hash on every core (64 MB
 * pieces left all but three threads idle on the 3.6M-triangle scene). */
#define RT_HASH_CHUNK (4u << 20)

/* Entries larger than this are not read (a 3.6M-triangle scene's is about
 * 0.6 GB). */
#define RT_CACHE_MAX_ENTRY (1ull << 36)

/* The entry's arrays: the scene's (in RT_SCENE_ARRAYS order), the
 * accelerator's and the packed dependency list. */
#define ARRAY_INDEX(T, name) A_##name,
enum { RT_SCENE_ARRAYS(ARRAY_INDEX) A_PRIMS, A_NODES, A_WIDE, A_DEPS, A_COUNT };
#undef ARRAY_INDEX
#define ARRAY_ELEM(T, name) sizeof(T),
static const size_t elem[A_COUNT] = {RT_SCENE_ARRAYS(ARRAY_ELEM) sizeof(RtPrim), sizeof(RtBvhNode),
                                     sizeof(RtBvh4Node), 1};
#undef ARRAY_ELEM

typedef struct CacheHeader {
    char magic[8];
    uint32_t format, header_size, settings_size; /* sizeof checks: another layout never loads */
    uint32_t counts[A_COUNT];
    uint64_t offset[A_COUNT];
    uint64_t file_size, payload_hash;
    uint8_t file_hash[16]; /* the scene's: the bytes it was parsed from */
    /* the lines that set the settings (line_fwd, line_up, line_fov,
     * line_res, line_depth, line_output), for messages after a load */
    int32_t lines[6];
    /* the accelerator's scalars */
    int32_t kind;
    uint32_t nsplit, depth, leaves;
    double sah_cost;
} CacheHeader;

/* XXH3-128 of piece i (RT_HASH_CHUNK bytes, the last one shorter) of a buffer. */
static XXH128_hash_t hash_piece(const void *data, size_t len, size_t i)
{
    const size_t a = i * RT_HASH_CHUNK, b = a + RT_HASH_CHUNK < len ? a + RT_HASH_CHUNK : len;
    return XXH3_128bits((const char *)data + a, b - a);
}

/* XXH3-128 of a buffer, over RT_HASH_CHUNK pieces in parallel, then of the
 * pieces' hashes: the same value on any number of threads. */
/* (GCC 12 mistakes XXH3's streaming state buffer for an overflow) */
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Warray-bounds"
#pragma GCC diagnostic ignored "-Wstringop-overread"
static XXH128_hash_t hash_big(const void *data, size_t len)
{
    const size_t n = len / RT_HASH_CHUNK + 1;
    XXH128_hash_t *part = malloc(n * sizeof *part);
    if (!part) { /* the same value, one piece at a time */
        XXH3_state_t st;
        XXH3_128bits_reset(&st);
        for (size_t i = 0; i < n; i++) {
            const XXH128_hash_t h = hash_piece(data, len, i);
            XXH3_128bits_update(&st, &h, sizeof h);
        }
        return XXH3_128bits_digest(&st);
    }
#pragma omp parallel for schedule(dynamic, 1) num_threads(rt_stream_threads())
    for (size_t i = 0; i < n; i++)
        part[i] = hash_piece(data, len, i);
    XXH128_hash_t h = XXH3_128bits(part, n * sizeof *part);
    free(part);
    return h;
}
#pragma GCC diagnostic pop

void rt_content_hash(const void *bytes, size_t len, uint8_t out[16])
{
    const XXH128_hash_t h = hash_big(bytes, len);
    memcpy(out, &h.high64, 8);
    memcpy(out + 8, &h.low64, 8);
}

/* ---- the folder ------------------------------------------------------------ */

/* The cache folder, opened once: every name in it is reached through fd
 * (openat, never a path that a link could redirect). */
typedef struct CacheDir {
    int fd, statfd; /* statfd: DIR/stat, -1 until needed */
    const char *path;
} CacheDir;

/* A folder the user alone can change: owned by the user, not writable by
 * group or others (ssh's rule for ~/.ssh). */
static int dir_trusted(int fd, const char *path, RtError *err)
{
    struct stat st;
    if (fstat(fd, &st) != 0)
        return rt_fail(err, "scene cache: %s: %s", path, strerror(errno));
    if (st.st_uid != geteuid())
        return rt_fail(err, "scene cache: %s belongs to user %u, not to you: refused (another user could plant "
                            "entries there); use a folder of your own", path, (unsigned)st.st_uid);
    if (st.st_mode & (S_IWGRP | S_IWOTH))
        return rt_fail(err, "scene cache: %s is writable by %s (mode %04o): refused; chmod go-w %s", path,
                       st.st_mode & S_IWOTH ? "others" : "its group", (unsigned)(st.st_mode & 07777), path);
    return 0;
}

/* Opens a folder (in `at`, never through a link), made 0700 first if
 * `create`. 1: open; 0: it does not exist (and create was 0); -1: refused. */
static int open_dir(int at, const char *name, const char *shown, int create, int *fd, RtError *err)
{
    struct stat lst; /* (O_NOFOLLOW on a link to a folder says ENOTDIR, not ELOOP) */
    if (fstatat(at, name, &lst, AT_SYMLINK_NOFOLLOW) == 0 && S_ISLNK(lst.st_mode))
        return rt_fail(err, "scene cache: %s is a symbolic link: refused (name the folder itself)", shown);
    if (create && mkdirat(at, name, 0700) != 0 && errno != EEXIST)
        return rt_fail(err, "scene cache: cannot create %s: %s", shown, strerror(errno));
    *fd = openat(at, name, O_RDONLY | O_DIRECTORY | O_NOFOLLOW | O_CLOEXEC);
    if (*fd < 0) {
        if (errno == ELOOP)
            return rt_fail(err, "scene cache: %s is a symbolic link: refused (name the folder itself)", shown);
        if ((errno == ENOENT || errno == ENOTDIR) && !create)
            return 0; /* (a miss; storing says why) */
        return rt_fail(err, "scene cache: cannot use %s: %s", shown, errno == ENOTDIR ? "not a folder" : strerror(errno));
    }
    if (dir_trusted(*fd, shown, err) != 0) {
        close(*fd);
        *fd = -1;
        return -1;
    }
    return 1;
}

static int cache_open(CacheDir *cd, const char *path, int create, RtError *err)
{
    cd->fd = cd->statfd = -1;
    cd->path = path;
    return open_dir(AT_FDCWD, path, path, create, &cd->fd, err);
}

static void cache_close(CacheDir *cd)
{
    if (cd->statfd >= 0)
        close(cd->statfd);
    if (cd->fd >= 0)
        close(cd->fd);
    cd->fd = cd->statfd = -1;
}

/* DIR/stat, opened (and made) on first use; -1 when it cannot be used. */
static int stat_dir(CacheDir *cd, int create)
{
    if (cd->statfd < 0 && cd->fd >= 0) {
        char shown[4200];
        snprintf(shown, sizeof shown, "%s/stat", cd->path);
        RtError ignored; /* (a memo is only ever a shortcut) */
        if (open_dir(cd->fd, "stat", shown, create, &cd->statfd, &ignored) != 1)
            cd->statfd = -1;
    }
    return cd->statfd;
}

/* Reads a whole regular file in folder fd (never through a link) into an
 * anonymous mapping (rt_scene_free unmaps it): read, not mapped from the
 * file, so a file truncated underneath is a miss, not a SIGBUS. 0 or -1. */
static int read_entry(int fd_dir, const char *name, void **out, size_t *len)
{
    const int fd = openat(fd_dir, name, O_RDONLY | O_NOFOLLOW | O_NONBLOCK | O_CLOEXEC);
    struct stat st, after;
    if (fd < 0)
        return -1;
    if (fstat(fd, &st) != 0 || !S_ISREG(st.st_mode) || st.st_size <= 0 ||
        (unsigned long long)st.st_size > RT_CACHE_MAX_ENTRY) {
        close(fd);
        return -1;
    }
    const size_t n = (size_t)st.st_size;
    char *m = mmap(NULL, n, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (m == MAP_FAILED) {
        close(fd);
        return -1;
    }
#ifdef MADV_HUGEPAGE
    madvise(m, n, MADV_HUGEPAGE); /* (a 0.5 GB entry: 240 faults instead of 120,000) */
#endif
    const int bad = rt_read_fd(fd, m, n) != 0 || fstat(fd, &after) != 0 || after.st_size != st.st_size;
    close(fd);
    if (bad) {
        munmap(m, n);
        return -1;
    }
    *out = m;
    *len = n;
    return 0;
}

/* ---- file hashes and their memos ------------------------------------------- */

/* A file's content hash remembered against its identity and times, as
 * git's index remembers a file's blob (DIR/stat/DEV-INO.memo): a later key
 * for the same unchanged file reads 120 bytes instead of hashing the file.
 * Any write to a file moves its ctime, which no user can set back, so a
 * memo whose size, mtime and ctime all match is the file's hash. The one
 * hole, a write within the same clock tick as the hashed state, is closed
 * as git closes it: a file changed less than RT_MEMO_SETTLE_S before its
 * hash was finished gets no memo. */
#define RT_MEMO_MAGIC "RBSTAT02" /* (hash_big's pieces are part of the value) */
#define RT_MEMO_SETTLE_S 2
typedef struct FileMemo {
    char magic[8];
    uint64_t dev, ino, size, mtime_s, mtime_ns, ctime_s, ctime_ns;
    XXH128_hash_t hash;
    uint64_t check; /* XXH3-64 of everything above */
} FileMemo;

static void memo_of(const struct stat *st, FileMemo *m)
{
    memset(m, 0, sizeof *m);
    memcpy(m->magic, RT_MEMO_MAGIC, 8);
    m->dev = (uint64_t)st->st_dev, m->ino = (uint64_t)st->st_ino, m->size = (uint64_t)st->st_size;
    m->mtime_s = (uint64_t)st->st_mtim.tv_sec, m->mtime_ns = (uint64_t)st->st_mtim.tv_nsec;
    m->ctime_s = (uint64_t)st->st_ctim.tv_sec, m->ctime_ns = (uint64_t)st->st_ctim.tv_nsec;
}

static void memo_name(char *out, size_t size, const struct stat *st)
{
    snprintf(out, size, "%llx-%llx.memo", (unsigned long long)st->st_dev, (unsigned long long)st->st_ino);
}

/* The remembered hash of the file st describes, if its memo matches. */
static int memo_read(CacheDir *cd, const struct stat *st, XXH128_hash_t *out)
{
    if (stat_dir(cd, 0) < 0)
        return 0;
    char name[64];
    memo_name(name, sizeof name, st);
    FileMemo want, m;
    memo_of(st, &want);
    const int fd = openat(cd->statfd, name, O_RDONLY | O_NOFOLLOW | O_NONBLOCK | O_CLOEXEC);
    if (fd < 0)
        return 0;
    char extra;
    const int got = read(fd, &m, sizeof m) == (ssize_t)sizeof m && read(fd, &extra, 1) == 0;
    close(fd);
    if (!got || m.check != XXH3_64bits(&m, offsetof(FileMemo, check)) ||
        memcmp(&m, &want, offsetof(FileMemo, hash)) != 0)
        return 0;
    *out = m.hash;
    return 1;
}

/* Remembers hash h for the file that was st while its bytes were read
 * (any failure only forgoes the memo). */
static void memo_write(CacheDir *cd, const struct stat *st, XXH128_hash_t h)
{
    struct timespec now;
    clock_gettime(CLOCK_REALTIME, &now);
    const time_t changed = st->st_mtim.tv_sec > st->st_ctim.tv_sec ? st->st_mtim.tv_sec : st->st_ctim.tv_sec;
    if (now.tv_sec - changed < RT_MEMO_SETTLE_S || stat_dir(cd, 1) < 0)
        return;
    char name[64];
    memo_name(name, sizeof name, st);
    FileMemo m;
    memo_of(st, &m);
    m.hash = h;
    m.check = XXH3_64bits(&m, offsetof(FileMemo, check));
    RtAtomicFile f;
    RtError ignored;
    if (rt_atomic_open(&f, cd->statfd, name, &ignored) != 0)
        return;
    if (write(f.fd, &m, sizeof m) == (ssize_t)sizeof m)
        rt_atomic_commit(&f, &ignored);
    else
        rt_atomic_abort(&f);
}

/* The hash of a regular file's bytes: remembered (the memo) or read once
 * and hashed. A file over RT_MAX_FILE is refused before a byte is read. */
static int file_hash(CacheDir *cd, const char *path, XXH128_hash_t *out, RtError *err)
{
    struct stat st;
    if (stat(path, &st) != 0)
        return rt_fail(err, "%s: cannot open: %s", path, strerror(errno));
    if (!S_ISREG(st.st_mode))
        return rt_fail(err, "%s: not a regular file", path);
    if ((unsigned long long)st.st_size > RT_MAX_FILE)
        return rt_fail(err, "%s: file of %lld bytes is larger than the %llu-byte limit", path, (long long)st.st_size,
                       (unsigned long long)RT_MAX_FILE);
    if (memo_read(cd, &st, out))
        return 0;
    char *data;
    size_t len;
    if (rt_read_file_stat(path, RT_MAX_FILE, &data, &len, &st, err) != 0)
        return -1;
    *out = hash_big(data, len);
    free(data);
    memo_write(cd, &st, *out);
    return 0;
}

/* ---- keys -------------------------------------------------------------------- */

static void hash_bytes(XXH128_hash_t h, uint8_t out[16])
{
    memcpy(out, &h.high64, 8);
    memcpy(out + 8, &h.low64, 8);
}

/* The key of a scene whose file hashed to file_hash: with the accelerator,
 * the format, the model loader's version and the program itself (a
 * rebuild with other code misses). */
static void cache_key(CacheDir *cd, const uint8_t file[16], RtAccelKind kind, char *hex)
{
    XXH128_hash_t prog;
    RtError ignored;
    if (file_hash(cd, "/proc/self/exe", &prog, &ignored) != 0)
        prog = XXH3_128bits(RT_BUILD_FLAGS, sizeof RT_BUILD_FLAGS);
    struct {
        uint8_t file[16];
        XXH128_hash_t prog;
        uint32_t kind, format, loader[3];
    } k;
    memset(&k, 0, sizeof k);
    memcpy(k.file, file, 16);
    k.prog = prog;
    k.kind = (uint32_t)kind;
    k.format = RT_CACHE_FORMAT;
#if HAVE_ASSIMP
    k.loader[0] = aiGetVersionMajor(), k.loader[1] = aiGetVersionMinor(), k.loader[2] = aiGetVersionRevision();
#endif
    const XXH128_hash_t h = XXH3_128bits(&k, sizeof k);
    snprintf(hex, 33, "%016llx%016llx", (unsigned long long)h.high64, (unsigned long long)h.low64);
}

/* ---- entries ---------------------------------------------------------------- */

/* The arrays of a scene and its accelerator, with their sizes in bytes
 * (the dependency list packed by the caller). */
static void arrays(const RtScene *s, const RtAccel *a, const char *deps, size_t ndeps, const void **p,
                   uint64_t *bytes, uint32_t *count)
{
#define ARRAY_PTR(T, name) s->name,
#define ARRAY_COUNT(T, name) s->n##name,
    const void *ptr[A_COUNT] = {RT_SCENE_ARRAYS(ARRAY_PTR) a->prims, a->nodes, a->wide, deps};
    const uint32_t n[A_COUNT] = {RT_SCENE_ARRAYS(ARRAY_COUNT) a->nprims, a->nnodes, a->wide ? a->nwide : 0,
                                 (uint32_t)ndeps};
#undef ARRAY_PTR
#undef ARRAY_COUNT
    for (int i = 0; i < A_COUNT; i++) {
        p[i] = ptr[i];
        count[i] = n[i];
        bytes[i] = (uint64_t)n[i] * elem[i];
    }
}

/* The entry's hash: of the header (its own hash field zeroed), the
 * settings and every array. */
static uint64_t payload_hash(const CacheHeader *hdr, const void *settings, const void **p, const uint64_t *bytes)
{
    CacheHeader h0 = *hdr;
    h0.payload_hash = 0;
    XXH128_hash_t h[2 + A_COUNT];
    h[0] = XXH3_128bits(&h0, sizeof h0);
    h[1] = XXH3_128bits(settings, sizeof(RtSceneSettings));
    for (int i = 0; i < A_COUNT; i++)
        h[2 + i] = hash_big(p[i], (size_t)bytes[i]);
    return XXH3_64bits(h, sizeof h);
}

/* Everything a header must satisfy before its offsets are followed. */
static int header_ok(const CacheHeader *h, size_t len)
{
    const size_t head = sizeof *h + sizeof(RtSceneSettings);
    if (len < head || memcmp(h->magic, RT_CACHE_MAGIC, 8) != 0 || h->format != RT_CACHE_FORMAT ||
        h->header_size != sizeof *h || h->settings_size != sizeof(RtSceneSettings) || h->file_size != len)
        return 0;
    for (int i = 0; i < A_COUNT; i++)
        if (h->offset[i] % RT_CACHE_ALIGN || h->offset[i] < head || h->offset[i] > len ||
            (uint64_t)h->counts[i] * elem[i] > len - h->offset[i])
            return 0;
    return 1;
}

/* The lines that set the settings, into an entry's header and back. */
static void lines_store(int32_t *l, const RtScene *s)
{
    l[0] = s->source.line_fwd, l[1] = s->source.line_up, l[2] = s->source.line_fov;
    l[3] = s->source.line_res, l[4] = s->source.line_depth, l[5] = s->source.line_output;
}

static void lines_load(RtScene *s, const int32_t *l)
{
    s->source.line_fwd = l[0], s->source.line_up = l[1], s->source.line_fov = l[2];
    s->source.line_res = l[3], s->source.line_depth = l[4], s->source.line_output = l[5];
}

/* The scene and accelerator an entry's bytes hold, pointing into m; of
 * the source only the file's hash and the lines (the loader names it). */
static void entry_views(char *m, RtScene *scene, RtAccel *accel)
{
    const CacheHeader *h = (const CacheHeader *)m;
    memset(scene, 0, sizeof *scene);
    memcpy(&scene->settings, m + sizeof *h, sizeof scene->settings);
    scene->settings.output[sizeof scene->settings.output - 1] = '\0';
#define ARRAY_VIEW(T, name) \
    scene->name = (T *)(m + h->offset[A_##name]), scene->n##name = scene->cap_##name = h->counts[A_##name];
    RT_SCENE_ARRAYS(ARRAY_VIEW)
#undef ARRAY_VIEW
    memcpy(scene->source.file_hash, h->file_hash, 16);
    lines_load(scene, h->lines);
    memset(accel, 0, sizeof *accel);
    accel->kind = (RtAccelKind)h->kind;
    accel->prims = (RtPrim *)(m + h->offset[A_PRIMS]);
    accel->nprims = h->counts[A_PRIMS];
    accel->nodes = h->counts[A_NODES] ? (RtBvhNode *)(m + h->offset[A_NODES]) : NULL;
    accel->nnodes = h->counts[A_NODES];
    accel->wide = h->counts[A_WIDE] ? (RtBvh4Node *)(m + h->offset[A_WIDE]) : NULL;
    accel->nwide = h->counts[A_WIDE];
    accel->nsplit = h->nsplit;
    accel->depth = h->depth;
    accel->leaves = h->leaves;
    accel->sah_cost = h->sah_cost;
    accel->mapped = 1;
}

int rt_cache_entry_parse(void *bytes, size_t len, RtAccelKind kind, RtScene *scene, RtAccel *accel, RtError *err)
{
    char *m = bytes;
    const CacheHeader *h = (const CacheHeader *)m;
    if (!header_ok(h, len) || h->kind != (int32_t)kind)
        return rt_fail(err, "not an entry of this format and accelerator");
    const void *p[A_COUNT];
    uint64_t bytes_of[A_COUNT];
    for (int i = 0; i < A_COUNT; i++) {
        p[i] = m + h->offset[i];
        bytes_of[i] = (uint64_t)h->counts[i] * elem[i];
    }
    if (payload_hash(h, m + sizeof *h, p, bytes_of) != h->payload_hash)
        return rt_fail(err, "damaged (its hash does not match)");
    entry_views(m, scene, accel);
    /* The hash finds damage, not tampering: everything the renderer follows
     * is checked as --verify checks a fresh build. */
    if (accel->kind == RT_ACCEL_BVH && accel->nprims && (!accel->wide || !accel->nwide))
        return rt_fail(err, "a BVH without its 4-wide copy");
    if (rt_scene_check(scene, accel, err) != 0 || rt_bvh_check(accel, err) != 0 ||
        rt_scene_deps_unpack(scene, p[A_DEPS], (size_t)bytes_of[A_DEPS], err) != 0) {
        rt_scene_free_deps(scene);
        return -1;
    }
    return 0;
}

void rt_cache_entry_seal(void *bytes, size_t len)
{
    CacheHeader *h = bytes;
    if (!header_ok(h, len))
        return;
    const void *p[A_COUNT];
    uint64_t bytes_of[A_COUNT];
    for (int i = 0; i < A_COUNT; i++) {
        p[i] = (char *)bytes + h->offset[i];
        bytes_of[i] = (uint64_t)h->counts[i] * elem[i];
    }
    h->payload_hash = payload_hash(h, (char *)bytes + sizeof *h, p, bytes_of);
}

/* Whether every file the entry's scene read still hashes as it did. */
static int deps_current(CacheDir *cd, const RtScene *s)
{
    for (uint32_t i = 0; i < s->source.ndeps; i++) {
        XXH128_hash_t h;
        uint8_t now[16];
        RtError ignored;
        if (file_hash(cd, s->source.deps[i].path, &h, &ignored) != 0)
            return 0;
        hash_bytes(h, now);
        if (memcmp(now, s->source.deps[i].hash, 16) != 0)
            return 0;
    }
    return 1;
}

/* ---- load and store ----------------------------------------------------------- */

int rt_cache_load(const char *dir, const char *scene_path, RtAccelKind kind, RtScene *scene, RtAccel *accel,
                  char *key, RtError *err)
{
    CacheDir cd;
    err->msg[0] = '\0';
    const int open = cache_open(&cd, dir, 0, err);
    if (open <= 0)
        return open; /* absent: a miss; refused: the caller's error */
    XXH128_hash_t fh;
    uint8_t file[16];
    RtError ignored;
    if (file_hash(&cd, scene_path, &fh, &ignored) != 0) { /* (the parse says why) */
        cache_close(&cd);
        return 0;
    }
    hash_bytes(fh, file);
    cache_key(&cd, file, kind, key);
    char name[64];
    snprintf(name, sizeof name, "%s.rbc", key);
    void *m = NULL;
    size_t len = 0;
    if (read_entry(cd.fd, name, &m, &len) != 0) {
        cache_close(&cd);
        return 0;
    }
    RtError why;
    int rc = rt_cache_entry_parse(m, len, kind, scene, accel, &why);
    if (rc == 0 && memcmp(scene->source.file_hash, file, 16) != 0)
        rc = rt_fail(&why, "made from other bytes than its key says");
    if (rc != 0) { /* never trusted: removed, built again */
        unlinkat(cd.fd, name, 0);
        rt_fail(err, "scene cache: entry %s/%s refused (%s); building it again", dir, name, why.msg);
    } else if (!deps_current(&cd, scene)) {
        rt_scene_free_deps(scene);
        rc = -1; /* a model file changed: built again, stored over it */
    }
    cache_close(&cd);
    if (rc != 0) {
        munmap(m, len);
        memset(scene, 0, sizeof *scene);
        memset(accel, 0, sizeof *accel);
        return 0;
    }
    rt_scene_name(scene, scene_path); /* (the rest of the source: entry_views) */
    if (rt_model_supported(scene_path)) /* raytrace MODEL: the image is named after this file */
        snprintf(scene->settings.output, sizeof scene->settings.output, "%s.png", scene->source.name);
    scene->source.cache_map = m;
    scene->source.cache_len = len;
    return 1;
}

/* Writes the header, the settings and the arrays to f. */
static int write_all(FILE *f, CacheHeader *h, const RtSceneSettings *settings, const void **p, const uint64_t *bytes)
{
    static const char zero[RT_CACHE_ALIGN] = {0};
    int ok = fwrite(h, sizeof *h, 1, f) == 1 && fwrite(settings, sizeof *settings, 1, f) == 1;
    uint64_t at = sizeof *h + sizeof *settings;
    for (int i = 0; i < A_COUNT && ok; i++) {
        ok = fwrite(zero, 1, h->offset[i] - at, f) == h->offset[i] - at &&
             (bytes[i] == 0 || fwrite(p[i], 1, bytes[i], f) == bytes[i]);
        at = h->offset[i] + bytes[i];
    }
    return ok;
}

/* Removes named temporary files that a killed writer left (only where the
 * file system has no O_TMPFILE; io/atomic.c) once they are an hour old. */
static void sweep_stale(int fd)
{
    const int fd2 = dup(fd);
    DIR *d = fd2 >= 0 ? fdopendir(fd2) : NULL;
    if (!d) {
        if (fd2 >= 0)
            close(fd2);
        return;
    }
    const time_t now = time(NULL);
    for (struct dirent *e; (e = readdir(d));) {
        struct stat st;
        if (strstr(e->d_name, ".rbc.tmp.") && fstatat(fd, e->d_name, &st, AT_SYMLINK_NOFOLLOW) == 0 &&
            S_ISREG(st.st_mode) && now - st.st_mtime > 3600)
            unlinkat(fd, e->d_name, 0);
    }
    closedir(d);
}

/* The header of an entry for scene and accel, with its offsets. */
static void make_header(CacheHeader *h, const RtScene *scene, const RtAccel *accel, const void **p,
                        uint64_t *bytes, const char *deps, size_t ndeps)
{
    const RtSceneSettings *settings = &scene->settings;
    memset(h, 0, sizeof *h);
    arrays(scene, accel, deps, ndeps, p, bytes, h->counts);
    memcpy(h->magic, RT_CACHE_MAGIC, 8);
    h->format = RT_CACHE_FORMAT;
    h->header_size = sizeof *h;
    h->settings_size = sizeof *settings;
    memcpy(h->file_hash, scene->source.file_hash, 16);
    lines_store(h->lines, scene);
    uint64_t at = sizeof *h + sizeof *settings;
    for (int i = 0; i < A_COUNT; i++) {
        at = (at + RT_CACHE_ALIGN - 1) / RT_CACHE_ALIGN * RT_CACHE_ALIGN;
        h->offset[i] = at;
        at += bytes[i];
    }
    h->file_size = at;
    h->kind = accel->kind;
    h->nsplit = accel->nsplit;
    h->depth = accel->depth;
    h->leaves = accel->leaves;
    h->sah_cost = accel->sah_cost;
    h->payload_hash = payload_hash(h, settings, p, bytes);
}

int rt_cache_store(const char *dir, const RtScene *scene, const RtAccel *accel, char *key, RtError *err)
{
    CacheDir cd;
    if (cache_open(&cd, dir, 1, err) != 1)
        return -1;
    /* the key of the bytes that were parsed, whatever the file holds now */
    cache_key(&cd, scene->source.file_hash, accel->kind, key);
    char *deps = NULL;
    size_t ndeps = 0;
    if (rt_scene_deps_pack(scene, &deps, &ndeps) != 0) {
        cache_close(&cd);
        return rt_fail(err, "scene cache: out of memory");
    }
    const void *p[A_COUNT];
    uint64_t bytes[A_COUNT];
    CacheHeader h;
    make_header(&h, scene, accel, p, bytes, deps, ndeps);
    char name[64];
    snprintf(name, sizeof name, "%s.rbc", key);
    RtAtomicFile af;
    int rc = rt_atomic_open(&af, cd.fd, name, err);
    if (rc == 0) {
        const int fd2 = dup(af.fd);
        FILE *f = fd2 >= 0 ? fdopen(fd2, "wb") : NULL;
        int ok = f && write_all(f, &h, &scene->settings, p, bytes);
        if (f)
            ok = fclose(f) == 0 && ok;
        else if (fd2 >= 0)
            close(fd2);
        if (ok) {
            rc = rt_atomic_commit(&af, err);
        } else {
            const int e = errno;
            rt_atomic_abort(&af);
            rc = rt_fail(err, "scene cache: %s/%s: cannot write: %s", dir, name, strerror(e));
        }
    }
    free(deps);
    sweep_stale(cd.fd);
    cache_close(&cd);
    return rc;
}

const char *rt_cache_unavailable(void) { return NULL; }

#else

int rt_cache_load(const char *dir, const char *scene_path, RtAccelKind kind, RtScene *scene, RtAccel *accel,
                  char *key, RtError *err)
{
    (void)dir; (void)scene_path; (void)kind; (void)scene; (void)accel; (void)key;
    return rt_fail(err, "--cache: this build has no scene cache (it needs libxxhash: scripts/install-deps.sh)");
}

int rt_cache_store(const char *dir, const RtScene *scene, const RtAccel *accel, char *key, RtError *err)
{
    (void)dir; (void)key; (void)scene; (void)accel;
    return rt_fail(err, "--cache: this build has no scene cache");
}

int rt_cache_entry_parse(void *bytes, size_t len, RtAccelKind kind, RtScene *scene, RtAccel *accel, RtError *err)
{
    (void)bytes; (void)len; (void)kind; (void)scene; (void)accel;
    return rt_fail(err, "this build has no scene cache");
}

void rt_cache_entry_seal(void *bytes, size_t len) { (void)bytes; (void)len; }

const char *rt_cache_unavailable(void) { return "this build has no scene cache (it needs libxxhash)"; }

void rt_content_hash(const void *bytes, size_t len, uint8_t out[16])
{
    const uint64_t a = rt_fnv1a64(bytes, len);
    uint8_t salted[8];
    memcpy(salted, &a, 8);
    const uint64_t b = rt_fnv1a64(salted, 8) ^ (uint64_t)len;
    memcpy(out, &a, 8);
    memcpy(out + 8, &b, 8);
}

#endif
