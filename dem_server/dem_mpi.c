/* The distributed world (dem_mpi.h): slabs along x, ghosts, migration. The
 * step (dem_step.c) calls these stages through w->dist:
 *   rebuild  global box and grid (allreduce) -> slab bounds from the grain
 *            counts per cell column (allreduce) -> owned grains leaving the
 *            slab sent to their new ranks with the springs of their pairs
 *            (alltoallv) -> ghosts from the two neighbouring slabs -> the
 *            neighbour list on the global grid (dem_neighbour_rebuild)
 *   halo     after integrate: ghosts' positions and velocities from their
 *            owners, the largest displacement and the non-finite flag over
 *            all ranks, so that every rank rebuilds at the same step (two
 *            ranks: one exchange, which may carry a rider from rank 0;
 *            more: two sendrecv and an allreduce)
 *   surf_gather (begin, end) after a surface pass: the ranks' contacts
 *            summed on rank 0 (isend, improbe and imrecv)
 * Layout of a rank's slots after a rebuild: [left ghosts | owned | right
 * ghosts], the global order restricted to them (cells x slowest): the left
 * ghosts are the left neighbour's grains of its last column in its order,
 * so halo messages are contiguous slot ranges matched one to one. */
#include "dem_mpi.h"

#include <limits.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dem_world.h"
#include "timer.h"

typedef struct dist_ctx {
    MPI_Comm comm;
    int rank, size;
    int col_lo, col_hi;        /* this rank's slab: cell columns [col_lo, col_hi) */
    int n_send_lo, n_send_hi;  /* owned grains that are ghosts of rank - 1 / rank + 1 (first / last owned slots) */
    int distributed;           /* 0 until the first rebuild spread rank 0's grains */
    long scattered, migrated, springs_sent;
    int *bounds;               /* size + 1 */
    long *cols, cols_cap;      /* grain weights per cell column (global after the allreduce) */
    /* the balance (dem_mpi_set_balance): by grains, or by each rank's
     * measured busy time per grain-step since the previous rebuild */
    int balance;
    double cost;               /* busy s per owned grain-step here, smoothed; 0 before the first measure */
    double *costs;             /* size: every rank's cost */
    double wall_mark, wait_mark; /* at the previous rebuild's end: the clock, the waits' CPU time (prof.wait_cpu) */
    double added;              /* busy s added since the previous rebuild (dem_mpi_add_busy) */
    long steps_mark, own_mark; /* steps then, grains owned since */
    int *dest;                 /* per slot: rank of the grain's new slab (owned grains) */
    int *scount, *sdispl, *rcount, *rdispl; /* size each, alltoallv */
    int *hcount, *hdispl, *hrcount, *hrdispl;
    int *hwhere;               /* per rank: fill cursor */
    double *sbuf, *rbuf;       /* grain records */
    size_t sbuf_cap, rbuf_cap;
    double *hsbuf, *hrbuf;     /* spring records: tag, tag, 3 doubles */
    size_t hsbuf_cap, hrbuf_cap;
    double *psbuf, *prbuf;     /* packed surface contacts: this rank's, every rank's (rank 0) */
    size_t psbuf_cap, prbuf_cap;
    MPI_Request surf_req;      /* this rank's contacts on their way (rank 0: the message of rank surf_next) */
    int surf_next, surf_cnt;   /* rank 0: the rank whose contacts come next, the doubles it sends */
    long surf_got;             /* rank 0: doubles in prbuf so far */
    long surf_contacts, surf_gathers, surf_doubles, surf_early;
    long collects;             /* dem_mpi_collect calls (terrain window shifts) */
    dem_hash extra;            /* received springs, by tag pair */
    double *extra_val;
    size_t extra_cap;
    int *order;                /* cap: the kept slots at a rebuild */
    /* rank 0: the capacities one process's two history tables would have
     * (dem_hash_reset grows a table to hold the pairs of each list entered
     * in it): the gathered list's table is rebuilt at that size, so that a
     * checkpoint holds the same bytes */
    int vcap[2];
    double *wall_rec;          /* w->wall_rec: cap * wall_rec_nw records */
    double *wsbuf, *wrbuf;     /* wall contacts gathered on rank 0 */
    size_t wsbuf_cap, wrbuf_cap;
} dist_ctx;

static int wall_rec_alloc(dem_world *w, dist_ctx *d);

enum { REC_FIXED = 39, SPRING_REC_MAX = 2 + DEM_HIST_MAX };

/* surface history per grain (dem_surface.h), after the wall springs */
enum { SURF_HIST = DEM_SURF_SLOTS * DEM_SURF_SLOT_SIZE };

/* the wall springs of one grain */
static size_t wall_hist_size(const dem_world *w) { return (size_t)w->hist_stride * w->wall_stride; }

static size_t rec_size(const dem_world *w)
{
    return REC_FIXED + wall_hist_size(w) + (w->surf ? SURF_HIST : 0);
}

/* A pair's spring record: the two grains' tags, then its history row
 * (hist_stride doubles) times sg (-1 turns it to the other grain's side). */
static int spring_rec(const dem_world *w) { return 2 + w->hist_stride; }

static void spring_record(const dem_world *w, double ta, double tb, double sg, const double *h, double *rec)
{
    rec[0] = ta, rec[1] = tb;
    for (int k = 0; k < w->hist_stride; k++)
        rec[2 + k] = sg * h[k];
}

/* Everything a grain carries, as doubles (integers exactly). */
static void pack_grain(const dem_world *w, int i, double *r)
{
    const dem_grains *g = &w->g;
    const double v[REC_FIXED] = {
        g->x[i],     g->y[i],     g->z[i],     g->vx[i],    g->vy[i],    g->vz[i],    g->wx[i],
        g->wy[i],    g->wz[i],    g->fx[i],    g->fy[i],    g->fz[i],    g->tx[i],    g->ty[i],
        g->tz[i],    g->r[i],     g->inv_m[i], g->inv_i[i], g->q[4 * i], g->q[4 * i + 1], g->q[4 * i + 2],
        g->q[4 * i + 3], g->x0[i], g->y0[i],   g->z0[i],    g->sc[i],    g->inertia[3 * i], g->inertia[3 * i + 1],
        g->inertia[3 * i + 2], g->angmom[3 * i], g->angmom[3 * i + 1], g->angmom[3 * i + 2], g->mat[i],
        g->tag[i],   g->frozen[i], g->shape[i], g->wall_mask[i], g->surf_count[i], g->wall_near[i]};
    memcpy(r, v, sizeof v);
    const size_t wh = wall_hist_size(w);
    memcpy(r + REC_FIXED, g->wall_hist + i * wh, wh * sizeof *r);
    if (w->surf) /* the tangential springs against the tire travel with the grain */
        memcpy(r + REC_FIXED + wh, w->surf->hist + (size_t)i * SURF_HIST, SURF_HIST * sizeof *r);
}

static void unpack_grain(dem_world *w, int i, const double *r)
{
    dem_grains *g = &w->g;
    double *d[] = {g->x,  g->y,  g->z,  g->vx, g->vy, g->vz,    g->wx,    g->wy,
                   g->wz, g->fx, g->fy, g->fz, g->tx, g->ty,    g->tz,    g->r,
                   g->inv_m, g->inv_i};
    for (int k = 0; k < 18; k++)
        d[k][i] = r[k];
    memcpy(g->q + 4 * i, r + 18, 4 * sizeof *r);
    g->x0[i] = r[22], g->y0[i] = r[23], g->z0[i] = r[24], g->sc[i] = r[25];
    memcpy(g->inertia + 3 * i, r + 26, 3 * sizeof *r);
    memcpy(g->angmom + 3 * i, r + 29, 3 * sizeof *r);
    g->mat[i] = (int)r[32], g->tag[i] = (int)r[33], g->frozen[i] = (unsigned char)r[34];
    g->shape[i] = (int)r[35], g->wall_mask[i] = (uint32_t)r[36], g->surf_count[i] = (int)r[37];
    g->wall_near[i] = (uint32_t)r[38];
    const size_t wh = wall_hist_size(w);
    memcpy(g->wall_hist + i * wh, r + REC_FIXED, wh * sizeof *r);
    if (w->surf) /* a gathered view without a surface skips them */
        memcpy(w->surf->hist + (size_t)i * SURF_HIST, r + REC_FIXED + wh, SURF_HIST * sizeof *r);
}

static int grow(double **a, size_t *cap, size_t need)
{
    if (need <= *cap)
        return 0;
    size_t c = *cap ? *cap : 4096;
    while (c < need)
        c *= 2;
    double *b = realloc(*a, c * sizeof *b);
    if (!b)
        return 1;
    *a = b, *cap = c;
    return 0;
}

static int mpi_fail(cm_error *err, int code, const char *what, long step)
{
    char msg[MPI_MAX_ERROR_STRING];
    int len = 0;
    MPI_Error_string(code, msg, &len);
    return cm_fail(err, CM_ERR_IO, "step %ld: MPI %s failed: %s", step, what, msg);
}

int dem_mpi_slabs(const long *count, int n_cols, int ranks, int *bounds, cm_error *err)
{
    if (n_cols < ranks)
        return cm_fail(err, CM_ERR_RANGE,
                       "%d ranks but the grains span only %d cell columns along x: use at most %d ranks", ranks,
                       n_cols, n_cols);
    long total = 0;
    for (int c = 0; c < n_cols; c++)
        total += count[c];
    bounds[0] = 0;
    long run = 0;
    int c = 0;
    for (int r = 1; r < ranks; r++) {
        /* the column boundary whose preceding count is nearest r/ranks of
         * the total: the first one reaching it or the one before (always the
         * first would hand the ranks below up to a column too much: on the
         * paper's scene, rank 0, which also shares its core with fem_server) */
        long target = (long)((double)total * r / ranks + 0.5);
        while (c < n_cols && run < target)
            run += count[c++];
        if (c > 0 && target - (run - count[c - 1]) < run - target)
            run -= count[--c];
        int b = c;
        if (b < bounds[r - 1] + 1)
            b = bounds[r - 1] + 1; /* at least one column each */
        if (b > n_cols - (ranks - r))
            b = n_cols - (ranks - r);
        bounds[r] = b;
        while (c < b)
            run += count[c++];
        while (c > b)
            run -= count[--c];
    }
    bounds[ranks] = n_cols;
    return CM_OK;
}

