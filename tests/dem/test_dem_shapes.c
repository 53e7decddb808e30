/* Non-spherical grains: mass properties, free rigid-body rotation (eq. 8),
 * resting and sliding on planes, the libccd narrow phase against the closed
 * form of the sphere path, triangle surfaces, and the angle of repose of
 * angular grains against spheres. */
#include <hdf5.h>
#include <stdlib.h>
#include <sys/stat.h>
#include <unistd.h>

#include "dem_bed.h"
#include "dem_config.h"
#include "dem_output.h"
#include "dem_shape.h"
#include "dem_surface.h"
#include "dem_world.h"
#include "scene.h"
#include "test_dem_common.h"
#include "timer.h"

static dem_shape_def box_def(double a, double b, double c)
{
    dem_shape_def d;
    memset(&d, 0, sizeof d);
    d.type = DEM_SHAPE_POLYHEDRON;
    d.n_verts = 8;
    for (int k = 0; k < 8; k++) {
        d.verts[k][0] = (k & 1 ? 0.5 : -0.5) * a;
        d.verts[k][1] = (k & 2 ? 0.5 : -0.5) * b;
        d.verts[k][2] = (k & 4 ? 0.5 : -0.5) * c;
    }
    return d;
}

static void quat_axis_angle(const double axis[3], double ang, double q[4])
{
    double l = sqrt(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]);
    q[0] = cos(0.5 * ang);
    for (int k = 0; k < 3; k++)
        q[k + 1] = sin(0.5 * ang) * axis[k] / l;
}

static double urand(uint64_t *s)
{
    *s = *s * 6364136223846793005ULL + 1442695040888963407ULL;
    return (double)(*s >> 11) * (1.0 / 9007199254740992.0);
}

/* Box a x b x c: V = abc, I_1 = V (b² + c²)/12 ...; rotated and shifted
 * vertices give the same moments and the shift back as centre of mass;
 * ellipsoid V = 4/3 π abc, I_1 = V (b² + c²)/5; the random generator is
 * reproducible and hits the requested volume-equivalent radius. */
static int shape_mass_properties(void)
{
    cm_error err = {0};
    dem_shape_def d = box_def(3.0, 2.0, 1.0);
    double q[4], R[9], ax[3] = {0.3, -0.5, 0.8}, shift[3] = {0.7, -1.1, 2.5};
    quat_axis_angle(ax, 0.9, q);
    dem_quat_to_mat(q, R);
    for (int k = 0; k < d.n_verts; k++) {
        double v[3];
        for (int r = 0; r < 3; r++)
            v[r] = R[3 * r] * d.verts[k][0] + R[3 * r + 1] * d.verts[k][1] + R[3 * r + 2] * d.verts[k][2];
        for (int r = 0; r < 3; r++)
            d.verts[k][r] = v[r] + shift[r];
    }
    dem_shape_info in;
    ENSURE(dem_shape_compute(&d, &in, &err) == CM_OK);
    ENSURE_REL(in.volume, 6.0, 1e-12);
    ENSURE_REL(in.inertia[0], 6.0 * (4.0 + 1.0) / 12.0, 1e-10);
    ENSURE_REL(in.inertia[1], 6.0 * (9.0 + 1.0) / 12.0, 1e-10);
    ENSURE_REL(in.inertia[2], 6.0 * (9.0 + 4.0) / 12.0, 1e-10);
    for (int k = 0; k < 3; k++)
        ENSURE_NEAR(in.com[k], shift[k], 1e-12);
    ENSURE(in.n_faces == 6 && in.n_verts == 8);
    ENSURE_REL(in.r_bound, 0.5 * sqrt(14.0), 1e-12);
    /* principal axis 1 (smallest moment) is the box's long edge, rotated */
    double dot = fabs(in.axes[0] * R[0] + in.axes[3] * R[3] + in.axes[6] * R[6]);
    ENSURE_NEAR(dot, 1.0, 1e-10);

    dem_shape_def e = {.type = DEM_SHAPE_ELLIPSOID, .semi_axes = {1.0, 3.0, 2.0}};
    ENSURE(dem_shape_compute(&e, &in, &err) == CM_OK);
    double V = 4.0 / 3.0 * M_PI * 6.0;
    ENSURE_REL(in.volume, V, 1e-14);
    ENSURE_REL(in.inertia[0], V * (4.0 + 1.0) / 5.0, 1e-14); /* about the 3-axis */
    ENSURE_REL(in.inertia[2], V * (9.0 + 4.0) / 5.0, 1e-14); /* about the 1-axis */
    ENSURE_NEAR(fabs(in.axes[3 * 1 + 0]), 1.0, 0.0);         /* principal axis 1 = definition y */

    dem_shape_def p1, p2;
    ENSURE(dem_shape_random_polyhedron(42, 2e-3, 1.6, 16, &p1, &err) == CM_OK);
    ENSURE(dem_shape_random_polyhedron(42, 2e-3, 1.6, 16, &p2, &err) == CM_OK);
    ENSURE(memcmp(&p1, &p2, sizeof p1) == 0);
    ENSURE(dem_shape_compute(&p1, &in, &err) == CM_OK);
    ENSURE_REL(in.r_eq, 2e-3, 1e-12);
    ENSURE(in.n_verts >= 8 && in.r_bound > in.r_eq);
    ENSURE(dem_shape_random_polyhedron(43, 2e-3, 1.6, 16, &p2, &err) == CM_OK);
    ENSURE(memcmp(&p1, &p2, sizeof p1) != 0);
    /* coplanar points are refused with a message */
    dem_shape_def flat = box_def(1, 1, 0);
    ENSURE(dem_shape_compute(&flat, &in, &err) != CM_OK && strstr(err.msg, "coplanar"));
    return 0;
}

/* Free box spinning about its intermediate axis, slightly perturbed: the
 * tennis-racket (Dzhanibekov) flip. Checks: the body-frame omega_2 reverses
 * sign, world angular momentum is kept to round-off, kinetic energy to 1e-5
 * (dt * |omega| = 0.005), |q| = 1. */
