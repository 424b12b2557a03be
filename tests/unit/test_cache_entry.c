/* test_cache_entry.c - a scene cache entry is checked as --verify checks a
 * fresh build, not only against its own hash: an entry whose payload hash
 * was recomputed after tampering (rt_cache_entry_seal, as anyone who can
 * write the folder could) is refused by rt_cache_entry_parse for every index
 * the renderer follows and every shape the traversals rely on, and
 * rt_cache_load removes such an entry and says "refused".
 * (Fails on the old code: it has no rt_cache_entry_parse/seal and trusted
 * any entry whose payload hash matched.)
 *
 * The header is private to io/scene_cache.c, so the arrays are found in the
 * entry's bytes by their known contents (each must occur exactly once at a
 * 64-byte offset), and the render settings by their output name. */
#define _GNU_SOURCE
#include <errno.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "check.h"
#include "rt.h"

static char tmpdir[256];

/* Writes the test scene: every light type, several materials, flat and
 * smooth triangles and spheres, enough primitives for a few wide nodes. */
static void write_scene(const char *path)
{
    FILE *f = fopen(path, "w");
    if (!f) {
        CHECK(0, "cannot write %s: %s", path, strerror(errno));
        return;
    }
    fprintf(f, "film_resolution: 32 24\ncamera_pos: 0 2 12\ncamera_fwd: 0 .1 1\ncamera_up: 0 1 0\n"
               "camera_fov_ha: 30\nmax_depth: 5\nbackground: .1 .1 .2\nambient_light: .1 .1 .1\n"
               "point_light: 10 10 10  1 6 4\ndirectional_light: .3 .3 .3  .2 -1 -.4\n"
               "spot_light: 8 8 6  -1 5 2  .1 -1 -.2  12 20\n"
               "material: .1 .1 .1  .6 .5 .4  .1 .1 .1  8  0 0 0  0\n"
               "material: .05 .1 .05  .3 .7 .3  .4 .4 .4  60  0 0 0  1\n"
               "material: .1 .02 .02  .8 .2 .2  .3 .3 .3  30  .2 .2 .2  1.5\n");
    /* 40 flat triangles on a 5 x 4 grid of quads (material 0) */
    for (int j = 0; j <= 4; j++)
        for (int i = 0; i <= 5; i++)
            fprintf(f, "vertex: %d %g %d\n", i * 2 - 5, -1.0 + 0.05 * i * j, -j * 2);
    for (int j = 0; j < 4; j++)
        for (int i = 0; i < 5; i++) {
            const int a = j * 6 + i;
            fprintf(f, "triangle: %d %d %d\ntriangle: %d %d %d\n", a, a + 1, a + 7, a, a + 7, a + 6);
        }
    /* 8 smooth triangles (material 1) */
    fprintf(f, "material: .05 .1 .05  .3 .7 .3  .4 .4 .4  60  0 0 0  1\n");
    for (int k = 0; k < 8; k++) {
        fprintf(f, "vertex: %d 1 -3\nvertex: %g 1 -3.5\nvertex: %g 2.5 -4\n", k - 4, k - 3.2, k - 3.6);
        fprintf(f, "normal: %g .1 1\nnormal: .2 %g 1\nnormal: -.1 .3 %g\n", 0.1 * k, 0.05 * k, 1.0 + 0.1 * k);
        fprintf(f, "normal_triangle: %d %d %d  %d %d %d\n", 30 + 3 * k, 31 + 3 * k, 32 + 3 * k, 3 * k, 3 * k + 1,
                3 * k + 2);
    }
    /* 10 spheres (material 2, then 4 after another material line) */
    fprintf(f, "material: .1 .02 .02  .8 .2 .2  .3 .3 .3  30  .2 .2 .2  1.5\n");
    for (int k = 0; k < 10; k++)
        fprintf(f, "sphere: %g %g %g %g\n", -4.5 + k, 0.5 + 0.1 * k, -5.0 - 0.3 * k, 0.3 + 0.02 * k);
    fclose(f);
}

/* Reads a whole file into a 64-byte aligned buffer. */
static char *read_aligned(const char *path, size_t *len)
{
    FILE *f = fopen(path, "rb");
    if (!f)
        return NULL;
    fseek(f, 0, SEEK_END);
    const long n = ftell(f);
    fseek(f, 0, SEEK_SET);
    char *b = n > 0 ? aligned_alloc(64, ((size_t)n + 63) / 64 * 64) : NULL;
    if (!b || fread(b, 1, (size_t)n, f) != (size_t)n) {
        free(b);
        fclose(f);
        return NULL;
    }
    fclose(f);
    *len = (size_t)n;
    return b;
}

/* The offset of the only 64-byte aligned place where `want` occurs; -1
 * when none or several. */
