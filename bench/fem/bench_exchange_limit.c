/* The staggered exchange's stability limit over the tire's interface nodes
 * (README, "The exchange's stability"): a grain contact of stiffness k_c on
 * a surface node of lumped mass m and own diagonal stiffness K_ii is stable
 * for an exchange interval H < 2 sqrt(m / (k_c + K_ii)). For each element
 * given, the built-in tire at the scene's defaults (resolution 1, E 20 MPa,
 * nu 0.45, rho 1100) and the free interface nodes (the rim's are held): the
 * smallest limit over the nodes for each k_c, which kind of node sets it
 * (corner or mid-edge), and the interface_mass_min that would give the
 * interval H asked for with each k_c, with the mass it adds (what
 * fem.interface_mass_min would add, fem_model.c).
 *
 *   bench_exchange_limit H ELEMENT[:RESOLUTION] ...     e.g. 1.75e-5 tet4 tet10
 *
 * K_ii is the largest of the node's three diagonal entries of K (the
 * stiffest direction sets the limit); m is the node's lumped mass. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fem.h"
#include "fem_model.h"
#include "log.h"

static const double KC[] = {1.0e5, 1.5e5, 3.0e5}; /* N/m: README's grain contact at ~50 N, with k, stiff */
#define NKC (sizeof KC / sizeof KC[0])

static double diag(const cholmod_sparse *K, int d)
{
    const int32_t *p = K->p, *i = K->i;
    const double *x = K->x;
    for (int32_t q = p[d]; q < p[d + 1]; q++)
        if (i[q] == d)
            return x[q];
    return 0.0;
}

int main(int argc, char **argv)
{
    if (argc < 3) {
        fprintf(stderr, "usage: %s H ELEMENT[:RESOLUTION] ...\n", argv[0]);
        return 2;
    }
    cm_log_set_quiet(1);
    double H = atof(argv[1]);
    if (!(H > 0)) {
        fprintf(stderr, "bench_exchange_limit: H must be a positive interval in s (got \"%s\")\n", argv[1]);
        return 2;
    }
    for (int k = 2; k < argc; k++) {
        char el[16];
        double res = 1.0;
        int nf = sscanf(argv[k], "%15[^:]:%lf", el, &res);
        if (nf < 1 || (strcmp(el, "tet4") && strcmp(el, "tet10"))) {
            fprintf(stderr, "bench_exchange_limit: \"%s\": tet4 or tet10[:RESOLUTION] expected\n", argv[k]);
            return 2;
        }
        fem_config c = fem_config_default();
        c.tire.resolution = res;
        c.element = strcmp(el, "tet10") == 0 ? FEM_ELEMENT_TET10 : FEM_ELEMENT_TET4;
        c.integrator = FEM_INTEGRATOR_RIGID; /* no stability analysis: not needed here */
        c.dt = 1e-5;
        cm_error err = {0};
        fem_model *m;
        if (fem_create(&c, &m, &err)) {
            fprintf(stderr, "bench_exchange_limit: %s\n", err.msg);
            return 1;
        }
        const fem_solver *s = m->s;
        double body = 0.0;
        for (int d = 0; d < s->n_dof; d += 3)
            body += s->mass[d];
        double hmin[NKC], mmin_node[NKC], kmin_node[NKC];
        int corner_min[NKC];
        for (size_t j = 0; j < NKC; j++)
            hmin[j] = INFINITY, mmin_node[j] = kmin_node[j] = NAN, corner_min[j] = -1;
        double m_lo = INFINITY, m_lo_c = INFINITY, m_lo_mid = INFINITY;
        double need[NKC] = {0}; /* interface_mass_min for H, per k_c */
        int n_free = 0;
        for (uint32_t q = 0; q < m->n_if_nodes; q++) {
            int node = (int)m->if_nodes[q];
            size_t d = 3 * (size_t)node;
            if (s->fixed[d] && s->fixed[d + 1] && s->fixed[d + 2])
                continue;
            n_free++;
            double mass = s->mass[d], kii = 0.0;
            for (int a = 0; a < 3; a++)
                if (!s->fixed[d + a])
                    kii = fmax(kii, diag(s->K, (int)d + a));
            int corner = node < m->mesh.n_corner;
            m_lo = fmin(m_lo, mass);
            if (corner)
                m_lo_c = fmin(m_lo_c, mass);
            else
                m_lo_mid = fmin(m_lo_mid, mass);
            for (size_t j = 0; j < NKC; j++) {
                double h = 2.0 * sqrt(mass / (KC[j] + kii));
                if (h < hmin[j])
                    hmin[j] = h, mmin_node[j] = mass, kmin_node[j] = kii, corner_min[j] = corner;
            }
            for (size_t j = 0; j < NKC; j++) /* the one threshold that lifts every node short of H */
                if (2.0 * sqrt(mass / (KC[j] + kii)) < H)
                    need[j] = fmax(need[j], (KC[j] + kii) * (H / 2) * (H / 2));
        }
        double added[NKC] = {0};
        for (uint32_t q = 0; q < m->n_if_nodes; q++) {
            size_t d = 3 * (size_t)m->if_nodes[q];
            for (size_t j = 0; j < NKC; j++)
                if (!s->fixed[d] && s->mass[d] < need[j])
                    added[j] += need[j] - s->mass[d];
        }
        printf("%s res %g: %d free interface nodes, body %.4f kg; lightest node %.4g kg (corner %.4g, mid-edge %.4g)\n",
               el, res, n_free, body, m_lo, m_lo_c, isfinite(m_lo_mid) ? m_lo_mid : NAN);
        for (size_t j = 0; j < NKC; j++)
            printf("  k_c %.3g N/m: min 2 sqrt(m/(k_c+K_ii)) = %.4g s at a %s node (m %.4g kg, K_ii %.4g N/m)%s\n",
                   KC[j], hmin[j], corner_min[j] ? "corner" : "mid-edge", mmin_node[j], kmin_node[j],
                   hmin[j] < H ? "  < H" : "");
        for (size_t j = 0; j < NKC; j++)
            printf("  interface_mass_min for H = %.3g s at k_c %.3g N/m: %.4g kg, adds %.4g kg (%.3g %% of the body)\n",
                   H, KC[j], need[j], added[j], 100 * added[j] / body);
        fem_destroy(&m);
    }
    return 0;
}
