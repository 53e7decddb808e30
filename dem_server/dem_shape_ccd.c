/* Posed convex bodies (sphere, ellipsoid, polyhedron, triangle) and the
 * libccd narrow phase between them: support functions, penetration (MPR, or
 * GJK+EPA for cross-checks), contact points (see dem_shape.h). */
#include "dem_shape.h"

#include <ccd/ccd.h>
#include <math.h>
#include <string.h>

#include "dem_shape_algebra.h"
#include "dem_surface.h"

#ifndef CCD_DOUBLE
#error "libccd must be built in double precision (CCD_DOUBLE): Debian's libccd-dev is"
#endif
_Static_assert(sizeof(ccd_real_t) == sizeof(double), "libccd in double precision");

/* ---- libccd glue ----------------------------------------------------------- */

void dem_body_support(const dem_body *b, const double d[3], double out[3])
{
    switch (b->type) {
    case DEM_BODY_SPHERE: {
        double l = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        double f = l > 0.0 ? b->k / l : 0.0;
        for (int k = 0; k < 3; k++)
            out[k] = b->c[k] + f * d[k];
        return;
    }
    case DEM_BODY_TRIANGLE: {
        int best = 0;
        double bd = -INFINITY;
        for (int t = 0; t < 3; t++) {
            double dd = b->tri[t][0] * d[0] + b->tri[t][1] * d[1] + b->tri[t][2] * d[2];
            if (dd > bd)
                bd = dd, best = t;
        }
        memcpy(out, b->tri[best], 3 * sizeof *out);
        return;
    }
    default:
        break;
    }
    double db[3], sb[3];
    mat_tvec(b->R, d, db);
    const dem_shape *s = b->s;
    if (b->type == DEM_BODY_ELLIPSOID) {
        /* x = A² d / sqrt(d^T A² d) */
        double a2[3] = {s->a[0] * s->a[0], s->a[1] * s->a[1], s->a[2] * s->a[2]};
        double h = sqrt(a2[0] * db[0] * db[0] + a2[1] * db[1] * db[1] + a2[2] * db[2] * db[2]);
        double f = h > 0.0 ? 1.0 / h : 0.0;
        for (int k = 0; k < 3; k++)
            sb[k] = a2[k] * db[k] * f;
    } else {
        int best = 0;
        double bd = -INFINITY;
        for (int t = 0; t < s->n_verts; t++) {
            double dd = s->v[t][0] * db[0] + s->v[t][1] * db[1] + s->v[t][2] * db[2];
            if (dd > bd)
                bd = dd, best = t;
        }
        memcpy(sb, s->v[best], sizeof sb);
    }
    double wv[3];
    mat_vec(b->R, sb, wv);
    for (int k = 0; k < 3; k++)
        out[k] = b->c[k] + b->k * wv[k];
}

void dem_body_contact_point(const dem_body *b, const double n[3], double depth, double frac, double out[3])
{
    double mn[3] = {-n[0], -n[1], -n[2]}, sp[3];
    dem_body_support(b, mn, sp);
    if (b->type == DEM_BODY_POLY) {
        double db[3], wsum = 0.0, acc[3] = {0, 0, 0};
        mat_tvec(b->R, n, db);
        const dem_shape *s = b->s;
        double hmin = INFINITY;
        for (int t = 0; t < s->n_verts; t++)
            hmin = fmin(hmin, b->k * (s->v[t][0] * db[0] + s->v[t][1] * db[1] + s->v[t][2] * db[2]));
        for (int t = 0; t < s->n_verts; t++) {
            double h = b->k * (s->v[t][0] * db[0] + s->v[t][1] * db[1] + s->v[t][2] * db[2]) - hmin;
            double wk = depth - h; /* how deep vertex t is in the overlap slab */
            if (wk <= 0.0)
                continue;
            double vw[3];
            mat_vec(b->R, s->v[t], vw);
            for (int k = 0; k < 3; k++) /* the vertex projected on the plane through sp + frac depth n */
                acc[k] += wk * (b->c[k] + b->k * vw[k] + (frac * depth - h) * n[k]);
            wsum += wk;
        }
        if (wsum > 0.0) {
            for (int k = 0; k < 3; k++)
                out[k] = acc[k] / wsum;
            return;
        }
    }
    for (int k = 0; k < 3; k++)
        out[k] = sp[k] + frac * depth * n[k];
}

/* Part [t0, t1] of segment p + t (q - p), t in [0, 1], inside body b
 * (scaled coordinates); returns 0 when it misses. Polyhedron: Cyrus–Beck
 * against the face planes; ellipsoid and sphere: the quadratic. */
