/* table_md.h: the default Markdown form of `harness table`, laid out so that
 * no line is wider than HX_MD_WIDTH (table_md.c). Private to table*.c. */
#ifndef TABLE_MD_H
#define TABLE_MD_H

#include "hx.h"

#define HX_MD_WIDTH 100
#define HX_MD_MAXCOL 12

/* What a column gives up while a line is too wide, lowest rank first; every
 * step says under the table what it did, so nothing is lost silently. */
enum {
    HX_MD_KEEP,  /* nothing */
    HX_MD_SCENE, /* one table per scene, the scene named in its title */
    HX_MD_SHORT, /* its cells' short form; the rest is in --wide */
    HX_MD_OPT,   /* left out; in --wide */
    HX_MD_CODE,  /* names as codes (S1, C2) explained under the table */
};

typedef struct {
    const char *head;
    int role, rank;         /* HX_MD_*; the order of giving up */
    const char *head_short; /* HX_MD_SHORT: the short form's heading */
    const char *wide;       /* what only --wide then shows */
    char code;              /* HX_MD_SCENE, HX_MD_CODE: the codes' letter */
} HxMdCol;

typedef struct {
    const char *title, *title_split; /* title_split: "..., scene NAME" */
    const char *split_note;          /* said under split tables (title's rest) */
    int ncol;
    HxMdCol col[HX_MD_MAXCOL];
    HxStrList text, brief;  /* cells, row by row; brief: short form or "" */
    int *idx;               /* per cell: the name's index for its code, or -1 */
    size_t nrows, cap;
    HxStrList legend;       /* lines under the table, each wrapped */
    const char *wide;       /* the columns only --wide has in any case */
} HxMdTab;

void hx_md_init(HxMdTab *t, const char *title, const HxMdCol *cols, int ncol);
/* One row: ncol cells, their short forms (NULL: none) and name indexes
 * (NULL: none, else -1 where a cell has no code). */
void hx_md_row(HxMdTab *t, const char *const *cells, const char *const *brief, const int *idx);
/* Lays the table out to fit, prints it with its legend, and frees it. */
void hx_md_print(FILE *o, HxMdTab *t);
void hx_md_free(HxMdTab *t);
/* Prose wrapped at HX_MD_WIDTH (a word longer than that is cut); control
 * characters as '?'. */
void hx_md_para(FILE *o, const char *text);
/* The scenes x configurations table, cell[scene * labels->n + label]: in
 * blocks of configurations that fit, transposed when that takes fewer. */
void hx_md_cross(FILE *o, const char *title, const HxStrList *scenes, const HxStrList *labels,
                 char *const *cell);
/* A configuration label with long keys shortened (schedule= -> sched=),
 * malloc'd; *used collects which (hx_md_keys_legend). */
char *hx_md_label(const char *label, unsigned *used);
void hx_md_keys_legend(FILE *o, unsigned used);

/* ---- shared by table.c (statistics, HTML, CSV, --wide, JSON) and the
 * default Markdown's tables (table_md.c) ---- */

/* The notes' short codes (bits of ConfigStats.used, Fit.used). */
enum { NC_TLE, NC_WRONG, NC_FAIL, NC_OVER, NC_UNPIN, NC_PARTIAL, NC_BUSY, NC_STEAL, NC_EFF, NC_OUT, NC_SLOW, NC_N };
enum { FC_IMPL, FC_UNCERTAIN, FC_LEFT, FC_NOFIT, FC_N };

/* What one configuration's row says, computed once for every format. */
typedef struct {
    const HxGroup *g, *a, *b;
    double spa, spa_lo, spa_hi, efa, kf, spb, efb;
    double ceil;         /* the machine's ceiling at these workers, NAN none */
    double pace;         /* this run against that many copies at once, NAN none */
    double step;         /* the best pace W workers' steps keep there (syncstep.c), NAN none */
    double ratio;        /* a size: median / the one-worker median (a) */
    char notes[256];
    char codes[160];     /* the notes as codes (default Markdown) */
    unsigned used;       /* which codes: 1 << NC_* */
} ConfigStats;

/* The headers that carry the metric's unit; a rate's best is its maximum. */
typedef struct {
    char med[48], min[40], iqr[40], t1[40], bt[40];
} UnitHeads;

/* The cells every metric's row has; medc: the interval compact. */
typedef struct {
    char w[16], n[32], med[112], medc[112], mn[32], iqr[32], out[16], t1[32];
} Cells;

/* A time's or rate's speedup cells: sp with its interval (spc compact, sps
 * none), ef with the ceiling (efs without; efb with the pace alone where
 * known, else efs: the default Markdown's short form). */
typedef struct {
    char sp[112], spc[112], sps[32], ef[80], efs[32], efb[48], kf[32], bt[32], sb[32], eb[32];
} SpeedCells;

/* One Amdahl fit over a series' samples (table.c's fit_series). */
typedef struct {
    HxAmdahl f;
    size_t np, left_out;
    int distinct;
    char note[128];
    char code[48];       /* the note as codes */
    unsigned used;       /* 1 << FC_* */
    const char *scene, *sweep;
    char *series; /* malloc'd */
} Fit;

void tab_fmt_ms(char *b, size_t n, double v);
void tab_fmt_num(char *b, size_t n, const char *f, double v);
void tab_config_stats(const HxStudy *s, const HxGroup *g, const char *baseline, ConfigStats *c);
void tab_unit_heads(const HxStudy *s, UnitHeads *h);
void tab_common_cells(const HxStudy *s, const ConfigStats *c, Cells *k);
void tab_speed_cells(const ConfigStats *c, SpeedCells *p);
Fit *tab_collect_fits(const HxStudy *s, int include_suspect, size_t *n);
void tab_fits_free(Fit *fits, size_t n);
/* The cross table's cell of group g (a median, TLE, wrong-image, a status). */
void tab_cross_cell(const HxGroup *g, char *b, size_t n);

/* The default Markdown's tables (table_md.c). */
void hx_md_configs(FILE *o, const HxStudy *s, const char *baseline);
void hx_md_fits(FILE *o, const HxStudy *s, int include_suspect);
void hx_md_cross_study(FILE *o, const HxStudy *s);

#endif
