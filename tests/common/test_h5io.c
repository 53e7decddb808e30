/* Results files: data read back through the plain HDF5 API equals what was
 * written, bit for bit; the XDMF index is well formed and every dataset it
 * names exists with the declared shape; a process killed by SIGKILL leaves
 * every flushed step and row readable; a writer killed at any of its writes
 * after a checkpoint resumes with exactly what the checkpoint covers (or, in
 * the one case HDF5's damage reaches it, fails naming the file and /steps);
 * errors name the path. */
#include <dirent.h>
#include <dlfcn.h>
#include <errno.h>
#include <signal.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <hdf5.h>

#include "h5io.h"
#include "test.h"

/* ---- scratch folder --------------------------------------------------------- */

static char g_dir[64];

static const char *scratch(void)
{
    snprintf(g_dir, sizeof g_dir, "/tmp/test_h5io.XXXXXX");
    return mkdtemp(g_dir);
}

static void scratch_remove(void)
{
    DIR *d = opendir(g_dir);
    if (!d)
        return;
    struct dirent *e;
    char p[512];
    while ((e = readdir(d)))
        if (strcmp(e->d_name, ".") && strcmp(e->d_name, "..")) {
            snprintf(p, sizeof p, "%s/%s", g_dir, e->d_name);
            unlink(p);
        }
    closedir(d);
    rmdir(g_dir);
}

static void in_scratch(char *buf, size_t len, const char *name)
{
    snprintf(buf, len, "%s/%s", g_dir, name);
}

/* ---- reading back ------------------------------------------------------------ */

/* Reads a whole dataset; checks its stored type and shape. Returns 0 on success. */
static int read_dataset(hid_t fid, const char *path, hid_t want_ftype, hid_t mtype, int want_rank, hsize_t d0,
                        hsize_t d1, void *out)
{
    hid_t d = H5Dopen2(fid, path, H5P_DEFAULT);
    if (d < 0) {
        fprintf(stderr, "cannot open %s\n", path);
        return 1;
    }
    hid_t t = H5Dget_type(d), s = H5Dget_space(d);
    hsize_t dims[2] = {0, 0};
    int rank = H5Sget_simple_extent_ndims(s);
    H5Sget_simple_extent_dims(s, dims, NULL);
    int bad = H5Tequal(t, want_ftype) <= 0 || rank != want_rank || dims[0] != d0 || (rank == 2 && dims[1] != d1);
    if (bad)
        fprintf(stderr, "%s: type or shape differs (rank %d, %llu x %llu)\n", path, rank,
                (unsigned long long)dims[0], (unsigned long long)dims[1]);
    else if (H5Dread(d, mtype, H5S_ALL, H5S_ALL, H5P_DEFAULT, out) < 0)
        bad = 1;
    H5Tclose(t);
    H5Sclose(s);
    H5Dclose(d);
    return bad;
}

static int read_attr(hid_t fid, const char *obj, const char *name, hid_t want_ftype, hid_t mtype, void *out)
{
    hid_t a = H5Aopen_by_name(fid, obj, name, H5P_DEFAULT, H5P_DEFAULT);
    if (a < 0)
        return 1;
    hid_t t = H5Aget_type(a);
    int bad = H5Tequal(t, want_ftype) <= 0 || H5Aread(a, mtype, out) < 0;
    H5Tclose(t);
    H5Aclose(a);
    return bad;
}

static char *slurp(const char *path)
{
    FILE *fp = fopen(path, "rb");
    if (!fp)
        return NULL;
    fseek(fp, 0, SEEK_END);
    long n = ftell(fp);
    fseek(fp, 0, SEEK_SET);
    char *s = malloc((size_t)n + 1);
    if (s && fread(s, 1, (size_t)n, fp) != (size_t)n) {
        free(s);
        s = NULL;
    }
    if (s)
        s[n] = '\0';
    fclose(fp);
    return s;
}

/* ---- a small mesh ------------------------------------------------------------- */

enum { NP = 5, NC = 2 };
static const double k_points0[NP * 3] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 1, 1, 1};
static const int k_tets[NC * 4] = {0, 1, 2, 3, 1, 2, 3, 4};

/* Values that do not survive a round trip through float or decimal %.6g. */
static double val(int i, int k)
{
    return (i + 1) / 3.0 + k * 1e-17 * (i + 7) - (k % 2 ? 1.0 / 7.0 : 0.0);
}

/* ---- tests ----------------------------------------------------------------------- */

static int snapshot_roundtrip(void)
{
    ENSURE(scratch());
    char path[128];
    in_scratch(path, sizeof path, "fem.h5");
    cm_error err = {0};
    cm_h5_def def = cm_h5_default_def();
    def.xdmf = CM_H5_XDMF_TETRAHEDRON;
    def.grid_name = "tire";
    def.geometry = "/mesh/points0";
    cm_h5 *f;
    ENSURE_MSG(cm_h5_create(path, &def, &f, &err) == CM_OK, "%s", err.msg);
    ENSURE(cm_h5_write_doubles(f, "/mesh/points0", k_points0, NP, 3, &err) == CM_OK);
    ENSURE(cm_h5_write_ints(f, "/mesh/connectivity", k_tets, NC, 4, &err) == CM_OK);
    ENSURE(cm_h5_attr_string(f, "/", "scene", "tire = { E = 5e6; };", &err) == CM_OK);
    ENSURE(cm_h5_attr_double(f, "/mesh", "scale", 0.25, &err) == CM_OK);

    double disp[NP * 3], stress[NC * 6], vm[NC];
    int region[NC] = {7, -3};
    for (int i = 0; i < NP * 3; i++)
        disp[i] = val(i, 1);
    for (int i = 0; i < NC * 6; i++)
        stress[i] = -val(i, 2) * 1e6;
    for (int i = 0; i < NC; i++)
        vm[i] = val(i, 3);
    const double t = 1.0 / 3.0 * 1e-3;
    ENSURE_MSG(cm_h5_step_begin(f, 123, t, &err) == CM_OK, "%s", err.msg);
    ENSURE(cm_h5_step_doubles(f, "displacement", CM_H5_NODE, disp, NP, 3, &err) == CM_OK);
    ENSURE(cm_h5_step_doubles(f, "stress", CM_H5_CELL, stress, NC, 6, &err) == CM_OK);
    ENSURE(cm_h5_step_doubles(f, "von_mises", CM_H5_CELL, vm, NC, 1, &err) == CM_OK);
    ENSURE(cm_h5_step_ints(f, "region", CM_H5_CELL, region, NC, 1, &err) == CM_OK);
    ENSURE_MSG(cm_h5_step_end(f, &err) == CM_OK, "%s", err.msg);
    /* A step number must grow. */
    ENSURE(cm_h5_step_begin(f, 123, 1.0, &err) == CM_ERR_STATE);
    ENSURE(strstr(err.msg, "123"));
    ENSURE(cm_h5_close(&f, &err) == CM_OK && f == NULL);

    hid_t fid = H5Fopen(path, H5F_ACC_RDONLY, H5P_DEFAULT);
    ENSURE(fid >= 0);
    double p[NP * 3], d[NP * 3], s[NC * 6], v[NC], time = 0;
    int c[NC * 4], r[NC];
    int64_t step = 0;
    ENSURE(!read_dataset(fid, "/mesh/points0", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, 2, NP, 3, p));
    ENSURE(!read_dataset(fid, "/mesh/connectivity", H5T_STD_I32LE, H5T_NATIVE_INT, 2, NC, 4, c));
    ENSURE(!read_dataset(fid, "/steps/000123/displacement", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, 2, NP, 3, d));
    ENSURE(!read_dataset(fid, "/steps/000123/stress", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, 2, NC, 6, s));
    ENSURE(!read_dataset(fid, "/steps/000123/von_mises", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, 1, NC, 0, v));
    ENSURE(!read_dataset(fid, "/steps/000123/region", H5T_STD_I32LE, H5T_NATIVE_INT, 1, NC, 0, r));
    ENSURE(memcmp(p, k_points0, sizeof p) == 0);
    ENSURE(memcmp(c, k_tets, sizeof c) == 0);
    ENSURE(memcmp(d, disp, sizeof d) == 0);
    ENSURE(memcmp(s, stress, sizeof s) == 0);
    ENSURE(memcmp(v, vm, sizeof v) == 0);
    ENSURE(r[0] == 7 && r[1] == -3);
    ENSURE(!read_attr(fid, "/steps/000123", "time", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, &time) && time == t);
    ENSURE(!read_attr(fid, "/steps/000123", "step", H5T_STD_I64LE, H5T_NATIVE_INT64, &step) && step == 123);
    double scale = 0;
    ENSURE(!read_attr(fid, "/mesh", "scale", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, &scale) && scale == 0.25);
    H5Fclose(fid);
    scratch_remove();
    return 0;
}

