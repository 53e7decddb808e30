/* Results files: one HDF5 file per server, with an XDMF 3 file beside it so
 * that ParaView opens the whole run as a time series, and h5py reads the
 * same data directly.
 *
 * Layout of <name>.h5 (all datasets plain little-endian types: doubles as
 * IEEE F64LE, ints as I32LE; arrays of n rows by ncomp columns in row-major
 * order, a 1-D array of length n when ncomp == 1):
 *   /mesh/...             static datasets written once (cm_h5_write_*)
 *   /steps/000123/        one group per snapshot, attributes time (F64) and
 *                         step (I64); datasets written by cm_h5_step_*
 *   /series               a table appended one row at a time (cm_h5_series_*):
 *                         1-D, chunked and unlimited, of a compound type with
 *                         one F64LE field per named column; h5py:
 *                         f["series"]["KE"] is the KE column as an array
 *   /xdmf/vertex_ids      0..N-1 (Polyvertex files only), the particles'
 *                         explicit connectivity, so both ParaView readers
 *                         ("Xdmf Reader" and "Xdmf3 Reader") show the points
 *
 * Durability: cm_h5_step_end and cm_h5_series_append flush the file
 * (H5Fflush) before returning (a series told to hold its rows,
 * cm_h5_series_hold, writes and flushes them in blocks instead, and on
 * every cm_h5_flush), and cm_h5_step_end then appends the step to
 * <name>.xmf in place (one write of the step and the closing tags over the
 * old closing tags; the first step, a resumed file and a growth of the
 * vertex ids rewrite it in full and atomically: temporary file, fsync,
 * rename). A process killed afterwards leaves a file that HDF5 opens, with
 * every completed step and every appended row not held. H5Fflush hands data to the operating system; it does not
 * fsync the .h5, so a power cut may lose the most recent steps. A process
 * killed DURING a write (a flush, or the metadata cache writing entries out
 * on its own) can leave metadata that refers past the file's recorded end:
 * the file is not crash-consistent, and cm_h5_reopen does not edit it in
 * place but rebuilds it from what the checkpoint covers (see cm_h5_reopen).
 *
 * The XDMF refers to datasets as "<basename of the .h5>:/steps/...", so the
 * .h5 / .xmf pair can be moved together to another folder.
 *
 * Not thread-safe (Debian's serial HDF5 is not): call from one thread.
 * cm_h5_create turns off HDF5's automatic printing of its error stack for
 * the whole process; failures come back as a cm_error naming the file and
 * dataset, with HDF5's innermost reason appended. */
#ifndef CM_H5IO_H
#define CM_H5IO_H

#include <stddef.h>

#include "error.h"

typedef struct cm_h5 cm_h5;
typedef struct cm_h5_series cm_h5_series;

/* What the XDMF file describes. */
typedef enum cm_h5_xdmf {
    CM_H5_XDMF_NONE = 0,    /* HDF5 only, no .xmf file */
    CM_H5_XDMF_POLYVERTEX,  /* particles: one vertex cell per point */
    CM_H5_XDMF_TETRAHEDRON  /* linear tetrahedra, fixed connectivity */
} cm_h5_xdmf;

/* Where a step dataset lives in the XDMF grid. */
typedef enum cm_h5_center {
    CM_H5_UNLISTED = 0, /* stored in HDF5 only, not listed in the XDMF */
    CM_H5_NODE,         /* one row per point  (XDMF Center="Node") */
    CM_H5_CELL          /* one row per tetrahedron (XDMF Center="Cell") */
} cm_h5_center;

typedef struct cm_h5_def {
    /* Kind of XDMF grid; CM_H5_XDMF_NONE writes no .xmf. */
    cm_h5_xdmf xdmf;
    /* Name of the temporal collection shown in ParaView. Default "grid". */
    const char *grid_name;
    /* Point coordinates, n x 3 doubles [m]. Either a step dataset name
     * ("position": written each step, e.g. grain centres or the deformed
     * mesh) or an absolute path to a static dataset ("/mesh/points0": the
     * reference mesh; then write the displacement as a CM_H5_NODE vector and
     * apply ParaView's "Warp By Vector"). Default "position". */
    const char *geometry;
    /* Tetrahedra only: absolute path of the static int m x 4 dataset of
     * 0-based point indices, written with cm_h5_write_ints before the first
     * cm_h5_step_end. Default "/mesh/connectivity". */
    const char *connectivity;
} cm_h5_def;

