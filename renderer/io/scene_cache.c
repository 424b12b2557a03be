/* scene_cache.c - the parsed scene and its acceleration structure in one
 * binary file, mapped by a later run instead of parsing and building again
 * (docs/scene-format.md, "Scene cache").
 *
 * A cache file is DIR/KEY.rbc. KEY is a 128-bit XXH3 hash of the scene
 * file's bytes, the accelerator kind, the format version and the running
 * program's own bytes, so any change of the scene, the options or the code
 * misses. The file is a header (counts, array offsets, the hash of the
 * payload), the scene struct and the arrays, each at a 64-byte offset. A
 * load checks the header against the file's size and the payload (the scene
 * struct and every array) against its hash; a file that fails is removed and
 * the scene is built again. A store writes a
 * temporary file and renames it, so a reader never sees half a file. */
#include <errno.h>
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

#define RT_CACHE_MAGIC "RBCACHE1"
#define RT_CACHE_FORMAT 2u
#define RT_CACHE_ALIGN 64u
/* Pieces of 4 MB: a few hundred MB of arrays hash on every core (64 MB
 * pieces left all but three threads idle on the 3.6M-triangle scene). */
#define RT_HASH_CHUNK (4u << 20)

enum { A_VERTS, A_NORMALS, A_SPHERES, A_TRIS, A_MATS, A_LIGHTS, A_PRIMS, A_NODES, A_WIDE, A_COUNT };
static const size_t elem[A_COUNT] = {sizeof(RtVec3),     sizeof(RtVec3),  sizeof(RtSphere), sizeof(RtTriangle),
                                     sizeof(RtMaterial), sizeof(RtLight), sizeof(RtPrim),   sizeof(RtBvhNode),
                                     sizeof(RtBvh4Node)};

typedef struct CacheHeader {
    char magic[8];
    uint32_t format, header_size, scene_size; /* sizeof checks: another layout never loads */
    uint32_t counts[A_COUNT];
    uint64_t offset[A_COUNT];
    uint64_t file_size, payload_hash;
    uint8_t key[16];
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
#pragma omp parallel for schedule(dynamic, 1)
    for (size_t i = 0; i < n; i++)
        part[i] = hash_piece(data, len, i);
    XXH128_hash_t h = XXH3_128bits(part, n * sizeof *part);
    free(part);
    return h;
}

void rt_content_hash(const void *bytes, size_t len, uint8_t out[16])
{
    const XXH128_hash_t h = hash_big(bytes, len);
    memcpy(out, &h.high64, 8);
    memcpy(out + 8, &h.low64, 8);
}

/* The whole of a regular, non-empty file in a private mapping (writable:
 * copy on write, so the loaded arrays are the very bytes that were checked);
 * NULL otherwise. */
static void *map_file(const char *path, size_t *len)
{
    struct stat st;
    RtError ignored;
    const int fd = rt_open_regular(path, &st, &ignored);
    if (fd < 0)
        return NULL;
    if (st.st_size <= 0) {
        close(fd);
        return NULL;
    }
    *len = (size_t)st.st_size;
    void *m = mmap(NULL, *len, PROT_READ | PROT_WRITE, MAP_PRIVATE, fd, 0);
    close(fd);
    return m == MAP_FAILED ? NULL : m;
}

/* A file's content hash remembered against its identity and times, as
 * git's index remembers a file's blob (DIR/stat/DEV-INO.memo): a later key
 * for the same unchanged file reads 56 bytes instead of hashing the file.
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

static void memo_path(char *out, size_t size, const char *dir, const struct stat *st)
{
    snprintf(out, size, "%s/stat/%llx-%llx.memo", dir, (unsigned long long)st->st_dev,
             (unsigned long long)st->st_ino);
}

/* The remembered hash of the file st describes, if its memo matches. */
static int memo_read(const char *dir, const struct stat *st, XXH128_hash_t *out)
{
    char path[4200];
    memo_path(path, sizeof path, dir, st);
    FileMemo want, m;
    memo_of(st, &want);
    FILE *f = fopen(path, "rb");
    if (!f)
        return 0;
    const int got = fread(&m, sizeof m, 1, f) == 1 && fgetc(f) == EOF;
    fclose(f);
    if (!got || m.check != XXH3_64bits(&m, offsetof(FileMemo, check)) ||
        memcmp(&m, &want, offsetof(FileMemo, hash)) != 0)
        return 0;
    *out = m.hash;
    return 1;
}