/* Reads the series table into rows x ncols doubles (by column name). */
static int read_series(hid_t fid, const char *path, const char *const *cols, int ncols, double *out,
                       hsize_t *rows)
{
    hid_t d = H5Dopen2(fid, path, H5P_DEFAULT);
    if (d < 0)
        return 1;
    hid_t s = H5Dget_space(d);
    H5Sget_simple_extent_dims(s, rows, NULL);
    hid_t mt = H5Tcreate(H5T_COMPOUND, sizeof(double) * (size_t)ncols);
    for (int i = 0; i < ncols; i++)
        H5Tinsert(mt, cols[i], sizeof(double) * (size_t)i, H5T_NATIVE_DOUBLE);
    int bad = out && H5Dread(d, mt, H5S_ALL, H5S_ALL, H5P_DEFAULT, out) < 0;
    H5Tclose(mt);
    H5Sclose(s);
    H5Dclose(d);
    return bad;
}

/* Checks the CSV: header, then each line's values equal rows[i][.] exactly. */
static int check_csv(const char *path, const char *header, const double *rows, long nrows, int ncols)
{
    char *text = slurp(path);
    ENSURE_MSG(text, "cannot read %s", path);
    long lines = 0;
    for (char *q = text; *q; q++)
        lines += *q == '\n';
    ENSURE_MSG(lines == nrows + 1, "%s: %ld lines, want %ld", path, lines, nrows + 1);
    char *line = text, *nl = strchr(line, '\n');
    *nl = '\0';
    ENSURE_MSG(strcmp(line, header) == 0, "header \"%s\"", line);
    for (long i = 0; i < nrows; i++) {
        line = nl + 1;
        nl = strchr(line, '\n');
        *nl = '\0';
        char *q = line;
        for (int k = 0; k < ncols; k++) {
            char *end;
            double x = strtod(q, &end);
            ENSURE_MSG(end != q && x == rows[i * ncols + k], "row %ld col %d: %s", i, k, line);
            q = *end == ',' ? end + 1 : end;
        }
        ENSURE(*q == '\0');
    }
    free(text);
    return 0;
}

static int series_1000_rows(void)
{
    ENSURE(scratch());
    char path[128], csv[128];
    in_scratch(path, sizeof path, "dem.h5");
    in_scratch(csv, sizeof csv, "dem_series.csv");
    cm_error err = {0};
    cm_h5 *f;
    ENSURE_MSG(cm_h5_create(path, NULL, &f, &err) == CM_OK, "%s", err.msg);
    static const char *const cols[] = {"t", "KE", "contacts"};
    enum { NR = 1000, NCOL = 3 };
    cm_h5_series *s;
    ENSURE_MSG(cm_h5_series_create(f, "/series", cols, NCOL, csv, &s, &err) == CM_OK, "%s", err.msg);
    static double rows[NR * NCOL];
    for (int i = 0; i < NR; i++) {
        rows[i * 3 + 0] = i * 1e-4 / 3.0;
        rows[i * 3 + 1] = val(i, 1) * 1e-9;
        rows[i * 3 + 2] = i % 17;
        ENSURE_MSG(cm_h5_series_append(s, &rows[i * 3], &err) == CM_OK, "%s", err.msg);
    }
    ENSURE(cm_h5_series_rows(s) == NR);
    /* Bad column sets are refused with the column named. */
    static const char *const dup[] = {"t", "t"};
    cm_h5_series *s2;
    ENSURE(cm_h5_series_create(f, "/series2", dup, 2, NULL, &s2, &err) == CM_ERR_RANGE && strstr(err.msg, "\"t\""));
    static const char *const comma[] = {"a,b"};
    ENSURE(cm_h5_series_create(f, "/series3", comma, 1, NULL, &s2, &err) == CM_ERR_RANGE &&
           strstr(err.msg, "a,b"));
    ENSURE(cm_h5_close(&f, &err) == CM_OK);

    hid_t fid = H5Fopen(path, H5F_ACC_RDONLY, H5P_DEFAULT);
    ENSURE(fid >= 0);
    static double back[NR * NCOL];
    hsize_t n = 0;
    ENSURE(!read_series(fid, "/series", cols, NCOL, back, &n));
    ENSURE(n == NR);
    ENSURE(memcmp(back, rows, sizeof rows) == 0);
    /* Each field is stored as IEEE F64LE, in column order. */
    hid_t d = H5Dopen2(fid, "/series", H5P_DEFAULT), t = H5Dget_type(d), pl = H5Dget_create_plist(d);
    ENSURE(H5Tget_nmembers(t) == NCOL);
    for (int i = 0; i < NCOL; i++) {
        char *name = H5Tget_member_name(t, (unsigned)i);
        hid_t mt = H5Tget_member_type(t, (unsigned)i);
        ENSURE(strcmp(name, cols[i]) == 0 && H5Tequal(mt, H5T_IEEE_F64LE) > 0);
        H5Tclose(mt);
        H5free_memory(name);
    }
    ENSURE(H5Pget_layout(pl) == H5D_CHUNKED);
    H5Pclose(pl);
    H5Tclose(t);
    H5Dclose(d);
    H5Fclose(fid);
    ENSURE(check_csv(csv, "t,KE,contacts", rows, NR, NCOL) == 0);
    scratch_remove();
    return 0;
}

