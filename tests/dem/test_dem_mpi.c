/* The DEM over MPI ranks (dem_server/dem_mpi.h), with the real MPI: run
 * under mpirun with 1, 2 and 3 ranks (oversubscribed on two cores), a loose
 * bed of grains stirred sideways, falling and settling against a floor and
 * side walls, part of it frozen, ends in the same state, bit for bit, as one
 * process stepping the same world on its own (rank 0 runs that reference
 * first). The run must exercise the distribution: grains migrate between
 * slabs and pairs cross the slab boundaries (both counted and asserted).
 *
 *   mpirun -np N test_dem_mpi same_bits      (registered for N = 1, 2, 3)
 *   mpirun -np 3 test_dem_mpi same_bits_spring
 *   mpirun -np 1 test_dem_mpi slab_bounds    (the slab split alone)
 *
 * Every rank runs the case; the verdict is agreed (any rank failing fails
 * the run on rank 0 and the others). */
#include <mpi.h>
#include <stdlib.h>

#include "dem_bed.h"
#include "dem_mpi.h"
#include "dem_world.h"
#include "test_dem_common.h"

enum { N_GRAINS = 3000, STEPS = 1500 };

static int g_rank, g_size;
static int g_model = DEM_ROLLING_CONSTANT_TORQUE; /* same_bits_spring: the rolling spring */

/* The world of the case: on rank 0 the grains and walls, elsewhere empty. */
static int make_world(int with_grains, dem_world **out)
{
    dem_material m = test_material(5e6, 0.3, 0.3, 0.5);
    m.rolling_friction = 0.05;
    dem_world_def d = dem_world_def_default();
    d.dt = 4e-5;
    d.max_grains = N_GRAINS;
    d.gravity[2] = -9.81;
    d.rolling_model = g_model;
    dem_world *w = NULL;
    cm_error err = {0};
    ENSURE_MSG(dem_world_create(&d, 1, &m, &w, &err) == 0, "%s", err.msg);
    *out = w;
    if (!with_grains)
        return 0;
    const double L = 0.16, B = 0.04;
    ENSURE(test_two_layer_box(w, L, B, N_GRAINS) == 0);
    /* sideways stir, so that grains cross the slab boundaries */
    for (int id = 0; id < dem_grain_count(w); id++) {
        double v[3] = {0.5 * sin(1.3 * id), 0.2 * cos(1.7 * id), -0.2}, om[3] = {30 * cos(id), 0, 10 * sin(3 * id)};
        dem_grain_set(w, id, NULL, v, om);
    }
    ENSURE(dem_freeze_outside_x(w, 0.012, 1.0) > 0); /* the first 12 mm frozen */
    return 0;
}

/* Every tag exactly once over the ranks' owned grains (gathered on rank 0). */
static int tags_once(dem_world *w, long *total)
{
    int n = w->own_hi - w->own_lo, counts[64] = {0}, displ[64] = {0}, sum = 0;
    ENSURE(g_size <= 64);
    MPI_Gather(&n, 1, MPI_INT, counts, 1, MPI_INT, 0, MPI_COMM_WORLD);
    for (int r = 0; r < g_size; r++)
        displ[r] = sum, sum += counts[r];
    int *all = malloc(sizeof(int) * (size_t)(sum + 1));
    ENSURE(all);
    MPI_Gatherv(w->g.tag + w->own_lo, n, MPI_INT, all, counts, displ, MPI_INT, 0, MPI_COMM_WORLD);
    int bad = 0;
    if (g_rank == 0) {
        unsigned char *seen = calloc(N_GRAINS, 1);
        ENSURE(seen);
        for (int k = 0; k < sum; k++) {
            if (all[k] < 0 || all[k] >= N_GRAINS || seen[all[k]]++)
                bad++;
        }
        free(seen);
    }
    free(all);
    *total = sum;
    ENSURE_MSG(bad == 0, "%d owned grains with a tag out of range or seen twice", bad);
    return 0;
}

