/* HDF5 results files with an XDMF 3 index; see h5io.h for the layout and
 * h5io_impl.h for how the code is split. Here: HDF5 errors, names, small
 * HDF5 helpers, the file's life, static datasets and attributes, raw typed
 * arrays. */
#include "h5io_impl.h"

/* ---- HDF5 errors ---------------------------------------------------------- */

typedef struct reason {
    char s[320];
} reason;

static herr_t walk_cb(unsigned n, const H5E_error2_t *e, void *data)
{
    reason *r = data;
    /* Walking upward, n == 0 is the innermost (most specific) error. */
    if (n == 0 && e->desc)
        snprintf(r->s, sizeof r->s, "%s", e->desc);
    return 0;
}

/* Fails with "<file>: <what>: <HDF5's innermost reason>". Call it right
 * after the failing HDF5 call: any later HDF5 call clears the stack. */
int h5io_fail(cm_error *err, const char *file, const char *fmt, ...)
{
    reason r = {{0}};
    H5Ewalk2(H5E_DEFAULT, H5E_WALK_UPWARD, walk_cb, &r);
    /* A failed write's reason is a long multi-line record ("file write
     * failed: time = ..., errno = 27, error message = 'File too large', ..."):
     * keep the system's message, or the first clause. */
    const char *sys = strstr(r.s, "error message = '");
    if (sys) {
        char msg[128];
        snprintf(msg, sizeof msg, "%s", sys + strlen("error message = '"));
        char *q = strchr(msg, '\'');
        if (q)
            *q = '\0';
        char *cut = strstr(r.s, ": time =");
        if (cut)
            *cut = '\0';
        size_t len = strlen(r.s);
        snprintf(r.s + len, sizeof r.s - len, " (%s)", msg);
    } else {
        r.s[strcspn(r.s, "\n")] = '\0';
    }
    char what[512];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(what, sizeof what, fmt, ap);
    va_end(ap);
    return cm_fail(err, CM_ERR_IO, "%s: %s: %s", file, what, r.s[0] ? r.s : "HDF5 error");
}

/* ---- names ------------------------------------------------------------------ */

/* A dataset, group, attribute or column name: safe in HDF5 paths, XML and CSV. */
static int name_ok(const char *s, size_t len)
{
    if (len == 0 || len > NAME_MAX_LEN)
        return 0;
    if ((len == 1 && s[0] == '.') || (len == 2 && s[0] == '.' && s[1] == '.'))
        return 0;
    for (size_t i = 0; i < len; i++)
        if (!isalnum((unsigned char)s[i]) && !strchr("_.-+", s[i]))
            return 0;
    return 1;
}

int h5io_simple_name_ok(const char *s)
{
    return s && name_ok(s, strlen(s));
}

/* "/a/b/c": absolute, non-empty valid components. */
int h5io_abs_path_ok(const char *p)
{
    if (!p || p[0] != '/' || p[1] == '\0')
        return 0;
    const char *c = p + 1;
    for (;;) {
        const char *slash = strchr(c, '/');
        size_t len = slash ? (size_t)(slash - c) : strlen(c);
        if (!name_ok(c, len))
            return 0;
        if (!slash)
            return 1;
        c = slash + 1;
    }
}

/* ---- small HDF5 helpers -------------------------------------------------------- */

static int write_typed(cm_h5 *f, hid_t loc, const char *name, const char *shown, hid_t ftype, hid_t mtype,
                       const void *data, size_t n, int ncomp, cm_error *err)
{
    if (ncomp < 1 || (n > 0 && !data))
        return cm_fail(err, CM_ERR_RANGE, "%s: dataset %s: need ncomp >= 1 and data for %zu rows", f->path,
                       shown, n);
    hsize_t dims[2] = {(hsize_t)n, (hsize_t)ncomp};
    hid_t space = H5Screate_simple(ncomp == 1 ? 1 : 2, dims, NULL);
    if (space < 0)
        return h5io_fail(err, f->path, "dataset %s: dataspace of %zu x %d", shown, n, ncomp);
    int rc = CM_OK;
    hid_t d = H5Dcreate2(loc, name, ftype, space, f->lcpl, H5P_DEFAULT, H5P_DEFAULT);
    if (d < 0)
        rc = h5io_fail(err, f->path, "creating dataset %s", shown);
    else if (n > 0 && H5Dwrite(d, mtype, H5S_ALL, H5S_ALL, H5P_DEFAULT, data) < 0)
        rc = h5io_fail(err, f->path, "writing dataset %s", shown);
    if (d >= 0)
        H5Dclose(d);
    H5Sclose(space);
    return rc;
}

