/* The neighbour list: a uniform cell grid over the grains, every pair within
 * r_i + r_j + skin, the springs carried over from the previous list, the
 * walls within reach of each grain; the grains re-sorted by cell now and
 * then for locality. */
#include "dem_world.h"

#include <float.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "log.h"
#include "timer.h"
#include "vec3.h"

#ifdef _OPENMP
#include <omp.h>
#endif

/* ---- neighbour list ---------------------------------------------------- */

static int grow_pairs(dem_world *w, int need)
{
    if (need <= w->pair_cap)
        return CM_OK;
    int cap = w->pair_cap ? w->pair_cap : 1024;
    while (cap < need)
        cap *= 2;
    int *a = realloc(w->pi, (size_t)cap * sizeof *a);
    if (!a)
        return CM_ERR_NOMEM;
    w->pi = a;
    a = realloc(w->pj, (size_t)cap * sizeof *a);
    if (!a)
        return CM_ERR_NOMEM;
    w->pj = a;
    for (int k = 0; k < 2; k++) {
        double *h = realloc(w->hist_val[k], (size_t)cap * 3 * sizeof *h);
        if (!h)
            return CM_ERR_NOMEM;
        w->hist_val[k] = h;
    }
    w->pair_cap = cap;
    return CM_OK;
}

typedef struct grid_dims {
    double lo[3], h;
    int n[3];
} grid_dims;

static int cell_of(const grid_dims *gd, double x, double y, double z)
{
    int c[3];
    double p[3] = {x, y, z};
    for (int k = 0; k < 3; k++) {
        int ck = (int)floor((p[k] - gd->lo[k]) / gd->h);
        c[k] = ck < 0 ? 0 : (ck >= gd->n[k] ? gd->n[k] - 1 : ck);
    }
    return (c[2] * gd->n[1] + c[1]) * gd->n[0] + c[0];
}

/* Uniform grid over the grains' bounding box, cell >= 2 r_max + skin,
 * grains counting-sorted by cell. */
static int grid_build(dem_world *w, grid_dims *gd)
{
    dem_grains *g = &w->g;
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (int i = 0; i < g->n; i++) {
        lo[0] = fmin(lo[0], g->x[i]), hi[0] = fmax(hi[0], g->x[i]);
        lo[1] = fmin(lo[1], g->y[i]), hi[1] = fmax(hi[1], g->y[i]);
        lo[2] = fmin(lo[2], g->z[i]), hi[2] = fmax(hi[2], g->z[i]);
    }
    double h = 2.0 * w->r_max + w->skin;
    long ncell;
    for (;;) {
        ncell = 1;
        for (int k = 0; k < 3; k++) {
            gd->n[k] = (int)fmin(1e6, floor((hi[k] - lo[k]) / h) + 1);
            ncell *= gd->n[k];
        }
        if (ncell <= 4L * g->n + 64)
            break;
        h *= 1.5; /* a few grains far away: coarser cells rather than a huge grid */
    }
    memcpy(gd->lo, lo, sizeof lo);
    gd->h = h;
    if (ncell + 1 > w->cell_cap) { /* grows only when the grains spread out */
        int *a = realloc(w->cell_start, (size_t)(ncell + 1) * sizeof *a);
        if (!a)
            return CM_ERR_NOMEM;
        w->cell_start = a;
        a = realloc(w->cell_pos, (size_t)(ncell + 1) * sizeof *a);
        if (!a)
            return CM_ERR_NOMEM;
        w->cell_pos = a;
        w->cell_cap = (int)(ncell + 1);
    }
    if (!w->cell_items) { /* once */
        w->cell_items = malloc((size_t)g->cap * sizeof *w->cell_items);
        if (!w->cell_items)
            return CM_ERR_NOMEM;
    }
    memset(w->cell_start, 0, (size_t)(ncell + 1) * sizeof *w->cell_start);
    for (int i = 0; i < g->n; i++) {
        w->grain_cell[i] = cell_of(gd, g->x[i], g->y[i], g->z[i]);
        w->cell_start[w->grain_cell[i] + 1]++;
    }
    for (long c = 0; c < ncell; c++)
        w->cell_start[c + 1] += w->cell_start[c];
    int *pos = w->cell_pos; /* stable counting sort */
    memcpy(pos, w->cell_start, (size_t)(ncell + 1) * sizeof *pos);
    for (int i = 0; i < g->n; i++)
        w->cell_items[pos[w->grain_cell[i]]++] = i;
    return CM_OK;
}

