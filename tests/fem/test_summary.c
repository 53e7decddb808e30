/* Steady-state statistics (fem_server/steady.c) and the run summary
 * (fem_server/fem_summary.c) on synthetic signals of known mean, known
 * correlation time and known transients: the intervals must cover the true
 * mean at the stated rate, transients must be excluded, the lug-periodic
 * signal recovered, the load checked against its target. */
#include <hdf5.h>
#include <stdint.h>
#include <stdlib.h>
#include <unistd.h>

#include "drive.h"
#include "fem_summary.h"
#include "h5io.h"
#include "steady.h"
#include "test.h"

static double gauss(uint64_t *s)
{
    /* Box-Muller on splitmix64 draws */
    double u[2];
    for (int k = 0; k < 2; k++) {
        uint64_t z = (*s += 0x9e3779b97f4a7c15ULL);
        z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
        z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
        z ^= z >> 31;
        u[k] = ((double)(z >> 11) + 0.5) * (1.0 / 9007199254740992.0);
    }
    return sqrt(-2.0 * log(u[0])) * cos(2.0 * M_PI * u[1]);
}

/* AR(1) x_i = phi x_{i-1} + e_i: tau = (1 + phi) / (1 - phi) exactly. */
static int iat_of_ar1(void)
{
    enum { N = 200000 };
    double *x = malloc(N * sizeof *x);
    ENSURE(x);
    uint64_t s = 11;
    const double phis[] = {0.0, 0.5, 0.9, 0.98};
    for (size_t k = 0; k < sizeof phis / sizeof *phis; k++) {
        double phi = phis[k], e = 0;
        for (int i = 0; i < N; i++)
            x[i] = e = phi * e + gauss(&s);
        double tau = steady_iat(x, N), want = (1 + phi) / (1 - phi);
        printf("  phi %.2f: tau %.2f (exact %.2f)\n", phi, tau, want);
        /* statistical error of the estimate ~ sqrt(2 (2 M + 1) / N) tau, M ~ 5 tau */
        ENSURE_REL(tau, want, phi < 0.95 ? 0.2 : 0.25);
    }
    /* constant: 1 */
    for (int i = 0; i < 1000; i++)
        x[i] = 3.25;
    ENSURE(steady_iat(x, 1000) == 1.0);
    free(x);
    return 0;
}

/* A strongly correlated signal (tau = 99 samples, like the lug and heave
 * swings): 20 fixed batches of a 3000-sample series would be 150 samples
 * each, barely longer than tau, and cover the mean ~80 % of the time; the
 * batches of 5 tau cover it at the stated 95 % (binomial 3 sd: >= 91 %). */
static int coverage_correlated(void)
{
    enum { N = 3000, RUNS = 400 };
    static double x[N];
    uint64_t s = 5;
    int covered = 0, rough = 0;
    for (int r = 0; r < RUNS; r++) {
        double e = 0;
        for (int i = 0; i < 400; i++) /* start in the stationary state */
            e = 0.98 * e + gauss(&s);
        for (int i = 0; i < N; i++)
            x[i] = 7.0 + (e = 0.98 * e + gauss(&s));
        steady_stats st;
        steady_summary(x, N, 0, &st);
        covered += fabs(st.mean - 7.0) <= st.half_width;
        rough += st.short_series;
    }
    printf("  interval covered the true mean in %d of %d runs (%d rough)\n", covered, RUNS, rough);
    ENSURE(covered >= 0.91 * RUNS);
    ENSURE(covered <= 0.995 * RUNS); /* not absurdly wide either */
    return 0;
}

/* Whole lug periods: a signal sin(lugs * angle) averages to zero exactly
 * over whole periods; over the raw window (ending mid-period) it does not. */
