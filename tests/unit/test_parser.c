/* test_parser.c - every command, the defaults, and every class of bad input
 * of the scene format. Run under ASan+UBSan too (tests/meson.build). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "rt.h"

static int warnings;
static char last_warning[512];
static void on_warn(void *ctx, const char *msg)
{
    (void)ctx;
    warnings++;
    snprintf(last_warning, sizeof last_warning, "%s", msg);
}

static size_t parse_len; /* 0: strlen */
static int parse(const char *text, RtScene *s, RtError *e)
{
    warnings = 0;
    last_warning[0] = '\0';
    e->msg[0] = '\0';
    size_t n = parse_len ? parse_len : strlen(text);
    parse_len = 0;
    return rt_scene_parse_buffer("t.txt", text, n, s, on_warn, NULL, e);
}

/* Expects a parse error whose message starts with "t.txt:LINE:" and contains needle. */
static void expect_error(const char *text, int line, const char *needle)
{
    RtScene s;
    RtError e;
    int rc = parse(text, &s, &e);
    char prefix[32];
    snprintf(prefix, sizeof prefix, "t.txt:%d:", line);
    CHECK(rc != 0, "accepted bad input: %s", text);
    CHECK(strncmp(e.msg, prefix, strlen(prefix)) == 0, "message '%s' lacks '%s'", e.msg, prefix);
    CHECK(strstr(e.msg, needle) != NULL, "message '%s' lacks '%s'", e.msg, needle);
    CHECK(strchr(e.msg, '\n') == NULL, "message is not one line: '%s'", e.msg);
    rt_scene_free(&s);
}

/* Parses fine, then the camera check must fail naming the line. */
static void expect_camera_error(const char *text, const char *prefix, const char *needle)
{
    RtScene s;
    RtError e;
    CHECK(parse(text, &s, &e) == 0, "parse failed: %s", e.msg);
    snprintf(s.source.path, sizeof s.source.path, "t.txt");
    RtCamera cam;
    int rc = rt_scene_camera(&s, &cam, &e);
    CHECK(rc != 0, "camera accepted: %s", text);
    CHECK(strncmp(e.msg, prefix, strlen(prefix)) == 0, "message '%s' lacks '%s'", e.msg, prefix);
    CHECK(strstr(e.msg, needle) != NULL, "message '%s' lacks '%s'", e.msg, needle);
    rt_scene_free(&s);
}

static void test_defaults(void)
{
    RtScene s;
    RtError e;
    CHECK(parse("", &s, &e) == 0, "%s", e.msg);
    CHECK(s.settings.width == 640 && s.settings.height == 480, "resolution %dx%d", s.settings.width, s.settings.height);
    CHECK(strcmp(s.settings.output, "raytraced.bmp") == 0, "output %s", s.settings.output);
    CHECK(s.settings.max_depth == 5, "max_depth %d", s.settings.max_depth);
    CHECK(s.settings.fov_ha == 45.0f, "fov %g", (double)s.settings.fov_ha);
    CHECK(s.settings.camera_fwd.z == -1.0f && s.settings.camera_up.y == 1.0f, "camera vectors");
    CHECK(s.settings.background.x == 0.0f && s.settings.ambient.x == 0.0f, "background/ambient");
    CHECK(s.nmaterials == 1, "default material present");
    const RtMaterial *m = &s.materials[0];
    CHECK(m->kd[0] == 1.0f && m->kd[2] == 1.0f && m->ka[0] == 0.0f && m->ks[0] == 0.0f, "default kd/ka/ks");
    CHECK(m->ns == 5.0f && m->ior == 1.0f && m->kt[0] == 0.0f, "default ns/ior/kt");
    rt_scene_free(&s);
}

