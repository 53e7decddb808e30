/* Bed generation and settling, HDF5 cache, output files, scene reading,
 * determinism. */
#include <stdlib.h>
#include <sys/stat.h>
#include <unistd.h>

#include <hdf5.h>

#include "dem_bed.h"
#include "dem_config.h"
#include "dem_output.h"
#include "scene.h"
#include "test_dem_common.h"

static dem_material soil(void)
{
    dem_material m = test_material(5e6, 0.3, 0.3, 0.5);
    return m;
}

static dem_bed_params small_bed(int count)
{
    dem_bed_params p = dem_bed_params_default();
    double lo[3] = {0, 0, 0}, hi[3] = {0.04, 0.04, 0.2};
    memcpy(p.box_min, lo, sizeof lo);
    memcpy(p.box_max, hi, sizeof hi);
    p.n_layers = 2; /* coarse below, fine on top, as the paper's table 2 */
    p.layers[0].count = count / 2;
    p.layers[0].radius[0] = 2.2e-3, p.layers[0].radius[1] = 2.6e-3;
    p.layers[1].count = count - count / 2;
    p.layers[1].radius[0] = 1.8e-3, p.layers[1].radius[1] = 2.0e-3;
    p.settle_ke = 1e-9;
    p.settle_min_time = 0.1;
    p.settle_max_time = 2.0;
    return p;
}

/* A name for a bed cache from a mkstemp template (the file made and removed
 * again, so that the test's first build settles and saves). */
static int fresh_path(char *tmpl)
{
    int fd = mkstemp(tmpl);
    if (fd < 0)
        return -1;
    close(fd);
    unlink(tmpl);
    return 0;
}

static dem_world *bed_world(int max_grains, int threads)
{
    dem_material m = soil();
    double g[3] = {0, 0, -9.81};
    return test_world(&m, 1, 4e-5, max_grains, g, threads);
}

/* Settled bed: packing fraction of the core in the random-packing range
 * (0.55..0.645 for frictional spheres); floor pressure = ρ_bulk g h within
 * 10 %, with h the mean surface height and ρ_bulk = grain mass / (A h) (the
 * side walls carry part of the weight by friction: Janssen). */
static int settled_bed(void)
{
    dem_world *w = bed_world(1000, 1);
    ENSURE(w);
    dem_bed_params p = small_bed(1000);
    cm_error err = {0};
    bool loaded;
    ENSURE_MSG(dem_bed_build(w, &p, NULL, NULL, &loaded, &err) == 0, "%s", err.msg);
    ENSURE(!loaded);
    /* one step at rest to have the wall forces of the settled state */
    for (int k = 0; k < 200; k++)
        ENSURE(dem_step(w, &err) == 0);
    int n = dem_grain_count(w);
    double h = dem_bed_height(w), vol = 0, mass = 0, rmax = 0;
    dem_grain_state *gs = malloc(sizeof *gs * (size_t)n);
    for (int i = 0; i < n; i++) {
        dem_grain_get(w, i, &gs[i]);
        vol += 4.0 / 3.0 * M_PI * pow(gs[i].radius, 3);
        mass += gs[i].mass;
        rmax = fmax(rmax, gs[i].radius);
    }
    double A = 0.04 * 0.04, phi_global = vol / (A * h);
    /* core: sample points at least 2 diameters from walls, floor and surface */
    double d = 4 * rmax, lo[3] = {d, d, d}, hi[3] = {0.04 - d, 0.04 - d, h - d};
    uint64_t rs = 5;
    int inside = 0, total = 20000;
    for (int k = 0; k < total; k++) {
        double q[3];
        for (int c = 0; c < 3; c++) {
            rs = rs * 6364136223846793005ULL + 1442695040888963407ULL;
            q[c] = lo[c] + (hi[c] - lo[c]) * ((double)(rs >> 11) / 9007199254740992.0);
        }
        for (int i = 0; i < n; i++) {
            double dx = q[0] - gs[i].x[0], dy = q[1] - gs[i].x[1], dz = q[2] - gs[i].x[2];
            if (dx * dx + dy * dy + dz * dz < gs[i].radius * gs[i].radius) {
                inside++;
                break;
            }
        }
    }
    double phi_core = (double)inside / total;
    double f[3];
    ENSURE(dem_wall_force(w, 0, f) == 0);
    double p_floor = -f[2] / A, rho_s = soil().density;
    double rho_bulk = mass / (A * h);
    double p_ref = rho_bulk * 9.81 * h;
    (void)rho_s;
    dem_stats st;
    dem_world_stats(w, &st);
    printf("bed: %d grains, height %.4f m, packing core %.3f global %.3f, floor pressure %.2f Pa vs rho_bulk g h "
           "%.2f Pa (%.2f %%; rho_bulk %.1f kg/m3), max overlap %.4f r\n",
           n, h, phi_core, phi_global, p_floor, p_ref, 100 * (p_floor / p_ref - 1), rho_bulk, st.max_overlap);
    ENSURE(phi_core > 0.55 && phi_core < 0.645);
    ENSURE(phi_global > 0.50 && phi_global < 0.645);
    ENSURE_REL(p_floor, p_ref, 0.10);
    free(gs);
    dem_world_destroy(&w);
    return 0;
}

