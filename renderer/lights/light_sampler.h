/* renderer/lights/light_sampler.h (private): the light-selection protocol.
 *
 * Next-event estimation picks a light through a LightSampler, whatever the strategy, in four
 * steps that every caller (surface shading now, a medium walk later) follows:
 *
 *   1. light_sampler_prepare(s, &ctx, &hint): once per vertex, before anything else. The
 *      strategy may do per-vertex work here (cache points: find the vertex's point, weigh its
 *      near lights into ctx.scratch) and leaves its per-vertex state in ctx.vertex, an opaque
 *      token the caller keeps (the path state stores it for the MIS pdf at the next wave).
 *      hint is per-caller scratch (UINT32_MAX to start) that a coherent stream of vertices
 *      passes from one vertex to the next; it speeds a strategy up, never changes a result.
 *   2. light_sampler_select(s, &ctx, u0, u1, &pmf, &outcome) -> a light and its probability;
 *      light_sampler_pmf(s, &ctx, light) returns exactly that probability for any light
 *      (MIS needs it for lights found by BSDF sampling). The two agree bit for bit.
 *   3. light_sampler_record(s, outcome, visibility): once the selection's shadow ray is
 *      traced, the fraction of it that reached the light (0 or 1 through opaque geometry, a
 *      transmittance through media; 0 when no shadow ray was cast). outcome is the token
 *      select returned (LIGHT_OUTCOME_NONE: nothing to learn). Thread-safe.
 *   4. light_sampler_barrier(s): at an iteration barrier, when no ray is in flight. Learned
 *      state changes only here, so every pmf within an iteration sees one distribution.
 *
 * Strategies (one file each; the wavefront never names one): uniform and power (this
 * protocol's own light_sampler.c), the light BVH (lighttree.c), per-vertex optimal
 * (lightselect_optimal.c) and cache points (lightselect_cachepoints.c). */
#ifndef CANDELA_LIGHT_SAMPLER_H
#define CANDELA_LIGHT_SAMPLER_H

#include <stdint.h>
#include <stdio.h>

#include "candela.h"
#include "lights.h"

struct Scene;
struct SceneMedia;
struct ThreadPool;

#define LIGHT_OUTCOME_NONE UINT32_MAX
/* Floats a caller provides in LightSampleContext.scratch (cache points' near lists hold at
 * most this many lights). */
#define LIGHT_SAMPLER_SCRATCH 256

typedef struct LightSamplerOps {
    const char *name;
    /* optional (NULL: nothing per vertex) */
    void (*prepare)(const void *state, LightSampleContext *ctx, uint32_t *hint);
    uint32_t (*select)(const void *state, const LightSampleContext *ctx, float u0, float u1, float *pmf,
                       uint32_t *outcome);
    float (*pmf)(const void *state, const LightSampleContext *ctx, uint32_t light);
    /* optional: strategies that learn from shadow rays */
    void (*record)(void *state, uint32_t outcome, float visibility);
    void (*prefetch_outcome)(const void *state, uint32_t outcome); /* a cache hint before tracing */
    void (*barrier)(void *state);
    /* optional, with record: the learned state for checkpoints (0 ok; load: -1 a damaged
     * record, -2 one of another build) */
    int (*save_learned)(const void *state, FILE *out);
    int (*load_learned)(void *state, FILE *in);
    /* optional: cache-point in-scattering sampling (§4.2): the importance of in-scattering
     * at x for distance sampling along camera rays (the summed scattering weights of x's
     * cache point) and in *radius the distance over which it holds; hint as for prepare */
    float (*inscatter_weight)(const void *state, const float x[3], uint32_t *hint, float *radius);
    /* optional (--aov cachepoint): false colours of what a prepared vertex uses (cache points:
     * its point, and the entry it weighs most); black where the strategy has none */
    void (*aov)(const void *state, const LightSampleContext *ctx, vec3 *point_rgb, vec3 *light_rgb);
    /* optional: at the end of a render, the strategy's own outputs its options asked for (cache
     * points: --dump-cachepoints). 0 ok; -1 with err */
    int (*finish)(const void *state, char err[CANDELA_ERR_LEN]);
    /* optional: the strategy's build statistics */
    void (*report)(const void *state, CandelaStats *stats);
    void (*destroy)(void *state);
} LightSamplerOps;

