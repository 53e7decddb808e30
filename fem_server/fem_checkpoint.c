/* fem_server's checkpoints (fem_checkpoint.h): one field list per part,
 * used for writing and reading alike (common/ckpt.h). What the integrator
 * prepares (Newmark's factor of K_eff) is rebuilt identically by the first
 * fem_advance and is not saved. */
#include "fem_checkpoint.h"

#include <stdlib.h>
#include <string.h>

#include "fem_model.h"
#include "fem_output.h"

void fem_checkpoint_drive(cm_ckpt *ck, drive_state *s)
{
    int phase = (int)s->phase;
    cm_ckpt_int(ck, "/drive/phase", &phase);
    s->phase = (drive_phase)phase;
    cm_ckpt_f64(ck, "/drive/center", s->center, 3);
    cm_ckpt_f64(ck, "/drive/velocity", s->velocity, 3);
    cm_ckpt_double(ck, "/drive/omega", &s->omega);
    cm_ckpt_double(ck, "/drive/angle", &s->angle);
    cm_ckpt_double(ck, "/drive/sunk", &s->sunk);
    cm_ckpt_double(ck, "/drive/load_avg", &s->load_avg);
    cm_ckpt_double(ck, "/drive/travelled", &s->travelled);
    cm_ckpt_double(ck, "/drive/t_phase", &s->t_phase);
    cm_ckpt_double(ck, "/drive/fx_avg", &s->fx_avg);
    cm_ckpt_double(ck, "/drive/my_avg", &s->my_avg);
    cm_ckpt_double(ck, "/drive/vz_avg", &s->vz_avg);
    cm_ckpt_long(ck, "/drive/rate_limited", &s->rate_limited);
}

static void visit_model(cm_ckpt *ck, fem_model *m)
{
    fem_solver *s = m->s;
    const size_t nd = (size_t)s->n_dof;
    cm_ckpt_same_u64(ck, "/model/n_dof", (uint64_t)s->n_dof, "the tire's number of unknowns (mesh)");
    cm_ckpt_same_u64(ck, "/model/integrator", (uint64_t)m->cfg.integrator, "fem.integrator");
    cm_ckpt_f64(ck, "/model/u", s->u, nd);
    cm_ckpt_f64(ck, "/model/v", s->v, nd);
    cm_ckpt_f64(ck, "/model/a", s->a, nd);
    cm_ckpt_f64(ck, "/model/f", s->f, nd);
    cm_ckpt_double(ck, "/model/time", &s->time);
    cm_ckpt_long(ck, "/model/steps", &s->steps);
    cm_ckpt_f64(ck, "/model/wheel/center", m->wheel.center, 3);
    cm_ckpt_f64(ck, "/model/wheel/R", m->wheel.R, 9);
    cm_ckpt_f64(ck, "/model/wheel/v_center", m->wheel.v_center, 3);
    cm_ckpt_f64(ck, "/model/wheel/omega", m->wheel.omega, 3);
    cm_ckpt_long(ck, "/model/advances", &m->advances);
    cm_ckpt_double(ck, "/model/max_substep", &m->max_substep);
    cm_ckpt_f64(ck, "/model/if_force", m->if_force, 3 * (size_t)m->n_if_nodes);
    if (!ck->writing && ck->rc == CM_OK) {
        /* a was left by the last step under f, whose last sub-step was
         * max_substep: what fem_solver_load_changed corrects from */
        memcpy(s->f_applied, s->f, nd * sizeof *s->f);
        s->h_last = m->cfg.integrator == FEM_INTEGRATOR_EXPLICIT ? m->max_substep : 0.0;
    }
}