/* The same run twice gives bit-identical states for a given thread count
 * (1 and 2 threads). */
static int determinism(void)
{
    uint64_t h[2][2];
    for (int t = 0; t < 2; t++)
        for (int rep = 0; rep < 2; rep++) {
            dem_world *w = bed_world(400, t + 1);
            ENSURE(w);
            dem_bed_params p = small_bed(400);
            cm_error err = {0};
            double lo[3] = {0, 0, 0}, n[3] = {0, 0, 1};
            ENSURE(dem_wall_add(w, lo, n, 0, &err) == 0);
            ENSURE(dem_bed_place(w, &p, &err) == 0);
            for (int k = 0; k < 1500; k++)
                ENSURE(dem_step(w, &err) == 0);
            h[t][rep] = dem_world_hash(w);
            dem_world_destroy(&w);
        }
    printf("hash 1 thread %016llx %016llx, 2 threads %016llx %016llx\n", (unsigned long long)h[0][0],
           (unsigned long long)h[0][1], (unsigned long long)h[1][0], (unsigned long long)h[1][1]);
    ENSURE(h[0][0] == h[0][1]);
    ENSURE(h[1][0] == h[1][1]);
    return 0;
}

/* A saved bed reloads identically; other parameters are detected. */
static int bed_cache(void)
{
    char path[] = "/tmp/dem_bed_test_XXXXXX";
    ENSURE(fresh_path(path) == 0);
    dem_bed_params p = small_bed(200);
    p.settle_min_time = 0.02;
    p.settle_ke = 1e-6;
    snprintf(p.file, sizeof p.file, "%s", path);
    cm_error err = {0};
    bool loaded;
    dem_world *a = bed_world(200, 1);
    ENSURE(dem_bed_build(a, &p, NULL, NULL, &loaded, &err) == 0 && !loaded);
    dem_world *b = bed_world(200, 1);
    ENSURE_MSG(dem_bed_build(b, &p, NULL, NULL, &loaded, &err) == 0 && loaded, "%s", err.msg);
    ENSURE(dem_grain_count(a) == dem_grain_count(b));
    for (int i = 0; i < dem_grain_count(a); i++) {
        dem_grain_state ga, gb;
        dem_grain_get(a, i, &ga);
        dem_grain_get(b, i, &gb);
        ENSURE(memcmp(ga.x, gb.x, sizeof ga.x) == 0 && ga.radius == gb.radius);
    }
    dem_bed_params q = p;
    q.seed = 2;
    dem_world *c = bed_world(200, 1);
    ENSURE(dem_bed_load(c, &q, path, &err) == CM_WARN_STALE); /* a warning (> 0): the caller settles again */
    ENSURE(dem_grain_count(c) == 0);
    /* the run's step is part of the key where it settles the bed ... */
    double g[3] = {0, 0, -9.81};
    dem_material m = soil();
    dem_world *d = test_world(&m, 1, 2e-5, 200, g, 1);
    ENSURE(d && dem_bed_load(d, &p, path, &err) == CM_WARN_STALE);
    /* ... and not with settle_dt, which settles it whatever the run's step */
    unlink(path);
    p.settle_dt = 4e-5;
    dem_world *e = bed_world(200, 1), *f = test_world(&m, 1, 2e-5, 200, g, 1);
    ENSURE(f && dem_bed_build(e, &p, NULL, NULL, &loaded, &err) == 0 && !loaded);
    ENSURE_MSG(dem_bed_build(f, &p, NULL, NULL, &loaded, &err) == 0 && loaded, "%s", err.msg);
    ENSURE(dem_grain_count(e) == dem_grain_count(f) && dem_grain_count(f) == 200);
    dem_world_destroy(&a);
    dem_world_destroy(&b);
    dem_world_destroy(&c);
    dem_world_destroy(&d);
    dem_world_destroy(&e);
    dem_world_destroy(&f);
    unlink(path);
    return 0;
}

