/* The terrain window: the second paper's terrain replacement (路面更替法,
 * Zhao & Zang, sec. 2): the bed follows the wheel along +x with a bounded
 * number of grains, and grains far from the wheel are frozen.
 *
 * The settled bed is the sample. At creation the grains of its interior
 * stretch [x_min + sample_margin, x_min + sample_margin + shift) (away from
 * the end walls' flat packing) are saved. Then, every exchange, with the
 * wheel centre x_c the FEM sends:
 *   - when x_c - behind has passed the back wall by `shift`, every grain with
 *     x < x_c - behind is removed and the back wall moves up to the survivors;
 *   - while the front wall is less than `ahead` in front of x_c, a copy of the
 *     sample stretch is appended in front of it (copies at the stretch's
 *     period, the first where the grains against the front wall end; a copied
 *     grain that would overlap one already there is pushed forward just clear
 *     of it) and the front wall moves to the copy's end;
 *   - grains outside the live stretch are frozen (dem_freeze_outside_x),
 *     re-evaluated every time x_c has moved by a grain radius: by default
 *     (freeze_distance < 0) the window's own extents, x < x_c - behind or
 *     x > x_c + ahead, the soil between them and the end walls (up to one
 *     `shift` each) held still; with freeze_distance > 0, |x - x_c| >
 *     freeze_distance; with 0, none.
 * Each shift is logged with the grains removed/added and the seam's density. */
#ifndef DEM_WINDOW_H
#define DEM_WINDOW_H

#include "dem.h"
#include "dem_config.h"

/* Freezing (measured: a rigid wheel under 150 N, 20 % slip,
 * tests/dem/test_dem_window.c freeze_distance_sweep, two seeds): grains
 * frozen beyond 1.1 contact lengths made the wheel sink 22-30 % less and pull
 * up to 2x the horizontal force (the frozen soil ahead acts as a wall); beyond
 * 1.7, 2.4 and 3.3 contact lengths sinkage and force stayed within the
 * seed-to-seed scatter of the long bed (sinkage +-5 %, horizontal force +-4 N
 * of 22 N). The default freezes beyond the window's own extents: ahead >= 2
 * contact lengths and behind >= 1 by the footprint check below, where the
 * window already puts its end walls at the moment before each shift; frozen,
 * the soil between them and the walls (up to one `shift`) costs nothing but
 * its contacts with the live grains. Measured on the scenes: README "Speed,
 * session 25". */

/* Everything that changes while the window moves (for checkpoints: these
 * fields plus the world; the sample is re-read from the settled bed, see
 * dem_window_create). */
typedef struct dem_window_state {
    double x_back, x_front;    /* m, planes of the back and front end walls */
    double x_cut;              /* m, where grains were last removed behind (the next removal waits for the
                                  wheel to advance `shift` past it; the back wall stands up to a grain
                                  diameter behind it, so it cannot serve) */
    double next_offset;        /* m, x offset of the next appended copy of the sample stretch */
    double x_freeze;           /* m, wheel x at the last freezing update (NAN: none yet) */
    int wall_back, wall_front; /* indices of the end walls in the world */
    int shifts_back;           /* removals done */
    int shifts_front;          /* stretches appended */
    long removed, added;       /* grains, in total */
    double seam_min_fraction;  /* lowest solid fraction of a seam slab relative to the sample's, of all seams */
} dem_window_state;

typedef struct dem_window dem_window;

/* Saves the sample stretch from the grains of w (which must hold the settled
 * bed and nothing else yet) and finds the end walls (normals +x and -x).
 * Errors name the dem.window key to change. */
int dem_window_create(const dem_world *w, const dem_window_def *def, dem_window **out, cm_error *err);
void dem_window_free(dem_window **win);

/* Footprint check against the trap of a too small soil bin (drawbar pull
 * 12-43 % low): contact length l = 2 sqrt(2 R z - z^2) from the surface's
 * radius R (half its z-extent) and the expected sinkage z, tire width b from
 * its y-extent. Warns (cm_log_warn) naming the key when
 *   ahead  < 2 l     (bed ahead of the wheel centre: its end wall, like frozen
 *                     grains, stiffens the soil the wheel pushes),
 *   behind < l       (bed behind it),
 *   side clearance (bed wall to tire side) < b / 2 on either side,
 *   soil under the tire's lowest point (bed height - floor - z) < a, the
 *                     radius of a circle of the footprint's area l b (the
 *                     floor bears > 65 % of the contact pressure: Boussinesq),
 *   0 < freeze_distance < 2 l.
 * win may be NULL (no window: the bed's ends at the wheel's start position
 * are checked, and `ahead` shrinks as the wheel travels). Returns the
 * warnings given, as
 * DEM_FOOTPRINT_* bits (0: none). */
enum {
    DEM_FOOTPRINT_AHEAD = 1,
    DEM_FOOTPRINT_BEHIND = 2,
    DEM_FOOTPRINT_SIDES = 4,
    DEM_FOOTPRINT_FLOOR = 8,
    DEM_FOOTPRINT_FREEZE = 16
};
int dem_window_check_footprint(const dem_window *win, const dem_world *w, const dem_window_def *def, double wheel_x,
                               double expected_sinkage);

/* One exchange's update with the wheel centre's x. */
int dem_window_update(dem_window *win, dem_world *w, double wheel_x, cm_error *err);

/* What dem_window_update would do at wheel_x (nothing changes): nothing,
 * only freeze (dem_freeze_outside_x(w, *freeze_lo, *freeze_hi)), or shift
 * (remove behind and/or append in front, then freeze). A distributed DEM
 * (dem_coupled.c) freezes on every rank for the second and updates the
 * world gathered on rank 0 for the third. */
enum { DEM_WINDOW_NONE = 0, DEM_WINDOW_FREEZE = 1, DEM_WINDOW_SHIFT = 2 };
int dem_window_pending(const dem_window *win, double wheel_x, double *freeze_lo, double *freeze_hi);

const dem_window_state *dem_window_get_state(const dem_window *win);
void dem_window_set_state(dem_window *win, const dem_window_state *st);

#endif
