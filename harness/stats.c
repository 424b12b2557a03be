/* stats.c: robust summaries, scaling metrics and the tests `compare` uses.
 * Medians and IQRs, not means and standard deviations: run times are skewed
 * (a preempted run is slow, never fast), so a mean chases the outliers. */
#include "hx.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

static double *sorted_copy(const double *x, size_t n)
{
    double *s = hx_xmalloc(n * sizeof *s);
    memcpy(s, x, n * sizeof *s);
    qsort(s, n, sizeof *s, hx_cmp_double);
    return s;
}

/* Linear interpolation between order statistics (Hyndman-Fan type 7, the
 * default of R and NumPy), so our IQRs match what a user recomputes. */
double hx_quantile_sorted(const double *s, size_t n, double q)
{
    if (n == 0)
        return NAN;
    double h = (double)(n - 1) * q;
    size_t lo = (size_t)floor(h);
    size_t hi = lo + 1 < n ? lo + 1 : lo;
    return s[lo] + (h - (double)lo) * (s[hi] - s[lo]);
}

double hx_quantile(const double *x, size_t n, double q)
{
    if (n == 0)
        return NAN;
    double *s = sorted_copy(x, n);
    double v = hx_quantile_sorted(s, n, q);
    free(s);
    return v;
}

double hx_median(const double *x, size_t n)
{
    return hx_quantile(x, n, 0.5);
}

double hx_min(const double *x, size_t n)
{
    double m = INFINITY;
    for (size_t i = 0; i < n; i++)
        if (x[i] < m)
            m = x[i];
    return n ? m : NAN;
}

/* Raw (unscaled) median absolute deviation. */
double hx_mad(const double *x, size_t n)
{
    if (n == 0)
        return NAN;
    double med = hx_median(x, n);
    double *d = hx_xmalloc(n * sizeof *d);
    for (size_t i = 0; i < n; i++)
        d[i] = fabs(x[i] - med);
    double m = hx_median(d, n);
    free(d);
    return m;
}

/* Flags samples further than k MADs from the median. With MAD == 0 (more
 * than half the samples identical) nothing is flagged: any k*0 threshold
 * would flag every sample that differs at all. Outliers are flagged, never
 * dropped: the median already ignores them. */
int hx_outliers(const double *x, size_t n, double k, int *flag)
{
    double med = hx_median(x, n), mad = hx_mad(x, n);
    int count = 0;
    for (size_t i = 0; i < n; i++) {
        int f = mad > 0 && fabs(x[i] - med) > k * mad;
        if (flag)
            flag[i] = f;
        count += f;
    }
    return count;
}

/* Karp-Flatt experimentally determined serial fraction (Karp & Flatt 1990):
 * e = (1/S - 1/p) / (1 - 1/p). Rising e with p points at overhead growing
 * with p (communication, imbalance), flat e at a true serial part. */
double hx_karp_flatt(double speedup, double p)
{
    if (p <= 1 || speedup <= 0)
        return NAN;
    return (1.0 / speedup - 1.0 / p) / (1.0 - 1.0 / p);
}

/* Ordinary least squares of t = a + b x with x = 1/p over all samples (not
 * medians, so the residual spread gives honest standard errors). Serial
 * fraction f = a/(a+b) = T_serial / T(1); its standard error by the delta
 * method with the covariance of (a, b). */
