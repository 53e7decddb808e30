/* Supports and dead loads by named set (issue 16 item 0b): the scene keys
 * fem.supports and fem.loads (fem_config.c), applied by fem_create. */
#include "fem_bc.h"

#include "fem_model.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

const char *const fem_set_names[FEM_SET_COUNT + 1] = {"rim",  "cavity", "contact", "xmin", "xmax", "ymin",
                                                      "ymax", "zmin",   "zmax",    NULL};

/* Bounding-box planes: a node lies on one within 1e-9 of the box's diagonal. */
typedef struct planes {
    double lo[3], hi[3], tol;
} planes;

static planes box_planes(const fem_mesh *m)
{
    planes p;
    for (int a = 0; a < 3; a++)
        p.lo[a] = INFINITY, p.hi[a] = -INFINITY;
    for (int n = 0; n < m->n_nodes; n++)
        for (int a = 0; a < 3; a++) {
            p.lo[a] = fmin(p.lo[a], m->x[3 * n + a]);
            p.hi[a] = fmax(p.hi[a], m->x[3 * n + a]);
        }
    double d = 0;
    for (int a = 0; a < 3; a++)
        d += (p.hi[a] - p.lo[a]) * (p.hi[a] - p.lo[a]);
    p.tol = 1e-9 * sqrt(d);
    return p;
}

static bool node_on_plane(const fem_mesh *m, const planes *p, fem_set set, int n)
{
    int k = set - FEM_SET_XMIN, a = k / 2;
    double target = k % 2 ? p->hi[a] : p->lo[a];
    return fabs(m->x[3 * n + a] - target) <= p->tol;
}

static bool face_in(const fem_mesh *m, const planes *p, fem_set set, int f)
{
    switch (set) {
    case FEM_SET_RIM: return m->face_tag[f] & FEM_FACE_RIM;
    case FEM_SET_CAVITY: return m->face_tag[f] & FEM_FACE_CAVITY;
    case FEM_SET_CONTACT: return m->face_tag[f] & FEM_FACE_CONTACT;
    default:
        for (int q = 0; q < 3; q++)
            if (!node_on_plane(m, p, set, m->faces[3 * f + q]))
                return false;
        return true;
    }
}

/* Marks in[n] for the nodes of a set: rim's tagged nodes, the nodes of a
 * face set's faces, the nodes on a plane. Returns their count. */
static int set_nodes(const fem_mesh *m, const planes *p, fem_set set, uint8_t *in)
{
    memset(in, 0, (size_t)m->n_nodes);
    if (set == FEM_SET_RIM) {
        for (int n = 0; n < m->n_nodes; n++)
            in[n] = (m->node_tag[n] & FEM_NODE_RIM) != 0;
    } else if (set >= FEM_SET_XMIN) {
        for (int n = 0; n < m->n_nodes; n++)
            in[n] = node_on_plane(m, p, set, n);
    } else {
        for (int f = 0; f < m->n_faces; f++)
            if (face_in(m, p, set, f)) {
                int32_t nd[6];
                int nn = fem_mesh_face_nodes(m, f, nd); /* with the mid-edge nodes of 10-node elements */
                for (int q = 0; q < nn; q++)
                    in[nd[q]] = 1;
            }
    }
    int count = 0;
    for (int n = 0; n < m->n_nodes; n++)
        count += in[n];
    return count;
}