static int unwritable_path_names_path(void)
{
    ENSURE(scratch());
    cm_error err = {0};
    cm_h5 *f = (cm_h5 *)&err; /* must be reset to NULL */
    const char *missing = "/nonexistent-folder-h5io/run/dem.h5";
    ENSURE(cm_h5_create(missing, NULL, &f, &err) == CM_ERR_IO);
    ENSURE(f == NULL);
    ENSURE_MSG(strstr(err.msg, missing) && strstr(err.msg, "No such file"), "%s", err.msg);

    /* A regular file where a folder should be (fails even for root). */
    char file[128], below[160];
    in_scratch(file, sizeof file, "plain");
    FILE *fp = fopen(file, "w");
    ENSURE(fp && fclose(fp) == 0);
    snprintf(below, sizeof below, "%s/fem.h5", file);
    ENSURE(cm_h5_create(below, NULL, &f, &err) == CM_ERR_IO);
    ENSURE_MSG(strstr(err.msg, below) && strstr(err.msg, "Not a directory"), "%s", err.msg);

    /* An HDF5-level failure also names the file and the dataset. */
    char path[128];
    in_scratch(path, sizeof path, "ok.h5");
    ENSURE(cm_h5_create(path, NULL, &f, &err) == CM_OK);
    double x[3] = {1, 2, 3};
    ENSURE(cm_h5_write_doubles(f, "/mesh/x", x, 3, 1, &err) == CM_OK);
    ENSURE(cm_h5_write_doubles(f, "/mesh/x", x, 3, 1, &err) == CM_ERR_IO);
    ENSURE_MSG(strstr(err.msg, path) && strstr(err.msg, "/mesh/x"), "%s", err.msg);
    ENSURE(cm_h5_attr_double(f, "/no/such", "a", 1.0, &err) == CM_ERR_IO);
    ENSURE_MSG(strstr(err.msg, path) && strstr(err.msg, "/no/such"), "%s", err.msg);
    ENSURE(cm_h5_write_doubles(f, "mesh/rel", x, 3, 1, &err) == CM_ERR_RANGE && strstr(err.msg, "mesh/rel"));
    ENSURE(cm_h5_step_doubles(f, "x", CM_H5_NODE, x, 3, 1, &err) == CM_ERR_STATE);
    ENSURE(cm_h5_close(&f, &err) == CM_OK);
    scratch_remove();
    return 0;
}

/* ---- XDMF checking ------------------------------------------------------------------ */

/* Value of attribute `name` inside the tag text [tag, end); copies into buf. */
static int tag_attr(const char *tag, const char *end, const char *name, char *buf, size_t len)
{
    size_t nl = strlen(name);
    for (const char *q = tag; q + nl + 2 < end; q++) {
        if ((q[-1] == ' ' || q[-1] == '\n') && strncmp(q, name, nl) == 0 && q[nl] == '=' && q[nl + 1] == '"') {
            const char *v = q + nl + 2, *ve = memchr(v, '"', (size_t)(end - v));
            if (!ve || (size_t)(ve - v) >= len)
                return 0;
            memcpy(buf, v, (size_t)(ve - v));
            buf[ve - v] = '\0';
            return 1;
        }
    }
    return 0;
}

typedef struct xdmf_info {
    int grids;       /* uniform grids (time steps) */
    double times[64];
    int hdf_items;   /* DataItems referring to the HDF5 file */
} xdmf_info;

/* Checks well-formedness (every tag closed in order, one root), collects
 * Time values, and opens every HDF5 dataset a DataItem names, checking its
 * dimensions against the DataItem's. */
static int check_xdmf(const char *xmf, const char *h5base, hid_t fid, xdmf_info *info)
{
    memset(info, 0, sizeof *info);
    char *text = slurp(xmf);
    ENSURE_MSG(text, "cannot read %s", xmf);
    char stack[32][32];
    int depth = 0, roots = 0;
    char dims[64] = "";
    int in_hdf_item = 0;
    const char *q = text;
    while ((q = strchr(q, '<'))) {
        const char *end = strchr(q, '>');
        ENSURE_MSG(end, "unterminated tag");
        if (q[1] == '?' || q[1] == '!') { /* declaration, doctype */
            q = end + 1;
            continue;
        }
        if (q[1] == '/') {
            char name[32];
            size_t n = (size_t)(end - q - 2);
            ENSURE(n < sizeof name);
            memcpy(name, q + 2, n);
            name[n] = '\0';
            ENSURE_MSG(depth > 0 && strcmp(stack[depth - 1], name) == 0, "</%s> does not close <%s>", name,
                       depth ? stack[depth - 1] : "");
            if (strcmp(name, "DataItem") == 0 && in_hdf_item) {
                /* text between the opening tag's end and this '<' */
                in_hdf_item = 0;
            }
            depth--;
            q = end + 1;
            continue;
        }
        size_t n = strcspn(q + 1, " />\n");
        ENSURE(n < 32);
        char name[32];
        memcpy(name, q + 1, n);
        name[n] = '\0';
        int self_closing = end[-1] == '/';
        if (depth == 0)
            roots++;
        if (strcmp(name, "Grid") == 0) {
            char gt[32];
            if (tag_attr(q, end, "GridType", gt, sizeof gt) && strcmp(gt, "Uniform") == 0)
                info->grids++;
        }
        if (strcmp(name, "Time") == 0) {
            char v[64];
            ENSURE(tag_attr(q, end, "Value", v, sizeof v));
            ENSURE(info->grids > 0 && info->grids <= 64);
            info->times[info->grids - 1] = strtod(v, NULL);
        }
        if (strcmp(name, "DataItem") == 0 && !self_closing) {
            char fmt[16] = "";
            tag_attr(q, end, "Format", fmt, sizeof fmt);
            if (strcmp(fmt, "HDF") == 0) {
                ENSURE(tag_attr(q, end, "Dimensions", dims, sizeof dims));
                const char *body = end + 1, *close = strchr(body, '<');
                ENSURE(close);
                char ref[256];
                ENSURE((size_t)(close - body) < sizeof ref);
                memcpy(ref, body, (size_t)(close - body));
                ref[close - body] = '\0';
                char *colon = strchr(ref, ':');
                ENSURE_MSG(colon, "no ':' in %s", ref);
                *colon = '\0';
                ENSURE_MSG(strcmp(ref, h5base) == 0, "DataItem refers to file %s, not %s", ref, h5base);
                const char *dpath = colon + 1;
                hid_t d = H5Dopen2(fid, dpath, H5P_DEFAULT);
                ENSURE_MSG(d >= 0, "XDMF names %s, which is not in the HDF5 file", dpath);
                hid_t s = H5Dget_space(d);
                hsize_t hd[2] = {0, 0};
                int rank = H5Sget_simple_extent_ndims(s);
                H5Sget_simple_extent_dims(s, hd, NULL);
                H5Sclose(s);
                H5Dclose(d);
                char want[64];
                if (rank == 1)
                    snprintf(want, sizeof want, "%llu", (unsigned long long)hd[0]);
                else
                    snprintf(want, sizeof want, "%llu %llu", (unsigned long long)hd[0], (unsigned long long)hd[1]);
                ENSURE_MSG(strcmp(want, dims) == 0, "%s: XDMF says %s, HDF5 has %s", dpath, dims, want);
                info->hdf_items++;
                in_hdf_item = 1;
            }
        }
        if (!self_closing) {
            ENSURE(depth < 32);
            snprintf(stack[depth++], sizeof stack[0], "%s", name);
        }
        q = end + 1;
    }
    ENSURE_MSG(depth == 0, "<%s> never closed", stack[depth - 1]);
    ENSURE(roots == 1);
    free(text);
    return 0;
}

