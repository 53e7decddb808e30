/* Results: HDF5 snapshots with an XDMF index (common/h5io) and a time
 * series. Internal to fem/. */
#ifndef FEM_OUTPUT_H
#define FEM_OUTPUT_H

#include "error.h"

typedef struct fem_output fem_output;
struct fem_model;

/* Creates <dir>/fem.h5, fem.xmf and the series (also <dir>/fem_series.csv). */
int fem_output_open(struct fem_model *m, const char *dir, fem_output **out, cm_error *err);
int fem_output_snapshot(fem_output *o, struct fem_model *m, cm_error *err);
int fem_output_series(fem_output *o, struct fem_model *m, cm_error *err);
int fem_output_close(fem_output **o, cm_error *err);
/* Resuming: reopens <dir>/fem.h5 keeping the snapshots of solver steps up
 * to keep_step and the first series_rows rows of the series. */
int fem_output_reopen(struct fem_model *m, const char *dir, long keep_step, long series_rows, fem_output **out,
                      cm_error *err);
/* Rows of the series written so far. */
long fem_output_rows(const fem_output *o);

#endif
