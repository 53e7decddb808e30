/* Compressible Neo-Hookean rubber at a point, and the linear tetrahedron's
 * internal forces under it (total Lagrangian): see fem_material.h. */
#include "fem_material.h"

#include <math.h>

static double det3(double A[3][3])
{
    return A[0][0] * (A[1][1] * A[2][2] - A[1][2] * A[2][1]) - A[0][1] * (A[1][0] * A[2][2] - A[1][2] * A[2][0]) +
           A[0][2] * (A[1][0] * A[2][1] - A[1][1] * A[2][0]);
}

/* F^-T = cof(F) / det F, cof the cofactor matrix. */
static void inverse_transpose(double F[3][3], double J, double Fit[3][3])
{
    double id = 1.0 / J;
    Fit[0][0] = (F[1][1] * F[2][2] - F[1][2] * F[2][1]) * id;
    Fit[0][1] = (F[1][2] * F[2][0] - F[1][0] * F[2][2]) * id;
    Fit[0][2] = (F[1][0] * F[2][1] - F[1][1] * F[2][0]) * id;
    Fit[1][0] = (F[0][2] * F[2][1] - F[0][1] * F[2][2]) * id;
    Fit[1][1] = (F[0][0] * F[2][2] - F[0][2] * F[2][0]) * id;
    Fit[1][2] = (F[0][1] * F[2][0] - F[0][0] * F[2][1]) * id;
    Fit[2][0] = (F[0][1] * F[1][2] - F[0][2] * F[1][1]) * id;
    Fit[2][1] = (F[0][2] * F[1][0] - F[0][0] * F[1][2]) * id;
    Fit[2][2] = (F[0][0] * F[1][1] - F[0][1] * F[1][0]) * id;
}

double fem_neo_hookean_energy(double F[3][3], double lambda, double mu)
{
    double J = det3(F);
    if (!(J > 0))
        return NAN;
    double I1 = 0;
    for (int i = 0; i < 3; i++)
        for (int k = 0; k < 3; k++)
            I1 += F[i][k] * F[i][k];
    double lnJ = log(J);
    return 0.5 * mu * (I1 - 3.0) - mu * lnJ + 0.5 * lambda * lnJ * lnJ;
}

double fem_neo_hookean_pk1(double F[3][3], double lambda, double mu, double P[3][3])
{
    double J = det3(F);
    if (!(J > 0))
        return J;
    double Fit[3][3];
    inverse_transpose(F, J, Fit);
    double c = lambda * log(J) - mu;
    for (int i = 0; i < 3; i++)
        for (int k = 0; k < 3; k++)
            P[i][k] = mu * F[i][k] + c * Fit[i][k];
    return J;
}

double fem_neo_hookean_cauchy(double F[3][3], double lambda, double mu, double sig[6])
{
    double J = det3(F);
    if (!(J > 0))
        return J;
    double b[3][3];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            b[i][j] = F[i][0] * F[j][0] + F[i][1] * F[j][1] + F[i][2] * F[j][2];
    double p = lambda * log(J) / J, m = mu / J;
    sig[0] = m * (b[0][0] - 1.0) + p;
    sig[1] = m * (b[1][1] - 1.0) + p;
    sig[2] = m * (b[2][2] - 1.0) + p;
    sig[3] = m * b[1][2];
    sig[4] = m * b[0][2];
    sig[5] = m * b[0][1];
    return J;
}

double fem_tet_internal_force_nh(double grad0[4][3], double V0, double u[4][3], double lambda, double mu,
                                 double f[4][3])
{
    double F[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    for (int a = 0; a < 4; a++)
        for (int i = 0; i < 3; i++)
            for (int k = 0; k < 3; k++)
                F[i][k] += u[a][i] * grad0[a][k];
    double P[3][3];
    double J = fem_neo_hookean_pk1(F, lambda, mu, P);
    if (!(J > 0))
        return J;
    for (int a = 0; a < 4; a++)
        for (int i = 0; i < 3; i++)
            f[a][i] = V0 * (P[i][0] * grad0[a][0] + P[i][1] * grad0[a][1] + P[i][2] * grad0[a][2]);
    return J;
}
