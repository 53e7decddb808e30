/* FEM verification: element and assembly (patch test), convergence
 * (cantilever vs beam theory), Lame's thick cylinder, P-wave speed, energy
 * behaviour of both integrators, the explicit stability limit, CHOLMOD vs
 * CG, the Gmsh reader, the tire mesher, loads, the interface and the wheel
 * frame. Tolerances are stated with each check; measured values are printed. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <hdf5.h>

#include "fem.h"
#include "fem_element.h"
#include "fem_mesh.h"
#include "fem_model.h"
#include "fem_solver.h"
#include "log.h"
#include "test.h"

static uint32_t g_seed = 2024u;
static double rnd(void) /* uniform in [-0.5, 0.5) */
{
    g_seed = g_seed * 1664525u + 1013904223u;
    return (double)(g_seed >> 8) / 16777216.0 - 0.5;
}

static double norm(const double *x, int n)
{
    double a = 0.0;
    for (int i = 0; i < n; i++)
        a += x[i] * x[i];
    return sqrt(a);
}

/* ---- Patch test --------------------------------------------------------- */

/* A linear displacement u = A x + c prescribed on the boundary of a mesh
 * with distorted interior nodes must be reproduced inside to round-off, and
 * every element must carry the constant strain sym(A). */
static int patch_test(void)
{
    fem_mesh m;
    cm_error err = {0};
    int cells[3] = {3, 3, 3};
    double size[3] = {1.0, 1.2, 0.9};
    ENSURE(fem_mesh_box(size, cells, &m, &err) == CM_OK);
    uint8_t *onb = calloc((size_t)m.n_nodes, 1);
    for (int f = 0; f < m.n_faces; f++)
        for (int q = 0; q < 3; q++)
            onb[m.faces[3 * f + q]] = 1;
    for (int n = 0; n < m.n_nodes; n++)
        if (!onb[n])
            for (int a = 0; a < 3; a++)
                m.x[3 * n + a] += 0.08 * rnd(); /* cells are 0.3..0.4 m */
    for (int e = 0; e < m.n_tets; e++) {
        const int32_t *t = &m.tets[4 * e];
        ENSURE(fem_tet_volume(&m.x[3 * t[0]], &m.x[3 * t[1]], &m.x[3 * t[2]], &m.x[3 * t[3]]) > 0.0);
    }
    fem_solver *s;
    ENSURE(fem_solver_create(&m, 1e7, 0.3, 1000.0, 0.0, 0.0, &s, &err) == CM_OK);
    const double A[3][3] = {{1e-3, 2e-4, -3e-4}, {-5e-4, 7e-4, 1e-4}, {3e-4, 0.0, -2e-3}}, c[3] = {1e-3, -2e-3, 5e-4};
    int nd = s->n_dof;
    uint8_t *fixed = calloc((size_t)nd, 1);
    double *val = calloc((size_t)nd, sizeof *val), *exact = calloc((size_t)nd, sizeof *exact),
           *b = calloc((size_t)nd, sizeof *b), *u = calloc((size_t)nd, sizeof *u);
    for (int n = 0; n < m.n_nodes; n++)
        for (int a = 0; a < 3; a++) {
            exact[3 * n + a] = c[a] + A[a][0] * m.x[3 * n] + A[a][1] * m.x[3 * n + 1] + A[a][2] * m.x[3 * n + 2];
            fixed[3 * n + a] = onb[n];
            val[3 * n + a] = exact[3 * n + a];
        }
    ENSURE(fem_solver_constrain(s, fixed, val, &err) == CM_OK);
    double worst = 0.0, worst_cg = 0.0;
    ENSURE(fem_solver_static(s, b, FEM_LINEAR_CHOLMOD, 0, 0, u, NULL, &err) == CM_OK);
    for (int d = 0; d < nd; d++)
        worst = fmax(worst, fabs(u[d] - exact[d]));
    ENSURE(fem_solver_static(s, b, FEM_LINEAR_CG, 1e-14, 0, u, NULL, &err) == CM_OK);
    for (int d = 0; d < nd; d++)
        worst_cg = fmax(worst_cg, fabs(u[d] - exact[d]));
    ENSURE(fem_solver_static(s, b, FEM_LINEAR_CHOLMOD, 0, 0, u, NULL, &err) == CM_OK);
    double eps_err = 0.0;
    for (int e = 0; e < m.n_tets; e++) {
        const int32_t *t = &m.tets[4 * e];
        double g[4][3], ue[4][3], eps[6];
        fem_tet_gradients(&m.x[3 * t[0]], &m.x[3 * t[1]], &m.x[3 * t[2]], &m.x[3 * t[3]], g);
        for (int i = 0; i < 4; i++)
            for (int a = 0; a < 3; a++)
                ue[i][a] = u[3 * t[i] + a];
        fem_tet_strain(g, ue, eps);
        double ref[6] = {A[0][0], A[1][1], A[2][2], 0.5 * (A[1][2] + A[2][1]), 0.5 * (A[0][2] + A[2][0]),
                         0.5 * (A[0][1] + A[1][0])};
        for (int k = 0; k < 6; k++)
            eps_err = fmax(eps_err, fabs(eps[k] - ref[k]));
    }
    printf("  patch: max |u - u_exact| = %.2e m (CHOLMOD), %.2e m (CG); max strain error %.2e (|u| ~ 2e-3)\n",
           worst, worst_cg, eps_err);
    ENSURE(worst < 1e-14);
    ENSURE(worst_cg < 1e-12);
    ENSURE(eps_err < 1e-13);
    fem_solver_destroy(&s);
    fem_mesh_free(&m);
    free(onb);
    free(fixed);
    free(val);
    free(exact);
    free(b);
    free(u);
    return 0;
}

/* ---- Cantilever --------------------------------------------------------- */

/* Tip deflection of a clamped beam (L = 1 m, 0.1 x 0.1 m) under an end
 * shear P, as uniform traction on the end face. Reference: Timoshenko
 * beam, d = P L^3 / (3 E I) + P L / (k G A), k = 5/6. */
static int cantilever_deflection(int nx, int nyz, double *tip)
{
    const double L = 1.0, h = 0.1, E = 1e7, nu = 0.3, P = 100.0;
    fem_mesh m;
    cm_error err = {0};
    double size[3] = {L, h, h};
    int cells[3] = {nx, nyz, nyz};
    ENSURE(fem_mesh_box(size, cells, &m, &err) == CM_OK);
    fem_solver *s;
    ENSURE(fem_solver_create(&m, E, nu, 1000.0, 0.0, 0.0, &s, &err) == CM_OK);
    ENSURE(fem_solver_constrain_rim(s, &m, &err) == CM_OK); /* x = 0 clamped */
    double *b = calloc((size_t)s->n_dof, sizeof *b), *u = calloc((size_t)s->n_dof, sizeof *u);
    for (int f = 0; f < m.n_faces; f++) {
        int on = 1;
        for (int q = 0; q < 3; q++)
            on &= m.node_ijk[3 * m.faces[3 * f + q]] == nx;
        if (!on)
            continue;
        const int32_t *t = &m.faces[3 * f];
        double e1[3], e2[3];
        for (int a = 0; a < 3; a++) {
            e1[a] = m.x[3 * t[1] + a] - m.x[3 * t[0] + a];
            e2[a] = m.x[3 * t[2] + a] - m.x[3 * t[0] + a];
        }
        double area = 0.5 * fabs(e1[1] * e2[2] - e1[2] * e2[1]);
        for (int q = 0; q < 3; q++)
            b[3 * t[q] + 2] -= P / (h * h) * area / 3.0; /* consistent: traction A / 3 */
    }
    ENSURE(fem_solver_static(s, b, FEM_LINEAR_CHOLMOD, 0, 0, u, NULL, &err) == CM_OK);
    /* mean vertical deflection of the end face nodes */
    double acc = 0.0;
    int cnt = 0;
    for (int n = 0; n < m.n_nodes; n++)
        if (m.node_ijk[3 * n] == nx) {
            acc += -u[3 * n + 2];
            cnt++;
        }
    *tip = acc / cnt;
    free(b);
    free(u);
    fem_solver_destroy(&s);
    fem_mesh_free(&m);
    return 0;
}

static int cantilever(void)
{
    const double L = 1.0, h = 0.1, E = 1e7, nu = 0.3, P = 100.0, I = h * h * h * h / 12.0, G = E / (2 * (1 + nu));
    double ref = P * L * L * L / (3 * E * I) + P * L / (5.0 / 6.0 * G * h * h);
    double d[4];
    const int nx[4] = {10, 20, 40, 80}, ny[4] = {1, 2, 4, 8};
    for (int k = 0; k < 4; k++) {
        if (cantilever_deflection(nx[k], ny[k], &d[k]))
            return 1;
        printf("  cantilever %2dx%dx%d (%6d tets): tip %.6e m, ratio to beam theory %.4f\n", nx[k], ny[k], ny[k],
               6 * nx[k] * ny[k] * ny[k], d[k], d[k] / ref);
    }
    double p1 = log2((ref - d[1]) / (ref - d[2])), p2 = log2((ref - d[2]) / (ref - d[3]));
    /* Richardson with the observed order, from the three finest meshes */
    double pr = log2((d[2] - d[1]) / (d[3] - d[2]));
    double extrap = d[3] + (d[3] - d[2]) / (pow(2.0, pr) - 1.0);
    printf("  cantilever: observed order vs beam theory %.2f, %.2f; Richardson order %.2f, extrapolated "
           "%.5e m = %.4f x beam theory\n", p1, p2, pr, extrap, extrap / ref);
    for (int k = 0; k < 4; k++)
        ENSURE(d[k] < ref); /* linear tets lock: converge from below */
    for (int k = 1; k < 4; k++)
        ENSURE(d[k] > d[k - 1]);
    ENSURE(d[3] / ref > 0.90);
    /* pre-asymptotic: the order rises towards 2 (O(h^2) displacements) */
    ENSURE(p1 > 1.0 && p2 > p1 && p2 < 2.2);
    double extrap2 = d[3] + (d[3] - d[2]) / 3.0; /* Richardson assuming order 2 */
    printf("  cantilever: Richardson with order 2: %.4f x beam theory\n", extrap2 / ref);
    ENSURE_REL(extrap2, ref, 0.05);
    return 0;
}

/* ---- Lame ---------------------------------------------------------------- */

/* Thick-walled cylinder ri = 0.1, ro = 0.2 under internal pressure, plane
 * strain (u_z = 0 at both ends). u_r = (1+nu) p ri^2 / (E (ro^2 - ri^2))
 * ((1-2nu) r + ro^2 / r). */
static int lame_run(int nt, int nr, double *err_in, double *err_out, double *sig_err)
{
    const double ri = 0.1, ro = 0.2, L = 0.02, E = 1e7, nu = 0.3, p = 1e5;
    fem_mesh m;
    cm_error err = {0};
    ENSURE(fem_mesh_tube(ri, ro, L, nt, nr, 1, &m, &err) == CM_OK);
    fem_solver *s;
    ENSURE(fem_solver_create(&m, E, nu, 1000.0, 0.0, 0.0, &s, &err) == CM_OK);
    uint8_t *fixed = calloc((size_t)s->n_dof, 1);
    for (int n = 0; n < m.n_nodes; n++) {
        fixed[3 * n + 2] = 1; /* plane strain */
        int i = m.node_ijk[3 * n];
        if (i == 0 || i == nt / 2)
            fixed[3 * n + 1] = 1; /* symmetry: no u_y on the x axis */
        if (i == nt / 4 || i == 3 * nt / 4)
            fixed[3 * n] = 1;
    }
    ENSURE(fem_solver_constrain(s, fixed, NULL, &err) == CM_OK);
    double *b = calloc((size_t)s->n_dof, sizeof *b), *u = calloc((size_t)s->n_dof, sizeof *u);
    fem_load_pressure(&m, FEM_FACE_CAVITY, p, b);
    ENSURE(fem_solver_static(s, b, FEM_LINEAR_CHOLMOD, 0, 0, u, NULL, &err) == CM_OK);
    double k = (1 + nu) * p * ri * ri / (E * (ro * ro - ri * ri));
    double ei = 0.0, eo = 0.0;
    for (int n = 0; n < m.n_nodes; n++) {
        double x = m.x[3 * n], y = m.x[3 * n + 1], r = sqrt(x * x + y * y);
        double ur = (u[3 * n] * x + u[3 * n + 1] * y) / r, ex = k * ((1 - 2 * nu) * r + ro * ro / r);
        int j = m.node_ijk[3 * n + 1];
        if (j == 0)
            ei = fmax(ei, fabs(ur - ex) / ex);
        if (j == nr)
            eo = fmax(eo, fabs(ur - ex) / ex);
    }
    /* hoop stress at mid-wall elements vs p ri^2/(ro^2-ri^2) (1 + ro^2/r^2) */
    double se = 0.0, sr = 0.0;
    for (int e = 0; e < m.n_tets; e++) {
        const int32_t *t = &m.tets[4 * e];
        double g[4][3], ue[4][3], eps[6], sig[6], c[3] = {0, 0, 0};
        fem_tet_gradients(&m.x[3 * t[0]], &m.x[3 * t[1]], &m.x[3 * t[2]], &m.x[3 * t[3]], g);
        for (int i = 0; i < 4; i++)
            for (int a = 0; a < 3; a++) {
                ue[i][a] = u[3 * t[i] + a];
                c[a] += 0.25 * m.x[3 * t[i] + a];
            }
        fem_tet_strain(g, ue, eps);
        fem_stress_from_strain(eps, s->lambda, s->mu, sig);
        double r = sqrt(c[0] * c[0] + c[1] * c[1]), cs = c[0] / r, sn = c[1] / r;
        double stt = sig[0] * sn * sn + sig[1] * cs * cs - 2 * sig[5] * sn * cs;
        double ref = p * ri * ri / (ro * ro - ri * ri) * (1 + ro * ro / (r * r));
        se += fabs(stt - ref);
        sr += fabs(ref);
    }
    *err_in = ei;
    *err_out = eo;
    *sig_err = se / sr;
    free(fixed);
    free(b);
    free(u);
    fem_solver_destroy(&s);
    fem_mesh_free(&m);
    return 0;
}

