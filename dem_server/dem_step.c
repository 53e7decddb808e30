/* The time step, a pipeline of named stages, each timed into w->prof
 * (dem_profile):
 *   surface    clear forces -> gravity -> walls -> triangle surface     (dem_step_surface)
 *   surf_gather distributed run only: the ranks' surface contacts summed
 *              on rank 0 (dem_mpi.c); begun here, ended here or, with
 *              dem_step_surface_then, among the next stage's pairs
 *   pairs      grain–grain narrow phase over the neighbour list, each     (dem_step_grains)
 *              pair's force added into its grains in pair-list order, the
 *              same sums for any thread count (dem_pairs.c)
 *   integrate  Verlet (eqs. 4–5), ω, quaternion (with shaped grains), largest displacement
 *   halo       distributed run only: the ghosts' states from their ranks,
 *              the largest displacement over all ranks (dem_mpi.c)
 *   rebuild    neighbour grid, re-sort and pair list when a grain moved
 *              more than skin/2 (or the grains changed; dem_grid.c); in a
 *              distributed run after stage "migrate" (dem_mpi.c)
 * In the coupled loop (dem_coupled.c) the exchange sits between surface and
 * pairs, so that pairs and integrate overlap the FEM's step. */
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

/* ---- the step ---------------------------------------------------------- */

/* Gravity (eq. 1) as the first term of every sum, torques zero, for grain
 * slots [lo, hi): a loop of its own, which vectorises. */
static void gravity_range(dem_grains *g, int lo, int hi, const double grav[3])
{
    double *restrict fx = g->fx, *restrict fy = g->fy, *restrict fz = g->fz;
    double *restrict tx = g->tx, *restrict ty = g->ty, *restrict tz = g->tz;
    const double *restrict inv_m = g->inv_m;
    const double gx = grav[0], gy = grav[1], gz = grav[2];
#pragma omp simd
    for (int i = lo; i < hi; i++) {
        double m = 1.0 / inv_m[i];
        fx[i] = m * gx, fy[i] = m * gy, fz[i] = m * gz;
        tx[i] = ty[i] = tz[i] = 0.0;
    }
}

/* ---- walls ------------------------------------------------------------
 *
 * A sphere's wall contacts go through a batched kernel as its pairs do
 * (dem_pairs.c): the pass over the grains finds the walls each one
 * touches and queues the contacts; the kernel computes a batch of them in a
 * loop the compiler vectorises, the lanes doing the scalar rules'
 * operations in their order (dem_contact.h, "one lane of a batched
 * kernel"; portable and AVX2 builds, the same bits); the results are added
 * in the queue's order, grain by grain and wall by wall, as one loop over
 * the grains adds them. A wall: R* = r, m* = m (eqs. 16, 17 with an
 * infinite partner), lever from the centre to the contact point on the
 * plane. */
enum { WALL_BATCH = 64 };

typedef struct wall_batch {
    int n;
    int i[WALL_BATCH], k[WALL_BATCH];    /* grain slot, wall */
    int c[WALL_BATCH];                   /* coefficients: mat_i * DEM_MAX_WALLS + k */
    double dist[WALL_BATCH];             /* the centre's distance from the plane (< r) */
    double nx[WALL_BATCH], ny[WALL_BATCH], nz[WALL_BATCH]; /* the wall's normal */
    /* out: force and torque on the grain, the new spring and rotation */
    double fx[WALL_BATCH], fy[WALL_BATCH], fz[WALL_BATCH], tx[WALL_BATCH], ty[WALL_BATCH], tz[WALL_BATCH];
    double sx[WALL_BATCH], sy[WALL_BATCH], sz[WALL_BATCH], ux[WALL_BATCH], uy[WALL_BATCH], uz[WALL_BATCH];
} wall_batch;

/* What the kernel reads: the grains and, for each grain material and wall,
 * the coefficients in structure-of-arrays (loads the loop can gather). */
enum { WALL_COEFS = DEM_MAX_MATERIALS * DEM_MAX_WALLS };
typedef struct wall_in {
    const double *vx, *vy, *vz, *wx, *wy, *wz, *r, *inv_m, *inv_i, *hist;
    double E[WALL_COEFS], G[WALL_COEFS], gn[WALL_COEFS], gt[WALL_COEFS], st_sn[WALL_COEFS], mu[WALL_COEFS];
    double mr[WALL_COEFS]; /* mu_roll */
    double dt;
    int nw, hs;
} wall_in;

/* rolling: 0 none anywhere, 1 the constant torque, 2 the spring (as the
 * pair kernel's) */
