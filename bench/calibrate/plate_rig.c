/* plate_rig: the virtual plate-sinkage test of the soil calibration (issue
 * 15). A rigid rectangular plate, served to dem_server as the FEM side of the
 * exchange protocol (ipc/PROTOCOL.md), is pressed into the settled bed at a
 * constant speed; every exchange it records the plate's depth below the
 * point where it first touched a grain and the pressure the grains put on it.
 * bench/calibrate/terramech.py fits Bekker's p = (k_c/b + k_phi) z^n to two
 * plate widths.
 *
 *   ./run scenes/calibrate/plate_sinkage.cfg --fem build/bench/calibrate/plate_rig
 *
 * It owns the scene's `fem` section (the FEM side's section belongs to the
 * program that plays that role):
 *   fem = { plate = { size = [0.05, 0.05];    # m, along x and y (b = the smaller)
 *                     center = [0.15, 0.15];  # m, x and y
 *                     start_z = 0.13;         # m, the plate's height at t = 0
 *                     speed = 0.05;           # m/s, downwards
 *                     start_gap = 0.0;        # m, optional: > 0 puts the plate this far above
 *                                             #   the highest grain top the DEM reports at the
 *                                             #   first exchange (start_z must be above it)
 *                     stop_sinkage = 0.0; }; };  # m, optional: > 0 ends the run at this
 *                                             #   sinkage below the first contact
 * and reads `run` and `coupling` like the servers. The DEM side ends the run
 * at run.end_time. Output: DIR/plate_sinkage.csv with the columns
 *   t (s), plate_z (m), sinkage (m, below the plate's first contact, 0
 *   before), depth (m, below the bed's mean surface as dem_server reports
 *   it; negative above), force (N, upward on the plate), pressure (Pa,
 *   force / plate area), contacts.
 * Bekker's z is the sinkage below the undisturbed surface, which a bed of
 * grains defines only to within a grain radius: the fit uses `sinkage`, and
 * `depth` tells where the first contact was. */
#include <math.h>
#include <stdio.h>

#include "csv.h"
#include "ipc.h"
#include "rig.h"

typedef struct plate_def {
    double size[2];   /* m, along x and y */
    double center[2]; /* m */
    double start_z;   /* m, height of the plate at t = 0 */
    double speed;     /* m/s, downwards */
    double start_gap; /* m above the highest grain top at the first exchange; 0: start at start_z */
    double stop_sinkage; /* m below the first contact where the rig ends the run; 0: run.end_time */
} plate_def;

typedef struct plate_rig {
    plate_def d;
    double x0[12]; /* m, the corners at t = 0 */
    cm_csv *csv;
    double row[7];
    double z_touch, f_max; /* m (NAN before the first contact), N */
    double z0, t0;         /* m, s: the descent is z0 - speed (t - t0) */
    int placed;            /* start_gap: the plate was put above the bed top */
} plate_rig;

static int read_plate(cm_scene *s, void *user, cm_error *err)
{
    plate_def *d = user;
    if (cm_scene_doubles(s, "fem.plate.size", 2, 1e-4, 100, d->size, err) ||
        cm_scene_doubles(s, "fem.plate.center", 2, -1e3, 1e3, d->center, err) ||
        cm_scene_double(s, "fem.plate.start_z", -1e3, 1e3, &d->start_z, err) ||
        cm_scene_double(s, "fem.plate.speed", 1e-6, 10, &d->speed, err) ||
        cm_scene_double_opt(s, "fem.plate.start_gap", 0, 1, 0, &d->start_gap, err) ||
        cm_scene_double_opt(s, "fem.plate.stop_sinkage", 0, 10, 0, &d->stop_sinkage, err))
        return err->code;
    return CM_OK;
}

/* The plate's height for the forces just received (at t) and where it goes
 * next (t_next). */
