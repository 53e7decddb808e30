/* Contact laws and integrator against closed forms. */
#include <stdlib.h>

#include "dem_contact.h"
#include "test_dem_common.h"

static const double R0 = 0.005; /* grain radius, m */

/* Impact of grain 0 (moving at v along -z) onto grain 1 or a wall; records
 * contact duration, max overlap, max force and the rebound velocity. */
typedef struct impact {
    double tc, dmax, fmax;
    double v_after[3], w_after[3];
} impact;

static int run_impact(dem_world *w, int two_spheres, const double v0[3], impact *out)
{
    cm_error err = {0};
    double x0[3] = {0, 0, R0 * 1.0001};
    if (two_spheres) {
        double x1[3] = {0, 0, -R0 * 1.0001};
        double v1[3] = {-v0[0], -v0[1], -v0[2]};
        if (dem_grain_add(w, x0, R0, 0, NULL, &err) || dem_grain_add(w, x1, R0, 0, NULL, &err))
            return 1;
        dem_grain_set(w, 1, NULL, v1, NULL);
    } else {
        double p[3] = {0, 0, 0}, n[3] = {0, 0, 1};
        if (dem_grain_add(w, x0, R0, 0, NULL, &err) || dem_wall_add(w, p, n, 0, &err))
            return 1;
    }
    dem_grain_set(w, 0, NULL, v0, NULL);
    memset(out, 0, sizeof *out);
    int steps_in = 0, seen = 0;
    const double dt = dem_world_get_def(w)->dt;
    for (int s = 0; s < 2000000; s++) {
        dem_grain_state g0, g1;
        dem_grain_get(w, 0, &g0);
        double delta;
        if (two_spheres) {
            dem_grain_get(w, 1, &g1);
            double dz = g0.x[2] - g1.x[2], dx = g0.x[0] - g1.x[0], dy = g0.x[1] - g1.x[1];
            delta = 2 * R0 - sqrt(dx * dx + dy * dy + dz * dz);
        } else {
            delta = R0 - g0.x[2];
        }
        if (delta > 0) {
            steps_in++;
            seen = 1;
            if (delta > out->dmax)
                out->dmax = delta;
        } else if (seen) {
            break;
        }
        if (dem_step(w, &err)) {
            fprintf(stderr, "%s\n", err.msg);
            return 1;
        }
        dem_grain_get(w, 0, &g0);
        double f = sqrt(g0.f[0] * g0.f[0] + g0.f[1] * g0.f[1] + g0.f[2] * g0.f[2]);
        if (f > out->fmax)
            out->fmax = f;
    }
    dem_grain_state g0;
    dem_grain_get(w, 0, &g0);
    memcpy(out->v_after, g0.v, sizeof g0.v);
    memcpy(out->w_after, g0.w, sizeof g0.w);
    out->tc = steps_in * dt;
    return 0;
}

/* Hertz: t_c = 2.943 dmax / v, dmax = (15 m* v² / (16 E* sqrt(R*)))^(2/5), Fmax = 4/3 E* sqrt(R*) dmax^(3/2). */
static int hertz_sphere_sphere(void)
{
    dem_material m = test_material(5e7, 0.3, 1.0, 0.0);
    double v = 0.5; /* each: relative speed 1 */
    double mass = sphere_mass(m.density, R0);
    hertz_ref h = hertz_closed_form(e_star_same(&m), R0 / 2, mass / 2, 2 * v);
    dem_world *w = test_world(&m, 1, h.tc / 500, 2, NULL, 1);
    ENSURE(w);
    impact r;
    double v0[3] = {0, 0, -v};
    ENSURE(run_impact(w, 1, v0, &r) == 0);
    printf("sphere-sphere: tc %.6g vs %.6g (%.3f %%), dmax %.6g vs %.6g (%.3f %%), Fmax %.6g vs %.6g (%.3f %%)\n",
           r.tc, h.tc, 100 * (r.tc / h.tc - 1), r.dmax, h.dmax, 100 * (r.dmax / h.dmax - 1), r.fmax, h.fmax,
           100 * (r.fmax / h.fmax - 1));
    ENSURE_REL(r.tc, h.tc, 0.01);
    ENSURE_REL(r.dmax, h.dmax, 0.01);
    ENSURE_REL(r.fmax, h.fmax, 0.01);
    ENSURE_REL(-r.v_after[2], -v, 1e-3); /* e = 1: elastic */
    dem_world_destroy(&w);
    return 0;
}

