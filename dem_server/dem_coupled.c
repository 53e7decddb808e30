/* The coupled DEM loop: dem_server's side of the exchange with fem_server
 * (ipc/PROTOCOL.md), the paper's fig. 8 split over two processes.
 *
 * One exchange n (k = coupling.exchange_every DEM steps) is a pipeline of
 * named stages, each timed into dem_coupled_profile:
 *   surface   k x: surface moved along its node velocities (j > 0),
 *             dem_step_surface (gravity, walls, triangles at x(t)), node
 *             forces and totals summed; between them the first k - 1
 *             dem_step_grains
 *   send      the interval's mean node forces (eq. 42) and totals posted,
 *             as soon as the last pass is summed (dem_step_surface_then:
 *             surface_ready): in one process right after it; distributed,
 *             once rank 0 has every rank's contacts (surf_gather,
 *             dem_mpi.c), among the grain pairs of the next stage, so
 *             that no rank idles while the slowest surface pass ends
 *   grains    the last dem_step_grains (grain pairs, integrate,
 *             neighbour rebuild): overlaps the FEM's step
 *   wait      the FEM's reply: surface positions and velocities at t + k dt
 *   surf_bcast distributed (def->dist): the reply from rank 0, the one that
 *             talks to fem_server, to the other ranks; on two ranks it
 *             rides stage grains' halo exchange instead (rank 0 waits for
 *             it there, timed as stage wait)
 *   update    dem_surface_update (the tree's root box; the rest of the tree
 *             is refitted in stage surface when the tree is walked), the
 *             terrain window moved
 *   record    output hook, checkpoint, health check, progress line
 * The FEM needs only the forces, so everything after send runs while it
 * steps; the DEM waits only if its grain work is shorter than the FEM's step. */
#include "dem_coupled.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "ipc.h"
#include "log.h"
#include "timer.h"

/* The frame from fem_server as the loop reads it: on rank 0 from the ring,
 * on the other ranks from rank 0 (stage surf_bcast). */
typedef struct reply {
    double kind, flags, wheel_x, stop_requested;
    double window, freeze_lo, freeze_hi; /* distributed: what the window does (dem_window_pending) */
} reply;

/* The reply and the surface's positions and velocities after it, in one
 * block: distributed, one broadcast takes it all to the other ranks (they
 * wait in it at every exchange; three in a row took three latencies). */
typedef struct reply_msg {
    reply in;
    double xv[]; /* 3 nn positions, then 3 nn velocities */
} reply_msg;

typedef struct coupled {
    dem_world *w;
    const dem_coupled_def *def;
    ipc_channel *ch; /* NULL on the ranks other than 0 */
    int root;        /* talks to fem_server */
    uint32_t nn;
    int *tris;
    reply_msg *msg;  /* x and v are its xv */
    double *f_sum, *x, *v, *x_sub, *mass;
    double w_dem; /* J, interface work seen by the DEM */
    /* the exchange in progress, for stage send (surface_ready) */
    dem_surface_total acc; /* the interval's surface totals */
    double time;
    long n;
    int *asked_checkpoint;
    const int *stop_requested;
    int ipc_rc;    /* the send's (or the reply's, received in the halo) ring status */
    double send_s; /* s, stage send so far */
} coupled;

static void coupled_free(coupled *c)
{
    free(c->tris);
    free(c->mass);
    free(c->f_sum);
    free(c->msg);
    free(c->x_sub);
}

/* Surface positions a fraction of the interval ahead, from the node
 * velocities the FEM sent (first-order extrapolation inside the interval). */
static int move_surface(coupled *c, double tau, cm_error *err)
{
    size_t m = 3 * (size_t)c->nn;
    for (size_t j = 0; j < m; j++)
        c->x_sub[j] = c->x[j] + tau * c->v[j];
    return dem_surface_update(c->w, c->x_sub, c->v, err);
}

