/* record_schema.h - the keys of raytrace's `record:` line, declared once.
 *
 * renderer/main.c prints the record by walking this list, harness/csv.c takes
 * its record columns from it, and tests/record_schema_test.sh checks
 * docs/record.md's table and raytrace's actual line against it. Plain C11
 * with no includes: the renderer and the harness share it, nothing else.
 *
 * RT_RECORD_KEYS(X) calls X(key, type, unit, col_kind, column, who, doc) once
 * per key:
 *   key       the name before '=' (an identifier)
 *   type      INT, UINT: decimal integers; F3, F4: decimals with 3 or 4 digits
 *             after the point; HEX64: 16 hex digits; STR: text without spaces
 *   unit      "ms", "px", ... or ""
 *   col_kind  OWN: CSV column `column` in the record part, in this list's
 *             order; AT: column `column` elsewhere in the CSV; EXTRA: the
 *             `extra` column (k=v;k=v)
 *   who       MAIN: raytrace prints it on every record; MAIN_IF: raytrace,
 *             where it applies; BACKEND: a backend adds it, after raytrace's
 *             own keys; LAST: raytrace, where it applies, after the backend's
 *   doc       its line in docs/record.md's table
 *
 * The order is raytrace's print order for its own keys and the CSV's column
 * order for OWN keys; existing CSVs fix the latter, which is why a few
 * backend keys sit among raytrace's own. Keys are added, never renamed; a new
 * OWN key is a new CSV column (a new header line). Backend keys that go to
 * `extra` are not listed: docs/cpu-backends.md and docs/gpu.md have them. */
#ifndef RAYBENCH_RECORD_SCHEMA_H
#define RAYBENCH_RECORD_SCHEMA_H

typedef enum { RT_REC_INT, RT_REC_UINT, RT_REC_F3, RT_REC_F4, RT_REC_HEX64, RT_REC_STR } RtRecType;
typedef enum { RT_REC_MAIN, RT_REC_MAIN_IF, RT_REC_BACKEND, RT_REC_LAST } RtRecWho;