static int lame_cylinder(void)
{
    double ei1, eo1, s1, ei2, eo2, s2;
    if (lame_run(32, 4, &ei1, &eo1, &s1) || lame_run(64, 8, &ei2, &eo2, &s2))
        return 1;
    printf("  Lame 32x4: max rel error u_r inner %.3e, outer %.3e, mean hoop stress error %.3e\n", ei1, eo1, s1);
    printf("  Lame 64x8: max rel error u_r inner %.3e, outer %.3e, mean hoop stress error %.3e\n", ei2, eo2, s2);
    ENSURE(ei2 < 0.02 && eo2 < 0.015);
    ENSURE(ei1 / ei2 > 2.5 && eo1 / eo2 > 2.5); /* order > 1.3 */
    ENSURE(s2 < 0.1 && s2 < 0.6 * s1);         /* constant-stress elements: O(h) */
    return 0;
}

/* ---- Pressure resultant -------------------------------------------------- */

/* Consistent pressure loads on the half tube x > 0: the resultant is p times
 * the projected area 2 ri L (exact for the polygon: nodes at +-90 deg). */
static int pressure_resultant(void)
{
    const double ri = 0.1, ro = 0.15, L = 0.07, p = 2.5e5;
    fem_mesh m;
    cm_error err = {0};
    ENSURE(fem_mesh_tube(ri, ro, L, 36, 2, 3, &m, &err) == CM_OK);
    for (int f = 0; f < m.n_faces; f++) {
        double cx = 0.0;
        for (int q = 0; q < 3; q++)
            cx += m.x[3 * m.faces[3 * f + q]];
        if (cx < 0.0)
            m.face_tag[f] &= (uint8_t)~FEM_FACE_CAVITY;
    }
    double *f = calloc((size_t)3 * (size_t)m.n_nodes, sizeof *f), F[3] = {0, 0, 0};
    fem_load_pressure(&m, FEM_FACE_CAVITY, p, f);
    for (int n = 0; n < m.n_nodes; n++)
        for (int a = 0; a < 3; a++)
            F[a] += f[3 * n + a];
    printf("  pressure on half tube: F = (%.10g, %.3g, %.3g) N, p 2 ri L = %.10g N\n", F[0], F[1], F[2],
           p * 2 * ri * L);
    ENSURE_REL(F[0], p * 2 * ri * L, 1e-12);
    ENSURE(fabs(F[1]) < 1e-9 * F[0] && fabs(F[2]) < 1e-9 * F[0]);
    free(f);
    fem_mesh_free(&m);

    /* Whole tire cavity: open only at the rim band, whose vector area is 0
     * by symmetry, so the resultant vanishes; its y half gives the side
     * thrust p * (projected area), checked against the surface integral. */
    fem_tire_def d = fem_tire_def_default();
    d.resolution = 0.25;
    ENSURE(fem_mesh_tire(&d, &m, &err) == CM_OK);
    f = calloc((size_t)3 * (size_t)m.n_nodes, sizeof *f);
    fem_load_pressure(&m, FEM_FACE_CAVITY, p, f);
    double Ft[3] = {0, 0, 0}, Aabs = 0.0;
    for (int n = 0; n < m.n_nodes; n++)
        for (int a = 0; a < 3; a++)
            Ft[a] += f[3 * n + a];
    for (int k = 0; k < m.n_faces; k++)
        if (m.face_tag[k] & FEM_FACE_CAVITY) {
            const int32_t *t = &m.faces[3 * k];
            double e1[3], e2[3];
            for (int a = 0; a < 3; a++) {
                e1[a] = m.x[3 * t[1] + a] - m.x[3 * t[0] + a];
                e2[a] = m.x[3 * t[2] + a] - m.x[3 * t[0] + a];
            }
            double c0 = e1[1] * e2[2] - e1[2] * e2[1], c1 = e1[2] * e2[0] - e1[0] * e2[2],
                   c2 = e1[0] * e2[1] - e1[1] * e2[0];
            Aabs += 0.5 * sqrt(c0 * c0 + c1 * c1 + c2 * c2);
        }
    printf("  tire cavity: |resultant| = %.3g N vs p A = %.4g N\n", norm(Ft, 3), p * Aabs);
    ENSURE(norm(Ft, 3) < 1e-12 * p * Aabs);
    free(f);
    fem_mesh_free(&m);
    return 0;
}

/* ---- P-wave -------------------------------------------------------------- */

/* Bar along x with lateral displacements suppressed (uniaxial strain): a
 * step load at x = 0 sends a front at c_d = sqrt((lambda + 2 mu)/rho). The
 * front (half the particle velocity behind it) is tracked at two times. */
static double front_position(const fem_mesh *m, const fem_solver *s, double vhalf)
{
    /* nodes on the line j = k = 0, ordered by i */
    double xf = 0.0;
    for (int n = 0; n < m->n_nodes; n++) {
        if (m->node_ijk[3 * n + 1] || m->node_ijk[3 * n + 2])
            continue;
        double v = s->v[3 * n];
        /* last node (largest x) whose velocity exceeds vhalf, then interpolate */
        if (v >= vhalf && m->x[3 * n] > xf)
            xf = m->x[3 * n];
    }
    /* linear interpolation to the next node */
    double dx = 0.0, vnext = 0.0, vcur = 0.0;
    for (int n = 0; n < m->n_nodes; n++) {
        if (m->node_ijk[3 * n + 1] || m->node_ijk[3 * n + 2])
            continue;
        if (fabs(m->x[3 * n] - xf) < 1e-12)
            vcur = s->v[3 * n];
        if (m->x[3 * n] > xf && (dx == 0.0 || m->x[3 * n] - xf < dx)) {
            dx = m->x[3 * n] - xf;
            vnext = s->v[3 * n];
        }
    }
    if (dx > 0.0 && vcur != vnext)
        xf += dx * (vcur - vhalf) / (vcur - vnext);
    return xf;
}

static int p_wave_speed(void)
{
    const double L = 1.0, a = 0.005, E = 2e7, nu = 0.45, rho = 1100.0, F = 1.0;
    fem_mesh m;
    cm_error err = {0};
    double size[3] = {L, a, a};
    int cells[3] = {400, 1, 1};
    ENSURE(fem_mesh_box(size, cells, &m, &err) == CM_OK);
    fem_solver *s;
    ENSURE(fem_solver_create(&m, E, nu, rho, 0.0, 0.0, &s, &err) == CM_OK);
    uint8_t *fixed = calloc((size_t)s->n_dof, 1);
    for (int n = 0; n < m.n_nodes; n++)
        fixed[3 * n + 1] = fixed[3 * n + 2] = 1;
    ENSURE(fem_solver_constrain(s, fixed, NULL, &err) == CM_OK);
    for (int n = 0; n < m.n_nodes; n++)
        if (m.node_ijk[3 * n] == 0)
            s->f[3 * n] = F / 4.0; /* step load, 4 nodes on the end face */
    fem_stability st;
    ENSURE(fem_solver_stability(s, &m, 2000, &st, &err) == CM_OK);
    double c = sqrt((s->lambda + 2 * s->mu) / rho), h = 0.5 * st.dt_power;
    fem_solver_set_state(s, NULL, NULL);
    ENSURE(fem_solver_prepare(s, FEM_INTEGRATOR_EXPLICIT, h, &err) == CM_OK);
    double v0 = F / (a * a * rho * c); /* particle velocity behind the front */
    double t1 = 0.25 * L / c, t2 = 0.75 * L / c, x1 = 0, x2 = 0;
    int n1 = (int)lround(t1 / h), n2 = (int)lround(t2 / h);
    for (int k = 1; k <= n2; k++) {
        ENSURE(fem_solver_step(s, h, &err) == CM_OK);
        if (k == n1)
            x1 = front_position(&m, s, 0.5 * v0);
    }
    x2 = front_position(&m, s, 0.5 * v0);
    double cm = (x2 - x1) / ((n2 - n1) * h);
    printf("  P-wave: measured %.2f m/s, sqrt((lambda+2mu)/rho) = %.2f m/s (rel. error %.2e); "
           "bar speed sqrt(E/rho) = %.2f m/s\n", cm, c, fabs(cm - c) / c, sqrt(E / rho));
    ENSURE_REL(cm, c, 0.01);
    free(fixed);
    fem_solver_destroy(&s);
    fem_mesh_free(&m);
    return 0;
}

/* ---- Energy -------------------------------------------------------------- */

/* Cantilever released from a bent static state (free vibration). */
static int vibrating_beam(fem_mesh *m, fem_solver **s, double **u0)
{
    cm_error err = {0};
    double size[3] = {0.6, 0.1, 0.1};
    int cells[3] = {6, 1, 1};
    ENSURE(fem_mesh_box(size, cells, m, &err) == CM_OK);
    ENSURE(fem_solver_create(m, 2e7, 0.45, 1100.0, 0.0, 0.0, s, &err) == CM_OK);
    ENSURE(fem_solver_constrain_rim(*s, m, &err) == CM_OK);
    double *b = calloc((size_t)(*s)->n_dof, sizeof *b);
    *u0 = calloc((size_t)(*s)->n_dof, sizeof **u0);
    for (int n = 0; n < m->n_nodes; n++)
        if (m->node_ijk[3 * n] == 6)
            b[3 * n + 2] = -10.0;
    ENSURE(fem_solver_static(*s, b, FEM_LINEAR_CHOLMOD, 0, 0, *u0, NULL, &err) == CM_OK);
    free(b);
    return 0;
}

static int energy_explicit(void)
{
    fem_mesh m;
    fem_solver *s;
    double *u0;
    cm_error err = {0};
    if (vibrating_beam(&m, &s, &u0))
        return 1;
    fem_stability st;
    ENSURE(fem_solver_stability(s, &m, 5000, &st, &err) == CM_OK);
    double h = 0.5 * st.dt_power;
    fem_solver_set_state(s, u0, NULL);
    ENSURE(fem_solver_prepare(s, FEM_INTEGRATOR_EXPLICIT, h, &err) == CM_OK);
    double *Ku = calloc((size_t)s->n_dof, sizeof *Ku);
    /* shadow energy of velocity Verlet, exactly conserved for linear
     * undamped systems: 1/2 v'Mv + 1/2 u'Ku - h^2/8 (Ku)' M^-1 (Ku) */
    double E0 = 0, Es0 = 0, dev = 0, devs = 0;
    for (int k = 0; k <= 20000; k++) {
        if (k)
            ENSURE(fem_solver_step(s, h, &err) == CM_OK);
        if (k % 100)
            continue;
        fem_solver_matvec(s, s->u, Ku);
        double corr = 0.0;
        for (int d = 0; d < s->n_dof; d++)
            corr += Ku[d] * Ku[d] * s->inv_mass[d];
        double E = fem_solver_elastic_energy(s) + fem_solver_kinetic_energy(s), Es = E - h * h / 8 * corr;
        if (k == 0) {
            E0 = E;
            Es0 = Es;
        }
        dev = fmax(dev, fabs(E - E0) / E0);
        devs = fmax(devs, fabs(Es - Es0) / Es0);
    }
    printf("  explicit, dt = 0.5 x 2/omega_max, 20000 steps: energy deviation %.2e, shadow energy deviation %.2e\n",
           dev, devs);
    ENSURE(devs < 1e-10);
    ENSURE(dev < 0.01);
    free(Ku);
    free(u0);
    fem_solver_destroy(&s);
    fem_mesh_free(&m);
    return 0;
}

static int energy_newmark(void)
{
    fem_mesh m;
    fem_solver *s;
    double *u0;
    cm_error err = {0};
    if (vibrating_beam(&m, &s, &u0))
        return 1;
    fem_stability st;
    ENSURE(fem_solver_stability(s, &m, 5000, &st, &err) == CM_OK);
    double h = 20.0 * st.dt_power; /* far beyond the explicit limit */
    fem_solver_set_state(s, u0, NULL);
    ENSURE(fem_solver_prepare(s, FEM_INTEGRATOR_NEWMARK, h, &err) == CM_OK);
    double E0 = fem_solver_elastic_energy(s) + fem_solver_kinetic_energy(s), dev = 0.0, kmax = 0.0;
    for (int k = 1; k <= 2000; k++) {
        ENSURE(fem_solver_step(s, h, &err) == CM_OK);
        double ke = fem_solver_kinetic_energy(s);
        kmax = fmax(kmax, ke);
        dev = fmax(dev, fabs(fem_solver_elastic_energy(s) + ke - E0) / E0);
    }
    printf("  Newmark, dt = 20 x 2/omega_max, 2000 steps: energy deviation %.2e (max KE share %.2f)\n", dev,
           kmax / E0);
    ENSURE(dev < 1e-10);
    ENSURE(kmax > 0.5 * E0); /* it did oscillate */
    free(u0);
    fem_solver_destroy(&s);
    fem_mesh_free(&m);
    return 0;
}

/* Rayleigh damping dissipates: Newmark exactly monotone
 * (E+ - E = -h vbar' C vbar), explicit decaying. */
static int rayleigh_damping(void)
{
    for (int integ = 0; integ < 2; integ++) {
        fem_mesh m;
        fem_solver *s;
        double *u0;
        cm_error err = {0};
        if (vibrating_beam(&m, &s, &u0))
            return 1;
        s->alpha = 5.0;   /* 1/s */
        s->beta = 2e-6;   /* s */
        fem_stability st;
        ENSURE(fem_solver_stability(s, &m, 5000, &st, &err) == CM_OK);
        ENSURE(st.dt_limit < st.dt_power);
        double h = integ == 0 ? 0.5 * st.dt_limit : 20.0 * st.dt_power;
        fem_solver_set_state(s, u0, NULL);
        ENSURE(fem_solver_prepare(s, integ == 0 ? FEM_INTEGRATOR_EXPLICIT : FEM_INTEGRATOR_NEWMARK, h, &err) ==
               CM_OK);
        double E0 = fem_solver_elastic_energy(s), Eprev = E0, rise = 0.0, E = E0;
        int n = integ == 0 ? 40000 : 2000;
        for (int k = 1; k <= n; k++) {
            ENSURE(fem_solver_step(s, h, &err) == CM_OK);
            E = fem_solver_elastic_energy(s) + fem_solver_kinetic_energy(s);
            rise = fmax(rise, (E - Eprev) / E0);
            Eprev = E;
        }
        printf("  %s with Rayleigh damping, %.3g s: energy %.3e of initial, largest one-step rise %.2e "
               "(limit %.4e s vs undamped %.4e s)\n", integ ? "Newmark" : "explicit", n * h, E / E0, rise,
               st.dt_limit, st.dt_power);
        ENSURE(E < 0.5 * E0);
        if (integ == 1)
            ENSURE(rise < 1e-12);
        free(u0);
        fem_solver_destroy(&s);
        fem_mesh_free(&m);
    }
    return 0;
}

