/* Triangle surface: closest points, de-duplication on shared edges and
 * vertices, wall-equivalence, history across triangle edges, and the
 * barycentric force transfer (eq. 42). */
#include <stdlib.h>

#include "dem_bed.h"
#include "dem_surface.h"
#include "dem_world.h"
#include "test_dem_common.h"

static const double R0 = 0.005;

static int closest_point_regions(void)
{
    double a[3] = {0, 0, 0}, b[3] = {1, 0, 0}, c[3] = {0, 1, 0}, w[3], p[3];
    struct {
        double q[3];
        int region;
        double cp[3];
    } cases[] = {
        {{0.2, 0.2, 1}, 0, {0.2, 0.2, 0}},   {{0.5, -1, 0.5}, 1, {0.5, 0, 0}}, {{1, 1, -2}, 2, {0.5, 0.5, 0}},
        {{-1, 0.5, 0}, 3, {0, 0.5, 0}},      {{-1, -1, 3}, 4, {0, 0, 0}},      {{2, -0.5, 0}, 5, {1, 0, 0}},
        {{-0.5, 2, 1}, 6, {0, 1, 0}},
    };
    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
        int r = dem_closest_on_triangle(cases[k].q, a, b, c, w, p);
        ENSURE_MSG(r == cases[k].region, "case %zu: region %d, expected %d", k, r, cases[k].region);
        for (int i = 0; i < 3; i++)
            ENSURE_NEAR(p[i], cases[k].cp[i], 1e-14);
        ENSURE_NEAR(w[0] + w[1] + w[2], 1.0, 1e-14);
    }
    return 0;
}

/* World with either a wall z = 0 or a 12 x 12-square plane of triangles of
 * side s (s < r: a grain touches up to a dozen triangles). */
static dem_world *plane_world(int tri, double s, double dt, const double g[3], double e, double mu)
{
    dem_material m = test_material(5e7, 0.3, e, mu);
    dem_world *w = test_world(&m, 1, dt, 4, g, 1);
    if (!w)
        return NULL;
    cm_error err = {0};
    if (!tri) {
        double p[3] = {0, 0, 0}, n[3] = {0, 0, 1};
        dem_wall_add(w, p, n, 0, &err);
        return w;
    }
    int nx = 12;
    double *x = malloc(sizeof(double) * 3 * (nx + 1) * (nx + 1));
    int *t = malloc(sizeof(int) * 6 * nx * nx);
    test_plane_mesh(nx, nx, s, -nx * s / 2, -nx * s / 2, 0.0, x, t);
    int rc = dem_surface_set(w, (nx + 1) * (nx + 1), x, 2 * nx * nx, t, 0, &err);
    free(x);
    free(t);
    if (rc) {
        fprintf(stderr, "%s\n", err.msg);
        dem_world_destroy(&w);
    }
    return w;
}

/* Resting force of a grain pressed into a triangulated plane equals the
 * wall's, wherever it sits: face interiors, edges, vertices. */
static int resting_force_anywhere(void)
{
    const double s = 0.6 * R0, delta = 1e-3 * R0;
    dem_world *ww = plane_world(0, s, 1e-6, NULL, 0.5, 0.5);
    ENSURE(ww);
    cm_error err = {0};
    double x[3] = {0, 0, R0 - delta};
    ENSURE(dem_grain_add(ww, x, R0, 0, NULL, &err) == 0);
    ENSURE(dem_step_surface(ww, &err) == 0);
    dem_grain_state ref;
    dem_grain_get(ww, 0, &ref);
    ENSURE(ref.f[2] > 0);
    double offsets[][2] = {{0, 0},         {0.5 * s, 0},     {0.5 * s, 0.5 * s}, {0.25 * s, 0.6 * s}, {s, s},
                           {s, 0.3 * s},  {0.3 * s, 0.3 * s}, {1e-13, 0},       {0, 1e-13},         {0.7 * s, 0.3 * s}};
    uint64_t rs = 99;
    double worst = 0;
    for (int k = 0; k < 60; k++) {
        double ox, oy;
        if (k < (int)(sizeof offsets / sizeof offsets[0])) {
            ox = offsets[k][0], oy = offsets[k][1];
        } else {
            rs = rs * 6364136223846793005ULL + 1442695040888963407ULL;
            ox = 2 * s * ((double)(rs >> 11) / 9007199254740992.0 - 0.5);
            rs = rs * 6364136223846793005ULL + 1442695040888963407ULL;
            oy = 2 * s * ((double)(rs >> 11) / 9007199254740992.0 - 0.5);
        }
        dem_world *wt = plane_world(1, s, 1e-6, NULL, 0.5, 0.5);
        ENSURE(wt);
        double xt[3] = {ox, oy, R0 - delta};
        ENSURE(dem_grain_add(wt, xt, R0, 0, NULL, &err) == 0);
        ENSURE(dem_step_surface(wt, &err) == 0);
        dem_grain_state g;
        dem_grain_get(wt, 0, &g);
        dem_surface_total tot;
        dem_surface_totals(wt, &tot);
        ENSURE_MSG(tot.contacts == 1, "grain at (%g, %g) s: %d contacts", ox / s, oy / s, tot.contacts);
        ENSURE_REL(g.f[2], ref.f[2], 1e-9);
        ENSURE_NEAR(g.f[0], 0.0, 1e-9 * ref.f[2]);
        ENSURE_NEAR(g.f[1], 0.0, 1e-9 * ref.f[2]);
        worst = fmax(worst, fabs(g.f[2] / ref.f[2] - 1));
        dem_world_destroy(&wt);
    }
    printf("resting force on triangles vs wall: worst relative difference %.3g over 60 positions\n", worst);
    dem_world_destroy(&ww);
    return 0;
}

/* Oblique drop with friction onto the wall and onto the triangle plane at
 * several positions: same rebound (velocity and spin) — the grain slides
 * across several triangle edges during the contact, so this also checks
 * that the tangential history survives them. */
