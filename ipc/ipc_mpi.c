/* ipc over MPI: the exchange protocol between the first ranks of the two
 * programs of one MPMD job, for a FEM side on another host. ipc.c keeps a
 * private image of the segment in each process (channel.h); this file
 * moves its regions between the two images as MPI messages, on an
 * intercommunicator of its own (no tag can meet the programs' own traffic):
 *   SURFACE  FEM -> DEM  once: header and surface, bytes [0, ring_offset[FEM])
 *   HELLO    DEM -> FEM  once: version, exchange_every, dt
 *   STATE    either way: the sender's state, its frames sent, the first
 *                        failure's reason (the answer to the hello, a
 *                        failure, the end)
 *   FRAME    either way: one frame, head and payload, sent from its slot
 * A slot is free again when its send completed (the ring's sem_empty); a
 * frame's receive is posted in advance into its slot (sem_full). Every wait
 * tests its request, spins for the channel's adaptive budget, then naps
 * (1 us doubling to 0.1 ms) with the stop flag and the peer's state checked
 * between naps. PROTOCOL.md, "The MPI transport". */
#include "ipc_mpi.h"

#include <math.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "channel.h"

enum { TAG_SURFACE = 1, TAG_HELLO = 2, TAG_STATE = 3, TAG_FRAME = 4, TAG_LINK = 0x1e17 };
enum { STATE_SENDS = 4 };           /* state messages in flight at most (answer, failure, end) */
#define NAP_MAX_NS 100000L          /* longest nap of a wait: 0.1 ms (a large frame's fragments wait for naps on both sides) */
#define CLOSE_WAIT_S 5.0            /* how long a normal close waits for its last sends */

typedef struct state_msg {
    uint32_t state;       /* ipc_state of the sender */
    uint32_t reserved_;
    uint64_t frames_sent; /* frames the sender has sent: a receiver takes them before a FINISHED state */
    char reason[IPC_REASON_LEN];
} state_msg;

typedef struct hello_msg {
    uint32_t version, exchange_every;
    double dt;
} hello_msg;

struct ipc_mpi_link {
    MPI_Comm comm;
    MPI_Request surface, hello; /* FEM: surface sent, hello received; DEM: hello sent */
    hello_msg hello_buf;
    MPI_Request state_in_req;
    state_msg state_in;
    MPI_Request state_out_req[STATE_SENDS];
    state_msg state_out[STATE_SENDS];
    unsigned state_next;
    int peer_finished;  /* a FINISHED state came, after peer_sent frames */
    uint64_t peer_sent;
    MPI_Request *send_req, *recv_req; /* by slot */
    uint32_t slots;
};

static MPI_Comm g_app = MPI_COMM_NULL, g_link = MPI_COMM_NULL;
static int g_programs = 1, g_app_rank, g_open;
/* Images a close could not free because a request may still read them
 * (a send the peer never took): kept reachable until exit. */
static void *g_kept[8];

static int mpi_fail(ipc_channel *ch, int mrc, const char *what)
{
    char s[MPI_MAX_ERROR_STRING];
    int n = 0, cls = 0;
    MPI_Error_string(mrc, s, &n);
    MPI_Error_class(mrc, &cls);
    if (cls == MPI_ERR_TRUNCATE)
        return ipc_channel_set_err(ch, IPC_ERR_PROTOCOL, "%s from %s: larger than the protocol allows (%s)", what,
                                   ipc_role_name(ch->peer), s);
    return ipc_channel_set_err(ch, IPC_ERR_SYS, "MPI failed for %s: %s", what, s);
}

static void nap(long ns)
{
    struct timespec ts = {0, ns};
    nanosleep(&ts, NULL);
}

static MPI_Request *slot_req(MPI_Request *reqs, const ipc_channel *ch, uint64_t seq) { return &reqs[seq % ch->slots]; }

static unsigned char *slot_at(ipc_channel *ch, ipc_role receiver, uint64_t seq)
{
    return ch->base + ch->lay.ring_offset[receiver] + (seq % ch->slots) * ch->lay.slot_size[receiver];
}

static int frame_bytes(const ipc_channel *ch, ipc_role receiver)
{
    return (int)(sizeof(ipc_frame_head) + ch->lay.payload_len[receiver] * sizeof(double));
}

/* ---- the peer's state messages ------------------------------------------------ */

