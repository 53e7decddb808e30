/* The soil's pointwise laws (pressure and shear at one point, unaware of the
 * grid), after Wong, Theory of Ground Vehicles, 3rd ed. (2001), ch. 2. */
#include <math.h>

#include "scm.h"

scm_soil scm_soil_default(void)
{
    /* Dry sand (Land Locomotion Laboratory), Wong table 2.3: n, k_c, k_phi,
     * c, phi. K: Wong's text gives about 1 cm for firm and 2.5 cm for loose
     * sand; a poured test bed is loose. The unloading stiffness is an
     * assumption (README.md, "Parameters"). */
    scm_soil s = {
        .k_c = 0.99e3,         /* N/m^(n+1) */
        .k_phi = 1528.43e3,    /* N/m^(n+2) */
        .n = 1.1,
        .cohesion = 1.04e3,    /* Pa */
        .phi = 28.0 * M_PI / 180.0,
        .K = 0.025,            /* m */
        .k0 = 4.0e7,           /* Pa/m */
        .A_u = 0.0,            /* Pa/m^2 */
        .b = 0.0,              /* from the surface */
        .z_reg = 1.0e-4,       /* m */
    };
    return s;
}

/* Bekker's pressure-sinkage relation p = (k_c/b + k_phi) z^n for first
 * loading. Below z_reg the secant k z_reg^(n-1) z replaces it: for n < 1 the
 * slope of z^n is infinite at z = 0, which no explicit exchange with a light
 * surface node could carry; the secant's finite slope k z_reg^(n-1) can. */
double scm_bekker(const scm_soil *s, double b, double z)
{
    if (!(z > 0))
        return 0.0;
    const double k = s->k_c / b + s->k_phi;
    if (z < s->z_reg)
        return k * pow(s->z_reg, s->n - 1.0) * z;
    return k * pow(z, s->n);
}

/* Unloading and reloading follow a straight line of slope k_u = k0 + A_u z_max
 * (Wong's form for repetitive loading: the stiffness grows with the sinkage
 * reached): p = p_max - k_u (z_max - z), springing back by p_max / k_u. */
double scm_unload_stiffness(const scm_soil *s, double z_max) { return s->k0 + s->A_u * z_max; }

/* Janosi–Hanamoto: tau = (c + p tan phi)(1 - exp(-j/K)). */
double scm_janosi(const scm_soil *s, double p, double j)
{
    return (s->cohesion + p * tan(s->phi)) * (1.0 - exp(-fabs(j) / s->K));
}

/* The shear stress as an elastic-plastic spring on the Janosi curve. The
 * stress is a stiffness times the elastic part e of the shear displacement,
 *   tau = k_tau |e|,  k_tau = (c + p_max tan phi) / K,
 * the Janosi curve's initial slope for soil first loaded to p_max (the
 * cell's deepest loading: p itself on first loading, fixed while the cell
 * unloads and reloads on its elastic line), and e is held within the
 * Janosi strength at the pressure now,
 *   k_tau |e| <= (c + p tan phi)(1 - e^{-j/K}),
 * the rest of the displacement j being plastic slip. In monotonic sliding
 * from rest on first loading e stays on that limit (j > K (1 - e^{-j/K}) for
 * every j > 0), so tau is Janosi's to round-off; when the sliding stops or
 * turns, tau follows the displacement elastically instead of jumping to the
 * full strength in the direction of the instantaneous velocity, which an
 * explicit exchange with light surface nodes turned into chatter. The
 * stiffness does not follow the pressure now: a stiffness k_tau(p) made the
 * shear force a function of the sinkage in the elastic range (a force
 * tangential to the surface growing with the normal displacement and none
 * the other way: a circulatory stiffness) and the tread's normal and
 * tangential oscillations fed each other; a falling pressure lowers the
 * limit instead, which only removes elastic energy (README.md, "The shear:
 * an elastic-plastic spring on the Janosi curve"). */
double scm_shear_stiffness(const scm_soil *s, double p_max) { return (s->cohesion + p_max * tan(s->phi)) / s->K; }

double scm_shear_elastic_limit(const scm_soil *s, double p, double p_max, double j)
{
    const double k = scm_shear_stiffness(s, p_max);
    return k > 0 ? scm_janosi(s, p, j) / k : 0.0;
}
