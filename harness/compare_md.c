/* compare_md.c: `harness compare --format md`, the regression check as a
 * pull-request comment: the verdict on its first line, then what changed,
 * one screen long whatever the number of configurations. It formats the
 * verdicts compare.c computed (compare.h) and computes nothing of its own.
 * A comment is rendered as HTML, so every string from a CSV is escaped: a
 * scene named "<img ...>" or "a|b" stays text inside its cell. */
#include "compare.h"
#include "hx.h"

#include <math.h>
#include <string.h>

/* Table rows at most: with the verdict line, the header, the line for the
 * rest, the legend, the notes and the link, the comment stays under 30
 * lines. */
#define MD_ROWS 15

/* The table's order: what needs a look first, "no change" last. */
static const char *const md_order[] = {"REGRESSION", "INCONCLUSIVE", "IMPROVEMENT", "new", "no change"};
/* The same in words, for counts (regressions and improvements take an s) */
static const char *const md_word[] = {"regression", "inconclusive", "improvement", "new", "no change"};
#define MD_NORDER 5
#define MD_NOCHANGE 4

static int md_rank(const char *verdict)
{
    for (int k = 0; k < MD_NORDER; k++)
        if (strcmp(verdict, md_order[k]) == 0)
            return k;
    return 0; /* unknown: shown first rather than hidden */
}

/* Text from a CSV as Markdown text: & < > as entities (never HTML), the
 * characters of inline markup backslash-escaped (| would end the table
 * cell, ` open code, [ a link, $ math), control characters (a newline would
 * end the row) as blanks. */
static void md_put(FILE *o, const char *s)
{
    for (const unsigned char *p = (const unsigned char *)(s ? s : ""); *p; p++) {
        const char one[2] = {(char)*p, '\0'};
        if (strchr("&<>", *p))
            hx_html_put(o, one);
        else if (strchr("\\`*_[]|~$", *p))
            fprintf(o, "\\%c", *p);
        else
            fputc(hx_is_ctrl(*p) ? ' ' : *p, o);
    }
}

/* The --report URL as a link destination: whatever could end the link or
 * the line or read as markup (blanks, control characters, ( ) < > " ' `
 * \ [ ] | { } ^, non-ASCII) percent-encoded; the rest verbatim, % included,
 * so an already encoded URL stays as it was. */
static void md_url(FILE *o, const char *u)
{
    for (const unsigned char *p = (const unsigned char *)u; *p; p++) {
        if (*p <= 0x20 || *p >= 0x7f || strchr("()<>\"'`\\[]|{}^", *p))
            fprintf(o, "%%%02X", *p);
        else
            fputc(*p, o);
    }
}

/* The distinct values of col in s ("-" and empty left out). */
static void md_distinct(const HxStudy *s, const char *col, HxStrList *out)
{
    for (size_t r = 0; r < s->csv.nrows; r++) {
        const char *v = hx_csv_get(&s->csv, r, col);
        if (*v && strcmp(v, "-") != 0 && hx_strlist_find(out, v) < 0)
            hx_strlist_push(out, v);
    }
}

/* "a", "a, b" or "a, b and N more" (a CSV of many commits must not make
 * the first line a page); "unknown" when empty. */
static void md_put_list(FILE *o, const HxStrList *l)
{
    if (!l->n)
        fputs("unknown", o);
    for (size_t i = 0; i < l->n && i < 2; i++) {
        fputs(i ? ", " : "", o);
        md_put(o, l->v[i]);
    }
    if (l->n > 2)
        fprintf(o, " and %zu more", l->n - 2);
}

static int md_same(const HxStrList *a, const HxStrList *b)
{
    int same = a->n == b->n;
    for (size_t i = 0; i < a->n && same; i++)
        same = hx_strlist_find(b, a->v[i]) >= 0;
    return same;
}

/* Where the numbers come from: each side's study and commit, the machine
 * in words (its CPU model, not the fingerprint hash). */
static void md_provenance(FILE *o, const CmpMdInfo *in)
{
    HxStrList l[2][3] = {{{0}}}; /* [new, base][study, git_commit, cpu_model] */
    static const char *const cols[] = {"study", "git_commit", "cpu_model"};
    for (int k = 0; k < 3; k++) {
        md_distinct(in->nw, cols[k], &l[0][k]);
        md_distinct(in->base, cols[k], &l[1][k]);
    }
    int one_machine = md_same(&l[0][2], &l[1][2]);
    for (int side = 0; side < 2; side++) {
        fputs(side ? "; base: study " : "new: study ", o);
        md_put_list(o, &l[side][0]);
        fputs(", commit ", o);
        md_put_list(o, &l[side][1]);
        if (!one_machine) {
            fputs(", machine ", o);
            md_put_list(o, &l[side][2]);
        }
    }
    if (one_machine) {
        fputs("; machine: ", o);
        md_put_list(o, &l[0][2]);
    }
    for (int side = 0; side < 2; side++)
        for (int k = 0; k < 3; k++)
            hx_strlist_free(&l[side][k]);
}

/* The first line: the verdict as the exit status gives it, the counts, what
 * was compared at which factor, and where. */