/* A state message from the peer, into our copy of the header (as the peer
 * would have written it into a shared one). Before the DEM has its image
 * only a failure counts (its reason is the error). */
static int apply_state(ipc_channel *ch, state_msg *m)
{
    struct ipc_mpi_link *l = ch->mpi;
    m->reason[IPC_REASON_LEN - 1] = '\0';
    if (m->state != IPC_STATE_STARTING && m->state != IPC_STATE_RUNNING && m->state != IPC_STATE_FINISHED &&
        m->state != IPC_STATE_FAILED)
        return ipc_channel_set_err(ch, IPC_ERR_PROTOCOL, "peer %s sent an unknown state %u",
                                   ipc_role_name(ch->peer), m->state);
    ipc_segment_header *h = ch->hdr;
    if (!h)
        return m->state == IPC_STATE_FAILED ? ipc_channel_set_err(ch, IPC_ERR_PEER_FAILED, "peer %s failed: %s",
                                                                 ipc_role_name(ch->peer), m->reason)
                                            : IPC_OK;
    if (m->state == IPC_STATE_FAILED) {
        int32_t none = 0;
        if (atomic_compare_exchange_strong(&h->failed_role, &none, (int32_t)ch->peer))
            memcpy(h->fail_reason, m->reason, IPC_REASON_LEN);
        atomic_store(&h->state, IPC_STATE_FAILED);
    } else if (m->state == IPC_STATE_RUNNING) {
        uint32_t starting = IPC_STATE_STARTING;
        atomic_compare_exchange_strong(&h->state, &starting, IPC_STATE_RUNNING);
    } else if (m->state == IPC_STATE_FINISHED) {
        l->peer_finished = 1;
        l->peer_sent = m->frames_sent;
    }
    return IPC_OK;
}

/* Takes every state message that has come; a FINISHED peer counts once its
 * frames are all received (a frame and a later state message may complete
 * in either order). */
static int poll_state(ipc_channel *ch)
{
    struct ipc_mpi_link *l = ch->mpi;
    for (;;) {
        int done = 0, count = 0;
        MPI_Status st;
        int mrc = MPI_Test(&l->state_in_req, &done, &st);
        if (mrc != MPI_SUCCESS)
            return mpi_fail(ch, mrc, "a state message");
        if (!done)
            break;
        MPI_Get_count(&st, MPI_BYTE, &count);
        if (count != (int)sizeof(state_msg))
            return ipc_channel_set_err(ch, IPC_ERR_PROTOCOL, "state message of %d bytes from %s, expected %zu", count,
                                       ipc_role_name(ch->peer), sizeof(state_msg));
        state_msg m = l->state_in;
        mrc = MPI_Irecv(&l->state_in, (int)sizeof l->state_in, MPI_BYTE, 0, TAG_STATE, l->comm, &l->state_in_req);
        if (mrc != MPI_SUCCESS)
            return mpi_fail(ch, mrc, "a state message");
        int rc = apply_state(ch, &m);
        if (rc)
            return rc;
    }
    if (l->peer_finished && ch->hdr && ch->recv_seq >= l->peer_sent) {
        uint32_t running = IPC_STATE_RUNNING;
        atomic_compare_exchange_strong(&ch->hdr->state, &running, IPC_STATE_FINISHED);
    }
    return IPC_OK;
}

/* ---- waiting ------------------------------------------------------------------ */

/* Waits for *req (NULL: for the header's state to leave STARTING, the
 * hello's answer). Spins up to *budget first (adapted as the ring's
 * wait_sem adapts it), then naps, checking the stop flag and the peer
 * (ipc_channel_check_peer: its failure, its end) between naps.
 * deadline_s > 0 bounds the whole wait. */
