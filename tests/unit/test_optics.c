/* test_optics.c - the shading maths against closed-form geometry and optics.
 *
 * Each case writes a small scene, renders it with the serial backend (the
 * reference every other backend must match), once with brute force and once
 * with the BVH, and compares every pixel with a value this file computes in
 * double precision from RENDERING-RULES.md alone: the camera ray, the
 * intersection, Lambert and Blinn-Phong, the spot falloff, a shadow edge,
 * Snell's law through a slab and the onset of total internal reflection.
 * Nothing here is read back from the renderer's own earlier output.
 *
 * Thresholds: a pixel away from an edge must be within 1/255 of the
 * closed-form value (float32 against double); a pixel whose centre lies
 * within EDGE_EPS (in the case's own units) of a discontinuity is not
 * judged, and every case asserts how many pixels it judged, so a case cannot
 * pass by judging none. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "rt.h"

typedef struct {
    double x, y, z;
} D3;

static D3 d3(double x, double y, double z)
{
    D3 r = {x, y, z};
    return r;
}
static D3 add(D3 a, D3 b) { return d3(a.x + b.x, a.y + b.y, a.z + b.z); }
static D3 sub(D3 a, D3 b) { return d3(a.x - b.x, a.y - b.y, a.z - b.z); }
static D3 scale(D3 a, double s) { return d3(a.x * s, a.y * s, a.z * s); }
static double dot(D3 a, D3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static D3 cross(D3 a, D3 b) { return d3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x); }
static D3 norm(D3 a) { return scale(a, 1.0 / sqrt(dot(a, a))); }

/* The camera of RENDERING-RULES.md: it looks along minus camera_fwd. */
typedef struct {
    D3 pos, fwd, right, up;
    double d;
    int w, h;
} Cam;

static Cam cam_make(D3 pos, D3 fwd, D3 up, double fov_deg, int w, int h)
{
    Cam c;
    c.pos = pos;
    c.fwd = norm(fwd);
    c.right = norm(cross(up, c.fwd));
    c.up = norm(cross(c.fwd, c.right));
    c.d = (h / 2.0) / tan(fov_deg * M_PI / 180.0);
    c.w = w;
    c.h = h;
    return c;
}

static D3 cam_dir(const Cam *c, int i, int j)
{
    D3 v = scale(c->fwd, -c->d);
    v = add(v, scale(c->right, c->w / 2.0 - (i + 0.5)));
    v = add(v, scale(c->up, c->h / 2.0 - (j + 0.5)));
    return norm(v);
}

/* Renders text with the serial backend and the given accelerator into 8-bit
 * RGB (malloc'd). The float image is poisoned with NaN first; a pixel left
 * unwritten fails the check. Returns NULL on any error (already CHECKed). */
static uint8_t *render(const char *text, RtAccelKind kind, int *w, int *h)
{
    RtScene s;
    RtAccel a;
    RtCamera cam;
    RtError e;
    memset(&s, 0, sizeof s);
    memset(&a, 0, sizeof a);
    uint8_t *rgb = NULL;
    float *f = NULL;
    if (rt_scene_parse_buffer("optics.txt", text, strlen(text), &s, NULL, NULL, &e) != 0 ||
        rt_scene_camera(&s, &cam, &e) != 0 || rt_accel_build(&s, kind, &a, &e) != 0) {
        CHECK(0, "%s", e.msg);
        goto out;
    }
    size_t n = (size_t)cam.width * (size_t)cam.height * 3;
    f = malloc(n * sizeof *f);
    rgb = malloc(n);
    for (size_t k = 0; k < n; k++)
        f[k] = NAN;
    RtRenderJob job;
    memset(&job, 0, sizeof job);
    job.scene = &s;
    job.accel = &a;
    job.view = rt_scene_view(&s, &a, &cam);
    RtRenderOut o;
    memset(&o, 0, sizeof o);
    o.rgb = f;
    CHECK(rt_backend_find("serial")->render(&job, &o, &e) == 0, "render: %s", e.msg);
    size_t unwritten = 0;
    for (size_t k = 0; k < n; k++)
        unwritten += isnan(f[k]) != 0;
    CHECK(unwritten == 0, "%zu channels never written", unwritten);
    rt_image_quantize(f, rgb, n / 3);
    *w = cam.width;
    *h = cam.height;
out:
    free(f);
    rt_accel_free(&a);
    rt_scene_free(&s);
    return rgb;
}

