/* The FE tire's outer surface as seen by the grains: linear triangles over
 * moving nodes, a bounding-volume tree over them (paper sec. 4.2, refitted
 * when the nodes move), sphere–triangle closest points (sec. 4.3) and the
 * barycentric distribution of contact forces to the nodes (eq. 42). */
#ifndef DEM_SURFACE_H
#define DEM_SURFACE_H

#include "dem.h"

typedef struct dem_world dem_world;

/* Tree node; its left child is the next node, `right` the other one (-1 for a
 * leaf, whose triangles are perm[first .. first+count)). Children always have
 * larger indices than their parent, so a reverse sweep refits the tree. */
typedef struct dem_bvh_node {
    double lo[3], hi[3];
    int right, first, count, pad;
} dem_bvh_node;

/* Tangential history per (grain, surface): up to DEM_SURF_SLOTS simultaneous
 * contacts of one grain with the surface (a grain in a tread groove), matched
 * step to step by their normal, so that a spring survives the contact point
 * crossing a triangle edge. */
#define DEM_SURF_SLOTS 4
#define DEM_SURF_SLOT_SIZE 7 /* xi[3], n[3], used: */
enum { DEM_SURF_SLOT_XI = 0, DEM_SURF_SLOT_N = 3, DEM_SURF_SLOT_USED = 6 }; /* offsets in a slot */
/* Candidate triangles per grain: the per-thread buffers start at this size
 * and double (logged) when a grain meets more triangles, e.g. a large grain
 * on a fine FE mesh. */
#define DEM_SURF_CAND_INIT 64
/* Two contacts of a grain with the surface are one when their normals are
 * within 45° (cos > 0.7) and, for spheres, the triangles between them all
 * touch the grain: a dent is one contact, a lug's root two. The same angle
 * matches a contact to its tangential history slot. */
#define DEM_SURF_PATCH_COS 0.7
/* The patch's shallower minima within this fraction of its overlap share
 * its reaction (linearly fading to none): a soft FE surface loaded on one
 * triangle of an even dent otherwise sees the load jump between its facets. */
#define DEM_SURF_SHARE 0.1
/* The tread's compliance counted once (issue 16 item 2): on a surface whose
 * nodes yield (an FE tread), the FE itself deflects under a contact's nodal
 * force by a share s of Hertz's approach, and the contact law carries only
 * the rest. Measured on FE rubber blocks (tests/coupling/block, linear tets,
 * one contact per patch; the FE's deflection under the contact at the force
 * peak against Hertz's approach, nearly whatever the contact law): s = 0.17,
 * 0.33, 0.56 at a/h = 0.15, 0.29, 0.55 (soil grain R 5 mm on the default
 * tread, E 20 MPa) and 0.59, 0.65, 0.71, 0.79 at a/h = 0.69, 1.0, 1.4, 2.0
 * (steel R 10 mm on E 10 MPa), a Hertz's contact radius, h the triangle's
 * size sqrt(2 area); fitted by s = x / (x + DEM_SURF_FE_A0), x = a/h (rms
 * 0.031, worst -0.06 at a/h 0.55): linear in a/h while the load is a point
 * at the mesh's scale (Boussinesq), towards 1 once the mesh resolves the
 * patch. dem_surface.c, surface_contact_stiffening. */
#define DEM_SURF_FE_A0 0.55

struct dem_surf_scratch;

typedef struct dem_surface {
    int n_nodes, n_tris, material;
    double *x, *v;   /* 3 n_nodes */
    double *node_f;  /* 3 n_nodes, forces ON the surface */
    double *inv_mass;/* n_nodes, 1/kg; NULL: the surface is rigid (infinite mass) */
    int *tri;        /* 3 n_tris */
    double *tri_h;   /* n_tris, m: each triangle's size sqrt(2 area) as installed (the FE share's h) */
    int n_bvh;
    dem_bvh_node *bvh;
    int tree_stale;  /* nodes moved since the last refit: every box but the root's is old (dem_surface_moved) */
    int *box_nodes, n_box_nodes; /* the triangles' nodes, each once: the root box from them alone */
    int *perm;
    double *hist;    /* DEM_SURF_SLOTS * DEM_SURF_SLOT_SIZE per grain slot */
    double ref[3], travel[3];
    dem_surface_total tot;
    int n_threads;
    struct dem_surf_scratch *scratch; /* n_threads candidate buffers (dem_surface.c) */
    int cand_cap_logged;      /* largest candidate buffer size already logged */
    /* surface neighbour lists (dem_surface_contacts): valid for the grain
     * list of rebuild lists_rebuild with lists_n grains, surface nodes then
     * at x_lists */
    int lists_valid, lists_n;
    long lists_rebuild;
    double *x_lists;          /* 3 n_nodes */
} dem_surface;

/* Closest point of triangle (a, b, c) to p (Ericson, Real-Time Collision
 * Detection 5.1.5). Fills barycentric weights and the point itself as
 * bary[0] a + bary[1] b + bary[2] c. Returns the region:
 * 0 face, 1 edge ab, 2 edge bc, 3 edge ca, 4 vertex a, 5 vertex b, 6 vertex c. */
int dem_closest_on_triangle(const double p[3], const double a[3], const double b[3], const double c[3],
                            double bary[3], double cp[3]);

int dem_surface_create(int n_nodes, const double *x0, int n_tris, const int *tris, int material, int grain_cap,
                       int n_threads, dem_surface **out, cm_error *err);
void dem_surface_free(dem_surface **s);
void dem_surface_refit(dem_surface *s);
/* The nodes moved: the root box now, the rest of the tree refitted only
 * before the tree is next walked (dem_surface_contacts, when the grains'
 * triangle lists are rebuilt; read from the lists, most passes never walk
 * it). Boxes are minima and maxima, exact in any order: the same tree as a
 * refit at every move. */
void dem_surface_moved(dem_surface *s);
int dem_surface_grow(dem_surface *s, int grain_cap);
/* Grain–triangle contacts at the current positions: forces and torques
 * added to the grains, node forces and totals of the surface refilled. */
int dem_surface_contacts(dem_world *w, cm_error *err);

/* Distributed run (dem_mpi.c): the contacts of this process's last
 * dem_surface_contacts packed as doubles in grain order, each as fs[3],
 * mom[3], along, overlap, energy, n_nodes, then per node its index and
 * force (DEM_SURF_PACK_NODE doubles; integers exactly). packed_size: the
 * doubles dem_surface_pack writes (and returns). */
#define DEM_SURF_PACK_NODE 4
long dem_surface_packed_size(const dem_world *w);
long dem_surface_pack(const dem_world *w, double *buf);
/* The node forces and totals refilled from n doubles of packed contacts
 * (every rank's, in rank order: the same sums, bit for bit, as one process
 * makes of the same contacts). The largest overlap's grain and triangle are
 * not known (-1). Checked as data from another process: CM_ERR_RANGE. */
int dem_surface_sum_packed(dem_world *w, const double *buf, long n, cm_error *err);

#endif
