/* Protocol integration tests: two real processes (ipc_peer) on a real POSIX
 * shared-memory segment. Each test checks exit codes, what the survivor says
 * and how fast, and that nothing is left in /dev/shm. The peers announce
 * their progress on a readiness pipe (tests/proc.h): no case waits by
 * sleeping or by polling for a short-lived state. */
#include <errno.h>
#include <fcntl.h>
#include <signal.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "ipc.h"
#include "segment.h"
#include "proc.h"
#include "test.h"

#ifndef IPC_PEER_PATH
#error "IPC_PEER_PATH must point at the ipc_peer executable"
#endif

static void unique_name(char *buf, size_t len, const char *what)
{
    static int counter;
    snprintf(buf, len, "/demfem-test-%d-%s-%d", (int)getpid(), what, counter++);
}

/* Starts ipc_peer with the given NULL-terminated extra arguments; with
 * TP_READY it announces its progress on the readiness pipe (ipc_peer.c). */
static int spawn_peer(tp_proc *p, const char *role, const char *shm, const char *const *args, int flags)
{
    const char *argv[40];
    int n = 0;
    argv[n++] = IPC_PEER_PATH;
    argv[n++] = "--role";
    argv[n++] = role;
    argv[n++] = "--shm";
    argv[n++] = shm;
    if (flags & TP_READY) {
        argv[n++] = "--ready-fd";
        argv[n++] = TP_READY_FD_TEXT;
    }
    for (int i = 0; args && args[i] && n < 38; i++)
        argv[n++] = args[i];
    argv[n] = NULL;
    char log[256];
    snprintf(log, sizeof log, "/tmp/demfem-test-%d-%s-%s.log", (int)getpid(), role, shm + 1);
    return tp_spawn(p, argv, log, flags);
}

static int shm_exists(const char *name)
{
    char path[300];
    snprintf(path, sizeof path, "/dev/shm%s", name);
    return access(path, F_OK) == 0;
}

