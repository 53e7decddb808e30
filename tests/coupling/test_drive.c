/* The wheel's prescribed motion (fem_server/drive) and the steady-state
 * statistics of the traction summary (fem_server/steady). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "drive.h"
#include "steady.h"
#include "test.h"

/* drive_update with a vertical soil force only. */
static int vertical_update(const drive_def *d, drive_state *s, double t, double dt, double load, cm_error *err)
{
    const drive_soil soil = {0.0, load, 0.0};
    return drive_update(d, s, t, dt, &soil, err);
}

/* The wheel section of a scene text read as fem_server reads it: r from
 * drive_def_default, the reader's status (a text that does not parse fails
 * too, with its own message). */
static int read_wheel(const char *text, drive_def *r, cm_error *err)
{
    cm_scene *sc;
    *r = drive_def_default();
    int rc = cm_scene_open_string(text, "wheel.cfg", &sc, err);
    if (rc)
        return rc;
    rc = drive_config_read(sc, r, err);
    cm_scene_close(&sc);
    return rc;
}

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
        ENSURE(vertical_update(&d, &s, t, dt, load, &err) == CM_OK);
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
        ENSURE(vertical_update(&d, &s, t, dt, load, &err) == CM_OK);
    }
    ENSURE(s.phase == DRIVE_DONE);
    ENSURE(s.travelled >= 0.05 && s.travelled < 0.05 + 0.5 * dt);
    ENSURE_NEAR(s.center[0] - x0, s.travelled, 1e-12);
    /* Rotation and travel are in the slip ratio: x = (1 - s) omega R t. */
    ENSURE_NEAR(s.travelled, (1 - 0.2) * 0.272 * (s.angle - a0), 1e-9);
    ENSURE(s.velocity[0] == 0 && s.omega == 0);
    return 0;
}

/* The approach: fast while the wheel carries nothing, slowing linearly with
 * the load to sink_velocity at approach_load W. On soil whose force grows
 * linearly with the sinkage, F = k z, the speed law z' = v_a - (v_a - v_s) z / z_h
 * (z_h = approach_load W / k) integrates in closed form to
 * z = z_inf (1 - exp(-t / tau)), tau = z_h / (v_a - v_s), z_inf = v_a tau,
 * so z_h is reached at t_h = -tau ln(1 - z_h / z_inf); the rest at v_s. */
