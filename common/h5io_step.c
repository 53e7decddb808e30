/* common/h5io: snapshots, one /steps/NNNNNN group per step (h5io.h). */
#include "h5io_impl.h"

/* ---- snapshots ---------------------------------------------------------------- */

/* /steps is created with room for the names of 4096 steps in its local
 * heap: a heap that outgrows its block is moved to a new address, and a
 * process killed between the write of the group's header (pointing to the
 * new block) and the end of that flush leaves every step unreachable, the
 * kept ones included (cm_h5_reopen cannot step over that damage). A block
 * with room is rewritten in place instead. 4096 x 8 bytes (a 6-digit name
 * and its padding) is 32 KiB. */
int h5io_create_steps_group(hid_t loc, const char *file, cm_error *err)
{
    hid_t gcpl = H5Pcreate(H5P_GROUP_CREATE), g = H5I_INVALID_HID;
    int rc = CM_OK;
    if (gcpl < 0 || H5Pset_local_heap_size_hint(gcpl, 4096 * 8) < 0 ||
        (g = H5Gcreate2(loc, "steps", H5P_DEFAULT, gcpl, H5P_DEFAULT)) < 0)
        rc = h5io_fail(err, file, "creating group /steps");
    if (g >= 0)
        H5Gclose(g);
    if (gcpl >= 0)
        H5Pclose(gcpl);
    return rc;
}

static int ensure_steps_group(cm_h5 *f, cm_error *err)
{
    if (f->steps_group)
        return CM_OK;
    htri_t has = H5Lexists(f->fid, "/steps", H5P_DEFAULT);
    if (has < 0)
        return h5io_fail(err, f->path, "looking for /steps");
    int rc = has ? CM_OK : h5io_create_steps_group(f->fid, f->path, err);
    f->steps_group = rc == CM_OK;
    return rc;
}

int cm_h5_step_begin(cm_h5 *f, long step, double time, cm_error *err)
{
    if (f->in_step)
        return cm_fail(err, CM_ERR_STATE, "%s: step %ld begun while step %ld is still open", f->path, step,
                       f->step);
    if (step < 0 || step <= f->last_step)
        return cm_fail(err, CM_ERR_STATE, "%s: step %ld does not follow step %ld (steps must increase)", f->path,
                       step, f->last_step);
    int rc = ensure_steps_group(f, err);
    if (rc != CM_OK)
        return rc;
    snprintf(f->group, sizeof f->group, "/steps/%06ld", step);
    f->gid = H5Gcreate2(f->fid, f->group, f->lcpl, H5P_DEFAULT, H5P_DEFAULT);
    if (f->gid < 0)
        return h5io_fail(err, f->path, "creating group %s", f->group);
    int64_t s64 = step;
    rc = h5io_write_attr(f, f->gid, f->group, "time", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, &time, err);
    if (rc == CM_OK)
        rc = h5io_write_attr(f, f->gid, f->group, "step", H5T_STD_I64LE, H5T_NATIVE_INT64, &s64, err);
    if (rc != CM_OK) {
        H5Gclose(f->gid);
        f->gid = H5I_INVALID_HID;
        return rc;
    }
    f->in_step = 1;
    f->step = step;
    f->last_step = step;
    f->time = time;
    f->step_first = f->nfields;
    return CM_OK;
}

int h5io_step_write(cm_h5 *f, const char *name, cm_h5_center center, int is_int, const void *data, size_t n,
                      int ncomp, cm_error *err)
{
    if (!f->in_step)
        return cm_fail(err, CM_ERR_STATE, "%s: dataset %s written outside cm_h5_step_begin/end", f->path,
                       name ? name : "(null)");
    if (!h5io_simple_name_ok(name))
        return cm_fail(err, CM_ERR_RANGE, "%s: %s: dataset name \"%s\" must be letters, digits, \"_.-+\"",
                       f->path, f->group, name ? name : "(null)");
    char shown[sizeof f->group + NAME_MAX_LEN + 2];
    snprintf(shown, sizeof shown, "%s/%s", f->group, name);
    if (center != CM_H5_UNLISTED && center != CM_H5_NODE && center != CM_H5_CELL)
        return cm_fail(err, CM_ERR_RANGE, "%s: dataset %s: unknown center %d", f->path, shown, (int)center);
    if (center != CM_H5_UNLISTED && ncomp != 1 && ncomp != 3 && ncomp != 6 && ncomp != 9)
        return cm_fail(err, CM_ERR_RANGE, "%s: dataset %s: an XDMF attribute has 1, 3, 6 or 9 components, not "
                       "%d (use CM_H5_UNLISTED)", f->path, shown, ncomp);
    for (size_t i = f->step_first; i < f->nfields; i++)
        if (strcmp(f->fields[i].name, name) == 0)
            return cm_fail(err, CM_ERR_STATE, "%s: dataset %s written twice", f->path, shown);
    if (f->nfields == f->cap_fields) {
        size_t cap = f->cap_fields ? 2 * f->cap_fields : 16;
        field *nf = realloc(f->fields, cap * sizeof *nf);
        if (!nf)
            return cm_fail(err, CM_ERR_NOMEM, "%s: dataset %s: out of memory", f->path, shown);
        f->fields = nf;
        f->cap_fields = cap;
    }
    int rc = h5io_write_array(f, f->gid, name, shown, is_int, data, n, ncomp, err);
    if (rc == CM_OK) { /* how the XDMF lists it, for cm_h5_reopen */
        hid_t d = H5Dopen2(f->gid, name, H5P_DEFAULT);
        int32_t c32 = (int32_t)center;
        rc = d < 0 ? h5io_fail(err, f->path, "reopening dataset %s", shown)
                   : h5io_write_attr(f, d, shown, "xdmf_center", H5T_STD_I32LE, H5T_NATIVE_INT32, &c32, err);
        if (d >= 0)
            H5Dclose(d);
    }
    if (rc != CM_OK)
        return rc;
    field *fl = &f->fields[f->nfields++];
    snprintf(fl->name, sizeof fl->name, "%s", name);
    fl->is_int = is_int;
    fl->n = n;
    fl->ncomp = ncomp;
    fl->center = center;
    return CM_OK;
}

