/* mpi_common.c - what the two MPI backends share (mpi_common.h): start and
 * end, agreeing on failures, the scene on every rank (and, for the CPU
 * backend, one copy of it per NUMA node), and the dynamic scheme's shared
 * image.
 *
 * Scene: every rank parses the file (--mpi-scene every, as the report) or
 * rank 0 parses and broadcasts the settings and the flat arrays
 * (--mpi-scene bcast); see docs/cpu-backends.md for the measurement behind
 * the default.
 *
 * Errors: every MPI call goes through RT_MPI_CHECK (file, line, MPI's error
 * string, then MPI_Abort, which ends all ranks: never a hang). Failures
 * before rendering are agreed on with MPI_Allreduce (rt_mpi_agree) so that
 * exactly one rank, rank 0, prints exactly one message. */
#define _GNU_SOURCE /* sched_getaffinity */
#include <mpi.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <dirent.h>
#include <fcntl.h>
#include <sched.h>
#include <sys/mman.h>
#include <unistd.h>

#include "config.h"
#include "cpu_trace.h"
#include "mpi_common.h"
#include "rt.h"

/* rank 0 parses and broadcasts: it wins at 16 ranks and on clusters, where P
 * ranks would otherwise read one file from a shared file system; at 2-4
 * ranks "every" is slightly faster (docs/cpu-backends.md). */
#define RT_MPI_SCENE_DEFAULT "bcast"
enum { RT_TAG_ERROR = 1 };

int rt_mpi_rank, rt_mpi_size = 1;
int rt_mpi_local_rank, rt_mpi_local_size = 1, rt_mpi_node, rt_mpi_nodes = 1;
MPI_Comm rt_mpi_node_comm = MPI_COMM_NULL;
int rt_mpi_thread_level;
double rt_mpi_load_ms;
int rt_mpi_scene_copies = 1;
int rt_mpi_shares_core, rt_mpi_core_sharing_ranks;
const char *rt_mpi_scene_how = "every";
static int g_inited;

void rt_mpi_die(const char *file, int line, const char *call, int code)
{
    char s[MPI_MAX_ERROR_STRING];
    int n = 0;
    if (MPI_Error_string(code, s, &n) != MPI_SUCCESS)
        snprintf(s, sizeof s, "error %d", code);
    fprintf(stderr, "raytrace: rank %d: %s:%d: %s failed: %s\n", rt_mpi_rank, file, line, call, s);
    fflush(stderr);
    MPI_Abort(MPI_COMM_WORLD, 1);
}

/* A CPU set of *size bytes, sized for every CPU the system may have (*ncpu
 * of them), and in it this process's CPUs; with none set where the kernel
 * does not say. Free with CPU_FREE. */
static cpu_set_t *own_cpus(size_t *size, int *ncpu, int *known)
{
    cpu_set_t *set = rt_thread_cpu_mask(size, ncpu, known);
    if (!set)
        rt_mpi_die(__FILE__, __LINE__, "malloc", MPI_ERR_NO_MEM);
    return set;
}

/* Whether another rank of this node may run on one of this rank's CPUs:
 * their affinity masks overlap (unbound ranks, or oversubscribed cores).
 * A mask this rank cannot read counts as every CPU. */
static int shares_core(void)
{
    size_t size;
    int ncpu, known;
    cpu_set_t *mine = own_cpus(&size, &ncpu, &known), *both = CPU_ALLOC(ncpu);
    unsigned char *all = malloc(size * (size_t)rt_mpi_local_size);
    if (!both || !all)
        rt_mpi_die(__FILE__, __LINE__, "malloc", MPI_ERR_NO_MEM);
    if (!known)
        memset(mine, 0xff, size);
    RT_MPI_CHECK(MPI_Allgather(mine, (int)size, MPI_BYTE, all, (int)size, MPI_BYTE, rt_mpi_node_comm));
    int shared = 0;
    for (int r = 0; r < rt_mpi_local_size && !shared; r++) {
        CPU_AND_S(size, both, mine, (cpu_set_t *)(void *)(all + size * (size_t)r));
        shared = r != rt_mpi_local_rank && CPU_COUNT_S(size, both) > 0;
    }
    CPU_FREE(mine);
    CPU_FREE(both);
    free(all);
    return shared;
}

