/* dem_server: the granular terrain side of the co-simulation.
 *
 *   dem_server --scene FILE --shm NAME [--out DIR] [--threads N]   coupled with fem_server
 *   dem_server --scene FILE --standalone [--out DIR] [--threads N] walls only, e.g. to settle a bed
 *   --resume DIR: continue the coupled run of DIR from its last checkpoint
 *
 * Builds the world of the scene's `dem` section: materials, walls, the
 * settled bed (reloaded from dem.bed.file when its parameters match, settled
 * and saved otherwise) and any explicitly placed grains (dem.grains). Then,
 * coupled, exchanges with the FEM side until run.end_time (dem_coupled.c);
 * stand-alone, steps to run.end_time with walls only (0 = just the bed).
 *
 * The coupling keys of the `dem` section, besides dem_server/README.md's:
 *   surface_material = "tread";   material of the exchanged surface (the tire)
 *   grains = ( { position = [x, y, z]; velocity = [vx, vy, vz];  m, m/s
 *                radius = r; material = "soil"; }, ... );           m
 * The time step is coupling.dt (dem.dt, if given, must agree with it). */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "ckpt.h"
#include "dem.h"
#include "dem_bed.h"
#include "dem_checkpoint.h"
#include "dem_config.h"
#include "dem_coupled.h"
#include "dem_output.h"
#include "dem_window.h"
#include "h5io.h"
#include "log.h"
#include "runcfg.h"
#include "runrec.h"
#include "scene.h"
#include "signals.h"
#include "timer.h"
#ifdef DEMFEM_MPI
#include "dem_mpi.h"
#include "ipc_mpi.h"
#endif

/* SIGINT/SIGTERM: common/signals.h (checkpoint the next exchange and stop,
 * or stop at once before the exchange loop or 10 s later). */
static cm_signal_flags *g_sig;

typedef struct options {
    const char *scene, *shm, *out, *resume;
    int threads;
    int standalone;
    char **argv; /* for the re-execution with passive OpenMP waiting */
} options;

/* OpenMP threads that wait actively spin on their core between parallel
 * regions; next to fem_server (and on a shared machine) that burns the core
 * the peer or the other thread needs: 2 DEM threads were 5.5x slower than 1.
 * Passive waiting (threads sleep on a futex at once) is the project's choice.
 * libgomp reads OMP_WAIT_POLICY when the library starts, before main, so
 * when it is unset and more than one thread will run, dem_server executes
 * itself again with it set (same pid, same arguments). ./run sets it itself;
 * a value the user gives is kept. Returns only if the re-execution failed. */
static void ensure_passive_waiting(const options *o, int threads)
{
    if (threads == 1 || getenv("OMP_WAIT_POLICY"))
        return;
    if (setenv("OMP_WAIT_POLICY", "passive", 1) != 0)
        return;
    fflush(NULL);
    execv("/proc/self/exe", o->argv);
    cm_log_warn("cannot re-execute with OMP_WAIT_POLICY=passive (%s): OpenMP threads wait actively", strerror(errno));
}

/* MPI: started only when a launcher (mpirun) started this process, so that
 * a plain dem_server behaves exactly as without MPI. With more than one rank
 * the DEM-only run (--standalone) is distributed (dem_mpi.h): rank 0 builds
 * or loads the bed and writes the outputs, the grains spread over the ranks
 * at the first neighbour rebuild. g_comm holds dem_server's own ranks: in an
 * MPMD job with fem_server (the channel "mpi", ipc_mpi.h) MPI_COMM_WORLD
 * holds both programs. */
static int g_rank = 0, g_ranks = 1;
#ifdef DEMFEM_MPI
static MPI_Comm g_comm = MPI_COMM_NULL;
static int g_balance = DEM_BALANCE_GRAINS; /* dem.balance */

/* Spreads the world over the ranks with the scene's balance. */
static int attach(dem_world *w, cm_error *err)
{
    int rc = dem_mpi_attach(w, g_comm, err);
    if (rc)
        return rc;
    const int b = g_balance == DEM_BALANCE_TIME ? DEM_MPI_BALANCE_TIME : DEM_MPI_BALANCE_GRAINS;
    return dem_mpi_set_balance(w, b) ? cm_fail(err, CM_ERR_STATE, "dem.balance: cannot set it") : CM_OK;
}
#endif

static int mpi_start(cm_error *err)
{
#ifdef DEMFEM_MPI
    char msg[256];
    if (ipc_mpi_start(&g_comm, msg, sizeof msg))
        return cm_fail(err, CM_ERR_PEER, "starting MPI: %s", msg);
    if (g_comm == MPI_COMM_NULL) /* no launcher */
        return CM_OK;
    MPI_Comm_rank(g_comm, &g_rank);
    MPI_Comm_size(g_comm, &g_ranks);
    if (g_rank > 0) {
        char tag[16];
        snprintf(tag, sizeof tag, "dem:r%d", g_rank);
        cm_log_set_tag(tag);
    }
#else
    (void)err;
#endif
    return CM_OK;
}

