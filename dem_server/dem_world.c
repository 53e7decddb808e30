/* The world: its lifecycle, grains (ids, slots, removal, addition, shapes),
 * walls, the triangle surface's entry points and the diagnostics. The rest
 * of the library by job: dem_step.c (the time step), dem_pairs.c (the
 * grain–grain stage), dem_grid.c (neighbour list), dem_timestep.c (time-step
 * limits), dem_surface.c (grain–triangle contacts), dem_shape*.c (shaped
 * grains), dem_bed.c, dem_output.c, dem_config.c, dem_window.c. */
#include "dem_world.h"

#include <assert.h>
#include <float.h>
#include <limits.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "log.h"
#include "timer.h"
#include "vec3.h"

#ifdef _OPENMP
#include <omp.h>
#endif

dem_world_def dem_world_def_default(void)
{
    dem_world_def d;
    memset(&d, 0, sizeof d);
    d.dt = 1e-5;
    d.gravity[2] = -9.81;
    d.max_grains = 1000;
    d.threads = 1;
    d.skin = 0.0;
    d.damping = DEM_DAMPING_CALIBRATED;
    d.impact_velocity = 1.0;
    d.dt_safety_rayleigh = 0.3;
    d.dt_safety_hertz = 0.1;
    d.allow_unstable = false;
    d.reorder_every = 1;
    d.gather_test_every = 1.25e-4;
    return d;
}

static int check_material(const dem_material *m, int k, cm_error *err)
{
    if (!(m->young > 0.0) || !(m->poisson >= 0.0 && m->poisson < 0.5) || !(m->restitution > 0.0 && m->restitution <= 1.0) ||
        !(m->friction >= 0.0) || !(m->rolling_friction >= 0.0) || !(m->density >= 0.0))
        return cm_fail(err, CM_ERR_RANGE,
                       "material %d: need E > 0, 0 <= nu < 0.5, 0 < e <= 1, mu >= 0, mu_r >= 0, density >= 0 "
                       "(E = %g, nu = %g, e = %g, mu = %g, mu_r = %g, density = %g)",
                       k, m->young, m->poisson, m->restitution, m->friction, m->rolling_friction, m->density);
    return CM_OK;
}

static void *xcalloc(size_t n, size_t sz, int *bad)
{
    void *p = calloc(n ? n : 1, sz);
    if (!p)
        *bad = 1;
    return p;
}

int dem_world_create(const dem_world_def *def, int n_materials, const dem_material *materials, dem_world **out,
                     cm_error *err)
{
    *out = NULL;
    if (n_materials < 1 || n_materials > DEM_MAX_MATERIALS)
        return cm_fail(err, CM_ERR_RANGE, "dem_world_create: %d materials (1..%d)", n_materials, DEM_MAX_MATERIALS);
    if (!(def->dt > 0.0) || def->max_grains < 1)
        return cm_fail(err, CM_ERR_RANGE, "dem_world_create: dt = %g s, max_grains = %d", def->dt, def->max_grains);
    if (def->rolling_model != DEM_ROLLING_CONSTANT_TORQUE && def->rolling_model != DEM_ROLLING_SPRING)
        return cm_fail(err, CM_ERR_RANGE, "dem_world_create: rolling model %d (0 constant torque, 1 spring)",
                       def->rolling_model);
    for (int k = 0; k < n_materials; k++) {
        int rc = check_material(&materials[k], k, err);
        if (rc)
            return rc;
    }
    dem_world *w = calloc(1, sizeof *w);
    if (!w)
        return cm_fail(err, CM_ERR_NOMEM, "dem_world_create: out of memory");
    w->def = *def;
    w->hist_stride = def->rolling_model == DEM_ROLLING_SPRING ? DEM_HIST_MAX : DEM_HIST_TANGENTIAL;
    w->n_mat = n_materials;
    memcpy(w->mat, materials, (size_t)n_materials * sizeof *materials);
    /* pair coefficients; the damping calibration (a few ms) is done once
     * per distinct pair restitution */
    double memo_e[DEM_MAX_MATERIALS * DEM_MAX_MATERIALS], memo_g[DEM_MAX_MATERIALS * DEM_MAX_MATERIALS];
    int n_memo = 0;
    for (int a = 0; a < n_materials; a++)
        for (int b = 0; b < n_materials; b++) {
            dem_pair_coef *c = &w->coef[a][b];
            dem_pair_coef_make(&materials[a], &materials[b], c);
            int k = 0;
            while (k < n_memo && memo_e[k] != c->e)
                k++;
            if (k == n_memo) {
                memo_e[k] = c->e;
                memo_g[k] = dem_damping_for_restitution(c->e, def->damping);
                n_memo++;
            }
            c->gamma_n = memo_g[k];
            c->gamma_t = memo_g[k]; /* eq. 27 in its standard form: same factor with S_t */
        }
#ifdef _OPENMP
    w->n_threads = def->threads > 0 ? def->threads : omp_get_max_threads();
#else
    w->n_threads = 1;
#endif
    int cap = def->max_grains, bad = 0;
    dem_grains *g = &w->g;
    g->cap = cap;
    double **dbl[] = {&g->x, &g->y, &g->z, &g->vx, &g->vy, &g->vz, &g->wx, &g->wy, &g->wz, &g->fx, &g->fy, &g->fz,
                      &g->tx, &g->ty, &g->tz, &g->r, &g->inv_m, &g->inv_i, &g->x0, &g->y0, &g->z0};
    /* One block for the hot per-grain doubles, each array starting 192 bytes
     * (three cache lines) further into a 4 KiB page than the previous: arrays
     * allocated apart all start at the same page offset, so x[i], y[i], ...
     * fx[i] fall into the same L1 set and evict each other (a 2x slower
     * narrow phase, measured with cachegrind). */
    const size_t n_dbl = sizeof dbl / sizeof dbl[0];
    const size_t stride = ((size_t)cap * sizeof(double) + 4095) / 4096 * 4096 + 192;
    _Static_assert(sizeof dbl / sizeof dbl[0] * 192 <= 4096, "the stagger of the grain arrays fits in a page");
    g->block = aligned_alloc(4096, (n_dbl * stride + 4095) / 4096 * 4096); /* C17: a multiple of the alignment */
    if (!g->block)
        bad = 1;
    else
        for (size_t k = 0; k < n_dbl; k++) {
            *dbl[k] = (double *)((char *)g->block + k * stride);
            memset(*dbl[k], 0, (size_t)cap * sizeof(double));
        }
    g->q = xcalloc(4 * (size_t)cap, sizeof(double), &bad);
    g->wall_hist = xcalloc((size_t)cap * DEM_MAX_WALLS * w->hist_stride, sizeof(double), &bad);
    g->mat = xcalloc((size_t)cap, sizeof(int), &bad);
    g->wall_mask = xcalloc((size_t)cap, sizeof(uint32_t), &bad);
    g->wall_near = xcalloc((size_t)cap, sizeof(uint32_t), &bad);
    w->wall_list = xcalloc((size_t)cap, sizeof(int), &bad);
    g->id = xcalloc((size_t)cap, sizeof(int), &bad);
    g->slot_of = xcalloc((size_t)cap, sizeof(int), &bad);
    g->tag = xcalloc((size_t)cap, sizeof(int), &bad);
    g->frozen = xcalloc((size_t)cap, 1, &bad);
    g->surf_count = xcalloc((size_t)cap, sizeof(int), &bad);
    g->shape = xcalloc((size_t)cap, sizeof(int), &bad);
    g->sc = xcalloc((size_t)cap, sizeof(double), &bad);
    g->inertia = xcalloc(3 * (size_t)cap, sizeof(double), &bad);
    g->angmom = xcalloc(3 * (size_t)cap, sizeof(double), &bad);
    w->grain_cell = xcalloc((size_t)cap, sizeof(int), &bad);
    dem_pair_plan *pl = &w->plan;
    const size_t nb1 = (size_t)DEM_PLAN_BLOCKS_PER_THREAD * (size_t)w->n_threads + 1; /* blocks + 1 */
    int *pstart = xcalloc(9 * nb1, sizeof(int), &bad);
    pl->own_start = pstart, pl->cross_start = pstart ? pstart + nb1 : NULL;
    pl->in_start = pstart ? pstart + 2 * nb1 : NULL;
    pl->count = pstart ? pstart + 3 * nb1 : NULL;
    pl->claim = pstart ? pstart + 6 * nb1 : NULL;
    pl->slot_lo = pstart ? pstart + 8 * nb1 : NULL;
    w->tb = xcalloc((size_t)w->n_threads, sizeof *w->tb, &bad);
    w->scratch = xcalloc((size_t)cap * DEM_SCRATCH_PER_GRAIN, sizeof(double), &bad);
    w->sparse_held = xcalloc((size_t)cap, 1, &bad);
    for (int t = 1; t < w->n_threads && !bad; t++)
        w->tb[t].f = xcalloc(6 * (size_t)cap, sizeof(double), &bad);
    if (bad) {
        dem_world_destroy(&w);
        return cm_fail(err, CM_ERR_NOMEM, "dem_world_create: out of memory for %d grains", cap);
    }
    w->need_rebuild = 1;
    w->walls_near_valid = 0;
    *out = w;
    return CM_OK;
}

