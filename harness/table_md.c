/* table_md.c: `harness table`'s default Markdown fits HX_MD_WIDTH columns
 * (docs/harness-table.md, "The default Markdown table"). A table that would be
 * wider gives up, in the order its columns' ranks say, one table per scene,
 * short forms, columns (--wide has them) and at last long names as codes,
 * and says under itself what it did; nothing is dropped silently. The cross
 * table goes in blocks of configurations, or transposed when that takes
 * fewer blocks. */
#include "table_md.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* The width of s as hx_fput_clean(md) prints it ('|' as "\|"), in bytes: a
 * UTF-8 name is never wider on the screen than counted. */
static size_t md_len(const char *s)
{
    size_t n = strlen(s);
    for (const char *p = s; (p = strchr(p, '|')) != NULL; p++)
        n++;
    return n;
}

static void put_clean(FILE *o, const char *s, size_t n)
{
    for (size_t i = 0; i < n; i++)
        fputc(hx_is_ctrl((unsigned char)s[i]) ? '?' : s[i], o);
}

void hx_md_para(FILE *o, const char *s)
{
    size_t col = 0;
    for (;;) {
        while (*s == ' ')
            s++;
        size_t n = strcspn(s, " ");
        if (!n)
            break;
        if (col && col + 1 + n > HX_MD_WIDTH) {
            fputc('\n', o);
            col = 0;
        } else if (col) {
            fputc(' ', o);
            col++;
        }
        while (col + n > HX_MD_WIDTH) { /* a word wider than a line (a path) */
            size_t k = HX_MD_WIDTH - col;
            put_clean(o, s, k);
            fputc('\n', o);
            s += k;
            n -= k;
            col = 0;
        }
        put_clean(o, s, n);
        col += n;
        s += n;
    }
    if (col)
        fputc('\n', o);
}

/* ---- configuration labels: long keys shortened, the same in every table ---- */

static const char *const key_long[] = {"mpi_schedule", "schedule", "resolution", "max_depth"};
static const char *const key_short[] = {"msched", "sched", "res", "depth"};
#define NKEYS (sizeof key_long / sizeof *key_long)

char *hx_md_label(const char *label, unsigned *used)
{
    HxBuf b = {0};
    hx_buf_put(&b, "");
    for (const char *p = label; *p;) {
        size_t n = strcspn(p, " "), k;
        for (k = 0; k < NKEYS; k++) {
            size_t kl = strlen(key_long[k]);
            if (n > kl && strncmp(p, key_long[k], kl) == 0 && p[kl] == '=')
                break;
        }
        if (k < NKEYS) {
            hx_buf_put(&b, key_short[k]);
            hx_buf_putn(&b, p + strlen(key_long[k]), n - strlen(key_long[k]));
            *used |= 1u << k;
        } else {
            hx_buf_putn(&b, p, n);
        }
        for (p += n; *p == ' '; p++)
            hx_buf_put(&b, " ");
    }
    return b.s;
}

void hx_md_keys_legend(FILE *o, unsigned used)
{
    if (!used)
        return;
    HxBuf b = {0};
    fputc('\n', o);
    hx_buf_put(&b, "Label keys:");
    for (size_t k = 0; k < NKEYS; k++)
        if (used >> k & 1)
            hx_buf_printf(&b, "%s %s = %s", b.len > 11 ? "," : "", key_short[k], key_long[k]);
    hx_buf_put(&b, ".");
    hx_md_para(o, b.s);
    hx_buf_free(&b);
}

/* ---- tables that give up columns to fit ---- */

void hx_md_init(HxMdTab *t, const char *title, const HxMdCol *cols, int ncol)
{
    memset(t, 0, sizeof *t);
    t->title = t->title_split = title;
    t->ncol = ncol;
    memcpy(t->col, cols, (size_t)ncol * sizeof *cols);
}

void hx_md_row(HxMdTab *t, const char *const *cells, const char *const *brief, const int *idx)
{
    if (t->nrows == t->cap) {
        t->cap = t->cap ? 2 * t->cap : 32;
        t->idx = hx_xrealloc(t->idx, t->cap * (size_t)t->ncol * sizeof *t->idx);
    }
    for (int c = 0; c < t->ncol; c++) {
        hx_strlist_push(&t->text, cells[c]);
        /* a short form that is not shorter is none: nothing to say under the table */
        hx_strlist_push(&t->brief, brief && brief[c] && strcmp(brief[c], cells[c]) ? brief[c] : "");
        t->idx[t->nrows * (size_t)t->ncol + (size_t)c] = idx ? idx[c] : -1;
    }
    t->nrows++;
}

