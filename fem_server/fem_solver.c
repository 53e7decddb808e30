/* Assembly (eqs. 33, 34), constraints, static solve, stable step and time
 * integration of M u'' + C u' + K u = f (eq. 28 discretised). */
#include "fem_solver.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fem_element.h"
#include "fem_material.h"

#ifdef _OPENMP
#define FEM_OMP_FOR _Pragma("omp parallel for schedule(static)")
#else
#define FEM_OMP_FOR
#endif

static int cholmod_failed(fem_solver *s, cm_error *err, const char *what)
{
    return cm_fail(err, s->cc.status == CHOLMOD_OUT_OF_MEMORY ? CM_ERR_NOMEM : CM_ERR_NUMERIC,
                   "fem solver: CHOLMOD %s failed (status %d)", what, s->cc.status);
}

/* ---- K by node blocks ---------------------------------------------------
 *
 * The explicit step's K w is the FEM server's hot loop (a pass over K, ~1e6
 * entries on the paper's tire, per sub-step). Row r of K holds, for each
 * node m coupled to r's node, the three columns 3m, 3m+1, 3m+2 (every
 * element adds its whole 12 x 12 matrix), so the three rows of a node can
 * be read together, by 3 x 3 blocks with one column index each: a third
 * less memory to stream than K's one index per entry, and three sums in
 * flight instead of one. Each row's sum still adds its entries one by one
 * in K's stored order, so the bits are those of the entry-wise product. */

/* 1: rows 3n .. 3n+2 of K hold the same block columns, each as the three
 * entries 3m, 3m+1, 3m+2 in that order; *nb: the blocks. */
static int whole_blocks(const cholmod_sparse *K, int n, int *nb)
{
    const int *Kp = K->p, *Ki = K->i;
    const int len = Kp[3 * n + 1] - Kp[3 * n];
    if (len % 3 || Kp[3 * n + 2] - Kp[3 * n + 1] != len || Kp[3 * n + 3] - Kp[3 * n + 2] != len)
        return 0;
    for (int a = 0; a < 3; a++)
        for (int q = 0; q < len; q += 3) {
            const int *c = Ki + Kp[3 * n + a] + q;
            if (c[0] % 3 || c[1] != c[0] + 1 || c[2] != c[0] + 2 || c[0] != Ki[Kp[3 * n] + q])
                return 0;
        }
    *nb = len / 3;
    return 1;
}

/* Fills s->kb_* from K, whose pattern is whole blocks by the assembly
 * (every element adds its whole matrix, both triangles are stored): a node
 * whose rows are not is an error of the assembly, named. */
static int blocks_of_k(fem_solver *s, cm_error *err)
{
    const cholmod_sparse *K = s->K;
    const int nn = s->n_dof / 3, *Kp = K->p, *Ki = K->i;
    const double *Kx = K->x;
    int total = 0;
    for (int n = 0, nb; n < nn; n++) {
        if (!whole_blocks(K, n, &nb))
            return cm_fail(err, CM_ERR_STATE, "fem solver: the rows of node %d of K are not whole 3 x 3 blocks", n);
        total += nb;
    }
    s->kb_start = malloc(((size_t)nn + 1) * sizeof *s->kb_start);
    s->kb_col = malloc((size_t)total * sizeof *s->kb_col);
    s->kb_val = malloc(9 * (size_t)total * sizeof *s->kb_val);
    if (!s->kb_start || !s->kb_col || !s->kb_val)
        return cm_fail(err, CM_ERR_NOMEM, "fem solver: out of memory for K's %d node blocks", total);
    s->kb_start[0] = 0;
    for (int n = 0; n < nn; n++) {
        const int b0 = s->kb_start[n], nb = (Kp[3 * n + 1] - Kp[3 * n]) / 3;
        s->kb_start[n + 1] = b0 + nb;
        for (int b = 0; b < nb; b++) {
            s->kb_col[b0 + b] = Ki[Kp[3 * n] + 3 * b] / 3;
            for (int a = 0; a < 3; a++)
                for (int c = 0; c < 3; c++)
                    s->kb_val[9 * (size_t)(b0 + b) + 3 * a + c] = Kx[Kp[3 * n + a] + 3 * b + c];
        }
    }
    return 0;
}

/* (K x) of node n's three rows, in k[0..2]: each row's entries added in
 * K's order (the entry-wise product's bits). */
static inline void block_row(const fem_solver *s, int n, const double *restrict x, double k[3])
{
    const int32_t *col = s->kb_col;
    const double *restrict v = s->kb_val;
    double k0 = 0.0, k1 = 0.0, k2 = 0.0;
    for (int b = s->kb_start[n]; b < s->kb_start[n + 1]; b++) {
        const double *xm = x + 3 * col[b], *e = v + 9 * (size_t)b;
        const double x0 = xm[0], x1 = xm[1], x2 = xm[2];
        k0 += e[0] * x0, k0 += e[1] * x1, k0 += e[2] * x2;
        k1 += e[3] * x0, k1 += e[4] * x1, k1 += e[5] * x2;
        k2 += e[6] * x0, k2 += e[7] * x1, k2 += e[8] * x2;
    }
    k[0] = k0, k[1] = k1, k[2] = k2;
}

