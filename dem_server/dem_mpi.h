/* A world distributed over the ranks of an MPI communicator: slabs along x
 * (the travel direction) whose boundaries are cell boundaries of the global
 * neighbour grid, chosen from the grain counts at every neighbour rebuild;
 * ghosts (copies of the neighbouring slabs' grains within one cell) refreshed
 * every step; owned grains migrate with their springs at rebuilds.
 *
 * Same bits for any number of ranks: every rank holds its grains (owned and
 * ghosts) in the global order (cell with x slowest, tag inside a cell;
 * dem_grid.c), so its pair list is the global list restricted to the pairs
 * with an owned grain, in the same order, and each owned grain adds the same
 * pairs' forces in the same order as one process does. A pair owned–ghost is
 * computed on both ranks, from the same data and spring. Only owned grains
 * are integrated.
 *
 * Internal to dem_server (the server and the tests); MPI stays out of the
 * `dem` library: the step calls the stages through w->dist (dem_world.h).
 * Spheres, walls, gravity, frozen grains and the tire's triangle surface
 * (installed on every rank before attaching; each rank's contacts summed on
 * rank 0 in the global grain order, stage surf_gather); no shaped grains.
 * Grains are added or removed only on the world collected on rank 0
 * (dem_mpi_collect, the terrain window). */
#ifndef DEM_MPI_H
#define DEM_MPI_H

#include <mpi.h>
#include <stdint.h>

#include "dem.h"

/* Distributes the world over comm (collective). Every rank passes a world
 * made with the same definition and materials; rank 0's holds the grains
 * and walls (the others' none). Walls are broadcast, the world prepared
 * (radii, skin and the time-step check over every grain), and the grains go
 * to their slabs at the next neighbour rebuild (rank 0 steps them alone
 * until then, as a world of its own would: attaching changes no bits).
 * Needs reorder_every = 1. */
int dem_mpi_attach(dem_world *w, MPI_Comm comm, cm_error *err);
/* How the slabs are chosen at each neighbour rebuild (after attach; the
 * same bits either way, only the rank that owns a grain changes):
 *   GRAINS  even grain counts (the default)
 *   TIME    even measured busy time: a grain weighs its rank's busy
 *           seconds (the clock less its waits for the other ranks and,
 *           coupled, for fem_server) per grain-step over the steps
 *           since the previous rebuild (the rebuild itself left out),
 *           relative to the slowest rank's (smoothed over
 *           rebuilds); for ranks that share cores with other work
 *           (fem_server) or that hold the tire's contacts, whose grains
 *           cost more.
 * CM_ERR_STATE for a world not attached or an unknown mode. */
enum { DEM_MPI_BALANCE_GRAINS = 0, DEM_MPI_BALANCE_TIME = 1 };
int dem_mpi_set_balance(dem_world *w, int balance);
/* Counts `seconds` (>= 0) more busy time on this rank for the time balance,
 * as if its core had spent them on its grains since the previous rebuild: a
 * slower core without the delay (test_dem_mpi.same_bits_time). A real delay
 * makes the other ranks wait for this one, and on a machine that other
 * programs load their waits lose their cores and measure as busy too.
 * CM_ERR_STATE for a world not attached or a negative or non-finite time. */
int dem_mpi_add_busy(dem_world *w, double seconds);

/* Frees the distribution (the world keeps this rank's grains and is no
 * longer stepped in step with the others); dem_world_destroy does it too. */
void dem_mpi_detach(dem_world *w);

