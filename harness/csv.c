/* csv.c: the results schema, crash-safe appending and an RFC 4180 reader.
 *
 * The column set is fixed and versioned by its header line: known record keys
 * get their own columns, keys a newer renderer adds go to one `extra` column
 * as k=v;k=v, so adding a key to `raytrace` never breaks old CSVs or tools. */
#include "hx.h"

#include <errno.h>
#include <fcntl.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

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
    /* the record line, known keys */
    "rec_scene", "width", "height", "rec_backend", "rec_accel", "rec_threads",
    "rec_ranks", "parse_ms", "build_ms", "render_ms", "write_ms", "total_ms",
    "rays", "primary_rays", "shadow_rays", "secondary_rays", "node_visits",
    "prim_tests", "mrays_per_s", "image_fnv1a", "rec_tile", "rec_schedule",
    "rec_mpi_schedule", "render_ms_min", "rec_block", "upload_ms",
    "download_ms", "rec_wall_ms", "rec_gpu",
    /* provenance: the kernel, the MPI library, the renderer's build, and a
     * hash of the study's expanded configuration (checked by --resume) */
    "kernel", "mpi_version", "build_flags", "config_hash",
    /* every other record key, k=v;k=v */
    "extra",
};
const int hx_ncolumns = (int)(sizeof hx_columns / sizeof hx_columns[0]);

/* record key -> column, where the name would collide with a planned value
 * (the record says what the renderer actually did, e.g. its default tile). */
static const char *const record_map[][2] = {
    {"scene", "rec_scene"}, {"backend", "rec_backend"}, {"accel", "rec_accel"},
    {"threads", "rec_threads"}, {"ranks", "rec_ranks"}, {"tile", "rec_tile"},
    {"schedule", "rec_schedule"}, {"mpi_schedule", "rec_mpi_schedule"},
    {"block", "rec_block"}, {"wall_ms", "rec_wall_ms"}, {"gpu", "rec_gpu"},
    {"cores", "cores_actual"},
    {"width", "width"}, {"height", "height"}, {"parse_ms", "parse_ms"},
    {"build_ms", "build_ms"}, {"render_ms", "render_ms"}, {"write_ms", "write_ms"},
    {"total_ms", "total_ms"}, {"rays", "rays"}, {"primary_rays", "primary_rays"},
    {"shadow_rays", "shadow_rays"}, {"secondary_rays", "secondary_rays"},
    {"node_visits", "node_visits"}, {"prim_tests", "prim_tests"},
    {"mrays_per_s", "mrays_per_s"}, {"image_fnv1a", "image_fnv1a"},
    {"render_ms_min", "render_ms_min"}, {"upload_ms", "upload_ms"},
    {"download_ms", "download_ms"},
};

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

