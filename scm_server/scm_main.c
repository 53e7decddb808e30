/* scm_server: a semi-empirical terrain (SCM) in dem_server's place.
 *
 *   scm_server --scene FILE --shm NAME [--out DIR] [--set KEY=VALUE]...
 *   (./run SCENE --terrain scm, or ./run SCENE --dem build/scm_server/scm_server)
 *
 * It speaks ipc/PROTOCOL.md as the DEM side: attaches to the FEM side's
 * segment, receives the tire's surface, and per exchange sends the nodal
 * forces of the soil (scm_terrain_step) with the totals in info[], then
 * receives the surface's new positions and velocities. It reads `run`,
 * `coupling` and its own `scm` section and ignores the other programs'
 * sections. It writes no checkpoints (it ignores the checkpoint flag, as the
 * protocol allows: --resume is refused), and in DIR:
 *   scm_series.csv  every scm.output.series_every exchanges: time, contacts,
 *                   force, deepest sinkage, interface work
 *   scm_rut.csv     at the end, every cell ever loaded: x, y, surface height,
 *                   deepest sinkage (the rut) */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

#include "csv.h"
#include "ipc.h"
#include "log.h"
#include "runcfg.h"
#include "signals.h"
#include "scene.h"
#include "scm.h"
#include "scm_config.h"
#include "timer.h"

/* SIGINT/SIGTERM: common/signals.h (checkpoint the next exchange and stop,
 * or stop at once before the exchange loop or 10 s later). */
static cm_signal_flags *g_sig;

typedef struct options {
    const char *scene, *shm, *out;
} options;

enum { SCM_EXIT_PEER = 3 };

static const char *const k_series_cols[] = {"time", "contacts", "Fx", "Fy", "Fz", "max_sinkage", "W_dem"};
enum { SERIES_N = 7 };

/* The rut: every cell ever loaded. */
static int write_rut(const char *dir, const scm_terrain *t, const scm_grid_def *g, cm_error *err)
{
    char path[1200];
    snprintf(path, sizeof path, "%s/scm_rut.csv", dir);
    static const char *const cols[] = {"x", "y", "height", "zmax"};
    cm_csv *csv;
    int rc = cm_csv_create(path, cols, 4, &csv, err);
    int nx, ny;
    scm_terrain_grid_size(t, &nx, &ny);
    for (int j = 0; j < ny && !rc; j++)
        for (int i = 0; i < nx && !rc; i++) {
            double zm = scm_terrain_cell_zmax(t, i, j);
            if (!(zm > 0))
                continue;
            double row[4] = {g->min[0] + (i + 0.5) * g->cell, g->min[1] + (j + 0.5) * g->cell,
                             scm_terrain_cell_height(t, i, j), zm};
            rc = cm_csv_row(csv, row, err);
        }
    int rc2 = cm_csv_close(&csv, err);
    return rc ? rc : rc2;
}

