/* util.c: string lists, growable buffers and number parsing.
 * Allocation failure aborts with a message: the harness is a short-lived
 * command and has nothing sensible to do without memory. */
#include "hx.h"

#include <ctype.h>
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <signal.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

void *hx_xmalloc(size_t n)
{
    void *p = malloc(n ? n : 1);
    if (!p) {
        fputs("harness: out of memory\n", stderr);
        abort();
    }
    return p;
}

void *hx_xrealloc(void *p, size_t n)
{
    void *q = realloc(p, n ? n : 1);
    if (!q) {
        fputs("harness: out of memory\n", stderr);
        abort();
    }
    return q;
}

char *hx_strndup(const char *s, size_t n)
{
    char *d = hx_xmalloc(n + 1);
    memcpy(d, s, n);
    d[n] = '\0';
    return d;
}

char *hx_label_drop(const char *label, const char *key)
{
    char *lab = hx_strdup(label);
    HxBuf tok = {0};
    hx_buf_printf(&tok, " %s=", key);
    char *at = strstr(lab, tok.s);
    if (at) {
        char *end = strchr(at + 1, ' ');
        const char *rest = end ? end : at + strlen(at);
        memmove(at, rest, strlen(rest) + 1);
    }
    hx_buf_free(&tok);
    return lab;
}

char *hx_strdup(const char *s)
{
    return hx_strndup(s, strlen(s));
}

void hx_strlist_push(HxStrList *l, const char *s)
{
    if (l->n == l->cap) {
        l->cap = l->cap ? 2 * l->cap : 8;
        l->v = hx_xrealloc(l->v, l->cap * sizeof *l->v);
    }
    l->v[l->n++] = hx_strdup(s);
}

static int cmp_str_ptr(const void *a, const void *b)
{
    return strcmp(*(char *const *)a, *(char *const *)b);
}

const char *hx_strlist_twice(const HxStrList *l)
{
    if (l->n < 2)
        return NULL;
    /* sorted, so a long list (param n: 1..100000) costs n log n, not n^2 */
    char **s = hx_xmalloc(l->n * sizeof *s);
    memcpy(s, l->v, l->n * sizeof *s);
    qsort(s, l->n, sizeof *s, cmp_str_ptr);
    const char *twice = NULL;
    for (size_t i = 1; i < l->n && !twice; i++)
        if (strcmp(s[i - 1], s[i]) == 0)
            twice = s[i];
    free(s);
    return twice;
}

void hx_strlist_free(HxStrList *l)
{
    for (size_t i = 0; i < l->n; i++)
        free(l->v[i]);
    free(l->v);
    l->v = NULL;
    l->n = l->cap = 0;
}

int hx_strlist_find(const HxStrList *l, const char *s)
{
    for (size_t i = 0; i < l->n; i++)
        if (strcmp(l->v[i], s) == 0)
            return (int)i;
    return -1;
}

static void buf_reserve(HxBuf *b, size_t extra)
{
    if (b->len + extra + 1 > b->cap) {
        size_t c = b->cap ? b->cap : 256;
        while (c < b->len + extra + 1)
            c *= 2;
        b->s = hx_xrealloc(b->s, c);
        b->cap = c;
    }
}

void hx_buf_putn(HxBuf *b, const char *s, size_t n)
{
    buf_reserve(b, n);
    memcpy(b->s + b->len, s, n);
    b->len += n;
    b->s[b->len] = '\0';
}

void hx_buf_put(HxBuf *b, const char *s)
{
    hx_buf_putn(b, s, strlen(s));
}

void hx_buf_printf(HxBuf *b, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    int n = vsnprintf(NULL, 0, fmt, ap);
    va_end(ap);
    if (n < 0)
        return;
    buf_reserve(b, (size_t)n);
    va_start(ap, fmt);
    vsnprintf(b->s + b->len, (size_t)n + 1, fmt, ap);
    va_end(ap);
    b->len += (size_t)n;
}

void hx_buf_free(HxBuf *b)
{
    free(b->s);
    b->s = NULL;
    b->len = b->cap = 0;
}

char *hx_trim(char *s)
{
    while (isspace((unsigned char)*s))
        s++;
    size_t n = strlen(s);
    while (n > 0 && isspace((unsigned char)s[n - 1]))
        s[--n] = '\0';
    return s;
}

