/* renderer/util/sequence.h (private): the numbers of a path's fixed dimensions.
 *
 * A path draws the random numbers of its camera ray and of each vertex from fixed dimensions
 * (rng.h: RNG_DIM_* for the camera, RNG_BOUNCE_* per depth). Two sequences supply them, chosen
 * by --sampler:
 *
 * - independent: rng_uniform(key, dim), a counter-based hash of (seed, pixel, sample, dim);
 * - sobol (the default): Owen-scrambled Sobol' points, Burley's "Practical Hash-based Owen
 *   Scrambling" (JCGT 2020). The dimensions are cut into groups of four (below); each group is
 *   one 4D Sobol' point of the pixel's sample index. A group's index goes through its own
 *   nested-uniform shuffle (Burley §4: a permutation within aligned power-of-two blocks, so
 *   the first 2^m samples of a pixel stay a (0,m,2)-net in the group's first two lanes), and
 *   each lane is Owen-scrambled by a hash (nested uniform, so nets stay nets): the groups of
 *   one sample are as independent of each other as padding makes them (pbrt-v4's ZSobol and
 *   Cycles' Sobol-Burley do the same), and every pixel has its own seed (pixels are
 *   decorrelated: no structure between neighbours).
 *
 * Both are pure functions of (seed, pixel, sample index, dimension): no state carries from one
 * sample or thread to another, so images are bit-identical for any thread count, batch size,
 * shard or checkpoint. What draws an unbounded number of numbers at one vertex (free flights in
 * media, in-scattering sampling, volume lights' emission lines, a shape's transmittance)
 * takes them from rng_stream sub-streams keyed by the path's independent key, with either
 * sequence.
 *
 * Groups (lanes 0-1 are the Sobol' pair that is a (0,2)-sequence, so each group puts its 2D
 * decision there):
 *   camera:          (pixel x, pixel y, the first hit's light selection, -): the camera has no
 *                    lens, so the first vertex's light choice takes lane 2 and is stratified
 *                    jointly with the pixel position (20k-light street, 16 spp: MSE 3% lower
 *                    than with the selection in its depth's light group)
 *   per depth, 0 light:  (light u, light v, light selection, light w)
 *                1 scatter: (BSDF u, BSDF v, BSDF lobe, roulette)
 *                2 guide:   (guide u, guide v, guide choice, light-tree descent)
 *                3 rest:    (light x, -, -, -)
 * The independent sequence keeps rng.h's dimension numbers (its images are those of the
 * versions before the Sobol' sampler). */
#ifndef CANDELA_SEQUENCE_H
#define CANDELA_SEQUENCE_H

#include <stdint.h>

#include "rng.h"

/* The Sobol' generator matrices of dimensions 0-3 as XOR tables over the six nibbles of a
 * group's shuffled index y (bits 8-31; sequence_sobol_group): the points are needed to 24 bits,
 * and the shuffle keeps the index below 2^24 (y's bits 0-7 are dropped). Built once per render
 * (sequence_tables_init). */
typedef struct SobolTables {
    uint32_t nibble[4][6][16];
} SobolTables;

/* Fills the tables: dimension 0 is the van der Corput sequence, 1-3 Joe and Kuo's dimensions
 * 2-4 (the primitive polynomials x + 1, x^2 + x + 1, x^3 + x + 1). */
void sequence_tables_init(SobolTables *t);

/* Column k (bit k of the index) of Sobol' dimension d (0-3) in the bit-reversed domain used
 * here (bit j of the value has weight 2^-(j+1)), for the tests. */
uint32_t sequence_direction(int d, int k);

/* What one path needs to draw its fixed dimensions. */
typedef struct PathDims {
    uint64_t key;             /* rng_path_key(seed, pixel, sample): the independent sequence */
    const SobolTables *sobol; /* NULL: the independent sequence */
    uint32_t scramble;        /* Sobol': the pixel's seed (sequence_pixel_scramble) */
    uint32_t rindex;          /* Sobol': the sample's index within its pixel (below 2^24), bit-reversed */
} PathDims;

static inline uint32_t sequence_hash32(uint32_t x) {
    x ^= x >> 16; x *= 0x7feb352du;
    x ^= x >> 15; x *= 0x846ca68bu;
    x ^= x >> 16;
    return x;
}