static int rebound_wall_vs_triangles(void)
{
    const double s = 0.6 * R0;
    double v0[3] = {0.3, 0.2, -1.0};
    double res[2][6];
    double start[][2] = {{0, 0}, {0.5 * s, 0}, {s, s}, {0.3 * s, 0.7 * s}};
    double worst = 0;
    for (size_t k = 0; k < sizeof start / sizeof start[0]; k++) {
        for (int tri = 0; tri < 2; tri++) {
            dem_world *w = plane_world(tri, s, 2e-6, NULL, 0.5, 0.3);
            ENSURE(w);
            cm_error err = {0};
            double x[3] = {start[k][0], start[k][1], R0 * 1.0001};
            ENSURE(dem_grain_add(w, x, R0, 0, NULL, &err) == 0);
            dem_grain_set(w, 0, NULL, v0, NULL);
            int seen = 0;
            for (int st = 0; st < 100000; st++) {
                ENSURE(dem_step(w, &err) == 0);
                dem_grain_state g;
                dem_grain_get(w, 0, &g);
                if (g.x[2] < R0)
                    seen = 1;
                else if (seen)
                    break;
            }
            dem_grain_state g;
            dem_grain_get(w, 0, &g);
            memcpy(res[tri], g.v, sizeof g.v);
            memcpy(res[tri] + 3, g.w, sizeof g.w);
            dem_world_destroy(&w);
        }
        for (int i = 0; i < 6; i++) {
            double scale = i < 3 ? 1.0 : 1.0 / R0;
            ENSURE_NEAR(res[1][i], res[0][i], 1e-9 * scale);
            worst = fmax(worst, fabs(res[1][i] - res[0][i]) / scale);
        }
    }
    printf("rebound wall vs triangles: v' = (%.6f, %.6f, %.6f), w' = (%.3f, %.3f, %.3f), worst diff %.3g\n", res[0][0],
           res[0][1], res[0][2], res[0][3], res[0][4], res[0][5], worst);
    ENSURE(res[0][2] > 0.4 && fabs(res[0][4]) > 1.0); /* it bounced and spun */
    return 0;
}

/* A grain rolling for a long time across many triangles (rotation on,
 * gravity on) follows the same path as on the analytic wall. */
static int rolling_across_edges(void)
{
    const double s = 0.6 * R0;
    double g[3] = {0, 0, -9.81};
    double out[2][3];
    for (int tri = 0; tri < 2; tri++) {
        dem_world *w = plane_world(tri, s, 2e-6, g, 0.3, 0.5);
        ENSURE(w);
        cm_error err = {0};
        double x[3] = {-0.01, -0.005, R0 - 2e-7}, v[3] = {0.1, 0.05, 0}, om[3] = {0, 0, 0};
        ENSURE(dem_grain_add(w, x, R0, 0, NULL, &err) == 0);
        dem_grain_set(w, 0, NULL, v, om);
        for (int st = 0; st < 50000; st++)
            ENSURE(dem_step(w, &err) == 0);
        dem_grain_state gs;
        dem_grain_get(w, 0, &gs);
        memcpy(out[tri], gs.x, sizeof gs.x);
        dem_world_destroy(&w);
    }
    printf("rolling across edges: end (%.9f, %.9f) wall vs (%.9f, %.9f) triangles\n", out[0][0], out[0][1], out[1][0],
           out[1][1]);
    ENSURE(out[0][0] - (-0.01) > 0.006); /* it travelled over a few triangles (s = 3 mm) */
    for (int i = 0; i < 3; i++)
        ENSURE_NEAR(out[1][i], out[0][i], 1e-9);
    return 0;
}

/* Node-force resultant and moment equal the per-contact totals; the totals
 * equal minus the forces on the grains; T_H + T_R = F . travel. A curved,
 * moving surface with several grains in contact. */
static int node_force_balance(void)
{
    dem_material m = test_material(5e7, 0.3, 0.5, 0.5);
    dem_world *w = test_world(&m, 1, 1e-6, 64, NULL, 2);
    ENSURE(w);
    cm_error err = {0};
    int nx = 10, nn = (nx + 1) * (nx + 1);
    const double s = 0.004;
    double *x = malloc(sizeof(double) * 3 * nn), *v = malloc(sizeof(double) * 3 * nn);
    int *t = malloc(sizeof(int) * 6 * nx * nx);
    test_plane_mesh(nx, nx, s, -0.02, -0.02, 0.0, x, t);
    for (int i = 0; i < nn; i++) { /* a bump, and a rigid rotation + translation velocity */
        double *p = x + 3 * i;
        p[2] = 0.004 * cos(60 * p[0]) * cos(50 * p[1]);
        v[3 * i] = 0.1 - 3.0 * p[1], v[3 * i + 1] = 3.0 * p[0], v[3 * i + 2] = 0.05;
    }
    ENSURE(dem_surface_set(w, nn, x, 2 * nx * nx, t, 0, &err) == 0);
    ENSURE(dem_surface_update(w, x, v, &err) == 0);
    double ref[3] = {0.01, -0.02, 0.05}, dir[3] = {1, 1, 0};
    dem_surface_set_frame(w, ref, dir);
    uint64_t rs = 7;
    int added = 0;
    for (int k = 0; k < 400 && added < 40; k++) {
        double q[3];
        for (int c = 0; c < 2; c++) {
            rs = rs * 6364136223846793005ULL + 1442695040888963407ULL;
            q[c] = 0.034 * ((double)(rs >> 11) / 9007199254740992.0 - 0.5);
        }
        q[2] = 0.004 * cos(60 * q[0]) * cos(50 * q[1]) + 0.8 * R0 * (k % 2 ? 1 : -1);
        int ok = 1;
        for (int j = 0; j < added && ok; j++) {
            dem_grain_state o;
            dem_grain_get(w, j, &o);
            double dx = o.x[0] - q[0], dy = o.x[1] - q[1], dz = o.x[2] - q[2];
            ok = dx * dx + dy * dy + dz * dz > 4 * R0 * R0;
        }
        if (!ok)
            continue;
        ENSURE(dem_grain_add(w, q, R0, 0, NULL, &err) == 0);
        double gv[3] = {0.1 * (k % 3), -0.2, 0.3}, gw[3] = {5, -3, 2};
        dem_grain_set(w, added, NULL, gv, gw);
        added++;
    }
    ENSURE(dem_step_surface(w, &err) == 0);
    dem_surface_total tot;
    dem_surface_totals(w, &tot);
    const double *nf = dem_surface_node_forces(w);
    double F[3] = {0, 0, 0}, M[3] = {0, 0, 0}, G[3] = {0, 0, 0}, fmag = 0;
    for (int i = 0; i < nn; i++) {
        const double *p = x + 3 * i, *f = nf + 3 * i;
        double r[3] = {p[0] - ref[0], p[1] - ref[1], p[2] - ref[2]};
        F[0] += f[0], F[1] += f[1], F[2] += f[2];
        M[0] += r[1] * f[2] - r[2] * f[1];
        M[1] += r[2] * f[0] - r[0] * f[2];
        M[2] += r[0] * f[1] - r[1] * f[0];
    }
    for (int j = 0; j < added; j++) {
        dem_grain_state g;
        dem_grain_get(w, j, &g);
        for (int c = 0; c < 3; c++)
            G[c] += g.f[c];
        fmag += sqrt(g.f[0] * g.f[0] + g.f[1] * g.f[1] + g.f[2] * g.f[2]);
    }
    printf("node balance: %d grains, %d contacts, |F| sum %.4g N, resultant (%.6g %.6g %.6g) vs totals (%.6g %.6g %.6g)\n",
           added, tot.contacts, fmag, F[0], F[1], F[2], tot.force[0], tot.force[1], tot.force[2]);
    ENSURE(tot.contacts >= 10);
    for (int c = 0; c < 3; c++) {
        ENSURE_NEAR(F[c], tot.force[c], 1e-12 * fmag);
        ENSURE_NEAR(M[c], tot.moment[c], 1e-12 * fmag * 0.05);
        ENSURE_NEAR(tot.force[c], -G[c], 1e-12 * fmag);
    }
    double along = (tot.force[0] + tot.force[1]) / sqrt(2.0);
    ENSURE_NEAR(tot.traction_pos + tot.traction_neg, along, 1e-12 * fmag);
    ENSURE(tot.traction_pos >= 0 && tot.traction_neg <= 0);
    free(x), free(v), free(t);
    dem_world_destroy(&w);
    return 0;
}

