/* options.c - raytrace's command line: getopt_long over the options of
 * --help, each value checked as it is read, into an Options (options.h). */
#include <errno.h>
#include <getopt.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "config.h"
#include "options.h"
#include "rt.h"
#include "rt_commit.h" /* RT_COMMIT: renderer/meson.build */
#include "backends/backends.h"

const char cli_prog[] = "raytrace";

/* The CPU backends' default tiles in this build: "serial 32x32, openmp ...". */
static void tile_defaults(char *buf, size_t size)
{
    const RtBackend *const *b = rt_backend_list();
    size_t n = 0;
    buf[0] = '\0';
    for (int i = 0; b[i] && n < size; i++) {
        if (b[i]->gpu || b[i]->unavailable)
            continue;
        const int t = b[i]->tile;
        n += (size_t)snprintf(buf + n, size - n, "%s%s %dx%d", n ? ", " : "", b[i]->name, t, t);
    }
}

static void usage(FILE *fp)
{
    char tiles[256];
    tile_defaults(tiles, sizeof tiles);
    fprintf(fp,
            "Usage: %s [OPTIONS] SCENE|MODEL\n"
            "Renders a scene file (docs/scene-format.md) with Whitted ray tracing; a model file (OBJ,\n"
            "PLY, STL, glTF, ...) alone with a camera that frames it.\n\n"
            "  -o, --output FILE        image to write (.png, .bmp, .ppm); default: the scene's output_image\n"
            "  -b, --backend NAME       serial (default), openmp, mpi, cuda, mpi-cuda (a GPU per rank)\n"
            "  -a, --accel NAME         bvh (default) or none (every ray against every primitive)\n"
            "  -r, --resolution WxH     override film_resolution\n"
            "  -d, --max-depth N        override max_depth (0..%d)\n"
            "  -t, --threads N          worker threads (openmp; per rank with mpi)\n"
            "      --build-threads N    threads that parse the scene and build the BVH (default: every CPU\n"
            "                           the process may use; the same scene and tree on any number)\n"
            "      --huge-pages on|off|auto  the BVH build's large arrays in 2 MiB pages; auto (default):\n"
            "                           on with 8 or more build threads (the same tree either way)\n"
            "      --builder B          who builds the BVH: cpu, gpu (cuda, mpi-cuda) or auto (default: the\n"
            "                           GPU for the GPU backends from 65536 primitives, else the CPU)\n"
            "      --gpu-split PCT|auto the GPU build cuts large triangles into pieces, up to PCT%% more\n"
            "                           references (0..100); auto (default): 100 for scenes of very unequal\n"
            "                           triangles, else 0 (the record's gpu_split; docs/performance.md)\n"
            "      --tile WxH           tile size in pixels (default %s)\n"
            "      --schedule S         openmp: tiles (dynamic, default) or pixels (the report's collapse(2) static)\n"
            "      --mpi-schedule S     mpi: dynamic (default) or rows (the report's block rows + Gatherv)\n"
            "      --mpi-scene HOW      mpi: every (each rank parses, as the report) or bcast (rank 0 parses\n"
            "                           and broadcasts the arrays); default in docs/cpu-backends.md\n"
            "      --block BXxBY        cuda: thread block shape (default chosen by measurement)\n"
            "      --device N           cuda: device index (default 0); mpi-cuda: the first rank's on each\n"
            "                           node, the next rank's N+1, ...\n"
            "      --share-gpu          mpi-cuda: let a node's ranks share its GPUs when it has fewer GPUs\n"
            "                           than ranks (default: that is an error)\n"
            "      --runs N             timed renders, render_ms their median (default 1; cuda 21 launches,\n"
            "                           fewer past 4 s of kernel time)\n"
            "      --warmup N|Tms       untimed renders first: N of them, or as many as take T ms, at least\n"
            "                           one (default 0; cuda 50ms)\n"
            "      --cache DIR          keep the parsed scene and its BVH in DIR (a folder of your own), keyed\n"
            "                           by the files read, the options and this program; a later run loads it\n"
            "      --max-model-triangles N  refuse a model that expands to more than N triangles (instanced\n"
            "                           nodes counted; default 50000000)\n"
            "      --verify             check the BVH's invariants, poison the image first and fail unless\n"
            "                           every pixel is written\n"
            "      --calibrate          time a fixed CPU workload before rendering (record key calib_ms)\n"
            "      --start-at MS        render no earlier than MS on CLOCK_MONOTONIC (harness ceiling starts its\n"
            "                           copies' renders together with it); 0: at once (default)\n"
            "      --isa NAME           CPU traversal: c, sse2, avx2 or avx512 (default: the best this CPU runs;\n"
            "                           the same images and counters with any; record key isa)\n"
            "  -q, --quiet              no progress output (warnings and errors still go to stderr)\n"
            "  -h, --help               this text\n"
            "  -V, --version            version and the backends in this build\n\n"
            "Prints one line 'record: key=value ...' on stdout (see docs/record.md).\n",
            cli_prog, RT_MAX_DEPTH, tiles);
}