int fem_solver_create(const fem_mesh *m, double E, double nu, double rho, double alpha, double beta,
                      fem_solver **out, cm_error *err)
{
    *out = NULL;
    if (!(E > 0.0) || !(nu > -1.0 && nu < 0.5) || !(rho > 0.0) || !(alpha >= 0.0) || !(beta >= 0.0))
        return cm_fail(err, CM_ERR_RANGE, "fem solver: need E > 0, -1 < nu < 0.5, rho > 0, damping >= 0");
    fem_solver *s = calloc(1, sizeof *s);
    if (!s)
        return cm_fail(err, CM_ERR_NOMEM, "fem solver: out of memory");
    cholmod_start(&s->cc);
    s->cc_started = true;
    s->cc.print = 0;
    s->n_dof = 3 * m->n_nodes;
    fem_lame(E, nu, &s->lambda, &s->mu);
    s->rho = rho;
    s->alpha = alpha;
    s->beta = beta;
    s->integrator = FEM_INTEGRATOR_RIGID;
    size_t n = (size_t)s->n_dof;
    s->mass = calloc(n, sizeof(double));
    s->inv_mass = calloc(n, sizeof(double));
    s->fixed = calloc(n, 1);
    s->u_fixed = calloc(n, sizeof(double));
    s->free_dofs = malloc(n * sizeof(int32_t));
    s->u = calloc(n, sizeof(double));
    s->v = calloc(n, sizeof(double));
    s->a = calloc(n, sizeof(double));
    s->f = calloc(n, sizeof(double));
    s->w = calloc(n, sizeof(double));
    s->tmp = calloc(n, sizeof(double));
    s->ku = calloc(n, sizeof(double));
    s->f_applied = calloc(n, sizeof(double));
    if (!s->mass || !s->inv_mass || !s->fixed || !s->u_fixed || !s->free_dofs || !s->u || !s->v || !s->a ||
        !s->f || !s->w || !s->tmp || !s->ku || !s->f_applied) {
        fem_solver_destroy(&s);
        return cm_fail(err, CM_ERR_NOMEM, "fem solver: out of memory for %d dofs", (int)n);
    }

    /* Element loop: upper triangle of each K_e into one triplet matrix;
     * cholmod_triplet_to_sparse sums the duplicates (the assembly). */
    bool quad = m->tet_mid != NULL;
    size_t nz = (size_t)m->n_tets * (quad ? 465u : 78u);
    cholmod_triplet *T = cholmod_allocate_triplet(n, n, nz, 1, CHOLMOD_REAL, &s->cc);
    if (!T) {
        int rc = cholmod_failed(s, err, "allocate_triplet");
        fem_solver_destroy(&s);
        return rc;
    }
    int *Ti = T->i, *Tj = T->j;
    double *Tx = T->x;
    size_t k = 0;
    for (int e = 0; e < m->n_tets && quad; e++) {
        int32_t t[10];
        double xe[10][3], Ke[30][30], V;
        fem_mesh_tet_nodes(m, e, t);
        for (int i = 0; i < 10; i++)
            memcpy(xe[i], &m->x[3 * t[i]], sizeof xe[i]);
        int bad = fem_tet10_stiffness(xe, s->lambda, s->mu, Ke, &V);
        if (bad || !(V > 0.0)) {
            cholmod_free_triplet(&T, &s->cc);
            fem_solver_destroy(&s);
            return cm_fail(err, CM_ERR_NUMERIC, "%s: 10-node element %d has det J <= 0 at Gauss point %d "
                           "(distorted or inverted)", m->source, e, bad);
        }
        /* HRZ lumped mass (fem_element.h): corners 1/36, mid-edge 4/27 */
        for (int i = 0; i < 10; i++)
            for (int a = 0; a < 3; a++)
                s->mass[3 * t[i] + a] += (i < 4 ? FEM_TET10_MASS_CORNER : FEM_TET10_MASS_MID) * rho * V;
        for (int p = 0; p < 30; p++) {
            int gp = 3 * t[p / 3] + p % 3;
            for (int q = p; q < 30; q++) {
                int gq = 3 * t[q / 3] + q % 3;
                Ti[k] = gp < gq ? gp : gq;
                Tj[k] = gp < gq ? gq : gp;
                Tx[k] = Ke[p][q];
                k++;
            }
        }
    }
    for (int e = 0; e < m->n_tets && !quad; e++) {
        const int32_t *t = &m->tets[4 * e];
        double g[4][3], Ke[12][12];
        double V = fem_tet_gradients(&m->x[3 * t[0]], &m->x[3 * t[1]], &m->x[3 * t[2]], &m->x[3 * t[3]], g);
        if (!(V > 0.0)) {
            cholmod_free_triplet(&T, &s->cc);
            fem_solver_destroy(&s);
            return cm_fail(err, CM_ERR_NUMERIC, "%s: element %d has volume %.3g m^3", m->source, e, V);
        }
        fem_tet_stiffness(g, V, s->lambda, s->mu, Ke); /* eq. 34 */
        /* eq. 33 lumped by row sums: sum_j int N_i N_j = int N_i = V/4 */
        for (int i = 0; i < 4; i++)
            for (int a = 0; a < 3; a++)
                s->mass[3 * t[i] + a] += 0.25 * rho * V;
        for (int p = 0; p < 12; p++) {
            int gp = 3 * t[p / 3] + p % 3;
            for (int q = p; q < 12; q++) {
                int gq = 3 * t[q / 3] + q % 3;
                Ti[k] = gp < gq ? gp : gq;
                Tj[k] = gp < gq ? gq : gp;
                Tx[k] = Ke[p][q];
                k++;
            }
        }
    }
    T->nnz = k;
    cholmod_sparse *Ku = cholmod_triplet_to_sparse(T, k, &s->cc);
    cholmod_free_triplet(&T, &s->cc);
    if (!Ku) {
        int rc = cholmod_failed(s, err, "triplet_to_sparse");
        fem_solver_destroy(&s);
        return rc;
    }
    s->K = cholmod_copy(Ku, 0, 1, &s->cc); /* both triangles, for the row-wise product */
    cholmod_free_sparse(&Ku, &s->cc);
    if (!s->K) {
        int rc = cholmod_failed(s, err, "copy");
        fem_solver_destroy(&s);
        return rc;
    }
    int rc = blocks_of_k(s, err);
    if (rc) {
        fem_solver_destroy(&s);
        return rc;
    }
    *out = s;
    return fem_solver_constrain(s, s->fixed, NULL, err);
}

