/* ipc: the lockstep exchange between dem_server and fem_server.
 *
 * One POSIX shared-memory segment per run holds a header, the interface
 * surface published once by the FEM side, and two rings of frames:
 *   DEM -> FEM : per-node interface forces         (3 n doubles)
 *   FEM -> DEM : node positions, then velocities   (6 n doubles)
 * Process-shared semaphores pace the rings. The protocol (frames, sequence,
 * error states) is documented in ipc/PROTOCOL.md so that a third program can
 * take either side's place.
 *
 * The FEM side ("surface owner") creates the segment; the DEM side attaches,
 * waiting for it if it started first. Once both are attached the name is
 * unlinked, so no segment is left in /dev/shm however either process ends.
 *
 * Nothing read from the segment is trusted: sizes, offsets, indices, sequence
 * numbers and checksums are checked before use, and every wait is bounded by
 * a check of the peer's liveness (pid and heartbeat), so a dead, stopped or
 * failed peer is noticed within about a second.
 *
 * The same protocol runs over MPI between hosts when the channel is named
 * IPC_MPI_NAME (below; ipc_mpi.h, PROTOCOL.md "The MPI transport").
 *
 * Usage, FEM side:                      DEM side:
 *   ipc_create(name, &def, &ch)           ipc_attach(name, &def, &ch)
 *   fill ipc_surface_nodes/_tris(ch)        (surface readable with the same calls)
 *   ipc_accept(ch)                          loop:
 *   loop:                                     ipc_send_begin / fill / ipc_send_commit
 *     ipc_recv (forces) ... ipc_recv_release  ... own work ...
 *     ipc_send_begin / fill / ipc_send_commit ipc_recv (positions) ... ipc_recv_release
 *   ipc_close(&ch, IPC_OK)                  ipc_close(&ch, IPC_OK)
 */
#ifndef IPC_H
#define IPC_H

#include <signal.h>
#include <stddef.h>
#include <stdint.h>

#define IPC_VERSION 1u

/* Status codes: 0 ok, negative error. */
enum {
    IPC_OK = 0,
    IPC_ERR_SYS = -1,         /* a system call failed (shm_open, mmap, sem_*) */
    IPC_ERR_ARG = -2,         /* bad argument from the caller */
    IPC_ERR_STALE = -3,       /* the name is taken by a segment from another run */
    IPC_ERR_VERSION = -4,     /* the peer speaks another protocol version */
    IPC_ERR_SIZE = -5,        /* segment sizes inconsistent, or not what was expected */
    IPC_ERR_MISMATCH = -6,    /* the handshake was refused (time step, ...) */
    IPC_ERR_PROTOCOL = -7,    /* a frame out of order, bad checksum, bad content */
    IPC_ERR_PEER_DEAD = -8,   /* the peer process is gone or stopped answering */
    IPC_ERR_PEER_FAILED = -9, /* the peer reported a failure */
    IPC_ERR_TIMEOUT = -10,    /* no peer within the connect timeout */
    IPC_ERR_INTERRUPTED = -11 /* our own stop flag was raised (SIGINT, SIGTERM) */
};

typedef enum ipc_role { IPC_ROLE_FEM = 1, IPC_ROLE_DEM = 2 } ipc_role;

/* The segment's life, in the header's state word. */
typedef enum ipc_state {
    IPC_STATE_STARTING = 1, /* created, handshake not complete */
    IPC_STATE_RUNNING = 2,  /* handshake accepted, exchanging */
    IPC_STATE_FINISHED = 3, /* ended normally */
    IPC_STATE_FAILED = 4    /* ended by an error; see the reason */
} ipc_state;

/* Frame kinds. */
enum { IPC_FRAME_DATA = 1, IPC_FRAME_FINISH = 2 };
/* Frame flags. */
enum {
    IPC_FLAG_STOP_REQUEST = 1u, /* FEM -> DEM: please end the run (send FINISH) */
    /* FEM -> DEM: both sides checkpoint the state after this exchange (the
     * FEM has written or is writing its own); DEM -> FEM: the DEM side was
     * interrupted (SIGINT/SIGTERM): please checkpoint this exchange and stop. */
    IPC_FLAG_CHECKPOINT = 2u
};

