/* Polyhedron–polyhedron contact from the overlap volume (Feng & Owen's
 * energy-conserving framework: Feng, Han & Owen, CMAME 2012; Feng, CMAME
 * 2021). The potential is a function of the intersection volume V alone,
 *   W(V) = k V² / 2,  k = 16 E* / (π² R*³),  R* = r_i r_j / (r_i + r_j)
 * (r: volume-equivalent radii), so the force and torque are its exact
 * gradient (k: poly_stiffness below):
 *   F_i = -k V A_i,  A_i = ∫_{S_i} n dA   (dV/dx_i),
 *   T_i = -k V M_i,  M_i = ∫_{S_i} (x - c_i) × n dA   (dV/dθ_i),
 * S_i the part of i's surface inside j, n its outward normal. Both change
 * continuously when vertices, edges and faces enter the overlap (no feature
 * choice, no jump of normal or depth), and the energy of an elastic impact is
 * kept up to the time integration's error. Why V² (p = 2 in W ∝ V^p): for two
 * flat faces in contact V = A δ and F = k A² δ, a linear spring (a flat
 * punch), while any p < 2 has an infinite stiffness at the touch of two
 * faces (a settled bed would need an ever smaller step). A vertex or an edge
 * pressed into a face is softer than Hertz at first (F ∝ δ⁵ and δ³); see
 * README.
 * Dissipation and friction act at the centroid of the overlap volume along
 * n = (A_j - A_i)/|A_j - A_i| (from j to i): the Hertz–Mindlin dashpot with
 * the contact's normal stiffness S_n = k |A|², the Mindlin spring with
 * S_t = 8 G* a, a = sqrt(|A| / π) (the radius of a disc of the contact's
 * projected area), Coulomb cap μ F_n.
 *
 * Cost: the hull vertices and face planes of every polyhedral grain are put
 * in the world frame once per step (dem_shaped_pose_update), not per pair.
 * A pair whose bounding spheres overlap is first tested on its cached
 * separating axis (kept in the pair's tangential-spring slot while the pair
 * is apart, see below), then on the centre line and all face normals of both
 * hulls (the vertex-to-plane table the clipping needs anyway); only pairs
 * that pass are clipped (each face of one hull against the other's planes
 * that cut it, Sutherland–Hodgman). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dem_contact.h"
#include "dem_shape.h"
#include "dem_world.h"
#include "vec3.h"

/* pose layout per grain slot: R (9, body -> world), then the vertices
 * relative to the centre in the world frame (3 per vertex, scaled), then the
 * face planes (n world, d relative to the centre: n . (x - c) <= d inside) */
static int pose_nv(const dem_world *w) { return w->pose_nv; }

int dem_shaped_pose_alloc(dem_world *w, cm_error *err)
{
    int nv = 0, nf = 0;
    for (int s = 0; s < w->n_shapes; s++)
        if (w->shapes[s].type == DEM_SHAPE_POLYHEDRON) {
            nv = w->shapes[s].n_verts > nv ? w->shapes[s].n_verts : nv;
            nf = w->shapes[s].n_faces > nf ? w->shapes[s].n_faces : nf;
        }
    if (nv == 0 || w->n_shaped == 0)
        return CM_OK;
    int stride = 9 + 3 * nv + 4 * nf;
    if (w->pose && stride == w->pose_stride)
        return CM_OK;
    free(w->pose);
    w->pose = malloc((size_t)w->g.cap * (size_t)stride * sizeof *w->pose);
    if (!w->pose)
        return cm_fail(err, CM_ERR_NOMEM, "dem_shaped_pose_alloc: %d grains x %d doubles", w->g.cap, stride);
    w->pose_stride = stride;
    w->pose_nv = nv;
    return CM_OK;
}

