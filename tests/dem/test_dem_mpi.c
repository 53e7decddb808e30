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
 *   mpirun -np 2 test_dem_mpi same_bits_time  (slabs balanced by measured
 *                                              time, rank 1 made slow)
 *   mpirun -np 1 test_dem_mpi slab_bounds    (the slab split alone)
 *   mpirun -np N test_dem_mpi surface_then   (registered for N = 2, 3: the
 *                                              surface's node forces handed
 *                                              on among the grain pairs)
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

#define SAME_ARRAY(a, b, n) (memcmp((a), (b), (size_t)(n) * sizeof *(a)) == 0)

/* The gathered view against one process's world, field by field, bit for
 * bit: everything a checkpoint holds (grains in slot order, the pair list,
 * its springs and history table, the wall forces, the contact counts) and
 * the series' totals. Rank 0. */
static int same_as_one_process(const dem_world *ref, const dem_world *v, long *wall_contacts)
{
    const dem_grains *a = &ref->g, *b = &v->g;
    const int n = a->n;
    ENSURE_MSG(b->n == n, "step %ld: %d grains gathered, one process %d", ref->step, b->n, n);
    const double *da[] = {a->x,  a->y,  a->z,  a->vx, a->vy, a->vz, a->wx, a->wy, a->wz,   a->fx,   a->fy,
                          a->fz, a->tx, a->ty, a->tz, a->r,  a->x0, a->y0, a->z0, a->inv_m, a->inv_i};
    const double *db[] = {b->x,  b->y,  b->z,  b->vx, b->vy, b->vz, b->wx, b->wy, b->wz,   b->fx,   b->fy,
                          b->fz, b->tx, b->ty, b->tz, b->r,  b->x0, b->y0, b->z0, b->inv_m, b->inv_i};
    for (int k = 0; k < (int)(sizeof da / sizeof da[0]); k++)
        ENSURE_MSG(SAME_ARRAY(da[k], db[k], n), "step %ld: grain array %d differs", ref->step, k);
    ENSURE(SAME_ARRAY(a->q, b->q, 4 * n));
    ENSURE(SAME_ARRAY(a->tag, b->tag, n) && SAME_ARRAY(a->id, b->id, n) && SAME_ARRAY(a->slot_of, b->slot_of, n));
    ENSURE(SAME_ARRAY(a->frozen, b->frozen, n) && SAME_ARRAY(a->wall_mask, b->wall_mask, n));
    ENSURE(ref->wall_stride == v->wall_stride && ref->hist_stride == v->hist_stride);
    ENSURE_MSG(SAME_ARRAY(a->wall_hist, b->wall_hist, (size_t)n * ref->wall_stride * ref->hist_stride),
               "step %ld: wall springs differ", ref->step);
    /* the pair list, its springs and history table */
    ENSURE_MSG(ref->n_pairs == v->n_pairs && ref->n_active_pairs == v->n_active_pairs,
               "step %ld: %d pairs (%d active) gathered, one process %d (%d)", ref->step, v->n_pairs,
               v->n_active_pairs, ref->n_pairs, ref->n_active_pairs);
    ENSURE_MSG(SAME_ARRAY(ref->pi, v->pi, ref->n_pairs) && SAME_ARRAY(ref->pj, v->pj, ref->n_pairs),
               "step %ld: the pair list differs", ref->step);
    ENSURE(ref->hist_cur == v->hist_cur);
    const int c = ref->hist_cur;
    ENSURE_MSG(SAME_ARRAY(ref->hist_val[c], v->hist_val[c], (size_t)ref->hist_stride * ref->n_pairs),
               "step %ld: the springs differ", ref->step);
    const dem_hash *ha = &ref->hist[c], *hb = &v->hist[c];
    ENSURE_MSG(ha->cap == hb->cap && ha->count == hb->count, "step %ld: history table %d/%d vs one process %d/%d",
               ref->step, hb->count, hb->cap, ha->count, ha->cap);
    ENSURE(SAME_ARRAY(ha->key, hb->key, ha->cap));
    for (int k = 0; k < ha->cap; k++)
        ENSURE(ha->key[k] == DEM_HASH_EMPTY || ha->row[k] == hb->row[k]);
    /* the wall forces, the contact counts, the series' totals */
    for (int k = 0; k < ref->n_walls; k++) {
        double fa[3], fb[3];
        ENSURE(dem_wall_force(ref, k, fa) == 0 && dem_wall_force(v, k, fb) == 0);
        ENSURE_MSG(SAME_ARRAY(fa, fb, 3), "step %ld: wall %d force (%.17g, %.17g, %.17g) gathered, one process "
                   "(%.17g, %.17g, %.17g)", ref->step, k, fb[0], fb[1], fb[2], fa[0], fa[1], fa[2]);
    }
    ENSURE_MSG(ref->contacts_gg == v->contacts_gg && ref->contacts_gw == v->contacts_gw,
               "step %ld: contacts %d/%d gathered, one process %d/%d", ref->step, v->contacts_gg, v->contacts_gw,
               ref->contacts_gg, ref->contacts_gw);
    dem_stats sa, sb;
    dem_world_stats(ref, &sa);
    dem_world_stats(v, &sb);
    ENSURE(SAME_ARRAY(&sa.ke_trans, &sb.ke_trans, 1) && SAME_ARRAY(&sa.ke_rot, &sb.ke_rot, 1));
    ENSURE(SAME_ARRAY(&sa.max_overlap, &sb.max_overlap, 1) && SAME_ARRAY(&sa.e_elastic, &sb.e_elastic, 1));
    ENSURE(sa.frozen == sb.frozen && sa.grains == sb.grains);
    *wall_contacts += ref->contacts_gw;
    return 0;
}

