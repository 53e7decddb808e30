/* The SCM height grid under a triangle surface: one step is
 *   raster  every downward-facing triangle onto the cell centres below it,
 *           keeping per cell the lowest surface point (its triangle and
 *           barycentric weights): the vertical ray from the cell hits there
 *   slide   each node in contact advances its shear displacement by its
 *           tangential motion since the last step (the elastic part e by
 *           the vector, held within the Janosi strength; the rest is
 *           plastic slip)
 *   soil    per cell hit below its current surface: pressure from the
 *           loading history (Bekker / elastic line), shear from the tread's
 *           elastic shear displacement (bounded by the Janosi curve), the
 *           force on the contact point distributed to the triangle's nodes
 *           (paper eq. 42); the rut is committed
 *   contact which nodes are below the soil now; a node out of contact
 *           starts its shear displacement again
 * (slide and contact are timed together as "shear").
 * Cells are stored structure-of-arrays; nothing is allocated per step. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "scm.h"
#include "timer.h"

/* Smallest |n_z| for the area of a cell on the surface (faces up to 60
 * degrees from horizontal carry their true area; a wheel's contact arc at
 * the sinkages here stays within 30 degrees). */
#define SCM_MIN_NZ 0.5

struct scm_terrain {
    scm_grid_def g;
    scm_soil s;
    double b;       /* m, Bekker's b in use */
    int nx, ny;
    /* cells: soil state and this step's hit */
    double *zmax;   /* m, deepest sinkage loaded to */
    double *pmax;   /* Pa, first-loading pressure at zmax */
    double *press;  /* Pa, pressure now */
    double *hit_z;  /* m, lowest surface point above the cell this step (INFINITY: none) */
    double *hit_w;  /* 3 per cell: its barycentric weights */
    int *hit_tri;   /* its triangle */
    int *touched;   /* cells hit this step */
    int n_touched;
    int *pressed;   /* cells with pressure at the last step (to clear press) */
    int n_pressed;
    /* surface */
    int nn, nt;
    int *tris;
    double *f;       /* 3 nn, N */
    /* the tread's shear displacement, Janosi's j = jp + |e|: */
    double *jp;      /* nn, m: its plastic part, the slip beyond the shear spring's reach */
    double *e;       /* 3 nn, m: its elastic part, a vector in the node's tangent plane (world frame) */
    double *x_prev;  /* 3 nn, m: the positions of the last step */
    /* per node, the soil under it at the last step (for the limit of e):
     * sums over the cells acting on its triangles of w area, w area p and
     * w area p_max (w the node's barycentric weight) */
    double *node_area, *node_p, *node_pmax;
    double *nrm;     /* 3 nn: node normals (area-weighted) */
    double *tri_n;   /* 3 nt: unit outward normals this step */
    unsigned char *in_contact; /* nn */
    scm_totals tot;
    scm_profile prof;
};

