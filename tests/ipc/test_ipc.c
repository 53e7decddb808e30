/* Protocol integration tests: two real processes (ipc_peer) on a real POSIX
 * shared-memory segment. Each test checks exit codes, what the survivor says
 * and how fast, and that nothing is left in /dev/shm. The peers announce
 * their progress on a readiness pipe (tests/proc.h): no case waits by
 * sleeping or by polling for a short-lived state.
 *
 * With DEMFEM_IPC_TRANSPORT=mpi the protocol cases run over the MPI
 * transport instead (ctest's test_ipc_mpi.*): both peers as one MPMD job of
 * the real mpirun (MPIEXEC, oversubscribed), `--shm mpi`. One status is
 * left for the job, so each side's exit code is read from its line
 * "ipc_peer ROLE: exit N" and its messages from its lines "ipc_peer ROLE...";
 * mpirun's processes inherit no pipe: they announce by creating files
 * (a lasting state, tp_wait_file). */
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

static int g_mpi; /* the MPI transport (DEMFEM_IPC_TRANSPORT=mpi) */

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
    snprintf(log, sizeof log, "/tmp/demfem-test-%d-%.8s-%.150s.log", (int)getpid(), role, shm + 1);
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

/* ---- a pair of peers over either transport -------------------------------------- */

typedef struct pair {
    char shm[128];
    tp_proc fem, dem; /* the ring: two processes */
    tp_proc job;      /* MPI: one mpirun with both */
    char ready[200];  /* MPI: readiness files ready.ROLE.MARK */
} pair;

#ifdef MPIEXEC
/* mpirun as the project runs it (oversubscribed, waiting ranks yield, no
 * cross-memory attach; components kept loaded for LeakSanitizer): argv's
 * first entries, their count returned. */
static int mpirun_argv(const char **argv)
{
    static const char *const head[] = {MPIEXEC, "--allow-run-as-root", "--oversubscribe", "--bind-to", "none",
                                       "--mca", "mpi_yield_when_idle", "1", "--mca",
                                       "btl_vader_single_copy_mechanism", "none", "--mca",
                                       "mca_base_component_disable_dlclose", "1"};
    int n = (int)(sizeof head / sizeof head[0]);
    for (int i = 0; i < n; i++)
        argv[i] = head[i];
    return n;
}
#endif

/* Starts the FEM peer with fa and the DEM peer with da (NULL-terminated). */
static int pair_start(pair *pr, const char *tag, const char *const *fa, const char *const *da, int flags)
{
    memset(pr, 0, sizeof *pr);
    pr->fem.status = pr->dem.status = pr->job.status = -1;
    pr->fem.pid = pr->dem.pid = pr->job.pid = 0;
    unique_name(pr->shm, sizeof pr->shm, tag);
    if (!g_mpi) {
        int rc = spawn_peer(&pr->fem, "fem", pr->shm, fa, flags);
        return rc ? rc : spawn_peer(&pr->dem, "dem", pr->shm, da, flags);
    }
#ifdef MPIEXEC
    snprintf(pr->ready, sizeof pr->ready, "/tmp%s", pr->shm);
    char fem_ready[220], dem_ready[220];
    snprintf(fem_ready, sizeof fem_ready, "%s.fem", pr->ready);
    snprintf(dem_ready, sizeof dem_ready, "%s.dem", pr->ready);
    const char *argv[100];
    int n = mpirun_argv(argv);
    for (int side = 0; side < 2; side++) {
        const char *const *args = side == 0 ? fa : da;
        if (side == 1)
            argv[n++] = ":";
        argv[n++] = "-np";
        argv[n++] = "1";
        argv[n++] = IPC_PEER_PATH;
        argv[n++] = "--role";
        argv[n++] = side == 0 ? "fem" : "dem";
        argv[n++] = "--shm";
        argv[n++] = IPC_MPI_NAME;
        if (flags & TP_READY) {
            argv[n++] = "--ready-file";
            argv[n++] = side == 0 ? fem_ready : dem_ready;
        }
        for (int i = 0; args && args[i] && n < 90; i++)
            argv[n++] = args[i];
    }
    argv[n] = NULL;
    char log[256];
    snprintf(log, sizeof log, "/tmp/demfem-test-%d-mpi-%s.log", (int)getpid(), pr->shm + 1);
    return tp_spawn(&pr->job, argv, log, TP_NEW_GROUP);
#else
    return ENOSYS;
#endif
}

