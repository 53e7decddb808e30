/* dem: discrete element side of the DEM–FEM tire tread co-simulation.
 *
 * Spherical grains (and, mixed with them, ellipsoids and convex polyhedra:
 * dem_shape_add / dem_grain_add_shape, rotation by Euler's equations with a
 * quaternion, libccd narrow phase; README "Non-spherical grains"), Hertz–Mindlin contacts (normal Hertz force with a
 * restitution-calibrated dashpot, Mindlin tangential spring with history and
 * Coulomb cap, optional rolling resistance: a constant torque or an
 * elastic–plastic spring), planar walls and
 * one deformable triangle surface (the FE tire's outer skin), integrated with
 * velocity Verlet (paper eqs. 4–5) for translation and directly in ω with a
 * unit quaternion for orientation.
 *
 * Units: SI throughout (m, s, kg, N, Pa, rad).
 *
 * One time step is split so that the FEM step overlaps the grain–grain work:
 *   dem_surface_update(w, node_x, node_v, err)   new surface state, BVH refit
 *   dem_step_surface(w, err)                     gravity + walls + triangles at x(t);
 *                                                node forces and totals ready
 *   dem_step_grains(w, err)                      grain–grain, Verlet completion,
 *                                                x(t) -> x(t+dt), time += dt
 * A walls-only step is dem_step_surface then dem_step_grains (dem_step does both).
 * dem_step_surface_then(w, fn, user, err) in dem_step_surface's place hands
 * the node forces and totals to fn as soon as they are ready: at once in one
 * process; in a distributed run, where the ranks' contacts are summed on
 * rank 0, between blocks of the next dem_step_grains' grain pairs (or after
 * them), so that no rank waits for the slowest surface pass.
 *
 * Velocities: the integrator is velocity Verlet in its predictor/corrector
 * form (paper sec. 2.1.1). Between steps a grain holds x(t+dt) and the
 * predicted velocity v(t+dt/2) = v(t) + a(t) dt/2; the contact dashpots see
 * that predicted velocity (as LIGGGHTS does). dem_grain_get() returns it.
 *
 * Errors: functions that can fail return CM_OK or a negative cm_error code and
 * fill the caller's cm_error with a message naming the grain, step, key or file.
 * Scene keys of the `dem` section are documented in dem_server/README.md. */
#ifndef DEM_H
#define DEM_H

#include <stdbool.h>
#include <stdint.h>

#include "error.h"

#define DEM_MAX_MATERIALS 8
#define DEM_MAX_WALLS 16

typedef struct dem_world dem_world;

/* ---- Materials -------------------------------------------------------- */

typedef struct dem_material {
    double density;          /* kg/m^3 (grains only; walls and the surface ignore it) */
    double young;            /* Young's modulus E, Pa */
    double poisson;          /* Poisson's ratio ν, [0, 0.5) */
    double restitution;      /* requested normal coefficient of restitution e, (0, 1] */
    double friction;         /* Coulomb sliding friction coefficient μ, >= 0 */
    double rolling_friction; /* rolling resistance μ_r (largest torque μ_r R* Fn, enum dem_rolling_model); 0 = off */
} dem_material;

/* Pair values mix the two materials: E*, G* after Hertz/Mindlin (eqs. 21, 26),
 * e, μ and μ_r as arithmetic means. */

enum dem_damping_model {
    /* Dashpot coefficient fitted so that the ACHIEVED restitution of a Hertz
     * contact whose force is clamped at >= 0 equals the requested e (the
     * non-dimensional impact equation is solved once per material pair). */
    DEM_DAMPING_CALIBRATED = 0,
    /* Plain ln(e) form (Tsuji 1992 / LIGGGHTS): achieved e overshoots. */
    DEM_DAMPING_LN_E = 1
};

