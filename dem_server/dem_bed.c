/* Terrain: random non-overlapping placement of layered grains in a box,
 * settling under gravity, and an HDF5 cache of the settled bed keyed by the
 * full text of the parameters that determine it and by a fingerprint of the
 * code that settles it (bed_code_fingerprint).
 *
 * A run starts from the same state whether its bed was just settled or read
 * from the cache: the bed is settled in a scratch world and handed to the
 * run's world exactly as a cached bed is (grains in id order, at rest, no
 * contact springs). Before, a fresh clone's first run (settled in place:
 * grains in cell order, tangential springs kept) differed from every later
 * run on the cached bed (tests/coupling tire_small: sinkage 6.4 against
 * 7.3 mm). */
#include <errno.h>
#include <hdf5.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "dem_bed.h"
#include "dem_world.h"
#include "log.h"

dem_bed_params dem_bed_params_default(void)
{
    dem_bed_params p;
    memset(&p, 0, sizeof p);
    p.side_walls = true;
    p.seed = 1;
    p.fill_fraction = 0.27;
    p.settle_ke = 1e-7;
    p.settle_min_time = 0.05;
    p.settle_max_time = 3.0;
    p.settle_friction = -1.0;
    return p;
}

/* splitmix64: small, seedable, the same on every platform */
static uint64_t rng_next(uint64_t *s)
{
    uint64_t z = (*s += 0x9e3779b97f4a7c15ULL);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
}
static double rng_uniform(uint64_t *s) { return (double)(rng_next(s) >> 11) * (1.0 / 9007199254740992.0); }

/* mean of 4/3 pi r^3 for r uniform in [a, b] */
static double mean_volume(double a, double b)
{
    if (b - a < 1e-15 * b)
        return (4.0 / 3.0) * M_PI * a * a * a;
    return (4.0 / 3.0) * M_PI * (pow(b, 4) - pow(a, 4)) / (4.0 * (b - a));
}

/* The shapes of the bed's layers, created in w in a fixed order (the same
 * for placing and for reloading a cached bed): per layer, one shape
 * (ellipsoid, explicit polyhedron) or `variants` random polyhedra, each of
 * unit volume-equivalent radius (a grain of drawn radius r is the shape
 * scaled by r). first[k]: id of layer k's first shape (-1: spheres),
 * count[k] shapes, bfac[k] = largest r_bound / r_eq (placement radius). */
static int bed_shapes(dem_world *w, const dem_bed_params *p, int *first, int *count, double *bfac, cm_error *err)
{
    for (int k = 0; k < p->n_layers; k++) {
        const dem_bed_shape *bs = &p->layers[k].shape;
        first[k] = -1, count[k] = 0, bfac[k] = 1.0;
        if (bs->type == DEM_SHAPE_SPHERE)
            continue;
        int nv = bs->type == DEM_SHAPE_POLYHEDRON && bs->n_verts == 0 ? (bs->variants > 0 ? bs->variants : 1) : 1;
        for (int v = 0; v < nv; v++) {
            dem_shape_def d;
            memset(&d, 0, sizeof d);
            int rc = CM_OK;
            if (bs->type == DEM_SHAPE_ELLIPSOID) {
                d.type = DEM_SHAPE_ELLIPSOID;
                double f = cbrt(bs->semi_axes[0] * bs->semi_axes[1] * bs->semi_axes[2]);
                for (int c = 0; c < 3; c++)
                    d.semi_axes[c] = f > 0.0 ? bs->semi_axes[c] / f : 0.0;
            } else if (bs->n_verts > 0) {
                d.type = DEM_SHAPE_POLYHEDRON;
                d.n_verts = bs->n_verts;
                memcpy(d.verts, bs->verts, sizeof d.verts);
                dem_shape_info in;
                if ((rc = dem_shape_compute(&d, &in, err)) == CM_OK)
                    for (int t = 0; t < d.n_verts; t++)
                        for (int c = 0; c < 3; c++)
                            d.verts[t][c] /= in.r_eq;
            } else {
                uint64_t seed = p->seed * 1000003ULL + (uint64_t)k * 7919ULL + (uint64_t)v;
                rc = dem_shape_random_polyhedron(seed, 1.0, bs->elongation >= 1.0 ? bs->elongation : 1.0,
                                                 bs->random_verts > 0 ? bs->random_verts : 12, &d, err);
            }
            int id;
            if (rc || (rc = dem_shape_add(w, &d, &id, err))) {
                cm_fail_prefix(err, "bed layer %d shape: ", k);
                return rc;
            }
            dem_shape_info in;
            dem_shape_get_info(w, id, &in);
            bfac[k] = fmax(bfac[k], in.r_bound / in.r_eq);
            if (v == 0)
                first[k] = id;
            count[k]++;
        }
    }
    return CM_OK;
}

