/* Helpers shared by the DEM tests. */
#ifndef TEST_DEM_COMMON_H
#define TEST_DEM_COMMON_H

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "dem.h"
#include "dem_bed.h"
#include "hertz.h"
#include "test.h"

static inline dem_material test_material(double E, double nu, double e, double mu)
{
    dem_material m = {.density = 2600.0, .young = E, .poisson = nu, .restitution = e, .friction = mu};
    return m;
}

/* World with one material, no gravity unless given. */
static inline dem_world *test_world(const dem_material *m, int n_mat, double dt, int max_grains, const double g[3],
                                    int threads)
{
    dem_world_def d = dem_world_def_default();
    d.dt = dt;
    d.max_grains = max_grains;
    d.threads = threads;
    d.gravity[0] = g ? g[0] : 0.0;
    d.gravity[1] = g ? g[1] : 0.0;
    d.gravity[2] = g ? g[2] : 0.0;
    dem_world *w = NULL;
    cm_error err = {0};
    if (dem_world_create(&d, n_mat, m, &w, &err)) {
        fprintf(stderr, "dem_world_create: %s\n", err.msg);
        return NULL;
    }
    return w;
}

static inline double e_star_same(const dem_material *m)
{
    return m->young / (2.0 * (1.0 - m->poisson * m->poisson));
}

/* Plane z = z0 over [x0, x0 + nx s] x [y0, y0 + ny s] as 2 nx ny triangles,
 * diagonals alternating. x: (nx+1)(ny+1)*3, tris: 2 nx ny * 3. */
static inline void test_plane_mesh(int nx, int ny, double s, double x0, double y0, double z0, double *x, int *tris)
{
    for (int j = 0; j <= ny; j++)
        for (int i = 0; i <= nx; i++) {
            double *p = x + 3 * (j * (nx + 1) + i);
            p[0] = x0 + i * s, p[1] = y0 + j * s, p[2] = z0;
        }
    int t = 0;
    for (int j = 0; j < ny; j++)
        for (int i = 0; i < nx; i++) {
            int a = j * (nx + 1) + i, b = a + 1, c = a + nx + 1, d = c + 1;
            if ((i + j) % 2) {
                int tt[6] = {a, b, d, a, d, c};
                memcpy(tris + 6 * t, tt, sizeof tt);
            } else {
                int tt[6] = {a, b, c, b, d, c};
                memcpy(tris + 6 * t, tt, sizeof tt);
            }
            t++;
        }
}

/* The side walls of an L x B box (x, y from 0, material 0), and its floor
 * z = 0 if floor. */
static inline int test_box_walls(dem_world *w, double L, double B, int floor)
{
    cm_error err = {0};
    const double walls[5][6] = {{0, 0, 0, 0, 0, 1}, {0, 0, 0, 1, 0, 0}, {L, 0, 0, -1, 0, 0},
                                {0, 0, 0, 0, 1, 0}, {0, B, 0, 0, -1, 0}};
    for (int k = floor ? 0 : 1; k < 5; k++)
        ENSURE(dem_wall_add(w, walls[k], walls[k] + 3, 0, &err) == 0);
    return 0;
}

/* An open box L x B (floor and four side walls, material 0) with n grains
 * placed, not settled, in two layers (radii 2.2-2.6 mm below, 1.8-2.0 mm
 * above): the falling beds of the thread and rank tests. */
static inline int test_two_layer_box(dem_world *w, double L, double B, int n)
{
    cm_error err = {0};
    ENSURE(test_box_walls(w, L, B, 1) == 0);
    dem_bed_params p = dem_bed_params_default();
    double lo[3] = {0, 0, 0}, hi[3] = {L, B, 0.2};
    memcpy(p.box_min, lo, sizeof lo);
    memcpy(p.box_max, hi, sizeof hi);
    p.n_layers = 2;
    p.layers[0].count = n / 2;
    p.layers[0].radius[0] = 2.2e-3, p.layers[0].radius[1] = 2.6e-3;
    p.layers[1].count = n - n / 2;
    p.layers[1].radius[0] = 1.8e-3, p.layers[1].radius[1] = 2.0e-3;
    ENSURE_MSG(dem_bed_place(w, &p, &err) == 0, "%s", err.msg);
    return 0;
}

#endif