static inline __attribute__((always_inline)) void wall_forces_body(const wall_in *in, wall_batch *b,
                                                                    const int rolling)
{
    const double *restrict vx = in->vx, *restrict vy = in->vy, *restrict vz = in->vz;
    const double *restrict wx = in->wx, *restrict wy = in->wy, *restrict wz = in->wz;
    const double *restrict r = in->r, *restrict inv_m = in->inv_m, *restrict inv_i = in->inv_i;
    const double *restrict hist = in->hist;
    const double *restrict cE = in->E, *restrict cG = in->G, *restrict cgn = in->gn, *restrict cgt = in->gt;
    const double *restrict cst = in->st_sn, *restrict cmu = in->mu, *restrict cmr = in->mr;
    const int *restrict bi = b->i, *restrict bk = b->k, *restrict bc = b->c;
    const double *restrict bdist = b->dist, *restrict bnx = b->nx, *restrict bny = b->ny, *restrict bnz = b->nz;
    double *restrict ofx = b->fx, *restrict ofy = b->fy, *restrict ofz = b->fz;
    double *restrict otx = b->tx, *restrict oty = b->ty, *restrict otz = b->tz;
    double *restrict osx = b->sx, *restrict osy = b->sy, *restrict osz = b->sz;
    double *restrict oux = b->ux, *restrict ouy = b->uy, *restrict ouz = b->uz;
    const double dt = in->dt;
    const int nw = in->nw, hs = in->hs, n = b->n;
#pragma omp simd
    for (int l = 0; l < n; l++) {
        const int i = bi[l], h = (i * nw + bk[l]) * hs, c = bc[l];
        const double nx = bnx[l], ny = bny[l], nz = bnz[l], dist = bdist[l], ri = r[i];
        const double delta = ri - dist;
        const double m = 1.0 / inv_m[i];
        const double lx = nx * -dist, ly = ny * -dist, lz = nz * -dist; /* centre -> contact point */
        const double wix = wx[i], wiy = wy[i], wiz = wz[i];
        const double vrx = vx[i] + (wiy * lz - wiz * ly), vry = vy[i] + (wiz * lx - wix * lz),
                     vrz = vz[i] + (wix * ly - wiy * lx);
        double sx = hist[h], sy = hist[h + 1], sz = hist[h + 2], Fx, Fy, Fz, f_n, sn;
        dem_hm_lane(cE[c], cG[c], cgn[c], cgt[c], cst[c], cmu[c], dt, nx, ny, nz, delta, ri, m, vrx, vry, vrz, &sx, &sy,
                    &sz, &Fx, &Fy, &Fz, &f_n, &sn);
        osx[l] = sx, osy[l] = sy, osz[l] = sz;
        ofx[l] = Fx, ofy[l] = Fy, ofz[l] = Fz;
        double trx = 0.0, try_ = 0.0, trz = 0.0;
        if (rolling) { /* where the pair's mu_roll > 0 */
            const double mr = cmr[c];
            const int roll = mr > 0.0;
            double ax, ay, az;
            if (rolling == 2) {
                const double u0x = hist[h + 3], u0y = hist[h + 4], u0z = hist[h + 5];
                double ux = u0x, uy = u0y, uz = u0z;
                dem_rolling_spring_lane(mr, ri, sn, f_n, wix, wiy, wiz, DEM_SPHERE_ROLL_INERTIA / inv_i[i], dt, &ux,
                                        &uy, &uz, &ax, &ay, &az);
                oux[l] = roll ? ux : u0x, ouy[l] = roll ? uy : u0y, ouz[l] = roll ? uz : u0z;
            } else {
                dem_rolling_torque_lane(mr, ri, f_n, wix, wiy, wiz, 1.0 / inv_i[i], dt, &ax, &ay, &az);
            }
            trx = roll ? ax : 0.0, try_ = roll ? ay : 0.0, trz = roll ? az : 0.0;
        }
        /* eq. 7: lever x F, plus the rolling torque (zero where none acts) */
        otx[l] = (ly * Fz - lz * Fy) + trx, oty[l] = (lz * Fx - lx * Fz) + try_, otz[l] = (lx * Fy - ly * Fx) + trz;
    }
}

static inline __attribute__((always_inline)) void wall_forces_dispatch(const wall_in *in, wall_batch *b,
                                                                        const int rolling)
{
    if (rolling == 2)
        wall_forces_body(in, b, 2);
    else if (rolling)
        wall_forces_body(in, b, 1);
    else
        wall_forces_body(in, b, 0);
}

#if defined(__x86_64__) && defined(__GNUC__)
__attribute__((target("avx2"))) static void wall_forces_avx2(const wall_in *in, wall_batch *b, int rolling)
{
    wall_forces_dispatch(in, b, rolling);
}
#endif

static void wall_forces_portable(const wall_in *in, wall_batch *b, int rolling)
{
    wall_forces_dispatch(in, b, rolling);
}

typedef void (*wall_fn)(const wall_in *, wall_batch *, int);

/* The queued contacts computed and added, in queue order: the springs back
 * into the history, force and torque into the grain, the reaction into wf,
 * each contact recorded (rec, distributed: the grain's place counted from
 * slot g0). */
