/* renderer/light_sampler.c: the light-selection protocol's dispatch (light_sampler.h) and its
 * two context-free strategies, uniform and power. */
#include "light_sampler.h"
#include "media.h"

#include <stdio.h>
#include <stdlib.h>

/* ---------------------------------------------------------------- uniform */

static uint32_t uniform_select(const void *state, const LightSampleContext *ctx, float u, float u1, float *pmf,
                               uint32_t *outcome) {
    (void)ctx; (void)u1; (void)outcome;
    uint32_t count = *(const uint32_t *)state;
    uint32_t i = (uint32_t)(u * (float)count);
    if (i >= count) i = count - 1;
    *pmf = 1.0f / (float)count;
    return i;
}

static float uniform_pmf(const void *state, const LightSampleContext *ctx, uint32_t light) {
    (void)ctx; (void)light;
    return 1.0f / (float)*(const uint32_t *)state;
}

static const LightSamplerOps UNIFORM_OPS = {
    .name = "uniform", .select = uniform_select, .pmf = uniform_pmf, .destroy = free};

int light_sampler_uniform_create(LightSampler *s, const Lights *lights) {
    uint32_t *count = malloc(sizeof *count);
    if (!count) return -1;
    *count = lights->count;
    *s = (LightSampler){&UNIFORM_OPS, count, lights->count};
    return 0;
}

/* ---------------------------------------------------------------- power */

/* In proportion to each light's power estimate (Light.power), whatever the shading point. */
static uint32_t power_select(const void *state, const LightSampleContext *ctx, float u, float u1, float *pmf,
                             uint32_t *outcome) {
    (void)ctx; (void)u1; (void)outcome;
    return dist1d_sample_discrete(state, u, pmf, NULL);
}

static float power_pmf(const void *state, const LightSampleContext *ctx, uint32_t light) {
    (void)ctx;
    return dist1d_pmf(state, light);
}

static void power_destroy(void *state) {
    dist1d_free(state);
    free(state);
}

static const LightSamplerOps POWER_OPS = {
    .name = "power", .select = power_select, .pmf = power_pmf, .destroy = power_destroy};

int light_sampler_power_create(LightSampler *s, const Lights *lights) {
    Distribution1D *d = calloc(1, sizeof *d);
    if (d && lights->count == 0) { /* nothing to select (the protocol never asks) */
        *s = (LightSampler){&POWER_OPS, d, 0};
        return 0;
    }
    float *powers = malloc(((size_t)lights->count + 1) * sizeof(float));
    if (!d || !powers) { free(d); free(powers); return -1; }
    for (uint32_t i = 0; i < lights->count; ++i) powers[i] = lights->lights[i].power;
    int rc = dist1d_init(d, powers, lights->count);
    free(powers);
    if (rc != 0) { free(d); return -1; }
    *s = (LightSampler){&POWER_OPS, d, lights->count};
    return 0;
}

/* ---------------------------------------------------------------- auto (the default) */

CandelaLightSampler light_sampler_auto_choice(const Lights *lights, const struct SceneMedia *media,
                                              const CandelaOptions *o) {
    /* in-scattering sampling along camera rays (§4.2) exists only with cache points */
    if (o->volume_inscatter_sampling == 1 || (o->volume_inscatter_sampling != 0 && media && media_any(media)))
        return CANDELA_LIGHT_SAMPLER_CACHEPOINTS;
    /* one light (or none): every strategy picks it with probability 1; power does no work */
    if (lights->count <= 1) return CANDELA_LIGHT_SAMPLER_POWER;
    /* few lights: every light's exact estimate per vertex (the distribution cache points
     * approximate, narrow spot cones included; the paper itself falls back to it below 10
     * points, §3.1.1), without a build, while that costs less per vertex than about
     * LIGHT_SAMPLER_AUTO_EXACT_COST point lights (an area light's estimate sums 16 points:
     * it counts LIGHT_SAMPLER_AUTO_AREA_COST) */
    if (lights->count > LIGHT_SAMPLER_SCRATCH) return CANDELA_LIGHT_SAMPLER_CACHEPOINTS;
    uint32_t cost = 0;
    for (uint32_t i = 0; i < lights->count; ++i)
        cost += lights->lights[i].type == LIGHT_AREA ? LIGHT_SAMPLER_AUTO_AREA_COST : 1u;
    return cost <= LIGHT_SAMPLER_AUTO_EXACT_COST ? CANDELA_LIGHT_SAMPLER_OPTIMAL : CANDELA_LIGHT_SAMPLER_CACHEPOINTS;
}

/* ---------------------------------------------------------------- dispatch */

int light_sampler_create(LightSampler *s, const Lights *lights, const struct Scene *scene,
                         const struct SceneMedia *media, struct ThreadPool *pool, const CandelaOptions *o,
                         char err[CANDELA_ERR_LEN]) {
    int rc;
    CandelaLightSampler which = o->light_sampler;
    if (which == CANDELA_LIGHT_SAMPLER_AUTO) which = light_sampler_auto_choice(lights, media, o);
    if ((o->aov_selection || o->cachepoint_dump_path) && which != CANDELA_LIGHT_SAMPLER_CACHEPOINTS && !o->no_warnings)
        fprintf(stderr, "%s: warning: --light-sampler auto chose %s for this scene: %s (give --light-sampler "
                "cachepoints to see cache points)\n", o->scene_path, candela_light_sampler_name(which),
                o->aov_selection ? "the cachepoint AOV stays black" : "the cache point dump is empty");
    switch (which) {
    case CANDELA_LIGHT_SAMPLER_POWER: rc = light_sampler_power_create(s, lights); break;
    case CANDELA_LIGHT_SAMPLER_TREE: rc = light_sampler_tree_create(s, lights); break;
    case CANDELA_LIGHT_SAMPLER_OPTIMAL:
        /* auto never adds occlusion rays (a shadow ray per light per vertex) */
        rc = light_sampler_optimal_create(s, lights, scene, o->light_sampler == which && o->optimal_occlusion);
        break;
    case CANDELA_LIGHT_SAMPLER_CACHEPOINTS:
        return light_sampler_cachepoints_create(s, lights, scene, media, pool, o, err); /* its own messages */
    default: rc = light_sampler_uniform_create(s, lights); break;
    }
    if (rc != 0) snprintf(err, CANDELA_ERR_LEN, "%s: out of memory building the light sampler", o->scene_path);
    return rc;
}

void light_sampler_free(LightSampler *s) {
    if (s->ops && s->ops->destroy) s->ops->destroy(s->state);
    *s = (LightSampler){0};
}
