/* renderer/util/clock.h (private): wall-clock seconds for statistics and progress (never for
 * results). */
#ifndef CANDELA_CLOCK_H
#define CANDELA_CLOCK_H

#include <time.h>

static inline double clock_seconds(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* CPU seconds of the whole process (all threads): what a step cost, less disturbed than the
 * wall clock by other processes on a busy machine (statistics only). */
static inline double clock_cpu_seconds(void) {
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

#endif
