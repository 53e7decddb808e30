/* dem_server's coupled mode: the DEM side of the exchange protocol
 * (ipc/PROTOCOL.md) around a dem_world that already holds its grains. */
#ifndef DEM_COUPLED_H
#define DEM_COUPLED_H

#include <signal.h>
#include <stddef.h>
#include <stdint.h>

#include "dem.h"
#include "dem_config.h"
#include "dem_window.h"
#include "ipc.h"

/* Where the coupled loop's wall time went, per stage of an exchange
 * (dem_coupled.c), summed over the run. */
typedef struct dem_coupled_profile {
    double surface;  /* s, k x (surface moved, dem_step_surface, node forces summed), and the k - 1 grain steps between */
    double send;     /* s, the interval's mean forces packed and posted */
    double grains;   /* s, dem_step_grains of the last step: overlaps the FEM's step */
    double wait;     /* s, waiting for the FEM's reply (ipc_recv; on two ranks inside stage grains, moved here) */
    double bcast;    /* s, distributed on three ranks or more: the reply broadcast from rank 0 to the other ranks
                        (stage surf_bcast; on two ranks it rides the step's halo, dem_halo_rider) */
    double update;   /* s, the received surface installed (BVH refit), terrain window moved */
    double record;   /* s, output, checkpoints, health check, progress line */
    double bcast_bytes; /* distributed: bytes broadcast by rank 0 in stage surf_bcast, summed */
    long halo_rides; /* two ranks: exchanges whose reply rode the halo */
    long exchanges;  /* exchanges completed */
} dem_coupled_profile;

/* The DEM side distributed over ranks (dem_mpi.h; dem_main.c fills it in):
 * rank 0 alone talks to fem_server, the others follow its exchanges. */
typedef struct dem_coupled_dist {
    int rank, ranks;
    /* `bytes` of buf from rank 0 to every rank (collective) */
    int (*bcast)(void *buf, size_t bytes, void *user, cm_error *err);
    /* distributes the world once the surface is installed (collective) */
    int (*attach)(dem_world *w, void *user, cm_error *err);
    /* the whole world's dem_world_hash, on every rank (collective) */
    int (*hash)(dem_world *w, uint64_t *hash, void *user, cm_error *err);
    /* the terrain window (collective, dem_mpi.h): the world gathered on rank
     * 0 (which alone holds the window) and spread again after its update;
     * the rebuild flag agreed after every rank froze its grains */
    int (*collect)(dem_world *w, void *user, cm_error *err);
    int (*rejoin)(dem_world *w, void *user, cm_error *err);
    int (*agree_rebuild)(dem_world *w, void *user, cm_error *err);
    /* the grains owned by all ranks, on every rank (collective) */
    int (*grains)(dem_world *w, long *grains, void *user, cm_error *err);
    void *user;
} dem_coupled_dist;

typedef struct dem_coupled_def {
    const char *shm;        /* segment name chosen by the launcher */
    double dt;              /* s, DEM step (coupling.dt) */
    int exchange_every;     /* DEM steps per exchange */
    double end_time;        /* s, the run ends here (or when the FEM asks) */
    double stall_timeout;   /* s, see ipc.h */
    double connect_timeout; /* s */
    double progress_every;  /* s of wall time between progress lines; 0 = none */
    int surface_material;   /* material index of the tire surface */
    double max_overlap;     /* stop when a grain–grain/wall overlap exceeds this fraction of the radius (0 = never) */
    double max_surface_overlap; /* the same for grain–tire overlaps (0 = never) */
    double bed_height;      /* m, undisturbed bed surface, sent for sinkage (0 = none) */
    double bed_top;         /* m, highest grain top z + r, sent for placing the wheel (0 = none) */
    volatile sig_atomic_t *stop_flag;  /* raised: stop at once (waits are abandoned) */
    volatile sig_atomic_t *interrupt;  /* raised: ask fem_server for a checkpoint of the next exchange,
                                          then end the run cleanly (SIGINT/SIGTERM); may be NULL */
    dem_window *window;     /* terrain window moved with the wheel every exchange (NULL = none) */
    dem_window_def window_def; /* its keys (also the footprint check's expected sinkage without a window) */
    dem_coupled_profile *profile; /* out: where the time went (may be NULL) */
    const dem_coupled_dist *dist; /* NULL: one process. Distributed: no checkpoints yet; ch (dem_run_coupled)
                                     and window only on rank 0, NULL elsewhere */
} dem_coupled_def;

/* The coupled loop's own state, saved in checkpoints besides the world's. */
typedef struct dem_coupled_state {
    long exchange;   /* exchanges completed (the last one's number) */
    double time;     /* s, simulated time of the loop */
    double w_dem;    /* J, interface work seen by the DEM */
    int n_nodes;     /* surface nodes */
    double *x, *v;   /* 3 n_nodes: the surface as last received (m, m/s) */
} dem_coupled_state;

typedef struct dem_coupled_hooks {
    /* Called after every exchange (output, diagnostics); nonzero stops the run. */
    int (*after_exchange)(dem_world *w, void *user, long exchange, cm_error *err);
    /* Called when fem_server flags a checkpoint, after after_exchange: saves
     * the world and the loop state (NULL: checkpoints are not written). */
    int (*checkpoint)(dem_world *w, const dem_coupled_state *st, void *user, cm_error *err);
    /* Resuming: called once the surface is installed, before the first
     * exchange; fills the world and st (st->x, st->v point to the loop's
     * arrays of st->n_nodes nodes). NULL: a fresh run. */
    int (*restore)(dem_world *w, dem_coupled_state *st, void *user, cm_error *err);
    void *user;
} dem_coupled_hooks;

/* Attaches to the FEM side's segment (handshake included). Done before the
 * bed is built, so that a long settling does not look to the FEM side like a
 * peer that never came: from the handshake on it waits on our heartbeat. */
int dem_coupled_attach(const dem_coupled_def *def, ipc_channel **ch, cm_error *err);
/* Runs until def->end_time or until fem_server asks to stop, then closes ch
 * (the world holds its grains by then). Both return common/error.h codes:
 * CM_ERR_PEER when the exchange failed (ipc's code mapped, the message naming
 * the peer: exit code 3), another error of the DEM's own (the peer is told). */
int dem_run_coupled(dem_world *w, ipc_channel *ch, const dem_coupled_def *def, dem_coupled_hooks *hooks,
                    cm_error *err);

#endif
