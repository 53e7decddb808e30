/* SIGINT/SIGTERM handling shared by the servers; see signals.h. */
#include "signals.h"

#include <string.h>
#include <unistd.h>

static cm_signal_flags g_flags;

static void on_signal(int sig)
{
    if (!g_flags.interrupt && g_flags.graceful)
        alarm(10);
    g_flags.interrupt = sig;
    if (!g_flags.graceful) /* before the exchange loop: stop at once */
        g_flags.stop = sig;
}

static void on_alarm(int sig) { g_flags.stop = g_flags.interrupt ? g_flags.interrupt : sig; }

cm_signal_flags *cm_signals_install(void)
{
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal; /* no SA_RESTART: waits wake up and see the flags */
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    sa.sa_handler = on_alarm;
    sigaction(SIGALRM, &sa, NULL);
    return &g_flags;
}

void cm_signals_graceful(int on)
{
    g_flags.graceful = on != 0;
    if (on && g_flags.interrupt) /* one that came during the set-up */
        alarm(10);
}
