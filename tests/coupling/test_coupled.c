/* Coupled runs through the launcher: real processes, a real segment.
 *
 * plate_*: dem_server against plate_peer (a stand-in FEM side swapped in with
 * `run --fem`), a grain hitting the exchanged surface: Hertz closed form.
 * tire_*: dem_server against fem_server on a small tire and bed. */
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <hdf5.h>

#include "proc.h"
#include "hertz.h"
#include "test.h"

#if !defined(DEMFEM_SOURCE_DIR) || !defined(DEMFEM_BUILD_DIR) || !defined(PLATE_PEER_PATH)
#error "DEMFEM_SOURCE_DIR, DEMFEM_BUILD_DIR and PLATE_PEER_PATH must be defined"
#endif

#define SCENES DEMFEM_SOURCE_DIR "/tests/coupling/scenes/"

typedef struct launch {
    tp_proc p; /* the launcher, leading its own process group with both servers */
    char out[256];
    int status;  /* the launcher's exit code */
    double wall; /* s, start to exit */
} launch;

/* Starts ./run SCENE --out DIR [extra...] with the build under test. */
static int start(launch *l, const char *scene, const char *tag, const char *const *extra)
{
    snprintf(l->out, sizeof l->out, "/tmp/demfem-coupled-%d-%s", (int)getpid(), tag);
    char log[300];
    snprintf(log, sizeof log, "%s.log", l->out);
    /* an empty folder: pids are recycled, and what an earlier run with this
     * name left (a plate_peer.running, a traction.csv) must not be read as
     * this run's */
    char rm[400];
    snprintf(rm, sizeof rm, "rm -rf '%s'", l->out);
    if (system(rm) != 0 || mkdir(l->out, 0755) != 0)
        return errno ? errno : -1;
    const char *argv[32] = {DEMFEM_SOURCE_DIR "/run", scene, "--out", l->out};
    int n = 4;
    for (int i = 0; extra && extra[i] && n < 31; i++)
        argv[n++] = extra[i];
    argv[n] = NULL;
    setenv("DEMFEM_NO_BUILD", "1", 1);
    setenv("DEMFEM_BUILD_DIR", DEMFEM_BUILD_DIR, 1);
    /* Its own process group, so that a test can signal the launcher alone
     * and a timeout kills the servers with it. */
    return tp_spawn(&l->p, argv, log, TP_NEW_GROUP);
}

static int finish(launch *l, double timeout_s)
{
    if (tp_wait(&l->p, timeout_s) != 0) {
        tp_kill(&l->p);
        return -1;
    }
    l->status = l->p.status;
    l->wall = l->p.t_exit - l->p.t_start;
    return 0;
}

static const char *log_text(const launch *l) { return tp_log_text(&l->p); }

static void dump_log(const launch *l) { tp_print_log(&l->p); }

/* The segment the launcher chose (its log names it) is gone from /dev/shm. */
static int shm_clean(const launch *l)
{
    const char *p = strstr(log_text(l), "(shared memory /");
    char name[128], path[160];
    if (!p || sscanf(p, "(shared memory %127[^)])", name) != 1)
        return 0;
    snprintf(path, sizeof path, "/dev/shm%s", name);
    return access(path, F_OK) != 0 && errno == ENOENT;
}

/* Hertz, sphere on a rigid plane: maximum overlap, contact time, peak force. */
typedef struct hertz {
    double m, estar, dmax, tc, fmax;
} hertz;

static hertz hertz_sphere_plane(double r, double rho, double E1, double nu1, double E2, double nu2, double v)
{
    hertz h;
    h.m = sphere_mass(rho, r);
    h.estar = hertz_e_star(E1, nu1, E2, nu2);
    const hertz_ref c = hertz_closed_form(h.estar, r, h.m, v);
    h.dmax = c.dmax, h.tc = c.tc, h.fmax = c.fmax;
    return h;
}

static int plate_run(const char *scene, const char *tag, double *impulse, double *duration, double *peak)
{
    launch l;
    const char *extra[] = {"--fem", PLATE_PEER_PATH, NULL};
    ENSURE(start(&l, scene, tag, extra) == 0);
    ENSURE(finish(&l, 60) == 0);
    if (l.status != 0)
        dump_log(&l);
    ENSURE(l.status == 0);
    const char *p = strstr(log_text(&l), "[plate] impulse ");
    ENSURE(p && sscanf(p, "[plate] impulse %lf N s, contact duration %lf s, peak force %lf N", impulse, duration,
                       peak) == 3);
    ENSURE(shm_clean(&l));
    return 0;
}

