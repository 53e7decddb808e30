/* Results through common/h5io: fem.h5 + fem.xmf (ParaView opens the
 * deformed tire as a time series) and the time series /series, also
 * written as fem_series.csv. */
#include "fem_output.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fem_element.h"
#include "fem_model.h"
#include "h5io.h"

struct fem_output {
    cm_h5 *h5;
    cm_h5_series *series;
    double *pos, *disp, *force, *strain, *stress, *e22, *e33; /* snapshot buffers, allocated once */
};

static const char *const k_columns[] = {"time", "elastic", "kinetic", "rim_Fx", "rim_Fy", "rim_Fz",
                                        "rim_Tx", "rim_Ty", "rim_Tz", "umax"};

/* Creates (or, resuming, reopens) the files: keep_step < -1 creates them. */
static int output_start(struct fem_model *m, const char *dir, long keep_step, long series_rows, fem_output **out,
                        cm_error *err)
{
    *out = NULL;
    char path[1024], csv[1024];
    snprintf(path, sizeof path, "%s/fem.h5", dir);
    snprintf(csv, sizeof csv, "%s/fem_series.csv", dir);
    fem_output *o = calloc(1, sizeof *o);
    if (!o)
        return cm_fail(err, CM_ERR_NOMEM, "fem output: out of memory");
    size_t nn = (size_t)m->mesh.n_nodes, ne = (size_t)m->mesh.n_tets;
    o->pos = malloc(3 * nn * sizeof(double));
    o->disp = malloc(3 * nn * sizeof(double));
    o->force = calloc(3 * nn, sizeof(double)); /* zero off the interface, always */
    o->strain = malloc(6 * ne * sizeof(double));
    o->stress = malloc(6 * ne * sizeof(double));
    o->e22 = malloc(ne * sizeof(double));
    o->e33 = malloc(ne * sizeof(double));
    int *conn = malloc(4 * ne * sizeof(int));
    int rc = CM_OK;
    if (!o->pos || !o->disp || !o->force || !o->strain || !o->stress || !o->e22 || !o->e33 || !conn) {
        rc = cm_fail(err, CM_ERR_NOMEM, "fem output: out of memory");
        goto done;
    }
    cm_h5_def def = cm_h5_default_def();
    def.xdmf = CM_H5_XDMF_TETRAHEDRON;
    def.grid_name = "tire";
    def.geometry = "position"; /* deformed mesh in the world frame */
    const int ncols = (int)(sizeof k_columns / sizeof *k_columns);
    if (keep_step >= -1) {
        if ((rc = cm_h5_reopen(path, &def, keep_step, &o->h5, err)) == CM_OK)
            rc = cm_h5_series_reopen(o->h5, "/series", k_columns, ncols, csv, series_rows, &o->series, err);
        goto done;
    }
    if ((rc = cm_h5_create(path, &def, &o->h5, err)))
        goto done;
    for (size_t k = 0; k < 4 * ne; k++)
        conn[k] = m->mesh.tets[k];
    if ((rc = cm_h5_write_ints(o->h5, "/mesh/connectivity", conn, ne, 4, err)) ||
        (rc = cm_h5_write_doubles(o->h5, "/mesh/points0", m->mesh.x, nn, 3, err)) ||
        (rc = cm_h5_attr_string(o->h5, "/", "units", "m, s, N, Pa; world frame (x travel, y axle, z up); /mesh/points0 undeformed, rim frame", err)))
        goto done;
    rc = cm_h5_series_create(o->h5, "/series", k_columns, ncols, csv, &o->series, err);
done:
    free(conn);
    if (rc) {
        cm_error e2 = {0};
        fem_output_close(&o, &e2);
        return rc;
    }
    *out = o;
    return CM_OK;
}

int fem_output_open(struct fem_model *m, const char *dir, fem_output **out, cm_error *err)
{
    return output_start(m, dir, -2, 0, out, err);
}

int fem_output_reopen(struct fem_model *m, const char *dir, long keep_step, long series_rows, fem_output **out,
                      cm_error *err)
{
    return output_start(m, dir, keep_step < -1 ? -1 : keep_step, series_rows, out, err);
}

long fem_output_rows(const fem_output *o)
{
    return o ? cm_h5_series_rows(o->series) : 0;
}

/* T_world = R T R^T for a symmetric tensor in XDMF Tensor6 order
 * (xx, xy, xz, yy, yz, zz); R is row-major, rim frame -> world. */
static void rotate_tensor6(const double R[9], const double t[6], double out[6])
{
    const double T[3][3] = {{t[0], t[1], t[2]}, {t[1], t[3], t[4]}, {t[2], t[4], t[5]}};
    double RT[3][3], W[3][3];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            RT[i][j] = 0.0;
            for (int k = 0; k < 3; k++)
                RT[i][j] += R[3 * i + k] * T[k][j];
        }
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            W[i][j] = 0.0;
            for (int k = 0; k < 3; k++)
                W[i][j] += RT[i][k] * R[3 * j + k];
        }
    out[0] = W[0][0], out[1] = W[0][1], out[2] = W[0][2], out[3] = W[1][1], out[4] = W[1][2], out[5] = W[2][2];
}

