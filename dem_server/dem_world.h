/* Private layout of dem_world (tests reach it through the private include
 * path; nothing outside dem_server/ should). */
#ifndef DEM_WORLD_H
#define DEM_WORLD_H

#include <stdint.h>
#include <stdlib.h>

#include "dem.h"
#include "dem_contact.h"
#include "dem_hash.h"
#include "dem_shape.h"
#include "dem_surface.h"

#ifdef _OPENMP
#include <omp.h>
#endif

/* The calling thread's number in its OpenMP team (0 without OpenMP). */
static inline int dem_thread_id(void)
{
#ifdef _OPENMP
    return omp_get_thread_num();
#else
    return 0;
#endif
}

/* The build of the vectorised loops (pairs, walls, integration) that runs
 * (enum dem_kernels, never AUTO): the widest this CPU has, at most
 * def->kernels. AVX-512 only for the pair kernel with the rolling spring
 * (the other loops then run their AVX2 builds), where the CPU has it,
 * except AMD's family 19h (Zen 4), whose 512-bit operations run as two
 * 256-bit halves: there the AVX-512 pair kernel ran 0.89-1.03x the AVX2
 * one (README, "Speed, session 19" and "session 24"). On Zen 5 (bench_dem,
 * one thread, best of six, session 26) the pair kernel with the rolling
 * spring ran 1.17-1.21x faster in eight lanes, without it 0.93x, and the
 * integration 0.7x. */
static inline int dem_kernels_of(const dem_world_def *def)
{
#if defined(__x86_64__) && defined(__GNUC__)
    int best = DEM_KERNELS_PORTABLE;
    if (__builtin_cpu_supports("avx2"))
        best = def->rolling_model == DEM_ROLLING_SPRING && __builtin_cpu_supports("avx512f") &&
                       __builtin_cpu_supports("avx512dq") && __builtin_cpu_supports("avx512vl") &&
                       !__builtin_cpu_is("amdfam19h")
                   ? DEM_KERNELS_AVX512
                   : DEM_KERNELS_AVX2;
    return def->kernels == DEM_KERNELS_AUTO || def->kernels > best ? best : def->kernels;
#else
    (void)def;
    return DEM_KERNELS_PORTABLE;
#endif
}

_Static_assert(DEM_MAX_WALLS <= 32, "dem_grains.wall_mask holds one bit per wall");

typedef struct dem_wall {
    double p[3], n[3]; /* point, unit normal (into the domain) */
    int material;
    double force[3];   /* force the grains exert on it in the last step, N */
} dem_wall;

/* Hot grain data in structure-of-arrays; index = current slot (grains are
 * re-sorted by grid cell now and then), id = stable name. */
typedef struct dem_grains {
    int n, cap;
    double *x, *y, *z;
    double *vx, *vy, *vz;
    double *wx, *wy, *wz;
    double *fx, *fy, *fz;
    double *tx, *ty, *tz;
    double *r, *inv_m, *inv_i;
    int *mat;
    void *block;       /* the doubles x .. z0 live in it, staggered (dem_world_create) */
    /* cold */
    double *q;         /* 4 per grain (w, x, y, z) */
    int *id;           /* id of the grain in slot i (dense: 0 .. n-1, renumbered on removal) */
    int *slot_of;      /* slot of grain id */
    int *tag;          /* stable name of the grain in slot i, never reused (output, contact history keys) */
    unsigned char *frozen; /* 1: not integrated, its pairs with other frozen grains skipped (dem_freeze_outside_x) */
    double *x0, *y0, *z0; /* positions at the last neighbour rebuild */
    double *wall_hist; /* wall_stride * hist_stride per grain: springs, as a pair's */
    uint32_t *wall_mask; /* bit k: the spring of wall k is non-zero (saves reading wall_hist) */
    uint32_t *wall_near; /* bit k: wall k within r + skin at the last neighbour rebuild (valid while walls_near_valid) */
    int *surf_count;   /* surface contacts of the grain in the last step */
    /* non-spherical grains (cold; spheres: shape -1, sc 1) */
    int *shape;        /* shape id, -1 = sphere (the fast path) */
    double *sc;        /* length scale of the shape */
    double *inertia;   /* 3 per grain: principal moments, kg m^2 */
    double *angmom;    /* 3 per grain: angular momentum, world frame, kg m^2/s (shaped grains only) */
} dem_grains;

/* Contact history per grain–grain pair and per grain–wall contact, in
 * doubles (dem_world.hist_stride): the tangential spring xi (3) and, with
 * DEM_ROLLING_SPRING, the rolling rotation (3) after it. Both are of i
 * relative to j: a swap of i and j negates all of them. */
enum { DEM_HIST_TANGENTIAL = 3, DEM_HIST_MAX = 6 };

