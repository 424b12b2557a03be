/* model_io.c - what the model import hands Assimp. A file system of its
 * own (aiFileIO): every name Assimp asks for must lie in the model's
 * folder, be a regular file, and is read whole once with rt_read_file and
 * recorded with rt_scene_add_dep, so the scene cache and MPI ranks see
 * exactly the bytes Assimp parsed. And checks of a model's bytes for the
 * inputs that make Assimp 5.2.5 hang or allocate gigabytes
 * (docs/scene-format.md, "Models"). */
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

static uint64_t sat_add(uint64_t a, uint64_t b) { return a + b < a ? UINT64_MAX : a + b; }
static uint64_t sat_mul(uint64_t a, uint64_t b) { return b && a > UINT64_MAX / b ? UINT64_MAX : a * b; }

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

/* glTF. Assimp 5.2.5 builds a node of its own for every place a glTF node
 * is listed as a child, so a node graph that lists the same child twice at
 * each of n levels makes 2^n nodes while the file stays a kilobyte (20
 * levels: 2 M nodes, 2.4 GB, 21 s before a triangle is read). The graph is
 * counted here from the JSON, before Assimp sees it. A small JSON reader
 * (values in one array, children linked) is enough: the graph needs
 * nodes, scenes, meshes and accessors only. */
enum { J_OBJ = 1, J_ARR, J_STR, J_NUM, J_LIT };
#define JSON_MAX_DEPTH 64
#define GRAPH_MAX_DEPTH 1024

typedef struct JVal {
    uint8_t type;
    uint32_t next, child; /* 0: none (value 0 is never used) */
    const char *key;      /* object members: the key's bytes (no escapes) */
    uint32_t key_len;
    uint64_t num; /* J_NUM: the value when a whole number, else UINT64_MAX */
} JVal;

typedef struct Json {
    const char *s, *p, *end;
    JVal *v;
    uint32_t n, cap;
    const char *bad; /* why it cannot be read */
} Json;

static void json_ws(Json *j)
{
    while (j->p < j->end && (*j->p == ' ' || *j->p == '\t' || *j->p == '\n' || *j->p == '\r'))
        j->p++;
}

/* Skips a string (p at its quote); its bytes, or NULL. escaped: whether it
 * had an escape. */
static const char *json_string(Json *j, uint32_t *len, int *escaped)
{
    const char *s = ++j->p;
    *escaped = 0;
    while (j->p < j->end && *j->p != '"') {
        if ((unsigned char)*j->p < 0x20)
            return NULL;
        if (*j->p == '\\')
            *escaped = 1, j->p++;
        j->p++;
    }
    if (j->p >= j->end)
        return NULL;
    *len = (uint32_t)(j->p++ - s);
    return s;
}

static uint32_t json_value(Json *j, int depth);

/* The members or items of an object or array (p after its bracket),
 * linked under value v. */
static int json_children(Json *j, uint32_t v, int depth, int obj)
{
    const char close = obj ? '}' : ']';
    uint32_t last = 0;
    json_ws(j);
    if (j->p < j->end && *j->p == close)
        return j->p++, 0;
    for (;;) {
        const char *key = NULL;
        uint32_t klen = 0;
        if (obj) {
            int esc;
            json_ws(j);
            if (j->p >= j->end || *j->p != '"' || !(key = json_string(j, &klen, &esc)))
                return -1;
            if (esc) /* (a key spelt with escapes would hide from this reader) */
                return j->bad = "a key written with escapes", -1;
            json_ws(j);
            if (j->p >= j->end || *j->p++ != ':')
                return -1;
        }
        const uint32_t c = json_value(j, depth + 1);
        if (!c)
            return -1;
        j->v[c].key = key, j->v[c].key_len = klen;
        *(last ? &j->v[last].next : &j->v[v].child) = c;
        last = c;
        json_ws(j);
        if (j->p < j->end && *j->p == ',') {
            j->p++;
            continue;
        }
        if (j->p < j->end && *j->p == close)
            return j->p++, 0;
        return -1;
    }
}