/* The time balance (LAMMPS' "fix balance ... weight time" in spirit): one
 * of this rank's grains weighs its busy seconds per grain-step between the
 * previous rebuild and this one, averaged over rebuilds, relative to the
 * slowest rank's. The rebuild itself is left out: the ranks wait for each
 * other at every step's halo, and the steps are what the balance can even
 * out. In a rebuild fem_server is idle and rank 0 waits for the others
 * whatever the split; counted in, the rebuild gave rank 0 more grains than
 * its core could step beside fem_server, and the other ranks waited for it
 * at every halo (session 32).
 * Busy is the clock minus the CPU time spent in the waits for the others
 * (halo, the rebuild's migration and agreements, the surface gather) and,
 * coupled, for fem_server or rank 0's reply (dem_profile.wait_cpu): a wait
 * in which the rank had its core to itself spins, one in which its core ran
 * something else (fem_server stepping beside rank 0) is busy for the core.
 * Wall times would count fem_server's step as rank 0's idle whenever it
 * fell in a wait, and give rank 0 more grains than its core can carry. A
 * rank that shares its core, holds the tire's contacts or does rank 0's
 * serial work measures more per grain and gets fewer. Weights are integers (1..1024), so the
 * column sums are exact and the bounds the same on every rank; which rank
 * owns a grain never changes a result (dem_mpi.h). Every grain weighs 1
 * until each rank has a measure. */
static int grain_weight(dem_world *w, dist_ctx *d, long *weight, cm_error *err)
{
    *weight = 1;
    if (d->balance != DEM_MPI_BALANCE_TIME)
        return CM_OK;
    const double now = cm_now(), waits = w->prof.wait_cpu;
    const long steps = w->prof.steps - d->steps_mark;
    if (d->distributed && steps > 0 && d->own_mark > 0) {
        const double c =
            ((now - d->wall_mark) - (waits - d->wait_mark) + d->added) / ((double)steps * (double)d->own_mark);
        if (isfinite(c) && c > 0.0)
            d->cost = d->cost > 0.0 ? 0.75 * d->cost + 0.25 * c : c;
    }
    d->added = 0.0; /* the marks themselves are set where the rebuild ends (dist_rebuild) */
    int rc = MPI_Allgather(&d->cost, 1, MPI_DOUBLE, d->costs, 1, MPI_DOUBLE, d->comm);
    if (rc != MPI_SUCCESS)
        return mpi_fail(err, rc, "allgather of the ranks' costs", w->step);
    double hi = 0.0;
    for (int r = 0; r < d->size; r++) {
        if (!(d->costs[r] > 0.0))
            return CM_OK;
        hi = fmax(hi, d->costs[r]);
    }
    *weight = lround(1024.0 * d->cost / hi);
    if (*weight < 1)
        *weight = 1;
    return CM_OK;
}

static int rank_of_col(const dist_ctx *d, int col)
{
    int lo = 0, hi = d->size - 1; /* bounds[lo] <= col < bounds[hi + 1] */
    while (lo < hi) {
        int mid = (lo + hi + 1) / 2;
        if (d->bounds[mid] <= col)
            lo = mid;
        else
            hi = mid - 1;
    }
    return lo;
}

/* Moves slots order[0 .. k) to 0 .. k and makes k the grain count. */
static void keep_slots(dem_world *w, const int *order, int k)
{
    dem_grains *g = &w->g;
    g->n = k;
    dem_grains_permute(w, order);
}

