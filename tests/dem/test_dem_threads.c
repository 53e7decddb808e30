/* The step's stages and thread counts: each grain adds its pairs' forces
 * in pair-list order whatever the thread count (dem_pairs.c), so a run
 * gives the same bits with 1, 2 or 3 OpenMP threads (Box2D's determinism
 * test: the final state hashed across thread counts). */
#include <stdlib.h>
#include <string.h>

#include "dem_bed.h"
#include "dem_world.h"
#include "test_dem_common.h"
#include "timer.h"

/* A loose bed of n grains dropped on a floor (dem_bed_place), optionally
 * with every grain stirred, and optionally a triangulated plane under it
 * (the surface stage), stepped `steps` times with `threads` threads. */
enum { nx_surf = 8 }; /* the surface's squares per side */

/* FNV-1a over n bytes, continuing from h. */
static uint64_t fold(uint64_t h, const void *p, size_t n)
{
    const unsigned char *b = p;
    for (size_t k = 0; k < n; k++)
        h = (h ^ b[k]) * 1099511628211ULL;
    return h;
}

typedef struct bed_case {
    int n, steps;
    bool stirred, surface, frozen;
    int kernels;   /* enum dem_kernels: the widest build of the vectorised loops (0: the CPU's best) */
    bool spring;   /* DEM_ROLLING_SPRING instead of the constant torque */
    int two_mat;   /* two materials alike, the grains of the first (1) or of both, alternately (2); two
                      different materials, alternately (3) */
} bed_case;

/* the build of the vectorised loops that run_bed's last world ran (dem_kernels_name) */
static const char *g_kernels_ran = "";