void dem_shaped_pose_update(dem_world *w)
{
    if (!w->pose)
        return;
    const dem_grains *g = &w->g;
    const int n = g->n, stride = w->pose_stride, nvm = pose_nv(w);
#ifdef _OPENMP
#pragma omp parallel for num_threads(w->n_threads) schedule(static)
#endif
    for (int i = 0; i < n; i++) {
        int sh = g->shape[i];
        if (sh < 0 || w->shapes[sh].type != DEM_SHAPE_POLYHEDRON)
            continue;
        const dem_shape *s = &w->shapes[sh];
        double *P = w->pose + (size_t)i * stride, *R = P, *V = P + 9, *F = P + 9 + 3 * nvm;
        double sc = g->sc[i];
        dem_quat_to_mat(g->q + 4 * i, R);
        for (int t = 0; t < s->n_verts; t++) {
            const double *v = s->v[t];
            V[3 * t + 0] = sc * (R[0] * v[0] + R[1] * v[1] + R[2] * v[2]);
            V[3 * t + 1] = sc * (R[3] * v[0] + R[4] * v[1] + R[5] * v[2]);
            V[3 * t + 2] = sc * (R[6] * v[0] + R[7] * v[1] + R[8] * v[2]);
        }
        for (int f = 0; f < s->n_faces; f++) {
            const double *pl = s->f[f];
            F[4 * f + 0] = R[0] * pl[0] + R[1] * pl[1] + R[2] * pl[2];
            F[4 * f + 1] = R[3] * pl[0] + R[4] * pl[1] + R[5] * pl[2];
            F[4 * f + 2] = R[6] * pl[0] + R[7] * pl[1] + R[8] * pl[2];
            F[4 * f + 3] = sc * pl[3];
        }
    }
}

/* A posed hull in coordinates relative to the second grain's centre. */
typedef struct posed_hull {
    const dem_shape *s;
    double c[3];       /* centre */
    const double *v;   /* vertex offsets from c (3 per vertex) */
    const double *f;   /* planes (n, d) about c */
} posed_hull;

static void hull_of(const dem_world *w, int i, const double origin[3], posed_hull *h)
{
    const double *P = w->pose + (size_t)i * w->pose_stride;
    h->s = &w->shapes[w->g.shape[i]];
    h->c[0] = w->g.x[i] - origin[0], h->c[1] = w->g.y[i] - origin[1], h->c[2] = w->g.z[i] - origin[2];
    h->v = P + 9;
    h->f = P + 9 + 3 * w->pose_nv;
}

/* min over a's vertices of x . u (x relative to the common origin) */
static inline double hull_min(const posed_hull *a, const double u[3])
{
    double m = INFINITY;
    for (int t = 0; t < a->s->n_verts; t++) {
        const double *v = a->v + 3 * t;
        double d = v[0] * u[0] + v[1] * u[1] + v[2] * u[2];
        m = d < m ? d : m;
    }
    return m + a->c[0] * u[0] + a->c[1] * u[1] + a->c[2] * u[2];
}

/* i lies entirely on the + side of j along unit axis u */
static inline int separates(const posed_hull *hi, const posed_hull *hj, const double u[3])
{
    double mu[3] = {-u[0], -u[1], -u[2]};
    return hull_min(hi, u) > -hull_min(hj, mu);
}

/* Overlap integrals accumulated over the clipped faces. */
typedef struct overlap {
    double V;        /* volume */
    double Vc[3];    /* ∫ x dV (relative to the origin) */
    double A[2][3];  /* ∫ n dA over S_i (0) and S_j (1) */
    double M[2][3];  /* ∫ (x - c) × n dA over S_i, S_j */
} overlap;

enum { CLIP_MAX = DEM_SHAPE_MAX_VERTS + 2 * DEM_SHAPE_MAX_VERTS + 2 };

/* The part of a hull that can meet the other inside the slab where both
 * extend along an axis u (a on its + side): the vertices with x.u on the
 * other's side of the slab's far bound, the faces having one of them
 * (`faces`, the only ones that reach into the slab) and all those faces'
 * corners (`verts`). The other hull's part of the slab lies inside the
 * convex hull of `verts` (an edge leaving the slab belongs to a listed
 * face), and within the slab the hull is the intersection of the listed
 * faces' half-spaces: clipping with them alone is exact. */
typedef struct hull_part {
    int n_faces;
    int faces[2 * DEM_SHAPE_MAX_VERTS];
    uint64_t verts;
} hull_part;