static void visit_run(cm_ckpt *ck, fem_ckpt_run *r)
{
    fem_checkpoint_drive(ck, r->drive);
    cm_ckpt_double(ck, "/run/w_fem", &r->w_fem);
    cm_ckpt_double(ck, "/run/max_force_mismatch", &r->max_force_mismatch);
    cm_ckpt_double(ck, "/run/max_moment_mismatch", &r->max_moment_mismatch);
    cm_ckpt_double(ck, "/run/work_abs", &r->work_abs);
    cm_ckpt_double(ck, "/run/work_scale", &r->work_scale);
    cm_ckpt_double(ck, "/run/work_gap_max", &r->work_gap_max);
    cm_ckpt_double(ck, "/run/work_warned_at", &r->work_warned_at);
    cm_ckpt_same_u64(ck, "/run/n_nodes", r->n_nodes, "the number of interface nodes");
    cm_ckpt_f64(ck, "/run/x_prev", r->x_prev, 3 * (size_t)r->n_nodes);
    cm_ckpt_long(ck, "/run/series_rows", &r->series_rows);
    int tn = (int)r->travel_n;
    cm_ckpt_count(ck, "/run/travel_n", &tn, 1 << 30);
    if (!ck->writing && ck->rc == CM_OK) {
        r->travel_n = (size_t)tn;
        for (int k = 0; k < FEM_CKPT_TRAVEL_COLS; k++)
            if (!(r->travel[k] = malloc((tn ? (size_t)tn : 1) * sizeof(double))))
                ck->rc = cm_fail(ck->err, CM_ERR_NOMEM, "%s: out of memory for the travel series", ck->path);
    }
    static const char *const names[FEM_CKPT_TRAVEL_COLS] = {"/run/travel_TH",      "/run/travel_TR",
                                                            "/run/travel_TP",      "/run/travel_sinkage",
                                                            "/run/travel_slip",    "/run/travel_Fx",
                                                            "/run/travel_My"};
    for (int k = 0; k < FEM_CKPT_TRAVEL_COLS; k++)
        cm_ckpt_f64(ck, names[k], r->travel[k], r->travel_n);
}

int fem_checkpoint_write(const char *dir, fem_model *m, fem_ckpt_run *run, uint64_t scene_hash, cm_error *err)
{
    cm_ckpt ck;
    if (cm_ckpt_begin_write(&ck, dir, "fem", run->exchange, err) == CM_OK) {
        cm_ckpt_same_u64(&ck, "/scene_hash", scene_hash, "the scene file or its --set overrides");
        visit_model(&ck, m);
        m->s->ku_valid = 0; /* u replaced */
        visit_run(&ck, run);
        long rows = m->out ? fem_output_rows(m->out) : 0;
        cm_ckpt_long(&ck, "/output/fem_series_rows", &rows);
    }
    return cm_ckpt_commit(&ck);
}

int fem_checkpoint_read(const char *path, long exchange, fem_model *m, fem_ckpt_run *run, uint64_t scene_hash,
                        const char *dir, cm_error *err)
{
    cm_ckpt ck;
    long rows = 0;
    memset(run->travel, 0, sizeof run->travel);
    if (cm_ckpt_begin_read(&ck, path, exchange, err) == CM_OK) {
        cm_ckpt_same_u64(&ck, "/scene_hash", scene_hash, "the scene file or its --set overrides");
        visit_model(&ck, m);
        visit_run(&ck, run);
        cm_ckpt_long(&ck, "/output/fem_series_rows", &rows);
    }
    run->exchange = exchange;
    int rc = cm_ckpt_end_read(&ck);
    if (rc == CM_OK && dir && dir[0]) {
        /* snapshots are numbered by solver step: keep those up to now */
        fem_output_close(&m->out, NULL);
        rc = fem_output_reopen(m, dir, m->s->steps, rows, &m->out, err);
    }
    return rc;
}

uint64_t fem_state_hash(const fem_model *m)
{
    const fem_solver *s = m->s;
    uint64_t h = 1469598103934665603ULL;
    const double *arr[3] = {s->u, s->v, s->a};
    for (int k = 0; k < 3; k++) {
        const unsigned char *b = (const unsigned char *)arr[k];
        for (size_t i = 0; i < (size_t)s->n_dof * sizeof(double); i++) {
            h ^= b[i];
            h *= 1099511628211ULL;
        }
    }
    return h;
}