int scm_terrain_create(const scm_grid_def *grid, const scm_soil *soil, scm_terrain **out, cm_error *err)
{
    *out = NULL;
    if (!(grid->cell > 0) || !(grid->max[0] > grid->min[0]) || !(grid->max[1] > grid->min[1]))
        return cm_fail(err, CM_ERR_RANGE, "scm grid: need max > min and cell > 0");
    double nxd = ceil((grid->max[0] - grid->min[0]) / grid->cell - 1e-9);
    double nyd = ceil((grid->max[1] - grid->min[1]) / grid->cell - 1e-9);
    if (nxd * nyd > 1e8)
        return cm_fail(err, CM_ERR_RANGE, "scm grid: %.0f x %.0f cells is too many (at most 1e8)", nxd, nyd);
    scm_terrain *t = calloc(1, sizeof *t);
    if (!t)
        return cm_fail(err, CM_ERR_NOMEM, "out of memory for the scm grid");
    t->g = *grid;
    t->s = *soil;
    t->nx = (int)nxd;
    t->ny = (int)nyd;
    size_t nc = (size_t)t->nx * (size_t)t->ny;
    t->zmax = calloc(nc, sizeof *t->zmax);
    t->pmax = calloc(nc, sizeof *t->pmax);
    t->press = calloc(nc, sizeof *t->press);
    t->hit_z = malloc(nc * sizeof *t->hit_z);
    t->hit_w = malloc(3 * nc * sizeof *t->hit_w);
    t->hit_tri = malloc(nc * sizeof *t->hit_tri);
    t->touched = malloc(nc * sizeof *t->touched);
    t->pressed = malloc(nc * sizeof *t->pressed);
    if (!t->zmax || !t->pmax || !t->press || !t->hit_z || !t->hit_w || !t->hit_tri || !t->touched || !t->pressed) {
        scm_terrain_destroy(&t);
        return cm_fail(err, CM_ERR_NOMEM, "out of memory for %zu scm cells", nc);
    }
    for (size_t c = 0; c < nc; c++)
        t->hit_z[c] = INFINITY;
    *out = t;
    return CM_OK;
}

static void free_surface(scm_terrain *t)
{
    free(t->tris);
    free(t->f);
    free(t->jp);
    free(t->e);
    free(t->x_prev);
    free(t->node_area);
    free(t->node_p);
    free(t->node_pmax);
    free(t->nrm);
    free(t->tri_n);
    free(t->in_contact);
    t->tris = NULL, t->f = t->jp = t->e = t->x_prev = t->nrm = t->tri_n = NULL;
    t->node_area = t->node_p = t->node_pmax = NULL, t->in_contact = NULL;
}

void scm_terrain_destroy(scm_terrain **tp)
{
    scm_terrain *t = tp ? *tp : NULL;
    if (!t)
        return;
    free_surface(t);
    free(t->zmax);
    free(t->pmax);
    free(t->press);
    free(t->hit_z);
    free(t->hit_w);
    free(t->hit_tri);
    free(t->touched);
    free(t->pressed);
    free(t);
    *tp = NULL;
}

int scm_terrain_set_surface(scm_terrain *t, int n_nodes, const double *x, int n_tris, const int *tris,
                            cm_error *err)
{
    if (n_nodes < 3 || n_tris < 1)
        return cm_fail(err, CM_ERR_RANGE, "scm surface: %d nodes, %d triangles", n_nodes, n_tris);
    for (long k = 0; k < 3L * n_tris; k++)
        if (tris[k] < 0 || tris[k] >= n_nodes)
            return cm_fail(err, CM_ERR_RANGE, "scm surface: triangle %ld names node %d of %d", k / 3, tris[k],
                           n_nodes);
    free_surface(t);
    t->nn = n_nodes;
    t->nt = n_tris;
    t->tris = malloc(3 * (size_t)n_tris * sizeof *t->tris);
    t->f = calloc(3 * (size_t)n_nodes, sizeof *t->f);
    t->jp = calloc((size_t)n_nodes, sizeof *t->jp);
    t->e = calloc(3 * (size_t)n_nodes, sizeof *t->e);
    t->x_prev = malloc(3 * (size_t)n_nodes * sizeof *t->x_prev);
    t->node_area = calloc((size_t)n_nodes, sizeof *t->node_area);
    t->node_p = calloc((size_t)n_nodes, sizeof *t->node_p);
    t->node_pmax = calloc((size_t)n_nodes, sizeof *t->node_pmax);
    t->nrm = calloc(3 * (size_t)n_nodes, sizeof *t->nrm);
    t->tri_n = calloc(3 * (size_t)n_tris, sizeof *t->tri_n);
    t->in_contact = calloc((size_t)n_nodes, 1);
    if (!t->tris || !t->f || !t->jp || !t->e || !t->x_prev || !t->node_area || !t->node_p || !t->node_pmax ||
        !t->nrm || !t->tri_n || !t->in_contact) {
        free_surface(t);
        return cm_fail(err, CM_ERR_NOMEM, "out of memory for a surface of %d nodes", n_nodes);
    }
    memcpy(t->tris, tris, 3 * (size_t)n_tris * sizeof *tris);
    memcpy(t->x_prev, x, 3 * (size_t)n_nodes * sizeof *x);
    /* Bekker's b: given, or the smaller horizontal dimension of the surface
     * (a plate's width; a tire's width, as Wong takes it for a wheel). */
    double lo[2] = {INFINITY, INFINITY}, hi[2] = {-INFINITY, -INFINITY};
    for (int k = 0; k < n_nodes; k++)
        for (int a = 0; a < 2; a++)
            lo[a] = fmin(lo[a], x[3 * k + a]), hi[a] = fmax(hi[a], x[3 * k + a]);
    t->b = t->s.b > 0 ? t->s.b : fmin(hi[0] - lo[0], hi[1] - lo[1]);
    if (!(t->b > 0))
        return cm_fail(err, CM_ERR_RANGE,
                       "scm surface: its horizontal extent is %g x %g m, so Bekker's b is undefined; give "
                       "scm.soil.plate_width",
                       hi[0] - lo[0], hi[1] - lo[1]);
    return CM_OK;
}