static int wait_for(ipc_channel *ch, MPI_Request *req, MPI_Status *st, double *budget, double deadline_s,
                    const char *what, double *waited)
{
    const double t0 = ipc_channel_now_s();
    int rc = IPC_OK, done = 0, spinning = ch->spin_s > 0;
    long nap_ns = 1000;
    for (;;) {
        if (req) {
            int mrc = MPI_Test(req, &done, st ? st : MPI_STATUS_IGNORE);
            if (mrc != MPI_SUCCESS) {
                rc = mpi_fail(ch, mrc, what);
                break;
            }
        } else {
            if ((rc = poll_state(ch)))
                break;
            done = atomic_load(&ch->hdr->state) != IPC_STATE_STARTING;
        }
        if (done)
            break;
        double t = ipc_channel_now_s();
        if (spinning && t - t0 < *budget)
            continue;
        if (spinning) { /* the spin missed: a shorter one next time */
            spinning = 0;
            *budget = fmax(0.5 * *budget, fmin(1e-6, ch->spin_s));
        }
        if ((rc = poll_state(ch)) || (rc = ipc_channel_check_peer(ch, what)))
            break;
        if (deadline_s > 0 && t - t0 > deadline_s) {
            rc = ipc_channel_set_err(ch, IPC_ERR_TIMEOUT, "no %s from peer %s within %.1f s", what,
                                     ipc_role_name(ch->peer), deadline_s);
            break;
        }
        nap(nap_ns);
        nap_ns = nap_ns * 2 < NAP_MAX_NS ? nap_ns * 2 : NAP_MAX_NS;
    }
    if (done && spinning)
        *budget = fmin(2.0 * *budget, ch->spin_s);
    if (waited)
        *waited += ipc_channel_now_s() - t0;
    return rc;
}

/* A send completed within timeout_s (0: tested once)? Else it is
 * cancelled if MPI can, or freed while still active: 1, the memory it
 * sends from must then be kept. */
static int settle_send(MPI_Request *r, double timeout_s)
{
    const double t0 = ipc_channel_now_s();
    int done = 0;
    while (*r != MPI_REQUEST_NULL) {
        if (MPI_Test(r, &done, MPI_STATUS_IGNORE) != MPI_SUCCESS || done)
            break;
        if (ipc_channel_now_s() - t0 >= timeout_s)
            break;
        nap(100000);
    }
    if (*r == MPI_REQUEST_NULL || done)
        return 0;
    MPI_Cancel(r);
    for (int k = 0; k < 100 && *r != MPI_REQUEST_NULL; k++) { /* a cancel completes at once, or never */
        if (MPI_Test(r, &done, MPI_STATUS_IGNORE) != MPI_SUCCESS || done)
            return 0;
        nap(1000);
    }
    if (*r == MPI_REQUEST_NULL)
        return 0;
    MPI_Request_free(r);
    return 1;
}

/* A posted receive that will not be needed: cancelled and completed. */
static void cancel_recv(MPI_Request *r)
{
    if (*r == MPI_REQUEST_NULL)
        return;
    MPI_Cancel(r);
    MPI_Wait(r, MPI_STATUS_IGNORE);
}

/* ---- the hooks ---------------------------------------------------------------- */

static int link_open(ipc_channel *ch)
{
    if (g_link == MPI_COMM_NULL)
        return ipc_channel_set_err(ch, IPC_ERR_ARG,
                                   "channel \"%s\": this process is not one of the two programs of an MPMD job (%d "
                                   "program(s) in this job): launch mpirun -np N dem_server ... : -np 1 fem_server ...",
                                   IPC_MPI_NAME, g_programs);
    if (g_app_rank != 0)
        return ipc_channel_set_err(ch, IPC_ERR_ARG, "channel \"%s\": only a program's first rank speaks on it (this is "
                                   "rank %d)", IPC_MPI_NAME, g_app_rank);
    if (g_open)
        return ipc_channel_set_err(ch, IPC_ERR_ARG, "channel \"%s\" is already open in this process", IPC_MPI_NAME);
    struct ipc_mpi_link *l = calloc(1, sizeof *l);
    if (!l)
        return ipc_channel_set_err(ch, IPC_ERR_SYS, "out of memory");
    l->comm = g_link;
    l->surface = l->hello = l->state_in_req = MPI_REQUEST_NULL;
    for (int k = 0; k < STATE_SENDS; k++)
        l->state_out_req[k] = MPI_REQUEST_NULL;
    ch->mpi = l;
    g_open = 1;
    int mrc = MPI_Irecv(&l->state_in, (int)sizeof l->state_in, MPI_BYTE, 0, TAG_STATE, l->comm, &l->state_in_req);
    return mrc == MPI_SUCCESS ? IPC_OK : mpi_fail(ch, mrc, "a state message");
}

