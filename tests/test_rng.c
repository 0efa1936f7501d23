/* tests/test_rng.c: statistical checks of the counter-based generator in renderer/util/rng.h.
 *
 * All checks use 1e6 draws and 5-sigma bounds (or a chi-square p-value > 1e-3), with fixed
 * keys, so the outcome is deterministic. The draws are taken along each axis of the key space
 * the renderer uses: consecutive pixels, consecutive samples, consecutive dimensions, and
 * consecutive seeds. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "stats.h"
#include "rng.h"

#define N 1000000
#define SEED 0x12345678ull

/* Chi-square p-value of counts against a uniform expectation (all bins have 1000+ expected). */
static double uniform_chi2(const double *obs, int bins, double total) {
    double e = total / bins, stat = 0.0;
    for (int i = 0; i < bins; ++i) stat += (obs[i] - e) * (obs[i] - e) / e;
    return gamma_q(0.5 * (bins - 1), 0.5 * stat);
}

enum { AXIS_PIXEL, AXIS_SAMPLE, AXIS_DIM, AXIS_SEED, AXIS_STREAM, AXIS_COUNT };
static const char *axis_name[AXIS_COUNT] = {"pixel", "sample", "dim", "seed", "stream"};

/* The i-th draw along an axis (the other coordinates fixed at arbitrary values). */
static float draw(int axis, uint64_t i) {
    switch (axis) {
    case AXIS_PIXEL: return rng_uniform(rng_path_key(SEED, i, 3), 5);
    case AXIS_SAMPLE: return rng_uniform(rng_path_key(SEED, 777, i), 5);
    case AXIS_DIM: return rng_uniform(rng_path_key(SEED, 777, 3), (uint32_t)i);
    case AXIS_STREAM: { /* the i-th number of one sub-stream */
        RngStream st = rng_stream(rng_path_key(SEED, 777, 3), 2, RNG_STREAM_MEDIUM);
        st.next = (uint32_t)i;
        return rng_stream_next(&st);
    }
    default: return rng_uniform(rng_path_key(SEED + i, 777, 3), 5);
    }
}

/* Pearson correlation; under independence it is ~N(0, 1/n). */
static double correlation(const float *a, const float *b, int n) {
    double ma = 0, mb = 0;
    for (int i = 0; i < n; ++i) { ma += a[i]; mb += b[i]; }
    ma /= n;
    mb /= n;
    double sab = 0, saa = 0, sbb = 0;
    for (int i = 0; i < n; ++i) {
        sab += (a[i] - ma) * (b[i] - mb);
        saa += (a[i] - ma) * (a[i] - ma);
        sbb += (b[i] - mb) * (b[i] - mb);
    }
    return sab / sqrt(saa * sbb);
}