static void hull_part_of(const posed_hull *a, const double u[3], double lim, double sgn, hull_part *hp)
{
    const dem_shape *s = a->s;
    double cu = a->c[0] * u[0] + a->c[1] * u[1] + a->c[2] * u[2];
    uint64_t near = 0;
    for (int t = 0; t < s->n_verts; t++) {
        const double *v = a->v + 3 * t;
        near |= (uint64_t)(sgn * (v[0] * u[0] + v[1] * u[1] + v[2] * u[2] + cu - lim) <= 0.0) << t;
    }
    hp->n_faces = 0;
    hp->verts = 0;
    for (int f = 0; f < s->n_faces; f++)
        if (s->face_mask[f] & near) {
            hp->faces[hp->n_faces++] = f;
            hp->verts |= s->face_mask[f];
        }
}

/* b's planes (of bp's faces) that have some of a's vertices (of ap) outside:
 * index and the mask of those vertices (the others cut nothing). */
typedef struct plane_set {
    int n;
    int f[2 * DEM_SHAPE_MAX_VERTS];
    uint64_t out[2 * DEM_SHAPE_MAX_VERTS];
} plane_set;

/* Fills ps. Returns 1 if one of the planes has all of ap's vertices outside
 * (then the hulls are apart; that plane's index in *sep). open: a vertex on
 * a plane counts as outside. Where faces of i and j lie in one plane with the
 * same outward normal, the overlap's boundary there must be counted once:
 * i's faces are clipped by j's closed half-spaces and j's faces by i's open
 * ones, so i's piece is kept and j's dropped (aligned cubes). */
static int plane_table(const posed_hull *a, const hull_part *ap, const posed_hull *b, const hull_part *bp, int open,
                       plane_set *ps, int *sep)
{
    double rel[3] = {a->c[0] - b->c[0], a->c[1] - b->c[1], a->c[2] - b->c[2]};
    int idx[DEM_SHAPE_MAX_VERTS], nv = 0;
    for (uint64_t m = ap->verts; m; m &= m - 1)
        idx[nv++] = __builtin_ctzll(m);
    ps->n = 0;
    for (int q = 0; q < bp->n_faces; q++) {
        const int f = bp->faces[q];
        const double *pl = b->f + 4 * f;
        double off = pl[3] - (pl[0] * rel[0] + pl[1] * rel[1] + pl[2] * rel[2]);
        uint64_t out = 0;
        for (int k = 0; k < nv; k++) {
            const double *v = a->v + 3 * idx[k];
            double d = v[0] * pl[0] + v[1] * pl[1] + v[2] * pl[2] - off;
            out |= (uint64_t)(open ? d >= 0.0 : d > 0.0) << idx[k];
        }
        if (out == ap->verts) {
            *sep = f;
            return 1;
        }
        if (out) {
            ps->f[ps->n] = f;
            ps->out[ps->n++] = out;
        }
    }
    return 0;
}

static void clip_faces(const posed_hull *a, const posed_hull *b, const plane_set *ps, const plane_set *faces, int side,
                       const double p0[3], overlap *o);

/* Integrals of the overlap of hulls i and j (i's centre relative to j's).
 * Returns 0 if they are found apart before clipping, with the separating
 * axis in sep (i on its + side) when it separates the whole hulls (the
 * centre line, or a face normal that the parts showed), zero otherwise. */
