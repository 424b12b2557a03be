/* scene_chunks.c - a large scene file parsed on several threads
 * (parse_chunks, scene_parse.h), with the serial parser's result: the
 * scene, the warnings and the first error byte for byte
 * (tests/unit/test_parse_threads.c).
 *
 * Pass 1, per chunk of lines: vertex and normal lines into the chunk's
 * pools, triangle and sphere lines into records that remember what the
 * serial parser would have known there (the chunk's vertices, normals and
 * deferred lines so far), every other line deferred; a chunk stops at its
 * first error. Pass 2, in file order: each chunk's pools, then its records
 * and deferred lines in their order, so materials, index checks, warnings
 * and the first error come out as the serial parser's. Of that pass only
 * the order is serial: the pools are copied to their places and each
 * chunk's first triangle with a bad index is found before it (in
 * parallel), the triangles before it are given slots and a material in
 * runs, and the runs are written after it (in parallel); from a bad
 * triangle on, parse_add_triangle reports it. A sink (rt.h's RtGeomSink)
 * is handed each chunk's vertices once placed and each run of triangles
 * once written: a backend copies them to its device while the rest is
 * parsed. */
#include <stdlib.h>
#include <string.h>

#include "pool.h"
#include "scene_parse.h"

typedef struct TriRec {
    uint32_t v[3], n[3];
    uint32_t nv, nn;    /* the chunk's vertices and normals before it */
    uint32_t deferred;  /* the chunk's deferred lines before it */
    int32_t line;       /* negative: a normal_triangle on line -line */
} TriRec;

typedef struct SphRec {
    float f[4];
    uint32_t deferred;
} SphRec;

typedef struct Chunk {
    size_t begin, end;  /* bytes */
    int line0;          /* lines before the chunk: 0 in pass 1, whose lines count from the
                         * chunk's start (records and deferred lines keep those), then set */
    int nlines;         /* the lines pass 1 read */
    RtVec3 *verts, *norms;
    uint32_t nv, nn, cap_v, cap_n;
    TriRec *tris;
    uint32_t nt, cap_t;
    SphRec *sphs;
    uint32_t ns, cap_s;
    struct Deferred {
        size_t pos;     /* the line's first byte */
        int line;
    } *defs;            /* the lines pass 2 runs through parse_line */
    uint32_t nd, cap_d;
    int failed;         /* pass 1 stopped at an error (err) after its records */
    int has_mesh;       /* a mesh: line (its vertices come between the chunk's): parse serially */
    RtError err;
} Chunk;

/* Room for one more element in a chunk's array (grow, with its limits and messages). */
#define CHUNK_GROW(c, arr, n, cap, what) parse_grow(p, (void **)&(c)->arr, &(c)->cap, (c)->n, sizeof *(c)->arr, (what))

