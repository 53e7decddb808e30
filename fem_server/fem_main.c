/* fem_server: the tire side of the co-simulation.
 *
 *   fem_server --scene FILE --shm NAME [--out DIR]
 *   mpirun -np N dem_server ... --shm mpi : -np 1 fem_server ... --shm mpi   the same over MPI
 *   fem_server --scene FILE --export-mesh FILE.msh   the scene's mesh as Gmsh .msh, then exit
 *   fem_server --scene FILE --print-config[=json]    the resolved scene (file + --set), then exit
 *   fem_server --scene FILE --fem-only [--out DIR]   the tire model alone (fem.supports, fem.loads)
 *   --resume DIR: continue the run of DIR from its last checkpoint
 *
 * Builds the tire model of the scene's `fem` section, solves the initial
 * static state (paper sec. 3.3), creates the exchange segment and publishes
 * the interface surface, then in lockstep with dem_server: receives the
 * interface forces of exchange n, moves the wheel as the `wheel` section
 * prescribes (sinkage, then travel at slip), advances the deformation over
 * the interval and answers the new interface positions and velocities: one
 * fem_exchange() per exchange, a pipeline of timed stages (fem_exchange.h).
 * Records traction, load, sinkage and energies every exchange; at the end
 * (finish_run) writes and prints the traction summary (fem_summary.c) over the detected steady part
 * and the stages' profile, which it also writes to wheel.h5.
 * Checkpoints (ipc/PROTOCOL.md): this side decides when both save the state
 * after an exchange: every run.checkpoint_every, and when either side is
 * interrupted (SIGINT/SIGTERM; the run then ends cleanly). */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "ckpt.h"
#include "drive.h"
#include "fem.h"
#include "fem_checkpoint.h"
#include "fem_exchange.h"
#include "h5io.h"
#include "ipc.h"
#include "log.h"
#include "runcfg.h"
#include "runrec.h"
#include "signals.h"
#include "fem_summary.h" /* [traction] */
#include "timer.h"
#ifdef DEMFEM_MPI
#include "ipc_mpi.h"
#endif

/* SIGINT/SIGTERM: common/signals.h (checkpoint the next exchange and stop,
 * or stop at once before the exchange loop or 10 s later). */
static cm_signal_flags *g_sig;

typedef struct options {
    const char *scene, *shm, *out, *export_mesh, *resume;
    int print_config, fem_only;
} options;

/* The record stage's hook: tire snapshots (fem.h5) every fem.output.every
 * exchanges. fem_advance itself writes nothing. */
static int after_advance(fem_model *m, void *user, long exchange, cm_error *err)
{
    (void)user;
    (void)exchange;
    return fem_output_due(m, err);
}

static const char *const k_control_names[] = {"slip", "torque", "drawbar"};

/* The end of a coupled run: the summaries of what the run measured. The
 * machine-readable summary (issue 18, fem_server/steady.c's owner) is
 * written here too, next to the profile: see the marked line. */
