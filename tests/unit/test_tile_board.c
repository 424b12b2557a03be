/* test_tile_board.c SCENE - the tile loop's strips and their backup renders
 * (cpu_tiles.h): however a frame's strips are split between first renders
 * and backups, and whichever render of a strip finishes first, the image
 * and the counters are the serial ones, every strip is in the image once,
 * and the board's count and end time say so. The races themselves are
 * forced here: a strip published twice, a frame rendered by backups alone,
 * strips that the board already calls done, strips whose backup has
 * started before their owner reaches them, and strips whose owner and
 * backup are both stalled (the rescue pass). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "backends/cpu_tiles.h"
#include "check.h"
#include "core/rt_shade.h"
#include "scene_fixture.h"

typedef struct {
    const RtSceneView *v;
    int w, h, tw, th;
    int64_t nstrips, total, words; /* strip numbers, strips that are not empty, state words */
    float *ref, *img;
    RtCounters cref;
    uint32_t *state;
    int64_t done, end_ns;
    RtTileBoard board;
} Frame;

static void frame_reset(Frame *f)
{
    for (size_t i = 0; i < (size_t)f->w * (size_t)f->h * 3; i++)
        f->img[i] = NAN;
    memset(f->state, 0, (size_t)f->words * sizeof *f->state);
    f->done = f->end_ns = 0;
    f->board = (RtTileBoard){f->state, &f->done, &f->end_ns, f->total};
}

/* The first pixel of strip s, or NULL if the strip is empty. */
static const float *strip_pixel(const Frame *f, const RtTileRun *r, int64_t s)
{
    int x0, x1, yw, i;
    const uint32_t *word = rt_strip_at(r, s, &x0, &x1, &yw, &i);
    return rt_word_strips(r, word - r->board->state) & RT_STRIP_DONE(i)
               ? &f->img[3 * ((size_t)(yw + i) * (size_t)f->w + (size_t)x0)]
               : NULL;
}

/* Strip s's state: 1 if done, 2 if backed up, 3 both. */
static unsigned strip_state(const RtTileRun *r, int64_t s)
{
    int x0, x1, yw, i;
    const uint32_t w = *rt_strip_at(r, s, &x0, &x1, &yw, &i);
    return (w >> i & 1) | (w >> (16 + i) & 1) << 1;
}

/* The pool's counters and the image against the serial ones; `skipped`
 * strips were left to others. */
static void frame_check(Frame *f, RtCpuPool *p, const RtTileRun *r, const char *what, int64_t skipped)
{
    RtCounters sum;
    char cores[256] = "";
    rt_cpu_pool_merge(p, &sum, cores, sizeof cores);
    size_t bad = 0, n = (size_t)f->w * (size_t)f->h * 3;
    for (size_t i = 0; i < n; i++)
        bad += memcmp(&f->img[i], &f->ref[i], sizeof(float)) != 0;
    if (skipped == 0) {
        CHECK(bad == 0, "%s: %zu of %zu floats differ from the serial image", what, bad, n);
        CHECK(memcmp(&sum, &f->cref, sizeof sum) == 0, "%s: counters differ (%llu node visits against %llu)", what,
              (unsigned long long)sum.node_visits, (unsigned long long)f->cref.node_visits);
        CHECK(f->done == f->total && f->end_ns > 0, "%s: %lld of %lld strips done, end %lld", what,
              (long long)f->done, (long long)f->total, (long long)f->end_ns);
        for (int64_t s = 0; s < f->nstrips; s++)
            CHECK(!strip_pixel(f, r, s) || strip_state(r, s) & 1, "%s: strip %lld not marked done", what,
                  (long long)s);
    } else {
        CHECK(f->done == f->total - skipped && f->end_ns == 0, "%s: %lld strips done, %lld expected", what,
              (long long)f->done, (long long)(f->total - skipped));
    }
}

/* Marks every third strip that exists as done (done) or backed up
 * elsewhere; how many. */
static int64_t mark_third(const Frame *f, const RtTileRun *r, int done)
{
    int64_t n = 0;
    for (int64_t s = 0; s < f->nstrips; s += 3)
        if (strip_pixel(f, r, s)) {
            int x0, x1, yw, i;
            uint32_t *word = rt_strip_at(r, s, &x0, &x1, &yw, &i); /* sets i */
            *word |= done ? RT_STRIP_DONE(i) : RT_STRIP_BACKUP(i);
            n++;
        }
    return n;
}