int hx_parse_int(const char *s, long lo, long hi, long *out)
{
    char *end;
    errno = 0;
    long v = strtol(s, &end, 10);
    if (errno || end == s || *end != '\0' || v < lo || v > hi)
        return -1;
    *out = v;
    return 0;
}

int hx_parse_double(const char *s, double *out)
{
    char *end;
    errno = 0;
    double v = strtod(s, &end);
    if (errno || end == s || *end != '\0' || !isfinite(v))
        return -1;
    *out = v;
    return 0;
}

int hx_parse_wxh(const char *s, long *w, long *h)
{
    const char *x = strchr(s, 'x');
    if (!x)
        return -1;
    char a[32], b[32];
    size_t na = (size_t)(x - s), nb = strlen(x + 1);
    if (na == 0 || nb == 0 || na >= sizeof a || nb >= sizeof b)
        return -1;
    memcpy(a, s, na);
    a[na] = '\0';
    memcpy(b, x + 1, nb + 1);
    return (hx_parse_int(a, 1, 1 << 20, w) || hx_parse_int(b, 1, 1 << 20, h)) ? -1 : 0;
}

double hx_now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

int hx_file_exists(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0 && S_ISREG(st.st_mode);
}

int hx_is_dir(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0 && S_ISDIR(st.st_mode);
}

int hx_may_replace(const char *who, const char *path, const char *own)
{
    struct stat st;
    if (stat(path, &st) != 0)
        return errno == ENOENT ? 0 : (fprintf(stderr, "%s: %s: %s\n", who, path, strerror(errno)), -1);
    char head[256] = "";
    const size_t n = strlen(own) < sizeof head - 1 ? strlen(own) : sizeof head - 1;
    if (S_ISREG(st.st_mode) && st.st_size > 0) {
        FILE *f = fopen(path, "r");
        const size_t got = f ? fread(head, 1, n, f) : 0;
        if (f)
            fclose(f);
        if (got == n && memcmp(head, own, n) == 0)
            return 0;
    } else if (S_ISREG(st.st_mode)) {
        return 0;
    }
    fprintf(stderr, "%s: %s: %s; move it away or choose another -o\n", who, path,
            S_ISREG(st.st_mode) ? "holds something else, which this would overwrite" : "not a regular file");
    return -1;
}

char *hx_dirname(const char *path)
{
    const char *slash = strrchr(path, '/');
    if (!slash)
        return hx_strdup(".");
    if (slash == path)
        return hx_strdup("/");
    return hx_strndup(path, (size_t)(slash - path));
}

char *hx_path_join(const char *a, const char *b)
{
    if (b[0] == '/' || a[0] == '\0' || strcmp(a, ".") == 0)
        return hx_strdup(b);
    HxBuf buf = {0};
    hx_buf_put(&buf, a);
    if (a[strlen(a) - 1] != '/')
        hx_buf_put(&buf, "/");
    hx_buf_put(&buf, b);
    return buf.s;
}

char *hx_temp_dir(const char *name, char *err, size_t n)
{
    const char *root = getenv("TMPDIR");
    if (!root || !*root)
        root = "/tmp";
    HxBuf t = {0};
    hx_buf_printf(&t, "%s/harness-%s-XXXXXX", root, name);
    if (mkdtemp(t.s))
        return t.s;
    snprintf(err, n, "cannot create a temporary folder in %s: %s", root, strerror(errno));
    hx_buf_free(&t);
    return NULL;
}

int hx_cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

const char *hx_read_error(int e)
{
    return e == EINVAL ? "not a regular file (a device?)" : strerror(e);
}

int hx_read_file(const char *path, HxBuf *b)
{
    FILE *f = fopen(path, "rb");
    if (!f)
        return -1;
    /* a folder, or a device that never ends (/dev/zero), is no file to
     * read whole; a pipe is (a shell's <(...)), up to a size */
    struct stat st;
    if (fstat(fileno(f), &st) != 0) {
        const int e = errno;
        fclose(f);
        errno = e;
        return -1;
    }
    if (!(S_ISREG(st.st_mode) || S_ISFIFO(st.st_mode))) {
        errno = S_ISDIR(st.st_mode) ? EISDIR : EINVAL;
        fclose(f);
        return -1;
    }
    char chunk[65536];
    size_t n;
    int big = 0;
    while (!big && (n = fread(chunk, 1, sizeof chunk, f)) > 0) {
        hx_buf_putn(b, chunk, n);
        big = b->len > HX_READ_MAX;
    }
    int bad = ferror(f);
    fclose(f);
    if (bad || big) {
        errno = big ? EFBIG : EIO;
        return -1;
    }
    return 0;
}