static int tennis_racket(void)
{
    dem_material m = test_material(1e7, 0.3, 0.5, 0.5);
    dem_world *w = test_world(&m, 1, 2.5e-4, 4, NULL, 1);
    ENSURE(w);
    cm_error err = {0};
    int sh, id;
    dem_shape_def d = box_def(0.03, 0.02, 0.01);
    ENSURE(dem_shape_add(w, &d, &sh, &err) == CM_OK);
    double x[3] = {0, 0, 0}, q[4] = {1, 0, 0, 0};
    ENSURE(dem_grain_add_shape(w, x, q, sh, 1.0, 0, &id, &err) == CM_OK);
    double om[3] = {0.01, 10.0, 0.01}; /* body = world frame at start */
    dem_grain_set(w, id, NULL, NULL, om);
    dem_grain_state s0, s;
    dem_grain_get(w, id, &s0);
    double L0[3], E0 = 0.0;
    for (int k = 0; k < 3; k++) {
        L0[k] = s0.inertia[k] * om[k];
        E0 += 0.5 * s0.inertia[k] * om[k] * om[k];
    }
    double emax = 0.0, lmax = 0.0, w2min = INFINITY, qmax = 0.0;
    double t_flip = -1.0;
    for (int step = 0; step < 16000; step++) {
        ENSURE(dem_step(w, &err) == CM_OK);
        dem_grain_get(w, id, &s);
        double R[9], wb[3], E = 0.0, L[3];
        dem_quat_to_mat(s.q, R);
        for (int k = 0; k < 3; k++)
            wb[k] = R[k] * s.w[0] + R[3 + k] * s.w[1] + R[6 + k] * s.w[2];
        for (int k = 0; k < 3; k++)
            E += 0.5 * s.inertia[k] * wb[k] * wb[k];
        for (int r = 0; r < 3; r++)
            L[r] = R[3 * r] * s.inertia[0] * wb[0] + R[3 * r + 1] * s.inertia[1] * wb[1] +
                   R[3 * r + 2] * s.inertia[2] * wb[2];
        emax = fmax(emax, fabs(E - E0) / E0);
        lmax = fmax(lmax, sqrt((L[0] - L0[0]) * (L[0] - L0[0]) + (L[1] - L0[1]) * (L[1] - L0[1]) +
                               (L[2] - L0[2]) * (L[2] - L0[2])) / sqrt(L0[0] * L0[0] + L0[1] * L0[1] + L0[2] * L0[2]));
        qmax = fmax(qmax, fabs(s.q[0] * s.q[0] + s.q[1] * s.q[1] + s.q[2] * s.q[2] + s.q[3] * s.q[3] - 1.0));
        if (wb[1] < w2min)
            w2min = wb[1];
        if (t_flip < 0 && wb[1] < 0)
            t_flip = (step + 1) * 2.5e-4;
    }
    printf("tennis_racket: omega_2 from 10 to min %.4f rad/s (first flip t = %.3f s); max |dE|/E = %.2e, "
           "max |dL|/|L| = %.2e, max ||q|-1| = %.1e\n",
           w2min, t_flip, emax, lmax, qmax);
    ENSURE(w2min < -9.5); /* flipped all the way */
    ENSURE(t_flip > 0.0);
    ENSURE(emax < 1e-5);
    ENSURE(lmax < 1e-12);
    ENSURE(qmax < 1e-14);
    /* and a spin about the major axis stays there (stable) */
    double om3[3] = {0.01, 0.01, 10.0};
    dem_grain_set_orientation(w, id, q);
    dem_grain_set(w, id, NULL, NULL, om3);
    double w3min = INFINITY;
    for (int step = 0; step < 4000; step++) {
        ENSURE(dem_step(w, &err) == CM_OK);
        dem_grain_get(w, id, &s);
        double R[9];
        dem_quat_to_mat(s.q, R);
        w3min = fmin(w3min, R[2] * s.w[0] + R[5] * s.w[1] + R[8] * s.w[2]);
    }
    ENSURE(w3min > 9.9);
    dem_world_destroy(&w);
    return 0;
}

/* A triaxial ellipsoid (semi-axes 6, 4.5, 3 mm) dropped tilted onto a floor
 * settles on its longest side: shortest axis vertical, centre at c = 3 mm.
 * Rolling resistance μ_r = 0.02: without it an ellipsoid rolling about its
 * long axis without slip loses almost nothing and rocks for seconds. */
static int ellipsoid_settles_flat(void)
{
    dem_material m = test_material(1e7, 0.3, 0.3, 0.5);
    m.rolling_friction = 0.02;
    double g[3] = {0, 0, -9.81};
    dem_world *w = test_world(&m, 1, 1e-5, 4, g, 1);
    ENSURE(w);
    cm_error err = {0};
    double p0[3] = {0, 0, 0}, nz[3] = {0, 0, 1};
    ENSURE(dem_wall_add(w, p0, nz, 0, &err) == CM_OK);
    dem_shape_def d = {.type = DEM_SHAPE_ELLIPSOID, .semi_axes = {6e-3, 4.5e-3, 3e-3}};
    int sh, id;
    ENSURE(dem_shape_add(w, &d, &sh, &err) == CM_OK);
    double q[4], ax[3] = {1.0, 0.6, 0.2}, x[3] = {0, 0, 0.012};
    quat_axis_angle(ax, 1.1, q); /* long axis well off the floor */
    ENSURE(dem_grain_add_shape(w, x, q, sh, 1.0, 0, &id, &err) == CM_OK);
    dem_grain_state s;
    double ke = 0.0;
    int step;
    for (step = 0; step < 200000; step++) {
        ENSURE(dem_step(w, &err) == CM_OK);
        if (step % 1000 == 999) {
            dem_stats st;
            dem_world_stats(w, &st);
            ke = st.ke_trans + st.ke_rot;
            if (step > 20000 && ke < 1e-12)
                break;
        }
    }
    dem_grain_get(w, id, &s);
    double R[9];
    dem_quat_to_mat(s.q, R);
    /* principal axes: columns of R (1 = longest semi-axis, 3 = shortest) */
    printf("ellipsoid_settles_flat: after %.3f s KE %.2e J, z = %.4f mm (c = 3), |e3.z| = %.5f, |e1.z| = %.5f\n",
           (step + 1) * 1e-5, ke, s.x[2] * 1e3, fabs(R[8]), fabs(R[6]));
    ENSURE(ke < 1e-10);
    ENSURE(fabs(R[8]) > 0.995); /* rolling resistance may hold a tilt of up to ~3 deg */
    ENSURE_NEAR(s.x[2], 3e-3, 0.05e-3);
    dem_world_destroy(&w);
    return 0;
}

/* Cube (edge 10 mm, μ = 0.5: friction angle 26.57°) on a plane tilted by θ
 * (gravity tilted instead of the plane). θ = 20°: it sticks (creep below
 * 1 µm in 0.3 s after it has landed); θ = 32°: it slides with
 * a = g (sin θ - μ cos θ) within 3 %. */
static int cube_tilted_plane(void)
{
    const double theta_deg[2] = {20.0, 32.0};
    for (int c = 0; c < 2; c++) {
        double th = theta_deg[c] * M_PI / 180.0;
        dem_material m = test_material(1e7, 0.3, 0.3, 0.5);
        double g[3] = {9.81 * sin(th), 0, -9.81 * cos(th)};
        dem_world *w = test_world(&m, 1, 1e-5, 4, g, 1);
        ENSURE(w);
        cm_error err = {0};
        double p0[3] = {0, 0, 0}, nz[3] = {0, 0, 1};
        ENSURE(dem_wall_add(w, p0, nz, 0, &err) == CM_OK);
        dem_shape_def d = box_def(0.01, 0.01, 0.01);
        int sh, id;
        ENSURE(dem_shape_add(w, &d, &sh, &err) == CM_OK);
        double x[3] = {0, 0, 0.005}, q[4] = {1, 0, 0, 0};
        ENSURE(dem_grain_add_shape(w, x, q, sh, 1.0, 0, &id, &err) == CM_OK);
        for (int k = 0; k < 5000; k++) /* land and damp the normal oscillation */
            ENSURE(dem_step(w, &err) == CM_OK);
        dem_grain_state s0, s1;
        dem_grain_get(w, id, &s0);
        const int n = 30000;
        for (int k = 0; k < n; k++)
            ENSURE(dem_step(w, &err) == CM_OK);
        dem_grain_get(w, id, &s1);
        double T = n * 1e-5, dx = s1.x[0] - s0.x[0];
        if (c == 0) {
            printf("cube_tilted_plane: theta = %.0f deg: creep %.3g m in %.2f s (sticks), tilt |e3.z| = %.6f\n",
                   theta_deg[c], dx, T, fabs(1.0 - 2.0 * (s1.q[1] * s1.q[1] + s1.q[2] * s1.q[2])));
            ENSURE(fabs(dx) < 1e-6);
        } else {
            /* dx = v0 T + a T²/2 */
            double a = 2.0 * (dx - s0.v[0] * T) / (T * T), a_ref = 9.81 * (sin(th) - 0.5 * cos(th));
            double mu_eff = (9.81 * sin(th) - a) / (9.81 * cos(th)); /* friction / normal force */
            printf("cube_tilted_plane: theta = %.0f deg: a = %.4f m/s² vs g (sin - mu cos) = %.4f (%.2f %%), "
                   "effective mu = %.4f (0.5)\n",
                   theta_deg[c], a, a_ref, 100.0 * (a - a_ref) / a_ref, mu_eff);
            ENSURE_REL(a, a_ref, 0.05);
            ENSURE_REL(mu_eff, 0.5, 0.02);
            ENSURE(fabs(s1.w[0]) + fabs(s1.w[1]) + fabs(s1.w[2]) < 0.5); /* slides, does not tumble */
        }
        dem_world_destroy(&w);
    }
    return 0;
}

