/* drive: the wheel's motion in the two phases of the tire test.
 *
 * "sink_travel" (first paper, fig. 13): sinkage at constant velocity until
 * the vertical contact force reaches the target load, then travel at a
 * prescribed slip at that height (position control).
 * "load_travel" (second paper, sec. 3): the wheel's height is free; a vertical
 * load, ramped up from zero over load_ramp so that the wheel settles gently,
 * presses it into the bed (m z'' = F_contact - W), lowered no faster than
 * sink_velocity (a test rig sets the wheel down); once the contact force
 * carries the load, the wheel travels at the prescribed slip, still free to
 * sink or rise under the same load.
 *
 * Frame: travel along +x, axle along +y, gravity along -z. Rolling forward
 * means angular velocity +omega about +y (the lowest point then moves at
 * v - omega R relative to the centre's velocity v).
 *
 * Slip (PHYSICS_NOTES, Wong): driving s = (omega R - v) / (omega R) in [0, 1);
 * braking s = (omega R - v) / v in (-1, 0), so both stay within [-1, 1].
 * Here omega is prescribed and v follows from s. */
#ifndef FEM_DRIVE_H
#define FEM_DRIVE_H

#include "error.h"
#include "scene.h"

typedef enum drive_phase { DRIVE_SINK = 0, DRIVE_TRAVEL = 1, DRIVE_DONE = 2, DRIVE_FIXED = 3 } drive_phase;

/* wheel.motion: the test's two phases, or a wheel held still (verification
 * scenes: grains dropped on a fixed tire or block). */
typedef enum drive_motion { DRIVE_SINK_TRAVEL = 0, DRIVE_HOLD = 1, DRIVE_LOAD_TRAVEL = 2 } drive_motion;

typedef struct drive_def {
    drive_motion motion;     /* "sink_travel" (default), "load_travel" or "fixed" */
    double center[3];        /* m, initial wheel centre (world) */
    double start_gap;        /* m, > 0: lower the wheel to this gap above the bed
                                surface reported by the DEM before sinking; 0 = keep centre */
    double radius;           /* m, rolling radius R_T used for slip (tire outer radius) */
    double sink_velocity;    /* m/s, downward speed in the sinkage phase (table 1: 0.1) */
    double target_load;      /* N, vertical contact force that ends the sinkage phase */
    double load_window;      /* s, time constant of the moving average of the load that
                                is compared with target_load (DEM forces are noisy) */
    double max_sink;         /* m, fail if the load is not reached after sinking this far */
    double slip;             /* (-1, 1): the prescribed slip in the travel phase */
    double omega;            /* rad/s, > 0: wheel angular speed in the travel phase */
    double travel_distance;  /* m, the travel phase ends after this distance */
    /* load_travel only: */
    double mass;             /* kg, mass of the wheel in the vertical equation of motion */
    double load_ramp;        /* s, the load grows linearly from 0 to target_load over this time */
    double settle_tolerance; /* the travel starts when the averaged contact force is within
                                this fraction of the load (after the ramp) ... */
    double settle_speed;     /* m/s, ... and the wheel sinks slower than this */
} drive_def;

drive_def drive_def_default(void);
/* Reads the `wheel = { ... }` section. */
int drive_config_read(cm_scene *s, drive_def *d, cm_error *err);

typedef struct drive_state {
    drive_phase phase;
    double center[3];   /* m */
    double velocity[3]; /* m/s, held during the next interval */
    double omega;       /* rad/s about +y, held during the next interval */
    double angle;       /* rad, accumulated rotation */
    double sunk;        /* m, distance moved down in the sinkage phase */
    double load_avg;    /* N, exponential moving average of the vertical contact force */
    double travelled;   /* m, distance moved along x in the travel phase */
    double t_phase;     /* s, when the current phase began */
} drive_state;

void drive_start(const drive_def *d, drive_state *s);

/* Travel velocity for the prescribed slip: v = omega R (1 - s) when driving,
 * v = omega R / (1 + s) when braking. */
double drive_travel_velocity(double omega, double radius, double slip);
/* The slip actually realised by v and omega (same definitions). */
double drive_slip(double omega, double radius, double v);

/* Decides the motion for the next interval from the vertical contact force
 * (N, upward on the tire) measured over the last one, and advances the
 * kinematic state by dt at the motion held during it. Returns CM_ERR_NUMERIC
 * when the sinkage phase went max_sink down without reaching the load. */
int drive_update(const drive_def *d, drive_state *s, double time, double dt, double load, cm_error *err);

#endif