static int finish_run(const options *o, fem_coupled *c, cm_h5 *h5, double lug_period, cm_error *err)
{
    const drive_def *drive = c->drive;
    ipc_stats st = ipc_get_stats(c->ch);
    cm_log_info("finished: %ld exchanges in %.1f s; waited for the DEM %.1f s", c->n, cm_now() - c->loop_t0,
                st.wait_recv_s + st.wait_send_s);
    cm_log_info("conservation: nodal forces vs contact totals differ by at most %.2e (force) and %.2e (moment), "
                "relative",
                c->max_force_mismatch, c->max_moment_mismatch);
    /* The coupling's own error: energy the staggered exchange created (> 0)
     * or destroyed (< 0) at the interface over the run. */
    double w_fem = c->w_fem, w_dem = c->w_dem_last, wmax = fmax(fabs(w_fem), fabs(w_dem));
    cm_log_info("interface work of the grains on the tire: seen by the DEM %.6g J, by the FEM %.6g J; FEM - DEM "
                "= %.3g J (%.2g %% of the larger), the coupling's own error at exchange interval %.3g s",
                w_dem, w_fem, w_fem - w_dem, wmax > 0 ? 100 * (w_fem - w_dem) / wmax : 0.0, c->interval);
    fem_profile_print(&c->prof);
    int rc = fem_profile_write(&c->prof, h5, err);
    if (rc || (rc = cm_h5_flush(h5, err)))
        return rc;
    /* [traction] The summary, from the recorded series (fem_summary.c):
     * wheel.h5:/summary and summary.json; logged there. */
    fem_summary_def sdef = {.out_dir = o->out, .scene = o->scene, .control = drive->control,
                            .motion = drive->motion, .target_load = drive->target_load, .radius = drive->radius,
                            .interval = c->interval, .lug_period = lug_period, .slip = drive->slip,
                            .torque = drive->torque, .drawbar = drive->drawbar,
                            .travel_distance = drive->travel_distance, .travelled = c->ds.travelled,
                            .travel_done = c->ds.phase == DRIVE_DONE, .fem_state_hash = fem_state_hash(c->model),
                            .work_dem = w_dem, .work_fem = w_fem, .work_gap_max = c->work_gap_max,
                            .work_warned_at = c->work_warned_at, .work_warn = FEM_WORK_WARN};
    if ((rc = fem_summary_write(&sdef, err)) < 0)
        return rc;
    /* [/traction] */
    if (c->travel.n > 0 && drive->control != DRIVE_CONTROL_SLIP)
        cm_log_info("  wheel.max_accel or a stop limited the motion at %ld of %zu travel exchanges",
                    c->ds.rate_limited, c->travel.n);
    cm_log_info("results: %s/traction.csv, %s/wheel.h5, %s/summary.json", o->out, o->out, o->out);
    cm_log_info("final state: fem_state_hash %016llx", (unsigned long long)fem_state_hash(c->model));
    return CM_OK;
}

/* --fem-only: the tire model alone, no DEM peer (verification, e.g. a bar
 * under an end load): the static solve under the scene's supports and
 * loads, or (fem.analysis = "dynamic") the response from rest to
 * run.end_time, snapshots every fem.output.every steps. Results in fem.h5
 * and fem_series.csv. */