/* Moving the surface with dem_surface_update refits the tree: a plane
 * lifted into a grain finds it. Non-finite node data is refused. */
static int surface_update_refit(void)
{
    dem_world *w = plane_world(1, 0.6 * R0, 1e-6, NULL, 0.5, 0.5);
    ENSURE(w);
    cm_error err = {0};
    double q[3] = {0.003, 0.002, R0 + 0.01};
    ENSURE(dem_grain_add(w, q, R0, 0, NULL, &err) == 0);
    ENSURE(dem_step_surface(w, &err) == 0);
    dem_surface_total tot;
    dem_surface_totals(w, &tot);
    ENSURE(tot.contacts == 0);
    int nx = 12, nn = (nx + 1) * (nx + 1);
    double *x = malloc(sizeof(double) * 3 * nn);
    int *t = malloc(sizeof(int) * 6 * nx * nx);
    test_plane_mesh(nx, nx, 0.6 * R0, -nx * 0.6 * R0 / 2, -nx * 0.6 * R0 / 2, 0.01 + 1e-4, x, t);
    ENSURE(dem_surface_update(w, x, NULL, &err) == 0);
    ENSURE(dem_step_surface(w, &err) == 0);
    dem_surface_totals(w, &tot);
    ENSURE(tot.contacts == 1 && tot.force[2] < 0);
    x[7] = NAN;
    ENSURE(dem_surface_update(w, x, NULL, &err) == CM_ERR_NUMERIC && strstr(err.msg, "node 2"));
    free(x), free(t);
    dem_world_destroy(&w);
    return 0;
}

/* A rigid triangulated plate pushed down into a small settled bed through
 * dem_surface_update, as the coupling will drive the tire: the grains push
 * back (force on the surface +z, growing with sinkage), node forces balance
 * the totals at every step, and no grain ends up above the plate. */
static int plate_sinkage(void)
{
    dem_material m = test_material(5e6, 0.3, 0.3, 0.5);
    double g[3] = {0, 0, -9.81};
    dem_world *w = test_world(&m, 1, 4e-5, 400, g, 2);
    ENSURE(w);
    cm_error err = {0};
    dem_bed_params p = dem_bed_params_default();
    double hi[3] = {0.04, 0.04, 0.2};
    memcpy(p.box_max, hi, sizeof hi);
    p.n_layers = 1;
    p.layers[0].count = 400;
    p.layers[0].radius[0] = 1.8e-3, p.layers[0].radius[1] = 2.2e-3;
    p.settle_ke = 1e-8;
    p.settle_min_time = 0.1;
    bool loaded;
    ENSURE_MSG(dem_bed_build(w, &p, NULL, NULL, &loaded, &err) == 0, "%s", err.msg);
    double h = 0; /* start above the highest grain */
    for (int i = 0; i < dem_grain_count(w); i++) {
        dem_grain_state gs;
        dem_grain_get(w, i, &gs);
        h = fmax(h, gs.x[2] + gs.radius);
    }
    int nx = 10, nn = (nx + 1) * (nx + 1);
    double *x = malloc(sizeof(double) * 3 * nn), *v = malloc(sizeof(double) * 3 * nn);
    int *t = malloc(sizeof(int) * 6 * nx * nx);
    const double z0 = h + 0.001, vz = -0.1;
    test_plane_mesh(nx, nx, 0.003, 0.005, 0.005, z0, x, t);
    ENSURE(dem_surface_set(w, nn, x, 2 * nx * nx, t, 0, &err) == 0);
    double ref[3] = {0.02, 0.02, z0}, dir[3] = {1, 0, 0};
    dem_surface_set_frame(w, ref, dir);
    for (int i = 0; i < nn; i++)
        v[3 * i] = v[3 * i + 1] = 0.0, v[3 * i + 2] = vz;
    double f_half = 0, f_end = 0, worst = 0;
    const int steps = 2000; /* 8 mm down */
    for (int s = 0; s < steps; s++) {
        double z = z0 + vz * s * 4e-5;
        for (int i = 0; i < nn; i++)
            x[3 * i + 2] = z;
        ENSURE(dem_surface_update(w, x, v, &err) == 0);
        ENSURE(dem_step_surface(w, &err) == 0);
        dem_surface_total tot;
        dem_surface_totals(w, &tot);
        const double *nf = dem_surface_node_forces(w);
        double F = 0;
        for (int i = 0; i < nn; i++)
            F += nf[3 * i + 2];
        worst = fmax(worst, fabs(F - tot.force[2]));
        if (s == steps / 2)
            f_half = tot.force[2];
        if (s == steps - 1)
            f_end = tot.force[2];
        ENSURE(dem_step_grains(w, &err) == 0);
    }
    double zplate = z0 + vz * steps * 4e-5;
    int above = 0;
    for (int i = 0; i < dem_grain_count(w); i++) {
        dem_grain_state gs;
        dem_grain_get(w, i, &gs);
        /* well inside the footprint: getting there from above the plate means crossing it */
        above += gs.x[2] > zplate && gs.x[0] > 0.012 && gs.x[0] < 0.028 && gs.x[1] > 0.012 && gs.x[1] < 0.028;
    }
    printf("plate sinkage: F_z after 4 mm %.4g N, after 8 mm %.4g N, node/total mismatch %.3g N, grains above %d\n", f_half,
           f_end, worst, above);
    ENSURE(f_half > 0 && f_end > f_half);
    ENSURE(worst < 1e-12 * f_end * nn);
    ENSURE(above == 0);
    free(x), free(v), free(t);
    dem_world_destroy(&w);
    return 0;
}

