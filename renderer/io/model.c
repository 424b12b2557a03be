/* model.c - triangle meshes from model files (OBJ, PLY, STL, glTF and the
 * other formats Assimp reads), appended to a scene: for the scene format's
 * `mesh:` line, and for `raytrace MODEL`, which scene_load.c frames with a
 * default camera, lights and material (docs/scene-format.md, "Models"). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "config.h"
#include "model_io.h"
#include "rt.h"

#if HAVE_ASSIMP
#include <assimp/cimport.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

/* The most triangles one model may expand to (rt_model_set_max_triangles). */
static uint64_t max_triangles = RT_MODEL_MAX_TRIANGLES;

/* Grows a scene pool to hold `more` further elements. */
static int reserve(void **arr, uint32_t *cap, uint32_t n, uint64_t more, size_t elem)
{
    if ((uint64_t)n + more <= *cap)
        return 0;
    if ((uint64_t)n + more > 0x7fffffffu)
        return -1;
    void *na = realloc(*arr, (size_t)(n + more) * elem);
    if (!na)
        return -1;
    *arr = na;
    *cap = (uint32_t)(n + more);
    return 0;
}

/* Assimp's message, on one line. */
static void one_line(char *dst, size_t size, const char *src)
{
    snprintf(dst, size, "%s", src && *src ? src : "unknown error");
    for (char *c = dst; *c; c++)
        if (*c == '\n' || *c == '\r')
            *c = ' ';
}

/* The normal matrix: the inverse transpose of xf's 3x3 part, up to a
 * positive factor (the adjugate's transpose; the renderer normalizes). */
static void normal_matrix(const float *xf, float n[9])
{
    const float a = xf[0], b = xf[1], c = xf[2], d = xf[4], e = xf[5], f = xf[6], g = xf[8], h = xf[9], i = xf[10];
    const float co[9] = {e * i - f * h, f * g - d * i, d * h - e * g, c * h - b * i, a * i - c * g,
                         b * g - a * h, b * f - c * e, c * d - a * f, a * e - b * d};
    const float det = a * co[0] + b * co[1] + c * co[2];
    for (int k = 0; k < 9; k++)
        n[k] = det < 0.0f ? -co[k] : co[k];
}

static RtVec3 apply(const float *m, int stride, const struct aiVector3D *v, int affine)
{
    return rt_v3(m[0] * v->x + m[1] * v->y + m[2] * v->z + (affine ? m[3] : 0.0f),
                 m[stride] * v->x + m[stride + 1] * v->y + m[stride + 2] * v->z + (affine ? m[stride + 3] : 0.0f),
                 m[2 * stride] * v->x + m[2 * stride + 1] * v->y + m[2 * stride + 2] * v->z +
                     (affine ? m[2 * stride + 3] : 0.0f));
}

/* Whether a face's normals can shade it: finite and not zero. */
static int usable_normals(const struct aiMesh *m, const unsigned *ix)
{
    for (int k = 0; k < 3; k++) {
        const struct aiVector3D *n = &m->mNormals[ix[k]];
        const float l = n->x * n->x + n->y * n->y + n->z * n->z;
        if (!(l > 0.0f) || !isfinite(l))
            return 0;
    }
    return 1;
}

/* One mesh's vertices, normals and triangles into the scene; -1 for a
 * vertex that is not finite (after the transform) or a face index past the
 * mesh's vertices. */
static int append_mesh(const struct aiMesh *m, const float *xf, const float *nm, uint32_t material, RtScene *s)
{
    const uint32_t v0 = s->nvertices, n0 = s->nnormals;
    for (unsigned k = 0; k < m->mNumVertices; k++) {
        const RtVec3 v = apply(xf, 4, &m->mVertices[k], 1);
        if (!isfinite(v.x) || !isfinite(v.y) || !isfinite(v.z))
            return -1;
        s->vertices[s->nvertices++] = v;
    }
    if (m->mNormals)
        for (unsigned k = 0; k < m->mNumVertices; k++)
            s->normals[s->nnormals++] = apply(nm, 3, &m->mNormals[k], 0);
    for (unsigned f = 0; f < m->mNumFaces; f++) {
        const struct aiFace *fc = &m->mFaces[f];
        if (fc->mNumIndices != 3)
            continue; /* points and lines (aiProcess_SortByPType keeps them apart) */
        if (fc->mIndices[0] >= m->mNumVertices || fc->mIndices[1] >= m->mNumVertices ||
            fc->mIndices[2] >= m->mNumVertices)
            return -1;
        RtTriangle *t = &s->triangles[s->ntriangles++];
        const int smooth = m->mNormals && usable_normals(m, fc->mIndices);
        for (int k = 0; k < 3; k++) {
            t->v[k] = v0 + fc->mIndices[k];
            t->n[k] = smooth ? (int32_t)(n0 + fc->mIndices[k]) : -1;
        }
        t->material = material;
    }
    return 0;
}