/* What depends on the constraints: the free-dof stiffness, the factors and
 * the solve workspaces (rebuilt by fem_solver_constrain and _prepare). */
static void free_constrained(fem_solver *s)
{
    cholmod_free_sparse(&s->Kff, &s->cc);
    cholmod_free_factor(&s->L, &s->cc);
    cholmod_free_factor(&s->Leff, &s->cc);
    cholmod_free_dense(&s->rhs, &s->cc);
    cholmod_free_dense(&s->sol, &s->cc);
    cholmod_free_dense(&s->Y, &s->cc);
    cholmod_free_dense(&s->E, &s->cc);
}

void fem_solver_destroy(fem_solver **ps)
{
    fem_solver *s = *ps;
    if (!s)
        return;
    if (s->cc_started) {
        cholmod_free_sparse(&s->K, &s->cc);
        free_constrained(s);
        cholmod_finish(&s->cc);
    }
    free(s->mass);
    free(s->inv_mass);
    free(s->fixed);
    free(s->u_fixed);
    free(s->free_dofs);
    free(s->u);
    free(s->v);
    free(s->a);
    free(s->f);
    free(s->w);
    free(s->tmp);
    free(s->ku);
    free(s->f_applied);
    free(s->kb_start);
    free(s->kb_col);
    free(s->kb_val);
    free(s->tets);
    free(s->grad0);
    free(s->vol0);
    free(s);
    *ps = NULL;
}

int fem_solver_constrain(fem_solver *s, const uint8_t *fixed, const double *values, cm_error *err)
{
    int n = s->n_dof;
    if (fixed != s->fixed)
        memcpy(s->fixed, fixed, (size_t)n);
    s->n_free = 0;
    for (int d = 0; d < n; d++) {
        s->u_fixed[d] = s->fixed[d] && values ? values[d] : 0.0;
        s->inv_mass[d] = s->fixed[d] ? 0.0 : 1.0 / s->mass[d];
        if (!s->fixed[d])
            s->free_dofs[s->n_free++] = d;
    }
    free_constrained(s);
    s->h_eff = 0.0;
    if (s->n_free == 0)
        return cm_fail(err, CM_ERR_STATE, "fem solver: every dof is fixed");
    cholmod_sparse *sub = cholmod_submatrix(s->K, s->free_dofs, s->n_free, s->free_dofs, s->n_free, 1, 1, &s->cc);
    if (!sub)
        return cholmod_failed(s, err, "submatrix");
    s->Kff = cholmod_copy(sub, 1, 1, &s->cc); /* upper triangle, symmetric */
    cholmod_free_sparse(&sub, &s->cc);
    s->rhs = cholmod_zeros((size_t)s->n_free, 1, CHOLMOD_REAL, &s->cc);
    if (!s->Kff || !s->rhs)
        return cholmod_failed(s, err, "copy");
    fem_solver_set_state(s, NULL, NULL);
    return CM_OK;
}

int fem_solver_constrain_rim(fem_solver *s, const fem_mesh *m, cm_error *err)
{
    memset(s->fixed, 0, (size_t)s->n_dof);
    int n_rim = 0;
    for (int i = 0; i < m->n_nodes; i++)
        if (m->node_tag[i] & FEM_NODE_RIM) {
            s->fixed[3 * i] = s->fixed[3 * i + 1] = s->fixed[3 * i + 2] = 1;
            n_rim++;
        }
    if (n_rim == 0)
        return cm_fail(err, CM_ERR_STATE, "%s: no rim nodes: the stiffness matrix would be singular", m->source);
    return fem_solver_constrain(s, s->fixed, NULL, err);
}

void fem_solver_matvec(const fem_solver *s, const double *x, double *y)
{
    /* K is symmetric and stored whole: column j read as row j (gather) */
    FEM_OMP_FOR
    for (int n = 0; n < s->n_dof / 3; n++)
        block_row(s, n, x, y + 3 * n);
}

