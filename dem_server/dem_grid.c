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

int dem_pairs_reserve(dem_world *w, int need)
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
        double *h = realloc(w->hist_val[k], (size_t)cap * w->hist_stride * sizeof *h);
        if (!h)
            return CM_ERR_NOMEM;
        w->hist_val[k] = h;
        unsigned char *o = realloc(w->hist_ori[k], (size_t)cap);
        if (!o)
            return CM_ERR_NOMEM;
        w->hist_ori[k] = o;
    }
    unsigned char *hd = realloc(w->held, (size_t)cap);
    if (!hd)
        return CM_ERR_NOMEM;
    w->held = hd;
    w->pair_cap = cap;
    return CM_OK;
}

/* Cell of coordinate v along axis k: cells sit on the lattice of multiples
 * of h (the box only says which ones exist), so that a grain's cell, and
 * with it the order of the grains, does not depend on where other grains
 * are: the same block of grains is ordered the same in any world. */
static inline int axis_cell(const dem_grid_dims *gd, int k, double v)
{
    /* in doubles (integers, exact below 2^53): a grain flung far away by an
     * unstable step still gets a cell, the nearest one */
    double c = floor(v / gd->h) - gd->base[k];
    return c >= 0.0 ? (c < gd->n[k] ? (int)c : gd->n[k] - 1) : 0;
}

static int cell_of(const dem_grid_dims *gd, double x, double y, double z)
{
    /* x slowest: x-slabs are slot ranges */
    return (axis_cell(gd, 0, x) * gd->n[1] + axis_cell(gd, 1, y)) * gd->n[2] + axis_cell(gd, 2, z);
}

int dem_grid_column(const dem_grid_dims *gd, double x) { return axis_cell(gd, 0, x); }

void dem_grid_dims_of(const double lo[3], const double hi[3], double h, long n_grains, dem_grid_dims *gd)
{
    long ncell;
    for (;;) {
        ncell = 1;
        for (int k = 0; k < 3; k++) {
            gd->base[k] = floor(lo[k] / h);
            gd->n[k] = (int)fmin(1e6, floor(hi[k] / h) - gd->base[k] + 1.0);
            ncell *= gd->n[k];
        }
        if (ncell <= 4L * n_grains + 64)
            break;
        h *= 1.5; /* a few grains far away: coarser cells rather than a huge grid */
    }
    gd->h = h;
}

/* Uniform grid over the grains' bounding box (a distributed world: the
 * global one, w->dist_grid), cell >= 2 r_max + skin, grains counting-sorted
 * by cell and by tag inside a cell. */