static void wall_flush(dem_world *w, wall_fn kernel, const wall_in *in, wall_batch *b, int rolling, double (*wf)[3],
                       double *rec, int g0, int *nrec)
{
    if (b->n == 0)
        return;
    kernel(in, b, rolling);
    dem_grains *g = &w->g;
    const int nw = in->nw, hs = in->hs;
    for (int l = 0; l < b->n; l++) {
        const int i = b->i[l], k = b->k[l];
        double *xi = g->wall_hist + ((size_t)i * nw + k) * hs;
        xi[0] = b->sx[l], xi[1] = b->sy[l], xi[2] = b->sz[l];
        if (rolling == 2)
            xi[3] = b->ux[l], xi[4] = b->uy[l], xi[5] = b->uz[l];
        const double Fx = b->fx[l], Fy = b->fy[l], Fz = b->fz[l];
        g->fx[i] += Fx, g->fy[i] += Fy, g->fz[i] += Fz;
        g->tx[i] += b->tx[l], g->ty[i] += b->ty[l], g->tz[i] += b->tz[l];
        wf[k][0] -= Fx, wf[k][1] -= Fy, wf[k][2] -= Fz;
        if (rec) {
            double *q = rec + (size_t)DEM_WALL_REC * (*nrec)++;
            q[0] = i - g0, q[1] = k, q[2] = Fx, q[3] = Fy, q[4] = Fz;
        }
    }
    b->n = 0;
}

/* The first k with a[k] >= v in the ascending a[0 .. n). */
static int lower_bound(const int *a, int n, int v)
{
    int k = 0;
    while (n > 0) {
        const int half = n / 2;
        if (a[k + half] < v)
            k += half + 1, n -= half + 1;
        else
            n = half;
    }
    return k;
}

/* Walls for grain slots [lo, hi), added after gravity; wall forces into wf;
 * returns the contacts. A shaped grain's contacts are computed on the spot
 * (dem_shaped_wall), after the queue is flushed, so that every sum keeps
 * its order. rec (distributed, spheres only): see wall_flush. */
static int walls_range(dem_world *w, int lo, int hi, double (*wf)[3], double *rec, int g0, int *nrec)
{
    dem_grains *g = &w->g;
    const int nw = w->n_walls, hs = w->hist_stride;
    const int shaped = w->n_shaped > 0;
    const int near_valid = w->walls_near_valid;
    const uint32_t all = nw >= 32 ? 0xffffffffu : (1u << nw) - 1u;
    wall_in in; /* the coefficients: only those of the grains' materials are filled and read */
    in.vx = g->vx, in.vy = g->vy, in.vz = g->vz, in.wx = g->wx, in.wy = g->wy, in.wz = g->wz;
    in.r = g->r, in.inv_m = g->inv_m, in.inv_i = g->inv_i, in.hist = g->wall_hist;
    in.dt = w->def.dt, in.nw = nw, in.hs = hs;
    int rolling = w->def.rolling_model == DEM_ROLLING_SPRING ? 2 : 0;
    for (int a = 0; a < w->n_mat; a++)
        for (int k = 0; k < nw; k++) {
            const dem_pair_coef *cf = &w->coef[a][w->walls[k].material];
            const int c = a * DEM_MAX_WALLS + k;
            in.E[c] = cf->E, in.G[c] = cf->G, in.gn[c] = cf->gamma_n, in.gt[c] = cf->gamma_t;
            in.st_sn[c] = cf->st_sn, in.mu[c] = cf->mu, in.mr[c] = cf->mu_roll;
            if (!rolling && cf->mu_roll > 0.0) /* the constant torque somewhere */
                rolling = 1;
        }
    wall_fn kernel = wall_forces_portable;
#if defined(__x86_64__) && defined(__GNUC__)
    if (dem_kernels_of(&w->def) >= DEM_KERNELS_AVX2) /* no AVX-512 build: see dem_kernels_of */
        kernel = wall_forces_avx2;
#endif
    wall_batch b;
    b.n = 0;
    int contacts = 0;
    /* the grains of the wall list in [lo, hi) where it is current (a few in
     * a hundred in a bed: the others have no wall in reach), else all */
    const int *list = near_valid ? w->wall_list : NULL;
    int q0 = lo, q1 = hi;
    if (list)
        q0 = lower_bound(list, w->n_wall_list, lo), q1 = lower_bound(list, w->n_wall_list, hi);
    for (int q = q0; q < q1; q++) {
        const int i = list ? list[q] : q;
        uint32_t mask = g->wall_mask[i];
        /* the walls within reach (and any still holding a spring), in
         * ascending order as the loop over all walls would take them */
        uint32_t todo = near_valid ? g->wall_near[i] | mask : all;
        if (!todo || g->frozen[i]) /* a frozen grain stays put: its wall springs wait unchanged */
            continue;
        const int shape = shaped && g->shape[i] >= 0;
        const double r = g->r[i];
        while (todo) {
            int k = __builtin_ctz(todo);
            todo &= todo - 1;
            const dem_wall *wl = &w->walls[k];
            double dist = (g->x[i] - wl->p[0]) * wl->n[0] + (g->y[i] - wl->p[1]) * wl->n[1] +
                          (g->z[i] - wl->p[2]) * wl->n[2];
            double *xi = g->wall_hist + ((size_t)i * nw + k) * hs;
            if (r - dist <= 0.0) {
                if (mask & (1u << k)) {
                    memset(xi, 0, (size_t)hs * sizeof *xi);
                    mask &= ~(1u << k);
                }
                continue;
            }
            if (shape) { /* bounding sphere touches: the shape itself */
                wall_flush(w, kernel, &in, &b, rolling, wf, rec, g0, nrec);
                double F[3], T[3];
                if (dem_shaped_wall(w, i, k, xi, F, T)) {
                    mask |= 1u << k;
                    contacts++;
                    g->fx[i] += F[0], g->fy[i] += F[1], g->fz[i] += F[2];
                    g->tx[i] += T[0], g->ty[i] += T[1], g->tz[i] += T[2];
                    wf[k][0] -= F[0], wf[k][1] -= F[1], wf[k][2] -= F[2];
                }
                continue;
            }
            mask |= 1u << k;
            contacts++;
            b.i[b.n] = i, b.k[b.n] = k, b.c[b.n] = g->mat[i] * DEM_MAX_WALLS + k, b.dist[b.n] = dist;
            b.nx[b.n] = wl->n[0], b.ny[b.n] = wl->n[1], b.nz[b.n] = wl->n[2];
            if (++b.n == WALL_BATCH)
                wall_flush(w, kernel, &in, &b, rolling, wf, rec, g0, nrec);
        }
        g->wall_mask[i] = mask;
    }
    wall_flush(w, kernel, &in, &b, rolling, wf, rec, g0, nrec);
    return contacts;
}

