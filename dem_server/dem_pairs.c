/* Stage "pairs" for spheres: the grain–grain narrow phase over the neighbour
 * list, each pair's force and torques added straight into its two grains.
 *
 * The order of the sums is the pair-list order: every grain receives its
 * pairs' contributions in ascending pair index p, whatever the number of
 * threads. One thread is the plain loop over p. With T threads the grains are
 * split into T blocks of slots with about equal numbers of pairs, and a pair
 * belongs to the block of its grain i (the plan, built once per neighbour
 * list):
 *   internal pairs (j in the same block) are computed and added by their
 *              block's thread in its walk;
 *   cross pairs (j in another block) are computed first, in parallel (the
 *              list shared out in equal parts) and batched, into a small
 *              store (phase A); after a barrier each
 *              thread walks its own pairs, its cross pairs taking their
 *              places in its batches, and the cross pairs arriving at its
 *              grains as j, merged by p (phase B), so that each grain adds
 *              its contributions in ascending p, as the single loop does.
 * The result is bit-identical for any thread count; only the few pairs
 * across a block boundary are stored. The list holds rows in slot order, so
 * a block's own pairs are a contiguous range of p. A thread takes its own
 * blocks first, then any left (block_claim; DEM_PLAN_BLOCKS_PER_THREAD,
 * dem_world.h, says how many there are). */
#include <limits.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#endif

#include "dem_world.h"
#include "vec3.h"

/* The arrays the narrow phase reads, copied into a local struct so that
 * their pointers stay in registers. */
typedef struct pair_arrays {
    const double *x, *y, *z, *vx, *vy, *vz, *wx, *wy, *wz, *r, *inv_m, *inv_i;
    const int *mat, *pi, *pj;
    double *hist;       /* hs per pair (dem_world.hist_stride) */
    unsigned char *held; /* per pair: its row holds something (dem_world.held) */
    dem_pair_coef (*coef)[DEM_MAX_MATERIALS];
    double dt;
    int roll_spring;    /* DEM_ROLLING_SPRING: history rows of DEM_HIST_MAX, the rolling rotation at + 3 */
    int one_c;          /* every grain of one material: the pairs' coefficient index (dem_pair_plan.one_c), else -1 */
    int avx2;           /* the candidates' test in its AVX2 build (dem_kernels_of at least DEM_KERNELS_AVX2) */
} pair_arrays;

static pair_arrays pair_arrays_of(dem_world *w)
{
    const dem_grains *g = &w->g;
    pair_arrays a = {g->x,     g->y,   g->z,     g->vx,    g->vy,   g->vz,   g->wx,
                     g->wy,    g->wz,  g->r,     g->inv_m, g->inv_i, g->mat, w->pi,
                     w->pj,    w->hist_val[w->hist_cur],   w->held,  w->coef,  w->def.dt,
                     w->def.rolling_model == DEM_ROLLING_SPRING, w->plan.one_c,
                     dem_kernels_of(&w->def) >= DEM_KERNELS_AVX2};
    return a;
}

/* 1 if a spring row of hs values holds one other than ±0: from the bits
 * without the sign, no floating-point compares. */
static inline int row_held(const double *xi, const int hs)
{
    uint64_t u = 0;
    for (int k = 0; k < hs; k++) {
        uint64_t b;
        memcpy(&b, xi + k, sizeof b);
        u |= b << 1;
    }
    return u != 0;
}

/* Pair p has come apart: its spring row of hs values and its held flag
 * cleared (rare; the candidates' tests call it). */
static inline void spring_clear(const pair_arrays *a, int p, int hs)
{
    memset(a->hist + (size_t)hs * p, 0, (size_t)hs * sizeof(double));
    a->held[p] = 0;
}

/* Grain–grain contact of pair p (slots i, j): the force on i and the torques
 * on i and j into out[DEM_PAIR_F]. Returns 1 in contact; out is not written
 * otherwise. */
