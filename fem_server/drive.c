#include "drive.h"

#include <math.h>
#include <string.h>

drive_def drive_def_default(void)
{
    drive_def d;
    memset(&d, 0, sizeof d);
    d.radius = 0.272;
    d.sink_velocity = 0.1;
    d.approach_velocity = 0.1;
    d.approach_load = 0.5;
    d.target_load = 5000.0;
    d.load_window = 0.005;
    d.max_sink = 0.2;
    d.slip = 0.05;
    d.omega = 1.8;
    d.travel_distance = 1.0;
    d.mass = 20.0;
    d.damping_window = DRIVE_DAMPING_WINDOW_DEFAULT;
    d.inertia = 1.0;
    d.velocity = 0.5;
    d.control_window = 0.002;
    d.max_accel = 5.0;
    d.load_ramp = 0.1;
    d.settle_tolerance = 0.05;
    d.settle_speed = 0.01;
    return d;
}

int drive_config_read(cm_scene *s, drive_def *d, cm_error *err)
{
    static const char *const motions[] = {"sink_travel", "fixed", "load_travel", NULL};
    static const char *const controls[] = {"slip", "torque", "drawbar", NULL};
    int motion = (int)d->motion, control = (int)d->control, rc;
    if ((rc = cm_scene_choice_opt(s, "wheel.motion", motions, motion, &motion, err)))
        return rc;
    d->motion = (drive_motion)motion;
    if (d->motion == DRIVE_HOLD) {
        /* Only the placement matters; the radius is still used for sinkage. */
        if ((rc = cm_scene_doubles(s, "wheel.center", 3, -1e3, 1e3, d->center, err)) ||
            (rc = cm_scene_double_opt(s, "wheel.radius", 1e-3, 10.0, d->radius, &d->radius, err)))
            return rc;
        return CM_OK;
    }
    if ((rc = cm_scene_choice_opt(s, "wheel.control", controls, control, &control, err)))
        return rc;
    d->control = (drive_control)control;
    if ((rc = cm_scene_doubles(s, "wheel.center", 3, -1e3, 1e3, d->center, err)) ||
        (rc = cm_scene_double_opt(s, "wheel.start_gap", 0.0, 1.0, d->start_gap, &d->start_gap, err)) ||
        (rc = cm_scene_double(s, "wheel.radius", 1e-3, 10.0, &d->radius, err)) ||
        (rc = cm_scene_double_opt(s, "wheel.sink_velocity", 1e-6, 10.0, d->sink_velocity, &d->sink_velocity, err)) ||
        (rc = cm_scene_double_opt(s, "wheel.approach_velocity", 1e-6, 10.0, d->sink_velocity,
                                  &d->approach_velocity, err)) ||
        (rc = cm_scene_double_opt(s, "wheel.approach_load", 1e-3, 1.0, d->approach_load, &d->approach_load, err)) ||
        (rc = cm_scene_double(s, "wheel.target_load", 0.0, 1e7, &d->target_load, err)) ||
        (rc = cm_scene_double_opt(s, "wheel.load_window", 0.0, 10.0, d->load_window, &d->load_window, err)) ||
        (rc = cm_scene_double_opt(s, "wheel.max_sink", 1e-4, 10.0, d->max_sink, &d->max_sink, err)) ||
        (rc = cm_scene_double_opt(s, "wheel.travel_distance", 0.0, 1e3, d->travel_distance, &d->travel_distance,
                                  err)))
        return rc;
    /* What the control prescribes; the keys of the other controls are
     * refused as unused (a scene that sets both slip and torque is wrong). */
    if (d->control == DRIVE_CONTROL_SLIP &&
        ((rc = cm_scene_double_opt(s, "wheel.slip", -DRIVE_SLIP_LIMIT, DRIVE_SLIP_LIMIT, d->slip, &d->slip, err)) ||
         (rc = cm_scene_double_opt(s, "wheel.slip_end", -DRIVE_SLIP_LIMIT, DRIVE_SLIP_LIMIT, NAN, &d->slip_end,
                                   err))))
        return rc;
    d->slip_ramp = d->control == DRIVE_CONTROL_SLIP && !isnan(d->slip_end);
    if (!d->slip_ramp)
        d->slip_end = d->slip;
    else if (!(d->travel_distance > 0))
        return cm_fail(err, CM_ERR_RANGE, "wheel.slip_end ramps the slip over wheel.travel_distance, which is %g: "
                       "give the travel a length", d->travel_distance);
    if (d->control != DRIVE_CONTROL_TORQUE &&
        (rc = cm_scene_double_opt(s, "wheel.omega", 1e-6, 1e3, d->omega, &d->omega, err)))
        return rc;
    if (d->control == DRIVE_CONTROL_TORQUE &&
        ((rc = cm_scene_double(s, "wheel.velocity", 1e-6, 100.0, &d->velocity, err)) ||
         (rc = cm_scene_double(s, "wheel.torque", -1e6, 1e6, &d->torque, err)) ||
         (rc = cm_scene_double_opt(s, "wheel.inertia", 1e-6, 1e4, 0.0, &d->inertia, err))))
        return rc;
    if (d->control == DRIVE_CONTROL_DRAWBAR &&
        (rc = cm_scene_double(s, "wheel.drawbar", -1e7, 1e7, &d->drawbar, err)))
        return rc;
    if (d->control != DRIVE_CONTROL_SLIP &&
        ((rc = cm_scene_double_opt(s, "wheel.control_window", 0.0, 10.0, d->control_window, &d->control_window,
                                   err)) ||
         (rc = cm_scene_double_opt(s, "wheel.max_accel", 1e-6, 1e4, d->max_accel, &d->max_accel, err))))
        return rc;
    if ((d->motion == DRIVE_LOAD_TRAVEL || d->control == DRIVE_CONTROL_DRAWBAR) &&
        (rc = cm_scene_double_opt(s, "wheel.mass", 1e-3, 1e5, 0.0, &d->mass, err)))
        return rc;
    if (d->motion == DRIVE_LOAD_TRAVEL &&
        ((rc = cm_scene_double_opt(s, "wheel.load_ramp", 0.0, 100.0, d->load_ramp, &d->load_ramp, err)) ||
         (rc = cm_scene_double_opt(s, "wheel.settle_tolerance", 1e-4, 1.0, d->settle_tolerance,
                                   &d->settle_tolerance, err)) ||
         (rc = cm_scene_double_opt(s, "wheel.settle_speed", 1e-6, 10.0, d->settle_speed, &d->settle_speed, err)) ||
         (rc = cm_scene_double_opt(s, "wheel.damping", 0.0, 1e7, -1.0, &d->damping, err)) ||
         (rc = cm_scene_double_opt(s, "wheel.damping_window", 0.0, 10.0, DRIVE_DAMPING_WINDOW_DEFAULT,
                                   &d->damping_window, err))))
        return rc;
    return CM_OK;
}

