/* report.c: `harness report CSV... -o DIR`: one self-contained HTML page
 * per call, a section per study: provenance, the pinning map, noise and
 * failure flags, `table`'s tables and `plot`'s plots inlined as SVG, and a
 * link to each CSV copied beside the page. No script, no stylesheet or font
 * fetched: the page reads the same from a file, offline. Every string from
 * a CSV goes through hx_html_put, so a scene named "<script>" is text. */
#include "hx.h"

#include <fcntl.h>
#include <getopt.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static void usage_report(FILE *f)
{
    fputs("usage: harness report CSV... -o DIR [--metric COLUMN] [--ceiling FILE]\n"
          "Writes DIR/index.html: one self-contained page (inline SVG plots and CSS, no\n"
          "script, nothing fetched) with a section per study: provenance, pinning map,\n"
          "noise and failure flags, the tables and plots, and a link to its CSV (copied\n"
          "into DIR). DIR must be new, empty, or a report or dashboard written before.\n"
          "  -o, --output DIR   the report's folder\n"
          "  --metric COLUMN    as for table and plot\n"
          "  --ceiling FILE     the machine's ceiling (harness ceiling)\n", f);
}

/* One provenance row: the distinct values of column col. */
static void prov_row(FILE *o, const HxCsv *c, const char *label, const char *col)
{
    HxStrList seen = {0};
    for (size_t r = 0; r < c->nrows; r++) {
        const char *v = hx_csv_get(c, r, col);
        if (*v && hx_strlist_find(&seen, v) < 0)
            hx_strlist_push(&seen, v);
    }
    fprintf(o, "<tr><th>%s</th><td>", label);
    for (size_t i = 0; i < seen.n; i++) {
        if (i)
            fputs("; ", o);
        hx_html_put(o, seen.v[i]);
    }
    fputs(seen.n ? "</td></tr>\n" : "-</td></tr>\n", o);
    hx_strlist_free(&seen);
}

static void provenance(FILE *o, const HxCsv *c)
{
    static const char *const rows[][2] = {
        {"commit", "git_commit"},   {"host", "host"},           {"CPU", "cpu_model"},
        {"cores", "phys_cores"},    {"CPUs", "logical_cpus"},   {"SMT", "smt"},
        {"governor", "governor"},   {"compiler", "compiler"},   {"build flags", "build_flags"},
        {"GPU", "gpu_name"},        {"GPU driver", "gpu_driver"}, {"MPI", "mpi_version"},
        {"kernel", "kernel"},       {"program version", "program_version"},
        {"machine fingerprint", "fingerprint"}};
    fputs("<h3>Provenance</h3>\n<table><tbody>\n", o);
    for (size_t i = 0; i < sizeof rows / sizeof rows[0]; i++)
        if (hx_csv_col(c, rows[i][1]) >= 0)
            prov_row(o, c, rows[i][0], rows[i][1]);
    if (c->nrows) {
        fputs("<tr><th>runs from</th><td>", o);
        hx_html_put(o, hx_csv_get(c, 0, "utc"));
        fputs(" to ", o);
        hx_html_put(o, hx_csv_get(c, c->nrows - 1, "utc"));
        fputs("</td></tr>\n", o);
    }
    fputs("</tbody></table>\n", o);
}

/* Counts of column col's values over the rows of configuration id (NULL: all). */
static void count_values(const HxCsv *c, const char *id, const char *col, HxStrList *vals, int *n)
{
    for (size_t r = 0; r < c->nrows; r++) {
        const char *run = hx_csv_get(c, r, "run_id");
        if (id && (strncmp(run, id, strlen(id)) != 0 || strncmp(run + strlen(id), " #r", 3) != 0))
            continue;
        const char *v = hx_csv_get(c, r, col);
        size_t k = 0;
        while (k < vals->n && strcmp(vals->v[k], v) != 0)
            k++;
        if (k == vals->n)
            hx_strlist_push(vals, v);
        n[k]++;
    }
}

static void put_counts(FILE *o, const HxStrList *vals, const int *n, const char *good)
{
    for (size_t k = 0; k < vals->n; k++) {
        const char *v = vals->v[k];
        int none = !*v || strcmp(v, "-") == 0;
        int bad = good && (*good ? strcmp(v, good) != 0 : !none);
        fprintf(o, "%s<span class=\"%s\">", k ? ", " : "", bad ? "warn" : "ok");
        hx_html_put(o, none ? (good && !*good ? "none" : "-") : v);
        fprintf(o, " &times;%d</span>", n[k]);
    }
}

