/* Grain-state output: one HDF5 file with a group per frame, an XDMF file
 * beside it that ParaView opens as a time series of Polyvertex grids
 * (position, velocity, radius, angular velocity, contact count), and a CSV
 * time series of energies and contact counts. With shaped grains in the
 * world, each frame also holds orientation (n x 4 quaternion w x y z, body
 * principal frame -> world), shape (shape id, -1 sphere), scale and
 * long_axis (the principal axis of least inertia, the longest, times the
 * grain's half-length along it: a vector for ParaView's glyphs; zero for
 * spheres), and /shapes the hull vertices of each polyhedral shape once
 * (principal frame, scale 1: a grain's corners are x + scale R(q) v).
 * Not in the hot loop: buffers are allocated per frame. */
#include <errno.h>
#include <hdf5.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "dem_output.h"
#include "dem_world.h"
#include "h5io.h"

struct dem_output {
    char dir[1024];
    hid_t h5;
    int shaped;        /* the frames carry orientation, shape, scale, long_axis */
    int shapes_written;
    FILE *series;
    int n_frames, cap_frames;
    long series_rows;
    double *times;
    int *counts;
};

int dem_output_open(const char *dir, dem_output **out, cm_error *err)
{
    *out = NULL;
    if (mkdir(dir, 0777) != 0 && errno != EEXIST)
        return cm_fail(err, CM_ERR_IO, "%s: cannot create output folder: %s", dir, strerror(errno));
    dem_output *o = calloc(1, sizeof *o);
    if (!o)
        return cm_fail(err, CM_ERR_NOMEM, "%s: out of memory", dir);
    snprintf(o->dir, sizeof o->dir, "%s", dir);
    char path[1100];
    snprintf(path, sizeof path, "%s/dem_grains.h5", dir);
    H5Eset_auto2(H5E_DEFAULT, NULL, NULL);
    o->h5 = H5Fcreate(path, H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    if (o->h5 < 0) {
        free(o);
        return cm_fail(err, CM_ERR_IO, "%s: cannot create HDF5 file", path);
    }
    snprintf(path, sizeof path, "%s/dem_series.csv", dir);
    o->series = fopen(path, "w");
    if (!o->series) {
        H5Fclose(o->h5);
        free(o);
        return cm_fail(err, CM_ERR_IO, "%s: %s", path, strerror(errno));
    }
    fprintf(o->series,
            "time_s,step,ke_trans_J,ke_rot_J,contacts_grain,contacts_wall,contacts_surface,max_overlap,grains,frozen,max_overlap_surface\n");
    *out = o;
    return CM_OK;
}

static int write_ds(hid_t grp, const char *name, hid_t type, int n, int cols, const void *data)
{
    hsize_t dims[2] = {(hsize_t)n, (hsize_t)cols};
    hid_t sp = H5Screate_simple(cols > 1 ? 2 : 1, dims, NULL);
    hid_t ds = H5Dcreate2(grp, name, type, sp, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    herr_t st = ds < 0 ? -1 : H5Dwrite(ds, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, data);
    if (ds >= 0)
        H5Dclose(ds);
    H5Sclose(sp);
    return st < 0 ? -1 : 0;
}

static int write_xdmf(const dem_output *o, cm_error *err)
{
    char path[1100], tmp[1200];
    snprintf(path, sizeof path, "%s/dem_grains.xmf", o->dir);
    snprintf(tmp, sizeof tmp, "%s.tmp", path);
    FILE *f = fopen(tmp, "w");
    if (!f)
        return cm_fail(err, CM_ERR_IO, "%s: %s", tmp, strerror(errno));
    fprintf(f, "<?xml version=\"1.0\" ?>\n<Xdmf Version=\"3.0\">\n <Domain>\n"
               "  <Grid Name=\"grains\" GridType=\"Collection\" CollectionType=\"Temporal\">\n");
    for (int k = 0; k < o->n_frames; k++) {
        int n = o->counts[k];
        fprintf(f, "   <Grid Name=\"frame_%06d\" GridType=\"Uniform\">\n    <Time Value=\"%.9g\"/>\n", k, o->times[k]);
        fprintf(f, "    <Topology TopologyType=\"Polyvertex\" NumberOfElements=\"%d\"/>\n", n);
        fprintf(f, "    <Geometry GeometryType=\"XYZ\">\n     <DataItem Dimensions=\"%d 3\" NumberType=\"Float\" "
                   "Precision=\"8\" Format=\"HDF\">dem_grains.h5:/frame_%06d/position</DataItem>\n    </Geometry>\n", n, k);
        const char *vec[] = {"velocity", "angular_velocity"};
        for (int a = 0; a < 2; a++)
            fprintf(f, "    <Attribute Name=\"%s\" AttributeType=\"Vector\" Center=\"Node\">\n     <DataItem "
                       "Dimensions=\"%d 3\" NumberType=\"Float\" Precision=\"8\" Format=\"HDF\">dem_grains.h5:/frame_%06d/%s"
                       "</DataItem>\n    </Attribute>\n", vec[a], n, k, vec[a]);
        fprintf(f, "    <Attribute Name=\"radius\" AttributeType=\"Scalar\" Center=\"Node\">\n     <DataItem "
                   "Dimensions=\"%d\" NumberType=\"Float\" Precision=\"8\" Format=\"HDF\">dem_grains.h5:/frame_%06d/radius"
                   "</DataItem>\n    </Attribute>\n", n, k);
        fprintf(f, "    <Attribute Name=\"contacts\" AttributeType=\"Scalar\" Center=\"Node\">\n     <DataItem "
                   "Dimensions=\"%d\" NumberType=\"Int\" Precision=\"4\" Format=\"HDF\">dem_grains.h5:/frame_%06d/contacts"
                   "</DataItem>\n    </Attribute>\n", n, k);
        fprintf(f, "    <Attribute Name=\"tag\" AttributeType=\"Scalar\" Center=\"Node\">\n     <DataItem "
                   "Dimensions=\"%d\" NumberType=\"Int\" Precision=\"4\" Format=\"HDF\">dem_grains.h5:/frame_%06d/tag"
                   "</DataItem>\n    </Attribute>\n", n, k);
        if (o->shaped) {
            fprintf(f, "    <Attribute Name=\"long_axis\" AttributeType=\"Vector\" Center=\"Node\">\n     <DataItem "
                       "Dimensions=\"%d 3\" NumberType=\"Float\" Precision=\"8\" Format=\"HDF\">dem_grains.h5:/frame_%06d/"
                       "long_axis</DataItem>\n    </Attribute>\n", n, k);
            fprintf(f, "    <Attribute Name=\"orientation\" AttributeType=\"Matrix\" Center=\"Node\">\n     <DataItem "
                       "Dimensions=\"%d 4\" NumberType=\"Float\" Precision=\"8\" Format=\"HDF\">dem_grains.h5:/frame_%06d/"
                       "orientation</DataItem>\n    </Attribute>\n", n, k);
            fprintf(f, "    <Attribute Name=\"shape\" AttributeType=\"Scalar\" Center=\"Node\">\n     <DataItem "
                       "Dimensions=\"%d\" NumberType=\"Int\" Precision=\"4\" Format=\"HDF\">dem_grains.h5:/frame_%06d/shape"
                       "</DataItem>\n    </Attribute>\n", n, k);
        }
        fprintf(f, "   </Grid>\n");
    }
    fprintf(f, "  </Grid>\n </Domain>\n</Xdmf>\n");
    if (fclose(f) != 0 || rename(tmp, path) != 0)
        return cm_fail(err, CM_ERR_IO, "%s: %s", path, strerror(errno));
    return CM_OK;
}

/* The shapes' hull vertices, once (group /shapes, dataset shape_NNN per
 * polyhedral shape, attribute type on each). */
static int write_shapes(const dem_world *w, hid_t h5)
{
    hid_t grp = H5Gcreate2(h5, "shapes", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    int bad = grp < 0;
    for (int k = 0; k < w->n_shapes && !bad; k++) {
        const dem_shape *s = &w->shapes[k];
        if (s->type != DEM_SHAPE_POLYHEDRON)
            continue;
        char name[32];
        snprintf(name, sizeof name, "shape_%03d", k);
        bad = write_ds(grp, name, H5T_NATIVE_DOUBLE, s->n_verts, 3, s->v);
    }
    if (grp >= 0)
        H5Gclose(grp);
    return bad;
}

/* Per-frame orientation, shape id, scale and long axis (see the top). */
static int write_shaped(dem_output *o, const dem_world *w, hid_t grp)
{
    const dem_grains *g = &w->g;
    int n = g->n;
    if (!o->shapes_written) {
        if (write_shapes(w, o->h5))
            return -1;
        o->shapes_written = 1;
    }
    o->shaped = 1;
    double *q = malloc((size_t)n * 4 * sizeof *q), *ax = malloc((size_t)n * 3 * sizeof *ax);
    double *sc = malloc((size_t)n * sizeof *sc);
    int *sh = malloc((size_t)n * sizeof *sh);
    int bad = !q || !ax || !sc || !sh;
    for (int id = 0; id < n && !bad; id++) {
        int i = g->slot_of[id], k = g->shape[i];
        memcpy(q + 4 * id, g->q + 4 * i, 4 * sizeof *q);
        sh[id] = k;
        sc[id] = k < 0 ? g->r[i] : g->sc[i];
        double half = 0.0;
        if (k >= 0) {
            const dem_shape *s = &w->shapes[k];
            if (s->type == DEM_SHAPE_POLYHEDRON)
                for (int t = 0; t < s->n_verts; t++)
                    half = fmax(half, fabs(s->v[t][0]));
            else
                half = s->a[0];
            half *= g->sc[i];
        }
        double R[9];
        dem_quat_to_mat(g->q + 4 * i, R);
        for (int c = 0; c < 3; c++) /* first column of R: body axis 1 in the world */
            ax[3 * id + c] = half * R[3 * c];
    }
    if (!bad)
        bad = write_ds(grp, "orientation", H5T_NATIVE_DOUBLE, n, 4, q) ||
              write_ds(grp, "long_axis", H5T_NATIVE_DOUBLE, n, 3, ax) ||
              write_ds(grp, "scale", H5T_NATIVE_DOUBLE, n, 1, sc) || write_ds(grp, "shape", H5T_NATIVE_INT, n, 1, sh);
    free(q), free(ax), free(sc), free(sh);
    return bad ? -1 : 0;
}

int dem_output_frame(dem_output *o, const dem_world *w, cm_error *err)
{
    const dem_grains *g = &w->g;
    int n = g->n;
    if (o->n_frames == o->cap_frames) {
        int cap = o->cap_frames ? 2 * o->cap_frames : 64;
        double *t = realloc(o->times, (size_t)cap * sizeof *t);
        if (t)
            o->times = t;
        int *c = realloc(o->counts, (size_t)cap * sizeof *c);
        if (c)
            o->counts = c;
        if (!t || !c)
            return cm_fail(err, CM_ERR_NOMEM, "output frame %d: out of memory", o->n_frames);
        o->cap_frames = cap;
    }
    double *buf = malloc((size_t)n * 9 * sizeof *buf), *rad = malloc((size_t)n * sizeof *rad);
    int *cnt = malloc((size_t)n * sizeof *cnt), *tag = malloc((size_t)n * sizeof *tag);
    int rc = CM_OK;
    if (!buf || !rad || !cnt || !tag) {
        rc = cm_fail(err, CM_ERR_NOMEM, "output frame %d: out of memory", o->n_frames);
        goto done;
    }
    for (int id = 0; id < n; id++) {
        int i = g->slot_of[id];
        double *b = buf + 9 * id; /* staged as three n x 3 blocks below */
        b[0] = g->x[i], b[1] = g->y[i], b[2] = g->z[i];
        b[3] = g->vx[i], b[4] = g->vy[i], b[5] = g->vz[i];
        b[6] = g->wx[i], b[7] = g->wy[i], b[8] = g->wz[i];
        rad[id] = g->r[i];
        tag[id] = g->tag[i]; /* follows a grain across the terrain window's removals (ids are renumbered) */
    }
    dem_grain_contact_counts(w, cnt);
    double *blk = malloc((size_t)n * 3 * sizeof *blk);
    if (!blk) {
        rc = cm_fail(err, CM_ERR_NOMEM, "output frame %d: out of memory", o->n_frames);
        goto done;
    }
    char name[64];
    snprintf(name, sizeof name, "frame_%06d", o->n_frames);
    hid_t grp = H5Gcreate2(o->h5, name, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    const char *names[3] = {"position", "velocity", "angular_velocity"};
    int bad = grp < 0;
    for (int a = 0; a < 3 && !bad; a++) {
        for (int i = 0; i < n; i++)
            for (int k = 0; k < 3; k++)
                blk[3 * i + k] = buf[9 * i + 3 * a + k];
        bad = write_ds(grp, names[a], H5T_NATIVE_DOUBLE, n, 3, blk);
    }
    if (!bad)
        bad = write_ds(grp, "radius", H5T_NATIVE_DOUBLE, n, 1, rad) || write_ds(grp, "contacts", H5T_NATIVE_INT, n, 1, cnt) ||
              write_ds(grp, "tag", H5T_NATIVE_INT, n, 1, tag);
    if (!bad && w->n_shaped > 0)
        bad = write_shaped(o, w, grp);
    if (!bad) {
        hid_t sp = H5Screate(H5S_SCALAR);
        hid_t at = H5Acreate2(grp, "time", H5T_NATIVE_DOUBLE, sp, H5P_DEFAULT, H5P_DEFAULT);
        bad = at < 0 || H5Awrite(at, H5T_NATIVE_DOUBLE, &w->time) < 0;
        H5Sclose(sp);
    }
    if (grp >= 0)
        H5Gclose(grp);
    free(blk);
    if (bad || H5Fflush(o->h5, H5F_SCOPE_GLOBAL) < 0) {
        rc = cm_fail(err, CM_ERR_IO, "%s/dem_grains.h5: writing %s failed", o->dir, name);
        goto done;
    }
    o->times[o->n_frames] = w->time;
    o->counts[o->n_frames] = n;
    o->n_frames++;
    rc = write_xdmf(o, err);
done:
    free(buf), free(rad), free(cnt), free(tag);
    return rc;
}

int dem_output_series(dem_output *o, const dem_world *w, cm_error *err)
{
    dem_stats s;
    dem_world_stats_lean(w, &s); /* the row has no energies */
    return dem_output_series_row(o, &s, err);
}

int dem_output_series_row(dem_output *o, const dem_stats *st, cm_error *err)
{
    const dem_stats s = *st;
    if (fprintf(o->series, "%.9g,%ld,%.9g,%.9g,%d,%d,%d,%.6g,%d,%d,%.6g\n", s.time, s.step, s.ke_trans, s.ke_rot,
                s.contacts_gg, s.contacts_gw, s.contacts_gs, s.max_overlap, s.grains, s.frozen,
                s.max_overlap_surface) < 0 ||
        fflush(o->series) != 0)
        return cm_fail(err, CM_ERR_IO, "%s/dem_series.csv: write failed", o->dir);
    o->series_rows++;
    return CM_OK;
}

void dem_output_close(dem_output **op)
{
    dem_output *o = *op;
    if (!o)
        return;
    if (o->h5 >= 0)
        H5Fclose(o->h5);
    if (o->series)
        fclose(o->series);
    free(o->times);
    free(o->counts);
    free(o);
    *op = NULL;
}

void dem_output_counts(const dem_output *o, long *frames, long *series_rows)
{
    *frames = o ? o->n_frames : 0;
    *series_rows = o ? o->series_rows : 0;
}

/* Keeps the header and the first `rows` lines of the series, appends after them. */
static int reopen_series(dem_output *o, long rows, cm_error *err)
{
    char path[1100];
    snprintf(path, sizeof path, "%s/dem_series.csv", o->dir);
    if (!(o->series = fopen(path, "r+")))
        return cm_fail(err, CM_ERR_IO, "cannot reopen %s: %s", path, strerror(errno));
    long lines = 0;
    int ch;
    while (lines < rows + 1 && (ch = getc(o->series)) != EOF)
        lines += ch == '\n';
    if (lines < rows + 1)
        return cm_fail(err, CM_ERR_IO, "%s holds %ld rows, the checkpoint expects %ld", path, lines ? lines - 1 : 0,
                       rows);
    long pos = ftell(o->series);
    if (pos < 0 || fflush(o->series) != 0 || ftruncate(fileno(o->series), pos) != 0 ||
        fseek(o->series, pos, SEEK_SET) != 0)
        return cm_fail(err, CM_ERR_IO, "cutting %s back to %ld rows: %s", path, rows, strerror(errno));
    o->series_rows = rows;
    return CM_OK;
}

int dem_output_reopen(const char *dir, long frames, long series_rows, dem_output **out, cm_error *err)
{
    *out = NULL;
    dem_output *o = calloc(1, sizeof *o);
    if (!o)
        return cm_fail(err, CM_ERR_NOMEM, "%s: out of memory", dir);
    o->h5 = H5I_INVALID_HID;
    snprintf(o->dir, sizeof o->dir, "%s", dir);
    char path[1100];
    snprintf(path, sizeof path, "%s/dem_grains.h5", dir);
    H5Eset_auto2(H5E_DEFAULT, NULL, NULL);
    int rc = CM_OK;
    int cap = frames > 64 ? (int)frames : 64;
    o->times = malloc((size_t)cap * sizeof *o->times);
    o->counts = malloc((size_t)cap * sizeof *o->counts);
    o->cap_frames = cap;
    if (!o->times || !o->counts) {
        rc = cm_fail(err, CM_ERR_NOMEM, "%s: out of memory", dir);
        goto done;
    }
    /* Frames past the checkpoint go: the file is rebuilt from the frames
     * and shapes the checkpoint covers, not trimmed in place (a kill during
     * an HDF5 write leaves metadata referring past the file's recorded end;
     * h5io.h, cm_h5_rebuild). */
    if ((rc = cm_h5_rebuild(path, "/", "frame_", frames - 1, err)) != CM_OK)
        goto done;
    if ((o->h5 = H5Fopen(path, H5F_ACC_RDWR, H5P_DEFAULT)) < 0) {
        rc = cm_fail(err, CM_ERR_IO, "%s: cannot reopen the grain frames to resume", path);
        goto done;
    }
    /* A run with shaped grains wrote their hulls once (and frames list their
     * orientation in the XDMF): not again after resuming. */
    o->shapes_written = o->shaped = H5Lexists(o->h5, "shapes", H5P_DEFAULT) > 0;
    /* The kept frames are listed again. */
    for (long k = 0; k < frames; k++) {
        char name[64];
        snprintf(name, sizeof name, "frame_%06ld/position", k);
        hid_t ds = H5Dopen2(o->h5, name, H5P_DEFAULT);
        hid_t sp = ds >= 0 ? H5Dget_space(ds) : H5I_INVALID_HID;
        hsize_t dims[2] = {0, 0};
        int bad = sp < 0 || H5Sget_simple_extent_dims(sp, dims, NULL) != 2;
        if (sp >= 0)
            H5Sclose(sp);
        if (ds >= 0)
            H5Dclose(ds);
        snprintf(name, sizeof name, "frame_%06ld", k);
        hid_t a = bad ? H5I_INVALID_HID : H5Aopen_by_name(o->h5, name, "time", H5P_DEFAULT, H5P_DEFAULT);
        bad = bad || a < 0 || H5Aread(a, H5T_NATIVE_DOUBLE, &o->times[k]) < 0;
        if (a >= 0)
            H5Aclose(a);
        if (bad) {
            rc = cm_fail(err, CM_ERR_IO, "%s: frame %ld of the checkpoint is missing or unreadable", path, k);
            goto done;
        }
        o->counts[k] = (int)dims[0];
    }
    o->n_frames = (int)frames;
    if (H5Fflush(o->h5, H5F_SCOPE_GLOBAL) < 0) {
        rc = cm_fail(err, CM_ERR_IO, "%s: flush failed", path);
        goto done;
    }
    if ((rc = write_xdmf(o, err)) == CM_OK)
        rc = reopen_series(o, series_rows, err);
done:
    if (rc) {
        dem_output_close(&o);
        return rc;
    }
    *out = o;
    return CM_OK;
}
