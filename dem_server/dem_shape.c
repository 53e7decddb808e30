/* Non-spherical grains: hull and mass properties, rigid-body rotation, libccd
 * narrow phase and the contacts of shaped grains (see dem_shape.h). */
#include "dem_shape.h"

#include <assert.h>
#include <ccd/ccd.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dem_contact.h"
#include "dem_surface.h"
#include "dem_world.h"
#include "vec3.h"

#ifndef CCD_DOUBLE
#error "libccd must be built in double precision (CCD_DOUBLE): Debian's libccd-dev is"
#endif
_Static_assert(sizeof(ccd_real_t) == sizeof(double), "libccd in double precision");

/* ---- small linear algebra ---------------------------------------------- */

void dem_quat_to_mat(const double q[4], double R[9])
{
    double w = q[0], x = q[1], y = q[2], z = q[3];
    R[0] = 1 - 2 * (y * y + z * z), R[1] = 2 * (x * y - w * z), R[2] = 2 * (x * z + w * y);
    R[3] = 2 * (x * y + w * z), R[4] = 1 - 2 * (x * x + z * z), R[5] = 2 * (y * z - w * x);
    R[6] = 2 * (x * z - w * y), R[7] = 2 * (y * z + w * x), R[8] = 1 - 2 * (x * x + y * y);
}

static inline void mat_vec(const double R[9], const double a[3], double out[3])
{
    double x = R[0] * a[0] + R[1] * a[1] + R[2] * a[2];
    double y = R[3] * a[0] + R[4] * a[1] + R[5] * a[2];
    double z = R[6] * a[0] + R[7] * a[1] + R[8] * a[2];
    out[0] = x, out[1] = y, out[2] = z;
}

static inline void mat_tvec(const double R[9], const double a[3], double out[3])
{
    double x = R[0] * a[0] + R[3] * a[1] + R[6] * a[2];
    double y = R[1] * a[0] + R[4] * a[1] + R[7] * a[2];
    double z = R[2] * a[0] + R[5] * a[1] + R[8] * a[2];
    out[0] = x, out[1] = y, out[2] = z;
}

/* Eigen-decomposition of a symmetric 3x3 matrix A (row-major) by cyclic
 * Jacobi rotations: A = V diag(e) V^T, V's columns the eigenvectors. */
static void jacobi3(const double Ain[9], double e[3], double V[9])
{
    double A[3][3];
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 3; c++) {
            A[r][c] = Ain[3 * r + c];
            V[3 * r + c] = r == c;
        }
    double scale = fabs(A[0][0]) + fabs(A[1][1]) + fabs(A[2][2]);
    for (int sweep = 0; sweep < 50; sweep++) {
        double off = fabs(A[0][1]) + fabs(A[0][2]) + fabs(A[1][2]);
        if (off <= 1e-15 * scale)
            break;
        for (int p = 0; p < 2; p++)
            for (int q = p + 1; q < 3; q++) {
                if (fabs(A[p][q]) <= 1e-18 * scale)
                    continue; /* an exact zero stays zero: a degenerate (cube) tensor keeps its frame */
                double theta = (A[q][q] - A[p][p]) / (2.0 * A[p][q]);
                double t = (theta >= 0 ? 1.0 : -1.0) / (fabs(theta) + sqrt(theta * theta + 1.0));
                double c = 1.0 / sqrt(t * t + 1.0), s = t * c;
                for (int k = 0; k < 3; k++) { /* A <- J^T A J */
                    double akp = A[k][p], akq = A[k][q];
                    A[k][p] = c * akp - s * akq;
                    A[k][q] = s * akp + c * akq;
                }
                for (int k = 0; k < 3; k++) {
                    double apk = A[p][k], aqk = A[q][k];
                    A[p][k] = c * apk - s * aqk;
                    A[q][k] = s * apk + c * aqk;
                }
                for (int k = 0; k < 3; k++) {
                    double vkp = V[3 * k + p], vkq = V[3 * k + q];
                    V[3 * k + p] = c * vkp - s * vkq;
                    V[3 * k + q] = s * vkp + c * vkq;
                }
            }
    }
    for (int k = 0; k < 3; k++)
        e[k] = A[k][k];
}

