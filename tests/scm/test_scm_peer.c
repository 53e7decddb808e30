/* scm_server as a real process on a real segment, against a FEM side that
 * this test plays itself (a forked child using the ipc library, serving a
 * rigid 0.1 x 0.1 m plate pressed 1 cm into the soil):
 *   plate_through_protocol  the forces that arrive are the closed form p(z) A, the info totals
 *                           equal the nodal sums, the run ends with finish frames, exit 0
 *   fem_peer_killed         the FEM side is SIGKILLed mid-run: scm_server exits 3 within 3 s
 *                           naming the dead peer, and /dev/shm holds nothing
 *   scm_killed              scm_server is SIGKILLed mid-run: the FEM side notices a dead peer
 *                           within 3 s; /dev/shm holds nothing
 *   tire_small_on_scm       ./run SCENE --terrain scm with the real fem_server (small tire, its
 *                           lightest surface nodes exchanged explicitly every 1e-5 s): it ends
 *                           cleanly, fem_server's check of the nodal forces against the totals
 *                           holds to round-off, both sides see the same interface work
 * Processes are stopped by the pid this test started; the moment to kill is
 * signalled by the FEM side through a pipe after 20 exchanges. */
#include <errno.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "ipc.h"
#include "proc.h"
#include "test.h"

#if !defined(SCM_SERVER_PATH) || !defined(DEMFEM_SOURCE_DIR) || !defined(DEMFEM_BUILD_DIR)
#error "SCM_SERVER_PATH, DEMFEM_SOURCE_DIR and DEMFEM_BUILD_DIR must be defined"
#endif

/* Soil of the scene below (dry sand defaults, z_reg 1e-4 < 1 cm). */
static const double k_c = 0.99e3, k_phi = 1528.43e3, n_exp = 1.1, depth = 0.01, side = 0.1, h0 = 0.08;
static const double dt = 1e-4;

typedef struct run_files {
    char scene[200], log[200], shm[64], out[200];
} run_files;

static int write_scene(run_files *f, const char *tag, double end_time)
{
    snprintf(f->scene, sizeof f->scene, "/tmp/scm-peer-%d-%s.cfg", (int)getpid(), tag);
    snprintf(f->log, sizeof f->log, "/tmp/scm-peer-%d-%s.log", (int)getpid(), tag);
    snprintf(f->out, sizeof f->out, "/tmp/scm-peer-%d-%s", (int)getpid(), tag);
    snprintf(f->shm, sizeof f->shm, "/scm-peer-%d-%s", (int)getpid(), tag);
    FILE *s = fopen(f->scene, "w");
    if (!s)
        return -1;
    fprintf(s,
            "run = { end_time = %.9g; progress_every = 0.0; };\n"
            "coupling = { dt = %g; connect_timeout = 30.0; stall_timeout = 30.0; };\n"
            "wheel = { radius = 0.3; };   # the FEM side's: skipped\n"
            "scm = { surface_height = %g; grid = { min = [-0.2, -0.2]; max = [0.2, 0.2]; cell = 0.005; }; };\n",
            end_time, dt, h0);
    return fclose(s);
}

static int spawn_scm(tp_proc *p, const run_files *f)
{
    const char *argv[] = {SCM_SERVER_PATH, "--scene", f->scene, "--shm", f->shm, "--out", f->out, NULL};
    return tp_spawn(p, argv, f->log, 0);
}

static const char *read_log(const run_files *f)
{
    tp_proc p = {.pid = -1};
    snprintf(p.log, sizeof p.log, "%s", f->log);
    return tp_log_text(&p);
}

static int shm_gone(const run_files *f)
{
    char path[128];
    snprintf(path, sizeof path, "/dev/shm%s", f->shm);
    return access(path, F_OK) != 0 && errno == ENOENT;
}

/* The FEM side, in the forked child. Serves the plate; after 20 exchanges
 * writes one byte to notify_fd (if >= 0). Exit codes: 0 a clean finish with
 * every force as the closed form; 10 a force off; 42 the peer died; 1 other. */
