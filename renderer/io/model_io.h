/* model_io.h - what model.c hands Assimp (model_io.c): a file system of
 * its own that serves the model's folder only, from memory, recording
 * every file as a scene dependency; and checks of a model's bytes that
 * Assimp 5.2.5 lacks (PLY headers, glTF node graphs). Internal to the
 * model import. */
#ifndef RT_MODEL_IO_H
#define RT_MODEL_IO_H

#include <stddef.h>
#include <stdint.h>

#include "rt.h"

struct aiFileIO;
typedef struct ModelIO ModelIO;

/* Reads the model file (whole, once) and records it in scene; the IO
 * system then serves it and the files it references. NULL, with "file:
 * message" in err, when the model cannot be read. */
ModelIO *rt_model_io_open(const char *file, RtScene *scene, RtError *err);
struct aiFileIO *rt_model_io_fs(ModelIO *io);
/* The model file's bytes as read. */
const char *rt_model_io_bytes(const ModelIO *io, size_t *len);
/* The first reference the IO system refused ("file: reference 'x' ..."),
 * or NULL: Assimp's OBJ loader goes on without a material library it could
 * not open, so a refusal is remembered and fails the import afterwards. */
const char *rt_model_io_refusal(const ModelIO *io);
void rt_model_io_close(ModelIO *io);

/* Checks the model's bytes before Assimp sees them: a PLY header whose
 * element counts the file cannot hold (Assimp 5.2.5 loops or allocates
 * gigabytes), a glTF node graph that expands past max_triangles triangles
 * or max_triangles / RT_MODEL_TRIANGLES_PER_NODE node instances (at least
 * 4096), or has a
 * cycle. 0, or -1 with "file: message". */
#define RT_MODEL_TRIANGLES_PER_NODE 50
int rt_model_check_bytes(const char *file, const char *data, size_t len, uint64_t max_triangles, RtError *err);

/* The expansion limit's message, shared by the graph check and model.c
 * (instanced: the count is of node instances, not of the meshes alone). */
int rt_model_fail_expands(RtError *err, const char *file, uint64_t limit, const char *what, int instanced);
/* A glTF's JSON (of a .gltf, or a .glb's first chunk) checked as
 * rt_model_check_bytes says (model_gltf.c). */
int rt_model_check_gltf(const char *file, const char *json, size_t len, uint64_t max_tris, RtError *err);
/* Counts that saturate instead of wrapping. */
static inline uint64_t sat_add(uint64_t a, uint64_t b) { return a + b < a ? UINT64_MAX : a + b; }
static inline uint64_t sat_mul(uint64_t a, uint64_t b) { return b && a > UINT64_MAX / b ? UINT64_MAX : a * b; }

/* The limit on the triangles one model may expand to (default
 * RT_MODEL_MAX_TRIANGLES): raytrace --max-model-triangles N. 0, or -1 when
 * n is 0. (Declared in rt.h by the command line's owner.) */
#define RT_MODEL_MAX_TRIANGLES 50000000ull
int rt_model_set_max_triangles(uint64_t n);

#endif