/* What the layout gave up; bit c of a mask is column c. */
typedef struct {
    int split;
    unsigned hidden, shortened, coded;
} Lay;

static int shown(const HxMdTab *t, const Lay *l, int c)
{
    return !(l->hidden >> c & 1) && !(l->split && t->col[c].role == HX_MD_SCENE);
}

/* Cell r, c as laid out; code: room for a code. */
static const char *cell_at(const HxMdTab *t, const Lay *l, size_t r, int c, char code[24])
{
    size_t k = r * (size_t)t->ncol + (size_t)c;
    if ((l->coded >> c & 1) && t->idx[k] >= 0) {
        snprintf(code, 24, "%c%d", t->col[c].code, t->idx[k] + 1);
        return code;
    }
    if ((l->shortened >> c & 1) && t->brief.v[k][0])
        return t->brief.v[k];
    return t->text.v[k];
}

static const char *head_at(const HxMdTab *t, const Lay *l, int c)
{
    return (l->shortened >> c & 1) && t->col[c].head_short ? t->col[c].head_short : t->col[c].head;
}

static size_t tab_width(const HxMdTab *t, const Lay *l)
{
    size_t top = 1;
    char code[24];
    for (int c = 0; c < t->ncol; c++)
        top += shown(t, l, c) ? md_len(head_at(t, l, c)) + 3 : 0;
    for (size_t r = 0; r < t->nrows; r++) {
        size_t w = 1;
        for (int c = 0; c < t->ncol; c++)
            w += shown(t, l, c) ? md_len(cell_at(t, l, r, c, code)) + 3 : 0;
        top = w > top ? w : top;
    }
    return top;
}

/* Gives up (on) or takes back rank's steps. */
static void step(const HxMdTab *t, Lay *l, int rank, int on)
{
    for (int c = 0; c < t->ncol; c++) {
        unsigned bit = t->col[c].rank == rank ? 1u << c : 0;
        if (t->col[c].role == HX_MD_SCENE && bit)
            l->split = on;
        else if (t->col[c].role == HX_MD_SHORT)
            l->shortened = on ? l->shortened | bit : l->shortened & ~bit;
        else if (t->col[c].role == HX_MD_OPT)
            l->hidden = on ? l->hidden | bit : l->hidden & ~bit;
        else if (t->col[c].role == HX_MD_CODE)
            l->coded = on ? l->coded | bit : l->coded & ~bit;
    }
}

/* The fewest steps, in rank order, that make the table fit; then, the last
 * first, each earlier step taken back if the table still fits without it
 * (codes can make room for a column given up before them). */
static void layout(const HxMdTab *t, Lay *l)
{
    int last = 0, rank;
    memset(l, 0, sizeof *l);
    for (int c = 0; c < t->ncol; c++)
        last = t->col[c].rank > last ? t->col[c].rank : last;
    for (rank = 1; rank <= last && tab_width(t, l) > HX_MD_WIDTH; rank++)
        step(t, l, rank, 1);
    for (int r = rank - 2; r >= 1; r--) {
        step(t, l, r, 0);
        if (tab_width(t, l) > HX_MD_WIDTH)
            step(t, l, r, 1);
    }
}

static void put_cells(FILE *o, const char *const *v, size_t n)
{
    fputc('|', o);
    for (size_t i = 0; i < n; i++) {
        fputc(' ', o);
        hx_fput_clean(o, v[i], 1);
        fputs(" |", o);
    }
    fputc('\n', o);
}

static void put_head(FILE *o, const HxMdTab *t, const Lay *l)
{
    const char *v[HX_MD_MAXCOL];
    size_t n = 0;
    for (int c = 0; c < t->ncol; c++)
        if (shown(t, l, c))
            v[n++] = head_at(t, l, c);
    put_cells(o, v, n);
    fputc('|', o);
    for (size_t i = 0; i < n; i++)
        fputs("---|", o);
    fputc('\n', o);
}

