/* FEM server of the DEM-FEM tire co-simulation: the public interface.
 *
 * A linear elastic tire (eqs. 28-34 of the XDEM-FEM paper) on linear
 * tetrahedra. The deformation u is computed in the rim frame, where the rim
 * nodes are fixed; the wheel as a whole moves rigidly (centre c, rotation R,
 * velocity v_c, angular velocity omega) and world-frame positions of the
 * interface nodes are  x = c + R (X + u),  velocities
 *   v = v_c + omega x R (X + u) + R du/dt.
 *
 * Life cycle:
 *   fem_config cfg = fem_config_default();  fem_config_read(scene, &cfg, &err);
 *   fem_create(&cfg, &model, &err);          mesh, K (eq. 34), M (eq. 33), loads
 *   fem_solve_static(model, &err);           K u0 = b0 (sect. 3.3), start state
 *   loop: fem_interface_state(...)           -> DEM
 *         fem_advance(model, f_iface, dt_exchange, &err)   <- DEM forces
 *         fem_output_due(model, &err)       snapshot every fem.output.every advances
 *   fem_destroy(&model);
 *
 * Units: SI throughout (m, s, kg, N, Pa). Interface arrays are indexed by the
 * compact interface node list (0..n_nodes-1), xyz interleaved, world frame. */
#ifndef FEM_H
#define FEM_H

#include <stdbool.h>
#include <stdint.h>

#include "error.h"
#include "scene.h"

typedef struct fem_model fem_model;

typedef enum fem_mesh_type { FEM_MESH_TIRE = 0, FEM_MESH_GMSH = 1, FEM_MESH_BOX = 2 } fem_mesh_type;
typedef enum fem_integrator {
    FEM_INTEGRATOR_EXPLICIT = 0, /* central differences, eq. 32 (lumped M) */
    FEM_INTEGRATOR_NEWMARK = 1,  /* average acceleration, unconditionally stable */
    FEM_INTEGRATOR_RIGID = 2     /* no deformation: u = 0 */
} fem_integrator;

/* The elastic law: eq. 29, or compressible Neo-Hookean with the same
 * small-strain E and nu (fem_material.h; explicit integrator only). */
typedef enum fem_material_model { FEM_MATERIAL_LINEAR = 0, FEM_MATERIAL_NEO_HOOKEAN = 1 } fem_material_model;
/* fem.element: the linear tetrahedron (eq. 34, default) or the 10-node
 * quadratic one (fem_element.h: no locking in bending; HRZ lumped mass). */
typedef enum fem_element_type { FEM_ELEMENT_TET4 = 0, FEM_ELEMENT_TET10 = 1 } fem_element_type;
typedef enum fem_linear_solver { FEM_LINEAR_CHOLMOD = 0, FEM_LINEAR_CG = 1 } fem_linear_solver;

/* Parametric 165/65 R13 tire. Axle along y, rolling in the x-z plane; the
 * cross-section is a shell of thickness `wall` around a mid-line made of two
 * vertical sidewalls (from the rim up), two shoulder arcs and a flat crown;
 * lugs of depth `lug_depth` stand on the crown and shoulders, alternating
 * between the two tread halves (left lugs in the right half's grooves),
 * separated by a centre groove one cell wide on each side of the mid-plane
 * (without it the two halves' lugs would touch along single edges). */
typedef struct fem_tire_def {
    double outer_radius;    /* m, lug tops on the crown: 0.544/2 = 0.272 */
    double rim_radius;      /* m, 13 in / 2 = 0.1651 */
    double width;           /* m, tread width over the lug tops: 0.165 */
    double wall;            /* m, carcass thickness: 0.016 */
    double lug_depth;       /* m, 0.015 */
    double shoulder_radius; /* m, mid-line radius of the shoulder arcs: 0.025 */
    int lugs;               /* lugs per tread half around the tire: 16 */
    double lug_fraction;    /* share of a pitch a lug covers, (0,1): 0.5 */
    double contact_depth;   /* m, outer faces whose centroid lies within this depth
                               below outer_radius form the contact set: 0.06 */
    double resolution;      /* 1 = paper (about 24 000 tets); cells per direction
                               scale with it, so elements ~ resolution^2..3 */
    int layers;             /* cells through the wall and through the lugs, each; 0: round(resolution)
                               (at least 1) */
} fem_tire_def;

