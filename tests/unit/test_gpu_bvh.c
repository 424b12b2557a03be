/* test_gpu_bvh.c SCENE... - the BVH the GPU builds (backends/cuda/bvh_gpu.cu)
 * against the CPU's, on the scenes given and on degenerate ones made here
 * (400,000 identical triangles, zero-area and collinear triangles, one
 * primitive, spheres alone, two records):
 *   - rt_bvh_check holds on the GPU's binary and 4-wide trees;
 *   - every record is in a leaf, bit-identical to the CPU's record of the
 *     same primitive; a record in more than one is a split triangle's
 *     piece, exactly nsplit of them (bvh_gpu_split.cuh);
 *   - long diagonal slivers across a grid of small triangles are split, and
 *     the tree's SAH cost falls against the build without splits;
 *   - every primary ray, and the mirror ray from each hit, gets the same hit
 *     (t, u, v, primitive) from the GPU's tree as from the CPU's;
 *   - a second build gives the same tree size and SAH cost;
 *   - every scene builds again with --gpu-split 30, every check the same;
 *   - the tree stays on the device until rt_accel_host copies it down.
 * Prints each tree's SAH cost, node visits per ray and build times. Exit 77
 * where no CUDA device is usable (CI); course:PATH as test_wide. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
/* the CPU's leaf vote (rt_traverse.h): a leaf at once */
#define RT_WIDE_LEAF_VOTE(has_leaf, any) (has_leaf)
#include "core/rt_shade.h"
#include "rt.h"
#include "backends/cuda/bvh_gpu.h"
#include "backends/cuda/cuda_session.h"

/* Each record, equal to the CPU's record of the same primitive; the copies
 * beyond the first are the split pieces. */
static void check_records(const char *name, const RtAccel *cpu, const RtAccel *gpu, uint32_t nspheres)
{
    const uint32_t n = cpu->nprims - cpu->nsplit;
    uint8_t *seen = calloc(n ? n : 1, 1);
    const RtPrim **want = calloc(n ? n : 1, sizeof *want);
    long dup = 0, bad = 0, diff = 0;
    for (uint32_t i = 0; i < cpu->nprims; i++) {
        const uint32_t id = cpu->prims[i].id, g = id & RT_PRIM_SPHERE_BIT ? id & ~RT_PRIM_SPHERE_BIT : id;
        if (g < n)
            want[g] = &cpu->prims[i];
    }
    for (uint32_t i = 0; i < gpu->nprims; i++) {
        const uint32_t id = gpu->prims[i].id, sphere = (id & RT_PRIM_SPHERE_BIT) != 0;
        const uint32_t g = sphere ? id & ~RT_PRIM_SPHERE_BIT : id;
        if (g >= n || sphere != (g < nspheres)) {
            bad++;
            continue;
        }
        dup += seen[g]++ != 0;
        diff += want[g] && memcmp(want[g], &gpu->prims[i], sizeof(RtPrim)) != 0;
    }
    CHECK(gpu->nprims == n + gpu->nsplit && dup == gpu->nsplit && bad == 0,
          "%s: %u records for %u primitives, %ld copies (%u pieces), %ld bad ids", name, gpu->nprims, n, dup,
          gpu->nsplit, bad);
    CHECK(diff == 0, "%s: %ld records differ from the CPU's", name, diff);
    free(seen);
    free(want);
}