static int dist_rebuild(dem_world *w, cm_error *err)
{
    dist_ctx *d = w->dist_ctx;
    dem_grains *g = &w->g;
    const double t0 = cm_now(), c0 = cm_thread_cpu_now();
    int rc;
    const int own_lo = w->own_lo, own_hi = w->own_hi;
    /* 1. the global box and grid (over the owned grains of every rank) */
    double box[6] = {INFINITY, INFINITY, INFINITY, INFINITY, INFINITY, INFINITY}; /* lo, -hi */
    for (int i = own_lo; i < own_hi; i++) {
        box[0] = fmin(box[0], g->x[i]), box[3] = fmin(box[3], -g->x[i]);
        box[1] = fmin(box[1], g->y[i]), box[4] = fmin(box[4], -g->y[i]);
        box[2] = fmin(box[2], g->z[i]), box[5] = fmin(box[5], -g->z[i]);
    }
    long n_own = own_hi - own_lo, n_all = 0;
    if ((rc = MPI_Allreduce(MPI_IN_PLACE, box, 6, MPI_DOUBLE, MPI_MIN, d->comm)) != MPI_SUCCESS ||
        (rc = MPI_Allreduce(&n_own, &n_all, 1, MPI_LONG, MPI_SUM, d->comm)) != MPI_SUCCESS)
        return mpi_fail(err, rc, "allreduce of the box", w->step);
    if (n_all == 0)
        box[0] = box[1] = box[2] = box[3] = box[4] = box[5] = 0.0;
    double lo[3] = {box[0], box[1], box[2]}, hi[3] = {-box[3], -box[4], -box[5]};
    dem_grid_dims_of(lo, hi, 2.0 * w->r_max + w->skin, n_all, &w->dist_grid);
    const dem_grid_dims *gd = &w->dist_grid;
    /* 2. slabs from the grains per column */
    const int n_cols = gd->n[0];
    if (n_cols > d->cols_cap) {
        long *c = realloc(d->cols, (size_t)n_cols * sizeof *c);
        if (!c)
            return cm_fail(err, CM_ERR_NOMEM, "step %ld: out of memory for %d cell columns", w->step, n_cols);
        d->cols = c, d->cols_cap = n_cols;
    }
    long weight;
    if ((rc = grain_weight(w, d, &weight, err)))
        return rc;
    memset(d->cols, 0, (size_t)n_cols * sizeof *d->cols);
    for (int i = own_lo; i < own_hi; i++) {
        int c = dem_grid_column(gd, g->x[i]);
        d->dest[i] = c; /* the column for now */
        d->cols[c] += weight;
    }
    if ((rc = MPI_Allreduce(MPI_IN_PLACE, d->cols, n_cols, MPI_LONG, MPI_SUM, d->comm)) != MPI_SUCCESS)
        return mpi_fail(err, rc, "allreduce of the column counts", w->step);
    if ((rc = dem_mpi_slabs(d->cols, n_cols, d->size, d->bounds, err)))
        return rc;
    d->col_lo = d->bounds[d->rank], d->col_hi = d->bounds[d->rank + 1];
    /* 3. owned grains leaving: records grouped by destination, in slot order */
    memset(d->scount, 0, (size_t)d->size * sizeof *d->scount);
    memset(d->hcount, 0, (size_t)d->size * sizeof *d->hcount);
    int n_keep = 0;
    for (int i = own_lo; i < own_hi; i++) {
        d->dest[i] = rank_of_col(d, d->dest[i]);
        if (d->dest[i] == d->rank)
            d->order[n_keep++] = i;
        else
            d->scount[d->dest[i]]++;
    }
    /* springs of the pairs of leaving grains (the previous list, every pair
     * with an owned grain), to each new rank of an owned grain of the pair */
    const double *hv = w->hist_val[w->hist_cur];
    for (int p = 0; p < w->n_pairs; p++) {
        int a = w->pi[p], b = w->pj[p];
        int ra = a >= own_lo && a < own_hi ? d->dest[a] : d->rank;
        int rb = b >= own_lo && b < own_hi ? d->dest[b] : d->rank;
        if (ra != d->rank)
            d->hcount[ra]++;
        if (rb != d->rank && rb != ra)
            d->hcount[rb]++;
    }
    const size_t rs = rec_size(w);
    d->sdispl[0] = d->hdispl[0] = 0;
    for (int r = 1; r < d->size; r++) {
        d->sdispl[r] = d->sdispl[r - 1] + d->scount[r - 1];
        d->hdispl[r] = d->hdispl[r - 1] + d->hcount[r - 1];
    }
    const long n_out = d->sdispl[d->size - 1] + d->scount[d->size - 1];
    const long h_out = d->hdispl[d->size - 1] + d->hcount[d->size - 1];
    const int sr = spring_rec(w);
    if (grow(&d->sbuf, &d->sbuf_cap, (size_t)n_out * rs) ||
        grow(&d->hsbuf, &d->hsbuf_cap, (size_t)h_out * sr))
        return cm_fail(err, CM_ERR_NOMEM, "step %ld: out of memory for %ld migrating grains", w->step, n_out);
    memcpy(d->hwhere, d->sdispl, (size_t)d->size * sizeof *d->hwhere);
    for (int i = own_lo; i < own_hi; i++)
        if (d->dest[i] != d->rank)
            pack_grain(w, i, d->sbuf + (size_t)d->hwhere[d->dest[i]]++ * rs);
    memcpy(d->hwhere, d->hdispl, (size_t)d->size * sizeof *d->hwhere);
    for (int p = 0; p < w->n_pairs; p++) {
        int a = w->pi[p], b = w->pj[p];
        int ra = a >= own_lo && a < own_hi ? d->dest[a] : d->rank;
        int rb = b >= own_lo && b < own_hi ? d->dest[b] : d->rank;
        /* lower tag first: the spring of i relative to j, negated if i is the higher */
        const double sg = g->tag[a] < g->tag[b] ? 1.0 : -1.0;
        double rec[SPRING_REC_MAX];
        spring_record(w, g->tag[a], g->tag[b], sg, hv + (size_t)w->hist_stride * p, rec);
        if (ra != d->rank)
            memcpy(d->hsbuf + (size_t)d->hwhere[ra]++ * sr, rec, (size_t)sr * sizeof *rec);
        if (rb != d->rank && rb != ra)
            memcpy(d->hsbuf + (size_t)d->hwhere[rb]++ * sr, rec, (size_t)sr * sizeof *rec);
    }
    if (d->distributed)
        d->migrated += n_out, d->springs_sent += h_out;
    else
        d->scattered += n_out;
    d->distributed = 1;
    if ((rc = MPI_Alltoall(d->scount, 1, MPI_INT, d->rcount, 1, MPI_INT, d->comm)) != MPI_SUCCESS ||
        (rc = MPI_Alltoall(d->hcount, 1, MPI_INT, d->hrcount, 1, MPI_INT, d->comm)) != MPI_SUCCESS)
        return mpi_fail(err, rc, "alltoall of the migration counts", w->step);
    d->rdispl[0] = d->hrdispl[0] = 0;
    for (int r = 1; r < d->size; r++) {
        d->rdispl[r] = d->rdispl[r - 1] + d->rcount[r - 1];
        d->hrdispl[r] = d->hrdispl[r - 1] + d->hrcount[r - 1];
    }
    const long n_in = d->rdispl[d->size - 1] + d->rcount[d->size - 1];
    const long h_in = d->hrdispl[d->size - 1] + d->hrcount[d->size - 1];
    if (n_keep + n_in > g->cap)
        return cm_fail(err, CM_ERR_RANGE, "step %ld: rank %d would hold %ld grains, more than max_grains = %d",
                       w->step, d->rank, n_keep + n_in, g->cap);
    if (grow(&d->rbuf, &d->rbuf_cap, (size_t)n_in * rs) || grow(&d->hrbuf, &d->hrbuf_cap, (size_t)h_in * sr))
        return cm_fail(err, CM_ERR_NOMEM, "step %ld: out of memory for %ld arriving grains", w->step, n_in);
    /* counts and displacements in doubles (records are whole doubles) */
    for (int r = 0; r < d->size; r++) {
        d->scount[r] *= (int)rs, d->sdispl[r] *= (int)rs, d->rcount[r] *= (int)rs, d->rdispl[r] *= (int)rs;
        d->hcount[r] *= sr, d->hdispl[r] *= sr;
        d->hrcount[r] *= sr, d->hrdispl[r] *= sr;
    }
    if ((rc = MPI_Alltoallv(d->sbuf, d->scount, d->sdispl, MPI_DOUBLE, d->rbuf, d->rcount, d->rdispl, MPI_DOUBLE,
                            d->comm)) != MPI_SUCCESS ||
        (rc = MPI_Alltoallv(d->hsbuf, d->hcount, d->hdispl, MPI_DOUBLE, d->hrbuf, d->hrcount, d->hrdispl,
                            MPI_DOUBLE, d->comm)) != MPI_SUCCESS)
        return mpi_fail(err, rc, "alltoallv of the migrating grains", w->step);
    /* 4. the staying grains first (ghosts dropped), then the arrivals */
    keep_slots(w, d->order, n_keep);
    for (long k = 0; k < n_in; k++)
        unpack_grain(w, g->n++, d->rbuf + (size_t)k * rs);
    /* springs that came with them, for the carry-over of the new list */
    const int hs = w->hist_stride;
    if (grow(&d->extra_val, &d->extra_cap, (size_t)hs * (size_t)(h_in ? h_in : 1)) ||
        dem_hash_reset(&d->extra, (int)h_in))
        return cm_fail(err, CM_ERR_NOMEM, "step %ld: out of memory for %ld arriving springs", w->step, h_in);
    for (long k = 0; k < h_in; k++) {
        const double *r = d->hrbuf + (size_t)k * sr;
        int s = dem_hash_insert(&d->extra, dem_pair_key((int)r[0], (int)r[1]));
        if (d->extra.row[s] < 0) { /* a pair sent by both its grains' ranks holds the same spring */
            d->extra.row[s] = (int)k;
            memcpy(d->extra_val + (size_t)hs * k, r + 2, (size_t)hs * sizeof *r);
        }
    }
    /* 5. ghosts: the owned grains of the first column to rank - 1, of the
     * last to rank + 1 (any slot order: both sides sort them the same) */
    const int lo_rank = d->rank > 0 ? d->rank - 1 : MPI_PROC_NULL;
    const int hi_rank = d->rank + 1 < d->size ? d->rank + 1 : MPI_PROC_NULL;
    int n_ghost[2] = {0, 0}; /* from lo_rank, hi_rank */
    const int n_owned = g->n;
    for (int side = 0; side < 2; side++) {
        const int col = side == 0 ? d->col_lo : d->col_hi - 1;
        const int to = side == 0 ? lo_rank : hi_rank, from = side == 0 ? hi_rank : lo_rank;
        int ns = 0, nr = 0;
        for (int i = 0; i < n_owned; i++)
            if (dem_grid_column(gd, g->x[i]) == col)
                d->order[ns++] = i;
        if (to == MPI_PROC_NULL)
            ns = 0;
        if ((rc = MPI_Sendrecv(&ns, 1, MPI_INT, to, 1, &nr, 1, MPI_INT, from, 1, d->comm, MPI_STATUS_IGNORE)) !=
            MPI_SUCCESS)
            return mpi_fail(err, rc, "sendrecv of the ghost counts", w->step);
        if (g->n + nr > g->cap)
            return cm_fail(err, CM_ERR_RANGE, "step %ld: rank %d would hold %d grains with its ghosts, more than "
                           "max_grains = %d", w->step, d->rank, g->n + nr, g->cap);
        if (grow(&d->sbuf, &d->sbuf_cap, (size_t)ns * rs) || grow(&d->rbuf, &d->rbuf_cap, (size_t)nr * rs))
            return cm_fail(err, CM_ERR_NOMEM, "step %ld: out of memory for %d ghosts", w->step, ns + nr);
        for (int k = 0; k < ns; k++)
            pack_grain(w, d->order[k], d->sbuf + (size_t)k * rs);
        if ((rc = MPI_Sendrecv(d->sbuf, ns * (int)rs, MPI_DOUBLE, to, 2, d->rbuf, nr * (int)rs, MPI_DOUBLE, from, 2,
                               d->comm, MPI_STATUS_IGNORE)) != MPI_SUCCESS)
            return mpi_fail(err, rc, "sendrecv of the ghosts", w->step);
        for (int k = 0; k < nr; k++)
            unpack_grain(w, g->n++, d->rbuf + (size_t)k * rs);
        n_ghost[side == 0 ? 1 : 0] = nr; /* side 0 receives from hi_rank */
        if (side == 0)
            d->n_send_lo = ns;
        else
            d->n_send_hi = ns;
    }
    /* 6. the neighbour list on the global grid: the sort puts the ghosts of
     * rank - 1 first and those of rank + 1 last */
    w->n_frozen = 0;
    for (int i = 0; i < g->n; i++) {
        g->id[i] = i, g->slot_of[i] = i;
        w->n_frozen += g->frozen[i];
    }
    w->own_lo = n_ghost[0];
    w->own_hi = g->n - n_ghost[1];
    d->own_mark = w->own_hi - w->own_lo;
    w->hist_extra = &d->extra;
    w->hist_extra_val = d->extra_val;
    const double t1 = cm_now();
    w->prof.migrate += t1 - t0;
    w->prof.wait_cpu += cm_thread_cpu_now() - c0;
    rc = dem_neighbour_rebuild(w, err);
    w->hist_extra = NULL;
    w->hist_extra_val = NULL;
    if (rc)
        return rc;
    /* 7. the rows of left ghosts (their owner counts their contacts), and
     * the pairs of one process's list (rows of owned grains) over the
     * ranks: the size of the history table one process entered them in */
    long rows = 0;
    w->n_ghost_rows = 0;
    for (int p = 0; p < w->n_pairs; p++) {
        const int ghost = w->pi[p] < w->own_lo;
        rows += !ghost;
        w->n_ghost_rows += ghost && p < w->n_active_pairs;
    }
    long all_rows = 0;
    if ((rc = MPI_Reduce(&rows, &all_rows, 1, MPI_LONG, MPI_SUM, 0, d->comm)) != MPI_SUCCESS)
        return mpi_fail(err, rc, "reduce of the pair counts", w->step);
    if (d->rank == 0) {
        const int c = dem_hash_cap_for(all_rows);
        if (c > d->vcap[w->hist_cur])
            d->vcap[w->hist_cur] = c;
    }
    /* the time balance's measure starts after the rebuild (grain_weight) */
    d->wall_mark = cm_now(), d->wait_mark = w->prof.wait_cpu, d->steps_mark = w->prof.steps;
    return CM_OK;
}

/* 9 doubles per grain: position, velocity, angular velocity. */
enum { HALO_REC = 9 };

static void pack_state(const dem_grains *g, int lo, int n, double *b)
{
    const double *a[HALO_REC] = {g->x, g->y, g->z, g->vx, g->vy, g->vz, g->wx, g->wy, g->wz};
    for (int k = 0; k < HALO_REC && n > 0; k++) /* no buffer yet before the first rebuild */
        memcpy(b + (size_t)k * n, a[k] + lo, (size_t)n * sizeof *b);
}

static void unpack_state(dem_grains *g, int lo, int n, const double *b)
{
    double *a[HALO_REC] = {g->x, g->y, g->z, g->vx, g->vy, g->vz, g->wx, g->wy, g->wz};
    for (int k = 0; k < HALO_REC && n > 0; k++)
        memcpy(a[k] + lo, b + (size_t)k * n, (size_t)n * sizeof *b);
}

