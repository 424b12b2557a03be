/* scene_parse.c - the course scene format (docs/scene-format.md).
 *
 * The whole file is read into memory and parsed in place, one line at a time.
 * Numbers go through a fast decimal path (exact for up to 19 significant
 * digits and powers of ten up to 1e22, Clinger 1990) with strtof as the
 * fallback, which is what makes the 500 KB dragon parse in a few ms.
 * Every error names file and line and leaves the scene freeable. */
#include <ctype.h>
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "rt.h"

/* Longest line accepted; longer is an error, not a silent truncation. */
#define RT_MAX_LINE 65536
/* Largest scene file accepted (1 GiB). */
#define RT_MAX_FILE (1ull << 30)
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

static int cmd_triangle(Parser *p, const char *cmd, const char *v)
{
    RtScene *sc = p->s;
    int64_t ix[6];
    int nt = cmd[0] == 'n';
    if (get_indices(p, cmd, v, ix, nt ? 6 : 3) != 0)
        return -1;
    for (int i = 0; i < 3; i++)
        if (check_index(p, cmd, ix[i], sc->nvertices, "vertex") != 0)
            return -1;
    if (nt)
        for (int i = 3; i < 6; i++)
            if (check_index(p, cmd, ix[i], sc->nnormals, "normal") != 0)
                return -1;
    if (GROW(p, triangles, "triangles") != 0)
        return -1;
    RtTriangle *t = &sc->triangles[sc->ntriangles++];
    for (int i = 0; i < 3; i++) {
        t->v[i] = (uint32_t)ix[i];
        t->n[i] = nt ? (int32_t)ix[3 + i] : -1;
    }
    t->material = p->material;
    return 0;
}

static int cmd_sphere(Parser *p, const char *v)
{
    float f[4];
    if (get_floats(p, "sphere", v, f, 4) != 0)
        return -1;
    if (!(f[3] > 0.0f))
        return perr(p, "sphere: radius must be positive, got %g", (double)f[3]);
    if (GROW(p, spheres, "spheres") != 0)
        return -1;
    RtSphere *sp = &p->s->spheres[p->s->nspheres++];
    memcpy(sp->c, f, 3 * sizeof(float));
    sp->r = f[3];
    sp->material = p->material;
    return 0;
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

static void scene_name(RtScene *s, const char *path)
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

int rt_scene_parse_buffer(const char *name, const char *buf, size_t len, RtScene *scene, RtWarnFn warn,
                          void *warn_ctx, RtError *err)
{
    memset(scene, 0, sizeof *scene);
    scene_defaults(scene);
    scene_name(scene, name);
    Parser p;
    memset(&p, 0, sizeof p);
    p.file = name;
    p.s = scene;
    p.err = err;
    p.warn = warn;
    p.warn_ctx = warn_ctx;
    /* Material 0 is the format's default, used until the first material line. */
    if (GROW(&p, materials, "materials") != 0)
        return -1;
    RtMaterial *m = &scene->materials[scene->nmaterials++];
    memset(m, 0, sizeof *m);
    m->kd[0] = m->kd[1] = m->kd[2] = 1.0f;
    m->ns = 5.0f;
    m->ior = 1.0f;
    char *line = malloc(RT_MAX_LINE + 1);
    if (!line)
        return rt_fail(err, "%s: out of memory", name);
    size_t pos = 0;
    int rc = 0;
    while (pos < len && rc == 0) {
        p.line++;
        size_t start = pos;
        while (pos < len && buf[pos] != '\n')
            pos++;
        size_t ll = pos - start;
        if (pos < len)
            pos++; /* the '\n' */
        if (ll > RT_MAX_LINE) {
            rc = perr(&p, "line longer than %d bytes", RT_MAX_LINE);
            break;
        }
        for (size_t i = 0; i < ll; i++) {
            unsigned char c = (unsigned char)buf[start + i];
            if ((c < 0x20 && c != '\t' && c != '\r') || c == 0x7f) {
                rc = perr(&p, "binary data (byte 0x%02x at column %zu): not a scene file", c, i + 1);
                break;
            }
        }
        if (rc)
            break;
        memcpy(line, buf + start, ll);
        line[ll] = '\0';
        rc = parse_line(&p, line);
    }
    free(line);
    return rc;
}

int rt_scene_load(const char *path, RtScene *scene, RtWarnFn warn, void *warn_ctx, RtError *err)
{
    memset(scene, 0, sizeof *scene);
    /* O_NONBLOCK: opening a FIFO for reading would wait for a writer forever;
     * opened this way it is refused below like any other non-regular file. */
    int fd = open(path, O_RDONLY | O_NONBLOCK | O_CLOEXEC);
    if (fd < 0)
        return rt_fail(err, "%s: cannot open: %s", path, strerror(errno));
    struct stat st;
    if (fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
        close(fd);
        return rt_fail(err, "%s: not a regular file", path);
    }
    FILE *fp = fdopen(fd, "rb");
    if (!fp) {
        close(fd);
        return rt_fail(err, "%s: cannot open: %s", path, strerror(errno));
    }
    if ((unsigned long long)st.st_size > RT_MAX_FILE) {
        fclose(fp);
        return rt_fail(err, "%s: file of %lld bytes is larger than the %llu-byte limit", path, (long long)st.st_size,
                       (unsigned long long)RT_MAX_FILE);
    }
    size_t len = (size_t)st.st_size;
    char *buf = malloc(len + 1);
    if (!buf) {
        fclose(fp);
        return rt_fail(err, "%s: out of memory reading %zu bytes", path, len);
    }
    size_t got = fread(buf, 1, len, fp);
    int rerr = ferror(fp);
    fclose(fp);
    if (rerr || got != len) {
        free(buf);
        return rt_fail(err, "%s: read error", path);
    }
    buf[len] = '\0';
    int rc = rt_scene_parse_buffer(path, buf, len, scene, warn, warn_ctx, err);
    free(buf);
    return rc;
}

void rt_scene_free(RtScene *s)
{
    free(s->vertices);
    free(s->normals);
    free(s->spheres);
    free(s->triangles);
    free(s->materials);
    free(s->lights);
    memset(s, 0, sizeof *s);
}