static long find_array(const char *m, size_t len, const void *want, size_t n, const char *what)
{
    long at = -1;
    int found = 0;
    if (n == 0)
        return -1;
    for (size_t o = 0; o + n <= len; o += 64)
        if (memcmp(m + o, want, n) == 0)
            at = (long)o, found++;
    CHECK(found == 1, "%s: found %d times in the entry (want exactly once)", what, found);
    return found == 1 ? at : -1;
}

/* Where the pieces of the entry are. */
typedef struct {
    long verts, normals, tris, lights, prims, nodes, wide, settings;
} Layout;

static RtScene S;
static RtAccel A;
static char *entry;
static size_t entry_len;
static Layout L;

static int locate(void)
{
    L.verts = find_array(entry, entry_len, S.vertices, S.nvertices * sizeof *S.vertices, "vertices");
    L.normals = find_array(entry, entry_len, S.normals, S.nnormals * sizeof *S.normals, "normals");
    L.tris = find_array(entry, entry_len, S.triangles, S.ntriangles * sizeof *S.triangles, "triangles");
    L.lights = find_array(entry, entry_len, S.lights, S.nlights * sizeof *S.lights, "lights");
    L.prims = find_array(entry, entry_len, A.prims, A.nprims * sizeof *A.prims, "primitive records");
    L.nodes = find_array(entry, entry_len, A.nodes, A.nnodes * sizeof *A.nodes, "BVH nodes");
    L.wide = find_array(entry, entry_len, A.wide, A.nwide * sizeof *A.wide, "wide nodes");
    /* the settings: by their output name (unique in the entry), then checked */
    L.settings = -1;
    const size_t ol = strlen(S.settings.output) + 1;
    int found = 0;
    for (size_t o = 0; o + ol <= entry_len; o++)
        if (memcmp(entry + o, S.settings.output, ol) == 0 && o >= offsetof(RtSceneSettings, output)) {
            L.settings = (long)(o - offsetof(RtSceneSettings, output));
            found++;
        }
    CHECK(found == 1, "the scene's output name found %d times", found);
    if (found == 1 && (size_t)L.settings + sizeof(RtSceneSettings) <= entry_len) {
        RtSceneSettings copy;
        memcpy(&copy, entry + L.settings, sizeof copy);
        CHECK(copy.max_depth == S.settings.max_depth &&
                  memcmp(&copy.camera_pos, &S.settings.camera_pos, sizeof S.settings.camera_pos) == 0 &&
                  copy.width == S.settings.width && copy.height == S.settings.height,
              "the settings are not where their output name says");
    } else {
        L.settings = -1;
    }
    return L.verts < 0 || L.normals < 0 || L.tris < 0 || L.lights < 0 || L.prims < 0 || L.nodes < 0 ||
                   L.wide < 0 || L.settings < 0
               ? -1
               : 0;
}

/* Array views into a copy of the entry. */
#define AT(buf, off, type) ((type *)((buf) + (off)))

typedef void (*Tamper)(char *b);

static uint32_t first_smooth(void)
{
    for (uint32_t i = 0; i < S.ntriangles; i++)
        if (S.triangles[i].n[0] >= 0)
            return i;
    return 0;
}
static uint32_t a_triangle_prim(void)
{
    for (uint32_t i = 0; i < A.nprims; i++)
        if (!(A.prims[i].id & RT_PRIM_SPHERE_BIT))
            return i;
    return 0;
}
/* A wide node with an inner child: its index and the child's slot. */
static int wide_inner(uint32_t from, uint32_t *node, uint32_t *slot)
{
    for (uint32_t n = from; n < A.nwide; n++)
        for (uint32_t k = 0; k < A.wide[n].count && k < 4; k++)
            if (!(A.wide[n].child[k] & RT_WIDE_LEAF) && A.wide[n].child[k] != RT_WIDE_EMPTY) {
                *node = n, *slot = k;
                return 1;
            }
    return 0;
}
static int wide_leaf(uint32_t *node, uint32_t *slot)
{
    for (uint32_t n = 0; n < A.nwide; n++)
        for (uint32_t k = 0; k < A.wide[n].count && k < 4; k++)
            if (A.wide[n].child[k] & RT_WIDE_LEAF && A.wide[n].child[k] != RT_WIDE_EMPTY) {
                *node = n, *slot = k;
                return 1;
            }
    return 0;
}