void dem_world_destroy(dem_world **wp)
{
    dem_world *w = *wp;
    if (!w)
        return;
    if (w->dist && w->dist->release)
        w->dist->release(w);
    dem_grains *g = &w->g;
    free(g->block); /* x .. z0 */
    free(g->q);
    free(g->wall_hist);
    free(g->mat);
    free(g->wall_mask);
    free(g->wall_near);
    free(w->wall_list);
    free(g->id);
    free(g->slot_of);
    free(g->tag);
    free(g->frozen);
    free(g->surf_count);
    free(g->shape);
    free(g->sc);
    free(g->inertia);
    free(g->angmom);
    free(w->shapes);
    free(w->pose);
    free(w->grain_cell);
    free(w->cell_start);
    free(w->cell_items);
    free(w->pi);
    free(w->pj);
    free(w->plan.cross);
    free(w->plan.in);
    free(w->plan.own_start); /* and the other per-block arrays: one allocation */
    free(w->plan.cf);
    free(w->plan.con);
    free(w->hist_val[0]);
    free(w->hist_val[1]);
    free(w->hist_ori[0]);
    free(w->hist_ori[1]);
    free(w->held);
    dem_hash_free(&w->hist[0]);
    dem_hash_free(&w->hist[1]);
    if (w->tb)
        for (int t = 0; t < w->n_threads; t++)
            free(w->tb[t].f), free(w->tb[t].rows);
    free(w->tb);
    free(w->scratch);
    free(w->sparse_held);
    free(w->cell_pos);
    free(w->cell_rmax);
    dem_surface_free(&w->surf);
    free(w);
    *wp = NULL;
}

const dem_world_def *dem_world_get_def(const dem_world *w) { return &w->def; }
const dem_material *dem_world_material(const dem_world *w, int k)
{
    return k >= 0 && k < w->n_mat ? &w->mat[k] : NULL;
}
int dem_world_material_count(const dem_world *w) { return w->n_mat; }

/* ---- grains ------------------------------------------------------------ */

int dem_grain_add(dem_world *w, const double x[3], double radius, int material, int *id, cm_error *err)
{
    dem_grains *g = &w->g;
    if (g->n >= g->cap)
        return cm_fail(err, CM_ERR_RANGE, "dem_grain_add: world is full (max_grains = %d)", g->cap);
    if (!(radius > 0.0) || material < 0 || material >= w->n_mat || !isfinite(x[0]) || !isfinite(x[1]) ||
        !isfinite(x[2]))
        return cm_fail(err, CM_ERR_RANGE, "dem_grain_add: grain %d: radius %g, material %d (of %d)", g->n, radius,
                       material, w->n_mat);
    if (!(w->mat[material].density > 0.0))
        return cm_fail(err, CM_ERR_RANGE, "dem_grain_add: material %d has no density", material);
    int i = g->n++;
    g->x[i] = x[0], g->y[i] = x[1], g->z[i] = x[2];
    g->vx[i] = g->vy[i] = g->vz[i] = 0.0;
    g->wx[i] = g->wy[i] = g->wz[i] = 0.0;
    g->fx[i] = g->fy[i] = g->fz[i] = g->tx[i] = g->ty[i] = g->tz[i] = 0.0;
    double m = w->mat[material].density * (4.0 / 3.0) * M_PI * radius * radius * radius;
    g->r[i] = radius;
    g->inv_m[i] = 1.0 / m;
    g->inv_i[i] = 1.0 / (0.4 * m * radius * radius);
    g->mat[i] = material;
    g->q[4 * i] = 1.0, g->q[4 * i + 1] = g->q[4 * i + 2] = g->q[4 * i + 3] = 0.0;
    g->id[i] = i;
    g->slot_of[i] = i;
    g->tag[i] = w->next_tag++;
    g->frozen[i] = 0;
    memset(g->wall_hist + (size_t)i * w->wall_stride * w->hist_stride, 0,
           (size_t)w->wall_stride * w->hist_stride * sizeof(double));
    g->wall_mask[i] = 0;
    g->surf_count[i] = 0;
    if (w->surf) /* the slot may have held a removed grain */
        memset(w->surf->hist + (size_t)i * DEM_SURF_SLOTS * DEM_SURF_SLOT_SIZE, 0,
               DEM_SURF_SLOTS * DEM_SURF_SLOT_SIZE * sizeof *w->surf->hist);
    g->shape[i] = -1;
    g->sc[i] = 1.0;
    for (int k = 0; k < 3; k++) {
        g->inertia[3 * i + k] = 0.4 * m * radius * radius;
        g->angmom[3 * i + k] = 0.0;
    }
    w->need_rebuild = 1;
    w->walls_near_valid = 0;
    w->prepared = 0;
    if (id)
        *id = i;
    return CM_OK;
}

