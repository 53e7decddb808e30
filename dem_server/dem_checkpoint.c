/* dem_server's checkpoints (dem_checkpoint.h). One field list, visit_world,
 * serves both writing and reading (common/ckpt.h): every array of
 * dem_world in slot order, the neighbour list with the history hash and
 * springs, the surface springs, counters; then the coupled loop's state and
 * the output positions. Transient data (cell grid, thread buffers, scratch,
 * this step's forces on the surface) is rebuilt by the next step and not saved. */
#include "dem_checkpoint.h"

#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "dem_world.h"

/* Per-grain flags stored as 32-bit integers (the checkpoint's smallest type). */
static void flags_u8(cm_ckpt *ck, const char *name, unsigned char *p, size_t n)
{
    int *tmp = malloc((n ? n : 1) * sizeof *tmp);
    if (!tmp) {
        if (ck->rc == CM_OK)
            ck->rc = cm_fail(ck->err, CM_ERR_NOMEM, "%s: out of memory", ck->path);
        return;
    }
    for (size_t k = 0; ck->writing && k < n; k++)
        tmp[k] = p[k];
    cm_ckpt_i32(ck, name, tmp, n);
    for (size_t k = 0; !ck->writing && ck->rc == CM_OK && k < n; k++)
        p[k] = (unsigned char)(tmp[k] != 0);
    free(tmp);
}

/* The terrain window: where its walls and planes stand and its counters
 * (dem_window_state); the frozen flags and tags are the world's. */
static void visit_window(cm_ckpt *ck, dem_window *win)
{
    int has = win != NULL;
    cm_ckpt_same_u64(ck, "/window/enabled", (uint64_t)has, "whether the scene has a dem.window");
    if (!win || ck->rc != CM_OK)
        return;
    dem_window_state st = *dem_window_get_state(win);
    cm_ckpt_double(ck, "/window/x_back", &st.x_back);
    cm_ckpt_double(ck, "/window/x_front", &st.x_front);
    cm_ckpt_double(ck, "/window/x_cut", &st.x_cut);
    cm_ckpt_double(ck, "/window/next_offset", &st.next_offset);
    cm_ckpt_double(ck, "/window/x_freeze", &st.x_freeze);
    cm_ckpt_int(ck, "/window/wall_back", &st.wall_back);
    cm_ckpt_int(ck, "/window/wall_front", &st.wall_front);
    cm_ckpt_int(ck, "/window/shifts_back", &st.shifts_back);
    cm_ckpt_int(ck, "/window/shifts_front", &st.shifts_front);
    cm_ckpt_long(ck, "/window/removed", &st.removed);
    cm_ckpt_long(ck, "/window/added", &st.added);
    cm_ckpt_double(ck, "/window/seam_min_fraction", &st.seam_min_fraction);
    if (!ck->writing && ck->rc == CM_OK)
        dem_window_set_state(win, &st);
}

/* Reading: room for n_pairs pairs. */
static void reserve_pairs(cm_ckpt *ck, dem_world *w, int n_pairs)
{
    if (!ck->writing && ck->rc == CM_OK && dem_pairs_reserve(w, n_pairs))
        ck->rc = cm_fail(ck->err, CM_ERR_NOMEM, "%s: out of memory for %d pairs", ck->path, n_pairs);
}

static void reserve_hash(cm_ckpt *ck, dem_hash *h, int cap)
{
    if (ck->writing || ck->rc != CM_OK || cap == h->cap)
        return;
    uint64_t *k = realloc(h->key, (size_t)(cap ? cap : 1) * sizeof *k);
    int *r = k ? realloc(h->row, (size_t)(cap ? cap : 1) * sizeof *r) : NULL;
    if (k)
        h->key = k;
    if (!r) {
        ck->rc = cm_fail(ck->err, CM_ERR_NOMEM, "%s: out of memory for the contact history", ck->path);
        return;
    }
    h->row = r;
    h->cap = cap;
}

/* The rows of a history table; an empty slot's row is never read and never
 * set (dem_hash_reset clears only the keys): stored as -1. */
static void hash_rows(cm_ckpt *ck, dem_hash *h, int cap)
{
    if (!ck->writing) {
        cm_ckpt_i32(ck, "/pairs/hash_row", h->row, (size_t)cap);
        return;
    }
    int *rows = malloc((size_t)(cap ? cap : 1) * sizeof *rows);
    if (!rows) {
        if (ck->rc == CM_OK)
            ck->rc = cm_fail(ck->err, CM_ERR_NOMEM, "%s: out of memory", ck->path);
        return;
    }
    for (int k = 0; k < cap; k++)
        rows[k] = h->key[k] == DEM_HASH_EMPTY ? -1 : h->row[k];
    cm_ckpt_i32(ck, "/pairs/hash_row", rows, (size_t)cap);
    free(rows);
}

