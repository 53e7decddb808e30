/* fem_server's exchange guards (fem_exchange.c), issue 16 item 0: the
 * interface-work guard compares the two sides' work relative to the work
 * itself, with a floor from the interface's energy scale.
 *
 * work_guard_relative: the guard's rule on numbers (no processes).
 * tire_drift_stopped: tire_small with an exchange interval 15x too long
 *   (coupling.dt 1.5e-4 s, twice the grains' own limit; fem.dt 2e-5 s
 *   sub-cycled): the sides' work parts by 0.034 J at t = 0.095 s, never
 *   near the old absolute 1 J gap; it must stop, naming the cause and the
 *   key to change. (Since the FEM applies each interval's load from the
 *   interval's start, fem_solver_load_changed, 1.4e-4 s runs to its end
 *   9.4 % apart; before, the late force drifted it from 1.3e-4 s on.)
 * tire_moderate_interval_passes: the same at coupling.dt 5e-5 s, where the
 *   two sides agree within 0.13 %: the guard must not fire.
 * block_impact: a steel sphere (R 10 mm, 0.5 m/s) on the rubber block of
 *   tests/coupling/block meshed at 2 mm, the bottom clamped, three runs:
 *   - exchanged every 1 us: the guard's floor is the contacts' stored energy
 *     the DEM reports, so the first contact exchanges (works of 1e-30 J, the
 *     FEM's twice the DEM's on a node at rest) no longer stop the run; the
 *     impact is elastic (no damping, no friction): the grain leaves with
 *     1/2 m v^2 within 1 % (measured 1.000; before the floor: stopped at the
 *     first contact); and with the tread's compliance counted once
 *     (dem_surface.c, surface_contact_stiffening) the peak force and contact
 *     time are Hertz's for steel on a rubber half-space within 3 % (measured
 *     20.06 N, +1.8 %, and 3.013 ms, -1.2 %; with the compliance counted
 *     twice 14.40 N and 4.09 ms, -27 % and +34 %);
 *   - every 16 us (fem.dt 1 us sub-cycled): the top nodes (4.4e-6 kg, K_zz
 *     ~ 7.6e4 N/m) under the contact (dF/d delta ~ 2.7e5 N/m at the peak)
 *     allow H < 2 sqrt(m / (k_c + K_zz)) ~ 7e-6 s, so the guard must stop it;
 *   - every 16 us with fem.interface_mass_min = 4.7e-5 kg (H_crit ~ 2.3e-5 s;
 *     17 % of the block's mass added; 2.5e-5 kg still failed): it runs, and
 *     the peak force and contact time agree with the 1 us run's within 1 %
 *     (measured 19.98 against 20.06 N, 3.040 against 3.013 ms).
 * block_hertz_coarse: the same sphere on the block meshed at 3 mm (the
 *   contact radius 2.3 mm is less than an element): Hertz within 3 % too
 *   (measured 19.84 N, +0.7 %, 3.061 ms, +0.4 %; counted twice 14.52 N and
 *   3.99 ms). 1.5 mm (at coupling.dt 2.5e-7 s: the stiffer contact on the
 *   lighter nodes needs it) gives 19.91 N, +1.0 %, 3.043 ms, -0.2 %
 *   (bench/results/compliance-block.txt), not in the suite for its time.
 * peer_nan_force_named: fem_server against this test acting as the DEM side,
 *   which sends one frame with a NaN nodal force: fem_server must stop with
 *   the peer's bad data named (exchange, node, component), not report an
 *   unstable tire.
 * The runs go through the launcher and wait for it with system() or
 * tests/proc.h: no polling for short-lived states, no sleeps. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "fem_exchange.h"
#include "hertz.h"
#include "proc.h"
#include "test.h"

#if !defined(DEMFEM_SOURCE_DIR) || !defined(DEMFEM_BUILD_DIR)
#error "DEMFEM_SOURCE_DIR and DEMFEM_BUILD_DIR must be defined"
#endif

static int work_guard_relative(void)
{
    cm_error err = {0};
    /* Stable: a few per cent apart, whatever the size of the work. */
    ENSURE(fem_check_interface_work(-0.385645, -0.385638, 0.09, 0.2, 1e-5, &err) == CM_OK);
    ENSURE(fem_check_interface_work(-3.7e-6, -3.8e-6, 0.0, 0.05, 1e-5, &err) == CM_OK);
    ENSURE(fem_check_interface_work(120.0, 110.0, 0.0, 1.0, 1e-5, &err) == CM_OK);
    /* The small unstable case: 66 % apart, far below the old 1 J. */
    ENSURE(fem_check_interface_work(-0.458, -1.337, 0.17, 0.21, 1.2e-4, &err) == CM_ERR_NUMERIC);
    ENSURE_MSG(strstr(err.msg, "coupling unstable at t = 0.2100 s") && strstr(err.msg, "reduce coupling.dt") &&
                   strstr(err.msg, "= 0.00012 s"),
               "%s", err.msg);
    /* The same relative gap on tiny works, just above the tolerance. */
    ENSURE(fem_check_interface_work(1e-6, 1.5e-6, 0.0, 0.1, 1e-5, &err) == CM_ERR_NUMERIC);
    /* Work passing through zero: the floor (the energy scale) holds it... */
    ENSURE(fem_check_interface_work(1e-4, -1e-4, 0.08, 0.1, 1e-5, &err) == CM_OK);
    /* ...but not a gap that is large against the floor too. */
    ENSURE(fem_check_interface_work(0.03, -0.03, 0.08, 0.1, 1e-5, &err) == CM_ERR_NUMERIC);
    /* NaN never passes. */
    ENSURE(fem_check_interface_work(NAN, 0.1, 0.08, 0.1, 1e-5, &err) == CM_ERR_NUMERIC);
    /* The measure the guard and its warning use: the gap over the larger
     * work or the floor. */
    ENSURE(fabs(fem_interface_work_gap(-0.458, -1.337, 0.17) - 0.879 / 1.337) < 1e-12);
    ENSURE(fabs(fem_interface_work_gap(1e-4, -1e-4, 0.08) - 2e-4 / 0.08) < 1e-12);
    ENSURE(fem_interface_work_gap(0.0, 0.0, 0.0) == 0.0);
    ENSURE(isinf(fem_interface_work_gap(NAN, 0.1, 0.08)) && isinf(fem_interface_work_gap(1e-3, 0.0, 0.0)) == 0);
    ENSURE(fem_interface_work_gap(1e-3, 0.0, 0.0) == 1.0);
    /* the warning sits between a stable exchange (< 1 %) and the guard */
    ENSURE(FEM_WORK_WARN > 0.01 && FEM_WORK_WARN < FEM_WORK_TOLERANCE);
    return 0;
}

