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
    int solves;
} floor_ctx;

/* The static state with the floor at `height`: the active set (nodes held
 * at z = height) grows by the free nodes found below the plane and loses
 * the held nodes the plane pulls (K u - b < 0 in z), until neither happens.
 * Frictionless: only z is held. Each pass refactorizes K_ff (CHOLMOD). */
static int floor_solve(floor_ctx *c, double height, fem_floor_result *res, cm_error *err)
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
            res->height = height;
            res->deflection = height - c->zmin;
            res->z_free = c->zmin;
            res->reaction = reaction;
            res->max_below = below;
            res->contact_nodes = held;
            res->solves = c->solves;
            return CM_OK;
        }
    }
    return cm_fail(err, CM_ERR_NUMERIC, "fem.floor: the contact set did not settle in 200 passes (floor at z = %.6g m)",
                   height);
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
    if (!c.cand || !c.active || !c.base_fixed || !c.base_val || !c.val || !c.r) {
        rc = cm_fail(err, CM_ERR_NOMEM, "fem.floor: out of memory");
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
    { /* the lowest point under the loads alone (the inflated tire), when the supports hold the body */
        fem_floor_result r0;
        cm_error e0 = {0};
        if (floor_solve(&c, -1e30, &r0, &e0) == CM_OK) {
            double z = INFINITY;
            for (int n = 0; n < nn; n++)
                if (c.cand[n])
                    z = fmin(z, m->mesh.x[3 * n + 2] + s->u[3 * n + 2]);
            c.zmin = z;
        }
    }
    if (!(cfg->floor_load > 0)) {
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
    free(c.cand);
    free(c.active);
    free(c.base_fixed);
    free(c.base_val);
    free(c.val);
    free(c.r);
    return rc;
}