/* A failing rank stops the others (they may wait in a collective). */
static void mpi_abort_others(int code)
{
#ifdef DEMFEM_MPI
    if (g_ranks > 1)
        MPI_Abort(g_comm, code);
#else
    (void)code;
#endif
}

static void mpi_stop(void)
{
#ifdef DEMFEM_MPI
    ipc_mpi_stop();
#endif
}

typedef struct output_ctx {
    const dem_config *cfg;
    dem_output *out;
    long last_frame, last_series;
    int failed;
    cm_error err;
    /* checkpoints */
    const char *dir;          /* output folder; checkpoints in dir/checkpoint */
    uint64_t scene_hash;
    dem_window *window; /* saved in checkpoints (NULL = none) */
    const char *resume_path;  /* checkpoint to resume from, NULL for a fresh run */
    long resume_exchange;
    /* distributed run: the whole world gathered into `view` (rank 0) for
     * frames, series rows and checkpoints, as one process holds it */
    int distributed, frames;  /* frames: rank 0 writes an output (the same on every rank) */
    dem_world *view;
    long view_step;           /* DEM step the view was gathered at (-1: none) */
} output_ctx;

#ifdef DEMFEM_MPI
/* The view of the current state (collective; gathered once per step: the
 * frame, the series row and the checkpoint of one exchange share it). */
static int gather_view(dem_world *w, output_ctx *c, cm_error *err)
{
    const long step = dem_world_steps(w);
    if (c->view_step == step)
        return CM_OK;
    int rc = dem_mpi_gather(w, c->view, err);
    if (rc == CM_OK)
        c->view_step = step;
    return rc;
}
#endif

/* Writes grain frames and series lines at the configured step intervals. */
static int write_outputs(dem_world *w, output_ctx *c, cm_error *err)
{
#ifdef DEMFEM_MPI
    if (c->distributed) { /* every rank: the gather is collective; rank 0 writes what one process writes */
        const long step = dem_world_steps(w);
        const int series = step - c->last_series >= c->cfg->series_every;
        const int frame = step - c->last_frame >= c->cfg->output_every;
        if (!c->frames || (!series && !frame))
            return CM_OK;
        /* a series row from the ranks' totals, the whole world gathered
         * only for a frame (the collectives first: rank 0 may fail writing) */
        dem_stats st;
        int rc = series ? dem_mpi_series_stats(w, &st, err) : CM_OK;
        if (rc == CM_OK && frame)
            rc = gather_view(w, c, err);
        if (series)
            c->last_series = step;
        if (frame)
            c->last_frame = step;
        if (rc || g_rank != 0)
            return rc;
        if (series && (rc = dem_output_series_row(c->out, &st, err)))
            return rc;
        return frame ? dem_output_frame(c->out, c->view, err) : CM_OK;
    }
#endif
    if (!c->out)
        return CM_OK;
    /* Called every exchange: only the step count, not dem_world_stats (a sum
     * over every grain and pair that cost a quarter of the coupled run). */
    const long step = dem_world_steps(w);
    int rc;
    if (step - c->last_series >= c->cfg->series_every) {
        c->last_series = step;
        if ((rc = dem_output_series(c->out, w, err)))
            return rc;
    }
    if (step - c->last_frame >= c->cfg->output_every) {
        c->last_frame = step;
        if ((rc = dem_output_frame(c->out, w, err)))
            return rc;
    }
    return CM_OK;
}

/* Settling is logged, not written: the run's files hold the run only (the
 * settled bed itself is the first frame). */
static int settle_progress(dem_world *w, void *user)
{
    (void)user;
    if (dem_world_steps(w) % 10000 != 0)
        return g_sig->stop != 0;
    dem_stats s;
    dem_world_stats(w, &s);
    cm_log_info("settling: t = %.4f s, KE/grain = %.3g J, contacts %d", s.time,
                (s.ke_trans + s.ke_rot) / (s.grains ? s.grains : 1), s.contacts_gg + s.contacts_gw);
    return g_sig->stop != 0;
}

static int after_exchange(dem_world *w, void *user, long exchange, cm_error *err)
{
    (void)exchange;
    return write_outputs(w, user, err);
}

#ifdef DEMFEM_MPI
/* The coupled loop over ranks (dem_coupled_dist): rank 0 talks to
 * fem_server, the reply is broadcast, the world distributed once the
 * surface is installed. */
static int coupled_bcast(void *buf, size_t bytes, void *user, cm_error *err)
{
    (void)user;
    return dem_mpi_bcast(g_comm, buf, bytes, err);
}