/* One value at p; its index, or 0. */
static uint32_t json_value(Json *j, int depth)
{
    if (depth > JSON_MAX_DEPTH)
        return j->bad = "nested too deep", 0;
    json_ws(j);
    if (j->p >= j->end)
        return 0;
    if (j->n >= j->cap) {
        const uint32_t cap = j->cap ? 2 * j->cap : 256;
        JVal *nv = cap > j->cap ? realloc(j->v, (size_t)cap * sizeof *nv) : NULL;
        if (!nv)
            return j->bad = "out of memory", 0;
        j->v = nv, j->cap = cap;
    }
    const uint32_t v = j->n++;
    j->v[v] = (JVal){0};
    j->v[v].num = UINT64_MAX;
    const char c = *j->p;
    uint32_t len;
    int esc;
    if (c == '{' || c == '[') {
        j->v[v].type = c == '{' ? J_OBJ : J_ARR;
        j->p++;
        return json_children(j, v, depth, c == '{') == 0 ? v : 0;
    }
    if (c == '"') {
        j->v[v].type = J_STR;
        return json_string(j, &len, &esc) ? v : 0;
    }
    const char *s = j->p;
    while (j->p < j->end && (strchr("+-.eE", *j->p) || (*j->p >= '0' && *j->p <= '9') || (*j->p >= 'a' && *j->p <= 'z')))
        j->p++;
    if (j->p == s)
        return 0;
    const size_t n = (size_t)(j->p - s);
    j->v[v].type = (c == '-' || (c >= '0' && c <= '9')) ? J_NUM : J_LIT;
    if (j->v[v].type == J_LIT && !(n == 4 && (!strncmp(s, "true", 4) || !strncmp(s, "null", 4))) &&
        !(n == 5 && !strncmp(s, "false", 5)))
        return 0;
    if (c >= '0' && c <= '9' && n <= 19 && strspn(s, "0123456789") >= n)
        j->v[v].num = strtoull(s, NULL, 10);
    return v;
}

/* The member key of object o; 0 when none (or o is not an object). */
static uint32_t jget(const Json *j, uint32_t o, const char *key)
{
    if (!o || j->v[o].type != J_OBJ)
        return 0;
    const size_t n = strlen(key);
    for (uint32_t c = j->v[o].child; c; c = j->v[c].next)
        if (j->v[c].key_len == n && memcmp(j->v[c].key, key, n) == 0)
            return c;
    return 0;
}

/* The items of array a (none when a is not an array), into a malloc'd list. */
static uint32_t *jitems(const Json *j, uint32_t a, uint32_t *count)
{
    *count = 0;
    if (!a || j->v[a].type != J_ARR)
        return calloc(1, sizeof(uint32_t));
    for (uint32_t c = j->v[a].child; c; c = j->v[c].next)
        ++*count;
    uint32_t *items = malloc((*count + 1) * sizeof *items), k = 0;
    if (items)
        for (uint32_t c = j->v[a].child; c; c = j->v[c].next)
            items[k++] = c;
    return items;
}

static uint64_t jnum(const Json *j, uint32_t v, uint64_t dflt)
{
    return v && j->v[v].type == J_NUM ? j->v[v].num : dflt;
}

/* The node graph, counted: each node's expanded instances and triangles. */
typedef struct Graph {
    const Json *j;
    uint32_t *nodes, nnodes;
    uint64_t *mesh_tris; /* per glTF mesh */
    uint32_t nmeshes;
    uint64_t *inst, *tris;
    uint8_t *state; /* 0 not counted, 1 being counted (a cycle if met), 2 counted */
} Graph;

/* Triangles mesh m's primitives make: the index (else position) accessor's
 * count, by mode (4 triangles, 5 strip, 6 fan; points and lines none). */
/* Whether a primitive names an accessor that does not exist (its indices
 * or an attribute): Assimp 5.2.5 then allocates by an unchecked index
 * (POSITION 18446744073709551615: tens of GB, found by fuzz-model). */
