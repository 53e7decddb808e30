/* Reading the `dem = { ... }` section of a scene (keys and units in README.md). */
#include <stdio.h>
#include <string.h>

#include "dem.h"
#include "dem_bed.h"
#include "dem_config.h"
#include "scene.h"

static int material_by_name(const dem_config *c, cm_scene *s, const char *path, int *out, cm_error *err)
{
    char name[64];
    int rc = cm_scene_string(s, path, name, sizeof name, err);
    if (rc)
        return rc;
    for (int k = 0; k < c->n_materials; k++)
        if (strcmp(name, c->material_names[k]) == 0) {
            *out = k;
            return CM_OK;
        }
    return cm_fail(err, CM_ERR_KEY, "%s: %s = \"%s\" is not a material listed in dem.materials", cm_scene_path(s),
                   path, name);
}

static int read_materials(cm_scene *s, dem_config *c, cm_error *err)
{
    int n = cm_scene_length(s, "dem.materials");
    if (n < 1 || n > DEM_MAX_MATERIALS)
        return cm_fail(err, CM_ERR_KEY, "%s: dem.materials must list 1..%d materials (found %d)", cm_scene_path(s),
                       DEM_MAX_MATERIALS, n);
    c->n_materials = n;
    char p[128];
    for (int k = 0; k < n; k++) {
        dem_material *m = &c->materials[k];
        int rc;
#define KEY(name) (snprintf(p, sizeof p, "dem.materials.[%d]." name, k), p)
        if ((rc = cm_scene_string(s, KEY("name"), c->material_names[k], sizeof c->material_names[k], err)) ||
            (rc = cm_scene_double_opt(s, KEY("density"), 0.0, 1e5, 0.0, &m->density, err)) ||
            (rc = cm_scene_double(s, KEY("young"), 1.0, 1e13, &m->young, err)) ||
            (rc = cm_scene_double(s, KEY("poisson"), 0.0, 0.4999, &m->poisson, err)) ||
            (rc = cm_scene_double(s, KEY("restitution"), 1e-3, 1.0, &m->restitution, err)) ||
            (rc = cm_scene_double(s, KEY("friction"), 0.0, 10.0, &m->friction, err)) ||
            (rc = cm_scene_double_opt(s, KEY("rolling_friction"), 0.0, 10.0, 0.0, &m->rolling_friction, err)))
            return rc;
#undef KEY
        for (int j = 0; j < k; j++)
            if (strcmp(c->material_names[j], c->material_names[k]) == 0)
                return cm_fail(err, CM_ERR_KEY, "%s: dem.materials.[%d].name \"%s\" is used twice", cm_scene_path(s),
                               k, c->material_names[k]);
    }
    return CM_OK;
}

static int read_walls(cm_scene *s, dem_config *c, cm_error *err)
{
    int n = cm_scene_length(s, "dem.walls");
    if (n > DEM_MAX_WALLS)
        return cm_fail(err, CM_ERR_RANGE, "%s: dem.walls lists %d walls (at most %d)", cm_scene_path(s), n,
                       DEM_MAX_WALLS);
    c->n_walls = n;
    char p[128];
    for (int k = 0; k < n; k++) {
        dem_wall_def *wd = &c->walls[k];
        int rc;
        snprintf(p, sizeof p, "dem.walls.[%d].point", k);
        if ((rc = cm_scene_doubles(s, p, 3, -1e6, 1e6, wd->point, err)))
            return rc;
        snprintf(p, sizeof p, "dem.walls.[%d].normal", k);
        if ((rc = cm_scene_doubles(s, p, 3, -1e6, 1e6, wd->normal, err)))
            return rc;
        if (wd->normal[0] == 0.0 && wd->normal[1] == 0.0 && wd->normal[2] == 0.0)
            return cm_fail(err, CM_ERR_RANGE, "%s: %s is the zero vector", cm_scene_path(s), p);
        snprintf(p, sizeof p, "dem.walls.[%d].material", k);
        if ((rc = material_by_name(c, s, p, &wd->material, err)))
            return rc;
    }
    return CM_OK;
}

/* dem.bed.layers.[k].shape = { type = "sphere" | "ellipsoid" | "polyhedron"; ... }
 * (README: sizes are relative, each grain is scaled to the layer's drawn
 * volume-equivalent radius). */