static int hertz_sphere_wall(void)
{
    dem_material m = test_material(5e7, 0.3, 1.0, 0.0);
    double v = 1.0;
    double mass = sphere_mass(m.density, R0);
    hertz_ref h = hertz_closed_form(e_star_same(&m), R0, mass, v);
    dem_world *w = test_world(&m, 1, h.tc / 500, 1, NULL, 1);
    ENSURE(w);
    impact r;
    double v0[3] = {0, 0, -v};
    ENSURE(run_impact(w, 0, v0, &r) == 0);
    printf("sphere-wall: tc %.6g vs %.6g (%.3f %%), dmax %.6g vs %.6g (%.3f %%), Fmax %.6g vs %.6g (%.3f %%)\n", r.tc,
           h.tc, 100 * (r.tc / h.tc - 1), r.dmax, h.dmax, 100 * (r.dmax / h.dmax - 1), r.fmax, h.fmax,
           100 * (r.fmax / h.fmax - 1));
    ENSURE_REL(r.tc, h.tc, 0.01);
    ENSURE_REL(r.dmax, h.dmax, 0.01);
    ENSURE_REL(r.fmax, h.fmax, 0.01);
    ENSURE_REL(r.v_after[2], v, 1e-3);
    dem_world_destroy(&w);
    return 0;
}

/* Achieved vs requested restitution over 0.1..0.9, sphere–wall and
 * sphere–sphere, for both dashpot forms. The calibrated one must hit e within
 * 2 %; the ln(e) one is reported and must overshoot (the clamp trap). */
static int restitution_sweep(void)
{
    const double es[] = {0.1, 0.2, 0.3, 0.5, 0.7, 0.9};
    printf("  e_req   wall:calibrated  wall:ln_e   pair:calibrated  pair:ln_e\n");
    for (size_t k = 0; k < sizeof es / sizeof es[0]; k++) {
        double ach[2][2];
        for (int model = 0; model < 2; model++)
            for (int pair = 0; pair < 2; pair++) {
                dem_material m = test_material(5e7, 0.3, es[k], 0.0);
                double mass = sphere_mass(m.density, R0);
                hertz_ref h = pair ? hertz_closed_form(e_star_same(&m), R0 / 2, mass / 2, 1.0)
                                   : hertz_closed_form(e_star_same(&m), R0, mass, 1.0);
                dem_world_def d = dem_world_def_default();
                d.dt = h.tc / 200;
                d.max_grains = 2;
                d.gravity[2] = 0.0;
                d.damping = model ? DEM_DAMPING_LN_E : DEM_DAMPING_CALIBRATED;
                dem_world *w = NULL;
                cm_error err = {0};
                ENSURE(dem_world_create(&d, 1, &m, &w, &err) == 0);
                impact r;
                double v0[3] = {0, 0, pair ? -0.5 : -1.0};
                ENSURE(run_impact(w, pair, v0, &r) == 0);
                ach[model][pair] = pair ? r.v_after[2] / 0.5 : r.v_after[2];
                dem_world_destroy(&w);
            }
        printf("  %.2f    %.4f           %.4f      %.4f           %.4f\n", es[k], ach[0][0], ach[1][0], ach[0][1],
               ach[1][1]);
        ENSURE_REL(ach[0][0], es[k], 0.02);
        ENSURE_REL(ach[0][1], es[k], 0.02);
        ENSURE(ach[1][0] > es[k]);
    }
    /* the calibration itself (non-dimensional impact) */
    for (double e = 0.1; e < 0.95; e += 0.2)
        ENSURE_REL(dem_restitution_achieved(dem_damping_for_restitution(e, DEM_DAMPING_CALIBRATED)), e, 1e-6);
    return 0;
}

/* Oblique impact on a wall. Gross sliding (tan θ > 3.5 μ (1+e)): the
 * tangential impulse is μ (1+e) m v_n, so v_t' = v_t - μ(1+e)v_n and
 * ω' = 5 μ (1+e) v_n / (2 r). Below: tangential compliance, ω' smaller and the
 * contact-point velocity reversed or reduced. */
static int oblique_impact(void)
{
    const double mu = 0.3, e = 0.5, vn = 1.0;
    for (int regime = 0; regime < 2; regime++) {
        double vt = regime == 0 ? 5.0 : 0.3; /* tan θ = 5 vs 0.3; threshold 3.5 μ (1+e) = 1.575 */
        /* stiff grains: the friction torque acts at the contact point, r - delta
         * from the centre, and the rigid closed form assumes r; at E = 5e7 Pa
         * that lowers ω' by 2.5 %, at 5e9 Pa by 0.4 % */
        dem_material m = test_material(5e9, 0.3, e, mu);
        double mass = sphere_mass(m.density, R0);
        hertz_ref h = hertz_closed_form(e_star_same(&m), R0, mass, vn);
        dem_world *w = test_world(&m, 1, h.tc / 400, 1, NULL, 1);
        ENSURE(w);
        impact r;
        double v0[3] = {vt, 0, -vn};
        ENSURE(run_impact(w, 0, v0, &r) == 0);
        double e_ach = r.v_after[2] / vn;
        double w_slide = 5.0 * mu * (1.0 + e_ach) * vn / (2.0 * R0);
        double wy = r.w_after[1]; /* v_t along +x, normal +z: spin about +y... sign: */
        /* friction at the contact point (-r z) acts along -x: torque (-r z) x (-F x) = -r F (z x x)... */
        double wmag = fabs(wy);
        double vt_after = r.v_after[0];
        double slip_after = vt_after - wy * R0; /* contact point velocity: v + w x (-r z) = v_x - w_y r */
        if (regime == 0) {
            printf("oblique sliding: w' %.6g vs %.6g (%.3f %%), vt' %.6g vs %.6g, e %.4f\n", wmag, w_slide,
                   100 * (wmag / w_slide - 1), vt_after, vt - mu * (1 + e_ach) * vn, e_ach);
            ENSURE_REL(wmag, w_slide, 0.01);
            ENSURE_REL(vt_after, vt - mu * (1 + e_ach) * vn, 0.01);
        } else {
            printf("oblique sticking: w' r / (w_slide r) = %.4f, contact-point velocity ratio %.4f, e %.4f\n",
                   wmag / w_slide, slip_after / vt, e_ach);
            ENSURE(wmag < 0.99 * w_slide);
            ENSURE(slip_after / vt < 0.3 && slip_after / vt > -1.0);
            /* even sticking cannot exceed the rigid no-slip rolling spin for this v_t */
            ENSURE(wmag * R0 < vt * 1.0);
        }
        dem_world_destroy(&w);
    }
    return 0;
}