int dem_shape_add(dem_world *w, const dem_shape_def *def, int *shape, cm_error *err)
{
    if (w->n_shapes >= DEM_MAX_SHAPES)
        return cm_fail(err, CM_ERR_RANGE, "dem_shape_add: at most %d shapes", DEM_MAX_SHAPES);
    if (!w->shapes && !(w->shapes = malloc(DEM_MAX_SHAPES * sizeof *w->shapes)))
        return cm_fail(err, CM_ERR_NOMEM, "dem_shape_add: out of memory");
    int rc = dem_shape_build(def, &w->shapes[w->n_shapes], err);
    if (rc) {
        cm_fail_prefix(err, "dem_shape_add: shape %d: ", w->n_shapes);
        return rc;
    }
    if (shape)
        *shape = w->n_shapes;
    w->n_shapes++;
    return CM_OK;
}

int dem_shape_get_info(const dem_world *w, int shape, dem_shape_info *info)
{
    if (shape < 0 || shape >= w->n_shapes)
        return CM_ERR_RANGE;
    *info = w->shapes[shape].info;
    return CM_OK;
}

/* L = R diag(I) R^T omega (world frame) */
static void angmom_from_omega(const double q[4], const double I[3], const double om[3], double L[3])
{
    double R[9], b[3];
    dem_quat_to_mat(q, R);
    for (int k = 0; k < 3; k++)
        b[k] = (R[k] * om[0] + R[3 + k] * om[1] + R[6 + k] * om[2]) * I[k];
    for (int k = 0; k < 3; k++)
        L[k] = R[3 * k] * b[0] + R[3 * k + 1] * b[1] + R[3 * k + 2] * b[2];
}

int dem_grain_add_shape(dem_world *w, const double x[3], const double q[4], int shape, double scale, int material,
                        int *id, cm_error *err)
{
    if (shape < 0 || shape >= w->n_shapes || !(scale > 0.0) || !isfinite(scale))
        return cm_fail(err, CM_ERR_RANGE, "dem_grain_add_shape: grain %d: shape %d (of %d), scale %g", w->g.n, shape,
                       w->n_shapes, scale);
    const dem_shape *s = &w->shapes[shape];
    if (s->type == DEM_SHAPE_SPHERE) /* the sphere path */
        return dem_grain_add(w, x, s->info.r_bound * scale, material, id, err);
    int i = w->g.n;
    int rc = dem_grain_add(w, x, s->info.r_bound * scale, material, id, err);
    if (rc)
        return rc;
    dem_grains *g = &w->g;
    double rho = w->mat[material].density, s3 = scale * scale * scale, s5 = s3 * scale * scale;
    double m = rho * s->info.volume * s3;
    g->inv_m[i] = 1.0 / m;
    double isum = 0.0;
    for (int k = 0; k < 3; k++) {
        g->inertia[3 * i + k] = rho * s->info.inertia[k] * s5;
        isum += g->inertia[3 * i + k];
    }
    g->inv_i[i] = 3.0 / isum; /* mean moment: rolling resistance and diagnostics only */
    g->shape[i] = shape;
    g->sc[i] = scale;
    if (q)
        dem_grain_set_orientation(w, i, q);
    w->n_shaped++;
    return CM_OK;
}

int dem_grain_set_orientation(dem_world *w, int id, const double q[4])
{
    dem_grains *g = &w->g;
    if (id < 0 || id >= g->n)
        return CM_ERR_RANGE;
    int i = g->slot_of[id];
    double n = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    if (!(n > 0.0) || !isfinite(n))
        return CM_ERR_RANGE;
    for (int k = 0; k < 4; k++)
        g->q[4 * i + k] = q[k] / n;
    if (g->shape[i] >= 0) { /* keep omega, recompute L for the new pose */
        double om[3] = {g->wx[i], g->wy[i], g->wz[i]};
        angmom_from_omega(g->q + 4 * i, g->inertia + 3 * i, om, g->angmom + 3 * i);
    }
    return CM_OK;
}

int dem_grain_count(const dem_world *w) { return w->g.n; }

const char *dem_kernels_name(const dem_world *w)
{
    switch (dem_kernels_of(&w->def)) {
    case DEM_KERNELS_AVX512:
        return "avx512";
    case DEM_KERNELS_AVX2:
        return "avx2";
    default:
        return "portable";
    }
}

int dem_grain_get(const dem_world *w, int id, dem_grain_state *s)
{
    const dem_grains *g = &w->g;
    if (id < 0 || id >= g->n)
        return CM_ERR_RANGE;
    int i = g->slot_of[id];
    s->x[0] = g->x[i], s->x[1] = g->y[i], s->x[2] = g->z[i];
    s->v[0] = g->vx[i], s->v[1] = g->vy[i], s->v[2] = g->vz[i];
    s->w[0] = g->wx[i], s->w[1] = g->wy[i], s->w[2] = g->wz[i];
    s->f[0] = g->fx[i], s->f[1] = g->fy[i], s->f[2] = g->fz[i];
    s->t[0] = g->tx[i], s->t[1] = g->ty[i], s->t[2] = g->tz[i];
    memcpy(s->q, g->q + 4 * i, 4 * sizeof(double));
    s->radius = g->r[i];
    s->mass = 1.0 / g->inv_m[i];
    s->material = g->mat[i];
    s->shape = g->shape[i];
    s->scale = g->sc[i];
    memcpy(s->inertia, g->inertia + 3 * i, sizeof s->inertia);
    return CM_OK;
}