static int approach_speed(void)
{
    const double va = 0.5, vs = 0.1, W = 400.0, zW = 0.02; /* the load W at 20 mm */
    drive_def d = drive_def_default();
    d.center[2] = 0.5;
    d.sink_velocity = vs;
    d.approach_velocity = va;
    d.approach_load = 0.5;
    d.target_load = W;
    d.load_window = 0.0;
    d.travel_distance = 0.01;
    drive_state s;
    drive_start(&d, &s);
    cm_error err = {0};
    const double dt = 1e-6, zh = d.approach_load * zW;
    double t = 0, load = 0, v_first = 0, v_last = 0, worst = 0;
    long k = 0;
    for (; s.phase == DRIVE_SINK && k < 1000000; k++) {
        t += dt;
        ENSURE(vertical_update(&d, &s, t, dt, load, &err) == CM_OK);
        if (k == 0)
            v_first = -s.velocity[2];
        if (s.phase == DRIVE_SINK) {
            v_last = -s.velocity[2];
            /* the speed law at the state's own load, within [v_s, v_a] */
            double expect = vs + (va - vs) * fmax(0.0, 1.0 - s.load_avg / (0.5 * W));
            worst = fmax(worst, fabs(-s.velocity[2] - expect));
            ENSURE(-s.velocity[2] <= va && -s.velocity[2] >= vs);
        }
        load = W * s.sunk / zW;
    }
    double tau = zh / (va - vs), zinf = va * tau;
    double t_expect = -tau * log(1.0 - zh / zinf) + (zW - zh) / vs;
    printf("  load reached after %.5f s (closed form %.5f s; at sink_velocity alone %.3f s); speed %.3f then %.3f "
           "m/s\n", t, t_expect, zW / vs, v_first, v_last);
    ENSURE(s.phase == DRIVE_TRAVEL);
    ENSURE(v_first == va && v_last == vs && worst < 1e-15);
    ENSURE_NEAR(t, t_expect, 2e-5 * t_expect + 2 * dt);

    /* Under load control the free wheel accelerates under the load but is
     * lowered no faster than the approach speed while it carries nothing. */
    d.motion = DRIVE_LOAD_TRAVEL;
    d.mass = 20.0;
    d.damping = 0.0;
    d.load_ramp = 0.0;
    drive_start(&d, &s);
    double vmax = 0;
    for (k = 0, t = 0; k < 200000; k++) {
        t += dt;
        ENSURE(vertical_update(&d, &s, t, dt, 0.0, &err) == CM_OK);
        vmax = fmax(vmax, -s.velocity[2]);
    }
    ENSURE(s.phase == DRIVE_SINK && vmax == va);

    /* The scene keys: off by default (approach_velocity = sink_velocity), and
     * an approach slower than the sinkage is none (a study varying
     * sink_velocity alone keeps its base's approach). */
    drive_def r;
    int rc = read_wheel("wheel = { center = [0.0, 0.0, 1.0]; radius = 0.3; target_load = 100.0; "
                        "sink_velocity = 0.2; };",
                        &r, &err);
    ENSURE_MSG(rc == CM_OK && r.approach_velocity == 0.2, "%s", err.msg);
    rc = read_wheel("wheel = { center = [0.0, 0.0, 1.0]; radius = 0.3; target_load = 100.0; "
                    "sink_velocity = 0.2; approach_velocity = 0.1; };",
                    &r, &err);
    ENSURE_MSG(rc == CM_OK, "%s", err.msg);
    drive_start(&r, &s);
    ENSURE(drive_sink_speed(&r, &s) == 0.2);
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
        ENSURE(vertical_update(&d, &s, k * dt, dt, load, &err) == CM_OK);
        ENSURE_MSG(s.phase == DRIVE_SINK, "switched at step %d, average %g N", k, s.load_avg);
    }
    for (int k = 0; k < 2000 && s.phase == DRIVE_SINK; k++)
        ENSURE(vertical_update(&d, &s, k * dt, dt, 1200.0, &err) == CM_OK);
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
        ENSURE(vertical_update(&d, &s, t, dt, load, &err) == CM_OK);
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
        ENSURE(vertical_update(&d, &s, k * 1e-3, 1e-3, 1e9, &err) == CM_OK);
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
        rc = vertical_update(&d, &s, k * 1e-3, 1e-3, 0.0, &err);
    ENSURE(rc == CM_ERR_NUMERIC);
    ENSURE_MSG(strstr(err.msg, "wheel.max_sink") && strstr(err.msg, "wheel.target_load"), "%s", err.msg);
    return 0;
}

/* ---- torque and drawbar control, the rig's damper ---------------------- */

/* A wheel whose travel starts at the first update (sink_travel with no load
 * to reach), the soil's force and moment fed back at once (no averaging). */
static drive_def control_def(drive_control control)
{
    drive_def d = drive_def_default();
    d.control = control;
    d.target_load = 0.0;
    d.load_window = 0.0;
    d.control_window = 0.0;
    d.travel_distance = 1e3;
    d.radius = 0.3;
    d.velocity = 0.6; /* torque: v prescribed */
    d.omega = 2.0;    /* drawbar: omega prescribed */
    d.inertia = 0.5;
    d.mass = 10.0;
    return d;
}

/* Constant soil moment: omega grows linearly, I omega' = T + M_y, from the
 * zero-slip start omega = v / R; v and the centre's travel are as prescribed.
 * Beyond max_accel the slope is max_accel / R; the stops hold the driven
 * wheel at slip 0.95 and lock the braked one (slip -1). */