static void check_frame(const RtSceneView *v, Frame *f)
{
    const int threads[] = {1, 2, 7};
    for (int k = 0; k < 3; k++) {
        char what[96];
        RtCpuPool p;
        RtError e;
        CHECK(rt_cpu_pool_init(&p, threads[k], f->tw, f->th, f->w, f->h, &e) == 0, "pool: %s", e.msg);
        /* claims, then the backups' pass: whatever the split, one image */
        frame_reset(f);
        RtTileRun run = {.v = v, .rx1 = f->w, .ry1 = f->h, .tw = f->tw, .th = f->th, .count = f->nstrips,
                         .scan_count = f->nstrips, .scan_slots = 1, .rgb = f->img, .board = &f->board};
        rt_cpu_render_tiles(&p, &run);
        snprintf(what, sizeof what, "%d threads, claims", threads[k]);
        frame_check(f, &p, &run, what, 0);
        uint64_t runs, won;
        rt_cpu_pool_backups(&p, &runs, &won);
        CHECK(won <= runs && runs <= (uint64_t)f->total, "%s: %llu backups, %llu won", what,
              (unsigned long long)runs, (unsigned long long)won);
        rt_cpu_pool_free(&p);

        /* nobody claims (the owners stalled): the backups render it all */
        CHECK(rt_cpu_pool_init(&p, threads[k], f->tw, f->th, f->w, f->h, &e) == 0, "pool: %s", e.msg);
        frame_reset(f);
        run.count = 0;
        rt_cpu_render_tiles(&p, &run);
        snprintf(what, sizeof what, "%d threads, backups only", threads[k]);
        frame_check(f, &p, &run, what, 0);
        rt_cpu_pool_backups(&p, &runs, &won);
        CHECK(runs == (uint64_t)f->total && won == runs, "%s: %llu backups, %llu won, %lld strips", what,
              (unsigned long long)runs, (unsigned long long)won, (long long)f->total);
        rt_cpu_pool_free(&p);

        /* strips already done elsewhere are neither rendered nor counted;
         * strips whose backup started elsewhere (and never ends, as if its
         * thread were stalled) are rendered by their owner all the same */
        for (unsigned mark = 1; mark <= 2; mark <<= 1) {
            CHECK(rt_cpu_pool_init(&p, threads[k], f->tw, f->th, f->w, f->h, &e) == 0, "pool: %s", e.msg);
            frame_reset(f);
            const int64_t marked = mark_third(f, &run, mark == 1), skipped = mark == 1 ? marked : 0;
            run.count = f->nstrips;
            rt_cpu_render_tiles(&p, &run);
            snprintf(what, sizeof what, "%d threads, a third %s elsewhere", threads[k],
                     mark == 1 ? "done" : "backed up");
            frame_check(f, &p, &run, what, skipped);
            for (int64_t s = 0; s < f->nstrips; s += 3) {
                const float *px = strip_pixel(f, &run, s);
                CHECK(!px || (mark == 1 ? isnan(*px) && strip_state(&run, s) == 1 : strip_state(&run, s) == 3),
                      "%s: strip %lld: state %u", what, (long long)s, strip_state(&run, s));
            }
            rt_cpu_pool_free(&p);
        }

        /* owners stalled (nobody claims) and a third of the strips backed
         * up elsewhere, by backups stalled too: the backups' pass leaves
         * those out; the rescue pass renders them */
        for (int rescue = 0; rescue <= 1; rescue++) {
            CHECK(rt_cpu_pool_init(&p, threads[k], f->tw, f->th, f->w, f->h, &e) == 0, "pool: %s", e.msg);
            frame_reset(f);
            const int64_t held = mark_third(f, &run, 0);
            run.count = 0;
            run.rescue = rescue;
            rt_cpu_render_tiles(&p, &run);
            snprintf(what, sizeof what, "%d threads, owners and a third's backups stalled, %s", threads[k],
                     rescue ? "rescue" : "no rescue");
            if (rescue) {
                frame_check(f, &p, &run, what, 0);
                rt_cpu_pool_backups(&p, &runs, &won);
                CHECK(won == (uint64_t)f->total, "%s: %llu renders won, %lld strips", what, (unsigned long long)won,
                      (long long)f->total);
                /* one thread: each strip once, by one pass or the other */
                CHECK(threads[k] > 1 || runs == (uint64_t)f->total, "%s: %llu renders, %lld strips", what,
                      (unsigned long long)runs, (long long)f->total);
            } else {
                frame_check(f, &p, &run, what, held);
            }
            run.rescue = 0;
            rt_cpu_pool_free(&p);
        }
    }
}

