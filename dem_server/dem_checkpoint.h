/* dem_server's checkpoints: the complete state of the world and of the
 * coupled loop after one exchange, to HDF5 (common/ckpt.h), so that a run
 * resumed from it continues bit for bit as the uninterrupted run would. */
#ifndef DEM_CHECKPOINT_H
#define DEM_CHECKPOINT_H

#include <stdint.h>

#include "ckpt.h"
#include "dem.h"
#include "dem_coupled.h"
#include "dem_window.h"

/* Where the run's output files stood at the checkpoint. */
typedef struct dem_ckpt_outputs {
    long frames;       /* frames in dem_grains.h5 */
    long series_rows;  /* rows in dem_series.csv */
    long last_frame;   /* DEM step of the last frame / series row written */
    long last_series;
} dem_ckpt_outputs;

/* Writes <dir>/checkpoint/dem.h5 (the previous one kept as dem.prev.h5).
 * scene_hash identifies the scene file; the resumed run must use the same.
 * win: the terrain window (NULL = none); its sample is not saved, a resumed
 * run rebuilds it from the same settled bed. */
int dem_checkpoint_write(const char *dir, dem_world *w, dem_window *win, const dem_coupled_state *st,
                         dem_ckpt_outputs *out, uint64_t scene_hash, cm_error *err);

/* Restores from `path` (which must hold `exchange`) into a world built from
 * the same scene (same grains count capacity, walls, shapes, thread count)
 * with its surface installed; st->x and st->v (st->n_nodes nodes) are filled. */
int dem_checkpoint_read(const char *path, long exchange, dem_world *w, dem_window *win, dem_coupled_state *st,
                        dem_ckpt_outputs *out, uint64_t scene_hash, cm_error *err);

#endif
