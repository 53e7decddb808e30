/* fem_server: the tire side of the co-simulation.
 *
 *   fem_server --scene FILE --shm NAME [--out DIR]
 *   fem_server --scene FILE --export-mesh FILE.msh   the scene's mesh as Gmsh .msh, then exit
 *   --resume DIR: continue the run of DIR from its last checkpoint
 *
 * Builds the tire model of the scene's `fem` section, solves the initial
 * static state (paper sec. 3.3), creates the exchange segment and publishes
 * the interface surface, then in lockstep with dem_server: receives the
 * interface forces of exchange n, moves the wheel as the `wheel` section
 * prescribes (sinkage, then travel at slip), advances the deformation over
 * the interval and answers the new interface positions and velocities.
 * Records traction, load, sinkage and energies every exchange and prints the
 * traction summary over the detected steady part at the end.
 * Checkpoints (ipc/PROTOCOL.md): this side decides when both save the state
 * after an exchange: every run.checkpoint_every, and when either side is
 * interrupted (SIGINT/SIGTERM; the run then ends cleanly). */
#include <errno.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "ckpt.h"
#include "drive.h"
#include "fem.h"
#include "fem_checkpoint.h"
#include "h5io.h"
#include "ipc.h"
#include "log.h"
#include "runcfg.h"
#include "steady.h"
#include "timer.h"

/* SIGINT/SIGTERM: during the exchange loop (g_graceful) the next exchange
 * is checkpointed and the run ends cleanly (g_interrupt); before that, or if
 * that has not ended the run within 10 s, everything stops at once (g_stop). */
static volatile sig_atomic_t g_stop, g_interrupt, g_graceful;
static void on_signal(int sig)
{
    if (!g_interrupt && g_graceful)
        alarm(10);
    g_interrupt = sig;
    if (!g_graceful)
        g_stop = sig;
}
static void on_alarm(int sig) { g_stop = g_interrupt ? g_interrupt : sig; }

typedef struct options {
    const char *scene, *shm, *out, *export_mesh, *resume;
} options;

/* Columns of the time series (fem.h5:/series and traction.csv). */
enum {
    COL_T, COL_PHASE, COL_X, COL_Z, COL_ANGLE, COL_OMEGA, COL_V, COL_SLIP, COL_FX, COL_FY, COL_FZ, COL_MY,
    COL_TH, COL_TR, COL_TP, COL_CONTACTS, COL_SINKAGE, COL_E_EL, COL_E_KIN, COL_W_DEM, COL_W_FEM, NCOL
};
static const char *const k_columns[NCOL] = {
    "t", "phase", "x", "z", "angle", "omega", "v", "slip", "Fx", "Fy", "Fz", "My",
    "T_H", "T_R", "T_P", "contacts", "sinkage", "E_elastic", "E_kinetic", "W_dem", "W_fem"};

/* The travel phase's series for the summary (grown by doubling). */
enum { SER_TH, SER_TR, SER_TP, SER_SINK, SER_SLIP, SER_FX, SER_MY, SER_N };
_Static_assert(SER_N == FEM_CKPT_TRAVEL_COLS, "the checkpoint keeps every column of the travel series");
typedef struct series_buf {
    double *col[SER_N];
    size_t n, cap;
} series_buf;

static int series_push(series_buf *b, const double row[SER_N])
{
    if (b->n == b->cap) {
        size_t cap = b->cap ? 2 * b->cap : 4096;
        for (int k = 0; k < SER_N; k++) {
            double *p = realloc(b->col[k], cap * sizeof(double));
            if (!p)
                return -1;
            b->col[k] = p;
        }
        b->cap = cap;
    }
    for (int k = 0; k < SER_N; k++)
        b->col[k][b->n] = row[k];
    b->n++;
    return 0;
}

static void series_free(series_buf *b)
{
    for (int k = 0; k < SER_N; k++)
        free(b->col[k]);
}

