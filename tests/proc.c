/* Process harness for the tests that start real processes: see proc.h. */
#include "proc.h"

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

extern char **environ;

double tp_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

void tp_nap_ms(int ms)
{
    struct timespec ts = {ms / 1000, (long)(ms % 1000) * 1000000L};
    while (nanosleep(&ts, &ts) != 0 && errno == EINTR)
        ;
}

int tp_spawn(tp_proc *p, const char *const *argv, const char *log, int flags)
{
    memset(p, 0, sizeof *p);
    p->pid = -1;
    p->status = -1;
    p->ready_fd = -1;
    p->flags = flags;
    snprintf(p->log, sizeof p->log, "%s", log);
    int pipe_fd[2] = {-1, -1};
    if (flags & TP_READY) {
        /* Close-on-exec ends, moved above the low descriptors: no other child
         * inherits the write end (the read end must see EOF when this child
         * dies), and dup2 onto TP_READY_FD is never a dup onto itself. (The
         * tests spawn from one thread: nothing can start between pipe and
         * the moves.) */
        int raw[2];
        if (pipe(raw) != 0)
            return errno;
        pipe_fd[0] = fcntl(raw[0], F_DUPFD_CLOEXEC, 10);
        pipe_fd[1] = fcntl(raw[1], F_DUPFD_CLOEXEC, 10);
        close(raw[0]);
        close(raw[1]);
        if (pipe_fd[0] < 0 || pipe_fd[1] < 0) {
            int e = errno;
            if (pipe_fd[0] >= 0)
                close(pipe_fd[0]);
            if (pipe_fd[1] >= 0)
                close(pipe_fd[1]);
            return e;
        }
    }
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 1, log, O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_adddup2(&fa, 1, 2);
    if (flags & TP_READY)
        posix_spawn_file_actions_adddup2(&fa, pipe_fd[1], TP_READY_FD); /* dup2 clears close-on-exec */
    posix_spawnattr_t at;
    posix_spawnattr_init(&at);
    if (flags & TP_NEW_GROUP) {
        posix_spawnattr_setflags(&at, POSIX_SPAWN_SETPGROUP);
        posix_spawnattr_setpgroup(&at, 0);
    }
    p->t_start = tp_now();
    int rc = posix_spawn(&p->pid, argv[0], &fa, &at, (char *const *)argv, environ);
    posix_spawn_file_actions_destroy(&fa);
    posix_spawnattr_destroy(&at);
    if (flags & TP_READY) {
        close(pipe_fd[1]);
        if (rc == 0)
            p->ready_fd = pipe_fd[0];
        else
            close(pipe_fd[0]);
    }
    if (rc != 0)
        p->pid = -1;
    return rc;
}

int tp_fork(tp_proc *p, int (*body)(void *arg, int ready_fd), void *arg, int flags)
{
    memset(p, 0, sizeof *p);
    p->pid = -1;
    p->status = -1;
    p->ready_fd = -1;
    p->flags = flags & ~TP_NEW_GROUP;
    int fds[2] = {-1, -1};
    if ((flags & TP_READY) && pipe(fds) != 0)
        return errno;
    if (fds[0] >= 0)
        fcntl(fds[0], F_SETFD, FD_CLOEXEC); /* a process spawned later does not hold it */
    fflush(NULL); /* nothing buffered is written twice */
    p->t_start = tp_now();
    pid_t pid = fork();
    if (pid == 0) {
        if (fds[0] >= 0)
            close(fds[0]);
        _exit(body(arg, fds[1]));
    }
    int e = errno;
    if (fds[1] >= 0)
        close(fds[1]);
    if (pid < 0) {
        if (fds[0] >= 0)
            close(fds[0]);
        return e;
    }
    p->pid = pid;
    p->ready_fd = fds[0];
    return 0;
}

int tp_wait_ready(tp_proc *p, char mark, double timeout_s)
{
    if (p->ready_fd < 0)
        return -1;
    double t_end = tp_now() + timeout_s;
    for (;;) {
        double left = t_end - tp_now();
        if (left <= 0)
            return -1;
        struct pollfd pf = {.fd = p->ready_fd, .events = POLLIN};
        int n = poll(&pf, 1, (int)(left * 1000) + 1);
        if (n < 0 && errno == EINTR)
            continue;
        if (n <= 0)
            return -1;
        char c;
        ssize_t r = read(p->ready_fd, &c, 1);
        if (r < 0 && errno == EINTR)
            continue;
        if (r <= 0)
            return -1; /* EOF: the child is gone without announcing it */
        if (c == mark)
            return 0;
    }
}