static inline __attribute__((always_inline)) int pair_force(const pair_arrays *g, int p, double *restrict out)
{
    int i = g->pi[p], j = g->pj[p];
    const int hs = g->roll_spring ? DEM_HIST_MAX : DEM_HIST_TANGENTIAL;
    double *xi = g->hist + (size_t)hs * p;
    double ex = g->x[i] - g->x[j], ey = g->y[i] - g->y[j], ez = g->z[i] - g->z[j];
    double d2 = ex * ex + ey * ey + ez * ez, rs = g->r[i] + g->r[j];
    if (d2 >= rs * rs || d2 == 0.0) { /* coincident centres: no normal, skip */
        int held = 0;
        for (int k = 0; k < hs; k++)
            held |= xi[k] != 0.0;
        if (held)
            memset(xi, 0, (size_t)hs * sizeof *xi);
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
        const double i_r = DEM_SPHERE_ROLL_INERTIA / (g->inv_i[i] + g->inv_i[j]);
        vec3 tr = g->roll_spring
                      ? dem_rolling_spring(cf, R, delta, fn, v3_sub(wi, wj), i_r, g->dt, xi + DEM_HIST_TANGENTIAL)
                      : dem_rolling_torque(cf, R, fn, v3_sub(wi, wj), 1.0 / (g->inv_i[i] + g->inv_i[j]), g->dt);
        Ti = v3_add(Ti, tr);
        Tj = v3_sub(Tj, tr);
    }
    out[0] = F.x, out[1] = F.y, out[2] = F.z;
    out[3] = Ti.x, out[4] = Ti.y, out[5] = Ti.z;
    out[6] = Tj.x, out[7] = Tj.y, out[8] = Tj.z;
    return 1;
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

/* Block of slot s: the t with lo[t] <= s < lo[t + 1] (a few blocks). */
static int owner(const int *lo, int s, int nt)
{
    int t = 0;
    while (t + 1 < nt && lo[t + 1] <= s)
        t++;
    return t;
}

int dem_pair_plan_build(dem_world *w, cm_error *err)
{
    dem_pair_plan *pl = &w->plan;
    const int n = w->g.n, np = w->n_active_pairs;
    const int nt = w->n_threads == 1 ? 1 : DEM_PLAN_BLOCKS_PER_THREAD * w->n_threads; /* blocks */
    const int *pi = w->pi, *pj = w->pj;
    pl->valid = 0;
    pl->n_blocks = nt;
    /* one grain material (a bed of one soil: always), so that the stage
     * need not look up each pair's */
    const int *mat = w->g.mat;
    int one = n > 0;
    for (int i = 1; i < n && one; i++)
        one = mat[i] == mat[0];
    pl->one_c = one ? mat[0] * DEM_MAX_MATERIALS + mat[0] : -1;
    /* which springs hold something, for the candidates' test (the list or
     * its rows changed) */
    const double *hv = w->hist_val[w->hist_cur];
    for (int p = 0; p < np; p++)
        w->held[p] = (unsigned char)row_held(hv + (size_t)w->hist_stride * p, w->hist_stride);
    if (nt == 1 || n == 0) { /* one thread: the plain loop, no plan needed */
        pl->valid = 1;
        return CM_OK;
    }
    /* The list holds rows in slot order (i ascending, every j > i:
     * dem_grid.c), so a block's own pairs are the range of p whose i lies
     * in it, and a pair's j lies in its own block or a later one. */
    /* Blocks of about equal numbers of pairs (the stage's work), each a
     * range of slots: lo[t] is the slot of the row where pair np t / T falls.
     * (Equal numbers of grains left the first block 4 % more pairs and 10 %
     * more time on bench_dem's bed.) */
    int *lo = pl->slot_lo;
    lo[0] = 0, lo[nt] = n;
    for (int t = 1; t < nt; t++) {
        const long k = (long)np * t / nt;
        lo[t] = np == 0 ? (int)((long)n * t / nt) : pi[k < np ? k : np - 1];
        if (lo[t] < lo[t - 1])
            lo[t] = lo[t - 1];
    }
    int *own_start = pl->own_start, *cross_start = pl->cross_start, *in_start = pl->in_start;
    int *cnt = pl->count; /* 3 * (nt + 1): cross and incoming per block, then cursors */
    memset(cnt, 0, 3 * ((size_t)nt + 1) * sizeof *cnt);
    int *ccnt = cnt, *icnt = cnt + nt + 1;
    int n_cross = 0;
    for (int t = 0, p = 0; t < nt; t++) {
        own_start[t] = p;
        const int hi = lo[t + 1];
        for (; p < np && pi[p] < hi; p++) {
            const int tj = pj[p] < hi ? t : owner(lo, pj[p], nt);
            if (tj != t)
                ccnt[t]++, icnt[tj]++, n_cross++;
        }
        own_start[t + 1] = p;
    }
    if (dem_grow_ints(&pl->cross, &pl->cross_cap, n_cross) || dem_grow_ints(&pl->in, &pl->in_cap, n_cross))
        return cm_fail(err, CM_ERR_NOMEM, "step %ld: out of memory for the pair plan (%d cross pairs)", w->step,
                       n_cross);
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
    cross_start[0] = in_start[0] = 0;
    for (int t = 0; t < nt; t++) {
        cross_start[t + 1] = cross_start[t] + ccnt[t];
        in_start[t + 1] = in_start[t] + icnt[t];
    }
    /* cross pairs grouped by the block of i, ascending p; the incoming list
     * of block u: those whose j it holds, ascending p too (they are taken in
     * ascending p) */
    int *fill = cnt + 2 * (nt + 1); /* per block of j: next slot of its incoming list */
    memcpy(fill, in_start, (size_t)nt * sizeof *fill);
    for (int t = 0, c = 0; t < nt; t++) {
        const int hi = lo[t + 1];
        for (int p = own_start[t]; p < own_start[t + 1]; p++)
            if (pj[p] >= hi) {
                pl->cross[c] = p;
                pl->in[fill[owner(lo, pj[p], nt)]++] = c;
                c++;
            }
    }
    pl->n_cross = n_cross;
    pl->valid = 1;
    return CM_OK;
}

/* ---- the batched kernel ------------------------------------------------
 *
 * The same arithmetic as pair_force, in the same order, for a batch of
 * pairs in contact: one loop the compiler vectorises, compiled for the
 * x86-64 baseline (SSE2, two lanes), for AVX2 (four lanes) and, with the
 * rolling spring, for AVX-512 (eight lanes), the widest chosen at start-up
 * (dem_kernels_of). Every lane does IEEE operations on its own pair,
 * branches become selects of values computed both ways, and
 * -ffp-contract=off forbids fused multiply-adds (the targets "avx2" and
 * "avx512f" do not enable FMA), so the bits are those of pair_force on any
 * CPU: test_dem_threads runs the scalar, portable, AVX2 and AVX-512 paths
 * against each other. Rolling resistance is built in only when some
 * material pair has it: the constant torque (dem_rolling_torque) in the
 * loop, the spring (dem_rolling_spring) in a second loop after it. */
enum { BATCH = 64 };

typedef struct pair_batch {
    int n;
    int p[BATCH], i[BATCH], j[BATCH], c[BATCH];
    double ex[BATCH], ey[BATCH], ez[BATCH], d2[BATCH];
    /* out: force on i, torques on i and j, the new spring; R and |F_n| for
     * the rolling torque */
    double fx[BATCH], fy[BATCH], fz[BATCH];
    double tix[BATCH], tiy[BATCH], tiz[BATCH], tjx[BATCH], tjy[BATCH], tjz[BATCH];
    double sx[BATCH], sy[BATCH], sz[BATCH];
    double ux[BATCH], uy[BATCH], uz[BATCH]; /* the new rolling rotation (spring model) */
    double R[BATCH], fn[BATCH], sn[BATCH];  /* R*, |F_n| and S_n, from the first loop to the rolling spring's */
    /* block-crossing pairs computed in phase A, in their place among the
     * others: entry st_k[s] adds stored contribution st_c[s] of cf (the
     * kernel's lane for it is computed and not used) */
    int n_st, st_k[BATCH], st_c[BATCH];
    const double *cf;
} pair_batch;

/* Coefficients of every material pair in structure-of-arrays, indexed by
 * mat_i * DEM_MAX_MATERIALS + mat_j (filled per stage: a few numbers). */
typedef struct coef_table {
    double E[DEM_MAX_MATERIALS * DEM_MAX_MATERIALS], G[DEM_MAX_MATERIALS * DEM_MAX_MATERIALS];
    double gn[DEM_MAX_MATERIALS * DEM_MAX_MATERIALS], gt[DEM_MAX_MATERIALS * DEM_MAX_MATERIALS];
    double mu[DEM_MAX_MATERIALS * DEM_MAX_MATERIALS], st_sn[DEM_MAX_MATERIALS * DEM_MAX_MATERIALS];
    double mr[DEM_MAX_MATERIALS * DEM_MAX_MATERIALS]; /* mu_roll */
    int rolling; /* some pair has mu_roll > 0 */
} coef_table;

static void coef_table_fill(const dem_world *w, coef_table *t)
{
    t->rolling = 0;
    for (int a = 0; a < DEM_MAX_MATERIALS; a++)
        for (int b = 0; b < DEM_MAX_MATERIALS; b++) {
            const dem_pair_coef *c = &w->coef[a][b];
            int k = a * DEM_MAX_MATERIALS + b;
            t->E[k] = c->E, t->G[k] = c->G, t->gn[k] = c->gamma_n, t->gt[k] = c->gamma_t;
            t->mu[k] = c->mu, t->st_sn[k] = c->st_sn, t->mr[k] = c->mu_roll;
            t->rolling |= a < w->n_mat && b < w->n_mat && c->mu_roll > 0.0;
        }
}

/* rolling: 0 none, 1 the constant torque, 2 the spring (whose history
 * rows are DEM_HIST_MAX long, also where no pair rolls) */
static inline __attribute__((always_inline)) void batch_forces_body(const pair_arrays *in, const coef_table *ct,
                                                                     pair_batch *b, const int rolling,
                                                                     const int uniform)
{
    const int hs = rolling == 2 ? DEM_HIST_MAX : DEM_HIST_TANGENTIAL;
    const double *restrict r = in->r, *restrict vx = in->vx, *restrict vy = in->vy, *restrict vz = in->vz;
    const double *restrict wx = in->wx, *restrict wy = in->wy, *restrict wz = in->wz;
    const double *restrict inv_m = in->inv_m, *restrict inv_i = in->inv_i, *restrict hist = in->hist;
    const double *restrict cE = ct->E, *restrict cG = ct->G, *restrict cgn = ct->gn, *restrict cgt = ct->gt;
    const double *restrict cmu = ct->mu, *restrict cst = ct->st_sn, *restrict cmr = ct->mr;
    const int *restrict bi = b->i, *restrict bj = b->j, *restrict bc = b->c, *restrict bp = b->p;
    const double *restrict bex = b->ex, *restrict bey = b->ey, *restrict bez = b->ez, *restrict bd2 = b->d2;
    double *restrict ofx = b->fx, *restrict ofy = b->fy, *restrict ofz = b->fz;
    double *restrict otix = b->tix, *restrict otiy = b->tiy, *restrict otiz = b->tiz;
    double *restrict otjx = b->tjx, *restrict otjy = b->tjy, *restrict otjz = b->tjz;
    double *restrict osx = b->sx, *restrict osy = b->sy, *restrict osz = b->sz;
    double *restrict oux = b->ux, *restrict ouy = b->uy, *restrict ouz = b->uz;
    double *restrict oR = b->R, *restrict ofn = b->fn, *restrict osn = b->sn;
    const double dt = in->dt;
    const int n = b->n;
#pragma omp simd
    for (int k = 0; k < n; k++) {
        /* uniform: one material pair in the batch, its coefficients loaded
         * once for all lanes instead of gathered lane by lane */
        const int i = bi[k], j = bj[k], c = uniform ? bc[0] : bc[k], p3 = hs * bp[k];
        const double ex = bex[k], ey = bey[k], ez = bez[k];
        const double ri = r[i], rj = r[j], rs = ri + rj;
        double d = sqrt(bd2[k]);
        double delta = rs - d; /* eq. 18 */
        double nx = ex / d, ny = ey / d, nz = ez / d; /* eq. 10 */
        double li = ri - 0.5 * delta, lj = rj - 0.5 * delta;
        double ax = wx[i] * li + wx[j] * lj, ay = wy[i] * li + wy[j] * lj, az = wz[i] * li + wz[j] * lj;
        /* eq. 12 */
        double vrx = (vx[i] - vx[j]) - (ay * nz - az * ny);
        double vry = (vy[i] - vy[j]) - (az * nx - ax * nz);
        double vrz = (vz[i] - vz[j]) - (ax * ny - ay * nx);
        double R = ri * rj / rs;                  /* eq. 16 */
        double m = 1.0 / (inv_m[i] + inv_m[j]);   /* eq. 17 */
        double sx = hist[p3], sy = hist[p3 + 1], sz = hist[p3 + 2], Fx, Fy, Fz, f_n, sn;
        dem_hm_lane(cE[c], cG[c], cgn[c], cgt[c], cst[c], cmu[c], dt, nx, ny, nz, delta, R, m, vrx, vry, vrz, &sx,
                    &sy, &sz, &Fx, &Fy, &Fz, &f_n, &sn);
        osx[k] = sx, osy[k] = sy, osz[k] = sz;
        ofx[k] = Fx, ofy[k] = Fy, ofz[k] = Fz;
        /* torques (eq. 7) */
        double cx = ny * Fz - nz * Fy, cy = nz * Fx - nx * Fz, cz = nx * Fy - ny * Fx;
        double tix = cx * -li, tiy = cy * -li, tiz = cz * -li;
        double tjx = cx * -lj, tjy = cy * -lj, tjz = cz * -lj;
        if (rolling == 1) { /* dem_rolling_torque, added where the pair's mu_roll > 0 */
            const int roll = cmr[c] > 0.0;
            double rwx = wx[i] - wx[j], rwy = wy[i] - wy[j], rwz = wz[i] - wz[j], trx, try_, trz;
            dem_rolling_torque_lane(cmr[c], R, f_n, rwx, rwy, rwz, 1.0 / (inv_i[i] + inv_i[j]), dt, &trx, &try_,
                                    &trz);
            tix = roll ? tix + trx : tix, tiy = roll ? tiy + try_ : tiy, tiz = roll ? tiz + trz : tiz;
            tjx = roll ? tjx - trx : tjx, tjy = roll ? tjy - try_ : tjy, tjz = roll ? tjz - trz : tjz;
        }
        if (rolling == 2)
            oR[k] = R, ofn[k] = f_n, osn[k] = sn;
        otix[k] = tix, otiy[k] = tiy, otiz[k] = tiz;
        otjx[k] = tjx, otjy[k] = tjy, otjz[k] = tjz;
    }
    if (rolling != 2)
        return;
    /* dem_rolling_spring, added where the pair's mu_roll > 0, in a loop of
     * its own over the first one's R*, |F_n| and S_n: inside the first
     * loop it made the body too long for the registers (spilled beyond 3 kB
     * of stack); split, bench/dem's spring sand ran 1.31x faster on one
     * thread and 1.33x on two, the same bits */
#pragma omp simd
    for (int k = 0; k < n; k++) {
        const int i = bi[k], j = bj[k], c = uniform ? bc[0] : bc[k], p3 = hs * bp[k];
        const int roll = cmr[c] > 0.0;
        double rwx = wx[i] - wx[j], rwy = wy[i] - wy[j], rwz = wz[i] - wz[j], trx, try_, trz;
        const double u0x = hist[p3 + 3], u0y = hist[p3 + 4], u0z = hist[p3 + 5];
        double ux = u0x, uy = u0y, uz = u0z;
        dem_rolling_spring_lane(cmr[c], oR[k], osn[k], ofn[k], rwx, rwy, rwz,
                                DEM_SPHERE_ROLL_INERTIA / (inv_i[i] + inv_i[j]), dt, &ux, &uy, &uz, &trx, &try_, &trz);
        oux[k] = roll ? ux : u0x, ouy[k] = roll ? uy : u0y, ouz[k] = roll ? uz : u0z;
        const double tix = otix[k], tiy = otiy[k], tiz = otiz[k], tjx = otjx[k], tjy = otjy[k], tjz = otjz[k];
        otix[k] = roll ? tix + trx : tix, otiy[k] = roll ? tiy + try_ : tiy, otiz[k] = roll ? tiz + trz : tiz;
        otjx[k] = roll ? tjx - trx : tjx, otjy[k] = roll ? tjy - try_ : tjy, otjz[k] = roll ? tjz - trz : tjz;
    }
}

/* 1 if every pair of the batch has the same material pair (a bed of one
 * soil: always). */
static inline int batch_uniform(const pair_batch *b)
{
    int same = 1;
    for (int k = 1; k < b->n; k++)
        same &= b->c[k] == b->c[0];
    return same;
}

/* The six instances of the loop: the rolling spring, the constant torque
 * or no rolling resistance; one material pair or several (inlined into each
 * instruction-set build). */
static inline __attribute__((always_inline)) void batch_forces_dispatch(const pair_arrays *in, const coef_table *ct,
                                                                         pair_batch *b)
{
    const int uniform = in->one_c >= 0 || batch_uniform(b);
    if (in->roll_spring) {
        if (uniform)
            batch_forces_body(in, ct, b, 2, 1);
        else
            batch_forces_body(in, ct, b, 2, 0);
    } else if (uniform) {
        if (ct->rolling)
            batch_forces_body(in, ct, b, 1, 1);
        else
            batch_forces_body(in, ct, b, 0, 1);
    } else if (ct->rolling)
        batch_forces_body(in, ct, b, 1, 0);
    else
        batch_forces_body(in, ct, b, 0, 0);
}

#if defined(__x86_64__) && defined(__GNUC__)
__attribute__((target("avx2"))) static void batch_forces_avx2(const pair_arrays *in, const coef_table *ct,
                                                               pair_batch *b)
{
    batch_forces_dispatch(in, ct, b);
}

/* Eight lanes, for the rolling spring only (dem_kernels_of): GCC keeps
 * to 256-bit vectors for AVX-512 targets unless told to prefer 512. Its two
 * spring instances only, not batch_forces_dispatch's six: built through the
 * dispatch, the same bits ran the spring's pairs 0.87-0.90x as fast
 * (bench_dem, best of six, session 26). */
__attribute__((target("avx512f,avx512dq,avx512vl,prefer-vector-width=512"))) static void
batch_forces_spring_avx512(const pair_arrays *in, const coef_table *ct, pair_batch *b)
{
    if (in->one_c >= 0 || batch_uniform(b))
        batch_forces_body(in, ct, b, 2, 1);
    else
        batch_forces_body(in, ct, b, 2, 0);
}
#endif

static void batch_forces_portable(const pair_arrays *in, const coef_table *ct, pair_batch *b)
{
    batch_forces_dispatch(in, ct, b);
}

typedef void (*batch_fn)(const pair_arrays *, const coef_table *, pair_batch *);

static batch_fn batch_kernel(const dem_world *w)
{
#if defined(__x86_64__) && defined(__GNUC__)
    const int build = dem_kernels_of(&w->def);
    if (build == DEM_KERNELS_AVX512) /* the rolling spring (dem_kernels_of) */
        return batch_forces_spring_avx512;
    if (build >= DEM_KERNELS_AVX2)
        return batch_forces_avx2;
#endif
    return batch_forces_portable;
}

/* The batch's springs back into the history and its forces into the grains,
 * in pair order. */
static inline __attribute__((always_inline)) void batch_scatter_body(const pair_arrays *a, const force_sums *s,
                                                                      const pair_batch *b, const int spring)
{
    /* the pointers in locals: the stores into held (bytes, which may alias
     * anything) would otherwise reload them from a and s on every pair */
    const int hs = spring ? DEM_HIST_MAX : DEM_HIST_TANGENTIAL, n = b->n, n_st = b->n_st;
    double *restrict hist = a->hist;
    unsigned char *restrict held = a->held;
    double *restrict fx = s->fx, *restrict fy = s->fy, *restrict fz = s->fz;
    double *restrict tx = s->tx, *restrict ty = s->ty, *restrict tz = s->tz;
    int si = 0, s_next = n_st > 0 ? b->st_k[0] : INT_MAX;
    for (int k = 0; k < n; k++) {
        int p = b->p[k], i = b->i[k], j = b->j[k];
        if (k == s_next) { /* a stored cross pair: its force and torque on i alone */
            add_i(s, i, b->cf + (size_t)DEM_PAIR_F * b->st_c[si]);
            s_next = ++si < n_st ? b->st_k[si] : INT_MAX;
            continue;
        }
        double *xi = hist + (size_t)hs * p;
        xi[0] = b->sx[k], xi[1] = b->sy[k], xi[2] = b->sz[k];
        if (spring)
            xi[3] = b->ux[k], xi[4] = b->uy[k], xi[5] = b->uz[k];
        held[p] = (unsigned char)row_held(xi, hs);
        /* add_i and add_j through the locals */
        const double f0 = b->fx[k], f1 = b->fy[k], f2 = b->fz[k];
        fx[i] += f0, fy[i] += f1, fz[i] += f2;
        tx[i] += b->tix[k], ty[i] += b->tiy[k], tz[i] += b->tiz[k];
        fx[j] -= f0, fy[j] -= f1, fz[j] -= f2;
        tx[j] += b->tjx[k], ty[j] += b->tjy[k], tz[j] += b->tjz[k];
    }
}

/* Its two instances, out of line (the walks' loops stay small). */
static __attribute__((noinline)) void batch_scatter_tangential(const pair_arrays *a, const force_sums *s,
                                                               const pair_batch *b)
{
    batch_scatter_body(a, s, b, 0);
}

static __attribute__((noinline)) void batch_scatter_spring(const pair_arrays *a, const force_sums *s,
                                                           const pair_batch *b)
{
    batch_scatter_body(a, s, b, 1);
}

static inline __attribute__((always_inline)) void batch_scatter(const pair_arrays *a, const force_sums *s,
                                                                 const pair_batch *b, const int spring)
{
    if (spring)
        batch_scatter_spring(a, s, b);
    else
        batch_scatter_tangential(a, s, b);
}

/* ---- the stage --------------------------------------------------------- */

#if defined(__x86_64__) && defined(__GNUC__)
/* Where the contacts of a group of four candidates go: for each mask of
 * lanes in contact, the lanes in ascending order, first as 32-bit lanes
 * (the indices), then as pairs of 32-bit lanes (the doubles); and how many. */
static const int32_t pack32[16][8] = {
    {0}, {0}, {1}, {0, 1}, {2}, {0, 2}, {1, 2}, {0, 1, 2}, {3}, {0, 3}, {1, 3}, {0, 1, 3}, {2, 3}, {0, 2, 3},
    {1, 2, 3}, {0, 1, 2, 3}};
static const int32_t pack64[16][8] = {{0},
                                      {0, 1},
                                      {2, 3},
                                      {0, 1, 2, 3},
                                      {4, 5},
                                      {0, 1, 4, 5},
                                      {2, 3, 4, 5},
                                      {0, 1, 2, 3, 4, 5},
                                      {6, 7},
                                      {0, 1, 6, 7},
                                      {2, 3, 6, 7},
                                      {0, 1, 2, 3, 6, 7},
                                      {4, 5, 6, 7},
                                      {0, 1, 4, 5, 6, 7},
                                      {2, 3, 4, 5, 6, 7},
                                      {0, 1, 2, 3, 4, 5, 6, 7}};
static const unsigned char pack_n[16] = {0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4};

/* fill's test four candidates at a time (AVX2): the same operations on
 * each lane in the same order (no fused multiply-add), so the same bits;
 * the lanes in contact packed to the batch's end in pair order (a table
 * permutation). Stops four short of a full batch or of pe (fill does the
 * rest); returns the next p. The grains' values are loaded lane by lane:
 * with the gather instructions the run was 10-14 % slower than with the
 * scalar test on these CPUs (AMD Zen 4); lane by lane, 5-9 % faster. */
__attribute__((target("avx2"))) static int fill_avx2(const pair_arrays *a, pair_batch *restrict b, int p,
                                                      const int pe, const int hs, const int one_mat)
{
    const int *restrict pi = a->pi, *restrict pj = a->pj, *restrict mat = a->mat;
    const double *restrict x = a->x, *restrict y = a->y, *restrict z = a->z, *restrict r = a->r;
    unsigned char *restrict held = a->held;
    const double *restrict hist = a->hist;
    const __m128i c_one = _mm_set1_epi32(a->one_c), nmat = _mm_set1_epi32(DEM_MAX_MATERIALS);
    const __m128i lane = _mm_setr_epi32(0, 1, 2, 3);
    const __m256d zero = _mm256_setzero_pd();
    int n = b->n;
    for (; p + 4 <= pe && n <= BATCH - 4; p += 4) {
        /* The four pairs' spring rows (hs * 32 bytes) asked for now: the
         * kernel reads those in contact once the batch is full. The rows
         * stream through once per step (~48 bytes a candidate with the
         * rolling spring, megabytes a rank), and the kernel's lane-by-lane
         * loads of them were ~23 % of its time (perf, bench_dem stirred);
         * the hardware does not see them coming. Asked for here, the paper
         * scene's pair stage ran ~1.09x as fast, the same bits (session 28). */
        const char *hrow = (const char *)(hist + (size_t)hs * p);
        for (int o = 0; o < hs * 32; o += 64)
            __builtin_prefetch(hrow + o);
        const __m128i vi = _mm_loadu_si128((const __m128i *)(pi + p)), vj = _mm_loadu_si128((const __m128i *)(pj + p));
        const int i0 = pi[p], i1 = pi[p + 1], i2 = pi[p + 2], i3 = pi[p + 3];
        const int j0 = pj[p], j1 = pj[p + 1], j2 = pj[p + 2], j3 = pj[p + 3];
#define LANES(v, a, b, c, d) _mm256_setr_pd(v[a], v[b], v[c], v[d])
        const __m256d ex = _mm256_sub_pd(LANES(x, i0, i1, i2, i3), LANES(x, j0, j1, j2, j3));
        const __m256d ey = _mm256_sub_pd(LANES(y, i0, i1, i2, i3), LANES(y, j0, j1, j2, j3));
        const __m256d ez = _mm256_sub_pd(LANES(z, i0, i1, i2, i3), LANES(z, j0, j1, j2, j3));
        const __m256d d2 = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(ex, ex), _mm256_mul_pd(ey, ey)),
                                         _mm256_mul_pd(ez, ez));
        const __m256d rs = _mm256_add_pd(LANES(r, i0, i1, i2, i3), LANES(r, j0, j1, j2, j3));
#undef LANES
        const __m256d apart =
            _mm256_or_pd(_mm256_cmp_pd(d2, _mm256_mul_pd(rs, rs), _CMP_GE_OQ), _mm256_cmp_pd(d2, zero, _CMP_EQ_OQ));
        const int m_apart = _mm256_movemask_pd(apart), m = ~m_apart & 15;
        uint32_t h;
        memcpy(&h, held + p, sizeof h); /* held is 0 or 1 per pair */
        const int m_held = (int)((h & 1u) | (h >> 7 & 2u) | (h >> 14 & 4u) | (h >> 21 & 8u));
        if (m_apart & m_held) /* a spring to clear (rare) */
            for (int k = 0; k < 4; k++)
                if (m_apart & m_held & 1 << k)
                    spring_clear(a, p + k, hs);
        const __m256i q64 = _mm256_loadu_si256((const __m256i *)pack64[m]);
        const __m256i q32 = _mm256_loadu_si256((const __m256i *)pack32[m]);
        const __m128i vc = one_mat ? c_one
                                   : _mm_add_epi32(_mm_mullo_epi32(_mm_setr_epi32(mat[i0], mat[i1], mat[i2], mat[i3]),
                                                                   nmat),
                                                   _mm_setr_epi32(mat[j0], mat[j1], mat[j2], mat[j3]));
#define PACK32(v) _mm256_castsi256_si128(_mm256_permutevar8x32_epi32(_mm256_castsi128_si256(v), q32))
#define PACK64(v) _mm256_castsi256_pd(_mm256_permutevar8x32_epi32(_mm256_castpd_si256(v), q64))
        _mm_storeu_si128((__m128i *)(b->p + n), PACK32(_mm_add_epi32(_mm_set1_epi32(p), lane)));
        _mm_storeu_si128((__m128i *)(b->i + n), PACK32(vi));
        _mm_storeu_si128((__m128i *)(b->j + n), PACK32(vj));
        _mm_storeu_si128((__m128i *)(b->c + n), PACK32(vc));
        _mm256_storeu_pd(b->ex + n, PACK64(ex));
        _mm256_storeu_pd(b->ey + n, PACK64(ey));
        _mm256_storeu_pd(b->ez + n, PACK64(ez));
        _mm256_storeu_pd(b->d2 + n, PACK64(d2));
#undef PACK32
#undef PACK64
        n += pack_n[m];
    }
    b->n = n;
    return p;
}
#endif

