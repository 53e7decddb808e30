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

/* ---- rebuilding the file from what the checkpoint covers ------------------------
 *
 * HDF5 files are not crash-consistent. A process killed in the middle of a
 * flush (or after the metadata cache wrote some entries out on its own)
 * leaves a file in which entries already written refer to space allocated
 * after the last completed flush, beyond the end of allocation the
 * superblock records ("addr overflow, addr = 889232, eoa = 889232"), or in
 * which a shared structure (the /steps group's name heap, B-tree nodes, the
 * series' chunk index) was written in its new state while its neighbours
 * are old. Everything a checkpoint covers, though, was complete at the
 * checkpoint's flush and is never rewritten afterwards (the kept steps'
 * groups and datasets, the static datasets) or rewritten with the same bytes
 * (the series' rows up to the checkpoint's count).
 *
 * So resuming never edits the killed file in place. It ALWAYS builds a
 * fresh file next to it ("<path>.resume.tmp"), copying into it (H5Ocopy)
 * the /steps groups up to the checkpoint, every other object the writer
 * made, with each extendible dataset (series, /xdmf/vertex_ids) cut to the
 * rows it can read, and the attributes; it then syncs the copy and renames
 * it over the old file (atomic on POSIX: a process killed during the resume
 * leaves the killed file as it was, and the resume can be run again). The
 * steps beyond the checkpoint are recognised by their names (the writer
 * names a group /steps/<step, 6+ digits>) and never opened: they are the
 * ones a kill leaves half written. A kept object that cannot be read fails
 * the resume with a message naming the file and the object.
 *
 * Trimming in place (the earlier design: delete the later steps, cut the
 * series) was dropped, not kept as a first attempt: it modifies a damaged
 * file, fails on the very damage it should step over (deleting a half-
 * written step reads its header), and a failure half way leaves the file
 * worse. One code path, exercised by every resume, is simpler to trust; its
 * cost is one copy of the kept data per resume. */

typedef struct names {
    char **v;
    size_t n;
} names;

static void names_free(names *nm)
{
    for (size_t i = 0; i < nm->n; i++)
        free(nm->v[i]);
    free(nm->v);
    nm->v = NULL;
    nm->n = 0;
}

/* The names of the links in group g (shown: its path, for messages). */
static int list_links(hid_t g, const char *file, const char *shown, names *out, cm_error *err)
{
    out->v = NULL;
    out->n = 0;
    H5G_info_t gi;
    if (H5Gget_info(g, &gi) < 0)
        return h5io_fail(err, file, "listing %s", shown);
    if (gi.nlinks == 0)
        return CM_OK;
    if (!(out->v = calloc((size_t)gi.nlinks, sizeof *out->v)))
        return cm_fail(err, CM_ERR_NOMEM, "%s: out of memory", file);
    for (hsize_t i = 0; i < gi.nlinks; i++) {
        ssize_t len = H5Lget_name_by_idx(g, ".", H5_INDEX_NAME, H5_ITER_INC, i, NULL, 0, H5P_DEFAULT);
        char *name = len < 0 ? NULL : malloc((size_t)len + 1);
        if (len < 0 || !name ||
            H5Lget_name_by_idx(g, ".", H5_INDEX_NAME, H5_ITER_INC, i, name, (size_t)len + 1, H5P_DEFAULT) < 0) {
            free(name);
            int rc = len < 0 ? h5io_fail(err, file, "listing %s", shown)
                             : cm_fail(err, CM_ERR_NOMEM, "%s: out of memory", file);
            names_free(out);
            return rc;
        }
        out->v[out->n++] = name;
    }
    return CM_OK;
}

typedef struct attr_copy {
    hid_t dst;
    const char *file, *shown;
    cm_error *err;
    int rc;
} attr_copy;