int h5io_write_array(cm_h5 *f, hid_t loc, const char *name, const char *shown, int is_int, const void *data,
                       size_t n, int ncomp, cm_error *err)
{
    return write_typed(f, loc, name, shown, is_int ? H5T_STD_I32LE : H5T_IEEE_F64LE,
                       is_int ? H5T_NATIVE_INT : H5T_NATIVE_DOUBLE, data, n, ncomp, err);
}

int h5io_write_attr(cm_h5 *f, hid_t obj, const char *shown, const char *name, hid_t ftype, hid_t mtype,
                      const void *value, cm_error *err)
{
    htri_t ex = H5Aexists(obj, name);
    if (ex < 0)
        return h5io_fail(err, f->path, "attribute %s of %s", name, shown);
    if (ex > 0 && H5Adelete(obj, name) < 0)
        return h5io_fail(err, f->path, "replacing attribute %s of %s", name, shown);
    hid_t space = H5Screate(H5S_SCALAR);
    if (space < 0)
        return h5io_fail(err, f->path, "attribute %s of %s: dataspace", name, shown);
    int rc = CM_OK;
    hid_t a = H5Acreate2(obj, name, ftype, space, H5P_DEFAULT, H5P_DEFAULT);
    if (a < 0)
        rc = h5io_fail(err, f->path, "creating attribute %s of %s", name, shown);
    else if (H5Awrite(a, mtype, value) < 0)
        rc = h5io_fail(err, f->path, "writing attribute %s of %s", name, shown);
    if (a >= 0)
        H5Aclose(a);
    H5Sclose(space);
    return rc;
}

/* Rank, dimensions and integer-ness of an existing dataset. */
int h5io_dataset_shape(cm_h5 *f, const char *path, int *rank, hsize_t dims[2], int *is_int, cm_error *err)
{
    hid_t d = H5Dopen2(f->fid, path, H5P_DEFAULT);
    if (d < 0)
        return h5io_fail(err, f->path, "opening dataset %s", path);
    int rc = CM_OK;
    hid_t s = H5Dget_space(d), t = H5Dget_type(d);
    int r = s < 0 ? -1 : H5Sget_simple_extent_ndims(s);
    if (t < 0 || r < 1 || r > 2) {
        rc = cm_fail(err, CM_ERR_PARSE, "%s: dataset %s: expected a 1-D or 2-D array", f->path, path);
    } else {
        dims[1] = 1;
        H5Sget_simple_extent_dims(s, dims, NULL);
        *rank = r;
        *is_int = H5Tget_class(t) == H5T_INTEGER && H5Tget_size(t) == 4;
    }
    if (t >= 0)
        H5Tclose(t);
    if (s >= 0)
        H5Sclose(s);
    H5Dclose(d);
    return rc;
}

/* ---- file ---------------------------------------------------------------------- */

void cm_h5_library_init(void)
{
    H5dont_atexit();
    H5Eset_auto2(H5E_DEFAULT, NULL, NULL);
}

cm_h5_def cm_h5_default_def(void)
{
    return (cm_h5_def){
        .xdmf = CM_H5_XDMF_NONE,
        .grid_name = "grid",
        .geometry = "position",
        .connectivity = "/mesh/connectivity",
    };
}

static void free_file(cm_h5 *f)
{
    if (f->xmf_fd >= 0)
        close(f->xmf_fd);
    free(f->path);
    free(f->xmf_path);
    free(f->grid_name);
    free(f->geometry);
    free(f->connectivity);
    free(f->fields);
    free(f->steps);
    free(f);
}

static char *make_xmf_path(const char *path)
{
    size_t len = strlen(path);
    const char *base = strrchr(path, '/');
    base = base ? base + 1 : path;
    static const char *const suffixes[] = {".h5", ".hdf5", ".hdf"};
    for (int i = 0; i < 3; i++) {
        size_t sl = strlen(suffixes[i]);
        if (len > sl && (size_t)(path + len - base) > sl && strcmp(path + len - sl, suffixes[i]) == 0) {
            len -= sl;
            break;
        }
    }
    char *x = malloc(len + 5);
    if (x) {
        memcpy(x, path, len);
        memcpy(x + len, ".xmf", 5);
    }
    return x;
}

