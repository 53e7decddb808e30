/* Public API of the FEM server: model creation, static solve, interface,
 * wheel motion, sub-cycled advance, reactions and energies.
 *
 * Rim frame. The deformation is integrated in the frame of the rim, where
 * the rim nodes are fixed (Dirichlet, u = 0). The wheel moves rigidly:
 *   x = c + R (X + u),   v = v_c + omega x R (X + u) + R du/dt.
 * Forces from the DEM arrive in the world frame and are rotated into the rim
 * frame with R^T; gravity likewise (it turns in the rim frame as the wheel
 * rolls).
 * What this neglects: the rim frame rotates (and translates with
 * acceleration), so the exact equations in it carry fictitious forces per
 * unit mass: centrifugal omega x (omega x r), Coriolis 2 omega x du/dt,
 * Euler domega/dt x r and the centre's acceleration. At the scene's speeds
 * (omega ~ 2 rad/s, r <= 0.272 m) the centrifugal acceleration is
 * omega^2 r = 1.09 m/s^2: as a load on the 31 mm thick tread (rho = 1100
 * kg/m^3) that is rho t omega^2 r = 37 Pa, 2.7e-4 of the 0.14 MPa inflation
 * pressure and 0.11 g; Coriolis with deformation rates of ~0.03 m/s
 * (a 5 mm deflection crossing the patch in ~0.2 s) is 2 omega du/dt =
 * 0.1 m/s^2 = 0.01 g; the wheel's prescribed motion has constant velocities
 * in the travel phase (no Euler term), and under torque or drawbar control
 * its accelerations are limited to wheel.max_accel (5 m/s^2 by default:
 * rho t a = 170 Pa on the tread, 1.2e-3 of the inflation pressure). All
 * small against pressure and contact loads, so the rim-frame model with
 * R^T g is adequate. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fem_bc.h"
#include "fem_element.h"
#include "fem_model.h"
#include "log.h"

void fem_load_pressure(const fem_mesh *m, uint8_t tag, double p, double *f)
{
    for (int k = 0; k < m->n_faces; k++) {
        if (!(m->face_tag[k] & tag))
            continue;
        if (m->face_mid) { /* 6-node face: -p int N_k n dA per node */
            int32_t nd[6];
            double an[6][3], a[6];
            int n = fem_mesh_face_nodes(m, k, nd);
            fem_mesh_face_load(m, k, an, a);
            for (int q = 0; q < n; q++)
                for (int d = 0; d < 3; d++)
                    f[3 * nd[q] + d] -= p * an[q][d];
            continue;
        }
        const int32_t *t = &m->faces[3 * k];
        const double *a = &m->x[3 * t[0]], *b = &m->x[3 * t[1]], *c = &m->x[3 * t[2]];
        double e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
        /* A n = (e1 x e2)/2, outward; one third of -p A n to each node */
        double an[3] = {0.5 * (e1[1] * e2[2] - e1[2] * e2[1]), 0.5 * (e1[2] * e2[0] - e1[0] * e2[2]),
                        0.5 * (e1[0] * e2[1] - e1[1] * e2[0])};
        for (int q = 0; q < 3; q++)
            for (int d = 0; d < 3; d++)
                f[3 * t[q] + d] -= p * an[d] / 3.0;
    }
}

static void wheel_identity(fem_wheel *w)
{
    memset(w, 0, sizeof *w);
    w->R[0] = w->R[4] = w->R[8] = 1.0;
}

/* y = R x / y = R^T x, R row-major */
static void rot(const double *R, const double *x, double *y)
{
    for (int i = 0; i < 3; i++)
        y[i] = R[3 * i] * x[0] + R[3 * i + 1] * x[1] + R[3 * i + 2] * x[2];
}
static void rot_t(const double *R, const double *x, double *y)
{
    for (int i = 0; i < 3; i++)
        y[i] = R[i] * x[0] + R[3 + i] * x[1] + R[6 + i] * x[2];
}

