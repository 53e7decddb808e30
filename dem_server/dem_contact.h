/* Hertz–Mindlin contact law (paper sec. 2.2), shared by grain–grain,
 * grain–wall and grain–triangle contacts.
 *
 * Conventions: n is the unit normal pointing from the other body to grain i
 * (eq. 10), delta > 0 the overlap (eq. 18), vrel the velocity of i's contact
 * point relative to the other body's (eq. 12). The returned force acts on i. */
#ifndef DEM_CONTACT_H
#define DEM_CONTACT_H

#include <math.h>

#include "dem.h"
#include "vec3.h"

/* Coefficients of one material pair. */
typedef struct dem_pair_coef {
    double E;       /* E*, Pa: 1/E* = (1-ν1²)/E1 + (1-ν2²)/E2 (eq. 21) */
    double G;       /* G*, Pa: 1/G* = (2-ν1)/G1 + (2-ν2)/G2 (eq. 26 in its standard form) */
    double gamma_n; /* dimensionless dashpot factor: F_d = gamma_n sqrt(S_n m*) d(delta)/dt */
    double gamma_t; /* same for the tangential dashpot with S_t */
    double mu;      /* Coulomb friction */
    double mu_roll; /* rolling resistance (constant torque) */
    double e;       /* requested restitution */
    double st_sn;   /* sqrt(S_t / S_n) = sqrt(4 G* / E*), saves a sqrt per contact */
} dem_pair_coef;

void dem_pair_coef_make(const dem_material *a, const dem_material *b, dem_pair_coef *c);

/* Achieved restitution of the clamped Hertz impact for a dashpot factor
 * gamma_n (solved in non-dimensional form, independent of speed and size). */
double dem_restitution_achieved(double gamma_n);

/* Normal and tangential force on i.
 *   R, m : effective radius and mass (eqs. 16, 17; R = r_i, m = m_i for a wall)
 *   xi   : accumulated tangential spring displacement (history, eq. 20), m
 *   fn   : out, magnitude of the normal force (>= 0)
 * Normal (eq. 22 with the standard coefficient): with a = sqrt(R delta),
 *   S_n = 2 E* a,  F_n = 4/3 E* sqrt(R) delta^(3/2) + gamma_n sqrt(S_n m) d(delta)/dt,
 * clamped at >= 0 (no tension). The paper's eq. 23 drops the factor 2 of S_n
 * and the sqrt(5/6): we use the standard Tsuji/LIGGGHTS form
 *   gamma_n = -2 sqrt(5/6) ln e / sqrt(ln² e + π²)
 * or the calibrated one (dem_contact.c).
 * Tangential (eqs. 20, 24, 25): the spring xi is rotated into the current
 * tangent plane (magnitude kept), incremented by v_t dt, and
 *   F_t = -S_t xi - gamma_t sqrt(S_t m) v_t,  S_t = 8 G* a,
 * capped by μ F_n; on sliding the spring is rescaled to carry the capped force
 * alone, xi = -F_t / S_t (Luding 2008). LIGGGHTS instead stores
 * xi = -(F_t + c_t v_t)/S_t; when the dashpot alone exceeds the cap (early in
 * a fast oblique impact) that spring points the wrong way and the friction
 * force changes sign: the oblique-impact test loses 17 % of the impulse. */
/* The Mindlin spring of the rules below, shared by every contact model:
 * xi rotated into the tangent plane of n (magnitude kept), incremented by
 * vt dt, F_t = -st xi - ct vt capped at fmax, the spring rescaled on sliding. */
static inline vec3 dem_mindlin_spring(vec3 n, vec3 vt, double st, double ct, double fmax, double dt, double xi[3])
{
    vec3 s = v3_load(xi);
    double s2 = v3_norm2(s);
    if (s2 > 0.0) {
        /* rotate the stored spring into the current tangent plane */
        vec3 sp = v3_sub(s, v3_scale(n, v3_dot(s, n)));
        double sp2 = v3_norm2(sp);
        s = sp2 > 0.0 ? v3_scale(sp, sqrt(s2 / sp2)) : sp;
    }
    s = v3_axpy(dt, vt, s);
    vec3 ft = v3_sub(v3_scale(s, -st), v3_scale(vt, ct));
    double ft2 = v3_norm2(ft);
    if (ft2 > fmax * fmax) {
        double k = ft2 > 0.0 ? fmax / sqrt(ft2) : 0.0;
        ft = v3_scale(ft, k);
        s = st > 0.0 ? v3_scale(ft, -1.0 / st) : v3(0, 0, 0);
    }
    v3_store(xi, s);
    return ft;
}