fem_tire_def fem_tire_def_default(void);

/* Supports and loads by named set (fem_bc.c). A set is one of the mesh's
 * named sets (rim: nodes; cavity, contact: boundary faces) or a plane of the
 * mesh's bounding box (xmin ... zmax: the nodes and boundary faces on it). */
typedef enum fem_set {
    FEM_SET_RIM, FEM_SET_CAVITY, FEM_SET_CONTACT,
    FEM_SET_XMIN, FEM_SET_XMAX, FEM_SET_YMIN, FEM_SET_YMAX, FEM_SET_ZMIN, FEM_SET_ZMAX,
    FEM_SET_COUNT
} fem_set;
extern const char *const fem_set_names[FEM_SET_COUNT + 1]; /* NULL-terminated */

enum { FEM_MAX_BC = 16 };
/* Components fix[a] of every node of the set held at displacement value[a]
 * (m, rim frame): all three = clamped, one = roller / symmetry plane. */
typedef struct fem_support {
    fem_set set;
    bool fix[3];
    double value[3];
} fem_support;
typedef enum fem_load_type {
    FEM_LOAD_PRESSURE = 0, /* value[0] Pa, pushing into the body on the set's faces */
    FEM_LOAD_TRACTION = 1, /* value Pa, a vector on the set's faces */
    FEM_LOAD_FORCE = 2     /* value N, the total: faces as a uniform traction, else equal per node */
} fem_load_type;
typedef struct fem_load {
    fem_set set;
    fem_load_type type;
    double value[3];
} fem_load;
typedef enum fem_analysis { FEM_ANALYSIS_STATIC = 0, FEM_ANALYSIS_DYNAMIC = 1 } fem_analysis;

typedef struct fem_config {
    fem_mesh_type mesh;
    fem_tire_def tire;       /* mesh = tire */
    char gmsh_path[512];     /* mesh = gmsh: .msh v4 ASCII, groups rim/cavity/contact */
    double box_size[3];      /* m, mesh = box */
    int box_cells[3];        /* mesh = box, cells per axis (6 tets each) */
    double E;                /* Pa, Young's modulus: 20e6 (table 3) */
    double nu;               /* Poisson's ratio: 0.45 */
    double rho;              /* kg/m^3: 1100 */
    double rayleigh_alpha;   /* 1/s, C = alpha M + beta K: 0 */
    double rayleigh_beta;    /* s: 0 */
    fem_material_model material_model; /* fem.material.model: linear (default) or neo_hookean (explicit) */
    fem_element_type element; /* fem.element: tet4 (default) or tet10 */
    fem_integrator integrator;
    double dt;               /* s, largest FEM sub-step */
    bool allow_unstable;     /* explicit: accept dt above the computed limit */
    fem_linear_solver static_solver;
    double cg_tol;           /* relative residual for CG: 1e-10 */
    int cg_max_iter;         /* 0: 10 * unknowns */
    double pressure;         /* Pa, inflation pressure on the cavity: 0.14e6 */
    double gravity[3];       /* m/s^2, world frame: (0,0,-9.81) */
    int power_iterations;    /* for the stable step: 300 */
    char output_dir[512];    /* results folder ("" = no output) */
    int output_every;        /* snapshot every N calls of fem_advance (0 = none) */
    double series_flush;     /* s of wall time: a coupled run's traction.csv and wheel.h5:/series rows
                                written in blocks at least this often, and at each checkpoint and the
                                end (0 = every row at once): 1 */
    int check_every;         /* energy guard every N calls of fem_advance, elements every 10 N (0 = never): 10 */
    double max_strain;       /* element guard: largest |strain component| accepted: 0.5 */
    double interface_mass_min; /* kg: interface nodes lighter than this are given this mass (selective mass
                                  scaling for a longer exchange interval, fem_model.c); 0 = none */
    int n_supports;          /* 0: the rim set clamped (all three components at 0) */
    fem_support supports[FEM_MAX_BC];
    int n_loads;             /* dead loads besides pressure and gravity (rim frame) */
    fem_load loads[FEM_MAX_BC];
    fem_analysis analysis;   /* fem_server --fem-only: static solve, or from rest to run.end_time */
    /* fem.floor (--fem-only static): a rigid frictionless plane z = floor_height (rim frame) that the
     * nodes of floor_set may touch but not pass (kinematic: exact, fem_bc.c); with floor_load > 0 the
     * height is found at which the floor carries that load (N). */
    bool floor;
    fem_set floor_set;
    double floor_height;     /* m */
    double floor_load;       /* N, 0: the height is given */
    bool floor_refactor;     /* not a scene key: the floor's reference method (each active-set pass
                                refactorizes K with the touching nodes held; also taken with
                                static_solver = cg); tests compare the default (K factorized once, the
                                active set through the contact nodes' influence matrix) with it */
} fem_config;

