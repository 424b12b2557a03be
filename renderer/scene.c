/* scene.c - camera set-up, the shading view, freeing a scene, and small shared helpers. */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <math.h>
#include <sched.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#ifdef _OPENMP
#include <omp.h>
#endif

#include "rt.h"
#include "core/rt_quantize.h"

int rt_fail(RtError *err, const char *fmt, ...)
{
    if (err) {
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(err->msg, sizeof err->msg, fmt, ap);
        va_end(ap);
    }
    return -1;
}

static int cam_err(const RtScene *s, int line, RtError *err, const char *msg)
{
    if (line > 0)
        return rt_fail(err, "%s:%d: %s", s->source.path, line, msg);
    return rt_fail(err, "%s: %s (default value)", s->source.path, msg);
}

int rt_scene_camera(const RtScene *s, RtCamera *cam, RtError *err)
{
    /* Camera vectors in double: they are computed once, and the reference
     * images were made in double. */
    double f[3] = {s->settings.camera_fwd.x, s->settings.camera_fwd.y, s->settings.camera_fwd.z};
    double u[3] = {s->settings.camera_up.x, s->settings.camera_up.y, s->settings.camera_up.z};
    double fl = sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]);
    if (!(fl > 0.0))
        return cam_err(s, s->source.line_fwd, err, "camera_fwd is the zero vector");
    for (int i = 0; i < 3; i++)
        f[i] /= fl;
    double r[3] = {u[1] * f[2] - u[2] * f[1], u[2] * f[0] - u[0] * f[2], u[0] * f[1] - u[1] * f[0]};
    double rl = sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
    double ul = sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
    if (!(ul > 0.0) || !(rl > 1e-6 * ul))
        return cam_err(s, s->source.line_up ? s->source.line_up : s->source.line_fwd, err,
                       "camera_up is zero or parallel to camera_fwd: no image plane");
    for (int i = 0; i < 3; i++)
        r[i] /= rl;
    double up[3] = {f[1] * r[2] - f[2] * r[1], f[2] * r[0] - f[0] * r[2], f[0] * r[1] - f[1] * r[0]};
    double upl = sqrt(up[0] * up[0] + up[1] * up[1] + up[2] * up[2]);
    for (int i = 0; i < 3; i++)
        up[i] /= upl;
    if (!(s->settings.fov_ha > 0.0f && s->settings.fov_ha < 90.0f))
        return cam_err(s, s->source.line_fov, err, "camera_fov_ha must be strictly between 0 and 90 degrees");
    if (s->settings.width < 1 || s->settings.height < 1 || s->settings.width > RT_MAX_SIDE ||
        s->settings.height > RT_MAX_SIDE ||
        (uint64_t)s->settings.width * (uint64_t)s->settings.height > RT_MAX_PIXELS) {
        char msg[256];
        snprintf(msg, sizeof msg, "resolution %dx%d is outside 1x1 .. %dx%d (at most %llu pixels)", s->settings.width,
                 s->settings.height, RT_MAX_SIDE, RT_MAX_SIDE, (unsigned long long)RT_MAX_PIXELS);
        return cam_err(s, s->source.line_res, err, msg);
    }
    cam->pos = s->settings.camera_pos;
    cam->fwd = rt_v3((float)f[0], (float)f[1], (float)f[2]);
    cam->right = rt_v3((float)r[0], (float)r[1], (float)r[2]);
    cam->up = rt_v3((float)up[0], (float)up[1], (float)up[2]);
    cam->d = (float)((s->settings.height * 0.5) / tan(s->settings.fov_ha * (M_PI / 180.0)));
    cam->width = s->settings.width;
    cam->height = s->settings.height;
    return 0;
}

