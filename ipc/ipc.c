/* ipc: shared-memory lockstep exchange between the DEM and FEM servers.
 * See ipc.h for the interface and PROTOCOL.md for the wire format. */
#define _GNU_SOURCE /* sem_clockwait */
#include "ipc.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "channel.h"
#include "segment.h"

/* The MPI transport's hooks (ipc_mpi.c), registered by ipc_mpi_start(); NULL
 * when it is not built or not started. */
static const ipc_mpi_hooks *g_mpi;

void ipc_mpi_register(const ipc_mpi_hooks *hooks) { g_mpi = hooks; }


/* ---- small helpers -------------------------------------------------------- */

static uint64_t now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000000000ull + (uint64_t)ts.tv_nsec;
}

static double now_s(void) { return 1e-9 * (double)now_ns(); }

static inline void cpu_relax(void)
{
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_pause();
#endif
}

static uint64_t align_up(uint64_t x, uint64_t a) { return (x + a - 1) / a * a; }

/* The channel's error message; returns code (channel.h: ipc_mpi.c's too). */
int ipc_channel_set_err(ipc_channel *ch, int code, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(ch->err, sizeof ch->err, fmt, ap);
    va_end(ap);
    return code;
}
#define set_err ipc_channel_set_err

const char *ipc_role_name(ipc_role role)
{
    return role == IPC_ROLE_FEM ? "fem" : role == IPC_ROLE_DEM ? "dem" : "?";
}

const char *ipc_status_name(int status)
{
    switch (status) {
    case IPC_OK: return "ok";
    case IPC_ERR_SYS: return "system error";
    case IPC_ERR_ARG: return "bad argument";
    case IPC_ERR_STALE: return "stale segment";
    case IPC_ERR_VERSION: return "protocol version mismatch";
    case IPC_ERR_SIZE: return "size mismatch";
    case IPC_ERR_MISMATCH: return "handshake refused";
    case IPC_ERR_PROTOCOL: return "protocol violation";
    case IPC_ERR_PEER_DEAD: return "peer dead";
    case IPC_ERR_PEER_FAILED: return "peer failed";
    case IPC_ERR_TIMEOUT: return "timeout";
    case IPC_ERR_INTERRUPTED: return "interrupted";
    default: return "unknown status";
    }
}

const char *ipc_error(const ipc_channel *ch) { return ch ? ch->err : "no channel"; }

ipc_stats ipc_get_stats(const ipc_channel *ch) { return ch->stats; }

uint64_t ipc_checksum(const void *data, size_t len)
{
    /* FNV-1a over 64-bit words (8x faster than bytewise), then the tail bytes. */
    const unsigned char *p = data;
    uint64_t h = 0xcbf29ce484222325ull;
    size_t i = 0;
    for (; i + 8 <= len; i += 8) {
        uint64_t w;
        memcpy(&w, p + i, 8);
        h = (h ^ w) * 0x100000001b3ull;
    }
    for (; i < len; i++)
        h = (h ^ p[i]) * 0x100000001b3ull;
    return h;
}

int ipc_name_valid(const char *name)
{
    if (!name || name[0] != '/')
        return 0;
    size_t n = strlen(name);
    if (n < 2 || n > 201)
        return 0;
    for (size_t i = 1; i < n; i++) {
        char c = name[i];
        int ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '.' ||
                 c == '_' || c == '-';
        if (!ok)
            return 0;
    }
    return 1;
}

ipc_create_def ipc_default_create_def(void)
{
    ipc_create_def d;
    memset(&d, 0, sizeof d);
    d.ring_slots = 2;
    d.connect_timeout = 60.0;
    d.stall_timeout = 1.0;
    d.spin_us = 50.0;
    return d;
}

ipc_attach_def ipc_default_attach_def(void)
{
    ipc_attach_def d;
    memset(&d, 0, sizeof d);
    d.exchange_every = 1;
    d.connect_timeout = 60.0;
    d.stall_timeout = 1.0;
    d.spin_us = 50.0;
    return d;
}

int ipc_layout_compute(uint32_t n_nodes, uint32_t n_tris, uint32_t slots, ipc_layout *lay)
{
    if (n_nodes < 1 || n_nodes > IPC_MAX_NODES || n_tris < 1 || n_tris > IPC_MAX_TRIS || slots < 1 || slots > 16)
        return -1;
    memset(lay, 0, sizeof *lay);
    uint64_t off = align_up(sizeof(ipc_segment_header), IPC_PAGE);
    lay->nodes_offset = off;
    off = align_up(off + 3ull * n_nodes * sizeof(double), IPC_ALIGN);
    lay->masses_offset = off;
    off = align_up(off + 1ull * n_nodes * sizeof(double), IPC_ALIGN);
    lay->tris_offset = off;
    off = align_up(off + 3ull * n_tris * sizeof(uint32_t), IPC_PAGE);
    lay->payload_len[IPC_ROLE_FEM] = 3ull * n_nodes; /* forces */
    lay->payload_len[IPC_ROLE_DEM] = 6ull * n_nodes; /* positions, velocities */
    for (int r = IPC_ROLE_FEM; r <= IPC_ROLE_DEM; r++) {
        lay->slot_size[r] = align_up(sizeof(ipc_frame_head) + lay->payload_len[r] * sizeof(double), IPC_ALIGN);
        lay->ring_offset[r] = off;
        off = align_up(off + lay->slot_size[r] * slots, IPC_PAGE);
    }
    lay->segment_size = off;
    return 0;
}

/* ---- heartbeat and liveness ---------------------------------------------- */

static void *heartbeat_main(void *arg)
{
    ipc_channel *ch = arg;
    while (!atomic_load(&ch->heartbeat_stop)) {
        atomic_store(&ch->hdr->heartbeat_ns[ch->role], now_ns());
        struct timespec ts = {0, 50 * 1000 * 1000};
        nanosleep(&ts, NULL);
    }
    return NULL;
}

