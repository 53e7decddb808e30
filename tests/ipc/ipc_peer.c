/* ipc_peer: a stand-in for either server that speaks the exchange protocol
 * with synthetic, verifiable payloads. The protocol tests run two of these as
 * real processes; it is also the smallest example of a third-party solver.
 *
 *   ipc_peer --role fem|dem --shm NAME [options]
 *
 * The DEM side sends forces f_j(seq) = value(seq, j); the FEM side checks
 * every value and answers positions f_j + 1 and velocities -f_j, which the
 * DEM side checks in turn. Any difference is a failure (exit 4). Exit codes:
 * 0 ok, 2 usage, 3 protocol/peer error, 4 wrong payload content.
 *
 * With --ready-fd FD it announces where it is on that descriptor (a pipe the
 * test holds, tests/proc.h), one byte each: 'c' the FEM side has created the
 * segment, 'a' the DEM side is about to attach, 'x' the first exchange is
 * done (both sides). With --ready-file PATH it creates the file PATH.<mark>
 * holding its pid instead (under mpirun, whose processes inherit no pipe).
 *
 * --shm mpi: the MPI transport; launch both roles as one MPMD job,
 *   mpirun -np 1 ipc_peer --role fem --shm mpi ... : -np 1 ipc_peer --role dem --shm mpi ...
 * --fail-at K: this side gives up at exchange K with a reason (ipc_fail)
 * that the other side must print. Each side ends with the line
 * "ipc_peer ROLE: exit CODE" (under mpirun, where one status is left). */
#include <errno.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "ipc.h"
#include "proc.h"
#ifdef DEMFEM_MPI
#include "ipc_mpi.h"
#endif

static volatile sig_atomic_t g_stop;

static void on_signal(int sig)
{
    (void)sig;
    g_stop = 1;
}

typedef struct options {
    const char *role, *shm;
    unsigned nodes, tris, exchanges, every, version, expect_nodes, slots;
    double dt, expect_dt, stall, connect, spin_us;
    int checksum, delay_ms, quiet, ready_fd, fail_at;
    const char *ready_file;
} options;

/* Announces `mark` on the readiness pipe or as the file ready_file.<mark>
 * (written whole, then renamed into place: it appears complete). */
static void announce(const options *o, char mark)
{
    tp_announce(o->ready_fd, mark);
    if (!o->ready_file)
        return;
    char tmp[620], path[600];
    snprintf(path, sizeof path, "%s.%c", o->ready_file, mark);
    snprintf(tmp, sizeof tmp, "%s.tmp", path);
    FILE *f = fopen(tmp, "w");
    if (!f)
        return;
    fprintf(f, "%d\n", (int)getpid());
    if (fclose(f) == 0)
        rename(tmp, path);
}

/* --fail-at: gives up at exchange n with a reason for the peer. */
static int give_up(const options *o, ipc_channel **ch, unsigned long long n)
{
    ipc_fail(*ch, "ipc_peer %s gave up at exchange %llu (--fail-at)", o->role, n);
    ipc_close(ch, IPC_ERR_PROTOCOL);
    fprintf(stderr, "ipc_peer %s: error: gave up at exchange %llu\n", o->role, n);
    return 3;
}

static double value(unsigned long long seq, size_t j)
{
    return (double)((seq * 2654435761ull + j * 40503ull) % 1000003ull) * 1e-3 - 500.0;
}

static int usage(void)
{
    fprintf(stderr,
            "usage: ipc_peer --role fem|dem --shm /NAME|mpi [--nodes N] [--tris M] [--exchanges K] [--dt S] "
            "[--every K] [--expect-dt S] [--expect-nodes N] [--version V] [--checksum] [--slots S] "
            "[--stall S] [--connect S] [--spin-us U] [--delay-ms D] [--ready-fd FD] [--ready-file PATH] "
            "[--fail-at K] [--quiet]\n");
    return 2;
}

static int fail(const char *role, int code, const char *msg)
{
    fprintf(stderr, "ipc_peer %s: error: %s\n", role, msg);
    return code;
}