static void put_row(FILE *o, const HxMdTab *t, const Lay *l, size_t r)
{
    const char *v[HX_MD_MAXCOL];
    char code[HX_MD_MAXCOL][24];
    size_t n = 0;
    for (int c = 0; c < t->ncol; c++)
        if (shown(t, l, c))
            v[n++] = cell_at(t, l, r, c, code[c]);
    put_cells(o, v, n);
}

/* "CODE = name" for the legend, each code once and on a line of its own
 * (a control character in the name as '?': only the '\n's put here break
 * lines, in put_lines). */
static void name_code(HxStrList *seen, HxBuf *b, const char *code, const char *name)
{
    if (hx_strlist_find(seen, code) >= 0)
        return;
    hx_strlist_push(seen, code);
    hx_buf_printf(b, "%s%s = ", b->len ? ";\n" : "Codes: ", code);
    for (const char *p = name; *p; p++)
        hx_buf_putn(b, hx_is_ctrl((unsigned char)*p) ? "?" : p, 1);
}

/* hx_md_para of each line of text. */
static void put_lines(FILE *o, const char *text)
{
    char *copy = hx_strdup(text), *line = copy;
    for (char *nl; (nl = strchr(line, '\n')) != NULL; line = nl + 1) {
        *nl = '\0';
        hx_md_para(o, line);
    }
    hx_md_para(o, line);
    free(copy);
}

static int scene_col(const HxMdTab *t)
{
    int sc = 0;
    while (sc < t->ncol && t->col[sc].role != HX_MD_SCENE)
        sc++;
    return sc;
}

/* Whether every row's scene is "-" (a command study's): its one table keeps
 * the whole title, with no "scene -". */
static int unnamed(const HxMdTab *t)
{
    int sc = scene_col(t);
    for (size_t r = 0; sc < t->ncol && r < t->nrows; r++)
        if (strcmp(t->text.v[r * (size_t)t->ncol + (size_t)sc], "-") != 0)
            return 0;
    return 1;
}

/* One table per scene, in the order the scenes come; a name too long for
 * the title goes there as its code. */
static void put_split(FILE *o, const HxMdTab *t, const Lay *l, HxStrList *seen, HxBuf *names)
{
    int sc = scene_col(t);
    char *done = calloc(t->nrows ? t->nrows : 1, 1);
    for (size_t r = 0; r < t->nrows; r++) {
        if (done[r])
            continue;
        const char *name = t->text.v[r * (size_t)t->ncol + (size_t)sc];
        char code[24];
        snprintf(code, sizeof code, "%c%d", t->col[sc].code, t->idx[r * (size_t)t->ncol + (size_t)sc] + 1);
        if (unnamed(t)) {
            fprintf(o, "\n### %s", t->title);
        } else if (4 + strlen(t->title_split) + 8 + strlen(name) <= HX_MD_WIDTH) {
            fprintf(o, "\n### %s, scene ", t->title_split);
            put_clean(o, name, strlen(name));
        } else {
            fprintf(o, "\n### %s, scene %s", t->title_split, code);
            name_code(seen, names, code, name);
        }
        fputs("\n\n", o);
        put_head(o, t, l);
        for (size_t q = r; q < t->nrows; q++) {
            if (!done[q] && strcmp(t->text.v[q * (size_t)t->ncol + (size_t)sc], name) == 0) {
                put_row(o, t, l, q);
                done[q] = 1;
            }
        }
    }
    free(done);
}

static int has_brief(const HxMdTab *t, int c)
{
    for (size_t r = 0; r < t->nrows; r++)
        if (t->brief.v[r * (size_t)t->ncol + (size_t)c][0])
            return 1;
    return 0;
}