/* What happened to the runs: status, pinning and noise, counted. */
static void flags(FILE *o, const HxCsv *c)
{
    static const char *const cols[][3] = {{"status", "status", "ok"}, {"pinning held", "pin_held", "yes"},
                                          {"noise", "noise", ""}};
    fputs("<h3>Runs, pinning and noise</h3>\n<table><tbody>\n", o);
    for (size_t i = 0; i < 3; i++) {
        if (hx_csv_col(c, cols[i][1]) < 0)
            continue;
        HxStrList vals = {0};
        int *n = calloc(c->nrows + 1, sizeof *n);
        count_values(c, NULL, cols[i][1], &vals, n);
        fprintf(o, "<tr><th>%s</th><td>", cols[i][0]);
        put_counts(o, &vals, n, cols[i][2]);
        fputs("</td></tr>\n", o);
        free(n);
        hx_strlist_free(&vals);
    }
    fputs("</tbody></table>\n", o);
}

/* Whether every run of the CSV held its pinning (or was not pinned). */
static int all_held(const HxCsv *c)
{
    for (size_t r = 0; r < c->nrows; r++) {
        const char *h = hx_csv_get(c, r, "pin_held");
        if (*h && strcmp(h, "yes") != 0 && strcmp(h, "-") != 0)
            return 0;
    }
    return 1;
}

/* The pinning map: per configuration the cores planned, those its runs were
 * seen on and whether the pinning held. Folded (<details>, no script) when
 * every run held, so a sweep of 85 configurations does not bury the plots. */
static void pinning_map(FILE *o, const HxCsv *c)
{
    int held = all_held(c);
    fprintf(o, "<details%s><summary><b>Pinning map</b>: %s</summary>\n", held ? "" : " open",
            held ? "every run's pinning held" : "some runs' pinning did not hold (marked in red)");
    fputs("<table><thead><tr><th>configuration</th><th>cores planned</th>"
          "<th>cores used</th><th>pinning held</th></tr></thead><tbody>\n", o);
    HxStrList ids = {0};
    for (size_t r = 0; r < c->nrows; r++) {
        char id[1024];
        snprintf(id, sizeof id, "%s", hx_csv_get(c, r, "run_id"));
        char *cut = strstr(id, " #r");
        if (cut)
            *cut = '\0';
        if (hx_strlist_find(&ids, id) >= 0)
            continue;
        hx_strlist_push(&ids, id);
        HxStrList used = {0}, held = {0};
        int *nu = calloc(c->nrows + 1, sizeof *nu), *nh = calloc(c->nrows + 1, sizeof *nh);
        count_values(c, id, "cores_actual", &used, nu);
        count_values(c, id, "pin_held", &held, nh);
        char lab[1024];
        hx_config_label(lab, sizeof lab, id);
        fputs("<tr><td>", o);
        hx_html_put(o, lab);
        fputs("</td><td>", o);
        hx_html_put(o, hx_csv_get(c, r, "cores_planned"));
        fputs("</td><td>", o);
        put_counts(o, &used, nu, NULL);
        fputs("</td><td>", o);
        put_counts(o, &held, nh, "yes");
        fputs("</td></tr>\n", o);
        free(nu);
        free(nh);
        hx_strlist_free(&used);
        hx_strlist_free(&held);
    }
    hx_strlist_free(&ids);
    fputs("</tbody></table></details>\n", o);
}

/* The CSV copied into the report as NAME.csv (the page links it). 0 or -1. */
static int copy_csv(const char *src, const char *dst)
{
    HxBuf t = {0};
    int rc = hx_read_file(src, &t);
    FILE *f = rc == 0 ? fopen(dst, "w") : NULL;
    rc = f && (!t.len || fwrite(t.s, 1, t.len, f) == t.len) ? 0 : -1;
    if (f && fclose(f) != 0)
        rc = -1;
    hx_buf_free(&t);
    return rc;
}

/* The study's plots (harness plot into DIR/NAME-*), inlined. */
static void plots(FILE *o, const char *dir, const char *name, const char *csv, const char *metric,
                  const char *ceiling)
{
    static const char *const kinds[][2] = {{"speedup", "Speedup against one worker, with the ideal line"},
                                           {"efficiency", "Parallel efficiency, with the machine's ceiling where measured"},
                                           {"size", "The metric against workers"},
                                           {"sweep", "The metric against the swept parameter, log axes"},
                                           {"blocks", "Median time by CUDA block width x height, one heatmap per "
                                                      "scene, best cell marked"},
                                           {"scenes", "Median per scene and configuration"}};
    HxBuf prefix = {0};
    hx_buf_printf(&prefix, "%s/%s", dir, name);
    const char *argv[10] = {"plot", csv, "-o", prefix.s};
    int argc = 4;
    if (metric) {
        argv[argc++] = "--metric";
        argv[argc++] = metric;
    }
    if (ceiling) {
        argv[argc++] = "--ceiling";
        argv[argc++] = ceiling;
    }
    /* plot's list of the files it wrote is not the report's output */
    fflush(stdout);
    int saved = dup(STDOUT_FILENO), null = open("/dev/null", O_WRONLY);
    if (null >= 0)
        dup2(null, STDOUT_FILENO);
    optind = 1;
    hx_cmd_plot(argc, (char **)argv);
    fflush(stdout);
    if (saved >= 0)
        dup2(saved, STDOUT_FILENO);
    if (saved >= 0)
        close(saved);
    if (null >= 0)
        close(null);
    int n = 0;
    fputs("<h3>Plots</h3>\n", o);
    for (size_t i = 0; i < sizeof kinds / sizeof kinds[0]; i++) {
        HxBuf svg = {0};
        hx_buf_printf(&svg, "%s-%s.svg", prefix.s, kinds[i][0]);
        n += hx_html_svg_file(o, svg.s, kinds[i][1]);
        hx_buf_free(&svg);
    }
    if (!n)
        fputs("<p class=\"warn\">No plot: gnuplot is missing, or nothing could be drawn.</p>\n", o);
    hx_buf_free(&prefix);
}