/* One line of pass 1; -1 stops the chunk (p->err holds the message). */
static int chunk_line(Parser *p, Chunk *c, char *line, size_t at)
{
    char *cmd = NULL, *v = NULL;
    const int rc = parse_split(p, line, &cmd, &v);
    if (rc != 0)
        return rc < 0 ? -1 : 0;
    float f[4];
    if (strcmp(cmd, "vertex") == 0 || strcmp(cmd, "normal") == 0) {
        if (lex_floats(p, cmd, v, f, 3) != 0)
            return -1;
        if (cmd[0] == 'v' ? CHUNK_GROW(c, verts, nv, cap_v, "vertices") : CHUNK_GROW(c, norms, nn, cap_n, "normals"))
            return -1;
        if (cmd[0] == 'v')
            c->verts[c->nv++] = v3f(f);
        else
            c->norms[c->nn++] = v3f(f);
    } else if (strcmp(cmd, "triangle") == 0 || strcmp(cmd, "normal_triangle") == 0) {
        int64_t ix[6];
        const int nt = cmd[0] == 'n';
        if (lex_indices(p, cmd, v, ix, nt ? 6 : 3) != 0)
            return -1;
        if (CHUNK_GROW(c, tris, nt, cap_t, "triangles"))
            return -1;
        TriRec *t = &c->tris[c->nt++];
        for (int i = 0; i < 3; i++) {
            t->v[i] = (uint32_t)ix[i];
            t->n[i] = nt ? (uint32_t)ix[3 + i] : 0;
        }
        t->nv = c->nv;
        t->nn = c->nn;
        t->deferred = c->nd;
        t->line = nt ? -p->line : p->line;
    } else if (strcmp(cmd, "sphere") == 0) {
        if (parse_sphere_values(p, v, f) != 0 || CHUNK_GROW(c, sphs, ns, cap_s, "spheres"))
            return -1;
        memcpy(c->sphs[c->ns].f, f, sizeof f);
        c->sphs[c->ns++].deferred = c->nd;
    } else {
        c->has_mesh |= strcmp(cmd, "mesh") == 0;
        if (CHUNK_GROW(c, defs, nd, cap_d, "lines"))
            return -1;
        c->defs[c->nd].pos = at;
        c->defs[c->nd++].line = p->line;
    }
    return 0;
}
/* Pass 1 over one chunk. */
static void chunk_parse(const Parser *p0, Chunk *c, const char *buf)
{
    Parser p = *p0;
    p.err = &c->err;
    p.warn = NULL;
    p.line = c->line0;
    char *line = malloc(RT_MAX_LINE + 1);
    if (!line) {
        c->failed = 1;
        rt_fail(&c->err, "%s: out of memory", p.file);
        return;
    }
    size_t pos = c->begin;
    while (pos < c->end && !c->failed) {
        const size_t at = pos;
        p.line++;
        c->failed = parse_next_line(&p, buf, c->end, &pos, line) != 0 || chunk_line(&p, c, line, at) != 0;
    }
    c->nlines = p.line - c->line0;
    free(line);
}

/* A run of a chunk's triangles that pass 2 placed without writing them:
 * their slots from `out` on, their material, and the pools' sizes before
 * the chunk (the records' indices were checked before, in parallel). */
typedef struct TriRun {
    const TriRec *t;
    uint32_t n, out, material;
} TriRun;

typedef struct Pass2 {
    TriRun *runs;
    uint32_t nruns, cap;
} Pass2;

/* The first of chunk c's triangles whose indices fail parse_add_triangle's checks
 * against the nv0 vertices and nn0 normals before the chunk (c->nt: none). */
static uint32_t chunk_first_bad(const Chunk *c, uint32_t nv0, uint32_t nn0)
{
    for (uint32_t k = 0; k < c->nt; k++) {
        const TriRec *t = &c->tris[k];
        const uint64_t nv = (uint64_t)nv0 + t->nv, nn = (uint64_t)nn0 + t->nn;
        int bad = t->v[0] >= nv || t->v[1] >= nv || t->v[2] >= nv;
        if (t->line < 0)
            bad |= t->n[0] >= nn || t->n[1] >= nn || t->n[2] >= nn;
        if (bad)
            return k;
    }
    return c->nt;
}

/* The end of the chunk's triangles from `from` on that come before its
 * deferred line j: galloping, then bisection, over the records' ordered
 * `deferred` counts (a scan of every record here was pass 2's serial
 * cost: 44-62 ms of 3.57M triangles). */
static uint32_t run_end(const Chunk *c, uint32_t from, uint32_t j)
{
    uint32_t lo = from, step = 1;
    while (lo < c->nt && c->tris[lo].deferred == j) { /* [from, lo] all before line j */
        const uint32_t next = step < c->nt - lo ? lo + step : c->nt;
        if (next == c->nt || c->tris[next].deferred != j) {
            uint32_t hi = next; /* the end lies in (lo, hi] */
            while (hi - lo > 1) {
                const uint32_t mid = lo + (hi - lo) / 2;
                if (c->tris[mid].deferred == j)
                    lo = mid;
                else
                    hi = mid;
            }
            return hi;
        }
        lo = next;
        step *= 2;
    }
    return lo;
}