/* Under the table: its own lines, the codes, and what only --wide has. */
static void put_legend(FILE *o, const HxMdTab *t, const Lay *l, HxStrList *seen, HxBuf *names)
{
    char code[24];
    for (size_t r = 0; r < t->nrows; r++)
        for (int c = 0; c < t->ncol; c++)
            if ((l->coded >> c & 1) && t->idx[r * (size_t)t->ncol + (size_t)c] >= 0)
                name_code(seen, names, cell_at(t, l, r, c, code), t->text.v[r * (size_t)t->ncol + (size_t)c]);
    HxBuf w = {0};
    if (t->wide)
        hx_buf_put(&w, t->wide);
    for (int c = 0; c < t->ncol; c++)
        if (((l->hidden >> c & 1) || ((l->shortened >> c & 1) && has_brief(t, c))) && t->col[c].wide)
            hx_buf_printf(&w, "%s%s", w.len ? ", " : "", t->col[c].wide);
    HxStrList all = {0}; /* the title's rest first, what --wide has last */
    if (l->split && t->split_note && !unnamed(t))
        hx_strlist_push(&all, t->split_note);
    for (size_t i = 0; i < t->legend.n; i++)
        hx_strlist_push(&all, t->legend.v[i]);
    if (names->len)
        hx_strlist_push(&all, names->s); /* its lines: put_lines */
    if (w.len) {
        HxBuf line = {0};
        hx_buf_printf(&line, "(--wide for %s)", w.s);
        hx_strlist_push(&all, line.s);
        hx_buf_free(&line);
    }
    hx_buf_free(&w);
    if (all.n)
        fputc('\n', o);
    for (size_t i = 0; i < all.n; i++)
        put_lines(o, all.v[i]);
    hx_strlist_free(&all);
}

void hx_md_free(HxMdTab *t)
{
    hx_strlist_free(&t->text);
    hx_strlist_free(&t->brief);
    hx_strlist_free(&t->legend);
    free(t->idx);
}

void hx_md_print(FILE *o, HxMdTab *t)
{
    Lay l;
    layout(t, &l);
    HxStrList seen = {0};
    HxBuf names = {0};
    if (l.split) {
        put_split(o, t, &l, &seen, &names);
    } else {
        fprintf(o, "\n### %s\n\n", t->title);
        put_head(o, t, &l);
        for (size_t r = 0; r < t->nrows; r++)
            put_row(o, t, &l, r);
    }
    put_legend(o, t, &l, &seen, &names);
    hx_strlist_free(&seen);
    hx_buf_free(&names);
    hx_md_free(t);
}

/* ---- the scenes x configurations table ---- */

typedef struct {
    const HxStrList *sc, *lb;
    char *const *cell;
    int tr, code_keys, code_heads; /* transposed: a row per configuration */
} Cross;

static size_t nkeys(const Cross *x)
{
    return x->tr ? x->lb->n : x->sc->n;
}

static size_t nheads(const Cross *x)
{
    return x->tr ? x->sc->n : x->lb->n;
}

/* Row key i or column heading j (head), a code when coded. */
static const char *xname(const Cross *x, int head, size_t i, char code[24])
{
    int scene = head == x->tr; /* rows are scenes unless transposed */
    if (head ? x->code_heads : x->code_keys) {
        snprintf(code, 24, "%c%zu", scene ? 'S' : 'C', i + 1);
        return code;
    }
    return (scene ? x->sc : x->lb)->v[i];
}

static const char *xval(const Cross *x, size_t i, size_t j)
{
    return x->tr ? x->cell[j * x->lb->n + i] : x->cell[i * x->lb->n + j];
}

static size_t key_width(const Cross *x)
{
    char code[24];
    size_t w = strlen(x->tr ? "configuration" : "scene");
    for (size_t i = 0; i < nkeys(x); i++) {
        size_t n = md_len(xname(x, 0, i, code));
        w = n > w ? n : w;
    }
    return w;
}

static size_t col_width(const Cross *x, size_t j)
{
    char code[24];
    size_t w = md_len(xname(x, 1, j, code));
    for (size_t i = 0; i < nkeys(x); i++) {
        size_t n = md_len(xval(x, i, j));
        w = n > w ? n : w;
    }
    return w;
}

/* The columns in blocks that fit: start[b] is block b's first; their
 * number, or 0 when a column does not fit beside the keys at all. */
static size_t cross_blocks(const Cross *x, size_t *start)
{
    size_t kw = 1 + key_width(x) + 3, nb = 0, w = 0;
    for (size_t j = 0; j < nheads(x); j++) {
        size_t cw = col_width(x, j) + 3;
        if (kw + cw > HX_MD_WIDTH)
            return 0;
        if (!nb || w + cw > HX_MD_WIDTH) {
            start[nb++] = j;
            w = kw;
        }
        w += cw;
    }
    return nb;
}