/* What a node graph adds once every instance is flattened: vertices,
 * normals, triangles (64-bit, saturating). */
typedef struct Totals {
    uint64_t v, n, t;
} Totals;

/* Assimp recursed as deep to build the tree; a bound keeps this walk's
 * stack small whatever the format. */
#define MAX_NODE_DEPTH 4096

static int count_node(const struct aiScene *sc, const struct aiNode *nd, const uint64_t *tris, Totals *tot,
                      int depth)
{
    if (depth > MAX_NODE_DEPTH)
        return -1;
    for (unsigned i = 0; i < nd->mNumMeshes; i++) {
        if (nd->mMeshes[i] >= sc->mNumMeshes)
            return -1;
        const struct aiMesh *m = sc->mMeshes[nd->mMeshes[i]];
        tot->v = sat_add(tot->v, m->mNumVertices);
        tot->n = sat_add(tot->n, m->mNormals ? m->mNumVertices : 0);
        tot->t = sat_add(tot->t, tris[nd->mMeshes[i]]);
    }
    for (unsigned i = 0; i < nd->mNumChildren; i++)
        if (count_node(sc, nd->mChildren[i], tris, tot, depth + 1) != 0)
            return -1;
    return 0;
}

/* A node's transform after its parent's: g = parent * local (4x4, row-major). */
static void compose(const double *parent, const struct aiMatrix4x4 *l, double *g)
{
    const double m[16] = {l->a1, l->a2, l->a3, l->a4, l->b1, l->b2, l->b3, l->b4,
                          l->c1, l->c2, l->c3, l->c4, l->d1, l->d2, l->d3, l->d4};
    for (int r = 0; r < 4; r++)
        for (int c = 0; c < 4; c++)
            g[4 * r + c] = parent[4 * r] * m[c] + parent[4 * r + 1] * m[4 + c] + parent[4 * r + 2] * m[8 + c] +
                           parent[4 * r + 3] * m[12 + c];
}

/* Appends every mesh instance under nd, each through xf after its node's
 * accumulated transform g (the flattening aiProcess_PreTransformVertices
 * would do, here after the count has been checked). */
static int append_node(const struct aiScene *sc, const struct aiNode *nd, const double *parent, const float *xf,
                       uint32_t material, RtScene *s)
{
    double g[16];
    compose(parent, &nd->mTransformation, g);
    if (nd->mNumMeshes) {
        float f[12], nm[9];
        for (int r = 0; r < 3; r++)
            for (int c = 0; c < 4; c++)
                f[4 * r + c] = (float)(xf[4 * r] * g[c] + xf[4 * r + 1] * g[4 + c] + xf[4 * r + 2] * g[8 + c] +
                                       xf[4 * r + 3] * g[12 + c]);
        normal_matrix(f, nm);
        for (unsigned i = 0; i < nd->mNumMeshes; i++)
            if (append_mesh(sc->mMeshes[nd->mMeshes[i]], f, nm, material, s) != 0)
                return -1;
    }
    for (unsigned i = 0; i < nd->mNumChildren; i++)
        if (append_node(sc, nd->mChildren[i], g, xf, material, s) != 0)
            return -1;
    return 0;
}

/* The imported scene's triangles into s: counted over the node graph and
 * checked against the limit before anything grows. */
