/* The Hertz contact of elastic spheres, in closed form: the one copy the
 * tests compare the DEM's contact laws and the coupled runs against.
 * Es is the effective modulus 1/E* = (1 - nu1^2)/E1 + (1 - nu2^2)/E2, Rs the
 * effective radius (R for a sphere on a plane, R/2 for equal spheres), ms the
 * effective mass (m, m/2), SI units throughout.
 *   force at overlap d:          F = 4/3 E* sqrt(R*) d^(3/2)
 *   static overlap under load W: d = (3 W / (4 E* sqrt(R*)))^(2/3)
 *   normal impact at speed v:    d_max = (15 m* v^2 / (16 E* sqrt(R*)))^(2/5),
 *                                t_c = 2.943 d_max / v, F_max = F(d_max)
 * (Johnson, Contact Mechanics, 1985, sections 4.2 and 11.4). */
#ifndef DEMFEM_TEST_HERTZ_H
#define DEMFEM_TEST_HERTZ_H

#include <math.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

static inline double hertz_e_star(double E1, double nu1, double E2, double nu2)
{
    return 1.0 / ((1.0 - nu1 * nu1) / E1 + (1.0 - nu2 * nu2) / E2);
}

static inline double hertz_force(double Es, double Rs, double overlap)
{
    return 4.0 / 3.0 * Es * sqrt(Rs) * pow(overlap, 1.5);
}

static inline double hertz_static_overlap(double Es, double Rs, double load)
{
    return pow(load / (4.0 / 3.0 * Es * sqrt(Rs)), 2.0 / 3.0);
}

/* Mass of a sphere of radius r and density rho. */
static inline double sphere_mass(double rho, double r) { return rho * 4.0 / 3.0 * M_PI * r * r * r; }

typedef struct hertz_ref {
    double dmax, tc, fmax; /* maximum overlap (m), contact time (s), peak force (N) */
} hertz_ref;

static inline hertz_ref hertz_closed_form(double Es, double Rs, double ms, double v)
{
    hertz_ref h;
    h.dmax = pow(15.0 * ms * v * v / (16.0 * Es * sqrt(Rs)), 0.4);
    h.tc = 2.943 * h.dmax / v; /* 2.9432 to four digits */
    h.fmax = hertz_force(Es, Rs, h.dmax);
    return h;
}

#endif