int dem_bed_place(dem_world *w, const dem_bed_params *p, cm_error *err)
{
    if (w->g.n != 0)
        return cm_fail(err, CM_ERR_STATE, "bed: the world already holds %d grains", w->g.n);
    double lx = p->box_max[0] - p->box_min[0], ly = p->box_max[1] - p->box_min[1];
    double rmax = 0.0, total_h = 0.0;
    double hl[DEM_MAX_LAYERS];
    int sh_first[DEM_MAX_LAYERS], sh_count[DEM_MAX_LAYERS];
    double bfac[DEM_MAX_LAYERS];
    int rcs = bed_shapes(w, p, sh_first, sh_count, bfac, err);
    if (rcs)
        return rcs;
    long total = 0;
    for (int k = 0; k < p->n_layers; k++) {
        const dem_bed_layer *L = &p->layers[k];
        /* shaped grains are placed by their bounding spheres (bfac r) */
        double b = bfac[k];
        rmax = fmax(rmax, b * L->radius[1]);
        /* centres keep r from the side walls: fill the reachable volume */
        double a_eff = (lx - 2 * b * L->radius[1]) * (ly - 2 * b * L->radius[1]);
        hl[k] = L->count * mean_volume(b * L->radius[0], b * L->radius[1]) / (p->fill_fraction * a_eff) +
                2 * b * L->radius[1];
        total_h += hl[k];
        total += L->count;
        if (2.0 * b * L->radius[1] >= fmin(lx, ly))
            return cm_fail(err, CM_ERR_RANGE, "bed layer %d: grains of radius %g m do not fit the %g x %g m box", k,
                           L->radius[1], lx, ly);
    }
    if (total <= 0)
        return cm_fail(err, CM_ERR_RANGE, "bed: no grains to place (%d layers, none with a count > 0): give "
                       "dem.bed.layers at least one layer with a count", p->n_layers);
    if (total > w->g.cap)
        return cm_fail(err, CM_ERR_RANGE, "bed: %ld grains but the world holds at most %d", total, w->g.cap);
    /* placement grid: cells of 2 rmax, a linked list per cell */
    double h = 2.0 * rmax;
    int nx = (int)(lx / h) + 1, ny = (int)(ly / h) + 1, nz = (int)(total_h / h) + 1;
    long ncell = (long)nx * ny * nz;
    if (ncell > 200000000L)
        return cm_fail(err, CM_ERR_RANGE, "bed: placement grid of %ld cells is too large", ncell);
    int *head = malloc((size_t)ncell * sizeof *head);
    int *next = malloc((size_t)total * sizeof *next);
    double *pos = malloc((size_t)total * 4 * sizeof *pos);
    int *mat_of = malloc((size_t)total * sizeof *mat_of);
    double *qsc = malloc((size_t)total * 6 * sizeof *qsc); /* q[4], scale, shape id */
    if (!head || !next || !pos || !mat_of || !qsc) {
        free(head), free(next), free(pos), free(mat_of), free(qsc);
        return cm_fail(err, CM_ERR_NOMEM, "bed: out of memory for %ld grains", total);
    }
    memset(head, 0xff, (size_t)ncell * sizeof *head);
    uint64_t rs = p->seed * 0x2545F4914F6CDD1DULL + 1;
    int n = 0, rc = CM_OK;
    double z0 = p->box_min[2];
    for (int k = 0; k < p->n_layers && rc == CM_OK; k++) {
        const dem_bed_layer *L = &p->layers[k];
        for (int c = 0; c < L->count; c++) {
            double r = L->radius[0] + (L->radius[1] - L->radius[0]) * rng_uniform(&rs);
            double r_eq = r;
            if (sh_first[k] >= 0) { /* shape variant, uniform random orientation (Shoemake) */
                int v = sh_count[k] > 1 ? (int)(rng_uniform(&rs) * sh_count[k]) : 0;
                dem_shape_info in;
                dem_shape_get_info(w, sh_first[k] + (v < sh_count[k] ? v : sh_count[k] - 1), &in);
                double u1 = rng_uniform(&rs), u2 = 2 * M_PI * rng_uniform(&rs), u3 = 2 * M_PI * rng_uniform(&rs);
                double *qq = qsc + 6 * n;
                qq[0] = sqrt(1 - u1) * sin(u2), qq[1] = sqrt(1 - u1) * cos(u2);
                qq[2] = sqrt(u1) * sin(u3), qq[3] = sqrt(u1) * cos(u3);
                qq[4] = r_eq;
                qq[5] = sh_first[k] + (v < sh_count[k] ? v : sh_count[k] - 1);
                r = r_eq * in.r_bound / in.r_eq; /* placement by the bounding sphere */
            } else {
                qsc[6 * n + 5] = -1;
            }
            int placed = 0;
            for (int tries = 0; tries < 100000 && !placed; tries++) {
                double x = p->box_min[0] + r + (lx - 2 * r) * rng_uniform(&rs);
                double y = p->box_min[1] + r + (ly - 2 * r) * rng_uniform(&rs);
                double z = z0 + r + (hl[k] - 2 * r) * rng_uniform(&rs);
                int cx = (int)((x - p->box_min[0]) / h), cy = (int)((y - p->box_min[1]) / h),
                    cz = (int)((z - p->box_min[2]) / h);
                int ok = 1;
                for (int dz = -1; dz <= 1 && ok; dz++)
                    for (int dy = -1; dy <= 1 && ok; dy++)
                        for (int dx = -1; dx <= 1 && ok; dx++) {
                            int X = cx + dx, Y = cy + dy, Z = cz + dz;
                            if (X < 0 || Y < 0 || Z < 0 || X >= nx || Y >= ny || Z >= nz)
                                continue;
                            for (int j = head[((long)Z * ny + Y) * nx + X]; j >= 0 && ok; j = next[j]) {
                                double ex = x - pos[4 * j], ey = y - pos[4 * j + 1], ez = z - pos[4 * j + 2];
                                double rr = r + pos[4 * j + 3];
                                ok = ex * ex + ey * ey + ez * ez >= rr * rr;
                            }
                        }
                if (!ok)
                    continue;
                long cell = ((long)cz * ny + cy) * nx + cx;
                pos[4 * n] = x, pos[4 * n + 1] = y, pos[4 * n + 2] = z, pos[4 * n + 3] = r;
                mat_of[n] = p->material;
                next[n] = head[cell];
                head[cell] = n;
                n++;
                placed = 1;
            }
            if (!placed) {
                rc = cm_fail(err, CM_ERR_RANGE,
                             "bed layer %d: placed only %d of %d grains without overlap; lower dem.bed.fill_fraction "
                             "(now %g)",
                             k, c, L->count, p->fill_fraction);
                break;
            }
        }
        z0 += hl[k];
    }
    for (int i = 0; i < n && rc == CM_OK; i++) {
        const double *qq = qsc + 6 * i;
        rc = qq[5] < 0 ? dem_grain_add(w, pos + 4 * i, pos[4 * i + 3], mat_of[i], NULL, err)
                       : dem_grain_add_shape(w, pos + 4 * i, qq, (int)qq[5], qq[4], mat_of[i], NULL, err);
    }
    free(head), free(next), free(pos), free(mat_of), free(qsc);
    return rc;
}

