/* fem_server's checkpoints: the tire's state (displacement, velocity,
 * acceleration, load, clocks, wheel pose), the drive's state and the
 * exchange loop's, after one exchange, to HDF5 (common/ckpt.h); a run
 * resumed from it continues bit for bit as the uninterrupted run would. */
#ifndef FEM_CHECKPOINT_H
#define FEM_CHECKPOINT_H

#include <stddef.h>
#include <stdint.h>

#include "ckpt.h"
#include "drive.h"
#include "fem.h"

/* Columns of the travel series kept for the summary, in this order:
 * T_H, T_R, T_P, sinkage, realised slip, soil F_x, soil M_y. */
#define FEM_CKPT_TRAVEL_COLS 7

/* The exchange loop's state besides the model's. */
typedef struct fem_ckpt_run {
    long exchange;                 /* exchanges completed (the last one's number) */
    drive_state *drive;
    double w_fem;                  /* J, interface work seen by the FEM */
    double max_force_mismatch, max_moment_mismatch;
    double work_abs, work_scale;   /* J, the interface-work guard's floor (fem_exchange.c) */
    double work_gap_max, work_warned_at; /* the largest relative gap of the works; s, its first warning (0: none) */
    uint32_t n_nodes;
    double *x_prev;                /* 3 n_nodes: the interface positions last sent */
    size_t travel_n;               /* the travel series for the summary, FEM_CKPT_TRAVEL_COLS columns */
    double *travel[FEM_CKPT_TRAVEL_COLS]; /* reading: allocated here (malloc), owned by the caller */
    long series_rows;              /* rows of wheel.h5:/series and traction.csv */
} fem_ckpt_run;

/* Every field of drive_state, one line each (new drive modes add theirs here). */
void fem_checkpoint_drive(cm_ckpt *ck, drive_state *s);

/* Writes <dir>/checkpoint/fem.h5 (the previous one kept as fem.prev.h5). */
int fem_checkpoint_write(const char *dir, fem_model *m, fem_ckpt_run *run, uint64_t scene_hash, cm_error *err);

/* Restores from `path` (which must hold `exchange`) into a model built and
 * statically solved from the same scene; with dir, reopens the model's
 * results (fem.h5, fem_series.csv) cut back to the checkpoint. */
int fem_checkpoint_read(const char *path, long exchange, fem_model *m, fem_ckpt_run *run, uint64_t scene_hash,
                        const char *dir, cm_error *err);

/* FNV-1a 64 over u, v, a of the tire: compares final states of two runs. */
uint64_t fem_state_hash(const fem_model *m);

#endif
