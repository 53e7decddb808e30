/* One exchange with dem_server as a pipeline of named, timed stages (the
 * list and what each does: fem_exchange.h). fem_exchange() below reads
 * top-down; each stage is a function of its own further down. */
#include "fem_exchange.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fem_checkpoint.h"
#include "log.h"
#include "timer.h"

_Static_assert(SER_N == FEM_CKPT_TRAVEL_COLS, "the checkpoint keeps every column of the travel series");

const char *const fem_stage_names[FEM_STAGE_COUNT] = {
    "receive", "check_frame", "check_balance", "place_wheel", "advance", "snapshot",
    "update_drive", "pack_reply", "check_work", "send", "record"};

/* Columns of the time series (wheel.h5:/series and traction.csv). */
enum {
    COL_T, COL_PHASE, COL_X, COL_Z, COL_ANGLE, COL_OMEGA, COL_V, COL_SLIP, COL_FX, COL_FY, COL_FZ, COL_MY,
    COL_TH, COL_TR, COL_TP, COL_CONTACTS, COL_SINKAGE, COL_E_EL, COL_E_KIN, COL_W_DEM, COL_W_FEM, NCOL
};
const char *const fem_series_columns[] = {
    "t", "phase", "x", "z", "angle", "omega", "v", "slip", "Fx", "Fy", "Fz", "My",
    "T_H", "T_R", "T_P", "contacts", "sinkage", "E_elastic", "E_kinetic", "W_dem", "W_fem"};
_Static_assert(sizeof fem_series_columns / sizeof *fem_series_columns == NCOL, "one name per column");
const int fem_series_ncols = NCOL;

int series_push(series_buf *b, const double row[SER_N])
{
    if (b->n == b->cap) {
        size_t cap = b->cap ? 2 * b->cap : 4096;
        for (int k = 0; k < SER_N; k++) {
            double *p = realloc(b->col[k], cap * sizeof(double));
            if (!p)
                return CM_ERR_NOMEM;
            b->col[k] = p;
        }
        b->cap = cap;
    }
    for (int k = 0; k < SER_N; k++)
        b->col[k][b->n] = row[k];
    b->n++;
    return CM_OK;
}

void series_free(series_buf *b)
{
    for (int k = 0; k < SER_N; k++) {
        free(b->col[k]);
        b->col[k] = NULL;
    }
    b->n = b->cap = 0;
}

/* What one exchange carries from stage to stage. */
typedef struct exchange {
    const ipc_frame_head *in;
    const double *f;             /* 3 nn: the grains' nodal forces (N, world) */
    double info[IPC_INFO_LEN];   /* the frame's totals, copied before the frame is released */
    double time;                 /* s, the frame's time; the reply is at time + interval */
    int interrupted, checkpoint; /* this exchange is checkpointed (and, interrupted, the last) */
    drive_soil soil;             /* the grains' force and moment about the axle */
    ipc_frame_head *out;
    double *p;                   /* the reply's payload: 3 nn positions, 3 nn velocities */
    fem_energy en;               /* the tire's energies after the advance */
} exchange;

static void rotation_about_y(double angle, double R[9])
{
    double c = cos(angle), s = sin(angle);
    const double r[9] = {c, 0, s, 0, 1, 0, -s, 0, c};
    memcpy(R, r, sizeof r);
}

int fem_set_wheel_motion(fem_model *m, const drive_state *ds, cm_error *err)
{
    fem_wheel w;
    memset(&w, 0, sizeof w);
    memcpy(w.center, ds->center, sizeof w.center);
    rotation_about_y(ds->angle, w.R);
    memcpy(w.v_center, ds->velocity, sizeof w.v_center);
    w.omega[1] = ds->omega;
    return fem_set_wheel(m, &w, err);
}

/* ---- stages --------------------------------------------------------------------------------------------- */