static int build_interface(fem_model *m, cm_error *err)
{
    const fem_mesh *me = &m->mesh;
    int32_t *map = malloc((size_t)me->n_nodes * sizeof *map);
    if (!map)
        return cm_fail(err, CM_ERR_NOMEM, "fem: out of memory");
    for (int i = 0; i < me->n_nodes; i++)
        map[i] = -1;
    /* A 6-node face of 10-node elements is given to the DEM as four linear
     * triangles (corner, mid, mid) x 3 and (mid, mid, mid), all oriented as
     * the face: the DEM sees linear triangles only, and its forces go to the
     * corner and mid-edge nodes by eq. 42 on the sub-triangle. */
    static const int sub[4][3] = {{0, 3, 5}, {3, 1, 4}, {5, 4, 2}, {3, 4, 5}};
    const uint32_t per_face = me->face_mid ? 4u : 1u;
    uint32_t nt = 0;
    for (int f = 0; f < me->n_faces; f++)
        if (me->face_tag[f] & FEM_FACE_CONTACT) {
            int32_t nd[6];
            int n = fem_mesh_face_nodes(me, f, nd);
            nt += per_face;
            for (int q = 0; q < n; q++)
                map[nd[q]] = 0;
        }
    uint32_t nn = 0;
    for (int i = 0; i < me->n_nodes; i++) /* ascending node id: compact and stable */
        if (map[i] == 0)
            map[i] = (int32_t)nn++;
    m->n_if_nodes = nn;
    m->n_if_tris = nt;
    m->if_nodes = malloc((nn ? nn : 1) * sizeof *m->if_nodes);
    m->if_force = calloc(3 * (nn ? nn : 1), sizeof *m->if_force);
    m->if_tris = malloc((size_t)3 * (nt ? nt : 1) * sizeof *m->if_tris);
    if (!m->if_nodes || !m->if_tris || !m->if_force) {
        free(map);
        return cm_fail(err, CM_ERR_NOMEM, "fem: out of memory");
    }
    for (int i = 0; i < me->n_nodes; i++)
        if (map[i] >= 0)
            m->if_nodes[map[i]] = (uint32_t)i;
    uint32_t t = 0;
    for (int f = 0; f < me->n_faces; f++)
        if (me->face_tag[f] & FEM_FACE_CONTACT) {
            int32_t nd[6];
            fem_mesh_face_nodes(me, f, nd);
            for (uint32_t s = 0; s < per_face; s++) {
                for (int q = 0; q < 3; q++)
                    m->if_tris[3 * t + (uint32_t)q] = (uint32_t)map[nd[per_face == 1 ? q : sub[s][q]]];
                t++;
            }
        }
    free(map);
    if (nn == 0)
        cm_log_warn("%s: the contact set is empty: no interface to the DEM", me->source);
    return CM_OK;
}

/* Selective mass scaling (fem.interface_mass_min): each free interface node
 * lighter than m_min gets the mass m_min (all three components, so gravity
 * and eq. 42's effective mass see it too). Why: a grain contact of
 * stiffness k_c on a surface node of mass m is sampled once per exchange
 * interval H (its force is computed from the node's position at the
 * exchange and held), so the staggered pair is stable only for
 *   H < 2 / sqrt((k_c + k_n) / m),
 * k_n the node's own FE stiffness (the diagonal of K; the FE itself is
 * sub-cycled). Light surface nodes set that limit; raising their mass to
 *   m_min = (k_c + k_n) (H / 2)^2 x safety
 * lifts it for the interval H wanted, changing only the surface's highest
 * frequencies. The added mass is logged and written to fem_run.json. */
static void scale_interface_masses(fem_model *m, double m_min)
{
    fem_solver *s = m->s;
    double added = 0.0;
    for (uint32_t k = 0; k < m->n_if_nodes; k++) {
        size_t d = 3 * (size_t)m->if_nodes[k];
        for (size_t a = 0; a < 3; a++) {
            if (s->fixed[d + a] || s->mass[d + a] >= m_min)
                continue;
            if (a == 0)
                added += m_min - s->mass[d];
            s->mass[d + a] = m_min;
            s->inv_mass[d + a] = 1.0 / m_min;
        }
    }
    m->added_mass = added;
}

double fem_added_mass(const fem_model *m) { return m->added_mass; }