static int run_fem(const options *o)
{
    ipc_create_def def = ipc_default_create_def();
    def.n_nodes = o->nodes;
    def.n_tris = o->tris;
    def.ring_slots = o->slots;
    def.checksum = o->checksum;
    def.exchange_dt = o->expect_dt;
    def.stall_timeout = o->stall;
    def.connect_timeout = o->connect;
    def.spin_us = o->spin_us;
    def.stop_flag = &g_stop;
    def.version = o->version;
    ipc_channel *ch;
    char err[512];
    int rc = ipc_create(o->shm, &def, &ch, err, sizeof err);
    if (rc)
        return fail("fem", 3, err);
    announce(o, 'c');
    double *x = ipc_surface_nodes(ch);
    uint32_t *t = ipc_surface_tris(ch);
    for (size_t i = 0; i < o->nodes; i++) {
        x[3 * i] = 1e-3 * (double)i;
        x[3 * i + 1] = 2e-3 * (double)i;
        x[3 * i + 2] = 3e-3 * (double)i;
    }
    for (size_t k = 0; k < o->tris; k++) {
        t[3 * k] = (uint32_t)(k % o->nodes);
        t[3 * k + 1] = (uint32_t)((k + 1) % o->nodes);
        t[3 * k + 2] = (uint32_t)((k + 2) % o->nodes);
    }
    rc = ipc_accept(ch);
    if (rc) {
        fail("fem", 3, ipc_error(ch));
        ipc_close(&ch, rc);
        return 3;
    }
    size_t nf = ipc_recv_len(ch), ns = ipc_send_len(ch);
    unsigned long long n = 0;
    for (;; n++) {
        const ipc_frame_head *in;
        const double *f;
        rc = ipc_recv(ch, &in, &f);
        if (rc)
            break;
        uint32_t kind = in->kind;
        if (o->fail_at > 0 && n == (unsigned long long)o->fail_at)
            return give_up(o, &ch, n);
        for (size_t j = 0; j < nf && kind == IPC_FRAME_DATA; j++)
            if (f[j] != value(n, j)) {
                char m[200];
                snprintf(m, sizeof m, "force %zu of exchange %llu is %.17g, sent %.17g", j, n, f[j], value(n, j));
                ipc_fail(ch, "%s", m);
                ipc_close(&ch, IPC_ERR_PROTOCOL);
                return fail("fem", 4, m);
            }
        ipc_frame_head *out;
        double *p;
        rc = ipc_send_begin(ch, &out, &p);
        if (rc)
            break;
        out->kind = kind;
        out->time = in->time;
        out->info[IPC_INFO_CENTER_X] = (double)n;
        for (size_t j = 0; j < nf && kind == IPC_FRAME_DATA; j++) {
            p[j] = f[j] + 1.0;
            p[nf + j] = -f[j];
        }
        (void)ns;
        ipc_recv_release(ch);
        rc = ipc_send_commit(ch);
        if (rc || kind == IPC_FRAME_FINISH)
            break;
        if (n == 0)
            announce(o, 'x');
    }
    if (rc) {
        fail("fem", 3, ipc_error(ch));
        ipc_close(&ch, rc);
        return 3;
    }
    ipc_stats st = ipc_get_stats(ch);
    if (!o->quiet)
        printf("ipc_peer fem: %llu exchanges ok, waited %.3f s\n", n, st.wait_recv_s + st.wait_send_s);
    ipc_close(&ch, IPC_OK);
    return 0;
}

static int run_dem(const options *o)
{
    ipc_attach_def def = ipc_default_attach_def();
    def.dt = o->dt;
    def.exchange_every = o->every;
    def.expect_nodes = o->expect_nodes;
    def.stall_timeout = o->stall;
    def.connect_timeout = o->connect;
    def.spin_us = o->spin_us;
    def.stop_flag = &g_stop;
    def.version = o->version;
    ipc_channel *ch;
    char err[512];
    announce(o, 'a');
    int rc = ipc_attach(o->shm, &def, &ch, err, sizeof err);
    if (rc)
        return fail("dem", 3, err);
    uint32_t nn = ipc_surface_node_count(ch);
    const double *x = ipc_surface_nodes(ch);
    for (size_t i = 0; i < nn; i++)
        if (x[3 * i + 2] != 3e-3 * (double)i) {
            ipc_close(&ch, IPC_ERR_PROTOCOL);
            return fail("dem", 4, "surface node positions differ from what the FEM peer wrote");
        }
    size_t nf = ipc_send_len(ch);
    unsigned long long n = 0;
    for (; n <= o->exchanges; n++) {
        int finish = n == o->exchanges;
        if (o->fail_at > 0 && n == (unsigned long long)o->fail_at)
            return give_up(o, &ch, n);
        ipc_frame_head *out;
        double *f;
        rc = ipc_send_begin(ch, &out, &f);
        if (rc)
            break;
        out->kind = finish ? IPC_FRAME_FINISH : IPC_FRAME_DATA;
        out->time = (double)n * o->dt * o->every;
        for (size_t j = 0; j < nf && !finish; j++)
            f[j] = value(n, j);
        rc = ipc_send_commit(ch);
        if (rc)
            break;
        const ipc_frame_head *in;
        const double *p;
        rc = ipc_recv(ch, &in, &p);
        if (rc)
            break;
        int bad = in->kind != (finish ? IPC_FRAME_FINISH : IPC_FRAME_DATA) || in->info[IPC_INFO_CENTER_X] != (double)n;
        for (size_t j = 0; j < nf && !finish && !bad; j++)
            bad = p[j] != value(n, j) + 1.0 || p[nf + j] != -value(n, j);
        ipc_recv_release(ch);
        if (bad) {
            char m[160];
            snprintf(m, sizeof m, "reply to exchange %llu does not match what was sent", n);
            ipc_fail(ch, "%s", m);
            ipc_close(&ch, IPC_ERR_PROTOCOL);
            return fail("dem", 4, m);
        }
        if (n == 0)
            announce(o, 'x');
    }
    if (rc) {
        fail("dem", 3, ipc_error(ch));
        ipc_close(&ch, rc);
        return 3;
    }
    ipc_stats st = ipc_get_stats(ch);
    if (!o->quiet)
        printf("ipc_peer dem: %u exchanges ok, waited %.3f s\n", o->exchanges, st.wait_recv_s + st.wait_send_s);
    ipc_close(&ch, IPC_OK);
    return 0;
}