static int coupled_attach(dem_world *w, void *user, cm_error *err)
{
    /* resuming, rank 0 read its output positions from the checkpoint: every
     * rank must write (gather) the next frame at the same exchange */
    output_ctx *c = user;
    long last[2] = {c->last_frame, c->last_series};
    int rc = MPI_Bcast(last, 2, MPI_LONG, 0, g_comm);
    if (rc != MPI_SUCCESS)
        return cm_fail(err, CM_ERR_IO, "MPI broadcast of the output positions failed");
    c->last_frame = last[0], c->last_series = last[1];
    return attach(w, err);
}

static int coupled_grains(dem_world *w, long *grains, void *user, cm_error *err)
{
    (void)user;
    dem_mpi_stats s;
    dem_mpi_stats_get(w, &s);
    long mine = s.owned;
    if (MPI_Allreduce(&mine, grains, 1, MPI_LONG, MPI_SUM, g_comm) != MPI_SUCCESS)
        return cm_fail(err, CM_ERR_IO, "MPI allreduce of the grain counts failed");
    return CM_OK;
}

static int coupled_hash(dem_world *w, uint64_t *hash, void *user, cm_error *err)
{
    (void)user;
    return dem_mpi_hash(w, hash, err);
}

static int coupled_collect(dem_world *w, void *user, cm_error *err)
{
    (void)user;
    return dem_mpi_collect(w, err);
}

static int coupled_rejoin(dem_world *w, void *user, cm_error *err)
{
    (void)user;
    return dem_mpi_rejoin(w, err);
}

static int coupled_agree_rebuild(dem_world *w, void *user, cm_error *err)
{
    (void)user;
    return dem_mpi_agree_rebuild(w, err);
}
#endif

static int write_checkpoint(dem_world *w, const dem_coupled_state *st, void *user, cm_error *err)
{
    output_ctx *c = user;
#ifdef DEMFEM_MPI
    if (c->distributed) { /* every rank: rank 0 writes the gathered world, one process's checkpoint */
        int rc = gather_view(w, c, err);
        if (rc || g_rank != 0)
            return rc;
        w = c->view;
    }
#endif
    dem_ckpt_outputs o = {.last_frame = c->last_frame, .last_series = c->last_series};
    dem_output_counts(c->out, &o.frames, &o.series_rows);
    double t0 = cm_now();
    int rc = dem_checkpoint_write(c->dir, w, c->window, st, &o, c->scene_hash, err);
    if (rc == CM_OK)
        cm_log_info("checkpoint of exchange %ld written (%.2f s)", st->exchange, cm_now() - t0);
    return rc;
}

/* Resuming: the world and loop state, then the outputs cut back to the checkpoint. */
static int restore_checkpoint(dem_world *w, dem_coupled_state *st, void *user, cm_error *err)
{
    output_ctx *c = user;
    dem_ckpt_outputs o;
    int rc = dem_checkpoint_read(c->resume_path, c->resume_exchange, w, c->window, st, &o, c->scene_hash, err);
    if (rc == CM_OK)
        rc = cm_ckpt_adopt(c->resume_path, err);
    if (rc == CM_OK && c->dir)
        rc = dem_output_reopen(c->dir, o.frames, o.series_rows, &c->out, err);
    c->last_frame = o.last_frame;
    c->last_series = o.last_series;
    if (rc == CM_OK)
        cm_log_info("resuming from %s (exchange %ld)", c->resume_path, c->resume_exchange);
    return rc;
}

static int material_index(cm_scene *s, const dem_config *cfg, const char *key, int *out, cm_error *err)
{
    char name[64];
    int rc = cm_scene_string(s, key, name, sizeof name, err);
    if (rc)
        return rc;
    for (int k = 0; k < cfg->n_materials; k++)
        if (strcmp(cfg->material_names[k], name) == 0) {
            *out = k;
            return CM_OK;
        }
    return cm_fail(err, CM_ERR_KEY, "%s: %s = \"%s\" is not a material listed in dem.materials", cm_scene_path(s),
                   key, name);
}

/* dem.grains: grains placed by hand (verification scenes). */
static int add_listed_grains(cm_scene *s, const dem_config *cfg, dem_world *w, cm_error *err)
{
    int n = cm_scene_length(s, "dem.grains");
    for (int i = 0; i < n; i++) {
        char key[128];
        double x[3], v[3] = {0, 0, 0}, omega[3] = {0, 0, 0}, r;
        int mat = 0, id = 0, rc;
#define GKEY(k) (snprintf(key, sizeof key, "dem.grains.[%d]." k, i), key)
        if ((rc = cm_scene_doubles(s, GKEY("position"), 3, -1e6, 1e6, x, err)) ||
            (rc = cm_scene_doubles_opt(s, GKEY("velocity"), 3, -1e4, 1e4, v, v, err)) ||
            (rc = cm_scene_doubles_opt(s, GKEY("angular_velocity"), 3, -1e6, 1e6, omega, omega, err)) ||
            (rc = cm_scene_double(s, GKEY("radius"), 1e-9, 100.0, &r, err)) ||
            (rc = material_index(s, cfg, GKEY("material"), &mat, err)) ||
            (rc = dem_grain_add(w, x, r, mat, &id, err)))
            return rc;
#undef GKEY
        dem_grain_set(w, id, x, v, omega);
    }
    return CM_OK;
}