/* Elastic impact (e = 1) of a grain on the edge shared by two triangles of
 * the exchanged plate: contact time and peak force as Hertz, impulse 2 m v. */
static int plate_impact_elastic(void)
{
    double J, tc, F;
    if (plate_run(SCENES "impact_plate.cfg", "elastic", &J, &tc, &F))
        return 1;
    hertz h = hertz_sphere_plane(0.005, 2600, 5e7, 0.3, 2e8, 0.25, 1.0);
    printf("  contact %.4g s (Hertz %.4g), peak %.4g N (Hertz %.4g), impulse %.5g N s (2 m v = %.5g)\n", tc, h.tc,
           F, h.fmax, J, 2 * h.m);
    ENSURE_REL(tc, h.tc, 0.01);  /* exchanges every 1e-6 s: 0.2 % resolution */
    ENSURE_REL(F, h.fmax, 0.01);
    ENSURE_REL(J, 2.0 * h.m * 1.0, 0.005);
    return 0;
}

/* Damped impact: the grain leaves with e v, so the plate takes (1 + e) m v. */
static int plate_impact_damped(void)
{
    double J, tc, F;
    if (plate_run(SCENES "impact_plate_damped.cfg", "damped", &J, &tc, &F))
        return 1;
    hertz h = hertz_sphere_plane(0.005, 2600, 5e7, 0.3, 2e8, 0.25, 1.0);
    printf("  impulse %.5g N s ((1 + e) m v = %.5g)\n", J, 1.5 * h.m);
    ENSURE_REL(J, 1.5 * h.m, 0.02);
    ENSURE(F < h.fmax); /* the dashpot lowers the peak */
    return 0;
}

/* The swapped-in FEM side dies mid-run: the launcher returns non-zero within
 * a few seconds and nothing is left in /dev/shm. */
static int plate_peer_killed(void)
{
    /* A long run of the same scene: the grain flies on after the impact. */
    char scene[300];
    snprintf(scene, sizeof scene, "/tmp/demfem-coupled-%d-long.cfg", (int)getpid());
    char cmd[800];
    snprintf(cmd, sizeof cmd, "sed 's/end_time = 0.0015;/end_time = 100.0;/' %simpact_plate.cfg > %s", SCENES,
             scene);
    ENSURE(system(cmd) == 0);
    launch l;
    const char *extra[] = {"--fem", PLATE_PEER_PATH, NULL};
    ENSURE(start(&l, scene, "killed", extra) == 0);
    /* Once the FEM side has done its first exchange it leaves its pid in
     * the output folder (plate_peer.c): kill that process, not one found by
     * name (with ctest -j another test's peer could match). */
    char running[400];
    snprintf(running, sizeof running, "%s/plate_peer.running", l.out);
    if (tp_wait_file(running, 60, &l.p) != 0) {
        finish(&l, 0);
        dump_log(&l);
        ENSURE_MSG(0, "the FEM side never reported its first exchange (%s)", running);
    }
    FILE *f = fopen(running, "r");
    int victim = 0, read_ok = f && fscanf(f, "%d", &victim) == 1 && victim > 1;
    if (f)
        fclose(f);
    if (!read_ok || kill((pid_t)victim, SIGKILL) != 0) {
        finish(&l, 0); /* never leave the 100 s run behind */
        ENSURE_MSG(0, "could not kill the FEM side named in %s (pid %d)", running, victim);
    }
    double t_kill = tp_now();
    ENSURE(finish(&l, 20) == 0);
    double reaction = tp_now() - t_kill;
    unlink(scene);
    if (l.status == 0)
        dump_log(&l);
    ENSURE(l.status != 0);
    ENSURE_MSG(reaction < 3.0, "launcher took %.2f s to end after the FEM side died", reaction);
    ENSURE_MSG(strstr(log_text(&l), "FEM side (plate_peer) failed"), "the launcher should name the dead peer");
    ENSURE(shm_clean(&l));
    return 0;
}

/* Numbers from the last row of a traction.csv. */
static int last_row(const char *dir, const char *const *cols, double *vals, int n, int *phase_seen)
{
    char path[400], line[4096], header[4096];
    snprintf(path, sizeof path, "%s/traction.csv", dir);
    FILE *f = fopen(path, "r");
    if (!f || !fgets(header, sizeof header, f))
        return -1;
    int idx[16], phase_col = -1, col = 0;
    for (int k = 0; k < n; k++)
        idx[k] = -1;
    for (char *tok = strtok(header, ",\n"); tok; tok = strtok(NULL, ",\n"), col++) {
        for (int k = 0; k < n; k++)
            if (strcmp(tok, cols[k]) == 0)
                idx[k] = col;
        if (strcmp(tok, "phase") == 0)
            phase_col = col;
    }
    int rows = 0;
    while (fgets(line, sizeof line, f)) {
        rows++;
        col = 0;
        for (char *tok = strtok(line, ","); tok; tok = strtok(NULL, ","), col++) {
            for (int k = 0; k < n; k++)
                if (col == idx[k])
                    vals[k] = strtod(tok, NULL);
            if (col == phase_col && phase_seen)
                phase_seen[(int)strtod(tok, NULL) & 3] = 1;
        }
    }
    fclose(f);
    for (int k = 0; k < n; k++)
        if (idx[k] < 0)
            return -1;
    return rows;
}