int fem_bc_constrain(fem_solver *s, const fem_mesh *m, const fem_config *cfg, cm_error *err)
{
    if (cfg->n_supports == 0)
        return fem_solver_constrain_rim(s, m, err);
    planes p = box_planes(m);
    uint8_t *in = malloc((size_t)m->n_nodes);
    double *values = calloc((size_t)s->n_dof, sizeof *values);
    if (!in || !values) {
        free(in);
        free(values);
        return cm_fail(err, CM_ERR_NOMEM, "fem: out of memory");
    }
    memset(s->fixed, 0, (size_t)s->n_dof);
    int rc = CM_OK;
    for (int k = 0; k < cfg->n_supports && !rc; k++) {
        const fem_support *sp = &cfg->supports[k];
        if (set_nodes(m, &p, sp->set, in) == 0)
            rc = cm_fail(err, CM_ERR_RANGE, "%s: fem.supports.[%d]: the set %s has no nodes", m->source, k,
                         fem_set_names[sp->set]);
        for (int n = 0; n < m->n_nodes && !rc; n++)
            for (int a = 0; a < 3; a++)
                if (in[n] && sp->fix[a]) {
                    s->fixed[3 * n + a] = 1;
                    values[3 * n + a] = sp->value[a]; /* a later support on the same dof wins */
                }
    }
    if (!rc)
        rc = fem_solver_constrain(s, s->fixed, values, err);
    free(in);
    free(values);
    return rc;
}

int fem_bc_loads(const fem_mesh *m, const fem_config *cfg, double *f, cm_error *err)
{
    if (cfg->n_loads == 0)
        return CM_OK;
    planes p = box_planes(m);
    uint8_t *in = malloc((size_t)m->n_nodes);
    if (!in)
        return cm_fail(err, CM_ERR_NOMEM, "fem: out of memory");
    int rc = CM_OK;
    for (int k = 0; k < cfg->n_loads && !rc; k++) {
        const fem_load *ld = &cfg->loads[k];
        /* The set's faces and their area. */
        double area = 0;
        int faces = 0;
        for (int fc = 0; fc < m->n_faces; fc++) {
            if (!face_in(m, &p, ld->set, fc))
                continue;
            if (m->face_mid) { /* 6-node face: int N_k n dA and int N_k dA per node */
                int32_t nd[6];
                double an[6][3], aw[6];
                int nn = fem_mesh_face_nodes(m, fc, nd);
                fem_mesh_face_load(m, fc, an, aw);
                for (int q = 0; q < nn; q++) {
                    area += aw[q];
                    for (int d = 0; d < 3; d++)
                        f[3 * nd[q] + d] += ld->type == FEM_LOAD_PRESSURE ? -ld->value[0] * an[q][d]
                                            : ld->type == FEM_LOAD_TRACTION ? ld->value[d] * aw[q] : 0.0;
                }
                faces++;
                continue;
            }
            const int32_t *t = &m->faces[3 * fc];
            const double *a = &m->x[3 * t[0]], *b = &m->x[3 * t[1]], *c = &m->x[3 * t[2]];
            double e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
            double an[3] = {0.5 * (e1[1] * e2[2] - e1[2] * e2[1]), 0.5 * (e1[2] * e2[0] - e1[0] * e2[2]),
                            0.5 * (e1[0] * e2[1] - e1[1] * e2[0])}; /* A n, outward */
            area += sqrt(an[0] * an[0] + an[1] * an[1] + an[2] * an[2]);
            faces++;
            /* consistent load of a constant traction on a linear triangle: A t / 3 per node */
            double tr[3];
            for (int d = 0; d < 3; d++)
                tr[d] = ld->type == FEM_LOAD_PRESSURE ? -ld->value[0] * an[d]
                                                      : ld->value[d] * sqrt(an[0] * an[0] + an[1] * an[1] + an[2] * an[2]);
            if (ld->type == FEM_LOAD_FORCE)
                continue; /* scaled once the area is known, below */
            for (int q = 0; q < 3; q++)
                for (int d = 0; d < 3; d++)
                    f[3 * t[q] + d] += tr[d] / 3.0;
        }
        if (ld->type != FEM_LOAD_FORCE)
            rc = faces ? CM_OK
                       : cm_fail(err, CM_ERR_RANGE, "%s: fem.loads.[%d]: the set %s has no boundary faces to carry a %s",
                                 m->source, k, fem_set_names[ld->set],
                                 ld->type == FEM_LOAD_PRESSURE ? "pressure" : "traction");
        else if (faces > 0) { /* a total force: the uniform traction F / A over the faces */
            for (int fc = 0; fc < m->n_faces; fc++) {
                if (!face_in(m, &p, ld->set, fc))
                    continue;
                if (m->face_mid) {
                    int32_t nd[6];
                    double an[6][3], aw[6];
                    int nn = fem_mesh_face_nodes(m, fc, nd);
                    fem_mesh_face_load(m, fc, an, aw);
                    for (int q = 0; q < nn; q++)
                        for (int d = 0; d < 3; d++)
                            f[3 * nd[q] + d] += ld->value[d] * aw[q] / area;
                    continue;
                }
                const int32_t *t = &m->faces[3 * fc];
                const double *a = &m->x[3 * t[0]], *b = &m->x[3 * t[1]], *c = &m->x[3 * t[2]];
                double e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
                double an[3] = {0.5 * (e1[1] * e2[2] - e1[2] * e2[1]), 0.5 * (e1[2] * e2[0] - e1[0] * e2[2]),
                                0.5 * (e1[0] * e2[1] - e1[1] * e2[0])};
                double A = sqrt(an[0] * an[0] + an[1] * an[1] + an[2] * an[2]);
                for (int q = 0; q < 3; q++)
                    for (int d = 0; d < 3; d++)
                        f[3 * t[q] + d] += ld->value[d] * A / area / 3.0;
            }
        } else { /* a node set without faces (rim nodes): equal shares */
            int n_in = set_nodes(m, &p, ld->set, in);
            if (n_in == 0)
                rc = cm_fail(err, CM_ERR_RANGE, "%s: fem.loads.[%d]: the set %s has no nodes", m->source, k,
                             fem_set_names[ld->set]);
            for (int n = 0; n < m->n_nodes && !rc; n++)
                if (in[n])
                    for (int d = 0; d < 3; d++)
                        f[3 * n + d] += ld->value[d] / n_in;
        }
    }
    free(in);
    return rc;
}