/* How rolling resistance acts (dem_contact.h has the laws). */
enum dem_rolling_model {
    /* A torque μ_r R* F_n against the relative angular velocity, limited so
     * that it cannot reverse it within a step (Zhou et al. 1999, LIGGGHTS'
     * "cdt"). It cannot hold a torque at rest: a grain under a steady torque
     * below the limit turns at ω = T dt / I, so a bed's strength depends on
     * the step (README "Rolling resistance"). */
    DEM_ROLLING_CONSTANT_TORQUE = 0,
    /* An elastic–plastic spring with a dashpot on the relative rotation, its
     * torque capped at μ_r R* F_n (Iwashita & Oda 1998; Ai et al. 2011 model
     * C, LIGGGHTS' "epsd"): below the cap a grain stands still, whatever the
     * step. History per contact, like the tangential spring. Sphere–sphere
     * and sphere–wall contacts; the tire surface and shaped grains keep the
     * constant torque. */
    DEM_ROLLING_SPRING = 1
};

/* ---- World ------------------------------------------------------------ */

/* Builds of the vectorised loops, in the order of their width (the same
 * bits in each: dem_pairs.c, "the batched kernel"). */
enum dem_kernels {
    DEM_KERNELS_AUTO = 0,  /* the best for this CPU */
    DEM_KERNELS_PORTABLE,  /* the x86-64 baseline (SSE2) or any other CPU's */
    DEM_KERNELS_AVX2,      /* four lanes */
    DEM_KERNELS_AVX512     /* eight lanes */
};

typedef struct dem_world_def {
    double dt;               /* time step, s */
    double gravity[3];       /* m/s^2 */
    int max_grains;          /* capacity; grains can be added up to it */
    int threads;             /* OpenMP threads; 0 = OpenMP default (1 without OpenMP) */
    double skin;             /* neighbour-list skin, m; <= 0 picks 0.3 * smallest radius */
    int damping;             /* enum dem_damping_model */
    double impact_velocity;  /* largest expected relative speed for the Hertz dt check, m/s */
    double dt_safety_rayleigh; /* dt must be <= this * Rayleigh time (default 0.3) */
    double dt_safety_hertz;    /* dt must be <= this * Hertz contact time (default 0.1) */
    bool allow_unstable;     /* true: a dt above the limits only warns */
    int reorder_every;       /* re-sort grains by cell (and tag inside a cell) every N neighbour rebuilds
                                (0 = never); 1 (the default) is needed by a distributed run */
    int rolling_model;       /* enum dem_rolling_model (default constant torque) */
    int kernels;             /* enum dem_kernels: the widest build of the vectorised loops (pairs, walls,
                                integration) to run; DEM_KERNELS_AUTO (0, the default) the best for this CPU
                                (dem_kernels_of). The same bits in every build; for the tests that show it */
    double gather_test_every; /* s, distributed: how often the surface contacts' gather to rank 0 is tested
                                 among the grain pairs (dem_step_surface_then); default 1.25e-4. A test costs
                                 a few us (MPI progress, a yield); testing seldom delays fem_server's step,
                                 which on two cores must overlap the other ranks' pairs: on the paper scene
                                 on 2 ranks, tests every ~500 us ran 0.90x as fast as every ~130 us, every
                                 ~35 us 0.97x (within the noise; session 15). 0: after every block of pairs */
} dem_world_def;

dem_world_def dem_world_def_default(void);

/* Materials are copied; their pair coefficients (and the damping calibration)
 * are computed here. */
int dem_world_create(const dem_world_def *def, int n_materials, const dem_material *materials,
                     dem_world **out, cm_error *err);
void dem_world_destroy(dem_world **w);

/* ---- Grains ----------------------------------------------------------- */