static inline vec3 dem_hm_force(const dem_pair_coef *c, vec3 n, double delta, double R, double m, vec3 vrel,
                                double dt, double xi[3], double *fn)
{
    double a = sqrt(R * delta);
    double sn = 2.0 * c->E * a;
    double st = 8.0 * c->G * a; /* eq. 25 */
    double vn = v3_dot(vrel, n);  /* < 0 approaching: d(delta)/dt = -vn */
    double f_el = (2.0 / 3.0) * sn * delta; /* = 4/3 E* sqrt(R) delta^(3/2) */
    double sq = sqrt(sn * m);
    double f_n = f_el - c->gamma_n * sq * vn;
    if (f_n < 0.0)
        f_n = 0.0;
    *fn = f_n;

    vec3 vt = v3_sub(vrel, v3_scale(n, vn)); /* eq. 14 */
    double ct = c->gamma_t * c->st_sn * sq; /* gamma_t sqrt(S_t m) */
    vec3 ft = dem_mindlin_spring(n, vt, st, ct, c->mu * f_n, dt, xi);
    return v3_add(v3_scale(n, f_n), ft);
}

/* The tangential force of dem_hm_force alone, for a given normal force fn
 * and tangential stiffness st (shaped and polyhedral contacts, whose normal
 * force is not Hertz's); xi updated. */
static inline vec3 dem_mindlin_tangential(const dem_pair_coef *c, vec3 n, vec3 vrel, double st, double m, double fn,
                                          double dt, double xi[3])
{
    vec3 vt = v3_sub(vrel, v3_scale(n, v3_dot(vrel, n)));
    return dem_mindlin_spring(n, vt, st, c->gamma_t * sqrt(st * m), c->mu * fn, dt, xi);
}

/* Constant-torque rolling resistance on i: -μ_r R F_n ω_rel/|ω_rel|, limited
 * so that it cannot reverse ω_rel within one step (i_eff: effective moment of
 * inertia of the pair, kg m²). */
static inline vec3 dem_rolling_torque(const dem_pair_coef *c, double R, double fn, vec3 wrel, double i_eff,
                                      double dt)
{
    double wn = v3_norm(wrel);
    if (c->mu_roll <= 0.0 || wn <= 0.0)
        return v3(0, 0, 0);
    double t = c->mu_roll * R * fn;
    double tmax = i_eff * wn / dt;
    if (t > tmax)
        t = tmax;
    return v3_scale(wrel, -t / wn);
}

/* Elastic–plastic rolling resistance on i (DEM_ROLLING_SPRING): Ai et al.
 * 2011's model C (Iwashita & Oda 1998's spring with a dashpot; LIGGGHTS'
 * epsd), on the whole relative rotation as the constant torque acts on the
 * whole relative angular velocity: twisting is resisted like rolling (without
 * it a grain spinning on its one contact, as the toe of a collapsed heap
 * leaves some, never stops).
 *   th    : accumulated relative rotation (history), rad
 *   wrel  : ω_i − ω_j (a wall: ω_i)
 *   i_r   : the pair's rolling inertia 1 / (1/(I_i + m_i r_i²) + 1/(I_j + m_j r_j²)),
 *           for spheres 3.5 / (1/I_i + 1/I_j) (a wall: 3.5 I_i)
 * th += ω_rel dt; M = −k_r th − C_r ω_rel, capped at μ_r R F_n, th rescaled
 * to carry the capped torque alone (as the Mindlin spring on sliding). th is
 * not turned with the contact: while a grain rolls on, the cap keeps it at
 * the limit; at rest nothing turns. The stiffness (Wensrich & Katterfeld 2012)
 *   k_r = 2.25 μ_r² R² k_n,  k_n = F_el / δ = (4/3) E* a (LIGGGHTS' kn),
 * i.e. k_r = 1.5 S_n (μ_r R)² with S_n = 2 E* a of dem_hm_force (same bits),
 * and C_r = 2 η_r sqrt(i_r k_r) with Ai et al.'s damping ratio η_r = 0.3:
 * without it a grain held by its springs rocks undamped (in pure rolling the
 * contact point does not slide, so no other dashpot acts). The rolling
 * mode's frequency is 0.97 μ_r times the normal one between equal spheres
 * and 1.9 μ_r against a wall; the Hertz limit (dem_check_dt, dt <= 0.1
 * contact time) keeps the normal mode's ω dt below ~0.3: stable for any
 * μ_r up to ~3. */