static void md_headline(FILE *o, const CmpVerdicts *vs, const int *count, const CmpRule *rule,
                        const CmpMdInfo *in)
{
    int reg = vs->regressions, imp = vs->improvements;
    fputs(reg ? "**FAIL**: " : "**PASS**: ", o);
    if (reg)
        fprintf(o, "**%d regression%s**", reg, reg == 1 ? "" : "s");
    else
        fputs("0 regressions", o);
    fprintf(o, ", %d improvement%s, %d no change, %d inconclusive", imp, imp == 1 ? "" : "s",
            count[MD_NOCHANGE], vs->inconclusive);
    if (count[3])
        fprintf(o, ", %d new", count[3]);
    fputs(" in ", o);
    md_put(o, in->metric);
    fprintf(o, " at factor %.2f (alpha %.3g); ", rule->factor, rule->alpha);
    md_provenance(o, in);
    fputs("\n", o);
}

/* One table row from the verdict's numbers: ratio and interval and p for
 * the time rule, what the noise lets it resolve when inconclusive, and a
 * note (the reason of a counter or a missing configuration). */
static void md_row(FILE *o, const CmpVerdict *v, const CmpRule *rule)
{
    int regression = strcmp(v->verdict, "REGRESSION") == 0;
    int judged = regression || strcmp(v->verdict, "IMPROVEMENT") == 0;
    fprintf(o, regression ? "| **%s** | " : "| %s | ", v->verdict);
    md_put(o, v->scene);
    fputs(" | ", o);
    md_put(o, v->label);
    fputs(" | ", o);
    if (v->kind == CMP_TIME && isfinite(v->ci_lo))
        fprintf(o, "%.2f [%.2f, %.2f]", v->ratio, v->ci_lo, v->ci_hi);
    else if (v->kind == CMP_TIME)
        fprintf(o, "%.2f", v->ratio);
    fputs(" | ", o);
    if (v->kind == CMP_TIME && isfinite(v->p))
        fprintf(o, "%.4f", v->p);
    else if (v->kind == CMP_TIME) /* too few samples for the test */
        fputs("-", o);
    fputs(" | ", o);
    int unresolved = v->kind == CMP_TIME && !judged && strcmp(v->verdict, "no change") != 0;
    if (unresolved && isfinite(v->mde))
        fprintf(o, "x%.2f | %ld", v->mde, v->need);
    else
        fputs(" | ", o);
    fputs(" | ", o);
    if (v->kind == CMP_NOTE) {
        md_put(o, v->note);
    } else if (v->kind == CMP_SHORT) {
        fprintf(o, "too short to judge: base %.3f ms, under --min-ms %.3g", v->raw_base, rule->min_ms);
    } else {
        fprintf(o, "median %.3f -> %.3f", v->base_median, v->new_median);
        if (*rule->unit) {
            fputc(' ', o);
            md_put(o, rule->unit);
        }
        if (judged && rule->fp_differs)
            fputs(", different machines", o);
        if (v->busy[0] || v->busy[1] || v->stolen[0] || v->stolen[1])
            fputs(", noisy rows (busy or CPU steal)", o);
        if (unresolved && !isfinite(v->mde))
            fputs(", too few samples for an interval", o);
    }
    fputs(" |\n", o);
}

/* The table: up to MD_ROWS rows in md_order; "no change" rows only when
 * all of them fit, else counted with whatever else did not fit in one
 * line. */
static void md_table(FILE *o, const CmpVerdicts *vs, const CmpRule *rule)
{
    int shown = 0, left[MD_NORDER] = {0}, rest = 0;
    int all_fit = vs->n <= MD_ROWS; /* else the "no change" rows go first */
    fputs("| verdict | scene | configuration | ratio [95% CI] | p | detectable | repeats needed | note |\n"
          "|---|---|---|---|---:|---:|---:|---|\n", o);
    for (int k = 0; k < MD_NORDER; k++)
        for (size_t i = 0; i < vs->n; i++) {
            if (md_rank(vs->v[i].verdict) != k)
                continue;
            if (shown < MD_ROWS && (k != MD_NOCHANGE || all_fit)) {
                md_row(o, &vs->v[i], rule);
                shown++;
            } else {
                left[k]++;
                rest++;
            }
        }
    if (!rest)
        return;
    fprintf(o, "\n_Not shown (%d):", rest);
    for (int k = 0, first = 1; k < MD_NORDER; k++)
        if (left[k]) {
            fprintf(o, "%s %d %s%s", first ? "" : ",", left[k], md_word[k],
                    left[k] > 1 && (k == 0 || k == 2) ? "s" : "");
            first = 0;
        }
    fputs("; every configuration is in the text output._\n", o);
}

void hx_cmp_print_md(FILE *o, const CmpVerdicts *vs, const CmpRule *rule, const CmpMdInfo *in)
{
    int count[MD_NORDER] = {0};
    for (size_t i = 0; i < vs->n; i++)
        count[md_rank(vs->v[i].verdict)]++;
    md_headline(o, vs, count, rule, in);
    fputs("\n", o);
    if (vs->n)
        md_table(o, vs, rule);
    else
        fputs("No configuration to compare.\n", o);
    fprintf(o, "\n_ratio: %s median (above 1: worse) with its 95%% bootstrap interval; p: Mann-Whitney U (4 "
            "samples a side or more); detectable: the smallest change these samples can tell from none._\n",
            rule->higher ? "base/new" : "new/base");
    for (size_t i = 0; in->notes && i < in->notes->n; i++) {
        fputs("\nNote: ", o);
        md_put(o, in->notes->v[i]);
        fputs("\n", o);
    }
    if (in->report_url) {
        fputs("\n[Full report](", o);
        md_url(o, in->report_url);
        fputs(")\n", o);
    }
}