/* Pass 2 for a chunk's triangles and spheres before its deferred line j:
 * triangles before the chunk's first bad one (bad) are placed as one run,
 * written later (pass2_fill); from the bad one on they go through
 * parse_add_triangle, which stops at it with the serial parser's message. */
static int chunk_prims(Parser *p, const Chunk *c, uint32_t j, uint32_t *ti, uint32_t *si, uint32_t nv0, uint32_t nn0,
                       uint32_t bad, Pass2 *q)
{
    const uint32_t end = run_end(c, *ti, j);
    const uint32_t good = end < bad ? end : bad;
    if (good > *ti) {
        RtScene *sc = p->s;
        if (q->nruns == q->cap && parse_grow(p, (void **)&q->runs, &q->cap, q->nruns, sizeof *q->runs, "lines") != 0)
            return -1;
        if ((uint64_t)sc->ntriangles + (good - *ti) > sc->cap_triangles) /* (reserve_all sized them) */
            return parse_fail(p, "internal error: triangle pool too small");
        q->runs[q->nruns++] = (TriRun){&c->tris[*ti], good - *ti, sc->ntriangles, p->material};
        sc->ntriangles += good - *ti;
        *ti = good;
    }
    for (; *ti < end; (*ti)++) {
        const TriRec *t = &c->tris[*ti];
        const int normals = t->line < 0;
        const int64_t ix[6] = {t->v[0], t->v[1], t->v[2], t->n[0], t->n[1], t->n[2]};
        p->line = (normals ? -t->line : t->line) + c->line0;
        if (parse_add_triangle(p, normals ? "normal_triangle" : "triangle", ix, normals, nv0 + t->nv, nn0 + t->nn) != 0)
            return -1;
    }
    for (; *si < c->ns && c->sphs[*si].deferred == j; (*si)++)
        if (parse_add_sphere(p, c->sphs[*si].f) != 0)
            return -1;
    return 0;
}

/* Pass 2's parallel part for one chunk reached (its pools' places in the
 * scene's known from the chunks before it): its first triangle with a bad
 * index, and its vertices and normals copied to their places. */
static uint32_t chunk_place(RtScene *sc, const Chunk *c, uint32_t nv0, uint32_t nn0)
{
    memcpy(sc->vertices + nv0, c->verts, (size_t)c->nv * sizeof *c->verts);
    memcpy(sc->normals + nn0, c->norms, (size_t)c->nn * sizeof *c->norms);
    return chunk_first_bad(c, nv0, nn0);
}

/* Pass 2 for one chunk, in file order. */
static int chunk_merge(Parser *p, const Chunk *c, const uint32_t at[2], const char *buf, char *line, uint32_t bad,
                       Pass2 *q)
{
    RtScene *sc = p->s;
    const uint32_t nv0 = sc->nvertices, nn0 = sc->nnormals;
    if (nv0 != at[0] || nn0 != at[1]) /* (chunk_place put the pools there; only mesh: lines move them) */
        return parse_fail(p, "internal error: a chunk's pools out of place");
    sc->nvertices += c->nv;
    sc->nnormals += c->nn;
    uint32_t ti = 0, si = 0;
    for (uint32_t j = 0; j <= c->nd; j++) {
        if (chunk_prims(p, c, j, &ti, &si, nv0, nn0, bad, q) != 0)
            return -1;
        if (j == c->nd)
            break;
        size_t pos = c->defs[j].pos;
        p->line = c->defs[j].line + c->line0;
        if (parse_next_line(p, buf, c->end, &pos, line) != 0 || parse_line(p, line) != 0)
            return -1;
    }
    if (c->failed) { /* the chunk's first error, after everything before it */
        *p->err = c->err;
        return -1;
    }
    return 0;
}

