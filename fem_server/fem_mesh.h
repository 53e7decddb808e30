/* Tetrahedral mesh with its boundary surface and named sets. Internal to
 * fem/ (tests include it through the private include path).
 *
 * Named sets, the same for every mesh source:
 *   rim     nodes, all three displacement components fixed (Dirichlet);
 *   cavity  boundary faces loaded by the inflation pressure;
 *   contact boundary faces that may touch the soil: the DEM interface. */
#ifndef FEM_MESH_H
#define FEM_MESH_H

#include <stdbool.h>
#include <stdint.h>

#include "error.h"
#include "fem.h"

enum { FEM_FACE_CAVITY = 1, FEM_FACE_CONTACT = 2, FEM_FACE_RIM = 4 };
enum { FEM_NODE_RIM = 1 };

typedef struct fem_mesh {
    int n_nodes;
    double *x;          /* 3*n_nodes reference coordinates [m] */
    int n_tets;
    int32_t *tets;      /* 4*n_tets node indices, positive volume */
    /* Boundary surface: faces belonging to exactly one tet, ordered so that
     * (x1-x0)x(x2-x0) points out of the body. */
    int n_faces;
    int32_t *faces;     /* 3*n_faces */
    int32_t *face_tet;  /* owning tet of each face */
    uint8_t *face_tag;  /* FEM_FACE_* bits */
    int32_t *face_sorted; /* face indices sorted by their sorted node triple (lookup) */
    uint8_t *node_tag;  /* FEM_NODE_* bits */
    int32_t *node_ijk;  /* structured meshes: 3 grid indices per node, else NULL */
    char source[256];   /* where the mesh came from, for messages */
} fem_mesh;

/* A structured grid of ni x nj x nk hexahedral cells, each split into six
 * tetrahedra around its main diagonal (Kuhn/Freudenthal split: the face
 * diagonals of neighbouring cells coincide, so the mesh is conforming, also
 * across the periodic seam in i). `map` gives the position of grid point
 * (i,j,k); `cell` (NULL: all) says which cells exist. */
typedef struct fem_grid {
    int ni, nj, nk;
    bool periodic_i;
    void (*map)(const void *ctx, int i, int j, int k, double x[3]);
    bool (*cell)(const void *ctx, int i, int j, int k);
    const void *ctx;
} fem_grid;

int fem_mesh_alloc(fem_mesh *m, int n_nodes, int n_tets, cm_error *err);
void fem_mesh_free(fem_mesh *m);

/* Builds nodes and tets of a grid (orients every tet positively), then the
 * boundary (fem_mesh_finish). node_ijk is filled. */
int fem_mesh_from_grid(const fem_grid *g, fem_mesh *m, cm_error *err);

/* Checks every tet: a zero (degenerate) volume is refused; a negative one is
 * re-ordered when fix_orientation, refused otherwise. Then extracts the
 * boundary. Errors name the source and the element (1-based in messages
 * when from a file, as the file numbers them: elem_ids may be NULL). */
int fem_mesh_finish(fem_mesh *m, bool fix_orientation, const long *elem_ids, cm_error *err);

/* Index of the boundary face with these three nodes (any order), -1 if none. */
int fem_mesh_find_face(const fem_mesh *m, int a, int b, int c);

/* Closed, oriented 2-manifold check of the boundary: every directed edge
 * (a,b) of a face is matched by exactly one (b,a) of another face. */
int fem_mesh_check_closed(const fem_mesh *m, cm_error *err);

/* Smallest altitude over all elements [m] and the total volume [m^3]. */
void fem_mesh_measure(const fem_mesh *m, double *h_min, double *volume);

/* Built-in meshers. Box [0,Lx]x[0,Ly]x[0,Lz] with n cells per axis:
 * rim = nodes on x = 0, cavity = faces on z = 0, contact = faces on z = Lz. */
int fem_mesh_box(const double size[3], const int cells[3], fem_mesh *m, cm_error *err);

/* Thick tube about the z axis, ri <= r <= ro, 0 <= z <= L (tests: Lame):
 * cavity = inner surface, contact = outer surface, rim = nodes and faces on
 * both end planes. */
int fem_mesh_tube(double ri, double ro, double L, int n_theta, int n_r, int n_z, fem_mesh *m, cm_error *err);

/* The paper's tire (see fem_tire_def in fem.h). */
int fem_mesh_tire(const fem_tire_def *def, fem_mesh *m, cm_error *err);

#endif