/* Run-time guard: stop with the cause and the setting to change rather than
 * write garbage. Grain overlaps beyond max_overlap of the radius mean the
 * contacts are too soft for the load or the step too long; non-finite
 * energies mean the integration has already failed.
 * Exchange n looks at part n % HEALTH_PARTS of the grains and pairs, so
 * every one of them once per 100 exchanges; the tire's largest overlap (of
 * the last step) at every 100th exchange. Until session 33 the whole world
 * every 100th exchange: a pause of ~1.5 ms on rank 1 of the paper scene
 * that the other rank and fem_server waited out (~1 % of the run). */
enum { HEALTH_PARTS = 100 };

static int check_health(dem_world *w, const dem_coupled_def *def, long n, cm_error *err)
{
    dem_stats s;
    const int part = (int)(n % HEALTH_PARTS);
    dem_world_stats_part(w, part, HEALTH_PARTS, &s);
    if (part != 0)
        s.max_overlap_surface = 0.0;
    if (!isfinite(s.ke_trans) || !isfinite(s.ke_rot))
        return cm_fail(err, CM_ERR_NUMERIC, "grain velocities are no longer finite at t = %.4f s (step %ld): the "
                       "integration is unstable; reduce coupling.dt", s.time, s.step);
    if (def->max_overlap > 0 && s.max_overlap > def->max_overlap)
        return cm_fail(err, CM_ERR_NUMERIC,
                       "a grain overlap reached %.0f %% of the radius at t = %.4f s (step %ld; limit "
                       "coupling.max_overlap = %.0f %%): the contacts are too soft for the load or coupling.dt is "
                       "too long; raise the soil's young modulus or reduce coupling.dt",
                       100 * s.max_overlap, s.time, s.step, 100 * def->max_overlap);
    /* Against the soft tread a grain's Hertz indentation is the rubber's real
     * deformation; only far beyond it (the grain about to pass the triangle,
     * whose contact is two-sided) is the run failing. */
    if (def->max_surface_overlap > 0 && s.max_overlap_surface > def->max_surface_overlap)
        return cm_fail(err, CM_ERR_NUMERIC,
                       "a grain pressed into the tire by %.0f %% of its radius at t = %.4f s (step %ld; limit "
                       "coupling.max_surface_overlap = %.0f %%): grain %d (r %.2f mm%s) at (%.4f, %.4f, %.4f) m moving "
                       "(%.3f, %.3f, %.3f) m/s against surface triangle %d; the tread's contact is too soft for the "
                       "load or coupling.dt is too long; raise the tread material's young modulus or reduce "
                       "coupling.dt",
                       100 * s.max_overlap_surface, s.time, s.step, 100 * def->max_surface_overlap,
                       s.worst_surface.tag, 1e3 * s.worst_surface.r, s.worst_surface.frozen ? ", frozen" : "",
                       s.worst_surface.x[0], s.worst_surface.x[1], s.worst_surface.x[2], s.worst_surface.v[0],
                       s.worst_surface.v[1], s.worst_surface.v[2], s.worst_surface.tri);
    return CM_OK;
}

/* Adds the wall time since *t to *acc and restarts the clock. */
static void lap(double *t, double *acc)
{
    double now = cm_now();
    *acc += now - *t;
    *t = now;
}

/* Stage "send": the interval's mean forces (or the finish frame) posted.
 * Returns the ring's status (an ipc error: the caller reports the peer). */
