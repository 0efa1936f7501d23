/* renderer/stage_shadow.c: the shadow rays of the wave's NEE. A ray that gets through adds its
 * pending contribution; either way its outcome (the fraction that reached the light: 0 or 1
 * through opaque geometry) goes back to the light sampler, which may learn from it (cache
 * points' visibility counters, §3.2.1). */
#include "integrator.h"

void stage_shadow(const Integrator *ig, Slice *s) {
    const PathState *ps = &ig->ps;
    const LightSampler *sampler = ig->light_sampler;
    uint8_t occluded[SCENE_RAY_PACKET];
    for (uint32_t b = 0; b < s->num_shadows; b += SCENE_RAY_PACKET) {
        uint32_t m = s->num_shadows - b < SCENE_RAY_PACKET ? s->num_shadows - b : SCENE_RAY_PACKET;
        const uint32_t *items = s->shadows + b;
        /* the learning state the outcomes will update arrives while the rays are traced */
        for (uint32_t k = 0; k < m; ++k) light_sampler_prefetch_outcome(sampler, ps->shadow_outcome[items[k]]);
        scene_occluded(ig->scene, ps->shadow_ray, items, m, occluded);
        for (uint32_t k = 0; k < m; ++k) {
            uint32_t p = items[k];
            float visibility = occluded[k] ? 0.0f : 1.0f;
            if (visibility > 0.0f) path_add_radiance(ps, p, v3_scale(ps->shadow_contrib[p], visibility), RADIANCE_DIRECT);
            light_sampler_record(sampler, ps->shadow_outcome[p], visibility);
        }
    }
}