int rt_mpi_init(int *argc, char ***argv, RtError *err)
{
    /* FUNNELED: OpenMP threads render, only the main thread calls MPI. */
    if (MPI_Init_thread(argc, argv, MPI_THREAD_FUNNELED, &rt_mpi_thread_level) != MPI_SUCCESS)
        return rt_fail(err, "MPI_Init_thread failed");
    g_inited = 1;
    MPI_Comm_set_errhandler(MPI_COMM_WORLD, MPI_ERRORS_RETURN);
    RT_MPI_CHECK(MPI_Comm_rank(MPI_COMM_WORLD, &rt_mpi_rank));
    RT_MPI_CHECK(MPI_Comm_size(MPI_COMM_WORLD, &rt_mpi_size));
    /* The ranks of this node (what the launcher calls a node: MPI_COMM_TYPE_SHARED)
     * and the node's number: the order of the nodes' lowest ranks. */
    RT_MPI_CHECK(MPI_Comm_split_type(MPI_COMM_WORLD, MPI_COMM_TYPE_SHARED, 0, MPI_INFO_NULL, &rt_mpi_node_comm));
    RT_MPI_CHECK(MPI_Comm_rank(rt_mpi_node_comm, &rt_mpi_local_rank));
    RT_MPI_CHECK(MPI_Comm_size(rt_mpi_node_comm, &rt_mpi_local_size));
    int leader = rt_mpi_local_rank == 0, before = 0;
    RT_MPI_CHECK(MPI_Allreduce(&leader, &rt_mpi_nodes, 1, MPI_INT, MPI_SUM, MPI_COMM_WORLD));
    RT_MPI_CHECK(MPI_Exscan(&leader, &before, 1, MPI_INT, MPI_SUM, MPI_COMM_WORLD));
    rt_mpi_node = rt_mpi_rank == 0 ? 0 : before; /* (Exscan leaves rank 0's undefined) */
    RT_MPI_CHECK(MPI_Bcast(&rt_mpi_node, 1, MPI_INT, 0, rt_mpi_node_comm));
    rt_mpi_shares_core = shares_core();
    RT_MPI_CHECK(MPI_Allreduce(&rt_mpi_shares_core, &rt_mpi_core_sharing_ranks, 1, MPI_INT, MPI_SUM, MPI_COMM_WORLD));
    return 0;
}

void rt_mpi_finalize(void)
{
    if (!g_inited)
        return;
    g_inited = 0;
    if (rt_mpi_node_comm != MPI_COMM_NULL)
        MPI_Comm_free(&rt_mpi_node_comm);
    /* After an agreed failure every rank is alive and knows it, and rank 0
     * has printed the one message (main.c): all ranks finalize together and
     * exit 1. MPI_Abort would return from mpirun faster, but Open MPI 4.1's
     * PMIx thread sometimes crashes during the abort (exit 139 and a
     * backtrace instead of one line). */
    fflush(stdout);
    fflush(stderr);
    MPI_Finalize();
}

static int mpi_is_root(void) { return rt_mpi_rank == 0; }

int rt_mpi_agree(int failed, RtError *err)
{
    int mine = failed ? rt_mpi_rank : rt_mpi_size, first;
    RT_MPI_CHECK(MPI_Allreduce(&mine, &first, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD));
    if (first == rt_mpi_size)
        return 0;
    if (first != 0) { /* the lowest failing rank tells rank 0 what went wrong */
        if (rt_mpi_rank == first) {
            err->msg[sizeof err->msg - 1] = '\0';
            RT_MPI_CHECK(MPI_Send(err->msg, (int)sizeof err->msg, MPI_CHAR, 0, RT_TAG_ERROR, MPI_COMM_WORLD));
        } else if (rt_mpi_rank == 0) {
            char msg[sizeof err->msg];
            RT_MPI_CHECK(MPI_Recv(msg, (int)sizeof msg, MPI_CHAR, first, RT_TAG_ERROR, MPI_COMM_WORLD,
                                  MPI_STATUS_IGNORE));
            msg[sizeof msg - 1] = '\0';
            rt_fail(err, "rank %d: %.1000s", first, msg);
        }
    }
    return 1;
}

