/* cachepoints/cachepoints.h: cache points for occlusion-aware many-light selection
 * (Li et al., DigiPro 2024, §3; implementation spec ../shared/design/cache-points-spec.md).
 *
 * A sparse set of world-space points, each holding a compressed light distribution: a near
 * list (lights evaluated exactly at the shading vertex) and seven far bins (irradiance on the
 * six cardinal planes and an omnidirectional fluence, unoccluded, blurred over neighbours),
 * multiplied at render time by a learned visibility weight per (point, light).
 *
 * The module knows nothing about the renderer: lights are seen through CachePointLights
 * (a centroid per light and an estimate callback), parallel loops through a parallel-for
 * callback. Everything is deterministic for a given input whatever the thread count. */
#ifndef CANDELA_CACHEPOINTS_H
#define CANDELA_CACHEPOINTS_H

#include <stddef.h>
#include <stdint.h>

/* The scene's lights as the cache points see them. */
typedef struct CachePointLights {
    uint32_t count;
    const float *centroid;   /* 3 per light */
    const uint8_t *infinite; /* 1: directional / environment (always far, §3.1.3) */
    /* Unoccluded estimate of light `light` at x (spec §3.4): out[0..5] irradiance on the
     * planes facing +X, -X, +Y, -Y, +Z, -Z; out[6] fluence. Deterministic. */
    void (*estimate7)(const void *user, uint32_t light, const float x[3], float out[7]);
    /* The same irradiance on the plane with unit normal n (n == NULL: fluence), used for the
     * exact near-light weights at a vertex (§3.3). */
    float (*estimate)(const void *user, uint32_t light, const float x[3], const float *n);
    const void *user;
} CachePointLights;

/* Camera footprint for the pixel-size radii of §3.1.2/§3.1.4 (r_px). */
typedef struct CachePointCamera {
    float position[3];
    float pixel_angle;   /* perspective: 2 tan(fov_y/2) / height; 0 for orthographic */
    float pixel_size;    /* orthographic: world size of a pixel */
} CachePointCamera;

typedef void (*CachePointParallelFor)(void *pool, size_t n, size_t grain,
                                      void (*fn)(void *ctx, size_t begin, size_t end, int thread), void *ctx);

typedef struct CachePointParams {
    uint32_t knn;             /* 20: merge passes (§3.1.2, §3.1.4) */
    float near_factor;        /* D = 4 (Eq. 1) */
    float energy_fraction;    /* 0.97 per far bin (§3.1.3) */
    uint32_t min_per_bin, max_per_bin; /* 4, 256 */
    uint32_t max_near;        /* 256 (spec §3.4 proposal) */
    uint32_t blur_neighbours; /* 16 (§3.1.5) */
    float r_min;              /* 0.04 (Eq. 6) */
    float epsilon;            /* 0.03 uniform floor (spec §5.4) */
    int visibility;           /* learn visibility (§3.2); 0 = --no-visibility */
    int vis_blur_renorm;      /* 1: divide the visibility blur by the weights of points holding e */
    int retruncate;           /* re-apply 97% / 4..256 per bin after the blur (bounds memory; off = paper) */
    CachePointParallelFor parallel_for;
    void *pool;
} CachePointParams;

void cachepoints_default_params(CachePointParams *p);

typedef struct CachePoints CachePoints;

/* Statistics of the build, for the comparison table. */
typedef struct CachePointStats {
    uint32_t candidates, after_pass1, final_points;
    double seconds;
    size_t bytes;
} CachePointStats;

/* Builds from candidate positions (3 floats each, in generation order: the spatial sort
 * breaks ties by it). Returns 0 and *out, or 1 with *out == NULL when fewer than 10 points
 * exist (the caller falls back to per-vertex optimal selection, §3.1.1), or -1 (out of
 * memory). */
int cachepoints_build(CachePoints **out, const float *candidates, uint32_t num_candidates,
                      const CachePointLights *lights, const CachePointCamera *camera,
                      const CachePointParams *params, CachePointStats *stats);
void cachepoints_free(CachePoints *cp);
uint32_t cachepoints_count(const CachePoints *cp);
/* Position and radius of point i (tests, debugging). */
void cachepoints_point(const CachePoints *cp, uint32_t i, float pos[3], float *radius);

/* Render-time selection (§3.3): the nearest point to x, near lights exact, far bins blended
 * by n (n == NULL: volumes and transmissive surfaces use the fluence bin), visibility
 * weights, uniform floor epsilon. *point receives the cache point used. */
uint32_t cachepoints_select(const CachePoints *cp, const CachePointLights *lights, const float x[3],
                            const float *n, uint32_t point_hint, float u, float *pmf, uint32_t *point);
/* The cache point a vertex at x uses (the nearest; ties: lowest index). */
uint32_t cachepoints_nearest(const CachePoints *cp, const float x[3]);
/* Exactly the probability cachepoints_select gives `light` at (x, n). point_hint: the
 * vertex's cache point if the caller already has it from cachepoints_nearest, else
 * UINT32_MAX. */
float cachepoints_pmf(const CachePoints *cp, const CachePointLights *lights, const float x[3],
                      const float *n, uint32_t point_hint, uint32_t light);

/* Visibility learning (§3.2): count an attempt of `light` from `point` (atomic; ignored when
 * the light is not in the point's lists), and a success when the shadow ray got through
 * with a useful contribution. */
void cachepoints_record(CachePoints *cp, uint32_t point, uint32_t light, int success);
/* At the iteration barrier: Eqs. 5-6 then the visibility blur (§3.2.2), out of place. */
void cachepoints_update_visibility(CachePoints *cp);
/* The visibility weight W' currently used for (point, light); 1 when not in its lists. */
float cachepoints_visibility(const CachePoints *cp, uint32_t point, uint32_t light);
/* Eq. 5-6 on raw counters (exposed for the anchor-value test). */
float cachepoints_visibility_weight(uint32_t successes, uint32_t attempts, float r_min);

#endif
