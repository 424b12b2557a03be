/* main.c - the raytrace command: options (cli/options.c) -> scene -> accel ->
 * backend -> image + one machine-readable record line on stdout. */
#include <errno.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>
#ifdef __GLIBC__
#include <malloc.h>
#endif

#include "config.h"
#include "rt.h"
#include "rt_commit.h" /* RT_COMMIT: renderer/meson.build */
#include "raybench/record_schema.h"
#include "backends/backends.h"
#include "cli/options.h"

typedef struct Progress {
    int enabled;
    int last_pct;
} Progress;

static void progress_cb(void *ctx, uint64_t done, uint64_t total)
{
    Progress *p = (Progress *)ctx;
    int pct = total ? (int)(100 * done / total) : 100;
    if (pct != p->last_pct) {
        p->last_pct = pct;
        fprintf(stderr, "\rrendering %3d%%", pct);
        if (done == total)
            fputc('\n', stderr);
        fflush(stderr);
    }
}

/* SIGINT/SIGTERM: no half-written file is left (the named temporary file
 * where a file system lacks O_TMPFILE: io/atomic.c); then the default
 * action, so the parent sees the signal. */
static void on_stop_signal(int sig)
{
    rt_atomic_abandon();
    signal(sig, SIG_DFL);
    raise(sig);
}

static void warn_cb(void *ctx, const char *msg)
{
    (void)ctx;
    rt_say(msg);
}

/* A material that both reflects and transmits doubles the rays at every
 * bounce: up to 2^max_depth - 1 per pixel. The render is the user's choice
 * (docs/scene-format.md, "Deep recursion"); the harness's timeout bounds it
 * in a study. Past about 10^9 rays (minutes to hours) say so up front. */
static void warn_deep(const RtScene *s, const RtCamera *cam)
{
    int branching = 0;
    for (uint32_t i = 0; i < s->nmaterials && !branching; i++) {
        const RtMaterial *m = &s->materials[i];
        branching = (m->ks[0] > 0 || m->ks[1] > 0 || m->ks[2] > 0) && (m->kt[0] > 0 || m->kt[1] > 0 || m->kt[2] > 0);
    }
    if (!branching || s->settings.max_depth < 2)
        return;
    double per_pixel = ldexp(1.0, s->settings.max_depth) - 1.0;
    double worst = per_pixel * (double)cam->width * (double)cam->height;
    if (worst < 1e9)
        return;
    char where[4200];
    if (s->source.line_depth)
        snprintf(where, sizeof where, "%s:%d", s->source.path, s->source.line_depth);
    else
        snprintf(where, sizeof where, "%s", s->source.path);
    fprintf(stderr,
            "%s: warning: max_depth %d with a material that both reflects and transmits: up to %.3g rays per pixel, "
            "%.3g in all; lower max_depth, or bound the run (harness timeout)\n",
            where, s->settings.max_depth, per_pixel, worst);
}

/* The rank a launcher (mpirun, srun) gave this process, known before
 * MPI_Init from its environment; 0 when not launched as one of several. */
static int launcher_rank(void)
{
    static const char *const vars[] = {"OMPI_COMM_WORLD_RANK", "PMIX_RANK", "PMI_RANK", "SLURM_PROCID"};
    for (size_t i = 0; i < sizeof vars / sizeof vars[0]; i++) {
        const char *v = getenv(vars[i]);
        if (v && *v)
            return atoi(v);
    }
    return 0;
}

/* Exit status 1 for an error found before MPI_Init. A rank other than 0
 * (which printed nothing) waits a moment first: mpirun ends the whole job
 * at the first non-zero exit, and if that were a silent rank, rank 0's
 * message could be dropped before mpirun forwarded it. */
static int quiet_rank_exit(int other_rank)
{
    if (other_rank) {
        struct timespec ts = {0, 300 * 1000 * 1000};
        nanosleep(&ts, NULL);
    }
    return 1;
}