static int fem_side(void *arg, int notify_fd)
{
    const run_files *f = arg;
    ipc_create_def def = ipc_default_create_def();
    def.n_nodes = 4;
    def.n_tris = 2;
    def.exchange_dt = dt;
    def.connect_timeout = 30;
    /* a loaded machine may not schedule a heartbeat for a second: a killed
     * peer is still noticed at once, by its pid */
    def.stall_timeout = 30;
    ipc_channel *ch;
    char msg[512];
    if (ipc_create(f->shm, &def, &ch, msg, sizeof msg)) {
        fprintf(stderr, "fem side: %s\n", msg);
        return 1;
    }
    const double h = 0.5 * side, z = h0 - depth;
    double *x = ipc_surface_nodes(ch);
    const double corners[4][2] = {{-h, -h}, {h, -h}, {h, h}, {-h, h}};
    for (int i = 0; i < 4; i++)
        x[3 * i] = corners[i][0], x[3 * i + 1] = corners[i][1], x[3 * i + 2] = z;
    /* counter-clockwise seen from below: the soil's side */
    const uint32_t tris[6] = {0, 2, 1, 0, 3, 2};
    memcpy(ipc_surface_tris(ch), tris, sizeof tris);
    double x0[12];
    memcpy(x0, x, sizeof x0);
    if (ipc_accept(ch)) {
        fprintf(stderr, "fem side: %s\n", ipc_error(ch));
        ipc_close(&ch, IPC_ERR_PEER_FAILED);
        return 1;
    }
    const double p = (k_c / side + k_phi) * pow(depth, n_exp), load = p * side * side;
    int bad = 0, rc;
    long n = 0;
    for (;; n++) {
        const ipc_frame_head *in;
        const double *fr;
        if ((rc = ipc_recv(ch, &in, &fr)))
            break;
        const uint32_t kind = in->kind;
        if (kind == IPC_FRAME_DATA) {
            double F[3] = {0, 0, 0};
            for (int i = 0; i < 4; i++)
                for (int a = 0; a < 3; a++)
                    F[a] += fr[3 * i + a];
            bad |= fabs(F[2] - load) > 1e-9 * load || fabs(F[0]) > 1e-9 * load;
            for (int a = 0; a < 3; a++)
                bad |= fabs(in->info[IPC_INFO_FORCE_X + a] - F[a]) > 1e-12 * load;
            bad |= in->info[IPC_INFO_BED_HEIGHT] != h0 || in->info[IPC_INFO_CONTACTS] != 400;
            if (bad)
                fprintf(stderr, "fem side: exchange %ld: F = (%g, %g, %g) N, closed form F_z %g N, info F_z %g\n", n,
                        F[0], F[1], F[2], load, in->info[IPC_INFO_FORCE_Z]);
        }
        ipc_recv_release(ch);
        ipc_frame_head *o;
        double *q;
        if ((rc = ipc_send_begin(ch, &o, &q)))
            break;
        o->kind = kind;
        o->time = (n + 1) * dt;
        if (kind == IPC_FRAME_DATA) {
            memcpy(q, x0, sizeof x0);
            memset(q + 12, 0, 12 * sizeof(double));
        }
        if ((rc = ipc_send_commit(ch)) || kind == IPC_FRAME_FINISH)
            break;
        if (n == 20)
            tp_announce(notify_fd, 'x');
    }
    if (rc) {
        fprintf(stderr, "fem side: %s\n", ipc_error(ch));
        ipc_close(&ch, rc);
        return rc == IPC_ERR_PEER_DEAD ? 42 : 1;
    }
    ipc_close(&ch, IPC_OK);
    return bad ? 10 : 0;
}

static int plate_through_protocol(void)
{
    run_files f;
    ENSURE(write_scene(&f, "plate", 50 * dt) == 0);
    tp_proc fem, scm;
    ENSURE(tp_fork(&fem, fem_side, &f, 0) == 0);
    ENSURE(spawn_scm(&scm, &f) == 0);
    int scm_rc = tp_finish(&scm, 60), fem_rc = tp_finish(&fem, 60);
    if (scm_rc != 0 || fem_rc != 0)
        fprintf(stderr, "---- %s ----\n%s----\n", f.log, read_log(&f));
    ENSURE(scm_rc == 0);
    ENSURE_MSG(fem_rc == 0, "the FEM side ended with %d (10: a force differed from p(z) A)", fem_rc);
    ENSURE(shm_gone(&f));
    char rut[300];
    snprintf(rut, sizeof rut, "%s/scm_rut.csv", f.out);
    ENSURE(access(rut, R_OK) == 0);
    printf("  50 exchanges: every force p(z) A = %.6g N to 1e-9, totals equal to the nodal sums\n",
           (k_c / side + k_phi) * pow(depth, n_exp) * side * side);
    unlink(f.scene);
    return 0;
}

/* Kills one side after 20 exchanges; returns the survivor's exit code and
 * its reaction time. */
static int kill_one(const char *tag, int kill_fem, int *survivor_rc, double *reaction, run_files *f)
{
    ENSURE(write_scene(f, tag, 1e6) == 0);
    tp_proc fem, scm;
    ENSURE(tp_fork(&fem, fem_side, f, TP_READY) == 0);
    if (spawn_scm(&scm, f) != 0) {
        tp_kill(&fem);
        ENSURE_MSG(0, "cannot start %s", SCM_SERVER_PATH);
    }
    /* until the 20th exchange, or EOF when the FEM side ends first */
    if (tp_wait_ready(&fem, 'x', 600) != 0) {
        tp_kill(&scm);
        tp_kill(&fem);
        tp_print_log(&scm);
        ENSURE_MSG(0, "the run did not reach 20 exchanges");
    }
    tp_proc *victim = kill_fem ? &fem : &scm, *survivor = kill_fem ? &scm : &fem;
    ENSURE(kill(victim->pid, SIGKILL) == 0);
    double t0 = tp_now();
    int killed_rc = tp_finish(victim, 10);
    *survivor_rc = tp_finish(survivor, 20);
    *reaction = tp_now() - t0;
    ENSURE(killed_rc == 128 + SIGKILL);
    unlink(f->scene);
    return 0;
}