/* --warmup: a count, or a time in milliseconds with the suffix ms. */
static int parse_warmup(const char *s, int *runs, double *ms)
{
    char buf[32];
    const size_t n = strlen(s);
    if (n > 2 && n < sizeof buf && strcmp(s + n - 2, "ms") == 0) {
        int v;
        memcpy(buf, s, n - 2);
        buf[n - 2] = '\0';
        if (rt_parse_int(buf, 0, 600000, &v) != 0)
            return -1;
        *ms = v;
        *runs = -1;
        return 0;
    }
    *ms = -1.0;
    return rt_parse_int(s, 0, 1000, runs);
}

static int opt_error(const char *opt, const char *val, const char *why)
{
    fprintf(stderr, "%s: option %s '%s': %s\n", cli_prog, opt, val, why);
    return -1;
}

enum { OPT_TILE = 256, OPT_SCHEDULE, OPT_MPI_SCHEDULE, OPT_BLOCK, OPT_DEVICE, OPT_VERIFY, OPT_MPI_SCENE, OPT_CALIBRATE,
       OPT_RUNS, OPT_WARMUP, OPT_BUILD_THREADS, OPT_CACHE, OPT_ISA, OPT_SHARE_GPU, OPT_HUGE_PAGES,
       OPT_MAX_MODEL_TRIS, OPT_BUILDER, OPT_GPU_SPLIT, OPT_START_AT };

static void print_version(void)
{
    printf("raytrace (raybench) %s\nbackends:", RT_VERSION);
    const RtBackend *const *b = rt_backend_list();
    for (int i = 0; b[i]; i++)
        printf(" %s%s", b[i]->name, b[i]->unavailable ? "(not built)" : "");
    printf("\nbuild: %s\ncommit: %s\n", RT_BUILD_FLAGS, RT_COMMIT);
}

/* --cache, --max-model-triangles, --build-threads, --builder, --gpu-split, --huge-pages, --runs,
 * --warmup and --start-at. */
static int parse_load_timing(int c, const char *arg, Options *o)
{
    switch (c) {
    case OPT_BUILDER:
        if (strcmp(arg, "cpu") == 0) o->builder = RT_BUILDER_CPU;
        else if (strcmp(arg, "gpu") == 0) o->builder = RT_BUILDER_GPU;
        else if (strcmp(arg, "auto") == 0) o->builder = RT_BUILDER_AUTO;
        else return opt_error("--builder", arg, "expected cpu, gpu or auto");
        return 0;
    case OPT_GPU_SPLIT:
        if (strcmp(arg, "auto") == 0)
            o->gpu_split = -1;
        else if (rt_parse_int(arg, 0, 100, &o->gpu_split) != 0)
            return opt_error("--gpu-split", arg, "expected auto or a percentage from 0 to 100");
        return 0;
    case OPT_HUGE_PAGES:
        if (strcmp(arg, "on") != 0 && strcmp(arg, "off") != 0 && strcmp(arg, "auto") != 0)
            return opt_error("--huge-pages", arg, "expected on, off or auto");
        o->huge_pages = strcmp(arg, "on") == 0 ? 1 : strcmp(arg, "off") == 0 ? 0 : -1;
        return 0;
    case OPT_CACHE:
        if (!*arg)
            return opt_error("--cache", arg, "expected a directory");
        if (rt_cache_unavailable())
            return opt_error("--cache", arg, rt_cache_unavailable());
        o->cache = arg;
        return 0;
    case OPT_MAX_MODEL_TRIS: {
        char *end;
        errno = 0;
        const unsigned long long n = strtoull(arg, &end, 10);
        if (errno || end == arg || *end || arg[0] == '-' || rt_model_set_max_triangles((uint64_t)n) != 0)
            return opt_error("--max-model-triangles", arg, "expected a positive integer");
        return 0;
    }
    case OPT_BUILD_THREADS:
        if (rt_parse_int(arg, 1, 4096, &o->build_threads) != 0)
            return opt_error("--build-threads", arg, "expected an integer from 1 to 4096");
        return 0;
    case OPT_RUNS:
        if (rt_parse_int(arg, 1, 1000, &o->runs) != 0)
            return opt_error("--runs", arg, "expected an integer from 1 to 1000");
        return 0;
    case OPT_START_AT: {
        /* at most 10 minutes ahead: a bad value never hangs a run for long */
        char *end;
        errno = 0;
        const double t = strtod(arg, &end);
        if (errno || end == arg || *end || !(t >= 0) || t > rt_now_ms() + 600000.0)
            return opt_error("--start-at", arg, "expected 0 or a CLOCK_MONOTONIC time in ms, at most 10 minutes ahead");
        o->start_at_ms = t;
        return 0;
    }
    default:
        if (parse_warmup(arg, &o->warmup_runs, &o->warmup_ms) != 0)
            return opt_error("--warmup", arg, "expected a count from 0 to 1000, or a time such as 50ms (at most 600000ms)");
        return 0;
    }
}