int dem_bed_add_walls(dem_world *w, const dem_bed_params *p, cm_error *err)
{
    const double *lo = p->box_min, *hi = p->box_max;
    double pts[5][3] = {{lo[0], lo[1], lo[2]}, {lo[0], lo[1], lo[2]}, {hi[0], hi[1], lo[2]}, {lo[0], lo[1], lo[2]},
                        {hi[0], hi[1], lo[2]}};
    double nrm[5][3] = {{0, 0, 1}, {1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}};
    int n = p->side_walls ? 5 : 1;
    for (int k = 0; k < n; k++) {
        int rc = dem_wall_add(w, pts[k], nrm[k], p->wall_material, err);
        if (rc)
            return rc;
    }
    return CM_OK;
}

int dem_bed_settle(dem_world *w, const dem_bed_params *p, dem_bed_progress cb, void *user, cm_error *err)
{
    double dt_run = w->def.dt;
    if (p->settle_dt > 0.0) {
        w->def.dt = p->settle_dt;
        w->prepared = 0;
    }
    /* settle_friction: every pair lubricated while settling, the
     * materials' coefficients back afterwards */
    const int lubricated = p->settle_friction >= 0.0;
    dem_pair_coef kept[DEM_MAX_MATERIALS][DEM_MAX_MATERIALS];
    memcpy(kept, w->coef, sizeof kept);
    for (int a = 0; lubricated && a < w->n_mat; a++)
        for (int b = 0; b < w->n_mat; b++)
            w->coef[a][b].mu = p->settle_friction, w->coef[a][b].mu_roll = 0.0;
    int rc = CM_OK;
    double ke_grain = INFINITY;
    double t_start = w->time;
    for (;;) {
        for (int k = 0; k < 100 && rc == CM_OK; k++)
            rc = dem_step(w, err);
        if (rc) {
            cm_fail_prefix(err, "settling the bed: ");
            break;
        }
        dem_stats st;
        dem_world_stats(w, &st);
        ke_grain = (st.ke_trans + st.ke_rot) / (w->g.n ? w->g.n : 1);
        if (cb && cb(w, user)) {
            rc = cm_fail(err, CM_ERR_STATE, "settling the bed: aborted at t = %g s", w->time);
            break;
        }
        double t = w->time - t_start;
        if (t >= p->settle_min_time && ke_grain < p->settle_ke)
            break;
        if (t > p->settle_max_time) {
            rc = cm_fail(err, CM_ERR_NUMERIC,
                         "bed did not settle within settle_max_time = %g s: KE per grain %g J > settle_ke = %g J",
                         p->settle_max_time, ke_grain, p->settle_ke);
            break;
        }
    }
    if (rc == CM_OK)
        cm_log_info("bed settled: %d grains, t = %.4f s (%ld steps), KE/grain = %.3g J", w->g.n, w->time - t_start,
                    w->step, ke_grain);
    if (lubricated)
        memcpy(w->coef, kept, sizeof kept);
    /* the settled state is the start of a run: at rest, clock at zero */
    for (int i = 0; i < w->g.n; i++)
        w->g.vx[i] = w->g.vy[i] = w->g.vz[i] = w->g.wx[i] = w->g.wy[i] = w->g.wz[i] = 0.0;
    w->time = 0.0;
    w->step = 0;
    if (w->def.dt != dt_run) {
        w->def.dt = dt_run;
        w->prepared = 0;
    }
    return rc;
}