int tp_wait(tp_proc *p, double timeout_s)
{
    if (p->status != -1)
        return 0;
    if (p->pid <= 0)
        return -1;
    double t0 = tp_now();
    for (;;) {
        int st;
        pid_t r = waitpid(p->pid, &st, WNOHANG);
        if (r == p->pid) {
            p->status = WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
            p->t_exit = tp_now();
            if (p->ready_fd >= 0) {
                close(p->ready_fd);
                p->ready_fd = -1;
            }
            return 0;
        }
        if (tp_now() - t0 > timeout_s)
            return -1;
        tp_nap_ms(2); /* an exited child stays a zombie until reaped: nothing to miss */
    }
}

int tp_finish(tp_proc *p, double timeout_s)
{
    if (tp_wait(p, timeout_s) != 0) {
        tp_kill(p);
        return -1;
    }
    return p->status;
}

void tp_kill(tp_proc *p)
{
    if (p->pid > 0 && p->status == -1) {
        kill((p->flags & TP_NEW_GROUP) ? -p->pid : p->pid, SIGKILL);
        int st;
        while (waitpid(p->pid, &st, 0) < 0 && errno == EINTR)
            ;
        p->status = 128 + SIGKILL;
        p->t_exit = tp_now();
    }
    if (p->ready_fd >= 0) {
        close(p->ready_fd);
        p->ready_fd = -1;
    }
}

int tp_pid_exited(pid_t pid)
{
    siginfo_t si;
    memset(&si, 0, sizeof si);
    return waitid(P_PID, (id_t)pid, &si, WEXITED | WNOHANG | WNOWAIT) != 0 || si.si_pid == pid;
}

int tp_wait_file(const char *path, double timeout_s, tp_proc *who)
{
    double t0 = tp_now();
    for (;;) {
        if (access(path, F_OK) == 0)
            return 0;
        if (who && (who->status != -1 || tp_pid_exited(who->pid)))
            return access(path, F_OK) == 0 ? 0 : -1;
        if (tp_now() - t0 > timeout_s)
            return -1;
        tp_nap_ms(2);
    }
}

const char *tp_log_text(const tp_proc *p)
{
    static char buf[1 << 18];
    FILE *f = fopen(p->log, "r");
    size_t n = f ? fread(buf, 1, sizeof buf - 1, f) : 0;
    if (f)
        fclose(f);
    buf[n] = '\0';
    return buf;
}

int tp_log_has(const tp_proc *p, const char *needle) { return strstr(tp_log_text(p), needle) != NULL; }

void tp_print_log(const tp_proc *p)
{
    fprintf(stderr, "---- %s ----\n%s---- end of %s ----\n", p->log, tp_log_text(p), p->log);
}

/* The record's text (a few hundred bytes) in buf; -1 when unreadable. */
static int record_text(const char *dir, const char *name, char *buf, size_t cap)
{
    char path[400];
    snprintf(path, sizeof path, "%s/%s", dir, name);
    FILE *f = fopen(path, "r");
    if (!f)
        return -1;
    size_t n = fread(buf, 1, cap - 1, f);
    fclose(f);
    buf[n] = '\0';
    return 0;
}

int tp_record_num(const char *dir, const char *name, const char *key, double *v)
{
    char text[8192], pat[80];
    if (record_text(dir, name, text, sizeof text))
        return -1;
    snprintf(pat, sizeof pat, "\"%s\": ", key);
    const char *p = strstr(text, pat);
    return p && sscanf(p + strlen(pat), "%lf", v) == 1 ? 0 : -1;
}

int tp_record_has(const char *dir, const char *name, const char *needle)
{
    char text[8192];
    return record_text(dir, name, text, sizeof text) == 0 && strstr(text, needle) != NULL;
}

void tp_announce(int fd, char mark)
{
    if (fd < 0)
        return;
    ssize_t w;
    do
        w = write(fd, &mark, 1);
    while (w < 0 && errno == EINTR);
}
