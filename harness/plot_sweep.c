/* plot_sweep.c: plots of what a study sweeps besides its workers.
 *
 * PREFIX-blocks: CUDA block sizes as a heatmap of block width by height,
 * one panel per scene and configuration, the best cell framed. A line per
 * configuration over an arbitrary order of blocks hid the shape (wide and
 * flat against square) that the choice depends on.
 * PREFIX-sweep: the metric against a swept size (a numeric param of a
 * command study, or the resolution in pixels) on log-log axes, where a
 * power law is a straight line. */
#include "hx.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* "SCENE LABEL-without-KEY", or the label alone in a command study. */
static char *series_name(const HxGroup *g, const char *key)
{
    char *lab = hx_label_drop(g->label, key);
    HxBuf t = {0};
    if (strcmp(g->scene, "-") != 0)
        hx_buf_printf(&t, "%s ", g->scene);
    hx_buf_put(&t, lab);
    free(lab);
    return t.s;
}

/* Each ok group's series name for KEY (NULL for the others), made once per
 * plot: panels and lines look them up per group. */
static char **group_names(const HxStudy *s, const char *key)
{
    char **name = calloc(s->ng + 1, sizeof *name);
    for (size_t i = 0; i < s->ng; i++)
        name[i] = s->g[i].nt ? series_name(&s->g[i], key) : NULL;
    return name;
}

static void names_free(char **name, size_t n)
{
    for (size_t i = 0; i < n; i++)
        free(name[i]);
    free(name);
}

/* A block "WxH" (or "W") as width and height; 0 when it is none. */
static int block_dims(const char *b, int *w, int *h)
{
    char *end;
    long x = strtol(b, &end, 10), y = 1;
    if (end == b || x <= 0)
        return 0;
    if (*end == 'x')
        y = strtol(end + 1, &end, 10);
    if (*end || y <= 0)
        return 0;
    *w = (int)x;
    *h = (int)y;
    return 1;
}

static int cmp_int(const void *a, const void *b)
{
    return (*(const int *)a > *(const int *)b) - (*(const int *)a < *(const int *)b);
}

/* v added to the sorted set xs of n (capacity of the study's groups). */
static void set_add(int *xs, int *n, int v)
{
    for (int i = 0; i < *n; i++)
        if (xs[i] == v)
            return;
    xs[(*n)++] = v;
    qsort(xs, *n, sizeof *xs, cmp_int);
}

static int index_of(const int *xs, int n, int v)
{
    for (int i = 0; i < n; i++)
        if (xs[i] == v)
            return i;
    return -1;
}

/* One panel: its cells into dat (block k), its gnuplot commands into body. */
static void heat_panel(const HxStudy *s, char *const *names, const char *series, const int *ws, int nw,
                       const int *hs, int nh, const HxPlot *c, FILE *dat, int k, HxBuf *body)
{
    const HxGroup *best = NULL;
    fprintf(dat, "# panel %d: width_index height_index median q1 q3 width height\n", k);
    for (size_t i = 0; i < s->ng; i++) {
        const HxGroup *g = &s->g[i];
        int w, h;
        if (names[i] && block_dims(g->block, &w, &h) && strcmp(names[i], series) == 0) {
            fprintf(dat, "%d %d %.6g %.6g %.6g %d %d\n", index_of(ws, nw, w), index_of(hs, nh, h), g->median, g->q1,
                    g->q3, w, h);
            if (!best || (s->higher ? g->median > best->median : g->median < best->median))
                best = g;
        }
    }
    fprintf(dat, "\n\n");
    int bw = 0, bh = 0;
    block_dims(best->block, &bw, &bh);
    HxBuf t = {0};
    hx_buf_printf(&t, "%s: best %s, %.3g %s", series, best->block, best->median, s->unit);
    hx_buf_put(body, "unset object\n");
    hx_buf_printf(body, "set object 1 rect from %g,%g to %g,%g front fillstyle empty border lc rgb 'black' lw 3\n",
                  index_of(ws, nw, bw) - 0.5, index_of(hs, nh, bh) - 0.5, index_of(ws, nw, bw) + 0.5,
                  index_of(hs, nh, bh) + 0.5);
    HxBuf q = {0}, f = {0};
    hx_gp_quote(&q, t.s);
    hx_buf_printf(&f, "%s-blocks.dat", c->base);
    hx_buf_printf(body, "set title %s\n", q.s);
    q.len = 0;
    hx_gp_quote(&q, f.s);
    hx_buf_printf(body, "plot %s index %d using 1:2:(0.5):(0.5):3 with boxxyerror fillstyle solid 1.0 noborder "
                        "lc palette notitle, \\\n     %s index %d using 1:2:(sprintf('%%.3g', $3)) with labels "
                        "font ',7' notitle\n", q.s, k, q.s, k);
    hx_buf_free(&q);
    hx_buf_free(&f);
    hx_buf_free(&t);
}

