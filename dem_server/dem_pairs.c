/* Stage "pairs" for spheres: the grain–grain narrow phase over the neighbour
 * list, each pair's force and torques added straight into its two grains.
 *
 * The order of the sums is the pair-list order: every grain receives its
 * pairs' contributions in ascending pair index p, whatever the number of
 * threads. One thread is the plain loop over p. With T threads the grains are
 * split into T blocks of slots, and a pair belongs to the block of its grain
 * i (the plan, built once per neighbour list):
 *   internal pairs (j in the same block) are computed and added by their
 *              block's thread in its walk;
 *   cross pairs (j in another block) are computed first, in parallel, into a
 *              small store (phase A); after a barrier each thread walks its
 *              own pairs and the cross pairs arriving at its grains as j,
 *              merged by p (phase B), so that each grain adds its
 *              contributions in ascending p, as the single loop does.
 * The result is bit-identical for any thread count; only the few pairs
 * across a block boundary are stored. */
#include <limits.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dem_world.h"
#include "vec3.h"

#ifdef _OPENMP
#include <omp.h>
#endif

/* The arrays the narrow phase reads, copied into a local struct so that
 * their pointers stay in registers. */
typedef struct pair_arrays {
    const double *x, *y, *z, *vx, *vy, *vz, *wx, *wy, *wz, *r, *inv_m, *inv_i;
    const int *mat, *pi, *pj;
    double *hist;
    dem_pair_coef (*coef)[DEM_MAX_MATERIALS];
    double dt;
} pair_arrays;

static pair_arrays pair_arrays_of(dem_world *w)
{
    const dem_grains *g = &w->g;
    pair_arrays a = {g->x,     g->y,   g->z,     g->vx,    g->vy,   g->vz,   g->wx,
                     g->wy,    g->wz,  g->r,     g->inv_m, g->inv_i, g->mat, w->pi,
                     w->pj,    w->hist_val[w->hist_cur],   w->coef,  w->def.dt};
    return a;
}

/* Grain–grain contact of pair p (slots i, j): the force on i and the torques
 * on i and j into out[DEM_PAIR_F]. Returns 1 in contact; out is not written
 * otherwise. */
static inline __attribute__((always_inline)) int pair_force(const pair_arrays *g, int p, double *restrict out)
{
    int i = g->pi[p], j = g->pj[p];
    double *xi = g->hist + 3 * (size_t)p;
    double ex = g->x[i] - g->x[j], ey = g->y[i] - g->y[j], ez = g->z[i] - g->z[j];
    double d2 = ex * ex + ey * ey + ez * ez, rs = g->r[i] + g->r[j];
    if (d2 >= rs * rs || d2 == 0.0) { /* coincident centres: no normal, skip */
        if (xi[0] != 0.0 || xi[1] != 0.0 || xi[2] != 0.0)
            xi[0] = xi[1] = xi[2] = 0.0;
        return 0;
    }
    double d = sqrt(d2);
    double delta = rs - d; /* eq. 18 */
    vec3 n = v3(ex / d, ey / d, ez / d); /* eq. 10: from j to i */
    /* levers to the contact point, the middle of the overlap (the paper's
     * eq. 11 is garbled; this is the usual choice) */
    double li = g->r[i] - 0.5 * delta, lj = g->r[j] - 0.5 * delta;
    vec3 wi = v3(g->wx[i], g->wy[i], g->wz[i]), wj = v3(g->wx[j], g->wy[j], g->wz[j]);
    /* eq. 12: v_i + w_i x d_i - (v_j + w_j x d_j), d_i = -li n, d_j = +lj n */
    vec3 vrel = v3_sub(v3(g->vx[i] - g->vx[j], g->vy[i] - g->vy[j], g->vz[i] - g->vz[j]),
                       v3_cross(v3_add(v3_scale(wi, li), v3_scale(wj, lj)), n));
    double R = g->r[i] * g->r[j] / rs;                        /* eq. 16 */
    double m = 1.0 / (g->inv_m[i] + g->inv_m[j]);             /* eq. 17 */
    const dem_pair_coef *cf = &g->coef[g->mat[i]][g->mat[j]];
    double fn;
    vec3 F = dem_hm_force(cf, n, delta, R, m, vrel, g->dt, xi, &fn);
    /* torques (eq. 7): d_i x F on i, d_j x (-F) on j; both are -l (n x F) */
    vec3 nxf = v3_cross(n, F);
    vec3 Ti = v3_scale(nxf, -li), Tj = v3_scale(nxf, -lj);
    if (cf->mu_roll > 0.0) {
        vec3 tr = dem_rolling_torque(cf, R, fn, v3_sub(wi, wj), 1.0 / (g->inv_i[i] + g->inv_i[j]), g->dt);
        Ti = v3_add(Ti, tr);
        Tj = v3_sub(Tj, tr);
    }
    out[0] = F.x, out[1] = F.y, out[2] = F.z;
    out[3] = Ti.x, out[4] = Ti.y, out[5] = Ti.z;
    out[6] = Tj.x, out[7] = Tj.y, out[8] = Tj.z;
    return 1;
}