static void test_every_command(void)
{
    const char *text =
        "# comment line\r\n"
        "camera_pos: 1 2 3   # trailing comment\r\n"
        "camera_fwd:\t0 0 1\n"
        "camera_up: 0 1 0\n"
        "camera_fov_ha: 30\n"
        "film_resolution: 64 48\n"
        "output_image: \"my image.png\"\n"
        "background: .5 .75 .93  # sky\n"
        "ambient_light: .1 .2 .3\n"
        "max_depth: 3\n"
        "max_vertices: 4\n"
        "max_normals: 3\n"
        "material: .1 .2 .3 .4 .5 .6 .7 .8 .9 10 .1 .1 .1 1.5\n"
        "vertex: 0 0 0\n"
        "vertex: 1 0 0\n"
        "vertex: 0 1 0\n"
        "normal: 0 0 1\n"
        "normal: 0 1 1\n"
        "normal: 1 0 1\n"
        "triangle: 0 1 2\n"
        "normal_triangle: 2 1 0 0 1 2\n"
        "sphere: 0 0 -5 1.5\n"
        "point_light: 1 1 1 0 5 0\n"
        "directional_light: 1 1 1 0 -2 0\n"
        "spot_light: 1 1 1 0 5 0 0 -1 0 10 20\n"
        "\n"
        "   \n";
    RtScene s;
    RtError e;
    CHECK(parse(text, &s, &e) == 0, "%s", e.msg);
    CHECK(warnings == 0, "unexpected warning %s", last_warning);
    CHECK(s.settings.camera_pos.x == 1.0f && s.settings.camera_pos.z == 3.0f, "camera_pos");
    CHECK(s.settings.camera_fwd.z == 1.0f, "camera_fwd");
    CHECK(s.settings.fov_ha == 30.0f, "fov");
    CHECK(s.settings.width == 64 && s.settings.height == 48, "resolution");
    CHECK(strcmp(s.settings.output, "my image.png") == 0, "quoted output '%s'", s.settings.output);
    CHECK(s.settings.background.y == 0.75f && s.settings.ambient.z == 0.3f, "background/ambient");
    CHECK(s.settings.max_depth == 3, "max_depth");
    CHECK(s.nmaterials == 2 && s.materials[1].ior == 1.5f && s.materials[1].ns == 10.0f, "material");
    CHECK(s.materials[1].ks[2] == 0.9f && s.materials[1].kt[0] == 0.1f, "material ks/kt");
    CHECK(s.nvertices == 3 && s.nnormals == 3, "pools %u %u", s.nvertices, s.nnormals);
    CHECK(s.ntriangles == 2, "triangles");
    CHECK(s.triangles[0].n[0] < 0 && s.triangles[0].material == 1, "flat triangle");
    CHECK(s.triangles[1].v[0] == 2 && s.triangles[1].n[2] == 2, "normal triangle");
    CHECK(s.nspheres == 1 && s.spheres[0].r == 1.5f && s.spheres[0].material == 1, "sphere");
    CHECK(s.nlights == 3, "lights %u", s.nlights);
    CHECK(s.lights[0].type == RT_LIGHT_POINT && s.lights[0].pos[1] == 5.0f, "point light");
    CHECK(s.lights[1].type == RT_LIGHT_DIRECTIONAL && s.lights[1].dir[1] == -1.0f, "directional normalized");
    CHECK(s.lights[2].type == RT_LIGHT_SPOT && s.lights[2].angle1 == 10.0f && s.lights[2].angle2 == 20.0f, "spot");
    RtCamera cam;
    CHECK(rt_scene_camera(&s, &cam, &e) == 0, "%s", e.msg);
    rt_scene_free(&s);
}

static void test_unknown_command_warns(void)
{
    RtScene s;
    RtError e;
    CHECK(parse("sphere: 0 0 0 1\nfrobnicate: 1 2 3\nsphere: 0 0 0 2\n", &s, &e) == 0, "%s", e.msg);
    CHECK(warnings == 1, "warnings %d", warnings);
    CHECK(strstr(last_warning, "t.txt:2:") && strstr(last_warning, "frobnicate"), "warning '%s'", last_warning);
    CHECK(s.nspheres == 2, "parsing carried on");
    rt_scene_free(&s);
}

static void test_no_capacity_hint(void)
{
    /* Many vertices without max_vertices: pools grow. */
    size_t cap = 1 << 20;
    char *buf = malloc(cap);
    size_t off = 0;
    for (int i = 0; i < 5000; i++)
        off += (size_t)snprintf(buf + off, cap - off, "vertex: %d 0 0\n", i);
    off += (size_t)snprintf(buf + off, cap - off, "triangle: 4999 0 1\nmax_vertices: 2\n");
    RtScene s;
    RtError e;
    CHECK(parse(buf, &s, &e) == 0, "%s", e.msg);
    CHECK(s.nvertices == 5000 && s.vertices[4999].x == 4999.0f, "grown pool");
    rt_scene_free(&s);
    free(buf);
}

static void test_numbers(void)
{
    RtScene s;
    RtError e;
    CHECK(parse("sphere: 1e-3 -2.5E2 +0.125 .5\nsphere: 0x1p-2 3. 0.1 12345678901234567890123\n", &s, &e) == 0,
          "%s", e.msg);
    CHECK(s.spheres[0].c[0] == 1e-3f && s.spheres[0].c[1] == -250.0f && s.spheres[0].c[2] == 0.125f, "floats");
    CHECK(s.spheres[1].c[0] == 0.25f && s.spheres[1].c[1] == 3.0f && s.spheres[1].c[2] == 0.1f, "hex and 3.");
    CHECK(fabsf(s.spheres[1].r - 1.2345679e22f) < 1e16f, "long mantissa %g", (double)s.spheres[1].r);
    rt_scene_free(&s);
}

