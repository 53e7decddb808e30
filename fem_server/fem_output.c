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
    double *pos, *strain, *stress, *e22, *e33; /* snapshot buffers, allocated once */
};

static const char *const k_columns[] = {"time", "elastic", "kinetic", "rim_Fx", "rim_Fy", "rim_Fz",
                                        "rim_Tx", "rim_Ty", "rim_Tz", "umax"};

int fem_output_open(struct fem_model *m, const char *dir, fem_output **out, cm_error *err)
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
    o->strain = malloc(6 * ne * sizeof(double));
    o->stress = malloc(6 * ne * sizeof(double));
    o->e22 = malloc(ne * sizeof(double));
    o->e33 = malloc(ne * sizeof(double));
    int *conn = malloc(4 * ne * sizeof(int));
    int rc = CM_OK;
    if (!o->pos || !o->strain || !o->stress || !o->e22 || !o->e33 || !conn) {
        rc = cm_fail(err, CM_ERR_NOMEM, "fem output: out of memory");
        goto done;
    }
    cm_h5_def def = cm_h5_default_def();
    def.xdmf = CM_H5_XDMF_TETRAHEDRON;
    def.grid_name = "tire";
    def.geometry = "position"; /* deformed mesh X + u, rim frame */
    if ((rc = cm_h5_create(path, &def, &o->h5, err)))
        goto done;
    for (size_t k = 0; k < 4 * ne; k++)
        conn[k] = m->mesh.tets[k];
    if ((rc = cm_h5_write_ints(o->h5, "/mesh/connectivity", conn, ne, 4, err)) ||
        (rc = cm_h5_write_doubles(o->h5, "/mesh/points0", m->mesh.x, nn, 3, err)) ||
        (rc = cm_h5_attr_string(o->h5, "/", "units", "m, s, N, Pa; strain and stress in the rim frame", err)))
        goto done;
    rc = cm_h5_series_create(o->h5, "/series", k_columns, (int)(sizeof k_columns / sizeof *k_columns), csv,
                             &o->series, err);
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

int fem_output_snapshot(fem_output *o, struct fem_model *m, cm_error *err)
{
    const fem_mesh *me = &m->mesh;
    const double *u = m->s->u;
    for (int d = 0; d < 3 * me->n_nodes; d++)
        o->pos[d] = me->x[d] + u[d];
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
        double *se = &o->strain[6 * e], *ss = &o->stress[6 * e];
        se[0] = eps[0]; se[1] = eps[5]; se[2] = eps[4]; se[3] = eps[1]; se[4] = eps[3]; se[5] = eps[2];
        ss[0] = sig[0]; ss[1] = sig[5]; ss[2] = sig[4]; ss[3] = sig[1]; ss[4] = sig[3]; ss[5] = sig[2];
        o->e22[e] = eps[1];
        o->e33[e] = eps[2];
    }
    size_t nn = (size_t)me->n_nodes, ne = (size_t)me->n_tets;
    int rc;
    if ((rc = cm_h5_step_begin(o->h5, m->s->steps, m->s->time, err)) ||
        (rc = cm_h5_step_doubles(o->h5, "position", CM_H5_NODE, o->pos, nn, 3, err)) ||
        (rc = cm_h5_step_doubles(o->h5, "displacement", CM_H5_NODE, u, nn, 3, err)) ||
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
    free(o->strain);
    free(o->stress);
    free(o->e22);
    free(o->e33);
    free(o);
    *po = NULL;
    return rc;
}
