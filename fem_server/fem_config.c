/* Scene section `fem = {...}`. Keys (SI units):
 *
 *   mesh = {
 *     type = "tire" | "gmsh" | "box";
 *     # tire (all optional; defaults = the paper's 165/65 R13, fem.h):
 *     resolution = 1.0;        # 1: ~24 000 tets; 0.25: ~1 500
 *     layers = 0;              # cells through the wall and through the lugs each; 0: round(resolution)
 *     outer_radius = 0.272;    # m, lug tops
 *     rim_radius = 0.1651;     # m
 *     width = 0.165;           # m, tread width over the lugs
 *     wall = 0.016;            # m
 *     lug_depth = 0.015;       # m
 *     shoulder_radius = 0.025; # m
 *     lugs = 16;               # per tread half, alternating halves
 *     lug_fraction = 0.5;      # share of the pitch under a lug
 *     contact_depth = 0.06;    # m, contact set = outer faces within this of outer_radius
 *     # gmsh:
 *     file = "tire.msh";       # relative to the scene folder; groups rim, cavity, contact
 *     # box (tests, demos): rim x=0, cavity z=0, contact z=top
 *     size = [1.0, 0.1, 0.1];  # m
 *     cells = [20, 2, 2];
 *   };
 *   material = { E = 20.0e6; nu = 0.45; rho = 1100.0;     # Pa, -, kg/m^3 (table 3)
 *                rayleigh_alpha = 0.0; rayleigh_beta = 0.0;     # 1/s, s (optional)
 *                model = "linear" | "neo_hookean"; };  # optional, default linear (eq. 29);
 *                # neo_hookean: compressible Neo-Hookean with the same small-strain E and nu,
 *                # explicit integrator only (fem_material.h); the static start stays linear
 *   element = "tet4" | "tet10"; # optional, default tet4: the linear tetrahedron (eq. 34; locks in
 *                               # bending); tet10: 10-node quadratic tetrahedron with HRZ lumped mass
 *                               # (fem_element.h), the tire and box meshes get mid-edge nodes, Gmsh
 *                               # files may hold second-order tets (type 11); linear material only
 *   integrator = "explicit" | "newmark" | "rigid";
 *   dt = 1.0e-5;                # s, largest sub-step
 *   allow_unstable = false;     # explicit: accept dt above the computed limit
 *   static_solver = "cholmod";  # or "cg" (Jacobi-preconditioned)
 *   cg_tol = 1e-10;  cg_max_iter = 0;   # 0: 10 x unknowns
 *   pressure = 0.14e6;          # Pa, inflation (table 2)
 *   gravity = [0.0, 0.0, -9.81];# m/s^2, world frame
 *   power_iterations = 300;     # stable-step estimate
 *   check_every = 10;           # energy-growth guard every N exchanges, element guard (inverted, or
 *   max_strain = 0.5;           #   |strain component| above max_strain) every 10 N; 0 = never
 *   interface_mass_min = 0.0;   # kg, optional: interface nodes lighter than this get this mass
 *                               # (selective mass scaling, fem_model.c): a grain contact of stiffness
 *                               # k_c on a node of mass m exchanged every H s is stable for
 *                               # H < 2 sqrt(m / (k_c + k_node)); the added mass is logged and
 *                               # written to fem_run.json (added_mass, added_mass_fraction)
 *   output = { dir = "out/fem"; every = 100;  # snapshot every N exchanges (optional)
 *              series_flush = 1.0; };        # s of wall time (optional): a coupled run's traction.csv
 *                               # and wheel.h5:/series rows are written in blocks at least this
 *                               # often, at every checkpoint and at the end (0: each row at once;
 *                               # a flush per row costs ~0.1 ms of the FEM's ~0.6 ms exchange)
 *   # Supports and dead loads by set (optional; sets: rim, cavity, contact, and the planes of the
 *   # mesh's bounding box xmin, xmax, ymin, ymax, zmin, zmax). Without supports the rim is clamped.
 *   supports = ( { set = "xmin"; fix = "x"; },                 # roller / symmetry plane
 *                { set = "rim"; fix = "xyz"; displacement = [0.0, 0.0, 0.001]; } );  # m, prescribed
 *   loads = ( { set = "xmax"; type = "traction"; value = [1.0e5, 0.0, 0.0]; },       # Pa
 *             { set = "contact"; type = "force"; value = [0.0, 0.0, -100.0]; },      # N, total
 *             { set = "cavity"; type = "pressure"; value = 1.0e5; } );               # Pa
 *   analysis = "static" | "dynamic";  # fem_server --fem-only: the static solve, or from rest
 *                                     # under the loads to run.end_time (default static)
 */