/* The step's stages and the coupled loop's, with their shares: printed, and
 * written to DIR/dem_profile.csv (stage, seconds, share of its group,
 * count) when there is an output folder. */
static void report_profile(const dem_profile *p, const dem_coupled_profile *c, const char *dir)
{
    const char *names[] = {"rebuild", "surface", "pairs", "integrate"};
    const double t[] = {p->rebuild, p->surface, p->pairs, p->integrate};
    const int n_st = (int)(sizeof t / sizeof t[0]);
    const char *cnames[] = {"surface", "send", "grains", "wait", "update", "record", "surf_bcast"};
    const double ct[] = {c ? c->surface : 0, c ? c->send : 0,   c ? c->grains : 0, c ? c->wait : 0,
                         c ? c->update : 0,  c ? c->record : 0, c ? c->bcast : 0};
    /* surf_bcast only in a distributed run */
    const int n_cst = (int)(sizeof ct / sizeof ct[0]) - (c && c->bcast_bytes > 0 ? 0 : 1);
    double tot = 0, ctot = 0;
    for (int k = 0; k < n_st; k++)
        tot += t[k];
    for (int k = 0; k < n_cst; k++)
        ctot += ct[k];
    char line[512];
    int len = snprintf(line, sizeof line, "profile of the step (%ld steps, %ld rebuilds, %ld surface list builds):",
                       p->steps, p->rebuilds, p->surface_lists);
    for (int k = 0; k < n_st; k++)
        len += snprintf(line + len, sizeof line - (size_t)len, " %s %.2f s (%.0f %%)", names[k], t[k],
                        tot > 0 ? 100 * t[k] / tot : 0.0);
    cm_log_info("%s", line);
    if (c) {
        len = snprintf(line, sizeof line, "profile of the exchange (%ld exchanges):", c->exchanges);
        for (int k = 0; k < n_cst; k++)
            len += snprintf(line + len, sizeof line - (size_t)len, " %s %.2f s (%.0f %%)", cnames[k], ct[k],
                            ctot > 0 ? 100 * ct[k] / ctot : 0.0);
        cm_log_info("%s", line);
    }
    if (!dir)
        return;
    char path[1200];
    snprintf(path, sizeof path, "%s/dem_profile.csv", dir);
    FILE *f = fopen(path, "w");
    if (!f) {
        cm_log_warn("cannot write %s: %s", path, strerror(errno));
        return;
    }
    fprintf(f, "group,stage,seconds,share,count\n");
    for (int k = 0; k < n_st; k++)
        fprintf(f, "step,%s,%.6f,%.4f,%ld\n", names[k], t[k], tot > 0 ? t[k] / tot : 0.0,
                k == 0 ? p->rebuilds : p->steps);
    if (c)
        for (int k = 0; k < n_cst; k++)
            fprintf(f, "exchange,%s,%.6f,%.4f,%ld\n", cnames[k], ct[k], ctot > 0 ? ct[k] / ctot : 0.0, c->exchanges);
    if (fclose(f) != 0)
        cm_log_warn("cannot write %s", path);
}

/* DIR/dem_profile_ranks.csv, one row per rank (rank 0 writes; every rank
 * calls it, the rows are gathered): its grains and ghosts at the end, the
 * steps, and the step's time split into compute (the stages without their
 * communication: rebuild - migrate + surface - surf_gather + pairs +
 * integrate), halo (ghost refresh and the agreed rebuild decision), migrate
 * (slabs, migration, ghosts at a rebuild), surf_gather (the surface
 * contacts reduced on rank 0) and, coupled, surf_bcast (the reply from rank
 * 0, which the other ranks wait in) and wait (rank 0: for fem_server); then
 * compute split into its stages (surface, pairs, integrate, rebuild without
 * the migration) and, coupled, update (the surface moved, the window). One
 * process writes its one row the same way (zeros for the communication). */
enum { RANK_COLS = 15 };

