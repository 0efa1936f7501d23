/* tests/test_sequence.c: the Owen-scrambled Sobol' sequence of renderer/util/sequence.h.
 *
 * - the generator: the tables equal the direction numbers' matrix product for random indices;
 *   the unscrambled first two dimensions are a (0,2)-sequence (every aligned block of 2^m
 *   points is a (0,m,2)-net), every dimension a (0,1)-sequence;
 * - the sequence a path draws (shuffle + Sobol' + Owen scramble + float): for many pixels and
 *   groups, the first 2^m samples of a group's lanes 0-1 are a (0,m,2)-net for m = 0..12 and
 *   every lane's first 2^m samples hit each interval of length 2^-m once (so the shuffle and
 *   the scramble keep the stratification, and the 24-bit truncation keeps it to 2^12 samples);
 * - uniformity of each lane over pixels (chi-square), and independence where the renderer
 *   needs it: neighbouring pixels' sequences, different groups of one sample, different
 *   depths, different seeds (Pearson correlation within 5 / sqrt(n), i.e. 5 sigma);
 * - dims_bounce and a group's dims_lane give the same numbers; the independent sequence is
 *   rng_uniform at rng.h's dimensions. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "stats.h"
#include "sequence.h"

static SobolTables T;

/* A path's dims for (seed, pixel, sample). */
static PathDims dims_of(uint64_t seed, uint32_t pixel, uint32_t sample) {
    PathDims d = {rng_path_key(seed, pixel, sample), &T, sequence_pixel_scramble(seed, pixel), sequence_reverse_bits(sample)};
    return d;
}

/* Sobol' dimension d of index i (MSB-first, 32 bits) by the plain matrix product. */
static uint32_t sobol_plain(int d, uint32_t i) {
    uint32_t x = 0;
    for (int k = 0; k < 32; ++k)
        if (i & (1u << k)) x ^= sequence_direction(d, k);
    return sequence_reverse_bits(x);
}

/* 1 if the 2^m points (x, y) (32-bit fixed point) are a (0,m,2)-net: every elementary interval
 * of area 2^-m (2^a x 2^(m-a) cells) holds exactly one point. */
static int is_net(const uint32_t *x, const uint32_t *y, int m) {
    uint32_t n = 1u << m;
    uint8_t *seen = malloc(n);
    int ok = 1;
    for (int a = 0; a <= m && ok; ++a) {
        memset(seen, 0, n);
        for (uint32_t i = 0; i < n; ++i) {
            uint32_t cx = a ? x[i] >> (32 - a) : 0, cy = (m - a) ? y[i] >> (32 - (m - a)) : 0;
            uint32_t cell = (cx << (m - a)) | cy;
            if (seen[cell]++) { ok = 0; break; }
        }
    }
    free(seen);
    return ok;
}

static int is_stratified_1d(const uint32_t *x, int m) {
    uint32_t n = 1u << m;
    uint8_t *seen = calloc(n, 1);
    int ok = 1;
    for (uint32_t i = 0; i < n && ok; ++i)
        if (seen[m ? x[i] >> (32 - m) : 0]++) ok = 0;
    free(seen);
    return ok;
}

