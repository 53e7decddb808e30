/* The model behind the public fem_model handle: mesh, solver, loads,
 * interface, wheel motion, output. Internal to fem/ (tests, bench). */
#ifndef FEM_MODEL_H
#define FEM_MODEL_H

#include "fem.h"
#include "fem_mesh.h"
#include "fem_output.h"
#include "fem_solver.h"

struct fem_model {
    fem_config cfg;
    fem_mesh mesh;
    fem_solver *s;
    double *b_pressure;     /* the dead loads per dof (rim frame, constant) [N]: the inflation pressure and
                               fem.loads */
    /* DEM interface */
    uint32_t n_if_nodes, n_if_tris;
    uint32_t *if_nodes;     /* mesh node ids */
    double *if_force;       /* 3 per interface node: the last DEM forces, world frame, N (output) */
    uint32_t *if_tris;      /* 3 per triangle, into if_nodes */
    fem_wheel wheel;
    fem_stability stab;
    bool have_stab;
    bool static_done;
    long advances;
    long output_advance;    /* advances at the last snapshot fem_output_due wrote (0: none) */
    double max_substep;     /* s, last sub-step used */
    double size;            /* m, bounding-box diagonal of the mesh */
    double added_mass;      /* kg, added to light interface nodes (cfg.interface_mass_min) */
    /* Energy guard: E = E_kin + E_el - b_pressure.u (pressure is conservative)
     * changes only by the work of the other loads (gravity turning with the
     * rim, the grains): work_in sums (f - b_pressure).du over each interval. */
    double *u_prev;         /* u at the start of the interval (n_dof) */
    double energy0;         /* J, E at the first interval */
    double work_in;         /* J, work of the non-conservative loads since then */
    double work_abs;        /* J, sum of |work| per interval: the scale of the balance */
    bool energy_started;
    fem_output *out;
};

/* Adds the consistent load of pressure p [Pa] on every boundary face tagged
 * `tag`: each of its three nodes gets -p A n / 3 (n outward from the solid,
 * so the pressure pushes into the body). */
void fem_load_pressure(const fem_mesh *m, uint8_t tag, double p, double *f);

/* Reads a Gmsh .msh v4.1 ASCII file / text (fem_gmsh.c). */
int fem_mesh_read_gmsh(const char *path, fem_mesh *m, cm_error *err);
int fem_mesh_parse_gmsh(const char *text, size_t len, const char *name, fem_mesh *m, cm_error *err);
/* Writes a mesh as .msh v4.1 ASCII with the named sets (view it in Gmsh;
 * rim is written as the rim faces: nodes tagged rim off those faces are lost). */
int fem_mesh_write_gmsh(const fem_mesh *m, const char *path, cm_error *err);

/* Builds the total load of the next interval into s->f: pressure + M R^T g
 * + R^T f_iface (f_iface may be NULL). */
void fem_model_build_load(fem_model *m, const double *f_iface);

/* Element guard: fails, naming the element, the time and step and the
 * setting to change, on the first tetrahedron of the current configuration
 * X + u that is inverted (signed volume <= 0; 10-node elements: det J <= 0
 * at a quadrature point) or stretched beyond cfg.max_strain (largest
 * |component| of its small strain, at each quadrature point for tet10). O(n_tets), no
 * allocation. The range version looks at elements [e0, e1) only: fem_advance
 * checks a share after each interval, every element once per 10
 * cfg.check_every intervals. */
int fem_check_elements(const fem_model *m, cm_error *err);
int fem_check_elements_range(const fem_model *m, int e0, int e1, cm_error *err);

/* Energy guard: fails when the tire's energy E (above) has grown by more than
 * 5 % of the energy scale (initial elastic energy + the loads' absolute work)
 * beyond the work the loads put in: energy from nowhere, an unstable
 * integration. Called by fem_advance every cfg.check_every intervals. */
int fem_check_energy(const fem_model *m, cm_error *err);

#endif