static int xdmf_well_formed(void)
{
    ENSURE(scratch());
    char path[128];
    in_scratch(path, sizeof path, "grains.h5");
    cm_error err = {0};
    cm_h5_def def = cm_h5_default_def();
    def.xdmf = CM_H5_XDMF_POLYVERTEX;
    def.grid_name = "grains";
    cm_h5 *f;
    ENSURE_MSG(cm_h5_create(path, &def, &f, &err) == CM_OK, "%s", err.msg);
    char xmf[128];
    in_scratch(xmf, sizeof xmf, "grains.xmf");
    ENSURE(strcmp(cm_h5_xdmf_path(f), xmf) == 0);
    /* Grain counts vary: the shared vertex ids grow, then are sliced. */
    static const int counts[] = {4, 9, 6, 9};
    double times[4];
    double pos[9 * 3], vel[9 * 3], rad[9];
    int ids[9];
    for (int k = 0; k < 4; k++) {
        int n = counts[k];
        for (int i = 0; i < n * 3; i++) {
            pos[i] = val(i, k);
            vel[i] = -val(i, k + 1);
        }
        for (int i = 0; i < n; i++) {
            rad[i] = 1e-3 * (1 + i % 3);
            ids[i] = 100 + i;
        }
        times[k] = (k + 1) * 2.5e-4 / 3.0;
        ENSURE(cm_h5_step_begin(f, 10L * k, times[k], &err) == CM_OK);
        ENSURE(cm_h5_step_doubles(f, "position", CM_H5_NODE, pos, (size_t)n, 3, &err) == CM_OK);
        ENSURE(cm_h5_step_doubles(f, "velocity", CM_H5_NODE, vel, (size_t)n, 3, &err) == CM_OK);
        ENSURE(cm_h5_step_doubles(f, "radius", CM_H5_NODE, rad, (size_t)n, 1, &err) == CM_OK);
        ENSURE(cm_h5_step_ints(f, "id", CM_H5_NODE, ids, (size_t)n, 1, &err) == CM_OK);
        ENSURE(cm_h5_step_doubles(f, "scratch", CM_H5_UNLISTED, rad, 2, 1, &err) == CM_OK);
        ENSURE_MSG(cm_h5_step_end(f, &err) == CM_OK, "%s", err.msg);
        /* After every step the index is complete and consistent. */
        hid_t fid = H5Fopen(path, H5F_ACC_RDONLY, H5P_DEFAULT);
        ENSURE(fid >= 0);
        xdmf_info info;
        int bad = check_xdmf(xmf, "grains.h5", fid, &info);
        H5Fclose(fid);
        ENSURE(bad == 0);
        ENSURE(info.grids == k + 1);
        for (int j = 0; j <= k; j++)
            ENSURE(info.times[j] == times[j]);
        /* topology, geometry and 3 attributes (velocity, radius, id) per step */
        ENSURE_MSG(info.hdf_items == 5 * (k + 1), "%d items", info.hdf_items);
        struct stat st;
        char tmp[160];
        snprintf(tmp, sizeof tmp, "%s.tmp", xmf);
        ENSURE(stat(tmp, &st) != 0 && errno == ENOENT);
    }
    char *text = slurp(xmf);
    ENSURE(text);
    ENSURE(strstr(text, "<Xdmf Version=\"3.0\">"));
    ENSURE(strstr(text, "TopologyType=\"Polyvertex\""));
    ENSURE(strstr(text, "ItemType=\"HyperSlab\"")); /* step 20 has 6 of 9 ids */
    ENSURE(strstr(text, "Name=\"velocity\" AttributeType=\"Vector\" Center=\"Node\""));
    ENSURE(!strstr(text, "scratch"));
    free(text);

    /* Mistakes are caught at step end, naming the dataset. */
    ENSURE(cm_h5_step_begin(f, 50, 1.0, &err) == CM_OK);
    ENSURE(cm_h5_step_doubles(f, "position", CM_H5_NODE, pos, 9, 3, &err) == CM_OK);
    ENSURE(cm_h5_step_doubles(f, "radius", CM_H5_NODE, rad, 8, 1, &err) == CM_OK);
    ENSURE(cm_h5_step_end(f, &err) == CM_ERR_RANGE);
    ENSURE_MSG(strstr(err.msg, "/steps/000050/radius") && strstr(err.msg, "8 rows"), "%s", err.msg);
    ENSURE(cm_h5_step_begin(f, 60, 1.1, &err) == CM_OK);
    ENSURE(cm_h5_step_doubles(f, "velocity", CM_H5_NODE, vel, 9, 2, &err) == CM_ERR_RANGE);
    ENSURE(cm_h5_step_end(f, &err) == CM_ERR_STATE && strstr(err.msg, "\"position\""));
    ENSURE(cm_h5_close(&f, &err) == CM_OK);

    /* The tetrahedral variant: per-step deformed points, cell tensors. */
    in_scratch(path, sizeof path, "tire.hdf5");
    def = cm_h5_default_def();
    def.xdmf = CM_H5_XDMF_TETRAHEDRON;
    ENSURE(cm_h5_create(path, &def, &f, &err) == CM_OK);
    in_scratch(xmf, sizeof xmf, "tire.xmf");
    ENSURE(strcmp(cm_h5_xdmf_path(f), xmf) == 0);
    ENSURE(cm_h5_write_ints(f, "/mesh/connectivity", k_tets, NC, 4, &err) == CM_OK);
    double strain[NC * 6] = {0};
    for (int k = 0; k < 3; k++) {
        for (int i = 0; i < NP * 3; i++)
            pos[i] = k_points0[i] + 1e-3 * k * val(i, 0);
        ENSURE(cm_h5_step_begin(f, k, 0.1 * k, &err) == CM_OK);
        ENSURE(cm_h5_step_doubles(f, "position", CM_H5_NODE, pos, NP, 3, &err) == CM_OK);
        ENSURE(cm_h5_step_doubles(f, "displacement", CM_H5_NODE, pos, NP, 3, &err) == CM_OK);
        ENSURE(cm_h5_step_doubles(f, "strain", CM_H5_CELL, strain, NC, 6, &err) == CM_OK);
        ENSURE(cm_h5_step_doubles(f, "strain_xx", CM_H5_CELL, strain, NC, 1, &err) == CM_OK);
        ENSURE_MSG(cm_h5_step_end(f, &err) == CM_OK, "%s", err.msg);
    }
    ENSURE(cm_h5_close(&f, &err) == CM_OK);
    hid_t fid = H5Fopen(path, H5F_ACC_RDONLY, H5P_DEFAULT);
    ENSURE(fid >= 0);
    xdmf_info info;
    int bad = check_xdmf(xmf, "tire.hdf5", fid, &info);
    H5Fclose(fid);
    ENSURE(bad == 0 && info.grids == 3 && info.hdf_items == 3 * 5);
    ENSURE(info.times[2] == 0.1 * 2);
    text = slurp(xmf);
    ENSURE(text && strstr(text, "TopologyType=\"Tetrahedron\" NumberOfElements=\"2\""));
    ENSURE(strstr(text, "Name=\"strain\" AttributeType=\"Tensor6\" Center=\"Cell\""));
    free(text);
    scratch_remove();
    return 0;
}

/* ---- durability ----------------------------------------------------------------------- */

enum { KILL_STEPS = 5, ROWS_PER_STEP = 7 };

static double kill_row(int r, int k)
{
    return k == 0 ? r * 1e-5 : val(r, k);
}

/* Runs child(path, csv, arg) in a forked process (which must end by
 * _exit or a signal); its wait status, or -1. */
static int child_status(void (*child)(const char *, const char *, long), const char *path, const char *csv,
                        long arg)
{
    fflush(NULL);
    pid_t pid = fork();
    if (pid < 0)
        return -1;
    if (pid == 0)
        child(path, csv, arg);
    int status = 0;
    return waitpid(pid, &status, 0) == pid ? status : -1;
}