/* ---- fem.floor: a rigid frictionless floor, kinematic ------------------------------------------------- */

typedef struct floor_ctx {
    fem_model *m;
    uint8_t *cand, *active;  /* per node: of the floor set; held on the plane */
    uint8_t *base_fixed;     /* per dof: the supports */
    double *base_val, *val;  /* per dof: their values; this solve's */
    double *r;               /* per dof: K u - b */
    double zmin;             /* m, the set's lowest z without the floor (fem_floor_result.z_free) */
    int solves, factorizations;
    /* The influence method (default): K factorized once with the supports only. */
    bool influence;
    double *u0;              /* per dof: the solution without the floor */
    int n_cand;
    int32_t *cand_node;      /* candidate index -> node */
    int32_t *cand_of;        /* node -> candidate index, -1 */
    int32_t *col_of;         /* node -> its influence column, -1: not solved yet */
    int n_col, cap_col;
    double *G;               /* n_col columns of n_cand: (K^-1 e_z(node of column))_z at every candidate */
    int32_t *act;            /* the held nodes of a pass, in node order */
    double *S, *lam, *zc;    /* the dense |A| x |A| system, the reactions, z of every candidate */
    int cap_act;
} floor_ctx;

static int floor_oom(cm_error *err)
{
    return cm_fail(err, CM_ERR_NOMEM, "fem.floor: out of memory");
}

/* The reference method: the static state with the floor at `height`: the
 * active set (nodes held at z = height) grows by the free nodes found below
 * the plane and loses the held nodes the plane pulls (K u - b < 0 in z),
 * until neither happens. Frictionless: only z is held. Each pass
 * refactorizes K_ff (CHOLMOD), or runs CG. */