RtSceneView rt_scene_view(const RtScene *s, const RtAccel *a, const RtCamera *cam)
{
    RtSceneView v;
    memset(&v, 0, sizeof v);
    v.prims = a->prims;
    v.nprims = a->nprims;
    v.nodes = a->nnodes ? a->nodes : NULL;
    v.nnodes = a->nnodes;
    v.wide = a->nwide ? a->wide : NULL;
    v.nwide = a->nwide;
#define VIEW_ARRAY(T, name) v.name = s->name, v.n##name = s->n##name;
    RT_SCENE_ARRAYS(VIEW_ARRAY)
#undef VIEW_ARRAY
    v.cam = *cam;
    v.background = s->settings.background;
    v.ambient = s->settings.ambient;
    v.max_depth = s->settings.max_depth;
    return v;
}

void rt_scene_free(RtScene *s)
{
    if (s->source.cache_map) {
        munmap(s->source.cache_map, s->source.cache_len);
    } else {
#define FREE_ARRAY(T, name) free(s->name);
        RT_SCENE_ARRAYS(FREE_ARRAY)
#undef FREE_ARRAY
    }
    rt_scene_free_deps(s);
    memset(s, 0, sizeof *s);
}

void rt_scene_name(RtScene *s, const char *path)
{
    const char *b = strrchr(path, '/');
    b = b ? b + 1 : path;
    snprintf(s->source.name, sizeof s->source.name, "%s", b);
    char *dot = strrchr(s->source.name, '.');
    if (dot && dot != s->source.name)
        *dot = '\0';
    /* The name goes into a space-separated record line. */
    for (char *c = s->source.name; *c; c++)
        if (*c == ' ' || *c == '\t' || *c == '=')
            *c = '_';
    snprintf(s->source.path, sizeof s->source.path, "%s", path);
}

int64_t rt_now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

double rt_now_ms(void) { return (double)rt_now_ns() * 1e-6; }

int rt_current_cpu(void)
{
    return sched_getcpu();
}

void *rt_thread_cpu_mask(size_t *size, int *ncpu, int *known)
{
    const long conf = sysconf(_SC_NPROCESSORS_CONF);
    *ncpu = conf > CPU_SETSIZE ? (int)conf : CPU_SETSIZE;
    *size = CPU_ALLOC_SIZE(*ncpu);
    cpu_set_t *set = CPU_ALLOC(*ncpu);
    *known = 0;
    if (!set)
        return NULL;
    CPU_ZERO_S(*size, set);
    *known = sched_getaffinity(0, *size, set) == 0;
    if (!*known)
        CPU_ZERO_S(*size, set);
    return set;
}

int rt_team_cpus(int nthreads)
{
    size_t size;
    int ncpu, known, n = 0, failed = 0;
    cpu_set_t *all = rt_thread_cpu_mask(&size, &ncpu, &known);
#ifndef _OPENMP
    (void)nthreads;
#endif
    if (!all)
        return 0;
    CPU_ZERO_S(size, all);
    /* (each thread's own mask: libgomp binds each one, the caller too,
     * where OMP_PROC_BIND asks it to) */
#pragma omp parallel num_threads(nthreads) reduction(| : failed)
    {
        size_t sz;
        int nc, kn;
        cpu_set_t *mine = rt_thread_cpu_mask(&sz, &nc, &kn);
        if (mine && kn && sz == size) {
#pragma omp critical(rt_team_cpus)
            CPU_OR_S(size, all, all, mine);
        } else {
            failed = 1;
        }
        CPU_FREE(mine);
    }
    if (!failed)
        n = CPU_COUNT_S(size, all);
    CPU_FREE(all);
    return n;
}

void rt_cores_note(char *list, size_t size, int cpu)
{
    if (cpu < 0)
        return;
    /* parse, insert sorted unique, re-emit */
    int cpus[512], n = 0;
    const char *p = list;
    while (*p && n < 511) {
        cpus[n++] = atoi(p);
        p = strchr(p, ',');
        if (!p)
            break;
        p++;
    }
    for (int i = 0; i < n; i++)
        if (cpus[i] == cpu)
            return;
    int k = n;
    while (k > 0 && cpus[k - 1] > cpu) {
        cpus[k] = cpus[k - 1];
        k--;
    }
    cpus[k] = cpu;
    n++;
    size_t off = 0;
    list[0] = '\0';
    for (int i = 0; i < n && off + 12 < size; i++)
        off += (size_t)snprintf(list + off, size - off, i ? ",%d" : "%d", cpus[i]);
}