typedef struct LightSampler {
    const LightSamplerOps *ops;
    void *state;
    uint32_t light_count;
    /* 1: select / pmf follow LightSampleContext.lobe (cache points with --cachepoint-bsdf on):
     * callers fill it (scatter_light_lobe); 0: the strategy ignores it, callers may leave it 0 */
    int uses_lobe;
    /* 1: select reads its second number (u1: cache points' far-bin descent); 0: callers may
     * pass 0 instead of drawing it (a counter-based generator: skipping a dimension changes
     * no other number) */
    int uses_descend;
} LightSampler;

/* Builds the strategy o->light_sampler over the lights (the optimal strategy's occlusion rays
 * and the cache points' candidates use the scene, and the media: points inside VDB volumes;
 * the cache point build runs on the pool). 0 ok; -1 with a message in err. */
int light_sampler_create(LightSampler *s, const Lights *lights, const struct Scene *scene,
                         const struct SceneMedia *media, struct ThreadPool *pool, const CandelaOptions *o,
                         char err[CANDELA_ERR_LEN]);
void light_sampler_free(LightSampler *s);

/* `auto` (the default): the strategy light_sampler_create builds for these lights (never
 * CANDELA_LIGHT_SAMPLER_AUTO): cache points when in-scattering sampling may run (media, §4.2),
 * power for one light, optimal (exact per-vertex estimates, no build) while the lights'
 * estimates cost at most LIGHT_SAMPLER_AUTO_EXACT_COST (a punctual or infinite light 1, an area
 * light LIGHT_SAMPLER_AUTO_AREA_COST), cache points above. Measured (scenes/
 * default_sampler_table.py, 320x180, 16 spp, CPU time): optimal's TTUV is 0.80-0.86x the best
 * of power/tree/cachepoints with 4-5 lights, 0.19x cache points' with 96 narrow spots, equal
 * with 64 points and a mesh (cost 72); with 16 points and 64 area lights (cost 528) it is 3.4x
 * cache points'. */
#define LIGHT_SAMPLER_AUTO_EXACT_COST 128u
#define LIGHT_SAMPLER_AUTO_AREA_COST 8u
CandelaLightSampler light_sampler_auto_choice(const Lights *lights, const struct SceneMedia *media,
                                              const CandelaOptions *o);
/* auto's second look (light_sampler_create, without media): when the lights are about equally
 * important wherever the camera looks (every light visible and of similar power: the cornell
 * boxes), `power` samples them as well as any per-vertex strategy at none of the cost. At the
 * first hits of a 16 x 16 grid of camera rays through pixel centres (deterministic), q_e = each
 * light's unoccluded estimate times the hit's diffuse reflectance / pi; power's second moment
 * there is (sum_e q_e)^2 sum_e (q_e / sum q)^2 / p_e (p_e: power's pmf), exact selection's
 * (sum_e q_e)^2. To both (per pixel, averaged over the grid) is added what no light sampler
 * changes: the within-pixel variance of the radiance the camera sees directly (emitters, the
 * environment; 64 x 64 pixels, 2 x 2 positions each), which holds 94 % of cornell_many_lights'
 * image variance (its panels' edges). The ratio (power / exact) is 1 when power is as good as
 * exact selection and INFINITY when power misses a light that matters. Scenes with more than
 * LIGHT_SAMPLER_AUTO_PROBE_MAX lights are not probed (INFINITY). */
#define LIGHT_SAMPLER_AUTO_PROBE_MAX 4096u
/* Power is chosen when the ratio is at most the alternative's cost per sample relative to
 * power's: optimal's per-vertex work costs 1.2-1.3x power's time per sample with 4-5 lights
 * (callgrind on bench: 737M vs 567M instructions); cache points' 1.47x on cornell_many_lights
 * (320x180, CPU seconds between 16 and 64 spp), their build on top. Probe ratios measured
 * (320x180): cornell_lights 1.000, cornell_1k_lights 1.04, cornell_many_lights 1.22 (power's
 * measured per-sample variance there: 1.14x cache points'), animation 1.66, emissive_mesh 2.29,
 * bench 2.36, default 2.49, windows 49, spotlights 56, city_1k 793, glossy 1602. */
#define LIGHT_SAMPLER_AUTO_POWER_RATIO 1.10f
#define LIGHT_SAMPLER_AUTO_POWER_RATIO_CACHEPOINTS 1.50f
float light_sampler_power_moment_ratio(const Lights *lights, const struct Scene *scene);