int dem_neighbour_rebuild(dem_world *w, cm_error *err)
{
    dem_grains *g = &w->g;
    grid_dims gd;
    if (grid_build(w, &gd))
        return cm_fail(err, CM_ERR_NOMEM, "step %ld: out of memory building the cell grid", w->step);
    if (w->def.reorder_every > 0 && w->rebuild_count % w->def.reorder_every == 0 && g->n > 1) {
        /* re-sort grains by cell (cell_items is that order) for memory locality */
        dem_grains_permute(w, w->cell_items);
        if (grid_build(w, &gd))
            return cm_fail(err, CM_ERR_NOMEM, "step %ld: out of memory building the cell grid", w->step);
    }
    w->n_pairs = 0;
    for (int i = 0; i < g->n; i++) {
        int c = w->grain_cell[i];
        int cx = c % gd.n[0], cy = (c / gd.n[0]) % gd.n[1], cz = c / (gd.n[0] * gd.n[1]);
        double ri = g->r[i] + w->skin;
        for (int dz = -1; dz <= 1; dz++) {
            int z = cz + dz;
            if (z < 0 || z >= gd.n[2])
                continue;
            for (int dy = -1; dy <= 1; dy++) {
                int y = cy + dy;
                if (y < 0 || y >= gd.n[1])
                    continue;
                for (int dx = -1; dx <= 1; dx++) {
                    int x = cx + dx;
                    if (x < 0 || x >= gd.n[0])
                        continue;
                    int cc = (z * gd.n[1] + y) * gd.n[0] + x;
                    for (int k = w->cell_start[cc]; k < w->cell_start[cc + 1]; k++) {
                        int j = w->cell_items[k];
                        if (j <= i)
                            continue;
                        double ex = g->x[i] - g->x[j], ey = g->y[i] - g->y[j], ez = g->z[i] - g->z[j];
                        double cut = ri + g->r[j];
                        if (ex * ex + ey * ey + ez * ez >= cut * cut)
                            continue;
                        if (w->n_pairs == w->pair_cap && grow_pairs(w, w->n_pairs + 1))
                            return cm_fail(err, CM_ERR_NOMEM, "step %ld: out of memory for %d pairs", w->step,
                                           w->n_pairs + 1);
                        w->pi[w->n_pairs] = i;
                        w->pj[w->n_pairs] = j;
                        w->n_pairs++;
                    }
                }
            }
        }
    }
    /* frozen-frozen pairs to the end of the list: the narrow phase stops at
     * n_active_pairs, their springs stay in the history untouched */
    int na = w->n_pairs;
    if (w->n_frozen > 0) {
        int lo = 0, hi = w->n_pairs - 1;
        for (;;) {
            while (lo <= hi && !(g->frozen[w->pi[lo]] && g->frozen[w->pj[lo]]))
                lo++;
            while (lo <= hi && g->frozen[w->pi[hi]] && g->frozen[w->pj[hi]])
                hi--;
            if (lo >= hi)
                break;
            int ti = w->pi[lo], tj = w->pj[lo];
            w->pi[lo] = w->pi[hi], w->pj[lo] = w->pj[hi];
            w->pi[hi] = ti, w->pj[hi] = tj;
        }
        na = lo;
    }
    w->n_active_pairs = na;
    /* history: every candidate pair is entered in the other table, its
     * spring carried over from the previous list when the pair was known */
    dem_hash *old = &w->hist[w->hist_cur], *nw = &w->hist[1 - w->hist_cur];
    const double *oval = w->hist_val[w->hist_cur];
    double *nval = w->hist_val[1 - w->hist_cur];
    if (dem_hash_reset(nw, w->n_pairs))
        return cm_fail(err, CM_ERR_NOMEM, "step %ld: out of memory for the contact history", w->step);
    for (int p = 0; p < w->n_pairs; p++) {
        uint64_t key = dem_pair_key(g->tag[w->pi[p]], g->tag[w->pj[p]]); /* tags survive removals */
        nw->row[dem_hash_insert(nw, key)] = p;
        int o = dem_hash_find(old, key);
        if (o >= 0)
            memcpy(nval + 3 * (size_t)p, oval + 3 * (size_t)old->row[o], 3 * sizeof(double));
        else
            nval[3 * p] = nval[3 * p + 1] = nval[3 * p + 2] = 0.0;
    }
    w->hist_cur = 1 - w->hist_cur;
    memcpy(g->x0, g->x, (size_t)g->n * sizeof(double));
    memcpy(g->y0, g->y, (size_t)g->n * sizeof(double));
    memcpy(g->z0, g->z, (size_t)g->n * sizeof(double));
    /* walls a grain can reach before the next rebuild: it moves at most
     * skin/2 until then, so a wall farther than r + skin stays out of reach */
    for (int i = 0; i < g->n; i++) {
        uint32_t near = 0;
        for (int k = 0; k < w->n_walls; k++) {
            const dem_wall *wl = &w->walls[k];
            double dist = (g->x[i] - wl->p[0]) * wl->n[0] + (g->y[i] - wl->p[1]) * wl->n[1] +
                          (g->z[i] - wl->p[2]) * wl->n[2];
            if (dist < g->r[i] + w->skin)
                near |= 1u << k;
        }
        g->wall_near[i] = near;
    }
    w->walls_near_valid = 1;
    w->rebuild_count++;
    w->prof.rebuilds++;
    w->need_rebuild = 0;
    return dem_pair_plan_build(w, err);
}

int dem_world_prepare(dem_world *w, cm_error *err)
{
    dem_grains *g = &w->g;
    w->r_min = INFINITY;
    w->r_max = 0.0;
    for (int i = 0; i < g->n; i++) {
        w->r_min = fmin(w->r_min, g->r[i]);
        w->r_max = fmax(w->r_max, g->r[i]);
    }
    if (g->n == 0)
        w->r_min = w->r_max = 1.0;
    w->skin = w->def.skin > 0.0 ? w->def.skin : 0.3 * w->r_min;
    if (w->wall_stride != w->n_walls) { /* walls added: new layout, springs restart */
        w->wall_stride = w->n_walls;
        memset(g->wall_hist, 0, (size_t)g->cap * DEM_MAX_WALLS * 3 * sizeof(double));
        memset(g->wall_mask, 0, (size_t)g->cap * sizeof *g->wall_mask);
    }
    int rc = dem_check_dt(w, err);
    if (rc == CM_OK)
        rc = dem_shaped_pose_alloc(w, err);
    if (rc)
        return rc;
    w->need_rebuild = 1;
    w->walls_near_valid = 0;
    w->plan.valid = 0; /* a checkpoint read after this replaces the pair list */
    w->prepared = 1;
    return CM_OK;
}
