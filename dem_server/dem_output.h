/* dem: grain states (HDF5 + XDMF, ParaView-ready) and a series of totals
 * (CSV) written during a run. */
#ifndef DEM_OUTPUT_H
#define DEM_OUTPUT_H

#include <stdbool.h>

#include "dem.h"

/* ---- Output ----------------------------------------------------------- */

typedef struct dem_output dem_output;
/* Opens dir/dem_grains.h5, dir/dem_grains.xmf and dir/dem_series.csv (dir is
 * created if needed; the dem_ prefix keeps them apart from fem_server's files). */
int dem_output_open(const char *dir, dem_output **out, cm_error *err);
int dem_output_frame(dem_output *o, const dem_world *w, cm_error *err);  /* grain states */
int dem_output_series(dem_output *o, const dem_world *w, cm_error *err); /* one line of KE, contacts */
/* The same line from totals already taken (dem_world_stats_lean's fields,
 * or dem_mpi_series_stats' for a distributed world). */
int dem_output_series_row(dem_output *o, const dem_stats *s, cm_error *err);
void dem_output_close(dem_output **o);
/* Resuming: reopens the files of `dir` keeping the first `frames` frames and
 * `series_rows` series rows (what a killed run wrote after its checkpoint is
 * dropped), to continue them. */
int dem_output_reopen(const char *dir, long frames, long series_rows, dem_output **out, cm_error *err);
/* Frames and series rows written so far. */
void dem_output_counts(const dem_output *o, long *frames, long *series_rows);

#endif