int fem_create(const fem_config *cfg, fem_model **out, cm_error *err)
{
    *out = NULL;
    if (!(cfg->dt > 0.0))
        return cm_fail(err, CM_ERR_RANGE, "fem: dt must be positive (%g)", cfg->dt);
    fem_model *m = calloc(1, sizeof *m);
    if (!m)
        return cm_fail(err, CM_ERR_NOMEM, "fem: out of memory");
    m->cfg = *cfg;
    wheel_identity(&m->wheel);
    int rc;
    switch (cfg->mesh) {
    case FEM_MESH_TIRE:
        rc = fem_mesh_tire_order(&cfg->tire, cfg->element == FEM_ELEMENT_TET10 ? 2 : 1, &m->mesh, err);
        break;
    case FEM_MESH_GMSH:
        rc = fem_mesh_read_gmsh(cfg->gmsh_path, &m->mesh, err);
        if (!rc && cfg->element == FEM_ELEMENT_TET10 && !m->mesh.tet_mid)
            rc = fem_mesh_make_quadratic(&m->mesh, NULL, err); /* straight edges */
        else if (!rc && cfg->element == FEM_ELEMENT_TET4 && m->mesh.tet_mid)
            rc = cm_fail(err, CM_ERR_RANGE, "%s: second-order tetrahedra need fem.element = \"tet10\"",
                         cfg->gmsh_path);
        break;
    default:
        rc = fem_mesh_box_order(cfg->box_size, cfg->box_cells, cfg->element == FEM_ELEMENT_TET10 ? 2 : 1, &m->mesh,
                                err);
        break;
    }
    if (rc)
        goto fail;
    rc = fem_solver_create(&m->mesh, cfg->E, cfg->nu, cfg->rho, cfg->rayleigh_alpha, cfg->rayleigh_beta, &m->s, err);
    if (rc)
        goto fail;
    rc = fem_bc_constrain(m->s, &m->mesh, cfg, err);
    if (rc)
        goto fail;
    if (cfg->material_model == FEM_MATERIAL_NEO_HOOKEAN) {
        rc = fem_solver_use_neo_hookean(m->s, &m->mesh, err);
        if (rc)
            goto fail;
        cm_log_info("fem: Neo-Hookean rubber (lambda %.4g Pa, mu %.4g Pa) in the explicit steps; the static start "
                    "and the stability estimate use the small-strain stiffness", m->s->lambda, m->s->mu);
    }
    m->b_pressure = calloc((size_t)m->s->n_dof, sizeof(double));
    m->u_prev = calloc((size_t)m->s->n_dof, sizeof(double));
    if (!m->b_pressure || !m->u_prev) {
        rc = cm_fail(err, CM_ERR_NOMEM, "fem: out of memory");
        goto fail;
    }
    fem_load_pressure(&m->mesh, FEM_FACE_CAVITY, cfg->pressure, m->b_pressure);
    if ((rc = fem_bc_loads(&m->mesh, cfg, m->b_pressure, err)))
        goto fail;
    rc = build_interface(m, err);
    if (rc)
        goto fail;
    if (cfg->interface_mass_min > 0.0 && cfg->integrator != FEM_INTEGRATOR_RIGID)
        scale_interface_masses(m, cfg->interface_mass_min);
    {   /* body size: bounding-box diagonal, the scale for "blown up" */
        double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
        for (int n = 0; n < m->mesh.n_nodes; n++)
            for (int a = 0; a < 3; a++) {
                lo[a] = fmin(lo[a], m->mesh.x[3 * n + a]);
                hi[a] = fmax(hi[a], m->mesh.x[3 * n + a]);
            }
        m->size = sqrt((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) +
                       (hi[2] - lo[2]) * (hi[2] - lo[2]));
    }
    if (cfg->integrator != FEM_INTEGRATOR_RIGID) {
        rc = fem_solver_stability(m->s, &m->mesh, cfg->power_iterations, &m->stab, err);
        if (rc)
            goto fail;
        m->have_stab = true;
        cm_log_info("fem: stable step: estimate h/c = %.4g s, 2/omega_max = %.4g s (%d power iterations), "
                    "Gershgorin bound %.4g s, limit with damping %.4g s; dt = %.4g s",
                    m->stab.dt_estimate, m->stab.dt_power, m->stab.power_iterations_done, m->stab.dt_gershgorin,
                    m->stab.dt_limit, cfg->dt);
        if (cfg->integrator == FEM_INTEGRATOR_EXPLICIT && cfg->dt > m->stab.dt_limit) {
            if (!cfg->allow_unstable) {
                rc = cm_fail(err, CM_ERR_RANGE,
                             "fem: dt = %.4g s exceeds the explicit stability limit %.4g s (2/omega_max; estimate "
                             "h/c = %.4g s): lower fem.dt or set fem.allow_unstable",
                             cfg->dt, m->stab.dt_limit, m->stab.dt_estimate);
                goto fail;
            }
            cm_log_warn("fem: dt = %.4g s above the stability limit %.4g s (allow_unstable)", cfg->dt,
                        m->stab.dt_limit);
        }
    }
    fem_model_build_load(m, NULL);
    fem_solver_set_state(m->s, NULL, NULL);
    if (cfg->output_dir[0]) {
        rc = fem_output_open(m, cfg->output_dir, &m->out, err);
        if (rc)
            goto fail;
    }
    *out = m;
    return CM_OK;
fail:
    fem_destroy(&m);
    return rc;
}