/* Sorts eigenpairs ascending and makes V a proper rotation (det +1). */
static void sort_eigen(double e[3], double V[9])
{
    for (int a = 0; a < 2; a++)
        for (int b = a + 1; b < 3; b++)
            if (e[b] < e[a]) {
                double t = e[a];
                e[a] = e[b], e[b] = t;
                for (int r = 0; r < 3; r++) {
                    t = V[3 * r + a];
                    V[3 * r + a] = V[3 * r + b], V[3 * r + b] = t;
                }
            }
    double det = V[0] * (V[4] * V[8] - V[5] * V[7]) - V[1] * (V[3] * V[8] - V[5] * V[6]) +
                 V[2] * (V[3] * V[7] - V[4] * V[6]);
    if (det < 0)
        for (int r = 0; r < 3; r++)
            V[3 * r + 2] = -V[3 * r + 2];
}

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
    jacobi3(Iten, e, V);
    sort_eigen(e, V);
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

/* ---- rotation -------------------------------------------------------------- */

/* q <- q (cos φ/2, sin φ/2 e_k): rotation by φ about body axis k; the body
 * components of the (world-constant) angular momentum turn by -φ. */
static inline void rotate_axis(double q[4], double pi[3], int k, double phi)
{
    double c = cos(0.5 * phi), s = sin(0.5 * phi);
    double r[4] = {c, 0, 0, 0};
    r[1 + k] = s;
    double w = q[0] * r[0] - q[1] * r[1] - q[2] * r[2] - q[3] * r[3];
    double x = q[0] * r[1] + q[1] * r[0] + q[2] * r[3] - q[3] * r[2];
    double y = q[0] * r[2] - q[1] * r[3] + q[2] * r[0] + q[3] * r[1];
    double z = q[0] * r[3] + q[1] * r[2] - q[2] * r[1] + q[3] * r[0];
    q[0] = w, q[1] = x, q[2] = y, q[3] = z;
    int a = (k + 1) % 3, b = (k + 2) % 3;
    double cp = cos(phi), sp = sin(phi);
    double pa = pi[a], pb = pi[b];
    pi[a] = cp * pa + sp * pb;
    pi[b] = -sp * pa + cp * pb;
}

void dem_rotate_free(double q[4], const double L[3], const double I[3], double dt, double omega[3])
{
    double R[9], pi[3];
    dem_quat_to_mat(q, R);
    mat_tvec(R, L, pi);
    const int axis[5] = {2, 1, 0, 1, 2};
    const double frac[5] = {0.5, 0.5, 1.0, 0.5, 0.5};
    for (int s = 0; s < 5; s++) {
        int k = axis[s];
        rotate_axis(q, pi, k, frac[s] * dt * pi[k] / I[k]);
    }
    double qn = 1.0 / sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    for (int k = 0; k < 4; k++)
        q[k] *= qn;
    dem_quat_to_mat(q, R);
    double wb[3] = {pi[0] / I[0], pi[1] / I[1], pi[2] / I[2]};
    mat_vec(R, wb, omega);
}

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

/* ---- contacts of shaped grains --------------------------------------------- */

void dem_grain_body(const dem_world *w, int i, const double origin[3], double inv_l, dem_body *b)
{
    const dem_grains *g = &w->g;
    b->c[0] = (g->x[i] - origin[0]) * inv_l;
    b->c[1] = (g->y[i] - origin[1]) * inv_l;
    b->c[2] = (g->z[i] - origin[2]) * inv_l;
    int sh = g->shape[i];
    if (sh < 0) {
        b->type = DEM_BODY_SPHERE;
        b->s = NULL;
        b->k = g->r[i] * inv_l;
        return;
    }
    b->s = &w->shapes[sh];
    b->type = b->s->type == DEM_SHAPE_ELLIPSOID ? DEM_BODY_ELLIPSOID : DEM_BODY_POLY;
    b->k = g->sc[i] * inv_l;
    dem_quat_to_mat(g->q + 4 * i, b->R);
}

static double grain_contact_radius(const dem_world *w, int i, const dem_body *b, const double u[3])
{
    int sh = w->g.shape[i];
    return sh < 0 ? w->g.r[i] : dem_shape_contact_radius(&w->shapes[sh], w->g.sc[i], b->R, u);
}

/* MPR's depth is measured along the line between the centres; for two
 * smooth bodies (spheres, ellipsoids) that is not the minimum translation
 * and the force is then not the gradient of the Hertz energy: a glancing
 * elastic collision of ellipsoids gained up to 30 % of its energy. Newton
 * iterations on the contact normal converge to the minimum translation,
 * where the support points differ along n: g(n) = s_i(-n) - s_j(n) (from j
 * towards i... in our sign, i's deepest point minus j's), tangential
 * residual t = g - (g.n) n, step n <- unit(n + t / (rho_i + rho_j)) with the
 * local radii of curvature rho (exact in one step for spheres). Depth
 * -g.n. Returns 0 if the bodies turn out apart. */