static int fem_peer_killed(void)
{
    run_files f;
    int rc;
    double reaction;
    if (kill_one("femkilled", 1, &rc, &reaction, &f))
        return 1;
    const char *log = read_log(&f);
    printf("  scm_server exited %d %.2f s after the FEM side was killed\n", rc, reaction);
    if (rc != 3)
        fprintf(stderr, "---- %s ----\n%s----\n", f.log, log);
    ENSURE(rc == 3);
    ENSURE_MSG(reaction < 3.0, "took %.2f s", reaction);
    ENSURE_MSG(strstr(log, "peer fem") && strstr(log, "died"), "the log should name the dead peer");
    ENSURE(shm_gone(&f));
    return 0;
}

static int scm_killed(void)
{
    run_files f;
    int rc;
    double reaction;
    if (kill_one("scmkilled", 0, &rc, &reaction, &f))
        return 1;
    printf("  the FEM side exited %d %.2f s after scm_server was killed\n", rc, reaction);
    ENSURE_MSG(rc == 42, "the FEM side should see a dead peer (42), ended with %d", rc);
    ENSURE_MSG(reaction < 3.0, "took %.2f s", reaction);
    ENSURE(shm_gone(&f));
    return 0;
}

/* Values of the named columns in the last row of DIR/traction.csv. */
static int last_row(const char *dir, const char *const *cols, double *vals, int n)
{
    char path[400], line[8192], header[8192];
    snprintf(path, sizeof path, "%s/traction.csv", dir);
    FILE *f = fopen(path, "r");
    if (!f || !fgets(header, sizeof header, f)) {
        if (f)
            fclose(f);
        return -1;
    }
    int idx[8], col = 0, rows = 0;
    for (int k = 0; k < n; k++)
        idx[k] = -1;
    for (char *tok = strtok(header, ",\n"); tok; tok = strtok(NULL, ",\n"), col++)
        for (int k = 0; k < n; k++)
            if (strcmp(tok, cols[k]) == 0)
                idx[k] = col;
    while (fgets(line, sizeof line, f)) {
        rows++;
        col = 0;
        for (char *tok = strtok(line, ","); tok; tok = strtok(NULL, ","), col++)
            for (int k = 0; k < n; k++)
                if (col == idx[k])
                    vals[k] = strtod(tok, NULL);
    }
    fclose(f);
    for (int k = 0; k < n; k++)
        if (idx[k] < 0)
            return -1;
    return rows;
}

static int tire_small_on_scm(void)
{
    char out[180], log[200], cmd[1200];
    snprintf(out, sizeof out, "/tmp/scm-peer-%d-tire", (int)getpid());
    snprintf(log, sizeof log, "%s.log", out);
    snprintf(cmd, sizeof cmd,
             "DEMFEM_NO_BUILD=1 DEMFEM_BUILD_DIR=%s %s/run %s/tests/scm/scenes/tire_small_scm.cfg --terrain scm "
             "--out %s > %s 2>&1",
             DEMFEM_BUILD_DIR, DEMFEM_SOURCE_DIR, DEMFEM_SOURCE_DIR, out, log);
    int rc = system(cmd);
    run_files f;
    snprintf(f.log, sizeof f.log, "%s", log);
    const char *text = read_log(&f);
    if (rc != 0)
        fprintf(stderr, "---- %s ----\n%s----\n", log, text);
    ENSURE(rc == 0);
    double df = 1, dm = 1;
    const char *p = strstr(text, "conservation: nodal forces vs contact totals differ by at most ");
    ENSURE(p && sscanf(p, "conservation: nodal forces vs contact totals differ by at most %lf (force) and %lf", &df,
                       &dm) == 2);
    static const char *const cols[] = {"W_dem", "W_fem", "sinkage", "Fz"};
    double v[4] = {0, 0, 0, 0};
    ENSURE(last_row(out, cols, v, 4) > 1000);
    printf("  nodal forces against the totals: %.1e (force), %.1e (moment); interface work: terrain %.5g J, FEM "
           "%.5g J; sinkage %.2f mm, load %.1f N\n",
           df, dm, v[0], v[1], 1e3 * v[2], v[3]);
    ENSURE_MSG(df < 1e-12 && dm < 1e-12, "force %g, moment %g", df, dm);
    ENSURE(v[0] < 0);              /* the tire works on the soil */
    ENSURE_REL(v[1], v[0], 0.05);  /* both sides see the same work */
    ENSURE(v[2] > 0.001 && v[2] < 0.08);
    const char *shm = strstr(text, "(shared memory /");
    char name[128], path[160];
    ENSURE(shm && sscanf(shm, "(shared memory %127[^)])", name) == 1);
    snprintf(path, sizeof path, "/dev/shm%s", name);
    ENSURE(access(path, F_OK) != 0 && errno == ENOENT);
    return 0;
}

static const test_case tests[] = {
    {"tire_small_on_scm", tire_small_on_scm},
    {"plate_through_protocol", plate_through_protocol},
    {"fem_peer_killed", fem_peer_killed},
    {"scm_killed", scm_killed},
};

int main(int argc, char **argv) { return test_main(argc, argv, tests, TEST_COUNT(tests)); }