/* Sect. 3.3: after the static solve the tire stays at rest (all
 * integrators) until the loads change. */
static int static_start_is_at_rest(void)
{
    for (int integ = 0; integ < 2; integ++) {
        fem_config c = fem_config_default();
        c.tire.resolution = 0.25;
        c.integrator = integ == 0 ? FEM_INTEGRATOR_EXPLICIT : FEM_INTEGRATOR_NEWMARK;
        c.dt = integ == 0 ? 2e-5 : 1e-4;
        fem_model *m;
        cm_error err = {0};
        ENSURE_MSG(fem_create(&c, &m, &err) == CM_OK, "%s", err.msg);
        ENSURE(fem_solve_static(m, &err) == CM_OK);
        int nd = m->s->n_dof;
        double *u0 = malloc((size_t)nd * sizeof *u0), umax = 0.0, drift = 0.0;
        memcpy(u0, m->s->u, (size_t)nd * sizeof *u0);
        for (int k = 0; k < 50; k++)
            ENSURE(fem_advance(m, NULL, 1e-3, &err) == CM_OK);
        for (int d = 0; d < nd; d++) {
            umax = fmax(umax, fabs(u0[d]));
            drift = fmax(drift, fabs(m->s->u[d] - u0[d]));
        }
        printf("  %s: max |u0| = %.4e m (inflation 0.14 MPa + gravity), drift after 0.05 s: %.2e m\n",
               integ ? "Newmark" : "explicit", umax, drift);
        ENSURE(drift < 1e-9 * umax);
        free(u0);
        fem_destroy(&m);
    }
    return 0;
}

/* ---- Explicit stability limit -------------------------------------------- */

static double run_explicit(fem_solver *s, const double *u0, double h, int steps)
{
    cm_error err = {0};
    fem_solver_set_state(s, u0, NULL);
    if (fem_solver_prepare(s, FEM_INTEGRATOR_EXPLICIT, h, &err))
        return NAN;
    double n0 = norm(s->u, s->n_dof), growth = 0.0;
    for (int k = 0; k < steps; k++) {
        fem_solver_step(s, h, &err);
        growth = fmax(growth, norm(s->u, s->n_dof) / n0);
        if (!(growth < 1e12))
            break;
    }
    return growth;
}

static int explicit_stability_limit(void)
{
    fem_mesh m;
    cm_error err = {0};
    double size[3] = {0.2, 0.1, 0.1};
    int cells[3] = {4, 2, 2};
    ENSURE(fem_mesh_box(size, cells, &m, &err) == CM_OK);
    fem_solver *s;
    ENSURE(fem_solver_create(&m, 2e7, 0.45, 1100.0, 0.0, 0.0, &s, &err) == CM_OK);
    ENSURE(fem_solver_constrain_rim(s, &m, &err) == CM_OK);
    fem_stability st;
    ENSURE(fem_solver_stability(s, &m, 100000, &st, &err) == CM_OK);
    printf("  stable step: h/c = %.4e s, 2/omega_max = %.4e s (%d iterations), Gershgorin %.4e s; "
           "estimate/limit = %.3f\n", st.dt_estimate, st.dt_power, st.power_iterations_done, st.dt_gershgorin,
           st.dt_estimate / st.dt_power);
    ENSURE(st.dt_gershgorin <= st.dt_power);
    double *u0 = calloc((size_t)s->n_dof, sizeof *u0);
    for (int d = 0; d < s->n_dof; d++)
        u0[d] = s->fixed[d] ? 0.0 : 1e-6 * rnd();
    double below = run_explicit(s, u0, 0.99 * st.dt_power, 20000);
    double above = run_explicit(s, u0, 1.01 * st.dt_power, 20000);
    double at_g = run_explicit(s, u0, st.dt_gershgorin, 20000);
    printf("  max |u|/|u0| over 20000 steps: %.3g at 0.99 limit, %.3g at 1.01 limit, %.3g at Gershgorin step\n",
           below, above, at_g);
    ENSURE(below < 100.0);
    ENSURE(at_g < 100.0);
    ENSURE(above > 1e6);
    free(u0);
    fem_solver_destroy(&s);
    fem_mesh_free(&m);
    return 0;
}

/* The same on the tire (res 0.25) through the model: 0.98 x 2/omega_max
 * stays bounded, 1.02 x blows up; the h/c estimate is reported beside it. */
static int explicit_stability_tire(void)
{
    fem_config c = fem_config_default();
    c.tire.resolution = 0.25;
    c.integrator = FEM_INTEGRATOR_EXPLICIT;
    c.dt = 1e-6;
    fem_model *m;
    cm_error err = {0};
    ENSURE(fem_create(&c, &m, &err) == CM_OK);
    fem_stability st;
    ENSURE(fem_get_stability(m, &st) == CM_OK);
    fem_solver *s = m->s;
    memset(s->f, 0, (size_t)s->n_dof * sizeof *s->f);
    double *u0 = calloc((size_t)s->n_dof, sizeof *u0);
    for (int d = 0; d < s->n_dof; d++)
        u0[d] = s->fixed[d] ? 0.0 : 1e-6 * rnd();
    double below = run_explicit(s, u0, 0.98 * st.dt_power, 5000);
    double above = run_explicit(s, u0, 1.02 * st.dt_power, 5000);
    printf("  tire: h/c = %.4e s, 2/omega_max = %.4e s (%d iterations), Gershgorin %.4e s; growth %.3g at 0.98, "
           "%.3g at 1.02\n", st.dt_estimate, st.dt_power, st.power_iterations_done, st.dt_gershgorin, below, above);
    ENSURE(below < 100.0 && above > 1e6);
    ENSURE(st.dt_gershgorin <= st.dt_power);
    free(u0);
    fem_destroy(&m);
    return 0;
}

/* K by node blocks (fem_solver.c): on the tire with linear and quadratic
 * elements the pattern is whole 3 x 3 blocks, and the block product gives
 * the bits of the entry-wise one (each row in K's stored order), written
 * out here from K's own arrays. */
static int k_node_blocks(void)
{
    const fem_element_type els[] = {FEM_ELEMENT_TET4, FEM_ELEMENT_TET10};
    for (int k = 0; k < 2; k++) {
        fem_config c = fem_config_default();
        c.tire.resolution = 0.25;
        c.element = els[k];
        c.integrator = FEM_INTEGRATOR_EXPLICIT;
        c.dt = 1e-7;
        fem_model *m;
        cm_error err = {0};
        ENSURE_MSG(fem_create(&c, &m, &err) == CM_OK, "%s", err.msg);
        const fem_solver *s = m->s;
        ENSURE(s->kb_start && s->kb_col && s->kb_val);
        const int n = s->n_dof, *Kp = s->K->p, *Ki = s->K->i;
        const double *Kx = s->K->x;
        ENSURE(s->kb_start[n / 3] * 9 == Kp[n]); /* every entry of K in a block */
        double *x = malloc((size_t)n * sizeof *x), *y = malloc((size_t)n * sizeof *y);
        ENSURE(x && y);
        for (int d = 0; d < n; d++)
            x[d] = rnd() * (d % 7 == 0 ? 1e3 : 1.0); /* magnitudes apart: rounding depends on the order */
        fem_solver_matvec(s, x, y);
        long same = 0;
        for (int r = 0; r < n; r++) {
            double acc = 0.0;
            for (int q = Kp[r]; q < Kp[r + 1]; q++)
                acc += Kx[q] * x[Ki[q]];
            same += memcmp(&acc, &y[r], sizeof acc) == 0;
        }
        printf("  %s tire: %d dofs, %d blocks, %ld of %d rows bit for bit\n", k ? "tet10" : "tet4", n,
               s->kb_start[n / 3], same, n);
        ENSURE(same == n);
        free(x);
        free(y);
        fem_destroy(&m);
    }
    return 0;
}

/* fem_solver_energies: in one pass after an explicit step (K u left by the
 * step) the same bits as the elastic and kinetic energies' own functions
 * and as load^T u summed here; without a load, the separate functions;
 * the elastic energy also against 1/2 u^T K u from K's entries. */
static int energies_one_pass(void)
{
    fem_config c = fem_config_default();
    c.tire.resolution = 0.25;
    c.integrator = FEM_INTEGRATOR_EXPLICIT;
    c.dt = 1e-7;
    fem_model *m;
    cm_error err = {0};
    ENSURE_MSG(fem_create(&c, &m, &err) == CM_OK, "%s", err.msg);
    fem_solver *s = m->s;
    const int n = s->n_dof;
    double *u = malloc((size_t)n * sizeof *u), *v = malloc((size_t)n * sizeof *v);
    ENSURE(u && v);
    for (int d = 0; d < n; d++) {
        u[d] = 1e-4 * rnd() * (d % 7 == 0 ? 1e3 : 1.0); /* magnitudes apart: rounding depends on the order */
        v[d] = 0.1 * rnd();
        s->f[d] = rnd() * (d % 5 == 0 ? 1e2 : 1.0);
    }
    fem_solver_set_state(s, u, v);
    ENSURE_MSG(fem_solver_prepare(s, FEM_INTEGRATOR_EXPLICIT, 1e-7, &err) == CM_OK, "%s", err.msg);
    ENSURE_MSG(fem_solver_step(s, 1e-7, &err) == CM_OK, "%s", err.msg);
    ENSURE(s->ku_valid);
    double e[3], e0[3], fu = 0.0, uku = 0.0;
    fem_solver_energies(s, s->f, e);
    for (int d = 0; d < n; d++)
        fu += s->f[d] * s->u[d];
    const double el = fem_solver_elastic_energy(s), ke = fem_solver_kinetic_energy(s);
    ENSURE(memcmp(&e[0], &el, sizeof el) == 0);
    ENSURE(memcmp(&e[1], &ke, sizeof ke) == 0);
    ENSURE(memcmp(&e[2], &fu, sizeof fu) == 0);
    fem_solver_energies(s, NULL, e0);
    ENSURE(memcmp(e0, e, 2 * sizeof *e) == 0 && e0[2] == 0.0);
    const int *Kp = s->K->p, *Ki = s->K->i;
    const double *Kx = s->K->x;
    for (int r = 0; r < n; r++)
        for (int q = Kp[r]; q < Kp[r + 1]; q++)
            uku += s->u[r] * Kx[q] * s->u[Ki[q]];
    printf("  elastic %.17g J (entry-wise %.17g), kinetic %.17g J, f.u %.17g J\n", e[0], 0.5 * uku, e[1], e[2]);
    ENSURE(e[0] > 0.0 && e[1] > 0.0);
    ENSURE_NEAR(e[0], 0.5 * uku, 1e-10 * e[0]);
    free(u);
    free(v);
    fem_destroy(&m);
    return 0;
}

/* The model refuses dt above the limit unless allow_unstable. */
static int explicit_refuses_unstable_dt(void)
{
    fem_config c = fem_config_default();
    c.mesh = FEM_MESH_BOX;
    c.box_size[0] = 0.2;
    c.box_cells[0] = 4;
    c.dt = 1.0; /* absurd */
    c.power_iterations = 2000;
    fem_model *m = NULL;
    cm_error err = {0};
    ENSURE(fem_create(&c, &m, &err) == CM_ERR_RANGE && m == NULL);
    ENSURE_MSG(strstr(err.msg, "stability limit"), "%s", err.msg);
    c.allow_unstable = true;
    ENSURE(fem_create(&c, &m, &err) == CM_OK);
    fem_destroy(&m);
    ENSURE(m == NULL);
    return 0;
}

/* ---- CHOLMOD vs CG --------------------------------------------------------- */

static int cholmod_vs_cg(void)
{
    fem_config c = fem_config_default();
    c.tire.resolution = 0.35;
    c.integrator = FEM_INTEGRATOR_RIGID; /* no stability analysis needed */
    fem_model *m;
    cm_error err = {0};
    ENSURE(fem_create(&c, &m, &err) == CM_OK);
    fem_model_build_load(m, NULL);
    int nd = m->s->n_dof, it1 = 0, it2 = 0;
    double *u1 = calloc((size_t)nd, sizeof *u1), *u2 = calloc((size_t)nd, sizeof *u2);
    ENSURE(fem_solver_static(m->s, m->s->f, FEM_LINEAR_CHOLMOD, 0, 0, u1, &it1, &err) == CM_OK);
    ENSURE_MSG(fem_solver_static(m->s, m->s->f, FEM_LINEAR_CG, 1e-10, 0, u2, &it2, &err) == CM_OK, "%s", err.msg);
    double dn = 0.0;
    for (int d = 0; d < nd; d++)
        dn += (u1[d] - u2[d]) * (u1[d] - u2[d]);
    int nn, ne;
    fem_mesh_size(m, &nn, &ne);
    printf("  tire %d tets, pressure + gravity: |u_chol - u_cg| / |u_chol| = %.2e (CG %d iterations, tol 1e-10), "
           "max |u| = %.3e m\n", ne, sqrt(dn) / norm(u1, nd), it2, u1[0] * 0 + norm(u1, nd) / sqrt(nd / 3.0));
    ENSURE(sqrt(dn) / norm(u1, nd) < 1e-7);
    free(u1);
    free(u2);
    fem_destroy(&m);
    return 0;
}

/* ---- Gmsh ------------------------------------------------------------------ */