double drive_default_damping(double mass)
{
    /* c = zeta 2 sqrt(k m): zeta = 0.3 of critical takes a heave down to
     * exp(-2 pi zeta / sqrt(1 - zeta^2)) = 14 % in one period, as a test
     * rig's damper, without holding up the slow sinkage (at 10 mm/s the
     * 20 kg wheel's damper carries 17 N of a 400 N load). */
    return DRIVE_DAMPING_RATIO_DEFAULT * 2.0 * sqrt(DRIVE_SOIL_STIFFNESS_REF * mass);
}

void drive_resolve(drive_def *d, double mesh_mass, double mesh_inertia)
{
    if (!(d->mass > 0) && mesh_mass > 0)
        d->mass = mesh_mass;
    if (!(d->inertia > 0) && mesh_inertia > 0)
        d->inertia = mesh_inertia;
    if (d->damping < 0)
        d->damping = drive_default_damping(d->mass);
}

void drive_start(const drive_def *d, drive_state *s)
{
    memset(s, 0, sizeof *s);
    memcpy(s->center, d->center, sizeof s->center);
    s->phase = d->motion == DRIVE_HOLD ? DRIVE_FIXED : DRIVE_SINK;
}

double drive_travel_velocity(double omega, double radius, double slip)
{
    double wr = omega * radius;
    return slip >= 0 ? wr * (1.0 - slip) : wr / (1.0 + slip);
}