/* Candidate pairs through the contact test, without a branch on its
 * outcome (in a settled bed about half the candidates touch, a coin a
 * branch predictor cannot call): each pair is written into the batch's next
 * place, which is taken only if the grains overlap. The pairs are p in
 * [p, pe). Stops when the batch is full; returns the next p.
 * A pair apart whose spring still holds something has it cleared (rare: the
 * pair just separated). Coincident centres (no normal) count as apart.
 * Nothing in the loop calls out, so the batch's count and the arrays stay
 * in registers. one_mat: the grains are all of one material, every pair's
 * coefficient index is a->one_c (no lookups). */
static inline __attribute__((always_inline)) int fill(const pair_arrays *a, pair_batch *restrict b, int p,
                                                       const int pe, const int spring, const int one_mat)
{
    const int hs = spring ? DEM_HIST_MAX : DEM_HIST_TANGENTIAL;
#if defined(__x86_64__) && defined(__GNUC__)
    if (a->avx2)
        p = fill_avx2(a, b, p, pe, hs, one_mat);
#endif
    const int *restrict pi = a->pi, *restrict pj = a->pj, *restrict mat = a->mat;
    const double *restrict x = a->x, *restrict y = a->y, *restrict z = a->z, *restrict r = a->r;
    unsigned char *restrict held = a->held;
    const int one_c = a->one_c;
    int n = b->n;
    for (; p < pe && n < BATCH; p++) {
        __builtin_prefetch(a->hist + (size_t)hs * p); /* its spring row, as fill_avx2 does */
        const int i = pi[p], j = pj[p];
        const double ex = x[i] - x[j], ey = y[i] - y[j], ez = z[i] - z[j];
        const double d2 = ex * ex + ey * ey + ez * ez, rs = r[i] + r[j];
        const int apart = (d2 >= rs * rs) | (d2 == 0.0);
        if (apart & held[p])
            spring_clear(a, p, hs);
        b->p[n] = p, b->i[n] = i, b->j[n] = j, b->c[n] = one_mat ? one_c : mat[i] * DEM_MAX_MATERIALS + mat[j];
        b->ex[n] = ex, b->ey[n] = ey, b->ez[n] = ez, b->d2[n] = d2;
        n += !apart;
    }
    b->n = n;
    return p;
}

