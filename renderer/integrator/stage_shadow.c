/* renderer/integrator/stage_shadow.c: the shadow rays of the wave's NEE. A ray that gets through adds its
 * pending contribution times the transmittance of the media it crosses; either way its
 * outcome (the fraction that reached the light: the transmittance's average, 0 when
 * occluded) goes back to the light sampler, which may learn from it. */
#include "vertex.h"
#include "record.h"
#include "volume_auto.h"

void stage_shadow(const Integrator *ig, Slice *s) {
    const PathState *ps = &ig->ps;
    const LightSampler *sampler = ig->light_sampler;
    int media = media_any(ig->media);
    uint8_t occluded[SCENE_RAY_PACKET];
    uint32_t masks[SCENE_RAY_PACKET]; /* shadow linking: each ray's mask, from its light */
    int shadow_linking = ig->lights->link && ig->lights->link->shadow_mask;
    for (uint32_t b = 0; b < s->num_shadows; b += SCENE_RAY_PACKET) {
        uint32_t m = s->num_shadows - b < SCENE_RAY_PACKET ? s->num_shadows - b : SCENE_RAY_PACKET;
        const uint32_t *items = s->shadows + b;
        /* the learning state the outcomes will update arrives while the rays are traced */
        for (uint32_t k = 0; k < m; ++k) light_sampler_prefetch_outcome(sampler, ps->shadow_outcome[items[k]]);
        record_prefetch_shadows(ig, items, m);
        if (shadow_linking) {
            for (uint32_t k = 0; k < m; ++k) masks[k] = lights_shadow_mask(ig->lights, ps->shadow_light[items[k]]);
            scene_occluded_masked(ig->scene, ps->shadow_ray, items, m, masks, occluded);
        } else {
            scene_occluded(ig->scene, ps->shadow_ray, items, m, occluded);
        }
        /* an NEE vertex hands its emission to its parent, which shading left long ago */
        record_prefetch_shadow_parents(ig, items, m);
        for (uint32_t k = 0; k < m; ++k) {
            uint32_t p = items[k];
            float visibility = 0.0f;
            if (!occluded[k]) {
                vec3 T = v3s(1.0f);
                if (media) {
                    const SceneRay *r = &ps->shadow_ray[p];
                    T = vertex_shadow_transmittance(ig, s, ps->rng_key[p], ps->shadow_depth[p], ps->shadow_medium[p], r->org,
                                             r->dir, r->tfar);
                }
                visibility = media ? clampf(v3_average(T), 0.0f, 1.0f) : 1.0f;
                vec3 c = v3_mul(ps->shadow_contrib[p], T);
                path_add_radiance(ig, p, c, RADIANCE_DIRECT, ps->shadow_depth[p]);
                if (ig->emission_auto.active) emission_probe_nee(ig, p, ps->shadow_light[p], v3_luminance(c), 0.0f);
            }
            light_sampler_record(sampler, ps->shadow_outcome[p], visibility);
            record_nee_done(ig, s, p);
        }
    }
}
