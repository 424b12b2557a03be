/* model_io.c - what the model import hands Assimp. A file system of its
 * own (aiFileIO): every name Assimp asks for must lie in the model's
 * folder, be a regular file, and is read whole once with rt_read_file and
 * recorded with rt_scene_add_dep, so the scene cache and MPI ranks see
 * exactly the bytes Assimp parsed. And checks of a model's bytes for the
 * inputs that make Assimp 5.2.5 hang or allocate gigabytes: PLY here, glTF
 * in model_gltf.c (docs/scene-format.md, "Models"). */
#define _GNU_SOURCE
#include <errno.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "config.h"
#include "model_io.h"

#if HAVE_ASSIMP
#include <assimp/cfileio.h>

/* A file read for the import, kept until the import ends: Assimp opens the
 * model several times (probing, then loading), and each open must see the
 * same bytes. */
typedef struct IoFile {
    char *name; /* as Assimp asked for it */
    char *data;
    size_t len;
} IoFile;

struct ModelIO {
    struct aiFileIO fs; /* first: the callbacks get this pointer */
    const char *file;   /* the model as named by the caller */
    char dir[PATH_MAX]; /* its folder as named ("." when none) */
    char real_dir[PATH_MAX];
    RtScene *scene;
    IoFile **files; /* each its own allocation: open cursors point at them */
    size_t nfiles;
    char refusal[1024];
};

/* An open file: a cursor over an IoFile's bytes. */
typedef struct IoCursor {
    const IoFile *f;
    size_t pos;
} IoCursor;

static size_t io_read(struct aiFile *af, char *buf, size_t size, size_t count)
{
    IoCursor *c = (IoCursor *)af->UserData;
    if (size == 0 || count == 0 || c->pos >= c->f->len)
        return 0;
    const size_t avail = (c->f->len - c->pos) / size, n = count < avail ? count : avail;
    memcpy(buf, c->f->data + c->pos, n * size);
    c->pos += n * size;
    return n;
}

static size_t io_write(struct aiFile *af, const char *buf, size_t size, size_t count)
{
    (void)af, (void)buf, (void)size, (void)count;
    return 0;
}

static size_t io_tell(struct aiFile *af) { return ((IoCursor *)af->UserData)->pos; }
static size_t io_size(struct aiFile *af) { return ((IoCursor *)af->UserData)->f->len; }
static void io_flush(struct aiFile *af) { (void)af; }

static enum aiReturn io_seek(struct aiFile *af, size_t off, enum aiOrigin origin)
{
    IoCursor *c = (IoCursor *)af->UserData;
    const size_t base = origin == aiOrigin_SET ? 0 : origin == aiOrigin_CUR ? c->pos : c->f->len;
    if (origin != aiOrigin_SET && origin != aiOrigin_CUR && origin != aiOrigin_END)
        return aiReturn_FAILURE;
    /* (Assimp passes negative offsets from CUR and END as wrapped size_t) */
    const size_t to = base + off;
    if (to > c->f->len)
        return aiReturn_FAILURE;
    c->pos = to;
    return aiReturn_SUCCESS;
}

/* Remembers the first refusal; NULL for the open callback to return. */
static struct aiFile *refuse(ModelIO *io, const char *ref, const char *why)
{
    if (!io->refusal[0])
        snprintf(io->refusal, sizeof io->refusal, "%.200s: reference '%.150s' %.600s", io->file, ref, why);
    return NULL;
}

/* The reference a name Assimp asks for makes: the name less the model's
 * folder, which Assimp puts before what the file names. */
static const char *reference_of(const ModelIO *io, const char *name)
{
    const size_t n = strcmp(io->dir, "/") == 0 ? 0 : strlen(io->dir);
    if (strncmp(name, io->dir, n) == 0 && name[n] == '/')
        return name + n + 1;
    if (strcmp(io->dir, ".") == 0)
        return name;
    return NULL;
}

/* Whether a relative path climbs with a `..` component. */
static int has_dotdot(const char *p)
{
    for (const char *c = p; (c = strstr(c, "..")) != NULL; c += 2)
        if ((c == p || c[-1] == '/' || c[-1] == '\\') && (c[2] == '\0' || c[2] == '/' || c[2] == '\\'))
            return 1;
    return 0;
}

/* Reads a file into the list and records it in the scene under the name
 * Assimp asked for; the file, or NULL with err set. */