static int same_state(const struct stat *a, const struct stat *b)
{
    FileMemo x, y;
    memo_of(a, &x);
    memo_of(b, &y);
    return memcmp(&x, &y, sizeof x) == 0;
}

/* Remembers hash h for the file that was st before and after hashing (a
 * temporary file renamed into place; any failure only forgoes the memo). */
static void memo_write(const char *dir, const struct stat *st, const struct stat *after, XXH128_hash_t h)
{
    struct timespec now;
    clock_gettime(CLOCK_REALTIME, &now);
    const time_t changed = st->st_mtim.tv_sec > st->st_ctim.tv_sec ? st->st_mtim.tv_sec : st->st_ctim.tv_sec;
    if (!same_state(st, after) || now.tv_sec - changed < RT_MEMO_SETTLE_S)
        return;
    char path[4200], tmp[4300];
    snprintf(path, sizeof path, "%s/stat", dir);
    if (mkdir(dir, 0777) != 0 && errno != EEXIST)
        return;
    if (mkdir(path, 0777) != 0 && errno != EEXIST)
        return;
    memo_path(path, sizeof path, dir, st);
    snprintf(tmp, sizeof tmp, "%s.tmp.XXXXXX", path);
    FileMemo m;
    memo_of(st, &m);
    m.hash = h;
    m.check = XXH3_64bits(&m, offsetof(FileMemo, check));
    const int fd = mkstemp(tmp);
    if (fd < 0)
        return;
    const int ok = write(fd, &m, sizeof m) == (ssize_t)sizeof m;
    if (close(fd) != 0 || !ok || chmod(tmp, 0644) != 0 || rename(tmp, path) != 0)
        unlink(tmp);
}

/* The hash of a regular file's bytes: remembered (dir's memo) or computed. */
static int file_hash(const char *dir, const char *path, XXH128_hash_t *out)
{
    struct stat st, after;
    if (stat(path, &st) != 0 || !S_ISREG(st.st_mode))
        return -1;
    if (memo_read(dir, &st, out))
        return 0;
    size_t len = 0;
    void *m = st.st_size > 0 ? map_file(path, &len) : NULL;
    if (st.st_size > 0 && !m)
        return -1;
    *out = m ? hash_big(m, len) : XXH3_128bits("", 0);
    if (m)
        munmap(m, len);
    if (stat(path, &after) == 0)
        memo_write(dir, &st, &after, *out);
    return 0;
}

/* The key: the scene's bytes, the accelerator kind, the format, and the
 * program itself (any rebuild with other code misses). */
static int cache_key(const char *dir, const char *scene_path, RtAccelKind kind, char *hex, RtError *err)
{
    XXH128_hash_t h[3];
    if (file_hash(dir, scene_path, &h[0]) != 0)
        return rt_fail(err, "%s: cannot read for the scene cache", scene_path); /* (the load says why) */
    if (file_hash(dir, "/proc/self/exe", &h[1]) != 0)
        h[1] = XXH3_128bits(RT_BUILD_FLAGS, sizeof RT_BUILD_FLAGS);
    const uint32_t opts[2] = {(uint32_t)kind, RT_CACHE_FORMAT};
    h[2] = XXH3_128bits(opts, sizeof opts);
    const XXH128_hash_t k = XXH3_128bits(h, sizeof h);
    snprintf(hex, 33, "%016llx%016llx", (unsigned long long)k.high64, (unsigned long long)k.low64);
    return 0;
}

static void cache_path(char *out, size_t size, const char *dir, const char *hex)
{
    snprintf(out, size, "%s/%s.rbc", dir, hex);
}

/* The arrays of a scene and its accelerator, with their sizes in bytes. */
static void arrays(const RtScene *s, const RtAccel *a, const void **p, uint64_t *bytes, uint32_t *count)
{
    const void *ptr[A_COUNT] = {s->vertices, s->normals, s->spheres, s->triangles, s->materials,
                                s->lights,   a->prims,   a->nodes,   a->wide};
    const uint32_t n[A_COUNT] = {s->nvertices, s->nnormals, s->nspheres, s->ntriangles, s->nmaterials,
                                 s->nlights,   a->nprims,   a->nnodes,   a->wide ? a->nwide : 0};
    for (int i = 0; i < A_COUNT; i++) {
        p[i] = ptr[i];
        count[i] = n[i];
        bytes[i] = (uint64_t)n[i] * elem[i];
    }
}