/* The closed-form sphere–triangle contact of the sphere path (Ericson's
 * closest point) against libccd on random configurations: triangle vertices
 * in a 4r cube, sphere centre at a random point of the triangle's plane
 * region plus an offset along a random direction, overlap in (0.01 r, 0.6 r).
 * Closed form: depth r - |c - cp|, normal (c - cp)/|c - cp|, point cp.
 * libccd: depth, direction (triangle -> sphere), and its point moved onto
 * the triangle, pos - (depth/2) n (libccd's point is midway between the
 * surfaces). Statistics per region (face / edge or vertex) and per method. */
static int sphere_triangle_vs_ccd(void)
{
    uint64_t rs = 12345;
    const int N = 4000;
    const double r = 1e-3;
    double worst[2][2][3] = {{{0}}}; /* [method][face?][depth, angle, point] */
    int count[2] = {0, 0}, fails = 0, bad_count[2] = {0, 0};
    for (int it = 0; it < N; it++) {
        double v[3][3], c[3];
        for (int k = 0; k < 3; k++)
            for (int j = 0; j < 3; j++)
                v[k][j] = (4.0 * urand(&rs) - 2.0) * r;
        double e1[3], e2[3], nn[3];
        for (int j = 0; j < 3; j++)
            e1[j] = v[1][j] - v[0][j], e2[j] = v[2][j] - v[0][j];
        nn[0] = e1[1] * e2[2] - e1[2] * e2[1], nn[1] = e1[2] * e2[0] - e1[0] * e2[2], nn[2] = e1[0] * e2[1] - e1[1] * e2[0];
        double area2 = sqrt(nn[0] * nn[0] + nn[1] * nn[1] + nn[2] * nn[2]);
        if (area2 < 0.5 * r * r) /* skip slivers */
            continue;
        /* a point on the triangle (or a little outside), pushed off by dist along a random direction */
        double a = 1.3 * urand(&rs) - 0.15, b = (1.3 - a) * urand(&rs) - 0.15;
        double dist = r * (0.4 + 0.59 * urand(&rs)), dir[3];
        double dl;
        do {
            for (int j = 0; j < 3; j++)
                dir[j] = 2.0 * urand(&rs) - 1.0;
            dl = sqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
        } while (dl > 1.0 || dl < 0.1);
        for (int j = 0; j < 3; j++)
            c[j] = v[0][j] + a * e1[j] + b * e2[j] + dist * dir[j] / dl;
        double bary[3], cp[3];
        int region = dem_closest_on_triangle(c, v[0], v[1], v[2], bary, cp);
        double dd[3] = {c[0] - cp[0], c[1] - cp[1], c[2] - cp[2]};
        double dn = sqrt(dd[0] * dd[0] + dd[1] * dd[1] + dd[2] * dd[2]);
        double depth = r - dn;
        if (depth < 0.01 * r || depth > 0.6 * r)
            continue;
        int face = region == 0;
        count[face]++;
        /* libccd in coordinates centred on the sphere, scaled by r */
        dem_body tri, sph = {.type = DEM_BODY_SPHERE, .k = 1.0};
        double vs[3][3], zero[3] = {0, 0, 0};
        for (int k = 0; k < 3; k++)
            for (int j = 0; j < 3; j++)
                vs[k][j] = (v[k][j] - c[j]) / r;
        dem_body_triangle(vs[0], vs[1], vs[2], zero, &tri);
        for (int m = 0; m < 2; m++) {
            double cd = 0.0, n[3], p[3];
            int in = dem_body_penetration(&tri, &sph, m, &cd, n, p);
            if (in != 1) {
                fails++;
                continue;
            }
            double ang = acos(fmin(1.0, (n[0] * dd[0] + n[1] * dd[1] + n[2] * dd[2]) / dn));
            /* the contact point as the surface code takes it: the grain's
             * deepest point along -n moved by depth onto the triangle, then
             * its closest point on the triangle (libccd's own point is an
             * average of portal support points, off by up to 0.3 r at edges) */
            double pb[3], pt[3], pe = 0.0, mn[3] = {-n[0], -n[1], -n[2]}, sp[3];
            dem_body_support(&sph, mn, sp);
            for (int j = 0; j < 3; j++)
                sp[j] += cd * n[j];
            dem_closest_on_triangle(sp, vs[0], vs[1], vs[2], pb, pt);
            for (int j = 0; j < 3; j++) {
                double pj = c[j] + r * pt[j];
                pe += (pj - cp[j]) * (pj - cp[j]);
            }
            double err3[3] = {fabs(cd * r - depth) / r, ang, sqrt(pe) / r};
            if (err3[0] > 1e-3)
                bad_count[m]++;
            for (int q = 0; q < 3; q++)
                worst[m][face][q] = fmax(worst[m][face][q], err3[q]);
        }
    }
    const char *mn[2] = {"MPR", "GJK+EPA"};
    for (int m = 0; m < 2; m++)
        for (int f = 1; f >= 0; f--)
            printf("sphere_triangle_vs_ccd: %-7s %-11s (%4d cases): max |depth err|/r = %.2e, max normal angle = "
                   "%.2e rad, max |point err|/r = %.2e\n",
                   mn[m], f ? "face" : "edge/vertex", count[f], worst[m][f][0], worst[m][f][1], worst[m][f][2]);
    printf("sphere_triangle_vs_ccd: depth off by > 1e-3 r: MPR %d, GJK+EPA %d of %d\n", bad_count[0], bad_count[1],
           count[0] + count[1]);
    ENSURE(fails == 0);
    ENSURE(count[0] > 500 && count[1] > 500);
    /* MPR started from the closest point (what the code uses): depth, normal
     * and point agree with the closed form in every region */
    for (int f = 0; f < 2; f++)
        ENSURE(worst[0][f][0] < 1e-6 && worst[0][f][1] < 1e-3 && worst[0][f][2] < 1e-3);
    /* libccd's GJK+EPA on a flat triangle is not usable (reported, not
     * asserted: depth ~0 or a reversed direction in a fraction of cases) */
    return 0;
}

/* Shaped grains on the FE interface: an ellipsoid dropped on a plane wall
 * and on the same plane as triangles (4 mm cells, grain 12 mm long, so it
 * lands across several triangles and edges) rebounds the same; a cube and an
 * ellipsoid at rest on the triangles carry their weight with the node
 * forces (barycentric, eq. 42) summing to m g and their moment about the
 * centre of mass matching the grain's. */