typedef struct dem_grain_state {
    double x[3];     /* position of the centre, m */
    double v[3];     /* velocity, m/s (predicted half-step value, see above) */
    double w[3];     /* angular velocity, rad/s */
    double q[4];     /* orientation quaternion (w, x, y, z); a sphere's turns only in a world with shaped grains */
    double f[3];     /* total force of the last step, N */
    double t[3];     /* total torque of the last step, N m */
    double radius;   /* m */
    double mass;     /* kg */
    int material;
    /* non-spherical grains (dem_grain_add_shape); spheres: shape = -1, scale = 1,
     * inertia = (2/5 m r^2) x 3 and radius is the sphere's */
    int shape;          /* shape id, -1 = sphere */
    double scale;       /* length factor applied to the shape */
    double inertia[3];  /* principal moments of inertia, kg m^2 (body frame, see dem_shape_info) */
} dem_grain_state;

/* Adds a grain at rest; *id (may be NULL) receives its id (0, 1, 2, ... in
 * order of addition; ids are stable even when grains are re-sorted). */
int dem_grain_add(dem_world *w, const double x[3], double radius, int material, int *id, cm_error *err);
int dem_grain_count(const dem_world *w);
/* The build of the vectorised loops this world runs on this CPU:
 * "portable", "avx2" or "avx512" (enum dem_kernels; "avx512": its pair
 * kernel, the others' AVX2). */
const char *dem_kernels_name(const dem_world *w);
int dem_grain_get(const dem_world *w, int id, dem_grain_state *s);
/* Sets position, velocity and angular velocity (the rest of s is ignored). */
int dem_grain_set(dem_world *w, int id, const double x[3], const double v[3], const double omega[3]);

/* ---- Removing and adding grains (the terrain window) ----------------- */

/* Ids and tags. An id is a grain's index in the API: dense, 0 .. count-1, in
 * order of addition. Removing grains renumbers the survivors keeping their
 * order (id k becomes k minus the number of removed grains of smaller id).
 * A tag is given once at addition (0, 1, 2, ... over the world's life) and
 * never changes nor is reused: the output writes it, so that a grain can be
 * followed across removals, and the grain-grain contact history is keyed by
 * it. Without removals tag = id. */
int dem_grain_tag(const dem_world *w, int id);
/* Removes every grain whose centre has x < x_cut; *removed (may be NULL)
 * receives how many. The arrays are compacted in place (no allocation), the
 * removed grains' wall, surface and pair springs go with them, the survivors'
 * springs stay, and the neighbour list is rebuilt before the next pair step.
 * CM_ERR_NOMEM (nothing else can fail) if the contact history could not be
 * re-entered; the world must not be stepped then. */
int dem_grains_remove_below_x(dem_world *w, double x_cut, int *removed);
/* Removes the grains of the n listed ids (ids as before the call; repeats
 * are ignored). CM_ERR_RANGE for an id out of range, nothing removed then. */
int dem_grains_remove(dem_world *w, int n, const int *ids, cm_error *err);
/* Adds n grains copied from saved states (dem_grain_get): position plus
 * offset (may be NULL), velocity, angular velocity, orientation, radius or
 * shape and scale, material. All or none: fails if the world has no room. */
int dem_grains_add_states(dem_world *w, int n, const dem_grain_state *s, const double offset[3], cm_error *err);

/* Frozen grains: every grain whose centre has x < x_lo or x > x_hi is frozen
 * (velocities zeroed, no longer integrated, its contacts with other frozen
 * grains skipped at no cost; an active grain still feels a frozen one), the
 * others are thawed. The neighbour list is rebuilt when the set changes.
 * Returns the number frozen. (-INFINITY, INFINITY) thaws all. */
int dem_freeze_outside_x(dem_world *w, double x_lo, double x_hi);

/* ---- Non-spherical grains ------------------------------------------- */

/* A grain class: convex shape in its own frame (m). The world stores it in its
 * principal frame about its centre of mass (dem_shape_info gives both), and a
 * grain of the class is posed by its centre of mass and a unit quaternion
 * rotating that principal frame into the world. Spheres keep their own fast
 * path (dem_grain_add); a scene may mix both. */