/* Snapshots are written in the world frame, so that ParaView shows the tire
 * where the grains are: positions c + R (X + u), displacement R u, strain
 * and stress rotated to R T R^T. eps22 and eps33 are the paper's components
 * (figs. 16-19): along the travel direction (world x) and the sinkage
 * direction (world z). */
int fem_output_snapshot(fem_output *o, struct fem_model *m, cm_error *err)
{
    const fem_mesh *me = &m->mesh;
    const double *u = m->s->u;
    const fem_wheel *w = &m->wheel;
    for (int n = 0; n < me->n_nodes; n++) {
        const double *X = &me->x[3 * n], *un = &u[3 * n];
        double r[3] = {X[0] + un[0], X[1] + un[1], X[2] + un[2]};
        for (int a = 0; a < 3; a++) {
            o->pos[3 * n + a] = w->center[a] + w->R[3 * a] * r[0] + w->R[3 * a + 1] * r[1] + w->R[3 * a + 2] * r[2];
            o->disp[3 * n + a] = w->R[3 * a] * un[0] + w->R[3 * a + 1] * un[1] + w->R[3 * a + 2] * un[2];
        }
    }
    /* The grains' forces on the tire as the FEM received them (eq. 42 nodal
     * forces, world frame), zero on nodes off the interface. */
    for (uint32_t k = 0; k < m->n_if_nodes; k++)
        memcpy(&o->force[3 * (size_t)m->if_nodes[k]], &m->if_force[3 * (size_t)k], 3 * sizeof(double));
    for (int e = 0; e < me->n_tets; e++) {
        const int32_t *t = &me->tets[4 * e];
        double g[4][3], ue[4][3], eps[6], sig[6];
        fem_tet_gradients(&me->x[3 * t[0]], &me->x[3 * t[1]], &me->x[3 * t[2]], &me->x[3 * t[3]], g);
        for (int i = 0; i < 4; i++)
            for (int a = 0; a < 3; a++)
                ue[i][a] = u[3 * t[i] + a];
        fem_tet_strain(g, ue, eps);
        fem_stress_from_strain(eps, m->s->lambda, m->s->mu, sig); /* eq. 29 */
        /* XDMF Tensor6 order: xx, xy, xz, yy, yz, zz; ours: 11 22 33 23 13 12 */
        const double se_rim[6] = {eps[0], eps[5], eps[4], eps[1], eps[3], eps[2]};
        const double ss_rim[6] = {sig[0], sig[5], sig[4], sig[1], sig[3], sig[2]};
        double *se = &o->strain[6 * e], *ss = &o->stress[6 * e];
        rotate_tensor6(w->R, se_rim, se);
        rotate_tensor6(w->R, ss_rim, ss);
        o->e22[e] = se[0]; /* travel direction, world x */
        o->e33[e] = se[5]; /* sinkage direction, world z */
    }
    size_t nn = (size_t)me->n_nodes, ne = (size_t)me->n_tets;
    int rc;
    if ((rc = cm_h5_step_begin(o->h5, m->s->steps, m->s->time, err)) ||
        (rc = cm_h5_step_doubles(o->h5, "position", CM_H5_NODE, o->pos, nn, 3, err)) ||
        (rc = cm_h5_step_doubles(o->h5, "displacement", CM_H5_NODE, o->disp, nn, 3, err)) ||
        (rc = cm_h5_step_doubles(o->h5, "contact_force", CM_H5_NODE, o->force, nn, 3, err)) ||
        (rc = cm_h5_step_doubles(o->h5, "strain", CM_H5_CELL, o->strain, ne, 6, err)) ||
        (rc = cm_h5_step_doubles(o->h5, "stress", CM_H5_CELL, o->stress, ne, 6, err)) ||
        (rc = cm_h5_step_doubles(o->h5, "eps22", CM_H5_CELL, o->e22, ne, 1, err)) ||
        (rc = cm_h5_step_doubles(o->h5, "eps33", CM_H5_CELL, o->e33, ne, 1, err)) ||
        (rc = cm_h5_step_end(o->h5, err)))
        return cm_fail_prefix(err, "fem output");
    return CM_OK;
}

int fem_output_series(fem_output *o, struct fem_model *m, cm_error *err)
{
    fem_energy en;
    double F[3], T[3], umax = 0.0;
    fem_get_energy(m, &en);
    fem_rim_reaction(m, F, T);
    for (int d = 0; d < m->s->n_dof; d++)
        umax = fabs(m->s->u[d]) > umax ? fabs(m->s->u[d]) : umax;
    double row[10] = {m->s->time, en.elastic, en.kinetic, F[0], F[1], F[2], T[0], T[1], T[2], umax};
    int rc = cm_h5_series_append(o->series, row, err);
    return rc ? cm_fail_prefix(err, "fem output") : CM_OK;
}

int fem_output_close(fem_output **po, cm_error *err)
{
    fem_output *o = *po;
    if (!o)
        return CM_OK;
    int rc = o->h5 ? cm_h5_close(&o->h5, err) : CM_OK;
    free(o->pos);
    free(o->disp);
    free(o->force);
    free(o->strain);
    free(o->stress);
    free(o->e22);
    free(o->e33);
    free(o);
    *po = NULL;
    return rc;
}
