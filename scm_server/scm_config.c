/* Reading the `scm` section of a scene. */
#include "scm_config.h"

#include <math.h>
#include <string.h>

#define TRY(x)                                                                                              \
    do {                                                                                                    \
        int rc_ = (x);                                                                                      \
        if (rc_)                                                                                            \
            return rc_;                                                                                     \
    } while (0)

int scm_config_read(cm_scene *s, scm_config *c, cm_error *err)
{
    memset(c, 0, sizeof *c);
    const scm_soil d = scm_soil_default();
    scm_soil *o = &c->soil;
    *o = d;
    double lo[2], hi[2], phi_deg = d.phi * 180.0 / M_PI;
    TRY(cm_scene_double(s, "scm.surface_height", -1e3, 1e3, &c->grid.height, err));
    TRY(cm_scene_doubles(s, "scm.grid.min", 2, -1e3, 1e3, lo, err));
    TRY(cm_scene_doubles(s, "scm.grid.max", 2, -1e3, 1e3, hi, err));
    TRY(cm_scene_double_opt(s, "scm.grid.cell", 1e-5, 1.0, 0.005, &c->grid.cell, err));
    TRY(cm_scene_double_opt(s, "scm.soil.k_c", -1e9, 1e9, d.k_c, &o->k_c, err));
    TRY(cm_scene_double_opt(s, "scm.soil.k_phi", 0.0, 1e12, d.k_phi, &o->k_phi, err));
    TRY(cm_scene_double_opt(s, "scm.soil.n", 0.1, 3.0, d.n, &o->n, err));
    TRY(cm_scene_double_opt(s, "scm.soil.cohesion", 0.0, 1e7, d.cohesion, &o->cohesion, err));
    TRY(cm_scene_double_opt(s, "scm.soil.friction_angle", 0.0, 60.0, phi_deg, &phi_deg, err));
    TRY(cm_scene_double_opt(s, "scm.soil.K", 1e-6, 10.0, d.K, &o->K, err));
    TRY(cm_scene_double_opt(s, "scm.soil.unload_k0", 0.0, 1e13, d.k0, &o->k0, err));
    TRY(cm_scene_double_opt(s, "scm.soil.unload_Au", 0.0, 1e15, d.A_u, &o->A_u, err));
    TRY(cm_scene_double_opt(s, "scm.soil.plate_width", 0.0, 100.0, d.b, &o->b, err));
    TRY(cm_scene_double_opt(s, "scm.soil.z_reg", 0.0, 1.0, d.z_reg, &o->z_reg, err));
    TRY(cm_scene_int_opt(s, "scm.output.series_every", 1, 100000000, 100, &c->series_every, err));
    o->phi = phi_deg * M_PI / 180.0;
    for (int a = 0; a < 2; a++)
        c->grid.min[a] = lo[a], c->grid.max[a] = hi[a];
    const char *path = cm_scene_path(s);
    if (!(hi[0] > lo[0] && hi[1] > lo[1]))
        return cm_fail(err, CM_ERR_RANGE, "%s: scm.grid.max must exceed scm.grid.min in x and y", path);
    if (!(o->k0 > 0 || o->A_u > 0))
        return cm_fail(err, CM_ERR_RANGE,
                       "%s: scm.soil.unload_k0 and scm.soil.unload_Au are both 0: the soil would never unload "
                       "(give a positive unloading stiffness)", path);
    if (o->n < 1 && !(o->z_reg > 0))
        return cm_fail(err, CM_ERR_RANGE,
                       "%s: scm.soil.n = %g < 1 needs scm.soil.z_reg > 0 (z^n is infinitely stiff at z = 0)", path,
                       o->n);
    if (!(o->k_phi > 0 || o->k_c > 0))
        return cm_fail(err, CM_ERR_RANGE, "%s: scm.soil.k_c and k_phi give no pressure", path);
    return CM_OK;
}