static int lug_window_and_profile(void)
{
    enum { N = 1500, BINS = 24 };
    static double a[N], x[N];
    double period = 2 * M_PI / 16;
    for (int i = 0; i < N; i++) {
        a[i] = -0.0013 * i; /* the wheel turns in the negative sense: |angle| counts */
        x[i] = 10.0 + 3.0 * sin(2 * M_PI * fabs(a[i]) / period);
    }
    size_t end = steady_lug_window(a, N, 100, period);
    double turned = fabs(a[end] - a[100]);
    ENSURE_NEAR(fmod(turned, period), 0.0, 0.0014);
    ENSURE(fabs(a[N - 1] - a[100]) - turned < period);
    steady_stats whole, raw;
    steady_summary(x, end, 100, &whole);
    steady_summary(x, N, 100, &raw);
    ENSURE_NEAR(whole.mean, 10.0, 0.01);
    ENSURE(fabs(raw.mean - 10.0) > 0.1); /* 3.4 periods: the part period biases the mean */
    double pm[BINS];
    int pc[BINS];
    steady_profile(x, a, 100, end, period, BINS, pm, pc);
    for (int b = 0; b < BINS; b++) {
        double ph0 = fabs(a[100]) / period, phase = (b + 0.5) / BINS + ph0;
        ENSURE(pc[b] > 0);
        ENSURE_NEAR(pm[b], 10.0 + 3.0 * sin(2 * M_PI * phase), 0.45); /* bin width 1/24 of a period */
    }
    /* less than one period turned: the whole stretch */
    ENSURE(steady_lug_window(a, 40, 0, period) == 40);
    return 0;
}

/* A run's series written as fem_server writes it, with known answers:
 * T_P steady from the start, the sinkage in a transient for the first 30 %
 * of the travel, the load low (position control). The summary's steady part
 * excludes the sinkage transient, its means cover the true ones, the
 * coefficient is per actual load, the load warning names position control. */
enum { SYN_SINK = 500, SYN_N = 20000 };
static const double syn_dt = 1e-4, syn_v = 0.5, syn_R = 0.3, syn_W = 150.0, syn_TP = -12.0, syn_S = 0.04;
/* the time and sinkage of the travel's first row, as write_synthetic wrote them */
static double syn_set_down[2];

/* dir/wheel.h5, new, with an empty /series of the columns the summary reads. */
static int create_series(const char *dir, cm_h5 **h5, cm_h5_series **ser)
{
    char path[256];
    snprintf(path, sizeof path, "%s/wheel.h5", dir);
    static const char *const cols[] = {"t", "phase", "x", "angle", "Fz", "T_H", "T_R", "T_P", "sinkage", "slip", "My",
                                       "Fx"};
    cm_error err = {0};
    cm_h5_def def = cm_h5_default_def();
    ENSURE_MSG(cm_h5_create(path, &def, h5, &err) == 0, "%s", err.msg);
    ENSURE_MSG(cm_h5_series_create(*h5, "/series", cols, 12, NULL, ser, &err) == 0, "%s", err.msg);
    return 0;
}

/* dir/wheel.h5 with SYN_SINK rows of sinking and SYN_N of travel: the load
 * and T_P AR(1) noise about their true values, the sinkage S in a transient
 * 0.015 m e^{-t/0.1} plus `sink_rate` t (m/s) over the travel. */
static int write_synthetic(const char *dir, double sink_rate)
{
    cm_error err = {0};
    cm_h5 *h5 = NULL;
    cm_h5_series *ser = NULL;
    ENSURE(create_series(dir, &h5, &ser) == 0);
    uint64_t s = 99;
    double e1 = 0, e2 = 0, e3 = 0;
    for (int i = 0; i < SYN_SINK + SYN_N; i++) {
        int travel = i >= SYN_SINK;
        double tt = travel ? (i - SYN_SINK) * syn_dt : 0;
        e1 = 0.95 * e1 + gauss(&s), e2 = 0.95 * e2 + gauss(&s), e3 = 0.9 * e3 + gauss(&s);
        double sink = syn_S - (travel ? 0.015 * exp(-tt / 0.1) : 0.02) + sink_rate * tt + 1e-4 * e3;
        double load = syn_W + 5.0 * e1, tp = syn_TP + 2.0 * e2;
        double row[12] = {i * syn_dt, travel ? DRIVE_TRAVEL : DRIVE_SINK, syn_v * tt, -syn_v * tt / (syn_R * 0.9),
                          load, 30 + tp / 2, -30 + tp / 2, tp, sink, 0.1, -syn_R * (30 + tp / 2), tp};
        if (i == SYN_SINK)
            syn_set_down[0] = row[0], syn_set_down[1] = sink;
        ENSURE_MSG(cm_h5_series_append(ser, row, &err) == 0, "%s", err.msg);
    }
    ENSURE(cm_h5_close(&h5, &err) == 0);
    return 0;
}