/* Stage "halo", after integrate: the ghosts' states from their owners and
 * the rebuild's agreement (the largest displacement and the non-finite flag
 * over every rank). On two ranks one exchange does it all: each rank posts
 * its boundary grains' states with its two values behind them to the other
 * and receives the other's, and rank 0 adds w->rider's bytes (fem_server's
 * reply in the coupled loop, which then needs no broadcast of its own): one
 * meeting of the ranks per step where there were four (two sendrecvs, the
 * allreduce, the broadcast), each of which the rank that came first waited
 * out. On more ranks: to rank - 1 and from rank + 1, then the other way,
 * then the allreduce. The same values either way (the maximum and the flag
 * are exact). */
enum { TAG_HALO = 3, TAG_HALO_UP = 4, TAG_RIDER = 7 }; /* the others: 1, 2 (rebuild), 5 (TAG_SURF), 6 (TAG_SERIES) */

static int halo_two(dem_world *w, double *maxd2, int *bad, cm_error *err)
{
    dist_ctx *d = w->dist_ctx;
    dem_grains *g = &w->g;
    dem_halo_rider *rd = w->rider;
    const int peer = 1 - d->rank;
    /* rank 0 sends its last owned grains and has ghosts after them; rank 1
     * sends its first owned grains and has ghosts before them */
    const int n_send = d->rank == 0 ? d->n_send_hi : d->n_send_lo;
    const int send_lo = d->rank == 0 ? w->own_hi - d->n_send_hi : w->own_lo;
    const int n_recv = d->rank == 0 ? g->n - w->own_hi : w->own_lo;
    const int recv_lo = d->rank == 0 ? w->own_hi : 0;
    const size_t ns = (size_t)HALO_REC * n_send + 2, nr = (size_t)HALO_REC * n_recv + 2;
    if (grow(&d->sbuf, &d->sbuf_cap, ns) || grow(&d->rbuf, &d->rbuf_cap, nr))
        return cm_fail(err, CM_ERR_NOMEM, "step %ld: out of memory for the halo", w->step);
    MPI_Request req[3];
    int nq = 0, rc;
    if ((rc = MPI_Irecv(d->rbuf, (int)nr, MPI_DOUBLE, peer, TAG_HALO, d->comm, &req[nq++])) != MPI_SUCCESS)
        return mpi_fail(err, rc, "receive of the ghost states", w->step);
    if (rd && d->rank == 1 &&
        (rc = MPI_Irecv(rd->buf, (int)rd->bytes, MPI_BYTE, 0, TAG_RIDER, d->comm, &req[nq++])) != MPI_SUCCESS)
        return mpi_fail(err, rc, "receive of the halo's rider", w->step);
    if (rd && d->rank == 0 && rd->fill) {
        const double t0 = cm_now();
        rc = rd->fill(rd->user, err);
        rd->fill_s += cm_now() - t0;
        if (rc) /* the caller stops every rank (MPI_Abort) */
            return rc;
    }
    pack_state(g, send_lo, n_send, d->sbuf);
    d->sbuf[ns - 2] = *maxd2, d->sbuf[ns - 1] = *bad ? 1.0 : 0.0;
    if ((rc = MPI_Isend(d->sbuf, (int)ns, MPI_DOUBLE, peer, TAG_HALO, d->comm, &req[nq++])) != MPI_SUCCESS)
        return mpi_fail(err, rc, "send of the ghost states", w->step);
    if (rd && d->rank == 0 &&
        (rc = MPI_Isend(rd->buf, (int)rd->bytes, MPI_BYTE, 1, TAG_RIDER, d->comm, &req[nq++])) != MPI_SUCCESS)
        return mpi_fail(err, rc, "send of the halo's rider", w->step);
    if ((rc = MPI_Waitall(nq, req, MPI_STATUSES_IGNORE)) != MPI_SUCCESS)
        return mpi_fail(err, rc, "halo exchange", w->step);
    unpack_state(g, recv_lo, n_recv, d->rbuf);
    *maxd2 = fmax(*maxd2, d->rbuf[nr - 2]);
    *bad = *bad || d->rbuf[nr - 1] != 0.0;
    if (rd)
        rd->carried = 1;
    return CM_OK;
}

static int dist_halo(dem_world *w, double *maxd2, int *bad, cm_error *err)
{
    dist_ctx *d = w->dist_ctx;
    if (d->size == 2)
        return halo_two(w, maxd2, bad, err);
    if (w->rider)
        return cm_fail(err, CM_ERR_STATE, "step %ld: a message riding the halo needs two ranks, not %d", w->step,
                       d->size);
    dem_grains *g = &w->g;
    const int lo_rank = d->rank > 0 ? d->rank - 1 : MPI_PROC_NULL;
    const int hi_rank = d->rank + 1 < d->size ? d->rank + 1 : MPI_PROC_NULL;
    const int n_lo = w->own_lo, n_hi = g->n - w->own_hi; /* ghosts from rank - 1, rank + 1 */
    /* the buffers were sized for these counts at the rebuild (whole records) */
    double *sb = d->sbuf, *rb = d->rbuf;
    int rc;
    /* to rank - 1 the first owned grains, from rank + 1 the last ghosts */
    pack_state(g, w->own_lo, d->n_send_lo, sb);
    if ((rc = MPI_Sendrecv(sb, HALO_REC * d->n_send_lo, MPI_DOUBLE, lo_rank, TAG_HALO, rb, HALO_REC * n_hi,
                           MPI_DOUBLE, hi_rank, TAG_HALO, d->comm, MPI_STATUS_IGNORE)) != MPI_SUCCESS)
        return mpi_fail(err, rc, "sendrecv of the ghost states", w->step);
    unpack_state(g, w->own_hi, n_hi, rb);
    pack_state(g, w->own_hi - d->n_send_hi, d->n_send_hi, sb);
    if ((rc = MPI_Sendrecv(sb, HALO_REC * d->n_send_hi, MPI_DOUBLE, hi_rank, TAG_HALO_UP, rb, HALO_REC * n_lo,
                           MPI_DOUBLE, lo_rank, TAG_HALO_UP, d->comm, MPI_STATUS_IGNORE)) != MPI_SUCCESS)
        return mpi_fail(err, rc, "sendrecv of the ghost states", w->step);
    unpack_state(g, 0, n_lo, rb);
    double v[2] = {*maxd2, *bad ? 1.0 : 0.0};
    if ((rc = MPI_Allreduce(MPI_IN_PLACE, v, 2, MPI_DOUBLE, MPI_MAX, d->comm)) != MPI_SUCCESS)
        return mpi_fail(err, rc, "allreduce of the displacement", w->step);
    *maxd2 = v[0];
    *bad = v[1] != 0.0;
    return CM_OK;
}

static int dist_ranks(const dem_world *w) { return ((const dist_ctx *)w->dist_ctx)->size; }

/* Stage "surf_gather", after every surface pass: the ranks' contacts
 * (dem_surface_pack: in slot order, owned grains only) to rank 0, summed
 * there in rank order, which is the global grain order (the slabs are
 * contiguous ranges of it), as one process sums its own
 * (dem_surface_sum_packed): the node forces sent to fem_server are the same
 * bits for any number of ranks. Each rank keeps its own largest overlap
 * (and its grain) for the health check: the largest over the ranks is the
 * one process's.
 * Begun after the pass, ended when the step needs it (dem_step.c): the
 * other ranks send theirs without waiting (MPI_Isend), rank 0 takes them
 * in rank order as they come (MPI_Improbe, MPI_Imrecv), so that between
 * tests each rank goes on with its grain pairs instead of waiting for the
 * slowest surface pass. */
enum { TAG_SURF = 5 };

/* The gather's time counts as a wait (dem_profile.wait_cpu). Its CPU time
 * is read from the thread's clock only where it blocks: that clock is a
 * system call, 1.3 us on this VM against 27 ns for the wall clock, and the
 * gather's ends were tested ~6 times a step between blocks of pairs, ~1 %
 * of the step on each rank (perf, session 34). A call that does not block
 * runs on its core throughout: its CPU time is its wall time. */
static int dist_surf_gather_begin(dem_world *w, cm_error *err)
{
    dist_ctx *d = w->dist_ctx;
    const double t0 = cm_now();
    const long n = dem_surface_packed_size(w);
    double **buf = d->rank == 0 ? &d->prbuf : &d->psbuf;
    size_t *cap = d->rank == 0 ? &d->prbuf_cap : &d->psbuf_cap;
    if (n > INT_MAX || grow(buf, cap, (size_t)n + 1))
        return cm_fail(err, CM_ERR_NOMEM, "step %ld: no room to pack %ld doubles of surface contacts", w->step, n);
    dem_surface_pack(w, *buf); /* rank 0's own first, the others' after them */
    d->surf_contacts += w->surf->tot.contacts;
    d->surf_got = n, d->surf_next = 1;
    int rc = MPI_SUCCESS;
    if (d->rank > 0)
        rc = MPI_Isend(d->psbuf, (int)n, MPI_DOUBLE, 0, TAG_SURF, d->comm, &d->surf_req);
    const double t = cm_now() - t0; /* no wait: packed and sent off */
    w->prof.surf_gather += t;
    w->prof.wait_cpu += t;
    return rc == MPI_SUCCESS ? CM_OK : mpi_fail(err, rc, "send of the surface contacts", w->step);
}

/* Rank 0: the next ranks' contacts in rank order, as far as they have come
 * (wait: all of them); *done once every rank's are summed. */