static void test_generator(void) {
    /* tables against the matrix product, through the same shuffle-free path: y = reversed index */
    uint64_t state = 12345;
    int mismatches = 0;
    for (int t = 0; t < 100000; ++t) {
        state = rng_mix64(state + 1);
        uint32_t i = (uint32_t)state & 0xffffffu;
        uint32_t y = sequence_reverse_bits(i);
        for (uint32_t d = 0; d < 4; ++d) {
            if (sequence_reverse_bits(sequence_sobol_reversed(&T, d, y)) != sobol_plain((int)d, i)) ++mismatches;
            /* bits 24-31 of the index (y's low byte) are ignored */
            if (sequence_sobol_reversed(&T, d, y | (uint32_t)(state >> 56)) != sequence_sobol_reversed(&T, d, y)) ++mismatches;
        }
    }
    CHECK(mismatches == 0, "%d table lookups differ from the matrix product", mismatches);
    /* the start of dimension 1 in index (not Gray-code) order: 1/2, 3/4, 1/4, 5/8, 1/8 */
    static const double want[5] = {0.5, 0.75, 0.25, 0.625, 0.125};
    for (int i = 1; i <= 5; ++i)
        CHECK(sobol_plain(1, (uint32_t)i) / 4294967296.0 == want[i - 1], "dimension 1, index %d: %g", i,
              sobol_plain(1, (uint32_t)i) / 4294967296.0);
    /* the first points in Gray-code order (as scipy's unscrambled Sobol' lists them): point k is
     * the index k ^ (k >> 1) */
    static const double gray[8][4] = {{0, 0, 0, 0},
                                      {0.5, 0.5, 0.5, 0.5},
                                      {0.75, 0.25, 0.25, 0.25},
                                      {0.25, 0.75, 0.75, 0.75},
                                      {0.375, 0.375, 0.625, 0.875},
                                      {0.875, 0.875, 0.125, 0.375},
                                      {0.625, 0.125, 0.875, 0.625},
                                      {0.125, 0.625, 0.375, 0.125}};
    for (uint32_t k = 0; k < 8; ++k)
        for (int d = 0; d < 4; ++d)
            CHECK(sobol_plain(d, k ^ (k >> 1)) / 4294967296.0 == gray[k][d], "Gray-code point %u, dimension %d: %g", k, d,
                  sobol_plain(d, k ^ (k >> 1)) / 4294967296.0);
    /* (0,2)-sequence in dimensions 0-1: aligned blocks are nets; each dimension a (0,1)-sequence */
    uint32_t x[4096], y[4096];
    for (int m = 0; m <= 12; ++m) {
        for (uint32_t block = 0; block < 3; ++block) {
            uint32_t base = block * (1u << m) + (block == 2 ? (1u << 20) : 0u);
            for (uint32_t i = 0; i < (1u << m); ++i) { x[i] = sobol_plain(0, base + i); y[i] = sobol_plain(1, base + i); }
            CHECK(is_net(x, y, m), "unscrambled dims 0-1, block at %u of 2^%d: not a (0,%d,2)-net", base, m, m);
            for (int d = 2; d < 4; ++d) {
                for (uint32_t i = 0; i < (1u << m); ++i) x[i] = sobol_plain(d, base + i);
                CHECK(is_stratified_1d(x, m), "unscrambled dim %d, block at %u of 2^%d: not stratified", d, base, m);
            }
        }
    }
}

/* The lane value as 32-bit fixed point (24 bits used). */
static uint32_t fixed(float u) { return (uint32_t)(u * 16777216.0f) << 8; }