/* The shared axes: every width and height seen, at even spacing. */
static void heat_axes(HxBuf *body, const int *ws, int nw, const int *hs, int nh, const HxStudy *s)
{
    hx_buf_printf(body, "set xrange [-0.5:%g]\nset yrange [-0.5:%g]\nset xtics (", nw - 0.5, nh - 0.5);
    for (int i = 0; i < nw; i++)
        hx_buf_printf(body, "%s'%d' %d", i ? ", " : "", ws[i], i);
    hx_buf_put(body, ")\nset ytics (");
    for (int i = 0; i < nh; i++)
        hx_buf_printf(body, "%s'%d' %d", i ? ", " : "", hs[i], i);
    hx_buf_put(body, ")\nset xlabel 'block width (threads)'\nset ylabel 'block height'\nunset grid\n");
    /* green is good: low for a time, high for a rate; each panel its own
     * colour range, since scenes differ by orders of magnitude */
    hx_buf_printf(body, "set palette defined (0 '%s', 0.5 '#ffffbf', 1 '%s')\nset cbrange [*:*]\n",
                  s->higher ? "#d73027" : "#1a9850", s->higher ? "#1a9850" : "#d73027");
}

void hx_plot_blocks(HxPlot *c, const HxStudy *s)
{
    HxStrList series = {0};
    char **names = group_names(s, "B");
    int *ws = calloc(s->ng + 1, sizeof *ws), *hs = calloc(s->ng + 1, sizeof *hs), nw = 0, nh = 0;
    for (size_t i = 0; i < s->ng; i++) {
        int w, h;
        if (!names[i] || !block_dims(s->g[i].block, &w, &h))
            continue;
        set_add(ws, &nw, w);
        set_add(hs, &nh, h);
        if (hx_strlist_find(&series, names[i]) < 0)
            hx_strlist_push(&series, names[i]);
    }
    FILE *dat = NULL, *gp = series.n ? hx_plot_open(c, "blocks", &dat) : NULL;
    if (!series.n)
        printf("(no block-size sweep in this study: blocks plot left out)\n");
    else if (!gp)
        c->failures++;
    if (gp) {
        int cols = series.n < 4 ? (int)series.n : 4, rows = (int)((series.n + cols - 1) / cols);
        HxBuf body = {0}, t = {0};
        heat_axes(&body, ws, nw, hs, nh, s);
        for (size_t k = 0; k < series.n; k++)
            heat_panel(s, names, series.v[k], ws, nw, hs, nh, c, dat, (int)k, &body);
        HxBuf what = {0};
        hx_buf_printf(&what, "median %s (%s) by CUDA block width x height, best cell framed", s->metric,
                      s->unit[0] ? s->unit : "-");
        hx_plot_title(&t, s, what.s, NULL);
        hx_buf_free(&what);
        hx_plot_multi(gp, c, "blocks", t.s, rows, cols, body.s, 480 * cols, 360 * rows + 60);
        hx_buf_free(&body);
        hx_buf_free(&t);
        hx_plot_finish(c, "blocks", gp, dat);
    }
    free(ws);
    free(hs);
    names_free(names, s->ng);
    hx_strlist_free(&series);
}

/* Group g's value of the swept size KEY: a param's number, or the
 * resolution's pixels ("WxH"); 0 when it has none. */
static double size_value(const HxStudy *s, const HxGroup *g, const char *key)
{
    char v[128];
    if (strcmp(key, "resolution") == 0) {
        int w, h;
        return block_dims(hx_csv_get(&s->csv, g->ok_row, "resolution"), &w, &h) ? (double)w * h : 0;
    }
    if (!hx_kv_get(hx_csv_get(&s->csv, g->ok_row, "params"), key, v, sizeof v))
        return 0;
    char *end;
    double x = strtod(v, &end);
    return end != v && !*end && x > 0 && isfinite(x) ? x : 0;
}

/* The first size the study sweeps: a param whose values are all positive
 * numbers and differ, else the resolution; 0 when there is none. */
static int swept_size(const HxStudy *s, char *key, size_t n)
{
    const char *p = s->csv.nrows ? hx_csv_get(&s->csv, 0, "params") : "";
    for (;;) {
        size_t len = strcspn(p, ";"), k = strcspn(p, "=");
        if (k < len) {
            snprintf(key, n, "%.*s", (int)k, p);
            double first = 0;
            int numeric = 1, differ = 0;
            for (size_t i = 0; i < s->ng && numeric; i++) {
                if (!s->g[i].nt)
                    continue;
                double x = size_value(s, &s->g[i], key);
                numeric = x > 0;
                differ |= first > 0 && x != first;
                first = first > 0 ? first : x;
            }
            if (numeric && differ)
                return 1;
        }
        if (!p[len])
            break;
        p += len + 1;
    }
    snprintf(key, n, "resolution");
    double first = 0;
    for (size_t i = 0; i < s->ng; i++) {
        double x = s->g[i].nt ? size_value(s, &s->g[i], key) : 0;
        if (s->g[i].nt && x <= 0)
            return 0;
        if (x > 0 && first > 0 && x != first)
            return 1;
        first = first > 0 ? first : x;
    }
    return 0;
}