typedef struct dem_mpi_stats {
    int rank, ranks;
    int owned, ghosts;   /* grains integrated here, copies of the neighbours' */
    int col_lo, col_hi;  /* this rank's slab: cell columns [col_lo, col_hi) of the global grid */
    long scattered;      /* grains rank 0 sent to the others at the first rebuild */
    long migrated;       /* grains this rank sent to another at later rebuilds */
    long springs_sent;   /* contact springs sent with them */
    long cross_pairs;    /* pairs owned–ghost in the current list */
    long surf_contacts;  /* grain–surface contacts of this rank's grains, summed over the steps */
    long surf_gathers;   /* surface passes gathered */
    long surf_early;     /* of them, ended by a test among the grain pairs, before the wait after them */
    long surf_doubles;   /* rank 0: doubles of packed contacts it received, summed over the passes */
    long collects;       /* dem_mpi_collect calls (terrain window shifts) */
} dem_mpi_stats;
void dem_mpi_stats_get(const dem_world *w, dem_mpi_stats *s);

/* dem_world_hash of the whole distributed world (every rank's owned grains
 * in tag order: the value one process computes for the same state), on
 * every rank (collective). */
int dem_mpi_hash(dem_world *w, uint64_t *hash, cm_error *err);

/* The whole world on rank 0 as one process holds it, for its outputs
 * (collective): into `view` (rank 0's; a world made with the same
 * definition and materials, NULL elsewhere; the surface is installed in it
 * when the world has one) every rank's owned grains in the global order,
 * ids in tag order as one process numbers them; one process's pair list
 * (each rank's pairs whose first grain it owns, active ones of every rank
 * then the frozen-frozen ones) with its springs and its history table at
 * one process's size; the wall forces summed from every rank's wall
 * contacts in one process's order; the contact counts (a pair counted by
 * the owner of its first grain); walls, clock and counters copied; the
 * surface's contact count and largest overlap. dem_output_frame,
 * dem_output_series and dem_checkpoint_write then write what one process
 * writes for the same state. */
int dem_mpi_gather(dem_world *w, dem_world *view, cm_error *err);
/* What dem_world_stats_lean gives for the world dem_mpi_gather would gather
 * (collective; *s valid on rank 0): the kinetic energies summed along the
 * global grain order (each rank continues the sums of the rank before it
 * over its owned grains, the additions one process makes, in its order),
 * the grain, frozen and contact counts summed, the largest grain, wall and
 * surface overlaps the largest over the ranks; the clock and profile rank
 * 0's, no worst surface contact (tag -1). A series row without the whole
 * world on rank 0 (dem_output_series_row): the gather of the paper scene's
 * 33 000 grains and their springs took ~28 ms, every 1 000 steps, with the
 * other rank waiting. */
int dem_mpi_series_stats(dem_world *w, dem_stats *s, cm_error *err);

/* The terrain window over ranks (collective): collect gathers the world on
 * rank 0 as dem_mpi_gather does, into rank 0's own world, which is then
 * exactly one process's (grains, list, springs, history table, wall
 * contacts, counts), and leaves the others empty; rank 0 then changes its world as one
 * process (dem_window_update: the removal, the appended stretch and its
 * seam relaxation are one process's, so every rank agrees on them); rejoin
 * spreads it again at the next neighbour rebuild (rank 0's walls, radii and
 * tag counter to every rank). The change must ask for a neighbour rebuild,
 * as removals and additions do (CM_ERR_STATE otherwise). */
int dem_mpi_collect(dem_world *w, cm_error *err);
int dem_mpi_rejoin(dem_world *w, cm_error *err);
/* need_rebuild raised on every rank when raised on one (collective), e.g.
 * after each rank froze its grains (dem_freeze_outside_x). */
int dem_mpi_agree_rebuild(dem_world *w, cm_error *err);

/* `bytes` of buf from rank 0 to every rank of comm (collective). */
int dem_mpi_bcast(MPI_Comm comm, void *buf, size_t bytes, cm_error *err);

/* Slab bounds: ranks r gets columns [bounds[r], bounds[r + 1]) of n_cols,
 * each at least one column, split so that the grain counts (or weights)
 * count[c] are as even as whole columns allow (rank r's slab starts at the
 * column boundary where the running count is nearest r/ranks of the total).
 * CM_ERR_RANGE when there are fewer columns than ranks. */
int dem_mpi_slabs(const long *count, int n_cols, int ranks, int *bounds, cm_error *err);

#endif