/* Sphere on a plane tilted by θ (gravity rotated). It rolls without slipping
 * (contact sticks) with a = 5/7 g sin θ while tan θ < 3.5 μ, and slides with
 * a = g (sin θ - μ cos θ) above. */
static int tilted_plane(void)
{
    const double mu = 0.2, gmag = 9.81;
    const double angles[] = {20.0, 30.0, 40.0, 55.0}; /* critical atan(0.7) = 35.0° */
    for (size_t k = 0; k < sizeof angles / sizeof angles[0]; k++) {
        double th = angles[k] * M_PI / 180.0;
        double g[3] = {gmag * sin(th), 0, -gmag * cos(th)};
        dem_material m = test_material(5e7, 0.3, 0.3, mu);
        dem_world *w = test_world(&m, 1, 2e-6, 1, g, 1);
        ENSURE(w);
        cm_error err = {0};
        double mass = sphere_mass(m.density, R0);
        double dstat = hertz_static_overlap(e_star_same(&m), R0, mass * gmag * cos(th));
        double x[3] = {0, 0, R0 - dstat}, p[3] = {0, 0, 0}, n[3] = {0, 0, 1};
        ENSURE(dem_grain_add(w, x, R0, 0, NULL, &err) == 0 && dem_wall_add(w, p, n, 0, &err) == 0);
        int n1 = 10000, n2 = 30000;
        for (int s = 0; s < n1; s++)
            ENSURE(dem_step(w, &err) == 0);
        dem_grain_state a, b;
        dem_grain_get(w, 0, &a);
        for (int s = 0; s < n2; s++)
            ENSURE(dem_step(w, &err) == 0);
        dem_grain_get(w, 0, &b);
        double acc = (b.v[0] - a.v[0]) / (n2 * 2e-6);
        double slip = b.v[0] - b.w[1] * R0;
        int sticks = tan(th) < 3.5 * mu;
        double ref = sticks ? 5.0 / 7.0 * gmag * sin(th) : gmag * (sin(th) - mu * cos(th));
        printf("tilted %.0f deg: %s, a = %.6g vs %.6g (%.3f %%), slip velocity %.3g m/s (v = %.3g)\n", angles[k],
               sticks ? "rolls (sticks)" : "slides", acc, ref, 100 * (acc / ref - 1), slip, b.v[0]);
        ENSURE_REL(acc, ref, 0.01);
        if (sticks)
            ENSURE(fabs(slip) < 1e-3 * fabs(b.v[0]));
        else
            ENSURE(slip > 0.05 * b.v[0]);
        dem_world_destroy(&w);
    }
    return 0;
}

/* No damping, no friction, no gravity: grains in a closed box keep their
 * kinetic energy between contacts (velocity Verlet is symplectic). On the
 * way, every step, the lean stats (the coupled run's health check) read the
 * same overlaps and kinetic energies as the full ones. */