cm_h5_def cm_h5_default_def(void);

/* Call first in main, before any other HDF5 use: HDF5 then does not tidy up
 * at exit (its exit-time clean-up crashed on a file whose final flush had
 * failed, e.g. on a full disk, turning one clear error into a segfault),
 * and prints no error stacks of its own. */
void cm_h5_library_init(void);

/* ---- File --------------------------------------------------------------- */

/* Creates (truncates) the results file `path`; with def->xdmf set, the XDMF
 * file is `path` with its .h5/.hdf5 suffix replaced by .xmf (cm_h5_xdmf_path).
 * def may be NULL (defaults: no XDMF). */
int cm_h5_create(const char *path, const cm_h5_def *def, cm_h5 **out, cm_error *err);

/* Closes the file and every series of it, sets *f to NULL (no-op on NULL).
 * A step begun and not ended stays in the HDF5 file but not in the XDMF. */
int cm_h5_close(cm_h5 **f, cm_error *err);

/* Flushes everything written so far to the operating system, the rows its
 * series hold first written. */
int cm_h5_flush(cm_h5 *f, cm_error *err);

const char *cm_h5_path(const cm_h5 *f);
const char *cm_h5_xdmf_path(const cm_h5 *f); /* NULL without XDMF */

/* ---- Static datasets and attributes ------------------------------------- */

/* Writes a new dataset at absolute `path` ("/mesh/points0"), creating the
 * groups above it: n rows of ncomp values (1-D when ncomp == 1). Path
 * components use only letters, digits and "_.-+". */
int cm_h5_write_doubles(cm_h5 *f, const char *path, const double *data, size_t n, int ncomp, cm_error *err);
int cm_h5_write_ints(cm_h5 *f, const char *path, const int *data, size_t n, int ncomp, cm_error *err);

/* Sets (or replaces) a scalar attribute on an existing group or dataset
 * ("/" for the file): provenance such as the scene text or units. Strings
 * are stored as variable-length UTF-8 (h5py returns str). */
int cm_h5_attr_double(cm_h5 *f, const char *object, const char *name, double value, cm_error *err);
int cm_h5_attr_string(cm_h5 *f, const char *object, const char *name, const char *value, cm_error *err);

/* ---- Snapshots ---------------------------------------------------------- */

/* Starts group /steps/<step, 6+ digits> with attributes time [s] and step.
 * Steps must increase from one snapshot to the next. */
int cm_h5_step_begin(cm_h5 *f, long step, double time, cm_error *err);

/* Writes dataset `name` (no '/') in the current step: n rows of ncomp
 * values. A dataset listed in the XDMF (center NODE or CELL) has ncomp 1
 * (Scalar), 3 (Vector), 6 (Tensor6, in XDMF's order xx, xy, xz, yy, yz, zz:
 * not Voigt order) or 9 (Tensor, row-major), and as many rows as points or
 * cells. The geometry dataset (def.geometry) is written like any other. */
int cm_h5_step_doubles(cm_h5 *f, const char *name, cm_h5_center center, const double *data, size_t n,
                       int ncomp, cm_error *err);
int cm_h5_step_ints(cm_h5 *f, const char *name, cm_h5_center center, const int *data, size_t n, int ncomp,
                    cm_error *err);

/* Ends the step: checks it against the XDMF grid (geometry present, row
 * counts), flushes the HDF5 file and appends the step to the XDMF. */
int cm_h5_step_end(cm_h5 *f, cm_error *err);

/* ---- Time series -------------------------------------------------------- */

/* Creates an empty table at absolute `path` ("/series") with ncols named
 * double columns (names: letters, digits, "_.-+", unique). With csv_path
 * non-NULL, every row is also appended to that CSV file (header of column
 * names, values as %.17g). The series belongs to f: it stays valid until
 * cm_h5_close, which closes it. */
int cm_h5_series_create(cm_h5 *f, const char *path, const char *const *columns, int ncols, const char *csv_path,
                        cm_h5_series **out, cm_error *err);

/* Appends one row of ncols values, flushes the HDF5 file, then the CSV
 * (or holds the row, see cm_h5_series_hold). */
int cm_h5_series_append(cm_h5_series *s, const double *row, cm_error *err);

