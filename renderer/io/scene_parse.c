/* scene_parse.c - the course scene format (docs/scene-format.md): its
 * commands, one line at a time, over a buffer held in memory, with the
 * values read by scene_lex.c. The parallel parse of large buffers
 * (scene_chunks.c) runs these same lines; which of the two parses a buffer,
 * and which file is a scene and which a model, is scene_load.c's choice.
 * Every error names file and line and leaves the scene freeable. */
#include <ctype.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "scene_parse.h"

int parse_grow(Parser *p, void **arr, uint32_t *cap, uint32_t n, size_t elem, const char *what)
{
    if (n < *cap)
        return 0;
    if (n >= RT_MAX_POOL)
        return parse_fail(p, "too many %s (limit %u)", what, RT_MAX_POOL);
    uint64_t nc = *cap ? (uint64_t)*cap * 2 : 64;
    if (nc > RT_MAX_POOL)
        nc = RT_MAX_POOL;
    void *na = realloc(*arr, (size_t)nc * elem);
    if (!na)
        return parse_fail(p, "out of memory growing %s to %llu entries", what, (unsigned long long)nc);
    *arr = na;
    *cap = (uint32_t)nc;
    return 0;
}

static int check_index(Parser *p, const char *cmd, int64_t idx, uint32_t n, const char *pool)
{
    if (idx >= (int64_t)n)
        return parse_fail(p, "%s: %s index %lld out of range (%u %s defined so far)", cmd, pool, (long long)idx, n,
                          pool);
    return 0;
}

static int cmd_output(Parser *p, const char *v)
{
    const char *s = lex_skip_ws(v);
    size_t n = strlen(s);
    while (n && (s[n - 1] == ' ' || s[n - 1] == '\t'))
        n--;
    if (n >= 2 && ((s[0] == '"' && s[n - 1] == '"') || (s[0] == '\'' && s[n - 1] == '\''))) {
        s++;
        n -= 2;
    }
    if (n == 0)
        return parse_fail(p, "output_image: expected a file name");
    if (n >= sizeof p->s->settings.output)
        return parse_fail(p, "output_image: name longer than %zu bytes", sizeof p->s->settings.output - 1);
    memcpy(p->s->settings.output, s, n);
    p->s->settings.output[n] = '\0';
    p->s->source.line_output = p->line;
    return 0;
}

static int cmd_resolution(Parser *p, const char *v)
{
    float f[2];
    if (lex_floats(p, "film_resolution", v, f, 2) != 0)
        return -1;
    for (int i = 0; i < 2; i++)
        if (f[i] != floorf(f[i]) || f[i] < 1.0f)
            return parse_fail(p, "film_resolution: %s must be a positive integer, got %g", i ? "height" : "width",
                              (double)f[i]);
    if (f[0] > RT_MAX_SIDE || f[1] > RT_MAX_SIDE || (double)f[0] * (double)f[1] > (double)RT_MAX_PIXELS)
        return parse_fail(p, "film_resolution %.0fx%.0f would need %.1f GiB of image memory (limit %dx%d, %llu pixels)",
                          (double)f[0], (double)f[1], (double)f[0] * (double)f[1] * 15.0 / (1024.0 * 1024.0 * 1024.0),
                          RT_MAX_SIDE, RT_MAX_SIDE, (unsigned long long)RT_MAX_PIXELS);
    p->s->settings.width = (int32_t)f[0];
    p->s->settings.height = (int32_t)f[1];
    p->s->source.line_res = p->line;
    return 0;
}