/* ---- dents, corners and fine meshes (issue 16) --------------------------
 * A steel grain (R 10 mm) on a rubber surface (E 10 MPa, ν 0.45), the
 * issue's case, with the surface held rigid: the DEM contact alone. */
static const double RS = 0.010;

static dem_world *steel_rubber_world(double dt, double mu, int max_grains, int threads)
{
    dem_material m[2] = {
        {.density = 7800.0, .young = 2.1e11, .poisson = 0.3, .restitution = 1.0, .friction = mu},
        {.density = 1100.0, .young = 1.0e7, .poisson = 0.45, .restitution = 1.0, .friction = mu},
    };
    return test_world(m, 2, dt, max_grains, NULL, threads);
}

static double e_star_steel_rubber(void)
{
    return 1.0 / ((1.0 - 0.09) / 2.1e11 + (1.0 - 0.45 * 0.45) / 1.0e7);
}

/* Plane z = 0 of nx x nx squares of side s centred on the origin, with a
 * spherical dent of radius rd and depth hd centred on the origin (nodes
 * inside the dent's rim lowered onto the sphere). */
static int dented_surface(dem_world *w, int nx, double s, double rd, double hd)
{
    int nn = (nx + 1) * (nx + 1);
    double *x = malloc(sizeof(double) * 3 * nn);
    int *t = malloc(sizeof(int) * 6 * nx * nx);
    if (!x || !t)
        return 1;
    test_plane_mesh(nx, nx, s, -nx * s / 2, -nx * s / 2, 0.0, x, t);
    for (int i = 0; i < nn; i++) {
        double *p = x + 3 * i, r2 = p[0] * p[0] + p[1] * p[1];
        double z = -hd + rd - sqrt(fmax(rd * rd - r2, 0.0));
        if (z < 0.0)
            p[2] = z;
    }
    cm_error err = {0};
    int rc = dem_surface_set(w, nn, x, 2 * nx * nx, t, 1, &err);
    if (rc)
        fprintf(stderr, "%s\n", err.msg);
    free(x), free(t);
    return rc;
}

typedef struct impact_out {
    double e_in, e_out, fmax, tc;
    int max_contacts, steps;
} impact_out;

/* Launches grain 0 from x0 with v0 and steps until it has left the surface
 * (in contact once, none now): peak force, contact time, energies (mass
 * and inertia from the grain, I = 2/5 m r²). */
static int run_impact(dem_world *w, const double x0[3], const double v0[3], impact_out *o)
{
    cm_error err = {0};
    if (dem_grain_add(w, x0, RS, 0, NULL, &err)) {
        fprintf(stderr, "%s\n", err.msg);
        return 1;
    }
    dem_grain_set(w, 0, NULL, v0, NULL);
    dem_grain_state g;
    dem_grain_get(w, 0, &g);
    o->e_in = 0.5 * g.mass * (v0[0] * v0[0] + v0[1] * v0[1] + v0[2] * v0[2]);
    o->fmax = 0, o->max_contacts = 0, o->tc = 0;
    int seen = 0, n_in = 0;
    for (o->steps = 0; o->steps < 200000; o->steps++) {
        if (dem_step(w, &err)) {
            fprintf(stderr, "step %d: %s\n", o->steps, err.msg);
            return 1;
        }
        dem_surface_total tot;
        dem_surface_totals(w, &tot);
        dem_grain_get(w, 0, &g);
        o->fmax = fmax(o->fmax, sqrt(g.f[0] * g.f[0] + g.f[1] * g.f[1] + g.f[2] * g.f[2]));
        if (tot.contacts > o->max_contacts)
            o->max_contacts = tot.contacts;
        if (tot.contacts > 0)
            seen = 1, n_in++;
        else if (seen)
            break;
    }
    dem_grain_get(w, 0, &g);
    double iner = 0.4 * g.mass * RS * RS;
    o->e_out = 0.5 * g.mass * (g.v[0] * g.v[0] + g.v[1] * g.v[1] + g.v[2] * g.v[2]) +
               0.5 * iner * (g.w[0] * g.w[0] + g.w[1] * g.w[1] + g.w[2] * g.w[2]);
    return seen ? 0 : 1;
}

/* An elastic grain (no damping, no friction) dropped into a dent of a rigid
 * triangulated surface leaves with the energy it brought, wherever it lands
 * in the dent: the dent is one contact (a local distance minimum on each of
 * its facets used to count as a full contact each). The dent (radius
 * 1.25 R, depth 0.15 R, facets of R/8) is the shape a soft tread takes under
 * a grain; the impact overlap (5 % of R) makes the grain meet the whole dent. */