static int run_bed(int threads, bed_case c, uint64_t *hash, dem_stats *st, double *wall_s)
{
    const int n = c.n;
    dem_material m = test_material(5e6, 0.3, 0.3, 0.5);
    m.rolling_friction = 0.05; /* the rolling torque enters the pair's torques too */
    dem_world_def d = dem_world_def_default();
    d.dt = 4e-5;
    d.max_grains = n;
    d.threads = threads;
    d.gravity[2] = -9.81;
    d.kernels = c.kernels;
    d.rolling_model = c.spring ? DEM_ROLLING_SPRING : DEM_ROLLING_CONSTANT_TORQUE;
    dem_world *w = NULL;
    cm_error err = {0};
    ENSURE_MSG(dem_world_create(&d, 1, &m, &w, &err) == 0, "%s", err.msg);
    ENSURE(test_two_layer_box(w, 0.04, 0.04, n) == 0);
    if (c.two_mat) { /* the same grains and walls in a world of two materials (alike unless two_mat is 3) */
        dem_material m2 = m;
        if (c.two_mat == 3) /* softer, rougher, rolling less */
            m2.young *= 0.5, m2.friction = 0.6, m2.rolling_friction = 0.02;
        const dem_material mats[2] = {m, m2};
        dem_world *w2 = NULL;
        ENSURE_MSG(dem_world_create(&d, 2, mats, &w2, &err) == 0, "%s", err.msg);
        ENSURE(test_box_walls(w2, 0.04, 0.04, 1) == 0);
        for (int id = 0; id < dem_grain_count(w); id++) {
            dem_grain_state gs;
            int id2;
            ENSURE(dem_grain_get(w, id, &gs) == 0);
            ENSURE_MSG(dem_grain_add(w2, gs.x, gs.radius, c.two_mat >= 2 ? id % 2 : 0, &id2, &err) == 0, "%s",
                       err.msg);
            ENSURE(id2 == id);
        }
        dem_world_destroy(&w);
        w = w2;
    }
    if (c.surface) { /* a tilted triangulated plane 5 mm above the floor */
        const int nx = nx_surf;
        const double s = 0.05 / nx;
        double *x = malloc(sizeof(double) * 3 * (nx + 1) * (nx + 1));
        int *t = malloc(sizeof(int) * 6 * nx * nx);
        ENSURE(x && t);
        test_plane_mesh(nx, nx, s, -0.005, -0.005, 0.005, x, t);
        for (int k = 0; k < (nx + 1) * (nx + 1); k++)
            x[3 * k + 2] += 0.1 * x[3 * k];
        ENSURE_MSG(dem_surface_set(w, (nx + 1) * (nx + 1), x, 2 * nx * nx, t, 0, &err) == 0, "%s", err.msg);
        free(x);
        free(t);
    }
    if (c.stirred)
        for (int id = 0; id < dem_grain_count(w); id++) {
            double v[3] = {0.3 * sin(id), 0.3 * cos(1.7 * id), -0.2}, om[3] = {50 * cos(id), 0, 20 * sin(3 * id)};
            dem_grain_set(w, id, NULL, v, om);
        }
    if (c.frozen) /* a third of the box frozen: its frozen pairs move to the end of the list, out of order */
        ENSURE(dem_freeze_outside_x(w, 0.013, 1.0) > 0);
    double t0 = cm_now();
    uint64_t hs = 1469598103934665603ULL; /* what the surface received, every step (the FEM's input) */
    for (int k = 0; k < c.steps; k++) {
        ENSURE_MSG(dem_step(w, &err) == 0, "%s", err.msg);
        if (c.surface) {
            dem_surface_total tot;
            dem_surface_totals(w, &tot);
            hs = fold(hs, dem_surface_node_forces(w), sizeof(double) * 3 * (nx_surf + 1) * (nx_surf + 1));
            double t[9] = {tot.force[0],  tot.force[1],  tot.force[2],        tot.moment[0],   tot.moment[1],
                           tot.moment[2], tot.traction_pos, tot.traction_neg, tot.max_overlap};
            hs = fold(hs, t, sizeof t);
            hs = fold(hs, &tot.contacts, sizeof tot.contacts);
        }
    }
    *wall_s = cm_now() - t0;
    *hash = dem_world_hash(w) ^ hs;
    for (int id = 0; id < dem_grain_count(w); id++) { /* and the orientations, which the state hash leaves out */
        dem_grain_state gs;
        ENSURE(dem_grain_get(w, id, &gs) == 0);
        const unsigned char *b = (const unsigned char *)gs.q;
        for (size_t k = 0; k < sizeof gs.q; k++)
            *hash = (*hash ^ b[k]) * 1099511628211ULL;
    }
    dem_world_stats(w, st);
    g_kernels_ran = dem_kernels_name(w);
    dem_world_destroy(&w);
    return 0;
}

/* One thread runs the batched pair kernel (the CPU's widest build: AVX2,
 * or AVX-512 with the rolling spring), a fourth run its portable path and
 * a fifth at most its AVX2 build; with 2 and 3 threads most pairs go
 * through the same batches, the block-crossing ones through the scalar
 * pair_force: equal hashes say all paths give the same bits. */
static int same_bits_for_thread_counts(bool stirred, bool surface, bool frozen, bool spring)
{
    uint64_t h[5];
    dem_stats st[5];
    double wall;
    bed_case c = {.n = 400, .steps = 1500, .stirred = stirred, .surface = surface, .frozen = frozen, .spring = spring};
    for (int t = 0; t < 3; t++)
        ENSURE(run_bed(t + 1, c, &h[t], &st[t], &wall) == 0);
    const char *best = g_kernels_ran;
    c.kernels = DEM_KERNELS_PORTABLE;
    ENSURE(run_bed(1, c, &h[3], &st[3], &wall) == 0);
    ENSURE(strcmp(g_kernels_ran, "portable") == 0);
    c.kernels = DEM_KERNELS_AVX2;
    ENSURE(run_bed(1, c, &h[4], &st[4], &wall) == 0);
    printf("hash with 1, 2, 3 threads: %016llx %016llx %016llx (%s), portable kernels %016llx, at most AVX2 %016llx "
           "(%s); %d grain-grain contacts, %d grain-wall, %d grain-surface, %ld rebuilds\n",
           (unsigned long long)h[0], (unsigned long long)h[1], (unsigned long long)h[2], best,
           (unsigned long long)h[3], (unsigned long long)h[4], g_kernels_ran, st[0].contacts_gg, st[0].contacts_gw,
           st[0].contacts_gs, st[0].profile.rebuilds);
    ENSURE(h[0] == h[4]);
    /* the scene must exercise what it claims: pairs in contact and rebuilds */
    ENSURE(st[0].contacts_gg > 50);
    ENSURE(st[0].profile.rebuilds > 5);
    ENSURE(!surface || st[0].contacts_gs > 0);
    ENSURE(h[0] == h[1]);
    ENSURE(h[0] == h[2]);
    ENSURE(h[0] == h[3]);
    return 0;
}