/* A batch computed and added; returns its contacts. */
static inline __attribute__((always_inline)) int batch_flush(const pair_arrays *a, const force_sums *s,
                                                             const coef_table *ct, batch_fn batch_forces,
                                                             pair_batch *b, const int spring)
{
    const int n = b->n;
    if (n > 0) {
        batch_forces(a, ct, b);
        batch_scatter(a, s, b, spring);
        b->n = b->n_st = 0;
    }
    return n;
}

/* Phase A for the crossing pairs c in [c0, ce) (of any blocks: each one
 * writes only its own row, cf and con, so the list is shared out in equal
 * parts, not by block; by block, the pairs crossing from block 0 to 1 would
 * all fall to one thread): through the batched kernel (the same bits as
 * pair_force), each one's force and torques into cf and whether it touches
 * into con, its spring into the history. */
static inline __attribute__((always_inline)) void cross_part(const pair_arrays *in, const coef_table *ct,
                                                             batch_fn batch_forces, const dem_pair_plan *pl,
                                                             int c0, const int ce, const int spring)
{
    const pair_arrays a = *in;
    const int hs = spring ? DEM_HIST_MAX : DEM_HIST_TANGENTIAL;
    pair_batch b;
    int cidx[BATCH];
    b.n = b.n_st = 0;
    for (int c = c0; c < ce || b.n > 0;) {
        for (; c < ce && b.n < BATCH; c++) { /* fill's test and its clearing of a spring apart */
            const int p = pl->cross[c], i = a.pi[p], j = a.pj[p];
            const double ex = a.x[i] - a.x[j], ey = a.y[i] - a.y[j], ez = a.z[i] - a.z[j];
            const double d2 = ex * ex + ey * ey + ez * ez, rs = a.r[i] + a.r[j];
            const int apart = (d2 >= rs * rs) | (d2 == 0.0);
            pl->con[c] = (unsigned char)!apart;
            if (apart) {
                if (a.held[p])
                    spring_clear(&a, p, hs);
                continue;
            }
            const int n = b.n++;
            cidx[n] = c;
            b.p[n] = p, b.i[n] = i, b.j[n] = j, b.c[n] = a.mat[i] * DEM_MAX_MATERIALS + a.mat[j];
            b.ex[n] = ex, b.ey[n] = ey, b.ez[n] = ez, b.d2[n] = d2;
        }
        if (b.n == 0)
            continue;
        batch_forces(&a, ct, &b);
        for (int k = 0; k < b.n; k++) { /* the spring back, the contribution stored */
            double *xi = a.hist + (size_t)hs * b.p[k];
            xi[0] = b.sx[k], xi[1] = b.sy[k], xi[2] = b.sz[k];
            if (spring)
                xi[3] = b.ux[k], xi[4] = b.uy[k], xi[5] = b.uz[k];
            a.held[b.p[k]] = (unsigned char)row_held(xi, hs);
            double *f = pl->cf + (size_t)DEM_PAIR_F * cidx[k];
            f[0] = b.fx[k], f[1] = b.fy[k], f[2] = b.fz[k];
            f[3] = b.tix[k], f[4] = b.tiy[k], f[5] = b.tiz[k];
            f[6] = b.tjx[k], f[7] = b.tjy[k], f[8] = b.tjz[k];
        }
        b.n = 0;
    }
}