int main(int argc, char **argv)
{
    options o = {.nodes = 1000, .exchanges = 100, .every = 1, .dt = 1e-5, .stall = 1.0, .connect = 10.0,
                 .spin_us = 50.0, .slots = 2, .ready_fd = -1};
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        const char *v = i + 1 < argc ? argv[i + 1] : NULL;
#define OPT(name) (strcmp(a, name) == 0 && v && (++i, 1))
        if (OPT("--role")) o.role = v;
        else if (OPT("--shm")) o.shm = v;
        else if (OPT("--nodes")) o.nodes = (unsigned)strtoul(v, NULL, 10);
        else if (OPT("--tris")) o.tris = (unsigned)strtoul(v, NULL, 10);
        else if (OPT("--exchanges")) o.exchanges = (unsigned)strtoul(v, NULL, 10);
        else if (OPT("--every")) o.every = (unsigned)strtoul(v, NULL, 10);
        else if (OPT("--version")) o.version = (unsigned)strtoul(v, NULL, 10);
        else if (OPT("--expect-nodes")) o.expect_nodes = (unsigned)strtoul(v, NULL, 10);
        else if (OPT("--slots")) o.slots = (unsigned)strtoul(v, NULL, 10);
        else if (OPT("--dt")) o.dt = strtod(v, NULL);
        else if (OPT("--expect-dt")) o.expect_dt = strtod(v, NULL);
        else if (OPT("--stall")) o.stall = strtod(v, NULL);
        else if (OPT("--connect")) o.connect = strtod(v, NULL);
        else if (OPT("--spin-us")) o.spin_us = strtod(v, NULL);
        else if (OPT("--delay-ms")) o.delay_ms = atoi(v);
        else if (OPT("--ready-fd")) o.ready_fd = atoi(v);
        else if (OPT("--ready-file")) o.ready_file = v;
        else if (OPT("--fail-at")) o.fail_at = atoi(v);
        else if (strcmp(a, "--checksum") == 0) o.checksum = 1;
        else if (strcmp(a, "--quiet") == 0) o.quiet = 1;
        else return usage();
#undef OPT
    }
    if (!o.role || !o.shm)
        return usage();
    if (!o.tris)
        o.tris = 2 * o.nodes;
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal; /* no SA_RESTART: waits wake up and see the flag */
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    signal(SIGPIPE, SIG_IGN); /* a test that stopped listening on the readiness pipe must not kill us */
    if (o.delay_ms > 0) {
        struct timespec ts = {o.delay_ms / 1000, (long)(o.delay_ms % 1000) * 1000000L};
        nanosleep(&ts, NULL);
    }
    if (strcmp(o.role, "fem") != 0 && strcmp(o.role, "dem") != 0)
        return usage();
#ifdef DEMFEM_MPI
    MPI_Comm own;
    char err[256];
    if (ipc_mpi_start(&own, err, sizeof err))
        return fail(o.role, 3, err);
#endif
    int rc = strcmp(o.role, "fem") == 0 ? run_fem(&o) : run_dem(&o);
    fprintf(stderr, "ipc_peer %s: exit %d\n", o.role, rc);
#ifdef DEMFEM_MPI
    ipc_mpi_stop();
#endif
    return rc;
}