static void report_rank_profiles(const dem_profile *p, const dem_coupled_profile *c, int owned, int ghosts,
                                 const char *dir)
{
    const double compute = p->rebuild - p->migrate + p->surface - p->surf_gather + p->pairs + p->integrate;
    const double mine[RANK_COLS] = {owned,         ghosts,           (double)p->steps, compute,
                                    p->halo,       p->migrate,       p->surf_gather,   c ? c->bcast : 0.0,
                                    c ? c->wait : 0.0, p->rebuild + p->surface + p->pairs + p->integrate + p->halo,
                                    p->surface - p->surf_gather, p->pairs, p->integrate, p->rebuild - p->migrate,
                                    c ? c->update : 0.0};
    double *all = g_rank == 0 ? malloc((size_t)g_ranks * sizeof mine) : NULL;
    if (g_rank == 0 && !all)
        cm_log_warn("out of memory for the ranks' profiles");
#ifdef DEMFEM_MPI
    if (g_ranks > 1)
        MPI_Gather(mine, RANK_COLS, MPI_DOUBLE, all, RANK_COLS, MPI_DOUBLE, 0, g_comm);
    else
#endif
        if (all)
        memcpy(all, mine, sizeof mine);
    if (!all || !dir) {
        free(all);
        return;
    }
    char path[1200];
    snprintf(path, sizeof path, "%s/dem_profile_ranks.csv", dir);
    FILE *f = fopen(path, "w");
    if (!f) {
        cm_log_warn("cannot write %s: %s", path, strerror(errno));
        free(all);
        return;
    }
    fprintf(f, "rank,ranks,grains,ghosts,steps,compute_s,halo_s,migrate_s,surf_gather_s,surf_bcast_s,wait_s,step_s,"
               "surface_s,pairs_s,integrate_s,rebuild_s,update_s\n");
    for (int r = 0; r < g_ranks; r++) {
        const double *v = all + (size_t)r * RANK_COLS;
        fprintf(f, "%d,%d,%.0f,%.0f,%.0f,%.6f,%.6f,%.6f,%.6f,%.6f,%.6f,%.6f,%.6f,%.6f,%.6f,%.6f,%.6f\n", r, g_ranks,
                v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8], v[9], v[10], v[11], v[12], v[13], v[14]);
    }
    if (fclose(f) != 0)
        cm_log_warn("cannot write %s", path);
    free(all);
}