static int q8(double c) /* RENDERING-RULES: clamp, times 255, rounded */
{
    c = c < 0 ? 0 : c > 1 ? 1 : c;
    return (int)floor(c * 255.0 + 0.5);
}

/* Expected colour of pixel (i, j), or 0 when the pixel is too near an edge
 * to judge. */
typedef int (*ExpectFn)(const void *ctx, int i, int j, D3 *rgb);

typedef struct {
    long judged, bad;
    int worst;
} Tally;

/* Compares both accelerators' renders of text with expect(); returns the
 * number of pixels judged. */
static long compare(const char *name, const char *text, ExpectFn expect, const void *ctx)
{
    long judged = 0;
    for (int k = 0; k < 2; k++) {
        RtAccelKind kind = k ? RT_ACCEL_BVH : RT_ACCEL_NONE;
        int w = 0, h = 0;
        uint8_t *img = render(text, kind, &w, &h);
        if (!img)
            return 0;
        Tally t = {0, 0, 0};
        for (int j = 0; j < h; j++)
            for (int i = 0; i < w; i++) {
                D3 c;
                if (!expect(ctx, i, j, &c))
                    continue;
                t.judged++;
                const uint8_t *p = img + 3 * ((size_t)j * (size_t)w + (size_t)i);
                int want[3] = {q8(c.x), q8(c.y), q8(c.z)};
                int off = 0;
                for (int ch = 0; ch < 3; ch++) {
                    int dd = abs((int)p[ch] - want[ch]);
                    off = dd > off ? dd : off;
                }
                if (off > t.worst)
                    t.worst = off;
                if (off > 1) {
                    if (t.bad < 3)
                        fprintf(stderr, "%s (%s): pixel (%d, %d) is %d %d %d, closed form %d %d %d\n", name,
                                rt_accel_name(kind), i, j, p[0], p[1], p[2], want[0], want[1], want[2]);
                    t.bad++;
                }
            }
        CHECK(t.bad == 0, "%s (%s): %ld of %ld judged pixels off by more than 1/255", name, rt_accel_name(kind), t.bad,
              t.judged);
        printf("%s (%s): %ld pixels judged, largest difference %d/255\n", name, rt_accel_name(kind), t.judged,
               t.worst);
        judged = t.judged;
        free(img);
    }
    return judged;
}

/* ------------------------------------------------------------------ cases */

/* 1. A plane under a directional light: ambient + Lambert + Blinn-Phong, and
 * (max_depth 2) the mirror ray's background. */
typedef struct {
    Cam cam;
    D3 ka, kd, ks, amb, light, ldir, bg;
    double ns;
    long specular_pixels; /* pixels whose highlight term is over 2/255 */
} PlaneCase;

static int plane_expect(const void *ctx, int i, int j, D3 *rgb)
{
    PlaneCase *pc = (PlaneCase *)ctx;
    D3 D = cam_dir(&pc->cam, i, j);
    if (D.y > -0.05) /* the horizon and the quad's far edge are not judged */
        return 0;
    double t = (0.0 - pc->cam.pos.y) / D.y;
    D3 p = add(pc->cam.pos, scale(D, t));
    if (fabs(p.x) > 90 || fabs(p.z) > 90)
        return 0;
    D3 N = d3(0, 1, 0), L = norm(scale(pc->ldir, -1)), V = scale(D, -1);
    D3 H = norm(add(L, V));
    double nl = fmax(0.0, dot(N, L)), spec = pow(fmax(0.0, dot(N, H)), pc->ns);
    D3 c;
    c.x = pc->ka.x * pc->amb.x + pc->kd.x * pc->light.x * nl + pc->ks.x * pc->light.x * spec + pc->ks.x * pc->bg.x;
    c.y = pc->ka.y * pc->amb.y + pc->kd.y * pc->light.y * nl + pc->ks.y * pc->light.y * spec + pc->ks.y * pc->bg.y;
    c.z = pc->ka.z * pc->amb.z + pc->kd.z * pc->light.z * nl + pc->ks.z * pc->light.z * spec + pc->ks.z * pc->bg.z;
    if (pc->ks.x * pc->light.x * spec > 2.0 / 255.0)
        pc->specular_pixels++;
    *rgb = c;
    return 1;
}