static const char *k_cube_msh =
    "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n"                                      /* 1-3 */
    "$PhysicalNames\n4\n2 1 \"rim\"\n2 2 \"contact\"\n2 3 \"cavity\"\n3 4 \"tire\"\n$EndPhysicalNames\n" /* 4-10 */
    "$Entities\n0 0 3 1\n"                                                         /* 11-12 */
    "1 0 0 0 0 1 1 1 1 0\n2 1 0 0 1 1 1 1 2 0\n3 0 0 0 1 1 0 1 3 0\n"              /* 13-15 */
    "1 0 0 0 1 1 1 1 4 0\n$EndEntities\n"                                          /* 16-17 */
    "$Nodes\n1 8 1 8\n3 1 0 8\n1\n2\n3\n4\n5\n6\n7\n8\n"                          /* 18-28 */
    "0 0 0\n1 0 0\n0 1 0\n1 1 0\n0 0 1\n1 0 1\n0 1 1\n1 1 1\n$EndNodes\n"          /* 29-37 */
    "$Elements\n4 12 1 12\n"                                                       /* 38-39 */
    "2 1 2 2\n1 1 3 7\n2 1 5 7\n"                                                  /* 40-42 */
    "2 2 2 2\n3 2 4 8\n4 2 6 8\n"                                                  /* 43-45 */
    "2 3 2 2\n5 1 2 4\n6 1 3 4\n"                                                  /* 46-48 */
    "3 1 4 6\n7 1 2 4 8\n8 1 2 8 6\n9 1 3 8 4\n10 1 3 7 8\n11 1 5 6 8\n12 1 5 8 7\n" /* 49-55 */
    "$EndElements\n";

/* Replaces the first occurrence of `from` in the cube file by `to`. */
static int parse_variant(const char *from, const char *to, fem_mesh *m, cm_error *err)
{
    char buf[4096];
    const char *at = strstr(k_cube_msh, from);
    if (!at)
        return 99;
    size_t pre = (size_t)(at - k_cube_msh);
    snprintf(buf, sizeof buf, "%.*s%s%s", (int)pre, k_cube_msh, to, at + strlen(from));
    return fem_mesh_parse_gmsh(buf, strlen(buf), "cube.msh", m, err);
}

static int gmsh_reader(void)
{
    fem_mesh m;
    cm_error err = {0};
    ENSURE_MSG(fem_mesh_parse_gmsh(k_cube_msh, strlen(k_cube_msh), "cube.msh", &m, &err) == CM_OK, "%s", err.msg);
    ENSURE(m.n_nodes == 8 && m.n_tets == 6 && m.n_faces == 12);
    int rim = 0, cav = 0, con = 0;
    for (int n = 0; n < m.n_nodes; n++)
        rim += (m.node_tag[n] & FEM_NODE_RIM) != 0;
    for (int f = 0; f < m.n_faces; f++) {
        cav += (m.face_tag[f] & FEM_FACE_CAVITY) != 0;
        con += (m.face_tag[f] & FEM_FACE_CONTACT) != 0;
    }
    ENSURE(rim == 4 && cav == 2 && con == 2);
    ENSURE(fem_mesh_check_closed(&m, &err) == CM_OK);
    double vol;
    fem_mesh_measure(&m, NULL, &vol);
    ENSURE_NEAR(vol, 1.0, 1e-14);
    fem_mesh_free(&m);

    /* The file written to disk reads the same. */
    char path[] = "/tmp/fem_test_cube_XXXXXX";
    int fd = mkstemp(path);
    ENSURE(fd >= 0);
    ENSURE(write(fd, k_cube_msh, strlen(k_cube_msh)) == (ssize_t)strlen(k_cube_msh));
    close(fd);
    ENSURE(fem_mesh_read_gmsh(path, &m, &err) == CM_OK && m.n_tets == 6);
    fem_mesh_free(&m);
    unlink(path);
    ENSURE(fem_mesh_read_gmsh("/nonexistent/x.msh", &m, &err) == CM_ERR_IO);
    return 0;
}

static int gmsh_malformed(void)
{
    static const struct {
        const char *from, *to, *expect;
    } cases[] = {
        {"4.1 0 8", "2.2 0 8", "cube.msh:2: MSH format 2.2"},
        {"4.1 0 8", "4.1 1 8", "binary"},
        {"$EndNodes", "$EndNodez", "cube.msh:37: expected $EndNodes"},
        {"0 1 1\n1 1 1\n", "0 1 1\n1 x 1\n", "cube.msh:36: expected a number"},
        {"7 1 2 4 8", "7 1 2 4 9", "cube.msh:50: element 7 refers to unknown node 9"},
        {"7 1 2 4 8", "7 1 4 2 8", "element 7 is inverted"},
        {"7 1 2 4 8", "7 1 2 3 4", "element 7 has zero volume"},
        {"5 1 2 4", "5 1 2 8", "cube.msh:47: triangle 5 of group cavity is not a face"},
        {"2 1 \"rim\"", "2 1 \"rimm\"", "no nodes in a physical group named \"rim\""},
        {"3 1 4 6", "3 1 99 6", "element type 99 not supported"},
        {"$EndElements\n", "", "unexpected end of file, expected $EndElements"},
        {"1 8 1 8", "1 9 1 8", "9 nodes declared, 8 read"},
    };
    for (size_t k = 0; k < sizeof cases / sizeof *cases; k++) {
        fem_mesh m;
        cm_error err = {0};
        int rc = parse_variant(cases[k].from, cases[k].to, &m, &err);
        ENSURE_MSG(rc != CM_OK && rc != 99, "case %zu accepted", k);
        ENSURE_MSG(strstr(err.msg, cases[k].expect), "case %zu: got \"%s\", want \"%s\"", k, err.msg,
                   cases[k].expect);
    }
    return 0;
}

/* The tire written as .msh and read back: same nodes (bit for bit), tets
 * and named sets. */
static int gmsh_roundtrip_tire(void)
{
    fem_tire_def d = fem_tire_def_default();
    d.resolution = 0.25;
    fem_mesh a, b;
    cm_error err = {0};
    ENSURE(fem_mesh_tire(&d, &a, &err) == CM_OK);
    char path[] = "/tmp/fem_test_tire_XXXXXX";
    int fd = mkstemp(path);
    ENSURE(fd >= 0);
    close(fd);
    ENSURE_MSG(fem_mesh_write_gmsh(&a, path, &err) == CM_OK, "%s", err.msg);
    ENSURE_MSG(fem_mesh_read_gmsh(path, &b, &err) == CM_OK, "%s", err.msg);
    unlink(path);
    ENSURE(a.n_nodes == b.n_nodes && a.n_tets == b.n_tets && a.n_faces == b.n_faces);
    ENSURE(memcmp(a.x, b.x, (size_t)a.n_nodes * 3 * sizeof *a.x) == 0);
    ENSURE(memcmp(a.tets, b.tets, (size_t)a.n_tets * 4 * sizeof *a.tets) == 0);
    ENSURE(memcmp(a.node_tag, b.node_tag, (size_t)a.n_nodes) == 0);
    for (int f = 0; f < a.n_faces; f++) {
        int g = fem_mesh_find_face(&b, a.faces[3 * f], a.faces[3 * f + 1], a.faces[3 * f + 2]);
        ENSURE(g >= 0);
        ENSURE((a.face_tag[f] & (FEM_FACE_CAVITY | FEM_FACE_CONTACT)) ==
               (b.face_tag[g] & (FEM_FACE_CAVITY | FEM_FACE_CONTACT)));
    }
    fem_mesh_free(&a);
    fem_mesh_free(&b);
    return 0;
}

/* ---- Tire mesher ------------------------------------------------------------ */

static int tire_mesher(void)
{
    const double res[3] = {0.25, 0.5, 1.0};
    int counts[3];
    for (int k = 0; k < 3; k++) {
        fem_tire_def d = fem_tire_def_default();
        d.resolution = res[k];
        fem_mesh m;
        cm_error err = {0};
        ENSURE(fem_mesh_tire(&d, &m, &err) == CM_OK);
        counts[k] = m.n_tets;
        double vmin = INFINITY, vol = 0.0, hmin;
        for (int e = 0; e < m.n_tets; e++) {
            const int32_t *t = &m.tets[4 * e];
            double v = fem_tet_volume(&m.x[3 * t[0]], &m.x[3 * t[1]], &m.x[3 * t[2]], &m.x[3 * t[3]]);
            vmin = fmin(vmin, v);
            vol += v;
        }
        fem_mesh_measure(&m, &hmin, NULL);
        ENSURE(vmin > 0.0);
        ENSURE_MSG(fem_mesh_check_closed(&m, &err) == CM_OK, "%s", err.msg);
        /* divergence theorem: V = 1/3 sum over boundary faces of x_c . n A */
        double vs = 0.0, rmax = 0.0;
        int rim = 0, cav = 0, con = 0;
        for (int f = 0; f < m.n_faces; f++) {
            const int32_t *t = &m.faces[3 * f];
            const double *a = &m.x[3 * t[0]], *b = &m.x[3 * t[1]], *c = &m.x[3 * t[2]];
            vs += (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
                   a[2] * (b[0] * c[1] - b[1] * c[0])) / 6.0;
            cav += (m.face_tag[f] & FEM_FACE_CAVITY) != 0;
            con += (m.face_tag[f] & FEM_FACE_CONTACT) != 0;
        }
        for (int n = 0; n < m.n_nodes; n++) {
            rim += (m.node_tag[n] & FEM_NODE_RIM) != 0;
            rmax = fmax(rmax, sqrt(m.x[3 * n] * m.x[3 * n] + m.x[3 * n + 2] * m.x[3 * n + 2]));
        }
        printf("  tire res %.2f: %d nodes, %d tets, %d boundary faces (cavity %d, contact %d), %d rim nodes, "
               "volume %.5f m^3 (surface %.5f), h_min %.2f mm, max radius %.4f m\n", res[k], m.n_nodes, m.n_tets,
               m.n_faces, cav, con, rim, vol, vs, 1e3 * hmin, rmax);
        ENSURE_REL(vs, vol, 1e-12);
        ENSURE(rim > 0 && cav > 0 && con > 0);
        ENSURE_NEAR(rmax, d.outer_radius, 1e-12);
        fem_mesh_free(&m);
    }
    ENSURE(counts[0] < counts[1] && counts[1] < counts[2]);
    ENSURE(counts[2] > 22000 && counts[2] < 26000); /* the paper: 24 287 */
    double ratio = (double)counts[2] / counts[1];
    ENSURE(ratio > 2.5 && ratio < 5.0); /* ~ resolution^2 */
    return 0;
}

/* ---- Model: interface, wheel frame, reactions, sub-cycling -------------------- */

static fem_config small_tire_config(fem_integrator integ)
{
    fem_config c = fem_config_default();
    c.tire.resolution = 0.25;
    c.integrator = integ;
    c.power_iterations = 200;
    return c;
}

/* Integer resolutions mesh the same tire (uniform refinement): the lug
 * tops' extent across the tread (the centre groove's edge and the
 * shoulder) and their share of the circumference are the same at 1 and 2,
 * so that a quantity converges under refinement instead of following a
 * changing geometry (the groove was two cells at every resolution: a
 * quarter of the crown at 1, an eighth at 2, half at 0.5). */
static int tire_mesher_same_tire(void)
{
    double ymin[2], ymax[2], share[2];
    for (int k = 0; k < 2; k++) {
        fem_tire_def d = fem_tire_def_default();
        d.resolution = k + 1.0;
        fem_mesh m;
        cm_error err = {0};
        ENSURE(fem_mesh_tire(&d, &m, &err) == CM_OK);
        /* lug-top nodes: on the outer radius; ymin: the groove's edge (smallest |y|), ymax: the widest */
        ymin[k] = INFINITY, ymax[k] = 0.0;
        for (int n = 0; n < m.n_nodes; n++) {
            const double *x = &m.x[3 * n];
            if (fabs(sqrt(x[0] * x[0] + x[2] * x[2]) - d.outer_radius) < 1e-9) {
                ymin[k] = fmin(ymin[k], fabs(x[1]));
                ymax[k] = fmax(ymax[k], fabs(x[1]));
            }
        }
        /* share of the crown line y = +ymin.. covered by lug tops: the outer-radius faces' area over the
         * band's (the chords' cosine cancels between the two: both on the same polygon) */
        double a_top = 0.0;
        for (int f = 0; f < m.n_faces; f++) {
            const int32_t *t = &m.faces[3 * f];
            int on = 1;
            for (int q = 0; q < 3; q++) {
                const double *x = &m.x[3 * t[q]];
                on &= fabs(sqrt(x[0] * x[0] + x[2] * x[2]) - d.outer_radius) < 1e-9;
            }
            if (on) {
                const double *a = &m.x[3 * t[0]], *b = &m.x[3 * t[1]], *c = &m.x[3 * t[2]];
                double e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
                double cr[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                                e1[0] * e2[1] - e1[1] * e2[0]};
                a_top += 0.5 * sqrt(cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2]);
            }
        }
        share[k] = a_top / (2.0 * M_PI * d.outer_radius * 2.0 * (ymax[k] - ymin[k]));
        printf("  tire res %d: lug tops from |y| = %.6f to %.6f m, %.4f of that band\n", k + 1, ymin[k], ymax[k],
               share[k]);
        fem_mesh_free(&m);
    }
    ENSURE_NEAR(ymin[1], ymin[0], 1e-12);
    ENSURE_NEAR(ymax[1], ymax[0], 1e-12);
    ENSURE_REL(share[1], share[0], 2e-3); /* the polygon's chords: 1 - cos(pi / n_theta) */
    ENSURE(share[0] > 0.49 && share[0] < 0.501); /* lug_fraction 0.5 */
    return 0;
}

/* fem.mesh.layers: the cells through the wall and through the lugs, read
 * from the scene (0..64), independent of the resolution; the same tire
 * (its volume within the chords' 1e-3) with three layers each instead of
 * one. */