static int grid_build(dem_world *w, dem_grid_dims *gd)
{
    dem_grains *g = &w->g;
    if (w->dist) {
        *gd = w->dist_grid;
    } else {
        double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
        for (int i = 0; i < g->n; i++) {
            lo[0] = fmin(lo[0], g->x[i]), hi[0] = fmax(hi[0], g->x[i]);
            lo[1] = fmin(lo[1], g->y[i]), hi[1] = fmax(hi[1], g->y[i]);
            lo[2] = fmin(lo[2], g->z[i]), hi[2] = fmax(hi[2], g->z[i]);
        }
        dem_grid_dims_of(lo, hi, 2.0 * w->r_max + w->skin, g->n, gd);
    }
    long ncell = (long)gd->n[0] * gd->n[1] * gd->n[2];
    if (ncell + 1 > w->cell_cap) { /* grows only when the grains spread out */
        int *a = realloc(w->cell_start, (size_t)(ncell + 1) * sizeof *a);
        if (!a)
            return CM_ERR_NOMEM;
        w->cell_start = a;
        a = realloc(w->cell_pos, (size_t)(ncell + 1) * sizeof *a);
        if (!a)
            return CM_ERR_NOMEM;
        w->cell_pos = a;
        double *m = realloc(w->cell_rmax, (size_t)(ncell + 1) * sizeof *m);
        if (!m)
            return CM_ERR_NOMEM;
        w->cell_rmax = m;
        w->cell_cap = (int)(ncell + 1);
    }
    if (!w->cell_items) { /* once */
        w->cell_items = malloc((size_t)g->cap * sizeof *w->cell_items);
        if (!w->cell_items)
            return CM_ERR_NOMEM;
    }
    memset(w->cell_start, 0, (size_t)(ncell + 1) * sizeof *w->cell_start);
    memset(w->cell_rmax, 0, (size_t)ncell * sizeof *w->cell_rmax);
    for (int i = 0; i < g->n; i++) {
        const int c = cell_of(gd, g->x[i], g->y[i], g->z[i]);
        w->grain_cell[i] = c;
        w->cell_start[c + 1]++;
        w->cell_rmax[c] = fmax(w->cell_rmax[c], g->r[i]);
    }
    for (long c = 0; c < ncell; c++)
        w->cell_start[c + 1] += w->cell_start[c];
    int *pos = w->cell_pos; /* stable counting sort */
    memcpy(pos, w->cell_start, (size_t)(ncell + 1) * sizeof *pos);
    for (int i = 0; i < g->n; i++)
        w->cell_items[pos[w->grain_cell[i]]++] = i;
    /* inside a cell by tag (insertion sort: a cell holds a few grains), so
     * that the order of the grains is a function of the global state alone
     * (positions and tags), not of their previous slots: every rank of a
     * distributed run then holds its grains in the global order */
    const int *tag = g->tag;
    for (long c = 0; c < ncell; c++) {
        int *it = w->cell_items;
        for (int k = w->cell_start[c] + 1; k < w->cell_start[c + 1]; k++) {
            int v = it[k], tv = tag[v], m = k;
            while (m > w->cell_start[c] && tag[it[m - 1]] > tv) {
                it[m] = it[m - 1];
                m--;
            }
            it[m] = v;
        }
    }
    return CM_OK;
}

void dem_hist_orient(dem_world *w)
{
    const int *tag = w->g.tag;
    for (int p = 0; p < w->n_pairs; p++)
        w->hist_ori[w->hist_cur][p] = tag[w->pi[p]] < tag[w->pj[p]];
}

/* What carry_spring reads and writes, taken out of the world once (its
 * stores could otherwise alias every field it reads). */
typedef struct spring_carry {
    const int *tag, *pi, *pj;
    int hs;
    const dem_hash *old, *extra;
    const double *oval, *extra_val;
    const unsigned char *oori;
    double *nval;
    unsigned char *nori;
} spring_carry;

static spring_carry spring_carry_of(const dem_world *w)
{
    const int c = w->hist_cur;
    return (spring_carry){w->g.tag,      w->pi,          w->pj,           w->hist_stride,   &w->hist[c],
                          w->hist_extra, w->hist_val[c], w->hist_extra_val, w->hist_ori[c], w->hist_val[1 - c],
                          w->hist_ori[1 - c]};
}

/* The history key of pair p of the new list. */
static inline uint64_t pair_key_at(const spring_carry *c, int p)
{
    return dem_pair_key(c->tag[c->pi[p]], c->tag[c->pj[p]]);
}

/* Pair p of the new list (its key already in the other table): its spring
 * from the previous list (by tags, which survive removals and re-sorts) or
 * from the springs received with migrated grains, else zero; sign flipped
 * where the pair's grains come in the other order. */
