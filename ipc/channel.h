/* ipc internals shared by the two transports: the channel, and the hooks
 * through which ipc.c reaches the MPI transport (ipc_mpi.c).
 *
 * Private to ipc/. The ring (POSIX shared memory) lives in ipc.c. The MPI
 * transport keeps a private image of the same segment layout in each
 * process (header, surface, both rings: ch->base) and moves its regions
 * between the two images as MPI messages, so that every check ipc.c makes
 * on a header, a surface or a frame is the same code for both transports.
 * ipc_mpi.c is built only with MPI (DEMFEM_MPI) and registers its hooks
 * from ipc_mpi_start(); without them a channel named IPC_MPI_NAME is
 * refused with a message saying why. */
#ifndef IPC_CHANNEL_H
#define IPC_CHANNEL_H

#include <pthread.h>
#include <signal.h>
#include <stddef.h>
#include <stdint.h>

#include "ipc.h"
#include "segment.h"

struct ipc_channel {
    ipc_role role, peer;
    char name[256];
    ipc_segment_header *hdr;
    unsigned char *base; /* == (unsigned char *)hdr */
    size_t size;
    int linked;          /* the name still exists and we created it */
    /* Trusted copies of what the header said when we checked it. */
    uint32_t n_nodes, n_tris, slots, flags;
    ipc_layout lay;
    double dem_dt;
    uint32_t exchange_every;
    /* Sequence numbers: next frame to send and to receive. */
    uint64_t send_seq, recv_seq;
    int send_open, recv_open; /* a begin/recv without its commit/release */
    /* Waiting policy. */
    double stall_timeout, connect_timeout, spin_s;
    /* adaptive spin budgets (s, 0 < budget <= spin_s): [0] the peer's
     * frames, [1] free slots and the handshake (wait_sem) */
    double spin_budget[2];
    volatile sig_atomic_t *stop_flag;
    /* Heartbeat thread. */
    pthread_t heartbeat;
    int heartbeat_running;
    _Atomic int heartbeat_stop;
    ipc_stats stats;
    char err[512];
    /* The MPI transport's state (ipc_mpi.c); NULL on the ring. base is then
     * a private image from aligned_alloc, not a mapping. */
    struct ipc_mpi_link *mpi;
    int image; /* base is such an image (freed, not unmapped) */
};

/* What ipc.c asks of the MPI transport. Each wait honours the stop flag
 * and the peer's failure (ipc_channel_check_peer) like the ring's waits;
 * deadline_s > 0 bounds it (handshake). Statuses are IPC_* codes with the
 * message in ch->err. */
typedef struct ipc_mpi_hooks {
    /* Both sides: the link to the peer program, the peer's state messages. */
    int (*open)(ipc_channel *ch);
    /* The image is complete (ch->base, ch->lay, ch->slots): post the frame receives. */
    int (*post_receives)(ipc_channel *ch);
    /* FEM: send the header and the surface (bytes [0, ring_offset[FEM]) of
     * the image), then wait for the DEM's hello into the header's hello fields. */
    int (*publish_and_wait_hello)(ipc_channel *ch, double deadline_s);
    /* DEM: receive the header and surface: *buf (malloc'ed, the caller frees) of *bytes. */
    int (*receive_surface)(ipc_channel *ch, void **buf, size_t *bytes);
    /* DEM: send the header's hello fields; wait until the state is no longer STARTING. */
    int (*hello_and_wait_answer)(ipc_channel *ch, double deadline_s);
    /* The header's state, failed role and reason, to the peer (answer, failure, end). */
    void (*send_state)(ipc_channel *ch);
    /* Frames: a free slot for send_seq; hand slot send_seq over; the frame
     * recv_seq received (its size checked); its slot free again. */
    int (*wait_slot)(ipc_channel *ch, const char *what);
    int (*send_frame)(ipc_channel *ch);
    int (*wait_frame)(ipc_channel *ch, const char *what);
    int (*release_frame)(ipc_channel *ch);
    /* Ends the link's traffic of this channel; 0 when the image may be freed
     * (no request still refers to it), else it must be kept until exit. */
    int (*close)(ipc_channel *ch);
} ipc_mpi_hooks;

void ipc_mpi_register(const ipc_mpi_hooks *hooks);

/* Tests only (tests/ipc/ipc_rogue.c, a broken or hostile peer): sends n
 * bytes as this side's next frame message exactly as given, unchecked. */
int ipc_mpi_send_raw(ipc_channel *ch, const void *bytes, int n);

/* ipc.c's helpers, for ipc_mpi.c. */
int ipc_channel_set_err(ipc_channel *ch, int code, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
int ipc_channel_check_peer(ipc_channel *ch, const char *waiting_for);
double ipc_channel_now_s(void);

#endif
