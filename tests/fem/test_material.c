/* The Neo-Hookean law at a point and in the linear tetrahedron
 * (fem_server/fem_material.c) against closed forms: no stress under a rigid
 * rotation, simple shear (sigma_12 = mu gamma, sigma_11 - sigma_22 =
 * mu gamma^2 for any gamma), the stress as the gradient of the energy, the
 * small-strain limit (Hooke, eq. 29), objectivity, uniaxial tension with
 * free sides, and the element's forces: zero under a large rotation (where
 * the linear element's are not) and the consistent gradient of its energy. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include <stdlib.h>

#include "fem_element.h"
#include "fem_material.h"
#include "fem_mesh.h"
#include "fem_solver.h"
#include "test.h"

static const double LAMBDA = 2.0e8, MU = 6.9e6; /* Pa: E 20 MPa, nu 0.45 (the tread) */

static void rotation(double ax, double ay, double az, double R[3][3])
{
    /* R = Rz(az) Ry(ay) Rx(ax) */
    double cx = cos(ax), sx = sin(ax), cy = cos(ay), sy = sin(ay), cz = cos(az), sz = sin(az);
    double Rx[3][3] = {{1, 0, 0}, {0, cx, -sx}, {0, sx, cx}}, Ry[3][3] = {{cy, 0, sy}, {0, 1, 0}, {-sy, 0, cy}},
           Rz[3][3] = {{cz, -sz, 0}, {sz, cz, 0}, {0, 0, 1}}, T[3][3];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            T[i][j] = 0;
            for (int k = 0; k < 3; k++)
                T[i][j] += Ry[i][k] * Rx[k][j];
        }
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            R[i][j] = 0;
            for (int k = 0; k < 3; k++)
                R[i][j] += Rz[i][k] * T[k][j];
        }
}

static void matmul(double A[3][3], double B[3][3], double C[3][3])
{
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            C[i][j] = 0;
            for (int k = 0; k < 3; k++)
                C[i][j] += A[i][k] * B[k][j];
        }
}

static int rigid_rotation_stress_free(void)
{
    double worst = 0;
    for (int k = 0; k < 20; k++) {
        double R[3][3], P[3][3], s[6];
        rotation(0.3 * k, 1.1 - 0.17 * k, 0.5 + 0.29 * k, R);
        ENSURE(fem_neo_hookean_pk1(R, LAMBDA, MU, P) > 0);
        ENSURE(fem_neo_hookean_cauchy(R, LAMBDA, MU, s) > 0);
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                worst = fmax(worst, fabs(P[i][j]));
        for (int i = 0; i < 6; i++)
            worst = fmax(worst, fabs(s[i]));
        ENSURE(fabs(fem_neo_hookean_energy(R, LAMBDA, MU)) < 1e-9 * MU);
    }
    printf("  20 rotations up to 5.5 rad: largest stress %.2e Pa (mu %.2e Pa)\n", worst, MU);
    ENSURE(worst < 1e-8 * MU);
    return 0;
}

static int simple_shear(void)
{
    const double gammas[] = {0.01, 0.3, 1.0, 2.5};
    for (int k = 0; k < 4; k++) {
        double g = gammas[k], F[3][3] = {{1, g, 0}, {0, 1, 0}, {0, 0, 1}}, s[6];
        ENSURE_NEAR(fem_neo_hookean_cauchy(F, LAMBDA, MU, s), 1.0, 1e-15);
        ENSURE_REL(s[5], MU * g, 1e-12);           /* sigma_12 = mu gamma, exactly linear */
        ENSURE_REL(s[0] - s[1], MU * g * g, 1e-9); /* the normal stress difference (cancellation at small gamma) */
        ENSURE_NEAR(s[1], 0.0, 1e-9 * MU);
        ENSURE_NEAR(s[2], 0.0, 1e-9 * MU);
        ENSURE_NEAR(s[3], 0.0, 1e-9 * MU);
        ENSURE_NEAR(s[4], 0.0, 1e-9 * MU);
    }
    return 0;
}