/* A run starts from the same state whether its bed was just settled or read
 * from the cache: after 400 steps both worlds hash the same. (Before the bed
 * was handed over as stored, the settled world kept its cell order and its
 * tangential springs and the two runs parted.) */
static int settled_equals_cached(void)
{
    char path[] = "/tmp/dem_bed_same_XXXXXX";
    ENSURE(fresh_path(path) == 0);
    dem_bed_params p = small_bed(200);
    p.settle_min_time = 0.02;
    p.settle_ke = 1e-6;
    snprintf(p.file, sizeof p.file, "%s", path);
    cm_error err = {0};
    bool loaded;
    dem_world *a = bed_world(200, 1), *b = bed_world(200, 1);
    ENSURE(a && b);
    ENSURE_MSG(dem_bed_build(a, &p, NULL, NULL, &loaded, &err) == 0 && !loaded, "%s", err.msg);
    ENSURE_MSG(dem_bed_build(b, &p, NULL, NULL, &loaded, &err) == 0 && loaded, "%s", err.msg);
    ENSURE(dem_world_hash(a) == dem_world_hash(b));
    /* shake the bed: a tilted gravity would do, a few hundred steps of it
     * settling further is enough to expose springs or a summation order */
    for (int k = 0; k < 400; k++) {
        ENSURE(dem_step(a, &err) == 0);
        ENSURE(dem_step(b, &err) == 0);
    }
    ENSURE_MSG(dem_world_hash(a) == dem_world_hash(b), "settled %016llx, cached %016llx",
               (unsigned long long)dem_world_hash(a), (unsigned long long)dem_world_hash(b));
    dem_world_destroy(&a);
    dem_world_destroy(&b);
    unlink(path);
    return 0;
}

/* A cache written by other settling code (another fingerprint, or none, as
 * every bed saved before fingerprints) is refused with the reason and the
 * bed is settled again (log line), then saved with this build's fingerprint. */