static int stage_send(coupled *c, const dem_coupled_def *def, int finish, double time, long n,
                      const dem_surface_total *acc, int *asked_checkpoint)
{
    const size_t m = 3 * (size_t)c->nn;
    const int k_steps = def->exchange_every;
    ipc_frame_head *out;
    double *p;
    int rc;
    if ((rc = ipc_send_begin(c->ch, &out, &p)))
        return rc;
    out->kind = finish ? IPC_FRAME_FINISH : IPC_FRAME_DATA;
    out->time = time;
    if (!finish) {
        const double inv = 1.0 / k_steps, interval = def->dt * k_steps, *f_sum = c->f_sum, *v = c->v;
        /* summed in a local: the frame p might alias c->w_dem for all the
         * compiler knows, and the sum went through memory at every node
         * (~1.5 % of rank 0's time in the paper scene, perf); the same adds
         * in the same order */
        double w_dem = c->w_dem;
        for (size_t q = 0; q < m; q++) {
            const double fq = f_sum[q] * inv;
            p[q] = fq;
            w_dem += fq * v[q] * interval; /* power of the forces on the moving surface */
        }
        c->w_dem = w_dem;
        for (int a = 0; a < 3; a++) {
            out->info[IPC_INFO_FORCE_X + a] = acc->force[a] * inv;
            out->info[IPC_INFO_MOMENT_X + a] = acc->moment[a] * inv;
        }
        out->info[IPC_INFO_TRACTION_POS] = acc->traction_pos * inv;
        out->info[IPC_INFO_TRACTION_NEG] = acc->traction_neg * inv;
        out->info[IPC_INFO_CONTACTS] = acc->contacts * inv;
        out->info[IPC_INFO_DEM_WORK] = c->w_dem;
        out->info[IPC_INFO_BED_HEIGHT] = def->bed_height;
        out->info[IPC_INFO_BED_TOP] = def->bed_top;
        out->info[IPC_INFO_CONTACT_ENERGY] = acc->energy * inv;
        if (def->interrupt && *def->interrupt && !*asked_checkpoint) {
            out->flags |= IPC_FLAG_CHECKPOINT; /* interrupted: checkpoint this exchange, then stop */
            *asked_checkpoint = 1;
            cm_log_info("interrupted: asking fem_server for a checkpoint of exchange %ld", n);
        }
    }
    return ipc_send_commit(c->ch);
}

/* One surface pass's node forces added into c->f_sum, its totals into c->acc. */
static void add_pass(coupled *c)
{
    const size_t m = 3 * (size_t)c->nn;
    dem_surface_total *acc = &c->acc;
    const double *fn = dem_surface_node_forces(c->w);
    for (size_t q = 0; q < m; q++)
        c->f_sum[q] += fn[q];
    dem_surface_total tt;
    dem_surface_totals(c->w, &tt);
    for (int a = 0; a < 3; a++) {
        acc->force[a] += tt.force[a];
        acc->moment[a] += tt.moment[a];
    }
    acc->traction_pos += tt.traction_pos;
    acc->traction_neg += tt.traction_neg;
    acc->contacts += tt.contacts;
    acc->energy += tt.energy;
}

/* The interval's last surface pass, once summed (distributed: every rank's
 * contacts on rank 0, dem_step_surface_then): added, then stage "send" on
 * rank 0. Its time goes to stage send wherever it ran (c->send_s). */
static int surface_ready(dem_world *w, void *user, cm_error *err)
{
    coupled *c = user;
    const double t0 = cm_now();
    int rc = CM_OK;
    (void)w;
    add_pass(c);
    if (c->root && (c->ipc_rc = stage_send(c, c->def, 0, c->time, c->n, &c->acc, c->asked_checkpoint)))
        rc = cm_fail(err, CM_ERR_PEER, "%s", ipc_error(c->ch));
    c->send_s += cm_now() - t0;
    return rc;
}

/* Stage "surface": the interval's k surface steps (and the k - 1 grain steps
 * between them), node forces summed into c->f_sum, totals into c->acc; the
 * last one hands on to surface_ready. */
static int stage_surface(coupled *c, const dem_coupled_def *def, int finish, cm_error *err)
{
    const size_t m = 3 * (size_t)c->nn;
    const int k_steps = def->exchange_every;
    int rc;
    memset(&c->acc, 0, sizeof c->acc);
    memset(c->f_sum, 0, m * sizeof *c->f_sum);
    if (finish)
        return CM_OK;
    for (int j = 0; j < k_steps; j++) {
        if (j > 0 && (rc = move_surface(c, j * def->dt, err)))
            return rc;
        if (j == k_steps - 1)
            return dem_step_surface_then(c->w, surface_ready, c, err);
        if ((rc = dem_step_surface(c->w, err)))
            return rc;
        add_pass(c);
        if ((rc = dem_step_grains(c->w, err)))
            return rc;
    }
    return CM_OK;
}

