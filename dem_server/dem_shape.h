/* Non-spherical grains: shapes (ellipsoid, convex polyhedron), their mass
 * properties, rigid-body rotation (paper eq. 8) and the libccd narrow phase.
 *
 * Narrow phase: MPR (ccdMPRPenetration), not GJK+EPA. MPR allocates nothing
 * (safe and cheap inside the OpenMP pair loop; EPA mallocs its polytope on
 * every call) and converges in a handful of support calls for the smooth or
 * few-vertex shapes here. Its depth is that along the direction of the portal
 * it converged to, not always the minimum translation: exact for a sphere
 * against a face, within a few per cent near edges and vertices
 * (test_dem_shapes/sphere_triangle_vs_ccd measures it against the closed
 * form). GJK+EPA is kept behind a flag for that cross-check.
 *
 * libccd's tolerances are absolute: every query runs in coordinates centred
 * on the first body and divided by the larger bounding radius of the pair, so
 * mpr_tolerance is relative to the grain size. CCD_INIT leaves max_iterations
 * unlimited; we set it.
 *
 * The code, by job: dem_shape.c (shapes: hulls, mass properties, random
 * polyhedra), dem_shape_algebra.c (3x3 algebra), dem_shape_rotation.c (free
 * rotation), dem_shape_ccd.c (posed bodies, libccd), dem_shape_contact.c
 * (contacts of shaped grains); dem_poly_contact.c (polyhedron pairs by
 * overlap volume). */
#ifndef DEM_SHAPE_H
#define DEM_SHAPE_H

#include <stdint.h>

#include "dem.h"

typedef struct dem_world dem_world;

_Static_assert(DEM_SHAPE_MAX_VERTS <= 64, "dem_shape.face_mask holds one bit per vertex");

typedef struct dem_shape {
    int type;                             /* enum dem_shape_type */
    double a[3];                          /* ellipsoid semi-axes in the principal frame, m (descending) */
    int n_verts;                          /* polyhedron hull vertices */
    double v[DEM_SHAPE_MAX_VERTS][3];     /* principal frame, about the centre of mass, m */
    int n_edges;                          /* polyhedron hull edges (pairs of indices into v) */
    int e[3 * DEM_SHAPE_MAX_VERTS][2];
    int n_faces;                          /* polyhedron hull planes: n . x <= d inside */
    double f[2 * DEM_SHAPE_MAX_VERTS][4]; /* (n, d), principal frame, m */
    /* vertices of face k: face_vert[face_first[k] .. face_first[k + 1]),
     * counter-clockwise about its outward normal (the overlap-volume contact
     * clips them) */
    int face_first[2 * DEM_SHAPE_MAX_VERTS + 1];
    unsigned char face_vert[6 * DEM_SHAPE_MAX_VERTS];
    uint64_t face_mask[2 * DEM_SHAPE_MAX_VERTS]; /* bit t: vertex t is a corner of face k */
    dem_shape_info info;
} dem_shape;

int dem_shape_build(const dem_shape_def *def, dem_shape *s, cm_error *err);

/* Rotation matrix (row-major, body -> world) of a unit quaternion (w, x, y, z). */
void dem_quat_to_mat(const double q[4], double R[9]);

/* A posed convex body as libccd sees it, in scaled coordinates. */
enum dem_body_type { DEM_BODY_SPHERE, DEM_BODY_ELLIPSOID, DEM_BODY_POLY, DEM_BODY_TRIANGLE };
typedef struct dem_body {
    int type;
    const dem_shape *s;
    double k;        /* shape length -> scaled length (scale / L); sphere: scaled radius */
    double c[3];     /* centre, scaled */
    double R[9];     /* body -> world */
    double tri[3][3];/* triangle vertices, scaled */
    double tc[3];    /* triangle: the interior point MPR starts from, scaled (see below) */
} dem_body;

/* A triangle body whose MPR interior point is the triangle's closest point to
 * `toward` (the other body's centre) when that is not on the triangle, its
 * centroid otherwise. MPR searches along the line between the two interior
 * points: from the closest point, the line is the contact normal of a sphere
 * (exact, as the closed form) and a good start for any convex grain; from the
 * centroid a large triangle would be "penetrated" sideways. */
void dem_body_triangle(const double a[3], const double b[3], const double c[3], const double toward[3],
                       dem_body *out);

/* Support point of b in direction d (scaled coordinates). */
void dem_body_support(const dem_body *b, const double d[3], double out[3]);