static int run(const options *o)
{
    cm_error err = {0};
    cm_scene *scene = NULL;
    dem_world *w = NULL;
    ipc_channel *ch = NULL;
    dem_window *window = NULL;
    output_ctx octx = {.view_step = -1};
    char dem_path[1100] = ""; /* the checkpoint to resume from: octx.resume_path, for the whole run */
    cm_run_config rcfg;
    dem_config cfg;
    int surface_material = 0, exit_code = 1, rc;
    dem_coupled_profile cprof = {0};
    cm_run_record rec = {0}; /* dem_run.json: what scripts read of this run (common/runrec.h) */
    cm_runrec_text(&rec, "program", "dem_server");
    cm_runrec_text(&rec, "scene", o->scene);

    if ((rc = cm_scene_open(o->scene, &scene, &err)) || (rc = cm_run_config_read(scene, &rcfg, &err)) ||
        (rc = dem_config_read(scene, &cfg, &err)))
        goto fail;
    if (cm_scene_has(scene, "dem.surface_material") &&
        (rc = material_index(scene, &cfg, "dem.surface_material", &surface_material, &err)))
        goto fail;
    if (cfg.world.dt != rcfg.dt) {
        rc = cm_fail(&err, CM_ERR_KEY, "%s: dem.dt = %g s differs from coupling.dt = %g s (give only coupling.dt)",
                     o->scene, cfg.world.dt, rcfg.dt);
        goto fail;
    }
    if (o->threads > 0)
        cfg.world.threads = o->threads;
    ensure_passive_waiting(o, cfg.world.threads);
    if ((rc = mpi_start(&err))) /* after the re-execution above */
        goto fail;
#ifdef DEMFEM_MPI
    g_balance = cfg.balance;
#endif
    if (g_rank == 0 && g_ranks > 1)
        cm_log_info("%d MPI ranks (the scene's dem.ranks: %d), slabs balanced by %s", g_ranks, cfg.ranks,
                    cfg.balance == DEM_BALANCE_TIME ? "measured busy time" : "grain count");
    if (o->out)
        snprintf(cfg.output_dir, sizeof cfg.output_dir, "%s", o->out);
    cfg.world.max_grains += cm_scene_length(scene, "dem.grains");
    if ((rc = dem_world_from_config(&cfg, &w, &err)))
        goto fail;
    dem_coupled_def def = {.shm = o->shm,
                           .dt = rcfg.dt,
                           .exchange_every = rcfg.exchange_every,
                           .end_time = rcfg.end_time,
                           .stall_timeout = rcfg.stall_timeout,
                           .connect_timeout = rcfg.connect_timeout,
                           .progress_every = rcfg.progress_every,
                           .surface_material = surface_material,
                           .max_overlap = rcfg.max_overlap,
                           .max_surface_overlap = rcfg.max_surface_overlap,
                           .stop_flag = &g_sig->stop,
                           .profile = &cprof};
    /* Coupled: shake hands first, so that settling a large bed does not run
     * into the FEM side's connect timeout. */
    if (!o->standalone && g_rank == 0 && (rc = dem_coupled_attach(&def, &ch, &err))) {
        if (g_sig->stop) /* stopped by the launcher because the other side failed: that side says why */
            cm_log_info("stopped by signal %d while waiting for fem_server", (int)g_sig->stop);
        else
            cm_log_error("%s", err.msg);
        exit_code = g_sig->stop ? 128 + (int)g_sig->stop : 3;
        goto cleanup;
    }

    octx.cfg = &cfg;
    octx.dir = cfg.output_dir[0] ? cfg.output_dir : NULL;
    if ((rc = cm_ckpt_file_hash(o->scene, &octx.scene_hash, &err)))
        goto fail;
    octx.scene_hash = cm_scene_overrides_hash(octx.scene_hash);
    if (o->resume) {
        char fem_path[1100];
        if ((rc = cm_ckpt_choose(o->resume, &octx.resume_exchange, dem_path, fem_path, sizeof dem_path, &err)))
            goto fail;
        octx.resume_path = dem_path;
    } else if (g_rank == 0 && octx.dir && (rc = dem_output_open(cfg.output_dir, &octx.out, &err))) {
        goto fail;
    }
    if (g_rank > 0)
        octx.dir = NULL; /* rank 0 writes */
    double t0 = cm_now(), bed_height = 0, bed_top = 0;
    if (cfg.has_bed && g_rank == 0) {
        bool loaded = false;
        rc = dem_bed_build(w, &cfg.bed, settle_progress, &octx, &loaded, &err);
        if (rc && octx.failed)
            err = octx.err;
        if (rc)
            goto fail;
        bed_height = dem_bed_height(w);
        for (int id = 0; id < dem_grain_count(w); id++) {
            dem_grain_state g;
            dem_grain_get(w, id, &g);
            bed_top = g.x[2] + g.radius > bed_top ? g.x[2] + g.radius : bed_top;
        }
        double bed_s = cm_now() - t0;
        cm_log_info("%s bed of %d grains, surface at z = %.4f m (%.1f s)", loaded ? "loaded" : "settled",
                    dem_grain_count(w), bed_height, bed_s);
        /* so that a study can count a run's cost without the bed it settled once for several runs */
        cm_runrec_num(&rec, "bed_s", bed_s);
        cm_runrec_num(&rec, "bed_loaded", loaded);
        /* the settled bed is the window's sample: taken before anything else is added */
        if (cfg.window.enabled && !o->standalone && (rc = dem_window_create(w, &cfg.window, &window, &err)))
            goto fail;
    }
    if (g_rank == 0 && (rc = add_listed_grains(scene, &cfg, w, &err)))
        goto fail;
    /* The run starts here: its first frame is the initial state. */
    if (octx.out && !o->resume && ((rc = dem_output_frame(octx.out, w, &err)) || (rc = dem_output_series(octx.out, w, &err))))
        goto fail;
    {
        dem_stats s0;
        dem_world_stats(w, &s0);
        octx.last_frame = octx.last_series = s0.step;
    }
    /* Every key is read: now a leftover is a typo. */
    static const char *const sections[] = {"run", "coupling", "dem", NULL};
    cm_scene_skip_foreign(scene, sections); /* fem, wheel, scm: the other programs' */
    if ((rc = cm_scene_check_unknown(scene, sections, &err)))
        goto fail;
    if (g_rank == 0 && dem_grain_count(w) == 0) {
        rc = cm_fail(&err, CM_ERR_KEY, "%s: no grains (give dem.bed or dem.grains)", o->scene);
        goto fail;
    }
    double t_rayleigh, t_hertz;
    dem_time_limits(w, &t_rayleigh, &t_hertz);
    if (g_rank == 0) /* the others hold no grain yet */
        cm_log_info("%d grains; dt = %.3g s (Rayleigh time %.3g s, Hertz contact time %.3g s); rolling resistance: "
                    "%s; vector loops: %s",
                    dem_grain_count(w), rcfg.dt, t_rayleigh, t_hertz,
                    cfg.world.rolling_model == DEM_ROLLING_SPRING ? "spring" : "constant torque", dem_kernels_name(w));
    cm_runrec_num(&rec, "grains", dem_grain_count(w));
    cm_runrec_num(&rec, "dt", rcfg.dt);
    cm_runrec_text(&rec, "kernels", dem_kernels_name(w));
    cm_runrec_num(&rec, "exchange_every", rcfg.exchange_every);
    cm_runrec_num(&rec, "t_rayleigh", t_rayleigh);
    cm_runrec_num(&rec, "t_hertz", t_hertz);
    cm_runrec_num(&rec, "dt_safety_rayleigh", cfg.world.dt_safety_rayleigh);
    cm_runrec_num(&rec, "dt_safety_hertz", cfg.world.dt_safety_hertz);

    if (o->standalone) {
        long steps = (long)(rcfg.end_time / rcfg.dt + 0.5);
        double last = cm_now();
#ifdef DEMFEM_MPI
        if (g_ranks > 1) {
            if ((rc = attach(w, &err)))
                goto fail;
            octx.last_frame = octx.last_series = dem_world_steps(w); /* rank 0's clock, now every rank's */
            octx.distributed = 1;
            octx.frames = octx.out != NULL;
            MPI_Bcast(&octx.frames, 1, MPI_INT, 0, g_comm);
            if (g_rank == 0 && octx.frames && (rc = dem_world_from_config(&cfg, &octx.view, &err)))
                goto fail;
        }
#endif
        for (long k = 0; k < steps && !g_sig->stop; k++) {
            if ((rc = dem_step(w, &err)) || (rc = write_outputs(w, &octx, &err)))
                goto fail;
            if (rcfg.progress_every > 0 && cm_now() - last > rcfg.progress_every) {
                last = cm_now();
                cm_log_info("t = %.4f s (%ld of %ld steps)", (k + 1) * rcfg.dt, k + 1, steps);
            }
        }
        exit_code = g_sig->stop ? 128 + (int)g_sig->stop : 0;
        uint64_t hash = dem_world_hash(w);
#ifdef DEMFEM_MPI
        if (g_ranks > 1 && (rc = dem_mpi_hash(w, &hash, &err)))
            goto fail;
#endif
        cm_log_info("final state: dem_world_hash %016llx (%d rank%s)", (unsigned long long)hash, g_ranks,
                    g_ranks > 1 ? "s" : "");
    } else {
        def.bed_height = bed_height;
        def.bed_top = bed_top;
        def.window = window;
        def.window_def = cfg.window;
        octx.window = window;
        def.interrupt = &g_sig->interrupt;
#ifdef DEMFEM_MPI
        const dem_coupled_dist dist = {.rank = g_rank, .ranks = g_ranks, .bcast = coupled_bcast,
                                       .attach = coupled_attach, .hash = coupled_hash, .collect = coupled_collect,
                                       .rejoin = coupled_rejoin, .agree_rebuild = coupled_agree_rebuild,
                                       .grains = coupled_grains,
                                       .user = &octx};
        if (g_ranks > 1) {
            def.dist = &dist;
            octx.distributed = 1;
            octx.frames = octx.dir != NULL; /* resuming, rank 0 opens its output in the restore hook */
            MPI_Bcast(&octx.frames, 1, MPI_INT, 0, g_comm);
            if (g_rank == 0 && octx.frames && (rc = dem_world_from_config(&cfg, &octx.view, &err)))
                goto fail;
        }
#endif
        dem_coupled_hooks hooks = {.after_exchange = after_exchange,
                                   /* distributed: every rank takes part (rank 0 writes) */
                                   .checkpoint = octx.dir || (octx.distributed && octx.frames) ? write_checkpoint
                                                                                               : NULL,
                                   .restore = o->resume ? restore_checkpoint : NULL,
                                   .user = &octx};
        cm_signals_graceful(octx.dir != NULL); /* from here a signal asks for a checkpoint */
        rc = dem_run_coupled(w, ch, &def, &hooks, &err);
        cm_signals_graceful(0);
        ch = NULL; /* closed by the run */
        if (rc == CM_ERR_PEER) {
            cm_log_error("%s", err.msg);
            mpi_abort_others(3); /* the other ranks wait for rank 0 */
            exit_code = g_sig->stop ? 128 + (int)g_sig->stop : 3;
            goto cleanup;
        }
        if (rc)
            goto fail;
        exit_code = g_sig->interrupt ? 128 + (int)g_sig->interrupt : 0;
        if (window) {
            const dem_window_state *ws = dem_window_get_state(window);
            cm_log_info("window: %d removals (%ld grains), %d stretches appended (%ld grains), lowest seam solid "
                        "fraction %.0f %% of the sample's; bed now x in [%.3f, %.3f] m",
                        ws->shifts_back, ws->removed, ws->shifts_front, ws->added, 100.0 * ws->seam_min_fraction,
                        ws->x_back, ws->x_front);
        }
    }
    {
        dem_stats s;
        dem_world_stats(w, &s);
        report_profile(&s.profile, o->standalone ? NULL : &cprof, octx.dir);
        int owned = s.grains, ghosts = 0;
#ifdef DEMFEM_MPI
        if (g_ranks > 1) {
            dem_mpi_stats ms;
            dem_mpi_stats_get(w, &ms);
            owned = ms.owned, ghosts = ms.ghosts;
            cm_log_info("rank %d of %d: %d grains (+%d ghosts), cell columns [%d, %d), %ld migrated; halo %.2f s, "
                        "migration %.2f s", g_rank, g_ranks, ms.owned, ms.ghosts, ms.col_lo, ms.col_hi,
                        ms.migrated, s.profile.halo, s.profile.migrate);
            if (!o->standalone)
                cm_log_info("rank %d of %d: %ld surface contacts over %ld passes (%ld gathers ended among the "
                            "grain pairs); surf_gather %.2f s, surf_bcast %.2f s, %ld replies in the halo; %ld "
                            "window shifts collected",
                            g_rank, g_ranks, ms.surf_contacts, ms.surf_gathers, ms.surf_early,
                            s.profile.surf_gather, cprof.bcast, cprof.halo_rides, ms.collects);
            if (!o->standalone && g_rank == 0 && ms.surf_gathers > 0 && cprof.exchanges > 0)
                cm_log_info("MPI traffic of the surface: %.0f bytes broadcast per exchange, %.0f bytes of contacts "
                            "gathered on rank 0 per DEM step (mean)", cprof.bcast_bytes / (double)cprof.exchanges,
                            (double)sizeof(double) * (double)ms.surf_doubles / (double)ms.surf_gathers);
        }
#endif
        report_rank_profiles(&s.profile, o->standalone ? NULL : &cprof, owned, ghosts, octx.dir);
    }
    goto cleanup;
fail:
    cm_log_error("%s", err.msg);
    if (ch) /* first: over MPI the abort below ends fem_server too */
        ipc_fail(ch, "dem_server: %s", err.msg);
    mpi_abort_others(1);
    exit_code = 1;
cleanup:
    ipc_close(&ch, exit_code == 0 ? IPC_OK : IPC_ERR_PEER_FAILED);
    if (o->out && g_rank == 0) {
        char path[1100];
        snprintf(path, sizeof path, "%s/dem_run.json", o->out);
        cm_runrec_num(&rec, "exchanges", (double)cprof.exchanges);
        cm_runrec_num(&rec, "exit_code", exit_code);
        cm_runrec_num(&rec, "signal", g_sig->stop ? g_sig->stop : g_sig->interrupt);
        cm_runrec_text(&rec, "error", exit_code != 0 ? err.msg : "");
        cm_error rerr = {0};
        if (cm_runrec_write(&rec, path, &rerr))
            cm_log_warn("%s", rerr.msg);
    }
    dem_output_close(&octx.out);
    dem_world_destroy(&octx.view);
    dem_window_free(&window);
    dem_world_destroy(&w);
    cm_scene_close(&scene);
    return exit_code;
}