/* Named scalars carried in every frame's info[] besides the payload. */
enum {
    /* DEM -> FEM: totals of what the grains put on the surface this exchange. */
    IPC_INFO_FORCE_X = 0, IPC_INFO_FORCE_Y, IPC_INFO_FORCE_Z, /* N, sum over contacts */
    IPC_INFO_MOMENT_X, IPC_INFO_MOMENT_Y, IPC_INFO_MOMENT_Z,  /* N m, about the world origin */
    IPC_INFO_TRACTION_POS,  /* N, sum of positive travel-direction contact forces (T_H) */
    IPC_INFO_TRACTION_NEG,  /* N, sum of negative ones (T_R, <= 0) */
    IPC_INFO_CONTACTS,      /* number of grain-surface contacts */
    IPC_INFO_DEM_WORK,      /* J, interface work seen by the DEM, accumulated */
    IPC_INFO_BED_HEIGHT,    /* m, height of the undisturbed bed surface (0 if none) */
    IPC_INFO_BED_TOP,       /* m, highest grain top (z + r) before the wheel arrives (0 if none) */
    IPC_INFO_CONTACT_ENERGY, /* J, elastic energy stored in the grain-surface contacts (0 if not known) */
    /* FEM -> DEM: wheel state, world frame. */
    IPC_INFO_CENTER_X = 16, IPC_INFO_CENTER_Y, IPC_INFO_CENTER_Z, /* m */
    IPC_INFO_VEL_X, IPC_INFO_VEL_Y, IPC_INFO_VEL_Z,              /* m/s */
    IPC_INFO_OMEGA,          /* rad/s about the axle (+y) */
    IPC_INFO_ANGLE,          /* rad, accumulated rotation */
    IPC_INFO_FEM_WORK,       /* J, interface work seen by the FEM, accumulated */
    IPC_INFO_LEN = 32
};

/* Every frame starts with this head; the payload (doubles) follows it. */
typedef struct ipc_frame_head {
    uint64_t seq;      /* exchange number: 0, 1, 2, ... per direction */
    double time;       /* simulated time of the exchange [s] */
    uint32_t kind;     /* IPC_FRAME_DATA or IPC_FRAME_FINISH */
    uint32_t flags;    /* IPC_FLAG_* */
    uint64_t checksum; /* ipc_checksum of the payload (FNV-1a over 64-bit words) when the segment asks for it, else 0 */
    double info[IPC_INFO_LEN];
    uint8_t pad_[32];  /* to 320 bytes: payloads start 64-byte aligned */
} ipc_frame_head;

typedef struct ipc_channel ipc_channel;

/* FEM side: what the segment must hold. */
typedef struct ipc_create_def {
    uint32_t n_nodes;       /* interface nodes (1 .. IPC_MAX_NODES) */
    uint32_t n_tris;        /* interface triangles (1 .. IPC_MAX_TRIS) */
    uint32_t ring_slots;    /* frames per direction (1..16); 0 -> 2 */
    int checksum;           /* 1: every frame carries a payload checksum, verified on receipt */
    double exchange_dt;     /* s, the exchange interval this side expects; 0 accepts the DEM's */
    double connect_timeout; /* s to wait for the DEM to attach; 0 -> 60 */
    double stall_timeout;   /* s without a peer heartbeat before it counts as dead; 0 -> 1 */
    double spin_us;         /* most microseconds to spin before sleeping in a wait (the spin adapts
                             * below it: ipc.c wait_sem); <0 -> 0, 0 -> 50 */
    volatile sig_atomic_t *stop_flag; /* optional: waits return IPC_ERR_INTERRUPTED when *stop_flag */
    uint32_t version;       /* protocol version to announce; 0 -> IPC_VERSION (tests only) */
} ipc_create_def;

/* DEM side: what it will send and expect. */
typedef struct ipc_attach_def {
    double dt;               /* s, DEM time step */
    uint32_t exchange_every; /* DEM steps per exchange (>= 1) */
    uint32_t expect_nodes;   /* refuse a surface with another node count; 0 -> any */
    double connect_timeout;  /* s to wait for the segment to appear; 0 -> 60 */
    double stall_timeout;    /* as above */
    double spin_us;          /* as above */
    volatile sig_atomic_t *stop_flag;
    uint32_t version;        /* protocol version to announce; 0 -> IPC_VERSION (tests only) */
} ipc_attach_def;

