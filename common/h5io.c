/* HDF5 results files with an XDMF 3 index; see h5io.h for the layout. */
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
    long rows;
    cm_csv *csv;
    cm_h5_series *next;
};

struct cm_h5 {
    char *path, *xmf_path;
    const char *base; /* points into path: the name the XDMF refers to */
    hid_t fid, lcpl;
    cm_h5_xdmf xdmf;
    char *grid_name, *geometry, *connectivity;
    int geometry_static;

    /* current step */
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
static int h5_fail(cm_error *err, const char *file, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
static int h5_fail(cm_error *err, const char *file, const char *fmt, ...)
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

static int simple_name_ok(const char *s)
{
    return s && name_ok(s, strlen(s));
}

/* "/a/b/c": absolute, non-empty valid components. */
static int abs_path_ok(const char *p)
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

/* ---- growing text buffer for the XDMF ---------------------------------------- */

typedef struct strbuf {
    char *s;
    size_t len, cap;
    int oom;
} strbuf;

static void sb_printf(strbuf *b, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void sb_printf(strbuf *b, const char *fmt, ...)
{
    if (b->oom)
        return;
    for (;;) {
        va_list ap;
        va_start(ap, fmt);
        int n = vsnprintf(b->s ? b->s + b->len : NULL, b->s ? b->cap - b->len : 0, fmt, ap);
        va_end(ap);
        if (n < 0) {
            b->oom = 1;
            return;
        }
        if (b->s && b->len + (size_t)n < b->cap) {
            b->len += (size_t)n;
            return;
        }
        size_t cap = b->cap ? b->cap : 4096;
        while (cap <= b->len + (size_t)n)
            cap *= 2;
        char *s = realloc(b->s, cap);
        if (!s) {
            b->oom = 1;
            return;
        }
        b->s = s;
        b->cap = cap;
    }
}

/* Text with XML's five special characters escaped. */
static void sb_xml(strbuf *b, const char *s)
{
    for (; *s; s++) {
        switch (*s) {
        case '&': sb_printf(b, "&amp;"); break;
        case '<': sb_printf(b, "&lt;"); break;
        case '>': sb_printf(b, "&gt;"); break;
        case '"': sb_printf(b, "&quot;"); break;
        case '\'': sb_printf(b, "&apos;"); break;
        default: sb_printf(b, "%c", *s);
        }
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
        return h5_fail(err, f->path, "dataset %s: dataspace of %zu x %d", shown, n, ncomp);
    int rc = CM_OK;
    hid_t d = H5Dcreate2(loc, name, ftype, space, f->lcpl, H5P_DEFAULT, H5P_DEFAULT);
    if (d < 0)
        rc = h5_fail(err, f->path, "creating dataset %s", shown);
    else if (n > 0 && H5Dwrite(d, mtype, H5S_ALL, H5S_ALL, H5P_DEFAULT, data) < 0)
        rc = h5_fail(err, f->path, "writing dataset %s", shown);
    if (d >= 0)
        H5Dclose(d);
    H5Sclose(space);
    return rc;
}

static int write_array(cm_h5 *f, hid_t loc, const char *name, const char *shown, int is_int, const void *data,
                       size_t n, int ncomp, cm_error *err)
{
    return write_typed(f, loc, name, shown, is_int ? H5T_STD_I32LE : H5T_IEEE_F64LE,
                       is_int ? H5T_NATIVE_INT : H5T_NATIVE_DOUBLE, data, n, ncomp, err);
}

static int write_attr(cm_h5 *f, hid_t obj, const char *shown, const char *name, hid_t ftype, hid_t mtype,
                      const void *value, cm_error *err)
{
    htri_t ex = H5Aexists(obj, name);
    if (ex < 0)
        return h5_fail(err, f->path, "attribute %s of %s", name, shown);
    if (ex > 0 && H5Adelete(obj, name) < 0)
        return h5_fail(err, f->path, "replacing attribute %s of %s", name, shown);
    hid_t space = H5Screate(H5S_SCALAR);
    if (space < 0)
        return h5_fail(err, f->path, "attribute %s of %s: dataspace", name, shown);
    int rc = CM_OK;
    hid_t a = H5Acreate2(obj, name, ftype, space, H5P_DEFAULT, H5P_DEFAULT);
    if (a < 0)
        rc = h5_fail(err, f->path, "creating attribute %s of %s", name, shown);
    else if (H5Awrite(a, mtype, value) < 0)
        rc = h5_fail(err, f->path, "writing attribute %s of %s", name, shown);
    if (a >= 0)
        H5Aclose(a);
    H5Sclose(space);
    return rc;
}

/* Rank, dimensions and integer-ness of an existing dataset. */
static int dataset_shape(cm_h5 *f, const char *path, int *rank, hsize_t dims[2], int *is_int, cm_error *err)
{
    hid_t d = H5Dopen2(f->fid, path, H5P_DEFAULT);
    if (d < 0)
        return h5_fail(err, f->path, "opening dataset %s", path);
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
static int file_new(const char *path, const cm_h5_def *def_in, cm_h5 **out, cm_error *err)
{
    *out = NULL;
    cm_h5_def def = def_in ? *def_in : cm_h5_default_def();
    if (!path || !*path)
        return cm_fail(err, CM_ERR_RANGE, "results file: empty path");
    if (def.xdmf != CM_H5_XDMF_NONE) {
        if (!def.grid_name || !simple_name_ok(def.grid_name))
            return cm_fail(err, CM_ERR_RANGE, "%s: XDMF grid name \"%s\" must be letters, digits, \"_.-+\"", path,
                           def.grid_name ? def.grid_name : "(null)");
        if (!def.geometry || (!simple_name_ok(def.geometry) && !abs_path_ok(def.geometry)))
            return cm_fail(err, CM_ERR_RANGE, "%s: XDMF geometry \"%s\" is neither a step dataset name nor an "
                           "absolute dataset path", path, def.geometry ? def.geometry : "(null)");
        if (def.xdmf == CM_H5_XDMF_TETRAHEDRON && !abs_path_ok(def.connectivity))
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

int cm_h5_create(const char *path, const cm_h5_def *def_in, cm_h5 **out, cm_error *err)
{
    *out = NULL;
    cm_h5 *f;
    int rc = file_new(path, def_in, &f, err);
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
    if ((f->fid = H5Fcreate(path, H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT)) < 0)
        rc = h5_fail(err, path, "cannot create results file");
    if (rc == CM_OK && ((f->lcpl = H5Pcreate(H5P_LINK_CREATE)) < 0 ||
                        H5Pset_create_intermediate_group(f->lcpl, 1) < 0))
        rc = h5_fail(err, path, "link creation properties");
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
    while (f->series) {
        cm_h5_series *s = f->series;
        f->series = s->next;
        cm_error e2 = {0};
        if (cm_csv_close(&s->csv, &e2) != CM_OK && rc == CM_OK)
            rc = cm_fail(err, e2.code, "%s", e2.msg);
        H5Dclose(s->dset);
        H5Tclose(s->memtype);
        free(s->path);
        free(s);
    }
    if (f->gid >= 0)
        H5Gclose(f->gid);
    if (f->lcpl >= 0)
        H5Pclose(f->lcpl);
    if (H5Fclose(f->fid) < 0 && rc == CM_OK)
        rc = h5_fail(err, f->path, "closing results file");
    free_file(f);
    *fp = NULL;
    return rc;
}

int cm_h5_flush(cm_h5 *f, cm_error *err)
{
    if (H5Fflush(f->fid, H5F_SCOPE_LOCAL) < 0)
        return h5_fail(err, f->path, "flushing results file");
    return CM_OK;
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
    if (!abs_path_ok(path))
        return cm_fail(err, CM_ERR_RANGE, "%s: dataset path \"%s\" must be absolute, with components of "
                       "letters, digits and \"_.-+\"", f->path, path ? path : "(null)");
    return write_array(f, f->fid, path, path, 0, data, n, ncomp, err);
}

int cm_h5_write_ints(cm_h5 *f, const char *path, const int *data, size_t n, int ncomp, cm_error *err)
{
    if (!abs_path_ok(path))
        return cm_fail(err, CM_ERR_RANGE, "%s: dataset path \"%s\" must be absolute, with components of "
                       "letters, digits and \"_.-+\"", f->path, path ? path : "(null)");
    return write_array(f, f->fid, path, path, 1, data, n, ncomp, err);
}

static int attr_common(cm_h5 *f, const char *object, const char *name, hid_t ftype, hid_t mtype,
                       const void *value, cm_error *err)
{
    if (!object || !simple_name_ok(name))
        return cm_fail(err, CM_ERR_RANGE, "%s: attribute name \"%s\" must be letters, digits, \"_.-+\"", f->path,
                       name ? name : "(null)");
    hid_t obj = H5Oopen(f->fid, object, H5P_DEFAULT);
    if (obj < 0)
        return h5_fail(err, f->path, "opening %s for attribute %s", object, name);
    int rc = write_attr(f, obj, object, name, ftype, mtype, value, err);
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
        int rc = h5_fail(err, f->path, "string type for attribute %s", name ? name : "(null)");
        if (t >= 0)
            H5Tclose(t);
        return rc;
    }
    const char *v = value ? value : "";
    int rc = attr_common(f, object, name, t, t, &v, err);
    H5Tclose(t);
    return rc;
}

/* ---- snapshots ---------------------------------------------------------------- */

int cm_h5_step_begin(cm_h5 *f, long step, double time, cm_error *err)
{
    if (f->in_step)
        return cm_fail(err, CM_ERR_STATE, "%s: step %ld begun while step %ld is still open", f->path, step,
                       f->step);
    if (step < 0 || step <= f->last_step)
        return cm_fail(err, CM_ERR_STATE, "%s: step %ld does not follow step %ld (steps must increase)", f->path,
                       step, f->last_step);
    snprintf(f->group, sizeof f->group, "/steps/%06ld", step);
    f->gid = H5Gcreate2(f->fid, f->group, f->lcpl, H5P_DEFAULT, H5P_DEFAULT);
    if (f->gid < 0)
        return h5_fail(err, f->path, "creating group %s", f->group);
    int64_t s64 = step;
    int rc = write_attr(f, f->gid, f->group, "time", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, &time, err);
    if (rc == CM_OK)
        rc = write_attr(f, f->gid, f->group, "step", H5T_STD_I64LE, H5T_NATIVE_INT64, &s64, err);
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

static int step_write(cm_h5 *f, const char *name, cm_h5_center center, int is_int, const void *data, size_t n,
                      int ncomp, cm_error *err)
{
    if (!f->in_step)
        return cm_fail(err, CM_ERR_STATE, "%s: dataset %s written outside cm_h5_step_begin/end", f->path,
                       name ? name : "(null)");
    if (!simple_name_ok(name))
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
    int rc = write_array(f, f->gid, name, shown, is_int, data, n, ncomp, err);
    if (rc == CM_OK) { /* how the XDMF lists it, for cm_h5_reopen */
        hid_t d = H5Dopen2(f->gid, name, H5P_DEFAULT);
        int32_t c32 = (int32_t)center;
        rc = d < 0 ? h5_fail(err, f->path, "reopening dataset %s", shown)
                   : write_attr(f, d, shown, "xdmf_center", H5T_STD_I32LE, H5T_NATIVE_INT32, &c32, err);
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
    return step_write(f, name, center, 0, data, n, ncomp, err);
}

int cm_h5_step_ints(cm_h5 *f, const char *name, cm_h5_center center, const int *data, size_t n, int ncomp,
                    cm_error *err)
{
    return step_write(f, name, center, 1, data, n, ncomp, err);
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
            rc = h5_fail(err, f->path, "creating dataset %s", path);
        if (dcpl >= 0)
            H5Pclose(dcpl);
        if (space >= 0)
            H5Sclose(space);
    } else if ((d = H5Dopen2(f->fid, path, H5P_DEFAULT)) < 0) {
        rc = h5_fail(err, f->path, "opening dataset %s", path);
    }
    hsize_t start = old, count = want - old;
    if (rc == CM_OK && (H5Dset_extent(d, &want) < 0 || (fs = H5Dget_space(d)) < 0 ||
                        H5Sselect_hyperslab(fs, H5S_SELECT_SET, &start, NULL, &count, NULL) < 0 ||
                        (ms = H5Screate_simple(1, &count, NULL)) < 0 ||
                        H5Dwrite(d, H5T_NATIVE_INT, ms, fs, H5P_DEFAULT, ids) < 0))
        rc = h5_fail(err, f->path, "writing dataset %s", path);
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
        if (dataset_shape(f, f->geometry, &rank, dims, &is_int, err) != CM_OK)
            return missing_static(f, "geometry", f->geometry, err);
        if (rank != 2 || dims[1] != 3 || is_int)
            return cm_fail(err, CM_ERR_RANGE, "%s: XDMF geometry %s must be n x 3 doubles", f->path, f->geometry);
        f->static_points = (size_t)dims[0];
    }
    if (f->xdmf == CM_H5_XDMF_TETRAHEDRON && f->cells == 0) {
        if (dataset_shape(f, f->connectivity, &rank, dims, &is_int, err) != CM_OK)
            return missing_static(f, "connectivity", f->connectivity, err);
        if (rank != 2 || dims[1] != 4 || !is_int)
            return cm_fail(err, CM_ERR_RANGE, "%s: XDMF connectivity %s must be m x 4 ints", f->path,
                           f->connectivity);
        f->cells = (size_t)dims[0];
    }
    return CM_OK;
}

/* Checks the current step against the grid; fills npoints / ncells. */
static int check_step(cm_h5 *f, size_t *npoints, size_t *ncells, cm_error *err)
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

static void xdmf_item(strbuf *b, const cm_h5 *f, const char *indent, const char *path, int is_int, size_t n,
                      int ncomp)
{
    sb_printf(b, "%s<DataItem Dimensions=\"%zu", indent, n);
    if (ncomp > 1)
        sb_printf(b, " %d", ncomp);
    sb_printf(b, "\" NumberType=\"%s\" Precision=\"%d\" Format=\"HDF\">", is_int ? "Int" : "Float",
              is_int ? 4 : 8);
    sb_xml(b, f->base);
    sb_printf(b, ":%s</DataItem>\n", path);
}

static void xdmf_step(strbuf *b, const cm_h5 *f, const step_rec *r)
{
    char group[32], path[sizeof group + NAME_MAX_LEN + 2];
    snprintf(group, sizeof group, "/steps/%06ld", r->step);
    sb_printf(b, "      <Grid Name=\"step_%06ld\" GridType=\"Uniform\">\n", r->step);
    sb_printf(b, "        <Time Value=\"%.17g\"/>\n", r->time);
    if (f->xdmf == CM_H5_XDMF_POLYVERTEX) {
        sb_printf(b, "        <Topology TopologyType=\"Polyvertex\" NumberOfElements=\"%zu\" "
                     "NodesPerElement=\"1\">\n", r->npoints);
        if (r->npoints == f->vertex_ids_len) {
            xdmf_item(b, f, "          ", "/xdmf/vertex_ids", 1, r->npoints, 1);
        } else { /* the first npoints of the shared ids */
            sb_printf(b, "          <DataItem ItemType=\"HyperSlab\" Dimensions=\"%zu\" Type=\"HyperSlab\">\n",
                      r->npoints);
            sb_printf(b, "            <DataItem Dimensions=\"3 1\" Format=\"XML\">0 1 %zu</DataItem>\n",
                      r->npoints);
            xdmf_item(b, f, "            ", "/xdmf/vertex_ids", 1, f->vertex_ids_len, 1);
            sb_printf(b, "          </DataItem>\n");
        }
    } else {
        sb_printf(b, "        <Topology TopologyType=\"Tetrahedron\" NumberOfElements=\"%zu\">\n", r->ncells);
        xdmf_item(b, f, "          ", f->connectivity, 1, r->ncells, 4);
    }
    sb_printf(b, "        </Topology>\n");
    sb_printf(b, "        <Geometry GeometryType=\"XYZ\">\n");
    if (f->geometry_static) {
        xdmf_item(b, f, "          ", f->geometry, 0, r->npoints, 3);
    } else {
        snprintf(path, sizeof path, "%s/%s", group, f->geometry);
        xdmf_item(b, f, "          ", path, 0, r->npoints, 3);
    }
    sb_printf(b, "        </Geometry>\n");
    for (size_t i = r->first; i < r->first + r->count; i++) {
        const field *fl = &f->fields[i];
        if (fl->center == CM_H5_UNLISTED || (!f->geometry_static && strcmp(fl->name, f->geometry) == 0))
            continue;
        const char *type = fl->ncomp == 1 ? "Scalar" : fl->ncomp == 3 ? "Vector" : fl->ncomp == 6 ? "Tensor6"
                                                                                                  : "Tensor";
        sb_printf(b, "        <Attribute Name=\"%s\" AttributeType=\"%s\" Center=\"%s\">\n", fl->name, type,
                  fl->center == CM_H5_NODE ? "Node" : "Cell");
        snprintf(path, sizeof path, "%s/%s", group, fl->name);
        xdmf_item(b, f, "          ", path, fl->is_int, fl->n, fl->ncomp);
        sb_printf(b, "        </Attribute>\n");
    }
    sb_printf(b, "      </Grid>\n");
}

static const char k_xdmf_tail[] = "    </Grid>\n  </Domain>\n</Xdmf>\n";

/* Writes all of buf at offset off of fd. */
static int write_at(int fd, const char *buf, size_t len, off_t off, const char *path, cm_error *err)
{
    size_t done = 0;
    while (done < len) {
        ssize_t w = pwrite(fd, buf + done, len - done, off + (off_t)done);
        if (w < 0 && errno == EINTR)
            continue;
        if (w < 0)
            return cm_fail(err, CM_ERR_IO, "writing %s: %s", path, strerror(errno));
        done += (size_t)w;
    }
    return CM_OK;
}

/* Writes the whole XDMF to a temporary file, syncs it and renames it over
 * the old one: a reader sees either the old or the new index, never half.
 * The new file is then kept open for xdmf_append. */
static int write_xdmf(cm_h5 *f, cm_error *err)
{
    if (f->xmf_fd >= 0) {
        close(f->xmf_fd);
        f->xmf_fd = -1;
    }
    strbuf b = {0};
    sb_printf(&b, "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<!DOCTYPE Xdmf SYSTEM \"Xdmf.dtd\" []>\n");
    sb_printf(&b, "<Xdmf Version=\"3.0\">\n  <Domain>\n");
    sb_printf(&b, "    <Grid Name=\"%s\" GridType=\"Collection\" CollectionType=\"Temporal\">\n", f->grid_name);
    for (size_t i = 0; i < f->nsteps; i++)
        xdmf_step(&b, f, &f->steps[i]);
    size_t body = b.len;
    sb_printf(&b, "%s", k_xdmf_tail);
    if (b.oom) {
        free(b.s);
        return cm_fail(err, CM_ERR_NOMEM, "%s: out of memory", f->xmf_path);
    }
    size_t tlen = strlen(f->xmf_path) + 5;
    char *tmp = malloc(tlen);
    if (!tmp) {
        free(b.s);
        return cm_fail(err, CM_ERR_NOMEM, "%s: out of memory", f->xmf_path);
    }
    snprintf(tmp, tlen, "%s.tmp", f->xmf_path);
    int rc = CM_OK;
    int fd = open(tmp, O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd < 0) {
        rc = cm_fail(err, CM_ERR_IO, "cannot create %s: %s", tmp, strerror(errno));
    } else {
        rc = write_at(fd, b.s, b.len, 0, tmp, err);
        if (rc == CM_OK && fsync(fd) != 0)
            rc = cm_fail(err, CM_ERR_IO, "syncing %s: %s", tmp, strerror(errno));
        if (rc == CM_OK && rename(tmp, f->xmf_path) != 0)
            rc = cm_fail(err, CM_ERR_IO, "renaming %s to %s: %s", tmp, f->xmf_path, strerror(errno));
        if (rc != CM_OK) {
            close(fd);
            unlink(tmp);
        } else { /* the descriptor now names the renamed file */
            f->xmf_fd = fd;
            f->xmf_end = (off_t)body;
            f->xmf_ids_len = f->vertex_ids_len;
        }
    }
    free(tmp);
    free(b.s);
    return rc;
}

/* Adds the last step to the XDMF: its grid and the closing tags written
 * over the old closing tags, in one write (no rewrite of the earlier steps:
 * rewriting the whole index after every step made output time grow with
 * the square of the steps). Written in place, the index is not atomic as a
 * full rewrite is; a reader catching the moment of the write sees a
 * truncated file and reads again, and a process killed mid-write is rare
 * (one small write) and repaired when the run is resumed (cm_h5_reopen
 * rewrites it). Falls back to the full rewrite when the shared vertex ids
 * grew (earlier steps list their length) or nothing is open yet. */
static int xdmf_append(cm_h5 *f, cm_error *err)
{
    if (f->xmf_fd < 0 || f->xmf_ids_len != f->vertex_ids_len)
        return write_xdmf(f, err);
    strbuf b = {0};
    xdmf_step(&b, f, &f->steps[f->nsteps - 1]);
    size_t step_len = b.len;
    sb_printf(&b, "%s", k_xdmf_tail);
    if (b.oom) {
        free(b.s);
        return cm_fail(err, CM_ERR_NOMEM, "%s: out of memory", f->xmf_path);
    }
    int rc = write_at(f->xmf_fd, b.s, b.len, f->xmf_end, f->xmf_path, err);
    if (rc == CM_OK)
        f->xmf_end += (off_t)step_len;
    free(b.s);
    return rc;
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
    rc = check_step(f, &npoints, &ncells, err);
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
    /* vertex ids may have been created or extended by check_step */
    if ((rc = cm_h5_flush(f, err)) != CM_OK)
        return rc;
    return xdmf_append(f, err);
}

/* ---- time series -------------------------------------------------------------- */

/* The common ending of creating and reopening a series: flushed and added
 * to the file's list, or, after a failure, released. */
static int series_adopt(cm_h5 *f, cm_h5_series *s, int rc, cm_h5_series **out, cm_error *err)
{
    if (rc == CM_OK)
        rc = cm_h5_flush(f, err);
    if (rc != CM_OK) {
        cm_csv_close(&s->csv, NULL);
        if (s->dset >= 0)
            H5Dclose(s->dset);
        if (s->memtype >= 0)
            H5Tclose(s->memtype);
        free(s->path);
        free(s);
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
    if (!abs_path_ok(path))
        return cm_fail(err, CM_ERR_RANGE, "%s: series path \"%s\" must be absolute, with components of "
                       "letters, digits and \"_.-+\"", f->path, path ? path : "(null)");
    if (ncols < 1 || !columns)
        return cm_fail(err, CM_ERR_RANGE, "%s: series %s: needs at least one column", f->path, path);
    for (int i = 0; i < ncols; i++) {
        if (!simple_name_ok(columns[i]))
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
        rc = h5_fail(err, f->path, "series %s: row type", path);
    for (int i = 0; i < ncols && rc == CM_OK; i++)
        if (H5Tinsert(ftype, columns[i], 8 * (size_t)i, H5T_IEEE_F64LE) < 0 ||
            H5Tinsert(s->memtype, columns[i], sizeof(double) * (size_t)i, H5T_NATIVE_DOUBLE) < 0)
            rc = h5_fail(err, f->path, "series %s: column %s", path, columns[i]);
    /* Chunks of about 8 KiB: each flush rewrites the last chunk. */
    hsize_t zero = 0, unlimited = H5S_UNLIMITED, chunk = 8192 / (8 * (hsize_t)ncols);
    if (chunk < 16)
        chunk = 16;
    hid_t space = H5I_INVALID_HID, dcpl = H5I_INVALID_HID;
    if (rc == CM_OK && ((space = H5Screate_simple(1, &zero, &unlimited)) < 0 ||
                        (dcpl = H5Pcreate(H5P_DATASET_CREATE)) < 0 || H5Pset_chunk(dcpl, 1, &chunk) < 0))
        rc = h5_fail(err, f->path, "series %s: dataspace", path);
    if (rc == CM_OK && (s->dset = H5Dcreate2(f->fid, path, ftype, space, f->lcpl, dcpl, H5P_DEFAULT)) < 0)
        rc = h5_fail(err, f->path, "creating series %s", path);
    if (dcpl >= 0)
        H5Pclose(dcpl);
    if (space >= 0)
        H5Sclose(space);
    if (ftype >= 0)
        H5Tclose(ftype);
    if (rc == CM_OK && csv_path)
        rc = cm_csv_create(csv_path, columns, ncols, &s->csv, err);
    return series_adopt(f, s, rc, out, err);
}

int cm_h5_series_append(cm_h5_series *s, const double *row, cm_error *err)
{
    cm_h5 *f = s->file;
    hsize_t start = (hsize_t)s->rows, one = 1, size = start + 1;
    hid_t fs = H5I_INVALID_HID, ms = H5I_INVALID_HID;
    int rc = CM_OK;
    if (H5Dset_extent(s->dset, &size) < 0)
        rc = h5_fail(err, f->path, "series %s: extending to row %ld", s->path, s->rows);
    else if ((fs = H5Dget_space(s->dset)) < 0 ||
             H5Sselect_hyperslab(fs, H5S_SELECT_SET, &start, NULL, &one, NULL) < 0 ||
             (ms = H5Screate_simple(1, &one, NULL)) < 0 ||
             H5Dwrite(s->dset, s->memtype, ms, fs, H5P_DEFAULT, row) < 0) {
        rc = h5_fail(err, f->path, "series %s: writing row %ld", s->path, s->rows);
        H5Dset_extent(s->dset, &start); /* do not leave a row of fill values */
    }
    if (ms >= 0)
        H5Sclose(ms);
    if (fs >= 0)
        H5Sclose(fs);
    if (rc != CM_OK)
        return rc;
    s->rows++;
    if ((rc = cm_h5_flush(f, err)) != CM_OK)
        return rc;
    return s->csv ? cm_csv_row(s->csv, row, err) : CM_OK;
}

long cm_h5_series_rows(const cm_h5_series *s)
{
    return s ? s->rows : 0;
}

/* ---- resuming a run ----------------------------------------------------------- */

static int open_existing(cm_h5 *f, const char *path, int writable, cm_error *err)
{
    if (access(path, writable ? R_OK | W_OK : R_OK) != 0)
        return cm_fail(err, CM_ERR_IO, "cannot open %s: %s", path, strerror(errno));
    if ((f->fid = H5Fopen(path, writable ? H5F_ACC_RDWR : H5F_ACC_RDONLY, H5P_DEFAULT)) < 0)
        return h5_fail(err, path, "cannot open as HDF5");
    if ((f->lcpl = H5Pcreate(H5P_LINK_CREATE)) < 0 || H5Pset_create_intermediate_group(f->lcpl, 1) < 0)
        return h5_fail(err, path, "link creation properties");
    return CM_OK;
}

int cm_h5_open(const char *path, int writable, cm_h5 **out, cm_error *err)
{
    cm_h5 *f;
    int rc = file_new(path, NULL, &f, err);
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

/* Lists the datasets of a kept step again (as step_write recorded them). */
static int relist_step(cm_h5 *f, hid_t g, const kept_step *k, cm_error *err)
{
    H5G_info_t gi;
    if (H5Gget_info(g, &gi) < 0)
        return h5_fail(err, f->path, "listing /steps/%s", k->name);
    f->step_first = f->nfields;
    for (hsize_t i = 0; i < gi.nlinks; i++) {
        char name[NAME_MAX_LEN + 1];
        if (H5Lget_name_by_idx(g, ".", H5_INDEX_NAME, H5_ITER_INC, i, name, sizeof name, H5P_DEFAULT) < 0)
            return h5_fail(err, f->path, "listing /steps/%s", k->name);
        char shown[sizeof k->name + NAME_MAX_LEN + 9];
        snprintf(shown, sizeof shown, "/steps/%s/%s", k->name, name);
        int rank, is_int;
        hsize_t dims[2];
        int rc = dataset_shape(f, shown, &rank, dims, &is_int, err);
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
    int rc = check_step(f, &npoints, &ncells, err);
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
        return h5_fail(err, f->path, "looking for /steps");
    if (has == 0)
        return CM_OK;
    hid_t g = H5Gopen2(f->fid, "/steps", H5P_DEFAULT);
    H5G_info_t gi;
    if (g < 0 || H5Gget_info(g, &gi) < 0) {
        int rc = h5_fail(err, f->path, "opening /steps");
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
            rc = h5_fail(err, f->path, "listing /steps");
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
                rc = h5_fail(err, f->path, "deleting /steps/%s beyond the checkpoint", ks[i].name);
        } else {
            ks[kept++] = ks[i];
        }
    }
    if (rc == CM_OK)
        qsort(ks, kept, sizeof *ks, cmp_kept);
    if (rc == CM_OK && f->xdmf == CM_H5_XDMF_POLYVERTEX && H5Lexists(f->fid, "/xdmf/vertex_ids", H5P_DEFAULT) > 0) {
        int rank, is_int;
        hsize_t dims[2];
        if ((rc = dataset_shape(f, "/xdmf/vertex_ids", &rank, dims, &is_int, err)) == CM_OK)
            f->vertex_ids_len = (size_t)dims[0];
    }
    for (size_t i = 0; i < kept && rc == CM_OK; i++) {
        hid_t sg = H5Gopen2(g, ks[i].name, H5P_DEFAULT);
        rc = sg < 0 ? h5_fail(err, f->path, "opening /steps/%s", ks[i].name) : relist_step(f, sg, &ks[i], err);
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
    int rc = file_new(path, def, &f, err);
    if (rc != CM_OK)
        return rc;
    if ((rc = open_existing(f, path, 1, err)) == CM_OK && (rc = reopen_steps(f, keep_through_step, err)) == CM_OK &&
        (rc = cm_h5_flush(f, err)) == CM_OK && f->xdmf != CM_H5_XDMF_NONE)
        rc = write_xdmf(f, err);
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
    if (!abs_path_ok(path) || ncols < 1 || !columns || rows < 0)
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
        rc = h5_fail(err, f->path, "opening series %s", path);
    hid_t ft = rc == CM_OK ? H5Dget_type(s->dset) : H5I_INVALID_HID;
    if (rc == CM_OK && (ft < 0 || H5Tget_class(ft) != H5T_COMPOUND || H5Tget_nmembers(ft) != ncols))
        rc = cm_fail(err, CM_ERR_PARSE, "%s: series %s is not a table of %d columns", f->path, path, ncols);
    if (ft >= 0)
        H5Tclose(ft);
    if (rc == CM_OK && (s->memtype = H5Tcreate(H5T_COMPOUND, sizeof(double) * (size_t)ncols)) < 0)
        rc = h5_fail(err, f->path, "series %s: row type", path);
    for (int i = 0; i < ncols && rc == CM_OK; i++)
        if (H5Tinsert(s->memtype, columns[i], sizeof(double) * (size_t)i, H5T_NATIVE_DOUBLE) < 0)
            rc = h5_fail(err, f->path, "series %s: column %s", path, columns[i]);
    hsize_t have = 0, want = (hsize_t)rows;
    if (rc == CM_OK) {
        hid_t sp = H5Dget_space(s->dset);
        if (sp < 0 || H5Sget_simple_extent_dims(sp, &have, NULL) != 1)
            rc = h5_fail(err, f->path, "series %s: extent", path);
        if (sp >= 0)
            H5Sclose(sp);
    }
    if (rc == CM_OK && have < want)
        rc = cm_fail(err, CM_ERR_IO, "%s: series %s holds %llu rows, the checkpoint expects %ld", f->path, path,
                     (unsigned long long)have, rows);
    if (rc == CM_OK && H5Dset_extent(s->dset, &want) < 0)
        rc = h5_fail(err, f->path, "series %s: cutting back to %ld rows", path, rows);
    if (rc == CM_OK && csv_path)
        rc = cm_csv_reopen(csv_path, ncols, rows, &s->csv, err);
    if (rc == CM_OK)
        s->rows = rows;
    return series_adopt(f, s, rc, out, err);
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
    if (!abs_path_ok(path))
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
        return h5_fail(err, f->path, "no dataset %s", path);
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
        rc = h5_fail(err, f->path, "reading dataset %s", path);
    if (t >= 0)
        H5Tclose(t);
    if (s >= 0)
        H5Sclose(s);
    H5Dclose(d);
    return rc;
}
