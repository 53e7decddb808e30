/* common/h5io: reopening a results file to resume a run, keeping the steps
 * and rows up to the checkpoint (h5io.h). */
#include "h5io_impl.h"

/* ---- resuming a run ----------------------------------------------------------- */

static int open_existing(cm_h5 *f, const char *path, int writable, cm_error *err)
{
    if (access(path, writable ? R_OK | W_OK : R_OK) != 0)
        return cm_fail(err, CM_ERR_IO, "cannot open %s: %s", path, strerror(errno));
    if ((f->fid = H5Fopen(path, writable ? H5F_ACC_RDWR : H5F_ACC_RDONLY, H5P_DEFAULT)) < 0)
        return h5io_fail(err, path, "cannot open as HDF5");
    if ((f->lcpl = H5Pcreate(H5P_LINK_CREATE)) < 0 || H5Pset_create_intermediate_group(f->lcpl, 1) < 0)
        return h5io_fail(err, path, "link creation properties");
    return CM_OK;
}

int cm_h5_open(const char *path, int writable, cm_h5 **out, cm_error *err)
{
    cm_h5 *f;
    int rc = h5io_file_new(path, NULL, &f, err);
    if (rc != CM_OK)
        return rc;
    if ((rc = open_existing(f, path, writable, err)) != CM_OK) {
        cm_h5_close(&f, NULL);
        return rc;
    }
    *out = f;
    return CM_OK;
}

typedef struct kept_step {
    long step;
    double time;
    char name[32];
} kept_step;

static int cmp_kept(const void *a, const void *b)
{
    long x = ((const kept_step *)a)->step, y = ((const kept_step *)b)->step;
    return (x > y) - (x < y);
}

static int read_attr(hid_t obj, const char *name, hid_t mtype, void *value)
{
    if (H5Aexists(obj, name) <= 0)
        return -1;
    hid_t a = H5Aopen(obj, name, H5P_DEFAULT);
    if (a < 0)
        return -1;
    herr_t st = H5Aread(a, mtype, value);
    H5Aclose(a);
    return st < 0 ? -1 : 0;
}

/* Lists the datasets of a kept step again (as h5io_step_write recorded them). */
static int relist_step(cm_h5 *f, hid_t g, const kept_step *k, cm_error *err)
{
    H5G_info_t gi;
    if (H5Gget_info(g, &gi) < 0)
        return h5io_fail(err, f->path, "listing /steps/%s", k->name);
    f->step_first = f->nfields;
    for (hsize_t i = 0; i < gi.nlinks; i++) {
        char name[NAME_MAX_LEN + 1];
        if (H5Lget_name_by_idx(g, ".", H5_INDEX_NAME, H5_ITER_INC, i, name, sizeof name, H5P_DEFAULT) < 0)
            return h5io_fail(err, f->path, "listing /steps/%s", k->name);
        char shown[sizeof k->name + NAME_MAX_LEN + 9];
        snprintf(shown, sizeof shown, "/steps/%s/%s", k->name, name);
        int rank, is_int;
        hsize_t dims[2];
        int rc = h5io_dataset_shape(f, shown, &rank, dims, &is_int, err);
        if (rc != CM_OK)
            return rc;
        int32_t center = CM_H5_UNLISTED;
        hid_t d = H5Dopen2(g, name, H5P_DEFAULT);
        if (d >= 0) {
            if (read_attr(d, "xdmf_center", H5T_NATIVE_INT32, &center) != 0 || center < 0 || center > CM_H5_CELL)
                center = CM_H5_UNLISTED;
            H5Dclose(d);
        }
        if (f->nfields == f->cap_fields) {
            size_t cap = f->cap_fields ? 2 * f->cap_fields : 16;
            field *nf = realloc(f->fields, cap * sizeof *nf);
            if (!nf)
                return cm_fail(err, CM_ERR_NOMEM, "%s: out of memory", f->path);
            f->fields = nf;
            f->cap_fields = cap;
        }
        field *fl = &f->fields[f->nfields++];
        snprintf(fl->name, sizeof fl->name, "%s", name);
        fl->is_int = is_int;
        fl->n = (size_t)dims[0];
        fl->ncomp = rank == 1 ? 1 : (int)dims[1];
        fl->center = (cm_h5_center)center;
    }
    f->step = k->step;
    f->time = k->time;
    snprintf(f->group, sizeof f->group, "/steps/%06ld", k->step);
    if (f->xdmf == CM_H5_XDMF_NONE) {
        f->nfields = f->step_first;
        return CM_OK;
    }
    size_t npoints = 0, ncells = 0;
    int rc = h5io_check_step(f, &npoints, &ncells, err);
    if (rc == CM_OK && f->nsteps == f->cap_steps) {
        size_t cap = f->cap_steps ? 2 * f->cap_steps : 64;
        step_rec *ns = realloc(f->steps, cap * sizeof *ns);
        if (!ns)
            return cm_fail(err, CM_ERR_NOMEM, "%s: out of memory", f->path);
        f->steps = ns;
        f->cap_steps = cap;
    }
    if (rc != CM_OK)
        return rc;
    f->steps[f->nsteps++] = (step_rec){.step = k->step, .time = k->time, .first = f->step_first,
                                       .count = f->nfields - f->step_first, .npoints = npoints, .ncells = ncells};
    return CM_OK;
}