/* dem_mpi_series_stats (a series row without gathering the world) against
 * one process's dem_world_stats_lean, bit for bit: the kinetic energies
 * summed along the global grain order across the ranks (a sum of the ranks'
 * own sums would differ in the last bits), the counts and largest overlaps. */
static int same_series_totals(const dem_world *ref, const dem_stats *s)
{
    dem_stats a;
    dem_world_stats_lean(ref, &a);
    ENSURE_MSG(SAME_ARRAY(&a.ke_trans, &s->ke_trans, 1) && SAME_ARRAY(&a.ke_rot, &s->ke_rot, 1),
               "step %ld: kinetic energies %.17g / %.17g over the ranks, one process %.17g / %.17g", ref->step,
               s->ke_trans, s->ke_rot, a.ke_trans, a.ke_rot);
    ENSURE_MSG(SAME_ARRAY(&a.max_overlap, &s->max_overlap, 1) && a.max_overlap > 0.0,
               "step %ld: largest overlap %.17g over the ranks, one process %.17g", ref->step, s->max_overlap,
               a.max_overlap);
    ENSURE(a.grains == s->grains && a.frozen == s->frozen && a.contacts_gg == s->contacts_gg &&
           a.contacts_gw == s->contacts_gw && a.contacts_gs == s->contacts_gs && a.step == s->step &&
           SAME_ARRAY(&a.time, &s->time, 1) && SAME_ARRAY(&a.max_overlap_surface, &s->max_overlap_surface, 1));
    return 0;
}

enum { CHECK_EVERY = 250, CUT_STEP = 750 };
#define X_CUT 0.03 /* m: grains removed behind it at CUT_STEP, as the terrain window does */

/* The terrain window's shift at CUT_STEP (dem_coupled.c, window_update):
 * the world collected on rank 0, which must then be one process's exactly
 * (compared before the change), the grains behind X_CUT removed there and
 * in one process (the pair list cut to the survivors' pairs, their springs
 * and history table kept), spread again (dem_mpi_rejoin), and the gathered
 * view in that state compared too. */