/* A double attribute of wheel.h5's root (the profile). */
static int wheel_attr(const char *dir, const char *name, double *v)
{
    char path[400];
    snprintf(path, sizeof path, "%s/wheel.h5", dir);
    hid_t f = H5Fopen(path, H5F_ACC_RDONLY, H5P_DEFAULT);
    if (f < 0)
        return -1;
    int bad = 1;
    if (H5Aexists(f, name) > 0) {
        hid_t a = H5Aopen(f, name, H5P_DEFAULT);
        bad = a < 0 || H5Aread(a, H5T_NATIVE_DOUBLE, v) < 0;
        if (a >= 0)
            H5Aclose(a);
    }
    H5Fclose(f);
    return bad ? -1 : 0;
}

/* The whole pipeline on a small tire and bed: sinkage to the load, travel,
 * summary. The nodal forces the FEM receives balance the DEM's contact totals
 * to round-off, and both sides agree on the interface work. */
static int tire_small_runs(void)
{
    launch l;
    ENSURE(start(&l, SCENES "tire_small.cfg", "tire", NULL) == 0);
    ENSURE(finish(&l, 300) == 0);
    if (l.status != 0)
        dump_log(&l);
    ENSURE(l.status == 0);
    const char *log = log_text(&l);
    double df = 1, dm = 1;
    const char *p = strstr(log, "conservation: nodal forces vs contact totals differ by at most ");
    ENSURE(p && sscanf(p, "conservation: nodal forces vs contact totals differ by at most %lf (force) and %lf", &df,
                       &dm) == 2);
    ENSURE_MSG(df < 1e-12 && dm < 1e-12, "force %g, moment %g", df, dm);
    ENSURE(strstr(log, "T_P  mean") && strstr(log, "sinkage mean"));
    const char *cols[] = {"W_dem", "W_fem", "sinkage", "Fz"};
    double v[4];
    int phases[4] = {0};
    int rows = last_row(l.out, cols, v, 4, phases);
    ENSURE(rows > 1000);
    ENSURE(phases[0] && phases[1]); /* sinkage and travel */
    printf("  %d exchanges in %.1f s; interface work DEM %.4g J, FEM %.4g J; sinkage %.1f mm\n", rows, l.wall, v[0],
           v[1], 1e3 * v[2]);
    ENSURE(v[0] < 0);                      /* the tire works on the soil */
    ENSURE_REL(v[1], v[0], 0.05);          /* both sides see the same work */
    ENSURE(v[2] > 0.001 && v[2] < 0.08);   /* it did sink, not through the bed */
    /* The summary reports the coupling's own error, as traction.csv has it. */
    double wd, wf, gap;
    p = strstr(log, "interface work of the grains on the tire: seen by the DEM ");
    ENSURE(p && sscanf(p, "interface work of the grains on the tire: seen by the DEM %lf J, by the FEM %lf J; "
                          "FEM - DEM = %lf J", &wd, &wf, &gap) == 3);
    ENSURE_REL(wd, v[0], 1e-5);
    ENSURE_REL(wf, v[1], 1e-5);
    ENSURE_NEAR(gap, v[1] - v[0], 0.01 * fabs(v[1] - v[0]) + 1e-12);
    /* The run records (what scripts read instead of the logs): both sides
     * ended well, after the same exchanges, one per traction.csv row. */
    double dem_ex = 0, fem_ex = 0, dem_rc = 1, fem_rc = 1, tets = 0, lim = 0;
    ENSURE(tp_record_num(l.out, "dem_run.json", "exchanges", &dem_ex) == 0 &&
           tp_record_num(l.out, "fem_run.json", "exchanges", &fem_ex) == 0);
    ENSURE(tp_record_num(l.out, "dem_run.json", "exit_code", &dem_rc) == 0 && dem_rc == 0);
    ENSURE(tp_record_num(l.out, "fem_run.json", "exit_code", &fem_rc) == 0 && fem_rc == 0);
    ENSURE(tp_record_num(l.out, "fem_run.json", "tets", &tets) == 0 && tets > 100);
    ENSURE(tp_record_num(l.out, "fem_run.json", "dt_limit", &lim) == 0 && lim > 0);
    ENSURE_MSG(dem_ex == fem_ex && dem_ex == rows, "exchanges: DEM %g, FEM %g, traction.csv %d rows", dem_ex, fem_ex,
               rows);
    ENSURE(tp_record_has(l.out, "fem_run.json", "\"error\": \"\""));
    /* The FEM's cost, from its profile in wheel.h5: every stage has its CPU
     * time beside its wall time; the advance's is not zero and, fem_server
     * being one thread, no more than its wall time. */
    double adv = -1, adv_cpu = -1, rcv_cpu = -1;
    ENSURE(wheel_attr(l.out, "profile_advance_s", &adv) == 0 &&
           wheel_attr(l.out, "profile_advance_cpu_s", &adv_cpu) == 0 &&
           wheel_attr(l.out, "profile_receive_cpu_s", &rcv_cpu) == 0);
    ENSURE_MSG(adv_cpu > 0 && rcv_cpu >= 0, "advance CPU %g s, receive CPU %g s", adv_cpu, rcv_cpu);
    ENSURE_MSG(adv_cpu <= adv * 1.01 + 0.01, "advance: CPU %g s above its wall time %g s", adv_cpu, adv);
    ENSURE(shm_clean(&l));
    return 0;
}

