/* Non-spherical grains: shapes (ellipsoid, convex polyhedron), their hulls and
 * mass properties, and random polyhedra (see dem_shape.h). The rest of the
 * shaped grains' code, by job: dem_shape_algebra.c (3x3 algebra),
 * dem_shape_rotation.c (free rotation, eq. 8), dem_shape_ccd.c (posed bodies
 * and the libccd narrow phase), dem_shape_contact.c (contacts of shaped
 * grains with grains and walls). */
#include "dem_shape.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dem_shape_algebra.h"
#include "vec3.h"

/* ---- shapes -------------------------------------------------------------- */

/* Polyhedron: convex hull by brute force over vertex triples (n <= 64, once
 * per shape), faces as planes with their vertices ordered around the
 * outward normal; volume, first and second moments from the tetrahedra of
 * each fan triangle with an interior point:
 *   V = a.(b x c)/6, ∫x dV = V (a+b+c)/4,
 *   ∫x x^T dV = V/20 (a a^T + b b^T + c c^T + s s^T), s = a + b + c. */
static int poly_build(const dem_shape_def *def, dem_shape *s, cm_error *err)
{
    int n = def->n_verts;
    if (n < 4 || n > DEM_SHAPE_MAX_VERTS)
        return cm_fail(err, CM_ERR_RANGE, "polyhedron: %d vertices (4..%d)", n, DEM_SHAPE_MAX_VERTS);
    vec3 P[DEM_SHAPE_MAX_VERTS], o = v3(0, 0, 0);
    for (int k = 0; k < n; k++) {
        P[k] = v3_load(def->verts[k]);
        if (!isfinite(P[k].x) || !isfinite(P[k].y) || !isfinite(P[k].z))
            return cm_fail(err, CM_ERR_NUMERIC, "polyhedron: vertex %d is not finite", k);
        o = v3_add(o, P[k]);
    }
    o = v3_scale(o, 1.0 / n);
    double ext = 0.0;
    for (int k = 0; k < n; k++)
        ext = fmax(ext, v3_norm(v3_sub(P[k], o)));
    if (!(ext > 0.0))
        return cm_fail(err, CM_ERR_RANGE, "polyhedron: all vertices coincide");
    const double eps = 1e-9 * ext;
    enum { MAXF = 2 * DEM_SHAPE_MAX_VERTS };
    vec3 fn[MAXF];
    double fd[MAXF];
    int nf = 0;
    int on_hull[DEM_SHAPE_MAX_VERTS] = {0};
    int edges[3 * DEM_SHAPE_MAX_VERTS][2], ne = 0;
    int face_first[MAXF + 1], face_vert[6 * DEM_SHAPE_MAX_VERTS], nfv = 0;
    face_first[0] = 0;
    double vol = 0.0, C[9] = {0};
    vec3 m1 = v3(0, 0, 0);
    for (int i = 0; i < n; i++)
        for (int j = i + 1; j < n; j++)
            for (int k = j + 1; k < n; k++) {
                vec3 nr = v3_cross(v3_sub(P[j], P[i]), v3_sub(P[k], P[i]));
                double nl = v3_norm(nr);
                if (nl <= 1e-12 * ext * ext)
                    continue;
                nr = v3_scale(nr, 1.0 / nl);
                int pos = 0, neg = 0;
                for (int m = 0; m < n && !(pos && neg); m++) {
                    double d = v3_dot(v3_sub(P[m], P[i]), nr);
                    pos |= d > eps, neg |= d < -eps;
                }
                if (pos && neg)
                    continue;
                if (pos)
                    nr = v3_scale(nr, -1.0); /* outward */
                double d0 = v3_dot(nr, P[i]);
                int dup = 0;
                for (int f = 0; f < nf && !dup; f++)
                    dup = v3_dot(fn[f], nr) > 1.0 - 1e-9 && fabs(fd[f] - d0) < eps;
                if (dup)
                    continue;
                if (nf == MAXF)
                    return cm_fail(err, CM_ERR_RANGE, "polyhedron: more than %d hull faces", MAXF);
                fn[nf] = nr, fd[nf] = d0;
                /* the face's vertices, ordered counter-clockwise about nr */
                int fv[DEM_SHAPE_MAX_VERTS], nv = 0;
                vec3 fc = v3(0, 0, 0);
                for (int m = 0; m < n; m++)
                    if (fabs(v3_dot(nr, P[m]) - d0) <= eps) {
                        fv[nv++] = m;
                        fc = v3_add(fc, P[m]);
                        on_hull[m] = 1;
                    }
                fc = v3_scale(fc, 1.0 / nv);
                vec3 u = v3_unit(v3_sub(P[fv[0]], fc)), wv = v3_cross(nr, u);
                double ang[DEM_SHAPE_MAX_VERTS];
                for (int a = 0; a < nv; a++) {
                    vec3 d = v3_sub(P[fv[a]], fc);
                    ang[a] = atan2(v3_dot(d, wv), v3_dot(d, u));
                }
                for (int a = 1; a < nv; a++) /* insertion sort by angle */
                    for (int b = a; b > 0 && ang[b] < ang[b - 1]; b--) {
                        double t = ang[b];
                        ang[b] = ang[b - 1], ang[b - 1] = t;
                        int ti = fv[b];
                        fv[b] = fv[b - 1], fv[b - 1] = ti;
                    }
                if (nfv + nv > 6 * DEM_SHAPE_MAX_VERTS)
                    return cm_fail(err, CM_ERR_RANGE, "polyhedron: more than %d face corners", 6 * DEM_SHAPE_MAX_VERTS);
                for (int a = 0; a < nv; a++)
                    face_vert[nfv++] = fv[a];
                face_first[nf + 1] = nfv;
                for (int a = 0; a < nv; a++) { /* the face's boundary edges, each once */
                    int e0 = fv[a], e1 = fv[(a + 1) % nv], dupe = 0;
                    if (e0 > e1) {
                        int t = e0;
                        e0 = e1, e1 = t;
                    }
                    for (int q = 0; q < ne && !dupe; q++)
                        dupe = edges[q][0] == e0 && edges[q][1] == e1;
                    if (!dupe && ne < 3 * DEM_SHAPE_MAX_VERTS)
                        edges[ne][0] = e0, edges[ne][1] = e1, ne++;
                }
                for (int a = 1; a + 1 < nv; a++) {
                    vec3 A = v3_sub(P[fv[0]], o), B = v3_sub(P[fv[a]], o), Cc = v3_sub(P[fv[a + 1]], o);
                    double V = v3_dot(A, v3_cross(B, Cc)) / 6.0;
                    vec3 S = v3_add(A, v3_add(B, Cc));
                    vol += V;
                    m1 = v3_axpy(V / 4.0, S, m1);
                    vec3 pts[4] = {A, B, Cc, S};
                    for (int t = 0; t < 4; t++) {
                        double p3[3] = {pts[t].x, pts[t].y, pts[t].z};
                        for (int r = 0; r < 3; r++)
                            for (int c = 0; c < 3; c++)
                                C[3 * r + c] += V / 20.0 * p3[r] * p3[c];
                    }
                }
                nf++;
            }
    if (nf < 4 || !(vol > 1e-12 * ext * ext * ext))
        return cm_fail(err, CM_ERR_RANGE, "polyhedron: the vertices are coplanar (volume %g m^3)", vol);
    vec3 com = v3_scale(m1, 1.0 / vol); /* relative to o */
    double cm3[3] = {com.x, com.y, com.z};
    for (int r = 0; r < 3; r++) /* second moment about the centre of mass */
        for (int c = 0; c < 3; c++)
            C[3 * r + c] -= vol * cm3[r] * cm3[c];
    double tr = C[0] + C[4] + C[8], Iten[9];
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 3; c++)
            Iten[3 * r + c] = (r == c ? tr : 0.0) - C[3 * r + c];
    double e[3], V[9];
    dem_jacobi3(Iten, e, V);
    dem_sort_eigen(e, V);
    dem_shape_info *in = &s->info;
    vec3 comw = v3_add(o, com);
    s->n_verts = 0;
    double rb = 0.0;
    int newidx[DEM_SHAPE_MAX_VERTS];
    for (int m = 0; m < n; m++) {
        if (!on_hull[m])
            continue;
        newidx[m] = s->n_verts;
        double d[3] = {P[m].x - comw.x, P[m].y - comw.y, P[m].z - comw.z}, b[3];
        mat_tvec(V, d, b);
        memcpy(s->v[s->n_verts++], b, sizeof b);
        rb = fmax(rb, sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2]));
    }
    s->n_edges = ne;
    for (int q = 0; q < ne; q++)
        s->e[q][0] = newidx[edges[q][0]], s->e[q][1] = newidx[edges[q][1]];
    s->n_faces = nf;
    memcpy(s->face_first, face_first, (size_t)(nf + 1) * sizeof *face_first);
    for (int q = 0; q < nfv; q++)
        s->face_vert[q] = (unsigned char)newidx[face_vert[q]];
    for (int f = 0; f < nf; f++)
        for (int q = face_first[f]; q < face_first[f + 1]; q++)
            s->face_mask[f] |= (uint64_t)1 << s->face_vert[q];
    for (int f = 0; f < nf; f++) {
        double nw[3] = {fn[f].x, fn[f].y, fn[f].z}, nb[3];
        mat_tvec(V, nw, nb);
        memcpy(s->f[f], nb, sizeof nb);
        s->f[f][3] = fd[f] - v3_dot(fn[f], comw);
    }
    in->volume = vol;
    in->r_bound = rb;
    memcpy(in->inertia, e, sizeof e);
    v3_store(in->com, comw);
    memcpy(in->axes, V, sizeof V);
    in->n_verts = s->n_verts;
    in->n_faces = nf;
    return CM_OK;
}

