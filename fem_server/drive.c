#include "drive.h"

#include <math.h>
#include <string.h>

drive_def drive_def_default(void)
{
    drive_def d;
    memset(&d, 0, sizeof d);
    d.radius = 0.272;
    d.sink_velocity = 0.1;
    d.target_load = 5000.0;
    d.load_window = 0.005;
    d.max_sink = 0.2;
    d.slip = 0.05;
    d.omega = 1.8;
    d.travel_distance = 1.0;
    d.mass = 20.0;
    d.load_ramp = 0.1;
    d.settle_tolerance = 0.05;
    d.settle_speed = 0.01;
    return d;
}

int drive_config_read(cm_scene *s, drive_def *d, cm_error *err)
{
    static const char *const motions[] = {"sink_travel", "fixed", "load_travel", NULL};
    int motion = (int)d->motion, rc;
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
    if ((rc = cm_scene_doubles(s, "wheel.center", 3, -1e3, 1e3, d->center, err)) ||
        (rc = cm_scene_double_opt(s, "wheel.start_gap", 0.0, 1.0, d->start_gap, &d->start_gap, err)) ||
        (rc = cm_scene_double(s, "wheel.radius", 1e-3, 10.0, &d->radius, err)) ||
        (rc = cm_scene_double_opt(s, "wheel.sink_velocity", 1e-6, 10.0, d->sink_velocity, &d->sink_velocity, err)) ||
        (rc = cm_scene_double(s, "wheel.target_load", 0.0, 1e7, &d->target_load, err)) ||
        (rc = cm_scene_double_opt(s, "wheel.load_window", 0.0, 10.0, d->load_window, &d->load_window, err)) ||
        (rc = cm_scene_double_opt(s, "wheel.max_sink", 1e-4, 10.0, d->max_sink, &d->max_sink, err)) ||
        (rc = cm_scene_double_opt(s, "wheel.slip", -0.95, 0.95, d->slip, &d->slip, err)) ||
        (rc = cm_scene_double_opt(s, "wheel.omega", 1e-6, 1e3, d->omega, &d->omega, err)) ||
        (rc = cm_scene_double_opt(s, "wheel.travel_distance", 0.0, 1e3, d->travel_distance, &d->travel_distance,
                                  err)))
        return rc;
    if (d->motion == DRIVE_LOAD_TRAVEL &&
        ((rc = cm_scene_double_opt(s, "wheel.mass", 1e-3, 1e5, d->mass, &d->mass, err)) ||
         (rc = cm_scene_double_opt(s, "wheel.load_ramp", 0.0, 100.0, d->load_ramp, &d->load_ramp, err)) ||
         (rc = cm_scene_double_opt(s, "wheel.settle_tolerance", 1e-4, 1.0, d->settle_tolerance,
                                   &d->settle_tolerance, err)) ||
         (rc = cm_scene_double_opt(s, "wheel.settle_speed", 1e-6, 10.0, d->settle_speed, &d->settle_speed, err))))
        return rc;
    return CM_OK;
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

/* The applied vertical load at time t: ramped up from zero, so that the
 * wheel is set down gently (no impact disturbing the settled bed). */
static double applied_load(const drive_def *d, double time)
{
    double ramp = d->load_ramp > 0 ? time / d->load_ramp : 1.0;
    return d->target_load * (ramp < 1.0 ? (ramp > 0.0 ? ramp : 0.0) : 1.0);
}

/* Moves the state by the motion held during the interval just computed,
 * and folds the interval's load into its moving average (over about
 * load_window, so that one grain's spike does not end a phase early). */
static void advance_interval(const drive_def *d, drive_state *s, double dt, double load)
{
    for (int k = 0; k < 3; k++)
        s->center[k] += s->velocity[k] * dt;
    s->angle += s->omega * dt;
    if (s->phase == DRIVE_SINK)
        s->sunk -= s->velocity[2] * dt;
    else if (s->phase == DRIVE_TRAVEL)
        s->travelled += s->velocity[0] * dt;
    double blend = d->load_window > dt ? dt / d->load_window : 1.0;
    s->load_avg += blend * (load - s->load_avg);
}

/* load_travel: m z'' = F_contact - W(t), integrated with symplectic Euler
 * over each interval (the contact force is that of the interval just done). */
static int drive_update_load(const drive_def *d, drive_state *s, double time, double dt, double load, cm_error *err)
{
    advance_interval(d, s, dt, load);
    double W = applied_load(d, time);

    if (s->phase == DRIVE_SINK) {
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
    } else if (s->phase == DRIVE_TRAVEL && s->travelled >= d->travel_distance) {
        s->phase = DRIVE_DONE;
        s->t_phase = time;
    }
    double vz = s->velocity[2] + (load - W) / d->mass * dt;
    if (s->phase == DRIVE_SINK && vz < -d->sink_velocity)
        vz = -d->sink_velocity; /* the rig lowers the wheel no faster than this */
    memset(s->velocity, 0, sizeof s->velocity);
    s->omega = 0.0;
    if (s->phase == DRIVE_DONE)
        return CM_OK;
    s->velocity[2] = vz;
    if (s->phase == DRIVE_TRAVEL) {
        s->omega = d->omega;
        s->velocity[0] = drive_travel_velocity(d->omega, d->radius, d->slip);
    }
    return CM_OK;
}

int drive_update(const drive_def *d, drive_state *s, double time, double dt, double load, cm_error *err)
{
    if (s->phase == DRIVE_FIXED)
        return CM_OK;
    if (d->motion == DRIVE_LOAD_TRAVEL)
        return drive_update_load(d, s, time, dt, load, err);
    /* 1. Move; 2. phase changes from the averaged load. */
    advance_interval(d, s, dt, load);
    if (s->phase == DRIVE_SINK && s->load_avg >= d->target_load) {
        s->phase = DRIVE_TRAVEL;
        s->t_phase = time;
    } else if (s->phase == DRIVE_SINK && s->sunk > d->max_sink) {
        return cm_fail(err, CM_ERR_NUMERIC,
                       "wheel sank %.3f m (wheel.max_sink) without reaching wheel.target_load = %g N (load %g N)",
                       s->sunk, d->target_load, s->load_avg);
    } else if (s->phase == DRIVE_TRAVEL && s->travelled >= d->travel_distance) {
        s->phase = DRIVE_DONE;
        s->t_phase = time;
    }

    /* 3. The motion for the next interval. */
    memset(s->velocity, 0, sizeof s->velocity);
    s->omega = 0.0;
    if (s->phase == DRIVE_SINK) {
        s->velocity[2] = -d->sink_velocity;
    } else if (s->phase == DRIVE_TRAVEL) {
        s->omega = d->omega;
        s->velocity[0] = drive_travel_velocity(d->omega, d->radius, d->slip);
    }
    return CM_OK;
}