static void test_plane(void)
{
    const char *text = "film_resolution: 64 48\n"
                       "camera_pos: 0 3 0\ncamera_fwd: 0 1 1\ncamera_up: 0 1 0\ncamera_fov_ha: 30\n"
                       "background: .1 .2 .3\nambient_light: .2 .25 .3\nmax_depth: 2\n"
                       "directional_light: .9 .8 .7  0 -1 .8\n"
                       "material: .1 .2 .3  .5 .4 .3  .3 .3 .3  20  0 0 0  1\n"
                       "vertex: -100 0 -100\nvertex: 100 0 -100\nvertex: 100 0 100\nvertex: -100 0 100\n"
                       "triangle: 0 1 2\ntriangle: 0 2 3\n";
    PlaneCase pc;
    pc.cam = cam_make(d3(0, 3, 0), d3(0, 1, 1), d3(0, 1, 0), 30, 64, 48);
    pc.ka = d3(.1, .2, .3);
    pc.kd = d3(.5, .4, .3);
    pc.ks = d3(.3, .3, .3);
    pc.amb = d3(.2, .25, .3);
    pc.light = d3(.9, .8, .7);
    pc.ldir = d3(0, -1, .8);
    pc.bg = d3(.1, .2, .3);
    pc.ns = 20;
    pc.specular_pixels = 0;
    long n = compare("plane Lambert + Blinn-Phong", text, plane_expect, &pc);
    CHECK(n > 64 * 48 / 2, "plane: only %ld pixels judged", n);
    CHECK(pc.specular_pixels / 2 > 20, "plane: the highlight is in view on only %ld pixels", pc.specular_pixels / 2);
}

/* 2. A sphere's silhouette: seen from its axis, pixel (i, j) shows the
 * sphere iff its centre is within d*tan(asin(r/Z)) pixels of the image
 * centre. Ambient-only shading makes both sides a known constant. */
typedef struct {
    Cam cam;
    double rpix;
    long inside;
} SilCase;

static int sil_expect(const void *ctx, int i, int j, D3 *rgb)
{
    SilCase *sc = (SilCase *)ctx;
    double x = sc->cam.w / 2.0 - (i + 0.5), y = sc->cam.h / 2.0 - (j + 0.5);
    double r = sqrt(x * x + y * y);
    if (fabs(r - sc->rpix) < 0.02)
        return 0;
    if (r < sc->rpix) {
        *rgb = d3(.8, .4, .2);
        sc->inside++;
    } else {
        *rgb = d3(0, 0, .5);
    }
    return 1;
}

static void test_silhouette(void)
{
    /* r/Z chosen so that the silhouette has a radius of 10.3 pixels */
    const int w = 48, h = 40;
    const double fov = 25, Z = 12, rpix = 10.3;
    const double d = (h / 2.0) / tan(fov * M_PI / 180.0);
    const double r = Z * sin(atan(rpix / d));
    char text[512];
    snprintf(text, sizeof text,
             "film_resolution: %d %d\ncamera_fwd: 0 0 1\ncamera_fov_ha: %g\nbackground: 0 0 .5\nambient_light: 1 1 1\nmax_depth: 1\n"
             "material: .8 .4 .2  0 0 0  0 0 0  1  0 0 0  1\nsphere: 0 0 %g %.9g\n",
             w, h, fov, -Z, r);
    SilCase sc;
    sc.cam = cam_make(d3(0, 0, 0), d3(0, 0, 1), d3(0, 1, 0), fov, w, h);
    sc.rpix = rpix;
    sc.inside = 0;
    long n = compare("sphere silhouette at 10.3 px", text, sil_expect, &sc);
    CHECK(n > w * h - 200, "silhouette: only %ld pixels judged", n);
    /* pi * 10.3^2 = 333 pixel centres, about */
    CHECK(sc.inside / 2 > 300 && sc.inside / 2 < 370, "silhouette: %ld pixels inside", sc.inside / 2);
}

/* 3. A spot light straight down onto a white floor, seen from above: full
 * inside angle1, the linear falloff between angle1 and angle2, dark outside. */
typedef struct {
    Cam cam;
    double hgt, a1, a2, power;
    long region[3];
} SpotCase;

static int floor_hit(const Cam *c, int i, int j, D3 *p)
{
    D3 D = cam_dir(c, i, j);
    if (D.y >= -1e-6)
        return 0;
    *p = add(c->pos, scale(D, -c->pos.y / D.y));
    return 1;
}