int dem_shape_build(const dem_shape_def *def, dem_shape *s, cm_error *err)
{
    memset(s, 0, sizeof *s);
    s->type = def->type;
    dem_shape_info *in = &s->info;
    in->type = def->type;
    switch (def->type) {
    case DEM_SHAPE_SPHERE: {
        double r = def->radius;
        if (!(r > 0.0) || !isfinite(r))
            return cm_fail(err, CM_ERR_RANGE, "sphere shape: radius %g m", r);
        in->volume = 4.0 / 3.0 * M_PI * r * r * r;
        in->r_bound = r;
        for (int k = 0; k < 3; k++)
            in->inertia[k] = 0.4 * in->volume * r * r;
        s->a[0] = s->a[1] = s->a[2] = r;
        break;
    }
    case DEM_SHAPE_ELLIPSOID: {
        double a[3];
        memcpy(a, def->semi_axes, sizeof a);
        for (int k = 0; k < 3; k++)
            if (!(a[k] > 0.0) || !isfinite(a[k]))
                return cm_fail(err, CM_ERR_RANGE, "ellipsoid shape: semi-axis %d = %g m", k, a[k]);
        /* principal frame: semi-axes descending = moments ascending,
         * I_1 = V (a2² + a3²) / 5 ... */
        int idx[3] = {0, 1, 2};
        for (int p = 0; p < 2; p++)
            for (int q = p + 1; q < 3; q++)
                if (a[idx[q]] > a[idx[p]]) {
                    int t = idx[p];
                    idx[p] = idx[q], idx[q] = t;
                }
        double V[9] = {0};
        for (int c = 0; c < 3; c++) {
            s->a[c] = a[idx[c]];
            V[3 * idx[c] + c] = 1.0;
        }
        double det = V[0] * (V[4] * V[8] - V[5] * V[7]) - V[1] * (V[3] * V[8] - V[5] * V[6]) +
                     V[2] * (V[3] * V[7] - V[4] * V[6]);
        if (det < 0)
            for (int r = 0; r < 3; r++)
                V[3 * r + 2] = -V[3 * r + 2];
        in->volume = 4.0 / 3.0 * M_PI * a[0] * a[1] * a[2];
        in->inertia[0] = in->volume / 5.0 * (s->a[1] * s->a[1] + s->a[2] * s->a[2]);
        in->inertia[1] = in->volume / 5.0 * (s->a[0] * s->a[0] + s->a[2] * s->a[2]);
        in->inertia[2] = in->volume / 5.0 * (s->a[0] * s->a[0] + s->a[1] * s->a[1]);
        in->r_bound = s->a[0];
        memcpy(in->axes, V, sizeof V);
        break;
    }
    case DEM_SHAPE_POLYHEDRON: {
        int rc = poly_build(def, s, err);
        if (rc)
            return rc;
        break;
    }
    default:
        return cm_fail(err, CM_ERR_RANGE, "shape type %d unknown", def->type);
    }
    in->r_eq = cbrt(in->volume * 3.0 / (4.0 * M_PI));
    return CM_OK;
}