double scm_terrain_plate_width(const scm_terrain *t) { return t->b; }

static inline double cross2(double ax, double ay, double bx, double by) { return ax * by - ay * bx; }

/* Stage raster: the lowest downward-facing surface point above each cell
 * centre. Only triangles reaching below the undisturbed surface matter. */
static int raster(scm_terrain *t, const double *x, cm_error *err)
{
    const scm_grid_def *g = &t->g;
    const double h0 = g->height, inv = 1.0 / g->cell;
    for (int q = 0; q < t->n_touched; q++)
        t->hit_z[t->touched[q]] = INFINITY;
    t->n_touched = 0;
    for (int e = 0; e < t->nt; e++) {
        const int *tr = t->tris + 3 * e;
        const double *a = x + 3 * tr[0], *b = x + 3 * tr[1], *c = x + 3 * tr[2];
        double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
        double n[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]};
        double len = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        double *tn = t->tri_n + 3 * e;
        if (len > 0)
            tn[0] = n[0] / len, tn[1] = n[1] / len, tn[2] = n[2] / len;
        else
            tn[0] = tn[1] = tn[2] = 0;
        /* facing down (outward normal below the horizon), reaching below the bed */
        if (!(n[2] < 0) || fmin(a[2], fmin(b[2], c[2])) >= h0)
            continue;
        double xlo = fmin(a[0], fmin(b[0], c[0])), xhi = fmax(a[0], fmax(b[0], c[0]));
        double ylo = fmin(a[1], fmin(b[1], c[1])), yhi = fmax(a[1], fmax(b[1], c[1]));
        if (xlo < g->min[0] || xhi > g->max[0] || ylo < g->min[1] || yhi > g->max[1])
            return cm_fail(err, CM_ERR_RANGE,
                           "the tire reaches below the soil surface at x in [%.4f, %.4f], y in [%.4f, %.4f] m, "
                           "outside scm.grid (x in [%g, %g], y in [%g, %g]): enlarge scm.grid.min / max",
                           xlo, xhi, ylo, yhi, g->min[0], g->max[0], g->min[1], g->max[1]);
        int i0 = (int)ceil((xlo - g->min[0]) * inv - 0.5), i1 = (int)floor((xhi - g->min[0]) * inv - 0.5);
        int j0 = (int)ceil((ylo - g->min[1]) * inv - 0.5), j1 = (int)floor((yhi - g->min[1]) * inv - 0.5);
        i0 = i0 < 0 ? 0 : i0, j0 = j0 < 0 ? 0 : j0;
        i1 = i1 >= t->nx ? t->nx - 1 : i1, j1 = j1 >= t->ny ? t->ny - 1 : j1;
        const double d = n[2]; /* = cross2(u, w) */
        const double tol = 1e-12;
        for (int jj = j0; jj <= j1; jj++) {
            const double py = g->min[1] + (jj + 0.5) * g->cell - a[1];
            for (int ii = i0; ii <= i1; ii++) {
                const double px = g->min[0] + (ii + 0.5) * g->cell - a[0];
                double w1 = cross2(px, py, w[0], w[1]) / d; /* weight of b */
                double w2 = cross2(u[0], u[1], px, py) / d; /* weight of c */
                double w0 = 1.0 - w1 - w2;
                if (w0 < -tol || w1 < -tol || w2 < -tol)
                    continue;
                double z = w0 * a[2] + w1 * b[2] + w2 * c[2];
                size_t cell = (size_t)jj * (size_t)t->nx + (size_t)ii;
                if (z < t->hit_z[cell]) {
                    if (t->hit_z[cell] == INFINITY)
                        t->touched[t->n_touched++] = (int)cell;
                    t->hit_z[cell] = z;
                    t->hit_tri[cell] = e;
                    t->hit_w[3 * cell] = w0, t->hit_w[3 * cell + 1] = w1, t->hit_w[3 * cell + 2] = w2;
                }
            }
        }
    }
    return CM_OK;
}