static int shaped_on_triangles(void)
{
    dem_material m = test_material(1e7, 0.3, 0.5, 0.5);
    double g[3] = {0, 0, -9.81};
    double rebound[2] = {0, 0};
    for (int mode = 0; mode < 2; mode++) {
        dem_world *w = test_world(&m, 1, 1e-5, 4, g, 1);
        ENSURE(w);
        cm_error err = {0};
        enum { NX = 10 };
        double xs[(NX + 1) * (NX + 1) * 3];
        int tris[2 * NX * NX * 3];
        test_plane_mesh(NX, NX, 4e-3, -0.0201, -0.0199, 0.0, xs, tris);
        if (mode == 0) {
            double p0[3] = {0, 0, 0}, nz[3] = {0, 0, 1};
            ENSURE(dem_wall_add(w, p0, nz, 0, &err) == CM_OK);
        } else {
            ENSURE(dem_surface_set(w, (NX + 1) * (NX + 1), xs, 2 * NX * NX, tris, 0, &err) == CM_OK);
        }
        dem_shape_def d = {.type = DEM_SHAPE_ELLIPSOID, .semi_axes = {6e-3, 4e-3, 3e-3}};
        int sh, id;
        ENSURE(dem_shape_add(w, &d, &sh, &err) == CM_OK);
        double x[3] = {0.0013, -0.0021, 0.0032}, q[4] = {1, 0, 0, 0}, v[3] = {0, 0, -0.5};
        ENSURE(dem_grain_add_shape(w, x, q, sh, 1.0, 0, &id, &err) == CM_OK);
        dem_grain_set(w, id, NULL, v, NULL);
        dem_grain_state st;
        for (int k = 0; k < 3000; k++) {
            ENSURE(dem_step(w, &err) == CM_OK);
            dem_grain_get(w, id, &st);
            rebound[mode] = fmax(rebound[mode], st.v[2]);
        }
        dem_world_destroy(&w);
    }
    printf("shaped_on_triangles: ellipsoid rebound at 0.5 m/s: wall %.5f m/s, triangles %.5f m/s (e = 0.5)\n",
           rebound[0], rebound[1]);
    ENSURE_REL(rebound[1], rebound[0], 0.01);
    ENSURE_NEAR(rebound[0] / 0.5, 0.5, 0.05);

    for (int kind = 0; kind < 2; kind++) {
        dem_world *w = test_world(&m, 1, 1e-5, 4, g, 1);
        ENSURE(w);
        cm_error err = {0};
        enum { NX = 10 };
        double xs[(NX + 1) * (NX + 1) * 3];
        int tris[2 * NX * NX * 3];
        test_plane_mesh(NX, NX, 4e-3, -0.0201, -0.0199, 0.0, xs, tris);
        ENSURE(dem_surface_set(w, (NX + 1) * (NX + 1), xs, 2 * NX * NX, tris, 0, &err) == CM_OK);
        dem_shape_def d = kind ? box_def(0.01, 0.01, 0.01)
                               : (dem_shape_def){.type = DEM_SHAPE_ELLIPSOID, .semi_axes = {6e-3, 4e-3, 3e-3}};
        int sh, id;
        ENSURE(dem_shape_add(w, &d, &sh, &err) == CM_OK);
        double x[3] = {0.0013, -0.0021, kind ? 0.0050 : 0.0030}, q[4] = {1, 0, 0, 0};
        ENSURE(dem_grain_add_shape(w, x, q, sh, 1.0, 0, &id, &err) == CM_OK);
        for (int k = 0; k < 20000; k++)
            ENSURE(dem_step(w, &err) == CM_OK);
        dem_grain_state st;
        dem_grain_get(w, id, &st);
        dem_surface_total tot;
        dem_surface_totals(w, &tot);
        const double *nf = dem_surface_node_forces(w);
        double fz = 0.0, mx = 0.0, my = 0.0;
        for (int k = 0; k < (NX + 1) * (NX + 1); k++) {
            fz += nf[3 * k + 2];
            /* moment of the node forces about the grain's centre */
            mx += (xs[3 * k + 1] - st.x[1]) * nf[3 * k + 2] - (xs[3 * k + 2] - st.x[2]) * nf[3 * k + 1];
            my += (xs[3 * k + 2] - st.x[2]) * nf[3 * k + 0] - (xs[3 * k + 0] - st.x[0]) * nf[3 * k + 2];
        }
        double wgt = st.mass * 9.81;
        printf("shaped_on_triangles: %s at rest: %d contact(s), node forces sum %.6f N vs weight %.6f N, "
               "moment about the centre %.2e N m, height %.4f mm\n",
               kind ? "cube" : "ellipsoid", tot.contacts, -fz, wgt, hypot(mx, my), st.x[2] * 1e3);
        ENSURE_REL(-fz, wgt, 1e-3);
        ENSURE(hypot(mx, my) < 1e-3 * wgt * 0.005); /* the grain's torque balance: lever error < 5 µm */
        ENSURE(tot.contacts >= 1 && tot.contacts <= (kind ? 1 : 1));
        dem_world_destroy(&w);
    }
    return 0;
}

/* A poured heap on a rough round platform (radius 25 mm, triangles over a
 * 5 mm grid with random node heights: a base of glued grains) from 160
 * grains dropped in batches of 4 onto the top; grains that roll off fall to
 * a floor below. Angle: least-squares slope of the heap's top surface
 * (highest grain top per 5 mm ring) between 20 % and 85 % of the platform
 * radius. Same material (E = 1 MPa, e = 0.2, μ = 0.5, no rolling
 * resistance), same volume-equivalent radius (2 mm), same pouring; one run
 * with spheres, one with random angular polyhedra (10 vertices, elongation
 * 1.4, 8 variants). */