/* One series' points over the size (xs: each group's), in increasing
 * order, into pts; how many. */
static int sweep_points(const HxStudy *s, char *const *names, const double *xs, const char *series, HxBuf *pts,
                        const HxGroup **one)
{
    int n = 0;
    for (double last = 0;; n++) {
        const HxGroup *next = NULL;
        double nx = 0;
        for (size_t i = 0; i < s->ng; i++) {
            if (names[i] && xs[i] > last && (!next || xs[i] < nx) && strcmp(names[i], series) == 0) {
                next = &s->g[i];
                nx = xs[i];
            }
        }
        if (!next)
            break;
        hx_buf_printf(pts, "%.6g %.6g %.6g %.6g\n", nx, next->median, next->q1, next->q3);
        *one = next;
        last = nx;
    }
    return n;
}

void hx_plot_sweep(HxPlot *c, const HxStudy *s)
{
    char key[96];
    if (!swept_size(s, key, sizeof key)) {
        printf("(no size swept in this study: sweep plot left out)\n");
        return;
    }
    FILE *dat, *gp = hx_plot_open(c, "sweep", &dat);
    if (!gp) {
        c->failures++;
        return;
    }
    fprintf(dat, "# %s median q1 q3 (%s, %s); one block per series, the last the one-configuration ones\n", key,
            s->metric, s->unit);
    HxStrList series = {0}, titles = {0};
    HxBuf singles = {0};
    char **names = group_names(s, key);
    double *xs = calloc(s->ng + 1, sizeof *xs);
    for (size_t i = 0; i < s->ng; i++)
        xs[i] = names[i] ? size_value(s, &s->g[i], key) : 0;
    for (size_t i = 0; i < s->ng; i++) {
        const char *name = names[i];
        if (name && hx_strlist_find(&series, name) < 0) {
            hx_strlist_push(&series, name);
            HxBuf pts = {0};
            const HxGroup *one = NULL;
            if (sweep_points(s, names, xs, name, &pts, &one) >= 2) {
                fprintf(dat, "%s\n\n", pts.s);
                hx_strlist_push(&titles, name);
            } else if (one) {
                char lab[256];
                hx_plot_clean_label(lab, sizeof lab, name);
                hx_buf_printf(&singles, "%.6g %.6g %.6g %.6g \"%s\"\n", xs[one - s->g], one->median, one->q1,
                              one->q3, lab);
            }
            hx_buf_free(&pts);
        }
    }
    if (singles.len)
        fprintf(dat, "%s\n\n", singles.s);
    HxBuf t = {0}, title = {0};
    size_t nseries = titles.n;
    hx_buf_printf(&t, "%s against %s (median; bars: quartiles)", s->metric, key);
    hx_plot_title(&title, s, t.s, &titles);
    hx_plot_head(gp, c, "sweep", title.s);
    t.len = 0;
    hx_buf_printf(&t, "%s%s (log scale)", key, strcmp(key, "resolution") == 0 ? " in pixels" : "");
    hx_plot_put(gp, "set xlabel %s\nset logscale xy\n", t.s);
    /* ranges that hold the data, with 1-2-5 tics: decades alone leave a
     * two-fold sweep with no tic at all */
    double xlo = INFINITY, xhi = 0, ylo = INFINITY, yhi = 0;
    for (size_t i = 0; i < s->ng; i++) {
        double x = xs[i];
        if (x > 0 && s->g[i].q1 > 0) {
            xlo = fmin(xlo, x), xhi = fmax(xhi, x);
            ylo = fmin(ylo, s->g[i].q1), yhi = fmax(yhi, s->g[i].q3);
        }
    }
    if (xhi > 0) {
        fprintf(gp, "set xrange [%g:%g]\nset yrange [%g:%g]\n", xlo / 1.3, xhi * 1.3, ylo / 1.3, yhi * 1.3);
        hx_plot_log_tics(gp, "x", xlo, xhi);
        hx_plot_log_tics(gp, "y", ylo, yhi);
    }
    t.len = 0;
    hx_buf_printf(&t, "median %s (%s, log scale)", s->metric, s->unit[0] ? s->unit : "-");
    hx_plot_put(gp, "set ylabel %s\nplot ", t.s);
    for (size_t k = 0; k < nseries; k++) {
        hx_plot_file(gp, "%s", c->base, "sweep", "dat");
        fprintf(gp, " index %zu using 1:2:3:4 with yerrorlines pt 7 title ", k);
        hx_plot_put(gp, k + 1 < nseries || singles.len ? "%s, \\\n     " : "%s\n", titles.v[k]);
    }
    if (singles.len)
        hx_plot_markers(gp, c, "sweep", (int)nseries, 1);
    hx_plot_tail(gp, c, "sweep");
    hx_plot_finish(c, "sweep", gp, dat);
    hx_buf_free(&t);
    hx_buf_free(&title);
    hx_buf_free(&singles);
    hx_strlist_free(&series);
    hx_strlist_free(&titles);
    names_free(names, s->ng);
    free(xs);
}