static IoFile *load(ModelIO *io, const char *name, const char *path, RtError *err)
{
    IoFile **nf = realloc(io->files, (io->nfiles + 1) * sizeof *nf);
    IoFile *f = nf ? calloc(1, sizeof *f) : NULL;
    if (nf)
        io->files = nf;
    if (!f || !(f->name = strdup(name))) {
        free(f);
        rt_fail(err, "%s: out of memory", path);
        return NULL;
    }
    if (rt_read_file(path, RT_MAX_FILE, &f->data, &f->len, err) != 0 ||
        rt_scene_add_dep(io->scene, name, f->data, f->len, err) != 0) {
        free(f->data), free(f->name), free(f);
        return NULL;
    }
    io->files[io->nfiles++] = f;
    return f;
}

/* The file for a name inside the model's folder: one already read, or
 * read now. NULL when refused (remembered) or absent (Assimp probes for
 * files that need not exist). */
static IoFile *resolve(ModelIO *io, const char *name)
{
    for (size_t i = 0; i < io->nfiles; i++)
        if (strcmp(io->files[i]->name, name) == 0)
            return io->files[i];
    const char *ref = reference_of(io, name);
    if (!ref || ref[0] == '/' || has_dotdot(ref))
        return refuse(io, ref ? ref : name, "leaves the model's folder"), NULL;
    if (strchr(ref, '\\'))
        return refuse(io, ref, "has a backslash (write folders with '/')"), NULL;
    char real[PATH_MAX];
    if (!realpath(name, real)) {
        if (errno != ENOENT && errno != ENOTDIR)
            refuse(io, ref, strerror(errno));
        return NULL;
    }
    /* a link inside the folder may lead anywhere: where it ends counts */
    const size_t n = strlen(io->real_dir);
    if (strncmp(real, io->real_dir, n) != 0 || (real[n] != '/' && strcmp(io->real_dir, "/") != 0))
        return refuse(io, ref, "leaves the model's folder (through a symbolic link)"), NULL;
    RtError e = {{0}};
    IoFile *f = load(io, name, real, &e);
    if (!f) {
        char why[600];
        snprintf(why, sizeof why, "cannot be read: %.580s", e.msg);
        refuse(io, ref, why);
    }
    return f;
}

static struct aiFile *io_open(struct aiFileIO *fs, const char *name, const char *mode)
{
    ModelIO *io = (ModelIO *)fs;
    if (!name || !mode || strpbrk(mode, "wa+"))
        return NULL; /* reading only: an import writes nothing */
    IoFile *f = strcmp(name, io->file) == 0 ? io->files[0] : resolve(io, name);
    if (!f)
        return NULL;
    struct aiFile *af = calloc(1, sizeof *af);
    IoCursor *c = calloc(1, sizeof *c);
    if (!af || !c) {
        free(af), free(c);
        return NULL;
    }
    c->f = f;
    af->ReadProc = io_read;
    af->WriteProc = io_write;
    af->TellProc = io_tell;
    af->FileSizeProc = io_size;
    af->SeekProc = io_seek;
    af->FlushProc = io_flush;
    af->UserData = (aiUserData)c;
    return af;
}

static void io_close(struct aiFileIO *fs, struct aiFile *af)
{
    (void)fs;
    if (af) {
        free(af->UserData);
        free(af);
    }
}

ModelIO *rt_model_io_open(const char *file, RtScene *scene, RtError *err)
{
    ModelIO *io = calloc(1, sizeof *io);
    if (!io) {
        rt_fail(err, "%s: out of memory", file);
        return NULL;
    }
    io->fs.OpenProc = io_open;
    io->fs.CloseProc = io_close;
    io->file = file;
    io->scene = scene;
    const char *slash = strrchr(file, '/');
    if (!slash)
        snprintf(io->dir, sizeof io->dir, ".");
    else if (slash == file)
        snprintf(io->dir, sizeof io->dir, "/");
    else
        snprintf(io->dir, sizeof io->dir, "%.*s", (int)(slash - file), file);
    if (!realpath(io->dir, io->real_dir)) {
        rt_fail(err, "%s: cannot open: %s", file, strerror(errno));
        free(io);
        return NULL;
    }
    if (!load(io, file, file, err)) {
        free(io->files);
        free(io);
        return NULL;
    }
    return io;
}

struct aiFileIO *rt_model_io_fs(ModelIO *io) { return &io->fs; }