static int cmd_material(Parser *p, const char *v)
{
    float f[14];
    if (lex_floats(p, "material", v, f, 14) != 0)
        return -1;
    for (int i = 0; i < 9; i++)
        if (f[i] < 0.0f)
            return parse_fail(p, "material: value %d is negative (%g); reflectances must be >= 0", i + 1, (double)f[i]);
    if (f[9] < 0.0f)
        return parse_fail(p, "material: Phong exponent ns is negative (%g)", (double)f[9]);
    for (int i = 10; i < 13; i++)
        if (f[i] < 0.0f)
            return parse_fail(p, "material: value %d is negative (%g); transmission must be >= 0", i + 1, (double)f[i]);
    /* The course's tools write ior 0 for opaque materials: the index only
     * matters where light is transmitted (RENDERING-RULES: kt != 0). */
    const int transmissive = f[10] > 0.0f || f[11] > 0.0f || f[12] > 0.0f;
    if (transmissive && !(f[13] > 0.0f))
        return parse_fail(p, "material: index of refraction must be positive for a transmissive material (kt > 0), "
                             "got %g", (double)f[13]);
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
        if (lex_floats(p, cmd, v, f, 6) != 0)
            return -1;
        l.type = RT_LIGHT_POINT;
        memcpy(l.pos, f + 3, 3 * sizeof(float));
    } else if (strcmp(cmd, "directional_light") == 0) {
        if (lex_floats(p, cmd, v, f, 6) != 0)
            return -1;
        RtVec3 d = v3f(f + 3);
        if (rt_is_zero(d))
            return parse_fail(p, "directional_light: direction is the zero vector");
        d = rt_normalize(d);
        l.type = RT_LIGHT_DIRECTIONAL;
        l.dir[0] = d.x; l.dir[1] = d.y; l.dir[2] = d.z;
    } else {
        if (lex_floats(p, cmd, v, f, 11) != 0)
            return -1;
        RtVec3 d = v3f(f + 6);
        if (rt_is_zero(d))
            return parse_fail(p, "spot_light: axis direction is the zero vector");
        if (f[9] < 0.0f || f[10] > 180.0f || f[9] > f[10])
            return parse_fail(p, "spot_light: angles must satisfy 0 <= angle1 <= angle2 <= 180, got %g %g",
                              (double)f[9], (double)f[10]);
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
void parse_set_triangle(RtTriangle *t, const int64_t *ix, int normals, uint32_t material)
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
int parse_add_triangle(Parser *p, const char *cmd, const int64_t *ix, int normals, uint32_t nv, uint32_t nn)
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
    parse_set_triangle(&sc->triangles[sc->ntriangles++], ix, normals, p->material);
    return 0;
}

static int cmd_triangle(Parser *p, const char *cmd, const char *v)
{
    int64_t ix[6];
    const int nt = cmd[0] == 'n';
    if (lex_indices(p, cmd, v, ix, nt ? 6 : 3) != 0)
        return -1;
    return parse_add_triangle(p, cmd, ix, nt, p->s->nvertices, p->s->nnormals);
}

/* A sphere line's centre and radius (positive). */
int parse_sphere_values(Parser *p, const char *v, float *f)
{
    if (lex_floats(p, "sphere", v, f, 4) != 0)
        return -1;
    if (!(f[3] > 0.0f))
        return parse_fail(p, "sphere: radius must be positive, got %g", (double)f[3]);
    return 0;
}

/* A sphere with the current material. */
int parse_add_sphere(Parser *p, const float *f)
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
    return parse_sphere_values(p, v, f) != 0 ? -1 : parse_add_sphere(p, f);
}

/* max_vertices / max_normals: a capacity hint only; reserve up to a sane
 * bound, never trust it, and ignore a failed reservation. */
static int cmd_capacity(Parser *p, const char *cmd, const char *v)
{
    RtScene *sc = p->s;
    float f[1];
    if (lex_floats(p, cmd, v, f, 1) != 0)
        return -1;
    if (f[0] < 0.0f || f[0] != floorf(f[0]))
        return parse_fail(p, "%s: expected a non-negative integer, got %g", cmd, (double)f[0]);
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
    const char *t = lex_skip_ws(*s), *e;
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
                !(tok = mesh_token(&s, num, sizeof num)) || lex_float(&tok, &v[0]) != 0 || *tok)
                return parse_fail(p, "mesh: rotate: expected an axis x, y or z and an angle in degrees");
            const float a = v[0] * 3.14159265358979f / 180.0f, c = cosf(a), sn = sinf(a);
            const int i = (axis[0] - 'x' + 1) % 3, j = (axis[0] - 'x' + 2) % 3; /* the plane it turns */
            op[5 * i] = c; op[4 * i + j] = -sn; op[4 * j + i] = sn; op[5 * j] = c;
        } else if (strcmp(kw, "scale") == 0 || strcmp(kw, "translate") == 0) {
            const char *save = s;
            while (n < 3 && (tok = mesh_token(&s, num, sizeof num)) != NULL && lex_float(&tok, &v[n]) == 0 &&
                   *tok == '\0') {
                n++;
                save = s;
            }
            s = save;
            if (kw[0] == 't' ? n != 3 : n != 1 && n != 3)
                return parse_fail(p, "mesh: %s: expected %s", kw, kw[0] == 't' ? "X Y Z" : "S or SX SY SZ");
            if (kw[0] == 't') {
                op[3] = v[0]; op[7] = v[1]; op[11] = v[2];
            } else {
                op[0] = v[0]; op[5] = n == 3 ? v[1] : v[0]; op[10] = n == 3 ? v[2] : v[0];
            }
        } else {
            return parse_fail(p, "mesh: unknown transform '%.40s' (expected scale, rotate or translate)", kw);
        }
        xf_then(m, op);
    }
    s = lex_skip_ws(s);
    if (*s) /* (mesh_token stops at a word of 64 bytes or more, or an open quote) */
        return parse_fail(p, "mesh: cannot read the transform at '%.40s'", s);
    return 0;
}

