/* output.c - where a run may write, checked before it renders, and its
 * messages as a terminal should see them. */
#include <errno.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "config.h"
#include "rt.h"

/* Writes one message line to stderr with every byte a terminal could act
 * on escaped: control characters and bytes that are not UTF-8 (a scene or
 * model's text quoted in a message) as \xNN. */
void rt_say(const char *msg)
{
    const unsigned char *c = (const unsigned char *)msg;
    while (*c) {
        int n = *c < 0x80 ? 1 : (*c & 0xe0) == 0xc0 && *c >= 0xc2 ? 2 : (*c & 0xf0) == 0xe0 ? 3
              : (*c & 0xf8) == 0xf0 && *c <= 0xf4 ? 4 : 0;
        for (int k = 1; k < n; k++)
            if ((c[k] & 0xc0) != 0x80)
                n = 0;
        if (n == 1 && (*c < 0x20 || *c == 0x7f))
            n = 0;
        if (n == 0) {
            fprintf(stderr, "\\x%02x", *c++);
        } else {
            fwrite(c, 1, (size_t)n, stderr);
            c += n;
        }
    }
    fputc('\n', stderr);
}


/* The directory of the output must be writable: checked before rendering, so
 * a long render never ends in a write error. */
int rt_output_check(const char *path, RtError *err)
{
    if (rt_image_format_for(path) == RT_IMG_UNKNOWN)
        return rt_fail(err, "%s: unknown image format (use .png, .bmp or .ppm)", path);
#if !HAVE_PNG
    if (rt_image_format_for(path) == RT_IMG_PNG)
        return rt_fail(err, "%s: this build has no libpng: write .bmp or .ppm", path);
#endif
    char dir[4096];
    snprintf(dir, sizeof dir, "%s", path);
    char *slash = strrchr(dir, '/');
    if (slash == dir)
        dir[1] = '\0';
    else if (slash)
        *slash = '\0';
    else
        snprintf(dir, sizeof dir, ".");
    struct stat st;
    if (stat(path, &st) == 0 && S_ISDIR(st.st_mode))
        return rt_fail(err, "%s: is a directory", path);
    if (access(dir, W_OK) != 0)
        return rt_fail(err, "%s: cannot write into directory '%s': %s", path, dir, strerror(errno));
    return 0;
}

/* Whether `inner` is the folder `outer` or lies inside it (both resolved). */
static int path_within(const char *inner, const char *outer)
{
    const size_t n = strlen(outer);
    return strncmp(inner, outer, n) == 0 && (inner[n] == '\0' || inner[n] == '/' || (n == 1 && outer[0] == '/'));
}

/* A scene's own output_image stays in the working folder: a scene someone
 * sent must not overwrite a file elsewhere (-o is the user's own choice).
 * Relative, no "..", and its folder, links resolved, inside this one. */
int rt_scene_output_check(const char *out, RtError *err)
{
    if (out[0] == '/')
        return rt_fail(err, "'%s' is an absolute path: a scene writes only into the working folder (use -o)", out);
    for (const char *c = out; *c; c = strchr(c, '/') ? strchr(c, '/') + 1 : c + strlen(c))
        if (c[0] == '.' && c[1] == '.' && (c[2] == '/' || c[2] == '\0'))
            return rt_fail(err, "'%s' leaves the working folder: a scene writes only into it (use -o)", out);
    char dir[4096], real_dir[PATH_MAX], real_cwd[PATH_MAX];
    snprintf(dir, sizeof dir, "%s", out);
    char *slash = strrchr(dir, '/');
    if (!slash)
        return 0;
    *slash = '\0';
    if (!realpath(dir, real_dir) || !realpath(".", real_cwd))
        return rt_fail(err, "'%s': cannot resolve its folder: %s", out, strerror(errno));
    if (!path_within(real_dir, real_cwd))
        return rt_fail(err, "'%s' leads out of the working folder through a link (use -o)", out);
    return 0;
}