static tp_proc *pair_side(pair *pr, const char *role) { return strcmp(role, "fem") == 0 ? &pr->fem : &pr->dem; }

/* Waits for both to end: 0 when they did within timeout_s. */
static int pair_wait(pair *pr, double timeout_s)
{
    if (g_mpi)
        return tp_wait(&pr->job, timeout_s);
    return tp_wait(&pr->dem, timeout_s) == 0 && tp_wait(&pr->fem, timeout_s) == 0 ? 0 : -1;
}

static void pair_kill(pair *pr)
{
    if (g_mpi) {
        tp_kill(&pr->job);
        for (const char *r = "fem"; r; r = strcmp(r, "fem") == 0 ? "dem" : NULL)
            for (const char *m = "cax"; *m; m++) {
                char path[240];
                snprintf(path, sizeof path, "%s.%s.%c", pr->ready, r, *m);
                unlink(path);
            }
        return;
    }
    tp_kill(&pr->fem);
    tp_kill(&pr->dem);
}

/* The side's mark came (a byte on its pipe, or its file): 0, else -1. */
static int pair_wait_ready(pair *pr, const char *role, char mark, double timeout_s)
{
    if (!g_mpi)
        return tp_wait_ready(pair_side(pr, role), mark, timeout_s);
    char path[240];
    snprintf(path, sizeof path, "%s.%s.%c", pr->ready, role, mark);
    return tp_wait_file(path, timeout_s, &pr->job);
}

/* The side's pid (MPI: from its readiness file of mark 'x'). */
static pid_t pair_pid(pair *pr, const char *role)
{
    if (!g_mpi)
        return pair_side(pr, role)->pid;
    char path[240];
    int pid = 0;
    snprintf(path, sizeof path, "%s.%s.x", pr->ready, role);
    FILE *f = fopen(path, "r");
    if (f && fscanf(f, "%d", &pid) != 1)
        pid = 0;
    if (f)
        fclose(f);
    return (pid_t)pid;
}

/* Over MPI: a line of the job's log starting with "ipc_peer ROLE" that holds needle. */
static int job_line_has(const tp_proc *job, const char *role, const char *needle)
{
    char prefix[32];
    snprintf(prefix, sizeof prefix, "ipc_peer %s", role);
    const char *text = tp_log_text(job);
    for (const char *line = text; line && *line;) {
        const char *end = strchr(line, '\n');
        size_t len = end ? (size_t)(end - line) : strlen(line);
        if (strncmp(line, prefix, strlen(prefix)) == 0) {
            char buf[2048];
            snprintf(buf, sizeof buf, "%.*s", (int)(len < sizeof buf ? len : sizeof buf - 1), line);
            if (strstr(buf, needle))
                return 1;
        }
        line = end ? end + 1 : NULL;
    }
    return 0;
}

/* The side's exit code (MPI: its line "ipc_peer ROLE: exit N"), -1 if unknown. */
static int pair_exit(pair *pr, const char *role)
{
    if (!g_mpi)
        return pair_side(pr, role)->status;
    for (int code = 0; code < 8; code++) {
        char line[40];
        snprintf(line, sizeof line, ": exit %d", code);
        if (job_line_has(&pr->job, role, line))
            return code;
    }
    return -1;
}

static int pair_log_has(pair *pr, const char *role, const char *needle)
{
    return g_mpi ? job_line_has(&pr->job, role, needle) : tp_log_has(pair_side(pr, role), needle);
}

static void pair_print_log(pair *pr, const char *role)
{
    tp_print_log(g_mpi ? &pr->job : pair_side(pr, role));
}