/* The parse's loops over chunks and runs, on the pool (each index one
 * claim, as OpenMP's schedule(dynamic, 1)). */
typedef struct ChunkJob {
    Parser *p;
    Chunk *c;
    const char *buf;
    uint32_t *bad, *nv0;
    const Pass2 *q;
} ChunkJob;

/* A placed run written: the records parse_add_triangle writes, the run
 * handed to the sink once written. */
static void fill_run(void *ctx, int r)
{
    const ChunkJob *j = ctx;
    RtScene *sc = j->p->s;
    const TriRun *run = &j->q->runs[r];
    for (uint32_t k = 0; k < run->n; k++) {
        const TriRec *t = &run->t[k];
        const int64_t ix[6] = {t->v[0], t->v[1], t->v[2], t->n[0], t->n[1], t->n[2]};
        parse_set_triangle(&sc->triangles[run->out + k], ix, t->line < 0, run->material);
    }
    if (j->p->sink)
        j->p->sink->ready(j->p->sink->ctx, RT_GEOM_TRIANGLES, run->out, run->n);
}

static void parse_one(void *ctx, int i)
{
    const ChunkJob *j = ctx;
    chunk_parse(j->p, &j->c[i], j->buf);
}

static void place_one(void *ctx, int i)
{
    const ChunkJob *j = ctx;
    j->bad[i] = chunk_place(j->p->s, &j->c[i], j->nv0[2 * i], j->nv0[2 * i + 1]);
    if (j->p->sink && j->c[i].nv)
        j->p->sink->ready(j->p->sink->ctx, RT_GEOM_VERTICES, j->nv0[2 * i], j->c[i].nv);
}

/* Chunks at line starts, about RT_PARSE_CHUNK bytes each. (Their lines are
 * counted by pass 1, which reads them anyway: a pass of its own over the
 * file to count them took 7-11 ms of 355 MB on 16 threads.) */
static int chunk_split(const char *buf, size_t len, Chunk **out)
{
    int n = (int)(len / RT_PARSE_CHUNK) + 1;
    Chunk *c = calloc((size_t)n, sizeof *c);
    if (!c)
        return -1;
    size_t at = 0;
    for (int i = 0; i < n; i++) {
        c[i].begin = at;
        size_t e = (size_t)(i + 1) * RT_PARSE_CHUNK;
        if (i == n - 1 || e >= len) {
            e = len;
        } else {
            const char *nl = memchr(buf + e, '\n', len - e);
            e = nl ? (size_t)(nl - buf) + 1 : len;
        }
        c[i].end = at = e;
    }
    *out = c;
    return n;
}

static void chunk_pools_free(Chunk *c)
{
    free(c->verts);
    free(c->norms);
    free(c->tris);
    free(c->sphs);
    free(c->defs);
}

/* The lines before each chunk up to `reached`, once pass 1 has counted
 * them; the first failed chunk (at `reached` - 1 when `failed`) parsed
 * again from its true first line for its error's line number. */
static void chunk_lines(const Parser *p, Chunk *c, int reached, int failed, const char *buf)
{
    for (int i = 1; i < reached; i++)
        c[i].line0 = c[i - 1].line0 + c[i - 1].nlines;
    if (!failed)
        return;
    Chunk *f = &c[reached - 1], again;
    memset(&again, 0, sizeof again);
    again.begin = f->begin;
    again.end = f->end;
    again.line0 = f->line0;
    chunk_parse(p, &again, buf);
    if (again.failed)
        f->err = again.err;
    chunk_pools_free(&again);
}

static void chunks_free(Chunk *c, int n)
{
    for (int i = 0; i < n; i++)
        chunk_pools_free(&c[i]);
    free(c);
}