static int link_post_receives(ipc_channel *ch)
{
    struct ipc_mpi_link *l = ch->mpi;
    l->slots = ch->slots;
    l->send_req = malloc(ch->slots * sizeof *l->send_req);
    l->recv_req = malloc(ch->slots * sizeof *l->recv_req);
    if (!l->send_req || !l->recv_req)
        return ipc_channel_set_err(ch, IPC_ERR_SYS, "out of memory");
    for (uint32_t k = 0; k < ch->slots; k++)
        l->send_req[k] = l->recv_req[k] = MPI_REQUEST_NULL;
    for (uint32_t k = 0; k < ch->slots; k++) {
        int mrc = MPI_Irecv(slot_at(ch, ch->role, k), (int)ch->lay.slot_size[ch->role], MPI_BYTE, 0, TAG_FRAME,
                            l->comm, &l->recv_req[k]);
        if (mrc != MPI_SUCCESS)
            return mpi_fail(ch, mrc, "posting a frame receive");
    }
    return IPC_OK;
}

static int link_publish_and_wait_hello(ipc_channel *ch, double deadline_s)
{
    struct ipc_mpi_link *l = ch->mpi;
    int mrc = MPI_Isend(ch->base, (int)ch->lay.ring_offset[IPC_ROLE_FEM], MPI_BYTE, 0, TAG_SURFACE, l->comm,
                        &l->surface);
    if (mrc == MPI_SUCCESS)
        mrc = MPI_Irecv(&l->hello_buf, (int)sizeof l->hello_buf, MPI_BYTE, 0, TAG_HELLO, l->comm, &l->hello);
    if (mrc != MPI_SUCCESS)
        return mpi_fail(ch, mrc, "the surface");
    MPI_Status st;
    int rc = wait_for(ch, &l->hello, &st, &ch->spin_budget[1], deadline_s, "the DEM's hello", NULL);
    if (rc)
        return rc;
    int count = 0;
    MPI_Get_count(&st, MPI_BYTE, &count);
    if (count != (int)sizeof l->hello_buf)
        return ipc_channel_set_err(ch, IPC_ERR_PROTOCOL, "hello of %d bytes from dem, expected %zu", count,
                                   sizeof l->hello_buf);
    ch->hdr->dem_version = l->hello_buf.version; /* checked by ipc_accept as the ring's */
    ch->hdr->dem_exchange_every = l->hello_buf.exchange_every;
    ch->hdr->dem_dt = l->hello_buf.dt;
    return IPC_OK;
}

static int link_receive_surface(ipc_channel *ch, void **buf, size_t *bytes)
{
    struct ipc_mpi_link *l = ch->mpi;
    const double t0 = ipc_channel_now_s();
    MPI_Status st;
    for (;;) {
        int flag = 0, rc;
        int mrc = MPI_Iprobe(0, TAG_SURFACE, l->comm, &flag, &st);
        if (mrc != MPI_SUCCESS)
            return mpi_fail(ch, mrc, "the FEM's surface");
        if (flag)
            break;
        if ((rc = poll_state(ch)))
            return rc;
        if (ch->stop_flag && *ch->stop_flag)
            return ipc_channel_set_err(ch, IPC_ERR_INTERRUPTED, "interrupted while waiting for the interface surface");
        if (ipc_channel_now_s() - t0 > ch->connect_timeout)
            return ipc_channel_set_err(ch, IPC_ERR_TIMEOUT, "FEM peer did not publish its surface within %.1f s",
                                       ch->connect_timeout);
        nap(1000000);
    }
    int count = 0;
    MPI_Get_count(&st, MPI_BYTE, &count);
    if (count < 0)
        return ipc_channel_set_err(ch, IPC_ERR_SIZE, "the FEM's surface: no byte count");
    *buf = malloc(count > 0 ? (size_t)count : 1);
    if (!*buf)
        return ipc_channel_set_err(ch, IPC_ERR_SYS, "out of memory for the surface (%d bytes)", count);
    int mrc = MPI_Recv(*buf, count, MPI_BYTE, 0, TAG_SURFACE, l->comm, MPI_STATUS_IGNORE);
    if (mrc != MPI_SUCCESS) {
        free(*buf);
        *buf = NULL;
        return mpi_fail(ch, mrc, "the FEM's surface");
    }
    *bytes = (size_t)count;
    return IPC_OK;
}