static int tire_mesher_layers(void)
{
    const char *text = "fem = {\n  mesh = { type = \"tire\"; resolution = 0.25; layers = 3; };\n"
                       "  material = { E = 20.0e6; nu = 0.45; rho = 1100.0; };\n  integrator = \"rigid\"; dt = 1e-5;\n};\n";
    static const char *const sections[] = {"fem", NULL};
    cm_scene *s;
    cm_error err = {0};
    ENSURE(cm_scene_open_string(text, "t.cfg", &s, &err) == CM_OK);
    fem_config c = fem_config_default();
    ENSURE_MSG(fem_config_read(s, &c, &err) == CM_OK, "%s", err.msg);
    ENSURE_MSG(cm_scene_check_unknown(s, sections, &err) == CM_OK, "%s", err.msg);
    ENSURE(c.tire.layers == 3 && c.tire.resolution == 0.25);
    cm_scene_close(&s);
    double vol[2];
    int kmax[2];
    for (int k = 0; k < 2; k++) {
        fem_tire_def d = c.tire;
        d.layers = k ? 3 : 0;
        fem_mesh m;
        ENSURE_MSG(fem_mesh_tire(&d, &m, &err) == CM_OK, "%s", err.msg);
        fem_mesh_measure(&m, NULL, &vol[k]);
        kmax[k] = 0;
        for (int n = 0; n < m.n_nodes; n++)
            kmax[k] = m.node_ijk[3 * n + 2] > kmax[k] ? m.node_ijk[3 * n + 2] : kmax[k];
        fem_mesh_free(&m);
    }
    printf("  resolution 0.25: %d node layers (default), %d with layers = 3; volume %.6f / %.6f m^3\n", kmax[0] + 1,
           kmax[1] + 1, vol[0], vol[1]);
    ENSURE(kmax[0] == 2 && kmax[1] == 6);
    ENSURE_REL(vol[1], vol[0], 1e-3);
    const char *bad = "fem = {\n  mesh = { type = \"tire\"; layers = -1; };\n"
                      "  material = { E = 20.0e6; nu = 0.45; rho = 1100.0; };\n  integrator = \"rigid\"; dt = 1e-5;\n};\n";
    ENSURE(cm_scene_open_string(bad, "bad.cfg", &s, &err) == CM_OK);
    c = fem_config_default();
    ENSURE(fem_config_read(s, &c, &err) != CM_OK);
    ENSURE_MSG(strstr(err.msg, "fem.mesh.layers"), "%s", err.msg);
    cm_scene_close(&s);
    return 0;
}

static int interface_and_wheel(void)
{
    fem_config c = small_tire_config(FEM_INTEGRATOR_RIGID);
    fem_model *m;
    cm_error err = {0};
    ENSURE(fem_create(&c, &m, &err) == CM_OK);
    ENSURE(fem_solve_static(m, &err) == CM_OK);
    uint32_t nn, nt;
    fem_interface_count(m, &nn, &nt);
    ENSURE(nn > 0 && nt > 0);
    double *x0 = malloc(3 * nn * sizeof *x0), *nrm = malloc(3 * nt * sizeof *nrm), *x = malloc(3 * nn * sizeof *x),
           *v = malloc(3 * nn * sizeof *v), *x1 = malloc(3 * nn * sizeof *x1);
    uint32_t *tris = malloc(3 * nt * sizeof *tris), *ids = malloc(nn * sizeof *ids);
    fem_interface_initial(m, x0, tris, nrm);
    fem_interface_nodes(m, ids);
    uint8_t *used = calloc(nn, 1);
    double rmin = INFINITY;
    for (uint32_t t = 0; t < 3 * nt; t++) {
        ENSURE(tris[t] < nn);
        used[tris[t]] = 1;
    }
    for (uint32_t k = 0; k < nn; k++) {
        ENSURE(used[k]); /* compact: every listed node is used */
        ENSURE(k == 0 || ids[k] > ids[k - 1]);
        rmin = fmin(rmin, sqrt(x0[3 * k] * x0[3 * k] + x0[3 * k + 2] * x0[3 * k + 2]));
    }
    /* outward: on the crown (|y| small, top of lugs) the normal is radial out */
    int crown = 0;
    for (uint32_t t = 0; t < nt; t++) {
        const double *a = &x0[3 * tris[3 * t]];
        double r = sqrt(a[0] * a[0] + a[2] * a[2]);
        if (fabs(a[1]) < 0.02 && fabs(nrm[3 * t + 1]) < 1e-9 && r > 0.2719) {
            ENSURE((nrm[3 * t] * a[0] + nrm[3 * t + 2] * a[2]) / r > 0.99);
            crown++;
        }
    }
    printf("  interface: %u nodes, %u triangles, lowest contact node radius %.4f m, %d crown triangles checked\n",
           nn, nt, rmin, crown);
    ENSURE(crown > 0);

    /* Wheel: rotate by 0.3 rad about y, then move; positions and velocities */
    fem_wheel w;
    fem_get_wheel(m, &w);
    double th = 0.3;
    double R[9] = {cos(th), 0, sin(th), 0, 1, 0, -sin(th), 0, cos(th)};
    memcpy(w.R, R, sizeof R);
    w.center[0] = 0.1;
    w.center[2] = 0.3;
    w.v_center[0] = 0.5;
    w.omega[1] = 2.0;
    ENSURE(fem_set_wheel(m, &w, &err) == CM_OK);
    fem_interface_state(m, x, v);
    double dt = 1e-6;
    ENSURE(fem_advance(m, NULL, dt, &err) == CM_OK);
    fem_interface_state(m, x1, NULL);
    double verr = 0.0, vmax = 0.0;
    for (uint32_t k = 0; k < 3 * nn; k++) {
        verr = fmax(verr, fabs((x1[k] - x[k]) / dt - v[k]));
        vmax = fmax(vmax, fabs(v[k]));
    }
    printf("  wheel: |dx/dt - v| = %.2e m/s (|v| up to %.3f m/s)\n", verr, vmax);
    ENSURE(verr < 1e-5 * vmax);
    /* a bad rotation is refused */
    w.R[0] = 2.0;
    ENSURE(fem_set_wheel(m, &w, &err) == CM_ERR_RANGE);
    free(x0);
    free(nrm);
    free(x);
    free(v);
    free(x1);
    free(tris);
    free(ids);
    free(used);
    fem_destroy(&m);
    return 0;
}

/* Static: the rim reaction balances every applied load, also when the
 * wheel is turned (gravity then acts in a rotated rim-frame direction). */
static int rim_reaction_balances_loads(void)
{
    fem_config c = small_tire_config(FEM_INTEGRATOR_NEWMARK);
    c.dt = 1e-4;
    fem_model *m;
    cm_error err = {0};
    ENSURE(fem_create(&c, &m, &err) == CM_OK);
    fem_wheel w;
    fem_get_wheel(m, &w);
    double th = 0.7;
    double R[9] = {cos(th), 0, sin(th), 0, 1, 0, -sin(th), 0, cos(th)};
    memcpy(w.R, R, sizeof R);
    ENSURE(fem_set_wheel(m, &w, &err) == CM_OK);
    ENSURE(fem_solve_static(m, &err) == CM_OK);
    double F[3], T[3], mass = 0.0;
    fem_rim_reaction(m, F, T);
    for (int d = 0; d < m->s->n_dof; d += 3)
        mass += m->s->mass[d];
    /* pressure resultant is zero (see pressure_resultant); gravity: the rim
     * carries the weight: support force = -m g (world frame) */
    printf("  rim reaction %.6g %.6g %.6g N, tire weight %.6g N (mass %.3f kg)\n", F[0], F[1], F[2], 9.81 * mass,
           mass);
    ENSURE_NEAR(F[0], 0.0, 1e-8 * 9.81 * mass);
    ENSURE_NEAR(F[1], 0.0, 1e-8 * 9.81 * mass);
    ENSURE_REL(F[2], 9.81 * mass, 1e-8);
    /* a DEM force on the interface appears at the rim, rotated back */
    uint32_t nn;
    fem_interface_count(m, &nn, NULL);
    double *f = calloc(3 * nn, sizeof *f);
    f[0] = 100.0; /* world x on interface node 0 */
    fem_model_build_load(m, f);
    ENSURE(fem_solver_static(m->s, m->s->f, FEM_LINEAR_CHOLMOD, 0, 0, m->s->u, NULL, &err) == CM_OK);
    fem_rim_reaction(m, F, T);
    printf("  with 100 N along world x on an interface node: reaction %.6g %.6g %.6g N\n", F[0], F[1], F[2]);
    ENSURE_NEAR(F[0], -100.0, 1e-6);
    ENSURE_REL(F[2], 9.81 * mass, 1e-8);
    free(f);
    fem_destroy(&m);
    return 0;
}

/* The 0.2 m box of 4 x 2 x 2 cells of the exchange tests below. */
static fem_config small_box_config(void)
{
    fem_config c = fem_config_default();
    c.mesh = FEM_MESH_BOX;
    c.box_size[0] = 0.2;
    c.box_cells[0] = 4;
    c.box_cells[1] = c.box_cells[2] = 2;
    return c;
}

/* That box without pressure or gravity, stepping at `fraction` of its
 * explicit limit (*h), after its static solve. */
static int small_box_stepping(double fraction, fem_model **m, double *h)
{
    fem_config c = small_box_config();
    c.pressure = 0.0;
    c.gravity[2] = 0.0;
    cm_error err = {0};
    ENSURE(fem_create(&c, m, &err) == CM_OK);
    fem_stability st;
    ENSURE(fem_get_stability(*m, &st) == CM_OK);
    *h = fraction * st.dt_limit;
    fem_destroy(m);
    c.dt = *h;
    ENSURE(fem_create(&c, m, &err) == CM_OK);
    ENSURE(fem_solve_static(*m, &err) == CM_OK);
    return 0;
}

/* The heaviest interface node: away from the clamped rim. */
static uint32_t heaviest_node(const double *mass, uint32_t nn)
{
    uint32_t k = 0;
    for (uint32_t i = 1; i < nn; i++)
        k = mass[i] > mass[k] ? i : k;
    return k;
}

/* A load held over an interval acts from the interval's start (central
 * differences: m (u+ - 2u + u-) / h^2 = f(t) - K u). From rest, one sub-step
 * h under a force P on one node moves it by h^2 P / (2 m) (u = a t^2 / 2;
 * the other nodes do not move yet). The old step used the acceleration of
 * the previous load for the interval's first half-kick: the node stayed at
 * 0, the force acted one sub-step late. */
static int step_load_from_interval_start(void)
{
    fem_model *m;
    double h;
    if (small_box_stepping(0.5, &m, &h))
        return 1;
    cm_error err = {0};
    uint32_t nn;
    fem_interface_count(m, &nn, NULL);
    double *f = calloc(3 * nn, sizeof *f), *mass = calloc(nn, sizeof *mass), *x0 = calloc(3 * nn, sizeof *x0),
           *x1 = calloc(3 * nn, sizeof *x1);
    ENSURE(f && mass && x0 && x1);
    fem_interface_masses(m, mass);
    uint32_t k = heaviest_node(mass, nn);
    ENSURE(mass[k] > 0.0);
    const double P = 3.0;
    f[3 * k + 2] = P;
    fem_interface_state(m, x0, NULL);
    ENSURE(fem_advance(m, f, h, &err) == CM_OK);
    fem_interface_state(m, x1, NULL);
    double expect = h * h * P / (2.0 * mass[k]), got = x1[3 * k + 2] - x0[3 * k + 2], other = 0.0;
    for (uint32_t i = 0; i < 3 * nn; i++)
        if (i != 3 * k + 2)
            other = fmax(other, fabs(x1[i] - x0[i]));
    printf("  one sub-step h = %.3g s under %.1f N on a %.4g kg node: moved %.6g m, h^2 P / (2 m) = %.6g m; "
           "largest other motion %.3g m\n", h, P, mass[k], got, expect, other);
    ENSURE_REL(got, expect, 1e-9);
    ENSURE(other < 1e-12 * expect);
    free(f);
    free(mass);
    free(x0);
    free(x1);
    fem_destroy(&m);
    return 0;
}

/* The staggered exchange as a two-mass oscillator: one interface node on a
 * contact spring k whose force is computed from the position the FEM last
 * sent and held over the next interval, as dem_server does. The whole
 * system (the body's elastic and kinetic energy + the spring's) is then
 * integrated by central differences and conserves its energy to O((w h)^2)
 * below the critical interval 2 / sqrt(w_fe^2 + k / m). A force applied one
 * sub-step late is a negative damper -k h on the node: on the old step the
 * FEM's energy guard stopped this case after 10 intervals. Measured with the
 * fix: within [0.990, 1.013] of the start. */
static int staggered_contact_spring(void)
{
    fem_model *m;
    double h;
    if (small_box_stepping(0.25, &m, &h))
        return 1;
    cm_error err = {0};
    uint32_t nn;
    fem_interface_count(m, &nn, NULL);
    double *f = calloc(3 * nn, sizeof *f), *mass = calloc(nn, sizeof *mass), *x = calloc(3 * nn, sizeof *x);
    ENSURE(f && mass && x);
    fem_interface_masses(m, mass);
    uint32_t k = heaviest_node(mass, nn);
    /* a stiff contact: k / m = 0.05 / h^2, pre-stretched by d along z */
    const double kc = 0.05 * mass[k] / (h * h), d = 1e-4;
    fem_interface_state(m, x, NULL);
    const double anchor = x[3 * k + 2] + d;
    double e0 = 0.5 * kc * d * d, emin = e0, emax = e0;
    for (int n = 0; n < 4000; n++) {
        double gap = x[3 * k + 2] - anchor;
        f[3 * k + 2] = -kc * gap;
        ENSURE_MSG(fem_advance(m, f, h, &err) == CM_OK, "%s", err.msg);
        fem_interface_state(m, x, NULL);
        fem_energy en;
        fem_get_energy(m, &en);
        double g = x[3 * k + 2] - anchor, e = en.elastic + en.kinetic + 0.5 * kc * g * g;
        emin = fmin(emin, e);
        emax = fmax(emax, e);
    }
    printf("  node %.4g kg on k = %.4g N/m (k/m = 0.05/h^2), h = %.3g s = 0.25 of the FE limit: total energy within "
           "[%.4f, %.4f] of its start over 4000 intervals\n", mass[k], kc, h, emin / e0, emax / e0);
    ENSURE(emax < 1.05 * e0 && emin > 0.95 * e0);
    free(f);
    free(mass);
    free(x);
    fem_destroy(&m);
    return 0;
}

/* fem_advance over k dt equals k advances of dt (same sub-step), the
 * sub-step count is ceil(interval/dt), and time adds up. */