/* Ends a pending surface gather if it can (wait: it must), then hands the
 * pass to what waits for it. The seconds it took are added to *t (the
 * gather's end also to stage surface). */
static int surf_ready(dem_world *w, int wait, double *t, cm_error *err)
{
    const double t0 = cm_now();
    int done = !w->surf_pending, rc = CM_OK;
    if (!done) {
        rc = w->dist->surf_gather_end(w, wait, &done, err);
        w->prof.surface += cm_now() - t0;
    }
    if (rc == CM_OK && done) {
        w->surf_pending = 0;
        dem_surface_ready_fn fn = w->surf_ready;
        w->surf_ready = NULL;
        if (fn)
            rc = fn(w, w->surf_ready_user, err);
    }
    *t += cm_now() - t0;
    return rc;
}

static int surface_begin(dem_world *w, cm_error *err)
{
    double t_late = 0.0;
    if (w->surf_pending) { /* a pass begun and never ended (no dem_step_grains since): ended first */
        int rc = surf_ready(w, 1, &t_late, err);
        if (rc)
            return rc;
    }
    if (!w->prepared) {
        int rc = dem_world_prepare(w, err);
        if (rc)
            return rc;
    }
    double t0 = cm_now();
    dem_grains *g = &w->g;
    const int nt = w->n_threads, nw = w->n_walls;
    const int shaped = w->n_shaped > 0;
    /* distributed: walls for the owned grains; the ghosts' sums only start
     * at zero (their pairs add into them, nothing reads them) */
    const int g0 = w->dist ? w->own_lo : 0, n = (w->dist ? w->own_hi : g->n) - g0;
    if (w->dist) {
        double *f[] = {g->fx, g->fy, g->fz, g->tx, g->ty, g->tz};
        for (int k = 0; k < 6; k++) {
            memset(f[k], 0, (size_t)g0 * sizeof(double));
            memset(f[k] + g0 + n, 0, (size_t)(g->n - g0 - n) * sizeof(double));
        }
    }
    int contacts = 0;
    for (int t = 0; t < nt; t++)
        memset(w->tb[t].wall_f, 0, sizeof w->tb[t].wall_f);
#ifdef _OPENMP
#pragma omp parallel num_threads(nt) reduction(+ : contacts)
#endif
    {
        int tid = dem_thread_id();
        int lo = g0 + (int)((long)n * tid / nt), hi = g0 + (int)((long)n * (tid + 1) / nt);
        double(*wf)[3] = w->tb[tid].wall_f;
        gravity_range(g, lo, hi, w->def.gravity);
        /* distributed: the contacts recorded for the wall forces over ranks */
        double *rec = w->wall_rec && w->wall_rec_nw >= nw && !shaped
                          ? w->wall_rec + (size_t)DEM_WALL_REC * w->wall_rec_nw * (lo - g0)
                          : NULL;
        w->tb[tid].wall_rec_n = 0;
        contacts += walls_range(w, lo, hi, wf, rec, g0, &w->tb[tid].wall_rec_n);
    }
    w->wall_rec_grains = n;
    for (int k = 0; k < nw; k++) {
        memset(w->walls[k].force, 0, sizeof w->walls[k].force);
        for (int t = 0; t < nt; t++)
            for (int c = 0; c < 3; c++)
                w->walls[k].force[c] += w->tb[t].wall_f[k][c];
    }
    w->contacts_gw = contacts;
    int rc = CM_OK;
    if (w->surf && !w->surf_paused)
        rc = dem_surface_contacts(w, err);
    /* stage "surf_gather" begun: every rank's contacts to rank 0 */
    if (rc == CM_OK && w->surf && !w->surf_paused && w->dist && w->dist->surf_gather_begin &&
        (rc = w->dist->surf_gather_begin(w, err)) == CM_OK)
        w->surf_pending = 1;
    w->prof.surface += cm_now() - t0;
    return rc;
}