/* One thread: the active pairs [k0, np) in ascending p (the plain loop).
 * spring: the history rows of the rolling spring (a constant: two
 * instances). Pairs are computed one by one, so where a walk starts and
 * ends never changes a sum. */
static inline __attribute__((always_inline)) int walk_all(const pair_arrays *in, const force_sums *s,
                                                           const coef_table *ct, batch_fn batch_forces, int k0,
                                                           int np, const int spring, const int one_mat)
{
    const pair_arrays a = *in;
    pair_batch b;
    b.n = b.n_st = 0;
    int contacts = 0;
    for (int k = k0; k < np;) {
        k = fill(&a, &b, k, np, spring, one_mat);
        if (b.n == BATCH)
            contacts += batch_flush(&a, s, ct, batch_forces, &b, spring);
    }
    return contacts + batch_flush(&a, s, ct, batch_forces, &b, spring);
}

/* A block-crossing pair p in contact, computed in phase A (stored as cf's
 * c-th), into the batch in its place: its force and torque on i then follow
 * the batch's earlier pairs and precede its later ones, as in the one-thread
 * order, without flushing the batch. Its lane gets the pair's geometry like
 * any other (the kernel computes it; the scatter adds the stored values). */
static inline __attribute__((always_inline)) void batch_stored(const pair_arrays *a, pair_batch *b, int p, int c,
                                                               const double *cf)
{
    const int i = a->pi[p], j = a->pj[p], n = b->n;
    const double ex = a->x[i] - a->x[j], ey = a->y[i] - a->y[j], ez = a->z[i] - a->z[j];
    b->p[n] = p, b->i[n] = i, b->j[n] = j, b->c[n] = a->mat[i] * DEM_MAX_MATERIALS + a->mat[j];
    b->ex[n] = ex, b->ey[n] = ey, b->ez[n] = ez, b->d2[n] = ex * ex + ey * ey + ez * ez;
    b->st_k[b->n_st] = n, b->st_c[b->n_st++] = c;
    b->cf = cf;
    b->n = n + 1;
}