#include <stdio.h>
#include <string.h>

#include "fem.h"

fem_config fem_config_default(void)
{
    fem_config c;
    memset(&c, 0, sizeof c);
    c.mesh = FEM_MESH_TIRE;
    c.tire = fem_tire_def_default();
    c.box_size[0] = 1.0;
    c.box_size[1] = c.box_size[2] = 0.1;
    c.box_cells[0] = 10;
    c.box_cells[1] = c.box_cells[2] = 1;
    c.E = 20.0e6;
    c.nu = 0.45;
    c.rho = 1100.0;
    c.integrator = FEM_INTEGRATOR_EXPLICIT;
    c.dt = 1.0e-5;
    c.static_solver = FEM_LINEAR_CHOLMOD;
    c.cg_tol = 1e-10;
    c.pressure = 0.14e6;
    c.gravity[2] = -9.81;
    c.power_iterations = 300;
    c.check_every = 10;
    c.series_flush = 1.0;
    c.max_strain = 0.5;
    return c;
}

#define TRY(call)                                                                                         \
    do {                                                                                                  \
        int rc_ = (call);                                                                                 \
        if (rc_)                                                                                          \
            return rc_;                                                                                   \
    } while (0)

static int read_int_opt(cm_scene *s, const char *path, long lo, long hi, int def, int *out, cm_error *err)
{
    long v;
    TRY(cm_scene_int_opt(s, path, lo, hi, def, &v, err));
    *out = (int)v;
    return CM_OK;
}

/* fem.supports = ( { set = "xmin"; fix = "x"; displacement = [0.0, 0.0, 0.0]; }, ... ); */
static int read_supports(cm_scene *s, fem_config *c, cm_error *err)
{
    int n = cm_scene_length(s, "fem.supports");
    if (n > FEM_MAX_BC)
        return cm_fail(err, CM_ERR_RANGE, "%s: fem.supports: %d entries, at most %d", cm_scene_path(s), n,
                       FEM_MAX_BC);
    c->n_supports = n;
    for (int i = 0; i < n; i++) {
        fem_support *sp = &c->supports[i];
        char key[96], fix[16];
        int k;
        snprintf(key, sizeof key, "fem.supports.[%d].set", i);
        TRY(cm_scene_choice(s, key, fem_set_names, &k, err));
        sp->set = (fem_set)k;
        snprintf(key, sizeof key, "fem.supports.[%d].fix", i);
        TRY(cm_scene_string(s, key, fix, sizeof fix, err));
        memset(sp->fix, 0, sizeof sp->fix);
        for (const char *q = fix; *q; q++) {
            const char *at = strchr("xyz", *q);
            if (!at || !*q || sp->fix[at - "xyz"])
                return cm_fail(err, CM_ERR_RANGE, "%s: %s = \"%s\": the components to fix, each of x, y, z at most "
                               "once (\"xyz\" clamps, \"x\" is a roller / symmetry plane normal to x)",
                               cm_scene_path(s), key, fix);
            sp->fix[at - "xyz"] = true;
        }
        if (!fix[0])
            return cm_fail(err, CM_ERR_RANGE, "%s: %s is empty: name the components to fix (x, y, z)",
                           cm_scene_path(s), key);
        static const double zero[3] = {0.0, 0.0, 0.0};
        snprintf(key, sizeof key, "fem.supports.[%d].displacement", i);
        TRY(cm_scene_doubles_opt(s, key, 3, -1e3, 1e3, zero, sp->value, err));
    }
    return CM_OK;
}

