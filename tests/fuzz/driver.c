/* driver.c - a standalone fuzzing loop for targets written for libFuzzer
 * (int LLVMFuzzerTestOneInput(const uint8_t *, size_t)): GCC has no
 * libFuzzer, so this runs the seed corpus, then mutated inputs for a
 * bounded time, with a seeded RNG so a run can be repeated.
 *
 *   fuzz_TARGET CORPUS_DIR SECONDS [SEED]   fuzz
 *   fuzz_TARGET FILE                        run one input (a reproducer)
 *
 * Before each call the input is written to a file (its path printed at the
 * start): when the sanitizer aborts on a crash, that file is the
 * reproducer. An input that runs longer than HANG_SECONDS aborts too. */
#define _GNU_SOURCE
#include <dirent.h>
#include <fcntl.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

#define FUZZ_MAX_INPUT (64u << 10) /* mutated inputs grow no larger */
#define MAX_POOL 512
#define HANG_SECONDS 10

typedef struct Input {
    uint8_t *data;
    size_t len;
} Input;

static char current_path[512];
static uint64_t rng_state;

static uint64_t rnd(void) /* xorshift64* */
{
    rng_state ^= rng_state >> 12, rng_state ^= rng_state << 25, rng_state ^= rng_state >> 27;
    return rng_state * 2685821657736338717ull;
}
static size_t below(size_t n) { return n ? (size_t)(rnd() % n) : 0; }

static void on_alarm(int sig)
{
    (void)sig;
    static const char msg[] = "fuzz: an input ran longer than the hang limit (a hang); reproducer in ";
    (void)!write(2, msg, sizeof msg - 1);
    (void)!write(2, current_path, strlen(current_path));
    (void)!write(2, "\n", 1);
    abort();
}

/* Writes the input where a crash leaves it, then runs the target. */
static void run(const uint8_t *data, size_t len)
{
    const int fd = open(current_path, O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd >= 0) {
        (void)!write(fd, data, len);
        close(fd);
    }
    alarm(HANG_SECONDS);
    LLVMFuzzerTestOneInput(data, len);
    alarm(0);
}

static int read_whole(const char *path, Input *in)
{
    FILE *f = fopen(path, "rb");
    if (!f)
        return -1;
    in->data = malloc(FUZZ_MAX_INPUT);
    in->len = in->data ? fread(in->data, 1, FUZZ_MAX_INPUT, f) : 0;
    fclose(f);
    return in->data ? 0 : -1;
}

static int load_corpus(const char *dir, Input *pool, size_t *n)
{
    DIR *d = opendir(dir);
    if (!d)
        return -1;
    struct dirent *e;
    char path[4096];
    while ((e = readdir(d)) != NULL && *n < MAX_POOL / 2) {
        struct stat st;
        snprintf(path, sizeof path, "%s/%s", dir, e->d_name);
        if (e->d_name[0] == '.' || stat(path, &st) != 0 || !S_ISREG(st.st_mode))
            continue;
        if (read_whole(path, &pool[*n]) == 0)
            ++*n;
    }
    closedir(d);
    return 0;
}

/* A number that breaks parsers: the edges of the integer types, huge
 * counts, values floats cannot hold. */
static const char *const big_numbers[] = {"0", "-1", "255", "65536", "2147483647", "2147483648", "4294967295",
                                          "4294967296", "100000000", "18446744073709551615",
                                          "99999999999999999999999", "1e38", "1e309", "-1e309", "nan", "0.5"};

/* Replaces the digits at a random place with a big number. */
static size_t replace_number(uint8_t *b, size_t len)
{
    size_t i = below(len), k = 0;
    while (k < len && !(b[(i + k) % len] >= '0' && b[(i + k) % len] <= '9'))
        k++;
    if (k == len)
        return len;
    i = (i + k) % len;
    size_t end = i;
    while (end < len && ((b[end] >= '0' && b[end] <= '9') || b[end] == '.'))
        end++;
    const char *num = big_numbers[below(sizeof big_numbers / sizeof *big_numbers)];
    const size_t nl = strlen(num);
    if (len - (end - i) + nl > FUZZ_MAX_INPUT)
        return len;
    memmove(b + i + nl, b + end, len - end);
    memcpy(b + i, num, nl);
    return len - (end - i) + nl;
}