/* Checks def and allocates the handle (no HDF5 file yet). */
int h5io_file_new(const char *path, const cm_h5_def *def_in, cm_h5 **out, cm_error *err)
{
    *out = NULL;
    cm_h5_def def = def_in ? *def_in : cm_h5_default_def();
    if (!path || !*path)
        return cm_fail(err, CM_ERR_RANGE, "results file: empty path");
    if (def.xdmf != CM_H5_XDMF_NONE) {
        if (!def.grid_name || !h5io_simple_name_ok(def.grid_name))
            return cm_fail(err, CM_ERR_RANGE, "%s: XDMF grid name \"%s\" must be letters, digits, \"_.-+\"", path,
                           def.grid_name ? def.grid_name : "(null)");
        if (!def.geometry || (!h5io_simple_name_ok(def.geometry) && !h5io_abs_path_ok(def.geometry)))
            return cm_fail(err, CM_ERR_RANGE, "%s: XDMF geometry \"%s\" is neither a step dataset name nor an "
                           "absolute dataset path", path, def.geometry ? def.geometry : "(null)");
        if (def.xdmf == CM_H5_XDMF_TETRAHEDRON && !h5io_abs_path_ok(def.connectivity))
            return cm_fail(err, CM_ERR_RANGE, "%s: XDMF connectivity \"%s\" must be an absolute dataset path",
                           path, def.connectivity ? def.connectivity : "(null)");
        if (def.xdmf != CM_H5_XDMF_POLYVERTEX && def.xdmf != CM_H5_XDMF_TETRAHEDRON)
            return cm_fail(err, CM_ERR_RANGE, "%s: unknown XDMF grid kind %d", path, (int)def.xdmf);
    }

    H5Eset_auto2(H5E_DEFAULT, NULL, NULL);

    cm_h5 *f = calloc(1, sizeof *f);
    if (!f)
        return cm_fail(err, CM_ERR_NOMEM, "%s: out of memory", path);
    f->fid = f->lcpl = H5I_INVALID_HID;
    f->gid = H5I_INVALID_HID;
    f->xmf_fd = -1;
    f->last_step = -1;
    f->xdmf = def.xdmf;
    f->path = strdup(path);
    int oom = !f->path;
    if (def.xdmf != CM_H5_XDMF_NONE) {
        f->xmf_path = make_xmf_path(path);
        f->grid_name = strdup(def.grid_name);
        f->geometry = strdup(def.geometry);
        f->connectivity = def.connectivity ? strdup(def.connectivity) : NULL;
        oom |= !f->xmf_path || !f->grid_name || !f->geometry || (def.connectivity && !f->connectivity);
        f->geometry_static = def.geometry[0] == '/';
    }
    if (oom) {
        free_file(f);
        return cm_fail(err, CM_ERR_NOMEM, "%s: out of memory", path);
    }
    const char *slash = strrchr(f->path, '/');
    f->base = slash ? slash + 1 : f->path;

    *out = f;
    return CM_OK;
}

/* Symbol-table nodes of 64 links instead of HDF5's 8: /steps splits a full
 * node when a step is added, and a process killed while a split is half
 * written can leave its B-tree pointing to a node never written, with kept
 * steps in it (the one damage cm_h5_reopen cannot step over): one step in
 * 32 instead of one in 4 opens that window. Costs 2.2 KiB more per group
 * (each step is one). */
int h5io_create_file(const char *path, const char *what, hid_t *fid, cm_error *err)
{
    hid_t fcpl = H5Pcreate(H5P_FILE_CREATE);
    int rc = CM_OK;
    if (fcpl < 0 || H5Pset_sym_k(fcpl, 16, 32) < 0 ||
        (*fid = H5Fcreate(path, H5F_ACC_TRUNC, fcpl, H5P_DEFAULT)) < 0)
        rc = h5io_fail(err, path, "%s", what); /* before H5Pclose clears HDF5's reason */
    if (fcpl >= 0)
        H5Pclose(fcpl);
    return rc;
}

int cm_h5_create(const char *path, const cm_h5_def *def_in, cm_h5 **out, cm_error *err)
{
    *out = NULL;
    cm_h5 *f;
    int rc = h5io_file_new(path, def_in, &f, err);
    if (rc != CM_OK)
        return rc;
    /* Open the file ourselves first: the system's reason ("No such file or
     * directory") is clearer than HDF5's error stack. No O_TRUNC: truncating
     * is left to H5Fcreate. */
    int fd = open(path, O_WRONLY | O_CREAT, 0644);
    if (fd < 0) {
        rc = cm_fail(err, CM_ERR_IO, "cannot create results file %s: %s", path, strerror(errno));
        free_file(f);
        return rc;
    }
    close(fd);
    /* Default file access: a reader in this process (H5Fopen with default
     * properties) shares the open file; a different close degree would make
     * it fail ("file close degree doesn't match"). */
    rc = h5io_create_file(path, "cannot create results file", &f->fid, err);
    if (rc == CM_OK && ((f->lcpl = H5Pcreate(H5P_LINK_CREATE)) < 0 ||
                        H5Pset_create_intermediate_group(f->lcpl, 1) < 0))
        rc = h5io_fail(err, path, "link creation properties");
    if (rc != CM_OK) {
        if (f->lcpl >= 0)
            H5Pclose(f->lcpl);
        if (f->fid >= 0)
            H5Fclose(f->fid);
        free_file(f);
        return rc;
    }
    *out = f;
    return CM_OK;
}