static void test_bad_input(void)
{
    expect_error("sphere: 1 2 3\n", 1, "expected 4 values, got 3");
    expect_error("\nsphere: 1 2 3 4 5\n", 2, "expected 4 values, got 5");
    expect_error("vertex: 1 abc 3\n", 1, "not a finite number");
    expect_error("vertex: 1 2 3x\n", 1, "not a finite number");
    expect_error("vertex: nan 0 0\n", 1, "not a finite number");
    expect_error("vertex: 0 inf 0\n", 1, "not a finite number");
    expect_error("vertex: 0 0 1e39\n", 1, "not a finite number");
    expect_error("vertex: 0 0 0\nvertex: 1 0 0\ntriangle: 0 1 2\n", 3, "vertex index 2 out of range");
    expect_error("vertex: 0 0 0\ntriangle: 0 -1 0\n", 2, "negative");
    /* 2^32 rounds to a representable float; read exactly, it is out of range */
    expect_error("vertex: 0 0 0\ntriangle: 0 0 4294967296\n", 2, "out of range");
    expect_error("vertex: 0 0 0\ntriangle: 0 0 16777217\n", 2, "vertex index 16777217 out of range");
    expect_error("vertex: 0 0 0\ntriangle: 0 0.5 0\n", 2, "not an integer");
    expect_error("vertex: 0 0 0\nnormal: 0 0 1\nnormal_triangle: 0 0 0 0 0 1\n", 3, "normal index 1 out of range");
    expect_error("film_resolution: 0 480\n", 1, "positive integer");
    expect_error("film_resolution: 640 -1\n", 1, "positive integer");
    expect_error("film_resolution: 1000000 1000000\n", 1, "GiB");
    expect_error("film_resolution: 30000 30000\n", 1, "would need");
    expect_error("sphere: 0 0 0 -1\n", 1, "radius must be positive");
    expect_error("sphere: 0 0 0 0\n", 1, "radius must be positive");
    expect_error("max_depth: -1\n", 1, "must not be negative");
    expect_error("max_depth: 1000\n", 1, "exceeds");
    expect_error("camera_fov_ha: 90\n", 1, "strictly between 0 and 90");
    expect_error("camera_fov_ha: 0\n", 1, "strictly between 0 and 90");
    expect_error("camera_fov_ha: -10\n", 1, "strictly between 0 and 90");
    expect_error("material: 1 1 1 1 1 1 1 1 1 1 1 1 1\n", 1, "expected 14 values, got 13");
    /* ior only matters where light is transmitted: refused there, at <= 0 */
    expect_error("material: 1 1 1 1 1 1 1 1 1 1 1 1 1 0\n", 1, "index of refraction");
    expect_error("material: 0 0 0 0 0 0 0 0 0 1 0 0 .5 -1.5\n", 1, "transmissive");
    expect_error("material: 0 0 0 0 0 0 0 0 0 1 .1 0 0 0\n", 1, "index of refraction must be positive");
    expect_error("directional_light: 1 1 1 0 0 0\n", 1, "zero vector");
    expect_error("spot_light: 1 1 1 0 0 0 0 -1 0 30 20\n", 1, "angle1 <= angle2");
    expect_error("output_image:   \n", 1, "expected a file name");
    expect_error("just some words\n", 1, "expected 'command: values'");
    expect_error("sphere: 0 0 0 1\n\x01\x02\x03garbage\n", 2, "binary data");
    /* the bytes are checked eight at a time: a tab in the word before, the
     * bad byte in a later word, the column still exact */
    expect_error("sphere:\t0 0 0 1 \x7f\n", 1, "byte 0x7f at column 17");
    expect_error("vertex:\t0 0\x1b" "0\n", 1, "byte 0x1b at column 12");
    expect_error("vertex: 1 2 3\r\nvertex:\t1 2 3 # tabs\t\tand \x80\xff fine, \x1f not\n", 2,
                 "byte 0x1f at column 36");
    parse_len = 7;
    expect_error("a\0b: 1\n", 1, "binary data");
    {
        /* an enormous line */
        size_t n = 200000;
        char *big = malloc(n + 16);
        memcpy(big, "vertex: ", 8);
        memset(big + 8, '1', n);
        big[n + 8] = '\n';
        big[n + 9] = '\0';
        expect_error(big, 1, "line longer than");
        free(big);
    }
}