static int other_code_refused(void)
{
    char path[] = "/tmp/dem_bed_code_XXXXXX", logp[] = "/tmp/dem_bed_log_XXXXXX";
    int fd = mkstemp(path), lfd = mkstemp(logp);
    ENSURE(fd >= 0 && lfd >= 0);
    close(fd);
    unlink(path);
    dem_bed_params p = small_bed(200);
    p.settle_min_time = 0.02;
    p.settle_ke = 1e-6;
    snprintf(p.file, sizeof p.file, "%s", path);
    cm_error err = {0};
    bool loaded;
    dem_world *a = bed_world(200, 1);
    ENSURE_MSG(dem_bed_build(a, &p, NULL, NULL, &loaded, &err) == 0 && !loaded, "%s", err.msg);
    /* overwrite the stored fingerprint as another build would have written it */
    hid_t f = H5Fopen(path, H5F_ACC_RDWR, H5P_DEFAULT);
    ENSURE(f >= 0);
    char good[64] = "";
    {
        hid_t at = H5Aopen(f, "code_fingerprint", H5P_DEFAULT);
        ENSURE(at >= 0);
        hid_t t = H5Aget_type(at);
        ENSURE(H5Tget_size(t) == 17);
        ENSURE(H5Aread(at, t, good) >= 0);
        const char *other = "0123456789abcdef";
        ENSURE(strcmp(good, other) != 0);
        ENSURE(H5Awrite(at, t, other) >= 0);
        H5Tclose(t);
        H5Aclose(at);
    }
    ENSURE(H5Fclose(f) >= 0);
    dem_world *c = bed_world(200, 1);
    ENSURE(dem_bed_load(c, &p, path, &err) == CM_WARN_STALE);
    ENSURE_MSG(strstr(err.msg, "settled by other code") && strstr(err.msg, "0123456789abcdef") &&
                   strstr(err.msg, good), "%s", err.msg);
    ENSURE(dem_grain_count(c) == 0);
    /* the build settles again and says why on its log (stdout) */
    fflush(stdout);
    int saved = dup(1);
    ENSURE(saved >= 0 && dup2(lfd, 1) == 1);
    dem_world *d = bed_world(200, 1);
    int rc = dem_bed_build(d, &p, NULL, NULL, &loaded, &err);
    fflush(stdout);
    dup2(saved, 1);
    close(saved);
    ENSURE_MSG(rc == 0 && !loaded, "%s", err.msg);
    ENSURE(dem_world_hash(d) == dem_world_hash(a));
    char logbuf[4096] = "";
    FILE *lf = fopen(logp, "r");
    ENSURE(lf);
    size_t got = fread(logbuf, 1, sizeof logbuf - 1, lf);
    fclose(lf);
    logbuf[got] = '\0';
    ENSURE_MSG(strstr(logbuf, "settled by other code") && strstr(logbuf, "settling the bed again"), "log: %s", logbuf);
    /* rewritten with this build's fingerprint: served again */
    dem_world *e = bed_world(200, 1);
    ENSURE_MSG(dem_bed_build(e, &p, NULL, NULL, &loaded, &err) == 0 && loaded, "%s", err.msg);
    dem_world_destroy(&a);
    dem_world_destroy(&c);
    dem_world_destroy(&d);
    dem_world_destroy(&e);
    unlink(path);
    unlink(logp);
    close(lfd);
    return 0;
}

/* Output writes grains.h5, grains.xmf and series.csv. */
static int output_files(void)
{
    char dir[] = "/tmp/dem_out_XXXXXX";
    ENSURE(mkdtemp(dir));
    dem_world *w = bed_world(100, 1);
    cm_error err = {0};
    dem_bed_params p = small_bed(100);
    ENSURE(dem_bed_place(w, &p, &err) == 0);
    dem_output *o = NULL;
    ENSURE_MSG(dem_output_open(dir, &o, &err) == 0, "%s", err.msg);
    for (int k = 0; k < 3; k++) {
        ENSURE(dem_step(w, &err) == 0);
        ENSURE(dem_output_frame(o, w, &err) == 0);
        ENSURE(dem_output_series(o, w, &err) == 0);
    }
    dem_output_close(&o);
    const char *names[] = {"dem_grains.h5", "dem_grains.xmf", "dem_series.csv"};
    for (int k = 0; k < 3; k++) {
        char path[256];
        snprintf(path, sizeof path, "%s/%s", dir, names[k]);
        struct stat sb;
        ENSURE_MSG(stat(path, &sb) == 0 && sb.st_size > 100, "%s", path);
        unlink(path);
    }
    char xmf[256];
    snprintf(xmf, sizeof xmf, "%s", dir);
    rmdir(dir);
    dem_world_destroy(&w);
    return 0;
}

