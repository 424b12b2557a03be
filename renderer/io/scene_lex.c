/* scene_lex.c - the parser's lowest layer (scene_parse.h): its errors,
 * which name file and line, and the values of a line: numbers through a
 * fast decimal path (exact for up to 19 significant digits and powers of
 * ten up to 1e22, Clinger 1990) with strtof as the fallback, which is what
 * makes the 500 KB dragon parse in a few ms, and indices read as plain
 * digits or in double, never through float. */
#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>

#include "scene_parse.h"

int parse_fail(Parser *p, const char *fmt, ...)
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

static const double pow10_tab[23] = {1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,  1e7,  1e8,  1e9,  1e10, 1e11,
                                     1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22};

int lex_float(const char **pp, float *out)
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

/* After n values: anything left on the line is an error that counts it. */
static int expect_end(Parser *p, const char *cmd, const char *s, int n)
{
    int extra = 0;
    while (*s) {
        while (*s && *s != ' ' && *s != '\t')
            s++;
        s = lex_skip_ws(s);
        extra++;
    }
    if (extra)
        return parse_fail(p, "%s: expected %d values, got %d", cmd, n, n + extra);
    return 0;
}

int lex_floats(Parser *p, const char *cmd, const char *v, float *out, int n)
{
    const char *s = lex_skip_ws(v);
    for (int i = 0; i < n; i++) {
        if (*s == '\0')
            return parse_fail(p, "%s: expected %d values, got %d", cmd, n, i);
        const char *tok = s;
        if (lex_float(&s, &out[i]) != 0) {
            int len = 0;
            while (tok[len] && tok[len] != ' ' && tok[len] != '\t' && len < 40)
                len++;
            return parse_fail(p, "%s: value %d is not a finite number: '%.*s'", cmd, i + 1, len, tok);
        }
        s = lex_skip_ws(s);
    }
    return expect_end(p, cmd, s, n);
}

/* Reads n non-negative integer indices (also written as 3.0 by exporters).
 * Up to ten plain digits are read in one pass; anything else in double
 * (strtod), never through float: a float holds integers exactly only up
 * to 2^24, and vertex pools may be larger. */
int lex_indices(Parser *p, const char *cmd, const char *v, int64_t *out, int n)
{
    const char *s = lex_skip_ws(v);
    for (int i = 0; i < n; i++) {
        if (*s == '\0')
            return parse_fail(p, "%s: expected %d values, got %d", cmd, n, i);
        const char *tok = s;
        /* plain digits, the common case, in one pass */
        uint64_t u = 0;
        int len = 0;
        while (len < 11 && tok[len] >= '0' && tok[len] <= '9')
            u = u * 10 + (uint64_t)(tok[len++] - '0');
        double d = (double)u; /* exact: < 2^53 */
        if (len == 0 || len > 10 || (tok[len] != '\0' && tok[len] != ' ' && tok[len] != '\t')) {
            while (tok[len] && tok[len] != ' ' && tok[len] != '\t')
                len++;
            char *end;
            errno = 0;
            d = strtod(tok, &end);
            if (end != tok + len || errno == ERANGE || !isfinite(d))
                return parse_fail(p, "%s: value %d is not a finite number: '%.*s'", cmd, i + 1, len < 40 ? len : 40,
                                  tok);
            if (d != floor(d))
                return parse_fail(p, "%s: index %d is not an integer: %.*s", cmd, i + 1, len < 40 ? len : 40, tok);
            if (d < 0.0)
                return parse_fail(p, "%s: index %d is negative: %.*s", cmd, i + 1, len < 40 ? len : 40, tok);
        }
        if (d > 4294967295.0)
            return parse_fail(p, "%s: index %d is out of range: %.*s", cmd, i + 1, len < 40 ? len : 40, tok);
        out[i] = (int64_t)d;
        s = lex_skip_ws(tok + len);
    }
    return expect_end(p, cmd, s, n);
}
