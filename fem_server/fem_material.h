/* Material laws at a point (libCEED's QFunction idea): deformation gradient
 * in, stress out, unaware of elements and meshes; and the linear
 * tetrahedron's internal nodal forces for such a law (total Lagrangian).
 * Internal to fem/.
 *
 * Compressible Neo-Hookean (the first paper's conclusion asks for nonlinear
 * rubber; PHYSICS_NOTES), with the Lame parameters of the small-strain limit:
 *   W = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2,   I1 = tr(F^T F), J = det F
 *   P = dW/dF = mu F + (lambda ln J - mu) F^-T          (first Piola-Kirchhoff)
 *   sigma = P F^T / J = mu/J (b - I) + lambda ln J / J I,   b = F F^T (Cauchy)
 * Zero stress under any rigid rotation; linear elasticity (eq. 29) for small
 * strains. */
#ifndef FEM_MATERIAL_H
#define FEM_MATERIAL_H

/* Strain energy per reference volume [J/m^3]; NAN when det F <= 0. */
double fem_neo_hookean_energy(double F[3][3], double lambda, double mu);

/* First Piola-Kirchhoff stress P [Pa]. Returns J = det F; P is left
 * unchanged when J <= 0 (an inverted point: the caller reports it). */
double fem_neo_hookean_pk1(double F[3][3], double lambda, double mu, double P[3][3]);

/* Cauchy stress in the order of fem_stress_from_strain: (s11, s22, s33,
 * s23, s13, s12). Returns J; sig unchanged when J <= 0. */
double fem_neo_hookean_cauchy(double F[3][3], double lambda, double mu, double sig[6]);

/* Internal forces of a linear tetrahedron under the Neo-Hookean law, total
 * Lagrangian: F = I + sum_a u_a (x) grad0 N_a (constant in the element),
 *   f_a = V0 P grad0 N_a   (the force the element exerts on node a is -f_a),
 * grad0 and V0 the shape-function gradients and volume in the reference
 * configuration (fem_tet_gradients of the undeformed nodes), u the nodal
 * displacements. Returns J (<= 0: the element is inverted, f unchanged). */
double fem_tet_internal_force_nh(double grad0[4][3], double V0, double u[4][3], double lambda, double mu,
                                 double f[4][3]);

#endif
