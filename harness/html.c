/* html.c: what the HTML writers (harness report, harness history publish)
 * share: the inline stylesheet, the output folder's check, SVG files inlined
 * and pages written whole. Pages are self-contained: no script, nothing
 * fetched, so they read the same from a file, offline. */
#include "hx.h"

#include <dirent.h>
#include <errno.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

const char *const hx_html_css =
    "body{font-family:sans-serif;max-width:72rem;margin:1rem auto;padding:0 1rem;color:#222}"
    "table{border-collapse:collapse;margin:.5rem 0;font-size:.85rem}"
    "th,td{border:1px solid #bbb;padding:.2rem .45rem;text-align:left}th{background:#eee}"
    "tr:nth-child(even) td{background:#f8f8f8}.warn{color:#a40000;font-weight:bold}"
    ".ok{color:#1a6d1a}figure{margin:1rem 0}figure svg{max-width:100%;height:auto}"
    "h2{border-bottom:2px solid #444;margin-top:2.5rem}.note{color:#555;font-size:.9rem}";

static int dir_empty(const char *dir)
{
    DIR *d = opendir(dir);
    struct dirent *e;
    int empty = d != NULL;
    while (d && empty && (e = readdir(d)) != NULL)
        empty = strcmp(e->d_name, ".") == 0 || strcmp(e->d_name, "..") == 0;
    if (d)
        closedir(d);
    return empty;
}

int hx_html_dir(const char *who, const char *dir, const char *mark_text)
{
    HxBuf mark = {0};
    hx_buf_printf(&mark, "%s/" HX_HTML_MARK, dir);
    int rc = 0;
    if (mkdir(dir, 0755) != 0 && errno != EEXIST) {
        fprintf(stderr, "%s: %s: %s\n", who, dir, strerror(errno));
        rc = -1;
    } else if (errno == EEXIST && !hx_is_dir(dir)) {
        fprintf(stderr, "%s: %s exists and is not a folder: refused\n", who, dir);
        rc = -1;
    } else if (!hx_file_exists(mark.s) && !dir_empty(dir)) {
        /* someone's own folder: never overwritten */
        fprintf(stderr, "%s: %s exists and is not a report or dashboard (no %s in it): refused, nothing written\n",
                who, dir, HX_HTML_MARK);
        rc = -1;
    } else {
        FILE *f = fopen(mark.s, "w");
        rc = f && fprintf(f, "%s\n", mark_text) >= 0 ? 0 : -1;
        if (f && fclose(f) != 0)
            rc = -1;
        if (rc)
            fprintf(stderr, "%s: %s: cannot write\n", who, mark.s);
    }
    hx_buf_free(&mark);
    return rc;
}

int hx_html_svg_file(FILE *o, const char *path, const char *caption)
{
    HxBuf t = {0};
    if (hx_read_file(path, &t) != 0 || !t.s) {
        hx_buf_free(&t);
        return 0;
    }
    const char *svg = strstr(t.s, "<svg");
    if (svg) {
        fputs("<figure>", o);
        fputs(svg, o);
        fputs("<figcaption>", o);
        hx_html_put(o, caption);
        fputs("</figcaption></figure>\n", o);
    }
    hx_buf_free(&t);
    return svg != NULL;
}

FILE *hx_html_open(HxHtmlPage *pg, const char *path, const char *title)
{
    const char *slash = strrchr(path, '/');
    size_t dn = slash ? (size_t)(slash - path) + 1 : 0;
    memset(pg, 0, sizeof *pg);
    pg->path = hx_strdup(path);
    HxBuf part = {0};
    /* hidden, beside the page: the rename that publishes it stays in one
     * file system */
    hx_buf_printf(&part, "%.*s.%s.part", (int)dn, path, path + dn);
    pg->part = part.s;
    pg->f = fopen(pg->part, "w");
    if (pg->f) {
        fputs("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>", pg->f);
        hx_html_put(pg->f, title);
        fprintf(pg->f, "</title><style>%s</style></head><body>\n", hx_html_css);
    }
    return pg->f;
}

int hx_html_close(HxHtmlPage *pg, const char *who, int ok)
{
    int rc = ok && pg->f ? 0 : -1;
    if (pg->f) {
        fputs("</body></html>\n", pg->f);
        if (fclose(pg->f) != 0)
            rc = -1;
    }
    pg->f = NULL;
    if (rc == 0 && rename(pg->part, pg->path) != 0)
        rc = -1;
    if (rc != 0) {
        unlink(pg->part);
        fprintf(stderr, "%s: %s not written\n", who, pg->path);
    }
    free(pg->path);
    free(pg->part);
    pg->path = pg->part = NULL;
    return rc;
}