static int read_layer_shape(cm_scene *s, int k, dem_bed_shape *bs, cm_error *err)
{
    static const char *const types[] = {"sphere", "ellipsoid", "polyhedron", NULL};
    char p[160], base[96];
    snprintf(base, sizeof base, "dem.bed.layers.[%d].shape", k);
    memset(bs, 0, sizeof *bs);
    if (!cm_scene_has(s, base))
        return CM_OK;
    int rc;
#define KEY(name) (snprintf(p, sizeof p, "%s." name, base), p)
    if ((rc = cm_scene_choice(s, KEY("type"), types, &bs->type, err)))
        return rc;
    if (bs->type == DEM_SHAPE_ELLIPSOID)
        return cm_scene_doubles(s, KEY("semi_axes"), 3, 1e-3, 1e3, bs->semi_axes, err);
    if (bs->type != DEM_SHAPE_POLYHEDRON)
        return CM_OK;
    if (cm_scene_has(s, KEY("vertices"))) {
        int n = cm_scene_length(s, p);
        if (n < 4 || n > DEM_SHAPE_MAX_VERTS)
            return cm_fail(err, CM_ERR_RANGE, "%s: %s lists %d vertices (4..%d)", cm_scene_path(s), p, n,
                           DEM_SHAPE_MAX_VERTS);
        bs->n_verts = n;
        for (int v = 0; v < n; v++) {
            snprintf(p, sizeof p, "%s.vertices.[%d]", base, v);
            if ((rc = cm_scene_doubles(s, p, 3, -1e3, 1e3, bs->verts[v], err)))
                return rc;
        }
        dem_shape_def d = {.type = DEM_SHAPE_POLYHEDRON, .n_verts = n};
        memcpy(d.verts, bs->verts, sizeof d.verts);
        dem_shape_info in;
        if ((rc = dem_shape_compute(&d, &in, err))) {
            cm_fail_prefix(err, "%s: %s.vertices: ", cm_scene_path(s), base);
            return rc;
        }
        return CM_OK;
    }
    long nv = 12, var = 16;
    if ((rc = cm_scene_double_opt(s, KEY("elongation"), 1.0, 10.0, 1.0, &bs->elongation, err)) ||
        (rc = cm_scene_int_opt(s, KEY("random_vertices"), 6, DEM_SHAPE_MAX_VERTS, 12, &nv, err)) ||
        (rc = cm_scene_int_opt(s, KEY("variants"), 1, 64, 16, &var, err)))
        return rc;
    bs->random_verts = (int)nv;
    bs->variants = (int)var;
#undef KEY
    return CM_OK;
}

static int read_bed(cm_scene *s, dem_config *c, cm_error *err)
{
    dem_bed_params *b = &c->bed;
    *b = dem_bed_params_default();
    int rc;
    if ((rc = cm_scene_doubles(s, "dem.bed.box_min", 3, -1e6, 1e6, b->box_min, err)) ||
        (rc = cm_scene_doubles(s, "dem.bed.box_max", 3, -1e6, 1e6, b->box_max, err)) ||
        (rc = material_by_name(c, s, "dem.bed.material", &b->material, err)))
        return rc;
    for (int k = 0; k < 3; k++)
        if (!(b->box_max[k] > b->box_min[k]))
            return cm_fail(err, CM_ERR_RANGE, "%s: dem.bed.box_max[%d] must exceed box_min[%d]", cm_scene_path(s), k, k);
    b->wall_material = b->material;
    if (cm_scene_has(s, "dem.bed.wall_material") &&
        (rc = material_by_name(c, s, "dem.bed.wall_material", &b->wall_material, err)))
        return rc;
    long seed = 1;
    if ((rc = cm_scene_bool_opt(s, "dem.bed.side_walls", true, &b->side_walls, err)) ||
        (rc = cm_scene_int_opt(s, "dem.bed.seed", 0, 2147483647L, 1, &seed, err)) ||
        (rc = cm_scene_double_opt(s, "dem.bed.fill_fraction", 0.01, 0.35, b->fill_fraction, &b->fill_fraction, err)) ||
        (rc = cm_scene_double_opt(s, "dem.bed.settle_ke", 0.0, 1e3, b->settle_ke, &b->settle_ke, err)) ||
        (rc = cm_scene_double_opt(s, "dem.bed.settle_min_time", 0.0, 1e4, b->settle_min_time, &b->settle_min_time,
                                  err)) ||
        (rc = cm_scene_double_opt(s, "dem.bed.settle_max_time", 0.0, 1e4, b->settle_max_time, &b->settle_max_time,
                                  err)) ||
        (rc = cm_scene_double_opt(s, "dem.bed.settle_dt", 0.0, 1.0, 0.0, &b->settle_dt, err)) ||
        (rc = cm_scene_double_opt(s, "dem.bed.settle_friction", 0.0, 2.0, -1.0, &b->settle_friction, err)))
        return rc;
    b->seed = (uint64_t)seed;
    char file[1024] = "";
    if ((rc = cm_scene_string_opt(s, "dem.bed.file", "", file, sizeof file, err)))
        return rc;
    if (file[0] && file[0] != '/')
        snprintf(b->file, sizeof b->file, "%.500s/%.500s", cm_scene_dir(s), file);
    else
        snprintf(b->file, sizeof b->file, "%s", file);
    int nl = cm_scene_length(s, "dem.bed.layers");
    if (nl < 1 || nl > DEM_MAX_LAYERS)
        return cm_fail(err, CM_ERR_KEY, "%s: dem.bed.layers must list 1..%d layers, bottom to top (found %d)",
                       cm_scene_path(s), DEM_MAX_LAYERS, nl);
    b->n_layers = nl;
    char p[128];
    for (int k = 0; k < nl; k++) {
        long count;
        snprintf(p, sizeof p, "dem.bed.layers.[%d].count", k);
        if ((rc = cm_scene_int(s, p, 1, 100000000L, &count, err)))
            return rc;
        b->layers[k].count = (int)count;
        snprintf(p, sizeof p, "dem.bed.layers.[%d].radius", k);
        if ((rc = cm_scene_doubles(s, p, 2, 1e-9, 10.0, b->layers[k].radius, err)))
            return rc;
        if (b->layers[k].radius[1] < b->layers[k].radius[0])
            return cm_fail(err, CM_ERR_RANGE, "%s: %s: [min, max] with max < min", cm_scene_path(s), p);
        if ((rc = read_layer_shape(s, k, &b->layers[k].shape, err)))
            return rc;
    }
    return CM_OK;
}