static int smooth_refine(const dem_body *bi, const dem_body *bj, double *depth, double n[3])
{
    for (int it = 0; it < 12; it++) {
        double mn[3] = {-n[0], -n[1], -n[2]}, si[3], sj[3], g[3];
        dem_body_support(bi, mn, si);
        dem_body_support(bj, n, sj);
        for (int k = 0; k < 3; k++)
            g[k] = sj[k] - si[k]; /* = depth n at the solution */
        double gn = g[0] * n[0] + g[1] * n[1] + g[2] * n[2];
        double t[3] = {g[0] - gn * n[0], g[1] - gn * n[1], g[2] - gn * n[2]};
        double t2 = t[0] * t[0] + t[1] * t[1] + t[2] * t[2];
        *depth = gn;
        if (t2 < 1e-24)
            break;
        double rho = (bi->type == DEM_BODY_SPHERE ? bi->k : dem_shape_contact_radius(bi->s, bi->k, bi->R, mn)) +
                     (bj->type == DEM_BODY_SPHERE ? bj->k : dem_shape_contact_radius(bj->s, bj->k, bj->R, n));
        double l = 0.0;
        for (int k = 0; k < 3; k++) {
            n[k] -= t[k] / rho;
            l += n[k] * n[k];
        }
        l = 1.0 / sqrt(l);
        for (int k = 0; k < 3; k++)
            n[k] *= l;
    }
    return *depth > 0.0;
}

/* Penetration of grain body b into a by MPR, for the pair kernels: 1 in
 * contact, 0 apart. libccd's MPR has no failure code (ccd.h: 0 intersect,
 * -1 apart; only GJK+EPA can fail, -2 on allocation, and the kernels do not
 * use it), so dem_body_penetration's "< 0" cannot come from here: a libccd
 * that changed this is caught in debug builds (the sanitizer CI build) rather
 * than read as "apart". */
static int grains_penetrate(const dem_body *a, const dem_body *b, double *depth, double n[3], double p[3])
{
    const int rc = dem_body_penetration(a, b, 0, depth, n, p);
    assert(rc >= 0 && "libccd's MPR returned a failure code (ccd.h documents 0 or -1)");
    return rc == 1;
}