static const char *scene_text =
    "dem = {\n"
    "  dt = 2e-5; gravity = [0.0, 0.0, -9.81]; threads = 2; damping = \"calibrated\";\n"
    "  impact_velocity = 2.0; allow_unstable_dt = false; neighbor_skin = 5e-4;\n"
    "  materials = ( { name = \"soil\"; density = 2600.0; young = 5e7; poisson = 0.3; restitution = 0.5;\n"
    "                  friction = 0.6; },\n"
    "                { name = \"rubber\"; young = 1e7; poisson = 0.45; restitution = 0.8; friction = 0.9;\n"
    "                  rolling_friction = 0.01; } );\n"
    "  walls = ( { point = [0.0, 0.0, -0.1]; normal = [0.0, 0.0, 1.0]; material = \"rubber\"; } );\n"
    "  bed = { box_min = [0.0, 0.0, 0.0]; box_max = [0.2, 0.2, 0.3]; material = \"soil\"; seed = 7;\n"
    "          layers = ( { count = 100; radius = [0.007, 0.008]; }, { count = 200; radius = [0.003, 0.0035]; } );\n"
    "          settle_ke = 1e-8; file = \"bed.h5\"; };\n"
    "  output = { dir = \"out\"; every = 500; series_every = 50; };\n"
    "};\n"
    "run = { whatever = 1; };\n";

static int config_read(void)
{
    cm_scene *s = NULL;
    cm_error err = {0};
    ENSURE(cm_scene_open_string(scene_text, "test.cfg", &s, &err) == 0);
    dem_config c;
    ENSURE_MSG(dem_config_read(s, &c, &err) == 0, "%s", err.msg);
    static const char *const sections[] = {"dem", "run", NULL};
    cm_scene_mark_known(s, "run");
    ENSURE_MSG(cm_scene_check_unknown(s, sections, &err) == 0, "%s", err.msg);
    ENSURE(c.world.dt == 2e-5 && c.world.threads == 2 && c.world.impact_velocity == 2.0);
    ENSURE(c.n_materials == 2 && c.materials[1].rolling_friction == 0.01 && c.materials[1].density == 0.0);
    ENSURE(c.n_walls == 1 && c.walls[0].material == 1 && c.walls[0].point[2] == -0.1);
    ENSURE(c.has_bed && c.bed.n_layers == 2 && c.bed.layers[1].count == 200 && c.bed.seed == 7);
    ENSURE(c.bed.layers[0].radius[1] == 0.008 && c.world.max_grains == 300);
    ENSURE(strcmp(c.bed.file, "./bed.h5") == 0 || strstr(c.bed.file, "bed.h5"));
    ENSURE(c.output_every == 500 && c.series_every == 50);
    dem_world *w = NULL;
    ENSURE(dem_world_from_config(&c, &w, &err) == 0);
    dem_world_destroy(&w);
    cm_scene_close(&s);

    /* a typo is an error naming the key; an unknown material names itself */
    char bad[4096];
    snprintf(bad, sizeof bad, "%s", scene_text);
    char *k = strstr(bad, "seed = 7");
    memcpy(k, "sed  = 7", 8);
    ENSURE(cm_scene_open_string(bad, "bad.cfg", &s, &err) == 0);
    ENSURE(dem_config_read(s, &c, &err) == 0);
    ENSURE(cm_scene_check_unknown(s, sections, &err) != 0 && strstr(err.msg, "sed"));
    cm_scene_close(&s);
    snprintf(bad, sizeof bad, "%s", scene_text);
    k = strstr(bad, "material = \"rubber\"");
    memcpy(k, "material = \"rubbel\"", 19);
    ENSURE(cm_scene_open_string(bad, "bad.cfg", &s, &err) == 0);
    ENSURE(dem_config_read(s, &c, &err) == CM_ERR_KEY && strstr(err.msg, "rubbel") && strstr(err.msg, "dem.walls"));
    cm_scene_close(&s);
    return 0;
}

/* dem.bed.settle_friction: a bed settled with lubricated grains (friction 0,
 * no rolling resistance) packs denser than one settled with the material's
 * friction 0.5 (random close against random loose packing: the mean surface
 * lower by more than 3 %). The cache key knows the settling friction (the
 * material-friction bed does not load the lubricated one), and a bed settled
 * lubricated starts from the same state whether settled now or read from
 * the cache (as settled_equals_cached). dem_bed_settle gives the world its
 * material friction back: every grain of the settled bed set spinning about
 * z at 20 rad/s has lost most of its spin 200 steps (8 ms) later (its
 * contacts' sliding friction brakes it), where frictionless grains, with no
 * rolling resistance either, would keep it. */