#define ENSURE_SIDE_EXIT(pr, role, code)                                                          \
    do {                                                                                          \
        int got_ = pair_exit(pr, role);                                                           \
        if (got_ != (code)) {                                                                     \
            fprintf(stderr, "%s:%d: the %s side exited %d, expected %d; its log:\n", __FILE__,     \
                    __LINE__, role, got_, (code));                                                \
            pair_print_log(pr, role);                                                             \
            return 1;                                                                             \
        }                                                                                         \
    } while (0)

#define ENSURE_SIDE_LOG(pr, role, needle)                                                         \
    do {                                                                                          \
        if (!pair_log_has(pr, role, needle)) {                                                    \
            fprintf(stderr, "%s:%d: the %s side's log lacks \"%s\"; its log:\n", __FILE__, __LINE__, \
                    role, needle);                                                                \
            pair_print_log(pr, role);                                                             \
            return 1;                                                                             \
        }                                                                                         \
    } while (0)

/* ---- normal runs -------------------------------------------------------------- */

/* 10 000 round trips of 20 000 nodes (480 kB out, 960 kB back), checksummed,
 * every value checked by the receiving process. */
static int roundtrip_10000(void)
{
    pair pr;
    const char *fa[] = {"--nodes", "20000", "--checksum", "--expect-dt", "1e-05", NULL};
    /* over MPI 2000: a large frame's fragments wait on naps (ipc_mpi.c) */
    const char *exchanges = g_mpi ? "2000" : "10000";
    const char *da[] = {"--exchanges", exchanges, "--dt", "1e-05", NULL};
    char ok_line[64];
    snprintf(ok_line, sizeof ok_line, "%s exchanges ok", exchanges);
    double t0 = tp_now();
    ENSURE(pair_start(&pr, "rt", fa, da, 0) == 0);
    int ok = pair_wait(&pr, 300) == 0;
    double wall = tp_now() - t0;
    pair_kill(&pr);
    ENSURE(ok);
    ENSURE_SIDE_EXIT(&pr, "dem", 0);
    ENSURE_SIDE_EXIT(&pr, "fem", 0);
    ENSURE_SIDE_LOG(&pr, "fem", ok_line);
    ENSURE_SIDE_LOG(&pr, "dem", ok_line);
    ENSURE(!shm_exists(pr.shm));
    printf("  %s round trips of 20000 nodes in %.2f s (%.0f us each, incl. filling and checking)\n", exchanges, wall,
           1e6 * wall / atof(exchanges));
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
    pair pr;
    const char *fa[] = {"--nodes", "300", "--slots", "4", "--expect-dt", "5e-05", NULL};
    const char *da[] = {"--exchanges", "3000", "--dt", "1e-05", "--every", "5", NULL};
    ENSURE(pair_start(&pr, "slots", fa, da, 0) == 0);
    int ok = pair_wait(&pr, 120) == 0;
    pair_kill(&pr);
    ENSURE(ok);
    ENSURE_SIDE_EXIT(&pr, "dem", 0);
    ENSURE_SIDE_EXIT(&pr, "fem", 0);
    ENSURE_SIDE_LOG(&pr, "dem", "3000 exchanges ok");
    return 0;
}

/* ---- a peer dies, stops or is interrupted ---------------------------------------- */

/* Over MPI: the pair exchanging, sig to one side's process. SIGTERM/SIGINT
 * raise its stop flag: it stops waiting and fails with a reason the
 * survivor prints, and both end. SIGKILL: mpirun ends the whole job (the
 * survivor too, killed by mpirun: it cannot hang) and names the victim. */