static int link_hello_and_wait_answer(ipc_channel *ch, double deadline_s)
{
    struct ipc_mpi_link *l = ch->mpi;
    l->hello_buf = (hello_msg){.version = ch->hdr->dem_version, .exchange_every = ch->hdr->dem_exchange_every,
                               .dt = ch->hdr->dem_dt};
    int mrc = MPI_Isend(&l->hello_buf, (int)sizeof l->hello_buf, MPI_BYTE, 0, TAG_HELLO, l->comm, &l->hello);
    if (mrc != MPI_SUCCESS)
        return mpi_fail(ch, mrc, "our hello");
    return wait_for(ch, NULL, NULL, &ch->spin_budget[1], deadline_s, "the FEM's answer to our hello", NULL);
}

static void link_send_state(ipc_channel *ch)
{
    struct ipc_mpi_link *l = ch->mpi;
    const unsigned k = l->state_next++ % STATE_SENDS;
    if (settle_send(&l->state_out_req[k], 1.0)) /* a small message: gone at once unless the peer is */
        return;
    state_msg *m = &l->state_out[k];
    memset(m, 0, sizeof *m);
    m->state = atomic_load(&ch->hdr->state);
    m->frames_sent = ch->send_seq;
    if (m->state == IPC_STATE_FAILED)
        memcpy(m->reason, ch->hdr->fail_reason, IPC_REASON_LEN);
    MPI_Isend(m, (int)sizeof *m, MPI_BYTE, 0, TAG_STATE, l->comm, &l->state_out_req[k]); /* best effort */
}

static int link_wait_slot(ipc_channel *ch, const char *what)
{
    struct ipc_mpi_link *l = ch->mpi;
    return wait_for(ch, slot_req(l->send_req, ch, ch->send_seq), NULL, &ch->spin_budget[1], 0, what,
                    &ch->stats.wait_send_s);
}

static int link_send_frame(ipc_channel *ch)
{
    struct ipc_mpi_link *l = ch->mpi;
    int mrc = MPI_Isend(slot_at(ch, ch->peer, ch->send_seq), frame_bytes(ch, ch->peer), MPI_BYTE, 0, TAG_FRAME,
                        l->comm, slot_req(l->send_req, ch, ch->send_seq));
    return mrc == MPI_SUCCESS ? IPC_OK : mpi_fail(ch, mrc, "sending a frame");
}

static int link_wait_frame(ipc_channel *ch, const char *what)
{
    struct ipc_mpi_link *l = ch->mpi;
    MPI_Status st;
    int rc = wait_for(ch, slot_req(l->recv_req, ch, ch->recv_seq), &st, &ch->spin_budget[0], 0, what,
                      &ch->stats.wait_recv_s);
    if (rc)
        return rc;
    int count = 0;
    MPI_Get_count(&st, MPI_BYTE, &count);
    if (count != frame_bytes(ch, ch->role))
        return ipc_channel_set_err(ch, IPC_ERR_PROTOCOL, "frame %llu from %s has %d bytes, expected %d",
                                   (unsigned long long)ch->recv_seq, ipc_role_name(ch->peer), count,
                                   frame_bytes(ch, ch->role));
    return IPC_OK;
}

static int link_release_frame(ipc_channel *ch)
{
    struct ipc_mpi_link *l = ch->mpi;
    const uint64_t seq = ch->recv_seq; /* its slot takes frame seq + slots */
    int mrc = MPI_Irecv(slot_at(ch, ch->role, seq), (int)ch->lay.slot_size[ch->role], MPI_BYTE, 0, TAG_FRAME,
                        l->comm, slot_req(l->recv_req, ch, seq));
    return mrc == MPI_SUCCESS ? IPC_OK : mpi_fail(ch, mrc, "posting a frame receive");
}

static int link_close(ipc_channel *ch)
{
    struct ipc_mpi_link *l = ch->mpi;
    if (!l)
        return 0;
    /* A normal end waits for the last sends (the peer takes them at once);
     * after a failure the peer may never take a frame: test once. The
     * state messages (small: sent at once) carry the reason: wait for them. */
    const int failed = ch->hdr && atomic_load(&ch->hdr->state) == IPC_STATE_FAILED;
    int keep = 0;
    for (int k = 0; k < STATE_SENDS; k++)
        keep |= settle_send(&l->state_out_req[k], 1.0);
    keep |= settle_send(&l->surface, failed ? 0.0 : CLOSE_WAIT_S);
    if (ch->role == IPC_ROLE_DEM)
        keep |= settle_send(&l->hello, failed ? 0.0 : CLOSE_WAIT_S);
    else
        cancel_recv(&l->hello);
    for (uint32_t k = 0; k < l->slots; k++) {
        keep |= settle_send(&l->send_req[k], failed ? 0.0 : CLOSE_WAIT_S);
        cancel_recv(&l->recv_req[k]);
    }
    cancel_recv(&l->state_in_req);
    if (keep) {
        for (size_t k = 0; k < sizeof g_kept / sizeof g_kept[0]; k++)
            if (!g_kept[k]) {
                g_kept[k] = ch->base;
                break;
            }
    }
    free(l->send_req);
    free(l->recv_req);
    free(l);
    ch->mpi = NULL;
    g_open = 0;
    return keep;
}