/* The backend --backend names, or NULL after saying why not (rank 0). */
static const RtBackend *pick_backend(const Options *o, int other_rank)
{
    const RtBackend *be = rt_backend_find(o->backend);
    if (!be) {
        if (!other_rank)
            fprintf(stderr, "%s: option --backend '%s': unknown backend (serial, openmp, mpi, cuda)\n", cli_prog,
                    o->backend);
        return NULL;
    }
    if (be->unavailable) {
        if (!other_rank)
            fprintf(stderr, "%s: --backend %s: %s\n", cli_prog, be->name, be->unavailable);
        return NULL;
    }
    if (o->builder == RT_BUILDER_GPU && !be->accel_build) {
        if (!other_rank)
            fprintf(stderr, "%s: option --builder 'gpu': the %s backend builds on the CPU (cuda and mpi-cuda "
                            "build on the GPU)\n", cli_prog, be->name);
        return NULL;
    }
    return be;
}

/* Records from which --builder auto builds on the GPU, where the backend
 * can: below, the CPU's build ends before the GPU's context would be ready
 * (docs/performance.md, "The GPU build"). */
#define RT_GPU_BUILD_MIN 65536

/* One render's data, from the scene to the record. */
typedef struct {
    const Options *o;
    const RtBackend *be;
    const RtCollective *col;
    int is_root;
    RtScene scene;
    RtAccel accel;
    RtCamera cam;
    const char *output;
    float *rgbf;
    uint8_t *rgb;
    size_t npix;
    double t_start, parse_ms, build_ms, calib_ms, write_ms;
    const char *builder; /* cpu, gpu */
    RtBuildInfo gpu_build;
    const char *cache;  /* off, built or loaded */
    char cache_key[33];
    uint64_t hash;
    RtRenderOut out;
} Run;

/* The scene and its accelerator from --cache, if every process finds them
 * there (MPI: a rank that missed would wait in the others' broadcast).
 * 1: loaded; 0: parse and build (an unreadable scene is reported there);
 * -1: the cache folder is refused (err says why). */
static int cache_load(Run *r, RtError *err)
{
    RtError why;
    int loaded = rt_cache_load(r->o->cache, r->o->scene, r->o->accel, &r->scene, &r->accel, r->cache_key, &why);
    if (loaded < 0)
        rt_fail(err, "%s: %.1000s", cli_prog, why.msg);
    /* a folder refused on any rank fails every rank, together */
    if (r->col ? r->col->agree(loaded < 0, err) != 0 : loaded < 0) {
        if (loaded == 1) {
            rt_accel_free(&r->accel);
            rt_scene_free(&r->scene);
        }
        return -1;
    }
    if (loaded == 0 && why.msg[0] && r->is_root)
        fprintf(stderr, "%s: warning: ", cli_prog), rt_say(why.msg);
    RtError scratch = {""};
    if (r->col && r->col->agree(!loaded, &scratch) != 0 && loaded) {
        rt_accel_free(&r->accel);
        rt_scene_free(&r->scene);
        loaded = 0;
    }
    return loaded;
}

/* Stores the scene as parsed (before the -r and -d overrides, which the key
 * does not cover) with its accelerator, under the key of the bytes it was
 * parsed from. */
static void cache_store(Run *r, const RtScene *parsed)
{
    RtScene st = r->scene;
    st.settings.width = parsed->settings.width;
    st.settings.height = parsed->settings.height;
    st.settings.max_depth = parsed->settings.max_depth;
    st.source.line_res = parsed->source.line_res;
    RtError cerr;
    if (rt_cache_store(r->o->cache, &st, &r->accel, r->cache_key, &cerr) != 0)
        fprintf(stderr, "%s: warning: ", cli_prog), rt_say(cerr.msg); /* the run goes on */
}

/* The BVH by --builder: on the backend's device where it can build and was
 * asked to, or (auto) for a scene large enough that the GPU gives the
 * earlier image; on the CPU otherwise, and after a GPU build that could not
 * run there (one notice line: too little device memory, say). */
static int build_accel(Run *r, const RtBvhSettings *bvh, RtError *err)
{
    const Options *o = r->o;
    const uint64_t n = (uint64_t)r->scene.nspheres + r->scene.ntriangles;
    if (o->accel == RT_ACCEL_BVH && r->be->accel_build &&
        (o->builder == RT_BUILDER_GPU || (o->builder == RT_BUILDER_AUTO && n >= RT_GPU_BUILD_MIN))) {
        const int rc = r->be->accel_build(&r->scene, bvh, o->device, &r->accel, &r->gpu_build, err);
        if (rc == 0)
            r->builder = "gpu";
        if (rc <= 0)
            return rc;
        if (r->is_root) {
            char note[1200];
            snprintf(note, sizeof note, "%s: note: building the BVH on the CPU: %s", cli_prog, err->msg);
            rt_say(note);
        }
        err->msg[0] = '\0';
    }
    return rt_accel_build_with(&r->scene, o->accel, bvh, &r->accel, err);
}