/* receive: the DEM's frame; a FINISH frame is answered and ends the run. */
static fem_exchange_status stage_receive(fem_coupled *c, exchange *x)
{
    if (ipc_recv(c->ch, &x->in, &x->f))
        return FEM_EXCHANGE_LINK_LOST;
    if (x->in->kind != IPC_FRAME_FINISH)
        return FEM_EXCHANGE_NEXT;
    ipc_recv_release(c->ch);
    ipc_frame_head *out;
    double *p;
    if (ipc_send_begin(c->ch, &out, &p))
        return FEM_EXCHANGE_LINK_LOST;
    out->kind = IPC_FRAME_FINISH;
    return ipc_send_commit(c->ch) ? FEM_EXCHANGE_LINK_LOST : FEM_EXCHANGE_FINISHED;
}

/* check_frame: everything this side uses from the peer is checked before it
 * is used, and bad data is reported as the peer's, with the exchange and
 * the value (a NaN force would otherwise surface as an unstable tire). */
static int stage_check_frame(fem_coupled *c, exchange *x, cm_error *err)
{
    const ipc_frame_head *in = x->in;
    if (in->kind != IPC_FRAME_DATA)
        return cm_fail(err, CM_ERR_RANGE, "dem_server sent a frame of unknown kind %u at exchange %ld", in->kind,
                       c->n);
    if (!isfinite(in->time))
        return cm_fail(err, CM_ERR_RANGE, "dem_server sent a non-finite time (%g) at exchange %ld", in->time, c->n);
    static const struct { int k; const char *name; } used[] = {
        {IPC_INFO_FORCE_X, "force x"},   {IPC_INFO_FORCE_Y, "force y"},    {IPC_INFO_FORCE_Z, "force z"},
        {IPC_INFO_MOMENT_X, "moment x"}, {IPC_INFO_MOMENT_Y, "moment y"},  {IPC_INFO_MOMENT_Z, "moment z"},
        {IPC_INFO_TRACTION_POS, "T_H"},  {IPC_INFO_TRACTION_NEG, "T_R"},   {IPC_INFO_CONTACTS, "contacts"},
        {IPC_INFO_DEM_WORK, "interface work"}, {IPC_INFO_BED_HEIGHT, "bed height"}, {IPC_INFO_BED_TOP, "bed top"},
        {IPC_INFO_CONTACT_ENERGY, "contact energy"}};
    for (size_t k = 0; k < sizeof used / sizeof *used; k++)
        if (!isfinite(in->info[used[k].k]))
            return cm_fail(err, CM_ERR_RANGE,
                           "dem_server sent bad data at exchange %ld (t = %.6f s): its %s total is %g; the DEM "
                           "side diverged (its guards and log say why; else reduce coupling.dt)",
                           c->n, in->time, used[k].name, in->info[used[k].k]);
    if (!(in->info[IPC_INFO_CONTACTS] >= 0))
        return cm_fail(err, CM_ERR_RANGE, "dem_server sent bad data at exchange %ld (t = %.6f s): %g contacts",
                       c->n, in->time, in->info[IPC_INFO_CONTACTS]);
    if (!(in->info[IPC_INFO_CONTACT_ENERGY] >= 0))
        return cm_fail(err, CM_ERR_RANGE,
                       "dem_server sent bad data at exchange %ld (t = %.6f s): a contact energy of %g J", c->n,
                       in->time, in->info[IPC_INFO_CONTACT_ENERGY]);
    for (size_t j = 0; j < 3 * (size_t)c->nn; j++)
        if (!isfinite(x->f[j]))
            return cm_fail(err, CM_ERR_RANGE,
                           "dem_server sent bad data at exchange %ld (t = %.6f s): the force on interface node %zu "
                           "(%c) is %g; the DEM side diverged (its guards and log say why; else reduce coupling.dt)",
                           c->n, in->time, j / 3, "xyz"[j % 3], x->f[j]);
    memcpy(x->info, in->info, sizeof x->info);
    x->time = in->time;
    /* A checkpoint of this exchange: periodic, or either side interrupted
     * (then the run stops after it). Not once the drive is done: the run
     * ends at the next exchange anyway. */
    long every = cm_run_checkpoint_exchanges(c->run);
    x->interrupted = (*c->interrupt || (in->flags & IPC_FLAG_CHECKPOINT)) && !c->stop_sent;
    x->checkpoint = (x->interrupted || (every > 0 && (c->n + 1) % every == 0)) && c->ds.phase != DRIVE_DONE;
    return CM_OK;
}