int cm_h5_step_doubles(cm_h5 *f, const char *name, cm_h5_center center, const double *data, size_t n,
                       int ncomp, cm_error *err)
{
    return h5io_step_write(f, name, center, 0, data, n, ncomp, err);
}

int cm_h5_step_ints(cm_h5 *f, const char *name, cm_h5_center center, const int *data, size_t n, int ncomp,
                    cm_error *err)
{
    return h5io_step_write(f, name, center, 1, data, n, ncomp, err);
}

/* /xdmf/vertex_ids holds 0..len-1 with len >= n: the Polyvertex connectivity. */
static int ensure_vertex_ids(cm_h5 *f, size_t n, cm_error *err)
{
    static const char *const path = "/xdmf/vertex_ids";
    if (n <= f->vertex_ids_len && f->vertex_ids_len > 0)
        return CM_OK;
    int rc = CM_OK;
    hid_t d = H5I_INVALID_HID, fs = H5I_INVALID_HID, ms = H5I_INVALID_HID;
    size_t old = f->vertex_ids_len;
    hsize_t want = n > 0 ? n : 1;
    int *ids = malloc((size_t)(want - old) * sizeof *ids);
    if (!ids)
        return cm_fail(err, CM_ERR_NOMEM, "%s: %s: out of memory", f->path, path);
    for (size_t i = old; i < want; i++)
        ids[i - old] = (int)i;
    if (old == 0) {
        hsize_t zero = 0, unlimited = H5S_UNLIMITED, chunk = 4096;
        hid_t space = H5Screate_simple(1, &zero, &unlimited);
        hid_t dcpl = H5Pcreate(H5P_DATASET_CREATE);
        if (space < 0 || dcpl < 0 || H5Pset_chunk(dcpl, 1, &chunk) < 0 ||
            (d = H5Dcreate2(f->fid, path, H5T_STD_I32LE, space, f->lcpl, dcpl, H5P_DEFAULT)) < 0)
            rc = h5io_fail(err, f->path, "creating dataset %s", path);
        if (dcpl >= 0)
            H5Pclose(dcpl);
        if (space >= 0)
            H5Sclose(space);
    } else if ((d = H5Dopen2(f->fid, path, H5P_DEFAULT)) < 0) {
        rc = h5io_fail(err, f->path, "opening dataset %s", path);
    }
    hsize_t start = old, count = want - old;
    if (rc == CM_OK && (H5Dset_extent(d, &want) < 0 || (fs = H5Dget_space(d)) < 0 ||
                        H5Sselect_hyperslab(fs, H5S_SELECT_SET, &start, NULL, &count, NULL) < 0 ||
                        (ms = H5Screate_simple(1, &count, NULL)) < 0 ||
                        H5Dwrite(d, H5T_NATIVE_INT, ms, fs, H5P_DEFAULT, ids) < 0))
        rc = h5io_fail(err, f->path, "writing dataset %s", path);
    if (ms >= 0)
        H5Sclose(ms);
    if (fs >= 0)
        H5Sclose(fs);
    if (d >= 0)
        H5Dclose(d);
    free(ids);
    if (rc == CM_OK)
        f->vertex_ids_len = want;
    return rc;
}

static int missing_static(cm_h5 *f, const char *role, const char *path, cm_error *err)
{
    char why[sizeof err->msg];
    snprintf(why, sizeof why, "%s", err ? err->msg : "");
    return cm_fail(err, CM_ERR_STATE, "%s: XDMF %s %s must be written before the first step ends (%s)", f->path,
                   role, path, why);
}

