/* renderer/util/rng.h (private): counter-based random numbers.
 *
 * Every random number is a pure function of (seed, pixel, sample, dimension): there is no
 * generator state to carry between threads, so the image cannot depend on thread count,
 * batch size or processing order. The hash is a 64-bit mix (splitmix64 finaliser chained over
 * the key words), which passes the statistical checks in tests/test_rng.c. */
#ifndef CANDELA_RNG_H
#define CANDELA_RNG_H

#include <stdint.h>

static inline uint64_t rng_mix64(uint64_t z) {
    z ^= z >> 30; z *= 0xbf58476d1ce4e5b9ull;
    z ^= z >> 27; z *= 0x94d049bb133111ebull;
    z ^= z >> 31;
    return z;
}

/* Key of one path: all dimensions of the path derive from it. */
static inline uint64_t rng_path_key(uint64_t seed, uint64_t pixel, uint64_t sample) {
    uint64_t h = rng_mix64(seed + 0x9e3779b97f4a7c15ull);
    h = rng_mix64(h ^ (pixel + 0x632be59bd9b4e019ull));
    h = rng_mix64(h ^ (sample * 0x9e3779b97f4a7c15ull + 0x2545f4914f6cdd1dull));
    return h;
}

/* Uniform float in [0, 1) for dimension dim of a path key. 24 random bits, so the result
 * is exactly representable and strictly below 1. */
static inline float rng_uniform(uint64_t key, uint32_t dim) {
    uint64_t h = rng_mix64(key ^ ((uint64_t)dim * 0xd1b54a32d192ed03ull + 0x8cb92ba72f3d8dd7ull));
    return (float)(h >> 40) * (1.0f / 16777216.0f);
}

/* Dimension layout of a path: the camera uses the first dimensions, then each bounce (path
 * vertex) `depth` a fixed block of RNG_BOUNCE_DIMS starting at rng_bounce_dim(depth, 0).
 * Dimensions 2-3 (a lens) and the unnamed ones of each block are unused: the layout is kept
 * so that images stay identical to earlier versions. */
enum {
    RNG_DIM_PIXEL_X = 0,
    RNG_DIM_PIXEL_Y = 1,
    RNG_DIM_FIRST_SELECT = 2, /* Sobol' only: the camera group's lane of the depth-0 light selection */
    RNG_DIM_CAMERA_END = 4,
    /* per bounce */
    RNG_BOUNCE_LIGHT_SELECT = 0,
    RNG_BOUNCE_LIGHT_U = 1,
    RNG_BOUNCE_LIGHT_V = 2,
    RNG_BOUNCE_LIGHT_W = 3,
    RNG_BOUNCE_BSDF_LOBE = 4,
    RNG_BOUNCE_BSDF_U = 5,
    RNG_BOUNCE_BSDF_V = 6,
    RNG_BOUNCE_RR = 7,
    RNG_BOUNCE_LIGHT_DESCEND = 9, /* strategies that descend a tree below their first choice */
    RNG_BOUNCE_LIGHT_X = 10,      /* a fourth light-sample dimension (volume lights) */
    RNG_BOUNCE_GUIDE_U = 11,      /* path guiding: the guide's direction, */
    RNG_BOUNCE_GUIDE_V = 12,
    RNG_BOUNCE_GUIDE_CHOICE = 13, /* and the choice between the function's and the guide's */
    RNG_BOUNCE_DIMS = 16
};

static inline uint32_t rng_bounce_dim(uint32_t depth, uint32_t which) {
    return RNG_DIM_CAMERA_END + depth * RNG_BOUNCE_DIMS + which;
}

/* A sub-stream: an unbounded sequence of numbers for one purpose at one bounce of a path,
 * for work that draws as many numbers as it needs (a null-collision walk through a medium
 * takes an unbounded number of steps per bounce). Its key is a function of (path key, depth,
 * purpose) only, so the numbers never depend on which thread runs the path or on what the
 * path did before; they are independent of the path's bounce dimensions. */
typedef struct RngStream {
    uint64_t key;
    uint32_t next;  /* the next dimension to draw */
} RngStream;

enum {
    RNG_STREAM_MEDIUM = 1,  /* the free flight towards the vertex of this depth */
    RNG_STREAM_SHADOW = 2,  /* the transmittance of this depth's NEE shadow ray */
    RNG_STREAM_LIGHT_LINE = 3, /* a volume light's emission line (keyed by the light sample) */
    RNG_STREAM_INSCATTER = 4,  /* in-scattering sampling on this depth's camera segment: distance, tracking, light */
    RNG_STREAM_INSCATTER_SHADOW = 5, /* the transmittance of that technique's shadow ray */
    RNG_STREAM_EMISSION_LINE = 6 /* the emission arriving along this depth's segment (Algorithm 1) */
};

static inline RngStream rng_stream(uint64_t path_key, uint32_t depth, uint32_t purpose) {
    uint64_t salt = ((uint64_t)depth << 32 | purpose) * 0x9e3779b97f4a7c15ull + 0x5851f42d4c957f2dull;
    RngStream s = {rng_mix64(rng_mix64(path_key ^ 0xa0761d6478bd642full) ^ salt), 0};
    return s;
}

static inline float rng_stream_next(RngStream *s) { return rng_uniform(s->key, s->next++); }
/* The same as a callback (the volumes module's VolumeRng). */
static inline float rng_stream_next_cb(void *stream) { return rng_stream_next((RngStream *)stream); }

#endif
