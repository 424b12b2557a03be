/* ceiling.h: W one-worker copies of a study's workload, run at once and
 * against one alone (ceiling_copies.c), for `harness ceiling` and for
 * `ceiling: rounds` (ceiling.c). */
#ifndef HX_CEILING_H
#define HX_CEILING_H

#include "run.h"

#include <stdio.h>

/* What a copy is measured by: the metric `table` reads the study by
 * (study.c's default_metric), so the ceiling and the efficiency against it
 * are ratios of the same thing. A copy's wall time would add its start, its
 * load and its writes, which scale otherwise: 40% of a 512x384 copy of the
 * dragon. */
typedef struct {
    const char *name; /* render_ms, a command study's first metric, or wall_ms */
    int higher;       /* a rate: the ratio is together / alone */
    double ms;        /* one unit in ms where it is a time, else 0 */
} HxCeilMetric;

HxCeilMetric hx_ceil_metric(const HxConfig *cfg);

/* n copies of one workload, ready to run. */
typedef struct {
    const HxConfig *cfg;
    HxCommand *c;
    int n;
    char **dir;      /* each copy's run folder (command studies), else NULL */
    const char *tmp; /* the copies' outputs */
    HxCeilMetric m;
    double pre; /* raytrace: how long the last copy alone took to reach its render, ms; 0 unknown */
} HxCopies;

/* Where a ceiling row belongs. */
typedef struct {
    const HxFingerprint *fp;
    const char *config, *scene;
    int round;      /* ceiling: rounds, else -1 */
    int name_scene; /* the W= line names the scene (the plan has several) */
} HxCeilKey;

#define HX_CEIL_HEADER                                                                                          \
    "fingerprint,host,workers,repeats,ratio_median,ratio_min,ratio_max,alone,config,metric,steal_pct,overlap,"      \
    "together,step,step_ms,round,scene\n"

/* n copies of the one-worker run one into cp: outputs in tmp, a command
 * study's folders (set up) in workdir. 0, or -1 with a line on stderr. */
int hx_copies_build(HxCopies *cp, const HxConfig *cfg, const HxTopo *t, const HxRun *one, const char *rt,
                    const char *tmp, const char *workdir, int n);
void hx_copies_free(HxCopies *cp);
/* w copies on cores, repeats times, each with a step after it: one line on
 * say (unless NULL), one CSV row into b. 0, or -1 when a copy or the step
 * failed or a stop signal came. */
int hx_copies_measure(HxCopies *cp, const HxTopo *t, int w, const int *cores, int repeats, const HxCeilKey *key,
                      FILE *say, HxBuf *b);

#endif