const char *rt_model_io_bytes(const ModelIO *io, size_t *len)
{
    *len = io->files[0]->len;
    return io->files[0]->data;
}

const char *rt_model_io_refusal(const ModelIO *io) { return io->refusal[0] ? io->refusal : NULL; }

void rt_model_io_close(ModelIO *io)
{
    if (!io)
        return;
    for (size_t i = 0; i < io->nfiles; i++)
        free(io->files[i]->name), free(io->files[i]->data), free(io->files[i]);
    free(io->files);
    free(io);
}

#endif /* HAVE_ASSIMP */

/* ---- checks of a model's bytes ----------------------------------------- */


int rt_model_fail_expands(RtError *err, const char *file, uint64_t limit, const char *what, int instanced)
{
    return rt_fail(err, "%s: %s more than %llu %s%s; raise the limit with --max-model-triangles N", file,
                   instanced ? "expands to" : "has", (unsigned long long)limit, what,
                   instanced ? " (nodes instanced repeatedly)" : "");
}

/* PLY. Assimp 5.2.5 reads a header without end_header forever, and sizes
 * its arrays from the declared counts before reading any data. So the
 * header must end within PLY_MAX_HEADER bytes, and every element's count
 * times the least bytes an item takes (ascii: a digit and a separator per
 * property; binary: the fixed sizes, a list's count field) must fit in the
 * bytes after it. */
#define PLY_MAX_HEADER 65536

/* The size of a PLY scalar type; 0 for one Assimp does not know either. */
static unsigned ply_type_size(const char *t, size_t n)
{
    static const struct { const char *name; unsigned size; } types[] = {
        {"char", 1},   {"uchar", 1},   {"int8", 1},   {"uint8", 1},   {"short", 2},   {"ushort", 2},
        {"int16", 2},  {"uint16", 2},  {"int", 4},    {"uint", 4},    {"int32", 4},   {"uint32", 4},
        {"float", 4},  {"float32", 4}, {"double", 8}, {"float64", 8},
    };
    for (size_t i = 0; i < sizeof types / sizeof *types; i++)
        if (strlen(types[i].name) == n && strncmp(t, types[i].name, n) == 0)
            return types[i].size;
    return 0;
}

/* The words of one header line: up to 4, as (start, length). */
static int ply_words(const char *line, const char *end, const char *w[4], size_t wl[4])
{
    int n = 0;
    for (const char *c = line; c < end && n < 4;) {
        while (c < end && (*c == ' ' || *c == '\t' || *c == '\r'))
            c++;
        const char *s = c;
        while (c < end && *c != ' ' && *c != '\t' && *c != '\r')
            c++;
        if (c > s)
            w[n] = s, wl[n] = (size_t)(c - s), n++;
    }
    return n;
}

#define WORD_IS(k, lit) (wl[k] == sizeof lit - 1 && strncmp(w[k], lit, sizeof lit - 1) == 0)

/* One element's need so far: count items of at least `item` bytes. */
typedef struct PlyElement {
    const char *name;
    size_t name_len;
    uint64_t count, item;
    unsigned nprops;
    uint64_t lists; /* bit k: property k is a list */
} PlyElement;
#define PLY_MAX_PROPS 64

#define PLY_MAX_ELEMENTS 256

/* Whether the elements fit in avail bytes: the first that does not, in
 * header order, is named. */
static int ply_fits(const char *file, const PlyElement *el, int n, uint64_t avail, RtError *err)
{
    uint64_t need = 0;
    for (int i = 0; i < n; i++) {
        const PlyElement *e = &el[i];
        need = sat_add(need, sat_mul(e->count, e->item ? e->item : 1));
        if (need <= avail)
            continue;
        const int v = e->name_len == 6 && strncmp(e->name, "vertex", 6) == 0;
        const int f = e->name_len == 4 && strncmp(e->name, "face", 4) == 0;
        if (v || f)
            return rt_fail(err, "%s: header declares %llu %s but the file holds %llu bytes after it", file,
                           (unsigned long long)e->count, v ? "vertices" : "faces", (unsigned long long)avail);
        return rt_fail(err, "%s: header declares %llu '%.*s' elements but the file holds %llu bytes after it",
                       file, (unsigned long long)e->count, (int)e->name_len, e->name, (unsigned long long)avail);
    }
    return 0;
}

