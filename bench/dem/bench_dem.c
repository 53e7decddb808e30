/* bench_dem: the DEM side of bench/dem/run.
 *   bench_dem prepare WORK_DIR          settle (or reload) the 20 000-grain bed,
 *                                       write WORK_DIR/bed.data for LIGGGHTS
 *   bench_dem prepare WORK_DIR spring   the same for the rolling-spring sand
 *                                       (its own cached bed; WORK_DIR/bed_spring.data)
 *   bench_dem run WORK_DIR THREADS STEPS [stirred] [spring]
 *                                       time STEPS steps from the bed (at rest,
 *                                       or "stirred": every grain given a random
 *                                       velocity in [-0.5, 0.5] m/s per axis, so
 *                                       the neighbour list is rebuilt often;
 *                                       "spring": the sand with the rolling spring
 *                                       of both scenes, DEM_ROLLING_SPRING with
 *                                       μ_r 0.15, as LIGGGHTS' rolling_friction
 *                                       epsd torsionTorque on),
 *                                       print "grain_steps_per_s <value>"
 *   bench_dem shapes WORK_DIR THREADS STEPS [N]
 *                                       settled bed of N (default 1500) random
 *                                       angular grains (12 vertices, elongation
 *                                       1.4, 16 variants) and the same bed of
 *                                       spheres (same volume-equivalent radii,
 *                                       box 0.1 x 0.1 m), both cached in
 *                                       WORK_DIR; time STEPS steps of each in
 *                                       one run, print both rates and the ratio
 * Materials and step are fixed here and in in.bench (keep them equal):
 * radius 3.2775–3.6225 mm, density 2600 kg/m3, E 5e7 Pa, ν 0.3, e 0.5,
 * μ 0.6, dt 1e-5 s, box 0.2 x 0.2 m with floor and four side walls; the
 * spring sand adds μ_r 0.15 and the damping ratio 0.3
 * (DEM_ROLLING_DAMPING_RATIO). */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "dem.h"
#include "dem_bed.h"
#include "log.h"
#include "timer.h"

static const dem_material SOIL = {.density = 2600.0, .young = 5e7, .poisson = 0.3, .restitution = 0.5, .friction = 0.6};
/* the spring sand's rolling resistance (scenes/paper.cfg's μ_r) */
#define SPRING_MU_ROLL 0.15

static dem_bed_params bed_params(const char *dir, int spring)
{
    dem_bed_params p = dem_bed_params_default();
    double lo[3] = {0, 0, 0}, hi[3] = {0.2, 0.2, 1.0};
    memcpy(p.box_min, lo, sizeof lo);
    memcpy(p.box_max, hi, sizeof hi);
    p.n_layers = 1;
    p.layers[0].count = 20000;
    p.layers[0].radius[0] = 3.2775e-3;
    p.layers[0].radius[1] = 3.6225e-3;
    p.seed = 2026;
    p.settle_ke = 1e-8;    /* J per grain: ~6 mm/s */
    p.settle_min_time = 0.3;
    p.settle_max_time = 3.0;
    p.settle_dt = 3e-5;    /* settling only; the benchmark runs 1e-5 */
    snprintf(p.file, sizeof p.file, "%s/bed_20000%s.h5", dir, spring ? "_spring" : "");
    return p;
}