int rt_mpi_test_rank(const char *var)
{
#if RT_TEST_HOOKS
    const char *v = getenv(var);
    return v && *v && atoi(v) == rt_mpi_rank;
#else
    (void)var;
    return 0;
#endif
}

void rt_mpi_rank_nodes(char *buf, size_t size)
{
    int *all = rt_mpi_rank == 0 ? malloc(sizeof *all * (size_t)rt_mpi_size) : NULL;
    if (rt_mpi_rank == 0 && !all)
        rt_mpi_die(__FILE__, __LINE__, "malloc", MPI_ERR_NO_MEM);
    RT_MPI_CHECK(MPI_Gather(&rt_mpi_node, 1, MPI_INT, all, 1, MPI_INT, 0, MPI_COMM_WORLD));
    if (rt_mpi_rank != 0)
        return;
    size_t len = 0;
    buf[0] = '\0';
    for (int r = 0; r < rt_mpi_size && len < size; r++)
        len += (size_t)snprintf(buf + len, size - len, "%s%d", r ? "/" : "", all[r]);
    free(all);
}

/* Broadcasts n bytes in pieces below INT_MAX (MPI counts are int). */
static void bcast_bytes(void *p, size_t n)
{
    const size_t piece = (size_t)1 << 30;
    for (size_t off = 0; off < n; off += piece) {
        size_t k = n - off < piece ? n - off : piece;
        RT_MPI_CHECK(MPI_Bcast((char *)p + off, (int)k, MPI_BYTE, 0, MPI_COMM_WORLD));
    }
}

static int mpi_same(const uint8_t digest[16], RtError *err)
{
    uint8_t root[16];
    memcpy(root, digest, 16);
    RT_MPI_CHECK(MPI_Bcast(root, 16, MPI_BYTE, 0, MPI_COMM_WORLD));
    const int differs = memcmp(root, digest, 16) != 0;
    if (differs)
        rt_fail(err, "the scene this rank read differs from rank 0's (its files changed between the ranks' reads, "
                     "or the ranks see different files)");
    return rt_mpi_agree(differs, err);
}

/* The dependency list from rank 0. */
static int bcast_deps(RtScene *scene, RtError *err)
{
    char *blob = NULL;
    size_t len = 0;
    int bad = rt_mpi_rank == 0 && rt_scene_deps_pack(scene, &blob, &len) != 0;
    unsigned long long n = len;
    RT_MPI_CHECK(MPI_Bcast(&n, 1, MPI_UNSIGNED_LONG_LONG, 0, MPI_COMM_WORLD));
    if (rt_mpi_rank != 0)
        bad = !(blob = malloc(n ? (size_t)n : 1));
    int any = 0;
    RT_MPI_CHECK(MPI_Allreduce(&bad, &any, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD));
    if (!any) {
        bcast_bytes(blob, (size_t)n);
        if (rt_mpi_rank != 0)
            any = rt_scene_deps_unpack(scene, blob, (size_t)n, err) != 0;
    }
    free(blob);
    return any ? rt_fail(err, "out of memory for the scene's file list") : 0;
}

/* Rank 0 parses; the others get the settings and the flat arrays (their
 * own copies), and the scene file's hash and file list that the ranks'
 * agreement compares (mpi_same). The rest of the source is each rank's own:
 * the path and name from `path`, no line numbers (only rank 0 reports). */
