#include "steady.h"

#include <math.h>

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

void steady_summary(const double *x, size_t n, size_t start, steady_stats *out)
{
    out->start = start < n ? start : n;
    out->count = n - out->start;
    out->mean = out->min = out->max = out->half_width = 0;
    out->batches = 0;
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
    int b = c >= 40 ? 20 : (int)(c / 2);
    if (b < 2)
        return;
    size_t len = c / (size_t)b;
    double bs = 0, bss = 0;
    for (int k = 0; k < b; k++) {
        double z = 0;
        for (size_t i = 0; i < len; i++)
            z += y[(size_t)k * len + i];
        z /= (double)len;
        bs += z;
        bss += z * z;
    }
    double bm = bs / b;
    double var = (bss - b * bm * bm) / (b - 1);
    out->half_width = steady_t95(b - 1) * sqrt(var > 0 ? var / b : 0);
    out->batches = b;
}