#define DEM_ROLLING_DAMPING_RATIO 0.3
/* A sphere's I + m r^2 over I (I = 2/5 m r^2): the pair's rolling inertia is
 * DEM_SPHERE_ROLL_INERTIA / (1/I_i + 1/I_j), a wall contact's
 * DEM_SPHERE_ROLL_INERTIA I_i */
#define DEM_SPHERE_ROLL_INERTIA 3.5

static inline vec3 dem_rolling_spring(const dem_pair_coef *c, double R, double delta, double fn, vec3 wrel,
                                      double i_r, double dt, double th[3])
{
    double mrR = c->mu_roll * R;
    double sn = 2.0 * c->E * sqrt(R * delta);
    double kr = 1.5 * sn * mrR * mrR;
    double cr = 2.0 * DEM_ROLLING_DAMPING_RATIO * sqrt(i_r * kr);
    vec3 s = v3_axpy(dt, wrel, v3_load(th));
    vec3 M = v3_sub(v3_scale(s, -kr), v3_scale(wrel, cr));
    double m2 = v3_norm2(M), mmax = mrR * fn;
    if (m2 > mmax * mmax) {
        M = v3_scale(M, mmax / sqrt(m2));
        s = kr > 0.0 ? v3_scale(M, -1.0 / kr) : v3(0, 0, 0);
    }
    v3_store(th, s);
    return M;
}

/* ---- the same rules, one lane of a batched kernel ----------------------
 * The batched kernels (grain pairs, dem_pairs.c; walls, dem_step.c) compute
 * many contacts in a loop the compiler vectorises. The functions below are
 * dem_hm_force, dem_rolling_torque and dem_rolling_spring on scalars: the
 * same operations in the same order, their branches as selects of values
 * computed both ways (a quotient may be inf or NaN in a lane that does not
 * use it), hence the same bits (-ffp-contract=off: no fused multiply-adds).
 * Always inlined, so that the outputs through pointers stay in registers
 * (one pointer per scalar: an output array kept GCC from vectorising). */

/* The capped spring of dem_mindlin_spring and dem_rolling_spring: the
 * spring s[xyz] += dt v, the force F = -k s - c v, capped at fmax with the
 * spring rescaled to carry the capped force alone. */
static inline __attribute__((always_inline)) void dem_capped_spring_lane(double k, double c, double fmax, double dt,
                                                                         double vx, double vy, double vz,
                                                                         double *restrict sx_, double *restrict sy_,
                                                                         double *restrict sz_, double *restrict fx_,
                                                                         double *restrict fy_, double *restrict fz_)
{
    double sx = dt * vx + *sx_, sy = dt * vy + *sy_, sz = dt * vz + *sz_;
    double fx = sx * -k - vx * c, fy = sy * -k - vy * c, fz = sz * -k - vz * c;
    double f2 = fx * fx + fy * fy + fz * fz;
    double kk = fmax / sqrt(f2); /* used only where capped, so f2 > 0 */
    double inv_k = -1.0 / k;
    if (f2 > fmax * fmax) { /* sliding (rolling): the capped force, the spring that carries it alone */
        fx = fx * kk, fy = fy * kk, fz = fz * kk;
        sx = k > 0.0 ? fx * inv_k : 0.0, sy = k > 0.0 ? fy * inv_k : 0.0, sz = k > 0.0 ? fz * inv_k : 0.0;
    }
    *sx_ = sx, *sy_ = sy, *sz_ = sz;
    *fx_ = fx, *fy_ = fy, *fz_ = fz;
}

/* dem_hm_force: normal n (from the partner to the grain), overlap delta,
 * R*, m*, relative velocity vr; coefficients E*, G*, gamma_n, gamma_t,
 * st_sn, mu of the pair; the spring s[xyz] updated. Out: the force F on the
 * grain, |F_n| and S_n (for the rolling spring). */