static int spot_expect(const void *ctx, int i, int j, D3 *rgb)
{
    SpotCase *sc = (SpotCase *)ctx;
    D3 p;
    if (!floor_hit(&sc->cam, i, j, &p))
        return 0;
    D3 tolight = d3(-p.x, sc->hgt, -p.z);
    double dist = sqrt(dot(tolight, tolight));
    double a = acos(sc->hgt / dist) * 180.0 / M_PI; /* angle from the spot's axis (0 -1 0) */
    double s;
    int region;
    if (a > sc->a2) {
        s = 0;
        region = 2;
    } else if (a > sc->a1) {
        s = 1.0 - (a - sc->a1) / (sc->a2 - sc->a1);
        region = 1;
    } else {
        s = 1;
        region = 0;
    }
    if (fabs(a - sc->a1) < 1e-3 || fabs(a - sc->a2) < 1e-3)
        return 0;
    sc->region[region]++;
    double v = sc->power / (dist * dist) * s * (sc->hgt / dist); /* kd = 1, N.L = cos a */
    *rgb = d3(v, v, v);
    return 1;
}

static void test_spot(void)
{
    const char *text = "film_resolution: 61 47\n"
                       "camera_pos: 0 5 0\ncamera_fwd: 0 1 0\ncamera_up: 0 0 -1\ncamera_fov_ha: 40\n"
                       "max_depth: 1\n"
                       "spot_light: 8.1 8.1 8.1  0 3 0  0 -1 0  15 35\n"
                       "material: 0 0 0  1 1 1  0 0 0  1  0 0 0  1\n"
                       "vertex: -50 0 -50\nvertex: 50 0 -50\nvertex: 50 0 50\nvertex: -50 0 50\n"
                       "triangle: 0 1 2\ntriangle: 0 2 3\n";
    SpotCase sc;
    sc.cam = cam_make(d3(0, 5, 0), d3(0, 1, 0), d3(0, 0, -1), 40, 61, 47);
    sc.hgt = 3;
    sc.a1 = 15;
    sc.a2 = 35;
    sc.power = 8.1;
    memset(sc.region, 0, sizeof sc.region);
    long n = compare("spot light falloff", text, spot_expect, &sc);
    CHECK(n > 61 * 47 - 20, "spot: only %ld pixels judged", n);
    CHECK(sc.region[0] > 40 && sc.region[1] > 200 && sc.region[2] > 200,
          "spot: inside %ld, between %ld, outside %ld pixels", sc.region[0] / 2, sc.region[1] / 2, sc.region[2] / 2);
}

/* 4. A hard shadow: a strip at height 1 under an oblique directional light
 * shades the floor where the shadow ray from p meets the strip, i.e. floor x
 * in [x0 + s, x1 + s] with s the light's horizontal run per unit height. The
 * camera above sees the strip itself and the shadow's visible part. */
typedef struct {
    Cam cam;
    double x0, x1, run;
    long shadow, lit, strip;
} ShadowCase;

static int shadow_expect(const void *ctx, int i, int j, D3 *rgb)
{
    ShadowCase *sc = (ShadowCase *)ctx;
    D3 D = cam_dir(&sc->cam, i, j);
    /* the strip at y = 1 first */
    double ts = (1.0 - sc->cam.pos.y) / D.y;
    D3 q = add(sc->cam.pos, scale(D, ts));
    const double e = 1e-3;
    if (fabs(q.x - sc->x0) < e || fabs(q.x - sc->x1) < e)
        return 0;
    if (q.x > sc->x0 && q.x < sc->x1 && fabs(q.z) < 20) {
        *rgb = d3(0, 0, 1); /* the strip: blue, ambient only */
        sc->strip++;
        return 1;
    }
    D3 p;
    if (!floor_hit(&sc->cam, i, j, &p))
        return 0;
    double xs = p.x - sc->run; /* where the shadow ray crosses y = 1 */
    if (fabs(xs - sc->x0) < e || fabs(xs - sc->x1) < e)
        return 0;
    D3 L = norm(d3(-sc->run, 1, 0));
    double lit = xs > sc->x0 && xs < sc->x1 ? 0 : 1;
    double v = .1 + .8 * L.y * lit; /* ka * ambient + kd * N.L */
    *rgb = d3(v, v, v);
    if (lit)
        sc->lit++;
    else
        sc->shadow++;
    return 1;
}