/* What the course's own tools write for an opaque material: ior 0 (or any
 * value) with kt all zero. It must load, and the value is kept as written. */
static void test_opaque_ior_lenient(void)
{
    const char *texts[] = {"material: .1 .7 0 .1 .7 0 0 0 0 0 0 0 0 0\nsphere: 0 0 -5 1\n",
                           "material: .1 .7 0 .1 .7 0 0 0 0 0 0 0 0 -3\nsphere: 0 0 -5 1\n"};
    for (int i = 0; i < 2; i++) {
        RtScene s;
        RtError e;
        CHECK(parse(texts[i], &s, &e) == 0, "opaque material with ior <= 0 refused: %s", e.msg);
        CHECK(s.nmaterials == 2 && s.materials[1].kd[1] == 0.7f && s.materials[1].kt[0] == 0.0f,
              "opaque material not read");
        CHECK(s.nspheres == 1 && s.spheres[0].material == 1, "sphere lost its material");
        rt_scene_free(&s);
    }
}

static void test_bad_files(void)
{
    RtScene s;
    RtError e;
    CHECK(rt_scene_load("/nonexistent/dir/scene.txt", &s, NULL, NULL, &e) != 0, "missing file accepted");
    CHECK(strstr(e.msg, "/nonexistent/dir/scene.txt: cannot open") != NULL, "message '%s'", e.msg);
    CHECK(rt_scene_load("/tmp", &s, NULL, NULL, &e) != 0, "directory accepted");
    CHECK(strstr(e.msg, "not a regular file") != NULL, "message '%s'", e.msg);
}

static void test_camera_errors(void)
{
    expect_camera_error("\ncamera_fwd: 0 0 0\n", "t.txt:2:", "zero vector");
    expect_camera_error("camera_fwd: 0 1 0\ncamera_up: 0 2 0\n", "t.txt:2:", "parallel");
    expect_camera_error("camera_fwd: 0 1 0\n", "t.txt:1:", "parallel");
}

/* Seeded mutation fuzzing: random byte edits of a valid scene never crash
 * and either parse or fail with a file:line message. */
static void test_mutations(void)
{
    const char *base = "camera_pos: 0 0 5\nmaterial: .1 .1 .1 .5 .5 .5 .2 .2 .2 10 0 0 0 1\n"
                       "vertex: 0 0 0\nvertex: 1 0 0\nvertex: 0 1 0\nnormal: 0 0 1\n"
                       "triangle: 0 1 2\nnormal_triangle: 0 1 2 0 0 0\nsphere: 0 0 -1 .5\n"
                       "spot_light: 1 1 1 0 5 0 0 -1 0 10 20\nfilm_resolution: 8 8\n";
    unsigned long long seed = 0x9e3779b97f4a7c15ull;
    size_t len = strlen(base);
    char *buf = malloc(len + 64);
    const char alphabet[] = "0123456789.-+e: \n#abcxyz\t\r\"";
    int ok = 0, failed = 0, bad_msg = 0;
    for (int iter = 0; iter < 4000; iter++) {
        memcpy(buf, base, len + 1);
        int edits = 1 + (int)(check_rand(&seed) % 4);
        for (int k = 0; k < edits; k++) {
            size_t pos = (size_t)(check_rand(&seed) % len);
            buf[pos] = alphabet[check_rand(&seed) % (sizeof alphabet - 1)];
        }
        RtScene s;
        RtError e;
        warnings = 0;
        if (rt_scene_parse_buffer("m.txt", buf, len, &s, on_warn, NULL, &e) == 0) {
            ok++;
            RtCamera cam;
            if (rt_scene_camera(&s, &cam, &e) == 0) {
                RtAccel a;
                if (rt_accel_build(&s, RT_ACCEL_BVH, &a, &e) == 0) {
                    CHECK(rt_bvh_check(&a, &e) == 0, "%s", e.msg);
                    rt_accel_free(&a);
                }
            }
        } else {
            failed++;
            if (strncmp(e.msg, "m.txt:", 6) != 0)
                bad_msg++;
        }
        rt_scene_free(&s);
    }
    free(buf);
    CHECK(bad_msg == 0, "%d error messages without file:line", bad_msg);
    CHECK(ok > 0 && failed > 0, "mutations exercised both paths (ok %d, failed %d)", ok, failed);
}

int main(void)
{
    test_defaults();
    test_every_command();
    test_unknown_command_warns();
    test_no_capacity_hint();
    test_numbers();
    test_bad_input();
    test_opaque_ior_lenient();
    test_bad_files();
    test_camera_errors();
    test_mutations();
    return check_report("test_parser");
}