/* The pairs of block t in ascending p, merged with the cross pairs arriving
 * at its grains as j (phase B).
 * Pairs in contact go through batches, the block's own crossing ones in
 * their places (batch_stored); a contribution arriving as j first flushes
 * the batch (they all come before the block's own pairs), so that each grain
 * still adds in ascending p. Returns the contacts of the block's own pairs. */
static inline __attribute__((always_inline)) int walk_block(const pair_arrays *in, const force_sums *s,
                                                             const coef_table *ct, batch_fn batch_forces,
                                                             const dem_pair_plan *pl, int t, const int spring,
                                                             const int one_mat)
{
    const pair_arrays a = *in;
    const int *cross = pl->cross, *inc = pl->in;
    int k = pl->own_start[t], ke = pl->own_start[t + 1];
    int cc = pl->cross_start[t], ce = pl->cross_start[t + 1];
    int m = pl->in_start[t], me = pl->in_start[t + 1];
    pair_batch b;
    b.n = b.n_st = 0;
    int contacts = 0;
    /* the next stored event (own cross pair or arriving one) by p */
    int p_cc = cc < ce ? cross[cc] : INT_MAX, p_in = m < me ? cross[inc[m]] : INT_MAX;
    for (; k < ke || m < me;) {
        int p = k < ke ? k : INT_MAX;
        if (p_in < p) { /* a cross pair arriving at its j */
            contacts += batch_flush(&a, s, ct, batch_forces, &b, spring);
            int c = inc[m++];
            if (pl->con[c])
                add_j(s, a.pj[cross[c]], pl->cf + (size_t)DEM_PAIR_F * c);
            p_in = m < me ? cross[inc[m]] : INT_MAX;
            continue;
        }
        if (p == p_cc) { /* own cross pair: computed in phase A */
            k++;
            int c = cc++;
            if (pl->con[c]) {
                batch_stored(&a, &b, p, c, pl->cf);
                if (b.n == BATCH)
                    contacts += batch_flush(&a, s, ct, batch_forces, &b, spring);
            }
            p_cc = cc < ce ? cross[cc] : INT_MAX;
            continue;
        }
        /* own pairs up to the next event */
        const int lim = p_cc < p_in ? p_cc : p_in;
        k = fill(&a, &b, k, lim < ke ? lim : ke, spring, one_mat);
        if (b.n == BATCH)
            contacts += batch_flush(&a, s, ct, batch_forces, &b, spring);
    }
    return contacts + batch_flush(&a, s, ct, batch_forces, &b, spring);
}