static int usage(void)
{
    fprintf(stderr, "usage: dem_server --scene FILE (--shm /NAME|mpi | --standalone) [--out DIR] [--threads N]\n"
                    "                  [--resume DIR] [--set KEY=VALUE]... [--print-config[=json]]\n"
                    "  The granular side of the co-simulation; run both servers with ./run SCENE.\n"
                    "  --set overrides a scene setting, e.g. --set coupling.dt=2e-5 (repeatable).\n");
    return 2;
}

int main(int argc, char **argv)
{
    options o = {.argv = argv};
    int print_config = 0;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
        if (strcmp(a, "--scene") == 0 && v)
            o.scene = v, i++;
        else if (strcmp(a, "--shm") == 0 && v)
            o.shm = v, i++;
        else if (strcmp(a, "--out") == 0 && v)
            o.out = v, i++;
        else if (strcmp(a, "--threads") == 0 && v)
            o.threads = atoi(v), i++;
        else if (strcmp(a, "--resume") == 0 && v)
            o.resume = o.out = v, i++;
        else if (strcmp(a, "--standalone") == 0)
            o.standalone = 1;
        else if (strcmp(a, "--print-config") == 0)
            print_config = 1;
        else if (strcmp(a, "--print-config=json") == 0)
            print_config = 2;
        else if (strcmp(a, "--set") == 0 && v) {
            cm_error err = {0};
            if (cm_scene_add_override(v, &err)) {
                fprintf(stderr, "dem_server: %s\n", err.msg);
                return 2;
            }
            i++;
        } else
            return usage();
    }
    if (o.scene && print_config) { /* the resolved scene (file + --set), common/scene.h */
        cm_error err = {0};
        if (cm_scene_print_config(o.scene, print_config == 2, stdout, &err) == CM_OK)
            return 0;
        fprintf(stderr, "dem_server: %s\n", err.msg);
        return 1;
    }
    if (!o.scene || (!o.shm && !o.standalone) || (o.resume && o.standalone))
        return usage();
    cm_log_set_tag("dem");
    cm_h5_library_init();
    g_sig = cm_signals_install();
    if (o.out && mkdir(o.out, 0755) != 0 && errno != EEXIST) {
        cm_log_error("cannot create output folder %s: %s", o.out, strerror(errno));
        return 1;
    }
    int rc = run(&o);
    mpi_stop();
    return rc;
}