/* spring: the sand with the rolling spring (its own cached bed) */
static int make_world(int threads, const char *dir, int spring, dem_world **w, cm_error *err)
{
    dem_world_def d = dem_world_def_default();
    d.dt = 1e-5;
    d.max_grains = 20000;
    d.threads = threads;
    /* DEM_BENCH_SKIN (m): the neighbour skin of the run (default: dem's
     * 0.3 r_min, which bench/dem/run gives LIGGGHTS too) */
    const char *skin = getenv("DEM_BENCH_SKIN");
    if (skin)
        d.skin = atof(skin);
    /* DEM_BENCH_KERNELS: the widest build of the vectorised loops,
     * "portable", "avx2" or "avx512" (default: the best for this CPU), to
     * time the builds against each other in one binary */
    const char *kb = getenv("DEM_BENCH_KERNELS");
    if (kb)
        d.kernels = strcmp(kb, "portable") == 0 ? DEM_KERNELS_PORTABLE
                    : strcmp(kb, "avx2") == 0   ? DEM_KERNELS_AVX2
                    : strcmp(kb, "avx512") == 0 ? DEM_KERNELS_AVX512
                                                : DEM_KERNELS_AUTO;
    dem_material soil = SOIL;
    if (spring) {
        d.rolling_model = DEM_ROLLING_SPRING;
        soil.rolling_friction = SPRING_MU_ROLL;
    }
    int rc = dem_world_create(&d, 1, &soil, w, err);
    if (rc)
        return rc;
    dem_bed_params p = bed_params(dir, spring);
    bool loaded;
    return dem_bed_build(*w, &p, NULL, NULL, &loaded, err);
}

/* The step's stages (dem_profile) and their shares of the step's time. */
static void print_profile(const dem_profile *p)
{
    double tot = p->rebuild + p->surface + p->pairs + p->integrate;
    if (!(tot > 0))
        tot = 1;
    printf("profile: rebuild %.3f s (%.1f %%) surface %.3f s (%.1f %%) pairs %.3f s (%.1f %%) "
           "integrate %.3f s (%.1f %%)\n",
           p->rebuild, 100 * p->rebuild / tot, p->surface, 100 * p->surface / tot, p->pairs, 100 * p->pairs / tot,
           p->integrate, 100 * p->integrate / tot);
}

/* The stirring velocity of grain id (deterministic). */
static void stir_velocity(int id, double v[3])
{
    uint64_t s = 0x9e3779b97f4a7c15ULL * (uint64_t)(id + 1);
    for (int k = 0; k < 3; k++) {
        s ^= s >> 31;
        s *= 0xbf58476d1ce4e5b9ULL;
        s ^= s >> 29;
        v[k] = ((double)(s >> 11) / 9007199254740992.0 - 0.5);
    }
}

static int write_liggghts_data(const dem_world *w, const char *path, int stirred, cm_error *err)
{
    FILE *f = fopen(path, "w");
    if (!f)
        return cm_fail(err, CM_ERR_IO, "%s: cannot write", path);
    int n = dem_grain_count(w);
    double zmax = 0;
    for (int i = 0; i < n; i++) {
        dem_grain_state g;
        dem_grain_get(w, i, &g);
        if (g.x[2] + g.radius > zmax)
            zmax = g.x[2] + g.radius;
    }
    fprintf(f, "LIGGGHTS data file: settled bed from bench_dem\n\n%d atoms\n1 atom types\n\n", n);
    fprintf(f, "0.0 0.2 xlo xhi\n0.0 0.2 ylo yhi\n0.0 %.6f zlo zhi\n\nAtoms\n\n", zmax * 1.5 + 0.01);
    for (int i = 0; i < n; i++) {
        dem_grain_state g;
        dem_grain_get(w, i, &g);
        /* atom_style granular: id type diameter density x y z */
        fprintf(f, "%d 1 %.17g %.17g %.17g %.17g %.17g\n", i + 1, 2 * g.radius, SOIL.density, g.x[0], g.x[1], g.x[2]);
    }
    if (stirred) {
        fprintf(f, "\nVelocities\n\n");
        for (int i = 0; i < n; i++) {
            double v[3];
            stir_velocity(i, v);
            fprintf(f, "%d %.17g %.17g %.17g 0 0 0\n", i + 1, v[0], v[1], v[2]);
        }
    }
    if (fclose(f) != 0)
        return cm_fail(err, CM_ERR_IO, "%s: write failed", path);
    return CM_OK;
}