static int plate_advance(void *user, const rig_in *in, rig_out *out, cm_error *err)
{
    (void)err;
    plate_rig *r = user;
    const double t = in->t, *f = in->force, *info = in->info;
    double fz = 0;
    for (int i = 0; i < 4; i++)
        fz += f[3 * i + 2];
    const double bed_top = info[IPC_INFO_BED_TOP];
    if (!r->placed && r->d.start_gap > 0) {
        /* the first exchange: no grain touches the plate at start_z (above
         * the bed top, checked), so it may be put start_gap above the top */
        if (!(bed_top > 0) || bed_top + r->d.start_gap > r->d.start_z)
            return cm_fail(err, CM_ERR_RANGE, "plate_rig: fem.plate.start_gap needs the DEM's bed top (%g m) "
                                "plus the gap below fem.plate.start_z (%g m)", bed_top, r->d.start_z);
        r->z0 = bed_top + r->d.start_gap;
        r->t0 = t;
    }
    r->placed = 1;
    const double z_now = r->z0 - r->d.speed * (t - r->t0), z_next = r->z0 - r->d.speed * (in->t_next - r->t0);
    for (int i = 0; i < 4; i++) {
        out->x[3 * i] = r->x0[3 * i];
        out->x[3 * i + 1] = r->x0[3 * i + 1];
        out->x[3 * i + 2] = z_next;
        out->v[3 * i] = out->v[3 * i + 1] = 0.0;
        out->v[3 * i + 2] = -r->d.speed;
    }
    const double contacts = info[IPC_INFO_CONTACTS], bed = info[IPC_INFO_BED_HEIGHT];
    if (isnan(r->z_touch) && contacts > 0)
        r->z_touch = z_now;
    const double sinkage = isnan(r->z_touch) ? 0.0 : r->z_touch - z_now;
    if (r->d.stop_sinkage > 0 && sinkage >= r->d.stop_sinkage)
        out->stop = 1;
    const double area = r->d.size[0] * r->d.size[1];
    const double row[7] = {t, z_now, sinkage, bed - z_now, fz, fz / area, contacts};
    for (int k = 0; k < 7; k++)
        r->row[k] = row[k];
    r->f_max = fz > r->f_max ? fz : r->f_max;
    return CM_OK;
}

static int plate_record(void *user, cm_error *err)
{
    plate_rig *r = user;
    return cm_csv_row(r->csv, r->row, err);
}

int main(int argc, char **argv)
{
    rig_args a;
    int rc = rig_parse_args("plate_rig", argc, argv, &a);
    if (rc)
        return rc;
    cm_run_config rcfg;
    plate_rig r = {.z_touch = NAN};
    if (rig_read_scene("plate_rig", &a, &rcfg, read_plate, &r.d))
        return 1;
    r.z0 = r.d.start_z;
    const double hx = 0.5 * r.d.size[0], hy = 0.5 * r.d.size[1];
    const double corners[4][2] = {{-hx, -hy}, {hx, -hy}, {hx, hy}, {-hx, hy}};
    double mass[4];
    for (int i = 0; i < 4; i++) {
        r.x0[3 * i] = r.d.center[0] + corners[i][0];
        r.x0[3 * i + 1] = r.d.center[1] + corners[i][1];
        r.x0[3 * i + 2] = r.d.start_z;
        mass[i] = 1.0; /* kg; the plate is driven, its mass only enters the DEM's contact dashpot */
    }
    /* Clockwise seen from above: the normal points down, to the grains. */
    static const uint32_t tris[6] = {0, 2, 1, 0, 3, 2};
    char path[1100];
    snprintf(path, sizeof path, "%s/plate_sinkage.csv", a.out);
    static const char *const cols[] = {"t", "plate_z", "sinkage", "depth", "force", "pressure", "contacts"};
    cm_error err = {0};
    if (cm_csv_create(path, cols, 7, &r.csv, &err)) {
        fprintf(stderr, "[plate_rig] error: %s\n", err.msg);
        return 1;
    }
    const rig_def def = {.name = "plate_rig", .n_nodes = 4, .n_tris = 2, .x0 = r.x0, .tris = tris, .mass = mass,
                         .advance = plate_advance, .record = plate_record, .user = &r};
    rc = rig_run(&def, &rcfg, &a);
    if (cm_csv_close(&r.csv, &err) && !rc) {
        fprintf(stderr, "[plate_rig] error: %s\n", err.msg);
        return 1;
    }
    if (rc)
        return rc;
    printf("[plate_rig] plate %.3f x %.3f m: first contact at z = %.4f m, peak pressure %.4g Pa; %s\n", r.d.size[0],
           r.d.size[1], r.z_touch, r.f_max / (r.d.size[0] * r.d.size[1]), path);
    return 0;
}
