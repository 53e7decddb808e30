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

#endif