static void t_wide_cycle_root(char *b)
{
    uint32_t n = 0, k = 0;
    wide_inner(0, &n, &k);
    AT(b, L.wide, RtBvh4Node)[n].child[k] = 0; /* back to the root */
}
static void t_wide_cycle_self(char *b)
{
    uint32_t n = 0, k = 0;
    wide_inner(0, &n, &k);
    const uint32_t c = A.wide[n].child[k];
    AT(b, L.wide, RtBvh4Node)[c].child[0] = c; /* a node that is its own child */
}
static void t_wide_past(char *b)
{
    uint32_t n = 0, k = 0;
    wide_inner(0, &n, &k);
    AT(b, L.wide, RtBvh4Node)[n].child[k] = A.nwide + 5;
}
static void t_wide_leaf_past(char *b)
{
    uint32_t n = 0, k = 0;
    wide_leaf(&n, &k);
    AT(b, L.wide, RtBvh4Node)[n].child[k] = RT_WIDE_LEAF | (A.nprims - 1) << 3 | 3u; /* 4 records from the last */
}
static void t_leaf_past(char *b)
{
    for (uint32_t i = 0; i < A.nnodes; i++)
        if (A.nodes[i].meta & 0xffu) {
            AT(b, L.nodes, RtBvhNode)[i].index = A.nprims; /* [nprims, +count) */
            return;
        }
}
static void t_second_child_back(char *b)
{
    for (uint32_t i = 1; i < A.nnodes; i++)
        if (!(A.nodes[i].meta & 0xffu)) {
            AT(b, L.nodes, RtBvhNode)[i].index = 0; /* back to the root */
            return;
        }
}
static void t_material(char *b) { AT(b, L.tris, RtTriangle)[0].material = S.nmaterials; }
static void t_normal(char *b) { AT(b, L.tris, RtTriangle)[first_smooth()].n[1] = (int32_t)S.nnormals; }
static void t_vertex(char *b) { AT(b, L.tris, RtTriangle)[0].v[2] = S.nvertices; }
static void t_sphere_bit(char *b) { AT(b, L.prims, RtPrim)[a_triangle_prim()].id |= RT_PRIM_SPHERE_BIT; }
static void t_prim_past(char *b) { AT(b, L.prims, RtPrim)[a_triangle_prim()].id = S.nspheres + S.ntriangles; }
static void t_light(char *b) { AT(b, L.lights, RtLight)[1].type = 7; }
static void t_depth(char *b) { AT(b, L.settings, RtSceneSettings)->max_depth = 99; }

static const struct {
    const char *name;
    Tamper f;
    const char *says; /* a word the message must hold */
} cases[] = {
    {"a wide node's child pointing back to node 0", t_wide_cycle_root, "wide"},
    {"a wide node that is its own child", t_wide_cycle_self, "wide"},
    {"a wide child index past nwide", t_wide_past, "wide"},
    {"a wide leaf's range past nprims", t_wide_leaf_past, "wide"},
    {"a leaf's range past nprims", t_leaf_past, "leaf"},
    {"a binary node's second child pointing backwards", t_second_child_back, "children"},
    {"a triangle's material past nmaterials", t_material, "material"},
    {"a normal index past nnormals", t_normal, "normal"},
    {"a vertex index past nvertices", t_vertex, "vertex"},
    {"a primitive id with the wrong sphere bit", t_sphere_bit, "sphere bit"},
    {"a primitive id past the scene", t_prim_past, "primitive"},
    {"a light of type 7", t_light, "type 7"},
    {"max_depth 99", t_depth, "max_depth 99"},
};

/* A fresh 64-byte aligned copy of the entry. */
static char *copy_entry(void)
{
    char *b = aligned_alloc(64, (entry_len + 63) / 64 * 64);
    if (b)
        memcpy(b, entry, entry_len);
    return b;
}

static void rm_rf(const char *dir)
{
    char cmd[512];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
    if (system(cmd) != 0)
        fprintf(stderr, "note: could not remove %s\n", dir);
}