static double dot_free(const fem_solver *s, const double *a, const double *b)
{
    double acc = 0.0; /* serial: the same sum for any thread count */
    for (int k = 0; k < s->n_free; k++) {
        int d = s->free_dofs[k];
        acc += a[d] * b[d];
    }
    return acc;
}

/* The Cholesky factor of Kff, made once per constraint set. */
static int ensure_factor(fem_solver *s, cm_error *err)
{
    if (!s->L) {
        s->L = cholmod_analyze(s->Kff, &s->cc);
        if (!s->L)
            return cholmod_failed(s, err, "analyze");
        if (!cholmod_factorize(s->Kff, s->L, &s->cc) || s->cc.status != CHOLMOD_OK) {
            int rc = cm_fail(err, CM_ERR_NUMERIC,
                             "fem solver: K not positive definite (CHOLMOD status %d, column %d of %d): "
                             "rigid-body mode not fixed?", s->cc.status, (int)s->L->minor, s->n_free);
            cholmod_free_factor(&s->L, &s->cc);
            return rc;
        }
    }
    return CM_OK;
}

int fem_solver_solve_free(fem_solver *s, int ncol, const double *b, double *x, cm_error *err)
{
    int rc = ensure_factor(s, err);
    if (rc)
        return rc;
    const size_t n = (size_t)s->n_dof, nf = (size_t)s->n_free;
    cholmod_dense *B = cholmod_zeros(nf, (size_t)ncol, CHOLMOD_REAL, &s->cc);
    if (!B)
        return cholmod_failed(s, err, "dense");
    double *bx = B->x;
    for (int c = 0; c < ncol; c++)
        for (size_t k = 0; k < nf; k++)
            bx[(size_t)c * nf + k] = b[(size_t)c * n + (size_t)s->free_dofs[k]];
    cholmod_dense *X = cholmod_solve(CHOLMOD_A, s->L, B, &s->cc);
    cholmod_free_dense(&B, &s->cc);
    if (!X)
        return cholmod_failed(s, err, "solve");
    const double *xx = X->x;
    memset(x, 0, n * (size_t)ncol * sizeof *x);
    for (int c = 0; c < ncol; c++)
        for (size_t k = 0; k < nf; k++)
            x[(size_t)c * n + (size_t)s->free_dofs[k]] = xx[(size_t)c * nf + k];
    cholmod_free_dense(&X, &s->cc);
    return CM_OK;
}

/* Direct solve of the free block: x_f = Kff^-1 r_f (eq. of sect. 3.3). */
static int static_cholmod(fem_solver *s, const double *r, double *du, cm_error *err)
{
    int rc = ensure_factor(s, err);
    if (rc)
        return rc;
    double *b = s->rhs->x;
    for (int k = 0; k < s->n_free; k++)
        b[k] = r[s->free_dofs[k]];
    if (!cholmod_solve2(CHOLMOD_A, s->L, s->rhs, NULL, &s->sol, NULL, &s->Y, &s->E, &s->cc))
        return cholmod_failed(s, err, "solve");
    const double *x = s->sol->x;
    memset(du, 0, (size_t)s->n_dof * sizeof *du);
    for (int k = 0; k < s->n_free; k++)
        du[s->free_dofs[k]] = x[k];
    return CM_OK;
}

/* Jacobi-preconditioned conjugate gradients on the free dofs (the paper's
 * choice, sect. 3.4). Vectors are full-length with zeros on fixed dofs. */
static int static_cg(fem_solver *s, const double *r0, double tol, int max_iter, double *x, int *iters,
                     cm_error *err)
{
    size_t n = (size_t)s->n_dof;
    double *r = malloc(n * sizeof *r), *z = malloc(n * sizeof *z), *p = malloc(n * sizeof *p),
           *q = malloc(n * sizeof *q), *dinv = calloc(n, sizeof *dinv);
    int rc = CM_OK;
    if (!r || !z || !p || !q || !dinv) {
        rc = cm_fail(err, CM_ERR_NOMEM, "fem solver: CG out of memory");
        goto done;
    }
    const int *Kp = s->K->p, *Ki = s->K->i;
    const double *Kx = s->K->x;
    for (int d = 0; d < s->n_dof; d++) {
        x[d] = 0.0;
        r[d] = s->fixed[d] ? 0.0 : r0[d];
        for (int k = Kp[d]; k < Kp[d + 1]; k++)
            if (Ki[k] == d)
                dinv[d] = s->fixed[d] ? 0.0 : 1.0 / Kx[k];
        z[d] = dinv[d] * r[d];
        p[d] = z[d];
    }
    double bnorm = sqrt(dot_free(s, r, r)), rz = dot_free(s, r, z);
    if (max_iter <= 0)
        max_iter = 10 * s->n_free;
    int it = 0;
    double rnorm = bnorm;
    while (rnorm > tol * bnorm && it < max_iter) {
        fem_solver_matvec(s, p, q);
        for (int d = 0; d < s->n_dof; d++)
            if (s->fixed[d])
                q[d] = 0.0;
        double pq = dot_free(s, p, q);
        if (!(pq > 0.0)) {
            rc = cm_fail(err, CM_ERR_NUMERIC, "fem solver: CG breakdown (p^T K p = %.3g at iteration %d): K not "
                         "positive definite on the free dofs", pq, it);
            goto done;
        }
        double al = rz / pq;
        for (int d = 0; d < s->n_dof; d++) {
            x[d] += al * p[d];
            r[d] -= al * q[d];
            z[d] = dinv[d] * r[d];
        }
        double rz_new = dot_free(s, r, z);
        double be = rz_new / rz;
        rz = rz_new;
        for (int d = 0; d < s->n_dof; d++)
            p[d] = z[d] + be * p[d];
        rnorm = sqrt(dot_free(s, r, r));
        it++;
    }
    if (iters)
        *iters = it;
    if (rnorm > tol * bnorm)
        rc = cm_fail(err, CM_ERR_NUMERIC, "fem solver: CG did not converge in %d iterations (|r|/|b| = %.3g > %.3g)",
                     it, rnorm / bnorm, tol);
done:
    free(r);
    free(z);
    free(p);
    free(q);
    free(dinv);
    return rc;
}