static int scene_load_bcast(const char *path, RtScene *scene, RtWarnFn warn, void *warn_ctx, RtError *err)
{
    int st = 0;
    if (rt_mpi_rank == 0)
        st = rt_scene_load(path, scene, warn, warn_ctx, err);
    RT_MPI_CHECK(MPI_Bcast(&st, 1, MPI_INT, 0, MPI_COMM_WORLD));
    if (st != 0) /* rank 0 has the parser's message and will print it */
        return rt_mpi_rank == 0 ? -1 : rt_fail(err, "%s: rank 0 could not load the scene", path);
    if (rt_mpi_rank != 0) {
        memset(scene, 0, sizeof *scene);
        rt_scene_name(scene, path);
    }
    bcast_bytes(&scene->settings, sizeof scene->settings);
    RT_MPI_CHECK(MPI_Bcast(scene->source.file_hash, 16, MPI_BYTE, 0, MPI_COMM_WORLD));
#define ARRAY_ENTRY(T, name) {(void **)&scene->name, &scene->n##name, &scene->cap_##name, sizeof(T)},
    struct { void **p; uint32_t *n, *cap; size_t size; } a[] = {RT_SCENE_ARRAYS(ARRAY_ENTRY)};
#undef ARRAY_ENTRY
    enum { NA = sizeof a / sizeof a[0] };
    uint32_t n[NA];
    for (int i = 0; i < NA; i++)
        n[i] = *a[i].n;
    RT_MPI_CHECK(MPI_Bcast(n, NA, MPI_UINT32_T, 0, MPI_COMM_WORLD));
    int nomem = 0;
    if (rt_mpi_rank != 0)
        for (int i = 0; i < NA; i++) {
            *a[i].p = malloc(n[i] ? (size_t)n[i] * a[i].size : 1);
            *a[i].n = *a[i].cap = n[i];
            nomem |= *a[i].p == NULL;
        }
    int any = 0;
    RT_MPI_CHECK(MPI_Allreduce(&nomem, &any, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD));
    if (any)
        return rt_fail(err, "%s: out of memory for the broadcast scene", path);
    for (int i = 0; i < NA; i++)
        bcast_bytes(*a[i].p, (size_t)n[i] * a[i].size);
    return bcast_deps(scene, err);
}

static int mpi_scene_load(const char *path, const char *how, RtScene *scene, RtWarnFn warn, void *warn_ctx,
                          RtError *err)
{
    double t0 = rt_now_ms();
    int bcast = strcmp(how ? how : RT_MPI_SCENE_DEFAULT, "bcast") == 0 && rt_mpi_size > 1;
    rt_mpi_scene_how = bcast ? "bcast" : "every";
    int rc = bcast ? scene_load_bcast(path, scene, warn, warn_ctx, err) : rt_scene_load(path, scene, warn, warn_ctx, err);
    rt_mpi_load_ms = rt_now_ms() - t0;
    return rc;
}

/* ---------------------------------------------------------------- one scene per NUMA node */

/* Lays the view's arrays out one after another from base, each on a
 * 128-byte line pair of its own; with base, points the view at them there,
 * and with copy, copies them in first. Returns the bytes they take. */
static size_t place_view(RtSceneView *v, char *base, int copy)
{
    size_t off = 0;
#define PLACE(ptr, bytes)                                                                                             \
    do {                                                                                                              \
        const size_t b_ = (bytes);                                                                                    \
        off = (off + 127) & ~(size_t)127;                                                                             \
        if (base && b_) {                                                                                             \
            if (copy)                                                                                                 \
                memcpy(base + off, (ptr), b_);                                                                        \
            (ptr) = (void *)(base + off);                                                                             \
        }                                                                                                             \
        off += b_;                                                                                                    \
    } while (0)
    PLACE(v->prims, (size_t)v->nprims * sizeof *v->prims);
    /* (the binary and 4-wide trees: only where the CPU's copy is missing) */
    PLACE(v->nodes, v->nodes && !v->cpu_wide ? (size_t)v->nnodes * sizeof *v->nodes : 0);
    PLACE(v->wide, v->wide && !v->cpu_wide ? (size_t)v->nwide * sizeof *v->wide : 0);
#define PLACE_ARRAY(T, name) PLACE(v->name, (size_t)v->n##name * sizeof(T));
    RT_SCENE_ARRAYS(PLACE_ARRAY)
#undef PLACE_ARRAY
    PLACE(v->cpu_wide, v->cpu_wide ? (size_t)v->nwide * sizeof *v->cpu_wide : 0);
    PLACE(v->cpu_leaves, (size_t)v->ncpu_leaves * sizeof(RtCpuLeaf4));
#undef PLACE
    return off;
}