int dem_step_surface_then(dem_world *w, dem_surface_ready_fn fn, void *user, cm_error *err)
{
    int rc = surface_begin(w, err);
    if (rc)
        return rc;
    w->surf_ready = fn, w->surf_ready_user = user;
    double t = 0.0;
    return w->surf_pending ? CM_OK : surf_ready(w, 1, &t, err);
}

int dem_step_surface(dem_world *w, cm_error *err)
{
    int rc = surface_begin(w, err);
    double t = 0.0;
    return rc == CM_OK && w->surf_pending ? surf_ready(w, 1, &t, err) : rc;
}

/* One grain's orientation: q <- (q + dt/2 (0, ω) q) / |...|, kept if the
 * grain is frozen. */
static inline __attribute__((always_inline)) void quat_step(double *q, double wx, double wy, double wz,
                                                            unsigned char frozen, double dt)
{
    double hx = 0.5 * dt * wx, hy = 0.5 * dt * wy, hz = 0.5 * dt * wz;
    double qw = q[0] - hx * q[1] - hy * q[2] - hz * q[3];
    double qx = q[1] + hx * q[0] + hy * q[3] - hz * q[2];
    double qy = q[2] - hx * q[3] + hy * q[0] + hz * q[1];
    double qz = q[3] + hx * q[2] - hy * q[1] + hz * q[0];
    double qn = 1.0 / sqrt(qw * qw + qx * qx + qy * qy + qz * qz);
    const int move = !frozen;
    qw = move ? qw * qn : q[0], qx = move ? qx * qn : q[1], qy = move ? qy * qn : q[2], qz = move ? qz * qn : q[3];
    q[0] = qw, q[1] = qx, q[2] = qy, q[3] = qz;
}

typedef double v4d __attribute__((vector_size(32)));
typedef long long v4l __attribute__((vector_size(32)));

/* a where mask's lanes are all ones, else b (bits, not arithmetic; a
 * macro: a function taking vectors would change the ABI without AVX) */
#define PICK(mask, a, b) ((v4d)(((v4l)(a) & (mask)) | ((v4l)(b) & ~(mask))))

/* quat_step for four grains: their rows q[0..15] transposed into one vector
 * per component, quat_step's expression on the vectors (each lane rounds
 * as the scalar code does; -ffp-contract=off keeps products and sums
 * apart), transposed back. */
static inline __attribute__((always_inline)) void quat_step4(double *q, const double *wx, const double *wy,
                                                             const double *wz, const unsigned char *frozen,
                                                             double dt)
{
    v4d r0, r1, r2, r3;
    memcpy(&r0, q, sizeof r0), memcpy(&r1, q + 4, sizeof r1), memcpy(&r2, q + 8, sizeof r2),
        memcpy(&r3, q + 12, sizeof r3);
    v4d t0 = __builtin_shuffle(r0, r1, (v4l){0, 4, 2, 6}), t1 = __builtin_shuffle(r0, r1, (v4l){1, 5, 3, 7});
    v4d t2 = __builtin_shuffle(r2, r3, (v4l){0, 4, 2, 6}), t3 = __builtin_shuffle(r2, r3, (v4l){1, 5, 3, 7});
    v4d cw = __builtin_shuffle(t0, t2, (v4l){0, 1, 4, 5}), cy = __builtin_shuffle(t0, t2, (v4l){2, 3, 6, 7});
    v4d cx = __builtin_shuffle(t1, t3, (v4l){0, 1, 4, 5}), cz = __builtin_shuffle(t1, t3, (v4l){2, 3, 6, 7});
    v4d vwx, vwy, vwz;
    memcpy(&vwx, wx, sizeof vwx), memcpy(&vwy, wy, sizeof vwy), memcpy(&vwz, wz, sizeof vwz);
    const double h = 0.5 * dt;
    v4d hx = h * vwx, hy = h * vwy, hz = h * vwz;
    v4d qw = cw - hx * cx - hy * cy - hz * cz;
    v4d qx = cx + hx * cw + hy * cz - hz * cy;
    v4d qy = cy - hx * cz + hy * cw + hz * cx;
    v4d qz = cz + hx * cy - hy * cx + hz * cw;
    v4d s2 = qw * qw + qx * qx + qy * qy + qz * qz, qn;
    for (int l = 0; l < 4; l++)
        qn[l] = 1.0 / sqrt(s2[l]);
    v4l move = {!frozen[0], !frozen[1], !frozen[2], !frozen[3]};
    move = -move; /* all bits set where the grain moves */
    qw = PICK(move, qw * qn, cw), qx = PICK(move, qx * qn, cx), qy = PICK(move, qy * qn, cy), qz = PICK(move, qz * qn, cz);
    t0 = __builtin_shuffle(qw, qx, (v4l){0, 4, 2, 6}), t1 = __builtin_shuffle(qw, qx, (v4l){1, 5, 3, 7});
    t2 = __builtin_shuffle(qy, qz, (v4l){0, 4, 2, 6}), t3 = __builtin_shuffle(qy, qz, (v4l){1, 5, 3, 7});
    r0 = __builtin_shuffle(t0, t2, (v4l){0, 1, 4, 5}), r2 = __builtin_shuffle(t0, t2, (v4l){2, 3, 6, 7});
    r1 = __builtin_shuffle(t1, t3, (v4l){0, 1, 4, 5}), r3 = __builtin_shuffle(t1, t3, (v4l){2, 3, 6, 7});
    memcpy(q, &r0, sizeof r0), memcpy(q + 4, &r1, sizeof r1), memcpy(q + 8, &r2, sizeof r2),
        memcpy(q + 12, &r3, sizeof r3);
}