static void test_stratification(void) {
    uint32_t x[4096], y[4096], z[4096], w[4096];
    int bad_net = 0, bad_1d = 0, out_of_range = 0;
    for (uint32_t pixel = 0; pixel < 40; ++pixel) {
        for (uint32_t depth = 0; depth < 3; ++depth) {
            for (uint32_t group = 0; group < DIMS_GROUPS; ++group) {
                for (uint32_t s = 0; s < 4096; ++s) {
                    PathDims d = dims_of(7 + pixel % 3, pixel * 7919u, s);
                    DimsGroup gr = dims_group(&d, depth, group);
                    float u[4];
                    for (uint32_t l = 0; l < 4; ++l) u[l] = dims_lane(&gr, l);
                    for (int l = 0; l < 4; ++l) out_of_range += !(u[l] >= 0.0f && u[l] < 1.0f);
                    x[s] = fixed(u[0]); y[s] = fixed(u[1]); z[s] = fixed(u[2]); w[s] = fixed(u[3]);
                }
                for (int m = 0; m <= 12; ++m) {
                    bad_net += !is_net(x, y, m);
                    bad_1d += !is_stratified_1d(x, m) + !is_stratified_1d(y, m) + !is_stratified_1d(z, m) +
                              !is_stratified_1d(w, m);
                }
            }
        }
    }
    CHECK(bad_net == 0, "%d groups' first 2^m samples are not a (0,m,2)-net in lanes 0-1", bad_net);
    CHECK(bad_1d == 0, "%d lanes' first 2^m samples are not stratified", bad_1d);
    CHECK(out_of_range == 0, "%d numbers outside [0, 1)", out_of_range);
    /* the camera group too */
    for (uint32_t s = 0; s < 1024; ++s) {
        PathDims d = dims_of(3, 12345, s);
        x[s] = fixed(dims_camera(&d, RNG_DIM_PIXEL_X));
        y[s] = fixed(dims_camera(&d, RNG_DIM_PIXEL_Y));
    }
    for (int m = 0; m <= 10; ++m) CHECK(is_net(x, y, m), "pixel jitter: the first 2^%d samples are not a net", m);
}

