/* dem: the scene file's dem section read into a world, its bed and its
 * walls (keys documented in dem_server/README.md). */
#ifndef DEM_CONFIG_H
#define DEM_CONFIG_H

#include <stdbool.h>

#include "dem.h"
#include "dem_bed.h"

typedef struct cm_scene cm_scene;

/* ---- Scene ------------------------------------------------------------ */

typedef struct dem_wall_def {
    double point[3], normal[3];
    int material;
} dem_wall_def;

/* The terrain window (dem.window; dem_window.h): the second paper's terrain
 * replacement, the bed follows the wheel along +x. */
typedef struct dem_window_def {
    bool enabled;
    double behind;           /* m: grains farther than this behind the wheel centre are removed */
    double ahead;            /* m: the bed is kept at least this long ahead of the wheel centre */
    double shift;            /* m: removal happens in steps of this; length of each appended stretch */
    double sample_margin;    /* m: the appended stretch is taken this far inside the bed's end walls */
    double freeze_distance;  /* m: grains farther than this from the wheel centre (along x) are frozen; 0 = never,
                              * < 0 = beyond the window's own behind and ahead (dem_window.h) */
    double expected_sinkage; /* m: for the footprint check at start */
} dem_window_def;

typedef struct dem_config {
    dem_world_def world;
    int n_materials;
    dem_material materials[DEM_MAX_MATERIALS];
    char material_names[DEM_MAX_MATERIALS][32];
    int n_walls;
    dem_wall_def walls[DEM_MAX_WALLS];
    bool has_bed;
    dem_bed_params bed;
    char output_dir[1024]; /* "" = no output */
    int output_every;      /* steps between grain frames */
    int series_every;      /* steps between time-series lines */
    dem_window_def window;
    /* MPI (dem_server/README.md, "MPI"): neither changes a result */
    int ranks;             /* dem.ranks: the ranks ./run starts dem_server on (its --ranks wins) */
    int balance;           /* dem.balance: DEM_BALANCE_GRAINS or DEM_BALANCE_TIME (how slabs are chosen) */
} dem_config;

enum { DEM_BALANCE_GRAINS = 0, DEM_BALANCE_TIME = 1 }; /* dem.balance's words, in order */

/* Reads the `dem = { ... }` section (only that one) of a scene. */
int dem_config_read(cm_scene *s, dem_config *c, cm_error *err);
/* Creates the world of a config (materials, walls; not the bed). */
int dem_world_from_config(const dem_config *c, dem_world **out, cm_error *err);

#endif