/* Copies one attribute (any type, variable-length strings included). */
static herr_t copy_attr_cb(hid_t src, const char *name, const H5A_info_t *info, void *data)
{
    (void)info;
    attr_copy *c = data;
    hid_t a = H5Aopen(src, name, H5P_DEFAULT);
    hid_t t = a < 0 ? H5I_INVALID_HID : H5Aget_type(a);
    hid_t sp = a < 0 ? H5I_INVALID_HID : H5Aget_space(a);
    hssize_t npts = sp < 0 ? -1 : H5Sget_simple_extent_npoints(sp);
    size_t size = t < 0 ? 0 : H5Tget_size(t);
    void *buf = npts < 0 || size == 0 ? NULL : calloc(npts > 0 ? (size_t)npts : 1, size);
    int read = buf && H5Aread(a, t, buf) >= 0;
    if (!read) {
        c->rc = h5io_fail(c->err, c->file, "reading attribute %s of %s", name, c->shown);
    } else {
        hid_t b = H5Acreate2(c->dst, name, t, sp, H5P_DEFAULT, H5P_DEFAULT);
        if (b < 0 || H5Awrite(b, t, buf) < 0)
            c->rc = h5io_fail(c->err, c->file, "copying attribute %s of %s", name, c->shown);
        if (b >= 0)
            H5Aclose(b);
        if (H5Tdetect_class(t, H5T_VLEN) > 0 || H5Tis_variable_str(t) > 0)
            H5Dvlen_reclaim(t, sp, H5P_DEFAULT, buf);
    }
    free(buf);
    if (sp >= 0)
        H5Sclose(sp);
    if (t >= 0)
        H5Tclose(t);
    if (a >= 0)
        H5Aclose(a);
    return c->rc == CM_OK ? 0 : -1;
}

static int copy_attrs(hid_t src, hid_t dst, const char *file, const char *shown, cm_error *err)
{
    attr_copy c = {.dst = dst, .file = file, .shown = shown, .err = err, .rc = CM_OK};
    hsize_t idx = 0;
    if (H5Aiterate2(src, H5_INDEX_NAME, H5_ITER_INC, &idx, copy_attr_cb, &c) < 0 && c.rc == CM_OK)
        c.rc = h5io_fail(err, file, "listing the attributes of %s", shown);
    return c.rc;
}

/* An extendible 1-D dataset (a series, /xdmf/vertex_ids): copied chunk by
 * chunk up to the first chunk that cannot be read. Rows after the
 * checkpoint's may be half written; cm_h5_series_reopen checks that the
 * rows it keeps were all copied. */