/* fem.loads = ( { set = "xmax"; type = "traction"; value = [1e5, 0.0, 0.0]; },
 *               { set = "cavity"; type = "pressure"; value = 2e5; }, ... ); */
static int read_loads(cm_scene *s, fem_config *c, cm_error *err)
{
    static const char *const types[] = {"pressure", "traction", "force", NULL};
    int n = cm_scene_length(s, "fem.loads");
    if (n > FEM_MAX_BC)
        return cm_fail(err, CM_ERR_RANGE, "%s: fem.loads: %d entries, at most %d", cm_scene_path(s), n, FEM_MAX_BC);
    c->n_loads = n;
    for (int i = 0; i < n; i++) {
        fem_load *ld = &c->loads[i];
        char key[96];
        int k;
        snprintf(key, sizeof key, "fem.loads.[%d].set", i);
        TRY(cm_scene_choice(s, key, fem_set_names, &k, err));
        ld->set = (fem_set)k;
        snprintf(key, sizeof key, "fem.loads.[%d].type", i);
        TRY(cm_scene_choice(s, key, types, &k, err));
        ld->type = (fem_load_type)k;
        snprintf(key, sizeof key, "fem.loads.[%d].value", i);
        memset(ld->value, 0, sizeof ld->value);
        if (ld->type == FEM_LOAD_PRESSURE)
            TRY(cm_scene_double(s, key, -1e12, 1e12, &ld->value[0], err));
        else
            TRY(cm_scene_doubles(s, key, 3, -1e12, 1e12, ld->value, err));
    }
    return CM_OK;
}

