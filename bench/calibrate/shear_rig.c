/* shear_rig: the virtual direct shear box of the soil calibration (issue 15).
 * Rigid triangle meshes, served to dem_server as the FEM side of the exchange
 * protocol (ipc/PROTOCOL.md, the loop in rig.c), make the box:
 *   - the lower half: four walls from the bed's floor (a DEM wall, dem.bed)
 *     up to the shear plane, fixed;
 *   - the upper half: four walls from the shear plane up, driven along +x at
 *     a constant speed once the normal stress is reached;
 *   - the lid: a plate inside the upper half, moving with it along x and
 *     servo-controlled along z to the normal stress sigma_n.
 * The walls parallel to the shear (y = const) are longer than the box by the
 * travel at both ends, so no grain escapes at the ends. The grains are the
 * scene's bed placed loosely in the box's footprint (dem.bed with
 * side_walls = false, not settled by dem_server): they settle inside the
 * box under gravity while the lid comes down.
 *
 *   ./run scenes/calibrate/shear_box.cfg --fem build/bench/calibrate/shear_rig
 *
 * It owns the scene's `fem` section:
 *   fem = { shear = {
 *     box = [0.05, 0.05];       # m, inner length (along the shear, x) and width (y)
 *     origin = [0, 0, 0];       # m, the box's corner at the floor (x, y, z)
 *     lower_height = 0.025;     # m, the shear plane above the floor
 *     upper_height = 0.08;      # m, the upper half's walls (hold the loose fill)
 *     walls = true;             # false: the lid alone (closed-form test on a frozen bed)
 *     lid_start_z = 0.1;        # m, the lid's height at t = 0; at the first exchange it
 *                               #   drops to the highest grain top + lid_clearance if lower
 *     lid_clearance = 0.0005;   # m, between the lid's edges and the walls
 *     normal_stress = 1.0e4;    # Pa, the servo's target (lid force / box area)
 *     settle_time = 0.3;        # s, the lid waits above the fill while the grains settle
 *     approach_speed = 0.5;     # m/s, then comes down at this speed until it feels
 *                               #   5 % of the target force (a bouncing grain does not count)
 *     servo_speed = 0.03;       # m/s, the servo's largest speed (at 100 % stress error)
 *     servo_time = 0.02;        # s, integral time (a creeping sample would otherwise
 *                               #   leave a steady error of creep speed / servo_speed)
 *     servo_tolerance = 0.02;   # relative stress error at which sigma_n counts as reached
 *     shear_delay = 0.05;       # s, after the servo first reaches sigma_n, before shearing
 *     shear_speed = 0.05;       # m/s, of the upper half and the lid along +x
 *     travel = 0.01;            # m, shear displacement at which the rig ends the run
 *     center_x = ...;           # m, optional: wheel centre reported to the DEM
 *   }; };                       #    (dem.window freezes grains far from it)
 * Servo (proportional-integral): with e = (F_target - F_lid) / F_target,
 * F_target = sigma_n * box area, v_z = -servo_speed * clamp(e + I, -1, 1),
 * I = clamp(integral of e dt / servo_time, -1, 1), integrated only while
 * |e| < 0.1 (no wind-up while the lid closes in). The proportional part is
 * stable while the sample's stiffness k satisfies k * servo_speed *
 * exchange_dt / F_target < 2; the integral part removes the steady error a
 * slowly compacting sample leaves.
 *
 * Output: DIR/shear_box.csv, one row per exchange:
 *   t (s), phase (0 settle/approach, 1 servo, 2 shear), displacement (m, of
 *   the upper half), lid_z (m), height (m, lid above the floor), normal_force
 *   (N, up on the lid), normal_stress (Pa, normal_force / box area),
 *   shear_force (N, the grains' resistance: -x force on the upper half and
 *   the lid), shear_stress (Pa, / box area), lid_shear_force (N, the lid's
 *   part of it), upper_wall_fz (N, up on the upper walls: as the grains
 *   dilate they rub up along the fixed upper walls, which push them down by
 *   as much, loading the shear plane beyond the lid; the normal force on the
 *   plane is normal_force + upper_wall_fz + the upper grains' weight,
 *   bench/calibrate/soiltests.py), lower_fx (N, x force on the lower walls),
 *   contacts (all grain-mesh contacts).
 * The box area is the nominal L * W throughout (the ratio tau / sigma_n does
 * not depend on it). bench/calibrate/run reads the file; nothing reads logs. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "csv.h"
#include "ipc.h"
#include "rig.h"

enum { SHEAR_COLS = 13, MAX_NODES = 36, MAX_TRIS = 18 };
enum { PHASE_APPROACH = 0, PHASE_SERVO = 1, PHASE_SHEAR = 2 };
/* the approach ends when the lid carries this share of the target force */
#define SHEAR_TOUCH_FRACTION 0.05
/* the servo's integral term integrates only errors smaller than this */
#define SHEAR_INTEGRATE_BAND 0.1