static double heap_angle(int angular, double *t_wall, int *on_plate)
{
    dem_material m = test_material(1e6, 0.3, 0.2, 0.5);
    double g[3] = {0, 0, -9.81};
    const double req = 2e-3, A = 0.025;
    const int N = 160;
    dem_world_def d = dem_world_def_default();
    d.dt = 7e-5;
    d.max_grains = N;
    memcpy(d.gravity, g, sizeof g);
    d.impact_velocity = 2.0;
    dem_world *w = NULL;
    cm_error err = {0};
    if (dem_world_create(&d, 1, &m, &w, &err))
        return NAN;
    /* platform: a rough disc (a rigid base of glued grains, as repose
     * tests use): triangles over a 2.5 mm grid with node heights random in
     * [0, 1.5] mm, those with all nodes within radius A; floor 3 cm below */
    enum { NG = 11 };
    const double hg = 2.0 * A / (NG - 1);
    double xs[NG * NG * 3];
    int tris[2 * (NG - 1) * (NG - 1) * 3], nt = 0;
    uint64_t rb_seed = 99;
    for (int j = 0; j < NG; j++)
        for (int i = 0; i < NG; i++) {
            double *p = xs + 3 * (j * NG + i);
            p[0] = -A + i * hg, p[1] = -A + j * hg, p[2] = 1.5e-3 * urand(&rb_seed);
        }
    for (int j = 0; j + 1 < NG; j++)
        for (int i = 0; i + 1 < NG; i++) {
            int a = j * NG + i, b = a + 1, c = a + NG, dd = c + 1;
            int q4[4] = {a, b, c, dd}, in = 1;
            for (int k = 0; k < 4; k++)
                in &= hypot(xs[3 * q4[k]], xs[3 * q4[k] + 1]) <= A;
            if (!in)
                continue;
            int tt[6] = {a, b, dd, a, dd, c};
            memcpy(tris + 3 * nt, tt, sizeof tt);
            nt += 2;
        }
    double fp[3] = {0, 0, -0.03}, nz[3] = {0, 0, 1};
    if (dem_surface_set(w, NG * NG, xs, nt, tris, 0, &err))
        return NAN;
    if (dem_wall_add(w, fp, nz, 0, &err))
        return NAN;
    int shapes[8];
    double rb = req;
    const int NV = 10;
    if (angular)
        for (int k = 0; k < 8; k++) {
            dem_shape_def sd;
            dem_shape_info in;
            if (dem_shape_random_polyhedron(100 + k, req, 1.4, NV, &sd, &err) || dem_shape_add(w, &sd, &shapes[k], &err))
                return NAN;
            dem_shape_get_info(w, shapes[k], &in);
            rb = fmax(rb, in.r_bound);
        }
    /* poured heap: batches of 4 grains (a 2 x 2 square, spacing 2.1 rb)
     * released just above the highest grain near the axis, one batch every
     * 300 steps, then 0.4 s to settle */
    uint64_t rs = 7;
    const int every = 200;
    double t0 = cm_now();
    int placed = 0;
    long k = 0;
    const long settle = (long)(0.4 / d.dt);
    long end = -1;
    for (;; k++) {
        if (placed < N && k % every == 0) {
            double ztop = 0.0; /* highest slow grain near the axis (falling ones do not count) */
            for (int id = 0; id < placed; id++) {
                dem_grain_state gs;
                dem_grain_get(w, id, &gs);
                if (hypot(gs.x[0], gs.x[1]) < 4 * rb && hypot(gs.v[2], hypot(gs.v[0], gs.v[1])) < 0.1)
                    ztop = fmax(ztop, gs.x[2]);
            }
            double ox = 0.5 * rb * (urand(&rs) - 0.5), oy = 0.5 * rb * (urand(&rs) - 0.5);
            int clear = 1; /* wait while the previous batch is still where this one goes */
            for (int id = 0; id < placed && clear; id++) {
                dem_grain_state gs;
                dem_grain_get(w, id, &gs);
                for (int b = 0; b < 4; b++) {
                    double dx = gs.x[0] - (ox + (b % 2 - 0.5) * 2.1 * rb), dy = gs.x[1] - (oy + (b / 2 - 0.5) * 2.1 * rb);
                    double dz = gs.x[2] - (ztop + 2.2 * rb);
                    clear &= dx * dx + dy * dy + dz * dz > 4.2 * rb * rb;
                }
            }
            for (int b = 0; b < 4 && placed < N && clear; b++) {
                double x[3] = {ox + (b % 2 - 0.5) * 2.1 * rb, oy + (b / 2 - 0.5) * 2.1 * rb, ztop + 2.2 * rb};
                double q[4] = {urand(&rs) - 0.5, urand(&rs) - 0.5, urand(&rs) - 0.5, urand(&rs) - 0.5};
                int rc = angular ? dem_grain_add_shape(w, x, q, shapes[placed % 8], 1.0, 0, NULL, &err)
                                 : dem_grain_add(w, x, req, 0, NULL, &err);
                if (rc) {
                    fprintf(stderr, "heap: %s\n", err.msg);
                    return NAN;
                }
                placed++;
            }
            if (placed == N)
                end = k + settle;
        }
        if (k == end)
            break;
        if (dem_step(w, &err)) {
            fprintf(stderr, "heap: %s\n", err.msg);
            return NAN;
        }
    }
    *t_wall = cm_now() - t0;
    /* top surface: highest grain top per ring */
    enum { NB = 5 };
    double top[NB];
    for (int b = 0; b < NB; b++)
        top[b] = -INFINITY;
    *on_plate = 0;
    dem_stats st;
    dem_world_stats(w, &st);
    for (int id = 0; id < N; id++) {
        dem_grain_state gs;
        dem_grain_get(w, id, &gs);
        double rho = hypot(gs.x[0], gs.x[1]);
        if (gs.x[2] < 0.0 || rho > A)
            continue;
        (*on_plate)++;
        int b = (int)(rho / (A / NB));
        double tz = gs.x[2] + (angular ? 0.5 * (gs.radius + req) : req);
        if (b < NB && tz > top[b])
            top[b] = tz;
    }
    /* fit z = z0 - s rho over all five ring centres: with 160 grains the
     * middle rings' highest grains swing with single grains (two angular
     * heaps differing only by round-off in the contact gave 17.8 and 38.8
     * deg over the three middle rings, 25.1 and 28.5 deg over all five) */
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    int nfit = 0;
    for (int b = 0; b < NB; b++) {
        double rc = (b + 0.5) * A / NB;
        if (!isfinite(top[b]))
            continue;
        sx += rc, sy += top[b], sxx += rc * rc, sxy += rc * top[b], nfit++;
    }
    double slope = (nfit * sxy - sx * sy) / (nfit * sxx - sx * sx);
    printf("heap (%s): KE at the end %.2e J, rings:", angular ? "angular" : "spheres", st.ke_trans + st.ke_rot);
    for (int b = 0; b < NB; b++)
        printf(" %.1f", top[b] * 1e3);
    printf(" mm\n");
    dem_world_destroy(&w);
    return atan(-slope) * 180.0 / M_PI;
}

static int angle_of_repose(void)
{
    double tw[2];
    int on[2];
    double a_sph = heap_angle(0, &tw[0], &on[0]);
    double a_ang = heap_angle(1, &tw[1], &on[1]);
    printf("angle_of_repose: spheres %.1f deg (%d grains on the platform, %.1f s), angular grains %.1f deg (%d, "
           "%.1f s); same mu = 0.5, no rolling resistance\n",
           a_sph, on[0], tw[0], a_ang, on[1], tw[1]);
    ENSURE(isfinite(a_sph) && isfinite(a_ang));
    ENSURE(a_ang > 20.0 && a_ang > a_sph + 8.0);
    ENSURE(on[1] > on[0]); /* and more of the angular grains stay on the platform */
    return 0;
}

/* Elastic (e = 1, μ = 0) collisions of two free grains at 1 m/s relative
 * speed, 40 off-centre configurations, no gravity: kinetic energy after /
 * before. Ellipsoids (smooth: MPR then Newton on the normal, the minimum
 * translation): within a few per cent (the Hertz stiffness follows the local
 * curvature, which changes during the contact, so exact conservation is not
 * expected). Polyhedra (16 vertices, overlap-volume contact, the exact
 * gradient of an energy: dem_poly_contact.c): mean >= 0.99 and every
 * collision within 2 %. Momentum is exact in both; every run really
 * collides (grain 0 leaves with a velocity changed by > 10 %). */
static double collide_pair(int poly, int run, double *dp, double *dv)
{
    dem_material m = test_material(2e6, 0.3, 1.0, 0.0);
    dem_world *w = test_world(&m, 1, 2e-5, 2, NULL, 1);
    cm_error err = {0};
    dem_shape_def sd = {.type = DEM_SHAPE_ELLIPSOID, .semi_axes = {2.8e-3, 2e-3, 1.5e-3}};
    if (poly)
        dem_shape_random_polyhedron(100 + run, 2e-3, 1.4, 16, &sd, &err);
    int sh;
    if (!w || dem_shape_add(w, &sd, &sh, &err))
        return NAN;
    double x1[3] = {0, 0, 0}, x2[3] = {0.008, 0.0005 * (run % 5 - 2), 0.0007 * (run % 3 - 1)};
    double q1[4] = {1, 0.1 * run, 0.3, -0.2}, q2[4] = {0.5, -0.3, 0.2 * run, 0.7};
    dem_grain_add_shape(w, x1, q1, sh, 1.0, 0, NULL, &err);
    dem_grain_add_shape(w, x2, q2, sh, 1.0, 0, NULL, &err);
    double v1[3] = {0.5, 0, 0}, v2[3] = {-0.5, 0, 0};
    dem_grain_set(w, 0, NULL, v1, NULL);
    dem_grain_set(w, 1, NULL, v2, NULL);
    dem_stats st;
    dem_world_stats(w, &st);
    double e0 = st.ke_trans + st.ke_rot;
    for (int k = 0; k < 2000; k++)
        if (dem_step(w, &err))
            return NAN;
    dem_world_stats(w, &st);
    dem_grain_state a, b;
    dem_grain_get(w, 0, &a);
    dem_grain_get(w, 1, &b);
    *dp = fabs(a.mass * a.v[0] + b.mass * b.v[0]) + fabs(a.mass * a.v[1] + b.mass * b.v[1]);
    *dv = hypot(a.v[0] - v1[0], hypot(a.v[1], a.v[2])) / v1[0];
    dem_world_destroy(&w);
    return (st.ke_trans + st.ke_rot) / e0;
}