/* The Sobol' seed of a pixel (every sample of the pixel shares it). */
static inline uint32_t sequence_pixel_scramble(uint64_t seed, uint32_t pixel) {
    return (uint32_t)(rng_mix64(rng_mix64(seed ^ 0x3c6ef372fe94f82bull) ^ ((uint64_t)pixel + 0x1f83d9abfb41bd6bull)) >> 32);
}

static inline uint32_t sequence_reverse_bits(uint32_t x) {
    x = __builtin_bswap32(x);
    x = ((x >> 4) & 0x0f0f0f0fu) | ((x & 0x0f0f0f0fu) << 4);
    x = ((x >> 2) & 0x33333333u) | ((x & 0x33333333u) << 2);
    x = ((x >> 1) & 0x55555555u) | ((x & 0x55555555u) << 1);
    return x;
}

/* Laine and Karras's hash-based permutation as Burley improved it: bit k of the result
 * depends on bits 0..k of x only, so applied to bit-reversed values it is a nested uniform
 * (Owen) scramble. */
static inline uint32_t sequence_lk_permute(uint32_t x, uint32_t seed) {
    x += seed;
    x ^= x * 0x6c50b47cu;
    x ^= x * 0xb82f1e52u;
    x ^= x * 0xc7afe638u;
    x ^= x * 0x8d22f6e6u;
    return x;
}

/* A group's seed: its index shuffle's, and through sequence_lane_seed its lanes' scrambles. */
static inline uint32_t sequence_group_seed(uint32_t scramble, uint32_t group) {
    return sequence_hash32(scramble ^ (group * 0x9e3779b9u + 0x7f4a7c15u));
}

static inline uint32_t sequence_lane_seed(uint32_t group_seed, uint32_t lane) {
    return sequence_hash32(group_seed + (lane + 1u) * 0x68bc21ebu);
}

/* The group's shuffled index, bit-reversed: a nested uniform scramble of the index from its low
 * bits up, so the first 2^m indices map onto one aligned block of 2^m indices (itself a net).
 * Index bit j of the result depends on index bits >= j only; for an index below 2^24 its bits
 * 24-31 (y's bits 0-7) are a scramble of zeros, which the tables ignore: the shuffled index stays
 * below 2^24 (the generator matrices are upper triangular, so an index bit above the points'
 * 24 would still reach every bit of the point). */
static inline uint32_t sequence_shuffle(uint32_t rindex, uint32_t group_seed) {
    return sequence_lk_permute(rindex, group_seed);
}

/* Sobol' dimension d (0-3) of the index whose bit-reversal is y (its bits 24-31, y's bits 0-7,
 * ignored), bit-reversed. */
static inline uint32_t sequence_sobol_reversed(const SobolTables *t, uint32_t d, uint32_t y) {
    const uint32_t (*n)[16] = t->nibble[d];
    return n[0][(y >> 8) & 15] ^ n[1][(y >> 12) & 15] ^ n[2][(y >> 16) & 15] ^ n[3][(y >> 20) & 15] ^
           n[4][(y >> 24) & 15] ^ n[5][y >> 28];
}

/* Lane `lane` (Sobol' dimension 0-3) of the point at the shuffled index y, Owen-scrambled: a
 * float in [0, 1) with 24 bits. */
static inline float sequence_lane(const SobolTables *t, uint32_t y, uint32_t group_seed, uint32_t lane) {
    uint32_t x = sequence_sobol_reversed(t, lane, y);
    x = sequence_lk_permute(x, sequence_lane_seed(group_seed, lane));
    return (float)(sequence_reverse_bits(x) >> 8) * (1.0f / 16777216.0f);
}

/* Lane `lane` of group `group` of a pixel's sample. */
static inline float sequence_sobol(const SobolTables *t, uint32_t scramble, uint32_t rindex, uint32_t group,
                                   uint32_t lane) {
    uint32_t seed = sequence_group_seed(scramble, group);
    return sequence_lane(t, sequence_shuffle(rindex, seed), seed, lane);
}

/* The groups of a vertex (sequence numbers 1 + 4 depth + group), and each one's four lanes as
 * rng.h's per-depth dimensions. */