typedef struct shear_def {
    double box[2];       /* m, L (x) and W (y) */
    double origin[3];    /* m */
    double lower_height; /* m */
    double upper_height; /* m */
    bool walls;
    double lid_start_z;    /* m */
    double lid_clearance;  /* m */
    double normal_stress;  /* Pa */
    double settle_time;    /* s, the lid waits this long above the fill */
    double approach_speed; /* m/s */
    double servo_speed;    /* m/s */
    double servo_tolerance; /* 1, relative: the target counts as reached within it */
    double servo_time;      /* s, integral time of the servo */
    double shear_delay;    /* s */
    double shear_speed;    /* m/s */
    double travel;         /* m */
    double center_x;       /* m, NAN: the box's centre */
} shear_def;

typedef struct shear_rig {
    shear_def d;
    int n_nodes, n_tris;
    int lid0, upper0; /* first node of the lid and of the upper half (-1: none) */
    double x0[3 * MAX_NODES];
    uint32_t tris[3 * MAX_TRIS];
    /* state */
    int phase;
    long exchanges;
    double servo_int; /* the servo's integral term, 1 */
    double lid_z, lid_vz; /* m, m/s: the lid at the state sent last */
    double t_target;      /* s, when the servo first reached the target (NAN before) */
    double t_shear;       /* s, when the shear started (NAN before) */
    cm_csv *csv;
    double row[SHEAR_COLS];
} shear_rig;

static int read_shear(cm_scene *s, void *user, cm_error *err)
{
    shear_def *d = user;
    static const double zero3[3] = {0, 0, 0};
    if (cm_scene_doubles(s, "fem.shear.box", 2, 1e-4, 100, d->box, err) ||
        cm_scene_doubles_opt(s, "fem.shear.origin", 3, -1e3, 1e3, zero3, d->origin, err) ||
        cm_scene_double(s, "fem.shear.lower_height", 1e-4, 100, &d->lower_height, err) ||
        cm_scene_double(s, "fem.shear.upper_height", 1e-4, 100, &d->upper_height, err) ||
        cm_scene_bool_opt(s, "fem.shear.walls", true, &d->walls, err) ||
        cm_scene_double(s, "fem.shear.lid_start_z", -1e3, 1e3, &d->lid_start_z, err) ||
        cm_scene_double_opt(s, "fem.shear.lid_clearance", 0, 1, 5e-4, &d->lid_clearance, err) ||
        cm_scene_double(s, "fem.shear.normal_stress", 1.0, 1e9, &d->normal_stress, err) ||
        cm_scene_double_opt(s, "fem.shear.settle_time", 0, 100, 0.3, &d->settle_time, err) ||
        cm_scene_double_opt(s, "fem.shear.approach_speed", 1e-6, 10, 0.5, &d->approach_speed, err) ||
        cm_scene_double_opt(s, "fem.shear.servo_speed", 1e-6, 10, 0.03, &d->servo_speed, err) ||
        cm_scene_double_opt(s, "fem.shear.servo_time", 1e-6, 100, 0.02, &d->servo_time, err) ||
        cm_scene_double_opt(s, "fem.shear.servo_tolerance", 1e-6, 0.5, 0.02, &d->servo_tolerance, err) ||
        cm_scene_double_opt(s, "fem.shear.shear_delay", 0, 100, 0.05, &d->shear_delay, err) ||
        cm_scene_double(s, "fem.shear.shear_speed", 1e-6, 10, &d->shear_speed, err) ||
        cm_scene_double(s, "fem.shear.travel", 1e-6, 10, &d->travel, err) ||
        cm_scene_double_opt(s, "fem.shear.center_x", -1e6, 1e6, NAN, &d->center_x, err))
        return err->code;
    if (2 * d->lid_clearance >= d->box[0] || 2 * d->lid_clearance >= d->box[1])
        return cm_fail(err, CM_ERR_RANGE, "%s: fem.shear.lid_clearance = %g m leaves no lid in a %g x %g m box",
                       cm_scene_path(s), d->lid_clearance, d->box[0], d->box[1]);
    if (d->walls && d->lid_start_z <= d->origin[2] + d->lower_height)
        return cm_fail(err, CM_ERR_RANGE,
                       "%s: fem.shear.lid_start_z = %g m is not above the shear plane (origin z + lower_height = %g m)",
                       cm_scene_path(s), d->lid_start_z, d->origin[2] + d->lower_height);
    return CM_OK;
}

/* A rectangle p, p + e1, p + e1 + e2, p + e2 as two triangles; its normal
 * e1 x e2 points to the grains. */