/* Looks up the static datasets the XDMF grid refers to (once). */
static int static_sizes(cm_h5 *f, cm_error *err)
{
    int rank, is_int;
    hsize_t dims[2];
    if (f->geometry_static && f->static_points == 0) {
        if (h5io_dataset_shape(f, f->geometry, &rank, dims, &is_int, err) != CM_OK)
            return missing_static(f, "geometry", f->geometry, err);
        if (rank != 2 || dims[1] != 3 || is_int)
            return cm_fail(err, CM_ERR_RANGE, "%s: XDMF geometry %s must be n x 3 doubles", f->path, f->geometry);
        f->static_points = (size_t)dims[0];
    }
    if (f->xdmf == CM_H5_XDMF_TETRAHEDRON && f->cells == 0) {
        if (h5io_dataset_shape(f, f->connectivity, &rank, dims, &is_int, err) != CM_OK)
            return missing_static(f, "connectivity", f->connectivity, err);
        if (rank != 2 || dims[1] != 4 || !is_int)
            return cm_fail(err, CM_ERR_RANGE, "%s: XDMF connectivity %s must be m x 4 ints", f->path,
                           f->connectivity);
        f->cells = (size_t)dims[0];
    }
    return CM_OK;
}

/* Checks the current step against the grid; fills npoints / ncells. */
int h5io_check_step(cm_h5 *f, size_t *npoints, size_t *ncells, cm_error *err)
{
    int rc = static_sizes(f, err);
    if (rc != CM_OK)
        return rc;
    if (f->geometry_static) {
        *npoints = f->static_points;
    } else {
        const field *g = NULL;
        for (size_t i = f->step_first; i < f->nfields; i++)
            if (strcmp(f->fields[i].name, f->geometry) == 0)
                g = &f->fields[i];
        if (!g)
            return cm_fail(err, CM_ERR_STATE, "%s: step %s has no geometry dataset \"%s\"", f->path, f->group,
                           f->geometry);
        if (g->is_int || g->ncomp != 3)
            return cm_fail(err, CM_ERR_RANGE, "%s: geometry %s/%s must be n x 3 doubles", f->path, f->group,
                           f->geometry);
        *npoints = g->n;
    }
    *ncells = f->xdmf == CM_H5_XDMF_TETRAHEDRON ? f->cells : *npoints;
    for (size_t i = f->step_first; i < f->nfields; i++) {
        const field *fl = &f->fields[i];
        if (fl->center == CM_H5_UNLISTED || (!f->geometry_static && strcmp(fl->name, f->geometry) == 0))
            continue;
        size_t want = fl->center == CM_H5_NODE ? *npoints : *ncells;
        if (fl->n != want)
            return cm_fail(err, CM_ERR_RANGE, "%s: %s/%s has %zu rows, the grid has %zu %s", f->path, f->group,
                           fl->name, fl->n, want, fl->center == CM_H5_NODE ? "points" : "cells");
    }
    if (f->xdmf == CM_H5_XDMF_POLYVERTEX)
        return ensure_vertex_ids(f, *npoints, err);
    return CM_OK;
}

int cm_h5_step_end(cm_h5 *f, cm_error *err)
{
    if (!f->in_step)
        return cm_fail(err, CM_ERR_STATE, "%s: cm_h5_step_end without cm_h5_step_begin", f->path);
    f->in_step = 0;
    H5Gclose(f->gid);
    f->gid = H5I_INVALID_HID;
    /* The step's data is made durable even if the XDMF check below fails. */
    int rc = cm_h5_flush(f, err);
    if (rc != CM_OK || f->xdmf == CM_H5_XDMF_NONE) {
        f->nfields = f->step_first; /* nothing to list in an XDMF */
        return rc;
    }
    size_t npoints = 0, ncells = 0;
    rc = h5io_check_step(f, &npoints, &ncells, err);
    if (rc == CM_OK && f->nsteps == f->cap_steps) {
        size_t cap = f->cap_steps ? 2 * f->cap_steps : 64;
        step_rec *ns = realloc(f->steps, cap * sizeof *ns);
        if (!ns)
            rc = cm_fail(err, CM_ERR_NOMEM, "%s: out of memory", f->path);
        else {
            f->steps = ns;
            f->cap_steps = cap;
        }
    }
    if (rc != CM_OK) {
        f->nfields = f->step_first; /* left out of the XDMF */
        return rc;
    }
    f->steps[f->nsteps++] = (step_rec){.step = f->step, .time = f->time, .first = f->step_first,
                                       .count = f->nfields - f->step_first, .npoints = npoints, .ncells = ncells};
    /* vertex ids may have been created or extended by h5io_check_step */
    if ((rc = cm_h5_flush(f, err)) != CM_OK)
        return rc;
    return h5io_xdmf_append(f, err);
}