static int surf_take(dem_world *w, dist_ctx *d, int wait, int *done, cm_error *err)
{
    int rc = MPI_SUCCESS, flag = 1;
    *done = 0;
    while (d->surf_next < d->size) {
        if (d->surf_req == MPI_REQUEST_NULL) { /* rank surf_next's message not yet matched */
            MPI_Message msg;
            MPI_Status st;
            int cnt;
            rc = wait ? MPI_Mprobe(d->surf_next, TAG_SURF, d->comm, &msg, &st)
                      : MPI_Improbe(d->surf_next, TAG_SURF, d->comm, &flag, &msg, &st);
            if (rc != MPI_SUCCESS)
                return mpi_fail(err, rc, "probe for the surface contacts", w->step);
            if (!flag)
                return CM_OK;
            if ((rc = MPI_Get_count(&st, MPI_DOUBLE, &cnt)) != MPI_SUCCESS || cnt == MPI_UNDEFINED)
                return cm_fail(err, CM_ERR_PEER, "step %ld: rank %d sent a broken message of surface contacts",
                               w->step, d->surf_next);
            if (d->surf_got + cnt > INT_MAX || grow(&d->prbuf, &d->prbuf_cap, (size_t)(d->surf_got + cnt) + 1))
                return cm_fail(err, CM_ERR_NOMEM, "step %ld: no room for %ld doubles of surface contacts", w->step,
                               d->surf_got + cnt);
            if ((rc = MPI_Imrecv(d->prbuf + d->surf_got, cnt, MPI_DOUBLE, &msg, &d->surf_req)) != MPI_SUCCESS)
                return mpi_fail(err, rc, "receive of the surface contacts", w->step);
            d->surf_cnt = cnt;
        }
        rc = wait ? MPI_Wait(&d->surf_req, MPI_STATUS_IGNORE) : MPI_Test(&d->surf_req, &flag, MPI_STATUS_IGNORE);
        if (rc != MPI_SUCCESS)
            return mpi_fail(err, rc, "receive of the surface contacts", w->step);
        if (!flag)
            return CM_OK;
        d->surf_got += d->surf_cnt, d->surf_next++;
    }
    dem_surface *s = w->surf;
    const double max_overlap = s->tot.max_overlap;
    const int worst_grain = s->tot.worst_grain, worst_tri = s->tot.worst_tri;
    if ((rc = dem_surface_sum_packed(w, d->prbuf, d->surf_got, err)))
        return rc;
    s->tot.max_overlap = max_overlap, s->tot.worst_grain = worst_grain, s->tot.worst_tri = worst_tri;
    d->surf_doubles += d->surf_got;
    *done = 1;
    return CM_OK;
}

static int dist_surf_gather_end(dem_world *w, int wait, int *done, cm_error *err)
{
    dist_ctx *d = w->dist_ctx;
    const double t0 = cm_now(), c0 = wait ? cm_thread_cpu_now() : 0.0;
    int rc = CM_OK, flag = 1;
    if (d->rank == 0)
        rc = surf_take(w, d, wait, &flag, err);
    else {
        int mrc = wait ? MPI_Wait(&d->surf_req, MPI_STATUS_IGNORE) : MPI_Test(&d->surf_req, &flag, MPI_STATUS_IGNORE);
        if (mrc != MPI_SUCCESS)
            rc = mpi_fail(err, mrc, "send of the surface contacts", w->step);
    }
    *done = rc == CM_OK && flag;
    d->surf_gathers += *done;
    d->surf_early += *done && !wait;
    const double t = cm_now() - t0;
    w->prof.surf_gather += t;
    w->prof.wait_cpu += wait ? cm_thread_cpu_now() - c0 : t;
    return rc;
}

static void ctx_free(dist_ctx *d);

static void dist_release(dem_world *w)
{
    ctx_free(w->dist_ctx);
    w->dist = NULL;
    w->dist_ctx = NULL;
    w->wall_rec = NULL;
    w->wall_rec_nw = 0;
    w->n_ghost_rows = 0;
}

static const dem_dist_ops dist_ops = {dist_rebuild, dist_halo, dist_ranks,
                                      dist_release, dist_surf_gather_begin, dist_surf_gather_end};

static void ctx_free(dist_ctx *d)
{
    if (!d)
        return;
    if (d->surf_req != MPI_REQUEST_NULL) {
        /* stopped by an error between a surface gather's begin and end: the
         * message may still move, its buffers stay to the process's end
         * (which MPI_Abort brings) */
        MPI_Request_free(&d->surf_req);
        d->psbuf = d->prbuf = NULL;
    }
    free(d->bounds);
    free(d->costs);
    free(d->cols);
    free(d->dest);
    free(d->scount);
    free(d->sbuf);
    free(d->rbuf);
    free(d->hsbuf);
    free(d->hrbuf);
    free(d->psbuf);
    free(d->prbuf);
    dem_hash_free(&d->extra);
    free(d->extra_val);
    free(d->order);
    free(d->wall_rec);
    free(d->wsbuf);
    free(d->wrbuf);
    free(d);
}

int dem_mpi_attach(dem_world *w, MPI_Comm comm, cm_error *err)
{
    int rank, size, rc;
    MPI_Comm_rank(comm, &rank);
    MPI_Comm_size(comm, &size);
    if (w->def.reorder_every != 1)
        return cm_fail(err, CM_ERR_KEY, "dem.reorder_every = %d: a distributed run needs 1 (the global grain order)",
                       w->def.reorder_every);
    if (w->n_shaped > 0)
        return cm_fail(err, CM_ERR_STATE, "a distributed world holds spheres only (no shaped grains) for now");
    /* every rank or none holds the surface (installed before attaching) */
    int has_surf = w->surf != NULL, surf_all[2] = {0, 0}, mine[2] = {has_surf, -has_surf};
    MPI_Allreduce(mine, surf_all, 2, MPI_INT, MPI_MIN, comm);
    if (surf_all[0] != -surf_all[1])
        return cm_fail(err, CM_ERR_STATE, "rank %d: the triangle surface must be installed on every rank before "
                       "dem_mpi_attach (or on none)", rank);
    /* walls from rank 0 */
    int nw = w->n_walls;
    if ((rc = MPI_Bcast(&nw, 1, MPI_INT, 0, comm)) != MPI_SUCCESS ||
        (rc = MPI_Bcast(w->walls, (int)(nw * sizeof(dem_wall)), MPI_BYTE, 0, comm)) != MPI_SUCCESS)
        return mpi_fail(err, rc, "broadcast of the walls", w->step);
    w->n_walls = nw;
    /* radii, skin and the time-step check over every grain (rank 0's): what
     * the first step would do, done now so that every rank is prepared */
    int prc = w->prepared && rank == 0 ? CM_OK : dem_world_prepare(w, err), all = 0;
    MPI_Allreduce(&prc, &all, 1, MPI_INT, MPI_MAX, comm);
    if (prc)
        return prc;
    if (all)
        return cm_fail(err, CM_ERR_STATE, "another rank could not prepare the world");
    /* rank 0 goes on as a world of its own until its next neighbour rebuild,
     * which distributes the grains (so its bits do not change at attach) */
    /* and the clock (a world read from a checkpoint on rank 0 is past step 0) */
    double rr[7] = {w->r_min, w->r_max, w->skin, w->need_rebuild, (double)w->step, w->time, (double)w->next_tag};
    if ((rc = MPI_Bcast(rr, 7, MPI_DOUBLE, 0, comm)) != MPI_SUCCESS)
        return mpi_fail(err, rc, "broadcast of the radii", w->step);
    w->r_min = rr[0], w->r_max = rr[1], w->skin = rr[2], w->need_rebuild = rr[3] != 0.0;
    w->step = (long)rr[4], w->time = rr[5], w->next_tag = (int)rr[6];
    if (rank > 0 && w->g.n > 0)
        return cm_fail(err, CM_ERR_STATE, "rank %d: only rank 0's world may hold grains at attach (%d here)", rank,
                       w->g.n);
    dist_ctx *d = calloc(1, sizeof *d);
    if (!d)
        return cm_fail(err, CM_ERR_NOMEM, "dem_mpi_attach: out of memory");
    d->comm = comm, d->rank = rank, d->size = size;
    d->surf_req = MPI_REQUEST_NULL;
    d->bounds = calloc((size_t)size + 1, sizeof *d->bounds);
    d->costs = calloc((size_t)size, sizeof *d->costs);
    d->scount = calloc(9 * (size_t)size, sizeof *d->scount);
    d->dest = calloc((size_t)w->g.cap, sizeof *d->dest);
    d->order = calloc((size_t)w->g.cap, sizeof *d->order);
    if (!d->bounds || !d->costs || !d->scount || !d->dest || !d->order) {
        ctx_free(d);
        return cm_fail(err, CM_ERR_NOMEM, "dem_mpi_attach: out of memory");
    }
    d->sdispl = d->scount + size, d->rcount = d->scount + 2 * size, d->rdispl = d->scount + 3 * size;
    d->hcount = d->scount + 4 * size, d->hdispl = d->scount + 5 * size, d->hrcount = d->scount + 6 * size;
    d->hrdispl = d->scount + 7 * size, d->hwhere = d->scount + 8 * size;
    if (wall_rec_alloc(w, d)) {
        ctx_free(d);
        w->wall_rec = NULL;
        return cm_fail(err, CM_ERR_NOMEM, "dem_mpi_attach: out of memory for the wall contacts");
    }
    /* rank 0 has been one process so far: its history tables' sizes are one process's */
    d->vcap[0] = w->hist[0].cap, d->vcap[1] = w->hist[1].cap;
    w->n_ghost_rows = 0;
    w->dist = &dist_ops;
    w->dist_ctx = d;
    w->own_lo = 0, w->own_hi = w->g.n; /* all on rank 0 until the first rebuild */
    return CM_OK;
}