/* check_balance: nodal forces against the contact totals (eq. 42 keeps
 * resultant and moment); positions are those the DEM saw, moments about the
 * world origin as the protocol defines them. Recorded, reported at the end. */
static fem_exchange_status stage_check_balance(fem_coupled *c, const exchange *x)
{
    double fs[3] = {0}, ms[3] = {0};
    for (uint32_t i = 0; i < c->nn; i++) {
        const double *fi = x->f + 3 * i, *r = c->x_prev + 3 * i;
        fs[0] += fi[0], fs[1] += fi[1], fs[2] += fi[2];
        ms[0] += r[1] * fi[2] - r[2] * fi[1];
        ms[1] += r[2] * fi[0] - r[0] * fi[2];
        ms[2] += r[0] * fi[1] - r[1] * fi[0];
    }
    const double *info = x->info;
    double fscale = 1e-9 + fabs(info[IPC_INFO_FORCE_X]) + fabs(info[IPC_INFO_FORCE_Y]) + fabs(info[IPC_INFO_FORCE_Z]);
    for (int k = 0; k < 3; k++) {
        double df = fabs(fs[k] - info[IPC_INFO_FORCE_X + k]) / fscale;
        double dm = fabs(ms[k] - info[IPC_INFO_MOMENT_X + k]) / (fscale * c->drive->radius);
        c->max_force_mismatch = df > c->max_force_mismatch ? df : c->max_force_mismatch;
        c->max_moment_mismatch = dm > c->max_moment_mismatch ? dm : c->max_moment_mismatch;
    }
    return FEM_EXCHANGE_NEXT;
}

/* place_wheel: at the first exchange, lower the wheel until its lowest
 * surface point is start_gap above the highest grain (a gentle start); then
 * the model takes the motion decided last time. */
static int stage_place_wheel(fem_coupled *c, const exchange *x, cm_error *err)
{
    double bed = x->info[IPC_INFO_BED_HEIGHT], bed_top = x->info[IPC_INFO_BED_TOP];
    if (c->n == 0 && c->drive->start_gap > 0 && bed_top != 0) {
        double lowest = c->x_prev[2];
        for (uint32_t i = 1; i < c->nn; i++)
            lowest = c->x_prev[3 * i + 2] < lowest ? c->x_prev[3 * i + 2] : lowest;
        /* the DEM's first forces were those of the tire where the scene put
         * it: lifting it out of the grains would keep forces it never felt
         * (lifting a tire that is clear of them is fine: a large start_gap) */
        if (lowest < bed_top)
            return cm_fail(err, CM_ERR_RANGE,
                           "wheel.center: the tire starts inside the bed: its lowest point (z = %.4f m) is %.1f mm "
                           "below the highest grain top (z = %.4f m); raise wheel.center[2] by at least that plus "
                           "wheel.start_gap (to %.4f m or more)",
                           lowest, 1e3 * (bed_top - lowest), bed_top,
                           c->ds.center[2] + bed_top + c->drive->start_gap - lowest);
        c->ds.center[2] += bed_top + c->drive->start_gap - lowest;
        cm_log_info("bed surface at z = %.4f m (highest grain top %.4f m): wheel lowered to %.1f mm above it", bed,
                    bed_top, 1e3 * c->drive->start_gap);
    }
    return fem_set_wheel_motion(c->model, &c->ds, err);
}

/* advance: the tire over the interval, the grains' forces held; the frame
 * is released once they are used. */
static int stage_advance(fem_coupled *c, const exchange *x, cm_error *err)
{
    int rc = fem_advance(c->model, x->f, c->interval, err);
    ipc_recv_release(c->ch);
    return rc;
}