static inline __attribute__((always_inline)) void dem_hm_lane(double E, double G, double gn, double gt, double st_sn,
                                                              double mu, double dt, double nx, double ny, double nz,
                                                              double delta, double R, double m, double vrx, double vry,
                                                              double vrz, double *restrict sx_, double *restrict sy_,
                                                              double *restrict sz_, double *restrict fx,
                                                              double *restrict fy, double *restrict fz,
                                                              double *restrict fn, double *restrict sn_)
{
    double a = sqrt(R * delta);
    double sn = 2.0 * E * a;
    double st = 8.0 * G * a; /* eq. 25 */
    double vn = vrx * nx + vry * ny + vrz * nz;
    double f_el = (2.0 / 3.0) * sn * delta;
    double sq = sqrt(sn * m);
    double f_n = f_el - gn * sq * vn;
    f_n = f_n < 0.0 ? 0.0 : f_n;
    double vtx = vrx - nx * vn, vty = vry - ny * vn, vtz = vrz - nz * vn; /* eq. 14 */
    double ctt = gt * st_sn * sq;
    /* dem_mindlin_spring */
    double sx = *sx_, sy = *sy_, sz = *sz_;
    double s2 = sx * sx + sy * sy + sz * sz;
    double dsn = sx * nx + sy * ny + sz * nz;
    double px = sx - nx * dsn, py = sy - ny * dsn, pz = sz - nz * dsn;
    double p2 = px * px + py * py + pz * pz;
    double sc = sqrt(s2 / p2); /* used only where s2 > 0 and p2 > 0 */
    double qx = p2 > 0.0 ? px * sc : px, qy = p2 > 0.0 ? py * sc : py, qz = p2 > 0.0 ? pz * sc : pz;
    *sx_ = s2 > 0.0 ? qx : sx, *sy_ = s2 > 0.0 ? qy : sy, *sz_ = s2 > 0.0 ? qz : sz;
    double ftx, fty, ftz;
    dem_capped_spring_lane(st, ctt, mu * f_n, dt, vtx, vty, vtz, sx_, sy_, sz_, &ftx, &fty, &ftz);
    *fx = nx * f_n + ftx, *fy = ny * f_n + fty, *fz = nz * f_n + ftz;
    *fn = f_n, *sn_ = sn;
}

/* dem_rolling_torque with mu_roll > 0 (the caller selects): the torque tr
 * on the grain (zero where w = 0). */
static inline __attribute__((always_inline)) void dem_rolling_torque_lane(double mu_roll, double R, double fn,
                                                                          double wx, double wy, double wz,
                                                                          double i_eff, double dt,
                                                                          double *restrict trx, double *restrict try_,
                                                                          double *restrict trz)
{
    double wn = sqrt(wx * wx + wy * wy + wz * wz);
    double t = mu_roll * R * fn;
    double tmax = i_eff * wn / dt;
    t = t > tmax ? tmax : t;
    double f = -t / wn; /* used only where wn > 0 */
    const int turn = wn > 0.0;
    *trx = turn ? wx * f : 0.0, *try_ = turn ? wy * f : 0.0, *trz = turn ? wz * f : 0.0;
}

/* dem_rolling_spring with mu_roll > 0 (the caller selects), S_n from
 * dem_hm_lane: the torque M on the grain, the rotation u[xyz] updated. */
static inline __attribute__((always_inline)) void dem_rolling_spring_lane(double mu_roll, double R, double sn,
                                                                          double fn, double wx, double wy, double wz,
                                                                          double i_r, double dt, double *restrict ux_,
                                                                          double *restrict uy_, double *restrict uz_,
                                                                          double *restrict mx_, double *restrict my_,
                                                                          double *restrict mz_)
{
    double mrR = mu_roll * R;
    double kr = 1.5 * sn * mrR * mrR;
    double cr = 2.0 * DEM_ROLLING_DAMPING_RATIO * sqrt(i_r * kr);
    dem_capped_spring_lane(kr, cr, mrR * fn, dt, wx, wy, wz, ux_, uy_, uz_, mx_, my_, mz_);
}

/* Normal elastic energy stored in a Hertz contact, J. */
static inline double dem_hertz_energy(const dem_pair_coef *c, double R, double delta)
{
    return (8.0 / 15.0) * c->E * sqrt(R) * delta * delta * sqrt(delta); /* delta^(5/2) without pow */
}

#endif