/* Runs tire_small through the launcher with extra --set arguments; returns
 * the launcher's exit status (-1: could not run) and leaves the log in log. */
static int run_tire_small(const char *tag, const char *sets, char *log, size_t len)
{
    char out[256], cmd[2048];
    snprintf(out, sizeof out, "/tmp/demfem-femguards-%d-%s", (int)getpid(), tag);
    snprintf(log, len, "%s.log", out);
    snprintf(cmd, sizeof cmd,
             "DEMFEM_NO_BUILD=1 DEMFEM_BUILD_DIR='%s' '%s/run' '%s/tests/coupling/scenes/tire_small.cfg' --out '%s' "
             "%s > '%s' 2>&1",
             DEMFEM_BUILD_DIR, DEMFEM_SOURCE_DIR, DEMFEM_SOURCE_DIR, out, sets, log);
    int st = system(cmd);
    char rm[400];
    snprintf(rm, sizeof rm, "rm -rf '%s'", out);
    if (system(rm) != 0)
        fprintf(stderr, "could not remove %s\n", out);
    return st == -1 || !WIFEXITED(st) ? -1 : WEXITSTATUS(st);
}

static char *slurp(const char *path)
{
    FILE *f = fopen(path, "r");
    if (!f)
        return NULL;
    static char buf[1 << 17];
    size_t n = fread(buf, 1, sizeof buf - 1, f);
    fclose(f);
    buf[n] = '\0';
    return buf;
}

static int tire_drift_stopped(void)
{
    char log[300];
    int status = run_tire_small("drift", "--set coupling.dt=1.5e-4 --set dem.allow_unstable_dt=true --set fem.dt=2e-5",
                                log, sizeof log);
    const char *text = slurp(log);
    ENSURE(text != NULL);
    if (status == 0 || !strstr(text, "coupling unstable"))
        fprintf(stderr, "---- %s ----\n%s----\n", log, text);
    ENSURE(status != 0 && status != -1);
    ENSURE(strstr(text, "[fem] error: coupling unstable at t = "));
    ENSURE(strstr(text, "interface work seen by the FEM") && strstr(text, "reduce coupling.dt"));
    ENSURE(strstr(text, "[dem] error: peer fem failed"));
    ENSURE(!strstr(text, "traction over the steady part")); /* stopped, not finished */
    unlink(log);
    return 0;
}

