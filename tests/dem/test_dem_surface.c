/* Triangle surface: closest points, de-duplication on shared edges and
 * vertices, wall-equivalence, history across triangle edges, and the
 * barycentric force transfer (eq. 42). */
#include <stdlib.h>

#include "dem_surface.h"
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
    {"closest_point_regions", closest_point_regions},
    {"resting_force_anywhere", resting_force_anywhere},
    {"rebound_wall_vs_triangles", rebound_wall_vs_triangles},
    {"rolling_across_edges", rolling_across_edges},
    {"node_force_balance", node_force_balance},
    {"surface_update_refit", surface_update_refit},
};

int main(int argc, char **argv) { return test_main(argc, argv, tests, TEST_COUNT(tests)); }