static int append_scene(const char *file, const struct aiScene *sc, const float *xf, uint32_t material, RtScene *s,
                        RtError *err)
{
    uint64_t *tris = calloc(sc->mNumMeshes + 1, sizeof *tris), plain = 0;
    if (!tris)
        return rt_fail(err, "%s: out of memory", file);
    for (unsigned i = 0; i < sc->mNumMeshes; i++) {
        for (unsigned f = 0; f < sc->mMeshes[i]->mNumFaces; f++)
            tris[i] += sc->mMeshes[i]->mFaces[f].mNumIndices == 3;
        plain += tris[i];
    }
    Totals tot = {0, 0, 0};
    const int bad = !sc->mRootNode || count_node(sc, sc->mRootNode, tris, &tot, 0) != 0;
    free(tris);
    if (bad)
        return rt_fail(err, "%s: a node graph nested deeper than %d or naming a mesh that is not there", file,
                       MAX_NODE_DEPTH);
    if (tot.t > max_triangles)
        return rt_model_fail_expands(err, file, max_triangles, "triangles", tot.t > plain);
    if (tot.t == 0)
        return rt_fail(err, "%s: no triangles in the model", file);
    if (reserve((void **)&s->vertices, &s->cap_vertices, s->nvertices, tot.v, sizeof *s->vertices) ||
        reserve((void **)&s->normals, &s->cap_normals, s->nnormals, tot.n, sizeof *s->normals) ||
        reserve((void **)&s->triangles, &s->cap_triangles, s->ntriangles, tot.t, sizeof *s->triangles))
        return rt_fail(err, "%s: out of memory for %llu triangles", file, (unsigned long long)tot.t);
    static const double id[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    if (append_node(sc, sc->mRootNode, id, xf, material, s) != 0)
        return rt_fail(err, "%s: a vertex that is not finite (after the transform) or a face index out of range",
                       file);
    return 0;
}

/* Whether every face has vertices, all inside its mesh: what Assimp's
 * post-processing steps assume without checking. */
static int faces_valid(const struct aiScene *sc)
{
    for (unsigned i = 0; i < sc->mNumMeshes; i++) {
        const struct aiMesh *m = sc->mMeshes[i];
        if (!m || (m->mNumVertices && !m->mVertices) || (m->mNumFaces && !m->mFaces))
            return 0;
        for (unsigned f = 0; f < m->mNumFaces; f++) {
            const struct aiFace *fc = &m->mFaces[f];
            if (fc->mNumIndices == 0 || !fc->mIndices)
                return 0;
            for (unsigned k = 0; k < fc->mNumIndices; k++)
                if (fc->mIndices[k] >= m->mNumVertices)
                    return 0;
        }
    }
    return 1;
}

int rt_model_set_max_triangles(uint64_t n)
{
    if (n == 0)
        return -1;
    max_triangles = n;
    return 0;
}

/* The import, through our file system (model_io.c): the model's bytes are
 * checked first, and a reference the file system refused fails the import
 * even where Assimp went on without it. */
int rt_model_append(const char *file, const float xf[12], uint32_t material, RtScene *s, RtError *err)
{
    ModelIO *io = rt_model_io_open(file, s, err);
    if (!io)
        return -1;
    size_t len;
    const char *bytes = rt_model_io_bytes(io, &len);
    if (rt_model_check_bytes(file, bytes, len, max_triangles, err) != 0) {
        rt_model_io_close(io);
        return -1;
    }
    /* Post-processing waits until the faces are checked: Assimp 5.2.5's
     * PLY loader can leave faces without indices, which its SortByPType
     * step reads past. ValidateDataStructure, the one step that can fail,
     * runs in the import: aiApplyPostProcessing's failure path frees the
     * scene twice. No aiProcess_PreTransformVertices: it would copy every
     * instance before the count could refuse them. */
    const struct aiScene *sc = aiImportFileEx(file, aiProcess_ValidateDataStructure, rt_model_io_fs(io));
    int rc = 0;
    if (rt_model_io_refusal(io)) {
        rc = rt_fail(err, "%s", rt_model_io_refusal(io));
    } else if (!sc) {
        char msg[400];
        one_line(msg, sizeof msg, aiGetErrorString());
        rc = rt_fail(err, "%s: %s", file, msg);
    } else if (!faces_valid(sc)) {
        rc = rt_fail(err, "%s: a face without vertices or with an index past its mesh's vertices", file);
    } else if (!(sc = aiApplyPostProcessing(sc, aiProcess_Triangulate | aiProcess_JoinIdenticalVertices |
                                                   aiProcess_SortByPType))) {
        char msg[400]; /* (not expected: these steps do not fail) */
        one_line(msg, sizeof msg, aiGetErrorString());
        rc = rt_fail(err, "%s: %s", file, msg);
    } else {
        rc = append_scene(file, sc, xf, material, s, err);
    }
    if (sc)
        aiReleaseImport(sc);
    rt_model_io_close(io);
    return rc;
}

int rt_model_supported(const char *path)
{
    const char *dot = strrchr(path, '.'), *slash = strrchr(path, '/');
    if (!dot || (slash && dot < slash) || strcmp(dot, ".txt") == 0)
        return 0;
    return aiIsExtensionSupported(dot) == AI_TRUE;
}

const char *rt_model_unavailable(void) { return NULL; }

#else

int rt_model_append(const char *file, const float xf[12], uint32_t material, RtScene *s, RtError *err)
{
    (void)xf; (void)material; (void)s;
    return rt_fail(err, "%s: this build cannot read models (it needs Assimp: scripts/install-deps.sh)", file);
}

int rt_model_supported(const char *path)
{
    (void)path;
    return 0;
}

const char *rt_model_unavailable(void) { return "this build cannot read models (it needs Assimp)"; }

int rt_model_set_max_triangles(uint64_t n) { return n ? 0 : -1; }

#endif