/* snapshot: the tire's output of the state the advance reached, through
 * the hook (fem_advance writes no files). */
static int stage_snapshot(fem_coupled *c, cm_error *err)
{
    return c->hooks.after_advance ? c->hooks.after_advance(c->model, c->hooks.user, c->n, err) : CM_OK;
}

/* update_drive: the wheel's motion for the next interval, from the grains'
 * force and their moment about the axle, M_o - c x F (the centre as it was
 * when the DEM computed them). */
static int stage_update_drive(fem_coupled *c, exchange *x, cm_error *err)
{
    const double *info = x->info, *ctr = c->ds.center;
    x->soil = (drive_soil){info[IPC_INFO_FORCE_X], info[IPC_INFO_FORCE_Z],
                           info[IPC_INFO_MOMENT_Y] - (ctr[2] * info[IPC_INFO_FORCE_X] - ctr[0] * info[IPC_INFO_FORCE_Z])};
    int rc = drive_update(c->drive, &c->ds, x->time + c->interval, c->interval, &x->soil, err);
    return rc ? rc : fem_set_wheel_motion(c->model, &c->ds, err);
}

/* pack_reply: the interface as the FEM moved it, straight into the reply,
 * and the work of the interface forces over that motion. */
static fem_exchange_status stage_pack_reply(fem_coupled *c, exchange *x)
{
    if (ipc_send_begin(c->ch, &x->out, &x->p))
        return FEM_EXCHANGE_LINK_LOST;
    size_t n3 = 3 * (size_t)c->nn;
    fem_interface_state(c->model, x->p, x->p + n3);
    double w0 = c->w_fem;
    for (size_t j = 0; j < n3; j++)
        c->w_fem += x->f[j] * (x->p[j] - c->x_prev[j]);
    c->work_abs += fabs(c->w_fem - w0);
    memcpy(c->x_prev, x->p, n3 * sizeof *x->p);
    return FEM_EXCHANGE_NEXT;
}

double fem_interface_work_gap(double w_fem, double w_dem, double scale)
{
    double gap = fabs(w_fem - w_dem), ref = fmax(fmax(fabs(w_fem), fabs(w_dem)), scale);
    if (!(gap <= ref)) /* NaN, or larger than both works and the floor */
        return isfinite(gap) && ref > 0 ? gap / ref : INFINITY;
    return ref > 0 ? gap / ref : 0.0;
}

int fem_check_interface_work(double w_fem, double w_dem, double scale, double t, double interval, cm_error *err)
{
    double gap = fabs(w_fem - w_dem);
    if (!(fem_interface_work_gap(w_fem, w_dem, scale) <= FEM_WORK_TOLERANCE))
        return cm_fail(err, CM_ERR_NUMERIC,
                       "coupling unstable at t = %.4f s: the interface work seen by the FEM (%.3g J) and by the DEM "
                       "(%.3g J) differ by %.3g J, more than %.0f %% of the larger and of the contacts' energy scale "
                       "%.3g J. The exchange interval (coupling.dt x coupling.exchange_every = %.3g s) is too long "
                       "for the grain contacts on the lightest surface nodes: reduce coupling.dt",
                       t, w_fem, w_dem, gap, 100 * FEM_WORK_TOLERANCE, scale, interval);
    return CM_OK;
}