static int energy_conservation(void)
{
    dem_material m = test_material(5e7, 0.3, 1.0, 0.0);
    dem_world_def d = dem_world_def_default();
    d.dt = 2e-6;
    d.max_grains = 40;
    d.gravity[2] = 0;
    d.impact_velocity = 2.0;
    dem_world *w = NULL;
    cm_error err = {0};
    ENSURE(dem_world_create(&d, 1, &m, &w, &err) == 0);
    const double L = 0.06;
    double walls[6][6] = {{0, 0, 0, 1, 0, 0}, {L, 0, 0, -1, 0, 0}, {0, 0, 0, 0, 1, 0},
                          {0, L, 0, 0, -1, 0}, {0, 0, 0, 0, 0, 1}, {0, 0, L, 0, 0, -1}};
    for (int k = 0; k < 6; k++)
        ENSURE(dem_wall_add(w, walls[k], walls[k] + 3, 0, &err) == 0);
    uint64_t s = 12345;
    for (int i = 0; i < 40; i++) {
        double x[3] = {0.008 + 0.011 * (i % 5), 0.008 + 0.011 * ((i / 5) % 5), 0.01 + 0.02 * (i / 25)};
        double v[3], om[3];
        for (int k = 0; k < 3; k++) {
            s = s * 6364136223846793005ULL + 1442695040888963407ULL;
            v[k] = ((double)(s >> 11) / 9007199254740992.0 - 0.5) * 2.0;
            om[k] = 0.0;
        }
        ENSURE(dem_grain_add(w, x, R0 * (0.8 + 0.01 * (i % 7)), 0, NULL, &err) == 0);
        dem_grain_set(w, i, NULL, v, om);
    }
    double e0 = -1, e1 = -1, emax = 0, emin = 1e300;
    int collisions = 0, was = 0, overlapping = 0;
    for (int step = 0; step < 100000; step++) {
        ENSURE(dem_step(w, &err) == 0);
        dem_stats st, lean;
        dem_world_stats(w, &st);
        /* the health check's lean stats: the same overlaps and kinetic
         * energies, no potential energies */
        dem_world_stats_lean(w, &lean);
        ENSURE(lean.max_overlap == st.max_overlap && lean.ke_trans == st.ke_trans && lean.ke_rot == st.ke_rot);
        ENSURE(lean.e_elastic == 0.0 && lean.pe_grav == 0.0);
        /* the health check a part at a time (dem_world_stats_part): the
         * parts' largest overlap is the whole's, their kinetic energies add
         * up to it (a part left out would miss a seventh), one part of one
         * is the whole, bit for bit */
        if (step % 50 == 0) {
            enum { PARTS = 7 };
            dem_stats part, one;
            double big = 0.0, ke = 0.0;
            for (int k = 0; k < PARTS; k++) {
                dem_world_stats_part(w, k, PARTS, &part);
                big = fmax(big, part.max_overlap);
                ke += part.ke_trans + part.ke_rot;
                ENSURE(part.grains == lean.grains && part.contacts_gg == lean.contacts_gg && part.step == lean.step);
            }
            ENSURE_MSG(big == lean.max_overlap, "step %d: parts' largest overlap %.17g, the whole's %.17g", step, big,
                       lean.max_overlap);
            ENSURE_MSG(fabs(ke - (lean.ke_trans + lean.ke_rot)) <= 1e-12 * (lean.ke_trans + lean.ke_rot),
                       "step %d: parts' kinetic energy %.17g, the whole's %.17g", step, ke,
                       lean.ke_trans + lean.ke_rot);
            dem_world_stats_part(w, 0, 1, &one);
            ENSURE(one.max_overlap == lean.max_overlap && one.ke_trans == lean.ke_trans && one.ke_rot == lean.ke_rot);
        }
        overlapping += st.max_overlap > 0.0 && st.e_elastic > 0.0;
        int c = st.contacts_gg + st.contacts_gw;
        collisions += c > 0 && !was;
        was = c > 0;
        if (c == 0) {
            double e = st.ke_trans + st.ke_rot;
            if (e0 < 0)
                e0 = e;
            e1 = e;
            emax = fmax(emax, e);
            emin = fmin(emin, e);
        }
    }
    printf("energy: %d contact episodes, KE between contacts %.9g -> %.9g (drift %.3g, spread %.3g)\n", collisions,
           e0, e1, e1 / e0 - 1, (emax - emin) / e0);
    ENSURE(collisions > 50);
    ENSURE(overlapping > 1000); /* the lean stats were compared while grains overlapped */
    ENSURE_REL(e1, e0, 1e-3);
    ENSURE((emax - emin) / e0 < 2e-3);
    dem_world_destroy(&w);
    return 0;
}

/* A dt above the Rayleigh/Hertz limit is refused with the limit in the
 * message, and accepted with allow_unstable. */
static int timestep_check(void)
{
    dem_material m = test_material(5e7, 0.3, 0.5, 0.5);
    for (int allow = 0; allow < 2; allow++) {
        dem_world_def d = dem_world_def_default();
        d.dt = 1e-3;
        d.max_grains = 1;
        d.allow_unstable = allow;
        dem_world *w = NULL;
        cm_error err = {0};
        ENSURE(dem_world_create(&d, 1, &m, &w, &err) == 0);
        double x[3] = {0, 0, 1};
        ENSURE(dem_grain_add(w, x, R0, 0, NULL, &err) == 0);
        int rc = dem_step(w, &err);
        double tr, th;
        dem_time_limits(w, &tr, &th);
        if (allow) {
            ENSURE(rc == CM_OK);
        } else {
            char lim[64];
            snprintf(lim, sizeof lim, "%g", fmin(0.3 * tr, 0.1 * th));
            ENSURE_MSG(rc == CM_ERR_RANGE && strstr(err.msg, lim) && strstr(err.msg, "allow_unstable_dt"), "%s",
                       err.msg);
            printf("refused: %s\n", err.msg);
        }
        dem_world_destroy(&w);
    }
    return 0;
}