#define RT_RECORD_KEYS(X) \
    X(scene, STR, "", OWN, "rec_scene", MAIN, "scene file name without directory and extension") \
    X(width, INT, "px", OWN, "width", MAIN, "image width") \
    X(height, INT, "px", OWN, "height", MAIN, "image height") \
    X(backend, STR, "", OWN, "rec_backend", MAIN, "serial, openmp, mpi, cuda or mpi-cuda") \
    X(accel, STR, "", OWN, "rec_accel", MAIN, "none (brute force) or bvh") \
    X(threads, INT, "", OWN, "rec_threads", MAIN, "worker threads (per rank for mpi); cuda: GPU threads launched, mpi-cuda: 1") \
    X(ranks, INT, "", OWN, "rec_ranks", MAIN, "MPI ranks (1 otherwise)") \
    X(parse_ms, F3, "ms", OWN, "parse_ms", MAIN, "reading and parsing the scene file") \
    X(build_ms, F3, "ms", OWN, "build_ms", MAIN, \
      "building the primitive records and the BVH, including its invariant check") \
    X(render_ms, F3, "ms", OWN, "render_ms", MAIN, \
      "the pixel work only, until the last pixel is in the image (openmp, mpi: docs/cpu-backends.md, " \
      "\"Strips and backups\"; mpi across nodes and with block rows: max over ranks, as the report timed it); " \
      "for cuda and mpi-cuda, " \
      "a frame until its 8-bit image is in (rank 0's) host memory, frames pipelined (docs/gpu.md)") \
    X(write_ms, F3, "ms", OWN, "write_ms", MAIN, "quantizing and writing the image file") \
    X(total_ms, F3, "ms", OWN, "total_ms", MAIN, "the whole command, start to record") \
    X(rays, UINT, "", OWN, "rays", MAIN, "primary + shadow + secondary rays") \
    X(primary_rays, UINT, "", OWN, "primary_rays", MAIN, \
      "camera rays; exact and deterministic, as every ray count") \
    X(shadow_rays, UINT, "", OWN, "shadow_rays", MAIN, "rays towards the lights") \
    X(secondary_rays, UINT, "", OWN, "secondary_rays", MAIN, "reflected and refracted rays") \
    X(node_visits, UINT, "", OWN, "node_visits", MAIN, "BVH nodes processed by all rays (0 for none)") \
    X(prim_tests, UINT, "", OWN, "prim_tests", MAIN, "ray-primitive intersection tests") \
    X(mrays_per_s, F3, "Mrays/s", OWN, "mrays_per_s", MAIN, "rays / render_ms / 1000") \
    X(image_fnv1a, HEX64, "", OWN, "image_fnv1a", MAIN, \
      "FNV-1a 64-bit hash of the 8-bit RGB pixels, row-major from the top, 16 hex digits") \
    X(tile, STR, "px", OWN, "rec_tile", MAIN, "tile size (WxH)") \
    X(cores, STR, "", AT, "cores_actual", MAIN, \
      "the CPUs the worker threads ran on, e.g. `0,1` (`unknown` where not known)") \
    X(prims, UINT, "", EXTRA, "extra", MAIN, "primitives in the scene (spheres + triangles)") \
    X(bvh_nodes, UINT, "", EXTRA, "extra", MAIN, "BVH nodes (0 for none)") \
    X(runs, INT, "", EXTRA, "extra", MAIN, "timed renders (`--runs`); `render_ms` is their median") \
    X(warmups, INT, "", EXTRA, "extra", MAIN, "untimed renders before them (`--warmup`)") \
    X(render_ms_best, F3, "ms", EXTRA, "extra", MAIN, "the fastest timed render") \
    X(build_threads, INT, "", EXTRA, "extra", MAIN, \
      "threads the BVH build ran on (`--build-threads`; the same tree on any number)") \
    X(huge_pages, STR, "", EXTRA, "extra", MAIN, \
      "`on` or `off`: whether the build asked for 2 MiB pages for its large arrays (`--huge-pages`, " \
      "by default on from 8 build threads; `off` when nothing was built; the same tree either way)") \
    X(sah_cost, F4, "", EXTRA, "extra", MAIN, \
      "the tree's SAH cost (traversal and intersection cost 1, relative to the root's area; 0 for none): " \
      "its quality beside `build_ms`") \
    X(builder, STR, "", EXTRA, "extra", MAIN, \
      "`cpu` or `gpu`: who built the BVH (`--builder`; `cpu` also for `none`), `cache`: none, the tree " \
      "came from `--cache DIR`") \
    X(gpu_build_ms, F3, "ms", EXTRA, "extra", MAIN_IF, \
      "`builder=gpu` only: the build's kernels on the GPU, first to last; `build_ms` adds its device " \
      "memory and copying the scene's geometry up (the tree stays on the GPU; docs/performance.md, " \
      "\"The GPU build\")") \
    X(build_init_ms, F3, "ms", EXTRA, "extra", MAIN_IF, \
      "`builder=gpu` only: how long the build waited for the GPU's context, not in `build_ms`") \
    X(gpu_split, INT, "", EXTRA, "extra", MAIN_IF, \
      "`builder=gpu` only: the pieces of large triangles the build might add, in percent of the " \
      "triangles (`--gpu-split`; `auto`, the default, takes 100 where `gpu_outsized` is 0.5 or more, " \
      "else 0; docs/performance.md, \"The GPU build\")") \
    X(gpu_outsized, F3, "", EXTRA, "extra", MAIN_IF, \
      "`builder=gpu` with `--gpu-split auto` from 65,536 triangles: the share of the triangles' excess " \
      "box area held by boxes over 16 times the median box, in 16,384 of them evenly spaced") \
    X(geom_up, STR, "", EXTRA, "extra", MAIN_IF, \
      "`builder=gpu` only: where the scene's vertices and triangles were copied to the GPU: `parse`, " \
      "range by range while the file was parsed on several threads, or `build`, by the build after " \
      "the parse (docs/performance.md, \"The GPU build\")") \
    X(geom_up_ms, F3, "ms", EXTRA, "extra", MAIN_IF, \
      "`builder=gpu` only: what copying the geometry up cost the build, in `build_ms`: its own copy, " \
      "or with `geom_up=parse` its wait for the parse's last copies") \
    X(bvh_pieces, UINT, "", EXTRA, "extra", MAIN_IF, \
      "where the tree holds records more than once: the copies, from the CPU build's spatial splits or " \
      "the GPU build's pieces of large triangles (`--gpu-split`); `prims` counts each record once") \
    X(cache, STR, "", EXTRA, "extra", MAIN, \
      "`off`, `built` (parsed, built and stored) or `loaded` (mapped from `--cache DIR`; `build_ms` is then 0)") \
    X(commit, STR, "", EXTRA, "extra", MAIN, \
      "the commit `raytrace` was built from, taken at build time (Meson's `vcs_tag`, so an out-of-tree " \
      "build knows it too): `git rev-parse --short HEAD` of the source tree, with `-dirty` when a tracked " \
      "file outside `results/` and `plots/` differed from it at the build; `unknown` for a source tree " \
      "that is no git checkout (a tarball). `raytrace -V` prints it on its `commit:` line, where the " \
      "harness takes its `git_commit` column from") \
    X(schedule, STR, "", OWN, "rec_schedule", BACKEND, \
      "openmp, mpi: `tiles` or `pixels` (`--schedule`; docs/cpu-backends.md)") \
    X(mpi_schedule, STR, "", OWN, "rec_mpi_schedule", BACKEND, \
      "mpi: `dynamic` or `rows` (`--mpi-schedule`; docs/cpu-backends.md)") \
    X(render_ms_min, F3, "ms", OWN, "render_ms_min", MAIN_IF, \
      "MPI only: the fastest rank's time (its median over the runs), which shows imbalance; " \
      "mpi-cuda: the earliest rank's end of the frame") \
    X(isa, STR, "", EXTRA, "extra", MAIN_IF, \
      "CPU backends only: the instruction set their traversal ran with, `c`, `sse2`, `avx2` or " \
      "`avx512` (`--isa`; docs/cpu-backends.md, \"Traversal and dispatch\")") \
    X(block, STR, "", OWN, "rec_block", BACKEND, \
      "cuda, mpi-cuda: the thread block shape BXxBY (`--block`; docs/gpu.md)") \
    X(upload_ms, F3, "ms", OWN, "upload_ms", BACKEND, "cuda: copying the scene's arrays to the GPU") \
    X(download_ms, F3, "ms", OWN, "download_ms", BACKEND, \
      "cuda, mpi-cuda: copying a frame's image (8-bit; the floats too with `--verify`) back from the GPU, " \
      "median over the frames (mpi-cuda: the slowest rank's)") \
    X(kernel_ms, F4, "ms", EXTRA, "extra", BACKEND, \
      "cuda, mpi-cuda: the render kernel alone, median over the frames (mpi-cuda: the slowest rank's); " \
      "`render_ms` is the time until the image is in host memory (docs/gpu.md, \"What render_ms means\")") \
    X(wall_ms, F3, "ms", OWN, "rec_wall_ms", BACKEND, "cuda: the whole backend call") \
    X(gpu, STR, "", OWN, "rec_gpu", BACKEND, \
      "cuda, mpi-cuda (rank 0's): the GPU's name, other characters than letters, digits, `-` and `.` as `_`") \
    X(calib_ms, F3, "ms", EXTRA, "extra", LAST, \
      "with `--calibrate` only, and last: the time of a fixed CPU workload run on the same core just before " \
      "rendering (the machine's speed at that moment; `harness compare --metric render_ms/calib`)")

#endif