/* Ranks 1, 2 or 3 against one process: same final state hash. */
static int same_bits(void)
{
    cm_error err = {0};
    uint64_t want = 0;
    dem_world *w = NULL;
    if (g_rank == 0) { /* the reference: one process, no MPI */
        ENSURE(make_world(1, &w) == 0);
        for (int k = 0; k < STEPS; k++)
            ENSURE_MSG(dem_step(w, &err) == 0, "%s", err.msg);
        want = dem_world_hash(w);
        dem_world_destroy(&w);
    }
    ENSURE(make_world(g_rank == 0, &w) == 0);
    ENSURE_MSG(dem_mpi_attach(w, MPI_COMM_WORLD, &err) == 0, "%s", err.msg);
    long cross = 0;
    for (int k = 0; k < STEPS; k++) {
        ENSURE_MSG(dem_step(w, &err) == 0, "rank %d: %s", g_rank, err.msg);
        dem_mpi_stats s;
        dem_mpi_stats_get(w, &s);
        cross = s.cross_pairs > cross ? s.cross_pairs : cross;
    }
    uint64_t got = 0;
    ENSURE_MSG(dem_mpi_hash(w, &got, &err) == 0, "%s", err.msg);
    dem_mpi_stats s;
    dem_mpi_stats_get(w, &s);
    long total = 0;
    ENSURE(tags_once(w, &total) == 0);
    long mine[4] = {s.migrated, cross, s.springs_sent, s.scattered}, all[4];
    MPI_Allreduce(mine, all, 4, MPI_LONG, MPI_SUM, MPI_COMM_WORLD);
    dem_stats st;
    dem_world_stats(w, &st);
    printf("rank %d of %d: %d owned, %d ghosts, columns [%d, %d), %ld rebuilds; all ranks: %ld grains scattered "
           "at the first rebuild, then %ld migrations, %ld springs sent with them, %ld owned-ghost pairs (largest "
           "list per rank, summed)\n",
           g_rank, g_size, s.owned, s.ghosts, s.col_lo, s.col_hi, st.profile.rebuilds, all[3], all[0], all[2],
           all[1]);
    if (g_rank == 0)
        printf("%ld grains; state hash: one process %016llx, %d ranks %016llx\n", total, (unsigned long long)want,
               g_size, (unsigned long long)got);
    fflush(stdout);
    dem_mpi_detach(w);
    dem_world_destroy(&w);
    ENSURE(g_rank > 0 || total == N_GRAINS); /* gathered on rank 0 */
    ENSURE(st.profile.rebuilds > 5);
    if (g_size > 1) {
        ENSURE(all[3] > 0); /* rank 0's grains spread */
        ENSURE(all[0] > 0); /* grains migrated afterwards */
        ENSURE(all[1] > 0); /* pairs across slab boundaries */
        ENSURE(all[2] > 0); /* springs went with migrating grains */
    }
    if (g_rank == 0)
        ENSURE(got == want);
    return 0;
}

/* The split of cell columns into slabs: even grain counts where whole
 * columns allow, at least one column per rank, too few columns refused. */
static int slab_bounds(void)
{
    cm_error err = {0};
    int b[5];
    const long even[8] = {10, 10, 10, 10, 10, 10, 10, 10};
    ENSURE(dem_mpi_slabs(even, 8, 4, b, &err) == 0);
    ENSURE(b[0] == 0 && b[1] == 2 && b[2] == 4 && b[3] == 6 && b[4] == 8);
    const long heavy[6] = {0, 0, 100, 1, 1, 0}; /* one dense column: the others still get a column each */
    ENSURE(dem_mpi_slabs(heavy, 6, 3, b, &err) == 0);
    ENSURE(b[0] == 0 && b[3] == 6);
    for (int r = 0; r < 3; r++)
        ENSURE(b[r + 1] > b[r]);
    ENSURE(b[1] == 3 && b[2] == 4); /* the slab of the dense column ends with it; the next gets one column */
    const long empty[3] = {0, 0, 0};
    ENSURE(dem_mpi_slabs(empty, 3, 3, b, &err) == 0);
    ENSURE(b[1] == 1 && b[2] == 2);
    ENSURE(dem_mpi_slabs(even, 2, 3, b, &err) == CM_ERR_RANGE);
    ENSURE(strstr(err.msg, "3 ranks") != NULL);
    return 0;
}

/* The same with the rolling spring: its rotations travel in the springs'
 * records (migration) and come out of the same bits. */
static int same_bits_spring(void)
{
    g_model = DEM_ROLLING_SPRING;
    return same_bits();
}

static const test_case tests[] = {
    {"same_bits", same_bits}, {"same_bits_spring", same_bits_spring}, {"slab_bounds", slab_bounds}};

/* A failing rank stops all of them (the others may wait in a collective). */
int main(int argc, char **argv)
{
    MPI_Init(&argc, &argv);
    MPI_Comm_rank(MPI_COMM_WORLD, &g_rank);
    MPI_Comm_size(MPI_COMM_WORLD, &g_size);
    int failed = 0, ran = 0;
    for (int a = 1; a < argc; a++)
        for (int i = 0; i < TEST_COUNT(tests); i++)
            if (strcmp(argv[a], tests[i].name) == 0) {
                ran++;
                if (tests[i].fn() != 0) {
                    fprintf(stderr, "FAIL %s (rank %d of %d)\n", tests[i].name, g_rank, g_size);
                    MPI_Abort(MPI_COMM_WORLD, 1);
                }
            }
    MPI_Barrier(MPI_COMM_WORLD);
    if (g_rank == 0)
        printf("%s: %d case(s) run on %d rank(s)\n", ran ? "ok" : "no case named", ran, g_size);
    MPI_Finalize();
    return ran ? failed : 2;
}