static int same_bits_1_2_3_threads(void) { return same_bits_for_thread_counts(false, false, false, false); }
static int same_bits_stirred(void) { return same_bits_for_thread_counts(true, false, false, false); }
static int same_bits_with_surface(void) { return same_bits_for_thread_counts(true, true, false, false); }
static int same_bits_with_frozen(void) { return same_bits_for_thread_counts(true, false, true, false); }

/* The rolling spring (its history in the pair rows, the batch kernel's third
 * mode, the scalar path for block-crossing pairs, the walls): the same bits
 * for every thread count and kernel path, and not the constant torque's. */
static int same_bits_rolling_spring(void)
{
    ENSURE(same_bits_for_thread_counts(true, true, false, true) == 0);
    uint64_t h[2];
    dem_stats st;
    double wall;
    for (int spring = 0; spring < 2; spring++) {
        bed_case c = {.n = 400, .steps = 1500, .stirred = true, .surface = true, .spring = spring};
        ENSURE(run_bed(1, c, &h[spring], &st, &wall) == 0);
    }
    ENSURE(h[0] != h[1]);
    return 0;
}

/* The profile counts every step and its stages add up to no more than the
 * steps' wall time measured outside the world (each stage is a part of it). */
static int profile_covers_the_step(void)
{
    uint64_t h;
    dem_stats st;
    double wall;
    bed_case c = {.n = 400, .steps = 300, .stirred = true, .surface = true};
    ENSURE(run_bed(2, c, &h, &st, &wall) == 0);
    const dem_profile *p = &st.profile;
    double sum = p->rebuild + p->surface + p->pairs + p->integrate;
    printf("300 steps in %.4f s: rebuild %.4f surface %.4f pairs %.4f integrate %.4f (sum %.4f s), %ld "
           "rebuilds\n",
           wall, p->rebuild, p->surface, p->pairs, p->integrate, sum, p->rebuilds);
    ENSURE(p->steps == 300);
    ENSURE(p->rebuilds >= 1);
    ENSURE(p->rebuild > 0 && p->surface > 0 && p->pairs > 0 && p->integrate > 0);
    ENSURE(sum <= wall);
    return 0;
}

/* Grains of two materials take the kernel's general path (each pair's
 * coefficients looked up by its grains' materials), grains of one skip the
 * lookups: with the two materials alike, both give the same bits, on one
 * thread and on two. */
static int same_bits_two_materials(void)
{
    uint64_t h[3];
    dem_stats st;
    double wall;
    bed_case c = {.n = 400, .steps = 1500, .stirred = true, .two_mat = 1};
    ENSURE(run_bed(1, c, &h[0], &st, &wall) == 0);
    c.two_mat = 2;
    ENSURE(run_bed(1, c, &h[1], &st, &wall) == 0);
    ENSURE(run_bed(2, c, &h[2], &st, &wall) == 0);
    printf("hash grains of one material %016llx, of two alike %016llx (2 threads %016llx); %d grain-grain contacts\n",
           (unsigned long long)h[0], (unsigned long long)h[1], (unsigned long long)h[2], st.contacts_gg);
    ENSURE(st.contacts_gg > 50);
    ENSURE(h[0] == h[1]);
    ENSURE(h[1] == h[2]);
    return 0;
}