enum dem_shape_type { DEM_SHAPE_SPHERE = 0, DEM_SHAPE_ELLIPSOID = 1, DEM_SHAPE_POLYHEDRON = 2 };
#define DEM_SHAPE_MAX_VERTS 64
#define DEM_MAX_SHAPES 256

typedef struct dem_shape_def {
    int type;                             /* enum dem_shape_type */
    double radius;                        /* sphere, m */
    double semi_axes[3];                  /* ellipsoid, m (any order; principal frame sorts them) */
    int n_verts;                          /* polyhedron: 4..DEM_SHAPE_MAX_VERTS points, */
    double verts[DEM_SHAPE_MAX_VERTS][3]; /* m; their convex hull is the grain */
} dem_shape_def;

typedef struct dem_shape_info {
    int type;
    double volume;       /* m^3 */
    double r_bound;      /* bounding-sphere radius about the centre of mass, m (broad phase) */
    double r_eq;         /* radius of the sphere of equal volume, m */
    double inertia[3];   /* principal moments per unit density, m^5 (x density = kg m^2), ascending */
    double com[3];       /* centre of mass in the frame of the definition, m */
    double axes[9];      /* principal axes as columns, in the frame of the definition */
    int n_verts;         /* polyhedron: hull vertices (principal frame) */
    int n_faces;         /* polyhedron: hull faces (planes) */
} dem_shape_info;

/* Random angular grain: n_verts points on an ellipsoid of axis ratios
 * elongation : 1 : 1 with radial jitter (angularity), rescaled so that the
 * volume-equivalent radius is r_eq. The same seed gives the same grain. */
int dem_shape_random_polyhedron(uint64_t seed, double r_eq, double elongation, int n_verts, dem_shape_def *out,
                                cm_error *err);
/* Mass properties of a definition (hull, volume, centre of mass, principal
 * inertia); no world needed. */
int dem_shape_compute(const dem_shape_def *def, dem_shape_info *info, cm_error *err);
/* Registers a shape in the world; *shape receives its id (0, 1, ...). */
int dem_shape_add(dem_world *w, const dem_shape_def *def, int *shape, cm_error *err);
int dem_shape_get_info(const dem_world *w, int shape, dem_shape_info *info);
/* Adds a grain of shape `shape` scaled by `scale` (lengths; mass ~ scale^3)
 * with its centre of mass at x and orientation q (w, x, y, z; normalised
 * here; NULL = identity) at rest. */
int dem_grain_add_shape(dem_world *w, const double x[3], const double q[4], int shape, double scale, int material,
                        int *id, cm_error *err);
/* Sets the orientation of a grain (normalised here). */
int dem_grain_set_orientation(dem_world *w, int id, const double q[4]);

/* ---- Walls ------------------------------------------------------------ */

/* An infinite plane through `point`; grains live on the side `normal` points to. */
int dem_wall_add(dem_world *w, const double point[3], const double normal[3], int material, cm_error *err);
int dem_wall_count(const dem_world *w);
/* Point and unit normal of wall k (CM_ERR_RANGE if there is none). */
int dem_wall_get(const dem_world *w, int k, double point[3], double normal[3]);
/* Moves wall k to pass through `point` (normal unchanged; the grains'
 * tangential springs on it are kept). */
int dem_wall_move(dem_world *w, int k, const double point[3]);

/* ---- Triangle surface (the FE tire) ----------------------------------- */

/* Installs the surface once: n_nodes positions x0 (3 n_nodes), n_tris
 * triangles as node-index triples. Velocities start at zero. */
int dem_surface_set(dem_world *w, int n_nodes, const double *x0, int n_tris, const int *tris, int material,
                    cm_error *err);
/* Lumped masses of the surface nodes (n, kg; 0 = a fixed node), so that a
 * grain–surface contact uses the two-body effective mass of the grain and the
 * surface point (1/m* = 1/m_grain + sum_k w_k^2 / m_k). Without it (or with
 * NULL) the surface counts as rigid: m* = m_grain. */