void fem_destroy(fem_model **pm)
{
    fem_model *m = *pm;
    if (!m)
        return;
    if (m->out) {
        cm_error e = {0};
        if (fem_output_close(&m->out, &e))
            cm_log_warn("fem: closing output: %s", e.msg);
    }
    fem_solver_destroy(&m->s);
    fem_mesh_free(&m->mesh);
    free(m->b_pressure);
    free(m->u_prev);
    free(m->if_nodes);
    free(m->if_force);
    free(m->if_tris);
    free(m);
    *pm = NULL;
}

void fem_model_build_load(fem_model *m, const double *f_iface)
{
    fem_solver *s = m->s;
    double g[3];
    rot_t(m->wheel.R, m->cfg.gravity, g);
    /* body force rho g: consistent nodal load int N_i rho g = m_i g (the
     * lumped mass of eq. 33 is exactly int rho N_i); by node, without a
     * division for d % 3 at every dof */
    double *restrict f = s->f;
    const double *restrict bp = m->b_pressure, *restrict mass = s->mass;
    for (int d = 0; d < s->n_dof; d += 3) {
        f[d] = bp[d] + mass[d] * g[0];
        f[d + 1] = bp[d + 1] + mass[d + 1] * g[1];
        f[d + 2] = bp[d + 2] + mass[d + 2] * g[2];
    }
    if (f_iface)
        memcpy(m->if_force, f_iface, 3 * (size_t)m->n_if_nodes * sizeof *m->if_force);
    else
        memset(m->if_force, 0, 3 * (size_t)m->n_if_nodes * sizeof *m->if_force);
    if (f_iface)
        for (uint32_t k = 0; k < m->n_if_nodes; k++) {
            double fr[3];
            rot_t(m->wheel.R, &f_iface[3 * k], fr);
            for (int a = 0; a < 3; a++)
                s->f[3 * m->if_nodes[k] + (uint32_t)a] += fr[a];
        }
}

int fem_solve_static(fem_model *m, cm_error *err)
{
    fem_model_build_load(m, NULL);
    if (m->cfg.integrator == FEM_INTEGRATOR_RIGID) {
        fem_solver_set_state(m->s, NULL, NULL);
        m->static_done = true;
        return CM_OK;
    }
    int iters = 0;
    int rc = fem_solver_static(m->s, m->s->f, m->cfg.static_solver, m->cfg.cg_tol, m->cfg.cg_max_iter, m->s->u,
                               &iters, err);
    if (rc)
        return cm_fail_prefix(err, "fem static solve (K u0 = b0)");
    fem_solver_set_state(m->s, m->s->u, NULL);
    m->static_done = true;
    double umax = 0.0;
    for (int d = 0; d < m->s->n_dof; d++)
        umax = fabs(m->s->u[d]) > umax ? fabs(m->s->u[d]) : umax;
    if (iters == 0) /* no load: nothing was factorized */
        cm_log_info("fem: static solve: no load (b0 = 0), u0 = the prescribed displacements (max |u0| = %.4g m)",
                    umax);
    else
        cm_log_info("fem: static solve (%s, %d iterations): max |u0| = %.4g m, elastic energy %.4g J",
                    m->cfg.static_solver == FEM_LINEAR_CHOLMOD ? "cholmod" : "cg", iters, umax,
                    fem_solver_elastic_energy(m->s));
    return CM_OK;
}

void fem_interface_count(const fem_model *m, uint32_t *n_nodes, uint32_t *n_tris)
{
    if (n_nodes)
        *n_nodes = m->n_if_nodes;
    if (n_tris)
        *n_tris = m->n_if_tris;
}

void fem_interface_nodes(const fem_model *m, uint32_t *ids)
{
    memcpy(ids, m->if_nodes, m->n_if_nodes * sizeof *ids);
}

int fem_write_mesh_gmsh(const fem_model *m, const char *path, cm_error *err)
{
    return fem_mesh_write_gmsh(&m->mesh, path, err);
}

void fem_mass_properties(const fem_model *m, double *mass, double *inertia_axle)
{
    double mt = 0, iy = 0;
    for (int n = 0; n < m->mesh.n_nodes; n++) {
        const double *x = &m->mesh.x[3 * n];
        double mn = m->s->mass[3 * n];
        mt += mn;
        iy += mn * (x[0] * x[0] + x[2] * x[2]);
    }
    *mass = mt;
    *inertia_axle = iy;
}