/* The summary's attribute `name` of dir/wheel.h5 into buf: a string in its
 * own type (as_double 0; len bytes with its terminator) or a double. */
static int read_summary_value(const char *dir, const char *name, int as_double, void *buf, size_t len)
{
    char path[256];
    snprintf(path, sizeof path, "%s/wheel.h5", dir);
    hid_t f = H5Fopen(path, H5F_ACC_RDONLY, H5P_DEFAULT);
    ENSURE(f >= 0);
    hid_t g = H5Gopen2(f, "/summary", H5P_DEFAULT);
    hid_t at = H5Aopen(g, name, H5P_DEFAULT);
    ENSURE(at >= 0);
    hid_t ty = as_double ? H5Tcopy(H5T_NATIVE_DOUBLE) : H5Aget_type(at);
    memset(buf, 0, len);
    ENSURE((as_double ? H5Tget_size(ty) == len : H5Tget_size(ty) < len) && H5Aread(at, ty, buf) >= 0);
    H5Tclose(ty);
    H5Aclose(at);
    H5Gclose(g);
    H5Fclose(f);
    return 0;
}

/* The summary's string attribute `name` of dir/wheel.h5 into buf. */
static int read_summary_attr(const char *dir, const char *name, char *buf, size_t len)
{
    return read_summary_value(dir, name, 0, buf, len);
}

/* The summary's number attribute `name` of dir/wheel.h5. */
static int read_summary_number(const char *dir, const char *name, double *v)
{
    return read_summary_value(dir, name, 1, v, sizeof *v);
}

/* dir/summary.json into buf (as text). */
static int read_summary_json(const char *dir, char *buf, size_t len)
{
    char jpath[256];
    snprintf(jpath, sizeof jpath, "%s/summary.json", dir);
    FILE *jf = fopen(jpath, "r");
    ENSURE(jf);
    size_t got = fread(buf, 1, len - 1, jf);
    fclose(jf);
    ENSURE_MSG(got < len - 1, "%s: larger than the test's buffer (%zu bytes)", jpath, len);
    buf[got] = '\0';
    return 0;
}