/* Contact point of body b overlapping another by depth along n (n points
 * towards b): its deepest point support(-n) moved by frac * depth along n;
 * for a polyhedron the mean of its vertices inside the overlap slab weighted
 * by how deep they are, moved onto that same plane, so that a face lying
 * flat on another is pushed through its middle instead of a corner. */
void dem_body_contact_point(const dem_body *b, const double n[3], double depth, double frac, double out[3]);

/* Contact point of two overlapping bodies (normal n from j to i, scaled
 * coordinates). With a polyhedron: the centre of the overlap's edge skeleton
 * (the parts of each polyhedron's edges inside the other body, length-
 * weighted midpoints) projected on the middle plane of the overlap; it moves
 * continuously as features enter the overlap. Polyhedron face on a smooth
 * body with no edge inside: the smooth body's deepest point. Two smooth
 * bodies: the middle of their deepest points. ccd_pos (libccd's point) is the
 * last resort. */
void dem_pair_contact_point(const dem_body *bi, const dem_body *bj, const double n[3], double depth,
                            const double ccd_pos[3], double out[3]);

/* Penetration of b into a (MPR, or GJK+EPA when gjk_epa): n is the unit
 * normal pointing from a to b (translating b by depth along n separates them:
 * libccd's convention with obj1 = a, obj2 = b), p a point in the overlap
 * (libccd: between the two surfaces). Returns 1 in contact, 0 apart, < 0 on
 * a libccd failure. Scaled coordinates throughout. */
int dem_body_penetration(const dem_body *a, const dem_body *b, int gjk_epa, double *depth, double n[3],
                         double p[3]);

/* Effective contact radius of a grain at the surface point whose outward
 * unit normal is u (world frame): ellipsoid, the Gaussian radius of curvature
 * 1/sqrt(K) = abc / (a² u1² + b² u2² + c² u3²) (u in the body frame);
 * polyhedron, the volume-equivalent radius (its faces are flat and its edges
 * sharp; see README). Times scale. */
double dem_shape_contact_radius(const dem_shape *s, double scale, const double R[9], const double u[3]);

/* Free rotation of a rigid body over dt with constant world angular momentum
 * L (Euler's equations, eq. 8, with zero torque), principal moments I:
 * NO_SQUISH splitting (Miller et al., J. Chem. Phys. 116, 2002): exact
 * rotations about body axes 3, 2, 1, 2, 3 for dt/2, dt/2, dt, dt/2, dt/2.
 * Each sub-step is the exact flow of one term of the kinetic energy, so the
 * scheme is symplectic and time-reversible, keeps |q| = 1 (renormalised
 * against round-off), keeps L exactly and the energy within O(dt²) without
 * drift. omega receives the world angular velocity at the new orientation. */
void dem_rotate_free(double q[4], const double L[3], const double I[3], double dt, double omega[3]);

/* Grain-level contacts of shaped grains (dem_world.c calls these). */
/* pair of slots i, j (at least one shaped): adds forces and torques, returns 1 in contact */
int dem_shaped_pair(dem_world *w, int i, int j, double *xi, double *fx, double *fy, double *fz, double *tx,
                    double *ty, double *tz);
/* shaped grain i against wall k (its bounding sphere already overlaps it):
 * force and torque added to out_f/out_t; returns 1 in contact */
int dem_shaped_wall(dem_world *w, int i, int k, double *xi, double out_f[3], double out_t[3]);
/* polyhedron pair (both hulls posed by dem_shaped_pose_update this step,
 * bounding spheres overlapping): overlap-volume contact (dem_poly_contact.c) */
int dem_poly_pair(dem_world *w, int i, int j, double *xi, double *fx, double *fy, double *fz, double *tx, double *ty,
                  double *tz);
/* overlap volume of polyhedral slots i, j at the last pose update, m^3 */
double dem_poly_overlap_volume(const dem_world *w, int i, int j);
/* per-grain world-frame hulls (rotation, vertices, face planes) of the
 * polyhedral grains: allocated when the world is prepared (cap x stride),
 * refreshed once per step before the narrow phase */
int dem_shaped_pose_alloc(dem_world *w, cm_error *err);
void dem_shaped_pose_update(dem_world *w);
/* diagnostics: depth of slot i below the plane (p, n) (> 0: overlap), and
 * whether slots i, j overlap */
double dem_shaped_plane_depth(const dem_world *w, int i, const double p[3], const double n[3]);
int dem_shaped_pair_touch(const dem_world *w, int i, int j);
/* pose of slot i as a libccd body, scaled about origin by 1/L */
void dem_grain_body(const dem_world *w, int i, const double origin[3], double inv_l, dem_body *b);

#endif