static void rotation_about_y(double angle, double R[9])
{
    double c = cos(angle), s = sin(angle);
    const double r[9] = {c, 0, s, 0, 1, 0, -s, 0, c};
    memcpy(R, r, sizeof r);
}

static int set_wheel(fem_model *m, const drive_state *ds, cm_error *err)
{
    fem_wheel w;
    memset(&w, 0, sizeof w);
    memcpy(w.center, ds->center, sizeof w.center);
    rotation_about_y(ds->angle, w.R);
    memcpy(w.v_center, ds->velocity, sizeof w.v_center);
    w.omega[1] = ds->omega;
    return fem_set_wheel(m, &w, err);
}

static void print_summary_line(const char *name, const double *x, size_t n, size_t start)
{
    steady_stats st;
    steady_summary(x, n, start, &st);
    cm_log_info("  %-4s mean %9.2f N  (95%% CI +-%7.2f N, %d batches)  min %9.2f  max %9.2f", name, st.mean,
                st.half_width, st.batches, st.min, st.max);
}

static const char *const k_control_names[] = {"slip", "torque", "drawbar"};

/* The traction summary over the steady part of the travel. Under torque or
 * drawbar control the slip is the outcome and settles too: the steady part
 * starts where both the drawbar pull and the slip are steady. */
static void print_traction_summary(const drive_def *d, const series_buf *tr, double interval)
{
    size_t start = steady_start(tr->col[SER_TP], tr->n);
    if (d->control != DRIVE_CONTROL_SLIP) {
        size_t s_slip = steady_start(tr->col[SER_SLIP], tr->n);
        start = s_slip > start ? s_slip : start;
    }
    char what[160];
    if (d->control == DRIVE_CONTROL_SLIP)
        snprintf(what, sizeof what, "slip %.1f %%", 100 * d->slip);
    else if (d->control == DRIVE_CONTROL_TORQUE)
        snprintf(what, sizeof what, "axle torque %g N m at v = %g m/s", d->torque, d->velocity);
    else
        snprintf(what, sizeof what, "drawbar load %g N at omega = %g rad/s", d->drawbar, d->omega);
    cm_log_info("traction over the steady part of the travel: from exchange %zu of %zu (t = %.3f s after "
                "travel began), %s",
                start, tr->n, (double)start * interval, what);
    print_summary_line("T_H", tr->col[SER_TH], tr->n, start);
    print_summary_line("T_R", tr->col[SER_TR], tr->n, start);
    print_summary_line("T_P", tr->col[SER_TP], tr->n, start);
    steady_stats st;
    steady_summary(tr->col[SER_SINK], tr->n, start, &st);
    cm_log_info("  sinkage mean %.1f mm (95%% CI +-%.1f mm)", 1e3 * st.mean, 1e3 * st.half_width);
    if (d->control == DRIVE_CONTROL_SLIP)
        return;
    steady_summary(tr->col[SER_SLIP], tr->n, start, &st);
    cm_log_info("  slip mean %.2f %% (95%% CI +-%.2f %%)  min %.2f %%  max %.2f %% (realised, %s control)",
                100 * st.mean, 100 * st.half_width, 100 * st.min, 100 * st.max, k_control_names[d->control]);
    /* The equation of motion's balance: the soil carries what is prescribed. */
    if (d->control == DRIVE_CONTROL_TORQUE) {
        steady_summary(tr->col[SER_MY], tr->n, start, &st);
        cm_log_info("  soil moment about the axle mean %.3f N m (95%% CI +-%.3f N m) against the axle torque %g N m",
                    st.mean, st.half_width, d->torque);
    } else {
        steady_summary(tr->col[SER_FX], tr->n, start, &st);
        cm_log_info("  soil force along the travel mean %.2f N (95%% CI +-%.2f N) against the drawbar load %g N",
                    st.mean, st.half_width, d->drawbar);
    }
}