static int start_heartbeat(ipc_channel *ch)
{
    atomic_store(&ch->hdr->heartbeat_ns[ch->role], now_ns());
    if (pthread_create(&ch->heartbeat, NULL, heartbeat_main, ch) != 0)
        return set_err(ch, IPC_ERR_SYS, "cannot start heartbeat thread: %s", strerror(errno));
    ch->heartbeat_running = 1;
    return IPC_OK;
}

static void record_failure(ipc_channel *ch, const char *reason)
{
    int32_t none = 0;
    /* The first failure wins: its reason is the one both sides print. */
    if (atomic_compare_exchange_strong(&ch->hdr->failed_role, &none, (int32_t)ch->role))
    {
        /* Truncation is fine: the reason is for people. */
        size_t n = strnlen(reason, IPC_REASON_LEN - 1);
        memcpy(ch->hdr->fail_reason, reason, n);
        ch->hdr->fail_reason[n] = '\0';
    }
    atomic_store(&ch->hdr->state, IPC_STATE_FAILED);
    if (ch->mpi) /* the peer holds its own copy of the header: tell it */
        g_mpi->send_state(ch);
}

/* A process that has exited but is not yet reaped by its parent (a zombie)
 * still answers kill(pid, 0): look at its state in /proc as well, so that a
 * killed peer is noticed at once rather than when its heartbeat goes stale. */
static int process_alive(int32_t pid)
{
    if (kill(pid, 0) != 0 && errno == ESRCH)
        return 0;
    char path[64], buf[256];
    snprintf(path, sizeof path, "/proc/%d/stat", (int)pid);
    FILE *f = fopen(path, "r");
    if (!f)
        return 1; /* no /proc: rely on the heartbeat */
    size_t n = fread(buf, 1, sizeof buf - 1, f);
    fclose(f);
    buf[n] = '\0';
    const char *paren = strrchr(buf, ')'); /* "pid (comm) S ..." */
    return !(paren && paren[1] == ' ' && (paren[2] == 'Z' || paren[2] == 'X'));
}

/* Called whenever a wait times out: is the peer still there? */
static int check_peer(ipc_channel *ch, const char *waiting_for)
{
    ipc_segment_header *h = ch->hdr;
    const char *peer = ipc_role_name(ch->peer);
    if (ch->stop_flag && *ch->stop_flag)
        return set_err(ch, IPC_ERR_INTERRUPTED, "interrupted while waiting for %s from %s", waiting_for, peer);
    uint32_t state = atomic_load(&h->state);
    if (state == IPC_STATE_FAILED) {
        int32_t who = atomic_load(&h->failed_role);
        char reason[IPC_REASON_LEN];
        memcpy(reason, h->fail_reason, sizeof reason);
        reason[IPC_REASON_LEN - 1] = '\0';
        if (who != (int32_t)ch->role)
            return set_err(ch, IPC_ERR_PEER_FAILED, "peer %s failed: %s", peer, reason);
    }
    if (state == IPC_STATE_FINISHED)
        return set_err(ch, IPC_ERR_PROTOCOL, "peer %s ended the run while we waited for %s", peer, waiting_for);
    int32_t pid = atomic_load(&h->pid[ch->peer]);
    if (pid > 0) {
        if (!process_alive(pid))
            return set_err(ch, IPC_ERR_PEER_DEAD, "peer %s (pid %d) died while we waited for %s", peer, (int)pid,
                           waiting_for);
        uint64_t beat = atomic_load(&h->heartbeat_ns[ch->peer]);
        uint64_t now = now_ns();
        if (now > beat && (double)(now - beat) * 1e-9 > ch->stall_timeout)
            return set_err(ch, IPC_ERR_PEER_DEAD,
                           "peer %s (pid %d) stopped answering (no heartbeat for %.1f s) while we waited for %s",
                           peer, (int)pid, (double)(now - beat) * 1e-9, waiting_for);
    }
    return IPC_OK;
}

int ipc_channel_check_peer(ipc_channel *ch, const char *waiting_for) { return check_peer(ch, waiting_for); }

double ipc_channel_now_s(void) { return now_s(); }

/* Shortest spin budget: a peer that answers fast is still noticed (and the
 * budget grows back) at the cost of a microsecond per wait. */
#define IPC_SPIN_FLOOR_S 1e-6

/* Waits for a semaphore. A frame that comes within microseconds (the peer
 * running on the other core) is caught by spinning; a longer wait sleeps in
 * the semaphore, in 20 ms slices with the peer checked between them.
 * The spin adapts to how long the waits turn out: its budget (at most
 * spin_s) halves after each wait the spin did not catch and doubles after
 * one it did, so that when the peer takes long, or shares our core with a
 * third process, we sleep almost at once instead of burning the core it
 * needs. (Yielding the core within the spin, sched_yield, was tried: with
 * many runnable processes a yield can cost a whole scheduling period, and
 * the ring's round trip on the loaded machine grew instead of shrinking.)
 * *budget: the budget of this kind of wait. deadline_s > 0 bounds the
 * whole wait (handshake); 0 waits as long as the peer lives. */
static int wait_sem(ipc_channel *ch, sem_t *sem, double *budget, double deadline_s, const char *what,
                    double *waited)
{
    double t0 = now_s();
    int rc = IPC_OK;
    if (ch->spin_s > 0) {
        double limit = *budget, t = t0;
        while (t - t0 < limit) {
            if (sem_trywait(sem) == 0) {
                *budget = fmin(2.0 * *budget, ch->spin_s);
                goto done;
            }
            cpu_relax();
            t = now_s();
        }
        *budget = fmax(0.5 * *budget, fmin(IPC_SPIN_FLOOR_S, ch->spin_s));
    }
    for (;;) {
        struct timespec ts;
        clock_gettime(CLOCK_MONOTONIC, &ts);
        ts.tv_nsec += 20 * 1000 * 1000;
        if (ts.tv_nsec >= 1000000000) {
            ts.tv_sec += 1;
            ts.tv_nsec -= 1000000000;
        }
        if (sem_clockwait(sem, CLOCK_MONOTONIC, &ts) == 0)
            break;
        if (errno != ETIMEDOUT && errno != EINTR) {
            rc = set_err(ch, IPC_ERR_SYS, "waiting for %s: %s", what, strerror(errno));
            break;
        }
        rc = check_peer(ch, what);
        if (rc)
            break;
        if (deadline_s > 0 && now_s() - t0 > deadline_s) {
            rc = set_err(ch, IPC_ERR_TIMEOUT, "no %s from peer %s within %.1f s", what, ipc_role_name(ch->peer),
                         deadline_s);
            break;
        }
    }
done:
    if (waited)
        *waited += now_s() - t0;
    return rc;
}