static int dented_impact_energy(void)
{
    const double hd = 0.15 * RS, s = RS / 8.0;
    double starts[][4] = {/* x, y, vx, vy */
                          {0, 0, 0, 0},         {0.3 * s, 0.2 * s, 0.05, 0.02}, {0.5 * s, 0, -0.1, 0},
                          {s, s, 0.0, 0.08},    {0.2 * RS, 0.1 * RS, -0.15, -0.05}};
    double worst = 0;
    int worst_contacts = 0;
    for (size_t k = 0; k < sizeof starts / sizeof starts[0]; k++) {
        dem_world *w = steel_rubber_world(3e-6, 0.0, 4, 1);
        ENSURE(w);
        ENSURE(dented_surface(w, 24, s, 1.25 * RS, hd) == 0);
        /* from just above the plane z = 0: it lands in the dent */
        double x0[3] = {starts[k][0], starts[k][1], RS + 1e-6}, v0[3] = {starts[k][2], starts[k][3], -0.5};
        impact_out o;
        ENSURE(run_impact(w, x0, v0, &o) == 0);
        double err = o.e_out / o.e_in - 1.0;
        printf("dented impact from (%.2f, %.2f) s: E_out/E_in - 1 = %+.2e, F_max %.2f N, up to %d contacts\n",
               starts[k][0] / s, starts[k][1] / s, err, o.fmax, o.max_contacts);
        worst = fmax(worst, fabs(err));
        worst_contacts = o.max_contacts > worst_contacts ? o.max_contacts : worst_contacts;
        dem_world_destroy(&w);
    }
    printf("dented impact: worst energy error %.2e, at most %d contacts\n", worst, worst_contacts);
    ENSURE(worst < 0.02);
    ENSURE(worst_contacts == 1);
    return 0;
}

/* A grain dropped on a finely meshed flat surface (facets R/25: some 200
 * triangles under the grain at the peak, more than the old fixed cap of
 * 64) feels the same peak force whether it lands on a vertex, an edge or
 * inside a face, and that is Hertz's for a steel sphere on a rubber
 * half-space (the surface's material). */
static int fine_mesh_landing(void)
{
    const double s = RS / 25.0, v = 0.5;
    const int nx = 60; /* ±1.2 R */
    dem_material steel = {.density = 7800.0, .young = 2.1e11, .poisson = 0.3, .restitution = 1.0};
    double m = sphere_mass(steel.density, RS);
    hertz_ref h = hertz_closed_form(e_star_steel_rubber(), RS, m, v);
    double land[][2] = {{0, 0}, {0.5 * s, 0}, {s / 3.0, s / 5.0}, {0.5 * s, 0.5 * s}};
    const char *what[] = {"vertex", "edge", "face", "diagonal"};
    double f[4], worst = 0;
    for (int k = 0; k < 4; k++) {
        dem_world *w = steel_rubber_world(h.tc / 1000.0, 0.0, 4, 1);
        ENSURE(w);
        ENSURE(dented_surface(w, nx, s, 1.0, 0.0) == 0);
        double x0[3] = {land[k][0], land[k][1], RS + 1e-7}, v0[3] = {0, 0, -v};
        impact_out o;
        ENSURE(run_impact(w, x0, v0, &o) == 0);
        f[k] = o.fmax;
        printf("fine mesh, landing on a %-8s: F_max %.4f N (Hertz %.4f N, %+.2e), contact time %.4f ms (%d steps)\n",
               what[k], o.fmax, h.fmax, o.fmax / h.fmax - 1, o.steps * h.tc / 1000.0 * 1e3, o.steps);
        ENSURE(o.max_contacts == 1);
        worst = fmax(worst, fabs(o.fmax / h.fmax - 1));
        dem_world_destroy(&w);
    }
    for (int k = 1; k < 4; k++)
        ENSURE_REL(f[k], f[0], 0.01);
    ENSURE(worst < 0.01);
    return 0;
}

/* Two planes meeting along the y axis: the floor z = 0 (x > 0) and a
 * second plane through the axis at angle `deg` to it (x < 0), as triangles
 * sharing the fold's nodes. */
static int folded_surface(dem_world *w, double deg, double s)
{
    const int nx = 16, ny = 8;
    int nn = (nx + 1) * (ny + 1);
    double *x = malloc(sizeof(double) * 3 * nn);
    int *t = malloc(sizeof(int) * 6 * nx * ny);
    if (!x || !t)
        return 1;
    test_plane_mesh(nx, ny, s, -nx * s / 2, -ny * s / 2, 0.0, x, t);
    double a = deg * M_PI / 180.0;
    for (int i = 0; i < nn; i++) { /* x < 0 rotated about the y axis, up into z > 0 */
        double *p = x + 3 * i;
        if (p[0] < 0.0) {
            double l = -p[0];
            p[0] = -l * cos(a), p[2] = l * sin(a);
        }
    }
    cm_error err = {0};
    int rc = dem_surface_set(w, nn, x, 2 * nx * ny, t, 1, &err);
    if (rc)
        fprintf(stderr, "%s\n", err.msg);
    free(x), free(t);
    return rc;
}

/* A real concave corner keeps one contact per face: a grain pressed into
 * the corner of a floor and a wall (90°), or of a floor and a 60° flank, by
 * the same overlap on both feels the Hertz force of each face. A shallow
 * fold (10°) is one surface patch: one contact, the deeper face's. */