/* The converged active set's result (both methods). */
static void floor_result_fill(const floor_ctx *c, double height, double reaction, double below, int held, int columns,
                              fem_floor_result *res)
{
    res->height = height;
    res->deflection = height - c->zmin;
    res->z_free = c->zmin;
    res->reaction = reaction;
    res->max_below = below;
    res->contact_nodes = held;
    res->solves = c->solves;
    res->factorizations = c->factorizations;
    res->columns = columns;
}

static int floor_solve_refactor(floor_ctx *c, double height, fem_floor_result *res, cm_error *err)
{
    fem_model *m = c->m;
    fem_solver *s = m->s;
    const int nn = m->mesh.n_nodes, nd = s->n_dof;
    const double tol = 1e-12 * (m->size > 0 ? m->size : 1.0);
    for (int n = 0; n < nn; n++) /* start: the nodes at or below the plane */
        c->active[n] = c->cand[n] && m->mesh.x[3 * n + 2] <= height + tol;
    for (int pass = 0; pass < 200; pass++) {
        memcpy(s->fixed, c->base_fixed, (size_t)nd);
        memcpy(c->val, c->base_val, (size_t)nd * sizeof *c->val);
        for (int n = 0; n < nn; n++)
            if (c->active[n]) {
                s->fixed[3 * n + 2] = 1;
                c->val[3 * n + 2] = height - m->mesh.x[3 * n + 2];
            }
        int rc = fem_solver_constrain(s, s->fixed, c->val, err);
        if (rc)
            return rc;
        fem_model_build_load(m, NULL);
        rc = fem_solver_static(s, s->f, m->cfg.static_solver, m->cfg.cg_tol, m->cfg.cg_max_iter, s->u, NULL, err);
        c->solves++;
        c->factorizations++;
        if (rc)
            return cm_fail_prefix(err, "fem.floor: static solve");
        fem_solver_matvec(s, s->u, c->r);
        int changed = 0;
        double reaction = 0.0, below = 0.0;
        int held = 0;
        for (int n = 0; n < nn; n++) {
            if (!c->cand[n])
                continue;
            int dz = 3 * n + 2;
            double rz = c->r[dz] - s->f[dz], z = m->mesh.x[dz] + s->u[dz];
            if (c->active[n]) {
                if (rz < 0.0) { /* pulled: let go */
                    c->active[n] = 0;
                    changed = 1;
                } else {
                    reaction += rz;
                    held++;
                }
            } else if (z < height - tol) {
                c->active[n] = 1;
                changed = 1;
            } else {
                below = fmax(below, height - z);
            }
        }
        if (!changed) {
            fem_solver_set_state(s, s->u, NULL);
            m->static_done = true;
            floor_result_fill(c, height, reaction, below, held, 0, res);
            return CM_OK;
        }
    }
    return cm_fail(err, CM_ERR_NUMERIC, "fem.floor: the contact set did not settle in 200 passes (floor at z = %.6g m)",
                   height);
}

/* Influence columns for the held nodes that have none yet: K^-1 e_z per
 * node, kept at the candidates' z dofs; solved in batches with the one
 * factor of K. */
