/* The servers' handling of SIGINT/SIGTERM, one implementation for
 * dem_server, fem_server and scm_server.
 *
 * While the server's exchange loop can write a checkpoint (graceful set by
 * the server), a first SIGINT/SIGTERM sets `interrupt` (the signal number):
 * the server checkpoints the next exchange and ends cleanly. If the run has
 * not ended 10 s later (SIGALRM), or the signal came before the loop could
 * checkpoint (graceful clear), `stop` is set as well: every wait gives up
 * (ipc waits watch it through their stop_flag) and the server exits with
 * 128 + the signal number. A second signal does not cut the 10 s short.
 * Handlers are installed without SA_RESTART, so blocking waits wake up and
 * see the flags. */
#ifndef CM_SIGNALS_H
#define CM_SIGNALS_H

#include <signal.h>

typedef struct cm_signal_flags {
    volatile sig_atomic_t stop;      /* stop at once: the signal number, 0 when none */
    volatile sig_atomic_t interrupt; /* checkpoint and stop: the first signal's number */
    volatile sig_atomic_t graceful;  /* set by the server while a checkpoint-and-stop can be honoured */
} cm_signal_flags;

/* Installs the handlers for SIGINT, SIGTERM and SIGALRM (the 10 s limit)
 * and returns the process's flags (all clear). Call once, from main. */
cm_signal_flags *cm_signals_install(void);

/* Sets graceful to on (the exchange loop starts, on != 0, or has ended).
 * A signal that came during the set-up, while graceful was clear, starts
 * the 10 s limit here. */
void cm_signals_graceful(int on);

#endif