static void visit_world(cm_ckpt *ck, dem_world *w)
{
    dem_grains *g = &w->g;
    /* What the scene fixes: a resumed run must have built the same. */
    /* sphere contacts give the same bits for any thread count (a run may
     * resume with another); shaped grains' contacts are summed per thread */
    if (w->n_shaped > 0)
        cm_ckpt_same_u64(ck, "/world/threads", (uint64_t)w->n_threads,
                         "the DEM thread count (dem.threads, --threads): with shaped grains results depend on it");
    cm_ckpt_same_u64(ck, "/world/walls", (uint64_t)w->n_walls, "the number of walls");
    cm_ckpt_same_u64(ck, "/world/wall_stride", (uint64_t)w->wall_stride, "the wall history layout");
    cm_ckpt_same_u64(ck, "/world/shapes", (uint64_t)w->n_shapes, "the number of grain shapes");
    cm_ckpt_same_u64(ck, "/world/surface_nodes", (uint64_t)(w->surf ? w->surf->n_nodes : 0),
                     "the number of surface nodes");

    /* Grains, slot order. */
    cm_ckpt_count(ck, "/grains/n", &g->n, g->cap);
    const size_t n = (size_t)g->n;
    struct {
        const char *name;
        double *p;
        size_t per;
    } dbl[] = {{"/grains/x", g->x, 1},          {"/grains/y", g->y, 1},          {"/grains/z", g->z, 1},
               {"/grains/vx", g->vx, 1},        {"/grains/vy", g->vy, 1},        {"/grains/vz", g->vz, 1},
               {"/grains/wx", g->wx, 1},        {"/grains/wy", g->wy, 1},        {"/grains/wz", g->wz, 1},
               {"/grains/fx", g->fx, 1},        {"/grains/fy", g->fy, 1},        {"/grains/fz", g->fz, 1},
               {"/grains/tx", g->tx, 1},        {"/grains/ty", g->ty, 1},        {"/grains/tz", g->tz, 1},
               {"/grains/r", g->r, 1},          {"/grains/inv_m", g->inv_m, 1},  {"/grains/inv_i", g->inv_i, 1},
               {"/grains/x0", g->x0, 1},        {"/grains/y0", g->y0, 1},        {"/grains/z0", g->z0, 1},
               {"/grains/q", g->q, 4},          {"/grains/sc", g->sc, 1},        {"/grains/inertia", g->inertia, 3},
               {"/grains/angmom", g->angmom, 3},
               {"/grains/wall_hist", g->wall_hist, (size_t)w->hist_stride * w->wall_stride}};
    for (size_t k = 0; k < sizeof dbl / sizeof dbl[0]; k++)
        cm_ckpt_f64(ck, dbl[k].name, dbl[k].p, dbl[k].per * n);
    cm_ckpt_i32(ck, "/grains/mat", g->mat, n);
    cm_ckpt_i32(ck, "/grains/id", g->id, n);
    cm_ckpt_i32(ck, "/grains/slot_of", g->slot_of, n);
    cm_ckpt_i32(ck, "/grains/surf_count", g->surf_count, n);
    cm_ckpt_i32(ck, "/grains/shape", g->shape, n);
    cm_ckpt_u32(ck, "/grains/wall_mask", g->wall_mask, n);
    cm_ckpt_int(ck, "/grains/n_shaped", &w->n_shaped);
    /* terrain window: stable tags (the contact history's keys), frozen grains */
    cm_ckpt_i32(ck, "/grains/tag", g->tag, n);
    flags_u8(ck, "/grains/frozen", g->frozen, n);
    cm_ckpt_int(ck, "/grains/next_tag", &w->next_tag);
    cm_ckpt_int(ck, "/grains/n_frozen", &w->n_frozen);
    for (int k = 0; k < w->n_walls; k++) {
        char name[64];
        snprintf(name, sizeof name, "/walls/%d/force", k);
        cm_ckpt_f64(ck, name, w->walls[k].force, 3);
        snprintf(name, sizeof name, "/walls/%d/point", k); /* end walls follow the window */
        cm_ckpt_f64(ck, name, w->walls[k].p, 3);
    }

    /* Neighbour list, its history table and springs (the current ones). */
    cm_ckpt_count(ck, "/pairs/n", &w->n_pairs, INT_MAX / 8);
    reserve_pairs(ck, w, w->n_pairs);
    cm_ckpt_i32(ck, "/pairs/i", w->pi, (size_t)w->n_pairs);
    cm_ckpt_i32(ck, "/pairs/j", w->pj, (size_t)w->n_pairs);
    cm_ckpt_int(ck, "/pairs/n_active", &w->n_active_pairs);
    cm_ckpt_count(ck, "/pairs/hist_cur", &w->hist_cur, 1);
    if (ck->rc == CM_OK) {
        dem_hash *h = &w->hist[w->hist_cur];
        int cap = h->cap;
        cm_ckpt_count(ck, "/pairs/hash_cap", &cap, INT_MAX / 8);
        reserve_hash(ck, h, cap);
        cm_ckpt_int(ck, "/pairs/hash_count", &h->count);
        cm_ckpt_u64(ck, "/pairs/hash_key", h->key, (size_t)cap);
        hash_rows(ck, h, cap);
        /* hist_stride per pair: a checkpoint of the other rolling model is
         * refused by the dataset's size, naming it */
        cm_ckpt_f64(ck, "/pairs/springs", w->hist_val[w->hist_cur], (size_t)w->hist_stride * w->n_pairs);
        if (!ck->writing && ck->rc == CM_OK) /* which way each spring points: from the pairs read */
            dem_hist_orient(w);
    }
    cm_ckpt_double(ck, "/pairs/skin", &w->skin);
    cm_ckpt_int(ck, "/pairs/need_rebuild", &w->need_rebuild);
    cm_ckpt_long(ck, "/pairs/rebuild_count", &w->rebuild_count);

    /* Surface springs, per grain slot (dem_surface.h). */
    if (w->surf)
        cm_ckpt_f64(ck, "/surface/hist", w->surf->hist, (size_t)DEM_SURF_SLOTS * DEM_SURF_SLOT_SIZE * n);

    cm_ckpt_long(ck, "/world/step", &w->step);
    cm_ckpt_double(ck, "/world/time", &w->time);
    cm_ckpt_double(ck, "/world/r_min", &w->r_min);
    cm_ckpt_double(ck, "/world/r_max", &w->r_max);
    cm_ckpt_int(ck, "/world/contacts_gg", &w->contacts_gg);
    cm_ckpt_int(ck, "/world/contacts_gw", &w->contacts_gw);
}