static int floor_columns(floor_ctx *c, int n_act, cm_error *err)
{
    fem_solver *s = c->m->s;
    const size_t nd = (size_t)s->n_dof;
    int need = 0;
    for (int k = 0; k < n_act; k++)
        need += c->col_of[c->act[k]] < 0;
    if (need == 0)
        return CM_OK;
    if (c->n_col + need > c->cap_col) {
        int cap = c->cap_col ? c->cap_col : 64;
        while (cap < c->n_col + need)
            cap *= 2;
        double *g = realloc(c->G, (size_t)cap * (size_t)c->n_cand * sizeof *g);
        if (!g)
            return floor_oom(err);
        c->G = g;
        c->cap_col = cap;
    }
    /* at most ~256 MB per right-hand-side block */
    int batch = (int)(32000000 / nd);
    batch = batch < 1 ? 1 : batch > 32 ? 32 : batch;
    double *B = calloc(nd * (size_t)batch, sizeof *B), *X = malloc(nd * (size_t)batch * sizeof *X);
    int32_t *nodes = malloc((size_t)batch * sizeof *nodes);
    int rc = CM_OK;
    if (!B || !X || !nodes)
        rc = floor_oom(err);
    for (int k = 0; k < n_act && !rc;) {
        int nb = 0;
        for (; k < n_act && nb < batch; k++)
            if (c->col_of[c->act[k]] < 0)
                nodes[nb++] = c->act[k];
        if (nb == 0)
            break;
        memset(B, 0, nd * (size_t)nb * sizeof *B);
        for (int q = 0; q < nb; q++)
            B[(size_t)q * nd + 3 * (size_t)nodes[q] + 2] = 1.0;
        if ((rc = fem_solver_solve_free(s, nb, B, X, err)))
            break;
        for (int q = 0; q < nb; q++) {
            double *g = &c->G[(size_t)c->n_col * (size_t)c->n_cand];
            const double *x = &X[(size_t)q * nd];
            for (int i = 0; i < c->n_cand; i++)
                g[i] = x[3 * (size_t)c->cand_node[i] + 2];
            c->col_of[nodes[q]] = c->n_col++;
        }
    }
    free(B);
    free(X);
    free(nodes);
    return rc;
}

/* Cholesky of the n x n SPD matrix S (row-major, in place: lower triangle),
 * then S x = b in place of b. Returns the failing column + 1, 0 on success. */
static int dense_cholesky_solve(int n, double *S, double *b)
{
    for (int j = 0; j < n; j++) {
        double d = S[(size_t)j * n + j];
        for (int k = 0; k < j; k++)
            d -= S[(size_t)j * n + k] * S[(size_t)j * n + k];
        if (!(d > 0.0))
            return j + 1;
        d = sqrt(d);
        S[(size_t)j * n + j] = d;
        for (int i = j + 1; i < n; i++) {
            double v = S[(size_t)i * n + j];
            for (int k = 0; k < j; k++)
                v -= S[(size_t)i * n + k] * S[(size_t)j * n + k];
            S[(size_t)i * n + j] = v / d;
        }
    }
    for (int i = 0; i < n; i++) { /* L y = b */
        double v = b[i];
        for (int k = 0; k < i; k++)
            v -= S[(size_t)i * n + k] * b[k];
        b[i] = v / S[(size_t)i * n + i];
    }
    for (int i = n - 1; i >= 0; i--) { /* L^T x = y */
        double v = b[i];
        for (int k = i + 1; k < n; k++)
            v -= S[(size_t)k * n + i] * b[k];
        b[i] = v / S[(size_t)i * n + i];
    }
    return 0;
}

/* The same active set as floor_solve_refactor, through the influence
 * matrix: with the held nodes A at z = height, u = u0 + sum_j lambda_j
 * K^-1 e_z(j), where G_AA lambda = height - X_z - u0_z on A (lambda: the
 * floor's push on each held node, K u - b in z). Leaves the solver
 * untouched; the state is set by floor_finish. */