/* Constant-torque rolling resistance stops a rolling sphere on a flat wall;
 * off by default (then it rolls on). Deceleration of the rolling sphere:
 * a = -μ_r g (5/7) (torque μ_r r m g against I + m r²). */
static int rolling_resistance(void)
{
    for (int on = 0; on < 2; on++) {
        dem_material m = test_material(5e7, 0.3, 0.3, 0.5);
        m.rolling_friction = on ? 0.05 : 0.0;
        double g[3] = {0, 0, -9.81};
        dem_world *w = test_world(&m, 1, 2e-6, 1, g, 1);
        ENSURE(w);
        cm_error err = {0};
        double mass = sphere_mass(m.density, R0);
        double dstat = hertz_static_overlap(e_star_same(&m), R0, mass * 9.81);
        double x[3] = {0, 0, R0 - dstat}, p[3] = {0, 0, 0}, n[3] = {0, 0, 1}, v[3] = {0.2, 0, 0},
               om[3] = {0, 0.2 / R0, 0};
        ENSURE(dem_grain_add(w, x, R0, 0, NULL, &err) == 0 && dem_wall_add(w, p, n, 0, &err) == 0);
        dem_grain_set(w, 0, NULL, v, om);
        for (int s = 0; s < 5000; s++)
            ENSURE(dem_step(w, &err) == 0);
        dem_grain_state a, b;
        dem_grain_get(w, 0, &a);
        for (int s = 0; s < 10000; s++)
            ENSURE(dem_step(w, &err) == 0);
        dem_grain_get(w, 0, &b);
        double acc = (b.v[0] - a.v[0]) / (10000 * 2e-6);
        double ref = on ? -m.rolling_friction * 9.81 * 5.0 / 7.0 : 0.0;
        printf("rolling resistance %s: a = %.6g vs %.6g\n", on ? "on" : "off", acc, ref);
        if (on)
            ENSURE_REL(acc, ref, 0.02);
        else
            ENSURE(fabs(acc) < 1e-3);
        dem_world_destroy(&w);
    }
    return 0;
}

/* A sphere on a floor under gravity tilted by th (a slope), rolling
 * resistance mu_r of the given model, sliding friction high enough to roll
 * without slip. The mean x position over [t0, t0 + win) and over
 * [t1, t1 + win) (a held grain rocks on its springs: the means show the
 * drift), and the x velocity at t0 + win and at t1 + win. */
static int slope_run(int model, double dt, double th, double mu_r, double t0, double t1, double win, double mean[2],
                     double vel[2])
{
    dem_material m = test_material(5e7, 0.3, 0.3, 1.0);
    m.rolling_friction = mu_r;
    dem_world_def d = dem_world_def_default();
    d.dt = dt;
    d.max_grains = 1;
    d.rolling_model = model;
    d.gravity[0] = 9.81 * sin(th), d.gravity[2] = -9.81 * cos(th);
    dem_world *w = NULL;
    cm_error err = {0};
    ENSURE_MSG(dem_world_create(&d, 1, &m, &w, &err) == 0, "%s", err.msg);
    double mass = sphere_mass(m.density, R0);
    double dstat = hertz_static_overlap(e_star_same(&m), R0, mass * 9.81 * cos(th));
    double x[3] = {0, 0, R0 - dstat}, p[3] = {0, 0, 0}, n[3] = {0, 0, 1};
    ENSURE(dem_grain_add(w, x, R0, 0, NULL, &err) == 0 && dem_wall_add(w, p, n, 0, &err) == 0);
    const double from[2] = {t0, t1};
    long step = 0;
    for (int k = 0; k < 2; k++) {
        for (; step * dt < from[k]; step++)
            ENSURE(dem_step(w, &err) == 0);
        double sum = 0.0;
        long cnt = 0;
        dem_grain_state g;
        for (; step * dt < from[k] + win; step++, cnt++) {
            ENSURE(dem_step(w, &err) == 0);
            dem_grain_get(w, 0, &g);
            sum += g.x[0];
        }
        mean[k] = sum / (double)cnt;
        vel[k] = g.v[0];
    }
    dem_world_destroy(&w);
    return 0;
}

/* Below the rolling limit (tan th = 0.8 mu_r) the spring model holds the
 * grain on the slope at two steps: once the start's transient has died out
 * (it moves the grain ~0.01 um within 0.06 s) no drift between two windows
 * 0.1 s apart (bound 1 nm). The constant torque cannot hold a torque at
 * rest: the same grain creeps at a speed proportional to the step (dem.h;
 * the reason the spring exists), ~1e-5 m/s here. */