int dem_coupled_attach(const dem_coupled_def *def, ipc_channel **ch, cm_error *err)
{
    ipc_attach_def ad = ipc_default_attach_def();
    ad.dt = def->dt;
    ad.exchange_every = (uint32_t)def->exchange_every;
    ad.stall_timeout = def->stall_timeout;
    ad.connect_timeout = def->connect_timeout;
    ad.stop_flag = def->stop_flag;
    char ipc_err[512];
    cm_log_info("attaching to %s (dt %.3g s, exchange every %d steps)", def->shm, def->dt, def->exchange_every);
    if (ipc_attach(def->shm, &ad, ch, ipc_err, sizeof ipc_err)) /* ipc's code, mapped: the message names the peer */
        return cm_fail(err, CM_ERR_PEER, "%s", ipc_err);
    return CM_OK;
}

/* The terrain window after an exchange. Distributed, rank 0 alone holds the
 * window and said what it does: freezing is done by every rank on its own
 * grains (the rebuild flag agreed), a shift (removal, appended stretch) on
 * the whole world gathered on rank 0, as one process does it. */
static int window_update(coupled *c, const dem_coupled_def *def, const reply *in, cm_error *err)
{
    const dem_coupled_dist *dist = def->dist;
    dem_world *w = c->w;
    int rc = CM_OK;
    if (!dist)
        return def->window && isfinite(in->wheel_x) ? dem_window_update(def->window, w, in->wheel_x, err) : CM_OK;
    if (in->window == DEM_WINDOW_FREEZE) {
        if (def->window)
            rc = dem_window_update(def->window, w, in->wheel_x, err);
        else
            dem_freeze_outside_x(w, in->freeze_lo, in->freeze_hi);
        return rc ? rc : dist->agree_rebuild(w, dist->user, err);
    }
    if (in->window == DEM_WINDOW_SHIFT) {
        if ((rc = dist->collect(w, dist->user, err)))
            return rc;
        if (def->window && (rc = dem_window_update(def->window, w, in->wheel_x, err)))
            return rc; /* dem_server stops the other ranks (MPI_Abort) */
        return dist->rejoin(w, dist->user, err);
    }
    return CM_OK;
}

/* Distributed: the surface as fem_server sent it at the handshake, from
 * rank 0 to every rank (node and triangle counts, triangles, positions,
 * masses). */
static int bcast_surface(coupled *c, const dem_coupled_dist *dist, uint32_t *nt, cm_error *err)
{
    uint32_t counts[2] = {c->nn, *nt};
    int rc = dist->bcast(counts, sizeof counts, dist->user, err);
    if (rc)
        return rc;
    c->nn = counts[0], *nt = counts[1];
    return CM_OK;
}

/* Stage "wait" on rank 0: fem_server's reply into c->msg: the frame's
 * kind and flags, the wheel's x, whether the run stops, distributed what
 * the window does, and a data frame's surface positions and velocities.
 * Returns the ring's status. */
static int receive_reply(coupled *c)
{
    const size_t m = 3 * (size_t)c->nn;
    reply *const in = &c->msg->in;
    memset(in, 0, sizeof *in);
    const ipc_frame_head *head;
    const double *q;
    int ipc_rc = ipc_recv(c->ch, &head, &q);
    if (ipc_rc)
        return ipc_rc;
    in->kind = head->kind, in->flags = head->flags, in->wheel_x = head->info[IPC_INFO_CENTER_X];
    /* After our own request the run ends whether or not the peer
     * checkpointed (a FEM side without checkpoints ignores it). */
    in->stop_requested = *c->stop_requested || (head->flags & IPC_FLAG_STOP_REQUEST) != 0 || *c->asked_checkpoint;
    if (c->def->dist && c->def->window && head->kind == IPC_FRAME_DATA && isfinite(in->wheel_x))
        in->window = dem_window_pending(c->def->window, in->wheel_x, &in->freeze_lo, &in->freeze_hi);
    if (head->kind == IPC_FRAME_DATA) {
        memcpy(c->x, q, m * sizeof *c->x);
        memcpy(c->v, q + m, m * sizeof *c->v);
    }
    ipc_recv_release(c->ch);
    return IPC_OK;
}

