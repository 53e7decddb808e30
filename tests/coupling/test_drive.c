/* The wheel's prescribed motion (fem_server/drive) and the steady-state
 * statistics of the traction summary (fem_server/steady). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "drive.h"
#include "steady.h"
#include "test.h"

/* Driving and braking slip round-trip through v, and stay within [-1, 1]. */
static int slip_definitions(void)
{
    const double R = 0.272, w = 2.0;
    for (double s = -0.9; s <= 0.9001; s += 0.05) {
        double v = drive_travel_velocity(w, R, s);
        ENSURE(v > 0);
        ENSURE_NEAR(drive_slip(w, R, v), s, 1e-12);
    }
    /* Driving: the tread moves faster than the wheel centre. */
    ENSURE_NEAR(drive_travel_velocity(w, R, 0.05), 0.95 * w * R, 1e-15);
    /* Braking s = (wR - v)/v: v = wR/(1+s). */
    ENSURE_NEAR(drive_travel_velocity(w, R, -0.2), w * R / 0.8, 1e-15);
    ENSURE_NEAR(drive_slip(w, R, w * R), 0.0, 1e-15);
    return 0;
}

/* Sinks at constant speed until the load is reached, then travels the given
 * distance at the prescribed slip, then stops. */
static int phases(void)
{
    drive_def d = drive_def_default();
    d.center[2] = 0.5;
    d.sink_velocity = 0.1;
    d.target_load = 1000;
    d.omega = 2.0;
    d.slip = 0.2;
    d.travel_distance = 0.05;
    d.load_window = 0.0; /* react to the load at once */
    drive_state s;
    drive_start(&d, &s);
    cm_error err = {0};
    const double dt = 1e-3;
    double t = 0, load = 0;
    int k = 0;
    /* Load grows linearly with sinkage: 1000 N after 20 mm. */
    for (; s.phase == DRIVE_SINK && k < 10000; k++) {
        t += dt;
        ENSURE(drive_update(&d, &s, t, dt, load, &err) == CM_OK);
        load = 1000.0 * s.sunk / 0.02;
    }
    ENSURE(s.phase == DRIVE_TRAVEL);
    /* The load is measured over the interval before the decision: the phase
     * changes one or two steps (0.1 mm each) after the load is reached. */
    ENSURE(s.sunk >= 0.02 && s.sunk <= 0.02 + 2.01e-4);
    ENSURE_NEAR(s.center[2], 0.5 - s.sunk, 1e-12);
    ENSURE_NEAR(s.velocity[0], 2.0 * 0.272 * 0.8, 1e-12);
    ENSURE(s.velocity[2] == 0 && s.omega == 2.0);
    double x0 = s.center[0], a0 = s.angle;
    for (k = 0; s.phase == DRIVE_TRAVEL && k < 100000; k++) {
        t += dt;
        ENSURE(drive_update(&d, &s, t, dt, load, &err) == CM_OK);
    }
    ENSURE(s.phase == DRIVE_DONE);
    ENSURE(s.travelled >= 0.05 && s.travelled < 0.05 + 0.5 * dt);
    ENSURE_NEAR(s.center[0] - x0, s.travelled, 1e-12);
    /* Rotation and travel are in the slip ratio: x = (1 - s) omega R t. */
    ENSURE_NEAR(s.travelled, (1 - 0.2) * 0.272 * (s.angle - a0), 1e-9);
    ENSURE(s.velocity[0] == 0 && s.omega == 0);
    return 0;
}

/* One spike above the target does not end the sinkage: the averaged load must
 * reach it. */
static int load_spike_ignored(void)
{
    drive_def d = drive_def_default();
    d.target_load = 1000;
    d.load_window = 0.005;
    drive_state s;
    drive_start(&d, &s);
    cm_error err = {0};
    const double dt = 1e-5;
    for (int k = 0; k < 2000; k++) {
        double load = k == 500 ? 50000.0 : 300.0; /* one 50 kN spike, else 300 N */
        ENSURE(drive_update(&d, &s, k * dt, dt, load, &err) == CM_OK);
        ENSURE_MSG(s.phase == DRIVE_SINK, "switched at step %d, average %g N", k, s.load_avg);
    }
    for (int k = 0; k < 2000 && s.phase == DRIVE_SINK; k++)
        ENSURE(drive_update(&d, &s, k * dt, dt, 1200.0, &err) == CM_OK);
    ENSURE(s.phase == DRIVE_TRAVEL);
    ENSURE(s.load_avg >= 1000.0 && s.load_avg < 1200.0);
    return 0;
}

/* load_travel on a linear "soil" (F = k z below the surface): the wheel
 * settles at the static sinkage W/k without bouncing off, then travels at
 * the prescribed slip at that height. */