static int rolling_spring_holds_on_slope(void)
{
    const double mu_r = 0.3, th = atan(0.8 * mu_r);
    double creep[2];
    for (int k = 0; k < 2; k++) {
        const double dt = k ? 4e-6 : 2e-6;
        double mean[2], vel[2], cm[2], cv[2];
        ENSURE(slope_run(DEM_ROLLING_SPRING, dt, th, mu_r, 0.1, 0.2, 0.01, mean, vel) == 0);
        ENSURE(slope_run(DEM_ROLLING_CONSTANT_TORQUE, dt, th, mu_r, 0.1, 0.2, 0.01, cm, cv) == 0);
        creep[k] = (cm[1] - cm[0]) / 0.1;
        printf("dt %g s: spring drift %.3g m (v %.3g m/s); constant torque creeps at %.4g m/s\n", dt,
               mean[1] - mean[0], vel[1], creep[k]);
        ENSURE(fabs(mean[1] - mean[0]) < 1e-9);
        ENSURE(creep[k] > 1e-6); /* 1e-6 m/s: 100x what the bound above allows the spring */
    }
    printf("constant torque: creep ratio %.3f for a step ratio of 2\n", creep[1] / creep[0]);
    ENSURE_REL(creep[1] / creep[0], 2.0, 0.1);
    return 0;
}

/* Above the limit (tan th = 2 mu_r) the sphere rolls with the capped torque,
 * at the same acceleration under either model:
 * a = (5/7) g (sin th - mu_r cos th) (torque mu_r r m g cos th against
 * I + m r^2). */
static int rolling_spring_rolls_above_limit(void)
{
    const double mu_r = 0.1, th = atan(2.0 * mu_r);
    const double ref = 5.0 / 7.0 * 9.81 * (sin(th) - mu_r * cos(th));
    for (int model = 0; model < 2; model++) {
        double mean[2], vel[2];
        ENSURE(slope_run(model, 2e-6, th, mu_r, 0.01, 0.05, 1e-5, mean, vel) == 0);
        double acc = (vel[1] - vel[0]) / 0.04;
        printf("%s: a = %.6g vs %.6g m/s^2 (%.3f %%)\n", model ? "spring" : "constant torque", acc, ref,
               100 * (acc / ref - 1));
        ENSURE_REL(acc, ref, 0.01);
    }
    return 0;
}

/* A sphere spinning about the vertical on a floor: both rolling models resist
 * the twist with the capped torque mu_r r m g, so the spin falls linearly:
 * omega(t) = omega0 - mu_r r m g t / I, half of omega0 at
 * t = I omega0 / (2 mu_r r m g). (Without it a grain spinning on its one
 * contact, as the toe of a collapsed heap leaves some, never stops.) */
static int rolling_spring_resists_twist(void)
{
    const double mu_r = 0.1, om0 = 50.0;
    for (int model = 0; model < 2; model++) {
        dem_material m = test_material(5e7, 0.3, 0.3, 0.5);
        m.rolling_friction = mu_r;
        dem_world_def d = dem_world_def_default();
        d.dt = 2e-6;
        d.max_grains = 1;
        d.rolling_model = model;
        d.gravity[2] = -9.81;
        dem_world *w = NULL;
        cm_error err = {0};
        ENSURE_MSG(dem_world_create(&d, 1, &m, &w, &err) == 0, "%s", err.msg);
        double mass = sphere_mass(m.density, R0);
        double dstat = hertz_static_overlap(e_star_same(&m), R0, mass * 9.81);
        double x[3] = {0, 0, R0 - dstat}, p[3] = {0, 0, 0}, n[3] = {0, 0, 1}, om[3] = {0, 0, om0};
        ENSURE(dem_grain_add(w, x, R0, 0, NULL, &err) == 0 && dem_wall_add(w, p, n, 0, &err) == 0);
        dem_grain_set(w, 0, NULL, NULL, om);
        /* the wall's mu_r is the mean of the two materials' (one here) */
        const double t_half = 0.4 * mass * R0 * R0 * om0 / (2.0 * mu_r * R0 * mass * 9.81);
        for (long s = 0; s < lround(t_half / d.dt); s++)
            ENSURE(dem_step(w, &err) == 0);
        dem_grain_state g;
        dem_grain_get(w, 0, &g);
        printf("%s: spin %.5g rad/s at t = %.4g s (closed form %.5g)\n", model ? "spring" : "constant torque", g.w[2],
               t_half, 0.5 * om0);
        ENSURE_REL(g.w[2], 0.5 * om0, 0.01);
        dem_world_destroy(&w);
    }
    return 0;
}

/* Tangential springs survive neighbour-list rebuilds and the re-sorting of
 * grains in memory: a chain of grains sheared against each other gives
 * bit-identical results with a rebuild + re-sort forced at every step and
 * with none. */