static int bad_accessor_ref(const Json *j, uint32_t prim, uint32_t nacc)
{
    const uint32_t ix = jget(j, prim, "indices"), at = jget(j, prim, "attributes");
    if (ix && jnum(j, ix, UINT64_MAX) >= nacc)
        return 1;
    for (uint32_t c = at && j->v[at].type == J_OBJ ? j->v[at].child : 0; c; c = j->v[c].next)
        if (jnum(j, c, UINT64_MAX) >= nacc)
            return 1;
    return 0;
}

static uint64_t mesh_triangles(const Json *j, uint32_t m, const uint32_t *acc, uint32_t nacc, int *bad)
{
    uint32_t np;
    uint32_t *prims = jitems(j, jget(j, m, "primitives"), &np);
    uint64_t t = 0;
    for (uint32_t i = 0; prims && i < np; i++) {
        *bad |= bad_accessor_ref(j, prims[i], nacc);
        const uint64_t mode = jnum(j, jget(j, prims[i], "mode"), 4);
        uint64_t a = jnum(j, jget(j, prims[i], "indices"), UINT64_MAX);
        if (a == UINT64_MAX)
            a = jnum(j, jget(j, jget(j, prims[i], "attributes"), "POSITION"), UINT64_MAX);
        const uint64_t c = a < nacc ? jnum(j, jget(j, acc[a], "count"), 0) : 0;
        t = sat_add(t, mode == 4 ? c / 3 : (mode == 5 || mode == 6) && c >= 3 ? c - 2 : 0);
    }
    free(prims);
    return t;
}

/* Counts node k and all it lists, depth first; -1 on a cycle or a graph
 * deeper than GRAPH_MAX_DEPTH (Assimp recurses as deep). */
static int count_node(Graph *g, uint32_t k, int depth)
{
    if (g->state[k] == 2)
        return 0;
    if (g->state[k] == 1 || depth > GRAPH_MAX_DEPTH)
        return -1;
    g->state[k] = 1;
    const Json *j = g->j;
    const uint64_t m = jnum(j, jget(j, g->nodes[k], "mesh"), UINT64_MAX);
    uint64_t inst = 1, tris = m < g->nmeshes ? g->mesh_tris[m] : 0;
    const uint32_t ch = jget(j, g->nodes[k], "children");
    for (uint32_t c = ch && j->v[ch].type == J_ARR ? j->v[ch].child : 0; c; c = j->v[c].next) {
        const uint64_t n = jnum(j, c, UINT64_MAX);
        if (n >= g->nnodes)
            continue; /* (Assimp refuses it) */
        if (count_node(g, (uint32_t)n, depth + 1) != 0)
            return -1;
        inst = sat_add(inst, g->inst[n]);
        tris = sat_add(tris, g->tris[n]);
    }
    g->inst[k] = inst, g->tris[k] = tris;
    g->state[k] = 2;
    return 0;
}

/* The node instances a model may expand to: a node copy costs Assimp about
 * as much as RT_MODEL_TRIANGLES_PER_NODE triangles, with a floor so that a
 * small limit still admits a small scene graph. */
static uint64_t max_nodes(uint64_t max_tris)
{
    const uint64_t n = max_tris / RT_MODEL_TRIANGLES_PER_NODE;
    return n > 4096 ? n : 4096;
}

/* Adds up what every scene's root nodes expand to (every node when no
 * scene is listed: more than Assimp makes, never less). */
static int count_scenes(Graph *g, uint32_t root, uint64_t *inst, uint64_t *tris)
{
    const Json *j = g->j;
    uint32_t ns;
    uint32_t *scenes = jitems(j, jget(j, root, "scenes"), &ns);
    if (!scenes)
        return -1;
    *inst = *tris = 0;
    for (uint32_t k = 0; !ns && k < g->nnodes; k++)
        if (count_node(g, k, 0) == 0)
            *inst = sat_add(*inst, g->inst[k]), *tris = sat_add(*tris, g->tris[k]);
        else
            return free(scenes), -1;
    for (uint32_t s = 0; s < ns; s++) {
        const uint32_t list = jget(j, scenes[s], "nodes");
        for (uint32_t c = list && j->v[list].type == J_ARR ? j->v[list].child : 0; c; c = j->v[c].next) {
            const uint64_t n = jnum(j, c, UINT64_MAX);
            if (n >= g->nnodes)
                continue;
            if (count_node(g, (uint32_t)n, 0) != 0)
                return free(scenes), -1;
            *inst = sat_add(*inst, g->inst[n]), *tris = sat_add(*tris, g->tris[n]);
        }
    }
    free(scenes);
    return 0;
}

