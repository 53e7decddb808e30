/* 3x3 algebra of the shaped grains (private to dem_server/): row-major
 * matrices, body -> world rotations. dem_quat_to_mat is in dem_shape.h. */
#ifndef DEM_SHAPE_ALGEBRA_H
#define DEM_SHAPE_ALGEBRA_H

/* out = R a */
static inline void mat_vec(const double R[9], const double a[3], double out[3])
{
    double x = R[0] * a[0] + R[1] * a[1] + R[2] * a[2];
    double y = R[3] * a[0] + R[4] * a[1] + R[5] * a[2];
    double z = R[6] * a[0] + R[7] * a[1] + R[8] * a[2];
    out[0] = x, out[1] = y, out[2] = z;
}

/* out = R^T a */
static inline void mat_tvec(const double R[9], const double a[3], double out[3])
{
    double x = R[0] * a[0] + R[3] * a[1] + R[6] * a[2];
    double y = R[1] * a[0] + R[4] * a[1] + R[7] * a[2];
    double z = R[2] * a[0] + R[5] * a[1] + R[8] * a[2];
    out[0] = x, out[1] = y, out[2] = z;
}

/* Eigen-decomposition of a symmetric 3x3 matrix A (row-major) by cyclic
 * Jacobi rotations: A = V diag(e) V^T, V's columns the eigenvectors. */
void dem_jacobi3(const double Ain[9], double e[3], double V[9]);
/* Sorts eigenpairs ascending and makes V a proper rotation (det +1). */
void dem_sort_eigen(double e[3], double V[9]);

#endif