int fem_solver_static(fem_solver *s, const double *b, fem_linear_solver kind, double tol, int max_iter,
                      double *u, int *iters, cm_error *err)
{
    s->ku_valid = 0;
    /* K u = b with u = u_c on fixed dofs: K_ff du_f = b_f - (K u_c)_f */
    double *r = s->w;
    fem_solver_matvec(s, s->u_fixed, s->tmp);
    for (int d = 0; d < s->n_dof; d++)
        r[d] = s->fixed[d] ? 0.0 : b[d] - s->tmp[d];
    /* No load on the free dofs: u = u_c exactly, and K need not be
     * factorized (29 s for a 165 000-tet mesh); iters = 0 says so. */
    bool loaded = false;
    for (int d = 0; d < s->n_dof && !loaded; d++)
        loaded = r[d] != 0.0;
    int rc;
    if (!loaded) {
        memset(s->tmp, 0, (size_t)s->n_dof * sizeof *s->tmp);
        if (iters)
            *iters = 0;
        rc = CM_OK;
    } else if (kind == FEM_LINEAR_CHOLMOD) {
        rc = static_cholmod(s, r, s->tmp, err);
        if (iters)
            *iters = 1;
    } else {
        rc = static_cg(s, r, tol, max_iter, s->tmp, iters, err);
    }
    if (rc)
        return rc;
    for (int d = 0; d < s->n_dof; d++)
        u[d] = s->fixed[d] ? s->u_fixed[d] : s->tmp[d];
    return CM_OK;
}

int fem_solver_stability(fem_solver *s, const fem_mesh *m, int max_power_iter, fem_stability *st, cm_error *err)
{
    memset(st, 0, sizeof *st);
    fem_mesh_measure(m, &st->h_min, NULL);
    st->wave_speed = sqrt((s->lambda + 2.0 * s->mu) / s->rho);
    st->dt_estimate = st->h_min / st->wave_speed;

    /* Gershgorin: lambda_max(M^-1 K) <= max_i sum_j |K_ij| / m_i (free rows
     * and columns; M^-1 K is similar to M^-1/2 K M^-1/2). */
    const int *Kp = s->K->p, *Ki = s->K->i;
    const double *Kx = s->K->x;
    double gmax = 0.0;
    for (int k = 0; k < s->n_free; k++) {
        int d = s->free_dofs[k];
        double acc = 0.0;
        for (int p = Kp[d]; p < Kp[d + 1]; p++)
            if (!s->fixed[Ki[p]])
                acc += fabs(Kx[p]) / sqrt(s->mass[d] * s->mass[Ki[p]]);
        gmax = acc > gmax ? acc : gmax;
    }
    st->dt_gershgorin = 2.0 / sqrt(gmax);

    /* Power iteration on A = M^-1/2 K M^-1/2 (free dofs), whose eigenvalues
     * are omega^2. The Rayleigh quotient rises monotonically towards
     * omega_max^2. Start: alternating signs (the highest modes are the most
     * oscillatory) plus a deterministic perturbation. */
    double *x = s->w, *y = s->tmp;
    uint32_t seed = 12345u;
    for (int d = 0; d < s->n_dof; d++) {
        seed = seed * 1664525u + 1013904223u;
        double rnd = (double)(seed >> 8) / 16777216.0 - 0.5;
        x[d] = s->fixed[d] ? 0.0 : ((d / 3 + d) % 2 ? 1.0 : -1.0) + 0.5 * rnd;
    }
    double nx = sqrt(dot_free(s, x, x)), rq = 0.0, rq_old = 0.0;
    int it;
    if (max_power_iter < 1)
        max_power_iter = 1;
    for (it = 0; it < max_power_iter; it++) {
        for (int d = 0; d < s->n_dof; d++)
            x[d] = s->fixed[d] ? 0.0 : x[d] / (nx * sqrt(s->mass[d]));
        fem_solver_matvec(s, x, y);
        for (int d = 0; d < s->n_dof; d++) {
            y[d] = s->fixed[d] ? 0.0 : y[d] / sqrt(s->mass[d]);
            x[d] *= sqrt(s->mass[d]); /* back to the unit vector */
        }
        rq = dot_free(s, x, y);
        nx = sqrt(dot_free(s, y, y));
        if (!(nx > 0.0))
            return cm_fail(err, CM_ERR_NUMERIC, "fem solver: power iteration broke down");
        memcpy(x, y, (size_t)s->n_dof * sizeof *x);
        if (it > 20 && fabs(rq - rq_old) < 1e-9 * rq)
            break;
        rq_old = rq;
    }
    st->power_iterations_done = it < max_power_iter ? it + 1 : max_power_iter;
    double w = sqrt(rq);
    st->dt_power = 2.0 / w;
    /* Damped central differences: dt <= (2/w)(sqrt(1+xi^2) - xi) with the
     * modal damping ratio xi = alpha/(2w) + beta w/2 of the highest mode. */
    double xi = 0.5 * (s->alpha / w + s->beta * w);
    st->dt_limit = st->dt_power * (sqrt(1.0 + xi * xi) - xi);
    memset(s->w, 0, (size_t)s->n_dof * sizeof(double));
    return CM_OK;
}

