/* Exchange latency: round-trip time of one lockstep exchange through the
 * shared-memory ring, against a plain pipe ping-pong moving the same bytes,
 * measured in the same run for payloads from 1 kB to 2 MB.
 *
 * One exchange = DEM sends S bytes of forces, FEM answers 2 S bytes of
 * positions and velocities (the protocol's ratio). Both ends write every
 * byte they send and read every byte they receive, on both transports.
 *
 * usage: ipc_latency [CSV] [--busy N] [--max-bytes B] [--iters-div K]
 *   --busy N       N extra processes spinning in a busy loop for the whole
 *                  run (a loaded machine: more runnable threads than cores),
 *                  stopped by their pids at the end
 *   --max-bytes B  largest payload (default 2 MB)
 *   --iters-div K  K times fewer round trips per size (a loaded machine) */
#include <errno.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "ipc.h"

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static double touch_read(const double *p, size_t n)
{
    double s = 0;
    for (size_t i = 0; i < n; i++)
        s += p[i];
    return s;
}

static void touch_write(double *p, size_t n, double v)
{
    for (size_t i = 0; i < n; i++)
        p[i] = v + (double)i;
}

static volatile double g_sink;

/* ---- ring ------------------------------------------------------------------- */

static int ring_fem(const char *name, uint32_t nodes)
{
    ipc_create_def def = ipc_default_create_def();
    def.n_nodes = nodes;
    def.n_tris = 1;
    ipc_channel *ch;
    char err[512];
    if (ipc_create(name, &def, &ch, err, sizeof err)) {
        fprintf(stderr, "fem: %s\n", err);
        return 1;
    }
    uint32_t *t = ipc_surface_tris(ch);
    t[0] = 0, t[1] = nodes > 1 ? 1 : 0, t[2] = nodes > 2 ? 2 : 0;
    if (nodes < 3) { /* the surface check wants distinct indices */
        fprintf(stderr, "need >= 3 nodes\n");
        return 1;
    }
    if (ipc_accept(ch)) {
        fprintf(stderr, "fem: %s\n", ipc_error(ch));
        return 1;
    }
    size_t nr = ipc_recv_len(ch), ns = ipc_send_len(ch);
    for (;;) {
        const ipc_frame_head *in;
        const double *f;
        if (ipc_recv(ch, &in, &f))
            break;
        uint32_t kind = in->kind;
        g_sink += touch_read(f, nr);
        ipc_recv_release(ch);
        ipc_frame_head *out;
        double *p;
        if (ipc_send_begin(ch, &out, &p))
            break;
        out->kind = kind;
        touch_write(p, ns, 1.0);
        ipc_send_commit(ch);
        if (kind == IPC_FRAME_FINISH)
            break;
    }
    ipc_close(&ch, IPC_OK);
    return 0;
}

static double ring_dem(const char *name, int iters)
{
    ipc_attach_def def = ipc_default_attach_def();
    def.dt = 1e-5;
    ipc_channel *ch;
    char err[512];
    if (ipc_attach(name, &def, &ch, err, sizeof err)) {
        fprintf(stderr, "dem: %s\n", err);
        return -1;
    }
    size_t ns = ipc_send_len(ch), nr = ipc_recv_len(ch);
    double t0 = 0;
    int warm = iters / 10 + 10;
    for (int k = 0; k <= warm + iters; k++) {
        if (k == warm)
            t0 = now();
        int finish = k == warm + iters;
        ipc_frame_head *out;
        double *f;
        if (ipc_send_begin(ch, &out, &f))
            return -1;
        out->kind = finish ? IPC_FRAME_FINISH : IPC_FRAME_DATA;
        touch_write(f, ns, 2.0);
        ipc_send_commit(ch);
        const ipc_frame_head *in;
        const double *p;
        if (ipc_recv(ch, &in, &p))
            return -1;
        g_sink += touch_read(p, nr);
        ipc_recv_release(ch);
    }
    double t = (now() - t0) / (iters + 1);
    ipc_close(&ch, IPC_OK);
    return t;
}

static double ring_roundtrip(uint32_t nodes, int iters)
{
    char name[64];
    snprintf(name, sizeof name, "/demfem-bench-%d", (int)getpid());
    pid_t child = fork();
    if (child == 0)
        _exit(ring_fem(name, nodes));
    double t = ring_dem(name, iters);
    int st;
    waitpid(child, &st, 0);
    return t;
}

/* ---- pipe ------------------------------------------------------------------- */

static int full_io(int fd, void *buf, size_t len, int writing)
{
    char *p = buf;
    while (len > 0) {
        ssize_t n = writing ? write(fd, p, len) : read(fd, p, len);
        if (n <= 0) {
            if (n < 0 && errno == EINTR)
                continue;
            return -1;
        }
        p += n;
        len -= (size_t)n;
    }
    return 0;
}