static int run(const options *o)
{
    cm_error err = {0};
    cm_scene *scene = NULL;
    fem_model *model = NULL;
    ipc_channel *ch = NULL;
    cm_h5 *h5 = NULL;
    cm_h5_series *series = NULL;
    double *x_prev = NULL, *x_now = NULL, *v_now = NULL;
    series_buf travel = {0};
    int exit_code = 1, rc, clean_stop = 0;

    cm_run_config rc_cfg;
    drive_def drive = drive_def_default();
    fem_config cfg = fem_config_default();
    if ((rc = cm_scene_open(o->scene, &scene, &err)) || (rc = cm_run_config_read(scene, &rc_cfg, &err)) ||
        (rc = drive_config_read(scene, &drive, &err)) || (rc = fem_config_read(scene, &cfg, &err)))
        goto fail;
    static const char *const sections[] = {"run", "coupling", "wheel", "fem", NULL};
    cm_scene_skip_foreign(scene, sections); /* dem, scm: the terrain's */
    if ((rc = cm_scene_check_unknown(scene, sections, &err)))
        goto fail;
    /* Resuming, the results files are reopened after the checkpoint is read. */
    snprintf(cfg.output_dir, sizeof cfg.output_dir, "%s", o->export_mesh || o->resume ? "" : o->out);
    uint64_t scene_hash = 0;
    long resume_exchange = -1;
    char ckpt_path[1100] = "";
    if ((rc = cm_ckpt_file_hash(o->scene, &scene_hash, &err)))
        goto fail;
    scene_hash = cm_scene_overrides_hash(scene_hash);
    if (o->resume) {
        char dem_path[1100];
        if ((rc = cm_ckpt_choose(o->resume, &resume_exchange, dem_path, ckpt_path, sizeof ckpt_path, &err)))
            goto fail;
    }

    double t0 = cm_now();
    if ((rc = fem_create(&cfg, &model, &err)))
        goto fail;
    if (o->export_mesh) {
        if ((rc = fem_write_mesh_gmsh(model, o->export_mesh, &err)))
            goto fail;
        cm_log_info("mesh written to %s", o->export_mesh);
        exit_code = 0;
        goto cleanup;
    }
    int n_mesh_nodes, n_tets;
    fem_mesh_size(model, &n_mesh_nodes, &n_tets);
    if ((rc = fem_solve_static(model, &err)))
        goto fail;
    fem_stability stab;
    fem_get_stability(model, &stab);
    cm_log_info("tire: %d nodes, %d tetrahedra; static solve done in %.2f s; FEM step limit %.3g s "
                "(estimate h/c %.3g s)",
                n_mesh_nodes, n_tets, cm_now() - t0, stab.dt_limit, stab.dt_estimate);

    double mesh_mass, mesh_inertia;
    fem_mass_properties(model, &mesh_mass, &mesh_inertia);
    drive_resolve(&drive, mesh_mass, mesh_inertia);
    if (drive.motion != DRIVE_HOLD) {
        char used[160] = "";
        if (drive.motion == DRIVE_LOAD_TRAVEL || drive.control == DRIVE_CONTROL_DRAWBAR)
            snprintf(used, sizeof used, "; mass %.3g kg", drive.mass);
        if (drive.control == DRIVE_CONTROL_TORQUE)
            snprintf(used + strlen(used), sizeof used - strlen(used), "; inertia %.3g kg m^2", drive.inertia);
        cm_log_info("wheel: %s, %s control%s (tire mesh: %.3g kg, %.3g kg m^2 about the axle)",
                    drive.motion == DRIVE_LOAD_TRAVEL ? "load_travel" : "sink_travel",
                    k_control_names[drive.control], used, mesh_mass, mesh_inertia);
    }
    if (drive.motion == DRIVE_LOAD_TRAVEL)
        cm_log_info("wheel: vertical damper %.4g N s/m (%.2f of critical on the reference soil stiffness %.3g N/m)",
                    drive.damping, drive.damping / (2.0 * sqrt(DRIVE_SOIL_STIFFNESS_REF * drive.mass)),
                    DRIVE_SOIL_STIFFNESS_REF);
    drive_state ds;
    drive_start(&drive, &ds);
    if ((rc = set_wheel(model, &ds, &err)))
        goto fail;

    /* The exchange segment, sized for the interface surface. */
    uint32_t nn, nt;
    fem_interface_count(model, &nn, &nt);
    ipc_create_def def = ipc_default_create_def();
    def.n_nodes = nn;
    def.n_tris = nt;
    def.exchange_dt = cm_run_exchange_dt(&rc_cfg);
    def.stall_timeout = rc_cfg.stall_timeout;
    def.connect_timeout = rc_cfg.connect_timeout;
    def.stop_flag = &g_stop;
    char ipc_err[512];
    if ((rc = ipc_create(o->shm, &def, &ch, ipc_err, sizeof ipc_err))) {
        cm_log_error("%s", ipc_err);
        exit_code = 3;
        goto cleanup;
    }
    x_prev = malloc(3 * (size_t)nn * sizeof(double));
    x_now = malloc(3 * (size_t)nn * sizeof(double));
    v_now = malloc(3 * (size_t)nn * sizeof(double));
    if (!x_prev || !x_now || !v_now) {
        cm_fail(&err, CM_ERR_NOMEM, "out of memory for %u interface nodes", nn);
        goto fail;
    }
    fem_interface_state(model, ipc_surface_nodes(ch), NULL);
    fem_interface_initial(model, NULL, ipc_surface_tris(ch), NULL);
    fem_interface_masses(model, ipc_surface_masses(ch));
    memcpy(x_prev, ipc_surface_nodes(ch), 3 * (size_t)nn * sizeof(double));
    cm_log_info("interface: %u nodes, %u triangles; waiting for dem_server on %s", nn, nt, o->shm);
    if ((rc = ipc_accept(ch))) {
        if (g_stop) /* stopped by the launcher because the other side failed: that side says why */
            cm_log_info("stopped by signal %d while waiting for dem_server", (int)g_stop);
        else
            cm_log_error("%s", ipc_error(ch));
        exit_code = 3;
        goto cleanup;
    }

    const double interval = cm_run_exchange_dt(&rc_cfg);
    double w_fem = 0, max_force_mismatch = 0, max_moment_mismatch = 0;
    long n = 0, series_rows = 0;
    if (o->resume) {
        fem_ckpt_run cr = {.drive = &ds, .n_nodes = nn, .x_prev = x_prev};
        rc = fem_checkpoint_read(ckpt_path, resume_exchange, model, &cr, scene_hash, o->out, &err);
        if (rc == CM_OK)
            rc = cm_ckpt_adopt(ckpt_path, &err);
        if (rc == CM_OK) {
            series_free(&travel);
            for (int k = 0; k < SER_N; k++)
                travel.col[k] = cr.travel[k];
            travel.n = travel.cap = cr.travel_n;
        } else {
            for (int k = 0; k < SER_N; k++)
                free(cr.travel[k]);
        }
        if (rc || (rc = set_wheel(model, &ds, &err)))
            goto fail;
        w_fem = cr.w_fem;
        max_force_mismatch = cr.max_force_mismatch;
        max_moment_mismatch = cr.max_moment_mismatch;
        series_rows = cr.series_rows;
        n = resume_exchange + 1;
        cm_log_info("resuming from %s after exchange %ld (t = %.6f s)", ckpt_path, resume_exchange, fem_time(model));
    }

    /* Outputs. */
    char path[1200], csv[1200];
    snprintf(path, sizeof path, "%s/wheel.h5", o->out);
    snprintf(csv, sizeof csv, "%s/traction.csv", o->out);
    cm_h5_def hdef = cm_h5_default_def();
    if (o->resume ? ((rc = cm_h5_reopen(path, &hdef, -1, &h5, &err)) ||
                     (rc = cm_h5_series_reopen(h5, "/series", k_columns, NCOL, csv, series_rows, &series, &err)))
                  : ((rc = cm_h5_create(path, &hdef, &h5, &err)) ||
                     (rc = cm_h5_series_create(h5, "/series", k_columns, NCOL, csv, &series, &err))))
        goto fail;

    const long ckpt_every = cm_run_checkpoint_exchanges(&rc_cfg);
    double w_dem_last = 0; /* J, the DEM's interface work in the last frame, for the summary */
    double last_progress = cm_now(), loop_t0 = cm_now();
    const long n_first = n;
    int finished = 0, stop_sent = 0;
    g_graceful = 1; /* from here a signal asks for a checkpoint */
    if (g_interrupt)
        alarm(10);
    for (;; n++) {
        const ipc_frame_head *in;
        const double *f;
        if ((rc = ipc_recv(ch, &in, &f)))
            break;
        if (in->kind == IPC_FRAME_FINISH) {
            ipc_recv_release(ch);
            ipc_frame_head *out;
            double *p;
            if ((rc = ipc_send_begin(ch, &out, &p)))
                break;
            out->kind = IPC_FRAME_FINISH;
            rc = ipc_send_commit(ch);
            finished = 1;
            break;
        }
        double time = in->time, info[IPC_INFO_LEN];
        memcpy(info, in->info, sizeof info);
        /* A checkpoint of this exchange: periodic, or either side interrupted
         * (then the run stops after it). Not once the drive is done: the run
         * ends at the next exchange anyway. */
        int interrupted = (g_interrupt || (in->flags & IPC_FLAG_CHECKPOINT)) && !stop_sent;
        int checkpoint = (interrupted || (ckpt_every > 0 && (n + 1) % ckpt_every == 0)) && ds.phase != DRIVE_DONE;

        /* Conservation: nodal forces against the contact totals (eq. 42 keeps
         * resultant and moment); positions are those the DEM saw, moments
         * about the world origin as the protocol defines them. */
        double fs[3] = {0}, ms[3] = {0};
        for (uint32_t i = 0; i < nn; i++) {
            const double *fi = f + 3 * i, *r = x_prev + 3 * i;
            fs[0] += fi[0], fs[1] += fi[1], fs[2] += fi[2];
            ms[0] += r[1] * fi[2] - r[2] * fi[1];
            ms[1] += r[2] * fi[0] - r[0] * fi[2];
            ms[2] += r[0] * fi[1] - r[1] * fi[0];
        }
        double fscale = 1e-9 + fabs(info[IPC_INFO_FORCE_X]) + fabs(info[IPC_INFO_FORCE_Y]) +
                        fabs(info[IPC_INFO_FORCE_Z]);
        for (int k = 0; k < 3; k++) {
            double df = fabs(fs[k] - info[IPC_INFO_FORCE_X + k]) / fscale;
            double dm = fabs(ms[k] - info[IPC_INFO_MOMENT_X + k]) / (fscale * drive.radius);
            max_force_mismatch = df > max_force_mismatch ? df : max_force_mismatch;
            max_moment_mismatch = dm > max_moment_mismatch ? dm : max_moment_mismatch;
        }

        /* Gentle placement: at the first exchange, lower the wheel until its
         * lowest surface point is start_gap above the highest grain. */
        double bed = info[IPC_INFO_BED_HEIGHT], bed_top = info[IPC_INFO_BED_TOP];
        if (n == 0 && drive.start_gap > 0 && bed_top != 0) {
            double lowest = x_prev[2];
            for (uint32_t i = 1; i < nn; i++)
                lowest = x_prev[3 * i + 2] < lowest ? x_prev[3 * i + 2] : lowest;
            ds.center[2] += bed_top + drive.start_gap - lowest;
            cm_log_info("bed surface at z = %.4f m (highest grain top %.4f m): wheel lowered to %.1f mm above it",
                        bed, bed_top, 1e3 * drive.start_gap);
        }

        /* Advance the tire over the interval with the motion decided last time. */
        if ((rc = set_wheel(model, &ds, &err)) || (rc = fem_advance(model, f, interval, &err))) {
            ipc_recv_release(ch);
            goto fail;
        }
        ipc_recv_release(ch);
        /* The grains' force and their moment about the axle, M_o - c x F
         * (the centre as it was when the DEM computed them). */
        double load = info[IPC_INFO_FORCE_Z];
        const double *c = ds.center;
        drive_soil soil = {info[IPC_INFO_FORCE_X], load,
                           info[IPC_INFO_MOMENT_Y] - (c[2] * info[IPC_INFO_FORCE_X] - c[0] * info[IPC_INFO_FORCE_Z])};
        if ((rc = drive_update(&drive, &ds, time + interval, interval, &soil, &err)))
            goto fail;
        if ((rc = set_wheel(model, &ds, &err)))
            goto fail;

        ipc_frame_head *out;
        double *p;
        if ((rc = ipc_send_begin(ch, &out, &p)))
            break;
        fem_interface_state(model, p, p + 3 * (size_t)nn);
        /* Work of the interface forces on the surface as the FEM moved it. */
        for (size_t j = 0; j < 3 * (size_t)nn; j++)
            w_fem += f[j] * (p[j] - x_prev[j]);
        memcpy(x_prev, p, 3 * (size_t)nn * sizeof(double));
        /* Coupling stability guard: the work of the interface forces seen by
         * the DEM (f . v dt, velocities it received) and by the FEM (f . dx,
         * how it moved the nodes) agree to O(dt) while the staggered exchange
         * is stable; an unstable exchange pumps energy into the tire and the
         * two diverge long before anything overflows. */
        double w_dem = info[IPC_INFO_DEM_WORK], gap = fabs(w_fem - w_dem);
        w_dem_last = w_dem;
        if (gap > 1.0 && gap > 0.25 * fmax(fabs(w_fem), fabs(w_dem))) {
            cm_fail(&err, CM_ERR_NUMERIC,
                    "coupling unstable at t = %.4f s: the interface work seen by the FEM (%.3g J) and by the DEM "
                    "(%.3g J) diverge. The exchange interval (coupling.dt x coupling.exchange_every = %.3g s) is "
                    "too long for the grain contacts on the lightest surface nodes: reduce coupling.dt",
                    time + interval, w_fem, w_dem, interval);
            goto fail;
        }
        out->kind = IPC_FRAME_DATA;
        out->time = time + interval;
        memcpy(&out->info[IPC_INFO_CENTER_X], ds.center, 3 * sizeof(double));
        memcpy(&out->info[IPC_INFO_VEL_X], ds.velocity, 3 * sizeof(double));
        out->info[IPC_INFO_OMEGA] = ds.omega;
        out->info[IPC_INFO_ANGLE] = ds.angle;
        out->info[IPC_INFO_FEM_WORK] = w_fem;
        if (ds.phase == DRIVE_DONE || interrupted)
            out->flags |= IPC_FLAG_STOP_REQUEST;
        stop_sent |= interrupted;
        checkpoint = checkpoint && ds.phase != DRIVE_DONE;
        if (checkpoint)
            out->flags |= IPC_FLAG_CHECKPOINT;
        if ((rc = ipc_send_commit(ch)))
            break;

        /* Record. Travel is along +x: T_H pushes the tire forward. My is the
         * grains' moment about the axle; slip the one realised by the motion
         * held for the next interval. */
        fem_energy en;
        fem_get_energy(model, &en);
        double th = info[IPC_INFO_TRACTION_POS], tr = info[IPC_INFO_TRACTION_NEG];
        double sinkage = bed != 0 ? bed - (ds.center[2] - drive.radius) : 0;
        double slip = drive_realised_slip(&drive, &ds);
        double row[NCOL] = {time + interval, ds.phase, ds.center[0], ds.center[2], ds.angle, ds.omega,
                            ds.velocity[0], slip, info[IPC_INFO_FORCE_X], info[IPC_INFO_FORCE_Y],
                            info[IPC_INFO_FORCE_Z], soil.my, th, tr, th - fabs(tr), info[IPC_INFO_CONTACTS], sinkage,
                            en.elastic, en.kinetic, info[IPC_INFO_DEM_WORK], w_fem};
        if ((rc = cm_h5_series_append(series, row, &err)))
            goto fail;
        const double travel_row[SER_N] = {th, tr, th - fabs(tr), sinkage, slip, soil.fx, soil.my};
        if (ds.phase == DRIVE_TRAVEL && series_push(&travel, travel_row)) {
            cm_fail(&err, CM_ERR_NOMEM, "out of memory recording the traction series");
            goto fail;
        }
        /* Tire snapshots: fem_advance writes one every fem.output.every calls. */
        if (checkpoint) {
            fem_ckpt_run cr = {.exchange = n, .drive = &ds, .w_fem = w_fem,
                               .max_force_mismatch = max_force_mismatch, .max_moment_mismatch = max_moment_mismatch,
                               .n_nodes = nn, .x_prev = x_prev, .travel_n = travel.n,
                               .travel = {travel.col[SER_TH], travel.col[SER_TR], travel.col[SER_TP],
                                          travel.col[SER_SINK], travel.col[SER_SLIP], travel.col[SER_FX],
                                          travel.col[SER_MY]},
                               .series_rows = cm_h5_series_rows(series)};
            double t_ck = cm_now();
            if ((rc = fem_checkpoint_write(o->out, model, &cr, scene_hash, &err)))
                goto fail;
            cm_log_info("checkpoint of exchange %ld written (t = %.6f s, %.2f s)%s", n, time + interval,
                        cm_now() - t_ck, interrupted ? "; stopping: resume with ./run --resume DIR" : "");
        }

        double now = cm_now();
        if (rc_cfg.progress_every > 0 && now - last_progress >= rc_cfg.progress_every) {
            last_progress = now;
            double rate = (double)(n + 1 - n_first) / (now - loop_t0);
            double remaining = (rc_cfg.end_time - (time + interval)) / interval;
            if (ds.phase == DRIVE_TRAVEL && ds.velocity[0] > 0) {
                double by_travel = (drive.travel_distance - ds.travelled) / ds.velocity[0] / interval;
                remaining = by_travel < remaining ? by_travel : remaining;
            }
            static const char *const phase_names[] = {"sinkage", "travel", "done", "fixed"};
            cm_log_info("%-7s t = %.4f s  %6.0f exch/s  ETA %5.0f s  load %8.1f N  T_P %8.1f N  sinkage %6.1f mm"
                        "  slip %5.1f %%",
                        phase_names[ds.phase], time + interval, rate, remaining > 0 ? remaining / rate : 0, load,
                        th - fabs(tr), 1e3 * sinkage, 100 * slip);
        }
    }
    g_graceful = 0;
    if (!finished) {
        cm_log_error("%s", ipc_error(ch));
        exit_code = g_stop ? 128 + (int)g_stop : 3;
        goto cleanup;
    }

    ipc_stats st = ipc_get_stats(ch);
    cm_log_info("finished: %ld exchanges in %.1f s; waited for the DEM %.1f s", n, cm_now() - loop_t0,
                st.wait_recv_s + st.wait_send_s);
    cm_log_info("conservation: nodal forces vs contact totals differ by at most %.2e (force) and %.2e (moment), "
                "relative",
                max_force_mismatch, max_moment_mismatch);
    /* The coupling's own error: energy the staggered exchange created (> 0)
     * or destroyed (< 0) at the interface over the run. */
    cm_log_info("interface work of the grains on the tire: seen by the DEM %.6g J, by the FEM %.6g J; FEM - DEM "
                "= %.3g J (%.2g %% of the larger), the coupling's own error at exchange interval %.3g s",
                w_dem_last, w_fem, w_fem - w_dem_last,
                fmax(fabs(w_fem), fabs(w_dem_last)) > 0 ? 100 * (w_fem - w_dem_last) / fmax(fabs(w_fem), fabs(w_dem_last))
                                                        : 0.0,
                interval);
    if (travel.n > 0) {
        print_traction_summary(&drive, &travel, interval);
        if (drive.control != DRIVE_CONTROL_SLIP)
            cm_log_info("  wheel.max_accel or a stop limited the motion at %ld of %zu travel exchanges",
                        ds.rate_limited, travel.n);
    } else {
        cm_log_info("the wheel never reached the travel phase (target load %g N): no traction summary",
                    drive.target_load);
    }
    cm_log_info("results: %s/traction.csv, %s/wheel.h5", o->out, o->out);
    cm_log_info("final state: fem_state_hash %016llx", (unsigned long long)fem_state_hash(model));
    exit_code = g_interrupt ? 128 + (int)g_interrupt : 0;
    clean_stop = 1;
    goto cleanup;

fail:
    cm_log_error("%s", err.msg);
    if (ch)
        ipc_fail(ch, "fem_server: %s", err.msg);
    exit_code = 1;
cleanup:
    if (h5 && cm_h5_close(&h5, &err))
        cm_log_error("%s", err.msg);
    /* interrupted but finished cleanly (checkpoint written, finish answered): not a failure for the peer */
    ipc_close(&ch, exit_code == 0 || clean_stop ? IPC_OK : IPC_ERR_PEER_FAILED);
    fem_destroy(&model);
    cm_scene_close(&scene);
    series_free(&travel);
    free(x_prev);
    free(x_now);
    free(v_now);
    return exit_code;
}