/* Lets the series hold up to max_rows appended rows in memory and write
 * them as one block (the HDF5 rows, the file's flush, then the CSV rows)
 * once max_rows are held or `seconds` of wall time have passed since the
 * last write: per row, a flush costs more than the row (about 0.1 ms, for a
 * run that appends every 2-3 ms). cm_h5_series_flush, cm_h5_flush,
 * cm_h5_step_end and cm_h5_close write the held rows first. max_rows <= 1,
 * the default: every row written and flushed by its append. A process
 * killed while rows are held loses them: flush before recording elsewhere
 * how many rows there are (a checkpoint). Rows that failed to be written
 * stay held: the next append fails too. */
int cm_h5_series_hold(cm_h5_series *s, long max_rows, double seconds, cm_error *err);

/* Writes the rows the series holds (and flushes its whole file). */
int cm_h5_series_flush(cm_h5_series *s, cm_error *err);

/* Rows appended so far (held ones included). */
long cm_h5_series_rows(const cm_h5_series *s);

/* ---- Resuming a run (checkpoint/restart) --------------------------------- */

/* Reopens an existing results file written by cm_h5_create to continue it
 * after a checkpoint at step keep_through_step, even when the writer was
 * killed in the middle of a write. The file is rebuilt, never edited in
 * place: a fresh file "<path>.resume.tmp" receives copies of the /steps
 * groups up to keep_through_step (the later ones, which a resumed run
 * rewrites, are not even opened), of every other object (extendible
 * datasets such as a series up to the last row that reads) and of the
 * attributes; it is synced and renamed over `path` (a kill during the
 * resume leaves the old file as it was). A kept object that cannot be read
 * fails with a message naming the file and the object. The kept steps are
 * then listed again in the XDMF (each step dataset carries its XDMF center
 * as the attribute "xdmf_center"), and later cm_h5_step_begin calls must
 * follow the last kept step. def must be the one the file was created with.
 * Costs one copy of the kept data. */
int cm_h5_reopen(const char *path, const cm_h5_def *def, long keep_through_step, cm_h5 **out, cm_error *err);

/* The rebuild cm_h5_reopen does, for any HDF5 file (dem_server's grain
 * frames too): `path` is replaced by a copy of everything in it except the
 * members of group `group` ("/" or "/steps") named <prefix><digits> with a
 * number greater than keep, which are not even opened. A kept numbered
 * member must be a group (whose attribute "step", if it has one, equals its
 * number). Extendible datasets are copied up to the last chunk that reads.
 * Written to "<path>.resume.tmp", synced and renamed over `path`. */
int cm_h5_rebuild(const char *path, const char *group, const char *prefix, long keep, cm_error *err);

/* fsync of a file, and of the folder that holds `path` (which makes a
 * rename in it durable): 0 or -1 with errno set. The resume's rebuild and
 * the checkpoints (ckpt.c) replace files this way. */
int cm_fsync_file(const char *path);
int cm_fsync_folder_of(const char *path);

/* Reopens the series `path` of a reopened file, cut back to its first `rows`
 * rows, and its CSV (cut back to the header and `rows` lines). columns as
 * for cm_h5_series_create. Fails naming the file if either holds fewer rows. */
int cm_h5_series_reopen(cm_h5 *f, const char *path, const char *const *columns, int ncols, const char *csv_path,
                        long rows, cm_h5_series **out, cm_error *err);

/* ---- Raw typed arrays (checkpoints) --------------------------------------- */

typedef enum cm_h5_type { CM_H5_F64 = 0, CM_H5_I32, CM_H5_U32, CM_H5_I64, CM_H5_U64 } cm_h5_type;

/* Opens an existing HDF5 file for cm_h5_write_array / cm_h5_read_array
 * (writable: read-write, else read-only). Close with cm_h5_close. */
int cm_h5_open(const char *path, int writable, cm_h5 **out, cm_error *err);

/* Writes a new dataset at absolute `path`, n rows of ncomp values of `type`
 * (stored little-endian, bit-exact; 1-D when ncomp == 1). */
int cm_h5_write_array(cm_h5 *f, const char *path, cm_h5_type type, const void *data, size_t n, int ncomp,
                      cm_error *err);
/* Reads dataset `path` into data; its type and shape must be exactly those
 * given (n rows, ncomp columns), else an error names the file and dataset. */
int cm_h5_read_array(cm_h5 *f, const char *path, cm_h5_type type, void *data, size_t n, int ncomp,
                     cm_error *err);

#endif