/* The backend's sink for the geometry while the file is parsed, where its
 * own build would run on the GPU (build_accel): the copy up then overlaps
 * the parse. NULL for ranks that load through their collective. */
static const RtGeomSink *geom_sink(const Run *r)
{
    const Options *o = r->o;
    if (!r->be->geom_sink || !r->be->accel_build || o->accel != RT_ACCEL_BVH || o->builder == RT_BUILDER_CPU ||
        (r->col && r->col->scene_load))
        return NULL;
    return r->be->geom_sink(o->device, o->builder == RT_BUILDER_GPU ? 0 : RT_GPU_BUILD_MIN);
}

/* The scene loaded with the overrides applied, the camera checked, the
 * output checked, the accelerator built and the image buffers allocated. */
static int prepare_with(Run *r, const RtGeomSink *sink, RtError *err)
{
    const Options *o = r->o;
    double t0 = rt_now_ms();
    /* warnings are not progress: --quiet keeps them (README) */
    RtWarnFn warn = r->is_root ? warn_cb : NULL;
    const int loaded = o->cache ? cache_load(r, err) : 0;
    if (loaded < 0)
        return -1;
    r->cache = loaded ? "loaded" : (o->cache ? "built" : "off");
    const int lrc = !loaded && (r->col && r->col->scene_load
                                    ? r->col->scene_load(o->scene, o->mpi_scene, &r->scene, warn, NULL, err) != 0
                                    : rt_scene_load_sink(o->scene, o->build_threads, sink, &r->scene, warn, NULL,
                                                         err) != 0);
    r->parse_ms = rt_now_ms() - t0;
    if (sink) /* (the copies finish for the build, or stop after a failed load) */
        sink->end(sink->ctx, !lrc);
    if (r->col && r->col->same) { /* every rank rendering the same bytes, parsed or loaded */
        uint8_t digest[16] = {0};
        if (!lrc)
            rt_scene_digest(&r->scene, digest);
        if (r->col->agree(lrc, err) != 0 || r->col->same(digest, err) != 0)
            return -1;
    } else if (lrc) {
        return -1;
    }
    const RtScene parsed = r->scene; /* (the settings as read, for the cache) */
    if (o->width) {
        r->scene.settings.width = o->width;
        r->scene.settings.height = o->height;
        r->scene.source.line_res = 0;
    }
    if (o->max_depth >= 0)
        r->scene.settings.max_depth = o->max_depth;
    if (rt_scene_camera(&r->scene, &r->cam, err) != 0)
        return -1;
    if (r->is_root)
        warn_deep(&r->scene, &r->cam);
    r->output = o->output ? o->output : r->scene.settings.output;
    /* only the root writes the image, so only its directory matters */
    if (r->is_root && ((!o->output && rt_scene_output_check(r->output, err) != 0) || rt_output_check(r->output, err) != 0)) {
        if (!o->output && r->scene.source.line_output) { /* the name came from the scene: say where */
            RtError e2 = *err;
            rt_fail(err, "%s:%d: output_image: %s", r->scene.source.path, r->scene.source.line_output, e2.msg);
        }
        return -1;
    }
    t0 = rt_now_ms();
    RtBvhSettings bvh = rt_bvh_settings_default();
    bvh.threads = o->build_threads;
    bvh.huge_pages = o->huge_pages;
    bvh.gpu_split = o->gpu_split;
    r->builder = loaded ? "cache" : "cpu";
    if (!loaded && build_accel(r, &bvh, err) != 0)
        return -1;
    r->build_ms = rt_now_ms() - t0 - r->gpu_build.init_ms; /* (the context is not the build's) */
    /* The tree's invariants (tests/unit run them on every build): with
     * --verify, after the timed build. */
    if ((o->verify || (o->cache && !loaded && r->is_root)) && rt_accel_host(&r->accel, err) != 0)
        return -1;
    if (o->verify && rt_bvh_check(&r->accel, err) != 0)
        return -1;
    if (o->cache && !loaded && r->is_root)
        cache_store(r, &parsed);
    r->npix = (size_t)r->cam.width * (size_t)r->cam.height;
    r->rgbf = malloc(r->npix * 3 * sizeof *r->rgbf);
    r->rgb = malloc(r->npix * 3);
    if (!r->rgbf || !r->rgb)
        return rt_fail(err, "out of memory for a %dx%d image (%.1f MiB)", r->cam.width, r->cam.height,
                       (double)r->npix * 15.0 / (1024.0 * 1024.0));
    return 0;
}

