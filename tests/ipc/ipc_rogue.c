/* ipc_rogue: a broken DEM peer on the MPI transport (the ring's test
 * corrupts the segment itself, test_ipc.out_of_order_frame_refused). It
 * attaches and exchanges frame 0 as the protocol says, then sends frame 1
 * as raw bytes with one fault, which the FEM side must refuse:
 *   --corrupt seq       the head says frame 5
 *   --corrupt checksum  the payload's checksum is off by one bit
 *   --corrupt kind      an unknown kind (9)
 *   --corrupt size      one double short
 * Run as the second program of an MPMD job with ipc_peer --role fem --shm mpi
 * --checksum. Exit 0 when the FEM side refused the frame with a reason (the
 * line "ipc_rogue: refused: ..."), 1 otherwise. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "channel.h"
#include "ipc.h"
#include "ipc_mpi.h"

/* ipc_peer's forces (ipc_peer.c), which its FEM side checks */
static double value(unsigned long long seq, size_t j)
{
    return (double)((seq * 2654435761ull + j * 40503ull) % 1000003ull) * 1e-3 - 500.0;
}

static int run(const char *fault)
{
    ipc_attach_def def = ipc_default_attach_def();
    def.dt = 1e-5;
    def.connect_timeout = 60;
    ipc_channel *ch;
    char err[512];
    if (ipc_attach(IPC_MPI_NAME, &def, &ch, err, sizeof err)) {
        fprintf(stderr, "ipc_rogue: attach: %s\n", err);
        return 1;
    }
    ipc_frame_head *out;
    double *f;
    const ipc_frame_head *in;
    const double *p;
    const size_t nf = ipc_send_len(ch);
    int rc = ipc_send_begin(ch, &out, &f);
    if (rc == IPC_OK) {
        for (size_t j = 0; j < nf; j++)
            f[j] = value(0, j);
        rc = ipc_send_commit(ch);
    }
    if (rc == IPC_OK && (rc = ipc_recv(ch, &in, &p)) == IPC_OK)
        rc = ipc_recv_release(ch);
    if (rc) {
        fprintf(stderr, "ipc_rogue: frame 0: %s\n", ipc_error(ch));
        ipc_close(&ch, rc);
        return 1;
    }
    /* frame 1, by hand */
    size_t bytes = sizeof(ipc_frame_head) + nf * sizeof(double);
    unsigned char *buf = calloc(1, bytes);
    if (!buf)
        return 1;
    ipc_frame_head *h = (ipc_frame_head *)buf;
    double *payload = (double *)(h + 1);
    for (size_t j = 0; j < nf; j++)
        payload[j] = value(1, j);
    h->seq = 1;
    h->kind = IPC_FRAME_DATA;
    h->checksum = ipc_checksum(payload, nf * sizeof(double));
    if (strcmp(fault, "seq") == 0)
        h->seq = 5;
    else if (strcmp(fault, "checksum") == 0)
        h->checksum ^= 1;
    else if (strcmp(fault, "kind") == 0)
        h->kind = 9;
    else if (strcmp(fault, "size") == 0)
        bytes -= sizeof(double);
    rc = ipc_mpi_send_raw(ch, buf, (int)bytes);
    free(buf);
    if (rc == IPC_OK)
        rc = ipc_recv(ch, &in, &p); /* the FEM's answer: its failure */
    int refused = rc == IPC_ERR_PEER_FAILED;
    fprintf(stderr, "ipc_rogue: %s: %s\n", refused ? "refused" : "not refused", rc ? ipc_error(ch) : "a reply came");
    ipc_close(&ch, rc ? rc : IPC_ERR_PROTOCOL);
    return refused ? 0 : 1;
}

int main(int argc, char **argv)
{
    if (argc != 3 || strcmp(argv[1], "--corrupt") != 0) {
        fprintf(stderr, "usage: ipc_rogue --corrupt seq|checksum|kind|size\n");
        return 2;
    }
    MPI_Comm own;
    char err[256];
    if (ipc_mpi_start(&own, err, sizeof err)) {
        fprintf(stderr, "ipc_rogue: %s\n", err);
        return 1;
    }
    int rc = run(argv[2]);
    fprintf(stderr, "ipc_rogue: exit %d\n", rc);
    ipc_mpi_stop();
    return rc;
}