/* Names (scenes as rows) first, then transposed; codes only when no
 * layout with names fits. The fewest blocks win. */
static size_t cross_layout(Cross *x, size_t *start)
{
    size_t best = 0, cost = (size_t)-1;
    int pick = 6;
    for (int v = 0; v < 8; v++) {
        x->tr = v & 1;
        x->code_keys = v >> 1 & 1;
        x->code_heads = v >> 2 & 1;
        size_t nb = cross_blocks(x, start);
        size_t c = nb + 1000 * (size_t)(x->code_keys + x->code_heads);
        if (nb && c < cost) {
            cost = c;
            pick = v;
        }
    }
    x->tr = pick & 1;
    x->code_keys = pick >> 1 & 1;
    x->code_heads = pick >> 2 & 1;
    best = cross_blocks(x, start);
    if (!best) { /* cells too wide for any layout: one table, as wide as it is */
        start[0] = 0;
        best = 1;
    }
    return best;
}

static void cross_block(FILE *o, const Cross *x, size_t from, size_t to)
{
    size_t n = to - from + 1;
    const char **v = hx_xmalloc((n + 1) * sizeof *v);
    char(*code)[24] = hx_xmalloc((n + 1) * sizeof *code);
    v[0] = x->tr ? "configuration" : "scene";
    for (size_t j = from; j < to; j++)
        v[j - from + 1] = xname(x, 1, j, code[j - from]);
    fputc('\n', o);
    put_cells(o, v, n);
    fputc('|', o);
    for (size_t j = 0; j < n; j++)
        fputs("---|", o);
    fputc('\n', o);
    for (size_t i = 0; i < nkeys(x); i++) {
        v[0] = xname(x, 0, i, code[n]);
        for (size_t j = from; j < to; j++)
            v[j - from + 1] = xval(x, i, j);
        put_cells(o, v, n);
    }
    free(code);
    free(v);
}

void hx_md_cross(FILE *o, const char *note, const HxStrList *scenes, const HxStrList *labels, char *const *cell)
{
    Cross x = {scenes, labels, cell, 0, 0, 0};
    size_t *start = hx_xmalloc((scenes->n + labels->n + 1) * sizeof *start);
    size_t nb = cross_layout(&x, start);
    fprintf(o, "\n### Scenes x configurations%s (%s)\n", x.tr ? ", transposed" : "", note);
    HxBuf b = {0};
    if (x.tr)
        hx_buf_put(&b, "A row per configuration, a column per scene.");
    if (nb > 1)
        hx_buf_printf(&b, "%s%s in %zu tables of at most %d columns (--wide: one table).", b.len ? " " : "",
                      x.tr ? "Scenes" : "Configurations", nb, HX_MD_WIDTH);
    if (b.len) {
        fputc('\n', o);
        hx_md_para(o, b.s);
    }
    for (size_t k = 0; k < nb; k++)
        cross_block(o, &x, start[k], k + 1 < nb ? start[k + 1] : nheads(&x));
    b.len = 0;
    HxStrList seen = {0};
    Cross y = x; /* the same, with names */
    y.code_keys = y.code_heads = 0;
    for (int head = 0; head < 2; head++) {
        char code[24], unused[24];
        for (size_t i = 0; (head ? x.code_heads : x.code_keys) && i < (head ? nheads(&x) : nkeys(&x)); i++)
            name_code(&seen, &b, xname(&x, head, i, code), xname(&y, head, i, unused));
    }
    if (b.len) {
        fputc('\n', o);
        put_lines(o, b.s);
    }
    hx_strlist_free(&seen);
    hx_buf_free(&b);
    free(start);
}

/* ---- the default Markdown's tables of a study ---- */

static const char *const nc_text[NC_N] = {
    "Tn = n runs timed out (TLE)", "Wn = n wrong images", "STATUS:n = n runs failed with that status",
    "OS = oversubscribed, left out of the fits", "NP = pinning did not hold, left out of the fits",
    "Pk/n = pinning partial in k of n runs", "Bk/n = busy machine in k of n runs",
    "CSk/n M% = CPU steal in k of n runs, up to M% of all CPU time", ">1 = efficiency above 1", "On = n outliers", "<1 = slower than 1 worker"};