static int history_survives_rebuild(void)
{
    double out[2][4][9];
    for (int forced = 0; forced < 2; forced++) {
        dem_material m = test_material(5e7, 0.3, 0.5, 0.4);
        dem_world_def d = dem_world_def_default();
        d.dt = 2e-6;
        d.max_grains = 4;
        d.gravity[2] = 0;
        d.reorder_every = forced ? 1 : 0;
        d.skin = forced ? 1e-9 : 0.01;
        dem_world *w = NULL;
        cm_error err = {0};
        ENSURE(dem_world_create(&d, 1, &m, &w, &err) == 0);
        for (int i = 0; i < 4; i++) { /* added in reverse x order so that a re-sort moves them */
            double x[3] = {(3 - i) * 1.98 * R0, 0.001 * i, 0}, v[3] = {-0.02 * (3 - i), 0.05 * (i % 2 ? 1 : -1), 0};
            ENSURE(dem_grain_add(w, x, R0, 0, NULL, &err) == 0);
            dem_grain_set(w, i, NULL, v, NULL);
        }
        for (int s = 0; s < 3000; s++) {
            if (forced) { /* same position: only forces a rebuild (and a re-sort) */
                dem_grain_state g;
                dem_grain_get(w, s % 4, &g);
                dem_grain_set(w, s % 4, g.x, NULL, NULL);
            }
            ENSURE(dem_step(w, &err) == 0);
        }
        dem_stats st;
        dem_world_stats(w, &st);
        printf("%s: %ld rebuilds, %d contacts at the end\n", forced ? "forced" : "none", st.profile.rebuilds,
               st.contacts_gg);
        if (forced)
            ENSURE(st.profile.rebuilds >= 3000);
        for (int i = 0; i < 4; i++) {
            dem_grain_state g;
            dem_grain_get(w, i, &g);
            memcpy(out[forced][i], g.x, sizeof g.x);
            memcpy(out[forced][i] + 3, g.v, sizeof g.v);
            memcpy(out[forced][i] + 6, g.w, sizeof g.w);
        }
        dem_world_destroy(&w);
    }
    ENSURE(fabs(out[0][0][6]) + fabs(out[0][1][8]) + fabs(out[0][2][8]) > 1.0); /* friction acted */
    ENSURE(memcmp(out[0], out[1], sizeof out[0]) == 0);
    return 0;
}

/* Grain s against wall (p, n) by the scalar rules of dem_contact.h, as one
 * loop over a grain's walls applies them: the force and torque on the
 * grain (the wall: R* = r, m* = m, lever to the contact point on the plane),
 * the spring xi[6] (tangential, then rolling) updated; 0 if apart (xi
 * cleared). */
static int wall_contact_ref(const dem_pair_coef *cf, int model, const dem_grain_state *s, const double p[3],
                            const double n[3], double dt, double xi[6], vec3 *F, vec3 *T)
{
    vec3 nrm = v3_load(n);
    double dist = (s->x[0] - p[0]) * nrm.x + (s->x[1] - p[1]) * nrm.y + (s->x[2] - p[2]) * nrm.z;
    double delta = s->radius - dist;
    if (delta <= 0.0) {
        memset(xi, 0, 6 * sizeof *xi);
        return 0;
    }
    const double inv_i = 1.0 / s->inertia[0]; /* the world's 1 / (0.4 m r^2) */
    vec3 lever = v3_scale(nrm, -dist), wi = v3_load(s->w);
    vec3 vrel = v3_add(v3_load(s->v), v3_cross(wi, lever));
    double fn;
    *F = dem_hm_force(cf, nrm, delta, s->radius, s->mass, vrel, dt, xi, &fn);
    vec3 Tr = model != DEM_ROLLING_SPRING ? dem_rolling_torque(cf, s->radius, fn, wi, 1.0 / inv_i, dt)
              : cf->mu_roll > 0.0
                  ? dem_rolling_spring(cf, s->radius, delta, fn, wi, DEM_SPHERE_ROLL_INERTIA / inv_i, dt, xi + 3)
                  : v3(0, 0, 0);
    *T = v3_add(v3_cross(lever, *F), Tr);
    return 1;
}

/* The walls' batched kernel (both of its builds) gives the bits of the scalar
 * rules, step after step: 80 grains apart from each other on a floor, every
 * other one against a side wall too (120 contacts, batches of 64), spinning
 * and sliding at assorted speeds, without rolling resistance, with the
 * constant torque and with the rolling spring. */