/* The guard's floor, the energy scale of the interface: the largest so far of
 *  - the energy the grains have stored in the tire's deformation,
 *    |E_el - E_el(inflated, before contact)|, about F delta / 2 with F
 *    the contact load and delta the tire's deflection under it (0.08-0.09 J
 *    on tests/coupling's small tire at 60-70 N),
 *  - FEM_WORK_ABS_SHARE of the absolute interface work, the sum over the
 *    exchanges of |f . dx| (a rigid tire stores no elastic energy), and
 *  - the elastic energy stored in the grain-surface contacts, as the DEM
 *    reports it (IPC_INFO_CONTACT_ENERGY). Without it the guard judged the
 *    first exchanges of a contact on the ratio of two round-off-sized works:
 *    the work the FEM sees over the first interval of a contact on a node at
 *    rest is twice the DEM's (f h^2 / m against half of it), so a steel
 *    sphere touching a resting rubber block stopped the run at its first
 *    contact (7.5e-30 J against 3.8e-30 J; tests/coupling/block).
 * It matters only where the accumulated work passes through zero (grains
 * pushed, then released): the relative comparison alone would then trip on
 * the O(dt) disagreement of a stable exchange, which on the test scenes
 * stays below 1 % of the work (0.24 % at dt 1e-5, 0.9 % at 5e-5). */
#define FEM_WORK_ABS_SHARE 0.1
static void update_work_scale(fem_coupled *c, double elastic, double contact_energy)
{
    double e = fabs(elastic - c->elastic0), a = FEM_WORK_ABS_SHARE * c->work_abs;
    e = e > a ? e : a;
    e = e > contact_energy ? e : contact_energy;
    c->work_scale = e > c->work_scale ? e : c->work_scale;
}

/* check_work: the coupling stability guard. The work of the interface
 * forces seen by the DEM (f . v dt, velocities it received) and by the FEM
 * (f . dx, how it moved the nodes) agree to O(dt) while the staggered
 * exchange is stable; an unstable exchange pumps energy into the tire and
 * the two diverge long before anything overflows. The floor of the
 * comparison is the problem's own energy scale, see update_work_scale. */
static int stage_check_work(fem_coupled *c, exchange *x, cm_error *err)
{
    fem_get_energy(c->model, &x->en);
    update_work_scale(c, x->en.elastic, x->info[IPC_INFO_CONTACT_ENERGY]);
    c->w_dem_last = x->info[IPC_INFO_DEM_WORK];
    const double t = x->time + c->interval, gap = fem_interface_work_gap(c->w_fem, c->w_dem_last, c->work_scale);
    c->work_gap_max = gap > c->work_gap_max ? gap : c->work_gap_max;
    if (gap > FEM_WORK_WARN && c->work_warned_at == 0.0 && gap <= FEM_WORK_TOLERANCE) {
        c->work_warned_at = t;
        cm_log_warn("t = %.4f s: the interface work seen by the FEM (%.4g J) and by the DEM (%.4g J) are %.1f %% "
                    "apart (a stable exchange stays below 1 %%; the run stops at %.0f %%): the exchange interval "
                    "%.3g s may be too long for the lightest interface nodes (coupling.dt, or "
                    "fem.interface_mass_min)",
                    t, c->w_fem, c->w_dem_last, 100 * gap, 100 * FEM_WORK_TOLERANCE, c->interval);
    }
    return fem_check_interface_work(c->w_fem, c->w_dem_last, c->work_scale, t, c->interval, err);
}

/* send: the wheel's state and the flags, then the frame goes. */
static fem_exchange_status stage_send(fem_coupled *c, exchange *x)
{
    ipc_frame_head *out = x->out;
    out->kind = IPC_FRAME_DATA;
    out->time = x->time + c->interval;
    memcpy(&out->info[IPC_INFO_CENTER_X], c->ds.center, 3 * sizeof(double));
    memcpy(&out->info[IPC_INFO_VEL_X], c->ds.velocity, 3 * sizeof(double));
    out->info[IPC_INFO_OMEGA] = c->ds.omega;
    out->info[IPC_INFO_ANGLE] = c->ds.angle;
    out->info[IPC_INFO_FEM_WORK] = c->w_fem;
    if (c->ds.phase == DRIVE_DONE || x->interrupted)
        out->flags |= IPC_FLAG_STOP_REQUEST;
    c->stop_sent |= x->interrupted;
    x->checkpoint = x->checkpoint && c->ds.phase != DRIVE_DONE;
    if (x->checkpoint)
        out->flags |= IPC_FLAG_CHECKPOINT;
    return ipc_send_commit(c->ch) ? FEM_EXCHANGE_LINK_LOST : FEM_EXCHANGE_NEXT;
}

