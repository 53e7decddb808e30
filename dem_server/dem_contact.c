/* Pair coefficients and the restitution calibration of the Hertz dashpot.
 *
 * Why calibrate: the dashpot F_d = gamma sqrt(S_n m*) d(delta)/dt with
 * S_n = 2 E* sqrt(R* delta) gives exactly the requested e for
 * gamma = -2 sqrt(5/6) ln e / sqrt(ln² e + π²) only if the total normal force
 * may turn attractive near separation. Clamped at >= 0, the grains leave the
 * contact early, faster than they would have, so the achieved e overshoots
 * (PHYSICS_NOTES; Thornton, Cummins & Cleary 2013).
 *
 * Scaling delta = delta0 xi, t = t0 tau with t0² = m* / (K sqrt(delta0)),
 * K = 2 E* sqrt(R*), delta0 = v0 t0 turns the impact into
 *     xi'' = min(0, -(2/3) xi^(3/2) - gamma xi^(1/4) xi'),  xi(0) = 0, xi'(0) = 1,
 * whose rebound speed -xi'(end) IS the achieved e, for any v0, R*, m*, E*.
 * We integrate it (RK4, fine step) and invert e(gamma) by bisection. */
#include "dem_contact.h"

#include <math.h>

/* Right-hand side of the non-dimensional clamped impact. */
static double impact_acc(double x, double v, double gamma)
{
    if (x <= 0.0)
        return 0.0;
    double a = -(2.0 / 3.0) * x * sqrt(x) - gamma * sqrt(sqrt(x)) * v;
    return a < 0.0 ? a : 0.0;
}

double dem_restitution_achieved(double gamma)
{
    /* Undamped contact lasts tau ~ 3.2; step 2e-4 gives e to ~1e-6. */
    const double h = 2e-4;
    double x = 0.0, v = 1.0;
    for (int it = 0; it < 1000000; it++) {
        double k1x = v, k1v = impact_acc(x, v, gamma);
        double k2x = v + 0.5 * h * k1v, k2v = impact_acc(x + 0.5 * h * k1x, v + 0.5 * h * k1v, gamma);
        double k3x = v + 0.5 * h * k2v, k3v = impact_acc(x + 0.5 * h * k2x, v + 0.5 * h * k2v, gamma);
        double k4x = v + h * k3v, k4v = impact_acc(x + h * k3x, v + h * k3v, gamma);
        double xn = x + h / 6.0 * (k1x + 2 * k2x + 2 * k3x + k4x);
        double vn = v + h / 6.0 * (k1v + 2 * k2v + 2 * k3v + k4v);
        if (xn <= 0.0 && it > 0)
            return -vn;
        if (vn >= 0.0 && xn <= 0.0)
            return 0.0;
        x = xn;
        v = vn;
        if (v >= 0.0 && x < 1e-12 && it > 10)
            return 0.0; /* stuck (cannot happen for finite gamma, kept as a guard) */
    }
    return -v;
}

double dem_damping_for_restitution(double e, int model)
{
    if (e >= 1.0)
        return 0.0;
    if (e <= 0.0)
        e = 1e-3;
    double le = log(e);
    double g_ln = -2.0 * sqrt(5.0 / 6.0) * le / sqrt(le * le + M_PI * M_PI);
    if (model == DEM_DAMPING_LN_E)
        return g_ln;
    /* e(gamma) decreases monotonically; the calibrated gamma is larger than g_ln. */
    double lo = 0.0, hi = g_ln > 0.0 ? g_ln : 1.0;
    while (dem_restitution_achieved(hi) > e && hi < 1e3)
        hi *= 2.0;
    for (int it = 0; it < 48 && hi - lo > 1e-9 * hi; it++) {
        double mid = 0.5 * (lo + hi);
        if (dem_restitution_achieved(mid) > e)
            lo = mid;
        else
            hi = mid;
    }
    return 0.5 * (lo + hi);
}

void dem_pair_coef_make(const dem_material *a, const dem_material *b, dem_pair_coef *c)
{
    c->E = 1.0 / ((1.0 - a->poisson * a->poisson) / a->young + (1.0 - b->poisson * b->poisson) / b->young);
    double ga = a->young / (2.0 * (1.0 + a->poisson)), gb = b->young / (2.0 * (1.0 + b->poisson));
    c->G = 1.0 / ((2.0 - a->poisson) / ga + (2.0 - b->poisson) / gb);
    c->e = 0.5 * (a->restitution + b->restitution);
    c->mu = 0.5 * (a->friction + b->friction);
    c->mu_roll = 0.5 * (a->rolling_friction + b->rolling_friction);
    c->gamma_n = c->gamma_t = 0.0; /* set by the caller: dem_damping_for_restitution() */
    c->st_sn = sqrt(4.0 * c->G / c->E);
}
