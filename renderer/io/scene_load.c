/* scene_load.c - a scene from a file or a buffer, and the choices of how
 * to read it: a scene file through the parser, or a model file (`raytrace
 * MODEL`) read by model.c and wrapped as a scene here; a buffer on one
 * thread (scene_parse.c) or in chunks on several (scene_chunks.c). Calls
 * go one way, from here down: the parser never chooses a model reader, and
 * model.c never calls the parser (a scene's `mesh:` lines are the one way
 * between them, parser to model.c). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "scene_parse.h"

int rt_scene_parse_buffer_sink(const char *name, const char *buf, size_t len, int threads, const RtGeomSink *sink,
                               RtScene *scene, RtWarnFn warn, void *warn_ctx, RtError *err)
{
    Parser p;
    if (parse_start(&p, name, scene, warn, warn_ctx, err) != 0)
        return -1;
    p.sink = sink;
    const int nt = rt_thread_count(threads);
    if (nt > 1 && len >= 2 * (size_t)RT_PARSE_CHUNK)
        return parse_chunks(&p, buf, len, nt);
    return parse_serial(&p, buf, len);
}

int rt_scene_parse_buffer_threads(const char *name, const char *buf, size_t len, int threads, RtScene *scene,
                                  RtWarnFn warn, void *warn_ctx, RtError *err)
{
    return rt_scene_parse_buffer_sink(name, buf, len, threads, NULL, scene, warn, warn_ctx, err);
}

int rt_scene_parse_buffer(const char *name, const char *buf, size_t len, RtScene *scene, RtWarnFn warn,
                          void *warn_ctx, RtError *err)
{
    return rt_scene_parse_buffer_threads(name, buf, len, 1, scene, warn, warn_ctx, err);
}

/* ---- raytrace MODEL ----------------------------------------------------------
 * A scene around one model: a 3/4 view from the front, above and to the
 * right, far enough that the bounding sphere fills the frame; a white key
 * light from the upper left, ambient light, a grey material with a
 * highlight. */
static void frame_model(RtScene *s)
{
    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint32_t i = 0; i < s->nvertices; i++) {
        const float v[3] = {s->vertices[i].x, s->vertices[i].y, s->vertices[i].z};
        for (int k = 0; k < 3; k++) {
            lo[k] = v[k] < lo[k] ? v[k] : lo[k];
            hi[k] = v[k] > hi[k] ? v[k] : hi[k];
        }
    }
    const RtVec3 c = rt_v3(0.5f * (lo[0] + hi[0]), 0.5f * (lo[1] + hi[1]), 0.5f * (lo[2] + hi[2]));
    float r = 0.5f * sqrtf((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) +
                           (hi[2] - lo[2]) * (hi[2] - lo[2]));
    r = r > 0.0f ? r : 1.0f;
    const RtVec3 dir = rt_normalize(rt_v3(0.55f, 0.45f, 1.0f)); /* from the model towards the camera */
    s->settings.fov_ha = 25.0f;
    const float dist = 1.15f * r / sinf(s->settings.fov_ha * 3.14159265f / 180.0f);
    s->settings.camera_pos = rt_madd(c, dir, dist);
    s->settings.camera_fwd = dir; /* the camera looks along minus camera_fwd */
    s->settings.camera_up = rt_v3(0.0f, 1.0f, 0.0f);
    s->settings.width = 800;
    s->settings.height = 600;
    s->settings.background = rt_v3(0.12f, 0.14f, 0.18f);
    s->settings.ambient = rt_v3(0.18f, 0.18f, 0.2f);
}

int rt_model_scene(const char *path, RtScene *s, RtError *err)
{
    static const char text[] = "material: .3 .3 .3 .65 .65 .62 .25 .25 .25 40 0 0 0 1\n"
                               "directional_light: .95 .95 .9 .6 -.8 -.5\n";
    if (rt_scene_parse_buffer(path, text, sizeof text - 1, s, NULL, NULL, err) != 0)
        return -1;
    static const float id[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
    if (rt_model_append(path, id, 1, s, err) != 0)
        return -1;
    frame_model(s);
    snprintf(s->settings.output, sizeof s->settings.output, "%s.png", s->source.name);
    return 0;
}

/* raytrace MODEL: the scene's file hash is that of the model's bytes as
 * Assimp read them (the first file model.c recorded under that name). */
static int model_scene(const char *path, RtScene *scene, RtError *err)
{
    if (rt_model_scene(path, scene, err) != 0)
        return -1;
    for (uint32_t i = 0; i < scene->source.ndeps; i++)
        if (strcmp(scene->source.deps[i].path, path) == 0) {
            memcpy(scene->source.file_hash, scene->source.deps[i].hash, 16);
            return 0;
        }
    char *buf; /* (a loader that read it otherwise: its bytes now) */
    size_t len;
    if (rt_read_file(path, RT_MAX_FILE, &buf, &len, err) != 0)
        return -1;
    rt_content_hash(buf, len, scene->source.file_hash);
    free(buf);
    return 0;
}

int rt_scene_load_threads(const char *path, int threads, RtScene *scene, RtWarnFn warn, void *warn_ctx,
                          RtError *err)
{
    return rt_scene_load_sink(path, threads, NULL, scene, warn, warn_ctx, err);
}

int rt_scene_load_sink(const char *path, int threads, const RtGeomSink *sink, RtScene *scene, RtWarnFn warn,
                       void *warn_ctx, RtError *err)
{
    memset(scene, 0, sizeof *scene);
    if (rt_model_supported(path)) /* raytrace MODEL: Assimp reads it (through model.c's own file access) */
        return model_scene(path, scene, err);
    /* Read once, whole: the bytes parsed are the bytes hashed (the cache's
     * key, MPI's agreement), and a file truncated underneath is an error,
     * not a SIGBUS in a mapping. */
    char *buf = NULL;
    size_t len = 0;
    if (rt_read_file(path, RT_MAX_FILE, &buf, &len, err) != 0)
        return -1;
    const int rc = rt_scene_parse_buffer_sink(path, buf, len, threads, sink, scene, warn, warn_ctx, err);
    if (rc == 0)
        rt_content_hash(buf, len, scene->source.file_hash);
    free(buf);
    return rc;
}

int rt_scene_load(const char *path, RtScene *scene, RtWarnFn warn, void *warn_ctx, RtError *err)
{
    return rt_scene_load_threads(path, 0, scene, warn, warn_ctx, err);
}