double drive_slip(double omega, double radius, double v)
{
    double wr = omega * radius;
    if (v <= wr)
        return wr > 0 ? (wr - v) / wr : 0.0;
    return v > 0 ? (wr - v) / v : 0.0;
}

double drive_prescribed_slip(const drive_def *d, double travelled)
{
    if (!d->slip_ramp)
        return d->slip;
    double f = travelled / d->travel_distance;
    f = f < 0 ? 0 : f > 1 ? 1 : f;
    return d->slip + (d->slip_end - d->slip) * f;
}

double drive_realised_slip(const drive_def *d, const drive_state *s)
{
    return s->phase == DRIVE_TRAVEL ? drive_slip(s->omega, d->radius, s->velocity[0]) : 0.0;
}

/* The applied vertical load at time t: ramped up from zero, so that the
 * wheel is set down gently (no impact disturbing the settled bed). */
static double applied_load(const drive_def *d, double time)
{
    double ramp = d->load_ramp > 0 ? time / d->load_ramp : 1.0;
    return d->target_load * (ramp < 1.0 ? (ramp > 0.0 ? ramp : 0.0) : 1.0);
}

/* Moves the state by the motion held during the interval just computed,
 * and folds the interval's soil force into its moving averages (over about
 * load_window and control_window, so that one grain's spike neither ends a
 * phase early nor kicks the wheel). */
static void advance_interval(const drive_def *d, drive_state *s, double dt, const drive_soil *soil)
{
    for (int k = 0; k < 3; k++)
        s->center[k] += s->velocity[k] * dt;
    s->angle += s->omega * dt;
    if (s->phase == DRIVE_SINK)
        s->sunk -= s->velocity[2] * dt;
    else if (s->phase == DRIVE_TRAVEL)
        s->travelled += s->velocity[0] * dt;
    double blend = d->load_window > dt ? dt / d->load_window : 1.0;
    s->load_avg += blend * (soil->fz - s->load_avg);
    blend = d->control_window > dt ? dt / d->control_window : 1.0;
    s->fx_avg += blend * (soil->fx - s->fx_avg);
    s->my_avg += blend * (soil->my - s->my_avg);
}

/* Phase changes from the averaged load; fails after max_sink. */
static int change_phase(const drive_def *d, drive_state *s, double time, cm_error *err)
{
    if (s->phase == DRIVE_SINK && d->motion == DRIVE_LOAD_TRAVEL) {
        double W = applied_load(d, time);
        if (time >= d->load_ramp && fabs(s->load_avg - W) <= d->settle_tolerance * W &&
            fabs(s->velocity[2]) < d->settle_speed) {
            s->phase = DRIVE_TRAVEL;
            s->t_phase = time;
        } else if (s->sunk > d->max_sink) {
            return cm_fail(err, CM_ERR_NUMERIC,
                           "wheel sank %.3f m (wheel.max_sink) under wheel.target_load = %g N without the contact "
                           "force carrying it (averaged %g N)",
                           s->sunk, d->target_load, s->load_avg);
        }
    } else if (s->phase == DRIVE_SINK) {
        if (s->load_avg >= d->target_load) {
            s->phase = DRIVE_TRAVEL;
            s->t_phase = time;
        } else if (s->sunk > d->max_sink) {
            return cm_fail(err, CM_ERR_NUMERIC,
                           "wheel sank %.3f m (wheel.max_sink) without reaching wheel.target_load = %g N (load %g N)",
                           s->sunk, d->target_load, s->load_avg);
        }
    } else if (s->phase == DRIVE_TRAVEL && s->travelled >= d->travel_distance) {
        s->phase = DRIVE_DONE;
        s->t_phase = time;
    }
    return CM_OK;
}

double drive_sink_speed(const drive_def *d, const drive_state *s)
{
    if (!(d->approach_velocity > d->sink_velocity)) /* no approach */
        return d->sink_velocity;
    double unloaded = 1.0 - s->load_avg / (d->approach_load * d->target_load);
    if (!(unloaded > 0)) /* also a target load of 0 */
        return d->sink_velocity;
    return d->sink_velocity + (d->approach_velocity - d->sink_velocity) * (unloaded < 1.0 ? unloaded : 1.0);
}

/* x limited to [lo, hi]; counts the exchanges at which a limit acted. */
static double limit(double x, double lo, double hi, int *hit)
{
    if (x < lo || x > hi) {
        *hit = 1;
        return x < lo ? lo : hi;
    }
    return x;
}