/* The entry's hash: of the header (its own hash field zeroed), the scene
 * struct and every array. */
static uint64_t payload_hash(const CacheHeader *hdr, const void *scene_struct, const void **p, const uint64_t *bytes)
{
    CacheHeader h0 = *hdr;
    h0.payload_hash = 0;
    XXH128_hash_t h[2 + A_COUNT];
    h[0] = XXH3_128bits(&h0, sizeof h0);
    h[1] = XXH3_128bits(scene_struct, sizeof(RtScene));
    for (int i = 0; i < A_COUNT; i++)
        h[2 + i] = hash_big(p[i], (size_t)bytes[i]);
    return XXH3_64bits(h, sizeof h);
}

/* Everything a header must satisfy before its offsets are followed. */
static int header_ok(const CacheHeader *h, size_t len)
{
    if (len < sizeof *h || memcmp(h->magic, RT_CACHE_MAGIC, 8) != 0 || h->format != RT_CACHE_FORMAT ||
        h->header_size != sizeof *h || h->scene_size != sizeof(RtScene) || h->file_size != len)
        return 0;
    for (int i = 0; i < A_COUNT; i++)
        if (h->offset[i] % RT_CACHE_ALIGN || h->offset[i] > len ||
            (uint64_t)h->counts[i] * elem[i] > len - h->offset[i])
            return 0;
    return 1;
}

int rt_cache_load(const char *dir, const char *scene_path, RtAccelKind kind, RtScene *scene, RtAccel *accel,
                  char *key, RtError *err)
{
    if (cache_key(dir, scene_path, kind, key, err) != 0)
        return -1;
    char path[4200];
    cache_path(path, sizeof path, dir, key);
    size_t len = 0;
    void *m = map_file(path, &len);
    if (!m)
        return 0; /* a miss */
    const CacheHeader *h = m;
    int ok = header_ok(h, len) && len >= sizeof(CacheHeader) + sizeof(RtScene) && h->kind == (int32_t)kind &&
             memcmp(h->key, key, sizeof h->key) == 0;
    if (ok) {
        const void *p[A_COUNT];
        uint64_t bytes[A_COUNT];
        for (int i = 0; i < A_COUNT; i++) {
            p[i] = (const char *)m + h->offset[i];
            bytes[i] = (uint64_t)h->counts[i] * elem[i];
        }
        ok = payload_hash(h, (const char *)m + sizeof *h, p, bytes) == h->payload_hash;
    }
    char *base = m;
    if (ok) { /* the settings the renderer relies on, in range */
        const RtScene *fs = (const RtScene *)(base + sizeof *h);
        ok = fs->max_depth >= 0 && fs->max_depth <= RT_MAX_DEPTH && h->nsplit <= h->counts[A_PRIMS];
    }
    if (!ok) {
        munmap(m, len);
        unlink(path); /* stale or corrupt: never trusted, built again */
        return 0;
    }
    memcpy(scene, base + sizeof *h, sizeof *scene);
    rt_scene_name(scene, scene_path);
    scene->output[sizeof scene->output - 1] = '\0';
    scene->models = 0;
    if (rt_model_supported(scene_path)) /* raytrace MODEL: the image is named after this file */
        snprintf(scene->output, sizeof scene->output, "%s.png", scene->name);
    /* the pools as the header (checked against the file) has them */
    void **sp[6] = {(void **)&scene->vertices, (void **)&scene->normals,   (void **)&scene->spheres,
                    (void **)&scene->triangles, (void **)&scene->materials, (void **)&scene->lights};
    uint32_t *np[6] = {&scene->nvertices, &scene->nnormals,   &scene->nspheres,
                       &scene->ntriangles, &scene->nmaterials, &scene->nlights};
    uint32_t *cp[6] = {&scene->cap_vertices, &scene->cap_normals,   &scene->cap_spheres,
                       &scene->cap_triangles, &scene->cap_materials, &scene->cap_lights};
    for (int i = 0; i < 6; i++) {
        *sp[i] = base + h->offset[i];
        *np[i] = *cp[i] = h->counts[i];
    }
    scene->cache_map = m;
    scene->cache_len = len;
    memset(accel, 0, sizeof *accel);
    accel->kind = (RtAccelKind)h->kind;
    accel->prims = (RtPrim *)(base + h->offset[A_PRIMS]);
    accel->nprims = h->counts[A_PRIMS];
    accel->nodes = h->counts[A_NODES] ? (RtBvhNode *)(base + h->offset[A_NODES]) : NULL;
    accel->nnodes = h->counts[A_NODES];
    accel->wide = h->counts[A_WIDE] ? (RtBvh4Node *)(base + h->offset[A_WIDE]) : NULL;
    accel->nwide = h->counts[A_WIDE];
    accel->nsplit = h->nsplit;
    accel->depth = h->depth;
    accel->leaves = h->leaves;
    accel->sah_cost = h->sah_cost;
    accel->mapped = 1;
    return 1;
}