/* Settling progress on stderr every 0.05 s of simulated time. */
static int settle_progress(dem_world *w, void *user)
{
    double *next = user;
    dem_stats s;
    dem_world_stats(w, &s);
    if (s.time >= *next) {
        fprintf(stderr, "settling: t = %.3f s, KE/grain = %.3g J, contacts %d\n", s.time,
                (s.ke_trans + s.ke_rot) / (s.grains ? s.grains : 1), s.contacts_gg + s.contacts_gw);
        *next += 0.05;
    }
    return 0;
}

/* Settled bed of n grains of one kind (0 spheres, 1 angular) for the
 * shapes comparison; cached in dir. */
static int make_shapes_world(int threads, const char *dir, int n, int angular, dem_world **w, cm_error *err)
{
    dem_world_def d = dem_world_def_default();
    d.dt = 1e-5;
    d.max_grains = n;
    d.threads = threads;
    int rc = dem_world_create(&d, 1, &SOIL, w, err);
    if (rc)
        return rc;
    dem_bed_params p = bed_params(dir, 0);
    p.box_max[0] = p.box_max[1] = 0.1;
    p.layers[0].count = n;
    p.settle_ke = 1e-7; /* J per grain, the scenes' default */
    p.settle_min_time = 0.2;
    if (angular) {
        p.layers[0].shape.type = DEM_SHAPE_POLYHEDRON;
        p.layers[0].shape.elongation = 1.4;
        p.layers[0].shape.random_verts = 12;
        p.layers[0].shape.variants = 16;
    }
    snprintf(p.file, sizeof p.file, "%s/bed_shapes_%s_%d.h5", dir, angular ? "angular" : "spheres", n);
    bool loaded;
    double next = 0.05;
    return dem_bed_build(*w, &p, settle_progress, &next, &loaded, err);
}

static int run_shapes(const char *dir, int threads, int steps, int n, cm_error *err)
{
    double rate[2] = {0, 0};
    /* DEM_BENCH_WARMUP: steps before timing (default 200; 0 for a short
     * callgrind count of the steps alone) */
    const char *wu = getenv("DEM_BENCH_WARMUP");
    int warmup = wu ? atoi(wu) : 200;
    /* DEM_BENCH_ONLY=spheres or angular: time that bed alone (a callgrind count of one kind) */
    const char *only = getenv("DEM_BENCH_ONLY");
    for (int kind = 0; kind < 2; kind++) {
        if (only && strcmp(only, kind ? "angular" : "spheres") != 0)
            continue;
        dem_world *w = NULL;
        int rc = make_shapes_world(threads, dir, n, kind, &w, err);
        for (int k = 0; k < warmup && rc == CM_OK; k++)
            rc = dem_step(w, err);
        double t0 = cm_now();
        for (int k = 0; k < steps && rc == CM_OK; k++)
            rc = dem_step(w, err);
        double t = cm_now() - t0;
        if (rc == CM_OK) {
            dem_stats s;
            dem_world_stats(w, &s);
            rate[kind] = (double)dem_grain_count(w) * steps / t;
            printf("%s: threads %d grains %d steps %d wall_s %.4f contacts %d (grain-grain %d) rebuilds %ld bed height "
                   "%.4f m\n",
                   kind ? "angular" : "spheres", threads, dem_grain_count(w), steps, t, s.contacts_gg + s.contacts_gw,
                   s.contacts_gg, s.profile.rebuilds, dem_bed_height(w));
            print_profile(&s.profile);
            printf("%s_grain_steps_per_s %.6g\n", kind ? "angular" : "spheres", rate[kind]);
        }
        dem_world_destroy(&w);
        if (rc)
            return rc;
    }
    printf("ratio_angular_over_spheres %.4f\n", rate[1] / rate[0]);
    return CM_OK;
}

/* The run's options after STEPS: "stirred" and/or "spring", each at most
 * once; 0 if another word is given. */
typedef struct run_opt {
    int stirred, spring;
} run_opt;

