/* drive: the wheel's motion in the two phases of the tire test.
 *
 * "sink_travel" (first paper, fig. 13): sinkage at constant velocity until
 * the vertical contact force reaches the target load, then travel at a
 * prescribed slip at that height (position control).
 * "load_travel" (second paper, sec. 3): the wheel's height is free; a vertical
 * load, ramped up from zero over load_ramp so that the wheel settles gently,
 * presses it into the bed (m z'' = F_contact - W - c (z' - u), c the rig's
 * damper, which takes the heave out of the free wheel; u the wheel's mean
 * sinking speed, so that the damper does not carry load while the wheel
 * sinks steadily), lowered no faster than
 * sink_velocity (a test rig sets the wheel down; faster while the wheel
 * carries little load with wheel.approach_velocity); once the contact force
 * carries the load, the wheel travels at the prescribed slip, still free to
 * sink or rise under the same load.
 *
 * Frame: travel along +x, axle along +y, gravity along -z. Rolling forward
 * means angular velocity +omega about +y (the lowest point then moves at
 * v - omega R relative to the centre's velocity v).
 *
 * Slip (PHYSICS_NOTES, Wong): driving s = (omega R - v) / (omega R) in [0, 1);
 * braking s = (omega R - v) / v in (-1, 0), so both stay within [-1, 1].
 *
 * wheel.control decides what is prescribed in the travel phase:
 * "slip" (default): omega and the slip; v follows from s. With
 *   wheel.slip_end the slip is ramped linearly in the distance travelled,
 *   from wheel.slip at the start of the travel to slip_end at
 *   travel_distance: the ramped-slip rig, the whole traction-slip curve in
 *   one run (real single-wheel testers do the same). Its reading lags the
 *   steady curve where the soil needs a distance L to build up its force
 *   (a shear displacement, a contact length): by about K L ds/dx, K the
 *   slope dF/ds (test_drive.slip_ramp_lag), so the ramp must be slow enough
 *   that this is below the accuracy wanted.
 * "torque": the travel velocity v and the axle torque T; omega follows from
 *   the wheel's rotational equation  I omega' = T + M_y  (M_y: the grains'
 *   moment about the axle, negative when they resist a driven wheel);
 * "drawbar": omega and the drawbar load D that the wheel pulls; v follows
 *   from  m v' = F_x - D  (F_x: the grains' force along the travel).
 * Both start the travel at zero slip (omega R = v) and record the slip they
 * realise. The soil's F_x and M_y are noisy (single grain contacts), so they
 * enter the equations averaged over control_window, and the accelerations
 * are limited to max_accel (a spike cannot kick the wheel). The rig's stops:
 * omega >= 0 (a braked wheel locks: slip -1) and at most slip 0.95 under
 * torque; v >= 0 (a stuck wheel: slip 1) and at least slip -0.95 under a
 * drawbar load. */
#ifndef FEM_DRIVE_H
#define FEM_DRIVE_H

#include "error.h"
#include "scene.h"

typedef enum drive_phase { DRIVE_SINK = 0, DRIVE_TRAVEL = 1, DRIVE_DONE = 2, DRIVE_FIXED = 3 } drive_phase;

/* wheel.motion: the test's two phases, or a wheel held still (verification
 * scenes: grains dropped on a fixed tire or block). */
typedef enum drive_motion { DRIVE_SINK_TRAVEL = 0, DRIVE_HOLD = 1, DRIVE_LOAD_TRAVEL = 2 } drive_motion;

/* wheel.control: what the travel phase prescribes (see above). */
typedef enum drive_control { DRIVE_CONTROL_SLIP = 0, DRIVE_CONTROL_TORQUE = 1, DRIVE_CONTROL_DRAWBAR = 2 } drive_control;

/* The largest braking slip magnitude the rig's stops allow (the range of wheel.slip). */
#define DRIVE_SLIP_LIMIT 0.95

/* Vertical stiffness of the default bed under the wheel, measured: the free
 * 20 kg wheel of scenes/default.cfg heaves at about 22 Hz on it while it
 * settles, before it turns (the load oscillates with a period of 45-48 ms),
 * k = m (2 pi f)^2. The default rig damper is a fraction of critical on it. */
#define DRIVE_SOIL_STIFFNESS_REF 3.8e5     /* N/m */
#define DRIVE_DAMPING_RATIO_DEFAULT 0.3
/* s: the heave damper's window, about half a period of that heave: at 22 Hz
 * the damper keeps 88 % of its effect (see drive_def.damping_window). */
#define DRIVE_DAMPING_WINDOW_DEFAULT 0.02