static double pipe_roundtrip(uint32_t nodes, int iters)
{
    size_t ns = 3ull * nodes, nr = 6ull * nodes;
    int to_fem[2], to_dem[2];
    if (pipe(to_fem) || pipe(to_dem))
        return -1;
    pid_t child = fork();
    if (child == 0) {
        close(to_fem[1]);
        close(to_dem[0]);
        double *in = malloc(ns * sizeof *in), *out = malloc(nr * sizeof *out);
        while (full_io(to_fem[0], in, ns * sizeof *in, 0) == 0) {
            g_sink += touch_read(in, ns);
            touch_write(out, nr, 1.0);
            if (full_io(to_dem[1], out, nr * sizeof *out, 1))
                break;
        }
        _exit(0);
    }
    close(to_fem[0]);
    close(to_dem[1]);
    double *out = malloc(ns * sizeof *out), *in = malloc(nr * sizeof *in);
    double t0 = 0;
    int warm = iters / 10 + 10;
    for (int k = 0; k < warm + iters; k++) {
        if (k == warm)
            t0 = now();
        touch_write(out, ns, 2.0);
        if (full_io(to_fem[1], out, ns * sizeof *out, 1) || full_io(to_dem[0], in, nr * sizeof *in, 0))
            return -1;
        g_sink += touch_read(in, nr);
    }
    double t = (now() - t0) / iters;
    close(to_fem[1]);
    close(to_dem[0]);
    int st;
    waitpid(child, &st, 0);
    free(out);
    free(in);
    return t;
}

/* A busy process: burns its core until killed. */
static void busy_loop(void)
{
    volatile unsigned long x = 0;
    for (;;)
        x++;
}

int main(int argc, char **argv)
{
    const char *csv = NULL;
    int busy = 0;
    size_t max_bytes = 2u * 1024 * 1024;
    int iters_div = 1;
    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--busy") == 0 && i + 1 < argc)
            busy = atoi(argv[++i]);
        else if (strcmp(argv[i], "--max-bytes") == 0 && i + 1 < argc)
            max_bytes = (size_t)atol(argv[++i]);
        else if (strcmp(argv[i], "--iters-div") == 0 && i + 1 < argc)
            iters_div = atoi(argv[++i]) > 0 ? atoi(argv[i]) : 1;
        else if (argv[i][0] != '-')
            csv = argv[i];
        else {
            fprintf(stderr, "usage: %s [CSV] [--busy N] [--max-bytes B] [--iters-div K]\n", argv[0]);
            return 2;
        }
    }
    pid_t busy_pid[64];
    if (busy > 64)
        busy = 64;
    for (int k = 0; k < busy; k++) {
        busy_pid[k] = fork();
        if (busy_pid[k] == 0)
            busy_loop();
    }
    FILE *f = csv ? fopen(csv, "w") : NULL;
    if (csv && !f) {
        fprintf(stderr, "cannot write %s: %s\n", csv, strerror(errno));
        return 1;
    }
    if (f)
        fprintf(f, "payload_bytes,busy_processes,ring_roundtrip_us,pipe_roundtrip_us,ratio_ring_over_pipe\n");
    printf("%12s %14s %14s %10s\n", "payload [B]", "ring [us]", "pipe [us]", "ring/pipe");
    int worst_ok = 1;
    for (size_t bytes = 1024; bytes <= max_bytes; bytes *= 2) {
        uint32_t nodes = (uint32_t)(bytes / 24);
        if (nodes < 3)
            nodes = 3;
        int iters = (bytes <= 16384 ? 20000 : bytes <= 262144 ? 2000 : 300) / iters_div;
        if (iters < 20)
            iters = 20;
        /* Median of three runs per transport, interleaved, to tame the noise. */
        double r[3], p[3];
        for (int k = 0; k < 3; k++) {
            r[k] = ring_roundtrip(nodes, iters);
            p[k] = pipe_roundtrip(nodes, iters);
        }
#define MED3(a) ((a)[0] > (a)[1] ? ((a)[1] > (a)[2] ? (a)[1] : ((a)[0] > (a)[2] ? (a)[2] : (a)[0])) \
                                 : ((a)[0] > (a)[2] ? (a)[0] : ((a)[1] > (a)[2] ? (a)[2] : (a)[1])))
        double ring = MED3(r), pip = MED3(p);
        if (ring < 0 || pip < 0) {
            fprintf(stderr, "benchmark failed at %zu bytes\n", bytes);
            for (int k = 0; k < busy; k++)
                kill(busy_pid[k], SIGKILL), waitpid(busy_pid[k], NULL, 0);
            return 1;
        }
        size_t payload = (size_t)nodes * 24;
        printf("%12zu %14.2f %14.2f %10.3f\n", payload, 1e6 * ring, 1e6 * pip, ring / pip);
        if (f)
            fprintf(f, "%zu,%d,%.3f,%.3f,%.4f\n", payload, busy, 1e6 * ring, 1e6 * pip, ring / pip);
        worst_ok &= ring <= pip;
    }
    if (f)
        fclose(f);
    for (int k = 0; k < busy; k++) {
        kill(busy_pid[k], SIGKILL);
        waitpid(busy_pid[k], NULL, 0);
    }
    if (busy)
        printf("(with %d busy processes)\n", busy);
    printf("ring %s the pipe at every size\n", worst_ok ? "is at least as fast as" : "is NOT always faster than");
    return 0;
}