static int run_fem_only(const options *o, cm_scene *scene, fem_config *cfg, cm_run_record *rec, cm_error *err)
{
    double end_time = 0;
    int rc = cm_scene_double_opt(scene, "run.end_time", 0.0, 1e9, 0.0, &end_time, err);
    if (rc)
        return rc;
    if (cfg->floor && cfg->analysis != FEM_ANALYSIS_STATIC)
        return cm_fail(err, CM_ERR_KEY, "%s: fem.floor needs fem.analysis = \"static\" (the kinematic floor is an "
                       "active set of the static solve)", o->scene);
    if (cfg->analysis == FEM_ANALYSIS_DYNAMIC && !(end_time > 0))
        return cm_fail(err, CM_ERR_KEY, "%s: fem.analysis = \"dynamic\" needs run.end_time > 0", o->scene);
    cm_scene_mark_known(scene, "run");
    cm_scene_mark_known(scene, "coupling");
    cm_scene_mark_known(scene, "wheel");
    cm_scene_mark_known(scene, "dem");
    static const char *const sections[] = {"run", "coupling", "wheel", "fem", "dem", NULL};
    if ((rc = cm_scene_check_unknown(scene, sections, err)))
        return rc;
    snprintf(cfg->output_dir, sizeof cfg->output_dir, "%s", o->out);
    fem_model *m = NULL;
    if ((rc = fem_create(cfg, &m, err)))
        return rc;
    double t0 = cm_now();
    if (cfg->analysis == FEM_ANALYSIS_STATIC && cfg->floor) {
        fem_floor_result fr;
        if ((rc = fem_floor_static(m, &fr, err)) == CM_OK) {
            cm_log_info("floor: at z = %.6g m, %.6g m above the set's lowest point (the deflection): reaction %.6g N "
                        "on %d nodes, deepest node %.3g m below it; %d active-set passes, %d factorization(s) of K, "
                        "%d influence columns, %.2f s",
                        fr.height, fr.deflection, fr.reaction, fr.contact_nodes, fr.max_below, fr.solves,
                        fr.factorizations, fr.columns, cm_now() - t0);
            cm_runrec_num(rec, "floor_height", fr.height);
            cm_runrec_num(rec, "floor_deflection", fr.deflection);
            cm_runrec_num(rec, "floor_reaction", fr.reaction);
            cm_runrec_num(rec, "floor_contact_nodes", fr.contact_nodes);
            cm_runrec_num(rec, "floor_max_below", fr.max_below);
            rc = fem_write_snapshot(m, err);
        }
    } else if (cfg->analysis == FEM_ANALYSIS_STATIC) {
        if ((rc = fem_solve_static(m, err)) == CM_OK)
            rc = fem_write_snapshot(m, err);
    } else { /* from rest, the loads applied at t = 0 */
        long steps = 0;
        rc = fem_write_snapshot(m, err);
        while (rc == CM_OK && fem_time(m) < end_time * (1 - 1e-12)) {
            if ((rc = fem_advance(m, NULL, cfg->dt, err)) == CM_OK)
                rc = fem_output_due(m, err);
            steps++;
        }
        if (rc == CM_OK)
            cm_log_info("dynamic: %ld steps of %.4g s to t = %.6g s in %.2f s", steps, cfg->dt, fem_time(m),
                        cm_now() - t0);
    }
    if (rc == CM_OK) {
        int nn, nt;
        fem_mesh_size(m, &nn, &nt);
        const double *u = fem_displacement(m);
        double umax = 0;
        for (int d = 0; d < 3 * nn; d++)
            umax = fabs(u[d]) > umax ? fabs(u[d]) : umax;
        fem_energy en;
        fem_get_energy(m, &en);
        cm_log_info("fem-only %s: %d nodes, %d tetrahedra; max |u component| %.6g m, elastic energy %.6g J; results: "
                    "%s/fem.h5, %s/fem_series.csv",
                    cfg->analysis == FEM_ANALYSIS_STATIC ? "static" : "dynamic", nn, nt, umax, en.elastic, o->out,
                    o->out);
        cm_log_info("final state: fem_state_hash %016llx", (unsigned long long)fem_state_hash(m));
    }
    fem_destroy(&m);
    return rc;
}