static int peer_lost_mpi(const char *victim_role, int sig, const char *survivor_says)
{
    pair pr;
    const char *fa[] = {"--nodes", "2000", NULL};
    const char *da[] = {"--exchanges", "100000000", NULL};
    ENSURE(pair_start(&pr, victim_role, fa, da, TP_READY) == 0);
    int up = pair_wait_ready(&pr, "fem", 'x', 60) == 0 && pair_wait_ready(&pr, "dem", 'x', 60) == 0;
    pid_t victim = up ? pair_pid(&pr, victim_role) : 0;
    if (!up || victim <= 0) {
        pair_kill(&pr);
        tp_print_log(&pr.job);
        ENSURE_MSG(0, "the pair did not start exchanging within 60 s");
    }
    const char *survivor = strcmp(victim_role, "fem") == 0 ? "dem" : "fem";
    double t_kill = tp_now();
    kill(victim, sig);
    int ended = tp_wait(&pr.job, 30.0) == 0;
    double dt = ended ? pr.job.t_exit - t_kill : 99;
    pair_kill(&pr);
    ENSURE_MSG(ended && dt < 10.0, "the job took %.2f s to end", dt);
    ENSURE_MSG(pr.job.status != 0, "the job exited 0");
    if (sig == SIGKILL) {
        ENSURE_MSG(strstr(tp_log_text(&pr.job), "exited on signal 9"), "mpirun did not name the killed process");
    } else {
        ENSURE_SIDE_LOG(&pr, victim_role, "interrupted");
        ENSURE_SIDE_EXIT(&pr, victim_role, 3);
        ENSURE_SIDE_EXIT(&pr, survivor, 3);
        ENSURE_SIDE_LOG(&pr, survivor, survivor_says);
    }
    printf("  %s got signal %d: the MPI job exited %d after %.3f s\n", victim_role, sig, pr.job.status, dt);
    return 0;
}

/* Starts a long run, waits until it is exchanging, delivers sig to one side;
 * the other must exit non-zero within 2 s naming the victim. */
static int peer_lost(const char *victim_role, int sig, const char *survivor_says)
{
    if (g_mpi)
        return peer_lost_mpi(victim_role, sig, survivor_says);
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
    pair pr;
    ENSURE(pair_start(&pr, tag, fa, da, 0) == 0);
    int ok = pair_wait(&pr, 60) == 0;
    pair_kill(&pr);
    ENSURE(ok);
    ENSURE_SIDE_EXIT(&pr, "dem", 3);
    ENSURE_SIDE_EXIT(&pr, "fem", 3);
    ENSURE_SIDE_LOG(&pr, "dem", needle);
    ENSURE_SIDE_LOG(&pr, "fem", needle);
    ENSURE(!shm_exists(pr.shm));
    return 0;
}

/* ---- a failure's reason reaches the peer ------------------------------------- */

/* One side gives up at exchange 7 with a reason (ipc_fail); the other must
 * stop and print that reason, naming the peer. */
static int failure_reason(const char *who)
{
    pair pr;
    const char *give_up[] = {"--nodes", "500", "--checksum", "--fail-at", "7", NULL};
    const char *plain_fem[] = {"--nodes", "500", "--checksum", NULL};
    const char *plain_dem[] = {"--exchanges", "1000", NULL};
    const int fem_fails = strcmp(who, "fem") == 0;
    const char *give_up_dem[] = {"--exchanges", "1000", "--fail-at", "7", NULL};
    ENSURE(pair_start(&pr, "reason", fem_fails ? give_up : plain_fem, fem_fails ? plain_dem : give_up_dem, 0) == 0);
    int ok = pair_wait(&pr, 60) == 0;
    pair_kill(&pr);
    ENSURE(ok);
    const char *other = fem_fails ? "dem" : "fem";
    char says[160];
    snprintf(says, sizeof says, "peer %s failed: ipc_peer %s gave up at exchange 7", who, who);
    ENSURE_SIDE_EXIT(&pr, who, 3);
    ENSURE_SIDE_EXIT(&pr, other, 3);
    ENSURE_SIDE_LOG(&pr, other, says);
    ENSURE(!shm_exists(pr.shm));
    return 0;
}

static int fem_failure_reason(void) { return failure_reason("fem"); }
static int dem_failure_reason(void) { return failure_reason("dem"); }

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