fem_config fem_config_default(void);

/* Reads the section `fem = {...}` (keys in fem_config.c and the README of
 * the scene format). Relative paths are resolved against the scene folder. */
int fem_config_read(cm_scene *s, fem_config *cfg, cm_error *err);

int fem_create(const fem_config *cfg, fem_model **out, cm_error *err);
void fem_destroy(fem_model **m);

/* Writes the model's mesh as Gmsh .msh v4.1 ASCII with the physical groups
 * rim, cavity and contact, so that a user can inspect or edit the built-in
 * tire in Gmsh and bring it back with mesh type "gmsh". */
int fem_write_mesh_gmsh(const fem_model *m, const char *path, cm_error *err);

/* Solves K u0 = b0 (pressure + gravity, no DEM forces) with the configured
 * solver and makes it the start state (v = 0). Without a load (b0 = 0 on
 * the free dofs) u0 is the prescribed displacement and K is not factorized. */
int fem_solve_static(fem_model *m, cm_error *err);

/* ---- Interface to the DEM ---------------------------------------------- */

void fem_interface_count(const fem_model *m, uint32_t *n_nodes, uint32_t *n_tris);
/* Reference positions (rim frame, undeformed) of the interface nodes,
 * triangles as index triples into that list (outward, counter-clockwise
 * seen from outside), unit outward normals per triangle. Any output may be
 * NULL. Sizes: x 3*n_nodes, tris 3*n_tris, normals 3*n_tris. */
void fem_interface_initial(const fem_model *m, double *x, uint32_t *tris, double *normals);
/* Lumped mass [kg] of each interface node (n_nodes entries); 0 for a fixed
 * (rim) node. The DEM uses it for the two-body contact mass. */
void fem_interface_masses(const fem_model *m, double *mass);
/* Mesh node ids of the interface nodes (n_nodes entries). */
void fem_interface_nodes(const fem_model *m, uint32_t *node_ids);
/* World-frame positions and velocities now (either may be NULL). */
void fem_interface_state(const fem_model *m, double *x, double *v);

/* ---- Wheel (rigid) motion ---------------------------------------------- */

typedef struct fem_wheel {
    double center[3];   /* m, world position of the rim-frame origin */
    double R[9];        /* rotation rim -> world, row-major */
    double v_center[3]; /* m/s */
    double omega[3];    /* rad/s, world frame */
} fem_wheel;

/* Sets the rigid motion; fem_advance then moves it with constant v_center
 * and omega. The default is the identity at the origin, at rest. */
int fem_set_wheel(fem_model *m, const fem_wheel *w, cm_error *err);
void fem_get_wheel(const fem_model *m, fem_wheel *w);

/* ---- Time stepping ----------------------------------------------------- */

/* Advances by `interval` [s] in n = ceil(interval / dt) equal sub-steps,
 * holding the external interface forces f_iface (3 per interface node,
 * world frame, N; NULL = none) constant. Runs the energy and element guards
 * (fem.check_every); writes no files (fem_output_due does). */
int fem_advance(fem_model *m, const double *f_iface, double interval, cm_error *err);