static int run_options(int n, char **words, run_opt *o)
{
    *o = (run_opt){0, 0};
    for (int k = 0; k < n; k++) {
        int *flag = strcmp(words[k], "stirred") == 0 ? &o->stirred : strcmp(words[k], "spring") == 0 ? &o->spring : NULL;
        if (!flag || *flag)
            return 0;
        *flag = 1;
    }
    return 1;
}

int main(int argc, char **argv)
{
    cm_log_set_tag("bench_dem");
    cm_error err = {0};
    dem_world *w = NULL;
    run_opt opt;
    int rc;
    if ((argc == 3 || (argc == 4 && strcmp(argv[3], "spring") == 0)) && strcmp(argv[1], "prepare") == 0) {
        double t0 = cm_now();
        const int spring = argc == 4;
        const char *tag = spring ? "_spring" : "";
        rc = make_world(2, argv[2], spring, &w, &err);
        if (rc == CM_OK) {
            char path[2048];
            snprintf(path, sizeof path, "%s/bed%s.data", argv[2], tag);
            rc = write_liggghts_data(w, path, 0, &err);
            snprintf(path, sizeof path, "%s/bed%s_stirred.data", argv[2], tag);
            if (rc == CM_OK)
                rc = write_liggghts_data(w, path, 1, &err);
            printf("bed ready: %d grains, height %.4f m (%.1f s)\n", dem_grain_count(w), dem_bed_height(w),
                   cm_now() - t0);
        }
    } else if (argc >= 5 && argc <= 7 && strcmp(argv[1], "run") == 0 && run_options(argc - 5, argv + 5, &opt)) {
        int threads = atoi(argv[3]), steps = atoi(argv[4]);
        rc = make_world(threads, argv[2], opt.spring, &w, &err);
        if (opt.stirred)
            for (int i = 0; i < dem_grain_count(w) && rc == CM_OK; i++) {
                double v[3];
                stir_velocity(i, v);
                dem_grain_set(w, i, NULL, v, NULL);
            }
        /* warm-up (as LIGGGHTS' "run 200"); DEM_BENCH_WARMUP overrides it
         * (e.g. 0 for a callgrind count of the timed steps alone) */
        const char *wu = getenv("DEM_BENCH_WARMUP");
        int warmup = wu ? atoi(wu) : 200;
        for (int k = 0; k < warmup && rc == CM_OK; k++)
            rc = dem_step(w, &err);
        dem_stats s0;
        dem_world_stats(w, &s0);
        double t0 = cm_now();
        for (int k = 0; k < steps && rc == CM_OK; k++)
            rc = dem_step(w, &err);
        double t = cm_now() - t0;
        if (rc == CM_OK) {
            dem_stats s;
            dem_world_stats(w, &s);
            /* rebuilds of the timed steps only, as LIGGGHTS' "Neighbor list builds" of its last run */
            printf("threads %d steps %d wall_s %.4f contacts %d rebuilds %ld\n", threads, steps, t,
                   s.contacts_gg + s.contacts_gw, s.profile.rebuilds - s0.profile.rebuilds);
            print_profile(&s.profile);
            printf("grain_steps_per_s %.6g\n", (double)dem_grain_count(w) * steps / t);
            printf("dem_world_hash %016llx\n", (unsigned long long)dem_world_hash(w));
            printf("kernels %s\n", dem_kernels_name(w));
        }
    } else if ((argc == 5 || argc == 6) && strcmp(argv[1], "shapes") == 0) {
        rc = run_shapes(argv[2], atoi(argv[3]), atoi(argv[4]), argc == 6 ? atoi(argv[5]) : 1500, &err);
    } else {
        fprintf(stderr, "usage: %s prepare WORK_DIR [spring] | run WORK_DIR THREADS STEPS [stirred] [spring] | shapes "
                        "WORK_DIR THREADS STEPS [N]\n",
                argv[0]);
        return 2;
    }
    if (rc)
        cm_log_error("%s: %s", cm_error_name(rc), err.msg);
    dem_world_destroy(&w);
    return rc ? 1 : 0;
}