enum { DIMS_LIGHT, DIMS_SCATTER, DIMS_GUIDE, DIMS_REST, DIMS_GROUPS };
static const uint8_t DIMS_GROUP_WHICH[DIMS_GROUPS][4] = {
    [DIMS_LIGHT] = {RNG_BOUNCE_LIGHT_U, RNG_BOUNCE_LIGHT_V, RNG_BOUNCE_LIGHT_SELECT, RNG_BOUNCE_LIGHT_W},
    [DIMS_SCATTER] = {RNG_BOUNCE_BSDF_U, RNG_BOUNCE_BSDF_V, RNG_BOUNCE_BSDF_LOBE, RNG_BOUNCE_RR},
    [DIMS_GUIDE] = {RNG_BOUNCE_GUIDE_U, RNG_BOUNCE_GUIDE_V, RNG_BOUNCE_GUIDE_CHOICE, RNG_BOUNCE_LIGHT_DESCEND},
    [DIMS_REST] = {RNG_BOUNCE_LIGHT_X, 8, 14, 15}};

/* rng.h's per-depth dimension -> its group and lane. */
static inline void sequence_bounce_slot(uint32_t which, uint32_t *group, uint32_t *lane) {
    static const uint8_t slot[RNG_BOUNCE_DIMS] = {
        [RNG_BOUNCE_LIGHT_U] = 0x00, [RNG_BOUNCE_LIGHT_V] = 0x01, [RNG_BOUNCE_LIGHT_SELECT] = 0x02,
        [RNG_BOUNCE_LIGHT_W] = 0x03, [RNG_BOUNCE_BSDF_U] = 0x10, [RNG_BOUNCE_BSDF_V] = 0x11,
        [RNG_BOUNCE_BSDF_LOBE] = 0x12, [RNG_BOUNCE_RR] = 0x13, [RNG_BOUNCE_GUIDE_U] = 0x20,
        [RNG_BOUNCE_GUIDE_V] = 0x21, [RNG_BOUNCE_GUIDE_CHOICE] = 0x22, [RNG_BOUNCE_LIGHT_DESCEND] = 0x23,
        [RNG_BOUNCE_LIGHT_X] = 0x30, [8] = 0x31, [14] = 0x32, [15] = 0x33};
    *group = slot[which] >> 4;
    *lane = slot[which] & 3u;
}

/* Camera dimension `which` (RNG_DIM_PIXEL_X, RNG_DIM_PIXEL_Y): group 0. */
static inline float dims_camera(const PathDims *d, uint32_t which) {
    if (!d->sobol) return rng_uniform(d->key, which);
    return sequence_sobol(d->sobol, d->scramble, d->rindex, 0, which);
}

/* Dimension `which` (RNG_BOUNCE_*) of the vertex at `depth`. */
static inline float dims_bounce(const PathDims *d, uint32_t depth, uint32_t which) {
    if (!d->sobol) return rng_uniform(d->key, rng_bounce_dim(depth, which));
    if (depth == 0 && which == RNG_BOUNCE_LIGHT_SELECT) /* the camera group's free lane (above) */
        return sequence_sobol(d->sobol, d->scramble, d->rindex, 0, RNG_DIM_FIRST_SELECT);
    uint32_t group, lane;
    sequence_bounce_slot(which, &group, &lane);
    return sequence_sobol(d->sobol, d->scramble, d->rindex, 1u + 4u * depth + group, lane);
}

/* One group (DIMS_*) of the vertex at `depth`, set up at its first lane (a group whose lanes
 * are never drawn costs nothing); its lanes are drawn on demand (dims_lane: the same numbers as
 * dims_bounce, but for the depth-0 light selection, which lives in the camera group: draw it
 * with dims_bounce), so a vertex pays only for the numbers it uses. */
typedef struct DimsGroup {
    const PathDims *dims;
    uint32_t depth, group;
    int ready;        /* Sobol': seed and y computed (at the first lane drawn) */
    uint32_t seed, y; /* Sobol': the group's seed and shuffled index */
} DimsGroup;

static inline DimsGroup dims_group(const PathDims *d, uint32_t depth, uint32_t group) {
    DimsGroup g = {d, depth, group, 0, 0, 0};
    return g;
}

static inline float dims_lane(DimsGroup *g, uint32_t lane) {
    if (!g->dims->sobol) return rng_uniform(g->dims->key, rng_bounce_dim(g->depth, DIMS_GROUP_WHICH[g->group][lane]));
    if (!g->ready) {
        g->seed = sequence_group_seed(g->dims->scramble, 1u + 4u * g->depth + g->group);
        g->y = sequence_shuffle(g->dims->rindex, g->seed);
        g->ready = 1;
    }
    return sequence_lane(g->dims->sobol, g->y, g->seed, lane);
}

#endif