double fem_time(const fem_model *m);

typedef struct fem_stability {
    double dt_estimate; /* s, h_min / c_d: the usual estimate, not a bound */
    double dt_power;    /* s, 2/omega_max, omega_max^2 from power iteration on
                           M^-1 K (converges from below: a slight overestimate) */
    double dt_gershgorin; /* s, 2/sqrt(max_i sum_j |K_ij| / m_i): a rigorous lower
                             bound of the limit, pessimistic */
    double dt_limit;    /* s, the limit applied: dt_power reduced for damping */
    int power_iterations_done;
    double h_min;       /* m, smallest element altitude */
    double wave_speed;  /* m/s, dilatational c_d = sqrt((lambda+2mu)/rho) */
} fem_stability;

int fem_get_stability(const fem_model *m, fem_stability *s);

/* ---- Results ----------------------------------------------------------- */

typedef struct fem_energy {
    double elastic;  /* J, 1/2 u^T K u (deformation) */
    double kinetic;  /* J, 1/2 du^T M du (deformation velocity, rim frame) */
    double load_potential; /* J, -b^T u for the current loads */
} fem_energy;

void fem_get_energy(const fem_model *m, fem_energy *e);

/* Force [N] and torque [N m] about the wheel centre that the rim exerts on
 * the tire, world frame: (K u + C v + M a - f) summed over the rim nodes.
 * The load on the axle is its negative. */
void fem_rim_reaction(const fem_model *m, double force[3], double torque[3]);

/* Mass [kg] of the tire mesh (sum of the lumped masses of eq. 33) and its
 * moment of inertia [kg m^2] about the axle (the rim frame's y axis). */
void fem_mass_properties(const fem_model *m, double *mass, double *inertia_axle);

/* The static solve against the rigid frictionless floor of cfg.floor (kinematic: the touching
 * nodes' z held on the plane, an active set iterated until every held node is pushed, not
 * pulled, and no free node is below the plane); with cfg.floor_load the height is searched
 * (bracketed secant) until the floor carries that load within 1e-6. K is factorized once (the
 * supports only); each pass solves the small dense system of the held nodes' influence matrix
 * G_AA = (K^-1)_AA for their reactions, u = u0 + K^-1 E_A lambda: exact, the same answer as
 * holding the nodes in K (fem_config.floor_refactor, the reference) to round-off. */
typedef struct fem_floor_result {
    double height;      /* m, the floor plane (rim frame) */
    double deflection;  /* m, height - z_free: how far the floor pressed in */
    double z_free;      /* m, the set's lowest z under the loads without the floor (the inflated tire's
                           bottom); the undeformed lowest z when the body needs the floor to be held */
    double reaction;    /* N, the floor's push on the body (+z) */
    double max_below;   /* m, the deepest node of the set below the plane (0 up to round-off) */
    int contact_nodes;  /* nodes held on the plane */
    int solves;         /* active-set passes over the whole search */
    int factorizations; /* of K: 1 (the reference method, fem_config.floor_refactor: one per pass) */
    int columns;        /* influence columns K^-1 e_z solved, one per node that was ever held (0 for the
                           reference method) */
} fem_floor_result;
int fem_floor_static(fem_model *m, fem_floor_result *r, cm_error *err);

/* Mass [kg] added to the interface nodes by fem.interface_mass_min (0 without). */
double fem_added_mass(const fem_model *m);

/* Mesh sizes, and the node displacements in the rim frame (3 per node). */
void fem_mesh_size(const fem_model *m, int *n_nodes, int *n_tets);
const double *fem_displacement(const fem_model *m);

/* Writes a snapshot (deformed mesh, u, strain, stress incl. e22 and e33)
 * now, whatever output_every says. No-op without an output folder. */
int fem_write_snapshot(fem_model *m, cm_error *err);
/* Writes a snapshot when the advances so far are a multiple of
 * fem.output.every and none was written at this advance yet: call it after
 * each fem_advance (fem_server's snapshot stage does). */
int fem_output_due(fem_model *m, cm_error *err);

#endif