static int copy_prefix(hid_t src, hid_t dst_loc, const char *name, const char *file, const char *shown,
                       cm_error *err)
{
    hid_t t = H5Dget_type(src), fs = H5Dget_space(src), dcpl = H5Dget_create_plist(src);
    hid_t dst = H5I_INVALID_HID, ms = H5I_INVALID_HID, ds = H5I_INVALID_HID;
    hsize_t n = 0, chunk = 0, zero = 0, unlimited = H5S_UNLIMITED;
    int rc = CM_OK;
    void *buf = NULL;
    if (t < 0 || fs < 0 || dcpl < 0 || H5Sget_simple_extent_dims(fs, &n, NULL) != 1 ||
        H5Pget_chunk(dcpl, 1, &chunk) != 1 || chunk == 0)
        rc = h5io_fail(err, file, "reading the layout of %s", shown);
    size_t rowsize = rc == CM_OK ? H5Tget_size(t) : 0;
    if (rc == CM_OK && !(buf = malloc((size_t)chunk * rowsize)))
        rc = cm_fail(err, CM_ERR_NOMEM, "%s: %s: out of memory", file, shown);
    if (rc == CM_OK && ((ds = H5Screate_simple(1, &zero, &unlimited)) < 0 ||
                        (dst = H5Dcreate2(dst_loc, name, t, ds, H5P_DEFAULT, dcpl, H5P_DEFAULT)) < 0))
        rc = h5io_fail(err, file, "creating the copy of %s", shown);
    for (hsize_t start = 0; start < n && rc == CM_OK; start += chunk) {
        hsize_t count = n - start < chunk ? n - start : chunk, end = start + count;
        if (ms >= 0)
            H5Sclose(ms);
        if ((ms = H5Screate_simple(1, &count, NULL)) < 0 ||
            H5Sselect_hyperslab(fs, H5S_SELECT_SET, &start, NULL, &count, NULL) < 0) {
            rc = h5io_fail(err, file, "%s: selecting rows %llu..%llu", shown, (unsigned long long)start,
                           (unsigned long long)end);
            break;
        }
        if (H5Dread(src, t, ms, fs, H5P_DEFAULT, buf) < 0)
            break; /* the readable prefix ends here */
        hid_t dfs = H5I_INVALID_HID;
        if (H5Dset_extent(dst, &end) < 0 || (dfs = H5Dget_space(dst)) < 0 ||
            H5Sselect_hyperslab(dfs, H5S_SELECT_SET, &start, NULL, &count, NULL) < 0 ||
            H5Dwrite(dst, t, ms, dfs, H5P_DEFAULT, buf) < 0)
            rc = h5io_fail(err, file, "copying rows %llu..%llu of %s", (unsigned long long)start,
                           (unsigned long long)end, shown);
        if (dfs >= 0)
            H5Sclose(dfs);
    }
    if (rc == CM_OK)
        rc = copy_attrs(src, dst, file, shown, err);
    free(buf);
    if (ms >= 0)
        H5Sclose(ms);
    if (ds >= 0)
        H5Sclose(ds);
    if (dst >= 0)
        H5Dclose(dst);
    if (dcpl >= 0)
        H5Pclose(dcpl);
    if (fs >= 0)
        H5Sclose(fs);
    if (t >= 0)
        H5Tclose(t);
    return rc;
}

/* 1 when dataset d is 1-D with an unlimited extent. */
static int extendible(hid_t d)
{
    hid_t sp = H5Dget_space(d);
    hsize_t dims[H5S_MAX_RANK], maxdims[H5S_MAX_RANK];
    int rank = sp < 0 ? -1 : H5Sget_simple_extent_dims(sp, dims, maxdims);
    if (sp >= 0)
        H5Sclose(sp);
    return rank == 1 && maxdims[0] == H5S_UNLIMITED;
}

/* The numbered members of one group that a rebuild filters (see
 * cm_h5_rebuild). */
typedef struct numbered {
    const char *group, *prefix;
    long keep;
} numbered;

/* The number in `name` when it is <prefix><digits>, else -1. */
static long number_of(const char *name, const char *prefix)
{
    size_t lp = strlen(prefix), len = strlen(name);
    if (strncmp(name, prefix, lp) != 0 || len == lp || len - lp > 18 || strspn(name + lp, "0123456789") != len - lp)
        return -1;
    return strtol(name + lp, NULL, 10);
}

/* Checks that object o, numbered member `number` of a group, kept by the
 * checkpoint, is a group (with the step attribute `number` if it has one:
 * a half-written name heap can pair a name with another object) and copies
 * it into dst as `name`. */
static int copy_kept(hid_t o, hid_t dst, const char *name, long number, const char *file, const char *shown,
                     cm_error *err)
{
    int64_t s64 = -1;
    if (o < 0)
        return h5io_fail(err, file, "opening %s (kept by the checkpoint)", shown);
    htri_t has = H5Iget_type(o) == H5I_GROUP ? H5Aexists(o, "step") : -1;
    if (has < 0 || (has > 0 && (read_attr(o, "step", H5T_NATIVE_INT64, &s64) != 0 || s64 != number)))
        return cm_fail(err, CM_ERR_PARSE, "%s: %s (kept by the checkpoint) is unreadable: not a group with the "
                       "step attribute %ld", file, shown, number);
    if (H5Ocopy(o, ".", dst, name, H5P_DEFAULT, H5P_DEFAULT) < 0)
        return h5io_fail(err, file, "copying %s (kept by the checkpoint)", shown);
    return CM_OK;
}