/* P = dW/dF by central differences, for a few general deformations. */
static int stress_is_energy_gradient(void)
{
    const double Fs[3][3][3] = {{{1.2, 0.1, -0.05}, {0.02, 0.9, 0.3}, {-0.1, 0.05, 1.1}},
                                {{0.7, -0.4, 0.1}, {0.5, 1.3, 0.0}, {0.2, 0.1, 0.8}},
                                {{1.0, 2.0, 0.0}, {0.0, 1.0, 0.5}, {0.1, 0.0, 0.6}}};
    double worst = 0;
    for (int c = 0; c < 3; c++) {
        double P[3][3], F[3][3];
        memcpy(F, Fs[c], sizeof F);
        ENSURE(fem_neo_hookean_pk1(F, LAMBDA, MU, P) > 0);
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++) {
                const double h = 1e-6;
                double Fp[3][3], Fm[3][3];
                memcpy(Fp, F, sizeof F);
                memcpy(Fm, F, sizeof F);
                Fp[i][j] += h;
                Fm[i][j] -= h;
                double d = (fem_neo_hookean_energy(Fp, LAMBDA, MU) - fem_neo_hookean_energy(Fm, LAMBDA, MU)) / (2 * h);
                worst = fmax(worst, fabs(d - P[i][j]) / (fabs(P[i][j]) + MU));
            }
    }
    printf("  P against central differences of W: worst %.2e of (|P| + mu)\n", worst);
    ENSURE(worst < 1e-6);
    return 0;
}

/* F = I + e H: the Cauchy stress tends to Hooke's (eq. 29) with an error
 * O(e^2); the linear element's stress for the same displacement gradient. */
static int small_strain_limit(void)
{
    const double H[3][3] = {{0.3, -0.7, 0.2}, {0.1, -0.4, 0.9}, {0.5, 0.2, 0.6}};
    double err_prev = 0;
    for (int k = 0; k < 3; k++) {
        double e = 1e-3 / pow(10.0, k), F[3][3], s[6], eps[6], h[6];
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                F[i][j] = (i == j) + e * H[i][j];
        fem_neo_hookean_cauchy(F, LAMBDA, MU, s);
        eps[0] = e * H[0][0], eps[1] = e * H[1][1], eps[2] = e * H[2][2];
        eps[3] = 0.5 * e * (H[1][2] + H[2][1]), eps[4] = 0.5 * e * (H[0][2] + H[2][0]),
        eps[5] = 0.5 * e * (H[0][1] + H[1][0]);
        fem_stress_from_strain(eps, LAMBDA, MU, h);
        double err = 0, scale = 0;
        for (int i = 0; i < 6; i++)
            err = fmax(err, fabs(s[i] - h[i])), scale = fmax(scale, fabs(h[i]));
        printf("  e = %.0e: |sigma_NH - sigma_Hooke| / |sigma| = %.3e\n", e, err / scale);
        ENSURE(err / scale < 5 * e);
        if (k > 0)
            ENSURE(err < 0.02 * err_prev); /* O(e^2): 100x smaller per decade, 2 % slack */
        err_prev = err;
    }
    return 0;
}

/* sigma(Q F) = Q sigma(F) Q^T. */
static int objectivity(void)
{
    double F[3][3] = {{1.3, 0.2, 0.0}, {-0.1, 0.8, 0.4}, {0.05, 0.0, 1.1}};
    double Q[3][3], QF[3][3], s[6], sq[6];
    rotation(0.7, -1.2, 2.1, Q);
    matmul(Q, F, QF);
    fem_neo_hookean_cauchy(F, LAMBDA, MU, s);
    fem_neo_hookean_cauchy(QF, LAMBDA, MU, sq);
    double S[3][3] = {{s[0], s[5], s[4]}, {s[5], s[1], s[3]}, {s[4], s[3], s[2]}}, T[3][3], R[3][3], Qt[3][3];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            Qt[i][j] = Q[j][i];
    matmul(Q, S, T);
    matmul(T, Qt, R);
    const double got[6] = {R[0][0], R[1][1], R[2][2], R[1][2], R[0][2], R[0][1]};
    for (int i = 0; i < 6; i++)
        ENSURE_NEAR(sq[i], got[i], 1e-9 * MU);
    return 0;
}