static int summary_of_synthetic_run(void)
{
    char dir[] = "/tmp/fem_summary_XXXXXX";
    ENSURE(mkdtemp(dir));
    char path[256];
    snprintf(path, sizeof path, "%s/wheel.h5", dir);
    enum { SINK = SYN_SINK };
    const double dt = syn_dt, R = syn_R, W_true = syn_W, TP_true = syn_TP, S_true = syn_S;
    ENSURE(write_synthetic(dir, 0.0) == 0);
    cm_error err = {0};
    fem_summary_def d = {.out_dir = dir, .scene = "synthetic", .control = DRIVE_CONTROL_SLIP,
                         .motion = DRIVE_SINK_TRAVEL, .target_load = 400.0, .radius = R,
                         .lug_period = 2 * M_PI / 16, .interval = dt, .slip = 0.1};
    int rc = fem_summary_write(&d, &err);
    ENSURE_MSG(rc == FEM_SUMMARY_LOAD_OFF, "rc %d: %s", rc, err.msg);
    /* read it back */
    hid_t f = H5Fopen(path, H5F_ACC_RDONLY, H5P_DEFAULT);
    ENSURE(f >= 0);
    double q[13][8], t_start = 0;
    hid_t ds = H5Dopen2(f, "/summary/quantities", H5P_DEFAULT);
    ENSURE(ds >= 0 && H5Dread(ds, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, q) >= 0);
    H5Dclose(ds);
    double conv[4][11];
    ds = H5Dopen2(f, "/summary/convergence", H5P_DEFAULT);
    ENSURE(ds >= 0 && H5Dread(ds, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, conv) >= 0);
    H5Dclose(ds);
    H5Fclose(f);
    double set_down[2] = {0, 0};
    ENSURE(read_summary_number(dir, "steady_start_time", &t_start) == 0);
    ENSURE(read_summary_number(dir, "set_down_time", &set_down[0]) == 0);
    ENSURE(read_summary_number(dir, "set_down_sinkage", &set_down[1]) == 0);
    char warn[600], drift[400];
    ENSURE(read_summary_attr(dir, "load_warning", warn, sizeof warn) == 0);
    ENSURE(read_summary_attr(dir, "drift_warning", drift, sizeof drift) == 0);
    ENSURE_MSG(drift[0] == '\0', "%s", drift); /* the transient is excluded: steady */
    printf("  steady from t = %.3f s; T_P %.3f +- %.3f, load %.2f +- %.2f, sinkage %.5f +- %.5f, T_P/W %.5f +- %.5f\n",
           t_start, q[2][0], q[2][1], q[3][0], q[3][1], q[4][0], q[4][1], q[8][0], q[8][1]);
    /* the sinkage transient (0.015 m e^{-t/0.1}) is out: < 1e-4 m left after 0.5 s of it */
    ENSURE(t_start - SINK * dt > 0.25);
    ENSURE(fabs(q[4][0] - S_true) <= q[4][1] + 2e-5);
    ENSURE(fabs(q[2][0] - TP_true) <= q[2][1]);
    ENSURE(fabs(q[3][0] - W_true) <= q[3][1]);
    ENSURE_NEAR(q[8][0], q[2][0] / q[3][0], 1e-12);    /* per actual load */
    ENSURE(fabs(q[8][0] - TP_true / W_true) <= q[8][1]);
    ENSURE_NEAR(q[9][0], q[4][0] / R, 1e-12);          /* sinkage / R */
    ENSURE_NEAR(q[10][0], q[0][0], 1e-9);              /* T_H from the axle torque, -M_y / R */
    ENSURE_NEAR(q[11][0], q[2][0], 1e-12);             /* Fx, here = T_P */
    ENSURE_NEAR(q[12][0], -R * q[0][0], 1e-9);         /* My */
    ENSURE(q[2][5] > 0.5 * 39 * dt && q[2][5] < 2 * 39 * dt); /* tau of AR(0.95) = 39 samples */
    ENSURE_MSG(strstr(warn, "sink_travel") && strstr(warn, "150"), "%s", warn);
    /* convergence with travel: the full stretch is the summary's; the
     * half-width of T_P shrinks about as 1/sqrt(travel) (x 1/2 from a
     * quarter to all, within the intervals' own scatter) */
    ENSURE_NEAR(conv[3][5], q[2][0], 1e-12);
    ENSURE_NEAR(conv[3][6], q[2][1], 1e-12);
    ENSURE(conv[0][0] > 0.2 * conv[3][0] && conv[0][0] < 0.3 * conv[3][0]);
    ENSURE_MSG(conv[3][6] / conv[0][6] > 0.3 && conv[3][6] / conv[0][6] < 0.75, "quarter %g, all %g", conv[0][6],
               conv[3][6]);
    /* summary.json beside it says the same */
    char buf[16384];
    ENSURE(read_summary_json(dir, buf, sizeof buf) == 0);
    ENSURE(strstr(buf, "\"T_P_per_W\"") && strstr(buf, "\"warnings\": [\"the steady load is 150"));
    /* the set-down is the travel's first row: not the last row of the
     * sinking (5 mm shallower here) nor the steady sinkage (15 mm deeper) */
    ENSURE(set_down[0] == syn_set_down[0] && set_down[1] == syn_set_down[1]);
    const char *sd = strstr(buf, "\"set_down\": {\"time_s\": ");
    double sd_json[2] = {0, 0};
    ENSURE_MSG(sd && sscanf(sd, "\"set_down\": {\"time_s\": %lf, \"sinkage_m\": %lf}", &sd_json[0], &sd_json[1]) == 2,
               "%s", buf);
    ENSURE(sd_json[0] == syn_set_down[0] && sd_json[1] == syn_set_down[1]);
    /* on target: no warning */
    d.target_load = 150.0;
    ENSURE_MSG(fem_summary_write(&d, &err) == CM_OK, "%s", err.msg);
    snprintf(buf, sizeof buf, "rm -rf %s", dir);
    ENSURE(system(buf) == 0);
    return 0;
}