static int reopen_steps(cm_h5 *f, long keep, cm_error *err)
{
    htri_t has = H5Lexists(f->fid, "/steps", H5P_DEFAULT);
    if (has < 0)
        return h5io_fail(err, f->path, "looking for /steps");
    if (has == 0)
        return CM_OK;
    hid_t g = H5Gopen2(f->fid, "/steps", H5P_DEFAULT);
    H5G_info_t gi;
    if (g < 0 || H5Gget_info(g, &gi) < 0) {
        int rc = h5io_fail(err, f->path, "opening /steps");
        if (g >= 0)
            H5Gclose(g);
        return rc;
    }
    kept_step *ks = calloc(gi.nlinks ? gi.nlinks : 1, sizeof *ks);
    size_t nk = 0;
    int rc = ks ? CM_OK : cm_fail(err, CM_ERR_NOMEM, "%s: out of memory", f->path);
    for (hsize_t i = 0; i < gi.nlinks && rc == CM_OK; i++) {
        kept_step *k = &ks[nk];
        int64_t s64 = -1;
        if (H5Lget_name_by_idx(g, ".", H5_INDEX_NAME, H5_ITER_INC, i, k->name, sizeof k->name, H5P_DEFAULT) < 0) {
            rc = h5io_fail(err, f->path, "listing /steps");
            break;
        }
        hid_t sg = H5Gopen2(g, k->name, H5P_DEFAULT);
        if (sg < 0 || read_attr(sg, "step", H5T_NATIVE_INT64, &s64) != 0 ||
            read_attr(sg, "time", H5T_NATIVE_DOUBLE, &k->time) != 0)
            rc = cm_fail(err, CM_ERR_PARSE, "%s: /steps/%s lacks its step or time attribute", f->path, k->name);
        if (sg >= 0)
            H5Gclose(sg);
        k->step = (long)s64;
        nk++;
    }
    /* Delete after listing: deleting shifts the link indices. */
    size_t kept = 0;
    for (size_t i = 0; i < nk && rc == CM_OK; i++) {
        if (ks[i].step > keep) {
            if (H5Ldelete(g, ks[i].name, H5P_DEFAULT) < 0)
                rc = h5io_fail(err, f->path, "deleting /steps/%s beyond the checkpoint", ks[i].name);
        } else {
            ks[kept++] = ks[i];
        }
    }
    if (rc == CM_OK)
        qsort(ks, kept, sizeof *ks, cmp_kept);
    if (rc == CM_OK && f->xdmf == CM_H5_XDMF_POLYVERTEX && H5Lexists(f->fid, "/xdmf/vertex_ids", H5P_DEFAULT) > 0) {
        int rank, is_int;
        hsize_t dims[2];
        if ((rc = h5io_dataset_shape(f, "/xdmf/vertex_ids", &rank, dims, &is_int, err)) == CM_OK)
            f->vertex_ids_len = (size_t)dims[0];
    }
    for (size_t i = 0; i < kept && rc == CM_OK; i++) {
        hid_t sg = H5Gopen2(g, ks[i].name, H5P_DEFAULT);
        rc = sg < 0 ? h5io_fail(err, f->path, "opening /steps/%s", ks[i].name) : relist_step(f, sg, &ks[i], err);
        if (sg >= 0)
            H5Gclose(sg);
        f->last_step = ks[i].step;
    }
    H5Gclose(g);
    free(ks);
    return rc;
}

