/* plate_rig: the virtual plate-sinkage test of the soil calibration (issue
 * 15). A rigid rectangular plate, served to dem_server as the FEM side of the
 * exchange protocol (ipc/PROTOCOL.md), is pressed into the settled bed at a
 * constant speed; every exchange it records the plate's depth below the
 * point where it first touched a grain and the pressure the grains put on it.
 * bench/calibrate/terramech.py fits Bekker's p = (k_c/b + k_phi) z^n to two
 * plate widths.
 *
 *   ./run scenes/calibrate/plate_sinkage.cfg --fem build/bench/calibrate/plate_rig
 *
 * It owns the scene's `fem` section (the FEM side's section belongs to the
 * program that plays that role):
 *   fem = { plate = { size = [0.05, 0.05];    # m, along x and y (b = the smaller)
 *                     center = [0.15, 0.15];  # m, x and y
 *                     start_z = 0.13;         # m, the plate's height at t = 0
 *                     speed = 0.05; }; };     # m/s, downwards
 * and reads `run` and `coupling` like the servers. The DEM side ends the run
 * at run.end_time. Output: DIR/plate_sinkage.csv with the columns
 *   t (s), plate_z (m), sinkage (m, below the plate's first contact, 0
 *   before), depth (m, below the bed's mean surface as dem_server reports
 *   it; negative above), force (N, upward on the plate), pressure (Pa,
 *   force / plate area), contacts.
 * Bekker's z is the sinkage below the undisturbed surface, which a bed of
 * grains defines only to within a grain radius: the fit uses `sinkage`, and
 * `depth` tells where the first contact was. */
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <string.h>

#include "csv.h"
#include "ipc.h"
#include "runcfg.h"
#include "scene.h"

static volatile sig_atomic_t g_stop;
static void on_signal(int sig) { g_stop = sig; }

typedef struct plate_def {
    double size[2];   /* m, along x and y */
    double center[2]; /* m */
    double start_z;   /* m, height of the plate at t = 0 */
    double speed;     /* m/s, downwards */
} plate_def;

