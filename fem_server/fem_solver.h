/* Linear elastic system: K (eq. 34), lumped M (eq. 33), Dirichlet
 * constraints, the static solve (sect. 3.3, CHOLMOD or Jacobi-CG), the stable
 * step, and the integrators. Owns the one cholmod_common. Internal to fem/. */
#ifndef FEM_SOLVER_H
#define FEM_SOLVER_H

#include <stdbool.h>
#include <stdint.h>

#include <cholmod.h>

#include "error.h"
#include "fem.h"
#include "fem_mesh.h"

typedef struct fem_solver {
    cholmod_common cc;     /* the one CHOLMOD context of the FEM server */
    bool cc_started;
    int n_dof;             /* 3 * nodes */
    double lambda, mu, rho;
    double alpha, beta;    /* Rayleigh damping C = alpha M + beta K */
    cholmod_sparse *K;     /* full symmetric storage (stype 0): columns == rows */
    /* K again by 3 x 3 node blocks (fem_solver.c, "K by node blocks"), what
     * fem_solver_matvec reads: node row n holds the blocks kb_col[kb_start[n]
     * .. kb_start[n + 1]), 9 values each, row-major, in K's own order */
    int32_t *kb_start, *kb_col;
    double *kb_val;
    double *mass;          /* lumped mass per dof [kg] (eq. 33 row sums) */
    double *inv_mass;      /* 1/m on free dofs, 0 on fixed ones */
    uint8_t *fixed;        /* per dof: 1 = Dirichlet */
    double *u_fixed;       /* prescribed displacement on fixed dofs */
    int n_free;
    int32_t *free_dofs;
    cholmod_sparse *Kff;   /* free-free block, upper (stype 1) */
    cholmod_factor *L;     /* Cholesky of Kff, made on first direct solve */
    /* Dynamics */
    fem_integrator integrator;
    cholmod_factor *Leff;  /* Newmark: K_eff = (1+2beta/h) K + (4/h^2 + 2alpha/h) M */
    double h_eff;          /* sub-step Leff was made for */
    cholmod_dense *rhs, *sol, *Y, *E; /* solve workspaces (n_free x 1), reused */
    double *u, *v, *a;     /* state per dof (rim frame) */
    double *f;             /* current total load per dof [N]: set by the caller */
    double *f_applied;     /* the load the acceleration a was computed with (fem_solver_load_changed) */
    double h_last;         /* s, the last explicit sub-step (0: none since the state was set) */
    double *w, *tmp;       /* work vectors */
    double *ku;            /* K u of the current u, left by the linear explicit step without stiffness damping
                              (its internal forces): the elastic energy reads it instead of a product */
    int ku_valid;          /* ku belongs to the current u (cleared by anything else that sets u) */
    double time;
    long steps;
    /* Neo-Hookean rubber (fem_solver_use_neo_hookean; explicit only): the
     * internal forces from the element loop instead of K u. */
    bool nh;
    int n_tets;
    int32_t *tets;         /* 4 per tet, the mesh's */
    double (*grad0)[4][3]; /* reference shape-function gradients per tet [1/m] */
    double *vol0;          /* reference volumes [m^3] */
    long nh_inverted;      /* element evaluations with det F <= 0 (their forces left out) */
} fem_solver;

int fem_solver_create(const fem_mesh *m, double E, double nu, double rho, double alpha, double beta,
                      fem_solver **out, cm_error *err);
void fem_solver_destroy(fem_solver **s);

/* Fixes the dofs with fixed[d] != 0 at values[d] (values NULL: 0) and builds
 * the free-free block. Resets the state to u = prescribed, v = a = 0. */
int fem_solver_constrain(fem_solver *s, const uint8_t *fixed, const double *values, cm_error *err);
/* Convenience: all three dofs of nodes tagged FEM_NODE_RIM, at 0. */
int fem_solver_constrain_rim(fem_solver *s, const fem_mesh *m, cm_error *err);

/* y = K x (all dofs). */
void fem_solver_matvec(const fem_solver *s, const double *x, double *y);

/* K u = b with the constraints: u (all dofs) gets the prescribed values on
 * fixed dofs. CG stops at |r| <= tol |b_free|; iters may be NULL. When
 * b_free - (K u_c)_free = 0 nothing is solved (u = u_c) and *iters = 0. */
int fem_solver_static(fem_solver *s, const double *b, fem_linear_solver kind, double tol, int max_iter,
                      double *u, int *iters, cm_error *err);

/* x = Kff^-1 b on the free dofs, 0 on the fixed ones, for ncol columns
 * (b and x: ncol full-length vectors one after the other; b's fixed dofs
 * are ignored). CHOLMOD; factorizes Kff on first use and keeps the factor
 * until the constraints change. Allocates (not for time loops). */
int fem_solver_solve_free(fem_solver *s, int ncol, const double *b, double *x, cm_error *err);

/* Stable explicit step (see fem_stability in fem.h). */
int fem_solver_stability(fem_solver *s, const fem_mesh *m, int max_power_iter, fem_stability *st,
                         cm_error *err);

/* Switches the elastic law to compressible Neo-Hookean (fem_material.h)
 * with the solver's Lame parameters: the explicit step and the elastic
 * energy then use the element loop (total Lagrangian); K stays the
 * small-strain stiffness for the static solve, the stability estimate and
 * the Rayleigh beta damping (C = alpha M + beta K). Newmark refuses it. */
int fem_solver_use_neo_hookean(fem_solver *s, const fem_mesh *m, cm_error *err);

/* Sets u, v (NULL: zero, prescribed values on fixed dofs) and the
 * acceleration a = M^-1 (f - K u - C v) from the current s->f. */
void fem_solver_set_state(fem_solver *s, const double *u, const double *v);

/* After the caller changed s->f between steps: the state takes the new
 * load as the force at the current time, a += M^-1 (f - f_applied) and,
 * explicit, the last half-kick v += h_last/2 M^-1 (f - f_applied), so that
 * the next step applies the load from its start (a load held over an
 * interval acts on that interval, not one sub-step later). */
void fem_solver_load_changed(fem_solver *s);

/* Prepares the integrator for sub-step h (Newmark: factorizes K_eff when h
 * changed). No allocation happens in fem_solver_step afterwards. */
int fem_solver_prepare(fem_solver *s, fem_integrator integ, double h, cm_error *err);

/* One step of length h (the prepared one for Newmark) with load s->f. */
int fem_solver_step(fem_solver *s, double h, cm_error *err);

double fem_solver_elastic_energy(const fem_solver *s);  /* 1/2 u^T K u (Neo-Hookean: sum V0 W(F)), uses s->tmp */
double fem_solver_kinetic_energy(const fem_solver *s);  /* 1/2 v^T M v */
/* The three at once, J: e[0] elastic and e[1] kinetic as above, e[2] =
 * load^T u (load NULL: 0). One pass over the dofs where the explicit step
 * left K u (each sum in the order of its own function: the same bits). */
void fem_solver_energies(const fem_solver *s, const double *load, double e[3]);

#endif
