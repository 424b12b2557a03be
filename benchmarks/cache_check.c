/* cache_check.c - what checking a scene cache entry costs: reads one entry
 * (DIR/KEY.rbc) into memory, then times, ROUNDS times each, the whole parse
 * (header, payload hash, index and tree checks: rt_cache_entry_parse) and
 * the checks alone (rt_scene_check and rt_bvh_check on the parsed entry).
 * A parse without the checks costs the difference (docs/performance.md,
 * "Scene cache").
 *
 *   cache-check ENTRY.rbc bvh|none [ROUNDS]
 */
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "rt.h"

static int read_all(const char *path, void **out, size_t *len)
{
    struct stat st;
    const int fd = open(path, O_RDONLY);
    if (fd < 0 || fstat(fd, &st) != 0 || st.st_size <= 0)
        return -1;
    *len = (size_t)st.st_size;
    if (posix_memalign(out, 64, *len) != 0)
        return -1;
    size_t at = 0;
    while (at < *len) {
        const ssize_t r = read(fd, (char *)*out + at, *len - at);
        if (r <= 0)
            return -1;
        at += (size_t)r;
    }
    close(fd);
    return 0;
}

int main(int argc, char **argv)
{
    RtAccelKind kind;
    if (argc < 3 || rt_accel_parse(argv[2], &kind) != 0) {
        fprintf(stderr, "usage: cache-check ENTRY.rbc bvh|none [ROUNDS]\n");
        return 2;
    }
    const int rounds = argc > 3 ? atoi(argv[3]) : 7;
    void *m;
    size_t len;
    if (read_all(argv[1], &m, &len) != 0 || rounds < 1) {
        fprintf(stderr, "cache-check: %s: cannot read\n", argv[1]);
        return 1;
    }
    double parse[64], check[64];
    const int n = rounds < 64 ? rounds : 64;
    RtScene s;
    RtAccel a;
    RtError err;
    for (int i = 0; i < n; i++) {
        double t0 = rt_now_ms();
        if (rt_cache_entry_parse(m, len, kind, &s, &a, &err) != 0) {
            fprintf(stderr, "cache-check: %s: %s\n", argv[1], err.msg);
            return 1;
        }
        parse[i] = rt_now_ms() - t0;
        t0 = rt_now_ms();
        if (rt_scene_check(&s, &a, &err) != 0 || rt_bvh_check(&a, &err) != 0)
            return 1;
        check[i] = rt_now_ms() - t0;
        rt_scene_free_deps(&s);
    }
    const double p = rt_median(parse, n), c = rt_median(check, n);
    printf("entry=%s bytes=%zu triangles=%u prims=%u rounds=%d parse_ms=%.3f check_ms=%.3f parse_unchecked_ms=%.3f\n",
           argv[1], len, s.ntriangles, a.nprims, n, p, c, p - c);
    free(m);
    return 0;
}