int dem_mpi_set_balance(dem_world *w, int balance)
{
    dist_ctx *d = w->dist_ctx;
    if (!w->dist || (balance != DEM_MPI_BALANCE_GRAINS && balance != DEM_MPI_BALANCE_TIME))
        return CM_ERR_STATE;
    d->balance = balance;
    return CM_OK;
}

int dem_mpi_add_busy(dem_world *w, double seconds)
{
    dist_ctx *d = w->dist_ctx;
    if (!w->dist || !(seconds >= 0.0) || !isfinite(seconds))
        return CM_ERR_STATE;
    d->added += seconds;
    return CM_OK;
}

void dem_mpi_detach(dem_world *w)
{
    if (!w->dist)
        return;
    dist_release(w);
    w->need_rebuild = 1;
}

void dem_mpi_stats_get(const dem_world *w, dem_mpi_stats *s)
{
    memset(s, 0, sizeof *s);
    const dist_ctx *d = w->dist_ctx;
    s->owned = w->dist ? w->own_hi - w->own_lo : w->g.n;
    s->ghosts = w->g.n - s->owned;
    s->ranks = 1;
    if (!d)
        return;
    s->rank = d->rank, s->ranks = d->size;
    s->col_lo = d->col_lo, s->col_hi = d->col_hi;
    s->migrated = d->migrated;
    s->scattered = d->scattered;
    s->springs_sent = d->springs_sent;
    s->cross_pairs = w->n_cross_pairs;
    s->surf_contacts = d->surf_contacts;
    s->surf_gathers = d->surf_gathers;
    s->surf_early = d->surf_early;
    s->surf_doubles = d->surf_doubles;
    s->collects = d->collects;
}

int dem_mpi_bcast(MPI_Comm comm, void *buf, size_t bytes, cm_error *err)
{
    for (size_t at = 0; at < bytes;) { /* counts are ints: pieces of at most 1 GiB */
        size_t k = bytes - at < ((size_t)1 << 30) ? bytes - at : (size_t)1 << 30;
        int rc = MPI_Bcast((char *)buf + at, (int)k, MPI_BYTE, 0, comm);
        if (rc != MPI_SUCCESS)
            return mpi_fail(err, rc, "broadcast from rank 0", -1);
        at += k;
    }
    return CM_OK;
}

static int by_tag(const void *a, const void *b)
{
    double x = ((const double *)a)[9], y = ((const double *)b)[9];
    return (x > y) - (x < y);
}

int dem_mpi_hash(dem_world *w, uint64_t *hash, cm_error *err)
{
    const dist_ctx *d = w->dist_ctx;
    if (!d) {
        *hash = dem_world_hash(w);
        return CM_OK;
    }
    enum { H = 11 }; /* dem_world_hash's values per grain: x, v, w, tag, frozen */
    const dem_grains *g = &w->g;
    int n = w->own_hi - w->own_lo, rc;
    int *counts = NULL, *displ = NULL, total = 0;
    double *mine = malloc(((size_t)n * H + 1) * sizeof *mine), *all = NULL;
    if (d->rank == 0) {
        counts = calloc(2 * (size_t)d->size, sizeof *counts);
        displ = counts ? counts + d->size : NULL;
    }
    int ok = mine && (d->rank != 0 || counts);
    for (int k = 0; ok && k < n; k++) {
        int i = w->own_lo + k;
        double v[H] = {g->x[i], g->y[i], g->z[i], g->vx[i], g->vy[i], g->vz[i], g->wx[i], g->wy[i], g->wz[i],
                       (double)g->tag[i], (double)g->frozen[i]};
        memcpy(mine + (size_t)k * H, v, sizeof v);
    }
    int cnt = n * H;
    rc = MPI_Gather(&cnt, 1, MPI_INT, counts, 1, MPI_INT, 0, d->comm);
    if (rc == MPI_SUCCESS && d->rank == 0 && counts) {
        for (int r = 0; r < d->size; r++)
            displ[r] = total, total += counts[r];
        all = malloc(((size_t)total + 1) * sizeof *all);
        ok = ok && all;
    }
    if (rc == MPI_SUCCESS)
        rc = MPI_Gatherv(mine, cnt, MPI_DOUBLE, all, counts, displ, MPI_DOUBLE, 0, d->comm);
    uint64_t h = 1469598103934665603ULL;
    if (rc == MPI_SUCCESS && d->rank == 0 && all) {
        qsort(all, (size_t)total / H, H * sizeof *all, by_tag);
        for (int k = 0; k < total / H; k++) {
            const unsigned char *b = (const unsigned char *)(all + (size_t)k * H);
            for (size_t c = 0; c < H * sizeof(double); c++) {
                h ^= b[c];
                h *= 1099511628211ULL;
            }
        }
    }
    free(mine);
    free(all);
    free(counts);
    if (rc != MPI_SUCCESS)
        return mpi_fail(err, rc, "gather of the state", w->step);
    int okall = 0;
    MPI_Allreduce(&ok, &okall, 1, MPI_INT, MPI_MIN, d->comm);
    if (!okall)
        return cm_fail(err, CM_ERR_NOMEM, "step %ld: out of memory gathering the state", w->step);
    MPI_Bcast(&h, 1, MPI_UINT64_T, 0, d->comm);
    *hash = h;
    return CM_OK;
}

static const int *g_sort_tags; /* qsort's comparison of slots by tag (rank 0, one gather at a time) */

static int slot_by_tag(const void *a, const void *b)
{
    int x = g_sort_tags[*(const int *)a], y = g_sort_tags[*(const int *)b];
    return (x > y) - (x < y);
}

/* A history table emptied at exactly `cap` entries (one process's size; 0:
 * a table never used, as a new world's). */
static int hash_exact(dem_hash *h, int cap)
{
    if (cap == 0) {
        dem_hash_free(h);
        return CM_OK;
    }
    if (h->cap != cap) {
        uint64_t *k = realloc(h->key, (size_t)cap * sizeof *k);
        if (!k)
            return CM_ERR_NOMEM;
        h->key = k;
        int *r = realloc(h->row, (size_t)cap * sizeof *r);
        if (!r)
            return CM_ERR_NOMEM;
        h->row = r;
        h->cap = cap;
    }
    memset(h->key, 0xff, (size_t)cap * sizeof *h->key);
    h->count = 0;
    return CM_OK;
}

/* The wall forces one process sums (dem_step_surface): each thread from
 * zero over its block of the grains (the stage's n grains split in
 * w->n_threads blocks), the contacts in grain order, then the threads'
 * sums added in thread order. recs: n_rec contacts in the global grain
 * order, their places among the n grains global. */
static void wall_forces_replay(dem_world *dst, int nt, const double *recs, long n_rec, long n)
{
    double part[DEM_MAX_WALLS][3];
    for (int k = 0; k < dst->n_walls; k++)
        memset(dst->walls[k].force, 0, sizeof dst->walls[k].force);
    long at = 0;
    for (int t = 0; t < nt; t++) {
        const long hi = (long)((long)n * (t + 1) / nt); /* block t: [n t / nt, n (t + 1) / nt) */
        memset(part, 0, sizeof part);
        for (; at < n_rec && recs[(size_t)at * DEM_WALL_REC] < (double)hi; at++) {
            const double *q = recs + (size_t)at * DEM_WALL_REC;
            const int k = (int)q[1];
            part[k][0] -= q[2], part[k][1] -= q[3], part[k][2] -= q[4];
        }
        for (int k = 0; k < dst->n_walls; k++)
            for (int c = 0; c < 3; c++)
                dst->walls[k].force[c] += part[k][c];
    }
}

/* What each rank sends to rank 0 first: its counts. */
enum { META_GRAINS, META_ACTIVE, META_FROZEN, META_WALL_RECS, META_WALL_GRAINS, META_GG, META_GW, META_N };

/* The whole world on rank 0 as one process holds it (collective): every
 * rank's owned grains in the global order (rank order), ids in tag order;
 * the pairs whose first grain it owns, with their springs, active ones of
 * every rank then the frozen-frozen ones (one process's list: rows in the
 * global grain order, its frozen-frozen pairs moved behind, stably); the
 * history table rebuilt at one process's size (or rank 0's own, when it
 * still holds every grain: it is one process's); the wall forces summed
 * from every rank's recorded contacts as one process sums them; the
 * grain–grain and grain–wall contact counts (each pair counted by the
 * owner of its first grain); the surface's largest overlap. dst: the view
 * (rank 0; a world made from the same scene) or, collecting, w itself. */
