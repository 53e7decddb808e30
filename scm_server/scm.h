/* scm: a semi-empirical terrain (the soil contact model, SCM) on a regular
 * height grid that remembers its ruts — the cheap alternative to the DEM.
 *
 * Each grid cell under the tire is loaded by the vertical sinkage z of the
 * tire surface below the undisturbed level:
 *   first loading      p = (k_c/b + k_phi) z^n           (Bekker)
 *   unloading/reload.  p = p_max - k_u (z_max - z)        (Wong: elastic line)
 *   shear              tau = (c + p tan phi)(1 - e^{-j/K}) (Janosi–Hanamoto)
 * with j the shear displacement accumulated by the tread element in contact
 * (the soil it carries) since it entered the contact. The shear stress is
 * an elastic-plastic spring on that curve: it acts against the elastic part
 * e of the tread's tangential displacement with the curve's initial slope,
 * tau = (c + p_max tan phi)/K |e|, and e is held where that reaches the
 * curve (so that monotonic sliding gives Janosi's tau exactly, and stopping
 * or turning does not make it chatter). The
 * normal stress acts along the tire surface's normal, both per unit of tire
 * surface area; each cell's force is
 * put on the three nodes of the triangle it touches with the contact point's
 * barycentric weights (paper eq. 42), so the nodal forces have the cells'
 * resultant and moment to round-off.
 *
 * Usage:
 *   scm_terrain_create(&grid, &soil, &t, &err);
 *   scm_terrain_set_surface(t, n_nodes, x0, n_tris, tris, &err);   once
 *   loop: scm_terrain_step(t, x, &err);   forces for the surface at x
 *         (the tread's shear displacement first advanced by its motion
 *         since the last step), scm_terrain_node_forces(t),
 *         scm_terrain_totals(t, &tot);
 *   scm_terrain_destroy(&t);
 * Units: SI (m, N, Pa, s). */
#ifndef SCM_H
#define SCM_H

#include <stdint.h>

#include "error.h"

/* The soil's semi-empirical parameters (every field SI; see README.md for
 * the defaults' sources). */
typedef struct scm_soil {
    double k_c;      /* N/m^(n+1), Bekker cohesive modulus */
    double k_phi;    /* N/m^(n+2), Bekker frictional modulus */
    double n;        /* Bekker sinkage exponent */
    double cohesion; /* Pa */
    double phi;      /* rad, internal friction angle */
    double K;        /* m, shear deformation modulus */
    double k0;       /* Pa/m, unloading stiffness k_u = k0 + A_u z_max */
    double A_u;      /* Pa/m^2 */
    double b;        /* m, Bekker's plate width b; 0: the surface's smaller horizontal dimension */
    double z_reg;    /* m, below this sinkage p is linear (the secant of the Bekker curve): finite stiffness */
} scm_soil;

/* Dry sand of the Land Locomotion Laboratory (Wong, Theory of Ground
 * Vehicles, 3rd ed., table 2.3) with the assumptions named in README.md. */
scm_soil scm_soil_default(void);

/* The laws, pointwise (tests use them as the closed forms' building blocks). */
double scm_bekker(const scm_soil *s, double b, double z);       /* Pa, first loading at sinkage z (m) */
double scm_unload_stiffness(const scm_soil *s, double z_max);   /* Pa/m */
double scm_janosi(const scm_soil *s, double p, double j);       /* Pa, shear stress at pressure p, displacement j */
/* The shear as an elastic-plastic spring on the Janosi curve (scm_soil.c):
 * tau = scm_shear_stiffness(p_max) |e| (Pa/m; p_max the pressure of the
 * soil's first loading, Pa), the elastic displacement |e| at most
 * scm_shear_elastic_limit(p, p_max, j) (m) at pressure p after a slide j. */
double scm_shear_stiffness(const scm_soil *s, double p_max);
double scm_shear_elastic_limit(const scm_soil *s, double p, double p_max, double j);

typedef struct scm_grid_def {
    double min[2], max[2]; /* m, horizontal extent (x, y) of the soil */
    double cell;           /* m, cell size (square cells) */
    double height;         /* m, undisturbed surface z */
} scm_grid_def;

typedef struct scm_terrain scm_terrain;

/* What the surface felt at the last step (moment about the world origin). */
typedef struct scm_totals {
    double force[3];     /* N */
    double moment[3];    /* N m */
    double traction_pos; /* N, sum of the positive x components (normal and shear counted apart) */
    double traction_neg; /* N, sum of the negative ones */
    double normal_force[3]; /* N, the normal stresses' part of force (Wong: -x is the motion resistance) */
    double shear_force[3];  /* N, the shear stresses' part (Wong: x is the thrust) */
    long contacts;       /* cells in contact */
    double max_sinkage;  /* m, deepest sinkage reached anywhere so far (z_max) */
} scm_totals;

/* Per-stage wall time, s, accumulated over the steps. */
typedef struct scm_profile {
    double raster;   /* surface triangles onto the grid: lowest hit per cell */
    double soil;     /* pressure, shear, node forces, soil state */
    double shear;    /* the tread's shear displacement */
    long steps;
} scm_profile;

int scm_terrain_create(const scm_grid_def *grid, const scm_soil *soil, scm_terrain **out, cm_error *err);
void scm_terrain_destroy(scm_terrain **t);

/* The surface: n nodes (3 n coordinates, only for b), m triangles counter-
 * clockwise seen from outside (the soil side). The node indices are checked. */
int scm_terrain_set_surface(scm_terrain *t, int n_nodes, const double *x, int n_tris, const int *tris,
                            cm_error *err);
/* Bekker's b in use, m. */
double scm_terrain_plate_width(const scm_terrain *t);

/* One exchange: the tread's shear displacement advances by the surface's
 * tangential motion since the last step (positions, not velocities: the
 * forces are a function of x, README.md), then the node forces (N) for the
 * surface at positions x (3 n, m), committing the soil's state (ruts) at x.
 * Fails when a contact is outside the grid (naming scm.grid). */
int scm_terrain_step(scm_terrain *t, const double *x, cm_error *err);
const double *scm_terrain_node_forces(const scm_terrain *t);
void scm_terrain_totals(const scm_terrain *t, scm_totals *out);
scm_profile scm_terrain_profile(const scm_terrain *t);

/* The grid, for output and tests. Cell (i, j) has its centre at
 * min + (i + 1/2, j + 1/2) cell. */
void scm_terrain_grid_size(const scm_terrain *t, int *nx, int *ny);
/* The soil surface of a cell now (m): the tire's height where in contact,
 * else the rut left after the elastic spring-back. */
double scm_terrain_cell_height(const scm_terrain *t, int i, int j);
/* The deepest sinkage the cell was loaded to (m), and its pressure now (Pa). */
double scm_terrain_cell_zmax(const scm_terrain *t, int i, int j);
double scm_terrain_cell_pressure(const scm_terrain *t, int i, int j);
/* The shear displacement the surface node carries (m), and the elastic
 * part of it (3 components, world frame, m; zeros for a bad index). */
double scm_terrain_node_shear(const scm_terrain *t, int node);
void scm_terrain_node_shear_elastic(const scm_terrain *t, int node, double e[3]);

#endif
