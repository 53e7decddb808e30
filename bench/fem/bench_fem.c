/* FEM speed at the paper's resolution (~24 000 tets): assembly, CHOLMOD
 * factorizations, the explicit step, the Newmark step, and the floor of the
 * explicit step: a plain CSR product with the same K, timed in the same run.
 *
 *   bench_fem OUT.csv [resolution=1.0] [steps=2000] [element=tet4|tet10]
 *
 * The element is fem.element: the 10-node tet has ~5.5x the nodes of the
 * linear one on the same cells and a smaller stable step; the CSV states
 * both, and the cost per simulated second at half the stable step.
 *
 * Each timing is the median of repeated blocks (the machine is noisy). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fem.h"
#include "fem_model.h"
#include "fem_solver.h"
#include "log.h"
#include "timer.h"

#ifdef _OPENMP
#include <omp.h>
#endif

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static double median(double *v, int n)
{
    qsort(v, (size_t)n, sizeof *v, cmp_double);
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/* Plain serial CSR y = A x: the floor any explicit step has to pay. */
static void csr_matvec(int n, const int *rp, const int *ci, const double *a, const double *x, double *y)
{
    for (int r = 0; r < n; r++) {
        double acc = 0.0;
        for (int p = rp[r]; p < rp[r + 1]; p++)
            acc += a[p] * x[ci[p]];
        y[r] = acc;
    }
}

