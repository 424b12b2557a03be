/* scene_parse.c - the course scene format (docs/scene-format.md).
 *
 * The whole file is read into memory and parsed in place, one line at a time.
 * Numbers go through a fast decimal path (exact for up to 19 significant
 * digits and powers of ten up to 1e22, Clinger 1990) with strtof as the
 * fallback, which is what makes the 500 KB dragon parse in a few ms.
 * Every error names file and line and leaves the scene freeable.
 *
 * Large files are mapped and parsed in two passes (parse_chunks below):
 * chunks of lines in parallel turn vertex, normal, triangle and sphere lines
 * into records, then one pass in file order gives each primitive its
 * material and slot and runs every other line as the serial parser does;
 * the triangles' index checks before it and their records after it run in
 * parallel again. The scene, the warnings and the first error are the
 * serial parser's, byte for byte (tests/unit/test_parse_threads.c). */
#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include "rt.h"

/* Longest line accepted; longer is an error, not a silent truncation. */
#define RT_MAX_LINE 65536
/* Pool sizes beyond this are refused (indices must fit 31 bits). */
#define RT_MAX_POOL 0x7fffffffu

typedef struct Parser {
    const char *file;
    int line;
    RtScene *s;
    RtError *err;
    RtWarnFn warn;
    void *warn_ctx;
    uint32_t material; /* index of the current material */
} Parser;