static int concave_corner_contacts(void)
{
    const double delta = 0.01 * RS, s = RS / 3.0;
    double fh = hertz_force(e_star_steel_rubber(), RS, delta);
    double angles[] = {90.0, 120.0, 170.0};
    int expect[] = {2, 2, 1};
    for (int k = 0; k < 3; k++) {
        dem_world *w = steel_rubber_world(1e-6, 0.0, 4, 1);
        ENSURE(w);
        /* the fold's flank at angle (180 - opening) from the floor */
        double flank = 180.0 - angles[k], a = flank * M_PI / 180.0;
        ENSURE(folded_surface(w, flank, s) == 0);
        /* centre at distance R - delta from both planes, on the bisector of
         * the opening: x = d tan(a/2) */
        double d = RS - delta, x[3] = {d * tan(0.5 * a), 0.0, d};
        cm_error err = {0};
        ENSURE(dem_grain_add(w, x, RS, 0, NULL, &err) == 0);
        ENSURE(dem_step_surface(w, &err) == 0);
        dem_surface_total tot;
        dem_surface_totals(w, &tot);
        dem_grain_state g;
        dem_grain_get(w, 0, &g);
        /* expected: each face pushes with the Hertz force along its normal */
        double n1[3] = {0, 0, 1}, n2[3] = {sin(a), 0, cos(a)};
        double fe[3];
        for (int c = 0; c < 3; c++)
            fe[c] = expect[k] == 2 ? fh * (n1[c] + n2[c]) : fh * n1[c];
        printf("fold opening %.0f°: %d contacts, force (%.4f %.4f %.4f) N, expected (%.4f %.4f %.4f)\n", angles[k],
               tot.contacts, g.f[0], g.f[1], g.f[2], fe[0], fe[1], fe[2]);
        ENSURE_MSG(tot.contacts == expect[k], "opening %g°: %d contacts", angles[k], tot.contacts);
        if (expect[k] == 2)
            for (int c = 0; c < 3; c++)
                ENSURE_NEAR(g.f[c], fe[c], 1e-9 * fh);
        else /* one contact with the Hertz force of the overlap */
            ENSURE_REL(sqrt(g.f[0] * g.f[0] + g.f[1] * g.f[1] + g.f[2] * g.f[2]), fh, 1e-9);
        dem_world_destroy(&w);
    }
    return 0;
}

/* On a dented surface with friction, grains moving and spinning in and
 * around the dent: the node forces balance the grains' forces and moments
 * (about the origin: sum x_k × f_k = -sum (c × F + T)) to round-off. */
static int dent_node_balance(void)
{
    dem_world *w = steel_rubber_world(1e-6, 0.5, 16, 2);
    ENSURE(w);
    const double hd = 0.15 * RS, s = RS / 8.0;
    const int nx = 48;
    ENSURE(dented_surface(w, nx, s, 1.25 * RS, hd) == 0);
    cm_error err = {0};
    double pos[][3] = {{0.001, -0.0005, -hd + 0.97 * RS}, {0.021, 0.0, 0.97 * RS}, {-0.005, 0.02, 0.99 * RS},
                       {-0.02, -0.02, 0.98 * RS}};
    for (int j = 0; j < 4; j++) {
        ENSURE(dem_grain_add(w, pos[j], RS, 0, NULL, &err) == 0);
        double v[3] = {0.1 * j - 0.1, 0.05, -0.2}, om[3] = {3, -2, 1 + j};
        dem_grain_set(w, j, NULL, v, om);
    }
    double fmag = 0, F[3] = {0, 0, 0}, M[3] = {0, 0, 0};
    for (int st = 0; st < 40; st++) { /* a few steps: the tangential springs load */
        ENSURE(dem_step_surface(w, &err) == 0);
        if (st < 39)
            ENSURE(dem_step_grains(w, &err) == 0);
    }
    dem_surface_total tot;
    dem_surface_totals(w, &tot);
    const double *nf = dem_surface_node_forces(w);
    int nn = (nx + 1) * (nx + 1);
    /* node positions: rebuild the mesh the same way */
    double *x = malloc(sizeof(double) * 3 * nn);
    int *t = malloc(sizeof(int) * 6 * nx * nx);
    ENSURE(x && t);
    test_plane_mesh(nx, nx, s, -nx * s / 2, -nx * s / 2, 0.0, x, t);
    for (int i = 0; i < nn; i++) {
        double *p = x + 3 * i, r2 = p[0] * p[0] + p[1] * p[1], rd = 1.25 * RS;
        double z = -hd + rd - sqrt(fmax(rd * rd - r2, 0.0));
        if (z < 0.0)
            p[2] = z;
        const double *f = nf + 3 * i;
        F[0] += f[0], F[1] += f[1], F[2] += f[2];
        M[0] += p[1] * f[2] - p[2] * f[1];
        M[1] += p[2] * f[0] - p[0] * f[2];
        M[2] += p[0] * f[1] - p[1] * f[0];
    }
    double G[3] = {0, 0, 0}, GM[3] = {0, 0, 0};
    for (int j = 0; j < 4; j++) { /* the grains have not moved since the surface step */
        dem_grain_state g;
        dem_grain_get(w, j, &g);
        for (int k = 0; k < 3; k++)
            G[k] += g.f[k], GM[k] += g.t[k];
        GM[0] += g.x[1] * g.f[2] - g.x[2] * g.f[1];
        GM[1] += g.x[2] * g.f[0] - g.x[0] * g.f[2];
        GM[2] += g.x[0] * g.f[1] - g.x[1] * g.f[0];
        fmag += sqrt(g.f[0] * g.f[0] + g.f[1] * g.f[1] + g.f[2] * g.f[2]);
    }
    free(x), free(t);
    printf("dent node balance: %d contacts, |F| sum %.4g N, node resultant (%.6g %.6g %.6g) vs grains (%.6g %.6g %.6g), "
           "moment (%.6g %.6g %.6g) vs (%.6g %.6g %.6g)\n",
           tot.contacts, fmag, F[0], F[1], F[2], -G[0], -G[1], -G[2], M[0], M[1], M[2], -GM[0], -GM[1], -GM[2]);
    for (int k = 0; k < 3; k++) {
        ENSURE_NEAR(F[k], -G[k], 1e-12 * fmag);
        ENSURE_NEAR(M[k], -GM[k], 1e-12 * fmag * RS);
    }
    ENSURE(tot.contacts >= 3);
    dem_world_destroy(&w);
    return 0;
}

/* A grain held at a constant overlap slides along a dent (moved on an arc
 * about the dent's centre, 0.3 rad: its contact point travels 3.75 mm,
 * three facets):
 * the tangential spring is keyed by grain and patch, not by triangle, so
 * the friction force stays at the Coulomb limit throughout (a reset would
 * drop it to the tiny elastic increment of one step). */
