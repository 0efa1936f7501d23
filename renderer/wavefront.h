/* renderer/wavefront.h (private): path state and work queues of the wavefront integrator.
 *
 * All per-path data lives in structure-of-arrays PathState indexed by the path's slot in the
 * batch. Queues are arrays of slot indices; each stage is a loop over one queue:
 *
 *   generate ──> ray queue ──sort(octant, Morton)──> trace ──┬─> escaped queue ──> shade background
 *                   ^                                        └─> hit queue ──sort(prim, tri)──> shade surface
 *                   │                                                  │            │
 *                   └──────────── continuation rays (next wave) <──────┘            └─> shadow queue ──> trace shadow
 *
 * A wave is one bounce for every live path of the batch; all paths of a wave share the
 * same depth. Queues are compacted by serial scans in queue order, so their contents and
 * order are a function of the input only (never of thread timing). */
#ifndef CANDELA_WAVEFRONT_H
#define CANDELA_WAVEFRONT_H

#include <stdint.h>

typedef struct PathState {
    uint32_t capacity;
    uint64_t *rng_key;      /* counter-based RNG key of the path (seed, pixel, sample) */
    uint32_t *pixel;
    float *radiance;        /* 3: accumulated L */
    float *throughput;      /* 3: beta */
    float *eta_scale;       /* for Russian roulette across refraction */
    float *ray_org, *ray_dir; /* 3 each: the ray to trace in this wave */
    /* previous vertex, for MIS when a BSDF-sampled ray finds a light */
    float *prev_pos, *prev_normal; /* 3 each: the light-selection context there */
    float *prev_bsdf_pdf;
    uint8_t *prev_delta;
    uint32_t *prev_cache_point1;   /* that vertex's cache point + 1 (0: none) */
    float *prev_cp_near_total;     /* and its near lights' summed weight (spec §5.6) */
    /* intersection results of the current wave */
    float *hit_t, *hit_u, *hit_v;
    uint32_t *hit_inst, *hit_geom, *hit_prim;
    /* shadow ray of the current wave */
    float *shadow_org, *shadow_dir, *shadow_tfar, *shadow_contrib; /* 3,3,1,3 */
    uint32_t *shadow_slot;  /* cache point visibility slot of the shadow ray's light (§3.2.1) */
    uint8_t *continues, *has_shadow;
    /* first-hit AOVs */
    float *aov_albedo, *aov_normal, *aov_depth; /* 3,3,1 */
} PathState;

typedef struct WorkQueue {
    uint32_t *items;
    uint32_t count;
} WorkQueue;

#endif