static int copy_object(hid_t src, hid_t dst, const char *name, const char *file, const char *shown,
                       const numbered *num, cm_error *err);

/* Copies the members of group src (path shown) into dst. In the filtered
 * group, a numbered member after the checkpoint is skipped without being
 * opened (a kill leaves those half written), and a kept one is opened by
 * its place in the listing, not looked up by name (a symbol-table node
 * written in its new state beside an old B-tree can list a name that the
 * lookup no longer finds). A group that cannot be listed fails: a kill
 * while one of its symbol-table nodes was split can leave its B-tree
 * pointing to a node never written, which may hold kept members. */
static int copy_members(hid_t src, hid_t dst, const char *file, const char *shown, const numbered *num,
                        cm_error *err)
{
    names nm;
    int rc = list_links(src, file, shown, &nm, err);
    int filtered = num && strcmp(shown, num->group) == 0;
    for (size_t i = 0; i < nm.n && rc == CM_OK; i++) {
        size_t len = strlen(shown) + strlen(nm.v[i]) + 2;
        char *sub = malloc(len);
        if (!sub) {
            rc = cm_fail(err, CM_ERR_NOMEM, "%s: out of memory", file);
            break;
        }
        snprintf(sub, len, "%s/%s", strcmp(shown, "/") ? shown : "", nm.v[i]);
        long k = filtered ? number_of(nm.v[i], num->prefix) : -1;
        if (k > num->keep) {
            /* after the checkpoint: not copied */
        } else if (k >= 0) {
            hid_t o = H5Oopen_by_idx(src, ".", H5_INDEX_NAME, H5_ITER_INC, (hsize_t)i, H5P_DEFAULT);
            rc = copy_kept(o, dst, nm.v[i], k, file, sub, err);
            if (o >= 0)
                H5Oclose(o);
        } else {
            rc = copy_object(src, dst, nm.v[i], file, sub, num, err);
        }
        free(sub);
    }
    names_free(&nm);
    return rc;
}

/* Copies object `name` of group src (path shown) into group dst: a group
 * member by member (attributes included), an extendible dataset by its
 * readable prefix, anything else whole with H5Ocopy. */
static int copy_object(hid_t src, hid_t dst, const char *name, const char *file, const char *shown,
                       const numbered *num, cm_error *err)
{
    hid_t o = H5Oopen(src, name, H5P_DEFAULT);
    if (o < 0)
        return h5io_fail(err, file, "opening %s", shown);
    H5I_type_t type = H5Iget_type(o);
    int rc = CM_OK;
    if (type == H5I_GROUP) {
        hid_t g = H5I_INVALID_HID;
        if (strcmp(shown, "/steps") == 0) /* as h5io creates it */
            rc = h5io_create_steps_group(dst, file, err);
        else if ((g = H5Gcreate2(dst, name, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT)) < 0)
            rc = h5io_fail(err, file, "creating the copy of %s", shown);
        if (rc == CM_OK && g < 0 && (g = H5Gopen2(dst, name, H5P_DEFAULT)) < 0)
            rc = h5io_fail(err, file, "opening the copy of %s", shown);
        if (rc == CM_OK)
            rc = copy_attrs(o, g, file, shown, err);
        if (rc == CM_OK)
            rc = copy_members(o, g, file, shown, num, err);
        if (g >= 0)
            H5Gclose(g);
    } else if (type == H5I_DATASET && extendible(o)) {
        rc = copy_prefix(o, dst, name, file, shown, err);
    } else if (H5Ocopy(src, name, dst, name, H5P_DEFAULT, H5P_DEFAULT) < 0) {
        rc = h5io_fail(err, file, "copying %s", shown);
    }
    H5Oclose(o);
    return rc;
}