#define IPC_MAX_NODES 4000000u
#define IPC_MAX_TRIS 8000000u

ipc_create_def ipc_default_create_def(void);
ipc_attach_def ipc_default_attach_def(void);

/* A valid segment name: "/" followed by 1..200 of [A-Za-z0-9._-]. */
int ipc_name_valid(const char *name);

/* The transport is chosen by the channel name given to ipc_create and
 * ipc_attach: a segment name ("/...") is the shared-memory ring on one
 * host; IPC_MPI_NAME is the same protocol over MPI, between the first ranks
 * of the two programs of one MPMD job (mpirun -np N dem_server ... : -np 1
 * fem_server ...), which works across hosts. It needs ipc_mpi_start()
 * (ipc_mpi.h, built with MPI) in both programs; else the name is refused.
 * Everything else (calls, frames, checks, errors) is the same. */
#define IPC_MPI_NAME "mpi"
int ipc_name_is_mpi(const char *name);

/* FEM side. Creates the segment (fails with IPC_ERR_STALE if the name exists). */
int ipc_create(const char *name, const ipc_create_def *def, ipc_channel **out, char *err, size_t errlen);
/* FEM side: after filling the surface, publish it and wait for the DEM's
 * hello; accept it (IPC_OK) or refuse a mismatch (both sides get the reason). */
int ipc_accept(ipc_channel *ch);

/* DEM side. Waits for the segment, checks it, reads the surface, says hello
 * and waits for the FEM's answer. */
int ipc_attach(const char *name, const ipc_attach_def *def, ipc_channel **out, char *err, size_t errlen);

/* The interface surface: node positions (3 n, m), node masses (n, kg: the
 * lumped mass of each node, 0 for a node that does not yield, e.g. a rim
 * node or a rigid wheel; the segment starts with all 0) and triangles (3 m
 * node indices, counter-clockwise seen from outside). Written by the FEM
 * side before ipc_accept; on the DEM side read-only and already validated. */
uint32_t ipc_surface_node_count(const ipc_channel *ch);
uint32_t ipc_surface_tri_count(const ipc_channel *ch);
double *ipc_surface_nodes(ipc_channel *ch);
double *ipc_surface_masses(ipc_channel *ch);
uint32_t *ipc_surface_tris(ipc_channel *ch);

/* Handshake results, valid on both sides after accept/attach. */
double ipc_dem_dt(const ipc_channel *ch);
uint32_t ipc_exchange_every(const ipc_channel *ch);

/* Number of doubles in the payload this side sends / receives. */
size_t ipc_send_len(const ipc_channel *ch);
size_t ipc_recv_len(const ipc_channel *ch);

/* Sending: begin waits for a free slot and returns its head and payload to
 * fill in place (no copy); commit stamps seq and checksum and hands it over. */
int ipc_send_begin(ipc_channel *ch, ipc_frame_head **head, double **payload);
int ipc_send_commit(ipc_channel *ch);

/* Receiving: waits for the next frame, checks its sequence number, kind and
 * checksum; head and payload stay valid until ipc_recv_release. */
int ipc_recv(ipc_channel *ch, const ipc_frame_head **head, const double **payload);
int ipc_recv_release(ipc_channel *ch);

/* Marks the run failed with a reason the peer will print. */
void ipc_fail(ipc_channel *ch, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

/* Ends the channel: status IPC_OK marks the segment finished, anything else
 * failed (unless a reason was already given). Safe on NULL. */
void ipc_close(ipc_channel **ch, int status);

/* The last error message of this channel (names the peer and the step). */
const char *ipc_error(const ipc_channel *ch);
const char *ipc_status_name(int status);
const char *ipc_role_name(ipc_role role);

typedef struct ipc_stats {
    uint64_t frames_sent, frames_received;
    double wait_send_s; /* time spent waiting for a free slot */
    double wait_recv_s; /* time spent waiting for the peer's frame */
} ipc_stats;
ipc_stats ipc_get_stats(const ipc_channel *ch);

/* The frame checksum: FNV-1a's 64-bit offset basis and prime, applied to the
 * payload taken as 64-bit words (h = (h ^ word) * prime, words read in the
 * machine's byte order), then to any tail bytes one by one. Not the bytewise
 * FNV-1a: 8x faster, and the same on both sides of the ring. */
uint64_t ipc_checksum(const void *data, size_t len);

#endif