static int prepare(Run *r, RtError *err)
{
    const RtGeomSink *sink = geom_sink(r);
    const int rc = prepare_with(r, sink, err);
    if (sink) /* what the build did not take (a CPU build, a failure) freed */
        sink->end(sink->ctx, 0);
    return rc;
}

/* NaN in every channel, so an unwritten pixel cannot pass as black. */
static void poison(float *rgbf, size_t n)
{
    for (size_t i = 0; i < n; i++)
        rgbf[i] = NAN;
}

/* Whether another warm-up render is due after `done` of them, started at t0.
 * Several processes decide as the root does (a rank rendering once more than
 * another would wait in a collective forever). */
static int warmup_due(const Run *r, int done, double t0)
{
    const Options *o = r->o;
    int due = rt_warmup_due(o->warmup_runs, o->warmup_ms, done, rt_now_ms() - t0);
    if (r->col && o->warmup_runs < 0 && o->warmup_ms >= 0.0) {
        RtError scratch;
        due = r->col->agree(r->is_root && due, &scratch) != 0;
    }
    return due;
}

/* --warmup and --runs for a backend that renders once per call: the last
 * run's image and counters, render_ms the median of the runs' (and
 * render_ms_min the median of theirs). */
static int render_runs(Run *r, const RtRenderJob *job, RtError *err)
{
    const int runs = r->o->runs > 0 ? r->o->runs : 1;
    int warm = 0, rc = 0;
    double *ms = malloc(2 * (size_t)runs * sizeof *ms);
    if (!ms)
        return rt_fail(err, "out of memory for %d timings", runs);
    for (const double t0 = rt_now_ms(); rc == 0 && warmup_due(r, warm, t0); warm++)
        rc = r->be->render(job, &r->out, err);
    for (int i = 0; i < runs && rc == 0; i++) {
        poison(r->rgbf, r->npix * 3);
        if ((rc = r->be->render(job, &r->out, err)) == 0) {
            ms[i] = r->out.render_ms;
            ms[runs + i] = r->out.render_ms_min;
        }
    }
    if (rc == 0 && r->out.is_root) {
        r->out.render_ms = rt_median(ms, runs);
        r->out.render_ms_best = ms[0];
        r->out.render_ms_min = rt_median(ms + runs, runs);
        r->out.runs = runs;
        r->out.warmups = warm;
    }
    free(ms);
    return rc;
}

/* --verify: no pixel left unwritten (NaN), and an image quantised by the
 * backend (on the GPU) equal to the CPU's quantisation of its floats. */
static int verify_image(const Run *r, RtError *err)
{
    const size_t w = (size_t)r->cam.width;
    for (size_t i = 0; i < r->npix * 3; i++) {
        if (isnan(r->rgbf[i]))
            return rt_fail(err, "--verify: pixel (%zu, %zu) was never written by the %s backend", (i / 3) % w,
                           (i / 3) / w, r->be->name);
        if (r->out.quantized && r->rgb[i] != rt_quantize_value(r->rgbf[i]))
            return rt_fail(err, "--verify: pixel (%zu, %zu) channel %zu: the %s backend quantised %.9g to %u, "
                                "the CPU's rule gives %u",
                           (i / 3) % w, (i / 3) / w, i % 3, r->be->name, (double)r->rgbf[i], (unsigned)r->rgb[i],
                           (unsigned)rt_quantize_value(r->rgbf[i]));
    }
    return 0;
}

/* The render itself, into the poisoned float image; with --verify, a pixel
 * left unwritten fails it. */