/* Child: writes steps and rows, starts one more step and then dies. */
static void kill_child(const char *path, const char *csv, long unused)
{
    cm_error err = {0};
    cm_h5_def def = cm_h5_default_def();
    def.xdmf = CM_H5_XDMF_POLYVERTEX;
    cm_h5 *f;
    if (cm_h5_create(path, &def, &f, &err) != CM_OK)
        _exit(3);
    static const char *const cols[] = {"t", "KE"};
    cm_h5_series *s;
    if (cm_h5_series_create(f, "/series", cols, 2, csv, &s, &err) != CM_OK)
        _exit(4);
    double pos[30], row[2];
    for (int i = 0; i < 30; i++)
        pos[i] = val(i, 0);
    int r = 0;
    /* Rows after each step: the last ones are made durable only by
     * cm_h5_series_append's own flush. */
    for (int k = 0; k < KILL_STEPS; k++) {
        if (cm_h5_step_begin(f, k, k * 0.5, &err) != CM_OK ||
            cm_h5_step_doubles(f, "position", CM_H5_NODE, pos, 10, 3, &err) != CM_OK ||
            cm_h5_step_end(f, &err) != CM_OK)
            _exit(6);
        for (int j = 0; j < ROWS_PER_STEP; j++, r++) {
            row[0] = kill_row(r, 0);
            row[1] = kill_row(r, 1);
            if (cm_h5_series_append(s, row, &err) != CM_OK)
                _exit(5);
        }
    }
    /* An unfinished step: written, not flushed, not in the XDMF. */
    if (cm_h5_step_begin(f, KILL_STEPS, 99.0, &err) != CM_OK ||
        cm_h5_step_doubles(f, "position", CM_H5_NODE, pos, 10, 3, &err) != CM_OK)
        _exit(7);
    raise(SIGKILL);
    _exit(8);
}

static int durability_after_sigkill(void)
{
    ENSURE(scratch());
    char path[128], csv[128], xmf[128];
    in_scratch(path, sizeof path, "killed.h5");
    in_scratch(csv, sizeof csv, "killed.csv");
    in_scratch(xmf, sizeof xmf, "killed.xmf");
    int status = child_status(kill_child, path, csv, 0);
    ENSURE(status != -1);
    ENSURE_MSG(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL, "child status %d", status);

    enum { NR = KILL_STEPS * ROWS_PER_STEP };
    double want[NR * 2];
    for (int r = 0; r < NR; r++) {
        want[2 * r] = kill_row(r, 0);
        want[2 * r + 1] = kill_row(r, 1);
    }
    hid_t fid = H5Fopen(path, H5F_ACC_RDONLY, H5P_DEFAULT);
    ENSURE_MSG(fid >= 0, "the killed writer's file does not open");
    static const char *const cols[] = {"t", "KE"};
    double back[NR * 2];
    hsize_t n = 0;
    ENSURE(!read_series(fid, "/series", cols, 2, NULL, &n));
    ENSURE_MSG(n == NR, "%llu rows, want %d", (unsigned long long)n, NR);
    ENSURE(!read_series(fid, "/series", cols, 2, back, &n));
    ENSURE(memcmp(back, want, sizeof want) == 0);
    for (int k = 0; k < KILL_STEPS; k++) {
        char ds[64];
        double pos[30], t = -1;
        snprintf(ds, sizeof ds, "/steps/%06d/position", k);
        ENSURE_MSG(!read_dataset(fid, ds, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, 2, 10, 3, pos), "%s", ds);
        ENSURE(pos[29] == val(29, 0));
        snprintf(ds, sizeof ds, "/steps/%06d", k);
        ENSURE(!read_attr(fid, ds, "time", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, &t) && t == k * 0.5);
    }
    xdmf_info info;
    int bad = check_xdmf(xmf, "killed.h5", fid, &info);
    H5Fclose(fid);
    ENSURE(bad == 0 && info.grids == KILL_STEPS);
    ENSURE(check_csv(csv, "t,KE", want, NR, 2) == 0);
    scratch_remove();
    return 0;
}

/* Held rows (cm_h5_series_hold): a child holds blocks of HOLD_ROWS, appends
 * HELD_N rows and then, by `how`, dies at once (0), after
 * cm_h5_series_flush (1), or closes the file (2). What reached the files:
 * the whole blocks only, or every row. */
enum { HOLD_ROWS = 4, HELD_N = 10 };

static void held_child(const char *path, const char *csv, long how)
{
    cm_error err = {0};
    cm_h5_def def = cm_h5_default_def();
    cm_h5 *f;
    static const char *const cols[] = {"t", "KE"};
    cm_h5_series *s;
    if (cm_h5_create(path, &def, &f, &err) != CM_OK || cm_h5_series_create(f, "/series", cols, 2, csv, &s, &err) ||
        cm_h5_series_hold(s, HOLD_ROWS, 1e9, &err)) /* never by time: the test must not depend on the clock */
        _exit(3);
    for (int r = 0; r < HELD_N; r++) {
        double row[2] = {kill_row(r, 0), kill_row(r, 1)};
        if (cm_h5_series_append(s, row, &err) != CM_OK || cm_h5_series_rows(s) != r + 1)
            _exit(4);
    }
    if (how == 1 && cm_h5_series_flush(s, &err) != CM_OK)
        _exit(5);
    if (how == 2)
        _exit(cm_h5_close(&f, &err) == CM_OK ? 0 : 6);
    raise(SIGKILL);
    _exit(8);
}

static int held_rows_reach_the_files_in_blocks(void)
{
    ENSURE(scratch());
    static const char *const cols[] = {"t", "KE"};
    double want[HELD_N * 2];
    for (int r = 0; r < HELD_N; r++)
        want[2 * r] = kill_row(r, 0), want[2 * r + 1] = kill_row(r, 1);
    for (int how = 0; how < 3; how++) {
        char path[128], csv[128];
        in_scratch(path, sizeof path, "held.h5");
        in_scratch(csv, sizeof csv, "held.csv");
        int status = child_status(held_child, path, csv, how);
        ENSURE(status != -1);
        ENSURE_MSG(how == 2 ? WIFEXITED(status) && WEXITSTATUS(status) == 0
                            : WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL,
                   "case %d: child status %d", how, status);
        /* killed holding rows: the two whole blocks; flushed or closed: all */
        const hsize_t expect = how == 0 ? HELD_N / HOLD_ROWS * HOLD_ROWS : HELD_N;
        hid_t fid = H5Fopen(path, H5F_ACC_RDONLY, H5P_DEFAULT);
        ENSURE_MSG(fid >= 0, "case %d: the file does not open", how);
        double back[HELD_N * 2];
        hsize_t n = 0;
        int bad = read_series(fid, "/series", cols, 2, NULL, &n) || n != expect ||
                  read_series(fid, "/series", cols, 2, back, &n) || memcmp(back, want, n * 2 * sizeof *back) != 0;
        H5Fclose(fid);
        ENSURE_MSG(!bad, "case %d: %llu rows in the HDF5 file, want %llu of the appended ones", how,
                   (unsigned long long)n, (unsigned long long)expect);
        ENSURE_MSG(check_csv(csv, "t,KE", want, (long)expect, 2) == 0, "case %d: the CSV", how);
    }
    scratch_remove();
    return 0;
}