void dem_bed_params_text(const dem_world *w, const dem_bed_params *p, char *buf, int len)
{
    int o = 0;
#define PUT(...) (o += snprintf(buf + o, o < len ? (size_t)(len - o) : 0, __VA_ARGS__))
    PUT("dem-bed-v1;box=%.17g,%.17g,%.17g,%.17g,%.17g,%.17g;", p->box_min[0], p->box_min[1], p->box_min[2],
        p->box_max[0], p->box_max[1], p->box_max[2]);
    for (int k = 0; k < p->n_layers; k++) {
        PUT("layer%d=%d:%.17g:%.17g;", k, p->layers[k].count, p->layers[k].radius[0], p->layers[k].radius[1]);
        const dem_bed_shape *bs = &p->layers[k].shape;
        if (bs->type != DEM_SHAPE_SPHERE) { /* sphere beds keep their v1 text (caches stay valid) */
            uint64_t vh = 1469598103934665603ULL;
            const unsigned char *b = (const unsigned char *)bs->verts;
            for (size_t t = 0; t < (size_t)bs->n_verts * 3 * sizeof(double); t++)
                vh = (vh ^ b[t]) * 1099511628211ULL;
            PUT("shape%d=%d:%.17g,%.17g,%.17g:%d:%016llx:%.17g:%d:%d;", k, bs->type, bs->semi_axes[0],
                bs->semi_axes[1], bs->semi_axes[2], bs->n_verts, (unsigned long long)vh, bs->elongation,
                bs->random_verts, bs->variants);
        }
    }
    int mats[2] = {p->material, p->wall_material};
    for (int k = 0; k < 2; k++) {
        const dem_material *m = dem_world_material(w, mats[k]);
        if (m)
            PUT("mat%d=%.17g,%.17g,%.17g,%.17g,%.17g,%.17g;", k, m->density, m->young, m->poisson, m->restitution,
                m->friction, m->rolling_friction);
    }
    const dem_world_def *d = dem_world_get_def(w);
    /* the run's step only where it settles the bed: with settle_dt the bed
     * is the same for any run step (and its cache serves them all) */
    PUT("side=%d;seed=%llu;fill=%.17g;ke=%.17g;tmin=%.17g;tmax=%.17g;sdt=%.17g;dt=%.17g;g=%.17g,%.17g,%.17g;damp=%d",
        (int)p->side_walls, (unsigned long long)p->seed, p->fill_fraction, p->settle_ke, p->settle_min_time,
        p->settle_max_time, p->settle_dt, p->settle_dt > 0.0 ? p->settle_dt : d->dt, d->gravity[0], d->gravity[1],
        d->gravity[2], d->damping);
    if (d->rolling_model != DEM_ROLLING_CONSTANT_TORQUE) /* the default's text is unchanged: its caches stay valid */
        PUT(";roll=%d", d->rolling_model);
    if (p->settle_friction >= 0.0) /* likewise */
        PUT(";sfric=%.17g", p->settle_friction);
#undef PUT
}

static uint64_t fnv1a(const char *s)
{
    uint64_t h = 1469598103934665603ULL;
    for (; *s; s++) {
        h ^= (unsigned char)*s;
        h *= 1099511628211ULL;
    }
    return h;
}

/* ---- HDF5 -------------------------------------------------------------- */

