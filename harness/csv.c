/* csv.c: the results schema, crash-safe appending and an RFC 4180 reader.
 *
 * The column set is fixed and versioned by its header line: known record keys
 * get their own columns, keys a newer renderer adds go to one `extra` column
 * as k=v;k=v, so adding a key to `raytrace` never breaks old CSVs or tools. */
#include "hx.h"
#include "raybench/record_schema.h"

#include <errno.h>
#include <fcntl.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

/* The record's columns, from include/raybench/record_schema.h: OWN keys get
 * a column of the record part (in the schema's order, that of existing
 * CSVs), AT keys one elsewhere, EXTRA keys none. */
#define HX_REC_COL_OWN(column) column,
#define HX_REC_COL_AT(column)
#define HX_REC_COL_EXTRA(column)
#define HX_REC_COLUMN(key, type, unit, col_kind, column, who, doc) HX_REC_COL_##col_kind(column)
#define HX_REC_MAP_OWN(key, column) {key, column},
#define HX_REC_MAP_AT(key, column) {key, column},
#define HX_REC_MAP_EXTRA(key, column)
#define HX_REC_MAP(key, type, unit, col_kind, column, who, doc) HX_REC_MAP_##col_kind(#key, column)

const char *const hx_columns[] = {
    /* who, when, where */
    "study", "run_id", "repeat", "utc", "git_commit", "host",
    "cpu_model", "phys_cores", "logical_cpus", "smt", "governor", "compiler",
    "gpu_name", "gpu_driver", "fingerprint",
    /* swept parameters as planned ("-": not set / not applicable) */
    "scene", "scene_path", "backend", "accel", "resolution", "max_depth",
    "tile", "schedule", "threads", "ranks", "mpi_schedule", "block", "pin",
    "workers", "oversubscribed", "baseline",
    /* outcome */
    "status", "status_detail", "exit_code", "wall_ms", "cores_planned",
    "cores_actual", "pin_held",
    /* measured by the harness for every run (wait4): CPU time, peak memory */
    "user_ms", "sys_ms", "maxrss_kib",
    /* the record line, known keys (rec_scene ... rec_gpu) */
    RT_RECORD_KEYS(HX_REC_COLUMN)
    /* provenance: the kernel, the MPI library, the renderer's build, and a
     * hash of the settings that change what a run measures (checked by
     * --resume, which may add runs: harness/resume.c) */
    "kernel", "mpi_version", "build_flags", "config_hash",
    /* command studies: the program, its params (k=v;k=v), its version
     * line and its metrics (name:unit:lower|higher;...) */
    "program", "params", "program_version", "metric_info",
    /* what else the machine did during the run (harness/noise.c): the load
     * at its start, other work in cores, steal and iowait in % of all CPU
     * time, and the verdict: busy, stolen, both or empty */
    "load1", "others_cores", "steal_pct", "iowait_pct", "noise",
    /* every other record key, k=v;k=v */
    "extra",
};
const int hx_ncolumns = (int)(sizeof hx_columns / sizeof hx_columns[0]);

/* record key -> column (the schema's OWN and AT keys); rec_ where the name
 * would collide with a planned value (the record says what the renderer
 * actually did, e.g. its default tile). */
static const char *const record_map[][2] = {RT_RECORD_KEYS(HX_REC_MAP)};

const char *hx_record_column(const char *key)
{
    for (size_t i = 0; i < sizeof record_map / sizeof record_map[0]; i++)
        if (strcmp(key, record_map[i][0]) == 0)
            return record_map[i][1];
    return NULL;
}

int hx_column_index(const char *name)
{
    for (int i = 0; i < hx_ncolumns; i++)
        if (strcmp(hx_columns[i], name) == 0)
            return i;
    return -1;
}

char *hx_record_find(char *out)
{
    char *rec = NULL;
    for (char *p = out; p && (p = strstr(p, "record: ")) != NULL; p++)
        if (p == out || p[-1] == '\n')
            rec = p;
    return rec;
}

void hx_row_set(char **vals, const char *col, const char *v)
{
    int i = hx_column_index(col);
    if (i < 0)
        return;
    free(vals[i]);
    vals[i] = hx_strdup(v ? v : "");
}

