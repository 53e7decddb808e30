/* Linear tetrahedron: gradients, stiffness (eq. 34), strain, stress (eq. 29). */
#include "fem_element.h"

#include <math.h>

void fem_lame(double E, double nu, double *lambda, double *mu)
{
    *lambda = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
    *mu = E / (2.0 * (1.0 + nu));
}

double fem_tet_volume(const double *x0, const double *x1, const double *x2, const double *x3)
{
    double a[3], b[3], c[3];
    for (int k = 0; k < 3; k++) {
        a[k] = x1[k] - x0[k];
        b[k] = x2[k] - x0[k];
        c[k] = x3[k] - x0[k];
    }
    double det = a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
                 a[2] * (b[0] * c[1] - b[1] * c[0]);
    return det / 6.0;
}

double fem_tet_gradients(const double *x0, const double *x1, const double *x2, const double *x3,
                         double grad[4][3])
{
    /* J has columns (x1-x0, x2-x0, x3-x0); x = x0 + J xi, so the rows of
     * J^-1 are the gradients of N1, N2, N3 and N0 = 1 - N1 - N2 - N3. */
    double J[3][3];
    for (int k = 0; k < 3; k++) {
        J[k][0] = x1[k] - x0[k];
        J[k][1] = x2[k] - x0[k];
        J[k][2] = x3[k] - x0[k];
    }
    double c00 = J[1][1] * J[2][2] - J[1][2] * J[2][1];
    double c01 = J[1][2] * J[2][0] - J[1][0] * J[2][2];
    double c02 = J[1][0] * J[2][1] - J[1][1] * J[2][0];
    double det = J[0][0] * c00 + J[0][1] * c01 + J[0][2] * c02;
    if (det == 0.0)
        return 0.0;
    double id = 1.0 / det;
    /* inverse = adj(J)/det, adj = cofactor matrix transposed */
    double inv[3][3];
    inv[0][0] = c00 * id;
    inv[1][0] = c01 * id;
    inv[2][0] = c02 * id;
    inv[0][1] = (J[0][2] * J[2][1] - J[0][1] * J[2][2]) * id;
    inv[1][1] = (J[0][0] * J[2][2] - J[0][2] * J[2][0]) * id;
    inv[2][1] = (J[0][1] * J[2][0] - J[0][0] * J[2][1]) * id;
    inv[0][2] = (J[0][1] * J[1][2] - J[0][2] * J[1][1]) * id;
    inv[1][2] = (J[0][2] * J[1][0] - J[0][0] * J[1][2]) * id;
    inv[2][2] = (J[0][0] * J[1][1] - J[0][1] * J[1][0]) * id;
    for (int a = 0; a < 3; a++) {
        grad[1][a] = inv[0][a];
        grad[2][a] = inv[1][a];
        grad[3][a] = inv[2][a];
        grad[0][a] = -(inv[0][a] + inv[1][a] + inv[2][a]);
    }
    return det / 6.0;
}

void fem_tet_stiffness(double grad[4][3], double volume, double lambda, double mu, double Ke[12][12])
{
    for (int i = 0; i < 4; i++)
        for (int j = 0; j < 4; j++) {
            double gg = grad[i][0] * grad[j][0] + grad[i][1] * grad[j][1] + grad[i][2] * grad[j][2];
            for (int a = 0; a < 3; a++)
                for (int b = 0; b < 3; b++) {
                    /* eq. 34 */
                    double k = lambda * grad[i][a] * grad[j][b] + mu * grad[i][b] * grad[j][a];
                    if (a == b)
                        k += mu * gg;
                    Ke[3 * i + a][3 * j + b] = volume * k;
                }
        }
}

void fem_tet_strain(double grad[4][3], double u[4][3], double eps[6])
{
    double H[3][3] = {{0}}; /* displacement gradient du_a/dx_b */
    for (int i = 0; i < 4; i++)
        for (int a = 0; a < 3; a++)
            for (int b = 0; b < 3; b++)
                H[a][b] += u[i][a] * grad[i][b];
    eps[0] = H[0][0];
    eps[1] = H[1][1];
    eps[2] = H[2][2];
    eps[3] = 0.5 * (H[1][2] + H[2][1]);
    eps[4] = 0.5 * (H[0][2] + H[2][0]);
    eps[5] = 0.5 * (H[0][1] + H[1][0]);
}

void fem_stress_from_strain(const double eps[6], double lambda, double mu, double sig[6])
{
    double tr = eps[0] + eps[1] + eps[2];
    /* eq. 29: sigma_ab = lambda u_g,g delta_ab + mu (u_a,b + u_b,a) */
    for (int k = 0; k < 3; k++)
        sig[k] = lambda * tr + 2.0 * mu * eps[k];
    for (int k = 3; k < 6; k++)
        sig[k] = 2.0 * mu * eps[k];
}