/* The same view on every rank of comm: the same counts of everything. */
static int same_counts(const RtSceneView *v, MPI_Comm comm)
{
    uint64_t c[] = {v->nprims, v->nnodes, v->nwide, v->ncpu_leaves, v->nodes != NULL, v->wide != NULL,
                    v->cpu_wide != NULL,
#define COUNT(T, name) v->n##name,
                    RT_SCENE_ARRAYS(COUNT)
#undef COUNT
    };
    enum { N = sizeof c / sizeof c[0] };
    if (rt_mpi_test_rank("RT_MPI_TEST_VIEW_DIFFERS")) /* (tests/cpu/mpi_fail.sh: the fallback) */
        c[0] ^= 1;
    uint64_t both[2 * N], max[2 * N];
    for (int i = 0; i < N; i++)
        both[i] = c[i], both[N + i] = ~c[i];
    RT_MPI_CHECK(MPI_Allreduce(both, max, 2 * N, MPI_UINT64_T, MPI_MAX, comm));
    for (int i = 0; i < N; i++) /* max == min everywhere: the same answer on every rank */
        if (max[i] != ~max[N + i])
            return 0;
    return 1;
}

typedef struct NodeScene {
    MPI_Comm comm;
    void *map; /* the node's copy, mapped here */
    size_t len;
} NodeScene;
static NodeScene g_node_scene = {MPI_COMM_NULL, NULL, 0};

/* The NUMA node that holds every CPU this process may run on (sysfs), or
 * -1: they span several (a rank bound to none), or the kernel does not say. */
static int numa_node(void)
{
    size_t size;
    int ncpu, known;
    cpu_set_t *mine = own_cpus(&size, &ncpu, &known), *node = CPU_ALLOC(ncpu), *both = CPU_ALLOC(ncpu);
    if (!node || !both)
        rt_mpi_die(__FILE__, __LINE__, "malloc", MPI_ERR_NO_MEM);
    DIR *d = known ? opendir("/sys/devices/system/node") : NULL;
    int found = -1;
    for (struct dirent *e; d && found < 0 && (e = readdir(d));) {
        char path[300], list[4096];
        int id;
        if (sscanf(e->d_name, "node%d", &id) != 1)
            continue;
        snprintf(path, sizeof path, "/sys/devices/system/node/%s/cpulist", e->d_name);
        FILE *f = fopen(path, "r");
        const int ok = f && fgets(list, sizeof list, f);
        if (f)
            fclose(f);
        CPU_ZERO_S(size, node);
        /* "0-31,64-95" */
        for (char *p = list; ok && *p && *p != '\n';) {
            char *end;
            long a = strtol(p, &end, 10), b = a;
            if (end == p)
                break;
            if (*end == '-')
                b = strtol(end + 1, &end, 10);
            for (long c = a; c <= b && c < ncpu; c++)
                CPU_SET_S((int)c, size, node);
            p = *end == ',' ? end + 1 : end;
        }
        CPU_AND_S(size, both, mine, node);
        if (ok && CPU_EQUAL_S(size, both, mine))
            found = id;
    }
    if (d)
        closedir(d);
    CPU_FREE(mine);
    CPU_FREE(node);
    CPU_FREE(both);
    return found;
}

/* The node's copy on its lowest rank: a POSIX shared-memory object of len
 * bytes, named in name, the view's arrays copied in. 0, or -1 (nothing
 * left behind). Its pages are reserved first (posix_fallocate): /dev/shm
 * can be small (64 MiB in a default Docker container), and a page that does
 * not fit would otherwise end the rank with SIGBUS. */