/* A wheel still sinking through the whole travel (2 cm/s on top of the
 * transient: 4 cm over the 2 s) is not called steady: MSER keeps the second
 * half, whose halves differ by ~1 cm; the summary says so in wheel.h5
 * (drift_warning), summary.json's warnings and the log, and names the
 * sinking. The load is on target, so the drift is the only warning. */
static int summary_sinkage_drift(void)
{
    char dir[] = "/tmp/fem_summary_drift_XXXXXX";
    ENSURE(mkdtemp(dir));
    ENSURE(write_synthetic(dir, 0.02) == 0);
    cm_error err = {0};
    fem_summary_def d = {.out_dir = dir, .scene = "synthetic", .control = DRIVE_CONTROL_SLIP,
                         .motion = DRIVE_LOAD_TRAVEL, .target_load = syn_W, .radius = syn_R,
                         .lug_period = 2 * M_PI / 16, .interval = syn_dt, .slip = 0.1};
    ENSURE_MSG(fem_summary_write(&d, &err) == CM_OK, "%s", err.msg);
    char warn[600], drift[400];
    ENSURE(read_summary_attr(dir, "load_warning", warn, sizeof warn) == 0);
    ENSURE(read_summary_attr(dir, "drift_warning", drift, sizeof drift) == 0);
    printf("  %s\n", drift);
    ENSURE_MSG(warn[0] == '\0', "%s", warn);
    ENSURE_MSG(strstr(drift, "not steady") && strstr(drift, "sinking"), "%s", drift);
    char buf[16384];
    ENSURE(read_summary_json(dir, buf, sizeof buf) == 0);
    ENSURE(strstr(buf, "\"warnings\": [\"the sinkage is not steady"));
    snprintf(buf, sizeof buf, "rm -rf %s", dir);
    ENSURE(system(buf) == 0);
    return 0;
}

/* The summary's settings for the synthetic run of write_synthetic: its
 * whole travel, not yet done (the tests set what they check). */
static fem_summary_def synthetic_def(const char *dir)
{
    const double travelled = syn_v * (SYN_N - 1) * syn_dt;
    return (fem_summary_def){.out_dir = dir, .scene = "synthetic", .control = DRIVE_CONTROL_SLIP,
                             .motion = DRIVE_LOAD_TRAVEL, .target_load = syn_W, .radius = syn_R,
                             .lug_period = 2 * M_PI / 16, .interval = syn_dt, .slip = 0.1,
                             .travel_distance = travelled, .travelled = travelled, .travel_done = 0};
}

/* A run that stopped short of its travel (interrupted, or run.end_time
 * first) says so: wheel.h5's travel_warning and travel_completed,
 * summary.json's travel_completed and warnings; the same series with the
 * travel done has no warning. */
static int summary_short_travel(void)
{
    char dir[] = "/tmp/fem_summary_short_XXXXXX";
    ENSURE(mkdtemp(dir));
    ENSURE(write_synthetic(dir, 0.0) == 0);
    cm_error err = {0};
    fem_summary_def d = synthetic_def(dir);
    d.travel_distance = 2.5;
    char warn[400], buf[16384];
    for (int done = 0; done <= 1; done++) {
        d.travel_done = done;
        ENSURE_MSG(fem_summary_write(&d, &err) == CM_OK, "%s", err.msg);
        ENSURE(read_summary_attr(dir, "travel_warning", warn, sizeof warn) == 0);
        ENSURE(read_summary_json(dir, buf, sizeof buf) == 0);
        if (!done) {
            printf("  %s\n", warn);
            ENSURE_MSG(strstr(warn, "stopped at 1.000 m of wheel.travel_distance = 2.500 m"), "%s", warn);
            ENSURE(strstr(buf, "\"travel_completed\": false") && strstr(buf, "\"warnings\": [\"the travel stopped"));
        } else {
            ENSURE_MSG(warn[0] == '\0', "%s", warn);
            ENSURE(strstr(buf, "\"travel_completed\": true") && strstr(buf, "\"warnings\": []"));
        }
    }
    snprintf(buf, sizeof buf, "rm -rf %s", dir);
    ENSURE(system(buf) == 0);
    return 0;
}

/* The interface-work check: a gap of the two sides' works above work_warn
 * at some time of the run warns in summary.json and wheel.h5, with the
 * worst gap and when it started; below it, nothing. */