static int perr(Parser *p, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;
static int perr(Parser *p, const char *fmt, ...)
{
    char msg[768];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    if (p->line > 0)
        return rt_fail(p->err, "%s:%d: %s", p->file, p->line, msg);
    return rt_fail(p->err, "%s: %s", p->file, msg);
}

/* Grows a pool to hold one more element. */
static int grow(Parser *p, void **arr, uint32_t *cap, uint32_t n, size_t elem, const char *what)
{
    if (n < *cap)
        return 0;
    if (n >= RT_MAX_POOL)
        return perr(p, "too many %s (limit %u)", what, RT_MAX_POOL);
    uint64_t nc = *cap ? (uint64_t)*cap * 2 : 64;
    if (nc > RT_MAX_POOL)
        nc = RT_MAX_POOL;
    void *na = realloc(*arr, (size_t)nc * elem);
    if (!na)
        return perr(p, "out of memory growing %s to %llu entries", what, (unsigned long long)nc);
    *arr = na;
    *cap = (uint32_t)nc;
    return 0;
}
#define GROW(p, field, what) \
    grow((p), (void **)&(p)->s->field, &(p)->s->cap_##field, (p)->s->n##field, sizeof(*(p)->s->field), (what))

static const double pow10_tab[23] = {1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,  1e7,  1e8,  1e9,  1e10, 1e11,
                                     1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22};

/* Parses one number at *pp; the token ends at whitespace or end of string.
 * Returns 0 and advances, or -1 when the token is not a finite number. */
static int parse_float(const char **pp, float *out)
{
    const char *s = *pp, *start = s;
    int neg = 0;
    if (*s == '+' || *s == '-')
        neg = *s++ == '-';
    uint64_t mant = 0;
    int digits = 0, frac = 0, any = 0;
    while (*s >= '0' && *s <= '9') {
        if (digits < 19) { mant = mant * 10 + (uint64_t)(*s - '0'); if (mant) digits++; }
        else frac--; /* dropped integer digit: shift exponent */
        s++; any = 1;
    }
    if (*s == '.') {
        s++;
        while (*s >= '0' && *s <= '9') {
            if (digits < 19) { mant = mant * 10 + (uint64_t)(*s - '0'); if (mant) digits++; frac++; }
            s++; any = 1;
        }
    }
    int exp10 = 0, fast = any && digits < 19;
    if (any && (*s == 'e' || *s == 'E')) {
        const char *e = s + 1;
        int eneg = 0, ev = 0, edig = 0;
        if (*e == '+' || *e == '-')
            eneg = *e++ == '-';
        while (*e >= '0' && *e <= '9') {
            if (ev < 10000) ev = ev * 10 + (*e - '0');
            e++; edig = 1;
        }
        if (!edig)
            return -1;
        exp10 = eneg ? -ev : ev;
        s = e;
    }
    if (fast && (*s == '\0' || *s == ' ' || *s == '\t')) {
        int e = exp10 - frac;
        double v = (double)mant;
        if (mant == 0) {
            *out = neg ? -0.0f : 0.0f;
            *pp = s;
            return 0;
        }
        if (e >= -22 && e <= 22 && mant < (1ull << 53)) {
            v = e >= 0 ? v * pow10_tab[e] : v / pow10_tab[-e];
            float f = (float)(neg ? -v : v);
            if (!isfinite(f))
                return -1;
            *out = f;
            *pp = s;
            return 0;
        }
    }
    /* Slow path: anything else strtof accepts (hex floats, many digits). */
    char *end;
    errno = 0;
    float f = strtof(start, &end);
    if (end == start || (*end != '\0' && *end != ' ' && *end != '\t') || !isfinite(f))
        return -1;
    if (errno == ERANGE && f != 0.0f)
        return -1;
    *out = f;
    *pp = end;
    return 0;
}

static const char *skip_ws(const char *s)
{
    while (*s == ' ' || *s == '\t')
        s++;
    return s;
}

/* After n values: anything left on the line is an error that counts it. */
static int expect_end(Parser *p, const char *cmd, const char *s, int n)
{
    int extra = 0;
    while (*s) {
        while (*s && *s != ' ' && *s != '\t')
            s++;
        s = skip_ws(s);
        extra++;
    }
    if (extra)
        return perr(p, "%s: expected %d values, got %d", cmd, n, n + extra);
    return 0;
}

/* Reads exactly n numbers from the value text. */
static int get_floats(Parser *p, const char *cmd, const char *v, float *out, int n)
{
    const char *s = skip_ws(v);
    for (int i = 0; i < n; i++) {
        if (*s == '\0')
            return perr(p, "%s: expected %d values, got %d", cmd, n, i);
        const char *tok = s;
        if (parse_float(&s, &out[i]) != 0) {
            int len = 0;
            while (tok[len] && tok[len] != ' ' && tok[len] != '\t' && len < 40)
                len++;
            return perr(p, "%s: value %d is not a finite number: '%.*s'", cmd, i + 1, len, tok);
        }
        s = skip_ws(s);
    }
    return expect_end(p, cmd, s, n);
}

/* Reads n non-negative integer indices (also written as 3.0 by exporters).
 * Parsed in double (or as plain digits), never through float: a float holds
 * integers exactly only up to 2^24, and vertex pools may be larger. */
static int get_indices(Parser *p, const char *cmd, const char *v, int64_t *out, int n)
{
    const char *s = skip_ws(v);
    for (int i = 0; i < n; i++) {
        if (*s == '\0')
            return perr(p, "%s: expected %d values, got %d", cmd, n, i);
        const char *tok = s;
        int len = 0;
        while (tok[len] && tok[len] != ' ' && tok[len] != '\t')
            len++;
        double d = 0.0;
        int digits = len > 0 && len <= 10;
        for (int k = 0; digits && k < len; k++) {
            if (tok[k] < '0' || tok[k] > '9')
                digits = 0;
            else
                d = d * 10.0 + (double)(tok[k] - '0'); /* exact: < 2^53 */
        }
        char *end = (char *)tok + len;
        errno = 0;
        if (!digits) /* the common plain-digit case skips strtod */
            d = strtod(tok, &end);
        if (end != tok + len || errno == ERANGE || !isfinite(d))
            return perr(p, "%s: value %d is not a finite number: '%.*s'", cmd, i + 1, len < 40 ? len : 40, tok);
        if (d != floor(d))
            return perr(p, "%s: index %d is not an integer: %.*s", cmd, i + 1, len < 40 ? len : 40, tok);
        if (d < 0.0)
            return perr(p, "%s: index %d is negative: %.*s", cmd, i + 1, len < 40 ? len : 40, tok);
        if (d > 4294967295.0)
            return perr(p, "%s: index %d is out of range: %.*s", cmd, i + 1, len < 40 ? len : 40, tok);
        out[i] = (int64_t)d;
        s = skip_ws(tok + len);
    }
    return expect_end(p, cmd, s, n);
}

static int check_index(Parser *p, const char *cmd, int64_t idx, uint32_t n, const char *pool)
{
    if (idx >= (int64_t)n)
        return perr(p, "%s: %s index %lld out of range (%u %s defined so far)", cmd, pool, (long long)idx, n,
                    pool);
    return 0;
}

static RtVec3 v3f(const float *f) { return rt_v3(f[0], f[1], f[2]); }

static int cmd_output(Parser *p, const char *v)
{
    const char *s = skip_ws(v);
    size_t n = strlen(s);
    while (n && (s[n - 1] == ' ' || s[n - 1] == '\t'))
        n--;
    if (n >= 2 && ((s[0] == '"' && s[n - 1] == '"') || (s[0] == '\'' && s[n - 1] == '\''))) {
        s++;
        n -= 2;
    }
    if (n == 0)
        return perr(p, "output_image: expected a file name");
    if (n >= sizeof p->s->output)
        return perr(p, "output_image: name longer than %zu bytes", sizeof p->s->output - 1);
    memcpy(p->s->output, s, n);
    p->s->output[n] = '\0';
    p->s->line_output = p->line;
    return 0;
}

static int cmd_resolution(Parser *p, const char *v)
{
    float f[2];
    if (get_floats(p, "film_resolution", v, f, 2) != 0)
        return -1;
    for (int i = 0; i < 2; i++)
        if (f[i] != floorf(f[i]) || f[i] < 1.0f)
            return perr(p, "film_resolution: %s must be a positive integer, got %g", i ? "height" : "width",
                        (double)f[i]);
    if (f[0] > RT_MAX_SIDE || f[1] > RT_MAX_SIDE || (double)f[0] * (double)f[1] > (double)RT_MAX_PIXELS)
        return perr(p, "film_resolution %.0fx%.0f would need %.1f GiB of image memory (limit %dx%d, %llu pixels)",
                    (double)f[0], (double)f[1], (double)f[0] * (double)f[1] * 15.0 / (1024.0 * 1024.0 * 1024.0),
                    RT_MAX_SIDE, RT_MAX_SIDE, (unsigned long long)RT_MAX_PIXELS);
    p->s->width = (int32_t)f[0];
    p->s->height = (int32_t)f[1];
    p->s->line_res = p->line;
    return 0;
}

static int cmd_material(Parser *p, const char *v)
{
    float f[14];
    if (get_floats(p, "material", v, f, 14) != 0)
        return -1;
    for (int i = 0; i < 9; i++)
        if (f[i] < 0.0f)
            return perr(p, "material: value %d is negative (%g); reflectances must be >= 0", i + 1, (double)f[i]);
    if (f[9] < 0.0f)
        return perr(p, "material: Phong exponent ns is negative (%g)", (double)f[9]);
    for (int i = 10; i < 13; i++)
        if (f[i] < 0.0f)
            return perr(p, "material: value %d is negative (%g); transmission must be >= 0", i + 1, (double)f[i]);
    /* The course's tools write ior 0 for opaque materials: the index only
     * matters where light is transmitted (RENDERING-RULES: kt != 0). */
    const int transmissive = f[10] > 0.0f || f[11] > 0.0f || f[12] > 0.0f;
    if (transmissive && !(f[13] > 0.0f))
        return perr(p, "material: index of refraction must be positive for a transmissive material (kt > 0), got %g",
                    (double)f[13]);
    if (GROW(p, materials, "materials") != 0)
        return -1;
    RtMaterial *m = &p->s->materials[p->s->nmaterials];
    memcpy(m->ka, f, 3 * sizeof(float));
    memcpy(m->kd, f + 3, 3 * sizeof(float));
    memcpy(m->ks, f + 6, 3 * sizeof(float));
    m->ns = f[9];
    memcpy(m->kt, f + 10, 3 * sizeof(float));
    m->ior = f[13];
    p->material = p->s->nmaterials++;
    return 0;
}

static int add_light(Parser *p, const RtLight *l)
{
    if (GROW(p, lights, "lights") != 0)
        return -1;
    p->s->lights[p->s->nlights++] = *l;
    return 0;
}

static int cmd_light(Parser *p, const char *cmd, const char *v)
{
    float f[11];
    RtLight l;
    memset(&l, 0, sizeof l);
    if (strcmp(cmd, "point_light") == 0) {
        if (get_floats(p, cmd, v, f, 6) != 0)
            return -1;
        l.type = RT_LIGHT_POINT;
        memcpy(l.pos, f + 3, 3 * sizeof(float));
    } else if (strcmp(cmd, "directional_light") == 0) {
        if (get_floats(p, cmd, v, f, 6) != 0)
            return -1;
        RtVec3 d = v3f(f + 3);
        if (rt_is_zero(d))
            return perr(p, "directional_light: direction is the zero vector");
        d = rt_normalize(d);
        l.type = RT_LIGHT_DIRECTIONAL;
        l.dir[0] = d.x; l.dir[1] = d.y; l.dir[2] = d.z;
    } else {
        if (get_floats(p, cmd, v, f, 11) != 0)
            return -1;
        RtVec3 d = v3f(f + 6);
        if (rt_is_zero(d))
            return perr(p, "spot_light: axis direction is the zero vector");
        if (f[9] < 0.0f || f[10] > 180.0f || f[9] > f[10])
            return perr(p, "spot_light: angles must satisfy 0 <= angle1 <= angle2 <= 180, got %g %g", (double)f[9],
                        (double)f[10]);
        d = rt_normalize(d);
        l.type = RT_LIGHT_SPOT;
        memcpy(l.pos, f + 3, 3 * sizeof(float));
        l.dir[0] = d.x; l.dir[1] = d.y; l.dir[2] = d.z;
        l.angle1 = f[9];
        l.angle2 = f[10];
    }
    memcpy(l.color, f, 3 * sizeof(float));
    return add_light(p, &l);
}

/* Returned by a command group for a command it does not handle; errors are
 * -1 (rt_fail), so the value cannot be mistaken for one. */
#define NOT_MINE 1

/* A triangle's record from its checked indices (normal indices in
 * ix[3..5] when `normals`) and its material. */
static void set_triangle(RtTriangle *t, const int64_t *ix, int normals, uint32_t material)
{
    for (int i = 0; i < 3; i++) {
        t->v[i] = (uint32_t)ix[i];
        t->n[i] = normals ? (int32_t)ix[3 + i] : -1;
    }
    t->material = material;
}

/* A triangle with the current material, its indices (normal indices in
 * ix[3..5] when `normals`) checked against the nv vertices and nn normals
 * defined before its line: for the serial parser and the chunks' pass 2. */
static int add_triangle(Parser *p, const char *cmd, const int64_t *ix, int normals, uint32_t nv, uint32_t nn)
{
    RtScene *sc = p->s;
    for (int i = 0; i < 3; i++)
        if (check_index(p, cmd, ix[i], nv, "vertex") != 0)
            return -1;
    for (int i = 3; i < 6 && normals; i++)
        if (check_index(p, cmd, ix[i], nn, "normal") != 0)
            return -1;
    if (GROW(p, triangles, "triangles") != 0)
        return -1;
    set_triangle(&sc->triangles[sc->ntriangles++], ix, normals, p->material);
    return 0;
}

static int cmd_triangle(Parser *p, const char *cmd, const char *v)
{
    int64_t ix[6];
    const int nt = cmd[0] == 'n';
    if (get_indices(p, cmd, v, ix, nt ? 6 : 3) != 0)
        return -1;
    return add_triangle(p, cmd, ix, nt, p->s->nvertices, p->s->nnormals);
}

/* A sphere line's centre and radius (positive). */
static int sphere_values(Parser *p, const char *v, float *f)
{
    if (get_floats(p, "sphere", v, f, 4) != 0)
        return -1;
    if (!(f[3] > 0.0f))
        return perr(p, "sphere: radius must be positive, got %g", (double)f[3]);
    return 0;
}

/* A sphere with the current material. */
static int add_sphere(Parser *p, const float *f)
{
    if (GROW(p, spheres, "spheres") != 0)
        return -1;
    RtSphere *sp = &p->s->spheres[p->s->nspheres++];
    memcpy(sp->c, f, 3 * sizeof(float));
    sp->r = f[3];
    sp->material = p->material;
    return 0;
}

static int cmd_sphere(Parser *p, const char *v)
{
    float f[4];
    return sphere_values(p, v, f) != 0 ? -1 : add_sphere(p, f);
}

/* max_vertices / max_normals: a capacity hint only; reserve up to a sane
 * bound, never trust it, and ignore a failed reservation. */
static int cmd_capacity(Parser *p, const char *cmd, const char *v)
{
    RtScene *sc = p->s;
    float f[1];
    if (get_floats(p, cmd, v, f, 1) != 0)
        return -1;
    if (f[0] < 0.0f || f[0] != floorf(f[0]))
        return perr(p, "%s: expected a non-negative integer, got %g", cmd, (double)f[0]);
    uint32_t want = f[0] > 1e7f ? 10000000u : (uint32_t)f[0];
    int is_v = cmd[4] == 'v';
    uint32_t *cap = is_v ? &sc->cap_vertices : &sc->cap_normals;
    void **arr = is_v ? (void **)&sc->vertices : (void **)&sc->normals;
    if (want > *cap) {
        void *na = realloc(*arr, (size_t)want * sizeof(RtVec3));
        if (na) {
            *arr = na;
            *cap = want;
        }
    }
    return 0;
}

/* The next token of a mesh line into tok (a file name may be quoted), *s
 * moved past it; NULL at the end, or for a token longer than tok. */
static char *mesh_token(const char **s, char *tok, size_t size)
{
    const char *t = skip_ws(*s), *e;
    if (!*t)
        return NULL;
    if (*t == '"' || *t == '\'') {
        if (!(e = strchr(t + 1, *t)))
            return NULL;
        *s = e + 1;
        t++;
    } else {
        for (e = t; *e && *e != ' ' && *e != '\t'; e++)
            ;
        *s = e;
    }
    if ((size_t)(e - t) >= size)
        return NULL;
    memcpy(tok, t, (size_t)(e - t));
    tok[e - t] = '\0';
    return tok;
}

/* M = op * M for the 3x4 row-major affine maps of a mesh line. */
static void xf_then(float *m, const float *op)
{
    float r[12];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 4; j++)
            r[4 * i + j] = op[4 * i] * m[j] + op[4 * i + 1] * m[4 + j] + op[4 * i + 2] * m[8 + j] + (j == 3 ? op[4 * i + 3] : 0.0f);
    memcpy(m, r, sizeof r);
}

/* The transform of a mesh line: scale S | scale SX SY SZ | rotate x|y|z DEG |
 * translate X Y Z, applied in the order written. */
static int mesh_transform(Parser *p, const char *s, float *m)
{
    char kw[64], axis[64], num[64];
    while (mesh_token(&s, kw, sizeof kw) != NULL) {
        float v[3] = {0, 0, 0}, op[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
        const char *tok;
        int n = 0;
        if (strcmp(kw, "rotate") == 0) {
            if (!mesh_token(&s, axis, sizeof axis) || strlen(axis) != 1 || !strchr("xyz", axis[0]) ||
                !(tok = mesh_token(&s, num, sizeof num)) || parse_float(&tok, &v[0]) != 0 || *tok)
                return perr(p, "mesh: rotate: expected an axis x, y or z and an angle in degrees");
            const float a = v[0] * 3.14159265358979f / 180.0f, c = cosf(a), sn = sinf(a);
            const int i = (axis[0] - 'x' + 1) % 3, j = (axis[0] - 'x' + 2) % 3; /* the plane it turns */
            op[5 * i] = c; op[4 * i + j] = -sn; op[4 * j + i] = sn; op[5 * j] = c;
        } else if (strcmp(kw, "scale") == 0 || strcmp(kw, "translate") == 0) {
            const char *save = s;
            while (n < 3 && (tok = mesh_token(&s, num, sizeof num)) != NULL && parse_float(&tok, &v[n]) == 0 &&
                   *tok == '\0') {
                n++;
                save = s;
            }
            s = save;
            if (kw[0] == 't' ? n != 3 : n != 1 && n != 3)
                return perr(p, "mesh: %s: expected %s", kw, kw[0] == 't' ? "X Y Z" : "S or SX SY SZ");
            if (kw[0] == 't') {
                op[3] = v[0]; op[7] = v[1]; op[11] = v[2];
            } else {
                op[0] = v[0]; op[5] = n == 3 ? v[1] : v[0]; op[10] = n == 3 ? v[2] : v[0];
            }
        } else {
            return perr(p, "mesh: unknown transform '%.40s' (expected scale, rotate or translate)", kw);
        }
        xf_then(m, op);
    }
    s = skip_ws(s);
    if (*s) /* (mesh_token stops at a word of 64 bytes or more, or an open quote) */
        return perr(p, "mesh: cannot read the transform at '%.40s'", s);
    return 0;
}

/* mesh: FILE [transform...]: every triangle of a model file (Assimp), with
 * the current material; FILE is relative to the scene file's folder. */
static int cmd_mesh(Parser *p, const char *v)
{
    const char *s = v;
    char file[2048];
    if (!mesh_token(&s, file, sizeof file) || !*file)
        return perr(p, "mesh: expected a model file name");
    float m[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
    if (mesh_transform(p, s, m) != 0)
        return -1;
    char path[4096];
    const char *slash = strrchr(p->file, '/');
    if (file[0] == '/' || !slash)
        snprintf(path, sizeof path, "%s", file);
    else
        snprintf(path, sizeof path, "%.*s/%s", (int)(slash - p->file), p->file, file);
    RtError e;
    if (rt_model_append(path, m, p->material, p->s, &e) != 0)
        return perr(p, "mesh: %s", e.msg);
    p->s->models++;
    return 0;
}

/* Geometry: the vertex and normal pools, triangles, spheres, pool hints. */
static int cmd_geometry(Parser *p, const char *cmd, const char *v)
{
    RtScene *sc = p->s;
    if (strcmp(cmd, "vertex") == 0 || strcmp(cmd, "normal") == 0) {
        float f[3];
        if (get_floats(p, cmd, v, f, 3) != 0)
            return -1;
        if (cmd[0] == 'v') {
            if (GROW(p, vertices, "vertices") != 0)
                return -1;
            sc->vertices[sc->nvertices++] = v3f(f);
        } else {
            if (GROW(p, normals, "normals") != 0)
                return -1;
            sc->normals[sc->nnormals++] = v3f(f);
        }
        return 0;
    }
    if (strcmp(cmd, "triangle") == 0 || strcmp(cmd, "normal_triangle") == 0)
        return cmd_triangle(p, cmd, v);
    if (strcmp(cmd, "sphere") == 0)
        return cmd_sphere(p, v);
    if (strcmp(cmd, "max_vertices") == 0 || strcmp(cmd, "max_normals") == 0)
        return cmd_capacity(p, cmd, v);
    if (strcmp(cmd, "mesh") == 0)
        return cmd_mesh(p, v);
    return NOT_MINE;
}

/* Shading: materials, lights and the background colour. */
static int cmd_shading(Parser *p, const char *cmd, const char *v)
{
    RtScene *sc = p->s;
    float f[3];
    if (strcmp(cmd, "material") == 0)
        return cmd_material(p, v);
    if (strcmp(cmd, "point_light") == 0 || strcmp(cmd, "directional_light") == 0 ||
        strcmp(cmd, "spot_light") == 0)
        return cmd_light(p, cmd, v);
    if (strcmp(cmd, "ambient_light") == 0) {
        if (get_floats(p, cmd, v, f, 3) != 0)
            return -1;
        /* Several ambient lights add up, like every other light. */
        sc->ambient = rt_add(sc->ambient, v3f(f));
        return 0;
    }
    if (strcmp(cmd, "background") == 0) {
        if (get_floats(p, cmd, v, f, 3) != 0)
            return -1;
        sc->background = v3f(f);
        return 0;
    }
    return NOT_MINE;
}

static int cmd_max_depth(Parser *p, const char *v)
{
    float f[1];
    if (get_floats(p, "max_depth", v, f, 1) != 0)
        return -1;
    if (f[0] != floorf(f[0]))
        return perr(p, "max_depth: must be an integer, got %g", (double)f[0]);
    if (f[0] < 0.0f)
        return perr(p, "max_depth: must not be negative, got %g", (double)f[0]);
    if (f[0] > RT_MAX_DEPTH)
        return perr(p, "max_depth: %g exceeds the supported maximum %d", (double)f[0], RT_MAX_DEPTH);
    p->s->max_depth = (int32_t)f[0];
    p->s->line_depth = p->line;
    return 0;
}

/* Camera and render settings. The line numbers kept here let later checks
 * (rt_scene_camera) point at the line that set the value. */
static int cmd_camera(Parser *p, const char *cmd, const char *v)
{
    RtScene *sc = p->s;
    float f[3];
    if (strcmp(cmd, "camera_pos") == 0 || strcmp(cmd, "camera_fwd") == 0 || strcmp(cmd, "camera_up") == 0) {
        if (get_floats(p, cmd, v, f, 3) != 0)
            return -1;
        if (cmd[7] == 'p') {
            sc->camera_pos = v3f(f);
        } else if (cmd[7] == 'f') {
            sc->camera_fwd = v3f(f);
            sc->line_fwd = p->line;
        } else {
            sc->camera_up = v3f(f);
            sc->line_up = p->line;
        }
        return 0;
    }
    if (strcmp(cmd, "camera_fov_ha") == 0) {
        if (get_floats(p, cmd, v, f, 1) != 0)
            return -1;
        if (!(f[0] > 0.0f && f[0] < 90.0f))
            return perr(p, "camera_fov_ha: must be strictly between 0 and 90 degrees, got %g", (double)f[0]);
        sc->fov_ha = f[0];
        sc->line_fov = p->line;
        return 0;
    }
    if (strcmp(cmd, "film_resolution") == 0)
        return cmd_resolution(p, v);
    if (strcmp(cmd, "output_image") == 0)
        return cmd_output(p, v);
    if (strcmp(cmd, "max_depth") == 0)
        return cmd_max_depth(p, v);
    return NOT_MINE;
}

/* Cuts comment and trailing whitespace off line and splits it at the first
 * ':' into a command name (checked) and its value text. Returns 1 for a
 * blank line, 0 for a command, -1 on error. */
static int split_line(Parser *p, char *line, char **cmd, char **v)
{
    char *hash = strchr(line, '#');
    if (hash)
        *hash = '\0';
    size_t n = strlen(line);
    while (n && (line[n - 1] == ' ' || line[n - 1] == '\t' || line[n - 1] == '\r'))
        line[--n] = '\0';
    char *s = (char *)skip_ws(line);
    if (*s == '\0')
        return 1;
    char *colon = strchr(s, ':');
    if (!colon)
        return perr(p, "expected 'command: values', got '%.40s'", s);
    *colon = '\0';
    *cmd = s;
    *v = colon + 1;
    size_t cl = strlen(s);
    while (cl && (s[cl - 1] == ' ' || s[cl - 1] == '\t'))
        s[--cl] = '\0';
    for (size_t i = 0; i < cl; i++)
        if (!(islower((unsigned char)s[i]) || isdigit((unsigned char)s[i]) || s[i] == '_' ||
              isupper((unsigned char)s[i])))
            return perr(p, "malformed command name '%.40s'", s);
    return 0;
}

static int parse_line(Parser *p, char *line)
{
    char *cmd = NULL, *v = NULL;
    int rc = split_line(p, line, &cmd, &v);
    if (rc != 0)
        return rc < 0 ? rc : 0;
    rc = cmd_geometry(p, cmd, v);
    if (rc == NOT_MINE)
        rc = cmd_shading(p, cmd, v);
    if (rc == NOT_MINE)
        rc = cmd_camera(p, cmd, v);
    if (rc != NOT_MINE)
        return rc;
    if (p->warn) {
        char msg[512];
        snprintf(msg, sizeof msg, "%s:%d: warning: unknown command '%.60s' ignored", p->file, p->line, cmd);
        p->warn(p->warn_ctx, msg);
    }
    return 0;
}

/* The line at *pos into `line` (NUL-terminated, the '\n' dropped), *pos
 * moved past it; a line too long or with binary bytes is an error. */
static int next_line(Parser *p, const char *buf, size_t len, size_t *pos, char *line)
{
    const size_t start = *pos;
    const char *nl = memchr(buf + start, '\n', len - start);
    const size_t ll = nl ? (size_t)(nl - (buf + start)) : len - start;
    *pos = start + ll + (nl != NULL);
    if (ll > RT_MAX_LINE)
        return perr(p, "line longer than %d bytes", RT_MAX_LINE);
    for (size_t i = 0; i < ll; i++) {
        const unsigned char c = (unsigned char)buf[start + i];
        if ((c < 0x20 && c != '\t' && c != '\r') || c == 0x7f)
            return perr(p, "binary data (byte 0x%02x at column %zu): not a scene file", c, i + 1);
    }
    memcpy(line, buf + start, ll);
    line[ll] = '\0';
    return 0;
}

static void scene_defaults(RtScene *s)
{
    s->camera_pos = rt_v3(0, 0, 0);
    s->camera_fwd = rt_v3(0, 0, -1);
    s->camera_up = rt_v3(0, 1, 0);
    s->fov_ha = 45.0f;
    s->width = 640;
    s->height = 480;
    s->max_depth = 5;
    s->background = rt_v3(0, 0, 0);
    s->ambient = rt_v3(0, 0, 0);
    snprintf(s->output, sizeof s->output, "raytraced.bmp");
}

void rt_scene_name(RtScene *s, const char *path)
{
    const char *b = strrchr(path, '/');
    b = b ? b + 1 : path;
    snprintf(s->name, sizeof s->name, "%s", b);
    char *dot = strrchr(s->name, '.');
    if (dot && dot != s->name)
        *dot = '\0';
    /* The name goes into a space-separated record line. */
    for (char *c = s->name; *c; c++)
        if (*c == ' ' || *c == '\t' || *c == '=')
            *c = '_';
    snprintf(s->path, sizeof s->path, "%s", path);
}

/* A parser at the start of a scene: the defaults and material 0, the
 * format's default, used until the first material line. */
static int parse_start(Parser *p, const char *name, RtScene *scene, RtWarnFn warn, void *warn_ctx, RtError *err)
{
    memset(scene, 0, sizeof *scene);
    scene_defaults(scene);
    rt_scene_name(scene, name);
    memset(p, 0, sizeof *p);
    p->file = name;
    p->s = scene;
    p->err = err;
    p->warn = warn;
    p->warn_ctx = warn_ctx;
    if (GROW(p, materials, "materials") != 0)
        return -1;
    RtMaterial *m = &scene->materials[scene->nmaterials++];
    memset(m, 0, sizeof *m);
    m->kd[0] = m->kd[1] = m->kd[2] = 1.0f;
    m->ns = 5.0f;
    m->ior = 1.0f;
    return 0;
}

static int parse_serial(Parser *p, const char *buf, size_t len)
{
    char *line = malloc(RT_MAX_LINE + 1);
    if (!line)
        return rt_fail(p->err, "%s: out of memory", p->file);
    size_t pos = 0;
    int rc = 0;
    while (pos < len && rc == 0) {
        p->line++;
        rc = next_line(p, buf, len, &pos, line);
        if (rc == 0)
            rc = parse_line(p, line);
    }
    free(line);
    return rc;
}

/* ---- Large files in parallel ----------------------------------------------
 * Pass 1, per chunk of lines: vertex and normal lines into the chunk's
 * pools, triangle and sphere lines into records that remember what the
 * serial parser would have known there (the chunk's vertices, normals and
 * deferred lines so far), every other line deferred; a chunk stops at its
 * first error. Pass 2, in file order: each chunk's pools appended, then its
 * records and deferred lines in their order, so materials, index checks,
 * warnings and the first error come out as the serial parser's. Of that
 * pass only the order is serial: each chunk's first triangle with a bad
 * index is found before it (in parallel), the triangles before it are given
 * slots and a material in runs, and the runs are written after it (in
 * parallel); from a bad triangle on, add_triangle reports it. */
#define RT_PARSE_CHUNK (4u << 20) /* bytes per chunk; smaller files are parsed serially */

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
    int line0;          /* lines before the chunk */
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
#define CHUNK_GROW(c, arr, n, cap, what) grow(p, (void **)&(c)->arr, &(c)->cap, (c)->n, sizeof *(c)->arr, (what))

/* One line of pass 1; -1 stops the chunk (p->err holds the message). */
static int chunk_line(Parser *p, Chunk *c, char *line, size_t at)
{
    char *cmd = NULL, *v = NULL;
    const int rc = split_line(p, line, &cmd, &v);
    if (rc != 0)
        return rc < 0 ? -1 : 0;
    float f[4];
    if (strcmp(cmd, "vertex") == 0 || strcmp(cmd, "normal") == 0) {
        if (get_floats(p, cmd, v, f, 3) != 0)
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
        if (get_indices(p, cmd, v, ix, nt ? 6 : 3) != 0)
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
        if (sphere_values(p, v, f) != 0 || CHUNK_GROW(c, sphs, ns, cap_s, "spheres"))
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
        c->failed = next_line(&p, buf, c->end, &pos, line) != 0 || chunk_line(&p, c, line, at) != 0;
    }
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

/* The first of chunk c's triangles whose indices fail add_triangle's checks
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

/* Pass 2 for a chunk's triangles and spheres before its deferred line j:
 * triangles before the chunk's first bad one (bad) are placed as one run,
 * written later (pass2_fill); from the bad one on they go through
 * add_triangle, which stops at it with the serial parser's message. */
static int chunk_prims(Parser *p, const Chunk *c, uint32_t j, uint32_t *ti, uint32_t *si, uint32_t nv0, uint32_t nn0,
                       uint32_t bad, Pass2 *q)
{
    uint32_t end = *ti;
    while (end < c->nt && c->tris[end].deferred == j)
        end++;
    const uint32_t good = end < bad ? end : bad;
    if (good > *ti) {
        RtScene *sc = p->s;
        if (q->nruns == q->cap && grow(p, (void **)&q->runs, &q->cap, q->nruns, sizeof *q->runs, "lines") != 0)
            return -1;
        if ((uint64_t)sc->ntriangles + (good - *ti) > sc->cap_triangles) /* (reserve_all sized them) */
            return perr(p, "internal error: triangle pool too small");
        q->runs[q->nruns++] = (TriRun){&c->tris[*ti], good - *ti, sc->ntriangles, p->material};
        sc->ntriangles += good - *ti;
        *ti = good;
    }
    for (; *ti < end; (*ti)++) {
        const TriRec *t = &c->tris[*ti];
        const int normals = t->line < 0;
        const int64_t ix[6] = {t->v[0], t->v[1], t->v[2], t->n[0], t->n[1], t->n[2]};
        p->line = normals ? -t->line : t->line;
        if (add_triangle(p, normals ? "normal_triangle" : "triangle", ix, normals, nv0 + t->nv, nn0 + t->nn) != 0)
            return -1;
    }
    for (; *si < c->ns && c->sphs[*si].deferred == j; (*si)++)
        if (add_sphere(p, c->sphs[*si].f) != 0)
            return -1;
    return 0;
}

/* Pass 2 for one chunk, in file order. */
static int chunk_merge(Parser *p, const Chunk *c, const char *buf, char *line, uint32_t bad, Pass2 *q)
{
    RtScene *sc = p->s;
    const uint32_t nv0 = sc->nvertices, nn0 = sc->nnormals;
    memcpy(sc->vertices + nv0, c->verts, (size_t)c->nv * sizeof *c->verts);
    memcpy(sc->normals + nn0, c->norms, (size_t)c->nn * sizeof *c->norms);
    sc->nvertices += c->nv;
    sc->nnormals += c->nn;
    uint32_t ti = 0, si = 0;
    for (uint32_t j = 0; j <= c->nd; j++) {
        if (chunk_prims(p, c, j, &ti, &si, nv0, nn0, bad, q) != 0)
            return -1;
        if (j == c->nd)
            break;
        size_t pos = c->defs[j].pos;
        p->line = c->defs[j].line;
        if (next_line(p, buf, c->end, &pos, line) != 0 || parse_line(p, line) != 0)
            return -1;
    }
    if (c->failed) { /* the chunk's first error, after everything before it */
        *p->err = c->err;
        return -1;
    }
    return 0;
}

/* The placed runs written, in parallel: the records add_triangle writes. */
static void pass2_fill(RtScene *sc, const Pass2 *q, int nt)
{
    (void)nt;
#pragma omp parallel for num_threads(nt) schedule(dynamic, 1)
    for (uint32_t r = 0; r < q->nruns; r++) {
        const TriRun *run = &q->runs[r];
        for (uint32_t k = 0; k < run->n; k++) {
            const TriRec *t = &run->t[k];
            const int64_t ix[6] = {t->v[0], t->v[1], t->v[2], t->n[0], t->n[1], t->n[2]};
            set_triangle(&sc->triangles[run->out + k], ix, t->line < 0, run->material);
        }
    }
}

/* Chunks at line starts, about RT_PARSE_CHUNK bytes each, and the lines
 * before each (counted in parallel). */
static int chunk_split(const char *buf, size_t len, Chunk **out, int nt)
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
    (void)nt;
#pragma omp parallel for num_threads(nt) schedule(dynamic, 1)
    for (int i = 0; i < n; i++) {
        int lines = 0;
        for (const char *q = buf + c[i].begin, *end = buf + c[i].end; (q = memchr(q, '\n', (size_t)(end - q))); q++)
            lines++;
        c[i].line0 = lines; /* (made cumulative below) */
    }
    for (int i = 0, sum = 0; i < n; i++) {
        const int k = c[i].line0;
        c[i].line0 = sum;
        sum += k;
    }
    *out = c;
    return n;
}

static void chunks_free(Chunk *c, int n)
{
    for (int i = 0; i < n; i++) {
        free(c[i].verts);
        free(c[i].norms);
        free(c[i].tris);
        free(c[i].sphs);
        free(c[i].defs);
    }
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
    sc->vertices = malloc((size_t)(nv ? nv : 1) * sizeof *sc->vertices);
    sc->normals = malloc((size_t)(nn ? nn : 1) * sizeof *sc->normals);
    sc->triangles = malloc((size_t)(nt ? nt : 1) * sizeof *sc->triangles);
    sc->spheres = malloc((size_t)(ns ? ns : 1) * sizeof *sc->spheres);
    if (!sc->vertices || !sc->normals || !sc->triangles || !sc->spheres)
        return rt_fail(p->err, "%s: out of memory for the scene's pools", p->file);
    sc->cap_vertices = (uint32_t)(nv ? nv : 1);
    sc->cap_normals = (uint32_t)(nn ? nn : 1);
    sc->cap_triangles = (uint32_t)(nt ? nt : 1);
    sc->cap_spheres = (uint32_t)(ns ? ns : 1);
    return 0;
}

static int parse_chunks(Parser *p, const char *buf, size_t len, int nt)
{
    Chunk *c = NULL;
    const int n = chunk_split(buf, len, &c, nt);
    if (n < 0)
        return rt_fail(p->err, "%s: out of memory", p->file);
#pragma omp parallel for num_threads(nt) schedule(dynamic, 1)
    for (int i = 0; i < n; i++)
        chunk_parse(p, &c[i], buf);
    for (int i = 0; i < n; i++)
        if (c[i].has_mesh) { /* a model's vertices go between the file's: one pass in order */
            chunks_free(c, n);
            return parse_serial(p, buf, len);
        }
    /* pools sized for every chunk up to the first that failed (the rest is never reached) */
    int upto = 0;
    while (upto < n && !c[upto].failed)
        upto++;
    /* each chunk's first bad triangle, against the pools before it */
    uint32_t *bad = malloc((size_t)n * sizeof *bad), *nv0 = malloc((size_t)n * 2 * sizeof *nv0);
    if (bad && nv0) {
        for (int i = 0; i < n; i++) {
            nv0[2 * i] = i ? nv0[2 * i - 2] + c[i - 1].nv : p->s->nvertices;
            nv0[2 * i + 1] = i ? nv0[2 * i - 1] + c[i - 1].nn : p->s->nnormals;
        }
#pragma omp parallel for num_threads(nt) schedule(dynamic, 1)
        for (int i = 0; i < n; i++)
            bad[i] = chunk_first_bad(&c[i], nv0[2 * i], nv0[2 * i + 1]);
    }
    char *line = malloc(RT_MAX_LINE + 1);
    Pass2 q = {NULL, 0, 0};
    int rc = line && bad && nv0 ? reserve_all(p, c, upto < n ? upto + 1 : n)
                                : rt_fail(p->err, "%s: out of memory", p->file);
    for (int i = 0; i < n && rc == 0; i++)
        rc = chunk_merge(p, &c[i], buf, line, bad[i], &q);
    /* (also after an error: the runs placed before it, as the serial parser
     * left them) */
    pass2_fill(p->s, &q, nt);
    free(q.runs);
    free(line);
    free(bad);
    free(nv0);
    chunks_free(c, n);
    return rc;
}

int rt_scene_parse_buffer_threads(const char *name, const char *buf, size_t len, int threads, RtScene *scene,
                                  RtWarnFn warn, void *warn_ctx, RtError *err)
{
    Parser p;
    if (parse_start(&p, name, scene, warn, warn_ctx, err) != 0)
        return -1;
    const int nt = rt_thread_count(threads);
    if (nt > 1 && len >= 2 * (size_t)RT_PARSE_CHUNK)
        return parse_chunks(&p, buf, len, nt);
    return parse_serial(&p, buf, len);
}

int rt_scene_parse_buffer(const char *name, const char *buf, size_t len, RtScene *scene, RtWarnFn warn,
                          void *warn_ctx, RtError *err)
{
    return rt_scene_parse_buffer_threads(name, buf, len, 1, scene, warn, warn_ctx, err);
}

/* raytrace MODEL: the scene's file hash is that of the model's bytes as
 * Assimp read them (the first file model.c recorded under that name). */
static int model_scene(const char *path, RtScene *scene, RtError *err)
{
    if (rt_model_scene(path, scene, err) != 0)
        return -1;
    for (uint32_t i = 0; i < scene->ndeps; i++)
        if (strcmp(scene->deps[i].path, path) == 0) {
            memcpy(scene->file_hash, scene->deps[i].hash, 16);
            return 0;
        }
    char *buf; /* (a loader that read it otherwise: its bytes now) */
    size_t len;
    if (rt_read_file(path, RT_MAX_FILE, &buf, &len, err) != 0)
        return -1;
    rt_content_hash(buf, len, scene->file_hash);
    free(buf);
    return 0;
}

int rt_scene_load_threads(const char *path, int threads, RtScene *scene, RtWarnFn warn, void *warn_ctx,
                          RtError *err)
{
    memset(scene, 0, sizeof *scene);
    if (rt_model_supported(path)) /* raytrace MODEL: Assimp reads it (through model.c's own file access) */
        return model_scene(path, scene, err);
    /* Read once, whole: the bytes parsed are the bytes hashed (the cache's
     * key, MPI's agreement), and a file truncated underneath is an error,
     * not a SIGBUS in a mapping. */
    char *buf = NULL;
    size_t len = 0;
    if (rt_read_file(path, RT_MAX_FILE, &buf, &len, err) != 0)
        return -1;
    const int rc = rt_scene_parse_buffer_threads(path, buf, len, threads, scene, warn, warn_ctx, err);
    if (rc == 0)
        rt_content_hash(buf, len, scene->file_hash);
    free(buf);
    return rc;
}

int rt_scene_load(const char *path, RtScene *scene, RtWarnFn warn, void *warn_ctx, RtError *err)
{
    return rt_scene_load_threads(path, 0, scene, warn, warn_ctx, err);
}

void rt_scene_free(RtScene *s)
{
    if (s->cache_map) {
        munmap(s->cache_map, s->cache_len);
    } else {
        free(s->vertices);
        free(s->normals);
        free(s->spheres);
        free(s->triangles);
        free(s->materials);
        free(s->lights);
    }
    rt_scene_free_deps(s);
    memset(s, 0, sizeof *s);
}