int hx_run_argv(char *const argv[], const char *dir, char *out, size_t n, int quiet)
{
    if (out && n)
        out[0] = '\0';
    int fd[2] = {-1, -1};
    if (out && pipe(fd) != 0)
        return 127;
    pid_t pid = fork();
    if (pid < 0) {
        if (out) {
            close(fd[0]);
            close(fd[1]);
        }
        return 127;
    }
    if (pid == 0) {
        signal(SIGINT, SIG_DFL); /* not the harness's handler until exec */
        signal(SIGTERM, SIG_DFL);
        int null = open("/dev/null", O_RDWR);
        if (out) {
            dup2(fd[1], STDOUT_FILENO);
            close(fd[0]);
            close(fd[1]);
        } else if (null >= 0) {
            dup2(null, STDOUT_FILENO);
        }
        if (quiet && null >= 0)
            dup2(null, STDERR_FILENO);
        if (null > STDERR_FILENO)
            close(null);
        if (dir && chdir(dir) != 0)
            _exit(127);
        execvp(argv[0], argv);
        _exit(127);
    }
    if (out) {
        close(fd[1]);
        size_t len = 0;
        char chunk[512];
        ssize_t r;
        /* read to the end, so the child never blocks on a full pipe */
        while ((r = read(fd[0], chunk, sizeof chunk)) > 0 || (r < 0 && errno == EINTR))
            for (ssize_t k = 0; k < r; k++)
                if (len + 1 < n)
                    out[len++] = chunk[k];
        out[len] = '\0';
        close(fd[0]);
    }
    int st;
    while (waitpid(pid, &st, 0) < 0)
        if (errno != EINTR)
            return 127;
    return WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
}

void hx_gp_quote(HxBuf *b, const char *s)
{
    hx_buf_put(b, "'");
    for (const unsigned char *p = (const unsigned char *)s; *p; p++) {
        if (*p == '\'')
            hx_buf_put(b, "''");
        else if (hx_is_ctrl(*p))
            hx_buf_put(b, "?");
        else
            hx_buf_putn(b, (const char *)p, 1);
    }
    hx_buf_put(b, "'");
}

void hx_fput_clean(FILE *o, const char *s, int md)
{
    for (const unsigned char *p = (const unsigned char *)s; *p; p++) {
        if (hx_is_ctrl(*p))
            fputc('?', o);
        else if (md && *p == '|')
            fputs("\\|", o);
        else
            fputc(*p, o);
    }
}

void hx_put_clean_line(FILE *o, const char *fmt, ...)
{
    HxBuf b = {0};
    va_list ap;
    va_start(ap, fmt);
    int n = vsnprintf(NULL, 0, fmt, ap);
    va_end(ap);
    if (n > 0) {
        b.s = hx_xmalloc((size_t)n + 1);
        va_start(ap, fmt);
        vsnprintf(b.s, (size_t)n + 1, fmt, ap);
        va_end(ap);
        hx_fput_clean(o, b.s, 0);
    }
    fputc('\n', o);
    hx_buf_free(&b);
}

int hx_has_ctrl(const char *s)
{
    for (const unsigned char *p = (const unsigned char *)s; *p; p++)
        if (hx_is_ctrl(*p))
            return 1;
    return 0;
}

/* Length of the valid UTF-8 sequence at p (1-4), or 0 if it is not one. */
static int utf8_len(const unsigned char *p)
{
    int n = p[0] < 0x80 ? 1 : (p[0] & 0xe0) == 0xc0 ? 2 : (p[0] & 0xf0) == 0xe0 ? 3 : (p[0] & 0xf8) == 0xf0 ? 4 : 0;
    if (n == 2 && p[0] < 0xc2)
        return 0; /* overlong */
    for (int k = 1; k < n; k++)
        if ((p[k] & 0xc0) != 0x80)
            return 0;
    return n;
}