int dem_pair_force(dem_world *w, int p, double out[DEM_PAIR_F])
{
    const pair_arrays a = pair_arrays_of(w);
    return pair_force(&a, p, out);
}

/* The grain arrays the sums go into. */
typedef struct force_sums {
    double *restrict fx, *restrict fy, *restrict fz, *restrict tx, *restrict ty, *restrict tz;
} force_sums;

static inline __attribute__((always_inline)) void add_i(const force_sums *s, int i, const double *f)
{
    s->fx[i] += f[0], s->fy[i] += f[1], s->fz[i] += f[2];
    s->tx[i] += f[3], s->ty[i] += f[4], s->tz[i] += f[5];
}

static inline __attribute__((always_inline)) void add_j(const force_sums *s, int j, const double *f)
{
    s->fx[j] -= f[0], s->fy[j] -= f[1], s->fz[j] -= f[2];
    s->tx[j] += f[6], s->ty[j] += f[7], s->tz[j] += f[8];
}

/* ---- the plan ---------------------------------------------------------- */

/* First slot of block t: blocks are [n t / T, n (t + 1) / T). */
static int block_lo(int t, int n, int nt) { return (int)((long)n * t / nt); }

static int grow_int(int **a, int *cap, int need)
{
    if (need <= *cap)
        return CM_OK;
    int c = *cap ? *cap : 1024;
    while (c < need)
        c *= 2;
    int *b = realloc(*a, (size_t)c * sizeof *b);
    if (!b)
        return CM_ERR_NOMEM;
    *a = b, *cap = c;
    return CM_OK;
}

/* Block of slot s: the t with block_lo(t) <= s < block_lo(t + 1). */
static int owner(int s, int n, int nt)
{
    int t = (int)((long)s * nt / n);
    while (t + 1 < nt && block_lo(t + 1, n, nt) <= s)
        t++;
    while (t > 0 && block_lo(t, n, nt) > s)
        t--;
    return t;
}

int dem_pair_plan_build(dem_world *w, cm_error *err)
{
    dem_pair_plan *pl = &w->plan;
    const int n = w->g.n, nt = w->n_threads, np = w->n_active_pairs;
    pl->valid = 0;
    if (nt == 1 || n == 0) { /* one thread: the plain loop, no plan needed */
        pl->valid = 1;
        return CM_OK;
    }
    int *cnt = pl->count; /* 3 * (nt + 1): own, cross, incoming per block */
    memset(cnt, 0, 3 * ((size_t)nt + 1) * sizeof *cnt);
    int n_cross = 0;
    for (int p = 0; p < np; p++) {
        int ti = owner(w->pi[p], n, nt), tj = owner(w->pj[p], n, nt);
        cnt[ti]++;
        if (ti != tj)
            n_cross++;
    }
    if (grow_int(&pl->own, &pl->own_cap, np) || grow_int(&pl->cross, &pl->cross_cap, n_cross) ||
        grow_int(&pl->in, &pl->in_cap, n_cross))
        return cm_fail(err, CM_ERR_NOMEM, "step %ld: out of memory for the pair plan (%d pairs)", w->step, np);
    if (n_cross > pl->cf_cap) {
        int c = pl->cf_cap ? pl->cf_cap : 256;
        while (c < n_cross)
            c *= 2;
        double *f = realloc(pl->cf, (size_t)c * DEM_PAIR_F * sizeof *f);
        if (f)
            pl->cf = f;
        unsigned char *on = realloc(pl->con, (size_t)c);
        if (on)
            pl->con = on;
        if (!f || !on)
            return cm_fail(err, CM_ERR_NOMEM, "step %ld: out of memory for the pair plan (%d cross pairs)", w->step,
                           n_cross);
        pl->cf_cap = c;
    }
    /* own lists: pairs grouped by block of i, ascending p inside */
    int *own_start = pl->own_start, *cross_start = pl->cross_start, *in_start = pl->in_start;
    own_start[0] = 0;
    for (int t = 0; t < nt; t++)
        own_start[t + 1] = own_start[t] + cnt[t];
    memset(cnt, 0, ((size_t)nt + 1) * sizeof *cnt); /* cursors */
    int *ccnt = cnt + nt + 1, *icnt = cnt + 2 * (nt + 1);
    for (int p = 0; p < np; p++) {
        int ti = owner(w->pi[p], n, nt), tj = owner(w->pj[p], n, nt);
        pl->own[own_start[ti] + cnt[ti]++] = p;
        if (ti != tj)
            ccnt[ti]++, icnt[tj]++;
    }
    cross_start[0] = in_start[0] = 0;
    for (int t = 0; t < nt; t++) {
        cross_start[t + 1] = cross_start[t] + ccnt[t];
        in_start[t + 1] = in_start[t] + icnt[t];
    }
    /* cross pairs grouped by the block of i; incoming lists by the block of
     * j; both in ascending p (the own lists are, and blocks are visited in
     * order for the incoming ones) */
    memset(ccnt, 0, 2 * ((size_t)nt + 1) * sizeof *ccnt);
    for (int t = 0; t < nt; t++)
        for (int k = own_start[t]; k < own_start[t + 1]; k++) {
            int p = pl->own[k];
            int tj = owner(w->pj[p], n, nt);
            if (tj != t)
                pl->cross[cross_start[t] + ccnt[t]++] = p;
        }
    /* incoming of block u: cross pairs of every block whose j is in u, by p:
     * a merge over the blocks' cross lists (each ascending) */
    {
        int *cursor = icnt; /* per block of i: next cross pair to look at */
        for (int t = 0; t < nt; t++)
            cursor[t] = cross_start[t];
        int *fill = ccnt; /* per block of j: next slot of its incoming list */
        for (int u = 0; u < nt; u++)
            fill[u] = in_start[u];
        for (;;) { /* repeatedly take the smallest p among the blocks' cross lists */
            int best = -1, bp = INT_MAX;
            for (int t = 0; t < nt; t++)
                if (cursor[t] < cross_start[t + 1] && pl->cross[cursor[t]] < bp)
                    bp = pl->cross[cursor[t]], best = t;
            if (best < 0)
                break;
            int c = cursor[best]++;
            pl->in[fill[owner(w->pj[bp], n, nt)]++] = c;
        }
    }
    pl->n_cross = n_cross;
    pl->valid = 1;
    return CM_OK;
}