/* The strategies' constructors (light_sampler_create dispatches to them). */
int light_sampler_uniform_create(LightSampler *s, const Lights *lights);
int light_sampler_power_create(LightSampler *s, const Lights *lights);
int light_sampler_tree_create(LightSampler *s, const Lights *lights);
int light_sampler_optimal_create(LightSampler *s, const Lights *lights, const struct Scene *scene, int occlusion);
int light_sampler_cachepoints_create(LightSampler *s, const Lights *lights, const struct Scene *scene,
                                     const struct SceneMedia *media, struct ThreadPool *pool,
                                     const CandelaOptions *o, char err[CANDELA_ERR_LEN]);

static inline void light_sampler_prepare(const LightSampler *s, LightSampleContext *ctx, uint32_t *hint) {
    ctx->vertex = (LightVertex){0, 0.0f};
    if (s->ops->prepare) s->ops->prepare(s->state, ctx, hint);
}

static inline uint32_t light_sampler_select(const LightSampler *s, const LightSampleContext *ctx, float u0, float u1,
                                            float *pmf, uint32_t *outcome) {
    *outcome = LIGHT_OUTCOME_NONE;
    if (s->light_count == 0) { *pmf = 0.0f; return 0; }
    return s->ops->select(s->state, ctx, u0, u1, pmf, outcome);
}

static inline float light_sampler_pmf(const LightSampler *s, const LightSampleContext *ctx, uint32_t light) {
    return light < s->light_count ? s->ops->pmf(s->state, ctx, light) : 0.0f;
}

static inline void light_sampler_record(const LightSampler *s, uint32_t outcome, float visibility) {
    if (outcome != LIGHT_OUTCOME_NONE && s->ops->record) s->ops->record(s->state, outcome, visibility);
}

static inline void light_sampler_prefetch_outcome(const LightSampler *s, uint32_t outcome) {
    if (outcome != LIGHT_OUTCOME_NONE && s->ops->prefetch_outcome) s->ops->prefetch_outcome(s->state, outcome);
}

static inline void light_sampler_barrier(const LightSampler *s) {
    if (s->ops->barrier) s->ops->barrier(s->state);
}

/* Checkpoints: a strategy without learned state saves nothing and loads nothing. */
static inline int light_sampler_save_learned(const LightSampler *s, FILE *out) {
    return s->ops->save_learned ? s->ops->save_learned(s->state, out) : 0;
}
static inline int light_sampler_load_learned(const LightSampler *s, FILE *in) {
    return s->ops->load_learned ? s->ops->load_learned(s->state, in) : 0;
}

static inline int light_sampler_learns(const LightSampler *s) { return s->ops->record != NULL; }
static inline int light_sampler_uses_lobe(const LightSampler *s) { return s->uses_lobe; }
static inline int light_sampler_uses_descend(const LightSampler *s) { return s->uses_descend; }
static inline int light_sampler_has_barrier(const LightSampler *s) { return s->ops->barrier != NULL; }

static inline int light_sampler_has_inscatter(const LightSampler *s) { return s->ops->inscatter_weight != NULL; }
static inline float light_sampler_inscatter_weight(const LightSampler *s, const float x[3], uint32_t *hint,
                                                   float *radius) {
    return s->ops->inscatter_weight(s->state, x, hint, radius);
}

static inline void light_sampler_aov(const LightSampler *s, const LightSampleContext *ctx, vec3 *point_rgb,
                                     vec3 *light_rgb) {
    *point_rgb = *light_rgb = v3s(0.0f);
    if (s->ops->aov && ctx->vertex.word) s->ops->aov(s->state, ctx, point_rgb, light_rgb);
}
static inline int light_sampler_finish(const LightSampler *s, char err[CANDELA_ERR_LEN]) {
    return s->ops->finish ? s->ops->finish(s->state, err) : 0;
}

/* The strategy that runs (what `auto` chose) and its build statistics. */
static inline void light_sampler_report(const LightSampler *s, CandelaStats *stats) {
    if (candela_light_sampler_parse(s->ops->name, &stats->light_sampler_used) != 0)
        stats->light_sampler_used = CANDELA_LIGHT_SAMPLER_AUTO; /* never: every strategy has its CLI name */
    if (s->ops->report) s->ops->report(s->state, stats);
}

#endif