static const char *const fc_text[FC_N] = {
    "I = implausible: serial fraction outside [0, 1]", "U = uncertain: std. error above the value",
    "Ln = n suspect samples left out", "no fit = too few points once they are left out"};

/* "Notes: CODE meaning; ..." for the codes used, else nothing. */
static void codes_legend(HxStrList *legend, const char *const *text, int n, unsigned used)
{
    if (!used)
        return;
    HxBuf b = {0};
    hx_buf_put(&b, "Notes:");
    for (int i = 0, first = 1; i < n; i++) {
        if (used >> i & 1) {
            hx_buf_printf(&b, "%s %s", first ? "" : ";", text[i]);
            first = 0;
        }
    }
    hx_buf_put(&b, ".");
    hx_strlist_push(legend, b.s);
    hx_buf_free(&b);
}

void hx_md_configs(FILE *o, const HxStudy *s, const char *baseline)
{
    UnitHeads h;
    tab_unit_heads(s, &h);
    const HxMdCol cols[8] = {
        {"scene", HX_MD_SCENE, 1, NULL, NULL, 'S'}, {"configuration", HX_MD_CODE, 5, NULL, NULL, 'C'},
        {"n", HX_MD_KEEP, 0, NULL, NULL, 0}, {h.med, HX_MD_KEEP, 0, NULL, NULL, 0},
        {"S(a) [CI]", HX_MD_SHORT, 2, "S(a)", "the CI of S(a)", 0},
        {"E(a)", HX_MD_SHORT, 4, NULL, "E(a)'s share of the ceiling", 0}, {"S(b)", HX_MD_OPT, 3, NULL, "S(b)", 0},
        {"notes", HX_MD_KEEP, 0, NULL, NULL, 0}};
    /* a size: its ratio to 1 worker in place of the speedup columns */
    const HxMdCol size_cols[6] = {cols[0], cols[1], cols[2], cols[3], {"x 1 worker", HX_MD_KEEP, 0, NULL, NULL, 0},
                                  cols[7]};
    HxMdTab t;
    hx_md_init(&t, "Per configuration", s->size ? size_cols : cols, s->size ? 6 : 8);
    unsigned used = 0, keys = 0;
    for (size_t i = 0; i < s->ng; i++) {
        ConfigStats c;
        tab_config_stats(s, &s->g[i], baseline, &c);
        Cells k;
        tab_common_cells(s, &c, &k);
        SpeedCells p;
        tab_speed_cells(&c, &p);
        char r[32], *lab = hx_md_label(c.g->label, &keys);
        tab_fmt_num(r, sizeof r, "%.2f", c.ratio);
        const char *notes = c.codes[0] ? c.codes : "-";
        const int idx[8] = {hx_strlist_find(&s->scenes, c.g->scene), hx_strlist_find(&s->labels, c.g->label),
                            -1, -1, -1, -1, -1, -1};
        const char *sized[6] = {c.g->scene, lab, k.n, k.medc, r, notes};
        const char *cells[8] = {c.g->scene, lab, k.n, k.medc, p.spc, p.ef, p.sb, notes};
        const char *brief[8] = {NULL, NULL, NULL, NULL, p.sps, p.efb, NULL, NULL};
        hx_md_row(&t, s->size ? sized : cells, s->size ? NULL : brief, idx);
        used |= c.used;
        free(lab);
    }
    if (s->size) {
        hx_strlist_push(&t.legend, "CI: 95% bootstrap interval. x 1 worker: the median over the same series' "
                                   "median at 1 worker.");
        t.wide = "workers, min, IQR, outliers, the median at 1 worker, the notes in words";
    } else {
        hx_strlist_push(&t.legend, "CI: 95% bootstrap interval. S(a), E(a): speedup and efficiency against (a) "
                                   "the same series at 1 worker; S(b): speedup against baseline (b).");
        t.wide = s->higher ? "workers, max, IQR, outliers, T(1), Karp-Flatt, baseline (b) and its value, "
                             "efficiency (b), the notes in words"
                           : "workers, min, IQR, outliers, T(1), Karp-Flatt, baseline (b) and its time, "
                             "efficiency (b), the notes in words";
    }
    codes_legend(&t.legend, nc_text, NC_N, used);
    hx_md_print(o, &t);
}

