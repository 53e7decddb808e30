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
    int32_t *node_ijk;  /* structured meshes: 3 grid indices per node (-1 on mid-edge nodes), else NULL */
    /* Quadratic (10-node) elements, fem.element = "tet10": tets and faces
     * keep their corner nodes above; the mid-edge nodes (numbered after the
     * n_corner corner nodes) are listed here. NULL for linear elements. */
    int n_corner;       /* corner nodes (= n_nodes for linear elements) */
    int32_t *tet_mid;   /* 6 per tet, on its edges (0,1),(1,2),(0,2),(0,3),(1,3),(2,3) */
    int32_t *face_mid;  /* 3 per boundary face, on its edges (f0,f1),(f1,f2),(f2,f0) */
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
    /* i, j, k are whole at the grid points; mid-edge nodes of quadratic
     * meshes are placed at the map of the mean of their ends' indices (on
     * the curved geometry, not on the chord). */
    void (*map)(const void *ctx, double i, double j, double k, double x[3]);
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

/* The same meshes with `order` 1 (4-node tets, as above) or 2 (10-node tets:
 * one node on each edge, shared by the elements around it). The named sets
 * include the mid-edge nodes lying on them: a face set's faces carry their
 * mid-edge nodes; a mid-edge node is a rim node when both ends are and the
 * edge lies on a boundary face whose corners are all rim nodes. */
int fem_mesh_box_order(const double size[3], const int cells[3], int order, fem_mesh *m, cm_error *err);
int fem_mesh_tube_order(double ri, double ro, double L, int n_theta, int n_r, int n_z, int order, fem_mesh *m,
                        cm_error *err);
int fem_mesh_tire_order(const fem_tire_def *def, int order, fem_mesh *m, cm_error *err);

/* Makes a linear mesh quadratic: an edge table built once (sorted corner
 * pairs), one new node per edge, at the map of the mean grid index when g is
 * given and the mesh has node_ijk, else at the chord's midpoint. Fills
 * tet_mid, face_mid and the mid-edge nodes' tags (rule above). */
int fem_mesh_make_quadratic(fem_mesh *m, const fem_grid *g, cm_error *err);

/* face_mid from tet_mid (the face's owning tet): after fem_mesh_finish on a
 * mesh read with its mid-edge nodes (Gmsh second-order tets). */
int fem_mesh_faces_quadratic(fem_mesh *m, cm_error *err);

/* Nodes of element e: 4 corners, then the 6 mid-edge nodes when quadratic.
 * Returns 4 or 10. */
int fem_mesh_tet_nodes(const fem_mesh *m, int e, int32_t nodes[10]);

/* Nodes of boundary face f: 3 corners, then the 3 mid-edge nodes when
 * quadratic. Returns 3 or 6. */
int fem_mesh_face_nodes(const fem_mesh *m, int f, int32_t nodes[6]);

/* The load of a uniform traction on face f per node of the face (order of
 * fem_mesh_face_nodes): an[k] = int N_k n dA (m^2, n outward: a pressure p
 * gives -p an[k]) and a[k] = int N_k dA (m^2: a traction t gives t a[k]).
 * Linear faces: A n / 3 and A / 3; quadratic faces by a 6-point rule of
 * degree 4 (exact for straight sides: 0 at the corners, A/3 mid-edge).
 * Returns the node count (3 or 6). */
int fem_mesh_face_load(const fem_mesh *m, int f, double an[6][3], double a[6]);

#endif