/* The next whitespace-separated token at or after *p; its start, or NULL. */
static const char *ply_token(const char **p, const char *end)
{
    const char *c = *p;
    while (c < end && (*c == ' ' || *c == '\t' || *c == '\r' || *c == '\n'))
        c++;
    if (c == end)
        return NULL;
    const char *t = c;
    while (c < end && !(*c == ' ' || *c == '\t' || *c == '\r' || *c == '\n'))
        c++;
    *p = c;
    return t;
}

/* Whether [t, e) is a number as PLY writes one: an optional sign, digits,
 * and for a real type a fraction and an exponent (no nan, inf or hex). */
static int ply_number(const char *t, const char *e, int integer)
{
    const char *c = t + (t < e && (*t == '-' || *t == '+'));
    int digits = 0;
    while (c < e && *c >= '0' && *c <= '9')
        c++, digits++;
    if (!integer && c < e && *c == '.')
        for (c++; c < e && *c >= '0' && *c <= '9'; c++)
            digits++;
    if (!integer && digits && c < e && (*c == 'e' || *c == 'E')) {
        c += 1 + (c + 1 < e && (c[1] == '-' || c[1] == '+'));
        if (!(c < e && *c >= '0' && *c <= '9'))
            return 0;
        while (c < e && *c >= '0' && *c <= '9')
            c++;
    }
    return digits > 0 && c == e;
}

/* One item's list property: its length, checked against the bytes left
 * (Assimp 5.2.5 reads a list of 2^31 items as long as it takes), then its
 * items. */
static int ply_list(const char *file, const PlyElement *el, uint64_t item, const char *t, const char **p,
                    const char *end, RtError *err)
{
    const unsigned long long c = strtoull(t, NULL, 10);
    if (t[0] == '-' || c > (unsigned long long)(end - *p) / 2)
        return rt_fail(err, "%s: PLY list of %s items in element '%.*s' %llu, with %llu bytes left", file,
                       t[0] == '-' ? "negative" : "too many", (int)el->name_len, el->name, (unsigned long long)item,
                       (unsigned long long)(end - *p));
    for (unsigned long long m = 0; m < c; m++) {
        const char *v = ply_token(p, end);
        if (!v || !ply_number(v, *p, 0))
            return rt_fail(err, "%s: PLY data of element '%.*s' %llu does not match its header", file,
                           (int)el->name_len, el->name, (unsigned long long)item);
    }
    return 0;
}

/* Ascii data walked as the header lays it out, in O(bytes) (the counts
 * have been checked against the size): every value a number, every list's
 * length an integer that fits, one item a line, no early end. Data that
 * does not match its header made Assimp 5.2.5 allocate 32 GB (fuzz-model). */
static int ply_ascii_data(const char *file, const PlyElement *el, int n, const char *p, const char *end,
                          RtError *err)
{
    for (int i = 0; i < n; i++)
        for (uint64_t item = 0; item < el[i].count; item++) {
            for (unsigned k = 0; k < el[i].nprops; k++) {
                const char *t = ply_token(&p, end);
                const int list = el[i].lists >> k & 1;
                if (!t)
                    return rt_fail(err, "%s: PLY data ends inside element '%.*s' %llu", file, (int)el[i].name_len,
                                   el[i].name, (unsigned long long)item);
                if (!ply_number(t, p, list))
                    return rt_fail(err, "%s: PLY data of element '%.*s' %llu does not match its header", file,
                                   (int)el[i].name_len, el[i].name, (unsigned long long)item);
                if (list && ply_list(file, &el[i], item, t, &p, end, err) != 0)
                    return -1;
            }
            while (p < end && (*p == ' ' || *p == '\t' || *p == '\r'))
                p++;
            if (p < end && *p != '\n')
                return rt_fail(err, "%s: PLY element '%.*s' %llu has more values than its header says", file,
                               (int)el[i].name_len, el[i].name, (unsigned long long)item);
        }
    return 0;
}

/* A header word that names something: letters, digits and underscores. */
static int ply_word(const char *w, size_t n)
{
    for (size_t i = 0; i < n; i++)
        if (!((w[i] >= 'a' && w[i] <= 'z') || (w[i] >= 'A' && w[i] <= 'Z') || (w[i] >= '0' && w[i] <= '9') ||
              w[i] == '_' || w[i] == '-' || w[i] == '.'))
            return 0;
    return n > 0;
}