static int render(Run *r, RtError *err)
{
    const Options *o = r->o;
    RtRenderJob job;
    memset(&job, 0, sizeof job);
    job.scene = &r->scene;
    job.accel = &r->accel;
    job.view = rt_scene_view(&r->scene, &r->accel, &r->cam);
    job.threads = o->threads;
    job.tile_w = o->tile_w;
    job.tile_h = o->tile_h;
    job.schedule = o->schedule;
    job.mpi_schedule = o->mpi_schedule;
    job.block_x = o->block_x;
    job.block_y = o->block_y;
    job.device = o->device;
    job.share_gpu = o->share_gpu;
    job.runs = o->runs;
    job.warmup_runs = o->warmup_runs;
    job.warmup_ms = o->warmup_ms;
    job.want_float = o->verify; /* the unwritten-pixel check needs the float image's NaN poison */
    Progress prog_state = {0, -1};
    if (!o->quiet && isatty(STDERR_FILENO)) {
        prog_state.enabled = 1;
        job.progress = progress_cb;
        job.progress_ctx = &prog_state;
    }
    /* The CPU traversal: its instruction set (--isa chose it already;
     * else the best this CPU runs, chosen before any thread runs) and the
     * copy of the records its leaf tests load. */
    if (!o->isa && rt_cpu_isa_select(NULL, err) != 0)
        return -1;
    void *soa = !r->be->gpu ? rt_cpu_prepare(&job.view) : NULL;
    void *shared = !r->be->gpu && r->col && r->col->share ? r->col->share(&job.view) : NULL;
    /* --start-at: processes started at once but loaded at different speeds
     * render together from here (harness ceiling's copies) */
    if (o->start_at_ms > 0) {
        const struct timespec at = {(time_t)(o->start_at_ms / 1e3),
                                    (long)((o->start_at_ms - floor(o->start_at_ms / 1e3) * 1e3) * 1e6)};
        while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &at, NULL) == EINTR)
            ;
    }
    /* Right before the render, on the same core: the machine's speed now. */
    r->calib_ms = o->calibrate ? rt_calibrate_ms() : 0.0;
    memset(&r->out, 0, sizeof r->out);
    r->out.rgb = r->rgbf;
    r->out.rgb8 = r->rgb;
    r->out.is_root = 1;
    if (!r->be->gpu || job.want_float) /* (a GPU backend leaves the floats alone) */
        poison(r->rgbf, r->npix * 3);
    const int rc = r->be->times_runs ? r->be->render(&job, &r->out, err) : render_runs(r, &job, err);
    if (shared)
        r->col->unshare(shared);
    free(soa);
    if (rc != 0)
        return -1;
    return r->out.is_root && o->verify ? verify_image(r, err) : 0;
}

/* The 8-bit image, its hash, and the file (whole or not at all). */
static int write_image(Run *r, RtError *err)
{
    if (!r->out.quantized)
        rt_image_quantize(r->rgbf, r->rgb, r->npix);
    r->hash = rt_fnv1a64(r->rgb, r->npix * 3);
    double t0 = rt_now_ms();
    if (rt_image_write(r->output, r->rgb, r->cam.width, r->cam.height, err) != 0)
        return -1;
    r->write_ms = rt_now_ms() - t0;
    return 0;
}

/* The record line: its keys, their types and order are declared once in
 * include/raybench/record_schema.h (docs/record.md). Each key gets an index
 * and a setter whose argument has the key's declared type; only keys set are
 * printed, so a key cannot be printed without being declared, and
 * tests/record_schema_test.sh fails when a declared MAIN key is not set. */
enum {
#define REC_INDEX(key, type, unit, col_kind, column, who, doc) REC_##key,
    RT_RECORD_KEYS(REC_INDEX)
#undef REC_INDEX
    REC_COUNT
};

typedef struct RecValue {
    int set;
    union {
        long long i;
        unsigned long long u;
        double d;
        const char *s;
    } v;
} RecValue;