static void test_axis(int axis) {
    float *u = malloc(sizeof(float) * (N + 1));
    int out_of_range = 0, not_24bit = 0;
    for (uint64_t i = 0; i <= N; ++i) {
        float x = draw(axis, i);
        u[i] = x;
        if (!(x >= 0.0f && x < 1.0f)) ++out_of_range;
        if (x * 16777216.0f != floorf(x * 16777216.0f)) ++not_24bit;
    }
    CHECK(out_of_range == 0, "%s: %d draws outside [0,1)", axis_name[axis], out_of_range);
    CHECK(not_24bit == 0, "%s: %d draws not multiples of 2^-24", axis_name[axis], not_24bit);

    /* Mean 1/2, sd of the mean sqrt(1/12 / N); variance 1/12, sd of the sample variance
     * sqrt((mu4 - sigma^4) / N) = sqrt((1/80 - 1/144) / N) = sqrt(1/180 / N). */
    double mean = 0.0;
    for (int i = 0; i < N; ++i) mean += u[i];
    mean /= N;
    double var = 0.0;
    for (int i = 0; i < N; ++i) var += (u[i] - mean) * (u[i] - mean);
    var /= N - 1;
    double sd_mean = sqrt(1.0 / 12.0 / N), sd_var = sqrt(1.0 / 180.0 / N);
    fprintf(stderr, "  %-6s mean %.6f (%+.2f sigma)  var %.6f (%+.2f sigma)", axis_name[axis], mean,
            (mean - 0.5) / sd_mean, var, (var - 1.0 / 12.0) / sd_var);
    CHECK(fabs(mean - 0.5) < 5.0 * sd_mean, "%s: mean %.6f", axis_name[axis], mean);
    CHECK(fabs(var - 1.0 / 12.0) < 5.0 * sd_var, "%s: variance %.6f", axis_name[axis], var);

    /* 1000-bin histogram (1000 expected per bin). */
    double *h = calloc(1000, sizeof(double));
    for (int i = 0; i < N; ++i) h[(int)(u[i] * 1000.0f) < 1000 ? (int)(u[i] * 1000.0f) : 999] += 1.0;
    double p = uniform_chi2(h, 1000, N);
    fprintf(stderr, "  chi2(1000) p %.4f", p);
    CHECK(p > 1e-3, "%s: 1000-bin chi-square p = %g", axis_name[axis], p);
    free(h);

    /* Neighbours along the axis: lag-1 correlation and 32x32 uniformity of the pairs. */
    double r = correlation(u, u + 1, N);
    fprintf(stderr, "  lag-1 corr %+.5f (%+.2f sigma)", r, r * sqrt((double)N));
    CHECK(fabs(r) < 5.0 / sqrt((double)N), "%s: adjacent correlation %g", axis_name[axis], r);
    double *h2 = calloc(32 * 32, sizeof(double));
    for (int i = 0; i < N; ++i) h2[(int)(u[i] * 32.0f) * 32 + (int)(u[i + 1] * 32.0f)] += 1.0;
    p = uniform_chi2(h2, 32 * 32, N);
    fprintf(stderr, "  pairs chi2 p %.4f\n", p);
    CHECK(p > 1e-3, "%s: pair chi-square p = %g", axis_name[axis], p);
    free(h2);
    free(u);
}

/* Dimensions of one path must be independent of each other: correlation between dims d and
 * d+1 over many paths (each path = one pixel), for the dimensions the renderer uses. */
static void test_dims_across_paths(void) {
    enum { M = 200000 };
    float *a = malloc(sizeof(float) * M), *b = malloc(sizeof(float) * M);
    double worst = 0.0;
    for (uint32_t d = 0; d < 40; d += 3) {
        for (int i = 0; i < M; ++i) {
            uint64_t key = rng_path_key(SEED, (uint64_t)i, 0);
            a[i] = rng_uniform(key, d);
            b[i] = rng_uniform(key, d + 1);
        }
        double r = correlation(a, b, M);
        worst = fmax(worst, fabs(r) * sqrt((double)M));
        CHECK(fabs(r) < 5.0 / sqrt((double)M), "dims %u/%u correlated over paths: %g", d, d + 1, r);
    }
    /* Same dimension of adjacent pixels / adjacent samples. */
    for (int i = 0; i < M; ++i) {
        a[i] = rng_uniform(rng_path_key(SEED, (uint64_t)i, 9), 4);
        b[i] = rng_uniform(rng_path_key(SEED, (uint64_t)i + 1, 9), 4);
    }
    double r = correlation(a, b, M);
    worst = fmax(worst, fabs(r) * sqrt((double)M));
    CHECK(fabs(r) < 5.0 / sqrt((double)M), "adjacent pixels correlated: %g", r);
    for (int i = 0; i < M; ++i) {
        a[i] = rng_uniform(rng_path_key(SEED, 5, (uint64_t)i), 4);
        b[i] = rng_uniform(rng_path_key(SEED, 6, (uint64_t)i), 4);
    }
    r = correlation(a, b, M);
    worst = fmax(worst, fabs(r) * sqrt((double)M));
    CHECK(fabs(r) < 5.0 / sqrt((double)M), "same sample of adjacent pixels correlated: %g", r);
    /* Sub-streams: independent of the path's own dimensions and of the streams of other
     * bounces, over many paths. */
    for (uint32_t d = 0; d < 4; ++d) {
        uint32_t dim = rng_bounce_dim(d, (d * 5) % RNG_BOUNCE_DIMS);
        for (int i = 0; i < M; ++i) {
            uint64_t key = rng_path_key(SEED, (uint64_t)i, 1);
            RngStream st = rng_stream(key, d, RNG_STREAM_MEDIUM);
            a[i] = rng_stream_next(&st);
            b[i] = rng_uniform(key, dim);
        }
        r = correlation(a, b, M);
        worst = fmax(worst, fabs(r) * sqrt((double)M));
        CHECK(fabs(r) < 5.0 / sqrt((double)M), "stream of depth %u correlated with its bounce dims: %g", d, r);
        for (int i = 0; i < M; ++i) {
            RngStream next = rng_stream(rng_path_key(SEED, (uint64_t)i, 1), d + 1, RNG_STREAM_MEDIUM);
            b[i] = rng_stream_next(&next);
        }
        r = correlation(a, b, M);
        worst = fmax(worst, fabs(r) * sqrt((double)M));
        CHECK(fabs(r) < 5.0 / sqrt((double)M), "streams of depths %u and %u correlated: %g", d, d + 1, r);
    }
    fprintf(stderr, "  cross-path correlations: worst %.2f sigma\n", worst);
    free(a);
    free(b);
}