/* Stage soil: pressure and shear per cell hit, forces onto the nodes. */
static void soil(scm_terrain *t, const double *x)
{
    const scm_soil *s = &t->s;
    const double h0 = t->g.height, area_h = t->g.cell * t->g.cell;
    memset(t->f, 0, 3 * (size_t)t->nn * sizeof *t->f);
    memset(t->node_area, 0, (size_t)t->nn * sizeof *t->node_area);
    memset(t->node_p, 0, (size_t)t->nn * sizeof *t->node_p);
    memset(t->node_pmax, 0, (size_t)t->nn * sizeof *t->node_pmax);
    for (int q = 0; q < t->n_pressed; q++)
        t->press[t->pressed[q]] = 0;
    t->n_pressed = 0;
    scm_totals *tot = &t->tot;
    const double max_sinkage = tot->max_sinkage;
    memset(tot, 0, sizeof *tot);
    tot->max_sinkage = max_sinkage;
    for (int q = 0; q < t->n_touched; q++) {
        const int c = t->touched[q];
        const double z = h0 - t->hit_z[c]; /* sinkage of the tire surface below the undisturbed level */
        double p;
        if (!(z > 0))
            continue;
        if (z >= t->zmax[c]) { /* first loading: the rut deepens */
            p = scm_bekker(s, t->b, z);
            t->zmax[c] = z;
            t->pmax[c] = p;
            tot->max_sinkage = fmax(tot->max_sinkage, z);
        } else { /* on the elastic line below the deepest loading */
            p = t->pmax[c] - scm_unload_stiffness(s, t->zmax[c]) * (t->zmax[c] - z);
            if (!(p > 0))
                continue;
        }
        t->press[c] = p;
        t->pressed[t->n_pressed++] = c;
        const int e = t->hit_tri[c];
        const int *tr = t->tris + 3 * e;
        const double *w = t->hit_w + 3 * (size_t)c, *nh = t->tri_n + 3 * e;
        /* per unit of tire surface: the cell's horizontal area over |n_z|,
         * at most twice it. A steep face (a lug's flank) is sampled by whole
         * cells although its horizontal projection may be a sliver: 1/|n_z|
         * would turn each hit into a spike (measured: T_H bursts of 800 N on
         * the default tire) while the vertical-sinkage law says nothing of
         * the lateral pressure on a flank anyway. */
        const double area = area_h / fmax(fabs(nh[2]), SCM_MIN_NZ);
        double P[3], ep[3], jc = 0; /* the contact point, its e and its j */
        for (int a = 0; a < 3; a++) {
            P[a] = w[0] * x[3 * tr[0] + a] + w[1] * x[3 * tr[1] + a] + w[2] * x[3 * tr[2] + a];
            ep[a] = w[0] * t->e[3 * tr[0] + a] + w[1] * t->e[3 * tr[1] + a] + w[2] * t->e[3 * tr[2] + a];
        }
        for (int k = 0; k < 3; k++) {
            const double *ek = t->e + 3 * tr[k];
            jc += w[k] * (t->jp[tr[k]] + sqrt(ek[0] * ek[0] + ek[1] * ek[1] + ek[2] * ek[2]));
        }
        /* the elastic shear displacement at the contact point, in the face's plane */
        const double en = ep[0] * nh[0] + ep[1] * nh[1] + ep[2] * nh[2];
        double et[3] = {ep[0] - en * nh[0], ep[1] - en * nh[1], ep[2] - en * nh[2]};
        const double etl = sqrt(et[0] * et[0] + et[1] * et[1] + et[2] * et[2]);
        /* normal stress pushes the surface back along -n; the shear stress
         * acts against the elastic shear displacement, k_tau(p_max) |e|, at
         * most Janosi's (c + p tan phi)(1 - e^{-j/K}) (scm_soil.c; the nodes'
         * limits on e keep it there but for the interpolation between them) */
        const double fn = p * area;
        const double tau = fmin(scm_shear_stiffness(s, t->pmax[c]) * etl, scm_janosi(s, p, jc));
        const double ft = etl > 0 ? tau * area / etl : 0.0;
        double F[3];
        for (int a = 0; a < 3; a++)
            F[a] = -fn * nh[a] - ft * et[a];
        for (int k = 0; k < 3; k++) {
            const int nk = tr[k];
            double *fk = t->f + 3 * nk;
            for (int a = 0; a < 3; a++)
                fk[a] += w[k] * F[a]; /* paper eq. 42: barycentric weights of the contact point */
            t->node_area[nk] += w[k] * area; /* the soil under the node, for its limit on e */
            t->node_p[nk] += w[k] * area * p;
            t->node_pmax[nk] += w[k] * area * t->pmax[c];
        }
        for (int a = 0; a < 3; a++) {
            tot->force[a] += F[a];
            tot->normal_force[a] -= fn * nh[a];
            tot->shear_force[a] -= ft * et[a];
        }
        tot->moment[0] += P[1] * F[2] - P[2] * F[1];
        tot->moment[1] += P[2] * F[0] - P[0] * F[2];
        tot->moment[2] += P[0] * F[1] - P[1] * F[0];
        /* gross traction and resistance: the normal and the shear parts apart */
        const double fx_n = -fn * nh[0], fx_t = -ft * et[0];
        tot->traction_pos += (fx_n > 0 ? fx_n : 0) + (fx_t > 0 ? fx_t : 0);
        tot->traction_neg += (fx_n < 0 ? fx_n : 0) + (fx_t < 0 ? fx_t : 0);
        tot->contacts++;
    }
}

