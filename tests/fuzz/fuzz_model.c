/* fuzz_model.c - fuzz target: one model file through rt_model_append into
 * a fresh scene (renderer/io/model.c and model_io.c, Assimp behind them).
 * The input is written as m.EXT in a folder of its own, the format picked
 * from its bytes (ply, glTF magic, '{', "solid") or else from the first
 * byte; beside it lie a buffer and a material library the seed models
 * reference, so the file system's resolution runs too. A scene that loads
 * must hold only indices inside its pools. Linked with driver.c. */
#define _GNU_SOURCE
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "io/model_io.h"
#include "rt.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static char dir[256];

static void put(const char *name, const void *bytes, size_t len)
{
    char path[512];
    snprintf(path, sizeof path, "%s/%s", dir, name);
    FILE *f = fopen(path, "wb");
    if (!f)
        abort();
    fwrite(bytes, 1, len, f);
    fclose(f);
}

/* The folder, once: buf.bin (a triangle's positions, then indices 0 1 2)
 * and m.mtl for the seeds that name them. */
static void setup(void)
{
    const char *tmp = getenv("TMPDIR") ? getenv("TMPDIR") : "/tmp";
    snprintf(dir, sizeof dir, "%s/fuzz-model-XXXXXX", tmp);
    if (!mkdtemp(dir))
        abort();
    const float pos[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    const uint16_t idx[4] = {0, 1, 2, 0};
    uint8_t buf[44];
    memcpy(buf, pos, 36), memcpy(buf + 36, idx, 8);
    put("buf.bin", buf, sizeof buf);
    static const char mtl[] = "newmtl red\nKd 1 0 0\n";
    put("m.mtl", mtl, sizeof mtl - 1);
    rt_model_set_max_triangles(2000000); /* expansions cost time, not findings */
}

static const char *format_of(const uint8_t *d, size_t n)
{
    static const char *const by_byte[] = {"obj", "ply", "stl", "gltf", "glb"};
    if (n >= 3 && (memcmp(d, "ply", 3) == 0 || memcmp(d, "PLY", 3) == 0))
        return "ply";
    if (n >= 4 && memcmp(d, "glTF", 4) == 0)
        return "glb";
    if (n >= 1 && d[0] == '{')
        return "gltf";
    if (n >= 5 && memcmp(d, "solid", 5) == 0)
        return "stl";
    if (n >= 1 && (d[0] == 'v' || d[0] == '#' || d[0] == 'o' || d[0] == 'm' || d[0] == 'f'))
        return "obj";
    return n ? by_byte[d[0] % 5] : "obj";
}

static void check_scene(const RtScene *s)
{
    for (uint32_t i = 0; i < s->ntriangles; i++)
        for (int k = 0; k < 3; k++)
            if (s->triangles[i].v[k] >= s->nvertices ||
                (s->triangles[i].n[k] != -1 && (uint32_t)s->triangles[i].n[k] >= s->nnormals)) {
                fprintf(stderr, "fuzz_model: triangle %u has an index outside the pools\n", i);
                abort();
            }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (!dir[0])
        setup();
    char name[16], path[512];
    snprintf(name, sizeof name, "m.%s", format_of(data, size));
    snprintf(path, sizeof path, "%s/%s", dir, name);
    put(name, data, size);
    RtScene s;
    memset(&s, 0, sizeof s);
    RtError err;
    static const float id[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
    if (rt_model_append(path, id, 0, &s, &err) == 0)
        check_scene(&s);
    else if (!err.msg[0] || strchr(err.msg, '\n'))
        (fprintf(stderr, "fuzz_model: an error that is not one line: '%s'\n", err.msg), abort());
    rt_scene_free(&s);
    unlink(path);
    return 0;
}
