/* Linear tetrahedron: gradients, stiffness (eq. 34), strain, stress (eq. 29). */
#include "fem_element.h"

#include <math.h>
#include <string.h>

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

/* ---- 10-node tetrahedron ------------------------------------------------ */

const int fem_tet10_edges[6][2] = {{0, 1}, {1, 2}, {0, 2}, {0, 3}, {1, 3}, {2, 3}};

/* Stroud's conical product rule, 2 x 2 x 2 points: Gauss-Jacobi in u with
 * weight (1-u)^2, in v with weight (1-v), Gauss-Legendre in w, mapped by
 * L1 = u, L2 = v (1-u), L3 = w (1-u)(1-v). Degree 3, all weights positive. */
const double fem_tet10_gauss_L[FEM_TET10_GAUSS][4] = {
    {0.58474756320489429, 0.12251482265544136, 0.13605497680284606, 0.15668263733681828},
    {0.15668263733681831, 0.12251482265544136, 0.13605497680284606, 0.58474756320489429},
    {0.24571332521171327, 0.12251482265544136, 0.565933165072801, 0.065838687060044393},
    {0.065838687060044365, 0.12251482265544136, 0.565933165072801, 0.2457133252117133},
    {0.3037727648147075, 0.54415184401122529, 0.070679724159396912, 0.081395667014670242},
    {0.081395667014670214, 0.54415184401122529, 0.070679724159396912, 0.30377276481470755},
    {0.12764656212038544, 0.54415184401122529, 0.29399880063162287, 0.0342027932367664},
    {0.034202793236766421, 0.54415184401122529, 0.29399880063162287, 0.12764656212038542}};
const double fem_tet10_gauss_w[FEM_TET10_GAUSS] = {
    0.036979856358852918, 0.036979856358852918, 0.021157006454524053, 0.021157006454524053,
    0.016027040598476615, 0.016027040598476615, 0.0091694299214797395, 0.0091694299214797395};

double fem_tet10_gradients(double x[10][3], const double L[4], double grad[10][3])
{
    /* dN_a/dL_i, then dN/dxi_k = dN/dL_k - dN/dL_0 (xi_k = L_k, k = 1..3) */
    double dL[10][4] = {{0}};
    for (int i = 0; i < 4; i++)
        dL[i][i] = 4.0 * L[i] - 1.0;
    for (int e = 0; e < 6; e++) {
        int i = fem_tet10_edges[e][0], j = fem_tet10_edges[e][1];
        dL[4 + e][i] = 4.0 * L[j];
        dL[4 + e][j] = 4.0 * L[i];
    }
    double dxi[10][3];
    for (int a = 0; a < 10; a++)
        for (int k = 0; k < 3; k++)
            dxi[a][k] = dL[a][k + 1] - dL[a][0];
    double J[3][3] = {{0}}; /* J[alpha][k] = dx_alpha / dxi_k */
    for (int a = 0; a < 10; a++)
        for (int al = 0; al < 3; al++)
            for (int k = 0; k < 3; k++)
                J[al][k] += x[a][al] * dxi[a][k];
    double c00 = J[1][1] * J[2][2] - J[1][2] * J[2][1];
    double c01 = J[1][2] * J[2][0] - J[1][0] * J[2][2];
    double c02 = J[1][0] * J[2][1] - J[1][1] * J[2][0];
    double det = J[0][0] * c00 + J[0][1] * c01 + J[0][2] * c02;
    if (!(det > 0.0))
        return det;
    double id = 1.0 / det, inv[3][3]; /* inv[k][alpha] = dxi_k / dx_alpha */
    inv[0][0] = c00 * id;
    inv[1][0] = c01 * id;
    inv[2][0] = c02 * id;
    inv[0][1] = (J[0][2] * J[2][1] - J[0][1] * J[2][2]) * id;
    inv[1][1] = (J[0][0] * J[2][2] - J[0][2] * J[2][0]) * id;
    inv[2][1] = (J[0][1] * J[2][0] - J[0][0] * J[2][1]) * id;
    inv[0][2] = (J[0][1] * J[1][2] - J[0][2] * J[1][1]) * id;
    inv[1][2] = (J[0][2] * J[1][0] - J[0][0] * J[1][2]) * id;
    inv[2][2] = (J[0][0] * J[1][1] - J[0][1] * J[1][0]) * id;
    for (int a = 0; a < 10; a++)
        for (int al = 0; al < 3; al++)
            grad[a][al] = dxi[a][0] * inv[0][al] + dxi[a][1] * inv[1][al] + dxi[a][2] * inv[2][al];
    return det;
}

int fem_tet10_stiffness(double x[10][3], double lambda, double mu, double Ke[30][30], double *volume)
{
    memset(Ke, 0, 30 * sizeof Ke[0]);
    double vol = 0.0;
    for (int q = 0; q < FEM_TET10_GAUSS; q++) {
        double g[10][3];
        double det = fem_tet10_gradients(x, fem_tet10_gauss_L[q], g);
        if (!(det > 0.0))
            return q + 1;
        double wv = fem_tet10_gauss_w[q] * det;
        vol += wv;
        for (int i = 0; i < 10; i++)
            for (int j = 0; j < 10; j++) {
                double gg = g[i][0] * g[j][0] + g[i][1] * g[j][1] + g[i][2] * g[j][2];
                for (int a = 0; a < 3; a++)
                    for (int b = 0; b < 3; b++) {
                        /* eq. 34 at the Gauss point */
                        double k = lambda * g[i][a] * g[j][b] + mu * g[i][b] * g[j][a];
                        if (a == b)
                            k += mu * gg;
                        Ke[3 * i + a][3 * j + b] += wv * k;
                    }
            }
    }
    *volume = vol;
    return 0;
}

void fem_tet10_strain(double grad[10][3], double u[10][3], double eps[6])
{
    double H[3][3] = {{0}};
    for (int i = 0; i < 10; i++)
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
