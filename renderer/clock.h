/* renderer/clock.h (private): wall-clock seconds for statistics and progress (never for
 * results). */
#ifndef CANDELA_CLOCK_H
#define CANDELA_CLOCK_H

#include <time.h>

static inline double clock_seconds(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

#endif