/* Pearson correlation; under independence ~N(0, 1/n). */
static double correlation(const double *a, const double *b, int n) {
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

#define NPAIR 200000
static void test_independence(void) {
    double *a = malloc(sizeof(double) * NPAIR), *b = malloc(sizeof(double) * NPAIR);
    double bound = 5.0 / sqrt((double)NPAIR);
    /* neighbouring pixels (x + 1 and y + 1 in a 640-wide image), same sample and dimension, over
     * pixels and the first 8 samples */
    for (int which = 0; which < 4; ++which) {
        for (int axis = 0; axis < 2; ++axis) {
            for (int i = 0; i < NPAIR; ++i) {
                uint32_t pixel = (uint32_t)(i / 8) * 3u, s = (uint32_t)(i % 8), next = pixel + (axis ? 640u : 1u);
                PathDims d0 = dims_of(1, pixel, s), d1 = dims_of(1, next, s);
                a[i] = dims_bounce(&d0, 1, (uint32_t)which * 4u + 1u);
                b[i] = dims_bounce(&d1, 1, (uint32_t)which * 4u + 1u);
            }
            double r = correlation(a, b, NPAIR);
            CHECK(fabs(r) < bound, "neighbouring pixels (%s), dimension %d: correlation %g", axis ? "y" : "x",
                  which * 4 + 1, r);
        }
    }
    /* different groups of one sample, and the same group at consecutive depths */
    static const uint32_t pairs[][4] = {{0, RNG_BOUNCE_LIGHT_U, 0, RNG_BOUNCE_BSDF_U},
                                        {0, RNG_BOUNCE_LIGHT_SELECT, 0, RNG_BOUNCE_GUIDE_CHOICE},
                                        {0, RNG_BOUNCE_BSDF_U, 1, RNG_BOUNCE_BSDF_U},
                                        {0, RNG_BOUNCE_LIGHT_U, 1, RNG_BOUNCE_LIGHT_U},
                                        {3, RNG_BOUNCE_RR, 4, RNG_BOUNCE_RR}};
    for (size_t k = 0; k < sizeof pairs / sizeof pairs[0]; ++k) {
        for (int i = 0; i < NPAIR; ++i) {
            PathDims d = dims_of(5, (uint32_t)(i / 16), (uint32_t)(i % 16));
            a[i] = dims_bounce(&d, pairs[k][0], pairs[k][1]);
            b[i] = dims_bounce(&d, pairs[k][2], pairs[k][3]);
        }
        double r = correlation(a, b, NPAIR);
        CHECK(fabs(r) < bound, "depth %u dim %u against depth %u dim %u: correlation %g", pairs[k][0], pairs[k][1],
              pairs[k][2], pairs[k][3], r);
    }
    /* another seed, same pixel and sample */
    for (int i = 0; i < NPAIR; ++i) {
        PathDims d0 = dims_of(1, (uint32_t)(i / 4), (uint32_t)(i % 4)), d1 = dims_of(2, (uint32_t)(i / 4), (uint32_t)(i % 4));
        a[i] = dims_camera(&d0, RNG_DIM_PIXEL_X);
        b[i] = dims_camera(&d1, RNG_DIM_PIXEL_X);
    }
    double r = correlation(a, b, NPAIR);
    CHECK(fabs(r) < bound, "seeds 1 and 2: correlation %g", r);
    /* uniform over pixels: sample 5 of 100k pixels, each lane of a group, 100 bins */
    for (uint32_t which = 0; which < RNG_BOUNCE_DIMS; which += 5) {
        double bins[100] = {0};
        for (int i = 0; i < 100000; ++i) {
            PathDims d = dims_of(9, (uint32_t)i, 5);
            bins[(int)(dims_bounce(&d, 2, which) * 100.0f)] += 1.0;
        }
        double e = 1000.0, stat = 0.0;
        for (int k = 0; k < 100; ++k) stat += (bins[k] - e) * (bins[k] - e) / e;
        double pv = gamma_q(0.5 * 99, 0.5 * stat);
        CHECK(pv > 1e-3, "dimension %u over pixels: chi-square p = %g", which, pv);
    }
    free(a);
    free(b);
}

static void test_consistency(void) {
    int differ = 0;
    for (uint32_t s = 0; s < 64; ++s) {
        PathDims d = dims_of(4, 99, s);
        for (uint32_t depth = 0; depth < 4; ++depth)
            for (uint32_t g = 0; g < DIMS_GROUPS; ++g) {
                DimsGroup gr = dims_group(&d, depth, g);
                for (uint32_t l = 0; l < 4; ++l)
                    if (depth > 0 || DIMS_GROUP_WHICH[g][l] != RNG_BOUNCE_LIGHT_SELECT) /* that one: the camera group's */
                        differ += dims_lane(&gr, l) != dims_bounce(&d, depth, DIMS_GROUP_WHICH[g][l]);
                PathDims ind = d;
                ind.sobol = NULL;
                DimsGroup gi = dims_group(&ind, depth, g);
                for (uint32_t l = 0; l < 4; ++l)
                    differ += dims_lane(&gi, l) != rng_uniform(d.key, rng_bounce_dim(depth, DIMS_GROUP_WHICH[g][l]));
            }
    }
    CHECK(differ == 0, "%d numbers differ between the group and single-number calls", differ);
    /* the first hit's light selection is the camera group's lane 2: stratified with the pixel
     * position (a 3D net: each 2D projection of the first 2^m samples onto (x, select) and
     * (y, select) is stratified in 1D per axis at least) */
    for (uint32_t s = 0; s < 64; ++s) {
        PathDims d = dims_of(4, 99, s);
        differ += dims_bounce(&d, 0, RNG_BOUNCE_LIGHT_SELECT) !=
                  sequence_sobol(&T, d.scramble, d.rindex, 0, RNG_DIM_FIRST_SELECT);
    }
    CHECK(differ == 0, "the depth-0 light selection is not the camera group's lane %d", RNG_DIM_FIRST_SELECT);
    /* every per-depth dimension belongs to exactly one group lane */
    int count[RNG_BOUNCE_DIMS] = {0};
    for (int g = 0; g < DIMS_GROUPS; ++g)
        for (int l = 0; l < 4; ++l) count[DIMS_GROUP_WHICH[g][l]]++;
    for (int k = 0; k < RNG_BOUNCE_DIMS; ++k) CHECK(count[k] == 1, "dimension %d is in %d group lanes", k, count[k]);
}

int main(void) {
    sequence_tables_init(&T);
    test_generator();
    test_stratification();
    test_independence();
    test_consistency();
    return test_exit();
}