/* Resuming: a file with steps 0, 10, 20 and 5 series rows (+ CSV) reopened
 * to continue after step 10 and row 3 keeps exactly those, lists them again
 * in the XDMF, and continues with step 30 and a 4th row; typed arrays read
 * back bit for bit and a wrong shape or type is refused. */
static int reopen_cuts_back_and_continues(void)
{
    ENSURE(scratch());
    char path[128], csv[128], xmf[128];
    in_scratch(path, sizeof path, "run.h5");
    in_scratch(csv, sizeof csv, "run.csv");
    in_scratch(xmf, sizeof xmf, "run.xmf");
    static const char *const cols[] = {"t", "x"};
    cm_error err = {0};
    cm_h5_def def = cm_h5_default_def();
    def.xdmf = CM_H5_XDMF_POLYVERTEX;
    cm_h5 *f = NULL;
    cm_h5_series *se = NULL;
    const double pos[6] = {0, 0, 0, 1, 1, 1}, vel[6] = {1, 2, 3, 4, 5, 6};
    ENSURE(cm_h5_create(path, &def, &f, &err) == CM_OK);
    ENSURE(cm_h5_series_create(f, "/series", cols, 2, csv, &se, &err) == CM_OK);
    for (int k = 0; k < 3; k++) {
        ENSURE(cm_h5_step_begin(f, 10L * k, 0.1 * k, &err) == CM_OK);
        ENSURE(cm_h5_step_doubles(f, "position", CM_H5_NODE, pos, 2, 3, &err) == CM_OK);
        ENSURE(cm_h5_step_doubles(f, "velocity", CM_H5_NODE, vel, 2, 3, &err) == CM_OK);
        ENSURE(cm_h5_step_end(f, &err) == CM_OK);
    }
    for (int r = 0; r < 5; r++) {
        const double row[2] = {r, r * 1.5};
        ENSURE(cm_h5_series_append(se, row, &err) == CM_OK);
    }
    ENSURE(cm_h5_close(&f, &err) == CM_OK);

    ENSURE_MSG(cm_h5_reopen(path, &def, 10, &f, &err) == CM_OK, "%s", err.msg);
    ENSURE_MSG(cm_h5_series_reopen(f, "/series", cols, 2, csv, 3, &se, &err) == CM_OK, "%s", err.msg);
    ENSURE(cm_h5_series_rows(se) == 3);
    char *text = slurp(xmf);
    ENSURE(text && strstr(text, "step_000010") && !strstr(text, "step_000020") &&
           strstr(text, "Name=\"velocity\""));
    free(text);
    ENSURE(cm_h5_step_begin(f, 10, 0.5, &err) != CM_OK); /* must follow the last kept step */
    ENSURE(cm_h5_step_begin(f, 30, 0.3, &err) == CM_OK);
    ENSURE(cm_h5_step_doubles(f, "position", CM_H5_NODE, pos, 2, 3, &err) == CM_OK);
    ENSURE(cm_h5_step_end(f, &err) == CM_OK);
    const double row[2] = {7, 8};
    ENSURE(cm_h5_series_append(se, row, &err) == CM_OK);
    /* raw arrays, as checkpoints use them */
    const uint64_t keys[3] = {UINT64_MAX, 1ull << 63, 12345};
    ENSURE(cm_h5_write_array(f, "/ck/keys", CM_H5_U64, keys, 3, 1, &err) == CM_OK);
    ENSURE(cm_h5_close(&f, &err) == CM_OK);

    const double want[8] = {0, 0, 1, 1.5, 2, 3, 7, 8};
    ENSURE(check_csv(csv, "t,x", want, 4, 2) == 0);
    ENSURE(cm_h5_open(path, 0, &f, &err) == CM_OK);
    uint64_t back[3];
    double wrong[3];
    ENSURE(cm_h5_read_array(f, "/ck/keys", CM_H5_U64, back, 3, 1, &err) == CM_OK);
    ENSURE(memcmp(back, keys, sizeof keys) == 0);
    ENSURE(cm_h5_read_array(f, "/ck/keys", CM_H5_F64, wrong, 3, 1, &err) == CM_ERR_PARSE);
    ENSURE(cm_h5_read_array(f, "/ck/keys", CM_H5_U64, back, 2, 1, &err) == CM_ERR_PARSE);
    ENSURE(cm_h5_close(&f, &err) == CM_OK);
    hid_t fid = H5Fopen(path, H5F_ACC_RDONLY, H5P_DEFAULT);
    ENSURE(fid >= 0);
    ENSURE(H5Lexists(fid, "/steps/000010", H5P_DEFAULT) > 0 && H5Lexists(fid, "/steps/000030", H5P_DEFAULT) > 0);
    ENSURE(H5Lexists(fid, "/steps/000020", H5P_DEFAULT) == 0);
    hid_t d = H5Dopen2(fid, "/series", H5P_DEFAULT), sp = H5Dget_space(d);
    hsize_t n = 0;
    H5Sget_simple_extent_dims(sp, &n, NULL);
    H5Sclose(sp);
    H5Dclose(d);
    H5Fclose(fid);
    ENSURE(n == 4);
    /* a CSV with fewer rows than the checkpoint expects is refused, naming it */
    ENSURE(cm_h5_reopen(path, &def, 30, &f, &err) == CM_OK);
    ENSURE(cm_h5_series_reopen(f, "/series", cols, 2, csv, 9, &se, &err) != CM_OK && strstr(err.msg, "run.h5"));
    ENSURE(cm_h5_close(&f, &err) == CM_OK);
    scratch_remove();
    return 0;
}

/* ---- resuming after a kill in the middle of a write ---------------------------------
 *
 * HDF5 files are not crash-consistent: a process killed while HDF5 writes
 * its metadata out (during a flush, or when the metadata cache evicts
 * entries) leaves entries that refer to space allocated after the last
 * completed flush. To kill at every such moment deterministically, this
 * program's pwrite (the system call HDF5's default file driver writes with;
 * h5io's XDMF append uses it too) counts the writes in the child and raises
 * SIGKILL before the n-th one. HDF5 itself is the real library: only the
 * moment of the kill is chosen. */

static long g_pwrites, g_kill_at; /* child only: kill before write g_kill_at (0: never) */

ssize_t pwrite(int fd, const void *buf, size_t n, off_t off)
{
    static ssize_t (*next)(int, const void *, size_t, off_t);
    if (!next)
        *(void **)&next = dlsym(RTLD_NEXT, "pwrite");
    if (g_kill_at > 0 && ++g_pwrites == g_kill_at)
        raise(SIGKILL);
    return next(fd, buf, n, off);
}

/* RS_ROWS rows: one with each of the last RS_ROWS kept steps (fewer flushes
 * than a row per step: the sweep forks a writer per kill point). */
enum { RS_KEPT = 64, RS_AFTER = 2, RS_NP = 6, RS_ROWS = 4 };

static double rs_val(long step, int ds, int i)
{
    return val(i, (int)step) + 100.0 * ds + step;
}

/* Child: a results file with static data, an attribute, RS_KEPT steps (a
 * row with each of the last RS_ROWS), a checkpoint (a flush), then RS_AFTER
 * more steps and rows, killed
 * before its kill_at-th write after the checkpoint. Exit 0: the writes
 * ended before kill_at. */
