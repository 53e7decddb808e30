#include "fem_summary.h"

#include <hdf5.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "drive.h"
#include "json.h"
#include "log.h"
#include "steady.h"

/* Columns read from wheel.h5:/series. */
enum { C_T, C_PHASE, C_ANGLE, C_FZ, C_TH, C_TR, C_TP, C_SINK, C_SLIP, C_X, C_MY, C_FX, NC };
static const char *const k_read[NC] = {"t", "phase", "angle", "Fz", "T_H", "T_R", "T_P", "sinkage", "slip", "x", "My", "Fx"};

/* Reported quantities, in this order. */
enum { Q_TH, Q_TR, Q_TP, Q_W, Q_SINK, Q_SLIP, Q_CTH, Q_CTR, Q_CTP, Q_SINK_R, Q_THM, Q_FX, Q_MY, NQ };
static const char *const k_names[NQ] = {"T_H",       "T_R",       "T_P",       "load",          "sinkage",
                                        "slip",      "T_H_per_W", "T_R_per_W", "T_P_per_W",     "sinkage_per_R",
                                        "T_H_torque", "Fx",       "My"};
static const char *const k_units[NQ] = {"N", "N", "N", "N", "m", "1", "1", "1", "1", "1", "N", "N", "N m"};
enum { NSTAT = 8, PROFILE_BINS = 24 };
static const char *const k_stat_names = "mean,half_width,sd,min,max,tau_s,batches,short_series";

static int read_series(const char *path, double **col, size_t *n, cm_error *err)
{
    H5Eset_auto2(H5E_DEFAULT, NULL, NULL);
    hid_t f = H5Fopen(path, H5F_ACC_RDONLY, H5P_DEFAULT);
    if (f < 0)
        return cm_fail(err, CM_ERR_IO, "%s: cannot open to summarise the run", path);
    int rc = CM_OK;
    hid_t ds = H5Dopen2(f, "/series", H5P_DEFAULT), sp = -1, mt = -1;
    hsize_t dims[1] = {0};
    if (ds < 0 || (sp = H5Dget_space(ds)) < 0 || H5Sget_simple_extent_ndims(sp) != 1 ||
        H5Sget_simple_extent_dims(sp, dims, NULL) != 1)
        rc = cm_fail(err, CM_ERR_PARSE, "%s: /series missing or not a table", path);
    *n = (size_t)dims[0];
    double *rows = NULL;
    if (rc == CM_OK && *n > 0) {
        rows = malloc(*n * NC * sizeof *rows);
        mt = H5Tcreate(H5T_COMPOUND, NC * sizeof(double));
        if (!rows || mt < 0)
            rc = cm_fail(err, CM_ERR_NOMEM, "%s: out of memory for %zu rows", path, *n);
        for (int k = 0; k < NC && rc == CM_OK; k++)
            if (H5Tinsert(mt, k_read[k], (size_t)k * sizeof(double), H5T_NATIVE_DOUBLE) < 0)
                rc = cm_fail(err, CM_ERR_PARSE, "%s: column %s", path, k_read[k]);
        if (rc == CM_OK && H5Dread(ds, mt, H5S_ALL, H5S_ALL, H5P_DEFAULT, rows) < 0)
            rc = cm_fail(err, CM_ERR_PARSE, "%s: /series lacks one of the columns t, phase, angle, Fz, T_H, T_R, T_P, "
                                           "sinkage, slip, x, My, Fx",
                         path);
    }
    for (int k = 0; k < NC && rc == CM_OK; k++) {
        col[k] = malloc((*n ? *n : 1) * sizeof(double));
        if (!col[k])
            rc = cm_fail(err, CM_ERR_NOMEM, "%s: out of memory", path);
        for (size_t i = 0; i < *n && col[k]; i++)
            col[k][i] = rows[i * NC + k];
    }
    free(rows);
    if (mt >= 0)
        H5Tclose(mt);
    if (sp >= 0)
        H5Sclose(sp);
    if (ds >= 0)
        H5Dclose(ds);
    H5Fclose(f);
    return rc;
}