int cm_h5_close(cm_h5 **fp, cm_error *err)
{
    if (!fp || !*fp)
        return CM_OK;
    cm_h5 *f = *fp;
    int rc = CM_OK;
    int held = 0;
    for (cm_h5_series *s = f->series; s; s = s->next)
        held |= s->n_held > 0;
    if (held) /* the rows a series still holds */
        rc = cm_h5_flush(f, err);
    while (f->series) {
        cm_h5_series *s = f->series;
        f->series = s->next;
        cm_error e2 = {0};
        if (cm_csv_close(&s->csv, &e2) != CM_OK && rc == CM_OK)
            rc = cm_fail(err, e2.code, "%s", e2.msg);
        H5Dclose(s->dset);
        H5Tclose(s->memtype);
        h5io_series_free(s);
    }
    if (f->gid >= 0)
        H5Gclose(f->gid);
    if (f->lcpl >= 0)
        H5Pclose(f->lcpl);
    if (H5Fclose(f->fid) < 0 && rc == CM_OK)
        rc = h5io_fail(err, f->path, "closing results file");
    free_file(f);
    *fp = NULL;
    return rc;
}

int cm_h5_flush(cm_h5 *f, cm_error *err)
{
    int rc = CM_OK;
    for (cm_h5_series *s = f->series; s && rc == CM_OK; s = s->next)
        rc = h5io_series_write_held(s, err);
    if (rc == CM_OK && H5Fflush(f->fid, H5F_SCOPE_LOCAL) < 0)
        rc = h5io_fail(err, f->path, "flushing results file");
    for (cm_h5_series *s = f->series; s && rc == CM_OK; s = s->next)
        rc = h5io_series_csv_held(s, err);
    return rc;
}

const char *cm_h5_path(const cm_h5 *f)
{
    return f ? f->path : NULL;
}

const char *cm_h5_xdmf_path(const cm_h5 *f)
{
    return f ? f->xmf_path : NULL;
}

/* ---- static datasets and attributes ------------------------------------------- */

int cm_h5_write_doubles(cm_h5 *f, const char *path, const double *data, size_t n, int ncomp, cm_error *err)
{
    if (!h5io_abs_path_ok(path))
        return cm_fail(err, CM_ERR_RANGE, "%s: dataset path \"%s\" must be absolute, with components of "
                       "letters, digits and \"_.-+\"", f->path, path ? path : "(null)");
    return h5io_write_array(f, f->fid, path, path, 0, data, n, ncomp, err);
}

int cm_h5_write_ints(cm_h5 *f, const char *path, const int *data, size_t n, int ncomp, cm_error *err)
{
    if (!h5io_abs_path_ok(path))
        return cm_fail(err, CM_ERR_RANGE, "%s: dataset path \"%s\" must be absolute, with components of "
                       "letters, digits and \"_.-+\"", f->path, path ? path : "(null)");
    return h5io_write_array(f, f->fid, path, path, 1, data, n, ncomp, err);
}

static int attr_common(cm_h5 *f, const char *object, const char *name, hid_t ftype, hid_t mtype,
                       const void *value, cm_error *err)
{
    if (!object || !h5io_simple_name_ok(name))
        return cm_fail(err, CM_ERR_RANGE, "%s: attribute name \"%s\" must be letters, digits, \"_.-+\"", f->path,
                       name ? name : "(null)");
    hid_t obj = H5Oopen(f->fid, object, H5P_DEFAULT);
    if (obj < 0)
        return h5io_fail(err, f->path, "opening %s for attribute %s", object, name);
    int rc = h5io_write_attr(f, obj, object, name, ftype, mtype, value, err);
    H5Oclose(obj);
    return rc;
}

int cm_h5_attr_double(cm_h5 *f, const char *object, const char *name, double value, cm_error *err)
{
    return attr_common(f, object, name, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, &value, err);
}

