/* The scene sections both servers read the same way: `run` (what the run is
 * and when it ends) and `coupling` (the time step and the exchange). */
#ifndef CM_RUNCFG_H
#define CM_RUNCFG_H

#include "error.h"
#include "scene.h"

typedef struct cm_run_config {
    char name[64];         /* run.name: label for logs and output files */
    double end_time;       /* run.end_time, s: simulated time at which the DEM side ends the run */
    double progress_every; /* run.progress_every, s of wall time between progress lines (default 2) */
    double checkpoint_every; /* run.checkpoint_every, s of simulated time between checkpoints (default 0:
                              only when a server is interrupted by SIGINT/SIGTERM) */
    double dt;             /* coupling.dt, s: the DEM time step */
    int exchange_every;    /* coupling.exchange_every: DEM steps per exchange (default 1) */
    double stall_timeout;  /* coupling.stall_timeout, s: a live peer silent this long counts as hung (default 10; a dead one is seen at once by its pid) */
    double connect_timeout;/* coupling.connect_timeout, s: wait this long for the peer to start (default 120) */
    double max_overlap;    /* coupling.max_overlap: stop when a grain–grain or grain–wall overlap exceeds this
                              fraction of the radius (default 0.2; 0 = never) */
    double max_surface_overlap; /* coupling.max_surface_overlap: the same for grain–tire contacts (default
                              0.5: a grain pressed into the soft tread indents it ~15-20 % of its radius
                              under ~50 N, which is the rubber's real local deformation, not a failure) */
    /* run.target = { quantity = "drawbar_pull"; tolerance = 0.05; study = "tire_small"; }: the accuracy the
     * user asks for. The launcher (bench/study/choose.py) picks the settings from the study results before
     * the servers start; the servers only check the keys. Empty quantity: no target. */
    char target_quantity[32];
    double target_tolerance; /* relative, e.g. 0.05 for 5 % */
    char target_study[64];   /* which study's results (default: the scene file's name) */
} cm_run_config;

int cm_run_config_read(cm_scene *s, cm_run_config *c, cm_error *err);

/* The exchange interval dt * exchange_every, s. */
static inline double cm_run_exchange_dt(const cm_run_config *c) { return c->dt * c->exchange_every; }

/* Exchanges between checkpoints: run.checkpoint_every rounded to whole
 * exchanges (at least one), 0 when periodic checkpoints are off. */
static inline long cm_run_checkpoint_exchanges(const cm_run_config *c)
{
    if (!(c->checkpoint_every > 0))
        return 0;
    double n = c->checkpoint_every / cm_run_exchange_dt(c) + 0.5;
    return n < 1.0 ? 1 : n > 1e15 ? (long)1e15 : (long)n;
}

#endif