uint64_t rt_fnv1a64(const uint8_t *data, size_t len)
{
    uint64_t h = 0xcbf29ce484222325ull;
    for (size_t i = 0; i < len; i++) {
        h ^= data[i];
        h *= 0x100000001b3ull;
    }
    return h;
}

uint8_t rt_quantize_value(float c) { return rt_quantize(c); }

void rt_image_quantize(const float *rgbf, uint8_t *rgb, size_t npixels)
{
    for (size_t i = 0; i < 3 * npixels; i++)
        rgb[i] = rt_quantize(rgbf[i]);
}

double rt_calibrate_ms(void)
{
    /* A fixed workload shaped like traversal: dependent loads from a 64 KB
     * table (L1/L2), a data-dependent branch and float arithmetic. Its time
     * tracks how fast this core runs right now, so a benchmark can divide
     * its render time by it and compare runs made while a shared machine was
     * faster or slower (harness compare --metric render_ms/calib). */
    enum { N = 16384, ITERS = 4000000 }; /* short next to a render, long enough to time */
    static float table[N];
    uint32_t s = 12345u;
    for (int i = 0; i < N; i++) {
        s = s * 1664525u + 1013904223u;
        table[i] = (float)(s >> 8) * (1.0f / 16777216.0f);
    }
    double t0 = rt_now_ms();
    float acc = 0.0f;
    uint32_t idx = 0;
    for (int k = 0; k < ITERS; k++) {
        float v = table[idx];
        idx = (idx * 1103515245u + 12345u + (v > 0.5f ? 7u : 0u)) & (N - 1);
        acc = acc * 0.999f + v * v;
    }
    volatile float sink = acc;
    (void)sink;
    return rt_now_ms() - t0;
}

static int cmp_double(const void *a, const void *b)
{
    const double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : (x > y ? 1 : 0);
}