/* --schedule, --mpi-schedule, --mpi-scene, --block and --device: how a
 * backend splits the image or which GPU it takes. */
static int parse_schedule(int c, const char *arg, Options *o)
{
    switch (c) {
    case OPT_SCHEDULE:
        if (strcmp(arg, "tiles") == 0) o->schedule = RT_SCHED_TILES;
        else if (strcmp(arg, "pixels") == 0) o->schedule = RT_SCHED_PIXELS;
        else return opt_error("--schedule", arg, "expected tiles or pixels");
        return 0;
    case OPT_MPI_SCHEDULE:
        if (strcmp(arg, "dynamic") == 0) o->mpi_schedule = RT_MPI_DYNAMIC;
        else if (strcmp(arg, "rows") == 0) o->mpi_schedule = RT_MPI_ROWS;
        else return opt_error("--mpi-schedule", arg, "expected dynamic or rows");
        return 0;
    case OPT_MPI_SCENE:
        if (strcmp(arg, "every") != 0 && strcmp(arg, "bcast") != 0)
            return opt_error("--mpi-scene", arg, "expected every or bcast");
        o->mpi_scene = arg;
        return 0;
    case OPT_BLOCK:
        if (rt_parse_wxh(arg, 1024, &o->block_x, &o->block_y) != 0 || o->block_x * o->block_y > 1024)
            return opt_error("--block", arg, "expected BXxBY with at most 1024 threads");
        return 0;
    default:
        if (rt_parse_int(arg, 0, 1023, &o->device) != 0)
            return opt_error("--device", arg, "expected a device index");
        return 0;
    }
}

/* --isa: a name in the CPU traversal's table that this CPU runs. */
static int parse_isa(const char *arg, Options *o)
{
    RtError e;
    if (rt_cpu_isa_select(arg, &e) != 0) {
        fprintf(stderr, "%s: ", cli_prog), rt_say(e.msg);
        return -1;
    }
    o->isa = arg;
    return 0;
}