static void print_progress(fem_coupled *c, const exchange *x, double th_minus_tr, double sinkage, double slip)
{
    double now = cm_now();
    if (!(c->run->progress_every > 0) || now - c->last_progress < c->run->progress_every)
        return;
    c->last_progress = now;
    double t = x->time + c->interval, elapsed = now - c->loop_t0;
    double rate = elapsed > 0 ? (double)(c->n + 1 - c->n_first) / elapsed : 0; /* exchanges per s */
    /* What ends the run: the travel distance while travelling (the wheel's
     * speed gives the exchanges left, unless end_time comes first); while
     * sinking, the time to reach the load is unknown ("-"); a fixed wheel
     * runs to end_time. */
    double by_time = (c->run->end_time - t) / c->interval, remaining = -1;
    const char *by = "end_time";
    if (c->ds.phase == DRIVE_TRAVEL && c->ds.velocity[0] > 0) {
        remaining = (c->drive->travel_distance - c->ds.travelled) / c->ds.velocity[0] / c->interval;
        by = "travel";
    } else if (c->ds.phase == DRIVE_FIXED) {
        remaining = by_time;
    }
    if (remaining >= 0 && by_time < remaining)
        remaining = by_time, by = "end_time";
    char eta[48];
    if (rate > 0 && c->n + 1 - c->n_first >= 2 && remaining >= 0)
        snprintf(eta, sizeof eta, "%5.0f s (%s)", remaining / rate, by);
    else
        snprintf(eta, sizeof eta, "%5s", "-"); /* no rate yet, or nothing to base it on */
    static const char *const phase_names[] = {"sinkage", "travel", "done", "fixed"};
    cm_log_info("%-7s t = %.4f s  %6.0f exch/s  ETA %s  load %8.1f N  T_P %8.1f N  sinkage %6.1f mm  slip %5.1f %%",
                phase_names[c->ds.phase], t, rate, eta, x->info[IPC_INFO_FORCE_Z], th_minus_tr, 1e3 * sinkage,
                100 * slip);
}

/* record: the series row (travel is along +x: T_H pushes the tire forward;
 * My is the grains' moment about the axle; slip the one realised by the
 * motion held for the next interval), the travel series for the summary,
 * a checkpoint when due, the progress line. */
static int stage_record(fem_coupled *c, const exchange *x, cm_error *err)
{
    const double *info = x->info;
    const fem_energy en = x->en;
    double bed = info[IPC_INFO_BED_HEIGHT];
    double th = info[IPC_INFO_TRACTION_POS], tr = info[IPC_INFO_TRACTION_NEG];
    double sinkage = bed != 0 ? bed - (c->ds.center[2] - c->drive->radius) : 0;
    double slip = drive_realised_slip(c->drive, &c->ds);
    double row[NCOL] = {x->time + c->interval, c->ds.phase, c->ds.center[0], c->ds.center[2], c->ds.angle,
                        c->ds.omega, c->ds.velocity[0], slip, info[IPC_INFO_FORCE_X], info[IPC_INFO_FORCE_Y],
                        info[IPC_INFO_FORCE_Z], x->soil.my, th, tr, th - fabs(tr), info[IPC_INFO_CONTACTS], sinkage,
                        en.elastic, en.kinetic, info[IPC_INFO_DEM_WORK], c->w_fem};
    int rc = cm_h5_series_append(c->series, row, err);
    if (rc)
        return rc;
    const double travel_row[SER_N] = {th, tr, th - fabs(tr), sinkage, slip, x->soil.fx, x->soil.my};
    if (c->ds.phase == DRIVE_TRAVEL && series_push(&c->travel, travel_row))
        return cm_fail(err, CM_ERR_NOMEM, "out of memory recording the traction series at exchange %ld", c->n);
    if (x->checkpoint) {
        /* the rows the checkpoint counts are in the files before it is */
        if ((rc = cm_h5_series_flush(c->series, err)))
            return rc;
        series_buf *tv = &c->travel;
        fem_ckpt_run cr = {.exchange = c->n, .drive = &c->ds, .w_fem = c->w_fem,
                           .max_force_mismatch = c->max_force_mismatch, .max_moment_mismatch = c->max_moment_mismatch,
                           .work_abs = c->work_abs, .work_scale = c->work_scale,
                           .work_gap_max = c->work_gap_max, .work_warned_at = c->work_warned_at,
                           .n_nodes = c->nn, .x_prev = c->x_prev, .travel_n = tv->n,
                           .travel = {tv->col[SER_TH], tv->col[SER_TR], tv->col[SER_TP], tv->col[SER_SINK],
                                      tv->col[SER_SLIP], tv->col[SER_FX], tv->col[SER_MY]},
                           .series_rows = cm_h5_series_rows(c->series)};
        double t_ck = cm_now();
        if ((rc = fem_checkpoint_write(c->out, c->model, &cr, c->scene_hash, err)))
            return rc;
        cm_log_info("checkpoint of exchange %ld written (t = %.6f s, %.2f s)%s", c->n, x->time + c->interval,
                    cm_now() - t_ck, x->interrupted ? "; stopping: resume with ./run --resume DIR" : "");
    }
    print_progress(c, x, th - fabs(tr), sinkage, slip);
    return CM_OK;
}