int hx_csv_has_values(const HxCsv *csv, const char *col)
{
    for (size_t r = 0; r < csv->nrows; r++)
        if (*hx_csv_get(csv, r, col))
            return 1;
    return 0;
}

/* The record's next key=value word (the record is one line of them) into
 * *key and its value; NULL at the end. Words that are not k=v are skipped
 * rather than failing the run. Cuts copy, as strtok_r. */
static char *record_next(char *copy, char **save, char **val)
{
    for (char *tok = strtok_r(copy, " \t\r\n", save); tok; tok = strtok_r(NULL, " \t\r\n", save)) {
        char *eq = strchr(tok, '=');
        if (eq && eq != tok) {
            *eq = '\0';
            *val = eq + 1;
            return tok;
        }
    }
    return NULL;
}

const char *hx_record_get(const char *line, const char *key, char *out, size_t n)
{
    if (strncmp(line, "record: ", 8) != 0)
        return NULL;
    char *copy = hx_strndup(line + 8, strcspn(line + 8, "\n")), *save = NULL, *val, *first = copy;
    const char *found = NULL;
    for (char *tok; !found && (tok = record_next(first, &save, &val)) != NULL; first = NULL)
        if (strcmp(tok, key) == 0) {
            snprintf(out, n, "%s", val);
            found = out;
        }
    free(copy);
    return found;
}

int hx_record_to_row(const char *line, char **vals)
{
    if (strncmp(line, "record: ", 8) != 0)
        return -1;
    char *copy = hx_strndup(line + 8, strcspn(line + 8, "\n")); /* the record is one line */
    HxBuf extra = {0};
    char *save = NULL, *val, *first = copy;
    int nkeys = 0;
    for (char *tok; (tok = record_next(first, &save, &val)) != NULL; first = NULL) {
        const char *col = hx_record_column(tok);
        int idx = col ? hx_column_index(col) : -1;
        if (idx >= 0) {
            free(vals[idx]);
            vals[idx] = hx_strdup(val);
        } else {
            hx_buf_printf(&extra, "%s%s=%s", extra.len ? ";" : "", tok, val);
        }
        nkeys++;
    }
    if (extra.len) {
        int idx = hx_column_index("extra");
        free(vals[idx]);
        vals[idx] = extra.s;
    } else {
        hx_buf_free(&extra);
    }
    free(copy);
    return nkeys;
}

void hx_csv_field(HxBuf *b, const char *s)
{
    if (!s)
        return;
    if (strpbrk(s, ",\"\n\r") == NULL) {
        hx_buf_put(b, s);
        return;
    }
    hx_buf_put(b, "\"");
    for (const char *p = s; *p; p++) {
        if (*p == '"')
            hx_buf_put(b, "\"");
        hx_buf_putn(b, p, 1);
    }
    hx_buf_put(b, "\"");
}

void hx_csv_format_row(HxBuf *b, const char *const *vals)
{
    for (int i = 0; i < hx_ncolumns; i++) {
        if (i)
            hx_buf_put(b, ",");
        hx_csv_field(b, vals ? vals[i] : hx_columns[i]);
    }
    hx_buf_put(b, "\n");
}

static int write_all(int fd, const char *s, size_t n)
{
    while (n > 0) {
        ssize_t w = write(fd, s, n);
        if (w < 0) {
            if (errno == EINTR)
                continue;
            return -1;
        }
        s += w;
        n -= (size_t)w;
    }
    return 0;
}

/* Cuts a failed write back off; if even that fails, the caller's error
 * (already being reported) is all there is to say. */
static void truncate_to(int fd, off_t len)
{
    if (ftruncate(fd, len) != 0)
        return;
}

int hx_csv_restart(int fd, const char *path, char *err, size_t errlen)
{
    if (ftruncate(fd, 0) != 0) {
        snprintf(err, errlen, "%s: cannot truncate: %s", path, strerror(errno));
        close(fd);
        return -1;
    }
    HxBuf header = {0};
    hx_csv_format_row(&header, NULL);
    int rc = write_all(fd, header.s, header.len);
    hx_buf_free(&header);
    if (rc || fsync(fd) != 0) {
        snprintf(err, errlen, "%s: write failed: %s", path, strerror(errno));
        truncate_to(fd, 0); /* a torn header is worse than none */
        close(fd);
        return -1;
    }
    return fd;
}