static int overlap_of(const posed_hull *hi, const posed_hull *hj, overlap *o, double sep[3])
{
    double u[3] = {hi->c[0], hi->c[1], hi->c[2]}, ul = sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
    sep[0] = sep[1] = sep[2] = 0.0;
    double lo = -INFINITY, hi_top = INFINITY;
    if (ul > 0.0) {
        for (int k = 0; k < 3; k++)
            u[k] /= ul;
        double mu[3] = {-u[0], -u[1], -u[2]};
        lo = hull_min(hi, u);       /* i's lowest point along u */
        hi_top = -hull_min(hj, mu); /* j's highest */
        if (lo > hi_top) {
            memcpy(sep, u, sizeof u);
            return 0;
        }
    } else {
        u[0] = 1.0, u[1] = u[2] = 0.0;
    }
    hull_part pi, pj;
    hull_part_of(hi, u, hi_top, 1.0, &pi);
    hull_part_of(hj, u, lo, -1.0, &pj);
    plane_set pij, pji;
    int f;
    if (plane_table(hi, &pi, hj, &pj, 0, &pij, &f)) { /* i's part outside j's face f */
        for (int k = 0; k < 3; k++)
            u[k] = hj->f[4 * f + k];
        if (separates(hi, hj, u)) /* and the whole of i: an axis for the next step */
            memcpy(sep, u, sizeof u);
        return 0;
    }
    if (plane_table(hj, &pj, hi, &pi, 1, &pji, &f)) { /* j's part outside i's face f */
        for (int k = 0; k < 3; k++)
            u[k] = -hi->f[4 * f + k];
        if (separates(hi, hj, u))
            memcpy(sep, u, sizeof u);
        return 0;
    }
    memset(o, 0, sizeof *o);
    double p0[3]; /* the middle of the slab on the centre line */
    double mid = isfinite(lo) && isfinite(hi_top) ? 0.5 * (lo + hi_top) : 0.0;
    for (int k = 0; k < 3; k++)
        p0[k] = mid * u[k];
    clip_faces(hi, hj, &pij, &pji, 0, p0, o);
    clip_faces(hj, hi, &pji, &pij, 1, p0, o);
    return 1;
}

/* outside a plane at signed distance d: i's faces (side 0) against j's
 * closed half-spaces, j's (side 1) against i's open ones (plane_table) */
static inline int out_of(double d, int side) { return side ? d >= 0.0 : d > 0.0; }

/* The faces of a clipped by b's planes (ps: plane_table(a, b); faces: plane_table(b, a),
 * the faces of a whose plane some vertex of b crosses, the only ones that can
 * meet b). Adds the clipped polygons' integrals to o (side 0 for i's faces,
 * 1 for j's). */