/* ---- the pipeline ---------------------------------------------------------------------------------------- */

/* The clocks at the end of a stage, which is where the next one starts:
 * each clock is read once per stage boundary, not twice. What runs between
 * two stages goes to the next. The wall clock is read at every boundary
 * (27 ns); the CPU clock is a system call (1.4 us on this VM: read at all
 * twelve boundaries, 17 us an exchange, 5 % of the paper scene's FEM step,
 * on the core the FEM shares with the DEM's rank 0), so it is read only
 * next to the stages that wait or can run long: receive (the wait), advance
 * (the step), snapshot and record (files, checkpoints). The short stages
 * between them neither wait nor write: their CPU time is taken as their wall
 * time. Measured at every boundary (the paper scene to t = 1.2 s, session
 * 34), the two agreed within 1.3 % for five of them; place_wheel's wall was
 * 6 % and send's 20 % over (its post wakes the DEM, which can take the
 * core): under 0.1 s in all against the run's 34.6 s of CPU. */
typedef struct stage_clock {
    double wall, cpu;
} stage_clock;

static stage_clock clock_now(void) { return (stage_clock){cm_now(), cm_cpu_now()}; }

/* 1 for the stages whose CPU time is read from the CPU clock. */
static int cpu_read(int id)
{
    return id == FEM_STAGE_RECEIVE || id == FEM_STAGE_ADVANCE || id == FEM_STAGE_SNAPSHOT || id == FEM_STAGE_RECORD;
}

/* Stage id ends: its times into p; the CPU clock read if this stage or the
 * one after it (the stages run in their enum's order) wants it. */
static void lap(fem_profile *p, int id, stage_clock *mark)
{
    const double wall = cm_now();
    const double cpu = cpu_read(id) || (id + 1 < FEM_STAGE_COUNT && cpu_read(id + 1)) ? cm_cpu_now()
                                                                                         : mark->cpu + (wall - mark->wall);
    p->seconds[id] += wall - mark->wall;
    p->cpu_seconds[id] += cpu - mark->cpu;
    *mark = (stage_clock){wall, cpu};
}

/* Times one stage into the profile (wall and CPU time); its status goes to st. */
#define STAGE(id, call)                                                                                        \
    do {                                                                                                       \
        st = (call);                                                                                           \
        lap(&c->prof, id, &mark);                                                                              \
    } while (0)
/* The same, and the exchange ends there unless the stage let it go on. */
#define STAGE_OR_RETURN(id, call)                                                                              \
    do {                                                                                                       \
        STAGE(id, call);                                                                                       \
        if (st != FEM_EXCHANGE_NEXT)                                                                           \
            return st;                                                                                         \
    } while (0)