static int torque_constant_moment(void)
{
    drive_def d = control_def(DRIVE_CONTROL_TORQUE);
    d.torque = 3.0;
    const drive_soil soil = {0.0, 0.0, -1.0}; /* the soil resists with 1 N m */
    drive_state s;
    drive_start(&d, &s);
    cm_error err = {0};
    const double dt = 1e-5;
    ENSURE(drive_update(&d, &s, dt, dt, &soil, &err) == CM_OK);
    ENSURE(s.phase == DRIVE_TRAVEL);
    ENSURE_NEAR(s.omega, 2.0, 1e-15); /* v / R: zero slip */
    ENSURE_NEAR(drive_realised_slip(&d, &s), 0.0, 1e-15);
    const int n = 10000; /* 0.1 s */
    double x0 = s.center[0], a0 = s.angle;
    for (int k = 0; k < n; k++)
        ENSURE(drive_update(&d, &s, (k + 2) * dt, dt, &soil, &err) == CM_OK);
    const double alpha = (3.0 - 1.0) / 0.5, t = n * dt; /* 4 rad/s^2 */
    ENSURE_NEAR(s.omega, 2.0 + alpha * t, 1e-9);
    /* The angle turned at the omega held over each interval: 2 t + alpha t^2 / 2 to O(dt). */
    ENSURE_NEAR(s.angle - a0, 2.0 * t + 0.5 * alpha * t * t, alpha * t * dt);
    ENSURE_NEAR(s.center[0] - x0, 0.6 * t, 1e-12);
    ENSURE(s.velocity[0] == 0.6 && s.rate_limited == 0);
    ENSURE_NEAR(drive_realised_slip(&d, &s), 1.0 - 0.6 / (2.4 * 0.3), 1e-9);

    /* A large torque: the slope is max_accel / R. */
    d.torque = 30.0;
    double w0 = s.omega;
    for (int k = 0; k < n; k++)
        ENSURE(drive_update(&d, &s, 0.1 + k * dt, dt, &soil, &err) == CM_OK);
    ENSURE_NEAR(s.omega, w0 + d.max_accel / d.radius * t, 1e-9);
    ENSURE(s.rate_limited == n);
    for (int k = 0; k < 300; k++) /* 3 s, the stop at slip 0.95 */
        ENSURE(drive_update(&d, &s, 1.0, 1e-2, &soil, &err) == CM_OK);
    ENSURE_NEAR(drive_realised_slip(&d, &s), DRIVE_SLIP_LIMIT, 1e-12);
    /* Braking harder than the soil drives: the wheel locks, slip -1. */
    d.torque = -5.0;
    for (int k = 0; k < 1000; k++)
        ENSURE(drive_update(&d, &s, 5.0, 1e-2, &soil, &err) == CM_OK);
    ENSURE(s.omega == 0.0);
    ENSURE_NEAR(drive_realised_slip(&d, &s), -1.0, 1e-15);
    ENSURE(s.velocity[0] == 0.6);
    return 0;
}

/* A soil whose traction grows linearly with the slip, F_x = K s (moment
 * about the axle -R F_x), with the averaging on: the driven wheel settles
 * at the slip where the soil carries the torque, s = T / (R K), and the
 * braked one at s = T / (R K) < 0, the averaged moment equal to -T. */