void fem_interface_masses(const fem_model *m, double *mass)
{
    /* Lumped (row-sum) mass of each interface node, eq. 33; rim nodes are
     * fixed and count as infinitely heavy (0 in the protocol's convention),
     * and so does every node of a rigid tire. */
    for (uint32_t k = 0; k < m->n_if_nodes; k++) {
        size_t d = 3 * (size_t)m->if_nodes[k];
        int moves = m->cfg.integrator != FEM_INTEGRATOR_RIGID && m->s->inv_mass[d] > 0.0;
        mass[k] = moves ? m->s->mass[d] : 0.0;
    }
}

void fem_interface_initial(const fem_model *m, double *x, uint32_t *tris, double *normals)
{
    if (x)
        for (uint32_t k = 0; k < m->n_if_nodes; k++)
            memcpy(&x[3 * k], &m->mesh.x[3 * m->if_nodes[k]], 3 * sizeof(double));
    if (tris)
        memcpy(tris, m->if_tris, (size_t)3 * m->n_if_tris * sizeof *tris);
    if (normals)
        for (uint32_t t = 0; t < m->n_if_tris; t++) {
            const double *a = &m->mesh.x[3 * m->if_nodes[m->if_tris[3 * t]]];
            const double *b = &m->mesh.x[3 * m->if_nodes[m->if_tris[3 * t + 1]]];
            const double *c = &m->mesh.x[3 * m->if_nodes[m->if_tris[3 * t + 2]]];
            double e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
            double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
            double l = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
            for (int q = 0; q < 3; q++)
                normals[3 * t + (uint32_t)q] = n[q] / l;
        }
}

void fem_interface_state(const fem_model *m, double *restrict x, double *restrict v)
{
    /* the wheel and the arrays taken out of the model once: the stores to x
     * and v could otherwise alias every field the loop reads */
    const fem_wheel w = m->wheel;
    const double *restrict X = m->mesh.x, *restrict U = m->s->u, *restrict V = m->s->v;
    const uint32_t *restrict nodes = m->if_nodes;
    for (uint32_t k = 0; k < m->n_if_nodes; k++) {
        uint32_t n = nodes[k];
        double r[3], Rr[3], Rv[3];
        for (int a = 0; a < 3; a++)
            r[a] = X[3 * n + (uint32_t)a] + U[3 * n + (uint32_t)a];
        rot(w.R, r, Rr);
        if (x)
            for (int a = 0; a < 3; a++)
                x[3 * k + (uint32_t)a] = w.center[a] + Rr[a];
        if (v) {
            rot(w.R, &V[3 * n], Rv);
            /* v = v_c + omega x R(X+u) + R du/dt */
            v[3 * k + 0] = w.v_center[0] + w.omega[1] * Rr[2] - w.omega[2] * Rr[1] + Rv[0];
            v[3 * k + 1] = w.v_center[1] + w.omega[2] * Rr[0] - w.omega[0] * Rr[2] + Rv[1];
            v[3 * k + 2] = w.v_center[2] + w.omega[0] * Rr[1] - w.omega[1] * Rr[0] + Rv[2];
        }
    }
}

int fem_set_wheel(fem_model *m, const fem_wheel *w, cm_error *err)
{
    /* R must be a rotation: R R^T = I within round-off, det = +1 */
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            double d = 0.0;
            for (int k = 0; k < 3; k++)
                d += w->R[3 * i + k] * w->R[3 * j + k];
            if (!(fabs(d - (i == j)) < 1e-9))
                return cm_fail(err, CM_ERR_RANGE, "fem_set_wheel: R is not orthonormal (R R^T)[%d][%d] = %.3g", i, j,
                               d);
        }
    m->wheel = *w;
    return CM_OK;
}

void fem_get_wheel(const fem_model *m, fem_wheel *w) { *w = m->wheel; }