/* Two different materials, alternately: every pair's coefficients looked
 * up by its two grains (a lookup by the wrong grain gives a 0–1 pair the
 * coefficients of 0–0 or 1–1): the batched kernel with its AVX2 candidate
 * test (and with the spring its AVX-512 build where the CPU has it), its
 * portable path, its AVX2 build and two threads give the same bits, and not
 * those of the two materials alike. */
static int two_materials_differ(bool spring)
{
    uint64_t h[5];
    dem_stats st;
    double wall;
    bed_case c = {.n = 400, .steps = 1500, .stirred = true, .two_mat = 3, .spring = spring};
    ENSURE(run_bed(1, c, &h[0], &st, &wall) == 0);
    const char *best = g_kernels_ran;
    ENSURE(run_bed(2, c, &h[1], &st, &wall) == 0);
    c.kernels = DEM_KERNELS_PORTABLE;
    ENSURE(run_bed(1, c, &h[2], &st, &wall) == 0);
    c.kernels = DEM_KERNELS_AVX2;
    ENSURE(run_bed(1, c, &h[4], &st, &wall) == 0);
    c.two_mat = 2, c.kernels = DEM_KERNELS_AUTO;
    ENSURE(run_bed(1, c, &h[3], &st, &wall) == 0);
    printf("hash two materials %016llx (%s; 2 threads %016llx, portable %016llx, at most AVX2 %016llx), alike "
           "%016llx; %d grain-grain contacts\n",
           (unsigned long long)h[0], best, (unsigned long long)h[1], (unsigned long long)h[2],
           (unsigned long long)h[4], (unsigned long long)h[3], st.contacts_gg);
    ENSURE(st.contacts_gg > 50);
    ENSURE(h[0] == h[1]);
    ENSURE(h[0] == h[2]);
    ENSURE(h[0] == h[4]);
    ENSURE(h[0] != h[3]);
    return 0;
}

static int same_bits_two_materials_differ(void) { return two_materials_differ(false); }
static int same_bits_two_materials_differ_spring(void) { return two_materials_differ(true); }

/* The neighbour list against brute force: a cloud of grains of three sizes
 * (cells of several grains, grains on cell and grid edges), searched with
 * the grains sorted by cell (the column ranges of dem_grid.c) and unsorted
 * (the 27-cell walk), on 1 and 2 threads: every pair within r_i + r_j +
 * skin once, no other, rows in ascending i (sorted: partners in ascending
 * slots, the walk's order). The sizes mixed, or in layers (coarse at the
 * bottom, fine on top: the cells of fine grains only, which the search
 * leaves out where they are beyond a fine grain's reach, dem_grid.c). */
static int cmp_u64(const void *a, const void *b)
{
    uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
    return (x > y) - (x < y);
}

