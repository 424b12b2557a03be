/* compare.h: what `harness compare` found, computed once by compare.c and
 * formatted by each output: text and JSON (compare.c), the pull-request
 * summary in Markdown (compare_md.c). Private to those two files. */
#ifndef HX_COMPARE_H
#define HX_COMPARE_H

#include "hx.h"

typedef struct {
    double factor, alpha, min_ms;
    const char *unit;
    int fp_differs;
    int higher;      /* the metric is a rate: higher is better */
} CmpRule;

/* Which rule gave the verdict, so each printer knows which fields hold. */
typedef enum {
    CMP_NOTE,  /* a counter, a missing configuration, failed runs: note says it */
    CMP_SHORT, /* the base time is under --min-ms: raw_base, raw_new */
    CMP_TIME   /* the time rule: medians, ratios, interval, p, resolution */
} CmpKind;

/* One configuration's verdict: REGRESSION, IMPROVEMENT, no change,
 * INCONCLUSIVE (the samples cannot tell), or new. */
typedef struct {
    const char *verdict, *scene, *label;
    CmpKind kind;
    char *note;               /* CMP_NOTE's reason, else NULL */
    double base_median, new_median, ratio, p, min_ratio; /* p NAN: too few for the test */
    double ci_lo, ci_hi, mde; /* the ratio's 95% interval, the smallest detectable change */
    double tail_ratio;        /* the slowest tenth's ratio (10 samples a side), else NAN */
    long need;                /* repeats a side that would resolve the factor */
    size_t n_new, n_base;
    double raw_base, raw_new; /* render_ms medians (CMP_SHORT) */
    size_t busy[2], stolen[2], rows[2]; /* new, base: the noise the rows recorded */
} CmpVerdict;

typedef struct {
    CmpVerdict *v;
    size_t n, cap;
    int compared, regressions, improvements, inconclusive;
} CmpVerdicts;

/* The verdict's reason in words, appended to r: text's line after
 * "VERDICT scene label: " and JSON's "reason". */
void hx_cmp_reason(HxBuf *r, const CmpVerdict *v, const CmpRule *rule);

/* What the Markdown summary says beside the verdicts. */
typedef struct {
    const HxStudy *nw, *base;
    const char *metric;
    const HxStrList *notes;   /* what text prints as NOTE lines */
    const char *report_url;   /* NULL: no link */
} CmpMdInfo;

/* --format md: the pull-request summary (compare_md.c). */
void hx_cmp_print_md(FILE *o, const CmpVerdicts *vs, const CmpRule *rule, const CmpMdInfo *info);

#endif