/* dem.window = { behind; ahead; shift; sample_margin; freeze_distance; expected_sinkage; } */
static int read_window(cm_scene *s, dem_config *c, cm_error *err)
{
    dem_window_def *wd = &c->window;
    wd->expected_sinkage = 0.03;
    if (!cm_scene_has(s, "dem.window"))
        return CM_OK;
    if (!c->has_bed)
        return cm_fail(err, CM_ERR_KEY, "%s: dem.window needs dem.bed (the settled bed is the window's sample)",
                       cm_scene_path(s));
    if (!c->bed.side_walls)
        return cm_fail(err, CM_ERR_KEY, "%s: dem.window moves the bed's end walls: set dem.bed.side_walls = true",
                       cm_scene_path(s));
    wd->enabled = true;
    int rc;
    if ((rc = cm_scene_double(s, "dem.window.behind", 0.0, 1e3, &wd->behind, err)) ||
        (rc = cm_scene_double(s, "dem.window.ahead", 1e-6, 1e3, &wd->ahead, err)) ||
        (rc = cm_scene_double(s, "dem.window.shift", 1e-6, 1e3, &wd->shift, err)) ||
        (rc = cm_scene_double_opt(s, "dem.window.sample_margin", 0.0, 1e3, 0.04, &wd->sample_margin, err)) ||
        (rc = cm_scene_double_opt(s, "dem.window.freeze_distance", 0.0, 1e3, -1.0, &wd->freeze_distance, err)) ||
        (rc = cm_scene_double_opt(s, "dem.window.expected_sinkage", 0.0, 10.0, 0.03, &wd->expected_sinkage, err)))
        return rc;
    double len = c->bed.box_max[0] - c->bed.box_min[0];
    if (wd->shift > len - 2 * wd->sample_margin)
        return cm_fail(err, CM_ERR_RANGE,
                       "%s: dem.window.shift = %g m is longer than the bed's interior (dem.bed length %g m minus 2 x "
                       "dem.window.sample_margin = %g m), from which each stretch is copied",
                       cm_scene_path(s), wd->shift, len, wd->sample_margin);
    return CM_OK;
}