int fem_solver_use_neo_hookean(fem_solver *s, const fem_mesh *m, cm_error *err)
{
    if (s->integrator == FEM_INTEGRATOR_NEWMARK)
        return cm_fail(err, CM_ERR_STATE, "fem solver: Neo-Hookean rubber needs the explicit integrator");
    if (m->tet_mid)
        return cm_fail(err, CM_ERR_STATE, "%s: fem.material.model = \"neo_hookean\" is implemented for "
                       "fem.element = \"tet4\" only", m->source);
    size_t nt = (size_t)m->n_tets;
    s->tets = malloc(4 * nt * sizeof *s->tets);
    s->grad0 = malloc(nt * sizeof *s->grad0);
    s->vol0 = malloc(nt * sizeof *s->vol0);
    if (!s->tets || !s->grad0 || !s->vol0)
        return cm_fail(err, CM_ERR_NOMEM, "fem solver: out of memory for %d elements", m->n_tets);
    memcpy(s->tets, m->tets, 4 * nt * sizeof *s->tets);
    for (size_t e = 0; e < nt; e++) {
        const int32_t *t = &m->tets[4 * e];
        s->vol0[e] = fem_tet_gradients(&m->x[3 * t[0]], &m->x[3 * t[1]], &m->x[3 * t[2]], &m->x[3 * t[3]],
                                       s->grad0[e]);
    }
    s->n_tets = m->n_tets;
    s->nh = true;
    return CM_OK;
}

/* y = internal forces of the displacement u under the Neo-Hookean law
 * (element loop, scattered in element order: the same sum every run). */
static void nh_internal_force(fem_solver *s, const double *u, double *y)
{
    memset(y, 0, (size_t)s->n_dof * sizeof(double));
    for (int e = 0; e < s->n_tets; e++) {
        const int32_t *t = &s->tets[4 * e];
        double ue[4][3], fe[4][3];
        for (int a = 0; a < 4; a++)
            for (int i = 0; i < 3; i++)
                ue[a][i] = u[3 * t[a] + i];
        if (!(fem_tet_internal_force_nh(s->grad0[e], s->vol0[e], ue, s->lambda, s->mu, fe) > 0)) {
            s->nh_inverted++; /* the element guard names it; its forces are left out meanwhile */
            continue;
        }
        for (int a = 0; a < 4; a++)
            for (int i = 0; i < 3; i++)
                y[3 * t[a] + i] += fe[a][i];
    }
}

/* y += beta K x (Rayleigh stiffness damping on the small-strain K), K x
 * in s->ku: the Neo-Hookean step leaves no K u there (ku_valid stays 0). */
static void add_beta_k(fem_solver *s, const double *x, double *y)
{
    if (s->beta == 0.0)
        return;
    fem_solver_matvec(s, x, s->ku);
    for (int r = 0; r < s->n_dof; r++)
        y[r] += s->beta * s->ku[r];
}

void fem_solver_set_state(fem_solver *s, const double *u, const double *v)
{
    s->ku_valid = 0;
    for (int d = 0; d < s->n_dof; d++) {
        s->u[d] = s->fixed[d] ? s->u_fixed[d] : (u ? u[d] : 0.0);
        s->v[d] = s->fixed[d] || !v ? 0.0 : v[d];
        s->w[d] = s->u[d] + s->beta * s->v[d];
    }
    /* a = M^-1 (f - K (u + beta v) - alpha M v) */
    if (s->nh) {
        nh_internal_force(s, s->u, s->tmp);
        add_beta_k(s, s->v, s->tmp);
    } else {
        fem_solver_matvec(s, s->w, s->tmp);
    }
    for (int d = 0; d < s->n_dof; d++)
        s->a[d] = s->inv_mass[d] * (s->f[d] - s->tmp[d]) - s->alpha * (s->fixed[d] ? 0.0 : s->v[d]);
    memcpy(s->f_applied, s->f, (size_t)s->n_dof * sizeof *s->f);
    s->h_last = 0.0; /* the state is not the end of a step: no half-kick to correct */
}

