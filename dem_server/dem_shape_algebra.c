/* 3x3 algebra of the shaped grains: quaternion -> rotation matrix and the
 * symmetric eigen-decomposition behind the principal axes (dem_shape_algebra.h). */
#include "dem_shape_algebra.h"

#include <math.h>

#include "dem_shape.h"

void dem_quat_to_mat(const double q[4], double R[9])
{
    double w = q[0], x = q[1], y = q[2], z = q[3];
    R[0] = 1 - 2 * (y * y + z * z), R[1] = 2 * (x * y - w * z), R[2] = 2 * (x * z + w * y);
    R[3] = 2 * (x * y + w * z), R[4] = 1 - 2 * (x * x + z * z), R[5] = 2 * (y * z - w * x);
    R[6] = 2 * (x * z - w * y), R[7] = 2 * (y * z + w * x), R[8] = 1 - 2 * (x * x + y * y);
}

/* Eigen-decomposition of a symmetric 3x3 matrix A (row-major) by cyclic
 * Jacobi rotations: A = V diag(e) V^T, V's columns the eigenvectors. */
void dem_jacobi3(const double Ain[9], double e[3], double V[9])
{
    double A[3][3];
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 3; c++) {
            A[r][c] = Ain[3 * r + c];
            V[3 * r + c] = r == c;
        }
    double scale = fabs(A[0][0]) + fabs(A[1][1]) + fabs(A[2][2]);
    for (int sweep = 0; sweep < 50; sweep++) {
        double off = fabs(A[0][1]) + fabs(A[0][2]) + fabs(A[1][2]);
        if (off <= 1e-15 * scale)
            break;
        for (int p = 0; p < 2; p++)
            for (int q = p + 1; q < 3; q++) {
                if (fabs(A[p][q]) <= 1e-18 * scale)
                    continue; /* an exact zero stays zero: a degenerate (cube) tensor keeps its frame */
                double theta = (A[q][q] - A[p][p]) / (2.0 * A[p][q]);
                double t = (theta >= 0 ? 1.0 : -1.0) / (fabs(theta) + sqrt(theta * theta + 1.0));
                double c = 1.0 / sqrt(t * t + 1.0), s = t * c;
                for (int k = 0; k < 3; k++) { /* A <- J^T A J */
                    double akp = A[k][p], akq = A[k][q];
                    A[k][p] = c * akp - s * akq;
                    A[k][q] = s * akp + c * akq;
                }
                for (int k = 0; k < 3; k++) {
                    double apk = A[p][k], aqk = A[q][k];
                    A[p][k] = c * apk - s * aqk;
                    A[q][k] = s * apk + c * aqk;
                }
                for (int k = 0; k < 3; k++) {
                    double vkp = V[3 * k + p], vkq = V[3 * k + q];
                    V[3 * k + p] = c * vkp - s * vkq;
                    V[3 * k + q] = s * vkp + c * vkq;
                }
            }
    }
    for (int k = 0; k < 3; k++)
        e[k] = A[k][k];
}

/* Sorts eigenpairs ascending and makes V a proper rotation (det +1). */
void dem_sort_eigen(double e[3], double V[9])
{
    for (int a = 0; a < 2; a++)
        for (int b = a + 1; b < 3; b++)
            if (e[b] < e[a]) {
                double t = e[a];
                e[a] = e[b], e[b] = t;
                for (int r = 0; r < 3; r++) {
                    t = V[3 * r + a];
                    V[3 * r + a] = V[3 * r + b], V[3 * r + b] = t;
                }
            }
    double det = V[0] * (V[4] * V[8] - V[5] * V[7]) - V[1] * (V[3] * V[8] - V[5] * V[6]) +
                 V[2] * (V[3] * V[7] - V[4] * V[6]);
    if (det < 0)
        for (int r = 0; r < 3; r++)
            V[3 * r + 2] = -V[3 * r + 2];
}