/* doubles per recorded grain–wall contact (dem_world.wall_rec) */
#define DEM_WALL_REC 5

/* doubles per stored pair: F on i (3), torque on i (3), torque on j (3) */
#define DEM_PAIR_F 9

/* How threads share the sphere pairs so that every grain adds its pairs'
 * contributions in ascending pair index, as one thread does (dem_pairs.c):
 * grains in T blocks of slots (of about equal numbers of pairs), a pair owned
 * by the block of its i. Rebuilt
 * with every neighbour list; nothing in it for one thread. */
/* Blocks of slots per thread. More than one lets a free thread take another
 * block while one shares its core with fem_server, but grains sorted by cell
 * (z slowest) make slot ranges thin layers of a flat bed, and every boundary
 * adds a layer of stored cross pairs; slabs in space instead scatter each
 * block's pairs over the whole list. Measured on bench_dem's bed (idle, 2
 * threads): 4 blocks 1.0-1.4e7, 1 block 1.2e7 grain-steps/s, x slabs 0.55e7.
 * A Morton order of the grains would give compact slot ranges. */
enum { DEM_PLAN_BLOCKS_PER_THREAD = 1 };
/* A surface gather still on its way (dem_step.c) is tested between blocks
 * of DEM_PAIRS_BLOCK pairs (dem_stage_pairs_between) once
 * dem_world_def.gather_test_every has passed since the last test. */
enum { DEM_PAIRS_BLOCK = 1024 };

typedef struct dem_pair_plan {
    int valid;          /* 0: the list changed (rebuild, checkpoint): rebuilt before the next pair stage */
    int n_blocks;       /* T blocks of slots: DEM_PLAN_BLOCKS_PER_THREAD per thread, 1 for one thread */
    int one_c;          /* every grain of one material m: m * DEM_MAX_MATERIALS + m (its pairs' coefficients), else -1 */
    int *cross, cross_cap; /* pairs whose j is in another block, grouped by the block of i, ascending p */
    int *in, in_cap;    /* per block, indices into cross of the pairs whose j it holds, ascending p */
    int *slot_lo;       /* T + 1: block t holds the grain slots [slot_lo[t], slot_lo[t + 1]) */
    int *own_start;     /* T + 1: block t owns the active pairs [own_start[t], own_start[t + 1]) (its grains' rows) */
    int *cross_start, *in_start; /* T + 1 each */
    int *count;         /* 3 (T + 1): scratch of the build */
    int *claim;         /* 2 T: the blocks taken by a thread in phases A and B of the stage (dem_pairs.c) */
    int n_cross;
    double *cf;         /* DEM_PAIR_F per cross pair: force on i, torques on i and j */
    unsigned char *con; /* per cross pair: in contact this step */
    int cf_cap;
} dem_pair_plan;

/* Per-thread force buffers (thread 0 writes the grain arrays directly). */
typedef struct dem_thread_buf {
    double *f; /* 6 * cap: fx fy fz tx ty tz blocks */
    double wall_f[DEM_MAX_WALLS][3];
    int contacts;
    int wall_rec_n;    /* distributed: wall contacts this thread recorded in dem_world.wall_rec */
    int *rows;         /* the neighbour search's pairs of this thread's rows, (i, j) interleaved */
    long rows_cap;     /* pairs rows can hold (grows at rebuilds, never shrinks) */
    long rows_n;       /* pairs in rows after the search */
    double pad[8];     /* keeps two threads' wall_f apart by a cache line (no false sharing) */
} dem_thread_buf;

/* The cell grid of the neighbour list: cell size h, cells per axis; cell
 * (cx, cy, cz) spans [(base + c) h, (base + c + 1) h) along each axis, index
 * (cx n1 + cy) n2 + cz, x slowest. */
typedef struct dem_grid_dims {
    double h;
    double base[3]; /* integers: the first cell's index on the lattice */
    int n[3];
} dem_grid_dims;

/* A distributed run (dem_mpi.c, MPI kept out of this library): the stages
 * the step calls on every rank, in the same order on all of them. */
typedef struct dem_dist_ops {
    /* migration of owned grains (with their springs) to the ranks of their
     * new slabs, fresh ghosts, then dem_neighbour_rebuild on the global grid */
    int (*rebuild)(dem_world *w, cm_error *err);
    /* after integrate: the ghosts' positions and velocities from their
     * owners, and *maxd2 and *bad (non-zero: a non-finite grain somewhere)
     * over every rank; with w->rider, its bytes from rank 0 to rank 1 */
    int (*halo)(dem_world *w, double *maxd2, int *bad, cm_error *err);
    /* the ranks (dem_world_set_halo_rider: two) */
    int (*ranks)(const dem_world *w);
    /* frees the distribution's own data (dem_world_destroy calls it) */
    void (*release)(dem_world *w);
    /* after every surface pass (dem_surface_contacts): the ranks' contacts
     * on their way to rank 0 (begin), then taken as far as they have come,
     * or all of them if wait (end: *done once rank 0 has summed them, its
     * node forces and totals then the whole surface's); NULL: each rank
     * keeps its own */
    int (*surf_gather_begin)(dem_world *w, cm_error *err);
    int (*surf_gather_end)(dem_world *w, int wait, int *done, cm_error *err);
} dem_dist_ops;