/* One study's section; 0, or -1 when its CSV could not be read (said). */
static int section(FILE *o, const char *dir, const char *csv, int idx, const char *metric, const char *ceiling)
{
    HxStudy s;
    if (hx_study_open("harness report", csv, metric, &s))
        return -1;
    if (hx_ceiling_load(&s, "harness report", ceiling, csv) != 0) {
        hx_study_free(&s);
        return -1;
    }
    const char *study = s.csv.nrows ? hx_csv_get(&s.csv, 0, "study") : "";
    HxBuf name = {0}, copy = {0};
    hx_buf_printf(&name, "study%d", idx);
    hx_buf_printf(&copy, "%s/%s.csv", dir, name.s);
    int rc = copy_csv(csv, copy.s);
    if (rc)
        fprintf(stderr, "harness report: %s: cannot write\n", copy.s);
    fputs("<section><h2>Study ", o);
    hx_html_put(o, *study ? study : csv);
    fprintf(o, "</h2>\n<p>Metric <b>");
    hx_html_put(o, s.metric);
    fprintf(o, "</b>%s; %zu rows; the CSV: <a href=\"%s.csv\">%s.csv</a> (from ", s.higher ? " (higher is better)" : "",
            s.csv.nrows, name.s, name.s);
    hx_html_put(o, csv);
    fputs(").</p>\n", o);
    flags(o, &s.csv);
    size_t ok = 0;
    for (size_t i = 0; i < s.ng; i++)
        ok += s.g[i].nt;
    if (ok == 0) {
        fputs("<p class=\"warn\">No ok rows: nothing to tabulate or plot (the flags above say what happened to "
              "the runs).</p>\n", o);
    } else {
        const char *base = s.csv.nrows && *hx_csv_get(&s.csv, 0, "baseline") ? hx_csv_get(&s.csv, 0, "baseline")
                                                                             : "backend=serial";
        /* the picture first, then the numbers, then where they came from */
        plots(o, dir, name.s, csv, metric, s.ceil_path);
        hx_table_html(o, &s, base);
    }
    provenance(o, &s.csv);
    pinning_map(o, &s.csv);
    fputs("</section>\n", o);
    hx_buf_free(&name);
    hx_buf_free(&copy);
    hx_study_free(&s);
    return rc;
}

int hx_cmd_report(int argc, char **argv)
{
    static const struct option lo[] = {{"output", required_argument, NULL, 'o'},
                                       {"metric", required_argument, NULL, 'm'},
                                       {"ceiling", required_argument, NULL, 'c'},
                                       {"help", no_argument, NULL, 'h'},
                                       {NULL, 0, NULL, 0}};
    const char *dir = NULL, *metric = NULL, *ceiling = NULL;
    int c;
    while ((c = getopt_long(argc, argv, "o:h", lo, NULL)) != -1) {
        switch (c) {
        case 'o': dir = optarg; break;
        case 'm': metric = optarg; break;
        case 'c': ceiling = optarg; break;
        case 'h': usage_report(stdout); return 0;
        default: usage_report(stderr); return 1;
        }
    }
    if (optind >= argc || !dir) {
        fprintf(stderr, "harness report: expected CSV... and -o DIR (see --help)\n");
        return 1;
    }
    int first = optind;
    for (int i = first; i < argc; i++)
        if (!hx_file_exists(argv[i])) {
            fprintf(stderr, "harness report: %s: no such file\n", argv[i]);
            return 1;
        }
    if (hx_html_dir("harness report", dir, "written by harness report") != 0)
        return 1;
    HxBuf page = {0};
    hx_buf_printf(&page, "%s/index.html", dir);
    HxHtmlPage pg;
    FILE *o = hx_html_open(&pg, page.s, "raybench report");
    int rc = o ? 0 : -1;
    if (o) {
        fputs("<h1>raybench report</h1>\n", o);
        for (int i = first; i < argc && rc == 0; i++)
            rc = section(o, dir, argv[i], i - first + 1, metric, ceiling);
        fputs("<p>Written by <code>harness report</code> (docs/harness-table.md, \"Reports\").</p>\n", o);
    }
    rc = hx_html_close(&pg, "harness report", rc == 0);
    if (rc == 0)
        printf("harness report: wrote %s\n", page.s);
    hx_buf_free(&page);
    return rc ? 1 : 0;
}