/* mesh: FILE [transform...]: every triangle of a model file (Assimp), with
 * the current material; FILE is relative to the scene file's folder. */
static int cmd_mesh(Parser *p, const char *v)
{
    const char *s = v;
    char file[2048];
    if (!mesh_token(&s, file, sizeof file) || !*file)
        return parse_fail(p, "mesh: expected a model file name");
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
        return parse_fail(p, "mesh: %s", e.msg);
    p->s->source.models++;
    return 0;
}

/* Geometry: the vertex and normal pools, triangles, spheres, pool hints. */
static int cmd_geometry(Parser *p, const char *cmd, const char *v)
{
    RtScene *sc = p->s;
    if (strcmp(cmd, "vertex") == 0 || strcmp(cmd, "normal") == 0) {
        float f[3];
        if (lex_floats(p, cmd, v, f, 3) != 0)
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
        if (lex_floats(p, cmd, v, f, 3) != 0)
            return -1;
        /* Several ambient lights add up, like every other light. */
        sc->settings.ambient = rt_add(sc->settings.ambient, v3f(f));
        return 0;
    }
    if (strcmp(cmd, "background") == 0) {
        if (lex_floats(p, cmd, v, f, 3) != 0)
            return -1;
        sc->settings.background = v3f(f);
        return 0;
    }
    return NOT_MINE;
}

static int cmd_max_depth(Parser *p, const char *v)
{
    float f[1];
    if (lex_floats(p, "max_depth", v, f, 1) != 0)
        return -1;
    if (f[0] != floorf(f[0]))
        return parse_fail(p, "max_depth: must be an integer, got %g", (double)f[0]);
    if (f[0] < 0.0f)
        return parse_fail(p, "max_depth: must not be negative, got %g", (double)f[0]);
    if (f[0] > RT_MAX_DEPTH)
        return parse_fail(p, "max_depth: %g exceeds the supported maximum %d", (double)f[0], RT_MAX_DEPTH);
    p->s->settings.max_depth = (int32_t)f[0];
    p->s->source.line_depth = p->line;
    return 0;
}

/* Camera and render settings. The line numbers kept here let later checks
 * (rt_scene_camera) point at the line that set the value. */