static int run(const options *o)
{
    cm_error err = {0};
    cm_scene *scene = NULL;
    scm_terrain *t = NULL;
    ipc_channel *ch = NULL;
    cm_csv *series = NULL;
    double *x = NULL, *v = NULL;
    int *tris = NULL;
    cm_run_config rcfg;
    scm_config cfg;
    int rc, exit_code = 1;
    int ipc_rc = IPC_OK; /* ipc.h codes of the exchange, apart from rc (common/error.h codes) */

    if ((rc = cm_scene_open(o->scene, &scene, &err)) || (rc = cm_run_config_read(scene, &rcfg, &err)) ||
        (rc = scm_config_read(scene, &cfg, &err)))
        goto fail;
    static const char *const sections[] = {"run", "coupling", "scm", NULL};
    cm_scene_skip_foreign(scene, sections);
    if ((rc = cm_scene_check_unknown(scene, sections, &err)))
        goto fail;
    cm_scene_close(&scene);
    if ((rc = scm_terrain_create(&cfg.grid, &cfg.soil, &t, &err)))
        goto fail;
    {
        int nx, ny;
        scm_terrain_grid_size(t, &nx, &ny);
        cm_log_info("soil: %d x %d cells of %.1f mm, surface at z = %.4f m; k_c %.4g, k_phi %.4g, n %.3g, c %.4g Pa, "
                    "phi %.1f deg, K %.3g m, unloading %.3g + %.3g z_max Pa/m",
                    nx, ny, 1e3 * cfg.grid.cell, cfg.grid.height, cfg.soil.k_c, cfg.soil.k_phi, cfg.soil.n,
                    cfg.soil.cohesion, cfg.soil.phi * 180 / M_PI, cfg.soil.K, cfg.soil.k0, cfg.soil.A_u);
    }

    ipc_attach_def ad = ipc_default_attach_def();
    ad.dt = rcfg.dt;
    ad.exchange_every = (uint32_t)rcfg.exchange_every;
    ad.stall_timeout = rcfg.stall_timeout;
    ad.connect_timeout = rcfg.connect_timeout;
    ad.stop_flag = &g_sig->stop;
    char ipc_err[512];
    cm_log_info("attaching to %s (dt %.3g s, exchange every %d steps)", o->shm, rcfg.dt, rcfg.exchange_every);
    if (ipc_attach(o->shm, &ad, &ch, ipc_err, sizeof ipc_err)) {
        if (g_sig->stop || g_sig->interrupt)
            cm_log_info("stopped by a signal while waiting for the FEM side");
        else
            cm_log_error("%s", ipc_err);
        exit_code = (g_sig->stop || g_sig->interrupt) ? 128 + (int)(g_sig->stop ? g_sig->stop : g_sig->interrupt) : SCM_EXIT_PEER;
        goto cleanup;
    }
    const uint32_t nn = ipc_surface_node_count(ch), nt = ipc_surface_tri_count(ch);
    const size_t m = 3 * (size_t)nn;
    x = malloc(m * sizeof *x);
    v = calloc(m, sizeof *v);
    tris = malloc(3 * (size_t)nt * sizeof *tris);
    if (!x || !v || !tris) {
        rc = cm_fail(&err, CM_ERR_NOMEM, "out of memory for a surface of %u nodes", nn);
        goto fail;
    }
    memcpy(x, ipc_surface_nodes(ch), m * sizeof *x);
    const uint32_t *st = ipc_surface_tris(ch);
    for (size_t k = 0; k < 3 * (size_t)nt; k++)
        tris[k] = (int)st[k]; /* ipc checked every index against the node count */
    if ((rc = scm_terrain_set_surface(t, (int)nn, x, (int)nt, tris, &err)))
        goto fail;
    cm_log_info("surface: %u nodes, %u triangles from the FEM side; Bekker b = %.4f m", nn, nt,
                scm_terrain_plate_width(t));
    if (o->out) {
        char path[1200];
        snprintf(path, sizeof path, "%s/scm_series.csv", o->out);
        if ((rc = cm_csv_create(path, k_series_cols, SERIES_N, &series, &err)))
            goto fail;
    }

    const double interval = cm_run_exchange_dt(&rcfg);
    double time = 0, w_dem = 0, t_start = cm_now(), last_progress = t_start, t_exchange = 0, t_output = 0;
    int stop_requested = 0, asked_checkpoint = 0;
    long n = 0;
    cm_signals_graceful(1); /* from here a signal asks for a checkpoint */
    scm_totals tot;
    memset(&tot, 0, sizeof tot);
    for (;; n++) {
        const int finish = stop_requested || time >= rcfg.end_time - 0.5 * rcfg.dt;
        if (!finish && (rc = scm_terrain_step(t, x, &err)))
            goto fail;
        double t0 = cm_now();
        ipc_frame_head *out;
        double *p;
        if ((ipc_rc = ipc_send_begin(ch, &out, &p)))
            break;
        out->kind = finish ? IPC_FRAME_FINISH : IPC_FRAME_DATA;
        out->time = time;
        if (!finish) {
            const double *f = scm_terrain_node_forces(t);
            scm_terrain_totals(t, &tot);
            for (size_t q = 0; q < m; q++) {
                p[q] = f[q];
                w_dem += f[q] * v[q] * interval; /* power of the soil's forces on the moving surface */
            }
            for (int a = 0; a < 3; a++) {
                out->info[IPC_INFO_FORCE_X + a] = tot.force[a];
                out->info[IPC_INFO_MOMENT_X + a] = tot.moment[a];
            }
            out->info[IPC_INFO_TRACTION_POS] = tot.traction_pos;
            out->info[IPC_INFO_TRACTION_NEG] = tot.traction_neg;
            out->info[IPC_INFO_CONTACTS] = (double)tot.contacts;
            out->info[IPC_INFO_DEM_WORK] = w_dem;
            out->info[IPC_INFO_BED_HEIGHT] = cfg.grid.height;
            out->info[IPC_INFO_BED_TOP] = cfg.grid.height;
            if (g_sig->interrupt && !asked_checkpoint) {
                out->flags |= IPC_FLAG_CHECKPOINT; /* interrupted: the FEM side checkpoints and stops */
                asked_checkpoint = 1;
                cm_log_info("interrupted: asking the FEM side to stop after exchange %ld", n);
            }
        }
        if ((ipc_rc = ipc_send_commit(ch)))
            break;
        const ipc_frame_head *in;
        const double *q;
        if ((ipc_rc = ipc_recv(ch, &in, &q)))
            break;
        const uint32_t kind = in->kind, flags = in->flags;
        stop_requested |= (flags & IPC_FLAG_STOP_REQUEST) != 0 || asked_checkpoint;
        if (kind == IPC_FRAME_DATA) {
            memcpy(x, q, m * sizeof *x);
            memcpy(v, q + m, m * sizeof *v);
        }
        ipc_recv_release(ch);
        double t1 = cm_now();
        t_exchange += t1 - t0;
        if (kind == IPC_FRAME_FINISH)
            break;
        if (kind != IPC_FRAME_DATA) {
            rc = cm_fail(&err, CM_ERR_PEER, "unexpected frame kind %u from the FEM side at exchange %ld", kind, n);
            goto fail;
        }
        for (size_t k = 0; k < m; k++)
            if (!isfinite(x[k]) || !isfinite(v[k])) {
                rc = cm_fail(&err, CM_ERR_NUMERIC,
                             "the FEM side sent a non-finite position or velocity of node %zu at exchange %ld", k / 3,
                             n);
                goto fail;
            }
        if (series && n % cfg.series_every == 0) {
            const double row[SERIES_N] = {time, (double)tot.contacts, tot.force[0], tot.force[1], tot.force[2],
                                          tot.max_sinkage, w_dem};
            if ((rc = cm_csv_row(series, row, &err)))
                goto fail;
        }
        time += interval;
        t_output += cm_now() - t1;
        double now = cm_now();
        if (rcfg.progress_every > 0 && now - last_progress >= rcfg.progress_every) {
            last_progress = now;
            cm_log_info("t = %.4f s  %.0f exchanges/s  cells in contact %ld  Fz %.1f N  deepest sinkage %.1f mm",
                        time, (double)(n + 1) / (now - t_start), tot.contacts, tot.force[2], 1e3 * tot.max_sinkage);
        }
    }
    if (ipc_rc) { /* ipc's code: its message names the peer */
        cm_log_error("%s", ipc_error(ch));
        exit_code = g_sig->stop ? 128 + (int)g_sig->stop : SCM_EXIT_PEER;
        goto cleanup;
    }
    {
        ipc_stats is = ipc_get_stats(ch);
        scm_profile pr = scm_terrain_profile(t);
        double wall = cm_now() - t_start;
        cm_log_info("coupled run finished: %ld exchanges, t = %.4f s in %.1f s; waited for the FEM %.1f s; "
                    "interface work seen by the terrain %.6g J",
                    n, time, wall, is.wait_recv_s + is.wait_send_s, w_dem);
        struct rusage ru;
        getrusage(RUSAGE_SELF, &ru);
        cm_log_info("profile: raster %.2f s, soil %.2f s, shear %.2f s, exchange %.2f s, output %.2f s "
                    "(%ld steps, %.1f us/step of terrain); CPU time of scm_server %.2f s",
                    pr.raster, pr.soil, pr.shear, t_exchange, t_output, pr.steps,
                    pr.steps ? 1e6 * (pr.raster + pr.soil + pr.shear) / pr.steps : 0.0,
                    (double)ru.ru_utime.tv_sec + 1e-6 * (double)ru.ru_utime.tv_usec + (double)ru.ru_stime.tv_sec +
                        1e-6 * (double)ru.ru_stime.tv_usec);
    }
    if (o->out && (rc = write_rut(o->out, t, &cfg.grid, &err)))
        goto fail;
    exit_code = g_sig->interrupt ? 128 + (int)g_sig->interrupt : 0;
    goto cleanup;
fail:
    cm_log_error("%s", err.msg);
    if (ch)
        ipc_fail(ch, "scm_server: %s", err.msg);
    exit_code = 1;
cleanup:
    ipc_close(&ch, exit_code == 0 ? IPC_OK : IPC_ERR_PEER_FAILED);
    cm_csv_close(&series, NULL);
    scm_terrain_destroy(&t);
    cm_scene_close(&scene);
    free(x);
    free(v);
    free(tris);
    return exit_code;
}