static int floor_solve_influence(floor_ctx *c, double height, fem_floor_result *res, cm_error *err)
{
    fem_model *m = c->m;
    const int nn = m->mesh.n_nodes;
    const double *X = m->mesh.x;
    const double tol = 1e-12 * (m->size > 0 ? m->size : 1.0);
    for (int n = 0; n < nn; n++)
        c->active[n] = c->cand[n] && X[3 * n + 2] <= height + tol;
    for (int pass = 0; pass < 200; pass++) {
        int na = 0;
        for (int i = 0; i < c->n_cand; i++)
            if (c->active[c->cand_node[i]])
                c->act[na++] = c->cand_node[i];
        if (na > c->cap_act) {
            int cap = na * 2;
            double *S = realloc(c->S, (size_t)cap * (size_t)cap * sizeof *S), *lam;
            if (!S)
                return floor_oom(err);
            c->S = S;
            if (!(lam = realloc(c->lam, (size_t)cap * sizeof *lam)))
                return floor_oom(err);
            c->lam = lam;
            c->cap_act = cap;
        }
        int rc = floor_columns(c, na, err);
        if (rc)
            return cm_fail_prefix(err, "fem.floor: influence columns");
        c->solves++;
        for (int a = 0; a < na; a++) {
            const double *ga = &c->G[(size_t)c->col_of[c->act[a]] * (size_t)c->n_cand];
            for (int b = 0; b < na; b++)
                c->S[(size_t)a * na + b] = ga[c->cand_of[c->act[b]]];
            int dz = 3 * c->act[a] + 2;
            c->lam[a] = height - X[dz] - c->u0[dz];
        }
        for (int a = 0; a < na; a++) /* symmetric up to round-off: use the mean */
            for (int b = 0; b < a; b++) {
                double v = 0.5 * (c->S[(size_t)a * na + b] + c->S[(size_t)b * na + a]);
                c->S[(size_t)a * na + b] = c->S[(size_t)b * na + a] = v;
            }
        int bad = dense_cholesky_solve(na, c->S, c->lam);
        if (bad)
            return cm_fail(err, CM_ERR_NUMERIC, "fem.floor: the influence matrix of the %d held nodes is not positive "
                           "definite (pivot %d; floor at z = %.6g m)", na, bad, height);
        for (int i = 0; i < c->n_cand; i++)
            c->zc[i] = X[3 * (size_t)c->cand_node[i] + 2] + c->u0[3 * (size_t)c->cand_node[i] + 2];
        for (int a = 0; a < na; a++) {
            const double *ga = &c->G[(size_t)c->col_of[c->act[a]] * (size_t)c->n_cand];
            const double l = c->lam[a];
            for (int i = 0; i < c->n_cand; i++)
                c->zc[i] += ga[i] * l;
        }
        int changed = 0, held = 0, a = 0;
        double reaction = 0.0, below = 0.0;
        for (int i = 0; i < c->n_cand; i++) {
            int n = c->cand_node[i];
            if (c->active[n]) {
                double rz = c->lam[a++];
                if (rz < 0.0) {
                    c->active[n] = 0;
                    changed = 1;
                } else {
                    reaction += rz;
                    held++;
                }
            } else if (c->zc[i] < height - tol) {
                c->active[n] = 1;
                changed = 1;
            } else {
                below = fmax(below, height - c->zc[i]);
            }
        }
        if (!changed) {
            floor_result_fill(c, height, reaction, below, held, c->n_col, res);
            return CM_OK;
        }
    }
    return cm_fail(err, CM_ERR_NUMERIC, "fem.floor: the contact set did not settle in 200 passes (floor at z = %.6g m)",
                   height);
}

static int floor_solve(floor_ctx *c, double height, fem_floor_result *res, cm_error *err)
{
    return c->influence ? floor_solve_influence(c, height, res, err) : floor_solve_refactor(c, height, res, err);
}

/* The influence method's state of the last floor_solve: u = u0 + K^-1
 * E_A lambda (one more solve), then the solver constrained as the
 * reference method leaves it (the held nodes' z fixed at the plane), so
 * that the model after the floor is the same whichever method ran. */