static int torque_settles_at_equilibrium(void)
{
    const double K = 200.0;
    for (int sign = 1; sign >= -1; sign -= 2) {
        drive_def d = control_def(DRIVE_CONTROL_TORQUE);
        d.control_window = 0.002;
        d.torque = sign * 6.0;
        drive_state s;
        drive_start(&d, &s);
        cm_error err = {0};
        const double dt = 1e-5;
        for (int k = 0; k < 50000; k++) { /* 0.5 s: time constant ~20 ms */
            double slip = drive_realised_slip(&d, &s);
            const drive_soil soil = {K * slip, 0.0, -d.radius * K * slip};
            ENSURE(drive_update(&d, &s, (k + 1) * dt, dt, &soil, &err) == CM_OK);
        }
        double expect = d.torque / (d.radius * K); /* +-0.1 */
        printf("  torque %+g N m: slip %.6f (closed form %.6f), soil moment %.6f N m\n", d.torque,
               drive_realised_slip(&d, &s), expect, s.my_avg);
        ENSURE_NEAR(drive_realised_slip(&d, &s), expect, 1e-6);
        ENSURE_NEAR(s.my_avg, -d.torque, 1e-4);
        ENSURE(s.velocity[0] == d.velocity);
    }
    return 0;
}

/* Drawbar control: a constant soil force makes v linear, m v' = F_x - D,
 * from the zero-slip start v = omega R; a soil with F_x = K s settles at
 * s = D / K; a drawbar load beyond what the soil can give (K at slip 1)
 * stops the wheel (v = 0, slip 1); a push (D < 0) on a soil that brakes
 * (F_x = K s < 0 when skidding) settles at the braking slip D / K. */
static int drawbar_control(void)
{
    drive_def d = control_def(DRIVE_CONTROL_DRAWBAR);
    d.drawbar = 10.0;
    drive_state s;
    drive_start(&d, &s);
    cm_error err = {0};
    const double dt = 1e-5;
    drive_soil soil = {30.0, 0.0, 0.0};
    ENSURE(drive_update(&d, &s, dt, dt, &soil, &err) == CM_OK);
    ENSURE(s.phase == DRIVE_TRAVEL);
    ENSURE_NEAR(s.velocity[0], 0.6, 1e-15); /* omega R: zero slip */
    for (int k = 0; k < 10000; k++)
        ENSURE(drive_update(&d, &s, (k + 2) * dt, dt, &soil, &err) == CM_OK);
    ENSURE_NEAR(s.velocity[0], 0.6 + (30.0 - 10.0) / 10.0 * 0.1, 1e-9);
    ENSURE(s.omega == 2.0 && s.rate_limited == 0);
    ENSURE(drive_realised_slip(&d, &s) < 0); /* pushed faster than it rolls: braking slip */

    const double K = 200.0;
    const double loads[] = {20.0, -20.0, 300.0};
    const double expect[] = {0.1, -0.1, 1.0};
    for (int c = 0; c < 3; c++) {
        d = control_def(DRIVE_CONTROL_DRAWBAR);
        d.control_window = 0.002;
        d.drawbar = loads[c];
        drive_start(&d, &s);
        for (int k = 0; k < 100000; k++) { /* 1 s: time constant m omega R / K = 30 ms */
            double slip = drive_realised_slip(&d, &s);
            soil.fx = K * slip;
            ENSURE(drive_update(&d, &s, (k + 1) * dt, dt, &soil, &err) == CM_OK);
        }
        printf("  drawbar %+g N: slip %.6f (expected %.6f), soil force %.4f N, v %.5f m/s\n", d.drawbar,
               drive_realised_slip(&d, &s), expect[c], s.fx_avg, s.velocity[0]);
        ENSURE_NEAR(drive_realised_slip(&d, &s), expect[c], 1e-6);
        if (c < 2)
            ENSURE_NEAR(s.fx_avg, d.drawbar, 1e-4);
        else
            ENSURE(s.velocity[0] == 0.0 && s.rate_limited > 0);
    }
    return 0;
}

/* The ramped-slip rig (wheel.slip_end): under slip control the realised
 * slip is linear in the distance travelled, from wheel.slip to slip_end at
 * travel_distance. A soil that needs a relaxation length L to build up its
 * force, dF/dx = (K s - F) / L, read through the ramp lags its steady law
 * F = K s by K L ds/dx once the start-up transient (~e^{-x/L}) has passed: the
 * steady solution of that lag equation for a linear ramp, and the rule for
 * how slow a ramp must be (K L ds/dx below the accuracy wanted). A scene
 * that ramps without a travel length is refused. */
