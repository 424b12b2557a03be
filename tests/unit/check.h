/* check.h - a minimal test harness: CHECK counts failures and keeps going, so
 * one run reports every broken property; main returns non-zero on any. */
#ifndef RT_CHECK_H
#define RT_CHECK_H

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static int check_failures = 0;
static int check_count = 0;

#define CHECK(cond, ...)                                                                                     \
    do {                                                                                                     \
        check_count++;                                                                                       \
        if (!(cond)) {                                                                                       \
            check_failures++;                                                                                \
            fprintf(stderr, "%s:%d: CHECK(%s) failed: ", __FILE__, __LINE__, #cond);                         \
            fprintf(stderr, __VA_ARGS__);                                                                    \
            fputc('\n', stderr);                                                                             \
        }                                                                                                    \
    } while (0)

static inline int check_report(const char *name)
{
    printf("%s: %d checks, %d failed\n", name, check_count, check_failures);
    return check_failures ? 1 : 0;
}

/* Deterministic xorshift64* for seeded property tests. */
static inline unsigned long long check_rand(unsigned long long *s)
{
    *s ^= *s >> 12;
    *s ^= *s << 25;
    *s ^= *s >> 27;
    return *s * 2685821657736338717ull;
}
static inline float check_randf(unsigned long long *s, float lo, float hi)
{
    return lo + (hi - lo) * (float)((check_rand(s) >> 40) * (1.0 / 16777216.0));
}

/* A scene argument: course:PATH is the course folder's PATH (as
 * tests/course.sh resolves it: RAYBENCH_COURSE_DIR, else
 * RAYBENCH_COURSE_DEFAULT), anything else a path as it is. */
static inline const char *check_scene_path(const char *arg, char *buf, size_t size)
{
    if (strncmp(arg, "course:", 7) != 0)
        return arg;
    const char *dir = getenv("RAYBENCH_COURSE_DIR");
    if (!dir || !*dir)
        dir = getenv("RAYBENCH_COURSE_DEFAULT");
    snprintf(buf, size, "%s/%s", dir && *dir ? dir : "../shared/scenes/course", arg + 7);
    return buf;
}

/* 77 (meson's skip) with a line saying which, when a scene argument
 * (argv[1..argc)) is missing; else 0. */
static inline int check_scenes_present(int argc, char **argv)
{
    char buf[4096];
    for (int k = 1; k < argc; k++) {
        const char *path = check_scene_path(argv[k], buf, sizeof buf);
        if (access(path, R_OK) != 0) {
            printf("SKIP: %s not found (the course scenes: set RAYBENCH_COURSE_DIR)\n", path);
            return 77;
        }
    }
    return 0;
}

#endif