/* Primary and mirror rays: the same hits through either tree. */
static void check_hits(const char *name, const RtScene *s, const RtAccel *cpu, const RtAccel *gpu)
{
    RtCamera cam;
    RtError e;
    if (rt_scene_camera(s, &cam, &e) != 0) {
        CHECK(0, "%s: %s", name, e.msg);
        return;
    }
    const RtSceneView vc = rt_scene_view(s, cpu, &cam), vg = rt_scene_view(s, gpu, &cam);
    RtCounters cc, cg;
    memset(&cc, 0, sizeof cc);
    memset(&cg, 0, sizeof cg);
    long rays = 0, bad = 0;
    const int step = cam.width * cam.height > 1 << 20 ? 4 : 1;
    for (int j = 0; j < cam.height; j += step)
        for (int i = 0; i < cam.width; i += step) {
            const RtRay r = rt_camera_ray(&cam, i, j);
            RtHit hc, hg;
            int fc = rt_trace_ray_wide(&vc, r.o, r.d, RT_INF, 0, &hc, &cc);
            int fg = rt_trace_ray_wide(&vg, r.o, r.d, RT_INF, 0, &hg, &cg);
            rays++;
            bad += !(fc == fg && (!fc || (hc.t == hg.t && hc.id == hg.id && hc.u == hg.u && hc.v == hg.v)));
            if (!fc || !vc.nmaterials)
                continue;
            const RtSurface sf = rt_surface(&vc, r.o, r.d, &hc);
            const RtVec3 R = rt_normalize(rt_sub(r.d, rt_scale(sf.n, 2.0f * rt_dot(r.d, sf.n))));
            const RtVec3 ro = rt_madd(sf.p, R, RT_SECONDARY_OFFSET);
            fc = rt_trace_ray_wide(&vc, ro, R, RT_INF, 0, &hc, &cc);
            fg = rt_trace_ray_wide(&vg, ro, R, RT_INF, 0, &hg, &cg);
            rays++;
            bad += !(fc == fg && (!fc || (hc.t == hg.t && hc.id == hg.id && hc.u == hg.u && hc.v == hg.v)));
        }
    CHECK(bad == 0, "%s: %ld of %ld rays hit differently through the GPU's tree", name, bad, rays);
    printf("%s: %ld rays, node visits per ray CPU %.2f GPU %.2f, tests %.2f / %.2f\n", name, rays,
           (double)cc.node_visits / (double)rays, (double)cg.node_visits / (double)rays,
           (double)cc.prim_tests / (double)rays, (double)cg.prim_tests / (double)rays);
}

/* Both builds of scene s (the GPU's with set), and every check;
 * with_camera: s has one. */
static void check_scene(const char *name, const RtScene *s, const RtBvhSettings *set, int with_camera)
{
    RtAccel cpu, gpu, again;
    RtBuildInfo info, info2;
    RtError e;
    double t0 = rt_now_ms();
    if (rt_accel_build(s, RT_ACCEL_BVH, &cpu, &e) != 0) {
        CHECK(0, "%s: CPU build: %s", name, e.msg);
        return;
    }
    const double cpu_ms = rt_now_ms() - t0;
    t0 = rt_now_ms();
    int rc = rt_cuda_accel_build(s, set, 0, &gpu, &info, &e);
    const double gpu_ms = rt_now_ms() - t0;
    CHECK(rc == 0, "%s: GPU build: %d, %s", name, rc, rc ? e.msg : "");
    double down_ms = 0.0;
    if (rc == 0) {
        CHECK(gpu.device != NULL && gpu.prims == NULL, "%s: the GPU's tree is not on the device alone", name);
        t0 = rt_now_ms();
        CHECK(rt_accel_host(&gpu, &e) == 0, "%s: copying the tree down: %s", name, e.msg);
        down_ms = rt_now_ms() - t0;
        CHECK(rt_bvh_check(&gpu, &e) == 0, "%s: the GPU's tree: %s", name, e.msg);
        check_records(name, &cpu, &gpu, s->nspheres);
        if (with_camera)
            check_hits(name, s, &cpu, &gpu);
        rc = rt_cuda_accel_build(s, set, 0, &again, &info2, &e);
        CHECK(rc == 0 && again.nnodes == gpu.nnodes && again.nwide == gpu.nwide && again.sah_cost == gpu.sah_cost,
              "%s: a second GPU build differs: %u/%u nodes, %u/%u wide, SAH %.4f/%.4f", name, gpu.nnodes,
              again.nnodes, gpu.nwide, again.nwide, gpu.sah_cost, again.sah_cost);
        printf("%s: %u records, %u pieces; CPU: %u nodes, depth %u, SAH %.3f, %.2f ms; GPU: %u nodes, %u wide, depth %u, "
               "SAH %.3f (%.3fx), kernels %.3f ms (again %.3f), upload %.2f, whole %.2f ms; tree down %.2f ms\n",
               name, gpu.nprims - gpu.nsplit, gpu.nsplit, cpu.nnodes, cpu.depth, cpu.sah_cost, cpu_ms, gpu.nnodes, gpu.nwide, gpu.depth,
               gpu.sah_cost, cpu.sah_cost > 0 ? gpu.sah_cost / cpu.sah_cost : 0.0, info.kernel_ms, info2.kernel_ms,
               info.upload_ms, gpu_ms, down_ms);
        if (rc == 0)
            rt_accel_free(&again);
        rt_accel_free(&gpu);
    }
    rt_accel_free(&cpu);
}