int dem_shaped_pair(dem_world *w, int i, int j, double *xi, double *fx, double *fy, double *fz, double *tx,
                    double *ty, double *tz)
{
    dem_grains *g = &w->g;
    double ex = g->x[i] - g->x[j], ey = g->y[i] - g->y[j], ez = g->z[i] - g->z[j];
    double d2 = ex * ex + ey * ey + ez * ez, rs = g->r[i] + g->r[j];
    if (w->pose && g->shape[i] >= 0 && g->shape[j] >= 0 && w->shapes[g->shape[i]].type == DEM_SHAPE_POLYHEDRON &&
        w->shapes[g->shape[j]].type == DEM_SHAPE_POLYHEDRON) {
        if (d2 < rs * rs)
            return dem_poly_pair(w, i, j, xi, fx, fy, fz, tx, ty, tz);
        xi[0] = xi[1] = xi[2] = 0.0;
        return 0;
    }
    double L = fmax(g->r[i], g->r[j]), inv_l = 1.0 / L;
    double origin[3] = {g->x[j], g->y[j], g->z[j]};
    dem_body bi, bj;
    double depth = 0.0, n[3], pc[3];
    int in = 0;
    if (d2 < rs * rs) { /* bounding spheres overlap: narrow phase */
        dem_grain_body(w, i, origin, inv_l, &bi);
        dem_grain_body(w, j, origin, inv_l, &bj);
        /* obj1 = j, obj2 = i: n points from j to i (eq. 10) */
        in = grains_penetrate(&bj, &bi, &depth, n, pc);
    }
    if (in && bi.type != DEM_BODY_POLY && bj.type != DEM_BODY_POLY)
        in = smooth_refine(&bi, &bj, &depth, n);
    if (!in) {
        if (xi[0] != 0.0 || xi[1] != 0.0 || xi[2] != 0.0)
            xi[0] = xi[1] = xi[2] = 0.0;
        return 0;
    }
    double delta = depth * L;
    vec3 nv = v3_load(n);
    /* contact point: the middle of the overlap along n from i's deepest
     * point, support_i(-n) + (delta/2) n (for two spheres exactly the sphere
     * path's point; libccd's own point averages portal support points and
     * wanders at edges), for a polyhedron the weighted mean of its vertices
     * in the overlap (dem_body_contact_point) */
    double cp[3];
    dem_pair_contact_point(&bi, &bj, n, depth, pc, cp);
    vec3 p = v3(origin[0] + cp[0] * L, origin[1] + cp[1] * L, origin[2] + cp[2] * L);
    vec3 di = v3_sub(p, v3(g->x[i], g->y[i], g->z[i])), dj = v3_sub(p, v3(g->x[j], g->y[j], g->z[j]));
    vec3 wi = v3(g->wx[i], g->wy[i], g->wz[i]), wj = v3(g->wx[j], g->wy[j], g->wz[j]);
    vec3 vrel = v3_sub(v3_add(v3(g->vx[i], g->vy[i], g->vz[i]), v3_cross(wi, di)),
                       v3_add(v3(g->vx[j], g->vy[j], g->vz[j]), v3_cross(wj, dj)));
    double mn[3] = {-n[0], -n[1], -n[2]}; /* outward normal of i at the contact; +n is j's */
    double Ri = grain_contact_radius(w, i, &bi, mn), Rj = grain_contact_radius(w, j, &bj, n);
    double R = Ri * Rj / (Ri + Rj);
    double m = 1.0 / (g->inv_m[i] + g->inv_m[j]);
    const dem_pair_coef *cf = &w->coef[g->mat[i]][g->mat[j]];
    double fn;
    vec3 F = dem_hm_force(cf, nv, delta, R, m, vrel, w->def.dt, xi, &fn);
    vec3 Ti = v3_cross(di, F), Tj = v3_cross(dj, v3_scale(F, -1.0));
    if (cf->mu_roll > 0.0) {
        vec3 tr = dem_rolling_torque(cf, R, fn, v3_sub(wi, wj), 1.0 / (g->inv_i[i] + g->inv_i[j]), w->def.dt);
        Ti = v3_add(Ti, tr);
        Tj = v3_sub(Tj, tr);
    }
    fx[i] += F.x, fy[i] += F.y, fz[i] += F.z;
    fx[j] -= F.x, fy[j] -= F.y, fz[j] -= F.z;
    tx[i] += Ti.x, ty[i] += Ti.y, tz[i] += Ti.z;
    tx[j] += Tj.x, ty[j] += Tj.y, tz[j] += Tj.z;
    return 1;
}

double dem_shaped_plane_depth(const dem_world *w, int i, const double p[3], const double n[3])
{
    const dem_grains *g = &w->g;
    dem_body b;
    double o[3] = {0, 0, 0}, d[3] = {-n[0], -n[1], -n[2]}, sp[3];
    dem_grain_body(w, i, o, 1.0, &b);
    dem_body_support(&b, d, sp);
    (void)g;
    return -((sp[0] - p[0]) * n[0] + (sp[1] - p[1]) * n[1] + (sp[2] - p[2]) * n[2]);
}

int dem_shaped_pair_touch(const dem_world *w, int i, int j)
{
    const dem_grains *g = &w->g;
    double ex = g->x[i] - g->x[j], ey = g->y[i] - g->y[j], ez = g->z[i] - g->z[j];
    double rs = g->r[i] + g->r[j];
    if (ex * ex + ey * ey + ez * ez >= rs * rs)
        return 0;
    double L = fmax(g->r[i], g->r[j]), origin[3] = {g->x[j], g->y[j], g->z[j]}, depth, n[3], pc[3];
    dem_body bi, bj;
    dem_grain_body(w, i, origin, 1.0 / L, &bi);
    dem_grain_body(w, j, origin, 1.0 / L, &bj);
    return grains_penetrate(&bj, &bi, &depth, n, pc);
}

/* Shaped grain against a plane: closed form, no libccd.
 * Ellipsoid: the support point in -n is the deepest point; one Hertz
 * contact with the local radius of curvature.
 * Polyhedron: every vertex below the plane is a Hertz contact of its own
 * (radius r_eq, dashpot with m / N for N vertices in contact, so that a face
 * landing flat rebounds with the requested e), normal forces applied at the
 * vertices: the normal force is the gradient of the summed Hertz energies
 * (energy-conserving), and a face resting flat is carried by all its corners
 * (no rocking). One tangential spring (history per grain and wall) at the
 * normal-force-weighted centre, S_t = 8 G* sum a_k (the vertices' springs in
 * parallel), capped at mu times the total normal force. */