static int elastic_collisions(void)
{
    for (int poly = 0; poly < 2; poly++) {
        double mean = 0.0, worst = 0.0, dpmax = 0.0;
        const int n = 40;
        for (int run = 0; run < n; run++) {
            double dp, dv, r = collide_pair(poly, run, &dp, &dv);
            ENSURE(isfinite(r));
            ENSURE(dv > 0.1);
            mean += r / n;
            worst = fmax(worst, fabs(r - 1.0));
            dpmax = fmax(dpmax, dp);
        }
        printf("elastic_collisions: %s: mean KE after/before %.4f, worst |ratio - 1| %.4f, max |momentum| %.1e kg m/s\n",
               poly ? "polyhedra (16 vertices)" : "ellipsoids", mean, worst, dpmax);
        ENSURE(dpmax < 1e-15);
        if (poly)
            ENSURE(mean >= 0.99 && mean <= 1.01 && worst < 0.02);
        else
            ENSURE(fabs(mean - 1.0) < 0.03 && worst < 0.05);
    }
    return 0;
}

/* Overlap volume of two polyhedra against closed forms: unit-free cubes of
 * side s, axis-aligned, face into face by d and shifted sideways by h,
 * V = d (s - h) s; turned 45° about z, an edge pressed d into a face,
 * V = d² s (a prism of cross-section d²); a corner along the diagonal,
 * pressed d into a face, V = (√3 d)³ / 6 (the corner tetrahedron). */
static double two_hulls_volume(const dem_shape_def *da, const dem_shape_def *db, const double xb[3], const double qb[4])
{
    dem_material m = test_material(1e7, 0.3, 1.0, 0.0);
    dem_world *w = test_world(&m, 1, 1e-6, 2, NULL, 1);
    cm_error err = {0};
    int sa, sb;
    double x0[3] = {0, 0, 0}, q0[4] = {1, 0, 0, 0};
    if (!w || dem_shape_add(w, da, &sa, &err) || dem_shape_add(w, db, &sb, &err) ||
        dem_grain_add_shape(w, x0, q0, sa, 1.0, 0, NULL, &err) || dem_grain_add_shape(w, xb, qb, sb, 1.0, 0, NULL, &err) ||
        dem_world_prepare(w, &err))
        return NAN;
    dem_shaped_pose_update(w);
    double v = dem_poly_overlap_volume(w, w->g.slot_of[1], w->g.slot_of[0]);
    double v2 = dem_poly_overlap_volume(w, w->g.slot_of[0], w->g.slot_of[1]);
    dem_world_destroy(&w);
    return fabs(v - v2) <= 1e-12 * fabs(v) ? v : NAN; /* the same with i and j swapped */
}

static int poly_overlap_volume(void)
{
    const double s = 4e-3;
    dem_shape_def cube = box_def(s, s, s);
    double worst = 0.0;
    for (int k = 0; k < 4; k++) {
        double d = 1e-5 * (1 + 7 * k), h = 0.3e-3 * k;
        double xb[3] = {s - d, h, 0}, q[4] = {1, 0, 0, 0};
        double v = two_hulls_volume(&cube, &cube, xb, q), ve = d * (s - h) * s;
        ENSURE(isfinite(v));
        worst = fmax(worst, fabs(v / ve - 1.0));
        /* edge: the cube turned 45° about z, its edge at x = s/2 + s/√2 - d */
        double qz[4], az[3] = {0, 0, 1};
        quat_axis_angle(az, M_PI / 4, qz);
        double xe[3] = {0.5 * s + s / sqrt(2.0) - d, 0.1 * h, 0};
        v = two_hulls_volume(&cube, &cube, xe, qz), ve = d * d * s;
        ENSURE(isfinite(v));
        worst = fmax(worst, fabs(v / ve - 1.0));
        /* corner: the cube's diagonal (1,1,1) turned onto -x, the corner at x = s/2 - d */
        double a1[3] = {0, -1, 1}, qc[4], ang = acos(-1.0 / sqrt(3.0));
        quat_axis_angle(a1, ang, qc);
        double xc[3] = {0.5 * s + 0.5 * sqrt(3.0) * s - d, 0.2 * h, -0.1 * h};
        v = two_hulls_volume(&cube, &cube, xc, qc), ve = pow(sqrt(3.0) * d, 3) / 6.0;
        ENSURE(isfinite(v));
        worst = fmax(worst, fabs(v / ve - 1.0));
    }
    printf("poly_overlap_volume: face, edge and corner contacts of cubes: worst |V / V_exact - 1| = %.2e\n", worst);
    ENSURE(worst < 1e-9);
    return 0;
}

/* The polyhedron contact force and torque are the gradient of
 * W = k V² / 2, k = 16 E* / (π² R*³) (dem_poly_contact.c): central
 * differences of W, from the overlap volume alone, under small translations
 * and rotations of one grain match F . e and T . e (no dashpot: e = 1; no
 * friction: μ = 0; at rest), over random overlapping pairs. */