static int run(const options *o)
{
    cm_error err = {0};
    cm_scene *scene = NULL;
    fem_model *model = NULL;
    ipc_channel *ch = NULL;
    cm_h5 *h5 = NULL;
    fem_coupled c = {0};
    int exit_code = 1, rc, clean_stop = 0;
    const char *peer_msg = NULL; /* what stopped the run when the link to the peer did */
    cm_run_record rec = {0};     /* fem_run.json: what scripts read of this run (common/runrec.h) */
    cm_runrec_text(&rec, "program", "fem_server");
    cm_runrec_text(&rec, "scene", o->scene);

    cm_run_config rc_cfg;
    drive_def drive = drive_def_default();
    fem_config cfg = fem_config_default();
    if (o->fem_only) {
        if ((rc = cm_scene_open(o->scene, &scene, &err)) || (rc = fem_config_read(scene, &cfg, &err)) ||
            (rc = run_fem_only(o, scene, &cfg, &rec, &err)))
            goto fail;
        exit_code = 0;
        goto cleanup;
    }
    if ((rc = cm_scene_open(o->scene, &scene, &err)) || (rc = cm_run_config_read(scene, &rc_cfg, &err)) || (rc = drive_config_read(scene, &drive, &err)) ||
        (rc = fem_config_read(scene, &cfg, &err)))
        goto fail;
    if (cfg.floor) {
        rc = cm_fail(&err, CM_ERR_KEY, "%s: fem.floor is for fem_server --fem-only static runs (the grains are the "
                     "floor of a coupled run)", o->scene);
        goto fail;
    }
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
    const int have_stab = fem_get_stability(model, &stab) == CM_OK; /* none for a rigid tire (zeros) */
    cm_log_info("tire: %d nodes, %d tetrahedra; static solve done in %.2f s; FEM step limit %.3g s "
                "(estimate h/c %.3g s)",
                n_mesh_nodes, n_tets, cm_now() - t0, stab.dt_limit, stab.dt_estimate);
    cm_runrec_num(&rec, "nodes", n_mesh_nodes);
    cm_runrec_num(&rec, "tets", n_tets);
    cm_runrec_num(&rec, "dt", cfg.dt);
    if (have_stab) {
        cm_runrec_num(&rec, "dt_limit", stab.dt_limit);
        cm_runrec_num(&rec, "dt_estimate", stab.dt_estimate);
    }

    double mesh_mass, mesh_inertia;
    fem_mass_properties(model, &mesh_mass, &mesh_inertia);
    if (cfg.interface_mass_min > 0) {
        double added = fem_added_mass(model);
        cm_log_info("fem: interface nodes raised to %.3g kg (fem.interface_mass_min): %.4g kg added, %.3g %% of the "
                    "body's %.4g kg", cfg.interface_mass_min, added, 100 * added / mesh_mass, mesh_mass);
        cm_runrec_num(&rec, "added_mass", added);
        cm_runrec_num(&rec, "added_mass_fraction", added / mesh_mass);
    }
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
    if (drive.motion != DRIVE_HOLD) {
        if (drive.approach_velocity > drive.sink_velocity)
            cm_log_info("wheel: set down at up to %g m/s while unloaded, slowing to %g m/s at %.0f %% of the load",
                        drive.approach_velocity, drive.sink_velocity, 100 * drive.approach_load);
        else
            cm_log_info("wheel: set down at up to %g m/s", drive.sink_velocity);
    }
    if (drive.motion == DRIVE_LOAD_TRAVEL)
        cm_log_info("wheel: vertical damper %.4g N s/m (%.2f of critical on the reference soil stiffness %.3g N/m)",
                    drive.damping, drive.damping / (2.0 * sqrt(DRIVE_SOIL_STIFFNESS_REF * drive.mass)),
                    DRIVE_SOIL_STIFFNESS_REF);

    /* The exchange loop's state. */
    c.model = model;
    c.drive = &drive;
    c.run = &rc_cfg;
    c.out = o->out;
    c.scene_hash = scene_hash;
    c.interval = cm_run_exchange_dt(&rc_cfg);
    c.hooks = (fem_exchange_hooks){.after_advance = after_advance, .user = NULL};
    c.interrupt = &g_sig->interrupt;
    fem_energy en0;
    fem_get_energy(model, &en0);
    c.elastic0 = en0.elastic; /* the inflated tire before any grain touches it */
    drive_start(&drive, &c.ds);
    if ((rc = fem_set_wheel_motion(model, &c.ds, &err)))
        goto fail;

    /* The exchange segment, sized for the interface surface. */
    uint32_t nt;
    fem_interface_count(model, &c.nn, &nt);
    ipc_create_def def = ipc_default_create_def();
    def.n_nodes = c.nn;
    def.n_tris = nt;
    def.exchange_dt = c.interval;
    def.stall_timeout = rc_cfg.stall_timeout;
    def.connect_timeout = rc_cfg.connect_timeout;
    def.stop_flag = &g_sig->stop;
    char ipc_err[512];
    if (ipc_create(o->shm, &def, &ch, ipc_err, sizeof ipc_err)) { /* ipc.h codes: not mixed into rc */
        cm_log_error("%s", ipc_err);
        peer_msg = ipc_err;
        exit_code = 3;
        goto cleanup;
    }
    c.ch = ch;
    c.x_prev = malloc(3 * (size_t)c.nn * sizeof(double));
    if (!c.x_prev) {
        cm_fail(&err, CM_ERR_NOMEM, "out of memory for %u interface nodes", c.nn);
        goto fail;
    }
    fem_interface_state(model, ipc_surface_nodes(ch), NULL);
    fem_interface_initial(model, NULL, ipc_surface_tris(ch), NULL);
    fem_interface_masses(model, ipc_surface_masses(ch));
    memcpy(c.x_prev, ipc_surface_nodes(ch), 3 * (size_t)c.nn * sizeof(double));
    cm_log_info("interface: %u nodes, %u triangles; waiting for dem_server on %s", c.nn, nt, o->shm);
    if (ipc_accept(ch)) {
        if (g_sig->stop) /* stopped by the launcher because the other side failed: that side says why */
            cm_log_info("stopped by signal %d while waiting for dem_server", (int)g_sig->stop);
        else
            cm_log_error("%s", peer_msg = ipc_error(ch));
        exit_code = 3;
        goto cleanup;
    }

    long series_rows = 0;
    if (o->resume) {
        fem_ckpt_run cr = {.drive = &c.ds, .n_nodes = c.nn, .x_prev = c.x_prev};
        rc = fem_checkpoint_read(ckpt_path, resume_exchange, model, &cr, scene_hash, o->out, &err);
        if (rc == CM_OK)
            rc = cm_ckpt_adopt(ckpt_path, &err);
        if (rc == CM_OK) {
            series_free(&c.travel);
            for (int k = 0; k < SER_N; k++)
                c.travel.col[k] = cr.travel[k];
            c.travel.n = c.travel.cap = cr.travel_n;
        } else {
            for (int k = 0; k < SER_N; k++)
                free(cr.travel[k]);
        }
        if (rc || (rc = fem_set_wheel_motion(model, &c.ds, &err)))
            goto fail;
        c.w_fem = cr.w_fem;
        c.max_force_mismatch = cr.max_force_mismatch;
        c.max_moment_mismatch = cr.max_moment_mismatch;
        c.work_abs = cr.work_abs;
        c.work_scale = cr.work_scale;
        c.work_gap_max = cr.work_gap_max;
        c.work_warned_at = cr.work_warned_at;
        series_rows = cr.series_rows;
        c.n = resume_exchange + 1;
        cm_log_info("resuming from %s after exchange %ld (t = %.6f s)", ckpt_path, resume_exchange, fem_time(model));
    }

    /* Outputs. */
    char path[1200], csv[1200];
    snprintf(path, sizeof path, "%s/wheel.h5", o->out);
    snprintf(csv, sizeof csv, "%s/traction.csv", o->out);
    cm_h5_def hdef = cm_h5_default_def();
    if (o->resume ? ((rc = cm_h5_reopen(path, &hdef, -1, &h5, &err)) ||
                     (rc = cm_h5_series_reopen(h5, "/series", fem_series_columns, fem_series_ncols, csv, series_rows,
                                               &c.series, &err)))
                  : ((rc = cm_h5_create(path, &hdef, &h5, &err)) ||
                     (rc = cm_h5_series_create(h5, "/series", fem_series_columns, fem_series_ncols, csv, &c.series,
                                               &err))))
        goto fail;
    /* rows in blocks (at most 4096, ~0.7 MB); stage record flushes them before a checkpoint */
    if (cfg.series_flush > 0 && (rc = cm_h5_series_hold(c.series, 4096, cfg.series_flush, &err)))
        goto fail;

    /* The exchange loop: one fem_exchange() per exchange until the DEM
     * finishes the run (fem_exchange.c has the stages). */
    c.last_progress = c.loop_t0 = cm_now();
    c.n_first = c.n;
    cm_signals_graceful(1); /* from here a signal asks for a checkpoint */
    fem_exchange_status st;
    while ((st = fem_exchange(&c, &err)) == FEM_EXCHANGE_NEXT)
        ;
    cm_signals_graceful(0);
    if (st == FEM_EXCHANGE_FAILED)
        goto fail;
    if (st == FEM_EXCHANGE_LINK_LOST) {
        cm_log_error("%s", peer_msg = ipc_error(ch));
        exit_code = g_sig->stop ? 128 + (int)g_sig->stop : 3;
        goto cleanup;
    }
    if ((rc = finish_run(o, &c, h5, cfg.mesh == FEM_MESH_TIRE ? 2.0 * M_PI / cfg.tire.lugs : 0.0, &err)))
        goto fail;
    exit_code = g_sig->interrupt ? 128 + (int)g_sig->interrupt : 0;
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
    if (!o->export_mesh) {
        char rec_path[1100];
        snprintf(rec_path, sizeof rec_path, "%s/fem_run.json", o->out);
        cm_runrec_num(&rec, "exchanges", (double)c.n);
        cm_runrec_num(&rec, "exit_code", exit_code);
        cm_runrec_num(&rec, "signal", g_sig->stop ? g_sig->stop : g_sig->interrupt);
        cm_runrec_text(&rec, "error", exit_code == 0 ? "" : peer_msg ? peer_msg : err.msg);
        cm_error rerr = {0};
        if (cm_runrec_write(&rec, rec_path, &rerr))
            cm_log_warn("%s", rerr.msg);
    }
    /* interrupted but finished cleanly (checkpoint written, finish answered): not a failure for the peer */
    ipc_close(&ch, exit_code == 0 || clean_stop ? IPC_OK : IPC_ERR_PEER_FAILED);
    fem_destroy(&model);
    cm_scene_close(&scene);
    series_free(&c.travel);
    free(c.x_prev);
    return exit_code;
}