static int dent_slide_keeps_history(void)
{
    const double hd = 0.15 * RS, s = RS / 8.0, rd = 1.25 * RS, delta = 0.02 * RS, mu = 0.5;
    dem_world *w = steel_rubber_world(1e-6, mu, 4, 1);
    ENSURE(w);
    ENSURE(dented_surface(w, 24, s, rd, hd) == 0);
    const double oz = rd - hd, arm = rd - RS + delta, phi_end = 0.3, dt = 1e-6;
    const int steps = 3000;
    const double dphi = phi_end / steps;
    cm_error err = {0};
    double x[3] = {0, 0, oz - arm};
    ENSURE(dem_grain_add(w, x, RS, 0, NULL, &err) == 0);
    double worst = INFINITY, fn_mean = 0;
    int counted = 0;
    for (int st = 0; st <= steps; st++) {
        double phi = st * dphi;
        double c[3] = {arm * sin(phi), 0, oz - arm * cos(phi)};
        double v[3] = {arm * cos(phi) * dphi / dt, 0, arm * sin(phi) * dphi / dt};
        ENSURE(dem_grain_set(w, 0, c, v, NULL) == 0);
        ENSURE(dem_step_surface(w, &err) == 0);
        dem_grain_state g;
        dem_grain_get(w, 0, &g);
        double n[3] = {-sin(phi), 0, cos(phi)}; /* from the bowl towards its centre */
        double fn = g.f[0] * n[0] + g.f[1] * n[1] + g.f[2] * n[2], ft[3];
        for (int k = 0; k < 3; k++)
            ft[k] = g.f[k] - fn * n[k];
        double ftm = sqrt(ft[0] * ft[0] + ft[1] * ft[1] + ft[2] * ft[2]);
        if (st > steps / 10) {
            worst = fmin(worst, ftm / (mu * fn));
            fn_mean += fn, counted++;
        }
    }
    printf("dent slide: F_n %.3f N, friction / (mu F_n) at least %.3f (the split uses the dent's radial normal, "
           "not the facets': a reset would give %.4f)\n",
           fn_mean / counted, worst, 2.5e4 * arm * dphi / (mu * fn_mean / counted));
    ENSURE(worst > 0.5);
    dem_world_destroy(&w);
    return 0;
}

/* The tread's compliance counted once (issue 16 item 2, DEM_SURF_FE_A0): a
 * steel grain pressed into a plane of rubber triangles of size h. Rigid
 * (no node masses): Hertz with the tread's modulus. Yielding nodes: the
 * contact's own overlap is the part of Hertz's approach the FE does not
 * supply, delta = (1 - s) delta_H(F), s = x / (x + A0), x = a_H / h,
 * a_H = sqrt(R delta_H); checked from the force back, at a coarse (h = 3 a),
 * a matching (h = a) and a fine (h = a/3) mesh; and on a mesh far finer than
 * the patch the contact is the grain's own modulus alone (a soil grain,
 * E 0.5 GPa: k capped at E_grain* / E*). */
static int fe_share_stiffening(void)
{
    const dem_material mats[2] = {test_material(2.1e11, 0.3, 1.0, 0.0), test_material(1.0e7, 0.45, 1.0, 0.0)};
    const double delta = 0.04 * R0, Es = hertz_e_star(2.1e11, 0.3, 1.0e7, 0.45);
    const double ac = sqrt(R0 * delta); /* the contact's own radius */
    const double hs[4] = {3.0 * ac, ac, ac / 3.0, ac / 12.0};
    for (int c = 0; c < 5; c++) {
        const int soil = c == 4, yielding = c > 0;
        const double h = hs[c == 0 ? 0 : c - 1];
        dem_material m[2] = {mats[0], mats[1]};
        if (soil)
            m[0] = test_material(5.0e8, 0.3, 1.0, 0.0);
        dem_world *w = test_world(m, 2, 5e-7, 4, NULL, 1);
        ENSURE(w);
        cm_error err = {0};
        const int nx = (int)ceil(2.2 * R0 / h) + 1, nn = (nx + 1) * (nx + 1);
        double *x = malloc(sizeof(double) * 3 * nn), *mass = malloc(sizeof(double) * nn);
        int *t = malloc(sizeof(int) * 6 * nx * nx);
        ENSURE(x && mass && t);
        test_plane_mesh(nx, nx, h, -0.5 * nx * h + 0.3 * h, -0.5 * nx * h + 0.4 * h, 0.0, x, t);
        for (int i = 0; i < nn; i++)
            mass[i] = 1e-3;
        ENSURE(dem_surface_set(w, nn, x, 2 * nx * nx, t, 1, &err) == 0);
        if (yielding)
            ENSURE(dem_surface_set_masses(w, mass, &err) == 0);
        double p[3] = {0, 0, R0 - delta};
        ENSURE(dem_grain_add(w, p, R0, 0, NULL, &err) == 0);
        int rc = dem_step_surface(w, &err);
        ENSURE_MSG(rc == 0, "%s", err.msg);
        dem_grain_state g;
        dem_grain_get(w, 0, &g);
        const double F = g.f[2];
        const double es = soil ? hertz_e_star(5.0e8, 0.3, 1.0e7, 0.45) : Es;
        const double dH = hertz_static_overlap(es, R0, F), xh = sqrt(R0 * dH) / h, sh = xh / (xh + DEM_SURF_FE_A0);
        printf("  %s grain, h = %.3g a_c, %s: F %.5g N, Hertz with the tread %.5g N; FE share s %.3f, "
               "overlap / (1 - s) delta_H = %.9f\n", soil ? "soil" : "steel", h / ac, yielding ? "yielding" : "rigid",
               F, hertz_force(es, R0, delta), yielding ? sh : 0.0, delta / ((1.0 - sh) * dH));
        if (!yielding)
            ENSURE_REL(F, hertz_force(es, R0, delta), 1e-9);
        else if (!soil)
            ENSURE_REL(delta, (1.0 - sh) * dH, 1e-9);
        else /* capped: the grain's own modulus, 5e8 / (1 - 0.09) */
            ENSURE_REL(F, hertz_force(5.0e8 / (1.0 - 0.09), R0, delta), 1e-9);
        if (yielding && !soil)
            ENSURE(F > hertz_force(es, R0, delta));
        free(x), free(mass), free(t);
        dem_world_destroy(&w);
    }
    return 0;
}

