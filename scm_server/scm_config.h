/* scm_server's scene section `scm` (every key documented in README.md). */
#ifndef SCM_CONFIG_H
#define SCM_CONFIG_H

#include "scene.h"
#include "scm.h"

typedef struct scm_config {
    scm_grid_def grid;
    scm_soil soil;
    long series_every; /* exchanges between rows of scm_series.csv */
} scm_config;

/* Reads scm.*: scm.surface_height and scm.grid.min / max are required, the
 * rest defaults to scm_soil_default(). Errors name the key and the line. */
int scm_config_read(cm_scene *s, scm_config *c, cm_error *err);

#endif