HxAmdahl hx_amdahl_fit(const double *p, const double *t, size_t n)
{
    HxAmdahl r;
    memset(&r, 0, sizeof r);
    r.se_a = r.se_b = r.se_serial_fraction = NAN;
    if (n < 2)
        return r;
    double sx = 0, sy = 0;
    for (size_t i = 0; i < n; i++) {
        sx += 1.0 / p[i];
        sy += t[i];
    }
    double mx = sx / (double)n, my = sy / (double)n, sxx = 0, sxy = 0;
    for (size_t i = 0; i < n; i++) {
        double dx = 1.0 / p[i] - mx;
        sxx += dx * dx;
        sxy += dx * (t[i] - my);
    }
    if (sxx <= 0) /* one distinct worker count: no fit */
        return r;
    r.b = sxy / sxx;
    r.a = my - r.b * mx;
    r.ok = 1;
    double sum = r.a + r.b;
    r.serial_fraction = sum != 0 ? r.a / sum : NAN;
    if (n >= 3) {
        double ssr = 0, sxx2 = 0;
        for (size_t i = 0; i < n; i++) {
            double e = t[i] - (r.a + r.b / p[i]);
            ssr += e * e;
            sxx2 += 1.0 / (p[i] * p[i]);
        }
        double s2 = ssr / (double)(n - 2);
        double var_b = s2 / sxx;
        double var_a = s2 * sxx2 / ((double)n * sxx);
        r.cov_ab = -s2 * mx / sxx;
        r.se_a = sqrt(var_a);
        r.se_b = sqrt(var_b);
        if (sum != 0) {
            double s4 = sum * sum * sum * sum;
            double var_f = (r.b * r.b * var_a - 2 * r.a * r.b * r.cov_ab + r.a * r.a * var_b) / s4;
            r.se_serial_fraction = sqrt(var_f > 0 ? var_f : 0);
        }
        r.has_se = 1;
    }
    return r;
}

/* Two-sided Mann-Whitney U test p-value (Mann & Whitney 1947). Up to 30
 * samples in all it is exact, ties too: the permutation distribution of the
 * x sample's rank sum over every way to pick nx of the pooled values, the
 * tied ones at their mid-ranks, counted by a dynamic program over the sorted
 * values (the normal approximation with tie correction gave p = 0.033 where
 * the exact p of 4 against 4 is 0.057). Beyond that, the normal
 * approximation with tie and continuity correction. Note: with 3 against 3
 * samples the smallest two-sided p is 0.1, so `compare` only uses this test
 * from 4 samples a side. */
#define HX_MW_EXACT 30

/* Twice the smaller tail, P(W <= w) or P(W >= w), as R's wilcox.test, for
 * the rank sum W of nx of the N doubled mid-ranks r2 (integers: 2 x the
 * mid-rank), w its observed value, doubled too. */
static double mw_exact(const int *r2, size_t N, size_t nx, long w)
{
    const long S = (long)N * ((long)N + 1); /* the doubled ranks' sum */
    const size_t W1 = (size_t)S + 1;
    double *f = calloc((nx + 1) * W1, sizeof *f); /* f[k][s]: subsets of k with sum s */
    if (!f)
        abort();
    f[0] = 1;
    for (size_t i = 0; i < N; i++)
        for (size_t k = (i + 1 < nx ? i + 1 : nx); k >= 1; k--)
            for (long s = S; s >= r2[i]; s--)
                f[k * W1 + (size_t)s] += f[(k - 1) * W1 + (size_t)(s - r2[i])];
    double total = 0, le = 0, ge = 0;
    for (long s = 0; s <= S; s++) {
        const double c = f[nx * W1 + (size_t)s];
        total += c;
        le += s <= w ? c : 0;
        ge += s >= w ? c : 0;
    }
    free(f);
    return total > 0 ? fmin(1.0, 2.0 * fmin(le, ge) / total) : 1.0;
}