/* The same with an exchange interval far too long: the run-time guard stops
 * it with the cause and the setting to change, and both sides exit non-zero. */
static int tire_unstable_exchange_stopped(void)
{
    launch l;
    ENSURE(start(&l, SCENES "tire_small_unstable.cfg", "unstable", NULL) == 0);
    ENSURE(finish(&l, 300) == 0);
    const char *log = log_text(&l);
    if (l.status == 0 || !strstr(log, "coupling unstable"))
        dump_log(&l);
    ENSURE(l.status != 0);
    ENSURE(strstr(log, "[fem] error: coupling unstable") && strstr(log, "reduce coupling.dt"));
    ENSURE(strstr(log, "[dem] error: peer fem failed"));
    /* The run records say the same (bench/study/run reads these). */
    ENSURE(tp_record_has(l.out, "fem_run.json", "\"error\": \"coupling unstable"));
    ENSURE(tp_record_has(l.out, "dem_run.json", "\"error\": \"peer fem failed"));
    ENSURE(shm_clean(&l));
    return 0;
}

/* A user's own mesh: the small tire written out as Gmsh .msh by fem_server
 * --export-mesh and read back through mesh type "gmsh" runs the same
 * coupled scene to the same sinkage. */
static int tire_from_gmsh_runs(void)
{
    char msh[200], scene[200], cmd[1200];
    snprintf(msh, sizeof msh, "/tmp/demfem-coupled-%d-tire.msh", (int)getpid());
    snprintf(scene, sizeof scene, "/tmp/demfem-coupled-%d-gmsh.cfg", (int)getpid());
    snprintf(cmd, sizeof cmd, "%s/fem_server/fem_server --scene %stire_small.cfg --export-mesh %s > /dev/null",
             DEMFEM_BUILD_DIR, SCENES, msh);
    ENSURE(system(cmd) == 0);
    snprintf(cmd, sizeof cmd,
             "sed 's|  mesh = { type = \"tire\"; resolution = 0.25; };|  mesh = { type = \"gmsh\"; file = \"%s\"; };|' "
             "%stire_small.cfg > %s && grep -q gmsh %s",
             msh, SCENES, scene, scene);
    ENSURE(system(cmd) == 0);
    launch l;
    ENSURE(start(&l, scene, "gmsh", NULL) == 0);
    ENSURE(finish(&l, 300) == 0);
    unlink(scene);
    unlink(msh);
    if (l.status != 0)
        dump_log(&l);
    ENSURE(l.status == 0);
    ENSURE(strstr(log_text(&l), "interface: 416 nodes, 768 triangles")); /* the same contact surface */
    const char *cols[] = {"sinkage", "W_dem", "W_fem"};
    double v[3];
    ENSURE(last_row(l.out, cols, v, 3, NULL) > 1000);
    printf("  sinkage %.2f mm, interface work DEM %.4g J, FEM %.4g J\n", 1e3 * v[0], v[1], v[2]);
    /* tire_small sinks 3.3, 6.6, 11.6 and 6.8 mm on the beds of seeds 1-4 (the
     * depth where the load first reaches 60 N jumps with single grains): a
     * sane sinkage, not one bed's */
    ENSURE(v[0] > 0.002 && v[0] < 0.02);
    ENSURE_REL(v[2], v[1], 0.05);
    ENSURE(shm_clean(&l));
    return 0;
}

