/* common/h5io: time series (/series, one compound row per append) with
 * their CSV mirror (h5io.h). */
#include "h5io_impl.h"

#include "timer.h"

/* ---- time series -------------------------------------------------------------- */

/* The common ending of creating and reopening a series: flushed and added
 * to the file's list, or, after a failure, released. */
int h5io_series_adopt(cm_h5 *f, cm_h5_series *s, int rc, cm_h5_series **out, cm_error *err)
{
    if (rc == CM_OK)
        rc = cm_h5_flush(f, err);
    if (rc != CM_OK) {
        cm_csv_close(&s->csv, NULL);
        if (s->dset >= 0)
            H5Dclose(s->dset);
        if (s->memtype >= 0)
            H5Tclose(s->memtype);
        h5io_series_free(s);
        return rc;
    }
    s->next = f->series;
    f->series = s;
    *out = s;
    return CM_OK;
}

int cm_h5_series_create(cm_h5 *f, const char *path, const char *const *columns, int ncols, const char *csv_path,
                        cm_h5_series **out, cm_error *err)
{
    *out = NULL;
    if (!h5io_abs_path_ok(path))
        return cm_fail(err, CM_ERR_RANGE, "%s: series path \"%s\" must be absolute, with components of "
                       "letters, digits and \"_.-+\"", f->path, path ? path : "(null)");
    if (ncols < 1 || !columns)
        return cm_fail(err, CM_ERR_RANGE, "%s: series %s: needs at least one column", f->path, path);
    for (int i = 0; i < ncols; i++) {
        if (!h5io_simple_name_ok(columns[i]))
            return cm_fail(err, CM_ERR_RANGE, "%s: series %s: column %d name \"%s\" must be letters, digits, "
                           "\"_.-+\"", f->path, path, i, columns[i] ? columns[i] : "(null)");
        for (int j = 0; j < i; j++)
            if (strcmp(columns[i], columns[j]) == 0)
                return cm_fail(err, CM_ERR_RANGE, "%s: series %s: column \"%s\" appears twice", f->path, path,
                               columns[i]);
    }
    cm_h5_series *s = calloc(1, sizeof *s);
    if (!s || !(s->path = strdup(path))) {
        free(s);
        return cm_fail(err, CM_ERR_NOMEM, "%s: series %s: out of memory", f->path, path);
    }
    s->file = f;
    s->ncols = ncols;
    s->dset = s->memtype = H5I_INVALID_HID;

    int rc = CM_OK;
    hid_t ftype = H5Tcreate(H5T_COMPOUND, 8 * (size_t)ncols);
    s->memtype = H5Tcreate(H5T_COMPOUND, sizeof(double) * (size_t)ncols);
    if (ftype < 0 || s->memtype < 0)
        rc = h5io_fail(err, f->path, "series %s: row type", path);
    for (int i = 0; i < ncols && rc == CM_OK; i++)
        if (H5Tinsert(ftype, columns[i], 8 * (size_t)i, H5T_IEEE_F64LE) < 0 ||
            H5Tinsert(s->memtype, columns[i], sizeof(double) * (size_t)i, H5T_NATIVE_DOUBLE) < 0)
            rc = h5io_fail(err, f->path, "series %s: column %s", path, columns[i]);
    /* Chunks of about 8 KiB: each flush rewrites the last chunk. */
    hsize_t zero = 0, unlimited = H5S_UNLIMITED, chunk = 8192 / (8 * (hsize_t)ncols);
    if (chunk < 16)
        chunk = 16;
    hid_t space = H5I_INVALID_HID, dcpl = H5I_INVALID_HID;
    if (rc == CM_OK && ((space = H5Screate_simple(1, &zero, &unlimited)) < 0 ||
                        (dcpl = H5Pcreate(H5P_DATASET_CREATE)) < 0 || H5Pset_chunk(dcpl, 1, &chunk) < 0))
        rc = h5io_fail(err, f->path, "series %s: dataspace", path);
    if (rc == CM_OK && (s->dset = H5Dcreate2(f->fid, path, ftype, space, f->lcpl, dcpl, H5P_DEFAULT)) < 0)
        rc = h5io_fail(err, f->path, "creating series %s", path);
    if (dcpl >= 0)
        H5Pclose(dcpl);
    if (space >= 0)
        H5Sclose(space);
    if (ftype >= 0)
        H5Tclose(ftype);
    if (rc == CM_OK && csv_path)
        rc = cm_csv_create(csv_path, columns, ncols, &s->csv, err);
    return h5io_series_adopt(f, s, rc, out, err);
}

