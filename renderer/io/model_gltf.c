/* model_gltf.c - a glTF's node graph counted before Assimp sees the file
 * (docs/scene-format.md, "Models"). */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "config.h"
#include "model_io.h"

/* glTF. Assimp 5.2.5 builds a node of its own for every place a glTF node
 * is listed as a child, so a node graph that lists the same child twice at
 * each of n levels makes 2^n nodes while the file stays a kilobyte (20
 * levels: 2 M nodes, all built before a triangle is read). The graph is
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
int rt_model_check_gltf(const char *file, const char *json, size_t len, uint64_t max_tris, RtError *err)
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

