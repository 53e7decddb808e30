/* Contacts of shaped grains: grain pairs by the libccd narrow phase
 * (dem_shape_ccd.c), grains against walls and planes in closed form; Hertz–
 * Mindlin forces (dem_contact.h) at the contact point (see dem_shape.h). */
#include "dem_shape.h"

#include <assert.h>
#include <math.h>
#include <string.h>

#include "dem_contact.h"
#include "dem_shape_algebra.h"
#include "dem_world.h"
#include "vec3.h"

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