struct dem_world {
    dem_world_def def;
    int n_mat;
    dem_material mat[DEM_MAX_MATERIALS];
    dem_pair_coef coef[DEM_MAX_MATERIALS][DEM_MAX_MATERIALS];
    dem_grains g;
    int n_walls;
    dem_wall walls[DEM_MAX_WALLS];
    int wall_stride; /* walls per grain in wall_hist (n_walls at the last prepare) */

    /* neighbour list: candidate pairs (slots i < j) within r_i + r_j + skin,
     * each owning a slot of the history hash for the list's lifetime */
    int n_pairs, pair_cap;
    int n_active_pairs; /* pairs [0, n_active_pairs) have an active grain; the rest (frozen-frozen) are skipped */
    int *pi, *pj;
    dem_pair_plan plan; /* how the threads share the pairs (dem_pairs.c) */
    int walls_near_valid; /* g.wall_near is current (0 after grains or walls changed: every wall is tested) */
    int *wall_list;       /* cap: the slots with a wall near or a wall spring at the last rebuild, ascending */
    int n_wall_list;      /* (with walls_near_valid: no other grain can touch a wall until the next one) */
    dem_hash hist[2];   /* pair key -> row of hist_val, current and previous list */
    double *hist_val[2]; /* springs, hist_stride per pair, in list order */
    int hist_stride;    /* DEM_HIST_TANGENTIAL, or DEM_HIST_MAX with the rolling spring */
    int hist_cur;
    /* per row of hist_val[k]: 1 when the pair's i has the lower tag. A
     * spring is the displacement of i relative to j: when a re-sort swaps a
     * pair's order it is carried over negated */
    unsigned char *hist_ori[2];
    /* per active pair of the current list: 1 when its row of hist_val holds
     * a value other than ±0 (the row a pair apart has cleared). Set from
     * the rows by the plan (dem_pair_plan_build), kept by the pair stage:
     * the candidates apart are tested on this byte instead of their row. */
    unsigned char *held;
    double skin;
    int need_rebuild;
    /* cell grid */
    int *cell_start, *cell_items, cell_cap;
    int *grain_cell;
    double *cell_rmax;  /* cell_cap: the largest radius in each cell (0 empty), the searches' reach */
    long rebuild_count;

    dem_surface *surf;
    int surf_paused; /* the steps leave the surface's contacts alone (dem_window.c's seam relaxation); its
                      * springs still move with their grains */

    dem_shape *shapes;  /* DEM_MAX_SHAPES, allocated by the first dem_shape_add */
    int n_shapes;
    int n_shaped;       /* shaped grains in the world; 0 = every loop takes the sphere path */
    double *pose;       /* polyhedral grains' world-frame hulls, pose_stride per slot (dem_shaped_pose_update) */
    int pose_stride, pose_nv;

    int n_threads;
    dem_thread_buf *tb; /* n_threads entries */
    double *scratch;    /* DEM_SCRATCH_PER_GRAIN * cap: re-sorting without allocation */
    unsigned char *sparse_held; /* cap: re-sorting the sparse history rows (dem_grains_permute) */
    int *cell_pos;      /* cell_cap: counting-sort cursor */

    int next_tag;       /* tag of the next grain added */
    int n_frozen;

    /* distributed run: NULL ops for a world of its own. The rank integrates
     * slots [own_lo, own_hi); the slots before and after are ghosts (copies
     * of the neighbouring slabs' grains within one cell), refreshed every
     * step. Without ops own_lo = 0 and own_hi = n at every rebuild. */
    const dem_dist_ops *dist;
    void *dist_ctx;
    dem_halo_rider *rider; /* NULL, or what the next halo carries (dem_world_set_halo_rider) */
    dem_grid_dims dist_grid; /* the global grid, set by dist->rebuild */
    int own_lo, own_hi;
    /* springs that arrived with migrated grains, searched after the previous
     * list's (NULL when none), each oriented lower tag first */
    const dem_hash *hist_extra;
    const double *hist_extra_val;
    long n_cross_pairs; /* pairs owned–ghost in the last list (distributed) */
    /* Active pairs whose first grain is a left ghost: a prefix of the list
     * (rows in slot order, the frozen-frozen pairs moved behind). Their
     * owner counts their contacts (contacts_gg), so that the ranks' counts
     * add up to one process's. */
    int n_ghost_rows;
    /* The grain–wall contacts of the last surface stage (distributed; NULL
     * otherwise), so that the wall forces can be summed over the ranks in
     * one process's order (dem_mpi.c): thread t records from
     * DEM_WALL_REC * wall_rec_nw * (its block's first grain - the stage's
     * first) on, per contact the grain's place among the stage's
     * wall_rec_grains grains, the wall, the force on the grain
     * (tb[t].wall_rec_n records). Owned by the distribution. */
    double *wall_rec;
    int wall_rec_nw, wall_rec_grains;