int ipc_mpi_send_raw(ipc_channel *ch, const void *bytes, int n)
{
    if (!ch->mpi)
        return ipc_channel_set_err(ch, IPC_ERR_ARG, "not a channel of the MPI transport");
    int mrc = MPI_Send(bytes, n, MPI_BYTE, 0, TAG_FRAME, ch->mpi->comm);
    return mrc == MPI_SUCCESS ? IPC_OK : mpi_fail(ch, mrc, "sending raw bytes");
}

static const ipc_mpi_hooks k_hooks = {
    .open = link_open,
    .post_receives = link_post_receives,
    .publish_and_wait_hello = link_publish_and_wait_hello,
    .receive_surface = link_receive_surface,
    .hello_and_wait_answer = link_hello_and_wait_answer,
    .send_state = link_send_state,
    .wait_slot = link_wait_slot,
    .send_frame = link_send_frame,
    .wait_frame = link_wait_frame,
    .release_frame = link_release_frame,
    .close = link_close,
};

/* ---- start and stop ------------------------------------------------------------- */

int ipc_mpi_start(MPI_Comm *app, char *err, size_t errlen)
{
    *app = MPI_COMM_NULL;
    if (!getenv("OMPI_COMM_WORLD_SIZE") && !getenv("PMIX_RANK") && !getenv("PMI_RANK")) /* no launcher */
        return IPC_OK;
    int on = 0;
    MPI_Initialized(&on);
    if (!on && MPI_Init(NULL, NULL) != MPI_SUCCESS) {
        snprintf(err, errlen, "MPI_Init failed");
        return IPC_ERR_SYS;
    }
    int rank = 0, size = 1, flag = 0, *appnum = NULL;
    MPI_Comm_rank(MPI_COMM_WORLD, &rank);
    MPI_Comm_size(MPI_COMM_WORLD, &size);
    MPI_Comm_get_attr(MPI_COMM_WORLD, MPI_APPNUM, &appnum, &flag);
    int mine = flag && appnum ? *appnum : 0;
    int *apps = malloc((size_t)size * sizeof *apps);
    if (!apps) {
        snprintf(err, errlen, "out of memory for %d ranks", size);
        return IPC_ERR_SYS;
    }
    /* collective over both programs: every rank of the job calls this */
    MPI_Allgather(&mine, 1, MPI_INT, apps, 1, MPI_INT, MPI_COMM_WORLD);
    MPI_Comm_split(MPI_COMM_WORLD, mine, rank, &g_app);
    MPI_Comm_rank(g_app, &g_app_rank);
    int other = -1; /* the other program's first rank in MPI_COMM_WORLD */
    g_programs = 0;
    for (int r = 0; r < size; r++) {
        int seen = 0;
        for (int q = 0; q < r && !seen; q++)
            seen = apps[q] == apps[r];
        g_programs += !seen;
        if (other < 0 && apps[r] != mine)
            other = r;
    }
    free(apps);
    if (g_programs == 2) {
        MPI_Intercomm_create(g_app, 0, MPI_COMM_WORLD, other, TAG_LINK, &g_link);
        MPI_Comm_set_errhandler(g_link, MPI_ERRORS_RETURN); /* errors are statuses with messages here */
    }
    ipc_mpi_register(&k_hooks);
    *app = g_app;
    return IPC_OK;
}

int ipc_mpi_programs(void) { return g_programs; }

void ipc_mpi_stop(void)
{
    int on = 0, off = 0;
    MPI_Initialized(&on);
    if (!on)
        return;
    MPI_Finalized(&off);
    if (off)
        return;
    ipc_mpi_register(NULL);
    if (g_link != MPI_COMM_NULL)
        MPI_Comm_free(&g_link);
    if (g_app != MPI_COMM_NULL)
        MPI_Comm_free(&g_app);
    MPI_Finalize();
}