/* ---- the stage --------------------------------------------------------- */

/* Phase B of block t (the whole stage for one thread): its own pairs and the
 * arriving cross pairs merged by p. Returns its contacts (own pairs). */
static int walk_block(const pair_arrays *in, const force_sums *s, const dem_pair_plan *pl, int t)
{
    const pair_arrays a = *in;
    const int *own = pl->own, *cross = pl->cross, *inc = pl->in;
    const int *pi = a.pi, *pj = a.pj;
    int k = pl->own_start[t], ke = pl->own_start[t + 1];
    int cc = pl->cross_start[t], ce = pl->cross_start[t + 1];
    int m = pl->in_start[t], me = pl->in_start[t + 1];
    int contacts = 0;
    double f[DEM_PAIR_F];
    while (k < ke || m < me) {
        int p_own = k < ke ? own[k] : INT_MAX;
        if (m < me && cross[inc[m]] < p_own) { /* a cross pair arriving at its j */
            int c = inc[m++];
            if (pl->con[c])
                add_j(s, pj[cross[c]], pl->cf + (size_t)DEM_PAIR_F * c);
            continue;
        }
        k++;
        if (cc < ce && cross[cc] == p_own) { /* own cross pair: computed in phase A */
            int c = cc++;
            if (pl->con[c]) {
                add_i(s, pi[p_own], pl->cf + (size_t)DEM_PAIR_F * c);
                contacts++;
            }
            continue;
        }
        if (pair_force(&a, p_own, f)) {
            add_i(s, pi[p_own], f);
            add_j(s, pj[p_own], f);
            contacts++;
        }
    }
    return contacts;
}

/* One thread: every pair in list order. */
static int pairs_serial(const pair_arrays *in, const force_sums *s, int np)
{
    const pair_arrays a = *in;
    int contacts = 0;
    double f[DEM_PAIR_F];
    for (int p = 0; p < np; p++)
        if (pair_force(&a, p, f)) {
            add_i(s, a.pi[p], f);
            add_j(s, a.pj[p], f);
            contacts++;
        }
    return contacts;
}

int dem_stage_pairs(dem_world *w)
{
    const int nt = w->n_threads;
    const pair_arrays a = pair_arrays_of(w);
    dem_grains *g = &w->g;
    const force_sums s = {g->fx, g->fy, g->fz, g->tx, g->ty, g->tz};
    if (nt == 1)
        return pairs_serial(&a, &s, w->n_active_pairs);
    const dem_pair_plan *pl = &w->plan;
    int contacts = 0;
#ifdef _OPENMP
#pragma omp parallel num_threads(nt) reduction(+ : contacts)
#endif
    {
#ifdef _OPENMP
        int t = omp_get_thread_num();
#else
        int t = 0;
#endif
        for (int c = pl->cross_start[t]; c < pl->cross_start[t + 1]; c++) /* phase A */
            pl->con[c] = (unsigned char)pair_force(&a, pl->cross[c], pl->cf + (size_t)DEM_PAIR_F * c);
#ifdef _OPENMP
#pragma omp barrier
#endif
        contacts += walk_block(&a, &s, pl, t);
    }
    return contacts;
}