static int subcycling(void)
{
    fem_config c = small_tire_config(FEM_INTEGRATOR_EXPLICIT);
    fem_model *a, *b;
    cm_error err = {0};
    ENSURE(fem_create(&c, &a, &err) == CM_OK);
    fem_stability st;
    ENSURE(fem_get_stability(a, &st) == CM_OK);
    c.dt = 0.5 * st.dt_limit;
    fem_destroy(&a);
    ENSURE(fem_create(&c, &a, &err) == CM_OK);
    ENSURE(fem_create(&c, &b, &err) == CM_OK);
    ENSURE(fem_solve_static(a, &err) == CM_OK && fem_solve_static(b, &err) == CM_OK);
    uint32_t nn;
    fem_interface_count(a, &nn, NULL);
    double *f = calloc(3 * nn, sizeof *f);
    for (uint32_t k = 0; k < nn; k++)
        f[3 * k + 2] = 1.0;
    ENSURE(fem_advance(a, f, 5 * c.dt, &err) == CM_OK);
    for (int k = 0; k < 5; k++)
        ENSURE(fem_advance(b, f, c.dt, &err) == CM_OK);
    double diff = 0.0;
    for (int d = 0; d < a->s->n_dof; d++)
        diff = fmax(diff, fabs(a->s->u[d] - b->s->u[d]));
    ENSURE(diff == 0.0);
    ENSURE(a->s->steps == 5 && b->s->steps == 5);
    long s0 = a->s->steps;
    ENSURE(fem_advance(a, f, 3.5 * c.dt, &err) == CM_OK);
    ENSURE(a->s->steps - s0 == 4);
    ENSURE_NEAR(fem_time(a), 8.5 * c.dt, 1e-15);
    ENSURE_NEAR(a->max_substep, 3.5 * c.dt / 4, 1e-18);
    ENSURE(fem_advance(a, f, -1.0, &err) == CM_ERR_RANGE);
    free(f);
    fem_destroy(&a);
    fem_destroy(&b);
    return 0;
}

/* ---- Scene section ------------------------------------------------------------ */

/* fem.interface_mass_min: every free interface node lighter than m_min
 * gets m_min in all three components (1/m too), no other node changes, the
 * added mass is the sum of the differences, the explicit limit does not
 * shrink, the DEM is told the new masses; a negative value is refused
 * naming the key, and the key reads from a scene. */
static int interface_mass_scaling(void)
{
    fem_config c = small_box_config();
    fem_model *a, *b;
    cm_error err = {0};
    ENSURE(fem_create(&c, &a, &err) == CM_OK);
    uint32_t nn;
    fem_interface_count(a, &nn, NULL);
    double *ma = calloc(nn, sizeof *ma), *mb = calloc(nn, sizeof *mb);
    ENSURE(ma && mb);
    fem_interface_masses(a, ma);
    double lo = INFINITY, hi = 0.0;
    for (uint32_t k = 0; k < nn; k++)
        if (ma[k] > 0.0)
            lo = fmin(lo, ma[k]), hi = fmax(hi, ma[k]);
    ENSURE(lo < hi);
    c.interface_mass_min = 0.5 * (lo + hi);
    ENSURE(fem_create(&c, &b, &err) == CM_OK);
    fem_interface_masses(b, mb);
    double added = 0.0;
    for (uint32_t k = 0; k < nn; k++) {
        if (ma[k] == 0.0) { /* on the clamped rim: stays fixed */
            ENSURE(mb[k] == 0.0);
            continue;
        }
        ENSURE(mb[k] == fmax(ma[k], c.interface_mass_min));
        added += mb[k] - ma[k];
        size_t d = 3 * (size_t)b->if_nodes[k];
        for (int q = 0; q < 3; q++)
            ENSURE(b->s->fixed[d + q] || (b->s->mass[d + q] == mb[k] && b->s->inv_mass[d + q] == 1.0 / mb[k]));
    }
    double mass_a, mass_b, ia, ib;
    fem_mass_properties(a, &mass_a, &ia);
    fem_mass_properties(b, &mass_b, &ib);
    printf("  interface nodes %.4g ... %.4g kg raised to %.4g kg: %.4g kg added (%.3g %% of %.4g kg); explicit limit "
           "%.4g -> %.4g s\n", lo, hi, c.interface_mass_min, fem_added_mass(b), 100 * fem_added_mass(b) / mass_a,
           mass_a, a->stab.dt_limit, b->stab.dt_limit);
    ENSURE(added > 0.0 && fem_added_mass(a) == 0.0);
    ENSURE_REL(fem_added_mass(b), added, 1e-12);
    ENSURE_REL(mass_b - mass_a, added, 1e-9);
    ENSURE(b->stab.dt_limit >= a->stab.dt_limit * (1.0 - 1e-6));
    for (int d = 0; d < a->s->n_dof; d++) /* nodes off the interface keep their masses */
        ENSURE(a->s->mass[d] == b->s->mass[d] || b->s->mass[d] == c.interface_mass_min);
    free(ma);
    free(mb);
    fem_destroy(&a);
    fem_destroy(&b);

    static const char *const sections[] = {"fem", NULL};
    const char *good = "fem = {\n  mesh = { type = \"box\"; size = [0.2, 0.1, 0.1]; cells = [4, 2, 2]; };\n"
                       "  material = { E = 20.0e6; nu = 0.45; rho = 1100.0; };\n"
                       "  integrator = \"explicit\"; dt = 1e-5; interface_mass_min = 2.5e-3; };\n";
    cm_scene *s;
    ENSURE(cm_scene_open_string(good, "good.cfg", &s, &err) == CM_OK);
    c = fem_config_default();
    ENSURE_MSG(fem_config_read(s, &c, &err) == CM_OK, "%s", err.msg);
    ENSURE_MSG(cm_scene_check_unknown(s, sections, &err) == CM_OK, "%s", err.msg);
    ENSURE(c.interface_mass_min == 2.5e-3);
    cm_scene_close(&s);
    const char *bad = "fem = {\n  mesh = { type = \"box\"; size = [0.2, 0.1, 0.1]; cells = [4, 2, 2]; };\n"
                      "  material = { E = 20.0e6; nu = 0.45; rho = 1100.0; };\n"
                      "  integrator = \"explicit\"; dt = 1e-5; interface_mass_min = -1.0; };\n";
    ENSURE(cm_scene_open_string(bad, "bad.cfg", &s, &err) == CM_OK);
    c = fem_config_default();
    ENSURE(fem_config_read(s, &c, &err) != CM_OK);
    ENSURE_MSG(strstr(err.msg, "fem.interface_mass_min"), "%s", err.msg);
    cm_scene_close(&s);
    return 0;
}

/* fem.floor, the rigid frictionless floor (kinematic), on a closed form: a
 * 20 mm cube on rollers (xmin: x, ymin: y), its top held (zmax: z = 0),
 * the floor pressed d = 0.2 mm up into its bottom: uniaxial stress E d / H,
 * a reaction of E A d / H = 40 N exactly (linear tetrahedra are exact under
 * uniform strain), every bottom node held, none below the plane; asked for
 * a load of 40 N instead, the floor is found at d. */
static int floor_block_closed_form(void)
{
    fem_config c = fem_config_default();
    c.mesh = FEM_MESH_BOX;
    c.box_size[0] = c.box_size[1] = c.box_size[2] = 0.02;
    c.box_cells[0] = c.box_cells[1] = c.box_cells[2] = 2;
    c.E = 1e7;
    c.nu = 0.3;
    c.pressure = 0.0;
    c.gravity[2] = 0.0;
    c.integrator = FEM_INTEGRATOR_RIGID; /* a static case: no stability analysis */
    c.n_supports = 3;
    c.supports[0] = (fem_support){.set = FEM_SET_XMIN, .fix = {true, false, false}};
    c.supports[1] = (fem_support){.set = FEM_SET_YMIN, .fix = {false, true, false}};
    c.supports[2] = (fem_support){.set = FEM_SET_ZMAX, .fix = {false, false, true}};
    c.floor = true;
    c.floor_set = FEM_SET_ZMIN;
    const double d = 2e-4, expect = 1e7 * 0.02 * 0.02 * d / 0.02;
    c.floor_height = d;
    fem_model *m;
    cm_error err = {0};
    fem_floor_result r;
    ENSURE(fem_create(&c, &m, &err) == CM_OK);
    ENSURE_MSG(fem_floor_static(m, &r, &err) == CM_OK, "%s", err.msg);
    printf("  cube pressed %.1f mm: reaction %.9g N (E A d / H = %.9g N) on %d nodes, deepest %.2g m below, %d "
           "solves\n", 1e3 * d, r.reaction, expect, r.contact_nodes, r.max_below, r.solves);
    ENSURE_REL(r.reaction, expect, 1e-9);
    ENSURE(r.contact_nodes == 9 && r.max_below <= 1e-15);
    ENSURE_NEAR(r.deflection, d, 1e-15);
    fem_destroy(&m);
    c.floor_height = 0.0;
    c.floor_load = expect;
    ENSURE(fem_create(&c, &m, &err) == CM_OK);
    ENSURE_MSG(fem_floor_static(m, &r, &err) == CM_OK, "%s", err.msg);
    printf("  asked for %.6g N: floor at %.9g m (d = %.9g m), reaction %.9g N, %d solves\n", expect, r.height, d,
           r.reaction, r.solves);
    ENSURE_REL(r.reaction, expect, 1e-6);
    ENSURE_REL(r.height, d, 1e-6);
    fem_destroy(&m);
    return 0;
}

/* The inflated small tire pressed onto the floor until it carries 400 N
 * (no gravity): the floor's reaction is the load, the rim holds the tire
 * with the opposite force (the balance of the whole body), no node of the
 * tread is below the plane, and only a patch touches (the active set let
 * go of the nodes the plane would pull). */
static int floor_tire_balance(void)
{
    fem_config c = small_tire_config(FEM_INTEGRATOR_RIGID);
    c.gravity[2] = 0.0;
    c.floor = true;
    c.floor_set = FEM_SET_CONTACT;
    c.floor_load = 400.0;
    fem_model *m;
    cm_error err = {0};
    fem_floor_result r;
    ENSURE(fem_create(&c, &m, &err) == CM_OK);
    ENSURE_MSG(fem_floor_static(m, &r, &err) == CM_OK, "%s", err.msg);
    double F[3], T[3];
    fem_rim_reaction(m, F, T);
    uint32_t nn;
    fem_interface_count(m, &nn, NULL);
    printf("  small tire, 0.14 MPa, 400 N: floor at %.6g m, deflection %.4f mm, %d nodes touch (of %u tread "
           "nodes), deepest %.2g m below; rim force %.6g %.6g %.6g N; %d solves\n",
           r.height, 1e3 * r.deflection, r.contact_nodes, nn, r.max_below, F[0], F[1], F[2], r.solves);
    ENSURE_REL(r.reaction, 400.0, 1e-6);
    ENSURE_NEAR(F[2], -r.reaction, 1e-6 * 400.0);
    ENSURE_NEAR(F[0], 0.0, 1e-3 * 400.0);
    ENSURE(r.max_below <= 1e-12 && r.deflection > 0.0);
    ENSURE(r.contact_nodes >= 3 && (uint32_t)r.contact_nodes < nn / 4);
    fem_destroy(&m);
    return 0;
}

/* The floor's influence method (K factorized once, the held nodes through
 * the dense system of their influence matrix) against the reference that
 * holds the nodes in K and refactorizes every pass, on the small tire with
 * both elements: at a fixed height the same active set, reactions and
 * displacement field to 1e-9 relative; with the load searched (tet4) the
 * same height to the search's tolerance (1e-6 of the load), with one
 * factorization instead of one per pass. */
static int floor_influence_matches_refactor(void)
{
    for (int el = 0; el < 2; el++) {
        fem_floor_result r[2], rh[2];
        double *u[2] = {NULL, NULL};
        int nd = 0;
        for (int ref = 0; ref < 2; ref++) {
            fem_config c = small_tire_config(FEM_INTEGRATOR_RIGID);
            c.element = el ? FEM_ELEMENT_TET10 : FEM_ELEMENT_TET4;
            c.gravity[2] = 0.0;
            c.floor = true;
            c.floor_set = FEM_SET_CONTACT;
            c.floor_load = 400.0;
            c.floor_refactor = ref;
            fem_model *m;
            cm_error err = {0};
            if (ref == 0 || el == 0) { /* the reference's search on tet10 takes a minute: tet4 only */
                ENSURE(fem_create(&c, &m, &err) == CM_OK);
                ENSURE_MSG(fem_floor_static(m, &r[ref], &err) == CM_OK, "%s", err.msg);
                fem_destroy(&m);
            } else {
                r[1] = r[0];
                r[1].factorizations = r[1].solves, r[1].columns = 0;
            }
            /* at the height the influence method found, fixed */
            c.floor_load = 0.0;
            c.floor_height = r[0].height;
            ENSURE(fem_create(&c, &m, &err) == CM_OK);
            ENSURE_MSG(fem_floor_static(m, &rh[ref], &err) == CM_OK, "%s", err.msg);
            nd = m->s->n_dof;
            u[ref] = malloc((size_t)nd * sizeof *u[ref]);
            ENSURE(u[ref]);
            memcpy(u[ref], m->s->u, (size_t)nd * sizeof *u[ref]);
            fem_destroy(&m);
        }
        double du = 0.0, umax = 0.0;
        for (int d = 0; d < nd; d++) {
            du = fmax(du, fabs(u[0][d] - u[1][d]));
            umax = fmax(umax, fabs(u[1][d]));
        }
        printf("  %s, 400 N: influence %.9f mm (%d nodes, %d passes, %d factorization, %d columns), reference "
               "%.9f mm (%d nodes, %d factorizations); at a fixed height: reaction %.9g / %.9g N, max |du| / max |u| "
               "= %.2g\n", el ? "tet10" : "tet4", 1e3 * r[0].deflection, r[0].contact_nodes, r[0].solves,
               r[0].factorizations, r[0].columns, 1e3 * r[1].deflection, r[1].contact_nodes, r[1].factorizations,
               rh[0].reaction, rh[1].reaction, du / umax);
        free(u[0]);
        free(u[1]);
        ENSURE(r[0].factorizations == 1 && r[1].factorizations == r[1].solves && r[1].columns == 0);
        ENSURE(rh[0].factorizations == 1 && rh[1].factorizations == rh[1].solves && rh[1].solves > 1);
        ENSURE(r[0].columns >= r[0].contact_nodes && r[0].contact_nodes >= 3);
        ENSURE(rh[0].contact_nodes == rh[1].contact_nodes);
        ENSURE_REL(rh[0].reaction, rh[1].reaction, 1e-9);
        ENSURE_NEAR(rh[0].max_below, rh[1].max_below, 1e-9 * umax);
        ENSURE(du <= 1e-9 * umax);
        ENSURE_REL(r[0].deflection, r[1].deflection, 2e-6);
        ENSURE(r[0].contact_nodes == r[1].contact_nodes);
    }
    return 0;
}