static int usage(void)
{
    fprintf(stderr, "usage: fem_server --scene FILE --shm /NAME|mpi [--out DIR] [--resume DIR] [--set KEY=VALUE]...\n"
                    "       fem_server --scene FILE --export-mesh FILE.msh\n"
                    "       fem_server --scene FILE [--set KEY=VALUE]... --print-config[=json]\n"
                    "       fem_server --scene FILE --fem-only [--out DIR] [--set KEY=VALUE]...\n"
                    "  The tire side of the co-simulation; run both servers with ./run SCENE.\n"
                    "  --export-mesh writes the scene's mesh (e.g. the built-in tire) as Gmsh .msh v4.1\n"
                    "  with the physical groups rim, cavity and contact, and exits.\n"
                    "  --set overrides a scene setting, e.g. --set fem.mesh.resolution=0.5 (repeatable).\n"
                    "  --print-config prints the scene as resolved (the file with every --set applied) in\n"
                    "  libconfig syntax on stdout and exits; --print-config=json prints it as JSON, which\n"
                    "  scripts read (bench/post/runio.py) instead of parsing libconfig.\n"
                    "  --fem-only runs the tire model alone, no DEM peer: the static solve under\n"
                    "  fem.supports and fem.loads, or with fem.analysis = \"dynamic\" the response\n"
                    "  from rest to run.end_time; results in DIR/fem.h5 and DIR/fem_series.csv.\n");
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
        else if (strcmp(argv[i], "--print-config") == 0)
            o.print_config = 1;
        else if (strcmp(argv[i], "--print-config=json") == 0)
            o.print_config = 2;
        else if (strcmp(argv[i], "--fem-only") == 0)
            o.fem_only = 1;
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
    if (!o.scene || (!o.shm && !o.export_mesh && !o.print_config && !o.fem_only))
        return usage();
    if (o.print_config) { /* the scene as resolved: file + --set, libconfig syntax */
        cm_error err = {0};
        if (cm_scene_print_config(o.scene, o.print_config == 2, stdout, &err) == CM_OK)
            return 0;
        fprintf(stderr, "fem_server: %s\n", err.msg);
        return 1;
    }
    cm_log_set_tag("fem");
    cm_h5_library_init();
    g_sig = cm_signals_install();
#ifdef DEMFEM_MPI
    /* Only when mpirun started us (as the second program of an MPMD job with
     * dem_server: the channel "mpi"); a plain fem_server runs without MPI. */
    MPI_Comm own;
    char mpi_err[256];
    if (ipc_mpi_start(&own, mpi_err, sizeof mpi_err)) {
        cm_log_error("starting MPI: %s", mpi_err);
        return 1;
    }
#endif
    int rc = 1;
    if (!o.export_mesh && mkdir(o.out, 0755) != 0 && errno != EEXIST)
        cm_log_error("cannot create output folder %s: %s", o.out, strerror(errno));
    else
        rc = run(&o);
#ifdef DEMFEM_MPI
    ipc_mpi_stop();
#endif
    return rc;
}