/* A load held over each interval acts from the interval's start: the force
 * at time t_n is the new f, so that central differences read
 * m (u+ - 2u + u-) / h^2 = f(t_n) - K u(t_n). The state at t_n was closed
 * with the previous load: the acceleration jumps by M^-1 (f - f_applied),
 * and (explicit) the closing half-kick v(t_n) = v(t_n - h/2) + h/2 a(t_n)
 * takes the same correction. Without it the interval's first half-kick used
 * the previous load, a force acting one sub-step late, which on a contact
 * spring k is a negative damper -k h: it pumped energy into the light
 * surface nodes of a finely meshed block (tests/coupling/block, 1 mm). */
void fem_solver_load_changed(fem_solver *s)
{
    const double *im = s->inv_mass;
    const double hv = s->integrator == FEM_INTEGRATOR_EXPLICIT ? 0.5 * s->h_last : 0.0;
    for (int d = 0; d < s->n_dof; d++) {
        double da = im[d] * (s->f[d] - s->f_applied[d]);
        s->a[d] += da;
        s->v[d] += hv * da;
        s->f_applied[d] = s->f[d];
    }
}

int fem_solver_prepare(fem_solver *s, fem_integrator integ, double h, cm_error *err)
{
    s->integrator = integ;
    if (integ != FEM_INTEGRATOR_NEWMARK)
        return CM_OK;
    if (!(h > 0.0))
        return cm_fail(err, CM_ERR_RANGE, "fem solver: Newmark step must be positive (%g)", h);
    if (s->Leff && s->h_eff == h)
        return CM_OK;
    /* K_eff = K + (2/h) C + (4/h^2) M, C = alpha M + beta K (average
     * acceleration: beta_N = 1/4, gamma_N = 1/2). M is diagonal, Kff upper
     * with sorted columns: the diagonal is the last entry of each column. */
    cholmod_sparse *Ke = cholmod_copy_sparse(s->Kff, &s->cc);
    if (!Ke)
        return cholmod_failed(s, err, "copy_sparse");
    double ck = 1.0 + 2.0 * s->beta / h, cm = 4.0 / (h * h) + 2.0 * s->alpha / h;
    const int *p = Ke->p, *ri = Ke->i;
    double *x = Ke->x;
    for (int j = 0; j < s->n_free; j++) {
        int diag = -1;
        for (int q = p[j]; q < p[j + 1]; q++) {
            x[q] *= ck;
            if (ri[q] == j)
                diag = q;
        }
        if (diag < 0) {
            cholmod_free_sparse(&Ke, &s->cc);
            return cm_fail(err, CM_ERR_NUMERIC, "fem solver: missing diagonal in K (free dof %d)", j);
        }
        x[diag] += cm * s->mass[s->free_dofs[j]];
    }
    if (!s->Leff) {
        s->Leff = cholmod_analyze(Ke, &s->cc);
        if (!s->Leff) {
            cholmod_free_sparse(&Ke, &s->cc);
            return cholmod_failed(s, err, "analyze");
        }
    }
    int ok = cholmod_factorize(Ke, s->Leff, &s->cc);
    cholmod_free_sparse(&Ke, &s->cc);
    if (!ok || s->cc.status != CHOLMOD_OK)
        return cm_fail(err, CM_ERR_NUMERIC, "fem solver: K_eff factorization failed (status %d, column %d)",
                       s->cc.status, (int)s->Leff->minor);
    s->h_eff = h;
    /* One solve now so that the solve workspaces exist before the loop. */
    if (!cholmod_solve2(CHOLMOD_A, s->Leff, s->rhs, NULL, &s->sol, NULL, &s->Y, &s->E, &s->cc))
        return cholmod_failed(s, err, "solve");
    return CM_OK;
}

/* Explicit central differences (eq. 32) in velocity-Verlet form, which for a
 * constant step is algebraically eq. 32, u+ = 2u - u- + dt^2 M^-1 (b - K u),
 * and keeps velocities at whole steps for the interface:
 *   v+1/2 = v + h/2 a;  u+ = u + h v+1/2;
 *   a+ = M^-1 (f - K (u+ + beta v+1/2)) - alpha v+1/2;  v+ = v+1/2 + h/2 a+
 * (Rayleigh damping uses the half-step velocity, lagged as usual). */
static void step_explicit(fem_solver *s, double h)
{
    int n = s->n_dof;
    double *u = s->u, *v = s->v, *a = s->a, *w = s->beta != 0.0 ? s->w : s->u;
    const double *f = s->f, *im = s->inv_mass;
    const double hh = 0.5 * h, beta = s->beta, alpha = s->alpha;
    FEM_OMP_FOR
    for (int d = 0; d < n; d++) {
        v[d] += hh * a[d];
        u[d] += h * v[d];
        if (beta != 0.0)
            s->w[d] = u[d] + beta * v[d];
    }
    double *kw = s->ku; /* the internal forces: K w, or the Neo-Hookean ones (and beta K v) */
    if (s->nh) {
        nh_internal_force(s, u, s->tmp);
        add_beta_k(s, v, s->tmp);
        kw = s->tmp;
    } else {
        fem_solver_matvec(s, w, kw);
    }
    FEM_OMP_FOR
    for (int r = 0; r < n; r++) {
        double ar = im[r] * (f[r] - kw[r]) - (im[r] != 0.0 ? alpha * v[r] : 0.0); /* eq. 32 */
        a[r] = ar;
        v[r] += hh * ar;
    }
    s->ku_valid = !s->nh && beta == 0.0; /* w is u: kw is K u */
}