int dem_shaped_wall(dem_world *w, int i, int k, double *xi, double out_f[3], double out_t[3])
{
    dem_grains *g = &w->g;
    const dem_wall *wl = &w->walls[k];
    const dem_shape *s = &w->shapes[g->shape[i]];
    double R[9], sc = g->sc[i];
    dem_quat_to_mat(g->q + 4 * i, R);
    vec3 c = v3(g->x[i], g->y[i], g->z[i]), nrm = v3_load(wl->n), wp = v3_load(wl->p);
    vec3 vi = v3(g->vx[i], g->vy[i], g->vz[i]), wi = v3(g->wx[i], g->wy[i], g->wz[i]);
    const dem_pair_coef *cf = &w->coef[g->mat[i]][wl->material];
    double m = 1.0 / g->inv_m[i], mn[3] = {-nrm.x, -nrm.y, -nrm.z};
    double Rc = dem_shape_contact_radius(s, sc, R, mn);
    if (s->type == DEM_SHAPE_ELLIPSOID) {
        dem_body b = {.type = DEM_BODY_ELLIPSOID, .s = s, .k = sc};
        memcpy(b.R, R, sizeof b.R);
        double sp[3];
        dem_body_support(&b, mn, sp);
        vec3 x = v3_add(c, v3_load(sp));
        double delta = -v3_dot(v3_sub(x, wp), nrm);
        if (!(delta > 0.0)) {
            xi[0] = xi[1] = xi[2] = 0.0;
            return 0;
        }
        vec3 lever = v3_sub(v3_axpy(delta, nrm, x), c);
        vec3 vrel = v3_add(vi, v3_cross(wi, lever));
        double fn;
        vec3 F = dem_hm_force(cf, nrm, delta, Rc, m, vrel, w->def.dt, xi, &fn);
        vec3 T = v3_add(v3_cross(lever, F), dem_rolling_torque(cf, Rc, fn, wi, 1.0 / g->inv_i[i], w->def.dt));
        v3_store(out_f, F);
        v3_store(out_t, T);
        return 1;
    }
    vec3 x[DEM_SHAPE_MAX_VERTS];
    double dk[DEM_SHAPE_MAX_VERTS];
    int np = 0;
    for (int t = 0; t < s->n_verts; t++) {
        double vw[3];
        mat_vec(R, s->v[t], vw);
        x[t] = v3_axpy(sc, v3_load(vw), c);
        dk[t] = -v3_dot(v3_sub(x[t], wp), nrm);
        np += dk[t] > 0.0;
    }
    if (np == 0) {
        xi[0] = xi[1] = xi[2] = 0.0;
        return 0;
    }
    double fn_tot = 0.0, a_sum = 0.0, mk = m / np;
    vec3 T = v3(0, 0, 0), pc = v3(0, 0, 0);
    for (int t = 0; t < s->n_verts; t++) {
        if (dk[t] <= 0.0)
            continue;
        vec3 lever = v3_sub(v3_axpy(dk[t], nrm, x[t]), c); /* the vertex on the plane */
        double vn = v3_dot(v3_add(vi, v3_cross(wi, lever)), nrm);
        double a = sqrt(Rc * dk[t]), sn = 2.0 * cf->E * a;
        double f = (2.0 / 3.0) * sn * dk[t] - cf->gamma_n * sqrt(sn * mk) * vn; /* eq. 22 per vertex */
        if (f < 0.0)
            f = 0.0;
        fn_tot += f;
        a_sum += a;
        T = v3_add(T, v3_cross(lever, v3_scale(nrm, f)));
        pc = v3_axpy(f, lever, pc);
    }
    vec3 lever = fn_tot > 0.0 ? v3_scale(pc, 1.0 / fn_tot) : v3_scale(nrm, -v3_dot(v3_sub(c, wp), nrm));
    vec3 vrel = v3_add(vi, v3_cross(wi, lever));
    vec3 ft = dem_mindlin_tangential(cf, nrm, vrel, 8.0 * cf->G * a_sum, m, fn_tot, w->def.dt, xi);
    vec3 F = v3_axpy(fn_tot, nrm, ft);
    T = v3_add(T, v3_cross(lever, ft));
    T = v3_add(T, dem_rolling_torque(cf, Rc, fn_tot, wi, 1.0 / g->inv_i[i], w->def.dt));
    v3_store(out_f, F);
    v3_store(out_t, T);
    return 1;
}