/* On two ranks the reply rides the step's halo (dem_halo_rider): rank 0
 * receives it just before the halo exchange, which takes it to rank 1. */
static int rider_fill(void *user, cm_error *err)
{
    coupled *c = user;
    c->ipc_rc = receive_reply(c);
    return c->ipc_rc ? cm_fail(err, CM_ERR_PEER, "%s", ipc_error(c->ch)) : CM_OK;
}

int dem_run_coupled(dem_world *w, ipc_channel *ch, const dem_coupled_def *def, dem_coupled_hooks *hooks,
                    cm_error *err)
{
    const dem_coupled_dist *dist = def->dist;
    const int root = !dist || dist->rank == 0; /* talks to fem_server */
    int stop_requested = 0, asked_checkpoint = 0;
    coupled c = {.w = w, .def = def, .ch = ch, .root = root, .asked_checkpoint = &asked_checkpoint,
                 .stop_requested = &stop_requested};
    int rc = CM_OK;     /* common/error.h codes */
    int ipc_rc = IPC_OK; /* ipc.h codes of the exchange, mapped to CM_ERR_PEER at the end */

    uint32_t nt = 0;
    if (root) {
        c.nn = ipc_surface_node_count(c.ch);
        nt = ipc_surface_tri_count(c.ch);
    }
    if (dist && (rc = bcast_surface(&c, dist, &nt, err)))
        goto done;
    size_t m = 3 * (size_t)c.nn;
    c.tris = malloc(3 * (size_t)nt * sizeof *c.tris);
    c.f_sum = calloc(m, sizeof *c.f_sum);
    const size_t msg_bytes = sizeof(reply_msg) + 2 * m * sizeof(double);
    c.msg = calloc(1, msg_bytes); /* v zero until the first reply */
    c.x_sub = malloc(m * sizeof *c.x_sub);
    c.mass = malloc(c.nn * sizeof *c.mass);
    if (c.msg)
        c.x = c.msg->xv, c.v = c.msg->xv + m;
    if (!c.tris || !c.f_sum || !c.msg || !c.x_sub || !c.mass) {
        rc = cm_fail(err, CM_ERR_NOMEM, "out of memory for a surface of %u nodes", c.nn);
        goto done;
    }
    if (root) {
        const uint32_t *t = ipc_surface_tris(c.ch);
        for (size_t k = 0; k < 3 * (size_t)nt; k++)
            c.tris[k] = (int)t[k]; /* ipc checked every index against the node count */
        memcpy(c.x, ipc_surface_nodes(c.ch), m * sizeof *c.x);
        memcpy(c.mass, ipc_surface_masses(c.ch), c.nn * sizeof *c.mass);
    }
    if (dist && ((rc = dist->bcast(c.tris, 3 * (size_t)nt * sizeof *c.tris, dist->user, err)) ||
                 (rc = dist->bcast(c.x, m * sizeof *c.x, dist->user, err)) ||
                 (rc = dist->bcast(c.mass, c.nn * sizeof *c.mass, dist->user, err))))
        goto done;
    /* dem_surface_create checks the triangles' node indices (rank 0's from ipc, checked there too) */
    if ((rc = dem_surface_set(w, (int)c.nn, c.x, (int)nt, c.tris, def->surface_material, err)) ||
        (rc = dem_surface_set_masses(w, c.mass, err)))
        goto done;
    /* Moments about the world origin and traction along +x (the protocol's). */
    const double origin[3] = {0, 0, 0}, travel[3] = {1, 0, 0};
    dem_surface_set_frame(w, origin, travel);
    if (root)
        cm_log_info("surface: %u nodes, %u triangles from fem_server", c.nn, nt);
    if (root) {
        /* the wheel centre's x before the first frame: middle of the surface */
        double xlo = INFINITY, xhi = -INFINITY;
        for (uint32_t k = 0; k < c.nn; k++)
            xlo = fmin(xlo, c.x[3 * k]), xhi = fmax(xhi, c.x[3 * k]);
        double xc = 0.5 * (xlo + xhi);
        dem_window_check_footprint(def->window, w, &def->window_def, xc, def->window_def.expected_sinkage);
        /* resuming, the checkpoint holds the window-changed world instead */
        const int resuming = hooks && hooks->restore;
        if (def->window && !resuming && (rc = dem_window_update(def->window, w, xc, err)))
            goto done;
    }

    const int k_steps = def->exchange_every;
    const double interval = def->dt * k_steps;
    double time = 0, last_progress = cm_now(), t_start = cm_now();
    long n = 0;
    if (hooks && hooks->restore) {
        /* distributed: rank 0 reads the checkpoint (one process's), the
         * loop's state goes to every rank, the grains at the first rebuild */
        dem_coupled_state st = {.n_nodes = (int)c.nn, .x = c.x, .v = c.v};
        if (root && (rc = hooks->restore(w, &st, hooks->user, err)))
            goto done;
        double loop[3] = {(double)st.exchange, st.time, st.w_dem};
        if (dist && ((rc = dist->bcast(loop, sizeof loop, dist->user, err)) ||
                     (rc = dist->bcast(c.x, m * sizeof *c.x, dist->user, err)) ||
                     (rc = dist->bcast(c.v, m * sizeof *c.v, dist->user, err))))
            goto done;
        if ((rc = dem_surface_update(w, c.x, c.v, err)))
            goto done;
        st.exchange = (long)loop[0], st.time = loop[1], st.w_dem = loop[2];
        n = st.exchange + 1;
        time = st.time;
        c.w_dem = st.w_dem;
        if (root)
            cm_log_info("resumed after exchange %ld, t = %.6f s", st.exchange, time);
    }
    /* distributed: rank 0's grains spread over the ranks at the first neighbour rebuild */
    if (dist && (rc = dist->attach(w, dist->user, err)))
        goto done;
    const long n_first = n;
    dem_coupled_profile prof = {0};
    long grains = 0; /* every rank's, for the progress line */
    double t_lap = cm_now();
    for (;; n++) {
        int finish = stop_requested || time >= def->end_time - 0.5 * def->dt;
        /* stage send runs where the last surface pass is ready: right after
         * it, or (distributed) among the grain pairs; its time is its own */
        c.time = time, c.n = n;
        const double send0 = c.send_s;
        rc = stage_surface(&c, def, finish, err);
        if (c.ipc_rc) /* distributed: dem_server stops the other ranks (MPI_Abort) */
            break;
        if (rc)
            goto done;
        lap(&t_lap, &prof.surface);
        const double send1 = c.send_s;
        if (finish && root && (ipc_rc = stage_send(&c, def, finish, time, n, &c.acc, &asked_checkpoint)))
            break;
        lap(&t_lap, &prof.send);
        /* two ranks: the reply rides this step's halo (stages wait and
         * surf_bcast happen inside stage grains; rider_fill's time is
         * moved to stage wait) */
        dem_halo_rider rider = {.buf = c.msg, .bytes = msg_bytes, .fill = root ? rider_fill : NULL, .user = &c};
        const int ride = dist && dist->ranks == 2 && !finish;
        if (ride && (rc = dem_world_set_halo_rider(w, &rider, err)))
            goto done;
        rc = finish ? CM_OK : dem_step_grains(w, err);
        if (ride)
            (void)dem_world_set_halo_rider(w, NULL, err);
        if (c.ipc_rc)
            break;
        if (rc)
            goto done;
        lap(&t_lap, &prof.grains);
        prof.surface -= send1 - send0, prof.grains -= c.send_s - send1, prof.send += c.send_s - send0;
        prof.grains -= rider.fill_s, prof.wait += rider.fill_s;

        reply *const in = &c.msg->in;
        if (!rider.carried) {
            const double idle0 = prof.wait + prof.bcast, cpu0 = dist ? cm_thread_cpu_now() : 0.0;
            if (root && (ipc_rc = receive_reply(&c)))
                break;
            lap(&t_lap, &prof.wait);
            /* stage "surf_bcast": what rank 0 received, to every rank (the
             * surface whatever the frame: a finishing one leaves it unread) */
            if (dist && (rc = dist->bcast(c.msg, msg_bytes, dist->user, err)))
                goto done;
            if (dist)
                prof.bcast_bytes += (double)msg_bytes;
            lap(&t_lap, &prof.bcast);
            /* what the time balance leaves out (dem_mpi.c) */
            dem_world_add_idle(w, prof.wait + prof.bcast - idle0, dist ? cm_thread_cpu_now() - cpu0 : 0.0);
        } else
            prof.halo_rides++;
        const uint32_t kind = (uint32_t)in->kind, flags = (uint32_t)in->flags;
        stop_requested = in->stop_requested != 0.0;
        if (kind == IPC_FRAME_FINISH)
            break;
        if (!(kind == IPC_FRAME_DATA)) {
            rc = cm_fail(err, CM_ERR_PEER, "unexpected frame kind %u from fem_server at exchange %ld", kind, n);
            goto done;
        }
        if ((rc = dem_surface_update(w, c.x, c.v, err)))
            goto done;
        time += interval;
        /* between two steps: grains at x(t), the next force sum starts after */
        if ((rc = window_update(&c, def, in, err)))
            goto done;
        lap(&t_lap, &prof.update);

        if (hooks && hooks->after_exchange && (rc = hooks->after_exchange(w, hooks->user, n, err)))
            goto done;
        if ((flags & IPC_FLAG_CHECKPOINT) && hooks && hooks->checkpoint) {
            dem_coupled_state st = {.exchange = n, .time = time, .w_dem = c.w_dem, .n_nodes = (int)c.nn,
                                    .x = c.x, .v = c.v};
            if ((rc = hooks->checkpoint(w, &st, hooks->user, err)))
                goto done;
        }
        /* distributed: each rank checks its own grains (the worst over the
         * ranks is the one process's), a failing one stops them all */
        if ((rc = check_health(w, def, n, err)))
            goto done;
        /* the grains of every rank for the progress line (if any), as often as the check */
        if (dist && def->progress_every > 0 && n % 100 == 0 && (rc = dist->grains(w, &grains, dist->user, err)))
            goto done;
        double now = cm_now();
        if (root && def->progress_every > 0 && now - last_progress >= def->progress_every) {
            last_progress = now;
            if (!dist)
                grains = dem_grain_count(w);
            double steps = (double)(n + 1 - n_first) * k_steps;
            cm_log_info("t = %.4f s  %.0f steps/s (%.2f M grain-steps/s)  grains %ld  surface contacts %.0f", time,
                        steps / (now - t_start), 1e-6 * steps * (double)grains / (now - t_start), grains,
                        c.acc.contacts / (double)k_steps);
        }
        lap(&t_lap, &prof.record);
        prof.exchanges++;
    }
    if (def->profile)
        *def->profile = prof;
    if (c.ipc_rc)
        ipc_rc = c.ipc_rc;
    if (ipc_rc) {
        /* The exchange failed: ipc's message names the peer and the step. */
        rc = cm_fail(err, CM_ERR_PEER, "%s", ipc_error(c.ch));
        goto done;
    }
    uint64_t hash = dem_world_hash(w);
    if (dist && (rc = dist->hash(w, &hash, dist->user, err)))
        goto done;
    if (root) {
        ipc_stats st = ipc_get_stats(c.ch);
        cm_log_info("coupled run finished: %ld exchanges, t = %.4f s; waited for the FEM %.1f s of %.1f s; "
                    "interface work seen by the DEM %.6g J",
                    n, time, st.wait_recv_s + st.wait_send_s, cm_now() - t_start, c.w_dem);
        cm_log_info("final state: dem_world_hash %016llx%s", (unsigned long long)hash,
                    dist ? " (every rank's grains)" : "");
    }
done:
    if (rc && c.ch && rc != CM_ERR_PEER)
        ipc_fail(c.ch, "dem_server: %s", err->msg);
    ipc_close(&c.ch, rc ? IPC_ERR_PEER_FAILED : IPC_OK);
    coupled_free(&c);
    return rc;
}