static int walls_batched_as_scalar(void)
{
    const int N = 80, steps = 40;
    const double dt = 2e-6, p[2][3] = {{0, 0, 0}, {0, 0, 0}}, n[2][3] = {{0, 0, 1}, {1, 0, 0}};
    double spin[4]; /* the grains' summed |torque z| at the end: the rolling resistance must act */
    for (int variant = 0; variant < 4; variant++) {
        const int model = variant == 3 ? DEM_ROLLING_SPRING : DEM_ROLLING_CONSTANT_TORQUE;
        dem_material m = test_material(5e7, 0.3, 0.3, 0.4);
        m.rolling_friction = variant == 0 ? 0.0 : 0.05;
        dem_world_def d = dem_world_def_default();
        d.dt = dt, d.max_grains = N, d.threads = 1, d.rolling_model = model;
        d.gravity[0] = d.gravity[1] = d.gravity[2] = 0.0;
        /* the constant torque once more, on the portable build */
        d.kernels = variant == 2 ? DEM_KERNELS_PORTABLE : DEM_KERNELS_AUTO;
        dem_world *w = NULL;
        cm_error err = {0};
        ENSURE(dem_world_create(&d, 1, &m, &w, &err) == 0);
        for (int k = 0; k < 2; k++)
            ENSURE(dem_wall_add(w, p[k], n[k], 0, &err) == 0);
        for (int i = 0; i < N; i++) {
            const double oz = R0 * (0.002 + 0.004 * (i % 7) / 6.0), ox = R0 * 0.003 * (1 + i % 3);
            double x[3] = {i % 2 ? 4 * R0 : R0 - ox, 3 * R0 * i, R0 - oz};
            const double sp = i % 3 ? 1.0 : 0.002; /* every third one slow: its springs hold */
            double v[3] = {sp * 0.3 * sin(i), sp * 0.3 * cos(1.7 * i), -0.02 * (i % 4)};
            double om[3] = {sp * 40 * cos(i), sp * 30 * sin(2.3 * i), sp * 50 * sin(0.7 * i)};
            ENSURE(dem_grain_add(w, x, R0, 0, NULL, &err) == 0);
            ENSURE(dem_grain_set(w, i, NULL, v, om) == 0);
        }
        dem_pair_coef cf; /* as dem_world_create makes it */
        dem_pair_coef_make(&m, &m, &cf);
        cf.gamma_n = cf.gamma_t = dem_damping_for_restitution(cf.e, d.damping);
        static double xi[80][2][6];
        memset(xi, 0, sizeof xi);
        int contacts = 0, sliding = 0, sticking = 0;
        spin[variant] = 0.0;
        for (int s = 0; s < steps; s++) {
            dem_grain_state before[80];
            for (int i = 0; i < N; i++)
                ENSURE(dem_grain_get(w, i, &before[i]) == 0);
            ENSURE(dem_step(w, &err) == 0);
            for (int i = 0; i < N; i++) {
                double f[3] = {0.0, 0.0, 0.0}, t[3] = {0.0, 0.0, 0.0}; /* gravity: m 0 = +0 */
                for (int k = 0; k < 2; k++) {
                    vec3 F, T;
                    if (!wall_contact_ref(&cf, model, &before[i], p[k], n[k], dt, xi[i][k], &F, &T))
                        continue;
                    contacts += s == 0;
                    f[0] += F.x, f[1] += F.y, f[2] += F.z;
                    t[0] += T.x, t[1] += T.y, t[2] += T.z;
                    vec3 nk = v3_load(n[k]), ft = v3_sub(F, v3_scale(nk, v3_dot(F, nk)));
                    double fnk = v3_dot(F, nk);
                    sliding += s == steps - 1 && v3_norm(ft) >= 0.999 * cf.mu * fnk;
                    sticking += s == steps - 1 && v3_norm(ft) < 0.9 * cf.mu * fnk;
                }
                dem_grain_state after;
                ENSURE(dem_grain_get(w, i, &after) == 0);
                spin[variant] += s == steps - 1 ? fabs(after.t[2]) : 0.0;
                if (memcmp(f, after.f, sizeof f) || memcmp(t, after.t, sizeof t)) {
                    printf("variant %d step %d grain %d: force %.17g %.17g %.17g torque %.17g %.17g %.17g, the "
                           "scalar rules %.17g %.17g %.17g, %.17g %.17g %.17g\n",
                           variant, s, i, after.f[0], after.f[1], after.f[2], after.t[0], after.t[1], after.t[2],
                           f[0], f[1], f[2], t[0], t[1], t[2]);
                    ENSURE(0);
                }
            }
        }
        printf("variant %d: %d grain-wall contacts, %d sliding and %d sticking at the end, sum |T_z| %.6g N m, "
               "%d steps bit for bit\n",
               variant, contacts, sliding, sticking, spin[variant], steps);
        ENSURE(contacts == N + N / 2);
        ENSURE(sliding > 5 && sticking > 5);
        dem_world_destroy(&w);
    }
    ENSURE(spin[1] == spin[2]); /* the two builds */
    ENSURE(fabs(spin[1] - spin[0]) > 0.01 * spin[0] && fabs(spin[3] - spin[0]) > 0.01 * spin[0]);
    return 0;
}

static const test_case tests[] = {
    {"history_survives_rebuild", history_survives_rebuild},
    {"hertz_sphere_sphere", hertz_sphere_sphere},
    {"hertz_sphere_wall", hertz_sphere_wall},
    {"restitution_sweep", restitution_sweep},
    {"oblique_impact", oblique_impact},
    {"tilted_plane", tilted_plane},
    {"energy_conservation", energy_conservation},
    {"timestep_check", timestep_check},
    {"rolling_resistance", rolling_resistance},
    {"rolling_spring_holds_on_slope", rolling_spring_holds_on_slope},
    {"rolling_spring_rolls_above_limit", rolling_spring_rolls_above_limit},
    {"rolling_spring_resists_twist", rolling_spring_resists_twist},
    {"walls_batched_as_scalar", walls_batched_as_scalar},
};

int main(int argc, char **argv) { return test_main(argc, argv, tests, TEST_COUNT(tests)); }
