/* The tire's deflection on a rigid floor, converged under refinement
 * (issue 16 item 1): the built-in tire inflated to 0.14 MPa and pressed
 * onto the kinematic floor (fem.floor) until it carries 400 N, no gravity,
 * for each element:resolution given; beside it the cost of an explicit
 * step and the stable step (2/omega_max), so that the deflection's error is
 * set against what a run pays for it.
 *
 *   bench_deflection OUT.csv tet4:0.5 tet4:1.0 tet10:0.5 ...
 *
 * Options after a second colon, comma-separated: refactor (the floor's
 * reference method, for its cost), nostep (no stability analysis and no
 * explicit steps, for the finest meshes, whose step cost nobody pays;
 * step_ms and dt_limit_s are nan), layersN (fem.mesh.layers = N: cells
 * through the wall and the lugs; the resolution column then reads
 * RES/N).
 *
 * CSV columns: element, resolution, nodes, tets, deflection_mm, contact_nodes,
 * floor_s (the static floor solve, wall clock), floor_cpu_s (its process CPU
 * time: what a loaded machine does not inflate), passes (active-set passes
 * of the whole height search), columns (influence columns solved), step_ms
 * (median of 5 blocks of explicit steps at 0.9 of the limit), dt_limit_s.
 * Integer resolutions mesh the same tire (fem_mesh.c: the centre groove);
 * others round the groove. */
#include <math.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fem.h"
#include "fem_model.h"
#include "log.h"
#include "timer.h"

static double cpu_now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

int main(int argc, char **argv)
{
    if (argc < 3) {
        fprintf(stderr, "usage: %s OUT.csv ELEMENT:RESOLUTION ...\n", argv[0]);
        return 2;
    }
    cm_log_set_quiet(1);
    FILE *fp = fopen(argv[1], "w");
    if (!fp) {
        perror(argv[1]);
        return 1;
    }
    fprintf(fp, "element,resolution,nodes,tets,deflection_mm,contact_nodes,floor_s,floor_cpu_s,passes,columns,step_ms,"
                "dt_limit_s\n");
    for (int k = 2; k < argc; k++) {
        char el[16], opts[64] = "";
        double res;
        int nf = sscanf(argv[k], "%15[^:]:%lf:%63s", el, &res, opts);
        bool refactor = false, steps = true, ok = nf >= 2 && (!strcmp(el, "tet4") || !strcmp(el, "tet10"));
        int layers = 0;
        for (char *save = NULL, *tok = strtok_r(opts, ",", &save); tok && ok; tok = strtok_r(NULL, ",", &save)) {
            if (!strcmp(tok, "refactor"))
                refactor = true;
            else if (!strcmp(tok, "nostep"))
                steps = false;
            else
                ok = sscanf(tok, "layers%d", &layers) == 1 && layers >= 1;
        }
        if (!ok) {
            fprintf(stderr, "bench_deflection: \"%s\": ELEMENT:RESOLUTION[:OPTION,...] expected (tet4 or tet10; "
                    "options refactor, nostep, layersN)\n", argv[k]);
            return 2;
        }
        fem_config c = fem_config_default();
        c.tire.resolution = res;
        c.element = strcmp(el, "tet10") == 0 ? FEM_ELEMENT_TET10 : FEM_ELEMENT_TET4;
        c.integrator = FEM_INTEGRATOR_EXPLICIT;
        c.dt = 1e-9; /* set to 0.9 of the limit below */
        c.gravity[2] = 0.0;
        c.check_every = 0;
        c.floor = true;
        c.floor_set = FEM_SET_CONTACT;
        c.floor_load = 400.0;
        c.tire.layers = layers;
        c.floor_refactor = refactor; /* the reference method: a factorization per active-set pass */
        if (!steps)
            c.integrator = FEM_INTEGRATOR_RIGID; /* no stability analysis */
        cm_error err = {0};
        fem_model *m;
        if (fem_create(&c, &m, &err)) {
            fprintf(stderr, "bench_deflection: %s\n", err.msg);
            return 1;
        }
        fem_stability st = {.dt_limit = NAN};
        if (steps) {
            fem_get_stability(m, &st);
            m->cfg.dt = 0.9 * st.dt_limit;
        }
        /* explicit steps from the inflated static state */
        double blocks[5] = {NAN, NAN, NAN, NAN, NAN};
        if (fem_solve_static(m, &err)) {
            fprintf(stderr, "bench_deflection: %s\n", err.msg);
            return 1;
        }
        for (int b = 0; b < 5 && steps; b++) {
            double t0 = cm_now();
            for (int i = 0; i < 40; i++)
                if (fem_advance(m, NULL, m->cfg.dt, &err)) {
                    fprintf(stderr, "bench_deflection: %s\n", err.msg);
                    return 1;
                }
            blocks[b] = (cm_now() - t0) / 40;
        }
        if (steps)
            qsort(blocks, 5, sizeof *blocks, cmp_double);
        fem_floor_result r;
        double t0 = cm_now(), c0 = cpu_now();
        if (fem_floor_static(m, &r, &err)) {
            fprintf(stderr, "bench_deflection: %s\n", err.msg);
            return 1;
        }
        double t_floor = cm_now() - t0, c_floor = cpu_now() - c0;
        int nn, nt;
        fem_mesh_size(m, &nn, &nt);
        char rescol[32];
        if (layers)
            snprintf(rescol, sizeof rescol, "%g/%d", res, layers);
        else
            snprintf(rescol, sizeof rescol, "%g", res);
        fprintf(fp, "%s%s,%s,%d,%d,%.6f,%d,%.3f,%.3f,%d,%d,%.4f,%.4g\n", el, refactor ? "_refactor" : "", rescol, nn, nt,
                1e3 * r.deflection, r.contact_nodes, t_floor, c_floor, r.solves, r.columns, 1e3 * blocks[2],
                st.dt_limit);
        fflush(fp);
        printf("%s res %s: %d nodes, %d tets: deflection %.6f mm (%d nodes touch, %d passes, %d columns, %.1f s, "
               "%.1f s CPU; the inflated tire's lowest point z = %.6f mm); step %.3f ms, limit %.3g s\n", el, rescol, nn,
               nt, 1e3 * r.deflection, r.contact_nodes, r.solves, r.columns, t_floor, c_floor, 1e3 * r.z_free,
               1e3 * blocks[2], st.dt_limit);
        fflush(stdout);
        fem_destroy(&m);
    }
    fclose(fp);
    return 0;
}
