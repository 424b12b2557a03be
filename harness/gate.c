/* gate.c: the correctness gate of `harness run`: each ok run's image hash
 * against the reference of the same image (scene, resolution, depth). A
 * fast wrong image never enters a table. */
#include "run.h"

#include <stdlib.h>
#include <string.h>

HxImageRef *hx_ref_find(HxRefTable *t, const char *key)
{
    for (size_t i = 0; i < t->n; i++)
        if (strcmp(t->v[i].key, key) == 0)
            return &t->v[i];
    return NULL;
}

const char *hx_gate(HxRefTable *t, const char *key, const char *backend,
                        const char *hash, const char *run_id, char **detail)
{
    if (!hash || !*hash)
        return "ok";
    int serial = strcmp(backend, "serial") == 0;
    int cuda = hx_backend_gpu(backend);
    HxImageRef *r = hx_ref_find(t, key);
    if (!r || (!r->serial && serial)) {
        if (!r && !cuda) {
            t->v = hx_xrealloc(t->v, (t->n + 1) * sizeof *t->v);
            r = &t->v[t->n++];
            r->key = hx_strdup(key);
        } else if (!r) {
            return "ok";
        } else {
            free(r->hash);
            free(r->run_id);
        }
        r->hash = hx_strdup(hash);
        r->run_id = hx_strdup(run_id);
        r->serial = serial;
        return "ok";
    }
    if (strcmp(r->hash, hash) == 0)
        return "ok";
    HxBuf b = {0};
    hx_buf_printf(&b, "%simage_fnv1a %s != reference %s (%s)",
                  cuda ? "gpu-tolerance: " : "", hash, r->hash, r->run_id);
    free(*detail);
    *detail = b.s;
    return cuda ? "ok" : "wrong-image";
}

void hx_ref_free(HxRefTable *t)
{
    for (size_t i = 0; i < t->n; i++) {
        free(t->v[i].key);
        free(t->v[i].hash);
        free(t->v[i].run_id);
    }
    free(t->v);
}

char *hx_image_key(const char *scene_path, const char *res, const char *depth)
{
    HxBuf b = {0};
    hx_buf_printf(&b, "%s|%s|%s", scene_path, res, depth);
    return b.s;
}