static void visit_run(cm_ckpt *ck, dem_coupled_state *st, dem_ckpt_outputs *o)
{
    cm_ckpt_double(ck, "/coupled/time", &st->time);
    cm_ckpt_double(ck, "/coupled/w_dem", &st->w_dem);
    cm_ckpt_same_u64(ck, "/coupled/n_nodes", (uint64_t)st->n_nodes, "the number of surface nodes");
    cm_ckpt_f64(ck, "/coupled/surface_x", st->x, 3 * (size_t)st->n_nodes);
    cm_ckpt_f64(ck, "/coupled/surface_v", st->v, 3 * (size_t)st->n_nodes);
    cm_ckpt_long(ck, "/output/frames", &o->frames);
    cm_ckpt_long(ck, "/output/series_rows", &o->series_rows);
    cm_ckpt_long(ck, "/output/last_frame", &o->last_frame);
    cm_ckpt_long(ck, "/output/last_series", &o->last_series);
}

int dem_checkpoint_write(const char *dir, dem_world *w, dem_window *win, const dem_coupled_state *st_in,
                         dem_ckpt_outputs *out, uint64_t scene_hash, cm_error *err)
{
    cm_ckpt ck;
    dem_coupled_state st = *st_in;
    if (cm_ckpt_begin_write(&ck, dir, "dem", st.exchange, err) == CM_OK) {
        cm_ckpt_same_u64(&ck, "/scene_hash", scene_hash, "the scene file or its --set overrides");
        visit_world(&ck, w);
        visit_window(&ck, win);
        visit_run(&ck, &st, out);
    }
    return cm_ckpt_commit(&ck);
}

int dem_checkpoint_read(const char *path, long exchange, dem_world *w, dem_window *win, dem_coupled_state *st,
                        dem_ckpt_outputs *out, uint64_t scene_hash, cm_error *err)
{
    /* prepare first (it resets what a fresh world starts with), then
     * overwrite with the saved state */
    int rc = dem_world_prepare(w, err);
    if (rc)
        return rc;
    cm_ckpt ck;
    if (cm_ckpt_begin_read(&ck, path, exchange, err) == CM_OK) {
        cm_ckpt_same_u64(&ck, "/scene_hash", scene_hash, "the scene file or its --set overrides");
        visit_world(&ck, w);
        visit_window(&ck, win);
        visit_run(&ck, st, out);
    }
    st->exchange = exchange;
    return cm_ckpt_end_read(&ck);
}