int dem_surface_set_masses(dem_world *w, const double *node_mass, cm_error *err);
/* New node positions and velocities (3n each, world frame); refits the BVH. */
int dem_surface_update(dem_world *w, const double *node_x, const double *node_v, cm_error *err);
/* Reference point for the moment and unit travel direction for T_H / T_R. */
void dem_surface_set_frame(dem_world *w, const double ref_point[3], const double travel_dir[3]);

typedef struct dem_surface_total {
    double force[3];     /* N, resultant force the grains exert ON the surface */
    double moment[3];    /* N m, its moment about the reference point */
    double traction_pos; /* N, T_H: sum of positive per-contact components along travel */
    double traction_neg; /* N, T_R: sum of negative per-contact components (<= 0) */
    int contacts;        /* grain–surface contacts after de-duplication */
    double max_overlap;  /* largest grain–surface overlap / grain radius (the run-time guard's) */
    int worst_grain;     /* slot of the grain with that overlap, its triangle (when contacts > 0) */
    int worst_tri;
    double energy;       /* J, elastic energy stored in the grain–surface contacts (Hertz, dem_hertz_energy):
                            the interface's energy scale, sent to the FEM for its work guard */
} dem_surface_total;

/* Per-node forces ON the surface from the last dem_step_surface (3n, N),
 * the contact forces distributed with barycentric weights (eq. 42). */
const double *dem_surface_node_forces(const dem_world *w);
void dem_surface_totals(const dem_world *w, dem_surface_total *t);

/* ---- Stepping --------------------------------------------------------- */

int dem_step_surface(dem_world *w, cm_error *err);
int dem_step_grains(dem_world *w, cm_error *err);
int dem_step(dem_world *w, cm_error *err); /* both */
/* What is to be done with a surface pass's node forces and totals (rank 0:
 * the whole surface's); an error stops the step with it. */
typedef int (*dem_surface_ready_fn)(dem_world *w, void *user, cm_error *err);
int dem_step_surface_then(dem_world *w, dem_surface_ready_fn fn, void *user, cm_error *err);

/* ---- Diagnostics ------------------------------------------------------ */

typedef struct dem_profile {
    /* wall-clock seconds per stage of the step (dem_world.c), summed over the
     * run; a stage's share is its time over the sum of the four */
    double rebuild;   /* s, neighbour grid, grain re-sort, pair list, history carry-over */
    double surface;   /* s, gravity, walls and the triangle surface (incl. BVH refit) */
    double pairs;     /* s, grain–grain narrow phase, forces summed into the grains in pair order */
    double integrate; /* s, Verlet, rotation, the moved-grain check */
    double halo;      /* s, distributed run: ghosts refreshed and the rebuild decision agreed by every rank */
    double migrate;   /* s, distributed run: slabs, grains to their new ranks, fresh ghosts (part of rebuild) */
    double surf_gather; /* s, distributed run: the ranks' surface contacts gathered and summed on rank 0 (part of
                         * surface, also where its end falls among the grain pairs) */
    double idle;      /* s, outside the step: the coupled loop waiting for fem_server's reply or (other ranks) rank 0's */
    double wait_cpu;  /* s, distributed run: this rank's CPU time in halo, migrate, surf_gather and idle, the part
                       * of those waits its core had nothing else to do (the rest it ran fem_server, say) */
    long steps;       /* steps timed */
    long rebuilds;    /* neighbour list rebuilds */
    long surface_lists; /* rebuilds of the grains' triangle lists (the tree walked instead of the lists) */
} dem_profile;

