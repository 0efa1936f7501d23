/* tests/check.h: the test suite's whole framework. Each test program is one meson test;
 * CHECK records a failure with file:line and keeps going; test_exit() returns 0 (pass),
 * 1 (fail) or 77 (skip, meson's convention). */
#ifndef CANDELA_CHECK_H
#define CANDELA_CHECK_H

#include <stdio.h>
#include <stdlib.h>
#include <time.h>

static int check_failures = 0;
static int check_count = 0;

#define CHECK(cond, ...)                                                         \
    do {                                                                         \
        ++check_count;                                                           \
        if (!(cond)) {                                                           \
            ++check_failures;                                                    \
            fprintf(stderr, "FAIL %s:%d: %s: ", __FILE__, __LINE__, #cond);      \
            fprintf(stderr, __VA_ARGS__);                                        \
            fputc('\n', stderr);                                                 \
        }                                                                        \
    } while (0)

#define SKIP(...)                                                                \
    do {                                                                         \
        fprintf(stderr, "SKIP: ");                                               \
        fprintf(stderr, __VA_ARGS__);                                            \
        fputc('\n', stderr);                                                     \
        exit(77);                                                                \
    } while (0)

/* Wall-clock seconds, for what a test prints (never for what it asserts: a test proves
 * results, the benchmarks measure time). */
static inline double test_seconds(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static inline int test_exit(void) {
    fprintf(stderr, "%d checks, %d failed\n", check_count, check_failures);
    return check_failures ? 1 : 0;
}

#endif