/* Newmark average acceleration in increments: with du = u+ - u,
 *   K_eff du = f+ - K (u - beta v) + M (4/h v + a + alpha v)   (C = aM + bK)
 *   a+ = 4/h^2 du - 4/h v - a;   v+ = 2/h du - v. */
static int step_newmark(fem_solver *s, double h, cm_error *err)
{
    int n = s->n_dof;
    double *u = s->u, *v = s->v, *a = s->a;
    for (int d = 0; d < n; d++)
        s->w[d] = u[d] - s->beta * v[d];
    fem_solver_matvec(s, s->w, s->tmp);
    double *b = s->rhs->x;
    for (int k = 0; k < s->n_free; k++) {
        int d = s->free_dofs[k];
        b[k] = s->f[d] - s->tmp[d] + s->mass[d] * (4.0 / h * v[d] + a[d] + s->alpha * v[d]);
    }
    if (!cholmod_solve2(CHOLMOD_A, s->Leff, s->rhs, NULL, &s->sol, NULL, &s->Y, &s->E, &s->cc))
        return cholmod_failed(s, err, "solve");
    const double *du = s->sol->x;
    for (int k = 0; k < s->n_free; k++) {
        int d = s->free_dofs[k];
        double an = 4.0 / (h * h) * du[k] - 4.0 / h * v[d] - a[d];
        v[d] = 2.0 / h * du[k] - v[d];
        a[d] = an;
        u[d] += du[k];
    }
    return CM_OK;
}

int fem_solver_step(fem_solver *s, double h, cm_error *err)
{
    int rc = CM_OK;
    s->ku_valid = 0; /* step_explicit sets it again where it leaves K u */
    switch (s->integrator) {
    case FEM_INTEGRATOR_EXPLICIT:
        step_explicit(s, h);
        s->h_last = h;
        break;
    case FEM_INTEGRATOR_NEWMARK:
        if (s->nh)
            return cm_fail(err, CM_ERR_STATE, "fem solver: Neo-Hookean rubber needs the explicit integrator");
        if (!s->Leff || s->h_eff != h)
            return cm_fail(err, CM_ERR_STATE, "fem solver: Newmark step %g s not prepared (have %g s)", h, s->h_eff);
        rc = step_newmark(s, h, err);
        break;
    case FEM_INTEGRATOR_RIGID:
        break;
    }
    s->time += h;
    s->steps++;
    return rc;
}

double fem_solver_elastic_energy(const fem_solver *s)
{
    if (s->nh) {
        double acc = 0.0;
        for (int e = 0; e < s->n_tets; e++) {
            const int32_t *t = &s->tets[4 * e];
            double F[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
            for (int a = 0; a < 4; a++)
                for (int i = 0; i < 3; i++)
                    for (int k = 0; k < 3; k++)
                        F[i][k] += s->u[3 * t[a] + i] * s->grad0[e][a][k];
            double W = fem_neo_hookean_energy(F, s->lambda, s->mu);
            acc += isfinite(W) ? s->vol0[e] * W : 0.0;
        }
        return acc;
    }
    const double *ku = s->ku;
    if (!s->ku_valid) { /* the explicit step did not leave it: the product */
        fem_solver_matvec(s, s->u, s->tmp);
        ku = s->tmp;
    }
    double acc = 0.0;
    for (int d = 0; d < s->n_dof; d++)
        acc += s->u[d] * ku[d];
    return 0.5 * acc;
}

double fem_solver_kinetic_energy(const fem_solver *s)
{
    double acc = 0.0;
    for (int d = 0; d < s->n_dof; d++)
        acc += s->mass[d] * s->v[d] * s->v[d];
    return 0.5 * acc;
}

void fem_solver_energies(const fem_solver *s, const double *load, double e[3])
{
    const int n = s->n_dof;
    const double *restrict u = s->u, *restrict v = s->v, *restrict mass = s->mass, *restrict ku = s->ku;
    double acc_e = 0.0, acc_k = 0.0, acc_l = 0.0;
    if (!s->nh && s->ku_valid && load) {
        /* the three sums of fem_solver_elastic_energy, _kinetic_energy and
         * load^T u, each in its order, in one loop: each add waits only
         * for its own sum (three passes waited for one chain at a time) */
        for (int d = 0; d < n; d++) {
            acc_e += u[d] * ku[d];
            acc_k += mass[d] * v[d] * v[d];
            acc_l += load[d] * u[d];
        }
        e[0] = 0.5 * acc_e;
        e[1] = 0.5 * acc_k;
        e[2] = acc_l;
        return;
    }
    for (int d = 0; load && d < n; d++)
        acc_l += load[d] * u[d];
    e[0] = fem_solver_elastic_energy(s);
    e[1] = fem_solver_kinetic_energy(s);
    e[2] = acc_l;
}