/* Stage "pairs" for a world with shaped grains: the shaped
 * contacts (dem_shape.c) add into force arrays, so each thread adds its
 * contiguous block of pairs into its own buffer (thread 0 into the grain
 * arrays), merged in thread order: deterministic for a given thread count. */
static int stage_pairs_shaped(dem_world *w)
{
    dem_grains *g = &w->g;
    const int n = g->n, nt = w->n_threads, cap = g->cap, np = w->n_active_pairs;
    int contacts = 0;
    const pair_arrays pa = pair_arrays_of(w);
    dem_shaped_pose_update(w);
#ifdef _OPENMP
#pragma omp parallel num_threads(nt) reduction(+ : contacts)
#endif
    {
        int tid = dem_thread_id();
        int lo = (int)((long)np * tid / nt), hi = (int)((long)np * (tid + 1) / nt);
        force_sums s = {g->fx, g->fy, g->fz, g->tx, g->ty, g->tz};
        if (tid > 0) {
            double *b = w->tb[tid].f;
            memset(b, 0, 6 * (size_t)cap * sizeof *b);
            s = (force_sums){b, b + cap, b + 2 * cap, b + 3 * cap, b + 4 * cap, b + 5 * cap};
        }
        for (int p = lo; p < hi; p++) {
            int i = w->pi[p], j = w->pj[p];
            double *xi = w->hist_val[w->hist_cur] + (size_t)w->hist_stride * p;
            if ((g->shape[i] & g->shape[j]) < 0) { /* both -1: spheres */
                double f[DEM_PAIR_F];
                if (pair_force(&pa, p, f)) {
                    contacts++;
                    add_i(&s, i, f);
                    add_j(&s, j, f);
                }
            } else
                contacts += dem_shaped_pair(w, i, j, xi, s.fx, s.fy, s.fz, s.tx, s.ty, s.tz);
        }
#ifdef _OPENMP
#pragma omp barrier
#pragma omp for schedule(static)
#endif
        for (int i = 0; i < n; i++)
            for (int t = 1; t < nt; t++) {
                const double *b = w->tb[t].f;
                g->fx[i] += b[i], g->fy[i] += b[cap + i], g->fz[i] += b[2 * cap + i];
                g->tx[i] += b[3 * cap + i], g->ty[i] += b[4 * cap + i], g->tz[i] += b[5 * cap + i];
            }
    }
    return contacts;
}