static int settle_friction(void)
{
    char path[] = "/tmp/dem_bed_lube_XXXXXX";
    ENSURE(fresh_path(path) == 0);
    dem_bed_params p = small_bed(400);
    p.settle_min_time = 0.05;
    p.settle_ke = 1e-8;
    cm_error err = {0};
    bool loaded;
    dem_world *a = bed_world(400, 1);
    ENSURE_MSG(a && dem_bed_build(a, &p, NULL, NULL, &loaded, &err) == 0, "%s", err.msg);
    dem_bed_params q = p;
    q.settle_friction = 0.0;
    snprintf(q.file, sizeof q.file, "%s", path);
    dem_world *b = bed_world(400, 1), *c = bed_world(400, 1), *d = bed_world(400, 1), *e = bed_world(400, 1);
    ENSURE(b && c && d && e);
    ENSURE_MSG(dem_bed_build(b, &q, NULL, NULL, &loaded, &err) == 0 && !loaded, "%s", err.msg);
    ENSURE_MSG(dem_bed_build(c, &q, NULL, NULL, &loaded, &err) == 0 && loaded, "%s", err.msg);
    ENSURE(dem_bed_load(d, &p, path, &err) == CM_WARN_STALE);
    double ha = dem_bed_height(a), hb = dem_bed_height(b);
    printf("mean surface: settled with friction 0.5 %.5f m, lubricated %.5f m (%.2f %% lower)\n", ha, hb,
           100 * (1 - hb / ha));
    ENSURE(hb < 0.97 * ha);
    ENSURE(dem_world_hash(b) == dem_world_hash(c));
    /* the settling itself, without the cache's scratch world */
    ENSURE(dem_bed_add_walls(e, &q, &err) == 0 && dem_bed_place(e, &q, &err) == 0);
    ENSURE_MSG(dem_bed_settle(e, &q, NULL, NULL, &err) == 0, "%s", err.msg);
    const double w0 = 20.0;
    int n = dem_grain_count(e);
    for (int i = 0; i < n; i++) {
        dem_grain_state g;
        dem_grain_get(e, i, &g);
        double v[3] = {0, 0, 0}, om[3] = {0, 0, w0};
        ENSURE(dem_grain_set(e, i, g.x, v, om) == 0);
    }
    for (int k = 0; k < 200; k++)
        ENSURE(dem_step(e, &err) == 0);
    double wz = 0;
    for (int i = 0; i < n; i++) {
        dem_grain_state g;
        dem_grain_get(e, i, &g);
        wz += g.w[2] / n;
    }
    printf("grains set spinning at %.1f rad/s: mean spin %.3f rad/s after 200 steps\n", w0, wz);
    ENSURE(fabs(wz) < 0.2 * w0);
    dem_world_destroy(&a);
    dem_world_destroy(&b);
    dem_world_destroy(&c);
    dem_world_destroy(&d);
    dem_world_destroy(&e);
    unlink(path);
    return 0;
}

/* A bed with no layers (or only empty ones) is refused with a reason that
 * names the layers, not as a failed allocation of 0 grains. */
static int no_layers_refused(void)
{
    dem_world *w = bed_world(100, 1);
    ENSURE(w);
    for (int variant = 0; variant < 2; variant++) {
        dem_bed_params p = small_bed(100);
        if (variant == 0)
            p.n_layers = 0;
        else
            p.layers[0].count = p.layers[1].count = 0;
        cm_error err = {0};
        int rc = dem_bed_place(w, &p, &err);
        ENSURE_MSG(rc == CM_ERR_RANGE && strstr(err.msg, "dem.bed.layers") && !strstr(err.msg, "memory"),
                   "variant %d: %d %s", variant, rc, err.msg);
    }
    dem_world_destroy(&w);
    return 0;
}

static const test_case tests[] = {
    {"settled_bed", settled_bed}, {"determinism", determinism}, {"bed_cache", bed_cache},
    {"settled_equals_cached", settled_equals_cached},
    {"other_code_refused", other_code_refused},
    {"output_files", output_files}, {"config_read", config_read}, {"settle_friction", settle_friction},
    {"no_layers_refused", no_layers_refused},
};

int main(int argc, char **argv) { return test_main(argc, argv, tests, TEST_COUNT(tests)); }