#define ENSURE_EXIT(p, code)                                                                 \
    do {                                                                                     \
        if ((p)->status != (code)) {                                                         \
            fprintf(stderr, "%s:%d: %s exited %d, expected %d; its log:\n", __FILE__, __LINE__, \
                    #p, (p)->status, (code));                                                \
            tp_print_log(p);                                                                 \
            return 1;                                                                        \
        }                                                                                    \
    } while (0)

#define ENSURE_LOG(p, needle)                                                                \
    do {                                                                                     \
        if (!tp_log_has(p, needle)) {                                                        \
            fprintf(stderr, "%s:%d: %s's log lacks \"%s\"; its log:\n", __FILE__, __LINE__, #p,  \
                    needle);                                                                 \
            tp_print_log(p);                                                                 \
            return 1;                                                                        \
        }                                                                                    \
    } while (0)

/* ---- normal runs -------------------------------------------------------------- */

/* 10 000 round trips of 20 000 nodes (480 kB out, 960 kB back), checksummed,
 * every value checked by the receiving process. */
static int roundtrip_10000(void)
{
    char shm[128];
    unique_name(shm, sizeof shm, "rt");
    tp_proc fem, dem;
    const char *fa[] = {"--nodes", "20000", "--checksum", "--expect-dt", "1e-05", NULL};
    const char *da[] = {"--exchanges", "10000", "--dt", "1e-05", NULL};
    double t0 = tp_now();
    ENSURE(spawn_peer(&fem, "fem", shm, fa, 0) == 0);
    ENSURE(spawn_peer(&dem, "dem", shm, da, 0) == 0);
    int ok = tp_wait(&dem, 300) == 0 && tp_wait(&fem, 10) == 0;
    double wall = tp_now() - t0;
    tp_kill(&dem);
    tp_kill(&fem);
    ENSURE(ok);
    ENSURE_EXIT(&dem, 0);
    ENSURE_EXIT(&fem, 0);
    ENSURE_LOG(&fem, "10000 exchanges ok");
    ENSURE_LOG(&dem, "10000 exchanges ok");
    ENSURE(!shm_exists(shm));
    printf("  10000 round trips of 20000 nodes in %.2f s (%.0f us each, incl. filling and checking)\n", wall,
           1e6 * wall / 10000);
    return 0;
}

static int dem_starts_first(void)
{
    char shm[128];
    unique_name(shm, sizeof shm, "demfirst");
    tp_proc fem, dem;
    const char *da[] = {"--exchanges", "2000", NULL};
    const char *fa[] = {"--nodes", "500", "--checksum", NULL};
    /* The FEM side starts only once the DEM side is about to attach: the DEM
     * must wait for a segment that does not exist yet. */
    ENSURE(spawn_peer(&dem, "dem", shm, da, TP_READY) == 0);
    if (tp_wait_ready(&dem, 'a', 30) != 0) {
        tp_kill(&dem);
        ENSURE_MSG(0, "the DEM peer did not start");
    }
    ENSURE(spawn_peer(&fem, "fem", shm, fa, 0) == 0);
    int ok = tp_wait(&dem, 60) == 0 && tp_wait(&fem, 10) == 0;
    tp_kill(&dem);
    tp_kill(&fem);
    ENSURE(ok);
    ENSURE_EXIT(&dem, 0);
    ENSURE_EXIT(&fem, 0);
    ENSURE(!shm_exists(shm));
    return 0;
}

/* A deeper ring and exchange_every > 1 change nothing in the content. */
static int ring_of_four_slots(void)
{
    char shm[128];
    unique_name(shm, sizeof shm, "slots");
    tp_proc fem, dem;
    const char *fa[] = {"--nodes", "300", "--slots", "4", "--expect-dt", "5e-05", NULL};
    const char *da[] = {"--exchanges", "3000", "--dt", "1e-05", "--every", "5", NULL};
    ENSURE(spawn_peer(&fem, "fem", shm, fa, 0) == 0);
    ENSURE(spawn_peer(&dem, "dem", shm, da, 0) == 0);
    int ok = tp_wait(&dem, 60) == 0 && tp_wait(&fem, 10) == 0;
    tp_kill(&dem);
    tp_kill(&fem);
    ENSURE(ok);
    ENSURE_EXIT(&dem, 0);
    ENSURE_EXIT(&fem, 0);
    return 0;
}

/* ---- a peer dies, stops or is interrupted ---------------------------------------- */

/* Starts a long run, waits until it is exchanging, delivers sig to one side;
 * the other must exit non-zero within 2 s naming the victim. */
static int peer_lost(const char *victim_role, int sig, const char *survivor_says)
{
    char shm[128];
    unique_name(shm, sizeof shm, victim_role);
    tp_proc fem, dem;
    const char *fa[] = {"--nodes", "2000", NULL};
    const char *da[] = {"--exchanges", "100000000", NULL};
    ENSURE(spawn_peer(&fem, "fem", shm, fa, TP_READY) == 0);
    ENSURE(spawn_peer(&dem, "dem", shm, da, TP_READY) == 0);
    /* Running once both have announced their first exchange (a byte on a
     * pipe: it cannot be missed, however fast or slow the handshake). */
    int up = tp_wait_ready(&fem, 'x', 30) == 0 && tp_wait_ready(&dem, 'x', 30) == 0;
    tp_proc *victim = strcmp(victim_role, "fem") == 0 ? &fem : &dem;
    tp_proc *survivor = victim == &fem ? &dem : &fem;
    if (!up) {
        tp_kill(&fem);
        tp_kill(&dem);
        tp_print_log(&fem);
        tp_print_log(&dem);
        ENSURE_MSG(0, "the pair did not start exchanging within 30 s");
    }
    double t_kill = tp_now();
    kill(victim->pid, sig);
    int survived = tp_wait(survivor, 5.0) == 0;
    double dt = survived ? survivor->t_exit - t_kill : 99;
    if (sig == SIGSTOP)
        kill(victim->pid, SIGKILL);
    tp_wait(victim, 5.0);
    tp_kill(&fem);
    tp_kill(&dem);
    ENSURE_MSG(survived && dt < 2.0, "survivor took %.2f s to exit", dt);
    ENSURE_MSG(survivor->status != 0, "survivor exited 0");
    ENSURE_LOG(survivor, survivor_says);
    ENSURE(!shm_exists(shm));
    printf("  %s got signal %d: survivor exited %d after %.3f s\n", victim_role, sig, survivor->status, dt);
    return 0;
}

static int fem_killed(void) { return peer_lost("fem", SIGKILL, "peer fem"); }
static int dem_killed(void) { return peer_lost("dem", SIGKILL, "peer dem"); }
static int fem_stopped(void) { return peer_lost("fem", SIGSTOP, "stopped answering"); }
static int dem_stopped(void) { return peer_lost("dem", SIGSTOP, "stopped answering"); }
static int fem_sigterm(void) { return peer_lost("fem", SIGTERM, "peer fem failed"); }
static int dem_sigint(void) { return peer_lost("dem", SIGINT, "peer dem failed"); }

/* The FEM side dies before anybody attached: the segment stays behind (the
 * launcher removes such leftovers); a new run with that name is refused. */
static int stale_segment_refused(void)
{
    char shm[128];
    unique_name(shm, sizeof shm, "stale");
    tp_proc fem, fem2, dem;
    const char *fa[] = {"--nodes", "100", "--connect", "30", NULL};
    ENSURE(spawn_peer(&fem, "fem", shm, fa, TP_READY) == 0);
    ENSURE(tp_wait_ready(&fem, 'c', 30) == 0); /* the segment is created and its header written */
    kill(fem.pid, SIGKILL);
    tp_wait(&fem, 5.0);
    ENSURE(shm_exists(shm));

    const char *fa2[] = {"--nodes", "100", NULL};
    ENSURE(spawn_peer(&fem2, "fem", shm, fa2, 0) == 0);
    const char *da[] = {"--connect", "5", NULL};
    ENSURE(spawn_peer(&dem, "dem", shm, da, 0) == 0);
    int ok = tp_wait(&fem2, 5.0) == 0 && tp_wait(&dem, 5.0) == 0;
    tp_kill(&fem2);
    tp_kill(&dem);
    shm_unlink(shm);
    ENSURE(ok);
    ENSURE_EXIT(&fem2, 3);
    ENSURE_LOG(&fem2, "already exists");
    ENSURE_EXIT(&dem, 3);
    ENSURE_LOG(&dem, "stale");
    return 0;
}

/* ---- handshake refusals ------------------------------------------------------- */

static int refused_both_sides(const char *tag, const char *const *fa, const char *const *da, const char *needle)
{
    char shm[128];
    unique_name(shm, sizeof shm, tag);
    tp_proc fem, dem;
    ENSURE(spawn_peer(&fem, "fem", shm, fa, 0) == 0);
    ENSURE(spawn_peer(&dem, "dem", shm, da, 0) == 0);
    int ok = tp_wait(&dem, 10) == 0 && tp_wait(&fem, 10) == 0;
    tp_kill(&dem);
    tp_kill(&fem);
    ENSURE(ok);
    ENSURE_EXIT(&dem, 3);
    ENSURE_EXIT(&fem, 3);
    ENSURE_LOG(&dem, needle);
    ENSURE_LOG(&fem, needle);
    ENSURE(!shm_exists(shm));
    return 0;
}

static int version_mismatch(void)
{
    const char *fa[] = {"--nodes", "100", NULL};
    const char *da[] = {"--version", "7", NULL};
    return refused_both_sides("ver", fa, da, "version mismatch");
}

static int size_mismatch(void)
{
    const char *fa[] = {"--nodes", "100", NULL};
    const char *da[] = {"--expect-nodes", "99", NULL};
    return refused_both_sides("size", fa, da, "size mismatch");
}

static int time_step_mismatch(void)
{
    const char *fa[] = {"--nodes", "100", "--expect-dt", "1e-05", NULL};
    const char *da[] = {"--dt", "2e-05", NULL};
    return refused_both_sides("dt", fa, da, "time step mismatch");
}

/* ---- corrupted segments: every size and index is checked -------------------- */

enum corruption {
    C_NODES, C_SEGSIZE, C_RING_OFFSET, C_SLOT_SIZE, C_HEADER_SIZE, C_MASS_OFFSET, C_TRI_INDEX, C_NAN_NODE,
    C_NEG_MASS, C_COUNT
};

static int corrupted_header_refused(void)
{
    static const char *const expect[C_COUNT] = {"size mismatch", "size mismatch", "size mismatch",
                                                "size mismatch", "size mismatch", "size mismatch",
                                                "invalid node indices", "non-finite", "has mass -1"};
    for (int c = 0; c < C_COUNT; c++) {
        char shm[128];
        unique_name(shm, sizeof shm, "corrupt");
        ipc_create_def def = ipc_default_create_def();
        def.n_nodes = 64;
        def.n_tris = 100;
        def.connect_timeout = 5;
        ipc_channel *ch;
        char err[512];
        ENSURE_MSG(ipc_create(shm, &def, &ch, err, sizeof err) == IPC_OK, "%s", err);
        double *x = ipc_surface_nodes(ch);
        uint32_t *t = ipc_surface_tris(ch);
        for (int i = 0; i < 3 * 64; i++)
            x[i] = 0.01 * i;
        for (int k = 0; k < 100; k++) {
            t[3 * k] = (uint32_t)(k % 64);
            t[3 * k + 1] = (uint32_t)((k + 1) % 64);
            t[3 * k + 2] = (uint32_t)((k + 2) % 64);
        }
        /* Reach into the segment as a buggy or hostile writer would. */
        int fd = shm_open(shm, O_RDWR, 0);
        ENSURE(fd >= 0);
        ipc_segment_header *h = mmap(NULL, IPC_PAGE, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
        close(fd);
        ENSURE(h != MAP_FAILED);
        switch (c) {
        case C_NODES: h->n_nodes = 65; break;
        case C_SEGSIZE: h->segment_size += 4096; break;
        case C_RING_OFFSET: h->ring_offset[IPC_ROLE_DEM] += 64; break;
        case C_SLOT_SIZE: h->slot_size[IPC_ROLE_FEM] = 1u << 30; break;
        case C_HEADER_SIZE: h->header_size = 12; break;
        case C_TRI_INDEX: t[3 * 57 + 1] = 64; break;
        case C_NAN_NODE: x[3 * 10 + 2] = NAN; break;
        case C_MASS_OFFSET: h->masses_offset -= 64; break;
        case C_NEG_MASS: ipc_surface_masses(ch)[33] = -1.0; break;
        }
        munmap(h, IPC_PAGE);
        tp_proc dem;
        const char *da[] = {"--connect", "5", NULL};
        ENSURE(spawn_peer(&dem, "dem", shm, da, 0) == 0);
        int rc = ipc_accept(ch); /* the DEM refuses: we must hear about it, not hang */
        int ok = tp_wait(&dem, 10) == 0;
        tp_kill(&dem);
        ipc_close(&ch, rc);
        ENSURE(ok);
        ENSURE_MSG(rc != IPC_OK, "corruption %d accepted", c);
        ENSURE_EXIT(&dem, 3);
        ENSURE_LOG(&dem, expect[c]);
        ENSURE(!shm_exists(shm));
    }
    return 0;
}

/* A frame whose sequence number is wrong (lost, repeated, reordered) stops
 * the receiver with a message naming both numbers. */
static int out_of_order_frame_refused(void)
{
    char shm[128];
    unique_name(shm, sizeof shm, "order");
    char err[512];
    /* Fork before the segment exists: ipc_create starts the heartbeat
     * thread, and a child forked from a threaded parent can inherit an
     * allocator lock held by that thread (it hung under AddressSanitizer).
     * The child's attach waits for the segment. */
    int corrupted[2], done[2]; /* child -> parent: frame 1 is corrupted; parent -> child: it was read */
    ENSURE(pipe(corrupted) == 0 && pipe(done) == 0);
    pid_t child = fork();
    if (child == 0) {
        /* DEM side in a child process: send frame 0, then a frame claiming seq 5. */
        close(corrupted[0]);
        close(done[1]);
        alarm(120); /* never outlive a lost parent */
        ipc_attach_def ad = ipc_default_attach_def();
        ad.dt = 1e-5;
        ipc_channel *dem;
        if (ipc_attach(shm, &ad, &dem, err, sizeof err))
            _exit(10);
        for (int k = 0; k < 2; k++) {
            ipc_frame_head *h;
            double *f;
            if (ipc_send_begin(dem, &h, &f))
                _exit(11);
            ipc_send_commit(dem);
            if (k == 1)
                h->seq = 5; /* corrupt it after the commit stamped it */
            const ipc_frame_head *rh;
            const double *p;
            if (k == 0) {
                if (ipc_recv(dem, &rh, &p))
                    _exit(12);
                ipc_recv_release(dem);
            }
        }
        tp_announce(corrupted[1], 'k');
        /* Stay attached until the parent has read the frame: closing first
         * would let it see a finished peer instead of the bad frame. */
        char c;
        while (read(done[0], &c, 1) < 0 && errno == EINTR)
            ;
        ipc_close(&dem, IPC_OK);
        _exit(0);
    }
    close(corrupted[1]);
    close(done[0]);
    ENSURE(child > 0);
    ipc_create_def def = ipc_default_create_def();
    def.n_nodes = 10;
    def.n_tris = 4;
    ipc_channel *fem;
    ENSURE(ipc_create(shm, &def, &fem, err, sizeof err) == IPC_OK);
    double *x = ipc_surface_nodes(fem);
    uint32_t *t = ipc_surface_tris(fem);
    for (int i = 0; i < 30; i++)
        x[i] = i;
    for (int k = 0; k < 4; k++) {
        t[3 * k] = (uint32_t)k;
        t[3 * k + 1] = (uint32_t)k + 1;
        t[3 * k + 2] = (uint32_t)k + 2;
    }
    int rc = ipc_accept(fem);
    ENSURE_MSG(rc == IPC_OK, "%s", ipc_error(fem));
    const ipc_frame_head *h;
    const double *f;
    ENSURE(ipc_recv(fem, &h, &f) == IPC_OK && h->seq == 0);
    ipc_recv_release(fem);
    ipc_frame_head *oh;
    double *p;
    ENSURE(ipc_send_begin(fem, &oh, &p) == IPC_OK);
    ENSURE(ipc_send_commit(fem) == IPC_OK);
    /* Read frame 1 only once the child says it has corrupted it. */
    char c = 0;
    ssize_t got;
    while ((got = read(corrupted[0], &c, 1)) < 0 && errno == EINTR)
        ;
    ENSURE_MSG(got == 1 && c == 'k', "the DEM child ended before corrupting its frame");
    rc = ipc_recv(fem, &h, &f);
    tp_announce(done[1], 'd');
    close(done[1]);
    close(corrupted[0]);
    int st;
    waitpid(child, &st, 0);
    ENSURE(rc == IPC_ERR_PROTOCOL);
    ENSURE_MSG(strstr(ipc_error(fem), "expected frame 1, got 5"), "%s", ipc_error(fem));
    ipc_close(&fem, rc);
    ENSURE(!shm_exists(shm));
    return 0;
}

static int names_and_layout(void)
{
    ENSURE(ipc_name_valid("/demfem-123_a.b"));
    ENSURE(!ipc_name_valid("demfem"));
    ENSURE(!ipc_name_valid("/"));
    ENSURE(!ipc_name_valid("/a/b"));
    ENSURE(!ipc_name_valid("/a b"));
    ipc_layout lay;
    ENSURE(ipc_layout_compute(0, 1, 2, &lay) != 0);
    ENSURE(ipc_layout_compute(IPC_MAX_NODES + 1, 1, 2, &lay) != 0);
    ENSURE(ipc_layout_compute(10, 1, 17, &lay) != 0);
    ENSURE(ipc_layout_compute(20000, 40000, 2, &lay) == 0);
    /* Slots hold the head plus the payload, aligned; rings do not overlap. */
    ENSURE(lay.slot_size[IPC_ROLE_FEM] >= sizeof(ipc_frame_head) + 3 * 20000 * 8);
    ENSURE(lay.slot_size[IPC_ROLE_DEM] >= sizeof(ipc_frame_head) + 6 * 20000 * 8);
    ENSURE(lay.masses_offset >= lay.nodes_offset + 3 * 20000 * 8);
    ENSURE(lay.tris_offset >= lay.masses_offset + 20000 * 8);
    ENSURE(lay.ring_offset[IPC_ROLE_FEM] >= lay.tris_offset + 3 * 40000 * 4);
    ENSURE(lay.ring_offset[IPC_ROLE_DEM] >= lay.ring_offset[IPC_ROLE_FEM] + 2 * lay.slot_size[IPC_ROLE_FEM]);
    ENSURE(lay.segment_size >= lay.ring_offset[IPC_ROLE_DEM] + 2 * lay.slot_size[IPC_ROLE_DEM]);
    ENSURE(lay.ring_offset[IPC_ROLE_FEM] % 64 == 0 && lay.slot_size[IPC_ROLE_DEM] % 64 == 0);
    /* The checksum sees a single flipped bit. */
    double a[100];
    for (int i = 0; i < 100; i++)
        a[i] = i * 0.5;
    uint64_t c0 = ipc_checksum(a, sizeof a);
    ((unsigned char *)a)[333] ^= 4;
    ENSURE(ipc_checksum(a, sizeof a) != c0);
    return 0;
}

static const test_case tests[] = {
    {"names_and_layout", names_and_layout},
    {"roundtrip_10000", roundtrip_10000},
    {"dem_starts_first", dem_starts_first},
    {"ring_of_four_slots", ring_of_four_slots},
    {"fem_killed", fem_killed},
    {"dem_killed", dem_killed},
    {"fem_stopped", fem_stopped},
    {"dem_stopped", dem_stopped},
    {"fem_sigterm", fem_sigterm},
    {"dem_sigint", dem_sigint},
    {"stale_segment_refused", stale_segment_refused},
    {"version_mismatch", version_mismatch},
    {"size_mismatch", size_mismatch},
    {"time_step_mismatch", time_step_mismatch},
    {"corrupted_header_refused", corrupted_header_refused},
    {"out_of_order_frame_refused", out_of_order_frame_refused},
};

int main(int argc, char **argv)
{
    signal(SIGPIPE, SIG_IGN);
    return test_main(argc, argv, tests, TEST_COUNT(tests));
}