/* The settings of the builds with pieces: Karras and Aila's budget. */
static RtBvhSettings split_settings(void)
{
    RtBvhSettings s = rt_bvh_settings_default();
    s.gpu_split = 30;
    return s;
}

/* A scene of ntri triangles over the vertex pool v (nv vertices, copied) and
 * nsph unit spheres along x. */
static void make_scene(RtScene *s, const RtVec3 *v, uint32_t nv, uint32_t ntri, const uint32_t (*tri)[3],
                       uint32_t nsph)
{
    memset(s, 0, sizeof *s);
    s->vertices = malloc((nv ? nv : 1) * sizeof *s->vertices);
    s->triangles = calloc(ntri ? ntri : 1, sizeof *s->triangles);
    s->spheres = calloc(nsph ? nsph : 1, sizeof *s->spheres);
    memcpy(s->vertices, v, nv * sizeof *v);
    s->nvertices = nv;
    for (uint32_t i = 0; i < ntri; i++)
        for (int k = 0; k < 3; k++) {
            s->triangles[i].v[k] = tri[i % 4][k];
            s->triangles[i].n[k] = -1;
        }
    s->ntriangles = ntri;
    for (uint32_t i = 0; i < nsph; i++) {
        s->spheres[i].c[0] = (float)(i % 7) * 0.5f;
        s->spheres[i].c[1] = (float)(i / 7);
        s->spheres[i].r = 1.0f + (float)(i % 3);
    }
    s->nspheres = nsph;
}

/* Input no build may fail on. */
static void check_degenerate(void)
{
    const RtVec3 v[5] = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {0, 1, 0}, {3, 0, 0}};
    const uint32_t same[4][3] = {{0, 1, 3}, {0, 1, 3}, {0, 1, 3}, {0, 1, 3}};
    const uint32_t flat[4][3] = {{0, 1, 2}, {0, 0, 0}, {1, 2, 4}, {2, 2, 2}}; /* collinear, a point */
    const struct {
        const char *name;
        uint32_t ntri;
        const uint32_t (*tri)[3];
        uint32_t nsph;
    } cases[] = {{"400000 identical triangles", 400000, same, 0}, {"1000 zero-area triangles", 1000, flat, 0},
                 {"one triangle", 1, same, 0},                    {"a triangle and a sphere", 1, same, 1},
                 {"3000 spheres", 0, same, 3000}};
    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
        RtScene s;
        make_scene(&s, v, 5, cases[k].ntri, cases[k].tri, cases[k].nsph);
        const RtBvhSettings split = split_settings();
        char name[128];
        snprintf(name, sizeof name, "%s, split", cases[k].name);
        check_scene(cases[k].name, &s, NULL, 0);
        check_scene(name, &s, &split, 0);
        rt_scene_free(&s);
    }
}