static int h5_write(hid_t f, const char *name, hid_t type, int rank, const hsize_t *dims, const void *data)
{
    hid_t sp = H5Screate_simple(rank, dims, NULL);
    hid_t ds = H5Dcreate2(f, name, type, sp, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    herr_t st = ds < 0 ? -1 : H5Dwrite(ds, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, data);
    if (ds >= 0)
        H5Dclose(ds);
    H5Sclose(sp);
    return st < 0 ? -1 : 0;
}

static int h5_attr_string(hid_t obj, const char *name, const char *text)
{
    hid_t t = H5Tcopy(H5T_C_S1);
    H5Tset_size(t, strlen(text) + 1);
    hid_t sp = H5Screate(H5S_SCALAR);
    hid_t a = H5Acreate2(obj, name, t, sp, H5P_DEFAULT, H5P_DEFAULT);
    herr_t st = a < 0 ? -1 : H5Awrite(a, t, text);
    if (a >= 0)
        H5Aclose(a);
    H5Sclose(sp);
    H5Tclose(t);
    return st < 0 ? -1 : 0;
}

/* A bed as stored: per grain in id order, position, radius, material and,
 * for shaped grains, orientation, shape id (-1 sphere) and scale. */
typedef struct bed_arrays {
    long n;
    double *xyz, *rad, *q, *sc;
    int *mat, *sh;
} bed_arrays;

static void bed_arrays_free(bed_arrays *a)
{
    free(a->xyz), free(a->rad), free(a->q), free(a->sc), free(a->mat), free(a->sh);
    memset(a, 0, sizeof *a);
}

static int bed_arrays_alloc(bed_arrays *a, long n, int shaped, const char *what, cm_error *err)
{
    memset(a, 0, sizeof *a);
    a->n = n;
    a->xyz = malloc((size_t)n * 3 * sizeof *a->xyz);
    a->rad = malloc((size_t)n * sizeof *a->rad);
    a->mat = malloc((size_t)n * sizeof *a->mat);
    if (shaped) {
        a->q = malloc((size_t)n * 4 * sizeof *a->q);
        a->sc = malloc((size_t)n * sizeof *a->sc);
        a->sh = malloc((size_t)n * sizeof *a->sh);
    }
    if (!a->xyz || !a->rad || !a->mat || (shaped && (!a->q || !a->sc || !a->sh))) {
        bed_arrays_free(a);
        return cm_fail(err, CM_ERR_NOMEM, "%s: out of memory", what);
    }
    return CM_OK;
}

static int bed_arrays_from_world(const dem_world *w, bed_arrays *a, cm_error *err)
{
    const dem_grains *g = &w->g;
    int rc = bed_arrays_alloc(a, g->n, w->n_shaped > 0, "bed", err);
    for (int id = 0; id < g->n && rc == CM_OK; id++) { /* in id order: a reload gives the same ids */
        int i = g->slot_of[id];
        a->xyz[3 * id] = g->x[i], a->xyz[3 * id + 1] = g->y[i], a->xyz[3 * id + 2] = g->z[i];
        a->rad[id] = g->r[i];
        a->mat[id] = g->mat[i];
        if (a->q) {
            memcpy(a->q + 4 * id, g->q + 4 * i, 4 * sizeof *a->q);
            a->sc[id] = g->sc[i];
            a->sh[id] = g->shape[i];
        }
    }
    return rc;
}

/* Adds the grains of a into w (no grains yet), creating the bed's shapes
 * first in the same order as when it was placed (the same shape ids). */
static int bed_arrays_add(dem_world *w, const dem_bed_params *p, const bed_arrays *a, const char *what, cm_error *err)
{
    int sh_first[DEM_MAX_LAYERS], sh_count[DEM_MAX_LAYERS];
    double bfac[DEM_MAX_LAYERS];
    int rc = CM_OK;
    if (a->q)
        rc = bed_shapes(w, p, sh_first, sh_count, bfac, err);
    for (long i = 0; i < a->n && rc == CM_OK; i++) {
        const double *x = a->xyz + 3 * i;
        if (!isfinite(x[0]) || !isfinite(x[1]) || !isfinite(x[2]) || !(a->rad[i] > 0.0))
            rc = cm_fail(err, CM_ERR_PARSE, "%s: grain %ld has a bad position or radius", what, i);
        else if (a->q && a->sh[i] >= 0) /* checked by dem_grain_add_shape (shape id, scale) */
            rc = dem_grain_add_shape(w, x, a->q + 4 * i, a->sh[i], a->sc[i], a->mat[i], NULL, err);
        else
            rc = dem_grain_add(w, x, a->rad[i], a->mat[i], NULL, err);
        if (rc && err)
            cm_fail_prefix(err, "%s: ", what);
    }
    return rc;
}

/* The settling code's fingerprint: the state hash of a miniature of the bed
 * (the same materials, layer shapes, seed, fill fraction, world settings and
 * settling step; at most 24 grains per layer in a box 12 largest radii
 * wide) after 300 steps. It changes whenever the arithmetic that settles
 * this bed changes: contact laws, integration, placement, the compiler's
 * code, and libm's results on this CPU (glibc picks FMA or non-FMA variants
 * of sin, cos, log, pow, atan2 by CPU, and they differ in the last bit).
 * A hand-bumped version constant would miss all but the first. */
static int bed_code_fingerprint(const dem_world *w, const dem_bed_params *p, uint64_t *fp, cm_error *err)
{
    dem_bed_params m = *p;
    m.file[0] = '\0';
    double rmax = 0.0;
    long total = 0;
    for (int k = 0; k < m.n_layers; k++) {
        m.layers[k].count = m.layers[k].count < 24 ? m.layers[k].count : 24;
        rmax = fmax(rmax, m.layers[k].radius[1]);
        total += m.layers[k].count;
    }
    double bfac = 1.0;
    for (int k = 0; k < m.n_layers; k++)
        if (m.layers[k].shape.type != DEM_SHAPE_SPHERE)
            bfac = 3.0; /* room for elongated shapes' bounding spheres */
    for (int d = 0; d < 2; d++)
        m.box_max[d] = m.box_min[d] + 12.0 * bfac * rmax;
    dem_world_def def = w->def;
    def.max_grains = (int)total + 1;
    if (m.settle_dt > 0.0)
        def.dt = m.settle_dt;
    dem_world *s = NULL;
    int rc = dem_world_create(&def, w->n_mat, w->mat, &s, err);
    if (rc == CM_OK)
        rc = dem_bed_add_walls(s, &m, err);
    if (rc == CM_OK)
        rc = dem_bed_place(s, &m, err);
    for (int k = 0; k < 300 && rc == CM_OK; k++)
        rc = dem_step(s, err);
    if (rc == CM_OK)
        *fp = dem_world_hash(s) ^ (0x9e3779b97f4a7c15ULL * (uint64_t)s->g.n);
    else
        cm_fail_prefix(err, "the settling code's fingerprint (a miniature bed): ");
    dem_world_destroy(&s);
    return rc;
}


static int bed_save_arrays(const dem_world *w, const dem_bed_params *p, const bed_arrays *a, uint64_t fp,
                           const char *path, cm_error *err)
{
    char text[4096];
    dem_bed_params_text(w, p, text, sizeof text);
    /* write to a temporary name, then rename: a crash never leaves a half bed */
    char tmp[1100];
    snprintf(tmp, sizeof tmp, "%s.tmp%ld", path, (long)getpid());
    int rc = CM_OK;
    H5Eset_auto2(H5E_DEFAULT, NULL, NULL);
    hid_t f = H5Fcreate(tmp, H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    if (f < 0)
        return cm_fail(err, CM_ERR_IO, "%s: cannot create HDF5 file", tmp);
    hsize_t d2[2] = {(hsize_t)a->n, 3}, d1[1] = {(hsize_t)a->n}, d4[2] = {(hsize_t)a->n, 4};
    char hs[32], fs[32];
    snprintf(hs, sizeof hs, "%016llx", (unsigned long long)fnv1a(text));
    snprintf(fs, sizeof fs, "%016llx", (unsigned long long)fp);
    if (h5_write(f, "position", H5T_NATIVE_DOUBLE, 2, d2, a->xyz) ||
        h5_write(f, "radius", H5T_NATIVE_DOUBLE, 1, d1, a->rad) ||
        h5_write(f, "material", H5T_NATIVE_INT, 1, d1, a->mat) || h5_attr_string(f, "params", text) ||
        h5_attr_string(f, "params_hash", hs) || h5_attr_string(f, "code_fingerprint", fs))
        rc = cm_fail(err, CM_ERR_IO, "%s: writing the bed failed", tmp);
    /* shaped grains: orientation (n x 4), shape id (-1 sphere) and scale */
    if (rc == CM_OK && a->q &&
        (h5_write(f, "orientation", H5T_NATIVE_DOUBLE, 2, d4, a->q) || h5_write(f, "shape", H5T_NATIVE_INT, 1, d1, a->sh) ||
         h5_write(f, "scale", H5T_NATIVE_DOUBLE, 1, d1, a->sc)))
        rc = cm_fail(err, CM_ERR_IO, "%s: writing the grain shapes failed", tmp);
    if (H5Fclose(f) < 0 && rc == CM_OK)
        rc = cm_fail(err, CM_ERR_IO, "%s: closing failed", tmp);
    if (rc == CM_OK && rename(tmp, path) != 0)
        rc = cm_fail(err, CM_ERR_IO, "%s: rename from %s: %s", path, tmp, strerror(errno));
    if (rc)
        unlink(tmp);
    return rc;
}

int dem_bed_save(const dem_world *w, const dem_bed_params *p, const char *path, cm_error *err)
{
    uint64_t fp = 0;
    bed_arrays a;
    int rc = bed_code_fingerprint(w, p, &fp, err);
    if (rc == CM_OK && (rc = bed_arrays_from_world(w, &a, err)) == CM_OK) {
        rc = bed_save_arrays(w, p, &a, fp, path, err);
        bed_arrays_free(&a);
    }
    return rc;
}

static int h5_read_attr_string(hid_t obj, const char *name, char *buf, size_t len)
{
    hid_t a = H5Aopen(obj, name, H5P_DEFAULT);
    if (a < 0)
        return -1;
    hid_t t = H5Aget_type(a);
    size_t sz = H5Tget_size(t);
    int rc = -1;
    if (sz > 0 && sz <= len && H5Tget_class(t) == H5T_STRING) {
        hid_t mt = H5Tcopy(H5T_C_S1);
        H5Tset_size(mt, sz);
        rc = H5Aread(a, mt, buf) < 0 ? -1 : 0;
        buf[sz - 1] = '\0';
        H5Tclose(mt);
    }
    H5Tclose(t);
    H5Aclose(a);
    return rc;
}

static int h5_read(hid_t f, const char *name, hid_t type, int rank, hsize_t *dims_expect, void *data)
{
    hid_t ds = H5Dopen2(f, name, H5P_DEFAULT);
    if (ds < 0)
        return -1;
    hid_t sp = H5Dget_space(ds);
    hsize_t dims[2] = {0, 0};
    int ok = H5Sget_simple_extent_ndims(sp) == rank && H5Sget_simple_extent_dims(sp, dims, NULL) == rank &&
             dims[0] == dims_expect[0] && (rank == 1 || dims[1] == dims_expect[1]);
    herr_t st = ok ? H5Dread(ds, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, data) : -1;
    H5Sclose(sp);
    H5Dclose(ds);
    return st < 0 ? -1 : 0;
}

int dem_bed_load(dem_world *w, const dem_bed_params *p, const char *path, cm_error *err)
{
    if (w->g.n != 0)
        return cm_fail(err, CM_ERR_STATE, "bed %s: the world already holds %d grains", path, w->g.n);
    char want[4096], have[4096], fp_have[64] = "";
    dem_bed_params_text(w, p, want, sizeof want);
    H5Eset_auto2(H5E_DEFAULT, NULL, NULL);
    hid_t f = H5Fopen(path, H5F_ACC_RDONLY, H5P_DEFAULT);
    if (f < 0)
        return cm_fail(err, CM_ERR_IO, "%s: cannot open as HDF5", path);
    if (h5_read_attr_string(f, "params", have, sizeof have) || strcmp(have, want) != 0) {
        H5Fclose(f);
        return cm_fail(err, CM_WARN_STALE, "holds a bed of other parameters"); /* the caller regenerates it */
    }
    /* The code that settled it: a bed this build would not produce is not served. */
    uint64_t fp = 0;
    int rc = bed_code_fingerprint(w, p, &fp, err);
    if (rc) {
        H5Fclose(f);
        return rc;
    }
    char fp_want[32];
    snprintf(fp_want, sizeof fp_want, "%016llx", (unsigned long long)fp);
    if (h5_read_attr_string(f, "code_fingerprint", fp_have, sizeof fp_have) || strcmp(fp_have, fp_want) != 0) {
        H5Fclose(f);
        return cm_fail(err, CM_WARN_STALE,
                       "was settled by other code (settling-code fingerprint %s, this build's %s: the contact laws, "
                       "integration, compiler or CPU-dependent libm results differ)",
                       fp_have[0] ? fp_have : "none", fp_want);
    }
    long total = 0;
    for (int k = 0; k < p->n_layers; k++)
        total += p->layers[k].count;
    /* the file's own size; the parameters already fix it, but check (defensive) */
    hid_t ds = H5Dopen2(f, "radius", H5P_DEFAULT);
    hsize_t dims[2] = {0, 3};
    if (ds >= 0) {
        hid_t sp = H5Dget_space(ds);
        H5Sget_simple_extent_dims(sp, dims, NULL);
        H5Sclose(sp);
        H5Dclose(ds);
    }
    long n = (long)dims[0];
    if (ds < 0 || n < 1 || n > total || n > w->g.cap) {
        H5Fclose(f);
        return cm_fail(err, CM_ERR_PARSE, "%s: radius dataset missing or of bad size %ld (expected <= %ld)", path, n,
                       total);
    }
    int shaped = 0;
    for (int k = 0; k < p->n_layers; k++)
        shaped |= p->layers[k].shape.type != DEM_SHAPE_SPHERE;
    bed_arrays a;
    hsize_t d2[2] = {(hsize_t)n, 3}, d1[1] = {(hsize_t)n}, d4[2] = {(hsize_t)n, 4};
    if ((rc = bed_arrays_alloc(&a, n, shaped, path, err)) == CM_OK) {
        if (h5_read(f, "position", H5T_NATIVE_DOUBLE, 2, d2, a.xyz) || h5_read(f, "radius", H5T_NATIVE_DOUBLE, 1, d1, a.rad) ||
            h5_read(f, "material", H5T_NATIVE_INT, 1, d1, a.mat))
            rc = cm_fail(err, CM_ERR_PARSE, "%s: position/radius/material datasets unreadable", path);
        else if (shaped && (h5_read(f, "orientation", H5T_NATIVE_DOUBLE, 2, d4, a.q) ||
                            h5_read(f, "shape", H5T_NATIVE_INT, 1, d1, a.sh) ||
                            h5_read(f, "scale", H5T_NATIVE_DOUBLE, 1, d1, a.sc)))
            rc = cm_fail(err, CM_ERR_PARSE, "%s: orientation/shape/scale datasets unreadable", path);
    }
    H5Fclose(f);
    if (rc == CM_OK)
        rc = bed_arrays_add(w, p, &a, path, err);
    bed_arrays_free(&a);
    return rc;
}

/* Places and settles the bed in a scratch world with w's settings,
 * materials and walls (w itself holds no grains yet), then hands it over as
 * a cached bed would be, saving it first when p->file is set. */
static int bed_settle_scratch(dem_world *w, const dem_bed_params *p, dem_bed_progress cb, void *user, cm_error *err)
{
    dem_world *s = NULL;
    int rc = dem_world_create(&w->def, w->n_mat, w->mat, &s, err);
    for (int k = 0; k < w->n_walls && rc == CM_OK; k++) /* the scene's walls and the box, in w's order */
        rc = dem_wall_add(s, w->walls[k].p, w->walls[k].n, w->walls[k].material, err);
    if (rc == CM_OK && (rc = dem_bed_place(s, p, err)) == CM_OK)
        rc = dem_bed_settle(s, p, cb, user, err);
    bed_arrays a;
    memset(&a, 0, sizeof a);
    if (rc == CM_OK)
        rc = bed_arrays_from_world(s, &a, err);
    if (rc == CM_OK && p->file[0]) {
        uint64_t fp = 0;
        if ((rc = bed_code_fingerprint(w, p, &fp, err)) == CM_OK &&
            (rc = bed_save_arrays(w, p, &a, fp, p->file, err)) == CM_OK)
            cm_log_info("bed saved to %s (settling-code fingerprint %016llx)", p->file, (unsigned long long)fp);
    }
    if (rc == CM_OK)
        rc = bed_arrays_add(w, p, &a, "settled bed", err);
    bed_arrays_free(&a);
    dem_world_destroy(&s);
    return rc;
}

int dem_bed_build(dem_world *w, const dem_bed_params *p, dem_bed_progress cb, void *user, bool *loaded, cm_error *err)
{
    *loaded = false;
    int rc = dem_bed_add_walls(w, p, err);
    if (rc)
        return rc;
    if (p->file[0] && access(p->file, R_OK) == 0) {
        cm_error why = {0};
        rc = dem_bed_load(w, p, p->file, &why);
        if (rc == CM_OK) {
            *loaded = true;
            cm_log_info("bed loaded from %s (%d grains)", p->file, w->g.n);
            return CM_OK;
        }
        if (rc != CM_WARN_STALE) { /* an error, not a stale file (a warning, > 0) */
            if (err)
                *err = why;
            return rc;
        }
        cm_log_info("bed file %s %s: settling the bed again", p->file, why.msg);
    }
    return bed_settle_scratch(w, p, cb, user, err);
}

double dem_bed_height(const dem_world *w)
{
    /* mean over columns (2 r_max square, covering the grains' footprint) of
     * the highest grain top in each column */
    const dem_grains *g = &w->g;
    int n = g->n;
    if (n == 0)
        return 0.0;
    double lo[2] = {INFINITY, INFINITY}, hi[2] = {-INFINITY, -INFINITY}, rmax = 0.0;
    for (int i = 0; i < n; i++) {
        lo[0] = fmin(lo[0], g->x[i]), hi[0] = fmax(hi[0], g->x[i]);
        lo[1] = fmin(lo[1], g->y[i]), hi[1] = fmax(hi[1], g->y[i]);
        rmax = fmax(rmax, g->r[i]);
    }
    double h = 2.0 * rmax;
    int nx = (int)((hi[0] - lo[0]) / h) + 1, ny = (int)((hi[1] - lo[1]) / h) + 1;
    if ((long)nx * ny > 100000000L)
        return NAN;
    double *top = malloc((size_t)nx * ny * sizeof *top);
    if (!top)
        return NAN;
    for (long k = 0; k < (long)nx * ny; k++)
        top[k] = -INFINITY;
    for (int i = 0; i < n; i++) {
        int cx = (int)((g->x[i] - lo[0]) / h), cy = (int)((g->y[i] - lo[1]) / h);
        double t = g->z[i] + g->r[i];
        if (t > top[(long)cy * nx + cx])
            top[(long)cy * nx + cx] = t;
    }
    double s = 0.0;
    int m = 0;
    for (long k = 0; k < (long)nx * ny; k++)
        if (isfinite(top[k]))
            s += top[k], m++;
    free(top);
    return s / m;
}