/* A stage's cm status as the exchange's. */
static fem_exchange_status failed(int rc) { return rc ? FEM_EXCHANGE_FAILED : FEM_EXCHANGE_NEXT; }

fem_exchange_status fem_exchange(fem_coupled *c, cm_error *err)
{
    exchange x;
    memset(&x, 0, sizeof x);
    fem_exchange_status st;
    stage_clock mark = clock_now();
    STAGE_OR_RETURN(FEM_STAGE_RECEIVE, stage_receive(c, &x));
    STAGE(FEM_STAGE_CHECK_FRAME, failed(stage_check_frame(c, &x, err)));
    if (st == FEM_EXCHANGE_NEXT)
        STAGE(FEM_STAGE_CHECK_BALANCE, stage_check_balance(c, &x));
    if (st == FEM_EXCHANGE_NEXT)
        STAGE(FEM_STAGE_PLACE_WHEEL, failed(stage_place_wheel(c, &x, err)));
    if (st != FEM_EXCHANGE_NEXT) { /* from the advance on, the frame is released there */
        ipc_recv_release(c->ch);
        return st;
    }
    STAGE_OR_RETURN(FEM_STAGE_ADVANCE, failed(stage_advance(c, &x, err)));
    STAGE_OR_RETURN(FEM_STAGE_SNAPSHOT, failed(stage_snapshot(c, err)));
    STAGE_OR_RETURN(FEM_STAGE_UPDATE_DRIVE, failed(stage_update_drive(c, &x, err)));
    STAGE_OR_RETURN(FEM_STAGE_PACK_REPLY, stage_pack_reply(c, &x));
    STAGE_OR_RETURN(FEM_STAGE_CHECK_WORK, failed(stage_check_work(c, &x, err)));
    STAGE_OR_RETURN(FEM_STAGE_SEND, stage_send(c, &x));
    STAGE_OR_RETURN(FEM_STAGE_RECORD, failed(stage_record(c, &x, err)));
    c->prof.exchanges++;
    c->n++;
    return FEM_EXCHANGE_NEXT;
}

/* ---- profile --------------------------------------------------------------------------------------------- */

void fem_profile_print(const fem_profile *p)
{
    double total = 0, total_cpu = 0;
    for (int k = 0; k < FEM_STAGE_COUNT; k++)
        total += p->seconds[k], total_cpu += p->cpu_seconds[k];
    cm_log_info("profile of %ld exchanges (wall time per stage, receive is the wait for the DEM; CPU time beside it):",
                p->exchanges);
    for (int k = 0; k < FEM_STAGE_COUNT; k++)
        cm_log_info("  %-13s %9.3f s  %5.1f %%  %9.1f us/exchange  CPU %9.3f s", fem_stage_names[k], p->seconds[k],
                    total > 0 ? 100 * p->seconds[k] / total : 0.0,
                    p->exchanges > 0 ? 1e6 * p->seconds[k] / (double)p->exchanges : 0.0, p->cpu_seconds[k]);
    cm_log_info("  %-13s %9.3f s  CPU %.3f s", "total", total, total_cpu);
}

int fem_profile_write(const fem_profile *p, cm_h5 *h5, cm_error *err)
{
    char name[64];
    int rc = cm_h5_attr_double(h5, "/", "profile_exchanges", (double)p->exchanges, err);
    for (int k = 0; k < FEM_STAGE_COUNT && !rc; k++) {
        snprintf(name, sizeof name, "profile_%s_s", fem_stage_names[k]);
        rc = cm_h5_attr_double(h5, "/", name, p->seconds[k], err);
        if (!rc) {
            snprintf(name, sizeof name, "profile_%s_cpu_s", fem_stage_names[k]);
            rc = cm_h5_attr_double(h5, "/", name, p->cpu_seconds[k], err);
        }
    }
    return rc;
}