int dem_shape_compute(const dem_shape_def *def, dem_shape_info *info, cm_error *err)
{
    dem_shape *s = malloc(sizeof *s);
    if (!s)
        return cm_fail(err, CM_ERR_NOMEM, "dem_shape_compute: out of memory");
    int rc = dem_shape_build(def, s, err);
    if (rc == CM_OK)
        *info = s->info;
    free(s);
    return rc;
}

static uint64_t splitmix(uint64_t *s)
{
    uint64_t z = (*s += 0x9e3779b97f4a7c15ULL);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
}
static double unif(uint64_t *s) { return (double)(splitmix(s) >> 11) * (1.0 / 9007199254740992.0); }

int dem_shape_random_polyhedron(uint64_t seed, double r_eq, double elongation, int n_verts, dem_shape_def *out,
                                cm_error *err)
{
    if (!(r_eq > 0.0) || !(elongation >= 1.0 && elongation <= 10.0) || n_verts < 6 || n_verts > DEM_SHAPE_MAX_VERTS)
        return cm_fail(err, CM_ERR_RANGE,
                       "random polyhedron: r_eq = %g m (> 0), elongation = %g (1..10), vertices = %d (6..%d)", r_eq,
                       elongation, n_verts, DEM_SHAPE_MAX_VERTS);
    memset(out, 0, sizeof *out);
    out->type = DEM_SHAPE_POLYHEDRON;
    out->n_verts = n_verts;
    uint64_t s = seed * 0xd1342543de82ef95ULL + 0x632be59bd9b4e019ULL;
    for (int k = 0; k < n_verts; k++) {
        /* direction uniform on the sphere (rejection from the cube), radius
         * jittered in [0.75, 1]: flat facets and sharp corners */
        double d[3], d2;
        do {
            for (int c = 0; c < 3; c++)
                d[c] = 2.0 * unif(&s) - 1.0;
            d2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        } while (d2 > 1.0 || d2 < 1e-4);
        double r = (0.75 + 0.25 * unif(&s)) / sqrt(d2);
        out->verts[k][0] = elongation * d[0] * r;
        out->verts[k][1] = d[1] * r;
        out->verts[k][2] = d[2] * r;
    }
    dem_shape_info in = {0};
    int rc = dem_shape_compute(out, &in, err);
    if (rc)
        return rc;
    double f = r_eq / in.r_eq;
    for (int k = 0; k < n_verts; k++)
        for (int c = 0; c < 3; c++)
            out->verts[k][c] *= f;
    return CM_OK;
}