static int tire_moderate_interval_passes(void)
{
    char log[300];
    int status = run_tire_small("moderate", "--set coupling.dt=5e-5 --set dem.allow_unstable_dt=true --set fem.dt=2e-5",
                                log, sizeof log);
    const char *text = slurp(log);
    ENSURE(text != NULL);
    if (status != 0)
        fprintf(stderr, "---- %s ----\n%s----\n", log, text);
    ENSURE(status == 0);
    ENSURE(!strstr(text, "coupling unstable"));
    ENSURE(strstr(text, "traction over the steady part"));
    unlink(log);
    return 0;
}

/* The last row's value of column `name` in a CSV file with a header. */
static int csv_last(const char *path, const char *name, double *out)
{
    FILE *f = fopen(path, "r");
    if (!f)
        return -1;
    char head[1024], line[1024], last[1024] = "";
    if (!fgets(head, sizeof head, f)) {
        fclose(f);
        return -1;
    }
    while (fgets(line, sizeof line, f))
        memcpy(last, line, sizeof line);
    fclose(f);
    int col = -1, k = 0;
    for (char *save = NULL, *t = strtok_r(head, ",\n", &save); t; t = strtok_r(NULL, ",\n", &save), k++)
        if (strcmp(t, name) == 0)
            col = k;
    if (col < 0 || !last[0])
        return -1;
    k = 0;
    for (char *save = NULL, *t = strtok_r(last, ",\n", &save); t; t = strtok_r(NULL, ",\n", &save), k++)
        if (k == col) {
            *out = strtod(t, NULL);
            return 0;
        }
    return -1;
}

/* Peak contact force (N) and contact time (s) from a run's traction.csv:
 * the time with |Fz| above 1e-3 of its peak. */
static int csv_peak(const char *path, double *peak, double *t_contact)
{
    FILE *f = fopen(path, "r");
    if (!f)
        return -1;
    char line[4096];
    int col_t = -1, col_f = -1, k = 0;
    if (!fgets(line, sizeof line, f)) {
        fclose(f);
        return -1;
    }
    for (char *save = NULL, *t = strtok_r(line, ",\n", &save); t; t = strtok_r(NULL, ",\n", &save), k++)
        col_t = strcmp(t, "t") == 0 ? k : col_t, col_f = strcmp(t, "Fz") == 0 ? k : col_f;
    static double tv[200000], fv[200000];
    size_t n = 0;
    while (n < 200000 && fgets(line, sizeof line, f)) {
        k = 0;
        for (char *save = NULL, *t = strtok_r(line, ",\n", &save); t; t = strtok_r(NULL, ",\n", &save), k++) {
            if (k == col_t)
                tv[n] = strtod(t, NULL);
            if (k == col_f)
                fv[n] = fabs(strtod(t, NULL));
        }
        n++;
    }
    fclose(f);
    if (col_t < 0 || col_f < 0 || n < 2)
        return -1;
    *peak = 0.0;
    for (size_t i = 0; i < n; i++)
        *peak = fmax(*peak, fv[i]);
    size_t on = 0;
    for (size_t i = 0; i < n; i++)
        on += fv[i] > 1e-3 * *peak;
    *t_contact = (double)on * (tv[1] - tv[0]);
    return 0;
}

/* Runs the sphere on the block meshed at h (m) in dir with extra --set
 * arguments; returns the launcher's exit status (-1: could not run). */
static int run_block_h(const char *dir, double h, const char *sets, char *log, size_t len)
{
    char cmd[2048];
    snprintf(log, len, "%s/run.log", dir);
    snprintf(cmd, sizeof cmd,
             "mkdir -p '%s' && cp '%s/tests/coupling/block/sphere_block.cfg' '%s/' && "
             "/usr/bin/python3 '%s/tests/coupling/block/block_mesh.py' '%s/block.msh' %g > /dev/null",
             dir, DEMFEM_SOURCE_DIR, dir, DEMFEM_SOURCE_DIR, dir, h);
    if (system(cmd) != 0)
        return -1;
    snprintf(cmd, sizeof cmd,
             "DEMFEM_NO_BUILD=1 DEMFEM_BUILD_DIR='%s' '%s/run' '%s/sphere_block.cfg' --out '%s/run' %s > '%s' 2>&1",
             DEMFEM_BUILD_DIR, DEMFEM_SOURCE_DIR, dir, dir, sets, log);
    int st = system(cmd);
    return st == -1 || !WIFEXITED(st) ? -1 : WEXITSTATUS(st);
}