static int check_graph(const char *file, const Json *j, uint64_t max_tris, RtError *err)
{
    Graph g = {.j = j};
    uint32_t nacc, nmeshes;
    uint32_t *acc = jitems(j, jget(j, 1, "accessors"), &nacc);
    uint32_t *meshes = jitems(j, jget(j, 1, "meshes"), &nmeshes);
    g.nodes = jitems(j, jget(j, 1, "nodes"), &g.nnodes);
    g.nmeshes = nmeshes;
    g.mesh_tris = calloc(nmeshes + 1, sizeof *g.mesh_tris);
    g.inst = calloc(g.nnodes + 1, sizeof *g.inst);
    g.tris = calloc(g.nnodes + 1, sizeof *g.tris);
    g.state = calloc(g.nnodes + 1, 1);
    int rc, bad = 0;
    uint64_t inst = 0, tris = 0;
    if (!acc || !meshes || !g.nodes || !g.mesh_tris || !g.inst || !g.tris || !g.state) {
        rc = rt_fail(err, "%s: out of memory", file);
    } else {
        for (uint32_t m = 0; m < nmeshes; m++)
            g.mesh_tris[m] = mesh_triangles(j, meshes[m], acc, nacc, &bad);
        if (bad)
            rc = rt_fail(err, "%s: a mesh primitive names an accessor the file does not have (of %u)", file, nacc);
        else if (count_scenes(&g, 1, &inst, &tris) != 0)
            rc = rt_fail(err, "%s: the node graph has a cycle or is nested deeper than %d", file, GRAPH_MAX_DEPTH);
        else if (tris > max_tris)
            rc = rt_model_fail_expands(err, file, max_tris, "triangles", 1);
        else if (inst > max_nodes(max_tris))
            rc = rt_model_fail_expands(err, file, max_nodes(max_tris), "node instances", 1);
        else
            rc = 0;
    }
    free(acc), free(meshes), free(g.nodes), free(g.mesh_tris), free(g.inst), free(g.tris), free(g.state);
    return rc;
}

/* The JSON of a .gltf, or of a .glb's first chunk. */
static int check_gltf(const char *file, const char *json, size_t len, uint64_t max_tris, RtError *err)
{
    Json j = {.s = json, .p = json, .end = json + len, .n = 1};
    if (len >= 3 && memcmp(json, "\xef\xbb\xbf", 3) == 0)
        j.p += 3;
    const uint32_t root = json_value(&j, 0);
    int rc;
    if (root != 1 || j.v[1].type != J_OBJ)
        rc = rt_fail(err, "%s: not valid glTF JSON (%s at byte %zu)", file, j.bad ? j.bad : "a syntax error",
                     (size_t)(j.p - json));
    else
        rc = check_graph(file, &j, max_tris, err);
    free(j.v);
    return rc;
}

int rt_model_check_bytes(const char *file, const char *data, size_t len, uint64_t max_tris, RtError *err)
{
    if (len >= 4 && (strncmp(data, "ply", 3) == 0 || strncmp(data, "PLY", 3) == 0))
        return check_ply(file, data, len, err);
    if (len >= 20 && memcmp(data, "glTF", 4) == 0) {
        const uint32_t n = (uint32_t)(unsigned char)data[12] | (uint32_t)(unsigned char)data[13] << 8 |
                           (uint32_t)(unsigned char)data[14] << 16 | (uint32_t)(unsigned char)data[15] << 24;
        return check_gltf(file, data + 20, n < len - 20 ? n : len - 20, max_tris, err);
    }
    size_t k = len >= 3 && memcmp(data, "\xef\xbb\xbf", 3) == 0 ? 3 : 0;
    while (k < len && strchr(" \t\r\n", data[k]) && data[k])
        k++;
    if (k < len && data[k] == '{')
        return check_gltf(file, data, len, max_tris, err);
    return 0;
}