/* v <- v + f/m dt, x <- x + v dt along one axis (or ω <- ω + T/I dt with
 * no position: x NULL) for grains [lo, hi), a frozen grain's values kept.
 * One array triple at a time: few streams, so the loop vectorises without
 * spilling (all nine at once spilled most of its registers). */
static inline __attribute__((always_inline)) void kick_drift(double *restrict v, double *restrict x,
                                                             const double *restrict f,
                                                             const double *restrict inv,
                                                             const unsigned char *restrict frozen, int lo, int hi,
                                                             double dt, const int drift)
{
#pragma omp simd
    for (int i = lo; i < hi; i++) {
        const int move = !frozen[i];
        double nv = v[i] + f[i] * inv[i] * dt;
        v[i] = move ? nv : v[i];
        if (drift) {
            double nx = x[i] + nv * dt;
            x[i] = move ? nx : x[i];
        }
    }
}

/* Verlet, eqs. 4–5 as predictor/corrector, for grains [lo, hi):
 * v(t) = v(t-dt/2) + a(t) dt/2 completes the previous step, v(t+dt/2) =
 * v(t) + a(t) dt/2 predicts, and x(t+dt) = x(t) + v(t+dt/2) dt = x + v dt +
 * a dt²/2 (eq. 4). Spheres: ω integrated directly (no gyroscopic term),
 * orientation (orient) as a unit quaternion rotated by ω dt (no Euler-angle
 * singularity, eq. 9 avoided). *maxd2: the largest squared displacement
 * since the last rebuild; returns the first slot with a non-finite position,
 * or INT_MAX. */
static inline __attribute__((always_inline)) int integrate_body(dem_grains *g, int lo, int hi, double dt,
                                                                 const int orient, double *maxd2_out)
{
    double *restrict x = g->x, *restrict y = g->y, *restrict z = g->z;
    double *restrict wx = g->wx, *restrict wy = g->wy, *restrict wz = g->wz;
    const double *restrict x0 = g->x0, *restrict y0 = g->y0, *restrict z0 = g->z0;
    double *restrict qa = g->q;
    const unsigned char *restrict frozen = g->frozen;
    double maxd2 = 0.0;
    int nonfinite = 0;
    /* Branch-free so that it vectorises: a frozen grain's values are computed
     * and thrown away (selects), the same bits as skipping it. Chunks of
     * grains small enough that the passes over them stay in the L1 cache.
     * A chunk of frozen grains only is skipped whole: slots are in cell
     * order, x the slowest axis, so the soil frozen beyond the terrain
     * window's extents (a sixth of the paper scene's grains) lies in runs of
     * whole chunks. */
    enum { CHUNK = 256 };
    for (int c0 = lo; c0 < hi; c0 += CHUNK) {
        const int c1 = hi - c0 > CHUNK ? c0 + CHUNK : hi;
        if (!memchr(frozen + c0, 0, (size_t)(c1 - c0)))
            continue; /* every grain frozen: nothing changes, d2 counts 0 */
        kick_drift(g->vx, x, g->fx, g->inv_m, frozen, c0, c1, dt, 1);
        kick_drift(g->vy, y, g->fy, g->inv_m, frozen, c0, c1, dt, 1);
        kick_drift(g->vz, z, g->fz, g->inv_m, frozen, c0, c1, dt, 1);
        kick_drift(wx, NULL, g->tx, g->inv_i, frozen, c0, c1, dt, 0);
        kick_drift(wy, NULL, g->ty, g->inv_i, frozen, c0, c1, dt, 0);
        kick_drift(wz, NULL, g->tz, g->inv_i, frozen, c0, c1, dt, 0);
#pragma omp simd reduction(max : maxd2) reduction(| : nonfinite)
        for (int i = c0; i < c1; i++) {
            double ex = x[i] - x0[i], ey = y[i] - y0[i], ez = z[i] - z0[i];
            double d2 = ex * ex + ey * ey + ez * ez;
            d2 = frozen[i] ? 0.0 : d2;
            maxd2 = d2 > maxd2 ? d2 : maxd2;
            nonfinite |= !(d2 <= DBL_MAX); /* NaN or inf */
        }
        /* q <- q + dt/2 (0, ω) q with the new ω, renormalised: first order
         * in ω dt per step, the orientation does not feed back into the
         * forces of spheres. A grain's four components lie together, so
         * four grains at a time are transposed into one vector per
         * component (quat_step4), the same operations in each lane as
         * quat_step on one. */
        if (!orient)
            continue;
        int k = c0;
        for (; k + 4 <= c1; k += 4)
            quat_step4(qa + 4 * (size_t)k, wx + k, wy + k, wz + k, frozen + k, dt);
        for (; k < c1; k++)
            quat_step(qa + 4 * (size_t)k, wx[k], wy[k], wz[k], frozen[k], dt);
    }
    *maxd2_out = maxd2;
    if (!nonfinite)
        return INT_MAX;
    for (int i = lo; i < hi; i++) { /* the first grain gone non-finite, for the message */
        double ex = x[i] - x0[i], ey = y[i] - y0[i], ez = z[i] - z0[i];
        if (!frozen[i] && !isfinite(ex * ex + ey * ey + ez * ez))
            return i;
    }
    return INT_MAX;
}

