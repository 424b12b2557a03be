/* scene_parse.h - what the scene parser's files share (renderer/io/), in
 * layers that call only downwards: scene_lex.c (the parser's errors and the
 * values of a line), scene_parse.c (the commands, a line at a time, and the
 * serial parse), scene_chunks.c (large buffers on several threads, through
 * scene_parse.c's lines) and scene_load.c (rt.h's entry points, which choose
 * among them). Not part of the library's API (that is rt.h). */
#ifndef RT_IO_SCENE_PARSE_H
#define RT_IO_SCENE_PARSE_H

#include <stddef.h>
#include <stdint.h>

#include "rt.h"

/* Longest line accepted; longer is an error, not a silent truncation. */
#define RT_MAX_LINE 65536
/* Pool sizes beyond this are refused (indices must fit 31 bits). */
#define RT_MAX_POOL 0x7fffffffu
/* Bytes per chunk of the parallel parse; smaller buffers are parsed serially. */
#define RT_PARSE_CHUNK (4u << 20)

typedef struct Parser {
    const char *file;
    int line;
    RtScene *s;
    RtError *err;
    RtWarnFn warn;
    void *warn_ctx;
    uint32_t material; /* index of the current material */
    const RtGeomSink *sink; /* parse_chunks's final ranges (rt.h), or NULL */
} Parser;

static inline RtVec3 v3f(const float *f) { return rt_v3(f[0], f[1], f[2]); }

/* ---- scene_lex.c --------------------------------------------------------- */

/* An error at the parser's line ("file:line: message"); returns -1. */
int parse_fail(Parser *p, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;
static inline const char *lex_skip_ws(const char *s)
{
    while (*s == ' ' || *s == '\t')
        s++;
    return s;
}
/* Parses one number at *pp; the token ends at whitespace or end of string.
 * Returns 0 and advances, or -1 when the token is not a finite number. */
int lex_float(const char **pp, float *out);
/* Reads exactly n numbers from the value text. */
int lex_floats(Parser *p, const char *cmd, const char *v, float *out, int n);
/* Reads n non-negative integer indices (also written as 3.0 by exporters). */
int lex_indices(Parser *p, const char *cmd, const char *v, int64_t *out, int n);

/* ---- scene_parse.c ------------------------------------------------------- */

/* A parser at the start of a scene (zeroed, then the defaults). */
int parse_start(Parser *p, const char *name, RtScene *scene, RtWarnFn warn, void *warn_ctx, RtError *err);
/* The lines of buf in order, one at a time. */
int parse_serial(Parser *p, const char *buf, size_t len);
/* Grows a pool to hold one more element. */
int parse_grow(Parser *p, void **arr, uint32_t *cap, uint32_t n, size_t elem, const char *what);
#define GROW(p, field, what) \
    parse_grow((p), (void **)&(p)->s->field, &(p)->s->cap_##field, (p)->s->n##field, sizeof(*(p)->s->field), (what))
/* The line at *pos into `line` (NUL-terminated, the '\n' dropped), *pos
 * moved past it; a line too long or with binary bytes is an error. */
int parse_next_line(Parser *p, const char *buf, size_t len, size_t *pos, char *line);
/* Cuts comment and trailing whitespace off line and splits it at the first
 * ':' into a command name (checked) and its value text. Returns 1 for a
 * blank line, 0 for a command, -1 on error. */
int parse_split(Parser *p, char *line, char **cmd, char **v);
/* One line, as the serial parser runs it. */
int parse_line(Parser *p, char *line);
/* A triangle's record from its checked indices (normal indices in
 * ix[3..5] when `normals`) and its material. */
void parse_set_triangle(RtTriangle *t, const int64_t *ix, int normals, uint32_t material);
/* A triangle with the current material, its indices checked against the
 * nv vertices and nn normals defined before its line. */
int parse_add_triangle(Parser *p, const char *cmd, const int64_t *ix, int normals, uint32_t nv, uint32_t nn);
/* A sphere line's centre and radius (positive), and a sphere with the
 * current material. */
int parse_sphere_values(Parser *p, const char *v, float *f);
int parse_add_sphere(Parser *p, const float *f);

/* ---- scene_chunks.c ------------------------------------------------------ */

/* A buffer of at least 2 * RT_PARSE_CHUNK bytes on nt threads, after
 * parse_start: the serial parser's scene, warnings and first error. */
int parse_chunks(Parser *p, const char *buf, size_t len, int nt);

#endif