int dem_config_read(cm_scene *s, dem_config *c, cm_error *err)
{
    memset(c, 0, sizeof *c);
    c->world = dem_world_def_default();
    dem_world_def *d = &c->world;
    static const char *const damping_words[] = {"calibrated", "ln_e", NULL};
    static const char *const rolling_words[] = {"constant_torque", "spring", NULL}; /* enum dem_rolling_model */
    static const double g_def[3] = {0.0, 0.0, -9.81};
    static const char *const balance_words[] = {"grains", "time", NULL}; /* DEM_BALANCE_* */
    long threads = 1, ranks = 1, max_grains = 0, reorder = d->reorder_every;
    int rc;
    /* The step is the coupling's (both servers read coupling.dt); dem.dt is
     * for DEM-only scenes without a coupling section. */
    const char *dt_key = cm_scene_has(s, "dem.dt") || !cm_scene_has(s, "coupling.dt") ? "dem.dt" : "coupling.dt";
    if ((rc = cm_scene_double(s, dt_key, 1e-12, 1.0, &d->dt, err)) ||
        (rc = cm_scene_doubles_opt(s, "dem.gravity", 3, -1e4, 1e4, g_def, d->gravity, err)) ||
        (rc = cm_scene_int_opt(s, "dem.threads", 0, 1024, 1, &threads, err)) ||
        (rc = cm_scene_int_opt(s, "dem.ranks", 1, 65536, 1, &ranks, err)) ||
        (rc = cm_scene_choice_opt(s, "dem.balance", balance_words, DEM_BALANCE_GRAINS, &c->balance, err)) ||
        (rc = cm_scene_choice_opt(s, "dem.damping", damping_words, DEM_DAMPING_CALIBRATED, &d->damping, err)) ||
        (rc = cm_scene_choice_opt(s, "dem.rolling_model", rolling_words, DEM_ROLLING_CONSTANT_TORQUE,
                                  &d->rolling_model, err)) ||
        (rc = cm_scene_double_opt(s, "dem.impact_velocity", 1e-6, 1e4, d->impact_velocity, &d->impact_velocity,
                                  err)) ||
        (rc = cm_scene_double_opt(s, "dem.dt_safety_rayleigh", 1e-3, 10.0, d->dt_safety_rayleigh,
                                  &d->dt_safety_rayleigh, err)) ||
        (rc = cm_scene_double_opt(s, "dem.dt_safety_hertz", 1e-3, 10.0, d->dt_safety_hertz, &d->dt_safety_hertz,
                                  err)) ||
        (rc = cm_scene_bool_opt(s, "dem.allow_unstable_dt", false, &d->allow_unstable, err)) ||
        (rc = cm_scene_double_opt(s, "dem.neighbor_skin", 0.0, 10.0, 0.0, &d->skin, err)) ||
        (rc = cm_scene_int_opt(s, "dem.max_grains", 0, 100000000L, 0, &max_grains, err)) ||
        (rc = cm_scene_int_opt(s, "dem.reorder_every", 0, 1000000L, reorder, &reorder, err)))
        return rc;
    d->threads = (int)threads;
    c->ranks = (int)ranks;
    d->reorder_every = (int)reorder;
    if ((rc = read_materials(s, c, err)) || (rc = read_walls(s, c, err)))
        return rc;
    c->has_bed = cm_scene_has(s, "dem.bed");
    long bed_count = 0;
    if (c->has_bed) {
        if ((rc = read_bed(s, c, err)))
            return rc;
        for (int k = 0; k < c->bed.n_layers; k++)
            bed_count += c->bed.layers[k].count;
    }
    if ((rc = read_window(s, c, err)))
        return rc;
    long need = bed_count;
    if (c->window.enabled) {
        /* The bed spans at most behind + shift (removal lags by one shift)
         * + ahead + shift (one appended stretch) + seam gaps: sized once here,
         * no allocation while the window moves (15 % for density scatter). */
        const dem_window_def *wd = &c->window;
        double len = c->bed.box_max[0] - c->bed.box_min[0];
        double span = wd->behind + wd->ahead + 2.0 * wd->shift + 2.0 * wd->sample_margin;
        long win = (long)(1.15 * (double)bed_count * span / len) + 64;
        need = win > bed_count ? win : bed_count;
    }
    d->max_grains = (int)(max_grains > 0 ? max_grains : (need > 0 ? need : 1000));
    if (d->max_grains < bed_count)
        return cm_fail(err, CM_ERR_RANGE, "%s: dem.max_grains = %ld is smaller than the bed's %ld grains",
                       cm_scene_path(s), max_grains, bed_count);
    long every = 0, series = 0;
    if ((rc = cm_scene_string_opt(s, "dem.output.dir", "", c->output_dir, sizeof c->output_dir, err)) ||
        (rc = cm_scene_int_opt(s, "dem.output.every", 1, 1000000000L, 1000, &every, err)) ||
        (rc = cm_scene_int_opt(s, "dem.output.series_every", 1, 1000000000L, 100, &series, err)))
        return rc;
    c->output_every = (int)every;
    c->series_every = (int)series;
    if (c->output_dir[0] && c->output_dir[0] != '/') {
        char tmp[1024];
        snprintf(tmp, sizeof tmp, "%.500s/%.500s", cm_scene_dir(s), c->output_dir);
        snprintf(c->output_dir, sizeof c->output_dir, "%s", tmp);
    }
    return CM_OK;
}

int dem_world_from_config(const dem_config *c, dem_world **out, cm_error *err)
{
    int rc = dem_world_create(&c->world, c->n_materials, c->materials, out, err);
    if (rc)
        return rc;
    for (int k = 0; k < c->n_walls; k++)
        if ((rc = dem_wall_add(*out, c->walls[k].point, c->walls[k].normal, c->walls[k].material, err))) {
            dem_world_destroy(out);
            return rc;
        }
    return CM_OK;
}