static int cmd_camera(Parser *p, const char *cmd, const char *v)
{
    RtScene *sc = p->s;
    float f[3];
    if (strcmp(cmd, "camera_pos") == 0 || strcmp(cmd, "camera_fwd") == 0 || strcmp(cmd, "camera_up") == 0) {
        if (lex_floats(p, cmd, v, f, 3) != 0)
            return -1;
        if (cmd[7] == 'p') {
            sc->settings.camera_pos = v3f(f);
        } else if (cmd[7] == 'f') {
            sc->settings.camera_fwd = v3f(f);
            sc->source.line_fwd = p->line;
        } else {
            sc->settings.camera_up = v3f(f);
            sc->source.line_up = p->line;
        }
        return 0;
    }
    if (strcmp(cmd, "camera_fov_ha") == 0) {
        if (lex_floats(p, cmd, v, f, 1) != 0)
            return -1;
        if (!(f[0] > 0.0f && f[0] < 90.0f))
            return parse_fail(p, "camera_fov_ha: must be strictly between 0 and 90 degrees, got %g", (double)f[0]);
        sc->settings.fov_ha = f[0];
        sc->source.line_fov = p->line;
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
int parse_split(Parser *p, char *line, char **cmd, char **v)
{
    char *hash = strchr(line, '#');
    if (hash)
        *hash = '\0';
    size_t n = strlen(line);
    while (n && (line[n - 1] == ' ' || line[n - 1] == '\t' || line[n - 1] == '\r'))
        line[--n] = '\0';
    char *s = (char *)lex_skip_ws(line);
    if (*s == '\0')
        return 1;
    char *colon = strchr(s, ':');
    if (!colon)
        return parse_fail(p, "expected 'command: values', got '%.40s'", s);
    *colon = '\0';
    *cmd = s;
    *v = colon + 1;
    size_t cl = strlen(s);
    while (cl && (s[cl - 1] == ' ' || s[cl - 1] == '\t'))
        s[--cl] = '\0';
    for (size_t i = 0; i < cl; i++)
        if (!(islower((unsigned char)s[i]) || isdigit((unsigned char)s[i]) || s[i] == '_' ||
              isupper((unsigned char)s[i])))
            return parse_fail(p, "malformed command name '%.40s'", s);
    return 0;
}

int parse_line(Parser *p, char *line)
{
    char *cmd = NULL, *v = NULL;
    int rc = parse_split(p, line, &cmd, &v);
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
int parse_next_line(Parser *p, const char *buf, size_t len, size_t *pos, char *line)
{
    const size_t start = *pos;
    const char *nl = memchr(buf + start, '\n', len - start);
    const size_t ll = nl ? (size_t)(nl - (buf + start)) : len - start;
    *pos = start + ll + (nl != NULL);
    if (ll > RT_MAX_LINE)
        return parse_fail(p, "line longer than %d bytes", RT_MAX_LINE);
    /* Eight bytes at a time: a word with no byte below 0x20 and none equal
     * to 0x7f needs no look at each (Mycroft's zero-byte test); the rest,
     * tabs and carriage returns among them, byte by byte. */
    const uint64_t ones = 0x0101010101010101ull, highs = 0x8080808080808080ull;
    for (size_t i = 0; i < ll;) {
        size_t n = ll - i < 8 ? ll - i : 8;
        if (n == 8) {
            uint64_t w, d;
            memcpy(&w, buf + start + i, 8);
            d = w ^ (0x7f * ones);
            if (!((((w - 0x20 * ones) & ~w) | ((d - ones) & ~d)) & highs))
                n = 0;
        }
        for (size_t k = i; k < i + n; k++) {
            const unsigned char c = (unsigned char)buf[start + k];
            if ((c < 0x20 && c != '\t' && c != '\r') || c == 0x7f)
                return parse_fail(p, "binary data (byte 0x%02x at column %zu): not a scene file", c, k + 1);
        }
        i += 8;
    }
    memcpy(line, buf + start, ll);
    line[ll] = '\0';
    return 0;
}

static void scene_defaults(RtScene *s)
{
    s->settings.camera_pos = rt_v3(0, 0, 0);
    s->settings.camera_fwd = rt_v3(0, 0, -1);
    s->settings.camera_up = rt_v3(0, 1, 0);
    s->settings.fov_ha = 45.0f;
    s->settings.width = 640;
    s->settings.height = 480;
    s->settings.max_depth = 5;
    s->settings.background = rt_v3(0, 0, 0);
    s->settings.ambient = rt_v3(0, 0, 0);
    snprintf(s->settings.output, sizeof s->settings.output, "raytraced.bmp");
}

/* A parser at the start of a scene: the defaults and material 0, the
 * format's default, used until the first material line. */
int parse_start(Parser *p, const char *name, RtScene *scene, RtWarnFn warn, void *warn_ctx, RtError *err)
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

int parse_serial(Parser *p, const char *buf, size_t len)
{
    char *line = malloc(RT_MAX_LINE + 1);
    if (!line)
        return rt_fail(p->err, "%s: out of memory", p->file);
    size_t pos = 0;
    int rc = 0;
    while (pos < len && rc == 0) {
        p->line++;
        rc = parse_next_line(p, buf, len, &pos, line);
        if (rc == 0)
            rc = parse_line(p, line);
    }
    free(line);
    return rc;
}