static void rs_child(const char *path, const char *csv, long kill_at)
{
    cm_error err = {0};
    cm_h5_def def = cm_h5_default_def();
    def.xdmf = CM_H5_XDMF_POLYVERTEX;
    cm_h5 *f;
    cm_h5_series *se;
    static const char *const cols[] = {"t", "KE"};
    if (cm_h5_create(path, &def, &f, &err) != CM_OK || cm_h5_series_create(f, "/series", cols, 2, csv, &se, &err) ||
        cm_h5_write_doubles(f, "/mesh/points0", k_points0, NP, 3, &err) ||
        cm_h5_attr_string(f, "/", "units", "m, s", &err))
        _exit(3);
    for (long k = 0; k < RS_KEPT + RS_AFTER; k++) {
        if (k == RS_KEPT) { /* the checkpoint */
            if (cm_h5_flush(f, &err) != CM_OK)
                _exit(4);
            g_kill_at = kill_at;
        }
        double pos[RS_NP * 3], vel[RS_NP * 3];
        int id[RS_NP];
        for (int i = 0; i < RS_NP * 3; i++)
            pos[i] = rs_val(k, 0, i), vel[i] = rs_val(k, 1, i);
        for (int i = 0; i < RS_NP; i++)
            id[i] = (int)(1000 * k) + i;
        const double row[2] = {rs_val(k, 2, 0), rs_val(k, 3, 0)};
        if (cm_h5_step_begin(f, 10 * k, 0.5 * (double)k, &err) ||
            cm_h5_step_doubles(f, "position", CM_H5_NODE, pos, RS_NP, 3, &err) ||
            cm_h5_step_doubles(f, "velocity", CM_H5_NODE, vel, RS_NP, 3, &err) ||
            cm_h5_step_ints(f, "id", CM_H5_NODE, id, RS_NP, 1, &err) || cm_h5_step_end(f, &err) ||
            (k >= RS_KEPT - RS_ROWS && cm_h5_series_append(se, row, &err)))
            _exit(5);
    }
    _exit(0);
}

/* The resumed file holds exactly the kept steps (values as written), the
 * static data, the attribute, the kept rows then the row appended after
 * resuming, and step 10 * (RS_KEPT + 5). */
static int rs_check(const char *path, const char *csv)
{
    hid_t fid = H5Fopen(path, H5F_ACC_RDONLY, H5P_DEFAULT);
    ENSURE_MSG(fid >= 0, "%s does not open", path);
    int bad = 0;
    for (long k = 0; k < RS_KEPT && !bad; k++) {
        char ds[64];
        double pos[RS_NP * 3], vel[RS_NP * 3], t = -1;
        int id[RS_NP];
        snprintf(ds, sizeof ds, "/steps/%06ld/position", 10 * k);
        bad |= read_dataset(fid, ds, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, 2, RS_NP, 3, pos);
        snprintf(ds, sizeof ds, "/steps/%06ld/velocity", 10 * k);
        bad |= read_dataset(fid, ds, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, 2, RS_NP, 3, vel);
        snprintf(ds, sizeof ds, "/steps/%06ld/id", 10 * k);
        bad |= read_dataset(fid, ds, H5T_STD_I32LE, H5T_NATIVE_INT, 1, RS_NP, 0, id);
        for (int i = 0; i < RS_NP * 3 && !bad; i++)
            bad |= pos[i] != rs_val(k, 0, i) || vel[i] != rs_val(k, 1, i);
        for (int i = 0; i < RS_NP && !bad; i++)
            bad |= id[i] != (int)(1000 * k) + i;
        snprintf(ds, sizeof ds, "/steps/%06ld", 10 * k);
        bad |= read_attr(fid, ds, "time", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, &t) || t != 0.5 * (double)k;
        if (bad)
            fprintf(stderr, "%s: step %ld differs from what was written\n", path, 10 * k);
    }
    hid_t g = H5Gopen2(fid, "/steps", H5P_DEFAULT);
    H5G_info_t gi = {0};
    bad |= g < 0 || H5Gget_info(g, &gi) < 0 || gi.nlinks != RS_KEPT + 1;
    if (g >= 0)
        H5Gclose(g);
    char last[32];
    snprintf(last, sizeof last, "/steps/%06d", 10 * (RS_KEPT + 5));
    bad |= H5Lexists(fid, last, H5P_DEFAULT) <= 0;
    double p0[NP * 3];
    bad |= read_dataset(fid, "/mesh/points0", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, 2, NP, 3, p0) ||
           memcmp(p0, k_points0, sizeof p0) != 0;
    hid_t a = H5Aopen_by_name(fid, "/", "units", H5P_DEFAULT, H5P_DEFAULT);
    bad |= a < 0;
    if (a >= 0)
        H5Aclose(a);
    static const char *const cols[] = {"t", "KE"};
    double want[(RS_ROWS + 1) * 2], back[(RS_ROWS + 1) * 2];
    for (int r = 0; r < RS_ROWS; r++) {
        long k = RS_KEPT - RS_ROWS + r;
        want[2 * r] = rs_val(k, 2, 0), want[2 * r + 1] = rs_val(k, 3, 0);
    }
    want[2 * RS_ROWS] = -1.0, want[2 * RS_ROWS + 1] = -2.0;
    hsize_t n = 0;
    bad |= read_series(fid, "/series", cols, 2, NULL, &n) || n != RS_ROWS + 1 ||
           read_series(fid, "/series", cols, 2, back, &n) || memcmp(back, want, sizeof want) != 0;
    H5Fclose(fid);
    ENSURE_MSG(!bad, "%s: the resumed file differs from what the checkpoint covers", path);
    ENSURE(check_csv(csv, "t,KE", want, RS_ROWS + 1, 2) == 0);
    return 0;
}

/* A writer killed at each of its writes after a checkpoint (all the writes
 * of the RS_AFTER steps and rows that follow it; RS_KEPT = 64 makes the
 * first of them split the full symbol-table node of /steps): resuming with
 * cm_h5_reopen and cm_h5_series_reopen gets back exactly the steps and rows
 * the checkpoint covers, appends a step and a row and closes; the files
 * open and read whole in h5py. Where the damage reaches what the checkpoint
 * covers (a kill while a /steps symbol-table node split is half written:
 * the group cannot be listed at all), the resume fails with a message
 * naming the file and /steps instead and leaves no temporary file; every
 * other kill point must be recovered. Prints the counts. */