static int parse_options(int argc, char **argv, Options *o)
{
    static const struct option longopts[] = {
        {"output", required_argument, NULL, 'o'},     {"backend", required_argument, NULL, 'b'},
        {"accel", required_argument, NULL, 'a'},      {"resolution", required_argument, NULL, 'r'},
        {"max-depth", required_argument, NULL, 'd'},  {"threads", required_argument, NULL, 't'},
        {"tile", required_argument, NULL, OPT_TILE},  {"schedule", required_argument, NULL, OPT_SCHEDULE},
        {"mpi-schedule", required_argument, NULL, OPT_MPI_SCHEDULE},
        {"mpi-scene", required_argument, NULL, OPT_MPI_SCENE},
        {"block", required_argument, NULL, OPT_BLOCK}, {"device", required_argument, NULL, OPT_DEVICE},
        {"runs", required_argument, NULL, OPT_RUNS},  {"warmup", required_argument, NULL, OPT_WARMUP},
        {"start-at", required_argument, NULL, OPT_START_AT},
        {"build-threads", required_argument, NULL, OPT_BUILD_THREADS}, {"cache", required_argument, NULL, OPT_CACHE},
        {"max-model-triangles", required_argument, NULL, OPT_MAX_MODEL_TRIS},
        {"huge-pages", required_argument, NULL, OPT_HUGE_PAGES}, {"builder", required_argument, NULL, OPT_BUILDER},
        {"gpu-split", required_argument, NULL, OPT_GPU_SPLIT},
        {"verify", no_argument, NULL, OPT_VERIFY},    {"calibrate", no_argument, NULL, OPT_CALIBRATE},    {"quiet", no_argument, NULL, 'q'},
        {"isa", required_argument, NULL, OPT_ISA},    {"share-gpu", no_argument, NULL, OPT_SHARE_GPU},
        {"help", no_argument, NULL, 'h'},             {"version", no_argument, NULL, 'V'},
        {NULL, 0, NULL, 0}};
    memset(o, 0, sizeof *o);
    o->backend = "serial";
    o->accel = RT_ACCEL_BVH;
    o->max_depth = -1;
    o->warmup_runs = -1;
    o->warmup_ms = -1.0;
    o->huge_pages = -1;
    o->gpu_split = -1;
    int c;
    opterr = 0;
    while ((c = getopt_long(argc, argv, ":o:b:a:r:d:t:qhV", longopts, NULL)) != -1) {
        switch (c) {
        case 'o': o->output = optarg; break;
        case 'b': o->backend = optarg; break;
        case 'a':
            if (rt_accel_parse(optarg, &o->accel) != 0)
                return opt_error("--accel", optarg, "expected none or bvh");
            break;
        case 'r':
            if (rt_parse_wxh(optarg, RT_MAX_SIDE, &o->width, &o->height) != 0)
                return opt_error("--resolution", optarg, "expected WxH with 1 <= W,H <= 32768");
            if ((unsigned long long)o->width * (unsigned long long)o->height > RT_MAX_PIXELS)
                return opt_error("--resolution", optarg, "more than 2^28 pixels");
            break;
        case 'd':
            if (rt_parse_int(optarg, 0, RT_MAX_DEPTH, &o->max_depth) != 0)
                return opt_error("--max-depth", optarg, "expected an integer from 0 to 32");
            break;
        case 't':
            if (rt_parse_int(optarg, 1, 4096, &o->threads) != 0)
                return opt_error("--threads", optarg, "expected an integer from 1 to 4096");
            break;
        case OPT_TILE:
            if (rt_parse_wxh(optarg, 4096, &o->tile_w, &o->tile_h) != 0)
                return opt_error("--tile", optarg, "expected WxH with 1 <= W,H <= 4096");
            break;
        case OPT_SCHEDULE: case OPT_MPI_SCHEDULE: case OPT_MPI_SCENE: case OPT_BLOCK: case OPT_DEVICE:
            if (parse_schedule(c, optarg, o) != 0)
                return -1;
            break;
        case OPT_CACHE: case OPT_BUILD_THREADS: case OPT_RUNS: case OPT_WARMUP: case OPT_HUGE_PAGES:
        case OPT_MAX_MODEL_TRIS: case OPT_BUILDER: case OPT_GPU_SPLIT: case OPT_START_AT:
            if (parse_load_timing(c, optarg, o) != 0)
                return -1;
            break;
        case OPT_VERIFY: o->verify = 1; break;
        case OPT_SHARE_GPU: o->share_gpu = 1; break;
        case OPT_CALIBRATE: o->calibrate = 1; break;
        case OPT_ISA:
            if (parse_isa(optarg, o) != 0)
                return -1;
            break;
        case 'q': o->quiet = 1; break;
        case 'h': usage(stdout); exit(0);
        case 'V': print_version(); exit(0);
        case ':':
            fprintf(stderr, "%s: option %s needs a value\n", cli_prog, argv[optind - 1]);
            return -1;
        default:
            fprintf(stderr, "%s: unknown option '%s' (see --help)\n", cli_prog, argv[optind - 1]);
            return -1;
        }
    }
    if (optind != argc - 1) {
        fprintf(stderr, "%s: expected exactly one scene file (see --help)\n", cli_prog);
        return -1;
    }
    o->scene = argv[optind];
    return 0;
}

/* Parses the options on every rank; under mpirun only rank 0 may say what
 * is wrong with them, or print --help and --version (stdout and stderr are
 * silenced meanwhile on the others). */
int cli_parse(int argc, char **argv, Options *o, int other_rank)
{
    int saved_stderr = -1, saved_stdout = -1;
    if (other_rank) {
        fflush(stdout);
        fflush(stderr);
        saved_stdout = dup(STDOUT_FILENO);
        saved_stderr = dup(STDERR_FILENO);
        FILE *null = fopen("/dev/null", "w");
        if (null) {
            dup2(fileno(null), STDOUT_FILENO);
            dup2(fileno(null), STDERR_FILENO);
            fclose(null);
        }
    }
    int parsed = parse_options(argc, argv, o);
    if (other_rank) {
        fflush(stdout);
        fflush(stderr);
        dup2(saved_stdout, STDOUT_FILENO);
        dup2(saved_stderr, STDERR_FILENO);
        close(saved_stdout);
        close(saved_stderr);
    }
    return parsed;
}