/* Exchanging every 2 DEM steps of half the size (same interval): the DEM
 * averages its forces over the interval and moves the surface with its node
 * velocities in between; the run agrees with exchanging every step. */
static int tire_exchange_every_two(void)
{
    char scene[200], cmd[800];
    snprintf(scene, sizeof scene, "/tmp/demfem-coupled-%d-every2.cfg", (int)getpid());
    snprintf(cmd, sizeof cmd,
             "sed 's/coupling = { dt = 1.0e-5; exchange_every = 1;/coupling = { dt = 5.0e-6; exchange_every = 2;/' "
             "%stire_small.cfg > %s && grep -q 'exchange_every = 2' %s",
             SCENES, scene, scene);
    ENSURE(system(cmd) == 0);
    launch l;
    ENSURE(start(&l, scene, "every2", NULL) == 0);
    ENSURE(finish(&l, 300) == 0);
    unlink(scene);
    if (l.status != 0)
        dump_log(&l);
    ENSURE(l.status == 0);
    ENSURE(strstr(log_text(&l), "exchange every 2 steps"));
    const char *cols[] = {"sinkage", "W_dem", "W_fem"};
    double v[3];
    ENSURE(last_row(l.out, cols, v, 3, NULL) > 1000);
    printf("  sinkage %.2f mm, interface work DEM %.4g J, FEM %.4g J\n", 1e3 * v[0], v[1], v[2]);
    /* tire_small sinks 3.3, 6.6, 11.6 and 6.8 mm on the beds of seeds 1-4 (the
     * depth where the load first reaches 60 N jumps with single grains): a
     * sane sinkage, not one bed's */
    ENSURE(v[0] > 0.002 && v[0] < 0.02);
    ENSURE_REL(v[2], v[1], 0.05);
    ENSURE(shm_clean(&l));
    return 0;
}

/* Runs a scene with --set overrides that must be stopped by a guard: the
 * launcher fails, the log has `want` (and `setting`, the key to change) in
 * the error line of `side`, and nothing is left in /dev/shm. */
static int stopped_by_guard(const char *scene, const char *tag, const char *const *extra, const char *side,
                            const char *want, const char *setting)
{
    launch l;
    ENSURE(start(&l, scene, tag, extra) == 0);
    ENSURE(finish(&l, 120) == 0);
    const char *log = log_text(&l);
    char line[64];
    snprintf(line, sizeof line, "[%s] error: ", side);
    const char *e = strstr(log, line);
    if (l.status == 0 || !e || !strstr(e, want) || !strstr(e, setting))
        dump_log(&l);
    ENSURE(l.status != 0);
    ENSURE(e && strstr(e, want) && strstr(e, setting));
    printf("  stopped after %.1f s: %.160s\n", l.wall, e);
    ENSURE(shm_clean(&l));
    return 0;
}

/* A grain 20 times faster than the plate scene's: its Hertz overlap would
 * reach ~40 % of the radius; the DEM side stops at a grain–surface limit of 20 %. */
static int guard_grain_overlap(void)
{
    const char *extra[] = {"--fem", PLATE_PEER_PATH, "--set", "dem.grains.[0].velocity=[0.0, 0.0, -20.0]",
                           "--set", "coupling.max_surface_overlap=0.2", NULL};
    return stopped_by_guard(SCENES "impact_plate.cfg", "overlap", extra, "dem", "pressed into the tire",
                            "coupling.max_surface_overlap");
}

/* A DEM step 30 times its limit (allowed) with the overlap guard off and the
 * tire far above the bed: the bed blows up to non-finite positions within a
 * few steps and the DEM side stops naming the step to reduce. (1 m above:
 * at 0.5 m grains thrown up by the blow-up reached the tire first and the
 * FEM's interface-work guard fired, since the bed is handed over as cached.) */
static int guard_grain_non_finite(void)
{
    const char *extra[] = {"--set", "wheel.start_gap=1.0", "--set", "wheel.sink_velocity=1e-6", "--set",
                           "coupling.dt=2e-3", "--set", "dem.allow_unstable_dt=true", "--set",
                           "coupling.max_overlap=0.0", "--set", "run.end_time=2.0", NULL};
    return stopped_by_guard(SCENES "tire_small.cfg", "nonfinite", extra, "dem", "non-finite", "coupling.dt");
}

/* The wheel's centre so low that the tire starts among the grains (the
 * highest grain top at 49 mm, the tire's lowest point at 17 mm; a tire clear
 * of the grains is still lifted to a large start_gap, guard_grain_non_finite
 * relies on it): refused at the first
 * exchange naming the key and the height needed, instead of being lifted
 * out with the forces of the grains it was inside (which the FEM's work
 * guard stopped as an "unstable coupling"). */