static void clip_faces(const posed_hull *a, const posed_hull *b, const plane_set *ps, const plane_set *faces, int side,
                       const double p0[3], overlap *o)
{
    const dem_shape *sa = a->s;
    double poly[2][CLIP_MAX][3];
    for (int qa = 0; qa < faces->n; qa++) {
        const int fa = faces->f[qa];
        const uint64_t fm = sa->face_mask[fa];
        /* b's planes that cut this face; skip the face if one has it all outside */
        int cut[2 * DEM_SHAPE_MAX_VERTS], ncut = 0, out = 0;
        for (int q = 0; q < ps->n; q++) {
            uint64_t om = ps->out[q];
            if (!(fm & ~om)) {
                out = 1;
                break;
            }
            if (fm & om)
                cut[ncut++] = ps->f[q];
        }
        if (out)
            continue;
        const int v0 = sa->face_first[fa], nva = sa->face_first[fa + 1] - v0;
        const unsigned char *fv = sa->face_vert + v0;
        int np = nva, cur = 0;
        for (int k = 0; k < nva; k++)
            for (int d = 0; d < 3; d++)
                poly[0][k][d] = a->c[d] + a->v[3 * fv[k] + d];
        for (int q = 0; q < ncut && np >= 3; q++) { /* Sutherland–Hodgman against plane cut[q] */
            const double *pl = b->f + 4 * cut[q];
            const double off = pl[3] + pl[0] * b->c[0] + pl[1] * b->c[1] + pl[2] * b->c[2];
            double (*in)[3] = poly[cur], (*res)[3] = poly[cur ^ 1];
            double dist[CLIP_MAX];
            int n_out = 0;
            for (int k = 0; k < np; k++) {
                dist[k] = in[k][0] * pl[0] + in[k][1] * pl[1] + in[k][2] * pl[2] - off;
                n_out += out_of(dist[k], side);
            }
            if (n_out == 0) /* an earlier plane already cut away what this one would */
                continue;
            if (n_out == np) {
                np = 0;
                break;
            }
            int nr = 0;
            for (int k = 0, kp = np - 1; k < np; kp = k++) {
                const double *pp = in[kp], *pc = in[k];
                double dp = dist[kp], dc = dist[k];
                if (out_of(dp, side) != out_of(dc, side) && nr < CLIP_MAX) { /* the edge crosses: its crossing point */
                    double t = dp / (dp - dc);
                    for (int d = 0; d < 3; d++)
                        res[nr][d] = pp[d] + t * (pc[d] - pp[d]);
                    nr++;
                }
                if (!out_of(dc, side) && nr < CLIP_MAX) {
                    memcpy(res[nr], pc, sizeof res[nr]);
                    nr++;
                }
            }
            np = nr;
            cur ^= 1;
        }
        if (np < 3)
            continue;
        /* fan from the first corner: area, ∫ x dA and the volume from the origin */
        const double *pl = a->f + 4 * fa; /* outward normal of a's face */
        double (*P)[3] = poly[cur];
        double area = 0.0, xa[3] = {0, 0, 0}, vol = 0.0, vc[3] = {0, 0, 0};
        for (int k = 1; k + 1 < np; k++) {
            double e1[3] = {P[k][0] - P[0][0], P[k][1] - P[0][1], P[k][2] - P[0][2]};
            double e2[3] = {P[k + 1][0] - P[0][0], P[k + 1][1] - P[0][1], P[k + 1][2] - P[0][2]};
            double cr[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
            double at = 0.5 * (cr[0] * pl[0] + cr[1] * pl[1] + cr[2] * pl[2]);
            /* signed volume of the tetrahedron (p0, triangle): at ((x - p0) . n) / 3; p0
             * inside the overlap's slab, so that thin overlaps do not cancel */
            double h = (P[0][0] - p0[0]) * pl[0] + (P[0][1] - p0[1]) * pl[1] + (P[0][2] - p0[2]) * pl[2];
            double vt = at * h / 3.0;
            area += at;
            vol += vt;
            for (int d = 0; d < 3; d++) {
                double s3 = P[0][d] + P[k][d] + P[k + 1][d];
                xa[d] += at * s3 / 3.0;
                vc[d] += vt * (s3 + p0[d]) / 4.0;
            }
        }
        if (!(area > 0.0))
            continue;
        o->V += vol;
        double cx[3]; /* ∫ (x - c) dA */
        for (int d = 0; d < 3; d++) {
            o->Vc[d] += vc[d];
            o->A[side][d] += area * pl[d];
            cx[d] = xa[d] - area * a->c[d];
        }
        o->M[side][0] += cx[1] * pl[2] - cx[2] * pl[1];
        o->M[side][1] += cx[2] * pl[0] - cx[0] * pl[2];
        o->M[side][2] += cx[0] * pl[1] - cx[1] * pl[0];
    }
}

/* k of W = k V² / 2: two flat faces in contact are a linear spring
 * F = k A² δ, the flat-punch stiffness 2 E* a (Johnson, Contact Mechanics
 * §5.2) for a face of area A = π a² with a = R* / 2, about a face's
 * inradius for the 10–16-vertex grains of dem_shape_random_polyhedron. */
static inline double poly_stiffness(double E_star, double R_star)
{
    double a = 0.5 * R_star;
    return 2.0 * E_star / (M_PI * M_PI * a * a * a);
}

/* The pair's history slot (3 doubles) holds the Mindlin spring while the
 * grains touch and, while they are apart, the unit axis that last separated
 * them (tried first next step: one support evaluation per hull). A spring is
 * a displacement of the order of the overlap (far below 1 m), so a vector
 * of length > 0.5 is an axis; a new contact starts its spring at zero. */
static inline int slot_is_axis(const double xi[3]) { return xi[0] * xi[0] + xi[1] * xi[1] + xi[2] * xi[2] > 0.25; }

int dem_poly_pair(dem_world *w, int i, int j, double *xi, double *fx, double *fy, double *fz, double *tx, double *ty,
                  double *tz)
{
    dem_grains *g = &w->g;
    const double origin[3] = {g->x[j], g->y[j], g->z[j]};
    posed_hull hi, hj;
    hull_of(w, i, origin, &hi);
    hull_of(w, j, origin, &hj);
    if (slot_is_axis(xi) && separates(&hi, &hj, xi))
        return 0;
    overlap o;
    double sep[3];
    if (!overlap_of(&hi, &hj, &o, sep)) {
        memcpy(xi, sep, sizeof sep);
        return 0;
    }
    vec3 Av = v3(0.5 * (o.A[1][0] - o.A[0][0]), 0.5 * (o.A[1][1] - o.A[0][1]), 0.5 * (o.A[1][2] - o.A[0][2]));
    double area = v3_norm(Av);
    if (!(o.V > 0.0) || !(area > 0.0)) { /* apart (separated along an edge-edge axis) or touching */
        xi[0] = xi[1] = xi[2] = 0.0;
        return 0;
    }
    if (slot_is_axis(xi)) /* a new contact: its spring starts at zero */
        xi[0] = xi[1] = xi[2] = 0.0;
    const dem_shape *si = hi.s, *sj = hj.s;
    double ri = si->info.r_eq * g->sc[i], rj = sj->info.r_eq * g->sc[j], Rs = ri * rj / (ri + rj);
    const dem_pair_coef *cf = &w->coef[g->mat[i]][g->mat[j]];
    double k = poly_stiffness(cf->E, Rs);
    double kv = k * o.V;
    vec3 n = v3_scale(Av, 1.0 / area); /* from j to i */
    vec3 Fe = v3_scale(Av, kv);        /* -k V A_i, symmetrised (A_j = -A_i for a closed surface) */
    vec3 Ti = v3(-kv * o.M[0][0], -kv * o.M[0][1], -kv * o.M[0][2]);
    vec3 Tj = v3(-kv * o.M[1][0], -kv * o.M[1][1], -kv * o.M[1][2]);
    /* dissipation and friction at the overlap's centroid */
    vec3 p = v3(o.Vc[0] / o.V, o.Vc[1] / o.V, o.Vc[2] / o.V); /* relative to the origin = c_j */
    vec3 di = v3_sub(p, v3_load(hi.c)), dj = p;
    vec3 wi = v3(g->wx[i], g->wy[i], g->wz[i]), wj = v3(g->wx[j], g->wy[j], g->wz[j]);
    vec3 vrel = v3_sub(v3_add(v3(g->vx[i], g->vy[i], g->vz[i]), v3_cross(wi, di)),
                       v3_add(v3(g->vx[j], g->vy[j], g->vz[j]), v3_cross(wj, dj)));
    double m = 1.0 / (g->inv_m[i] + g->inv_m[j]);
    double fe = kv * area, sn = k * area * area;
    double fd = -cf->gamma_n * sqrt(sn * m) * v3_dot(vrel, n);
    if (fe + fd < 0.0) /* no tension */
        fd = -fe;
    double fn = fe + fd;
    vec3 ft = dem_mindlin_tangential(cf, n, vrel, 8.0 * cf->G * sqrt(area / M_PI), m, fn, w->def.dt, xi);
    vec3 Fp = v3_axpy(fd, n, ft); /* the part acting at p */
    vec3 F = v3_add(Fe, Fp);
    Ti = v3_add(Ti, v3_cross(di, Fp));
    Tj = v3_sub(Tj, v3_cross(dj, Fp));
    if (cf->mu_roll > 0.0) {
        vec3 tr = dem_rolling_torque(cf, Rs, fn, v3_sub(wi, wj), 1.0 / (g->inv_i[i] + g->inv_i[j]), w->def.dt);
        Ti = v3_add(Ti, tr);
        Tj = v3_sub(Tj, tr);
    }
    fx[i] += F.x, fy[i] += F.y, fz[i] += F.z;
    fx[j] -= F.x, fy[j] -= F.y, fz[j] -= F.z;
    tx[i] += Ti.x, ty[i] += Ti.y, tz[i] += Ti.z;
    tx[j] += Tj.x, ty[j] += Tj.y, tz[j] += Tj.z;
    return 1;
}

/* Overlap volume of two polyhedral grains (diagnostics and tests), m³. */
double dem_poly_overlap_volume(const dem_world *w, int i, int j)
{
    const dem_grains *g = &w->g;
    const double origin[3] = {g->x[j], g->y[j], g->z[j]};
    posed_hull hi, hj;
    hull_of(w, i, origin, &hi);
    hull_of(w, j, origin, &hj);
    overlap o;
    double sep[3];
    return overlap_of(&hi, &hj, &o, sep) && o.V > 0.0 ? o.V : 0.0;
}