static int slip_ramp_lag(void)
{
    drive_def d = control_def(DRIVE_CONTROL_SLIP);
    d.slip = -0.1;
    d.slip_end = 0.5;
    d.slip_ramp = 1;
    d.travel_distance = 0.3;
    const double K = 1000.0, L = 0.01, g = (d.slip_end - d.slip) / d.travel_distance; /* ds/dx = 2 per m */
    drive_state s;
    drive_start(&d, &s);
    cm_error err = {0};
    const double dt = 1e-4;
    drive_soil soil = {0.0, 0.0, 0.0};
    double F = 0.0, worst_ramp = 0.0, worst_lag = 0.0, last_slip = 0.0;
    long n = 0, steady = 0;
    for (; n < 1000000; n++) {
        double slip_held = drive_realised_slip(&d, &s), x0 = s.travelled;
        ENSURE(drive_update(&d, &s, (n + 1) * dt, dt, &soil, &err) == CM_OK);
        if (s.phase != DRIVE_TRAVEL)
            break;
        /* the soil over the interval just moved, at the slip held over it (exact for constant slip) */
        double dx = s.travelled - x0;
        F = K * slip_held + (F - K * slip_held) * exp(-dx / L);
        soil.fx = F;
        double slip = drive_realised_slip(&d, &s);
        double ramp = d.slip + g * s.travelled;
        worst_ramp = fmax(worst_ramp, fabs(slip - ramp));
        /* the ramp's reading of the soil against the steady law, once the
         * start-up transient (100 N at the first slip) has decayed: past 8 L */
        if (s.travelled > 8 * L) {
            worst_lag = fmax(worst_lag, fabs((K * slip - F) - K * L * g));
            steady++;
        }
        last_slip = slip;
    }
    printf("  %ld intervals, %ld past 8 L: slip off the ramp by at most %.2e; lag K s - F off K L ds/dx = %.3f N "
           "by at most %.3f N; last slip %.4f\n", n, steady, worst_ramp, K * L * g, worst_lag, last_slip);
    ENSURE(s.phase == DRIVE_DONE && steady > 1000);
    ENSURE(worst_ramp < 1e-12);
    ENSURE_NEAR(last_slip, d.slip_end, 1e-3);
    ENSURE(worst_lag < 0.02 * K * L * g);

    /* the scene keys: a ramp needs a travel length */
    drive_def r;
    int rc = read_wheel("wheel = { center = [0.0, 0.0, 1.0]; radius = 0.3; target_load = 100.0; "
                        "slip = 0.0; slip_end = 0.4; travel_distance = 0.0; };",
                        &r, &err);
    ENSURE_MSG(rc != CM_OK && strstr(err.msg, "wheel.slip_end"), "a ramp without travel accepted (%s)", err.msg);
    rc = read_wheel("wheel = { center = [0.0, 0.0, 1.0]; radius = 0.3; target_load = 100.0; "
                    "slip = 0.0; slip_end = 0.4; travel_distance = 0.5; };",
                    &r, &err);
    ENSURE_MSG(rc == CM_OK && r.slip_ramp && r.slip_end == 0.4, "%s", err.msg);
    ENSURE_NEAR(drive_prescribed_slip(&r, 0.25), 0.2, 1e-15);
    return 0;
}

/* Slip control: the recorded (realised) slip is the prescribed one, driving
 * and braking, in both motions, throughout the travel. */