/* The attach's polls: ready() says whether what we wait for is there (1),
 * not yet (0) or failed (a negative status, message set). Polled every
 * sleep_us until it is, the stop flag is raised, or the connect timeout
 * (from t0) passes: then status late_code with the message `late`. With
 * watch_peer, the peer is checked between polls too. */
typedef int (*poll_ready_fn)(ipc_channel *ch, void *arg);

static int poll_until(ipc_channel *ch, double t0, long sleep_us, int watch_peer, poll_ready_fn ready, void *arg,
                      const char *what, int late_code, const char *late)
{
    for (;;) {
        int r = ready(ch, arg);
        if (r != 0)
            return r > 0 ? IPC_OK : r;
        if (ch->stop_flag && *ch->stop_flag)
            return set_err(ch, IPC_ERR_INTERRUPTED, "interrupted while waiting for %s", what);
        if (watch_peer && (r = check_peer(ch, what)) != IPC_OK)
            return r;
        if (now_s() - t0 > ch->connect_timeout)
            return set_err(ch, late_code, "%s", late);
        struct timespec ts = {0, sleep_us * 1000};
        nanosleep(&ts, NULL);
    }
}

/* ---- creation (FEM side) -------------------------------------------------- */

static ipc_channel *channel_new(ipc_role role, const char *name)
{
    ipc_channel *ch = calloc(1, sizeof *ch);
    if (!ch)
        return NULL;
    ch->role = role;
    ch->peer = role == IPC_ROLE_FEM ? IPC_ROLE_DEM : IPC_ROLE_FEM;
    snprintf(ch->name, sizeof ch->name, "%s", name);
    return ch;
}

static void channel_free(ipc_channel *ch)
{
    if (ch->heartbeat_running) {
        atomic_store(&ch->heartbeat_stop, 1);
        pthread_join(ch->heartbeat, NULL);
    }
    const int keep = ch->mpi ? g_mpi->close(ch) : 0; /* keep: a request may still refer to the image */
    if (ch->image) {
        if (!keep)
            free(ch->base);
    } else if (ch->hdr) {
        munmap(ch->base, ch->size);
    }
    if (ch->linked)
        shm_unlink(ch->name);
    free(ch);
}

static void copy_err(char *err, size_t errlen, const char *msg)
{
    if (err && errlen)
        snprintf(err, errlen, "%s", msg);
}

static double positive_or(double v, double def) { return v > 0 ? v : def; }

int ipc_name_is_mpi(const char *name) { return name && strcmp(name, IPC_MPI_NAME) == 0; }

/* A channel name: the MPI transport's, when it is started, or a segment's. */
static int check_name(const char *name, char *err, size_t errlen)
{
    if (ipc_name_is_mpi(name) && !g_mpi) {
        copy_err(err, errlen, "channel \"" IPC_MPI_NAME "\": the MPI transport is not started in this process (it "
                              "needs a build with MPI and an MPMD launch, mpirun -np N dem_server ... : -np 1 "
                              "fem_server ...; ipc/PROTOCOL.md, \"The MPI transport\")");
        return IPC_ERR_ARG;
    }
    if (!ipc_name_is_mpi(name) && !ipc_name_valid(name)) {
        copy_err(err, errlen, "invalid shared-memory name (want \"/\" then letters, digits, '.', '_', '-')");
        return IPC_ERR_ARG;
    }
    return IPC_OK;
}

/* The MPI transport's private image of the segment, zero-filled as a new segment is. */
static int image_new(ipc_channel *ch, uint64_t size)
{
    ch->base = aligned_alloc(IPC_PAGE, size); /* size is a whole number of pages */
    if (!ch->base)
        return set_err(ch, IPC_ERR_SYS, "out of memory for a %llu-byte exchange image",
                       (unsigned long long)size);
    memset(ch->base, 0, size);
    ch->image = 1;
    ch->hdr = (ipc_segment_header *)ch->base;
    ch->size = size;
    return IPC_OK;
}

