/* CSV tables of doubles: a header line of column names, then one line per
 * row with every value printed as %.17g (round-trips a double exactly), so
 * `pandas.read_csv` / `numpy.loadtxt(skiprows=1, delimiter=",")` read back
 * the very numbers that were written.
 *
 * Every row is flushed to the operating system before cm_csv_row (or
 * cm_csv_rows) returns: a process killed later leaves every complete row in
 * the file. */
#ifndef CM_CSV_H
#define CM_CSV_H

#include "error.h"

typedef struct cm_csv cm_csv;

/* Creates (truncates) `path` and writes the header line "c0,c1,...".
 * Column names must be non-empty and free of ',', '"', and line breaks. */
int cm_csv_create(const char *path, const char *const *columns, int ncols, cm_csv **out, cm_error *err);

/* Reopens `path` to continue it after a restart: keeps the header and the
 * first `rows` rows, cuts off anything after them (rows a killed run wrote
 * past its last checkpoint) and appends from there. Fails naming the file
 * when it holds fewer rows. */
int cm_csv_reopen(const char *path, int ncols, long rows, cm_csv **out, cm_error *err);

/* Appends one row of ncols values and flushes it. */
int cm_csv_row(cm_csv *c, const double *values, cm_error *err);

/* Appends nrows rows (values row after row, ncols each) and flushes once. */
int cm_csv_rows(cm_csv *c, const double *values, long nrows, cm_error *err);

/* Closes the file and sets *c to NULL (no-op on NULL). Fails if the final
 * close reports a write error. */
int cm_csv_close(cm_csv **c, cm_error *err);

const char *cm_csv_path(const cm_csv *c);

#endif
