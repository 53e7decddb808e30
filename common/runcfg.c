#include "runcfg.h"

#include <stdio.h>
#include <string.h>

int cm_run_config_read(cm_scene *s, cm_run_config *c, cm_error *err)
{
    memset(c, 0, sizeof *c);
    long every = 1;
    int rc;
    if ((rc = cm_scene_string_opt(s, "run.name", "run", c->name, sizeof c->name, err)) ||
        (rc = cm_scene_double(s, "run.end_time", 0.0, 1e6, &c->end_time, err)) ||
        (rc = cm_scene_double_opt(s, "run.progress_every", 0.0, 3600.0, 2.0, &c->progress_every, err)) ||
        (rc = cm_scene_double_opt(s, "run.checkpoint_every", 0.0, 1e6, 0.0, &c->checkpoint_every, err)) ||
        (rc = cm_scene_double(s, "coupling.dt", 1e-12, 1.0, &c->dt, err)) ||
        (rc = cm_scene_int_opt(s, "coupling.exchange_every", 1, 100000, 1, &every, err)) ||
        (rc = cm_scene_double_opt(s, "coupling.stall_timeout", 0.1, 60.0, 10.0, &c->stall_timeout, err)) ||
        (rc = cm_scene_double_opt(s, "coupling.connect_timeout", 1.0, 3600.0, 120.0, &c->connect_timeout, err)) ||
        (rc = cm_scene_double_opt(s, "coupling.max_overlap", 0.0, 1.0, 0.2, &c->max_overlap, err)) ||
        (rc = cm_scene_double_opt(s, "coupling.max_surface_overlap", 0.0, 1.0, 0.5, &c->max_surface_overlap,
                                  err)))
        return rc;
    c->exchange_every = (int)every;
    if (cm_scene_has(s, "run.target")) {
        /* The quantities the study measures (bench/study/run). */
        static const char *const quantities[] = {"drawbar_pull", "gross_traction", "sinkage", "deflection",
                                                 "contact_time", "peak_force", "restitution", NULL};
        int q;
        if ((rc = cm_scene_choice(s, "run.target.quantity", quantities, &q, err)) ||
            (rc = cm_scene_double(s, "run.target.tolerance", 1e-6, 10.0, &c->target_tolerance, err)) ||
            (rc = cm_scene_string_opt(s, "run.target.study", "", c->target_study, sizeof c->target_study, err)))
            return rc;
        snprintf(c->target_quantity, sizeof c->target_quantity, "%s", quantities[q]);
    }
    return CM_OK;
}