int hx_record_to_row(const char *line, char **vals)
{
    if (strncmp(line, "record: ", 8) != 0)
        return -1;
    char *copy = hx_strdup(line + 8);
    HxBuf extra = {0};
    char *save = NULL;
    int nkeys = 0;
    for (char *tok = strtok_r(copy, " \t\r\n", &save); tok; tok = strtok_r(NULL, " \t\r\n", &save)) {
        char *eq = strchr(tok, '=');
        if (!eq || eq == tok)
            continue; /* not k=v: ignore rather than fail the run */
        *eq = '\0';
        const char *col = hx_record_column(tok);
        int idx = col ? hx_column_index(col) : -1;
        if (idx >= 0) {
            free(vals[idx]);
            vals[idx] = hx_strdup(eq + 1);
        } else {
            hx_buf_printf(&extra, "%s%s=%s", extra.len ? ";" : "", tok, eq + 1);
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
    if (truncate_it && ftruncate(fd, 0) != 0) {
        snprintf(err, errlen, "%s: cannot truncate: %s", path, strerror(errno));
        close(fd);
        return -1;
    }
    HxBuf header = {0};
    hx_csv_format_row(&header, NULL);
    fstat(fd, &st);
    if (st.st_size == 0) {
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

/* ---- reader ---- */

static void push_field(char ***row, int *n, int *cap, HxBuf *f)
{
    if (*n == *cap) {
        *cap = *cap ? 2 * *cap : 32;
        *row = hx_xrealloc(*row, (size_t)*cap * sizeof **row);
    }
    (*row)[(*n)++] = f->s ? f->s : hx_strdup("");
    f->s = NULL;
    f->len = f->cap = 0;
}

/* After a parse error in the last row of a file that does not end in a
 * newline: that row was cut short (a killed study, a full disk). */
static void torn_hint(const char *text, const char *p, char *err, size_t errlen)
{
    size_t len = strlen(text), used = strlen(err);
    if (len && text[len - 1] != '\n' && !strchr(p, '\n') && used < errlen)
        snprintf(err + used, errlen - used, "; the last row is torn (cut short): `harness run CONFIG "
                 "-o FILE --resume` drops it and runs it again");
}

int hx_csv_parse(const char *text, HxCsv *csv, char *err, size_t errlen)
{
    memset(csv, 0, sizeof *csv);
    size_t rcap = 0;
    const char *p = text;
    int line = 1;
    while (*p) {
        char **row = NULL;
        int n = 0, cap = 0;
        HxBuf f = {0};
        int start_line = line;
        for (;;) {
            if (*p == '"') {
                p++;
                for (;;) {
                    if (*p == '\0') {
                        snprintf(err, errlen, "line %d: unterminated quoted field", start_line);
                        torn_hint(text, p, err, errlen);
                        hx_buf_free(&f);
                        for (int i = 0; i < n; i++)
                            free(row[i]);
                        free(row);
                        hx_csv_free(csv);
                        return -1;
                    }
                    if (*p == '"' && p[1] == '"') {
                        hx_buf_putn(&f, "\"", 1);
                        p += 2;
                    } else if (*p == '"') {
                        p++;
                        break;
                    } else {
                        if (*p == '\n')
                            line++;
                        hx_buf_putn(&f, p++, 1);
                    }
                }
            }
            while (*p && *p != ',' && *p != '\n' && *p != '\r')
                hx_buf_putn(&f, p++, 1);
            push_field(&row, &n, &cap, &f);
            if (*p == ',') {
                p++;
                continue;
            }
            if (*p == '\r')
                p++;
            if (*p == '\n') {
                p++;
                line++;
            }
            break;
        }
        if (csv->ncol == 0 && csv->cols == NULL) {
            csv->cols = row;
            csv->ncol = n;
            continue;
        }
        if (n == 1 && row[0][0] == '\0') { /* blank line */
            free(row[0]);
            free(row);
            continue;
        }
        if (n != csv->ncol) {
            snprintf(err, errlen, "line %d: %d fields, header has %d", start_line, n, csv->ncol);
            torn_hint(text, p, err, errlen);
            for (int i = 0; i < n; i++)
                free(row[i]);
            free(row);
            hx_csv_free(csv);
            return -1;
        }
        if (csv->nrows == rcap) {
            rcap = rcap ? 2 * rcap : 64;
            csv->rows = hx_xrealloc(csv->rows, rcap * sizeof *csv->rows);
        }
        csv->rows[csv->nrows++] = row;
    }
    if (!csv->cols) {
        snprintf(err, errlen, "empty file (no header)");
        return -1;
    }
    return 0;
}

int hx_csv_read(const char *path, HxCsv *csv, char *err, size_t errlen)
{
    memset(csv, 0, sizeof *csv);
    HxBuf b = {0};
    if (hx_read_file(path, &b) != 0) {
        snprintf(err, errlen, "%s: cannot read: %s", path, strerror(errno));
        hx_buf_free(&b);
        return -1;
    }
    char e[256];
    int rc = hx_csv_parse(b.s ? b.s : "", csv, e, sizeof e);
    hx_buf_free(&b);
    if (rc)
        snprintf(err, errlen, "%s: %s", path, e);
    return rc;
}

void hx_csv_free(HxCsv *csv)
{
    for (size_t r = 0; r < csv->nrows; r++) {
        for (int i = 0; i < csv->ncol; i++)
            free(csv->rows[r][i]);
        free(csv->rows[r]);
    }
    free(csv->rows);
    for (int i = 0; i < csv->ncol; i++)
        free(csv->cols[i]);
    free(csv->cols);
    memset(csv, 0, sizeof *csv);
}

int hx_csv_col(const HxCsv *csv, const char *name)
{
    for (int i = 0; i < csv->ncol; i++)
        if (strcmp(csv->cols[i], name) == 0)
            return i;
    return -1;
}

const char *hx_csv_get(const HxCsv *csv, size_t row, const char *name)
{
    int c = hx_csv_col(csv, name);
    return c < 0 ? "" : csv->rows[row][c];
}