int dem_grain_set(dem_world *w, int id, const double x[3], const double v[3], const double omega[3])
{
    dem_grains *g = &w->g;
    if (id < 0 || id >= g->n)
        return CM_ERR_RANGE;
    int i = g->slot_of[id];
    if (x) {
        g->x[i] = x[0], g->y[i] = x[1], g->z[i] = x[2];
        w->need_rebuild = 1;
        w->walls_near_valid = 0;
    }
    if (v)
        g->vx[i] = v[0], g->vy[i] = v[1], g->vz[i] = v[2];
    if (omega) {
        g->wx[i] = omega[0], g->wy[i] = omega[1], g->wz[i] = omega[2];
        if (g->shape[i] >= 0)
            angmom_from_omega(g->q + 4 * i, g->inertia + 3 * i, omega, g->angmom + 3 * i);
    }
    return CM_OK;
}

/* An ascending order (order_ascends) as runs of consecutive slots: run k
 * moves r[3k + 2] slots from r[3k + 1] to r[3k]. */
typedef struct slot_runs {
    const int *r;
    int n;
} slot_runs;

/* Rows of `row` bytes: a[k] <- a[order[k]] through tmp, this thread's share
 * of k (called inside a parallel region, or alone); the worksharing loops'
 * barriers keep tmp whole from one array to the next. Inlined with `row`
 * constant, each row is a plain move. fw (one thread only): the order
 * ascends, so each run's source lies at or after its place and is not yet
 * overwritten: the runs move in place, front to back, once each. */
static inline __attribute__((always_inline)) void permute_rows(void *a, void *tmp, const size_t row, const int *order,
                                                               int n, const slot_runs *fw)
{
    char *s = a, *d = tmp;
    if (fw) {
        for (int k = 0; k < fw->n; k++) {
            const int *r = fw->r + 3 * k;
            if (r[0] != r[1])
                memmove(s + row * (size_t)r[0], s + row * (size_t)r[1], row * (size_t)r[2]);
        }
        return;
    }
#ifdef _OPENMP
#pragma omp for schedule(static)
#endif
    for (int i = 0; i < n; i++)
        memcpy(d + row * (size_t)i, s + row * (size_t)order[i], row);
#ifdef _OPENMP
#pragma omp for schedule(static)
#endif
    for (int i = 0; i < n; i++)
        memcpy(s + row * (size_t)i, d + row * (size_t)i, row);
}

/* 1 if a row of `len` doubles has a bit set (-0.0 counts: moved rows keep
 * their bits). */
static inline int row_nonzero(const double *a, size_t len)
{
    uint64_t u = 0;
    for (size_t k = 0; k < len; k++) {
        uint64_t b;
        memcpy(&b, a + k, sizeof b);
        u |= b;
    }
    return u != 0;
}

/* Whether row i of a sparse history may hold a bit. The wall springs keep
 * their own record (mask: wall_mask, a wall's bit set while its spring is
 * non-zero; the walls stage clears a spring when it clears the bit, every
 * other writer moves or zeroes a row with its mask), so their rows are not
 * read to be found zero. The surface springs' rows are read (mask NULL):
 * their counts (surf_count) parted from the rows while the window's seam
 * relaxation re-sorted with the surface detached (a debug build of the
 * counts as marks showed it; fixed in dem_window.c, session 32). The counts
 * could mark these rows too once a debug run shows them consistent on
 * every path. */
static inline int row_marked(const uint32_t *mask, const double *a, size_t len, int i)
{
    return mask ? mask[i] != 0 : row_nonzero(a + len * (size_t)i, len);
}

/* permute_rows for rows of `len` doubles that are mostly zero (the wall and
 * surface springs: a few grains in a hundred touch a wall or the tire),
 * by one thread, before the masks themselves move: the marked rows
 * gathered into tmp, then every row of the result either one of them or
 * zeroed where its old row was marked. Moved this way, the rows of a
 * re-sort cost a read or two each instead of two copies (session 27, the
 * paper scene: the ranks' time in memmove 3.5 -> 1.9 %); the wall rows are
 * not even read unless their mask is set (session 32). A debug build
 * checks that every unmarked wall row it passes over is zero. held: n bytes
 * of work space. forward: in place, front to back, as permute_rows. */
static void permute_sparse_rows(double *a, double *tmp, unsigned char *held, size_t len, const int *order, int n,
                                const uint32_t *mask, int forward)
{
    if (forward) {
        for (int i = 0; i < n; i++) {
            const int o = order[i];
            if (o == i) { /* stays */
                assert(!mask || mask[o] || !row_nonzero(a + len * (size_t)o, len));
                continue;
            }
            const int marked = row_marked(mask, a, len, o);
            assert(marked || !row_nonzero(a + len * (size_t)o, len));
            double *dst = a + len * (size_t)i;
            if (marked)
                memcpy(dst, a + len * (size_t)o, len * sizeof *a);
            else if (row_marked(mask, a, len, i))
                memset(dst, 0, len * sizeof *a);
        }
        return;
    }
    size_t k = 0;
    for (int i = 0; i < n; i++) {
        const double *src = a + len * (size_t)order[i];
        held[i] = (unsigned char)row_marked(mask, a, len, order[i]);
        assert(held[i] || !row_nonzero(src, len));
        if (held[i])
            memcpy(tmp + len * k++, src, len * sizeof *a);
    }
    k = 0;
    for (int i = 0; i < n; i++) {
        double *dst = a + len * (size_t)i;
        if (held[i])
            memcpy(dst, tmp + len * k++, len * sizeof *a);
        else if (row_marked(mask, a, len, i))
            memset(dst, 0, len * sizeof *a);
    }
}

/* 1 if order ascends (grains dropped, the others kept in their order): then
 * order[k] >= k, and the moves can be made in place, front to back. */
static int order_ascends(const int *order, int n)
{
    for (int k = 1; k < n; k++)
        if (order[k] <= order[k - 1])
            return 0;
    return n == 0 || order[0] >= 0;
}