static int poly_force_gradient(void)
{
    const double E = 1e7, nu = 0.3;
    dem_material m = test_material(E, nu, 1.0, 0.0);
    cm_error err = {0};
    dem_shape_def sd[2];
    ENSURE(dem_shape_random_polyhedron(11, 2e-3, 1.4, 12, &sd[0], &err) == 0);
    ENSURE(dem_shape_random_polyhedron(12, 1.6e-3, 1.2, 14, &sd[1], &err) == 0);
    uint64_t rs = 5;
    double worst_f = 0.0, worst_t = 0.0;
    int n_ok = 0;
    for (int run = 0; run < 12; run++) {
        dem_world *w = test_world(&m, 1, 1e-6, 2, NULL, 1);
        ENSURE(w);
        int sh[2];
        ENSURE(dem_shape_add(w, &sd[0], &sh[0], &err) == 0 && dem_shape_add(w, &sd[1], &sh[1], &err) == 0);
        double q[2][4], x[2][3] = {{0, 0, 0}, {0, 0, 0}};
        for (int b = 0; b < 2; b++)
            for (int k = 0; k < 4; k++)
                q[b][k] = urand(&rs) - 0.5;
        double dir[3] = {urand(&rs) - 0.5, urand(&rs) - 0.5, urand(&rs) - 0.5};
        double dl = sqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
        ENSURE(dem_grain_add_shape(w, x[0], q[0], sh[0], 1.0, 0, NULL, &err) == 0);
        ENSURE(dem_grain_add_shape(w, x[1], q[1], sh[1], 1.0, 0, NULL, &err) == 0);
        ENSURE(dem_world_prepare(w, &err) == 0);
        /* move grain 1 out along dir until the overlap is small */
        double dist = 0.0, V = 0.0;
        for (int it = 0; it < 200; it++) {
            dist += 5e-5;
            for (int k = 0; k < 3; k++)
                x[1][k] = dist * dir[k] / dl;
            dem_grain_set(w, 1, x[1], NULL, NULL);
            dem_shaped_pose_update(w);
            V = dem_poly_overlap_volume(w, w->g.slot_of[1], w->g.slot_of[0]);
            if (V < 2e-10)
                break;
        }
        if (!(V > 0.0)) {
            dem_world_destroy(&w);
            continue;
        }
        dem_shape_info in0, in1;
        dem_shape_get_info(w, sh[0], &in0);
        dem_shape_get_info(w, sh[1], &in1);
        double Es = E / (2.0 * (1.0 - nu * nu)), Rs = in0.r_eq * in1.r_eq / (in0.r_eq + in1.r_eq);
        double kk = 16.0 * Es / (M_PI * M_PI * Rs * Rs * Rs);
        int i1 = w->g.slot_of[1], i0 = w->g.slot_of[0];
        double f[6][2] = {{0}}, xi[3] = {0, 0, 0};
        double fx[2] = {0}, fy[2] = {0}, fz[2] = {0}, tx[2] = {0}, ty[2] = {0}, tz[2] = {0};
        int a = i1 > i0 ? i0 : i1, b = i1 > i0 ? i1 : i0; /* the world's pair order */
        ENSURE(dem_poly_pair(w, a, b, xi, fx, fy, fz, tx, ty, tz) == 1);
        double F[3] = {fx[i1], fy[i1], fz[i1]}, T[3] = {tx[i1], ty[i1], tz[i1]};
        (void)f;
        double fscale = 0.0, tscale = 0.0;
        for (int k = 0; k < 3; k++)
            fscale = fmax(fscale, fabs(F[k])), tscale = fmax(tscale, fabs(T[k]));
        const double h = 1e-8, ha = 1e-6;
        for (int k = 0; k < 3; k++) {
            double Wd[2];
            for (int sgn = 0; sgn < 2; sgn++) { /* translation of grain 1 along axis k */
                double xp[3] = {x[1][0], x[1][1], x[1][2]};
                xp[k] += sgn ? h : -h;
                dem_grain_set(w, 1, xp, NULL, NULL);
                dem_shaped_pose_update(w);
                double v = dem_poly_overlap_volume(w, i1, i0);
                Wd[sgn] = 0.5 * kk * v * v;
            }
            dem_grain_set(w, 1, x[1], NULL, NULL);
            double fd = -(Wd[1] - Wd[0]) / (2 * h);
            worst_f = fmax(worst_f, fabs(fd - F[k]) / fscale);
            for (int sgn = 0; sgn < 2; sgn++) { /* rotation of grain 1 about world axis k */
                double ax[3] = {0, 0, 0}, dq[4], qn[4];
                ax[k] = 1.0;
                quat_axis_angle(ax, sgn ? ha : -ha, dq);
                const double *q1 = w->g.q + 4 * i1;
                double q1c[4] = {q1[0], q1[1], q1[2], q1[3]};
                qn[0] = dq[0] * q1c[0] - dq[1] * q1c[1] - dq[2] * q1c[2] - dq[3] * q1c[3];
                qn[1] = dq[0] * q1c[1] + dq[1] * q1c[0] + dq[2] * q1c[3] - dq[3] * q1c[2];
                qn[2] = dq[0] * q1c[2] - dq[1] * q1c[3] + dq[2] * q1c[0] + dq[3] * q1c[1];
                qn[3] = dq[0] * q1c[3] + dq[1] * q1c[2] - dq[2] * q1c[1] + dq[3] * q1c[0];
                memcpy(w->g.q + 4 * i1, qn, sizeof qn);
                dem_shaped_pose_update(w);
                double v = dem_poly_overlap_volume(w, i1, i0);
                Wd[sgn] = 0.5 * kk * v * v;
                memcpy(w->g.q + 4 * i1, q1c, sizeof q1c);
            }
            double td = -(Wd[1] - Wd[0]) / (2 * ha);
            worst_t = fmax(worst_t, fabs(td - T[k]) / tscale);
        }
        n_ok++;
        dem_world_destroy(&w);
    }
    printf("poly_force_gradient: %d random pairs: worst |F - (-dW/dx)| / |F| = %.2e, worst |T - (-dW/dθ)| / |T| = "
           "%.2e\n",
           n_ok, worst_f, worst_t);
    ENSURE(n_ok >= 10);
    ENSURE(worst_f < 1e-4 && worst_t < 1e-4);
    return 0;
}

static int read_ds(hid_t f, const char *name, hid_t type, void *buf)
{
    hid_t d = H5Dopen2(f, name, H5P_DEFAULT);
    if (d < 0)
        return -1;
    herr_t st = H5Dread(d, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, buf);
    H5Dclose(d);
    return st < 0 ? -1 : 0;
}

/* Grain output with shaped grains: each frame carries the orientation
 * quaternion, shape id, scale and the long axis (rotated here with q v q*,
 * independently of the library's matrix), /shapes the hull vertices once;
 * the XDMF file names the new attributes. A box 6 x 2 x 1 mm: long axis
 * half-length 3 mm along the rotated x. A sphere-only world writes none of
 * them (its output is unchanged). */
static int shaped_output(void)
{
    dem_material m = test_material(1e7, 0.3, 0.5, 0.5);
    cm_error err = {0};
    for (int shaped = 0; shaped < 2; shaped++) {
        char dir[] = "/tmp/dem_shape_out_XXXXXX";
        ENSURE(mkdtemp(dir));
        dem_world *w = test_world(&m, 1, 1e-5, 3, NULL, 1);
        ENSURE(w);
        dem_shape_def box = box_def(6e-3, 2e-3, 1e-3);
        int sh;
        ENSURE(dem_shape_add(w, &box, &sh, &err) == 0);
        double x0[3] = {0, 0, 0}, x1[3] = {0.02, 0, 0}, x2[3] = {0, 0.02, 0}, q[4], ax[3] = {0.2, -0.7, 0.4};
        quat_axis_angle(ax, 1.1, q);
        ENSURE(dem_grain_add(w, x0, 1e-3, 0, NULL, &err) == 0);
        if (shaped) {
            ENSURE(dem_grain_add_shape(w, x1, q, sh, 1.0, 0, NULL, &err) == 0);
            ENSURE(dem_grain_add_shape(w, x2, q, sh, 0.5, 0, NULL, &err) == 0);
        }
        dem_output *o = NULL;
        ENSURE_MSG(dem_output_open(dir, &o, &err) == 0, "%s", err.msg);
        ENSURE(dem_output_frame(o, w, &err) == 0 && dem_output_frame(o, w, &err) == 0);
        dem_output_close(&o);
        char path[256];
        snprintf(path, sizeof path, "%s/dem_grains.h5", dir);
        hid_t f = H5Fopen(path, H5F_ACC_RDONLY, H5P_DEFAULT);
        ENSURE(f >= 0);
        H5Eset_auto2(H5E_DEFAULT, NULL, NULL);
        double qq[3][4], la[3][3], scale[3], hv[8][3];
        int sid[3];
        int has = read_ds(f, "/frame_000001/orientation", H5T_NATIVE_DOUBLE, qq) == 0;
        ENSURE(has == shaped);
        if (shaped) {
            ENSURE(read_ds(f, "/frame_000001/long_axis", H5T_NATIVE_DOUBLE, la) == 0);
            ENSURE(read_ds(f, "/frame_000001/scale", H5T_NATIVE_DOUBLE, scale) == 0);
            ENSURE(read_ds(f, "/frame_000001/shape", H5T_NATIVE_INT, sid) == 0);
            ENSURE(read_ds(f, "/shapes/shape_000", H5T_NATIVE_DOUBLE, hv) == 0);
            ENSURE(sid[0] == -1 && sid[1] == sh && sid[2] == sh);
            ENSURE(scale[0] == 1e-3 && scale[1] == 1.0 && scale[2] == 0.5);
            ENSURE(la[0][0] == 0.0 && la[0][1] == 0.0 && la[0][2] == 0.0);
            for (int k = 0; k < 4; k++)
                ENSURE_NEAR(qq[1][k] - q[k], 0.0, 1e-15);
            /* q (1,0,0) q*: the rotated x axis, times the half-length */
            double w0 = q[0], v[3] = {q[1], q[2], q[3]};
            double ex[3] = {1 - 2 * (v[1] * v[1] + v[2] * v[2]), 2 * (v[0] * v[1] + w0 * v[2]), 2 * (v[0] * v[2] - w0 * v[1])};
            for (int k = 0; k < 3; k++) {
                ENSURE_NEAR(fabs(la[1][k]) - fabs(3e-3 * ex[k]), 0.0, 1e-15);
                ENSURE_NEAR(fabs(la[2][k]) - fabs(1.5e-3 * ex[k]), 0.0, 1e-15);
            }
            for (int t = 0; t < 8; t++) /* the box's corners about its centre */
                ENSURE_NEAR(fabs(hv[t][0]) + fabs(hv[t][1]) + fabs(hv[t][2]) - 4.5e-3, 0.0, 1e-15);
        }
        H5Fclose(f);
        unlink(path);
        snprintf(path, sizeof path, "%s/dem_grains.xmf", dir);
        FILE *x = fopen(path, "r");
        ENSURE(x);
        char text[16384];
        size_t nr = fread(text, 1, sizeof text - 1, x);
        text[nr] = '\0';
        fclose(x);
        ENSURE((strstr(text, "long_axis") != NULL) == shaped && (strstr(text, "orientation") != NULL) == shaped);
        unlink(path);
        snprintf(path, sizeof path, "%s/dem_series.csv", dir);
        unlink(path);
        rmdir(dir);
        dem_world_destroy(&w);
    }
    printf("shaped_output: orientation, long_axis, shape, scale and /shapes written for shaped grains only\n");
    return 0;
}