/* Uniaxial tension with free sides: F = diag(a, c, c) with sigma_22 = 0
 * (c by bisection). Then the nominal stress P_11 is dW/da along that path
 * (the sides are free: dW/dc = 0), checked by differences, and the axial
 * force grows with a more slowly than linearly (Neo-Hookean softening in
 * tension) while staying above the small-strain slope E at a -> 1. */
static double lateral(double a)
{
    double lo = 0.2, hi = 1.5;
    for (int k = 0; k < 200; k++) {
        double c = 0.5 * (lo + hi), F[3][3] = {{a, 0, 0}, {0, c, 0}, {0, 0, c}}, s[6];
        fem_neo_hookean_cauchy(F, LAMBDA, MU, s);
        if (s[1] > 0)
            hi = c;
        else
            lo = c;
    }
    return 0.5 * (lo + hi);
}

static double path_energy(double a)
{
    double c = lateral(a), F[3][3] = {{a, 0, 0}, {0, c, 0}, {0, 0, c}};
    return fem_neo_hookean_energy(F, LAMBDA, MU);
}

static int uniaxial_tension(void)
{
    const double E = MU * (3 * LAMBDA + 2 * MU) / (LAMBDA + MU), nu = LAMBDA / (2 * (LAMBDA + MU));
    for (int k = 0; k < 3; k++) {
        double a = 1.0 + 0.25 * (k + 1), c = lateral(a), F[3][3] = {{a, 0, 0}, {0, c, 0}, {0, 0, c}}, P[3][3];
        fem_neo_hookean_pk1(F, LAMBDA, MU, P);
        double h = 1e-5, dW = (path_energy(a + h) - path_energy(a - h)) / (2 * h);
        printf("  stretch %.2f: lateral %.5f, P11 %.6g Pa, dW/da %.6g Pa, E (a - 1) %.6g Pa\n", a, c, P[0][0], dW,
               E * (a - 1));
        ENSURE_REL(dW, P[0][0], 1e-5);
        ENSURE(fabs(P[1][1]) < 1e-6 * MU);
        ENSURE(P[0][0] < E * (a - 1)); /* softer than linear in tension */
    }
    /* small stretch: Poisson's ratio and Young's modulus of the linear limit */
    double a = 1.0 + 1e-6, c = lateral(a), F[3][3] = {{a, 0, 0}, {0, c, 0}, {0, 0, c}}, P[3][3];
    fem_neo_hookean_pk1(F, LAMBDA, MU, P);
    ENSURE_REL((1 - c) / (a - 1), nu, 1e-4);
    ENSURE_REL(P[0][0] / (a - 1), E, 1e-4);
    return 0;
}

/* The element: forces zero under a rigid rotation of 90 degrees (the linear
 * element's are of the order of E times the rotation); the forces are the
 * gradient of the element energy V0 W(F) (central differences); they sum
 * to zero (no net force). */