static int run_block(const char *dir, const char *sets, char *log, size_t len)
{
    return run_block_h(dir, 0.002, sets, log, len);
}

/* Hertz for the block's steel sphere on a rubber half-space (sphere_block.cfg). */
static hertz_ref block_hertz(void)
{
    return hertz_closed_form(hertz_e_star(2.1e11, 0.3, 1.0e7, 0.45), 0.01, sphere_mass(7800.0, 0.01), 0.5);
}

static int block_impact(void)
{
    char base[200], dir[260], log[300], csv[320];
    snprintf(base, sizeof base, "/tmp/demfem-femguards-%d-interval", (int)getpid());
    double peak[2], tc[2];
    static const char *const sets[2] = {"", "--set coupling.exchange_every=16 --set fem.interface_mass_min=4.7e-5"};
    for (int r = 0; r < 2; r++) {
        snprintf(dir, sizeof dir, "%s/%d", base, r);
        int st = run_block(dir, sets[r], log, sizeof log);
        const char *text = slurp(log);
        ENSURE(text != NULL);
        if (st != 0)
            fprintf(stderr, "---- %s ----\n%s----\n", log, text);
        ENSURE(st == 0);
        ENSURE(!strstr(text, "coupling unstable"));
        ENSURE(r == 0 || strstr(text, "interface nodes raised to 4.7e-05 kg"));
        snprintf(csv, sizeof csv, "%s/run/traction.csv", dir);
        ENSURE(csv_peak(csv, &peak[r], &tc[r]) == 0);
        double ke = -1.0;
        snprintf(csv, sizeof csv, "%s/run/dem_series.csv", dir);
        ENSURE(csv_last(csv, "ke_trans_J", &ke) == 0);
        const double mass = 7800.0 * 4.0 / 3.0 * M_PI * 1e-6, e_in = 0.5 * mass * 0.5 * 0.5;
        printf("  run %d: rebound energy %.6g J = %.4f of the input %.6g J\n", r, ke, ke / e_in, e_in);
        ENSURE(fabs(ke / e_in - 1.0) < 0.01);
        if (r == 0) { /* the tread's compliance once: Hertz */
            const hertz_ref hz = block_hertz();
            printf("  run 0: peak %.3f N against Hertz %.3f N (%+.2f %%), contact %.4f ms against %.4f ms (%+.2f %%)\n",
                   peak[0], hz.fmax, 100 * (peak[0] / hz.fmax - 1), 1e3 * tc[0], 1e3 * hz.tc, 100 * (tc[0] / hz.tc - 1));
            ENSURE(fabs(peak[0] / hz.fmax - 1.0) < 0.03 && fabs(tc[0] / hz.tc - 1.0) < 0.03);
        }
    }
    snprintf(dir, sizeof dir, "%s/2", base);
    int st = run_block(dir, "--set coupling.exchange_every=16", log, sizeof log);
    const char *text = slurp(log);
    ENSURE(text != NULL);
    printf("  exchange every 1 us: peak %.3f N, contact %.4f ms; every 16 us with light nodes raised to 4.7e-5 kg: "
           "%.3f N, %.4f ms; every 16 us unscaled: exit %d\n", peak[0], 1e3 * tc[0], peak[1], 1e3 * tc[1], st);
    ENSURE(fabs(peak[1] / peak[0] - 1.0) < 0.01 && fabs(tc[1] / tc[0] - 1.0) < 0.01);
    ENSURE(st != 0 && st != -1 && strstr(text, "coupling unstable"));
    char cmd[300];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", base);
    ENSURE(system(cmd) == 0);
    return 0;
}