int hx_csv_open_append(const char *path, int truncate_it, char *err, size_t errlen)
{
    struct stat st;
    /* a device or FIFO is no CSV: /dev/full or /dev/zero would be read forever */
    if (stat(path, &st) == 0 && !S_ISREG(st.st_mode)) {
        snprintf(err, errlen, "%s: not a regular file", path);
        return -1;
    }
    /* O_CLOEXEC: no run's process keeps the file, or its lock, open */
    int fd = open(path, O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (fd < 0) {
        snprintf(err, errlen, "%s: cannot open for writing: %s", path, strerror(errno));
        return -1;
    }
    /* One writer per CSV for the whole study, taken before anything is
     * truncated: two studies appending to one file interleave and lose rows. */
    if (flock(fd, LOCK_EX | LOCK_NB) != 0) {
        if (errno == EWOULDBLOCK)
            snprintf(err, errlen, "%s: another harness run is writing it; wait for it to end or "
                     "write to another file", path);
        else
            snprintf(err, errlen, "%s: cannot lock: %s", path, strerror(errno));
        close(fd);
        return -1;
    }
    if (truncate_it == HX_CSV_LOCK_ONLY)
        return fd;
    fstat(fd, &st);
    if (truncate_it || st.st_size == 0)
        return hx_csv_restart(fd, path, err, errlen);
    HxBuf header = {0};
    hx_csv_format_row(&header, NULL);
    /* An existing file must have our exact header: mixing schemas in one
     * file would silently shift columns. */
    char *buf = hx_xmalloc(header.len + 1);
    ssize_t n = pread(fd, buf, header.len, 0);
    int same = n == (ssize_t)header.len && memcmp(buf, header.s, header.len) == 0;
    free(buf);
    hx_buf_free(&header);
    if (!same) {
        snprintf(err, errlen, "%s: header differs from this harness's CSV schema; write to a new file", path);
        close(fd);
        return -1;
    }
    /* A row cut short by a power loss (no final newline) is dropped so the
     * next row does not glue onto it; write() of one row is otherwise whole. */
    char last;
    if (pread(fd, &last, 1, st.st_size - 1) == 1 && last != '\n') {
        off_t pos = st.st_size - 1;
        char c;
        while (pos > 0 && pread(fd, &c, 1, pos - 1) == 1 && c != '\n')
            pos--;
        fprintf(stderr, "harness: %s: dropping a torn last row\n", path);
        if (ftruncate(fd, pos) != 0) {
            snprintf(err, errlen, "%s: cannot truncate torn row: %s", path, strerror(errno));
            close(fd);
            return -1;
        }
    }
    lseek(fd, 0, SEEK_END);
    return fd;
}

int hx_csv_append_row(int fd, const char *const *vals)
{
    HxBuf row = {0};
    hx_csv_format_row(&row, vals);
    /* one write() per row + fsync: an interrupted study leaves whole rows.
     * A write or fsync that fails (a full disk) is cut back off, so the file
     * never ends in part of a row. */
    off_t before = lseek(fd, 0, SEEK_END);
    int rc = write_all(fd, row.s, row.len);
    if (rc == 0 && fsync(fd) != 0)
        rc = -1;
    hx_buf_free(&row);
    if (rc != 0 && before >= 0) {
        int e = errno;
        truncate_to(fd, before);
        errno = e;
    }
    return rc;
}

/* ---- reader ----
 * The file's text is read once and parsed in place: each field is unquoted
 * where it stands and NUL-terminated, and a row keeps only the offsets of
 * its fields. A field therefore costs its own bytes plus 4, so reading a CSV
 * takes about 1.5x its size (a field of its own allocation took 256 bytes
 * or more: a million-row study needed gigabytes). */

typedef struct {
    char *p, *w;   /* read and write positions: w <= p, text before w is parsed */
    int line;
} Cursor;

/* One field at c->p, unquoted at c->w and NUL-terminated there. Returns 1
 * when a comma follows (more fields), 0 at the row's end (a newline, CRLF,
 * a lone CR or the text's end), -1 for a quoted field that never closes. */
static int next_field(Cursor *c)
{
    if (*c->p == '"') {
        c->p++;
        for (;;) {
            if (*c->p == '\0')
                return -1;
            if (*c->p == '"' && c->p[1] != '"') {
                c->p++;
                break;
            }
            if (*c->p == '"')
                c->p++; /* "" is one quote */
            else if (*c->p == '\n')
                c->line++;
            *c->w++ = *c->p++;
        }
    }
    while (*c->p && *c->p != ',' && *c->p != '\n' && *c->p != '\r')
        *c->w++ = *c->p++;
    /* the delimiter is consumed before the NUL goes where it may have been */
    char d = *c->p;
    if (d == ',' || d == '\r')
        c->p++;
    if (d != ',' && *c->p == '\n') {
        c->p++;
        c->line++;
    }
    *c->w++ = '\0';
    return d == ',';
}

/* One row: the offset of each field from the row's start into off[0..max)
 * (fields past max are only counted). Returns the field count, -1 for an
 * unterminated quote, -2 for a row over 4 GiB (its offsets would not fit). */
static int next_row(Cursor *c, uint32_t *off, int max)
{
    const char *row = c->w;
    int n = 0, more;
    do {
        size_t at = (size_t)(c->w - row);
        if (at > UINT32_MAX)
            return -2;
        if (n < max)
            off[n] = (uint32_t)at;
        n++;
        more = next_field(c);
    } while (more == 1);
    return more < 0 ? -1 : n;
}

/* After a parse error in the last row of a file that does not end in a
 * newline: that row was cut short (a killed study, a full disk). p is where
 * parsing stopped; the text from there on is as read. */
static void torn_hint(int ends_nl, const char *p, char *err, size_t errlen)
{
    size_t used = strlen(err);
    if (!ends_nl && !strchr(p, '\n') && used < errlen)
        snprintf(err + used, errlen - used, "; the last row is torn (cut short): `harness run CONFIG "
                 "-o FILE --resume` drops it and runs it again");
}

/* The header's names, pointing into the text. 0, or -1 with err. */
static int parse_header(Cursor *c, HxCsv *csv, char *err, size_t errlen)
{
    int cap = 0, more;
    do {
        if (csv->ncol == cap) {
            cap = cap ? 2 * cap : 64;
            csv->cols = hx_xrealloc(csv->cols, (size_t)cap * sizeof *csv->cols);
        }
        csv->cols[csv->ncol++] = c->w;
        more = next_field(c);
    } while (more == 1);
    if (more < 0)
        snprintf(err, errlen, "line 1: unterminated quoted field");
    return more < 0 ? -1 : 0;
}

/* Room for row csv->nrows: the first guess is one row per newline, which a
 * file with lone CRs as line ends outgrows. */
static void reserve_row(HxCsv *csv, size_t *cap)
{
    if (csv->nrows < *cap)
        return;
    *cap = *cap ? 2 * *cap : 64;
    csv->row_at = hx_xrealloc(csv->row_at, *cap * sizeof *csv->row_at);
    csv->field_at = hx_xrealloc(csv->field_at, *cap * (size_t)csv->ncol * sizeof *csv->field_at);
}

static int parse_rows(Cursor *c, HxCsv *csv, int ends_nl, char *err, size_t errlen)
{
    size_t cap = 1;
    for (const char *q = c->p; (q = strchr(q, '\n')) != NULL; q++)
        cap++;
    csv->row_at = hx_xmalloc(cap * sizeof *csv->row_at);
    csv->field_at = hx_xmalloc(cap * (size_t)csv->ncol * sizeof *csv->field_at);
    while (*c->p) {
        reserve_row(csv, &cap);
        int start_line = c->line;
        char *row = c->w;
        int n = next_row(c, csv->field_at + csv->nrows * (size_t)csv->ncol, csv->ncol);
        if (n == -1)
            snprintf(err, errlen, "line %d: unterminated quoted field", start_line);
        else if (n == -2)
            snprintf(err, errlen, "line %d: a row over 4 GiB", start_line);
        else if (n == 1 && *row == '\0')
            continue; /* blank line */
        else if (n != csv->ncol)
            snprintf(err, errlen, "line %d: %d fields, header has %d", start_line, n, csv->ncol);
        if (n < 0 || n != csv->ncol) {
            torn_hint(ends_nl, c->p, err, errlen);
            return -1;
        }
        csv->row_at[csv->nrows++] = (size_t)(row - csv->text);
    }
    /* the harness ends every row it writes with a newline: in its own CSV,
     * a last row without one was cut short, maybe inside its last field,
     * where the count of fields cannot tell; it is left out, and said
     * (hx_csv_read) */
    if (!ends_nl && csv->nrows > 0 && csv->ncol >= 2 && strcmp(csv->cols[0], "study") == 0 &&
        strcmp(csv->cols[1], "run_id") == 0) {
        csv->torn_line = c->line;
        csv->nrows--;
    }
    return 0;
}

int hx_csv_parse_buf(HxBuf *text, HxCsv *csv, char *err, size_t errlen)
{
    memset(csv, 0, sizeof *csv);
    csv->text = text->s ? text->s : hx_strdup("");
    size_t len = text->s ? text->len : 0;
    text->s = NULL;
    text->len = text->cap = 0;
    Cursor c = {csv->text, csv->text, 1};
    if (!*c.p) {
        snprintf(err, errlen, "empty file (no header)");
        hx_csv_free(csv);
        return -1;
    }
    int ends_nl = len > 0 && csv->text[len - 1] == '\n';
    if (parse_header(&c, csv, err, errlen) != 0 || parse_rows(&c, csv, ends_nl, err, errlen) != 0) {
        hx_csv_free(csv);
        return -1;
    }
    return 0;
}

int hx_csv_parse(const char *text, HxCsv *csv, char *err, size_t errlen)
{
    HxBuf b = {0};
    hx_buf_put(&b, text);
    return hx_csv_parse_buf(&b, csv, err, errlen);
}

int hx_csv_read_text(const char *path, HxBuf *b)
{
    int fd = open(path, O_RDONLY | O_CLOEXEC);
    if (fd < 0)
        return -1;
    /* sized once from the file's size: growing by doubling could hold
     * twice the file */
    struct stat st;
    if (fstat(fd, &st) == 0 && S_ISREG(st.st_mode) && st.st_size > 0) {
        b->cap = b->len + (size_t)st.st_size + 1;
        b->s = hx_xrealloc(b->s, b->cap);
    }
    for (;;) {
        char more[65536];
        int full = b->len + 1 >= b->cap; /* the file grew, or its size was unknown */
        ssize_t r = full ? read(fd, more, sizeof more) : read(fd, b->s + b->len, b->cap - b->len - 1);
        if (r < 0 && errno == EINTR)
            continue;
        if (r <= 0) {
            int e = errno;
            close(fd);
            if (b->s)
                b->s[b->len] = '\0';
            errno = e;
            return r < 0 ? -1 : 0;
        }
        if (full)
            hx_buf_putn(b, more, (size_t)r);
        else
            b->len += (size_t)r;
    }
}

int hx_csv_read(const char *path, HxCsv *csv, char *err, size_t errlen)
{
    memset(csv, 0, sizeof *csv);
    HxBuf b = {0};
    if (hx_csv_read_text(path, &b) != 0) {
        snprintf(err, errlen, "%s: cannot read: %s", path, strerror(errno));
        hx_buf_free(&b);
        return -1;
    }
    char e[256];
    int rc = hx_csv_parse_buf(&b, csv, e, sizeof e);
    if (rc)
        snprintf(err, errlen, "%s: %s", path, e);
    else if (csv->torn_line)
        fprintf(stderr, "harness: %s: line %d has no line end: left out as torn (cut short; `harness run CONFIG "
                        "-o FILE --resume` runs it again; a whole row needs only its newline)\n", path,
                csv->torn_line);
    return rc;
}

void hx_csv_free(HxCsv *csv)
{
    free(csv->text);
    free(csv->cols);
    free(csv->row_at);
    free(csv->field_at);
    memset(csv, 0, sizeof *csv);
}

int hx_csv_col(const HxCsv *csv, const char *name)
{
    for (int i = 0; i < csv->ncol; i++)
        if (strcmp(csv->cols[i], name) == 0)
            return i;
    return -1;
}

const char *hx_csv_cell(const HxCsv *csv, size_t row, int col)
{
    return csv->text + csv->row_at[row] + csv->field_at[row * (size_t)csv->ncol + (size_t)col];
}

const char *hx_csv_get(const HxCsv *csv, size_t row, const char *name)
{
    int c = hx_csv_col(csv, name);
    return c < 0 ? "" : hx_csv_cell(csv, row, c);
}