static int floor_finish(floor_ctx *c, double height, cm_error *err)
{
    fem_model *m = c->m;
    fem_solver *s = m->s;
    const int nd = s->n_dof;
    double *b = calloc((size_t)nd, sizeof *b), *x = malloc((size_t)nd * sizeof *x);
    int rc = CM_OK;
    if (!b || !x)
        rc = floor_oom(err);
    int a = 0;
    for (int i = 0; i < c->n_cand && !rc; i++)
        if (c->active[c->cand_node[i]])
            b[3 * (size_t)c->cand_node[i] + 2] = c->lam[a++];
    if (!rc)
        rc = fem_solver_solve_free(s, 1, b, x, err);
    if (!rc) {
        for (int d = 0; d < nd; d++)
            x[d] += c->u0[d];
        memcpy(s->fixed, c->base_fixed, (size_t)nd);
        memcpy(c->val, c->base_val, (size_t)nd * sizeof *c->val);
        for (int i = 0; i < c->n_cand; i++)
            if (c->active[c->cand_node[i]]) {
                int dz = 3 * c->cand_node[i] + 2;
                s->fixed[dz] = 1;
                c->val[dz] = height - m->mesh.x[dz];
                x[dz] = c->val[dz]; /* on the plane exactly, as the reference holds it */
            }
        rc = fem_solver_constrain(s, s->fixed, c->val, err);
    }
    if (!rc) {
        fem_solver_set_state(s, x, NULL);
        m->static_done = true;
    }
    free(b);
    free(x);
    return rc;
}

