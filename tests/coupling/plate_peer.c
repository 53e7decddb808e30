/* plate_peer: a stand-in FEM side that speaks the exchange protocol with a
 * rigid square plate (4 nodes, 2 triangles) held still. It shows how a
 * third-party solver replaces fem_server (./run SCENE --fem plate_peer) and
 * lets the coupled tests compare a grain's impact on the exchanged surface
 * with Hertz theory.
 *
 *   plate_peer --scene FILE --shm NAME --out DIR
 *
 * It owns the scene's `fem` section (the FEM side's section belongs to
 * whichever program plays that role):
 *   fem = { plate_z = 0.0; plate_half_size = 0.05; };
 * and reads `run` and `coupling` like the servers. Every exchange it writes
 * t, Fx, Fy, Fz, contacts (the resultant of the nodal forces on the plate)
 * to DIR/plate.csv, and at the end prints the impulse, the contact duration
 * and the peak of the load (the downward force the grains put on the plate),
 * also written to DIR/plate_run.json (common/runrec.h).
 * After its first exchange it writes its pid to DIR/plate_peer.running. */
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

#include "ipc.h"
#include "runcfg.h"
#include "runrec.h"
#include "scene.h"

static volatile sig_atomic_t g_stop;
static void on_signal(int sig) { g_stop = sig; }

/* After its first exchange the peer leaves its pid in DIR/plate_peer.running
 * (written, then renamed into place): a test waits for the file and kills
 * this process by that pid. */
static int announce_running(const char *out)
{
    char tmp[1100], path[1100];
    snprintf(tmp, sizeof tmp, "%s/plate_peer.running.tmp", out);
    snprintf(path, sizeof path, "%s/plate_peer.running", out);
    FILE *f = fopen(tmp, "w");
    if (!f)
        return -1;
    int ok = fprintf(f, "%d\n", (int)getpid()) > 0;
    ok = fclose(f) == 0 && ok;
    return ok && rename(tmp, path) == 0 ? 0 : -1;
}