#if defined(__x86_64__) && defined(__GNUC__)
__attribute__((target("avx2"))) static int integrate_avx2(dem_grains *g, int lo, int hi, double dt, int orient,
                                                          double *maxd2)
{
    return integrate_body(g, lo, hi, dt, orient, maxd2);
}
#endif

/* The AVX2 build of the loop where dem_kernels_of allows it (build; no
 * AVX-512 build: see there): the same bits, as for the pair kernel. */
static int integrate_range(dem_grains *g, int lo, int hi, double dt, int orient, double *maxd2, int build)
{
#if defined(__x86_64__) && defined(__GNUC__)
    if (build >= DEM_KERNELS_AVX2)
        return integrate_avx2(g, lo, hi, dt, orient, maxd2);
#else
    (void)build;
#endif
    return integrate_body(g, lo, hi, dt, orient, maxd2);
}

/* Stage "integrate": integrate_range over the threads, then the rotation
 * of shaped grains. *maxd2: the largest squared displacement since the last
 * rebuild; returns the first slot with a non-finite position, or n. */
static int stage_integrate(dem_world *w, double *maxd2_out)
{
    dem_grains *g = &w->g;
    const int nt = w->n_threads;
    const int g0 = w->dist ? w->own_lo : 0, n = w->dist ? w->own_hi : g->n; /* the owned grains */
    const double dt = w->def.dt;
    /* A sphere's orientation feeds back into nothing (not its forces, not
     * the state hash) and frames write orientations only in a world with
     * shaped grains (dem_output.c): in a world of spheres it is not
     * integrated, and stays as the grain was made or last set. The
     * quaternion's pass was ~44 % of this stage on the paper scene's rank 1
     * (perf, session 34); nothing else moves by a bit. */
    const int shaped = w->n_shaped > 0, build = dem_kernels_of(&w->def);
    double maxd2 = 0.0;
    int bad = INT_MAX;
    double *qsave = w->scratch; /* free between rebuilds (cap * DEM_SCRATCH_PER_GRAIN >= 4 per grain) */
    if (shaped)
        for (int i = g0; i < n; i++)
            if (g->shape[i] >= 0)
                memcpy(qsave + 4 * i, g->q + 4 * i, 4 * sizeof *qsave);
    if (nt == 1) {
        bad = integrate_range(g, g0, n, dt, shaped, &maxd2, build);
    } else {
#ifdef _OPENMP
#pragma omp parallel num_threads(nt) reduction(max : maxd2) reduction(min : bad)
#endif
        {
            int tid = dem_thread_id();
            double m2;
            const long no = n - g0;
            int b = integrate_range(g, g0 + (int)(no * tid / nt), g0 + (int)(no * (tid + 1) / nt), dt, shaped, &m2,
                                    build);
            maxd2 = m2 > maxd2 ? m2 : maxd2;
            bad = b < bad ? b : bad;
        }
    }
    if (bad > g->n)
        bad = g->n;
    if (shaped) {
        /* Shaped grains: the loop above moved them (translation is the same)
         * but treated their rotation as a sphere's; redo it. Euler's
         * equations (eq. 8) in the body frame, leapfrog in the world angular
         * momentum, L(t+dt/2) = L(t-dt/2) + T(t) dt, then the free rotation
         * with that L over dt from the saved orientation (NO_SQUISH,
         * dem_shape.h); omega from L at the new orientation. */
#ifdef _OPENMP
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
#endif
        for (int i = g0; i < n; i++) {
            if (g->shape[i] < 0 || g->frozen[i])
                continue;
            double *L = g->angmom + 3 * i, *q = g->q + 4 * i, om[3];
            memcpy(q, qsave + 4 * i, 4 * sizeof *q);
            L[0] += g->tx[i] * dt, L[1] += g->ty[i] * dt, L[2] += g->tz[i] * dt;
            dem_rotate_free(q, L, g->inertia + 3 * i, dt, om);
            g->wx[i] = om[0], g->wy[i] = om[1], g->wz[i] = om[2];
        }
    }
    *maxd2_out = maxd2;
    return bad;
}