/* One mutation of b (len bytes, room for FUZZ_MAX_INPUT); the new length. */
static size_t mutate(uint8_t *b, size_t len, const Input *pool, size_t npool)
{
    static const uint8_t interesting[] = {0, 255, '0', '9', '\n', ' ', '-', '"', '{', '}'};
    if (len == 0)
        return b[0] = (uint8_t)rnd(), 1;
    switch (below(7)) {
    case 0: /* bit flip */
        b[below(len)] ^= (uint8_t)(1u << below(8));
        return len;
    case 1: /* an interesting byte */
        b[below(len)] = interesting[below(sizeof interesting)];
        return len;
    case 2: { /* delete a chunk */
        const size_t at = below(len), n = 1 + below(len - at < 64 ? len - at : 64);
        memmove(b + at, b + at + n, len - at - n);
        return len - n;
    }
    case 3: { /* duplicate a chunk */
        const size_t at = below(len), n = 1 + below(len - at < 256 ? len - at : 256);
        if (len + n > FUZZ_MAX_INPUT)
            return len;
        memmove(b + at + n, b + at, len - at);
        return len + n;
    }
    case 4: { /* splice: this input's head, another's tail */
        const Input *o = &pool[below(npool)];
        const size_t cut = below(len), from = below(o->len), n = o->len - from;
        if (cut + n > FUZZ_MAX_INPUT)
            return len;
        memcpy(b + cut, o->data + from, n);
        return cut + n;
    }
    case 5: /* a random byte */
        b[below(len)] = (uint8_t)rnd();
        return len;
    default:
        return replace_number(b, len);
    }
}

int main(int argc, char **argv)
{
    const char *name = strrchr(argv[0], '/') ? strrchr(argv[0], '/') + 1 : argv[0];
    const char *tmp = getenv("TMPDIR") ? getenv("TMPDIR") : "/tmp";
    snprintf(current_path, sizeof current_path, "%s/%s-%ld.input", tmp, name, (long)getpid());
    signal(SIGALRM, on_alarm);
    struct stat st;
    if (argc == 2 && stat(argv[1], &st) == 0 && S_ISREG(st.st_mode)) { /* replay one input */
        Input in;
        if (read_whole(argv[1], &in) != 0)
            return perror(argv[1]), 2;
        run(in.data, in.len);
        printf("%s: ran %s (%zu bytes) without a crash\n", name, argv[1], in.len);
        free(in.data);
        remove(current_path);
        return 0;
    }
    if (argc < 3 || argc > 4) {
        fprintf(stderr, "usage: %s CORPUS_DIR SECONDS [SEED] | %s FILE\n", name, name);
        return 2;
    }
    const double seconds = atof(argv[2]);
    const uint64_t seed = argc == 4 ? strtoull(argv[3], NULL, 0) : (uint64_t)time(NULL) ^ (uint64_t)getpid() << 32;
    rng_state = seed ? seed : 1;
    Input *pool = calloc(MAX_POOL, sizeof *pool);
    size_t npool = 0;
    if (!pool || load_corpus(argv[1], pool, &npool) != 0 || npool == 0) {
        fprintf(stderr, "%s: no seed inputs in %s\n", name, argv[1]);
        return 2;
    }
    printf("%s: seed %llu, %zu seed inputs, %g s; the input being run is kept in %s\n", name,
           (unsigned long long)seed, npool, seconds, current_path);
    fflush(stdout);
    for (size_t i = 0; i < npool; i++)
        run(pool[i].data, pool[i].len);
    uint8_t *buf = malloc(FUZZ_MAX_INPUT);
    unsigned long long iters = 0;
    struct timespec t0, t;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    for (;; iters++) {
        clock_gettime(CLOCK_MONOTONIC, &t);
        if ((double)(t.tv_sec - t0.tv_sec) + 1e-9 * (double)(t.tv_nsec - t0.tv_nsec) >= seconds)
            break;
        const Input *src = &pool[below(npool)];
        memcpy(buf, src->data, src->len);
        size_t len = src->len;
        for (size_t k = 1 + below(4); k > 0; k--)
            len = mutate(buf, len, pool, npool);
        run(buf, len);
        /* some mutants join the pool, so edits can build on each other */
        if (below(16) == 0 && npool < MAX_POOL && (pool[npool].data = malloc(FUZZ_MAX_INPUT)) != NULL) {
            memcpy(pool[npool].data, buf, len);
            pool[npool++].len = len;
        }
    }
    printf("%s: seed %llu: %llu iterations in %g s, no crash\n", name, (unsigned long long)seed, iters, seconds);
    fflush(stdout); /* (before LeakSanitizer runs at exit) */
    remove(current_path);
    for (size_t i = 0; i < npool; i++)
        free(pool[i].data);
    free(pool), free(buf);
    return 0;
}