/* R <- exp([omega dt]x) R (Rodrigues), then re-orthonormalized rows. */
static void wheel_move(fem_wheel *w, double dt)
{
    for (int a = 0; a < 3; a++)
        w->center[a] += w->v_center[a] * dt;
    double th = sqrt(w->omega[0] * w->omega[0] + w->omega[1] * w->omega[1] + w->omega[2] * w->omega[2]) * dt;
    if (th == 0.0)
        return;
    double k[3], wn = th / dt;
    for (int a = 0; a < 3; a++)
        k[a] = w->omega[a] / wn;
    double c = cos(th), s = sin(th), C = 1.0 - c;
    double Q[9] = {c + k[0] * k[0] * C,        k[0] * k[1] * C - k[2] * s, k[0] * k[2] * C + k[1] * s,
                   k[1] * k[0] * C + k[2] * s, c + k[1] * k[1] * C,        k[1] * k[2] * C - k[0] * s,
                   k[2] * k[0] * C - k[1] * s, k[2] * k[1] * C + k[0] * s, c + k[2] * k[2] * C};
    double Rn[9];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            Rn[3 * i + j] = Q[3 * i] * w->R[j] + Q[3 * i + 1] * w->R[3 + j] + Q[3 * i + 2] * w->R[6 + j];
    /* Gram-Schmidt on the rows keeps R a rotation over millions of steps */
    double *r0 = Rn, *r1 = Rn + 3, *r2 = Rn + 6;
    double l = sqrt(r0[0] * r0[0] + r0[1] * r0[1] + r0[2] * r0[2]);
    for (int a = 0; a < 3; a++)
        r0[a] /= l;
    double d = r0[0] * r1[0] + r0[1] * r1[1] + r0[2] * r1[2];
    for (int a = 0; a < 3; a++)
        r1[a] -= d * r0[a];
    l = sqrt(r1[0] * r1[0] + r1[1] * r1[1] + r1[2] * r1[2]);
    for (int a = 0; a < 3; a++)
        r1[a] /= l;
    r2[0] = r0[1] * r1[2] - r0[2] * r1[1];
    r2[1] = r0[2] * r1[0] - r0[0] * r1[2];
    r2[2] = r0[0] * r1[1] - r0[1] * r1[0];
    memcpy(w->R, Rn, sizeof Rn);
}

/* E_kin + E_el - b_pressure.u, J (rim frame). */
static double mechanical_energy(const fem_model *m)
{
    double e[3];
    fem_solver_energies(m->s, m->b_pressure, e);
    return e[1] + e[0] - e[2];
}

int fem_advance(fem_model *m, const double *f_iface, double interval, cm_error *err)
{
    if (!(interval > 0.0))
        return cm_fail(err, CM_ERR_RANGE, "fem_advance: interval must be positive (%g)", interval);
    /* Sub-cycling: n equal sub-steps no longer than dt. */
    double nd = ceil(interval / m->cfg.dt * (1.0 - 1e-12));
    if (nd > 1e9)
        return cm_fail(err, CM_ERR_RANGE, "fem_advance: interval %g s needs %g sub-steps", interval, nd);
    int n = nd < 1.0 ? 1 : (int)nd;
    double h = interval / n;
    m->max_substep = h;
    /* The load is held constant over the interval; gravity and the DEM
     * forces are rotated into the rim frame with R at its start (the wheel
     * turns by omega * interval ~ 1e-4 rad per exchange). */
    fem_model_build_load(m, f_iface);
    if (m->cfg.integrator == FEM_INTEGRATOR_NEWMARK && m->s->h_eff != h) {
        if (m->s->h_eff != 0.0)
            cm_log_warn("fem: sub-step changed from %.6g s to %.6g s: refactorizing K_eff (keep the exchange "
                        "interval constant to avoid this)", m->s->h_eff, h);
        int rc = fem_solver_prepare(m->s, FEM_INTEGRATOR_NEWMARK, h, err);
        if (rc)
            return rc;
    } else if (m->s->integrator != m->cfg.integrator) {
        int rc = fem_solver_prepare(m->s, m->cfg.integrator, h, err);
        if (rc)
            return rc;
    }
    fem_solver *s = m->s;
    fem_solver_load_changed(s); /* after the prepare: it reads the integrator */
    if (!m->energy_started) {
        m->energy0 = mechanical_energy(m);
        m->energy_started = true;
    }
    memcpy(m->u_prev, s->u, (size_t)s->n_dof * sizeof *s->u);
    for (int i = 0; i < n; i++) {
        int rc = fem_solver_step(s, h, err);
        if (rc)
            return rc;
    }
    /* The load was constant over the interval: its work is (f - b_p).du. */
    double dw = 0.0;
    for (int d = 0; d < s->n_dof; d++)
        dw += (s->f[d] - m->b_pressure[d]) * (s->u[d] - m->u_prev[d]);
    m->work_in += dw;
    m->work_abs += fabs(dw);
    wheel_move(&m->wheel, interval);
    m->advances++;
    /* Instability shows first as huge or non-finite displacements. */
    double umax = 0.0;
    for (uint32_t k = 0; k < m->n_if_nodes; k++)
        for (uint32_t a = 0; a < 3; a++) {
            double u = fabs(m->s->u[3 * m->if_nodes[k] + a]);
            umax = u > umax || u != u ? u : umax;
        }
    if (!(umax < 10.0 * m->size))
        return cm_fail(err, CM_ERR_NUMERIC, "fem: displacement %.3g m at t = %.6g s (step %ld): integration "
                       "unstable (dt %.4g s, limit %.4g s)", umax, m->s->time, m->s->steps, h, m->stab.dt_limit);
    /* The energy costs about one K u product, the elements several: the
     * energy every check_every intervals (an unstable explicit tire blows up
     * within some 20), the elements once per 10 energy checks (an element
     * inverts over many intervals), a share of 1 / (10 check_every) of them
     * after each interval. Until session 33 all elements every 10th energy
     * check: a pause of ~3 ms every 100 exchanges of the paper scene on the
     * core fem_server shares with DEM rank 0, which rank 1 waited out. */
    if (m->cfg.check_every > 0) {
        const long parts = 10L * m->cfg.check_every, part = m->advances % parts;
        const int n_tets = m->mesh.n_tets;
        int rc = m->advances % m->cfg.check_every == 0 ? fem_check_energy(m, err) : CM_OK;
        if (!rc)
            rc = fem_check_elements_range(m, (int)(n_tets * part / parts), (int)(n_tets * (part + 1) / parts), err);
        if (rc)
            return rc;
    }
    return CM_OK;
}

