/* Linear tetrahedron (4 nodes, constant strain): shape-function gradients,
 * element stiffness (eq. 34), strain and stress (eq. 29). Internal to fem/. */
#ifndef FEM_ELEMENT_H
#define FEM_ELEMENT_H

/* Lame parameters from Young's modulus [Pa] and Poisson's ratio. */
void fem_lame(double E, double nu, double *lambda, double *mu);

/* Signed volume [m^3] of the tet (x0,x1,x2,x3), positive when
 * (x1-x0, x2-x0, x3-x0) is right-handed. Each x is 3 doubles. */
double fem_tet_volume(const double *x0, const double *x1, const double *x2, const double *x3);

/* Gradients dN_i/dx_alpha of the four linear shape functions (eq. 31),
 * grad[i][alpha] in 1/m, and the signed volume. Returns the volume; the
 * gradients are undefined when it is 0. */
double fem_tet_gradients(const double *x0, const double *x1, const double *x2, const double *x3,
                         double grad[4][3]);

/* Element stiffness (eq. 34), row/column index 3*i+alpha:
 *   K_{i alpha, j beta} = V [ lambda N_i,alpha N_j,beta + mu N_i,beta N_j,alpha
 *                             + mu delta_{alpha beta} N_i,gamma N_j,gamma ]
 * (the paper prints the indices of the last two terms garbled; this is the
 * form that follows from the strain energy of eq. 29). */
void fem_tet_stiffness(double grad[4][3], double volume, double lambda, double mu, double Ke[12][12]);

/* Constant strain of the element from nodal displacements u[4][3], in Voigt
 * order (e11, e22, e33, 2e23, 2e13, 2e12) -> returned as tensor components
 * eps[6] = (e11, e22, e33, e23, e13, e12) (no factor 2). */
void fem_tet_strain(double grad[4][3], double u[4][3], double eps[6]);

/* Hooke's law (eq. 29): sigma = lambda tr(eps) I + 2 mu eps, same ordering. */
void fem_stress_from_strain(const double eps[6], double lambda, double mu, double sig[6]);

/* ---- 10-node (quadratic) tetrahedron ------------------------------------
 * Nodes: corners 0..3 as the linear tet, then the mid-edge nodes on the
 * edges (0,1), (1,2), (0,2), (0,3), (1,3), (2,3) (the VTK/Abaqus order; Gmsh
 * swaps the last two, fem_gmsh.c maps them). Isoparametric: in barycentric
 * coordinates L, N_i = L_i (2 L_i - 1) at the corners and N_ij = 4 L_i L_j at
 * the mid-edge nodes; the displacement field is complete to second order, so
 * the element bends without shear locking (issue 16 item 1). */
enum { FEM_TET10_NODES = 10, FEM_TET10_DOF = 30, FEM_TET10_GAUSS = 8 };
extern const int fem_tet10_edges[6][2];

/* Gradients dN_a/dx [1/m] of the ten shape functions at barycentric point
 * L (L[0..3], sum 1) of the element with nodes x[10][3]. Returns det J of
 * the map from the unit reference tet (6 x the volume for a straight-sided
 * element); the gradients are undefined when it is <= 0. */
double fem_tet10_gradients(double x[10][3], const double L[4], double grad[10][3]);

/* The quadrature rule on the tet: barycentric points and weights (sum 1/6,
 * the reference volume). 8 points of degree 3 with positive weights: the
 * 4-point rule (degree 2) is exact for straight-sided elements only; on a
 * curved one (the tire's mid-edge nodes lie on its arcs, Gmsh may curve
 * them) det J grad N is cubic, and the patch test needs it integrated
 * exactly; the 5-point degree-3 rule has a negative weight. The rule costs
 * only at assembly: the explicit step multiplies by the assembled K. */
extern const double fem_tet10_gauss_L[FEM_TET10_GAUSS][4];
extern const double fem_tet10_gauss_w[FEM_TET10_GAUSS];

/* Element stiffness K_e (eq. 34 at each quadrature point, weights w det J), row
 * index 3a+alpha, and the element volume (sum w det J). Returns 0, or the
 * 1-based index of the first Gauss point where det J <= 0 (a distorted or
 * inverted element: Ke and volume undefined). */
int fem_tet10_stiffness(double x[10][3], double lambda, double mu, double Ke[30][30], double *volume);

/* Diagonal (lumped) mass by HRZ (Hinton, Rock and Zienkiewicz 1976): the
 * consistent mass's diagonal rho int N_a^2 (corner V/70, mid-edge 8V/105 on a
 * straight-sided element) scaled so that the total is exact: each corner
 * carries 1/36, each mid-edge node 4/27 of the element's mass (ratio 16/3;
 * all positive, unlike the row sums, which give the corners -1/20). */
#define FEM_TET10_MASS_CORNER (1.0 / 36.0)
#define FEM_TET10_MASS_MID (4.0 / 27.0)

/* Small strain (tensor components, order of fem_tet_strain) at a point from
 * the gradients there and the nodal displacements u[10][3]. */
void fem_tet10_strain(double grad[10][3], double u[10][3], double eps[6]);

#endif