/* Twenty long slivers across a 100x100 grid of small triangles, diagonal,
 * so each one's box covers a sixth of the grid (the case Karras and Aila
 * split for): with --gpu-split they are split, and the tree costs less
 * than one without. */
static void check_split(void)
{
    enum { G = 100, S = 20 };
    const uint32_t ntri = G * G + S, nv = 3 * ntri;
    RtVec3 *v = malloc(nv * sizeof *v);
    for (uint32_t i = 0; i < G * G; i++) {
        const float x = (float)(i % G), z = (float)(i / G);
        v[3 * i] = (RtVec3){x, 0.0f, z}, v[3 * i + 1] = (RtVec3){x + 0.5f, 0.0f, z};
        v[3 * i + 2] = (RtVec3){x, 0.5f, z + 0.5f};
    }
    for (uint32_t j = 0; j < S; j++) {
        const uint32_t i = G * G + j;
        const float x0 = 4.0f * (float)j, z0 = 30.0f;
        v[3 * i] = (RtVec3){x0, 0.25f, z0}, v[3 * i + 1] = (RtVec3){x0 + 40.0f, 0.25f, z0 + 40.0f};
        v[3 * i + 2] = (RtVec3){x0 + 0.1f, 0.3f, z0};
    }
    RtScene s;
    memset(&s, 0, sizeof s);
    s.vertices = v, s.nvertices = nv, s.ntriangles = ntri;
    s.triangles = calloc(ntri, sizeof *s.triangles);
    s.spheres = calloc(1, sizeof *s.spheres);
    for (uint32_t i = 0; i < ntri; i++)
        for (int k = 0; k < 3; k++)
            s.triangles[i].v[k] = 3 * i + (uint32_t)k, s.triangles[i].n[k] = -1;
    RtBvhSettings set = split_settings();
    check_scene("20 slivers across 10000 triangles, split", &s, &set, 0);
    RtAccel with, without;
    RtBuildInfo info;
    RtError e;
    int rc = rt_cuda_accel_build(&s, &set, 0, &with, &info, &e);
    set.gpu_split = 0;
    const int rc0 = rt_cuda_accel_build(&s, &set, 0, &without, &info, &e);
    CHECK(rc == 0 && rc0 == 0, "split scene: GPU build: %s", e.msg);
    if (rc == 0 && rc0 == 0) {
        CHECK(with.nsplit > 0 && without.nsplit == 0, "split scene: %u pieces with splits, %u without", with.nsplit,
              without.nsplit);
        CHECK(with.sah_cost < 0.9 * without.sah_cost, "split scene: SAH %.3f with splits, %.3f without",
              with.sah_cost, without.sah_cost);
        printf("split scene: %u pieces, SAH %.3f against %.3f without\n", with.nsplit, with.sah_cost,
               without.sah_cost);
    }
    if (rc == 0)
        rt_accel_free(&with);
    if (rc0 == 0)
        rt_accel_free(&without);
    rt_scene_free(&s);
}

int main(int argc, char **argv)
{
    char buf[4096];
    int ndev = 0;
    RtError e;
    if (rt_cuda_device_count(&ndev, &e) != 0) {
        printf("SKIP: %s\n", e.msg);
        return 77;
    }
    if (check_scenes_present(argc, argv) != 0)
        return 77;
    check_degenerate();
    check_split();
    for (int k = 1; k < argc; k++) {
        const char *path = check_scene_path(argv[k], buf, sizeof buf);
        RtScene s;
        if (rt_scene_load(path, &s, NULL, NULL, &e) != 0) {
            CHECK(0, "%s", e.msg);
            continue;
        }
        const RtBvhSettings split = split_settings();
        check_scene(path, &s, NULL, 1);
        char name[4200];
        snprintf(name, sizeof name, "%s, split", path);
        check_scene(name, &s, &split, 1);
        rt_scene_free(&s);
    }
    return check_report("test_gpu_bvh");
}