static inline void carry_spring(const spring_carry *c, int p)
{
    const int hs = c->hs, ti = c->tag[c->pi[p]], tj = c->tag[c->pj[p]];
    const uint64_t key = dem_pair_key(ti, tj);
    int o = dem_hash_find(c->old, key), flip = 0;
    double *xi = c->nval + (size_t)hs * p;
    if (o >= 0) {
        int r = c->old->row[o];
        memcpy(xi, c->oval + (size_t)hs * r, (size_t)hs * sizeof(double));
        flip = c->oori[r] != (ti < tj); /* a re-sort swapped i and j */
    } else if (c->extra && (o = dem_hash_find(c->extra, key)) >= 0) {
        memcpy(xi, c->extra_val + (size_t)hs * c->extra->row[o], (size_t)hs * sizeof(double));
        flip = ti > tj; /* received lower tag first */
    } else {
        memset(xi, 0, (size_t)hs * sizeof(double));
    }
    if (flip)
        for (int k = 0; k < hs; k++)
            xi[k] = -xi[k];
    c->nori[p] = ti < tj;
}

/* How many pairs ahead the history carry asks for the tables' slots
 * (dem_hash_prefetch). The inserts and lookups go to random slots of tables
 * larger than the caches (12 bytes a slot, two slots a pair: 6 MB for a
 * paper rank's 140 000 candidates); each waited for the memory, ~90 % of
 * their time (perf annotate). Asked for ahead, their share of bench_dem's
 * stirred run fell from 4-5 % to under 1 %, the same bits (session 28). */
enum { HASH_AHEAD = 16 };

/* Makes room for `more` pairs past n in the thread's destination (the list
 * for the first rows' thread, else tb->rows). Returns 0, -1 when out of
 * memory. */
static int rows_room(dem_world *w, dem_thread_buf *tb, int to_list, long n, long more)
{
    if (to_list) {
        if (n + more <= w->pair_cap)
            return 0;
        return n + more >= INT_MAX || dem_pairs_reserve(w, (int)(n + more)) ? -1 : 0;
    }
    if (n + more <= tb->rows_cap)
        return 0;
    long c2 = tb->rows_cap ? 2 * tb->rows_cap : 4096;
    while (c2 < n + more)
        c2 *= 2;
    int *b = realloc(tb->rows, (size_t)c2 * 2 * sizeof *b);
    if (!b)
        return -1;
    tb->rows = b, tb->rows_cap = c2;
    return 0;
}

/* The search's reach. Grain j can be a candidate of grain i only within
 * r_i + r_j + skin of it, so a neighbour cell farther from i than
 * r_i + skin + (the cell's largest radius) holds none: in a bed of fine
 * grains over coarse ones (cells sized by the coarse), most of the 27 cells
 * around a fine grain. Testing the cells pays only for grains well smaller
 * than the cells (reach_prunes); in a bed of one size it would cost more
 * than it saves. gap2 gets the squared distance of coordinate v (in cell c
 * along axis k) to the cells c - 1, c, c + 1 along that axis (0 inside, or
 * where v lies past the face: a grain clamped into an edge cell). The faces
 * are computed as axis_cell places grains, with a margin of 1e-6 cells for
 * their rounding: a cell left out holds no candidate, and the lists are
 * those of the whole 27-cell walk, pair for pair. */
static inline void axis_gap2(const dem_grid_dims *gd, int k, int c, double v, double gap2[3])
{
    const double below = v - (c + gd->base[k]) * gd->h, above = (c + 1 + gd->base[k]) * gd->h - v;
    gap2[0] = below > 0.0 ? below * below : 0.0;
    gap2[1] = 0.0;
    gap2[2] = above > 0.0 ? above * above : 0.0;
}

/* 1 if the cells are worth testing for grain i (ri_skin = r_i + skin): its
 * reach against the largest grain is under 0.9 of a cell. */
static inline int reach_prunes(const dem_world *w, const dem_grid_dims *gd, double ri_skin)
{
    return ri_skin + w->r_max < 0.9 * gd->h;
}

/* 1 if cell cc, at squared distance d2 from grain i, can hold a candidate
 * of i. */
static inline int cell_in_reach(const dem_world *w, const dem_grid_dims *gd, long cc, double d2, double ri_skin)
{
    const double reach = ri_skin + w->cell_rmax[cc] + 1e-6 * gd->h;
    return d2 < reach * reach;
}