int fem_output_due(fem_model *m, cm_error *err)
{
    if (!m->out || m->cfg.output_every <= 0 || m->advances % m->cfg.output_every != 0 ||
        m->advances == m->output_advance)
        return CM_OK;
    m->output_advance = m->advances;
    return fem_write_snapshot(m, err);
}

int fem_check_energy(const fem_model *m, cm_error *err)
{
    if (m->cfg.integrator == FEM_INTEGRATOR_RIGID || !m->energy_started)
        return CM_OK;
    double e = mechanical_energy(m), made = e - m->energy0 - m->work_in;
    double scale = fem_solver_elastic_energy(m->s) + m->work_abs;
    if (!(made <= 0.05 * scale + 1e-9))
        return cm_fail(err, CM_ERR_NUMERIC,
                       "fem: the tire's energy grew by %.3g J more than its loads put in (%.3g J of work) at t = "
                       "%.6g s (step %ld): energy growth with no input power, the integration is unstable; lower "
                       "fem.dt (explicit limit %.4g s) or coupling.dt",
                       made, m->work_in, m->s->time, m->s->steps, m->stab.dt_limit);
    return CM_OK;
}

int fem_check_elements(const fem_model *m, cm_error *err) { return fem_check_elements_range(m, 0, m->mesh.n_tets, err); }