int cm_h5_reopen(const char *path, const cm_h5_def *def, long keep_through_step, cm_h5 **out, cm_error *err)
{
    *out = NULL;
    cm_h5 *f;
    int rc = h5io_file_new(path, def, &f, err);
    if (rc != CM_OK)
        return rc;
    if ((rc = open_existing(f, path, 1, err)) == CM_OK && (rc = reopen_steps(f, keep_through_step, err)) == CM_OK &&
        (rc = cm_h5_flush(f, err)) == CM_OK && f->xdmf != CM_H5_XDMF_NONE)
        rc = h5io_write_xdmf(f, err);
    if (rc != CM_OK) {
        cm_h5_close(&f, NULL);
        return rc;
    }
    *out = f;
    return CM_OK;
}

int cm_h5_series_reopen(cm_h5 *f, const char *path, const char *const *columns, int ncols, const char *csv_path,
                        long rows, cm_h5_series **out, cm_error *err)
{
    *out = NULL;
    if (!h5io_abs_path_ok(path) || ncols < 1 || !columns || rows < 0)
        return cm_fail(err, CM_ERR_RANGE, "%s: series %s: bad arguments to reopen", f->path, path ? path : "(null)");
    cm_h5_series *s = calloc(1, sizeof *s);
    if (!s || !(s->path = strdup(path))) {
        free(s);
        return cm_fail(err, CM_ERR_NOMEM, "%s: series %s: out of memory", f->path, path);
    }
    s->file = f;
    s->ncols = ncols;
    s->dset = s->memtype = H5I_INVALID_HID;
    int rc = CM_OK;
    if ((s->dset = H5Dopen2(f->fid, path, H5P_DEFAULT)) < 0)
        rc = h5io_fail(err, f->path, "opening series %s", path);
    hid_t ft = rc == CM_OK ? H5Dget_type(s->dset) : H5I_INVALID_HID;
    if (rc == CM_OK && (ft < 0 || H5Tget_class(ft) != H5T_COMPOUND || H5Tget_nmembers(ft) != ncols))
        rc = cm_fail(err, CM_ERR_PARSE, "%s: series %s is not a table of %d columns", f->path, path, ncols);
    if (ft >= 0)
        H5Tclose(ft);
    if (rc == CM_OK && (s->memtype = H5Tcreate(H5T_COMPOUND, sizeof(double) * (size_t)ncols)) < 0)
        rc = h5io_fail(err, f->path, "series %s: row type", path);
    for (int i = 0; i < ncols && rc == CM_OK; i++)
        if (H5Tinsert(s->memtype, columns[i], sizeof(double) * (size_t)i, H5T_NATIVE_DOUBLE) < 0)
            rc = h5io_fail(err, f->path, "series %s: column %s", path, columns[i]);
    hsize_t have = 0, want = (hsize_t)rows;
    if (rc == CM_OK) {
        hid_t sp = H5Dget_space(s->dset);
        if (sp < 0 || H5Sget_simple_extent_dims(sp, &have, NULL) != 1)
            rc = h5io_fail(err, f->path, "series %s: extent", path);
        if (sp >= 0)
            H5Sclose(sp);
    }
    if (rc == CM_OK && have < want)
        rc = cm_fail(err, CM_ERR_IO, "%s: series %s holds %llu rows, the checkpoint expects %ld", f->path, path,
                     (unsigned long long)have, rows);
    if (rc == CM_OK && H5Dset_extent(s->dset, &want) < 0)
        rc = h5io_fail(err, f->path, "series %s: cutting back to %ld rows", path, rows);
    if (rc == CM_OK && csv_path)
        rc = cm_csv_reopen(csv_path, ncols, rows, &s->csv, err);
    if (rc == CM_OK)
        s->rows = rows;
    return h5io_series_adopt(f, s, rc, out, err);
}