int main(void)
{
    snprintf(tmpdir, sizeof tmpdir, "%s/rt-cache-entry-XXXXXX", getenv("TMPDIR") ? getenv("TMPDIR") : "/tmp");
    if (!mkdtemp(tmpdir)) {
        perror("mkdtemp");
        return 1;
    }
    char scene_path[512], dir[512], entry_path[600];
    snprintf(scene_path, sizeof scene_path, "%s/s.txt", tmpdir);
    snprintf(dir, sizeof dir, "%s/c", tmpdir);
    write_scene(scene_path);
    RtError e;
    if (rt_scene_load(scene_path, &S, NULL, NULL, &e) != 0 || rt_accel_build(&S, RT_ACCEL_BVH, &A, &e) != 0) {
        CHECK(0, "%s", e.msg);
        rm_rf(tmpdir);
        return check_report("cache-entry");
    }
    CHECK(S.nlights == 3 && S.nspheres == 10 && S.ntriangles == 48 && S.nnormals == 24 && S.nmaterials >= 3,
          "the scene: %u lights, %u spheres, %u triangles, %u normals, %u materials", S.nlights, S.nspheres,
          S.ntriangles, S.nnormals, S.nmaterials);
    uint32_t n0, k0, n1, k1;
    CHECK(A.nwide >= 3 && wide_inner(0, &n0, &k0) && wide_leaf(&n1, &k1),
          "the tree is too small to tamper with (%u wide nodes)", A.nwide);

    char key[64] = "";
    if (rt_cache_store(dir, &S, &A, key, &e) != 0) {
        CHECK(0, "rt_cache_store: %s", e.msg);
        goto out;
    }
    snprintf(entry_path, sizeof entry_path, "%s/%s.rbc", dir, key);
    entry = read_aligned(entry_path, &entry_len);
    CHECK(entry != NULL, "cannot read the entry %s", entry_path);
    if (!entry || locate() != 0)
        goto out;

    /* the entry as stored is accepted, before and after sealing it again */
    for (int sealed = 0; sealed < 2; sealed++) {
        char *b = copy_entry();
        if (sealed)
            rt_cache_entry_seal(b, entry_len);
        RtScene s;
        RtAccel a;
        e.msg[0] = '\0';
        const int rc = rt_cache_entry_parse(b, entry_len, RT_ACCEL_BVH, &s, &a, &e);
        CHECK(rc == 0, "the untampered entry (sealed %d) refused: %s", sealed, e.msg);
        if (rc == 0) {
            CHECK(s.ntriangles == S.ntriangles && a.nprims == A.nprims && a.nwide == A.nwide &&
                      memcmp(s.triangles, S.triangles, S.ntriangles * sizeof *S.triangles) == 0,
                  "the parsed entry is not the scene stored");
            rt_scene_free_deps(&s);
        }
        free(b);
    }
    /* a tampered entry without a new seal is damage (the hash) */
    {
        char *b = copy_entry();
        t_light(b);
        RtScene s;
        RtAccel a;
        CHECK(rt_cache_entry_parse(b, entry_len, RT_ACCEL_BVH, &s, &a, &e) != 0, "an unsealed tampered entry accepted");
        free(b);
    }

    /* each tampering, sealed: refused with a message */
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        char *b = copy_entry();
        cases[i].f(b);
        CHECK(memcmp(b, entry, entry_len) != 0, "%s: the tampering changed nothing", cases[i].name);
        rt_cache_entry_seal(b, entry_len);
        RtScene s;
        RtAccel a;
        e.msg[0] = '\0';
        const int rc = rt_cache_entry_parse(b, entry_len, RT_ACCEL_BVH, &s, &a, &e);
        CHECK(rc != 0, "%s: accepted", cases[i].name);
        if (rc == 0)
            rt_scene_free_deps(&s);
        CHECK(rc == 0 || (e.msg[0] && strstr(e.msg, cases[i].says)), "%s: message '%s' lacks '%s'", cases[i].name,
              e.msg, cases[i].says);
        printf("%-50s -> %s\n", cases[i].name, rc ? e.msg : "ACCEPTED");
        free(b);
    }

    /* through the folder: the real entry loads; a sealed tampered one
     * written over it is refused, removed, and said so */
    {
        RtScene s;
        RtAccel a;
        char k2[64];
        e.msg[0] = '\0';
        const int rc = rt_cache_load(dir, scene_path, RT_ACCEL_BVH, &s, &a, k2, &e);
        CHECK(rc == 1, "the real entry did not load (%d): %s", rc, e.msg);
        if (rc == 1) {
            CHECK(strcmp(k2, key) == 0, "load key %s, store key %s", k2, key);
            CHECK(s.ntriangles == S.ntriangles && a.nprims == A.nprims, "the loaded scene differs");
            rt_accel_free(&a);
            rt_scene_free(&s);
        }
        for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
            char *b = copy_entry();
            cases[i].f(b);
            rt_cache_entry_seal(b, entry_len);
            FILE *f = fopen(entry_path, "wb");
            CHECK(f && fwrite(b, 1, entry_len, f) == entry_len && fclose(f) == 0, "cannot write %s", entry_path);
            free(b);
            e.msg[0] = '\0';
            const int lr = rt_cache_load(dir, scene_path, RT_ACCEL_BVH, &s, &a, k2, &e);
            CHECK(lr == 0, "%s: rt_cache_load gave %d (want 0, a miss)", cases[i].name, lr);
            if (lr == 1) {
                rt_accel_free(&a);
                rt_scene_free(&s);
            }
            CHECK(strstr(e.msg, "refused") != NULL, "%s: load message '%s' lacks 'refused'", cases[i].name, e.msg);
            CHECK(access(entry_path, F_OK) != 0 && errno == ENOENT, "%s: the refused entry is still there",
                  cases[i].name);
        }
    }
out:
    free(entry);
    rt_accel_free(&A);
    rt_scene_free(&S);
    rm_rf(tmpdir);
    return check_report("cache-entry");
}