/* The soil surface of cell c (m): the rut after the elastic spring-back. */
static double rest_height(const scm_terrain *t, size_t c)
{
    const double zm = t->zmax[c];
    if (!(zm > 0))
        return t->g.height;
    const double ku = scm_unload_stiffness(&t->s, zm);
    const double rest = zm - t->pmax[c] / ku;
    return t->g.height - (rest > 0 ? rest : 0.0);
}

/* Stage slide: the tread's shear displacement from the nodes' motion since
 * the last exchange, dx = x - x_prev, its part in the node's tangent plane
 * dx_t (the node normal: the mean of its faces' normals now), for each node
 * in contact at the last exchange. The elastic part e is turned into
 * today's tangent plane as the tread rotates (its length kept) and moves by
 * dx_t; what passes the point where the shear spring meets the Janosi curve
 * at the node's pressure (scm_soil.c) is plastic slip, added to jp. Janosi's
 * j = jp + |e| is then the slip integrated from the entry into the contact
 * in monotonic sliding (Wong's j: the slide, exactly, since the limit is
 * evaluated at the j of the slide so far), and does not grow while the
 * tread vibrates within the elastic range (a j summing |dx_t| grew with
 * every oscillation and raised the stress: +7 % on test_scm's patch).
 * From positions, not velocities: the shear stress is then a function of
 * the positions just received, as the normal stress is (e from the
 * velocities is e at x_n - v dt/2, a stress half an exchange late: a
 * negative damper that pumped energy into the light nodes). */