/* The candidate pairs of rows [i0, i1): each grain's neighbours in the 27
 * cells around it (those in reach), within r_i + r_j + skin, later in the
 * grain order (a left ghost pairs with owned grains only), partners in a
 * fixed cell order. The first rows' thread (to_list) writes them into the
 * pair list itself, the others into tb->rows; both grow as needed. Returns
 * the count, -1 when out of memory; *n_cross counts the pairs with a ghost. */
static long search_rows(dem_world *w, const dem_grid_dims *gd, int i0, int i1, dem_thread_buf *tb, int to_list,
                        long *n_cross)
{
    const dem_grains *g = &w->g;
    const int own_lo = w->own_lo, own_hi = w->own_hi;
    const double *x = g->x, *y = g->y, *z = g->z, *r = g->r;
    const int *cell_start = w->cell_start, *cell_items = w->cell_items;
    const double skin = w->skin;
    long n = 0;
    for (int i = i0; i < i1; i++) {
        const int jmin = i < own_lo ? own_lo - 1 : i;
        int c = w->grain_cell[i];
        int cz = c % gd->n[2], cy = (c / gd->n[2]) % gd->n[1], cx = c / (gd->n[2] * gd->n[1]);
        double ri = r[i] + skin, gx2[3], gy2[3], gz2[3];
        const int prune = reach_prunes(w, gd, ri);
        axis_gap2(gd, 0, cx, x[i], gx2), axis_gap2(gd, 1, cy, y[i], gy2), axis_gap2(gd, 2, cz, z[i], gz2);
        for (int dx = -1; dx <= 1; dx++) {
            int ix = cx + dx;
            if (ix < 0 || ix >= gd->n[0])
                continue;
            for (int dy = -1; dy <= 1; dy++) {
                int iy = cy + dy;
                if (iy < 0 || iy >= gd->n[1])
                    continue;
                for (int dz = -1; dz <= 1; dz++) {
                    int iz = cz + dz;
                    if (iz < 0 || iz >= gd->n[2])
                        continue;
                    int cc = (ix * gd->n[1] + iy) * gd->n[2] + iz;
                    if (prune && !cell_in_reach(w, gd, cc, gx2[dx + 1] + gy2[dy + 1] + gz2[dz + 1], ri))
                        continue;
                    for (int k = cell_start[cc]; k < cell_start[cc + 1]; k++) {
                        int j = cell_items[k];
                        if (j <= jmin)
                            continue;
                        double ex = x[i] - x[j], ey = y[i] - y[j], ez = z[i] - z[j];
                        double cut = ri + r[j];
                        if (ex * ex + ey * ey + ez * ez >= cut * cut)
                            continue;
                        if (rows_room(w, tb, to_list, n, 1)) /* grows at rebuilds only, rarely after the first */
                            return -1;
                        if (to_list)
                            w->pi[n] = i, w->pj[n] = j;
                        else
                            tb->rows[2 * n] = i, tb->rows[2 * n + 1] = j;
                        n++;
                        *n_cross += i < own_lo || j >= own_hi;
                    }
                }
            }
        }
    }
    return n;
}

/* Row i's partners to test and where they go (search_rows_sorted). */
typedef struct scan_row {
    const double *restrict x, *restrict y, *restrict z, *restrict r;
    double xi, yi, zi, ri; /* ri: r_i + skin */
    int i, left, own_hi;   /* left: i is a left ghost */
} scan_row;

/* The slots k0 .. k1 - 1 tested as partners of row s->i, from the n-th
 * pair on: every slot is written, and the count advanced by the test (no
 * branch on it). Returns the new count, -1 when out of memory. */
