/* Wall-clock timing from the monotonic clock, for profiles and progress, and
 * the process's CPU time. */
#ifndef CM_TIMER_H
#define CM_TIMER_H

#include <time.h>

/* Seconds since an arbitrary fixed point (CLOCK_MONOTONIC). */
static inline double cm_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* CPU seconds the whole process has used (CLOCK_PROCESS_CPUTIME_ID): beside
 * the wall time, what a loaded machine does not inflate. */
static inline double cm_cpu_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* CPU seconds the calling thread has used (CLOCK_THREAD_CPUTIME_ID): over a
 * wait, what it spent spinning; the rest of the wait's wall time its core
 * ran something else. */
static inline double cm_thread_cpu_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

#endif