static void test_shadow_edge(void)
{
    const char *text = "film_resolution: 80 60\n"
                       "camera_pos: 0 5 0\ncamera_fwd: 0 1 0\ncamera_up: 0 0 -1\ncamera_fov_ha: 35\n"
                       "ambient_light: 1 1 1\nmax_depth: 1\n"
                       "directional_light: 1 1 1  .5 -1 0\n"
                       "material: .1 .1 .1  .8 .8 .8  0 0 0  1  0 0 0  1\n"
                       "vertex: -50 0 -50\nvertex: 50 0 -50\nvertex: 50 0 50\nvertex: -50 0 50\n"
                       "triangle: 0 1 2\ntriangle: 0 2 3\n"
                       "material: 0 0 1  0 0 0  0 0 0  1  0 0 0  1\n"
                       "vertex: -2 1 -20\nvertex: -1 1 -20\nvertex: -1 1 20\nvertex: -2 1 20\n"
                       "triangle: 4 5 6\ntriangle: 4 6 7\n";
    ShadowCase sc;
    sc.cam = cam_make(d3(0, 5, 0), d3(0, 1, 0), d3(0, 0, -1), 35, 80, 60);
    sc.x0 = -2;
    sc.x1 = -1;
    sc.run = 0.5; /* light (.5, -1, 0): the shadow is the strip moved by +0.5 in x */
    sc.shadow = sc.lit = sc.strip = 0;
    long n = compare("shadow edge", text, shadow_expect, &sc);
    CHECK(n > 80 * 60 - 200, "shadow: only %ld pixels judged", n);
    /* visible shadow: floor x in (-1.25, -0.5), about 5.3 columns of 60 rows */
    CHECK(sc.shadow / 2 > 200 && sc.strip / 2 > 300 && sc.lit / 2 > 3000, "shadow: %ld shadow, %ld strip, %ld lit",
          sc.shadow / 2, sc.strip / 2, sc.lit / 2);
}

/* 5. A horizontal glass slab (ior 1.5, kt 1) over a floor whose colour
 * changes at z = 0, across the view: each ray refracts in at the top face and
 * out at the bottom one, parallel to itself but moved sideways by
 * t sin(i - r) / cos(r). The boundary seen through the slab sits where the
 * shifted ray crosses z = 0. */
typedef struct {
    Cam cam;
    double ior, top, bottom;
    long shifted; /* judged pixels that a straight ray would colour otherwise */
} SlabCase;

static D3 refract(D3 D, D3 n, double eta) /* the rules' T, with n against D */
{
    double ci = -dot(D, n);
    double k = 1 - eta * eta * (1 - ci * ci);
    return norm(add(scale(D, eta), scale(n, eta * ci - sqrt(k))));
}

static int slab_expect(const void *ctx, int i, int j, D3 *rgb)
{
    SlabCase *sc = (SlabCase *)ctx;
    D3 D = cam_dir(&sc->cam, i, j);
    if (D.y > -0.2)
        return 0;
    D3 p = add(sc->cam.pos, scale(D, (sc->top - sc->cam.pos.y) / D.y));
    D3 T = refract(D, d3(0, 1, 0), 1.0 / sc->ior);   /* entering: front, eta = 1/ior */
    p = add(p, scale(T, (sc->bottom - p.y) / T.y));
    D3 O = refract(T, d3(0, 1, 0), sc->ior);         /* leaving: the normal flipped, eta = ior */
    p = add(p, scale(O, (0 - p.y) / O.y));
    D3 straight = add(sc->cam.pos, scale(D, -sc->cam.pos.y / D.y));
    if (fabs(p.z) < 2e-3 || fabs(p.x) > 40 || fabs(p.z) > 40)
        return 0;
    if ((p.z < 0) != (straight.z < 0))
        sc->shifted++;
    *rgb = p.z < 0 ? d3(1, 0, 0) : d3(0, 0, 1); /* ka * ambient through kt = 1 twice */
    return 1;
}

