/* Internals of common/h5io (private to common/): the file and series
 * structures and the helpers the h5io_*.c files share. h5io.h is the
 * interface; the code is split by job:
 *   h5io.c         HDF5 errors, names, small HDF5 helpers, the file's life
 *                  (create, flush, close), static datasets and attributes,
 *                  raw typed arrays
 *   h5io_step.c    snapshots: /steps/NNNNNN groups and their datasets
 *   h5io_xdmf.c    the XDMF index beside the file (written in full or
 *                  appended step by step)
 *   h5io_series.c  time series (/series) with their CSV mirror
 *   h5io_resume.c  reopening a results file to resume a run */
#ifndef CM_H5IO_IMPL_H
#define CM_H5IO_IMPL_H

#include "h5io.h"

#include <ctype.h>
#include <errno.h>
#include <fcntl.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <hdf5.h>

#include "csv.h"

_Static_assert(sizeof(int) == 4, "ints are stored as I32LE");

enum { NAME_MAX_LEN = 63 };

/* One dataset written in a step, kept for regenerating the XDMF. */
typedef struct field {
    char name[NAME_MAX_LEN + 1];
    int is_int;
    size_t n;
    int ncomp;
    cm_h5_center center;
} field;

/* One completed step: its fields are fields[first .. first + count). */
typedef struct step_rec {
    long step;
    double time;
    size_t first, count;
    size_t npoints, ncells;
} step_rec;

struct cm_h5_series {
    cm_h5 *file;
    char *path;
    hid_t dset, memtype;
    int ncols;
    long rows; /* rows in the dataset */
    cm_csv *csv;
    cm_h5_series *next;
    /* appended rows not yet in the files (cm_h5_series_hold): n_held rows
     * of ncols, the first h5_done of them already in the dataset */
    double *held;
    long n_held, h5_done, max_held; /* max_held <= 1: every row written by its append */
    double hold_s, t_written;       /* hold at most hold_s of wall time since t_written */
};

/* The held rows of s into its dataset (the file not flushed). */
int h5io_series_write_held(cm_h5_series *s, cm_error *err);

/* ...then, once the file is flushed, into the CSV: no longer held. */
int h5io_series_csv_held(cm_h5_series *s, cm_error *err);

/* Frees a series' memory (its HDF5 objects and CSV are closed by the caller). */
void h5io_series_free(cm_h5_series *s);

struct cm_h5 {
    char *path, *xmf_path;
    const char *base; /* points into path: the name the XDMF refers to */
    hid_t fid, lcpl;
    cm_h5_xdmf xdmf;
    char *grid_name, *geometry, *connectivity;
    int geometry_static;

    /* current step */
    int steps_group; /* /steps exists (ensure_steps_group) */
    int in_step;
    long step, last_step;
    double time;
    hid_t gid;
    char group[32];

    field *fields; /* completed steps' fields, then the current step's */
    size_t nfields, cap_fields, step_first;
    step_rec *steps;
    size_t nsteps, cap_steps;

    /* sizes of static datasets, looked up at the first step_end (0: unknown) */
    size_t static_points, cells;
    size_t vertex_ids_len;

    /* The XDMF as last written in full, kept open to append steps: xmf_end
     * is where its closing tags begin; xmf_ids_len the vertex ids' length
     * its steps were listed with (a change rewrites it in full). */
    int xmf_fd;
    off_t xmf_end;
    size_t xmf_ids_len;

    cm_h5_series *series;
};

/* ---- shared between the h5io_*.c files ---------------------------------------- */

/* h5io.c: fails with the message, HDF5's innermost reason appended. */
int h5io_fail(cm_error *err, const char *file, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
/* h5io.c: names safe in HDF5 paths, XML and CSV (one part; an absolute path). */
int h5io_simple_name_ok(const char *s);
int h5io_abs_path_ok(const char *p);
/* h5io.c: a dataset of n x ncomp doubles or ints, an attribute, a dataset's shape. */
int h5io_write_array(cm_h5 *f, hid_t loc, const char *name, const char *shown, int is_int, const void *data,
                     size_t n, int ncomp, cm_error *err);
int h5io_write_attr(cm_h5 *f, hid_t obj, const char *shown, const char *name, hid_t ftype, hid_t mtype,
                    const void *value, cm_error *err);
int h5io_dataset_shape(cm_h5 *f, const char *path, int *rank, hsize_t dims[2], int *is_int, cm_error *err);
/* h5io.c: H5Fcreate (truncating) with h5io's file creation properties;
 * fails with "<path>: <what>: <HDF5's reason>". */
int h5io_create_file(const char *path, const char *what, hid_t *fid, cm_error *err);
/* h5io.c: the handle of a file being created or reopened. */
int h5io_file_new(const char *path, const cm_h5_def *def_in, cm_h5 **out, cm_error *err);
/* h5io_xdmf.c: the XDMF rewritten in full (atomically), or the last step appended. */
int h5io_write_xdmf(cm_h5 *f, cm_error *err);
int h5io_xdmf_append(cm_h5 *f, cm_error *err);
/* h5io_step.c: one dataset of the open step; the sizes a step's grid needs. */
int h5io_step_write(cm_h5 *f, const char *name, cm_h5_center center, int is_int, const void *data, size_t n,
                    int ncomp, cm_error *err);
int h5io_check_step(cm_h5 *f, size_t *npoints, size_t *ncells, cm_error *err);
/* h5io_step.c: the group "steps" in loc, with room for many step names. */
int h5io_create_steps_group(hid_t loc, const char *file, cm_error *err);
/* h5io_series.c: links a new or reopened series into its file (or frees it on rc). */
int h5io_series_adopt(cm_h5 *f, cm_h5_series *s, int rc, cm_h5_series **out, cm_error *err);

#endif