static inline __attribute__((always_inline)) long scan_slots(dem_world *w, dem_thread_buf *tb, int to_list,
                                                              const scan_row *s, long n, int k0, int k1, long *nc)
{
    if (rows_room(w, tb, to_list, n, k1 - k0))
        return -1;
    int *di = to_list ? w->pi : tb->rows, *dj = to_list ? w->pj : tb->rows + 1;
    const long st = to_list ? 1 : 2;
    long c = 0;
    for (int j = k0; j < k1; j++) {
        const double ex = s->xi - s->x[j], ey = s->yi - s->y[j], ez = s->zi - s->z[j];
        const double cut = s->ri + s->r[j];
        const int hit = !(ex * ex + ey * ey + ez * ez >= cut * cut);
        di[st * n] = s->i, dj[st * n] = j;
        c += hit & (s->left | (j >= s->own_hi));
        n += hit;
    }
    *nc += c;
    return n;
}

/* search_rows for grains sorted by cell (slot order is cell order, z
 * fastest): the cells cz - 1 .. cz + 1 of a column (dx, dy), less those out
 * of reach at either end where the reach prunes, are one range of slots, in
 * the order the 27-cell walk takes them, so nine ranges give the same pairs
 * in the same order; slots up to jmin are cut off each range's front. */
static long search_rows_sorted(dem_world *w, const dem_grid_dims *gd, int i0, int i1, dem_thread_buf *tb,
                               int to_list, long *n_cross)
{
    const dem_grains *g = &w->g;
    const int own_lo = w->own_lo;
    const int *cell_start = w->cell_start;
    const int n0 = gd->n[0], n1 = gd->n[1], n2 = gd->n[2];
    scan_row s = {.x = g->x, .y = g->y, .z = g->z, .r = g->r, .own_hi = w->own_hi};
    long n = 0, nc = 0;
    for (int i = i0; i < i1; i++) {
        const int jmin = i < own_lo ? own_lo - 1 : i;
        const int c = w->grain_cell[i];
        const int cz = c % n2, cy = (c / n2) % n1, cx = c / (n2 * n1);
        const int z0 = cz > 0 ? cz - 1 : 0, z1 = cz + 1 < n2 ? cz + 1 : n2 - 1;
        const int ix0 = cx > 0 ? cx - 1 : 0, ix1 = cx + 1 < n0 ? cx + 1 : n0 - 1;
        const int iy0 = cy > 0 ? cy - 1 : 0, iy1 = cy + 1 < n1 ? cy + 1 : n1 - 1;
        s.xi = g->x[i], s.yi = g->y[i], s.zi = g->z[i], s.ri = g->r[i] + w->skin;
        s.i = i, s.left = i < own_lo;
        /* two loops, not one with the trimming under `if`: merged, the
         * search of a bed of one size ran 17 % more instructions (bench_dem
         * stirred, callgrind, session 27) */
        if (!reach_prunes(w, gd, s.ri)) {
            for (int ix = ix0; ix <= ix1; ix++)
                for (int iy = iy0; iy <= iy1; iy++) {
                    const int col = (ix * n1 + iy) * n2;
                    const int k0 = cell_start[col + z0] > jmin ? cell_start[col + z0] : jmin + 1;
                    const int k1 = cell_start[col + z1 + 1];
                    if (k0 < k1 && (n = scan_slots(w, tb, to_list, &s, n, k0, k1, &nc)) < 0)
                        return -1;
                }
            continue;
        }
        double gx2[3], gy2[3], gz2[3];
        axis_gap2(gd, 0, cx, s.xi, gx2), axis_gap2(gd, 1, cy, s.yi, gy2), axis_gap2(gd, 2, cz, s.zi, gz2);
        for (int ix = ix0; ix <= ix1; ix++)
            for (int iy = iy0; iy <= iy1; iy++) {
                const int col = (ix * n1 + iy) * n2;
                const double dxy2 = gx2[ix - cx + 1] + gy2[iy - cy + 1];
                int za = z0, zb = z1; /* a middle cell out of reach between two in reach is tested whole */
                while (za <= zb && !cell_in_reach(w, gd, col + za, dxy2 + gz2[za - cz + 1], s.ri))
                    za++;
                while (zb > za && !cell_in_reach(w, gd, col + zb, dxy2 + gz2[zb - cz + 1], s.ri))
                    zb--;
                if (za > zb)
                    continue;
                const int k0 = cell_start[col + za] > jmin ? cell_start[col + za] : jmin + 1;
                const int k1 = cell_start[col + zb + 1];
                if (k0 < k1 && (n = scan_slots(w, tb, to_list, &s, n, k0, k1, &nc)) < 0)
                    return -1;
            }
    }
    *n_cross += nc;
    return n;
}