#if defined(MPIEXEC) && defined(IPC_ROGUE_PATH)
/* Over MPI nothing received is trusted either: a DEM peer (ipc_rogue) sends
 * frame 1 with one fault each time; the FEM side refuses it naming the
 * fault, and the rogue hears that reason. */
static int bad_frames_refused(void)
{
    static const char *const faults[] = {"seq", "checksum", "kind", "size"};
    static const char *const says[] = {"expected frame 1, got 5", "payload checksum mismatch", "has unknown kind 9",
                                       "has 1512 bytes, expected 1520"}; /* 320 + 3 x 50 x 8, one double short */
    for (int k = 0; k < 4; k++) {
        const char *argv[60];
        int n = mpirun_argv(argv);
        const char *rest[] = {"-np", "1", IPC_PEER_PATH, "--role", "fem", "--shm", IPC_MPI_NAME, "--nodes", "50",
                              "--checksum", ":", "-np", "1", IPC_ROGUE_PATH, "--corrupt", faults[k], NULL};
        for (int i = 0; rest[i]; i++)
            argv[n++] = rest[i];
        argv[n] = NULL;
        char log[256];
        snprintf(log, sizeof log, "/tmp/demfem-test-%d-rogue-%s.log", (int)getpid(), faults[k]);
        tp_proc job;
        ENSURE(tp_spawn(&job, argv, log, TP_NEW_GROUP) == 0);
        int ok = tp_wait(&job, 60) == 0;
        tp_kill(&job);
        ENSURE_MSG(ok, "the job with a bad frame (%s) did not end within 60 s", faults[k]);
        if (!job_line_has(&job, "fem", says[k]) || !job_line_has(&job, "fem", ": exit 3") ||
            !strstr(tp_log_text(&job), "ipc_rogue: refused: peer fem failed") ||
            !strstr(tp_log_text(&job), "ipc_rogue: exit 0")) {
            tp_print_log(&job);
            ENSURE_MSG(0, "fault %s: the FEM side did not refuse the frame with \"%s\", or the rogue did not hear it",
                       faults[k], says[k]);
        }
        printf("  bad frame (%s) refused: %s\n", faults[k], says[k]);
    }
    return 0;
}
#endif

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
    {"fem_failure_reason", fem_failure_reason},
    {"dem_failure_reason", dem_failure_reason},
    {"corrupted_header_refused", corrupted_header_refused},
    {"out_of_order_frame_refused", out_of_order_frame_refused},
};

/* The cases that run over the MPI transport too (ctest's test_ipc_mpi.*,
 * tests/ipc/CMakeLists.txt). Not over MPI: the segment's own cases (names,
 * stale and corrupted segments), a peer started late (mpirun starts both),
 * a stopped peer (no heartbeat over MPI: PROTOCOL.md). */
#ifdef MPIEXEC
static const test_case mpi_tests[] = {
    {"roundtrip_10000", roundtrip_10000},
    {"ring_of_four_slots", ring_of_four_slots},
    {"version_mismatch", version_mismatch},
    {"size_mismatch", size_mismatch},
    {"time_step_mismatch", time_step_mismatch},
    {"fem_failure_reason", fem_failure_reason},
    {"dem_failure_reason", dem_failure_reason},
    {"fem_sigterm", fem_sigterm},
    {"dem_sigint", dem_sigint},
    {"fem_killed", fem_killed},
    {"dem_killed", dem_killed},
#ifdef IPC_ROGUE_PATH
    {"bad_frames_refused", bad_frames_refused},
#endif
};
#endif

int main(int argc, char **argv)
{
    signal(SIGPIPE, SIG_IGN);
    const char *transport = getenv("DEMFEM_IPC_TRANSPORT");
    g_mpi = transport && strcmp(transport, "mpi") == 0;
#ifdef MPIEXEC
    if (g_mpi)
        return test_main(argc, argv, mpi_tests, TEST_COUNT(mpi_tests));
#endif
    return test_main(argc, argv, tests, TEST_COUNT(tests));
}