static int gather_into(dem_world *w, dem_world *dst, int collecting, cm_error *err)
{
    dist_ctx *d = w->dist_ctx;
    const size_t rs = rec_size(w);
    const int hs = w->hist_stride, pr = 2 + hs, own_lo = w->own_lo;
    const int n = w->own_hi - own_lo;
    int rc, ok = 1;
    /* this rank's share */
    long meta[META_N] = {n, 0, 0, 0, w->wall_rec_grains, w->contacts_gg, w->contacts_gw};
    for (int p = 0; p < w->n_pairs; p++)
        if (w->pi[p] >= own_lo)
            meta[p < w->n_active_pairs ? META_ACTIVE : META_FROZEN]++;
    if (w->wall_rec)
        for (int t = 0; t < w->n_threads; t++)
            meta[META_WALL_RECS] += w->tb[t].wall_rec_n;
    const long np = meta[META_ACTIVE] + meta[META_FROZEN], nwr = meta[META_WALL_RECS];
    if (grow(&d->sbuf, &d->sbuf_cap, (size_t)n * rs + 1) || grow(&d->hsbuf, &d->hsbuf_cap, (size_t)np * pr + 1) ||
        grow(&d->wsbuf, &d->wsbuf_cap, (size_t)nwr * DEM_WALL_REC + 1))
        ok = 0;
    double smax = w->surf ? w->surf->tot.max_overlap : 0.0, smax_all = 0.0;
    long *all = d->rank == 0 ? calloc((size_t)d->size * META_N, sizeof *all) : NULL;
    if (d->rank == 0 && !all)
        ok = 0;
    if ((rc = MPI_Gather(meta, META_N, MPI_LONG, all, META_N, MPI_LONG, 0, d->comm)) != MPI_SUCCESS ||
        (rc = MPI_Reduce(&smax, &smax_all, 1, MPI_DOUBLE, MPI_MAX, 0, d->comm)) != MPI_SUCCESS) {
        free(all);
        return mpi_fail(err, rc, "gather of the grain and pair counts", w->step);
    }
    long tot[META_N] = {0};
    if (d->rank == 0 && all) {
        for (int r = 0; r < d->size; r++)
            for (int m = 0; m < META_N; m++)
                tot[m] += all[(size_t)r * META_N + m];
        const long tp = tot[META_ACTIVE] + tot[META_FROZEN];
        ok = ok && dst && tot[META_GRAINS] <= dst->g.cap && dst->hist_stride == hs &&
             tot[META_GRAINS] * (long)rs <= INT_MAX && tp * pr <= INT_MAX &&
             tot[META_WALL_RECS] * DEM_WALL_REC <= INT_MAX && tp < INT_MAX / 8 &&
             !grow(&d->rbuf, &d->rbuf_cap, (size_t)tot[META_GRAINS] * rs + 1) &&
             !grow(&d->hrbuf, &d->hrbuf_cap, (size_t)tp * pr + 1) &&
             !grow(&d->wrbuf, &d->wrbuf_cap, (size_t)tot[META_WALL_RECS] * DEM_WALL_REC + 1) &&
             dem_pairs_reserve(dst, (int)(tp ? tp : 1)) == CM_OK &&
             (!collecting || !w->wall_rec || tot[META_WALL_RECS] <= (long)w->g.cap * w->wall_rec_nw);
        if (ok && w->surf && !dst->surf) /* the view holds the surface springs too (a checkpoint's) */
            ok = dem_surface_set(dst, w->surf->n_nodes, w->surf->x, w->surf->n_tris, w->surf->tri,
                                 w->surf->material, err) == CM_OK;
    }
    int okall = 0;
    MPI_Allreduce(&ok, &okall, 1, MPI_INT, MPI_MIN, d->comm);
    if (!okall) {
        free(all);
        return cm_fail(err, CM_ERR_NOMEM, "step %ld: no room to gather %ld grains and %ld pairs on rank 0 "
                       "(max_grains %d)", w->step, tot[META_GRAINS], tot[META_ACTIVE] + tot[META_FROZEN],
                       dst ? dst->g.cap : 0);
    }
    /* pack: grains; pairs (slots counted from the first owned grain: a right
     * ghost is the next rank's first grains), active then frozen; wall contacts */
    for (int k = 0; k < n; k++)
        pack_grain(w, own_lo + k, d->sbuf + (size_t)k * rs);
    const double *hv = w->hist_val[w->hist_cur];
    long at = 0;
    for (int part = 0; part < 2; part++)
        for (int p = part ? w->n_active_pairs : 0; p < (part ? w->n_pairs : w->n_active_pairs); p++) {
            if (w->pi[p] < own_lo)
                continue;
            double *q = d->hsbuf + (size_t)at++ * pr;
            q[0] = w->pi[p] - own_lo, q[1] = w->pj[p] - own_lo;
            memcpy(q + 2, hv + (size_t)hs * p, (size_t)hs * sizeof *q);
        }
    at = 0;
    for (int t = 0; t < w->n_threads && w->wall_rec; t++) {
        const long lo = (long)w->wall_rec_grains * t / w->n_threads;
        memcpy(d->wsbuf + (size_t)at * DEM_WALL_REC, w->wall_rec + (size_t)DEM_WALL_REC * w->wall_rec_nw * lo,
               (size_t)w->tb[t].wall_rec_n * DEM_WALL_REC * sizeof *d->wsbuf);
        at += w->tb[t].wall_rec_n;
    }
    int *gc = d->rcount, *gd = d->rdispl, *hc = d->hrcount, *hd = d->hrdispl, *wc = d->scount, *wd = d->sdispl;
    if (d->rank == 0)
        for (int r = 0, a = 0, b = 0, c = 0; r < d->size; r++) {
            const long *m = all + (size_t)r * META_N;
            gc[r] = (int)(m[META_GRAINS] * (long)rs), gd[r] = a, a += gc[r];
            hc[r] = (int)((m[META_ACTIVE] + m[META_FROZEN]) * pr), hd[r] = b, b += hc[r];
            wc[r] = (int)(m[META_WALL_RECS] * DEM_WALL_REC), wd[r] = c, c += wc[r];
        }
    if ((rc = MPI_Gatherv(d->sbuf, (int)(n * rs), MPI_DOUBLE, d->rbuf, gc, gd, MPI_DOUBLE, 0, d->comm)) !=
            MPI_SUCCESS ||
        (rc = MPI_Gatherv(d->hsbuf, (int)(np * pr), MPI_DOUBLE, d->hrbuf, hc, hd, MPI_DOUBLE, 0, d->comm)) !=
            MPI_SUCCESS ||
        (rc = MPI_Gatherv(d->wsbuf, (int)(nwr * DEM_WALL_REC), MPI_DOUBLE, d->wrbuf, wc, wd, MPI_DOUBLE, 0,
                          d->comm)) != MPI_SUCCESS) {
        free(all);
        return mpi_fail(err, rc, "gather of the grains, pairs and wall contacts", w->step);
    }
    if (d->rank != 0)
        return CM_OK;
    /* rank 0: the grains, rank order being the global order (the view
     * takes the walls first: the wall springs' layout) */
    dst->n_walls = w->n_walls;
    memcpy(dst->walls, w->walls, sizeof w->walls);
    dst->wall_stride = w->wall_stride;
    const int total = (int)tot[META_GRAINS];
    dem_grains *g = &dst->g;
    g->n = total;
    dst->n_frozen = 0;
    for (int k = 0; k < total; k++) {
        unpack_grain(dst, k, d->rbuf + (size_t)k * rs);
        dst->n_frozen += g->frozen[k];
        d->order[k] = k;
    }
    g_sort_tags = g->tag;
    qsort(d->order, (size_t)total, sizeof *d->order, slot_by_tag);
    for (int id = 0; id < total; id++)
        g->id[d->order[id]] = id, g->slot_of[id] = d->order[id];
    /* the pairs: every rank's active ones, then every rank's frozen ones */
    const int cur = w->hist_cur;
    dst->hist_cur = cur;
    double *dv = dst->hist_val[cur];
    int np_all = 0;
    for (int part = 0; part < 2; part++) {
        long base = 0, off = 0; /* the rank's first grain, its first pair record */
        for (int r = 0; r < d->size; r++) {
            const long *m = all + (size_t)r * META_N;
            const long lo = off + (part ? m[META_ACTIVE] : 0), hi = lo + m[part ? META_FROZEN : META_ACTIVE];
            for (long k = lo; k < hi; k++) {
                const double *q = d->hrbuf + (size_t)k * pr;
                dst->pi[np_all] = (int)(base + (long)q[0]), dst->pj[np_all] = (int)(base + (long)q[1]);
                memcpy(dv + (size_t)hs * np_all, q + 2, (size_t)hs * sizeof *dv);
                np_all++;
            }
            base += m[META_GRAINS];
            off += m[META_ACTIVE] + m[META_FROZEN];
        }
    }
    dst->n_pairs = np_all;
    dst->n_active_pairs = (int)tot[META_ACTIVE];
    dem_hist_orient(dst);
    /* the history table: one process's (keys entered in list order) */
    dem_hash *h = &dst->hist[cur];
    if (d->distributed) {
        if (hash_exact(h, d->vcap[cur]) || (collecting && hash_exact(&dst->hist[1 - cur], d->vcap[1 - cur]))) {
            free(all);
            return cm_fail(err, CM_ERR_NOMEM, "step %ld: out of memory for the contact history", w->step);
        }
        for (int p = 0; p < np_all; p++)
            h->row[dem_hash_insert(h, dem_pair_key(g->tag[dst->pi[p]], g->tag[dst->pj[p]]))] = p;
    } else if (dst != w) { /* rank 0 holds every grain: its table is one process's */
        const dem_hash *src = &w->hist[cur];
        if (hash_exact(h, src->cap)) {
            free(all);
            return cm_fail(err, CM_ERR_NOMEM, "step %ld: out of memory for the contact history", w->step);
        }
        if (src->cap > 0) {
            memcpy(h->key, src->key, (size_t)src->cap * sizeof *h->key);
            memcpy(h->row, src->row, (size_t)src->cap * sizeof *h->row);
        }
        h->count = src->count;
    }
    /* the wall contacts in the global order: places from each rank's first grain */
    long wbase = 0, wat = 0;
    for (int r = 0; r < d->size; r++) {
        const long *m = all + (size_t)r * META_N;
        for (long k = 0; k < m[META_WALL_RECS]; k++, wat++)
            d->wrbuf[(size_t)wat * DEM_WALL_REC] += (double)wbase;
        wbase += m[META_WALL_GRAINS];
    }
    if (d->distributed) /* otherwise rank 0 holds every grain: its wall forces are one process's */
        wall_forces_replay(dst, w->n_threads, d->wrbuf, tot[META_WALL_RECS], tot[META_WALL_GRAINS]);
    if (collecting && w->wall_rec) { /* rank 0 holds every grain's wall contacts now */
        memcpy(w->wall_rec, d->wrbuf, (size_t)tot[META_WALL_RECS] * DEM_WALL_REC * sizeof *w->wall_rec);
        for (int t = 0; t < w->n_threads; t++)
            w->tb[t].wall_rec_n = t == 0 ? (int)tot[META_WALL_RECS] : 0;
        w->wall_rec_grains = (int)tot[META_WALL_GRAINS];
    }
    dst->contacts_gg = (int)tot[META_GG], dst->contacts_gw = (int)tot[META_GW];
    if (dst->surf) { /* the series' surface columns: rank 0 summed the contacts, the largest overlap over the ranks */
        dst->surf->tot.contacts = w->surf->tot.contacts;
        dst->surf->tot.max_overlap = smax_all;
        if (dst != w) /* a slot of the view (the worst contact's grain is not named) */
            dst->surf->tot.worst_grain = 0, dst->surf->tot.worst_tri = 0;
    }
    free(all);
    if (dst == w)
        return CM_OK;
    dst->time = w->time, dst->step = w->step, dst->next_tag = w->next_tag;
    dst->r_min = w->r_min, dst->r_max = w->r_max, dst->skin = w->skin;
    dst->need_rebuild = w->need_rebuild, dst->rebuild_count = w->rebuild_count;
    dst->prof.rebuilds = w->prof.rebuilds;
    dst->n_shaped = 0;
    dst->prepared = 1;
    dst->plan.valid = 0;
    return CM_OK;
}