static int summary_work_warning(void)
{
    char dir[] = "/tmp/fem_summary_work_XXXXXX";
    ENSURE(mkdtemp(dir));
    ENSURE(write_synthetic(dir, 0.0) == 0);
    cm_error err = {0};
    fem_summary_def d = synthetic_def(dir);
    d.travel_done = 1, d.work_dem = -2.0, d.work_fem = -2.1, d.work_warn = 0.02;
    char warn[600], buf[16384];
    const double gaps[] = {0.005, 0.02, 0.12};
    for (int k = 0; k < 3; k++) {
        d.work_gap_max = gaps[k];
        d.work_warned_at = gaps[k] > d.work_warn ? 0.29 : 0.0;
        ENSURE_MSG(fem_summary_write(&d, &err) == CM_OK, "%s", err.msg);
        ENSURE(read_summary_attr(dir, "work_warning", warn, sizeof warn) == 0);
        ENSURE(read_summary_json(dir, buf, sizeof buf) == 0);
        ENSURE_MSG(strstr(buf, "\"interface_work\": {\"dem_J\": -2, \"fem_J\": -2.1"), "%s", buf);
        if (gaps[k] > d.work_warn) {
            printf("  %s\n", warn);
            ENSURE_MSG(strstr(warn, "up to 12.0 % apart") && strstr(warn, "at t = 0.2900 s") &&
                           strstr(warn, "4.8 % of the larger") && strstr(warn, "coupling.dt"),
                       "%s", warn);
            ENSURE(strstr(buf, "\"warnings\": [\"the interface work seen by the FEM"));
        } else { /* at the threshold or below: no warning */
            ENSURE_MSG(warn[0] == '\0', "%s", warn);
            ENSURE(strstr(buf, "\"warnings\": []"));
        }
    }
    snprintf(buf, sizeof buf, "rm -rf %s", dir);
    ENSURE(system(buf) == 0);
    return 0;
}

/* A wheel that never reached the travel phase (still sinking when the run
 * stopped) has no set-down: null in summary.json, NaN in wheel.h5. */
static int summary_never_travelled(void)
{
    char dir[] = "/tmp/fem_summary_sink_XXXXXX";
    ENSURE(mkdtemp(dir));
    cm_error err = {0};
    cm_h5 *h5 = NULL;
    cm_h5_series *ser = NULL;
    ENSURE(create_series(dir, &h5, &ser) == 0);
    for (int i = 0; i < 100; i++) {
        double row[12] = {i * syn_dt, DRIVE_SINK, 0, 0, 2.0 * i, 0, 0, 0, 1e-4 * i, 0, 0, 0};
        ENSURE_MSG(cm_h5_series_append(ser, row, &err) == 0, "%s", err.msg);
    }
    ENSURE(cm_h5_close(&h5, &err) == 0);
    fem_summary_def d = synthetic_def(dir);
    ENSURE_MSG(fem_summary_write(&d, &err) == CM_OK, "%s", err.msg);
    char buf[16384];
    ENSURE(read_summary_json(dir, buf, sizeof buf) == 0);
    ENSURE_MSG(strstr(buf, "\"travelled\": false") &&
                   strstr(buf, "\"set_down\": {\"time_s\": null, \"sinkage_m\": null}"),
               "%s", buf);
    double v = 0;
    ENSURE(read_summary_number(dir, "set_down_sinkage", &v) == 0 && isnan(v));
    snprintf(buf, sizeof buf, "rm -rf %s", dir);
    ENSURE(system(buf) == 0);
    return 0;
}

static const test_case tests[] = {
    {"iat_of_ar1", iat_of_ar1},
    {"coverage_correlated", coverage_correlated},
    {"lug_window_and_profile", lug_window_and_profile},
    {"summary_of_synthetic_run", summary_of_synthetic_run},
    {"summary_sinkage_drift", summary_sinkage_drift},
    {"summary_short_travel", summary_short_travel},
    {"summary_work_warning", summary_work_warning},
    {"summary_never_travelled", summary_never_travelled},
};

int main(int argc, char **argv)
{
    cm_h5_library_init();
    return test_main(argc, argv, tests, TEST_COUNT(tests));
}