static void add_rect(shear_rig *r, const double p[3], const double e1[3], const double e2[3])
{
    const int b = r->n_nodes;
    for (int k = 0; k < 3; k++) {
        r->x0[3 * b + k] = p[k];
        r->x0[3 * (b + 1) + k] = p[k] + e1[k];
        r->x0[3 * (b + 2) + k] = p[k] + e1[k] + e2[k];
        r->x0[3 * (b + 3) + k] = p[k] + e2[k];
    }
    const uint32_t t[6] = {(uint32_t)b, (uint32_t)b + 1, (uint32_t)b + 2, (uint32_t)b, (uint32_t)b + 2, (uint32_t)b + 3};
    memcpy(r->tris + 3 * r->n_tris, t, sizeof t);
    r->n_nodes += 4;
    r->n_tris += 2;
}

/* Four walls from z0 up by h around the box, the y-walls longer by `ext` at
 * both ends, normals inwards. */
static void add_walls(shear_rig *r, double z0, double h, double ext)
{
    const double x0 = r->d.origin[0], y0 = r->d.origin[1], L = r->d.box[0], W = r->d.box[1];
    add_rect(r, (double[]){x0, y0, z0}, (double[]){0, W, 0}, (double[]){0, 0, h});         /* x = x0, +x */
    add_rect(r, (double[]){x0 + L, y0, z0}, (double[]){0, 0, h}, (double[]){0, W, 0});     /* x = x0+L, -x */
    add_rect(r, (double[]){x0 - ext, y0, z0}, (double[]){0, 0, h}, (double[]){L + 2 * ext, 0, 0}); /* y = y0, +y */
    add_rect(r, (double[]){x0 - ext, y0 + W, z0}, (double[]){L + 2 * ext, 0, 0}, (double[]){0, 0, h}); /* -y */
}

static void build_mesh(shear_rig *r)
{
    const shear_def *d = &r->d;
    r->upper0 = -1;
    if (d->walls) {
        const double ext = d->travel + 0.1 * d->box[0];
        add_walls(r, d->origin[2], d->lower_height, ext);
        r->upper0 = r->n_nodes;
        add_walls(r, d->origin[2] + d->lower_height, d->upper_height, ext);
    }
    r->lid0 = r->n_nodes;
    const double c = d->lid_clearance;
    add_rect(r, (double[]){d->origin[0] + c, d->origin[1] + c, d->lid_start_z}, (double[]){0, d->box[1] - 2 * c, 0},
             (double[]){d->box[0] - 2 * c, 0, 0}); /* normal -z */
}