/* The ring's segment: created (never reused), sized and mapped. */
static int segment_create(ipc_channel *ch, const char *name, const ipc_layout *lay)
{
    int fd = shm_open(name, O_CREAT | O_EXCL | O_RDWR, 0600);
    if (fd < 0) {
        if (errno == EEXIST)
            return set_err(ch, IPC_ERR_STALE,
                           "shared-memory segment %s already exists (left by another run?): refusing to reuse it; "
                           "remove /dev/shm%s or choose another name",
                           name, name);
        return set_err(ch, IPC_ERR_SYS, "shm_open %s: %s", name, strerror(errno));
    }
    ch->linked = 1;
    if (ftruncate(fd, (off_t)lay->segment_size) != 0) {
        close(fd);
        return set_err(ch, IPC_ERR_SYS, "sizing %s to %llu bytes: %s", name, (unsigned long long)lay->segment_size,
                       strerror(errno));
    }
    void *p = mmap(NULL, lay->segment_size, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
    close(fd);
    if (p == MAP_FAILED)
        return set_err(ch, IPC_ERR_SYS, "mmap %s: %s", name, strerror(errno));
    ch->base = p;
    ch->hdr = p;
    ch->size = lay->segment_size;
    return IPC_OK;
}

int ipc_create(const char *name, const ipc_create_def *def, ipc_channel **out, char *err, size_t errlen)
{
    *out = NULL;
    int rc = check_name(name, err, errlen);
    if (rc)
        return rc;
    ipc_layout lay;
    uint32_t slots = def->ring_slots ? def->ring_slots : 2;
    if (ipc_layout_compute(def->n_nodes, def->n_tris, slots, &lay) != 0) {
        char m[512];
        snprintf(m, sizeof m, "%s: surface of %u nodes, %u triangles, %u slots is out of range", name, def->n_nodes,
                 def->n_tris, slots);
        copy_err(err, errlen, m);
        return IPC_ERR_ARG;
    }
    ipc_channel *ch = channel_new(IPC_ROLE_FEM, name);
    if (!ch) {
        copy_err(err, errlen, "out of memory");
        return IPC_ERR_SYS;
    }
    const int mpi = ipc_name_is_mpi(name);
    rc = mpi ? image_new(ch, lay.segment_size) : segment_create(ch, name, &lay);
    if (rc)
        goto fail;
    ch->lay = lay;
    ch->n_nodes = def->n_nodes;
    ch->n_tris = def->n_tris;
    ch->slots = slots;
    ch->flags = def->checksum ? IPC_SEG_CHECKSUM : 0;
    ch->stall_timeout = positive_or(def->stall_timeout, 1.0);
    ch->connect_timeout = positive_or(def->connect_timeout, 60.0);
    ch->spin_s = def->spin_us < 0 ? 0 : 1e-6 * positive_or(def->spin_us, 50.0);
    ch->spin_budget[0] = ch->spin_budget[1] = ch->spin_s;
    ch->stop_flag = def->stop_flag;

    ipc_segment_header *h = ch->hdr; /* ftruncate zero-filled it */
    h->version = def->version ? def->version : IPC_VERSION;
    h->header_size = sizeof *h;
    h->segment_size = lay.segment_size;
    atomic_store(&h->state, IPC_STATE_STARTING);
    h->n_nodes = def->n_nodes;
    h->n_tris = def->n_tris;
    h->ring_slots = slots;
    h->flags = ch->flags;
    h->nodes_offset = lay.nodes_offset;
    h->masses_offset = lay.masses_offset;
    h->tris_offset = lay.tris_offset;
    for (int r = IPC_ROLE_FEM; r <= IPC_ROLE_DEM; r++) {
        h->ring_offset[r] = lay.ring_offset[r];
        h->slot_size[r] = lay.slot_size[r];
        h->payload_len[r] = lay.payload_len[r];
    }
    h->fem_exchange_dt = def->exchange_dt;
    if (mpi) { /* no semaphores, pid or heartbeat: messages, and mpirun watches the processes */
        if ((rc = g_mpi->open(ch)) || (rc = g_mpi->post_receives(ch)))
            goto fail;
        atomic_store_explicit(&h->magic, IPC_MAGIC, memory_order_release);
        *out = ch;
        return IPC_OK;
    }
    int sem_ok = sem_init(&h->sem_hello, 1, 0) == 0 && sem_init(&h->sem_ack, 1, 0) == 0;
    for (int r = IPC_ROLE_FEM; r <= IPC_ROLE_DEM; r++)
        sem_ok = sem_ok && sem_init(&h->sem_full[r], 1, 0) == 0 && sem_init(&h->sem_empty[r], 1, slots) == 0;
    if (!sem_ok) {
        rc = set_err(ch, IPC_ERR_SYS, "sem_init in %s: %s", name, strerror(errno));
        goto fail;
    }
    atomic_store(&h->pid[IPC_ROLE_FEM], (int32_t)getpid());
    rc = start_heartbeat(ch);
    if (rc)
        goto fail;
    /* Publish last: an attacher that sees the magic sees a complete header. */
    atomic_store_explicit(&h->magic, IPC_MAGIC, memory_order_release);
    *out = ch;
    return IPC_OK;
fail:
    copy_err(err, errlen, ch->err);
    channel_free(ch);
    return rc;
}

int ipc_accept(ipc_channel *ch)
{
    if (ch->role != IPC_ROLE_FEM)
        return set_err(ch, IPC_ERR_ARG, "ipc_accept is for the FEM side");
    ipc_segment_header *h = ch->hdr;
    atomic_store_explicit(&h->surface_ready, 1, memory_order_release);
    int rc = ch->mpi ? g_mpi->publish_and_wait_hello(ch, ch->connect_timeout)
                     : wait_sem(ch, &h->sem_hello, &ch->spin_budget[1], ch->connect_timeout, "the DEM's hello", NULL);
    /* The DEM attached (or never will): nobody else needs the name. */
    if (ch->linked) {
        shm_unlink(ch->name);
        ch->linked = 0;
    }
    if (rc) {
        if (rc == IPC_ERR_TIMEOUT)
            set_err(ch, rc, "no DEM peer attached to %s within %.1f s", ch->name, ch->connect_timeout);
        return rc;
    }
    char reason[IPC_REASON_LEN] = "";
    uint32_t dem_version = h->dem_version;
    double dem_dt = h->dem_dt;
    uint32_t every = h->dem_exchange_every;
    uint32_t my_version = h->version;
    if (dem_version != my_version) {
        snprintf(reason, sizeof reason, "protocol version mismatch: FEM speaks %u, DEM speaks %u", my_version,
                 dem_version);
        rc = IPC_ERR_VERSION;
    } else if (!(dem_dt > 0 && isfinite(dem_dt)) || every < 1) {
        snprintf(reason, sizeof reason, "DEM announced an invalid time step %g s x %u", dem_dt, every);
        rc = IPC_ERR_MISMATCH;
    } else if (h->fem_exchange_dt > 0) {
        double dem_interval = dem_dt * every;
        if (fabs(dem_interval - h->fem_exchange_dt) > 1e-9 * h->fem_exchange_dt) {
            snprintf(reason, sizeof reason,
                     "time step mismatch: DEM exchanges every %u x %g s = %g s, FEM expects %g s", every, dem_dt,
                     dem_interval, h->fem_exchange_dt);
            rc = IPC_ERR_MISMATCH;
        }
    }
    if (rc) {
        record_failure(ch, reason); /* over MPI this is the answer */
        if (!ch->mpi)
            sem_post(&h->sem_ack);
        return set_err(ch, rc, "refused the DEM peer: %s", reason);
    }
    ch->dem_dt = dem_dt;
    ch->exchange_every = every;
    atomic_store(&h->state, IPC_STATE_RUNNING);
    if (ch->mpi)
        g_mpi->send_state(ch);
    else
        sem_post(&h->sem_ack);
    return IPC_OK;
}

/* ---- attaching (DEM side) ------------------------------------------------- */

static int check_header_fields(ipc_channel *ch, size_t file_size, uint32_t my_version, uint32_t expect_nodes);

/* Reads and checks the header against the layout its counts imply. A refusal
 * is written into the stable prefix too, so the creator hears why at once. */
static int check_header(ipc_channel *ch, size_t file_size, uint32_t my_version, uint32_t expect_nodes)
{
    int rc = check_header_fields(ch, file_size, my_version, expect_nodes);
    if (rc && atomic_load(&ch->hdr->state) != IPC_STATE_FAILED)
        record_failure(ch, ch->err);
    return rc;
}

/* Every value used later is copied into ch first (never re-read). */
static int check_header_fields(ipc_channel *ch, size_t file_size, uint32_t my_version, uint32_t expect_nodes)
{
    ipc_segment_header *h = ch->hdr;
    uint32_t version = h->version;
    if (version != my_version) {
        char reason[IPC_REASON_LEN];
        snprintf(reason, sizeof reason, "protocol version mismatch: segment (FEM) is version %u, DEM speaks %u",
                 version, my_version);
        record_failure(ch, reason);
        return set_err(ch, IPC_ERR_VERSION, "%s: %s", ch->name, reason);
    }
    if (h->header_size != sizeof *h || h->segment_size != file_size)
        return set_err(ch, IPC_ERR_SIZE,
                       "%s: size mismatch: header says %u-byte header and %llu-byte segment, expected %zu and %zu",
                       ch->name, h->header_size, (unsigned long long)h->segment_size, sizeof *h, file_size);
    uint32_t n = h->n_nodes, m = h->n_tris, slots = h->ring_slots;
    ipc_layout lay;
    if (ipc_layout_compute(n, m, slots, &lay) != 0)
        return set_err(ch, IPC_ERR_SIZE, "%s: size mismatch: counts out of range (%u nodes, %u triangles, %u slots)",
                       ch->name, n, m, slots);
    int same = lay.segment_size == file_size && lay.nodes_offset == h->nodes_offset &&
               lay.masses_offset == h->masses_offset && lay.tris_offset == h->tris_offset;
    for (int r = IPC_ROLE_FEM; r <= IPC_ROLE_DEM; r++)
        same = same && lay.ring_offset[r] == h->ring_offset[r] && lay.slot_size[r] == h->slot_size[r] &&
               lay.payload_len[r] == h->payload_len[r];
    if (!same)
        return set_err(ch, IPC_ERR_SIZE,
                       "%s: size mismatch: offsets in the header do not match %u nodes, %u triangles, %u slots",
                       ch->name, n, m, slots);
    if (expect_nodes && expect_nodes != n) {
        char reason[IPC_REASON_LEN];
        snprintf(reason, sizeof reason, "size mismatch: FEM publishes %u interface nodes, DEM expects %u", n,
                 expect_nodes);
        record_failure(ch, reason);
        return set_err(ch, IPC_ERR_SIZE, "%s: %s", ch->name, reason);
    }
    ch->n_nodes = n;
    ch->n_tris = m;
    ch->slots = slots;
    ch->flags = h->flags;
    ch->lay = lay;
    return IPC_OK;
}

static int check_surface(ipc_channel *ch)
{
    const double *x = (const double *)(ch->base + ch->lay.nodes_offset);
    const double *mass = (const double *)(ch->base + ch->lay.masses_offset);
    const uint32_t *t = (const uint32_t *)(ch->base + ch->lay.tris_offset);
    for (uint64_t i = 0; i < 3ull * ch->n_nodes; i++)
        if (!isfinite(x[i]))
            return set_err(ch, IPC_ERR_PROTOCOL, "%s: interface node %llu has a non-finite coordinate", ch->name,
                           (unsigned long long)(i / 3));
    for (uint64_t i = 0; i < ch->n_nodes; i++)
        if (!isfinite(mass[i]) || mass[i] < 0)
            return set_err(ch, IPC_ERR_PROTOCOL, "%s: interface node %llu has mass %g (want finite, >= 0)", ch->name,
                           (unsigned long long)i, mass[i]);
    for (uint64_t k = 0; k < ch->n_tris; k++) {
        uint32_t a = t[3 * k], b = t[3 * k + 1], c = t[3 * k + 2];
        if (a >= ch->n_nodes || b >= ch->n_nodes || c >= ch->n_nodes || a == b || b == c || a == c)
            return set_err(ch, IPC_ERR_PROTOCOL,
                           "%s: interface triangle %llu has invalid node indices (%u, %u, %u) for %u nodes",
                           ch->name, (unsigned long long)k, a, b, c, ch->n_nodes);
    }
    return IPC_OK;
}

/* What ipc_attach polls for (poll_until). */
typedef struct attach_poll {
    const char *name;
    int fd;
    struct stat st;
} attach_poll;

static int segment_exists(ipc_channel *ch, void *arg) /* 1. the FEM side created it */
{
    attach_poll *a = arg;
    a->fd = shm_open(a->name, O_RDWR, 0);
    if (a->fd >= 0)
        return 1;
    return errno == ENOENT ? 0 : set_err(ch, IPC_ERR_SYS, "shm_open %s: %s", a->name, strerror(errno));
}

static int segment_sized(ipc_channel *ch, void *arg) /* the creator sizes it right after creating it */
{
    attach_poll *a = arg;
    if (fstat(a->fd, &a->st) != 0)
        return set_err(ch, IPC_ERR_SYS, "fstat %s: %s", a->name, strerror(errno));
    return (size_t)a->st.st_size >= sizeof(ipc_segment_header);
}

static int header_published(ipc_channel *ch, void *arg) /* 2. the creator stores the magic last */
{
    (void)arg;
    return atomic_load_explicit(&ch->hdr->magic, memory_order_acquire) == IPC_MAGIC;
}

static int surface_published(ipc_channel *ch, void *arg) /* 4. the FEM side's surface */
{
    (void)arg;
    return atomic_load_explicit(&ch->hdr->surface_ready, memory_order_acquire) != 0;
}

/* 4b. The surface published: check it. 5. Hello: our version and time
 * step; the FEM accepts or refuses. */
static int say_hello(ipc_channel *ch, const ipc_attach_def *def, uint32_t my_version)
{
    ipc_segment_header *h = ch->hdr;
    int rc = check_surface(ch);
    if (rc) {
        record_failure(ch, ch->err);
        return rc;
    }
    h->dem_version = my_version;
    h->dem_dt = def->dt;
    h->dem_exchange_every = def->exchange_every;
    if (ch->mpi) {
        rc = g_mpi->hello_and_wait_answer(ch, ch->connect_timeout);
    } else {
        sem_post(&h->sem_hello);
        rc = wait_sem(ch, &h->sem_ack, &ch->spin_budget[1], ch->connect_timeout, "the FEM's answer to our hello",
                      NULL);
    }
    if (rc)
        return rc;
    if (atomic_load(&h->state) != IPC_STATE_RUNNING) {
        char reason[IPC_REASON_LEN];
        memcpy(reason, h->fail_reason, sizeof reason);
        reason[IPC_REASON_LEN - 1] = '\0';
        return set_err(ch, strstr(reason, "version") ? IPC_ERR_VERSION : IPC_ERR_MISMATCH,
                       "FEM peer refused the handshake: %s", reason);
    }
    ch->dem_dt = def->dt;
    ch->exchange_every = def->exchange_every;
    return IPC_OK;
}

/* The MPI transport's steps 1-4: the FEM's header and surface arrive as one
 * message, checked as a segment's would be (check_header) before the image
 * of the whole layout is made from it. */
static int attach_image(ipc_channel *ch, uint32_t my_version, uint32_t expect_nodes)
{
    void *buf = NULL;
    size_t bytes = 0;
    int rc = g_mpi->open(ch);
    if (rc || (rc = g_mpi->receive_surface(ch, &buf, &bytes)))
        return rc;
    ipc_segment_header *h = buf;
    if (bytes < sizeof *h || atomic_load(&h->magic) != IPC_MAGIC) {
        free(buf);
        return set_err(ch, IPC_ERR_STALE, "%s: the FEM peer's first message (%zu bytes) has no valid header (bad "
                       "magic): not a peer of this protocol", ch->name, bytes);
    }
    ipc_layout lay;
    if (ipc_layout_compute(h->n_nodes, h->n_tris, h->ring_slots, &lay) != 0) {
        ch->base = buf; /* check_header names what is out of range (and tells the peer) */
        ch->image = 1;
        ch->hdr = buf;
        ch->size = bytes;
        return check_header(ch, bytes, my_version, expect_nodes);
    }
    if (lay.ring_offset[IPC_ROLE_FEM] != bytes) {
        ch->base = buf; /* record_failure writes into it; channel_free frees it */
        ch->image = 1;
        ch->hdr = buf;
        ch->size = bytes;
        rc = set_err(ch, IPC_ERR_SIZE, "%s: size mismatch: header and surface in %zu bytes, the header's counts "
                     "imply %llu", ch->name, bytes, (unsigned long long)lay.ring_offset[IPC_ROLE_FEM]);
        record_failure(ch, ch->err);
        return rc;
    }
    rc = image_new(ch, lay.segment_size);
    if (rc == IPC_OK)
        memcpy(ch->base, buf, bytes);
    free(buf);
    if (rc || (rc = check_header(ch, ch->size, my_version, expect_nodes)))
        return rc;
    return g_mpi->post_receives(ch);
}

int ipc_attach(const char *name, const ipc_attach_def *def, ipc_channel **out, char *err, size_t errlen)
{
    *out = NULL;
    int rc = check_name(name, err, errlen);
    if (rc)
        return rc;
    if (!(def->dt > 0 && isfinite(def->dt)) || def->exchange_every < 1) {
        copy_err(err, errlen, "ipc_attach: dt must be > 0 and exchange_every >= 1");
        return IPC_ERR_ARG;
    }
    ipc_channel *ch = channel_new(IPC_ROLE_DEM, name);
    if (!ch) {
        copy_err(err, errlen, "out of memory");
        return IPC_ERR_SYS;
    }
    ch->stall_timeout = positive_or(def->stall_timeout, 1.0);
    ch->connect_timeout = positive_or(def->connect_timeout, 60.0);
    ch->spin_s = def->spin_us < 0 ? 0 : 1e-6 * positive_or(def->spin_us, 50.0);
    ch->spin_budget[0] = ch->spin_budget[1] = ch->spin_s;
    ch->stop_flag = def->stop_flag;
    uint32_t my_version = def->version ? def->version : IPC_VERSION;
    double t0 = now_s();
    if (ipc_name_is_mpi(name)) {
        if ((rc = attach_image(ch, my_version, def->expect_nodes)) || (rc = say_hello(ch, def, my_version)))
            goto fail;
        *out = ch;
        return IPC_OK;
    }

    /* 1. Wait for the FEM side to create the segment (either may start first). */
    char late[600];
    attach_poll ap = {.name = name, .fd = -1};
    snprintf(late, sizeof late, "no FEM peer created segment %s within %.1f s", name, ch->connect_timeout);
    rc = poll_until(ch, t0, 2000, 0, segment_exists, &ap, "the segment", IPC_ERR_TIMEOUT, late);
    if (rc)
        goto fail;
    int fd = ap.fd;
    struct stat st;
    if (fstat(fd, &st) != 0) {
        rc = set_err(ch, IPC_ERR_SYS, "fstat %s: %s", name, strerror(errno));
        close(fd);
        goto fail;
    }
    /* Owner-only segments of our own user: never follow someone else's. */
    if (st.st_uid != geteuid() || (st.st_mode & 077) != 0) {
        rc = set_err(ch, IPC_ERR_STALE, "%s is owned by uid %u with mode %o: refusing to attach (want uid %u, 0600)",
                     name, (unsigned)st.st_uid, (unsigned)(st.st_mode & 0777), (unsigned)geteuid());
        close(fd);
        goto fail;
    }
    snprintf(late, sizeof late, "%s is too small for a header", name);
    rc = poll_until(ch, t0, 2000, 0, segment_sized, &ap, "the segment's size", IPC_ERR_SIZE, late);
    if (rc) {
        close(fd);
        goto fail;
    }
    st = ap.st;
    size_t file_size = (size_t)st.st_size;
    void *p = mmap(NULL, file_size, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
    close(fd);
    if (p == MAP_FAILED) {
        rc = set_err(ch, IPC_ERR_SYS, "mmap %s: %s", name, strerror(errno));
        goto fail;
    }
    ch->base = p;
    ch->hdr = p;
    ch->size = file_size;
    ipc_segment_header *h = ch->hdr;

    /* 2. Wait for the magic: the creator stores it last. */
    snprintf(late, sizeof late, "%s has no valid header (bad magic): not a segment of this protocol", name);
    rc = poll_until(ch, t0, 2000, 0, header_published, NULL, "the segment's header", IPC_ERR_STALE, late);
    if (rc)
        goto fail;
    rc = check_header(ch, file_size, my_version, def->expect_nodes);
    if (rc)
        goto fail;

    /* 3. A live creator, still starting, with no DEM yet: else it is stale. */
    int32_t fem_pid = atomic_load(&h->pid[IPC_ROLE_FEM]);
    uint32_t state = atomic_load(&h->state);
    int fem_alive = fem_pid > 0 && process_alive(fem_pid);
    if (!fem_alive || state != IPC_STATE_STARTING) {
        rc = set_err(ch, IPC_ERR_STALE,
                     "%s is stale (creator pid %d %s, state %u): refusing to attach; remove /dev/shm%s", name,
                     (int)fem_pid, fem_alive ? "alive" : "gone", state, name);
        goto fail;
    }
    int32_t zero = 0;
    if (!atomic_compare_exchange_strong(&h->pid[IPC_ROLE_DEM], &zero, (int32_t)getpid())) {
        rc = set_err(ch, IPC_ERR_STALE, "%s already has a DEM peer (pid %d)", name, (int)zero);
        goto fail;
    }
    rc = start_heartbeat(ch);
    if (rc)
        goto fail;

    /* 4. Wait for the surface, then check it. */
    snprintf(late, sizeof late, "FEM peer did not publish its surface within %.1f s", ch->connect_timeout);
    rc = poll_until(ch, t0, 1000, 1, surface_published, NULL, "the interface surface", IPC_ERR_TIMEOUT, late);
    if (rc)
        goto fail;
    rc = say_hello(ch, def, my_version);
    if (rc)
        goto fail;
    *out = ch;
    return IPC_OK;
fail:
    copy_err(err, errlen, ch->err);
    channel_free(ch);
    return rc;
}

/* ---- accessors -------------------------------------------------------------- */

uint32_t ipc_surface_node_count(const ipc_channel *ch) { return ch->n_nodes; }
uint32_t ipc_surface_tri_count(const ipc_channel *ch) { return ch->n_tris; }
double *ipc_surface_nodes(ipc_channel *ch) { return (double *)(ch->base + ch->lay.nodes_offset); }
double *ipc_surface_masses(ipc_channel *ch) { return (double *)(ch->base + ch->lay.masses_offset); }
uint32_t *ipc_surface_tris(ipc_channel *ch) { return (uint32_t *)(ch->base + ch->lay.tris_offset); }
double ipc_dem_dt(const ipc_channel *ch) { return ch->dem_dt; }
uint32_t ipc_exchange_every(const ipc_channel *ch) { return ch->exchange_every; }
size_t ipc_send_len(const ipc_channel *ch) { return (size_t)ch->lay.payload_len[ch->peer]; }
size_t ipc_recv_len(const ipc_channel *ch) { return (size_t)ch->lay.payload_len[ch->role]; }

/* ---- frames ----------------------------------------------------------------- */

static ipc_frame_head *slot(ipc_channel *ch, ipc_role receiver, uint64_t seq)
{
    uint64_t off = ch->lay.ring_offset[receiver] + (seq % ch->slots) * ch->lay.slot_size[receiver];
    return (ipc_frame_head *)(ch->base + off);
}

/* Frames flow once the handshake is accepted. A finished peer may still have
 * left its last frame in the ring, so FINISHED is not an error here: the wait
 * takes a posted frame before it ever checks on the peer. */
static int check_can_exchange(ipc_channel *ch)
{
    if (ch->stop_flag && *ch->stop_flag)
        return set_err(ch, IPC_ERR_INTERRUPTED, "interrupted at exchange %llu",
                       (unsigned long long)(ch->role == IPC_ROLE_DEM ? ch->send_seq : ch->recv_seq));
    uint32_t state = atomic_load(&ch->hdr->state);
    if (state == IPC_STATE_RUNNING || state == IPC_STATE_FINISHED)
        return IPC_OK;
    int rc = check_peer(ch, "a frame");
    return rc ? rc : set_err(ch, IPC_ERR_PROTOCOL, "exchange attempted in state %u", state);
}

int ipc_send_begin(ipc_channel *ch, ipc_frame_head **head, double **payload)
{
    if (ch->send_open)
        return set_err(ch, IPC_ERR_ARG, "ipc_send_begin twice without ipc_send_commit");
    int rc = check_can_exchange(ch);
    if (rc)
        return rc;
    char what[96];
    snprintf(what, sizeof what, "a free slot for exchange %llu", (unsigned long long)ch->send_seq);
    rc = ch->mpi ? g_mpi->wait_slot(ch, what)
                 : wait_sem(ch, &ch->hdr->sem_empty[ch->peer], &ch->spin_budget[1], 0, what, &ch->stats.wait_send_s);
    if (rc)
        return rc;
    ipc_frame_head *f = slot(ch, ch->peer, ch->send_seq);
    memset(f, 0, sizeof *f);
    f->kind = IPC_FRAME_DATA;
    *head = f;
    *payload = (double *)(f + 1);
    ch->send_open = 1;
    return IPC_OK;
}

int ipc_send_commit(ipc_channel *ch)
{
    if (!ch->send_open)
        return set_err(ch, IPC_ERR_ARG, "ipc_send_commit without ipc_send_begin");
    ipc_frame_head *f = slot(ch, ch->peer, ch->send_seq);
    f->seq = ch->send_seq;
    if (ch->flags & IPC_SEG_CHECKSUM)
        f->checksum = ipc_checksum(f + 1, ch->lay.payload_len[ch->peer] * sizeof(double));
    ch->send_open = 0;
    if (ch->mpi) {
        int rc = g_mpi->send_frame(ch);
        if (rc)
            return rc;
    }
    ch->send_seq++;
    ch->stats.frames_sent++;
    if (!ch->mpi)
        sem_post(&ch->hdr->sem_full[ch->peer]);
    return IPC_OK;
}

int ipc_recv(ipc_channel *ch, const ipc_frame_head **head, const double **payload)
{
    if (ch->recv_open)
        return set_err(ch, IPC_ERR_ARG, "ipc_recv twice without ipc_recv_release");
    int rc = check_can_exchange(ch);
    if (rc)
        return rc;
    char what[96];
    snprintf(what, sizeof what, "exchange %llu", (unsigned long long)ch->recv_seq);
    rc = ch->mpi ? g_mpi->wait_frame(ch, what)
                 : wait_sem(ch, &ch->hdr->sem_full[ch->role], &ch->spin_budget[0], 0, what, &ch->stats.wait_recv_s);
    if (rc == IPC_ERR_PROTOCOL && ch->mpi) /* a frame of the wrong size: the peer hears why, as below */
        record_failure(ch, ch->err);
    if (rc)
        return rc;
    ipc_frame_head *f = slot(ch, ch->role, ch->recv_seq);
    uint64_t seq = f->seq;
    if (seq != ch->recv_seq) {
        rc = set_err(ch, IPC_ERR_PROTOCOL, "exchange out of order from %s: expected frame %llu, got %llu",
                     ipc_role_name(ch->peer), (unsigned long long)ch->recv_seq, (unsigned long long)seq);
        record_failure(ch, ch->err);
        return rc;
    }
    if (f->kind != IPC_FRAME_DATA && f->kind != IPC_FRAME_FINISH) {
        rc = set_err(ch, IPC_ERR_PROTOCOL, "frame %llu from %s has unknown kind %u", (unsigned long long)seq,
                     ipc_role_name(ch->peer), f->kind);
        record_failure(ch, ch->err);
        return rc;
    }
    if (ch->flags & IPC_SEG_CHECKSUM) {
        uint64_t sum = ipc_checksum(f + 1, ch->lay.payload_len[ch->role] * sizeof(double));
        if (sum != f->checksum) {
            rc = set_err(ch, IPC_ERR_PROTOCOL, "frame %llu from %s: payload checksum mismatch",
                         (unsigned long long)seq, ipc_role_name(ch->peer));
            record_failure(ch, ch->err);
            return rc;
        }
    }
    *head = f;
    *payload = (const double *)(f + 1);
    ch->recv_open = 1;
    return IPC_OK;
}

int ipc_recv_release(ipc_channel *ch)
{
    if (!ch->recv_open)
        return set_err(ch, IPC_ERR_ARG, "ipc_recv_release without ipc_recv");
    ch->recv_open = 0;
    if (ch->mpi) {
        int rc = g_mpi->release_frame(ch); /* reposts the receive of slot recv_seq for recv_seq + slots */
        if (rc)
            return rc;
    }
    ch->recv_seq++;
    ch->stats.frames_received++;
    if (!ch->mpi)
        sem_post(&ch->hdr->sem_empty[ch->role]);
    return IPC_OK;
}

void ipc_fail(ipc_channel *ch, const char *fmt, ...)
{
    if (!ch || !ch->hdr)
        return;
    char reason[IPC_REASON_LEN];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(reason, sizeof reason, fmt, ap);
    va_end(ap);
    record_failure(ch, reason);
}

void ipc_close(ipc_channel **chp, int status)
{
    if (!chp || !*chp)
        return;
    ipc_channel *ch = *chp;
    if (ch->hdr) {
        if (status == IPC_OK) {
            uint32_t running = IPC_STATE_RUNNING;
            if (atomic_compare_exchange_strong(&ch->hdr->state, &running, IPC_STATE_FINISHED) && ch->mpi)
                g_mpi->send_state(ch); /* with the count of frames sent: the peer takes them first */
        } else if (atomic_load(&ch->hdr->state) != IPC_STATE_FAILED) {
            char reason[sizeof ch->err + 64]; /* record_failure truncates to the header's size */
            snprintf(reason, sizeof reason, "%s: %s", ipc_status_name(status), ch->err[0] ? ch->err : "stopped");
            record_failure(ch, reason);
        }
    }
    channel_free(ch);
    *chp = NULL;
}