static int check_ply(const char *file, const char *data, size_t len, RtError *err)
{
    const size_t scan = len < PLY_MAX_HEADER ? len : PLY_MAX_HEADER;
    const char *p = data, *end = data + scan;
    int ascii = 1, n = 0;
    PlyElement el[PLY_MAX_ELEMENTS];
    while (p < end) {
        const char *nl = memchr(p, '\n', (size_t)(end - p));
        if (!nl)
            break;
        const char *w[4];
        size_t wl[4];
        const int nw = ply_words(p, nl, w, wl);
        p = nl + 1;
        if (nw == 0)
            continue;
        if (WORD_IS(0, "end_header"))
            return ply_fits(file, el, n, (uint64_t)(len - (size_t)(p - data)), err) != 0 ? -1
                   : ascii ? ply_ascii_data(file, el, n, p, data + len, err) : 0;
        if (WORD_IS(0, "format") && nw >= 2) {
            ascii = WORD_IS(1, "ascii");
        } else if (WORD_IS(0, "element") && nw >= 3 && !ply_word(w[1], wl[1])) {
            return rt_fail(err, "%s: PLY element name '%.*s' is not a word", file, (int)(wl[1] < 60 ? wl[1] : 60), w[1]);
        } else if (WORD_IS(0, "element") && nw >= 3) {
            if (n == PLY_MAX_ELEMENTS)
                return rt_fail(err, "%s: PLY header with more than %d elements", file, PLY_MAX_ELEMENTS);
            /* Assimp 5.2.5 jumps to a wild address on an element declared twice */
            for (int i = 0; i < n; i++)
                if (el[i].name_len == wl[1] && strncmp(el[i].name, w[1], wl[1]) == 0)
                    return rt_fail(err, "%s: PLY header declares element '%.*s' twice", file, (int)wl[1], w[1]);
            const unsigned long long c = strtoull(w[2], NULL, 10);
            el[n++] = (PlyElement){w[1], wl[1], w[2][0] == '-' || c == ULLONG_MAX ? UINT64_MAX : c, 0, 0, 0};
        } else if (WORD_IS(0, "property")) {
            const int list = nw >= 2 && WORD_IS(1, "list");
            /* a type Assimp 5.2.5 does not know makes it read item sizes it
             * never set (an allocation of 33 GB, found by fuzz-model) */
            if (n == 0 || nw < (list ? 4 : 3) || !ply_type_size(w[list ? 2 : 1], wl[list ? 2 : 1]) ||
                (list && !ply_type_size(w[3], wl[3])))
                return rt_fail(err, "%s: PLY property line of an unknown type or shape: '%.*s'", file,
                               (int)(nl - w[0] < 60 ? nl - w[0] : 60), w[0]);
            const unsigned size = list ? ply_type_size(w[2], wl[2]) : ply_type_size(w[1], wl[1]);
            PlyElement *e = &el[n - 1];
            if (e->nprops == PLY_MAX_PROPS)
                return rt_fail(err, "%s: PLY element with more than %d properties", file, PLY_MAX_PROPS);
            e->lists |= (uint64_t)list << e->nprops++;
            e->item = sat_add(e->item, ascii ? 2 : size ? size : 1);
        } else if (WORD_IS(0, "element")) {
            return rt_fail(err, "%s: PLY element line without a name and a count", file);
        } /* (other lines are comments to Assimp too: Blender writes one without the keyword) */
    }
    return rt_fail(err, "%s: PLY header without end_header in its first %d bytes", file, PLY_MAX_HEADER);
}

int rt_model_check_bytes(const char *file, const char *data, size_t len, uint64_t max_tris, RtError *err)
{
    if (len >= 4 && (strncmp(data, "ply", 3) == 0 || strncmp(data, "PLY", 3) == 0))
        return check_ply(file, data, len, err);
    if (len >= 20 && memcmp(data, "glTF", 4) == 0) {
        const uint32_t n = (uint32_t)(unsigned char)data[12] | (uint32_t)(unsigned char)data[13] << 8 |
                           (uint32_t)(unsigned char)data[14] << 16 | (uint32_t)(unsigned char)data[15] << 24;
        return rt_model_check_gltf(file, data + 20, n < len - 20 ? n : len - 20, max_tris, err);
    }
    size_t k = len >= 3 && memcmp(data, "\xef\xbb\xbf", 3) == 0 ? 3 : 0;
    while (k < len && strchr(" \t\r\n", data[k]) && data[k])
        k++;
    if (k < len && data[k] == '{')
        return rt_model_check_gltf(file, data, len, max_tris, err);
    return 0;
}