/* Between blocks of the pair stage: the pending surface gather tested once
 * gather_test_every has passed since the last test. */
typedef struct gather_test {
    double t_test; /* the last test (or the stage's start) */
    double *t_out; /* surf_ready's seconds */
    cm_error *err;
} gather_test;

static int test_gather(dem_world *w, void *user)
{
    gather_test *gt = user;
    if (cm_now() - gt->t_test >= w->def.gather_test_every) {
        int rc = surf_ready(w, 0, gt->t_out, gt->err);
        if (rc)
            return rc;
        gt->t_test = cm_now();
    }
    return w->surf_pending;
}

/* Stage "rebuild": the neighbour list, in a distributed run after the
 * migration of grains between ranks (dem_mpi.c). */
static int rebuild(dem_world *w, cm_error *err)
{
    return w->dist ? w->dist->rebuild(w, err) : dem_neighbour_rebuild(w, err);
}

/* The rest of the step after the surface stage: rebuild (if the grains
 * changed) -> pairs -> integrate -> rebuild if a grain moved more
 * than skin/2. */
int dem_step_grains(dem_world *w, cm_error *err)
{
    if (!w->prepared)
        return cm_fail(err, CM_ERR_STATE, "dem_step_grains at step %ld before dem_step_surface", w->step);
    int rc = CM_OK;
    double t_out = 0.0; /* the surface gather's end and what it handed the pass to */
    if (w->need_rebuild && w->surf_pending && (rc = surf_ready(w, 1, &t_out, err))) /* grains move: gather first */
        return rc;
    double t0 = cm_now();
    if (w->need_rebuild || !w->plan.valid) {
        rc = w->need_rebuild ? rebuild(w, err) : dem_pair_plan_build(w, err);
        if (rc)
            return rc;
        double t = cm_now();
        w->prof.rebuild += t - t0;
        t0 = t;
    }
    /* a surface gather still on its way: ended as soon as it can be, tried
     * between blocks of pairs (one thread, spheres) or after them */
    const double t_out0 = t_out;
    if (w->surf_pending && w->n_threads == 1 && w->n_shaped == 0) {
        gather_test gt = {t0, &t_out, err};
        if ((rc = dem_stage_pairs_between(w, test_gather, &gt, &w->contacts_gg)))
            return rc;
    } else
        w->contacts_gg = dem_stage_pairs(w);
    if (w->surf_pending && (rc = surf_ready(w, 1, &t_out, err)))
        return rc;
    if (w->dist) /* a left ghost's pairs are counted by its owner (the ranks' counts add up to one process's) */
        w->contacts_gg -= dem_pairs_contacts(w, 0, w->n_ghost_rows);
    double t_pairs = cm_now();
    w->prof.pairs += t_pairs - t0 - (t_out - t_out0);
    t0 = t_pairs;
    double maxd2;
    int bad = stage_integrate(w, &maxd2);
    w->step++;
    w->time += w->def.dt;
    w->prof.steps++;
    double t1 = cm_now();
    w->prof.integrate += t1 - t0;
    if (bad < w->g.n)
        return cm_fail(err, CM_ERR_NUMERIC, "step %ld (t = %g s): grain %d has a non-finite position: the integration is unstable; reduce coupling.dt (dem.dt stand-alone)",
                       w->step, w->time, w->g.id[bad]);
    if (w->dist) { /* stage "halo": ghosts from their owners, the rebuild decided by all */
        const double c1 = cm_thread_cpu_now();
        int any_bad = 0;
        rc = w->dist->halo(w, &maxd2, &any_bad, err);
        double t = cm_now(), fill = w->rider ? w->rider->fill_s : 0.0; /* a rider's fill waits for its own reasons */
        w->prof.halo += t - t1 - fill;
        w->prof.idle += fill;
        w->prof.wait_cpu += cm_thread_cpu_now() - c1;
        t1 = t;
        if (rc)
            return rc;
        if (any_bad)
            return cm_fail(err, CM_ERR_NUMERIC, "step %ld (t = %g s): a grain of another rank has a non-finite position: the integration is unstable; reduce coupling.dt (dem.dt stand-alone)",
                           w->step, w->time);
    }
    const double half = 0.5 * w->skin;
    if (maxd2 > half * half) {
        rc = rebuild(w, err);
        w->prof.rebuild += cm_now() - t1;
        if (rc)
            return rc;
    }
    return CM_OK;
}

int dem_step(dem_world *w, cm_error *err)
{
    int rc = dem_step_surface(w, err);
    return rc ? rc : dem_step_grains(w, err);
}