static int usage(void)
{
    fprintf(stderr, "usage: scm_server --scene FILE --shm /NAME [--out DIR] [--set KEY=VALUE]...\n"
                    "  A semi-empirical terrain (Bekker-Wong SCM) in dem_server's place:\n"
                    "  ./run SCENE --terrain scm. It writes no checkpoints (no --resume).\n");
    return 2;
}

int main(int argc, char **argv)
{
    options o = {0};
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *val = i + 1 < argc ? argv[i + 1] : NULL;
        if (strcmp(a, "--scene") == 0 && val)
            o.scene = val, i++;
        else if (strcmp(a, "--shm") == 0 && val)
            o.shm = val, i++;
        else if (strcmp(a, "--out") == 0 && val)
            o.out = val, i++;
        else if (strcmp(a, "--resume") == 0) {
            fprintf(stderr, "scm_server: writes no checkpoints, so it cannot resume (run the scene again)\n");
            return 2;
        } else if (strcmp(a, "--set") == 0 && val) {
            cm_error err = {0};
            if (cm_scene_add_override(val, &err)) {
                fprintf(stderr, "scm_server: %s\n", err.msg);
                return 2;
            }
            i++;
        } else
            return usage();
    }
    if (!o.scene || !o.shm)
        return usage();
    cm_log_set_tag("scm");
    g_sig = cm_signals_install();
    if (o.out && mkdir(o.out, 0755) != 0 && errno != EEXIST) {
        cm_log_error("cannot create output folder %s: %s", o.out, strerror(errno));
        return 1;
    }
    return run(&o);
}