static int block_hertz_coarse(void)
{
    char dir[200], log[300], csv[320];
    snprintf(dir, sizeof dir, "/tmp/demfem-femguards-%d-coarse", (int)getpid());
    int st = run_block_h(dir, 0.003, "", log, sizeof log);
    const char *text = slurp(log);
    ENSURE(text != NULL);
    if (st != 0)
        fprintf(stderr, "---- %s ----\n%s----\n", log, text);
    ENSURE(st == 0);
    double peak, tc, ke = -1.0;
    snprintf(csv, sizeof csv, "%s/run/traction.csv", dir);
    ENSURE(csv_peak(csv, &peak, &tc) == 0);
    snprintf(csv, sizeof csv, "%s/run/dem_series.csv", dir);
    ENSURE(csv_last(csv, "ke_trans_J", &ke) == 0);
    const hertz_ref hz = block_hertz();
    const double e_in = 0.5 * sphere_mass(7800.0, 0.01) * 0.5 * 0.5;
    printf("  3 mm block: peak %.3f N against Hertz %.3f N (%+.2f %%), contact %.4f ms against %.4f ms (%+.2f %%), "
           "rebound energy %.4f of the input\n", peak, hz.fmax, 100 * (peak / hz.fmax - 1), 1e3 * tc, 1e3 * hz.tc,
           100 * (tc / hz.tc - 1), ke / e_in);
    ENSURE(fabs(peak / hz.fmax - 1.0) < 0.03 && fabs(tc / hz.tc - 1.0) < 0.03);
    ENSURE(fabs(ke / e_in - 1.0) < 0.01);
    char cmd[300];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
    ENSURE(system(cmd) == 0);
    return 0;
}

static int peer_nan_force_named(void)
{
    char name[64], out[256], log[300];
    snprintf(name, sizeof name, "/demfem-femguards-%d-nan", (int)getpid());
    snprintf(out, sizeof out, "/tmp/demfem-femguards-%d-nan", (int)getpid());
    snprintf(log, sizeof log, "%s.log", out);
    mkdir(out, 0755);
    const char *argv[] = {DEMFEM_BUILD_DIR "/fem_server/fem_server", "--scene",
                          DEMFEM_SOURCE_DIR "/tests/coupling/scenes/tire_small.cfg", "--shm", name, "--out", out, NULL};
    tp_proc fem;
    ENSURE(tp_spawn(&fem, argv, log, 0) == 0);
    /* The DEM side: attach (the library waits for the segment), one frame. */
    ipc_attach_def def = ipc_default_attach_def();
    def.dt = 1e-5;
    def.exchange_every = 1;
    def.connect_timeout = 120;
    ipc_channel *ch = NULL;
    char err[512];
    int rc = ipc_attach(name, &def, &ch, err, sizeof err);
    if (rc != IPC_OK)
        fprintf(stderr, "attach: %s\n", err);
    ENSURE(rc == IPC_OK);
    ipc_frame_head *fr;
    double *p;
    ENSURE(ipc_send_begin(ch, &fr, &p) == IPC_OK);
    uint32_t nn = ipc_surface_node_count(ch);
    ENSURE(nn > 7);
    memset(p, 0, ipc_send_len(ch) * sizeof *p);
    fr->kind = IPC_FRAME_DATA;
    fr->time = 0.0;
    p[3 * 7 + 2] = NAN; /* node 7, z */
    ENSURE(ipc_send_commit(ch) == IPC_OK);
    const ipc_frame_head *in;
    const double *f;
    ENSURE(ipc_recv(ch, &in, &f) != IPC_OK); /* fem_server failed the channel */
    ipc_close(&ch, IPC_OK);
    const int status = tp_finish(&fem, 600);
    const char *text = slurp(log);
    ENSURE(text != NULL);
    if (status != 1 || !strstr(text, "sent bad data"))
        fprintf(stderr, "---- %s ----\n%s----\n", log, text);
    ENSURE(status == 1);
    ENSURE(strstr(text, "error: dem_server sent bad data at exchange 0 (t = 0.000000 s): the force on interface "
                        "node 7 (z) is nan"));
    ENSURE(!strstr(text, "unstable"));
    char rm[700];
    snprintf(rm, sizeof rm, "rm -rf '%s' '%s'", out, log);
    ENSURE(system(rm) == 0);
    return 0;
}

static const test_case tests[] = {
    {"work_guard_relative", work_guard_relative},
    {"tire_drift_stopped", tire_drift_stopped},
    {"tire_moderate_interval_passes", tire_moderate_interval_passes},
    {"block_impact", block_impact},
    {"block_hertz_coarse", block_hertz_coarse},
    {"peer_nan_force_named", peer_nan_force_named},
};

int main(int argc, char **argv) { return test_main(argc, argv, tests, TEST_COUNT(tests)); }