static int cut_behind(dem_world *w, dem_world *ref, dem_world *view, long *wall_contacts)
{
    cm_error err = {0};
    ENSURE_MSG(dem_mpi_collect(w, &err) == 0, "rank %d: %s", g_rank, err.msg);
    if (ref) {
        ENSURE(same_as_one_process(ref, w, wall_contacts) == 0);
        int r_ref = 0, r = 0;
        ENSURE(dem_grains_remove_below_x(ref, X_CUT, &r_ref) == 0 && dem_grains_remove_below_x(w, X_CUT, &r) == 0);
        ENSURE(r == r_ref && r > 0);
        ENSURE(ref->n_pairs > 0 && ref->hist[ref->hist_cur].count == ref->n_pairs);
        printf("collected on rank 0 at step %d: one process's state; %d grains removed behind x = %.3f m\n",
               CUT_STEP, r, X_CUT);
    }
    ENSURE_MSG(dem_mpi_rejoin(w, &err) == 0, "rank %d: %s", g_rank, err.msg);
    ENSURE_MSG(dem_mpi_gather(w, view, &err) == 0, "rank %d: %s", g_rank, err.msg);
    if (ref)
        ENSURE(same_as_one_process(ref, view, wall_contacts) == 0);
    return 0;
}

/* Ranks 1, 2 or 3 against one process stepping the same world in step with
 * them on rank 0: same final state hash, and every CHECK_EVERY steps the
 * state gathered on rank 0 (dem_mpi_gather) is one process's, field by
 * field (same_as_one_process), also around a window-like removal at
 * CUT_STEP (cut_behind). */
