/* ipc over MPI: the start-up that makes the channel IPC_MPI_NAME ("mpi")
 * available (ipc.h), for programs built with MPI (DEMFEM_MPI).
 *
 * Launch both programs as one MPMD job, e.g.
 *   mpirun -np N dem_server --shm mpi ... : -np 1 fem_server --shm mpi ...
 * Each program calls ipc_mpi_start() first thing (every rank: it is
 * collective over MPI_COMM_WORLD), then uses the communicator it returns for
 * its own ranks' traffic, never MPI_COMM_WORLD (which holds both programs).
 * The first rank of each program then opens the channel with
 * ipc_create / ipc_attach(IPC_MPI_NAME, ...). PROTOCOL.md, "The MPI
 * transport", has the messages. */
#ifndef IPC_MPI_H
#define IPC_MPI_H

#include <mpi.h>
#include <stddef.h>

/* When an MPI launcher started this process (mpirun's environment), starts
 * MPI (MPI_Init), splits MPI_COMM_WORLD by program (the MPI_APPNUM
 * attribute) into *app and, in a job of exactly two programs, links their
 * first ranks for the channel IPC_MPI_NAME. Without a launcher it does
 * nothing and *app is MPI_COMM_NULL: the process runs as without MPI.
 * IPC_OK, or an IPC_* error with its message in err. */
int ipc_mpi_start(MPI_Comm *app, char *err, size_t errlen);

/* The number of programs in the job (1 without a launcher). */
int ipc_mpi_programs(void);

/* Frees what ipc_mpi_start made and ends MPI (MPI_Finalize) if it was
 * started and not yet ended. Safe to call when nothing was started. */
void ipc_mpi_stop(void);

#endif