int dem_mpi_gather(dem_world *w, dem_world *view, cm_error *err)
{
    if (!w->dist_ctx)
        return cm_fail(err, CM_ERR_STATE, "dem_mpi_gather: the world is not distributed");
    return gather_into(w, view, 0, err);
}

enum { TAG_SERIES = 6 };

int dem_mpi_series_stats(dem_world *w, dem_stats *s, cm_error *err)
{
    dist_ctx *d = w->dist_ctx;
    if (!d || !w->dist)
        return cm_fail(err, CM_ERR_STATE, "dem_mpi_series_stats: the world is not distributed");
    const dem_grains *g = &w->g;
    const int last = d->size - 1;
    int rc;
    dem_stats part;
    memset(&part, 0, sizeof part);
    dem_world_stats_rows(w, w->own_lo, &part); /* the pairs' overlaps first: they wait for no other rank */
    /* the kinetic energies: this rank's owned grains after every grain of the ranks before */
    double ke[2] = {0.0, 0.0};
    if (d->rank > 0 &&
        (rc = MPI_Recv(ke, 2, MPI_DOUBLE, d->rank - 1, TAG_SERIES, d->comm, MPI_STATUS_IGNORE)) != MPI_SUCCESS)
        return mpi_fail(err, rc, "receive of the series' kinetic energies", w->step);
    part.ke_trans = ke[0], part.ke_rot = ke[1];
    dem_world_stats_grains(w, w->own_lo, w->own_hi, &part);
    ke[0] = part.ke_trans, ke[1] = part.ke_rot;
    const int to = d->rank < last ? d->rank + 1 : 0; /* the last rank's sums are the whole world's */
    if (last > 0 && (rc = MPI_Send(ke, 2, MPI_DOUBLE, to, TAG_SERIES, d->comm)) != MPI_SUCCESS)
        return mpi_fail(err, rc, "send of the series' kinetic energies", w->step);
    if (last > 0 && d->rank == 0 &&
        (rc = MPI_Recv(ke, 2, MPI_DOUBLE, last, TAG_SERIES, d->comm, MPI_STATUS_IGNORE)) != MPI_SUCCESS)
        return mpi_fail(err, rc, "receive of the series' kinetic energies", w->step);
    long count[4] = {w->own_hi - w->own_lo, 0, w->contacts_gg, w->contacts_gw}, count_all[4] = {0};
    for (int i = w->own_lo; i < w->own_hi; i++)
        count[1] += g->frozen[i];
    double big[2] = {part.max_overlap, w->surf ? w->surf->tot.max_overlap : 0.0}, big_all[2] = {0.0, 0.0};
    if ((rc = MPI_Reduce(count, count_all, 4, MPI_LONG, MPI_SUM, 0, d->comm)) != MPI_SUCCESS ||
        (rc = MPI_Reduce(big, big_all, 2, MPI_DOUBLE, MPI_MAX, 0, d->comm)) != MPI_SUCCESS)
        return mpi_fail(err, rc, "reduce of the series' counts and overlaps", w->step);
    memset(s, 0, sizeof *s);
    s->time = w->time, s->step = w->step;
    s->grains = (int)count_all[0], s->frozen = (int)count_all[1];
    s->ke_trans = ke[0], s->ke_rot = ke[1];
    s->contacts_gg = (int)count_all[2], s->contacts_gw = (int)count_all[3];
    s->contacts_gs = w->surf ? w->surf->tot.contacts : 0; /* rank 0 summed every rank's */
    s->max_overlap = big_all[0], s->max_overlap_surface = big_all[1];
    s->worst_surface.tag = -1;
    s->profile = w->prof;
    return CM_OK;
}

int dem_mpi_collect(dem_world *w, cm_error *err)
{
    dist_ctx *d = w->dist_ctx;
    if (!d || !w->dist)
        return cm_fail(err, CM_ERR_STATE, "dem_mpi_collect: the world is not distributed");
    /* rank 0 becomes the one process: its grains, list, springs, history
     * table, wall contacts and counts are one process's */
    int rc = gather_into(w, d->rank == 0 ? w : NULL, 1, err);
    if (rc)
        return rc;
    dem_grains *g = &w->g;
    d->collects++;
    d->distributed = 0; /* the next rebuild spreads rank 0's grains again */
    w->plan.valid = 0;
    w->n_ghost_rows = 0;
    w->n_cross_pairs = 0;
    if (d->rank != 0) { /* nothing left here: grains and springs come back at the next rebuild */
        g->n = 0;
        w->n_pairs = w->n_active_pairs = 0;
        w->own_lo = w->own_hi = 0;
        w->n_frozen = 0;
        w->need_rebuild = 1;
        w->contacts_gg = w->contacts_gw = 0;
        w->wall_rec_grains = 0;
        for (int t = 0; t < w->n_threads; t++)
            w->tb[t].wall_rec_n = 0;
        if (w->surf)
            w->surf->tot.max_overlap = 0.0;
        if (dem_hash_reset(&w->hist[w->hist_cur], 0))
            return cm_fail(err, CM_ERR_NOMEM, "step %ld: out of memory", w->step);
        return CM_OK;
    }
    w->own_lo = 0, w->own_hi = g->n;
    /* one process is between two steps here: its list current (no rebuild
     * pending); what changes the world must ask for one (dem_mpi_rejoin checks) */
    w->need_rebuild = 0;
    w->dist = NULL; /* rank 0 steps alone until dem_mpi_rejoin */
    return CM_OK;
}

/* Room for the wall contacts of every grain of a world with w->n_walls walls. */
static int wall_rec_alloc(dem_world *w, dist_ctx *d)
{
    if (w->n_walls <= w->wall_rec_nw && d->wall_rec)
        return CM_OK;
    const size_t n = (size_t)w->g.cap * (size_t)(w->n_walls ? w->n_walls : 1) * DEM_WALL_REC;
    double *b = realloc(d->wall_rec, n * sizeof *b);
    if (!b)
        return CM_ERR_NOMEM;
    d->wall_rec = w->wall_rec = b;
    w->wall_rec_nw = w->n_walls;
    return CM_OK;
}

int dem_mpi_rejoin(dem_world *w, cm_error *err)
{
    dist_ctx *d = w->dist_ctx;
    if (!d)
        return cm_fail(err, CM_ERR_STATE, "dem_mpi_rejoin: the world is not distributed");
    int rc;
    double hdr[6] = {0};
    if (d->rank == 0) {
        w->dist = &dist_ops;
        w->own_lo = 0, w->own_hi = w->g.n;
        /* rank 0 was one process since the collect: its tables' sizes are one process's */
        d->vcap[0] = w->hist[0].cap, d->vcap[1] = w->hist[1].cap;
        hdr[0] = w->need_rebuild && w->prepared, hdr[1] = w->r_min, hdr[2] = w->r_max, hdr[3] = w->skin;
        hdr[4] = w->n_walls, hdr[5] = w->next_tag;
    }
    if ((rc = MPI_Bcast(hdr, 6, MPI_DOUBLE, 0, d->comm)) != MPI_SUCCESS ||
        (rc = MPI_Bcast(w->walls, (int)((int)hdr[4] * sizeof(dem_wall)), MPI_BYTE, 0, d->comm)) != MPI_SUCCESS)
        return mpi_fail(err, rc, "broadcast of the changed world", w->step);
    if (hdr[0] == 0.0)
        return cm_fail(err, CM_ERR_STATE, "step %ld: rank 0 changed the gathered world without asking for a neighbour "
                       "rebuild: its grains cannot be spread over the ranks again", w->step);
    w->r_min = hdr[1], w->r_max = hdr[2], w->skin = hdr[3], w->n_walls = (int)hdr[4], w->next_tag = (int)hdr[5];
    w->need_rebuild = 1;
    w->walls_near_valid = 0;
    if (wall_rec_alloc(w, d))
        return cm_fail(err, CM_ERR_NOMEM, "step %ld: out of memory for the wall contacts", w->step);
    return CM_OK;
}

int dem_mpi_agree_rebuild(dem_world *w, cm_error *err)
{
    dist_ctx *d = w->dist_ctx;
    if (!d)
        return CM_OK;
    int mine = w->need_rebuild != 0, any = 0;
    int rc = MPI_Allreduce(&mine, &any, 1, MPI_INT, MPI_MAX, d->comm);
    if (rc != MPI_SUCCESS)
        return mpi_fail(err, rc, "allreduce of the rebuild flag", w->step);
    w->need_rebuild = any;
    return CM_OK;
}
