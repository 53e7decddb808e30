#include "steady.h"

#include <math.h>
#include <stdlib.h>

double steady_t95(int dof)
{
    static const double t[] = {0,     12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228,
                               2.201, 2.179,  2.160, 2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086,
                               2.080, 2.074,  2.069, 2.064, 2.060, 2.056, 2.052, 2.048, 2.045, 2.042};
    if (dof < 1)
        return INFINITY;
    if (dof <= 30)
        return t[dof];
    return 1.960 + 2.4 / dof; /* within 0.3 % of the exact quantile above 30 */
}

size_t steady_start(const double *x, size_t n)
{
    enum { B = 5 };
    size_t m = n / B;
    if (m < 4)
        return 0;
    /* Suffix sums of batch means give each candidate's variance in O(1). */
    double best = INFINITY;
    size_t best_d = 0;
    double s1 = 0, s2 = 0;
    for (size_t j = m; j-- > 0;) {
        double z = 0;
        for (size_t k = 0; k < B; k++)
            z += x[j * B + k];
        z /= B;
        s1 += z;
        s2 += z * z;
        size_t d = j, len = m - j;
        if (d > m / 2 || len < 2)
            continue;
        double mean = s1 / (double)len;
        double ss = s2 - (double)len * mean * mean;
        if (ss < 0)
            ss = 0;
        double mser = ss / ((double)len * (double)len);
        if (mser <= best) { /* <=: prefer the earliest start among equals */
            best = mser;
            best_d = d;
        }
    }
    return best_d * B;
}

double steady_iat(const double *x, size_t n)
{
    if (n < 8)
        return 1.0;
    size_t b0 = (n + 4095) / 4096; /* block length: at most 4096 blocks */
    size_t m = n / b0;
    double *y = malloc(m * sizeof *y);
    if (!y)
        return (double)n; /* no memory: the most cautious answer (one batch) */
    double mean = 0;
    for (size_t j = 0; j < m; j++) {
        double z = 0;
        for (size_t k = 0; k < b0; k++)
            z += x[j * b0 + k];
        y[j] = z / (double)b0;
        mean += y[j];
    }
    mean /= (double)m;
    double c0 = 0, v0 = 0;
    for (size_t j = 0; j < m; j++) {
        y[j] -= mean;
        c0 += y[j] * y[j];
    }
    for (size_t i = 0; i < m * b0; i++)
        v0 += (x[i] - mean) * (x[i] - mean);
    double tau = 1.0;
    /* constant to round-off (a prescribed sinkage): uncorrelated by definition */
    if (c0 > 1e-24 * (double)m * (mean * mean + 1e-300)) {
        for (size_t k = 1; k < m / 2; k++) {
            double ck = 0;
            for (size_t j = 0; j + k < m; j++)
                ck += y[j] * y[j + k];
            tau += 2.0 * ck / c0;
            if ((double)k >= 5.0 * tau) /* Sokal's window: stop once k >= 5 tau */
                break;
        }
    }
    free(y);
    /* back to samples: the block means' variance is sigma^2 tau / b0 (blocks
     * longer than tau) and their own correlation time tau_b counts blocks
     * (blocks shorter than tau), so tau = tau_b b0 var(block means) / var(x)
     * holds in both limits */
    if (b0 > 1 && v0 > 0)
        tau *= (double)b0 * (c0 / (double)m) / (v0 / (double)(m * b0));
    return tau < 1.0 ? 1.0 : tau;
}

void steady_summary(const double *x, size_t n, size_t start, steady_stats *out)
{
    out->start = start < n ? start : n;
    out->count = n - out->start;
    out->mean = out->min = out->max = out->sd = out->half_width = 0;
    out->tau = 1.0;
    out->batches = 0;
    out->short_series = 1;
    if (out->count == 0)
        return;
    const double *y = x + out->start;
    size_t c = out->count;
    double sum = 0, mn = y[0], mx = y[0];
    for (size_t i = 0; i < c; i++) {
        sum += y[i];
        mn = y[i] < mn ? y[i] : mn;
        mx = y[i] > mx ? y[i] : mx;
    }
    out->mean = sum / (double)c;
    out->min = mn;
    out->max = mx;
    double ss = 0;
    for (size_t i = 0; i < c; i++)
        ss += (y[i] - out->mean) * (y[i] - out->mean);
    out->sd = c > 1 ? sqrt(ss / (double)(c - 1)) : 0.0;
    if (c < 2)
        return;
    out->tau = steady_iat(y, c);
    /* batches of at least 5 tau, at most 20 of them */
    size_t len = (size_t)ceil(5.0 * out->tau);
    size_t b = c / (len > 0 ? len : 1);
    if (b > 20)
        b = 20;
    if (b < 4) {
        out->half_width = 1.960 * out->sd * sqrt(out->tau / (double)c);
        return;
    }
    len = c / b;
    double bs = 0, bss = 0;
    for (size_t k = 0; k < b; k++) {
        double z = 0;
        for (size_t i = 0; i < len; i++)
            z += y[k * len + i];
        z /= (double)len;
        bs += z;
        bss += z * z;
    }
    double bm = bs / (double)b;
    double var = (bss - (double)b * bm * bm) / (double)(b - 1);
    out->half_width = steady_t95((int)b - 1) * sqrt(var > 0 ? var / (double)b : 0);
    out->batches = (int)b;
    out->short_series = 0;
}

size_t steady_lug_window(const double *angle, size_t n, size_t start, double period)
{
    if (!(period > 0) || start >= n)
        return n;
    double turned = fabs(angle[n - 1] - angle[start]);
    double k = floor(turned / period);
    if (k < 1)
        return n;
    for (size_t i = start; i < n; i++)
        if (fabs(angle[i] - angle[start]) >= k * period)
            return i;
    return n;
}

void steady_profile(const double *x, const double *angle, size_t start, size_t end, double period, int bins,
                    double *mean, int *count)
{
    for (int b = 0; b < bins; b++)
        mean[b] = 0, count[b] = 0;
    if (!(period > 0) || bins < 1)
        return;
    for (size_t i = start; i < end; i++) {
        double ph = fabs(angle[i] - angle[start]) / period;
        int b = (int)((ph - floor(ph)) * bins);
        b = b < 0 ? 0 : b >= bins ? bins - 1 : b;
        mean[b] += x[i];
        count[b]++;
    }
    for (int b = 0; b < bins; b++)
        mean[b] = count[b] ? mean[b] / count[b] : 0.0;
}