int main(int argc, char **argv)
{
    const char *scene_path = NULL, *shm = NULL, *out = ".";
    for (int i = 1; i + 1 < argc; i += 2) {
        if (strcmp(argv[i], "--scene") == 0)
            scene_path = argv[i + 1];
        else if (strcmp(argv[i], "--shm") == 0)
            shm = argv[i + 1];
        else if (strcmp(argv[i], "--out") == 0)
            out = argv[i + 1];
        else if (strcmp(argv[i], "--set") == 0 && cm_scene_add_override(argv[i + 1], NULL) != CM_OK)
            return 2;
    }
    if (!scene_path || !shm) {
        fprintf(stderr, "usage: plate_peer --scene FILE --shm NAME [--out DIR]\n");
        return 2;
    }
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);

    cm_error err = {0};
    cm_scene *scene;
    cm_run_config rc_cfg;
    double z = 0, h = 0.05;
    if (cm_scene_open(scene_path, &scene, &err) || cm_run_config_read(scene, &rc_cfg, &err) ||
        cm_scene_double_opt(scene, "fem.plate_z", -100, 100, 0.0, &z, &err) ||
        cm_scene_double_opt(scene, "fem.plate_half_size", 1e-6, 100, 0.05, &h, &err)) {
        fprintf(stderr, "[plate] error: %s\n", err.msg);
        return 1;
    }
    cm_scene_close(&scene);

    ipc_create_def def = ipc_default_create_def();
    def.n_nodes = 4;
    def.n_tris = 2;
    def.exchange_dt = cm_run_exchange_dt(&rc_cfg);
    def.stop_flag = &g_stop;
    ipc_channel *ch;
    char msg[512];
    if (ipc_create(shm, &def, &ch, msg, sizeof msg)) {
        fprintf(stderr, "[plate] error: %s\n", msg);
        return 3;
    }
    double *x = ipc_surface_nodes(ch);
    const double corners[4][2] = {{-h, -h}, {h, -h}, {h, h}, {-h, h}};
    for (int i = 0; i < 4; i++) {
        x[3 * i] = corners[i][0];
        x[3 * i + 1] = corners[i][1];
        x[3 * i + 2] = z;
    }
    /* Counter-clockwise seen from above (+z): the grains' side. */
    const uint32_t tris[6] = {0, 1, 2, 0, 2, 3};
    memcpy(ipc_surface_tris(ch), tris, sizeof tris);
    double x0[12];
    memcpy(x0, x, sizeof x0);
    if (ipc_accept(ch)) {
        fprintf(stderr, "[plate] error: %s\n", ipc_error(ch));
        ipc_close(&ch, IPC_ERR_PEER_FAILED);
        return 3;
    }
    char path[1100];
    snprintf(path, sizeof path, "%s/plate.csv", out);
    FILE *csv = fopen(path, "w");
    if (!csv) {
        fprintf(stderr, "[plate] error: cannot write %s\n", path);
        ipc_close(&ch, IPC_ERR_PEER_FAILED);
        return 1;
    }
    fprintf(csv, "t,Fx,Fy,Fz,contacts\n");
    double impulse = 0, t_first = -1, t_last = -1, f_max = 0;
    const double interval = cm_run_exchange_dt(&rc_cfg);
    int rc = 0, announced = 0;
    for (;;) {
        const ipc_frame_head *in;
        const double *f;
        if ((rc = ipc_recv(ch, &in, &f)))
            break;
        uint32_t kind = in->kind;
        double t = in->time, fz = 0, fx = 0, fy = 0, contacts = in->info[IPC_INFO_CONTACTS];
        for (int i = 0; i < 4 && kind == IPC_FRAME_DATA; i++) {
            fx += f[3 * i];
            fy += f[3 * i + 1];
            fz += f[3 * i + 2];
        }
        ipc_recv_release(ch);
        ipc_frame_head *o;
        double *p;
        if ((rc = ipc_send_begin(ch, &o, &p)))
            break;
        o->kind = kind;
        o->time = t + interval;
        if (kind == IPC_FRAME_DATA) {
            memcpy(p, x0, sizeof x0);      /* positions: the plate does not move */
            memset(p + 12, 0, 12 * sizeof(double)); /* velocities */
        }
        if ((rc = ipc_send_commit(ch)) || kind == IPC_FRAME_FINISH)
            break;
        if (!announced && announce_running(out) != 0) {
            ipc_fail(ch, "plate_peer: cannot write %s/plate_peer.running", out);
            rc = IPC_ERR_PEER_FAILED;
            break;
        }
        announced = 1;
        fprintf(csv, "%.9g,%.9g,%.9g,%.9g,%g\n", t, fx, fy, fz, contacts);
        double load = -fz; /* grains push the plate down */
        impulse += load * interval;
        if (load > 0) {
            if (t_first < 0)
                t_first = t;
            t_last = t + interval;
        }
        f_max = load > f_max ? load : f_max;
    }
    fclose(csv);
    if (rc) {
        fprintf(stderr, "[plate] error: %s\n", ipc_error(ch));
        ipc_close(&ch, rc);
        return g_stop ? 128 + (int)g_stop : 3;
    }
    const double duration = t_first >= 0 ? t_last - t_first : 0.0;
    printf("[plate] impulse %.9g N s, contact duration %.9g s, peak force %.9g N\n", impulse, duration, f_max);
    ipc_close(&ch, IPC_OK);
    /* The same for scripts (bench/study/run): DIR/plate_run.json */
    cm_run_record rec = {0};
    cm_runrec_text(&rec, "program", "plate_peer");
    cm_runrec_num(&rec, "impulse", impulse);
    cm_runrec_num(&rec, "contact_time", duration);
    cm_runrec_num(&rec, "peak_force", f_max);
    snprintf(path, sizeof path, "%s/plate_run.json", out);
    if (cm_runrec_write(&rec, path, &err)) {
        fprintf(stderr, "[plate] error: %s\n", err.msg);
        return 1;
    }
    return 0;
}