static int resume_after_kill_at_every_write(void)
{
    ENSURE(scratch());
    cm_h5_def def = cm_h5_default_def();
    def.xdmf = CM_H5_XDMF_POLYVERTEX;
    static const char *const cols[] = {"t", "KE"};
    int recovered = 0, refused = 0, failed = 0;
    char list[8192] = "";
    size_t used = 0;
    long n;
    for (n = 1;; n++) {
        char path[128], csv[128], name[32];
        snprintf(name, sizeof name, "k%03ld.h5", n);
        in_scratch(path, sizeof path, name);
        snprintf(name, sizeof name, "k%03ld.csv", n);
        in_scratch(csv, sizeof csv, name);
        int status = child_status(rs_child, path, csv, n);
        ENSURE(status != -1);
        if (WIFEXITED(status) && WEXITSTATUS(status) == 0)
            break; /* n is past the last write: every kill point was tried */
        ENSURE_MSG(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL, "kill point %ld: child status %d", n, status);
        cm_error err = {0};
        cm_h5 *f = NULL;
        cm_h5_series *se = NULL;
        int rc = cm_h5_reopen(path, &def, 10 * (RS_KEPT - 1), &f, &err);
        if (rc != CM_OK) {
            /* only the damage resuming cannot step over (the /steps group
             * itself cannot be listed), and named */
            if (!strstr(err.msg, path) || !strstr(err.msg, "listing /steps: ")) {
                printf("  kill point %3ld: FAILED: %s\n", n, err.msg);
                failed++;
                continue;
            }
            char tmp[160];
            snprintf(tmp, sizeof tmp, "%s.resume.tmp", path);
            ENSURE_MSG(access(tmp, F_OK) != 0, "kill point %ld: %s left behind", n, tmp);
            printf("  kill point %3ld: refused: %s\n", n, err.msg);
            refused++;
            continue;
        }
        const double pos[3] = {1, 2, 3}, row[2] = {-1.0, -2.0};
        ENSURE_MSG(cm_h5_series_reopen(f, "/series", cols, 2, csv, RS_ROWS, &se, &err) == CM_OK,
                   "kill point %ld: %s", n, err.msg);
        ENSURE_MSG(cm_h5_step_begin(f, 10 * (RS_KEPT + 5), 99.0, &err) == CM_OK &&
                   cm_h5_step_doubles(f, "position", CM_H5_NODE, pos, 1, 3, &err) == CM_OK &&
                   cm_h5_step_end(f, &err) == CM_OK && cm_h5_series_append(se, row, &err) == CM_OK,
                   "kill point %ld: %s", n, err.msg);
        ENSURE_MSG(cm_h5_close(&f, &err) == CM_OK, "kill point %ld: %s", n, err.msg);
        if (rs_check(path, csv))
            return 1;
        if (used + strlen(path) + 2 < sizeof list)
            used += (size_t)snprintf(list + used, sizeof list - used, " %s", path);
        recovered++;
    }
    printf("%ld kill points: %d recovered exactly, %d refused naming /steps, %d failed\n", n - 1, recovered, refused,
           failed);
    ENSURE(failed == 0);
    ENSURE(n > 10);        /* the child did write after the checkpoint */
    ENSURE(recovered > 0); /* and the sweep recovered files to check below */
    /* Every recovered file reads whole in h5py (every dataset, every attribute). */
    char cmd[sizeof list + 400];
    snprintf(cmd, sizeof cmd,
             "/usr/bin/python3 -c 'import sys, h5py\n"
             "for p in sys.argv[1:]:\n"
             "    with h5py.File(p, \"r\") as f:\n"
             "        f.visititems(lambda n, o: (o[()] if isinstance(o, h5py.Dataset) else None, dict(o.attrs)) and None)\n"
             "' %s",
             list);
    ENSURE_MSG(system(cmd) == 0, "h5py could not read every recovered file");
    scratch_remove();
    return 0;
}

/* cm_h5_rebuild on a file not written by h5io (dem_server's grain frames:
 * root groups frame_NNNNNN and /shapes): the frames up to the one kept
 * remain with their data and attributes, the later ones go, other groups
 * stay, no temporary file is left; a file that is not HDF5 is refused
 * naming it, and left as it was. */
static int rebuild_numbered_root_groups(void)
{
    ENSURE(scratch());
    char path[128], tmp[160], junk[128];
    in_scratch(path, sizeof path, "dem_grains.h5");
    in_scratch(junk, sizeof junk, "junk.h5");
    snprintf(tmp, sizeof tmp, "%s.resume.tmp", path);
    hid_t fid = H5Fcreate(path, H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    ENSURE(fid >= 0);
    hsize_t dims[2] = {4, 3};
    hid_t sp = H5Screate_simple(2, dims, NULL), one = H5Screate(H5S_SCALAR);
    for (int k = 0; k < 4; k++) {
        char name[32];
        snprintf(name, sizeof name, "frame_%06d", k);
        double x[12], t = 0.25 * k;
        for (int i = 0; i < 12; i++)
            x[i] = val(i, k);
        hid_t g = H5Gcreate2(fid, name, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
        hid_t d = H5Dcreate2(g, "position", H5T_IEEE_F64LE, sp, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
        hid_t a = H5Acreate2(g, "time", H5T_IEEE_F64LE, one, H5P_DEFAULT, H5P_DEFAULT);
        ENSURE(g >= 0 && d >= 0 && a >= 0 && H5Dwrite(d, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, x) >= 0 &&
               H5Awrite(a, H5T_NATIVE_DOUBLE, &t) >= 0);
        H5Aclose(a);
        H5Dclose(d);
        H5Gclose(g);
    }
    hid_t g = H5Gcreate2(fid, "shapes", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    hid_t d = H5Dcreate2(g, "shape_000", H5T_IEEE_F64LE, sp, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    ENSURE(d >= 0 && H5Dwrite(d, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, k_points0) >= 0);
    H5Dclose(d);
    H5Gclose(g);
    H5Sclose(one);
    H5Sclose(sp);
    ENSURE(H5Fclose(fid) >= 0);

    cm_error err = {0};
    ENSURE_MSG(cm_h5_rebuild(path, "/", "frame_", 1, &err) == CM_OK, "%s", err.msg);
    ENSURE(access(tmp, F_OK) != 0);
    fid = H5Fopen(path, H5F_ACC_RDONLY, H5P_DEFAULT);
    ENSURE(fid >= 0);
    for (int k = 0; k < 2; k++) {
        char name[64];
        double x[12], t = -1;
        snprintf(name, sizeof name, "/frame_%06d/position", k);
        ENSURE(!read_dataset(fid, name, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, 2, 4, 3, x));
        for (int i = 0; i < 12; i++)
            ENSURE(x[i] == val(i, k));
        snprintf(name, sizeof name, "/frame_%06d", k);
        ENSURE(!read_attr(fid, name, "time", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, &t) && t == 0.25 * k);
    }
    double sh[12];
    ENSURE(H5Lexists(fid, "frame_000002", H5P_DEFAULT) == 0 && H5Lexists(fid, "frame_000003", H5P_DEFAULT) == 0);
    ENSURE(!read_dataset(fid, "/shapes/shape_000", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, 2, 4, 3, sh) &&
           memcmp(sh, k_points0, sizeof sh) == 0);
    H5Fclose(fid);

    FILE *fp = fopen(junk, "w");
    ENSURE(fp && fputs("not HDF5\n", fp) >= 0 && fclose(fp) == 0);
    ENSURE(cm_h5_rebuild(junk, "/", "frame_", 1, &err) == CM_ERR_IO && strstr(err.msg, junk));
    char *text = slurp(junk);
    ENSURE(text && strcmp(text, "not HDF5\n") == 0);
    free(text);
    scratch_remove();
    return 0;
}

int main(int argc, char **argv)
{
    static const test_case tests[] = {
        {"snapshot_roundtrip", snapshot_roundtrip},
        {"series_1000_rows", series_1000_rows},
        {"unwritable_path_names_path", unwritable_path_names_path},
        {"xdmf_well_formed", xdmf_well_formed},
        {"durability_after_sigkill", durability_after_sigkill},
        {"held_rows_reach_the_files_in_blocks", held_rows_reach_the_files_in_blocks},
        {"reopen_cuts_back_and_continues", reopen_cuts_back_and_continues},
        {"resume_after_kill_at_every_write", resume_after_kill_at_every_write},
        {"rebuild_numbered_root_groups", rebuild_numbered_root_groups},
    };
    H5Eset_auto2(H5E_DEFAULT, NULL, NULL); /* the reading side's own failures are ENSUREd */
    return test_main(argc, argv, tests, TEST_COUNT(tests));
}