    /* a surface pass whose gather has not ended (dem_step_surface_then), and
     * what is then to be done */
    int surf_pending;
    dem_surface_ready_fn surf_ready;
    void *surf_ready_user;

    long step;
    double time;
    int prepared;
    int contacts_gg, contacts_gw;
    double r_min, r_max;
    dem_profile prof;
};


/* doubles of scratch per grain: the larger of the wall and surface history */
#define DEM_SCRATCH_PER_GRAIN                                                                         \
    (DEM_MAX_WALLS * DEM_HIST_MAX > DEM_SURF_SLOTS * DEM_SURF_SLOT_SIZE ? DEM_MAX_WALLS * DEM_HIST_MAX \
                                                                        : DEM_SURF_SLOTS * DEM_SURF_SLOT_SIZE)

_Static_assert(DEM_SCRATCH_PER_GRAIN >= 4, "scratch holds the saved quaternions of shaped grains");

/* Grows an int array to hold `need` entries (doubling from 1024); CM_OK or
 * CM_ERR_NOMEM (the array is kept). */
static inline int dem_grow_ints(int **a, int *cap, int need)
{
    if (need <= *cap)
        return CM_OK;
    int c = *cap ? *cap : 1024;
    while (c < need)
        c *= 2;
    int *b = realloc(*a, (size_t)c * sizeof *b);
    if (!b)
        return CM_ERR_NOMEM;
    *a = b, *cap = c;
    return CM_OK;
}

/* dem_grid.c: radii, skin and the time-step check before the first step
 * (also after grains or walls changed), and the neighbour list. */
int dem_world_prepare(dem_world *w, cm_error *err);
int dem_neighbour_rebuild(dem_world *w, cm_error *err);
/* Room for `need` pairs: pi, pj and both history tables (springs and
 * orientations) grow together, doubling; kept contents. CM_ERR_NOMEM. */
int dem_pairs_reserve(dem_world *w, int need);
/* The orientations of the current list's springs (hist_ori) from its pairs'
 * tags, after the list was read back (a checkpoint). */
void dem_hist_orient(dem_world *w);
/* The grid over the box [lo, hi] for cells >= h and n_grains grains (coarser
 * when a few grains far away would make it huge), and a position's cell
 * column along x: every rank computes the same from the same global box. */
void dem_grid_dims_of(const double lo[3], const double hi[3], double h, long n_grains, dem_grid_dims *gd);
int dem_grid_column(const dem_grid_dims *gd, double x);
/* dem_timestep.c: dem.dt against the time-step limits (error naming the
 * limit and the setting to change). */
int dem_check_dt(dem_world *w, cm_error *err);

/* dem_pairs.c: the plan for the current pair list, and stage "pairs"
 * (forces and torques added into the grains; returns the contacts). */
int dem_pair_plan_build(dem_world *w, cm_error *err);
int dem_stage_pairs(dem_world *w);
/* One thread, spheres only: the stage (the same bits), with between(w, user)
 * called after each block of DEM_PAIRS_BLOCK pairs while it returns > 0;
 * 0 ends the calls (the rest of the pairs walked in one go), < 0 is an
 * error, returned with the stage unfinished. *contacts as dem_stage_pairs. */
int dem_stage_pairs_between(dem_world *w, int (*between)(dem_world *w, void *user), void *user, int *contacts);
/* Sphere pairs [p0, p1) of the list in contact, by the stage's own test. */
int dem_pairs_contacts(const dem_world *w, int p0, int p1);
/* dem_world.c: moves grain data so that slot k holds the grain previously in
 * order[k] (the re-sort at a rebuild). */
void dem_grains_permute(dem_world *w, const int *order);
/* dem_world.c, distributed: a rank's share of dem_world_stats_lean, added
 * into s (the counts and clock are the caller's, dem_mpi_series_stats):
 * grains [lo, hi), their kinetic energies added to s's sums in slot order
 * and their wall overlaps; the pairs whose first grain is at slot row_lo or
 * later, their overlaps. */
void dem_world_stats_grains(const dem_world *w, int lo, int hi, dem_stats *s);
void dem_world_stats_rows(const dem_world *w, int row_lo, dem_stats *s);

#endif