static int attr_double(hid_t obj, const char *name, double v)
{
    hid_t sp = H5Screate(H5S_SCALAR);
    H5Adelete(obj, name);
    hid_t a = H5Acreate2(obj, name, H5T_IEEE_F64LE, sp, H5P_DEFAULT, H5P_DEFAULT);
    herr_t st = a < 0 ? -1 : H5Awrite(a, H5T_NATIVE_DOUBLE, &v);
    if (a >= 0)
        H5Aclose(a);
    H5Sclose(sp);
    return st < 0 ? -1 : 0;
}

static int attr_string(hid_t obj, const char *name, const char *text)
{
    hid_t t = H5Tcopy(H5T_C_S1);
    H5Tset_size(t, strlen(text) + 1);
    hid_t sp = H5Screate(H5S_SCALAR);
    H5Adelete(obj, name);
    hid_t a = H5Acreate2(obj, name, t, sp, H5P_DEFAULT, H5P_DEFAULT);
    herr_t st = a < 0 ? -1 : H5Awrite(a, t, text);
    if (a >= 0)
        H5Aclose(a);
    H5Sclose(sp);
    H5Tclose(t);
    return st < 0 ? -1 : 0;
}

static int write_matrix(hid_t g, const char *name, const double *data, size_t rows, size_t cols)
{
    hsize_t d[2] = {rows, cols};
    if (H5Lexists(g, name, H5P_DEFAULT) > 0)
        H5Ldelete(g, name, H5P_DEFAULT);
    hid_t sp = H5Screate_simple(2, d, NULL);
    hid_t ds = H5Dcreate2(g, name, H5T_IEEE_F64LE, sp, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    herr_t st = ds < 0 ? -1 : H5Dwrite(ds, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, data);
    if (ds >= 0)
        H5Dclose(ds);
    H5Sclose(sp);
    return st < 0 ? -1 : 0;
}

typedef struct summary_result {
    int travelled;            /* the run reached the travel phase */
    size_t n_travel, start, end;
    double t_start, t_end, travel_m, lug_periods;
    /* the set-down: the time and sinkage of the travel's first row, where
     * the wheel began to roll under its load (the static sinkage of a
     * load-controlled set-down); NaN when it never travelled */
    double t_set_down, sinkage_set_down;
    steady_stats q[NQ];
    double profile[PROFILE_BINS][6]; /* phase, T_H, T_R, T_P, load, sinkage */
    /* convergence with travel: the first quarter, half, three quarters and
     * all of the steady part; travel (m), then mean and half-width of T_H,
     * T_R, T_P, load, sinkage */
    double conv[4][11];
    char warning[600]; /* the load check */
    char drift[400];   /* the sinkage check: still changing over the averaged part */
    char short_travel[400]; /* the travel stopped before travel_distance */
    char work[500];    /* the two sides' interface works parted */
} summary_result;

static const char *const k_control[] = {"slip", "torque", "drawbar"};
static const char *const k_motion[] = {"sink_travel", "hold", "load_travel"};

static void compute(const fem_summary_def *d, double *const *col, size_t n, summary_result *r)
{
    memset(r, 0, sizeof *r);
    r->t_set_down = r->sinkage_set_down = NAN;
    /* the travel phase: the rows of phase DRIVE_TRAVEL, in order */
    size_t m = 0;
    for (size_t i = 0; i < n; i++)
        m += (int)lround(col[C_PHASE][i]) == DRIVE_TRAVEL;
    r->n_travel = m;
    if (m == 0)
        return;
    r->travelled = 1;
    double *tr[NC];
    for (int k = 0; k < NC; k++) {
        tr[k] = malloc(m * sizeof(double));
        if (!tr[k]) { /* out of memory: report as not travelled rather than crash */
            for (int j = 0; j < k; j++)
                free(tr[j]);
            r->travelled = 0;
            return;
        }
    }
    for (size_t i = 0, j = 0; i < n; i++)
        if ((int)lround(col[C_PHASE][i]) == DRIVE_TRAVEL) {
            for (int k = 0; k < NC; k++)
                tr[k][j] = col[k][i];
            j++;
        }
    r->t_set_down = tr[C_T][0];
    r->sinkage_set_down = tr[C_SINK][0];
    /* the steady part: every reported quantity past its transient */
    static const int steady_cols[] = {C_TH, C_TR, C_TP, C_FZ, C_SINK};
    size_t start = 0;
    for (size_t k = 0; k < sizeof steady_cols / sizeof *steady_cols; k++) {
        size_t s = steady_start(tr[steady_cols[k]], m);
        start = s > start ? s : start;
    }
    if (d->control != DRIVE_CONTROL_SLIP) {
        size_t s = steady_start(tr[C_SLIP], m);
        start = s > start ? s : start;
    }
    size_t end = steady_lug_window(tr[C_ANGLE], m, start, d->lug_period);
    r->start = start;
    r->end = end;
    r->t_start = tr[C_T][start < m ? start : m - 1];
    r->t_end = tr[C_T][end > 0 ? end - 1 : 0];
    r->travel_m = fabs(tr[C_X][end > 0 ? end - 1 : 0] - tr[C_X][start < m ? start : m - 1]);
    r->lug_periods = d->lug_period > 0 && end > start
                         ? floor(fabs(tr[C_ANGLE][end - 1] - tr[C_ANGLE][start]) / d->lug_period + 1e-9)
                         : 0;
    if (d->lug_period > 0 && end > start && end < m) /* [start, end) spans exactly k periods */
        r->lug_periods = floor(fabs(tr[C_ANGLE][end] - tr[C_ANGLE][start]) / d->lug_period + 1e-9);
    static const int qcol[] = {C_TH, C_TR, C_TP, C_FZ, C_SINK, C_SLIP};
    for (int q = 0; q <= Q_SLIP; q++)
        steady_summary(tr[qcol[q]], end, start, &r->q[q]);
    /* per actual load: c = mean T / mean W; interval from z = (T - c W) / mean W */
    double W = r->q[Q_W].mean;
    double *z = malloc(m * sizeof *z);
    for (int q = Q_CTH; q <= Q_CTP && z; q++) {
        const double *t = tr[qcol[q - Q_CTH]];
        double c = W != 0 ? r->q[q - Q_CTH].mean / W : NAN;
        for (size_t i = 0; i < m; i++)
            z[i] = W != 0 ? (t[i] - c * tr[C_FZ][i]) / W : 0;
        steady_summary(z, end, start, &r->q[q]);
        r->q[q].mean = c;
        r->q[q].min = W != 0 ? r->q[q - Q_CTH].min / W : NAN; /* the extremes as the force's over the mean load */
        r->q[q].max = W != 0 ? r->q[q - Q_CTH].max / W : NAN;
    }
    free(z);
    r->q[Q_SINK_R] = r->q[Q_SINK];
    r->q[Q_SINK_R].mean /= d->radius, r->q[Q_SINK_R].half_width /= d->radius, r->q[Q_SINK_R].sd /= d->radius;
    r->q[Q_SINK_R].min /= d->radius, r->q[Q_SINK_R].max /= d->radius;
    /* the soil's force along the travel and moment about the axle: under
     * drawbar or torque control they balance what is prescribed */
    steady_summary(tr[C_FX], end, start, &r->q[Q_FX]);
    steady_summary(tr[C_MY], end, start, &r->q[Q_MY]);
    /* the first paper's gross traction from the axle torque: T_H = -M_y / R_T */
    for (size_t i = 0; i < m; i++)
        tr[C_MY][i] = -tr[C_MY][i] / d->radius;
    steady_summary(tr[C_MY], end, start, &r->q[Q_THM]);
    /* the lug-periodic signal */
    static const int pcol[] = {C_TH, C_TR, C_TP, C_FZ, C_SINK};
    double pm[PROFILE_BINS];
    int pc[PROFILE_BINS];
    for (int b = 0; b < PROFILE_BINS; b++)
        r->profile[b][0] = (b + 0.5) / PROFILE_BINS;
    for (int k = 0; k < 5; k++) {
        steady_profile(tr[pcol[k]], tr[C_ANGLE], start, end, d->lug_period, PROFILE_BINS, pm, pc);
        for (int b = 0; b < PROFILE_BINS; b++)
            r->profile[b][1 + k] = pc[b] ? pm[b] : NAN;
    }
    for (int f = 0; f < 4; f++) {
        size_t e = start + (size_t)((double)(end - start) * (f + 1) / 4.0);
        e = e > end ? end : e;
        r->conv[f][0] = e > start ? fabs(tr[C_X][e - 1] - tr[C_X][start]) : 0;
        for (int k = 0; k < 5; k++) {
            steady_stats cs;
            steady_summary(tr[pcol[k]], e, start, &cs);
            r->conv[f][1 + 2 * k] = cs.mean;
            r->conv[f][2 + 2 * k] = cs.half_width;
        }
    }
    /* the sinkage check: MSER truncates at most half the travel, so a wheel
     * still sinking (or digging in) at the end gets a "steady" part that is
     * not: the means of its two halves differ by more than both their 95 %
     * intervals and 5 % of the sinkage */
    if (end > start + 8) {
        size_t mid = start + (end - start) / 2;
        steady_stats h1, h2;
        steady_summary(tr[C_SINK], mid, start, &h1);
        steady_summary(tr[C_SINK], end, mid, &h2);
        double dz = h2.mean - h1.mean;
        if (fabs(dz) > h1.half_width + h2.half_width && fabs(dz) > 0.05 * fabs(r->q[Q_SINK].mean))
            snprintf(r->drift, sizeof r->drift,
                     "the sinkage is not steady over the averaged part (t = %.3f to %.3f s): %.1f mm over its first "
                     "half, %.1f mm over its second (95 %% intervals +-%.1f, +-%.1f mm); the wheel is still %s: its "
                     "means are not a steady state (travel longer, or see whether it digs in)",
                     r->t_start, r->t_end, 1e3 * h1.mean, 1e3 * h2.mean, 1e3 * h1.half_width, 1e3 * h2.half_width,
                     dz > 0 ? "sinking" : "rising");
    }
    /* the travel check: a run interrupted (and not resumed to its end) or
     * stopped by run.end_time averaged less than the scene asked for */
    if (!d->travel_done && d->travel_distance > 0 && d->motion != DRIVE_HOLD)
        snprintf(r->short_travel, sizeof r->short_travel,
                 "the travel stopped at %.3f m of wheel.travel_distance = %.3f m (the run was interrupted, or "
                 "run.end_time came first): these statistics cover only the part travelled (./run --resume DIR "
                 "continues an interrupted run; raise run.end_time otherwise)",
                 d->travelled, d->travel_distance);
    /* the load check */
    if (d->target_load > 0 && fabs(W - d->target_load) > 0.10 * d->target_load) {
        if (d->motion == DRIVE_SINK_TRAVEL)
            snprintf(r->warning, sizeof r->warning,
                     "the steady load is %.1f N, %.0f %% of target_load %.1f N: the wheel's height is prescribed "
                     "(wheel.motion = \"sink_travel\", position control), so the load is whatever the soil carries "
                     "at that height, and the soil under the travelling wheel gave way; wheel.motion = "
                     "\"load_travel\" holds the load. Traction here is that of a wheel carrying %.1f N",
                     W, 100 * W / d->target_load, d->target_load, W);
        else
            snprintf(r->warning, sizeof r->warning,
                     "the steady load is %.1f N, %.0f %% of target_load %.1f N although the height is free "
                     "(wheel.motion = \"%s\"): the heave has not settled over the averaged part (travel longer, or "
                     "more wheel.damping) or the wheel reached wheel.max_sink",
                     W, 100 * W / d->target_load, d->target_load,
                     d->motion >= 0 && d->motion <= 2 ? k_motion[d->motion] : "?");
    }
    for (int k = 0; k < NC; k++)
        free(tr[k]);
}

/* The interface-work check: a gap of the two sides' works above work_warn
 * at any time of the run. */
static void check_work(const fem_summary_def *d, summary_result *r)
{
    if (d->work_warn > 0 && d->work_gap_max > d->work_warn) {
        double wmax = fmax(fabs(d->work_fem), fabs(d->work_dem));
        snprintf(r->work, sizeof r->work,
                 "the interface work seen by the FEM and by the DEM were up to %.1f %% apart (%.0f %% first passed "
                 "at t = %.4f s; at the end %.4g J against %.4g J, %.2g %% of the larger): energy the exchange "
                 "created or destroyed on the tire's surface, where a stable exchange stays below 1 %%. Shorten "
                 "coupling.dt or raise fem.interface_mass_min before trusting these numbers",
                 100 * d->work_gap_max, 100 * d->work_warn, d->work_warned_at, d->work_fem, d->work_dem,
                 wmax > 0 ? 100 * fabs(d->work_fem - d->work_dem) / wmax : 0.0);
    }
}

static void log_result(const fem_summary_def *d, const summary_result *r)
{
    char what[160];
    if (d->control == DRIVE_CONTROL_SLIP)
        snprintf(what, sizeof what, "slip %.1f %%", 100 * d->slip);
    else if (d->control == DRIVE_CONTROL_TORQUE)
        snprintf(what, sizeof what, "axle torque %g N m", d->torque);
    else
        snprintf(what, sizeof what, "drawbar load %g N", d->drawbar);
    cm_log_info("traction over the steady part of the travel (every quantity past its transient, %.0f whole lug "
                "periods): exchanges %zu to %zu of %zu (t = %.3f to %.3f s, %.3f m), %s",
                r->lug_periods, r->start, r->end, r->n_travel, r->t_start, r->t_end, r->travel_m, what);
    cm_log_info("  set down: sinkage %.1f mm when the travel began (t = %.3f s)", 1e3 * r->sinkage_set_down,
                r->t_set_down);
    for (int q = 0; q < NQ; q++) {
        const steady_stats *s = &r->q[q];
        double scale = q == Q_SINK ? 1e3 : q == Q_SLIP ? 100 : 1;
        const char *unit = q == Q_SINK ? "mm" : q == Q_SLIP ? "%" : q == Q_MY ? "Nm" : k_units[q][0] == 'N' ? "N" : "";
        cm_log_info("  %-4s mean %10.4g %-2s (95%% CI +-%9.3g; time sd %9.3g; tau %.3g s, %d batches%s)", k_names[q],
                    scale * s->mean, unit, scale * s->half_width, scale * s->sd, s->tau * d->interval, s->batches,
                    s->short_series ? ": SHORT, rough interval" : "");
    }
    if (d->control != DRIVE_CONTROL_SLIP) {
        const steady_stats *sl = &r->q[Q_SLIP];
        cm_log_info("  slip mean %.2f %% (95%% CI +-%.2f %%)  min %.2f %%  max %.2f %% (realised, %s control)",
                    100 * sl->mean, 100 * sl->half_width, 100 * sl->min, 100 * sl->max, k_control[d->control]);
    }
    if (d->control == DRIVE_CONTROL_TORQUE)
        cm_log_info("  soil moment about the axle %.3f N m against the axle torque %g N m", r->q[Q_MY].mean, d->torque);
    else if (d->control == DRIVE_CONTROL_DRAWBAR)
        cm_log_info("  soil force along the travel %.2f N against the drawbar load %g N", r->q[Q_FX].mean, d->drawbar);
    if (r->warning[0])
        cm_log_warn("%s", r->warning);
    if (r->drift[0])
        cm_log_warn("%s", r->drift);
    if (r->short_travel[0])
        cm_log_warn("%s", r->short_travel);
    if (r->work[0])
        cm_log_warn("%s", r->work);
}

static int write_h5(const char *path, const fem_summary_def *d, const summary_result *r, cm_error *err)
{
    hid_t f = H5Fopen(path, H5F_ACC_RDWR, H5P_DEFAULT);
    if (f < 0)
        return cm_fail(err, CM_ERR_IO, "%s: cannot reopen to write /summary", path);
    if (H5Lexists(f, "/summary", H5P_DEFAULT) > 0)
        H5Ldelete(f, "/summary", H5P_DEFAULT);
    hid_t g = H5Gcreate2(f, "/summary", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    int bad = g < 0;
    char names[512] = "";
    for (int q = 0; q < NQ; q++)
        snprintf(names + strlen(names), sizeof names - strlen(names), "%s%s", q ? "," : "", k_names[q]);
    double rows[NQ][NSTAT];
    for (int q = 0; q < NQ; q++) {
        const steady_stats *s = &r->q[q];
        double v[NSTAT] = {s->mean, s->half_width, s->sd, s->min, s->max, s->tau * d->interval, s->batches,
                           s->short_series};
        memcpy(rows[q], v, sizeof v);
    }
    if (!bad) {
        bad |= attr_double(g, "travelled", r->travelled) || attr_double(g, "steady_start_time", r->t_start) ||
               attr_double(g, "steady_end_time", r->t_end) || attr_double(g, "steady_travel_m", r->travel_m) ||
               attr_double(g, "steady_exchanges", (double)(r->end - r->start)) ||
               attr_double(g, "lug_periods", r->lug_periods) || attr_double(g, "lug_period_rad", d->lug_period) ||
               attr_double(g, "target_load", d->target_load) || attr_string(g, "control", k_control[d->control]) ||
               attr_string(g, "load_warning", r->warning) || attr_string(g, "drift_warning", r->drift) ||
               attr_double(g, "travel_completed", d->travel_done) || attr_double(g, "travelled_m", d->travelled) ||
               attr_string(g, "travel_warning", r->short_travel) || attr_string(g, "work_warning", r->work) ||
               attr_double(g, "interface_work_dem", d->work_dem) || attr_double(g, "interface_work_fem", d->work_fem) ||
               attr_double(g, "interface_work_gap_max", d->work_gap_max) ||
               attr_double(g, "set_down_time", r->t_set_down) ||
               attr_double(g, "set_down_sinkage", r->sinkage_set_down);
        if (r->travelled)
            bad |= write_matrix(g, "quantities", &rows[0][0], NQ, NSTAT) ||
                   write_matrix(g, "convergence", &r->conv[0][0], 4, 11) ||
                   attr_string(g, "names", names) || write_matrix(g, "lug_profile", &r->profile[0][0], PROFILE_BINS, 6);
        hid_t q = r->travelled ? H5Dopen2(g, "quantities", H5P_DEFAULT) : -1;
        if (q >= 0) {
            bad |= attr_string(q, "names", names) || attr_string(q, "columns", k_stat_names);
            H5Dclose(q);
        }
        hid_t p = r->travelled ? H5Dopen2(g, "lug_profile", H5P_DEFAULT) : -1;
        if (p >= 0) {
            bad |= attr_string(p, "columns", "phase,T_H,T_R,T_P,load,sinkage");
            H5Dclose(p);
        }
        H5Gclose(g);
    }
    if (H5Fclose(f) < 0 || bad)
        return cm_fail(err, CM_ERR_IO, "%s: writing /summary failed", path);
    return CM_OK;
}

/* The text before a number (separator and key), then the number. */
static void json_field(FILE *f, const char *before, double v)
{
    fputs(before, f);
    cm_json_number(f, v);
}

static int write_json(const char *path, const fem_summary_def *d, const summary_result *r, cm_error *err)
{
    char tmp[1200];
    snprintf(tmp, sizeof tmp, "%s.tmp", path);
    FILE *f = fopen(tmp, "w");
    if (!f)
        return cm_fail(err, CM_ERR_IO, "%s: cannot create", tmp);
    fputs("{\n  \"format\": \"demfem-summary-1\",\n  \"scene\": ", f);
    cm_json_string(f, d->scene);
    fprintf(f, ",\n  \"control\": \"%s\",\n  \"motion\": \"%s\",\n  \"target_load\": ", k_control[d->control],
            d->motion >= 0 && d->motion <= 2 ? k_motion[d->motion] : "?");
    cm_json_number(f, d->target_load);
    fputs(",\n  \"radius\": ", f);
    cm_json_number(f, d->radius);
    fprintf(f, ",\n  \"fem_state_hash\": \"%016llx\",\n  \"travelled\": %s,\n  \"travel_completed\": %s,\n  "
               "\"travelled_m\": ",
            (unsigned long long)d->fem_state_hash, r->travelled ? "true" : "false", d->travel_done ? "true" : "false");
    cm_json_number(f, d->travelled);
    json_field(f, ",\n  \"interface_work\": {\"dem_J\": ", d->work_dem);
    json_field(f, ", \"fem_J\": ", d->work_fem);
    json_field(f, ", \"gap_max\": ", d->work_gap_max);
    json_field(f, ", \"warned_at_s\": ", d->work_warned_at);
    json_field(f, "},\n  \"set_down\": {\"time_s\": ", r->t_set_down);
    json_field(f, ", \"sinkage_m\": ", r->sinkage_set_down);
    fputs("}", f);
    fputs(",\n  \"steady\": {\"start_time\": ", f);
    cm_json_number(f, r->t_start);
    fputs(", \"end_time\": ", f);
    cm_json_number(f, r->t_end);
    fputs(", \"travel_m\": ", f);
    cm_json_number(f, r->travel_m);
    fprintf(f, ", \"exchanges\": %zu, \"travel_exchanges\": %zu, \"lug_periods\": %.0f, \"lug_period_rad\": ",
            r->end - r->start, r->n_travel, r->lug_periods);
    cm_json_number(f, d->lug_period);
    fputs("},\n  \"quantities\": {", f);
    for (int q = 0; r->travelled && q < NQ; q++) {
        const steady_stats *s = &r->q[q];
        fprintf(f, "%s\n    \"%s\": {\"unit\": \"%s\", \"mean\": ", q ? "," : "", k_names[q], k_units[q]);
        cm_json_number(f, s->mean);
        json_field(f, ", \"half_width\": ", s->half_width);
        json_field(f, ", \"sd\": ", s->sd);
        json_field(f, ", \"min\": ", s->min);
        json_field(f, ", \"max\": ", s->max);
        json_field(f, ", \"tau_s\": ", s->tau * d->interval);
        fprintf(f, ", \"samples\": %zu, \"batches\": %d, \"short_series\": %s}", s->count, s->batches,
                s->short_series ? "true" : "false");
    }
    fputs("\n  },\n  \"lug_profile\": {\"columns\": [\"phase\", \"T_H\", \"T_R\", \"T_P\", \"load\", \"sinkage\"], "
          "\"rows\": [",
          f);
    for (int b = 0; r->travelled && d->lug_period > 0 && b < PROFILE_BINS; b++) {
        fputs(b ? ", [" : "[", f);
        for (int k = 0; k < 6; k++) {
            if (k)
                fputs(", ", f);
            cm_json_number(f, r->profile[b][k]);
        }
        fputc(']', f);
    }
    fputs("]},\n  \"convergence\": {\"columns\": [\"travel_m\", \"T_H\", \"T_H_half_width\", \"T_R\", "
          "\"T_R_half_width\", \"T_P\", \"T_P_half_width\", \"load\", \"load_half_width\", \"sinkage\", "
          "\"sinkage_half_width\"], \"rows\": [",
          f);
    for (int c = 0; r->travelled && c < 4; c++) {
        fputs(c ? ", [" : "[", f);
        for (int k = 0; k < 11; k++) {
            if (k)
                fputs(", ", f);
            cm_json_number(f, r->conv[c][k]);
        }
        fputc(']', f);
    }
    fputs("]},\n  \"warnings\": [", f);
    const char *warnings[] = {r->warning, r->drift, r->short_travel, r->work};
    for (int k = 0, any = 0; k < 4; k++)
        if (warnings[k][0]) {
            fputs(any++ ? ", " : "", f);
            cm_json_string(f, warnings[k]);
        }
    fputs("]\n}\n", f);
    int bad = ferror(f);
    if (fclose(f) != 0 || bad || rename(tmp, path) != 0) {
        remove(tmp);
        return cm_fail(err, CM_ERR_IO, "%s: writing failed", path);
    }
    return CM_OK;
}

int fem_summary_write(const fem_summary_def *d, cm_error *err)
{
    char h5path[1100], jpath[1100];
    snprintf(h5path, sizeof h5path, "%s/wheel.h5", d->out_dir);
    snprintf(jpath, sizeof jpath, "%s/summary.json", d->out_dir);
    double *col[NC] = {0};
    size_t n = 0;
    int rc = read_series(h5path, col, &n, err);
    summary_result *r = calloc(1, sizeof *r);
    if (rc == CM_OK && !r)
        rc = cm_fail(err, CM_ERR_NOMEM, "summary: out of memory");
    if (rc == CM_OK) {
        compute(d, col, n, r);
        check_work(d, r);
        if (r->travelled)
            log_result(d, r);
        else
            cm_log_info("the wheel never reached the travel phase (target load %g N): no traction summary",
                        d->target_load);
        if (!r->travelled && r->work[0])
            cm_log_warn("%s", r->work);
        if ((rc = write_h5(h5path, d, r, err)) == CM_OK && (rc = write_json(jpath, d, r, err)) == CM_OK)
            rc = r->warning[0] ? FEM_SUMMARY_LOAD_OFF : CM_OK;
    }
    for (int k = 0; k < NC; k++)
        free(col[k]);
    free(r);
    return rc;
}