static int usage(void)
{
    fprintf(stderr, "usage: fem_server --scene FILE --shm /NAME [--out DIR] [--resume DIR] [--set KEY=VALUE]...\n"
                    "       fem_server --scene FILE --export-mesh FILE.msh\n"
                    "  The tire side of the co-simulation; run both servers with ./run SCENE.\n"
                    "  --export-mesh writes the scene's mesh (e.g. the built-in tire) as Gmsh .msh v4.1\n"
                    "  with the physical groups rim, cavity and contact, and exits.\n"
                    "  --set overrides a scene setting, e.g. --set fem.mesh.resolution=0.5 (repeatable).\n");
    return 2;
}

int main(int argc, char **argv)
{
    options o = {0};
    o.out = "out";
    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--scene") == 0 && i + 1 < argc)
            o.scene = argv[++i];
        else if (strcmp(argv[i], "--shm") == 0 && i + 1 < argc)
            o.shm = argv[++i];
        else if (strcmp(argv[i], "--out") == 0 && i + 1 < argc)
            o.out = argv[++i];
        else if (strcmp(argv[i], "--resume") == 0 && i + 1 < argc)
            o.resume = o.out = argv[++i];
        else if (strcmp(argv[i], "--export-mesh") == 0 && i + 1 < argc)
            o.export_mesh = argv[++i];
        else if (strcmp(argv[i], "--set") == 0 && i + 1 < argc) {
            cm_error err = {0};
            if (cm_scene_add_override(argv[++i], &err)) {
                fprintf(stderr, "fem_server: %s\n", err.msg);
                return 2;
            }
        } else
            return usage();
    }
    if (!o.scene || (!o.shm && !o.export_mesh))
        return usage();
    cm_log_set_tag("fem");
    cm_h5_library_init();
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal; /* no SA_RESTART: waits wake up and see the flag */
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    sa.sa_handler = on_alarm;
    sigaction(SIGALRM, &sa, NULL);
    if (!o.export_mesh && mkdir(o.out, 0755) != 0 && errno != EEXIST) {
        cm_log_error("cannot create output folder %s: %s", o.out, strerror(errno));
        return 1;
    }
    return run(&o);
}
