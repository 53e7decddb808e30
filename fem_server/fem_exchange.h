/* One exchange of fem_server with dem_server, as a pipeline of named, timed
 * stages (fem_exchange.c), and the coupled run's state it works on.
 *
 *   receive         wait for the DEM's frame of exchange n
 *   check_frame     the peer's data: frame kind, time, finite totals and nodal forces
 *   check_balance   nodal forces against the contact totals (eq. 42 keeps resultant and moment)
 *   place_wheel     the first exchange lowers the wheel to start_gap above the bed; set the rigid motion
 *   advance         the tire over the interval under the received forces (fem_advance)
 *   snapshot        the after_advance hook: tire output (fem.h5) of the state just reached
 *   update_drive    the wheel's motion for the next interval (drive.c)
 *   pack_reply      the new interface positions and velocities, the FEM's interface work
 *   check_work      the coupling guard: the two sides' interface work must agree
 *   send            the wheel state and flags; commit the frame
 *   record          series row, travel series, checkpoint, progress line
 *
 * Each stage's wall and CPU time are summed into fem_profile, printed at the
 * end of a run and written to wheel.h5 as attributes of "/"
 * (profile_<stage>_s, profile_<stage>_cpu_s). */
#ifndef FEM_EXCHANGE_H
#define FEM_EXCHANGE_H

#include <signal.h>
#include <stdint.h>

#include "drive.h"
#include "error.h"
#include "fem.h"
#include "h5io.h"
#include "ipc.h"
#include "runcfg.h"

typedef enum fem_stage {
    FEM_STAGE_RECEIVE,
    FEM_STAGE_CHECK_FRAME,
    FEM_STAGE_CHECK_BALANCE,
    FEM_STAGE_PLACE_WHEEL,
    FEM_STAGE_ADVANCE,
    FEM_STAGE_SNAPSHOT,
    FEM_STAGE_UPDATE_DRIVE,
    FEM_STAGE_PACK_REPLY,
    FEM_STAGE_CHECK_WORK,
    FEM_STAGE_SEND,
    FEM_STAGE_RECORD,
    FEM_STAGE_COUNT
} fem_stage;

/* Stage names as printed and as written ("profile_<name>_s"). */
extern const char *const fem_stage_names[FEM_STAGE_COUNT];

typedef struct fem_profile {
    double seconds[FEM_STAGE_COUNT]; /* s of wall time per stage, summed over the exchanges */
    double cpu_seconds[FEM_STAGE_COUNT]; /* s of the process's CPU time per stage (fem_server is one thread;
                                            receive's includes the wait's spin; the short stages between receive,
                                            advance, snapshot and record: their wall time, fem_exchange.c) */
    long exchanges;                  /* exchanges timed */
} fem_profile;

/* The travel phase's series for the summary (grown by doubling). */
enum { SER_TH, SER_TR, SER_TP, SER_SINK, SER_SLIP, SER_FX, SER_MY, SER_N };
typedef struct series_buf {
    double *col[SER_N];
    size_t n, cap;
} series_buf;

/* Columns of wheel.h5:/series and traction.csv, one row per exchange. */
extern const char *const fem_series_columns[];
extern const int fem_series_ncols;

/* The model's rigid motion (fem_set_wheel) from the drive's state. */
int fem_set_wheel_motion(fem_model *m, const drive_state *ds, cm_error *err);

/* Appends a row; CM_ERR_NOMEM when the series cannot grow. */
int series_push(series_buf *b, const double row[SER_N]);
void series_free(series_buf *b);

/* Called by the snapshot stage right after each fem_advance (the tire's
 * output: fem_output_due), before the wheel's next motion is set; nonzero
 * stops the run with err. */
typedef struct fem_exchange_hooks {
    int (*after_advance)(fem_model *m, void *user, long exchange, cm_error *err);
    void *user;
} fem_exchange_hooks;

/* Everything the exchange loop keeps from one exchange to the next. Set up
 * by fem_main.c (fields above `state`), advanced by fem_exchange(). */