typedef struct dem_stats {
    double time;          /* s */
    long step;
    int grains;
    int frozen;           /* grains frozen by dem_freeze_outside_x */
    double ke_trans;      /* J */
    double ke_rot;        /* J */
    double pe_grav;       /* J, -m g.x summed */
    double e_elastic;     /* J, normal Hertz energy 8/15 E* sqrt(R*) delta^(5/2) */
    int contacts_gg, contacts_gw, contacts_gs;
    double max_overlap;   /* largest delta / r_min of a grain–grain or grain–wall pair */
    double max_overlap_surface; /* largest grain–surface overlap / grain radius in the last step */
    struct {                    /* the grain with that overlap (tag -1: none), for the guard's message */
        int tag, tri;
        double x[3], v[3], r;
        int frozen;
    } worst_surface;
    dem_profile profile;
} dem_stats;

void dem_world_stats(const dem_world *w, dem_stats *s);
/* dem_world_stats without the energies (e_elastic and pe_grav left zero):
 * what a health check reads, the overlaps and the kinetic energies, without
 * a Hertz energy (a power 5/2) for every contact. */
void dem_world_stats_lean(const dem_world *w, dem_stats *s);
/* dem_world_stats_lean over part `part` of `parts` (0 <= part < parts) of
 * the grain slots and of the pair list: the kinetic energies and largest
 * overlap of that share, the clock, counts and the surface's overlaps of
 * the whole. Over `parts` calls, one per part, every grain and pair is
 * looked at once: a health check spread over as many exchanges. */
void dem_world_stats_part(const dem_world *w, int part, int parts, dem_stats *s);
/* Adds to the profile's idle time (the coupled loop's waits outside the step):
 * seconds of wall time, cpu_seconds of the calling thread's CPU time in them. */
void dem_world_add_idle(dem_world *w, double seconds, double cpu_seconds);
/* Steps taken so far (cheap; dem_world_stats sums over every grain and pair). */
long dem_world_steps(const dem_world *w);

/* Distributed on two ranks (dem_mpi.h): `bytes` of buf carried from rank 0
 * to rank 1 in the next step's halo exchange, the one message the two
 * ranks swap after integrating (with the ghosts' states and the rebuild's
 * agreement), instead of in a collective of their own. The coupled loop
 * (dem_coupled.c) sends fem_server's reply this way. Rank 0 calls fill (if
 * any) just before sending: its time is a wait (dem_profile.idle), not the
 * halo's. Set on both ranks with the same bytes, for one
 * dem_step_grains. */
typedef struct dem_halo_rider {
    void *buf;
    size_t bytes;
    int (*fill)(void *user, cm_error *err); /* rank 0: writes buf */
    void *user;
    double fill_s; /* out, rank 0: s spent in fill */
    int carried;   /* out: 1 once the step's halo has carried buf */
} dem_halo_rider;

/* r rides the next halo (r NULL: none); the world keeps the pointer and
 * writes r's outputs. Fails unless the world is distributed on two ranks. */
int dem_world_set_halo_rider(dem_world *w, dem_halo_rider *r, cm_error *err);
/* Total force on wall k from the last step (the grains push it), N. */
int dem_wall_force(const dem_world *w, int k, double f[3]);
/* Contacts per grain (by id), out has dem_grain_count entries. */
void dem_grain_contact_counts(const dem_world *w, int *out);
/* Time-step limits for the current grains: Rayleigh time and Hertz contact
 * time at def.impact_velocity (s). */
void dem_time_limits(const dem_world *w, double *t_rayleigh, double *t_hertz);
/* Dashpot factor gamma_n giving restitution e (model: enum dem_damping_model;
 * the calibrated one is fitted to the clamped contact, see dem_contact.c). */
double dem_damping_for_restitution(double e, int model);
/* FNV-1a hash of all grain positions, velocities, tags and frozen flags (determinism tests). */
uint64_t dem_world_hash(const dem_world *w);
const dem_world_def *dem_world_get_def(const dem_world *w);
const dem_material *dem_world_material(const dem_world *w, int k);
int dem_world_material_count(const dem_world *w);

/* The rest of the library's public interface, by job: dem_bed.h (settled
 * beds and their cache), dem_output.h (grain states and series to HDF5/CSV),
 * dem_config.h (the scene's dem section). */

#endif