static void slide(scm_terrain *t, const double *x)
{
    memset(t->nrm, 0, 3 * (size_t)t->nn * sizeof *t->nrm);
    for (int e = 0; e < t->nt; e++) {
        const int *tr = t->tris + 3 * e;
        if (!(t->in_contact[tr[0]] | t->in_contact[tr[1]] | t->in_contact[tr[2]]))
            continue;
        for (int k = 0; k < 3; k++)
            for (int a = 0; a < 3; a++)
                t->nrm[3 * tr[k] + a] += t->tri_n[3 * e + a];
    }
    for (int k = 0; k < t->nn; k++) {
        double *ek = t->e + 3 * k, *xp = t->x_prev + 3 * k;
        const double *xk = x + 3 * k;
        const double d[3] = {xk[0] - xp[0], xk[1] - xp[1], xk[2] - xp[2]};
        xp[0] = xk[0], xp[1] = xk[1], xp[2] = xk[2];
        if (!t->in_contact[k])
            continue;
        const double *n = t->nrm + 3 * k;
        const double nl = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        const double u[3] = {nl > 0 ? n[0] / nl : 0, nl > 0 ? n[1] / nl : 0, nl > 0 ? n[2] / nl : 0};
        const double dn = d[0] * u[0] + d[1] * u[1] + d[2] * u[2];
        const double dtan[3] = {d[0] - dn * u[0], d[1] - dn * u[1], d[2] - dn * u[2]};
        /* e into today's tangent plane, its length kept, then moved by dx_t */
        const double e2 = ek[0] * ek[0] + ek[1] * ek[1] + ek[2] * ek[2];
        const double en = ek[0] * u[0] + ek[1] * u[1] + ek[2] * u[2];
        const double p2 = e2 - en * en;
        const double keep = p2 > 0 ? sqrt(e2 / p2) : 0.0;
        for (int a = 0; a < 3; a++)
            ek[a] = (ek[a] - en * u[a]) * keep + dtan[a];
        /* plastic slip beyond the Janosi strength at the node's pressure (that
         * of the cells on its faces at the last step; none yet: first
         * loading), at the j this motion reaches */
        const double el = sqrt(ek[0] * ek[0] + ek[1] * ek[1] + ek[2] * ek[2]);
        const double na = t->node_area[k], j = t->jp[k] + el;
        const double lim = na > 0 ? scm_shear_elastic_limit(&t->s, t->node_p[k] / na, t->node_pmax[k] / na, j)
                                  : t->s.K * (1.0 - exp(-j / t->s.K)); /* p = p_max */
        if (el > lim) {
            t->jp[k] += el - lim;
            for (int a = 0; a < 3; a++)
                ek[a] *= lim / el;
        }
    }
}

/* Stage contact: a node is in contact when it is below the soil surface at
 * its position (the ruts just committed, bilinear between the cell centres:
 * on a convex tread, the wheel's bottom, it lies above the loaded nodes); a
 * node out of the soil starts its shear displacement again from 0. */