static int wheel_starts_inside_bed(void)
{
    const char *extra[] = {"--set", "wheel.center=[0.1, 0.1, 0.29]", NULL};
    return stopped_by_guard(SCENES "tire_small.cfg", "inside", extra, "fem", "the tire starts inside the bed",
                            "wheel.center");
}

/* An explicit FEM step 1.5 times its computed limit (allowed), the tire
 * clear of the grains: no load puts energy in, the energy guard stops it. */
static int guard_tire_energy_growth(void)
{
    const char *extra[] = {"--set", "wheel.start_gap=0.05", "--set", "wheel.sink_velocity=1e-6", "--set",
                           "fem.allow_unstable=true", "--set", "fem.dt=6e-5", "--set", "coupling.dt=1e-5", "--set",
                           "coupling.exchange_every=6", "--set", "run.end_time=0.05", NULL};
    return stopped_by_guard(SCENES "tire_small.cfg", "energy", extra, "fem", "energy grew", "fem.dt");
}

/* Every travel row (phase 1) of a traction.csv, or every row: the named columns. */
typedef struct travel_rows {
    int n;
    double *v[12];
} travel_rows;

static void travel_rows_free(travel_rows *tr)
{
    for (int k = 0; k < 12; k++)
        free(tr->v[k]);
}

static int read_rows(const char *dir, const char *const *cols, int ncols, int travel_only, travel_rows *tr)
{
    char path[400], line[4096];
    snprintf(path, sizeof path, "%s/traction.csv", dir);
    FILE *f = fopen(path, "r");
    memset(tr, 0, sizeof *tr);
    if (!f || !fgets(line, sizeof line, f) || ncols > 12) {
        if (f)
            fclose(f);
        return -1;
    }
    int idx[12], phase_col = -1, col = 0, cap = 0;
    for (int k = 0; k < ncols; k++)
        idx[k] = -1;
    for (char *tok = strtok(line, ",\n"); tok; tok = strtok(NULL, ",\n"), col++) {
        for (int k = 0; k < ncols; k++)
            if (strcmp(tok, cols[k]) == 0)
                idx[k] = col;
        if (strcmp(tok, "phase") == 0)
            phase_col = col;
    }
    for (int k = 0; k < ncols; k++)
        if (idx[k] < 0)
            phase_col = -1;
    while (phase_col >= 0 && fgets(line, sizeof line, f)) {
        double row[64];
        col = 0;
        for (char *tok = strtok(line, ",\n"); tok && col < 64; tok = strtok(NULL, ",\n"))
            row[col++] = strtod(tok, NULL);
        if (travel_only && (int)row[phase_col] != 1)
            continue;
        if (tr->n == cap) {
            cap = cap ? 2 * cap : 4096;
            for (int k = 0; k < ncols; k++)
                tr->v[k] = realloc(tr->v[k], (size_t)cap * sizeof(double));
        }
        for (int k = 0; k < ncols; k++)
            tr->v[k][tr->n] = row[idx[k]];
        tr->n++;
    }
    fclose(f);
    return phase_col >= 0 ? tr->n : -1;
}

static double mean_of(const double *x, int from, int to)
{
    double s = 0;
    for (int i = from; i < to; i++)
        s += x[i];
    return s / (to - from);
}

/* The realised slip recomputed from the recorded omega and v (the paper's
 * definitions, independent of fem_server/drive.c). */
static double slip_from(double omega, double R, double v)
{
    return v <= omega * R ? (omega * R - v) / (omega * R) : (omega * R - v) / v;
}

/* Braking (skid) end to end, slip control at s = -0.3 on the load-controlled
 * small tire: v = omega R / (1 + s) and the recorded slip is s in every
 * travel row; T_H >= 0, T_R <= 0 and F_x = T_H + T_R = T_P; over the second
 * half of the travel the skidding wheel is held back (T_P < 0) and the grains
 * turn it forward (moment about the axle > 0: the brake holds it). */