int main(int argc, char **argv)
{
    if (argc < 2) {
        fprintf(stderr, "usage: %s OUT.csv [resolution] [steps] [tet4|tet10]\n", argv[0]);
        return 2;
    }
    double res = argc > 2 ? atof(argv[2]) : 1.0;
    int steps = argc > 3 ? atoi(argv[3]) : 2000;
    const char *element = argc > 4 ? argv[4] : "tet4";
    if (strcmp(element, "tet4") != 0 && strcmp(element, "tet10") != 0) {
        fprintf(stderr, "bench_fem: element \"%s\": tet4 or tet10 expected\n", element);
        return 2;
    }
    const int blocks = 9;
    int per = steps / blocks > 0 ? steps / blocks : 1;
    cm_log_set_quiet(1);
    int threads = 1;
#ifdef _OPENMP
    threads = omp_get_max_threads();
#endif
    cm_error err = {0};
    fem_config c = fem_config_default();
    c.tire.resolution = res;
    c.element = strcmp(element, "tet10") == 0 ? FEM_ELEMENT_TET10 : FEM_ELEMENT_TET4;
    c.integrator = FEM_INTEGRATOR_EXPLICIT;
    c.dt = 1e-9; /* replaced by half the limit below */

    double t0 = cm_now();
    fem_model *m;
    if (fem_create(&c, &m, &err)) {
        fprintf(stderr, "bench_fem: %s\n", err.msg);
        return 1;
    }
    double t_create = cm_now() - t0; /* mesh + assembly + stability (power iteration) */
    /* separate timings */
    t0 = cm_now();
    fem_solver *s2;
    if (fem_solver_create(&m->mesh, c.E, c.nu, c.rho, 0, 0, &s2, &err)) {
        fprintf(stderr, "bench_fem: %s\n", err.msg);
        return 1;
    }
    double t_assembly = cm_now() - t0;
    fem_solver_destroy(&s2);
    fem_stability st;
    fem_get_stability(m, &st);
    t0 = cm_now();
    fem_stability st2;
    fem_solver_stability(m->s, &m->mesh, c.power_iterations, &st2, &err);
    double t_power = cm_now() - t0;

    fem_solver *s = m->s;
    t0 = cm_now();
    if (fem_solve_static(m, &err)) {
        fprintf(stderr, "bench_fem: %s\n", err.msg);
        return 1;
    }
    double t_static = cm_now() - t0; /* analyze + factorize + solve */
    double t_solve_again;
    {
        double *u = malloc((size_t)s->n_dof * sizeof *u);
        t0 = cm_now();
        fem_solver_static(s, s->f, FEM_LINEAR_CHOLMOD, 0, 0, u, NULL, &err);
        t_solve_again = cm_now() - t0;
        free(u);
    }
    double t_cg;
    int cg_iters = 0;
    {
        double *u = malloc((size_t)s->n_dof * sizeof *u);
        t0 = cm_now();
        fem_solver_static(s, s->f, FEM_LINEAR_CG, 1e-10, 0, u, &cg_iters, &err);
        t_cg = cm_now() - t0;
        free(u);
    }

    /* explicit step vs plain CSR product, interleaved blocks */
    double h = 0.5 * st.dt_limit;
    fem_solver_set_state(s, s->u, NULL);
    fem_solver_prepare(s, FEM_INTEGRATOR_EXPLICIT, h, &err);
    int n = s->n_dof;
    const int *rp = s->K->p, *ci = s->K->i;
    const double *ax = s->K->x;
    double *x = malloc((size_t)n * sizeof *x), *y = malloc((size_t)n * sizeof *y);
    for (int d = 0; d < n; d++)
        x[d] = 1e-3 * (d % 7);
    double te[32], tc[32], tn[32];
    for (int b = 0; b < blocks; b++) {
        t0 = cm_now();
        for (int k = 0; k < per; k++)
            fem_solver_step(s, h, &err);
        te[b] = (cm_now() - t0) / per;
        t0 = cm_now();
        for (int k = 0; k < per; k++) {
            csr_matvec(n, rp, ci, ax, x, y);
            x[k % n] += 1e-30 * y[(k * 7) % n]; /* keep the compiler honest */
        }
        tc[b] = (cm_now() - t0) / per;
    }
    double t_explicit = median(te, blocks), t_csr = median(tc, blocks);

    /* the energies after an explicit step (coupled runs: every exchange):
     * one pass (fem_solver_energies) vs the three sums one after another,
     * interleaved blocks; the same bits (test_fem.energies_one_pass) */
    double t1p[32], t3p[32], sink = 0.0;
    for (int b = 0; b < blocks; b++) {
        double e[3];
        t0 = cm_now();
        for (int k = 0; k < per; k++) {
            fem_solver_energies(s, s->f, e);
            sink += e[0] + e[1] + e[2];
        }
        t1p[b] = (cm_now() - t0) / per;
        t0 = cm_now();
        for (int k = 0; k < per; k++) {
            double fu = 0.0;
            for (int d = 0; d < n; d++)
                fu += s->f[d] * s->u[d];
            sink += fem_solver_elastic_energy(s) + fem_solver_kinetic_energy(s) + fu;
        }
        t3p[b] = (cm_now() - t0) / per;
    }
    double t_en1 = median(t1p, blocks), t_en3 = median(t3p, blocks);

    /* Newmark: factorization of K_eff, then steps */
    double hn = 1e-4;
    t0 = cm_now();
    if (fem_solver_prepare(s, FEM_INTEGRATOR_NEWMARK, hn, &err)) {
        fprintf(stderr, "bench_fem: %s\n", err.msg);
        return 1;
    }
    double t_factor_eff = cm_now() - t0;
    fem_solver_set_state(s, s->u, NULL);
    int pern = per / 10 > 0 ? per / 10 : 1;
    for (int b = 0; b < blocks; b++) {
        t0 = cm_now();
        for (int k = 0; k < pern; k++)
            fem_solver_step(s, hn, &err);
        tn[b] = (cm_now() - t0) / pern;
    }
    double t_newmark = median(tn, blocks);
    double fl = (double)s->cc.lnz; /* nonzeros in L */

    int nn, ne;
    fem_mesh_size(m, &nn, &ne);
    size_t nnz = (size_t)rp[n];
    FILE *fp = fopen(argv[1], "w");
    if (!fp) {
        perror(argv[1]);
        return 1;
    }
    fprintf(fp, "quantity,value,unit\n");
    fprintf(fp, "threads,%d,-\nelement,%s,-\nresolution,%g,-\nnodes,%d,-\ntets,%d,-\ndofs,%d,-\nnnz_K,%zu,-\n"
            "nnz_L_Keff,%.0f,-\n", threads, element, res, nn, ne, n, nnz, fl);
    fprintf(fp, "create_total,%.6g,s\nassembly,%.6g,s\npower_iteration_%d,%.6g,s\n", t_create, t_assembly,
            st2.power_iterations_done, t_power);
    fprintf(fp, "static_cholmod_analyze_factor_solve,%.6g,s\nstatic_cholmod_resolve,%.6g,s\n", t_static,
            t_solve_again);
    fprintf(fp, "static_cg_1e-10,%.6g,s\ncg_iterations,%d,-\n", t_cg, cg_iters);
    fprintf(fp, "explicit_step,%.6g,s\ncsr_matvec_floor,%.6g,s\nexplicit_over_floor,%.4g,-\n", t_explicit, t_csr,
            t_explicit / t_csr);
    fprintf(fp, "newmark_factorize_Keff,%.6g,s\nnewmark_step,%.6g,s\n", t_factor_eff, t_newmark);
    fprintf(fp, "dt_estimate,%.6g,s\ndt_power,%.6g,s\ndt_gershgorin,%.6g,s\n", st.dt_estimate, st.dt_power,
            st.dt_gershgorin);
    fprintf(fp, "explicit_cost_per_simulated_second,%.6g,s\n", t_explicit / h);
    fprintf(fp, "energies_one_pass,%.6g,s\nenergies_three_passes,%.6g,s\n", t_en1, t_en3);
    fclose(fp);
    printf("fem bench (%d threads, %s): %d tets, %d dofs; explicit step %.1f us vs CSR floor %.1f us (x%.2f); "
           "dt_power %.4g s, %.3g s per simulated second; "
           "Newmark step %.2f ms, K_eff factorization %.3f s; static CHOLMOD %.3f s, CG %.3f s (%d it)\n",
           threads, element, ne, n, 1e6 * t_explicit, 1e6 * t_csr, t_explicit / t_csr, st.dt_power, t_explicit / h,
           1e3 * t_newmark, t_factor_eff,
           t_static, t_cg, cg_iters);
    printf("energies after a step: one pass %.1f us, three passes %.1f us (x%.2f)%s\n", 1e6 * t_en1, 1e6 * t_en3,
           t_en3 / t_en1, sink == 0.0 ? " (all zero)" : "");
    free(x);
    free(y);
    fem_destroy(&m);
    return 0;
}