static int clip_segment(const dem_body *b, const double p[3], const double q[3], double *t0, double *t1)
{
    double dp[3] = {p[0] - b->c[0], p[1] - b->c[1], p[2] - b->c[2]}, dq[3] = {q[0] - p[0], q[1] - p[1], q[2] - p[2]};
    double pb[3], db[3];
    if (b->type == DEM_BODY_SPHERE) {
        memcpy(pb, dp, sizeof pb), memcpy(db, dq, sizeof db);
    } else {
        mat_tvec(b->R, dp, pb);
        mat_tvec(b->R, dq, db);
    }
    double lo = 0.0, hi = 1.0;
    if (b->type == DEM_BODY_POLY) {
        const dem_shape *s = b->s;
        for (int f = 0; f < s->n_faces && lo <= hi; f++) {
            double num = s->f[f][3] * b->k - (s->f[f][0] * pb[0] + s->f[f][1] * pb[1] + s->f[f][2] * pb[2]);
            double den = s->f[f][0] * db[0] + s->f[f][1] * db[1] + s->f[f][2] * db[2];
            if (den == 0.0) {
                if (num < 0.0)
                    return 0;
            } else if (den > 0.0) {
                hi = fmin(hi, num / den);
            } else {
                lo = fmax(lo, num / den);
            }
        }
    } else {
        double ia[3];
        for (int k = 0; k < 3; k++)
            ia[k] = b->type == DEM_BODY_SPHERE ? 1.0 / b->k : 1.0 / (b->k * b->s->a[k]);
        double A = 0, B = 0, C = -1.0;
        for (int k = 0; k < 3; k++) {
            double x = pb[k] * ia[k], d = db[k] * ia[k];
            A += d * d, B += 2 * x * d, C += x * x;
        }
        double disc = B * B - 4 * A * C;
        if (!(A > 0.0) || disc <= 0.0)
            return 0;
        double sq = sqrt(disc);
        lo = fmax(lo, (-B - sq) / (2 * A));
        hi = fmin(hi, (-B + sq) / (2 * A));
    }
    if (!(lo < hi))
        return 0;
    *t0 = lo, *t1 = hi;
    return 1;
}

/* Adds the parts of polyhedron a's edges inside body b, each as its
 * midpoint weighted by its length. */
static void clipped_edges(const dem_body *a, const dem_body *b, double acc[3], double *wsum)
{
    const dem_shape *s = a->s;
    double v[DEM_SHAPE_MAX_VERTS][3];
    for (int t = 0; t < s->n_verts; t++) {
        double vw[3];
        mat_vec(a->R, s->v[t], vw);
        for (int k = 0; k < 3; k++)
            v[t][k] = a->c[k] + a->k * vw[k];
    }
    for (int e = 0; e < s->n_edges; e++) {
        const double *p = v[s->e[e][0]], *q = v[s->e[e][1]];
        double t0, t1;
        if (!clip_segment(b, p, q, &t0, &t1))
            continue;
        double d[3] = {q[0] - p[0], q[1] - p[1], q[2] - p[2]};
        double len = (t1 - t0) * sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]), tm = 0.5 * (t0 + t1);
        for (int k = 0; k < 3; k++)
            acc[k] += len * (p[k] + tm * d[k]);
        *wsum += len;
    }
}

void dem_pair_contact_point(const dem_body *bi, const dem_body *bj, const double n[3], double depth,
                            const double ccd_pos[3], double out[3])
{
    double si[3], sj[3], mn[3] = {-n[0], -n[1], -n[2]};
    dem_body_support(bi, mn, si);
    dem_body_support(bj, n, sj);
    double hi = si[0] * n[0] + si[1] * n[1] + si[2] * n[2]; /* i's extreme plane (towards j) */
    double hj = sj[0] * n[0] + sj[1] * n[1] + sj[2] * n[2]; /* j's extreme plane (towards i) */
    double hm = 0.5 * (hi + hj);
    (void)depth;
    int pi = bi->type == DEM_BODY_POLY, pj = bj->type == DEM_BODY_POLY;
    if (pi || pj) {
        /* the overlap's edge skeleton: the parts of each polyhedron's edges
         * inside the other body, length-weighted midpoints. It moves
         * continuously as features enter the overlap (a new part starts
         * with zero length), unlike a choice between vertex and edge rules,
         * which made elastic collisions gain up to 120 % of their energy. */
        double acc[3] = {0, 0, 0}, wsum = 0.0;
        if (pi)
            clipped_edges(bi, bj, acc, &wsum);
        if (pj)
            clipped_edges(bj, bi, acc, &wsum);
        if (wsum > 0.0) {
            for (int k = 0; k < 3; k++) { /* projected on the middle plane of the overlap */
                double c = acc[k] / wsum;
                out[k] = c;
            }
            double h = out[0] * n[0] + out[1] * n[1] + out[2] * n[2];
            for (int k = 0; k < 3; k++)
                out[k] += (hm - h) * n[k];
            return;
        }
        /* a face on a smooth body, no edge inside it: the smooth body's deepest point */
        const double *sp = pi && !pj ? sj : (pj && !pi ? si : ccd_pos);
        for (int k = 0; k < 3; k++)
            out[k] = sp[k];
        double h = out[0] * n[0] + out[1] * n[1] + out[2] * n[2];
        for (int k = 0; k < 3; k++)
            out[k] += (hm - h) * n[k];
        return;
    }
    for (int k = 0; k < 3; k++) /* smooth bodies */
        out[k] = 0.5 * (si[k] + sj[k]);
}