int fem_check_elements_range(const fem_model *m, int e0, int e1, cm_error *err)
{
    if (m->cfg.integrator == FEM_INTEGRATOR_RIGID)
        return CM_OK;
    const fem_mesh *mesh = &m->mesh;
    const double *u = m->s->u;
    for (int e = e0; e < e1 && mesh->tet_mid; e++) {
        /* 10-node elements: det J of X + u and the strain at each quadrature point */
        int32_t t[10];
        double X[10][3], x[10][3], ue[10][3], g[10][3], eps[6];
        fem_mesh_tet_nodes(mesh, e, t);
        for (int i = 0; i < 10; i++)
            for (int a = 0; a < 3; a++) {
                X[i][a] = mesh->x[3 * t[i] + a];
                ue[i][a] = u[3 * t[i] + a];
                x[i][a] = X[i][a] + ue[i][a];
            }
        for (int q = 0; q < FEM_TET10_GAUSS; q++) {
            double det0 = fem_tet10_gradients(X, fem_tet10_gauss_L[q], g);
            fem_tet10_strain(g, ue, eps);
            double emax = 0.0;
            for (int k = 0; k < 6; k++)
                emax = fabs(eps[k]) > emax || eps[k] != eps[k] ? fabs(eps[k]) : emax;
            double det = fem_tet10_gradients(x, fem_tet10_gauss_L[q], g);
            if (!(det > 0.0))
                return cm_fail(err, CM_ERR_NUMERIC,
                               "fem: 10-node element %d inverted at quadrature point %d (det J %.3g of its initial "
                               "%.3g) at t = %.6g s (step %ld): the tire is crushed or its integration is unstable; "
                               "lower fem.dt or coupling.dt, or stiffen fem.material.E",
                               e, q + 1, det, det0, m->s->time, m->s->steps);
            if (!(emax <= m->cfg.max_strain))
                return cm_fail(err, CM_ERR_NUMERIC,
                               "fem: element %d stretched to a strain of %.3g (fem.max_strain = %.3g) at t = %.6g s "
                               "(step %ld): far outside linear elasticity, the integration is unstable or the load "
                               "too high; lower fem.dt or coupling.dt, or raise fem.max_strain if this is meant",
                               e, emax, m->cfg.max_strain, m->s->time, m->s->steps);
        }
    }
    for (int e = e0; e < e1 && !mesh->tet_mid; e++) {
        const int32_t *t = &mesh->tets[4 * e];
        double x[4][3], ue[4][3], grad[4][3], eps[6];
        for (int i = 0; i < 4; i++)
            for (int a = 0; a < 3; a++) {
                ue[i][a] = u[3 * t[i] + a];
                x[i][a] = mesh->x[3 * t[i] + a] + ue[i][a];
            }
        double v0 = fem_tet_gradients(&mesh->x[3 * t[0]], &mesh->x[3 * t[1]], &mesh->x[3 * t[2]],
                                      &mesh->x[3 * t[3]], grad);
        double v = fem_tet_volume(x[0], x[1], x[2], x[3]);
        if (!(v > 0.0))
            return cm_fail(err, CM_ERR_NUMERIC,
                           "fem: element %d inverted (volume %.3g of its initial %.3g m^3) at t = %.6g s (step "
                           "%ld): the tire is crushed or its integration is unstable; lower fem.dt or "
                           "coupling.dt, or stiffen fem.material.E",
                           e, v, v0, m->s->time, m->s->steps);
        fem_tet_strain(grad, ue, eps);
        double emax = 0.0;
        for (int k = 0; k < 6; k++)
            emax = fabs(eps[k]) > emax || eps[k] != eps[k] ? fabs(eps[k]) : emax;
        if (!(emax <= m->cfg.max_strain))
            return cm_fail(err, CM_ERR_NUMERIC,
                           "fem: element %d stretched to a strain of %.3g (fem.max_strain = %.3g) at t = %.6g s "
                           "(step %ld): far outside linear elasticity, the integration is unstable or the load "
                           "too high; lower fem.dt or coupling.dt, or raise fem.max_strain if this is meant",
                           e, emax, m->cfg.max_strain, m->s->time, m->s->steps);
    }
    return CM_OK;
}

double fem_time(const fem_model *m) { return m->s->time; }

int fem_get_stability(const fem_model *m, fem_stability *s)
{
    if (!m->have_stab) {
        memset(s, 0, sizeof *s);
        return CM_ERR_STATE;
    }
    *s = m->stab;
    return CM_OK;
}

void fem_get_energy(const fem_model *m, fem_energy *e)
{
    double en[3];
    fem_solver_energies(m->s, m->s->f, en);
    e->elastic = en[0];
    e->kinetic = en[1];
    e->load_potential = -en[2];
}

void fem_rim_reaction(const fem_model *m, double force[3], double torque[3])
{
    const fem_solver *s = m->s;
    const int *Kp = s->K->p, *Ki = s->K->i;
    const double *Kx = s->K->x;
    double F[3] = {0, 0, 0}, T[3] = {0, 0, 0};
    for (int n = 0; n < m->mesh.n_nodes; n++) {
        if (!(m->mesh.node_tag[n] & FEM_NODE_RIM))
            continue;
        double r[3];
        for (int a = 0; a < 3; a++) {
            int d = 3 * n + a;
            double ku = 0.0;
            for (int p = Kp[d]; p < Kp[d + 1]; p++)
                ku += Kx[p] * (s->u[Ki[p]] + s->beta * s->v[Ki[p]]);
            /* support force: K u + C v + M a - f on the rim dofs (a = v = 0
             * there, so C v reduces to beta K v) */
            r[a] = ku - s->f[d];
            F[a] += r[a];
        }
        const double *X = &m->mesh.x[3 * n];
        T[0] += X[1] * r[2] - X[2] * r[1];
        T[1] += X[2] * r[0] - X[0] * r[2];
        T[2] += X[0] * r[1] - X[1] * r[0];
    }
    rot(m->wheel.R, F, force);
    rot(m->wheel.R, T, torque);
}

void fem_mesh_size(const fem_model *m, int *n_nodes, int *n_tets)
{
    if (n_nodes)
        *n_nodes = m->mesh.n_nodes;
    if (n_tets)
        *n_tets = m->mesh.n_tets;
}

const double *fem_displacement(const fem_model *m) { return m->s->u; }

int fem_write_snapshot(fem_model *m, cm_error *err)
{
    if (!m->out)
        return CM_OK;
    int rc = fem_output_snapshot(m->out, m, err);
    return rc ? rc : fem_output_series(m->out, m, err);
}