static int tet_element(void)
{
    double X[4][3] = {{0, 0, 0}, {0.01, 0, 0}, {0.002, 0.012, 0}, {0.003, 0.002, 0.009}}, g[4][3];
    double V0 = fem_tet_gradients(X[0], X[1], X[2], X[3], g);
    ENSURE(V0 > 0);
    double R[3][3], u[4][3], f[4][3];
    rotation(0.0, 0.0, M_PI / 2, R);
    for (int a = 0; a < 4; a++)
        for (int i = 0; i < 3; i++)
            u[a][i] = R[i][0] * X[a][0] + R[i][1] * X[a][1] + R[i][2] * X[a][2] - X[a][i];
    ENSURE(fem_tet_internal_force_nh(g, V0, u, LAMBDA, MU, f) > 0);
    double fmax_nh = 0, fmax_lin = 0, Ke[12][12];
    fem_tet_stiffness(g, V0, LAMBDA, MU, Ke);
    for (int r = 0; r < 12; r++) {
        double fl = 0;
        for (int c = 0; c < 12; c++)
            fl += Ke[r][c] * u[c / 3][c % 3];
        fmax_lin = fmax(fmax_lin, fabs(fl));
        fmax_nh = fmax(fmax_nh, fabs(f[r / 3][r % 3]));
    }
    printf("  rotated 90 degrees: largest nodal force %.2e N (Neo-Hookean), %.2e N (linear element)\n", fmax_nh,
           fmax_lin);
    ENSURE(fmax_nh < 1e-9 * fmax_lin);
    ENSURE(fmax_lin > 1e3);

    /* a general deformation: f = d(V0 W)/du, and sum_a f_a = 0 */
    const double d[4][3] = {{0.0, 0.0, 0.0}, {0.002, -0.001, 0.0005}, {-0.0015, 0.003, 0.001}, {0.001, 0.0, -0.002}};
    memcpy(u, d, sizeof u);
    fem_tet_internal_force_nh(g, V0, u, LAMBDA, MU, f);
    double worst = 0, fs[3] = {0, 0, 0}, scale = 0;
    for (int a = 0; a < 4; a++)
        for (int i = 0; i < 3; i++) {
            double up[4][3], um[4][3], F[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}, G[3][3] = {{1, 0, 0}, {0, 1, 0},
                                                                                               {0, 0, 1}};
            const double h = 1e-9;
            memcpy(up, u, sizeof u);
            memcpy(um, u, sizeof u);
            up[a][i] += h;
            um[a][i] -= h;
            for (int b = 0; b < 4; b++)
                for (int p = 0; p < 3; p++)
                    for (int q = 0; q < 3; q++) {
                        F[p][q] += up[b][p] * g[b][q];
                        G[p][q] += um[b][p] * g[b][q];
                    }
            double dE = V0 * (fem_neo_hookean_energy(F, LAMBDA, MU) - fem_neo_hookean_energy(G, LAMBDA, MU)) / (2 * h);
            worst = fmax(worst, fabs(dE - f[a][i]));
            scale = fmax(scale, fabs(f[a][i]));
            fs[i] += f[a][i];
        }
    printf("  general deformation: forces vs energy differences %.2e of %.2e N; net force %.1e N\n", worst, scale,
           fmax(fabs(fs[0]), fmax(fabs(fs[1]), fabs(fs[2]))));
    ENSURE(worst < 1e-5 * scale);
    ENSURE(fabs(fs[0]) + fabs(fs[1]) + fabs(fs[2]) < 1e-9 * scale);
    /* an inverted element is reported, not computed */
    u[3][2] = -0.02;
    ENSURE(fem_tet_internal_force_nh(g, V0, u, LAMBDA, MU, f) <= 0);
    return 0;
}

/* The explicit solver with the Neo-Hookean law on a cantilever (0.6 x 0.1 x
 * 0.1 m, E 20 MPa, nu 0.45, clamped at x = 0), released from a static
 * deflection: (a) small (tip 0.6 mm): the motion is the linear one to
 * O(strain); (b) large (tip 57 mm): the energy 1/2 v'Mv + sum V0 W(F) is
 * kept to second order in the step (below 1 % at 0.1 of the limit), and
 * the motion differs from the linear model's. */