static int same_bits(void)
{
    cm_error err = {0};
    uint64_t want = 0;
    dem_world *w = NULL, *ref = NULL, *view = NULL;
    if (g_rank == 0) { /* the reference: one process, no MPI */
        ENSURE(make_world(1, &ref) == 0);
        ENSURE(make_world(0, &view) == 0);
    }
    ENSURE(make_world(g_rank == 0, &w) == 0);
    ENSURE_MSG(dem_mpi_attach(w, MPI_COMM_WORLD, &err) == 0, "%s", err.msg);
    long cross = 0, checks = 0, wall_contacts = 0;
    for (int k = 0; k < STEPS; k++) {
        if (ref)
            ENSURE_MSG(dem_step(ref, &err) == 0, "%s", err.msg);
        ENSURE_MSG(dem_step(w, &err) == 0, "rank %d: %s", g_rank, err.msg);
        dem_mpi_stats s;
        dem_mpi_stats_get(w, &s);
        cross = s.cross_pairs > cross ? s.cross_pairs : cross;
        if ((k + 1) % CHECK_EVERY == 0) {
            dem_stats ss;
            ENSURE_MSG(dem_mpi_series_stats(w, &ss, &err) == 0, "rank %d: %s", g_rank, err.msg);
            ENSURE_MSG(dem_mpi_gather(w, view, &err) == 0, "rank %d: %s", g_rank, err.msg);
            if (ref) {
                ENSURE(same_as_one_process(ref, view, &wall_contacts) == 0);
                ENSURE(same_series_totals(ref, &ss) == 0);
                checks++;
            }
        }
        if (k + 1 == CUT_STEP)
            ENSURE(cut_behind(w, ref, view, &wall_contacts) == 0);
    }
    if (ref) {
        want = dem_world_hash(ref);
        printf("one process and the gathered view: the same grains, pair list, springs, history table, wall forces "
               "and contact counts at %ld checks (%ld wall contacts counted)\n", checks, wall_contacts);
        dem_world_destroy(&ref);
        dem_world_destroy(&view);
        ENSURE(checks == STEPS / CHECK_EVERY && wall_contacts > 0);
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
    ENSURE(g_rank > 0 || (total > N_GRAINS / 2 && total < N_GRAINS)); /* gathered on rank 0, after the cut */
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

/* Slabs balanced by measured time (dem_mpi_set_balance): after each step
 * rank 1 works 10 us more per grain it owns (a step costs a few us per
 * grain or less, more under the sanitizers), outside the step, where the
 * balance counts it as the rank's own work. Rank 1 must end with clearly
 * fewer grains than rank 0 (even counts under the grain balance, same_bits)
 * and the state must be one process's, bit for bit (rank 0 steps the
 * reference alone first, so that its own time is the distributed world's). */
static int same_bits_time(void)
{
    ENSURE(g_size == 2);
    cm_error err = {0};
    uint64_t want = 0, got = 0;
    dem_world *w = NULL;
    if (g_rank == 0) {
        ENSURE(make_world(1, &w) == 0);
        for (int k = 0; k < STEPS; k++)
            ENSURE_MSG(dem_step(w, &err) == 0, "%s", err.msg);
        want = dem_world_hash(w);
        dem_world_destroy(&w);
    }
    ENSURE(make_world(g_rank == 0, &w) == 0);
    ENSURE_MSG(dem_mpi_attach(w, MPI_COMM_WORLD, &err) == 0, "%s", err.msg);
    ENSURE(dem_mpi_set_balance(w, DEM_MPI_BALANCE_TIME) == 0);
    ENSURE(dem_mpi_set_balance(w, 7) == CM_ERR_STATE);
    ENSURE(dem_mpi_add_busy(w, -1.0) == CM_ERR_STATE && dem_mpi_add_busy(w, NAN) == CM_ERR_STATE);
    dem_mpi_stats s;
    for (int k = 0; k < STEPS; k++) {
        ENSURE_MSG(dem_step(w, &err) == 0, "rank %d: %s", g_rank, err.msg);
        dem_mpi_stats_get(w, &s);
        /* rank 1's core as if 10 us per grain slower: counted, not spent,
         * so that no rank waits for it and a loaded machine measures the
         * same (dem_mpi_add_busy) */
        ENSURE(dem_mpi_add_busy(w, g_rank == 1 ? 10e-6 * s.owned : 0.0) == CM_OK);
    }
    ENSURE_MSG(dem_mpi_hash(w, &got, &err) == 0, "%s", err.msg);
    int owned[2] = {0, 0};
    MPI_Allgather(&s.owned, 1, MPI_INT, owned, 1, MPI_INT, MPI_COMM_WORLD);
    dem_stats st;
    dem_world_stats(w, &st);
    if (g_rank == 0)
        printf("time balance, %ld rebuilds: rank 0 owns %d grains, the slow rank 1 %d; state hash: one process "
               "%016llx, 2 ranks %016llx\n", st.profile.rebuilds, owned[0], owned[1], (unsigned long long)want,
               (unsigned long long)got);
    dem_mpi_detach(w);
    dem_world_destroy(&w);
    ENSURE(st.profile.rebuilds > 5);
    ENSURE(owned[1] < 0.75 * owned[0]);
    ENSURE(g_rank > 0 || got == want);
    return 0;
}

/* The split of cell columns into slabs: even grain counts where whole
 * columns allow (the boundary nearest the even share, on either side of
 * it), at least one column per rank, too few columns refused. */
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
    long most = 0; /* the dense column alone is the heaviest slab: 100 */
    for (int r = 0; r < 3; r++) {
        long load = 0;
        for (int c = b[r]; c < b[r + 1]; c++)
            load += heavy[c];
        most = load > most ? load : most;
    }
    ENSURE(most == 100);
    /* 40 | 30 30 (40 against 60) is nearer an even split than 40 30 | 30
     * (70 against 30): the boundary before the column that reaches half */
    const long front[3] = {40, 30, 30};
    ENSURE(dem_mpi_slabs(front, 3, 2, b, &err) == 0);
    ENSURE(b[0] == 0 && b[1] == 1 && b[2] == 3);
    const long back[3] = {30, 30, 40}; /* 30 30 | 40 (60 against 40) before 30 | 30 40 (30 against 70) */
    ENSURE(dem_mpi_slabs(back, 3, 2, b, &err) == 0);
    ENSURE(b[1] == 2);
    const long empty[3] = {0, 0, 0};
    ENSURE(dem_mpi_slabs(empty, 3, 3, b, &err) == 0);
    ENSURE(b[1] == 1 && b[2] == 2);
    ENSURE(dem_mpi_slabs(even, 2, 3, b, &err) == CM_ERR_RANGE);
    ENSURE(strstr(err.msg, "3 ranks") != NULL);
    return 0;
}

/* dem_step_surface_then: the grains fall onto a triangulated floor (a
 * surface in place of the floor wall) spanning every slab. One process
 * hands each pass's node forces and totals on at once; distributed, they
 * are handed on among the next dem_step_grains' pairs, once the ranks'
 * contacts are summed on rank 0 (tested after every block of pairs here,
 * so that most passes end there rather than in the wait after them), and
 * there they must be one process's, bit for bit, at every step; so must
 * the final state. Every rank must see its callback exactly once per step,
 * and surface contacts must come from more than one rank. */
enum { FLOOR_NX = 16, FLOOR_NY = 4, FLOOR_STEPS = 600 };

typedef struct floor_rec {
    dem_world *w;
    int calls, in_grains, during; /* callbacks, those inside dem_step_grains; during: in dem_step_grains now */
    uint64_t *hash;               /* per step: the node forces' and totals' bits (rank 0) */
    long step;
} floor_rec;

static uint64_t fnv(uint64_t h, const void *p, size_t n)
{
    const unsigned char *b = p;
    for (size_t k = 0; k < n; k++)
        h = (h ^ b[k]) * 1099511628211ULL;
    return h;
}

static int floor_ready(dem_world *w, void *user, cm_error *err)
{
    (void)err;
    floor_rec *r = user;
    const int nn = (FLOOR_NX + 1) * (FLOOR_NY + 1);
    dem_surface_total t;
    dem_surface_totals(w, &t);
    double tot[4] = {t.force[0], t.force[1], t.force[2], (double)t.contacts};
    r->hash[r->step] = fnv(fnv(14695981039346656037ULL, dem_surface_node_forces(w), 3 * (size_t)nn * sizeof(double)),
                           tot, sizeof tot);
    r->calls++;
    r->in_grains += r->during;
    return CM_OK;
}

static int floor_world(int with_grains, dem_world **out)
{
    dem_material m = test_material(5e6, 0.3, 0.3, 0.5);
    dem_world_def d = dem_world_def_default();
    d.dt = 4e-5;
    d.max_grains = N_GRAINS;
    d.gravity[2] = -9.81;
    d.gather_test_every = 0.0;
    dem_world *w = NULL;
    cm_error err = {0};
    ENSURE_MSG(dem_world_create(&d, 1, &m, &w, &err) == 0, "%s", err.msg);
    *out = w;
    const double L = 0.16, B = 0.04;
    ENSURE(test_box_walls(w, L, B, 0) == 0); /* the floor is the surface */
    double x[3 * (FLOOR_NX + 1) * (FLOOR_NY + 1)];
    int tris[3 * 2 * FLOOR_NX * FLOOR_NY], nt = 0;
    for (int j = 0; j <= FLOOR_NY; j++)
        for (int i = 0; i <= FLOOR_NX; i++) {
            double *p = x + 3 * (j * (FLOOR_NX + 1) + i);
            p[0] = L * i / FLOOR_NX, p[1] = B * j / FLOOR_NY, p[2] = 0.0;
        }
    for (int j = 0; j < FLOOR_NY; j++)
        for (int i = 0; i < FLOOR_NX; i++) {
            const int a = j * (FLOOR_NX + 1) + i, b = a + 1, c = a + FLOOR_NX + 1, e = c + 1;
            const int t2[6] = {a, b, e, a, e, c};
            memcpy(tris + 3 * nt, t2, sizeof t2);
            nt += 2;
        }
    const int nn = (FLOOR_NX + 1) * (FLOOR_NY + 1);
    ENSURE_MSG(dem_surface_set(w, nn, x, nt, tris, 0, &err) == 0, "%s", err.msg);
    if (!with_grains)
        return 0;
    dem_bed_params p = dem_bed_params_default();
    double lo[3] = {0, 0, 0}, hi[3] = {L, B, 0.2};
    memcpy(p.box_min, lo, sizeof lo);
    memcpy(p.box_max, hi, sizeof hi);
    p.n_layers = 1;
    p.layers[0].count = N_GRAINS / 2;
    p.layers[0].radius[0] = 2.2e-3, p.layers[0].radius[1] = 2.6e-3;
    ENSURE_MSG(dem_bed_place(w, &p, &err) == 0, "%s", err.msg);
    return 0;
}

/* FLOOR_STEPS steps through dem_step_surface_then; r->hash filled. */
static int floor_steps(dem_world *w, floor_rec *r)
{
    cm_error err = {0};
    for (r->step = 0; r->step < FLOOR_STEPS; r->step++) {
        ENSURE_MSG(dem_step_surface_then(w, floor_ready, r, &err) == 0, "rank %d: %s", g_rank, err.msg);
        r->during = 1;
        ENSURE_MSG(dem_step_grains(w, &err) == 0, "rank %d: %s", g_rank, err.msg);
        r->during = 0;
        ENSURE_MSG(r->calls == r->step + 1, "rank %d, step %ld: %d callbacks", g_rank, r->step, r->calls);
    }
    return 0;
}

static int surface_then(void)
{
    ENSURE(g_size > 1);
    cm_error err = {0};
    uint64_t want = 0, got = 0, *ref_hash = calloc(FLOOR_STEPS, sizeof *ref_hash),
             *hash = calloc(FLOOR_STEPS, sizeof *hash);
    ENSURE(ref_hash && hash);
    dem_world *w = NULL;
    if (g_rank == 0) {
        floor_rec r = {.hash = ref_hash};
        ENSURE(floor_world(1, &w) == 0);
        ENSURE(floor_steps(w, &r) == 0);
        ENSURE(r.in_grains == 0); /* one process: at once */
        want = dem_world_hash(w);
        dem_world_destroy(&w);
    }
    floor_rec r = {.hash = hash};
    ENSURE(floor_world(g_rank == 0, &w) == 0);
    ENSURE_MSG(dem_mpi_attach(w, MPI_COMM_WORLD, &err) == 0, "%s", err.msg);
    ENSURE(floor_steps(w, &r) == 0);
    ENSURE_MSG(dem_mpi_hash(w, &got, &err) == 0, "%s", err.msg);
    dem_mpi_stats s;
    dem_mpi_stats_get(w, &s);
    int touching = s.surf_contacts > 0, ranks_touching = 0, same = 0;
    long early = 0;
    MPI_Allreduce(&touching, &ranks_touching, 1, MPI_INT, MPI_SUM, MPI_COMM_WORLD);
    MPI_Allreduce(&s.surf_early, &early, 1, MPI_LONG, MPI_SUM, MPI_COMM_WORLD);
    if (g_rank == 0) {
        for (int k = 0; k < FLOOR_STEPS; k++)
            same += hash[k] == ref_hash[k];
        printf("floor: %d of %d passes' node forces as one process's; callbacks in the grain step %d of %d; "
               "gathers ended among the pairs %ld (all ranks); %d ranks with surface contacts (%ld here); state "
               "hash: one process %016llx, %d ranks %016llx\n",
               same, FLOOR_STEPS, r.in_grains, r.calls, early, ranks_touching, s.surf_contacts,
               (unsigned long long)want, g_size, (unsigned long long)got);
    }
    fflush(stdout);
    dem_mpi_detach(w);
    dem_world_destroy(&w);
    free(ref_hash);
    free(hash);
    ENSURE(r.in_grains == FLOOR_STEPS); /* distributed: handed on among the pairs (or after them) */
    ENSURE(early > 0);                   /* and the tests among the pairs did end some */
    ENSURE(ranks_touching > 1);
    ENSURE(g_rank > 0 || (same == FLOOR_STEPS && got == want));
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
    {"same_bits", same_bits},
    {"same_bits_spring", same_bits_spring},
    {"same_bits_time", same_bits_time},
    {"slab_bounds", slab_bounds},
    {"surface_then", surface_then}};

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