static void contact(scm_terrain *t, const double *x)
{
    const scm_grid_def *g = &t->g;
    const double inv = 1.0 / g->cell;
    for (int k = 0; k < t->nn; k++) {
        const double *p = x + 3 * k;
        int in = 0;
        const double fi = (p[0] - g->min[0]) * inv - 0.5, fj = (p[1] - g->min[1]) * inv - 0.5;
        if (p[2] < g->height && fi > -1 && fj > -1 && fi < t->nx && fj < t->ny) {
            const int i0 = (int)floor(fi), j0 = (int)floor(fj);
            const double tx = fi - i0, ty = fj - j0;
            const int ia = i0 < 0 ? 0 : i0, ib = i0 + 1 >= t->nx ? t->nx - 1 : i0 + 1;
            const int ja = j0 < 0 ? 0 : j0, jb = j0 + 1 >= t->ny ? t->ny - 1 : j0 + 1;
            const size_t nx = (size_t)t->nx;
            const double h = (1 - ty) * ((1 - tx) * rest_height(t, (size_t)ja * nx + (size_t)ia) +
                                         tx * rest_height(t, (size_t)ja * nx + (size_t)ib)) +
                             ty * ((1 - tx) * rest_height(t, (size_t)jb * nx + (size_t)ia) +
                                   tx * rest_height(t, (size_t)jb * nx + (size_t)ib));
            in = p[2] < h;
        }
        t->in_contact[k] = (unsigned char)in;
        if (!in) {
            t->jp[k] = 0;
            t->e[3 * k] = t->e[3 * k + 1] = t->e[3 * k + 2] = 0;
        }
    }
}

int scm_terrain_step(scm_terrain *t, const double *x, cm_error *err)
{
    if (!t->tris)
        return cm_fail(err, CM_ERR_STATE, "scm_terrain_step before scm_terrain_set_surface");
    double t0 = cm_now();
    int rc = raster(t, x, err);
    double t1 = cm_now();
    t->prof.raster += t1 - t0;
    if (rc)
        return rc;
    slide(t, x);
    double t2 = cm_now();
    soil(t, x);
    double t3 = cm_now();
    t->prof.soil += t3 - t2;
    contact(t, x);
    t->prof.shear += (t2 - t1) + (cm_now() - t3);
    t->prof.steps++;
    return CM_OK;
}

const double *scm_terrain_node_forces(const scm_terrain *t) { return t->f; }
void scm_terrain_totals(const scm_terrain *t, scm_totals *out) { *out = t->tot; }
scm_profile scm_terrain_profile(const scm_terrain *t) { return t->prof; }

void scm_terrain_grid_size(const scm_terrain *t, int *nx, int *ny)
{
    *nx = t->nx;
    *ny = t->ny;
}

static size_t cell_index(const scm_terrain *t, int i, int j)
{
    i = i < 0 ? 0 : i >= t->nx ? t->nx - 1 : i;
    j = j < 0 ? 0 : j >= t->ny ? t->ny - 1 : j;
    return (size_t)j * (size_t)t->nx + (size_t)i;
}

double scm_terrain_cell_height(const scm_terrain *t, int i, int j)
{
    size_t c = cell_index(t, i, j);
    return t->press[c] > 0 ? t->hit_z[c] : rest_height(t, c);
}

double scm_terrain_cell_zmax(const scm_terrain *t, int i, int j) { return t->zmax[cell_index(t, i, j)]; }
double scm_terrain_cell_pressure(const scm_terrain *t, int i, int j) { return t->press[cell_index(t, i, j)]; }
double scm_terrain_node_shear(const scm_terrain *t, int node)
{
    if (!(node >= 0 && node < t->nn))
        return 0.0;
    const double *e = t->e + 3 * (size_t)node;
    return t->jp[node] + sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]);
}

void scm_terrain_node_shear_elastic(const scm_terrain *t, int node, double e[3])
{
    for (int a = 0; a < 3; a++)
        e[a] = node >= 0 && node < t->nn ? t->e[3 * node + a] : 0.0;
}
