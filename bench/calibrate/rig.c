/* rig: the protocol loop of the calibration rigs (rig.h). */
#include "rig.h"

#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "ipc.h"

static volatile sig_atomic_t g_stop;
static void on_signal(int sig) { g_stop = sig; }

int rig_parse_args(const char *name, int argc, char **argv, rig_args *a)
{
    a->scene = a->shm = NULL;
    a->out = ".";
    for (int i = 1; i + 1 < argc; i += 2) {
        if (strcmp(argv[i], "--scene") == 0)
            a->scene = argv[i + 1];
        else if (strcmp(argv[i], "--shm") == 0)
            a->shm = argv[i + 1];
        else if (strcmp(argv[i], "--out") == 0)
            a->out = argv[i + 1];
        else if (strcmp(argv[i], "--set") == 0) {
            cm_error e = {0};
            if (cm_scene_add_override(argv[i + 1], &e) != CM_OK) {
                fprintf(stderr, "[%s] error: %s\n", name, e.msg);
                return 2;
            }
        }
    }
    if (!a->scene || !a->shm) {
        fprintf(stderr, "usage: %s --scene FILE --shm NAME [--out DIR] [--set KEY=VALUE ...]\n", name);
        return 2;
    }
    return 0;
}

int rig_read_scene(const char *name, const rig_args *a, cm_run_config *rc,
                   int (*read)(cm_scene *s, void *user, cm_error *err), void *user)
{
    /* strict, as the servers: a misspelt fem key is an error; the terrain's
     * sections are dem_server's (or scm_server's) */
    static const char *const sections[] = {"run", "coupling", "fem", NULL};
    cm_error err = {0};
    cm_scene *s = NULL;
    int rc_ = cm_scene_open(a->scene, &s, &err);
    if (!rc_)
        rc_ = cm_run_config_read(s, rc, &err);
    if (!rc_)
        rc_ = read(s, user, &err);
    if (!rc_) {
        cm_scene_skip_foreign(s, sections);
        rc_ = cm_scene_check_unknown(s, sections, &err);
    }
    cm_scene_close(&s);
    if (rc_) {
        fprintf(stderr, "[%s] error: %s\n", name, err.msg);
        return 1;
    }
    return 0;
}

int rig_run(const rig_def *d, const cm_run_config *rcfg, const rig_args *a)
{
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);

    const double interval = cm_run_exchange_dt(rcfg);
    ipc_create_def def = ipc_default_create_def();
    def.n_nodes = (uint32_t)d->n_nodes;
    def.n_tris = (uint32_t)d->n_tris;
    def.exchange_dt = interval;
    def.stall_timeout = rcfg->stall_timeout;
    def.connect_timeout = rcfg->connect_timeout;
    def.stop_flag = &g_stop;
    ipc_channel *ch;
    char msg[512];
    if (ipc_create(a->shm, &def, &ch, msg, sizeof msg)) {
        fprintf(stderr, "[%s] error: %s\n", d->name, msg);
        return 3;
    }
    const size_t n3 = 3 * (size_t)d->n_nodes;
    memcpy(ipc_surface_nodes(ch), d->x0, n3 * sizeof(double));
    memcpy(ipc_surface_tris(ch), d->tris, 3 * (size_t)d->n_tris * sizeof(uint32_t));
    double *mass = ipc_surface_masses(ch);
    for (int i = 0; i < d->n_nodes; i++)
        mass[i] = d->mass ? d->mass[i] : 0.0;
    if (ipc_accept(ch)) {
        fprintf(stderr, "[%s] error: %s\n", d->name, ipc_error(ch));
        ipc_close(&ch, IPC_ERR_PEER_FAILED);
        return 3;
    }
    /* the forces are copied out of the ring slot so that the slot goes back
     * to the DEM side before the rig computes */
    double *force = malloc(n3 * sizeof *force), info[IPC_INFO_LEN];
    if (!force) {
        ipc_fail(ch, "%s: out of memory", d->name);
        ipc_close(&ch, IPC_ERR_PEER_FAILED);
        return 1;
    }
    cm_error err = {0};
    int rc = 0, own = 0;
    for (;;) {
        const ipc_frame_head *in;
        const double *f;
        if ((rc = ipc_recv(ch, &in, &f)))
            break;
        const uint32_t kind = in->kind;
        const double t = in->time;
        if (kind == IPC_FRAME_DATA) {
            memcpy(force, f, n3 * sizeof *force);
            memcpy(info, in->info, sizeof info);
        }
        ipc_recv_release(ch);
        int finite = 1;
        for (size_t k = 0; k < n3 && kind == IPC_FRAME_DATA; k++)
            finite = finite && isfinite(force[k]);
        if (!finite) {
            ipc_fail(ch, "%s: non-finite force from the DEM side at t = %.6g s", d->name, t);
            rc = IPC_ERR_PROTOCOL;
            break;
        }
        ipc_frame_head *o;
        double *p;
        if ((rc = ipc_send_begin(ch, &o, &p)))
            break;
        o->kind = kind;
        o->time = t + interval;
        if (kind == IPC_FRAME_DATA) {
            const rig_in ri = {.t = t, .t_next = t + interval, .force = force, .info = info};
            rig_out ro = {.x = p, .v = p + n3, .info = o->info, .stop = 0};
            memset(o->info, 0, sizeof o->info);
            if (d->advance(d->user, &ri, &ro, &err)) {
                ipc_fail(ch, "%s: %s", d->name, err.msg);
                rc = IPC_ERR_PEER_FAILED;
                own = 1;
                break;
            }
            if (ro.stop)
                o->flags |= IPC_FLAG_STOP_REQUEST;
        }
        if ((rc = ipc_send_commit(ch)) || kind == IPC_FRAME_FINISH)
            break;
        if (d->record && d->record(d->user, &err)) {
            ipc_fail(ch, "%s: %s", d->name, err.msg);
            rc = IPC_ERR_PEER_FAILED;
            own = 1;
            break;
        }
    }
    free(force);
    if (rc) {
        fprintf(stderr, "[%s] error: %s\n", d->name, own ? err.msg : ipc_error(ch));
        ipc_close(&ch, rc);
        return g_stop ? 128 + (int)g_stop : own ? 1 : 3;
    }
    ipc_close(&ch, IPC_OK);
    return 0;
}