typedef struct drive_def {
    drive_motion motion;     /* "sink_travel" (default), "load_travel" or "fixed" */
    double center[3];        /* m, initial wheel centre (world) */
    double start_gap;        /* m, > 0: lower the wheel to this gap above the bed
                                surface reported by the DEM before sinking; 0 = keep centre */
    double radius;           /* m, rolling radius R_T used for slip (tire outer radius) */
    double sink_velocity;    /* m/s, downward speed in the sinkage phase (table 1: 0.1) */
    double approach_velocity; /* m/s: the rig's lowering speed while the wheel carries no load,
                                falling linearly with the averaged load to sink_velocity at
                                approach_load (drive_sink_speed); <= sink_velocity (default): off */
    double approach_load;    /* (0, 1]: the fraction of target_load at which the approach ends */
    double target_load;      /* N, vertical contact force that ends the sinkage phase */
    double load_window;      /* s, time constant of the moving average of the load that
                                is compared with target_load (DEM forces are noisy) */
    double max_sink;         /* m, fail if the load is not reached after sinking this far */
    double slip;             /* (-1, 1): the prescribed slip in the travel phase (its start, with a ramp) */
    double slip_end;         /* (-1, 1): the slip at travel_distance (wheel.slip_end; slip control) */
    int slip_ramp;           /* 1: the slip is ramped from slip to slip_end over the travel */
    double omega;            /* rad/s, > 0: wheel angular speed in the travel phase */
    double travel_distance;  /* m, the travel phase ends after this distance */
    drive_control control;   /* "slip" (default), "torque" or "drawbar" */
    /* torque control: */
    double velocity;         /* m/s, > 0: the prescribed travel velocity */
    double torque;           /* N m, axle torque about +y: > 0 drives, < 0 brakes */
    double inertia;          /* kg m^2, the wheel's moment of inertia about the axle
                                (read from the scene: 0 = the tire mesh's, drive_resolve) */
    /* drawbar control: */
    double drawbar;          /* N, the pull the wheel carries (force on the axle along -x) */
    /* torque and drawbar control: */
    double control_window;   /* s, time constant of the moving average of F_x and M_y fed
                                to the equations of motion */
    double max_accel;        /* m/s^2, limit of |v'| (drawbar) and of R |omega'| (torque) */
    /* load_travel, and drawbar control: */
    double mass;             /* kg, mass of the wheel in its equations of motion
                                (read from the scene: 0 = the tire mesh's, drive_resolve) */
    /* load_travel only: */
    double damping;          /* N s/m, the rig's vertical damper: m z'' = F - W - c (z' - u)
                                (read from the scene: < 0 = default, drive_resolve) */
    double damping_window;   /* s, u: the wheel's vertical velocity averaged over this
                                window, so that the damper takes the heave and leaves
                                a steady sinkage to the load (0: u = 0, a plain damper) */
    double load_ramp;        /* s, the load grows linearly from 0 to target_load over this time */
    double settle_tolerance; /* the travel starts when the averaged contact force is within
                                this fraction of the load (after the ramp) ... */
    double settle_speed;     /* m/s, ... and the wheel sinks slower than this */
} drive_def;

/* Defaults usable as they are (mass 20 kg, inertia 1 kg m^2, no damper). */
drive_def drive_def_default(void);
/* Reads the `wheel = { ... }` section. Leaves mass and inertia 0 and damping
 * negative where the scene does not give them: drive_resolve fills them. */
int drive_config_read(cm_scene *s, drive_def *d, cm_error *err);
/* Fills what the scene left open: mass and inertia from the tire mesh
 * (kg, kg m^2 about the axle), the damper at DRIVE_DAMPING_RATIO_DEFAULT of
 * critical for that mass on DRIVE_SOIL_STIFFNESS_REF. */
void drive_resolve(drive_def *d, double mesh_mass, double mesh_inertia);
/* The default damper for a wheel of mass m [kg]: N s/m. */
double drive_default_damping(double mass);

/* What the grains put on the tire over the last interval, world frame. */
typedef struct drive_soil {
    double fx;  /* N, along the travel (+x) */
    double fz;  /* N, vertical, upward on the tire: the load it carries */
    double my;  /* N m, moment about the axle (+y) through the wheel centre */
} drive_soil;

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
    double fx_avg;      /* N, moving average of the soil's F_x over control_window */
    double my_avg;      /* N m, moving average of the soil's M_y over control_window */
    double vz_avg;      /* m/s, moving average of the vertical velocity over damping_window */
    long rate_limited;  /* exchanges at which max_accel or a stop limited the motion */
} drive_state;

void drive_start(const drive_def *d, drive_state *s);

/* Travel velocity for the prescribed slip: v = omega R (1 - s) when driving,
 * v = omega R / (1 + s) when braking. */
double drive_travel_velocity(double omega, double radius, double slip);
/* The slip actually realised by v and omega (same definitions). */
double drive_slip(double omega, double radius, double v);
/* The slip slip control prescribes after `travelled` m of travel: wheel.slip,
 * or with a ramp linear from slip to slip_end over travel_distance. */
double drive_prescribed_slip(const drive_def *d, double travelled);
/* The slip of the motion held for the next interval (0 outside the travel). */
double drive_realised_slip(const drive_def *d, const drive_state *s);

/* The rig's lowering speed limit in the sinkage phase, m/s (> 0): a rig sets
 * a wheel down quickly and slows as it takes the load,
 *   v = sink_velocity + (approach_velocity - sink_velocity) max(0, 1 - L / (approach_load W)),
 * L the averaged contact force, W the target load. Without load the wheel
 * comes down at approach_velocity; from approach_load W on, at
 * sink_velocity, as the paper's rig (table 1); never below sink_velocity
 * (an approach_velocity at or below it is no approach). A function of the
 * state, not a switch, so a noisy load only modulates the speed and a
 * checkpoint needs nothing more. */
double drive_sink_speed(const drive_def *d, const drive_state *s);

/* Advances the kinematic state by dt at the motion held during the last
 * interval, then decides the motion for the next one from the soil's force
 * and moment measured over the last one. Returns CM_ERR_NUMERIC when the
 * sinkage phase went max_sink down without reaching the load. */
int drive_update(const drive_def *d, drive_state *s, double time, double dt, const drive_soil *soil,
                 cm_error *err);

#endif