/* The runs of an ascending order into r (3 ints a run, at most n runs). */
static slot_runs slot_runs_of(const int *order, int n, int *r)
{
    int k = 0;
    for (int i = 0; i < n; k++) {
        int len = 1;
        while (i + len < n && order[i + len] == order[i] + len)
            len++;
        r[3 * k] = i, r[3 * k + 1] = order[i], r[3 * k + 2] = len;
        i += len;
    }
    return (slot_runs){r, k};
}

/* Moves grain data so that slot k holds the grain previously in order[k]
 * (over the world's threads when there are many grains; in place by one
 * thread where the order ascends, as keeping a rank's staying grains does). */
void dem_grains_permute(dem_world *w, const int *order)
{
    dem_grains *g = &w->g;
    const int n = g->n;
    const int threads = w->n_threads > 1 && n >= 4096, fw = !threads && order_ascends(order, n);
    double *tmp = w->scratch; /* cap * DEM_SCRATCH_PER_GRAIN doubles: no allocation in the loop */
    double *dbl[] = {g->x,  g->y,  g->z,  g->vx, g->vy, g->vz,    g->wx,    g->wy, g->wz, g->fx, g->fy,
                     g->fz, g->tx, g->ty, g->tz, g->r,  g->inv_m, g->inv_i, g->x0, g->y0, g->z0, g->sc};
    int *ints[] = {g->mat, g->id, g->surf_count, g->shape, g->tag};
    const size_t wh = (size_t)w->wall_stride * w->hist_stride, sh = DEM_SURF_SLOTS * DEM_SURF_SLOT_SIZE;
    /* ascending: the runs in the scratch space, which the in-place moves leave unused */
    _Static_assert(DEM_SCRATCH_PER_GRAIN * sizeof(double) >= 3 * sizeof(int), "scratch holds a run per grain");
    const slot_runs runs = fw ? slot_runs_of(order, n, (int *)(void *)tmp) : (slot_runs){NULL, 0};
    const slot_runs *rw = fw ? &runs : NULL;
#ifdef _OPENMP
#pragma omp parallel num_threads(w->n_threads) if (threads)
#endif
    {
        /* first, while the wall masks are the old slots' */
#ifdef _OPENMP
#pragma omp single
#endif
        {
            permute_sparse_rows(g->wall_hist, tmp, w->sparse_held, wh, order, n, g->wall_mask, fw);
            if (w->surf)
                permute_sparse_rows(w->surf->hist, tmp, w->sparse_held, sh, order, n, NULL, fw);
        }
        for (size_t k = 0; k < sizeof dbl / sizeof dbl[0]; k++)
            permute_rows(dbl[k], tmp, sizeof(double), order, n, rw);
        for (size_t k = 0; k < sizeof ints / sizeof ints[0]; k++)
            permute_rows(ints[k], tmp, sizeof(int), order, n, rw);
        permute_rows(g->wall_mask, tmp, sizeof *g->wall_mask, order, n, rw);
        permute_rows(g->frozen, tmp, sizeof *g->frozen, order, n, rw);
        permute_rows(g->q, tmp, 4 * sizeof(double), order, n, rw);
        permute_rows(g->inertia, tmp, 3 * sizeof(double), order, n, rw);
        permute_rows(g->angmom, tmp, 3 * sizeof(double), order, n, rw);
#ifdef _OPENMP
#pragma omp for schedule(static)
#endif
        for (int i = 0; i < n; i++)
            g->slot_of[g->id[i]] = i;
    }
}

/* ---- removing and adding grains ---------------------------------------- */

int dem_grain_tag(const dem_world *w, int id)
{
    if (id < 0 || id >= w->g.n)
        return -1;
    return w->g.tag[w->g.slot_of[id]];
}

/* The pair list after grains_compact: the pairs of two survivors, in their
 * order (active ones first, as the list keeps them), renamed to the new
 * slots, each with its spring row and orientation moved along, and the
 * history table re-entered for them (its capacity kept: dem_hash_reset
 * only grows a table, and the survivors are fewer). The list is never
 * stepped with (the world is rebuilt first); it keeps the state whole, so
 * that a checkpoint or a gather taken now holds every surviving spring, and
 * the next rebuild carries them over as from any list. Emptying the list
 * instead left the table pointing at spring rows no one saved. */
static int pairs_compact(dem_world *w, const int *new_slot)
{
    dem_hash *h = &w->hist[w->hist_cur];
    double *hv = w->hist_val[w->hist_cur];
    unsigned char *ori = w->hist_ori[w->hist_cur];
    const size_t hs = (size_t)w->hist_stride;
    int np = 0, na = 0;
    for (int p = 0; p < w->n_pairs; p++) {
        const int a = new_slot[w->pi[p]], b = new_slot[w->pj[p]];
        if (a < 0 || b < 0)
            continue;
        w->pi[np] = a, w->pj[np] = b;
        memmove(hv + hs * np, hv + hs * p, hs * sizeof *hv);
        ori[np] = ori[p];
        na += p < w->n_active_pairs;
        np++;
    }
    w->n_pairs = np, w->n_active_pairs = na;
    w->plan.valid = 0;
    if (dem_hash_reset(h, np)) /* grows only when the table was smaller than its list */
        return CM_ERR_NOMEM;
    for (int p = 0; p < np; p++)
        h->row[dem_hash_insert(h, dem_pair_key(w->g.tag[w->pi[p]], w->g.tag[w->pj[p]]))] = p;
    return CM_OK;
}

/* Compacts the grain arrays to the slots with keep[slot] != 0, in place and
 * in slot order (the destination never passes the source). Survivors get
 * dense ids in their old id order; every per-grain side array moves along.
 * keep and the id and slot maps live in w->scratch (no allocation).
 * Returns the number removed, or -1 when the history table could not grow. */
