/* Time-step limits of the grains (Rayleigh, Hertz contact time, the
 * dashpot's explicit stability) and the check of dem.dt against them. */
#include "dem_world.h"

#include <float.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "log.h"
#include "timer.h"
#include "vec3.h"

#ifdef _OPENMP
#include <omp.h>
#endif

/* ---- time-step limits -------------------------------------------------- */

/* Hertz contact time t_c = 2.943 delta_max / v, delta_max = (15 m* v² / (16 E* sqrt(R*)))^(2/5). */
static double hertz_time(double E, double R, double m, double v)
{
    double dmax = pow(15.0 * m * v * v / (16.0 * E * sqrt(R)), 0.4);
    return 2.943 * dmax / v;
}

/* Explicit stability of the dashpot: c dt / m* <= 1 with c = gamma_n sqrt(S_n m*)
 * at the largest overlap (bites only for very low restitution, e < ~0.05). */
static double damping_limit(const dem_pair_coef *c, double R, double m, double v)
{
    if (c->gamma_n <= 0.0)
        return INFINITY;
    double dmax = pow(15.0 * m * v * v / (16.0 * c->E * sqrt(R)), 0.4);
    double sn = 2.0 * c->E * sqrt(R * dmax);
    return 1.0 / (c->gamma_n * sqrt(sn / m));
}

static void time_limits(const dem_world *w, double *t_rayleigh, double *t_hertz, double *t_damp)
{
    const dem_grains *g = &w->g;
    double tr = INFINITY, th = INFINITY, td = INFINITY;
    double rmin[DEM_MAX_MATERIALS];
    for (int k = 0; k < DEM_MAX_MATERIALS; k++)
        rmin[k] = INFINITY;
    for (int i = 0; i < g->n; i++)
        if (g->r[i] < rmin[g->mat[i]])
            rmin[g->mat[i]] = g->r[i];
    double v = w->def.impact_velocity > 0.0 ? w->def.impact_velocity : 1.0;
    for (int k = 0; k < w->n_mat; k++) {
        if (!isfinite(rmin[k]))
            continue;
        const dem_material *m = &w->mat[k];
        double G = m->young / (2.0 * (1.0 + m->poisson));
        /* Rayleigh time (Li et al. 2005): pi r sqrt(rho/G) / (0.1631 nu + 0.8766) */
        double t = M_PI * rmin[k] * sqrt(m->density / G) / (0.1631 * m->poisson + 0.8766);
        tr = fmin(tr, t);
        double mass = m->density * (4.0 / 3.0) * M_PI * pow(rmin[k], 3);
        for (int j = 0; j < w->n_mat; j++)
            if (isfinite(rmin[j])) { /* smallest grain of k against smallest of j */
                const dem_material *mj = &w->mat[j];
                double mj_mass = mj->density * (4.0 / 3.0) * M_PI * pow(rmin[j], 3);
                double R = rmin[k] * rmin[j] / (rmin[k] + rmin[j]), ms = mass * mj_mass / (mass + mj_mass);
                th = fmin(th, hertz_time(w->coef[k][j].E, R, ms, v));
                td = fmin(td, damping_limit(&w->coef[k][j], R, ms, v));
            }
        for (int wl = 0; wl < w->n_walls; wl++) {
            const dem_pair_coef *c = &w->coef[k][w->walls[wl].material];
            th = fmin(th, hertz_time(c->E, rmin[k], mass, v));
            td = fmin(td, damping_limit(c, rmin[k], mass, v));
        }
        if (w->surf) {
            const dem_pair_coef *c = &w->coef[k][w->surf->material];
            th = fmin(th, hertz_time(c->E, rmin[k], mass, v));
            td = fmin(td, damping_limit(c, rmin[k], mass, v));
        }
    }
    *t_rayleigh = tr;
    *t_hertz = th;
    *t_damp = td;
}

void dem_time_limits(const dem_world *w, double *t_rayleigh, double *t_hertz)
{
    double td;
    time_limits(w, t_rayleigh, t_hertz, &td);
}

int dem_check_dt(dem_world *w, cm_error *err)
{
    double tr, th, td;
    time_limits(w, &tr, &th, &td);
    double lim_r = w->def.dt_safety_rayleigh * tr, lim_h = w->def.dt_safety_hertz * th;
    double lim = fmin(fmin(lim_r, lim_h), td);
    if (w->def.dt <= lim || !isfinite(lim))
        return CM_OK;
    const char *which = lim == td ? "dashpot" : (lim_r < lim_h ? "Rayleigh" : "Hertz");
    char what[512];
    snprintf(what, sizeof what,
             "dt = %g s exceeds the stable limit %g s (%s: Rayleigh time %g s x %g, Hertz contact time %g s at "
             "%g m/s x %g, dashpot limit %g s)",
             w->def.dt, lim, which, tr, w->def.dt_safety_rayleigh, th, w->def.impact_velocity, w->def.dt_safety_hertz,
             td);
    if (w->def.allow_unstable) {
        cm_log_warn("%s; running anyway (allow_unstable_dt)", what);
        return CM_OK;
    }
    return cm_fail(err, CM_ERR_RANGE, "%s; lower dem.dt or set dem.allow_unstable_dt = true", what);
}