/* A scene mixing spheres (bottom layer) and random angular grains (top
 * layer), read from scene text: keys checked (an unknown key is caught), the
 * bed placed, settled, cached and reloaded bit for bit (orientations and
 * shapes included); the settled angular layer stands higher for the same
 * grain volume. And a bed of ellipsoids from an explicit shape key. */
static const char shaped_scene[] =
    "dem = {\n"
    "  dt = 5e-5; impact_velocity = 1.0;\n"
    "  materials = ( { name = \"sand\"; density = 2600.0; young = 1e6; poisson = 0.3; restitution = 0.3; "
    "friction = 0.5; } );\n"
    "  bed = { box_min = [0.0, 0.0, 0.0]; box_max = [0.03, 0.03, 0.2]; material = \"sand\"; seed = 3;\n"
    "    settle_ke = 1e-8; settle_min_time = 0.1; settle_max_time = 2.0; file = \"%s\";\n"
    "    layers = ( { count = 60; radius = [0.0019, 0.0021]; },\n"
    "               { count = 60; radius = [0.0019, 0.0021];\n"
    "                 shape = { type = \"polyhedron\"; elongation = 1.5; random_vertices = 10; variants = 4; }; } );\n"
    "  };\n"
    "};\n";

static int shaped_bed_config(void)
{
    char path[256], text[4096];
    snprintf(path, sizeof path, "/tmp/test_dem_shapes_bed_%ld.h5", (long)getpid());
    snprintf(text, sizeof text, shaped_scene, path);
    unlink(path);
    cm_scene *s = NULL;
    cm_error err = {0};
    ENSURE(cm_scene_open_string(text, "shapes.cfg", &s, &err) == 0);
    dem_config c;
    ENSURE_MSG(dem_config_read(s, &c, &err) == 0, "%s", err.msg);
    static const char *const sections[] = {"dem", NULL};
    ENSURE_MSG(cm_scene_check_unknown(s, sections, &err) == 0, "%s", err.msg);
    cm_scene_close(&s);
    ENSURE(c.bed.layers[0].shape.type == DEM_SHAPE_SPHERE && c.bed.layers[1].shape.type == DEM_SHAPE_POLYHEDRON);
    ENSURE(c.bed.layers[1].shape.variants == 4 && c.bed.layers[1].shape.random_verts == 10);
    uint64_t h[2];
    double top[2][2], q100[4] = {0};
    for (int pass = 0; pass < 2; pass++) {
        dem_world *w = NULL;
        ENSURE(dem_world_from_config(&c, &w, &err) == 0);
        bool loaded = false;
        ENSURE_MSG(dem_bed_build(w, &c.bed, NULL, NULL, &loaded, &err) == 0, "%s", err.msg);
        ENSURE(loaded == (pass == 1));
        ENSURE(dem_grain_count(w) == 120 && w->n_shaped == 60);
        h[pass] = dem_world_hash(w);
        /* mean top of each layer's grains: the angular layer is on top */
        top[pass][0] = top[pass][1] = 0.0;
        for (int id = 0; id < 120; id++) {
            dem_grain_state gs;
            dem_grain_get(w, id, &gs);
            top[pass][gs.shape >= 0] += gs.x[2] / 60.0;
            if (id == 100 && pass == 0)
                memcpy(q100, gs.q, sizeof q100);
            if (id == 100 && pass == 1)
                ENSURE(gs.shape >= 0 && gs.scale > 0.0019 && gs.scale < 0.0021 && memcmp(q100, gs.q, sizeof q100) == 0);
        }
        for (int k = 0; k < 200; k++) /* and it steps */
            ENSURE_MSG(dem_step(w, &err) == 0, "%s", err.msg);
        dem_world_destroy(&w);
    }
    printf("shaped_bed_config: mean height: spheres %.2f mm, angular grains %.2f mm; reload identical: %s\n",
           top[0][0] * 1e3, top[0][1] * 1e3, h[0] == h[1] ? "yes" : "no");
    ENSURE(h[0] == h[1]);
    ENSURE(top[0][1] > top[0][0]);
    unlink(path);

    /* ellipsoid layer and a bad shape key */
    char t2[4096];
    snprintf(t2, sizeof t2, "%s", text);
    char *k = strstr(t2, "type = \"polyhedron\"; elongation = 1.5; random_vertices = 10; variants = 4;");
    ENSURE(k);
    const char *ell = "type = \"ellipsoid\"; semi_axes = [1.5, 1.0, 0.7];";
    memset(k, ' ', strlen("type = \"polyhedron\"; elongation = 1.5; random_vertices = 10; variants = 4;"));
    memcpy(k, ell, strlen(ell));
    ENSURE(cm_scene_open_string(t2, "ell.cfg", &s, &err) == 0);
    ENSURE_MSG(dem_config_read(s, &c, &err) == 0, "%s", err.msg);
    cm_scene_close(&s);
    ENSURE(c.bed.layers[1].shape.type == DEM_SHAPE_ELLIPSOID && c.bed.layers[1].shape.semi_axes[2] == 0.7);
    c.bed.file[0] = '\0';
    dem_world *w = NULL;
    ENSURE(dem_world_from_config(&c, &w, &err) == 0);
    ENSURE_MSG(dem_bed_place(w, &c.bed, &err) == 0, "%s", err.msg);
    ENSURE(w->n_shaped == 60 && w->n_shapes == 1);
    dem_world_destroy(&w);
    k = strstr(t2, "ellipsoid");
    memcpy(k, "ellipsoiD", 9);
    ENSURE(cm_scene_open_string(t2, "bad.cfg", &s, &err) == 0);
    ENSURE(dem_config_read(s, &c, &err) != 0 && strstr(err.msg, "shape.type"));
    cm_scene_close(&s);
    return 0;
}

static const test_case tests[] = {
    {"shaped_bed_config", shaped_bed_config},
    {"elastic_collisions", elastic_collisions},
    {"poly_overlap_volume", poly_overlap_volume},
    {"poly_force_gradient", poly_force_gradient},
    {"shaped_output", shaped_output},
    {"angle_of_repose", angle_of_repose},
    {"shaped_on_triangles", shaped_on_triangles},
    {"sphere_triangle_vs_ccd", sphere_triangle_vs_ccd},
    {"shape_mass_properties", shape_mass_properties},
    {"tennis_racket", tennis_racket},
    {"ellipsoid_settles_flat", ellipsoid_settles_flat},
    {"cube_tilted_plane", cube_tilted_plane},
};

int main(int argc, char **argv) { return test_main(argc, argv, tests, TEST_COUNT(tests)); }