static int cmp_u64(const void *a, const void *b) {
    uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
    return (x > y) - (x < y);
}

static void test_determinism(void) {
    int mismatch = 0;
    for (uint64_t i = 0; i < 10000; ++i) {
        uint64_t k1 = rng_path_key(SEED, i, i * 7 + 1), k2 = rng_path_key(SEED, i, i * 7 + 1);
        if (k1 != k2 || rng_uniform(k1, (uint32_t)i) != rng_uniform(k2, (uint32_t)i)) ++mismatch;
    }
    CHECK(mismatch == 0, "same key gave different values %d times", mismatch);
    /* Keys of distinct (pixel, sample) pairs never collide (64-bit: a collision among 1e6 keys
     * has probability ~3e-8 for a good hash). */
    uint64_t *keys = malloc(sizeof(uint64_t) * N);
    for (int i = 0; i < N; ++i) keys[i] = rng_path_key(SEED, (uint64_t)(i / 1000), (uint64_t)(i % 1000));
    qsort(keys, N, sizeof(uint64_t), cmp_u64);
    int dup = 0;
    for (int i = 1; i < N; ++i) dup += keys[i] == keys[i - 1];
    CHECK(dup == 0, "%d duplicate path keys", dup);
    free(keys);
    /* Different seeds give different images. */
    CHECK(rng_path_key(1, 0, 0) != rng_path_key(2, 0, 0), "seed changes the key");
    /* The first draws of dimension 0 and 1 of a key differ (dims are not aliased). */
    int same = 0;
    for (uint64_t i = 0; i < 1000; ++i) {
        uint64_t k = rng_path_key(SEED, i, 0);
        same += rng_uniform(k, 0) == rng_uniform(k, 1);
    }
    CHECK(same < 3, "dims 0 and 1 equal %d times in 1000", same);
    /* The bounce layout stays inside its block. */
    CHECK(rng_bounce_dim(0, RNG_BOUNCE_LIGHT_SELECT) == RNG_DIM_CAMERA_END &&
              rng_bounce_dim(1, 0) == rng_bounce_dim(0, RNG_BOUNCE_DIMS - 1) + 1,
          "bounce dimension layout");
}

int main(void) {
    fprintf(stderr, "rng_uniform along each key axis (1e6 draws):\n");
    for (int a = 0; a < AXIS_COUNT; ++a) test_axis(a);
    test_dims_across_paths();
    test_determinism();
    return test_exit();
}