static int load_mode_settles_and_travels(void)
{
    drive_def d = drive_def_default();
    d.motion = DRIVE_LOAD_TRAVEL;
    d.center[2] = 0.0; /* surface at z = 0: contact force k (0 - z) */
    d.target_load = 1000.0;
    d.load_ramp = 0.1;
    d.mass = 20.0;
    d.slip = 0.1;
    d.omega = 2.0;
    d.travel_distance = 0.1;
    d.load_window = 0.002;
    const double k = 2e5, c = 2.0 * 0.3 * sqrt(k * d.mass); /* soil with 30 % damping */
    drive_state s;
    drive_start(&d, &s);
    cm_error err = {0};
    const double dt = 1e-5;
    double t = 0, max_rise = 0, t_travel = -1, z_travel = 0;
    for (int n = 0; n < 200000 && s.phase != DRIVE_DONE; n++) {
        if (s.phase == DRIVE_TRAVEL && t_travel < 0)
            t_travel = t, z_travel = s.center[2];
        double z = s.center[2];
        double load = z < 0 ? -k * z - c * s.velocity[2] : 0.0;
        load = load > 0 ? load : 0.0;
        t += dt;
        ENSURE(drive_update(&d, &s, t, dt, load, &err) == CM_OK);
        max_rise = s.center[2] > max_rise ? s.center[2] : max_rise;
        if (s.phase == DRIVE_SINK)
            ENSURE(s.omega == 0.0 && s.velocity[0] == 0.0);
    }
    ENSURE(s.phase == DRIVE_DONE);
    ENSURE(t_travel >= d.load_ramp);                    /* not before the load is fully applied */
    ENSURE_REL(-z_travel, d.target_load / k, 0.1);     /* settled near the static sinkage 5 mm */
    ENSURE_REL(-s.center[2], d.target_load / k, 0.01);
    ENSURE(max_rise == 0.0);                            /* never lifted off the surface */
    ENSURE(s.travelled >= 0.1);
    /* Travel took distance / v at v = omega R (1 - s). */
    ENSURE_REL(s.t_phase - t_travel, d.travel_distance / (d.omega * d.radius * (1 - d.slip)), 0.001);
    return 0;
}

static int fixed_wheel_stays(void)
{
    drive_def d = drive_def_default();
    d.motion = DRIVE_HOLD;
    d.center[0] = 0.1, d.center[2] = 0.3;
    drive_state s;
    drive_start(&d, &s);
    cm_error err = {0};
    for (int k = 0; k < 100; k++)
        ENSURE(drive_update(&d, &s, k * 1e-3, 1e-3, 1e9, &err) == CM_OK);
    ENSURE(s.phase == DRIVE_FIXED && s.center[0] == 0.1 && s.center[2] == 0.3 && s.omega == 0 && s.angle == 0);
    return 0;
}

static int sinkage_without_load_fails(void)
{
    drive_def d = drive_def_default();
    d.max_sink = 0.01;
    drive_state s;
    drive_start(&d, &s);
    cm_error err = {0};
    int rc = CM_OK;
    for (int k = 0; k < 1000 && rc == CM_OK; k++)
        rc = drive_update(&d, &s, k * 1e-3, 1e-3, 0.0, &err);
    ENSURE(rc == CM_ERR_NUMERIC);
    ENSURE_MSG(strstr(err.msg, "wheel.max_sink") && strstr(err.msg, "wheel.target_load"), "%s", err.msg);
    return 0;
}

/* Deterministic pseudo-random normal numbers (xorshift + Box–Muller). */
static double gauss(unsigned long long *state)
{
    double u[2];
    for (int k = 0; k < 2; k++) {
        *state ^= *state << 13;
        *state ^= *state >> 7;
        *state ^= *state << 17;
        u[k] = ((double)(*state >> 11) + 0.5) / 9007199254740992.0;
    }
    return sqrt(-2 * log(u[0])) * cos(2 * M_PI * u[1]);
}

/* A transient decaying into AR(1) noise around a known mean: MSER-5 finds
 * the end of the transient, and the 95 % interval covers the true mean in
 * about 95 % of independent runs. */
static int steady_detection_and_coverage(void)
{
    enum { N = 4000, RUNS = 300 };
    static double x[N];
    unsigned long long st = 88172645463325252ull;
    int covered = 0;
    double start_sum = 0;
    for (int r = 0; r < RUNS; r++) {
        double e = 0;
        for (int i = 0; i < N; i++) {
            e = 0.8 * e + gauss(&st); /* correlated noise, sd 1.67 */
            x[i] = 100.0 + 60.0 * exp(-i / 100.0) + e;
        }
        size_t s0 = steady_start(x, N);
        ENSURE_MSG(s0 >= 250 && s0 <= 1200, "run %d: steady part detected from %zu", r, s0);
        start_sum += (double)s0;
        steady_stats ss;
        steady_summary(x, N, s0, &ss);
        ENSURE(ss.batches == 20 && ss.half_width > 0);
        covered += fabs(ss.mean - 100.0) <= ss.half_width;
    }
    printf("  mean detected start %.0f; interval covered the true mean in %d of %d runs\n", start_sum / RUNS,
           covered, RUNS);
    ENSURE(covered >= 0.89 * RUNS && covered <= RUNS);
    /* Without a transient nothing much is dropped. */
    for (int i = 0; i < N; i++)
        x[i] = 5.0 + gauss(&st);
    ENSURE(steady_start(x, N) <= N / 2);
    ENSURE_NEAR(steady_t95(19), 2.093, 1e-9);
    ENSURE(steady_t95(200) > 1.96 && steady_t95(200) < 1.98);
    return 0;
}

static const test_case tests[] = {
    {"slip_definitions", slip_definitions},
    {"phases", phases},
    {"load_spike_ignored", load_spike_ignored},
    {"load_mode_settles_and_travels", load_mode_settles_and_travels},
    {"fixed_wheel_stays", fixed_wheel_stays},
    {"sinkage_without_load_fails", sinkage_without_load_fails},
    {"steady_detection_and_coverage", steady_detection_and_coverage},
};

int main(int argc, char **argv) { return test_main(argc, argv, tests, TEST_COUNT(tests)); }