#define REC_CTYPE_INT long long
#define REC_CTYPE_UINT unsigned long long
#define REC_CTYPE_F3 double
#define REC_CTYPE_F4 double
#define REC_CTYPE_HEX64 unsigned long long
#define REC_CTYPE_STR const char *
#define REC_FIELD_INT i
#define REC_FIELD_UINT u
#define REC_FIELD_F3 d
#define REC_FIELD_F4 d
#define REC_FIELD_HEX64 u
#define REC_FIELD_STR s
#define REC_SETTER(key, type, unit, col_kind, column, who, doc)                                        \
    static inline void rec_##key(RecValue *v, REC_CTYPE_##type x)                                   \
    {                                                                                                \
        v[REC_##key].set = 1;                                                                        \
        v[REC_##key].v.REC_FIELD_##type = x;                                                         \
    }
RT_RECORD_KEYS(REC_SETTER)
#undef REC_SETTER

/* raytrace's own keys; tile is written into tile[32]. */
static void record_values(const Run *r, RecValue *v, char *tile)
{
    const Options *o = r->o;
    const RtRenderOut *out = &r->out;
    const uint64_t rays = rt_counters_rays(&out->counters);
    const int tw = o->tile_w ? o->tile_w : r->be->tile;
    snprintf(tile, 32, "%dx%d", tw, o->tile_h ? o->tile_h : tw);
    rec_scene(v, r->scene.source.name);
    rec_width(v, r->cam.width);
    rec_height(v, r->cam.height);
    rec_backend(v, r->be->name);
    rec_accel(v, rt_accel_name(o->accel));
    rec_threads(v, out->threads_used);
    rec_ranks(v, out->ranks_used);
    rec_parse_ms(v, r->parse_ms);
    rec_build_ms(v, r->build_ms);
    rec_render_ms(v, out->render_ms);
    rec_write_ms(v, r->write_ms);
    rec_total_ms(v, rt_now_ms() - r->t_start);
    rec_rays(v, rays);
    rec_primary_rays(v, out->counters.primary_rays);
    rec_shadow_rays(v, out->counters.shadow_rays);
    rec_secondary_rays(v, out->counters.secondary_rays);
    rec_node_visits(v, out->counters.node_visits);
    rec_prim_tests(v, out->counters.prim_tests);
    rec_mrays_per_s(v, out->render_ms > 0.0 ? (double)rays / (out->render_ms * 1000.0) : 0.0);
    rec_image_fnv1a(v, r->hash);
    rec_tile(v, tile);
    rec_cores(v, out->cores[0] ? out->cores : "unknown");
    rec_prims(v, r->accel.nprims - r->accel.nsplit);
    rec_bvh_nodes(v, r->accel.nnodes);
    rec_runs(v, out->runs);
    rec_warmups(v, out->warmups);
    rec_render_ms_best(v, out->render_ms_best);
    rec_build_threads(v, r->accel.build_threads);
    rec_huge_pages(v, r->accel.huge_pages ? "on" : "off");
    rec_sah_cost(v, r->accel.sah_cost);
    rec_builder(v, r->builder ? r->builder : "cpu");
    if (r->gpu_build.kernel_ms > 0.0) {
        rec_gpu_build_ms(v, r->gpu_build.kernel_ms);
        rec_build_init_ms(v, r->gpu_build.init_ms);
        rec_gpu_split(v, r->gpu_build.split_pct);
        if (r->gpu_build.outsized >= 0.0)
            rec_gpu_outsized(v, r->gpu_build.outsized);
        rec_geom_up(v, r->gpu_build.geom_streamed ? "parse" : "build");
        rec_geom_up_ms(v, r->gpu_build.upload_ms);
    }
    if (r->accel.nsplit)
        rec_bvh_pieces(v, r->accel.nsplit);
    rec_cache(v, r->cache);
    rec_commit(v, RT_COMMIT);
    if (r->col) /* several processes: the fastest rank's time shows the imbalance */
        rec_render_ms_min(v, out->render_ms_min);
    if (!r->be->gpu) /* the CPU traversal's instruction set */
        rec_isa(v, rt_cpu_isa_name());
    if (o->calibrate)
        rec_calib_ms(v, r->calib_ms);
}

/* The keys set, in declaration order: the LAST ones (after the backend's
 * keys) or all others. */
static void print_record_keys(const RecValue *v, int last)
{
#define REC_NAME(key, type, unit, col_kind, column, who, doc) #key,
#define REC_TYPE(key, type, unit, col_kind, column, who, doc) RT_REC_##type,
#define REC_WHO(key, type, unit, col_kind, column, who, doc) RT_REC_##who,
    static const char *const name[REC_COUNT] = {RT_RECORD_KEYS(REC_NAME)};
    static const RtRecType type[REC_COUNT] = {RT_RECORD_KEYS(REC_TYPE)};
    static const RtRecWho who[REC_COUNT] = {RT_RECORD_KEYS(REC_WHO)};
#undef REC_NAME
#undef REC_TYPE
#undef REC_WHO
    for (int k = 0; k < REC_COUNT; k++) {
        if (!v[k].set || (who[k] == RT_REC_LAST) != last)
            continue;
        printf(" %s=", name[k]);
        switch (type[k]) {
        case RT_REC_INT: printf("%lld", v[k].v.i); break;
        case RT_REC_UINT: printf("%llu", v[k].v.u); break;
        case RT_REC_F3: printf("%.3f", v[k].v.d); break;
        case RT_REC_F4: printf("%.4f", v[k].v.d); break;
        case RT_REC_HEX64: printf("%016llx", v[k].v.u); break;
        case RT_REC_STR: fputs(v[k].v.s, stdout); break;
        }
    }
}

/* The record line (docs/record.md): raytrace's keys, the backend's, then
 * the LAST ones. */
static void print_record(const Run *r)
{
    RecValue v[REC_COUNT];
    char tile[32];
    memset(v, 0, sizeof v);
    record_values(r, v, tile);
    fputs("record:", stdout);
    print_record_keys(v, 0);
    fputs(r->out.extra, stdout);
    print_record_keys(v, 1);
    putchar('\n');
    fflush(stdout);
}

/* The data flow: options, backend, scene and accelerator (every rank agrees
 * on failure first), render, image, record. */
int main(int argc, char **argv)
{
    Options o;
    int other_rank = launcher_rank() != 0;
    double t_start = rt_now_ms();
#ifdef __GLIBC__
    /* The BVH build frees and allocates each level's reference arrays; from
     * the heap they reuse pages already mapped, where glibc's default maps
     * fresh ones above a few MiB and faults every page in again (the
     * measurement: docs/performance.md, "Large scenes"). */
    mallopt(M_MMAP_THRESHOLD, 32 << 20);
    mallopt(M_TRIM_THRESHOLD, 1 << 30);
#endif
    if (cli_parse(argc, argv, &o, other_rank) != 0)
        return quiet_rank_exit(other_rank);
    const RtBackend *be = pick_backend(&o, other_rank);
    if (!be)
        return quiet_rank_exit(other_rank);
    RtError err;
    err.msg[0] = '\0';
    /* (a signal ignored at start, as SIGINT in a shell's background job,
     * stays ignored) */
    if (signal(SIGINT, on_stop_signal) == SIG_IGN)
        signal(SIGINT, SIG_IGN);
    if (signal(SIGTERM, on_stop_signal) == SIG_IGN)
        signal(SIGTERM, SIG_IGN);
    if (be->init && be->init(&argc, &argv, &err) != 0) {
        fprintf(stderr, "%s: ", cli_prog), rt_say(err.msg);
        return 1;
    }
    if (be->prewarm) /* (the GPU's context while the scene loads) */
        be->prewarm(o.device);
    Run r;
    memset(&r, 0, sizeof r);
    r.o = &o;
    r.be = be;
    r.t_start = t_start;
    /* Several processes (MPI): only the root prints, and every failure
     * before rendering is agreed on by all ranks (col->agree) instead of
     * ending one rank while the others wait for it in a collective call. */
    r.col = be->collective;
    r.is_root = r.col ? r.col->is_root() : 1;
    int failed = prepare(&r, &err) != 0;
    if (r.col && r.col->agree(failed, &err) != 0)
        failed = 1;
    int rc = 0;
    if (failed || render(&r, &err) != 0 || (r.out.is_root && write_image(&r, &err) != 0)) {
        if (r.is_root)
            rt_say(err.msg);
        rc = 1;
    } else if (r.out.is_root) {
        print_record(&r);
    }
    free(r.rgbf);
    free(r.rgb);
    rt_accel_free(&r.accel);
    rt_scene_free(&r.scene);
    if (be->finalize)
        be->finalize();
    return rc;
}
