/* Process harness shared by the tests that start real processes (tests/ipc, tests/scm,
 * tests/coupling): spawn with the output in a log file, wait for an exit with
 * a timeout, kill by the pid we started, and a readiness pipe.
 *
 * Synchronisation rule (tests must pass on an idle and on a loaded machine):
 * a test never decides that something happened by polling for a short-lived
 * state or by sleeping. It waits for a signal that cannot be missed:
 *   - a byte on the readiness pipe (tp_wait_ready): the child finds the pipe's
 *     write end at file descriptor TP_READY_FD and writes one byte at each
 *     point it announces; the read end sees EOF if the child dies first;
 *   - a state that, once reached, stays (a file that appears, a count of
 *     rows that only grows: tp_wait_file), re-checked until a generous
 *     timeout. */
#ifndef DEMFEM_TEST_PROC_H
#define DEMFEM_TEST_PROC_H

#include <stddef.h>
#include <sys/types.h>

/* The descriptor at which a child started with TP_READY finds the pipe. */
#define TP_READY_FD 3
#define TP_READY_FD_TEXT "3"

enum {
    TP_READY = 1 << 0,     /* give the child a readiness pipe at TP_READY_FD */
    TP_NEW_GROUP = 1 << 1, /* the child leads a process group of its own (a launcher and its servers);
                              tp_kill signals the whole group */
};

typedef struct tp_proc {
    pid_t pid;
    int status;     /* exit status as a shell reports it (128 + signal), -1 while running */
    int flags;
    int ready_fd;   /* read end of the readiness pipe, -1 without one */
    double t_start; /* s, monotonic */
    double t_exit;  /* s, monotonic, when tp_wait saw the exit */
    char log[320];  /* standard output and error of the child */
} tp_proc;

/* Monotonic time in s; a short sleep for re-checking a lasting state. */
double tp_now(void);
void tp_nap_ms(int ms);

/* Starts argv[0] (a path) with argv, its output to log (truncated). 0 or an
 * errno value. */
int tp_spawn(tp_proc *p, const char *const *argv, const char *log, int flags);

/* Forks a child that runs body(arg, ready_fd) and exits with its return
 * value (its output stays this process's). With TP_READY, ready_fd is the
 * write end of the readiness pipe (for tp_announce), else -1. A child that
 * uses the ipc library itself, in place of a server. 0 or an errno value. */
int tp_fork(tp_proc *p, int (*body)(void *arg, int ready_fd), void *arg, int flags);

/* Waits for the byte `mark` on the readiness pipe (bytes before it are
 * skipped). 0 when it came; -1 on timeout or when the child closed the pipe
 * (exited) without sending it. */
int tp_wait_ready(tp_proc *p, char mark, double timeout_s);

/* Waits up to timeout_s for the child to exit and reaps it. 0 when it exited
 * (p->status and p->t_exit set), -1 when it is still running. */
int tp_wait(tp_proc *p, double timeout_s);

/* tp_wait, and when the child is still running after timeout_s, tp_kill:
 * the exit status as a shell reports it (128 + signal), or -1 on timeout. */
int tp_finish(tp_proc *p, double timeout_s);

/* SIGKILL (to its group with TP_NEW_GROUP) and reap, if still running;
 * closes the readiness pipe. Safe to call twice. */
void tp_kill(tp_proc *p);

/* Whether the child pid has exited (it stays a zombie for waitpid). */
int tp_pid_exited(pid_t pid);

/* Waits until path exists (a lasting state: a file written once by the
 * child and renamed into place). 0 when it does; -1 on timeout or when `who`
 * (if given) exited first. */
int tp_wait_file(const char *path, double timeout_s, tp_proc *who);

/* The child's whole log, NUL-terminated, in a static buffer (valid until the
 * next call); whether it contains needle; copy it to stderr. */
const char *tp_log_text(const tp_proc *p);
int tp_log_has(const tp_proc *p, const char *needle);
void tp_print_log(const tp_proc *p);

/* A server's run record (DIR/NAME, common/runrec.h, e.g. dem_run.json):
 * the number after "key": (0 when found, -1 otherwise); whether its text
 * contains needle. */
int tp_record_num(const char *dir, const char *name, const char *key, double *v);
int tp_record_has(const char *dir, const char *name, const char *needle);

/* Child side: writes `mark` on the readiness pipe handed down as fd (from a
 * command-line option); a no-op for fd < 0. */
void tp_announce(int fd, char mark);

#endif
