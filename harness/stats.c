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

double hx_median(const double *x, size_t n)
{
    if (n == 0)
        return NAN;
    double *s = sorted_copy(x, n);
    double m = hx_quantile_sorted(s, n, 0.5);
    free(s);
    return m;
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

/* Number of arrangements with U = u for sample sizes m, n (no ties), by the
 * recurrence f(m,n,u) = f(m-1,n,u-n) + f(m,n-1,u); exact for small samples
 * where the normal approximation is poor. */
static double *u_counts(int m, int n)
{
    /* f[i][j][u]: i x-samples, j y-samples; the largest element is either an
     * x (it beats all j y's: u - j) or a y (u unchanged). */
    size_t U1 = (size_t)m * (size_t)n + 1;
    size_t J = (size_t)n + 1;
    double *f = calloc(((size_t)m + 1) * J * U1, sizeof(double));
    if (!f)
        abort();
#define F(i, j, u) f[((size_t)(i) * J + (size_t)(j)) * U1 + (size_t)(u)]
    for (int i = 0; i <= m; i++)
        for (int j = 0; j <= n; j++) {
            if (i == 0 || j == 0) {
                F(i, j, 0) = 1;
                continue;
            }
            for (int u = 0; u <= i * j; u++)
                F(i, j, u) = (u - j >= 0 ? F(i - 1, j, u - j) : 0) + F(i, j - 1, u);
        }
    double *res = hx_xmalloc(U1 * sizeof *res);
    for (size_t u = 0; u < U1; u++)
        res[u] = F(m, n, u);
#undef F
    free(f);
    return res;
}

/* Two-sided Mann-Whitney U test p-value: exact without ties for small
 * samples, else the normal approximation with tie and continuity
 * correction. Note: with 3 against 3 samples the smallest exact two-sided p
 * is 0.1, so `compare` only uses this test from 4 samples a side. */
double hx_mann_whitney_p(const double *x, size_t nx, const double *y, size_t ny)
{
    if (nx == 0 || ny == 0)
        return 1.0;
    size_t N = nx + ny;
    double *v = hx_xmalloc(N * sizeof *v);
    int *grp = hx_xmalloc(N * sizeof *grp);
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
    double rx = 0, tie_term = 0;
    int ties = 0;
    for (size_t i = 0; i < N;) {
        size_t j = i;
        while (j + 1 < N && v[idx[j + 1]] == v[idx[i]])
            j++;
        double rank = (double)(i + j) / 2.0 + 1.0;
        double t = (double)(j - i + 1);
        if (t > 1) {
            ties = 1;
            tie_term += t * t * t - t;
        }
        for (size_t k = i; k <= j; k++)
            if (grp[idx[k]] == 0)
                rx += rank;
        i = j + 1;
    }
    free(v);
    free(grp);
    free(idx);
    double m = (double)nx, n = (double)ny;
    double U = rx - m * (m + 1) / 2.0;
    if (!ties && nx * ny <= 400) {
        double *cnt = u_counts((int)nx, (int)ny);
        double total = 0, le = 0, ge = 0;
        int umax = (int)(nx * ny);
        int u = (int)llround(U);
        for (int k = 0; k <= umax; k++) {
            total += cnt[k];
            if (k <= u) le += cnt[k];
            if (k >= u) ge += cnt[k];
        }
        free(cnt);
        double p = 2.0 * fmin(le, ge) / total;
        return p > 1 ? 1 : p;
    }
    double mu = m * n / 2.0;
    double var = m * n / 12.0 * ((m + n + 1) - tie_term / ((m + n) * (m + n - 1)));
    if (var <= 0)
        return 1.0;
    double z = (fabs(U - mu) - 0.5) / sqrt(var);
    if (z < 0)
        z = 0;
    return erfc(z / sqrt(2.0));
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