static int node_copy_create(RtSceneView *v, size_t len, char *name, size_t size, void **map)
{
    snprintf(name, size, "/raytrace.%ld.%llx", (long)getpid(), (unsigned long long)rt_now_ns());
    /* (RT_MPI_TEST_SHM_FAIL: tests/cpu/mpi_fail.sh, the fallback) */
    const int fd = rt_mpi_test_rank("RT_MPI_TEST_SHM_FAIL") ? -1 : shm_open(name, O_RDWR | O_CREAT | O_EXCL, 0600);
    if (fd < 0)
        return -1;
    *map = MAP_FAILED;
    if (posix_fallocate(fd, 0, (off_t)len) == 0)
        *map = mmap(NULL, len, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
    close(fd);
    if (*map == MAP_FAILED) {
        shm_unlink(name);
        return -1;
    }
    RtSceneView copy = *v; /* (this rank's view moves there only once every rank can map it) */
    place_view(&copy, *map, 1);
    __atomic_thread_fence(__ATOMIC_RELEASE);
    return 0;
}

/* RtCollective.share's work. Every rank renders from its own copy of the
 * scene otherwise: at 64 ranks, 64 copies of the dragon's 2 MB ask 128 MB
 * of a last-level cache that one copy fits, as the OpenMP backend's threads
 * share theirs, and as many times the memory. The ranks of a NUMA node (sysfs: the node
 * holding all of a rank's CPUs; the whole node where a rank is bound to
 * none) read one copy in shared memory, which their lowest rank makes
 * (the "MPI + MPI" model: Hoefler et al., Computing 95, 2013). Where it
 * cannot, each rank keeps its own. */
static NodeScene *share_numa(RtSceneView *v)
{
    NodeScene *s = &g_node_scene;
    /* one copy per NUMA node; one per node where a rank is bound to none */
    int id = numa_node(), low;
    RT_MPI_CHECK(MPI_Allreduce(&id, &low, 1, MPI_INT, MPI_MIN, rt_mpi_node_comm));
    RT_MPI_CHECK(MPI_Comm_split(rt_mpi_node_comm, low < 0 ? 0 : id, rt_mpi_local_rank, &s->comm));
    int lrank, lsize;
    RT_MPI_CHECK(MPI_Comm_rank(s->comm, &lrank));
    RT_MPI_CHECK(MPI_Comm_size(s->comm, &lsize));
    /* (a rank alone on its NUMA node still takes part in the collectives) */
    if (!same_counts(v, s->comm) || lsize < 2) {
        MPI_Comm_free(&s->comm);
        return NULL;
    }
    s->len = place_view(v, NULL, 0);
    s->map = NULL;
    char name[64] = "";
    int failed = lrank == 0 && node_copy_create(v, s->len, name, sizeof name, &s->map) != 0;
    RT_MPI_CHECK(MPI_Bcast(name, (int)sizeof name, MPI_CHAR, 0, s->comm));
    RT_MPI_CHECK(MPI_Bcast(&failed, 1, MPI_INT, 0, s->comm));
    int any = failed;
    if (!failed) {
        int mine = 0;
        if (lrank != 0) {
            const int fd = rt_mpi_test_rank("RT_MPI_TEST_SHM_FAIL") ? -1 : shm_open(name, O_RDONLY, 0);
            /* (its page tables filled now, not by faults inside the frame) */
            void *m = fd < 0 ? MAP_FAILED : mmap(NULL, s->len, PROT_READ, MAP_SHARED | MAP_POPULATE, fd, 0);
            if (fd >= 0)
                close(fd);
            s->map = m == MAP_FAILED ? NULL : m;
            mine = !s->map;
        }
        RT_MPI_CHECK(MPI_Allreduce(&mine, &any, 1, MPI_INT, MPI_MAX, s->comm));
        if (lrank == 0) /* every rank has mapped it, or failed to: no name left behind */
            shm_unlink(name);
    }
    if (any) {
        if (s->map)
            munmap(s->map, s->len);
        s->map = NULL;
        MPI_Comm_free(&s->comm);
        return NULL;
    }
    __atomic_thread_fence(__ATOMIC_ACQUIRE);
    place_view(v, s->map, 0);
    return s;
}

static void *mpi_share(RtSceneView *v)
{
    rt_mpi_scene_copies = rt_mpi_size;
    if (rt_mpi_size < 2 || g_node_scene.map)
        return NULL;
    NodeScene *s = share_numa(v);
    int mine = 1, lrank = 0;
    if (s) {
        RT_MPI_CHECK(MPI_Comm_rank(s->comm, &lrank));
        mine = lrank == 0;
    }
    RT_MPI_CHECK(MPI_Allreduce(&mine, &rt_mpi_scene_copies, 1, MPI_INT, MPI_SUM, MPI_COMM_WORLD));
    return s;
}

/* RtCollective.unshare. */
static void mpi_unshare(void *shared)
{
    NodeScene *s = shared;
    if (!s)
        return;
    munmap(s->map, s->len);
    s->map = NULL;
    MPI_Comm_free(&s->comm);
}

const RtCollective rt_mpi_collective = {mpi_is_root, rt_mpi_agree, mpi_scene_load, mpi_same, mpi_share, mpi_unshare};

/* ---------------------------------------------------------------- the shared image */

/* Maps [p, p + n) of rank 0's segment into this process's page tables now.
 * Each rank maps a shared segment page by page, on its first write to each
 * page: a fault per page, 400-5,200 per rank in a frame at 2 ranks (the
 * record's rank_faults), taken inside the frame. Taken here, they come
 * before the starting barrier. MADV_POPULATE_WRITE (Linux 5.14) maps
 * without writing; elsewhere an atomic add of zero per page does. */
static void map_now(void *p, size_t n)
{
    const uintptr_t pg = (uintptr_t)sysconf(_SC_PAGESIZE), a = (uintptr_t)p & ~(pg - 1), end = (uintptr_t)p + n;
#ifdef MADV_POPULATE_WRITE
    if (madvise((void *)a, end - a, MADV_POPULATE_WRITE) == 0)
        return;
#endif
    for (uintptr_t q = (uintptr_t)p; q < end; q = (q & ~(pg - 1)) + pg)
        __atomic_fetch_add((unsigned char *)q, 0, __ATOMIC_RELAXED);
}

void rt_mpi_image_open(RtMpiImage *m, size_t bytes, const void *init, int shared, size_t extra)
{
    memset(m, 0, sizeof *m);
    m->bytes = bytes;
    m->extra_bytes = extra;
    m->img_off = RT_WIN_EXTRA + (extra + 127) / 128 * 128;
    shared = shared && rt_mpi_size > 1;
    MPI_Aint size = rt_mpi_rank == 0 ? (MPI_Aint)(m->img_off + bytes) : 0;
    if (shared)
        RT_MPI_CHECK(MPI_Win_allocate_shared(size, 1, MPI_INFO_NULL, MPI_COMM_WORLD, &m->base, &m->win));
    else
        RT_MPI_CHECK(MPI_Win_allocate(size, 1, MPI_INFO_NULL, MPI_COMM_WORLD, &m->base, &m->win));
    MPI_Win_set_errhandler(m->win, MPI_ERRORS_RETURN);
    int *model = NULL, flag = 0;
    RT_MPI_CHECK(MPI_Win_get_attr(m->win, MPI_WIN_MODEL, &model, &flag));
    /* In the unified memory model (osc/sm, osc/rdma) rank 0 can render into
     * the window directly; in the separate model it MPI_Puts to itself. */
    m->direct = rt_mpi_rank == 0 && flag && *model == MPI_WIN_UNIFIED;
    if (shared) { /* rank 0's segment, mapped here */
        MPI_Aint seg;
        int disp;
        RT_MPI_CHECK(MPI_Win_shared_query(m->win, 0, &seg, &disp, &m->base));
        m->direct = 1;
        m->atomic = 1;
        if (rt_mpi_rank != 0) /* rank 0 writes all of it below */
            map_now(m->base, m->img_off + bytes);
    } else if (rt_mpi_size == 1) { /* the counter is this process's own memory */
        m->atomic = 1;
    }
    m->extra = (char *)m->base + RT_WIN_EXTRA;
    m->img0 = (char *)m->base + m->img_off;
    if (rt_mpi_rank == 0) {
        if (init)
            memcpy(m->img0, init, bytes); /* e.g. main's NaN poison, for --verify */
        else
            memset(m->img0, 0, bytes);
    }
    RT_MPI_CHECK(MPI_Win_lock_all(MPI_MODE_NOCHECK, m->win));
}

void rt_mpi_frame_start(RtMpiImage *m)
{
    int64_t *arrived = (int64_t *)(void *)((char *)m->base + 128); /* (shared memory only) */
    if (rt_mpi_rank == 0) {
        *(int64_t *)m->base = 0;
        if (m->atomic)
            *arrived = 0;
        memset(m->extra, 0, m->extra_bytes);
    }
    RT_MPI_CHECK(MPI_Win_sync(m->win));
    RT_MPI_CHECK(MPI_Barrier(MPI_COMM_WORLD));
    if (!m->atomic)
        return;
    /* Then a flat barrier on one counter, every rank spinning: Open MPI's
     * barrier releases its ranks along a tree, and one rank preempted on
     * the way holds up its whole subtree (at 64 ranks, groups of ranks 16
     * apart left it 1-5 ms after the first). Here each rank leaves as soon
     * as it sees the last arrival, within a cache line's transfer. A rank
     * yields its core only where a rank it waits for may need that core
     * (Open MPI's own rule: yield when idle only when oversubscribed);
     * elsewhere a yield hands the core to any other task on it, a
     * background job's, until the next tick. */
    __atomic_fetch_add(arrived, 1, __ATOMIC_ACQ_REL);
    for (unsigned i = 0; __atomic_load_n(arrived, __ATOMIC_ACQUIRE) < rt_mpi_size; i++) {
        if (i >= 4096 && rt_mpi_shares_core) /* past ~0.2 ms */
            sched_yield();
#if defined(__x86_64__) || defined(__i386__)
        else
            __builtin_ia32_pause();
#endif
    }
}

/* The counter now, and the counter before adding n to it. Nothing is
 * published through the counter: relaxed atomics. (A look and an add rather
 * than a compare-and-swap: Open MPI 4.1's osc/rdma crashes in
 * MPI_Compare_and_swap on one node.) */
static int64_t counter_add(RtMpiImage *m, int64_t n)
{
    int64_t was;
    if (m->atomic)
        return n ? __atomic_fetch_add((int64_t *)m->base, n, __ATOMIC_RELAXED)
                 : __atomic_load_n((int64_t *)m->base, __ATOMIC_RELAXED);
    RT_MPI_CHECK(MPI_Fetch_and_op(&n, &was, MPI_INT64_T, 0, 0, n ? MPI_SUM : MPI_NO_OP, m->win));
    RT_MPI_CHECK(MPI_Win_flush(0, m->win));
    return was;
}

int64_t rt_mpi_claim(RtMpiImage *m, int64_t total, int64_t min_claim, int claimers, int64_t *first)
{
    /* The claim is sized from a look at the counter just before it is
     * added, never from this rank's last claim: a rank that last looked
     * early would otherwise take a large claim at the end of the frame and
     * finish last. */
    int64_t now = counter_add(m, 0), claim = (total - now) / (4 * (int64_t)rt_mpi_size * claimers);
    claim = claim < min_claim ? min_claim : claim;
    *first = now >= total ? now : counter_add(m, claim);
    if (*first >= total)
        return 0;
    return total - *first < claim ? total - *first : claim;
}

void rt_mpi_put_runs(RtMpiImage *m, const void *src, size_t off, size_t width, size_t pitch, size_t count)
{
    if (count == 0 || width == 0)
        return;
    MPI_Datatype t;
    RT_MPI_CHECK(MPI_Type_vector((int)count, (int)width, (int)pitch, MPI_BYTE, &t));
    RT_MPI_CHECK(MPI_Type_commit(&t));
    RT_MPI_CHECK(MPI_Put((const char *)src + off, 1, t, 0, (MPI_Aint)(m->img_off + off), 1, t, m->win));
    MPI_Type_free(&t);
}

void rt_mpi_frame_end(RtMpiImage *m)
{
    RT_MPI_CHECK(MPI_Win_flush(0, m->win));    /* this rank's puts are in rank 0's memory, */
    RT_MPI_CHECK(MPI_Win_sync(m->win));        /* and its direct stores visible */
    RT_MPI_CHECK(MPI_Barrier(MPI_COMM_WORLD)); /* ... and everyone's */
    if (rt_mpi_rank == 0)
        RT_MPI_CHECK(MPI_Win_sync(m->win));
}

void rt_mpi_image_close(RtMpiImage *m, void *out)
{
    if (rt_mpi_rank == 0)
        memcpy(out, m->img0, m->bytes);
    RT_MPI_CHECK(MPI_Win_unlock_all(m->win));
    RT_MPI_CHECK(MPI_Win_free(&m->win));
}