static int shear_advance(void *user, const rig_in *in, rig_out *out, cm_error *err)
{
    (void)err;
    shear_rig *r = user;
    const shear_def *d = &r->d;
    const double area = d->box[0] * d->box[1], f_target = d->normal_stress * area;
    double lid_fz = 0, lid_fx = 0, up_fx = 0, up_fz = 0, low_fx = 0;
    for (int i = r->lid0; i < r->lid0 + 4; i++) {
        lid_fx += in->force[3 * i];
        lid_fz += in->force[3 * i + 2];
    }
    if (r->upper0 >= 0) {
        for (int i = 0; i < r->upper0; i++)
            low_fx += in->force[3 * i];
        for (int i = r->upper0; i < r->lid0; i++) {
            up_fx += in->force[3 * i];
            up_fz += in->force[3 * i + 2];
        }
    }
    /* the displacement of the state these forces belong to (at t) */
    const double disp = isnan(r->t_shear) ? 0.0 : d->shear_speed * (in->t - r->t_shear);
    const double row[SHEAR_COLS] = {in->t,
                                    (double)r->phase,
                                    disp,
                                    r->lid_z,
                                    r->lid_z - d->origin[2],
                                    lid_fz,
                                    lid_fz / area,
                                    -(up_fx + lid_fx),
                                    -(up_fx + lid_fx) / area,
                                    -lid_fx,
                                    up_fz,
                                    low_fx,
                                    in->info[IPC_INFO_CONTACTS]};
    memcpy(r->row, row, sizeof row);

    /* the phases: approach until the lid first feels the grains, servo,
     * shear once sigma_n has been reached (within servo_tolerance) and
     * shear_delay has passed since */
    if (r->phase == PHASE_APPROACH && in->t >= d->settle_time && lid_fz >= SHEAR_TOUCH_FRACTION * f_target)
        r->phase = PHASE_SERVO;
    if (r->phase == PHASE_SERVO && isnan(r->t_target) && lid_fz >= (1.0 - d->servo_tolerance) * f_target)
        r->t_target = in->t;
    if (r->phase == PHASE_SERVO && !isnan(r->t_target) && in->t >= r->t_target + d->shear_delay) {
        r->phase = PHASE_SHEAR;
        r->t_shear = in->t;
    }
    /* the first exchange: a lid placed high above the loose fill drops to
     * just above its highest grain (the DEM's IPC_INFO_BED_TOP) */
    const double top = in->info[IPC_INFO_BED_TOP];
    if (r->exchanges++ == 0 && top > 0 && r->lid_z > top + d->lid_clearance)
        r->lid_z = top + d->lid_clearance;
    double e = (f_target - lid_fz) / f_target;
    e = e > 1 ? 1 : e < -1 ? -1 : e;
    if (r->phase == PHASE_APPROACH)
        r->lid_vz = in->t_next > d->settle_time ? -d->approach_speed : 0.0;
    else {
        if (fabs(e) < SHEAR_INTEGRATE_BAND) /* no wind-up while the lid closes in */
            r->servo_int += e * (in->t_next - in->t) / d->servo_time;
        r->servo_int = r->servo_int > 1 ? 1 : r->servo_int < -1 ? -1 : r->servo_int;
        double u = e + r->servo_int;
        r->lid_vz = -d->servo_speed * (u > 1 ? 1 : u < -1 ? -1 : u);
    }
    r->lid_z += r->lid_vz * (in->t_next - in->t);

    const double vx = r->phase == PHASE_SHEAR ? d->shear_speed : 0.0;
    const double dx = isnan(r->t_shear) ? 0.0 : d->shear_speed * (in->t_next - r->t_shear);
    for (int i = 0; i < r->n_nodes; i++) {
        const int moves = r->upper0 >= 0 ? i >= r->upper0 : i >= r->lid0;
        const int lid = i >= r->lid0;
        out->x[3 * i] = r->x0[3 * i] + (moves ? dx : 0.0);
        out->x[3 * i + 1] = r->x0[3 * i + 1];
        out->x[3 * i + 2] = lid ? r->lid_z : r->x0[3 * i + 2];
        out->v[3 * i] = moves ? vx : 0.0;
        out->v[3 * i + 1] = 0.0;
        out->v[3 * i + 2] = lid ? r->lid_vz : 0.0;
    }
    out->info[IPC_INFO_CENTER_X] = isnan(d->center_x) ? d->origin[0] + 0.5 * d->box[0] + dx : d->center_x;
    out->info[IPC_INFO_CENTER_Y] = d->origin[1] + 0.5 * d->box[1];
    out->info[IPC_INFO_CENTER_Z] = r->lid_z;
    out->info[IPC_INFO_VEL_X] = vx;
    out->info[IPC_INFO_VEL_Z] = r->lid_vz;
    out->stop = dx >= d->travel;
    return CM_OK;
}

static int shear_record(void *user, cm_error *err)
{
    shear_rig *r = user;
    return cm_csv_row(r->csv, r->row, err);
}

int main(int argc, char **argv)
{
    rig_args a;
    int rc = rig_parse_args("shear_rig", argc, argv, &a);
    if (rc)
        return rc;
    cm_run_config rcfg;
    static shear_rig r;
    if (rig_read_scene("shear_rig", &a, &rcfg, read_shear, &r.d))
        return 1;
    build_mesh(&r);
    r.phase = PHASE_APPROACH;
    r.lid_z = r.d.lid_start_z;
    r.t_target = r.t_shear = NAN;
    char path[1100];
    snprintf(path, sizeof path, "%s/shear_box.csv", a.out);
    static const char *const cols[SHEAR_COLS] = {
        "t",           "phase",           "displacement",  "lid_z",    "height",
        "normal_force", "normal_stress",  "shear_force",   "shear_stress", "lid_shear_force",
        "upper_wall_fz", "lower_fx",      "contacts"};
    cm_error err = {0};
    if (cm_csv_create(path, cols, SHEAR_COLS, &r.csv, &err)) {
        fprintf(stderr, "[shear_rig] error: %s\n", err.msg);
        return 1;
    }
    const rig_def def = {.name = "shear_rig", .n_nodes = r.n_nodes, .n_tris = r.n_tris, .x0 = r.x0, .tris = r.tris,
                         .mass = NULL, .advance = shear_advance, .record = shear_record, .user = &r};
    rc = rig_run(&def, &rcfg, &a);
    if (cm_csv_close(&r.csv, &err) && !rc) {
        fprintf(stderr, "[shear_rig] error: %s\n", err.msg);
        return 1;
    }
    if (rc)
        return rc;
    printf("[shear_rig] box %.3f x %.3f m, sigma_n %.4g Pa: sheared %.4f m; %s\n", r.d.box[0], r.d.box[1],
           r.d.normal_stress, isnan(r.t_shear) ? 0.0 : r.row[2], path);
    return 0;
}