/* Writes the header, the scene struct and the arrays to f. */
static int write_all(FILE *f, CacheHeader *h, const RtScene *scene, const void **p, const uint64_t *bytes)
{
    static const char zero[RT_CACHE_ALIGN] = {0};
    int ok = fwrite(h, sizeof *h, 1, f) == 1 && fwrite(scene, sizeof *scene, 1, f) == 1;
    uint64_t at = sizeof *h + sizeof *scene;
    for (int i = 0; i < A_COUNT && ok; i++) {
        ok = fwrite(zero, 1, h->offset[i] - at, f) == h->offset[i] - at &&
             (bytes[i] == 0 || fwrite(p[i], 1, bytes[i], f) == bytes[i]);
        at = h->offset[i] + bytes[i];
    }
    return ok;
}

int rt_cache_store(const char *dir, const char *key, const RtScene *scene, const RtAccel *accel, RtError *err)
{
    const void *p[A_COUNT];
    uint64_t bytes[A_COUNT];
    CacheHeader h;
    memset(&h, 0, sizeof h);
    arrays(scene, accel, p, bytes, h.counts);
    memcpy(h.magic, RT_CACHE_MAGIC, 8);
    h.format = RT_CACHE_FORMAT;
    h.header_size = sizeof h;
    h.scene_size = sizeof *scene;
    uint64_t at = sizeof h + sizeof *scene;
    for (int i = 0; i < A_COUNT; i++) {
        at = (at + RT_CACHE_ALIGN - 1) / RT_CACHE_ALIGN * RT_CACHE_ALIGN;
        h.offset[i] = at;
        at += bytes[i];
    }
    h.file_size = at;
    h.kind = accel->kind;
    h.nsplit = accel->nsplit;
    h.depth = accel->depth;
    h.leaves = accel->leaves;
    h.sah_cost = accel->sah_cost;
    memcpy(h.key, key, sizeof h.key); /* (the first half of the hex: a check only) */
    h.payload_hash = payload_hash(&h, scene, p, bytes);
    char path[4200], tmp[4300];
    cache_path(path, sizeof path, dir, key);
    snprintf(tmp, sizeof tmp, "%s.tmp.XXXXXX", path);
    if (mkdir(dir, 0777) != 0 && errno != EEXIST)
        return rt_fail(err, "scene cache: cannot create %s: %s", dir, strerror(errno));
    int fd = mkstemp(tmp);
    FILE *f = fd >= 0 ? fdopen(fd, "wb") : NULL;
    int ok = f && write_all(f, &h, scene, p, bytes);
    if (f)
        ok = fclose(f) == 0 && ok;
    else if (fd >= 0)
        close(fd);
    if (!ok || chmod(tmp, 0644) != 0 || rename(tmp, path) != 0) {
        const int e = errno;
        if (fd >= 0)
            unlink(tmp);
        return rt_fail(err, "scene cache: cannot write %s: %s", path, strerror(e));
    }
    return 0;
}

const char *rt_cache_unavailable(void) { return NULL; }

#else

int rt_cache_load(const char *dir, const char *scene_path, RtAccelKind kind, RtScene *scene, RtAccel *accel,
                  char *key, RtError *err)
{
    (void)dir; (void)scene_path; (void)kind; (void)scene; (void)accel; (void)key;
    return rt_fail(err, "--cache: this build has no scene cache (it needs libxxhash: scripts/install-deps.sh)");
}

int rt_cache_store(const char *dir, const char *key, const RtScene *scene, const RtAccel *accel, RtError *err)
{
    (void)dir; (void)key; (void)scene; (void)accel;
    return rt_fail(err, "--cache: this build has no scene cache");
}

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