static int read_plate(cm_scene *s, plate_def *d, cm_error *err)
{
    /* strict, as the servers: a misspelt fem.plate key is an error; the
     * terrain's sections are dem_server's (or scm_server's) */
    static const char *const sections[] = {"run", "coupling", "fem", NULL};
    if (cm_scene_doubles(s, "fem.plate.size", 2, 1e-4, 100, d->size, err) ||
        cm_scene_doubles(s, "fem.plate.center", 2, -1e3, 1e3, d->center, err) ||
        cm_scene_double(s, "fem.plate.start_z", -1e3, 1e3, &d->start_z, err) ||
        cm_scene_double(s, "fem.plate.speed", 1e-6, 10, &d->speed, err))
        return err->code;
    cm_scene_skip_foreign(s, sections);
    return cm_scene_check_unknown(s, sections, err);
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
        else if (strcmp(argv[i], "--set") == 0) {
            cm_error e = {0};
            if (cm_scene_add_override(argv[i + 1], &e) != CM_OK) {
                fprintf(stderr, "[plate_rig] error: %s\n", e.msg);
                return 2;
            }
        }
    }
    if (!scene_path || !shm) {
        fprintf(stderr, "usage: plate_rig --scene FILE --shm NAME [--out DIR] [--set KEY=VALUE ...]\n");
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
    plate_def pd;
    if (cm_scene_open(scene_path, &scene, &err) || cm_run_config_read(scene, &rc_cfg, &err) ||
        read_plate(scene, &pd, &err)) {
        fprintf(stderr, "[plate_rig] error: %s\n", err.msg);
        return 1;
    }
    cm_scene_close(&scene);

    const double interval = cm_run_exchange_dt(&rc_cfg);
    ipc_create_def def = ipc_default_create_def();
    def.n_nodes = 4;
    def.n_tris = 2;
    def.exchange_dt = interval;
    def.stall_timeout = rc_cfg.stall_timeout;
    def.connect_timeout = rc_cfg.connect_timeout;
    def.stop_flag = &g_stop;
    ipc_channel *ch;
    char msg[512];
    if (ipc_create(shm, &def, &ch, msg, sizeof msg)) {
        fprintf(stderr, "[plate_rig] error: %s\n", msg);
        return 3;
    }
    const double hx = 0.5 * pd.size[0], hy = 0.5 * pd.size[1];
    const double corners[4][2] = {{-hx, -hy}, {hx, -hy}, {hx, hy}, {-hx, hy}};
    double *x = ipc_surface_nodes(ch);
    for (int i = 0; i < 4; i++) {
        x[3 * i] = pd.center[0] + corners[i][0];
        x[3 * i + 1] = pd.center[1] + corners[i][1];
        x[3 * i + 2] = pd.start_z;
    }
    /* Clockwise seen from above: the normal points down, to the grains. */
    const uint32_t tris[6] = {0, 2, 1, 0, 3, 2};
    memcpy(ipc_surface_tris(ch), tris, sizeof tris);
    double *mass = ipc_surface_masses(ch);
    for (int i = 0; i < 4; i++)
        mass[i] = 1.0; /* kg; the plate is driven, its mass only enters the DEM's time-step check */
    if (ipc_accept(ch)) {
        fprintf(stderr, "[plate_rig] error: %s\n", ipc_error(ch));
        ipc_close(&ch, IPC_ERR_PEER_FAILED);
        return 3;
    }
    char path[1100];
    snprintf(path, sizeof path, "%s/plate_sinkage.csv", out);
    static const char *const cols[] = {"t", "plate_z", "sinkage", "depth", "force", "pressure", "contacts"};
    cm_csv *csv;
    if (cm_csv_create(path, cols, 7, &csv, &err)) {
        fprintf(stderr, "[plate_rig] error: %s\n", err.msg);
        ipc_close(&ch, IPC_ERR_PEER_FAILED);
        return 1;
    }
    const double area = pd.size[0] * pd.size[1];
    double z_touch = NAN, f_max = 0;
    int rc = 0;
    for (;;) {
        const ipc_frame_head *in;
        const double *f;
        if ((rc = ipc_recv(ch, &in, &f)))
            break;
        uint32_t kind = in->kind;
        double t = in->time, fz = 0, contacts = in->info[IPC_INFO_CONTACTS], bed = in->info[IPC_INFO_BED_HEIGHT];
        for (int i = 0; i < 4 && kind == IPC_FRAME_DATA; i++)
            fz += f[3 * i + 2];
        ipc_recv_release(ch);
        if (kind == IPC_FRAME_DATA && !isfinite(fz)) {
            ipc_fail(ch, "plate_rig: non-finite force from the DEM side at t = %.6g s", t);
            rc = IPC_ERR_PROTOCOL;
            break;
        }
        /* The plate's height for the forces just received (at t) and where
         * it goes next (t + interval). */
        double z_now = pd.start_z - pd.speed * t, z_next = z_now - pd.speed * interval;
        ipc_frame_head *o;
        double *p;
        if ((rc = ipc_send_begin(ch, &o, &p)))
            break;
        o->kind = kind;
        o->time = t + interval;
        if (kind == IPC_FRAME_DATA) {
            for (int i = 0; i < 4; i++) {
                p[3 * i] = x[3 * i];
                p[3 * i + 1] = x[3 * i + 1];
                p[3 * i + 2] = z_next;
                p[12 + 3 * i] = 0.0;
                p[12 + 3 * i + 1] = 0.0;
                p[12 + 3 * i + 2] = -pd.speed;
            }
        }
        if ((rc = ipc_send_commit(ch)) || kind == IPC_FRAME_FINISH)
            break;
        if (isnan(z_touch) && contacts > 0)
            z_touch = z_now;
        double sinkage = isnan(z_touch) ? 0.0 : z_touch - z_now;
        double row[7] = {t, z_now, sinkage, bed - z_now, fz, fz / area, contacts};
        if (cm_csv_row(csv, row, &err)) {
            ipc_fail(ch, "plate_rig: %s", err.msg);
            rc = IPC_ERR_PEER_FAILED;
            break;
        }
        f_max = fz > f_max ? fz : f_max;
    }
    if (cm_csv_close(&csv, &err) && !rc) {
        fprintf(stderr, "[plate_rig] error: %s\n", err.msg);
        ipc_close(&ch, IPC_ERR_PEER_FAILED);
        return 1;
    }
    if (rc) {
        fprintf(stderr, "[plate_rig] error: %s\n", ipc_error(ch));
        ipc_close(&ch, rc);
        return g_stop ? 128 + (int)g_stop : 3;
    }
    printf("[plate_rig] plate %.3f x %.3f m: first contact at z = %.4f m, peak pressure %.4g Pa; %s\n", pd.size[0],
           pd.size[1], z_touch, f_max / area, path);
    ipc_close(&ch, IPC_OK);
    return 0;
}