int cm_h5_rebuild(const char *path, const char *group, const char *prefix, long keep, cm_error *err)
{
    if (!group || !prefix || group[0] != '/')
        return cm_fail(err, CM_ERR_RANGE, "%s: rebuild: bad arguments", path ? path : "(null)");
    const numbered num = {.group = group, .prefix = prefix, .keep = keep};
    if (access(path, R_OK | W_OK) != 0)
        return cm_fail(err, CM_ERR_IO, "cannot open %s: %s", path, strerror(errno));
    size_t tlen = strlen(path) + sizeof ".resume.tmp";
    char *tmp = malloc(tlen);
    if (!tmp)
        return cm_fail(err, CM_ERR_NOMEM, "%s: out of memory", path);
    snprintf(tmp, tlen, "%s.resume.tmp", path);
    int rc = CM_OK;
    H5Eset_auto2(H5E_DEFAULT, NULL, NULL);
    hid_t src = H5Fopen(path, H5F_ACC_RDONLY, H5P_DEFAULT), dst = H5I_INVALID_HID;
    hid_t sroot = H5I_INVALID_HID, droot = H5I_INVALID_HID;
    if (src < 0)
        rc = h5io_fail(err, path, "cannot open as HDF5 to resume");
    else
        rc = h5io_create_file(tmp, "cannot create the rebuilt results file", &dst, err);
    if (rc == CM_OK && ((sroot = H5Gopen2(src, "/", H5P_DEFAULT)) < 0 ||
                        (droot = H5Gopen2(dst, "/", H5P_DEFAULT)) < 0))
        rc = h5io_fail(err, path, "opening the root group");
    if (rc == CM_OK)
        rc = copy_attrs(sroot, droot, path, "/", err);
    if (rc == CM_OK)
        rc = copy_members(sroot, droot, path, "/", &num, err);
    if (droot >= 0)
        H5Gclose(droot);
    if (sroot >= 0)
        H5Gclose(sroot);
    if (dst >= 0 && H5Fclose(dst) < 0 && rc == CM_OK)
        rc = h5io_fail(err, tmp, "closing the rebuilt results file");
    if (src >= 0)
        H5Fclose(src);
    if (rc == CM_OK && cm_fsync_file(tmp) != 0)
        rc = cm_fail(err, CM_ERR_IO, "syncing %s: %s", tmp, strerror(errno));
    if (rc == CM_OK && rename(tmp, path) != 0)
        rc = cm_fail(err, CM_ERR_IO, "renaming %s to %s: %s", tmp, path, strerror(errno));
    if (rc == CM_OK)
        cm_fsync_folder_of(path); /* the rename itself */
    else
        unlink(tmp);
    free(tmp);
    return rc;
}

/* Lists the steps of a rebuilt file again (all of them are kept). */
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
        else if (s64 > keep) /* rebuild() kept none: a bug, not a damaged file */
            rc = cm_fail(err, CM_ERR_STATE, "%s: /steps/%s is after step %ld and was kept", f->path, k->name, keep);
        if (sg >= 0)
            H5Gclose(sg);
        k->step = (long)s64;
        nk++;
    }
    if (rc == CM_OK)
        qsort(ks, nk, sizeof *ks, cmp_kept);
    if (rc == CM_OK && f->xdmf == CM_H5_XDMF_POLYVERTEX && H5Lexists(f->fid, "/xdmf/vertex_ids", H5P_DEFAULT) > 0) {
        int rank, is_int;
        hsize_t dims[2];
        if ((rc = h5io_dataset_shape(f, "/xdmf/vertex_ids", &rank, dims, &is_int, err)) == CM_OK)
            f->vertex_ids_len = (size_t)dims[0];
    }
    for (size_t i = 0; i < nk && rc == CM_OK; i++) {
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
    if ((rc = cm_h5_rebuild(path, "/steps", "", keep_through_step, err)) != CM_OK) {
        cm_h5_close(&f, NULL);
        return rc;
    }
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