static int neighbour_list_brute_force_of(int layered)
{
    enum { N = 6000 };
    static double pos[N][3], rad[N];
    uint32_t seed = 7u;
    for (int i = 0; i < N; i++) {
        for (int a = 0; a < 3; a++) {
            seed = seed * 1664525u + 1013904223u;
            pos[i][a] = 0.06 * (double)(seed >> 8) / 16777216.0 * (a == 2 ? 0.5 : 1.0);
        }
        const int size = layered ? (pos[i][2] < 0.01 ? 0 : pos[i][2] < 0.02 ? 1 : 2) : i % 3;
        rad[i] = size == 0 ? 1.5e-3 : (size == 1 ? 1.0e-3 : 0.6e-3);
    }
    dem_material m = test_material(5e7, 0.3, 0.5, 0.4);
    uint64_t *want = malloc((size_t)N * 64 * sizeof *want), *got = malloc((size_t)N * 64 * sizeof *got);
    ENSURE(want && got);
    long nw = 0;
    const double skin = 0.3 * 0.6e-3; /* the default: 0.3 r_min */
    for (int i = 0; i < N; i++)
        for (int j = i + 1; j < N; j++) {
            double ex = pos[i][0] - pos[j][0], ey = pos[i][1] - pos[j][1], ez = pos[i][2] - pos[j][2];
            double cut = rad[i] + skin + rad[j];
            if (ex * ex + ey * ey + ez * ez < cut * cut) {
                ENSURE(nw < (long)N * 64);
                want[nw++] = (uint64_t)i << 32 | (uint64_t)j; /* grains added in order: tag = index */
            }
        }
    qsort(want, (size_t)nw, sizeof *want, cmp_u64);
    for (int k = 0; k < 4; k++) {
        const int sorted = k & 1, threads = 1 + (k >> 1);
        dem_world_def d = dem_world_def_default();
        d.dt = 1e-7, d.max_grains = N, d.threads = threads, d.reorder_every = sorted;
        dem_world *w = NULL;
        cm_error err = {0};
        ENSURE(dem_world_create(&d, 1, &m, &w, &err) == 0);
        for (int i = 0; i < N; i++)
            ENSURE(dem_grain_add(w, pos[i], rad[i], 0, NULL, &err) == 0);
        ENSURE(dem_world_prepare(w, &err) == 0);
        ENSURE(w->skin == skin);
        ENSURE(dem_neighbour_rebuild(w, &err) == 0);
        ENSURE(w->n_pairs == nw);
        for (int p = 0; p < w->n_pairs; p++) {
            int ti = w->g.tag[w->pi[p]], tj = w->g.tag[w->pj[p]];
            got[p] = ti < tj ? (uint64_t)ti << 32 | (uint64_t)tj : (uint64_t)tj << 32 | (uint64_t)ti;
            ENSURE(p == 0 || w->pi[p] >= w->pi[p - 1]);
            ENSURE(w->pj[p] > w->pi[p]);
            ENSURE(!sorted || p == 0 || w->pi[p] > w->pi[p - 1] || w->pj[p] > w->pj[p - 1]);
        }
        qsort(got, (size_t)nw, sizeof *got, cmp_u64);
        ENSURE(memcmp(got, want, (size_t)nw * sizeof *got) == 0);
        printf("%s, %s, %d thread%s: %ld pairs as brute force\n", layered ? "layered" : "mixed",
               sorted ? "sorted" : "unsorted", threads, threads > 1 ? "s" : "", nw);
        dem_world_destroy(&w);
    }
    free(want);
    free(got);
    return 0;
}

static int neighbour_list_brute_force(void) { return neighbour_list_brute_force_of(0); }
static int neighbour_list_brute_force_layered(void) { return neighbour_list_brute_force_of(1); }

static const test_case tests[] = {{"neighbour_list_brute_force", neighbour_list_brute_force},
                                  {"neighbour_list_brute_force_layered", neighbour_list_brute_force_layered},
                                  {"same_bits_two_materials", same_bits_two_materials},
                                  {"same_bits_two_materials_differ", same_bits_two_materials_differ},
                                  {"same_bits_two_materials_differ_spring", same_bits_two_materials_differ_spring},
                                  {"same_bits_1_2_3_threads", same_bits_1_2_3_threads},
                                  {"same_bits_stirred", same_bits_stirred},
                                  {"same_bits_with_surface", same_bits_with_surface},
                                  {"same_bits_with_frozen", same_bits_with_frozen},
                                  {"same_bits_rolling_spring", same_bits_rolling_spring},
                                  {"profile_covers_the_step", profile_covers_the_step}};

int main(int argc, char **argv) { return test_main(argc, argv, tests, TEST_COUNT(tests)); }