void hx_md_fits(FILE *o, const HxStudy *s, int include_suspect)
{
    size_t n;
    Fit *fits = tab_collect_fits(s, include_suspect, &n);
    char ah[48], bh[48];
    const char *u = s->unit[0] ? s->unit : "-";
    snprintf(ah, sizeof ah, s->higher ? "a (1/%s)" : "a %s", u); /* a rate is fitted as 1/rate */
    snprintf(bh, sizeof bh, s->higher ? "b (1/%s)" : "b %s", u);
    const HxMdCol cols[9] = {
        {"scene", HX_MD_SCENE, 1, NULL, NULL, 'S'}, {"series", HX_MD_CODE, 5, NULL, NULL, 'R'},
        {"sweep", HX_MD_KEEP, 0, NULL, NULL, 0}, {"points", HX_MD_KEEP, 0, NULL, NULL, 0},
        {"serial fraction", HX_MD_KEEP, 0, NULL, NULL, 0}, {"std. error", HX_MD_KEEP, 0, NULL, NULL, 0},
        {ah, HX_MD_OPT, 2, NULL, "a", 0}, {bh, HX_MD_OPT, 2, NULL, "b", 0}, {"note", HX_MD_KEEP, 0, NULL, NULL, 0}};
    HxMdTab t;
    hx_md_init(&t, "Amdahl fit T(p) = a + b/p per series (least squares over all samples)", cols, 9);
    t.title_split = "Amdahl fit";
    t.split_note = "Amdahl fit: T(p) = a + b/p per series, least squares over all samples.";
    HxStrList series = {0};
    unsigned used = 0, keys = 0;
    for (size_t i = 0; i < n; i++) {
        const Fit *f = &fits[i];
        char pts[16], fs[32], se[32], as[32], bs[32], *lab = hx_md_label(f->series, &keys);
        snprintf(pts, sizeof pts, "%zu", f->np);
        tab_fmt_num(fs, sizeof fs, "%.4f", f->f.serial_fraction);
        tab_fmt_num(se, sizeof se, "%.4f", f->f.has_se ? f->f.se_serial_fraction : NAN);
        tab_fmt_ms(as, sizeof as, f->f.a);
        tab_fmt_ms(bs, sizeof bs, f->f.b);
        if (hx_strlist_find(&series, lab) < 0)
            hx_strlist_push(&series, lab);
        const int idx[9] = {hx_strlist_find(&s->scenes, f->scene), hx_strlist_find(&series, lab), -1, -1, -1, -1,
                            -1, -1, -1};
        const char *cells[9] = {f->scene, lab, f->sweep, pts, fs, se, as, bs, f->code};
        hx_md_row(&t, cells, NULL, idx);
        used |= f->used;
        free(lab);
    }
    codes_legend(&t.legend, fc_text, FC_N, used);
    if (n)
        hx_md_print(o, &t);
    else
        hx_md_free(&t);
    hx_strlist_free(&series);
    tab_fits_free(fits, n);
}

void hx_md_cross_study(FILE *o, const HxStudy *s)
{
    size_t ns = s->scenes.n, nl = s->labels.n;
    char **cell = hx_xmalloc((ns * nl + 1) * sizeof *cell);
    for (size_t i = 0; i < ns * nl; i++) {
        cell[i] = hx_xmalloc(32);
        snprintf(cell[i], 32, "-");
    }
    for (size_t i = 0; i < s->ng; i++) {
        int sc = hx_strlist_find(&s->scenes, s->g[i].scene), l = hx_strlist_find(&s->labels, s->g[i].label);
        if (sc >= 0 && l >= 0)
            tab_cross_cell(&s->g[i], cell[(size_t)sc * nl + (size_t)l], 32);
    }
    HxStrList labels = {0};
    unsigned keys = 0;
    for (size_t l = 0; l < nl; l++) {
        char *a = hx_md_label(s->labels.v[l], &keys);
        hx_strlist_push(&labels, a);
        free(a);
    }
    char note[64];
    snprintf(note, sizeof note, "median %s; TLE = timed out", s->size ? s->unit : "ms");
    hx_md_cross(o, note, &s->scenes, &labels, cell);
    for (size_t i = 0; i < ns * nl; i++)
        free(cell[i]);
    free(cell);
    hx_strlist_free(&labels);
}