static void test_glass_slab(void)
{
    const char *text = "film_resolution: 64 48\n"
                       "camera_pos: 0.7 4 3\ncamera_fwd: 0 4 3\ncamera_up: 0 1 0\ncamera_fov_ha: 20\n"
                       "ambient_light: 1 1 1\nmax_depth: 3\n"
                       "material: 1 0 0  0 0 0  0 0 0  1  0 0 0  1\n"
                       "vertex: -60 0 -60\nvertex: 60 0 -60\nvertex: 60 0 0\nvertex: -60 0 0\n"
                       "triangle: 0 1 2\ntriangle: 0 2 3\n"
                       "material: 0 0 1  0 0 0  0 0 0  1  0 0 0  1\n"
                       "vertex: 60 0 60\nvertex: -60 0 60\n"
                       "triangle: 3 2 4\ntriangle: 3 4 5\n"
                       "material: 0 0 0  0 0 0  0 0 0  1  1 1 1  1.5\n"
                       /* top face y = 2 wound to face up, bottom y = 1 to face down */
                       "vertex: -60 2 -60\nvertex: 60 2 -60\nvertex: 60 2 60\nvertex: -60 2 60\n"
                       "triangle: 6 8 7\ntriangle: 6 9 8\n"
                       "vertex: -60 1 -60\nvertex: 60 1 -60\nvertex: 60 1 60\nvertex: -60 1 60\n"
                       "triangle: 10 11 12\ntriangle: 10 12 13\n";
    SlabCase sc;
    sc.cam = cam_make(d3(0.7, 4, 3), d3(0, 4, 3), d3(0, 1, 0), 20, 64, 48);
    sc.ior = 1.5;
    sc.top = 2;
    sc.bottom = 1;
    sc.shifted = 0;
    long n = compare("glass slab lateral shift", text, slab_expect, &sc);
    CHECK(n > 64 * 48 - 100, "slab: only %ld pixels judged", n);
    /* the shift is about a quarter of the slab's thickness at these angles:
     * two rows or more across the image land on the other colour */
    CHECK(sc.shifted / 2 > 2 * 64, "slab: only %ld pixels moved across the boundary by refraction", sc.shifted / 2);
}

/* 6. Total internal reflection: from inside a glass ball (ior 1.5, kt 1) a
 * ray meets the surface at sin(theta) = (distance of the centre from the
 * ray) / R. Beyond the critical angle asin(1/1.5) it reflects, at the same
 * angle every time, until max_depth ends it (black); below it the ray leaves
 * and shows the background. */
typedef struct {
    Cam cam;
    double R, ior;
    long tir, out;
} TirCase;

static int tir_expect(const void *ctx, int i, int j, D3 *rgb)
{
    TirCase *tc = (TirCase *)ctx;
    D3 D = cam_dir(&tc->cam, i, j);
    D3 C = scale(tc->cam.pos, -1); /* the centre (the origin) relative to the camera */
    D3 perp = sub(C, scale(D, dot(C, D)));
    double s = sqrt(dot(perp, perp)) / tc->R;
    if (fabs(s - 1.0 / tc->ior) < 1e-4)
        return 0;
    if (s > 1.0 / tc->ior) {
        *rgb = d3(0, 0, 0);
        tc->tir++;
    } else {
        *rgb = d3(.2, .6, 1);
        tc->out++;
    }
    return 1;
}

static void test_tir(void)
{
    const char *text = "film_resolution: 64 48\n"
                       "camera_pos: 1.7 0 0\ncamera_fwd: 0 0 1\ncamera_fov_ha: 40\n"
                       "background: .2 .6 1\nmax_depth: 5\n"
                       "material: 0 0 0  0 0 0  0 0 0  1  1 1 1  1.5\nsphere: 0 0 0 2\n";
    TirCase tc;
    tc.cam = cam_make(d3(1.7, 0, 0), d3(0, 0, 1), d3(0, 1, 0), 40, 64, 48);
    tc.R = 2;
    tc.ior = 1.5;
    tc.tir = tc.out = 0;
    long n = compare("total internal reflection onset", text, tir_expect, &tc);
    CHECK(n > 64 * 48 - 40, "tir: only %ld pixels judged", n);
    CHECK(tc.tir / 2 > 300 && tc.out / 2 > 300, "tir: %ld reflected, %ld leaving", tc.tir / 2, tc.out / 2);
}

int main(void)
{
    test_plane();
    test_silhouette();
    test_spot();
    test_shadow_edge();
    test_glass_slab();
    test_tir();
    return check_report("test_optics");
}