/* One strip rendered twice: the first publishes, the second does not. */
static void check_twice(const RtSceneView *v, Frame *f)
{
    frame_reset(f);
    RtTileRun run = {.v = v, .rx1 = f->w, .ry1 = f->h, .tw = f->tw, .th = f->th, .scan_slots = 1, .rgb = f->img,
                     .board = &f->board};
    float *buf = malloc(sizeof(float) * 3 * (size_t)f->tw * (size_t)f->th);
    RtCounters a, b;
    memset(&a, 0, sizeof a);
    memset(&b, 0, sizeof b);
    CHECK(rt_strip_render(&run, 1, buf, &a) == 1, "the first render of a strip publishes");
    CHECK(rt_strip_render(&run, 1, buf, &b) == 0, "the second render of a strip does not");
    CHECK(a.primary_rays == (uint64_t)f->tw && b.primary_rays == 0,
          "only the first render counts: %llu, %llu primary rays", (unsigned long long)a.primary_rays,
          (unsigned long long)b.primary_rays);
    rt_strips_done(&f->board, 1);
    CHECK(f->done == 1 && f->end_ns == 0, "one strip done (%lld), frame not complete", (long long)f->done);
    /* an owner's claim of two tiles counts each word as it publishes it
     * (here all but strip 1, already in): an owner held between two words
     * leaves none of its published strips uncounted */
    RtCounters c;
    memset(&c, 0, sizeof c);
    float *tiles = malloc(sizeof(float) * 3 * (size_t)f->tw * 16);
    rt_strips_render(&run, 0, 2 * (int64_t)f->th, tiles, &c);
    int64_t in = 0;
    for (int64_t s = 0; s < 2 * (int64_t)f->th; s++)
        in += strip_pixel(f, &run, s) != NULL;
    CHECK(f->done == in, "a claim of two tiles: %lld strips counted, %lld in the image", (long long)f->done,
          (long long)in);
    free(tiles);
    /* the bottom tiles' strips past the image's edge are empty */
    const int64_t last = f->nstrips - 1;
    CHECK(f->h % f->th != 0 && rt_strip_render(&run, last, buf, &a) == 0 && strip_state(&run, last) == 0,
          "an empty strip renders nothing");
    free(buf);
}

int main(int argc, char **argv)
{
    char buf[4096];
    if (argc != 2)
        return fprintf(stderr, "usage: test_tile_board SCENE\n"), 2;
    RtScene s;
    RtAccel a;
    RtCamera cam;
    RtSceneView v;
    const char *path = check_scene_path(argv[1], buf, sizeof buf);
    if (fixture_load(path, &s, &a, &cam, &v) != 0)
        return check_report("test_tile_board");
    /* 61x47: uneven edges, in 7x5 tiles (one state word per tile) and in
     * 9x20 tiles (two, the second half used; the bottom tiles 7 rows) */
    RtError e;
    s.settings.width = 61;
    s.settings.height = 47;
    CHECK(rt_scene_camera(&s, &cam, &e) == 0, "camera: %s", e.msg);
    v = rt_scene_view(&s, &a, &cam);
    void *soa = rt_cpu_prepare(&v);
    const int tiles[2][2] = {{7, 5}, {9, 20}};
    for (int k = 0; k < 2; k++) {
        const int tw = tiles[k][0], th = tiles[k][1];
        Frame f = {&v, 61, 47, tw, th, rt_strip_count(61, 47, tw, th), rt_strip_total(61, 47, tw),
                   rt_board_words(61, 47, tw, th), NULL, NULL, {0}, NULL, 0, 0, {0}};
        size_t n = (size_t)f.w * (size_t)f.h * 3;
        f.ref = malloc(n * sizeof(float));
        f.img = malloc(n * sizeof(float));
        f.state = malloc((size_t)f.words * sizeof *f.state);
        memset(&f.cref, 0, sizeof f.cref);
        rt_cpu_render_tile(&v, 0, 0, f.w, f.h, f.ref, 3 * (size_t)f.w, &f.cref);
        check_twice(&v, &f);
        check_frame(&v, &f);
        printf("%s: %lld strips of %dx%d tiles\n", path, (long long)f.total, f.tw, f.th);
        free(f.ref);
        free(f.img);
        free(f.state);
    }
    free(soa);
    fixture_free(&s, &a);
    return check_report("test_tile_board");
}