/* The scene's pools sized for every chunk's records at once. */
static int reserve_all(Parser *p, const Chunk *c, int n)
{
    uint64_t nv = 0, nn = 0, nt = 0, ns = 0;
    for (int i = 0; i < n; i++) {
        nv += c[i].nv;
        nn += c[i].nn;
        nt += c[i].nt;
        ns += c[i].ns;
    }
    RtScene *sc = p->s;
    if (nv > RT_MAX_POOL || nn > RT_MAX_POOL || nt > RT_MAX_POOL || ns > RT_MAX_POOL)
        return rt_fail(p->err, "%s: more than %u vertices, normals, triangles or spheres", p->file, RT_MAX_POOL);
    /* (in 2 MiB pages: fewer faults while the chunks fill them, and the GPU
     * build locks 121 MB of them for its copy in 61 pages, not 31,000) */
    sc->vertices = rt_huge_alloc((size_t)(nv ? nv : 1) * sizeof *sc->vertices);
    sc->normals = rt_huge_alloc((size_t)(nn ? nn : 1) * sizeof *sc->normals);
    sc->triangles = rt_huge_alloc((size_t)(nt ? nt : 1) * sizeof *sc->triangles);
    sc->spheres = rt_huge_alloc((size_t)(ns ? ns : 1) * sizeof *sc->spheres);
    if (!sc->vertices || !sc->normals || !sc->triangles || !sc->spheres)
        return rt_fail(p->err, "%s: out of memory for the scene's pools", p->file);
    sc->cap_vertices = (uint32_t)(nv ? nv : 1);
    sc->cap_normals = (uint32_t)(nn ? nn : 1);
    sc->cap_triangles = (uint32_t)(nt ? nt : 1);
    sc->cap_spheres = (uint32_t)(ns ? ns : 1);
    return 0;
}

int parse_chunks(Parser *p, const char *buf, size_t len, int nt)
{
    Chunk *c = NULL;
    const int n = chunk_split(buf, len, &c);
    if (n < 0)
        return rt_fail(p->err, "%s: out of memory", p->file);
    RtPool *pool = pool_start(nt < n ? nt : n);
    ChunkJob job = {p, c, buf, NULL, NULL, NULL};
    pool_for(pool, n, parse_one, &job);
    for (int i = 0; i < n; i++)
        if (c[i].has_mesh) { /* a model's vertices go between the file's: one pass in order */
            pool_stop(pool);
            chunks_free(c, n);
            return parse_serial(p, buf, len);
        }
    /* pools sized for every chunk up to the first that failed (the rest is never reached) */
    int upto = 0;
    while (upto < n && !c[upto].failed)
        upto++;
    const int reached = upto < n ? upto + 1 : n;
    chunk_lines(p, c, reached, upto < n, buf);
    uint32_t *bad = malloc((size_t)n * sizeof *bad), *nv0 = malloc((size_t)n * 2 * sizeof *nv0);
    char *line = malloc(RT_MAX_LINE + 1);
    Pass2 q = {NULL, 0, 0};
    int rc = line && bad && nv0 ? reserve_all(p, c, reached) : rt_fail(p->err, "%s: out of memory", p->file);
    if (rc == 0) {
        for (int i = 0; i < n; i++) {
            nv0[2 * i] = i ? nv0[2 * i - 2] + c[i - 1].nv : p->s->nvertices;
            nv0[2 * i + 1] = i ? nv0[2 * i - 1] + c[i - 1].nn : p->s->nnormals;
        }
        if (p->sink)
            p->sink->sized(p->sink->ctx, p->s);
        job.bad = bad;
        job.nv0 = nv0;
        pool_for(pool, reached, place_one, &job);
    }
    for (int i = 0; i < reached && rc == 0; i++)
        rc = chunk_merge(p, &c[i], &nv0[2 * i], buf, line, bad[i], &q);
    /* (also after an error: the runs placed before it, as the serial parser
     * left them) */
    job.q = &q;
    pool_for(pool, (int)q.nruns, fill_run, &job);
    pool_stop(pool);
    free(q.runs);
    free(line);
    free(bad);
    free(nv0);
    chunks_free(c, n);
    return rc;
}