static int slip_control_realises_slip(void)
{
    const double slips[] = {-0.9, -0.3, -0.05, 0.0, 0.05, 0.3, 0.9};
    for (int m = 0; m < 2; m++)
        for (int i = 0; i < 7; i++) {
            drive_def d = control_def(DRIVE_CONTROL_SLIP);
            d.motion = m ? DRIVE_LOAD_TRAVEL : DRIVE_SINK_TRAVEL;
            d.load_ramp = 0.0;
            d.target_load = 100.0;
            d.slip = slips[i];
            d.damping = 2.0 * sqrt(1e6 * d.mass); /* critical on the soil below */
            drive_state s;
            drive_start(&d, &s);
            cm_error err = {0};
            int travel = 0;
            for (int k = 0; k < 3000; k++) {
                /* A stiff linear soil under the load_travel wheel; the
                 * sink_travel wheel sees 100 N at once. */
                double fz = m ? (s.center[2] < 0 ? -1e6 * s.center[2] : 0.0) : 100.0;
                const drive_soil soil = {-50.0, fz, 20.0};
                ENSURE(drive_update(&d, &s, (k + 1) * 1e-4, 1e-4, &soil, &err) == CM_OK);
                if (s.phase == DRIVE_TRAVEL) {
                    travel++;
                    ENSURE_NEAR(drive_realised_slip(&d, &s), d.slip, 1e-12);
                    ENSURE(s.omega == d.omega);
                } else {
                    ENSURE(drive_realised_slip(&d, &s) == 0.0);
                }
            }
            ENSURE_MSG(travel > 1000, "motion %d slip %g: %d travel updates", m, d.slip, travel);
        }
    return 0;
}

/* The rig's damper on the load_travel wheel: on a linear undamped soil
 * (F = k (0 - z)) the load W applied at once gives the damped step response
 *   z(t) = -W/k (1 - e^(-zeta w t) (cos w_d t + zeta / sqrt(1 - zeta^2) sin w_d t)),
 * with the default damper zeta = 0.3 for the reference soil stiffness: the
 * heave decays to 14 % per period, where the undamped wheel keeps heaving. */
static int damper_decays_heave(void)
{
    const double k = DRIVE_SOIL_STIFFNESS_REF, m = 20.0, W = 1000.0;
    const double wn = sqrt(k / m), zeta = DRIVE_DAMPING_RATIO_DEFAULT;
    const double wd = wn * sqrt(1 - zeta * zeta), period = 2 * M_PI / wd, zs = W / k;
    ENSURE_NEAR(drive_default_damping(m), zeta * 2 * sqrt(k * m), 1e-9);
    for (int damped = 2; damped >= 0; damped--) { /* 2: heave damper, 1: plain, 0: none */
        drive_def d = control_def(DRIVE_CONTROL_SLIP);
        d.motion = DRIVE_LOAD_TRAVEL;
        d.mass = m;
        d.damping = damped ? drive_default_damping(m) : 0.0;
        d.damping_window = damped == 2 ? DRIVE_DAMPING_WINDOW_DEFAULT : 0.0; /* 1: the textbook oscillator */
        d.target_load = W;
        d.load_ramp = 0.0;
        d.sink_velocity = 10.0; /* the rig's lowering speed limit out of the way */
        d.center[2] = 0.0;      /* on the surface */
        drive_state s;
        drive_start(&d, &s);
        cm_error err = {0};
        const double dt = 1e-5;
        double max_err = 0, late_amp = 0;
        const int n = (int)(8 * period / dt);
        for (int i = 0; i < n; i++) {
            double z = s.center[2], t = i * dt;
            const drive_soil soil = {0.0, z < 0 ? -k * z : 0.0, 0.0};
            if (damped == 1) {
                double zx = -zs * (1 - exp(-zeta * wn * t) * (cos(wd * t) + zeta / sqrt(1 - zeta * zeta) * sin(wd * t)));
                max_err = fmax(max_err, fabs(z - zx));
            }
            if (t > 7 * period)
                late_amp = fmax(late_amp, fabs(z + zs));
            ENSURE(drive_update(&d, &s, t + dt, dt, &soil, &err) == CM_OK);
        }
        static const char *const names[] = {"undamped", "plain damper", "heave damper"};
        if (damped == 1)
            printf("  plain damper (zeta 0.3): largest deviation from the closed form %.3g of W/k\n", max_err / zs);
        printf("  %s: heave after 7 periods %.3g of W/k\n", names[damped], late_amp / zs);
        if (damped == 2) {
            ENSURE(late_amp < 1e-4 * zs);
            ENSURE(s.phase == DRIVE_TRAVEL);
        } else if (damped) {
            ENSURE(max_err < 0.01 * zs);
            ENSURE(late_amp < 1e-3 * zs); /* 0.14^7 = 1e-6 of the first overshoot */
            ENSURE(s.phase == DRIVE_TRAVEL); /* settled: it travels */
        } else {
            ENSURE(late_amp > 0.9 * zs); /* still heaving by the full static sinkage */
        }
    }
    return 0;
}