int fem_floor_static(fem_model *m, fem_floor_result *res, cm_error *err)
{
    const fem_config *cfg = &m->cfg;
    if (!cfg->floor)
        return cm_fail(err, CM_ERR_STATE, "fem_floor_static: no fem.floor in the scene");
    fem_solver *s = m->s;
    const int nn = m->mesh.n_nodes, nd = s->n_dof;
    floor_ctx c = {.m = m};
    c.cand = calloc((size_t)nn, 1);
    c.active = calloc((size_t)nn, 1);
    c.base_fixed = malloc((size_t)nd);
    c.base_val = malloc((size_t)nd * sizeof *c.base_val);
    c.val = malloc((size_t)nd * sizeof *c.val);
    c.r = malloc((size_t)nd * sizeof *c.r);
    int rc = CM_OK;
    double h_final = 0.0;
    if (!c.cand || !c.active || !c.base_fixed || !c.base_val || !c.val || !c.r) {
        rc = floor_oom(err);
        goto done;
    }
    planes p = box_planes(&m->mesh);
    if (set_nodes(&m->mesh, &p, cfg->floor_set, c.cand) == 0) {
        rc = cm_fail(err, CM_ERR_RANGE, "%s: fem.floor.set: the set %s has no nodes", m->mesh.source,
                     fem_set_names[cfg->floor_set]);
        goto done;
    }
    memcpy(c.base_fixed, s->fixed, (size_t)nd);
    memcpy(c.base_val, s->u_fixed, (size_t)nd * sizeof *c.base_val);
    c.zmin = INFINITY;
    for (int n = 0; n < nn; n++)
        if (c.cand[n])
            c.zmin = fmin(c.zmin, m->mesh.x[3 * n + 2]);
    fem_model_build_load(m, NULL);
    if (!cfg->floor_refactor && cfg->static_solver == FEM_LINEAR_CHOLMOD) {
        /* u0: the supports only, K factorized once. A body the floor must hold (K singular without it)
         * cannot: it takes the reference method. */
        cm_error e0 = {0};
        c.u0 = malloc((size_t)nd * sizeof *c.u0);
        if (!c.u0) {
            rc = floor_oom(err);
            goto done;
        }
        if (fem_solver_static(s, s->f, FEM_LINEAR_CHOLMOD, 0.0, 0, c.u0, NULL, &e0) == CM_OK) {
            c.influence = true;
            c.factorizations = 1;
            for (int n = 0; n < nn; n++)
                c.n_cand += c.cand[n];
            c.cand_node = malloc((size_t)c.n_cand * sizeof *c.cand_node);
            c.cand_of = malloc((size_t)nn * sizeof *c.cand_of);
            c.col_of = malloc((size_t)nn * sizeof *c.col_of);
            c.act = malloc((size_t)c.n_cand * sizeof *c.act);
            c.zc = malloc((size_t)c.n_cand * sizeof *c.zc);
            if (!c.cand_node || !c.cand_of || !c.col_of || !c.act || !c.zc) {
                rc = floor_oom(err);
                goto done;
            }
            for (int n = 0, i = 0; n < nn; n++) {
                c.col_of[n] = -1;
                c.cand_of[n] = c.cand[n] ? i : -1;
                if (c.cand[n])
                    c.cand_node[i++] = n;
            }
        }
    }
    { /* the lowest point under the loads alone (the inflated tire), when the supports hold the body */
        fem_floor_result r0;
        cm_error e0 = {0};
        if (floor_solve(&c, -1e30, &r0, &e0) == CM_OK) {
            double z = INFINITY;
            for (int n = 0; n < nn; n++)
                if (c.cand[n])
                    z = fmin(z, m->mesh.x[3 * n + 2] + (c.influence ? c.u0 : s->u)[3 * n + 2]);
            c.zmin = z;
        }
    }
    if (!(cfg->floor_load > 0)) {
        h_final = cfg->floor_height;
        rc = floor_solve(&c, cfg->floor_height, res, err);
        goto done;
    }
    /* The height at which the floor carries floor_load: R(h) grows with h.
     * Bracket from the lowest point upwards (doubling steps of 1e-3 of the
     * body's size), then the Illinois variant of regula falsi. */
    const double L = cfg->floor_load;
    double h_lo = c.zmin - 1e-3 * m->size, step = 1e-3 * m->size, h_hi;
    fem_floor_result r_lo, r_hi;
    if ((rc = floor_solve(&c, h_lo, &r_lo, err)))
        goto done;
    while (r_lo.reaction > L) { /* already above the load (e.g. the inflated tire bulges down) */
        h_lo -= step, step *= 2;
        if ((rc = floor_solve(&c, h_lo, &r_lo, err)))
            goto done;
    }
    h_hi = h_lo + step;
    for (;;) {
        if ((rc = floor_solve(&c, h_hi, &r_hi, err)))
            goto done;
        if (r_hi.reaction >= L)
            break;
        h_lo = h_hi, r_lo = r_hi, step *= 2, h_hi = h_lo + step;
        if (step > m->size) {
            rc = cm_fail(err, CM_ERR_NUMERIC, "fem.floor.load = %g N: not reached with the floor %g m into the body "
                         "(%g N)", L, h_hi - c.zmin, r_hi.reaction);
            goto done;
        }
    }
    double f_lo = r_lo.reaction - L, f_hi = r_hi.reaction - L;
    int side = 0;
    for (int it = 0; it < 100; it++) {
        double h = (h_lo * f_hi - h_hi * f_lo) / (f_hi - f_lo);
        fem_floor_result r;
        if ((rc = floor_solve(&c, h, &r, err)))
            goto done;
        double fr = r.reaction - L;
        if (fabs(fr) <= 1e-6 * L || h_hi - h_lo <= 1e-12 * m->size) {
            *res = r;
            h_final = h;
            goto done;
        }
        if (fr > 0) {
            h_hi = h, f_hi = fr;
            if (side == -1)
                f_lo *= 0.5;
            side = -1;
        } else {
            h_lo = h, f_lo = fr;
            if (side == 1)
                f_hi *= 0.5;
            side = 1;
        }
    }
    rc = cm_fail(err, CM_ERR_NUMERIC, "fem.floor.load = %g N: the height search did not converge", L);
done:
    if (rc == CM_OK && c.influence)
        rc = floor_finish(&c, h_final, err);
    free(c.cand);
    free(c.active);
    free(c.base_fixed);
    free(c.base_val);
    free(c.val);
    free(c.r);
    free(c.u0);
    free(c.cand_node);
    free(c.cand_of);
    free(c.col_of);
    free(c.G);
    free(c.act);
    free(c.S);
    free(c.lam);
    free(c.zc);
    return rc;
}