/* The floor's solve converges under uniform refinement, on a body with a
 * closed form: a cantilever L x W x H = 200 x 20 x 20 mm (E 10 MPa,
 * nu 0.3) clamped at x = 0 (the whole end face, xyz), a tip load P =
 * 0.1 N down (a uniform traction on x = L) and the floor d = 1 mm below
 * its bottom: the tip comes down by more than d (Timoshenko: P L^3 / 3EI +
 * P L / kGA = 2.015 mm), so the floor carries R = P (1 - d / delta) at the
 * tip's bottom edge (the deflection grows monotonically to the tip: no
 * other node touches). tet10 on 1, 2, 4 cells through the thickness
 * (10 x 1 x 1 ... 40 x 4 x 4 cells, 6 tets each): the differences shrink
 * with an observed order above 1, and the Richardson extrapolate is within
 * 2 % of Timoshenko's R (the clamped end face holds the Poisson
 * contraction, a 3D effect beam theory does not have). */
static int floor_cantilever_converges(void)
{
    const double L = 0.2, W = 0.02, H = 0.02, E = 1e7, nu = 0.3, P = 0.1, d = 1e-3;
    const double I = W * H * H * H / 12.0, G = E / (2.0 * (1.0 + nu)), kappa = 10.0 * (1.0 + nu) / (12.0 + 11.0 * nu);
    const double delta = P * L * L * L / (3.0 * E * I) + P * L / (kappa * G * W * H), R_beam = P * (1.0 - d / delta);
    double R[3];
    for (int k = 0; k < 3; k++) {
        int n = 1 << k;
        fem_config c = fem_config_default();
        c.mesh = FEM_MESH_BOX;
        c.element = FEM_ELEMENT_TET10;
        c.box_size[0] = L, c.box_size[1] = W, c.box_size[2] = H;
        c.box_cells[0] = 10 * n, c.box_cells[1] = c.box_cells[2] = n;
        c.E = E;
        c.nu = nu;
        c.pressure = 0.0;
        c.gravity[2] = 0.0;
        c.integrator = FEM_INTEGRATOR_RIGID;
        c.n_supports = 1;
        c.supports[0] = (fem_support){.set = FEM_SET_XMIN, .fix = {true, true, true}};
        c.n_loads = 1;
        c.loads[0] = (fem_load){.set = FEM_SET_XMAX, .type = FEM_LOAD_FORCE, .value = {0.0, 0.0, -P}};
        c.floor = true;
        c.floor_set = FEM_SET_ZMIN;
        c.floor_height = -d;
        fem_model *m;
        cm_error err = {0};
        fem_floor_result r;
        ENSURE(fem_create(&c, &m, &err) == CM_OK);
        ENSURE_MSG(fem_floor_static(m, &r, &err) == CM_OK, "%s", err.msg);
        double xmin = INFINITY; /* the held nodes: at the tip */
        for (int q = 0; q < m->mesh.n_nodes; q++)
            if (m->s->fixed[3 * q + 2] && !m->s->fixed[3 * q])
                xmin = fmin(xmin, m->mesh.x[3 * q]);
        printf("  %d cell(s) through: floor reaction %.8f N on %d nodes (from x = %.4f m), the free tip at z = %.5f "
               "mm, %d passes\n", n, r.reaction, r.contact_nodes, xmin, 1e3 * r.z_free, r.solves);
        ENSURE(r.factorizations == 1 && r.max_below <= 1e-12);
        ENSURE(xmin > L - 1e-9);
        R[k] = r.reaction;
        fem_destroy(&m);
    }
    double p = log(fabs(R[1] - R[0]) / fabs(R[2] - R[1])) / log(2.0);
    double R_ext = R[2] + (R[2] - R[1]) / (pow(2.0, p) - 1.0);
    printf("  observed order %.2f, extrapolated R %.8f N; Timoshenko %.8f N (%+.2f %%)\n", p, R_ext, R_beam,
           100.0 * (R_ext / R_beam - 1.0));
    ENSURE(fabs(R[2] - R[1]) < fabs(R[1] - R[0]));
    ENSURE(p > 1.0);
    ENSURE_REL(R_ext, R_beam, 0.02);
    return 0;
}

/* fem.floor's keys: read from a scene, exactly one of height and load,
 * the set named, a misspelt key refused by the strict check. */
static int floor_keys_checked(void)
{
    static const char *const sections[] = {"fem", NULL};
    const char *head = "fem = {\n  mesh = { type = \"box\"; size = [0.02, 0.02, 0.02]; cells = [2, 2, 2]; };\n"
                       "  material = { E = 1.0e7; nu = 0.3; rho = 1000.0; };\n  integrator = \"rigid\"; dt = 1e-5;\n";
    static const struct { const char *floor; int ok; const char *msg; } cases[] = {
        {"floor = { set = \"zmin\"; height = 2e-4; };", 1, NULL},
        {"floor = { load = 400.0; };", 1, NULL},
        {"floor = { set = \"zmin\"; height = 2e-4; load = 40.0; };", 0, "exactly one of height"},
        {"floor = { set = \"zmin\"; };", 0, "exactly one of height"},
        {"floor = { set = \"bottom\"; height = 0.0; };", 0, "fem.floor.set"},
        {"floor = { load = -1.0; };", 0, "fem.floor.load"},
        {"floor = { height = 0.0; heigth = 1.0; };", -1, "heigth"},
    };
    for (size_t k = 0; k < sizeof cases / sizeof *cases; k++) {
        char text[1024];
        snprintf(text, sizeof text, "%s  %s\n};\n", head, cases[k].floor);
        cm_scene *s;
        cm_error err = {0};
        ENSURE(cm_scene_open_string(text, "floor.cfg", &s, &err) == CM_OK);
        fem_config c = fem_config_default();
        int rc = fem_config_read(s, &c, &err);
        if (rc == CM_OK && cases[k].ok == -1)
            rc = cm_scene_check_unknown(s, sections, &err);
        else if (rc == CM_OK)
            ENSURE_MSG(cm_scene_check_unknown(s, sections, &err) == CM_OK, "%s: %s", cases[k].floor, err.msg);
        ENSURE_MSG(cases[k].ok == 1 ? rc == CM_OK : rc != CM_OK, "%s", cases[k].floor);
        if (cases[k].msg)
            ENSURE_MSG(strstr(err.msg, cases[k].msg), "%s: %s", cases[k].floor, err.msg);
        if (cases[k].ok == 1)
            ENSURE(c.floor && (k == 0 ? c.floor_set == FEM_SET_ZMIN && c.floor_height == 2e-4 && c.floor_load == 0
                                      : c.floor_set == FEM_SET_CONTACT && c.floor_load == 400.0));
        cm_scene_close(&s);
    }
    return 0;
}

static int config_from_scene(void)
{
    const char *text = "fem = {\n"
                       "  mesh = { type = \"tire\"; resolution = 0.25; lugs = 12; };\n"
                       "  material = { E = 20.0e6; nu = 0.45; rho = 1100.0; rayleigh_beta = 1e-5; };\n"
                       "  integrator = \"newmark\";\n"
                       "  dt = 1e-4;\n"
                       "  pressure = 0.14e6;\n"
                       "  gravity = [0.0, 0.0, -9.81];\n"
                       "  output = { dir = \"out\"; every = 10; };\n"
                       "};\n";
    cm_scene *s;
    cm_error err = {0};
    ENSURE(cm_scene_open_string(text, "t.cfg", &s, &err) == CM_OK);
    fem_config c = fem_config_default();
    ENSURE_MSG(fem_config_read(s, &c, &err) == CM_OK, "%s", err.msg);
    static const char *const sections[] = {"fem", NULL};
    ENSURE_MSG(cm_scene_check_unknown(s, sections, &err) == CM_OK, "%s", err.msg);
    ENSURE(c.mesh == FEM_MESH_TIRE && c.tire.resolution == 0.25 && c.tire.lugs == 12);
    ENSURE(c.integrator == FEM_INTEGRATOR_NEWMARK && c.dt == 1e-4 && c.rayleigh_beta == 1e-5);
    ENSURE(c.output_every == 10 && strstr(c.output_dir, "out"));
    cm_scene_close(&s);

    const char *bad = "fem = {\n  mesh = { type = \"tire\"; lug_dept = 0.01; };\n"
                      "  material = { E = 20.0e6; nu = 0.45; rho = 1100.0; };\n"
                      "  integrator = \"explicit\"; dt = 1e-5; };\n";
    ENSURE(cm_scene_open_string(bad, "bad.cfg", &s, &err) == CM_OK);
    c = fem_config_default();
    ENSURE(fem_config_read(s, &c, &err) == CM_OK);
    ENSURE(cm_scene_check_unknown(s, sections, &err) != CM_OK);
    ENSURE_MSG(strstr(err.msg, "lug_dept"), "%s", err.msg);
    cm_scene_close(&s);

    const char *bad2 = "fem = {\n  mesh = { type = \"tyre\"; };\n};\n";
    ENSURE(cm_scene_open_string(bad2, "bad2.cfg", &s, &err) == CM_OK);
    ENSURE(fem_config_read(s, &c, &err) != CM_OK);
    ENSURE_MSG(strstr(err.msg, "fem.mesh.type"), "%s", err.msg);
    cm_scene_close(&s);
    return 0;
}

/* The shipped scene section reads, passes the strict check and builds. */
static int scene_file_reads(void)
{
    cm_scene *s;
    cm_error err = {0};
    ENSURE_MSG(cm_scene_open(DEMFEM_SOURCE_DIR "/scenes/fem_tire.cfg", &s, &err) == CM_OK, "%s", err.msg);
    fem_config c = fem_config_default();
    ENSURE_MSG(fem_config_read(s, &c, &err) == CM_OK, "%s", err.msg);
    static const char *const sections[] = {"fem", NULL};
    ENSURE_MSG(cm_scene_check_unknown(s, sections, &err) == CM_OK, "%s", err.msg);
    cm_scene_close(&s);
    ENSURE(c.tire.outer_radius == 0.272 && c.E == 20.0e6 && c.integrator == FEM_INTEGRATOR_EXPLICIT);
    c.output_dir[0] = 0;
    c.tire.resolution = 0.25; /* the build itself at resolution 1 is in bench/fem */
    fem_model *m;
    ENSURE_MSG(fem_create(&c, &m, &err) == CM_OK, "%s", err.msg);
    fem_destroy(&m);
    return 0;
}

/* ---- Output ------------------------------------------------------------------ */

static int output_files(void)
{
    char dir[] = "/tmp/fem_test_out_XXXXXX";
    ENSURE(mkdtemp(dir) != NULL);
    fem_config c = small_tire_config(FEM_INTEGRATOR_NEWMARK);
    c.dt = 2e-4;
    snprintf(c.output_dir, sizeof c.output_dir, "%s", dir);
    c.output_every = 2;
    fem_model *m;
    cm_error err = {0};
    ENSURE_MSG(fem_create(&c, &m, &err) == CM_OK, "%s", err.msg);
    ENSURE(fem_solve_static(m, &err) == CM_OK);
    ENSURE_MSG(fem_write_snapshot(m, &err) == CM_OK, "%s", err.msg);
    for (int k = 0; k < 4; k++) {
        ENSURE_MSG(fem_advance(m, NULL, 2e-4, &err) == CM_OK, "%s", err.msg);
        ENSURE_MSG(fem_output_due(m, &err) == CM_OK, "%s", err.msg); /* every 2nd: advances 2 and 4 */
        ENSURE(fem_output_due(m, &err) == CM_OK);                    /* at most once per advance */
    }
    fem_destroy(&m);
    char p[256];
    const char *names[] = {"fem.h5", "fem.xmf", "fem_series.csv"};
    for (int k = 0; k < 3; k++) {
        snprintf(p, sizeof p, "%s/%s", dir, names[k]);
        ENSURE_MSG(access(p, R_OK) == 0, "%s missing", p);
    }
    snprintf(p, sizeof p, "%s/fem.xmf", dir);
    FILE *fp = fopen(p, "r");
    char buf[1 << 16];
    size_t n = fread(buf, 1, sizeof buf - 1, fp);
    buf[n] = 0;
    fclose(fp);
    ENSURE(strstr(buf, "Tetrahedron") && strstr(buf, "eps22") && strstr(buf, "stress"));
    int steps = 0;
    for (const char *q = buf; (q = strstr(q, "<Time ")) != NULL; q++)
        steps++;
    ENSURE_MSG(steps == 3, "%d steps in the XDMF", steps);
    for (int k = 0; k < 3; k++) {
        snprintf(p, sizeof p, "%s/%s", dir, names[k]);
        unlink(p);
    }
    rmdir(dir);
    return 0;
}

/* Snapshots are in the world frame (ParaView shows the tire where the grains
 * are): positions c + R (X + u), and eps33 the vertical strain. A wheel
 * turned by 90 degrees about the axle under inflation: the rim-frame
 * strains swap x and z, so the written eps33 must equal the rim-frame xx. */