static int run_beam(double tip_load, int neo_hookean, double h_frac, int steps, double *tip_z, double *energy_dev)
{
    fem_mesh m;
    fem_solver *s;
    cm_error err = {0};
    double size[3] = {0.6, 0.1, 0.1};
    int cells[3] = {6, 1, 1};
    ENSURE(fem_mesh_box(size, cells, &m, &err) == CM_OK);
    ENSURE(fem_solver_create(&m, 2e7, 0.45, 1100.0, 0.0, 0.0, &s, &err) == CM_OK);
    ENSURE(fem_solver_constrain_rim(s, &m, &err) == CM_OK);
    double *b = calloc((size_t)s->n_dof, sizeof *b), *u0 = calloc((size_t)s->n_dof, sizeof *u0);
    ENSURE(b && u0);
    int tip = -1;
    for (int n = 0; n < m.n_nodes; n++)
        if (m.node_ijk[3 * n] == 6) {
            b[3 * n + 2] = tip_load;
            tip = n;
        }
    ENSURE(fem_solver_static(s, b, FEM_LINEAR_CHOLMOD, 0, 0, u0, NULL, &err) == CM_OK);
    fem_stability st;
    ENSURE(fem_solver_stability(s, &m, 5000, &st, &err) == CM_OK);
    if (neo_hookean)
        ENSURE_MSG(fem_solver_use_neo_hookean(s, &m, &err) == CM_OK, "%s", err.msg);
    double h = h_frac * st.dt_power;
    fem_solver_set_state(s, u0, NULL);
    ENSURE(fem_solver_prepare(s, FEM_INTEGRATOR_EXPLICIT, h, &err) == CM_OK);
    double E0 = fem_solver_elastic_energy(s), dev = 0;
    for (int k = 1; k <= steps; k++) {
        ENSURE(fem_solver_step(s, h, &err) == CM_OK);
        if (k % 100 == 0)
            dev = fmax(dev, fabs(fem_solver_elastic_energy(s) + fem_solver_kinetic_energy(s) - E0) / E0);
    }
    *tip_z = s->u[3 * tip + 2];
    *energy_dev = dev;
    ENSURE(s->nh_inverted == 0);
    free(b);
    free(u0);
    fem_solver_destroy(&s);
    fem_mesh_free(&m);
    return 0;
}

static int explicit_beam(void)
{
    double zl, zn, dl, dn;
    if (run_beam(-10.0, 0, 0.5, 3000, &zl, &dl) || run_beam(-10.0, 1, 0.5, 3000, &zn, &dn))
        return 1;
    printf("  small: tip after 3000 steps %.6e m (linear) %.6e m (Neo-Hookean); energy error %.1e / %.1e\n", zl, zn,
           dl, dn);
    ENSURE(fabs(zn - zl) < 0.01 * 5e-4); /* O(strain ~1e-3) of the amplitude */
    /* large: released from the linear deflection under 1000 N (tip 57 mm),
     * which is not a Neo-Hookean equilibrium: the stiff volumetric modes
     * (nu 0.45) ring, and velocity Verlet's energy error on them is O(h^2),
     * oscillating, not a drift: 6.25x smaller from 0.25 to 0.1 of the limit */
    double zL, zN, dL, d25, d10;
    if (run_beam(-1000.0, 0, 0.1, 20000, &zL, &dL) || run_beam(-1000.0, 1, 0.25, 8000, &zN, &d25) ||
        run_beam(-1000.0, 1, 0.1, 20000, &zN, &d10))
        return 1;
    printf("  large: tip after 20000 steps %.5f m (linear) %.5f m (Neo-Hookean); energy error %.2e (linear), "
           "%.2e / %.2e (Neo-Hookean at 0.25 / 0.1 of the limit)\n", zL, zN, dL, d25, d10);
    ENSURE(d10 < 0.01);
    ENSURE(d25 > 4.0 * d10); /* second order */
    ENSURE(fabs(zN - zL) > 1e-3); /* at 10 % of the length the two laws part */
    return 0;
}

static const test_case tests[] = {
    {"explicit_beam", explicit_beam},
    {"rigid_rotation_stress_free", rigid_rotation_stress_free},
    {"simple_shear", simple_shear},
    {"stress_is_energy_gradient", stress_is_energy_gradient},
    {"small_strain_limit", small_strain_limit},
    {"objectivity", objectivity},
    {"uniaxial_tension", uniaxial_tension},
    {"tet_element", tet_element},
};

int main(int argc, char **argv) { return test_main(argc, argv, tests, TEST_COUNT(tests)); }
