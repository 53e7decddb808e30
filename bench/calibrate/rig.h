/* rig: the protocol loop shared by the calibration rigs (plate_rig,
 * shear_rig). A rig is a program that plays the FEM side of the exchange
 * protocol (ipc/PROTOCOL.md) with rigid, driven triangle meshes: it creates
 * the segment, publishes its surface, and every exchange reads the nodal
 * forces the grains put on it and sends where its nodes go next. The rig's
 * own physics (how it moves, what it records) sits in two callbacks; the
 * arguments, signals, handshake, frame bookkeeping and error paths live here
 * once.
 *
 *   RIG --scene FILE --shm NAME [--out DIR] [--set KEY=VALUE ...]
 */
#ifndef RIG_H
#define RIG_H

#include <stdint.h>

#include "error.h"
#include "runcfg.h"
#include "scene.h"

typedef struct rig_args {
    const char *scene; /* scene file */
    const char *shm;   /* segment name, from the launcher */
    const char *out;   /* output folder (default ".") */
} rig_args;

/* Reads the command line (--set overrides go to the scene reader).
 * Returns 0, or 2 after printing the usage / the bad override. */
int rig_parse_args(const char *name, int argc, char **argv, rig_args *a);

/* Opens the scene, reads `run` and `coupling` into *rc, then calls
 * read(s, user, err) for the rig's own `fem` section and checks that no key
 * of run / coupling / fem is unknown (the terrain's sections are skipped).
 * Prints "[NAME] error: ..." and returns 1 on failure. */
int rig_read_scene(const char *name, const rig_args *a, cm_run_config *rc,
                   int (*read)(cm_scene *s, void *user, cm_error *err), void *user);

/* One exchange, as the rig sees it. */
typedef struct rig_in {
    double t;            /* s, time of the forces received */
    double t_next;       /* s, time of the state the rig sends back */
    const double *force; /* 3 n, N, the grains' forces on the nodes */
    const double *info;  /* the DEM's named scalars (IPC_INFO_*) */
} rig_in;
typedef struct rig_out {
    double *x, *v; /* 3 n each: the nodes' positions (m) and velocities (m/s) at t_next */
    double *info;  /* FEM -> DEM named scalars (IPC_INFO_CENTER_X ...), zeroed before the call */
    int stop;      /* set to 1 to ask the DEM side to end the run */
} rig_out;
/* Fill `out` from `in`. Return 0, or nonzero with err set to stop the run. */
typedef int (*rig_advance_fn)(void *user, const rig_in *in, rig_out *out, cm_error *err);
/* After the exchange's reply is sent (the DEM side computes meanwhile):
 * record what the rig measured. Return 0, or nonzero with err set. */
typedef int (*rig_record_fn)(void *user, cm_error *err);

typedef struct rig_def {
    const char *name;       /* for messages, e.g. "plate_rig" */
    int n_nodes, n_tris;
    const double *x0;       /* 3 n_nodes, m: the surface at t = 0 */
    const uint32_t *tris;   /* 3 n_tris, counter-clockwise seen from the grains */
    const double *mass;     /* n_nodes, kg (0: a node that does not yield); NULL: all 0 */
    rig_advance_fn advance;
    rig_record_fn record;   /* may be NULL */
    void *user;
} rig_def;

/* Creates the segment, waits for the DEM side and runs the exchange loop
 * until the DEM side finishes. Returns the process exit code: 0 finished,
 * 1 the rig's own failure, 3 an exchange or peer failure, 128 + signal. */
int rig_run(const rig_def *def, const cm_run_config *rc, const rig_args *a);

#endif