int cm_h5_attr_string(cm_h5 *f, const char *object, const char *name, const char *value, cm_error *err)
{
    hid_t t = H5Tcopy(H5T_C_S1);
    if (t < 0 || H5Tset_size(t, H5T_VARIABLE) < 0 || H5Tset_cset(t, H5T_CSET_UTF8) < 0) {
        int rc = h5io_fail(err, f->path, "string type for attribute %s", name ? name : "(null)");
        if (t >= 0)
            H5Tclose(t);
        return rc;
    }
    const char *v = value ? value : "";
    int rc = attr_common(f, object, name, t, t, &v, err);
    H5Tclose(t);
    return rc;
}

/* ---- raw typed arrays ---------------------------------------------------------- */

static void h5_types(cm_h5_type t, hid_t *ftype, hid_t *mtype)
{
    switch (t) {
    case CM_H5_I32: *ftype = H5T_STD_I32LE, *mtype = H5T_NATIVE_INT32; break;
    case CM_H5_U32: *ftype = H5T_STD_U32LE, *mtype = H5T_NATIVE_UINT32; break;
    case CM_H5_I64: *ftype = H5T_STD_I64LE, *mtype = H5T_NATIVE_INT64; break;
    case CM_H5_U64: *ftype = H5T_STD_U64LE, *mtype = H5T_NATIVE_UINT64; break;
    default: *ftype = H5T_IEEE_F64LE, *mtype = H5T_NATIVE_DOUBLE; break;
    }
}

int cm_h5_write_array(cm_h5 *f, const char *path, cm_h5_type type, const void *data, size_t n, int ncomp,
                      cm_error *err)
{
    if (!h5io_abs_path_ok(path))
        return cm_fail(err, CM_ERR_RANGE, "%s: dataset path \"%s\" must be absolute, with components of "
                       "letters, digits and \"_.-+\"", f->path, path ? path : "(null)");
    hid_t ft, mt;
    h5_types(type, &ft, &mt);
    return write_typed(f, f->fid, path, path, ft, mt, data, n, ncomp, err);
}

int cm_h5_read_array(cm_h5 *f, const char *path, cm_h5_type type, void *data, size_t n, int ncomp, cm_error *err)
{
    hid_t ft, mt;
    h5_types(type, &ft, &mt);
    hid_t d = H5Dopen2(f->fid, path, H5P_DEFAULT);
    if (d < 0)
        return h5io_fail(err, f->path, "no dataset %s", path);
    int rc = CM_OK;
    hid_t s = H5Dget_space(d), t = H5Dget_type(d);
    hsize_t dims[2] = {0, 1};
    int rank = s < 0 ? -1 : H5Sget_simple_extent_ndims(s);
    if (rank >= 1 && rank <= 2)
        H5Sget_simple_extent_dims(s, dims, NULL);
    if (t < 0 || H5Tequal(t, ft) <= 0)
        rc = cm_fail(err, CM_ERR_PARSE, "%s: dataset %s has another element type than expected", f->path, path);
    else if (rank != (ncomp == 1 ? 1 : 2) || dims[0] != (hsize_t)n || dims[1] != (hsize_t)ncomp)
        rc = cm_fail(err, CM_ERR_PARSE, "%s: dataset %s is %llu x %llu, expected %zu x %d", f->path, path,
                     (unsigned long long)dims[0], (unsigned long long)dims[1], n, ncomp);
    else if (n > 0 && H5Dread(d, mt, H5S_ALL, H5S_ALL, H5P_DEFAULT, data) < 0)
        rc = h5io_fail(err, f->path, "reading dataset %s", path);
    if (t >= 0)
        H5Tclose(t);
    if (s >= 0)
        H5Sclose(s);
    H5Dclose(d);
    return rc;
}

/* ---- durable file replacement ------------------------------------------------ */

static int fsync_open(const char *path, int flags)
{
    int fd = open(path, flags);
    if (fd < 0)
        return -1;
    int rc = fsync(fd);
    close(fd);
    return rc;
}

int cm_fsync_file(const char *path) { return fsync_open(path, O_RDONLY); }

int cm_fsync_folder_of(const char *path)
{
    char *dir = strdup(path);
    if (!dir)
        return -1;
    char *slash = strrchr(dir, '/');
    if (slash)
        *slash = '\0';
    int rc = fsync_open(slash ? (slash == dir ? "/" : dir) : ".", O_RDONLY | O_DIRECTORY);
    free(dir);
    return rc;
}