static int grains_compact(dem_world *w, const unsigned char *keep)
{
    dem_grains *g = &w->g;
    const int n = g->n;
    /* scratch: >= 4 doubles per grain; keep uses the first cap bytes, the
     * two maps a cap of ints each from one and two doubles per grain on */
    int *new_id = (int *)(w->scratch + g->cap);
    int next = 0;
    for (int id = 0; id < n; id++)
        new_id[id] = keep[g->slot_of[id]] ? next++ : -1;
    if (next == n)
        return 0;
    double *dbl[] = {g->x,  g->y,  g->z,  g->vx, g->vy, g->vz,    g->wx,    g->wy, g->wz, g->fx, g->fy,
                     g->fz, g->tx, g->ty, g->tz, g->r,  g->inv_m, g->inv_i, g->x0, g->y0, g->z0, g->sc};
    int *ints[] = {g->mat, g->surf_count, g->shape, g->tag};
    const size_t wh = (size_t)w->wall_stride * w->hist_stride, sh = DEM_SURF_SLOTS * DEM_SURF_SLOT_SIZE;
    int *new_slot = (int *)(w->scratch + 2 * (size_t)g->cap);
    int d = 0;
    for (int i = 0; i < n; i++) {
        new_slot[i] = keep[i] ? d : -1;
        if (!keep[i]) {
            w->n_shaped -= g->shape[i] >= 0;
            w->n_frozen -= g->frozen[i] != 0;
            continue;
        }
        g->id[d] = new_id[g->id[i]];
        if (d != i) {
            for (size_t k = 0; k < sizeof dbl / sizeof dbl[0]; k++)
                dbl[k][d] = dbl[k][i];
            for (size_t k = 0; k < sizeof ints / sizeof ints[0]; k++)
                ints[k][d] = ints[k][i];
            g->wall_mask[d] = g->wall_mask[i];
            g->frozen[d] = g->frozen[i];
            memcpy(g->q + 4 * d, g->q + 4 * i, 4 * sizeof *g->q);
            memcpy(g->inertia + 3 * d, g->inertia + 3 * i, 3 * sizeof *g->inertia);
            memcpy(g->angmom + 3 * d, g->angmom + 3 * i, 3 * sizeof *g->angmom);
            memcpy(g->wall_hist + wh * d, g->wall_hist + wh * i, wh * sizeof *g->wall_hist);
            if (w->surf)
                memcpy(w->surf->hist + sh * d, w->surf->hist + sh * i, sh * sizeof *w->surf->hist);
        }
        d++;
    }
    for (int i = 0; i < d; i++)
        g->slot_of[g->id[i]] = i;
    g->n = d;
    w->need_rebuild = 1;
    w->walls_near_valid = 0;
    return pairs_compact(w, new_slot) == CM_OK ? n - d : -1;
}

int dem_grains_remove_below_x(dem_world *w, double x_cut, int *removed)
{
    dem_grains *g = &w->g;
    unsigned char *keep = (unsigned char *)w->scratch;
    for (int i = 0; i < g->n; i++)
        keep[i] = !(g->x[i] < x_cut);
    int r = grains_compact(w, keep);
    if (removed)
        *removed = r < 0 ? 0 : r;
    return r < 0 ? CM_ERR_NOMEM : CM_OK;
}

int dem_grains_remove(dem_world *w, int n, const int *ids, cm_error *err)
{
    dem_grains *g = &w->g;
    for (int k = 0; k < n; k++)
        if (ids[k] < 0 || ids[k] >= g->n)
            return cm_fail(err, CM_ERR_RANGE, "dem_grains_remove: id %d (of %d grains)", ids[k], g->n);
    unsigned char *keep = (unsigned char *)w->scratch;
    memset(keep, 1, (size_t)g->n);
    for (int k = 0; k < n; k++)
        keep[g->slot_of[ids[k]]] = 0;
    if (grains_compact(w, keep) < 0)
        return cm_fail(err, CM_ERR_NOMEM, "dem_grains_remove: out of memory for the contact history");
    return CM_OK;
}

int dem_grains_add_states(dem_world *w, int n, const dem_grain_state *s, const double offset[3], cm_error *err)
{
    dem_grains *g = &w->g;
    if (n < 0 || g->n + n > g->cap)
        return cm_fail(err, CM_ERR_RANGE, "adding %d grains to %d: world is full (max_grains = %d)", n, g->n, g->cap);
    const double zero[3] = {0, 0, 0};
    const double *off = offset ? offset : zero;
    for (int k = 0; k < n; k++) {
        const dem_grain_state *st = &s[k];
        double x[3] = {st->x[0] + off[0], st->x[1] + off[1], st->x[2] + off[2]};
        int id, rc = st->shape >= 0 ? dem_grain_add_shape(w, x, st->q, st->shape, st->scale, st->material, &id, err)
                                    : dem_grain_add(w, x, st->radius, st->material, &id, err);
        if (rc)
            return rc;
        if (st->shape < 0)
            dem_grain_set_orientation(w, id, st->q);
        dem_grain_set(w, id, NULL, st->v, st->w);
    }
    return CM_OK;
}

int dem_freeze_outside_x(dem_world *w, double x_lo, double x_hi)
{
    dem_grains *g = &w->g;
    int frozen = 0, changed = 0;
    for (int i = 0; i < g->n; i++) {
        unsigned char f = g->x[i] < x_lo || g->x[i] > x_hi;
        if (f != g->frozen[i]) {
            changed = 1;
            g->frozen[i] = f;
            if (f) { /* it stays put: no velocity for the dashpots of its active neighbours to see */
                g->vx[i] = g->vy[i] = g->vz[i] = g->wx[i] = g->wy[i] = g->wz[i] = 0.0;
                g->angmom[3 * i] = g->angmom[3 * i + 1] = g->angmom[3 * i + 2] = 0.0;
            }
        }
        frozen += f;
    }
    w->n_frozen = frozen;
    if (changed) {
        w->need_rebuild = 1;
        w->walls_near_valid = 0;
    }
    return frozen;
}

/* ---- walls ------------------------------------------------------------- */

int dem_wall_add(dem_world *w, const double point[3], const double normal[3], int material, cm_error *err)
{
    if (w->n_walls >= DEM_MAX_WALLS)
        return cm_fail(err, CM_ERR_RANGE, "dem_wall_add: at most %d walls", DEM_MAX_WALLS);
    if (material < 0 || material >= w->n_mat)
        return cm_fail(err, CM_ERR_RANGE, "dem_wall_add: wall %d: material %d (of %d)", w->n_walls, material, w->n_mat);
    vec3 n = v3_load(normal);
    double nn = v3_norm(n);
    if (!(nn > 0.0) || !isfinite(nn))
        return cm_fail(err, CM_ERR_RANGE, "dem_wall_add: wall %d: zero or non-finite normal", w->n_walls);
    dem_wall *wl = &w->walls[w->n_walls++];
    memset(wl, 0, sizeof *wl);
    memcpy(wl->p, point, sizeof wl->p);
    v3_store(wl->n, v3_scale(n, 1.0 / nn));
    wl->material = material;
    w->prepared = 0;
    return CM_OK;
}

int dem_wall_count(const dem_world *w) { return w->n_walls; }