static void ccd_support(const void *obj, const ccd_vec3_t *dir, ccd_vec3_t *v)
{
    dem_body_support((const dem_body *)obj, dir->v, v->v);
}

static void ccd_center(const void *obj, ccd_vec3_t *c)
{
    const dem_body *b = obj;
    memcpy(c->v, b->type == DEM_BODY_TRIANGLE ? b->tc : b->c, sizeof c->v);
}

void dem_body_triangle(const double a[3], const double b[3], const double c[3], const double toward[3],
                       dem_body *out)
{
    memset(out, 0, sizeof *out);
    out->type = DEM_BODY_TRIANGLE;
    memcpy(out->tri[0], a, 3 * sizeof *a);
    memcpy(out->tri[1], b, 3 * sizeof *b);
    memcpy(out->tri[2], c, 3 * sizeof *c);
    double bary[3], cp[3];
    dem_closest_on_triangle(toward, a, b, c, bary, cp);
    double d2 = 0.0, l2 = 0.0;
    for (int k = 0; k < 3; k++) {
        d2 += (toward[k] - cp[k]) * (toward[k] - cp[k]);
        l2 += (b[k] - a[k]) * (b[k] - a[k]) + (c[k] - a[k]) * (c[k] - a[k]);
    }
    if (d2 > 1e-20 * l2)
        memcpy(out->tc, cp, sizeof cp);
    else
        for (int k = 0; k < 3; k++)
            out->tc[k] = (a[k] + b[k] + c[k]) / 3.0;
}

int dem_body_penetration(const dem_body *a, const dem_body *b, int gjk_epa, double *depth, double n[3], double p[3])
{
    ccd_t ccd;
    CCD_INIT(&ccd);
    ccd.support1 = ccd_support;
    ccd.support2 = ccd_support;
    ccd.center1 = ccd_center;
    ccd.center2 = ccd_center;
    ccd.max_iterations = 100; /* CCD_INIT: unlimited */
    ccd.mpr_tolerance = 1e-9; /* scaled coordinates: relative to the grain size */
    ccd.epa_tolerance = 1e-9;
    ccd.dist_tolerance = 1e-12;
    ccd_real_t d;
    ccd_vec3_t dir, pos;
    int rc = gjk_epa ? ccdGJKPenetration(a, b, &ccd, &d, &dir, &pos) : ccdMPRPenetration(a, b, &ccd, &d, &dir, &pos);
    if (rc == -1)
        return 0;
    if (rc != 0)
        return -1;
    double l = sqrt(dir.v[0] * dir.v[0] + dir.v[1] * dir.v[1] + dir.v[2] * dir.v[2]);
    if (!(l > 0.0) || !isfinite(d))
        return 0; /* touching with no defined direction */
    for (int k = 0; k < 3; k++) {
        n[k] = dir.v[k] / l;
        p[k] = pos.v[k];
    }
    *depth = d;
    return d > 0.0;
}

double dem_shape_contact_radius(const dem_shape *s, double scale, const double R[9], const double u[3])
{
    if (s->type == DEM_SHAPE_ELLIPSOID) {
        double ub[3];
        mat_tvec(R, u, ub);
        double h = s->a[0] * s->a[0] * ub[0] * ub[0] + s->a[1] * s->a[1] * ub[1] * ub[1] +
                   s->a[2] * s->a[2] * ub[2] * ub[2];
        return scale * s->a[0] * s->a[1] * s->a[2] / h;
    }
    return scale * s->info.r_eq;
}