int fem_config_read(cm_scene *s, fem_config *c, cm_error *err)
{
    static const char *const mesh_types[] = {"tire", "gmsh", "box", NULL};
    static const char *const integrators[] = {"explicit", "newmark", "rigid", NULL};
    static const char *const solvers[] = {"cholmod", "cg", NULL};
    int k;
    TRY(cm_scene_choice(s, "fem.mesh.type", mesh_types, &k, err));
    c->mesh = (fem_mesh_type)k;
    if (c->mesh == FEM_MESH_TIRE) {
        fem_tire_def d = fem_tire_def_default(), *t = &c->tire;
        TRY(cm_scene_double_opt(s, "fem.mesh.resolution", 0.05, 16.0, d.resolution, &t->resolution, err));
        TRY(cm_scene_double_opt(s, "fem.mesh.outer_radius", 0.01, 10.0, d.outer_radius, &t->outer_radius, err));
        TRY(cm_scene_double_opt(s, "fem.mesh.rim_radius", 0.001, 10.0, d.rim_radius, &t->rim_radius, err));
        TRY(cm_scene_double_opt(s, "fem.mesh.width", 0.001, 10.0, d.width, &t->width, err));
        TRY(cm_scene_double_opt(s, "fem.mesh.wall", 1e-4, 1.0, d.wall, &t->wall, err));
        TRY(cm_scene_double_opt(s, "fem.mesh.lug_depth", 0.0, 1.0, d.lug_depth, &t->lug_depth, err));
        TRY(cm_scene_double_opt(s, "fem.mesh.shoulder_radius", 1e-4, 1.0, d.shoulder_radius, &t->shoulder_radius,
                                err));
        TRY(read_int_opt(s, "fem.mesh.lugs", 1, 1000, d.lugs, &t->lugs, err));
        TRY(cm_scene_double_opt(s, "fem.mesh.lug_fraction", 0.01, 0.99, d.lug_fraction, &t->lug_fraction, err));
        TRY(cm_scene_double_opt(s, "fem.mesh.contact_depth", 0.0, 10.0, d.contact_depth, &t->contact_depth, err));
        TRY(read_int_opt(s, "fem.mesh.layers", 0, 64, d.layers, &t->layers, err));
    } else if (c->mesh == FEM_MESH_GMSH) {
        char file[512];
        TRY(cm_scene_string(s, "fem.mesh.file", file, sizeof file, err));
        const char *dir = cm_scene_dir(s);
        if (file[0] == '/' || !dir || !dir[0])
            snprintf(c->gmsh_path, sizeof c->gmsh_path, "%s", file);
        else if ((size_t)snprintf(c->gmsh_path, sizeof c->gmsh_path, "%s/%s", dir, file) >= sizeof c->gmsh_path)
            return cm_fail(err, CM_ERR_RANGE, "%s: fem.mesh.file: path too long", cm_scene_path(s));
    } else {
        double cells[3];
        TRY(cm_scene_doubles(s, "fem.mesh.size", 3, 1e-6, 1e3, c->box_size, err));
        TRY(cm_scene_doubles(s, "fem.mesh.cells", 3, 1, 1000, cells, err));
        for (int a = 0; a < 3; a++) {
            if (cells[a] != (double)(int)cells[a])
                return cm_fail(err, CM_ERR_RANGE, "%s: fem.mesh.cells: whole numbers expected", cm_scene_path(s));
            c->box_cells[a] = (int)cells[a];
        }
        /* fem_mesh_from_grid's limit, said here with the key and the file */
        if (6.0 * cells[0] * cells[1] * cells[2] > 1e8)
            return cm_fail(err, CM_ERR_RANGE, "%s: fem.mesh.cells: %g x %g x %g cells make %.3g tetrahedra, more "
                           "than the 1e+08 allowed", cm_scene_path(s), cells[0], cells[1], cells[2],
                           6.0 * cells[0] * cells[1] * cells[2]);
    }
    TRY(cm_scene_double(s, "fem.material.E", 1.0, 1e13, &c->E, err));
    TRY(cm_scene_double(s, "fem.material.nu", -0.99, 0.4999, &c->nu, err));
    TRY(cm_scene_double(s, "fem.material.rho", 1e-3, 1e5, &c->rho, err));
    TRY(cm_scene_double_opt(s, "fem.material.rayleigh_alpha", 0.0, 1e6, 0.0, &c->rayleigh_alpha, err));
    TRY(cm_scene_double_opt(s, "fem.material.rayleigh_beta", 0.0, 1.0, 0.0, &c->rayleigh_beta, err));
    TRY(cm_scene_choice(s, "fem.integrator", integrators, &k, err));
    c->integrator = (fem_integrator)k;
    static const char *const models[] = {"linear", "neo_hookean", NULL};
    TRY(cm_scene_choice_opt(s, "fem.material.model", models, FEM_MATERIAL_LINEAR, &k, err));
    c->material_model = (fem_material_model)k;
    if (c->material_model == FEM_MATERIAL_NEO_HOOKEAN && c->integrator == FEM_INTEGRATOR_NEWMARK)
        return cm_fail(err, CM_ERR_RANGE, "%s: fem.material.model = \"neo_hookean\" needs fem.integrator = "
                       "\"explicit\": Newmark's linear solve cannot use it yet", cm_scene_path(s));
    static const char *const elements[] = {"tet4", "tet10", NULL};
    TRY(cm_scene_choice_opt(s, "fem.element", elements, FEM_ELEMENT_TET4, &k, err));
    c->element = (fem_element_type)k;
    if (c->element == FEM_ELEMENT_TET10 && c->material_model == FEM_MATERIAL_NEO_HOOKEAN)
        return cm_fail(err, CM_ERR_RANGE, "%s: fem.element = \"tet10\" is linear elastic only: fem.material.model "
                       "= \"neo_hookean\" needs fem.element = \"tet4\"", cm_scene_path(s));
    TRY(cm_scene_double(s, "fem.dt", 1e-12, 1.0, &c->dt, err));
    TRY(cm_scene_bool_opt(s, "fem.allow_unstable", false, &c->allow_unstable, err));
    TRY(cm_scene_choice_opt(s, "fem.static_solver", solvers, FEM_LINEAR_CHOLMOD, &k, err));
    c->static_solver = (fem_linear_solver)k;
    TRY(cm_scene_double_opt(s, "fem.cg_tol", 1e-16, 1e-1, 1e-10, &c->cg_tol, err));
    TRY(read_int_opt(s, "fem.cg_max_iter", 0, 100000000, 0, &c->cg_max_iter, err));
    TRY(cm_scene_double_opt(s, "fem.pressure", 0.0, 1e9, 0.14e6, &c->pressure, err));
    static const double g0[3] = {0.0, 0.0, -9.81};
    TRY(cm_scene_doubles_opt(s, "fem.gravity", 3, -1e3, 1e3, g0, c->gravity, err));
    TRY(read_int_opt(s, "fem.power_iterations", 1, 1000000, 300, &c->power_iterations, err));
    char dir[512];
    TRY(cm_scene_string_opt(s, "fem.output.dir", "", dir, sizeof dir, err));
    if (dir[0] && dir[0] != '/' && cm_scene_dir(s) && cm_scene_dir(s)[0]) {
        if ((size_t)snprintf(c->output_dir, sizeof c->output_dir, "%s/%s", cm_scene_dir(s), dir) >=
            sizeof c->output_dir)
            return cm_fail(err, CM_ERR_RANGE, "%s: fem.output.dir: path too long", cm_scene_path(s));
    } else {
        snprintf(c->output_dir, sizeof c->output_dir, "%s", dir);
    }
    TRY(read_int_opt(s, "fem.output.every", 0, 1000000000, 0, &c->output_every, err));
    TRY(cm_scene_double_opt(s, "fem.output.series_flush", 0.0, 1e9, c->series_flush, &c->series_flush, err));
    TRY(read_int_opt(s, "fem.check_every", 0, 1000000000, c->check_every, &c->check_every, err));
    TRY(cm_scene_double_opt(s, "fem.max_strain", 1e-6, 100.0, c->max_strain, &c->max_strain, err));
    TRY(cm_scene_double_opt(s, "fem.interface_mass_min", 0.0, 1e3, 0.0, &c->interface_mass_min, err));
    TRY(read_supports(s, c, err));
    TRY(read_loads(s, c, err));
    if (cm_scene_has(s, "fem.floor")) {
        c->floor = true;
        TRY(cm_scene_choice_opt(s, "fem.floor.set", fem_set_names, FEM_SET_CONTACT, &k, err));
        c->floor_set = (fem_set)k;
        int has_h = cm_scene_has(s, "fem.floor.height"), has_l = cm_scene_has(s, "fem.floor.load");
        if (has_h == has_l)
            return cm_fail(err, CM_ERR_KEY, "%s: fem.floor needs exactly one of height (m, the plane z = height in "
                           "the rim frame) and load (N, the load the floor must carry)", cm_scene_path(s));
        if (has_h)
            TRY(cm_scene_double(s, "fem.floor.height", -1e3, 1e3, &c->floor_height, err));
        else
            TRY(cm_scene_double(s, "fem.floor.load", 1e-9, 1e12, &c->floor_load, err));
    }
    static const char *const analyses[] = {"static", "dynamic", NULL};
    TRY(cm_scene_choice_opt(s, "fem.analysis", analyses, FEM_ANALYSIS_STATIC, &k, err));
    c->analysis = (fem_analysis)k;
    return CM_OK;
}