void hx_json_str(FILE *o, const char *v)
{
    fputc('"', o);
    for (const unsigned char *p = (const unsigned char *)(v ? v : ""); *p;) {
        int n = utf8_len(p);
        if (*p == '"' || *p == '\\')
            fprintf(o, "\\%c", *p);
        else if (*p < 0x20)
            fprintf(o, "\\u%04x", *p);
        else if (n == 0) /* not UTF-8 (a name from a CSV): the replacement character */
            fputs("\\ufffd", o);
        else
            fwrite(p, 1, (size_t)n, o);
        p += n ? n : 1;
    }
    fputc('"', o);
}

static void json_num(FILE *o, double v)
{
    if (isnan(v) || isinf(v))
        fputs("null", o);
    else
        fprintf(o, "%.6g", v);
}

void hx_json_num(FILE *o, const char *key, double v)
{
    fprintf(o, ", \"%s\": ", key);
    json_num(o, v);
}

void hx_json_pair(FILE *o, const char *key, double a, double b)
{
    fprintf(o, ", \"%s\": [", key);
    json_num(o, a);
    fputs(", ", o);
    json_num(o, b);
    fputc(']', o);
}

void hx_json_kstr(FILE *o, const char *key, const char *v)
{
    fprintf(o, ", \"%s\": ", key);
    hx_json_str(o, v);
}

void hx_fnv1a_hex(const char *s, char out[20])
{
    uint64_t h = 1469598103934665603ull;
    for (const unsigned char *p = (const unsigned char *)s; p && *p; p++) {
        h ^= *p;
        h *= 1099511628211ull;
    }
    snprintf(out, 20, "%016llx", (unsigned long long)h);
}

const char *hx_kv_get_sep(const char *list, const char *key, char sep, char *out, size_t n)
{
    size_t kl = strlen(key);
    for (const char *k = list; (k = strstr(k, key)) != NULL; k += kl) {
        if ((k != list && k[-1] != ';') || k[kl] != sep)
            continue;
        size_t m = 0;
        for (k += kl + 1; *k && *k != ';' && m + 1 < n; k++)
            out[m++] = *k;
        out[m] = '\0';
        return out;
    }
    return NULL;
}

const char *hx_kv_get(const char *list, const char *key, char *out, size_t n)
{
    return hx_kv_get_sep(list, key, '=', out, n);
}

char *hx_which(const char *name)
{
    if (strchr(name, '/'))
        return access(name, X_OK) == 0 && !hx_is_dir(name) ? realpath(name, NULL) : NULL;
    const char *path = getenv("PATH");
    for (const char *d = path ? path : "/usr/bin:/bin"; d && *d;) {
        size_t dl = strcspn(d, ":");
        HxBuf f = {0};
        hx_buf_printf(&f, "%.*s/%s", (int)dl, d, name);
        char *abs = dl && access(f.s, X_OK) == 0 && !hx_is_dir(f.s) ? realpath(f.s, NULL) : NULL;
        hx_buf_free(&f);
        if (abs)
            return abs;
        d = d[dl] ? d + dl + 1 : NULL;
    }
    return NULL;
}

/* The configuration without its unset values ("key=-"), for people. */
void hx_config_label(char *dst, size_t n, const char *config)
{
    size_t m = 0;
    const char *w = config;
    while (*w && m + 1 < n) {
        size_t len = strcspn(w, " ");
        int unset = len >= 2 && w[len - 1] == '-' && w[len - 2] == '=';
        if (!unset && len > 0) {
            m += (size_t)snprintf(dst + m, n - m, "%s%.*s", m ? " " : "", (int)len, w);
            m = m < n ? m : n - 1;
        }
        w += len + (w[len] == ' ');
    }
    dst[m] = '\0';
}

const char *hx_first_line(const char *s, int *n)
{
    s = s ? s + strspn(s, " \n") : "";
    *n = (int)strcspn(s, "\n");
    return s;
}

void hx_html_put(FILE *o, const char *s)
{
    for (const unsigned char *p = (const unsigned char *)(s ? s : ""); *p; p++) {
        switch (*p) {
        case '&': fputs("&amp;", o); break;
        case '<': fputs("&lt;", o); break;
        case '>': fputs("&gt;", o); break;
        case '"': fputs("&quot;", o); break;
        case '\'': fputs("&#39;", o); break;
        default: fputc(hx_is_ctrl(*p) ? ' ' : *p, o);
        }
    }
}