int dem_neighbour_rebuild(dem_world *w, cm_error *err)
{
    dem_grains *g = &w->g;
    dem_grid_dims gd;
    if (grid_build(w, &gd))
        return cm_fail(err, CM_ERR_NOMEM, "step %ld: out of memory building the cell grid", w->step);
    int sorted = 0; /* grains re-sorted: slot order is cell order */
    if (w->def.reorder_every > 0 && w->rebuild_count % w->def.reorder_every == 0 && g->n > 1) {
        sorted = 1;
        /* re-sort grains by cell (cell_items is that order) for memory locality */
        dem_grains_permute(w, w->cell_items);
        /* the grid of the sorted grains: cell k's grains are now slots
         * cell_start[k] .. in order (cell_starts unchanged) */
        for (long c = 0, ncell = (long)gd.n[0] * gd.n[1] * gd.n[2]; c < ncell; c++)
            for (int k = w->cell_start[c]; k < w->cell_start[c + 1]; k++)
                w->grain_cell[k] = (int)c, w->cell_items[k] = k;
    }
    /* A distributed world: only pairs with an owned grain (a left ghost
     * pairs with owned grains only, the right ghosts come last and start no
     * row). Either way the list is the global list restricted to this rank:
     * rows in the global grain order, partners in a fixed cell order. */
    if (!w->dist)
        w->own_lo = 0, w->own_hi = g->n;
    const int own_hi = w->own_hi;
    /* each thread walks a contiguous range of rows, the first into the
     * list, the others into their buffers, appended in thread order: the
     * one-thread list (a small world is searched by one thread) */
    const int t_n = own_hi >= 4096 ? w->n_threads : 1;
    long n_cross = 0;
    int nomem = 0;
#ifdef _OPENMP
#pragma omp parallel num_threads(t_n) if (t_n > 1) reduction(+ : n_cross) reduction(| : nomem)
#endif
    {
        const int t = dem_thread_id();
        dem_thread_buf *tb = &w->tb[t];
        const int i0 = (int)((long)own_hi * t / t_n), i1 = (int)((long)own_hi * (t + 1) / t_n);
        long n = sorted ? search_rows_sorted(w, &gd, i0, i1, tb, t == 0, &n_cross)
                        : search_rows(w, &gd, i0, i1, tb, t == 0, &n_cross);
        nomem |= n < 0;
        tb->rows_n = n < 0 ? 0 : n;
    }
    long total = 0;
    for (int t = 0; t < t_n; t++)
        total += w->tb[t].rows_n;
    if (nomem || total > INT_MAX || dem_pairs_reserve(w, (int)total))
        return cm_fail(err, CM_ERR_NOMEM, "step %ld: out of memory for %ld pairs", w->step, total);
    w->n_pairs = (int)w->tb[0].rows_n;
    for (int t = 1; t < t_n; t++) {
        const int *b = w->tb[t].rows;
        for (long k = 0; k < w->tb[t].rows_n; k++, w->n_pairs++)
            w->pi[w->n_pairs] = b[2 * k], w->pj[w->n_pairs] = b[2 * k + 1];
    }
    /* frozen-frozen pairs to the end of the list: the narrow phase stops at
     * n_active_pairs, their springs stay in the history untouched */
    int na = w->n_pairs;
    if (w->n_frozen > 0) {
        /* stable partition (the active pairs keep their order, a function of
         * the global state); the frozen ones wait in the next history's
         * array, free until it is filled below */
        int *tmp = (int *)w->hist_val[1 - w->hist_cur], nf = 0;
        na = 0;
        for (int p = 0; p < w->n_pairs; p++) {
            int i = w->pi[p], j = w->pj[p];
            if (g->frozen[i] && g->frozen[j])
                tmp[2 * nf] = i, tmp[2 * nf + 1] = j, nf++;
            else
                w->pi[na] = i, w->pj[na] = j, na++;
        }
        for (int k = 0; k < nf; k++)
            w->pi[na + k] = tmp[2 * k], w->pj[na + k] = tmp[2 * k + 1];
    }
    w->n_active_pairs = na;
    w->n_cross_pairs = n_cross;
    /* history: every candidate pair is entered in the other table, its
     * spring carried over from the previous list when the pair was known */
    dem_hash *nw = &w->hist[1 - w->hist_cur];
    if (dem_hash_reset(nw, w->n_pairs))
        return cm_fail(err, CM_ERR_NOMEM, "step %ld: out of memory for the contact history", w->step);
    const int np = w->n_pairs;
    const spring_carry sc = spring_carry_of(w);
    /* the table in pair order, by one thread; the springs (lookups in the
     * previous table only, any order) with it on one thread, else by the
     * other threads meanwhile, in chunks taken as they come, thread 0
     * joining them when the table is done */
    if (t_n == 1) {
        for (int p = 0; p < np; p++) {
            if (p + HASH_AHEAD < np) {
                const uint64_t ka = pair_key_at(&sc, p + HASH_AHEAD);
                dem_hash_prefetch(nw, ka);
                dem_hash_prefetch(sc.old, ka);
            }
            nw->row[dem_hash_insert(nw, pair_key_at(&sc, p))] = p;
            carry_spring(&sc, p);
        }
    } else {
#ifdef _OPENMP
#pragma omp parallel num_threads(t_n)
#endif
        {
            if (dem_thread_id() == 0)
                for (int p = 0; p < np; p++) {
                    if (p + HASH_AHEAD < np)
                        dem_hash_prefetch(nw, pair_key_at(&sc, p + HASH_AHEAD));
                    nw->row[dem_hash_insert(nw, pair_key_at(&sc, p))] = p;
                }
#ifdef _OPENMP
#pragma omp for schedule(dynamic, 2048)
#endif
            for (int p = 0; p < np; p++) {
                if (p + HASH_AHEAD < np)
                    dem_hash_prefetch(sc.old, pair_key_at(&sc, p + HASH_AHEAD));
                carry_spring(&sc, p);
            }
        }
    }
    w->hist_cur = 1 - w->hist_cur;
    memcpy(g->x0, g->x, (size_t)g->n * sizeof(double));
    memcpy(g->y0, g->y, (size_t)g->n * sizeof(double));
    memcpy(g->z0, g->z, (size_t)g->n * sizeof(double));
    /* walls a grain can reach before the next rebuild: it moves at most
     * skin/2 until then, so a wall farther than r + skin stays out of reach */
#ifdef _OPENMP
#pragma omp parallel for num_threads(t_n) if (t_n > 1) schedule(static)
#endif
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
    /* the grains the walls stage visits until the next rebuild: a grain
     * with neither a wall near nor a wall spring gains neither before it */
    int nl = 0;
    for (int i = 0; i < g->n; i++)
        if (g->wall_near[i] | g->wall_mask[i])
            w->wall_list[nl++] = i;
    w->n_wall_list = nl;
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
        memset(g->wall_hist, 0, (size_t)g->cap * DEM_MAX_WALLS * w->hist_stride * sizeof(double));
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