int dem_pairs_contacts(const dem_world *w, int p0, int p1)
{
    const dem_grains *g = &w->g;
    int contacts = 0;
    for (int p = p0; p < p1; p++) { /* the test of candidate(), the same operations */
        const int i = w->pi[p], j = w->pj[p];
        const double ex = g->x[i] - g->x[j], ey = g->y[i] - g->y[j], ez = g->z[i] - g->z[j];
        const double d2 = ex * ex + ey * ey + ez * ez, rs = g->r[i] + g->r[j];
        contacts += !((d2 >= rs * rs) | (d2 == 0.0));
    }
    return contacts;
}

/* What every walk of the stage reads: the arrays, the grains' sums, the
 * coefficients, the kernel. */
typedef struct stage_in {
    pair_arrays a;
    force_sums s;
    coef_table ct;
    batch_fn bf;
} stage_in;

static void stage_in_of(dem_world *w, stage_in *in)
{
    dem_grains *g = &w->g;
    in->a = pair_arrays_of(w);
    in->s = (force_sums){g->fx, g->fy, g->fz, g->tx, g->ty, g->tz};
    coef_table_fill(w, &in->ct);
    in->bf = batch_kernel(w);
}

static int walk_part(const stage_in *in, int p0, int p1)
{
    const pair_arrays *a = &in->a;
    if (a->one_c >= 0)
        return a->roll_spring ? walk_all(a, &in->s, &in->ct, in->bf, p0, p1, 1, 1)
                              : walk_all(a, &in->s, &in->ct, in->bf, p0, p1, 0, 1);
    return a->roll_spring ? walk_all(a, &in->s, &in->ct, in->bf, p0, p1, 1, 0)
                          : walk_all(a, &in->s, &in->ct, in->bf, p0, p1, 0, 0);
}

int dem_stage_pairs_between(dem_world *w, int (*between)(dem_world *w, void *user), void *user, int *contacts)
{
    stage_in in;
    stage_in_of(w, &in);
    const int np = w->n_active_pairs;
    int p0 = 0, more = 1;
    *contacts = 0;
    while (more > 0 && p0 < np) {
        const int p1 = np - p0 > DEM_PAIRS_BLOCK ? p0 + DEM_PAIRS_BLOCK : np;
        *contacts += walk_part(&in, p0, p1);
        p0 = p1;
        more = between(w, user);
    }
    if (more < 0)
        return more;
    *contacts += walk_part(&in, p0, np); /* the rest in one go */
    return CM_OK;
}

/* Blocks to threads: a thread takes its own blocks first (block t holds
 * about the grains that thread t's surface and integrate passes handle, so
 * their data sits in its core's cache: taken by whichever thread came first,
 * as omp's dynamic schedule does, the stage ran some 20 % slower on two
 * threads), then any block no thread has claimed yet (a thread whose core
 * is shared, e.g. with fem_server, must not hold the others up). Who does a
 * block changes no bits. *k: the thread's place in its order (0 at first);
 * returns the next block, or -1 when none is left. */
static int block_claim(int *claim, int nb, int tid, int nt, int *k)
{
    const int first = (int)((long)nb * tid / nt);
    while (*k < nb) {
        const int t = (first + (*k)++) % nb;
        if (__atomic_exchange_n(&claim[t], 1, __ATOMIC_ACQ_REL) == 0)
            return t;
    }
    return -1;
}

int dem_stage_pairs(dem_world *w)
{
    if (w->n_shaped > 0)
        return stage_pairs_shaped(w);
    const int nt = w->n_threads;
    stage_in in;
    stage_in_of(w, &in);
    if (nt == 1)
        return walk_part(&in, 0, w->n_active_pairs);
    const pair_arrays a = in.a;
    const force_sums s = in.s;
    const batch_fn bf = in.bf;
    const dem_pair_plan *pl = &w->plan;
    const int nb = pl->n_blocks;
    int contacts = 0;
    int *claim = pl->claim; /* phase A's claims, then phase B's */
    memset(claim, 0, 2 * (size_t)nb * sizeof *claim);
#ifdef _OPENMP
#pragma omp parallel num_threads(nt) reduction(+ : contacts)
#endif
    {
        const int tid = dem_thread_id();
        const int nc = pl->cross_start[nb];
        for (int k = 0, t; (t = block_claim(claim, nb, tid, nt, &k)) >= 0;) { /* phase A: nb equal parts */
            const int c0 = (int)((long)nc * t / nb), c1 = (int)((long)nc * (t + 1) / nb);
            if (a.roll_spring)
                cross_part(&a, &in.ct, bf, pl, c0, c1, 1);
            else
                cross_part(&a, &in.ct, bf, pl, c0, c1, 0);
        }
#ifdef _OPENMP
#pragma omp barrier
#endif
        for (int k = 0, t; (t = block_claim(claim + nb, nb, tid, nt, &k)) >= 0;) /* phase B */
            contacts += a.one_c >= 0 ? (a.roll_spring ? walk_block(&a, &s, &in.ct, bf, pl, t, 1, 1)
                                                   : walk_block(&a, &s, &in.ct, bf, pl, t, 0, 1))
                                  : (a.roll_spring ? walk_block(&a, &s, &in.ct, bf, pl, t, 1, 0)
                                                   : walk_block(&a, &s, &in.ct, bf, pl, t, 0, 0));
    }
    return contacts;
}
