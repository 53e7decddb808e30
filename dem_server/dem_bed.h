/* dem: settled beds of grains (placed, settled under gravity, saved and
 * reloaded as a cache keyed by their parameters and the settling code). */
#ifndef DEM_BED_H
#define DEM_BED_H

#include <stdbool.h>

#include "dem.h"

/* ---- Bed generation --------------------------------------------------- */

#define DEM_MAX_LAYERS 8

/* Shape of the grains of a bed layer. Sizes are relative: each grain is
 * scaled so that its volume-equivalent radius is the layer's drawn radius
 * (same mass as the sphere of that radius). */
typedef struct dem_bed_shape {
    int type;               /* enum dem_shape_type; DEM_SHAPE_SPHERE (0) = spheres */
    double semi_axes[3];    /* ellipsoid: axis ratios */
    int n_verts;            /* polyhedron: explicit vertices (relative), or 0 = random angular grains */
    double verts[DEM_SHAPE_MAX_VERTS][3];
    double elongation;      /* random grains: long / short axis ratio, >= 1 */
    int random_verts;       /* random grains: vertices per grain */
    int variants;           /* random grains: distinct shapes in the layer */
} dem_bed_shape;

typedef struct dem_bed_layer {
    int count;          /* grains in the layer */
    double radius[2];   /* radius range [min, max], m, uniform distribution (volume-equivalent for shapes) */
    dem_bed_shape shape; /* zero-initialised = spheres */
} dem_bed_layer;

typedef struct dem_bed_params {
    double box_min[3], box_max[3]; /* m: floor at box_min[2], side walls at x/y limits */
    int n_layers;                  /* listed bottom to top (paper: finest on top) */
    dem_bed_layer layers[DEM_MAX_LAYERS];
    int material;                  /* grain material */
    int wall_material;
    bool side_walls;               /* add the four side walls (the floor is always added) */
    uint64_t seed;
    double fill_fraction;          /* solid fraction of the loose initial placement */
    double settle_ke;              /* J per grain: settled when KE/grain falls below */
    double settle_min_time;        /* s, settle at least this long */
    double settle_max_time;        /* s, fail if not settled by then */
    double settle_dt;              /* s, step used while settling (<= 0: the world's dt) */
    double settle_friction;        /* sliding friction of every contact while settling, rolling resistance off
                                    * then (< 0: the materials' own); a denser bed, as pouring with lubricated
                                    * grains gives; the materials' values act from the run's first step */
    char file[1024];               /* HDF5 cache; "" = none */
} dem_bed_params;

dem_bed_params dem_bed_params_default(void);

/* Progress callback during settling (may be NULL); return nonzero to abort. */
typedef int (*dem_bed_progress)(dem_world *w, void *user);

/* Fills w (which must hold no grains) with a settled bed: loads params->file
 * when it exists and its stored parameters and settling-code fingerprint
 * match, otherwise places grains randomly without overlap, lets them settle
 * under gravity (in a scratch world with w's settings and walls) and saves
 * the file. Either way w receives the bed as stored (id order, at rest, no
 * springs), so a run is the same whether its bed was cached or not.
 * Adds the floor (and side walls) to w. *loaded tells which happened. */
int dem_bed_build(dem_world *w, const dem_bed_params *params, dem_bed_progress cb, void *user, bool *loaded,
                  cm_error *err);
/* The pieces, for tests. */
/* The floor at box_min[2] and, with side_walls, the four walls at the box's
 * x and y limits, of wall_material (as dem_bed_build adds them). */
int dem_bed_add_walls(dem_world *w, const dem_bed_params *params, cm_error *err);
int dem_bed_place(dem_world *w, const dem_bed_params *params, cm_error *err);
int dem_bed_settle(dem_world *w, const dem_bed_params *params, dem_bed_progress cb, void *user,
                   cm_error *err);
int dem_bed_save(const dem_world *w, const dem_bed_params *params, const char *path, cm_error *err);
/* CM_OK when loaded; CM_WARN_STALE (a warning), the reason in err, when the file's
 * parameters differ or it was settled by other code (its settling-code
 * fingerprint, a miniature of the bed settled by this build, differs);
 * another error when the file cannot be read. */
int dem_bed_load(dem_world *w, const dem_bed_params *params, const char *path, cm_error *err);
/* Canonical text of everything that determines a bed (materials included). */
void dem_bed_params_text(const dem_world *w, const dem_bed_params *p, char *buf, int len);
/* Bed surface height, m: mean over columns (2 r_max wide) of the highest grain top. */
double dem_bed_height(const dem_world *w);

#endif