static int tire_braking_skid(void)
{
    char scene[200], cmd[800];
    snprintf(scene, sizeof scene, "/tmp/demfem-coupled-%d-brake.cfg", (int)getpid());
    snprintf(cmd, sizeof cmd, "sed 's/  slip = 0.2;/  slip = -0.3;/' %stire_small_load.cfg > %s && grep -q 'slip = -0.3' %s",
             SCENES, scene, scene);
    ENSURE(system(cmd) == 0);
    launch l;
    ENSURE(start(&l, scene, "brake", NULL) == 0);
    ENSURE(finish(&l, 300) == 0);
    unlink(scene);
    if (l.status != 0)
        dump_log(&l);
    ENSURE(l.status == 0);
    ENSURE(strstr(log_text(&l), "slip -30.0 %"));
    const char *cols[] = {"omega", "v", "slip", "Fx", "T_H", "T_R", "T_P", "My"};
    travel_rows tr;
    int n = read_rows(l.out, cols, 8, 1, &tr);
    ENSURE(n > 1000);
    double **c = tr.v;
    int bad = 0;
    for (int i = 0; i < n; i++) {
        bad += fabs(c[0][i] - 2.0) > 1e-12 || fabs(c[1][i] - 2.0 * 0.272 / 0.7) > 1e-12;
        bad += fabs(c[2][i] + 0.3) > 1e-12 || fabs(slip_from(c[0][i], 0.272, c[1][i]) + 0.3) > 1e-12;
        bad += c[4][i] < 0 || c[5][i] > 0;
        bad += fabs(c[3][i] - (c[4][i] + c[5][i])) > 1e-9 * (1 + c[4][i] - c[5][i]);
        bad += fabs(c[6][i] - c[3][i]) > 1e-9 * (1 + c[4][i] - c[5][i]);
    }
    double tp = mean_of(c[6], n / 2, n), my = mean_of(c[7], n / 2, n);
    printf("  %d travel exchanges in %.1f s; second half: T_P %.2f N, moment about the axle %.3f N m\n", n, l.wall,
           tp, my);
    travel_rows_free(&tr);
    ENSURE_MSG(bad == 0, "%d inconsistent travel rows", bad);
    ENSURE(tp < 0);
    ENSURE(my > 0);
    ENSURE(shm_clean(&l));
    return 0;
}

/* The moving average of the soil's force or moment that the controls use
 * (drive.h: over control_window, folded in at every exchange from the
 * first), recomputed from the recorded series. */
static void control_average(const double *x, int n, double window, double dt, double *avg)
{
    double y = 0, b = window > dt ? dt / window : 1.0;
    for (int i = 0; i < n; i++)
        avg[i] = y += b * (x[i] - y);
}

/* The momentum balance of a controlled wheel over the travel rows of a run:
 * inertia * (rate_end - rate_first) against the impulse of (prescribed +
 * averaged soil load); the first travel row starts at zero slip without
 * integrating. Returns the relative mismatch. */
static double momentum_mismatch(const travel_rows *tr, int rate_col, int load_col, double inertia, double prescribed,
                                double window, double *change, double *impulse)
{
    const double dt = 1e-5;
    double *avg = malloc((size_t)tr->n * sizeof(double)), scale = 0;
    control_average(tr->v[load_col], tr->n, window, dt, avg);
    int first = -1;
    *impulse = 0;
    for (int i = 0; i < tr->n; i++) {
        if ((int)tr->v[0][i] != 1)
            continue;
        if (first < 0) {
            first = i;
            continue;
        }
        *impulse += (prescribed + avg[i]) * dt;
        scale += (fabs(prescribed) + fabs(avg[i])) * dt;
    }
    int last = first;
    for (int i = first; i < tr->n; i++)
        last = (int)tr->v[0][i] == 1 ? i : last;
    *change = inertia * (tr->v[rate_col][last] - tr->v[rate_col][first]);
    free(avg);
    return fabs(*change - *impulse) / scale;
}

/* Torque control (axle torque 3 N m at v = 0.4 m/s, the tire mesh's
 * inertia): v stays prescribed, the recorded slip is the one omega and v
 * realise, the wheel's angular momentum changes by the impulse of the axle
 * torque and the grains' recorded moment (averaged over control_window):
 * I (omega_end - omega_0) = sum (T + <M_y>) dt, and the driving torque makes
 * a driving slip. */