/* omega and v for the next travel interval. The first one starts at zero
 * slip; then torque and drawbar control integrate their equation of motion
 * (explicit Euler on the averaged soil force of the intervals done). */
static void travel_motion(const drive_def *d, drive_state *s, double dt, int entering)
{
    int hit = 0;
    switch (d->control) {
    case DRIVE_CONTROL_SLIP:
        s->omega = d->omega;
        s->velocity[0] = drive_travel_velocity(d->omega, d->radius, drive_prescribed_slip(d, s->travelled));
        return;
    case DRIVE_CONTROL_TORQUE: {
        s->velocity[0] = d->velocity;
        if (entering) {
            s->omega = d->velocity / d->radius;
            return;
        }
        /* I omega' = T + M_y; the stops: a braked wheel locks (omega = 0,
         * slip -1) and the driven one spins at most to slip DRIVE_SLIP_LIMIT. */
        double a_max = d->max_accel / d->radius;
        double a = limit((d->torque + s->my_avg) / d->inertia, -a_max, a_max, &hit);
        s->omega = limit(s->omega + a * dt, 0.0, d->velocity / (d->radius * (1.0 - DRIVE_SLIP_LIMIT)), &hit);
        break;
    }
    case DRIVE_CONTROL_DRAWBAR: {
        s->omega = d->omega;
        if (entering) {
            s->velocity[0] = d->omega * d->radius;
            return;
        }
        /* m v' = F_x - D; the stops: a stuck wheel stands (v = 0, slip 1)
         * and a pushed one skids at most to slip -DRIVE_SLIP_LIMIT. */
        double a = limit((s->fx_avg - d->drawbar) / d->mass, -d->max_accel, d->max_accel, &hit);
        s->velocity[0] = limit(s->velocity[0] + a * dt, 0.0, d->omega * d->radius / (1.0 - DRIVE_SLIP_LIMIT), &hit);
        break;
    }
    }
    s->rate_limited += hit;
}

int drive_update(const drive_def *d, drive_state *s, double time, double dt, const drive_soil *soil,
                 cm_error *err)
{
    if (s->phase == DRIVE_FIXED)
        return CM_OK;
    /* 1. Move; 2. phase changes from the averaged load. */
    advance_interval(d, s, dt, soil);
    drive_phase before = s->phase;
    int rc = change_phase(d, s, time, err);
    if (rc)
        return rc;

    /* 3. The motion for the next interval. Vertical: held height in
     * sink_travel's travel; with load_travel m z'' = F_contact - W(t) -
     * c (z' - u), explicit Euler on the contact force of the interval just
     * done, the damper implicit (stable for any c dt / m). u, the mean of z'
     * over damping_window, makes it a heave damper: a sinkage at a steady
     * rate under the load is not braked (a plain damper would carry c z' of
     * the load while the wheel sinks, 20 % of it at the default scene's
     * 5 cm/s at the start of the travel). */
    double vz = 0.0;
    if (d->motion == DRIVE_LOAD_TRAVEL) {
        double W = applied_load(d, time), cdm = d->damping * dt / d->mass;
        vz = (s->velocity[2] + (soil->fz - W) / d->mass * dt + cdm * s->vz_avg) / (1.0 + cdm);
        const double v_max = drive_sink_speed(d, s);
        if (s->phase == DRIVE_SINK && vz < -v_max)
            vz = -v_max; /* the rig lowers the wheel no faster than this */
        if (d->damping_window > 0)
            s->vz_avg += (d->damping_window > dt ? dt / d->damping_window : 1.0) * (vz - s->vz_avg);
    } else if (s->phase == DRIVE_SINK) {
        vz = -drive_sink_speed(d, s);
    }
    if (s->phase == DRIVE_TRAVEL) {
        s->velocity[1] = 0.0;
        s->velocity[2] = vz;
        travel_motion(d, s, dt, before != DRIVE_TRAVEL);
    } else {
        memset(s->velocity, 0, sizeof s->velocity);
        s->omega = 0.0;
        if (s->phase == DRIVE_SINK)
            s->velocity[2] = vz;
    }
    return CM_OK;
}