int dem_wall_get(const dem_world *w, int k, double point[3], double normal[3])
{
    if (k < 0 || k >= w->n_walls)
        return CM_ERR_RANGE;
    memcpy(point, w->walls[k].p, 3 * sizeof *point);
    memcpy(normal, w->walls[k].n, 3 * sizeof *normal);
    return CM_OK;
}

int dem_wall_move(dem_world *w, int k, const double point[3])
{
    if (k < 0 || k >= w->n_walls || !isfinite(point[0]) || !isfinite(point[1]) || !isfinite(point[2]))
        return CM_ERR_RANGE;
    memcpy(w->walls[k].p, point, sizeof w->walls[k].p);
    w->walls_near_valid = 0; /* every wall is tested until the next rebuild */
    return CM_OK;
}

int dem_wall_force(const dem_world *w, int k, double f[3])
{
    if (k < 0 || k >= w->n_walls)
        return CM_ERR_RANGE;
    memcpy(f, w->walls[k].force, 3 * sizeof *f);
    return CM_OK;
}

/* ---- surface ----------------------------------------------------------- */

int dem_surface_set(dem_world *w, int n_nodes, const double *x0, int n_tris, const int *tris, int material,
                    cm_error *err)
{
    if (material < 0 || material >= w->n_mat)
        return cm_fail(err, CM_ERR_RANGE, "dem_surface_set: material %d (of %d)", material, w->n_mat);
    dem_surface_free(&w->surf);
    w->prepared = 0;
    return dem_surface_create(n_nodes, x0, n_tris, tris, material, w->g.cap, w->n_threads, &w->surf, err);
}

int dem_surface_set_masses(dem_world *w, const double *node_mass, cm_error *err)
{
    dem_surface *s = w->surf;
    if (!s)
        return cm_fail(err, CM_ERR_STATE, "dem_surface_set_masses: no surface installed");
    if (!node_mass) {
        free(s->inv_mass);
        s->inv_mass = NULL;
        return CM_OK;
    }
    double *inv = malloc((size_t)s->n_nodes * sizeof *inv);
    if (!inv)
        return cm_fail(err, CM_ERR_NOMEM, "dem_surface_set_masses: out of memory");
    for (int k = 0; k < s->n_nodes; k++) {
        if (!(node_mass[k] >= 0.0) || !isfinite(node_mass[k])) {
            free(inv);
            return cm_fail(err, CM_ERR_NUMERIC, "dem_surface_set_masses: node %d has mass %g", k, node_mass[k]);
        }
        inv[k] = node_mass[k] > 0.0 ? 1.0 / node_mass[k] : 0.0; /* 0: a fixed node */
    }
    free(s->inv_mass);
    s->inv_mass = inv;
    return CM_OK;
}

int dem_surface_update(dem_world *w, const double *node_x, const double *node_v, cm_error *err)
{
    dem_surface *s = w->surf;
    if (!s)
        return cm_fail(err, CM_ERR_STATE, "dem_surface_update at step %ld: no surface installed", w->step);
    int n3 = 3 * s->n_nodes;
    /* data from the other process: check before use */
    for (int k = 0; k < n3; k++)
        if (!isfinite(node_x[k]) || (node_v && !isfinite(node_v[k])))
            return cm_fail(err, CM_ERR_NUMERIC, "dem_surface_update at step %ld: node %d has a non-finite %s",
                           w->step, k / 3, isfinite(node_x[k]) ? "velocity" : "position");
    memcpy(s->x, node_x, (size_t)n3 * sizeof *s->x);
    if (node_v)
        memcpy(s->v, node_v, (size_t)n3 * sizeof *s->v);
    else
        memset(s->v, 0, (size_t)n3 * sizeof *s->v);
    dem_surface_moved(s);
    return CM_OK;
}

void dem_surface_set_frame(dem_world *w, const double ref_point[3], const double travel_dir[3])
{
    if (!w->surf)
        return;
    memcpy(w->surf->ref, ref_point, sizeof w->surf->ref);
    v3_store(w->surf->travel, v3_unit(v3_load(travel_dir)));
}

const double *dem_surface_node_forces(const dem_world *w) { return w->surf ? w->surf->node_f : NULL; }

void dem_surface_totals(const dem_world *w, dem_surface_total *t)
{
    if (w->surf)
        *t = w->surf->tot;
    else
        memset(t, 0, sizeof *t);
}

/* ---- diagnostics ------------------------------------------------------- */

void dem_world_add_idle(dem_world *w, double seconds, double cpu_seconds)
{
    w->prof.idle += seconds;
    w->prof.wait_cpu += cpu_seconds;
}

long dem_world_steps(const dem_world *w) { return w->step; }

int dem_world_set_halo_rider(dem_world *w, dem_halo_rider *r, cm_error *err)
{
    if (r && (!w->dist || w->dist->ranks(w) != 2))
        return cm_fail(err, CM_ERR_STATE, "a message riding the halo needs a world distributed on two ranks");
    if (r)
        r->fill_s = 0.0, r->carried = 0;
    w->rider = r;
    return CM_OK;
}

/* Grains [lo, hi): their kinetic energies added to s's sums in slot order
 * (a sum along the grain order, which dem_mpi_series_stats continues from
 * rank to rank), the gravity potential and wall energies with `energies`,
 * s's largest overlap raised to their wall overlaps. */
static void stats_grains(const dem_world *w, int lo, int hi, dem_stats *s, int energies)
{
    const dem_grains *g = &w->g;
    vec3 grav = v3_load(w->def.gravity);
    for (int i = lo; i < hi; i++) {
        double m = 1.0 / g->inv_m[i], I = 1.0 / g->inv_i[i];
        s->ke_trans += 0.5 * m * (g->vx[i] * g->vx[i] + g->vy[i] * g->vy[i] + g->vz[i] * g->vz[i]);
        if (energies)
            s->pe_grav -= m * (grav.x * g->x[i] + grav.y * g->y[i] + grav.z * g->z[i]);
        if (g->shape[i] >= 0) { /* 1/2 omega.L; the elastic energy of shaped contacts is not summed */
            const double *L = g->angmom + 3 * i;
            s->ke_rot += 0.5 * (g->wx[i] * L[0] + g->wy[i] * L[1] + g->wz[i] * L[2]);
            continue;
        }
        s->ke_rot += 0.5 * I * (g->wx[i] * g->wx[i] + g->wy[i] * g->wy[i] + g->wz[i] * g->wz[i]);
        for (int k = 0; k < w->n_walls; k++) {
            const dem_wall *wl = &w->walls[k];
            double dist = (g->x[i] - wl->p[0]) * wl->n[0] + (g->y[i] - wl->p[1]) * wl->n[1] + (g->z[i] - wl->p[2]) * wl->n[2];
            double delta = g->r[i] - dist;
            if (delta > 0.0) {
                if (energies)
                    s->e_elastic += dem_hertz_energy(&w->coef[g->mat[i]][wl->material], g->r[i], delta);
                s->max_overlap = fmax(s->max_overlap, delta / g->r[i]);
            }
        }
    }
}

