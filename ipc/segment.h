/* ipc internals: the layout of the shared-memory segment.
 *
 * Private to ipc/ (tests reach it through a private include path to corrupt
 * segments on purpose). Nothing here is a pointer: offsets and indices only.
 * PROTOCOL.md describes the same layout for writers of other solvers. */
#ifndef IPC_SEGMENT_H
#define IPC_SEGMENT_H

#include <semaphore.h>
#include <stdatomic.h>
#include <stdint.h>

#include "ipc.h"

/* "DEMFEMIP" read as a little-endian 64-bit integer. */
#define IPC_MAGIC 0x50494d4546454d44ull

#define IPC_PAGE 4096u
#define IPC_ALIGN 64u
#define IPC_REASON_LEN 256

/* Frames travel in two rings, indexed by the role that RECEIVES them:
 * ring[IPC_ROLE_FEM] carries DEM->FEM forces, ring[IPC_ROLE_DEM] FEM->DEM positions. */
typedef struct ipc_segment_header {
    /* --- Stable prefix: identical in every protocol version, so that a peer
     * of another version can still read who we are and leave a reason. --- */
    _Atomic uint64_t magic;        /* IPC_MAGIC, stored last by the creator */
    uint32_t version;              /* protocol version of the creator */
    uint32_t header_size;          /* sizeof(ipc_segment_header) */
    uint64_t segment_size;         /* bytes in the whole segment */
    _Atomic uint32_t state;        /* ipc_state */
    _Atomic int32_t failed_role;   /* role that failed first, 0 if none */
    char fail_reason[IPC_REASON_LEN];

    /* --- Version 1 --- */
    _Atomic int32_t pid[3];          /* by role; 0 until attached */
    _Atomic uint64_t heartbeat_ns[3];/* CLOCK_MONOTONIC, by role, every 50 ms */
    uint32_t n_nodes, n_tris;
    uint32_t ring_slots;
    uint32_t flags;                  /* IPC_SEG_* */
    uint64_t nodes_offset, masses_offset, tris_offset;
    uint64_t ring_offset[3];         /* by receiving role */
    uint64_t slot_size[3];           /* bytes per frame incl. head, by receiving role */
    uint64_t payload_len[3];         /* doubles per frame, by receiving role */
    _Atomic uint32_t surface_ready;  /* 1 once the FEM has written the surface */
    uint32_t dem_version;            /* hello: the DEM's protocol version */
    uint32_t dem_exchange_every;     /* hello: DEM steps per exchange */
    uint32_t reserved_;
    double dem_dt;                   /* hello: DEM time step [s] */
    double fem_exchange_dt;          /* FEM's expected exchange interval [s], 0 = any */
    sem_t sem_hello;                 /* DEM -> FEM: hello written */
    sem_t sem_ack;                   /* FEM -> DEM: hello answered (state tells how) */
    sem_t sem_full[3];               /* frames ready, by receiving role */
    sem_t sem_empty[3];              /* free slots, by receiving role */
} ipc_segment_header;

enum { IPC_SEG_CHECKSUM = 1u };

/* Byte offsets of the stable prefix: fixed forever. */
_Static_assert(sizeof(uint64_t) == 8 && sizeof(double) == 8, "64-bit types expected");
_Static_assert(__builtin_offsetof(ipc_segment_header, version) == 8, "stable prefix moved");
_Static_assert(__builtin_offsetof(ipc_segment_header, segment_size) == 16, "stable prefix moved");
_Static_assert(__builtin_offsetof(ipc_segment_header, state) == 24, "stable prefix moved");
_Static_assert(__builtin_offsetof(ipc_segment_header, fail_reason) == 32, "stable prefix moved");
_Static_assert(sizeof(ipc_frame_head) == 320, "frame head is 320 bytes");
_Static_assert(sizeof(ipc_frame_head) % IPC_ALIGN == 0, "payloads start aligned");
_Static_assert(sizeof(ipc_segment_header) <= IPC_PAGE, "header fits one page");

/* The layout implied by the counts; both sides compute it, the attacher
 * compares it field by field with what the header claims. */
typedef struct ipc_layout {
    uint64_t nodes_offset, masses_offset, tris_offset;
    uint64_t ring_offset[3], slot_size[3], payload_len[3];
    uint64_t segment_size;
} ipc_layout;

/* Returns 0 and fills lay, or -1 when the counts are out of range. */
int ipc_layout_compute(uint32_t n_nodes, uint32_t n_tris, uint32_t slots, ipc_layout *lay);

#endif