/* The surface lists pass over groups of slots whose box meets no leaf of
 * the tree (dem_surface.c, surf_lists_build): a 10 x 10 x 6 lattice of
 * grains, 2 mm, falling at 0.5 m/s onto a 6.4 cm plate with a 6 mm dent
 * (dented_surface), the lowest layer 0.25 mm above its flat part (under
 * half a skin: they touch before the lists are rebuilt), the others up to
 * 3.5 cm higher and beyond its edges (groups far, near, and split between
 * the two), stepped for 300 steps. At every step, each grain has a surface contact if and
 * only if a triangle's closest point lies within its radius (every triangle
 * tried), and the lists were built more than once. */
static int lists_pass_far_groups(void)
{
    dem_material m[2] = {test_material(5e7, 0.3, 0.5, 0.5), test_material(5e7, 0.3, 0.5, 0.5)};
    double g[3] = {0, 0, -9.81};
    dem_world *w = test_world(m, 2, 1e-5, 600, g, 1); /* material 1: the surface's */
    ENSURE(w);
    cm_error err = {0};
    const double r = 0.002;
    ENSURE(dented_surface(w, 16, 0.004, 0.02, 0.006) == 0);
    const int nt = w->surf->n_tris;
    const double *x = w->surf->x; /* the surface never moves here */
    const int *t = w->surf->tri;
    for (int ix = 0; ix < 10; ix++)
        for (int iy = 0; iy < 10; iy++)
            for (int iz = 0; iz < 6; iz++) {
                const double p[3] = {-0.045 + 0.01 * ix + 0.0007 * iz, -0.045 + 0.01 * iy + 0.0005 * iz,
                                     0.00225 + 0.007 * iz},
                             v[3] = {0, 0, -0.5}, om[3] = {0, 0, 0};
                int id;
                ENSURE(dem_grain_add(w, p, r, 0, &id, &err) == 0);
                ENSURE(dem_grain_set(w, id, p, v, om) == 0);
            }
    long touched = 0;
    for (int step = 0; step < 300; step++) {
        ENSURE_MSG(dem_step_surface(w, &err) == 0, "%s", err.msg);
        const dem_grains *gr = &w->g;
        for (int i = 0; i < gr->n; i++) {
            const double c[3] = {gr->x[i], gr->y[i], gr->z[i]};
            int over = 0;
            for (int k = 0; k < nt && !over; k++) {
                const int *tk = t + 3 * k;
                double bary[3], cp[3];
                dem_closest_on_triangle(c, x + 3 * tk[0], x + 3 * tk[1], x + 3 * tk[2], bary, cp);
                const double d2 = (c[0] - cp[0]) * (c[0] - cp[0]) + (c[1] - cp[1]) * (c[1] - cp[1]) +
                                  (c[2] - cp[2]) * (c[2] - cp[2]);
                over = d2 < gr->r[i] * gr->r[i];
            }
            ENSURE_MSG((gr->surf_count[i] > 0) == over, "step %d, grain %d at (%g, %g, %g): %d surface contacts, "
                       "overlaps a triangle: %d", step, gr->id[i], c[0], c[1], c[2], gr->surf_count[i], over);
            touched += over;
        }
        ENSURE_MSG(dem_step_grains(w, &err) == 0, "%s", err.msg);
    }
    ENSURE_MSG(touched > 1000, "only %ld grain-steps touched the plate", touched);
    ENSURE_MSG(w->prof.surface_lists > 1, "lists built %ld times", (long)w->prof.surface_lists);
    dem_world_destroy(&w);
    return 0;
}

/* Error paths name the culprit. */
static int errors_name_culprit(void)
{
    dem_material m = test_material(5e7, 0.3, 0.5, 0.5);
    dem_world *w = test_world(&m, 1, 1e-6, 1, NULL, 1);
    ENSURE(w);
    cm_error err = {0};
    double x[3] = {0, 0, 0}, zero[3] = {0, 0, 0};
    ENSURE(dem_grain_add(w, x, -1.0, 0, NULL, &err) == CM_ERR_RANGE && strstr(err.msg, "radius"));
    ENSURE(dem_grain_add(w, x, 1e-3, 3, NULL, &err) == CM_ERR_RANGE && strstr(err.msg, "material 3"));
    ENSURE(dem_grain_add(w, x, 1e-3, 0, NULL, &err) == CM_OK);
    ENSURE(dem_grain_add(w, x, 1e-3, 0, NULL, &err) == CM_ERR_RANGE && strstr(err.msg, "max_grains"));
    ENSURE(dem_wall_add(w, x, zero, 0, &err) == CM_ERR_RANGE && strstr(err.msg, "normal"));
    double nodes[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    int tri[3] = {0, 1, 5};
    ENSURE(dem_surface_set(w, 3, nodes, 1, tri, 0, &err) == CM_ERR_RANGE && strstr(err.msg, "triangle 0"));
    ENSURE(dem_surface_update(w, nodes, NULL, &err) == CM_ERR_STATE);
    dem_material bad = m;
    bad.poisson = 0.6;
    dem_world *w2 = NULL;
    dem_world_def d = dem_world_def_default();
    ENSURE(dem_world_create(&d, 1, &bad, &w2, &err) == CM_ERR_RANGE && strstr(err.msg, "material 0"));
    dem_world_destroy(&w);
    return 0;
}

static const test_case tests[] = {
    {"plate_sinkage", plate_sinkage},
    {"errors_name_culprit", errors_name_culprit},
    {"lists_pass_far_groups", lists_pass_far_groups},
    {"closest_point_regions", closest_point_regions},
    {"resting_force_anywhere", resting_force_anywhere},
    {"rebound_wall_vs_triangles", rebound_wall_vs_triangles},
    {"rolling_across_edges", rolling_across_edges},
    {"node_force_balance", node_force_balance},
    {"surface_update_refit", surface_update_refit},
    {"dented_impact_energy", dented_impact_energy},
    {"fine_mesh_landing", fine_mesh_landing},
    {"concave_corner_contacts", concave_corner_contacts},
    {"dent_node_balance", dent_node_balance},
    {"dent_slide_keeps_history", dent_slide_keeps_history},
    {"fe_share_stiffening", fe_share_stiffening},
};

int main(int argc, char **argv) { return test_main(argc, argv, tests, TEST_COUNT(tests)); }
