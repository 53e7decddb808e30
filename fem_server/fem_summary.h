/* fem_summary: the traction summary of a run, the one source of its numbers.
 *
 * Reads the recorded series (wheel.h5:/series, every exchange; resumed runs
 * included), takes the travel phase, finds its steady part (the latest
 * MSER-5 start of T_H, T_R, T_P, the load and the sinkage, and of the slip
 * when it is an outcome), cuts it to whole lug periods of the wheel angle,
 * and writes for every quantity the mean, its 95 % interval (batches longer
 * than the measured autocorrelation time), the time scatter, extremes and
 * correlation time:
 *   wheel.h5:/summary              attributes (steady part, load check)
 *   wheel.h5:/summary/quantities   one row per quantity: mean, half_width,
 *                                  sd, min, max, tau_s, batches, short_series
 *                                  (names in the attribute "names")
 *   wheel.h5:/summary/lug_profile  the lug-periodic signal: per phase bin
 *                                  (rows), phase then T_H, T_R, T_P, load,
 *                                  sinkage
 *   wheel.h5:/summary/convergence  how the means and intervals converge with
 *                                  travel: over the first 1/4, 1/2, 3/4 and all
 *                                  of the steady part, travel (m) then mean and
 *                                  half-width of T_H, T_R, T_P, load, sinkage
 *                                  (the half-width shrinks as 1/sqrt(travel)
 *                                  once batches are long enough: choose the
 *                                  travel a target needs from it)
 *   wheel.h5:/summary attributes   also the set-down: set_down_time and
 *                                  set_down_sinkage, the travel's first row
 *                                  (the static sinkage under the load)
 *   summary.json                   the same, for scripts (bench/post)
 * Quantities: T_H, T_R, T_P (N), load W = Fz (N), sinkage (m), slip, and per
 * actual load the coefficients T_H/W, T_R/W, T_P/W (ratio of the means,
 * interval by linearisation: batch means of (T - c W)/mean W),
 * sinkage/R, T_H_torque = -M_y / R (the first paper's gross traction
 * from the axle torque), and the soil's force Fx along the travel and
 * moment My about the axle (under drawbar or torque control they balance
 * the prescribed load). The run warns, naming the cause, when the steady load is more
 * than 10 % from target_load, when the sinkage is still drifting over the
 * averaged part, and when the travel stopped short of travel_distance
 * (interrupted, or run.end_time came first: the statistics cover only the
 * part travelled; summary.json's travel_completed). */
#ifndef FEM_SUMMARY_H
#define FEM_SUMMARY_H

#include <stdint.h>

#include "error.h"

typedef struct fem_summary_def {
    const char *out_dir;   /* holds wheel.h5 (closed); summary.json is written there */
    const char *scene;     /* scene file, recorded */
    int control;           /* drive_control */
    int motion;            /* drive_motion */
    double target_load;    /* N */
    double radius;         /* m, rolling radius (sinkage / R) */
    double lug_period;     /* rad, the tread pattern's period (2 pi / lugs); 0: none */
    double interval;       /* s, exchange interval */
    double slip, torque, drawbar; /* the prescribed slip, axle torque or drawbar load (per control) */
    double travel_distance; /* m, wheel.travel_distance */
    double travelled;       /* m, travelled when the run ended */
    int travel_done;        /* the travel reached travel_distance (else interrupted or run.end_time) */
    uint64_t fem_state_hash;
    /* the interface work of the grains on the tire (fem_exchange.c's guard):
     * seen by the DEM and by the FEM at the end (J), their largest relative
     * gap over the run, when it first passed work_warn (s; 0: never), and
     * the gap above which the summary warns (0: no check) */
    double work_dem, work_fem, work_gap_max, work_warned_at, work_warn;
} fem_summary_def;

enum { FEM_SUMMARY_LOAD_OFF = 1 }; /* warning: the steady load is > 10 % from target_load */

/* Writes the summary and logs it. CM_OK, or FEM_SUMMARY_LOAD_OFF (> 0, a
 * warning, already logged) when the load check failed, or a negative error
 * naming the file. A run that never reached the travel phase gets a summary
 * saying so (no quantities). */
int fem_summary_write(const fem_summary_def *d, cm_error *err);

#endif
