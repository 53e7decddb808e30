/* steady: where a noisy time series (traction, load, sinkage) becomes
 * stationary, and the mean over that part with a confidence interval that
 * accounts for the series' autocorrelation.
 *
 * The start of the steady part is detected with MSER-5 (White 1997; Franklin
 * & White 2008): average the series in batches of 5 and drop the leading d
 * batches that minimise the squared standard error of the remaining mean,
 * with d limited to half the series. A summary of several quantities uses
 * the latest of their starts, so that none is averaged over its transient.
 *
 * The interval of the mean uses non-overlapping batch means and Student's t,
 * with batches at least 5 integrated autocorrelation times long (measured,
 * steady_iat), at most 20 batches. Batches shorter than the correlation time
 * are correlated and understate the interval (the default scene's forces
 * swing with lug passage and heave: ~0.1 s). With fewer than 4 such batches
 * the interval is sigma sqrt(tau / n) with the normal quantile and flagged
 * `short_series`: the steady part is too short for a trustworthy interval.
 *
 * Lug passage: the tread pattern repeats every 2 pi / lugs of wheel angle.
 * steady_lug_window cuts the steady part to whole pattern periods (a mean
 * over a fraction of a period is biased by the phase where it stops), and
 * steady_profile averages a quantity over the pattern phase (the lug-periodic
 * signal itself). */
#ifndef FEM_STEADY_H
#define FEM_STEADY_H

#include <stddef.h>

typedef struct steady_stats {
    size_t start;      /* index of the first sample of the averaged part */
    size_t count;      /* samples in the averaged part */
    double mean, min, max;
    double sd;         /* standard deviation of the samples (the time scatter) */
    double half_width; /* 95 % confidence half-width of the mean (0 if too short) */
    double tau;        /* integrated autocorrelation time, samples (1 = uncorrelated) */
    int batches;       /* batches used for the interval (0: from tau, see short_series) */
    int short_series;  /* 1: fewer than 4 batches of 5 tau: the interval is a rough one */
} steady_stats;

/* Index where the steady part of x[0..n) starts (MSER-5). */
size_t steady_start(const double *x, size_t n);
/* Integrated autocorrelation time of x[0..n) in samples,
 * tau = 1 + 2 sum_k rho(k), summed over k < 5 tau (Sokal's window); series
 * longer than 4096 are first averaged in blocks and tau is taken back to
 * samples by the ratio of the block means' variance to the samples' (exact
 * for blocks much shorter or much longer than tau). 1 for a constant or too
 * short series. */
double steady_iat(const double *x, size_t n);
/* Mean, extremes, scatter and 95 % interval of x[start..n). */
void steady_summary(const double *x, size_t n, size_t start, steady_stats *out);
/* The end (exclusive) of the longest stretch from `start` that covers a
 * whole number (>= 1) of periods of the wheel angle (rad, either sense of
 * rotation); n when the wheel turns less than one period or period <= 0. */
size_t steady_lug_window(const double *angle, size_t n, size_t start, double period);
/* Mean of x over `bins` bins of the pattern phase, frac(|angle - angle[start]| / period),
 * for samples [start, end); count[b] samples per bin (mean 0 where none). */
void steady_profile(const double *x, const double *angle, size_t start, size_t end, double period, int bins,
                    double *mean, int *count);
/* Two-sided 95 % Student t quantile for dof degrees of freedom. */
double steady_t95(int dof);

#endif