static int tire_torque_control(void)
{
    launch l;
    ENSURE(start(&l, SCENES "tire_small_torque.cfg", "torque", NULL) == 0);
    ENSURE(finish(&l, 300) == 0);
    if (l.status != 0)
        dump_log(&l);
    ENSURE(l.status == 0);
    const char *log = log_text(&l);
    double I = 0;
    const char *p = strstr(log, "; inertia ");
    ENSURE(p && sscanf(p, "; inertia %lf kg m^2", &I) == 1 && I > 0.1 && I < 1.0); /* the mesh's */
    ENSURE(strstr(log, "realised, torque control") && strstr(log, "against the axle torque 3 N m"));
    ENSURE(strstr(log, "limited the motion at 0 of")); /* else the balance below would not be exact */
    const char *cols[] = {"phase", "omega", "v", "slip", "My"};
    travel_rows tr;
    int n = read_rows(l.out, cols, 5, 0, &tr);
    ENSURE(n > 5000);
    double **c = tr.v;
    int bad = 0, travel = 0;
    for (int i = 0; i < n; i++)
        if ((int)c[0][i] == 1) {
            travel++;
            bad += c[2][i] != 0.4 || fabs(c[3][i] - slip_from(c[1][i], 0.272, c[2][i])) > 1e-12;
        }
    double dL, impulse, mis = momentum_mismatch(&tr, 1, 4, I, 3.0, 0.002, &dL, &impulse);
    double slip = 0;
    for (int i = n - travel / 2; i < n; i++)
        slip += c[3][i] / (travel - travel / 2);
    printf("  %d travel exchanges in %.1f s: I domega %.6f N m s, torque impulse %.6f N m s; slip %.1f %%\n", travel,
           l.wall, dL, impulse, 100 * slip);
    travel_rows_free(&tr);
    ENSURE(travel > 5000);
    ENSURE_MSG(bad == 0, "%d inconsistent travel rows", bad);
    ENSURE_MSG(mis < 1e-3, "momentum mismatch %.3g (I is printed to 3 digits)", mis);
    ENSURE(slip > 0.01 && slip < 0.9);
    ENSURE(shm_clean(&l));
    return 0;
}

/* Drawbar control (5 N at omega = 2 rad/s, wheel mass 3 kg): omega stays
 * prescribed, the recorded slip is the one realised,
 * m (v_end - v_0) = sum (<F_x> - D) dt, and pulling a load takes a driving
 * slip. */
static int tire_drawbar_control(void)
{
    launch l;
    ENSURE(start(&l, SCENES "tire_small_drawbar.cfg", "drawbar", NULL) == 0);
    ENSURE(finish(&l, 300) == 0);
    if (l.status != 0)
        dump_log(&l);
    ENSURE(l.status == 0);
    ENSURE(strstr(log_text(&l), "realised, drawbar control") &&
           strstr(log_text(&l), "against the drawbar load 5 N"));
    ENSURE(strstr(log_text(&l), "limited the motion at 0 of")); /* else the balance below would not be exact */
    const char *cols[] = {"phase", "omega", "v", "slip", "Fx"};
    travel_rows tr;
    int n = read_rows(l.out, cols, 5, 0, &tr);
    ENSURE(n > 5000);
    double **c = tr.v;
    int bad = 0, travel = 0;
    for (int i = 0; i < n; i++)
        if ((int)c[0][i] == 1) {
            travel++;
            bad += c[1][i] != 2.0 || fabs(c[3][i] - slip_from(c[1][i], 0.272, c[2][i])) > 1e-12;
        }
    double dp, impulse, mis = momentum_mismatch(&tr, 2, 4, 3.0, -5.0, 0.005, &dp, &impulse);
    double slip = 0;
    for (int i = n - travel / 2; i < n; i++)
        slip += c[3][i] / (travel - travel / 2);
    printf("  %d travel exchanges in %.1f s: m dv %.6f N s, force impulse %.6f N s; slip %.1f %%\n", travel, l.wall,
           dp, impulse, 100 * slip);
    travel_rows_free(&tr);
    ENSURE(travel > 3000);
    ENSURE_MSG(bad == 0, "%d inconsistent travel rows", bad);
    ENSURE_MSG(mis < 1e-9, "momentum mismatch %.3g", mis);
    ENSURE(slip > 0.01 && slip < 0.9);
    ENSURE(shm_clean(&l));
    return 0;
}

static const test_case tests[] = {
    {"guard_grain_overlap", guard_grain_overlap},
    {"guard_grain_non_finite", guard_grain_non_finite},
    {"guard_tire_energy_growth", guard_tire_energy_growth},
    {"wheel_starts_inside_bed", wheel_starts_inside_bed},
    {"tire_exchange_every_two", tire_exchange_every_two},
    {"tire_from_gmsh_runs", tire_from_gmsh_runs},
    {"tire_small_runs", tire_small_runs},
    {"tire_unstable_exchange_stopped", tire_unstable_exchange_stopped},
    {"plate_impact_elastic", plate_impact_elastic},
    {"plate_impact_damped", plate_impact_damped},
    {"plate_peer_killed", plate_peer_killed},
    {"tire_braking_skid", tire_braking_skid},
    {"tire_torque_control", tire_torque_control},
    {"tire_drawbar_control", tire_drawbar_control},
};

int main(int argc, char **argv) { return test_main(argc, argv, tests, TEST_COUNT(tests)); }