typedef struct fem_coupled {
    fem_model *model;
    ipc_channel *ch;
    const drive_def *drive;
    const cm_run_config *run;
    const char *out;              /* results folder (checkpoints) */
    uint64_t scene_hash;          /* for checkpoints */
    uint32_t nn;                  /* interface nodes */
    double interval;              /* s, the exchange interval */
    cm_h5_series *series;         /* wheel.h5:/series + traction.csv */
    fem_exchange_hooks hooks;
    volatile sig_atomic_t *interrupt; /* set by SIGINT/SIGTERM: checkpoint and stop */

    /* state */
    drive_state ds;
    double *x_prev;               /* 3 nn: the interface as the DEM last saw it (m, world) */
    series_buf travel;            /* the travel phase, for the summary */
    long n;                       /* number of the exchange under way */
    long n_first;                 /* first exchange of this process (resuming: > 0) */
    double w_fem;                 /* J, interface work seen by the FEM, accumulated */
    double w_dem_last;            /* J, the DEM's, as of its last frame */
    double work_abs;              /* J, sum over the exchanges of |the FEM's interface work| */
    double work_scale;            /* J, the guard's floor (fem_exchange.c, update_work_scale) */
    double work_gap_max;          /* the largest relative gap of the two works so far (fem_interface_work_gap) */
    double work_warned_at;        /* s, when that gap first passed FEM_WORK_WARN (warned once); 0: not yet */
    double elastic0;              /* J, the tire's elastic energy before any grain touched it */
    double max_force_mismatch, max_moment_mismatch; /* relative, nodal forces vs contact totals */
    int stop_sent;
    double last_progress, loop_t0; /* s, wall clock */
    fem_profile prof;
} fem_coupled;

/* What an exchange ended with. FEM_EXCHANGE_FAILED: err says why (this
 * side's guard, or the peer's bad data); the caller fails the channel.
 * FEM_EXCHANGE_LINK_LOST: the channel failed (ipc_error() says why). */
typedef enum fem_exchange_status {
    FEM_EXCHANGE_NEXT = 0,
    FEM_EXCHANGE_FINISHED = 1,
    FEM_EXCHANGE_FAILED = -1,
    FEM_EXCHANGE_LINK_LOST = -2
} fem_exchange_status;

/* Runs exchange c->n through the stages above and, unless it ended the run,
 * moves on to the next (c->n + 1). */
fem_exchange_status fem_exchange(fem_coupled *c, cm_error *err);

/* The interface-work guard (issue 16): fails when the FEM's and the DEM's
 * interface work differ by more than FEM_WORK_TOLERANCE of the larger of the
 * two and of the floor `scale` (J). Pure, for tests. A gap above
 * FEM_WORK_WARN is warned about once in the log, when it happens, and in the
 * summary: a stable exchange stays below 1 % (the largest gap over a run:
 * 0.64 % on the default scene and on tests/coupling's small tire, early in
 * the contact; 0.05 % and 0.002 % at their ends), while a drifting one grows
 * for a while before the guard stops it (tet10 without interface_mass_min:
 * 0.4 % at t = 0.29 s, 12 % at 0.39 s). */
#define FEM_WORK_TOLERANCE 0.25
#define FEM_WORK_WARN 0.02
/* |w_fem - w_dem| over the larger of |w_fem|, |w_dem| and scale: the guard's
 * measure (infinity when a work is not finite). */
double fem_interface_work_gap(double w_fem, double w_dem, double scale);
int fem_check_interface_work(double w_fem, double w_dem, double scale, double t, double interval,
                             cm_error *err);

/* Prints the profile (one line per stage: total s, share, us per exchange). */
void fem_profile_print(const fem_profile *p);
/* Writes it as attributes of "/" of h5 (profile_<stage>_s, profile_exchanges). */
int fem_profile_write(const fem_profile *p, cm_h5 *h5, cm_error *err);

#endif