double rt_median(double *v, int n)
{
    qsort(v, (size_t)n, sizeof *v, cmp_double);
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

int rt_warmup_due(int warmup_runs, double warmup_ms, int done, double elapsed_ms)
{
    if (warmup_runs >= 0)
        return done < warmup_runs;
    return warmup_ms >= 0.0 && (done == 0 || elapsed_ms < warmup_ms);
}

int rt_open_regular(const char *path, struct stat *st, RtError *err)
{
    /* O_NONBLOCK: opening a FIFO for reading would wait for a writer forever;
     * opened this way it is refused below like any other non-regular file. */
    const int fd = open(path, O_RDONLY | O_NONBLOCK | O_CLOEXEC);
    if (fd < 0)
        return rt_fail(err, "%s: cannot open: %s", path, strerror(errno));
    if (fstat(fd, st) != 0 || !S_ISREG(st->st_mode)) {
        close(fd);
        return rt_fail(err, "%s: not a regular file", path);
    }
    return fd;
}

int rt_parse_int(const char *s, long lo, long hi, int *out)
{
    char *end;
    errno = 0;
    const long v = strtol(s, &end, 10);
    if (errno || end == s || *end != '\0' || v < lo || v > hi)
        return -1;
    *out = (int)v;
    return 0;
}

int rt_parse_wxh(const char *s, int maxside, int *w, int *h)
{
    char buf[64];
    if (strlen(s) >= sizeof buf) /* never judge a truncated copy */
        return -1;
    snprintf(buf, sizeof buf, "%s", s);
    char *x = strchr(buf, 'x');
    if (!x)
        x = strchr(buf, 'X');
    if (!x)
        return -1;
    *x = '\0';
    if (rt_parse_int(buf, 1, maxside, w) != 0 || rt_parse_int(x + 1, 1, maxside, h) != 0)
        return -1;
    return 0;
}

int rt_thread_count(int asked)
{
#ifdef _OPENMP
    return asked > 0 ? asked : omp_get_max_threads();
#else
    (void)asked;
    return 1;
#endif
}

int rt_stream_threads(void)
{
    const int n = rt_thread_count(0);
    return n < RT_STREAM_THREADS ? n : RT_STREAM_THREADS;
}

/* The first i in 0..n for which bad(ctx, i), or -1: in parallel (a
 * scene cache entry of millions of triangles is checked on every load). */
static long first_bad(long n, int (*bad)(const void *, const void *, long), const void *s, const void *a)
{
    long first = LONG_MAX;
#pragma omp parallel for reduction(min : first) schedule(static) num_threads(rt_stream_threads())
    for (long i = 0; i < n; i++)
        if (i < first && bad(s, a, i))
            first = i;
    return first == LONG_MAX ? -1 : first;
}

static int bad_triangle(const void *sp, const void *ap, long i)
{
    const RtScene *s = sp;
    (void)ap;
    const RtTriangle *t = &s->triangles[i];
    const int smooth = t->n[0] >= 0;
    for (int k = 0; k < 3; k++)
        if (t->v[k] >= s->nvertices || (smooth && (t->n[k] < 0 || (uint32_t)t->n[k] >= s->nnormals)))
            return 1;
    return t->material >= s->nmaterials;
}

/* A primitive record whose id is out of range or whose sphere bit is not
 * set exactly for the spheres (the shading follows it into either array). */
static int bad_prim(const void *sp, const void *ap, long i)
{
    const RtScene *s = sp;
    const RtAccel *a = ap;
    const uint32_t id = a->prims[i].id, gid = id & ~RT_PRIM_SPHERE_BIT;
    return gid >= (uint64_t)s->nspheres + s->ntriangles || !(id & RT_PRIM_SPHERE_BIT) != (gid >= s->nspheres);
}

/* Whether the primitive records name the scene's primitives. */
static int check_prims(const RtScene *s, const RtAccel *a, RtError *err)
{
    const uint64_t nscene = (uint64_t)s->nspheres + s->ntriangles;
    if (a->nsplit > a->nprims || (uint64_t)(a->nprims - a->nsplit) != nscene)
        return rt_fail(err, "%u primitive records (%u split copies) for %llu primitives", a->nprims, a->nsplit,
                       (unsigned long long)nscene);
    if (a->kind == RT_ACCEL_NONE && (a->nsplit || a->nnodes || a->nwide))
        return rt_fail(err, "a brute-force accelerator with a tree");
    if (a->kind == RT_ACCEL_BVH && a->nprims && (!a->nodes || !a->nnodes))
        return rt_fail(err, "a BVH without nodes");
    const long i = first_bad(a->nprims, bad_prim, s, a);
    if (i >= 0)
        return rt_fail(err, "primitive record %ld names primitive %u (sphere bit %u)", i,
                       a->prims[i].id & ~RT_PRIM_SPHERE_BIT, !!(a->prims[i].id & RT_PRIM_SPHERE_BIT));
    return 0;
}

int rt_scene_check(const RtScene *s, const RtAccel *a, RtError *err)
{
    if (s->settings.max_depth < 0 || s->settings.max_depth > RT_MAX_DEPTH)
        return rt_fail(err, "max_depth %d outside 0..%d", s->settings.max_depth, RT_MAX_DEPTH);
    const long t = first_bad(s->ntriangles, bad_triangle, s, NULL);
    if (t >= 0)
        return rt_fail(err, "triangle %ld: vertex, normal or material index out of range", t);
    for (uint32_t i = 0; i < s->nspheres; i++)
        if (s->spheres[i].material >= s->nmaterials || !(s->spheres[i].r > 0.0f))
            return rt_fail(err, "sphere %u: material %u of %u, radius %g", i, s->spheres[i].material, s->nmaterials,
                           (double)s->spheres[i].r);
    for (uint32_t i = 0; i < s->nlights; i++)
        if (s->lights[i].type != RT_LIGHT_POINT && s->lights[i].type != RT_LIGHT_DIRECTIONAL &&
            s->lights[i].type != RT_LIGHT_SPOT)
            return rt_fail(err, "light %u: unknown type %d", i, s->lights[i].type);
    return a ? check_prims(s, a, err) : 0;
}