void h5io_series_free(cm_h5_series *s)
{
    free(s->held);
    free(s->path);
    free(s);
}

int h5io_series_write_held(cm_h5_series *s, cm_error *err)
{
    cm_h5 *f = s->file;
    hsize_t start = (hsize_t)s->rows, count = (hsize_t)(s->n_held - s->h5_done), size = start + count;
    if (count == 0)
        return CM_OK;
    hid_t fs = H5I_INVALID_HID, ms = H5I_INVALID_HID;
    int rc = CM_OK;
    if (H5Dset_extent(s->dset, &size) < 0)
        rc = h5io_fail(err, f->path, "series %s: extending to row %ld", s->path, s->rows + (long)count - 1);
    else if ((fs = H5Dget_space(s->dset)) < 0 ||
             H5Sselect_hyperslab(fs, H5S_SELECT_SET, &start, NULL, &count, NULL) < 0 ||
             (ms = H5Screate_simple(1, &count, NULL)) < 0 ||
             H5Dwrite(s->dset, s->memtype, ms, fs, H5P_DEFAULT, s->held + (size_t)s->h5_done * (size_t)s->ncols) < 0) {
        rc = h5io_fail(err, f->path, "series %s: writing rows %ld to %ld", s->path, s->rows,
                       s->rows + (long)count - 1);
        H5Dset_extent(s->dset, &start); /* do not leave rows of fill values */
    }
    if (ms >= 0)
        H5Sclose(ms);
    if (fs >= 0)
        H5Sclose(fs);
    if (rc == CM_OK) {
        s->rows += (long)count;
        s->h5_done = s->n_held;
    }
    return rc;
}

int h5io_series_csv_held(cm_h5_series *s, cm_error *err)
{
    if (s->n_held == 0)
        return CM_OK;
    int rc = s->csv ? cm_csv_rows(s->csv, s->held, s->n_held, err) : CM_OK;
    if (rc == CM_OK) {
        s->n_held = s->h5_done = 0;
        s->t_written = cm_now();
    }
    return rc;
}

int cm_h5_series_hold(cm_h5_series *s, long max_rows, double seconds, cm_error *err)
{
    if (!(seconds >= 0.0))
        return cm_fail(err, CM_ERR_RANGE, "%s: series %s: hold time %g s must be >= 0", s->file->path, s->path,
                       seconds);
    int rc = s->n_held > 0 ? cm_h5_flush(s->file, err) : CM_OK;
    if (rc)
        return rc;
    long cap = max_rows > 1 ? max_rows : 1;
    double *held = realloc(s->held, (size_t)cap * (size_t)s->ncols * sizeof *held);
    if (!held)
        return cm_fail(err, CM_ERR_NOMEM, "%s: series %s: out of memory holding %ld rows", s->file->path, s->path,
                       cap);
    s->held = held;
    s->max_held = cap;
    s->hold_s = seconds;
    s->t_written = cm_now();
    return CM_OK;
}

int cm_h5_series_append(cm_h5_series *s, const double *row, cm_error *err)
{
    if (!s->held && (s->held = malloc((size_t)s->ncols * sizeof *s->held)))
        s->max_held = 1;
    if (!s->held)
        return cm_fail(err, CM_ERR_NOMEM, "%s: series %s: out of memory for a row", s->file->path, s->path);
    if (s->n_held == s->max_held) /* the last write failed and the caller went on */
        return cm_fail(err, CM_ERR_STATE, "%s: series %s: rows held after a failed write", s->file->path, s->path);
    memcpy(s->held + (size_t)s->n_held * (size_t)s->ncols, row, (size_t)s->ncols * sizeof *row);
    s->n_held++;
    if (s->n_held < s->max_held && cm_now() - s->t_written < s->hold_s)
        return CM_OK;
    return cm_h5_flush(s->file, err);
}

int cm_h5_series_flush(cm_h5_series *s, cm_error *err)
{
    return cm_h5_flush(s->file, err);
}

long cm_h5_series_rows(const cm_h5_series *s)
{
    return s ? s->rows + s->n_held - s->h5_done : 0;
}
