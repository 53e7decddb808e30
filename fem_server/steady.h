/* steady: where a noisy time series (traction, sinkage) becomes stationary,
 * and the mean over that part with a confidence interval.
 *
 * The start of the steady part is detected with MSER-5 (White 1997; Franklin
 * & White 2008): average the series in batches of 5 and drop the leading d
 * batches that minimise the squared standard error of the remaining mean,
 * with d limited to half the series. The confidence interval of the mean
 * uses non-overlapping batch means (up to 20 batches) and Student's t, which
 * allows for the autocorrelation of DEM force signals. */
#ifndef FEM_STEADY_H
#define FEM_STEADY_H

#include <stddef.h>

typedef struct steady_stats {
    size_t start;      /* index of the first sample of the steady part */
    size_t count;      /* samples in the steady part */
    double mean, min, max;
    double half_width; /* 95 % confidence half-width of the mean (0 if too short) */
    int batches;       /* batches used for the interval */
} steady_stats;

/* Index where the steady part of x[0..n) starts (MSER-5). */
size_t steady_start(const double *x, size_t n);
/* Mean, extremes and 95 % interval of x[start..n). */
void steady_summary(const double *x, size_t n, size_t start, steady_stats *out);
/* Two-sided 95 % Student t quantile for dof degrees of freedom. */
double steady_t95(int dof);

#endif