/* Pairs [p0, p1) whose first grain is at slot row_lo or later: s's largest
 * overlap raised to theirs, their Hertz energies added with `energies`. */
static void stats_pairs(const dem_world *w, int p0, int p1, int row_lo, dem_stats *s, int energies)
{
    const dem_grains *g = &w->g;
    for (int p = p0; p < p1; p++) {
        int i = w->pi[p], j = w->pj[p];
        if (i < row_lo || (g->shape[i] & g->shape[j]) >= 0)
            continue;
        double ex = g->x[i] - g->x[j], ey = g->y[i] - g->y[j], ez = g->z[i] - g->z[j];
        double d = sqrt(ex * ex + ey * ey + ez * ez), delta = g->r[i] + g->r[j] - d;
        if (delta > 0.0) {
            if (energies) {
                double R = g->r[i] * g->r[j] / (g->r[i] + g->r[j]);
                s->e_elastic += dem_hertz_energy(&w->coef[g->mat[i]][g->mat[j]], R, delta);
            }
            s->max_overlap = fmax(s->max_overlap, delta / fmin(g->r[i], g->r[j]));
        }
    }
}

/* The clock, counts and the surface's overlaps (the last surface step's). */
static void stats_counts(const dem_world *w, dem_stats *s)
{
    const dem_grains *g = &w->g;
    s->time = w->time;
    s->step = w->step;
    s->grains = g->n;
    s->frozen = w->n_frozen;
    s->contacts_gg = w->contacts_gg;
    s->contacts_gw = w->contacts_gw;
    s->contacts_gs = w->surf ? w->surf->tot.contacts : 0;
    /* Grain–surface overlaps of the last surface step (the tire's). */
    s->max_overlap_surface = w->surf ? w->surf->tot.max_overlap : 0.0;
    s->worst_surface.tag = -1;
    if (w->surf && w->surf->tot.contacts > 0) {
        int i = w->surf->tot.worst_grain;
        s->worst_surface.tag = g->tag[i];
        s->worst_surface.tri = w->surf->tot.worst_tri;
        s->worst_surface.x[0] = g->x[i], s->worst_surface.x[1] = g->y[i], s->worst_surface.x[2] = g->z[i];
        s->worst_surface.v[0] = g->vx[i], s->worst_surface.v[1] = g->vy[i], s->worst_surface.v[2] = g->vz[i];
        s->worst_surface.r = g->r[i];
        s->worst_surface.frozen = g->frozen[i];
    }
    s->profile = w->prof;
}

static void world_stats(const dem_world *w, dem_stats *s, int energies)
{
    memset(s, 0, sizeof *s);
    stats_grains(w, 0, w->g.n, s, energies);
    stats_pairs(w, 0, w->n_pairs, 0, s, energies);
    stats_counts(w, s);
}

void dem_world_stats(const dem_world *w, dem_stats *s) { world_stats(w, s, 1); }
void dem_world_stats_lean(const dem_world *w, dem_stats *s) { world_stats(w, s, 0); }

void dem_world_stats_part(const dem_world *w, int part, int parts, dem_stats *s)
{
    memset(s, 0, sizeof *s);
    const int n = w->g.n, np = w->n_pairs;
    stats_grains(w, (int)((long)n * part / parts), (int)((long)n * (part + 1) / parts), s, 0);
    stats_pairs(w, (int)((long)np * part / parts), (int)((long)np * (part + 1) / parts), 0, s, 0);
    stats_counts(w, s);
}

void dem_world_stats_grains(const dem_world *w, int lo, int hi, dem_stats *s) { stats_grains(w, lo, hi, s, 0); }

void dem_world_stats_rows(const dem_world *w, int row_lo, dem_stats *s) { stats_pairs(w, 0, w->n_pairs, row_lo, s, 0); }

void dem_grain_contact_counts(const dem_world *w, int *out)
{
    const dem_grains *g = &w->g;
    for (int i = 0; i < g->n; i++) {
        int c = g->surf_count[i];
        for (int k = 0; k < w->n_walls; k++) {
            const dem_wall *wl = &w->walls[k];
            double dist = (g->x[i] - wl->p[0]) * wl->n[0] + (g->y[i] - wl->p[1]) * wl->n[1] + (g->z[i] - wl->p[2]) * wl->n[2];
            if (g->shape[i] >= 0 && dist < g->r[i])
                c += dem_shaped_plane_depth(w, i, wl->p, wl->n) > 0.0;
            else
                c += dist < g->r[i];
        }
        out[g->id[i]] = c;
    }
    for (int p = 0; p < w->n_pairs; p++) {
        int i = w->pi[p], j = w->pj[p];
        double ex = g->x[i] - g->x[j], ey = g->y[i] - g->y[j], ez = g->z[i] - g->z[j];
        double rs = g->r[i] + g->r[j];
        if ((g->shape[i] & g->shape[j]) < 0 ? ex * ex + ey * ey + ez * ez < rs * rs
                                               : dem_shaped_pair_touch(w, i, j)) {
            out[g->id[i]]++;
            out[g->id[j]]++;
        }
    }
}

uint64_t dem_world_hash(const dem_world *w)
{
    const dem_grains *g = &w->g;
    uint64_t h = 1469598103934665603ULL;
    for (int id = 0; id < g->n; id++) {
        int i = g->slot_of[id];
        /* the grain's tag and frozen flag too: a window-changed world must
         * come back with the same names (they key the contact history) */
        double v[11] = {g->x[i], g->y[i], g->z[i], g->vx[i], g->vy[i], g->vz[i], g->wx[i], g->wy[i], g->wz[i],
                        (double)g->tag[i], (double)g->frozen[i]};
        const unsigned char *b = (const unsigned char *)v;
        for (size_t k = 0; k < sizeof v; k++) {
            h ^= b[k];
            h *= 1099511628211ULL;
        }
    }
    return h;
}