double hx_mann_whitney_p(const double *x, size_t nx, const double *y, size_t ny)
{
    if (nx == 0 || ny == 0)
        return 1.0;
    size_t N = nx + ny;
    double *v = hx_xmalloc(N * sizeof *v);
    int *grp = hx_xmalloc(N * sizeof *grp), *r2 = hx_xmalloc(N * sizeof *r2);
    size_t *idx = hx_xmalloc(N * sizeof *idx);
    for (size_t i = 0; i < nx; i++) v[i] = x[i], grp[i] = 0;
    for (size_t i = 0; i < ny; i++) v[nx + i] = y[i], grp[nx + i] = 1;
    for (size_t i = 0; i < N; i++) idx[i] = i;
    /* insertion sort of indices by value: N is small */
    for (size_t i = 1; i < N; i++) {
        size_t k = idx[i];
        size_t j = i;
        while (j > 0 && v[idx[j - 1]] > v[k]) {
            idx[j] = idx[j - 1];
            j--;
        }
        idx[j] = k;
    }
    long wx2 = 0; /* the x sample's rank sum, doubled */
    double tie_term = 0;
    for (size_t i = 0; i < N;) {
        size_t j = i;
        while (j + 1 < N && v[idx[j + 1]] == v[idx[i]])
            j++;
        const int rank2 = (int)(i + j + 2); /* 2 x the mid-rank (1-based) */
        double t = (double)(j - i + 1);
        tie_term += t * t * t - t;
        for (size_t k = i; k <= j; k++) {
            r2[k] = rank2;
            if (grp[idx[k]] == 0)
                wx2 += rank2;
        }
        i = j + 1;
    }
    double p;
    if (N <= HX_MW_EXACT) {
        /* (the smaller sample's sums: fewer of them; the doubled smaller
         * tail is the same for either sample's rank sum) */
        long total2 = (long)N * ((long)N + 1);
        p = nx <= ny ? mw_exact(r2, N, nx, wx2) : mw_exact(r2, N, ny, total2 - wx2);
    } else {
        double m = (double)nx, n = (double)ny;
        double U = (double)wx2 / 2.0 - m * (m + 1) / 2.0;
        double mu = m * n / 2.0;
        double var = m * n / 12.0 * ((m + n + 1) - tie_term / ((m + n) * (m + n - 1)));
        double z = var > 0 ? (fabs(U - mu) - 0.5) / sqrt(var) : 0;
        p = var > 0 ? erfc((z < 0 ? 0 : z) / sqrt(2.0)) : 1.0;
    }
    free(v);
    free(grp);
    free(r2);
    free(idx);
    return p;
}

/* ---- bootstrap intervals (Efron & Tibshirani 1993, percentile method) ----
 * A fixed seed: the same CSV always gives the same interval. */
#define HX_BOOT 2000

static double boot_median(const double *x, size_t n, unsigned long long *s, double *scratch)
{
    for (size_t i = 0; i < n; i++) {
        *s ^= *s >> 12;
        *s ^= *s << 25;
        *s ^= *s >> 27;
        scratch[i] = x[(*s * 2685821657736338717ull >> 11) % n];
    }
    qsort(scratch, n, sizeof *scratch, hx_cmp_double);
    return hx_quantile_sorted(scratch, n, 0.5);
}

/* 95% interval of median(b) / median(a) (a speedup with b the baseline);
 * b NULL: of median(a) alone. Both
 * ends NAN with fewer than 3 samples a side: no interval worth printing. */
void hx_bootstrap_ci(const double *a, size_t na, const double *b, size_t nb, double *lo, double *hi)
{
    *lo = *hi = NAN;
    if (na < 3 || (b && nb < 3))
        return;
    unsigned long long s = 0x9e3779b97f4a7c15ull;
    double *est = hx_xmalloc(HX_BOOT * sizeof *est);
    double *scratch = hx_xmalloc((na > nb ? na : nb) * sizeof *scratch);
    for (int k = 0; k < HX_BOOT; k++) {
        double m = boot_median(a, na, &s, scratch);
        est[k] = b ? boot_median(b, nb, &s, scratch) / m : m;
    }
    qsort(est, HX_BOOT, sizeof *est, hx_cmp_double);
    *lo = hx_quantile_sorted(est, HX_BOOT, 0.025);
    *hi = hx_quantile_sorted(est, HX_BOOT, 0.975);
    free(est);
    free(scratch);
}