static int snapshot_world_frame(void)
{
    char dir[] = "/tmp/fem_test_world_XXXXXX";
    ENSURE(mkdtemp(dir) != NULL);
    fem_config c = small_tire_config(FEM_INTEGRATOR_NEWMARK);
    c.dt = 2e-4;
    snprintf(c.output_dir, sizeof c.output_dir, "%s", dir);
    fem_model *m;
    cm_error err = {0};
    ENSURE_MSG(fem_create(&c, &m, &err) == CM_OK, "%s", err.msg);
    ENSURE(fem_solve_static(m, &err) == CM_OK);
    fem_wheel w = {.center = {1.0, 2.0, 3.0}, .R = {0, 0, 1, 0, 1, 0, -1, 0, 0}}; /* 90 deg about +y */
    ENSURE(fem_set_wheel(m, &w, &err) == CM_OK);
    /* One DEM force on interface node 5: the snapshot shows it there. */
    uint32_t nif, ntf;
    fem_interface_count(m, &nif, &ntf);
    double *fi = calloc(3 * (size_t)nif, sizeof *fi);
    uint32_t *ids = malloc((size_t)nif * sizeof *ids);
    ENSURE(fi && ids);
    fem_interface_nodes(m, ids);
    fi[3 * 5 + 0] = 1.5, fi[3 * 5 + 2] = -2.5;
    ENSURE(fem_advance(m, fi, 1e-6, &err) == CM_OK);
    ENSURE_MSG(fem_write_snapshot(m, &err) == CM_OK, "%s", err.msg);
    int fnode = (int)ids[5];
    free(fi);
    free(ids);
    /* Expected, from the rim-frame state. */
    int nn, ne;
    fem_mesh_size(m, &nn, &ne);
    const double *u = fem_displacement(m);
    double *pos = malloc(3 * (size_t)nn * sizeof *pos), *e33 = malloc((size_t)ne * sizeof *e33);
    ENSURE(pos && e33);
    const fem_mesh *me = &m->mesh;
    int k = nn / 2, e = ne / 3;
    double r[3] = {me->x[3 * k] + u[3 * k], me->x[3 * k + 1] + u[3 * k + 1], me->x[3 * k + 2] + u[3 * k + 2]};
    double want[3] = {1.0 + r[2], 2.0 + r[1], 3.0 - r[0]};
    const int32_t *t = &me->tets[4 * e];
    double g[4][3], ue[4][3], eps[6];
    fem_tet_gradients(&me->x[3 * t[0]], &me->x[3 * t[1]], &me->x[3 * t[2]], &me->x[3 * t[3]], g);
    for (int i = 0; i < 4; i++)
        for (int a = 0; a < 3; a++)
            ue[i][a] = u[3 * t[i] + a];
    fem_tet_strain(g, ue, eps);
    fem_destroy(&m);
    char p[256];
    snprintf(p, sizeof p, "%s/fem.h5", dir);
    hid_t f = H5Fopen(p, H5F_ACC_RDONLY, H5P_DEFAULT);
    ENSURE(f >= 0);
    hid_t g0 = H5Gopen2(f, "/steps", H5P_DEFAULT);
    ENSURE(g0 >= 0);
    char name[64];
    ENSURE(H5Lget_name_by_idx(g0, ".", H5_INDEX_NAME, H5_ITER_INC, 0, name, sizeof name, H5P_DEFAULT) > 0);
    char path[128];
    snprintf(path, sizeof path, "/steps/%s/position", name);
    hid_t d = H5Dopen2(f, path, H5P_DEFAULT);
    ENSURE(d >= 0 && H5Dread(d, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, pos) >= 0);
    H5Dclose(d);
    double *cf = malloc(3 * (size_t)nn * sizeof *cf);
    ENSURE(cf);
    snprintf(path, sizeof path, "/steps/%s/contact_force", name);
    d = H5Dopen2(f, path, H5P_DEFAULT);
    ENSURE(d >= 0 && H5Dread(d, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, cf) >= 0);
    H5Dclose(d);
    double fsum[3] = {0, 0, 0};
    for (int q = 0; q < nn; q++)
        for (int a = 0; a < 3; a++)
            fsum[a] += cf[3 * q + a];
    ENSURE(cf[3 * fnode] == 1.5 && cf[3 * fnode + 2] == -2.5);
    ENSURE(fsum[0] == 1.5 && fsum[1] == 0.0 && fsum[2] == -2.5); /* nowhere else */
    free(cf);
    snprintf(path, sizeof path, "/steps/%s/eps33", name);
    d = H5Dopen2(f, path, H5P_DEFAULT);
    ENSURE(d >= 0 && H5Dread(d, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, e33) >= 0);
    H5Dclose(d);
    H5Gclose(g0);
    H5Fclose(f);
    for (int a = 0; a < 3; a++)
        ENSURE_NEAR(pos[3 * k + a], want[a], 1e-12);
    ENSURE(fabs(eps[0]) > 1e-9);               /* inflation does strain it */
    ENSURE_NEAR(e33[e], eps[0], 1e-12 + 1e-9 * fabs(eps[0])); /* world zz = rim xx after the turn */
    free(pos);
    free(e33);
    const char *names[] = {"fem.h5", "fem.xmf", "fem_series.csv"};
    for (int q = 0; q < 3; q++) {
        snprintf(p, sizeof p, "%s/%s", dir, names[q]);
        unlink(p);
    }
    rmdir(dir);
    return 0;
}

/* ---- Run-time guards --------------------------------------------------------- */

/* Inverted and stretched elements are found in the current configuration,
 * named by index; a sound state passes. */
static int guard_inverted_and_stretched(void)
{
    fem_config c = fem_config_default();
    c.mesh = FEM_MESH_BOX;
    c.box_size[0] = 0.2;
    c.box_cells[0] = 4;
    c.pressure = 0.0;
    c.power_iterations = 200;
    fem_model *m;
    cm_error err = {0};
    ENSURE_MSG(fem_create(&c, &m, &err) == CM_OK, "%s", err.msg);
    ENSURE(fem_solve_static(m, &err) == CM_OK);
    ENSURE_MSG(fem_check_elements(m, &err) == CM_OK, "%s", err.msg);
    /* Mirror the last node of tet 7 through the plane of its other three:
     * that tet's current volume changes sign. */
    const fem_mesh *mesh = &m->mesh;
    const int e = 7;
    const int32_t *t = &mesh->tets[4 * e];
    double *u = m->s->u, xc[4][3];
    for (int i = 0; i < 4; i++)
        for (int a = 0; a < 3; a++)
            xc[i][a] = mesh->x[3 * t[i] + a] + u[3 * t[i] + a];
    double e1[3], e2[3], d3[3], n[3];
    for (int a = 0; a < 3; a++) {
        e1[a] = xc[1][a] - xc[0][a];
        e2[a] = xc[2][a] - xc[0][a];
        d3[a] = xc[3][a] - xc[0][a];
    }
    n[0] = e1[1] * e2[2] - e1[2] * e2[1];
    n[1] = e1[2] * e2[0] - e1[0] * e2[2];
    n[2] = e1[0] * e2[1] - e1[1] * e2[0];
    double nn = n[0] * n[0] + n[1] * n[1] + n[2] * n[2], dist = (d3[0] * n[0] + d3[1] * n[1] + d3[2] * n[2]) / nn;
    double saved[3], moved[3];
    for (int a = 0; a < 3; a++) {
        saved[a] = u[3 * t[3] + a];
        u[3 * t[3] + a] -= 2.0 * dist * n[a];
        moved[a] = xc[3][a] - 2.0 * dist * n[a];
    }
    ENSURE(fem_tet_volume(xc[0], xc[1], xc[2], moved) < 0.0);
    ENSURE(fem_check_elements(m, &err) == CM_ERR_NUMERIC);
    /* The first inverted element is named: tet 7 or a lower-numbered one
     * around the moved node, inverted too (checked independently). */
    int reported = -1;
    const char *p = strstr(err.msg, "element ");
    ENSURE_MSG(p && sscanf(p, "element %d inverted", &reported) == 1, "%s", err.msg);
    ENSURE(reported >= 0 && reported <= e);
    const int32_t *tr = &mesh->tets[4 * reported];
    double xr[4][3];
    for (int i = 0; i < 4; i++)
        for (int a = 0; a < 3; a++)
            xr[i][a] = mesh->x[3 * tr[i] + a] + u[3 * tr[i] + a];
    ENSURE(fem_tet_volume(xr[0], xr[1], xr[2], xr[3]) <= 0.0);
    ENSURE_MSG(strstr(err.msg, "fem.dt") && strstr(err.msg, "t = "), "%s", err.msg);
    /* a share of the elements (fem_advance checks one after each interval):
     * those before the first inverted one pass, the share holding it fails */
    ENSURE(fem_check_elements_range(m, 0, reported, &err) == CM_OK);
    ENSURE(fem_check_elements_range(m, reported, reported + 1, &err) == CM_ERR_NUMERIC);
    /* Stretched: the node back, then moved 30 % of a cell along x: strains
     * of that order in the tets around it, none inverted; with max_strain =
     * 0.1 that is reported as stretched. */
    for (int a = 0; a < 3; a++)
        u[3 * t[3] + a] = saved[a];
    ENSURE(fem_check_elements(m, &err) == CM_OK);
    m->cfg.max_strain = 0.1;
    u[3 * t[3] + 0] += 0.3 * (0.2 / 4);
    ENSURE(fem_check_elements(m, &err) == CM_ERR_NUMERIC);
    double strain = 0.0;
    p = strstr(err.msg, "strain of ");
    ENSURE_MSG(strstr(err.msg, "stretched") && p && sscanf(p, "strain of %lf", &strain) == 1 && strain > 0.1,
               "%s", err.msg);
    ENSURE_MSG(strstr(err.msg, "fem.max_strain = 0.1"), "%s", err.msg);
    /* A small stretch passes. */
    u[3 * t[3] + 0] = saved[0] + 0.01 * (0.2 / 4);
    ENSURE_MSG(fem_check_elements(m, &err) == CM_OK, "%s", err.msg);
    fem_destroy(&m);
    return 0;
}

/* An explicit step above the limit (allow_unstable): the energy guard stops
 * the run with no load putting energy in, long before the displacements run
 * away; a step below runs 400 intervals without a word. */
static int guard_energy_growth(void)
{
    for (int above = 0; above < 2; above++) {
        fem_config c = fem_config_default();
        c.mesh = FEM_MESH_BOX;
        c.box_size[0] = 0.2;
        c.box_cells[0] = 4;
        c.power_iterations = 2000;
        c.allow_unstable = true;
        c.check_every = 1;
        c.max_strain = 100.0; /* the energy guard alone */
        fem_model *m;
        cm_error err = {0};
        ENSURE(fem_create(&c, &m, &err) == CM_OK);
        fem_stability st;
        ENSURE(fem_get_stability(m, &st) == CM_OK);
        fem_destroy(&m);
        c.dt = (above ? 1.2 : 0.9) * st.dt_limit;
        ENSURE(fem_create(&c, &m, &err) == CM_OK);
        ENSURE(fem_solve_static(m, &err) == CM_OK);
        /* A small random disturbance excites every mode. */
        for (int d = 0; d < m->s->n_dof; d++)
            if (!m->s->fixed[d])
                m->s->u[d] += 1e-9 * rnd();
        int k, rc = CM_OK;
        for (k = 0; k < 400 && rc == CM_OK; k++)
            rc = fem_advance(m, NULL, c.dt, &err);
        printf("  dt = %.2f x limit: %s after %d intervals%s%s\n", above ? 1.2 : 0.9, rc ? "stopped" : "ran", k,
               rc ? ": " : "", rc ? err.msg : "");
        if (above) {
            ENSURE(rc == CM_ERR_NUMERIC);
            ENSURE_MSG(strstr(err.msg, "energy grew") && strstr(err.msg, "no input power") &&
                           strstr(err.msg, "fem.dt"), "%s", err.msg);
        } else {
            ENSURE_MSG(rc == CM_OK, "%s", err.msg);
        }
        fem_destroy(&m);
    }
    return 0;
}

/* Gravity turning with the rim and a disturbed tire under Newmark's large
 * steps: the loads' work balances the energy, no false alarm over 400
 * intervals checked every interval. */
static int guard_quiet_when_balanced(void)
{
    fem_config c = fem_config_default();
    c.tire.resolution = 0.25;
    c.integrator = FEM_INTEGRATOR_NEWMARK;
    c.dt = 5e-4;
    c.check_every = 1;
    fem_model *m;
    cm_error err = {0};
    ENSURE(fem_create(&c, &m, &err) == CM_OK);
    ENSURE(fem_solve_static(m, &err) == CM_OK);
    for (int d = 0; d < m->s->n_dof; d++)
        if (!m->s->fixed[d])
            m->s->u[d] += 1e-5 * rnd();
    for (int k = 0; k < 400; k++)
        ENSURE_MSG(fem_advance(m, NULL, 5e-4, &err) == CM_OK, "interval %d: %s", k, err.msg);
    fem_destroy(&m);
    return 0;
}

int main(int argc, char **argv)
{
    cm_log_set_quiet(1);
    static const test_case tests[] = {
    {"guard_inverted_and_stretched", guard_inverted_and_stretched},
    {"guard_energy_growth", guard_energy_growth},
    {"guard_quiet_when_balanced", guard_quiet_when_balanced},
        {"patch_test", patch_test},
        {"cantilever", cantilever},
        {"lame_cylinder", lame_cylinder},
        {"pressure_resultant", pressure_resultant},
        {"p_wave_speed", p_wave_speed},
        {"energy_explicit", energy_explicit},
        {"energy_newmark", energy_newmark},
        {"rayleigh_damping", rayleigh_damping},
        {"static_start_is_at_rest", static_start_is_at_rest},
        {"explicit_stability_limit", explicit_stability_limit},
        {"explicit_stability_tire", explicit_stability_tire},
        {"explicit_refuses_unstable_dt", explicit_refuses_unstable_dt},
        {"k_node_blocks", k_node_blocks},
        {"energies_one_pass", energies_one_pass},
        {"cholmod_vs_cg", cholmod_vs_cg},
        {"gmsh_reader", gmsh_reader},
        {"gmsh_malformed", gmsh_malformed},
        {"gmsh_roundtrip_tire", gmsh_roundtrip_tire},
        {"tire_mesher", tire_mesher},
        {"tire_mesher_same_tire", tire_mesher_same_tire},
        {"tire_mesher_layers", tire_mesher_layers},
        {"interface_and_wheel", interface_and_wheel},
        {"rim_reaction_balances_loads", rim_reaction_balances_loads},
        {"subcycling", subcycling},
        {"step_load_from_interval_start", step_load_from_interval_start},
        {"staggered_contact_spring", staggered_contact_spring},
        {"config_from_scene", config_from_scene},
        {"interface_mass_scaling", interface_mass_scaling},
        {"floor_block_closed_form", floor_block_closed_form},
        {"floor_tire_balance", floor_tire_balance},
        {"floor_influence_matches_refactor", floor_influence_matches_refactor},
        {"floor_cantilever_converges", floor_cantilever_converges},
        {"floor_keys_checked", floor_keys_checked},
        {"scene_file_reads", scene_file_reads},
        {"output_files", output_files},
        {"snapshot_world_frame", snapshot_world_frame},
    };
    return test_main(argc, argv, tests, TEST_COUNT(tests));
}