/* A wheel sinking at v0 into a soil that carries exactly the load (a
 * plastic soil, F = W): a plain damper brakes it to rest (time constant
 * m / c); the heave damper acts on z' - u, u the mean of z' over the window
 * tau, so m z' + c tau u is conserved and the wheel goes on sinking at
 * m v0 / (m + c tau) with the damper carrying nothing. */
static int damper_spares_steady_sinkage(void)
{
    const double m = 20.0, W = 1000.0, v0 = 0.05, c = drive_default_damping(m);
    for (int windowed = 0; windowed < 2; windowed++) {
        drive_def d = control_def(DRIVE_CONTROL_SLIP);
        d.motion = DRIVE_LOAD_TRAVEL;
        d.mass = m;
        d.damping = c;
        d.damping_window = windowed ? DRIVE_DAMPING_WINDOW_DEFAULT : 0.0;
        d.target_load = W;
        d.load_ramp = 0.0;
        d.sink_velocity = 10.0;
        d.max_sink = 100.0;
        drive_state s;
        drive_start(&d, &s);
        s.velocity[2] = -v0;
        cm_error err = {0};
        const double dt = 1e-5;
        const drive_soil soil = {0.0, W, 0.0};
        for (int i = 0; i < 20000; i++) /* 0.2 s: 12 m / c, 10 windows */
            ENSURE(drive_update(&d, &s, (i + 1) * dt, dt, &soil, &err) == CM_OK);
        double vz = -s.velocity[2], expect = windowed ? m * v0 / (m + c * d.damping_window) : 0.0;
        printf("  %s damper: sinks at %.5f m/s after 0.2 s (closed form %.5f), damper force %.3f N\n",
               windowed ? "heave" : "plain", vz, expect, c * (s.vz_avg - s.velocity[2]));
        ENSURE_NEAR(vz, expect, 0.01 * v0);
        if (windowed) {
            ENSURE(s.phase == DRIVE_SINK); /* still sinking: no travel */
            ENSURE(fabs(c * (s.velocity[2] - s.vz_avg)) < 1e-3 * W);
        }
    }
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
    {"approach_speed", approach_speed},
    {"load_spike_ignored", load_spike_ignored},
    {"load_mode_settles_and_travels", load_mode_settles_and_travels},
    {"fixed_wheel_stays", fixed_wheel_stays},
    {"sinkage_without_load_fails", sinkage_without_load_fails},
    {"steady_detection_and_coverage", steady_detection_and_coverage},
    {"torque_constant_moment", torque_constant_moment},
    {"torque_settles_at_equilibrium", torque_settles_at_equilibrium},
    {"drawbar_control", drawbar_control},
    {"slip_control_realises_slip", slip_control_realises_slip},
    {"slip_ramp_lag", slip_ramp_lag},
    {"damper_decays_heave", damper_decays_heave},
    {"damper_spares_steady_sinkage", damper_spares_steady_sinkage},
};

int main(int argc, char **argv) { return test_main(argc, argv, tests, TEST_COUNT(tests)); }
